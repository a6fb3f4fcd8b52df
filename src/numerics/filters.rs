//! Linear filters on grids: Gaussian smoothing and finite-difference
//! derivatives, the building blocks of metric design (edges, vesselness,
//! structure tensors).
//!
//! Values are a flat slice in the grid's linear (C) order, see
//! [`Grid`]. Derivatives are in physical units (per unit of `spacing`) and are
//! returned per storage axis: for a 2D grid, component 0 (the padded axis) is
//! always zero and components 1 and 2 are the derivatives along the grid's
//! axes 0 and 1.
//!
//! Every filter takes a [`Control`] and polls its cancel flag before each
//! line it filters (a line of `n` cells costs `O(n)`, `O(n r)` for a
//! Gaussian of radius `r`); a raised flag returns [`FilterError::Cancelled`].

use super::{Control, Grid};

/// Why a filter was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FilterError {
    /// The value slice does not have one entry per cell.
    #[error("{got} values for a grid of {expected} cells")]
    Length {
        /// Values given.
        got: usize,
        /// Cells in the grid.
        expected: usize,
    },
    /// A scale is negative or not finite.
    #[error("sigma = {0} must be finite and >= 0")]
    Sigma(f64),
    /// The caller raised the cancel flag.
    #[error("cancelled")]
    Cancelled,
}

fn check(grid: &Grid, values: &[f64]) -> Result<(), FilterError> {
    if values.len() != grid.len() {
        return Err(FilterError::Length {
            got: values.len(),
            expected: grid.len(),
        });
    }
    Ok(())
}

/// The storage axes a grid really has (`[1, 2]` in 2D, `[0, 1, 2]` in 3D).
fn axes(grid: &Grid) -> std::ops::Range<usize> {
    (3 - grid.ndim())..3
}

/// Normalised sampled Gaussian `exp(-x²/2s²)` on `[-r, r]`, `r = ceil(4 s)`.
fn kernel(s: f64) -> Vec<f64> {
    let r = (4.0 * s).ceil().max(1.0) as usize;
    let mut k: Vec<f64> = (0..=2 * r)
        .map(|i| {
            let x = i as f64 - r as f64;
            (-x * x / (2.0 * s * s)).exp()
        })
        .collect();
    let sum: f64 = k.iter().sum();
    k.iter_mut().for_each(|v| *v /= sum);
    k
}

/// Mirror an index into `0..n` (half-sample symmetric: `-1 -> 0`, `n -> n-1`).
#[inline]
fn mirror(i: isize, n: usize) -> usize {
    let n = n as isize;
    let period = 2 * n;
    let mut m = i.rem_euclid(period);
    if m >= n {
        m = period - 1 - m;
    }
    m as usize
}

/// Applies `f` to every line of the grid along storage axis `axis`: `f(line)`
/// gets the values of the line in a scratch buffer and writes back in place.
/// `control` is polled before each line.
fn for_each_line(
    grid: &Grid,
    values: &mut [f64],
    axis: usize,
    control: &Control<'_>,
    mut f: impl FnMut(&mut Vec<f64>),
) -> Result<(), FilterError> {
    let shape = grid.shape3();
    let strides = grid.strides3();
    let n = shape[axis];
    let stride = strides[axis];
    let (a, b) = match axis {
        0 => (1, 2),
        1 => (0, 2),
        _ => (0, 1),
    };
    let mut line = Vec::with_capacity(n);
    for i in 0..shape[a] {
        for j in 0..shape[b] {
            if control.is_cancelled() {
                return Err(FilterError::Cancelled);
            }
            let base = i * strides[a] + j * strides[b];
            line.clear();
            line.extend((0..n).map(|t| values[base + t * stride]));
            f(&mut line);
            for (t, v) in line.iter().enumerate() {
                values[base + t * stride] = *v;
            }
        }
    }
    Ok(())
}

/// Gaussian smoothing `G_σ * f` with a standard deviation of `sigma` in
/// physical units (so `sigma / spacing[k]` cells along axis `k`), as separable
/// 1D convolutions with the sampled kernel truncated at 4σ and mirrored
/// boundaries. `sigma = 0` returns a copy.
///
/// # Examples
/// ```
/// use geodex::numerics::{filters, Control, Grid};
/// let grid = Grid::unit(&[16, 16])?;
/// let f = vec![2.5; 256];
/// let g = filters::gaussian_smooth(&grid, &f, 1.5, &Control::new())?;
/// assert!(g.iter().all(|v| (v - 2.5).abs() < 1e-12));
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn gaussian_smooth(
    grid: &Grid,
    values: &[f64],
    sigma: f64,
    control: &Control<'_>,
) -> Result<Vec<f64>, FilterError> {
    check(grid, values)?;
    if !(sigma.is_finite() && sigma >= 0.0) {
        return Err(FilterError::Sigma(sigma));
    }
    let mut out = values.to_vec();
    if sigma == 0.0 {
        return Ok(out);
    }
    let spacing = grid.spacing3();
    let shape = grid.shape3();
    for axis in axes(grid) {
        let s = sigma / spacing[axis];
        if s < 1e-3 || shape[axis] < 2 {
            continue;
        }
        let k = kernel(s);
        let r = k.len() / 2;
        let n = shape[axis];
        // The line extended by `r` mirrored values at each end, so that the
        // taps need no index arithmetic: `ext[t + q] = line[mirror(t + q - r)]`.
        let mut ext = vec![0.0; n + 2 * r];
        for_each_line(grid, &mut out, axis, control, |line| {
            for (e, slot) in ext.iter_mut().enumerate() {
                *slot = line[mirror(e as isize - r as isize, n)];
            }
            for (t, slot) in line.iter_mut().enumerate() {
                let mut acc = 0.0;
                for (w, v) in k.iter().zip(&ext[t..t + k.len()]) {
                    acc += w * v;
                }
                *slot = acc;
            }
        })?;
    }
    Ok(out)
}

/// Derivative along one storage axis: central differences `(f[i+1] - f[i-1]) / 2h`
/// inside (second order), one-sided differences at the two ends (first order).
fn derivative(
    grid: &Grid,
    values: &[f64],
    axis: usize,
    control: &Control<'_>,
) -> Result<Vec<f64>, FilterError> {
    let h = grid.spacing3()[axis];
    let n = grid.shape3()[axis];
    let mut out = values.to_vec();
    if n < 2 {
        out.iter_mut().for_each(|v| *v = 0.0);
        return Ok(out);
    }
    let mut tmp = vec![0.0; n];
    for_each_line(grid, &mut out, axis, control, |line| {
        tmp[0] = (line[1] - line[0]) / h;
        tmp[n - 1] = (line[n - 1] - line[n - 2]) / h;
        for t in 1..n - 1 {
            tmp[t] = (line[t + 1] - line[t - 1]) / (2.0 * h);
        }
        line.copy_from_slice(&tmp);
    })?;
    Ok(out)
}

/// The gradient `∇f` per cell, in physical units, per storage axis (see the
/// module docs): central differences inside, one-sided at the border.
pub fn gradient(
    grid: &Grid,
    values: &[f64],
    control: &Control<'_>,
) -> Result<Vec<[f64; 3]>, FilterError> {
    check(grid, values)?;
    let mut out = vec![[0.0; 3]; values.len()];
    for axis in axes(grid) {
        for (o, d) in out.iter_mut().zip(derivative(grid, values, axis, control)?) {
            o[axis] = d;
        }
    }
    Ok(out)
}

/// The Hessian of `f` per cell as `[f00, f11, f22, f01, f02, f12]` over the
/// storage axes, by repeated central differences (second order inside).
/// Entries involving the padded axis of a 2D grid are zero.
pub fn hessian(
    grid: &Grid,
    values: &[f64],
    control: &Control<'_>,
) -> Result<Vec<[f64; 6]>, FilterError> {
    check(grid, values)?;
    let mut out = vec![[0.0; 6]; values.len()];
    let first: Vec<Option<Vec<f64>>> = (0..3)
        .map(|a| {
            axes(grid)
                .contains(&a)
                .then(|| derivative(grid, values, a, control))
                .transpose()
        })
        .collect::<Result<_, _>>()?;
    let slots = [
        (0, 0, 0),
        (1, 1, 1),
        (2, 2, 2),
        (3, 0, 1),
        (4, 0, 2),
        (5, 1, 2),
    ];
    for (slot, a, b) in slots {
        let (Some(da), true) = (&first[a], axes(grid).contains(&b)) else {
            continue;
        };
        for (o, d) in out.iter_mut().zip(derivative(grid, da, b, control)?) {
            o[slot] = d;
        }
    }
    Ok(out)
}

/// Affine rescaling of the finite values to `[0, 1]` (min to 0, max to 1); a
/// constant image becomes all zeros. Non-finite values are left as they are.
pub fn normalize_unit(values: &[f64]) -> Vec<f64> {
    let (lo, hi) = values
        .iter()
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        });
    let span = hi - lo;
    values
        .iter()
        .map(|&v| {
            if !v.is_finite() {
                v
            } else if span > 0.0 {
                (v - lo) / span
            } else {
                0.0
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn smoothing_preserves_mass_and_linear_functions_inside() {
        let grid = Grid::new(&[40, 50], &[1.0, 0.5]).unwrap();
        let f: Vec<f64> = (0..grid.len())
            .map(|i| {
                let [_, a, b] = grid.unravel(i);
                3.0 * a as f64 - 2.0 * b as f64
            })
            .collect();
        let g = gaussian_smooth(&grid, &f, 1.0, &Control::new()).unwrap();
        // Away from the border (4 sigma = 4 cells on axis 0, 8 on axis 1) a linear function is kept.
        for i in 0..grid.len() {
            let [_, a, b] = grid.unravel(i);
            if (5..35).contains(&a) && (9..41).contains(&b) {
                assert!((g[i] - f[i]).abs() < 1e-9, "{a} {b}: {} vs {}", g[i], f[i]);
            }
        }
        // A delta spreads into a Gaussian of the right width (variance sigma^2 / h^2 cells^2).
        let grid = Grid::new(&[1, 101], &[1.0, 0.5]).unwrap();
        let mut d = vec![0.0; 101];
        d[50] = 1.0;
        let g = gaussian_smooth(&grid, &d, 2.0, &Control::new()).unwrap();
        let mass: f64 = g.iter().sum();
        let var: f64 = g
            .iter()
            .enumerate()
            .map(|(i, v)| v * (i as f64 - 50.0).powi(2))
            .sum();
        assert!((mass - 1.0).abs() < 1e-12);
        // Truncation at 4 sigma removes about 0.07 % of the variance.
        assert!((var - 16.0).abs() < 0.02, "variance {var}");
    }

    #[test]
    fn derivatives_of_a_quadratic_are_exact_inside() {
        let grid = Grid::new(&[6, 7, 8], &[0.5, 1.0, 2.0]).unwrap();
        let pos = |i: usize| {
            let [a, b, c] = grid.unravel(i);
            (a as f64 * 0.5, b as f64, c as f64 * 2.0)
        };
        let f: Vec<f64> = (0..grid.len())
            .map(|i| {
                let (x, y, z) = pos(i);
                x * x + 3.0 * x * y - y * z + 0.5 * z * z
            })
            .collect();
        let g = gradient(&grid, &f, &Control::new()).unwrap();
        let h = hessian(&grid, &f, &Control::new()).unwrap();
        for i in 0..grid.len() {
            let [a, b, c] = grid.unravel(i);
            if !(2..4).contains(&a) || !(2..5).contains(&b) || !(2..6).contains(&c) {
                continue;
            }
            let (x, y, z) = pos(i);
            let want = [2.0 * x + 3.0 * y, 3.0 * x - z, -y + z];
            for k in 0..3 {
                assert!((g[i][k] - want[k]).abs() < 1e-9, "grad {k}");
            }
            let want_h = [2.0, 0.0, 1.0, 3.0, 0.0, -1.0];
            for k in 0..6 {
                assert!((h[i][k] - want_h[k]).abs() < 1e-9, "hess {k}: {}", h[i][k]);
            }
        }
    }

    #[test]
    fn two_dimensional_grids_have_no_padded_component() {
        let grid = Grid::unit(&[5, 6]).unwrap();
        let f: Vec<f64> = (0..30).map(|i| (i * i) as f64).collect();
        assert!(gradient(&grid, &f, &Control::new())
            .unwrap()
            .iter()
            .all(|g| g[0] == 0.0));
        assert!(hessian(&grid, &f, &Control::new())
            .unwrap()
            .iter()
            .all(|h| h[0] == 0.0 && h[3] == 0.0 && h[4] == 0.0));
        assert!(matches!(
            gradient(&grid, &f[..3], &Control::new()),
            Err(FilterError::Length { .. })
        ));
        assert!(gaussian_smooth(&grid, &f, f64::NAN, &Control::new()).is_err());
    }

    #[test]
    fn a_raised_flag_stops_every_filter() {
        let grid = Grid::unit(&[5, 6]).unwrap();
        let f = vec![1.0; 30];
        let flag = std::sync::atomic::AtomicBool::new(true);
        let c = Control::new().with_cancel(&flag);
        assert_eq!(
            gaussian_smooth(&grid, &f, 1.0, &c),
            Err(FilterError::Cancelled)
        );
        assert_eq!(gradient(&grid, &f, &c), Err(FilterError::Cancelled));
        assert_eq!(hessian(&grid, &f, &c), Err(FilterError::Cancelled));
    }

    #[test]
    fn normalisation_maps_to_the_unit_interval() {
        assert_eq!(normalize_unit(&[2.0, 4.0, 3.0]), vec![0.0, 1.0, 0.5]);
        assert_eq!(normalize_unit(&[7.0, 7.0]), vec![0.0, 0.0]);
    }
}
