//! Scale-out: two service processes share a PostgreSQL queue, a data
//! directory and a result store. Needs `GEODEX_TEST_POSTGRES_URL`
//! (`.ci/run` sets it); without it the test says it was skipped.
//!
//! Each run works in a fresh schema (`search_path` in the connection
//! options), so parallel runs do not see each other's jobs.

mod jobs_support;

use std::time::{Duration, Instant};

use geodex::io::ArrayData;
use jobs_support::{assert_same, attempt_dirs, compute, request, wavy_cost, Server};
use serde_json::{json, Value};
use sqlx::Executor;

/// Grid side of these jobs (smaller than the SQLite test: 40 of them).
const N: usize = 800;

fn postgres_url() -> Option<String> {
    match std::env::var("GEODEX_TEST_POSTGRES_URL") {
        Ok(u) if !u.is_empty() => Some(u),
        _ => {
            eprintln!(
                "skipped: set GEODEX_TEST_POSTGRES_URL=postgres://postgres@127.0.0.1:5432/test \
                 to run the PostgreSQL job tests"
            );
            None
        }
    }
}

/// A fresh schema; returns the URL that selects it, and the admin pool.
async fn fresh_schema(base: &str) -> (String, sqlx::PgPool, String) {
    let pool = sqlx::PgPool::connect(base)
        .await
        .expect("connect to PostgreSQL");
    let schema = format!("geodex_test_{}", uuid::Uuid::new_v4().simple());
    pool.execute(sqlx::AssertSqlSafe(format!("CREATE SCHEMA {schema}")))
        .await
        .expect("create schema");
    let sep = if base.contains('?') { '&' } else { '?' };
    (
        format!("{base}{sep}options[search_path]={schema}"),
        pool,
        schema,
    )
}

async fn drop_schema(pool: &sqlx::PgPool, schema: &str) {
    let _ = pool
        .execute(sqlx::AssertSqlSafe(format!("DROP SCHEMA {schema} CASCADE")))
        .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn two_processes_share_a_postgres_queue() {
    let Some(base) = postgres_url() else {
        return;
    };
    let (url, admin, schema) = fresh_schema(&base).await;
    let data = tempfile::tempdir().expect("tempdir");
    let results = tempfile::tempdir().expect("tempdir");
    let store = format!("file://{}", results.path().display());
    let args = [
        "--queue",
        url.as_str(),
        "--store",
        store.as_str(),
        "--pool-threads",
        "1",
        "--job-lease-secs",
        "1.5",
        "--job-poll-ms",
        "100",
    ];
    // Both share the data directory (datasets) and the result store.
    let mut a = Server::start(data.path(), "a", &args).await;
    let b = Server::start(data.path(), "b", &args).await;

    // The cost is uploaded to A; jobs that B runs read it from the shared directory.
    let cost = wavy_cost(N);
    let cost_id = a.upload(&ArrayData::F64(cost.clone())).await;
    let mut ids = Vec::new();
    let mut params = Vec::new();
    for k in 0..40 {
        let p = request(&cost_id, k, N);
        let server = if k % 2 == 0 { &a } else { &b };
        ids.push(
            server
                .submit(&json!({"operation": "grid.distance", "params": p}))
                .await,
        );
        params.push(p);
    }
    // Kill A mid-run: once a few jobs are done and both servers run one
    // (each has one worker, so two running jobs means A holds one: with
    // "at least one" the running job could be B's alone, and nothing was
    // left for B to run again). The jobs are large enough (N) that A is
    // still inside its job when the kill lands.
    let t = Instant::now();
    loop {
        let done = b.get_json("/v1/jobs?state=succeeded&limit=1000").await["jobs"]
            .as_array()
            .map_or(0, Vec::len);
        let running = b.get_json("/v1/jobs?state=running").await["jobs"]
            .as_array()
            .map_or(0, Vec::len);
        if done >= 4 && running >= 2 {
            break;
        }
        assert!(t.elapsed() < Duration::from_secs(60), "jobs did not start");
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    a.kill();

    let refs = {
        let params = params.clone();
        let cost = cost.clone();
        let cost_id = cost_id.clone();
        tokio::task::spawn_blocking(move || {
            params
                .iter()
                .map(|p| compute(p, &cost_id, &cost))
                .collect::<Vec<_>>()
        })
    };
    for id in &ids {
        let j = b.wait_final(id, Duration::from_secs(120)).await;
        assert_eq!(j["state"], "succeeded", "{j}\n{}", b.log_text());
    }
    let refs = refs.await.expect("references");
    let mut rerun = 0;
    for (k, id) in ids.iter().enumerate() {
        let j = b.job(id).await;
        if j["attempts"].as_i64() == Some(2) {
            rerun += 1;
        }
        let got = b.result(id, "distance").await;
        assert_same(&got, &refs[k], id);
        assert_eq!(attempt_dirs(results.path(), id), 1, "one result for {id}");
    }
    assert!(rerun >= 1, "the job A was running ran again on B");

    // Cancellation travels through the database: A' serves the API only, the
    // job runs on B, A' cancels it, B's solver stops within a second.
    let mut api_args = args.to_vec();
    api_args.extend(["--job-workers", "0"]);
    let a2 = Server::start(data.path(), "a2", &api_args).await;
    let long = json!({"cost": {"constant": 1.0, "shape": [6000, 6000]}, "sources": [{"point": [1.0, 1.0]}], "outputs": {"labels": false}});
    let id = a2
        .submit(&json!({"operation": "grid.distance", "params": long}))
        .await;
    let t = Instant::now();
    while a2.job(&id).await["progress"].as_f64().unwrap_or(0.0) <= 0.0 {
        assert!(
            t.elapsed() < Duration::from_secs(30),
            "the long job did not start on B"
        );
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    let asked = Instant::now();
    let r = a2
        .post_json(&format!("/v1/jobs/{id}/cancel"), &json!({}), &[])
        .await;
    let status = r.status();
    assert_eq!(status, 202, "{}", r.text().await.unwrap_or_default());
    let j: Value = loop {
        let j = a2.job(&id).await;
        if j["state"] == "cancelled" {
            break j;
        }
        assert!(asked.elapsed() < Duration::from_secs(5), "{j}");
        tokio::time::sleep(Duration::from_millis(10)).await;
    };
    let took = asked.elapsed();
    assert!(took < Duration::from_secs(1), "stopped after {took:?}");
    assert!(j["progress"].as_f64().is_some_and(|p| p < 1.0), "{j}");
    drop(a2);
    drop(b);
    drop_schema(&admin, &schema).await;
}
