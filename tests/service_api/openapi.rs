//! The OpenAPI contract: the committed document matches the code, is served,
//! and documents problem+json for every error status.

use crate::common::{problem, spawn};

const COMMITTED: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/api/openapi.json");

/// Fails when `api/openapi.json` differs from the generated document;
/// `UPDATE_OPENAPI=1 cargo test --test service_api openapi` rewrites it.
#[test]
fn committed_document_matches_the_code() {
    let generated = geodex::http::openapi::document_json();
    if std::env::var_os("UPDATE_OPENAPI").is_some() {
        std::fs::write(COMMITTED, &generated).expect("write api/openapi.json");
        return;
    }
    let committed = std::fs::read_to_string(COMMITTED).unwrap_or_default();
    assert!(
        committed == generated,
        "api/openapi.json is out of date; run UPDATE_OPENAPI=1 cargo test --test service_api openapi"
    );
}

#[test]
fn document_is_3_1_and_every_error_is_problem_json_with_an_example() {
    let doc: serde_json::Value =
        serde_json::from_str(&geodex::http::openapi::document_json()).expect("json");
    assert!(doc["openapi"]
        .as_str()
        .is_some_and(|v| v.starts_with("3.1")));
    let responses = &doc["components"]["responses"];
    let paths = doc["paths"].as_object().expect("paths");
    let mut checked = 0;
    for (path, item) in paths {
        for (method, op) in item.as_object().expect("path item") {
            assert!(op["summary"].is_string(), "{method} {path}: summary");
            assert!(
                op["description"].is_string(),
                "{method} {path}: description"
            );
            for (status, resp) in op["responses"].as_object().expect("responses") {
                let code: u16 = status.parse().expect("numeric status");
                if code < 400 {
                    continue;
                }
                let name = resp["$ref"]
                    .as_str()
                    .and_then(|r| r.strip_prefix("#/components/responses/"))
                    .unwrap_or_else(|| panic!("{method} {path} {status}: reusable response"));
                let content = &responses[name]["content"]["application/problem+json"];
                assert!(content["example"].is_object(), "{name}: example");
                assert_eq!(content["example"]["status"], code, "{name}: status");
                checked += 1;
            }
        }
    }
    assert!(checked >= 20, "only {checked} error responses documented");
    let distance = &paths["/v1/grid/distance"]["post"];
    let text = distance["description"].as_str().expect("description");
    assert!(text.contains("array index order (axis 0 first)") && text.contains("spacing"));
    for code in ["400", "404", "413", "415", "422", "500", "503", "504"] {
        assert!(
            distance["responses"][code].is_object(),
            "distance documents {code}"
        );
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn serves_the_document_the_docs_and_problem_fallbacks() {
    let app = spawn(|_| {}).await;
    let served: serde_json::Value = app.get("/openapi.json").await.json().await.expect("json");
    let generated: serde_json::Value =
        serde_json::from_str(&geodex::http::openapi::document_json()).expect("json");
    assert_eq!(served, generated);
    let docs = app.get("/docs/").await;
    assert_eq!(docs.status(), 200);
    assert!(docs.text().await.expect("html").contains("swagger"));

    let res = app.get("/v2/nothing").await;
    problem(res, 404).await;
    let res = app
        .client
        .put(app.url("/healthz"))
        .send()
        .await
        .expect("put");
    let allow = res.headers().get("allow").cloned();
    let v = problem(res, 405).await;
    assert_eq!(v["type"], "https://geodex.dev/problems/method-not-allowed");
    assert!(allow.is_some(), "405 keeps its Allow header");

    // A request id sent by the client comes back in the header and the problem.
    let res = app
        .client
        .get(app.url("/v1/datasets/ds_00000000000000000000000000000000"))
        .header("x-request-id", "test-123")
        .send()
        .await
        .expect("get");
    assert_eq!(res.headers()["x-request-id"], "test-123");
    let v = problem(res, 404).await;
    assert_eq!(v["request_id"], "test-123");
    assert_eq!(
        v["instance"],
        "/v1/datasets/ds_00000000000000000000000000000000"
    );

    let metrics = app.get("/metrics").await.text().await.expect("text");
    assert!(
        metrics.contains("geodex_http_request_duration_seconds_bucket"),
        "{metrics}"
    );
    let ready = app.get("/readyz").await;
    assert_eq!(ready.status(), 200);
}

/// Issue 21, item 4: every operation's JSON request and success answer
/// carry an example (recorded from a real call of the generated client,
/// `bash .ci/clients.sh --record`), and an answer that is bytes by default is
/// offered as `application/octet-stream` first, so that a generated client
/// reads it as bytes.
#[test]
fn every_operation_has_examples_and_binary_answers_come_first() {
    let doc: serde_json::Value =
        serde_json::from_str(&geodex::http::openapi::document_json()).expect("json");
    let mut missing = Vec::new();
    let mut examples = 0;
    for (path, item) in doc["paths"].as_object().expect("paths") {
        for (method, op) in item.as_object().expect("path item") {
            let id = op["operationId"].as_str().unwrap_or_default();
            if let Some(body) = op["requestBody"]["content"]["application/json"].as_object() {
                let schema_example = body["schema"]["$ref"]
                    .as_str()
                    .and_then(|r| r.strip_prefix("#/components/schemas/"))
                    .is_some_and(|name| doc["components"]["schemas"][name]["example"].is_object());
                if body.contains_key("example") || schema_example {
                    examples += 1;
                } else {
                    missing.push(format!("{method} {path} ({id}): request"));
                }
            }
            for (status, resp) in op["responses"].as_object().expect("responses") {
                if !status.starts_with('2') {
                    continue;
                }
                let content = resp["content"].as_object();
                let Some(content) = content else { continue };
                if let Some(json) = content.get("application/json") {
                    if json.get("example").is_some() {
                        examples += 1;
                    } else {
                        missing.push(format!("{method} {path} ({id}): answer {status}"));
                    }
                }
            }
        }
    }
    // The order of media types matters to generators (they take the first
    // they know), and serde_json's maps are sorted: read the typed document.
    let typed = geodex::http::openapi::document();
    let mut binary = 0;
    for (path, item) in &typed.paths.paths {
        for op in [&item.get, &item.post, &item.delete].into_iter().flatten() {
            for (status, resp) in &op.responses.responses {
                let utoipa::openapi::RefOr::T(resp) = resp else {
                    continue;
                };
                let Some((kind, content)) = resp.content.iter().next() else {
                    continue;
                };
                let bytes = matches!(content,
                    utoipa::openapi::RefOr::T(utoipa::openapi::Content {
                        schema: Some(utoipa::openapi::RefOr::Ref(r)),
                        ..
                    }) if r.ref_location.ends_with("/FileBytes"));
                if bytes {
                    binary += 1;
                    assert_eq!(
                        kind, "application/octet-stream",
                        "{path} {status}: an answer that is bytes by default lists octet-stream first"
                    );
                }
            }
        }
    }
    assert!(
        binary >= 2,
        "the dataset and job-result downloads are binary"
    );
    assert!(
        missing.is_empty(),
        "operations without an example (record them with `bash .ci/clients.sh --record`): {missing:#?}"
    );
    assert!(examples >= 60, "only {examples} examples");
}
