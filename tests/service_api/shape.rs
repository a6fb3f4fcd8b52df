//! Shape analysis over HTTP: `/v1/mesh/distance-matrix`, `/v1/mesh/embed`,
//! `/v1/points/isomap`.

use geodex::io::mesh::write::write_obj;
use geodex::io::{self, ArrayData};
use geodex::numerics::mesh::shapes::{flat_square, icosphere};
use geodex::numerics::mesh::TriMesh;
use geodex::numerics::shape::isomap::swiss_roll;
use serde_json::json;

use crate::common::{problem, spawn, TestApp};

async fn upload_mesh(app: &TestApp, mesh: &TriMesh) -> String {
    let res = app
        .client
        .post(app.url("/v1/datasets"))
        .header("content-type", "model/obj")
        .body(write_obj(mesh))
        .send()
        .await
        .expect("upload");
    assert_eq!(res.status(), 201, "{:?}", res.text().await);
    let meta: serde_json::Value = res.json().await.expect("json");
    meta["id"].as_str().expect("id").to_string()
}

async fn post(app: &TestApp, path: &str, body: serde_json::Value) -> reqwest::Response {
    app.client
        .post(app.url(path))
        .json(&body)
        .send()
        .await
        .expect("post")
}

async fn npy(app: &TestApp, data_url: &serde_json::Value) -> ArrayData {
    let res = app
        .get(&format!(
            "{}?format=npy",
            data_url.as_str().expect("data_url")
        ))
        .await;
    assert_eq!(res.status(), 200);
    io::decode(
        &res.bytes().await.expect("bytes"),
        None,
        &io::Limits::default(),
    )
    .expect("npy")
    .array
}

#[tokio::test]
async fn distance_matrix_all_pairs_landmarks_and_the_size_limit() {
    let app = spawn(|_| {}).await;
    let square = flat_square(4, 1.0, 0.0);
    let id = upload_mesh(&app, &square).await;
    let res = post(
        &app,
        "/v1/mesh/distance-matrix",
        json!({"mesh": id, "method": "exact"}),
    )
    .await;
    assert_eq!(res.status(), 200);
    let body: serde_json::Value = res.json().await.expect("json");
    assert_eq!(body["all_pairs"], true);
    assert_eq!(body["matrix"]["shape"], json!([25, 25]));
    let ArrayData::F64(m) = npy(&app, &body["matrix"]["data_url"]).await else {
        panic!("f64 matrix");
    };
    // Flat: the exact distance is the Euclidean one, symmetric.
    let p = square.positions();
    for i in 0..25 {
        for j in 0..25 {
            let e = ((p[i][0] - p[j][0]).powi(2) + (p[i][1] - p[j][1]).powi(2)).sqrt();
            assert!((m[[i, j]] - e).abs() < 1e-12, "{i} {j}");
            assert_eq!(m[[i, j]], m[[j, i]]);
        }
    }
    // Landmark rows through the heat method.
    let res = post(
        &app,
        "/v1/mesh/distance-matrix",
        json!({"mesh": id, "landmarks": 5, "method": "heat"}),
    )
    .await;
    let body: serde_json::Value = res.json().await.expect("json");
    assert_eq!(body["matrix"]["shape"], json!([5, 25]));
    assert_eq!(body["sources"].as_array().expect("sources").len(), 5);
    // Too many vertices for all pairs: a 413 naming `landmarks`.
    let big = upload_mesh(&app, &icosphere(5, 1.0)).await;
    let p = problem(
        post(&app, "/v1/mesh/distance-matrix", json!({"mesh": big})).await,
        413,
    )
    .await;
    assert_eq!(p["field"], "landmarks", "{p}");
    assert!(
        p["detail"].as_str().unwrap_or("").contains("landmarks"),
        "{p}"
    );
    let p = problem(
        post(
            &app,
            "/v1/mesh/distance-matrix",
            json!({"mesh": id, "sources": [99]}),
        )
        .await,
        422,
    )
    .await;
    assert_eq!(p["field"], "sources[0]", "{p}");
}

#[tokio::test]
async fn embed_returns_a_mesh_and_refuses_a_disconnected_one() {
    let app = spawn(|_| {}).await;
    let sphere = icosphere(2, 1.0);
    let id = upload_mesh(&app, &sphere).await;
    let res = post(&app, "/v1/mesh/embed", json!({"mesh": id, "landmarks": 40})).await;
    assert_eq!(res.status(), 200);
    let body: serde_json::Value = res.json().await.expect("json");
    assert_eq!(body["coordinates"]["shape"], json!([162, 3]));
    let ev = body["explained_variance"]
        .as_f64()
        .expect("explained_variance");
    // Σ top-3 λ / tr B exceeds 1 when B has negative eigenvalues, as the
    // geodesic distances of a sphere (not Euclidean) give: 1.24 measured.
    assert!(ev > 0.5 && ev < 1.5, "{ev}");
    assert!(body["stress"].as_f64().expect("stress") < 0.3, "{body}");
    let meta = app.get(body["result"]["url"].as_str().expect("url")).await;
    let meta: serde_json::Value = meta.json().await.expect("json");
    assert_eq!(meta["mesh"]["vertices"], 162);
    assert_eq!(meta["mesh"]["faces"], 320);
    // Two separate squares: one 422 naming the mesh and the way out.
    let a = flat_square(3, 1.0, 0.0);
    let mut pos = a.positions().to_vec();
    pos.extend(a.positions().iter().map(|q| [q[0] + 5.0, q[1], q[2]]));
    let mut faces = a.faces().to_vec();
    faces.extend(a.faces().iter().map(|f| f.map(|v| v + 16)));
    let two = upload_mesh(&app, &TriMesh::new(pos, faces).expect("mesh")).await;
    let p = problem(
        post(&app, "/v1/mesh/embed", json!({"mesh": two})).await,
        422,
    )
    .await;
    assert_eq!(p["field"], "mesh", "{p}");
    assert!(
        p["detail"].as_str().unwrap_or("").contains("component"),
        "{p}"
    );
    let p = problem(
        post(&app, "/v1/mesh/embed", json!({"mesh": id, "dimensions": 4})).await,
        422,
    )
    .await;
    assert_eq!(p["field"], "dimensions", "{p}");
}

#[tokio::test]
async fn isomap_of_an_uploaded_swiss_roll() {
    let app = spawn(|_| {}).await;
    let (p, _) = swiss_roll(600, 9);
    let id = app.upload(&ArrayData::F64(p.into_dyn())).await;
    let res = post(&app, "/v1/points/isomap", json!({"points": id, "k": 10})).await;
    assert_eq!(res.status(), 200);
    let body: serde_json::Value = res.json().await.expect("json");
    assert_eq!(body["embedding"]["shape"], json!([600, 2]));
    let rv = body["residual_variance"]
        .as_f64()
        .expect("residual_variance");
    assert!(rv < 0.1, "{rv}");
    // k = 1 cannot join the roll: a 422 naming `k`.
    let p = problem(
        post(&app, "/v1/points/isomap", json!({"points": id, "k": 1})).await,
        422,
    )
    .await;
    assert_eq!(p["field"], "k", "{p}");
}
