//! `grid.cost_gradient`: how geodesic distances change when the cost
//! changes (the monograph's section 2.9), the discrete adjoint of fast
//! marching ([`crate::numerics::eikonal::cost_gradient`]) as an operation.
//!
//! The objective is a function of the distance `U` at target points `y_m`:
//!
//! ```text
//! sum:     J = Σ_m w_m U(y_m)
//! misfit:  J = ½ Σ_m w_m (U(y_m) − T_m)²,   ∂J/∂W = Σ_m w_m (U(y_m) − T_m) ∂U(y_m)/∂W
//! ```
//!
//! With one target of weight 1, `J = U(y)` is also the length `∫ W ds` of
//! the minimal path from `y` to the sources, so the answer is the
//! sensitivity of that path's length to the cost of every cell (the path's
//! own move does not enter at first order). The misfit is the travel-time
//! objective of tomography: `T_m` the observed times.
//!
//! With a tensor `metric` instead of a `cost` the forward solve is the
//! anisotropic fast marching and the answer is `∂J/∂m` for every component
//! `m` of the metric at every cell
//! ([`crate::numerics::anisotropic::metric_gradient`]).

use std::time::Instant;

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use ndarray::ArrayD;

use super::spec::cost::{resolve_cost, CostSpec, InterpretationSpec};
use super::spec::defaults::{default_order, default_true};
use super::spec::errors::eikonal_error;
use super::spec::grid::{check_point, check_spacing};
use super::spec::scheme::{
    metric_dataset_ids, resolve_sources, source_dataset_ids, stop_name, SourceSpec,
};
use super::spec::tensor::{resolve_tensor, tensor_solve_error, TensorSpec};
use super::{Inputs, OpError, OpLimits, OpOutput, Operation, OutputArray};
use crate::io::ArrayData;
use crate::numerics::anisotropic::{self, metric_gradient, TensorOptions, TensorSolveError};
use crate::numerics::eikonal::{
    adjoint_options, cost_gradient, probe_values, EikonalError, EikonalOptions, EikonalProblem,
    Order, Probe, StopReason,
};
use crate::numerics::{self, Control};

/// Request of `grid.cost_gradient` (`POST /v1/grid/cost-gradient`, job
/// operation `grid.cost_gradient`, `geodex cost-gradient`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({
    "cost": {"constant": 1.0, "shape": [128, 128]},
    "sources": [{"point": [64.0, 10.0]}],
    "targets": [{"point": [64.0, 118.0]}],
    "order": 2
}))]
pub struct GridCostGradientRequest {
    /// The isotropic metric: a cost (or speed) dataset, a constant over a
    /// shape, or a cost designed from an image. The gradient is taken with
    /// respect to the values as given: the cost `W`, or the speed `F = 1/W`
    /// with `interpretation: speed` (`∂J/∂F = −W² ∂J/∂W`); with a `design`,
    /// with respect to the designed cost. Give exactly one of `cost` and
    /// `metric`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cost: Option<CostSpec>,
    /// A Riemannian metric (tensor field `M`, as in `grid.distance`) instead
    /// of `cost`: the gradient is then taken with respect to each component
    /// of `M` at every cell (`[m00, m01, m11]` in 2D, `[m00, m01, m02, m11,
    /// m12, m22]` in 3D; an off-diagonal component moves `M_ab` and `M_ba`
    /// together), an array of the grid's shape plus one axis of 3 or 6.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub metric: Option<TensorSpec>,
    /// Physical size of a cell along each axis (axis 0 first). Default: the
    /// cost dataset's, else 1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(min_items = 2, max_items = 3)]
    pub spacing: Option<Vec<f64>>,
    /// Id of a dataset of the grid's shape whose non-zero cells are walls
    /// (their gradient is 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub obstacles: Option<String>,
    /// The sources: `point`, `cells` (with `values`) or `mask`; not
    /// `level_set`.
    #[schema(min_items = 1)]
    pub sources: Vec<SourceSpec>,
    /// Where the distance is read: the terms of the objective.
    #[schema(min_items = 1)]
    pub targets: Vec<TargetSpec>,
    /// The objective: `sum` (default) or `misfit` (needs `observed` on every
    /// target).
    #[serde(default)]
    pub objective: ObjectiveSpec,
    /// Order of the fast-marching scheme that is differentiated, 1 or 2
    /// (unfactored; the forward solve is that very scheme). Default: 2.
    #[serde(default = "default_order")]
    #[schema(minimum = 1, maximum = 2)]
    pub order: u8,
    /// Return the distance map too (`distance`). Default: true.
    #[serde(default = "default_true")]
    pub distance: bool,
}

/// One target point of the objective.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct TargetSpec {
    /// A point in index coordinates (axis 0 first), possibly between cells:
    /// `U` there is the multilinear interpolation of the cells around it,
    /// which must all be reached.
    #[schema(min_items = 2, max_items = 3)]
    pub point: Vec<f64>,
    /// Its weight `w_m` (finite). Default: 1.
    #[serde(default = "default_weight")]
    pub weight: f64,
    /// The observed distance `T_m` (a travel time), for `objective: misfit`;
    /// with `sum` it only adds the residual to the answer.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub observed: Option<f64>,
}

fn default_weight() -> f64 {
    1.0
}

/// The function of the target distances that is differentiated.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum ObjectiveSpec {
    /// `J = Σ_m w_m U(y_m)`.
    #[default]
    Sum,
    /// `J = ½ Σ_m w_m (U(y_m) − T_m)²`, `T_m` the targets' `observed`.
    Misfit,
}

impl GridCostGradientRequest {
    fn check(&self, limits: &OpLimits) -> Result<(), OpError> {
        match (&self.cost, &self.metric) {
            (Some(cost), None) => cost.validate(limits)?,
            (None, Some(metric)) => metric.validate("metric", limits)?,
            (Some(_), Some(_)) => {
                return Err(OpError::invalid(
                    "metric",
                    "give either an isotropic `cost` or a tensor `metric`, not both",
                ))
            }
            (None, None) => {
                return Err(OpError::invalid(
                    "cost",
                    "give the metric: an isotropic `cost` or a tensor `metric`",
                ))
            }
        }
        check_spacing(&self.spacing)?;
        if self.sources.is_empty() {
            return Err(OpError::invalid(
                "sources",
                "at least one source is required",
            ));
        }
        crate::ops::spec::scheme::check_source_count(&self.sources, limits)?;
        for (i, s) in self.sources.iter().enumerate() {
            s.check(&format!("sources[{i}]"))?;
            if s.level_set.is_some() {
                return Err(OpError::invalid(
                    format!("sources[{i}].level_set"),
                    "the gradient is taken through point, cell and mask sources; give the \
                     interface as `cells` with their `values` (from grid.distance of the level set)",
                ));
            }
        }
        if self.targets.is_empty() {
            return Err(OpError::invalid(
                "targets",
                "give at least one target point: the objective reads the distance there",
            ));
        }
        if self.targets.len() > limits.max_sources {
            return Err(OpError::TooLarge {
                field: "targets".into(),
                reason: format!(
                    "{} targets, more than the limit of {}",
                    self.targets.len(),
                    limits.max_sources
                ),
            });
        }
        for (m, t) in self.targets.iter().enumerate() {
            check_point(&t.point, &format!("targets[{m}].point"), None)?;
            if !t.weight.is_finite() {
                return Err(OpError::invalid(
                    format!("targets[{m}].weight"),
                    format!("{} must be finite", t.weight),
                ));
            }
            match t.observed {
                Some(o) if !o.is_finite() => {
                    return Err(OpError::invalid(
                        format!("targets[{m}].observed"),
                        format!("{o} must be finite"),
                    ))
                }
                None if self.objective == ObjectiveSpec::Misfit => {
                    return Err(OpError::invalid(
                        format!("targets[{m}].observed"),
                        "the misfit objective needs the observed distance of every target",
                    ))
                }
                _ => {}
            }
        }
        if !matches!(self.order, 1 | 2) {
            return Err(OpError::invalid(
                "order",
                format!("{} must be 1 or 2", self.order),
            ));
        }
        Ok(())
    }

    /// The forward solve whose adjoint is taken ([`adjoint_options`] of the
    /// request's order).
    pub fn options(&self) -> EikonalOptions {
        adjoint_options(if self.order == 1 {
            Order::First
        } else {
            Order::Second
        })
    }
}

impl Operation for GridCostGradientRequest {
    const NAME: &'static str = "grid.cost_gradient";

    fn validate(&self, limits: &OpLimits) -> Result<(), OpError> {
        self.check(limits)
    }

    fn dataset_ids(&self) -> Vec<(String, String)> {
        let mut ids = metric_dataset_ids(self.cost.as_ref(), self.metric.as_ref());
        if let Some(id) = &self.obstacles {
            ids.push(("obstacles".into(), id.clone()));
        }
        ids.extend(source_dataset_ids(&self.sources));
        ids
    }

    /// Arrays: `gradient` (f64, the grid's shape: `∂J/∂W`, or `∂J/∂F` for a
    /// speed; 0 on walls and unreached cells) and `distance` (f64, unless
    /// `distance: false`). Document: `objective` (`kind`, `value`),
    /// `targets` (`distance`, `residual` where observed), `with_respect_to`
    /// (`cost` or `speed`), `stats`.
    fn run(
        &self,
        inputs: &dyn Inputs,
        limits: &OpLimits,
        control: &Control<'_>,
    ) -> Result<OpOutput, OpError> {
        self.check(limits)?;
        let solved = match (&self.cost, &self.metric) {
            (Some(cost), _) => self.solve_isotropic(cost, inputs, limits, control)?,
            (None, Some(metric)) => self.solve_tensor(metric, inputs, limits, control)?,
            (None, None) => return Err(OpError::invalid("cost", "missing")),
        };
        let residuals = self.residuals(&solved.values);
        let spacing = Some(solved.spacing);
        let cells = solved.distance.len();
        let mut arrays = vec![OutputArray {
            name: "gradient".into(),
            array: ArrayData::F64(solved.gradient),
            spacing: spacing.clone(),
        }];
        if self.distance {
            arrays.push(OutputArray {
                name: "distance".into(),
                array: ArrayData::F64(solved.distance),
                spacing,
            });
        }
        let targets: Vec<serde_json::Value> = solved
            .values
            .iter()
            .zip(&residuals)
            .map(|(u, r)| match r {
                Some(r) => serde_json::json!({"distance": u, "residual": r}),
                None => serde_json::json!({"distance": u}),
            })
            .collect();
        let kind = match self.objective {
            ObjectiveSpec::Sum => "sum",
            ObjectiveSpec::Misfit => "misfit",
        };
        Ok(OpOutput::new(
            arrays,
            serde_json::json!({
                "objective": {"kind": kind, "value": self.objective_value(&solved.values)},
                "targets": targets,
                "with_respect_to": solved.with_respect_to,
                "stats": {
                    "cells": cells,
                    "frozen": solved.frozen,
                    "stop": stop_name(solved.stop),
                    "order": self.order,
                    "solve_seconds": solved.solve_seconds,
                    "gradient_seconds": solved.gradient_seconds,
                },
            }),
        ))
    }
}

/// A forward solve and its adjoint, isotropic or tensor.
struct Solved {
    gradient: ArrayD<f64>,
    distance: ArrayD<f64>,
    values: Vec<f64>,
    spacing: Vec<f64>,
    frozen: usize,
    stop: StopReason,
    with_respect_to: &'static str,
    solve_seconds: f64,
    gradient_seconds: f64,
}

impl GridCostGradientRequest {
    fn probes(&self) -> Vec<Probe> {
        self.targets
            .iter()
            .map(|t| Probe::Point(t.point.clone()))
            .collect()
    }

    fn residuals(&self, values: &[f64]) -> Vec<Option<f64>> {
        self.targets
            .iter()
            .zip(values)
            .map(|(t, u)| t.observed.map(|o| u - o))
            .collect()
    }

    /// `J` at the target values `U(y_m)`.
    fn objective_value(&self, values: &[f64]) -> f64 {
        let terms = self.targets.iter().zip(values);
        match self.objective {
            ObjectiveSpec::Sum => terms.map(|(t, u)| t.weight * u).sum(),
            ObjectiveSpec::Misfit => {
                0.5 * terms
                    .map(|(t, u)| {
                        let r = u - t.observed.unwrap_or(*u);
                        t.weight * r * r
                    })
                    .sum::<f64>()
            }
        }
    }

    /// The adjoint's weights `∂J/∂U(y_m)`: `w_m`, or `w_m (U(y_m) − T_m)`.
    fn adjoint_weights(&self, values: &[f64]) -> Vec<(Probe, f64)> {
        self.probes()
            .into_iter()
            .zip(self.targets.iter().zip(values))
            .map(|(p, (t, u))| match self.objective {
                ObjectiveSpec::Sum => (p, t.weight),
                ObjectiveSpec::Misfit => (p, t.weight * (u - t.observed.unwrap_or(*u))),
            })
            .collect()
    }

    fn check_targets(&self, ndim: usize) -> Result<(), OpError> {
        for (m, t) in self.targets.iter().enumerate() {
            check_point(&t.point, &format!("targets[{m}].point"), Some(ndim))?;
        }
        Ok(())
    }

    fn solve_isotropic(
        &self,
        cost: &CostSpec,
        inputs: &dyn Inputs,
        limits: &OpLimits,
        control: &Control<'_>,
    ) -> Result<Solved, OpError> {
        let resolved = resolve_cost(
            cost,
            self.spacing.as_deref(),
            self.obstacles.as_deref(),
            inputs,
            limits,
            control,
        )?;
        let cost_field = resolved.isotropic()?;
        let grid = resolved.grid.clone();
        self.check_targets(grid.ndim())?;
        let sources = resolve_sources(&self.sources, &grid, &cost_field, inputs, control)?;
        let problem = EikonalProblem {
            grid: grid.clone(),
            cost: cost_field,
            sources,
        };
        let options = self.options();
        let started = Instant::now();
        let out = numerics::solve(&problem, &options, control).map_err(eikonal_error)?;
        let solve_seconds = started.elapsed().as_secs_f64();

        let values = probe_values(&grid, &out, &self.probes()).map_err(target_error)?;
        let started = Instant::now();
        let weights = self.adjoint_weights(&values);
        let mut gradient =
            cost_gradient(&problem, &options, &out, &weights, control).map_err(target_error)?;
        let speed = cost.interpretation == InterpretationSpec::Speed;
        if speed {
            // `W = 1/F`: `∂J/∂F = −W² ∂J/∂W` (0 on walls, where `W = +inf`).
            for (i, g) in gradient.iter_mut().enumerate() {
                let w = problem.cost.at(i);
                *g = if w.is_finite() { -w * w * *g } else { 0.0 };
            }
        }
        Ok(Solved {
            gradient,
            distance: out.distance,
            values,
            spacing: resolved.spacing.clone(),
            frozen: out.frozen,
            stop: out.stop,
            with_respect_to: if speed { "speed" } else { "cost" },
            solve_seconds,
            gradient_seconds: started.elapsed().as_secs_f64(),
        })
    }

    fn solve_tensor(
        &self,
        metric: &TensorSpec,
        inputs: &dyn Inputs,
        limits: &OpLimits,
        control: &Control<'_>,
    ) -> Result<Solved, OpError> {
        let resolved = resolve_tensor(
            metric,
            "metric",
            self.spacing.as_deref(),
            self.obstacles.as_deref(),
            inputs,
            limits,
            control,
        )?;
        self.check_targets(resolved.grid.ndim())?;
        // Masks are cells at 0; walls are the tensor's own.
        let unit = numerics::IsotropicCost::constant(1.0)
            .map_err(|e| OpError::invalid("metric", e.to_string()))?;
        let sources = resolve_sources(&self.sources, &resolved.grid, &unit, inputs, control)?;
        let (problem, spacing) = resolved.into_problem(sources);
        let mut options = TensorOptions::DEFAULT
            .with_order(if self.order == 1 {
                Order::First
            } else {
                Order::Second
            })
            .with_factoring(false);
        options.record_order = true;
        let started = Instant::now();
        let out = anisotropic::solve(&problem, &options, control).map_err(tensor_error)?;
        let solve_seconds = started.elapsed().as_secs_f64();
        let values =
            probe_values(&problem.grid, &out.output, &self.probes()).map_err(target_error)?;
        let started = Instant::now();
        let weights = self.adjoint_weights(&values);
        let gradient =
            metric_gradient(&problem, &options, &out, &weights, control).map_err(tensor_error)?;
        Ok(Solved {
            gradient,
            distance: out.output.distance,
            values,
            spacing,
            frozen: out.output.frozen,
            stop: out.output.stop,
            with_respect_to: "metric",
            solve_seconds,
            gradient_seconds: started.elapsed().as_secs_f64(),
        })
    }
}

/// A tensor solve's or adjoint's error, naming the field at fault.
fn tensor_error(e: TensorSolveError) -> OpError {
    match e {
        TensorSolveError::Solve(e) => target_error(e),
        other => tensor_solve_error(other, "metric"),
    }
}

/// A core error of the probes or the adjoint, naming the target at fault
/// (`weights[m]` in the core is `targets[m]` here).
fn target_error(e: EikonalError) -> OpError {
    match e {
        EikonalError::Option {
            field: "weights",
            reason,
        } => {
            let field = reason
                .strip_prefix("weights[")
                .and_then(|r| r.split_once(']'))
                .map_or("targets".to_string(), |(m, _)| {
                    format!("targets[{m}].point")
                });
            let reason = reason
                .split_once(": ")
                .map_or(reason.as_str(), |(_, r)| r)
                .to_string();
            OpError::invalid(
                field,
                format!("{reason}; move the target into the region the sources reach"),
            )
        }
        other => eikonal_error(other),
    }
}
