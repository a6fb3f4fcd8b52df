//! Turning [`Source`]s into the initial front of a solver.
//!
//! A point source `p` (index coordinates, possibly between cells) freezes
//! every non-wall cell `x` with `|x - p| <= r` (index units) and each of the
//! `2^d` cells around `p` at the exact local value `U(x) = W(p) |x - p|_h`,
//! where `|.|_h` is the physical (spacing-weighted) length and `W(p)` the cost
//! of the cell nearest to `p`. This is exact for a locally constant cost and
//! removes the `O(h)` bias of rounding `p` to a cell. Cells whose segment to
//! `p` crosses a wall are not initialised, so nothing leaks through walls.

use super::{EikonalError, EikonalProblem, Source};
use crate::numerics::grid::Grid;
use crate::numerics::metric::IsotropicCost;
use crate::numerics::Control;

/// Seed cells between two polls of the cancel flag.
const POLL_CELLS: usize = 1 << 16;

/// A cell whose value is prescribed before the solve starts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SeedCell {
    /// Linear index.
    pub index: usize,
    /// Prescribed value of `U`.
    pub value: f64,
    /// Index of the source it belongs to.
    pub label: i32,
}

/// A point source, kept for source factoring.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SeedPoint {
    /// Position in padded 3D index coordinates.
    pub position: [f64; 3],
    /// Index of the source.
    pub label: i32,
    /// The cost `W(p)` used for the local solution.
    pub cost: f64,
}

/// The cells to freeze first, and the point sources (for factoring).
#[derive(Debug, Clone, Default)]
pub struct InitialFront {
    /// Seed cells, one per linear index (the smallest value wins).
    pub cells: Vec<SeedCell>,
    /// Point sources in input order.
    pub points: Vec<SeedPoint>,
}

impl InitialFront {
    /// Validates the sources of `problem` and builds the initial front.
    ///
    /// Errors name the source: outside the grid, on a wall, a wrong number of
    /// coordinates, non-finite values.
    /// Polls `control` every [`POLL_CELLS`] seed cells: a mask of millions
    /// of cells as sources takes a while to seed.
    pub fn build(
        problem: &EikonalProblem<'_>,
        radius: f64,
        control: &Control<'_>,
    ) -> Result<Self, EikonalError> {
        if problem.sources.is_empty() {
            return Err(EikonalError::NoSources);
        }
        if problem.sources.len() > i32::MAX as usize {
            return Err(EikonalError::Option {
                field: "sources",
                reason: "too many sources".into(),
            });
        }
        let grid = &problem.grid;
        let cost = &problem.cost;
        // Every candidate, then the smallest value per cell (sort + dedup:
        // a hash map of millions of cells was the slow part of seeding).
        let mut all: Vec<SeedCell> = Vec::new();
        let mut points = Vec::new();
        let mut put = |c: SeedCell| all.push(c);
        for (index, source) in problem.sources.iter().enumerate() {
            let label = index as i32;
            let err = |reason: String| EikonalError::Source { index, reason };
            match source {
                Source::Point(p) => {
                    let p3 = grid.point3(p).map_err(|e| err(e.to_string()))?;
                    if !grid.contains_point3(p3) {
                        return Err(err(format!(
                            "point {p:?} is outside the grid of shape {:?} (index coordinates, axis 0 first)",
                            grid.shape()
                        )));
                    }
                    let nearest = nearest_cell(grid, p3);
                    let w = cost.at(grid.linear(nearest));
                    if !w.is_finite() {
                        return Err(err(format!("point {p:?} lies on an obstacle")));
                    }
                    points.push(SeedPoint {
                        position: p3,
                        label,
                        cost: w,
                    });
                    let mut any = false;
                    for cell in cells_near(grid, p3, radius) {
                        let i = grid.linear(cell);
                        let x = cell.map(|c| c as f64);
                        if !cost.at(i).is_finite() || crosses_wall(grid, cost, p3, x) {
                            continue;
                        }
                        any = true;
                        put(SeedCell {
                            index: i,
                            value: w * grid.physical_distance3(x, p3),
                            label,
                        });
                    }
                    if !any {
                        return Err(err(format!("point {p:?} lies on an obstacle")));
                    }
                }
                Source::Cells { cells, values } => {
                    if cells.is_empty() {
                        return Err(err("the cell list is empty".into()));
                    }
                    if let Some(v) = values {
                        if v.len() != cells.len() {
                            return Err(err(format!(
                                "{} values for {} cells",
                                v.len(),
                                cells.len()
                            )));
                        }
                    }
                    for (k, c) in cells.iter().enumerate() {
                        if k % POLL_CELLS == POLL_CELLS - 1 && control.is_cancelled() {
                            return Err(EikonalError::Cancelled);
                        }
                        let c3 = grid
                            .index3(c)
                            .map_err(|e| err(format!("cells[{k}]: {e}")))?;
                        if !grid.contains_index3(c3) {
                            return Err(err(format!(
                                "cells[{k}] = {c:?} is outside the grid of shape {:?}",
                                grid.shape()
                            )));
                        }
                        let i = grid.linear(c3);
                        if !cost.at(i).is_finite() {
                            return Err(err(format!("cells[{k}] = {c:?} lies on an obstacle")));
                        }
                        let value = values.as_ref().map_or(0.0, |v| v[k]);
                        if !value.is_finite() {
                            return Err(err(format!("values[{k}] = {value} is not finite")));
                        }
                        put(SeedCell {
                            index: i,
                            value,
                            label,
                        });
                    }
                }
            }
        }
        if control.is_cancelled() {
            return Err(EikonalError::Cancelled);
        }
        // Stable: among equal values at one cell, the first source wins.
        all.sort_by(|a, b| a.index.cmp(&b.index).then(a.value.total_cmp(&b.value)));
        all.dedup_by_key(|c| c.index);
        Ok(Self { cells: all, points })
    }
}

/// Validates stop targets and returns their nearest cells (linear indices).
pub fn target_cells(grid: &Grid, targets: &[Vec<f64>]) -> Result<Vec<usize>, EikonalError> {
    targets
        .iter()
        .enumerate()
        .map(|(index, t)| {
            let p3 = grid.point3(t).map_err(|e| EikonalError::Target {
                index,
                reason: e.to_string(),
            })?;
            if !grid.contains_point3(p3) {
                return Err(EikonalError::Target {
                    index,
                    reason: format!(
                        "point {t:?} is outside the grid of shape {:?}",
                        grid.shape()
                    ),
                });
            }
            Ok(grid.linear(nearest_cell(grid, p3)))
        })
        .collect()
}

/// The cell nearest to a padded point inside the grid box.
pub fn nearest_cell(grid: &Grid, p: [f64; 3]) -> [usize; 3] {
    let s = grid.shape3();
    let mut c = [0usize; 3];
    for k in 0..3 {
        c[k] = (p[k].round().max(0.0) as usize).min(s[k] - 1);
    }
    c
}

/// Cells within `radius` (index units) of `p`, plus the `2^d` cells around it.
fn cells_near(grid: &Grid, p: [f64; 3], radius: f64) -> Vec<[usize; 3]> {
    let s = grid.shape3();
    let mut lo = [0usize; 3];
    let mut hi = [0usize; 3];
    for k in 0..3 {
        let r = if s[k] == 1 { 0.0 } else { radius };
        lo[k] = ((p[k] - r).floor().max(0.0) as usize).min(p[k].floor() as usize);
        hi[k] = (((p[k] + r).ceil().max(0.0) as usize).max(p[k].ceil() as usize)).min(s[k] - 1);
    }
    let mut out = Vec::new();
    for a in lo[0]..=hi[0] {
        for b in lo[1]..=hi[1] {
            for c in lo[2]..=hi[2] {
                let x = [a as f64, b as f64, c as f64];
                let d2: f64 = (0..3).map(|k| (x[k] - p[k]).powi(2)).sum();
                let corner = (0..3).all(|k| (x[k] - p[k]).abs() < 1.0);
                if corner || d2 <= radius * radius + 1e-12 {
                    out.push([a, b, c]);
                }
            }
        }
    }
    out
}

/// True if the segment from `p` to cell centre `x` passes through a wall cell.
fn crosses_wall(grid: &Grid, cost: &IsotropicCost<'_>, p: [f64; 3], x: [f64; 3]) -> bool {
    const STEPS: usize = 16;
    (1..STEPS).any(|s| {
        let t = s as f64 / STEPS as f64;
        let q = [
            p[0] + t * (x[0] - p[0]),
            p[1] + t * (x[1] - p[1]),
            p[2] + t * (x[2] - p[2]),
        ];
        !cost.at(grid.linear(nearest_cell(grid, q))).is_finite()
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::numerics::metric::{CostValues, Interpretation};

    fn problem(shape: &[usize], sources: Vec<Source>) -> EikonalProblem<'static> {
        EikonalProblem {
            grid: Grid::unit(shape).unwrap(),
            cost: IsotropicCost::constant(2.0).unwrap(),
            sources,
        }
    }

    #[test]
    fn off_grid_point_gets_exact_values_on_its_corners() {
        // Exact local solution: U(x) = W |x - p| with W = 2.
        let p = problem(&[4, 4], vec![Source::Point(vec![1.5, 1.25])]);
        let f = InitialFront::build(&p, 0.0, &Control::new()).unwrap();
        assert_eq!(f.cells.len(), 4);
        for c in &f.cells {
            let x = p.grid.unravel(c.index);
            let d = ((x[1] as f64 - 1.5).powi(2) + (x[2] as f64 - 1.25).powi(2)).sqrt();
            assert!((c.value - 2.0 * d).abs() < 1e-12);
        }
    }

    #[test]
    fn sources_outside_or_on_walls_are_refused() {
        let p = problem(&[4, 4], vec![Source::Point(vec![0.0, 4.5])]);
        assert!(matches!(
            InitialFront::build(&p, 1.5, &Control::new()),
            Err(EikonalError::Source { index: 0, .. })
        ));
        let grid = Grid::unit(&[3, 3]).unwrap();
        let mut v = vec![1.0; 9];
        v[4] = f64::INFINITY;
        let p = EikonalProblem {
            cost: IsotropicCost::new(&grid, CostValues::F64(v.into()), Interpretation::Cost, None)
                .unwrap(),
            grid,
            sources: vec![
                Source::Point(vec![0.0, 0.0]),
                Source::Cells {
                    cells: vec![vec![1, 1]],
                    values: None,
                },
            ],
        };
        assert!(matches!(
            InitialFront::build(&p, 1.5, &Control::new()),
            Err(EikonalError::Source { index: 1, .. })
        ));
    }

    #[test]
    fn no_initial_value_leaks_through_a_thin_wall() {
        // A wall on column 2; the source sits just left of it.
        let grid = Grid::unit(&[5, 5]).unwrap();
        let mut v = vec![1.0; 25];
        for r in 0..5 {
            v[r * 5 + 2] = f64::INFINITY;
        }
        let p = EikonalProblem {
            cost: IsotropicCost::new(&grid, CostValues::F64(v.into()), Interpretation::Cost, None)
                .unwrap(),
            grid,
            sources: vec![Source::Point(vec![2.0, 1.4])],
        };
        let f = InitialFront::build(&p, 2.0, &Control::new()).unwrap();
        assert!(f.cells.iter().all(|c| p.grid.unravel(c.index)[2] < 2));
    }
}
