//! Benchmark of the exact polyhedral distance (`numerics::mesh::exact`) on
//! icospheres of radius 1, one vertex source: propagation time (best of
//! `--repeat`), topology time, peak memory of the solve, windows, and the
//! mean / max relative error against great circles.
//!
//! ```sh
//! cargo bench --bench mesh_exact -- --levels 6,7,8 --repeat 3
//! # the same meshes for the Python peers (tests/bench/compare_mesh_exact.py):
//! cargo bench --bench mesh_exact -- --levels 6,7,8 --repeat 1 --dump /tmp/geodex-ico
//! ```
//!
//! Levels 6, 7, 8 have 40,962, 163,842 and 655,362 vertices. One thread.
//! One JSON line per level.

use geodex::numerics::mesh::exact::exact_distance_with_stats;
use geodex::numerics::mesh::{SurfacePoint, Topology};
use geodex::numerics::Control;
use std::time::Instant;

#[path = "../mesh_support/mod.rs"]
mod mesh_support;

fn status_kib(key: &str) -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with(key))?;
    line[key.len()..].split_whitespace().next()?.parse().ok()
}

/// Resets the peak RSS to the current RSS (Linux); returns the current RSS in KiB.
fn reset_peak() -> Option<u64> {
    std::fs::write("/proc/self/clear_refs", "5").ok()?;
    status_kib("VmRSS:")
}

fn main() {
    let mut levels = vec![6u32, 7, 8];
    let mut repeat = 3;
    let mut dump: Option<String> = None;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--levels" => {
                levels = args
                    .next()
                    .unwrap_or_default()
                    .split(',')
                    .filter_map(|s| s.parse().ok())
                    .collect()
            }
            "--repeat" => repeat = args.next().and_then(|s| s.parse().ok()).unwrap_or(3),
            "--dump" => dump = args.next(),
            "--bench" => {}
            other => {
                eprintln!("unknown argument {other}; use --levels 6,7,8 --repeat N --dump DIR");
                std::process::exit(2);
            }
        }
    }
    for level in levels {
        let mesh = mesh_support::icosphere(level);
        if let Some(dir) = &dump {
            std::fs::create_dir_all(dir).unwrap();
            let pos: Vec<f64> = mesh.positions().iter().flatten().copied().collect();
            let fac: Vec<i32> = mesh.faces().iter().flatten().map(|&v| v as i32).collect();
            let pos = ndarray::Array2::from_shape_vec((mesh.num_vertices(), 3), pos).unwrap();
            let fac = ndarray::Array2::from_shape_vec((mesh.num_faces(), 3), fac).unwrap();
            ndarray_npy::write_npy(format!("{dir}/ico{level}_vertices.npy"), &pos).unwrap();
            ndarray_npy::write_npy(format!("{dir}/ico{level}_faces.npy"), &fac).unwrap();
        }
        let t0 = Instant::now();
        let topo = Topology::new(&mesh);
        let topo_s = t0.elapsed().as_secs_f64();
        let before = reset_peak();
        let mut best = f64::INFINITY;
        let mut out = None;
        for _ in 0..repeat {
            let t = Instant::now();
            let r = exact_distance_with_stats(
                &mesh,
                &topo,
                &[SurfacePoint::Vertex(0)],
                f64::INFINITY,
                &Control::new(),
            )
            .unwrap();
            best = best.min(t.elapsed().as_secs_f64());
            out = Some(r);
        }
        let peak = status_kib("VmHWM:");
        let (d, stats) = out.unwrap();
        let p0 = mesh.position(0);
        let (mut sum, mut max) = (0.0, 0.0f64);
        for (v, q) in mesh.positions().iter().enumerate().skip(1) {
            let g = (p0[0] * q[0] + p0[1] * q[1] + p0[2] * q[2])
                .clamp(-1.0, 1.0)
                .acos();
            let e = (d.distance[v] - g).abs() / g;
            sum += e;
            max = max.max(e);
        }
        let n = mesh.num_vertices();
        let extra = match (before, peak) {
            (Some(b), Some(p)) => Some((p.saturating_sub(b)) as f64 * 1024.0 / n as f64),
            _ => None,
        };
        println!(
            "{}",
            serde_json::json!({
                "tool": "geodex",
                "method": "exact (window propagation)",
                "level": level,
                "vertices": n,
                "faces": mesh.num_faces(),
                "repeat": repeat,
                "seconds": best,
                "topology_seconds": topo_s,
                "peak_rss_mib": peak.map(|p| p as f64 / 1024.0),
                "solve_extra_bytes_per_vertex": extra,
                "windows_created": stats.windows_created,
                "windows_propagated": stats.windows_propagated,
                "windows_per_vertex": stats.windows_propagated as f64 / n as f64,
                "max_queue": stats.max_queue,
                "mean_rel_error": sum / (n - 1) as f64,
                "max_rel_error": max,
            })
        );
    }
}
