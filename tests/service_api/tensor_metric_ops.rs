//! `metric: {"kind": ...}` (a tensor field) on `grid.distance`,
//! `grid.segment` and `grid.paths` over HTTP: the anisotropic solver and
//! descent behind the isotropic endpoints, and their 422 answers.

use geodex::io::ArrayData;
use ndarray::{ArrayD, IxDyn};
use serde_json::json;

use crate::common::{problem, spawn, TestApp};

async fn post(app: &TestApp, path: &str, body: serde_json::Value) -> reqwest::Response {
    app.client
        .post(app.url(path))
        .json(&body)
        .send()
        .await
        .expect("post")
}

/// The values of a result array, as f64, fetched as NPY.
async fn fetch(app: &TestApp, reference: &serde_json::Value) -> Vec<f64> {
    let url = format!(
        "{}?format=npy",
        reference["data_url"].as_str().expect("data_url")
    );
    let bytes = app.get(&url).await.bytes().await.expect("bytes");
    let array = geodex::io::decode(&bytes, None, &geodex::io::Limits::default())
        .expect("decode")
        .array;
    (0..array.len())
        .map(|i| array.get_f64(i).expect("number"))
        .collect()
}

/// `M = λ1 e1e1ᵀ + λ2 (Id − e1e1ᵀ)` with `e1` at `theta` from axis 0: `[m00, m01, m11]`.
fn eigen2(l1: f64, l2: f64, theta: f64) -> [f64; 3] {
    let (c, s) = (theta.cos(), theta.sin());
    [
        l1 * c * c + l2 * s * s,
        (l1 - l2) * c * s,
        l1 * s * s + l2 * c * c,
    ]
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn distance_with_a_constant_tensor_metric_is_the_exact_riemannian_distance() {
    let app = spawn(|_| {}).await;
    let n = 61;
    let (s0, s1) = (30.0, 30.0);
    // Anisotropy ratio 5, cheap direction at 30° from axis 0.
    let m = eigen2(1.0, 25.0, std::f64::consts::PI / 6.0);
    let res = post(
        &app,
        "/v1/grid/distance",
        json!({
            "metric": {"kind": "constant", "shape": [n, n], "components": m},
            "sources": [{"point": [s0, s1]}],
        }),
    )
    .await;
    assert_eq!(res.status(), 200);
    let body: serde_json::Value = res.json().await.expect("json");
    assert_eq!(body["stats"]["stop"], "completed");
    assert!((body["stats"]["max_anisotropy"].as_f64().expect("ratio") - 5.0).abs() < 1e-9);
    let u = fetch(&app, &body["distance"]).await;
    assert_eq!(u.len(), n * n);
    let mut worst: f64 = 0.0;
    for i in 0..n {
        for j in 0..n {
            let (a, b) = (i as f64 - s0, j as f64 - s1);
            let exact = (m[0] * a * a + 2.0 * m[1] * a * b + m[2] * b * b).sqrt();
            if exact < 5.0 {
                continue;
            }
            worst = worst.max((u[i * n + j] - exact).abs() / exact);
        }
    }
    assert!(worst < 0.03, "relative max error {worst}");
    // The isotropic answer on the same grid is far from it: the metric was used.
    let iso = post(
        &app,
        "/v1/grid/distance",
        json!({"cost": {"constant": 1.0, "shape": [n, n]}, "sources": [{"point": [s0, s1]}]}),
    )
    .await;
    let body: serde_json::Value = iso.json().await.expect("json");
    let v = fetch(&app, &body["distance"]).await;
    let far = 50 * n + 30; // (50, 30): 20 cells along axis 0.
    assert!(u[far] > 1.5 * v[far], "{} vs {}", u[far], v[far]);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn segment_with_a_needle_metric_moves_the_voronoi_boundary() {
    let app = spawn(|_| {}).await;
    let n = 41;
    let seeds = json!([
        {"label": 1, "point": [5.0, 20.0]},
        {"label": 2, "point": [20.0, 8.0]}
    ]);
    let iso = post(
        &app,
        "/v1/grid/segment",
        json!({"cost": {"constant": 1.0, "shape": [n, n]}, "seeds": seeds, "contours": false}),
    )
    .await;
    assert_eq!(iso.status(), 200);
    let iso: serde_json::Value = iso.json().await.expect("json");
    let iso_labels = fetch(&app, &iso["labels"]).await;
    // Needle metric: moving along axis 0 costs 1, across it 10 (ratio 10).
    let res = post(
        &app,
        "/v1/grid/segment",
        json!({
            "metric": {"kind": "eigen", "shape": [n, n], "eigenvalues": [1.0, 100.0], "direction": [1.0, 0.0]},
            "seeds": seeds,
            "contours": false
        }),
    )
    .await;
    assert_eq!(res.status(), 200);
    let body: serde_json::Value = res.json().await.expect("json");
    let labels = fetch(&app, &body["labels"]).await;
    // (35, 20): Euclidean 30 from seed 1 and 19.2 from seed 2; under M it is
    // 30 from seed 1 (along the needle) and sqrt(15² + 100·12²) = 121 from seed 2.
    let p = 35 * n + 20;
    assert_eq!(iso_labels[p], 2.0);
    assert_eq!(labels[p], 1.0);
    // Each seed keeps its own cell, and the anisotropic distance is the exact one there.
    assert_eq!(labels[5 * n + 20], 1.0);
    assert_eq!(labels[20 * n + 8], 2.0);
    let d = fetch(&app, &body["distance"]).await;
    assert!((d[p] - 30.0).abs() < 0.6, "{}", d[p]);
    let differ = labels
        .iter()
        .zip(&iso_labels)
        .filter(|(a, b)| a != b)
        .count();
    assert!(differ > 100, "only {differ} cells changed label");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn paths_with_a_tensor_metric_follow_the_straight_riemannian_geodesic() {
    let app = spawn(|_| {}).await;
    // Cheap along (1, 1) (eigenvalue 1), expensive across (16): ratio 4.
    let m = eigen2(1.0, 16.0, std::f64::consts::FRAC_PI_4);
    let request = json!({
        "metric": {"kind": "constant", "shape": [51, 51], "components": m},
        "sources": [{"point": [10.0, 12.0]}],
        "ends": [[40.0, 30.0]]
    });
    let res = post(&app, "/v1/grid/paths", request.clone()).await;
    assert_eq!(res.status(), 200);
    let body: serde_json::Value = res.json().await.expect("json");
    let path = &body["paths"][0];
    let d = [30.0, 18.0];
    let exact = (m[0] * d[0] * d[0] + 2.0 * m[1] * d[0] * d[1] + m[2] * d[1] * d[1]).sqrt();
    let len = path["geodesic_length"].as_f64().expect("length");
    assert!(
        (len - exact).abs() < 0.03 * exact,
        "geodesic length {len} vs {exact}"
    );
    // A constant metric's geodesic is the straight segment: every vertex within a cell of it.
    let points = path["points"].as_array().expect("points");
    assert!(points.len() > 10);
    let norm = (d[0] * d[0] + d[1] * d[1]).sqrt();
    let worst = points
        .iter()
        .map(|p| {
            let (a, b) = (
                p[0].as_f64().expect("x") - 10.0,
                p[1].as_f64().expect("y") - 12.0,
            );
            (a * d[1] - b * d[0]).abs() / norm
        })
        .fold(0.0, f64::max);
    assert!(
        worst < 1.0,
        "deviation {worst} cells from the straight line"
    );
    assert_eq!(points[0], json!([10.0, 12.0]));
    assert_eq!(points[points.len() - 1], json!([40.0, 30.0]));
    // Tensor maps skip the cache: the same request solves again.
    let again: serde_json::Value = post(&app, "/v1/grid/paths", request)
        .await
        .json()
        .await
        .expect("json");
    assert_eq!(again["stats"]["maps"][0]["cached"], false);
    assert_eq!(again["paths"][0]["points"], path["points"]);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_tensor_metrics_are_422_naming_the_field() {
    let app = spawn(|_| {}).await;
    let src = json!([{"point": [2.0, 2.0]}]);
    let eigen = json!({"kind": "eigen", "shape": [8, 8], "eigenvalues": [1.0, 4.0], "direction": [1.0, 0.0]});

    // A components dataset with one indefinite cell.
    let mut t = ArrayD::from_elem(IxDyn(&[8, 8, 3]), 0.0f64);
    for i in 0..8 {
        for j in 0..8 {
            t[[i, j, 0]] = 1.0;
            t[[i, j, 2]] = 1.0;
        }
    }
    t[[2, 3, 1]] = 2.0;
    let id = app.upload(&ArrayData::F64(t)).await;
    let v = problem(
        post(
            &app,
            "/v1/grid/distance",
            json!({"metric": {"kind": "components", "dataset": id}, "sources": src}),
        )
        .await,
        422,
    )
    .await;
    assert_eq!(v["field"], "metric.dataset");
    assert!(
        v["detail"].as_str().expect("detail").contains("[2, 3]"),
        "{v}"
    );

    // A dataset without a trailing component axis of 3 or 6.
    let flat = app
        .upload(&ArrayData::F64(ArrayD::from_elem(IxDyn(&[8, 8, 2]), 1.0)))
        .await;
    let v = problem(
        post(
            &app,
            "/v1/grid/segment",
            json!({"metric": {"kind": "components", "dataset": flat}, "seeds": [{"label": 1, "point": [2.0, 2.0]}]}),
        )
        .await,
        422,
    )
    .await;
    assert_eq!(v["field"], "metric.dataset");

    // Negative eigenvalue.
    let v = problem(
        post(
            &app,
            "/v1/grid/paths",
            json!({"metric": {"kind": "eigen", "shape": [8, 8], "eigenvalues": [-1.0, 4.0], "direction": [1.0, 0.0]},
                   "sources": src, "ends": [[6.0, 6.0]]}),
        )
        .await,
        422,
    )
    .await;
    assert_eq!(v["field"], "metric.eigenvalues");

    // Both metrics, or neither.
    let v = problem(
        post(
            &app,
            "/v1/grid/distance",
            json!({"cost": {"constant": 1.0, "shape": [8, 8]}, "metric": eigen, "sources": src}),
        )
        .await,
        422,
    )
    .await;
    assert_eq!(v["field"], "metric");
    let v = problem(
        post(&app, "/v1/grid/distance", json!({"sources": src})).await,
        422,
    )
    .await;
    assert_eq!(v["field"], "cost");
    let v = problem(
        post(
            &app,
            "/v1/grid/segment",
            json!({"seeds": [{"label": 1, "point": [2.0, 2.0]}]}),
        )
        .await,
        422,
    )
    .await;
    assert_eq!(v["field"], "cost");

    // A tensor metric is fast marching only.
    let v = problem(
        post(
            &app,
            "/v1/grid/distance",
            json!({"metric": eigen, "sources": src, "method": "dijkstra"}),
        )
        .await,
        422,
    )
    .await;
    assert_eq!(v["field"], "method");
    let v = problem(
        post(
            &app,
            "/v1/grid/paths",
            json!({"metric": eigen, "sources": src, "ends": [[6.0, 6.0]], "connectivity": "extended"}),
        )
        .await,
        422,
    )
    .await;
    assert_eq!(v["field"], "connectivity");
}
