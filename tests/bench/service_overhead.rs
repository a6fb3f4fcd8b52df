//! The service's own overhead: a 512² distance request end to end over HTTP
//! against the same solve called in-process.
//!
//! Run with `cargo bench --bench service_overhead` (optionally
//! `-- --repeat 30 --size 512`). It starts the real server on a free loopback
//! port with a pool of one thread, uploads a 512² f64 cost once, then times:
//! * `in-process`: `ops::grid_distance::execute` on the decoded array;
//! * `http, json`: `POST /v1/grid/distance` answered with the ids of the stored
//!   distance and label datasets (what a front end chains into later calls);
//! * `http, npy`: the same with `Accept: application/x-npy`, the distance array
//!   streamed back (2 MiB) without being stored.
//!
//! It prints the median and minimum of each, and the overhead against the
//! target of the issue: at most 20 % of the solve plus 2 ms.

use std::collections::HashMap;
use std::sync::Arc;
use std::time::{Duration, Instant};

use geodex::app::Application;
use geodex::config::ServeArgs;
use geodex::io::{self, ArrayData};
use geodex::numerics::Control;
use geodex::ops::grid_distance::{self, GridDistanceRequest};
use geodex::ops::{InputArray, OpLimits};
use ndarray::ArrayD;

fn stats(mut v: Vec<Duration>) -> (f64, f64) {
    v.sort();
    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    (ms(v[v.len() / 2]), ms(v[0]))
}

fn arg(name: &str, default: usize) -> usize {
    let args: Vec<String> = std::env::args().collect();
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1))
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

#[tokio::main]
async fn main() -> anyhow::Result<()> {
    let n = arg("--size", 512);
    let repeat = arg("--repeat", 20);
    let cost = ArrayD::from_shape_fn(ndarray::IxDyn(&[n, n]), |ix| {
        1.0 + 0.5 * (0.05 * ix[0] as f64).sin() * (0.03 * ix[1] as f64).cos()
    });
    let cost = ArrayData::F64(cost);

    let dir = tempfile::tempdir()?;
    let settings = ServeArgs {
        addr: "127.0.0.1:0".parse()?,
        data_dir: dir.path().to_path_buf(),
        pool_threads: Some(1),
        ..ServeArgs::default()
    };
    let app = Application::build(settings).await?;
    let base = format!("http://127.0.0.1:{}", app.port());
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let server = tokio::spawn(
        app.with_shutdown(async move {
            let _ = stopped.await;
        })
        .run_until_stopped(),
    );
    let client = reqwest::Client::new();
    let res = client
        .post(format!("{base}/v1/datasets"))
        .header("content-type", "application/x-npy")
        .body(io::encode_npy(&cost)?)
        .send()
        .await?;
    anyhow::ensure!(res.status() == 201, "upload failed: {}", res.status());
    let meta: serde_json::Value = res.json().await?;
    let id = meta["id"].as_str().unwrap_or_default().to_string();

    let body = serde_json::json!({
        "cost": {"dataset": id},
        "sources": [{"point": [n as f64 / 3.0, n as f64 / 2.0]}],
    });
    let req: GridDistanceRequest = serde_json::from_value(body.clone())?;
    let inputs: HashMap<String, InputArray> = [(
        id.clone(),
        InputArray {
            array: Arc::new(cost),
            spacing: None,
        },
    )]
    .into();

    let mut inproc = Vec::new();
    let mut json = Vec::new();
    let mut npy = Vec::new();
    for _ in 0..repeat {
        let t = Instant::now();
        grid_distance::execute(&req, &inputs, &OpLimits::default(), &Control::new())?;
        inproc.push(t.elapsed());

        let t = Instant::now();
        let res = client
            .post(format!("{base}/v1/grid/distance"))
            .json(&body)
            .send()
            .await?;
        anyhow::ensure!(res.status() == 200, "distance failed: {}", res.status());
        res.bytes().await?;
        json.push(t.elapsed());

        let t = Instant::now();
        let res = client
            .post(format!("{base}/v1/grid/distance"))
            .header("accept", "application/x-npy")
            .json(&body)
            .send()
            .await?;
        anyhow::ensure!(res.status() == 200, "distance failed: {}", res.status());
        res.bytes().await?;
        npy.push(t.elapsed());
    }
    let (base_med, base_min) = stats(inproc);
    println!("service overhead, {n}x{n} grid, {repeat} repeats, pool of 1 thread");
    println!(
        "{:<12} {:>10} {:>10} {:>14} {:>12}",
        "case", "median ms", "min ms", "overhead ms", "target ms"
    );
    println!("{:<12} {:>10.2} {:>10.2}", "in-process", base_med, base_min);
    let target = 0.2 * base_med + 2.0;
    for (name, v) in [("http, json", json), ("http, npy", npy)] {
        let (med, min) = stats(v);
        let over = med - base_med;
        println!(
            "{name:<12} {med:>10.2} {min:>10.2} {over:>14.2} {target:>12.2} {}",
            if over <= target { "ok" } else { "OVER" }
        );
    }
    let _ = stop.send(());
    server.await??;
    Ok(())
}
