//! `POST /v1/grid/paths` and `POST /v1/grid/metric`: answers against the
//! exact straight path, the cache of distance maps, the formats, and the
//! 4xx answers naming their field.

use geodex::io::ArrayData;
use ndarray::ArrayD;
use serde_json::{json, Value};

use crate::common::{f64_values, problem, spawn};

async fn post(app: &crate::common::TestApp, path: &str, body: &Value) -> reqwest::Response {
    app.client
        .post(app.url(path))
        .json(body)
        .send()
        .await
        .expect("post")
}

/// A 2D image: a bright horizontal band (rows 14..=16) on a dark background.
fn band_image() -> ArrayData {
    ArrayData::U8(ArrayD::from_shape_fn(ndarray::IxDyn(&[32, 48]), |ix| {
        if (14..=16).contains(&ix[0]) {
            200
        } else {
            20 + (ix[1] % 7) as u8
        }
    }))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn paths_follow_the_exact_segment_and_the_second_request_only_descends() {
    let app = spawn(|_| {}).await;
    let body = json!({
        "cost": {"constant": 1.0, "shape": [64, 64]},
        "sources": [{"point": [5.0, 6.0]}],
        "ends": [[50.0, 40.0], [60.0, 10.0]]
    });
    let res = post(&app, "/v1/grid/paths", &body).await;
    assert_eq!(res.status(), 200);
    let v: Value = res.json().await.expect("json");
    let paths = v["paths"].as_array().expect("paths");
    assert_eq!(paths.len(), 2);
    let exact = (45.0f64 * 45.0 + 34.0 * 34.0).sqrt();
    let len = paths[0]["euclidean_length"].as_f64().unwrap();
    assert!((len - exact).abs() < 0.05, "{len} vs {exact}");
    assert_eq!(paths[0]["points"][0], json!([5.0, 6.0]));
    assert_eq!(
        paths[0]["points"].as_array().unwrap().last().unwrap(),
        &json!([50.0, 40.0])
    );
    assert_eq!(v["stats"]["maps"][0]["cached"], false);
    assert_eq!(v["stats"]["maps"][0]["stop"], "targets_reached");

    // New end points inside the computed region: the map is reused.
    let again = json!({
        "cost": {"constant": 1.0, "shape": [64, 64]},
        "sources": [{"point": [5.0, 6.0]}],
        "ends": [[30.0, 30.0]]
    });
    let v: Value = post(&app, "/v1/grid/paths", &again)
        .await
        .json()
        .await
        .unwrap();
    assert_eq!(v["stats"]["maps"][0]["cached"], true, "{v}");
    // An end point beyond the early-stopped region: the map is recomputed in full.
    let far = json!({
        "cost": {"constant": 1.0, "shape": [64, 64]},
        "sources": [{"point": [5.0, 6.0]}],
        "ends": [[63.0, 63.0]]
    });
    let v: Value = post(&app, "/v1/grid/paths", &far)
        .await
        .json()
        .await
        .unwrap();
    assert_eq!(v["stats"]["maps"][0]["cached"], false);
    assert_eq!(v["stats"]["maps"][0]["stop"], "completed");
    let len = v["paths"][0]["euclidean_length"].as_f64().unwrap();
    assert!((len - (58.0f64 * 58.0 + 57.0 * 57.0).sqrt()).abs() < 0.05);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn designed_metrics_steer_paths_and_come_back_as_datasets() {
    let app = spawn(|_| {}).await;
    let id = app.upload(&band_image()).await;
    // The metric endpoint: W = |f - c| + eps, c read on the band.
    let res = post(
        &app,
        "/v1/grid/metric",
        &json!({"cost": {"dataset": id, "design": {"kind": "intensity", "at": [15.0, 3.0]}}}),
    )
    .await;
    assert_eq!(res.status(), 200);
    let v: Value = res.json().await.unwrap();
    assert_eq!(v["metric"]["shape"], json!([32, 48]));
    assert!((v["stats"]["min"].as_f64().unwrap() - 0.01).abs() < 1e-12);

    // A path between two band points bends into the band and stays there.
    let body = json!({
        "cost": {"dataset": id, "design": {"kind": "intensity", "at": [15.0, 3.0]}},
        "waypoints": [[15.0, 3.0], [15.0, 44.0]],
    });
    let v: Value = post(&app, "/v1/grid/paths", &body)
        .await
        .json()
        .await
        .unwrap();
    for p in v["chain"]["points"].as_array().unwrap() {
        let row = p[0].as_f64().unwrap();
        assert!((14.0..=16.0).contains(&row), "{p}");
    }
    // GeoJSON and SVG forms.
    let mut geo = body.clone();
    geo["format"] = json!("geojson");
    let res = post(&app, "/v1/grid/paths", &geo).await;
    assert_eq!(res.headers()["content-type"], "application/geo+json");
    let g: Value = res.json().await.unwrap();
    assert_eq!(g["type"], "FeatureCollection");
    assert_eq!(g["features"][0]["geometry"]["type"], "LineString");
    // [x, y] = [axis 1, axis 0].
    assert_eq!(
        g["features"][0]["geometry"]["coordinates"][0],
        json!([3.0, 15.0])
    );
    let mut svg = body.clone();
    svg["format"] = json!("svg");
    let res = post(&app, "/v1/grid/paths", &svg).await;
    assert_eq!(res.headers()["content-type"], "image/svg+xml");
    let text = res.text().await.unwrap();
    assert!(text.contains("data:image/png;base64,") && text.contains("<polyline"));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_path_requests_are_4xx_naming_the_field() {
    let app = spawn(|_| {}).await;
    let id = app.upload(&band_image()).await;
    let cases = [
        (
            json!({"cost": {"constant": 1.0, "shape": [16, 16]}, "sources": [{"point": [1.0, 1.0]}], "ends": [[40.0, 1.0]]}),
            422,
            "ends[0]",
        ),
        (
            json!({"cost": {"constant": 1.0, "shape": [16, 16]}, "waypoints": [[1.0, 1.0]]}),
            422,
            "waypoints",
        ),
        (
            json!({"cost": {"constant": 1.0, "shape": [16, 16]}, "contour": [[1.0, 1.0], [2.0, 2.0], [99.0, 2.0]]}),
            422,
            "contour[2]",
        ),
        (
            json!({"cost": {"dataset": id, "design": {"kind": "edges", "sigma": -1.0}}, "sources": [{"point": [1.0, 1.0]}], "ends": [[3.0, 3.0]]}),
            422,
            "cost.design.sigma",
        ),
        (
            json!({"cost": {"constant": 1.0, "shape": [16, 16], "design": {"kind": "edges"}}, "sources": [{"point": [1.0, 1.0]}], "ends": [[3.0, 3.0]]}),
            422,
            "cost.design",
        ),
        (
            json!({"cost": {"dataset": "ds_nope"}, "sources": [{"point": [1.0, 1.0]}], "ends": [[3.0, 3.0]]}),
            404,
            "cost.dataset",
        ),
        (
            json!({"cost": {"constant": 1.0, "shape": [8, 8, 8]}, "sources": [{"point": [1.0, 1.0, 1.0]}], "ends": [[3.0, 3.0, 3.0]], "format": "svg"}),
            422,
            "format",
        ),
        (
            json!({"cost": {"constant": 1.0, "shape": [16, 16]}, "sources": [{"point": [1.0, 1.0]}], "ends": [[3.0, 3.0]], "step": 2.0}),
            422,
            "step",
        ),
    ];
    for (body, status, field) in cases {
        let v = problem(post(&app, "/v1/grid/paths", &body).await, status).await;
        assert_eq!(v["field"], field, "{body}");
    }
    // An end point behind a wall is unreachable: 422 naming it.
    let mut walls = ArrayD::from_elem(ndarray::IxDyn(&[16, 16]), 1.0f64);
    for j in 0..16 {
        walls[[8, j]] = f64::INFINITY;
    }
    let wid = app.upload(&ArrayData::F64(walls)).await;
    let body = json!({"cost": {"dataset": wid}, "sources": [{"point": [1.0, 1.0]}], "ends": [[3.0, 3.0], [12.0, 3.0]]});
    let v = problem(post(&app, "/v1/grid/paths", &body).await, 422).await;
    assert_eq!(v["field"], "ends[1]");
    // Unknown fields and kinds are refused by the parser.
    let body = json!({"cost": {"dataset": id, "design": {"kind": "blobs"}}, "sources": [{"point": [1.0, 1.0]}], "ends": [[3.0, 3.0]]});
    let res = post(&app, "/v1/grid/paths", &body).await;
    assert!(res.status().is_client_error());
    let v = problem(
        post(
            &app,
            "/v1/grid/metric",
            &json!({"cost": {"dataset": id, "design": {"kind": "vesselness", "scales": []}}}),
        )
        .await,
        422,
    )
    .await;
    assert_eq!(v["field"], "cost.design.scales");
    let v = problem(
        post(
            &app,
            "/v1/grid/metric",
            &json!({"cost": {"dataset": "ds_nope", "design": {"kind": "edges"}}}),
        )
        .await,
        404,
    )
    .await;
    assert_eq!(v["field"], "cost.dataset");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_distance_on_a_cost_the_paths_designed_equals_a_fresh_one() {
    // grid.distance takes the designed cost from the paths' cache when it is
    // there (the playground warms it before the first click): the map must be
    // the one a server that never saw the paths computes, to the bit.
    let image = ArrayD::from_shape_fn(ndarray::IxDyn(&[30, 40]), |ix| {
        ((ix[0] * 7 + ix[1] * 3) % 17) as f64
            + if (14..=16).contains(&ix[0]) {
                40.0
            } else {
                0.0
            }
    });
    let cost = |id: &str| json!({"dataset": id, "design": {"kind": "intensity", "value": 45, "power": 2, "epsilon": 0.05, "sigma": 1}});
    let distance = |id: &str| json!({"cost": cost(id), "spacing": [1.0, 0.5], "sources": [{"point": [3.0, 30.5]}], "order": 2});
    let fresh_app = spawn(|_| {}).await;
    let fresh_id = fresh_app.upload(&ArrayData::F64(image.clone())).await;
    let res = post(&fresh_app, "/v1/grid/distance", &distance(&fresh_id)).await;
    assert_eq!(res.status(), 200);
    let fresh: Value = res.json().await.expect("json");
    let fresh = f64_values(&fresh_app, &fresh["distance"]).await;

    let app = spawn(|_| {}).await;
    let id = app.upload(&ArrayData::F64(image)).await;
    let warm = json!({"cost": cost(&id), "spacing": [1.0, 0.5], "order": 2,
        "sources": [{"point": [15.0, 20.0]}], "ends": [[15.0, 20.0]], "early_stop": true});
    let v: Value = post(&app, "/v1/grid/paths", &warm)
        .await
        .json()
        .await
        .expect("json");
    assert_eq!(v["stats"]["cost_cached"], false, "{v}");
    let res = post(&app, "/v1/grid/distance", &distance(&id)).await;
    assert_eq!(res.status(), 200);
    let from_cache: Value = res.json().await.expect("json");
    let from_cache = f64_values(&app, &from_cache["distance"]).await;
    assert_eq!(fresh.len(), from_cache.len());
    assert!(
        fresh.iter().zip(&from_cache).all(|(a, b)| a == b),
        "the maps differ"
    );
    // And the map it kept serves the paths from that source.
    let path = json!({"cost": cost(&id), "spacing": [1.0, 0.5], "order": 2,
        "sources": [{"point": [3.0, 30.5]}], "ends": [[25.0, 2.0]], "early_stop": false});
    let v: Value = post(&app, "/v1/grid/paths", &path)
        .await
        .json()
        .await
        .expect("json");
    assert_eq!(v["stats"]["cost_cached"], true, "{v}");
    assert_eq!(v["stats"]["maps"][0]["cached"], true, "{v}");
}
