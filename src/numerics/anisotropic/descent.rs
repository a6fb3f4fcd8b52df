//! Minimal paths of a tensor metric: the descent of [`crate::numerics::paths`]
//! with the Riemannian direction field (seed eq. 1.26)
//!
//! ```text
//! γ'(t) = −v / |v|,     v = M(γ)⁻¹ ∇U(γ),
//! ```
//!
//! not `−∇U`: for an anisotropic metric the two differ, and only `v` is
//! tangent to the geodesics. Everything else is the isotropic descent
//! (one code path): `∇U` interpolated from the upwind / centred cell
//! gradients, classical Runge–Kutta 4 at a step of at most half a cell, the
//! discrete steepest-descent fallback where the direction is undefined or
//! would climb `U` or cross a wall, a step budget, arrival within one cell of
//! a source. [`Riemannian`] supplies the three metric-dependent pieces:
//!
//! * the direction `−M⁻¹∇U` ([`DescentDirection`]), with `M` of the cell nearest to `x`;
//! * the length integrand `sqrt(dᵀ M d)` ([`CellCost::norm_at`]), so the
//!   geodesic length is the Riemannian `∫ sqrt(γ'ᵀ M γ')` (Simpson per segment);
//! * the gradient `M d / sqrt(dᵀ M d)` of the local solution `‖x − p‖_M`
//!   around a point source ([`CellCost::local_gradient`]).
//!
//! Walls are the wall cells of the field (`+inf` cost, and `U = +inf` there
//! in the solver's output), so a path never crosses one.

use super::tensor::TensorField;
use crate::numerics::eikonal::Source;
use crate::numerics::grid::Grid;
use crate::numerics::paths::{
    CellCost, DescentDirection, DescentOptions, DistanceMap, MinimalPath, PathError, SourceSet,
};

/// A tensor field seen by the generic descent: the direction `−M⁻¹∇U`, the
/// length integrand `sqrt(dᵀ M d)` and walls. Vectors are per storage axis
/// (axis 0 is the padding axis of a 2D grid, where every component is 0).
#[derive(Debug, Clone, Copy)]
pub struct Riemannian<'a> {
    grid: &'a Grid,
    metric: &'a TensorField,
}

impl<'a> Riemannian<'a> {
    /// Wraps the metric of `grid` (the field's dimension must be the grid's).
    pub fn new(grid: &'a Grid, metric: &'a TensorField) -> Self {
        Self { grid, metric }
    }

    /// `M` of cell `i` as a padded 3×3 matrix (zero row and column 0 in 2D).
    #[inline]
    fn matrix(&self, i: usize) -> [[f64; 3]; 3] {
        let m = self.metric.at(i);
        if m.len() == 3 {
            [[0.0; 3], [0.0, m[0], m[1]], [0.0, m[1], m[2]]]
        } else {
            [[m[0], m[1], m[2]], [m[1], m[3], m[4]], [m[2], m[4], m[5]]]
        }
    }

    /// `M⁻¹ g` for the SPD `M` of cell `i` (Cramer's rule; `None` if singular).
    fn solve(&self, i: usize, g: [f64; 3]) -> Option<[f64; 3]> {
        let m = self.metric.at(i);
        if m.len() == 3 {
            let det = m[0] * m[2] - m[1] * m[1];
            if !(det.is_finite() && det > 0.0) {
                return None;
            }
            return Some([
                0.0,
                (m[2] * g[1] - m[1] * g[2]) / det,
                (m[0] * g[2] - m[1] * g[1]) / det,
            ]);
        }
        let a = self.matrix(i);
        let det3 = |c: [[f64; 3]; 3]| {
            c[0][0] * (c[1][1] * c[2][2] - c[1][2] * c[2][1])
                - c[0][1] * (c[1][0] * c[2][2] - c[1][2] * c[2][0])
                + c[0][2] * (c[1][0] * c[2][1] - c[1][1] * c[2][0])
        };
        let det = det3(a);
        if !(det.is_finite() && det > 0.0) {
            return None;
        }
        let mut x = [0.0; 3];
        for (col, xc) in x.iter_mut().enumerate() {
            let mut b = a;
            for row in 0..3 {
                b[row][col] = g[row];
            }
            *xc = det3(b) / det;
        }
        Some(x)
    }

    /// `M d` at cell `i`.
    #[inline]
    fn apply(&self, i: usize, d: [f64; 3]) -> [f64; 3] {
        let a = self.matrix(i);
        [0, 1, 2].map(|r| a[r][0] * d[0] + a[r][1] * d[1] + a[r][2] * d[2])
    }
}

impl CellCost for Riemannian<'_> {
    /// A representative scalar cost `sqrt(tr M / d)` (`+inf` on walls); the
    /// descent itself uses [`CellCost::norm_at`] and [`CellCost::local_gradient`].
    fn cost_at(&self, i: usize) -> f64 {
        if self.metric.is_wall(i) {
            return f64::INFINITY;
        }
        let m = self.metric.at(i);
        let trace = if m.len() == 3 {
            m[0] + m[2]
        } else {
            m[0] + m[3] + m[5]
        };
        (trace / self.metric.ndim() as f64).sqrt()
    }

    /// `sqrt(dᵀ M d)`, `+inf` on walls.
    fn norm_at(&self, i: usize, d: [f64; 3]) -> f64 {
        if self.metric.is_wall(i) {
            return f64::INFINITY;
        }
        let md = self.apply(i, d);
        (d[0] * md[0] + d[1] * md[1] + d[2] * md[2]).max(0.0).sqrt()
    }

    /// `M d / sqrt(dᵀ M d)`: the gradient of `‖x − p‖_M`.
    fn local_gradient(&self, i: usize, d: [f64; 3]) -> Option<[f64; 3]> {
        if self.metric.is_wall(i) {
            return None;
        }
        let md = self.apply(i, d);
        let n = (d[0] * md[0] + d[1] * md[1] + d[2] * md[2]).max(0.0).sqrt();
        (n > 0.0 && n.is_finite()).then(|| md.map(|v| v / n))
    }
}

impl DescentDirection for Riemannian<'_> {
    /// `−M⁻¹∇U` with `M` of the cell nearest to `x`.
    fn direction(&self, x: [f64; 3], grad: [f64; 3]) -> Option<[f64; 3]> {
        let i = self
            .grid
            .linear(crate::numerics::eikonal::nearest_cell(self.grid, x));
        if self.metric.is_wall(i) {
            return None;
        }
        self.solve(i, grad).map(|v| v.map(|c| -c))
    }
}

/// The minimal path from `end` (index coordinates, axis 0 first) to the
/// nearest of `sources` on `distance` (the solution for `metric` on `grid`,
/// C order, `+inf` on walls and unreached cells), traced along `−M⁻¹∇U` by
/// [`DistanceMap::descend`]. `geodesic_length` is the Riemannian length.
pub fn minimal_path(
    grid: &Grid,
    metric: &TensorField,
    distance: &[f64],
    sources: &[Source],
    end: &[f64],
    options: &DescentOptions,
) -> Result<MinimalPath, PathError> {
    let riemannian = Riemannian::new(grid, metric);
    let set = SourceSet::new(grid, sources)?;
    let map = DistanceMap::new(grid, distance, &riemannian)?;
    map.descend(&set, end, &riemannian, options)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::numerics::anisotropic::{solve, TensorOptions, TensorProblem};
    use crate::numerics::Control;

    /// A constant metric: geodesics are straight segments, the Riemannian
    /// length is `sqrt((x − s)ᵀ M (x − s))`, and the path is not the one of
    /// `−∇U` (which bends towards the cheap axis).
    #[test]
    fn constant_metric_paths_are_straight_with_riemannian_length() {
        let grid = Grid::unit(&[61, 61]).unwrap();
        // Cheap along (1, 1): eigenvalue 1 there, 16 across.
        let m = crate::numerics::anisotropic::eigen_tensor(2, &[1.0, 16.0], &[1.0, 1.0]).unwrap();
        let metric = TensorField::constant(&grid, &m).unwrap();
        let sources = vec![Source::Point(vec![30.0, 30.0])];
        let problem = TensorProblem {
            grid: grid.clone(),
            metric: metric.clone(),
            sources: sources.clone(),
        };
        let out = solve(&problem, &TensorOptions::DEFAULT, &Control::new()).unwrap();
        let u: Vec<f64> = out.output.distance.iter().copied().collect();
        let end = [50.0, 42.0];
        let path = minimal_path(
            &grid,
            &metric,
            &u,
            &sources,
            &end,
            &DescentOptions::default(),
        )
        .unwrap();
        let d = [20.0, 12.0];
        let exact = (m[0] * d[0] * d[0] + 2.0 * m[1] * d[0] * d[1] + m[2] * d[1] * d[1]).sqrt();
        assert!(
            (path.geodesic_length - exact).abs() < 0.03 * exact,
            "length {} vs {exact}",
            path.geodesic_length
        );
        // Every vertex within a cell of the straight segment.
        let pts = path.index_points(&grid);
        let worst = pts
            .iter()
            .map(|p| {
                let (a, b) = (p[0] - 30.0, p[1] - 30.0);
                (a * d[1] - b * d[0]).abs() / (d[0] * d[0] + d[1] * d[1]).sqrt()
            })
            .fold(0.0, f64::max);
        assert!(worst < 1.0, "deviation {worst}");
        assert_eq!(pts.last().unwrap(), &end.to_vec());
    }
}
