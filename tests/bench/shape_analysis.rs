//! Shape analysis benchmark: Isomap of a point cloud, landmark distance
//! matrices and landmark-MDS canonical forms of icospheres.
//!
//! ```text
//! cargo bench --bench shape_analysis -- roll 10000 7 /tmp/roll.npy /tmp/roll_flat.npy  # the cloud, and its unrolled truth
//! cargo bench --bench shape_analysis -- isomap /tmp/roll.npy 10 500     # k = 10, 500 landmarks (0: all pairs)
//! cargo bench --bench shape_analysis -- matrix 7 500 heat               # 500 landmark rows, icosphere level 7
//! cargo bench --bench shape_analysis -- matrix 7 500 heat /tmp/ico7      # also writes /tmp/ico7.obj and its landmarks
//! cargo bench --bench shape_analysis -- embed 7 500 heat                # landmark-MDS canonical form, end to end
//! cargo bench --bench shape_analysis -- retrieval 10 5 1500 3000 64 32  # 11 classes × 10 poses of 1500..3000 vertices
//! ```
//!
//! `retrieval POSES LEVEL MIN MAX LANDMARKS BINS`: the generated benchmark
//! of articulated shapes (`numerics::shape::benchmark`, icosphere `LEVEL`,
//! remeshed to `MIN..MAX` vertices), every shape queried against the others
//! by descriptor distance; prints NN, first tier, second tier, DCG.
//!
//! Prints one JSON line per case; `tests/bench/compare_isomap.py` runs the
//! Isomap case beside scikit-learn's on the same file. Threads: rayon's
//! global pool (every core), as the service's solver pool would use.

use std::time::Instant;

use geodex::io::{self, ArrayData};
use geodex::numerics::mesh::shapes::icosphere;
use geodex::numerics::mesh::{HeatOptions, HeatSolver, MeshMethod, Topology};
use geodex::numerics::shape::benchmark::{
    benchmark_shape, classes, retrieval_scores, BenchmarkOptions,
};
use geodex::numerics::shape::canonical::{canonical_form, CanonicalOptions};
use geodex::numerics::shape::descriptor::{descriptor, descriptor_distance, DescriptorOptions};
use geodex::numerics::shape::isomap::{isomap, swiss_roll, IsomapOptions};
use geodex::numerics::shape::matrix::{distance_rows, landmarks, Symmetry};
use geodex::numerics::Control;
use ndarray::Array2;

fn method(name: &str) -> MeshMethod {
    match name {
        "heat" => MeshMethod::Heat,
        "exact" => MeshMethod::Exact,
        "dijkstra" => MeshMethod::Dijkstra,
        _ => MeshMethod::FastMarching,
    }
}

/// Mean relative error of distance rows on the unit icosphere against the
/// great-circle distance, over the vertices farther than 0.1 from each source
/// (the measure of `compare_potpourri3d.py`).
fn sphere_error(
    mesh: &geodex::numerics::mesh::TriMesh,
    sources: &[u32],
    rows: ndarray::ArrayView2<'_, f64>,
) -> f64 {
    let p = mesh.positions();
    let unit = |v: [f64; 3]| {
        let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        [v[0] / n, v[1] / n, v[2] / n]
    };
    let (mut sum, mut count) = (0.0, 0usize);
    for (i, &s) in sources.iter().enumerate() {
        let a = unit(p[s as usize]);
        for (v, &d) in rows.row(i).iter().enumerate() {
            let b = unit(p[v]);
            let cross = [
                a[1] * b[2] - a[2] * b[1],
                a[2] * b[0] - a[0] * b[2],
                a[0] * b[1] - a[1] * b[0],
            ];
            let sin = (cross[0] * cross[0] + cross[1] * cross[1] + cross[2] * cross[2]).sqrt();
            let exact = sin.atan2(a[0] * b[0] + a[1] * b[1] + a[2] * b[2]);
            if exact > 0.1 {
                sum += (d - exact).abs() / exact;
                count += 1;
            }
        }
    }
    sum / count.max(1) as f64
}

fn arg<T: std::str::FromStr>(args: &[String], i: usize, default: T) -> T {
    args.get(i).and_then(|s| s.parse().ok()).unwrap_or(default)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| a != "--bench")
        .collect();
    let threads = rayon::current_num_threads();
    let control = Control::new();
    match args.first().map(String::as_str) {
        Some("roll") => {
            let (p, flat) = swiss_roll(arg(&args, 1, 10_000), arg(&args, 2, 7));
            std::fs::write(&args[3], io::encode_npy(&ArrayData::F64(p.into_dyn()))?)?;
            if let Some(path) = args.get(4) {
                std::fs::write(path, io::encode_npy(&ArrayData::F64(flat.into_dyn()))?)?;
            }
        }
        Some("isomap") => {
            let bytes = std::fs::read(&args[1])?;
            let ArrayData::F64(a) = io::decode(&bytes, None, &io::Limits::default())?.array else {
                return Err("an f64 N × D array is needed".into());
            };
            let p: Array2<f64> = a.into_dimensionality()?;
            let k = arg(&args, 2, 10);
            let l: usize = arg(&args, 3, 0);
            let started = Instant::now();
            let r = isomap(
                p.view(),
                &IsomapOptions {
                    neighbours: k,
                    dimensions: 2,
                    landmarks: (l > 0).then_some(l),
                },
                &control,
            )?;
            let secs = started.elapsed().as_secs_f64();
            if let Some(out) = args.get(4) {
                std::fs::write(
                    out,
                    io::encode_npy(&ArrayData::F64(r.embedding.coords.into_dyn()))?,
                )?;
            }
            println!(
                "{{\"tool\": \"geodex\", \"case\": \"isomap\", \"points\": {}, \"k\": {k}, \"landmarks\": {l}, \
                 \"seconds\": {secs:.4}, \"residual_variance\": {:.6}, \"threads\": {threads}}}",
                p.nrows(),
                r.residual_variance
            );
        }
        Some(case @ ("matrix" | "embed")) => {
            let mesh = icosphere(arg(&args, 1, 7), 1.0);
            let count = arg(&args, 2, 500);
            let m = method(args.get(3).map_or("fast_marching", String::as_str));
            let started = Instant::now();
            let topo = Topology::new(&mesh);
            let heat = match m {
                MeshMethod::Heat => Some(HeatSolver::new(
                    &mesh,
                    &topo,
                    &HeatOptions::default(),
                    &control,
                )?),
                _ => None,
            };
            let setup = started.elapsed().as_secs_f64();
            if case == "matrix" {
                let t = Instant::now();
                let l = landmarks(&mesh, &topo, count, &control)?;
                let pick = t.elapsed().as_secs_f64();
                let t = Instant::now();
                let r = distance_rows(
                    &mesh,
                    &topo,
                    &l,
                    m,
                    heat.as_ref(),
                    Symmetry::Average,
                    &control,
                )?;
                let rows = t.elapsed().as_secs_f64();
                let total = started.elapsed().as_secs_f64();
                let error = sphere_error(&mesh, &r.sources, r.rows.view());
                println!(
                    "{{\"tool\": \"geodex\", \"case\": \"matrix\", \"vertices\": {}, \"landmarks\": {count}, \
                     \"method\": \"{m:?}\", \"setup_s\": {setup:.3}, \"landmarks_s\": {pick:.3}, \"rows_s\": {rows:.3}, \
                     \"total_s\": {total:.3}, \"asymmetry\": {:.5}, \"mean_relative_error\": {error:.6}, \"threads\": {threads}}}",
                    mesh.num_vertices(),
                    r.asymmetry
                );
                if let Some(prefix) = args.get(4) {
                    // The same mesh and landmarks for a peer (compare_distance_matrix.py).
                    let obj = std::path::PathBuf::from(format!("{prefix}.obj"));
                    std::fs::write(
                        &obj,
                        geodex::io::mesh::write::encode_by_extension(&mesh, &[], &obj)?,
                    )?;
                    let l: Vec<i64> = r.sources.iter().map(|&v| i64::from(v)).collect();
                    let l = ndarray::Array1::from(l).into_dyn();
                    std::fs::write(
                        format!("{prefix}_landmarks.npy"),
                        io::encode_npy(&ArrayData::I64(l))?,
                    )?;
                }
            } else {
                let f = canonical_form(
                    &mesh,
                    &topo,
                    &CanonicalOptions {
                        method: m,
                        landmarks: Some(count),
                        ..Default::default()
                    },
                    heat.as_ref(),
                    &control,
                )?;
                println!(
                    "{{\"tool\": \"geodex\", \"case\": \"embed\", \"vertices\": {}, \"landmarks\": {count}, \
                     \"method\": \"{m:?}\", \"total_s\": {:.3}, \"stress\": {:.5}, \"explained_variance\": {:.5}, \
                     \"threads\": {threads}}}",
                    mesh.num_vertices(),
                    started.elapsed().as_secs_f64(),
                    f.stress,
                    f.explained_variance
                );
            }
        }
        Some("retrieval") => {
            use rayon::prelude::*;
            let poses: usize = arg(&args, 1, 10);
            let bench = BenchmarkOptions {
                level: arg(&args, 2, 5),
                min_vertices: arg(&args, 3, 1500),
                max_vertices: arg(&args, 4, 3000),
                ..BenchmarkOptions::default()
            };
            let options = DescriptorOptions {
                landmarks: arg(&args, 5, 64),
                bins: arg(&args, 6, 32),
                method: MeshMethod::FastMarching,
            };
            let classes = classes();
            let jobs: Vec<(usize, usize)> = (0..classes.len())
                .flat_map(|c| (0..poses).map(move |p| (c, p)))
                .collect();
            let started = Instant::now();
            let shapes = jobs
                .par_iter()
                .map(|&(c, p)| benchmark_shape(&classes[c], c, p, &bench, &control))
                .collect::<Result<Vec<_>, _>>()?;
            let generated = started.elapsed().as_secs_f64();
            let started = Instant::now();
            let described = shapes
                .par_iter()
                .map(|m| descriptor(m, &Topology::new(m), &options, None, &control))
                .collect::<Result<Vec<_>, _>>()?;
            let describe = started.elapsed().as_secs_f64();
            let mut matrix = Vec::with_capacity(described.len());
            for a in &described {
                let row = described
                    .iter()
                    .map(|b| descriptor_distance(a, b))
                    .collect::<Result<Vec<_>, _>>()?;
                matrix.push(row);
            }
            let labels: Vec<usize> = jobs.iter().map(|j| j.0).collect();
            let s = retrieval_scores(&matrix, &labels);
            let vertices: Vec<usize> = shapes.iter().map(|m| m.num_vertices()).collect();
            println!(
                "{{\"tool\": \"geodex\", \"case\": \"retrieval\", \"classes\": {}, \"poses\": {poses}, \
                 \"min_vertices\": {}, \"max_vertices\": {}, \"landmarks\": {}, \"bins\": {}, \
                 \"nn\": {:.4}, \"first_tier\": {:.4}, \"second_tier\": {:.4}, \"dcg\": {:.4}, \
                 \"generate_seconds\": {generated:.3}, \"describe_seconds\": {describe:.3}, \"threads\": {threads}}}",
                classes.len(),
                vertices.iter().min().copied().unwrap_or(0),
                vertices.iter().max().copied().unwrap_or(0),
                options.landmarks,
                options.bins,
                s.nearest_neighbour,
                s.first_tier,
                s.second_tier,
                s.dcg
            );
        }
        _ => return Err(
            "usage: shape_analysis roll|isomap|matrix|embed|retrieval ... (see the file's docs)"
                .into(),
        ),
    }
    Ok(())
}
