//! Durable jobs on the embedded default (SQLite + local result files), with
//! the real binary: a crash with SIGKILL and a restart, idempotency, time
//! limits, progress, cancellation, `Prefer: respond-async`, listing.

mod jobs_support;

use std::time::{Duration, Instant};

use geodex::io::{self, ArrayData};
use jobs_support::{assert_same, attempt_dirs, compute, request, wavy_cost, Server, N};
use serde_json::{json, Value};

const FAST: &[&str] = &[
    "--pool-threads",
    "2",
    "--job-lease-secs",
    "1.5",
    "--job-poll-ms",
    "100",
];

/// 20 jobs; SIGKILL while some run; restart on the same directory: every job
/// ends `succeeded` once, equal to the synchronous computation.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sqlite_jobs_survive_sigkill_and_restart() {
    let dir = tempfile::tempdir().expect("tempdir");
    let cost = wavy_cost(N);
    let mut a = Server::start(dir.path(), "a", FAST).await;
    let cost_id = a.upload(&ArrayData::F64(cost.clone())).await;
    let mut ids = Vec::new();
    let mut params = Vec::new();
    for k in 0..20 {
        let p = request(&cost_id, k, N);
        ids.push(
            a.submit(&json!({"operation": "grid.distance", "params": p}))
                .await,
        );
        params.push(p);
    }
    // Kill once some jobs run and most are still queued.
    let t = Instant::now();
    loop {
        let running = a.get_json("/v1/jobs?state=running").await["jobs"]
            .as_array()
            .map_or(0, Vec::len);
        if running > 0 {
            break;
        }
        assert!(t.elapsed() < Duration::from_secs(30), "no job started");
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    tokio::time::sleep(Duration::from_millis(100)).await;
    a.kill();

    // The references, computed while the restarted server works.
    let refs = {
        let params = params.clone();
        let cost = cost.clone();
        let cost_id = cost_id.clone();
        tokio::task::spawn_blocking(move || {
            params
                .iter()
                .map(|p| compute(p, &cost_id, &cost))
                .collect::<Vec<_>>()
        })
    };
    let b = Server::start(dir.path(), "b", FAST).await;
    let mut rerun = 0;
    for id in &ids {
        let j = b.wait_final(id, Duration::from_secs(90)).await;
        assert_eq!(j["state"], "succeeded", "{j}\n{}", b.log_text());
        assert_eq!(j["progress"], 1.0);
        let attempts = j["attempts"].as_i64().expect("attempts");
        assert!((1..=2).contains(&attempts), "{j}");
        if attempts == 2 {
            rerun += 1;
        }
        assert!(j["result"]["distance"]["url"].is_string(), "{j}");
    }
    assert!(rerun >= 1, "the jobs running at the kill ran again");
    let refs = refs.await.expect("references");
    for (k, id) in ids.iter().enumerate() {
        let got = b.result(id, "distance").await;
        assert_same(&got, &refs[k], id);
        if k == 0 {
            // As for datasets: `?dtype=f32` sends the result in single precision.
            let r = b
                .get(&format!("/v1/jobs/{id}/results/distance?dtype=f32"))
                .await;
            assert_eq!(r.status(), 200);
            let bytes = r.bytes().await.expect("bytes");
            let single = io::decode(&bytes, Some(io::Format::Npy), &io::Limits::default())
                .expect("npy")
                .array;
            let (ArrayData::F32(single), ArrayData::F64(full)) = (&single, &got) else {
                panic!("{:?} / {:?}", single.dtype(), got.dtype())
            };
            assert!(single.iter().zip(full.iter()).all(|(s, d)| *s == *d as f32));
        }
        // One result per job: objects of the killed attempt were removed.
        assert_eq!(attempt_dirs(&dir.path().join("results"), id), 1, "{id}");
    }
}

async fn problem(r: reqwest::Response, status: u16) -> Value {
    assert_eq!(r.status(), status);
    assert_eq!(
        r.headers()
            .get("content-type")
            .and_then(|v| v.to_str().ok()),
        Some("application/problem+json")
    );
    r.json().await.expect("problem")
}

/// Idempotency, validation at submit, time limit, progress, cancellation of
/// queued and running jobs, `Prefer: respond-async`, listing.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sqlite_job_api() {
    let dir = tempfile::tempdir().expect("tempdir");
    let s = Server::start(
        dir.path(),
        "api",
        &[
            "--pool-threads",
            "1",
            "--job-workers",
            "1",
            "--job-poll-ms",
            "50",
        ],
    )
    .await;
    let small =
        json!({"cost": {"constant": 1.0, "shape": [40, 40]}, "sources": [{"point": [3.0, 4.0]}]});

    // Idempotency: the same key twice gives one job; another body is refused.
    let body = json!({"operation": "grid.distance", "params": small});
    let key = [("Idempotency-Key", "k-123")];
    let r1 = s.post_json("/v1/jobs", &body, &key).await;
    assert_eq!(r1.status(), 202);
    let j1: Value = r1.json().await.expect("json");
    let r2 = s.post_json("/v1/jobs", &body, &key).await;
    assert_eq!(r2.status(), 202);
    assert_eq!(
        r2.headers()
            .get("idempotent-replayed")
            .and_then(|v| v.to_str().ok()),
        Some("true")
    );
    let j2: Value = r2.json().await.expect("json");
    assert_eq!(j1["id"], j2["id"]);
    let other = json!({"operation": "grid.distance", "params": {"cost": {"constant": 2.0, "shape": [40, 40]}, "sources": [{"point": [3.0, 4.0]}]}});
    let p = problem(s.post_json("/v1/jobs", &other, &key).await, 422).await;
    assert_eq!(p["field"], "Idempotency-Key");
    let all = s.get_json("/v1/jobs?limit=1000").await;
    assert_eq!(all["jobs"].as_array().map(Vec::len), Some(1), "{all}");
    let done = s
        .wait_final(j1["id"].as_str().expect("id"), Duration::from_secs(30))
        .await;
    assert_eq!(done["state"], "succeeded", "{done}");
    assert_eq!(done["attempts"], 1);
    // The 40x40 constant-cost distance from (3, 4): at (3, 30) it is 26 (a straight axis line).
    let got = s.result(done["id"].as_str().expect("id"), "distance").await;
    let d = got.get_f64(3 * 40 + 30).expect("cell");
    assert!((d - 26.0).abs() < 1e-9, "{d}");

    // Validation happens at submit and names the field.
    let bad = json!({"operation": "grid.distance", "params": {"cost": {"constant": -1.0, "shape": [8, 8]}, "sources": [{"point": [1.0, 1.0]}]}});
    assert_eq!(
        problem(s.post_json("/v1/jobs", &bad, &[]).await, 422).await["field"],
        "params.cost.constant"
    );
    let bad = json!({"operation": "grid.nope", "params": {}});
    assert_eq!(
        problem(s.post_json("/v1/jobs", &bad, &[]).await, 422).await["field"],
        "operation"
    );
    let bad = json!({"operation": "grid.distance", "params": {"cost": {"dataset": "ds_0192f1b27c1e7d3a9d553c0f2b8a1e44"}, "sources": [{"point": [1.0, 1.0]}]}});
    assert_eq!(
        problem(s.post_json("/v1/jobs", &bad, &[]).await, 404).await["field"],
        "params.cost.dataset"
    );
    let bad = json!({"operation": "grid.distance", "params": small, "time_limit_secs": -1});
    assert_eq!(
        problem(s.post_json("/v1/jobs", &bad, &[]).await, 422).await["field"],
        "time_limit_secs"
    );
    problem(
        s.get("/v1/jobs/job_0192f1b27c1e7d3a9d553c0f2b8a1e44").await,
        404,
    )
    .await;
    problem(s.get("/v1/jobs?limit=0").await, 422).await;

    // Time limit: a large solve with a 0.3 s limit ends failed, with a clear problem.
    let big = json!({"cost": {"constant": 1.0, "shape": [3000, 3000]}, "sources": [{"point": [1.0, 1.0]}], "outputs": {"labels": false}});
    let id = s
        .submit(&json!({"operation": "grid.distance", "params": big, "time_limit_secs": 0.3}))
        .await;
    let t = Instant::now();
    let j = s.wait_final(&id, Duration::from_secs(30)).await;
    assert!(t.elapsed() < Duration::from_secs(10), "{:?}", t.elapsed());
    assert_eq!(j["state"], "failed", "{j}");
    assert_eq!(j["error"]["type"], "https://geodex.dev/problems/time-limit");
    assert_eq!(j["error"]["field"], "time_limit_secs");
    assert!(
        j["error"]["detail"]
            .as_str()
            .is_some_and(|d| d.contains("0.3 s")),
        "{j}"
    );
    assert!(j["progress"].as_f64().is_some_and(|p| p < 1.0));
    problem(s.get(&format!("/v1/jobs/{id}/results/distance")).await, 409).await;

    // Progress goes from 0 to 1, never backwards.
    let mid = json!({"cost": {"constant": 1.0, "shape": [900, 900]}, "sources": [{"point": [1.0, 1.0]}], "outputs": {"labels": false}});
    let id = s
        .submit(&json!({"operation": "grid.distance", "params": mid}))
        .await;
    let mut seen = Vec::new();
    let t = Instant::now();
    let last = loop {
        let j = s.job(&id).await;
        seen.push(j["progress"].as_f64().expect("progress"));
        if j["state"] == "succeeded" {
            break j;
        }
        assert!(t.elapsed() < Duration::from_secs(60), "{j}");
        tokio::time::sleep(Duration::from_millis(20)).await;
    };
    assert_eq!(seen.first().copied(), Some(0.0), "{seen:?}");
    assert_eq!(last["progress"], 1.0);
    assert!(seen.windows(2).all(|w| w[0] <= w[1]), "{seen:?}");
    assert!(
        seen.iter().any(|p| *p > 0.0 && *p < 1.0),
        "an intermediate value: {seen:?}"
    );

    // Cancellation: a running job stops within a second; a queued one never starts.
    let long = json!({"cost": {"constant": 1.0, "shape": [4000, 4000]}, "sources": [{"point": [1.0, 1.0]}], "outputs": {"labels": false}});
    let running = s
        .submit(&json!({"operation": "grid.distance", "params": long}))
        .await;
    let queued = s
        .submit(&json!({"operation": "grid.distance", "params": small, "priority": "batch"}))
        .await;
    let t = Instant::now();
    // Running, and the solver loop started (it reports progress).
    while s.job(&running).await["progress"].as_f64().unwrap_or(0.0) <= 0.0 {
        assert!(t.elapsed() < Duration::from_secs(30));
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    let r = s
        .post_json(&format!("/v1/jobs/{queued}/cancel"), &json!({}), &[])
        .await;
    assert_eq!(r.status(), 200);
    let q: Value = r.json().await.expect("json");
    assert_eq!(q["state"], "cancelled");
    let asked = Instant::now();
    let r = s
        .post_json(&format!("/v1/jobs/{running}/cancel"), &json!({}), &[])
        .await;
    assert_eq!(r.status(), 202);
    let j = s.wait_final(&running, Duration::from_secs(5)).await;
    let took = asked.elapsed();
    assert_eq!(j["state"], "cancelled", "{j}");
    assert!(took < Duration::from_secs(1), "stopped after {took:?}");
    assert_eq!(j["error"]["type"], "https://geodex.dev/problems/cancelled");
    tokio::time::sleep(Duration::from_millis(300)).await;
    let q = s.job(&queued).await;
    assert_eq!(q["state"], "cancelled");
    assert_eq!(q["attempts"], 0, "never started: {q}");
    assert!(q.get("started_at").is_none(), "{q}");
    problem(
        s.post_json(
            &format!("/v1/jobs/{}/cancel", j1["id"].as_str().expect("id")),
            &json!({}),
            &[],
        )
        .await,
        409,
    )
    .await;

    // Prefer: respond-async on the synchronous endpoint.
    let r = s
        .post_json("/v1/grid/distance", &small, &[("Prefer", "respond-async")])
        .await;
    assert_eq!(r.status(), 202);
    let loc = r
        .headers()
        .get("location")
        .and_then(|v| v.to_str().ok())
        .map(str::to_string);
    assert!(r.headers().contains_key("retry-after"));
    let j: Value = r.json().await.expect("json");
    assert_eq!(j["priority"], "interactive");
    assert_eq!(
        loc,
        Some(format!("/v1/jobs/{}", j["id"].as_str().expect("id")))
    );
    let j = s
        .wait_final(j["id"].as_str().expect("id"), Duration::from_secs(30))
        .await;
    assert_eq!(j["state"], "succeeded");
    let got = s.result(j["id"].as_str().expect("id"), "distance").await;
    let want = compute(&small, "none", &wavy_cost(2));
    assert_same(&got, &want, "respond-async");

    // Listing with a filter and a cursor.
    let page = s.get_json("/v1/jobs?state=succeeded&limit=1").await;
    assert_eq!(page["jobs"].as_array().map(Vec::len), Some(1));
    let cursor = page["next_cursor"].as_str().expect("cursor").to_string();
    let page2 = s
        .get_json(&format!(
            "/v1/jobs?state=succeeded&limit=10&cursor={cursor}"
        ))
        .await;
    let n2 = page2["jobs"].as_array().map_or(0, Vec::len);
    assert_eq!(n2, 2, "{page2}");
    assert!(page2.get("next_cursor").is_none());
    let metrics = s.get("/metrics").await.text().await.expect("metrics");
    assert!(
        metrics.contains("geodex_job_run_seconds_bucket"),
        "{metrics}"
    );
    assert!(metrics.contains("geodex_job_failures_total"), "{metrics}");
}

/// Retention: an ended job and its result files are removed once it expires.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sqlite_jobs_expire_with_their_results() {
    let dir = tempfile::tempdir().expect("tempdir");
    let s = Server::start(
        dir.path(),
        "retention",
        &["--pool-threads", "1", "--job-retention-secs", "1"],
    )
    .await;
    let small =
        json!({"cost": {"constant": 1.0, "shape": [20, 20]}, "sources": [{"point": [3.0, 4.0]}]});
    let id = s
        .submit(&json!({"operation": "grid.distance", "params": small}))
        .await;
    let j = s.wait_final(&id, Duration::from_secs(30)).await;
    assert_eq!(j["state"], "succeeded", "{j}");
    assert_eq!(attempt_dirs(&dir.path().join("results"), &id), 1);
    let t = Instant::now();
    loop {
        let r = s.get(&format!("/v1/jobs/{id}")).await;
        if r.status() == 404 {
            break;
        }
        assert!(t.elapsed() < Duration::from_secs(10), "job not swept");
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    assert_eq!(attempt_dirs(&dir.path().join("results"), &id), 0);
}
