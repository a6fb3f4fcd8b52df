//! `POST /v1/grid/cost-gradient` over HTTP: the discrete adjoint against
//! its own objective perturbed (finite differences through the endpoint),
//! Euler's identity, the speed reading, the misfit, a job, and the 4xx.

use geodex::io::ArrayData;
use ndarray::ArrayD;
use serde_json::json;

use crate::common::{f64_values, problem, spawn, wavy_cost, TestApp};

async fn post(app: &TestApp, body: &serde_json::Value) -> reqwest::Response {
    app.client
        .post(app.url("/v1/grid/cost-gradient"))
        .json(body)
        .send()
        .await
        .expect("post")
}

async fn ok(app: &TestApp, body: &serde_json::Value) -> serde_json::Value {
    let res = post(app, body).await;
    let status = res.status();
    let text = res.text().await.expect("body");
    assert_eq!(status, 200, "{body}: {text}");
    serde_json::from_str(&text).expect("json")
}

#[tokio::test]
async fn straight_line_gradient_sums_to_the_length_on_its_row() {
    let app = spawn(|_| {}).await;
    // W = 1, a source and a target on row 20, 40 cells apart: U = 40 exactly
    // (first order, along an axis), and every cell of the row between them
    // adds its length, so the gradient is 1 there and 0 elsewhere.
    let body = json!({
        "cost": {"constant": 1.0, "shape": [41, 51]},
        "sources": [{"point": [20.0, 5.0]}],
        "targets": [{"point": [20.0, 45.0]}],
        "order": 1
    });
    let v = ok(&app, &body).await;
    assert_eq!(v["with_respect_to"], "cost");
    let j = v["objective"]["value"].as_f64().expect("value");
    assert!((j - 40.0).abs() < 1e-9, "{v}");
    assert_eq!(v["targets"][0]["distance"], v["objective"]["value"]);
    assert_eq!(v["gradient"]["shape"], json!([41, 51]));
    let g = f64_values(&app, &v["gradient"]).await;
    let row: f64 = g[20 * 51..21 * 51].iter().sum();
    let all: f64 = g.iter().sum();
    assert!((row - 40.0).abs() < 1e-9, "row sum {row}");
    assert!((all - 40.0).abs() < 1e-9, "total {all}");
    let u = f64_values(&app, &v["distance"]).await;
    assert_eq!(u.len(), 41 * 51);
    assert!((u[20 * 51 + 45] - 40.0).abs() < 1e-9);
}

/// The objective of `body` with the cost dataset replaced by `cost`.
async fn objective(app: &TestApp, body: &serde_json::Value, cost: &ArrayD<f64>) -> f64 {
    let id = app.upload(&ArrayData::F64(cost.clone())).await;
    let mut body = body.clone();
    body["cost"]["dataset"] = json!(id);
    body["distance"] = json!(false);
    ok(app, &body).await["objective"]["value"]
        .as_f64()
        .expect("value")
}

#[tokio::test]
async fn gradient_matches_finite_differences_of_its_own_objective() {
    let app = spawn(|_| {}).await;
    let (n0, n1) = (33, 29);
    let cost = wavy_cost(n0, n1);
    let id = app.upload(&ArrayData::F64(cost.clone())).await;
    // A smooth perturbation direction δ.
    let delta = ArrayD::from_shape_fn(ndarray::IxDyn(&[n0, n1]), |ix| {
        let (a, b) = (ix[0] as f64 / n0 as f64, ix[1] as f64 / n1 as f64);
        (3.0 * a).sin() * (2.0 * b).cos() + 0.5
    });
    for (order, objective_kind) in [(1, "sum"), (2, "sum"), (2, "misfit")] {
        let body = json!({
            "cost": {"dataset": id},
            "sources": [{"point": [3.0, 4.0]}, {"point": [28.5, 6.0]}],
            "targets": [
                {"point": [30.0, 25.0], "weight": 1.0, "observed": 20.0},
                {"point": [10.25, 26.5], "weight": 0.5, "observed": 30.0},
                {"point": [16.0, 14.0], "weight": 2.0, "observed": 5.0}
            ],
            "objective": objective_kind,
            "order": order
        });
        let v = ok(&app, &body).await;
        let g = f64_values(&app, &v["gradient"]).await;
        let directional: f64 = g.iter().zip(delta.iter()).map(|(g, d)| g * d).sum();
        let eps = 1e-5;
        let plus = objective(&app, &body, &(&cost + &(&delta * eps))).await;
        let minus = objective(&app, &body, &(&cost - &(&delta * eps))).await;
        let fd = (plus - minus) / (2.0 * eps);
        let rel = (directional - fd).abs() / fd.abs().max(1e-12);
        assert!(
            rel < 1e-5,
            "order {order}, {objective_kind}: adjoint {directional}, finite difference {fd} (rel {rel:.2e})"
        );
        if objective_kind == "misfit" {
            let r = v["targets"][0]["residual"].as_f64().expect("residual");
            let u = v["targets"][0]["distance"].as_f64().expect("distance");
            assert!((r - (u - 20.0)).abs() < 1e-12);
        }
    }
}

#[tokio::test]
async fn speed_gradient_obeys_euler_identity_of_degree_minus_one() {
    let app = spawn(|_| {}).await;
    // U is homogeneous of degree -1 in the speed F: Σ F ∂U/∂F = -U.
    let speed = ArrayD::from_shape_fn(ndarray::IxDyn(&[24, 30]), |ix| {
        1.0 + 0.5 * ((ix[0] as f64) / 5.0).sin() * ((ix[1] as f64) / 7.0).cos()
    });
    let id = app.upload(&ArrayData::F64(speed.clone())).await;
    for order in [1, 2] {
        let v = ok(
            &app,
            &json!({
                "cost": {"dataset": id, "interpretation": "speed"},
                "sources": [{"point": [2.0, 2.0]}],
                "targets": [{"point": [20.0, 27.0]}],
                "order": order,
                "distance": false
            }),
        )
        .await;
        assert_eq!(v["with_respect_to"], "speed");
        assert!(v.get("distance").is_none_or(|d| d.is_null()), "{v}");
        let g = f64_values(&app, &v["gradient"]).await;
        let euler: f64 = g.iter().zip(speed.iter()).map(|(g, f)| g * f).sum();
        let j = v["objective"]["value"].as_f64().expect("value");
        assert!(
            (euler + j).abs() < 1e-9 * j,
            "order {order}: Σ F ∂U/∂F = {euler}, U = {j}"
        );
        if order == 1 {
            // The first-order scheme is monotone: a faster cell never
            // lengthens the path. (Order 2 is not: its second upwind cell
            // enters with a negative coefficient.)
            assert!(g.iter().all(|&x| x <= 0.0), "a positive ∂U/∂F at order 1");
        }
    }
}

#[tokio::test]
async fn cost_gradient_runs_as_a_job() {
    let app = spawn(|_| {}).await;
    let res = app
        .client
        .post(app.url("/v1/jobs"))
        .json(&json!({"operation": "grid.cost_gradient", "params": {
            "cost": {"constant": 2.0, "shape": [16, 16]},
            "sources": [{"point": [0.0, 0.0]}],
            "targets": [{"point": [0.0, 15.0]}],
            "order": 1
        }}))
        .send()
        .await
        .expect("submit");
    assert_eq!(
        res.status(),
        202,
        "{}",
        res.text().await.unwrap_or_default()
    );
    let job: serde_json::Value = res.json().await.expect("json");
    let id = job["id"].as_str().expect("id").to_string();
    for _ in 0..200 {
        let v: serde_json::Value = app
            .get(&format!("/v1/jobs/{id}"))
            .await
            .json()
            .await
            .expect("json");
        match v["state"].as_str() {
            Some("succeeded") => {
                let r = &v["result"];
                let j = r["objective"]["value"].as_f64().expect("value");
                assert!((j - 30.0).abs() < 1e-9, "{v}");
                assert!(r["gradient"]["url"].is_string(), "{v}");
                return;
            }
            Some("failed" | "cancelled") => panic!("{v}"),
            _ => tokio::time::sleep(std::time::Duration::from_millis(50)).await,
        }
    }
    panic!("the job did not finish");
}

#[tokio::test]
async fn cost_gradient_refusals_name_the_field() {
    let app = spawn(|_| {}).await;
    let walled = app
        .upload(&ArrayData::F64(ArrayD::from_shape_fn(
            ndarray::IxDyn(&[10, 10]),
            |ix| if ix[1] == 5 { f64::INFINITY } else { 1.0 },
        )))
        .await;
    let phi = app
        .upload(&ArrayData::F64(ArrayD::from_elem(
            ndarray::IxDyn(&[10, 10]),
            1.0,
        )))
        .await;
    let cost = json!({"constant": 1.0, "shape": [10, 10]});
    let src = json!([{"point": [1.0, 1.0]}]);
    for (body, field) in [
        (
            json!({"cost": cost, "sources": src, "targets": []}),
            "targets",
        ),
        (
            json!({"cost": cost, "sources": src, "targets": [{"point": [1.0, 2.0]}, {"point": [10.5, 2.0]}]}),
            "targets[1].point",
        ),
        (
            json!({"cost": cost, "sources": src, "targets": [{"point": [1.0, 2.0, 3.0]}]}),
            "targets[0].point",
        ),
        (
            json!({"cost": cost, "sources": src, "targets": [{"point": [1.0, 2.0]}], "objective": "misfit"}),
            "targets[0].observed",
        ),
        (
            json!({"cost": cost, "sources": [{"level_set": phi}], "targets": [{"point": [1.0, 2.0]}]}),
            "sources[0].level_set",
        ),
        (
            json!({"cost": cost, "sources": src, "targets": [{"point": [1.0, 2.0]}], "order": 3}),
            "order",
        ),
        (
            json!({"cost": cost, "sources": [], "targets": [{"point": [1.0, 2.0]}]}),
            "sources",
        ),
        (
            json!({"cost": {"dataset": walled}, "sources": src, "targets": [{"point": [1.0, 8.0]}]}),
            "targets[0].point",
        ),
        (
            json!({"cost": {"dataset": "ds_missing"}, "sources": src, "targets": [{"point": [1.0, 2.0]}]}),
            "cost.dataset",
        ),
    ] {
        let res = post(&app, &body).await;
        let status = res.status().as_u16();
        assert!(status == 422 || status == 404, "{body}: {status}");
        let v = problem(res, status).await;
        assert_eq!(v["field"], field, "{body}: {v}");
    }
}

#[tokio::test]
async fn metric_gradient_matches_finite_differences_and_euler_identity() {
    let app = spawn(|_| {}).await;
    let (n0, n1) = (21, 19);
    // A smooth SPD field [m00, m01, m11] and a symmetric direction δ.
    let field = |eps: f64| {
        ArrayD::from_shape_fn(ndarray::IxDyn(&[n0, n1, 3]), |ix| {
            let (a, b) = (ix[0] as f64 / n0 as f64, ix[1] as f64 / n1 as f64);
            let m = [
                2.0 + (3.0 * a).sin(),
                0.6 * (2.0 * b).cos(),
                1.5 + 0.5 * (4.0 * a * b).cos(),
            ];
            let d = [(2.0 * b).sin() + 0.3, 0.4 * (a - b), (3.0 * a).cos()];
            m[ix[2]] + eps * d[ix[2]]
        })
    };
    let body = |id: &str, order: u8| {
        json!({
            "metric": {"kind": "components", "dataset": id},
            "sources": [{"point": [2.0, 3.0]}],
            "targets": [{"point": [18.0, 15.0]}, {"point": [6.5, 16.25], "weight": 0.5}],
            "order": order,
            "distance": false
        })
    };
    let base = field(0.0);
    let id = app.upload(&ArrayData::F64(base.clone())).await;
    for order in [1u8, 2] {
        let v = ok(&app, &body(&id, order)).await;
        assert_eq!(v["with_respect_to"], "metric");
        assert_eq!(v["gradient"]["shape"], json!([n0, n1, 3]));
        let g = f64_values(&app, &v["gradient"]).await;
        let j = v["objective"]["value"].as_f64().expect("value");
        // U is homogeneous of degree 1/2 in M.
        let euler: f64 = g.iter().zip(base.iter()).map(|(g, m)| g * m).sum();
        assert!(
            (euler - 0.5 * j).abs() < 1e-9 * j,
            "order {order}: {euler} vs {j}/2"
        );
        let eps = 1e-5;
        let mut js = Vec::new();
        for e in [eps, -eps] {
            let id = app.upload(&ArrayData::F64(field(e))).await;
            js.push(
                ok(&app, &body(&id, order)).await["objective"]["value"]
                    .as_f64()
                    .expect("value"),
            );
        }
        let fd = (js[0] - js[1]) / (2.0 * eps);
        let delta = &field(1.0) - &base;
        let directional: f64 = g.iter().zip(delta.iter()).map(|(g, d)| g * d).sum();
        let rel = (directional - fd).abs() / fd.abs();
        assert!(
            rel < 1e-4,
            "order {order}: adjoint {directional}, FD {fd} (rel {rel:.2e})"
        );
    }
    // Both metrics, or neither: named.
    for (body, field) in [
        (
            json!({"cost": {"constant": 1.0, "shape": [5, 5]}, "metric": {"kind": "components", "dataset": id}, "sources": [{"point": [0.0, 0.0]}], "targets": [{"point": [1.0, 1.0]}]}),
            "metric",
        ),
        (
            json!({"sources": [{"point": [0.0, 0.0]}], "targets": [{"point": [1.0, 1.0]}]}),
            "cost",
        ),
    ] {
        let res = post(&app, &body).await;
        let v = problem(res, 422).await;
        assert_eq!(v["field"], field, "{body}: {v}");
    }
}
