//! Regular 2D and 3D grids with a per-axis spacing.
//!
//! A grid of shape `(n0, n1[, n2])` samples the box `[0, (n0-1) h0] x ...`;
//! cell `(i, j[, k])` sits at the physical point `(i h0, j h1[, k h2])`.
//! Internally every grid is stored as 3D: a 2D grid of shape `(n0, n1)` is
//! the 3D grid `(1, n0, n1)` with a dummy spacing of 1 on the padded axis.
//! Linear indices are in C (row-major) order, the order of `ndarray`'s
//! standard layout and of NPY files.

/// The largest number of cells a grid may have: linear indices fit in `u32`,
/// with the top 16 values left free for the per-cell tags of
/// [`crate::numerics::heap`].
pub const MAX_CELLS: usize = u32::MAX as usize - 16;

/// Why a grid description was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GridError {
    /// Only 2D and 3D grids are supported.
    #[error("the grid must be 2D or 3D, got {0} dimensions")]
    Dimensions(usize),
    /// An axis has no cells.
    #[error("axis {axis} has length 0")]
    EmptyAxis {
        /// The empty axis.
        axis: usize,
    },
    /// More cells than [`MAX_CELLS`].
    #[error("the grid has {0} cells, more than the limit of {MAX_CELLS}")]
    TooLarge(u128),
    /// The spacing does not have one entry per axis.
    #[error("spacing has {got} entries but the grid has {expected} axes")]
    SpacingLength {
        /// Entries given.
        got: usize,
        /// Axes of the grid.
        expected: usize,
    },
    /// A spacing entry is zero, negative or not finite.
    #[error("spacing[{axis}] = {value} must be finite and > 0")]
    Spacing {
        /// The offending axis.
        axis: usize,
        /// The value given.
        value: f64,
    },
    /// A point has the wrong number of coordinates.
    #[error("a point has {got} coordinates but the grid has {expected} axes")]
    PointLength {
        /// Coordinates given.
        got: usize,
        /// Axes of the grid.
        expected: usize,
    },
}

/// Shape and spacing of a 2D or 3D regular grid.
///
/// # Examples
/// ```
/// use geodex::numerics::Grid;
/// let g = Grid::new(&[3, 4], &[1.0, 0.5])?;
/// assert_eq!(g.ndim(), 2);
/// assert_eq!(g.shape(), &[3, 4]);
/// assert_eq!(g.shape3(), [1, 3, 4]);
/// assert_eq!(g.len(), 12);
/// assert_eq!(g.linear([0, 2, 1]), 9);
/// assert_eq!(g.unravel(9), [0, 2, 1]);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct Grid {
    ndim: usize,
    shape: [usize; 3],
    spacing: [f64; 3],
    strides: [usize; 3],
}

impl Grid {
    /// A grid of the given shape (2 or 3 axes) and per-axis spacing.
    pub fn new(shape: &[usize], spacing: &[f64]) -> Result<Self, GridError> {
        let ndim = shape.len();
        if !(2..=3).contains(&ndim) {
            return Err(GridError::Dimensions(ndim));
        }
        if spacing.len() != ndim {
            return Err(GridError::SpacingLength {
                got: spacing.len(),
                expected: ndim,
            });
        }
        if let Some(axis) = shape.iter().position(|&n| n == 0) {
            return Err(GridError::EmptyAxis { axis });
        }
        let cells = shape
            .iter()
            .fold(1u128, |a, &n| a.saturating_mul(n as u128));
        if cells > MAX_CELLS as u128 {
            return Err(GridError::TooLarge(cells));
        }
        for (axis, &h) in spacing.iter().enumerate() {
            if !(h.is_finite() && h > 0.0) {
                return Err(GridError::Spacing { axis, value: h });
            }
        }
        let off = 3 - ndim;
        let mut s = [1usize; 3];
        let mut h = [1.0f64; 3];
        s[off..].copy_from_slice(shape);
        h[off..].copy_from_slice(spacing);
        let strides = [s[1] * s[2], s[2], 1];
        Ok(Self {
            ndim,
            shape: s,
            spacing: h,
            strides,
        })
    }

    /// A grid with unit spacing.
    pub fn unit(shape: &[usize]) -> Result<Self, GridError> {
        Self::new(shape, &vec![1.0; shape.len()])
    }

    /// Number of axes the caller sees (2 or 3).
    #[inline]
    pub fn ndim(&self) -> usize {
        self.ndim
    }

    /// The shape as the caller gave it.
    #[inline]
    pub fn shape(&self) -> &[usize] {
        &self.shape[3 - self.ndim..]
    }

    /// The spacing as the caller gave it.
    #[inline]
    pub fn spacing(&self) -> &[f64] {
        &self.spacing[3 - self.ndim..]
    }

    /// The shape padded to 3 axes (axis 0 has length 1 for a 2D grid).
    #[inline]
    pub fn shape3(&self) -> [usize; 3] {
        self.shape
    }

    /// The spacing padded to 3 axes (1 on the padded axis of a 2D grid).
    #[inline]
    pub fn spacing3(&self) -> [f64; 3] {
        self.spacing
    }

    /// C-order strides of the padded 3D shape.
    #[inline]
    pub fn strides3(&self) -> [usize; 3] {
        self.strides
    }

    /// Total number of cells.
    #[inline]
    pub fn len(&self) -> usize {
        self.shape[0] * self.shape[1] * self.shape[2]
    }

    /// Always false: a grid has at least one cell.
    #[inline]
    pub fn is_empty(&self) -> bool {
        false
    }

    /// Linear (C-order) index of a padded 3D index.
    #[inline]
    pub fn linear(&self, idx: [usize; 3]) -> usize {
        idx[0] * self.strides[0] + idx[1] * self.strides[1] + idx[2]
    }

    /// Padded 3D index of a linear index.
    #[inline]
    pub fn unravel(&self, i: usize) -> [usize; 3] {
        let a = i / self.strides[0];
        let r = i - a * self.strides[0];
        let b = r / self.strides[1];
        [a, b, r - b * self.strides[1]]
    }

    /// Pads a caller point (2 or 3 coordinates, index units) to 3 coordinates.
    pub fn point3(&self, p: &[f64]) -> Result<[f64; 3], GridError> {
        if p.len() != self.ndim {
            return Err(GridError::PointLength {
                got: p.len(),
                expected: self.ndim,
            });
        }
        let mut q = [0.0; 3];
        q[3 - self.ndim..].copy_from_slice(p);
        Ok(q)
    }

    /// Pads a caller cell index (2 or 3 entries) to 3 entries.
    pub fn index3(&self, p: &[usize]) -> Result<[usize; 3], GridError> {
        if p.len() != self.ndim {
            return Err(GridError::PointLength {
                got: p.len(),
                expected: self.ndim,
            });
        }
        let mut q = [0usize; 3];
        q[3 - self.ndim..].copy_from_slice(p);
        Ok(q)
    }

    /// True if a padded point lies in the closed box `[0, n_k - 1]` on every axis.
    pub fn contains_point3(&self, p: [f64; 3]) -> bool {
        (0..3).all(|k| p[k].is_finite() && p[k] >= 0.0 && p[k] <= (self.shape[k] - 1) as f64)
    }

    /// True if a padded cell index is inside the grid.
    pub fn contains_index3(&self, p: [usize; 3]) -> bool {
        (0..3).all(|k| p[k] < self.shape[k])
    }

    /// Physical (spacing-weighted) Euclidean distance between two padded points.
    #[inline]
    pub fn physical_distance3(&self, a: [f64; 3], b: [f64; 3]) -> f64 {
        let mut s = 0.0;
        for k in 0..3 {
            let d = (a[k] - b[k]) * self.spacing[k];
            s += d * d;
        }
        s.sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rejects_bad_shapes_and_spacings() {
        assert_eq!(Grid::unit(&[4]), Err(GridError::Dimensions(1)));
        assert_eq!(Grid::unit(&[2, 2, 2, 2]), Err(GridError::Dimensions(4)));
        assert_eq!(Grid::unit(&[3, 0]), Err(GridError::EmptyAxis { axis: 1 }));
        assert!(matches!(
            Grid::new(&[3, 3], &[1.0, 0.0]),
            Err(GridError::Spacing { axis: 1, .. })
        ));
        assert!(matches!(
            Grid::new(&[3, 3], &[f64::NAN, 1.0]),
            Err(GridError::Spacing { axis: 0, .. })
        ));
        assert!(matches!(
            Grid::unit(&[100_000, 100_000, 100]),
            Err(GridError::TooLarge(_))
        ));
    }

    #[test]
    fn linear_index_round_trips_in_3d() {
        let g = Grid::unit(&[3, 4, 5]).unwrap();
        for i in 0..g.len() {
            assert_eq!(g.linear(g.unravel(i)), i);
        }
        assert_eq!(g.linear([2, 3, 4]), 59);
    }
}
