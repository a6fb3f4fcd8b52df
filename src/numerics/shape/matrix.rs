//! Geodesic distance matrices on triangle meshes: `D[i, v] = d(sᵢ, v)` for
//! sources `s₀ … s_{k-1}` and every vertex `v` (landmark rows), or all pairs
//! (`k = n`).
//!
//! Every source is a single-source solve of [`crate::numerics::mesh`]; what
//! they share is built once: one topology (the caller's), the fast-marching
//! tables ([`MarchPrep`]: one-ring graph, unfolded obtuse corners), one heat
//! factorisation ([`HeatSolver`], two triangular solves per row afterwards),
//! one edge graph for Dijkstra. The rows run in parallel on the caller's
//! rayon pool (the solver pool when called from an operation), the cancel
//! flags polled by every solve and before every row; progress is the
//! fraction of rows done. Each row is the same numbers as the single-source
//! solver's (the tests compare them bit for bit), except the heat method's:
//! its rows are solved [`HEAT_BLOCK`] at a time, both sparse solves taking
//! the block's right-hand sides together (each factor read once per block:
//! the speed of dense kernels), equal to the single-source rows up to the
//! rounding of those solves (`1e-12` relative in the tests).
//!
//! **Symmetry.** Only the exact method (up to rounding) and Dijkstra on the
//! edge graph give `d(i, j) = d(j, i)`; fast marching and the heat method
//! solve from `i` and from `j` with different discretisation errors (first
//! order in the edge length, of either sign). [`symmetrize`] replaces both
//! by their **average** by default: the closest symmetric matrix in the
//! Frobenius norm (what MDS and SMACOF assume), and, the two errors being of
//! either sign, no worse than the worse of the two. [`Symmetry::Min`] takes
//! the smaller instead, the right choice for methods that only overestimate
//! (Dijkstra on a coarse graph, or distances bounded by `max_distance`).

use std::sync::atomic::{AtomicUsize, Ordering};

use ndarray::Array2;
use rayon::prelude::*;

use super::graph::{par_rows, Graph};
use super::ShapeError;
use crate::numerics::mesh::exact::exact_distance_threads;
use crate::numerics::mesh::exact_seeds::{exact_seeds, EXACT_SEED_RINGS};
use crate::numerics::mesh::fast_marching::{
    check_tensors, march, march_metric, MarchPrep, MarchWork, Metric,
};
use crate::numerics::mesh::sampling::{farthest_point_sampling, SamplingOptions};
use crate::numerics::mesh::sources::{check_weights, tensor_seeds, VertexGraph};
use crate::numerics::mesh::{
    norm, sub, HeatOptions, HeatSolver, MeshDistance, MeshMethod, SurfacePoint, Topology, TriMesh,
};
use crate::numerics::Control;

/// How a matrix that should be symmetric is made so.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum Symmetry {
    /// `(D[i, j] + D[j, i]) / 2` (default).
    #[default]
    Average,
    /// `min(D[i, j], D[j, i])`.
    Min,
    /// Leave the matrix as solved.
    None,
}

/// Landmark rows: the sources and their `k × n` distances.
#[derive(Debug, Clone, PartialEq)]
pub struct DistanceRows {
    /// The source vertices, in row order.
    pub sources: Vec<u32>,
    /// `rows[[i, v]] = d(sources[i], v)`; `+inf` in other components.
    pub rows: Array2<f64>,
    /// Largest `|D[i, sⱼ] − D[j, sᵢ]|` over the source block before
    /// symmetrisation (0 for the exact method up to rounding).
    pub asymmetry: f64,
}

/// The distance rows from `sources` with `method`, sharing one setup (see
/// the module docs). `heat` may hand in the mesh's prefactored solver (it is
/// built once otherwise, with default options). The source block
/// `D[i, sⱼ]` is symmetrised by `symmetry`.
pub fn distance_rows(
    mesh: &TriMesh,
    topo: &Topology,
    sources: &[u32],
    method: MeshMethod,
    heat: Option<&HeatSolver>,
    symmetry: Symmetry,
    control: &Control<'_>,
) -> Result<DistanceRows, ShapeError> {
    distance_rows_in(
        mesh,
        topo,
        sources,
        method,
        Metric::Weights(None),
        heat,
        symmetry,
        control,
    )
}

/// [`distance_rows`] under a metric on the surface: per-vertex weights `W`
/// (fast marching, whose rows are the solves of
/// [`crate::numerics::mesh::mesh_distance`] with those weights, and
/// Dijkstra, with the edge length `½(W_u + W_v)|uv|`) or one tensor per
/// face (fast marching only, as
/// [`crate::numerics::mesh::fast_marching::fast_marching_distance`]). The
/// setup (the march's corner data, unfolded in the metric for tensors) is
/// shared by every row. Any metric but `W = 1` with the heat or exact
/// method is refused, naming `metric`. Under a tensor metric the distance
/// need not be symmetric: `asymmetry` says by how much the source block
/// was not.
#[allow(clippy::too_many_arguments)]
pub fn distance_rows_in(
    mesh: &TriMesh,
    topo: &Topology,
    sources: &[u32],
    method: MeshMethod,
    metric: Metric<'_>,
    heat: Option<&HeatSolver>,
    symmetry: Symmetry,
    control: &Control<'_>,
) -> Result<DistanceRows, ShapeError> {
    let n = mesh.num_vertices();
    let solve = ShapeError::from_solve;
    let plain = matches!(metric, Metric::Weights(None));
    let supported = match metric {
        Metric::Weights(_) => matches!(method, MeshMethod::FastMarching | MeshMethod::Dijkstra),
        Metric::Faces(_) => method == MeshMethod::FastMarching,
    };
    if !plain && !supported {
        return Err(ShapeError::InvalidOption {
            option: "metric",
            reason: format!(
                "the method {method:?} runs with W = 1 only; weights run with fast marching or \
                 Dijkstra, face tensors with fast marching"
            ),
        });
    }
    match metric {
        Metric::Weights(w) => check_weights(mesh, w).map_err(solve)?,
        Metric::Faces(t) => check_tensors(mesh, t).map_err(solve)?,
    }
    if sources.is_empty() {
        return Err(ShapeError::InvalidOption {
            option: "sources",
            reason: "at least one source is needed".into(),
        });
    }
    if let Some(&s) = sources.iter().find(|&&s| s as usize >= n) {
        return Err(ShapeError::InvalidOption {
            option: "sources",
            reason: format!("vertex {s} does not exist (the mesh has {n} vertices)"),
        });
    }
    let inner = control.cancel_only();
    let copy = |d: MeshDistance, row: &mut [f64]| row.copy_from_slice(&d.distance);
    let mut rows = match method {
        MeshMethod::FastMarching => {
            let prep = match metric {
                Metric::Faces(t) => MarchPrep::with_tensors(mesh, topo, t),
                Metric::Weights(_) => MarchPrep::new(mesh, topo),
            };
            par_rows(sources, n, control, |s, row| {
                let source = [SurfacePoint::Vertex(s)];
                let mut out = MeshDistance {
                    distance: vec![f64::INFINITY; n],
                    labels: vec![-1; n],
                };
                match metric {
                    Metric::Weights(w) => {
                        let seeds = exact_seeds(mesh, topo, &source, w, EXACT_SEED_RINGS, &inner)
                            .map_err(solve)?;
                        march(mesh, &prep, &seeds, w, f64::INFINITY, &mut out, &inner)
                    }
                    Metric::Faces(t) => {
                        let seeds = tensor_seeds(mesh, &source, t).map_err(solve)?;
                        march_metric(
                            &mut MarchWork::new(n),
                            mesh,
                            &prep,
                            &seeds,
                            metric,
                            f64::INFINITY,
                            &mut out,
                            &inner,
                        )
                    }
                }
                .map_err(solve)?;
                copy(out, row);
                Ok(())
            })?
        }
        MeshMethod::Heat => {
            let built;
            let solver = match heat {
                Some(h) => h,
                None => {
                    built = HeatSolver::new(mesh, topo, &HeatOptions::default(), &inner)
                        .map_err(solve)?;
                    &built
                }
            };
            heat_rows(solver, sources, n, control)?
        }
        // One worker per row: the rows already keep the pool busy.
        MeshMethod::Exact => par_rows(sources, n, control, |s, row| {
            let (d, _) = exact_distance_threads(
                mesh,
                topo,
                &[SurfacePoint::Vertex(s)],
                f64::INFINITY,
                1,
                &inner,
            )
            .map_err(solve)?;
            copy(d, row);
            Ok(())
        })?,
        MeshMethod::Dijkstra => {
            let graph = match metric {
                Metric::Weights(w) => weighted_edge_graph(mesh, w),
                Metric::Faces(_) => edge_graph(mesh),
            };
            par_rows(sources, n, control, |s, row| {
                graph.dijkstra_into(s, row, &inner)
            })?
        }
    };
    let asymmetry = symmetrize_block(&mut rows, sources, symmetry);
    Ok(DistanceRows {
        sources: sources.to_vec(),
        rows,
        asymmetry,
    })
}

/// Sources per block solve of the heat method ([`HeatSolver::vertex_rows`]):
/// enough right-hand sides for the sparse solves to run at the speed of
/// dense blocks, few enough that a block's two `n × HEAT_BLOCK` matrices
/// stay small (42 MB at 164k vertices) and the blocks spread over the pool.
const HEAT_BLOCK: usize = 16;

/// Heat-method rows, [`HEAT_BLOCK`] sources per block solve, the blocks in
/// parallel on the caller's pool.
fn heat_rows(
    solver: &HeatSolver,
    sources: &[u32],
    n: usize,
    control: &Control<'_>,
) -> Result<Array2<f64>, ShapeError> {
    let mut rows = Array2::<f64>::from_elem((sources.len(), n), f64::INFINITY);
    let inner = control.cancel_only();
    let done = AtomicUsize::new(0);
    let k = sources.len().max(1) as f64;
    let Some(flat) = rows.as_slice_mut() else {
        return Err(ShapeError::Numerical("rows not in standard layout".into()));
    };
    flat.par_chunks_mut(HEAT_BLOCK * n.max(1))
        .zip(sources.par_chunks(HEAT_BLOCK))
        .try_for_each(|(block, src)| {
            if control.is_cancelled() {
                return Err(ShapeError::Cancelled);
            }
            solver
                .vertex_rows(src, block, &inner)
                .map_err(ShapeError::from_solve)?;
            let d = done.fetch_add(src.len(), Ordering::Relaxed) + src.len();
            control.report(d as f64 / k);
            Ok(())
        })?;
    Ok(rows)
}

/// The edge graph of a mesh with Euclidean edge lengths.
pub fn edge_graph(mesh: &TriMesh) -> Graph {
    weighted_edge_graph(mesh, None)
}

/// The edge graph of a mesh under per-vertex weights (`None`: 1): edge
/// `uv` has the length `½(W_u + W_v)|uv|`, as
/// [`crate::numerics::mesh::dijkstra`] reads it.
fn weighted_edge_graph(mesh: &TriMesh, w: Option<&[f64]>) -> Graph {
    let vg = VertexGraph::new(mesh);
    let n = mesh.num_vertices();
    let weight = |v: u32| w.map_or(1.0, |w| w[v as usize]);
    let mut edges = Vec::with_capacity(vg.neighbours.len() / 2);
    for v in 0..n as u32 {
        for &u in vg.of(v) {
            if u > v {
                let length = norm(sub(mesh.position(u), mesh.position(v)));
                let length = match w {
                    Some(_) => 0.5 * (weight(v) + weight(u)) * length,
                    None => length,
                };
                edges.push((v, u, length));
            }
        }
    }
    Graph::from_edges(n, &edges)
}

/// All pairs: `n × n`, symmetrised by `symmetry`.
pub fn all_pairs(
    mesh: &TriMesh,
    topo: &Topology,
    method: MeshMethod,
    heat: Option<&HeatSolver>,
    symmetry: Symmetry,
    control: &Control<'_>,
) -> Result<DistanceRows, ShapeError> {
    let sources: Vec<u32> = (0..mesh.num_vertices() as u32).collect();
    distance_rows(mesh, topo, &sources, method, heat, symmetry, control)
}

/// `count` farthest-point landmarks (fast-marching farthest-point sampling
/// from the vertex farthest from vertex 0, [`farthest_point_sampling`]);
/// fewer when the mesh has fewer vertices.
pub fn landmarks(
    mesh: &TriMesh,
    topo: &Topology,
    count: usize,
    control: &Control<'_>,
) -> Result<Vec<u32>, ShapeError> {
    if count == 0 {
        return Err(ShapeError::InvalidOption {
            option: "landmarks",
            reason: "must be >= 1".into(),
        });
    }
    let s = farthest_point_sampling(
        mesh,
        topo,
        &SamplingOptions {
            count: Some(count),
            radius: None,
            first: None,
            method: MeshMethod::FastMarching,
        },
        None,
        control,
    )
    .map_err(ShapeError::from_solve)?;
    Ok(s.samples)
}

/// Symmetrises the block `rows[[i, sources[j]]]` in place and returns the
/// largest finite asymmetry found. A source listed twice keeps its rows.
pub fn symmetrize_block(rows: &mut Array2<f64>, sources: &[u32], symmetry: Symmetry) -> f64 {
    let mut worst = 0.0f64;
    for i in 0..sources.len() {
        for j in i + 1..sources.len() {
            let (a, b) = (
                rows[[i, sources[j] as usize]],
                rows[[j, sources[i] as usize]],
            );
            if a.is_finite() && b.is_finite() {
                worst = worst.max((a - b).abs());
            }
            let v = match symmetry {
                Symmetry::Average if a.is_finite() && b.is_finite() => 0.5 * (a + b),
                Symmetry::Average | Symmetry::Min => a.min(b),
                Symmetry::None => continue,
            };
            rows[[i, sources[j] as usize]] = v;
            rows[[j, sources[i] as usize]] = v;
        }
    }
    worst
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::numerics::mesh::shapes::{flat_square, icosphere};
    use crate::numerics::mesh::{mesh_distance, MeshDistanceOptions};

    const METHODS: [MeshMethod; 4] = [
        MeshMethod::FastMarching,
        MeshMethod::Heat,
        MeshMethod::Exact,
        MeshMethod::Dijkstra,
    ];

    /// Under weights (fast marching, Dijkstra) and face tensors (fast
    /// marching), each row is the single-source solve under the same metric,
    /// to the bit; the heat and exact methods refuse a metric by name.
    #[test]
    fn rows_under_a_metric_are_the_single_source_solves_under_it() {
        let mesh = icosphere(2, 1.0);
        let topo = Topology::new(&mesh);
        let n = mesh.num_vertices();
        let w: Vec<f64> = (0..n)
            .map(|v| 1.0 + 0.8 * (mesh.position(v as u32)[2] * 3.0).sin().abs())
            .collect();
        // A tensor per face: lengths along z twice those across (on each
        // face's plane, where it is positive definite).
        let t: Vec<[f64; 6]> = vec![[1.0, 0.0, 0.0, 1.0, 0.0, 4.0]; mesh.num_faces()];
        let sources = [0u32, 17, 101];
        let cases = [
            (MeshMethod::FastMarching, Metric::Weights(Some(&w))),
            (MeshMethod::Dijkstra, Metric::Weights(Some(&w))),
            (MeshMethod::FastMarching, Metric::Faces(&t)),
        ];
        for (method, metric) in cases {
            let (weights, tensors) = match metric {
                Metric::Weights(w) => (w, None),
                Metric::Faces(t) => (None, Some(t)),
            };
            let r = distance_rows_in(
                &mesh,
                &topo,
                &sources,
                method,
                metric,
                None,
                Symmetry::None,
                &Control::new(),
            )
            .unwrap();
            let plain = distance_rows(
                &mesh,
                &topo,
                &sources,
                method,
                None,
                Symmetry::None,
                &Control::new(),
            )
            .unwrap();
            assert_ne!(r.rows, plain.rows, "{method:?}: the metric changed nothing");
            for (i, &s) in sources.iter().enumerate() {
                let one = mesh_distance(
                    &mesh,
                    &topo,
                    &[SurfacePoint::Vertex(s)],
                    &MeshDistanceOptions {
                        method,
                        weights,
                        tensors,
                        ..Default::default()
                    },
                    None,
                    &Control::new(),
                )
                .unwrap();
                assert_eq!(
                    r.rows.row(i).to_vec(),
                    one.distance,
                    "{method:?} source {s}"
                );
            }
        }
        for method in [MeshMethod::Heat, MeshMethod::Exact] {
            let e = distance_rows_in(
                &mesh,
                &topo,
                &sources,
                method,
                Metric::Weights(Some(&w)),
                None,
                Symmetry::None,
                &Control::new(),
            )
            .unwrap_err();
            assert!(
                matches!(
                    e,
                    ShapeError::InvalidOption {
                        option: "metric",
                        ..
                    }
                ),
                "{method:?}: {e}"
            );
        }
    }

    #[test]
    fn rows_are_the_single_source_solvers_rows() {
        let mesh = icosphere(2, 1.0);
        let topo = Topology::new(&mesh);
        let heat = HeatSolver::new(&mesh, &topo, &HeatOptions::default(), &Control::new()).unwrap();
        let sources = [0u32, 17, 101, 161];
        for method in METHODS {
            let r = distance_rows(
                &mesh,
                &topo,
                &sources,
                method,
                Some(&heat),
                Symmetry::None,
                &Control::new(),
            )
            .unwrap();
            assert_eq!(r.rows.dim(), (4, 162));
            for (i, &s) in sources.iter().enumerate() {
                let one = mesh_distance(
                    &mesh,
                    &topo,
                    &[SurfacePoint::Vertex(s)],
                    &MeshDistanceOptions {
                        method,
                        ..Default::default()
                    },
                    Some(&heat),
                    &Control::new(),
                )
                .unwrap();
                if matches!(method, MeshMethod::Heat | MeshMethod::Exact) {
                    // Heat: block solves, the same numbers up to the
                    // rounding of the multi-column triangular solves.
                    // Exact: the rows run on one worker each, a single
                    // solve may split its propagation in two halves (the
                    // same distances to rounding).
                    for (a, b) in r.rows.row(i).iter().zip(&one.distance) {
                        assert!(
                            (a - b).abs() <= 1e-12 * (1.0 + b.abs()),
                            "source {s}: {a} {b}"
                        );
                    }
                } else {
                    assert_eq!(
                        r.rows.row(i).to_vec(),
                        one.distance,
                        "{method:?}, source {s}"
                    );
                }
            }
        }
    }

    #[test]
    fn heat_rows_in_several_blocks_are_the_single_source_rows() {
        let mesh = icosphere(2, 1.0);
        let topo = Topology::new(&mesh);
        let heat = HeatSolver::new(&mesh, &topo, &HeatOptions::default(), &Control::new()).unwrap();
        // 40 sources: blocks of 16, 16 and 8.
        let sources: Vec<u32> = (0..40).map(|i| (i * 4) as u32).collect();
        let r = heat_rows(&heat, &sources, 162, &Control::new()).unwrap();
        for (i, &s) in sources.iter().enumerate() {
            let one = heat
                .distance(
                    &mesh,
                    &[SurfacePoint::Vertex(s)],
                    f64::INFINITY,
                    &Control::new(),
                )
                .unwrap();
            for (a, b) in r.row(i).iter().zip(&one.distance) {
                assert!(
                    (a - b).abs() <= 1e-12 * (1.0 + b.abs()),
                    "source {s}: {a} {b}"
                );
            }
        }
        let flag = std::sync::atomic::AtomicBool::new(true);
        let stopped = heat_rows(&heat, &sources, 162, &Control::new().with_cancel(&flag));
        assert_eq!(stopped, Err(ShapeError::Cancelled));
    }

    #[test]
    fn symmetry_within_the_methods_tolerance() {
        // Asymmetry before symmetrisation, relative to the diameter (π):
        // rounding for exact and Dijkstra, the discretisation error otherwise.
        let mesh = icosphere(2, 1.0);
        let topo = Topology::new(&mesh);
        for (method, tol) in [
            (MeshMethod::Exact, 1e-12),
            (MeshMethod::Dijkstra, 1e-12),
            (MeshMethod::FastMarching, 0.03),
            (MeshMethod::Heat, 0.05),
        ] {
            let r = all_pairs(
                &mesh,
                &topo,
                method,
                None,
                Symmetry::Average,
                &Control::new(),
            )
            .unwrap();
            let rel = r.asymmetry / std::f64::consts::PI;
            assert!(rel <= tol, "{method:?}: asymmetry {rel}");
            let d = &r.rows;
            for i in 0..162 {
                assert_eq!(d[[i, i]], 0.0);
                for j in 0..162 {
                    assert_eq!(d[[i, j]], d[[j, i]]);
                }
            }
        }
        // The average is symmetric and Min never exceeds it.
        let mut a = Array2::from_shape_vec((2, 2), vec![0.0, 1.0, 3.0, 0.0]).unwrap();
        let mut b = a.clone();
        assert_eq!(symmetrize_block(&mut a, &[0, 1], Symmetry::Average), 2.0);
        symmetrize_block(&mut b, &[0, 1], Symmetry::Min);
        assert_eq!(
            (a[[0, 1]], a[[1, 0]], b[[0, 1]], b[[1, 0]]),
            (2.0, 2.0, 1.0, 1.0)
        );
    }

    #[test]
    fn exact_on_a_flat_square() {
        let mesh = flat_square(6, 1.0, 0.3);
        let topo = Topology::new(&mesh);
        let r = all_pairs(
            &mesh,
            &topo,
            MeshMethod::Exact,
            None,
            Symmetry::Average,
            &Control::new(),
        )
        .unwrap();
        let p = mesh.positions();
        let mut worst = 0.0f64;
        for i in 0..p.len() {
            for j in 0..p.len() {
                worst = worst.max((r.rows[[i, j]] - norm(sub(p[i], p[j]))).abs());
            }
        }
        assert!(worst < 1e-12, "max error {worst}");
    }

    #[test]
    fn landmarks_are_spread_and_rows_cancel() {
        let mesh = icosphere(3, 1.0);
        let topo = Topology::new(&mesh);
        let l = landmarks(&mesh, &topo, 12, &Control::new()).unwrap();
        assert_eq!(l.len(), 12);
        let r = distance_rows(
            &mesh,
            &topo,
            &l,
            MeshMethod::FastMarching,
            None,
            Symmetry::Average,
            &Control::new(),
        )
        .unwrap();
        // Twelve well-spread points on the unit sphere: every pair at least
        // ~0.9 apart (the icosahedron's 1.107, minus the greedy's slack).
        for i in 0..12 {
            for (j, &lj) in l.iter().enumerate().take(12) {
                if i != j {
                    assert!(r.rows[[i, lj as usize]] > 0.8, "{i} {j}");
                }
            }
        }
        let flag = std::sync::atomic::AtomicBool::new(true);
        let c = Control::new().with_cancel(&flag);
        for method in METHODS {
            let e = distance_rows(&mesh, &topo, &l, method, None, Symmetry::None, &c);
            assert_eq!(e, Err(ShapeError::Cancelled), "{method:?}");
        }
        assert!(distance_rows(
            &mesh,
            &topo,
            &[9999],
            MeshMethod::Heat,
            None,
            Symmetry::None,
            &Control::new()
        )
        .is_err());
    }
}
