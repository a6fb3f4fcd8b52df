//! Mesh datasets and `/v1/mesh/*` over HTTP.

use geodex::io::mesh::write::write_obj;
use geodex::io::mesh::{ply::vertex_values, read_mesh, MeshFormat, MeshLimits};
use geodex::numerics::mesh::shapes::{great_circle, icosphere};
use serde_json::json;

use crate::common::{problem, spawn, TestApp};

async fn upload_mesh(
    app: &TestApp,
    body: Vec<u8>,
    content_type: &str,
    query: &str,
) -> serde_json::Value {
    let res = app
        .client
        .post(app.url(&format!("/v1/datasets{query}")))
        .header("content-type", content_type)
        .body(body)
        .send()
        .await
        .expect("upload");
    assert_eq!(res.status(), 201, "{:?}", res.text().await);
    res.json().await.expect("json")
}

async fn post(app: &TestApp, path: &str, body: serde_json::Value) -> reqwest::Response {
    app.client
        .post(app.url(path))
        .json(&body)
        .send()
        .await
        .expect("post")
}

#[tokio::test]
async fn mesh_upload_distance_download() {
    let app = spawn(|_| {}).await;
    let sphere = icosphere(3, 1.0);
    let meta = upload_mesh(&app, write_obj(&sphere), "model/obj", "").await;
    assert_eq!(meta["kind"], "mesh");
    assert_eq!(meta["source_format"], "obj");
    assert_eq!(meta["mesh"]["vertices"], 642);
    assert_eq!(meta["mesh"]["faces"], 1280);
    assert_eq!(meta["mesh"]["components"], 1);
    assert_eq!(meta["mesh"]["boundary_loops"], 0);
    let id = meta["id"].as_str().unwrap().to_string();

    // The same mesh via ?format= and via detection.
    let m2 = upload_mesh(
        &app,
        write_obj(&sphere),
        "application/octet-stream",
        "?format=obj",
    )
    .await;
    assert_eq!(m2["mesh"]["vertices"], 642);

    for (method, tol) in [
        ("fast_marching", 0.08),
        ("heat", 0.08),
        ("exact", 0.05),
        ("dijkstra", 0.2),
    ] {
        let res = post(
            &app,
            "/v1/mesh/distance",
            json!({"mesh": id, "sources": [{"vertex": 0}], "method": method}),
        )
        .await;
        assert_eq!(res.status(), 200, "{method}: {:?}", res.text().await);
        let body: serde_json::Value = res.json().await.unwrap();
        assert_eq!(body["stats"]["reached"], 642);
        let url = body["result"]["data_url"].as_str().unwrap().to_string();
        let res = app.get(&url).await;
        assert_eq!(res.status(), 200);
        assert_eq!(res.headers()["content-type"], "model/ply");
        let ply = res.bytes().await.unwrap();
        let d = vertex_values(&ply).unwrap().distance.unwrap();
        let back = read_mesh(&ply, Some(MeshFormat::Ply), &MeshLimits::default()).unwrap();
        assert_eq!(back.mesh.num_vertices(), 642);
        // Antipode of vertex 0 is at distance pi.
        let p0 = sphere.position(0);
        let far = (0..642)
            .max_by(|&a, &b| {
                great_circle(p0, sphere.position(a), 1.0).total_cmp(&great_circle(
                    p0,
                    sphere.position(b),
                    1.0,
                ))
            })
            .unwrap();
        assert!(
            (d[far as usize] - std::f64::consts::PI).abs() < tol * std::f64::consts::PI,
            "{method}: {}",
            d[far as usize]
        );
    }
    // Heat: the second query reuses the factorisation.
    let body: serde_json::Value = post(
        &app,
        "/v1/mesh/distance",
        json!({"mesh": id, "sources": [{"vertex": 5}], "method": "heat"}),
    )
    .await
    .json()
    .await
    .unwrap();
    assert_eq!(body["heat"]["cached"], true);
    assert_eq!(body["heat"]["factor_seconds"], 0.0);

    // JSON and OBJ downloads of a result.
    let url = body["result"]["data_url"].as_str().unwrap().to_string();
    let j: serde_json::Value = app
        .get(&format!("{url}?format=json"))
        .await
        .json()
        .await
        .unwrap();
    assert_eq!(j["vertices"].as_array().unwrap().len(), 642);
    assert_eq!(j["properties"]["distance"][5], 0.0);
    // OBJ has no place for the distances: refused, naming the formats that keep them.
    let obj = problem(app.get(&format!("{url}?format=obj")).await, 406).await;
    assert!(obj["detail"].as_str().unwrap().contains("ply"), "{obj}");
    // GLB by Accept, read back with an independent reader: 642 positions,
    // the distance as an attribute and as colours.
    let glb = app
        .client
        .get(app.url(&url))
        .header("accept", "model/gltf-binary")
        .send()
        .await
        .unwrap();
    assert_eq!(glb.headers()["content-type"], "model/gltf-binary");
    let bytes = glb.bytes().await.unwrap();
    let gltf = gltf::Gltf::from_slice(&bytes).expect("a valid GLB");
    let blob = gltf.blob.as_deref().unwrap();
    let prim = gltf
        .document
        .meshes()
        .next()
        .unwrap()
        .primitives()
        .next()
        .unwrap();
    let reader = prim.reader(|_| Some(blob));
    assert_eq!(reader.read_positions().unwrap().count(), 642);
    assert_eq!(reader.read_indices().unwrap().into_u32().count(), 3 * 1280);
    assert!(reader.read_colors(0).is_some());
    let (_, dist) = prim
        .attributes()
        .find(|(s, _)| s.to_string() == "_DISTANCE")
        .expect("the distance attribute");
    let view = dist.view().unwrap();
    let at = view.offset() + 4 * 5;
    assert_eq!(
        f32::from_le_bytes(blob[at..at + 4].try_into().unwrap()),
        0.0
    );

    // Voronoi, paths, sampling.
    let v: serde_json::Value = post(
        &app,
        "/v1/mesh/voronoi",
        json!({"mesh": id, "sources": [{"vertex": 0}, {"face": 100, "bary": [0.2, 0.3, 0.5]}]}),
    )
    .await
    .json()
    .await
    .unwrap();
    let cells = v["cells"].as_array().unwrap();
    assert_eq!(cells.len(), 2);
    let total: f64 = cells.iter().map(|c| c["area"].as_f64().unwrap()).sum();
    assert!((total - 4.0 * std::f64::consts::PI).abs() < 0.1, "{total}");
    let p: serde_json::Value = post(
        &app,
        "/v1/mesh/paths",
        json!({"mesh": id, "sources": [{"vertex": 0}], "ends": [{"vertex": 300}]}),
    )
    .await
    .json()
    .await
    .unwrap();
    let path = &p["paths"][0];
    assert_eq!(path["source"], 0);
    assert!(path["points"].as_array().unwrap().len() >= 2);
    assert!(path["result"].is_null());
    // With the exact method the path is backtracked: its length is the
    // exact distance, and every piece is at most a chord of the sphere.
    let p: serde_json::Value = post(
        &app,
        "/v1/mesh/paths",
        json!({"mesh": id, "sources": [{"vertex": 0}], "ends": [{"vertex": 300}, {"face": 7, "bary": [0.2, 0.3, 0.5]}], "method": "exact"}),
    )
    .await
    .json()
    .await
    .unwrap();
    for path in p["paths"].as_array().unwrap() {
        let (length, distance) = (
            path["euclidean_length"].as_f64().unwrap(),
            path["geodesic_length"].as_f64().unwrap(),
        );
        assert!((length - distance).abs() < 1e-9 * distance, "{path}");
        assert!(path["points"].as_array().unwrap().len() >= 3, "{path}");
    }
    // The heat method reports its Laplacian; the cotangent one is cached
    // apart from the robust one (built by the distance call above).
    for (laplacian, cached) in [("robust", true), ("cotangent", false), ("cotangent", true)] {
        let h: serde_json::Value = post(
            &app,
            "/v1/mesh/distance",
            json!({"mesh": id, "sources": [{"vertex": 0}], "method": "heat", "heat": {"laplacian": laplacian}}),
        )
        .await
        .json()
        .await
        .unwrap();
        assert_eq!(h["heat"]["laplacian"], laplacian, "{h}");
        assert_eq!(h["heat"]["cached"], cached, "{h}");
        assert_eq!(h["heat"]["tufted"], false, "{h}");
        // The setup's phases are kept with the solver (also when cached).
        let setup = &h["heat"]["setup"];
        assert!(
            setup["factorisation_seconds"].as_f64().unwrap() > 0.0,
            "{h}"
        );
        assert!(setup["laplacian_seconds"].as_f64().unwrap() >= 0.0, "{h}");
    }
    let s: serde_json::Value = post(&app, "/v1/mesh/sample", json!({"mesh": id, "count": 10}))
        .await
        .json()
        .await
        .unwrap();
    assert_eq!(s["samples"].as_array().unwrap().len(), 10);
}

#[tokio::test]
async fn mesh_errors_name_the_field() {
    let app = spawn(|_| {}).await;
    let sphere = icosphere(1, 1.0);
    let meta = upload_mesh(&app, write_obj(&sphere), "model/obj", "").await;
    let id = meta["id"].as_str().unwrap();
    // Bad mesh files: one clear 422.
    let res = app
        .client
        .post(app.url("/v1/datasets"))
        .header("content-type", "model/obj")
        .body("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n")
        .send()
        .await
        .unwrap();
    let p = problem(res, 422).await;
    assert!(p["detail"].as_str().unwrap().contains("vertex 6"), "{p}");
    let res = app
        .client
        .post(app.url("/v1/datasets"))
        .header("content-type", "model/stl")
        .body(vec![0u8; 90])
        .send()
        .await
        .unwrap();
    problem(res, 422).await;
    // Sources out of range, bad bary, unknown dataset, array given as mesh.
    let p = problem(
        post(
            &app,
            "/v1/mesh/distance",
            json!({"mesh": id, "sources": [{"vertex": 9999}]}),
        )
        .await,
        422,
    )
    .await;
    assert!(p.to_string().contains("sources[0]"), "{p}");
    let p = problem(
        post(
            &app,
            "/v1/mesh/distance",
            json!({"mesh": id, "sources": [{"face": 0, "bary": [0.5, 0.5, 0.5]}]}),
        )
        .await,
        422,
    )
    .await;
    assert!(p.to_string().contains("sources[0]"), "{p}");
    let p = problem(
        post(
            &app,
            "/v1/mesh/distance",
            json!({"mesh": id, "sources": [{"face": 0}]}),
        )
        .await,
        422,
    )
    .await;
    assert!(p.to_string().contains("sources[0].bary"), "{p}");
    problem(
        post(
            &app,
            "/v1/mesh/distance",
            json!({"mesh": "ds_00000000000000000000000000000000", "sources": [{"vertex": 0}]}),
        )
        .await,
        404,
    )
    .await;
    let p = problem(
        post(&app, "/v1/mesh/sample", json!({"mesh": id})).await,
        422,
    )
    .await;
    assert!(p.to_string().contains("count"), "{p}");
    let res = app
        .client
        .post(app.url("/v1/mesh/distance"))
        .json(&json!({"mesh": id, "sources": [{"vertex": 0}], "method": "nope"}))
        .send()
        .await
        .unwrap();
    assert!(res.status().is_client_error());
    // A mesh has no NPY representation.
    let res = app.get(&format!("/v1/datasets/{id}/data?format=npy")).await;
    problem(res, 406).await;
}

/// `mesh.remesh` through the real server: a valid mesh of the sphere's
/// topology, non-increasing Lloyd energies, and a too-large count refused
/// as a 422 naming `count`.
#[tokio::test]
async fn remesh_keeps_the_sphere_and_refuses_a_large_count() {
    let app = spawn(|_| {}).await;
    let sphere = icosphere(4, 1.0);
    let meta = upload_mesh(&app, write_obj(&sphere), "model/obj", "").await;
    let id = meta["id"].as_str().unwrap();
    let res = post(
        &app,
        "/v1/mesh/remesh",
        json!({"mesh": id, "count": 400, "lloyd_iterations": 3}),
    )
    .await;
    assert_eq!(res.status(), 200);
    let v: serde_json::Value = res.json().await.unwrap();
    let stats = &v["stats"];
    assert_eq!(stats["valid"], true, "{stats}");
    assert_eq!(stats["topology_kept"], true, "{stats}");
    assert_eq!(stats["output_topology"]["genus"], 0, "{stats}");
    let e: Vec<f64> = stats["lloyd_energies"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    assert!(e.len() >= 2, "{e:?}");
    assert!(e.windows(2).all(|w| w[1] <= w[0]), "{e:?}");
    assert!(
        stats["hausdorff_relative"].as_f64().unwrap() < 0.02,
        "{stats}"
    );
    assert!(v["remeshed"]["id"].is_string(), "{v}");
    // The final relaxation ran (its default sweeps for 400 vertices) and
    // moved the vertices; with 0 sweeps it does not run.
    assert_eq!(stats["smoothing_sweeps"], 100, "{stats}");
    assert!(stats["vertex_moves"].as_u64().unwrap() > 0, "{stats}");
    // The covering and mending sweeps report their moves (counts).
    assert!(stats["covering_moves"].is_u64(), "{stats}");
    assert!(stats["mending_moves"].is_u64(), "{stats}");
    let res = post(
        &app,
        "/v1/mesh/remesh",
        json!({"mesh": id, "count": 400, "smoothing_iterations": 0}),
    )
    .await;
    assert_eq!(res.status(), 200);
    let plain: serde_json::Value = res.json().await.unwrap();
    assert_eq!(plain["stats"]["smoothing_sweeps"], 0, "{plain}");
    assert_eq!(plain["stats"]["vertex_moves"], 0, "{plain}");
    assert_eq!(plain["stats"]["covering_moves"], 0, "{plain}");
    assert_eq!(plain["stats"]["mending_moves"], 0, "{plain}");
    // `auto` samples exactly below 8 input vertices per sample (2,562 for
    // 400 here); `clustered` is taken as asked, and refused naming
    // `sampling` under the anisotropic adaptation.
    assert_eq!(stats["sampling"]["method"], "exact", "{stats}");
    assert_eq!(stats["sampling"]["clusters"], 0, "{stats}");
    let res = post(
        &app,
        "/v1/mesh/remesh",
        json!({"mesh": id, "count": 400, "sampling": "clustered"}),
    )
    .await;
    assert_eq!(res.status(), 200);
    let clustered: serde_json::Value = res.json().await.unwrap();
    let s = &clustered["stats"];
    assert_eq!(s["sampling"]["method"], "clustered", "{s}");
    assert!(s["sampling"]["clusters"].as_u64().unwrap() >= 400, "{s}");
    assert_eq!(s["sampling"]["restarted"], false, "{s}");
    assert_eq!(s["valid"], true, "{s}");
    assert_eq!(s["topology_kept"], true, "{s}");
    let p = problem(
        post(
            &app,
            "/v1/mesh/remesh",
            json!({"mesh": id, "count": 400, "sampling": "clustered", "adaptation": "anisotropic"}),
        )
        .await,
        422,
    )
    .await;
    assert!(p.to_string().contains("sampling"), "{p}");
    let p = problem(
        post(
            &app,
            "/v1/mesh/remesh",
            json!({"mesh": id, "count": 400, "smoothing_iterations": 101}),
        )
        .await,
        422,
    )
    .await;
    assert!(p.to_string().contains("smoothing_iterations"), "{p}");
    let p = problem(
        post(&app, "/v1/mesh/remesh", json!({"mesh": id, "count": 5000})).await,
        422,
    )
    .await;
    assert!(p.to_string().contains("count"), "{p}");
    // The anisotropic adaptation runs, and a ratio below 1 is refused naming it.
    let res = post(
        &app,
        "/v1/mesh/remesh",
        json!({"mesh": id, "count": 400, "adaptation": "anisotropic", "max_ratio": 2.0}),
    )
    .await;
    assert_eq!(res.status(), 200);
    let v: serde_json::Value = res.json().await.unwrap();
    assert_eq!(v["stats"]["valid"], true, "{v}");
    let p = problem(
        post(
            &app,
            "/v1/mesh/remesh",
            json!({"mesh": id, "count": 400, "adaptation": "anisotropic", "max_ratio": 0.5}),
        )
        .await,
        422,
    )
    .await;
    assert!(p.to_string().contains("max_ratio"), "{p}");
}

/// `metric` on `mesh.distance` and `mesh.paths` (issue 24 item 4): a
/// constant face tensor (ratio 10 at 30°) gives `sqrt(vᵀMv)` on a flat
/// square; a field design pulls a path onto the field's cheap line; every
/// misuse is a 422 naming the field.
#[tokio::test]
async fn mesh_metrics_designs_and_face_tensors() {
    use geodex::io::ArrayData;
    use geodex::numerics::mesh::shapes::flat_square;
    let app = spawn(|_| {}).await;
    let n = 32;
    let square = flat_square(n, 1.0, 0.0);
    let meta = upload_mesh(&app, write_obj(&square), "model/obj", "").await;
    let id = meta["id"].as_str().unwrap().to_string();
    assert_eq!(meta["mesh"]["vertices"], (n + 1) * (n + 1));

    // R diag(100, 1) Rᵀ, R the rotation by 30°.
    let (c, s) = (30f64.to_radians().cos(), 30f64.to_radians().sin());
    let m = [
        [100.0 * c * c + s * s, 99.0 * c * s, 0.0],
        [99.0 * c * s, 100.0 * s * s + c * c, 0.0],
        [0.0, 0.0, 1.0],
    ];
    let centre = n / 2 * (n + 1) + n / 2;
    let res = post(
        &app,
        "/v1/mesh/distance",
        json!({"mesh": id, "sources": [{"vertex": centre}],
               "metric": {"kind": "tensors", "constant": m}}),
    )
    .await;
    assert_eq!(res.status(), 200, "{:?}", res.text().await);
    let body: serde_json::Value = res.json().await.unwrap();
    let url = body["result"]["data_url"].as_str().unwrap().to_string();
    let ply = app.get(&url).await.bytes().await.unwrap();
    let d = vertex_values(&ply).unwrap().distance.unwrap();
    let pc = square.position(centre as u32);
    let exact: Vec<f64> = (0..square.num_vertices())
        .map(|v| {
            let p = square.position(v as u32);
            let (x, y) = (p[0] - pc[0], p[1] - pc[1]);
            (m[0][0] * x * x + 2.0 * m[0][1] * x * y + m[1][1] * y * y).sqrt()
        })
        .collect();
    let far = exact.iter().cloned().fold(0.0, f64::max) / 4.0;
    let worst = exact
        .iter()
        .zip(&d)
        .filter(|(e, _)| **e >= far)
        .map(|(e, u)| (u - e).abs() / e)
        .fold(0.0, f64::max);
    assert!(worst < 0.03, "largest relative error {worst}");

    // A field equal to x, cheapest at 0.5: the path from (0.125, 0.125) to
    // (0.125, 0.875) detours through the line x = 0.5; without it, it is
    // the straight segment x = 0.125.
    let field: Vec<f64> = square.positions().iter().map(|p| p[0]).collect();
    let nv = field.len();
    let field_id = app
        .upload(&ArrayData::F64(
            ndarray::ArrayD::from_shape_vec(vec![1, nv], field).unwrap(),
        ))
        .await;
    let (a, b) = (4 * (n + 1) + 4, 28 * (n + 1) + 4);
    let path_x = |body: serde_json::Value| {
        body["paths"][0]["points"]
            .as_array()
            .unwrap()
            .iter()
            .map(|p| p["position"][0].as_f64().unwrap())
            .fold(0.0, f64::max)
    };
    let designed = post(
        &app,
        "/v1/mesh/paths",
        json!({"mesh": id, "sources": [{"vertex": a}], "ends": [{"vertex": b}],
               "metric": {"kind": "field", "field": field_id, "mode": "value", "reference": 0.5}}),
    )
    .await;
    assert_eq!(designed.status(), 200, "{:?}", designed.text().await);
    let plain = post(
        &app,
        "/v1/mesh/paths",
        json!({"mesh": id, "sources": [{"vertex": a}], "ends": [{"vertex": b}]}),
    )
    .await;
    let (dx, px) = (
        path_x(designed.json().await.unwrap()),
        path_x(plain.json().await.unwrap()),
    );
    assert!(dx > 0.45, "designed path reaches x = {dx}");
    assert!(px < 0.13, "plain path reaches x = {px}");

    // A curvature design runs (the square is flat: a constant cost).
    let res = post(
        &app,
        "/v1/mesh/voronoi",
        json!({"mesh": id, "sources": [{"vertex": 0}, {"vertex": centre}],
               "metric": {"kind": "curvature", "feature": "ridges"}}),
    )
    .await;
    assert_eq!(res.status(), 200, "{:?}", res.text().await);

    // Sampling under a designed metric, and refused with another method.
    let res = post(
        &app,
        "/v1/mesh/sample",
        json!({"mesh": id, "count": 20,
               "metric": {"kind": "field", "field": field_id, "mode": "value", "reference": 0.5}}),
    )
    .await;
    assert_eq!(res.status(), 200, "{:?}", res.text().await);
    let p = problem(
        post(
            &app,
            "/v1/mesh/sample",
            json!({"mesh": id, "count": 20, "method": "dijkstra",
                   "metric": {"kind": "curvature"}}),
        )
        .await,
        422,
    )
    .await;
    assert!(p.to_string().contains("metric"), "{p}");

    // Misuse: each a 422 naming the field.
    let short = app
        .upload(&ArrayData::F64(
            ndarray::ArrayD::from_shape_vec(vec![1, 5], vec![1.0; 5]).unwrap(),
        ))
        .await;
    for (metric, extra, field) in [
        (
            json!({"kind": "curvature"}),
            json!({"weights": short}),
            "metric",
        ),
        (
            json!({"kind": "curvature_tensors"}),
            json!({"method": "heat"}),
            "metric",
        ),
        (
            json!({"kind": "curvature"}),
            json!({"method": "exact"}),
            "metric",
        ),
        (
            json!({"kind": "field", "field": short}),
            json!({}),
            "metric.field",
        ),
        (
            json!({"kind": "field", "field": short, "mode": "value"}),
            json!({}),
            "metric.reference",
        ),
        (
            json!({"kind": "tensors", "constant": [[1, 0, 0], [0, -1, 0], [0, 0, 1]]}),
            json!({}),
            "metric.constant",
        ),
        (
            json!({"kind": "tensors", "constant": [[1, 2, 0], [0, 1, 0], [0, 0, 1]]}),
            json!({}),
            "metric.constant",
        ),
        (json!({"kind": "tensors"}), json!({}), "metric"),
        (
            json!({"kind": "tensors", "dataset": short}),
            json!({}),
            "metric.dataset",
        ),
        (
            json!({"kind": "curvature_tensors", "max_ratio": 0.5}),
            json!({}),
            "metric.max_ratio",
        ),
        (
            json!({"kind": "curvature", "epsilon": 0}),
            json!({}),
            "metric.epsilon",
        ),
    ] {
        let mut req = json!({"mesh": id, "sources": [{"vertex": 0}], "metric": metric});
        for (k, v) in extra.as_object().unwrap() {
            req[k] = v.clone();
        }
        let p = problem(post(&app, "/v1/mesh/distance", req.clone()).await, 422).await;
        assert!(p.to_string().contains(field), "{req}: {p}");
    }
    problem(
        post(
            &app,
            "/v1/mesh/distance",
            json!({"mesh": id, "sources": [{"vertex": 0}],
                   "metric": {"kind": "field", "field": "ds_00000000000000000000000000000000"}}),
        )
        .await,
        404,
    )
    .await;
}

/// `POST /v1/mesh/curvature`: on a sphere of radius 2 every vertex has
/// `k1 = k2 = 1/2`, `H = 1/2`, `K = 1/4` within 2 %; the result mesh
/// carries `H` as its `value`, the directions are unit tangent
/// vectors, the same request runs as a job, and too much smoothing is a
/// 422 naming `smoothing`.
#[tokio::test]
async fn mesh_curvature_of_a_sphere() {
    let app = spawn(|_| {}).await;
    let sphere = icosphere(4, 2.0);
    let meta = upload_mesh(&app, write_obj(&sphere), "model/obj", "").await;
    let id = meta["id"].as_str().unwrap().to_string();
    let res = post(&app, "/v1/mesh/curvature", json!({"mesh": id})).await;
    assert_eq!(res.status(), 200, "{:?}", res.text().await);
    let body: serde_json::Value = res.json().await.unwrap();
    assert_eq!(body["smoothing"], 1);
    for (name, exact) in [("k1", 0.5), ("k2", 0.5), ("mean", 0.5), ("gaussian", 0.25)] {
        for k in ["min", "max"] {
            let x = body["stats"][name][k].as_f64().unwrap();
            assert!((x - exact).abs() <= 0.02 * exact, "{name}.{k} = {x}");
        }
    }
    let url = body["result"]["data_url"].as_str().unwrap().to_string();
    let j: serde_json::Value = app
        .get(&format!("{url}?format=json"))
        .await
        .json()
        .await
        .unwrap();
    let mean = j["properties"]["value"].as_array().unwrap();
    assert_eq!(mean.len(), sphere.num_vertices());
    assert!(mean
        .iter()
        .all(|h| (h.as_f64().unwrap() - 0.5).abs() < 0.01));
    // d1: unit, orthogonal to the returned normal, which is within 1° of
    // the position's direction on a sphere.
    let array = |key: &'static str| {
        let body = body.clone();
        let app = &app;
        async move {
            match app.download(&body[key]).await {
                geodex::io::ArrayData::F64(a) => a,
                other => panic!("{other:?}"),
            }
        }
    };
    let (d1, normal) = (array("d1").await, array("normal").await);
    assert_eq!(d1.shape(), &[sphere.num_vertices(), 3]);
    for v in 0..sphere.num_vertices() {
        let p = sphere.position(v as u32);
        let d = [d1[[v, 0]], d1[[v, 1]], d1[[v, 2]]];
        let n = [normal[[v, 0]], normal[[v, 1]], normal[[v, 2]]];
        let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        let across = d[0] * n[0] + d[1] * n[1] + d[2] * n[2];
        let radial = (n[0] * p[0] + n[1] * p[1] + n[2] * p[2]) / 2.0;
        assert!(
            (len - 1.0).abs() < 1e-9 && across.abs() < 1e-9,
            "{v}: {d:?}"
        );
        assert!(radial > 1f64.to_radians().cos(), "{v}: {n:?}");
    }
    // As a job.
    let job: serde_json::Value = post(
        &app,
        "/v1/jobs",
        json!({"operation": "mesh.curvature", "params": {"mesh": id, "smoothing": 0}}),
    )
    .await
    .json()
    .await
    .unwrap();
    let job_id = job["id"].as_str().expect("job id").to_string();
    let mut done = serde_json::Value::Null;
    for _ in 0..200 {
        done = app
            .get(&format!("/v1/jobs/{job_id}"))
            .await
            .json()
            .await
            .unwrap();
        if ["succeeded", "failed", "cancelled"].contains(&done["state"].as_str().unwrap_or("")) {
            break;
        }
        tokio::time::sleep(std::time::Duration::from_millis(50)).await;
    }
    assert_eq!(done["state"], "succeeded", "{done}");
    let p = problem(
        post(
            &app,
            "/v1/mesh/curvature",
            json!({"mesh": id, "smoothing": 2000}),
        )
        .await,
        422,
    )
    .await;
    assert!(p.to_string().contains("smoothing"), "{p}");
}
