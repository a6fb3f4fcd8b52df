// The mesh view: upload a mesh (OBJ, PLY, OFF, STL) or make a sample, then
// click a point (a face and barycentric coordinates) for the geodesic
// distance by the chosen method, click again for the minimal path to it,
// compare the methods against the exact one, place farthest-point samples.
"use strict";
window.GX = window.GX || {};

(function () {
  const $ = (id) => document.getElementById(id);
  const M = { id: null, mesh: null, source: null, results: {}, viewer: null };
  GX.meshState = M;

  async function loadMeshBlob(blob, name) {
    GX.status("uploading " + name + " …");
    const ext = name.split(".").pop().toLowerCase();
    const type = { obj: "model/obj", ply: "model/ply", off: "model/off", stl: "model/stl" }[ext] || "application/octet-stream";
    const meta = await GX.upload(blob, name, type);
    // The stored mesh (welded, repaired): its vertex order is the one results use.
    const mesh = await GX.api("GET", `/v1/datasets/${meta.id}/data?format=json`, { out: "mesh.json" });
    M.id = meta.id; M.mesh = mesh; M.source = null; M.results = {};
    M.viewer.setMesh(mesh.vertices, mesh.faces);
    const rep = meta.mesh || {};
    $("mesh-info").textContent = `${name}: ${mesh.vertices.length} vertices, ${mesh.faces.length} faces, dataset ${meta.id}` +
      (rep.boundary_loops !== undefined ? `, ${rep.boundary_loops} boundary loops` : "");
    $("mesh-compare").innerHTML = "";
    GX.status("click on the mesh for a source; click again for a path; drag to rotate, wheel to zoom");
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
    $("mesh-new-source").addEventListener("click", () => { M.source = null; M.viewer.clearLines(); M.viewer.setValues(new Array(M.mesh ? M.mesh.vertices.length : 0).fill(-1), 0); });
  }

  GX.mesh = { init, loadSample, loadMeshBlob };
})();
