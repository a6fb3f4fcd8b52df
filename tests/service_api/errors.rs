//! Every bad input gets its 4xx problem+json naming the field.

use geodex::io::{self, ArrayData};
use ndarray::ArrayD;
use serde_json::json;

use crate::common::{problem, spawn, wavy_cost, TestApp};

async fn post_distance(app: &TestApp, body: serde_json::Value) -> reqwest::Response {
    app.client
        .post(app.url("/v1/grid/distance"))
        .json(&body)
        .send()
        .await
        .expect("post")
}

async fn upload_raw(app: &TestApp, content_type: &str, body: Vec<u8>) -> reqwest::Response {
    app.client
        .post(app.url("/v1/datasets"))
        .header("content-type", content_type)
        .body(body)
        .send()
        .await
        .expect("post")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn malformed_requests_are_problems_naming_the_field() {
    let app = spawn(|_| {}).await;

    // Unknown JSON field, at the top and nested.
    let v = problem(
        post_distance(
            &app,
            json!({"cost": {"constant": 1.0, "shape": [8, 8]},
            "sources": [{"point": [1.0, 1.0]}], "bogus": 1}),
        )
        .await,
        422,
    )
    .await;
    assert_eq!(v["field"], "bogus");
    let v = problem(
        post_distance(
            &app,
            json!({"cost": {"constant": 1.0, "shape": [8, 8]},
            "sources": [{"point": [1.0, 1.0], "pt": 2}]}),
        )
        .await,
        422,
    )
    .await;
    assert_eq!(v["field"], "sources[0].pt");

    // Missing field.
    let v = problem(
        post_distance(&app, json!({"cost": {"constant": 1.0, "shape": [8, 8]}})).await,
        422,
    )
    .await;
    assert_eq!(v["field"], "sources");

    // Malformed JSON.
    let res = app
        .client
        .post(app.url("/v1/grid/distance"))
        .header("content-type", "application/json")
        .body("{\"cost\": ")
        .send()
        .await
        .expect("post");
    let v = problem(res, 400).await;
    assert_eq!(v["field"], "body");

    // Unsupported media types.
    let res = app
        .client
        .post(app.url("/v1/grid/distance"))
        .header("content-type", "text/plain")
        .body("hello")
        .send()
        .await
        .expect("post");
    problem(res, 415).await;
    let v = problem(upload_raw(&app, "text/plain", b"hello".to_vec()).await, 415).await;
    assert_eq!(v["field"], "Content-Type");

    // Zero and negative spacing.
    for (h, k) in [(0.0, 0), (-1.0, 1)] {
        let mut spacing = vec![1.0, 1.0];
        spacing[k] = h;
        let v = problem(
            post_distance(
                &app,
                json!({"cost": {"constant": 1.0, "shape": [8, 8]},
                "spacing": spacing, "sources": [{"point": [1.0, 1.0]}]}),
            )
            .await,
            422,
        )
        .await;
        assert_eq!(v["field"], format!("spacing[{k}]"));
    }

    // Non-positive constant cost, 1D and 4D shapes.
    let v = problem(
        post_distance(
            &app,
            json!({"cost": {"constant": -2.0, "shape": [8, 8]},
            "sources": [{"point": [1.0, 1.0]}]}),
        )
        .await,
        422,
    )
    .await;
    assert_eq!(v["field"], "cost.constant");
    for shape in [json!([64]), json!([2, 2, 2, 2])] {
        let v = problem(
            post_distance(
                &app,
                json!({"cost": {"constant": 1.0, "shape": shape},
                "sources": [{"point": [1.0]}]}),
            )
            .await,
            422,
        )
        .await;
        assert_eq!(v["field"], "cost.shape");
    }

    // Unknown dataset ids, in the request and in the path.
    let v = problem(
        post_distance(
            &app,
            json!({"cost": {"dataset": "ds_0123456789abcdef0123456789abcdef"},
            "sources": [{"point": [1.0, 1.0]}]}),
        )
        .await,
        404,
    )
    .await;
    assert_eq!(v["field"], "cost.dataset");
    let res = app.get("/v1/datasets/nope/data").await;
    problem(res, 404).await;
    let res = app
        .client
        .delete(app.url("/v1/datasets/ds_0123456789abcdef0123456789abcdef"))
        .send()
        .await
        .expect("delete");
    problem(res, 404).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bodies_over_the_limit_are_413() {
    let app = spawn(|s| s.max_body_bytes = 1024).await;
    let big =
        io::encode_npy(&ArrayData::F64(ArrayD::zeros(ndarray::IxDyn(&[32, 32])))).expect("npy");
    let v = problem(
        upload_raw(&app, "application/x-npy", big.clone()).await,
        413,
    )
    .await;
    assert_eq!(v["field"], "body");
    let form = reqwest::multipart::Form::new()
        .part("file", reqwest::multipart::Part::bytes(big))
        .text("params", "{\"sources\": [{\"point\": [1, 1]}]}");
    let res = app
        .client
        .post(app.url("/v1/grid/distance"))
        .multipart(form)
        .send()
        .await
        .expect("post");
    problem(res, 413).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn json_bodies_of_millions_of_values_are_413_before_parsing() {
    let app = spawn(|_| {}).await;
    // 4,194,305 cells of 1 value each (8.4 MB): one more than the limit.
    let n = geodex::ops::parse::MAX_JSON_VALUES;
    let mut body =
        String::from(r#"{"cost": {"constant": 1.0, "shape": [8, 8]}, "sources": [{"cells": ["#);
    body.push_str(&"0,".repeat(n));
    body.push_str("0]}]}");
    let res = app
        .client
        .post(app.url("/v1/grid/distance"))
        .header("content-type", "application/json")
        .body(body)
        .send()
        .await
        .expect("post");
    let v = problem(res, 413).await;
    assert_eq!(v["field"], "body", "{v}");
    assert!(
        v["detail"]
            .as_str()
            .is_some_and(|d| d.contains("/v1/datasets")),
        "{v}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_files_are_problems() {
    let app = spawn(|_| {}).await;

    // Corrupt PNG: a valid signature followed by garbage.
    let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
    png.extend_from_slice(&[0xAB; 64]);
    let v = problem(upload_raw(&app, "image/png", png).await, 400).await;
    assert_eq!(v["field"], "body");

    // Truncated NPY.
    let npy = io::encode_npy(&ArrayData::F64(wavy_cost(16, 16))).expect("npy");
    let v = problem(
        upload_raw(&app, "application/x-npy", npy[..npy.len() / 2].to_vec()).await,
        400,
    )
    .await;
    assert_eq!(v["field"], "body");

    // 1D and 4D arrays.
    for shape in [vec![64usize], vec![2, 2, 2, 2]] {
        let npy =
            io::encode_npy(&ArrayData::F32(ArrayD::ones(ndarray::IxDyn(&shape)))).expect("npy");
        let res = upload_raw(&app, "application/x-npy", npy).await;
        let status = res.status().as_u16();
        assert!(status == 422 || status == 415, "{shape:?}: {status}");
        let v = problem(res, status).await;
        assert_eq!(v["field"], "body");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_costs_and_sources_are_422_naming_the_field() {
    let app = spawn(|_| {}).await;
    let mut nan = wavy_cost(12, 12);
    nan[[3, 4]] = f64::NAN;
    let mut negative = wavy_cost(12, 12);
    negative[[5, 5]] = -1.0;
    for cost in [nan, negative] {
        let id = app.upload(&ArrayData::F64(cost)).await;
        let v = problem(
            post_distance(
                &app,
                json!({"cost": {"dataset": id},
                "sources": [{"point": [1.0, 1.0]}]}),
            )
            .await,
            422,
        )
        .await;
        assert_eq!(v["field"], "cost.dataset", "{v}");
    }

    let cost = app.upload(&ArrayData::F64(wavy_cost(12, 12))).await;
    // Source outside the grid.
    let v = problem(
        post_distance(
            &app,
            json!({"cost": {"dataset": cost},
            "sources": [{"point": [1.0, 1.0]}, {"point": [30.0, 2.0]}]}),
        )
        .await,
        422,
    )
    .await;
    assert_eq!(v["field"], "sources[1]");

    // Source on an obstacle.
    let mut mask = ArrayD::from_elem(ndarray::IxDyn(&[12, 12]), false);
    mask[[6, 6]] = true;
    let obstacles = app.upload(&ArrayData::Bool(mask)).await;
    let v = problem(
        post_distance(
            &app,
            json!({"cost": {"dataset": cost}, "obstacles": obstacles,
            "sources": [{"point": [6.0, 6.0]}]}),
        )
        .await,
        422,
    )
    .await;
    assert_eq!(v["field"], "sources[0]");

    // Distances that would overflow f64 (and read as "unreached"): 422
    // naming the larger factor, cost or spacing.
    for (body, field) in [
        (
            json!({"cost": {"constant": 1e306, "shape": [64, 64]}, "sources": [{"point": [1, 1]}]}),
            "cost",
        ),
        (
            json!({"cost": {"constant": 1.0, "shape": [64, 64]}, "spacing": [1e300, 1e300],
                "sources": [{"point": [1, 1]}]}),
            "spacing",
        ),
    ] {
        let v = problem(post_distance(&app, body).await, 422).await;
        assert_eq!(v["field"], field, "{v}");
        assert!(
            v["detail"].as_str().is_some_and(|d| d.contains("overflow")),
            "{v}"
        );
    }

    // Every cell of a `cells` list counts against the source limit
    // (100,000): 100,001 cells of a 64 x 64 grid are refused by name.
    let cells: Vec<[usize; 2]> = (0..100_001).map(|k| [k % 64, (k / 64) % 64]).collect();
    let v = problem(
        post_distance(
            &app,
            json!({"cost": {"constant": 1.0, "shape": [64, 64]}, "sources": [{"cells": cells}]}),
        )
        .await,
        413,
    )
    .await;
    assert_eq!(v["field"], "sources", "{v}");
    assert!(
        v["detail"].as_str().is_some_and(|d| d.contains("mask")),
        "{v}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn quota_expiry_and_representations() {
    // A quota that holds one 64 x 64 f64 array (32 KiB + header) but not two.
    let app = spawn(|s| {
        s.storage_quota_bytes = 40_000;
        s.dataset_ttl_secs = 1;
    })
    .await;
    let cost = ArrayData::F64(wavy_cost(64, 64));
    let id = app.upload(&cost).await;
    let npy = io::encode_npy(&cost).expect("npy");
    problem(upload_raw(&app, "application/x-npy", npy).await, 507).await;

    // JSON only for small arrays; unknown formats are 400.
    let small = app.client.get(app.url(&format!("/v1/datasets/{id}/data")));
    let res = small
        .header("accept", "application/json")
        .send()
        .await
        .expect("get");
    assert_eq!(res.status(), 200, "4096 cells fit in JSON");
    let res = app.get(&format!("/v1/datasets/{id}/data?format=bmp")).await;
    let v = problem(res, 400).await;
    assert_eq!(v["field"], "query");

    // JSON answers are gzip-compressed when the client allows it.
    let res = app
        .client
        .get(app.url("/openapi.json"))
        .header("accept-encoding", "gzip")
        .send()
        .await
        .expect("get");
    assert_eq!(res.headers()["content-encoding"], "gzip");
    // NPY arrays are not (binary floats: megabytes for little gain).
    let res = app
        .client
        .get(app.url(&format!("/v1/datasets/{id}/data")))
        .header("accept", "application/x-npy")
        .header("accept-encoding", "gzip")
        .send()
        .await
        .expect("get");
    assert_eq!(res.status(), 200);
    assert_eq!(res.headers()["content-type"], "application/x-npy");
    assert!(res.headers().get("content-encoding").is_none());

    // After its lifetime the dataset is gone.
    tokio::time::sleep(std::time::Duration::from_millis(1100)).await;
    let res = app.get(&format!("/v1/datasets/{id}")).await;
    problem(res, 404).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn json_downloads_are_refused_for_large_arrays() {
    let app = spawn(|_| {}).await;
    let id = app
        .upload(&ArrayData::U8(ArrayD::zeros(ndarray::IxDyn(&[300, 300]))))
        .await;
    let res = app
        .get(&format!("/v1/datasets/{id}/data?format=json"))
        .await;
    let v = problem(res, 406).await;
    assert_eq!(v["field"], "Accept");
}

/// Issue 21, item 2: a photograph with black pixels used as a cost gets a 422
/// that names the pixel and offers the fixes that work, and each offered
/// fix, applied to the same request, is answered 200.
#[tokio::test]
async fn an_image_with_zero_pixels_as_a_cost_gets_the_fixes() {
    let app = spawn(|_| {}).await;
    let img = ArrayData::U8(ArrayD::from_shape_fn(ndarray::IxDyn(&[24, 24]), |ix| {
        if ix[0] == 12 {
            0
        } else {
            (10 + ix[1] * 9) as u8
        }
    }));
    let id = app.upload(&img).await;
    let request =
        |cost: serde_json::Value| json!({"cost": cost, "sources": [{"point": [2.0, 2.0]}]});
    let v = problem(
        post_distance(&app, request(json!({"dataset": id}))).await,
        422,
    )
    .await;
    assert_eq!(v["field"], "cost.dataset", "{v}");
    let detail = v["detail"].as_str().expect("detail");
    for hint in [
        "[12, 0]",
        "\"interpretation\": \"speed\"",
        "design",
        "edges",
        "epsilon",
    ] {
        assert!(detail.contains(hint), "missing {hint:?} in: {detail}");
    }
    for fix in [
        json!({"dataset": id, "interpretation": "speed"}),
        json!({"dataset": id, "design": {"kind": "edges"}}),
        json!({"dataset": id, "design": {"kind": "intensity", "value": 100.0}}),
    ] {
        let res = post_distance(&app, request(fix.clone())).await;
        assert_eq!(res.status(), 200, "{fix}: {:?}", res.text().await);
    }
}
