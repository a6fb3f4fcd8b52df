//! Overhead of the job queue, on the real binary (release build):
//!
//! * submit-to-start latency on an idle pool: `started_at - created_at` of
//!   tiny jobs submitted one at a time (both times written by the server);
//! * tiny jobs per second: 400 jobs of an 8x8 grid submitted at once, rate
//!   = jobs / (last `finished_at` - first `started_at`), with one process and
//!   (PostgreSQL) two processes sharing the queue.
//!
//! ```text
//! cargo bench --bench jobs_queue
//! GEODEX_TEST_POSTGRES_URL=postgres://postgres@127.0.0.1:5432/test cargo bench --bench jobs_queue
//! ```

#[path = "../jobs_support/mod.rs"]
mod jobs_support;

use std::time::{Duration, Instant};

use chrono::{DateTime, Utc};
use jobs_support::Server;
use serde_json::{json, Value};
use sqlx::Executor;

const LATENCY_JOBS: usize = 60;
const THROUGHPUT_JOBS: usize = 400;

fn tiny(k: usize) -> Value {
    json!({"operation": "grid.distance", "params": {
        "cost": {"constant": 1.0, "shape": [8, 8]},
        "sources": [{"point": [(k % 8) as f64, 1.0]}],
        "outputs": {"labels": false}
    }})
}

fn ms(v: &Value) -> f64 {
    v.as_str()
        .and_then(|s| s.parse::<DateTime<Utc>>().ok())
        .map_or(f64::NAN, |t| t.timestamp_micros() as f64 / 1000.0)
}

fn percentile(sorted: &[f64], q: f64) -> f64 {
    let i = ((sorted.len() as f64 - 1.0) * q).round() as usize;
    sorted[i.min(sorted.len() - 1)]
}

async fn wait_done(s: &Server, id: &str) -> Value {
    let t = Instant::now();
    loop {
        let j = s.job(id).await;
        if j["state"] == "succeeded" {
            return j;
        }
        assert!(
            j["state"] == "queued" || j["state"] == "running",
            "job failed: {j}"
        );
        assert!(t.elapsed() < Duration::from_secs(60), "{j}");
        tokio::time::sleep(Duration::from_millis(2)).await;
    }
}

/// Submit-to-start latency (ms): p50, p95, max.
async fn latency(s: &Server) -> (f64, f64, f64) {
    let mut waits = Vec::new();
    for k in 0..LATENCY_JOBS {
        let id = s.submit(&tiny(k)).await;
        let j = wait_done(s, &id).await;
        waits.push(ms(&j["started_at"]) - ms(&j["created_at"]));
        // Let the pool go idle again.
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    waits.sort_by(f64::total_cmp);
    (
        percentile(&waits, 0.5),
        percentile(&waits, 0.95),
        *waits.last().unwrap_or(&f64::NAN),
    )
}

/// Tiny jobs per second through `servers` (submissions alternate).
async fn throughput(servers: &[&Server]) -> f64 {
    use futures::StreamExt;
    let ids: Vec<String> = futures::stream::iter(0..THROUGHPUT_JOBS)
        .map(|k| {
            let s = servers[k % servers.len()];
            async move { s.submit(&tiny(k)).await }
        })
        .buffered(32)
        .collect()
        .await;
    let mut first = f64::INFINITY;
    let mut last = f64::NEG_INFINITY;
    for id in &ids {
        let j = wait_done(servers[0], id).await;
        first = first.min(ms(&j["started_at"]));
        last = last.max(ms(&j["finished_at"]));
    }
    THROUGHPUT_JOBS as f64 / ((last - first) / 1000.0)
}

#[tokio::main(flavor = "multi_thread", worker_threads = 2)]
async fn main() {
    let args = ["--pool-threads", "2", "--job-poll-ms", "250"];
    println!("| queue | processes | submit-to-start p50 / p95 / max (ms) | tiny jobs/s |");
    println!("|---|---|---|---|");
    {
        let dir = tempfile::tempdir().expect("tempdir");
        let s = Server::start(dir.path(), "bench", &args).await;
        let (p50, p95, max) = latency(&s).await;
        let rate = throughput(&[&s]).await;
        println!("| SQLite | 1 | {p50:.1} / {p95:.1} / {max:.1} | {rate:.0} |");
    }
    let Ok(base) = std::env::var("GEODEX_TEST_POSTGRES_URL") else {
        println!("(PostgreSQL skipped: set GEODEX_TEST_POSTGRES_URL)");
        return;
    };
    let admin = sqlx::PgPool::connect(&base).await.expect("connect");
    let schema = format!("geodex_bench_{}", uuid::Uuid::new_v4().simple());
    admin
        .execute(sqlx::AssertSqlSafe(format!("CREATE SCHEMA {schema}")))
        .await
        .expect("schema");
    let sep = if base.contains('?') { '&' } else { '?' };
    let url = format!("{base}{sep}options[search_path]={schema}");
    let dir = tempfile::tempdir().expect("tempdir");
    let store = format!("file://{}/results", dir.path().display());
    let mut pg_args = args.to_vec();
    pg_args.extend(["--queue", url.as_str(), "--store", store.as_str()]);
    let a = Server::start(dir.path(), "a", &pg_args).await;
    let (p50, p95, max) = latency(&a).await;
    let rate1 = throughput(&[&a]).await;
    println!("| PostgreSQL | 1 | {p50:.1} / {p95:.1} / {max:.1} | {rate1:.0} |");
    let b = Server::start(dir.path(), "b", &pg_args).await;
    let rate2 = throughput(&[&a, &b]).await;
    println!("| PostgreSQL | 2 | | {rate2:.0} |");
    drop(a);
    drop(b);
    let _ = admin
        .execute(sqlx::AssertSqlSafe(format!("DROP SCHEMA {schema} CASCADE")))
        .await;
}
