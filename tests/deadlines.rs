//! Every solve stops when asked (issue 20, item 1): for every operation of
//! the registry, an input built to be slow is run with a short deadline as
//! a synchronous request (504, and the pool slot is free again within 1 s
//! of the deadline), after a client disconnect (the slot is free within
//! 1 s), and as a job with a time limit (failed `time-limit`) and with a
//! cancel (`cancelled` within 1 s). An operation added to
//! `ops::registry::ENTRIES` without a slow case here fails the test.
//!
//! A test binary of its own: its bounds are about responsiveness, and the
//! other HTTP tests running beside it on a 2-core machine would blur them.

use std::time::{Duration, Instant};

use geodex::io::mesh::write::write_ply;
use geodex::io::ArrayData;
use geodex::numerics::mesh::shapes::icosphere;
use ndarray::ArrayD;
use serde_json::{json, Value};

#[allow(dead_code)]
#[path = "service_api/common.rs"]
mod common;

use common::{spawn, TestApp};

/// The sync deadline of the first server (seconds).
const DEADLINE: f64 = 0.3;
/// How long after the deadline (or the disconnect, or the cancel) the solve
/// must have let go of its pool slot.
const STOP_WITHIN: Duration = Duration::from_secs(1);

async fn upload_mesh(app: &TestApp, level: u32) -> String {
    let body = write_ply(&icosphere(level, 1.0), &[]);
    let res = app
        .client
        .post(app.url("/v1/datasets"))
        .header("content-type", "model/ply")
        .body(body)
        .send()
        .await
        .expect("upload");
    assert_eq!(res.status(), 201);
    let v: Value = res.json().await.expect("json");
    v["id"].as_str().expect("id").to_string()
}

/// A disc image, `n × n`, values in [0, 1] (also a mask: non-zero inside).
fn disc(n: usize) -> ArrayData {
    let c = n as f64 / 2.0;
    ArrayData::F64(ArrayD::from_shape_fn(ndarray::IxDyn(&[n, n]), |ix| {
        let (x, y) = (ix[0] as f64 - c, ix[1] as f64 - c);
        let r = (x * x + y * y).sqrt() / c;
        if r < 0.9 {
            (1.0 - r * r).sqrt()
        } else {
            0.0
        }
    }))
}

/// Uploads `array` for a slow case. The upload is the setup, not what is
/// tested, but it is decoded on the pool under this server's short sync
/// deadline; on a busy machine a large one can miss it (504), and then it is
/// sent again.
async fn upload(app: &TestApp, array: &ArrayData) -> String {
    let body = geodex::io::encode_npy(array).expect("encode npy");
    for _ in 0..10 {
        let res = app
            .client
            .post(app.url("/v1/datasets"))
            .header("content-type", "application/x-npy")
            .body(body.clone())
            .send()
            .await
            .expect("upload");
        match res.status().as_u16() {
            201 => {
                let meta: Value = res.json().await.expect("json");
                return meta["id"].as_str().expect("id").to_string();
            }
            504 => tokio::time::sleep(Duration::from_millis(200)).await,
            other => panic!("upload: {other} {:?}", res.text().await),
        }
    }
    panic!("the upload missed the deadline ten times");
}

/// `(operation, route, body)`: one slow request per operation.
async fn slow_cases(app: &TestApp) -> Vec<(&'static str, &'static str, Value)> {
    let n = 3000;
    let image = upload(app, &disc(n)).await;
    let small_image = upload(app, &disc(1000)).await;
    let ArrayData::F64(lit) = disc(n) else {
        unreachable!("disc is f64")
    };
    // Lit everywhere (shape from shading refuses shadowed anchors).
    let shaded = upload(app, &ArrayData::F64(lit.mapv(|v| 0.2 + 0.8 * v))).await;
    // The EDT is linear and fast: it needs a larger mask to outlast a job's
    // time limit plus a heartbeat.
    let big_mask = upload(
        app,
        &ArrayData::U8(ArrayD::from_shape_fn(ndarray::IxDyn(&[6000, 6000]), |ix| {
            u8::from((ix[0] / 7 + ix[1] / 5) % 3 == 0)
        })),
    )
    .await;
    let empty = upload(app, &ArrayData::U8(ArrayD::zeros(ndarray::IxDyn(&[n, n])))).await;
    let mut cloud = Vec::with_capacity(20000 * 3);
    let mut state = 1u64;
    for _ in 0..20000 * 3 {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        cloud.push((state >> 11) as f64 / (1u64 << 53) as f64);
    }
    let points = upload(
        app,
        &ArrayData::F64(ArrayD::from_shape_vec(vec![20000, 3], cloud).expect("shape")),
    )
    .await;
    let mesh = upload_mesh(app, 6).await;
    let big = json!({"constant": 1.0, "shape": [n, n]});
    let src = json!([{"point": [1.0, 1.0]}]);
    let far = json!([(n - 1) as f64, (n - 1) as f64]);
    vec![
        (
            "grid.distance",
            "/v1/grid/distance",
            json!({"cost": big, "sources": src}),
        ),
        (
            "grid.metric",
            "/v1/grid/metric",
            json!({"cost": {"dataset": image, "design": {"kind": "vesselness", "scales": [2.0, 4.0, 8.0]}}}),
        ),
        (
            "grid.paths",
            "/v1/grid/paths",
            json!({"cost": big, "sources": src, "ends": [far]}),
        ),
        (
            "grid.edt",
            "/v1/grid/edt",
            json!({"mask": big_mask, "features": false}),
        ),
        (
            "grid.segment",
            "/v1/grid/segment",
            json!({"cost": big, "seeds": [{"label": 1, "point": [1.0, 1.0]}, {"label": 2, "point": far}]}),
        ),
        ("grid.skeleton", "/v1/grid/skeleton", json!({"mask": image})),
        (
            "grid.shape_embed",
            "/v1/grid/shape-embed",
            json!({"mask": small_image, "landmarks": 100}),
        ),
        (
            "grid.offset",
            "/v1/grid/offset",
            json!({"mask": image, "radius": 400.0, "metric": "geodesic", "cost": big}),
        ),
        (
            "grid.plan",
            "/v1/grid/plan",
            json!({"obstacles": empty, "radius": 2.0, "start": [1.0, 1.0], "goal": far}),
        ),
        (
            "grid.sample",
            "/v1/grid/sample",
            json!({"cost": big, "count": 20000}),
        ),
        (
            "grid.mesh",
            "/v1/grid/mesh",
            json!({"dataset": small_image, "count": 20000}),
        ),
        (
            "domain.mesh",
            "/v1/domain/mesh",
            json!({"polygons": {"type": "Polygon", "coordinates": [[[0, 0], [2999, 0], [2999, 2999], [0, 2999]]]},
                   "cost": shaded, "count": 3_000_000}),
        ),
        (
            "mesh.remesh",
            "/v1/mesh/remesh",
            json!({"mesh": mesh, "count": 20000}),
        ),
        (
            "grid.shape_from_shading",
            "/v1/grid/shape-from-shading",
            json!({"image": shaded, "anchors": {"kind": "border"}}),
        ),
        (
            "grid.cost_gradient",
            "/v1/grid/cost-gradient",
            json!({"cost": {"constant": 1.0, "shape": [n, n]}, "sources": src, "targets": [{"point": [0.0, 0.0]}], "distance": false}),
        ),
        (
            "grid.tomography",
            "/v1/grid/tomography",
            json!({"shape": [2000, 2000], "sources": [{"point": [0.0, 0.0]}, {"point": [0.0, 1999.0]}],
                   "receivers": [{"point": [1999.0, 0.0]}, {"point": [1999.0, 1999.0]}],
                   "times": [[2000.0, 2800.0], [2800.0, 2000.0]]}),
        ),
        (
            "grid.fit_metric",
            "/v1/grid/fit-metric",
            json!({"image": small_image, "examples": [[[1.0, 1.0], [500.0, 700.0], [998.0, 998.0]]]}),
        ),
        (
            "grid.shape_from_shading",
            "/v1/grid/shape-from-shading",
            json!({"image": shaded, "camera": {"kind": "perspective", "focal": 3000.0}, "mesh": false}),
        ),
        (
            "grid.shape_from_shading",
            "/v1/grid/shape-from-shading",
            json!({"image": shaded, "light": [0.2, 0.1, 1.0], "mesh": false}),
        ),
        (
            "grid.group",
            "/v1/grid/group",
            json!({"cost": big, "key_points": (0..400).map(|k| [7.0 * (k / 20) as f64 + 3.0, 7.0 * (k % 20) as f64 + 3.0]).collect::<Vec<_>>()}),
        ),
        (
            "grid.tensor_distance",
            "/v1/grid/tensor-distance",
            json!({"metric": {"kind": "eigen", "shape": [n, n], "eigenvalues": [1.0, 4.0], "direction": [1.0, 1.0]}, "sources": src}),
        ),
        (
            "grid.tensor_metric",
            "/v1/grid/tensor-metric",
            json!({"metric": {"kind": "structure_tensor", "image": image, "sigma": 4.0, "rho": 8.0, "energy": 1.0, "anisotropy": 0.9}}),
        ),
        (
            "mesh.distance",
            "/v1/mesh/distance",
            json!({"mesh": mesh, "sources": [{"vertex": 0}], "method": "exact"}),
        ),
        (
            "mesh.voronoi",
            "/v1/mesh/voronoi",
            json!({"mesh": mesh, "sources": [{"vertex": 0}, {"vertex": 7}], "method": "exact"}),
        ),
        (
            "mesh.curvature",
            "/v1/mesh/curvature",
            json!({"mesh": mesh, "smoothing": 1024}),
        ),
        (
            "mesh.paths",
            "/v1/mesh/paths",
            json!({"mesh": mesh, "sources": [{"vertex": 0}], "ends": [{"vertex": 9}], "method": "exact"}),
        ),
        (
            "mesh.sample",
            "/v1/mesh/sample",
            json!({"mesh": mesh, "count": 200, "method": "exact"}),
        ),
        (
            "mesh.distance_matrix",
            "/v1/mesh/distance-matrix",
            json!({"mesh": mesh, "landmarks": 200, "method": "exact"}),
        ),
        (
            "mesh.embed",
            "/v1/mesh/embed",
            json!({"mesh": mesh, "landmarks": 200, "method": "exact"}),
        ),
        (
            "mesh.descriptor",
            "/v1/mesh/descriptor",
            json!({"mesh": mesh, "landmarks": 200, "method": "exact"}),
        ),
        (
            "mesh.correspond",
            "/v1/mesh/correspond",
            json!({"a": mesh, "b": mesh, "landmarks": 500}),
        ),
        (
            "points.isomap",
            "/v1/points/isomap",
            json!({"points": points, "k": 12, "landmarks": 1000}),
        ),
    ]
}

/// Solves waiting or running on this server's pool, from `/readyz`.
async fn in_flight(app: &TestApp) -> u64 {
    let res = app.get("/readyz").await;
    if res.status() != 200 {
        return u64::MAX; // not ready: the pool is full
    }
    let v: Value = res.json().await.expect("readyz");
    v["running"].as_u64().unwrap_or(0) + v["queued"].as_u64().unwrap_or(0)
}

/// Waits until no solve runs; returns how long that took.
async fn until_idle(app: &TestApp, op: &str) -> Duration {
    let t = Instant::now();
    while in_flight(app).await > 0 {
        assert!(
            t.elapsed() < Duration::from_secs(30),
            "{op}: the solve never stopped"
        );
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    t.elapsed()
}

/// Polls job `id` until `done(state)` holds; panics after 30 s.
async fn wait_job(app: &TestApp, id: &str, what: &str, done: impl Fn(&str) -> bool) -> Value {
    let t = Instant::now();
    loop {
        let j: Value = app
            .get(&format!("/v1/jobs/{id}"))
            .await
            .json()
            .await
            .expect("job");
        if done(j["state"].as_str().unwrap_or("")) {
            return j;
        }
        assert!(t.elapsed() < Duration::from_secs(30), "{what}: {j}");
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn every_operation_stops_at_its_deadline_on_disconnect_and_as_a_job() {
    let app = spawn(|s| {
        s.pool_threads = Some(1);
        s.queue_capacity = Some(4);
        s.request_timeout_secs = DEADLINE;
        s.max_body_bytes = 512 << 20;
    })
    .await;
    let cases = slow_cases(&app).await;
    for e in geodex::ops::registry::ENTRIES {
        assert!(
            cases.iter().any(|c| c.0 == e.name),
            "operation {} has no slow case in tests/service_api/deadlines.rs",
            e.name
        );
    }
    // Synchronous requests: 504 at the deadline, the slot free soon after.
    for (op, route, body) in &cases {
        until_idle(&app, op).await;
        let t = Instant::now();
        let res = app
            .client
            .post(app.url(route))
            .json(body)
            .send()
            .await
            .expect("post");
        let status = res.status().as_u16();
        let text = res.text().await.unwrap_or_default();
        assert_eq!(status, 504, "{op}: {text}");
        until_idle(&app, op).await;
        let freed = t.elapsed();
        assert!(
            freed < Duration::from_secs_f64(DEADLINE) + STOP_WITHIN,
            "{op}: the slot was freed {freed:?} after the request (deadline {DEADLINE} s)"
        );
    }

    // A client that gives up: the solve stops within a second.
    let patient = spawn(|s| {
        s.pool_threads = Some(1);
        s.request_timeout_secs = 600.0;
        s.max_body_bytes = 512 << 20;
    })
    .await;
    let cases = slow_cases(&patient).await;
    for (op, route, body) in &cases {
        until_idle(&patient, op).await;
        let quitter = reqwest::Client::builder()
            .timeout(Duration::from_millis(300))
            .build()
            .expect("client");
        let t = Instant::now();
        let res = quitter.post(patient.url(route)).json(body).send().await;
        assert!(
            res.is_err(),
            "{op}: answered within 300 ms; not a slow case"
        );
        let gone = t.elapsed();
        let freed = until_idle(&patient, op).await;
        assert!(
            freed < STOP_WITHIN,
            "{op}: the solve ran {freed:?} after its client left (at {gone:?})"
        );
    }

    // Jobs: a time limit ends the job `failed`, a cancel ends it `cancelled`.
    for (op, _, body) in &cases {
        let submit = |limit: Option<f64>| {
            let mut job = json!({"operation": op, "params": body});
            if let Some(l) = limit {
                job["time_limit_secs"] = json!(l);
            }
            job
        };
        let res = patient
            .client
            .post(patient.url("/v1/jobs"))
            .json(&submit(Some(0.3)))
            .send()
            .await
            .expect("submit");
        assert_eq!(res.status(), 202, "{op}");
        let id = res.json::<Value>().await.expect("json")["id"]
            .as_str()
            .expect("id")
            .to_string();
        let job = wait_job(&patient, &id, op, |st| {
            ["failed", "succeeded", "cancelled"].contains(&st)
        })
        .await;
        assert_eq!(job["state"], "failed", "{op}: {job}");
        assert_eq!(
            job["error"]["type"], "https://geodex.dev/problems/time-limit",
            "{op}: {job}"
        );
        until_idle(&patient, op).await;

        let res = patient
            .client
            .post(patient.url("/v1/jobs"))
            .json(&submit(None))
            .send()
            .await
            .expect("submit");
        let id = res.json::<Value>().await.expect("json")["id"]
            .as_str()
            .expect("id")
            .to_string();
        wait_job(&patient, &id, &format!("{op}: never ran"), |st| {
            st == "running"
        })
        .await;
        let cancelled_at = Instant::now();
        let res = patient
            .client
            .post(patient.url(&format!("/v1/jobs/{id}/cancel")))
            .json(&json!({}))
            .send()
            .await
            .expect("cancel");
        assert!(res.status().is_success(), "{op}: cancel {}", res.status());
        wait_job(&patient, &id, &format!("{op}: not cancelled"), |st| {
            st == "cancelled"
        })
        .await;
        until_idle(&patient, op).await;
        let freed = cancelled_at.elapsed();
        assert!(
            freed < STOP_WITHIN + Duration::from_millis(500),
            "{op}: the cancelled job held the pool {freed:?} after the cancel"
        );
    }
}
