// Start-up: the tabs, the "Requests" panel (each request as curl, newest
// first, with a copy button), then the three views.
"use strict";
(function () {
  const $ = (id) => document.getElementById(id);

  function showView(name) {
    document.querySelectorAll(".view").forEach((v) => { v.hidden = v.id !== "view-" + name; });
    document.querySelectorAll("nav button").forEach((b) => b.classList.toggle("on", b.dataset.view === name));
    if (name === "mesh" && GX.meshState.viewer) GX.meshState.viewer.draw();
    if (name === "jobs") GX.jobs.list().catch(GX.fail);
  }
  GX.showView = showView;

  function renderLog() {
    const box = $("requests");
    box.innerHTML = "";
    for (const e of GX.requestLog.slice(0, 14)) {
      const div = document.createElement("div");
      div.className = "req" + (typeof e.status === "number" && e.status >= 400 ? " bad" : "");
      const head = document.createElement("div");
      head.className = "req-head";
      head.textContent = `${e.method} ${e.path.split("?")[0]}  ${e.status}  ${e.ms.toFixed(1)} ms`;
      const copy = document.createElement("button");
      copy.textContent = "copy";
      copy.addEventListener("click", () => navigator.clipboard && navigator.clipboard.writeText(e.curl).catch(() => {}));
      head.appendChild(copy);
      const pre = document.createElement("pre");
      pre.textContent = e.curl;
      div.append(head, pre);
      box.appendChild(div);
    }
  }

  let pending = false;
  GX.onRequest(() => {
    // Re-render at most once per frame: pointer moves send many requests.
    if (pending) return;
    pending = true;
    requestAnimationFrame(() => { pending = false; renderLog(); });
  });

  window.addEventListener("DOMContentLoaded", () => {
    document.querySelectorAll("nav button").forEach((b) => b.addEventListener("click", () => showView(b.dataset.view)));
    $("toggle-requests").addEventListener("change", (e) => { $("requests-panel").hidden = !e.target.checked; });
    GX.image.init();
    try { GX.mesh.init(); } catch (e) { GX.fail(e); }
    GX.jobs.init();
    showView("image");
    GX.ready = true;
  });
})();
