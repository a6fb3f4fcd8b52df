//! Triangle meshes: the [`TriMesh`] container and its [`Topology`]
//! (edge adjacency, vertex rings, boundaries, connected components), the
//! common ground of every surface solver.
//!
//! Half-edge convention: edge `k` of face `f` goes from `faces[f][k]` to
//! `faces[f][(k + 1) % 3]` and has the id `3 f + k`.

pub mod curvature;
pub mod design;
pub mod dijkstra;
pub mod exact_seeds;
pub mod fast_marching;
pub mod heat;
pub mod intrinsic;
pub mod paths;
pub mod sampling;
pub mod shapes;
pub mod solve;
pub mod sources;

pub use fast_marching::{fast_marching_distance, FastMarchingOptions};
pub use heat::{HeatOptions, HeatSolver, Laplacian, SetupPhases};
pub use solve::{mesh_distance, MeshDistanceOptions, MeshMethod};
pub mod exact;

/// Sentinel for "no such half-edge / face".
pub const NONE: u32 = u32::MAX;

/// Why a mesh was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MeshError {
    /// The mesh has no faces.
    #[error("the mesh has no faces")]
    NoFaces,
    /// A vertex coordinate is NaN or infinite.
    #[error("vertex {vertex} has a non-finite coordinate")]
    NonFinite {
        /// The vertex.
        vertex: usize,
    },
    /// A face names a vertex that does not exist.
    #[error("face {face} refers to vertex {index} but the mesh has {vertices} vertices")]
    IndexOutOfRange {
        /// The face.
        face: usize,
        /// The index it holds.
        index: u64,
        /// Number of vertices.
        vertices: usize,
    },
    /// A face repeats a vertex.
    #[error("face {face} repeats a vertex")]
    RepeatedVertex {
        /// The face.
        face: usize,
    },
    /// More vertices or faces than 32-bit indices allow.
    #[error("the mesh is too large ({0} elements)")]
    TooLarge(usize),
    /// The coordinates span more orders of magnitude than `f64` lengths
    /// can represent (see [`TriMesh::check_representable`]).
    #[error("the mesh's coordinates cannot be represented meaningfully: {0}")]
    Unrepresentable(String),
}

/// Largest coordinate magnitude and extent: squared lengths stay below
/// `4·10^300`, well inside `f64` (overflow at `1.8·10^308`).
pub const MAX_COORDINATE: f64 = 1e150;
/// Smallest extent: squared lengths stay above `10^-300` (normal numbers).
pub const MIN_EXTENT: f64 = 1e-150;
/// The first half of [`TriMesh::check_representable`], for raw parts
/// before degenerate faces are dropped: every coordinate of a vertex in
/// `faces` within ±[`MAX_COORDINATE`], and their extent at least
/// [`MIN_EXTENT`]. Returns the extent. Indices must be in range.
pub fn check_scale(positions: &[[f64; 3]], faces: &[[u32; 3]]) -> Result<f64, MeshError> {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for f in faces {
        for &v in f {
            let Some(p) = positions.get(v as usize) else {
                continue;
            };
            for a in 0..3 {
                if p[a].abs() > MAX_COORDINATE {
                    return Err(MeshError::Unrepresentable(format!(
                        "vertex {v} has coordinate {:e}, beyond ±{MAX_COORDINATE:e} (squared \
                         lengths would overflow); rescale the mesh",
                        p[a]
                    )));
                }
                lo[a] = lo[a].min(p[a]);
                hi[a] = hi[a].max(p[a]);
            }
        }
    }
    if faces.is_empty() {
        return Ok(0.0);
    }
    let extent = (0..3).map(|a| (hi[a] - lo[a]).powi(2)).sum::<f64>().sqrt();
    if extent < MIN_EXTENT {
        return Err(MeshError::Unrepresentable(format!(
            "the mesh spans {extent:e}, below {MIN_EXTENT:e} (squared lengths would \
             underflow); rescale the mesh"
        )));
    }
    Ok(extent)
}

/// Smallest face (its longest edge) relative to the mesh's extent: about
/// `10^4` units in the last place of the coordinates, below which a face's
/// shape is round-off.
pub const MIN_FACE_RELATIVE: f64 = 1e-12;

/// A triangle mesh: vertex positions and faces (three vertex indices each).
///
/// # Examples
/// ```
/// use geodex::numerics::mesh::TriMesh;
/// let m = TriMesh::new(
///     vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
///     vec![[0, 1, 2]],
/// )?;
/// assert_eq!(m.face_area(0), 0.5);
/// # Ok::<(), geodex::numerics::mesh::MeshError>(())
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct TriMesh {
    positions: Vec<[f64; 3]>,
    faces: Vec<[u32; 3]>,
}

impl TriMesh {
    /// A mesh with these vertices and faces: coordinates finite, indices in
    /// range, no face repeating a vertex, at least one face. Zero-area faces
    /// with three distinct vertices are accepted (readers drop them first).
    pub fn new(positions: Vec<[f64; 3]>, faces: Vec<[u32; 3]>) -> Result<Self, MeshError> {
        if positions.len() >= NONE as usize || 3 * faces.len() >= NONE as usize {
            return Err(MeshError::TooLarge(positions.len().max(faces.len())));
        }
        if faces.is_empty() {
            return Err(MeshError::NoFaces);
        }
        if let Some(vertex) = positions
            .iter()
            .position(|p| p.iter().any(|c| !c.is_finite()))
        {
            return Err(MeshError::NonFinite { vertex });
        }
        for (face, f) in faces.iter().enumerate() {
            if let Some(&index) = f.iter().find(|&&i| i as usize >= positions.len()) {
                return Err(MeshError::IndexOutOfRange {
                    face,
                    index: index.into(),
                    vertices: positions.len(),
                });
            }
            if f[0] == f[1] || f[1] == f[2] || f[0] == f[2] {
                return Err(MeshError::RepeatedVertex { face });
            }
        }
        Ok(Self { positions, faces })
    }

    /// Checks that lengths on this mesh can be computed in `f64`: every
    /// coordinate at most [`MAX_COORDINATE`] in magnitude, the extent (the
    /// diagonal of the bounding box of the vertices in faces) at least
    /// [`MIN_EXTENT`], and the longest edge of every face at least
    /// [`MIN_FACE_RELATIVE`] times the extent. A mesh that fails has
    /// squared lengths that overflow or underflow, or faces whose shape is
    /// lost in round-off: the solvers' results on it would be meaningless
    /// (and the exact method's window propagation may not settle).
    ///
    /// # Examples
    /// ```
    /// use geodex::numerics::mesh::TriMesh;
    /// let tiny = TriMesh::new(
    ///     vec![[0., 0., 0.], [1e130, 0., 0.], [0., 1e130, 0.], [1e-159, 0., 0.], [0., 1e-159, 0.]],
    ///     vec![[0, 1, 2], [0, 3, 4]],
    /// )?;
    /// assert!(tiny.check_representable().is_err());
    /// # Ok::<(), geodex::numerics::mesh::MeshError>(())
    /// ```
    pub fn check_representable(&self) -> Result<(), MeshError> {
        let extent = check_scale(&self.positions, &self.faces)?;
        let dist = |a: [f64; 3], b: [f64; 3]| norm(sub(a, b));
        for (face, f) in self.faces.iter().enumerate() {
            let p = f.map(|v| self.positions[v as usize]);
            let longest = dist(p[0], p[1]).max(dist(p[1], p[2])).max(dist(p[2], p[0]));
            if longest < MIN_FACE_RELATIVE * extent {
                return Err(MeshError::Unrepresentable(format!(
                    "face {face} is {longest:e} across in a mesh {extent:e} across (below \
                     {MIN_FACE_RELATIVE:e} of it, its shape is round-off); weld its vertices \
                     or remove it"
                )));
            }
        }
        Ok(())
    }

    /// A mesh from parts the caller guarantees valid (generators in
    /// [`shapes`]): no check is made.
    pub(crate) fn from_parts_unchecked(positions: Vec<[f64; 3]>, faces: Vec<[u32; 3]>) -> Self {
        Self { positions, faces }
    }

    /// Vertex positions.
    pub fn positions(&self) -> &[[f64; 3]] {
        &self.positions
    }

    /// Faces as vertex index triples.
    pub fn faces(&self) -> &[[u32; 3]] {
        &self.faces
    }

    /// Number of vertices.
    pub fn num_vertices(&self) -> usize {
        self.positions.len()
    }

    /// Number of faces.
    pub fn num_faces(&self) -> usize {
        self.faces.len()
    }

    /// Position of vertex `v`.
    #[inline]
    pub fn position(&self, v: u32) -> [f64; 3] {
        self.positions[v as usize]
    }

    /// Area of face `f` (half the norm of the cross product of two edges).
    pub fn face_area(&self, f: usize) -> f64 {
        let [a, b, c] = self.faces[f].map(|v| self.position(v));
        0.5 * norm(cross(sub(b, a), sub(c, a)))
    }

    /// Mean edge length over all faces' edges (shared edges counted twice).
    pub fn mean_edge_length(&self) -> f64 {
        let total: f64 = self
            .faces
            .iter()
            .map(|f| {
                (0..3)
                    .map(|k| norm(sub(self.position(f[(k + 1) % 3]), self.position(f[k]))))
                    .sum::<f64>()
            })
            .sum();
        total / (3 * self.faces.len()) as f64
    }
}

/// Edge adjacency of a [`TriMesh`].
#[derive(Debug, Clone, PartialEq)]
pub struct Topology {
    /// `opposite[3 f + k]`: the half-edge glued to edge `k` of face `f`, or
    /// [`NONE`] on a boundary or on a non-manifold edge (more than two faces).
    pub opposite: Vec<u32>,
    /// Faces around each vertex in CSR form: the faces of `v` are
    /// `vertex_faces[vertex_face_offsets[v]..vertex_face_offsets[v + 1]]`.
    pub vertex_face_offsets: Vec<u32>,
    /// See `vertex_face_offsets`.
    pub vertex_faces: Vec<u32>,
    /// Connected component of each vertex (through faces), `0..components`.
    /// A vertex in no face is a component of its own.
    pub component: Vec<u32>,
    /// Number of connected components.
    pub components: usize,
    /// Edges with exactly one face.
    pub boundary_edges: usize,
    /// Edges with more than two faces (their faces are not glued to each other).
    pub non_manifold_edges: usize,
    /// Edges whose two faces traverse them in the same direction (inconsistent orientation).
    pub misoriented_edges: usize,
}

impl Topology {
    /// Builds the adjacency in `O(V + F)` (a counting sort of the half-edges
    /// by their smaller end, then a sort of each vertex's few edges).
    pub fn new(mesh: &TriMesh) -> Self {
        let nf = mesh.num_faces();
        let nv = mesh.num_vertices();
        // Half-edges grouped by their undirected edge: bucketed by the
        // smaller end (a counting sort), then sorted by the larger end
        // within each bucket (a vertex's few edges).
        let faces = mesh.faces();
        let ends = |h: usize| {
            let face = faces[h / 3];
            let (a, b) = (face[h % 3], face[(h + 1) % 3]);
            (a.min(b), a.max(b))
        };
        // Each half-edge carries its larger end, so that sorting a bucket
        // reads no face.
        let (start, mut halves) = crate::numerics::buckets::bucket(
            nv,
            (0..3 * nf).map(|h| {
                let (near, far) = ends(h);
                (near as usize, (far, h as u32))
            }),
        );
        let mut opposite = vec![NONE; 3 * nf];
        let (mut boundary_edges, mut non_manifold_edges, mut misoriented_edges) = (0, 0, 0);
        let from = |h: u32| faces[h as usize / 3][h as usize % 3];
        for v in 0..nv {
            let group = &mut halves[start[v]..start[v + 1]];
            group.sort_unstable();
            let mut i = 0;
            while i < group.len() {
                let far = group[i].0;
                let mut j = i + 1;
                while j < group.len() && group[j].0 == far {
                    j += 1;
                }
                match j - i {
                    1 => boundary_edges += 1,
                    2 => {
                        let (h0, h1) = (group[i].1, group[i + 1].1);
                        opposite[h0 as usize] = h1;
                        opposite[h1 as usize] = h0;
                        if from(h0) == from(h1) {
                            misoriented_edges += 1;
                        }
                    }
                    _ => non_manifold_edges += 1,
                }
                i = j;
            }
        }
        // Vertex -> faces (CSR).
        let mut counts = vec![0u32; nv + 1];
        for face in mesh.faces() {
            for &v in face {
                counts[v as usize + 1] += 1;
            }
        }
        for v in 0..nv {
            counts[v + 1] += counts[v];
        }
        let mut fill = counts.clone();
        let mut vertex_faces = vec![0u32; 3 * nf];
        for (f, face) in mesh.faces().iter().enumerate() {
            for &v in face {
                vertex_faces[fill[v as usize] as usize] = f as u32;
                fill[v as usize] += 1;
            }
        }
        // Components by union-find over face edges.
        let mut parent: Vec<u32> = (0..nv as u32).collect();
        fn find(parent: &mut [u32], mut x: u32) -> u32 {
            while parent[x as usize] != x {
                parent[x as usize] = parent[parent[x as usize] as usize];
                x = parent[x as usize];
            }
            x
        }
        for face in mesh.faces() {
            for k in 1..3 {
                let (a, b) = (find(&mut parent, face[0]), find(&mut parent, face[k]));
                if a != b {
                    parent[a.max(b) as usize] = a.min(b);
                }
            }
        }
        let mut component = vec![NONE; nv];
        let mut components = 0u32;
        let mut root_id = vec![NONE; nv];
        for v in 0..nv as u32 {
            let r = find(&mut parent, v);
            if root_id[r as usize] == NONE {
                root_id[r as usize] = components;
                components += 1;
            }
            component[v as usize] = root_id[r as usize];
        }
        Self {
            opposite,
            vertex_face_offsets: counts,
            vertex_faces,
            component,
            components: components as usize,
            boundary_edges,
            non_manifold_edges,
            misoriented_edges,
        }
    }

    /// Faces incident to vertex `v`.
    pub fn faces_of(&self, v: u32) -> &[u32] {
        let (a, b) = (
            self.vertex_face_offsets[v as usize] as usize,
            self.vertex_face_offsets[v as usize + 1] as usize,
        );
        &self.vertex_faces[a..b]
    }

    /// The face across edge `k` of face `f`, if the edge is interior and manifold.
    pub fn neighbour(&self, f: usize, k: usize) -> Option<usize> {
        let h = self.opposite[3 * f + k];
        (h != NONE).then_some(h as usize / 3)
    }
}

/// A point on a surface: a vertex, or a point inside a face given by its
/// barycentric coordinates (non-negative, summing to 1, in the order of the
/// face's vertices).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SurfacePoint {
    /// A vertex.
    Vertex(u32),
    /// A point of face `face` with barycentric coordinates `bary`.
    Face {
        /// The face.
        face: u32,
        /// Barycentric coordinates with respect to the face's three vertices.
        bary: [f64; 3],
    },
}

impl SurfacePoint {
    /// Checks that the point exists on `mesh` (index in range, barycentric
    /// coordinates finite, >= -1e-12 and summing to 1 within 1e-9).
    pub fn validate(&self, mesh: &TriMesh) -> Result<(), String> {
        match *self {
            SurfacePoint::Vertex(v) if (v as usize) < mesh.num_vertices() => Ok(()),
            SurfacePoint::Vertex(v) => Err(format!(
                "vertex {v} does not exist (the mesh has {} vertices)",
                mesh.num_vertices()
            )),
            SurfacePoint::Face { face, bary } => {
                if face as usize >= mesh.num_faces() {
                    return Err(format!(
                        "face {face} does not exist (the mesh has {} faces)",
                        mesh.num_faces()
                    ));
                }
                if bary.iter().any(|b| !b.is_finite() || *b < -1e-12)
                    || (bary.iter().sum::<f64>() - 1.0).abs() > 1e-9
                {
                    return Err(format!(
                        "barycentric coordinates {bary:?} must be >= 0 and sum to 1"
                    ));
                }
                Ok(())
            }
        }
    }

    /// Position in space.
    pub fn position(&self, mesh: &TriMesh) -> [f64; 3] {
        match *self {
            SurfacePoint::Vertex(v) => mesh.position(v),
            SurfacePoint::Face { face, bary } => {
                let f = mesh.faces()[face as usize];
                let mut p = [0.0; 3];
                for k in 0..3 {
                    let q = mesh.position(f[k]);
                    for c in 0..3 {
                        p[c] += bary[k] * q[c];
                    }
                }
                p
            }
        }
    }
}

/// Per-vertex result of a surface distance solver.
#[derive(Debug, Clone, PartialEq)]
pub struct MeshDistance {
    /// Geodesic distance of every vertex to the nearest source (`+inf` where
    /// unreachable: another component, or beyond the maximum distance).
    pub distance: Vec<f64>,
    /// Index (in the source list) of the nearest source, `-1` where unreachable.
    pub labels: Vec<i32>,
}

/// Why a surface solver stopped without a result.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MeshSolveError {
    /// No sources were given.
    #[error("at least one source is needed")]
    NoSources,
    /// A source is not on the mesh.
    #[error("source {index}: {reason}")]
    InvalidSource {
        /// Index of the source in the list.
        index: usize,
        /// Why.
        reason: String,
    },
    /// An option is out of range.
    #[error("{option}: {reason}")]
    InvalidOption {
        /// The option.
        option: &'static str,
        /// Why.
        reason: String,
    },
    /// The caller raised the cancel flag.
    #[error("cancelled")]
    Cancelled,
    /// A numerical failure the solver could not recover from (for example a
    /// factorisation that broke down); the message says which.
    #[error("numerical failure: {0}")]
    Numerical(String),
}

/// `a - b`.
#[inline]
pub fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// Cross product.
#[inline]
pub fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// Dot product.
#[inline]
pub fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Euclidean norm.
#[inline]
pub fn norm(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}

/// The gradient in face `f` of the linear interpolant of the per-vertex
/// `values`: `∇f = Σ_k f_k (n × e_k) / 2A`, with `n` the unit normal and
/// `e_k` the edge opposite corner `k`; `None` for a face of zero (or NaN)
/// area.
pub fn face_gradient(mesh: &TriMesh, f: u32, values: &[f64]) -> Option<[f64; 3]> {
    let face = mesh.faces()[f as usize];
    let p = face.map(|v| mesh.position(v));
    let n = cross(sub(p[1], p[0]), sub(p[2], p[0]));
    let a2 = norm(n);
    if a2.is_nan() || a2 <= 0.0 {
        return None;
    }
    let n = n.map(|c| c / a2);
    let mut g = [0.0; 3];
    for k in 0..3 {
        let r = cross(n, sub(p[(k + 2) % 3], p[(k + 1) % 3]));
        let fk = values[face[k] as usize];
        for c in 0..3 {
            g[c] += fk * r[c] / a2;
        }
    }
    Some(g)
}

/// An orthonormal frame `(x, y)` of the plane of face `f`: `x` along its
/// first edge, `y = n × x` with `n` the unit normal (so `(x, y, n)` is
/// right-handed); `None` for a degenerate face.
pub fn face_frame(mesh: &TriMesh, f: u32) -> Option<([f64; 3], [f64; 3])> {
    let face = mesh.faces()[f as usize];
    let p0 = mesh.position(face[0]);
    let e = sub(mesh.position(face[1]), p0);
    let n = cross(e, sub(mesh.position(face[2]), p0));
    let (le, ln) = (norm(e), norm(n));
    if le.is_nan() || ln.is_nan() || le <= 0.0 || ln <= 0.0 {
        return None;
    }
    let x = e.map(|c| c / le);
    Some((x, cross(n.map(|c| c / ln), x)))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square() -> TriMesh {
        TriMesh::new(
            vec![
                [0., 0., 0.],
                [1., 0., 0.],
                [1., 1., 0.],
                [0., 1., 0.],
                [5., 5., 5.],
            ],
            vec![[0, 1, 2], [0, 2, 3]],
        )
        .unwrap()
    }

    #[test]
    fn adjacency_of_two_triangles() {
        let m = square();
        let t = Topology::new(&m);
        assert_eq!(t.boundary_edges, 4);
        assert_eq!(t.non_manifold_edges, 0);
        assert_eq!(t.misoriented_edges, 0);
        // Edge 2 of face 0 is (2, 0); edge 0 of face 1 is (0, 2).
        assert_eq!(t.opposite[2], 3);
        assert_eq!(t.neighbour(1, 0), Some(0));
        assert_eq!(t.neighbour(0, 0), None);
        assert_eq!(t.faces_of(0), &[0, 1]);
        assert_eq!(t.faces_of(4), &[] as &[u32]);
        // The isolated vertex is its own component.
        assert_eq!(t.components, 2);
        assert_eq!(t.component[4], 1);
        assert!((m.mean_edge_length() - (4.0 + 2.0 * 2f64.sqrt()) / 6.0).abs() < 1e-12);
    }

    #[test]
    fn non_manifold_fans_are_counted_not_glued() {
        let m = TriMesh::new(
            vec![
                [0., 0., 0.],
                [1., 0., 0.],
                [0., 1., 0.],
                [0., -1., 0.],
                [0., 0., 1.],
            ],
            vec![[0, 1, 2], [1, 0, 3], [0, 1, 4]],
        )
        .unwrap();
        let t = Topology::new(&m);
        assert_eq!(t.non_manifold_edges, 1);
        assert_eq!(t.opposite[0], NONE);
    }

    #[test]
    fn invalid_meshes_are_refused() {
        let p = vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        assert_eq!(TriMesh::new(p.clone(), vec![]), Err(MeshError::NoFaces));
        assert!(matches!(
            TriMesh::new(p.clone(), vec![[0, 1, 3]]),
            Err(MeshError::IndexOutOfRange {
                face: 0,
                index: 3,
                ..
            })
        ));
        assert_eq!(
            TriMesh::new(p.clone(), vec![[0, 1, 1]]),
            Err(MeshError::RepeatedVertex { face: 0 })
        );
        let mut bad = p;
        bad[1][2] = f64::NAN;
        assert_eq!(
            TriMesh::new(bad, vec![[0, 1, 2]]),
            Err(MeshError::NonFinite { vertex: 1 })
        );
    }
}
