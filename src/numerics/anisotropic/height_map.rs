//! The metric of a height map: geodesics on the terrain `z = h(x)`.
//!
//! The graph surface `φ(x) = (x, h(x))` has the first fundamental form
//! `I_φ = Dφᵀ Dφ = Id + ∇h ∇hᵀ` (seed eq. 1.10), so the length on the
//! surface of a curve drawn in the plane is `∫ sqrt(γ'ᵀ (Id + ∇h∇hᵀ) γ')`.
//! With a cost `W ≥ 0` per unit of surface length the tensor is
//!
//! ```text
//! M(x) = W(x)² (Id + ∇h(x) ∇h(x)ᵀ),
//! ```
//!
//! and `U` is `W` times the distance on the surface. `∇h` is taken in
//! physical units (the grid spacing; `h` in the same unit) by central
//! differences (second order inside, first order on the border), after an
//! optional Gaussian smoothing of `h` with standard deviation `sigma`.
//! Its anisotropy ratio is `sqrt(1 + |∇h|²)`. 2D and 3D (a graph of a
//! volume function in 4D) grids are accepted alike.

use super::structure_tensor::filter_error;
use super::tensor::{components, TensorError, TensorField};
use crate::numerics::filters::{gaussian_smooth, gradient};
use crate::numerics::grid::Grid;
use crate::numerics::Control;

/// Builds `W² (Id + ∇h∇hᵀ)` from heights `h` (one per cell, C order), a
/// cost `w` (a constant, or one value per cell) and a smoothing `sigma`
/// (physical units, 0 for none). `control` is polled by the filters, once
/// per line.
///
/// # Examples
/// ```
/// use geodex::numerics::{Control, Grid};
/// use geodex::numerics::anisotropic::height_map::height_map_metric;
/// let grid = Grid::unit(&[8, 8])?;
/// let h: Vec<f64> = (0..64).map(|i| 2.0 * (i / 8) as f64).collect(); // slope 2 along axis 0
/// let t = height_map_metric(&grid, &h, &[1.0], 0.0, &Control::new())?;
/// assert_eq!(t.at(9), &[5.0, 0.0, 1.0]);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn height_map_metric(
    grid: &Grid,
    h: &[f64],
    w: &[f64],
    sigma: f64,
    control: &Control<'_>,
) -> Result<TensorField, TensorError> {
    if h.len() != grid.len() {
        return Err(TensorError::Parameter {
            field: "heights",
            reason: format!("{} values for a grid of {} cells", h.len(), grid.len()),
        });
    }
    if let Some(i) = h.iter().position(|v| !v.is_finite()) {
        return Err(TensorError::Parameter {
            field: "heights",
            reason: format!(
                "cell {:?} has height {}, which is not finite",
                crate::numerics::metric::unravel_user(grid, i),
                h[i]
            ),
        });
    }
    if w.len() != 1 && w.len() != grid.len() {
        return Err(TensorError::Parameter {
            field: "energy",
            reason: format!(
                "give one cost or one per cell ({}), got {}",
                grid.len(),
                w.len()
            ),
        });
    }
    if let Some(i) = w.iter().position(|v| !(v.is_finite() && *v > 0.0)) {
        return Err(TensorError::Parameter {
            field: "energy",
            reason: format!("cost {} must be finite and > 0", w[i]),
        });
    }
    let smoothed;
    let h = if sigma > 0.0 {
        smoothed =
            gaussian_smooth(grid, h, sigma, control).map_err(|e| filter_error("sigma", e))?;
        &smoothed[..]
    } else {
        h
    };
    let grad = gradient(grid, h, control).map_err(|e| filter_error("heights", e))?;
    let d = grid.ndim();
    let nc = components(d);
    let mut out = Vec::with_capacity(grid.len() * nc);
    for (i, g3) in grad.iter().enumerate() {
        let g = &g3[3 - d..];
        let w2 = if w.len() == 1 {
            w[0] * w[0]
        } else {
            w[i] * w[i]
        };
        for a in 0..d {
            for b in a..d {
                let id = if a == b { 1.0 } else { 0.0 };
                out.push(w2 * (id + g[a] * g[b]));
            }
        }
    }
    TensorField::from_components(grid, out)
}
