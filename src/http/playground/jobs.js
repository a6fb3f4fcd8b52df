// The jobs view: a long run goes through the durable queue (POST /v1/jobs),
// its progress is polled (GET /v1/jobs/{id}) into a progress bar, and it can
// be cancelled (POST /v1/jobs/{id}/cancel). The result is shown as a picture.
"use strict";
window.GX = window.GX || {};

(function () {
  const $ = (id) => document.getElementById(id);
  const J = { job: null, timer: null };
  GX.jobState = J;

  function params() {
    const which = $("job-kind").value;
    const n = Number($("job-size").value);
    if (which === "image") {
      if (!GX.imageState.image) throw new Error("load an image in the Image view first");
      const [h, w] = GX.imageState.image.shape;
      return { operation: "grid.distance", params: { ...GX.image.metricSection(), sources: [{ point: [h / 2, w / 2] }] } };
    }
    return { operation: "grid.distance", params: { cost: { constant: 1, shape: [n, n] }, sources: [{ point: [n / 3, n / 2] }, { point: [0.8 * n, 0.2 * n] }], order: 2 } };
  }

  async function submit() {
    const body = { ...params(), priority: "interactive", time_limit_secs: 600 };
    const job = await GX.api("POST", "/v1/jobs", { json: body });
    J.job = job;
    $("job-result").removeAttribute("src");
    $("job-cancel").disabled = false;
    show(job);
    poll();
  }

  function show(job) {
    $("job-bar").value = job.progress || 0;
    $("job-state").textContent = `${job.id}: ${job.state}, ${(100 * (job.progress || 0)).toFixed(0)} %` + (job.error ? ` (${job.error.detail || job.error.title})` : "");
  }

  function poll() {
    clearTimeout(J.timer);
    J.timer = setTimeout(async () => {
      try {
        const job = await GX.api("GET", "/v1/jobs/" + J.job.id, { key: "job-poll" });
        J.job = job;
        show(job);
        if (job.state === "queued" || job.state === "running") { poll(); return; }
        $("job-cancel").disabled = true;
        if (job.state === "succeeded" && job.result && job.result.distance) {
          $("job-result").src = await GX.src(job.result.distance.url + "?format=png");
          GX.status(`job ${job.id} succeeded: ${JSON.stringify(job.result.stats || {})}`);
        }
        list();
      } catch (e) { GX.fail(e); }
    }, 200);
  }

  async function cancel() {
    if (!J.job) return;
    const job = await GX.api("POST", `/v1/jobs/${J.job.id}/cancel`, {});
    show(job);
  }

  async function list() {
    const r = await GX.api("GET", "/v1/jobs?limit=8", { key: "job-list" });
    const rows = (r.jobs || r.items || []).map((j) => `<tr><td>${j.id}</td><td>${j.operation}</td><td>${j.state}</td><td>${(100 * j.progress).toFixed(0)} %</td></tr>`);
    $("job-list").innerHTML = "<table><tr><th>job</th><th>operation</th><th>state</th><th>progress</th></tr>" + rows.join("") + "</table>";
  }

  function init() {
    $("job-submit").addEventListener("click", () => submit().catch(GX.fail));
    $("job-cancel").addEventListener("click", () => cancel().catch(GX.fail));
    $("job-size").addEventListener("input", () => { $("job-size-out").textContent = $("job-size").value + "²"; });
  }

  GX.jobs = { init, list, submit, cancel };
})();
