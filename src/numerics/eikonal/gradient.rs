//! The gradient of a fast-marching distance with respect to the cost: the
//! discrete adjoint of the unfactored scheme, orders 1 and 2 (seed section
//! 2.9, "how does `U` change when the metric `W` changes").
//!
//! # The equation that is differentiated
//!
//! [`super::solve`] with [`Method::FastMarching`], [`Order::First`] and
//! `factoring: false` gives every reached cell `x` that is not a seed its
//! value from the cells frozen before it. Along each axis `k` of length
//! `> 1` the upwind value is `a_k = min(U(x − e_k), U(x + e_k))` over the
//! neighbours frozen before `x` (the lower side on a tie), `+inf` if there
//! is none, and `U_x` is the root of the upwind quadratic
//!
//! ```text
//! F(U_x, a, W_x) = Σ_k c_k ((U_x − a_k)⁺)² − W_x² = 0,     c_k = 1 / h_k²
//! ```
//!
//! (`h_k` the spacing of axis `k`): an axis whose `a_k ≥ U_x` does not
//! contribute, which is the solver's causal dropping of axes. Fast marching
//! freezes in non-decreasing `U`, so "frozen before `x`" is `U_nb < U_x` for
//! every neighbour that matters (a neighbour with `U_nb = U_x` has a zero
//! term either way). With several sources a cell whose frozen neighbours
//! carry several labels takes the smallest of the per-label updates; the
//! winning label is the cell's label, so the upwind neighbours are those of
//! the cell's own label. Implicit differentiation, with `d_k = U_x − a_k` over the
//! contributing axes and `S = Σ_k c_k d_k > 0`:
//!
//! ```text
//! ∂U_x/∂W_x = W_x / S,        ∂U_x/∂a_k = c_k d_k / S
//! ```
//!
//! # The adjoint
//!
//! For `J = Σ_m w_m U(y_m)` the adjoint state `λ` starts as the weights
//! (`λ_x = Σ_{m: y_m = x} w_m`, a point between cells spreading its weight
//! over its corners with the multilinear weights) and one sweep over the
//! reached cells in decreasing `U` (every upwind neighbour has a strictly
//! smaller `U` than the cell it serves, so each `λ_x` is final when `x` is
//! reached) does, for a non-seed cell,
//!
//! ```text
//! ∂J/∂W_x = λ_x W_x / S_x,        λ_{a_k(x)} += λ_x c_k d_k / S_x.
//! ```
//!
//! The cost is one sort of the reached cells by `U` (or none, when the solve
//! recorded its freezing order) and one pass over them that rebuilds each
//! update: comparable to a solve. With one label, order 1 reads its
//! derivatives off `U_x` without solving the quadratic again
//! (`first_order_step`) and order 2 gathers its update in fixed slots
//! (`second_order_step`): on 1024² (release, one thread) the adjoint takes
//! about 0.75 (order 1) and 1.3 (order 2) times the solve; see the ignored
//! test `time_against_one_solve` and `tests/bench/README.md`.
//!
//! # Sources
//!
//! Seed cells hold Dirichlet values and are not recomputed. A cell given by
//! [`Source::Cells`] has a value that does not depend on `W`: its `λ` stops
//! there. A cell seeded by a [`Source::Point`] `p` holds `W(q) |x − p|_h`,
//! `q` the cell nearest to `p` (see [`InitialFront`]), so its `λ` goes to
//! `∂J/∂W_q += λ_x |x − p|_h`. With this term the discrete `U` is
//! homogeneous of degree 1 in `W` (`U(tW) = t U(W)`), hence Euler's identity
//! `Σ_x W_x ∂J/∂W_x = J`, which the tests check to round-off.
//!
//! Walls (`W = +inf`) and cells never reached get 0.
//!
//! # Points, paths
//!
//! The gradient of `U` at one point is [`distance_gradient`], the case of
//! one weight `1`. The length of a minimal path from a point to the sources
//! (its cost `∫ W ds`) equals `U` there, so this is also the sensitivity of
//! a minimal path's length to the cost (the envelope theorem: the path's own
//! change does not enter at first order).
//!
//! # Where it is not differentiable
//!
//! `U` is a piecewise smooth function of `W`: the pieces change where an
//! axis' two neighbours tie (`a_k` switches sides: on the cut locus, where
//! two fronts of one source meet) or where two labels tie (a Voronoi
//! boundary). There the result is one one-sided derivative (the solver's
//! choice of side, the lower side on a tie). The solver's fallback for
//! overflow (the one-axis step `a_k + h_k W_x` when the quadratic has no
//! finite root) is differentiated as that step.
//!
//! # Order 2
//!
//! [`Order::Second`] is differentiated the same way, from the update the
//! solver made (see [`super::update`]): along an axis whose second upwind
//! cell `x + 2σe_k` was known with `a2_k < a1_k`, the term is
//! `c_k = 9/(4h_k²)`, `b_k = (4a1_k − a2_k)/3`, elsewhere the first-order
//! one; the root is kept if it is at least every active `a1_k`, then capped
//! by the straight steps `a1_k + h_k max(W_x, W_{x+σe_k})` (a binding cap has
//! `∂U_x/∂a1_k = 1` and `∂U_x/∂W = h_k` on the larger of the two costs);
//! otherwise the first-order root. Order 2 does not freeze in increasing
//! `U` (a value may go up as more neighbours freeze), so the cells known at a
//! cell's last update are read from the freezing ranks
//! ([`EikonalOptions::record_order`], required for order 2): the cells
//! frozen no later than the last neighbour frozen before it, and the
//! backward sweep goes in decreasing rank.
//!
//! Every rebuilt update is checked against the solve's value (relative
//! `1e-9`): an output that does not come from the problem and options given
//! is refused ([`EikonalError::Option`] on `output`).
//!
//! Not supported (refused with [`EikonalError::Option`] naming the option):
//! source factoring, fast sweeping and Dijkstra.
//!
//! [`Method::FastMarching`]: super::Method::FastMarching
//! [`Source::Cells`]: super::Source::Cells
//! [`Source::Point`]: super::Source::Point

use std::borrow::Cow;

use ndarray::{ArrayD, IxDyn};

use super::sources::nearest_cell;
use super::update::Stencil;
use super::{
    EikonalError, EikonalOptions, EikonalOutput, EikonalProblem, InitialFront, Method, Order,
    Source,
};
use crate::numerics::control::Control;
use crate::numerics::grid::Grid;

/// Cells between two polls of the cancel flag.
const CANCEL_EVERY: usize = 4096;
/// Cells between two progress reports.
const PROGRESS_EVERY: usize = 65536;

/// Where the distance is read for the objective `J = Σ_m w_m U(y_m)`.
#[derive(Debug, Clone, PartialEq)]
pub enum Probe {
    /// A cell, in array index order (axis 0 first).
    Cell(Vec<usize>),
    /// A point in index coordinates (axis 0 first), possibly between cells:
    /// `U` there is the multilinear interpolation of the `2^d` cells around
    /// it (the corners of weight `> 0` must be reached).
    Point(Vec<f64>),
}

/// The gradient of `J = Σ_m w_m U(y_m)` with respect to the cost `W` of
/// every cell, the discrete adjoint of the solve that gave `output` (see the
/// module documentation for the equation and the handling of sources).
///
/// `problem` and `options` must be those of the solve; `options` must be
/// fast marching without factoring, of order 1, or of order 2 with
/// [`EikonalOptions::record_order`] (anything else is refused with
/// [`EikonalError::Option`] naming the option). Each probe
/// must be reached (`U < +inf` at it); a weight must be finite. The result
/// has the grid's shape; walls and unreached cells get 0. `W` is the cost
/// as [`crate::numerics::IsotropicCost::at`] returns it (for a speed field
/// `F = 1/W`, `∂J/∂F = −W² ∂J/∂W`).
///
/// Polls `control` every 4096 cells; reports progress.
///
/// # Examples
/// ```
/// use geodex::numerics::eikonal::{cost_gradient, Probe};
/// use geodex::numerics::{solve, Control, EikonalOptions, EikonalProblem, Grid, IsotropicCost, Order, Source};
/// let problem = EikonalProblem {
///     grid: Grid::unit(&[1, 6])?,
///     cost: IsotropicCost::constant(2.0)?,
///     sources: vec![Source::Point(vec![0.0, 0.0])],
/// };
/// let options = EikonalOptions::DEFAULT.with_order(Order::First).with_factoring(false);
/// let out = solve(&problem, &options, &Control::new())?;
/// let g = cost_gradient(&problem, &options, &out, &[(Probe::Cell(vec![0, 5]), 1.0)], &Control::new())?;
/// // U(5) = W |5 − 0|: each cell on the way adds its length.
/// let total: f64 = g.iter().sum();
/// assert!((total - 5.0).abs() < 1e-12);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn cost_gradient(
    problem: &EikonalProblem<'_>,
    options: &EikonalOptions,
    output: &EikonalOutput,
    weights: &[(Probe, f64)],
    control: &Control<'_>,
) -> Result<ArrayD<f64>, EikonalError> {
    let march = Replay::new(problem, options, output, control)?;
    let probes = probe_weights(&problem.grid, &march.u, weights)?;
    let grad = front_order_sweep(&march, output, &probes, Steps::Specialised, control)?;
    control.report(1.0);
    ArrayD::from_shape_vec(IxDyn(problem.grid.shape()), grad).map_err(|e| EikonalError::Option {
        field: "output",
        reason: e.to_string(),
    })
}

/// The backward sweep over the cells in front order ([`backward_order`]),
/// each row rebuilt where it is needed ([`adjoint_step`]): no memory
/// beyond `λ`. The cells of a front lie scattered in memory, so each step
/// would wait on cache misses; chunks of cells are read ahead
/// ([`Replay::warm`]). Storing every row first, in index order, and
/// sweeping them in rank space was measured slower (0.20 s against 0.15 s
/// at order 1 on 1024²): rebuilding the rows, not the misses, dominates.
fn front_order_sweep(
    march: &Replay<'_>,
    output: &EikonalOutput,
    probes: &[(usize, f64)],
    steps: Steps,
    control: &Control<'_>,
) -> Result<Vec<f64>, EikonalError> {
    let specialised = steps == Steps::Specialised;
    // `[λ_x, ∂J/∂W_x]` side by side: one cache line serves both.
    let mut acc = vec![[0.0f64; 2]; march.u.len()];
    for &(i, w) in probes {
        acc[i][0] += w;
    }
    let order = backward_order(&march.u, output);
    for (c, chunk) in order.chunks(WARM_CHUNK).enumerate() {
        poll(control, c * WARM_CHUNK, order.len())?;
        // First read what the chunk's steps will read, in a loop of
        // independent loads that the processor overlaps; the steps then
        // find it in the cache instead of waiting for each miss in turn
        // (about 10 % of this sweep on 1024²).
        std::hint::black_box(chunk.iter().fold(0.0, |s, &x| s + march.warm(x, &acc)));
        if specialised && march.plain_first_order() {
            for &x in chunk {
                first_order_step(march, x, &mut acc)?;
            }
        } else if specialised && march.plain_second_order() {
            for &x in chunk {
                second_order_step(march, x, &mut acc)?;
            }
        } else {
            for &x in chunk {
                adjoint_step(march, x, &mut acc)?;
            }
        }
    }
    Ok(acc.iter().map(|a| a[1]).collect())
}

/// Which steps the backward sweep takes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Steps {
    /// [`first_order_step`] and [`second_order_step`] where they apply
    /// (one label), [`adjoint_step`] elsewhere.
    Specialised,
    /// [`adjoint_step`] everywhere (the tests' reference).
    #[cfg_attr(not(test), allow(dead_code))]
    General,
}

/// The cancel poll and the progress report of the sweep at its `done`-th
/// cell of `total`.
fn poll(control: &Control<'_>, done: usize, total: usize) -> Result<(), EikonalError> {
    if done.is_multiple_of(CANCEL_EVERY) && control.is_cancelled() {
        return Err(EikonalError::Cancelled);
    }
    if done.is_multiple_of(PROGRESS_EVERY) && done > 0 {
        control.report(done as f64 / total as f64);
    }
    Ok(())
}

/// Cells of the backward sweep whose memory is read ahead at once
/// ([`Replay::warm`]): enough loads in flight to hide the misses, few
/// enough lines (about a dozen per cell) to stay in the first-level cache.
/// It divides [`CANCEL_EVERY`] and [`PROGRESS_EVERY`], so that their polls
/// fall on the starts of chunks.
const WARM_CHUNK: usize = 32;
const _: () =
    assert!(CANCEL_EVERY.is_multiple_of(WARM_CHUNK) && PROGRESS_EVERY.is_multiple_of(WARM_CHUNK));

/// One cell `x` of the backward sweep: its `λ` goes to `∂J/∂W` and to
/// the `λ` of the cells its update read (see the module documentation).
fn adjoint_step(march: &Replay<'_>, x: usize, acc: &mut [[f64; 2]]) -> Result<(), EikonalError> {
    let lam = acc[x][0];
    if lam == 0.0 {
        return Ok(());
    }
    if let Some(seed) = march.seed(x) {
        // A point source's seed is `W(q) |x − p|_h`; a cell source's
        // value does not depend on `W`.
        if let Some((q, r)) = seed {
            acc[q][1] += lam * r;
        }
        return Ok(());
    }
    if let Some(row) = march.row(x)? {
        apply_row(acc, x, lam, &row);
    }
    Ok(())
}

/// `λ_x` through the row of `x`: `∂J/∂W` of `x` (and of the neighbour a
/// binding cap reads) and `λ` of the cells its update read.
#[inline]
fn apply_row(acc: &mut [[f64; 2]], x: usize, lam: f64, row: &Row) {
    acc[x][1] += lam * row.dw;
    if let Some((j, d)) = row.dw_neighbour {
        acc[j][1] += lam * d;
    }
    for &(j, d) in row.du() {
        acc[j][0] += lam * d;
    }
}

/// The common start of the specialised steps: `Some(λ_x)` for a cell they
/// take; `None` when there is nothing to carry (`λ_x = 0`) or when `x` is a
/// seed, which [`adjoint_step`] has then handled.
#[inline]
fn ordinary_cell(
    march: &Replay<'_>,
    x: usize,
    acc: &mut [[f64; 2]],
) -> Result<Option<f64>, EikonalError> {
    let lam = acc[x][0];
    if lam == 0.0 {
        return Ok(None);
    }
    if march.seed(x).is_some() {
        adjoint_step(march, x, acc)?;
        return Ok(None);
    }
    Ok(Some(lam))
}

/// [`adjoint_step`] for order 1 with one label, without rebuilding the
/// update: order 1 freezes in non-decreasing `U`, so the axis `k`'s upwind
/// value is the smaller of its two neighbours (the lower one on a tie), it
/// contributes when `d_k = U_x − a_k > 0`, and the derivatives follow from
/// `U_x` itself: `∂U_x/∂a_k = c_k d_k / S`, `∂U_x/∂W_x = W_x / S`,
/// `S = Σ c_k d_k` (the module documentation). `U_x` must be the root of
/// that quadratic, `Σ c_k d_k² = W_x²`, to the rebuild's tolerance (a first
/// order change of `U_x` moves the residual by `2 S`); any other cell (a
/// fallback step of the solver, or an output that is not this problem's)
/// goes through [`Replay::row`], which handles or refuses it. The same
/// derivatives as [`adjoint_step`] up to round-off (`U_x` in place of the
/// rebuilt root); about twice as fast on 1024².
fn first_order_step(
    march: &Replay<'_>,
    x: usize,
    acc: &mut [[f64; 2]],
) -> Result<(), EikonalError> {
    let Some(lam) = ordinary_cell(march, x, acc)? else {
        return Ok(());
    };
    let st = &march.st;
    let u = &march.u;
    let ux = u[x];
    let idx = st.unravel(x);
    let mut reads = [(usize::MAX, 0.0f64); 3];
    let (mut s, mut r) = (0.0, 0.0);
    for (slot, &k) in st.axes().iter().enumerate() {
        let step = st.strides[k];
        let lo = if idx[k] > 0 {
            u[x - step]
        } else {
            f64::INFINITY
        };
        let hi = if idx[k] + 1 < st.shape[k] {
            u[x + step]
        } else {
            f64::INFINITY
        };
        let lower = lo <= hi;
        let d = ux - if lower { lo } else { hi };
        // `d > 0` only for a finite upwind value, so that side exists.
        if d > 0.0 {
            let h = st.h[k];
            let cd = d / (h * h);
            s += cd;
            r += cd * d;
            reads[slot] = (if lower { x - step } else { x + step }, cd);
        }
    }
    let w = march.problem.cost.at(x);
    let residual = r - w * w;
    if !(s > 0.0 && s.is_finite() && residual.abs() <= 2e-9 * s * ux.abs().max(1.0)) {
        return adjoint_step(march, x, acc);
    }
    let scale = lam / s;
    acc[x][1] += scale * w;
    for &(j, cd) in &reads {
        if j != usize::MAX {
            acc[j][0] += scale * cd;
        }
    }
    Ok(())
}

/// [`adjoint_step`] for order 2 with one label: the row gathered without
/// the label logic, in fixed slots, then the very update of [`local_update`]
/// (the same bits as [`Replay::row`]); anything it does not cover goes
/// through [`adjoint_step`].
///
/// The known cells are read from the ranks as in [`Replay::row`]: an axis
/// neighbour is known when it froze before `x` (`0 <= r_j < r_x`), a second
/// neighbour when it froze no later than the last of those.
fn second_order_step(
    march: &Replay<'_>,
    x: usize,
    acc: &mut [[f64; 2]],
) -> Result<(), EikonalError> {
    let Some(ranks) = march.ranks.as_deref() else {
        return adjoint_step(march, x, acc);
    };
    let Some(lam) = ordinary_cell(march, x, acc)? else {
        return Ok(());
    };
    let st = &march.st;
    let u = &march.u;
    let ux = u[x];
    let rx = ranks[x];
    let idx = st.unravel(x);
    let axes = st.axes();
    // Per axis slot: the lower and upper neighbours and their ranks
    // (`-1`: outside the grid or never frozen).
    let mut nb = [[(usize::MAX, -1i64); 2]; 3];
    let mut last = -1i64;
    for (slot, &k) in axes.iter().enumerate() {
        let step = st.strides[k];
        if idx[k] > 0 {
            nb[slot][0] = (x - step, ranks[x - step]);
        }
        if idx[k] + 1 < st.shape[k] {
            nb[slot][1] = (x + step, ranks[x + step]);
        }
        for &(_, r) in &nb[slot] {
            if r >= 0 && r < rx {
                last = last.max(r);
            }
        }
    }
    let mut ax = [Axis::default(); 3];
    let mut na = 0;
    for (slot, &k) in axes.iter().enumerate() {
        let step = st.strides[k];
        let [(lo, rlo), (hi, rhi)] = nb[slot];
        let mut a1 = f64::INFINITY;
        let mut j1 = usize::MAX;
        let mut lower = false;
        if rlo >= 0 && rlo < rx {
            a1 = u[lo];
            j1 = lo;
            lower = true;
        }
        if rhi >= 0 && rhi < rx && u[hi] < a1 {
            a1 = u[hi];
            j1 = hi;
            lower = false;
        }
        if j1 == usize::MAX {
            continue;
        }
        let j2 = if lower {
            (idx[k] >= 2).then(|| j1 - step)
        } else {
            (idx[k] + 2 < st.shape[k]).then(|| j1 + step)
        };
        let a2 = j2.and_then(|j2| {
            let r2 = ranks[j2];
            (r2 >= 0 && r2 <= last && u[j2] < a1).then(|| (u[j2], j2))
        });
        ax[na] = Axis { k, a1, j1, a2 };
        na += 1;
    }
    if na == 0 {
        return Ok(());
    }
    let w = march.problem.cost.at(x);
    let row = match local_update(st, &ax[..na], w, true, |j| march.problem.cost.at(j)) {
        Some((v, row)) if (v - ux).abs() <= 1e-9 * ux.abs().max(1.0) => row,
        _ => return adjoint_step(march, x, acc),
    };
    apply_row(acc, x, lam, &row);
    Ok(())
}

/// The gradient of `U` at one probe with respect to the cost of every cell:
/// [`cost_gradient`] with the one weight `1`. For a point `y`, this is also
/// the gradient of the length `∫ W ds` of the minimal path from `y` to the
/// sources, which equals `U(y)`.
pub fn distance_gradient(
    problem: &EikonalProblem<'_>,
    options: &EikonalOptions,
    output: &EikonalOutput,
    probe: Probe,
    control: &Control<'_>,
) -> Result<ArrayD<f64>, EikonalError> {
    cost_gradient(problem, options, output, &[(probe, 1.0)], control)
}

/// The value `U(y_m)` the objective of [`cost_gradient`] reads at each
/// probe: the cell's value, or the multilinear interpolation of the `2^d`
/// cells around a point. Refused like the probes of [`cost_gradient`]
/// (outside the grid, a corner not reached), with the probe's index in
/// `weights[m]` of the reason. Works for any solve on `grid` (the
/// anisotropic one's [`EikonalOutput`] too).
pub fn probe_values(
    grid: &Grid,
    output: &EikonalOutput,
    probes: &[Probe],
) -> Result<Vec<f64>, EikonalError> {
    let u = flat(&output.distance);
    probes
        .iter()
        .enumerate()
        .map(|(m, probe)| {
            let corners =
                probe_weights(grid, &u, &[(probe.clone(), 1.0)]).map_err(|e| match e {
                    EikonalError::Option { field, reason } => EikonalError::Option {
                        field,
                        reason: reason.replacen("weights[0]", &format!("weights[{m}]"), 1),
                    },
                    other => other,
                })?;
            Ok(corners.iter().map(|&(i, w)| w * u[i]).sum())
        })
        .collect()
}

/// Refuses the options whose scheme is not the one differentiated here.
fn check_options(options: &EikonalOptions, output: &EikonalOutput) -> Result<(), EikonalError> {
    let refuse = |field: &'static str, what: &str| {
        Err(EikonalError::Option {
            field,
            reason: format!(
                "the cost gradient differentiates fast marching of order 1 or 2 without \
                 source factoring only (order 2 with the freezing order recorded); {what}"
            ),
        })
    };
    if options.method != Method::FastMarching {
        return refuse("method", &format!("got {:?}", options.method));
    }
    if options.factoring {
        return refuse("factoring", "got factoring on");
    }
    if options.order == Order::Second && output.frozen_order.is_none() {
        return refuse(
            "record_order",
            "order 2 needs the solve's freezing order: solve with record_order",
        );
    }
    Ok(())
}

/// The most upwind cells one update reads: two per axis.
const MAX_READS: usize = 6;

/// The derivatives of one cell's update `U_x = G(U_upwind, W)`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Row {
    /// `∂U_x/∂W_x`.
    dw: f64,
    /// `(j, ∂U_x/∂U_j)` for the upwind cells read.
    du: [(usize, f64); MAX_READS],
    n: usize,
    /// `(j, ∂U_x/∂W_j)` when the step cap binds on a neighbour's larger cost.
    dw_neighbour: Option<(usize, f64)>,
    /// Which branch of the update gave the value (for the tests' structure).
    #[cfg_attr(not(test), allow(dead_code))]
    branch: Branch,
}

impl Row {
    fn du(&self) -> &[(usize, f64)] {
        &self.du[..self.n]
    }
}

/// The branch of the local update that gave a cell's value.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Branch {
    /// The second-order quadratic.
    Second,
    /// The step cap `a_k + h_k max(W_x, W_j)` along one axis.
    Cap,
    /// The first-order quadratic.
    First,
    /// The one-axis step of the overflow fallback.
    Step,
}

/// One axis' upwind data at a cell's last update (the default: an
/// unfilled slot).
#[derive(Debug, Clone, Copy, Default)]
struct Axis {
    k: usize,
    a1: f64,
    j1: usize,
    /// The second neighbour `(value, index)` when the second-order
    /// difference applies (known and `< a1`).
    a2: Option<(f64, usize)>,
}

/// One term `c2 ((U − b)⁺)²` of the quadratic, with `b = Σ coef · U_cell`.
#[derive(Debug, Clone, Copy)]
struct Term {
    b: f64,
    c2: f64,
    a1: f64,
    /// `(cell, ∂b/∂U_cell)`: one or two.
    reads: [(usize, f64); 2],
    nreads: usize,
}

/// The solve replayed: the final values, the labels, the freezing ranks
/// and the seeds, from which the update of every cell is rebuilt.
struct Replay<'a> {
    problem: &'a EikonalProblem<'a>,
    st: Stencil,
    second: bool,
    /// Several sources (labels may differ between neighbours).
    multi: bool,
    u: Cow<'a, [f64]>,
    labels: Cow<'a, [i32]>,
    ranks: Option<Cow<'a, [i64]>>,
    /// The seed cells, in increasing index.
    seed_cells: Vec<usize>,
    /// Per cell the index in `seeds` of its seed, or `u32::MAX`, when
    /// there are many seeds (a mask); otherwise a binary search of
    /// `seed_cells` (a point source's few seeds stay in the cache).
    seed_of: Option<Vec<u32>>,
    /// Per seed: `Some((q, |x − p|_h))` for a point source's seed (`q` the
    /// cell whose cost it uses), `None` for a cell source's.
    seeds: Vec<Option<(usize, f64)>>,
}

impl<'a> Replay<'a> {
    fn new(
        problem: &'a EikonalProblem<'a>,
        options: &EikonalOptions,
        output: &'a EikonalOutput,
        control: &Control<'_>,
    ) -> Result<Self, EikonalError> {
        check_options(options, output)?;
        let grid = &problem.grid;
        let n = grid.len();
        let shapes_agree = output.distance.shape() == grid.shape()
            && output.labels.shape() == grid.shape()
            && output
                .frozen_order
                .as_ref()
                .is_none_or(|o| o.shape() == grid.shape());
        if !shapes_agree {
            return Err(EikonalError::Option {
                field: "output",
                reason: format!(
                    "the solve's output has shape {:?}, the grid {:?}",
                    output.distance.shape(),
                    grid.shape()
                ),
            });
        }
        // The seeds, as the solve made them.
        let front = InitialFront::build(problem, options.source_radius, control)?;
        let mut seed_of = (front.cells.len() * 16 > n).then(|| vec![u32::MAX; n]);
        let mut seeds = Vec::with_capacity(front.cells.len());
        let mut seed_cells = Vec::with_capacity(front.cells.len());
        for (s, c) in front.cells.iter().enumerate() {
            if let Some(of) = seed_of.as_mut() {
                of[c.index] = s as u32;
            }
            seed_cells.push(c.index);
            let point = usize::try_from(c.label)
                .ok()
                .and_then(|l| problem.sources.get(l))
                .is_some_and(|s| matches!(s, Source::Point(_)));
            let sp = front.points.iter().find(|p| p.label == c.label);
            seeds.push(match sp {
                Some(sp) if point => {
                    let q = grid.linear(nearest_cell(grid, sp.position));
                    let x = grid.unravel(c.index).map(|v| v as f64);
                    Some((q, grid.physical_distance3(x, sp.position)))
                }
                _ => None,
            });
        }
        Ok(Self {
            problem,
            st: Stencil::new(grid),
            second: options.order == Order::Second,
            multi: problem.sources.len() > 1,
            u: flat(&output.distance),
            labels: flat(&output.labels),
            ranks: output.frozen_order.as_ref().map(flat),
            seed_cells,
            seed_of,
            seeds,
        })
    }

    /// Reads what the update of cell `x` and its adjoint step read (the
    /// cost and `λ` of `x`, `U` and `λ` of its axis neighbours, their
    /// freezing ranks at order 2 and the second neighbours' `U`, `λ` and
    /// ranks), to bring
    /// it into the cache ahead of the step; the sum means nothing.
    fn warm(&self, x: usize, acc: &[[f64; 2]]) -> f64 {
        let mut s = self.problem.cost.at(x) + acc[x][0];
        let ranks = self.ranks.as_deref().filter(|_| self.second);
        for &k in self.st.axes() {
            let step = self.st.strides[k];
            for j in [x.wrapping_sub(step), x.wrapping_add(step)] {
                s += self.u.get(j).copied().unwrap_or(0.0);
                s += acc.get(j).map_or(0.0, |a| a[0]);
                if let Some(r) = ranks {
                    s += r.get(j).copied().unwrap_or(0) as f64;
                }
            }
            if self.second {
                for j in [x.wrapping_sub(2 * step), x.wrapping_add(2 * step)] {
                    s += self.u.get(j).copied().unwrap_or(0.0);
                    s += acc.get(j).map_or(0.0, |a| a[0]);
                    if let Some(r) = ranks {
                        s += r.get(j).copied().unwrap_or(0) as f64;
                    }
                }
            }
        }
        s
    }

    /// Order 1 with one label: the case of [`first_order_step`].
    fn plain_first_order(&self) -> bool {
        !self.second && !self.multi
    }

    /// Order 2 with one label: the case of [`second_order_step`].
    fn plain_second_order(&self) -> bool {
        self.second && !self.multi
    }

    /// `Some(seed)` if cell `x` is a seed (see [`Replay::seeds`]).
    fn seed(&self, x: usize) -> Option<Option<(usize, f64)>> {
        let s = match &self.seed_of {
            Some(of) => Some(of[x] as usize).filter(|&s| s != u32::MAX as usize),
            None => self.seed_cells.binary_search(&x).ok(),
        }?;
        Some(self.seeds.get(s).copied().flatten())
    }

    /// The derivatives of the update of reached non-seed cell `x`, rebuilt
    /// from the cells known at its last update; `None` if it read nothing.
    /// An error if the rebuilt value is not the solve's: the output does not
    /// come from this problem and these options.
    fn row(&self, x: usize) -> Result<Option<Row>, EikonalError> {
        let st = &self.st;
        let (u, labels) = (&self.u, &self.labels);
        let idx = st.unravel(x);
        let ux = u[x];
        // Known at the last update: with the ranks, the cells frozen no
        // later than the last neighbour frozen before `x`; without them
        // (order 1, which freezes in non-decreasing `U`), the neighbours
        // of smaller `U` (a neighbour of equal `U` has a zero term).
        // The axis neighbours, lower side first (`usize::MAX`: none).
        let axes = st.axes();
        let mut nbs = [usize::MAX; MAX_READS];
        for (slot, &k) in axes.iter().enumerate() {
            let s = st.strides[k];
            if idx[k] > 0 {
                nbs[2 * slot] = x - s;
            }
            if idx[k] + 1 < st.shape[k] {
                nbs[2 * slot + 1] = x + s;
            }
        }
        let nbs = &nbs[..2 * axes.len()];
        // Order 1 freezes in non-decreasing `U`, so "smaller `U`" is exact
        // there even when the ranks were recorded (the two sets differ only
        // by neighbours of equal `U`, whose terms are zero), and it spares
        // the rank reads, cache misses in front order.
        let ranks = self.ranks.as_ref().filter(|_| self.second);
        let last = ranks.map(|r| {
            let rx = r[x];
            nbs.iter()
                .filter(|&&j| j != usize::MAX && r[j] >= 0 && r[j] < rx)
                .map(|&j| r[j])
                .fold(-1i64, i64::max)
        });
        let frozen = |j: usize| match (ranks, last) {
            (Some(r), Some(t)) => r[j] >= 0 && r[j] <= t,
            _ => u[j] < ux,
        };
        // Several labels among the known neighbours: the update of the
        // cell's own label won (see the module documentation).
        let mut mixed = false;
        if self.multi {
            let mut first_label = None;
            for &j in nbs {
                if j != usize::MAX && frozen(j) {
                    match first_label {
                        None => first_label = Some(labels[j]),
                        Some(l) if l != labels[j] => mixed = true,
                        _ => {}
                    }
                }
            }
        }
        // Read only when needed: one array less in the cache otherwise.
        let lx = if mixed { labels[x] } else { 0 };
        let known = |j: usize| frozen(j) && (!mixed || labels[j] == lx);

        let mut ax = [Axis::default(); 3];
        let mut na = 0;
        for &k in st.axes() {
            let s = st.strides[k];
            let mut a1 = f64::INFINITY;
            let mut j1 = usize::MAX;
            let mut lower = false;
            // The lower side first, the upper one only if strictly smaller
            // (as the solver's update).
            if idx[k] > 0 && known(x - s) {
                a1 = u[x - s];
                j1 = x - s;
                lower = true;
            }
            if idx[k] + 1 < st.shape[k] && known(x + s) && u[x + s] < a1 {
                a1 = u[x + s];
                j1 = x + s;
                lower = false;
            }
            if j1 == usize::MAX {
                continue;
            }
            let mut a2 = None;
            if self.second {
                let j2 = if lower {
                    (idx[k] >= 2).then(|| j1 - s)
                } else {
                    (idx[k] + 2 < st.shape[k]).then(|| j1 + s)
                };
                if let Some(j2) = j2 {
                    if known(j2) && u[j2] < a1 {
                        a2 = Some((u[j2], j2));
                    }
                }
            }
            ax[na] = Axis { k, a1, j1, a2 };
            na += 1;
        }
        if na == 0 {
            return Ok(None);
        }
        let w = self.problem.cost.at(x);
        let row = local_update(st, &ax[..na], w, self.second, |j| self.problem.cost.at(j));
        match row {
            Some((v, row)) if (v - ux).abs() <= 1e-9 * ux.abs().max(1.0) => Ok(Some(row)),
            other => Err(EikonalError::Option {
                field: "output",
                reason: format!(
                    "the output does not come from this problem and these options: at cell \
                     {:?} the scheme gives {:?}, the output {ux}",
                    crate::numerics::metric::unravel_user(&self.problem.grid, x),
                    other.map(|r| r.0)
                ),
            }),
        }
    }
}

/// The values of an array in C order (as the solvers' working arrays),
/// borrowed when it is laid out so.
fn flat<T: Clone>(a: &ArrayD<T>) -> Cow<'_, [T]> {
    match a.as_slice() {
        Some(s) => Cow::Borrowed(s),
        None => Cow::Owned(a.iter().cloned().collect()),
    }
}

/// The unfactored upwind update of one cell (cost `w`, upwind axes `ax`)
/// as [`super::update`] computes it, with its derivatives: the second-order
/// quadratic when an axis has its second neighbour and the root is at
/// least every active term's `a1`, capped by the straight steps
/// `a_k + h_k max(W_x, W_j)`; otherwise the first-order quadratic; the
/// one-axis step when neither has a finite root.
///
/// For the quadratic `Σ_t c_t ((U − b_t)⁺)² = W²` with `d_t = U − b_t`
/// and `S = Σ_t c_t d_t` over the active terms: `∂U/∂b_t = c_t d_t / S`
/// and `∂U/∂W = W / S`; `b_t = a1` (first order) or `(4 a1 − a2) / 3`
/// (second order, so `∂b/∂a1 = 4/3`, `∂b/∂a2 = −1/3`).
fn local_update(
    st: &Stencil,
    ax: &[Axis],
    w: f64,
    second: bool,
    cost_at: impl Fn(usize) -> f64,
) -> Option<(f64, Row)> {
    let w2 = w * w;
    let mut t = [Term {
        b: 0.0,
        c2: 0.0,
        a1: 0.0,
        reads: [(0, 0.0); 2],
        nreads: 0,
    }; 3];
    let n = ax.len();
    let first_term = |a: &Axis| {
        let h = st.h[a.k];
        Term {
            b: a.a1,
            c2: 1.0 / (h * h),
            a1: a.a1,
            reads: [(a.j1, 1.0), (0, 0.0)],
            nreads: 1,
        }
    };
    if second && ax.iter().any(|a| a.a2.is_some()) {
        for (t, a) in t.iter_mut().zip(ax) {
            *t = match a.a2 {
                Some((a2, j2)) => {
                    let h = st.h[a.k];
                    Term {
                        b: (4.0 * a.a1 - a2) / 3.0,
                        c2: 2.25 / (h * h),
                        a1: a.a1,
                        reads: [(a.j1, 4.0 / 3.0), (j2, -1.0 / 3.0)],
                        nreads: 2,
                    }
                }
                None => first_term(a),
            };
        }
        if let Some((v, m)) = solve_terms(&mut t[..n], w2) {
            if v.is_finite() && t[..m].iter().all(|t| v >= t.a1) {
                // The cap, axis by axis as the solver: the last bound that
                // lowers the value wins.
                let mut best = v;
                let mut binding = None;
                for a in ax {
                    let h = st.h[a.k];
                    if a.a1 + w * h < best {
                        let wj = cost_at(a.j1);
                        let bound = a.a1 + h * w.max(wj);
                        if bound < best {
                            best = bound;
                            binding = Some((a, h, wj));
                        }
                    }
                }
                let row = match binding {
                    Some((a, h, wj)) => {
                        let mut du = [(0, 0.0); MAX_READS];
                        du[0] = (a.j1, 1.0);
                        let (dw, dw_neighbour) = if w >= wj {
                            (h, None)
                        } else {
                            (0.0, Some((a.j1, h)))
                        };
                        Row {
                            dw,
                            du,
                            n: 1,
                            dw_neighbour,
                            branch: Branch::Cap,
                        }
                    }
                    None => quadratic_row(&t[..m], v, w, Branch::Second),
                };
                return Some((best, row));
            }
        }
    }
    for (t, a) in t.iter_mut().zip(ax) {
        *t = first_term(a);
    }
    if let Some((v, m)) = solve_terms(&mut t[..n], w2) {
        if v.is_finite() && v >= t[0].a1 {
            return Some((v, quadratic_row(&t[..m], v, w, Branch::First)));
        }
    }
    // Only reached through overflow or rounding: the one-axis update.
    let (v, j, h) = ax
        .iter()
        .map(|a| (a.a1 + w * st.h[a.k], a.j1, st.h[a.k]))
        .min_by(|x, y| x.0.total_cmp(&y.0))?;
    let mut du = [(0, 0.0); MAX_READS];
    du[0] = (j, 1.0);
    v.is_finite().then_some((
        v,
        Row {
            dw: h,
            du,
            n: 1,
            dw_neighbour: None,
            branch: Branch::Step,
        },
    ))
}

/// The derivatives of the root `v` of the active terms `t` (see [`local_update`]).
fn quadratic_row(t: &[Term], v: f64, w: f64, branch: Branch) -> Row {
    let s: f64 = t.iter().map(|t| t.c2 * (v - t.b)).sum();
    let mut du = [(0, 0.0); MAX_READS];
    let mut n = 0;
    let inv = if s > 0.0 && s.is_finite() {
        1.0 / s
    } else {
        0.0
    };
    for t in t {
        let db = t.c2 * (v - t.b) * inv;
        for &(j, coef) in &t.reads[..t.nreads] {
            du[n] = (j, db * coef);
            n += 1;
        }
    }
    Row {
        dw: w * inv,
        du,
        n,
        dw_neighbour: None,
        branch,
    }
}

/// The root of `Σ_t c2_t ((U − b_t)⁺)² = rhs`, adding the terms in
/// increasing `b` while the root lies above the next `b` (the same
/// arithmetic as the solver's): the root and the number of active terms
/// (the first ones of `t`, which is left sorted).
fn solve_terms(t: &mut [Term], rhs: f64) -> Option<(f64, usize)> {
    for a in 1..t.len() {
        let mut b = a;
        while b > 0 && t[b].b < t[b - 1].b {
            t.swap(b, b - 1);
            b -= 1;
        }
    }
    let b0 = t.first()?.b;
    let (mut sa, mut sb, mut sc) = (0.0, 0.0, 0.0);
    for m in 0..t.len() {
        let c2 = t[m].c2;
        let d = t[m].b - b0;
        sa += c2;
        sb += c2 * d;
        sc += c2 * d * d;
        let disc = sb * sb - sa * (sc - rhs);
        if disc.is_nan() || disc < 0.0 {
            return None;
        }
        let v = (sb + disc.sqrt()) / sa;
        if m + 1 == t.len() || v <= t[m + 1].b - b0 {
            return Some((b0 + v, m + 1));
        }
    }
    None
}

/// The weights of the probes on cells: `(cell, w_m × corner weight)`
/// (also the anisotropic adjoint's, [`crate::numerics::anisotropic::metric_gradient`]).
pub(crate) fn probe_weights(
    grid: &Grid,
    u: &[f64],
    weights: &[(Probe, f64)],
) -> Result<Vec<(usize, f64)>, EikonalError> {
    let mut out = Vec::with_capacity(weights.len());
    for (index, (probe, weight)) in weights.iter().enumerate() {
        let err = |reason: String| EikonalError::Option {
            field: "weights",
            reason: format!("weights[{index}]: {reason}"),
        };
        if !weight.is_finite() {
            return Err(err(format!("the weight {weight} is not finite")));
        }
        let mut corners: Vec<(usize, f64)> = Vec::with_capacity(8);
        match probe {
            Probe::Cell(c) => {
                let c3 = grid.index3(c).map_err(|e| err(e.to_string()))?;
                if !grid.contains_index3(c3) {
                    return Err(err(format!(
                        "cell {c:?} is outside the grid of shape {:?}",
                        grid.shape()
                    )));
                }
                corners.push((grid.linear(c3), 1.0));
            }
            Probe::Point(p) => {
                let p3 = grid.point3(p).map_err(|e| err(e.to_string()))?;
                if !(p3.iter().all(|x| x.is_finite()) && grid.contains_point3(p3)) {
                    return Err(err(format!(
                        "point {p:?} is outside the grid of shape {:?}",
                        grid.shape()
                    )));
                }
                corners = point_corners(grid, p3);
            }
        }
        for &(i, _) in &corners {
            if !u[i].is_finite() {
                return Err(err(format!(
                    "the distance is not finite at cell {:?} (a wall, unreached, or past a stop rule)",
                    crate::numerics::metric::unravel_user(grid, i)
                )));
            }
        }
        out.extend(corners.into_iter().map(|(i, wc)| (i, weight * wc)));
    }
    Ok(out)
}

/// The cells around the padded point `p3` (inside the grid) and their
/// multilinear weights, those `> 0`: `U(p) = Σ w_c U_c` is the value a
/// [`Probe::Point`] reads (an index past the last cell is clamped to it).
pub(crate) fn point_corners(grid: &Grid, p3: [f64; 3]) -> Vec<(usize, f64)> {
    let shape = grid.shape3();
    let lo = p3.map(|x| x.floor().max(0.0) as usize);
    let mut out = Vec::with_capacity(8);
    for corner in 0..8usize {
        let mut idx = [0usize; 3];
        let mut wc = 1.0;
        for k in 0..3 {
            let up = corner >> k & 1 == 1;
            let t = p3[k] - lo[k] as f64;
            idx[k] = if up {
                (lo[k] + 1).min(shape[k] - 1)
            } else {
                lo[k].min(shape[k] - 1)
            };
            wc *= if up { t } else { 1.0 - t };
        }
        if wc > 0.0 {
            out.push((grid.linear(idx), wc));
        }
    }
    out
}

/// The options of the forward solve that [`cost_gradient`] differentiates:
/// fast marching of `order` without source factoring, recording the
/// freezing order (order 2 needs it; at order 1 it spares the adjoint a sort).
pub fn adjoint_options(order: Order) -> EikonalOptions {
    let mut options = EikonalOptions::DEFAULT
        .with_method(Method::FastMarching)
        .with_order(order)
        .with_factoring(false);
    options.record_order = true;
    options
}

/// The reached cells in decreasing `U` (decreasing freezing rank when the
/// solve recorded it; otherwise sorted by `U`, ties by decreasing index):
/// every cell comes before the upwind neighbours its value was computed from.
pub(crate) fn backward_order(u: &[f64], output: &EikonalOutput) -> Vec<usize> {
    if let Some(ranks) = &output.frozen_order {
        // Straight into decreasing rank. A ranked cell was frozen, so its
        // `U` is finite: no read of `u` at random here.
        let total = output.frozen;
        let mut order = vec![usize::MAX; total];
        for (i, &r) in ranks.iter().enumerate() {
            if let Some(slot) = usize::try_from(r)
                .ok()
                .filter(|&r| r < total)
                .map(|r| total - 1 - r)
            {
                order[slot] = i;
            }
        }
        order.retain(|&i| i != usize::MAX);
        return order;
    }
    // Sort (key, index) pairs, the key ordering as `f64::total_cmp`: the
    // comparisons then read contiguous memory instead of `u` at random.
    let mut keyed: Vec<(u64, u32)> = (0..u.len())
        .filter(|&i| u[i].is_finite())
        .map(|i| {
            let b = u[i].to_bits();
            let key = if b >> 63 == 1 { !b } else { b | 1 << 63 };
            (key, i as u32)
        })
        .collect();
    keyed.sort_unstable();
    keyed.iter().rev().map(|&(_, i)| i as usize).collect()
}

#[cfg(test)]
mod tests {
    use std::sync::atomic::AtomicBool;

    use super::*;
    use crate::numerics::eikonal::{solve, StopRules};
    use crate::numerics::metric::{CostValues, Interpretation};
    use crate::numerics::{Grid, IsotropicCost};

    fn first_order() -> EikonalOptions {
        EikonalOptions::DEFAULT
            .with_order(Order::First)
            .with_factoring(false)
    }

    fn second_order() -> EikonalOptions {
        let mut o = EikonalOptions::DEFAULT.with_factoring(false);
        o.record_order = true;
        o
    }

    /// A smooth positive cost, `1 + 0.5 sin(.) cos(.)` (times a third factor in 3D).
    fn smooth_cost(shape: &[usize]) -> Vec<f64> {
        let grid = Grid::unit(shape).unwrap();
        (0..grid.len())
            .map(|i| {
                let [a, b, c] = grid.unravel(i).map(|x| x as f64);
                1.0 + 0.5 * (0.37 * b + 0.2 + 0.11 * a).sin() * (0.29 * c + 0.1 - 0.23 * a).cos()
            })
            .collect()
    }

    fn field_problem(grid: Grid, w: Vec<f64>, sources: Vec<Source>) -> EikonalProblem<'static> {
        let cost = IsotropicCost::new(
            &grid,
            CostValues::F64(Cow::Owned(w)),
            Interpretation::Cost,
            None,
        )
        .unwrap();
        EikonalProblem {
            grid,
            cost,
            sources,
        }
    }

    /// `J = Σ w_m U(y_m)` read from a solve, as the adjoint defines it.
    fn objective(problem: &EikonalProblem<'_>, u: &ArrayD<f64>, weights: &[(Probe, f64)]) -> f64 {
        let flat: Vec<f64> = u.iter().copied().collect();
        probe_weights(&problem.grid, &flat, weights)
            .unwrap()
            .iter()
            .map(|&(i, w)| w * flat[i])
            .sum()
    }

    /// Per cell the label, the branch of its update and the cells it reads:
    /// two solves with the same structure solve the same smooth equations.
    type Structure = Vec<(i32, Option<(Branch, Vec<usize>, Option<usize>)>)>;

    fn structure(
        problem: &EikonalProblem<'_>,
        opts: &EikonalOptions,
        out: &EikonalOutput,
    ) -> Structure {
        let replay = Replay::new(problem, opts, out, &Control::new()).unwrap();
        (0..problem.grid.len())
            .map(|x| {
                let row = if replay.u[x].is_finite() && replay.seed(x).is_none() {
                    replay.row(x).unwrap().map(|r| {
                        let mut cells: Vec<usize> = r.du().iter().map(|d| d.0).collect();
                        cells.sort_unstable();
                        (r.branch, cells, r.dw_neighbour.map(|d| d.0))
                    })
                } else {
                    None
                };
                (replay.labels[x], row)
            })
            .collect()
    }

    struct FdReport {
        max_rel: f64,
        checked: usize,
        skipped: usize,
        /// Cells by the branch of their update in the unperturbed solve:
        /// second order, cap, first order, one-axis step.
        branches: [usize; 4],
    }

    /// Compares the adjoint gradient with centred differences of the solver
    /// at every cell, `ε = 1e-6 W`, skipping the cells whose perturbation
    /// changes the upwind structure (a tie switched: not differentiable
    /// there). The relative difference is taken against
    /// `max(|g|, 1e-3 max |g|)`.
    fn finite_differences(
        opts: &EikonalOptions,
        grid: &Grid,
        w: &[f64],
        sources: &[Source],
        weights: &[(Probe, f64)],
    ) -> FdReport {
        let opts = opts.clone();
        let base = field_problem(grid.clone(), w.to_vec(), sources.to_vec());
        let out = solve(&base, &opts, &Control::new()).unwrap();
        let g = cost_gradient(&base, &opts, &out, weights, &Control::new()).unwrap();
        let g: Vec<f64> = g.iter().copied().collect();
        let gmax = g.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!(gmax > 0.1, "a gradient of {gmax}");
        let s0 = structure(&base, &opts, &out);
        let mut branches = [0usize; 4];
        for (_, row) in &s0 {
            if let Some((b, _, _)) = row {
                branches[match b {
                    Branch::Second => 0,
                    Branch::Cap => 1,
                    Branch::First => 2,
                    Branch::Step => 3,
                }] += 1;
            }
        }
        let mut report = FdReport {
            max_rel: 0.0,
            checked: 0,
            skipped: 0,
            branches,
        };
        for c in 0..w.len() {
            let eps = 1e-6 * w[c];
            let mut j = [0.0; 2];
            let mut same = true;
            for (slot, sign) in [1.0, -1.0].into_iter().enumerate() {
                let mut wp = w.to_vec();
                wp[c] += sign * eps;
                let p = field_problem(grid.clone(), wp, sources.to_vec());
                let o = solve(&p, &opts, &Control::new()).unwrap();
                same &= structure(&p, &opts, &o) == s0;
                j[slot] = objective(&p, &o.distance, weights);
            }
            if !same {
                report.skipped += 1;
                continue;
            }
            let fd = (j[0] - j[1]) / (2.0 * eps);
            let rel = (fd - g[c]).abs() / g[c].abs().max(1e-3 * gmax);
            report.max_rel = report.max_rel.max(rel);
            report.checked += 1;
        }
        report
    }

    #[test]
    fn matches_finite_differences_of_the_solver_in_2d() {
        let shape = [24, 24];
        let grid = Grid::new(&shape, &[1.0, 1.0]).unwrap();
        let weights = [
            (Probe::Cell(vec![20, 3]), 1.0),
            (Probe::Cell(vec![22, 22]), 0.7),
            (Probe::Cell(vec![3, 20]), -0.4),
            (Probe::Cell(vec![12, 12]), 1.3),
            (Probe::Point(vec![17.4, 9.7]), 0.5),
        ];
        let r = finite_differences(
            &first_order(),
            &grid,
            &smooth_cost(&shape),
            &[Source::Point(vec![5.3, 7.6])],
            &weights,
        );
        eprintln!(
            "2D: max relative difference {:.3e} over {} cells ({} skipped)",
            r.max_rel, r.checked, r.skipped
        );
        assert!(r.max_rel <= 1e-4, "max relative difference {}", r.max_rel);
        assert!(r.skipped * 20 <= r.checked, "{} skipped", r.skipped);
    }

    #[test]
    fn matches_finite_differences_with_anisotropic_spacing() {
        let shape = [20, 16];
        let grid = Grid::new(&shape, &[0.7, 1.3]).unwrap();
        let weights = [
            (Probe::Cell(vec![19, 15]), 1.0),
            (Probe::Cell(vec![0, 12]), 0.6),
        ];
        let r = finite_differences(
            &first_order(),
            &grid,
            &smooth_cost(&shape),
            &[Source::Point(vec![6.0, 4.0])],
            &weights,
        );
        eprintln!(
            "2D spacing (0.7, 1.3): max relative difference {:.3e} over {} cells ({} skipped)",
            r.max_rel, r.checked, r.skipped
        );
        assert!(r.max_rel <= 1e-4, "max relative difference {}", r.max_rel);
        assert!(r.skipped * 20 <= r.checked, "{} skipped", r.skipped);
    }

    #[test]
    fn matches_finite_differences_of_the_solver_in_3d() {
        let shape = [10, 10, 10];
        let grid = Grid::unit(&shape).unwrap();
        let weights = [
            (Probe::Cell(vec![9, 9, 9]), 1.0),
            (Probe::Cell(vec![0, 8, 2]), 0.8),
            (Probe::Point(vec![7.5, 1.2, 4.4]), 0.5),
        ];
        let r = finite_differences(
            &first_order(),
            &grid,
            &smooth_cost(&shape),
            &[Source::Point(vec![3.2, 4.7, 2.4])],
            &weights,
        );
        eprintln!(
            "3D: max relative difference {:.3e} over {} cells ({} skipped)",
            r.max_rel, r.checked, r.skipped
        );
        assert!(r.max_rel <= 1e-4, "max relative difference {}", r.max_rel);
        assert!(r.skipped * 20 <= r.checked, "{} skipped", r.skipped);
    }

    #[test]
    fn order_two_matches_finite_differences_in_2d_and_3d() {
        let shape = [24, 24];
        let grid = Grid::unit(&shape).unwrap();
        let weights = [
            (Probe::Cell(vec![20, 3]), 1.0),
            (Probe::Cell(vec![22, 22]), 0.7),
            (Probe::Cell(vec![3, 20]), -0.4),
            (Probe::Point(vec![17.4, 9.7]), 0.5),
        ];
        let r = finite_differences(
            &second_order(),
            &grid,
            &smooth_cost(&shape),
            &[Source::Point(vec![5.3, 7.6])],
            &weights,
        );
        eprintln!(
            "order 2, 2D: max relative difference {:.3e} over {} cells ({} skipped), branches {:?}",
            r.max_rel, r.checked, r.skipped, r.branches
        );
        // Most cells use the second-order stencil.
        assert!(r.branches[0] * 2 > r.checked, "{:?}", r.branches);
        assert!(r.max_rel <= 1e-4, "max relative difference {}", r.max_rel);
        assert!(r.skipped * 10 <= r.checked, "{} skipped", r.skipped);

        let shape = [10, 10, 10];
        let weights = [
            (Probe::Cell(vec![9, 9, 9]), 1.0),
            (Probe::Point(vec![7.5, 1.2, 4.4]), 0.5),
        ];
        let r = finite_differences(
            &second_order(),
            &Grid::unit(&shape).unwrap(),
            &smooth_cost(&shape),
            &[Source::Point(vec![3.2, 4.7, 2.4])],
            &weights,
        );
        eprintln!(
            "order 2, 3D: max relative difference {:.3e} over {} cells ({} skipped), branches {:?}",
            r.max_rel, r.checked, r.skipped, r.branches
        );
        assert!(r.branches[0] * 2 > r.checked, "{:?}", r.branches);
        assert!(r.max_rel <= 1e-4, "max relative difference {}", r.max_rel);
        assert!(r.skipped * 10 <= r.checked, "{} skipped", r.skipped);
    }

    /// A rough cost in `[0.3, 3]` (a hash of the cell), where the
    /// second-order values overshoot and the step cap binds.
    fn rough_cost(shape: &[usize]) -> Vec<f64> {
        let n: usize = shape.iter().product();
        (0..n)
            .map(|i| {
                let mut z = (i as u64 + 1).wrapping_mul(0x9e37_79b9_7f4a_7c15);
                z ^= z >> 29;
                z = z.wrapping_mul(0xbf58_476d_1ce4_e5b9);
                z ^= z >> 32;
                0.3 + 2.7 * (z % 10_000) as f64 / 10_000.0
            })
            .collect()
    }

    /// The specialised steps give the general step's gradient: the same
    /// bits at order 2 (the same update), round-off at order 1 (`U_x` in
    /// place of the rebuilt root), on a rough cost with walls, a point
    /// source between cells and anisotropic spacing, in 2D and 3D.
    #[test]
    fn the_specialised_steps_agree_with_the_general_one() {
        for (shape, spacing) in [
            (vec![37usize, 41], vec![1.0, 0.7]),
            (vec![13, 11, 9], vec![1.0, 1.3, 0.8]),
        ] {
            let grid = Grid::new(&shape, &spacing).unwrap();
            let mut w = rough_cost(&shape);
            for (i, v) in w.iter_mut().enumerate() {
                if i % 7 == 3 && i % 5 == 1 {
                    *v = f64::INFINITY;
                }
            }
            let source = shape.iter().map(|&n| n as f64 / 2.0 - 0.3).collect();
            let problem = field_problem(grid.clone(), w, vec![Source::Point(source)]);
            for order in [Order::First, Order::Second] {
                let opts = adjoint_options(order);
                let out = solve(&problem, &opts, &Control::new()).unwrap();
                let u = flat(&out.distance);
                let probes: Vec<(usize, f64)> = (0..u.len())
                    .filter(|&i| u[i].is_finite())
                    .step_by(3)
                    .map(|i| (i, 1.0 + (i % 4) as f64))
                    .collect();
                let march = Replay::new(&problem, &opts, &out, &Control::new()).unwrap();
                let sweep = |steps| {
                    front_order_sweep(&march, &out, &probes, steps, &Control::new()).unwrap()
                };
                let (fast, general) = (sweep(Steps::Specialised), sweep(Steps::General));
                let scale = general.iter().fold(0.0f64, |m, g| m.max(g.abs()));
                assert!(scale > 1.0, "{shape:?} {order:?}: a gradient of {scale}");
                let worst = fast
                    .iter()
                    .zip(&general)
                    .map(|(a, b)| (a - b).abs())
                    .fold(0.0f64, f64::max);
                match order {
                    Order::Second => assert_eq!(fast, general, "{shape:?}"),
                    _ => assert!(worst <= 1e-12 * scale, "{shape:?} {order:?}: {worst}"),
                }
            }
        }
    }

    #[test]
    fn order_two_matches_finite_differences_on_a_rough_cost() {
        let shape = [20, 20];
        let weights = [
            (Probe::Cell(vec![19, 19]), 1.0),
            (Probe::Cell(vec![0, 19]), 0.5),
            (Probe::Cell(vec![19, 2]), 0.5),
        ];
        let r = finite_differences(
            &second_order(),
            &Grid::unit(&shape).unwrap(),
            &rough_cost(&shape),
            &[Source::Point(vec![4.4, 6.1])],
            &weights,
        );
        eprintln!(
            "order 2, rough cost: max relative difference {:.3e} over {} cells ({} skipped), branches {:?}",
            r.max_rel, r.checked, r.skipped, r.branches
        );
        assert!(r.max_rel <= 1e-4, "max relative difference {}", r.max_rel);
        assert!(r.branches[1] > 0, "the cap never binds: {:?}", r.branches);
        assert!(r.skipped * 4 <= r.checked, "{} skipped", r.skipped);
    }

    #[test]
    fn matches_finite_differences_with_two_sources() {
        // Two point sources and a cell source: the Voronoi boundaries are
        // kinks, skipped when a perturbation moves them.
        let shape = [24, 24];
        let weights = [
            (Probe::Cell(vec![23, 0]), 1.0),
            (Probe::Cell(vec![12, 12]), 1.0),
            (Probe::Cell(vec![0, 23]), 1.0),
            (Probe::Cell(vec![23, 23]), 1.0),
        ];
        let sources = [
            Source::Point(vec![3.3, 4.2]),
            Source::Point(vec![18.6, 15.1]),
            Source::Cells {
                cells: vec![vec![2, 20], vec![3, 20]],
                values: Some(vec![1.0, 1.5]),
            },
        ];
        for opts in [first_order(), second_order()] {
            let r = finite_differences(
                &opts,
                &Grid::unit(&shape).unwrap(),
                &smooth_cost(&shape),
                &sources,
                &weights,
            );
            eprintln!(
                "three sources, {:?}: max relative difference {:.3e} over {} cells ({} skipped)",
                opts.order, r.max_rel, r.checked, r.skipped
            );
            assert!(r.max_rel <= 1e-4, "max relative difference {}", r.max_rel);
            assert!(r.skipped * 10 <= r.checked, "{} skipped", r.skipped);
        }
    }

    #[test]
    fn an_output_of_another_problem_is_refused() {
        let shape = [12, 12];
        let grid = Grid::unit(&shape).unwrap();
        let problem = field_problem(
            grid,
            smooth_cost(&shape),
            vec![Source::Point(vec![2.0, 3.0])],
        );
        let other = EikonalProblem {
            grid: Grid::unit(&shape).unwrap(),
            cost: IsotropicCost::constant(1.0).unwrap(),
            sources: vec![Source::Point(vec![2.0, 3.0])],
        };
        for opts in [first_order(), second_order()] {
            let out = solve(&other, &opts, &Control::new()).unwrap();
            let r = distance_gradient(
                &problem,
                &opts,
                &out,
                Probe::Cell(vec![11, 11]),
                &Control::new(),
            );
            assert!(
                matches!(
                    r,
                    Err(EikonalError::Option {
                        field: "output",
                        ..
                    })
                ),
                "{r:?}"
            );
        }
    }

    #[test]
    fn the_adjoint_of_a_sum_is_the_sum_of_the_adjoints() {
        let shape = [24, 24];
        let grid = Grid::unit(&shape).unwrap();
        let sources = vec![
            Source::Point(vec![5.3, 7.6]),
            Source::Cells {
                cells: vec![vec![18, 18], vec![18, 19]],
                values: Some(vec![0.5, 0.25]),
            },
        ];
        let problem = field_problem(grid, smooth_cost(&shape), sources);
        let opts = first_order();
        let out = solve(&problem, &opts, &Control::new()).unwrap();
        let weights = [
            (Probe::Cell(vec![20, 3]), 1.0),
            (Probe::Cell(vec![22, 22]), 0.7),
            (Probe::Cell(vec![3, 20]), -0.4),
            (Probe::Point(vec![17.4, 9.7]), 2.5),
        ];
        let all = cost_gradient(&problem, &opts, &out, &weights, &Control::new()).unwrap();
        let mut sum = ArrayD::<f64>::zeros(all.raw_dim());
        for (probe, w) in &weights {
            let g =
                distance_gradient(&problem, &opts, &out, probe.clone(), &Control::new()).unwrap();
            sum.scaled_add(*w, &g);
        }
        let scale = all.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!(scale > 0.1);
        let worst = all
            .iter()
            .zip(sum.iter())
            .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
        assert!(worst <= 1e-12 * scale, "{worst} against {scale}");
    }

    /// Euler's identity for a degree-1 homogeneous `U`: `Σ_x W_x ∂U(y)/∂W_x = U(y)`.
    fn assert_euler(problem: &EikonalProblem<'_>, probes: &[Probe]) {
        assert_euler_with(&first_order(), problem, probes);
        assert_euler_with(&second_order(), problem, probes);
    }

    fn assert_euler_with(opts: &EikonalOptions, problem: &EikonalProblem<'_>, probes: &[Probe]) {
        let opts = opts.clone();
        let out = solve(problem, &opts, &Control::new()).unwrap();
        let n = problem.grid.len();
        for probe in probes {
            let g =
                distance_gradient(problem, &opts, &out, probe.clone(), &Control::new()).unwrap();
            let euler: f64 = g
                .iter()
                .enumerate()
                .filter(|(_, g)| **g != 0.0)
                .map(|(i, g)| problem.cost.at(i) * g)
                .sum();
            let u = objective(problem, &out.distance, &[(probe.clone(), 1.0)]);
            assert!(
                (euler - u).abs() <= 1e-12 * u.abs().max(1.0),
                "{probe:?}: Σ W ∂U/∂W = {euler}, U = {u} ({n} cells)"
            );
        }
    }

    #[test]
    fn constant_cost_satisfies_euler_identity() {
        let problem = EikonalProblem {
            grid: Grid::unit(&[24, 24]).unwrap(),
            cost: IsotropicCost::constant(1.7).unwrap(),
            sources: vec![Source::Point(vec![5.3, 7.6])],
        };
        let probes = [
            Probe::Cell(vec![23, 23]),
            Probe::Cell(vec![0, 0]),
            Probe::Cell(vec![5, 20]),
            Probe::Cell(vec![6, 8]),
            Probe::Point(vec![11.5, 3.25]),
        ];
        assert_euler(&problem, &probes);
    }

    #[test]
    fn random_costs_satisfy_euler_identity_in_2d_and_3d() {
        // 2D, anisotropic spacing, a point and a cell source (of value 0,
        // so that U stays homogeneous).
        let shape = [24, 18];
        let grid = Grid::new(&shape, &[0.8, 1.25]).unwrap();
        let problem = field_problem(
            grid,
            smooth_cost(&shape),
            vec![
                Source::Point(vec![4.6, 3.3]),
                Source::Cells {
                    cells: vec![vec![20, 15]],
                    values: None,
                },
            ],
        );
        assert_euler(
            &problem,
            &[
                Probe::Cell(vec![23, 0]),
                Probe::Cell(vec![12, 9]),
                Probe::Point(vec![0.5, 17.0]),
            ],
        );
        let shape = [10, 10, 10];
        let problem = field_problem(
            Grid::unit(&shape).unwrap(),
            smooth_cost(&shape),
            vec![Source::Point(vec![3.2, 4.7, 2.4])],
        );
        assert_euler(
            &problem,
            &[Probe::Cell(vec![9, 9, 9]), Probe::Cell(vec![0, 0, 9])],
        );
    }

    #[test]
    fn one_dimensional_line_has_unit_sensitivities() {
        // U(x) = 3 |x − 2| on a line: the seeds are cells 1, 2, 3 (radius
        // 1.5), cells 4..=8 each add their length 1, and seed 3 holds
        // W(2) |3 − 2|.
        let problem = EikonalProblem {
            grid: Grid::unit(&[1, 9]).unwrap(),
            cost: IsotropicCost::constant(3.0).unwrap(),
            sources: vec![Source::Point(vec![0.0, 2.0])],
        };
        let opts = first_order();
        let out = solve(&problem, &opts, &Control::new()).unwrap();
        let g = distance_gradient(
            &problem,
            &opts,
            &out,
            Probe::Cell(vec![0, 8]),
            &Control::new(),
        )
        .unwrap();
        let expected = [0.0, 0.0, 1.0, 0.0, 1.0, 1.0, 1.0, 1.0, 1.0];
        for (x, (&g, e)) in g.iter().zip(expected).enumerate() {
            assert!((g - e).abs() < 1e-14, "cell {x}: {g} instead of {e}");
        }
    }

    #[test]
    fn walls_and_unreached_cells_get_zero() {
        // A wall across the grid but for one gap, and a pocket closed by walls.
        let shape = [12, 12];
        let grid = Grid::unit(&shape).unwrap();
        let mut w = smooth_cost(&shape);
        for j in 0..12 {
            if j != 9 {
                w[6 * 12 + j] = f64::INFINITY;
            }
        }
        // The pocket: cell (10, 1) walled in.
        for (a, b) in [(9, 1), (11, 1), (10, 0), (10, 2)] {
            w[a * 12 + b] = f64::INFINITY;
        }
        let problem = field_problem(grid, w.clone(), vec![Source::Point(vec![2.0, 2.0])]);
        let opts = first_order();
        let out = solve(&problem, &opts, &Control::new()).unwrap();
        assert_eq!(out.distance[[10, 1]], f64::INFINITY);
        let weights = [(Probe::Cell(vec![11, 3]), 1.0)];
        let g = cost_gradient(&problem, &opts, &out, &weights, &Control::new()).unwrap();
        for (i, (&g, &wi)) in g.iter().zip(&w).enumerate() {
            if wi == f64::INFINITY {
                assert_eq!(g, 0.0, "wall cell {i}");
            }
        }
        assert_eq!(g[[10, 1]], 0.0);
        // The path goes through the gap: the gap's cost matters.
        assert!(g[[6, 9]] > 0.5);
        // A probe on a wall or in the pocket is refused by name.
        for probe in [Probe::Cell(vec![6, 0]), Probe::Cell(vec![10, 1])] {
            let e = distance_gradient(&problem, &opts, &out, probe, &Control::new());
            assert!(
                matches!(
                    e,
                    Err(EikonalError::Option {
                        field: "weights",
                        ..
                    })
                ),
                "{e:?}"
            );
        }
    }

    #[test]
    fn an_early_stop_keeps_the_gradient_of_the_cells_it_froze() {
        // The cells frozen before a stop have the values, and the updates,
        // of the full solve: so has the gradient of a probe among them.
        let shape = [20, 20];
        let problem = field_problem(
            Grid::unit(&shape).unwrap(),
            smooth_cost(&shape),
            vec![Source::Point(vec![3.5, 4.0])],
        );
        let probe = Probe::Cell(vec![9, 8]);
        for opts in [first_order(), second_order()] {
            let full = solve(&problem, &opts, &Control::new()).unwrap();
            let g =
                distance_gradient(&problem, &opts, &full, probe.clone(), &Control::new()).unwrap();
            let stops = [
                StopRules {
                    max_distance: Some(full.distance[[9, 8]] + 0.5),
                    ..StopRules::default()
                },
                StopRules {
                    targets: vec![vec![9.0, 8.0]],
                    ..StopRules::default()
                },
            ];
            for stop in stops {
                let early_opts = opts.clone().with_stop(stop);
                let early = solve(&problem, &early_opts, &Control::new()).unwrap();
                assert!(early.frozen < problem.grid.len());
                let ge = distance_gradient(
                    &problem,
                    &early_opts,
                    &early,
                    probe.clone(),
                    &Control::new(),
                )
                .unwrap();
                assert!(g.iter().zip(ge.iter()).all(|(a, b)| (a - b).abs() <= 1e-13));
                // A cell the stop left out has no distance to differentiate.
                let out = distance_gradient(
                    &problem,
                    &early_opts,
                    &early,
                    Probe::Cell(vec![19, 19]),
                    &Control::new(),
                );
                assert!(
                    matches!(
                        out,
                        Err(EikonalError::Option {
                            field: "weights",
                            ..
                        })
                    ),
                    "{out:?}"
                );
            }
        }
    }

    #[test]
    fn the_freezing_order_and_the_sort_by_distance_agree() {
        let shape = [16, 20];
        let problem = field_problem(
            Grid::unit(&shape).unwrap(),
            smooth_cost(&shape),
            vec![Source::Point(vec![8.0, 3.5])],
        );
        let mut opts = first_order();
        opts.record_order = true;
        let out = solve(&problem, &opts, &Control::new()).unwrap();
        let weights = [
            (Probe::Cell(vec![15, 19]), 1.0),
            (Probe::Cell(vec![0, 18]), 2.0),
        ];
        let a = cost_gradient(&problem, &opts, &out, &weights, &Control::new()).unwrap();
        let mut sorted = out.clone();
        sorted.frozen_order = None;
        let b = cost_gradient(&problem, &opts, &sorted, &weights, &Control::new()).unwrap();
        for (x, y) in a.iter().zip(b.iter()) {
            assert!((x - y).abs() <= 1e-13 * x.abs().max(1.0), "{x} {y}");
        }
    }

    #[test]
    fn other_schemes_are_refused_by_name() {
        let problem = EikonalProblem {
            grid: Grid::unit(&[6, 6]).unwrap(),
            cost: IsotropicCost::constant(1.0).unwrap(),
            sources: vec![Source::Point(vec![1.0, 1.0])],
        };
        let out = solve(&problem, &first_order(), &Control::new()).unwrap();
        let probe = [(Probe::Cell(vec![5, 5]), 1.0)];
        let cases: [(EikonalOptions, &str); 4] = [
            (
                EikonalOptions::DEFAULT.with_factoring(false),
                "record_order",
            ),
            (
                EikonalOptions::DEFAULT.with_order(Order::First),
                "factoring",
            ),
            (first_order().with_method(Method::FastSweeping), "method"),
            (first_order().with_method(Method::Dijkstra), "method"),
        ];
        for (opts, name) in cases {
            match cost_gradient(&problem, &opts, &out, &probe, &Control::new()) {
                Err(EikonalError::Option { field, reason }) => {
                    assert_eq!(field, name);
                    assert!(reason.contains("order 1"), "{reason}");
                }
                other => panic!("{name}: {other:?}"),
            }
        }
        // A probe outside the grid, a weight that is not finite.
        for weights in [
            [(Probe::Cell(vec![6, 0]), 1.0)],
            [(Probe::Point(vec![0.0, 5.5]), 1.0)],
            [(Probe::Cell(vec![1, 1]), f64::NAN)],
        ] {
            assert!(matches!(
                cost_gradient(&problem, &first_order(), &out, &weights, &Control::new()),
                Err(EikonalError::Option {
                    field: "weights",
                    ..
                })
            ));
        }
    }

    #[test]
    fn a_raised_flag_stops_it() {
        let problem = EikonalProblem {
            grid: Grid::unit(&[8, 8]).unwrap(),
            cost: IsotropicCost::constant(1.0).unwrap(),
            sources: vec![Source::Point(vec![1.0, 1.0])],
        };
        let opts = first_order();
        let out = solve(&problem, &opts, &Control::new()).unwrap();
        let flag = AtomicBool::new(true);
        let r = cost_gradient(
            &problem,
            &opts,
            &out,
            &[(Probe::Cell(vec![7, 7]), 1.0)],
            &Control::new().with_cancel(&flag),
        );
        assert_eq!(r, Err(EikonalError::Cancelled));
    }

    /// The adjoint against one forward solve on 1024² (release:
    /// `cargo test --release --lib numerics::eikonal::gradient -- --ignored --nocapture`).
    #[test]
    #[ignore]
    fn time_against_one_solve() {
        let shape = [1024, 1024];
        let problem = field_problem(
            Grid::unit(&shape).unwrap(),
            smooth_cost(&shape),
            vec![Source::Point(vec![511.3, 200.7])],
        );
        let opts = first_order();
        let t = std::time::Instant::now();
        let out = solve(&problem, &opts, &Control::new()).unwrap();
        let forward = t.elapsed().as_secs_f64();
        let weights: Vec<(Probe, f64)> = (0..100)
            .map(|m| (Probe::Cell(vec![(m * 97) % 1024, (m * 389) % 1024]), 1.0))
            .collect();
        let t = std::time::Instant::now();
        let g = cost_gradient(&problem, &opts, &out, &weights, &Control::new()).unwrap();
        let adjoint = t.elapsed().as_secs_f64();
        let mut recorded = opts.clone();
        recorded.record_order = true;
        let out_r = solve(&problem, &recorded, &Control::new()).unwrap();
        let t = std::time::Instant::now();
        let g_r = cost_gradient(&problem, &recorded, &out_r, &weights, &Control::new()).unwrap();
        let adjoint_r = t.elapsed().as_secs_f64();
        eprintln!(
            "1024²: solve {forward:.3} s, adjoint {adjoint:.3} s (ratio {:.2}), \
             adjoint from the recorded order {adjoint_r:.3} s (ratio {:.2})",
            adjoint / forward,
            adjoint_r / forward
        );
        assert!(g.iter().sum::<f64>() > 0.0 && g_r.iter().sum::<f64>() > 0.0);
    }
}
