//! Speed of minimal paths (issue 4).
//!
//! Run with `cargo bench --bench minimal_paths` (optionally
//! `-- --paths 50 --size2 1024 --size3 256`). It prints:
//! * `descent 2D` / `descent 3D`: time per path once the distance map is
//!   known (core, one thread), on a smooth cost over `N²` and `M³` grids,
//!   end points spread over the grid, source near a corner;
//! * `early stop vs full`: one point-to-point request (`grid.paths` without
//!   a cache) against the full map, 2D and 3D;
//! * `http, cached`: end to end through HTTP on `N²`: the first
//!   `POST /v1/grid/paths` (solve + descent), then requests with new end
//!   points (map from the cache, descent only), median and minimum. Target of
//!   the issue: at most 5 ms per extra path on 1024².

use std::collections::HashMap;
use std::sync::Arc;
use std::time::{Duration, Instant};

use geodex::app::Application;
use geodex::config::ServeArgs;
use geodex::io::{self, ArrayData};
use geodex::numerics::metric::{CostValues, Interpretation};
use geodex::numerics::paths::{DescentOptions, DistanceMap, Isotropic, SourceSet};
use geodex::numerics::{
    solve, Control, EikonalOptions, EikonalProblem, Grid, IsotropicCost, Source,
};
use geodex::ops::grid_paths::{self, GridPathsRequest};
use geodex::ops::{InputArray, OpLimits};
use ndarray::ArrayD;

fn arg(name: &str, default: usize) -> usize {
    let args: Vec<String> = std::env::args().collect();
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1))
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

fn stats(mut v: Vec<Duration>) -> (f64, f64) {
    v.sort();
    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    (ms(v[v.len() / 2]), ms(v[0]))
}

/// A smooth cost `1 + 0.5 sin(0.05 i) cos(0.03 j) [cos(0.04 k)]`.
fn cost(shape: &[usize]) -> Vec<f64> {
    let grid = Grid::unit(shape).unwrap();
    (0..grid.len())
        .map(|c| {
            let [a, b, d] = grid.unravel(c);
            let third = if shape.len() == 3 {
                (0.04 * a as f64).cos()
            } else {
                1.0
            };
            1.0 + 0.5 * (0.05 * b as f64).sin() * (0.03 * d as f64).cos() * third
        })
        .collect()
}

/// `count` end points spread over the far half of the grid (deterministic).
fn ends(shape: &[usize], count: usize) -> Vec<Vec<f64>> {
    (0..count)
        .map(|k| {
            shape
                .iter()
                .enumerate()
                .map(|(axis, &n)| {
                    let t = ((k * (7 + 5 * axis) + 3 * axis) % 97) as f64 / 97.0;
                    (0.5 + 0.45 * t) * (n - 1) as f64
                })
                .collect()
        })
        .collect()
}

fn descent(shape: &[usize], count: usize) {
    let grid = Grid::unit(shape).unwrap();
    let w = cost(shape);
    let src: Vec<f64> = shape.iter().map(|&n| 0.05 * n as f64).collect();
    let problem = EikonalProblem {
        grid: grid.clone(),
        cost: IsotropicCost::new(
            &grid,
            CostValues::F64(w.as_slice().into()),
            Interpretation::Cost,
            None,
        )
        .unwrap(),
        sources: vec![Source::Point(src)],
    };
    let t = Instant::now();
    let out = solve(&problem, &EikonalOptions::DEFAULT, &Control::new()).unwrap();
    let map_s = t.elapsed().as_secs_f64();
    let u: Vec<f64> = out.distance.iter().copied().collect();
    let sources = SourceSet::new(&grid, &problem.sources).unwrap();
    let map = DistanceMap::new(&grid, &u, w.as_slice()).unwrap();
    let mut times = Vec::new();
    let mut vertices = 0;
    for e in ends(shape, count) {
        let t = Instant::now();
        let p = map
            .descend(&sources, &e, &Isotropic, &DescentOptions::default())
            .unwrap();
        times.push(t.elapsed());
        vertices += p.points.len();
    }
    let (med, min) = stats(times);
    println!(
        "descent {:<10} map {:>8.1} ms | per path: median {med:>7.3} ms, min {min:>7.3} ms, {:>5} vertices on average",
        format!("{shape:?}"),
        1e3 * map_s,
        vertices / count
    );
}

fn early_vs_full(shape: &[usize], repeat: usize) {
    let w = cost(shape);
    let array = ArrayData::F64(ArrayD::from_shape_vec(ndarray::IxDyn(shape), w).unwrap());
    let inputs: HashMap<String, InputArray> = [(
        "w".to_string(),
        InputArray {
            array: Arc::new(array),
            spacing: None,
        },
    )]
    .into();
    let src: Vec<f64> = shape.iter().map(|&n| 0.3 * n as f64).collect();
    let end: Vec<f64> = shape.iter().map(|&n| 0.45 * n as f64).collect();
    for early in [true, false] {
        let req: GridPathsRequest = serde_json::from_value(serde_json::json!({
            "cost": {"dataset": "w"},
            "sources": [{"point": src}],
            "ends": [end],
            "early_stop": early,
        }))
        .unwrap();
        let mut times = Vec::new();
        let mut frozen = 0;
        for _ in 0..repeat {
            let t = Instant::now();
            let r = grid_paths::execute(
                &req,
                &inputs,
                &OpLimits::default(),
                &Control::new(),
                None,
                None,
            )
            .unwrap();
            times.push(t.elapsed());
            frozen = r.stats.maps[0].frozen;
        }
        let (med, min) = stats(times);
        println!(
            "point-to-point {:<10} {:<10} median {med:>8.1} ms, min {min:>8.1} ms, {frozen} cells frozen",
            format!("{shape:?}"),
            if early { "early stop" } else { "full map" }
        );
    }
}

async fn http(n: usize, count: usize) -> anyhow::Result<()> {
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
    let array = ArrayData::F64(ArrayD::from_shape_vec(
        ndarray::IxDyn(&[n, n]),
        cost(&[n, n]),
    )?);
    let res = client
        .post(format!("{base}/v1/datasets"))
        .header("content-type", "application/x-npy")
        .body(io::encode_npy(&array)?)
        .send()
        .await?;
    anyhow::ensure!(res.status() == 201, "upload failed: {}", res.status());
    let meta: serde_json::Value = res.json().await?;
    let id = meta["id"].as_str().unwrap_or_default().to_string();
    let source = [0.05 * n as f64, 0.05 * n as f64];
    let request = |end: &[f64], early: bool| {
        serde_json::json!({
            "cost": {"dataset": id},
            "sources": [{"point": source}],
            "ends": [end],
            "early_stop": early,
        })
    };
    // First request: the full map (as a front end would ask for), then descents only.
    let t = Instant::now();
    let res = client
        .post(format!("{base}/v1/grid/paths"))
        .json(&request(&[(n - 1) as f64, (n - 1) as f64], false))
        .send()
        .await?;
    anyhow::ensure!(res.status() == 200, "paths failed: {}", res.text().await?);
    res.bytes().await?;
    let first = t.elapsed();
    let mut times = Vec::new();
    let mut cached = 0;
    for e in ends(&[n, n], count) {
        let t = Instant::now();
        let res = client
            .post(format!("{base}/v1/grid/paths"))
            .json(&request(&e, true))
            .send()
            .await?;
        anyhow::ensure!(res.status() == 200, "paths failed: {}", res.status());
        let v: serde_json::Value = res.json().await?;
        times.push(t.elapsed());
        if v["stats"]["maps"][0]["cached"] == true {
            cached += 1;
        }
    }
    let (med, min) = stats(times);
    println!(
        "http {n}x{n}: first request (full map + path) {:.1} ms; then per new end point: median {med:.2} ms, min {min:.2} ms ({cached}/{count} from the cache) target 5 ms {}",
        first.as_secs_f64() * 1e3,
        if med <= 5.0 { "ok" } else { "OVER" }
    );
    let _ = stop.send(());
    server.await??;
    Ok(())
}

#[tokio::main]
async fn main() -> anyhow::Result<()> {
    let count = arg("--paths", 50);
    let n2 = arg("--size2", 1024);
    let n3 = arg("--size3", 256);
    descent(&[n2, n2], count);
    descent(&[n3, n3, n3], count.min(20));
    early_vs_full(&[n2, n2], 3);
    early_vs_full(&[n3, n3, n3], 1);
    http(n2, count).await
}
