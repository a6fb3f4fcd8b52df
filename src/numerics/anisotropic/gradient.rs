//! The gradient of a Riemannian fast-marching distance with respect to the
//! metric: the discrete adjoint of the unfactored adaptive-stencil scheme of
//! [`super::fast_marching`], orders 1 and 2 (issue 23; the tensor
//! counterpart of [`crate::numerics::eikonal::cost_gradient`]).
//!
//! # The equation that is differentiated
//!
//! [`super::solve`] with `factoring: false` gives every reached cell `x`
//! that is not a seed its value from the cells frozen before its update.
//! With `D̃ = (H M_x H)⁻¹` the dual metric in index units (`H = diag(h)`)
//! and Selling's decomposition `D̃ = Σ_k ρ_k e_k e_kᵀ`, where
//! `ρ_k = −⟨b_i, D̃ b_j⟩` for the pair `(i, j)` of the `D̃`-obtuse superbase
//! `(b_0, …, b_d)` that belongs to slot `k` ([`super::selling`]), the update
//! solves
//!
//! ```text
//! F(U_x, b, ρ) = Σ_k s_k ρ_k ((U_x − b_k)⁺)² − 1 = 0
//! ```
//!
//! over the offsets with a known neighbour `x ± e_k`, each on the side of
//! smaller `b`: `b_k = U(x − σe_k)`, `s_k = 1` at order 1; at order 2, when
//! `x − 2σe_k` is known, carries the same label and
//! `U(x − 2σe_k) ≤ U(x − σe_k)`, `b_k = (4U(x − σe_k) − U(x − 2σe_k))/3` and
//! `s_k = 9/4`. The terms with `b_k ≥ U_x` drop out (causality). Implicit
//! differentiation, with `d_k = U_x − b_k` over the active terms and
//! `S = Σ_k s_k ρ_k d_k > 0`:
//!
//! ```text
//! ∂U_x/∂b_k = s_k ρ_k d_k / S,      ∂U_x/∂ρ_k = −s_k d_k² / (2S),
//! ∂U_x/∂D̃ = Σ_k ∂U_x/∂ρ_k · (−(b_i b_jᵀ + b_j b_iᵀ)/2),
//! ∂U_x/∂A = −D̃ (∂U_x/∂D̃) D̃   (A = H M_x H),     ∂U_x/∂M_ab = h_a h_b ∂U_x/∂A_ab
//! ```
//!
//! (`∂b_k/∂U(x − σe) = 4/3`, `∂b_k/∂U(x − 2σe) = −1/3` at order 2). The
//! superbase is piecewise constant in `M`, so for a fixed superbase the
//! weights are linear in `D̃`.
//!
//! Cells whose stencil is incomplete (near corners of the domain and of
//! walls) also take the semi-Lagrangian fallback
//! `min_t (1 − t) U(y1) + t U(y2) + ‖w(t)‖_A`, `w(t)` the displacement from
//! `(1 − t) y1 + t y2` to `x`; where it gives the value, the envelope
//! theorem gives `∂U_x/∂U(y1) = 1 − t`, `∂U_x/∂U(y2) = t` and
//! `∂U_x/∂A = w wᵀ / (2‖w‖_A)` at the minimising `t`.
//!
//! # The adjoint
//!
//! For `J = Σ_m w_m U(y_m)` the adjoint state `λ` starts as the weights (a
//! point between cells spreads its weight over its corners with the
//! multilinear weights, as [`crate::numerics::eikonal::Probe`] says) and one
//! sweep over the reached cells in reverse freezing order (every cell an
//! update reads was frozen before the cell, so `λ_x` is final when `x` is
//! reached) does, for a non-seed cell,
//!
//! ```text
//! ∂J/∂M_x += λ_x ∂U_x/∂M_x,        λ_j += λ_x ∂U_x/∂U_j  for each cell j read.
//! ```
//!
//! A seed of a point source `p` holds `‖x − p‖_{A_q}` (`q` the cell nearest
//! to `p`), so its `λ` goes to `∂J/∂A_q += λ_x z zᵀ / (2‖z‖_{A_q})`,
//! `z = x − p`; a cell source's values do not depend on `M`.
//!
//! # Homogeneity
//!
//! Scaling the metric by `t > 0` scales every `ρ_k` by `1/t`, every length
//! by `√t`, and leaves the superbases and the stencils unchanged, so
//! `U(tM) = √t U(M)` (cell sources of value 0) and Euler's identity reads
//! `Σ_x M_x : ∂J/∂M_x = J/2`; the tests check it to round-off.
//!
//! # Layout of the result
//!
//! The gradient has the layout of [`super::TensorField::to_components`]:
//! the grid's shape plus a trailing axis of the components
//! `[m00, m01, m11]` (2D) or `[m00, m01, m02, m11, m12, m22]` (3D), in
//! physical units. Entry `c` is the derivative of `J` with respect to the
//! component `c` as one number, so an off-diagonal entry moves both `M_ab`
//! and `M_ba`: it is twice the `(a, b)` entry of the symmetric matrix
//! gradient `G` (`δJ = Σ_ab G_ab δM_ab`). For a symmetric perturbation
//! given by its components `δm`, `δJ = Σ_{x, c} grad[x, c] δm[x, c]`, and
//! Euler's identity is `Σ_{x, c} grad[x, c] m[x, c] = J/2`. Walls and
//! unreached cells get 0.
//!
//! # Which update, and where it is not differentiable
//!
//! Each cell's value is the smallest of the updates the solver made, one
//! each time a neighbour froze. Order 1 freezes in non-decreasing `U`, so
//! the update is rebuilt from the neighbours of smaller `U`. Order 2 needs
//! the freezing ranks ([`TensorOptions::record_order`]): the known cells at
//! each of the cell's updates are those of rank no later than the
//! neighbour that triggered it, and the update that gave the stored value
//! (the first that reached it) is the one differentiated. Every rebuilt
//! value is checked against the solve's (relative `1e-9`): an output that
//! does not come from this problem and these options is refused
//! ([`EikonalError::Option`] on `output`).
//!
//! `U` is a piecewise smooth function of `M`: the pieces change where two
//! sides of an offset tie, where a term enters or leaves the update, where
//! the second-order condition switches, where the superbase flips (some
//! `ρ_k` passes through 0), where the fallback and the scheme tie, and on
//! Voronoi boundaries. There the result is the derivative of the piece the
//! solver chose.
//!
//! Not supported (refused with [`EikonalError::Option`] naming the option):
//! source factoring (`factoring`), and order 2 without the freezing order
//! (`record_order`).
//!
//! The cost is one stencil build, one sort (none with the freezing order
//! recorded) and one pass that rebuilds each cell's update: comparable to
//! one solve (see the ignored test `time_against_one_solve`).

use std::borrow::Cow;

use ndarray::{ArrayD, IxDyn};

use super::fast_marching::{
    seeds, semi_lagrangian_choice, solve_terms, FactorPoint, SlChoice, Term,
};
use super::selling::{superbase2, superbase3, PAIRS2, PAIRS3};
use super::stencil::{self, dual_index_metric, Stencils, NEIGHBOURS, NONE};
use super::{components, TensorOptions, TensorOutput, TensorProblem, TensorSolveError};
use crate::numerics::control::Control;
use crate::numerics::eikonal::{
    backward_order, nearest_cell, probe_weights, EikonalError, Order, Probe,
};

/// Cells between two polls of the cancel flag.
const CANCEL_EVERY: usize = 4096;
/// Cells between two progress reports.
const PROGRESS_EVERY: usize = 65536;

/// The gradient of `J = Σ_m w_m U(y_m)` with respect to every component of
/// the metric at every cell: the discrete adjoint of the solve that gave
/// `output` (see the module documentation for the equation, the sources
/// and the layout).
///
/// `problem` and `options` must be those of the solve; `options` must have
/// `factoring: false`, and order 2 needs `record_order: true` (refused with
/// [`EikonalError::Option`] naming the option otherwise). Each probe must be
/// reached; a weight must be finite (refused on `weights`). The result has
/// shape `grid shape + [3]` (2D) or `+ [6]` (3D), the layout of
/// [`super::TensorField::to_components`]; an off-diagonal entry is the
/// derivative with respect to that one component (both `M_ab` and `M_ba`).
///
/// Polls `control` every 4096 cells; reports progress.
///
/// # Examples
/// ```
/// use geodex::numerics::anisotropic::{metric_gradient, solve, TensorField, TensorOptions, TensorProblem};
/// use geodex::numerics::eikonal::Probe;
/// use geodex::numerics::{Control, Grid, Order, Source};
/// let grid = Grid::unit(&[12, 12])?;
/// let metric = TensorField::constant(&grid, &[2.0, 0.5, 1.0])?;
/// let problem = TensorProblem { grid, metric, sources: vec![Source::Point(vec![2.0, 3.0])] };
/// let options = TensorOptions::DEFAULT.with_order(Order::First).with_factoring(false);
/// let out = solve(&problem, &options, &Control::new())?;
/// let weights = [(Probe::Cell(vec![10, 9]), 1.0)];
/// let g = metric_gradient(&problem, &options, &out, &weights, &Control::new())?;
/// assert_eq!(g.shape(), &[12, 12, 3]);
/// // Euler: U(tM) = √t U(M), so Σ m·∂U/∂m = U/2.
/// let m = [2.0, 0.5, 1.0];
/// let euler: f64 = g.iter().enumerate().map(|(i, g)| g * m[i % 3]).sum();
/// assert!((euler - 0.5 * out.output.distance[[10, 9]]).abs() < 1e-12);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn metric_gradient(
    problem: &TensorProblem,
    options: &TensorOptions,
    output: &TensorOutput,
    weights: &[(Probe, f64)],
    control: &Control<'_>,
) -> Result<ArrayD<f64>, TensorSolveError> {
    let replay = Replay::new(problem, options, output, control)?;
    let grid = &problem.grid;
    let n = grid.len();
    let mut lam = vec![0.0f64; n];
    for (i, w) in probe_weights(grid, &replay.u, weights)? {
        lam[i] += w;
    }
    // ∂J/∂A per cell, `A = H M H` padded to 3×3, upper triangle.
    let mut ga = vec![[0.0f64; 6]; n];
    let order = backward_order(&replay.u, &output.output);
    for (done, &x) in order.iter().enumerate() {
        if done % CANCEL_EVERY == 0 && control.is_cancelled() {
            return Err(EikonalError::Cancelled.into());
        }
        if done % PROGRESS_EVERY == 0 && done > 0 {
            control.report(done as f64 / order.len() as f64);
        }
        let l = lam[x];
        if l == 0.0 {
            continue;
        }
        if replay.fixed[x] {
            if let Some((q, z, v)) = replay.point_seed(x) {
                add_outer(&mut ga[q], z, l / (2.0 * v));
            }
            continue;
        }
        let Some(row) = replay.row(x)? else {
            continue;
        };
        for &(j, d) in row.du() {
            lam[j] += l * d;
        }
        for (g, d) in ga[x].iter_mut().zip(row.da) {
            *g += l * d;
        }
    }
    control.report(1.0);
    let nd = grid.ndim();
    let nc = components(nd);
    let off = 3 - nd;
    let h = grid.spacing3();
    let mut out = vec![0.0f64; n * nc];
    for (c, g) in ga.iter().enumerate() {
        let mut s = 0;
        for a in 0..nd {
            for b in a..nd {
                let (pa, pb) = (a + off, b + off);
                let v = h[pa] * h[pb] * g[sym(pa, pb)];
                out[c * nc + s] = if a == b { v } else { 2.0 * v };
                s += 1;
            }
        }
    }
    let mut shape = grid.shape().to_vec();
    shape.push(nc);
    ArrayD::from_shape_vec(IxDyn(&shape), out).map_err(|e| {
        EikonalError::Option {
            field: "output",
            reason: e.to_string(),
        }
        .into()
    })
}

/// The gradient of `U` at one probe with respect to every metric component:
/// [`metric_gradient`] with the one weight `1`. For a point `y`, this is
/// also the gradient of the Riemannian length of the minimal path from `y`
/// to the sources (the envelope theorem: the path's own change does not
/// enter at first order).
pub fn metric_distance_gradient(
    problem: &TensorProblem,
    options: &TensorOptions,
    output: &TensorOutput,
    probe: Probe,
    control: &Control<'_>,
) -> Result<ArrayD<f64>, TensorSolveError> {
    metric_gradient(problem, options, output, &[(probe, 1.0)], control)
}

/// Index of `(a, b)` in a padded symmetric 3×3 stored as its upper triangle.
#[inline]
fn sym(a: usize, b: usize) -> usize {
    const S: [[usize; 3]; 3] = [[0, 1, 2], [1, 3, 4], [2, 4, 5]];
    S[a][b]
}

/// `g += s z zᵀ` on the upper triangle.
#[inline]
fn add_outer(g: &mut [f64; 6], z: [f64; 3], s: f64) {
    for a in 0..3 {
        for b in a..3 {
            g[sym(a, b)] += s * z[a] * z[b];
        }
    }
}

/// Refuses the options whose scheme is not the one differentiated here.
fn check_options(options: &TensorOptions, output: &TensorOutput) -> Result<(), TensorSolveError> {
    let refuse = |field: &'static str, what: &str| -> Result<(), TensorSolveError> {
        Err(EikonalError::Option {
            field,
            reason: format!(
                "the metric gradient differentiates the anisotropic fast marching of order 1 \
                 or 2 without source factoring only (order 2 with the freezing order \
                 recorded); {what}"
            ),
        }
        .into())
    };
    if options.factoring {
        return refuse("factoring", "got factoring on: solve with factoring off");
    }
    if options.order == Order::Second && output.output.frozen_order.is_none() {
        return refuse(
            "record_order",
            "order 2 needs the solve's freezing order: solve with record_order",
        );
    }
    Ok(())
}

/// The most cells one update reads: two per offset.
const MAX_READS: usize = 12;

/// The derivatives of one cell's update `U_x = G(U_read, M_x)`.
#[derive(Debug, Clone, Copy)]
struct Row {
    /// `(j, ∂U_x/∂U_j)` for the cells read.
    du: [(usize, f64); MAX_READS],
    n: usize,
    /// `∂U_x/∂A_x`, `A = H M_x H` padded, upper triangle.
    da: [f64; 6],
    /// The semi-Lagrangian fallback gave the value (for the tests' structure).
    #[cfg_attr(not(test), allow(dead_code))]
    fallback: bool,
}

impl Row {
    fn du(&self) -> &[(usize, f64)] {
        &self.du[..self.n]
    }
}

/// One update of a cell as the solver computed it.
#[derive(Debug, Clone, Copy)]
enum Update {
    /// The Eulerian scheme: its terms (sorted by `b`) and root.
    Scheme {
        terms: [Term; 6],
        nt: usize,
        value: f64,
    },
    /// The semi-Lagrangian fallback.
    Fallback(SlChoice),
}

impl Update {
    fn value(&self) -> f64 {
        match self {
            Update::Scheme { value, .. } => *value,
            Update::Fallback(c) => c.value,
        }
    }
}

/// The solve replayed: the final values, labels and ranks, the stencils and
/// the seeds, from which every cell's update is rebuilt.
struct Replay<'a> {
    problem: &'a TensorProblem,
    st: Stencils,
    second: bool,
    u: Cow<'a, [f64]>,
    labels: Cow<'a, [i32]>,
    ranks: Option<Cow<'a, [i64]>>,
    /// The seed cells.
    fixed: Vec<bool>,
    /// The label the seeds gave (the source whose seed won).
    seed_labels: Vec<i32>,
    /// Per source: its factoring point and nearest cell, for point sources.
    points: Vec<Option<(FactorPoint, usize)>>,
}

impl<'a> Replay<'a> {
    fn new(
        problem: &'a TensorProblem,
        options: &TensorOptions,
        output: &'a TensorOutput,
        control: &Control<'_>,
    ) -> Result<Self, TensorSolveError> {
        check_options(options, output)?;
        let grid = &problem.grid;
        if problem.metric.ndim() != grid.ndim() {
            return Err(TensorSolveError::Dimension {
                field: problem.metric.ndim(),
                grid: grid.ndim(),
            });
        }
        let out = &output.output;
        let shapes_agree = out.distance.shape() == grid.shape()
            && out.labels.shape() == grid.shape()
            && out
                .frozen_order
                .as_ref()
                .is_none_or(|o| o.shape() == grid.shape());
        if !shapes_agree {
            return Err(EikonalError::Option {
                field: "output",
                reason: format!(
                    "the solve's output has shape {:?}, the grid {:?}",
                    out.distance.shape(),
                    grid.shape()
                ),
            }
            .into());
        }
        let st = stencil::build(grid, &problem.metric, control)
            .map_err(|_| TensorSolveError::from(EikonalError::Cancelled))?;
        let s = seeds(problem, &st, options)?;
        let points = s
            .factor
            .iter()
            .map(|f| f.map(|fp| (fp, grid.linear(nearest_cell(grid, fp.p)))))
            .collect();
        Ok(Self {
            problem,
            st,
            second: options.order == Order::Second,
            u: flat(&out.distance),
            labels: flat(&out.labels),
            ranks: out.frozen_order.as_ref().map(flat),
            fixed: s.fixed,
            seed_labels: s.labels,
            points,
        })
    }

    /// For a seed of a point source: `(q, z, ‖z‖_{A_q})` with `q` the cell
    /// whose metric it uses and `z = x − p`; `None` for a cell source's seed
    /// or a seed at the source itself.
    fn point_seed(&self, x: usize) -> Option<(usize, [f64; 3], f64)> {
        let l = usize::try_from(self.seed_labels[x]).ok()?;
        let (fp, q) = self.points.get(l).copied().flatten()?;
        let xi = self.problem.grid.unravel(x).map(|c| c as f64);
        let z = [0, 1, 2].map(|k| xi[k] - fp.p[k]);
        let v = fp.at(xi);
        (v > 0.0).then_some((q, z, v))
    }

    /// The update of cell `x` from the cells `known` accepts, as the solver
    /// computes it (the scheme, and the fallback where it is smaller).
    fn update(&self, x: usize, known: &dyn Fn(usize) -> bool) -> Option<Update> {
        let st = &self.st;
        let k = st.k;
        let (u, labels) = (&self.u, &self.labels);
        let mut terms = [Term::default(); 6];
        let mut nt = 0;
        for s in 0..k {
            let rho = st.rho[x * k + s];
            if rho <= 0.0 {
                continue;
            }
            let mut best: Option<Term> = None;
            for side in 0..2 {
                let j = st.nb[(x * k + s) * 2 + side];
                if j == NONE || !known(j as usize) {
                    continue;
                }
                let j = j as usize;
                let a = u[j];
                let (mut c2, mut b) = (rho, a);
                if self.second && st.second[x] & (1 << (2 * s + side)) != 0 {
                    let j2 = 2 * j - x;
                    if known(j2) && labels[j2] == labels[j] {
                        let b2 = (4.0 * a - u[j2]) / 3.0;
                        if b2 >= b && b2.is_finite() {
                            c2 = 2.25 * rho;
                            b = b2;
                        }
                    }
                }
                if best.is_none_or(|t: Term| b < t.b) {
                    best = Some(Term {
                        c2,
                        b,
                        label: labels[j],
                        a,
                        j: j as u32,
                        second: c2 > rho,
                    });
                }
            }
            if let Some(t) = best {
                terms[nt] = t;
                nt += 1;
            }
        }
        let mut best = solve_terms(&mut terms[..nt], 1.0).map(|(value, _, _)| Update::Scheme {
            terms,
            nt,
            value,
        });
        let mask = st.fallback[x];
        if mask != 0 {
            let grid = &self.problem.grid;
            let metric = &self.problem.metric;
            if let Some(c) = semi_lagrangian_choice(grid, metric, x, mask, u, labels, known) {
                if best.is_none_or(|b| c.value < b.value()) {
                    best = Some(Update::Fallback(c));
                }
            }
        }
        best
    }

    /// The cells whose freezing triggered an update of `x`, as their ranks
    /// (increasing, distinct, before `x`'s own).
    fn events(&self, x: usize, ranks: &[i64]) -> ([i64; 38], usize) {
        let st = &self.st;
        let rx = ranks[x];
        let mut ev = [0i64; 38];
        let mut ne = 0;
        let mut offer = |j: usize| {
            let r = ranks[j];
            if r >= 0 && r < rx {
                ev[ne] = r;
                ne += 1;
            }
        };
        for &j in &st.nb[x * 2 * st.k..(x + 1) * 2 * st.k] {
            if j != NONE {
                offer(j as usize);
            }
        }
        let mask = st.fallback[x];
        if mask != 0 {
            let grid = &self.problem.grid;
            let xi = grid.unravel(x);
            for (b, o) in NEIGHBOURS.iter().enumerate() {
                if mask & (1 << b) != 0 {
                    offer(grid.linear([0, 1, 2].map(|a| (xi[a] as i64 + o[a]) as usize)));
                }
            }
        }
        ev[..ne].sort_unstable();
        let mut m = 0;
        for i in 0..ne {
            if m == 0 || ev[i] != ev[m - 1] {
                ev[m] = ev[i];
                m += 1;
            }
        }
        (ev, m)
    }

    /// The update that gave cell `x` its value: with the ranks, the first
    /// of its updates (one per freezing neighbour) that reached the stored
    /// value; without them (order 1), the one from the neighbours of
    /// smaller `U`.
    fn winning(&self, x: usize) -> Option<Update> {
        let ux = self.u[x];
        let Some(ranks) = &self.ranks else {
            let u = &self.u;
            return self.update(x, &|j| u[j] < ux);
        };
        let (ev, ne) = self.events(x, ranks);
        let at = |t: i64| {
            let known = |j: usize| ranks[j] >= 0 && ranks[j] <= t;
            self.update(x, &known)
        };
        let last = at(*ev[..ne].last()?);
        if last.is_some_and(|u| u.value() == ux) {
            return last;
        }
        // The stored value is the smallest of the updates, the first one
        // that reached it; otherwise the closest (checked by the caller).
        let mut closest = last;
        for &t in &ev[..ne] {
            let upd = at(t);
            if upd.is_some_and(|u| u.value() == ux) {
                return upd;
            }
            if let Some(c) = upd {
                if closest.is_none_or(|b| (c.value() - ux).abs() < (b.value() - ux).abs()) {
                    closest = upd;
                }
            }
        }
        closest
    }

    /// The derivatives of the update of reached non-seed cell `x`; `None`
    /// if it read nothing. An error if the rebuilt value is not the solve's.
    fn row(&self, x: usize) -> Result<Option<Row>, TensorSolveError> {
        let ux = self.u[x];
        let upd = self.winning(x);
        match upd {
            Some(upd) if (upd.value() - ux).abs() <= 1e-9 * ux.abs().max(1.0) => {
                Ok(Some(self.derivatives(x, &upd)))
            }
            other => Err(EikonalError::Option {
                field: "output",
                reason: format!(
                    "the output does not come from this problem and these options: at cell \
                     {:?} the scheme gives {:?}, the output {ux}",
                    crate::numerics::metric::unravel_user(&self.problem.grid, x),
                    other.map(|u| u.value())
                ),
            }
            .into()),
        }
    }

    /// The derivatives of one update (see the module documentation).
    fn derivatives(&self, x: usize, upd: &Update) -> Row {
        let mut row = Row {
            du: [(0, 0.0); MAX_READS],
            n: 0,
            da: [0.0; 6],
            fallback: false,
        };
        let (terms, nt, v) = match upd {
            Update::Fallback(c) => {
                row.fallback = true;
                row.du[0] = (c.y1, 1.0 - c.t);
                row.n = 1;
                if let Some(y2) = c.y2 {
                    row.du[1] = (y2, c.t);
                    row.n = 2;
                }
                if c.len > 0.0 {
                    add_outer(&mut row.da, c.w, 1.0 / (2.0 * c.len));
                }
                return row;
            }
            Update::Scheme { terms, nt, value } => (terms, *nt, *value),
        };
        let st = &self.st;
        let k = st.k;
        let grid = &self.problem.grid;
        let nd = grid.ndim();
        let used = terms[..nt].iter().filter(|t| t.b < v);
        let s: f64 = used.clone().map(|t| t.c2 * (v - t.b)).sum();
        let inv = if s > 0.0 && s.is_finite() {
            1.0 / s
        } else {
            0.0
        };
        // The dual metric and its superbase, as the stencils were built.
        let dual = dual_index_metric(self.problem.metric.at(x), grid.spacing());
        let mut dm = [[0.0f64; 3]; 3];
        // `∂ρ_slot/∂D̃ = −(b_i b_jᵀ + b_j b_iᵀ)/2`, `b` as f64 (nd components).
        let mut pair = [[[0.0f64; 3]; 2]; 6];
        if nd == 2 {
            dm[0] = [dual[0], dual[1], 0.0];
            dm[1] = [dual[1], dual[2], 0.0];
            let b = superbase2([dual[0], dual[1], dual[2]]);
            for (slot, &(i, j)) in PAIRS2.iter().enumerate() {
                pair[slot] = [
                    [b[i][0] as f64, b[i][1] as f64, 0.0],
                    [b[j][0] as f64, b[j][1] as f64, 0.0],
                ];
            }
        } else {
            dm[0] = [dual[0], dual[1], dual[2]];
            dm[1] = [dual[1], dual[3], dual[4]];
            dm[2] = [dual[2], dual[4], dual[5]];
            let b = superbase3([dual[0], dual[1], dual[2], dual[3], dual[4], dual[5]]);
            for (slot, &(i, j, _, _)) in PAIRS3.iter().enumerate() {
                pair[slot] = [b[i].map(|c| c as f64), b[j].map(|c| c as f64)];
            }
        }
        let mut gd = [[0.0f64; 3]; 3];
        for t in used {
            let d = v - t.b;
            let db = t.c2 * d * inv;
            let j = t.j as usize;
            if t.second {
                row.du[row.n] = (j, db * 4.0 / 3.0);
                row.du[row.n + 1] = (2 * j - x, -db / 3.0);
                row.n += 2;
            } else {
                row.du[row.n] = (j, db);
                row.n += 1;
            }
            let nb = &st.nb[x * 2 * k..(x + 1) * 2 * k];
            let Some(slot) = nb.iter().position(|&y| y == t.j).map(|p| p / 2) else {
                continue;
            };
            let sk = if t.second { 2.25 } else { 1.0 };
            let r = -sk * d * d * 0.5 * inv;
            let [bi, bj] = pair[slot];
            for a in 0..nd {
                for c in 0..nd {
                    gd[a][c] -= r * 0.5 * (bi[a] * bj[c] + bj[a] * bi[c]);
                }
            }
        }
        // ∂U/∂A = −D̃ (∂U/∂D̃) D̃.
        let off = 3 - nd;
        for a in 0..nd {
            for c in a..nd {
                let mut g = 0.0;
                for p in 0..nd {
                    for q in 0..nd {
                        g += dm[a][p] * gd[p][q] * dm[q][c];
                    }
                }
                row.da[sym(a + off, c + off)] = -g;
            }
        }
        row
    }
}

/// The values of an array in C order, borrowed when it is laid out so.
fn flat<T: Clone>(a: &ArrayD<T>) -> Cow<'_, [T]> {
    match a.as_slice() {
        Some(s) => Cow::Borrowed(s),
        None => Cow::Owned(a.iter().cloned().collect()),
    }
}

#[cfg(test)]
mod tests {
    use std::sync::atomic::AtomicBool;

    use super::*;
    use crate::numerics::anisotropic::{solve, TensorField};
    use crate::numerics::eikonal::{Source, StopRules};
    use crate::numerics::Grid;

    fn first_order() -> TensorOptions {
        TensorOptions::DEFAULT
            .with_order(Order::First)
            .with_factoring(false)
    }

    fn second_order() -> TensorOptions {
        let mut o = TensorOptions::DEFAULT.with_factoring(false);
        o.record_order = true;
        o
    }

    /// A smooth SPD field: in 2D eigenvalues `λ1 ∈ [0.7, 1.3]` along a
    /// turning direction and `λ2 ∈ [4, 8]` across it (anisotropy up to
    /// about 3); in 3D `(1 + 0.3 sin) I + 3 v vᵀ + w wᵀ` with smooth `v`, `w`.
    fn smooth_field(shape: &[usize]) -> Vec<f64> {
        let grid = Grid::unit(shape).unwrap();
        let mut out = Vec::new();
        for i in 0..grid.len() {
            let [a, b, c] = grid.unravel(i).map(|x| x as f64);
            if shape.len() == 2 {
                let theta = 0.6 + 0.13 * b - 0.07 * c + 0.3 * (0.2 * c).sin();
                let l1 = 1.0 + 0.3 * (0.31 * b + 0.17 * c).sin();
                let l2 = 6.0 + 2.0 * (0.23 * c - 0.11 * b + 0.4).cos();
                let (e0, e1) = (theta.cos(), theta.sin());
                out.extend([
                    l1 * e0 * e0 + l2 * e1 * e1,
                    (l1 - l2) * e0 * e1,
                    l1 * e1 * e1 + l2 * e0 * e0,
                ]);
            } else {
                let s = 1.0 + 0.3 * (0.3 * a + 0.2 * b - 0.1 * c).sin();
                let v = [
                    (0.4 * a + 0.1).cos(),
                    0.5 + 0.5 * (0.3 * b - 0.2 * c).sin(),
                    (0.2 * c + 0.3 * a).sin(),
                ];
                let w = [0.3 * (0.5 * b).sin(), (0.25 * c + 0.1 * a).cos(), 0.4];
                let mut m = Vec::with_capacity(6);
                for p in 0..3 {
                    for q in p..3 {
                        let id = if p == q { s } else { 0.0 };
                        m.push(id + 3.0 * v[p] * v[q] + w[p] * w[q]);
                    }
                }
                out.extend(m);
            }
        }
        out
    }

    fn problem_of(grid: &Grid, m: Vec<f64>, sources: &[Source]) -> TensorProblem {
        TensorProblem {
            grid: grid.clone(),
            metric: TensorField::from_components(grid, m).unwrap(),
            sources: sources.to_vec(),
        }
    }

    /// `J = Σ w_m U(y_m)` read from a solve.
    fn objective(grid: &Grid, out: &TensorOutput, weights: &[(Probe, f64)]) -> f64 {
        let flat: Vec<f64> = out.output.distance.iter().copied().collect();
        probe_weights(grid, &flat, weights)
            .unwrap()
            .iter()
            .map(|&(i, w)| w * flat[i])
            .sum()
    }

    /// Per cell: seed or not, and for an update the branch, the cells read
    /// and the superbase of the cell: two solves with the same structure
    /// solve the same smooth equations.
    type Structure = Vec<(bool, Option<(bool, Vec<usize>)>, Vec<i32>)>;

    fn structure(problem: &TensorProblem, opts: &TensorOptions, out: &TensorOutput) -> Structure {
        let replay = Replay::new(problem, opts, out, &Control::new()).unwrap();
        let grid = &problem.grid;
        (0..grid.len())
            .map(|x| {
                let dual = dual_index_metric(problem.metric.at(x), grid.spacing());
                let base: Vec<i32> = if grid.ndim() == 2 {
                    superbase2([dual[0], dual[1], dual[2]]).concat()
                } else {
                    superbase3([dual[0], dual[1], dual[2], dual[3], dual[4], dual[5]]).concat()
                };
                let row = if replay.u[x].is_finite() && !replay.fixed[x] {
                    replay.row(x).unwrap().map(|r| {
                        let mut cells: Vec<usize> =
                            r.du().iter().filter(|d| d.1 != 0.0).map(|d| d.0).collect();
                        cells.sort_unstable();
                        (r.fallback, cells)
                    })
                } else {
                    None
                };
                (replay.fixed[x] && replay.u[x].is_finite(), row, base)
            })
            .collect()
    }

    #[derive(Debug)]
    struct FdReport {
        max_rel: f64,
        checked: usize,
        skipped: usize,
        /// Cells whose update is second order (reads a second neighbour).
        second: usize,
        /// Cells whose value comes from the fallback.
        fallback: usize,
    }

    /// Compares the adjoint gradient with centred differences of the solver
    /// for every component of every cell, `ε = 1e-6 · tr(M_x)/d`, skipping
    /// the cells whose perturbation changes the structure of any update
    /// (not differentiable there). The relative difference is taken against
    /// `max(|g|, 1e-3 max |g|)`.
    fn finite_differences(
        opts: &TensorOptions,
        grid: &Grid,
        m: &[f64],
        sources: &[Source],
        weights: &[(Probe, f64)],
    ) -> FdReport {
        let base = problem_of(grid, m.to_vec(), sources);
        let out = solve(&base, opts, &Control::new()).unwrap();
        let g = metric_gradient(&base, opts, &out, weights, &Control::new()).unwrap();
        assert_eq!(g.ndim(), grid.ndim() + 1);
        let g: Vec<f64> = g.iter().copied().collect();
        let gmax = g.iter().fold(0.0f64, |a, v| a.max(v.abs()));
        assert!(gmax > 1e-2, "a gradient of {gmax}");
        let s0 = structure(&base, opts, &out);
        let replay = Replay::new(&base, opts, &out, &Control::new()).unwrap();
        let (mut second, mut fallback) = (0, 0);
        for (x, entry) in s0.iter().enumerate() {
            if let (_, Some((fb, cells)), _) = entry {
                fallback += usize::from(*fb);
                let r = replay.row(x).unwrap().unwrap();
                // A second-order term reads its second neighbour with a
                // negative coefficient (−1/3 of the term's).
                second +=
                    usize::from(!fb && cells.len() > r.du().iter().filter(|d| d.1 > 0.0).count());
            }
        }
        let nc = components(grid.ndim());
        let diag: Vec<usize> = if nc == 3 { vec![0, 2] } else { vec![0, 3, 5] };
        let mut report = FdReport {
            max_rel: 0.0,
            checked: 0,
            skipped: 0,
            second,
            fallback,
        };
        for c in 0..grid.len() {
            let scale = diag.iter().map(|&q| m[c * nc + q]).sum::<f64>() / diag.len() as f64;
            let eps = 1e-6 * scale;
            for q in 0..nc {
                let mut j = [0.0; 2];
                let mut same = true;
                for (slot, sign) in [1.0, -1.0].into_iter().enumerate() {
                    let mut mp = m.to_vec();
                    mp[c * nc + q] += sign * eps;
                    let p = problem_of(grid, mp, sources);
                    let o = solve(&p, opts, &Control::new()).unwrap();
                    same &= structure(&p, opts, &o) == s0;
                    j[slot] = objective(grid, &o, weights);
                }
                if !same {
                    report.skipped += 1;
                    continue;
                }
                let fd = (j[0] - j[1]) / (2.0 * eps);
                let gi = g[c * nc + q];
                let rel = (fd - gi).abs() / gi.abs().max(1e-3 * gmax);
                report.max_rel = report.max_rel.max(rel);
                report.checked += 1;
            }
        }
        report
    }

    #[test]
    fn matches_finite_differences_in_2d_order_1() {
        let shape = [14, 14];
        let grid = Grid::new(&shape, &[1.0, 0.8]).unwrap();
        let weights = [
            (Probe::Cell(vec![13, 2]), 1.0),
            (Probe::Cell(vec![12, 13]), 0.7),
            (Probe::Cell(vec![1, 12]), -0.4),
            (Probe::Point(vec![9.4, 6.7]), 0.5),
        ];
        let r = finite_differences(
            &first_order(),
            &grid,
            &smooth_field(&shape),
            &[Source::Point(vec![3.3, 4.6])],
            &weights,
        );
        eprintln!("2D order 1: {r:?}");
        assert!(r.max_rel <= 1e-4, "{r:?}");
        assert!(r.skipped * 20 <= r.checked, "{r:?}");
    }

    #[test]
    fn matches_finite_differences_in_2d_order_2() {
        let shape = [14, 14];
        let grid = Grid::unit(&shape).unwrap();
        let weights = [
            (Probe::Cell(vec![13, 2]), 1.0),
            (Probe::Cell(vec![12, 13]), 0.7),
            (Probe::Point(vec![9.4, 6.7]), 0.5),
        ];
        let r = finite_differences(
            &second_order(),
            &grid,
            &smooth_field(&shape),
            &[Source::Point(vec![3.3, 4.6])],
            &weights,
        );
        eprintln!("2D order 2: {r:?}");
        assert!(r.max_rel <= 1e-4, "{r:?}");
        assert!(r.skipped * 10 <= r.checked, "{r:?}");
        // Most updated cells use a second-order term.
        assert!(r.second * 2 > grid.len(), "{r:?}");
    }

    #[test]
    fn matches_finite_differences_in_3d_order_1_and_2() {
        let shape = [6, 7, 6];
        let grid = Grid::unit(&shape).unwrap();
        let weights = [
            (Probe::Cell(vec![5, 6, 5]), 1.0),
            (Probe::Cell(vec![0, 6, 1]), 0.8),
            (Probe::Point(vec![4.5, 1.2, 3.4]), 0.5),
        ];
        for (opts, name) in [(first_order(), "order 1"), (second_order(), "order 2")] {
            let r = finite_differences(
                &opts,
                &grid,
                &smooth_field(&shape),
                &[Source::Point(vec![1.2, 2.7, 2.4])],
                &weights,
            );
            eprintln!("3D {name}: {r:?}");
            assert!(r.max_rel <= 1e-4, "{name}: {r:?}");
            // The corners' fallback gives some values: it is checked too.
            assert!(r.fallback > 0, "{name}: {r:?}");
            assert!(r.skipped * 10 <= r.checked, "{name}: {r:?}");
        }
    }

    /// A random symmetric perturbation of every cell at once: the
    /// directional derivative is `Σ grad · δm` over the components, each
    /// off-diagonal component counted once.
    #[test]
    fn a_directional_derivative_is_the_sum_over_the_components() {
        for shape in [vec![16, 13], vec![6, 6, 7]] {
            let grid = Grid::unit(&shape).unwrap();
            let m = smooth_field(&shape);
            let nc = components(shape.len());
            let dm: Vec<f64> = (0..m.len())
                .map(|i| {
                    let mut z = (i as u64 + 7).wrapping_mul(0x9e37_79b9_7f4a_7c15);
                    z ^= z >> 29;
                    z = z.wrapping_mul(0xbf58_476d_1ce4_e5b9);
                    z ^= z >> 32;
                    // Larger off-diagonal parts, so that they matter.
                    let off = !matches!((nc, i % nc), (3, 0 | 2) | (6, 0 | 3 | 5));
                    (if off { 2.0 } else { 1.0 }) * ((z % 2001) as f64 / 1000.0 - 1.0)
                })
                .collect();
            let probe = if shape.len() == 2 {
                Probe::Point(vec![14.3, 11.6])
            } else {
                Probe::Cell(vec![5, 5, 6])
            };
            let weights = [(probe, 1.0)];
            let sources = [Source::Point(vec![1.5, 2.0, 1.0][..shape.len()].to_vec())];
            for opts in [first_order(), second_order()] {
                let base = problem_of(&grid, m.clone(), &sources);
                let out = solve(&base, &opts, &Control::new()).unwrap();
                let g = metric_gradient(&base, &opts, &out, &weights, &Control::new()).unwrap();
                let predicted: f64 = g.iter().zip(&dm).map(|(g, d)| g * d).sum();
                let s0 = structure(&base, &opts, &out);
                let eps = 1e-7;
                let mut j = [0.0; 2];
                for (slot, sign) in [1.0, -1.0].into_iter().enumerate() {
                    let mp: Vec<f64> = m.iter().zip(&dm).map(|(m, d)| m + sign * eps * d).collect();
                    let p = problem_of(&grid, mp, &sources);
                    let o = solve(&p, &opts, &Control::new()).unwrap();
                    assert!(
                        structure(&p, &opts, &o) == s0,
                        "{shape:?}: the structure changed"
                    );
                    j[slot] = objective(&grid, &o, &weights);
                }
                let fd = (j[0] - j[1]) / (2.0 * eps);
                // Counting an off-diagonal component twice would be off by
                // the off-diagonal part, which is not small here.
                let off_part: f64 = g
                    .iter()
                    .zip(&dm)
                    .enumerate()
                    .filter(|(i, _)| !matches!((nc, i % nc), (3, 0 | 2) | (6, 0 | 3 | 5)))
                    .map(|(_, (g, d))| g * d)
                    .sum();
                eprintln!(
                    "{shape:?} {:?}: δJ {fd:.9e}, Σ grad·δm {predicted:.9e} (off-diagonal part {off_part:.3e})",
                    opts.order
                );
                assert!(off_part.abs() > 1e-2 * fd.abs().max(1e-3));
                assert!(
                    (fd - predicted).abs() <= 1e-5 * fd.abs().max(1e-3),
                    "{fd} {predicted}"
                );
            }
        }
    }

    #[test]
    fn the_adjoint_of_a_sum_is_the_sum_of_the_adjoints() {
        let shape = [20, 18];
        let grid = Grid::unit(&shape).unwrap();
        let sources = [
            Source::Point(vec![5.3, 7.6]),
            Source::Cells {
                cells: vec![vec![16, 15], vec![16, 16]],
                values: Some(vec![0.5, 0.25]),
            },
        ];
        let problem = problem_of(&grid, smooth_field(&shape), &sources);
        let weights = [
            (Probe::Cell(vec![19, 3]), 1.0),
            (Probe::Cell(vec![0, 17]), 0.7),
            (Probe::Cell(vec![3, 16]), -0.4),
            (Probe::Point(vec![14.4, 9.7]), 2.5),
        ];
        for opts in [first_order(), second_order()] {
            let out = solve(&problem, &opts, &Control::new()).unwrap();
            let all = metric_gradient(&problem, &opts, &out, &weights, &Control::new()).unwrap();
            let mut sum = ArrayD::<f64>::zeros(all.raw_dim());
            for (probe, w) in &weights {
                let g =
                    metric_distance_gradient(&problem, &opts, &out, probe.clone(), &Control::new())
                        .unwrap();
                sum.scaled_add(*w, &g);
            }
            let scale = all.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            assert!(scale > 1e-2);
            let worst = all
                .iter()
                .zip(sum.iter())
                .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
            assert!(worst <= 1e-10 * scale, "{worst} against {scale}");
        }
    }

    /// Euler's identity for `U(tM) = √t U(M)`: `Σ m · ∂U/∂m = U/2`.
    fn assert_euler(problem: &TensorProblem, opts: &TensorOptions, probes: &[Probe]) {
        let out = solve(problem, opts, &Control::new()).unwrap();
        let m = problem.metric.to_components(problem.grid.len());
        for probe in probes {
            let g = metric_distance_gradient(problem, opts, &out, probe.clone(), &Control::new())
                .unwrap();
            let euler: f64 = g.iter().zip(&m).map(|(g, m)| g * m).sum();
            let u = objective(&problem.grid, &out, &[(probe.clone(), 1.0)]);
            assert!(
                (euler - 0.5 * u).abs() <= 1e-12 * u.abs().max(1.0),
                "{probe:?} {:?}: Σ m ∂U/∂m = {euler}, U/2 = {}",
                opts.order,
                0.5 * u
            );
        }
    }

    #[test]
    fn random_fields_satisfy_euler_identity_in_2d_and_3d() {
        let shape = [22, 17];
        let grid = Grid::new(&shape, &[0.8, 1.25]).unwrap();
        let problem = problem_of(
            &grid,
            smooth_field(&shape),
            &[
                Source::Point(vec![4.6, 3.3]),
                Source::Cells {
                    cells: vec![vec![18, 14]],
                    values: None,
                },
            ],
        );
        let probes = [
            Probe::Cell(vec![21, 0]),
            Probe::Cell(vec![11, 9]),
            Probe::Cell(vec![0, 16]),
            Probe::Point(vec![0.5, 13.0]),
        ];
        for opts in [first_order(), second_order()] {
            assert_euler(&problem, &opts, &probes);
        }
        let shape = [8, 9, 7];
        let problem = problem_of(
            &Grid::unit(&shape).unwrap(),
            smooth_field(&shape),
            &[Source::Point(vec![3.2, 4.7, 2.4])],
        );
        let probes = [Probe::Cell(vec![7, 8, 6]), Probe::Cell(vec![0, 0, 6])];
        for opts in [first_order(), second_order()] {
            assert_euler(&problem, &opts, &probes);
        }
    }

    #[test]
    fn a_seed_has_the_gradient_of_its_closed_form() {
        // A seed of a point source p holds ‖x − p‖ in the metric of the cell
        // nearest to p: its gradient is (Hz)(Hz)ᵀ / (2U) there, the
        // off-diagonal component counted once (2 × the matrix entry).
        let grid = Grid::new(&[9, 9], &[0.5, 2.0]).unwrap();
        let m = [3.0, 0.7, 0.4];
        let metric = TensorField::constant(&grid, &m).unwrap();
        let problem = TensorProblem {
            grid: grid.clone(),
            metric,
            sources: vec![Source::Point(vec![4.2, 3.9])],
        };
        let opts = first_order();
        let out = solve(&problem, &opts, &Control::new()).unwrap();
        let g = metric_distance_gradient(
            &problem,
            &opts,
            &out,
            Probe::Cell(vec![5, 4]),
            &Control::new(),
        )
        .unwrap();
        let z = [(5.0 - 4.2) * 0.5, (4.0 - 3.9) * 2.0];
        let u = (m[0] * z[0] * z[0] + 2.0 * m[1] * z[0] * z[1] + m[2] * z[1] * z[1]).sqrt();
        assert!((out.output.distance[[5, 4]] - u).abs() < 1e-14);
        let expected = [
            z[0] * z[0] / (2.0 * u),
            z[0] * z[1] / u,
            z[1] * z[1] / (2.0 * u),
        ];
        for i in 0..9 {
            for j in 0..9 {
                for c in 0..3 {
                    let e = if (i, j) == (4, 4) { expected[c] } else { 0.0 };
                    assert!(
                        (g[[i, j, c]] - e).abs() < 1e-14,
                        "({i}, {j}) component {c}: {} instead of {e}",
                        g[[i, j, c]]
                    );
                }
            }
        }
    }

    #[test]
    fn a_constant_diagonal_metric_along_an_axis_has_its_closed_form() {
        // M = diag(m0, m1): the canonical superbase is obtuse, the offset
        // (1, −1) has weight 0 and (0, 1) has ρ = D̃01 + D̃11 = 1/m1. From the
        // cell source (0, 0) along row 0 each update is the one-offset step
        // U(0, j) = U(0, j − 1) + 1/√ρ, so U(0, j) = j √m1, and every cell
        // 1..=j of the row carries ∂/∂m0 = 0, ∂/∂m1 = 1/(2√m1).
        // In m01, U has a kink at 0 (for either sign the weight of (0, ±1)
        // is D̃11 − |m01|/det): the adjoint gives the canonical superbase's
        // piece, ∂ρ/∂m01 = −1/det, i.e. √m1/(2 m0) per cell.
        let grid = Grid::unit(&[6, 10]).unwrap();
        let m = [9.0, 0.0, 2.25];
        let metric = TensorField::constant(&grid, &m).unwrap();
        let problem = TensorProblem {
            grid: grid.clone(),
            metric,
            sources: vec![Source::Cells {
                cells: vec![vec![0, 0]],
                values: None,
            }],
        };
        for opts in [first_order(), second_order()] {
            let out = solve(&problem, &opts, &Control::new()).unwrap();
            let j = 7;
            let u = out.output.distance[[0, j]];
            assert!((u - 1.5 * j as f64).abs() < 1e-12, "{u}");
            let g = metric_distance_gradient(
                &problem,
                &opts,
                &out,
                Probe::Cell(vec![0, j]),
                &Control::new(),
            )
            .unwrap();
            if opts.order == Order::First {
                let per_cell = [0.0, 1.5 / 18.0, 1.0 / 3.0];
                for col in 0..10 {
                    for c in 0..3 {
                        let e = if (1..=j).contains(&col) {
                            per_cell[c]
                        } else {
                            0.0
                        };
                        let got = g[[0, col, c]];
                        assert!(
                            (got - e).abs() < 1e-12,
                            "(0, {col}) component {c}: {got} instead of {e}"
                        );
                    }
                }
            }
            // Order 2 differs cell by cell (the second-order differences
            // spread it) but not in total: dU/dm1 = j/(2√m1), dU/dm0 = 0.
            let total = |c: usize| g.slice(ndarray::s![0, .., c]).sum();
            assert!(total(0).abs() < 1e-12, "{}", total(0));
            assert!((total(2) - j as f64 / 3.0).abs() < 1e-12, "{}", total(2));
            assert!(g.slice(ndarray::s![1.., .., ..]).iter().all(|&v| v == 0.0));
        }
    }

    #[test]
    fn an_early_stop_keeps_the_gradient_of_the_cells_it_froze() {
        let shape = [16, 16];
        let grid = Grid::unit(&shape).unwrap();
        let problem = problem_of(
            &grid,
            smooth_field(&shape),
            &[Source::Point(vec![3.5, 4.0])],
        );
        let probe = Probe::Cell(vec![8, 8]);
        for opts in [first_order(), second_order()] {
            let full = solve(&problem, &opts, &Control::new()).unwrap();
            let g =
                metric_distance_gradient(&problem, &opts, &full, probe.clone(), &Control::new())
                    .unwrap();
            let early_opts = opts.clone().with_stop(StopRules {
                targets: vec![vec![8.0, 8.0]],
                ..StopRules::default()
            });
            let early = solve(&problem, &early_opts, &Control::new()).unwrap();
            assert!(early.output.frozen < grid.len());
            let ge = metric_distance_gradient(
                &problem,
                &early_opts,
                &early,
                probe.clone(),
                &Control::new(),
            )
            .unwrap();
            assert!(g.iter().zip(ge.iter()).all(|(a, b)| (a - b).abs() <= 1e-13));
            let out = metric_distance_gradient(
                &problem,
                &early_opts,
                &early,
                Probe::Cell(vec![15, 15]),
                &Control::new(),
            );
            assert!(
                matches!(
                    out,
                    Err(TensorSolveError::Solve(EikonalError::Option {
                        field: "weights",
                        ..
                    }))
                ),
                "{out:?}"
            );
        }
    }

    #[test]
    fn other_schemes_and_foreign_outputs_are_refused_by_name() {
        let grid = Grid::unit(&[8, 8]).unwrap();
        let problem = problem_of(
            &grid,
            smooth_field(&[8, 8]),
            &[Source::Point(vec![1.0, 1.0])],
        );
        let out = solve(&problem, &first_order(), &Control::new()).unwrap();
        let probe = [(Probe::Cell(vec![7, 7]), 1.0)];
        let cases = [
            (TensorOptions::DEFAULT, "factoring"),
            (TensorOptions::DEFAULT.with_order(Order::First), "factoring"),
            (TensorOptions::DEFAULT.with_factoring(false), "record_order"),
        ];
        for (opts, name) in cases {
            match metric_gradient(&problem, &opts, &out, &probe, &Control::new()) {
                Err(TensorSolveError::Solve(EikonalError::Option { field, reason })) => {
                    assert_eq!(field, name);
                    assert!(reason.contains("order 1"), "{reason}");
                }
                other => panic!("{name}: {other:?}"),
            }
        }
        // The output of another metric.
        let other = TensorProblem {
            grid: grid.clone(),
            metric: TensorField::constant(&grid, &[1.0, 0.0, 1.0]).unwrap(),
            sources: problem.sources.clone(),
        };
        let foreign = solve(&other, &first_order(), &Control::new()).unwrap();
        let r = metric_gradient(&problem, &first_order(), &foreign, &probe, &Control::new());
        assert!(
            matches!(
                r,
                Err(TensorSolveError::Solve(EikonalError::Option {
                    field: "output",
                    ..
                }))
            ),
            "{r:?}"
        );
        // A probe outside the grid, a weight that is not finite.
        for weights in [
            [(Probe::Cell(vec![8, 0]), 1.0)],
            [(Probe::Cell(vec![1, 1]), f64::NAN)],
        ] {
            assert!(matches!(
                metric_gradient(&problem, &first_order(), &out, &weights, &Control::new()),
                Err(TensorSolveError::Solve(EikonalError::Option {
                    field: "weights",
                    ..
                }))
            ));
        }
    }

    #[test]
    fn walls_get_zero() {
        let shape = [12, 12];
        let grid = Grid::unit(&shape).unwrap();
        let mut walls = vec![false; grid.len()];
        // A wall across row 6 but for a gap of three cells.
        for j in 0..12 {
            if !(7..=9).contains(&j) {
                walls[6 * 12 + j] = true;
            }
        }
        let metric = TensorField::from_components(&grid, smooth_field(&shape))
            .unwrap()
            .with_walls(&grid, walls.clone())
            .unwrap();
        let problem = TensorProblem {
            grid: grid.clone(),
            metric,
            sources: vec![Source::Point(vec![2.0, 2.0])],
        };
        for opts in [first_order(), second_order()] {
            let out = solve(&problem, &opts, &Control::new()).unwrap();
            let g = metric_distance_gradient(
                &problem,
                &opts,
                &out,
                Probe::Cell(vec![11, 3]),
                &Control::new(),
            )
            .unwrap();
            for (i, &w) in walls.iter().enumerate() {
                if w {
                    let [_, a, b] = grid.unravel(i);
                    assert!((0..3).all(|c| g[[a, b, c]] == 0.0), "wall cell {i}");
                }
            }
            // The way goes through the gap.
            assert!((7..=9).any(|j| (0..3).any(|c| g[[6, j, c]].abs() > 1e-3)));
            assert_euler(&problem, &opts, &[Probe::Cell(vec![11, 3])]);
        }
    }

    #[test]
    fn a_raised_flag_stops_it() {
        let grid = Grid::unit(&[8, 8]).unwrap();
        let problem = problem_of(
            &grid,
            smooth_field(&[8, 8]),
            &[Source::Point(vec![1.0, 1.0])],
        );
        let opts = first_order();
        let out = solve(&problem, &opts, &Control::new()).unwrap();
        let flag = AtomicBool::new(true);
        let r = metric_gradient(
            &problem,
            &opts,
            &out,
            &[(Probe::Cell(vec![7, 7]), 1.0)],
            &Control::new().with_cancel(&flag),
        );
        assert!(
            matches!(r, Err(TensorSolveError::Solve(EikonalError::Cancelled))),
            "{r:?}"
        );
    }

    /// The adjoint against one forward solve on 1024² (release:
    /// `cargo test --release --lib numerics::anisotropic::gradient -- --ignored --nocapture`).
    #[test]
    #[ignore]
    fn time_against_one_solve() {
        let shape = [1024, 1024];
        let grid = Grid::unit(&shape).unwrap();
        let problem = problem_of(
            &grid,
            smooth_field(&shape),
            &[Source::Point(vec![511.3, 200.7])],
        );
        let weights: Vec<(Probe, f64)> = (0..100)
            .map(|m| (Probe::Cell(vec![(m * 97) % 1024, (m * 389) % 1024]), 1.0))
            .collect();
        for (opts, name) in [
            (first_order(), "order 1"),
            (
                {
                    let mut o = first_order();
                    o.record_order = true;
                    o
                },
                "order 1, recorded order",
            ),
            (second_order(), "order 2, recorded order"),
        ] {
            let t = std::time::Instant::now();
            let out = solve(&problem, &opts, &Control::new()).unwrap();
            let forward = t.elapsed().as_secs_f64();
            let t = std::time::Instant::now();
            let g = metric_gradient(&problem, &opts, &out, &weights, &Control::new()).unwrap();
            let adjoint = t.elapsed().as_secs_f64();
            eprintln!(
                "1024², {name}: solve {forward:.3} s, adjoint {adjoint:.3} s (ratio {:.2})",
                adjoint / forward
            );
            assert!(g.iter().any(|v| *v != 0.0));
        }
    }
}
