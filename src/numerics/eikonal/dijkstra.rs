//! Dijkstra's algorithm on the grid graph: the graph baseline of the eikonal
//! solvers.
//!
//! # The graph
//! Every non-wall cell is a node. Cell `a` is joined to the cells `b = a + d`
//! for the offsets `d` of the neighbourhood chosen by
//! [`EikonalOptions::connectivity`]:
//!
//! | [`Connectivity`] | 2D offsets                         | 3D offsets                      |
//! |------------------|------------------------------------|---------------------------------|
//! | `Axial`          | 4: `(±1,0)`, `(0,±1)`              | 6: the faces of the cube        |
//! | `Diagonal`       | 8: adds `(±1,±1)`                  | 18: adds the edge diagonals     |
//! | `Extended`       | 16: adds the knight moves `(±1,±2)`, `(±2,±1)` | 26: the full `3x3x3` cube |
//!
//! Offsets along an axis of length 1 (axis 0 of a 2D grid) are skipped.
//! The weight of the edge `a → b` is the trapezoid rule for
//! `∫ W ds` along the segment:
//!
//! ```text
//! w(a, b) = |a - b|_h · (W(a) + W(b)) / 2,     |d|_h = sqrt(Σ_k (d_k h_k)^2)
//! ```
//!
//! Walls (`W = +inf`) are never entered. A move that is not axial must not
//! slip between walls: a diagonal move is allowed only if at least one
//! monotone axial staircase inside its unit box avoids the walls (so the
//! graph connects exactly the cells that 4 / 6-connected paths connect, like
//! the finite-difference solvers), and a knight move only if the two cells its
//! segment passes through are not walls.
//!
//! Seeds are the cells of the [`InitialFront`] with their values and labels;
//! `U` is the length of the shortest path from a seed (plus the seed's value),
//! and the label of a cell is the label of the seed at the root of its branch
//! of the shortest-path tree. The open cells live in the indexed heap of
//! [`crate::numerics::heap`] (decrease-key, no stale entries). Runtime
//! `O(N k log N)` for `k` neighbours; memory 17 bytes per cell (distance,
//! label, settled flag, heap position) plus 16 per cell of the open set.
//!
//! # Metrication error
//! A graph path can only move along the offsets of the neighbourhood, so even
//! on a unit cost the graph distance overestimates the Euclidean length.
//! Between two consecutive move directions at angle `α` the worst direction
//! is the bisector, with relative error `1 / cos(α / 2) − 1` (Goodchild,
//! 1977; the error does not shrink when the grid is refined):
//!
//! | 2D neighbours | worst-case elongation |
//! |---------------|-----------------------|
//! | 4             | 41.4 %                |
//! | 8             | 8.2 %                 |
//! | 16            | 2.79 %                |
//!
//! (the 16-neighbour bisector value is `1/cos(atan(1/2)/2) − 1 = 2.75 %`; the
//! tests assert the measured error stays below these figures and above most of
//! them). In 3D, for a direction `(a, b, c)` with `a ≥ b ≥ c ≥ 0`, the graph
//! length is `(a−b) + (b−c)√2 + c√3` with 26 neighbours, `(a−b−c) + (b+c)√2`
//! (or `(a+b+c)/√2` when `b + c > a`) with 18, and `a + b + c` with 6;
//! maximising over directions gives the worst-case elongations:
//!
//! | 3D neighbours | worst-case elongation |
//! |---------------|-----------------------|
//! | 6             | 73.2 % (`√3 − 1`)     |
//! | 18            | 22.5 % (`√(3/2) − 1`) |
//! | 26            | 12.8 %                |
//! Use fast marching for a consistent `O(h)` / `O(h^2)` solution;
//! Dijkstra is a baseline and the only solver whose result is exactly a path
//! length on the graph.
//!
//! # Stopping
//! As for fast marching: [`StopRules::targets`](super::StopRules::targets)
//! (stop once every target's nearest cell is settled),
//! [`max_distance`](super::StopRules::max_distance) (stop before settling a
//! cell whose value exceeds it) and
//! [`max_frozen`](super::StopRules::max_frozen). After an early stop every
//! cell that was not settled gets `+inf` and label `-1`. The cancel flag is
//! polled every 4096 settled cells.

use super::{
    finish, target_cells, Connectivity, EikonalError, EikonalOptions, EikonalOutput,
    EikonalProblem, InitialFront, StopReason,
};
use crate::numerics::control::Control;
use crate::numerics::grid::Grid;
use crate::numerics::heap::IndexedHeap;

/// Cells settled between two polls of the cancel flag.
const POLL_EVERY: usize = 4096;

/// One edge direction of the grid graph.
#[derive(Debug, Clone)]
struct Move {
    /// Offset per padded axis.
    offset: [isize; 3],
    /// Physical length `|offset|_h`.
    length: f64,
    /// Alternative sets of cells (offsets from the start cell) of which at
    /// least one must be wall-free for the move to be allowed; empty for an
    /// axial move, which needs nothing.
    detours: Vec<Vec<[isize; 3]>>,
}

/// The moves of a neighbourhood on `grid`, skipping axes of length 1.
fn moves(grid: &Grid, connectivity: Connectivity) -> Vec<Move> {
    let shape = grid.shape3();
    let h = grid.spacing3();
    let knight = connectivity == Connectivity::Extended && grid.ndim() == 2;
    let reach: isize = if knight { 2 } else { 1 };
    let mut out = Vec::new();
    for a in -reach..=reach {
        for b in -reach..=reach {
            for c in -reach..=reach {
                let d = [a, b, c];
                if d == [0, 0, 0] || (0..3).any(|k| d[k] != 0 && shape[k] == 1) {
                    continue;
                }
                let nonzero = d.iter().filter(|&&x| x != 0).count();
                let twos = d.iter().filter(|&&x| x.abs() == 2).count();
                let keep = match twos {
                    // Knight moves: one component ±2 and one ±1 (2D only).
                    1 => knight && nonzero == 2,
                    0 => match connectivity {
                        Connectivity::Axial => nonzero == 1,
                        Connectivity::Diagonal => nonzero <= 2,
                        Connectivity::Extended => true,
                    },
                    _ => false,
                };
                if !keep {
                    continue;
                }
                let length = (0..3)
                    .map(|k| (d[k] as f64 * h[k]).powi(2))
                    .sum::<f64>()
                    .sqrt();
                out.push(Move {
                    offset: d,
                    length,
                    detours: detours(d),
                });
            }
        }
    }
    out
}

/// The cells a non-axial move must not slip between (see the module docs).
fn detours(d: [isize; 3]) -> Vec<Vec<[isize; 3]>> {
    let axes: Vec<usize> = (0..3).filter(|&k| d[k] != 0).collect();
    if axes.len() == 1 {
        return Vec::new();
    }
    if let Some(long) = (0..3).find(|&k| d[k].abs() == 2) {
        // Knight move: the segment crosses the two cells at the middle of the
        // long axis, on either side of the short step.
        let mut first = [0isize; 3];
        first[long] = d[long] / 2;
        let mut second = first;
        for &k in &axes {
            if k != long {
                second[k] = d[k];
            }
        }
        return vec![vec![first, second]];
    }
    // Diagonal move: every monotone staircase through the unit box, as the
    // list of its intermediate cells.
    let mut out = Vec::new();
    let mut perm = axes.clone();
    permutations(&mut perm, 0, &mut |order| {
        let mut at = [0isize; 3];
        let mut cells = Vec::new();
        for &k in &order[..order.len() - 1] {
            at[k] = d[k];
            cells.push(at);
        }
        out.push(cells);
    });
    out
}

fn permutations(v: &mut Vec<usize>, start: usize, f: &mut dyn FnMut(&[usize])) {
    if start == v.len() {
        f(v);
        return;
    }
    for i in start..v.len() {
        v.swap(start, i);
        permutations(v, start + 1, f);
        v.swap(start, i);
    }
}

/// Solves the problem; see the module documentation.
pub(super) fn solve(
    problem: &EikonalProblem<'_>,
    front: &InitialFront,
    options: &EikonalOptions,
    control: &Control<'_>,
) -> Result<EikonalOutput, EikonalError> {
    let grid = &problem.grid;
    let cost = &problem.cost;
    let n = grid.len();
    let shape = grid.shape3().map(|s| s as isize);
    let strides = grid.strides3().map(|s| s as isize);
    let targets = target_cells(grid, &options.stop.targets)?;
    let moves = moves(grid, options.connectivity);
    let steps: Vec<isize> = moves
        .iter()
        .map(|m| (0..3).map(|k| m.offset[k] * strides[k]).sum())
        .collect();
    let has_walls = !cost.is_uniform() && (0..n).any(|i| cost.is_wall(i));

    let mut dist = vec![f64::INFINITY; n];
    let mut labels = vec![-1i32; n];
    let mut settled = vec![false; n];
    let mut order = options.record_order.then(|| vec![-1i64; n]);
    let mut is_target = vec![false; if targets.is_empty() { 0 } else { n }];
    let mut targets_left = 0usize;
    for &t in &targets {
        if !is_target[t] {
            is_target[t] = true;
            targets_left += 1;
        }
    }

    let mut heap = IndexedHeap::new(n);
    for seed in &front.cells {
        if seed.value < dist[seed.index] {
            dist[seed.index] = seed.value;
            labels[seed.index] = seed.label;
            heap.push_or_decrease(seed.index as u32, seed.value);
        }
    }

    let mut frozen = 0usize;
    let mut stop = StopReason::Completed;
    let mut early = false;
    let poll = |frozen: usize| {
        if control.is_cancelled() {
            return Err(EikonalError::Cancelled);
        }
        control.report(frozen as f64 / n as f64);
        Ok(())
    };
    poll(0)?;
    loop {
        if options.stop.max_frozen.is_some_and(|m| frozen >= m) {
            stop = StopReason::MaxFrozen;
            early = true;
            break;
        }
        let Some((cell, value)) = heap.pop() else {
            break;
        };
        let a = cell as usize;
        if options.stop.max_distance.is_some_and(|d| value > d) {
            stop = StopReason::MaxDistance;
            early = true;
            break;
        }
        settled[a] = true;
        if let Some(o) = order.as_mut() {
            o[a] = frozen as i64;
        }
        frozen += 1;
        if frozen.is_multiple_of(POLL_EVERY) {
            poll(frozen)?;
        }
        if targets_left > 0 && is_target[a] {
            targets_left -= 1;
            if targets_left == 0 {
                stop = StopReason::TargetsReached;
                early = true;
                break;
            }
        }

        let wa = cost.at(a);
        let label = labels[a];
        let pos = grid.unravel(a).map(|x| x as isize);
        'moves: for (m, &step) in moves.iter().zip(&steps) {
            for k in 0..3 {
                let x = pos[k] + m.offset[k];
                if x < 0 || x >= shape[k] {
                    continue 'moves;
                }
            }
            let b = (a as isize + step) as usize;
            if settled[b] {
                continue;
            }
            let wb = cost.at(b);
            if wb == f64::INFINITY {
                continue;
            }
            if has_walls && !m.detours.is_empty() {
                let free = |c: &[isize; 3]| {
                    let i = (0..3).map(|k| (pos[k] + c[k]) * strides[k]).sum::<isize>();
                    !cost.is_wall(i as usize)
                };
                if !m.detours.iter().any(|path| path.iter().all(free)) {
                    continue;
                }
            }
            let candidate = value + m.length * 0.5 * (wa + wb);
            if candidate < dist[b] {
                dist[b] = candidate;
                labels[b] = label;
                heap.push_or_decrease(b as u32, candidate);
            }
        }
    }

    if early {
        for i in 0..n {
            if !settled[i] {
                dist[i] = f64::INFINITY;
                labels[i] = -1;
            }
        }
    }
    control.report(1.0);
    Ok(finish(grid, dist, labels, order, frozen, stop, None))
}

#[cfg(test)]
mod tests {
    use std::sync::atomic::AtomicBool;

    use super::*;
    use crate::numerics::eikonal::{solve as solve_any, Method, Source, StopRules};
    use crate::numerics::metric::{CostValues, Interpretation, IsotropicCost};

    fn options(connectivity: Connectivity) -> EikonalOptions {
        EikonalOptions::DEFAULT
            .with_method(Method::Dijkstra)
            .with_connectivity(connectivity)
    }

    fn unit_problem(shape: &[usize], sources: Vec<Source>) -> EikonalProblem<'static> {
        EikonalProblem {
            grid: Grid::unit(shape).unwrap(),
            cost: IsotropicCost::constant(1.0).unwrap(),
            sources,
        }
    }

    fn field_problem(
        shape: &[usize],
        w: Vec<f64>,
        sources: Vec<Source>,
    ) -> EikonalProblem<'static> {
        let grid = Grid::unit(shape).unwrap();
        EikonalProblem {
            cost: IsotropicCost::new(&grid, CostValues::F64(w.into()), Interpretation::Cost, None)
                .unwrap(),
            grid,
            sources,
        }
    }

    fn cell(c: &[usize]) -> Source {
        Source::Cells {
            cells: vec![c.to_vec()],
            values: None,
        }
    }

    /// Max and mean of `(U - r) / r` over cells at Euclidean distance `r >= 5`
    /// from the point source at the centre of a 201 x 201 unit grid.
    fn metrication(connectivity: Connectivity) -> (f64, f64) {
        let n = 201;
        let c = 100.0;
        let p = unit_problem(&[n, n], vec![Source::Point(vec![c, c])]);
        let out = solve_any(&p, &options(connectivity), &Control::new()).unwrap();
        let (mut max, mut sum, mut count) = (0.0f64, 0.0, 0usize);
        for ((i, j), &u) in out
            .distance
            .view()
            .into_dimensionality::<ndarray::Ix2>()
            .unwrap()
            .indexed_iter()
        {
            // Exact solution of |∇U| = 1 with a point source: U = |x - p|.
            let r = crate::numerics::exact::point_source(&[i as f64, j as f64], &[c, c], 1.0);
            if r >= 5.0 {
                let e = (u - r) / r;
                assert!(e > -1e-12, "a graph path is never shorter than the segment");
                max = max.max(e);
                sum += e;
                count += 1;
            }
        }
        eprintln!(
            "metrication {connectivity:?}: max {max:.5} mean {:.5}",
            sum / count as f64
        );
        (max, sum / count as f64)
    }

    #[test]
    fn metrication_error_4_neighbours_is_at_most_41_4_percent_and_real() {
        let (max, mean) = metrication(Connectivity::Axial);
        assert!(max <= 0.4142 + 1e-3 && max > 0.40, "max {max}");
        // The mean of |cos| + |sin| - 1 over directions is 4/π - 1 = 27.3 %;
        // the corners of the square weigh the diagonals a little more.
        assert!(mean > 0.26 && mean < 0.31, "mean {mean}");
    }

    #[test]
    fn metrication_error_8_neighbours_is_at_most_8_2_percent_and_real() {
        let (max, mean) = metrication(Connectivity::Diagonal);
        assert!(max <= 0.0824 + 1e-3 && max > 0.08, "max {max}");
        assert!(mean > 0.045 && mean < 0.06, "mean {mean}");
    }

    #[test]
    fn metrication_error_16_neighbours_is_at_most_2_79_percent_and_real() {
        let (max, mean) = metrication(Connectivity::Extended);
        assert!(max <= 0.0279 + 1e-3 && max > 0.026, "max {max}");
        assert!(mean > 0.011 && mean < 0.016, "mean {mean}");
    }

    #[test]
    fn neighbourhood_sizes_in_2d_and_3d() {
        let g2 = Grid::unit(&[5, 5]).unwrap();
        let g3 = Grid::unit(&[5, 5, 5]).unwrap();
        let flat = Grid::unit(&[1, 5, 5]).unwrap();
        let count = |g: &Grid, c| moves(g, c).len();
        assert_eq!(count(&g2, Connectivity::Axial), 4);
        assert_eq!(count(&g2, Connectivity::Diagonal), 8);
        assert_eq!(count(&g2, Connectivity::Extended), 16);
        assert_eq!(count(&g3, Connectivity::Axial), 6);
        assert_eq!(count(&g3, Connectivity::Diagonal), 18);
        assert_eq!(count(&g3, Connectivity::Extended), 26);
        // A 3D grid with a length-1 axis only has in-plane moves.
        assert_eq!(count(&flat, Connectivity::Extended), 8);
    }

    #[test]
    fn ball_of_radius_1_5_counts_the_3d_neighbourhood() {
        // From the centre cell of a unit 5^3 grid, the cells at graph
        // distance <= 1.5 are the centre and its axial (1) and edge-diagonal
        // (√2) neighbours; the corners (√3 = 1.73) need <= 1.8.
        for (conn, radius, expected) in [
            (Connectivity::Axial, 1.5, 7),
            (Connectivity::Diagonal, 1.5, 19),
            (Connectivity::Diagonal, 1.8, 19),
            (Connectivity::Extended, 1.5, 19),
            (Connectivity::Extended, 1.8, 27),
        ] {
            let p = unit_problem(&[5, 5, 5], vec![cell(&[2, 2, 2])]);
            let o = options(conn).with_stop(StopRules {
                max_distance: Some(radius),
                ..Default::default()
            });
            let out = solve_any(&p, &o, &Control::new()).unwrap();
            let finite = out.distance.iter().filter(|u| u.is_finite()).count();
            assert_eq!(finite, expected, "{conn:?} radius {radius}");
            assert_eq!(out.frozen, expected);
            assert_eq!(out.stop, StopReason::MaxDistance);
        }
    }

    #[test]
    fn exact_graph_distances_in_3d() {
        // From the corner (0,0,0) to (a,b,c) with a >= b >= c, unit cost:
        // 6 neighbours: a + b + c; 26 neighbours: c√3 + (b - c)√2 + (a - b);
        // 18 neighbours with a >= b + c: (b + c)√2 + (a - b - c).
        let p = unit_problem(&[7, 6, 5], vec![cell(&[0, 0, 0])]);
        let s2 = 2f64.sqrt();
        let s3 = 3f64.sqrt();
        let run = |c| {
            solve_any(&p, &options(c), &Control::new())
                .unwrap()
                .distance
        };
        let u6 = run(Connectivity::Axial);
        let u18 = run(Connectivity::Diagonal);
        let u26 = run(Connectivity::Extended);
        assert!((u6[[6, 4, 3]] - 13.0).abs() < 1e-12);
        assert!((u26[[6, 4, 3]] - (3.0 * s3 + s2 + 2.0)).abs() < 1e-12);
        assert!((u18[[6, 3, 2]] - (5.0 * s2 + 1.0)).abs() < 1e-12);
        assert!((u26[[4, 4, 4]] - 4.0 * s3).abs() < 1e-12);
    }

    #[test]
    fn edge_weights_use_the_trapezoid_rule_and_the_spacing() {
        // Two cells on a line, W = 1 and 3, spacing 0.5: U = 0.5 (1 + 3) / 2 = 1.
        let grid = Grid::new(&[1, 2], &[1.0, 0.5]).unwrap();
        let w = vec![1.0, 3.0];
        let p = EikonalProblem {
            cost: IsotropicCost::new(&grid, CostValues::F64(w.into()), Interpretation::Cost, None)
                .unwrap(),
            grid,
            sources: vec![cell(&[0, 0])],
        };
        let out = solve_any(&p, &options(Connectivity::Axial), &Control::new()).unwrap();
        assert!((out.distance[[0, 1]] - 1.0).abs() < 1e-15);
        // A knight move on an anisotropic grid: length sqrt(1 + (2 * 0.5)^2).
        let grid = Grid::new(&[2, 3], &[1.0, 0.5]).unwrap();
        let p = EikonalProblem {
            grid,
            cost: IsotropicCost::constant(2.0).unwrap(),
            sources: vec![cell(&[0, 0])],
        };
        let out = solve_any(&p, &options(Connectivity::Extended), &Control::new()).unwrap();
        assert!((out.distance[[1, 2]] - 2.0 * 2f64.sqrt()).abs() < 1e-12);
    }

    #[test]
    fn walls_are_never_entered_nor_slipped_through() {
        // 7 x 7, a wall on column 3 except row 6. From (0, 0) to (0, 6) the
        // shortest 8-neighbour path goes through the gap.
        let n = 7;
        let mut w = vec![1.0; n * n];
        for r in 0..6 {
            w[r * n + 3] = f64::INFINITY;
        }
        let p = field_problem(&[n, n], w.clone(), vec![cell(&[0, 0])]);
        let out = solve_any(&p, &options(Connectivity::Diagonal), &Control::new()).unwrap();
        for r in 0..6 {
            assert_eq!(out.distance[[r, 3]], f64::INFINITY);
            assert_eq!(out.labels[[r, 3]], -1);
        }
        // Through the gap (6, 3): 3 diagonal and 3 axial steps on each side.
        let expect = 2.0 * (3.0 * 2f64.sqrt() + 3.0);
        assert!((out.distance[[0, 6]] - expect).abs() < 1e-12);
        // A one-cell-thick diagonal wall from (0, 4) to (4, 0) closes the
        // corner: diagonal and knight moves must not slip through it.
        let mut w = vec![1.0; n * n];
        for k in 0..5 {
            w[k * n + (4 - k)] = f64::INFINITY;
        }
        for conn in [Connectivity::Diagonal, Connectivity::Extended] {
            let p = field_problem(&[n, n], w.clone(), vec![cell(&[0, 0])]);
            let out = solve_any(&p, &options(conn), &Control::new()).unwrap();
            assert!(out.distance[[1, 1]].is_finite());
            assert_eq!(out.distance[[4, 4]], f64::INFINITY, "{conn:?}");
            assert_eq!(out.labels[[6, 6]], -1);
            assert_eq!(out.frozen, 10);
        }
    }

    #[test]
    fn labels_follow_the_shortest_path_tree() {
        // Two sources on a 1 x 9 line with costs that push the boundary: the
        // left source is cheap to leave, so it wins cells right of the middle.
        let mut w = vec![1.0; 9];
        for v in &mut w[5..] {
            *v = 3.0;
        }
        let p = field_problem(&[1, 9], w, vec![cell(&[0, 0]), cell(&[0, 8])]);
        let out = solve_any(&p, &options(Connectivity::Axial), &Control::new()).unwrap();
        let labels: Vec<i32> = out.labels.iter().copied().collect();
        // U_left(5) = 4 + 2 = 6, U_right(5) = 9 (3 steps at 3): label 0.
        // U_left(6) = 9, U_right(6) = 6: label 1.
        assert_eq!(labels, vec![0, 0, 0, 0, 0, 0, 1, 1, 1]);
        assert!((out.distance[[0, 5]] - 6.0).abs() < 1e-12);
        // Voronoi of two points in 2D: every cell takes the nearer source.
        let p = unit_problem(
            &[21, 21],
            vec![
                Source::Point(vec![5.0, 5.0]),
                Source::Point(vec![15.0, 15.0]),
            ],
        );
        let out = solve_any(&p, &options(Connectivity::Diagonal), &Control::new()).unwrap();
        for ((i, j), &l) in out
            .labels
            .view()
            .into_dimensionality::<ndarray::Ix2>()
            .unwrap()
            .indexed_iter()
        {
            if i + j < 19 {
                assert_eq!(l, 0, "({i}, {j})");
            } else if i + j > 21 {
                assert_eq!(l, 1, "({i}, {j})");
            }
        }
    }

    #[test]
    fn stop_rules_leave_unsettled_cells_at_infinity() {
        let p = unit_problem(&[50, 50], vec![cell(&[0, 0])]);
        let base = options(Connectivity::Diagonal);
        let full = solve_any(&p, &base, &Control::new()).unwrap();
        assert_eq!(full.stop, StopReason::Completed);
        assert_eq!(full.frozen, 2500);

        // Targets: stops once (10, 10) and (3, 20) are settled.
        let o = base.clone().with_stop(StopRules {
            targets: vec![vec![10.0, 10.0], vec![3.2, 19.8]],
            ..Default::default()
        });
        let out = solve_any(&p, &o, &Control::new()).unwrap();
        assert_eq!(out.stop, StopReason::TargetsReached);
        assert_eq!(out.distance[[10, 10]], full.distance[[10, 10]]);
        assert_eq!(out.distance[[3, 20]], full.distance[[3, 20]]);
        let reached = full.distance[[3, 20]].max(full.distance[[10, 10]]);
        for (u, f) in out.distance.iter().zip(full.distance.iter()) {
            assert!(u.is_infinite() || (u == f && *u <= reached));
            assert!(u.is_finite() || *f >= reached);
        }
        assert_eq!(out.labels[[49, 49]], -1);

        // Max distance 12: exactly the cells with U <= 12 are kept.
        let o = base.clone().with_stop(StopRules {
            max_distance: Some(12.0),
            ..Default::default()
        });
        let out = solve_any(&p, &o, &Control::new()).unwrap();
        assert_eq!(out.stop, StopReason::MaxDistance);
        let inside = full.distance.iter().filter(|&&u| u <= 12.0).count();
        assert_eq!(out.frozen, inside);
        for (u, f) in out.distance.iter().zip(full.distance.iter()) {
            assert_eq!(u.is_finite(), *f <= 12.0);
        }

        // Max frozen, with the freeze order recorded.
        let mut o = base.with_stop(StopRules {
            max_frozen: Some(100),
            ..Default::default()
        });
        o.record_order = true;
        let out = solve_any(&p, &o, &Control::new()).unwrap();
        assert_eq!(out.stop, StopReason::MaxFrozen);
        assert_eq!(out.frozen, 100);
        assert_eq!(out.distance.iter().filter(|u| u.is_finite()).count(), 100);
        let order = out.frozen_order.unwrap();
        let mut ranked: Vec<(i64, f64)> = order
            .iter()
            .zip(out.distance.iter())
            .filter(|(r, _)| **r >= 0)
            .map(|(r, u)| (*r, *u))
            .collect();
        ranked.sort_by_key(|x| x.0);
        assert_eq!(ranked.len(), 100);
        assert_eq!(ranked.last().unwrap().0, 99);
        assert!(ranked.windows(2).all(|w| w[0].1 <= w[1].1));
    }

    #[test]
    fn cancel_flag_stops_the_solve() {
        let p = unit_problem(&[100, 100], vec![cell(&[0, 0])]);
        let flag = AtomicBool::new(true);
        let control = Control::new().with_cancel(&flag);
        let r = solve_any(&p, &options(Connectivity::Diagonal), &control);
        assert_eq!(r.unwrap_err(), EikonalError::Cancelled);
    }

    #[test]
    fn progress_reaches_one() {
        let p = unit_problem(&[100, 100], vec![cell(&[0, 0])]);
        let last = std::sync::Mutex::new(Vec::new());
        let sink = |f: f64| last.lock().unwrap().push(f);
        let control = Control::new().with_progress(&sink);
        solve_any(&p, &options(Connectivity::Axial), &control).unwrap();
        let seen = last.into_inner().unwrap();
        assert!(seen.len() >= 3);
        assert!(seen.windows(2).all(|w| w[0] <= w[1]));
        assert_eq!(*seen.last().unwrap(), 1.0);
    }
}
