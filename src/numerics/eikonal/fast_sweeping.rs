//! Fast sweeping (Zhao 2005) for `|∇U| = W` on 2D/3D grids.
//!
//! After the seed cells of the [`InitialFront`] receive their prescribed
//! (Dirichlet, never recomputed) values, Gauss–Seidel sweeps visit every
//! cell in each of the `2^d` axis orderings (Gray-code order: `(+,+)`,
//! `(−,+)`, `(−,−)`, `(+,−)` in 2D) and recompute it with the same local
//! upwind update as fast marching ([`super::update`]), using every neighbour
//! with a finite value. A round is the `2^d` sweeps; rounds repeat until the
//! largest change of a round is `≤` [`EikonalOptions::sweep_tolerance`], or
//! [`EikonalOptions::max_sweeps`] rounds were done
//! ([`StopReason::SweepLimit`], the values are then the last iterate).
//!
//! * First order: `U ← min(U, update)`; values only decrease, so the
//!   iteration converges, in a number of rounds that depends on how often
//!   the characteristics turn (one or two rounds for a point source under a
//!   constant cost).
//! * Second order ([`Order::Second`]): the first-order solution is computed
//!   first, then rounds of the second-order update (with the same per-axis
//!   and per-cell fallbacks) *replace* the values (`U ← update`) until the
//!   change is below the tolerance. Source factoring applies as in fast
//!   marching. This iteration is not monotone and may cycle on rough costs:
//!   if it does not reach the tolerance within the remaining rounds, the
//!   result is the converged *first-order* solution, with
//!   [`StopReason::SweepLimit`] (12 more bytes per cell are held for it
//!   during the second phase).
//!
//! Labels come from the update (the upwind neighbour with the smallest value
//! used); with several sources a final pass in increasing `U` gives each
//! cell the label of its smallest neighbour, so that every label region is
//! connected (4 bytes per reached cell, temporarily). Stop rules: only [`StopRules::max_distance`] applies (cells with
//! `U >` it are set to `+inf`, label `-1`, and the reason is
//! [`StopReason::MaxDistance`] if any reachable cell was cut); targets and
//! `max_frozen` are ignored, and no freezing order exists
//! (`frozen_order` is `None`). [`EikonalOutput::sweeps`] counts single
//! sweeps. Cancellation is polled once per sweep line; progress is reported
//! after each round as the fraction of rounds allowed.
//!
//! [`StopRules::max_distance`]: super::StopRules::max_distance

use super::update::{update, Factor, Stencil};
use super::{
    finish, EikonalError, EikonalOptions, EikonalOutput, EikonalProblem, InitialFront, Order,
    StopReason,
};
use crate::numerics::control::Control;

const FREE: u8 = 0;
const SEED: u8 = 1;
const WALL: u8 = 2;

/// Solves the problem; see the module documentation.
pub(super) fn solve(
    problem: &EikonalProblem<'_>,
    front: &InitialFront,
    options: &EikonalOptions,
    control: &Control<'_>,
) -> Result<EikonalOutput, EikonalError> {
    if control.is_cancelled() {
        return Err(EikonalError::Cancelled);
    }
    let grid = &problem.grid;
    let cost = &problem.cost;
    let n = grid.len();
    let st = Stencil::new(grid);
    let factor = if options.factoring {
        Factor::new(problem, front)
    } else {
        None
    };
    let mut u = vec![f64::INFINITY; n];
    let mut labels = vec![-1i32; n];
    let mut fixed = vec![FREE; n];
    if !cost.is_uniform() {
        for (i, f) in fixed.iter_mut().enumerate() {
            if cost.is_wall(i) {
                *f = WALL;
            }
        }
    }
    for c in &front.cells {
        u[c.index] = c.value;
        labels[c.index] = c.label;
        fixed[c.index] = SEED;
    }

    let phases: &[bool] = if options.order == Order::Second {
        &[false, true]
    } else {
        &[false]
    };
    let orderings = 1usize << st.axes().len();
    let mut rounds = 0usize;
    let mut sweeps = 0usize;
    let mut stop = StopReason::Completed;
    // The converged first-order solution, kept while the second-order phase runs.
    let mut first_order: Option<(Vec<f64>, Vec<i32>)> = None;
    'phases: for &second in phases {
        if second {
            first_order = Some((u.clone(), labels.clone()));
        }
        loop {
            if rounds >= options.max_sweeps {
                stop = StopReason::SweepLimit;
                break 'phases;
            }
            let mut change = 0.0f64;
            for o in 0..orderings {
                let gray = o ^ (o >> 1);
                let mut reverse = [false; 3];
                for (b, &k) in st.axes().iter().enumerate() {
                    reverse[k] = gray >> b & 1 == 1;
                }
                let ctx = Sweep {
                    st: &st,
                    cost,
                    fixed: &fixed,
                    factor: factor.as_ref(),
                    second,
                    multi: problem.sources.len() > 1,
                };
                change = change.max(ctx.sweep(reverse, &mut u, &mut labels, control)?);
                sweeps += 1;
            }
            rounds += 1;
            control.report(rounds as f64 / options.max_sweeps.max(1) as f64);
            if change <= options.sweep_tolerance {
                break;
            }
        }
    }
    if stop == StopReason::SweepLimit {
        if let Some((u1, l1)) = first_order.take() {
            // The second-order iteration did not settle: return the
            // converged first-order solution rather than a mid-iteration state.
            u = u1;
            labels = l1;
        }
    }

    if problem.sources.len() > 1 {
        relabel(&st, &u, &mut labels, &fixed);
    }
    if let Some(d) = options.stop.max_distance {
        for (v, l) in u.iter_mut().zip(labels.iter_mut()) {
            if *v > d && v.is_finite() {
                *v = f64::INFINITY;
                *l = -1;
                if stop == StopReason::Completed {
                    stop = StopReason::MaxDistance;
                }
            }
        }
    }
    let frozen = u.iter().filter(|v| v.is_finite()).count();
    control.report(1.0);
    Ok(finish(grid, u, labels, None, frozen, stop, Some(sweeps)))
}

/// Makes the Voronoi labels of several sources consistent after the sweeps.
///
/// During the sweeps a cell copies the label of a neighbour whose own label
/// may change later, so label regions could end up disconnected. Visiting
/// the free cells in increasing `U` and giving each the label of its axis
/// neighbour of smallest (strictly smaller) value restores the rule "the
/// label of the smallest upwind value" and makes every region a tree rooted
/// at its source's seeds.
fn relabel(st: &Stencil, u: &[f64], labels: &mut [i32], fixed: &[u8]) {
    let mut cells: Vec<u32> = (0..u.len())
        .filter(|&i| fixed[i] == FREE && u[i].is_finite())
        .map(|i| i as u32)
        .collect();
    cells.sort_unstable_by(|&a, &b| u[a as usize].total_cmp(&u[b as usize]));
    let [_, s1, s2] = st.shape;
    for &c in &cells {
        let i = c as usize;
        let idx = [i / (s1 * s2), i / s2 % s1, i % s2];
        let mut best = (u[i], -1);
        for &k in st.axes() {
            let s = st.strides[k];
            let lo = (idx[k] > 0).then(|| i - s);
            let hi = (idx[k] + 1 < st.shape[k]).then(|| i + s);
            for j in [lo, hi].into_iter().flatten() {
                if u[j] < best.0 {
                    best = (u[j], labels[j]);
                }
            }
        }
        if best.1 >= 0 {
            labels[i] = best.1;
        }
    }
}

/// What one sweep needs besides the working arrays.
struct Sweep<'a> {
    st: &'a Stencil,
    cost: &'a crate::numerics::metric::IsotropicCost<'a>,
    fixed: &'a [u8],
    factor: Option<&'a Factor>,
    second: bool,
    multi: bool,
}

impl Sweep<'_> {
    /// One Gauss–Seidel pass in the given axis directions; returns the
    /// largest change (`+inf` when a cell got its first finite value).
    fn sweep(
        &self,
        reverse: [bool; 3],
        u: &mut [f64],
        labels: &mut [i32],
        control: &Control<'_>,
    ) -> Result<f64, EikonalError> {
        let [n0, n1, n2] = self.st.shape;
        let [s0, s1, _] = self.st.strides;
        let pick = |r: bool, len: usize, t: usize| if r { len - 1 - t } else { t };
        let mut change = 0.0f64;
        for t0 in 0..n0 {
            let a = pick(reverse[0], n0, t0);
            for t1 in 0..n1 {
                if control.is_cancelled() {
                    return Err(EikonalError::Cancelled);
                }
                let b = pick(reverse[1], n1, t1);
                let base = a * s0 + b * s1;
                for t2 in 0..n2 {
                    let c = pick(reverse[2], n2, t2);
                    let i = base + c;
                    if self.fixed[i] != FREE {
                        continue;
                    }
                    let w = self.cost.at(i);
                    let known = |j: usize| u[j] < f64::INFINITY;
                    let Some((v, l)) = update::<0, _, _>(
                        self.st,
                        i,
                        [a, b, c],
                        w,
                        u,
                        labels,
                        known,
                        self.second,
                        self.factor,
                        self.multi,
                        self.cost,
                    ) else {
                        continue;
                    };
                    let old = u[i];
                    if self.second {
                        if v != old {
                            change = change.max((v - old).abs());
                            u[i] = v;
                            labels[i] = l;
                        }
                    } else if v < old {
                        change = change.max(old - v);
                        u[i] = v;
                        labels[i] = l;
                    }
                }
            }
        }
        Ok(change)
    }
}
