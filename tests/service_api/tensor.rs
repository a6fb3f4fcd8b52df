//! `POST /v1/grid/tensor-distance` and `/v1/grid/tensor-metric`: the
//! anisotropic operations over HTTP, and their 4xx answers.

use geodex::io::ArrayData;
use ndarray::{ArrayD, IxDyn};
use serde_json::json;

use crate::common::{problem, spawn};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tensor_distance_of_a_constant_metric_is_exact_and_paths_reach_the_source() {
    let app = spawn(|_| {}).await;
    // M = diag(1, 100) on 41 × 41: U = sqrt(dx² + 100 dy²) from (20, 20).
    let res = app
        .client
        .post(app.url("/v1/grid/tensor-distance"))
        .json(&json!({
            "metric": {"kind": "eigen", "shape": [41, 41], "eigenvalues": [1.0, 100.0], "direction": [1.0, 0.0]},
            "sources": [{"point": [20.0, 20.0]}],
            "ends": [[35.0, 24.0]]
        }))
        .send()
        .await
        .expect("post");
    assert_eq!(res.status(), 200);
    let body: serde_json::Value = res.json().await.expect("json");
    assert_eq!(body["stats"]["stop"], "completed");
    assert_eq!(body["stats"]["cells"], 1681);
    assert!((body["stats"]["max_anisotropy"].as_f64().unwrap() - 10.0).abs() < 1e-9);
    assert_eq!(body["distance"]["shape"], json!([41, 41]));
    let path = &body["paths"][0];
    assert_eq!(path["source"], 0);
    assert_eq!(path["end"], json!([35.0, 24.0]));
    let exact = (15.0f64 * 15.0 + 100.0 * 16.0).sqrt();
    let len = path["geodesic_length"].as_f64().unwrap();
    assert!(
        (len - exact).abs() < 0.05 * exact,
        "path length {len} vs {exact}"
    );
    // From the source to the end.
    let first = path["points"][0].clone();
    let (l0, l1) = (first[0].as_f64().unwrap(), first[1].as_f64().unwrap());
    assert!(
        (l0 - 20.0).abs() <= 1.0 && (l1 - 20.0).abs() <= 1.0,
        "{first}"
    );

    // The stored distance map agrees along the cheap axis exactly.
    let url = body["distance"]["data_url"].as_str().unwrap();
    let res = app.get(&format!("{url}?format=json")).await;
    assert_eq!(res.status(), 200);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tensor_datasets_round_trip_through_tensor_metric() {
    let app = spawn(|_| {}).await;
    let res = app
        .client
        .post(app.url("/v1/grid/tensor-metric"))
        .json(&json!({
            "metric": {"kind": "energy_anisotropy", "shape": [16, 16], "energy": 2.0, "anisotropy": 0.5, "angle": 0.0}
        }))
        .send()
        .await
        .expect("post");
    assert_eq!(res.status(), 200);
    let body: serde_json::Value = res.json().await.expect("json");
    assert_eq!(body["tensor"]["shape"], json!([16, 16, 3]));
    assert!((body["stats"]["max_anisotropy"].as_f64().unwrap() - 3f64.sqrt()).abs() < 1e-9);
    let id = body["tensor"]["id"].as_str().unwrap().to_string();
    // The stored field feeds a distance request.
    let res = app
        .client
        .post(app.url("/v1/grid/tensor-distance"))
        .json(&json!({"metric": {"kind": "components", "dataset": id}, "sources": [{"point": [3.0, 3.0]}]}))
        .send()
        .await
        .expect("post");
    assert_eq!(res.status(), 200);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_tensors_are_4xx_naming_the_field_and_the_first_bad_cell() {
    let app = spawn(|_| {}).await;
    // Not positive definite at cell (2, 1).
    let mut t = ArrayD::from_shape_fn(IxDyn(&[4, 5, 3]), |ix| if ix[2] == 1 { 0.0 } else { 1.0 });
    t[[2, 1, 1]] = 3.0;
    t[[3, 4, 0]] = f64::NAN;
    let id = app.upload(&ArrayData::F64(t)).await;
    let res = app
        .client
        .post(app.url("/v1/grid/tensor-distance"))
        .json(&json!({"metric": {"kind": "components", "dataset": id}, "sources": [{"point": [0.0, 0.0]}]}))
        .send()
        .await
        .expect("post");
    let p = problem(res, 422).await;
    assert_eq!(p["field"], "metric.dataset");
    assert!(p["detail"].as_str().unwrap().contains("[2, 1]"), "{p}");

    // A dataset without a component axis.
    let id = app
        .upload(&ArrayData::F64(ArrayD::zeros(IxDyn(&[4, 5]))))
        .await;
    let res = app
        .client
        .post(app.url("/v1/grid/tensor-distance"))
        .json(&json!({"metric": {"kind": "components", "dataset": id}, "sources": [{"point": [0.0, 0.0]}]}))
        .send()
        .await
        .expect("post");
    assert_eq!(problem(res, 422).await["field"], "metric.dataset");

    // A constant that is not positive definite, an anisotropy of 1, an unknown kind.
    for (body, field) in [
        (
            json!({"metric": {"kind": "constant", "shape": [8, 8], "components": [1.0, 2.0, 1.0]}, "sources": [{"point": [0.0, 0.0]}]}),
            "metric.components",
        ),
        (
            json!({"metric": {"kind": "energy_anisotropy", "shape": [8, 8], "anisotropy": 1.0}, "sources": [{"point": [0.0, 0.0]}]}),
            "metric.anisotropy",
        ),
        (
            json!({"metric": {"kind": "eigen", "shape": [8, 8], "eigenvalues": [1.0, -1.0], "direction": [1.0, 0.0]}, "sources": [{"point": [0.0, 0.0]}]}),
            "metric.eigenvalues",
        ),
        (
            json!({"metric": {"kind": "eigen", "shape": [8, 8], "eigenvalues": [1.0, 4.0], "direction": [1.0, 0.0]}, "sources": [{"point": [9.0, 0.0]}]}),
            "sources[0]",
        ),
    ] {
        let res = app
            .client
            .post(app.url("/v1/grid/tensor-distance"))
            .json(&body)
            .send()
            .await
            .expect("post");
        let p = problem(res, 422).await;
        assert_eq!(p["field"], field, "{p}");
    }
    let res = app
        .client
        .post(app.url("/v1/grid/tensor-distance"))
        .json(&json!({"metric": {"kind": "nope"}, "sources": [{"point": [0.0, 0.0]}]}))
        .send()
        .await
        .expect("post");
    assert!(res.status().is_client_error());
    // An unknown dataset is a 404.
    let res = app
        .client
        .post(app.url("/v1/grid/tensor-distance"))
        .json(&json!({"metric": {"kind": "height_map", "heights": "ds_missing"}, "sources": [{"point": [0.0, 0.0]}]}))
        .send()
        .await
        .expect("post");
    assert_eq!(problem(res, 404).await["field"], "metric.heights");
}
