//! Inverse problems over the eikonal equation, built on the discrete adjoint
//! [`crate::numerics::eikonal::cost_gradient`] (seed section 2.9: how `U`
//! changes when the metric `W` changes).
//!
//! * [`tomography`]: first-arrival travel-time tomography, a slowness map
//!   `W` recovered from the travel times between sources and receivers.
//! * [`metric_fit`]: a designed metric's parameters fitted so that its
//!   minimal paths follow example paths (inverse optimal control).
//!
//! Both differentiate first- or second-order fast marching without source
//! factoring (the scheme `cost_gradient` differentiates) and share the
//! multilinear read of `U` at a point ([`interpolate`]), which is the one the
//! adjoint's [`crate::numerics::eikonal::Probe::Point`] differentiates.

pub mod metric_fit;
pub mod tomography;

pub use super::eikonal::adjoint_options;
use super::eikonal::point_corners;
use super::grid::Grid;

/// The value at point `p` (index coordinates, caller axes) of the
/// multilinear interpolation of the cell values `u`: the `2^d` cells around
/// `p`, with the corner weights of [`crate::numerics::eikonal::Probe::Point`]
/// (an index past the last cell is clamped to it). `None` if `p` is
/// outside the grid or malformed.
///
/// # Examples
/// ```
/// use geodex::numerics::{Grid, inverse::interpolate};
/// let grid = Grid::unit(&[2, 2])?;
/// let u = [0.0, 1.0, 2.0, 3.0];
/// assert_eq!(interpolate(&grid, &u, &[0.5, 0.5]), Some(1.5));
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn interpolate(grid: &Grid, u: &[f64], p: &[f64]) -> Option<f64> {
    let mut value = 0.0;
    for (i, w) in corners(grid, p)? {
        value += w * u[i];
    }
    Some(value)
}

/// The cells around `p` and their multilinear weights (those `> 0`).
pub(crate) fn corners(grid: &Grid, p: &[f64]) -> Option<Vec<(usize, f64)>> {
    let p3 = grid.point3(p).ok()?;
    if !(p3.iter().all(|x| x.is_finite()) && grid.contains_point3(p3)) {
        return None;
    }
    Some(point_corners(grid, p3))
}
