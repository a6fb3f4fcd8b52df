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

  /**
   * Shows the newest 14 requests. Each row is rebuilt only when its request
   * changed: a pointer move replaces the top row's text, not the whole list,
   * so that the frame that draws the new path does no extra layout.
   */
  function renderLog() {
    const box = $("requests");
    const shown = GX.requestLog.slice(0, 14);
    shown.forEach((e, i) => {
      let div = box.children[i];
      if (!div) {
        div = document.createElement("div");
        const head = document.createElement("div");
        head.className = "req-head";
        const title = document.createElement("span");
        const copy = document.createElement("button");
        copy.textContent = "copy";
        copy.addEventListener("click", () => navigator.clipboard && navigator.clipboard.writeText(div.curl).catch(() => {}));
        head.append(title, copy);
        div.append(head, document.createElement("pre"));
        box.appendChild(div);
      }
      const title = `${e.method} ${e.path.split("?")[0]}  ${e.status}  ${e.ms.toFixed(1)} ms`;
      if (div.title_ === title && div.curl === e.curl) return;
      div.className = "req" + (typeof e.status === "number" && e.status >= 400 ? " bad" : "");
      div.firstChild.firstChild.textContent = title;
      div.lastChild.textContent = e.curl;
      div.title_ = title;
      div.curl = e.curl;
    });
    while (box.children.length > shown.length) box.lastChild.remove();
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
