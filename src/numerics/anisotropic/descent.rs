//! Minimal paths of a tensor metric: descent of the distance map along the
//! Riemannian gradient direction (seed eq. 1.26)
//!
//! ```text
//! γ'(t) = −v / |v|,     v = M(γ)⁻¹ ∇U(γ),
//! ```
//!
//! not along `−∇U`: for an anisotropic metric the two differ, and only `v`
//! is tangent to the geodesics. `∇U` is the multilinear interpolation of
//! the cell gradients (central differences, one-sided next to walls and
//! unreached cells), `M⁻¹` that of the nearest cell, and the curve is
//! integrated with Heun's method (second order) at a fixed step in cells.
//!
//! Robustness (as the isotropic paths): where the interpolated direction is
//! not finite, vanishes, would climb `U` or enter a wall, the step falls
//! back to the discrete descent (to the neighbour cell, 8 / 26-connected,
//! with the smallest `U`); the descent ends at a discrete minimum of `U` (a
//! source) or after a step budget, and says which.

use super::stencil::dual_index_metric;
use super::tensor::TensorField;
use crate::numerics::grid::Grid;

/// Options of [`minimal_path`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DescentOptions {
    /// Step length in cells (index units). Default 0.5.
    pub step: f64,
    /// Most steps before giving up. Default: 20 × the sum of the shape.
    pub max_steps: Option<usize>,
}

impl Default for DescentOptions {
    fn default() -> Self {
        Self {
            step: 0.5,
            max_steps: None,
        }
    }
}

/// A minimal path, from the start point to the source.
#[derive(Debug, Clone, PartialEq)]
pub struct MinimalPath {
    /// Points in index coordinates (caller's axes, axis 0 first).
    pub points: Vec<Vec<f64>>,
    /// Its Riemannian length `Σ ‖Δx‖_M` (physical units).
    pub length: f64,
    /// True when the descent ended at a minimum of `U` (a source).
    pub reached_source: bool,
    /// Steps that fell back to the discrete descent.
    pub discrete_steps: usize,
}

/// Why a descent could not start.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DescentError {
    /// The distance map does not have one value per cell.
    #[error("the distance map has {got} values but the grid has {expected} cells")]
    Length {
        /// Values given.
        got: usize,
        /// Cells of the grid.
        expected: usize,
    },
    /// The start point is outside the grid or was not reached by the front.
    #[error("start point {0:?}: {1}")]
    Start(Vec<f64>, String),
    /// The step is not a positive finite number.
    #[error("step {0} must be finite and > 0")]
    Step(f64),
}

/// Descends `distance` (the solution for `metric` on `grid`, C order) from
/// `start` (index coordinates) to the source.
pub fn minimal_path(
    grid: &Grid,
    metric: &TensorField,
    distance: &[f64],
    start: &[f64],
    options: &DescentOptions,
) -> Result<MinimalPath, DescentError> {
    if distance.len() != grid.len() {
        return Err(DescentError::Length {
            got: distance.len(),
            expected: grid.len(),
        });
    }
    if !(options.step.is_finite() && options.step > 0.0) {
        return Err(DescentError::Step(options.step));
    }
    let p = grid
        .point3(start)
        .map_err(|e| DescentError::Start(start.to_vec(), e.to_string()))?;
    if !grid.contains_point3(p) {
        return Err(DescentError::Start(
            start.to_vec(),
            "outside the grid".into(),
        ));
    }
    let d = Descent {
        grid,
        metric,
        u: distance,
    };
    if !d.u[d.nearest(p)].is_finite() {
        return Err(DescentError::Start(
            start.to_vec(),
            "the front did not reach it (wall or unreached cell)".into(),
        ));
    }
    let shape = grid.shape3();
    let budget = options
        .max_steps
        .unwrap_or(20 * (shape[0] + shape[1] + shape[2]));
    let mut x = p;
    let mut pts = vec![x];
    let mut length = 0.0;
    let mut discrete_steps = 0;
    let mut reached = false;
    for _ in 0..budget {
        let here = d.nearest(x);
        if d.is_minimum(here) && d.interp(x) <= d.u[here] + 1e-12 {
            // Land on the source cell itself.
            let c = grid.unravel(here).map(|v| v as f64);
            if c != x {
                length += d.seg_len(x, c);
                x = c;
                pts.push(x);
            }
            reached = true;
            break;
        }
        let next = d.heun(x, options.step).filter(|y| {
            grid.contains_point3(*y) && d.u[d.nearest(*y)].is_finite() && d.interp(*y) < d.interp(x)
        });
        let y = match next {
            Some(y) => y,
            None => {
                discrete_steps += 1;
                match d.best_neighbour(here) {
                    Some(c) => grid.unravel(c).map(|v| v as f64),
                    None => {
                        reached = true;
                        break;
                    }
                }
            }
        };
        length += d.seg_len(x, y);
        x = y;
        pts.push(x);
    }
    let off = 3 - grid.ndim();
    Ok(MinimalPath {
        points: pts.iter().map(|q| q[off..].to_vec()).collect(),
        length,
        reached_source: reached,
        discrete_steps,
    })
}

struct Descent<'a> {
    grid: &'a Grid,
    metric: &'a TensorField,
    u: &'a [f64],
}

impl Descent<'_> {
    fn nearest(&self, p: [f64; 3]) -> usize {
        self.grid
            .linear(crate::numerics::eikonal::nearest_cell(self.grid, p))
    }

    fn neighbours(&self, i: usize) -> Vec<usize> {
        let s = self.grid.shape3();
        let c = self.grid.unravel(i);
        let mut out = Vec::with_capacity(26);
        for a in -1i64..=1 {
            for b in -1i64..=1 {
                for e in -1i64..=1 {
                    if a == 0 && b == 0 && e == 0 {
                        continue;
                    }
                    let y = [c[0] as i64 + a, c[1] as i64 + b, c[2] as i64 + e];
                    if (0..3).all(|k| y[k] >= 0 && (y[k] as usize) < s[k]) {
                        out.push(
                            self.grid
                                .linear([y[0] as usize, y[1] as usize, y[2] as usize]),
                        );
                    }
                }
            }
        }
        out
    }

    fn is_minimum(&self, i: usize) -> bool {
        self.neighbours(i).iter().all(|&j| self.u[j] >= self.u[i])
    }

    fn best_neighbour(&self, i: usize) -> Option<usize> {
        self.neighbours(i)
            .into_iter()
            .filter(|&j| self.u[j] < self.u[i])
            .min_by(|&a, &b| self.u[a].total_cmp(&self.u[b]))
    }

    /// Index-unit gradient of `U` at a cell: central differences, one-sided
    /// where a neighbour is infinite or outside.
    fn cell_grad(&self, i: usize) -> [f64; 3] {
        let s = self.grid.shape3();
        let st = self.grid.strides3();
        let c = self.grid.unravel(i);
        let mut g = [0.0; 3];
        for k in 0..3 {
            if s[k] < 2 {
                continue;
            }
            let lo = (c[k] > 0)
                .then(|| self.u[i - st[k]])
                .filter(|v| v.is_finite());
            let hi = (c[k] + 1 < s[k])
                .then(|| self.u[i + st[k]])
                .filter(|v| v.is_finite());
            g[k] = match (lo, hi) {
                (Some(a), Some(b)) => 0.5 * (b - a),
                (Some(a), None) => self.u[i] - a,
                (None, Some(b)) => b - self.u[i],
                (None, None) => 0.0,
            };
        }
        g
    }

    /// Multilinear interpolation over the `2^d` cells around `p` of a per-cell
    /// quantity; cells with infinite `U` are skipped (weights renormalised).
    fn interp_with<const N: usize>(
        &self,
        p: [f64; 3],
        f: impl Fn(usize) -> [f64; N],
    ) -> Option<[f64; N]> {
        let s = self.grid.shape3();
        let mut base = [0usize; 3];
        let mut frac = [0.0; 3];
        for k in 0..3 {
            let fl = p[k].floor().clamp(0.0, (s[k].max(2) - 2) as f64);
            base[k] = if s[k] == 1 { 0 } else { fl as usize };
            frac[k] = if s[k] == 1 { 0.0 } else { p[k] - fl };
        }
        let mut acc = [0.0; N];
        let mut wsum = 0.0;
        for corner in 0..8 {
            let mut idx = base;
            let mut w = 1.0;
            for k in 0..3 {
                let bit = (corner >> k) & 1;
                if s[k] == 1 {
                    if bit == 1 {
                        w = 0.0;
                    }
                    continue;
                }
                idx[k] += bit;
                w *= if bit == 1 { frac[k] } else { 1.0 - frac[k] };
            }
            if w <= 0.0 {
                continue;
            }
            let i = self.grid.linear(idx);
            if !self.u[i].is_finite() {
                continue;
            }
            let v = f(i);
            for n in 0..N {
                acc[n] += w * v[n];
            }
            wsum += w;
        }
        (wsum > 1e-9).then(|| acc.map(|a| a / wsum))
    }

    fn interp(&self, p: [f64; 3]) -> f64 {
        self.interp_with(p, |i| [self.u[i]])
            .map_or(f64::INFINITY, |v| v[0])
    }

    /// The unit descent direction `−D̃∇U / |D̃∇U|` at `p` (index units).
    fn direction(&self, p: [f64; 3]) -> Option<[f64; 3]> {
        let g = self.interp_with(p, |i| self.cell_grad(i))?;
        let i = self.nearest(p);
        let h = self.grid.spacing();
        let dual = dual_index_metric(self.metric.at(i), h);
        let off = 3 - self.grid.ndim();
        let mut v = [0.0; 3];
        if dual.len() == 3 {
            v[1] = -(dual[0] * g[1] + dual[1] * g[2]);
            v[2] = -(dual[1] * g[1] + dual[2] * g[2]);
        } else {
            let m = [
                [dual[0], dual[1], dual[2]],
                [dual[1], dual[3], dual[4]],
                [dual[2], dual[4], dual[5]],
            ];
            for a in 0..3 {
                v[a] = -(m[a][0] * g[0] + m[a][1] * g[1] + m[a][2] * g[2]);
            }
        }
        let _ = off;
        let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        (n.is_finite() && n > 1e-12).then(|| v.map(|c| c / n))
    }

    fn heun(&self, x: [f64; 3], step: f64) -> Option<[f64; 3]> {
        let d1 = self.direction(x)?;
        let mid = [0, 1, 2].map(|k| x[k] + step * d1[k]);
        let s = self.grid.shape3();
        let clamp = |q: [f64; 3]| [0, 1, 2].map(|k| q[k].clamp(0.0, (s[k] - 1) as f64));
        let d2 = self.direction(clamp(mid)).unwrap_or(d1);
        let mut d = [0, 1, 2].map(|k| d1[k] + d2[k]);
        let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        if n.is_nan() || n <= 1e-12 {
            d = d1;
        } else {
            d = d.map(|c| c / n);
        }
        Some([0, 1, 2].map(|k| x[k] + step * d[k]))
    }

    /// `‖y − x‖_M` in physical units with the metric of the midpoint's cell.
    fn seg_len(&self, x: [f64; 3], y: [f64; 3]) -> f64 {
        let mid = [0, 1, 2].map(|k| 0.5 * (x[k] + y[k]));
        let m = super::fast_marching::index_metric(self.grid, self.metric.at(self.nearest(mid)));
        let z = [0, 1, 2].map(|k| y[k] - x[k]);
        let mut s = 0.0;
        for a in 0..3 {
            for b in 0..3 {
                s += z[a] * m[a][b] * z[b];
            }
        }
        s.max(0.0).sqrt()
    }
}
