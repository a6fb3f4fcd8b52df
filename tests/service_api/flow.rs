//! The main flows: upload, solve, download; the one-round-trip form; the
//! committed examples.

use std::collections::HashMap;
use std::sync::Arc;

use geodex::io::{self, ArrayData, Format, Limits};
use geodex::numerics::Control;
use geodex::ops::grid_distance::{self, GridDistanceRequest};
use geodex::ops::{InputArray, OpLimits};
use serde_json::json;

use crate::common::{spawn, wavy_cost, TestApp};

async fn download(app: &TestApp, url: &str) -> ArrayData {
    let res = app
        .client
        .get(app.url(url))
        .header("accept", "application/x-npy")
        .send()
        .await
        .expect("get");
    assert_eq!(res.status(), 200);
    assert_eq!(res.headers()["content-type"], "application/x-npy");
    let bytes = res.bytes().await.expect("bytes");
    io::decode(&bytes, Some(Format::Npy), &Limits::default())
        .expect("decode")
        .array
}

/// The same request, run directly through the core.
fn direct(req: &serde_json::Value, id: &str, cost: ArrayData) -> grid_distance::GridDistanceResult {
    let req: GridDistanceRequest = serde_json::from_value(req.clone()).expect("request");
    let mut inputs = HashMap::new();
    inputs.insert(
        id.to_string(),
        InputArray {
            array: Arc::new(cost),
            spacing: None,
        },
    );
    grid_distance::execute(&req, &inputs, &OpLimits::default(), &Control::new()).expect("solve")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn upload_distance_download_equals_the_core_bit_for_bit() {
    let app = spawn(|_| {}).await;
    let cost = ArrayData::F64(wavy_cost(40, 50));
    let id = app.upload(&cost).await;

    let meta: serde_json::Value = app
        .get(&format!("/v1/datasets/{id}"))
        .await
        .json()
        .await
        .expect("json");
    assert_eq!(meta["shape"], json!([40, 50]));
    assert_eq!(meta["kind"], "image");
    assert_eq!(meta["dtype"], "f64");
    assert_eq!(meta["source_format"], "npy");

    let req = json!({
        "cost": {"dataset": id},
        "spacing": [0.5, 0.25],
        "sources": [{"point": [10.0, 12.5]}, {"point": [30.0, 40.0]}],
        "outputs": {"labels": true, "frozen_order": true}
    });
    let res = app
        .client
        .post(app.url("/v1/grid/distance"))
        .json(&req)
        .send()
        .await
        .expect("post");
    assert_eq!(res.status(), 200, "{:?}", res.text().await);
    let body: serde_json::Value = res.json().await.expect("json");
    assert_eq!(body["stats"]["cells"], 2000);
    assert!(body["stats"]["total_seconds"]
        .as_f64()
        .is_some_and(|t| t >= 0.0));

    let expected = direct(&req, &id, cost);
    let distance = download(&app, body["distance"]["data_url"].as_str().expect("url")).await;
    let labels = download(&app, body["labels"]["data_url"].as_str().expect("url")).await;
    let order = download(
        &app,
        body["frozen_order"]["data_url"].as_str().expect("url"),
    )
    .await;
    let ArrayData::F64(distance) = distance else {
        panic!("distance is f64")
    };
    assert_eq!(distance.shape(), &[40, 50]);
    let same = distance
        .iter()
        .zip(expected.distance.iter())
        .all(|(a, b)| a.to_bits() == b.to_bits());
    assert!(same, "the served distance equals the core's bit for bit");
    assert_eq!(labels, ArrayData::I32(expected.labels.expect("labels")));
    assert_eq!(order, ArrayData::I64(expected.frozen_order.expect("order")));

    // Small results are also offered as JSON, with the same values.
    let url = body["distance"]["data_url"].as_str().expect("url");
    let as_json: serde_json::Value = app
        .get(&format!("{url}?format=json"))
        .await
        .json()
        .await
        .expect("json");
    assert_eq!(as_json["shape"], json!([40, 50]));
    assert_eq!(
        as_json["data"][0].as_f64(),
        Some(distance.as_slice().expect("std")[0])
    );

    // The other representations.
    for (format, magic, media) in [
        ("png", &b"\x89PNG"[..], "image/png"),
        ("png16", &b"\x89PNG"[..], "image/png"),
        ("tiff", &b"II*\0"[..], "image/tiff"),
    ] {
        let res = app.get(&format!("{url}?format={format}")).await;
        assert_eq!(res.status(), 200, "{format}");
        assert_eq!(res.headers()["content-type"], media);
        let bytes = res.bytes().await.expect("bytes");
        assert!(bytes.starts_with(magic), "{format}");
    }

    // Delete: 204, then 404.
    let res = app
        .client
        .delete(app.url(&format!("/v1/datasets/{id}")))
        .send()
        .await
        .expect("delete");
    assert_eq!(res.status(), 204);
    let res = app.get(&format!("/v1/datasets/{id}")).await;
    assert_eq!(res.status(), 404);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn multipart_one_round_trip_returns_npy() {
    let app = spawn(|_| {}).await;
    let cost = ArrayData::F64(wavy_cost(30, 20));
    let file = io::encode_npy(&cost).expect("npy");
    let params = json!({"sources": [{"point": [15.0, 10.0]}]});
    let form = reqwest::multipart::Form::new()
        .part(
            "file",
            reqwest::multipart::Part::bytes(file)
                .file_name("cost.npy")
                .mime_str("application/x-npy")
                .expect("mime"),
        )
        .text("params", params.to_string());
    let res = app
        .client
        .post(app.url("/v1/grid/distance"))
        .header("accept", "application/x-npy")
        .multipart(form)
        .send()
        .await
        .expect("post");
    assert_eq!(res.status(), 200, "{:?}", res.text().await);
    assert_eq!(res.headers()["content-type"], "application/x-npy");
    let bytes = res.bytes().await.expect("bytes");
    let got = io::decode(&bytes, Some(Format::Npy), &Limits::default())
        .expect("decode")
        .array;
    let mut req = params.clone();
    req["cost"] = json!({"dataset": "file"});
    let expected = direct(&req, "file", cost);
    assert_eq!(got, ArrayData::F64(expected.distance));
}

/// Every committed example request is accepted. `$COST` stands for the id of
/// an uploaded 64 x 64 cost, `$MASK` for an obstacle mask of the same shape.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn committed_examples_are_accepted() {
    let app = spawn(|_| {}).await;
    let cost = app.upload(&ArrayData::F64(wavy_cost(64, 64))).await;
    let mut mask = ndarray::ArrayD::from_elem(ndarray::IxDyn(&[64, 64]), 0u8);
    for i in 10..50 {
        mask[[i, 32]] = 1;
    }
    let mask = app.upload(&ArrayData::U8(mask)).await;
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/api/examples");
    let mut seen = 0;
    let mut entries: Vec<_> = std::fs::read_dir(dir)
        .expect("api/examples")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().is_some_and(|x| x == "json"))
        .collect();
    entries.sort();
    for path in entries {
        let text = std::fs::read_to_string(&path).expect("read");
        let text = text.replace("$COST", &cost).replace("$MASK", &mask);
        let body: serde_json::Value = serde_json::from_str(&text).expect("example json");
        let res = app
            .client
            .post(app.url("/v1/grid/distance"))
            .json(&body)
            .send()
            .await
            .expect("post");
        assert_eq!(
            res.status(),
            200,
            "{}: {:?}",
            path.display(),
            res.text().await
        );
        seen += 1;
    }
    assert!(seen >= 3, "{seen} examples");
}
