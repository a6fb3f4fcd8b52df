//! Metric fitting (inverse optimal control): the parameters `θ` of a
//! designed metric adjusted so that its minimal paths follow example paths
//! a user traced.
//!
//! # The family
//!
//! The intensity metric of [`crate::numerics::metric_design::intensity`],
//! `W_θ(x) = ε + |f(x) − c|^p`, on a feature image `f` (the image mapped to
//! `[0, 1]`, smoothed if asked, as the design does), with `θ = (c, p)`: the
//! reference grey value `c ∈ [0, 1]` always, the exponent `p ∈ [1, 4]` on
//! request ([`MetricFitOptions::fit_power`]). `ε` is **fixed**: it sets the
//! scale of `W` (without it `W → 0` would make every loss below vanish, the
//! trivial scaling solution), and `p ≥ 1` keeps `∂W/∂c` bounded.
//!
//! # The loss
//!
//! For example `k`, a polyline `γ_k` from `a_k` to `b_k` of length `ℓ_k`,
//! with `U_θ^{(k)}` the fast-marching distance from `a_k` (first or second
//! order, unfactored):
//!
//! ```text
//! L(θ) = Σ_k [ ∫_{γ_k} W_θ ds − U_θ^{(k)}(b_k) ] / ℓ_k
//! ```
//!
//! the structured margin of inverse optimal control: each term is the excess
//! of the example's length over the minimal length between its ends, so it
//! is `≥ 0` and `0` iff the example is a minimal path (up to the
//! discretisation: the integral is the midpoint rule on the multilinear `W`
//! every quarter cell, `U` the scheme's value, which may differ by `O(h)`).
//! Dividing by `ℓ_k` makes each term the mean excess cost per unit length, so
//! long and short examples weigh alike.
//!
//! # The gradient
//!
//! By the envelope theorem the minimal path's own change does not enter:
//!
//! ```text
//! ∂L/∂θ = Σ_k Σ_x [ ∂C_k/∂W_x − ∂U^{(k)}(b_k)/∂W_x ] ∂W_x/∂θ / ℓ_k,
//! ∂W/∂c = −p |f − c|^{p−1} sgn(f − c),   ∂W/∂p = |f − c|^p ln|f − c|
//! ```
//!
//! `∂C_k/∂W_x` the quadrature weights of the integral, `∂U/∂W_x` from
//! [`cost_gradient`] (one forward solve and one adjoint sweep per example,
//! the examples in parallel on the caller's rayon pool). With `p = 1`,
//! `∂W/∂c = ±1` does not depend on how far `f` is from `c`, so `∂L/∂c` only
//! compares the lengths of the example and of the minimal path on the parts
//! where `f < c` and `f > c`: start from `p > 1` (e.g. 2) or fit `p` too.
//! `L` is piecewise
//! smooth (the minimal path jumps where two routes tie): the descent is the
//! projected gradient on the box of `θ` with a Barzilai–Borwein step and a
//! monotone Armijo backtracking, as in [`super::tomography`].
//!
//! # The report
//!
//! For each example the distance (index units) between it and the fitted
//! metric's minimal path between its ends (descent of `U` by
//! [`crate::numerics::paths::minimal_path`]), before and after: the mean
//! over the example (resampled every half cell) of the distance to the path,
//! and the symmetric Hausdorff distance.

use std::borrow::Cow;

use rayon::prelude::*;

use super::{adjoint_options, corners, interpolate};
use crate::numerics::control::Control;
use crate::numerics::eikonal::{cost_gradient, Probe};
use crate::numerics::grid::Grid;
use crate::numerics::metric::{CostValues, Interpretation, IsotropicCost};
use crate::numerics::paths::{minimal_path, DescentOptions};
use crate::numerics::{solve, EikonalError, EikonalProblem, Order, Source};

/// Armijo's sufficient-decrease constant.
const ARMIJO: f64 = 1e-4;
/// Halvings of the step before the line search gives up.
const MAX_HALVINGS: usize = 30;
/// The bounds of the exponent `p`.
pub const POWER_BOUNDS: (f64, f64) = (1.0, 4.0);

/// Why a fit was refused or interrupted.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MetricFitError {
    /// An input is malformed; `field` is `examples`, `feature`, `epsilon`,
    /// `reference`, `power` or `max_iterations`.
    #[error("{field}: {reason}")]
    Input {
        /// The input at fault.
        field: &'static str,
        /// Why it is refused.
        reason: String,
    },
    /// A solve, an adjoint sweep or a path descent failed.
    #[error("{0}")]
    Solve(String),
    /// The caller raised the cancel flag.
    #[error("cancelled")]
    Cancelled,
}

impl From<EikonalError> for MetricFitError {
    fn from(e: EikonalError) -> Self {
        match e {
            EikonalError::Cancelled => MetricFitError::Cancelled,
            other => MetricFitError::Solve(other.to_string()),
        }
    }
}

/// The parameters `θ = (c, p)` of `W = ε + |f − c|^p`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IntensityParams {
    /// The reference value `c` of the feature image, in `[0, 1]`.
    pub reference: f64,
    /// The exponent `p`, in [`POWER_BOUNDS`].
    pub power: f64,
}

/// The data: a grid, the feature image `f` (one finite value per cell, C
/// order; `[0, 1]` for the bounds of `c` to make sense), the fixed `ε > 0`
/// and the examples, each a polyline of at least two points (index
/// coordinates, axis 0 first) from its start to its end.
#[derive(Debug, Clone)]
pub struct MetricFitProblem<'a> {
    /// Shape and spacing.
    pub grid: Grid,
    /// The feature image.
    pub feature: &'a [f64],
    /// The floor `ε` of the cost.
    pub epsilon: f64,
    /// The example paths.
    pub examples: &'a [Vec<Vec<f64>>],
}

/// Options, with the defaults of [`MetricFitOptions::new`].
#[derive(Debug, Clone, PartialEq)]
pub struct MetricFitOptions {
    /// The start `θ_0`.
    pub initial: IntensityParams,
    /// Also fit the exponent (else it stays at its initial value). Default: false.
    pub fit_power: bool,
    /// Largest number of accepted steps. Default: 30.
    pub max_iterations: usize,
    /// Stop when a step lowers `L` by less than `tolerance × max(|L|, 1e-12)`. Default: 1e-6.
    pub tolerance: f64,
    /// Order of the fast marching. Default: first.
    pub order: Order,
}

impl MetricFitOptions {
    /// The defaults, from `initial`.
    pub fn new(initial: IntensityParams) -> Self {
        Self {
            initial,
            fit_power: false,
            max_iterations: 30,
            tolerance: 1e-6,
            order: Order::First,
        }
    }
}

/// One accepted iterate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitIterate {
    /// The loss `L(θ)`.
    pub loss: f64,
    /// `θ` there.
    pub params: IntensityParams,
    /// `∂L/∂c`, `∂L/∂p` there.
    pub gradient: [f64; 2],
    /// The step accepted (0 for the start).
    pub step: f64,
    /// Halvings before it was accepted.
    pub halvings: usize,
}

/// The distance between an example and a minimal path (index units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PathDistance {
    /// Mean over the example of the distance to the path.
    pub mean: f64,
    /// The symmetric Hausdorff distance.
    pub hausdorff: f64,
}

/// What the fit did for one example.
#[derive(Debug, Clone, PartialEq)]
pub struct ExampleFit {
    /// Its term of the loss at `θ_0` and at the fitted `θ`.
    pub loss_before: f64,
    /// See `loss_before`.
    pub loss_after: f64,
    /// Distance to the minimal path of `θ_0`.
    pub before: PathDistance,
    /// Distance to the minimal path of the fitted `θ`.
    pub after: PathDistance,
    /// The fitted metric's minimal path between its ends (index coordinates, start first).
    pub path: Vec<Vec<f64>>,
}

/// How the descent ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FitStop {
    /// `max_iterations` steps were taken.
    MaxIterations,
    /// A step lowered `L` by less than `tolerance × |L|`.
    Tolerance,
    /// The projected gradient step is zero.
    Stationary,
    /// No step along the projected gradient lowers the loss.
    LineSearch,
}

impl FitStop {
    /// The stop as a word.
    pub fn as_str(&self) -> &'static str {
        match self {
            FitStop::MaxIterations => "max_iterations",
            FitStop::Tolerance => "tolerance",
            FitStop::Stationary => "stationary",
            FitStop::LineSearch => "line_search",
        }
    }
}

/// The fitted parameters, the history and the per-example report.
#[derive(Debug, Clone, PartialEq)]
pub struct MetricFitOutput {
    /// The fitted `θ`.
    pub params: IntensityParams,
    /// `history[0]` is `θ_0`, then one per accepted step.
    pub history: Vec<FitIterate>,
    /// One per example.
    pub examples: Vec<ExampleFit>,
    /// The fitted cost `W`, one value per cell.
    pub cost: Vec<f64>,
    /// How the descent ended.
    pub stop: FitStop,
}

/// `W = ε + |f − c|^p` and its derivatives in `c` and `p` at one cell.
fn family(f: f64, epsilon: f64, th: IntensityParams) -> (f64, f64, f64) {
    let d = f - th.reference;
    let a = d.abs();
    if a == 0.0 {
        return (epsilon, 0.0, 0.0);
    }
    let ap = a.powf(th.power);
    let dc = -th.power * a.powf(th.power - 1.0) * d.signum();
    (epsilon + ap, dc, ap * a.ln())
}

/// The cost map of `θ`.
pub fn intensity_cost(feature: &[f64], epsilon: f64, th: IntensityParams) -> Vec<f64> {
    feature.iter().map(|&f| family(f, epsilon, th).0).collect()
}

/// The quadrature of `∫_γ W ds`: `(cell, ∂C/∂W_cell)` over the polyline
/// (midpoint rule every quarter cell on the multilinear `W`), and the
/// physical length.
fn line_weights(grid: &Grid, polyline: &[Vec<f64>]) -> (Vec<(usize, f64)>, f64) {
    let h = grid.spacing();
    let mut weights: Vec<(usize, f64)> = Vec::new();
    let mut length = 0.0;
    for seg in polyline.windows(2) {
        let (a, b) = (&seg[0], &seg[1]);
        let index_len = a
            .iter()
            .zip(b)
            .map(|(x, y)| (y - x) * (y - x))
            .sum::<f64>()
            .sqrt();
        let phys = a
            .iter()
            .zip(b)
            .zip(h)
            .map(|((x, y), hk)| ((y - x) * hk).powi(2))
            .sum::<f64>()
            .sqrt();
        length += phys;
        let m = (index_len / 0.25).ceil().max(1.0) as usize;
        let ds = phys / m as f64;
        for i in 0..m {
            let t = (i as f64 + 0.5) / m as f64;
            let p: Vec<f64> = a.iter().zip(b).map(|(x, y)| x + t * (y - x)).collect();
            if let Some(cs) = corners(grid, &p) {
                weights.extend(cs.into_iter().map(|(c, w)| (c, w * ds)));
            }
        }
    }
    weights.sort_unstable_by_key(|&(c, _)| c);
    let mut merged: Vec<(usize, f64)> = Vec::with_capacity(weights.len());
    for (c, w) in weights {
        match merged.last_mut() {
            Some(last) if last.0 == c => last.1 += w,
            _ => merged.push((c, w)),
        }
    }
    (merged, length)
}

struct Fit<'a> {
    problem: &'a MetricFitProblem<'a>,
    order: Order,
    /// Per example: the quadrature weights and the length.
    lines: Vec<(Vec<(usize, f64)>, f64)>,
}

/// The loss terms and the gradient `[∂L/∂c, ∂L/∂p]` at `θ`.
struct Evaluation {
    terms: Vec<f64>,
    loss: f64,
    gradient: [f64; 2],
}

impl Fit<'_> {
    fn eikonal<'w>(&self, w: &'w [f64], k: usize) -> Result<EikonalProblem<'w>, MetricFitError> {
        let grid = &self.problem.grid;
        let cost = IsotropicCost::new(
            grid,
            CostValues::F64(Cow::Borrowed(w)),
            Interpretation::Cost,
            None,
        )
        .map_err(|e| MetricFitError::Solve(e.to_string()))?;
        let start = self.problem.examples[k]
            .first()
            .cloned()
            .unwrap_or_default();
        Ok(EikonalProblem {
            grid: grid.clone(),
            cost,
            sources: vec![Source::Point(start)],
        })
    }

    fn evaluate(
        &self,
        th: IntensityParams,
        control: &Control<'_>,
    ) -> Result<Evaluation, MetricFitError> {
        let p = self.problem;
        let derivs: Vec<(f64, f64, f64)> = p
            .feature
            .iter()
            .map(|&f| family(f, p.epsilon, th))
            .collect();
        let w: Vec<f64> = derivs.iter().map(|d| d.0).collect();
        let options = adjoint_options(self.order);
        let inner = control.cancel_only();
        let per: Vec<(f64, [f64; 2])> = (0..p.examples.len())
            .into_par_iter()
            .map(|k| {
                let problem = self.eikonal(&w, k)?;
                let out = solve(&problem, &options, &inner)?;
                let end = p.examples[k].last().cloned().unwrap_or_default();
                let u = out
                    .distance
                    .as_slice()
                    .map(Cow::Borrowed)
                    .unwrap_or_else(|| Cow::Owned(out.distance.iter().copied().collect()));
                let u_end = interpolate(&p.grid, &u, &end).unwrap_or(f64::INFINITY);
                let (line, len) = &self.lines[k];
                let c: f64 = line.iter().map(|&(x, wt)| wt * w[x]).sum();
                let g = cost_gradient(
                    &problem,
                    &options,
                    &out,
                    &[(Probe::Point(end), 1.0)],
                    &inner,
                )?;
                let mut grad = [0.0; 2];
                for &(x, wt) in line {
                    grad[0] += wt * derivs[x].1;
                    grad[1] += wt * derivs[x].2;
                }
                for (x, gu) in g.iter().enumerate() {
                    if *gu != 0.0 {
                        grad[0] -= gu * derivs[x].1;
                        grad[1] -= gu * derivs[x].2;
                    }
                }
                Ok(((c - u_end) / len, [grad[0] / len, grad[1] / len]))
            })
            .collect::<Result<_, MetricFitError>>()?;
        let mut gradient = [0.0; 2];
        for (_, g) in &per {
            gradient[0] += g[0];
            gradient[1] += g[1];
        }
        let terms: Vec<f64> = per.iter().map(|t| t.0).collect();
        Ok(Evaluation {
            loss: terms.iter().sum(),
            terms,
            gradient,
        })
    }

    /// The minimal paths of `θ` between the ends of every example.
    fn paths(
        &self,
        th: IntensityParams,
        control: &Control<'_>,
    ) -> Result<Vec<Vec<Vec<f64>>>, MetricFitError> {
        let p = self.problem;
        let w = intensity_cost(p.feature, p.epsilon, th);
        let options = adjoint_options(self.order);
        let inner = control.cancel_only();
        (0..p.examples.len())
            .into_par_iter()
            .map(|k| {
                let problem = self.eikonal(&w, k)?;
                let out = solve(&problem, &options, &inner)?;
                let u: Vec<f64> = out.distance.iter().copied().collect();
                let end = p.examples[k].last().cloned().unwrap_or_default();
                let path = minimal_path(&problem, &u, &end, &DescentOptions::default())
                    .map_err(|e| MetricFitError::Solve(e.to_string()))?;
                Ok(path.index_points(&p.grid))
            })
            .collect()
    }
}

/// The distance from `p` to the polyline `line`.
fn to_polyline(p: &[f64], line: &[Vec<f64>]) -> f64 {
    if line.len() == 1 {
        return dist(p, &line[0]);
    }
    line.windows(2)
        .map(|s| {
            let (a, b) = (&s[0], &s[1]);
            let ab: f64 = a.iter().zip(b).map(|(x, y)| (y - x) * (y - x)).sum();
            let t = if ab > 0.0 {
                (a.iter()
                    .zip(b)
                    .zip(p)
                    .map(|((x, y), q)| (q - x) * (y - x))
                    .sum::<f64>()
                    / ab)
                    .clamp(0.0, 1.0)
            } else {
                0.0
            };
            let q: Vec<f64> = a.iter().zip(b).map(|(x, y)| x + t * (y - x)).collect();
            dist(p, &q)
        })
        .fold(f64::INFINITY, f64::min)
}

fn dist(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y) * (x - y))
        .sum::<f64>()
        .sqrt()
}

/// The polyline's points every `step` (index units) or closer, ends included.
fn resample(line: &[Vec<f64>], step: f64) -> Vec<Vec<f64>> {
    let mut out = Vec::new();
    for s in line.windows(2) {
        let (a, b) = (&s[0], &s[1]);
        let m = (dist(a, b) / step).ceil().max(1.0) as usize;
        for i in 0..m {
            let t = i as f64 / m as f64;
            out.push(a.iter().zip(b).map(|(x, y)| x + t * (y - x)).collect());
        }
    }
    if let Some(last) = line.last() {
        out.push(last.clone());
    }
    out
}

/// The mean (over the example) and Hausdorff distances between an example
/// and a path, index units.
pub fn path_distance(example: &[Vec<f64>], path: &[Vec<f64>]) -> PathDistance {
    let ex = resample(example, 0.5);
    let pa = resample(path, 0.5);
    let d_ex: Vec<f64> = ex.iter().map(|p| to_polyline(p, path)).collect();
    let mean = d_ex.iter().sum::<f64>() / d_ex.len().max(1) as f64;
    let h1 = d_ex.iter().copied().fold(0.0, f64::max);
    let h2 = pa
        .iter()
        .map(|p| to_polyline(p, example))
        .fold(0.0, f64::max);
    PathDistance {
        mean,
        hausdorff: h1.max(h2),
    }
}

fn check(problem: &MetricFitProblem<'_>, options: &MetricFitOptions) -> Result<(), MetricFitError> {
    let input = |field: &'static str, reason: String| Err(MetricFitError::Input { field, reason });
    let grid = &problem.grid;
    if problem.feature.len() != grid.len() {
        return input(
            "feature",
            format!("{} values for {} cells", problem.feature.len(), grid.len()),
        );
    }
    if let Some(i) = problem.feature.iter().position(|v| !v.is_finite()) {
        return input("feature", format!("value {i} (C order) is not finite"));
    }
    if !(problem.epsilon.is_finite() && problem.epsilon > 0.0) {
        return input(
            "epsilon",
            format!("{} must be finite and > 0", problem.epsilon),
        );
    }
    if problem.examples.is_empty() {
        return input("examples", "give at least one example path".into());
    }
    for (k, ex) in problem.examples.iter().enumerate() {
        if ex.len() < 2 {
            return input(
                "examples",
                format!("[{k}] has {} points, a path needs 2", ex.len()),
            );
        }
        for (i, p) in ex.iter().enumerate() {
            if p.len() != grid.ndim() || corners(grid, p).is_none() {
                return input(
                    "examples",
                    format!(
                        "[{k}][{i}] {p:?} is not a point of the grid of shape {:?}",
                        grid.shape()
                    ),
                );
            }
        }
        if dist(&ex[0], &ex[ex.len() - 1]) < 1.0 {
            return input(
                "examples",
                format!("[{k}] ends within one cell of its start: nothing to follow"),
            );
        }
    }
    let th = options.initial;
    if !(th.reference.is_finite() && (0.0..=1.0).contains(&th.reference)) {
        return input("reference", format!("{} must be in [0, 1]", th.reference));
    }
    if !(POWER_BOUNDS.0..=POWER_BOUNDS.1).contains(&th.power) {
        return input(
            "power",
            format!(
                "{} must be in [{}, {}]",
                th.power, POWER_BOUNDS.0, POWER_BOUNDS.1
            ),
        );
    }
    if !(options.tolerance.is_finite() && options.tolerance >= 0.0) {
        return input(
            "tolerance",
            format!("{} must be finite and >= 0", options.tolerance),
        );
    }
    Ok(())
}

/// Fits `θ` to the examples: the projected-gradient descent of the loss of
/// the module documentation from `options.initial`.
///
/// Polls `control` in every solve and between the steps; reports the
/// fraction of `max_iterations` done.
pub fn fit_metric(
    problem: &MetricFitProblem<'_>,
    options: &MetricFitOptions,
    control: &Control<'_>,
) -> Result<MetricFitOutput, MetricFitError> {
    check(problem, options)?;
    let fit = Fit {
        problem,
        order: options.order,
        lines: problem
            .examples
            .iter()
            .map(|ex| line_weights(&problem.grid, ex))
            .collect(),
    };
    let project = |th: IntensityParams| IntensityParams {
        reference: th.reference.clamp(0.0, 1.0),
        power: if options.fit_power {
            th.power.clamp(POWER_BOUNDS.0, POWER_BOUNDS.1)
        } else {
            options.initial.power
        },
    };
    let mask = |g: [f64; 2]| [g[0], if options.fit_power { g[1] } else { 0.0 }];
    let mut th = options.initial;
    let mut current = fit.evaluate(th, control)?;
    let first_terms = current.terms.clone();
    let mut history = vec![FitIterate {
        loss: current.loss,
        params: th,
        gradient: current.gradient,
        step: 0.0,
        halvings: 0,
    }];
    let g = mask(current.gradient);
    let gmax = g[0].abs().max(g[1].abs());
    let mut step = if gmax > 0.0 { 0.05 / gmax } else { 0.0 };
    let mut stop = FitStop::MaxIterations;
    for it in 0..options.max_iterations {
        if control.is_cancelled() {
            return Err(MetricFitError::Cancelled);
        }
        if step == 0.0 {
            stop = FitStop::Stationary;
            break;
        }
        let g = mask(current.gradient);
        let mut t = step;
        let mut accepted = None;
        for halvings in 0..=MAX_HALVINGS {
            let trial = project(IntensityParams {
                reference: th.reference - t * g[0],
                power: th.power - t * g[1],
            });
            if trial == th {
                break;
            }
            let slope = g[0] * (trial.reference - th.reference) + g[1] * (trial.power - th.power);
            let e = fit.evaluate(trial, control)?;
            if e.loss <= current.loss + ARMIJO * slope {
                accepted = Some((trial, e, t, halvings));
                break;
            }
            t *= 0.5;
        }
        let Some((trial, e, t, halvings)) = accepted else {
            stop = if t == step {
                FitStop::Stationary
            } else {
                FitStop::LineSearch
            };
            break;
        };
        let gn = mask(e.gradient);
        let s = [trial.reference - th.reference, trial.power - th.power];
        let y = [gn[0] - g[0], gn[1] - g[1]];
        let (ss, sy) = (s[0] * s[0] + s[1] * s[1], s[0] * y[0] + s[1] * y[1]);
        step = if sy > 0.0 && ss > 0.0 {
            ss / sy
        } else {
            2.0 * t
        };
        let decrease = current.loss - e.loss;
        let small = decrease <= options.tolerance * current.loss.abs().max(1e-12);
        history.push(FitIterate {
            loss: e.loss,
            params: trial,
            gradient: e.gradient,
            step: t,
            halvings,
        });
        th = trial;
        current = e;
        control.report((it + 1) as f64 / options.max_iterations.max(1) as f64);
        if small {
            stop = FitStop::Tolerance;
            break;
        }
    }
    let before = fit.paths(options.initial, control)?;
    let after = fit.paths(th, control)?;
    let examples = problem
        .examples
        .iter()
        .enumerate()
        .map(|(k, ex)| ExampleFit {
            loss_before: first_terms[k],
            loss_after: current.terms[k],
            before: path_distance(ex, &before[k]),
            after: path_distance(ex, &after[k]),
            path: after[k].clone(),
        })
        .collect();
    control.report(1.0);
    Ok(MetricFitOutput {
        params: th,
        history,
        examples,
        cost: intensity_cost(problem.feature, problem.epsilon, th),
        stop,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::AtomicBool;

    const N: usize = 64;

    /// The dim ridge: an arc bulging towards row 0 from (32, 8) to (32, 56).
    fn dim_arc(t: f64) -> [f64; 2] {
        [
            32.0 - 16.0 * (std::f64::consts::PI * t).sin(),
            8.0 + 48.0 * t,
        ]
    }

    /// The bright ridge: the mirror arc, bulging towards the last row.
    fn bright_arc(t: f64) -> [f64; 2] {
        [
            32.0 + 16.0 * (std::f64::consts::PI * t).sin(),
            8.0 + 48.0 * t,
        ]
    }

    /// Two Gaussian-profile ridges (width 1.5): the bright one of height 1,
    /// the dim one of height 0.6, on a background 0.
    fn two_ridges() -> Vec<f64> {
        let samples = |arc: fn(f64) -> [f64; 2]| -> Vec<[f64; 2]> {
            (0..=400).map(|i| arc(i as f64 / 400.0)).collect()
        };
        let (dim, bright) = (samples(dim_arc), samples(bright_arc));
        let near = |pts: &[[f64; 2]], i: f64, j: f64| {
            pts.iter()
                .map(|p| (p[0] - i).powi(2) + (p[1] - j).powi(2))
                .fold(f64::INFINITY, f64::min)
        };
        (0..N * N)
            .map(|x| {
                let (i, j) = ((x / N) as f64, (x % N) as f64);
                let a = 0.6 * (-near(&dim, i, j) / (2.0 * 1.5 * 1.5)).exp();
                let b = (-near(&bright, i, j) / (2.0 * 1.5 * 1.5)).exp();
                a.max(b)
            })
            .collect()
    }

    /// Examples traced along the dim ridge (a user's clicks: every 4 px).
    fn examples() -> Vec<Vec<Vec<f64>>> {
        let along = |t0: f64, t1: f64| -> Vec<Vec<f64>> {
            (0..=12)
                .map(|i| {
                    let p = dim_arc(t0 + (t1 - t0) * i as f64 / 12.0);
                    vec![p[0], p[1]]
                })
                .collect()
        };
        vec![along(0.0, 1.0), along(0.1, 0.9)]
    }

    #[test]
    fn the_fitted_metric_follows_the_dim_ridge() {
        let feature = two_ridges();
        let examples = examples();
        let problem = MetricFitProblem {
            grid: Grid::unit(&[N, N]).unwrap(),
            feature: &feature,
            epsilon: 0.01,
            examples: &examples,
        };
        // From the default reference (the brightest value) with p = 2.
        let options = MetricFitOptions::new(IntensityParams {
            reference: 1.0,
            power: 2.0,
        });
        let out = fit_metric(&problem, &options, &Control::new()).unwrap();
        eprintln!(
            "c = {:.4}, p = {:.3} after {} steps ({:?}); loss {:.4e} -> {:.4e}",
            out.params.reference,
            out.params.power,
            out.history.len() - 1,
            out.stop,
            out.history[0].loss,
            out.history.last().unwrap().loss
        );
        for e in &out.examples {
            eprintln!("before {:?}, after {:?}", e.before, e.after);
            assert!(e.before.mean > 3.0, "{:?}", e.before);
            assert!(e.after.mean <= 1.5, "{:?}", e.after);
        }
        for pair in out.history.windows(2) {
            assert!(pair[1].loss <= pair[0].loss);
        }
        assert!(
            (out.params.reference - 0.6).abs() < 0.25,
            "{:?}",
            out.params
        );
    }

    #[test]
    fn the_gradient_matches_finite_differences() {
        let feature = two_ridges();
        let examples = examples();
        let problem = MetricFitProblem {
            grid: Grid::unit(&[N, N]).unwrap(),
            feature: &feature,
            epsilon: 0.01,
            examples: &examples,
        };
        let fit = Fit {
            problem: &problem,
            order: Order::First,
            lines: examples
                .iter()
                .map(|ex| line_weights(&problem.grid, ex))
                .collect(),
        };
        for th in [
            IntensityParams {
                reference: 0.83,
                power: 1.7,
            },
            IntensityParams {
                reference: 0.47,
                power: 2.3,
            },
        ] {
            let e = fit.evaluate(th, &Control::new()).unwrap();
            let h = 1e-6;
            let loss = |t: IntensityParams| fit.evaluate(t, &Control::new()).unwrap().loss;
            let fd_c = (loss(IntensityParams {
                reference: th.reference + h,
                ..th
            }) - loss(IntensityParams {
                reference: th.reference - h,
                ..th
            })) / (2.0 * h);
            let fd_p = (loss(IntensityParams {
                power: th.power + h,
                ..th
            }) - loss(IntensityParams {
                power: th.power - h,
                ..th
            })) / (2.0 * h);
            eprintln!(
                "{th:?}: dL/dc {} vs {fd_c}, dL/dp {} vs {fd_p}",
                e.gradient[0], e.gradient[1]
            );
            assert!(
                (e.gradient[0] - fd_c).abs() <= 1e-4 * fd_c.abs().max(1e-2),
                "{} vs {fd_c}",
                e.gradient[0]
            );
            assert!(
                (e.gradient[1] - fd_p).abs() <= 1e-4 * fd_p.abs().max(1e-2),
                "{} vs {fd_p}",
                e.gradient[1]
            );
        }
    }

    #[test]
    fn path_distance_of_parallel_lines() {
        let a = vec![vec![0.0, 0.0], vec![0.0, 10.0]];
        let b = vec![vec![2.0, 0.0], vec![2.0, 5.0], vec![2.0, 10.0]];
        let d = path_distance(&a, &b);
        assert!(
            (d.mean - 2.0).abs() < 1e-12 && (d.hausdorff - 2.0).abs() < 1e-12,
            "{d:?}"
        );
    }

    #[test]
    fn refusals_and_cancel() {
        let feature = vec![0.5; 100];
        let grid = Grid::unit(&[10, 10]).unwrap();
        let good = vec![vec![vec![1.0, 1.0], vec![8.0, 8.0]]];
        let outside = vec![vec![vec![1.0, 1.0], vec![8.0, 10.5]]];
        let short = vec![vec![vec![1.0, 1.0]]];
        let init = IntensityParams {
            reference: 1.0,
            power: 1.0,
        };
        for (examples, name) in [(&outside, "examples"), (&short, "examples")] {
            let problem = MetricFitProblem {
                grid: grid.clone(),
                feature: &feature,
                epsilon: 0.01,
                examples,
            };
            match fit_metric(&problem, &MetricFitOptions::new(init), &Control::new()) {
                Err(MetricFitError::Input { field, .. }) => assert_eq!(field, name),
                other => panic!("{other:?}"),
            }
        }
        let problem = MetricFitProblem {
            grid: grid.clone(),
            feature: &feature,
            epsilon: 0.01,
            examples: &good,
        };
        let bad = MetricFitOptions::new(IntensityParams {
            reference: 1.0,
            power: 0.5,
        });
        assert!(matches!(
            fit_metric(&problem, &bad, &Control::new()),
            Err(MetricFitError::Input { field: "power", .. })
        ));
        let flag = AtomicBool::new(true);
        assert_eq!(
            fit_metric(
                &problem,
                &MetricFitOptions::new(init),
                &Control::new().with_cancel(&flag)
            ),
            Err(MetricFitError::Cancelled)
        );
    }
}
