//! Image meshing (the monograph's section 4.3; Bougleux, Peyré and Cohen,
//! "Anisotropic geodesics for perceptual grouping and domain meshing", 2008).
//!
//! # Math
//!
//! An image `f` on a 2D grid gets an isotropic metric that is large where
//! `f` varies:
//!
//! ```text
//! W(x) = 1 + α · q(x) / max q,   q = |∇(G_σ * f)|   (gradient)
//!                                q = ‖H(G_σ * f)‖_F (Hessian)
//! ```
//!
//! Farthest-point sampling under `W` places about `∝ W²` samples per unit
//! area (the covering radius is uniform in the metric), so vertices gather
//! along edges (gradient) or where the image bends (Hessian, the term that
//! bounds the linear interpolation error `|f − f̃| ≤ ‖H‖ h² / 2`). The
//! vertices are triangulated by the conforming geodesic Delaunay dual
//! ([`crate::numerics::sampling::delaunay`]: corners and border samples
//! included, so the triangles tile the rectangle `[0, n0−1] × [0, n1−1]`),
//! and `f̃` is the linear interpolation of the vertex values `f(s_i)` on
//! each triangle (barycentric coordinates). The error reported is the root
//! mean square `‖f − f̃‖₂ = (Σ_x (f − f̃)² / n)^{1/2}` over the grid cells.
//!
//! The uniform metric (`W = 1`) gives the mesh of the same vertex count to
//! compare with.
//!
//! With [`ImageMeshOptions::flips`] the dual is then improved by
//! data-dependent edge flips ([`super::image_flips`]): same vertices, a
//! triangulation whose interpolant has a lower L2 error. With
//! [`ImageMeshOptions::moves`] the vertices move too ([`super::image_moves`]:
//! a pattern search over grid cells, each move lowering that error, with
//! the flips between sweeps).
//!
//! # Anisotropic metrics
//!
//! An isotropic metric can only make triangles smaller; along an edge or a
//! ridge they should also be long and thin. Two Riemannian metrics `M(x)`
//! are sampled with the tensor farthest-point sampler
//! ([`crate::numerics::sampling::tensor_farthest`]) and triangulated by the
//! same conforming geodesic Delaunay dual
//! ([`crate::numerics::sampling::delaunay::geodesic_delaunay_tensor`]):
//!
//! * **Hessian** ([`ImageMetric::HessianTensor`], Bougleux, Peyré & Cohen
//!   2008 after the anisotropic-mesh literature): the error of linear
//!   interpolation on a triangle with edges `e` is about `eᵀ|H|e / 2`, with
//!   `|H| = R diag(|λ1|, |λ2|) Rᵀ` the absolute Hessian of `G_σ * f`. A
//!   triangle of unit size in `|H|` has an error of order 1 and an area of
//!   `det|H|^{-1/2}`; minimising the `L^p` error for a given number of
//!   vertices equidistributes `|e|^p · area` and gives
//!   `M = det(|H|)^{-1/(2p+2)} |H|`, i.e. `det(|H|)^{-1/6} |H|` for the
//!   `L²` norm. `|H|` is regularised first: each `|λ_k|` is raised to at
//!   least `Λ / strength` (`Λ` the largest `|λ|` over the image: flat regions
//!   keep a finite size) and the smaller to at least the larger over
//!   `anisotropy²` (elements at most `anisotropy` times longer than wide).
//! * **Structure tensor** ([`ImageMetric::StructureTensor`]):
//!   `J = G_ρ * (∇f_σ ∇f_σᵀ)` is large across edges and small along them;
//!   `M = Id + strength · J / μ_max` (`μ_max` the largest eigenvalue of `J`
//!   over the image), with the same cap on the anisotropy.
//! * **Edge tensor** ([`ImageMetric::EdgeTensor`]): the gradient metric's
//!   density with the structure tensor's directions,
//!   `M = W² R diag(a, 1/a) Rᵀ`, `W = 1 + α |∇f_σ| / max` as in
//!   [`ImageMetric::Gradient`], `R` the eigenvectors of `J_ρ` (across the
//!   edge first) and `a = 1 + (A − 1) c` with the coherence
//!   `c = (μ1 − μ2) / (μ1 + μ2)` of `J_ρ`. `det M = W⁴`, so the vertices
//!   have the gradient mesh's density (`det(M)^{1/4} = W`) and only the
//!   shape changes: elements `a` times longer than wide along coherent
//!   edges, isotropic in flat or textured regions (`c ≈ 0`). It isolates
//!   what anisotropy buys: on `camera` (512², 2,000 vertices) its error is
//!   6-11 % below the isotropic meshes' at the same `α`
//!   (`tests/bench/README.md`). Ratios above about 2 fold the dual where
//!   the edges turn, and the repair then adds many samples.
//!
//! The `cost` reported for a tensor metric is `det(M)^{1/4}`: the isotropic
//! cost with the same density of vertices (`∝ sqrt(det M)` per unit area).

use std::borrow::Cow;

use super::image_flips::flip_to_image;
use super::image_moves::move_to_image;
use crate::numerics::anisotropic::structure_tensor::structure_tensor;
use crate::numerics::anisotropic::{TensorError, TensorField};
use crate::numerics::control::Control;
use crate::numerics::filters::{self, FilterError};
use crate::numerics::grid::Grid;
use crate::numerics::metric::{CostValues, Interpretation, IsotropicCost, MetricError};
use crate::numerics::sampling::delaunay::{
    geodesic_delaunay, geodesic_delaunay_tensor, DelaunayError, DelaunayOptions, RepairCounts,
};
use crate::numerics::sampling::{
    farthest_point_sampling, tensor_farthest_point_sampling, SamplingError, SamplingMethod,
    SamplingOptions,
};

/// The metric derived from the image.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ImageMetric {
    /// `W = 1`: a uniform mesh.
    Uniform,
    /// `W = 1 + α |∇(G_σ * f)| / max`.
    Gradient {
        /// Smoothing scale `σ` (physical units), `>= 0`.
        sigma: f64,
        /// Contrast `α >= 0`: the ratio of the largest to the smallest `W`, minus 1.
        strength: f64,
    },
    /// `W = 1 + α ‖H(G_σ * f)‖_F / max`.
    Hessian {
        /// Smoothing scale `σ` (physical units), `>= 0`.
        sigma: f64,
        /// Contrast `α >= 0`.
        strength: f64,
    },
    /// Anisotropic: `M = det(|H_ε|)^{-1/6} |H_ε|`, the `L²`-optimal metric of
    /// the regularised absolute Hessian (see the module docs).
    HessianTensor {
        /// Smoothing scale `σ` (physical units), `>= 0`.
        sigma: f64,
        /// Ratio of the largest `|λ|` to the floor of every `|λ|`, `>= 1`.
        strength: f64,
        /// Largest ratio of an element's length to its width, `>= 1`.
        anisotropy: f64,
    },
    /// Anisotropic: `M = Id + strength · J / μ_max`, `J` the structure tensor.
    StructureTensor {
        /// Noise scale `σ` of the gradient (physical units), `>= 0`.
        sigma: f64,
        /// Integration scale `ρ` (physical units), `>= 0`.
        rho: f64,
        /// Contrast `>= 0`.
        strength: f64,
        /// Largest ratio of an element's length to its width, `>= 1`.
        anisotropy: f64,
    },
    /// Anisotropic with the gradient metric's density:
    /// `M = W² R diag(a, 1/a) Rᵀ`, `W` as in [`ImageMetric::Gradient`], `R`
    /// the eigenvectors of the structure tensor `J_ρ` (across the edge
    /// first) and `a = 1 + (anisotropy − 1) c`, `c` the coherence of `J_ρ`.
    EdgeTensor {
        /// Noise scale `σ` of the gradient (physical units), `>= 0`.
        sigma: f64,
        /// Integration scale `ρ` of the structure tensor (physical units), `>= 0`.
        rho: f64,
        /// Contrast `α >= 0` of `W`.
        strength: f64,
        /// Element length-to-width ratio where the image has one direction, `>= 1`.
        anisotropy: f64,
    },
}

/// Options of [`mesh_image`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImageMeshOptions {
    /// Target number of vertices (at least 4: the corners).
    pub count: usize,
    /// The metric.
    pub metric: ImageMetric,
    /// After the Delaunay dual, flip edges while that lowers the L2 error
    /// ([`super::image_flips`]): a data-dependent triangulation of the same
    /// vertices.
    pub flips: bool,
    /// After the dual, move vertices to grid cells near them and flip
    /// edges while that lowers the L2 error ([`super::image_moves`]; implies
    /// the flips): the same vertex count, placed by the image itself.
    pub moves: bool,
}

/// A mesh of an image and the image's approximation on it.
#[derive(Debug, Clone, PartialEq)]
pub struct ImageMesh {
    /// Vertices in index coordinates (axis 0 first): grid cells.
    pub points: Vec<[f64; 2]>,
    /// Triangles, counter-clockwise in the (axis 0, axis 1) plane.
    pub triangles: Vec<[u32; 3]>,
    /// The image at each vertex.
    pub values: Vec<f64>,
    /// The piecewise-linear approximation `f̃` per grid cell (C order).
    pub approximation: Vec<f64>,
    /// `‖f − f̃‖₂` (root mean square over the grid cells).
    pub l2_error: f64,
    /// The metric `W` per grid cell.
    pub cost: Vec<f64>,
    /// Samples the Delaunay repair added (to the sampling's count).
    pub added: usize,
    /// Defects repaired, by kind.
    pub repaired: RepairCounts,
    /// The covering radius of the samples in the metric.
    pub covering_radius: f64,
    /// Edges flipped to lower the error (0 without `flips` or `moves`).
    pub flips: usize,
    /// Vertex moves that lowered the error (0 without `moves`).
    pub moves: usize,
}

/// Why an image could not be meshed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MeshingError {
    /// The grid is not 2D.
    #[error("image meshing is defined on 2D grids; this grid has {0} axes")]
    NotPlanar(usize),
    /// The image does not match the grid, or has a non-finite value.
    #[error("{0}")]
    Image(String),
    /// The count is below 4 or above the number of cells.
    #[error("count {count} must be between 4 and the number of cells ({cells})")]
    Count {
        /// The count given.
        count: usize,
        /// Cells of the grid.
        cells: usize,
    },
    /// A metric parameter is out of range.
    #[error("{0}")]
    Metric(String),
    /// Sampling failed.
    #[error(transparent)]
    Sampling(#[from] SamplingError),
    /// The triangulation could not be repaired.
    #[error(transparent)]
    Delaunay(#[from] DelaunayError),
    /// The caller raised the cancel flag.
    #[error("cancelled")]
    Cancelled,
}

impl From<FilterError> for MeshingError {
    fn from(e: FilterError) -> Self {
        match e {
            FilterError::Cancelled => MeshingError::Cancelled,
            other => MeshingError::Metric(other.to_string()),
        }
    }
}

impl From<MetricError> for MeshingError {
    fn from(e: MetricError) -> Self {
        MeshingError::Metric(e.to_string())
    }
}

/// The metric `W` of `image` (see the module docs), one value per cell.
pub fn image_cost(
    grid: &Grid,
    image: &[f64],
    metric: ImageMetric,
    control: &Control<'_>,
) -> Result<Vec<f64>, MeshingError> {
    let (sigma, strength, hessian) = match metric {
        ImageMetric::Uniform => return Ok(vec![1.0; grid.len()]),
        ImageMetric::HessianTensor { .. }
        | ImageMetric::StructureTensor { .. }
        | ImageMetric::EdgeTensor { .. } => {
            let t = image_tensor(grid, image, metric, control)?;
            return Ok(tensor_density(grid, t.as_ref()));
        }
        ImageMetric::Gradient { sigma, strength } => (sigma, strength, false),
        ImageMetric::Hessian { sigma, strength } => (sigma, strength, true),
    };
    if !(strength.is_finite() && strength >= 0.0) {
        return Err(MeshingError::Metric(format!(
            "strength {strength} must be finite and >= 0"
        )));
    }
    let smooth = filters::gaussian_smooth(grid, image, sigma, control)?;
    let q: Vec<f64> = if hessian {
        filters::hessian(grid, &smooth, control)?
            .iter()
            .map(|h| (h[1] * h[1] + h[2] * h[2] + 2.0 * h[5] * h[5]).sqrt())
            .collect()
    } else {
        filters::gradient(grid, &smooth, control)?
            .iter()
            .map(|g| (g[1] * g[1] + g[2] * g[2]).sqrt())
            .collect()
    };
    let max = q.iter().copied().fold(0.0, f64::max);
    if max <= 0.0 {
        return Ok(vec![1.0; grid.len()]);
    }
    Ok(q.iter().map(|v| 1.0 + strength * v / max).collect())
}

/// `det(M)^{1/4}` per cell (1 without a field): the isotropic cost with the
/// same vertex density as the tensor `M`.
fn tensor_density(grid: &Grid, t: Option<&TensorField>) -> Vec<f64> {
    match t {
        None => vec![1.0; grid.len()],
        Some(t) => (0..grid.len())
            .map(|i| {
                let m = t.at(i);
                (m[0] * m[2] - m[1] * m[1]).max(0.0).powf(0.25)
            })
            .collect(),
    }
}

/// The symmetric 2×2 matrix `R diag(μ1, μ2) Rᵀ` with the leading
/// eigenvector at angle `phi` (axis 0 first), as `[m00, m01, m11]`.
fn from_eigen(mu1: f64, mu2: f64, phi: f64) -> [f64; 3] {
    let (c, s) = (phi.cos(), phi.sin());
    [
        mu1 * c * c + mu2 * s * s,
        (mu1 - mu2) * c * s,
        mu1 * s * s + mu2 * c * c,
    ]
}

/// Eigenvalues (larger first) and the angle of the leading eigenvector of
/// the symmetric `[a, b; b, c]`.
fn eigen2(a: f64, b: f64, c: f64) -> (f64, f64, f64) {
    let mean = 0.5 * (a + c);
    let d = (0.25 * (a - c) * (a - c) + b * b).sqrt();
    (mean + d, mean - d, 0.5 * (2.0 * b).atan2(a - c))
}

/// The anisotropic metric of `image` for [`ImageMetric::HessianTensor`] and
/// [`ImageMetric::StructureTensor`] (see the module docs); `None` for the
/// isotropic metrics.
pub fn image_tensor(
    grid: &Grid,
    image: &[f64],
    metric: ImageMetric,
    control: &Control<'_>,
) -> Result<Option<TensorField>, MeshingError> {
    let check = |name: &str, v: f64, min: f64| {
        if v.is_finite() && v >= min {
            Ok(())
        } else {
            Err(MeshingError::Metric(format!(
                "{name} {v} must be finite and >= {min}"
            )))
        }
    };
    let comps: Vec<f64> = match metric {
        ImageMetric::Uniform | ImageMetric::Gradient { .. } | ImageMetric::Hessian { .. } => {
            return Ok(None)
        }
        ImageMetric::HessianTensor {
            sigma,
            strength,
            anisotropy,
        } => {
            check("strength", strength, 1.0)?;
            check("anisotropy", anisotropy, 1.0)?;
            let smooth = filters::gaussian_smooth(grid, image, sigma, control)?;
            let h = filters::hessian(grid, &smooth, control)?;
            // |λ| per cell, larger first, and the leading direction.
            let eig: Vec<(f64, f64, f64)> = h
                .iter()
                .map(|h| {
                    let (l1, l2, phi) = eigen2(h[1], h[5], h[2]);
                    if l1.abs() >= l2.abs() {
                        (l1.abs(), l2.abs(), phi)
                    } else {
                        (l2.abs(), l1.abs(), phi + std::f64::consts::FRAC_PI_2)
                    }
                })
                .collect();
            let top = eig.iter().map(|e| e.0).fold(0.0, f64::max);
            if top <= 0.0 {
                return Ok(Some(TensorField::constant(grid, &[1.0, 0.0, 1.0])?));
            }
            let floor = top / strength;
            let cap = anisotropy * anisotropy;
            let mut out = Vec::with_capacity(3 * grid.len());
            for &(a, b, phi) in &eig {
                let mu1 = a.max(floor);
                let mu2 = b.max(floor).max(mu1 / cap);
                // det(|H|)^{-1/6} |H|, scaled by the floor so values stay near 1.
                let scale = ((mu1 / floor) * (mu2 / floor)).powf(-1.0 / 6.0) / floor;
                out.extend(from_eigen(mu1 * scale, mu2 * scale, phi));
            }
            out
        }
        ImageMetric::StructureTensor {
            sigma,
            rho,
            strength,
            anisotropy,
        } => {
            check("strength", strength, 0.0)?;
            check("anisotropy", anisotropy, 1.0)?;
            let j = structure_tensor(grid, image, sigma, rho, control).map_err(tensor_error)?;
            let eig: Vec<(f64, f64, f64)> = j
                .chunks_exact(3)
                .map(|m| eigen2(m[0], m[1], m[2]))
                .collect();
            let top = eig.iter().map(|e| e.0).fold(0.0, f64::max);
            let cap = anisotropy * anisotropy;
            let mut out = Vec::with_capacity(3 * grid.len());
            for &(a, b, phi) in &eig {
                let (mu1, mu2) = if top > 0.0 {
                    (
                        1.0 + strength * a.max(0.0) / top,
                        1.0 + strength * b.max(0.0) / top,
                    )
                } else {
                    (1.0, 1.0)
                };
                out.extend(from_eigen(mu1, mu2.max(mu1 / cap), phi));
            }
            out
        }
        ImageMetric::EdgeTensor {
            sigma,
            rho,
            strength,
            anisotropy,
        } => {
            check("anisotropy", anisotropy, 1.0)?;
            let w = image_cost(
                grid,
                image,
                ImageMetric::Gradient { sigma, strength },
                control,
            )?;
            let j = structure_tensor(grid, image, sigma, rho, control).map_err(tensor_error)?;
            let mut out = Vec::with_capacity(3 * grid.len());
            for (m, w) in j.chunks_exact(3).zip(&w) {
                let (a, b, phi) = eigen2(m[0], m[1], m[2]);
                let total = a.max(0.0) + b.max(0.0);
                let coherence = if total > 0.0 {
                    ((a - b) / total).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                let ratio = 1.0 + (anisotropy - 1.0) * coherence;
                out.extend(from_eigen(w * w * ratio, w * w / ratio, phi));
            }
            out
        }
    };
    Ok(Some(TensorField::from_components(grid, comps)?))
}

fn tensor_error(e: TensorError) -> MeshingError {
    match e {
        TensorError::Cancelled => MeshingError::Cancelled,
        other => MeshingError::Metric(other.to_string()),
    }
}

impl From<TensorError> for MeshingError {
    fn from(e: TensorError) -> Self {
        tensor_error(e)
    }
}

/// Meshes `image` (one value per cell of the 2D `grid`, C order) with about
/// `options.count` vertices; see the module docs. The repair of the
/// triangulation adds samples (on the border, and where the metric turns
/// fast); the sampling is then run again with fewer samples (at most five
/// more times, interpolating the vertex count between requests), keeping
/// the mesh whose vertex count is closest to the target.
///
/// Polls `control` throughout (filters, sampling, repair).
pub fn mesh_image(
    grid: &Grid,
    image: &[f64],
    options: &ImageMeshOptions,
    control: &Control<'_>,
) -> Result<ImageMesh, MeshingError> {
    if grid.ndim() != 2 {
        return Err(MeshingError::NotPlanar(grid.ndim()));
    }
    let n = grid.len();
    if image.len() != n {
        return Err(MeshingError::Image(format!(
            "{} values for a grid of {n} cells",
            image.len()
        )));
    }
    if let Some(i) = image.iter().position(|v| !v.is_finite()) {
        return Err(MeshingError::Image(format!("value {i} is not finite")));
    }
    if options.count < 4 || options.count > n {
        return Err(MeshingError::Count {
            count: options.count,
            cells: n,
        });
    }
    let [_, n0, n1] = grid.shape3();
    let tensor = image_tensor(grid, image, options.metric, control)?;
    let w = match &tensor {
        Some(t) => tensor_density(grid, Some(t)),
        None => image_cost(grid, image, options.metric, control)?,
    };
    let cost = IsotropicCost::new(
        grid,
        CostValues::F64(Cow::Borrowed(&w)),
        Interpretation::Cost,
        None,
    )?;
    let corners = vec![
        vec![0, 0],
        vec![0, n1 - 1],
        vec![n0 - 1, 0],
        vec![n0 - 1, n1 - 1],
    ];
    let run = |count: usize| {
        let sampling_options = SamplingOptions {
            count: Some(count.max(4)),
            radius: None,
            seeds: corners.clone(),
            method: SamplingMethod::Exact,
        };
        let options = DelaunayOptions {
            conforming: true,
            max_added: None,
        };
        Ok::<_, MeshingError>(match &tensor {
            None => {
                let sampling = farthest_point_sampling(grid, &cost, &sampling_options, control)?;
                geodesic_delaunay(grid, &cost, sampling, &options, control)?
            }
            Some(t) => {
                let sampling = tensor_farthest_point_sampling(grid, t, &sampling_options, control)?;
                geodesic_delaunay_tensor(grid, t, sampling, &options, control)?
            }
        })
    };
    // The repair adds samples: sample fewer so that the vertex count lands
    // near the target. The first retry asks for `count − added`; further
    // ones interpolate linearly between the closest requests that gave too
    // few and too many vertices (or extrapolate from the last two), at most
    // five retries in all, until the count is within 2 % of the target.
    let target = options.count;
    let off = |x: usize| x.abs_diff(target);
    let mut d = run(target)?;
    let mut tried = vec![(target, d.points.len())];
    let mut request = target.saturating_sub(d.added);
    while d.added > 0
        && tried.len() <= 5
        && off(d.points.len()) > (target / 50).max(2)
        && request >= 4
        && tried.iter().all(|&(r, _)| r != request)
    {
        let next = run(request)?;
        tried.push((request, next.points.len()));
        if off(next.points.len()) < off(d.points.len()) {
            d = next;
        }
        let below = tried
            .iter()
            .filter(|&&(_, v)| v < target)
            .max_by_key(|&&(_, v)| v);
        let above = tried
            .iter()
            .filter(|&&(_, v)| v > target)
            .min_by_key(|&&(_, v)| v);
        let [(r1, v1), (r2, v2)] = match (below, above) {
            (Some(&lo), Some(&hi)) => [lo, hi],
            _ => [tried[tried.len() - 2], tried[tried.len() - 1]],
        };
        if v1 == v2 || r1 == r2 {
            break;
        }
        let slope = (v2 as f64 - v1 as f64) / (r2 as f64 - r1 as f64);
        let guess = r1 as f64 + (target as f64 - v1 as f64) / slope;
        if !(guess.is_finite() && slope > 0.0) {
            break;
        }
        request = guess.round().clamp(4.0, n as f64) as usize;
    }
    let mut values: Vec<f64> = d
        .points
        .iter()
        .map(|p| image[p[0] as usize * n1 + p[1] as usize])
        .collect();
    let (flips, moves) = if options.moves {
        let s = move_to_image(
            [n0, n1],
            &mut d.points,
            &mut d.dual.triangles,
            &mut values,
            image,
            control,
        )?;
        (s.flips, s.moves)
    } else if options.flips {
        let s = flip_to_image(
            [n0, n1],
            &d.points,
            &mut d.dual.triangles,
            &values,
            image,
            control,
        )?;
        (s.flips, 0)
    } else {
        (0, 0)
    };
    let approximation = piecewise_linear([n0, n1], &d.points, &d.dual.triangles, &values);
    let sq: f64 = image
        .iter()
        .zip(&approximation)
        .map(|(f, g)| {
            if g.is_finite() {
                (f - g).powi(2)
            } else {
                f * f
            }
        })
        .sum();
    Ok(ImageMesh {
        l2_error: (sq / n as f64).sqrt(),
        covering_radius: d.sampling.covering_radius,
        added: d.added,
        repaired: d.repaired,
        points: d.points,
        triangles: d.dual.triangles,
        values,
        approximation,
        cost: w,
        flips,
        moves,
    })
}

/// `orient(a, b, c) > 0` when `a b c` turns counter-clockwise in the
/// (axis 0, axis 1) plane (twice the signed area).
pub(super) fn orient(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
}

/// The linear interpolant of the triangle `t` (corners and their values) at
/// `x` (barycentric coordinates), if `x` is in the closed triangle (within
/// 1e-9). The one rule of [`piecewise_linear`] and of the flips' error.
pub(super) fn interpolate(t: &[([f64; 2], f64); 3], x: [f64; 2]) -> Option<f64> {
    locate(t, x).map(|(value, _)| value)
}

/// [`interpolate`], and whether `x` is on the triangle's boundary (a
/// barycentric coordinate within 1e-9 of 0), where a neighbour may hold it
/// too.
pub(super) fn locate(t: &[([f64; 2], f64); 3], x: [f64; 2]) -> Option<(f64, bool)> {
    let [(a, fa), (b, fb), (c, fc)] = *t;
    let det = orient(a, b, c);
    let lb = orient(a, x, c) / det;
    let lc = orient(a, b, x) / det;
    let la = 1.0 - lb - lc;
    let eps = 1e-9;
    (la >= -eps && lb >= -eps && lc >= -eps)
        .then(|| (la * fa + lb * fb + lc * fc, la.min(lb).min(lc) <= eps))
}

/// The piecewise-linear interpolation of `values` (one per point) on the
/// triangles, at every cell of a grid of `shape` (C order); NaN at cells no
/// triangle covers. A cell on a shared edge takes the first triangle's value
/// (both agree there).
pub fn piecewise_linear(
    shape: [usize; 2],
    points: &[[f64; 2]],
    triangles: &[[u32; 3]],
    values: &[f64],
) -> Vec<f64> {
    let [n0, n1] = shape;
    let mut out = vec![f64::NAN; n0 * n1];
    for t in triangles {
        let [a, b, c] = t.map(|v| points[v as usize]);
        let [fa, fb, fc] = t.map(|v| values[v as usize]);
        let det = orient(a, b, c);
        if det.abs() < 1e-12 {
            continue;
        }
        let lo = |k: usize| a[k].min(b[k]).min(c[k]).ceil().max(0.0) as usize;
        let hi = |k: usize, n: usize| (a[k].max(b[k]).max(c[k]).floor() as usize).min(n - 1);
        let corners = [(a, fa), (b, fb), (c, fc)];
        for r in lo(0)..=hi(0, n0) {
            for col in lo(1)..=hi(1, n1) {
                if let Some(v) = interpolate(&corners, [r as f64, col as f64]) {
                    let slot = &mut out[r * n1 + col];
                    if slot.is_nan() {
                        *slot = v;
                    }
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The edge tensor has the gradient metric's density (`det(M)^{1/4} =
    /// W`) everywhere, and on a straight edge its elements are `anisotropy`
    /// times longer along the edge than across it.
    #[test]
    fn the_edge_tensor_keeps_the_gradient_density_and_stretches_along_edges() {
        let (n0, n1) = (40usize, 40usize);
        let grid = Grid::unit(&[n0, n1]).expect("grid");
        // A ramp across axis 1 from column 18 to 21, flat elsewhere: the
        // edge runs along axis 0.
        let image: Vec<f64> = (0..n0 * n1)
            .map(|i| (((i % n1) as f64 - 19.5) / 1.5).clamp(-1.0, 1.0))
            .collect();
        let control = Control::new();
        let (sigma, strength) = (1.0, 8.0);
        let w = image_cost(
            &grid,
            &image,
            ImageMetric::Gradient { sigma, strength },
            &control,
        )
        .expect("gradient");
        let metric = ImageMetric::EdgeTensor {
            sigma,
            rho: 2.0,
            strength,
            anisotropy: 3.0,
        };
        let density = image_cost(&grid, &image, metric, &control).expect("edge tensor");
        for (a, b) in w.iter().zip(&density) {
            assert!((a - b).abs() < 1e-9 * a, "{a} vs {b}");
        }
        let t = image_tensor(&grid, &image, metric, &control)
            .expect("edge tensor")
            .expect("a field");
        // On the edge, away from the image's border: across (axis 1) costs
        // `a² = 9` times more than along (axis 0), and the axes are the
        // eigenvectors.
        let m = t.at(20 * n1 + 20);
        assert!(m[1].abs() < 1e-9 * m[2], "{m:?}");
        assert!((m[2] / m[0] - 9.0).abs() < 0.05, "{m:?}");
        // Far from the edge the image is flat, its structure tensor zero:
        // isotropic.
        let m = t.at(20 * n1 + 2);
        assert!(
            (m[2] / m[0] - 1.0).abs() < 0.05 && m[1].abs() < 0.05 * m[0],
            "{m:?}"
        );
    }
}
