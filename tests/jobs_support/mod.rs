//! Shared by the `jobs_*` tests: the real `geodex` binary started as a child
//! process (so that it can be killed with SIGKILL), and small HTTP helpers.
#![allow(dead_code)]

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::time::{Duration, Instant};

use geodex::io::{self, ArrayData};
use geodex::numerics::Control;
use geodex::ops::grid_distance::GridDistanceRequest;
use geodex::ops::{InputArray, OpLimits};
use ndarray::ArrayD;
use serde_json::{json, Value};

/// Side of the square grid of a "moderate" job: a few hundred ms in the
/// debug profile, long enough to be killed mid-run.
pub const N: usize = 360;

/// A running `geodex serve` child process.
pub struct Server {
    child: Option<Child>,
    pub base: String,
    pub client: reqwest::Client,
    pub log: PathBuf,
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .expect("free port")
}

impl Server {
    /// Starts the binary on a free port with its data under `data_dir`, and
    /// waits until `/healthz` answers.
    pub async fn start(data_dir: &Path, name: &str, extra: &[&str]) -> Server {
        Self::start_under(&[], data_dir, name, extra).await
    }

    /// As [`Server::start`], with the binary run by `wrapper` (a program and
    /// its arguments, which must end by executing the rest of its command
    /// line in the same process, as `unshare` does).
    pub async fn start_under(
        wrapper: &[&str],
        data_dir: &Path,
        name: &str,
        extra: &[&str],
    ) -> Server {
        let port = free_port();
        let log = data_dir.join(format!("{name}-{port}.log"));
        let out = std::fs::File::create(&log).expect("log file");
        let err = out.try_clone().expect("log file");
        let bin = env!("CARGO_BIN_EXE_geodex");
        let mut command = match wrapper.split_first() {
            Some((program, args)) => {
                let mut c = Command::new(program);
                c.args(args).arg(bin);
                c
            }
            None => Command::new(bin),
        };
        let child = command
            .arg("serve")
            .arg("--addr")
            .arg(format!("127.0.0.1:{port}"))
            .arg("--data-dir")
            .arg(data_dir)
            .args(extra)
            .env("RUST_LOG", "info,sqlx=warn")
            .stdin(Stdio::null())
            .stdout(out)
            .stderr(err)
            .spawn()
            .expect("start geodex");
        let server = Server {
            child: Some(child),
            base: format!("http://127.0.0.1:{port}"),
            client: reqwest::Client::new(),
            log,
        };
        let t = Instant::now();
        loop {
            if let Ok(r) = server.client.get(server.url("/healthz")).send().await {
                if r.status() == 200 {
                    return server;
                }
            }
            assert!(
                t.elapsed() < Duration::from_secs(60),
                "server did not start: {}",
                std::fs::read_to_string(&server.log).unwrap_or_default()
            );
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    }

    /// The child's process id.
    pub fn pid(&self) -> Option<u32> {
        self.child.as_ref().map(Child::id)
    }

    pub fn url(&self, path: &str) -> String {
        format!("{}{}", self.base, path)
    }

    /// SIGKILL: the process dies at once, leases and all.
    pub fn kill(&mut self) {
        if let Some(mut c) = self.child.take() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }

    pub async fn get(&self, path: &str) -> reqwest::Response {
        self.client
            .get(self.url(path))
            .send()
            .await
            .unwrap_or_else(|e| panic!("GET {path}: {e}"))
    }

    pub async fn get_json(&self, path: &str) -> Value {
        let r = self.get(path).await;
        assert_eq!(r.status(), 200, "GET {path}");
        r.json().await.expect("json")
    }

    pub async fn post_json(
        &self,
        path: &str,
        body: &Value,
        headers: &[(&str, &str)],
    ) -> reqwest::Response {
        let mut req = self.client.post(self.url(path)).json(body);
        for (k, v) in headers {
            req = req.header(*k, *v);
        }
        req.send()
            .await
            .unwrap_or_else(|e| panic!("POST {path}: {e}"))
    }

    /// Submits a job and returns its id (asserting 202 + Location).
    pub async fn submit(&self, body: &Value) -> String {
        let r = self.post_json("/v1/jobs", body, &[]).await;
        let status = r.status();
        let location = r
            .headers()
            .get("location")
            .and_then(|v| v.to_str().ok())
            .map(str::to_string);
        let v: Value = r.json().await.expect("json");
        assert_eq!(status, 202, "{v}");
        let id = v["id"].as_str().expect("id").to_string();
        assert_eq!(location.as_deref(), Some(format!("/v1/jobs/{id}").as_str()));
        id
    }

    pub async fn job(&self, id: &str) -> Value {
        self.get_json(&format!("/v1/jobs/{id}")).await
    }

    /// Polls until the job is final; returns it.
    pub async fn wait_final(&self, id: &str, timeout: Duration) -> Value {
        let t = Instant::now();
        loop {
            let j = self.job(id).await;
            if ["succeeded", "failed", "cancelled"].contains(&j["state"].as_str().unwrap_or("")) {
                return j;
            }
            assert!(t.elapsed() < timeout, "job {id} not done: {j}");
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    }

    /// Downloads a result array.
    pub async fn result(&self, id: &str, name: &str) -> ArrayData {
        let r = self.get(&format!("/v1/jobs/{id}/results/{name}")).await;
        assert_eq!(r.status(), 200);
        assert_eq!(
            r.headers()
                .get("content-type")
                .and_then(|v| v.to_str().ok()),
            Some("application/x-npy")
        );
        let bytes = r.bytes().await.expect("bytes");
        io::decode(&bytes, Some(io::Format::Npy), &io::Limits::default())
            .expect("npy")
            .array
    }

    /// Uploads an array as a dataset; returns its id.
    pub async fn upload(&self, array: &ArrayData) -> String {
        let body = io::encode_npy(array).expect("encode");
        let r = self
            .client
            .post(self.url("/v1/datasets"))
            .header("content-type", "application/x-npy")
            .body(body)
            .send()
            .await
            .expect("upload");
        assert_eq!(r.status(), 201);
        let v: Value = r.json().await.expect("json");
        v["id"].as_str().expect("id").to_string()
    }

    pub fn log_text(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        self.kill();
    }
}

/// A smooth positive cost `W = 1 + 0.5 sin(0.3 i) cos(0.2 j)` on an n x n grid.
pub fn wavy_cost(n: usize) -> ArrayD<f64> {
    ArrayD::from_shape_fn(ndarray::IxDyn(&[n, n]), |ix| {
        1.0 + 0.5 * (0.3 * ix[0] as f64).sin() * (0.2 * ix[1] as f64).cos()
    })
}

/// The `k`-th distinct distance request over the dataset `cost`.
pub fn request(cost: &str, k: usize, n: usize) -> Value {
    let a = (3 + 7 * k) % (n - 2);
    let b = (5 + 13 * k) % (n - 2);
    json!({
        "cost": {"dataset": cost},
        "sources": [{"point": [a as f64 + 0.5, b as f64]}],
        "outputs": {"labels": false}
    })
}

/// The synchronous computation of `params` (what `POST /v1/grid/distance`
/// runs), on the given cost array.
pub fn compute(params: &Value, cost_id: &str, cost: &ArrayD<f64>) -> ArrayD<f64> {
    let req: GridDistanceRequest = serde_json::from_value(params.clone()).expect("request");
    let mut inputs = HashMap::new();
    inputs.insert(
        cost_id.to_string(),
        InputArray {
            array: Arc::new(ArrayData::F64(cost.clone())),
            spacing: None,
        },
    );
    geodex::ops::grid_distance::execute(&req, &inputs, &OpLimits::default(), &Control::new())
        .expect("solve")
        .distance
}

/// Asserts two distance maps are identical (same code, same input: bit for bit).
pub fn assert_same(got: &ArrayData, want: &ArrayD<f64>, what: &str) {
    let ArrayData::F64(got) = got else {
        panic!("{what}: expected f64, got {:?}", got.dtype());
    };
    assert_eq!(got.shape(), want.shape(), "{what}: shape");
    let worst = got
        .iter()
        .zip(want.iter())
        .map(|(a, b)| if a == b { 0.0 } else { (a - b).abs() })
        .fold(0.0_f64, f64::max);
    assert!(worst == 0.0, "{what}: differs by up to {worst}");
}

/// Counts the attempt directories under `<results>/results/<job>/`.
pub fn attempt_dirs(results: &Path, job: &str) -> usize {
    std::fs::read_dir(results.join("results").join(job))
        .map(|d| d.filter(|e| e.is_ok()).count())
        .unwrap_or(0)
}
