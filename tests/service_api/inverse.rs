//! `POST /v1/grid/tomography` and `POST /v1/grid/fit-metric` over HTTP, as a
//! job, and their 4xx naming the field.

use std::time::{Duration, Instant};

use geodex::io::ArrayData;
use ndarray::ArrayD;
use serde_json::{json, Value};

use crate::common::{problem, spawn, TestApp};

async fn post(app: &TestApp, path: &str, body: &Value) -> reqwest::Response {
    app.client
        .post(app.url(path))
        .json(body)
        .send()
        .await
        .expect("post")
}

/// 24 × 24, sources on the left and top edges, receivers on the right and
/// bottom ones; the times of the constant slowness 2 at the straight
/// distances (the solver's are within its first-order error of them).
fn small_tomography() -> Value {
    let sources: Vec<[f64; 2]> = (0..4).map(|k| [0.0, 2.0 + 6.0 * k as f64]).collect();
    let receivers: Vec<[f64; 2]> = (0..4).map(|k| [23.0, 1.0 + 7.0 * k as f64]).collect();
    let times: Vec<Vec<f64>> = sources
        .iter()
        .map(|s| {
            receivers
                .iter()
                .map(|r| 2.0 * ((r[0] - s[0]).powi(2) + (r[1] - s[1]).powi(2)).sqrt())
                .collect()
        })
        .collect();
    let points = |p: &[[f64; 2]]| p.iter().map(|p| json!({"point": p})).collect::<Vec<_>>();
    json!({"shape": [24, 24], "sources": points(&sources), "receivers": points(&receivers), "times": times,
           "alpha": 0.1, "max_iterations": 5})
}

#[tokio::test]
async fn tomography_recovers_a_constant_slowness_over_http_and_as_a_job() {
    let app = spawn(|_| {}).await;
    let body = small_tomography();
    let res = post(&app, "/v1/grid/tomography", &body).await;
    assert_eq!(res.status(), 200);
    let v: Value = res.json().await.expect("json");
    let c = v["constant_cost"].as_f64().expect("constant");
    // The straight lengths overestimate nothing: the solver's first-order
    // distances are a few percent longer on the diagonals, so c* < 2.
    assert!((c - 2.0).abs() < 0.15, "{v}");
    let history: Vec<f64> = v["misfit"]["history"]
        .as_array()
        .expect("history")
        .iter()
        .map(|x| x.as_f64().expect("number"))
        .collect();
    assert!(!history.is_empty());
    assert!(history.windows(2).all(|w| w[1] <= w[0]), "{history:?}");
    assert_eq!(v["misfit"]["constant"], history[0]);
    assert_eq!(v["cost"]["shape"], json!([24, 24]));
    assert_eq!(v["predicted"].as_array().map(Vec::len), Some(4));

    // As a job: the same request, with progress, ending at 1.
    let res = app
        .client
        .post(app.url("/v1/jobs"))
        .json(&json!({"operation": "grid.tomography", "params": body}))
        .send()
        .await
        .expect("submit");
    assert_eq!(res.status(), 202);
    let id = res.json::<Value>().await.expect("json")["id"]
        .as_str()
        .expect("id")
        .to_string();
    let t = Instant::now();
    let job = loop {
        let j: Value = app
            .get(&format!("/v1/jobs/{id}"))
            .await
            .json()
            .await
            .expect("job");
        if ["succeeded", "failed", "cancelled"].contains(&j["state"].as_str().unwrap_or("")) {
            break j;
        }
        assert!(t.elapsed() < Duration::from_secs(60), "{j}");
        tokio::time::sleep(Duration::from_millis(20)).await;
    };
    assert_eq!(job["state"], "succeeded", "{job}");
    assert_eq!(job["progress"], 1.0);
    assert_eq!(
        job["result"]["misfit"]["history"], v["misfit"]["history"],
        "{job}"
    );
    assert!(job["result"]["cost"]["url"].is_string(), "{job}");
}

#[tokio::test]
async fn tomography_refusals_name_the_field() {
    let app = spawn(|_| {}).await;
    let good = small_tomography();
    let with = |key: &str, value: Value| {
        let mut b = good.clone();
        b[key] = value;
        b
    };
    let mut ragged = good.clone();
    ragged["times"][2] = json!([1.0, 2.0]);
    let mut negative = good.clone();
    negative["times"][1][3] = json!(-1.0);
    for (body, field) in [
        (with("times", json!([[1.0, 2.0, 3.0, 4.0]])), "times"),
        (ragged, "times[2]"),
        (negative, "times[1][3]"),
        (
            with(
                "receivers",
                json!([{"point": [23.0, 1.0]}, {"point": [23.0, 24.5]}, {"point": [0.0, 0.0]}, {"point": [1.0, 1.0]}]),
            ),
            "receivers[1].point[1]",
        ),
        (
            with(
                "sources",
                json!([{"point": [0.0, 2.0]}, {"point": [0.0]}, {"point": [0.0, 3.0]}, {"point": [0.0, 4.0]}]),
            ),
            "sources[1].point",
        ),
        (with("sources", json!([])), "sources"),
        (with("shape", json!([24])), "shape"),
        (with("alpha", json!(-1.0)), "alpha"),
        (with("min_cost", json!(0.0)), "min_cost"),
        (with("max_iterations", json!(0)), "max_iterations"),
        (with("order", json!(3)), "order"),
        (with("spacing", json!([1.0, 0.0])), "spacing[1]"),
    ] {
        let res = post(&app, "/v1/grid/tomography", &body).await;
        let v = problem(res, 422).await;
        assert_eq!(v["field"], field, "{body}: {v}");
    }
    let mut unknown = good.clone();
    unknown["iterations"] = json!(3);
    let res = post(&app, "/v1/grid/tomography", &unknown).await;
    assert_eq!(res.status().as_u16(), 422);
}

/// A dim horizontal ridge (0.5) along row 10 and a bright one (1) along
/// row 20 of a 32 × 40 image, joined by a bright link at both ends: from
/// the brightest reference the paths between the dim ridge's ends go round
/// by the bright one.
fn ridges() -> ArrayData {
    ArrayData::F64(ArrayD::from_shape_fn(ndarray::IxDyn(&[32, 40]), |ix| {
        let (i, j) = (ix[0] as f64, ix[1] as f64);
        let g = |d: f64| (-d * d / (2.0 * 1.5 * 1.5)).exp();
        let dim = 0.5 * g(i - 10.0) * f64::from(u8::from((4.0..=36.0).contains(&j)));
        let bright = g(i - 20.0) * f64::from(u8::from((4.0..=36.0).contains(&j)));
        let links = if (10.0..=20.0).contains(&i) {
            g(j - 4.0).max(g(j - 36.0))
        } else {
            0.0
        };
        dim.max(bright).max(links)
    }))
}

#[tokio::test]
async fn fit_metric_moves_the_paths_onto_the_examples() {
    let app = spawn(|_| {}).await;
    let image = app.upload(&ridges()).await;
    let example: Vec<[f64; 2]> = (0..=8).map(|k| [10.0, 6.0 + 3.5 * k as f64]).collect();
    let body = json!({"image": image, "examples": [example], "design": {"kind": "intensity", "power": 2.0}});
    let res = post(&app, "/v1/grid/fit-metric", &body).await;
    assert_eq!(res.status(), 200);
    let v: Value = res.json().await.expect("json");
    let loss: Vec<f64> = v["loss"]["history"]
        .as_array()
        .expect("history")
        .iter()
        .map(|x| x.as_f64().expect("number"))
        .collect();
    assert!(loss.windows(2).all(|w| w[1] <= w[0]), "{loss:?}");
    let e = &v["examples"][0];
    let before = e["before"]["mean"].as_f64().expect("before");
    let after = e["after"]["mean"].as_f64().expect("after");
    assert!(before > 3.0 && after <= 1.5, "{v}");
    assert_eq!(v["design"]["kind"], "intensity");
    assert!(v["design"]["value"].as_f64().expect("value") < 0.8, "{v}");
    assert_eq!(v["cost"]["shape"], json!([32, 40]));
}

#[tokio::test]
async fn fit_metric_refusals_name_the_field() {
    let app = spawn(|_| {}).await;
    let image = app.upload(&ridges()).await;
    let good = json!({"image": image, "examples": [[[10.0, 6.0], [10.0, 34.0]]]});
    let with = |key: &str, value: Value| {
        let mut b = good.clone();
        b[key] = value;
        b
    };
    for (body, field, status) in [
        (with("examples", json!([])), "examples", 422),
        (with("examples", json!([[[10.0, 6.0]]])), "examples[0]", 422),
        (
            with("examples", json!([[[10.0, 6.0], [10.0, 40.5]]])),
            "examples[0][1][1]",
            422,
        ),
        (
            with("examples", json!([[[10.0, 6.0], [10.0]]])),
            "examples[0][1]",
            422,
        ),
        (with("design", json!({"kind": "edges"})), "design.kind", 422),
        (
            with("design", json!({"kind": "intensity", "power": 0.5})),
            "design.power",
            422,
        ),
        (
            with("design", json!({"kind": "intensity", "value": 7.0})),
            "design.value",
            422,
        ),
        (
            with("design", json!({"kind": "intensity", "epsilon": 0.0})),
            "design.epsilon",
            422,
        ),
        (with("max_iterations", json!(0)), "max_iterations", 422),
        (with("order", json!(5)), "order", 422),
        (with("image", json!("ds_missing")), "image", 404),
    ] {
        let res = post(&app, "/v1/grid/fit-metric", &body).await;
        let v = problem(res, status).await;
        assert_eq!(v["field"], field, "{body}: {v}");
    }
}
