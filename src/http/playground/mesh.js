// The mesh view: upload a mesh (OBJ, PLY, OFF, STL) or make a sample, then
// click a point (a face and barycentric coordinates) for the geodesic
// distance by the chosen method, click again for the minimal path to it,
// compare the methods against the exact one, place farthest-point samples;
// remesh it (mesh.remesh) or show its bending-invariant canonical form
// (mesh.embed), each shown in place of the mesh (clicks then measure on
// the shown one) until "back to the original".
"use strict";
window.GX = window.GX || {};

(function () {
  const $ = (id) => document.getElementById(id);
  // `id`, `mesh`: the shown mesh (what clicks measure on); `kind`: "original",
  // "remeshed" or "canonical"; `original`: the uploaded one, to go back to.
  const M = { id: null, mesh: null, kind: null, original: null, source: null, results: {}, viewer: null };
  GX.meshState = M;

  /** Shows a mesh dataset ({vertices, faces} as `?format=json` answers it) in the viewer. */
  function show(id, mesh, kind, info) {
    M.id = id; M.mesh = mesh; M.kind = kind; M.source = null; M.results = {};
    M.viewer.setMesh(mesh.vertices, mesh.faces);
    $("mesh-info").textContent = info;
    $("mesh-compare").innerHTML = "";
    $("mesh-original").disabled = kind === "original";
    // remesh.count must not exceed the shown mesh's vertex count.
    const c = $("remesh-count");
    c.max = Math.max(4, mesh.vertices.length);
    if (Number(c.value) > mesh.vertices.length) c.value = Math.max(4, Math.round(mesh.vertices.length / 2));
    $("remesh-count-out").textContent = c.value;
    GX.meshView = { kind, id, vertices: mesh.vertices.length, faces: mesh.faces.length };
  }

  async function loadMeshBlob(blob, name) {
    GX.status("uploading " + name + " …");
    const ext = name.split(".").pop().toLowerCase();
    const type = { obj: "model/obj", ply: "model/ply", off: "model/off", stl: "model/stl" }[ext] || "application/octet-stream";
    const meta = await GX.upload(blob, name, type);
    // The stored mesh (welded, repaired): its vertex order is the one results use.
    const mesh = await GX.api("GET", `/v1/datasets/${meta.id}/data?format=json`, { out: "mesh.json" });
    const rep = meta.mesh || {};
    const info = `${name}: ${mesh.vertices.length} vertices, ${mesh.faces.length} faces, dataset ${meta.id}` +
      (rep.boundary_loops !== undefined ? `, ${rep.boundary_loops} boundary loops` : "");
    M.original = { id: meta.id, mesh, info };
    $("mesh-derived").innerHTML = "";
    show(meta.id, mesh, "original", info);
    GX.status("click on the mesh for a source; click again for a path; drag to rotate, wheel to zoom");
  }

  function backToOriginal() {
    if (!M.original) return;
    show(M.original.id, M.original.mesh, "original", M.original.info);
    $("mesh-derived").innerHTML = "";
    GX.status("the original mesh again");
  }

  const fmt = (x, p) => (typeof x === "number" ? x.toPrecision(p || 3) : "–");

  /** A two-column table of what an answer says, under the buttons. */
  function statsTable(title, rows) {
    $("mesh-derived").innerHTML = `<p class=hint>${title}</p><table>` +
      rows.map(([k, v]) => `<tr><td>${k}</td><td>${v}</td></tr>`).join("") + "</table>";
  }

  /** Remeshes the shown mesh to about `count` vertices and shows the result with its edges. */
  async function remesh() {
    if (!M.id) return;
    const count = Math.min(Number($("remesh-count").value), M.mesh.vertices.length);
    const adaptation = $("remesh-adapt").value;
    GX.status(`remeshing to ${count} vertices (${adaptation}) …`);
    const t0 = performance.now();
    const r = await GX.api("POST", "/v1/mesh/remesh", { json: { mesh: M.id, count, adaptation } });
    const mesh = await GX.api("GET", r.remeshed.data_url + "?format=json", { out: "remeshed.json" });
    const ms = performance.now() - t0;
    const s = r.stats, from = M.mesh.vertices.length;
    show(r.remeshed.id, mesh, "remeshed",
      `remeshed (${adaptation}) from ${from} vertices: ${mesh.vertices.length} vertices, ${mesh.faces.length} faces, dataset ${r.remeshed.id}`);
    $("mesh-edges").checked = true;
    M.viewer.setEdges(true);
    const e = s.lloyd_energies || [];
    const topo = (t) => t ? `genus ${t.genus}, ${t.boundary_loops} boundary loops, ${t.components} component${t.components === 1 ? "" : "s"}` : "–";
    statsTable("remeshing (mesh.remesh)", [
      ["vertices / target", `${s.vertices} / ${s.target_count}` + (s.added ? ` (${s.added} added by the repair)` : "")],
      ["triangles", s.triangles],
      ["Hausdorff to the input", s.hausdorff === undefined ? "–" : `${fmt(s.hausdorff)} (${fmt(100 * s.hausdorff_relative)} % of the diagonal)`],
      ["Lloyd energy", e.length ? `${fmt(e[0])} → ${fmt(e[e.length - 1])} (${s.lloyd_accepted} iteration${s.lloyd_accepted === 1 ? "" : "s"} kept)` : "–"],
      ["valid, flipped", `${s.valid}, ${s.flipped}`],
      ["topology", (s.topology_kept ? "kept: " : "changed: ") + topo(s.output_topology)],
    ]);
    GX.meshRemesh = { target: count, vertices: mesh.vertices.length, triangles: mesh.faces.length, stats: s };
    GX.status(`remeshed: ${s.vertices} vertices, ${s.triangles} triangles (target ${s.target_count}); ` +
      (s.hausdorff === undefined ? "" : `Hausdorff ${fmt(s.hausdorff)} = ${fmt(100 * s.hausdorff_relative)} % of the diagonal; `) +
      `${s.topology_kept ? "topology kept" : s.topology_note}; valid ${s.valid}, ${s.flipped} flipped; ${ms.toFixed(0)} ms`);
  }

  /**
   * The canonical form of the shown mesh: its geodesic distances embedded by
   * MDS (all pairs, or landmark MDS); the same faces at the embedded
   * positions. Distances shown on the mesh stay on the same vertices.
   */
  async function embed() {
    if (!M.id) return;
    const n = M.mesh.vertices.length;
    const dimensions = Number($("embed-dims").value);
    let landmarks = Number($("embed-landmarks").value);
    // All pairs only up to 5000 vertices (the operation's limit).
    if (!landmarks && n > 5000) landmarks = 200;
    const body = { mesh: M.id, dimensions };
    if (landmarks) body.landmarks = Math.min(landmarks, n);
    GX.status(`canonical form of ${n} vertices (${landmarks ? landmarks + " landmarks" : "all pairs"}) …`);
    const t0 = performance.now();
    const r = await GX.api("POST", "/v1/mesh/embed", { json: body });
    const mesh = await GX.api("GET", r.result.data_url + "?format=json", { out: "canonical.json" });
    const ms = performance.now() - t0;
    const values = M.viewer.values && M.viewer.n === mesh.vertices.length ? Array.from(M.viewer.values) : null;
    const edges = M.viewer.showEdges;
    // MDS answers principal axes, largest spread first: look along the third
    // (the thinnest), slightly from above, with the first across the screen.
    M.viewer.yaw = 0; M.viewer.pitch = 0.25;
    show(r.result.id, mesh, "canonical",
      `canonical form (${r.dimensions}D, ${r.landmarks && r.landmarks.length ? r.landmarks.length + " landmarks" : "all pairs"}) of ${n} vertices, dataset ${r.result.id}`);
    if (values) M.viewer.setValues(values.map((v) => (v === -2 ? null : v)), 12);
    M.viewer.setEdges(edges);
    statsTable("canonical form (mesh.embed)", [
      ["stress", fmt(r.stress)],
      ["explained variance", fmt(r.explained_variance)],
      ["asymmetry of the distances", fmt(r.asymmetry)],
      ["method", `${r.method}, ${r.landmarks && r.landmarks.length ? r.landmarks.length + " landmarks" : "all pairs"}`],
      ["solve", r.stats && typeof r.stats.solve_seconds === "number" ? (r.stats.solve_seconds * 1000).toFixed(0) + " ms" : "–"],
    ]);
    GX.meshEmbed = { stress: r.stress, explained_variance: r.explained_variance, dimensions: r.dimensions, vertices: mesh.vertices.length };
    GX.status(`canonical form: stress ${fmt(r.stress)}, explained variance ${fmt(r.explained_variance)}, ` +
      `asymmetry ${fmt(r.asymmetry)} (${r.dimensions}D, ${ms.toFixed(0)} ms)`);
  }

  async function loadSample() {
    const name = $("mesh-sample").value;
    const text = GX.samples.MESHES[name]();
    await loadMeshBlob(new Blob([text], { type: "model/obj" }), name.replace(/[^a-z]+/g, "-") + ".obj");
  }

  const point = (hit) => ({ face: hit.face, bary: hit.bary.map((b) => Math.max(0, b)) });

  function normalise(p) {
    const s = p.bary[0] + p.bary[1] + p.bary[2];
    return { face: p.face, bary: p.bary.map((b) => b / s) };
  }

  async function distance() {
    const method = $("mesh-method").value;
    const r = await GX.api("POST", "/v1/mesh/distance", { json: { mesh: M.id, sources: [M.source], method } });
    const data = await GX.api("GET", r.result.data_url + "?format=json", { out: "distance.json" });
    const d = data.properties.distance;
    M.results[method] = { d, seconds: r.stats && (r.stats.solve_seconds || r.stats.seconds) };
    M.viewer.clearLines();
    M.viewer.setValues(d, 12);
    let hi = 0;
    for (const v of d) if (v !== null && v > hi) hi = v;
    GX.meshShown = { method, max: hi, reached: d.filter((v) => v !== null).length };
    GX.status(`${method}: max distance ${hi.toPrecision(4)} (${JSON.stringify(r.stats)})`);
    compare();
  }

  /** The table of methods run from this source: max and mean |d − d_exact|. */
  function compare() {
    const ex = M.results.exact && M.results.exact.d;
    let html = "<tr><th>method</th><th>solve</th><th>max |Δ exact|</th><th>mean |Δ exact|</th></tr>";
    for (const [m, r] of Object.entries(M.results)) {
      let mx = "", mean = "";
      if (ex && m !== "exact") {
        let a = 0, s = 0, n = 0;
        r.d.forEach((v, i) => { if (v !== null && ex[i] !== null) { const e = Math.abs(v - ex[i]); a = Math.max(a, e); s += e; n++; } });
        mx = a.toExponential(2); mean = (s / Math.max(1, n)).toExponential(2);
      }
      const t = typeof r.seconds === "number" ? (r.seconds * 1000).toFixed(1) + " ms" : "";
      html += `<tr><td>${m}</td><td>${t}</td><td>${mx}</td><td>${mean}</td></tr>`;
    }
    $("mesh-compare").innerHTML = "<table>" + html + "</table>" + (ex ? "" : "<p class=hint>run <b>exact</b> from the same source to compare.</p>");
  }

  async function pathTo(target) {
    const method = $("mesh-method").value;
    const r = await GX.api("POST", "/v1/mesh/paths", { json: { mesh: M.id, sources: [M.source], ends: [target], method } });
    const p = r.paths[0];
    M.viewer.clearLines();
    // Points on edges are sparse on a coarse mesh: add 8 steps per segment so the dots read as a line.
    const dense = [];
    const q = p.points.map((x) => x.position);
    for (let i = 0; i + 1 < q.length; i++) for (let k = 0; k < 8; k++) dense.push(q[i].map((v, j) => v + (q[i + 1][j] - v) * k / 8));
    if (q.length) dense.push(q[q.length - 1]);
    M.viewer.addLine(dense, [1, 0.23, 0.19]);
    GX.meshPath = p;
    GX.status(`path: ${p.points.length} points, geodesic length ${p.geodesic_length.toPrecision(4)} (polyline ${p.euclidean_length.toPrecision(4)})`);
  }

  async function sample() {
    if (!M.id) return;
    const count = Number($("mesh-count").value);
    const method = $("mesh-method").value;
    const r = await GX.api("POST", "/v1/mesh/sample", { json: { mesh: M.id, count, method } });
    const data = await GX.api("GET", r.result.data_url + "?format=json", { out: "sample.json" });
    M.viewer.clearLines();
    M.viewer.setValues(data.properties.distance, 6);
    const ids = r.samples.map((s) => (Array.isArray(s) ? s[0] : s));
    M.viewer.setPoints(ids);
    GX.meshSamples = ids;
    GX.status(`${ids.length} farthest-point samples, covering radius ${Number(r.covering_radius).toPrecision(4)}`);
  }

  async function onPick(hit, ev) {
    const p = normalise(point(hit));
    if (!M.source || ev.shiftKey) {
      M.source = p; M.results = {};
      await distance();
    } else {
      await pathTo(p);
    }
  }

  function init() {
    M.viewer = new GX.Viewer($("mesh-canvas"));
    M.viewer.onPick = (hit, ev) => onPick(hit, ev).catch(GX.fail);
    $("mesh-load-sample").addEventListener("click", () => loadSample().catch(GX.fail));
    $("mesh-file").addEventListener("change", (e) => {
      const f = e.target.files[0];
      if (f) loadMeshBlob(f, f.name).catch(GX.fail);
    });
    $("mesh-method").addEventListener("change", () => { if (M.source) distance().catch(GX.fail); });
    $("mesh-sample-run").addEventListener("click", () => sample().catch(GX.fail));
    $("mesh-count").addEventListener("input", () => { $("mesh-count-out").textContent = $("mesh-count").value; });
    $("remesh-run").addEventListener("click", () => remesh().catch(GX.fail));
    $("remesh-count").addEventListener("input", () => { $("remesh-count-out").textContent = $("remesh-count").value; });
    $("embed-run").addEventListener("click", () => embed().catch(GX.fail));
    $("embed-landmarks").addEventListener("input", () => {
      const v = $("embed-landmarks").value;
      $("embed-landmarks-out").textContent = v === "0" ? "all" : v;
    });
    $("mesh-original").addEventListener("click", backToOriginal);
    $("mesh-edges").addEventListener("change", () => M.viewer.setEdges($("mesh-edges").checked));
    $("mesh-new-source").addEventListener("click", () => { M.source = null; M.viewer.clearLines(); M.viewer.setValues(new Array(M.mesh ? M.mesh.vertices.length : 0).fill(-1), 0); });
  }

  GX.mesh = { init, loadSample, loadMeshBlob, remesh, embed, backToOriginal };
})();
