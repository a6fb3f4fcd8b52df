//! Metric design on surfaces: a per-vertex cost `W(v) > 0` built from the
//! surface's curvature or from a per-vertex field (a texture, a scalar
//! function), so that minimal paths follow ridges, valleys or the edges of
//! the field (the monograph's sections 1.1.2 and 3.2.4, the surface
//! counterpart of [`crate::numerics::metric_design`]).
//!
//! Every design maps its feature to `g ∈ [0, 1]` and returns a cost in
//! `[ε, 1/ε]`-bounded form, so every value is finite and `> 0`:
//!
//! * [`MeshDesign::Curvature`]: with the principal curvatures `κ₁ >= κ₂`
//!   of [`super::curvature`] (positive where the surface bends away from
//!   its normal), the feature is `s = max(κ₁, 0)` for
//!   [`CurvatureFeature::Ridges`] (convex creases), `s = max(−κ₂, 0)` for
//!   [`CurvatureFeature::Valleys`] and `s = max(|κ₁|, |κ₂|)` for
//!   [`CurvatureFeature::Both`]; `g = min(1, s / s₉₉)` with `s₉₉` the 99th
//!   percentile over the vertices of `max(|κ₁|, |κ₂|)` (robust to a few
//!   spikes of a noisy scan, and the same scale for every feature, so that
//!   a surface without ridges gets no cheap ridge), and `W = 1 / (ε + g^p)`:
//!   cheap where the surface bends.
//!   The sign needs consistently oriented faces (outward normals); `Both`
//!   does not.
//! * [`MeshDesign::Field`] with [`FieldMode::Value`]: `f` mapped affinely to
//!   `[0, 1]` (minimum to 0, maximum to 1) and `W = |f − c|^p + ε`, cheap
//!   where the field has the value `c` (given in the field's units).
//! * [`MeshDesign::Field`] with [`FieldMode::Follow`] or
//!   [`FieldMode::Barrier`]: `g = |∇_S f| / max |∇_S f|` with `∇_S f` the
//!   gradient of the piecewise-linear field, a vertex taking the
//!   area-weighted mean of its faces' gradient norms; `Follow` gives
//!   `W = 1 / (ε + g^p)` (paths run along the field's edges, the livewire
//!   metric on a surface) and `Barrier` gives `W = ε + g^p` (crossing an
//!   edge of the field is expensive).
//!
//! # Examples
//! ```
//! use geodex::numerics::mesh::design::{design, FieldMode, MeshDesign};
//! use geodex::numerics::mesh::{shapes::flat_square, Topology};
//! use geodex::numerics::Control;
//! let mesh = flat_square(4, 1.0, 0.0);
//! // A texture equal to x: the vertices where x = 0.5 are the cheapest.
//! let f: Vec<f64> = mesh.positions().iter().map(|p| p[0]).collect();
//! let d = MeshDesign::Field { values: &f, mode: FieldMode::Value { reference: 0.5 }, epsilon: 0.01, power: 1.0 };
//! let w = design(&mesh, &Topology::new(&mesh), &d, &Control::new())?;
//! assert!((w[2] - 0.01).abs() < 1e-12 && (w[0] - 0.51).abs() < 1e-12);
//! # Ok::<(), geodex::numerics::mesh::MeshSolveError>(())
//! ```

use super::curvature::curvature;
use super::{face_gradient, norm, MeshSolveError, Topology, TriMesh};
use crate::numerics::Control;

/// Which bends of the surface a curvature design makes cheap.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CurvatureFeature {
    /// Convex creases: `max(κ₁, 0)`.
    Ridges,
    /// Concave creases: `max(−κ₂, 0)`.
    Valleys,
    /// Both: `max(|κ₁|, |κ₂|)`.
    Both,
}

/// How a field design reads the field.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FieldMode {
    /// `W = |f − c|^p + ε` on the normalised field (`reference` = `c` in
    /// the field's units).
    Value {
        /// The value that is cheapest.
        reference: f64,
    },
    /// `W = 1 / (ε + g^p)`: cheap along the field's edges.
    Follow,
    /// `W = ε + g^p`: expensive across the field's edges.
    Barrier,
}

/// A metric design on a surface (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MeshDesign<'a> {
    /// From the principal curvatures.
    Curvature {
        /// Which bends.
        feature: CurvatureFeature,
        /// `ε > 0`: the cost ranges over `[1/(1 + ε), 1/ε]`.
        epsilon: f64,
        /// `p > 0`.
        power: f64,
        /// Passes of one-ring smoothing of the curvature tensor
        /// ([`super::curvature::curvature`]).
        smoothing: usize,
    },
    /// From one value per vertex.
    Field {
        /// The field, one finite value per vertex.
        values: &'a [f64],
        /// How it is read.
        mode: FieldMode,
        /// `ε > 0`.
        epsilon: f64,
        /// `p > 0`.
        power: f64,
    },
}

fn invalid(option: &'static str, reason: impl Into<String>) -> MeshSolveError {
    MeshSolveError::InvalidOption {
        option,
        reason: reason.into(),
    }
}

fn check_positive(option: &'static str, x: f64) -> Result<(), MeshSolveError> {
    if x.is_finite() && x > 0.0 {
        Ok(())
    } else {
        Err(invalid(option, format!("{x} (must be finite and > 0)")))
    }
}

/// The per-vertex cost `W` of `design` on `mesh` (see the module docs).
pub fn design(
    mesh: &TriMesh,
    topo: &Topology,
    design: &MeshDesign<'_>,
    control: &Control<'_>,
) -> Result<Vec<f64>, MeshSolveError> {
    match *design {
        MeshDesign::Curvature {
            feature,
            epsilon,
            power,
            smoothing,
        } => {
            check_positive("epsilon", epsilon)?;
            check_positive("power", power)?;
            let c = curvature(mesh, topo, smoothing, control)?;
            let s: Vec<f64> = c
                .iter()
                .map(|v| match feature {
                    CurvatureFeature::Ridges => v.k1.max(0.0),
                    CurvatureFeature::Valleys => (-v.k2).max(0.0),
                    CurvatureFeature::Both => v.k1.abs().max(v.k2.abs()),
                })
                .collect();
            let magnitude: Vec<f64> = c.iter().map(|v| v.k1.abs().max(v.k2.abs())).collect();
            let reference = percentile(&magnitude, 0.99);
            Ok(s.iter()
                .map(|&x| {
                    let g = if reference > 0.0 {
                        (x / reference).min(1.0)
                    } else {
                        0.0
                    };
                    1.0 / (epsilon + g.powf(power))
                })
                .collect())
        }
        MeshDesign::Field {
            values,
            mode,
            epsilon,
            power,
        } => {
            check_positive("epsilon", epsilon)?;
            check_positive("power", power)?;
            if values.len() != mesh.num_vertices() {
                return Err(invalid(
                    "field",
                    format!(
                        "{} values for {} vertices",
                        values.len(),
                        mesh.num_vertices()
                    ),
                ));
            }
            if let Some(i) = values.iter().position(|x| !x.is_finite()) {
                return Err(invalid(
                    "field",
                    format!("the value of vertex {i} is {} (must be finite)", values[i]),
                ));
            }
            match mode {
                FieldMode::Value { reference } => {
                    if !reference.is_finite() {
                        return Err(invalid("reference", "must be finite"));
                    }
                    let lo = values.iter().copied().fold(f64::INFINITY, f64::min);
                    let hi = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
                    let span = if hi > lo { hi - lo } else { 1.0 };
                    let c = (reference - lo) / span;
                    Ok(values
                        .iter()
                        .map(|&f| ((f - lo) / span - c).abs().powf(power) + epsilon)
                        .collect())
                }
                FieldMode::Follow | FieldMode::Barrier => {
                    let g = gradient_norms(mesh, topo, values, control)?;
                    let max = g.iter().copied().fold(0.0, f64::max);
                    Ok(g.iter()
                        .map(|&x| {
                            let t = if max > 0.0 { x / max } else { 0.0 };
                            match mode {
                                FieldMode::Follow => 1.0 / (epsilon + t.powf(power)),
                                _ => epsilon + t.powf(power),
                            }
                        })
                        .collect())
                }
            }
        }
    }
}

/// The `q`-quantile of `x` (nearest rank), 0 for an empty slice.
fn percentile(x: &[f64], q: f64) -> f64 {
    if x.is_empty() {
        return 0.0;
    }
    let mut v = x.to_vec();
    let k = ((q * (v.len() - 1) as f64).round() as usize).min(v.len() - 1);
    let (_, kth, _) = v.select_nth_unstable_by(k, |a, b| a.total_cmp(b));
    *kth
}

/// `|∇_S f|` per vertex: the area-weighted mean over its faces of the norm
/// of the gradient of the linear interpolant, `∇f = Σ_k f_k (n × e_k) / 2A`
/// with `e_k` the edge opposite corner `k`.
pub fn gradient_norms(
    mesh: &TriMesh,
    topo: &Topology,
    f: &[f64],
    control: &Control<'_>,
) -> Result<Vec<f64>, MeshSolveError> {
    let per_face: Vec<(f64, f64)> = (0..mesh.num_faces() as u32)
        .map(|fi| match face_gradient(mesh, fi, f) {
            Some(g) => (norm(g), mesh.face_area(fi as usize)),
            None => (0.0, 0.0),
        })
        .collect();
    if control.is_cancelled() {
        return Err(MeshSolveError::Cancelled);
    }
    Ok((0..mesh.num_vertices())
        .map(|v| {
            let (mut s, mut a) = (0.0, 0.0);
            for &fi in topo.faces_of(v as u32) {
                let (g, area) = per_face[fi as usize];
                s += g * area;
                a += area;
            }
            if a > 0.0 {
                s / a
            } else {
                0.0
            }
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::numerics::mesh::paths::trace_path;
    use crate::numerics::mesh::{mesh_distance, MeshDistanceOptions, SurfacePoint};

    /// The sheet `z = −a sqrt(x² + δ²)` over `[−1, 1] × [0, 2]` (a roof
    /// folded along the ridge `x = 0`), `n × 2n` cells, faces
    /// counter-clockwise seen from above (normals up).
    fn folded_sheet(n: usize, a: f64, delta: f64) -> TriMesh {
        let (nx, ny) = (n, 2 * n);
        let mut pos = Vec::new();
        for i in 0..=ny {
            for j in 0..=nx {
                let x = -1.0 + 2.0 * j as f64 / nx as f64;
                let y = 2.0 * i as f64 / ny as f64;
                pos.push([x, y, -a * (x * x + delta * delta).sqrt()]);
            }
        }
        let id = |i: usize, j: usize| (i * (nx + 1) + j) as u32;
        let mut faces = Vec::new();
        for i in 0..ny {
            for j in 0..nx {
                let (p, q, r, s) = (id(i, j), id(i, j + 1), id(i + 1, j + 1), id(i + 1, j));
                faces.push([p, q, r]);
                faces.push([p, r, s]);
            }
        }
        TriMesh::new(pos, faces).unwrap()
    }

    fn nearest(mesh: &TriMesh, x: f64, y: f64) -> u32 {
        (0..mesh.num_vertices() as u32)
            .min_by(|&a, &b| {
                let d = |v: u32| {
                    let p = mesh.position(v);
                    (p[0] - x).powi(2) + (p[1] - y).powi(2)
                };
                d(a).total_cmp(&d(b))
            })
            .unwrap()
    }

    /// Issue 24: on a folded sheet, the minimal path of a ridge design
    /// follows the ridge within two mean edge lengths while the plain
    /// geodesic cuts across.
    #[test]
    fn a_ridge_design_follows_the_ridge() {
        let mesh = folded_sheet(40, 0.5, 0.02);
        let topo = Topology::new(&mesh);
        let mean_edge = mesh.mean_edge_length();
        let w = design(
            &mesh,
            &topo,
            &MeshDesign::Curvature {
                feature: CurvatureFeature::Ridges,
                epsilon: 0.01,
                power: 1.0,
                smoothing: 1,
            },
            &Control::new(),
        )
        .unwrap();
        let (s, e) = (nearest(&mesh, -0.6, 0.2), nearest(&mesh, 0.6, 1.8));
        let path_x = |weights: Option<&[f64]>| {
            let opts = MeshDistanceOptions {
                weights,
                ..Default::default()
            };
            let sources = [SurfacePoint::Vertex(s)];
            let d = mesh_distance(&mesh, &topo, &sources, &opts, None, &Control::new()).unwrap();
            let path =
                trace_path(&mesh, &topo, &d.distance, &sources, SurfacePoint::Vertex(e)).unwrap();
            assert_eq!(path.source, Some(0));
            // Largest |x| over the middle part of the path (0.6 <= y <= 1.4).
            path.points
                .iter()
                .filter(|p| (0.6..=1.4).contains(&p.position[1]))
                .map(|p| p.position[0].abs())
                .fold(0.0, f64::max)
        };
        let (designed, plain) = (path_x(Some(&w)), path_x(None));
        eprintln!("mean edge {mean_edge}: designed {designed}, plain {plain}");
        assert!(
            designed <= 2.0 * mean_edge,
            "designed path strays {designed}"
        );
        assert!(
            plain > 5.0 * mean_edge,
            "the plain geodesic cuts across: {plain}"
        );
    }

    #[test]
    fn a_valley_design_is_cheap_in_the_valley_only() {
        // The same sheet upside down is a valley along x = 0.
        let roof = folded_sheet(20, 0.5, 0.02);
        let pos: Vec<[f64; 3]> = roof
            .positions()
            .iter()
            .map(|p| [p[0], p[1], -p[2]])
            .collect();
        let valley = TriMesh::new(pos, roof.faces().to_vec()).unwrap();
        let topo = Topology::new(&valley);
        let cost = |feature| {
            let d = MeshDesign::Curvature {
                feature,
                epsilon: 0.01,
                power: 1.0,
                smoothing: 0,
            };
            design(&valley, &topo, &d, &Control::new()).unwrap()
        };
        let on = nearest(&valley, 0.0, 1.0) as usize;
        let off = nearest(&valley, -0.5, 1.0) as usize;
        let (v, r, b) = (
            cost(CurvatureFeature::Valleys),
            cost(CurvatureFeature::Ridges),
            cost(CurvatureFeature::Both),
        );
        assert!(v[on] < 1.1 && v[off] > 50.0, "valleys {} {}", v[on], v[off]);
        assert!(r[on] > 50.0, "no ridge here: {}", r[on]);
        assert!(b[on] < 1.1 && b[off] > 50.0);
    }

    #[test]
    fn field_edges_are_followed_or_barred() {
        let mesh = crate::numerics::mesh::shapes::flat_square(10, 1.0, 0.0);
        let topo = Topology::new(&mesh);
        // A step at x = 0.5.
        let f: Vec<f64> = mesh
            .positions()
            .iter()
            .map(|p| if p[0] > 0.5 { 1.0 } else { 0.0 })
            .collect();
        let run = |mode| {
            let d = MeshDesign::Field {
                values: &f,
                mode,
                epsilon: 0.01,
                power: 1.0,
            };
            design(&mesh, &topo, &d, &Control::new()).unwrap()
        };
        let (follow, barrier) = (run(FieldMode::Follow), run(FieldMode::Barrier));
        let on = nearest(&mesh, 0.5, 0.5) as usize;
        let off = nearest(&mesh, 0.1, 0.5) as usize;
        assert!(follow[on] < 2.0 && follow[off] > 99.0);
        assert!(barrier[on] > 0.5 && (barrier[off] - 0.01).abs() < 1e-12);
        let bad = MeshDesign::Field {
            values: &f[1..],
            mode: FieldMode::Follow,
            epsilon: 0.01,
            power: 1.0,
        };
        assert!(matches!(
            design(&mesh, &topo, &bad, &Control::new()),
            Err(MeshSolveError::InvalidOption {
                option: "field",
                ..
            })
        ));
    }
}
