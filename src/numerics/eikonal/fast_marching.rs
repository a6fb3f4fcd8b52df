//! Fast marching (Sethian 1996; Tsitsiklis 1995) for `|∇U| = W` on 2D/3D grids.
//!
//! Every cell is `Far`, `Trial` (in the narrow band, an [`IndexedHeap`]) or
//! `Frozen`. The seed cells of the [`InitialFront`] enter the band with their
//! prescribed values, which are Dirichlet data: they are never recomputed.
//! The band cell of smallest value is frozen, and each of its non-frozen,
//! non-wall axis neighbours is recomputed from its frozen neighbours with the
//! upwind update of [`super::update`] (the latest recomputation replaces the
//! band value: for the second-order scheme, which uses more information as
//! more neighbours freeze, it can go up as well as down). Complexity
//! `O(N log N)`.
//!
//! * [`Order::First`]: the first-order upwind quadratic, error `O(h |log h|)`
//!   for a point source, `O(h)` for smooth data.
//! * [`Order::Second`]: one-sided second-order differences where the stencil
//!   exists, first order elsewhere (Sethian's FMM 2). Combined with source
//!   factoring (Treister–Haber 2016) the error at a point source is `O(h²)`
//!   for smooth costs (measured in `tests/eikonal_accuracy.rs`).
//! * Factoring ([`EikonalOptions::factoring`], default on) applies to point
//!   sources over the whole domain, not only within a radius: the cone
//!   `U_0` is an excellent local model near the source and is harmless far
//!   from it (the scheme then solves for a smooth `V = U − U_0`), and the
//!   second-order convergence of the whole map needs it everywhere.
//!
//! Walls (`W = +inf`) are never updated. Cells that cannot be reached keep
//! `U = +inf` and label `-1`. Voronoi labels: a cell takes the label of the
//! upwind neighbour with the smallest value used in its update.
//!
//! Stop rules ([`StopRules`]): targets (all their nearest cells frozen),
//! `max_distance` (the smallest band value exceeds it) and `max_frozen`. On
//! an early stop every non-frozen cell gets `U = +inf` and label `-1`.
//! Cancellation is polled every 4096 frozen cells; progress is reported every
//! 65536 frozen cells and at the end.
//!
//! Memory beyond the input cost and the output `U` (`f64`) and labels
//! (`i32`): 1 byte of state and 4 bytes of heap position per cell, plus 16
//! bytes per band cell (at most 21 bytes per cell); 1 byte per cell more when
//! targets are given and 8 when the freezing order is recorded (an output).
//!
//! [`StopRules`]: super::StopRules

use super::update::{update, Factor, Stencil};
use super::{
    finish, target_cells, EikonalError, EikonalOptions, EikonalOutput, EikonalProblem,
    InitialFront, Order, StopReason,
};
use crate::numerics::control::Control;
use crate::numerics::heap::IndexedHeap;

const FAR: u8 = 0;
const TRIAL: u8 = 1;
const FROZEN: u8 = 2;
const WALL: u8 = 3;
/// In the band with a prescribed (Dirichlet) value: never recomputed.
const SEED: u8 = 4;

const CANCEL_EVERY: usize = 4096;
const PROGRESS_EVERY: usize = 65536;

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
    let st = Stencil::new(grid);
    let second = options.order == Order::Second;
    let multi = problem.sources.len() > 1;
    let factor = if options.factoring {
        Factor::new(problem, front)
    } else {
        None
    };

    let mut u = vec![f64::INFINITY; n];
    let mut labels = vec![-1i32; n];
    let mut state = vec![FAR; n];
    if !cost.is_uniform() {
        for (i, s) in state.iter_mut().enumerate() {
            if cost.is_wall(i) {
                *s = WALL;
            }
        }
    }

    let mut is_target: Vec<bool> = Vec::new();
    let mut targets_left = 0usize;
    if !options.stop.targets.is_empty() {
        is_target = vec![false; n];
        for t in target_cells(grid, &options.stop.targets)? {
            if !is_target[t] {
                is_target[t] = true;
                targets_left += 1;
            }
        }
    }

    let mut heap = IndexedHeap::new(n);
    for c in &front.cells {
        u[c.index] = c.value;
        labels[c.index] = c.label;
        state[c.index] = SEED;
        heap.push(c.index as u32, c.value);
    }
    let mut order = options.record_order.then(|| vec![-1i64; n]);

    let mut frozen = 0usize;
    let stop = loop {
        if frozen.is_multiple_of(CANCEL_EVERY) && control.is_cancelled() {
            return Err(EikonalError::Cancelled);
        }
        if frozen.is_multiple_of(PROGRESS_EVERY) && frozen > 0 {
            control.report(frozen as f64 / n as f64);
        }
        let Some((id, key)) = heap.peek() else {
            break StopReason::Completed;
        };
        if options.stop.max_distance.is_some_and(|d| key > d) {
            break StopReason::MaxDistance;
        }
        if options.stop.max_frozen.is_some_and(|m| frozen >= m) {
            break StopReason::MaxFrozen;
        }
        heap.pop();
        let i = id as usize;
        state[i] = FROZEN;
        if let Some(o) = order.as_mut() {
            o[i] = frozen as i64;
        }
        frozen += 1;
        if targets_left > 0 && is_target[i] {
            targets_left -= 1;
            if targets_left == 0 {
                break StopReason::TargetsReached;
            }
        }

        let idx = grid.unravel(i);
        for &k in st.axes() {
            let s = st.strides[k];
            for up in [false, true] {
                let (j, jk) = if up {
                    if idx[k] + 1 >= st.shape[k] {
                        continue;
                    }
                    (i + s, idx[k] + 1)
                } else {
                    if idx[k] == 0 {
                        continue;
                    }
                    (i - s, idx[k] - 1)
                };
                let sj = state[j];
                if sj != FAR && sj != TRIAL {
                    continue;
                }
                let mut jdx = idx;
                jdx[k] = jk;
                let w = cost.at(j);
                let known = |x: usize| state[x] == FROZEN;
                if let Some((v, l)) = update(
                    &st,
                    j,
                    jdx,
                    w,
                    &u,
                    &labels,
                    known,
                    second,
                    factor.as_ref(),
                    multi,
                    cost,
                ) {
                    u[j] = v;
                    labels[j] = l;
                    state[j] = TRIAL;
                    heap.set_key(j as u32, v);
                }
            }
        }
    };

    if stop != StopReason::Completed {
        for ((s, v), l) in state.iter().zip(u.iter_mut()).zip(labels.iter_mut()) {
            if *s != FROZEN {
                *v = f64::INFINITY;
                *l = -1;
            }
        }
    }
    control.report(1.0);
    Ok(finish(grid, u, labels, order, frozen, stop, None))
}
