// The image view: upload or make an image, design its metric, then
// * path tool: click a source (distance map with iso-lines and colour bar),
//   move the pointer (the minimal path to it, redrawn as it moves, one
//   request in flight at a time), click again to fix a way-point (livewire),
//   close the contour;
// * segment tool: labelled seeds → geodesic Voronoi regions and boundaries;
// * mask tool: threshold the image → EDT, skeleton, offset.
// Coordinates sent are [row, column] (axis 0 first, index units); the SVG
// overlay has one unit per pixel, so cell (r, c) is centred at (c + .5, r + .5).
"use strict";
window.GX = window.GX || {};

(function () {
  const $ = (id) => document.getElementById(id);
  const SVGNS = "http://www.w3.org/2000/svg";

  const S = {
    image: null, // {id, shape: [h, w], grey: Uint8Array}
    tool: "path",
    // path tool
    source: null, chain: [], live: null, inflight: false, pending: null, distanceId: null,
    field: null, // {data, h, w, min, max} of the shown distance (for the read-out)
    // segment tool
    seeds: [], segInflight: false, segPending: false,
    mask: null, // {id, key}
  };
  // What the browser test and a curious developer can read.
  GX.imageState = S;
  GX.stats = { pathMs: [], pathFrameMs: [], pathFetchMs: [], pathServerMs: [], firstMapMs: [], firstMapParts: [], previewMs: [], lastPreview: null, lastPath: null, segment: null };

  // ---- metric -------------------------------------------------------------

  const PARAMS = {
    intensity: [
      ["value", "c (grey value; shift-click picks it)", 0, 255, 1, 128],
      ["power", "p", 0.25, 4, 0.25, 1],
      ["epsilon", "ε", 0.001, 0.5, 0.001, 0.01],
      ["sigma", "σ (smoothing)", 0, 8, 0.5, 1],
    ],
    edges: [
      ["sigma", "σ", 0, 8, 0.5, 1.5],
      ["power", "p", 0.25, 4, 0.25, 1],
      ["epsilon", "ε", 0.001, 0.5, 0.001, 0.02],
    ],
    vesselness: [
      ["smin", "smallest scale", 0.5, 8, 0.5, 1],
      ["smax", "largest scale", 0.5, 12, 0.5, 3],
      ["beta", "β", 0.1, 2, 0.05, 0.5],
      ["power", "p", 0.25, 4, 0.25, 1],
      ["epsilon", "ε", 0.001, 0.5, 0.001, 0.01],
    ],
    structure_tensor: [
      ["sigma", "σ (noise)", 0, 6, 0.5, 1],
      ["rho", "ρ (integration)", 0, 12, 0.5, 3],
      ["anisotropy", "A (0: isotropic)", 0, 0.98, 0.01, 0.9],
    ],
    constant: [],
  };

  function buildParams() {
    const kind = $("metric-kind").value;
    const box = $("metric-params");
    box.innerHTML = "";
    for (const [name, label, lo, hi, step, def] of PARAMS[kind]) {
      const row = document.createElement("label");
      row.className = "slider";
      row.innerHTML = `<span>${label}</span><input type="range" id="mp-${name}" min="${lo}" max="${hi}" step="${step}" value="${def}"><output id="mo-${name}">${def}</output>`;
      box.appendChild(row);
      row.querySelector("input").addEventListener("input", (e) => {
        $("mo-" + name).textContent = e.target.value;
        metricChanged();
      });
    }
    const extra = $("metric-extra");
    extra.innerHTML = "";
    if (kind === "edges") extra.innerHTML = `<label>mode <select id="mp-mode"><option value="follow">follow contours</option><option value="barrier">barrier</option></select></label>`;
    if (kind === "vesselness") extra.innerHTML = `<label>tubes <select id="mp-polarity"><option value="dark">dark</option><option value="bright">bright</option></select></label>`;
    const sel = extra.querySelector("select");
    if (sel) sel.addEventListener("change", metricChanged);
  }

  const num = (name) => Number($("mp-" + name).value);

  /**
   * The scheme of the distance maps behind paths: order 2, with source
   * factoring only if asked for. Plain order 2 solves a 1024² map in about
   * 60 % of the time, and its paths differ by a fraction of a cell; the map
   * of `grid.distance` and the paths that follow use the same scheme, so that
   * the paths descend the very map on screen (the server keeps it).
   */
  function scheme() {
    return { order: 2, factoring: $("factoring").checked };
  }

  /** Tolerance (cells) of the paths' simplification (`simplify` of grid.paths). */
  const PATH_SIMPLIFY = 0.25;

  /** The metric section of every grid request: {cost: ...} or {metric: ...}. */
  function metricSection() {
    const kind = $("metric-kind").value;
    const id = S.image.id;
    switch (kind) {
      case "constant": return { cost: { constant: 1, shape: S.image.shape } };
      case "intensity": return { cost: { dataset: id, design: { kind, value: num("value"), power: num("power"), epsilon: num("epsilon"), sigma: num("sigma") } } };
      case "edges": return { cost: { dataset: id, design: { kind, sigma: num("sigma"), power: num("power"), epsilon: num("epsilon"), mode: $("mp-mode").value } } };
      case "vesselness": {
        const a = Math.min(num("smin"), num("smax")), b = Math.max(num("smin"), num("smax"));
        const scales = a === b ? [a] : [a, (a + b) / 2, b];
        return { cost: { dataset: id, design: { kind, scales, polarity: $("mp-polarity").value, beta: num("beta"), power: num("power"), epsilon: num("epsilon") } } };
      }
      case "structure_tensor": return { metric: { kind, image: id, sigma: num("sigma"), rho: num("rho"), anisotropy: num("anisotropy") } };
    }
    throw new Error("unknown metric " + kind);
  }

  let metricTimer = null;
  function metricChanged() {
    clearTimeout(metricTimer);
    metricTimer = setTimeout(() => {
      if (!S.image) return;
      resetPath();
      warmCost();
      if ($("show-metric").checked) showMetric().catch(GX.fail);
      if (S.tool === "segment" && S.seeds.length) runSegment();
    }, 250);
  }

  /** The image again in place of a metric picture. */
  function showImage() {
    $("base").classList.remove("glyphs");
    S.metricPicture = null;
    $("base").src = S.image.url;
  }

  async function showMetric() {
    const kind = $("metric-kind").value;
    const image = S.image;
    if (kind === "constant") {
      showImage();
      GX.status("constant metric W = 1");
      return;
    }
    if (kind === "structure_tensor") {
      // A tensor field is drawn by the server as glyphs: the unit ball of the
      // metric on a lattice of one glyph every g cells, coloured by the
      // anisotropy. The picture has a caption above the field: the <img>
      // (class glyphs) covers the stage with it cropped off, so that the
      // glyphs sit over their cells.
      const r = await GX.api("POST", "/v1/grid/tensor-metric", { json: metricSection() });
      if (S.image !== image || $("metric-kind").value !== kind) return; // a newer image or metric won
      $("base").classList.add("glyphs");
      await setImg($("base"), r.tensor.data_url + "?format=png&colorbar=false");
      const g = Math.max(1, Math.ceil(Math.max(...image.shape) / 32));
      S.metricPicture = { kind, id: r.tensor.id, shape: r.tensor.shape, lattice: g };
      if (!S.field) showColourbar(0, 1, `glyph colour: anisotropy 1 − λmin/λmax; unit balls of the metric every ${g} cells`, 0);
      GX.status(`tensor metric (structure tensor): max anisotropy ${Number(r.stats.max_anisotropy).toPrecision(3)} over ${r.stats.cells} cells; ` +
        "each glyph is the unit ball of the metric (long along the cheap direction)");
      return;
    }
    const m = metricSection().cost;
    const r = await GX.api("POST", "/v1/grid/metric", { json: { cost: m } });
    if (S.image !== image || $("metric-kind").value !== kind) return;
    $("base").classList.remove("glyphs");
    await setImg($("base"), r.metric.data_url + "?format=png&colorbar=false");
    S.metricPicture = { kind, id: r.metric.id };
    GX.status(`metric ${kind}: ${r.stats ? JSON.stringify(r.stats) : ""}`);
  }

  /**
   * Designs the metric on the server before the first click: a path from
   * the centre to itself with `early_stop` (its solve stops at once) keeps
   * the designed cost in the server's cache, and grid.distance takes a
   * cached cost, so the first source's map is solved without designing W
   * again (a third of the request on a smoothed 1024² image). Debounced;
   * tensor metrics are not cached, a constant one needs no design.
   */
  let warmTimer = null;
  function warmCost() {
    clearTimeout(warmTimer);
    warmTimer = setTimeout(() => {
      if (!S.image) return;
      const sec = metricSection();
      if (!sec.cost || sec.cost.constant !== undefined) return;
      const c = [Math.floor(S.image.shape[0] / 2), Math.floor(S.image.shape[1] / 2)];
      GX.api("POST", "/v1/grid/paths", { json: { ...sec, ...scheme(), sources: [{ point: c }], ends: [c], early_stop: true }, key: "warm-metric" })
        .catch(GX.fail);
    }, 100);
  }

  // ---- image loading ------------------------------------------------------

  async function setImg(img, src) {
    const url = await GX.src(src);
    return new Promise((ok, bad) => {
      img.onload = () => ok(img);
      img.onerror = () => bad(new Error("could not load " + src));
      img.src = url;
    });
  }

  /** Reads grey values of an image Blob (for the intensity picker and masks). */
  async function greyOf(blob) {
    const bmp = await createImageBitmap(blob);
    const c = document.createElement("canvas");
    c.width = bmp.width; c.height = bmp.height;
    const ctx = c.getContext("2d");
    ctx.drawImage(bmp, 0, 0);
    const d = ctx.getImageData(0, 0, c.width, c.height).data;
    const g = new Uint8Array(c.width * c.height);
    for (let k = 0; k < g.length; k++) g[k] = Math.round(0.299 * d[4 * k] + 0.587 * d[4 * k + 1] + 0.114 * d[4 * k + 2]);
    return { grey: g, h: c.height, w: c.width };
  }

  async function loadBlob(blob, name) {
    GX.status("uploading " + name + " …");
    const meta = await GX.upload(blob, name, blob.type || "image/png");
    if (!meta.shape || meta.shape.length !== 2) throw new Error("the playground shows 2D images; this dataset has shape " + JSON.stringify(meta.shape));
    const { grey } = await greyOf(blob);
    if (S.image && S.image.url) URL.revokeObjectURL(S.image.url);
    S.image = { id: meta.id, shape: meta.shape, grey, url: URL.createObjectURL(blob), name };
    $("base").classList.remove("glyphs");
    S.metricPicture = null;
    const [h, w] = meta.shape;
    const svg = $("svg");
    svg.setAttribute("viewBox", `0 0 ${w} ${h}`);
    for (const el of [$("base"), $("overlay"), $("layer"), svg]) { el.style.aspectRatio = `${w} / ${h}`; }
    $("layer").width = w; $("layer").height = h;
    $("stage").style.aspectRatio = `${w} / ${h}`;
    await setImg($("base"), S.image.url);
    clearAll();
    $("image-info").textContent = `${name}: ${h}×${w}, dataset ${meta.id}`;
    GX.status("uploaded " + name + ": click on the image");
    warmCost();
    if ($("show-metric").checked) await showMetric();
  }

  async function loadSample() {
    const name = $("sample").value, n = Number($("sample-size").value);
    const grey = GX.samples.IMAGES[name](n);
    const blob = await GX.samples.greyToPng(grey, n, n);
    await loadBlob(blob, `${name}-${n}.png`);
    // Sensible metrics per sample.
    const kind = { vessels: "vesselness", cells: "edges", rooms: "intensity", shape: "constant" }[name];
    if (kind && $("metric-kind").value !== kind) {
      $("metric-kind").value = kind;
      buildParams();
      if (kind === "intensity") { $("mp-value").value = 220; $("mo-value").textContent = "220"; }
      warmCost();
      if ($("show-metric").checked) await showMetric();
    }
    if (name === "shape") setTool("mask");
  }

  // ---- pointer to index coordinates --------------------------------------

  function indexAt(ev) {
    const r = $("svg").getBoundingClientRect();
    const [h, w] = S.image.shape;
    const x = (ev.clientX - r.left) / r.width * w, y = (ev.clientY - r.top) / r.height * h;
    const row = Math.min(h - 1, Math.max(0, y - 0.5)), col = Math.min(w - 1, Math.max(0, x - 0.5));
    return [Math.round(row * 10) / 10, Math.round(col * 10) / 10];
  }

  function svgEl(tag, attrs, parent) {
    const e = document.createElementNS(SVGNS, tag);
    for (const k in attrs) e.setAttribute(k, attrs[k]);
    (parent || $("svg")).appendChild(e);
    return e;
  }
  const pts = (points) => points.map(([r, c]) => (c + 0.5).toFixed(2) + "," + (r + 0.5).toFixed(2)).join(" ");
  function marker(p, cls, colour) {
    const rad = Math.max(2, S.image.shape[1] / 150);
    return svgEl("circle", { cx: p[1] + 0.5, cy: p[0] + 0.5, r: rad, class: cls, fill: colour || "#ff3b30" });
  }

  // ---- path tool ----------------------------------------------------------

  function resetPath() {
    S.source = null; S.chain = []; S.pending = null; S.distanceId = null; S.field = null;
    $("svg").innerHTML = "";
    $("overlay").removeAttribute("src");
    $("overlay").style.display = "none";
    $("fastmap").style.display = "none";
    hideColourbar();
  }

  function clearAll() {
    resetPath();
    S.seeds = [];
    S.mask = null;
    const ctx = $("layer").getContext("2d");
    ctx.clearRect(0, 0, $("layer").width, $("layer").height);
  }

  /**
   * A new source: the distance map (shown), and the map cache warmed for paths.
   *
   * The map is shown from its values: the NPY download (which the read-out
   * and the colour bar need anyway) is drawn at once with the colours and
   * iso-lines of the server's picture (`fieldPixels`), then the server's
   * own `?format=png` replaces it when it has arrived. Waiting for the PNG
   * (encoded on the server, about 50 ms for 1024²) before showing anything
   * made the first map 450-510 ms; labels are not asked for (`outputs`),
   * which spares the server a 4 MB array.
   */
  async function setSource(p) {
    S.source = p;
    S.warmed = null;
    S.live = null;
    const t0 = performance.now();
    const sec = metricSection();
    let warmed;
    S.warmPromise = new Promise((ok) => { warmed = ok; });
    // Pointer moves wait on `warmPromise`: it is settled on every way out
    // (a newer click, a refused request), so that they never wait forever.
    let picture = null;
    try {
      const r = await GX.api("POST", "/v1/grid/distance", { json: { ...sec, ...scheme(), sources: [{ point: p }], outputs: { labels: false } } });
      if (S.source !== p) return; // a newer click won
      const tPost = performance.now();
      S.distanceId = r.distance.id;
      await loadField(r.distance.data_url, "distance");
      if (S.source !== p) return;
      const tLoad = performance.now();
      drawField(S.field);
      const ms = performance.now() - t0;
      GX.stats.firstMapMs.push(ms);
      GX.stats.firstMapParts.push({ post: tPost - t0, solve: r.stats.solve_seconds * 1000, download: tLoad - tPost, draw: t0 + ms - tLoad });
      GX.status(`distance map in ${ms.toFixed(0)} ms (solve ${(r.stats.solve_seconds * 1000).toFixed(1)} ms, ${r.stats.stop}); move the pointer`);
      // The server's picture, and the map kept for /v1/grid/paths, side by
      // side. The server keeps the map grid.distance just solved for the
      // paths of the same cost, sources and scheme, so the warming answer
      // is a descent on that map (stats.maps[0].cached); had it been
      // evicted, this request solves and keeps the whole map
      // (early_stop: false). Pointer moves wait for it rather than each
      // solving the same map.
      const ov = $("overlay");
      picture = setImg(ov, r.distance.data_url + "?format=png&colorbar=false").then(() => {
        if (S.source !== p) return;
        ov.style.display = "";
        $("fastmap").style.display = "none";
      });
      await GX.api("POST", "/v1/grid/paths", { json: { ...sec, ...scheme(), sources: [{ point: p }], ends: [p], early_stop: false }, key: "warm" })
        .catch(GX.fail);
      if (S.source === p) S.warmed = p;
    } finally {
      warmed();
    }
    await picture;
  }

  /**
   * RGBA pixels of a scalar field as the server draws `?format=png` with
   * `colorbar=false` (`io::render`): viridis over the finite range, walls
   * (NaN) black, unreached (+inf) grey, and 10 iso-lines (spacing
   * (max − min) / 11) drawn on the cells whose band differs from their
   * right or lower neighbour's, in the colour mixed 60 % towards black
   * (light colours) or white (dark ones).
   */
  function fieldPixels(f) {
    const n = f.h * f.w, w = f.w, v = f.data, min = f.min, span = f.max - f.min;
    // Each colour of the map and its iso-line colour, packed as the four
    // bytes R, G, B, A of a pixel (little-endian words: one store a pixel).
    const pack = (c) => ((255 << 24) | (c[2] << 16) | (c[1] << 8) | c[0]) >>> 0;
    const fill = new Uint32Array(1024), line = new Uint32Array(1024);
    for (let k = 0; k < 1024; k++) {
      const c = GX.viridis(k / 1023).map((x) => Math.min(255, Math.max(0, Math.round(x))));
      const luma = 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
      const t = luma >= 100 ? 0 : 255;
      fill[k] = pack(c);
      line[k] = pack(c.map((x) => Math.round(x * 0.4 + t * 0.6)));
    }
    const px = new Uint8ClampedArray(4 * n), out = new Uint32Array(px.buffer);
    const colour = new Uint16Array(n); // the colour index of each finite cell
    const band = new Int8Array(n); // its iso band (at most 10), −1 where not finite
    const grey = pack([128, 128, 128]), black = pack([0, 0, 0]);
    const step = span / 11, top = Math.max(Math.ceil(span / step) - 1, 0);
    for (let i = 0; i < n; i++) {
      const x = v[i];
      if (x === Infinity) { out[i] = grey; band[i] = -1; continue; }
      if (Number.isNaN(x)) { out[i] = black; band[i] = -1; continue; }
      const k = span > 0 ? Math.round(Math.min(1, Math.max(0, (x - min) / span)) * 1023) : 0;
      out[i] = fill[k];
      colour[i] = k;
      band[i] = step > 0 && x !== -Infinity ? Math.min(Math.floor(Math.max((x - min) / step, 0)), top) : -1;
    }
    if (step > 0) {
      for (let i = 0, c = 0; i < n; i++, c = c + 1 === w ? 0 : c + 1) {
        const a = band[i];
        if (a < 0) continue;
        const right = c + 1 < w ? band[i + 1] : -1, down = i + w < n ? band[i + w] : -1;
        if ((right >= 0 && right !== a) || (down >= 0 && down !== a)) out[i] = line[colour[i]];
      }
    }
    return px;
  }

  /** Shows a field at once on the `fastmap` canvas (see `setSource`). */
  function drawField(f) {
    const c = $("fastmap");
    c.width = f.w; c.height = f.h;
    c.style.aspectRatio = `${f.w} / ${f.h}`;
    c.style.opacity = $("overlay-opacity").value;
    c.getContext("2d").putImageData(new ImageData(fieldPixels(f), f.w, f.h), 0, 0);
    c.style.display = "";
    $("overlay").style.display = "none";
  }

  /** Fetches a scalar field as NPY for the colour bar and the read-out. */
  async function loadField(dataUrl, label) {
    // Single precision: half the bytes of the stored f64 map (8 MB → 4 MB
    // at 1024²), and the picture and read-out need no more.
    const buf = await GX.api("GET", dataUrl + "?format=npy&dtype=f32", { as: "arraybuffer", out: label + ".npy" });
    const a = GX.parseNpy(buf);
    let lo = Infinity, hi = -Infinity;
    for (let k = 0; k < a.data.length; k++) { const v = a.data[k]; if (Number.isFinite(v)) { if (v < lo) lo = v; if (v > hi) hi = v; } }
    S.field = { data: a.data, h: a.shape[0], w: a.shape[1], min: lo, max: hi, label, source: S.source };
    showColourbar(lo, hi, label);
  }

  /** The colour bar, with `lines` iso-lines (the server's pictures: 10) marked. */
  function showColourbar(lo, hi, label, lines) {
    if (lines === undefined) lines = 10;
    const c = $("colourbar");
    const ctx = c.getContext("2d");
    const w = c.width, h = c.height;
    for (let x = 0; x < w; x++) {
      const [r, g, b] = GX.viridis(x / (w - 1));
      ctx.fillStyle = `rgb(${r},${g},${b})`;
      ctx.fillRect(x, 0, 1, h);
    }
    // The server draws 10 iso-lines, spaced (max − min) / 11.
    ctx.fillStyle = "rgba(255,255,255,0.85)";
    for (let k = 1; k <= lines; k++) ctx.fillRect(Math.round(k / (lines + 1) * (w - 1)), 0, 1, h);
    $("cb-lo").textContent = lo.toPrecision(4);
    $("cb-hi").textContent = hi.toPrecision(4);
    $("cb-label").textContent = lines ? `${label}: iso-lines every ${((hi - lo) / (lines + 1)).toPrecision(3)}` : label;
    $("colourbar-box").style.visibility = "visible";
  }
  function hideColourbar() { $("colourbar-box").style.visibility = "hidden"; }

  /**
   * Asks for the path to `p`; coalesced: one request in flight, only the newest waits.
   *
   * The answer takes a round trip (about 10 ms at 1024²), so it can be on
   * screen one frame after the move at best. Until it lands, the page
   * draws at once a preview traced on the distance map it already holds
   * (`previewPath`), in the frame of the move; the server's path replaces
   * it.
   */
  function pathTo(p) {
    const t = performance.now();
    S.pending = { p, t };
    const preview = previewPath(p);
    if (preview) {
      if (!S.live) S.live = svgEl("polyline", { class: "live" });
      S.live.setAttribute("points", pts(preview));
      S.live.dataset.from = "preview";
      requestAnimationFrame(() => {
        GX.stats.previewMs.push(performance.now() - t);
        GX.stats.lastPreview = { end: p, points: preview };
      });
    }
    if (!S.inflight) pump();
  }

  /**
   * The minimal path from the source to `p` traced on the map in the page
   * (the f32 download of the map the server solved): steepest descent from
   * the cell of `p` to whichever of its 8 neighbours has the smallest U,
   * until U = 0 (the source's cell). Fast marching freezes every cell after
   * an upwind neighbour of smaller U, so U has no other local minimum and
   * the descent ends at the source, in one step per cell of the path (the
   * browser test measures it drawn 2.6-3.1 ms after the move, median, at
   * 1024², waiting for the frame included). A staircase of cell centres, not
   * the server's sub-cell path, which replaces it one frame later. `null`
   * while the map is not this source's, or where `p` is unreached.
   */
  function previewPath(p) {
    const f = S.field;
    if (!f || f.label !== "distance" || f.source !== S.source) return null;
    const { w, h, data } = f;
    let r = Math.min(h - 1, Math.max(0, Math.round(p[0]))), c = Math.min(w - 1, Math.max(0, Math.round(p[1])));
    let u = data[r * w + c];
    if (!Number.isFinite(u)) return null;
    const cells = [p];
    for (let guard = 0; u > 0 && guard < w * h; guard++) {
      let best = u, br = -1, bc = -1;
      for (let dr = -1; dr <= 1; dr++) {
        const rr = r + dr;
        if (rr < 0 || rr >= h) continue;
        for (let dc = -1; dc <= 1; dc++) {
          const cc = c + dc;
          if ((dr === 0 && dc === 0) || cc < 0 || cc >= w) continue;
          const v = data[rr * w + cc];
          if (v < best) { best = v; br = rr; bc = cc; }
        }
      }
      if (br < 0) break; // a flat spot of the f32 rounding: stop here
      r = br; c = bc; u = best;
      cells.push([r, c]);
    }
    cells.push(S.source);
    return cells.reverse();
  }

  async function pump() {
    S.inflight = true;
    try {
      if (S.warmPromise) await S.warmPromise;
      while (S.pending && S.source) {
        const { p, t } = S.pending;
        S.pending = null;
        const src = S.source;
        const t1 = performance.now();
        // `simplify`: vertices within a quarter cell of the drawn line are
        // dropped (a few dozen instead of one per half cell): less to send,
        // parse and draw, and nothing visible lost.
        const r = await GX.api("POST", "/v1/grid/paths", { json: { ...metricSection(), ...scheme(), sources: [{ point: src }], ends: [p], early_stop: false, simplify: PATH_SIMPLIFY }, key: "pointer-path" });
        GX.stats.pathFetchMs.push(performance.now() - t1);
        GX.stats.pathServerMs.push(r.stats.total_seconds * 1000);
        if (S.source !== src) continue;
        const path = r.paths[0];
        if (!S.live) S.live = svgEl("polyline", { class: "live" });
        // A newer move's preview stays until its own answer.
        if (S.pending) continue;
        S.live.setAttribute("points", pts(path.points));
        S.live.dataset.from = "server";
        // Drawn: the next frame's rAF callback (its argument is the frame's
        // start, the time the frame that shows the path began).
        const frame = await new Promise((ok) => requestAnimationFrame(ok));
        const ms = performance.now() - t;
        GX.stats.pathMs.push(ms);
        GX.stats.pathFrameMs.push(frame - t);
        GX.stats.lastPath = { end: p, points: path.points, ms, cached: r.stats.maps.every((m) => m.cached) };
        $("path-info").textContent = `path: ${path.points.length} points, geodesic length ${path.geodesic_length.toPrecision(4)}, euclidean ${path.euclidean_length.toPrecision(4)}; ${ms.toFixed(1)} ms move→drawn (${r.stats.maps[0].cached ? "cached map" : "map solved"}, server ${(r.stats.total_seconds * 1000).toFixed(1)} ms)`;
      }
    } catch (e) {
      GX.fail(e);
    } finally {
      S.inflight = false;
    }
  }

  async function pathClick(p) {
    if (!S.source) {
      S.chain = [p];
      marker(p, "src");
      await setSource(p);
      return;
    }
    // Fix the live path as a leg of the livewire and continue from p.
    if (S.live) { S.live.setAttribute("class", "fixed"); S.live = null; }
    S.chain.push(p);
    marker(p, "way", "#ffcc00");
    await setSource(p);
  }

  async function closeContour() {
    if (S.chain.length < 3) { GX.status("place at least 3 points (clicks) before closing the contour", true); return; }
    const r = await GX.api("POST", "/v1/grid/paths", { json: { ...metricSection(), ...scheme(), contour: S.chain, simplify: PATH_SIMPLIFY } });
    const chain = S.chain;
    resetPath();
    chain.forEach((p) => marker(p, "way", "#ffcc00"));
    const all = [];
    for (const path of r.paths) { svgEl("polyline", { class: "contour", points: pts(path.points) }); all.push(...path.points); }
    GX.stats.contour = all;
    GX.status(`closed contour through ${chain.length} points: ${r.paths.length} legs, ${all.length} points`);
  }

  // ---- segment tool -------------------------------------------------------

  const LABEL_COLOURS = ["#ff3b30", "#34c759", "#0a84ff", "#ffcc00", "#af52de", "#ff9500", "#5ac8fa", "#ff2d55"];

  function segClick(p) {
    const label = Number($("seg-label").value);
    S.seeds.push({ label, point: p });
    runSegment();
  }

  async function runSegment() {
    if (!S.seeds.length) return;
    if (S.segInflight) { S.segPending = true; return; }
    S.segInflight = true;
    try {
      do {
        S.segPending = false;
        const radius = Number($("seg-radius").value);
        const body = { ...metricSection(), seeds: S.seeds, contours: true };
        if (radius > 0) body.max_distance = radius;
        const r = await GX.api("POST", "/v1/grid/segment", { json: body });
        const ov = $("overlay");
        ov.style.display = ""; $("fastmap").style.display = "none";
        await setImg(ov, r.labels.data_url + "?format=png");
        const svg = $("svg");
        svg.innerHTML = "";
        const features = (r.contours && r.contours.features) || [];
        for (const f of features) {
          // GeoJSON rings: [x, y] = [column, row] of cell corners (spacing 1 here).
          let d = "";
          for (const poly of f.geometry.coordinates) for (const ring of poly) d += "M" + ring.map(([x, y]) => (x + 0.5).toFixed(1) + "," + (y + 0.5).toFixed(1)).join("L") + "Z";
          svgEl("path", { d, class: "region", "data-label": f.properties.label, stroke: LABEL_COLOURS[(f.properties.label - 1) % 8] });
        }
        S.seeds.forEach((s) => marker(s.point, "seed", LABEL_COLOURS[(s.label - 1) % 8]));
        GX.stats.segment = { labels: features.map((f) => ({ label: f.properties.label, cells: f.properties.cells })), id: r.labels.id, summary: r.labels_summary };
        GX.status(`${S.seeds.length} seeds → ${features.length} regions: ` + features.map((f) => `label ${f.properties.label}: ${f.properties.cells} cells`).join(", "));
        hideColourbar();
      } while (S.segPending);
    } catch (e) {
      GX.fail(e);
    } finally {
      S.segInflight = false;
    }
  }

  // ---- mask tool ----------------------------------------------------------

  function maskBits() {
    const thr = Number($("mask-thr").value), inv = $("mask-invert").checked;
    const g = S.image.grey, m = new Uint8Array(g.length);
    for (let k = 0; k < g.length; k++) m[k] = (g[k] >= thr) !== inv ? 255 : 0;
    return m;
  }

  function drawMask(bits, rgba) {
    const [h, w] = S.image.shape;
    const ctx = $("layer").getContext("2d");
    const img = ctx.createImageData(w, h);
    for (let k = 0; k < w * h; k++) if (bits[k]) { img.data.set(rgba, 4 * k); }
    ctx.putImageData(img, 0, 0);
  }

  async function maskId() {
    const key = $("mask-thr").value + ":" + $("mask-invert").checked + ":" + S.image.id;
    if (S.mask && S.mask.key === key) return S.mask.id;
    const bits = maskBits();
    const blob = await GX.samples.greyToPng(bits, S.image.shape[0], S.image.shape[1]);
    const meta = await GX.upload(blob, "mask.png", "image/png");
    S.mask = { id: meta.id, key };
    return meta.id;
  }

  function previewMask() {
    if (!S.image) return;
    $("svg").innerHTML = "";
    $("overlay").style.display = "none";
    hideColourbar();
    drawMask(maskBits(), [10, 132, 255, 110]);
  }

  async function maskOp(op) {
    const id = await maskId();
    const ov = $("overlay");
    $("svg").innerHTML = "";
    if (op === "edt") {
      const r = await GX.api("POST", "/v1/grid/edt", { json: { mask: id, mode: "signed" } });
      ov.style.display = ""; $("fastmap").style.display = "none";
      await setImg(ov, r.distance.data_url + "?format=png&colorbar=false");
      drawMask(new Uint8Array(0), [0, 0, 0, 0]);
      await loadField(r.distance.data_url, "signed distance");
      GX.status("signed Euclidean distance transform (negative inside)");
    } else if (op === "skeleton") {
      const r = await GX.api("POST", "/v1/grid/skeleton", { json: { mask: id, min_boundary_fraction: 0.05 } });
      ov.style.display = "none";
      hideColourbar();
      drawMask(maskBits(), [10, 132, 255, 90]);
      const edges = (r.graph && r.graph.edges) || [];
      for (const e of edges) svgEl("polyline", { class: "skeleton", points: pts(e.points) });
      for (const n of (r.graph && r.graph.nodes) || []) marker(n.point, "node", n.degree === 1 ? "#ffcc00" : "#ff3b30");
      GX.status(`skeleton: ${edges.length} branches, ${(r.graph && r.graph.nodes.length) || 0} nodes`);
    } else {
      const radius = Number($("mask-radius").value);
      const operation = $("mask-erode").checked ? "erode" : "dilate";
      const r = await GX.api("POST", "/v1/grid/offset", { json: { mask: id, radius, operation } });
      ov.style.display = "none";
      hideColourbar();
      const buf = await GX.api("GET", r.offset.data_url + "?format=npy", { as: "arraybuffer", out: "offset.npy" });
      const off = GX.parseNpy(buf).data;
      drawMask(off, [255, 149, 0, 120]);
      const ctx = $("layer").getContext("2d");
      const img = ctx.getImageData(0, 0, $("layer").width, $("layer").height);
      const m = maskBits();
      for (let k = 0; k < m.length; k++) if (m[k]) img.data.set([10, 132, 255, 160], 4 * k);
      ctx.putImageData(img, 0, 0);
      GX.status(`${operation} by ${radius}: orange is the offset shape, blue the mask`);
    }
  }

  // ---- wiring -------------------------------------------------------------

  function setTool(t) {
    S.tool = t;
    document.querySelectorAll("input[name=tool]").forEach((r) => { r.checked = r.value === t; });
    document.querySelectorAll(".tool-box").forEach((b) => { b.hidden = b.dataset.tool !== t; });
    if (!S.image) return;
    clearAll();
    if (t === "mask") previewMask();
  }
  GX.setTool = setTool;

  function readout(p) {
    const [h, w] = S.image.shape;
    const k = Math.round(p[0]) * w + Math.round(p[1]);
    let s = `[${p[0].toFixed(1)}, ${p[1].toFixed(1)}]  grey ${S.image.grey[k]}`;
    if (S.field && S.field.h === h) s += `  ${S.field.label} ${Number(S.field.data[k]).toPrecision(4)}`;
    $("readout").textContent = s;
  }

  function init() {
    buildParams();
    $("metric-kind").addEventListener("change", () => { buildParams(); metricChanged(); });
    $("show-metric").addEventListener("change", () => {
      if (!S.image) return;
      if ($("show-metric").checked) showMetric().catch(GX.fail); else { showImage(); if (!S.field) hideColourbar(); }
    });
    $("load-sample").addEventListener("click", () => loadSample().catch(GX.fail));
    $("image-file").addEventListener("change", (e) => {
      const f = e.target.files[0];
      if (f) loadBlob(f, f.name).catch(GX.fail);
    });
    document.querySelectorAll("input[name=tool]").forEach((r) => r.addEventListener("change", () => setTool(r.value)));
    $("close-contour").addEventListener("click", () => closeContour().catch(GX.fail));
    $("clear-path").addEventListener("click", resetPath);
    $("factoring").addEventListener("change", resetPath);
    $("clear-seeds").addEventListener("click", () => { clearAll(); });
    $("seg-radius").addEventListener("input", () => { $("seg-radius-out").textContent = $("seg-radius").value === "0" ? "off" : $("seg-radius").value; runSegment(); });
    $("overlay-opacity").addEventListener("input", () => {
      for (const id of ["overlay", "fastmap"]) $(id).style.opacity = $("overlay-opacity").value;
    });
    $("mask-thr").addEventListener("input", () => { $("mask-thr-out").textContent = $("mask-thr").value; previewMask(); });
    $("mask-invert").addEventListener("change", previewMask);
    $("mask-radius").addEventListener("input", () => { $("mask-radius-out").textContent = $("mask-radius").value; });
    for (const op of ["edt", "skeleton", "offset"]) $("mask-" + op).addEventListener("click", () => maskOp(op).catch(GX.fail));

    const svg = $("svg");
    svg.addEventListener("pointermove", (ev) => {
      if (!S.image) return;
      const p = indexAt(ev);
      readout(p);
      if (S.tool === "path" && S.source) pathTo(p);
    });
    svg.addEventListener("click", (ev) => {
      if (!S.image) return;
      const p = indexAt(ev);
      if (ev.shiftKey && $("metric-kind").value === "intensity") {
        const v = S.image.grey[Math.round(p[0]) * S.image.shape[1] + Math.round(p[1])];
        $("mp-value").value = v; $("mo-value").textContent = v;
        metricChanged();
        return;
      }
      if (S.tool === "path") pathClick(p).catch(GX.fail);
      else if (S.tool === "segment") segClick(p);
    });
    setTool("path");
  }

  GX.image = { init, loadSample, loadBlob, metricSection, setTool, closeContour };
})();
