//! Shape analysis over HTTP: `/v1/mesh/distance-matrix`, `/v1/mesh/embed`,
//! `/v1/points/isomap`, `/v1/grid/shape-embed`.

use geodex::io::mesh::write::write_obj;
use geodex::io::{self, ArrayData};
use geodex::numerics::mesh::shapes::{flat_square, icosphere};
use geodex::numerics::mesh::TriMesh;
use geodex::numerics::shape::isomap::swiss_roll;
use serde_json::json;

use crate::common::{problem, spawn, TestApp};

pub(crate) async fn upload_mesh(app: &TestApp, mesh: &TriMesh) -> String {
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

pub(crate) async fn post(app: &TestApp, path: &str, body: serde_json::Value) -> reqwest::Response {
    app.client
        .post(app.url(path))
        .json(&body)
        .send()
        .await
        .expect("post")
}

pub(crate) async fn npy(app: &TestApp, data_url: &serde_json::Value) -> ArrayData {
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

/// A `rows × cols` u8 mask with the cells where `inside(i, j)` set.
fn mask(rows: usize, cols: usize, inside: impl Fn(usize, usize) -> bool) -> ArrayData {
    ArrayData::U8(
        ndarray::Array2::from_shape_fn((rows, cols), |(i, j)| u8::from(inside(i, j))).into_dyn(),
    )
}

#[tokio::test]
async fn shape_embed_of_a_mask_and_its_refusals() {
    let app = spawn(|_| {}).await;
    // An L: two 8-cell-wide arms of a 30 × 30 grid.
    let l_shape = mask(30, 30, |i, j| {
        (2..28).contains(&i) && (2..10).contains(&j)
            || (20..28).contains(&i) && (2..28).contains(&j)
    });
    let cells = match &l_shape {
        ArrayData::U8(a) => a.iter().filter(|&&v| v > 0).count(),
        _ => unreachable!(),
    };
    let id = app.upload(&l_shape).await;
    let res = post(
        &app,
        "/v1/grid/shape-embed",
        json!({"mask": id, "landmarks": 20, "matrix": true}),
    )
    .await;
    assert_eq!(res.status(), 200);
    let body: serde_json::Value = res.json().await.expect("json");
    assert_eq!(body["coordinates"]["shape"], json!([cells, 2]));
    assert_eq!(body["cells"]["shape"], json!([cells, 2]));
    assert_eq!(body["matrix"]["shape"], json!([20, cells]));
    assert_eq!(body["landmarks"].as_array().map(Vec::len), Some(20));
    // The L (26 × 26 cells) unfolds: its canonical form is longer than the
    // L and twice as long as wide (38.5 × 18.9 measured; the elbow keeps a
    // bend, since the inner corner shortens the paths of one side only).
    let ArrayData::F64(x) = npy(&app, &body["coordinates"]["data_url"]).await else {
        panic!("f64 coordinates");
    };
    let extent = |a: usize| {
        let col = x.index_axis(ndarray::Axis(1), a);
        col.fold(f64::NEG_INFINITY, |m, &v| m.max(v)) - col.fold(f64::INFINITY, |m, &v| m.min(v))
    };
    assert!(
        extent(0) > 35.0 && extent(0) > 1.8 * extent(1),
        "{} × {}",
        extent(0),
        extent(1)
    );
    assert!(
        body["residual_variance"].as_f64().expect("rv") < 0.2,
        "{body}"
    );
    // The pixel mesh at the embedded positions.
    let meta = app.get(body["result"]["url"].as_str().expect("url")).await;
    let meta: serde_json::Value = meta.json().await.expect("json");
    assert_eq!(meta["mesh"]["vertices"], cells);
    // Two pieces: a 422 naming the mask and the way out.
    let two = app
        .upload(&mask(20, 20, |i, j| {
            (2..6).contains(&i) && (2..18).contains(&j)
                || (10..14).contains(&i) && (2..18).contains(&j)
        }))
        .await;
    let p = problem(
        post(
            &app,
            "/v1/grid/shape-embed",
            json!({"mask": two, "landmarks": 8}),
        )
        .await,
        422,
    )
    .await;
    assert_eq!(p["field"], "mask", "{p}");
    assert!(p["detail"].as_str().unwrap_or("").contains("piece"), "{p}");
    // All pairs of 6400 cells: a 413 naming the landmark option.
    let big = app.upload(&mask(80, 80, |_, _| true)).await;
    let p = problem(
        post(&app, "/v1/grid/shape-embed", json!({"mask": big})).await,
        413,
    )
    .await;
    assert_eq!(p["field"], "landmarks", "{p}");
    let p = problem(
        post(
            &app,
            "/v1/grid/shape-embed",
            json!({"mask": id, "order": 3}),
        )
        .await,
        422,
    )
    .await;
    assert_eq!(p["field"], "order", "{p}");
}

/// The distance matrix under a metric: each row is `mesh.distance` from
/// that source under the same metric (a field design, and face tensors),
/// the metric is echoed with its defaults, and a method that cannot run it gets a 422 naming
/// the field.
#[tokio::test]
async fn distance_matrix_under_a_metric_matches_mesh_distance() {
    let app = spawn(|_| {}).await;
    let sphere = icosphere(2, 1.0);
    let id = upload_mesh(&app, &sphere).await;
    let height: Vec<f64> = sphere.positions().iter().map(|p| p[2]).collect();
    let nv = height.len();
    let field = app
        .upload(&ArrayData::F64(
            ndarray::ArrayD::from_shape_vec(vec![1, nv], height).expect("shape"),
        ))
        .await;
    let sources = [0u32, 40, 99];
    for metric in [
        json!({"kind": "field", "field": field, "mode": "value", "reference": 0.5}),
        json!({"kind": "tensors", "constant": [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 9.0]]}),
    ] {
        let res = post(
            &app,
            "/v1/mesh/distance-matrix",
            json!({"mesh": id, "sources": sources, "metric": metric, "symmetry": "none"}),
        )
        .await;
        assert_eq!(res.status(), 200, "{:?}", res.text().await);
        let body: serde_json::Value = res.json().await.expect("json");
        // Echoed with its defaults filled in.
        assert_eq!(body["metric"]["kind"], metric["kind"], "{body}");
        let ArrayData::F64(m) = npy(&app, &body["matrix"]["data_url"]).await else {
            panic!("f64 matrix");
        };
        let m = m.into_dimensionality::<ndarray::Ix2>().expect("a matrix");
        let plain = post(
            &app,
            "/v1/mesh/distance-matrix",
            json!({"mesh": id, "sources": sources, "symmetry": "none"}),
        )
        .await;
        let plain: serde_json::Value = plain.json().await.expect("json");
        let ArrayData::F64(p) = npy(&app, &plain["matrix"]["data_url"]).await else {
            panic!("f64 matrix");
        };
        let p = p.into_dimensionality::<ndarray::Ix2>().expect("a matrix");
        assert!(
            (&m - &p).iter().map(|d| d.abs()).fold(0.0, f64::max) > 0.05,
            "the metric changed nothing: {metric}"
        );
        for (i, &s) in sources.iter().enumerate() {
            let res = post(
                &app,
                "/v1/mesh/distance",
                json!({"mesh": id, "sources": [{"vertex": s}], "metric": metric}),
            )
            .await;
            assert_eq!(res.status(), 200, "{:?}", res.text().await);
            let one: serde_json::Value = res.json().await.expect("json");
            let url = one["result"]["data_url"].as_str().expect("data_url");
            let j: serde_json::Value = app
                .get(&format!("{url}?format=json"))
                .await
                .json()
                .await
                .expect("json mesh");
            let d: Vec<f64> = j["properties"]["distance"]
                .as_array()
                .expect("distance")
                .iter()
                .map(|x| x.as_f64().unwrap_or(f64::INFINITY))
                .collect();
            assert_eq!(m.row(i).to_vec(), d, "{metric} source {s}");
        }
    }
    for (body, field) in [
        (
            json!({"mesh": id, "landmarks": 4, "method": "heat",
                   "metric": {"kind": "curvature"}}),
            "metric",
        ),
        (
            json!({"mesh": id, "landmarks": 4, "method": "exact", "weights": field}),
            "weights",
        ),
        (
            json!({"mesh": id, "landmarks": 4, "method": "dijkstra",
                   "metric": {"kind": "curvature_tensors"}}),
            "metric",
        ),
    ] {
        let p = problem(post(&app, "/v1/mesh/distance-matrix", body).await, 422).await;
        assert_eq!(p["field"], field, "{p}");
    }
}
