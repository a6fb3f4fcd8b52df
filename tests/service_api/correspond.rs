//! `POST /v1/mesh/correspond` through the real server: a moved copy of a
//! flat trapezoid is matched (arrays and the mesh with its per-vertex
//! matches stored), a copy of twice the size is refused naming `b` and the
//! way out (`scale`), which then works; a disconnected mesh is refused
//! naming `a`.

use geodex::io::ArrayData;
use geodex::numerics::mesh::shapes::flat_square;
use geodex::numerics::mesh::TriMesh;
use serde_json::json;

use crate::common::{problem, spawn, TestApp};
use crate::shape::{npy, upload_mesh};

async fn post(app: &TestApp, body: serde_json::Value) -> reqwest::Response {
    crate::shape::post(app, "/v1/mesh/correspond", body).await
}

/// A flat right trapezoid (no symmetry) of 121 vertices, scaled by `s`,
/// turned by `angle` in its plane and moved.
fn trapezoid(s: f64, angle: f64) -> TriMesh {
    let m = flat_square(10, 1.0, 0.0);
    let (c, sn) = (angle.cos(), angle.sin());
    let pos = m
        .positions()
        .iter()
        .map(|p| {
            let (x, y) = (2.0 * p[0], p[1] * (0.4 + 0.6 * p[0]));
            [s * (c * x - sn * y) + 1.0, s * (sn * x + c * y), 0.0]
        })
        .collect();
    TriMesh::new(pos, m.faces().to_vec()).expect("mesh")
}

#[tokio::test]
async fn correspond_matches_a_moved_copy_and_names_the_bad_field() {
    let app = spawn(|_| {}).await;
    let a = upload_mesh(&app, &trapezoid(1.0, 0.0)).await;
    let b = upload_mesh(&app, &trapezoid(1.0, 0.5)).await;
    let res = post(&app, json!({"a": a, "b": b, "landmarks": 20})).await;
    let status = res.status();
    let body: serde_json::Value = res.json().await.expect("json");
    assert_eq!(status, 200, "{body}");
    assert_eq!(body["face"]["shape"], json!([121]));
    assert_eq!(body["bary"]["shape"], json!([121, 3]));
    assert_eq!(body["confidence"]["shape"], json!([121]));
    assert_eq!(body["symmetric"], false, "{body}");
    let ArrayData::I32(vertex) = npy(&app, &body["vertex"]["data_url"]).await else {
        panic!("int32 vertices");
    };
    // The copy has the same indices: most vertices go to themselves.
    let same = vertex
        .iter()
        .enumerate()
        .filter(|(i, &v)| *i as i32 == v)
        .count();
    assert!(same >= 110, "{same} of 121");
    let ArrayData::F64(bary) = npy(&app, &body["bary"]["data_url"]).await else {
        panic!("f64 bary");
    };
    for row in bary.rows() {
        assert!((row.sum() - 1.0).abs() < 1e-9);
    }
    let meta = app.get(body["result"]["url"].as_str().expect("url")).await;
    let meta: serde_json::Value = meta.json().await.expect("json");
    assert_eq!(meta["mesh"]["vertices"], 121, "{meta}");
    // Twice the size: four times the area, refused naming `b` and `scale`.
    let big = upload_mesh(&app, &trapezoid(2.0, 0.5)).await;
    let p = problem(
        post(&app, json!({"a": a, "b": big, "landmarks": 20})).await,
        422,
    )
    .await;
    assert_eq!(p["field"], "b", "{p}");
    assert!(
        p["detail"]
            .as_str()
            .unwrap_or("")
            .contains("\"scale\": true"),
        "{p}"
    );
    let res = post(
        &app,
        json!({"a": a, "b": big, "landmarks": 20, "scale": true}),
    )
    .await;
    assert_eq!(res.status(), 200);
    let body: serde_json::Value = res.json().await.expect("json");
    assert!((body["scale_factor"].as_f64().expect("factor") - 0.5).abs() < 1e-9);
    // Two separate squares: refused naming `a`.
    let s = flat_square(3, 1.0, 0.0);
    let mut pos = s.positions().to_vec();
    pos.extend(s.positions().iter().map(|q| [q[0] + 5.0, q[1], q[2]]));
    let mut faces = s.faces().to_vec();
    faces.extend(s.faces().iter().map(|f| f.map(|v| v + 16)));
    let two = upload_mesh(&app, &TriMesh::new(pos, faces).expect("mesh")).await;
    let p = problem(post(&app, json!({"a": two, "b": b})).await, 422).await;
    assert_eq!(p["field"], "a", "{p}");
    assert!(
        p["detail"].as_str().unwrap_or("").contains("component"),
        "{p}"
    );
}
