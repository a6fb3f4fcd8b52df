//! Admission control, deadlines and liveness under load.

use std::time::{Duration, Instant};

use serde_json::json;

use crate::common::{problem, spawn, TestApp};

/// 50 concurrent solves against a pool of 2 threads admitting 4: every answer
/// is 200 or 503 with Retry-After (none lost, none 500), and `/healthz` keeps
/// answering within 100 ms during the storm.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn storm_of_solves_gets_200_or_503_and_healthz_stays_fast() {
    let app = std::sync::Arc::new(
        spawn(|s| {
            s.pool_threads = Some(2);
            s.queue_capacity = Some(4);
        })
        .await,
    );
    let body = json!({"cost": {"constant": 1.0, "shape": [160, 160]},
        "sources": [{"point": [80.0, 80.0]}], "outputs": {"labels": false}});
    let storm: Vec<_> = (0..50)
        .map(|_| {
            let app = app.clone();
            let body = body.clone();
            tokio::spawn(async move {
                let res = app
                    .client
                    .post(app.url("/v1/grid/distance"))
                    .header("accept", "application/x-npy")
                    .json(&body)
                    .send()
                    .await
                    .expect("every request gets an answer");
                let status = res.status().as_u16();
                let retry = res.headers().get("retry-after").cloned();
                if status == 503 {
                    assert!(retry.is_some(), "503 carries Retry-After");
                    problem(res, 503).await;
                } else {
                    let _ = res.bytes().await;
                }
                status
            })
        })
        .collect();

    let health = {
        let app = app.clone();
        tokio::spawn(async move {
            let client = reqwest::Client::new();
            let mut worst = Duration::ZERO;
            let mut n = 0;
            let started = Instant::now();
            while started.elapsed() < Duration::from_millis(1500) {
                let t = Instant::now();
                let res = client
                    .get(app.url("/healthz"))
                    .send()
                    .await
                    .expect("healthz");
                assert_eq!(res.status(), 200);
                let _ = res.bytes().await;
                worst = worst.max(t.elapsed());
                n += 1;
                tokio::time::sleep(Duration::from_millis(10)).await;
            }
            (worst, n)
        })
    };

    let mut ok = 0;
    let mut busy = 0;
    for h in storm {
        match h.await.expect("join") {
            200 => ok += 1,
            503 => busy += 1,
            other => panic!("unexpected status {other}"),
        }
    }
    assert_eq!(ok + busy, 50);
    assert!(
        ok >= 4,
        "at least the admitted solves succeed ({ok} ok, {busy} busy)"
    );
    let (worst, n) = health.await.expect("join");
    assert!(n >= 10, "{n} health checks");
    assert!(
        worst < Duration::from_millis(100),
        "worst healthz round trip {worst:?}"
    );
}

/// A solve past its deadline is cancelled (504), and the pool then serves the
/// next request.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_solve_past_its_deadline_is_cancelled_and_the_pool_recovers() {
    let app = spawn(|s| {
        s.pool_threads = Some(1);
        s.queue_capacity = Some(1);
        s.request_timeout_secs = 0.05;
    })
    .await;
    let big = json!({"cost": {"constant": 1.0, "shape": [3000, 3000]},
        "sources": [{"point": [1500.0, 1500.0]}]});
    let res = app
        .client
        .post(app.url("/v1/grid/distance"))
        .json(&big)
        .send()
        .await
        .expect("post");
    let v = problem(res, 504).await;
    assert_eq!(v["type"], "https://geodex.dev/problems/deadline-exceeded");

    // The cancelled solve frees its slot as soon as the solver notices; until
    // then the pool (capacity 1) may still answer 503.
    let last = status_once_a_slot_is_free(&app).await;
    assert_eq!(last, 200, "the pool serves the next request");
}

/// A client that gives up (disconnects) cancels its solve: the solve stops
/// long before it would have finished (its recorded run time, outcome
/// `cancelled`, is a fraction of the same solve run to completion), and the
/// single pool slot becomes free again.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_disconnected_client_cancels_its_solve() {
    let app = spawn(|s| {
        s.pool_threads = Some(1);
        s.queue_capacity = Some(1);
    })
    .await;
    let big = json!({"cost": {"constant": 1.0, "shape": [2000, 2000]},
        "sources": [{"point": [1500.0, 1500.0]}], "outputs": {"labels": false}});
    // The same solve, run to completion: how long it takes on this machine.
    let res = app
        .client
        .post(app.url("/v1/grid/distance"))
        .json(&big)
        .send()
        .await
        .expect("post");
    assert_eq!(res.status(), 200);
    let full: serde_json::Value = res.json().await.expect("json");
    let full_seconds = full["stats"]["solve_seconds"]
        .as_f64()
        .expect("solve_seconds");

    // The metric is process-wide (other tests cancel grid.distance solves
    // too): count only what this abandoned solve adds to it.
    let before = cancelled_distance_seconds(&app).await.unwrap_or(0.0);
    let impatient = reqwest::Client::builder()
        .timeout(Duration::from_millis(100))
        .build()
        .expect("client");
    let err = impatient
        .post(app.url("/v1/grid/distance"))
        .json(&big)
        .send()
        .await;
    assert!(err.is_err(), "the client timed out");
    let last = status_once_a_slot_is_free(&app).await;
    assert_eq!(last, 200, "the slot was freed by the disconnect");

    // The pool recorded the abandoned solve as cancelled, with a run time
    // well below the full solve's: it stopped, it did not run to the end.
    let cancelled = cancelled_distance_seconds(&app)
        .await
        .expect("a cancelled grid.distance solve in /metrics")
        - before;
    assert!(
        cancelled < 0.5 * full_seconds,
        "the cancelled solve ran {cancelled} s, the full one {full_seconds} s"
    );
}

/// `geodex_solve_seconds_sum` of cancelled grid.distance solves, if any.
async fn cancelled_distance_seconds(app: &TestApp) -> Option<f64> {
    let metrics = app
        .client
        .get(app.url("/metrics"))
        .send()
        .await
        .expect("metrics")
        .text()
        .await
        .expect("text");
    metrics
        .lines()
        .find(|l| {
            l.starts_with("geodex_solve_seconds_sum{")
                && l.contains("operation=\"grid.distance\"")
                && l.contains("outcome=\"cancelled\"")
        })
        .and_then(|l| l.rsplit(' ').next())
        .and_then(|v| v.parse::<f64>().ok())
}

/// Posts a tiny solve every 20 ms (at most 500 times) until the pool stops
/// answering 503, and returns the first other status.
async fn status_once_a_slot_is_free(app: &TestApp) -> u16 {
    let small = json!({"cost": {"constant": 1.0, "shape": [8, 8]},
        "sources": [{"point": [1.0, 1.0]}]});
    let mut last = 0;
    for _ in 0..500 {
        let res = app
            .client
            .post(app.url("/v1/grid/distance"))
            .json(&small)
            .send()
            .await
            .expect("post");
        last = res.status().as_u16();
        if last != 503 {
            break;
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    last
}
