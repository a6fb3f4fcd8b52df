//! Source initialisation shared by the surface solvers, and the vertex
//! one-ring graph.

use super::{norm, sub, MeshSolveError, SurfacePoint, TriMesh};
use crate::numerics::buckets::bucket;

/// A vertex value fixed before propagation: vertex, distance, source label.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Seed {
    /// The vertex.
    pub vertex: u32,
    /// Its initial distance.
    pub distance: f64,
    /// Index of the source it comes from.
    pub label: i32,
}

/// Validates `sources` and turns them into vertex seeds.
///
/// A vertex source gives distance 0 at the vertex; a point inside face `f`
/// gives its three vertices the straight-line distance to the point, scaled
/// by the mean weight `W` of the face's vertices (exact on a flat face for
/// `W = 1`, since the face is developable and geodesics inside it are
/// segments). When two sources seed the same vertex the smaller value wins.
pub fn seeds(
    mesh: &TriMesh,
    sources: &[SurfacePoint],
    weights: Option<&[f64]>,
) -> Result<Vec<Seed>, MeshSolveError> {
    seeds_with(mesh, sources, |face, v, p| {
        let f = mesh.faces()[face as usize];
        let w = weights.map_or(1.0, |w| f.iter().map(|&v| w[v as usize]).sum::<f64>() / 3.0);
        w * norm(sub(mesh.position(v), p))
    })
}

/// [`seeds`] under one tensor per face: a point inside face `f` gives its
/// vertices the length `sqrt(dᵀ M_f d)` of the segment `d` to the point
/// (exact, the metric being constant in the face).
pub fn tensor_seeds(
    mesh: &TriMesh,
    sources: &[SurfacePoint],
    tensors: &[[f64; 6]],
) -> Result<Vec<Seed>, MeshSolveError> {
    seeds_with(mesh, sources, |face, v, p| {
        let d = sub(mesh.position(v), p);
        super::fast_marching::tensor_form(&tensors[face as usize], d, d)
            .max(0.0)
            .sqrt()
    })
}

/// The seeds, with `length(face, vertex, point)` the distance from a face
/// source's point to one of the face's vertices.
fn seeds_with(
    mesh: &TriMesh,
    sources: &[SurfacePoint],
    length: impl Fn(u32, u32, [f64; 3]) -> f64,
) -> Result<Vec<Seed>, MeshSolveError> {
    if sources.is_empty() {
        return Err(MeshSolveError::NoSources);
    }
    let mut out: Vec<Seed> = Vec::with_capacity(sources.len() * 3);
    for (index, s) in sources.iter().enumerate() {
        s.validate(mesh)
            .map_err(|reason| MeshSolveError::InvalidSource { index, reason })?;
        let label = index as i32;
        match *s {
            SurfacePoint::Vertex(v) => out.push(Seed {
                vertex: v,
                distance: 0.0,
                label,
            }),
            SurfacePoint::Face { face, .. } => {
                let p = s.position(mesh);
                for v in mesh.faces()[face as usize] {
                    out.push(Seed {
                        vertex: v,
                        distance: length(face, v, p),
                        label,
                    });
                }
            }
        }
    }
    keep_smallest(&mut out);
    Ok(out)
}

/// Keeps the smallest value per vertex, sorted by vertex (the lower label
/// wins a tie).
pub fn keep_smallest(seeds: &mut Vec<Seed>) {
    seeds.sort_by(|a, b| {
        a.vertex
            .cmp(&b.vertex)
            .then(a.distance.total_cmp(&b.distance))
            .then(a.label.cmp(&b.label))
    });
    seeds.dedup_by_key(|s| s.vertex);
}

/// Checks a per-vertex weight `W` (length, finite, > 0).
pub fn check_weights(mesh: &TriMesh, weights: Option<&[f64]>) -> Result<(), MeshSolveError> {
    if let Some(w) = weights {
        if w.len() != mesh.num_vertices() {
            return Err(MeshSolveError::InvalidOption {
                option: "weights",
                reason: format!("{} values for {} vertices", w.len(), mesh.num_vertices()),
            });
        }
        if let Some(i) = w.iter().position(|x| !x.is_finite() || *x <= 0.0) {
            return Err(MeshSolveError::InvalidOption {
                option: "weights",
                reason: format!("weight of vertex {i} is {} (must be finite and > 0)", w[i]),
            });
        }
    }
    Ok(())
}

/// The one-ring graph in CSR form: neighbours of `v` are
/// `neighbours[offsets[v]..offsets[v + 1]]`, sorted, without duplicates.
#[derive(Debug, Clone, PartialEq)]
pub struct VertexGraph {
    /// Row offsets (`n + 1`).
    pub offsets: Vec<u32>,
    /// Neighbour lists.
    pub neighbours: Vec<u32>,
}

impl VertexGraph {
    /// Builds the graph of the mesh's edges in `O(F)`: the six directed
    /// half-pairs of every face bucketed by their first vertex (a counting
    /// sort), then each vertex's few neighbours sorted and deduplicated.
    pub fn new(mesh: &TriMesh) -> Self {
        let n = mesh.num_vertices();
        let (start, mut bucket) = bucket(
            n,
            mesh.faces().iter().flat_map(|&[a, b, c]| {
                let (ua, ub, uc) = (a as usize, b as usize, c as usize);
                [(ua, b), (ub, a), (ub, c), (uc, b), (uc, a), (ua, c)]
            }),
        );
        let mut offsets = Vec::with_capacity(n + 1);
        let mut neighbours = Vec::with_capacity(bucket.len() / 2);
        for v in 0..n {
            offsets.push(neighbours.len() as u32);
            let row = &mut bucket[start[v]..start[v + 1]];
            row.sort_unstable();
            let first = neighbours.len();
            for &u in row.iter() {
                if neighbours.len() == first || neighbours[neighbours.len() - 1] != u {
                    neighbours.push(u);
                }
            }
        }
        offsets.push(neighbours.len() as u32);
        Self {
            offsets,
            neighbours,
        }
    }

    /// Neighbours of `v`.
    #[inline]
    pub fn of(&self, v: u32) -> &[u32] {
        &self.neighbours[self.offsets[v as usize] as usize..self.offsets[v as usize + 1] as usize]
    }
}
