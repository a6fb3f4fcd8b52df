//! Exact geodesic paths: the window propagation of the parent module, with
//! each vertex (and each target point) remembering how it got its final
//! distance, then the path traced back from the target.
//!
//! A record is either a straight segment to another vertex (a
//! pseudo-source's edge or face, or the Dijkstra safety net) or a straight
//! segment to a point `p` on an edge followed by the window's ray: the
//! straight line, in the unfolding of the faces it crosses, from `p`
//! towards the source image `I` of the window, of length `|p − I|`. That
//! line is walked back face by face (each step lays the next face out in
//! the plane of the current edge, as the propagation did) until it ends at
//! the window's pseudo-source (a vertex: the corner nearest to `I` in the
//! last face) or at the source point, and the walk goes on from that
//! vertex's own record. Every piece is a straight segment on the surface
//! and the pieces' lengths add up to the recorded distance, so the path's
//! length equals the exact distance up to rounding, and the path is a
//! shortest one (a path as long as the distance is a geodesic).
//!
//! A target inside a face is reached by every window crossing an edge of
//! its face (the nearest ray of the window's interval, as for the third
//! vertex of a face), by the pseudo-sources at the face's corners, by a
//! source in the same face, and finally through the face's corners.

use std::collections::HashMap;

use super::{
    barycentric_point, check_inputs, norm, sub, Geometry, MeshDistance, MeshSolveError, Parent,
    Propagation, SurfacePoint, Target, Topology, TriMesh, NONE,
};
use crate::numerics::mesh::paths::{GeodesicPath, PathLocation, PathPoint};
use crate::numerics::Control;

/// Exact distances from `sources` and, for each of `targets`, the exact
/// shortest path from the target to its nearest source (the same order as
/// [`crate::numerics::mesh::paths::trace_path`]: the target first).
///
/// A target that is not reached (another component) gets an error of its
/// own; the distances are those of [`super::exact_distance`].
///
/// # Examples
/// ```
/// use geodex::numerics::mesh::{exact::exact_paths, SurfacePoint, Topology, TriMesh};
/// use geodex::numerics::Control;
/// let m = TriMesh::new(
///     vec![[0., 0., 0.], [1., 0., 0.], [1., 1., 0.], [0., 1., 0.]],
///     vec![[0, 1, 2], [0, 2, 3]],
/// )?;
/// let t = Topology::new(&m);
/// let (_, paths) = exact_paths(&m, &t, &[SurfacePoint::Vertex(1)], &[SurfacePoint::Vertex(3)],
///     &Control::new())?;
/// let path = paths[0].clone()?;
/// assert!((path.length - 2f64.sqrt()).abs() < 1e-12);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[allow(clippy::type_complexity)]
pub fn exact_paths(
    mesh: &TriMesh,
    topo: &Topology,
    sources: &[SurfacePoint],
    targets: &[SurfacePoint],
    control: &Control<'_>,
) -> Result<(MeshDistance, Vec<Result<GeodesicPath, MeshSolveError>>), MeshSolveError> {
    check_inputs(mesh, topo, sources)?;
    for t in targets {
        t.validate(mesh)
            .map_err(|reason| MeshSolveError::InvalidOption {
                option: "targets",
                reason,
            })?;
    }
    let geo = Geometry::new(mesh, topo);
    let mut p = Propagation::new(&geo, f64::INFINITY, 0);
    p.parents = vec![Parent::None; mesh.num_vertices()];
    let mut face_targets: HashMap<u32, Vec<u32>> = HashMap::new();
    for t in targets {
        if let SurfacePoint::Face { face, bary } = *t {
            face_targets
                .entry(face)
                .or_default()
                .push(p.targets.len() as u32);
            p.targets.push(Target {
                face,
                bary,
                dist: f64::INFINITY,
                label: NONE,
                parent: Parent::None,
            });
        }
    }
    p.face_targets = face_targets;
    p.seed(sources);
    p.run(control)?;
    p.settle();
    // Targets through the corners of their face (the vertex paths are final).
    for t in p.targets.iter_mut() {
        let f = mesh.faces()[t.face as usize];
        let corners = f.map(|v| mesh.position(v));
        let q = barycentric_point(&corners, t.bary);
        for &v in &f {
            let d = p.dist[v as usize] + norm(sub(mesh.position(v), q));
            if d < t.dist {
                t.dist = d;
                t.label = p.label[v as usize];
                t.parent = Parent::Vertex(v);
            }
        }
    }
    let mut paths = Vec::with_capacity(targets.len());
    let mut next_face_target = 0usize;
    for (i, t) in targets.iter().enumerate() {
        if control.is_cancelled() {
            return Err(MeshSolveError::Cancelled);
        }
        let path = match *t {
            SurfacePoint::Vertex(v) => {
                let start = PathPoint {
                    position: mesh.position(v),
                    location: PathLocation::Vertex(v),
                };
                let label = p.label[v as usize];
                p.backtrack(
                    sources,
                    start,
                    p.parents[v as usize],
                    label,
                    p.dist[v as usize],
                )
            }
            SurfacePoint::Face { face, bary } => {
                let rec = p.targets[next_face_target];
                next_face_target += 1;
                let f = mesh.faces()[face as usize];
                let corners = f.map(|v| mesh.position(v));
                let start = PathPoint {
                    position: barycentric_point(&corners, bary),
                    location: PathLocation::Face(face),
                };
                p.backtrack(sources, start, rec.parent, rec.label, rec.dist)
            }
        };
        paths.push(path.map_err(|e| match e {
            MeshSolveError::Numerical(reason) => {
                MeshSolveError::Numerical(format!("target {i}: {reason}"))
            }
            e => e,
        }));
    }
    let (d, _) = p.finish();
    Ok((d, paths))
}

impl Propagation<'_> {
    /// The path from `start` (with record `parent`, nearest source `label`
    /// and distance `dist`) back to its source.
    fn backtrack(
        &self,
        sources: &[SurfacePoint],
        start: PathPoint,
        mut parent: Parent,
        label: u32,
        dist: f64,
    ) -> Result<GeodesicPath, MeshSolveError> {
        if !dist.is_finite() || label == NONE {
            return Err(MeshSolveError::Numerical(
                "not reached from the sources (another component)".into(),
            ));
        }
        let mesh = self.mesh;
        let mut at = match start.location {
            PathLocation::Vertex(v) => Some(v),
            _ => None,
        };
        let mut points = vec![start];
        // Every step either walks a ray (bounded below) or moves to a
        // vertex of smaller distance: a bound on the records visited.
        let mut budget = 4 * mesh.num_vertices() + 16;
        loop {
            budget = budget.checked_sub(1).ok_or_else(|| {
                MeshSolveError::Numerical("the path's records do not lead to a source".into())
            })?;
            match parent {
                Parent::None => {
                    return Err(MeshSolveError::Numerical(
                        "a point on the path has no record of how it was reached".into(),
                    ))
                }
                Parent::Root => break,
                Parent::SourcePoint(l) => {
                    let q = sources[l as usize].position(mesh);
                    points.push(PathPoint {
                        position: q,
                        location: location_of(sources[l as usize]),
                    });
                    break;
                }
                Parent::Vertex(u) => {
                    points.push(vertex_point(mesh, u));
                    parent = self.parents[u as usize];
                    at = Some(u);
                }
                Parent::Ray {
                    h,
                    x,
                    sx,
                    sy,
                    sigma,
                } => match self.walk_ray(at, h, x, sx, sy, &mut points)? {
                    End::Vertex(u) => {
                        parent = self.parents[u as usize];
                        at = Some(u);
                    }
                    End::Inside(face, q) => {
                        // The ray ends at its source image: the source
                        // itself for a window of distance 0, else the
                        // pseudo-source at a corner of the last face.
                        if sigma == 0.0 {
                            let s = sources[label as usize];
                            points.push(PathPoint {
                                position: s.position(mesh),
                                location: location_of(s),
                            });
                            break;
                        }
                        let u = self.nearest_corner(face, q);
                        points.push(vertex_point(mesh, u));
                        parent = self.parents[u as usize];
                        at = Some(u);
                    }
                },
            }
        }
        dedup(&mut points);
        let path = GeodesicPath::from_points(points, Some(label as usize));
        // The pieces must add up to the distance. On faces whose unfolding
        // is lost in round-off (needles 1e-9 of an edge long) a ray can end
        // short of its source image; such a path is refused rather than
        // returned as exact.
        if (path.length - dist).abs() > 1e-6 * (dist + path.length) + 1e-12 {
            return Err(MeshSolveError::Numerical(format!(
                "the path traced back through the windows is {:.9} long for an exact distance \
                 of {dist:.9}: a ray lost its way on near-degenerate faces",
                path.length
            )));
        }
        Ok(path)
    }

    /// The corner of `face` nearest to `p`.
    fn nearest_corner(&self, face: u32, p: [f64; 3]) -> u32 {
        let f = self.mesh.faces()[face as usize];
        let mut best = (f64::INFINITY, f[0]);
        for &v in &f {
            let d = norm(sub(self.mesh.position(v), p));
            if d < best.0 {
                best = (d, v);
            }
        }
        best.1
    }

    /// Walks the straight unfolded ray from the point at `x` on half-edge
    /// `h` (reached from vertex `from`, if any) towards the source image `(sx, sy)` (frame of `h`, `sy <= 0`),
    /// pushing the 3D points where it crosses edges, until it reaches the
    /// source image: returns the vertex it ends on (pushed), or the face it
    /// ends inside (the end point not pushed).
    fn walk_ray(
        &self,
        mut from: Option<u32>,
        mut h: u32,
        mut x: f64,
        mut sx: f64,
        mut sy: f64,
        points: &mut Vec<PathPoint>,
    ) -> Result<End, MeshSolveError> {
        let mesh = self.mesh;
        let faces = mesh.faces();
        // The starting crossing.
        points.push(self.edge_point(h, x));
        let mut steps = 2 * mesh.num_faces() + 8;
        loop {
            steps = steps.checked_sub(1).ok_or_else(|| {
                MeshSolveError::Numerical(
                    "a ray of the path crosses more faces than the mesh has".into(),
                )
            })?;
            let t = self.topo.opposite[h as usize];
            if t == NONE {
                return Err(MeshSolveError::Numerical(
                    "a ray of the path leaves the surface across a boundary".into(),
                ));
            }
            let (f, k) = ((h / 3) as usize, (h % 3) as usize);
            let (g, kg) = ((t / 3) as usize, (t % 3) as usize);
            let l = self.len(h as usize);
            // At an end of the edge: the path passes through that vertex
            // (the ray may go on through any face around it); its own
            // record is a shortest path from there. At the vertex the walk
            // starts from, the ray leaves it instead: `pivot` is its
            // corner in the frame below.
            let mut pivot = None;
            if x <= 1e-9 * l || x >= (1.0 - 1e-9) * l {
                let v = if x <= 1e-9 * l {
                    faces[f][k]
                } else {
                    faces[f][(k + 1) % 3]
                };
                if Some(v) != from {
                    points.push(vertex_point(mesh, v));
                    return Ok(End::Vertex(v));
                }
                pivot = Some(v);
            } else {
                from = None;
            }
            // Into the frame of t (face g on its positive side).
            let reversed = faces[g][kg] == faces[f][(k + 1) % 3];
            let (px, qx, qy) = if reversed {
                (l - x, l - sx, -sy)
            } else {
                (x, sx, -sy)
            };
            let fr = self.frame(g, kg);
            let corners = [(0.0, 0.0), (fr.l, 0.0), (fr.cx, fr.cy)];
            // The pivot's corner (0 or 1 of this frame), snapped.
            let pc = pivot.map(|v| if faces[g][kg] == v { 0 } else { 1 });
            let px = match pc {
                Some(0) => 0.0,
                Some(_) => fr.l,
                None => px,
            };
            // Segment P = (px, 0) -> Q = (qx, qy), qy >= 0: where does it
            // leave face g, through edge kg+1 (b -> c) or kg+2 (c -> a)?
            // From a pivot corner only the opposite edge counts.
            let (dx, dy) = (qx - px, qy);
            let mut best: Option<(f64, usize, f64)> = None;
            for e in [1usize, 2] {
                if pc.is_some_and(|c| c == e || c == (e + 1) % 3) {
                    continue;
                }
                let (e0, e1) = (corners[e], corners[(e + 1) % 3]);
                let (ex, ey) = (e1.0 - e0.0, e1.1 - e0.1);
                let den = dx * ey - dy * ex;
                if den == 0.0 || !den.is_finite() {
                    continue;
                }
                // P + s d = e0 + u e  ⇒  s = cross(e0 − P, e) / cross(d, e),
                // u = cross(e0 − P, d) / cross(d, e).
                let (wx, wy) = (e0.0 - px, e0.1);
                let s = (wx * ey - wy * ex) / den;
                let u = (wx * dy - wy * dx) / den;
                if s > 1e-12 && (-1e-9..=1.0 + 1e-9).contains(&u) && best.is_none_or(|b| s < b.0) {
                    best = Some((s, e, u.clamp(0.0, 1.0)));
                }
            }
            let inside = End::Inside(g as u32, self.point_in_frame(g, kg, qx, qy));
            let tol = 1e-9 * fr.l.max(fr.lbc).max(fr.lca);
            let (e, u) = match best {
                // The image is reached in (or on the boundary of) this face.
                Some((s, ..)) if s >= 1.0 - 1e-9 => return Ok(inside),
                Some((_, e, u)) => (e, u),
                None if contains(&corners, (qx, qy), tol) => return Ok(inside),
                None => {
                    // From the pivot the ray runs outside this face's
                    // corner: turn around the vertex, into the face across
                    // its other edge (the ray came in through the first).
                    let Some(c) = pc else {
                        return Err(MeshSolveError::Numerical(
                            "a ray of the path was lost between two faces".into(),
                        ));
                    };
                    let e = if c == 0 { 2 } else { 1 };
                    let he = (3 * g + (kg + e) % 3) as u32;
                    let le = self.len(he as usize);
                    let (e0, e1) = (corners[e], corners[(e + 1) % 3]);
                    let (ux, uy) = ((e1.0 - e0.0) / le, (e1.1 - e0.1) / le);
                    let (nx, ny) = super::to_frame(qx, qy, e0.0, e0.1, ux, uy);
                    if ny > tol {
                        return Err(MeshSolveError::Numerical(
                            "a ray of the path turns back around a vertex".into(),
                        ));
                    }
                    h = he;
                    x = if c == 0 { le } else { 0.0 };
                    sx = nx;
                    sy = ny.min(0.0);
                    continue;
                }
            };
            let he = (3 * g + (kg + e) % 3) as u32;
            let le = self.len(he as usize);
            // Passing exactly through a vertex: the path bends there only
            // if it is a pseudo-source; go on from that vertex's record,
            // whose length is the same up to rounding.
            if u <= 1e-9 || u >= 1.0 - 1e-9 {
                let v = if u <= 1e-9 {
                    faces[g][(kg + e) % 3]
                } else {
                    faces[g][(kg + e + 1) % 3]
                };
                points.push(vertex_point(mesh, v));
                return Ok(End::Vertex(v));
            }
            // The image in the frame of the exit half-edge (g on its
            // positive side, the image beyond it).
            let (e0, e1) = (corners[e], corners[(e + 1) % 3]);
            let (ux, uy) = ((e1.0 - e0.0) / le, (e1.1 - e0.1) / le);
            let (nx, ny) = super::to_frame(qx, qy, e0.0, e0.1, ux, uy);
            h = he;
            x = u * le;
            sx = nx;
            sy = ny.min(0.0);
            from = None;
            points.push(self.edge_point(h, x));
        }
    }

    /// The 3D point at `(x, y)` in the frame of edge `k` of face `g`.
    fn point_in_frame(&self, g: usize, k: usize, x: f64, y: f64) -> [f64; 3] {
        let faces = self.mesh.faces();
        let a = self.mesh.position(faces[g][k]);
        let b = self.mesh.position(faces[g][(k + 1) % 3]);
        let c = self.mesh.position(faces[g][(k + 2) % 3]);
        let l = self.len(3 * g + k);
        let ex = sub(b, a).map(|v| v / l);
        let ac = sub(c, a);
        let along = ac[0] * ex[0] + ac[1] * ex[1] + ac[2] * ex[2];
        let perp = [0, 1, 2].map(|i| ac[i] - along * ex[i]);
        let pn = norm(perp);
        let ey = if pn > 0.0 {
            perp.map(|v| v / pn)
        } else {
            [0.0; 3]
        };
        [0, 1, 2].map(|i| a[i] + x * ex[i] + y * ey[i])
    }

    /// The 3D point at `x` along half-edge `h`.
    fn edge_point(&self, h: u32, x: f64) -> PathPoint {
        let faces = self.mesh.faces();
        let (f, k) = ((h / 3) as usize, (h % 3) as usize);
        let (a, b) = (faces[f][k], faces[f][(k + 1) % 3]);
        let l = self.len(h as usize);
        let t = if l > 0.0 {
            (x / l).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let (pa, pb) = (self.mesh.position(a), self.mesh.position(b));
        let position = [0, 1, 2].map(|c| pa[c] + t * (pb[c] - pa[c]));
        let location = if t <= 0.0 {
            PathLocation::Vertex(a)
        } else if t >= 1.0 {
            PathLocation::Vertex(b)
        } else {
            PathLocation::Edge(a, b, t)
        };
        PathPoint { position, location }
    }
}

/// Whether `q` lies in the triangle `c` (counter-clockwise), up to `tol`.
fn contains(c: &[(f64, f64); 3], q: (f64, f64), tol: f64) -> bool {
    (0..3).all(|i| {
        let (a, b) = (c[i], c[(i + 1) % 3]);
        let (ex, ey) = (b.0 - a.0, b.1 - a.1);
        let l = ex.hypot(ey);
        // Signed distance of q to the edge's line, positive inside.
        l > 0.0 && (ex * (q.1 - a.1) - ey * (q.0 - a.0)) / l >= -tol
    })
}

enum End {
    /// At this vertex (pushed).
    Vertex(u32),
    /// Inside this face, at the source image (not pushed).
    Inside(u32, [f64; 3]),
}

fn vertex_point(mesh: &TriMesh, v: u32) -> PathPoint {
    PathPoint {
        position: mesh.position(v),
        location: PathLocation::Vertex(v),
    }
}

fn location_of(s: SurfacePoint) -> PathLocation {
    match s {
        SurfacePoint::Vertex(v) => PathLocation::Vertex(v),
        SurfacePoint::Face { face, .. } => PathLocation::Face(face),
    }
}

/// Drops consecutive points at the same position.
fn dedup(points: &mut Vec<PathPoint>) {
    points.dedup_by(|b, a| {
        let d = norm(sub(a.position, b.position));
        let scale = norm(a.position).max(1.0);
        let same = d <= 1e-12 * scale;
        // Keep the vertex of the two (an edge point at a vertex is that vertex).
        if same && matches!(b.location, PathLocation::Vertex(_)) {
            *a = *b;
        }
        same
    });
}
