//! Exact distances near the sources, as seeds for the first-order solvers.
//!
//! Fast marching's error is largest next to a point source, where the
//! distance is a cone that a piecewise linear update cannot follow: the
//! first rings inherit an error that the front then carries everywhere.
//! Here every source gets the exact polyhedral distance
//! ([`super::exact`]) on a small patch around it, and the patch vertices
//! where that value is provably the distance on the whole surface are
//! handed to the march as seeds.
//!
//! **Patch.** The vertices within [`EXACT_SEED_RINGS`] edge hops of the
//! source (of its face's corners for a point inside a face) and the faces
//! all of whose corners are among them. Every face around a vertex at
//! fewer hops is in the patch, so the patch's frontier inside the surface
//! lies on the edges whose two ends are at exactly that many hops.
//!
//! **Which values are exact.** Let `r` be the smallest Euclidean distance
//! from the source point to those frontier edges (segments in space) and
//! to the vertices six hops away that have a face outside the patch (a
//! non-manifold vertex can join the patch to another fan without an edge).
//! A path that leaves the patch crosses the frontier at some point `q`, so it
//! is longer than `|p − q| ≥ r` (a geodesic is never shorter than the
//! chord). A patch vertex whose distance on the patch `d_P(v)` is below
//! `r` therefore has a shortest path that stays in the patch: `d(v) =
//! d_P(v)`. The patch's exact solve stops at `r` (its `max_distance`).
//! The bound uses no value of the solve itself, so it holds on every mesh;
//! on a strongly curved patch `r` is smaller and fewer vertices are seeded.
//!
//! **Weights.** Under a per-vertex weight `W` the patch is used only when
//! `W` is the same at all its vertices (within 1e-12, relative): the
//! weighted distance inside it is then `W d_P`, and a path leaving it
//! costs at least `W r` before it does. Elsewhere the plain seeds stand.
//!
//! With several sources each gets its own patch; a vertex seeded by two
//! keeps the smaller value (the march takes minima anyway). Fast marching
//! uses this start for a few sources only ([`exact_start_pays`]).

use std::collections::HashMap;

use super::exact::exact_distance_threads;
use super::sources::{keep_smallest, seeds, Seed};
use super::{norm, sub, MeshSolveError, SurfacePoint, Topology, TriMesh};
use crate::numerics::Control;

/// Edge hops of the patch around a source. Six rings hold about 130
/// vertices on a regular mesh: the exact solve costs tens of microseconds
/// and takes the cone's error out of the first rings (on the 41k-vertex
/// icosphere the mean error of fast marching falls from 0.59 % to 0.38 %).
pub const EXACT_SEED_RINGS: usize = 6;

/// Vertices per source from which the exact start is worth its cost.
///
/// A patch costs about 0.3 ms (the exact solve on ~250 faces and its
/// setup), what fast marching spends on several hundred vertices: on the
/// 41k-vertex icosphere, 1,000 sources took 0.33 s with exact starts. With
/// many sources every cell is small and the start would dominate, so it is
/// used for at most `1 + n / 4096` sources (one on any mesh, so that a
/// distance matrix's rows stay single solves; 11 on that icosphere).
pub const VERTICES_PER_EXACT_START: usize = 4096;

/// Whether fast marching from `sources` sources on `vertices` vertices
/// starts from exact seeds (see [`VERTICES_PER_EXACT_START`]).
pub fn exact_start_pays(sources: usize, vertices: usize) -> bool {
    sources <= 1 + vertices / VERTICES_PER_EXACT_START
}

/// Euclidean distance from `p` to the segment `ab`.
fn segment_distance(p: [f64; 3], a: [f64; 3], b: [f64; 3]) -> f64 {
    let ab = sub(b, a);
    let l2 = super::dot(ab, ab);
    let t = if l2 > 0.0 {
        (super::dot(sub(p, a), ab) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    norm(sub(
        p,
        [a[0] + t * ab[0], a[1] + t * ab[1], a[2] + t * ab[2]],
    ))
}

/// The seeds of [`seeds`] completed by the exact distances of the patch
/// vertices around each source (see the module docs), smallest value per
/// vertex. `weights` as in [`seeds`] (checked by the caller). Errors are
/// those of [`seeds`], and cancellation.
pub fn exact_seeds(
    mesh: &TriMesh,
    topo: &Topology,
    sources: &[SurfacePoint],
    weights: Option<&[f64]>,
    rings: usize,
    control: &Control<'_>,
) -> Result<Vec<Seed>, MeshSolveError> {
    let mut out = seeds(mesh, sources, weights)?;
    for (label, source) in sources.iter().enumerate() {
        if control.is_cancelled() {
            return Err(MeshSolveError::Cancelled);
        }
        let patch = patch_seeds(mesh, topo, source, label as i32, weights, rings, control)?;
        out.extend(patch);
    }
    keep_smallest(&mut out);
    Ok(out)
}

/// The exact seeds of one (validated) source.
fn patch_seeds(
    mesh: &TriMesh,
    topo: &Topology,
    source: &SurfacePoint,
    label: i32,
    weights: Option<&[f64]>,
    rings: usize,
    control: &Control<'_>,
) -> Result<Vec<Seed>, MeshSolveError> {
    // Hops from the source's vertices, breadth first.
    let start: Vec<u32> = match *source {
        SurfacePoint::Vertex(v) => vec![v],
        SurfacePoint::Face { face, .. } => mesh.faces()[face as usize].to_vec(),
    };
    let mut hops: HashMap<u32, usize> = start.iter().map(|&v| (v, 0)).collect();
    let mut order = start.clone();
    let mut layer = start;
    for h in 1..=rings {
        let mut next = Vec::new();
        for &v in &layer {
            for &f in topo.faces_of(v) {
                for w in mesh.faces()[f as usize] {
                    if let std::collections::hash_map::Entry::Vacant(e) = hops.entry(w) {
                        e.insert(h);
                        next.push(w);
                    }
                }
            }
        }
        order.extend_from_slice(&next);
        layer = next;
    }
    // Faces of the inner vertices (every corner within `rings` hops).
    let mut faces: Vec<u32> = order
        .iter()
        .filter(|v| hops[v] < rings)
        .flat_map(|&v| topo.faces_of(v).iter().copied())
        .collect();
    faces.sort_unstable();
    faces.dedup();
    if faces.is_empty() {
        return Ok(Vec::new());
    }
    // One weight over the patch, or no exact seeds.
    let w = match weights {
        None => 1.0,
        Some(w) => {
            let (lo, hi) = order.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), &v| {
                (lo.min(w[v as usize]), hi.max(w[v as usize]))
            });
            if hi - lo > 1e-12 * hi {
                return Ok(Vec::new());
            }
            hi
        }
    };
    let local: HashMap<u32, u32> = order
        .iter()
        .enumerate()
        .map(|(i, &v)| (v, i as u32))
        .collect();
    let p = source.position(mesh);
    let mut r = f64::INFINITY;
    let mut tris = Vec::with_capacity(faces.len());
    for &f in &faces {
        let c = mesh.faces()[f as usize];
        for k in 0..3 {
            let (a, b) = (c[k], c[(k + 1) % 3]);
            if hops[&a] == rings && hops[&b] == rings {
                r = r.min(segment_distance(p, mesh.position(a), mesh.position(b)));
            }
        }
        tris.push(c.map(|v| local[&v]));
    }
    // A vertex where the patch meets a face outside it without an edge (a
    // non-manifold vertex joining two fans) is a way out too. (A path out
    // through such a vertex only matters if it comes back in through
    // another one: through a frontier edge it is already longer than `r`.)
    for &x in order.iter().filter(|v| hops[v] == rings) {
        if topo
            .faces_of(x)
            .iter()
            .any(|f| faces.binary_search(f).is_err())
        {
            r = r.min(norm(sub(p, mesh.position(x))));
        }
    }
    let positions = order.iter().map(|&v| mesh.position(v)).collect();
    // A patch the container refuses (it checks scales) is left to the march.
    let Ok(patch) = TriMesh::new(positions, tris) else {
        return Ok(Vec::new());
    };
    let local_source = match *source {
        SurfacePoint::Vertex(v) => SurfacePoint::Vertex(local[&v]),
        SurfacePoint::Face { face, bary } => match faces.binary_search(&face) {
            Ok(i) => SurfacePoint::Face {
                face: i as u32,
                bary,
            },
            Err(_) => return Ok(Vec::new()),
        },
    };
    let patch_topo = Topology::new(&patch);
    let d = match exact_distance_threads(
        &patch,
        &patch_topo,
        &[local_source],
        r,
        1,
        &control.cancel_only(),
    ) {
        Ok((d, _)) => d,
        Err(MeshSolveError::Cancelled) => return Err(MeshSolveError::Cancelled),
        Err(_) => return Ok(Vec::new()),
    };
    Ok(order
        .iter()
        .zip(&d.distance)
        .filter(|(_, &dv)| dv < r)
        .map(|(&vertex, &distance)| Seed {
            vertex,
            distance: w * distance,
            label,
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::numerics::mesh::exact::exact_distance;
    use crate::numerics::mesh::shapes::icosphere;

    #[test]
    fn the_seeds_are_the_exact_distances_inside_the_bound() {
        let mesh = icosphere(4, 1.0);
        let topo = Topology::new(&mesh);
        let sources = [
            SurfacePoint::Vertex(17),
            SurfacePoint::Face {
                face: 300,
                bary: [0.2, 0.3, 0.5],
            },
        ];
        let s = exact_seeds(&mesh, &topo, &sources, None, 6, &Control::new()).unwrap();
        // Many vertices per source, each the exact distance to its source.
        assert!(s.len() > 150, "{}", s.len());
        let all = exact_distance(&mesh, &topo, &sources, f64::INFINITY, &Control::new()).unwrap();
        for seed in &s {
            let v = seed.vertex as usize;
            assert!(
                (seed.distance - all.distance[v]).abs() < 1e-12,
                "{v}: {} vs {}",
                seed.distance,
                all.distance[v]
            );
            assert_eq!(seed.label, all.labels[v]);
        }
    }

    #[test]
    fn a_thin_tube_keeps_every_seed_exact() {
        // Six rings wrap around a tube of six sides: the patch's frontier
        // is a ring across the tube, and every seed is still exact.
        let mesh = crate::numerics::mesh::shapes::torus(64, 6, 1.0, 0.05);
        let topo = Topology::new(&mesh);
        let src = [SurfacePoint::Vertex(0)];
        let s = exact_seeds(&mesh, &topo, &src, None, 6, &Control::new()).unwrap();
        let all = exact_distance(&mesh, &topo, &src, f64::INFINITY, &Control::new()).unwrap();
        assert!(s.len() > 1);
        for seed in &s {
            let v = seed.vertex as usize;
            assert!((seed.distance - all.distance[v]).abs() < 1e-12);
        }
    }

    #[test]
    fn a_constant_weight_scales_the_seeds_and_a_varying_one_keeps_the_plain_start() {
        let mesh = icosphere(3, 1.0);
        let topo = Topology::new(&mesh);
        let src = [SurfacePoint::Vertex(3)];
        let unit = exact_seeds(&mesh, &topo, &src, None, 6, &Control::new()).unwrap();
        let two = vec![2.0; mesh.num_vertices()];
        let s = exact_seeds(&mesh, &topo, &src, Some(&two), 6, &Control::new()).unwrap();
        assert_eq!(s.len(), unit.len());
        for (a, b) in s.iter().zip(&unit) {
            assert_eq!(a.vertex, b.vertex);
            assert!((a.distance - 2.0 * b.distance).abs() < 1e-12);
        }
        let mut varying = two.clone();
        varying[unit[unit.len() / 2].vertex as usize] = 3.0;
        let s = exact_seeds(&mesh, &topo, &src, Some(&varying), 6, &Control::new()).unwrap();
        assert_eq!(s, seeds(&mesh, &src, Some(&varying)).unwrap());
    }

    #[test]
    fn cancelled_before_the_patches() {
        let mesh = icosphere(2, 1.0);
        let topo = Topology::new(&mesh);
        let cancel = std::sync::atomic::AtomicBool::new(true);
        let control = Control::new().with_cancel(&cancel);
        let r = exact_seeds(&mesh, &topo, &[SurfacePoint::Vertex(0)], None, 6, &control);
        assert!(matches!(r, Err(MeshSolveError::Cancelled)));
    }
}
