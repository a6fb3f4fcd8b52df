//! API keys and tenants through HTTP, against the real binary: keys made
//! with `geodex keys create`, every resource kind (datasets, results, jobs
//! with their results and idempotency keys, collections) isolated between
//! tenants, on SQLite and on PostgreSQL (`GEODEX_TEST_POSTGRES_URL`, which
//! `.ci/run` sets; without it the PostgreSQL test says it was skipped).
//! Also: revocation, rate limits, the admin routes, the browser-origin
//! check, the tenant quota, the refusal to serve on a public address
//! without auth, and secrets kept out of `--help` and errors.

mod jobs_support;

use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

use geodex::io::ArrayData;
use jobs_support::{attempt_dirs, wavy_cost, Server};
use reqwest::header::{HeaderMap, HeaderValue, AUTHORIZATION};
use serde_json::{json, Value};
use sqlx::Executor;

/// `geodex keys <args>` with the service's storage flags; returns stdout.
fn keys(storage: &[&str], args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_geodex"))
        .arg("keys")
        .args(args)
        .args(storage)
        .output()
        .expect("run geodex keys");
    assert!(
        out.status.success(),
        "geodex keys {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).expect("utf-8")
}

/// A new key of `tenant` (with extra `keys create` flags).
fn create_key(storage: &[&str], tenant: &str, extra: &[&str]) -> String {
    let mut args = vec!["create", "--tenant", tenant];
    args.extend_from_slice(extra);
    let key = keys(storage, &args).trim().to_string();
    assert!(
        key.starts_with("gdx_") && key.len() == 4 + 16 + 1 + 64,
        "{key}"
    );
    key
}

/// A client that sends `key` with every request.
struct As {
    base: String,
    client: reqwest::Client,
}

impl As {
    fn new(server: &Server, key: &str) -> Self {
        let mut headers = HeaderMap::new();
        headers.insert(
            AUTHORIZATION,
            HeaderValue::from_str(&format!("Bearer {key}")).expect("header"),
        );
        Self {
            base: server.base.clone(),
            client: reqwest::Client::builder()
                .default_headers(headers)
                .build()
                .expect("client"),
        }
    }

    async fn get(&self, path: &str) -> reqwest::Response {
        self.client
            .get(format!("{}{path}", self.base))
            .send()
            .await
            .expect("GET")
    }

    async fn delete(&self, path: &str) -> reqwest::Response {
        self.client
            .delete(format!("{}{path}", self.base))
            .send()
            .await
            .expect("DELETE")
    }

    async fn post(&self, path: &str, body: &Value, headers: &[(&str, &str)]) -> reqwest::Response {
        let mut req = self.client.post(format!("{}{path}", self.base)).json(body);
        for (k, v) in headers {
            req = req.header(*k, *v);
        }
        req.send().await.expect("POST")
    }

    async fn upload(&self, array: &ArrayData) -> reqwest::Response {
        self.client
            .post(format!("{}/v1/datasets", self.base))
            .header("content-type", "application/x-npy")
            .body(geodex::io::encode_npy(array).expect("npy"))
            .send()
            .await
            .expect("upload")
    }

    async fn json(&self, path: &str) -> Value {
        let r = self.get(path).await;
        assert_eq!(r.status(), 200, "GET {path}");
        r.json().await.expect("json")
    }

    async fn wait_final(&self, job: &str) -> Value {
        let t = Instant::now();
        loop {
            let j = self.json(&format!("/v1/jobs/{job}")).await;
            if ["succeeded", "failed", "cancelled"].contains(&j["state"].as_str().unwrap_or("")) {
                return j;
            }
            assert!(t.elapsed() < Duration::from_secs(60), "job {job}: {j}");
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    }
}

async fn status_of(r: reqwest::Response) -> (u16, Value) {
    let s = r.status().as_u16();
    let v = r.json().await.unwrap_or(Value::Null);
    (s, v)
}

fn distance_request(cost: &str) -> Value {
    json!({"cost": {"dataset": cost}, "sources": [{"point": [3, 4]}]})
}

/// Every resource kind of tenant `alpha` is invisible to tenant `beta`.
async fn tenants_are_isolated(server: &Server, storage: &[&str]) {
    let a = As::new(server, &create_key(storage, "alpha", &["--name", "a"]));
    let b = As::new(server, &create_key(storage, "beta", &[]));

    // Without a key: 401 with WWW-Authenticate; the probes stay public.
    let anonymous = reqwest::Client::new();
    let r = anonymous
        .get(format!("{}/v1/datasets", server.base))
        .send()
        .await
        .expect("GET");
    assert_eq!(r.status(), 401);
    assert!(r.headers().contains_key("www-authenticate"));
    let (_, p) = status_of(r).await;
    assert_eq!(p["field"], "Authorization", "{p}");
    let ready: Value = anonymous
        .get(format!("{}/readyz", server.base))
        .send()
        .await
        .expect("readyz")
        .json()
        .await
        .expect("json");
    assert_eq!(
        ready,
        json!({"status": "ready"}),
        "no details without an admin key"
    );

    // Datasets and the results of synchronous solves.
    let cost = ArrayData::F64(wavy_cost(24));
    let r = a.upload(&cost).await;
    assert_eq!(r.status(), 201);
    let meta: Value = r.json().await.expect("json");
    let ds = meta["id"].as_str().expect("id").to_string();
    assert_eq!(meta["tenant"], "alpha");
    let (s, solved) = status_of(
        a.post("/v1/grid/distance", &distance_request(&ds), &[])
            .await,
    )
    .await;
    assert_eq!(s, 200, "{solved}");
    let results: Vec<String> = ["distance", "labels"]
        .iter()
        .map(|k| solved[k]["id"].as_str().expect("result id").to_string())
        .collect();
    for id in std::iter::once(&ds).chain(&results) {
        assert_eq!(a.get(&format!("/v1/datasets/{id}")).await.status(), 200);
        assert_eq!(
            b.get(&format!("/v1/datasets/{id}")).await.status(),
            404,
            "meta of {id}"
        );
        assert_eq!(
            b.get(&format!("/v1/datasets/{id}/data")).await.status(),
            404
        );
        assert_eq!(b.delete(&format!("/v1/datasets/{id}")).await.status(), 404);
    }
    let listed = b.json("/v1/datasets").await;
    assert_eq!(listed["items"], json!([]), "{listed}");
    let listed = a.json("/v1/datasets").await;
    assert_eq!(
        listed["items"].as_array().map(Vec::len),
        Some(3),
        "{listed}"
    );
    // Naming another tenant's dataset in a solve, synchronous or as a job.
    let (s, p) = status_of(
        b.post("/v1/grid/distance", &distance_request(&ds), &[])
            .await,
    )
    .await;
    assert_eq!((s, p["field"].as_str()), (404, Some("cost.dataset")), "{p}");
    let job = json!({"operation": "grid.distance", "params": distance_request(&ds)});
    let (s, p) = status_of(b.post("/v1/jobs", &job, &[]).await).await;
    assert_eq!(s, 404, "{p}");

    // Jobs, their results and their idempotency keys.
    let key = [("idempotency-key", "same-key")];
    let (s, submitted) = status_of(a.post("/v1/jobs", &job, &key).await).await;
    assert_eq!(s, 202, "{submitted}");
    let job_id = submitted["id"].as_str().expect("job id").to_string();
    let done = a.wait_final(&job_id).await;
    assert_eq!(done["state"], "succeeded", "{done}");
    assert_eq!(
        a.get(&format!("/v1/jobs/{job_id}/results/distance"))
            .await
            .status(),
        200
    );
    assert_eq!(b.get(&format!("/v1/jobs/{job_id}")).await.status(), 404);
    assert_eq!(
        b.get(&format!("/v1/jobs/{job_id}/results/distance"))
            .await
            .status(),
        404
    );
    let cancel = json!({});
    assert_eq!(
        b.post(&format!("/v1/jobs/{job_id}/cancel"), &cancel, &[])
            .await
            .status(),
        404
    );
    assert_eq!(b.json("/v1/jobs").await["jobs"], json!([]));
    assert_eq!(
        a.json("/v1/jobs").await["jobs"].as_array().map(Vec::len),
        Some(1)
    );
    // The same key replayed by its tenant returns its job ...
    let r = a.post("/v1/jobs", &job, &key).await;
    assert_eq!(
        r.headers().get("idempotent-replayed").map(|v| v.as_bytes()),
        Some(&b"true"[..])
    );
    let (_, replayed) = status_of(r).await;
    assert_eq!(replayed["id"], job_id.as_str());
    // ... and is another tenant's own key: beta's job on its own dataset.
    let own = b.upload(&cost).await.json::<Value>().await.expect("json");
    let beta_job = json!({"operation": "grid.distance",
        "params": distance_request(own["id"].as_str().expect("id"))});
    let r = b.post("/v1/jobs", &beta_job, &key).await;
    assert!(!r.headers().contains_key("idempotent-replayed"));
    let (s, theirs) = status_of(r).await;
    assert_eq!(s, 202, "{theirs}");
    assert_ne!(theirs["id"], job_id.as_str());

    // Collections.
    let (s, col) = status_of(
        a.post(
            "/v1/collections",
            &json!({"name": "parts", "descriptor": {"landmarks": 8, "bins": 8}}),
            &[],
        )
        .await,
    )
    .await;
    assert_eq!(s, 201, "{col}");
    let col = col["id"].as_str().expect("collection id").to_string();
    assert_eq!(a.get(&format!("/v1/collections/{col}")).await.status(), 200);
    assert_eq!(b.get(&format!("/v1/collections/{col}")).await.status(), 404);
    assert_eq!(b.json("/v1/collections").await["collections"], json!([]));
    let shape = json!({"mesh": "ds_0192f1b27c1e7d3a9d553c0f2b8a1e44"});
    assert_eq!(
        b.post(&format!("/v1/collections/{col}/shapes"), &shape, &[])
            .await
            .status(),
        404
    );
    assert_eq!(
        b.delete(&format!("/v1/collections/{col}")).await.status(),
        404
    );
    assert_eq!(
        a.get(&format!("/v1/collections/{col}")).await.status(),
        200,
        "still there"
    );
    assert_eq!(
        a.delete(&format!("/v1/collections/{col}")).await.status(),
        204
    );

    // The owner deletes its dataset; the other tenant never could.
    assert_eq!(a.delete(&format!("/v1/datasets/{ds}")).await.status(), 204);
}

/// Revocation, rate limits, admin routes, the origin check and the quota.
async fn keys_are_enforced(server: &Server, storage: &[&str], data_dir: &Path) {
    let key = create_key(storage, "gamma", &[]);
    let c = As::new(server, &key);
    assert_eq!(c.get("/v1/jobs").await.status(), 200);
    // Only an admin reads the metrics and the readiness details.
    assert_eq!(c.get("/metrics").await.status(), 403);
    let admin = As::new(server, &create_key(storage, "ops", &["--admin"]));
    assert_eq!(admin.get("/metrics").await.status(), 200);
    let ready = admin.json("/readyz").await;
    assert!(ready["pool_threads"].is_u64(), "{ready}");

    // A page of another site cannot upload, even with the visitor's key.
    let r = c
        .client
        .post(format!("{}/v1/datasets", server.base))
        .header("content-type", "application/x-npy")
        .header("origin", "https://evil.example")
        .header("sec-fetch-site", "cross-site")
        .body(geodex::io::encode_npy(&ArrayData::F64(wavy_cost(4))).expect("npy"))
        .send()
        .await
        .expect("POST");
    let (s, p) = status_of(r).await;
    assert_eq!((s, p["field"].as_str()), (403, Some("Origin")), "{p}");

    // A key with a rate limit: a burst of 2, then 429 with Retry-After.
    let slow = As::new(
        server,
        &create_key(storage, "delta", &["--rate-per-sec", "0.5", "--burst", "2"]),
    );
    assert_eq!(slow.get("/v1/jobs").await.status(), 200);
    assert_eq!(slow.get("/v1/jobs").await.status(), 200);
    let r = slow.get("/v1/jobs").await;
    assert_eq!(r.status(), 429);
    let wait: u64 = r
        .headers()
        .get("retry-after")
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.parse().ok())
        .expect("Retry-After");
    assert!((1..=2).contains(&wait), "{wait}");

    // A tenant quota of 1 KB: a 24 x 24 f64 upload (4.7 KB) is a 507.
    let small = As::new(
        server,
        &create_key(storage, "epsilon", &["--quota-bytes", "1000"]),
    );
    let (s, p) = status_of(small.upload(&ArrayData::F64(wavy_cost(24))).await).await;
    assert_eq!(s, 507, "{p}");
    assert!(
        p["detail"].as_str().is_some_and(|d| d.contains("epsilon")),
        "{p}"
    );
    // An 8 x 8 cost (640 bytes) fits; its job's results (a 640-byte distance
    // and labels) do not: the job fails with the 507, and leaves no file.
    let (s, meta) = status_of(small.upload(&ArrayData::F64(wavy_cost(8))).await).await;
    assert_eq!(s, 201, "{meta}");
    let job = json!({"operation": "grid.distance",
        "params": distance_request(meta["id"].as_str().expect("id"))});
    let (s, submitted) = status_of(small.post("/v1/jobs", &job, &[]).await).await;
    assert_eq!(s, 202, "{submitted}");
    let id = submitted["id"].as_str().expect("job id").to_string();
    let done = small.wait_final(&id).await;
    assert_eq!(done["state"], "failed", "{done}");
    assert_eq!(done["error"]["status"], 507, "{done}");
    assert!(
        done["error"]["detail"]
            .as_str()
            .is_some_and(|d| d.contains("epsilon")),
        "{done}"
    );
    assert_eq!(
        attempt_dirs(&data_dir.join("results"), &id),
        0,
        "files of {id} left behind"
    );

    // Wrong keys: malformed, unknown, revoked (within the 2 s cache).
    let mut unknown = key.clone();
    let last = unknown.pop().expect("non-empty");
    unknown.push(if last == '0' { '1' } else { '0' });
    for bad in ["nope", unknown.as_str()] {
        assert_eq!(
            As::new(server, bad).get("/v1/jobs").await.status(),
            401,
            "{bad}"
        );
    }
    let id = format!("key_{}", &key[4..20]);
    let listed = keys(storage, &["list", "--json"]);
    assert!(
        listed.contains(&id) && !listed.contains(&key[21..]),
        "{listed}"
    );
    keys(storage, &["revoke", &id]);
    tokio::time::sleep(geodex::auth::VERIFY_CACHE + Duration::from_millis(300)).await;
    let (s, p) = status_of(c.get("/v1/jobs").await).await;
    assert_eq!(s, 401, "{p}");
    assert!(
        p["detail"].as_str().is_some_and(|d| d.contains("revoked")),
        "{p}"
    );
}

async fn start(dir: &Path, extra: &[&str]) -> Server {
    let mut args = vec!["--auth"];
    args.extend_from_slice(extra);
    Server::start(dir, "auth", &args).await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tenants_on_sqlite() {
    let dir = tempfile::tempdir().expect("tempdir");
    let data = dir.path().to_str().expect("utf-8 path").to_string();
    let storage = ["--data-dir", data.as_str()];
    let server = start(dir.path(), &[]).await;
    tenants_are_isolated(&server, &storage).await;
    keys_are_enforced(&server, &storage, dir.path()).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tenants_on_postgres() {
    let Some(base) = std::env::var("GEODEX_TEST_POSTGRES_URL")
        .ok()
        .filter(|u| !u.is_empty())
    else {
        eprintln!("skipped: set GEODEX_TEST_POSTGRES_URL to run the PostgreSQL tenant test");
        return;
    };
    let pool = sqlx::PgPool::connect(&base).await.expect("PostgreSQL");
    let schema = format!("geodex_auth_{}", uuid::Uuid::new_v4().simple());
    pool.execute(sqlx::AssertSqlSafe(format!("CREATE SCHEMA {schema}")))
        .await
        .expect("schema");
    let sep = if base.contains('?') { '&' } else { '?' };
    let url = format!("{base}{sep}options[search_path]={schema}");
    let dir = tempfile::tempdir().expect("tempdir");
    let data = dir.path().to_str().expect("utf-8 path").to_string();
    let storage = ["--data-dir", data.as_str(), "--queue", url.as_str()];
    let server = start(dir.path(), &["--queue", url.as_str()]).await;
    tenants_are_isolated(&server, &storage).await;
    keys_are_enforced(&server, &storage, dir.path()).await;
    drop(server);
    let _ = pool
        .execute(sqlx::AssertSqlSafe(format!("DROP SCHEMA {schema} CASCADE")))
        .await;
}

/// Without `--auth` and without a key, the service refuses a non-loopback
/// address and says how to create a key; `--auth` lets it start.
#[test]
fn a_public_address_needs_auth() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = Command::new(env!("CARGO_BIN_EXE_geodex"))
        .args(["serve", "--addr", "0.0.0.0:0", "--data-dir"])
        .arg(dir.path())
        .output()
        .expect("run");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("refusing to serve on 0.0.0.0") && err.contains("geodex keys create"),
        "{err}"
    );
}

/// A database password never appears in `--help` (from the environment) or
/// in the error of a queue that cannot be reached.
#[test]
fn secrets_are_not_echoed() {
    let secret = "hunter2-s3cret";
    let url = format!("postgres://geo:{secret}@127.0.0.1:1/nowhere");
    let help = Command::new(env!("CARGO_BIN_EXE_geodex"))
        .args(["serve", "--help"])
        .env("GEODEX_QUEUE", &url)
        .output()
        .expect("help");
    let text = String::from_utf8_lossy(&help.stdout);
    assert!(text.contains("--queue") && !text.contains(secret), "{text}");
    let dir = tempfile::tempdir().expect("tempdir");
    let out = Command::new(env!("CARGO_BIN_EXE_geodex"))
        .args([
            "serve",
            "--addr",
            "127.0.0.1:0",
            "--queue",
            &url,
            "--data-dir",
        ])
        .arg(dir.path())
        .output()
        .expect("run");
    assert!(!out.status.success());
    let all = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(!all.contains(secret), "{all}");
    assert!(
        all.contains("geo:***@127.0.0.1:1") || all.contains("queue"),
        "{all}"
    );
}
