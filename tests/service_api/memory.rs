//! Admission by estimated peak memory (`--solve-memory-bytes`): a solve or
//! an upload whose estimate is larger than the whole budget is a 413 that
//! names the flag, before anything is allocated; one that fits is served.

use geodex::io::ArrayData;
use serde_json::json;

use crate::common::{problem, spawn, wavy_cost};

#[tokio::test]
async fn solves_and_uploads_are_admitted_by_their_estimated_memory() {
    // 4 MB: a 100 x 100 solve (about 1 MB) fits, a 400 x 400 one (about
    // 16 MB) never does.
    let app = spawn(|s| s.solve_memory_bytes = Some(4 << 20)).await;
    let small =
        json!({"cost": {"constant": 1.0, "shape": [100, 100]}, "sources": [{"point": [5, 5]}]});
    let res = app
        .client
        .post(app.url("/v1/grid/distance"))
        .json(&small)
        .send()
        .await
        .expect("send");
    assert_eq!(res.status(), 200);
    let big =
        json!({"cost": {"constant": 1.0, "shape": [400, 400]}, "sources": [{"point": [5, 5]}]});
    let res = app
        .client
        .post(app.url("/v1/grid/distance"))
        .json(&big)
        .send()
        .await
        .expect("send");
    let p = problem(res, 413).await;
    assert!(
        p["detail"]
            .as_str()
            .is_some_and(|d| d.contains("--solve-memory-bytes")),
        "{p}"
    );
    // An upload is admitted by the size its header declares: a 300 x 300
    // f64 array (0.7 MB on the wire, three times that held while decoding
    // and storing, plus the body) fits in 4 MB; 800 x 800 (5.1 MB) does not.
    let fits = app.upload(&ArrayData::F64(wavy_cost(300, 300))).await;
    assert!(fits.starts_with("ds_"));
    let body = geodex::io::encode_npy(&ArrayData::F64(wavy_cost(800, 800))).expect("npy");
    let res = app
        .client
        .post(app.url("/v1/datasets"))
        .header("content-type", "application/x-npy")
        .body(body)
        .send()
        .await
        .expect("send");
    problem(res, 413).await;
    // Nothing stays held, and `/readyz` (auth off: every figure shown)
    // reports the budget and what is held against it.
    let ready: serde_json::Value = app.get("/readyz").await.json().await.expect("json");
    assert_eq!(ready["status"], "ready");
    assert_eq!(ready["solve_memory_budget_bytes"], 4 << 20, "{ready}");
    assert_eq!(ready["solve_memory_held_bytes"], 0, "{ready}");
    assert!(
        ready["cache_budget_bytes"].as_u64().is_some_and(|b| b > 0),
        "{ready}"
    );
    assert!(ready["cache_bytes"].as_u64().is_some(), "{ready}");
}
