//! Geodesic paths by steepest descent of a distance field across faces.
//!
//! From a point, the path follows `−∇d` of the per-face linear interpolant
//! of the vertex distances `d`: inside a face it is a straight segment to
//! the edge it exits through, then it continues in the face across that
//! edge. At a vertex it leaves through the incident face whose descent
//! direction points into the face's corner (else along the edge to the
//! lowest neighbour). Where the descent directions of two faces point at
//! their common edge (a valley of `d`), the path slides along the edge to
//! its lower end. Once in a face that touches a source (a source vertex or
//! the face of a source point) the path ends with the straight segment to
//! it, which is the exact geodesic inside one face. The path is as accurate
//! as `d` (first order for fast marching and the heat method).

use super::{cross, dot, norm, sub, MeshSolveError, SurfacePoint, Topology, TriMesh, NONE};

/// Where a path point lies.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PathLocation {
    /// At a vertex.
    Vertex(u32),
    /// On the edge between two vertices (`t` from the first: `p = (1−t)a + t b`).
    Edge(u32, u32, f64),
    /// Inside a face.
    Face(u32),
}

/// One point of a path.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PathPoint {
    /// Position in space.
    pub position: [f64; 3],
    /// Vertex, edge or face of the point.
    pub location: PathLocation,
}

/// A traced path, from the start point to a source.
#[derive(Debug, Clone, PartialEq)]
pub struct GeodesicPath {
    /// Polyline from the start to the source.
    pub points: Vec<PathPoint>,
    /// The source reached (index in the source list), if any.
    pub source: Option<usize>,
    /// Length of the polyline.
    pub length: f64,
}

impl GeodesicPath {
    /// The path through `points`, its length the polyline's.
    pub fn from_points(points: Vec<PathPoint>, source: Option<usize>) -> Self {
        let length = points
            .windows(2)
            .map(|w| norm(sub(w[1].position, w[0].position)))
            .sum();
        Self {
            points,
            source,
            length,
        }
    }
}

enum At {
    Vertex(u32),
    /// In face `f` at barycentric `b` (possibly on its boundary).
    Face(u32, [f64; 3]),
}

/// Traces the descent path from `start` on the field `distance`.
///
/// Fails with [`MeshSolveError::InvalidSource`] (index 0) when `start` is not
/// on the mesh, and with [`MeshSolveError::Numerical`] when it is not reached
/// by the field (another component, beyond the maximum distance).
pub fn trace_path(
    mesh: &TriMesh,
    topo: &Topology,
    distance: &[f64],
    sources: &[SurfacePoint],
    start: SurfacePoint,
) -> Result<GeodesicPath, MeshSolveError> {
    trace_path_in(mesh, topo, distance, sources, start, None)
}

/// [`trace_path`] on a field computed under face tensors (`tensors`, one
/// per face, as in [`super::fast_marching::Metric::Faces`]): in face `f`
/// the path follows the characteristic direction `−M_f⁻¹ ∇d` (the inverse
/// taken on the face's plane) rather than `−∇d`, so that it bends with
/// the anisotropy. `None` is [`trace_path`].
pub fn trace_path_in(
    mesh: &TriMesh,
    topo: &Topology,
    distance: &[f64],
    sources: &[SurfacePoint],
    start: SurfacePoint,
    tensors: Option<&[[f64; 6]]>,
) -> Result<GeodesicPath, MeshSolveError> {
    start
        .validate(mesh)
        .map_err(|reason| MeshSolveError::InvalidSource { index: 0, reason })?;
    let faces = mesh.faces();
    let finite_face = |f: u32| {
        faces[f as usize]
            .iter()
            .all(|&v| distance[v as usize].is_finite())
    };
    let mut points: Vec<PathPoint> = Vec::new();
    let mut at = match start {
        SurfacePoint::Vertex(v) => {
            if !distance[v as usize].is_finite() {
                return Err(MeshSolveError::Numerical(format!(
                    "vertex {v} is not reached from the sources"
                )));
            }
            points.push(PathPoint {
                position: mesh.position(v),
                location: PathLocation::Vertex(v),
            });
            At::Vertex(v)
        }
        SurfacePoint::Face { face, bary } => {
            if !finite_face(face) {
                return Err(MeshSolveError::Numerical(format!(
                    "face {face} is not reached from the sources"
                )));
            }
            points.push(PathPoint {
                position: start.position(mesh),
                location: PathLocation::Face(face),
            });
            At::Face(face, bary)
        }
    };
    let source_vertex = |v: u32| {
        sources
            .iter()
            .position(|s| matches!(*s, SurfacePoint::Vertex(x) if x == v))
    };
    // The source to finish with from face f, if f touches one.
    let finish_in = |f: u32, from: [f64; 3]| -> Option<(usize, SurfacePoint)> {
        let mut best: Option<(f64, usize, SurfacePoint)> = None;
        for (i, s) in sources.iter().enumerate() {
            let touches = match *s {
                SurfacePoint::Vertex(v) => faces[f as usize].contains(&v),
                SurfacePoint::Face { face, .. } => face == f,
            };
            if touches {
                let d = norm(sub(s.position(mesh), from));
                if best.is_none_or(|b| d < b.0) {
                    best = Some((d, i, *s));
                }
            }
        }
        best.map(|(_, i, s)| (i, s))
    };
    let max_steps = 8 * mesh.num_faces() + 16;
    let mut source = None;
    for _ in 0..max_steps {
        match at {
            At::Vertex(v) => {
                if let Some(i) = source_vertex(v) {
                    source = Some(i);
                    break;
                }
                let pv = mesh.position(v);
                // A face touching a source: straight to it.
                if let Some((i, s)) = topo.faces_of(v).iter().find_map(|&f| finish_in(f, pv)) {
                    push_source(mesh, &mut points, s);
                    source = Some(i);
                    break;
                }
                // Steepest descent direction pointing into a corner.
                let mut best: Option<(f64, u32)> = None;
                for &f in topo.faces_of(v) {
                    if !finite_face(f) {
                        continue;
                    }
                    let Some(g) = descent(mesh, distance, f, tensors) else {
                        continue;
                    };
                    let face = faces[f as usize];
                    let Some(k) = face.iter().position(|&x| x == v) else {
                        continue;
                    };
                    let e1 = sub(mesh.position(face[(k + 1) % 3]), pv);
                    let e2 = sub(mesh.position(face[(k + 2) % 3]), pv);
                    let (g11, g12, g22) = (dot(e1, e1), dot(e1, e2), dot(e2, e2));
                    let det = g11 * g22 - g12 * g12;
                    let (r1, r2) = (dot(e1, g), dot(e2, g));
                    let alpha = (g22 * r1 - g12 * r2) / det;
                    let beta = (g11 * r2 - g12 * r1) / det;
                    let slope = norm(g);
                    if alpha >= -1e-12 && beta >= -1e-12 && best.is_none_or(|b| slope > b.0) {
                        best = Some((slope, f));
                    }
                }
                if let Some((_, f)) = best {
                    let face = faces[f as usize];
                    let mut b = [0.0; 3];
                    if let Some(k) = face.iter().position(|&x| x == v) {
                        b[k] = 1.0;
                    }
                    // Walk one segment now so that the loop makes progress.
                    at = walk(mesh, topo, distance, f, b, &mut points, tensors);
                    continue;
                }
                // Along the edge to the lowest neighbour.
                let mut low: Option<(f64, u32)> = None;
                for &f in topo.faces_of(v) {
                    for &w in &faces[f as usize] {
                        if w != v
                            && distance[w as usize] < distance[v as usize]
                            && low.is_none_or(|l| distance[w as usize] < l.0)
                        {
                            low = Some((distance[w as usize], w));
                        }
                    }
                }
                match low {
                    Some((_, w)) => {
                        points.push(PathPoint {
                            position: mesh.position(w),
                            location: PathLocation::Vertex(w),
                        });
                        at = At::Vertex(w);
                    }
                    None => break, // local minimum that is not a source
                }
            }
            At::Face(f, b) => {
                let here = bary_point(mesh, f, b);
                if let Some((i, s)) = finish_in(f, here) {
                    push_source(mesh, &mut points, s);
                    source = Some(i);
                    break;
                }
                at = walk(mesh, topo, distance, f, b, &mut points, tensors);
            }
        }
    }
    Ok(GeodesicPath::from_points(points, source))
}

fn push_source(mesh: &TriMesh, points: &mut Vec<PathPoint>, s: SurfacePoint) {
    points.push(PathPoint {
        position: s.position(mesh),
        location: match s {
            SurfacePoint::Vertex(v) => PathLocation::Vertex(v),
            SurfacePoint::Face { face, .. } => PathLocation::Face(face),
        },
    });
}

fn bary_point(mesh: &TriMesh, f: u32, b: [f64; 3]) -> [f64; 3] {
    SurfacePoint::Face { face: f, bary: b }.position(mesh)
}

/// `−∇d` in face `f` (`−M_f⁻¹∇d` under face tensors), `None` when the face
/// is degenerate or flat in `d`.
fn descent(
    mesh: &TriMesh,
    distance: &[f64],
    f: u32,
    tensors: Option<&[[f64; 6]]>,
) -> Option<[f64; 3]> {
    let mut g = super::face_gradient(mesh, f, distance)?.map(|c| -c);
    if let Some(t) = tensors {
        // Solve M₂ v₂ = g₂ in the orthonormal frame (x, y) of the face.
        let m = &t[f as usize];
        let (x, y) = super::face_frame(mesh, f)?;
        let form = super::fast_marching::tensor_form;
        let (a, b, c) = (form(m, x, x), form(m, x, y), form(m, y, y));
        let det = a * c - b * b;
        if det.is_nan() || det <= 0.0 {
            return None;
        }
        let (gx, gy) = (dot(g, x), dot(g, y));
        let (vx, vy) = ((c * gx - b * gy) / det, (a * gy - b * gx) / det);
        g = std::array::from_fn(|j| vx * x[j] + vy * y[j]);
    }
    (norm(g) > 0.0 && g.iter().all(|x| x.is_finite())).then_some(g)
}

/// Walks from barycentric `b` in face `f` along `−∇d` to the face's
/// boundary; pushes the exit point and returns where the path continues.
fn walk(
    mesh: &TriMesh,
    topo: &Topology,
    distance: &[f64],
    f: u32,
    b: [f64; 3],
    points: &mut Vec<PathPoint>,
    tensors: Option<&[[f64; 6]]>,
) -> At {
    let face = mesh.faces()[f as usize];
    let lowest = || {
        let k = (0..3)
            .min_by(|&i, &j| distance[face[i] as usize].total_cmp(&distance[face[j] as usize]))
            .unwrap_or(0);
        face[k]
    };
    let to_vertex = |v: u32, points: &mut Vec<PathPoint>| {
        points.push(PathPoint {
            position: mesh.position(v),
            location: PathLocation::Vertex(v),
        });
        At::Vertex(v)
    };
    let Some(g) = descent(mesh, distance, f, tensors) else {
        return to_vertex(lowest(), points);
    };
    let p = face.map(|v| mesh.position(v));
    let n = cross(sub(p[1], p[0]), sub(p[2], p[0]));
    let a2 = norm(n);
    let nn = [n[0] / a2, n[1] / a2, n[2] / a2];
    // d(λ_k)/ds along g: ∇λ_k = (N × e_k) / 2A.
    let db: [f64; 3] =
        std::array::from_fn(|k| dot(cross(nn, sub(p[(k + 2) % 3], p[(k + 1) % 3])), g) / a2);
    let scale = db.iter().map(|x| x.abs()).fold(0.0, f64::max);
    let mut s_exit = f64::INFINITY;
    let mut k_exit = 3;
    for k in 0..3 {
        if db[k] < -1e-12 * scale {
            let s = b[k].max(0.0) / -db[k];
            if s < s_exit {
                s_exit = s;
                k_exit = k;
            }
        }
    }
    if k_exit == 3 || !s_exit.is_finite() {
        return to_vertex(lowest(), points);
    }
    let mut nb: [f64; 3] = std::array::from_fn(|k| (b[k] + s_exit * db[k]).max(0.0));
    nb[k_exit] = 0.0;
    let sum: f64 = nb.iter().sum();
    for x in nb.iter_mut() {
        *x /= sum;
    }
    // A zero-length step from an edge: the descent points back out of this
    // face (a valley along the edge). Slide to the edge's lower end.
    let moved = s_exit * norm(g) > 1e-12 * (norm(sub(p[1], p[0])) + 1e-300);
    let (ia, ib) = ((k_exit + 1) % 3, (k_exit + 2) % 3);
    if !moved {
        let w = if distance[face[ia] as usize] <= distance[face[ib] as usize] {
            face[ia]
        } else {
            face[ib]
        };
        return to_vertex(w, points);
    }
    // Landing on a vertex.
    for k in 0..3 {
        if nb[k] > 1.0 - 1e-9 {
            return to_vertex(face[k], points);
        }
    }
    let (va, vb) = (face[ia], face[ib]);
    let t = nb[ib] / (nb[ia] + nb[ib]);
    let position = bary_point(mesh, f, nb);
    points.push(PathPoint {
        position,
        location: PathLocation::Edge(va, vb, t),
    });
    // Across the edge (ia -> ib is edge index ia of the face).
    let h = topo.opposite[3 * f as usize + ia];
    if h == NONE {
        let w = if distance[va as usize] <= distance[vb as usize] {
            va
        } else {
            vb
        };
        return to_vertex(w, points);
    }
    let g2 = h / 3;
    let face2 = mesh.faces()[g2 as usize];
    let mut b2 = [0.0; 3];
    for k in 0..3 {
        if face2[k] == va {
            b2[k] = 1.0 - t;
        } else if face2[k] == vb {
            b2[k] = t;
        }
    }
    At::Face(g2, b2)
}
