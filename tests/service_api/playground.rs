//! The playground page: served at `/playground` (and `/`), its scripts
//! embedded, and every endpoint its scripts call is one of the documented
//! public API (a path of `/openapi.json`).

use crate::common::spawn;

/// The `/v1/...` paths written in a script, with `${...}` and `" + x` parts
/// as `{}` segments.
fn api_paths(script: &str) -> Vec<String> {
    let mut out = Vec::new();
    for (at, _) in script.match_indices("/v1/") {
        let rest = &script[at..];
        let mut path = String::new();
        let mut chars = rest.chars().peekable();
        while let Some(c) = chars.next() {
            match c {
                '$' if chars.peek() == Some(&'{') => {
                    for d in chars.by_ref() {
                        if d == '}' {
                            break;
                        }
                    }
                    path.push_str("{}");
                }
                '"' | '\'' | '`' | '?' | ' ' | ',' | ')' | ':' | ';' | '.' => break,
                _ => path.push(c),
            }
        }
        if path.ends_with('/') {
            // "/v1/jobs/" + id
            path.push_str("{}");
        }
        out.push(path);
    }
    out
}

fn same_route(used: &str, documented: &str) -> bool {
    let a: Vec<&str> = used.split('/').collect();
    let b: Vec<&str> = documented.split('/').collect();
    a.len() == b.len()
        && a.iter().zip(&b).all(|(x, y)| {
            x == y
                || (x.starts_with('{')
                    && y.starts_with('{')
                    && x.ends_with('}')
                    && y.ends_with('}'))
        })
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_page_is_served_with_its_scripts_and_calls_only_documented_endpoints() {
    let app = spawn(|_| {}).await;

    let res = app.get("/").await;
    assert_eq!(res.status(), 200);
    assert!(res.url().path().ends_with("/playground"), "{}", res.url());
    assert!(res.headers()["content-type"]
        .to_str()
        .expect("ascii")
        .starts_with("text/html"));
    let page = res.text().await.expect("text");

    let doc: serde_json::Value = app.get("/openapi.json").await.json().await.expect("json");
    let documented: Vec<String> = doc["paths"]
        .as_object()
        .expect("paths")
        .keys()
        .cloned()
        .collect();

    let assets: Vec<&str> = page
        .split("/playground/")
        .skip(1)
        .filter_map(|s| s.split('"').next())
        .collect();
    assert!(
        assets.contains(&"main.js") && assets.contains(&"style.css"),
        "{assets:?}"
    );
    let mut used = Vec::new();
    for name in &assets {
        let res = app.get(&format!("/playground/{name}")).await;
        assert_eq!(res.status(), 200, "{name}");
        let media = res.headers()["content-type"]
            .to_str()
            .expect("ascii")
            .to_string();
        let want = if name.ends_with(".js") {
            "text/javascript"
        } else {
            "text/css"
        };
        assert!(media.starts_with(want), "{name}: {media}");
        let body = res.text().await.expect("text");
        used.extend(api_paths(&body));
    }
    for must in [
        "/v1/datasets",
        "/v1/grid/distance",
        "/v1/grid/paths",
        "/v1/grid/segment",
        "/v1/mesh/distance",
        "/v1/mesh/remesh",
        "/v1/mesh/embed",
        "/v1/grid/tensor-metric",
        "/v1/jobs",
    ] {
        assert!(
            used.iter().any(|u| u == must),
            "the scripts never call {must}: {used:?}"
        );
    }
    for u in &used {
        assert!(
            documented.iter().any(|d| same_route(u, d)),
            "the playground calls {u}, which is not a documented endpoint"
        );
    }

    let res = app.get("/playground/missing.js").await;
    assert_eq!(res.status(), 404);
    assert_eq!(res.headers()["content-type"], "application/problem+json");
}
