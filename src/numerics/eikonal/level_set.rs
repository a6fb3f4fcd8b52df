//! Level sets and masks as sources: the distance to the zero level set of a
//! function `phi` sampled on the grid (scikit-fmm's `distance`), signed on
//! request (the redistancing of `phi`), and mask sources.
//!
//! # The interface cells
//!
//! The interface is `Γ = {phi = 0}`; inside is `phi < 0`. A cell `x` is an
//! interface cell when `phi(x) = 0` (its distance is 0) or when an axis
//! neighbour `y = x ± e_k` lies on the other side (`phi(y) = 0` or
//! `sign phi(y) ≠ sign phi(x)`). Each interface cell gets its distance to
//! `Γ` before the solve and is frozen there (a Dirichlet value); the solve
//! then marches from these cells. Two fits are offered ([`InterfaceFit`]):
//!
//! * [`InterfaceFit::Linear`] (scikit-fmm's): along each axis `k` with a
//!   crossing, linear interpolation puts `Γ` at `d_k = h_k phi(x)/(phi(x) -
//!   phi(y))` from `x` (the nearer crossing of the two sides), and the
//!   per-axis distances combine as the distance to the plane through these
//!   crossings, `1/d² = Σ_k 1/d_k²`. Exact for a plane interface of a
//!   linear `phi`; when only one axis crosses, the distance is taken along
//!   that axis, which overestimates it by up to `d(1/cos θ - 1)` for an
//!   interface at angle `θ` to the axis.
//! * [`InterfaceFit::Quadratic`] (the default): the second-order Taylor
//!   model `q(y) = phi + g·y + ½ yᵀHy` of `phi` at `x`, with the gradient
//!   `g` and the Hessian `H` from central differences (physical units), and
//!   the closest point of `{q = 0}` to `x` by Chopp's iteration (Chopp 2001,
//!   "Some improvements of the fast marching method"): from `y = 0`, repeat
//!   `y ← y − q(y)∇q/|∇q|² − (y − (y·∇q)∇q/|∇q|²)` (a Newton step onto
//!   `q = 0` along `∇q`, then the component of `y` across `∇q` removed, so
//!   that at the fixed point `y` is normal to the level set). The distance
//!   is `|y|`. It does not assume `|∇phi| = 1` and is exact for any
//!   quadratic `phi` (a circle's `|x − c|² − r²`); its error for a smooth
//!   `phi` is `O(h³)`. Cells on the grid's border (no central difference),
//!   an iteration that does not converge within 30 steps, or a point
//!   farther than 1.25 times the nearest axis crossing fall back to the
//!   linear fit.
//!
//! With a cost `W`, the initial value of an interface cell is its distance
//! times `W` at that cell (the cost is taken as constant across the cell).
//! Interface cells on walls are left out.
//!
//! # The solve
//!
//! The first-order schemes (fast marching and sweeping) and Dijkstra use
//! only the values of immediate neighbours, so one solve from the interface
//! cells gives the unsigned distance on both sides. The second-order scheme
//! reaches two cells upwind, and next to the interface that second cell
//! may be on the other side, where the *unsigned* distance folds back
//! (`|x|` is not smooth at `Γ`), which biases the one-sided difference by
//! up to a tenth of a cell. With [`Order::Second`] the two sides are
//! therefore solved separately: the outside with the inside's interface
//! cells at their *signed* (negative) values and the rest of the inside
//! walled off, then the inside the same way with the signs swapped; the
//! second-order difference across `Γ` is then one of the smooth signed
//! distance. Each cell is computed once in all (the walled side is not
//! entered), plus the interface cells twice.
//!
//! Signed output ([`LevelSetOptions::signed`]) negates `U` where `phi < 0`:
//! the redistancing of `phi` (a signed distance function with the same zero
//! level set).

use std::borrow::Cow;

use ndarray::ArrayViewD;

use super::{solve, EikonalError, EikonalOptions, EikonalOutput, EikonalProblem, Method, Order};
use super::{Source, StopReason};
use crate::numerics::control::Control;
use crate::numerics::grid::Grid;
use crate::numerics::metric::{CostValues, Interpretation, IsotropicCost};

/// How the interface cells get their distance to the zero level set.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum InterfaceFit {
    /// Linear interpolation along each axis, `1/d² = Σ 1/d_k²` (scikit-fmm).
    Linear,
    /// A local quadratic model of `phi` and its closest zero (the default).
    #[default]
    Quadratic,
}

/// Options of [`level_set_distance`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LevelSetOptions {
    /// How the interface is located. Default: quadratic.
    pub fit: InterfaceFit,
    /// Negate the distance where `phi < 0` (redistancing). Default: false.
    pub signed: bool,
}

/// The cells next to the zero level set and their distance to it.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Interface {
    /// Linear indices (C order), increasing.
    pub cells: Vec<usize>,
    /// The physical distance of each cell to the interface, `>= 0` (not
    /// multiplied by a cost).
    pub distance: Vec<f64>,
    /// True for the cells with `phi < 0`.
    pub inside: Vec<bool>,
    /// How many cells fell back from the quadratic to the linear fit.
    pub linear_fallbacks: usize,
}

/// Why a level-set or mask source was refused or a solve interrupted.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LevelSetError {
    /// `phi` (or the mask) does not have the grid's shape.
    #[error("the array has shape {got:?} but the grid has shape {expected:?}")]
    Shape {
        /// The array's shape.
        got: Vec<usize>,
        /// The grid's shape.
        expected: Vec<usize>,
    },
    /// `phi` holds a NaN or an infinity.
    #[error("phi{index:?} = {value} is not finite")]
    NotFinite {
        /// The cell, in the caller's index order.
        index: Vec<usize>,
        /// The value.
        value: f64,
    },
    /// `phi` has no zero and does not change sign: there is no interface.
    #[error("phi has no zero level set: it is {sign} on every cell; the interface is where phi changes sign (phi < 0 inside, > 0 outside)")]
    NoInterface {
        /// "positive" or "negative".
        sign: &'static str,
    },
    /// Every interface cell (or mask cell) lies on a wall.
    #[error("every cell of the {what} lies on an obstacle")]
    AllOnWalls {
        /// "interface" or "mask".
        what: &'static str,
    },
    /// The mask has no non-zero cell.
    #[error("the mask has no non-zero cell: mark the source cells with non-zero values")]
    EmptyMask,
    /// The solve failed or was cancelled.
    #[error(transparent)]
    Eikonal(#[from] EikonalError),
}

const CANCEL_EVERY: usize = 1 << 14;

/// `phi` in C order, checked against the grid (shape, finite values).
fn flat_phi<'a>(
    grid: &Grid,
    phi: &'a ArrayViewD<'_, f64>,
) -> Result<Cow<'a, [f64]>, LevelSetError> {
    if phi.shape() != grid.shape() {
        return Err(LevelSetError::Shape {
            got: phi.shape().to_vec(),
            expected: grid.shape().to_vec(),
        });
    }
    let flat: Cow<'a, [f64]> = match phi.as_slice() {
        Some(s) => Cow::Borrowed(s),
        None => Cow::Owned(phi.iter().copied().collect()),
    };
    if let Some(i) = flat.iter().position(|v| !v.is_finite()) {
        return Err(LevelSetError::NotFinite {
            index: crate::numerics::metric::unravel_user(grid, i),
            value: flat[i],
        });
    }
    Ok(flat)
}

/// Finds the interface cells of `phi` (the grid's shape, any layout) and
/// their distance to the zero level set; see the module documentation for
/// the two fits. Polls `control` every 16384 cells.
///
/// Errors: a shape other than the grid's, a non-finite value, no interface
/// (phi of one sign everywhere), cancellation.
///
/// # Examples
/// ```
/// use geodex::numerics::{Control, Grid};
/// use geodex::numerics::eikonal::{locate_interface, InterfaceFit};
/// // phi = x - 1.25 along axis 1: the interface is the line x = 1.25.
/// let grid = Grid::unit(&[3, 4])?;
/// let phi = ndarray::Array2::from_shape_fn((3, 4), |(_, j)| j as f64 - 1.25).into_dyn();
/// let f = locate_interface(&grid, &phi.view(), InterfaceFit::Linear, &Control::new())?;
/// assert_eq!(f.cells.len(), 6); // columns 1 and 2
/// assert!((f.distance[0] - 0.25).abs() < 1e-12 && (f.distance[1] - 0.75).abs() < 1e-12);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn locate_interface(
    grid: &Grid,
    phi: &ArrayViewD<'_, f64>,
    fit: InterfaceFit,
    control: &Control<'_>,
) -> Result<Interface, LevelSetError> {
    let phi = flat_phi(grid, phi)?;
    let s = grid.shape3();
    let st = grid.strides3();
    let h = grid.spacing3();
    let axes: Vec<usize> = (0..3).filter(|&k| s[k] > 1).collect();
    let mut out = Interface::default();
    for i in 0..phi.len() {
        if i % CANCEL_EVERY == 0 && control.is_cancelled() {
            return Err(EikonalError::Cancelled.into());
        }
        let p = phi[i];
        if p == 0.0 {
            out.cells.push(i);
            out.distance.push(0.0);
            out.inside.push(false);
            continue;
        }
        let idx = grid.unravel(i);
        // The nearest crossing along each axis (physical distance), +inf if none.
        let mut d_axis = [f64::INFINITY; 3];
        let mut any = false;
        for &k in &axes {
            let lo = (idx[k] > 0).then(|| i - st[k]);
            let hi = (idx[k] + 1 < s[k]).then(|| i + st[k]);
            for j in [lo, hi].into_iter().flatten() {
                let q = phi[j];
                if q == 0.0 || (q < 0.0) != (p < 0.0) {
                    let t = p / (p - q);
                    d_axis[k] = d_axis[k].min(t * h[k]);
                    any = true;
                }
            }
        }
        if !any {
            continue;
        }
        let linear = combine(&d_axis);
        let d = match fit {
            InterfaceFit::Linear => linear,
            InterfaceFit::Quadratic => {
                let nearest = d_axis.iter().copied().fold(f64::INFINITY, f64::min);
                match quadratic(&phi, grid, &axes, idx, i) {
                    Some(q) if q <= 1.25 * nearest => q,
                    _ => {
                        out.linear_fallbacks += 1;
                        linear
                    }
                }
            }
        };
        out.cells.push(i);
        out.distance.push(d);
        out.inside.push(p < 0.0);
    }
    if out.cells.is_empty() {
        let sign = if phi.first().is_some_and(|&v| v < 0.0) {
            "negative"
        } else {
            "positive"
        };
        return Err(LevelSetError::NoInterface { sign });
    }
    Ok(out)
}

/// The distance to the plane through the per-axis crossings: `1/d² = Σ 1/d_k²`.
fn combine(d_axis: &[f64; 3]) -> f64 {
    if d_axis.contains(&0.0) {
        return 0.0;
    }
    let s: f64 = d_axis
        .iter()
        .filter(|d| d.is_finite())
        .map(|d| 1.0 / (d * d))
        .sum();
    1.0 / s.sqrt()
}

/// The distance from cell `i` to the zero set of the quadratic Taylor model
/// of `phi` there (Chopp's iteration), or `None` on the border or without
/// convergence.
fn quadratic(phi: &[f64], grid: &Grid, axes: &[usize], idx: [usize; 3], i: usize) -> Option<f64> {
    let s = grid.shape3();
    let st = grid.strides3();
    let h = grid.spacing3();
    if axes.iter().any(|&k| idx[k] == 0 || idx[k] + 1 >= s[k]) {
        return None;
    }
    let p = phi[i];
    let mut g = [0.0; 3];
    let mut hess = [[0.0; 3]; 3];
    for &k in axes {
        let (a, b) = (phi[i + st[k]], phi[i - st[k]]);
        g[k] = (a - b) / (2.0 * h[k]);
        hess[k][k] = (a - 2.0 * p + b) / (h[k] * h[k]);
    }
    for (n, &k) in axes.iter().enumerate() {
        for &l in &axes[n + 1..] {
            let (sk, sl) = (st[k], st[l]);
            let v = (phi[i + sk + sl] - phi[i + sk - sl] - phi[i - sk + sl] + phi[i - sk - sl])
                / (4.0 * h[k] * h[l]);
            hess[k][l] = v;
            hess[l][k] = v;
        }
    }
    let dot = |a: &[f64; 3], b: &[f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let hmax = h.iter().copied().fold(0.0, f64::max);
    let mut y = [0.0f64; 3];
    for _ in 0..30 {
        let hy = [dot(&hess[0], &y), dot(&hess[1], &y), dot(&hess[2], &y)];
        let grad = [g[0] + hy[0], g[1] + hy[1], g[2] + hy[2]];
        let n2 = dot(&grad, &grad);
        if !(n2 > 0.0 && n2.is_finite()) {
            return None;
        }
        let q = p + dot(&g, &y) + 0.5 * dot(&y, &hy);
        let along = dot(&y, &grad) / n2;
        let mut step = [0.0; 3];
        for k in 0..3 {
            // Newton onto q = 0 along ∇q, and the part of y across ∇q removed.
            step[k] = -q / n2 * grad[k] - (y[k] - along * grad[k]);
            y[k] += step[k];
        }
        if dot(&step, &step).sqrt() <= 1e-12 * hmax {
            let d = dot(&y, &y).sqrt();
            return d.is_finite().then_some(d);
        }
    }
    None
}

/// The distance to the zero level set of `phi` under `cost`, from the
/// interface cells of [`locate_interface`] (initial values: distance times
/// the cell's cost), unsigned or signed ([`LevelSetOptions::signed`]: `-U`
/// where `phi < 0`, the redistancing of `phi`). With [`Order::Second`]
/// (fast marching or sweeping) the two sides are solved separately (see the
/// module documentation). The labels are 0 where reached, -1 elsewhere;
/// with two solves, `frozen_order` ranks the outside cells first, then the
/// inside ones, and the stop reason is the first side's that is not
/// `Completed`, if any.
///
/// # Examples
/// ```
/// use geodex::numerics::{Control, EikonalOptions, Grid, IsotropicCost};
/// use geodex::numerics::eikonal::{level_set_distance, LevelSetOptions};
/// // A circle of radius 10 around (16, 16): phi = |x - c|² - r² is not a distance.
/// let grid = Grid::unit(&[33, 33])?;
/// let phi = ndarray::Array2::from_shape_fn((33, 33), |(i, j)| {
///     (i as f64 - 16.0).powi(2) + (j as f64 - 16.0).powi(2) - 100.0
/// }).into_dyn();
/// let options = LevelSetOptions { signed: true, ..Default::default() };
/// let cost = IsotropicCost::constant(1.0)?;
/// let out = level_set_distance(&grid, &cost, &phi.view(), &options, &EikonalOptions::DEFAULT, &Control::new())?;
/// assert!((out.distance[[16, 30]] - 4.0).abs() < 0.05);
/// assert!((out.distance[[16, 12]] + 6.0).abs() < 0.1);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn level_set_distance(
    grid: &Grid,
    cost: &IsotropicCost<'_>,
    phi: &ArrayViewD<'_, f64>,
    options: &LevelSetOptions,
    eikonal: &EikonalOptions,
    control: &Control<'_>,
) -> Result<EikonalOutput, LevelSetError> {
    let interface = locate_interface(grid, phi, options.fit, control)?;
    // Logical (C) order whatever the layout; the shape was checked above.
    let inside: Vec<bool> = phi.iter().map(|&v| v < 0.0).collect();
    let seeds: Vec<(usize, f64, bool)> = interface
        .cells
        .iter()
        .zip(&interface.distance)
        .zip(&interface.inside)
        .filter_map(|((&i, &d), &inside)| {
            let w = cost.at(i);
            w.is_finite().then_some((i, d * w, inside))
        })
        .collect();
    if seeds.is_empty() {
        return Err(LevelSetError::AllOnWalls { what: "interface" });
    }
    let two_sides = eikonal.order == Order::Second && eikonal.method != Method::Dijkstra;
    let mut out = if two_sides {
        // Outside (phi >= 0): the inside's interface cells at -d, the rest of
        // the inside walled off; then the inside. Progress: each side in
        // proportion to its cells, so that the fraction only grows.
        let outside_cells = inside.iter().filter(|&&v| !v).count() as f64;
        let share = outside_cells / inside.len().max(1) as f64;
        let first = |f: f64| control.report(share * f);
        let second = |f: f64| control.report(share + (1.0 - share) * f);
        let c1 = control.cancel_only().with_progress(&first);
        let outside = side_solve(grid, cost, &seeds, &inside, false, eikonal, &c1)?;
        let c2 = control.cancel_only().with_progress(&second);
        let inner = side_solve(grid, cost, &seeds, &inside, true, eikonal, &c2)?;
        merge(outside, inner, &inside)
    } else {
        let problem = EikonalProblem {
            grid: grid.clone(),
            cost: cost.clone(),
            sources: vec![cells_source(grid, seeds.iter().map(|&(i, v, _)| (i, v)))],
        };
        solve(&problem, eikonal, control)?
    };
    if options.signed {
        for (u, &inside) in out.distance.iter_mut().zip(&inside) {
            if inside && u.is_finite() {
                *u = -*u;
            }
        }
    }
    Ok(out)
}

/// A [`Source::Cells`] from linear indices and values.
fn cells_source(grid: &Grid, seeds: impl Iterator<Item = (usize, f64)>) -> Source {
    let (cells, values): (Vec<Vec<usize>>, Vec<f64>) = seeds
        .map(|(i, v)| (crate::numerics::metric::unravel_user(grid, i), v))
        .unzip();
    Source::Cells {
        cells,
        values: Some(values),
    }
}

/// One side of a second-order solve: the side's interface cells at `+d`,
/// the other side's at `-d`, the other side's other cells walls.
fn side_solve(
    grid: &Grid,
    cost: &IsotropicCost<'_>,
    seeds: &[(usize, f64, bool)],
    inside: &[bool],
    solve_inside: bool,
    eikonal: &EikonalOptions,
    control: &Control<'_>,
) -> Result<EikonalOutput, LevelSetError> {
    let mut walls: Vec<bool> = inside.iter().map(|&v| v != solve_inside).collect();
    for &(i, _, _) in seeds {
        walls[i] = false;
    }
    let values = match cost.uniform_value() {
        Some(w) => CostValues::Constant(w),
        None => CostValues::F64((0..grid.len()).map(|i| cost.at(i)).collect()),
    };
    let side_cost = IsotropicCost::new(grid, values, Interpretation::Cost, Some(walls.into()))
        .map_err(EikonalError::from)?;
    let signed = seeds.iter().map(|&(i, v, inside)| {
        if inside == solve_inside {
            (i, v)
        } else {
            (i, -v)
        }
    });
    let problem = EikonalProblem {
        grid: grid.clone(),
        cost: side_cost,
        sources: vec![cells_source(grid, signed)],
    };
    Ok(solve(&problem, eikonal, control)?)
}

/// The outside cells from `outside`, the inside ones from `inner`.
fn merge(outside: EikonalOutput, inner: EikonalOutput, inside: &[bool]) -> EikonalOutput {
    let mut out = outside;
    let offset = out.frozen as i64;
    let inner_distance = inner.distance.as_slice_memory_order();
    let inner_labels = inner.labels.as_slice_memory_order();
    let inner_order = inner
        .frozen_order
        .as_ref()
        .and_then(|o| o.as_slice_memory_order());
    if let (Some(u), Some(l), Some(ud), Some(ld)) = (
        out.distance.as_slice_memory_order_mut(),
        out.labels.as_slice_memory_order_mut(),
        inner_distance,
        inner_labels,
    ) {
        for i in 0..inside.len() {
            if inside[i] {
                u[i] = ud[i];
                l[i] = ld[i];
            } else if u[i] < 0.0 {
                // Cannot happen (an outside cell is never one of the inside's
                // seeds), kept so that no negative unsigned value escapes.
                u[i] = u[i].abs();
            }
        }
    }
    if let (Some(o), Some(io)) = (
        out.frozen_order
            .as_mut()
            .and_then(|o| o.as_slice_memory_order_mut()),
        inner_order,
    ) {
        for i in 0..inside.len() {
            if inside[i] {
                o[i] = if io[i] >= 0 { io[i] + offset } else { -1 };
            }
        }
    }
    out.frozen = out.distance.iter().filter(|v| v.is_finite()).count();
    if out.stop == StopReason::Completed {
        out.stop = inner.stop;
    }
    out.sweeps = match (out.sweeps, inner.sweeps) {
        (Some(a), Some(b)) => Some(a + b),
        (a, b) => a.or(b),
    };
    out
}

/// A source of value 0 on every non-zero cell of `mask` (the grid's shape),
/// leaving out the cells on walls.
///
/// Errors: a shape other than the grid's, no non-zero cell, every cell on a
/// wall, cancellation.
pub fn mask_source(
    grid: &Grid,
    cost: &IsotropicCost<'_>,
    mask: &ArrayViewD<'_, bool>,
    control: &Control<'_>,
) -> Result<Source, LevelSetError> {
    if mask.shape() != grid.shape() {
        return Err(LevelSetError::Shape {
            got: mask.shape().to_vec(),
            expected: grid.shape().to_vec(),
        });
    }
    let mut cells = Vec::new();
    let mut any = false;
    // Logical (C) order whatever the layout: the n-th value is cell n.
    for (i, &m) in mask.iter().enumerate() {
        if i % CANCEL_EVERY == 0 && control.is_cancelled() {
            return Err(EikonalError::Cancelled.into());
        }
        if !m {
            continue;
        }
        any = true;
        if cost.at(i).is_finite() {
            cells.push(crate::numerics::metric::unravel_user(grid, i));
        }
    }
    if !any {
        return Err(LevelSetError::EmptyMask);
    }
    if cells.is_empty() {
        return Err(LevelSetError::AllOnWalls { what: "mask" });
    }
    Ok(Source::Cells {
        cells,
        values: None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::{Array2, Array3};

    fn circle_phi(n: usize, c: [f64; 2], r: f64, squared: bool) -> ndarray::ArrayD<f64> {
        Array2::from_shape_fn((n, n), |(i, j)| {
            let d = ((i as f64 - c[0]).powi(2) + (j as f64 - c[1]).powi(2)).sqrt();
            if squared {
                d * d - r * r
            } else {
                d - r
            }
        })
        .into_dyn()
    }

    #[test]
    fn a_plane_is_located_exactly_by_both_fits() {
        // phi = a·x - b with |a| = 1: a line at an angle. The quadratic fit
        // is exact on every interior cell; the linear one where both axes
        // cross (elsewhere it measures along the one crossing axis).
        let n = 12;
        let grid = Grid::unit(&[n, n]).unwrap();
        let a = [0.6, 0.8];
        let phi = Array2::from_shape_fn((n, n), |(i, j)| a[0] * i as f64 + a[1] * j as f64 - 6.3)
            .into_dyn();
        let side = |i: usize, j: usize| phi[[i, j]] < 0.0;
        for fit in [InterfaceFit::Linear, InterfaceFit::Quadratic] {
            let f = locate_interface(&grid, &phi.view(), fit, &Control::new()).unwrap();
            assert!(f.cells.len() > n);
            let mut checked = 0;
            for (&c, &d) in f.cells.iter().zip(&f.distance) {
                let [_, i, j] = grid.unravel(c);
                if i == 0 || j == 0 || i == n - 1 || j == n - 1 {
                    continue;
                }
                let me = side(i, j);
                let both = (side(i - 1, j) != me || side(i + 1, j) != me)
                    && (side(i, j - 1) != me || side(i, j + 1) != me);
                if fit == InterfaceFit::Linear && !both {
                    continue;
                }
                checked += 1;
                let exact = phi[[i, j]].abs();
                assert!(
                    (d - exact).abs() < 1e-12,
                    "{fit:?} ({i}, {j}): {d} vs {exact}"
                );
            }
            assert!(checked > 5);
        }
    }

    #[test]
    fn the_quadratic_fit_is_exact_for_a_quadratic_phi() {
        let n = 64;
        let (c, r) = ([31.3, 32.6], 17.2);
        let grid = Grid::unit(&[n, n]).unwrap();
        let phi = circle_phi(n, c, r, true);
        let f =
            locate_interface(&grid, &phi.view(), InterfaceFit::Quadratic, &Control::new()).unwrap();
        assert_eq!(f.linear_fallbacks, 0);
        for (&i, &d) in f.cells.iter().zip(&f.distance) {
            let x = grid.unravel(i);
            let exact = ((x[1] as f64 - c[0]).hypot(x[2] as f64 - c[1]) - r).abs();
            assert!((d - exact).abs() < 1e-9, "{x:?}: {d} vs {exact}");
        }
    }

    #[test]
    fn zero_cells_get_zero_and_one_signed_phi_is_refused() {
        let grid = Grid::unit(&[3, 3]).unwrap();
        let mut phi = Array2::<f64>::ones((3, 3)).into_dyn();
        assert!(matches!(
            locate_interface(&grid, &phi.view(), InterfaceFit::Quadratic, &Control::new()),
            Err(LevelSetError::NoInterface { sign: "positive" })
        ));
        phi[[1, 1]] = 0.0;
        // The zero cell, and its four neighbours at one cell (the crossing is
        // on the zero cell; they are on the border, so the fit is linear).
        let f =
            locate_interface(&grid, &phi.view(), InterfaceFit::Quadratic, &Control::new()).unwrap();
        assert_eq!(f.cells, vec![1, 3, 4, 5, 7]);
        assert_eq!(f.distance, vec![1.0, 1.0, 0.0, 1.0, 1.0]);
        phi[[0, 0]] = f64::NAN;
        assert!(matches!(
            locate_interface(&grid, &phi.view(), InterfaceFit::Quadratic, &Control::new()),
            Err(LevelSetError::NotFinite { .. })
        ));
        let wrong = Array2::<f64>::ones((3, 4)).into_dyn();
        assert!(matches!(
            locate_interface(&grid, &wrong.view(), InterfaceFit::Linear, &Control::new()),
            Err(LevelSetError::Shape { .. })
        ));
    }

    #[test]
    fn a_sphere_in_3d_with_spacing() {
        // phi = |x - c|² - r² in physical units, spacing (1, 0.8, 1.2).
        let h = [1.0, 0.8, 1.2];
        let (c, r) = ([16.2, 20.3, 13.1], 9.0);
        let grid = Grid::new(&[33, 41, 27], &h).unwrap();
        let phi = Array3::from_shape_fn((33, 41, 27), |(i, j, k)| {
            let x = [i as f64 * h[0], j as f64 * h[1], k as f64 * h[2]];
            (0..3).map(|a| (x[a] - c[a]).powi(2)).sum::<f64>() - r * r
        })
        .into_dyn();
        let cost = IsotropicCost::constant(1.0).unwrap();
        let options = LevelSetOptions {
            signed: true,
            ..Default::default()
        };
        let out = level_set_distance(
            &grid,
            &cost,
            &phi.view(),
            &options,
            &EikonalOptions::DEFAULT,
            &Control::new(),
        )
        .unwrap();
        let mut max = 0.0f64;
        for ((i, j, k), &u) in out
            .distance
            .view()
            .into_dimensionality::<ndarray::Ix3>()
            .unwrap()
            .indexed_iter()
        {
            let x = [i as f64 * h[0], j as f64 * h[1], k as f64 * h[2]];
            let exact = (0..3).map(|a| (x[a] - c[a]).powi(2)).sum::<f64>().sqrt() - r;
            // Off the centre, where converging fronts leave an error of
            // the scheme's own (0.3 at 0.4 from it).
            if exact + r >= 3.0 {
                max = max.max((u - exact).abs());
            }
        }
        assert!(max < 0.1, "max error {max}");
    }

    #[test]
    fn a_mask_is_a_zero_source_and_an_empty_one_is_refused() {
        let grid = Grid::unit(&[5, 5]).unwrap();
        let cost = IsotropicCost::constant(1.0).unwrap();
        let mut mask = ndarray::Array2::from_elem((5, 5), false).into_dyn();
        assert_eq!(
            mask_source(&grid, &cost, &mask.view(), &Control::new()),
            Err(LevelSetError::EmptyMask)
        );
        mask[[1, 2]] = true;
        mask[[3, 3]] = true;
        let s = mask_source(&grid, &cost, &mask.view(), &Control::new()).unwrap();
        assert_eq!(
            s,
            Source::Cells {
                cells: vec![vec![1, 2], vec![3, 3]],
                values: None
            }
        );
    }

    #[test]
    fn progress_only_grows_over_the_two_sides() {
        // Fast marching reports every 65536 frozen cells.
        let n = 600;
        let grid = Grid::unit(&[n, n]).unwrap();
        let phi = circle_phi(n, [299.5, 300.2], 200.3, false);
        let seen = std::sync::Mutex::new(Vec::new());
        let sink = |f: f64| seen.lock().unwrap().push(f);
        let control = Control::new().with_progress(&sink);
        let cost = IsotropicCost::constant(1.0).unwrap();
        level_set_distance(
            &grid,
            &cost,
            &phi.view(),
            &LevelSetOptions::default(),
            &EikonalOptions::DEFAULT,
            &control,
        )
        .unwrap();
        let seen = seen.into_inner().unwrap();
        assert!(seen.len() > 2, "{seen:?}");
        assert!(seen.windows(2).all(|w| w[0] <= w[1]), "{seen:?}");
        assert!((seen[seen.len() - 1] - 1.0).abs() < 1e-12, "{seen:?}");
    }

    #[test]
    fn a_raised_flag_stops_the_location() {
        let flag = std::sync::atomic::AtomicBool::new(true);
        let grid = Grid::unit(&[8, 8]).unwrap();
        let phi = circle_phi(8, [4.0, 4.0], 2.0, false);
        assert_eq!(
            locate_interface(
                &grid,
                &phi.view(),
                InterfaceFit::Quadratic,
                &Control::new().with_cancel(&flag)
            ),
            Err(LevelSetError::Eikonal(EikonalError::Cancelled))
        );
    }
}
