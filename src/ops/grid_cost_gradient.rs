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

use std::time::Instant;

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::spec::cost::{resolve_cost, CostSpec, InterpretationSpec};
use super::spec::defaults::{default_order, default_true};
use super::spec::errors::eikonal_error;
use super::spec::grid::{check_point, check_spacing, shaped};
use super::spec::scheme::{resolve_sources, source_dataset_ids, stop_name, SourceSpec};
use super::{Inputs, OpError, OpLimits, OpOutput, Operation, OutputArray};
use crate::io::ArrayData;
use crate::numerics::eikonal::{
    cost_gradient, probe_values, EikonalError, EikonalOptions, EikonalProblem, Method, Order, Probe,
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
    /// with respect to the designed cost.
    pub cost: CostSpec,
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
        self.cost.validate(limits)?;
        check_spacing(&self.spacing)?;
        if self.sources.is_empty() {
            return Err(OpError::invalid(
                "sources",
                "at least one source is required",
            ));
        }
        if self.sources.len() > limits.max_sources {
            return Err(OpError::TooLarge {
                field: "sources".into(),
                reason: format!(
                    "{} sources, more than the limit of {}",
                    self.sources.len(),
                    limits.max_sources
                ),
            });
        }
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

    /// The forward solve whose adjoint is taken: unfactored fast marching of
    /// the request's order, recording its freezing order (which order 2
    /// needs and which spares order 1 a sort).
    pub fn options(&self) -> EikonalOptions {
        let order = if self.order == 1 {
            Order::First
        } else {
            Order::Second
        };
        let mut o = EikonalOptions::DEFAULT
            .with_method(Method::FastMarching)
            .with_order(order)
            .with_factoring(false);
        o.record_order = true;
        o
    }
}

impl Operation for GridCostGradientRequest {
    const NAME: &'static str = "grid.cost_gradient";

    fn validate(&self, limits: &OpLimits) -> Result<(), OpError> {
        self.check(limits)
    }

    fn dataset_ids(&self) -> Vec<(String, String)> {
        let mut ids = Vec::new();
        if let Some(id) = &self.cost.dataset {
            ids.push(("cost.dataset".to_string(), id.clone()));
        }
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
        let resolved = resolve_cost(
            &self.cost,
            self.spacing.as_deref(),
            self.obstacles.as_deref(),
            inputs,
            limits,
            control,
        )?;
        let cost = resolved.isotropic()?;
        let grid = resolved.grid.clone();
        for (m, t) in self.targets.iter().enumerate() {
            check_point(&t.point, &format!("targets[{m}].point"), Some(grid.ndim()))?;
        }
        let sources = resolve_sources(&self.sources, &grid, &cost, inputs, control)?;
        let problem = EikonalProblem {
            grid: grid.clone(),
            cost,
            sources,
        };
        let options = self.options();
        let started = Instant::now();
        let out = numerics::solve(&problem, &options, control).map_err(eikonal_error)?;
        let solve_seconds = started.elapsed().as_secs_f64();

        let probes: Vec<Probe> = self
            .targets
            .iter()
            .map(|t| Probe::Point(t.point.clone()))
            .collect();
        let values = probe_values(&problem, &out, &probes).map_err(target_error)?;
        let residuals: Vec<Option<f64>> = self
            .targets
            .iter()
            .zip(&values)
            .map(|(t, u)| t.observed.map(|o| u - o))
            .collect();
        let (objective, weights): (f64, Vec<(Probe, f64)>) = match self.objective {
            ObjectiveSpec::Sum => (
                self.targets
                    .iter()
                    .zip(&values)
                    .map(|(t, u)| t.weight * u)
                    .sum(),
                probes
                    .into_iter()
                    .zip(&self.targets)
                    .map(|(p, t)| (p, t.weight))
                    .collect(),
            ),
            ObjectiveSpec::Misfit => {
                let r: Vec<f64> = residuals.iter().map(|r| r.unwrap_or(0.0)).collect();
                (
                    0.5 * self
                        .targets
                        .iter()
                        .zip(&r)
                        .map(|(t, r)| t.weight * r * r)
                        .sum::<f64>(),
                    probes
                        .into_iter()
                        .zip(self.targets.iter().zip(&r))
                        .map(|(p, (t, r))| (p, t.weight * r))
                        .collect(),
                )
            }
        };
        let started = Instant::now();
        let mut gradient =
            cost_gradient(&problem, &options, &out, &weights, control).map_err(target_error)?;
        let speed = self.cost.interpretation == InterpretationSpec::Speed;
        if speed {
            // `W = 1/F`: `∂J/∂F = −W² ∂J/∂W` (0 on walls, where `W = +inf`).
            for (i, g) in gradient.iter_mut().enumerate() {
                let w = problem.cost.at(i);
                *g = if w.is_finite() { -w * w * *g } else { 0.0 };
            }
        }
        let gradient_seconds = started.elapsed().as_secs_f64();

        let spacing = Some(resolved.spacing.clone());
        let mut arrays = vec![OutputArray {
            name: "gradient".into(),
            array: ArrayData::F64(gradient),
            spacing: spacing.clone(),
        }];
        if self.distance {
            arrays.push(OutputArray {
                name: "distance".into(),
                array: ArrayData::F64(shaped(&grid, out.distance.iter().copied().collect())?),
                spacing,
            });
        }
        let targets: Vec<serde_json::Value> = values
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
                "objective": {"kind": kind, "value": objective},
                "targets": targets,
                "with_respect_to": if speed { "speed" } else { "cost" },
                "stats": {
                    "cells": grid.len(),
                    "frozen": out.frozen,
                    "stop": stop_name(out.stop),
                    "order": self.order,
                    "solve_seconds": solve_seconds,
                    "gradient_seconds": gradient_seconds,
                },
            }),
        ))
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
