//! Geodesic shape descriptors for retrieval (the monograph's §5.3: geodesic
//! distance distributions, eccentricity, canonical-form moments), invariant
//! to rigid motion, scale, bending and remeshing.
//!
//! From `k` farthest-point landmarks `l₁ … l_k` ([`super::matrix::landmarks`])
//! and their distance rows `d(lᵢ, v)` ([`super::matrix::distance_rows`]):
//!
//! * **Scale.** `D = maxᵢ,ᵥ d(lᵢ, v)`, the geodesic diameter estimated by the
//!   landmarks (the first landmark is the vertex farthest from vertex 0 and
//!   the second the vertex farthest from it: the double sweep, whose
//!   estimate is exact on trees and close on limbed shapes). Every length
//!   below is divided by `D`, so the descriptor does not change when the
//!   shape is scaled.
//! * **Area weights.** `a_v = Σ_{f ∋ v} |f| / 3`, normalised to `Σ a_v = 1`:
//!   a vertex stands for its share of the surface, so a finer triangulation
//!   of the same region does not weigh more (invariance to remeshing).
//! * **Distance distribution** (`B` bins on `[0, 1]`):
//!   `H_D[b] = (1/k) Σᵢ Σ_v a_v · [d(lᵢ, v)/D ∈ bin b]`: the distribution of
//!   the geodesic distance from a landmark to a random point of the surface.
//! * **Eccentricity** (`B` bins on `[0, 1]`): `e(v) = (1/k) Σᵢ d(lᵢ, v) / D`,
//!   the mean geodesic distance from `v` to the landmarks (an estimate of
//!   the mean distance to the whole surface), and
//!   `H_E[b] = Σ_v a_v · [e(v) ∈ bin b]`.
//! * **Canonical-form moments** (nine numbers): the landmark-MDS canonical
//!   form `x_v ∈ R³` of the same rows (Elad and Kimmel,
//!   [`super::canonical`]), its area-weighted centroid and covariance with
//!   eigenvalues `λ₁ ≥ λ₂ ≥ λ₃` and axes `e₁, e₂, e₃`, and `y_{v,j} = (x_v −
//!   x̄)·e_j`. The moments are `√λ_j / D` (the spread along each principal
//!   axis relative to the diameter), `s_j / (1 + s_j)` with the skewness
//!   magnitude `s_j = |Σ_v a_v y_{v,j}³| / λ_j^{3/2}` (the sign of an axis is
//!   arbitrary), and `(κ_j − 1)/(κ_j + 1)` with the kurtosis `κ_j = Σ_v a_v
//!   y_{v,j}⁴ / λ_j² ≥ 1`: nine numbers in `[0, 1]`, invariant to rigid
//!   motion (principal axes) and scale (divided by `D` or dimensionless).
//!
//! Histogram votes are split linearly between the two nearest bin centres,
//! so a value moving across a bin edge changes the histogram continuously.
//! Both histograms sum to 1.
//!
//! **Distance between descriptors** ([`descriptor_distance`]):
//! `δ = (χ²(H_D, H_D') + χ²(H_E, H_E') + L̄₁(M, M')) / 3` with
//! `χ²(p, q) = ½ Σ_b (p_b − q_b)² / (p_b + q_b)` (0 for two empty bins) and
//! `L̄₁` the mean absolute difference of the nine moments: each term lies in
//! `[0, 1]`, so `δ ∈ [0, 1]`, 0 for identical descriptors. Descriptors are
//! comparable only when computed with the same number of bins.

use ndarray::Array2;

use super::eigen::top_eigen;
use super::matrix::{distance_rows, landmarks, Symmetry};
use super::mds::landmark_mds;
use super::ShapeError;
use crate::numerics::mesh::{HeatSolver, MeshMethod, Topology, TriMesh};
use crate::numerics::Control;

/// Number of canonical-form moments in a descriptor.
pub const MOMENTS: usize = 9;

/// Options of [`descriptor`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DescriptorOptions {
    /// Farthest-point landmarks (at least 4: the canonical form is 3D).
    pub landmarks: usize,
    /// Bins of each histogram (at least 2).
    pub bins: usize,
    /// The distance method.
    pub method: MeshMethod,
}

impl Default for DescriptorOptions {
    fn default() -> Self {
        Self {
            landmarks: 32,
            bins: 32,
            method: MeshMethod::FastMarching,
        }
    }
}

/// A shape descriptor (see the module docs for each block).
#[derive(Debug, Clone, PartialEq)]
pub struct Descriptor {
    /// `H_D`: the geodesic distance distribution, `bins` values summing to 1.
    pub distances: Vec<f64>,
    /// `H_E`: the eccentricity histogram, `bins` values summing to 1.
    pub eccentricity: Vec<f64>,
    /// The [`MOMENTS`] canonical-form moments, each in `[0, 1]`.
    pub moments: Vec<f64>,
    /// `D`, the estimated geodesic diameter (in the mesh's units).
    pub diameter: f64,
    /// The surface area (in the mesh's units squared).
    pub area: f64,
    /// The landmarks used.
    pub landmarks: Vec<u32>,
}

impl Descriptor {
    /// The blocks one after the other: `H_D`, `H_E`, the moments
    /// (`2·bins + 9` values).
    pub fn to_vector(&self) -> Vec<f64> {
        let mut v = Vec::with_capacity(self.distances.len() * 2 + self.moments.len());
        v.extend_from_slice(&self.distances);
        v.extend_from_slice(&self.eccentricity);
        v.extend_from_slice(&self.moments);
        v
    }

    /// Splits a vector of [`Descriptor::to_vector`] back into its blocks
    /// (diameter, area and landmarks are not part of it: 0 and empty).
    pub fn from_vector(values: &[f64]) -> Result<Self, ShapeError> {
        let n = values.len();
        if n < 2 * 2 + MOMENTS || !(n - MOMENTS).is_multiple_of(2) {
            return Err(ShapeError::InvalidOption {
                option: "descriptor",
                reason: format!("{n} values are not 2·bins + {MOMENTS} with bins >= 2"),
            });
        }
        if values.iter().any(|x| !x.is_finite()) {
            return Err(ShapeError::InvalidOption {
                option: "descriptor",
                reason: "a value is not finite".into(),
            });
        }
        let bins = (n - MOMENTS) / 2;
        Ok(Descriptor {
            distances: values[..bins].to_vec(),
            eccentricity: values[bins..2 * bins].to_vec(),
            moments: values[2 * bins..].to_vec(),
            diameter: 0.0,
            area: 0.0,
            landmarks: Vec::new(),
        })
    }

    /// Bins of each histogram.
    pub fn bins(&self) -> usize {
        self.distances.len()
    }
}

/// `½ Σ (p − q)² / (p + q)`, in `[0, 1]` for two distributions.
fn chi2(p: &[f64], q: &[f64]) -> f64 {
    0.5 * p
        .iter()
        .zip(q)
        .map(|(a, b)| {
            let s = a + b;
            if s > 0.0 {
                (a - b) * (a - b) / s
            } else {
                0.0
            }
        })
        .sum::<f64>()
}

/// The distance `δ ∈ [0, 1]` between two descriptors (see the module docs);
/// refused when their bin counts differ.
pub fn descriptor_distance(a: &Descriptor, b: &Descriptor) -> Result<f64, ShapeError> {
    if a.bins() != b.bins() || a.moments.len() != b.moments.len() {
        return Err(ShapeError::InvalidOption {
            option: "bins",
            reason: format!(
                "descriptors of {} and {} bins cannot be compared: compute both with the same bins",
                a.bins(),
                b.bins()
            ),
        });
    }
    let m = a
        .moments
        .iter()
        .zip(&b.moments)
        .map(|(x, y)| (x - y).abs())
        .sum::<f64>()
        / a.moments.len().max(1) as f64;
    Ok((chi2(&a.distances, &b.distances) + chi2(&a.eccentricity, &b.eccentricity) + m) / 3.0)
}

/// `a_v = Σ_{f ∋ v} |f| / 3` and the total area.
pub fn vertex_areas(mesh: &TriMesh) -> (Vec<f64>, f64) {
    let mut a = vec![0.0; mesh.num_vertices()];
    let mut total = 0.0;
    for (f, face) in mesh.faces().iter().enumerate() {
        let s = mesh.face_area(f);
        total += s;
        for &v in face {
            a[v as usize] += s / 3.0;
        }
    }
    (a, total)
}

/// Adds `weight` to `hist` at `x ∈ [0, 1]`, split linearly between the two
/// nearest bin centres (clamped at the ends).
fn vote(hist: &mut [f64], x: f64, weight: f64) {
    let bins = hist.len();
    let pos = (x.clamp(0.0, 1.0) * bins as f64 - 0.5).clamp(0.0, (bins - 1) as f64);
    let lo = pos.floor() as usize;
    let frac = pos - lo as f64;
    hist[lo] += weight * (1.0 - frac);
    if lo + 1 < bins {
        hist[lo + 1] += weight * frac;
    }
}

fn normalise(hist: &mut [f64]) {
    let s: f64 = hist.iter().sum();
    if s > 0.0 {
        hist.iter_mut().for_each(|h| *h /= s);
    }
}

/// The descriptor of `mesh` (see the module docs). A disconnected mesh is
/// refused. `heat` may hand in the mesh's prefactored heat solver.
pub fn descriptor(
    mesh: &TriMesh,
    topo: &Topology,
    options: &DescriptorOptions,
    heat: Option<&HeatSolver>,
    control: &Control<'_>,
) -> Result<Descriptor, ShapeError> {
    if options.landmarks < 4 {
        return Err(ShapeError::InvalidOption {
            option: "landmarks",
            reason: format!(
                "at least 4 landmarks are needed for a 3D canonical form, got {}",
                options.landmarks
            ),
        });
    }
    if options.bins < 2 {
        return Err(ShapeError::InvalidOption {
            option: "bins",
            reason: format!("at least 2 bins are needed, got {}", options.bins),
        });
    }
    if topo.components > 1 {
        return Err(ShapeError::Disconnected {
            what: "mesh",
            components: topo.components,
            hint: "describe each component on its own (split the mesh, drop unused vertices)",
        });
    }
    let n = mesh.num_vertices();
    if n < 4 {
        return Err(ShapeError::InvalidOption {
            option: "mesh",
            reason: format!("{n} vertices cannot be described: at least 4 are needed"),
        });
    }
    let inner = control.cancel_only();
    let lms = landmarks(mesh, topo, options.landmarks.min(n), &inner)?;
    let rows = distance_rows(
        mesh,
        topo,
        &lms,
        options.method,
        heat,
        Symmetry::Average,
        control,
    )?;
    if control.is_cancelled() {
        return Err(ShapeError::Cancelled);
    }
    let d = &rows.rows;
    let k = lms.len();
    let diameter = d
        .iter()
        .copied()
        .filter(|x| x.is_finite())
        .fold(0.0, f64::max);
    if diameter <= 0.0 {
        return Err(ShapeError::Numerical(
            "the mesh has zero geodesic diameter".into(),
        ));
    }
    let (mut area, total) = vertex_areas(mesh);
    if total <= 0.0 || !total.is_finite() {
        return Err(ShapeError::InvalidOption {
            option: "mesh",
            reason: "the mesh has zero area".into(),
        });
    }
    area.iter_mut().for_each(|a| *a /= total);

    let bins = options.bins;
    let mut h_d = vec![0.0; bins];
    let mut h_e = vec![0.0; bins];
    for (v, &a) in area.iter().enumerate() {
        let mut sum = 0.0;
        for i in 0..k {
            let x = d[[i, v]] / diameter;
            vote(&mut h_d, x, a / k as f64);
            sum += x;
        }
        vote(&mut h_e, sum / k as f64, a);
    }
    normalise(&mut h_d);
    normalise(&mut h_e);

    let moments = if k > 3 {
        let cols: Vec<usize> = lms.iter().map(|&v| v as usize).collect();
        let e = landmark_mds(d.view(), &cols, 3, &inner)?;
        canonical_moments(&e.coords, &area, diameter, &inner)?
    } else {
        // Fewer than four vertices reached by the sampling (a tiny mesh):
        // no 3D canonical form.
        vec![0.0; MOMENTS]
    };
    control.report(1.0);
    Ok(Descriptor {
        distances: h_d,
        eccentricity: h_e,
        moments,
        diameter,
        area: total,
        landmarks: lms,
    })
}

/// The nine moments of the module docs from the `n × 3` embedded points and
/// the normalised vertex areas.
fn canonical_moments(
    x: &Array2<f64>,
    area: &[f64],
    diameter: f64,
    control: &Control<'_>,
) -> Result<Vec<f64>, ShapeError> {
    let point = |row: ndarray::ArrayView1<'_, f64>| [row[0], row[1], row[2]];
    let mut mean = [0.0; 3];
    for (row, &a) in x.rows().into_iter().zip(area) {
        let p = point(row);
        mean = [mean[0] + a * p[0], mean[1] + a * p[1], mean[2] + a * p[2]];
    }
    let centred: Vec<[f64; 3]> = x
        .rows()
        .into_iter()
        .map(|row| {
            let p = point(row);
            [p[0] - mean[0], p[1] - mean[1], p[2] - mean[2]]
        })
        .collect();
    let cov = Array2::from_shape_fn((3, 3), |(i, j)| {
        centred
            .iter()
            .zip(area)
            .map(|(c, &a)| a * c[i] * c[j])
            .sum::<f64>()
    });
    let top = top_eigen(cov.view(), 3, control)?;
    let mut spreads = Vec::with_capacity(3);
    let mut skew = Vec::with_capacity(3);
    let mut kurt = Vec::with_capacity(3);
    for (j, &value) in top.values.iter().enumerate().take(3) {
        let l = value.max(0.0);
        spreads.push(l.sqrt() / diameter);
        if l <= f64::MIN_POSITIVE {
            skew.push(0.0);
            kurt.push(0.0);
            continue;
        }
        let axis = top.vectors.column(j);
        let (mut m3, mut m4) = (0.0, 0.0);
        for (c, &a) in centred.iter().zip(area) {
            let y = c[0] * axis[0] + c[1] * axis[1] + c[2] * axis[2];
            m3 += a * y * y * y;
            m4 += a * y * y * y * y;
        }
        let s = m3.abs() / l.powf(1.5);
        let kappa = (m4 / (l * l)).max(1.0);
        skew.push(s / (1.0 + s));
        kurt.push((kappa - 1.0) / (kappa + 1.0));
    }
    let mut out = spreads;
    out.extend(skew);
    out.extend(kurt);
    out.resize(MOMENTS, 0.0);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::numerics::mesh::shapes::{icosphere, torus};

    fn moved(mesh: &TriMesh, scale: f64) -> TriMesh {
        // A rotation about z by 0.7 rad, a scale and a shift.
        let (s, c) = 0.7f64.sin_cos();
        let p = mesh
            .positions()
            .iter()
            .map(|q| {
                [
                    scale * (c * q[0] - s * q[1]) + 3.0,
                    scale * (s * q[0] + c * q[1]) - 1.0,
                    scale * q[2] + 2.0,
                ]
            })
            .collect();
        TriMesh::new(p, mesh.faces().to_vec()).unwrap()
    }

    #[test]
    fn histograms_sum_to_one_and_invariance_to_rigid_motion_and_scale() {
        let m = torus(24, 12, 1.0, 0.35);
        let options = DescriptorOptions {
            landmarks: 16,
            bins: 16,
            ..Default::default()
        };
        let a = descriptor(&m, &Topology::new(&m), &options, None, &Control::new()).unwrap();
        assert_eq!(a.distances.len(), 16);
        assert!((a.distances.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        assert!((a.eccentricity.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        assert_eq!(a.moments.len(), MOMENTS);
        assert!(a.moments.iter().all(|x| (0.0..=1.0).contains(x)));
        let b = moved(&m, 3.5);
        let db = descriptor(&b, &Topology::new(&b), &options, None, &Control::new()).unwrap();
        assert!((db.diameter / a.diameter - 3.5).abs() < 1e-9);
        // Not 0: on a torus the farthest-point sampling meets exact ties,
        // which rounding after the motion breaks differently (other
        // landmarks, the same statistics). Measured 0.004; two different
        // shapes are over 0.1 apart (next test).
        let delta = descriptor_distance(&a, &db).unwrap();
        assert!(delta < 0.01, "{delta}");
        assert_eq!(descriptor_distance(&a, &a).unwrap(), 0.0);
        // The vector round trip keeps the blocks.
        let back = Descriptor::from_vector(&a.to_vector()).unwrap();
        assert_eq!(descriptor_distance(&a, &back).unwrap(), 0.0);
        assert!(Descriptor::from_vector(&[0.0; 10]).is_err());
    }

    #[test]
    fn a_sphere_and_a_torus_differ_more_than_two_spheres() {
        let options = DescriptorOptions {
            landmarks: 16,
            bins: 16,
            ..Default::default()
        };
        let d = |m: &TriMesh| {
            descriptor(m, &Topology::new(m), &options, None, &Control::new()).unwrap()
        };
        let (s2, s3, t) = (
            icosphere(2, 1.0),
            icosphere(3, 2.0),
            torus(24, 12, 1.0, 0.35),
        );
        let (a, b, c) = (d(&s2), d(&s3), d(&t));
        let same = descriptor_distance(&a, &b).unwrap();
        let other = descriptor_distance(&a, &c).unwrap();
        assert!(same < 0.3 * other, "{same} vs {other}");
    }

    #[test]
    fn refusals_name_the_option_and_cancel_stops() {
        let m = icosphere(2, 1.0);
        let topo = Topology::new(&m);
        for (o, name) in [
            (
                DescriptorOptions {
                    landmarks: 3,
                    ..Default::default()
                },
                "landmarks",
            ),
            (
                DescriptorOptions {
                    bins: 1,
                    ..Default::default()
                },
                "bins",
            ),
        ] {
            match descriptor(&m, &topo, &o, None, &Control::new()) {
                Err(ShapeError::InvalidOption { option, .. }) => assert_eq!(option, name),
                other => panic!("{other:?}"),
            }
        }
        let flag = std::sync::atomic::AtomicBool::new(true);
        let c = Control::new().with_cancel(&flag);
        assert_eq!(
            descriptor(&m, &topo, &DescriptorOptions::default(), None, &c),
            Err(ShapeError::Cancelled)
        );
        let a = Descriptor::from_vector(&[0.5; 2 * 4 + MOMENTS]).unwrap();
        let b = Descriptor::from_vector(&[0.5; 2 * 5 + MOMENTS]).unwrap();
        assert!(descriptor_distance(&a, &b).is_err());
    }
}
