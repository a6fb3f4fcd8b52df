//! Shape collections over HTTP (`/v1/collections`, issue 19 item 4):
//! create, add meshes, query the nearest, list, read, delete; the 4xx of
//! bad input naming the field; durability across a restart (SQLite, the
//! default) and the same flow on PostgreSQL when
//! `GEODEX_TEST_POSTGRES_URL` is set (skipped otherwise).

use geodex::io::mesh::write::write_obj;
use geodex::numerics::mesh::TriMesh;
use geodex::numerics::shape::benchmark::{benchmark_shape, classes, BenchmarkOptions};
use geodex::numerics::Control;
use serde_json::{json, Value};
use sqlx::Executor;

#[allow(dead_code)]
#[path = "service_api/common.rs"]
mod common;

use common::{problem, spawn, TestApp};

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
    let meta: Value = res.json().await.expect("json");
    meta["id"].as_str().expect("id").to_string()
}

async fn post(app: &TestApp, path: &str, body: Value) -> reqwest::Response {
    app.client
        .post(app.url(path))
        .json(&body)
        .send()
        .await
        .expect("post")
}

/// Small benchmark poses: 250..350 vertices.
fn shape(class: usize, pose: usize) -> TriMesh {
    let options = BenchmarkOptions {
        level: 3,
        min_vertices: 250,
        max_vertices: 350,
        seed: 11,
        ..Default::default()
    };
    let c = &classes()[class];
    benchmark_shape(c, class, pose, &options, &Control::new()).expect("benchmark shape")
}

/// Classes used: star3, snake, table (far apart in descriptor space).
const CLASSES: [usize; 3] = [0, 6, 10];

/// Creates a collection, adds two poses of each class, queries a third
/// pose of each: the nearest shape is of its class. Returns the id.
async fn the_flow(app: &TestApp) -> String {
    let res = post(
        app,
        "/v1/collections",
        json!({"name": "articulated", "descriptor": {"landmarks": 16, "bins": 16}}),
    )
    .await;
    assert_eq!(res.status(), 201);
    let location = res
        .headers()
        .get("location")
        .and_then(|v| v.to_str().ok())
        .map(str::to_string);
    let c: Value = res.json().await.expect("json");
    let id = c["id"].as_str().expect("id").to_string();
    assert_eq!(location.as_deref(), c["url"].as_str());
    assert_eq!(c["descriptor"]["landmarks"], 16);
    assert_eq!(c["descriptor"]["method"], "fast_marching");
    assert_eq!(c["shapes"], 0);
    let names = classes();
    for &k in &CLASSES {
        for pose in 0..2 {
            let mesh = upload_mesh(app, &shape(k, pose)).await;
            let res = post(
                app,
                &format!("/v1/collections/{id}/shapes"),
                json!({"mesh": mesh, "name": format!("{}-{pose}", names[k].name), "label": names[k].name}),
            )
            .await;
            assert_eq!(res.status(), 201);
            let added: Value = res.json().await.expect("json");
            assert_eq!(added["shape"]["label"], names[k].name);
            assert_eq!(added["shape"]["dataset"], mesh.as_str());
            assert_eq!(
                added["descriptor"]["vector"].as_array().map(Vec::len),
                Some(2 * 16 + 9)
            );
        }
    }
    for &k in &CLASSES {
        let mesh = upload_mesh(app, &shape(k, 5)).await;
        let res = post(
            app,
            &format!("/v1/collections/{id}/query"),
            json!({"mesh": mesh, "k": 3}),
        )
        .await;
        assert_eq!(res.status(), 200);
        let answer: Value = res.json().await.expect("json");
        let matches = answer["matches"].as_array().expect("matches");
        assert_eq!(matches.len(), 3);
        assert_eq!(matches[0]["shape"]["label"], names[k].name, "{answer}");
        let d: Vec<f64> = matches
            .iter()
            .map(|m| m["distance"].as_f64().expect("distance"))
            .collect();
        assert!(d.windows(2).all(|w| w[0] <= w[1]), "{d:?}");
        let score = matches[0]["score"].as_f64().expect("score");
        assert!((score - (1.0 - d[0])).abs() < 1e-12);
    }
    id
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn collections_on_sqlite_rank_poses_and_survive_a_restart() {
    let data = tempfile::tempdir().expect("tempdir");
    let dir = data.path().to_path_buf();
    let app = spawn(|s| s.data_dir = dir.clone()).await;
    let id = the_flow(&app).await;

    // Read, list.
    let res = app.get(&format!("/v1/collections/{id}")).await;
    assert_eq!(res.status(), 200);
    let detail: Value = res.json().await.expect("json");
    assert_eq!(detail["collection"]["shapes"], 6);
    assert_eq!(detail["shapes"].as_array().map(Vec::len), Some(6));
    let res = post(&app, "/v1/collections", json!({"name": "second"})).await;
    assert_eq!(res.status(), 201);
    let second: Value = res.json().await.expect("json");
    assert_eq!(second["descriptor"]["bins"], 32);
    let res = app.get("/v1/collections?limit=1").await;
    let page: Value = res.json().await.expect("json");
    assert_eq!(page["collections"][0]["id"], second["id"]);
    let cursor = page["next_cursor"].as_str().expect("cursor").to_string();
    let res = app
        .get(&format!("/v1/collections?limit=1&cursor={cursor}"))
        .await;
    let page: Value = res.json().await.expect("json");
    assert_eq!(page["collections"][0]["id"], id.as_str());
    assert!(page.get("next_cursor").is_none());

    // Bad input: 4xx naming the field and the way out.
    let p = problem(
        post(&app, "/v1/collections", json!({"name": ""})).await,
        422,
    )
    .await;
    assert_eq!(p["field"], "name", "{p}");
    let p = problem(
        post(
            &app,
            "/v1/collections",
            json!({"name": "x", "descriptor": {"landmarks": 2}}),
        )
        .await,
        422,
    )
    .await;
    assert_eq!(p["field"], "descriptor.landmarks", "{p}");
    assert!(
        p["detail"]
            .as_str()
            .is_some_and(|d| d.contains("4 to 1000")),
        "{p}"
    );
    let p = problem(
        post(
            &app,
            "/v1/collections",
            json!({"name": "x", "descriptor": {"bins": 1}}),
        )
        .await,
        422,
    )
    .await;
    assert_eq!(p["field"], "descriptor.bins", "{p}");
    let p = problem(
        post(&app, "/v1/collections", json!({"name": "x", "colour": 1})).await,
        422,
    )
    .await;
    assert!(
        p["detail"].as_str().is_some_and(|d| d.contains("colour")),
        "{p}"
    );
    let mesh = upload_mesh(&app, &shape(0, 7)).await;
    let p = problem(
        post(
            &app,
            &format!("/v1/collections/{id}/query"),
            json!({"mesh": mesh, "k": 0}),
        )
        .await,
        422,
    )
    .await;
    assert_eq!(p["field"], "k", "{p}");
    let p = problem(
        post(
            &app,
            &format!("/v1/collections/{id}/shapes"),
            json!({"mesh": "ds_00000000000000000000000000000000"}),
        )
        .await,
        404,
    )
    .await;
    assert_eq!(p["field"], "mesh", "{p}");
    let unknown = "col_0192f1b27c1e7d3a9d553c0f2b8a1e44";
    for res in [
        app.get(&format!("/v1/collections/{unknown}")).await,
        app.get("/v1/collections/nonsense").await,
        post(
            &app,
            &format!("/v1/collections/{unknown}/query"),
            json!({"mesh": mesh}),
        )
        .await,
        post(
            &app,
            &format!("/v1/collections/{unknown}/shapes"),
            json!({"mesh": mesh}),
        )
        .await,
        app.client
            .delete(app.url(&format!("/v1/collections/{unknown}")))
            .send()
            .await
            .expect("delete"),
    ] {
        let p = problem(res, 404).await;
        assert_eq!(p["field"], "id", "{p}");
        assert!(
            p["detail"]
                .as_str()
                .is_some_and(|d| d.contains("GET /v1/collections")),
            "{p}"
        );
    }

    // Durable: a new process on the same data directory sees the collection.
    drop(app);
    tokio::time::sleep(std::time::Duration::from_millis(300)).await;
    let app = spawn(|s| s.data_dir = dir.clone()).await;
    let res = app.get(&format!("/v1/collections/{id}")).await;
    assert_eq!(res.status(), 200);
    let detail: Value = res.json().await.expect("json");
    assert_eq!(detail["collection"]["shapes"], 6);
    let mesh = upload_mesh(&app, &shape(CLASSES[1], 6)).await;
    let res = post(
        &app,
        &format!("/v1/collections/{id}/query"),
        json!({"mesh": mesh, "k": 1}),
    )
    .await;
    let answer: Value = res.json().await.expect("json");
    assert_eq!(
        answer["matches"][0]["shape"]["label"],
        classes()[CLASSES[1]].name,
        "{answer}"
    );

    // Delete: 204, then 404.
    let res = app
        .client
        .delete(app.url(&format!("/v1/collections/{id}")))
        .send()
        .await
        .expect("delete");
    assert_eq!(res.status(), 204);
    problem(app.get(&format!("/v1/collections/{id}")).await, 404).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn collections_on_postgres() {
    let base = match std::env::var("GEODEX_TEST_POSTGRES_URL") {
        Ok(u) if !u.is_empty() => u,
        _ => {
            eprintln!(
                "skipped: set GEODEX_TEST_POSTGRES_URL=postgres://postgres@127.0.0.1:5432/test \
                 to run the PostgreSQL collection test"
            );
            return;
        }
    };
    let admin = sqlx::PgPool::connect(&base)
        .await
        .expect("connect to PostgreSQL");
    let schema = format!("geodex_test_{}", uuid::Uuid::new_v4().simple());
    admin
        .execute(sqlx::AssertSqlSafe(format!("CREATE SCHEMA {schema}")))
        .await
        .expect("create schema");
    let sep = if base.contains('?') { '&' } else { '?' };
    let url = format!("{base}{sep}options[search_path]={schema}");
    let app = spawn(|s| s.queue = url.clone()).await;
    let id = the_flow(&app).await;
    let n: i64 = sqlx::query_scalar(sqlx::AssertSqlSafe(format!(
        "SELECT COUNT(*) FROM {schema}.geodex_collection_shapes WHERE collection_id = $1"
    )))
    .bind(&id)
    .fetch_one(&admin)
    .await
    .expect("count");
    assert_eq!(n, 6);
    drop(app);
    let _ = admin
        .execute(sqlx::AssertSqlSafe(format!("DROP SCHEMA {schema} CASCADE")))
        .await;
}
