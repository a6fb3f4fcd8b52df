//! Motion planning for a disc (ball) robot of radius `ρ` among obstacle cells
//! (seed §3.6): the obstacles are grown by `ρ` with the exact distance
//! transform, and a shortest path is found in the free space that is left.
//!
//! # Method
//! * Clearance `C(x)`: exact Euclidean distance from `x` to the nearest
//!   obstacle cell centre ([`crate::numerics::edt`]). A cell is free when
//!   `C >= ρ` (and `C > 0`: obstacle cells are never free).
//! * Widest robot: the largest `ρ*` such that start and goal lie in one
//!   connected component of `{C >= ρ*}` (union–find over the cells in
//!   decreasing clearance, `O(N log N)`). When `ρ > ρ*` there is no path, and
//!   the answer says so, with `ρ*`.
//! * Distance to the goal in the free space: fast marching with a unit cost,
//!   the non-free cells as walls ([`crate::numerics::solve`]).
//! * Path: steepest discrete descent of that distance from the start over safe
//!   moves, then shortened by line of sight ("string pulling").
//!
//! # Clearance guarantee
//! The distance from an axis-aligned box whose corners are lattice points to
//! a lattice point is attained at a corner of the box (the nearest point is
//! the coordinate-wise clamp, whose coordinates are lattice values). So a
//! segment that only crosses cell boxes whose corners are all free keeps
//! clearance `>= ρ` at every one of its points. Every move and every shortcut
//! of the path is checked that way, so the returned polyline has clearance
//! `>= ρ` everywhere, not only at its vertices.

use std::borrow::Cow;

use super::edt::{self, EdtError, EdtOptions};
use super::eikonal::{EikonalOptions, EikonalProblem, Source};
use super::metric::{CostValues, Interpretation, IsotropicCost};
use super::{Control, EikonalError, Grid};

/// Why a plan was refused, or why there is none.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlanError {
    /// The obstacle mask does not have one value per cell.
    #[error("the obstacle mask has {got} values but the grid has {expected} cells")]
    Length {
        /// Values given.
        got: usize,
        /// Cells.
        expected: usize,
    },
    /// The radius is negative or not finite.
    #[error("radius {0} must be finite and >= 0")]
    Radius(f64),
    /// A point is outside the grid or has the wrong number of coordinates.
    #[error("{which}: {reason}")]
    Point {
        /// `start` or `goal`.
        which: &'static str,
        /// Why.
        reason: String,
    },
    /// The robot does not fit at the start or the goal.
    #[error("{which}: the robot does not fit there: clearance {clearance} < radius {radius}")]
    Blocked {
        /// `start` or `goal`.
        which: &'static str,
        /// Clearance at that cell.
        clearance: f64,
        /// The robot's radius.
        radius: f64,
    },
    /// Start and goal are in different components of the free space.
    #[error("no collision-free path from start to goal for a robot of radius {radius}; the widest robot that can go from start to goal has radius {widest}")]
    NoPath {
        /// The robot's radius.
        radius: f64,
        /// The largest radius that has a path (0 if even a point robot has none).
        widest: f64,
    },
    /// The distance transform failed (or was cancelled).
    #[error(transparent)]
    Edt(#[from] EdtError),
    /// The eikonal solve failed (or was cancelled).
    #[error(transparent)]
    Eikonal(#[from] EikonalError),
}

/// A collision-free path.
#[derive(Debug, Clone, PartialEq)]
pub struct Plan {
    /// Vertices in index coordinates (axis 0 first), start to goal.
    pub path: Vec<Vec<f64>>,
    /// Physical length of the polyline.
    pub length: f64,
    /// Smallest clearance over the path's vertices (>= radius).
    pub min_clearance: f64,
    /// The widest robot that can go from start to goal.
    pub widest: f64,
    /// Clearance of every cell (distance to the nearest obstacle centre).
    pub clearance: Vec<f64>,
    /// Distance to the goal in the free space (`+inf` where not free or not reached).
    pub distance: Vec<f64>,
}

/// Plans a path for a robot of radius `radius` from `start` to `goal`
/// (cells, in index coordinates; points between cells are rounded).
pub fn plan(
    grid: &Grid,
    obstacles: &[bool],
    radius: f64,
    start: &[f64],
    goal: &[f64],
    control: &Control<'_>,
) -> Result<Plan, PlanError> {
    if obstacles.len() != grid.len() {
        return Err(PlanError::Length {
            got: obstacles.len(),
            expected: grid.len(),
        });
    }
    if !(radius.is_finite() && radius >= 0.0) {
        return Err(PlanError::Radius(radius));
    }
    let cell = |which: &'static str, p: &[f64]| -> Result<usize, PlanError> {
        let bad = |reason: String| PlanError::Point { which, reason };
        let p3 = grid.point3(p).map_err(|e| bad(e.to_string()))?;
        if !grid.contains_point3(p3) {
            return Err(bad(format!(
                "point {p:?} is outside the grid of shape {:?}",
                grid.shape()
            )));
        }
        let s = grid.shape3();
        let idx = [0, 1, 2].map(|k| (p3[k].round().max(0.0) as usize).min(s[k] - 1));
        Ok(grid.linear(idx))
    };
    let s_cell = cell("start", start)?;
    let g_cell = cell("goal", goal)?;
    let clearance = edt::edt(grid, obstacles, &EdtOptions::default(), control)?.distance;
    for (which, c) in [("start", s_cell), ("goal", g_cell)] {
        if clearance[c] < radius || clearance[c] == 0.0 {
            return Err(PlanError::Blocked {
                which,
                clearance: clearance[c],
                radius,
            });
        }
    }
    let widest = widest_radius(grid, &clearance, s_cell, g_cell);
    if widest < radius || widest == 0.0 {
        return Err(PlanError::NoPath { radius, widest });
    }
    // Obstacle cells stay walls for a point robot (radius 0).
    let walls: Vec<bool> = clearance.iter().map(|&c| c < radius || c == 0.0).collect();
    let cost = IsotropicCost::new(
        grid,
        CostValues::Constant(1.0),
        Interpretation::Cost,
        Some(Cow::Borrowed(&walls)),
    )
    .map_err(EikonalError::Metric)?;
    let g3 = grid.unravel(g_cell);
    let problem = EikonalProblem {
        grid: grid.clone(),
        cost,
        sources: vec![Source::Cells {
            cells: vec![g3[3 - grid.ndim()..].to_vec()],
            values: None,
        }],
    };
    let out = super::solve(&problem, &EikonalOptions::DEFAULT, control)?;
    let u: Vec<f64> = out.distance.iter().copied().collect();
    let free = |c: usize| !walls[c];
    // Discrete descent over safe moves.
    let mut cells = vec![s_cell];
    let mut cur = s_cell;
    while cur != g_cell {
        let mut best: Option<(usize, f64)> = None;
        for n in neighbours(grid, cur) {
            if u[n] < u[cur] && box_free(grid, cur, n, &free) && best.is_none_or(|(_, b)| u[n] < b)
            {
                best = Some((n, u[n]));
            }
        }
        match best {
            Some((n, _)) => {
                cells.push(n);
                cur = n;
            }
            None => {
                // Cannot happen for a fast-marching map (each cell has an
                // upwind axis neighbour); refuse rather than return a bad path.
                return Err(PlanError::NoPath { radius, widest });
            }
        }
        if cells.len() > grid.len() {
            return Err(PlanError::NoPath { radius, widest });
        }
    }
    // String pulling.
    let mut keep = vec![cells[0]];
    let mut i = 0;
    while i + 1 < cells.len() {
        let mut j = i + 1;
        while j + 1 < cells.len() && segment_free(grid, cells[i], cells[j + 1], &free) {
            j += 1;
        }
        keep.push(cells[j]);
        i = j;
    }
    let h = grid.spacing3();
    let off = 3 - grid.ndim();
    let pts: Vec<[f64; 3]> = keep
        .iter()
        .map(|&c| grid.unravel(c).map(|v| v as f64))
        .collect();
    let length = pts
        .windows(2)
        .map(|w| {
            (0..3)
                .map(|k| ((w[1][k] - w[0][k]) * h[k]).powi(2))
                .sum::<f64>()
                .sqrt()
        })
        .sum();
    let min_clearance = keep
        .iter()
        .map(|&c| clearance[c])
        .fold(f64::INFINITY, f64::min);
    Ok(Plan {
        path: pts.iter().map(|p| p[off..].to_vec()).collect(),
        length,
        min_clearance,
        widest,
        clearance,
        distance: u,
    })
}

/// The 8 (2D) or 26 (3D) neighbours of a cell.
fn neighbours(grid: &Grid, c: usize) -> Vec<usize> {
    let s = grid.shape3();
    let p = grid.unravel(c);
    let r0: &[i64] = if s[0] == 1 { &[0] } else { &[-1, 0, 1] };
    let mut out = Vec::with_capacity(26);
    for &d0 in r0 {
        for d1 in -1..=1i64 {
            for d2 in -1..=1i64 {
                if d0 == 0 && d1 == 0 && d2 == 0 {
                    continue;
                }
                let q = [p[0] as i64 + d0, p[1] as i64 + d1, p[2] as i64 + d2];
                if (0..3).all(|k| q[k] >= 0 && (q[k] as usize) < s[k]) {
                    out.push(grid.linear(q.map(|v| v as usize)));
                }
            }
        }
    }
    out
}

/// True if every corner of the box spanned by cells `a` and `b` is free.
fn box_free(grid: &Grid, a: usize, b: usize, free: &impl Fn(usize) -> bool) -> bool {
    let (pa, pb) = (grid.unravel(a), grid.unravel(b));
    let lo = [0, 1, 2].map(|k| pa[k].min(pb[k]));
    let hi = [0, 1, 2].map(|k| pa[k].max(pb[k]));
    for i in lo[0]..=hi[0] {
        for j in lo[1]..=hi[1] {
            for k in lo[2]..=hi[2] {
                if !free(grid.linear([i, j, k])) {
                    return false;
                }
            }
        }
    }
    true
}

/// True if the segment between the centres of cells `a` and `b` only
/// crosses boxes whose corners are all free (exact: the parameter interval
/// is cut at every crossing of a lattice plane).
fn segment_free(grid: &Grid, a: usize, b: usize, free: &impl Fn(usize) -> bool) -> bool {
    let (pa, pb) = (grid.unravel(a), grid.unravel(b));
    let pa = pa.map(|v| v as f64);
    let pb = pb.map(|v| v as f64);
    let mut ts = vec![0.0, 1.0];
    for k in 0..3 {
        let (x0, x1) = (pa[k], pb[k]);
        if x0 == x1 {
            continue;
        }
        let (lo, hi) = (x0.min(x1), x0.max(x1));
        let mut v = lo.ceil();
        while v <= hi {
            ts.push((v - x0) / (x1 - x0));
            v += 1.0;
        }
    }
    ts.sort_by(f64::total_cmp);
    let s = grid.shape3();
    for w in ts.windows(2) {
        if w[1] - w[0] <= 0.0 {
            continue;
        }
        let t = 0.5 * (w[0] + w[1]);
        let p = [0, 1, 2].map(|k| pa[k] + t * (pb[k] - pa[k]));
        let lo = p.map(|v| v.floor() as usize);
        let hi = [0, 1, 2].map(|k| {
            if p[k].fract() == 0.0 {
                lo[k]
            } else {
                (lo[k] + 1).min(s[k] - 1)
            }
        });
        for i in lo[0]..=hi[0] {
            for j in lo[1]..=hi[1] {
                for k in lo[2]..=hi[2] {
                    if !free(grid.linear([i, j, k])) {
                        return false;
                    }
                }
            }
        }
    }
    true
}

/// The largest `r` such that `a` and `b` are connected (axis neighbours)
/// through cells of clearance `>= r`.
pub fn widest_radius(grid: &Grid, clearance: &[f64], a: usize, b: usize) -> f64 {
    let n = grid.len();
    let mut order: Vec<u32> = (0..n as u32).collect();
    order.sort_unstable_by(|&x, &y| clearance[y as usize].total_cmp(&clearance[x as usize]));
    let mut parent: Vec<u32> = (0..n as u32).collect();
    let mut added = vec![false; n];
    fn find(parent: &mut [u32], mut x: u32) -> u32 {
        while parent[x as usize] != x {
            let g = parent[parent[x as usize] as usize];
            parent[x as usize] = g;
            x = g;
        }
        x
    }
    let s = grid.shape3();
    let st = grid.strides3();
    for &c in &order {
        let c = c as usize;
        added[c] = true;
        let p = grid.unravel(c);
        for k in 0..3 {
            for dir in [-1i64, 1] {
                let q = p[k] as i64 + dir;
                if q < 0 || q as usize >= s[k] {
                    continue;
                }
                let m = if dir < 0 { c - st[k] } else { c + st[k] };
                if added[m] {
                    let (ra, rb) = (find(&mut parent, c as u32), find(&mut parent, m as u32));
                    if ra != rb {
                        parent[ra as usize] = rb;
                    }
                }
            }
        }
        if added[a] && added[b] && find(&mut parent, a as u32) == find(&mut parent, b as u32) {
            return clearance[c];
        }
    }
    0.0
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A wall across the grid with a gap of `gap` cells.
    fn corridor(n0: usize, n1: usize, gap: usize) -> Vec<bool> {
        let mut m = vec![false; n0 * n1];
        let wall = n1 / 2;
        let g0 = n0 / 2 - gap / 2;
        for i in 0..n0 {
            if !(g0..g0 + gap).contains(&i) {
                for j in wall..wall + 3 {
                    m[i * n1 + j] = true;
                }
            }
        }
        m
    }

    fn clearance_along(path: &[Vec<f64>], obstacles: &[bool], n1: usize) -> f64 {
        let obs: Vec<[f64; 2]> = (0..obstacles.len())
            .filter(|&c| obstacles[c])
            .map(|c| [(c / n1) as f64, (c % n1) as f64])
            .collect();
        let mut worst = f64::INFINITY;
        for w in path.windows(2) {
            for k in 0..=200 {
                let t = k as f64 / 200.0;
                let p = [
                    w[0][0] + t * (w[1][0] - w[0][0]),
                    w[0][1] + t * (w[1][1] - w[0][1]),
                ];
                for o in &obs {
                    worst = worst.min(((p[0] - o[0]).powi(2) + (p[1] - o[1]).powi(2)).sqrt());
                }
            }
        }
        worst
    }

    #[test]
    fn wide_robot_has_no_path_and_narrow_one_keeps_its_clearance() {
        let (n0, n1) = (60, 60);
        let obstacles = corridor(n0, n1, 9);
        let grid = Grid::unit(&[n0, n1]).unwrap();
        // The gap spans 9 free rows between wall cells 10 rows apart: widest robot 5.
        let err = plan(
            &grid,
            &obstacles,
            6.0,
            &[30.0, 5.0],
            &[30.0, 55.0],
            &Control::new(),
        )
        .unwrap_err();
        match err {
            PlanError::NoPath { radius, widest } => {
                assert_eq!(radius, 6.0);
                assert!((widest - 5.0).abs() < 1e-12, "{widest}");
            }
            other => panic!("{other:?}"),
        }
        for radius in [2.0, 4.0, 5.0] {
            let p = plan(
                &grid,
                &obstacles,
                radius,
                &[10.0, 5.0],
                &[50.0, 55.0],
                &Control::new(),
            )
            .unwrap();
            assert_eq!(p.path.first().unwrap(), &vec![10.0, 5.0]);
            assert_eq!(p.path.last().unwrap(), &vec![50.0, 55.0]);
            let c = clearance_along(&p.path, &obstacles, n1);
            assert!(c >= radius - 1e-9, "radius {radius}: clearance {c}");
            // Through the gap, no longer than 12 % over the straight line.
            let straight = (40f64.powi(2) + 50f64.powi(2)).sqrt();
            assert!(
                p.length >= straight && p.length < 1.12 * straight,
                "{}",
                p.length
            );
        }
    }

    #[test]
    fn blocked_start_and_bad_points_are_refused() {
        let grid = Grid::unit(&[20, 20]).unwrap();
        let obstacles = corridor(20, 20, 4);
        assert!(matches!(
            plan(
                &grid,
                &obstacles,
                3.0,
                &[10.0, 9.0],
                &[10.0, 18.0],
                &Control::new()
            ),
            Err(PlanError::Blocked { which: "start", .. })
        ));
        assert!(matches!(
            plan(
                &grid,
                &obstacles,
                1.0,
                &[30.0, 9.0],
                &[10.0, 18.0],
                &Control::new()
            ),
            Err(PlanError::Point { which: "start", .. })
        ));
        assert!(matches!(
            plan(
                &grid,
                &obstacles,
                -1.0,
                &[1.0, 1.0],
                &[10.0, 18.0],
                &Control::new()
            ),
            Err(PlanError::Radius(_))
        ));
    }
}
