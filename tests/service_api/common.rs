//! Starting a server for a test, and small helpers.

use geodex::app::Application;
use geodex::config::ServeArgs;
use geodex::io::{self, ArrayData};
use ndarray::ArrayD;
use tokio::sync::oneshot;

/// A running server.
pub struct TestApp {
    pub base: String,
    pub client: reqwest::Client,
    _dir: tempfile::TempDir,
    _stop: oneshot::Sender<()>,
}

impl TestApp {
    pub fn url(&self, path: &str) -> String {
        format!("{}{}", self.base, path)
    }

    /// `GET path`, panicking if the request cannot be sent.
    pub async fn get(&self, path: &str) -> reqwest::Response {
        self.client
            .get(self.url(path))
            .send()
            .await
            .unwrap_or_else(|e| panic!("GET {path}: {e}"))
    }

    /// Uploads an array as NPY and returns its id.
    pub async fn upload(&self, array: &ArrayData) -> String {
        let body = io::encode_npy(array).expect("encode npy");
        let res = self
            .client
            .post(self.url("/v1/datasets"))
            .header("content-type", "application/x-npy")
            .body(body)
            .send()
            .await
            .expect("upload");
        assert_eq!(res.status(), 201, "{:?}", res.text().await);
        let meta: serde_json::Value = res.json().await.expect("json");
        meta["id"].as_str().expect("id").to_string()
    }
}

impl TestApp {
    /// Downloads a result array (`{"data_url": ...}`) as NPY and decodes it.
    pub async fn download(&self, reference: &serde_json::Value) -> ArrayData {
        let url = format!(
            "{}?format=npy",
            reference["data_url"].as_str().expect("data_url")
        );
        let bytes = self.get(&url).await.bytes().await.expect("bytes");
        io::decode(&bytes, None, &io::Limits::default())
            .expect("decode")
            .array
    }
}

/// The values of an f64 result array (see [`TestApp::download`]).
pub async fn f64_values(app: &TestApp, reference: &serde_json::Value) -> Vec<f64> {
    match app.download(reference).await {
        ArrayData::F64(a) => a.iter().copied().collect(),
        other => panic!("{:?}", other.dtype()),
    }
}

/// Starts a server with the defaults changed by `tune`.
pub async fn spawn(tune: impl FnOnce(&mut ServeArgs)) -> TestApp {
    let dir = tempfile::tempdir().expect("tempdir");
    let mut settings = ServeArgs {
        addr: "127.0.0.1:0".parse().expect("addr"),
        data_dir: dir.path().to_path_buf(),
        pool_threads: Some(2),
        ..ServeArgs::default()
    };
    tune(&mut settings);
    let app = Application::build(settings).await.expect("build");
    let port = app.port();
    let (tx, rx) = oneshot::channel::<()>();
    let app = app.with_shutdown(async move {
        let _ = rx.await;
    });
    tokio::spawn(app.run_until_stopped());
    TestApp {
        base: format!("http://127.0.0.1:{port}"),
        client: reqwest::Client::new(),
        _dir: dir,
        _stop: tx,
    }
}

/// A smooth positive 2D cost field `W(i, j) = 1 + 0.5 sin(0.3 i) cos(0.2 j)`.
pub fn wavy_cost(n0: usize, n1: usize) -> ArrayD<f64> {
    ArrayD::from_shape_fn(ndarray::IxDyn(&[n0, n1]), |ix| {
        1.0 + 0.5 * (0.3 * ix[0] as f64).sin() * (0.2 * ix[1] as f64).cos()
    })
}

/// Checks that `res` is a problem+json answer with this status and returns its body.
pub async fn problem(res: reqwest::Response, status: u16) -> serde_json::Value {
    let got = res.status().as_u16();
    let ct = res
        .headers()
        .get("content-type")
        .and_then(|v| v.to_str().ok())
        .unwrap_or("")
        .to_string();
    let has_id = res.headers().contains_key("x-request-id");
    let body = res.text().await.expect("body");
    assert_eq!(got, status, "body: {body}");
    assert_eq!(ct, "application/problem+json", "body: {body}");
    assert!(has_id, "x-request-id header");
    let v: serde_json::Value = serde_json::from_str(&body).expect("problem json");
    assert_eq!(v["status"], status);
    assert!(v["type"]
        .as_str()
        .is_some_and(|t| t.starts_with("https://geodex.dev/problems/")));
    assert!(v["title"].is_string() && v["detail"].is_string());
    assert!(v["instance"].as_str().is_some_and(|i| i.starts_with('/')));
    assert!(v["request_id"].is_string());
    v
}
