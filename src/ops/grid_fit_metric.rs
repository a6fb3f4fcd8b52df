//! `grid.fit_metric`: the parameters of an intensity metric fitted so that
//! its minimal paths follow example paths traced by a user (inverse optimal
//! control; see [`crate::numerics::inverse::metric_fit`]). The answer's
//! `design` is a `cost.design` section that the other operations take as it
//! is.

use std::time::Instant;

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::spec::design::{array_to_f64, DesignSpec, IntensitySpec};
use super::spec::grid::{check_point, check_spacing, fetch, grid_of, shaped};
use super::{Inputs, OpError, OpLimits, OpOutput, Operation, OutputArray};
use crate::io::ArrayData;
use crate::numerics::filters;
use crate::numerics::inverse::metric_fit::{
    fit_metric, IntensityParams, MetricFitError, MetricFitOptions, MetricFitProblem, POWER_BOUNDS,
};
use crate::numerics::{Control, Order};

/// The most example paths in one request.
pub const MAX_EXAMPLES: usize = 256;
/// The most points in one example.
pub const MAX_POINTS: usize = 100_000;

/// Request of `grid.fit_metric` (`POST /v1/grid/fit-metric`).
///
/// Fits the reference grey value `c` (and, with `fit_power`, the exponent
/// `p`) of the intensity metric `W = ε + |f − c|^p` (`f` the image mapped to
/// `[0, 1]` and smoothed by `sigma`, as `cost.design` does; `ε` fixed: it
/// sets the scale) by minimising `L = Σ_k [∫_{γ_k} W ds − U^{(k)}(end_k)] /
/// length_k`, the excess of each example's length over the minimal one
/// between its ends (0 iff every example is a minimal path).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"image": "ds_0192f1b27c1e7d3a9d553c0f2b8a1e45", "examples": [[[32.0, 8.0], [20.0, 20.0], [16.0, 32.0], [20.0, 44.0], [32.0, 56.0]]], "design": {"kind": "intensity", "power": 2.0}}))]
pub struct GridFitMetricRequest {
    /// Id of a 2D or 3D image dataset.
    pub image: String,
    /// Physical size of a cell along each axis. Default: the dataset's, else 1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(min_items = 2, max_items = 3)]
    pub spacing: Option<Vec<f64>>,
    /// The example paths: each a polyline of at least 2 points (index
    /// coordinates, axis 0 first) from its start to its end.
    #[schema(min_items = 1)]
    pub examples: Vec<Vec<Vec<f64>>>,
    /// The metric to start from: an `intensity` design (its `value` or `at`
    /// is the initial `c`, default the brightest value; `power` the initial
    /// `p`, in [1, 4]; `epsilon` and `sigma` stay fixed). Default:
    /// `{"kind": "intensity", "power": 2}`.
    #[serde(default = "default_design")]
    pub design: DesignSpec,
    /// Also fit the exponent `p`. Default: false.
    #[serde(default)]
    pub fit_power: bool,
    /// Largest number of descent steps (1 to 200). Default: 30.
    #[serde(default = "default_iterations")]
    #[schema(minimum = 1, maximum = 200)]
    pub max_iterations: usize,
    /// Stop when a step lowers the loss by less than `tolerance ×` it. Default: 1e-6.
    #[serde(default = "default_tolerance")]
    #[schema(minimum = 0.0)]
    pub tolerance: f64,
    /// Order of the fast marching, 1 or 2. Default: 1.
    #[serde(default = "default_order_one")]
    pub order: u8,
}

fn default_design() -> DesignSpec {
    DesignSpec::Intensity(IntensitySpec {
        value: None,
        at: None,
        power: 2.0,
        epsilon: 0.01,
        sigma: 0.0,
    })
}
fn default_iterations() -> usize {
    30
}
fn default_tolerance() -> f64 {
    1e-6
}
fn default_order_one() -> u8 {
    1
}

impl GridFitMetricRequest {
    fn intensity(&self) -> Result<&IntensitySpec, OpError> {
        match &self.design {
            DesignSpec::Intensity(s) => Ok(s),
            _ => Err(OpError::invalid(
                "design.kind",
                "only the `intensity` family is fitted: give {\"kind\": \"intensity\", ...}",
            )),
        }
    }

    fn check(&self) -> Result<(), OpError> {
        if self.image.is_empty() {
            return Err(OpError::invalid("image", "a dataset id is required"));
        }
        check_spacing(&self.spacing)?;
        let spec = self.intensity()?;
        self.design.validate("design")?;
        if !(POWER_BOUNDS.0..=POWER_BOUNDS.1).contains(&spec.power) {
            return Err(OpError::invalid(
                "design.power",
                format!(
                    "{} must be in [{}, {}] (p >= 1 keeps the derivative in c bounded)",
                    spec.power, POWER_BOUNDS.0, POWER_BOUNDS.1
                ),
            ));
        }
        if self.examples.is_empty() {
            return Err(OpError::invalid(
                "examples",
                "give at least one example path",
            ));
        }
        if self.examples.len() > MAX_EXAMPLES {
            return Err(OpError::TooLarge {
                field: "examples".into(),
                reason: format!("more than {MAX_EXAMPLES} examples"),
            });
        }
        for (k, ex) in self.examples.iter().enumerate() {
            if ex.len() < 2 {
                return Err(OpError::invalid(
                    format!("examples[{k}]"),
                    format!(
                        "{} points: a path needs at least its start and its end",
                        ex.len()
                    ),
                ));
            }
            if ex.len() > MAX_POINTS {
                return Err(OpError::TooLarge {
                    field: format!("examples[{k}]"),
                    reason: format!("more than {MAX_POINTS} points"),
                });
            }
            for (i, p) in ex.iter().enumerate() {
                check_point(p, &format!("examples[{k}][{i}]"), Some(ex[0].len()))?;
            }
        }
        if !(1..=200).contains(&self.max_iterations) {
            return Err(OpError::invalid(
                "max_iterations",
                format!("{} must be in 1..=200", self.max_iterations),
            ));
        }
        if !(self.tolerance.is_finite() && self.tolerance >= 0.0) {
            return Err(OpError::invalid(
                "tolerance",
                format!("{} must be finite and >= 0", self.tolerance),
            ));
        }
        if !matches!(self.order, 1 | 2) {
            return Err(OpError::invalid("order", "must be 1 or 2"));
        }
        Ok(())
    }
}

impl Operation for GridFitMetricRequest {
    const NAME: &'static str = "grid.fit_metric";

    fn validate(&self, _limits: &OpLimits) -> Result<(), OpError> {
        self.check()
    }

    fn dataset_ids(&self) -> Vec<(String, String)> {
        vec![("image".to_string(), self.image.clone())]
    }

    /// Arrays: `cost` (f64, the fitted `W`). Document: `{"design" (the fitted
    /// `cost.design`), "reference" (`c` on the `[0, 1]` scale), "power",
    /// "loss": {"initial", "final", "history"}, "iterations", "stop",
    /// "examples": [{"loss_before", "loss_after", "before": {"mean",
    /// "hausdorff"}, "after": {...}, "path"}], "stats": {"cells", "seconds"}}`.
    fn run(
        &self,
        inputs: &dyn Inputs,
        limits: &OpLimits,
        control: &Control<'_>,
    ) -> Result<OpOutput, OpError> {
        self.check()?;
        let spec = self.intensity()?;
        let input = fetch(inputs, "image", &self.image)?;
        let grid = grid_of(&input, "image", &self.spacing, limits)?;
        if input.array.dtype() == crate::io::DType::Bool {
            return Err(OpError::invalid("image", "a boolean mask is not an image"));
        }
        let raw = array_to_f64(&input.array);
        if let Some(i) = raw.iter().position(|v| !v.is_finite()) {
            return Err(OpError::invalid(
                "image",
                format!("value {i} (C order) is {}: an image must be finite", raw[i]),
            ));
        }
        let ndim = grid.ndim();
        for (k, ex) in self.examples.iter().enumerate() {
            for (i, p) in ex.iter().enumerate() {
                check_point(p, &format!("examples[{k}][{i}]"), Some(ndim))?;
                if let Some(a) =
                    (0..ndim).find(|&a| !(0.0..=(grid.shape()[a] - 1) as f64).contains(&p[a]))
                {
                    return Err(OpError::invalid(
                        format!("examples[{k}][{i}][{a}]"),
                        format!(
                            "{} is outside the image (axis {a} runs from 0 to {})",
                            p[a],
                            grid.shape()[a] - 1
                        ),
                    ));
                }
            }
        }
        // The feature image of the intensity design: [0, 1], then smoothed.
        let lo = raw.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = raw.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let span = hi - lo;
        let feature =
            filters::gaussian_smooth(&grid, &filters::normalize_unit(&raw), spec.sigma, control)
                .map_err(|e| {
                    if control.is_cancelled() {
                        OpError::Cancelled
                    } else {
                        OpError::invalid("design.sigma", e.to_string())
                    }
                })?;
        let reference = match (&spec.at, spec.value) {
            (Some(p), _) => {
                check_point(p, "design.at", Some(ndim))?;
                let cell: Vec<usize> = p.iter().map(|v| v.round().max(0.0) as usize).collect();
                if cell.iter().zip(grid.shape()).any(|(c, n)| c >= n) {
                    return Err(OpError::invalid(
                        "design.at",
                        format!("{p:?} is outside the image"),
                    ));
                }
                let [_, n1, n2] = grid.shape3();
                let c3 = if ndim == 2 {
                    [0, cell[0], cell[1]]
                } else {
                    [cell[0], cell[1], cell[2]]
                };
                feature[(c3[0] * n1 + c3[1]) * n2 + c3[2]]
            }
            (None, Some(v)) => {
                if !(lo..=hi).contains(&v) {
                    return Err(OpError::invalid(
                        "design.value",
                        format!("{v} is outside the image's range [{lo}, {hi}]"),
                    ));
                }
                if span > 0.0 {
                    (v - lo) / span
                } else {
                    0.0
                }
            }
            (None, None) => 1.0,
        };
        let problem = MetricFitProblem {
            grid: grid.clone(),
            feature: &feature,
            epsilon: spec.epsilon,
            examples: &self.examples,
        };
        let mut options = MetricFitOptions::new(IntensityParams {
            reference,
            power: spec.power,
        });
        options.fit_power = self.fit_power;
        options.max_iterations = self.max_iterations;
        options.tolerance = self.tolerance;
        options.order = if self.order == 2 {
            Order::Second
        } else {
            Order::First
        };
        let started = Instant::now();
        let out = fit_metric(&problem, &options, control).map_err(|e| match e {
            MetricFitError::Cancelled => OpError::Cancelled,
            MetricFitError::Input { field, reason } => {
                let field = match field {
                    "feature" => "image",
                    "epsilon" => "design.epsilon",
                    "reference" => "design.value",
                    "power" => "design.power",
                    other => other,
                };
                OpError::invalid(field, reason)
            }
            MetricFitError::Solve(reason) => OpError::invalid("examples", reason),
        })?;
        let seconds = started.elapsed().as_secs_f64();
        let value = lo + out.params.reference * span;
        let distance = |d: &crate::numerics::inverse::metric_fit::PathDistance| serde_json::json!({"mean": d.mean, "hausdorff": d.hausdorff});
        let examples: Vec<serde_json::Value> = out
            .examples
            .iter()
            .map(|e| {
                serde_json::json!({
                    "loss_before": e.loss_before,
                    "loss_after": e.loss_after,
                    "before": distance(&e.before),
                    "after": distance(&e.after),
                    "path": e.path,
                })
            })
            .collect();
        let document = serde_json::json!({
            "design": {
                "kind": "intensity",
                "value": value,
                "power": out.params.power,
                "epsilon": spec.epsilon,
                "sigma": spec.sigma,
            },
            "reference": out.params.reference,
            "power": out.params.power,
            "loss": {
                "initial": out.history.first().map(|i| i.loss),
                "final": out.history.last().map(|i| i.loss),
                "history": out.history.iter().map(|i| i.loss).collect::<Vec<_>>(),
            },
            "iterations": out.history.len() - 1,
            "stop": out.stop.as_str(),
            "examples": examples,
            "stats": {"cells": grid.len(), "seconds": seconds},
        });
        Ok(OpOutput::new(
            vec![OutputArray {
                name: "cost".into(),
                array: ArrayData::F64(shaped(&grid, out.cost)?),
                spacing: Some(grid.spacing().to_vec()),
            }],
            document,
        ))
    }
}
