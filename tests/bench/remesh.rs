//! Surface remeshing benchmark and the helpers of `compare_remesh.py`.
//!
//! ```text
//! cargo bench --bench remesh -- run 8 10000                 # icosphere level 8 (655,362 vertices) to 10k
//! cargo bench --bench remesh -- run 8 10000 anisotropic     # uniform | curvature | anisotropic
//! cargo bench --bench remesh -- run /tmp/scanned/bunny.obj 5000
//! cargo bench --bench remesh -- run 8 1000 uniform OUT.ply default default exact   # [OUT] [sweeps] [lloyd] [sampling]
//! cargo bench --bench remesh -- dump 7 /tmp/ico7.ply        # the icosphere for the Python peers
//! cargo bench --bench remesh -- measure IN.ply OUT.ply      # Hausdorff / diagonal and angle quality
//! ```
//!
//! `run` times the remeshing alone (no Hausdorff) and prints one JSON line
//! with the quality figures; `measure` computes the same figures for any
//! output mesh (pyacvd's, pymeshlab's), so the three tools are measured by
//! one routine: Hausdorff distance by
//! `geodex::numerics::meshing::surface::hausdorff_distance` (vertices, edge
//! midpoints and face centroids of each mesh against the other), over the
//! input's bounding-box diagonal, and the share of triangles whose smallest
//! angle is at least 30°.

use std::time::Instant;

use geodex::io::mesh::write::write_ply;
use geodex::io::mesh::{read_mesh, MeshFormat, MeshLimits};
use geodex::numerics::mesh::shapes::icosphere;
use geodex::numerics::mesh::TriMesh;
use geodex::numerics::meshing::surface::{
    bounding_diagonal, hausdorff_distance, remesh, Adaptation, RemeshOptions, Sampling,
    TopologySummary,
};
use geodex::numerics::Control;

fn load(arg: &str) -> TriMesh {
    if let Ok(level) = arg.parse::<u32>() {
        return icosphere(level, 1.0);
    }
    let bytes = std::fs::read(arg).expect("read mesh");
    let format = MeshFormat::from_name(arg);
    read_mesh(&bytes, format, &MeshLimits::default())
        .expect("decode mesh")
        .mesh
}

/// Smallest angle of each triangle, in degrees.
fn min_angles(mesh: &TriMesh) -> Vec<f64> {
    mesh.faces()
        .iter()
        .map(|f| {
            let p = f.map(|v| mesh.position(v));
            (0..3)
                .map(|k| {
                    let (a, b, c) = (p[k], p[(k + 1) % 3], p[(k + 2) % 3]);
                    let u: [f64; 3] = std::array::from_fn(|j| b[j] - a[j]);
                    let w: [f64; 3] = std::array::from_fn(|j| c[j] - a[j]);
                    let dot: f64 = (0..3).map(|j| u[j] * w[j]).sum();
                    let nu = u.iter().map(|x| x * x).sum::<f64>().sqrt();
                    let nw = w.iter().map(|x| x * x).sum::<f64>().sqrt();
                    (dot / (nu * nw).max(f64::MIN_POSITIVE))
                        .clamp(-1.0, 1.0)
                        .acos()
                        .to_degrees()
                })
                .fold(180.0f64, f64::min)
        })
        .collect()
}

fn quality(input: &TriMesh, out: &TriMesh) -> serde_json::Value {
    let t = Instant::now();
    let h = hausdorff_distance(input, out, &Control::new()).expect("hausdorff");
    let hausdorff_seconds = t.elapsed().as_secs_f64();
    let angles = min_angles(out);
    let good = angles.iter().filter(|&&a| a >= 30.0).count();
    let topo = TopologySummary::of(out);
    serde_json::json!({
        "vertices": out.num_vertices(),
        "triangles": out.num_faces(),
        "hausdorff_relative": h / bounding_diagonal(input),
        "share_min_angle_ge_30": good as f64 / angles.len().max(1) as f64,
        "min_angle": angles.iter().copied().fold(180.0f64, f64::min),
        "mean_min_angle": angles.iter().sum::<f64>() / angles.len().max(1) as f64,
        "genus": topo.genus,
        "non_manifold_edges": topo.non_manifold_edges,
        "hausdorff_seconds": hausdorff_seconds,
    })
}

fn main() {
    let args: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| a != "--bench")
        .collect();
    match args.first().map(String::as_str) {
        Some("dump") => {
            let mesh = load(&args[1]);
            std::fs::write(&args[2], write_ply(&mesh, &[])).expect("write");
            println!("{} vertices to {}", mesh.num_vertices(), args[2]);
        }
        Some("measure") => {
            let (input, out) = (load(&args[1]), load(&args[2]));
            println!("{}", quality(&input, &out));
        }
        Some("run") => {
            let mesh = load(&args[1]);
            let count: usize = args.get(2).map_or(10_000, |c| c.parse().expect("count"));
            let adaptation = match args.get(3).map(String::as_str) {
                None | Some("uniform") => Adaptation::Uniform,
                Some("curvature") => Adaptation::Curvature { strength: 2.0 },
                Some("anisotropic") => Adaptation::Anisotropic { max_ratio: 3.0 },
                Some(other) => panic!("unknown adaptation {other}"),
            };
            let mut options = RemeshOptions {
                count,
                adaptation,
                ..Default::default()
            };
            if let Some(s) = args.get(7) {
                options.sampling = match s.as_str() {
                    "auto" => Sampling::Auto,
                    "exact" => Sampling::Exact,
                    "clustered" => Sampling::Clustered,
                    other => panic!("unknown sampling {other}"),
                };
            }
            if let Some(k) = args.get(6).filter(|k| *k != "default") {
                options.lloyd_iterations = Some(k.parse().expect("lloyd iterations"));
            }
            if let Some(k) = args.get(5).filter(|k| *k != "default") {
                options.smoothing_iterations = Some(k.parse().expect("smoothing iterations"));
            }
            let t = Instant::now();
            let r = remesh(&mesh, &options, &Control::new()).expect("remesh");
            let seconds = t.elapsed().as_secs_f64();
            if let Some(path) = args.get(4) {
                std::fs::write(path, write_ply(&r.mesh, &[])).expect("write");
            }
            let mut q = quality(&mesh, &r.mesh);
            q["input_vertices"] = mesh.num_vertices().into();
            q["seconds"] = seconds.into();
            q["topology_kept"] = r.topology_kept.into();
            q["added"] = r.added.into();
            q["repair_rounds"] = r.repair_rounds.into();
            q["removed_faces"] = r.cleaned.removed_faces.into();
            q["dropped_vertices"] = r.cleaned.dropped_vertices.into();
            q["valid"] = r.valid.into();
            q["input_topology"] = format!("{:?}", r.input_topology).into();
            q["output_topology"] = format!("{:?}", r.output_topology).into();
            q["lloyd_accepted"] = r.lloyd_accepted.into();
            q["sampling"] = if r.sampled.clustered {
                "clustered"
            } else {
                "exact"
            }
            .into();
            q["clusters"] = r.sampled.clusters.into();
            q["front_visits"] = r.sampled.front_visits.into();
            q["flips"] = r.relaxed.flips.into();
            q["moves"] = r.relaxed.moves.into();
            q["moves_rejected"] = r.relaxed.rejected.into();
            q["covering_moves"] = r.relaxed.covering_moves.into();
            q["mending_moves"] = r.relaxed.mending_moves.into();
            println!("{q}");
        }
        _ => eprintln!("usage: remesh run|dump|measure ... (see the file's docs)"),
    }
}
