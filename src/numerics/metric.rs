//! Isotropic metrics: a cost per unit length `W(x) > 0` on every cell.
//!
//! The geodesic length of a curve γ is `L(γ) = ∫ W(γ(t)) |γ'(t)| dt` (seed
//! eq. 1.2), and the distance map solves `|∇U| = W` (the eikonal equation).
//! A speed `F = 1/W` may be given instead. Cells with `W = +inf` (or `F = 0`)
//! and cells marked in the obstacle mask are walls: they are never entered
//! and keep `U = +inf`.

use std::borrow::Cow;

use super::grid::Grid;

/// Why a cost field was refused. Cell indices are in array index order.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MetricError {
    /// The field does not have one value per cell.
    #[error("the field has {got} values but the grid has {expected} cells")]
    Length {
        /// Values given.
        got: usize,
        /// Cells in the grid.
        expected: usize,
    },
    /// A value is NaN, negative or zero (for a cost), or NaN, negative or infinite (for a speed).
    #[error("cell {index:?} has {kind} {value}, which is not allowed: {reason}")]
    BadValue {
        /// The cell, in array index order.
        index: Vec<usize>,
        /// `"cost"` or `"speed"`.
        kind: &'static str,
        /// The value found.
        value: f64,
        /// Why it is refused.
        reason: &'static str,
    },
    /// The constant is not a valid cost.
    #[error("constant cost {0} must be finite and > 0")]
    Constant(f64),
    /// The obstacle mask does not have one entry per cell.
    #[error("the obstacle mask has {got} values but the grid has {expected} cells")]
    MaskLength {
        /// Values given.
        got: usize,
        /// Cells in the grid.
        expected: usize,
    },
}

/// Whether the numbers of a field are a cost `W` or a speed `F = 1/W`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Interpretation {
    /// Cost per unit length `W` (the default).
    #[default]
    Cost,
    /// Speed `F = 1/W`.
    Speed,
}

/// Cell values, borrowed or owned, in C order.
#[derive(Debug, Clone)]
pub enum CostValues<'a> {
    /// The same cost everywhere.
    Constant(f64),
    /// Per-cell single precision values.
    F32(Cow<'a, [f32]>),
    /// Per-cell double precision values.
    F64(Cow<'a, [f64]>),
}

/// A validated isotropic cost on a grid: every cell has `W` in `(0, +inf]`.
///
/// # Examples
/// ```
/// use geodex::numerics::{Grid, IsotropicCost};
/// use geodex::numerics::metric::{CostValues, Interpretation};
/// let grid = Grid::unit(&[2, 2])?;
/// let speed = vec![1.0f32, 2.0, 0.0, 4.0];
/// let cost = IsotropicCost::new(&grid, CostValues::F32(speed.into()), Interpretation::Speed, None)?;
/// assert_eq!(cost.at(1), 0.5);
/// assert!(cost.is_wall(2));
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Debug, Clone)]
pub struct IsotropicCost<'a> {
    values: CostValues<'a>,
    interpretation: Interpretation,
    obstacles: Option<Cow<'a, [bool]>>,
}

impl<'a> IsotropicCost<'a> {
    /// The constant cost `W = value` without obstacles.
    pub fn constant(value: f64) -> Result<Self, MetricError> {
        if !(value.is_finite() && value > 0.0) {
            return Err(MetricError::Constant(value));
        }
        Ok(Self {
            values: CostValues::Constant(value),
            interpretation: Interpretation::Cost,
            obstacles: None,
        })
    }

    /// Validates a field against a grid: one value per cell; a cost must be
    /// `> 0` (NaN refused, `+inf` is a wall); a speed must be finite and `>= 0`
    /// (`0` is a wall). The obstacle mask, if any, marks walls with `true`.
    pub fn new(
        grid: &Grid,
        values: CostValues<'a>,
        interpretation: Interpretation,
        obstacles: Option<Cow<'a, [bool]>>,
    ) -> Result<Self, MetricError> {
        let n = grid.len();
        if let Some(mask) = &obstacles {
            if mask.len() != n {
                return Err(MetricError::MaskLength {
                    got: mask.len(),
                    expected: n,
                });
            }
        }
        let check = |i: usize, v: f64| -> Result<(), MetricError> {
            let bad = |reason| MetricError::BadValue {
                index: unravel_user(grid, i),
                kind: match interpretation {
                    Interpretation::Cost => "cost",
                    Interpretation::Speed => "speed",
                },
                value: v,
                reason,
            };
            match interpretation {
                Interpretation::Cost if v.is_nan() => Err(bad("a cost must not be NaN")),
                Interpretation::Cost if v <= 0.0 => Err(bad(
                    "a cost must be > 0 (use +inf or the obstacle mask for walls)",
                )),
                Interpretation::Speed if v.is_nan() => Err(bad("a speed must not be NaN")),
                Interpretation::Speed if v < 0.0 => Err(bad("a speed must be >= 0")),
                Interpretation::Speed if v.is_infinite() => Err(bad("a speed must be finite")),
                _ => Ok(()),
            }
        };
        match &values {
            CostValues::Constant(v) => {
                check(0, *v)?;
            }
            CostValues::F32(s) => {
                if s.len() != n {
                    return Err(MetricError::Length {
                        got: s.len(),
                        expected: n,
                    });
                }
                for (i, &v) in s.iter().enumerate() {
                    check(i, v as f64)?;
                }
            }
            CostValues::F64(s) => {
                if s.len() != n {
                    return Err(MetricError::Length {
                        got: s.len(),
                        expected: n,
                    });
                }
                for (i, &v) in s.iter().enumerate() {
                    check(i, v)?;
                }
            }
        }
        Ok(Self {
            values,
            interpretation,
            obstacles,
        })
    }

    /// The cost `W` of cell `i` (linear index); `+inf` on walls.
    #[inline]
    pub fn at(&self, i: usize) -> f64 {
        if let Some(mask) = &self.obstacles {
            if mask[i] {
                return f64::INFINITY;
            }
        }
        let raw = match &self.values {
            CostValues::Constant(v) => *v,
            CostValues::F32(s) => s[i] as f64,
            CostValues::F64(s) => s[i],
        };
        match self.interpretation {
            Interpretation::Cost => raw,
            Interpretation::Speed => 1.0 / raw,
        }
    }

    /// Asks the processor to bring the cost of cell `i` into the cache (a
    /// hint: nothing for a constant cost, an index out of range or on other
    /// architectures than x86-64).
    #[inline(always)]
    pub fn prefetch(&self, i: usize) {
        match &self.values {
            CostValues::Constant(_) => {}
            CostValues::F32(s) => super::prefetch::prefetch(s, i),
            CostValues::F64(s) => super::prefetch::prefetch(s, i),
        }
    }

    /// True if cell `i` can never be entered.
    #[inline]
    pub fn is_wall(&self, i: usize) -> bool {
        self.at(i) == f64::INFINITY
    }

    /// The largest finite cost (used for Lipschitz bounds); `None` if every cell is a wall.
    pub fn max_finite(&self, grid: &Grid) -> Option<f64> {
        (0..grid.len())
            .map(|i| self.at(i))
            .filter(|v| v.is_finite())
            .reduce(f64::max)
    }

    /// True when the cost is the same on every cell and there are no walls.
    pub fn is_uniform(&self) -> bool {
        matches!(self.values, CostValues::Constant(_)) && self.obstacles.is_none()
    }

    /// The cost of every cell when it is uniform ([`IsotropicCost::is_uniform`]).
    pub fn uniform_value(&self) -> Option<f64> {
        self.is_uniform().then(|| self.at(0))
    }
}

/// A linear index as the caller's (2D or 3D) array index.
pub fn unravel_user(grid: &Grid, i: usize) -> Vec<usize> {
    let idx = grid.unravel(i);
    idx[3 - grid.ndim()..].to_vec()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refuses_nan_and_negative_costs_naming_the_cell() {
        let grid = Grid::unit(&[2, 3]).unwrap();
        let v = vec![1.0, 1.0, 1.0, 1.0, f64::NAN, 1.0];
        let err = IsotropicCost::new(&grid, CostValues::F64(v.into()), Interpretation::Cost, None)
            .unwrap_err();
        assert!(matches!(err, MetricError::BadValue { ref index, .. } if index == &vec![1, 1]));
        let v = vec![1.0, -1.0, 1.0, 1.0, 1.0, 1.0];
        let err = IsotropicCost::new(&grid, CostValues::F64(v.into()), Interpretation::Cost, None)
            .unwrap_err();
        assert!(matches!(err, MetricError::BadValue { ref index, .. } if index == &vec![0, 1]));
    }

    #[test]
    fn infinite_cost_and_mask_are_walls() {
        let grid = Grid::unit(&[1, 3]).unwrap();
        let v = vec![1.0, f64::INFINITY, 2.0];
        let mask = vec![false, false, true];
        let c = IsotropicCost::new(
            &grid,
            CostValues::F64(v.into()),
            Interpretation::Cost,
            Some(mask.into()),
        )
        .unwrap();
        assert!(!c.is_wall(0));
        assert!(c.is_wall(1));
        assert!(c.is_wall(2));
        assert_eq!(c.max_finite(&grid), Some(1.0));
    }
}
