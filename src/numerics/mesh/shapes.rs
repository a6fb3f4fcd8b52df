//! Analytic test surfaces: icospheres, flat triangulated squares, prisms and
//! cones, used as oracles by tests and by `geodex bench`.

use super::{norm, MeshError, TriMesh};
use std::collections::HashMap;

/// The icosphere of radius `radius` after `level` 1-to-4 subdivisions of the
/// icosahedron, midpoints projected onto the sphere: `10·4^level + 2`
/// vertices (level 5: 10,242; level 7: 163,842; level 8: 655,362).
pub fn icosphere(level: u32, radius: f64) -> TriMesh {
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let mut pos: Vec<[f64; 3]> = vec![
        [-1., t, 0.],
        [1., t, 0.],
        [-1., -t, 0.],
        [1., -t, 0.],
        [0., -1., t],
        [0., 1., t],
        [0., -1., -t],
        [0., 1., -t],
        [t, 0., -1.],
        [t, 0., 1.],
        [-t, 0., -1.],
        [-t, 0., 1.],
    ];
    let mut faces: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    let unit = |p: [f64; 3]| {
        let n = norm(p);
        [p[0] / n, p[1] / n, p[2] / n]
    };
    for p in pos.iter_mut() {
        *p = unit(*p);
    }
    for _ in 0..level {
        let mut mid: HashMap<(u32, u32), u32> = HashMap::with_capacity(faces.len() * 2);
        let mut next = Vec::with_capacity(faces.len() * 4);
        for f in &faces {
            let mut m = [0u32; 3];
            for k in 0..3 {
                let (a, b) = (f[k], f[(k + 1) % 3]);
                let key = (a.min(b), a.max(b));
                m[k] = *mid.entry(key).or_insert_with(|| {
                    let (pa, pb) = (pos[a as usize], pos[b as usize]);
                    pos.push(unit([pa[0] + pb[0], pa[1] + pb[1], pa[2] + pb[2]]));
                    (pos.len() - 1) as u32
                });
            }
            next.push([f[0], m[0], m[2]]);
            next.push([f[1], m[1], m[0]]);
            next.push([f[2], m[2], m[1]]);
            next.push([m[0], m[1], m[2]]);
        }
        faces = next;
    }
    for p in pos.iter_mut() {
        *p = [p[0] * radius, p[1] * radius, p[2] * radius];
    }
    // Indices are in range and faces non-degenerate by construction.
    TriMesh::from_parts_unchecked(pos, faces)
}

/// The square `[0, size]²` in the plane z = 0, `n × n` cells, each cut into
/// two triangles along alternating diagonals; `jitter` in `[0, 0.4)` moves
/// interior vertices pseudo-randomly by that fraction of a cell (obtuse and
/// skinny triangles).
pub fn flat_square(n: usize, size: f64, jitter: f64) -> TriMesh {
    let n = n.max(1);
    let h = size / n as f64;
    let mut pos = Vec::with_capacity((n + 1) * (n + 1));
    let mut state = 0x9e37_79b9_7f4a_7c15_u64;
    let mut rand = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    for i in 0..=n {
        for j in 0..=n {
            let interior = i > 0 && i < n && j > 0 && j < n;
            let (dx, dy) = if interior {
                (2.0 * jitter * rand(), 2.0 * jitter * rand())
            } else {
                (0.0, 0.0)
            };
            pos.push([(j as f64 + dx) * h, (i as f64 + dy) * h, 0.0]);
        }
    }
    let id = |i: usize, j: usize| (i * (n + 1) + j) as u32;
    let mut faces = Vec::with_capacity(2 * n * n);
    for i in 0..n {
        for j in 0..n {
            let (a, b, c, d) = (id(i, j), id(i, j + 1), id(i + 1, j + 1), id(i + 1, j));
            if (i + j) % 2 == 0 {
                faces.push([a, b, c]);
                faces.push([a, c, d]);
            } else {
                faces.push([a, b, d]);
                faces.push([b, c, d]);
            }
        }
    }
    TriMesh::from_parts_unchecked(pos, faces)
}

/// An open prism with `sides` sides inscribed in the cylinder of radius
/// `radius`, height `height`, `rings` layers of quads split in two: a
/// developable surface whose geodesics unroll to straight lines (perimeter
/// `2·sides·radius·sin(π/sides)`).
pub fn prism(sides: usize, rings: usize, radius: f64, height: f64) -> TriMesh {
    let sides = sides.max(3);
    let section: Vec<[f64; 2]> = (0..sides)
        .map(|s| {
            let a = std::f64::consts::TAU * s as f64 / sides as f64;
            [radius * a.cos(), radius * a.sin()]
        })
        .collect();
    tube_unchecked(&section, rings, height)
}

/// The open tube over the closed polygon `section` (in the plane z = 0,
/// at least three corners, else [`MeshError::NoFaces`]), straight along z up to `height` in `rings`
/// layers of quads split in two. Every quad is a flat rectangle whose sides
/// are a polygon edge and a vertical segment, so two tubes over polygons
/// with the same edge lengths have identical triangles: an exact isometry
/// of the meshes, however the section is bent (the test pairs of the
/// canonical forms).
pub fn tube(section: &[[f64; 2]], rings: usize, height: f64) -> Result<TriMesh, MeshError> {
    if section.len() < 3 {
        return Err(MeshError::NoFaces);
    }
    let m = tube_unchecked(section, rings, height);
    TriMesh::new(m.positions().to_vec(), m.faces().to_vec())
}

fn tube_unchecked(section: &[[f64; 2]], rings: usize, height: f64) -> TriMesh {
    let (sides, rings) = (section.len(), rings.max(1));
    let mut pos = Vec::with_capacity(sides * (rings + 1));
    for r in 0..=rings {
        let z = height * r as f64 / rings as f64;
        for p in section {
            pos.push([p[0], p[1], z]);
        }
    }
    let id = |r: usize, s: usize| (r * sides + s % sides) as u32;
    let mut faces = Vec::with_capacity(2 * sides * rings);
    for r in 0..rings {
        for s in 0..sides {
            faces.push([id(r, s), id(r, s + 1), id(r + 1, s + 1)]);
            faces.push([id(r, s), id(r + 1, s + 1), id(r + 1, s)]);
        }
    }
    TriMesh::from_parts_unchecked(pos, faces)
}

/// The torus of major radius `major` and minor radius `minor` (axis z),
/// `rings × sides` vertices, quads split in two, outward orientation: the
/// point of angles `(θ, φ)` is `((R + r cos φ) cos θ, (R + r cos φ) sin θ,
/// r sin φ)`; genus 1, Euler characteristic 0.
pub fn torus(rings: usize, sides: usize, major: f64, minor: f64) -> TriMesh {
    let (rings, sides) = (rings.max(3), sides.max(3));
    let mut pos = Vec::with_capacity(rings * sides);
    for i in 0..rings {
        let t = std::f64::consts::TAU * i as f64 / rings as f64;
        for j in 0..sides {
            let p = std::f64::consts::TAU * j as f64 / sides as f64;
            let rho = major + minor * p.cos();
            pos.push([rho * t.cos(), rho * t.sin(), minor * p.sin()]);
        }
    }
    let id = |i: usize, j: usize| ((i % rings) * sides + j % sides) as u32;
    let mut faces = Vec::with_capacity(2 * rings * sides);
    for i in 0..rings {
        for j in 0..sides {
            faces.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            faces.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    TriMesh::from_parts_unchecked(pos, faces)
}

/// Great-circle distance between two points of the sphere of radius `r`
/// centred at the origin: `r · atan2(|p × q|, p · q)`.
pub fn great_circle(p: [f64; 3], q: [f64; 3], r: f64) -> f64 {
    let c = super::cross(p, q);
    r * norm(c).atan2(super::dot(p, q))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::numerics::mesh::Topology;

    #[test]
    fn icosphere_counts_and_closedness() {
        for level in 0..4 {
            let m = icosphere(level, 1.0);
            assert_eq!(m.num_vertices(), 10 * 4usize.pow(level) + 2);
            assert_eq!(m.num_faces(), 20 * 4usize.pow(level));
            let t = Topology::new(&m);
            assert_eq!(t.boundary_edges, 0);
            assert_eq!(t.misoriented_edges, 0);
            assert_eq!(t.components, 1);
        }
    }
}
