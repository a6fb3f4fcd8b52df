//! Mesh geodesics benchmark: icospheres of radius 1 (level 6: 40,962
//! vertices; 7: 163,842; 8: 655,362).
//!
//! ```text
//! cargo bench --bench mesh_geodesics -- heat 7      # factorisation, per-query time, error
//! cargo bench --bench mesh_geodesics -- fmm 7       # fast marching time, error
//! cargo bench --bench mesh_geodesics -- dijkstra 7
//! cargo bench --bench mesh_geodesics -- dump 7 /tmp/ico7.obj   # the mesh for the Python peers
//! ```
//!
//! One case per process so that the peak resident memory (`VmHWM`) is the
//! case's own. Prints one JSON line. `GEODEX_THREADS=1` (default) runs faer
//! sequentially, like the single-thread figures of the peers.

use std::time::Instant;

use geodex::io::mesh::write::write_obj;
use geodex::numerics::mesh::shapes::{great_circle, icosphere};
use geodex::numerics::mesh::{
    fast_marching_distance, FastMarchingOptions, HeatOptions, HeatSolver, SurfacePoint, Topology,
};
use geodex::numerics::Control;

fn peak_mib() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines().find(|l| l.starts_with("VmHWM:")).and_then(|l| {
                l.split_whitespace()
                    .nth(1)
                    .and_then(|k| k.parse::<f64>().ok())
            })
        })
        .map_or(f64::NAN, |kib| kib / 1024.0)
}

fn errors(mesh: &geodex::numerics::mesh::TriMesh, d: &[f64]) -> (f64, f64) {
    let p0 = mesh.position(0);
    let (mut sum, mut n, mut max) = (0.0, 0, 0.0f64);
    for (v, &x) in d.iter().enumerate() {
        let e = great_circle(p0, mesh.position(v as u32), 1.0);
        max = max.max((x - e).abs());
        if e > 0.1 {
            sum += (x - e).abs() / e;
            n += 1;
        }
    }
    (sum / n as f64, max)
}

fn main() {
    let args: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| a != "--bench")
        .collect();
    let case = args.first().map_or("heat", String::as_str);
    let level: u32 = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(6);
    let threads = std::env::var("GEODEX_THREADS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1usize);
    if threads == 1 {
        faer::set_global_parallelism(faer::Par::Seq);
    } else {
        faer::set_global_parallelism(faer::Par::rayon(threads));
    }
    let mesh = icosphere(level, 1.0);
    let topo = Topology::new(&mesh);
    let n = mesh.num_vertices();
    let control = Control::new();
    let src = [SurfacePoint::Vertex(0)];
    match case {
        "dump" => {
            let path = args.get(2).map_or("/tmp/ico.obj", String::as_str);
            if let Err(e) = std::fs::write(path, write_obj(&mesh)) {
                eprintln!("{path}: {e}");
            }
            println!("{{\"case\":\"dump\",\"vertices\":{n},\"path\":\"{path}\"}}");
        }
        "heat" => {
            let t0 = Instant::now();
            let Ok(solver) = HeatSolver::new(&mesh, &topo, &HeatOptions::default(), &control)
            else {
                eprintln!("factorisation failed");
                return;
            };
            let factor = t0.elapsed().as_secs_f64();
            let mut best = f64::INFINITY;
            let mut d = Vec::new();
            for _ in 0..5 {
                let t = Instant::now();
                let Ok(r) = solver.distance(&mesh, &src, f64::INFINITY, &control) else {
                    eprintln!("query failed");
                    return;
                };
                best = best.min(t.elapsed().as_secs_f64());
                d = r.distance;
            }
            let (mean, max) = errors(&mesh, &d);
            println!(
                "{{\"case\":\"heat\",\"vertices\":{n},\"threads\":{threads},\"factor_s\":{factor:.4},\"query_s\":{best:.4},\"t\":{:.3e},\"mean_rel_err\":{mean:.5},\"max_abs_err\":{max:.5},\"peak_mib\":{:.1}}}",
                solver.t(),
                peak_mib()
            );
        }
        "fmm" | "dijkstra" => {
            let mut best = f64::INFINITY;
            let mut d = Vec::new();
            for _ in 0..3 {
                let t = Instant::now();
                let r = if case == "fmm" {
                    fast_marching_distance(
                        &mesh,
                        &topo,
                        &src,
                        &FastMarchingOptions::default(),
                        &control,
                    )
                } else {
                    geodex::numerics::mesh::dijkstra::dijkstra_distance(
                        &mesh,
                        &src,
                        None,
                        f64::INFINITY,
                        &control,
                    )
                };
                let Ok(r) = r else {
                    eprintln!("solve failed");
                    return;
                };
                best = best.min(t.elapsed().as_secs_f64());
                d = r.distance;
            }
            let (mean, max) = errors(&mesh, &d);
            println!(
                "{{\"case\":\"{case}\",\"vertices\":{n},\"solve_s\":{best:.4},\"mean_rel_err\":{mean:.5},\"max_abs_err\":{max:.5},\"peak_mib\":{:.1}}}",
                peak_mib()
            );
        }
        other => eprintln!("unknown case {other}: heat, fmm, dijkstra or dump"),
    }
}
