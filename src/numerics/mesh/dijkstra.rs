//! Dijkstra's algorithm on the edge graph: the graph baseline.
//!
//! `d(v) = min_u d(u) + ½(W_u + W_v)·|uv|` over edges. It overestimates the
//! geodesic distance by a factor that does not shrink under refinement
//! (paths are confined to edges: about 8 % on a regular triangulated plane),
//! so it is a baseline, not an approximation method.

use super::sources::{check_weights, seeds, VertexGraph};
use super::{norm, sub, MeshDistance, MeshSolveError, SurfacePoint, TriMesh};
use crate::numerics::heap::IndexedHeap;
use crate::numerics::Control;

/// Edge-graph distances from `sources`, optional per-vertex weight `W`,
/// stopping beyond `max_distance` (`+inf` and label -1 there).
pub fn dijkstra_distance(
    mesh: &TriMesh,
    sources: &[SurfacePoint],
    weights: Option<&[f64]>,
    max_distance: f64,
    control: &Control<'_>,
) -> Result<MeshDistance, MeshSolveError> {
    check_weights(mesh, weights)?;
    let graph = VertexGraph::new(mesh);
    dijkstra_on_graph(mesh, &graph, sources, weights, max_distance, control)
}

/// [`dijkstra_distance`] on the mesh's edge graph already built.
pub(crate) fn dijkstra_on_graph(
    mesh: &TriMesh,
    graph: &VertexGraph,
    sources: &[SurfacePoint],
    weights: Option<&[f64]>,
    max_distance: f64,
    control: &Control<'_>,
) -> Result<MeshDistance, MeshSolveError> {
    check_weights(mesh, weights)?;
    let n = mesh.num_vertices();
    let mut out = MeshDistance {
        distance: vec![f64::INFINITY; n],
        labels: vec![-1; n],
    };
    let mut heap = IndexedHeap::new(n);
    for s in seeds(mesh, sources, weights)? {
        out.distance[s.vertex as usize] = s.distance;
        out.labels[s.vertex as usize] = s.label;
        heap.push_or_decrease(s.vertex, s.distance);
    }
    let mut done = vec![false; n];
    let mut count = 0usize;
    while let Some((v, d)) = heap.pop() {
        if d > max_distance {
            out.distance[v as usize] = f64::INFINITY;
            out.labels[v as usize] = -1;
            break;
        }
        done[v as usize] = true;
        count += 1;
        if count.is_multiple_of(4096) {
            if control.is_cancelled() {
                return Err(MeshSolveError::Cancelled);
            }
            control.report(count as f64 / n as f64);
        }
        let pv = mesh.position(v);
        for &u in graph.of(v) {
            if done[u as usize] {
                continue;
            }
            let w = weights.map_or(1.0, |w| 0.5 * (w[u as usize] + w[v as usize]));
            let cand = d + w * norm(sub(mesh.position(u), pv));
            if cand < out.distance[u as usize] {
                out.distance[u as usize] = cand;
                out.labels[u as usize] = out.labels[v as usize];
                heap.push_or_decrease(u, cand);
            }
        }
    }
    // Whatever is left in the band lies beyond the maximum distance.
    for (v, &d) in done.iter().enumerate() {
        if !d {
            out.distance[v] = f64::INFINITY;
            out.labels[v] = -1;
        }
    }
    control.report(1.0);
    Ok(out)
}
