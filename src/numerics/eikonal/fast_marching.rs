//! Fast marching (Sethian 1996; Tsitsiklis 1995) for `|∇U| = W` on 2D/3D grids.
//!
//! Every cell is `Far`, `Trial` (in the narrow band, an [`IndexedHeap`]) or
//! `Frozen`. The seed cells of the [`InitialFront`] wait in a queue sorted by
//! their prescribed values, which are Dirichlet data: they are never
//! recomputed. The smallest of the band and of the seed queue is frozen, and each of its non-frozen,
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
//! Three kernels compute the band values, all with the update of
//! [`super::update`]: `FirstOrder` (one source, first order, no factoring),
//! `OneSourceKernel` (one source, order 2 or factoring) and `General`
//! (several sources, with labels). The first two are specialisations in
//! fixed axis slots that give the very bits of the general update (checked
//! by proptests in `update.rs`); they exist for speed only.
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
//! (`i32`): nothing per cell for the state, which lives in the NaNs of `U`
//! while the march runs (see `Cells`), and 16 bytes per band or seed cell
//! (at most 16 bytes per cell); 1 byte per cell more when targets are given
//! and 8 when the freezing order is recorded (an output).
//!
//! [`StopRules`]: super::StopRules

use super::update::{
    first_order, one_axis_root, one_neighbour, one_source, one_source_first, update, Factor,
    FactorPoint, Stencil,
};
use super::{
    finish, target_cells, EikonalError, EikonalOptions, EikonalOutput, EikonalProblem,
    InitialFront, Order, StopReason,
};
use crate::numerics::control::Control;
use crate::numerics::heap::{IndexedHeap, Positions, ABSENT, FIRST_TAG};
use crate::numerics::metric::IsotropicCost;

// Cell states, kept with `U` in [`Cells`] (a slot `< FIRST_TAG` means
// Trial, i.e. in the band).
/// Not reached yet.
const FAR: u32 = ABSENT;
/// Final value (the cell holds its finite `U`).
const FROZEN: u32 = FIRST_TAG;
/// Never entered.
const WALL: u32 = FIRST_TAG + 1;
/// Waiting in the seed queue with a prescribed (Dirichlet) value: never recomputed.
const SEED: u32 = FIRST_TAG + 2;

/// True for the states whose value an update may (re)compute: Far and Trial.
#[inline]
fn open(state: u32) -> bool {
    state < FIRST_TAG || state == FAR
}

/// `U` and the state of every cell in one `f64`: a frozen cell holds its
/// (finite) value; any other cell holds a NaN whose low 32 bits are its heap
/// slot or tag. One array instead of two halves the cache lines and pages
/// touched per neighbour (3D grids are memory bound), and "known" is
/// `u < +inf`, which is false for every NaN.
struct Cells(Vec<f64>);

/// The high bits of a boxed slot or tag: a quiet NaN that arithmetic never
/// produces here (values are never NaN).
const BOX: u64 = 0x7ffc_0000_0000_0000;

impl Cells {
    fn new(n: usize) -> Self {
        Self(vec![f64::from_bits(BOX | u64::from(FAR)); n])
    }
}

impl Positions for Cells {
    #[inline(always)]
    fn get(&self, id: u32) -> u32 {
        let b = self.0[id as usize].to_bits();
        if b >> 32 == BOX >> 32 {
            b as u32
        } else {
            FROZEN
        }
    }
    #[inline(always)]
    fn set(&mut self, id: u32, p: u32) {
        self.0[id as usize] = f64::from_bits(BOX | u64::from(p));
    }
    fn len(&self) -> usize {
        self.0.len()
    }
}

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

    let mut m = March {
        st: &st,
        // One source: no labels during the march (all 0); they are made
        // from `U` at the end, in the pass that turns the NaNs into +inf.
        labels: if multi { vec![-1i32; n] } else { Vec::new() },
        heap: IndexedHeap::with_positions(Cells::new(n)),
        seeds: Vec::with_capacity(front.cells.len()),
        is_target: Vec::new(),
        targets_left: 0,
        order: options.record_order.then(|| vec![-1i64; n]),
    };
    if !cost.is_uniform() {
        for i in 0..n {
            if cost.is_wall(i) {
                m.heap.tag(i as u32, WALL);
            }
        }
    }
    if !options.stop.targets.is_empty() {
        m.is_target = vec![false; n];
        for t in target_cells(grid, &options.stop.targets)? {
            if !m.is_target[t] {
                m.is_target[t] = true;
                m.targets_left += 1;
            }
        }
    }
    // The seeds are frozen in increasing value, interleaved with the band:
    // a sorted queue beside the heap (ties go to the seed).
    for c in &front.cells {
        if multi {
            m.labels[c.index] = c.label;
        }
        m.heap.tag(c.index as u32, SEED);
        m.seeds.push((c.value, c.index as u32));
    }
    m.seeds
        .sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));

    // The first-order unfactored scheme with one source (labels are all 0)
    // has a kernel of its own, monomorphised on the kind of cost.
    let (stop, frozen) = if !second && factor.is_none() && !multi {
        match cost.uniform_value() {
            Some(w) => {
                let one = [0, 1, 2].map(|k| one_axis_root(&st, k, w));
                let cost = Uniform { w, one };
                m.run_first_order(cost, options, control)?
            }
            None => m.run_first_order(cost, options, control)?,
        }
    } else if !multi {
        // One source, order 2 or factoring: the fixed-slot kernel.
        let point = factor.as_ref().and_then(|f| f.point(0));
        match cost.uniform_value() {
            Some(w) => {
                let one = [0, 1, 2].map(|k| one_axis_root(&st, k, w));
                m.run_one_source(Uniform { w, one }, second, point, options, control)?
            }
            None => m.run_one_source(cost, second, point, options, control)?,
        }
    } else {
        // Several sources: the general kernel, with labels.
        let kernel = General {
            st: &st,
            cost,
            second,
            factor: factor.as_ref(),
        };
        m.run(&kernel, options, control)?
    };
    let March {
        mut labels,
        heap,
        order,
        ..
    } = m;
    // Every cell not frozen (early stop, unreachable, wall) gets +inf and
    // -1; with one source every frozen cell gets label 0.
    let mut u = heap.into_positions().0;
    if multi {
        for (v, l) in u.iter_mut().zip(labels.iter_mut()) {
            if v.is_nan() {
                *v = f64::INFINITY;
                *l = -1;
            }
        }
    } else {
        labels = u
            .iter_mut()
            .map(|v| {
                if v.is_nan() {
                    *v = f64::INFINITY;
                    -1
                } else {
                    0
                }
            })
            .collect();
    }
    control.report(1.0);
    Ok(finish(grid, u, labels, order, frozen, stop, None))
}

/// The working state of a solve.
struct March<'a> {
    st: &'a Stencil,
    /// The labels (several sources only; empty with one source, whose
    /// kernels neither read nor write labels).
    labels: Vec<i32>,
    /// The band; its position storage holds `U` and every cell's state.
    heap: IndexedHeap<Cells>,
    /// Seed cells `(value, index)` sorted by value; the first `next_seed` are frozen.
    seeds: Vec<(f64, u32)>,
    is_target: Vec<bool>,
    targets_left: usize,
    order: Option<Vec<i64>>,
}

impl March<'_> {
    /// [`March::run`] with the first-order kernel, its axis loops unrolled
    /// for the usual 2D and 3D grids.
    fn run_first_order<C: CostAt>(
        &mut self,
        cost: C,
        options: &EikonalOptions,
        control: &Control<'_>,
    ) -> Result<(StopReason, usize), EikonalError> {
        let st = self.st;
        match st.trailing() {
            Some(2) => self.run(&FirstOrder::<C, 2> { st, cost }, options, control),
            Some(3) => self.run(&FirstOrder::<C, 3> { st, cost }, options, control),
            _ => self.run(&FirstOrder::<C, 0> { st, cost }, options, control),
        }
    }

    /// [`March::run`] with the one-source kernel of order 2 or factoring.
    fn run_one_source<C: CostAt>(
        &mut self,
        cost: C,
        second: bool,
        point: Option<FactorPoint>,
        options: &EikonalOptions,
        control: &Control<'_>,
    ) -> Result<(StopReason, usize), EikonalError> {
        let st = self.st;
        match st.trailing() {
            Some(2) => {
                let k = OneSourceKernel::<C, 2> {
                    st,
                    cost,
                    second,
                    point,
                };
                self.run(&k, options, control)
            }
            Some(3) => {
                let k = OneSourceKernel::<C, 3> {
                    st,
                    cost,
                    second,
                    point,
                };
                self.run(&k, options, control)
            }
            _ => {
                let k = OneSourceKernel::<C, 0> {
                    st,
                    cost,
                    second,
                    point,
                };
                self.run(&k, options, control)
            }
        }
    }

    /// Freezes cells until the band is empty or a stop rule fires; returns
    /// the reason and the number of frozen cells.
    fn run<K: Kernel>(
        &mut self,
        kernel: &K,
        options: &EikonalOptions,
        control: &Control<'_>,
    ) -> Result<(StopReason, usize), EikonalError> {
        let n = self.heap.positions().len();
        let st = self.st;
        let mut next_seed = 0usize;
        let mut frozen = 0usize;
        let stop = loop {
            if frozen.is_multiple_of(CANCEL_EVERY) && control.is_cancelled() {
                return Err(EikonalError::Cancelled);
            }
            if frozen.is_multiple_of(PROGRESS_EVERY) && frozen > 0 {
                control.report(frozen as f64 / n as f64);
            }
            let seed = self.seeds.get(next_seed).copied();
            let (id, key, from_seed) = match (self.heap.peek(), seed) {
                (Some((hid, hk)), Some((sk, sid))) => {
                    if sk <= hk {
                        (sid, sk, true)
                    } else {
                        (hid, hk, false)
                    }
                }
                (Some((hid, hk)), None) => (hid, hk, false),
                (None, Some((sk, sid))) => (sid, sk, true),
                (None, None) => break StopReason::Completed,
            };
            if options.stop.max_distance.is_some_and(|d| key > d) {
                break StopReason::MaxDistance;
            }
            if options.stop.max_frozen.is_some_and(|m| frozen >= m) {
                break StopReason::MaxFrozen;
            }
            if from_seed {
                next_seed += 1;
            } else {
                self.heap.pop();
            }
            let i = id as usize;
            self.heap.positions_mut().0[i] = key;
            if let Some(o) = self.order.as_mut() {
                o[i] = frozen as i64;
            }
            frozen += 1;
            if self.targets_left > 0 && self.is_target[i] {
                self.targets_left -= 1;
                if self.targets_left == 0 {
                    break StopReason::TargetsReached;
                }
            }

            let idx = st.unravel(i);
            kernel.frozen(i, idx);
            // Constant axis numbers for the usual 2D and 3D grids, so that
            // the index stays in registers (a loop over the axes is not
            // unrolled: its body is too large).
            match K::AXES {
                2 => {
                    self.visit_axis::<K, 1>(kernel, i, idx);
                    self.visit_axis::<K, 2>(kernel, i, idx);
                }
                3 => {
                    self.visit_axis::<K, 0>(kernel, i, idx);
                    self.visit_axis::<K, 1>(kernel, i, idx);
                    self.visit_axis::<K, 2>(kernel, i, idx);
                }
                _ => {
                    for &k in st.axes() {
                        let s = st.strides[k];
                        if idx[k] > 0 {
                            self.visit(kernel, i - s, i, idx, k, idx[k] - 1);
                        }
                        if idx[k] + 1 < st.shape[k] {
                            self.visit(kernel, i + s, i, idx, k, idx[k] + 1);
                        }
                    }
                }
            }
        };
        Ok((stop, frozen))
    }

    /// Visits the two neighbours of cell `i` (padded index `idx`) along axis `AX`.
    #[inline(always)]
    fn visit_axis<K: Kernel, const AX: usize>(&mut self, kernel: &K, i: usize, idx: [usize; 3]) {
        let st = self.st;
        let s = st.strides[AX];
        if idx[AX] > 0 {
            self.visit(kernel, i - s, i, idx, AX, idx[AX] - 1);
        }
        if idx[AX] + 1 < st.shape[AX] {
            self.visit(kernel, i + s, i, idx, AX, idx[AX] + 1);
        }
    }

    /// Recomputes cell `j` (index `idx` with `idx[k] = jk`), the neighbour
    /// along axis `k` of cell `i` (index `idx`) just frozen, if it is Far or
    /// Trial.
    ///
    /// A Far cell has no frozen neighbour but `i`: every earlier visit of
    /// it would have made it Trial, unless its value overflowed, and a
    /// neighbour that far up cannot be used by the update either. Its
    /// value then comes from `i` alone ([`Kernel::first`]).
    #[inline(always)]
    fn visit<K: Kernel>(
        &mut self,
        kernel: &K,
        j: usize,
        i: usize,
        idx: [usize; 3],
        k: usize,
        jk: usize,
    ) {
        let state = self.heap.state(j as u32);
        if !open(state) {
            return;
        }
        let mut jdx = idx;
        jdx[k] = jk;
        if K::FIRST && state == FAR {
            let st = self.st;
            let u = &self.heap.positions().0;
            // The cell beyond `i`, on the side away from `j`.
            let beyond = if j < i {
                (idx[k] + 1 < st.shape[k]).then(|| i + (i - j))
            } else {
                (idx[k] >= 1).then(|| i - (j - i))
            };
            if let Some(v) = kernel.first(j, jdx, i, u[i], k, beyond, u) {
                self.heap.push(j as u32, v);
            }
            return;
        }
        if let Some((v, l)) = kernel.value(j, jdx, &self.heap.positions().0, &self.labels) {
            if K::LABELS {
                self.labels[j] = l;
            }
            // The state read above is still current: the kernel only reads.
            self.heap.set_key_at(j as u32, state, v);
        }
    }
}

/// How a band value is computed from the frozen neighbours.
trait Kernel {
    /// Whether the kernel gives labels; if not (one source) every reached
    /// cell gets label 0 at the end.
    const LABELS: bool;

    /// The number of axes when they are the last `AXES` padded axes
    /// ([`Stencil::trailing`]), 0 for any other layout.
    const AXES: usize;

    /// Whether [`Kernel::first`] is implemented.
    const FIRST: bool = false;

    /// The value of a Far cell `j` (index `jdx`) whose only known neighbour is `i`, of
    /// value `ui`, along axis `k` (`beyond` is the cell after `i` on that
    /// axis, if any), or `None`: the same as [`Kernel::value`] would give,
    /// without reading the other neighbours.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn first(
        &self,
        _j: usize,
        _jdx: [usize; 3],
        _i: usize,
        _ui: f64,
        _k: usize,
        _beyond: Option<usize>,
        _u: &[f64],
    ) -> Option<f64> {
        None
    }

    /// Called when cell `i` is frozen, before its neighbours are visited.
    #[inline(always)]
    fn frozen(&self, _i: usize, _idx: [usize; 3]) {}

    /// The new value and label of cell `j` (padded index `jdx`), or `None`;
    /// `u` is finite exactly on the frozen cells (NaN or `+inf` elsewhere).
    fn value(&self, j: usize, jdx: [usize; 3], u: &[f64], labels: &[i32]) -> Option<(f64, i32)>;
}

/// The general update of [`super::update`] for several sources: either
/// order, factoring, labels.
struct General<'a> {
    st: &'a Stencil,
    cost: &'a IsotropicCost<'a>,
    second: bool,
    factor: Option<&'a Factor>,
}

impl Kernel for General<'_> {
    const LABELS: bool = true;
    const AXES: usize = 0;

    #[inline(always)]
    fn frozen(&self, i: usize, idx: [usize; 3]) {
        prefetch_rows(self.st, self.cost, i, idx);
    }

    /// Not inlined: its callers would grow too much (measured 7 % slower
    /// with one source, when this kernel served it). The index `jdx` is
    /// recomputed from `j` (two multiplications): an index passed through
    /// memory costs a failed store-to-load forwarding per call.
    #[inline]
    fn value(&self, j: usize, _jdx: [usize; 3], u: &[f64], labels: &[i32]) -> Option<(f64, i32)> {
        let jdx = self.st.unravel(j);
        let w = self.cost.at(j);
        let known = |x: usize| u[x] < f64::INFINITY;
        update::<0, _, _>(
            self.st,
            j,
            jdx,
            w,
            u,
            labels,
            known,
            self.second,
            self.factor,
            true,
            self.cost,
        )
    }
}

/// A cost lookup, monomorphised: a constant or the general field.
trait CostAt {
    fn at(&self, i: usize) -> f64;
    /// [`one_axis_root`] of axis `k` at a cell of cost `w`.
    fn one_axis(&self, st: &Stencil, k: usize, w: f64) -> f64;
    /// [`prefetch_rows`] for a cost field, nothing for a constant.
    #[inline(always)]
    fn prefetch_rows(&self, _st: &Stencil, _i: usize, _idx: [usize; 3]) {}
}

/// A uniform cost, with its one-axis roots precomputed per axis.
struct Uniform {
    w: f64,
    one: [f64; 3],
}

impl CostAt for Uniform {
    #[inline(always)]
    fn at(&self, _: usize) -> f64 {
        self.w
    }
    #[inline(always)]
    fn one_axis(&self, _: &Stencil, k: usize, _: f64) -> f64 {
        self.one[k]
    }
}

impl CostAt for &IsotropicCost<'_> {
    #[inline(always)]
    fn at(&self, i: usize) -> f64 {
        IsotropicCost::at(self, i)
    }
    #[inline(always)]
    fn one_axis(&self, st: &Stencil, k: usize, w: f64) -> f64 {
        one_axis_root(st, k, w)
    }
    #[inline(always)]
    fn prefetch_rows(&self, st: &Stencil, i: usize, idx: [usize; 3]) {
        prefetch_rows(st, self, i, idx);
    }
}

/// Prefetches the costs of the cells four steps away from frozen cell `i`
/// (index `idx`) across rows (axes 0 and 1 of the padded shape). They are
/// visited soon, and their cost lies in lines the front has not touched yet
/// (a cache miss per row entered; their `U` lines are already read by the
/// updates of the cells in between, and prefetching those as well measured
/// nothing). Four rows ahead measured a few per cent faster than two on the
/// Poincaré case, eight the same as four within the noise. Along the rows
/// the hardware prefetcher sees the stream itself.
#[inline(always)]
fn prefetch_rows(st: &Stencil, cost: &IsotropicCost<'_>, i: usize, idx: [usize; 3]) {
    for ((&x, &n), &s) in idx.iter().zip(&st.shape).zip(&st.strides).take(2) {
        if n > 1 {
            if x >= 4 {
                cost.prefetch(i - 4 * s);
            }
            if x + 4 < n {
                cost.prefetch(i + 4 * s);
            }
        }
    }
}

/// The first-order unfactored update for one source ([`first_order`]);
/// `A > 0` when the axes are the last `A` ones ([`Stencil::axes_as`]).
struct FirstOrder<'a, C, const A: usize> {
    st: &'a Stencil,
    cost: C,
}

impl<C: CostAt, const A: usize> Kernel for FirstOrder<'_, C, A> {
    const LABELS: bool = false;
    const AXES: usize = A;

    #[inline(always)]
    fn frozen(&self, i: usize, idx: [usize; 3]) {
        self.cost.prefetch_rows(self.st, i, idx);
    }

    #[inline(always)]
    fn value(&self, j: usize, jdx: [usize; 3], u: &[f64], _labels: &[i32]) -> Option<(f64, i32)> {
        let w = self.cost.at(j);
        let one = |k| self.cost.one_axis(self.st, k, w);
        first_order::<A>(self.st, j, jdx, w, u, one).map(|v| (v, 0))
    }

    const FIRST: bool = true;

    #[inline(always)]
    fn first(
        &self,
        j: usize,
        _jdx: [usize; 3],
        _i: usize,
        ui: f64,
        k: usize,
        _beyond: Option<usize>,
        _u: &[f64],
    ) -> Option<f64> {
        let w = self.cost.at(j);
        let one = self.cost.one_axis(self.st, k, w);
        one_neighbour(self.st, k, w, ui, f64::INFINITY, false, one, || w)
    }
}

/// The update of one source with order 2 or factoring ([`one_source`]).
struct OneSourceKernel<'a, C, const A: usize> {
    st: &'a Stencil,
    cost: C,
    second: bool,
    point: Option<FactorPoint>,
}

impl<C: CostAt, const A: usize> Kernel for OneSourceKernel<'_, C, A> {
    const LABELS: bool = false;
    const AXES: usize = A;

    #[inline(always)]
    fn frozen(&self, i: usize, idx: [usize; 3]) {
        self.cost.prefetch_rows(self.st, i, idx);
    }

    #[inline]
    fn value(&self, j: usize, _jdx: [usize; 3], u: &[f64], _labels: &[i32]) -> Option<(f64, i32)> {
        let jdx = self.st.unravel(j);
        let w = self.cost.at(j);
        let cost = |x| self.cost.at(x);
        one_source::<A>(self.st, j, jdx, w, u, self.second, self.point, cost).map(|v| (v, 0))
    }

    const FIRST: bool = true;

    #[inline(always)]
    fn first(
        &self,
        j: usize,
        jdx: [usize; 3],
        i: usize,
        ui: f64,
        k: usize,
        beyond: Option<usize>,
        u: &[f64],
    ) -> Option<f64> {
        let w = self.cost.at(j);
        let a2 = beyond.map_or(f64::INFINITY, |b| u[b]);
        let sigma = if i > j { 1.0 } else { -1.0 };
        let one = self.cost.one_axis(self.st, k, w);
        let (st, second, point) = (self.st, self.second, self.point);
        let cost_i = || self.cost.at(i);
        match one_source_first::<A>(st, jdx, k, sigma, w, ui, a2, second, point, one, cost_i) {
            Some(v) => v,
            // The strip rule reads the other neighbours: the full update.
            None => self.value(j, jdx, u, &[]).map(|r| r.0),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::{solve, EikonalOptions, Order, Source};
    use crate::numerics::{Control, EikonalProblem, Grid, IsotropicCost};

    fn first_order_unit(shape: &[usize], p: Vec<f64>) -> Vec<f64> {
        let problem = EikonalProblem {
            grid: Grid::unit(shape).unwrap(),
            cost: IsotropicCost::constant(1.0).unwrap(),
            sources: vec![Source::Point(p)],
        };
        let o = EikonalOptions::DEFAULT
            .with_order(Order::First)
            .with_factoring(false);
        let out = solve(&problem, &o, &Control::new()).unwrap();
        out.distance.iter().copied().collect()
    }

    #[test]
    fn unrolled_and_generic_axis_loops_agree() {
        // (6, 7) runs the kernel unrolled for the last two axes; (6, 1, 7)
        // has the same cells but its axes are 0 and 2 (generic loop).
        let a = first_order_unit(&[6, 7], vec![2.3, 4.1]);
        let b = first_order_unit(&[6, 1, 7], vec![2.3, 0.0, 4.1]);
        assert_eq!(a, b);
        // One axis: exact U = |x − p| beyond the seeds.
        let c = first_order_unit(&[1, 9], vec![0.0, 2.0]);
        for (x, u) in c.iter().enumerate() {
            assert_eq!(*u, (x as f64 - 2.0).abs());
        }
    }
}
