//! Edge-following metrics from the structure tensor of an image (seed
//! section 1.3.3, Fig. 1.7-1.8).
//!
//! The structure tensor of an image `f` at noise scale `σ` and integration
//! scale `ρ` is the smoothed outer product of the gradient,
//!
//! ```text
//! J = G_ρ * (∇f_σ ∇f_σᵀ),     f_σ = G_σ * f.
//! ```
//!
//! Its leading eigenvector is across edges (the gradient direction), the
//! others along them. The metric makes the direction along edges cheap:
//!
//! ```text
//! M = W² (Id + A (d J / tr J − Id)),    A ∈ [0, 1),
//! ```
//!
//! whose eigenvalues are `W²(1 + A(d ν_k − 1))` for the normalised eigenvalues
//! `ν_k = μ_k / tr J` of `J`: in 2D `W²(1 − A c)` along the edge and
//! `W²(1 + A c)` across it, with the coherence `c = (μ1 − μ2)/(μ1 + μ2)`.
//! This is the energy / anisotropy form of seed eq. 1.17 with anisotropy
//! `A c`: isotropic (`W² Id`) where the image is flat or has no preferred
//! direction, and as `A → 0` everywhere.

use super::tensor::{components, TensorError, TensorField};
use crate::numerics::filters::{gaussian_smooth, gradient, FilterError};
use crate::numerics::grid::Grid;
use crate::numerics::Control;

/// A filter error as a tensor error: a cancellation stays one, anything
/// else is a bad `field`.
pub(super) fn filter_error(field: &'static str, e: FilterError) -> TensorError {
    match e {
        FilterError::Cancelled => TensorError::Cancelled,
        other => TensorError::Parameter {
            field,
            reason: other.to_string(),
        },
    }
}

/// The structure tensor `J` of `image` (one value per cell, C order) with
/// noise scale `sigma` and integration scale `rho` (physical units), as 3 or
/// 6 components per cell (`[j00, j01, j11]`, axis 0 first). `control` is
/// polled by the filters, once per line.
pub fn structure_tensor(
    grid: &Grid,
    image: &[f64],
    sigma: f64,
    rho: f64,
    control: &Control<'_>,
) -> Result<Vec<f64>, TensorError> {
    let smoothed =
        gaussian_smooth(grid, image, sigma, control).map_err(|e| filter_error("sigma", e))?;
    let grad = gradient(grid, &smoothed, control).map_err(|e| filter_error("image", e))?;
    let d = grid.ndim();
    let nc = components(d);
    let mut comps: Vec<Vec<f64>> = vec![Vec::with_capacity(grid.len()); nc];
    for g3 in &grad {
        let g = &g3[3 - d..];
        let mut s = 0;
        for a in 0..d {
            for b in a..d {
                comps[s].push(g[a] * g[b]);
                s += 1;
            }
        }
    }
    let mut smooth = Vec::with_capacity(nc);
    for c in comps {
        smooth.push(gaussian_smooth(grid, &c, rho, control).map_err(|e| filter_error("rho", e))?);
    }
    let mut out = Vec::with_capacity(grid.len() * nc);
    for i in 0..grid.len() {
        for c in &smooth {
            out.push(c[i]);
        }
    }
    Ok(out)
}

/// The edge-following metric `W² (Id + A (d J / tr J − Id))` of `image` (see
/// the module docs). `energy` is `W > 0`, `anisotropy` is `A ∈ [0, 1)`.
///
/// # Examples
/// ```
/// use geodex::numerics::{Control, Grid};
/// use geodex::numerics::anisotropic::structure_tensor::edge_metric;
/// let grid = Grid::unit(&[32, 32])?;
/// // A vertical edge (intensity varies along axis 1): cheap along axis 0.
/// let img: Vec<f64> = (0..1024).map(|i| if i % 32 < 16 { 0.0 } else { 1.0 }).collect();
/// let t = edge_metric(&grid, &img, 1.0, 2.0, 1.0, 0.9, &Control::new())?;
/// let m = t.at(16 * 32 + 16);
/// assert!(m[0] < 0.2 && m[2] > 1.8);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn edge_metric(
    grid: &Grid,
    image: &[f64],
    sigma: f64,
    rho: f64,
    energy: f64,
    anisotropy: f64,
    control: &Control<'_>,
) -> Result<TensorField, TensorError> {
    if image.len() != grid.len() {
        return Err(TensorError::Parameter {
            field: "image",
            reason: format!("{} values for a grid of {} cells", image.len(), grid.len()),
        });
    }
    if let Some(i) = image.iter().position(|v| !v.is_finite()) {
        return Err(TensorError::Parameter {
            field: "image",
            reason: format!(
                "cell {:?} has value {}, which is not finite",
                crate::numerics::metric::unravel_user(grid, i),
                image[i]
            ),
        });
    }
    if !(energy.is_finite() && energy > 0.0) {
        return Err(TensorError::Parameter {
            field: "energy",
            reason: format!("W = {energy} must be finite and > 0"),
        });
    }
    if !(anisotropy.is_finite() && (0.0..1.0).contains(&anisotropy)) {
        return Err(TensorError::Parameter {
            field: "anisotropy",
            reason: format!("A = {anisotropy} must be in [0, 1)"),
        });
    }
    let j = structure_tensor(grid, image, sigma, rho, control)?;
    let d = grid.ndim();
    let nc = components(d);
    let diag: Vec<usize> = (0..d)
        .map(|a| a * d - a * (a.saturating_sub(1)) / 2)
        .collect();
    let trace = |m: &[f64]| diag.iter().map(|&k| m[k]).sum::<f64>();
    let max_tr = j.chunks_exact(nc).map(trace).fold(0.0, f64::max);
    let eps = 1e-12 * max_tr;
    let w2 = energy * energy;
    let mut out = Vec::with_capacity(j.len());
    for m in j.chunks_exact(nc) {
        let tr = trace(m);
        let mut s = 0;
        for a in 0..d {
            for b in a..d {
                let id = if a == b { 1.0 } else { 0.0 };
                let n = if tr > eps { d as f64 * m[s] / tr } else { id };
                out.push(w2 * (id + anisotropy * (n - id)));
                s += 1;
            }
        }
    }
    TensorField::from_components(grid, out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::numerics::anisotropic::height_map::height_map_metric;

    #[test]
    fn a_raised_flag_stops_the_designed_fields() {
        let grid = Grid::unit(&[8, 8]).unwrap();
        let img: Vec<f64> = (0..64).map(f64::from).collect();
        let flag = std::sync::atomic::AtomicBool::new(true);
        let c = Control::new().with_cancel(&flag);
        assert_eq!(
            structure_tensor(&grid, &img, 1.0, 2.0, &c),
            Err(TensorError::Cancelled)
        );
        assert_eq!(
            edge_metric(&grid, &img, 1.0, 2.0, 1.0, 0.5, &c),
            Err(TensorError::Cancelled)
        );
        assert_eq!(
            height_map_metric(&grid, &img, &[1.0], 0.0, &c),
            Err(TensorError::Cancelled)
        );
        // A filter's refusal stays a refusal of the parameter.
        assert!(matches!(
            structure_tensor(&grid, &img, -1.0, 2.0, &Control::new()),
            Err(TensorError::Parameter { field: "sigma", .. })
        ));
    }
}
