//! `POST /v1/grid/group` over HTTP (perceptual grouping by minimal paths), and its 4xx.

use geodex::io::ArrayData;
use ndarray::ArrayD;
use serde_json::json;

use crate::common::{problem, spawn, TestApp};

async fn post(app: &TestApp, body: serde_json::Value) -> reqwest::Response {
    app.client
        .post(app.url("/v1/grid/group"))
        .json(&body)
        .send()
        .await
        .expect("post")
}

/// A circle of 8 key points drawn as a cheap ring in the cost, a row of 4
/// points along a cheap segment, and 2 clutter points: one closed and one
/// open contour, the clutter left out, the labels as a dataset.
#[tokio::test]
async fn group_finds_a_closed_and_an_open_contour() {
    let app = spawn(|_| {}).await;
    let n = 64;
    let cost = ArrayData::F64(ArrayD::from_shape_fn(ndarray::IxDyn(&[n, n]), |ix| {
        let (r, c) = (ix[0] as f64, ix[1] as f64);
        let on_ring = (((r - 20.0).powi(2) + (c - 20.0).powi(2)).sqrt() - 12.0).abs() <= 1.5;
        let on_line = (r - 52.0).abs() <= 1.0 && (8.0..=56.0).contains(&c);
        if on_ring || on_line {
            0.05
        } else {
            1.0
        }
    }));
    let id = app.upload(&cost).await;
    let mut points: Vec<[f64; 2]> = (0..8)
        .map(|k| {
            let a = k as f64 * std::f64::consts::TAU / 8.0;
            [20.0 + 12.0 * a.cos(), 20.0 + 12.0 * a.sin()]
        })
        .collect();
    points.extend([[52.0, 10.0], [52.0, 24.0], [52.0, 38.0], [52.0, 52.0]]);
    points.extend([[20.0, 52.0], [40.0, 40.0]]);
    let res = post(&app, json!({"cost": {"dataset": id}, "key_points": points})).await;
    assert_eq!(res.status(), 200);
    let body: serde_json::Value = res.json().await.expect("json");
    let contours = body["contours"].as_array().expect("contours");
    assert_eq!(contours.len(), 2, "{body}");
    assert_eq!(contours[0]["key_points"], json!([0, 1, 2, 3, 4, 5, 6, 7]));
    assert_eq!(contours[0]["closed"], true);
    assert_eq!(contours[1]["key_points"], json!([8, 9, 10, 11]));
    assert_eq!(contours[1]["closed"], false);
    assert_eq!(body["isolated"], json!([12, 13]));
    assert_eq!(body["labels"]["shape"], json!([n, n]));
    // The open chain's links: cost = U_i + U_j at the saddle = 14 cells at
    // W = 0.05 (0.7), the saddle halfway.
    let links = body["links"].as_array().expect("links");
    let l = links
        .iter()
        .find(|l| l["pair"] == json!([9, 10]))
        .expect("link 9-10");
    assert_eq!(l["kept"], true);
    let cost = l["geodesic_length"].as_f64().expect("geodesic_length");
    assert!((cost - 0.7).abs() < 0.02, "{l}");
    let s = &l["saddle"];
    assert!((s[1].as_f64().expect("x") - 31.0).abs() <= 1.0, "{l}");
    // GeoJSON positions are [x, y] = [column, row].
    let f = &body["geojson"]["features"][1];
    assert_eq!(f["geometry"]["type"], "LineString");
    let first = &f["geometry"]["coordinates"][0];
    assert_eq!(first, &json!([10.0, 52.0]));
    assert_eq!(body["stats"]["closed"], 1);
    assert!(geodex::ops::registry::find("grid.group").is_some());
}

#[tokio::test]
async fn group_refusals_name_the_field() {
    let app = spawn(|_| {}).await;
    let cost = json!({"constant": 1.0, "shape": [32, 32]});
    for (body, field) in [
        (
            json!({"cost": cost, "key_points": [[1.0, 1.0]]}),
            "key_points",
        ),
        (
            json!({"cost": cost, "key_points": [[1.0, 1.0], [5.0, 32.0]]}),
            "key_points[1]",
        ),
        (
            json!({"cost": cost, "key_points": [[1.0, 1.0], [5.0, 5.0, 1.0]]}),
            "key_points[1]",
        ),
        (
            json!({"cost": cost, "key_points": [[1.0, 1.0], [5.0, 5.0]], "orientations": [0.0]}),
            "orientations",
        ),
        (
            json!({"cost": cost, "key_points": [[1.0, 1.0], [5.0, 5.0]], "ratio": 0.5}),
            "ratio",
        ),
        (
            json!({"cost": cost, "key_points": [[1.0, 1.0], [5.0, 5.0]], "max_links": 0}),
            "max_links",
        ),
        (
            json!({"cost": cost, "key_points": [[1.0, 1.0], [5.0, 5.0]], "anisotropy": 0.5}),
            "anisotropy",
        ),
        (
            json!({"cost": {"constant": 1.0, "shape": [8, 8, 8]}, "key_points": [[1.0, 1.0], [5.0, 5.0]]}),
            "cost.shape",
        ),
        (
            json!({"cost": {"dataset": "ds_missing"}, "key_points": [[1.0, 1.0], [5.0, 5.0]]}),
            "cost.dataset",
        ),
    ] {
        let res = post(&app, body.clone()).await;
        let status = res.status().as_u16();
        assert!(status == 422 || status == 404, "{body}: {status}");
        let v = problem(res, status).await;
        assert_eq!(v["field"], field, "{body}: {v}");
    }
}
