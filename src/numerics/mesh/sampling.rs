//! Farthest-point sampling on a surface (Peyré & Cohen 2006) and the
//! geodesic Voronoi cells of the samples.
//!
//! Start from a vertex, then repeatedly add the vertex farthest from the
//! samples so far, until `count` samples are placed or every vertex lies
//! within `radius` of a sample. With fast marching or Dijkstra each new
//! sample costs one *local* march: the front only visits the vertices that
//! get closer to the new sample (its Voronoi cell), so sampling `k` points
//! costs about `O(n log n · log k)` on a well-spread set rather than `k`
//! full solves. With the heat method (or the exact method) each sample is a
//! full solve merged by minimum.

use super::fast_marching::{march, MarchPrep};
use super::heat::HeatSolver;
use super::solve::{mesh_distance, MeshDistanceOptions, MeshMethod};
use super::sources::{seeds, VertexGraph};
use super::{norm, sub, MeshDistance, MeshSolveError, SurfacePoint, Topology, TriMesh};
use crate::numerics::heap::IndexedHeap;
use crate::numerics::Control;

/// Options of [`farthest_point_sampling`].
#[derive(Debug, Clone, Copy)]
pub struct SamplingOptions {
    /// Stop after this many samples.
    pub count: Option<usize>,
    /// Stop once every reachable vertex is within this distance of a sample.
    pub radius: Option<f64>,
    /// First sample (default: the vertex farthest from vertex 0).
    pub first: Option<u32>,
    /// Distance method (fast marching by default).
    pub method: MeshMethod,
}

impl Default for SamplingOptions {
    fn default() -> Self {
        Self {
            count: Some(100),
            radius: None,
            first: None,
            method: MeshMethod::FastMarching,
        }
    }
}

/// Samples, their Voronoi cells and the distance to the nearest sample.
#[derive(Debug, Clone, PartialEq)]
pub struct Sampling {
    /// Sample vertices, in the order they were chosen.
    pub samples: Vec<u32>,
    /// Distance to the nearest sample; labels index `samples`.
    pub field: MeshDistance,
    /// Largest finite distance to a sample at the end (the covering radius).
    pub covering_radius: f64,
}

/// Farthest-point sampling; see the module docs.
pub fn farthest_point_sampling(
    mesh: &TriMesh,
    topo: &Topology,
    options: &SamplingOptions,
    heat: Option<&HeatSolver>,
    control: &Control<'_>,
) -> Result<Sampling, MeshSolveError> {
    let n = mesh.num_vertices();
    if options.count.is_none() && options.radius.is_none() {
        return Err(MeshSolveError::InvalidOption {
            option: "count",
            reason: "give a count, a radius or both".into(),
        });
    }
    if options.count == Some(0) {
        return Err(MeshSolveError::InvalidOption {
            option: "count",
            reason: "must be >= 1".into(),
        });
    }
    if let Some(r) = options.radius {
        if !(r.is_finite() && r > 0.0) {
            return Err(MeshSolveError::InvalidOption {
                option: "radius",
                reason: "must be finite and > 0".into(),
            });
        }
    }
    let cap = options.count.unwrap_or(n).min(n);
    let first = match options.first {
        Some(v) if (v as usize) < n => v,
        Some(v) => {
            return Err(MeshSolveError::InvalidSource {
                index: 0,
                reason: format!("vertex {v} does not exist (the mesh has {n} vertices)"),
            })
        }
        None => {
            let d = super::dijkstra::dijkstra_distance(
                mesh,
                &[SurfacePoint::Vertex(0)],
                None,
                f64::INFINITY,
                control,
            )?;
            argmax(&d.distance).map_or(0, |(v, _)| v)
        }
    };
    let mut field = MeshDistance {
        distance: vec![f64::INFINITY; n],
        labels: vec![-1; n],
    };
    let prep =
        matches!(options.method, MeshMethod::FastMarching).then(|| MarchPrep::new(mesh, topo));
    let graph = matches!(options.method, MeshMethod::Dijkstra).then(|| VertexGraph::new(mesh));
    // Each per-sample solve polls the caller's flags (deadline, client gone,
    // job cancel); progress is reported per sample below.
    let inner = control.cancel_only();
    let mut samples = Vec::new();
    let mut next = first;
    loop {
        if control.is_cancelled() {
            return Err(MeshSolveError::Cancelled);
        }
        let label = samples.len() as i32;
        samples.push(next);
        let src = [SurfacePoint::Vertex(next)];
        match (&prep, &graph) {
            (Some(prep), _) => {
                let mut s = seeds(mesh, &src, None)?;
                s[0].label = label;
                march(mesh, prep, &s, None, f64::INFINITY, &mut field, &inner)?;
            }
            (_, Some(graph)) => local_dijkstra(mesh, graph, next, label, &mut field),
            _ => {
                let d = mesh_distance(
                    mesh,
                    topo,
                    &src,
                    &MeshDistanceOptions {
                        method: options.method,
                        ..Default::default()
                    },
                    heat,
                    &inner,
                )?;
                for v in 0..n {
                    if d.distance[v] < field.distance[v] {
                        field.distance[v] = d.distance[v];
                        field.labels[v] = label;
                    }
                }
            }
        }
        control.report(samples.len() as f64 / cap as f64);
        let Some((v, d)) = argmax(&field.distance) else {
            break;
        };
        if samples.len() >= cap || options.radius.is_some_and(|r| d <= r) || d <= 0.0 {
            break;
        }
        next = v;
    }
    let covering_radius = field
        .distance
        .iter()
        .filter(|x| x.is_finite())
        .fold(0.0f64, |a, &b| a.max(b));
    Ok(Sampling {
        samples,
        field,
        covering_radius,
    })
}

/// The vertex with the largest distance (`+inf` first: unreached components
/// are sampled before anything else).
fn argmax(d: &[f64]) -> Option<(u32, f64)> {
    let mut best: Option<(u32, f64)> = None;
    for (v, &x) in d.iter().enumerate() {
        if !x.is_nan() && best.is_none_or(|b| x > b.1) {
            best = Some((v as u32, x));
        }
    }
    best
}

fn local_dijkstra(mesh: &TriMesh, graph: &VertexGraph, s: u32, label: i32, f: &mut MeshDistance) {
    let mut heap = IndexedHeap::new(mesh.num_vertices());
    f.distance[s as usize] = 0.0;
    f.labels[s as usize] = label;
    heap.push(s, 0.0);
    while let Some((v, d)) = heap.pop() {
        let pv = mesh.position(v);
        for &u in graph.of(v) {
            let c = d + norm(sub(mesh.position(u), pv));
            if c < f.distance[u as usize] {
                f.distance[u as usize] = c;
                f.labels[u as usize] = label;
                heap.push_or_decrease(u, c);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::numerics::mesh::shapes::icosphere;
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::sync::Arc;

    /// One sample (`count: 1`, first given) runs exactly one per-sample solve
    /// and then stops without polling again: the run can only end in
    /// `Cancelled` if that solve itself polled the caller's flag, raised 5 ms
    /// into it (the exact solve of a 10k-vertex sphere takes far longer). A
    /// fresh `Control::new()` there used to ignore the flag, freezing a pool
    /// thread for the whole solve.
    #[test]
    fn a_per_sample_solve_polls_the_callers_flag() {
        let mesh = icosphere(5, 1.0);
        let topo = Topology::new(&mesh);
        let flag = Arc::new(AtomicBool::new(false));
        let raise = Arc::clone(&flag);
        let raiser = std::thread::spawn(move || {
            std::thread::sleep(std::time::Duration::from_millis(5));
            raise.store(true, Ordering::Relaxed);
        });
        let options = SamplingOptions {
            count: Some(1),
            radius: None,
            first: Some(0),
            method: MeshMethod::Exact,
        };
        let control = Control::new().with_cancel(&flag);
        let r = farthest_point_sampling(&mesh, &topo, &options, None, &control);
        raiser.join().expect("raiser");
        assert!(matches!(r, Err(MeshSolveError::Cancelled)), "{r:?}");
    }
}
