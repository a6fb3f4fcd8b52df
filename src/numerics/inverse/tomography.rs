//! First-arrival travel-time tomography: the slowness (cost) map `W` of a
//! 2D or 3D grid recovered from travel times measured between point
//! sources and point receivers.
//!
//! # The problem
//!
//! With `U_s` the fast-marching distance from source `s` for the cost `W`
//! (first or second order, unfactored: the scheme that
//! [`cost_gradient`] differentiates) and `T_sr` the measured time from
//! source `s` to receiver `y_r`, minimise over `W_min ≤ W ≤ W_max`
//!
//! ```text
//! E(W) = D(W) + R(W),   D(W) = ½ Σ_s Σ_r (U_s(y_r) − T_sr)²,
//! R(W) = (α/2) Σ_k Σ_x ((W_{x+e_k} − W_x) / h_k)²
//! ```
//!
//! (`U_s(y_r)` the multilinear read of [`super::interpolate`]; `R` the
//! smoothness term over the pairs of neighbours along each axis `k` of
//! spacing `h_k`, without the cell volume, so `α` is per pair of cells).
//!
//! # The gradient
//!
//! `∂D/∂W = Σ_s ∂J_s/∂W` with `J_s = Σ_r (U_s(y_r) − T_sr) U_s(y_r)`, the
//! residuals held fixed: one forward solve and one adjoint sweep
//! ([`cost_gradient`] with the weights `w_r = U_s(y_r) − T_sr` at the
//! probes `y_r`) per source. Sources are independent: they run in
//! parallel on the caller's rayon pool (the solver pool from an operation).
//! `∂R/∂W_x = α Σ_k Σ_{neighbours y of x along k} (W_x − W_y) / h_k²`.
//!
//! # The start
//!
//! The best constant map. Unfactored fast marching from point sources is
//! homogeneous of degree 1 in `W` (the seeds hold `W(q)|x − p|`), so for
//! `W ≡ c`, `U_s(y_r) = c L_sr` with `L_sr` the solver's distance for
//! `W ≡ 1` (the discrete straight-line length) and the least-squares
//! constant is closed-form: `c* = Σ L_sr T_sr / Σ L_sr²`, clamped to the
//! bounds. Its misfit `D(c*)` is the baseline the recovered map is judged
//! against.
//!
//! # The descent
//!
//! `W` is kept in the box by projection (no change of variables): the
//! iteration is the spectral projected gradient (Birgin, Martínez, Raydan),
//! `W⁺ = P(W − t ∇E)` with the Barzilai–Borwein step
//! `t = ⟨s, s⟩ / ⟨s, y⟩` (`s`, `y` the last changes of `W` and `∇E`; the
//! first step moves `W` by at most 5 % of `c*`), and a monotone backtracking
//! line search: `t` is halved until both the Armijo condition
//! `E(W⁺) ≤ E(W) + 10⁻⁴ ⟨∇E, W⁺ − W⟩` and `D(W⁺) ≤ D(W)` hold. The second
//! condition makes the travel-time misfit itself non-increasing, not only
//! `E`; with `α = 0` they coincide. A step is evaluated by the forward
//! solves only; the adjoint sweeps run once the step is accepted.
//!
//! It stops after `max_iterations`, when an accepted step lowers `E` by less
//! than `tolerance × E` ([`TomographyStop::Tolerance`]), when the projected
//! step is zero ([`TomographyStop::Stationary`]) or when 30 halvings find
//! no decrease ([`TomographyStop::LineSearch`]); a raised cancel flag ends
//! it with [`TomographyError::Cancelled`].
//!
//! `U_s` is a piecewise smooth function of `W` (see [`cost_gradient`]), so
//! `E` is too: the line search is what keeps the descent monotone across
//! the switches of the upwind structure.

use std::borrow::Cow;

use rayon::prelude::*;

use super::{adjoint_options, interpolate};
use crate::numerics::control::Control;
use crate::numerics::eikonal::{cost_gradient, Probe};
use crate::numerics::grid::Grid;
use crate::numerics::metric::{CostValues, Interpretation, IsotropicCost};
use crate::numerics::{solve, EikonalError, EikonalOutput, EikonalProblem, Order, Source};

/// Armijo's sufficient-decrease constant.
const ARMIJO: f64 = 1e-4;
/// Halvings of the step before the line search gives up.
const MAX_HALVINGS: usize = 30;
/// Sources whose gradients are held at once (then summed in order).
const GRADIENT_BATCH: usize = 16;

/// Why a tomography was refused or interrupted.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TomographyError {
    /// An input is malformed; `field` is `sources`, `receivers`, `times`,
    /// `alpha`, `bounds`, `max_iterations` or `tolerance`.
    #[error("{field}: {reason}")]
    Input {
        /// The input at fault.
        field: &'static str,
        /// Why it is refused.
        reason: String,
    },
    /// A forward solve or an adjoint sweep failed.
    #[error(transparent)]
    Eikonal(EikonalError),
    /// The caller raised the cancel flag.
    #[error("cancelled")]
    Cancelled,
}

impl From<EikonalError> for TomographyError {
    fn from(e: EikonalError) -> Self {
        match e {
            EikonalError::Cancelled => TomographyError::Cancelled,
            other => TomographyError::Eikonal(other),
        }
    }
}

/// The data: a grid, the source and receiver points (index coordinates,
/// axis 0 first) and the measured times, `times[s * receivers.len() + r]`
/// from source `s` to receiver `r` (physical units: the time of a path is
/// `∫ W ds` with lengths in the units of the spacing).
#[derive(Debug, Clone)]
pub struct TomographyProblem<'a> {
    /// Shape and spacing.
    pub grid: Grid,
    /// The source points.
    pub sources: &'a [Vec<f64>],
    /// The receiver points.
    pub receivers: &'a [Vec<f64>],
    /// The measured times, row-major (one row per source).
    pub times: &'a [f64],
}

/// Options, with the defaults of [`TomographyOptions::default`].
#[derive(Debug, Clone, PartialEq)]
pub struct TomographyOptions {
    /// Weight `α ≥ 0` of the smoothness term. Default: 0.
    pub alpha: f64,
    /// Lower bound `W_min > 0`. Default: `c*/10`.
    pub min_cost: Option<f64>,
    /// Upper bound `W_max`. Default: `10 c*`.
    pub max_cost: Option<f64>,
    /// Largest number of accepted steps. Default: 50.
    pub max_iterations: usize,
    /// Stop when a step lowers `E` by less than `tolerance × E`. Default: 1e-6.
    pub tolerance: f64,
    /// Order of the fast marching. Default: first.
    pub order: Order,
}

impl Default for TomographyOptions {
    fn default() -> Self {
        Self {
            alpha: 0.0,
            min_cost: None,
            max_cost: None,
            max_iterations: 50,
            tolerance: 1e-6,
            order: Order::First,
        }
    }
}

/// How the descent ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TomographyStop {
    /// `max_iterations` steps were taken.
    MaxIterations,
    /// A step lowered `E` by less than `tolerance × E`.
    Tolerance,
    /// The projected gradient step is zero (a constrained stationary point).
    Stationary,
    /// No step along the projected gradient lowers the objective.
    LineSearch,
}

impl TomographyStop {
    /// The stop as a word (`max_iterations`, `tolerance`, `stationary`, `line_search`).
    pub fn as_str(&self) -> &'static str {
        match self {
            TomographyStop::MaxIterations => "max_iterations",
            TomographyStop::Tolerance => "tolerance",
            TomographyStop::Stationary => "stationary",
            TomographyStop::LineSearch => "line_search",
        }
    }
}

/// One accepted iterate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Iterate {
    /// The travel-time misfit `D = ½ Σ (U − T)²`.
    pub misfit: f64,
    /// The objective `E = D + R`.
    pub objective: f64,
    /// The step `t` that was accepted (0 for the start).
    pub step: f64,
    /// Halvings of the step before it was accepted.
    pub halvings: usize,
}

/// The recovered map and the history of the descent.
#[derive(Debug, Clone, PartialEq)]
pub struct TomographyOutput {
    /// The recovered cost `W`, one value per cell (C order).
    pub cost: Vec<f64>,
    /// The best constant cost `c*` (the start).
    pub constant: f64,
    /// The bounds used.
    pub bounds: (f64, f64),
    /// The iterates: `history[0]` is the best constant map, then one per accepted step.
    pub history: Vec<Iterate>,
    /// The predicted times of the recovered map, row-major like the data.
    pub predicted: Vec<f64>,
    /// How the descent ended.
    pub stop: TomographyStop,
    /// Forward solves made (adjoint sweeps not counted).
    pub solves: usize,
}

impl TomographyOutput {
    /// The misfit `D` of the best constant map.
    pub fn constant_misfit(&self) -> f64 {
        self.history.first().map_or(f64::NAN, |i| i.misfit)
    }

    /// The misfit `D` of the recovered map.
    pub fn final_misfit(&self) -> f64 {
        self.history.last().map_or(f64::NAN, |i| i.misfit)
    }
}

/// Checks the data against the grid.
fn check(
    problem: &TomographyProblem<'_>,
    options: &TomographyOptions,
) -> Result<(), TomographyError> {
    let input = |field: &'static str, reason: String| Err(TomographyError::Input { field, reason });
    let grid = &problem.grid;
    for (field, points) in [
        ("sources", problem.sources),
        ("receivers", problem.receivers),
    ] {
        if points.is_empty() {
            return input(field, "give at least one point".into());
        }
        for (k, p) in points.iter().enumerate() {
            if p.len() != grid.ndim() {
                return input(
                    field,
                    format!(
                        "[{k}] has {} coordinates, the grid {} axes",
                        p.len(),
                        grid.ndim()
                    ),
                );
            }
            if super::corners(grid, p).is_none() {
                return input(
                    field,
                    format!(
                        "[{k}] {p:?} is outside the grid of shape {:?}",
                        grid.shape()
                    ),
                );
            }
        }
    }
    let (ns, nr) = (problem.sources.len(), problem.receivers.len());
    if problem.times.len() != ns * nr {
        return input(
            "times",
            format!(
                "{} times for {ns} sources × {nr} receivers",
                problem.times.len()
            ),
        );
    }
    if let Some(i) = problem
        .times
        .iter()
        .position(|t| !(t.is_finite() && *t >= 0.0))
    {
        return input(
            "times",
            format!(
                "[{}][{}] = {} must be finite and >= 0",
                i / nr,
                i % nr,
                problem.times[i]
            ),
        );
    }
    if problem.times.iter().all(|&t| t == 0.0) {
        return input(
            "times",
            "every time is 0: there is no slowness to recover".into(),
        );
    }
    if !(options.alpha.is_finite() && options.alpha >= 0.0) {
        return input(
            "alpha",
            format!("{} must be finite and >= 0", options.alpha),
        );
    }
    if !(options.tolerance.is_finite() && options.tolerance >= 0.0) {
        return input(
            "tolerance",
            format!("{} must be finite and >= 0", options.tolerance),
        );
    }
    for b in [options.min_cost, options.max_cost].into_iter().flatten() {
        if !(b.is_finite() && b > 0.0) {
            return input("bounds", format!("{b} must be finite and > 0"));
        }
    }
    if let (Some(lo), Some(hi)) = (options.min_cost, options.max_cost) {
        if lo > hi {
            return input("bounds", format!("min_cost {lo} > max_cost {hi}"));
        }
    }
    Ok(())
}

/// The forward model of one cost map: per source, its solve and its
/// predicted times.
struct Forward {
    outputs: Vec<EikonalOutput>,
    /// `predicted[s * nr + r]`.
    predicted: Vec<f64>,
    misfit: f64,
    objective: f64,
}

struct Model<'a> {
    problem: &'a TomographyProblem<'a>,
    alpha: f64,
    order: Order,
}

impl Model<'_> {
    fn eikonal<'w>(
        &self,
        w: &'w [f64],
        source: usize,
    ) -> Result<EikonalProblem<'w>, TomographyError> {
        let grid = &self.problem.grid;
        let cost = IsotropicCost::new(
            grid,
            CostValues::F64(Cow::Borrowed(w)),
            Interpretation::Cost,
            None,
        )
        .map_err(|e| TomographyError::Eikonal(e.into()))?;
        Ok(EikonalProblem {
            grid: grid.clone(),
            cost,
            sources: vec![Source::Point(self.problem.sources[source].clone())],
        })
    }

    /// The solves of every source for `w`, the predicted times and `D`, `E`.
    fn forward(&self, w: &[f64], control: &Control<'_>) -> Result<Forward, TomographyError> {
        let p = self.problem;
        let nr = p.receivers.len();
        let options = adjoint_options(self.order);
        let inner = control.cancel_only();
        let per_source: Vec<(EikonalOutput, Vec<f64>)> = (0..p.sources.len())
            .into_par_iter()
            .map(|s| {
                let problem = self.eikonal(w, s)?;
                let out = solve(&problem, &options, &inner)?;
                let u = out
                    .distance
                    .as_slice()
                    .map(Cow::Borrowed)
                    .unwrap_or_else(|| Cow::Owned(out.distance.iter().copied().collect()));
                let times = p
                    .receivers
                    .iter()
                    .map(|y| interpolate(&p.grid, &u, y).unwrap_or(f64::INFINITY))
                    .collect();
                Ok((out, times))
            })
            .collect::<Result<_, TomographyError>>()?;
        let mut predicted = Vec::with_capacity(p.times.len());
        let mut outputs = Vec::with_capacity(per_source.len());
        for (out, times) in per_source {
            outputs.push(out);
            predicted.extend(times);
        }
        let misfit = 0.5
            * predicted
                .iter()
                .zip(p.times)
                .map(|(u, t)| (u - t) * (u - t))
                .sum::<f64>();
        debug_assert_eq!(predicted.len(), p.sources.len() * nr);
        let objective = misfit + smoothness(&p.grid, w, self.alpha, None);
        Ok(Forward {
            outputs,
            predicted,
            misfit,
            objective,
        })
    }

    /// `∇E` at `w`, from the solves of `forward` (the adjoint sweeps).
    fn gradient(
        &self,
        w: &[f64],
        forward: &Forward,
        control: &Control<'_>,
    ) -> Result<Vec<f64>, TomographyError> {
        let p = self.problem;
        let nr = p.receivers.len();
        let options = adjoint_options(self.order);
        let inner = control.cancel_only();
        let n = p.grid.len();
        // Sources in parallel by batches, summed in source order: the
        // result does not depend on how the pool split the work.
        let mut g = vec![0.0; n];
        let all: Vec<usize> = (0..p.sources.len()).collect();
        for batch in all.chunks(GRADIENT_BATCH) {
            let parts = batch
                .par_iter()
                .map(|&s| {
                    let problem = self.eikonal(w, s)?;
                    let weights: Vec<(Probe, f64)> = p
                        .receivers
                        .iter()
                        .enumerate()
                        .map(|(r, y)| {
                            let k = s * nr + r;
                            (Probe::Point(y.clone()), forward.predicted[k] - p.times[k])
                        })
                        .collect();
                    cost_gradient(&problem, &options, &forward.outputs[s], &weights, &inner)
                        .map_err(TomographyError::from)
                })
                .collect::<Result<Vec<_>, TomographyError>>()?;
            for part in parts {
                g.iter_mut().zip(part.iter()).for_each(|(x, y)| *x += y);
            }
        }
        smoothness(&p.grid, w, self.alpha, Some(g.as_mut_slice()));
        Ok(g)
    }
}

/// `R(W) = (α/2) Σ_k Σ_x ((W_{x+e_k} − W_x)/h_k)²`; adds `∂R/∂W` to `grad` if given.
fn smoothness(grid: &Grid, w: &[f64], alpha: f64, mut grad: Option<&mut [f64]>) -> f64 {
    if alpha == 0.0 {
        return 0.0;
    }
    let shape = grid.shape3();
    let strides = grid.strides3();
    let h = grid.spacing3();
    let mut r = 0.0;
    for (i, &wi) in w.iter().enumerate() {
        let idx = grid.unravel(i);
        for k in 0..3 {
            if idx[k] + 1 < shape[k] {
                let j = i + strides[k];
                let c = 1.0 / (h[k] * h[k]);
                let d = w[j] - wi;
                r += c * d * d;
                if let Some(g) = grad.as_deref_mut() {
                    g[j] += alpha * c * d;
                    g[i] -= alpha * c * d;
                }
            }
        }
    }
    0.5 * alpha * r
}

/// Recovers the cost map from the travel times: the spectral projected
/// gradient descent of the module documentation, from the best constant
/// map.
///
/// Polls `control` in every solve and between the steps; reports the
/// fraction of `max_iterations` done.
///
/// # Examples
/// ```
/// use geodex::numerics::{Control, Grid};
/// use geodex::numerics::inverse::tomography::{tomography, TomographyOptions, TomographyProblem};
/// // A constant slowness 2: the best constant map is the answer.
/// let sources = vec![vec![0.0, 0.0], vec![0.0, 9.0]];
/// let receivers = vec![vec![9.0, 0.0], vec![9.0, 9.0]];
/// let d = 9.0 * 2f64.sqrt();
/// let problem = TomographyProblem {
///     grid: Grid::unit(&[10, 10])?,
///     sources: &sources,
///     receivers: &receivers,
///     times: &[18.0, 2.0 * d, 2.0 * d, 18.0],
/// };
/// let out = tomography(&problem, &TomographyOptions::default(), &Control::new())?;
/// assert!(out.final_misfit() <= out.constant_misfit());
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn tomography(
    problem: &TomographyProblem<'_>,
    options: &TomographyOptions,
    control: &Control<'_>,
) -> Result<TomographyOutput, TomographyError> {
    check(problem, options)?;
    let n = problem.grid.len();
    let model = Model {
        problem,
        alpha: options.alpha,
        order: options.order,
    };
    // The best constant: U(c) = c U(1).
    let ones = vec![1.0; n];
    let unit = model.forward(&ones, control)?;
    let mut solves = problem.sources.len();
    let (lt, ll) = unit
        .predicted
        .iter()
        .zip(problem.times)
        .fold((0.0, 0.0), |(lt, ll), (l, t)| (lt + l * t, ll + l * l));
    if ll.is_nan() || ll <= 0.0 {
        return Err(TomographyError::Input {
            field: "receivers",
            reason: "every receiver is at its source: no path to measure".into(),
        });
    }
    let c_ls = lt / ll;
    let lo = options.min_cost.unwrap_or(c_ls / 10.0);
    let hi = options.max_cost.unwrap_or(c_ls * 10.0).max(lo);
    let constant = c_ls.clamp(lo, hi);
    let project = |v: f64| v.clamp(lo, hi);

    let mut w = vec![constant; n];
    let mut current = model.forward(&w, control)?;
    solves += problem.sources.len();
    let mut grad = model.gradient(&w, &current, control)?;
    let mut history = vec![Iterate {
        misfit: current.misfit,
        objective: current.objective,
        step: 0.0,
        halvings: 0,
    }];
    let gmax = grad.iter().fold(0.0f64, |m, g| m.max(g.abs()));
    let mut step = if gmax > 0.0 {
        0.05 * constant / gmax
    } else {
        0.0
    };
    let mut stop = TomographyStop::MaxIterations;
    control.report(0.0);
    for it in 0..options.max_iterations {
        if control.is_cancelled() {
            return Err(TomographyError::Cancelled);
        }
        if step == 0.0 {
            stop = TomographyStop::Stationary;
            break;
        }
        let mut accepted = None;
        let mut t = step;
        for halvings in 0..=MAX_HALVINGS {
            let trial: Vec<f64> = w
                .iter()
                .zip(&grad)
                .map(|(x, g)| project(x - t * g))
                .collect();
            let slope: f64 = trial
                .iter()
                .zip(&w)
                .zip(&grad)
                .map(|((a, b), g)| g * (a - b))
                .sum();
            if trial == w {
                break;
            }
            let f = model.forward(&trial, control)?;
            solves += problem.sources.len();
            if f.objective <= current.objective + ARMIJO * slope && f.misfit <= current.misfit {
                accepted = Some((trial, f, t, halvings));
                break;
            }
            t *= 0.5;
        }
        let Some((trial, f, t, halvings)) = accepted else {
            stop = if t == step {
                TomographyStop::Stationary
            } else {
                TomographyStop::LineSearch
            };
            break;
        };
        let g_new = model.gradient(&trial, &f, control)?;
        // Barzilai–Borwein: t = <s, s> / <s, y>.
        let (ss, sy) = trial.iter().zip(&w).zip(g_new.iter().zip(&grad)).fold(
            (0.0, 0.0),
            |(ss, sy), ((a, b), (ga, gb))| {
                let s = a - b;
                (ss + s * s, sy + s * (ga - gb))
            },
        );
        step = if sy > 0.0 && ss > 0.0 {
            ss / sy
        } else {
            2.0 * t
        };
        let decrease = current.objective - f.objective;
        history.push(Iterate {
            misfit: f.misfit,
            objective: f.objective,
            step: t,
            halvings,
        });
        let small = decrease <= options.tolerance * current.objective;
        w = trial;
        current = f;
        grad = g_new;
        control.report((it + 1) as f64 / options.max_iterations as f64);
        if small {
            stop = TomographyStop::Tolerance;
            break;
        }
    }
    control.report(1.0);
    Ok(TomographyOutput {
        cost: w,
        constant,
        bounds: (lo, hi),
        history,
        predicted: current.predicted,
        stop,
        solves,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::AtomicBool;

    /// `n` points evenly spaced along the boundary of the square
    /// `[a, b]²`, starting `offset` (a fraction of the spacing) along it.
    fn around_square(a: f64, b: f64, n: usize, offset: f64) -> Vec<Vec<f64>> {
        let side = b - a;
        let per = 4.0 * side;
        (0..n)
            .map(|i| {
                let s = (i as f64 + offset) * per / n as f64;
                let (k, t) = ((s / side).floor() as usize % 4, s % side);
                match k {
                    0 => vec![a, a + t],
                    1 => vec![a + t, b],
                    2 => vec![b, b - t],
                    _ => vec![b - t, a],
                }
            })
            .collect()
    }

    /// Background speed 1, a fast and a slow Gaussian anomaly; the cost is `1/F`.
    fn two_anomalies(n: usize) -> Vec<f64> {
        let s = n as f64 / 64.0;
        let bump = |i: usize, j: usize, ci: f64, cj: f64, r: f64| {
            let (di, dj) = (i as f64 - ci * s, j as f64 - cj * s);
            (-(di * di + dj * dj) / (2.0 * (r * s).powi(2))).exp()
        };
        (0..n * n)
            .map(|x| {
                let (i, j) = (x / n, x % n);
                let speed =
                    1.0 + 0.4 * bump(i, j, 22.0, 24.0, 7.0) - 0.3 * bump(i, j, 42.0, 40.0, 7.0);
                1.0 / speed
            })
            .collect()
    }

    /// The times of `w` by the same solver (the same resolution and scheme:
    /// the data are exact for the discrete model).
    fn synthetic_times(
        grid: &Grid,
        w: &[f64],
        sources: &[Vec<f64>],
        receivers: &[Vec<f64>],
    ) -> Vec<f64> {
        let problem = TomographyProblem {
            grid: grid.clone(),
            sources,
            receivers,
            times: &[],
        };
        let model = Model {
            problem: &problem,
            alpha: 0.0,
            order: Order::First,
        };
        model.forward(w, &Control::new()).unwrap().predicted
    }

    fn relative_error(w: &[f64], truth: &[f64]) -> f64 {
        let num: f64 = w.iter().zip(truth).map(|(a, b)| (a - b) * (a - b)).sum();
        let den: f64 = truth.iter().map(|b| b * b).sum();
        (num / den).sqrt()
    }

    #[test]
    fn recovers_two_anomalies_better_than_the_best_constant() {
        let n = 64;
        let grid = Grid::unit(&[n, n]).unwrap();
        let truth = two_anomalies(n);
        let sources = around_square(0.0, (n - 1) as f64, 32, 0.0);
        let receivers = around_square(0.0, (n - 1) as f64, 32, 0.5);
        let times = synthetic_times(&grid, &truth, &sources, &receivers);
        let problem = TomographyProblem {
            grid,
            sources: &sources,
            receivers: &receivers,
            times: &times,
        };
        let options = TomographyOptions {
            alpha: 0.5,
            max_iterations: 40,
            tolerance: 0.0,
            ..TomographyOptions::default()
        };
        let out = tomography(&problem, &options, &Control::new()).unwrap();
        let constant = vec![out.constant; n * n];
        let e0 = relative_error(&constant, &truth);
        let e = relative_error(&out.cost, &truth);
        eprintln!(
            "constant {:.4}: error {e0:.4}; recovered: error {e:.4} after {} steps ({:?}, {} solves); misfit {:.4e} -> {:.4e}",
            out.constant,
            out.history.len() - 1,
            out.stop,
            out.solves,
            out.constant_misfit(),
            out.final_misfit()
        );
        for pair in out.history.windows(2) {
            assert!(pair[1].misfit <= pair[0].misfit, "{:?}", out.history);
            assert!(pair[1].objective <= pair[0].objective, "{:?}", out.history);
        }
        assert!(out.history.len() > 10, "{:?}", out.stop);
        assert!(e <= 0.5 * e0, "error {e} against the constant's {e0}");
        assert!(out.final_misfit() < 0.05 * out.constant_misfit());
    }

    #[test]
    fn a_constant_map_is_recovered_exactly_by_the_start() {
        // 3D, anisotropic spacing: the data of W ≡ 1.5 are fitted by c* = 1.5.
        let grid = Grid::new(&[9, 10, 11], &[1.0, 0.8, 1.2]).unwrap();
        let sources = vec![vec![0.0, 0.0, 0.0], vec![8.0, 9.0, 0.0]];
        let receivers = vec![
            vec![8.0, 9.0, 10.0],
            vec![0.0, 4.5, 10.0],
            vec![4.0, 0.0, 5.5],
        ];
        let w = vec![1.5; grid.len()];
        let times = synthetic_times(&grid, &w, &sources, &receivers);
        let problem = TomographyProblem {
            grid,
            sources: &sources,
            receivers: &receivers,
            times: &times,
        };
        let out = tomography(&problem, &TomographyOptions::default(), &Control::new()).unwrap();
        assert!((out.constant - 1.5).abs() < 1e-12, "{}", out.constant);
        assert!(out.constant_misfit() < 1e-20);
        assert!(out.final_misfit() <= out.constant_misfit());
    }

    #[test]
    fn the_gradient_matches_finite_differences() {
        let n = 20;
        let grid = Grid::unit(&[n, n]).unwrap();
        let truth = two_anomalies(n);
        let sources = around_square(0.0, 19.0, 4, 0.0);
        let receivers = around_square(0.0, 19.0, 6, 0.5);
        let times = synthetic_times(&grid, &truth, &sources, &receivers);
        let problem = TomographyProblem {
            grid,
            sources: &sources,
            receivers: &receivers,
            times: &times,
        };
        let model = Model {
            problem: &problem,
            alpha: 0.3,
            order: Order::First,
        };
        let w: Vec<f64> = (0..n * n)
            .map(|x| 1.0 + 0.1 * ((x % 7) as f64 / 7.0))
            .collect();
        let f = model.forward(&w, &Control::new()).unwrap();
        let g = model.gradient(&w, &f, &Control::new()).unwrap();
        let scale = g.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for x in [0, 45, 110, 211, 399, 250] {
            let h = 1e-6;
            let mut wp = w.clone();
            wp[x] += h;
            let mut wm = w.clone();
            wm[x] -= h;
            let ep = model.forward(&wp, &Control::new()).unwrap().objective;
            let em = model.forward(&wm, &Control::new()).unwrap().objective;
            let fd = (ep - em) / (2.0 * h);
            assert!(
                (fd - g[x]).abs() <= 1e-5 * scale.max(1.0),
                "cell {x}: {fd} vs {}",
                g[x]
            );
        }
    }

    #[test]
    fn refusals_name_the_input() {
        let grid = Grid::unit(&[8, 8]).unwrap();
        let s = vec![vec![0.0, 0.0]];
        let r = vec![vec![7.0, 7.0], vec![7.0, 0.0]];
        let outside = vec![vec![7.0, 8.5]];
        type Case<'a> = (&'a [Vec<f64>], &'a [f64], &'a str);
        let cases: [Case<'_>; 4] = [
            (&r, &[1.0], "times"),
            (&r, &[1.0, f64::NAN], "times"),
            (&outside, &[1.0], "receivers"),
            (&r, &[0.0, 0.0], "times"),
        ];
        for (receivers, times, name) in cases {
            let problem = TomographyProblem {
                grid: grid.clone(),
                sources: &s,
                receivers,
                times,
            };
            match tomography(&problem, &TomographyOptions::default(), &Control::new()) {
                Err(TomographyError::Input { field, .. }) => assert_eq!(field, name),
                other => panic!("{name}: {other:?}"),
            }
        }
    }

    #[test]
    fn a_raised_flag_stops_it() {
        let grid = Grid::unit(&[16, 16]).unwrap();
        let s = vec![vec![0.0, 0.0]];
        let r = vec![vec![15.0, 15.0]];
        let problem = TomographyProblem {
            grid,
            sources: &s,
            receivers: &r,
            times: &[30.0],
        };
        let flag = AtomicBool::new(true);
        let out = tomography(
            &problem,
            &TomographyOptions::default(),
            &Control::new().with_cancel(&flag),
        );
        assert_eq!(out, Err(TomographyError::Cancelled));
    }
}
