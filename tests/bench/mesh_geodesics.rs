//! Mesh geodesics benchmark: icospheres of radius 1 (level 6: 40,962
//! vertices; 7: 163,842; 8: 655,362).
//!
//! ```text
//! cargo bench --bench mesh_geodesics -- heat 7      # factorisation, per-query time, error
//! cargo bench --bench mesh_geodesics -- fmm 7       # fast marching time, error
//! cargo bench --bench mesh_geodesics -- dijkstra 7
//! cargo bench --bench mesh_geodesics -- dump 7 /tmp/ico7.obj   # the mesh for the Python peers
//! cargo bench --bench mesh_geodesics -- exact 6     # exact window propagation (exact: the default, exact1: one worker, exact2: two halves)
//! cargo bench --bench mesh_geodesics -- heat /tmp/dragon.ply   # any mesh file (source: vertex 0)
//! ```
//!
//! With a mesh file instead of a level the errors are left out (no closed
//! form); the heat and fast-marching answers are compared with each other.
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
    let which = args.get(1).map_or("6", String::as_str);
    let level: Option<u32> = which.parse().ok();
    let threads = std::env::var("GEODEX_THREADS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1usize);
    if threads == 1 {
        faer::set_global_parallelism(faer::Par::Seq);
    } else {
        faer::set_global_parallelism(faer::Par::rayon(threads));
    }
    let (mesh, topo) = match level {
        Some(level) => {
            let mesh = icosphere(level, 1.0);
            let topo = Topology::new(&mesh);
            (mesh, topo)
        }
        None => {
            let bytes = match std::fs::read(which) {
                Ok(b) => b,
                Err(e) => {
                    eprintln!("{which}: {e}");
                    return;
                }
            };
            let format = geodex::io::mesh::MeshFormat::from_name(which);
            match geodex::io::mesh::read_mesh(
                &bytes,
                format,
                &geodex::io::mesh::MeshLimits::default(),
            ) {
                Ok(l) => {
                    eprintln!("{which}: {:?}", l.report);
                    (l.mesh, l.topology)
                }
                Err(e) => {
                    eprintln!("{which}: {e}");
                    return;
                }
            }
        }
    };
    let sphere = level.is_some();
    let errors = |mesh: &geodex::numerics::mesh::TriMesh, d: &[f64]| {
        if sphere {
            errors(mesh, d)
        } else {
            (f64::NAN, f64::NAN)
        }
    };
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
            let solver = match HeatSolver::new(&mesh, &topo, &HeatOptions::default(), &control) {
                Ok(s) => s,
                Err(e) => {
                    eprintln!("factorisation failed: {e}");
                    return;
                }
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
        "exact" | "exact1" | "exact2" => {
            // `exact` as the library runs it (two halves where the split
            // pays, on a pool of two threads or more), `exact1` on one
            // worker, `exact2` split in two halves whenever a plane can.
            let threads = match case {
                "exact1" => 1,
                "exact2" => 2,
                _ => 0,
            };
            let t = Instant::now();
            let r = if threads == 0 {
                geodex::numerics::mesh::exact::exact_distance_with_stats(
                    &mesh,
                    &topo,
                    &src,
                    f64::INFINITY,
                    &control,
                )
            } else {
                geodex::numerics::mesh::exact::exact_distance_threads(
                    &mesh,
                    &topo,
                    &src,
                    f64::INFINITY,
                    threads,
                    &control,
                )
            };
            let Ok((r, stats)) = r else {
                eprintln!("solve failed");
                return;
            };
            let secs = t.elapsed().as_secs_f64();
            let (mean, max) = errors(&mesh, &r.distance);
            println!(
                "{{\"case\":\"{case}\",\"vertices\":{n},\"solve_s\":{secs:.4},\"windows_per_vertex\":{:.1},\"created_per_vertex\":{:.1},\"pseudo_sources\":{},\"sector_emissions\":{},\"max_queue\":{},\"mean_rel_err\":{mean:.3e},\"max_abs_err\":{max:.3e},\"peak_mib\":{:.1}}}",
                stats.windows_propagated as f64 / n as f64,
                stats.windows_created as f64 / n as f64,
                stats.pseudo_sources,
                stats.sector_emissions,
                stats.max_queue,
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
