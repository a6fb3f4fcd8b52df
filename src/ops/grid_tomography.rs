//! `grid.tomography`: first-arrival travel-time tomography, a slowness
//! (cost) map recovered from the times measured between sources and
//! receivers (see [`crate::numerics::inverse::tomography`]). A long run:
//! submit it as a job (`POST /v1/jobs` with `"operation": "grid.tomography"`)
//! to follow its progress.

use std::time::Instant;

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::spec::errors::{eikonal_error, grid_error};
use super::spec::grid::{check_point, check_shape, check_spacing, shaped};
use super::{Inputs, OpError, OpLimits, OpOutput, Operation, OutputArray};
use crate::io::ArrayData;
use crate::numerics::inverse::tomography::{
    tomography, TomographyError, TomographyOptions, TomographyProblem,
};
use crate::numerics::{Control, Grid, Order};

/// The most measured times in one request.
pub const MAX_TIMES: usize = 1_000_000;
/// The most iterations in one request.
pub const MAX_ITERATIONS: usize = 1000;

/// Request of `grid.tomography` (`POST /v1/grid/tomography`).
///
/// Minimises `½ Σ_s Σ_r (U_s(y_r) − T_sr)² + (α/2) ‖∇W‖²` over the cost `W`
/// in `[min_cost, max_cost]`, `U_s` the fast-marching distance from source
/// `s` (unfactored, of `order`), from the best constant map, by projected
/// gradient descent with the adjoint of fast marching (monotone line search:
/// the misfit never increases).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"shape": [64, 64], "sources": [{"point": [0.0, 0.0]}, {"point": [0.0, 63.0]}], "receivers": [{"point": [63.0, 0.0]}, {"point": [63.0, 63.0]}], "times": [[63.0, 89.1], [89.1, 63.0]], "alpha": 0.5}))]
pub struct GridTomographyRequest {
    /// Grid shape (2 or 3 axes).
    #[schema(min_items = 2, max_items = 3)]
    pub shape: Vec<usize>,
    /// Physical size of a cell along each axis (axis 0 first). Default: 1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(min_items = 2, max_items = 3)]
    pub spacing: Option<Vec<f64>>,
    /// Source points (index coordinates, axis 0 first), inside the grid.
    #[schema(min_items = 1)]
    pub sources: Vec<SurveyPoint>,
    /// Receiver points (index coordinates, axis 0 first), inside the grid.
    #[schema(min_items = 1)]
    pub receivers: Vec<SurveyPoint>,
    /// The measured travel times: one row per source, one value per
    /// receiver, finite and `>= 0` (physical units: `∫ W ds`).
    pub times: Vec<Vec<f64>>,
    /// Weight `α >= 0` of the smoothness term `(α/2) Σ ((W_{x+e_k} − W_x)/h_k)²`. Default: 0.
    #[serde(default)]
    #[schema(minimum = 0.0)]
    pub alpha: f64,
    /// Lower bound of `W` (> 0). Default: a tenth of the best constant.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(exclusive_minimum = 0.0)]
    pub min_cost: Option<f64>,
    /// Upper bound of `W`. Default: ten times the best constant.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(exclusive_minimum = 0.0)]
    pub max_cost: Option<f64>,
    /// Largest number of descent steps (1 to 1000). Default: 50.
    #[serde(default = "default_iterations")]
    #[schema(minimum = 1, maximum = 1000)]
    pub max_iterations: usize,
    /// Stop when a step lowers the objective by less than `tolerance ×` it. Default: 1e-6.
    #[serde(default = "default_tolerance")]
    #[schema(minimum = 0.0)]
    pub tolerance: f64,
    /// Order of the fast marching, 1 or 2. Default: 1.
    #[serde(default = "default_order_one")]
    pub order: u8,
}

/// A source or receiver of a survey: `{"point": [...]}`, the shape of a
/// point source elsewhere in the API.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct SurveyPoint {
    /// Index coordinates (axis 0 first), inside the grid, possibly between cells.
    #[schema(min_items = 2, max_items = 3)]
    pub point: Vec<f64>,
}

fn default_iterations() -> usize {
    50
}
fn default_tolerance() -> f64 {
    1e-6
}
fn default_order_one() -> u8 {
    1
}

impl GridTomographyRequest {
    fn check(&self, limits: &OpLimits) -> Result<(), OpError> {
        check_shape(&self.shape, "shape", limits)?;
        let ndim = self.shape.len();
        if let Some(s) = &self.spacing {
            if s.len() != ndim {
                return Err(OpError::invalid(
                    "spacing",
                    format!("{} spacings for a grid of {ndim} axes", s.len()),
                ));
            }
        }
        check_spacing(&self.spacing)?;
        for (field, points) in [("sources", &self.sources), ("receivers", &self.receivers)] {
            if points.is_empty() {
                return Err(OpError::invalid(field, "give at least one point"));
            }
            if points.len() > limits.max_sources {
                return Err(OpError::TooLarge {
                    field: field.into(),
                    reason: format!("more than {} points", limits.max_sources),
                });
            }
            for (k, p) in points.iter().enumerate() {
                let p = &p.point;
                let name = format!("{field}[{k}].point");
                check_point(p, &name, Some(ndim))?;
                if let Some(a) =
                    (0..ndim).find(|&a| !(0.0..=(self.shape[a] - 1) as f64).contains(&p[a]))
                {
                    return Err(OpError::invalid(
                        format!("{name}[{a}]"),
                        format!(
                            "{} is outside the grid (axis {a} runs from 0 to {})",
                            p[a],
                            self.shape[a] - 1
                        ),
                    ));
                }
            }
        }
        let (ns, nr) = (self.sources.len(), self.receivers.len());
        if ns.saturating_mul(nr) > MAX_TIMES {
            return Err(OpError::TooLarge {
                field: "times".into(),
                reason: format!("{ns} × {nr} times, more than the limit of {MAX_TIMES}"),
            });
        }
        if self.times.len() != ns {
            return Err(OpError::invalid(
                "times",
                format!(
                    "{} rows for {ns} sources: give one row per source",
                    self.times.len()
                ),
            ));
        }
        for (s, row) in self.times.iter().enumerate() {
            if row.len() != nr {
                return Err(OpError::invalid(
                    format!("times[{s}]"),
                    format!(
                        "{} times for {nr} receivers: give one per receiver",
                        row.len()
                    ),
                ));
            }
            if let Some(r) = row.iter().position(|t| !(t.is_finite() && *t >= 0.0)) {
                return Err(OpError::invalid(
                    format!("times[{s}][{r}]"),
                    format!("{} must be finite and >= 0", row[r]),
                ));
            }
        }
        if !(self.alpha.is_finite() && self.alpha >= 0.0) {
            return Err(OpError::invalid(
                "alpha",
                format!("{} must be finite and >= 0", self.alpha),
            ));
        }
        for (field, v) in [("min_cost", self.min_cost), ("max_cost", self.max_cost)] {
            if let Some(v) = v {
                if !(v.is_finite() && v > 0.0) {
                    return Err(OpError::invalid(
                        field,
                        format!("{v} must be finite and > 0"),
                    ));
                }
            }
        }
        if let (Some(lo), Some(hi)) = (self.min_cost, self.max_cost) {
            if lo > hi {
                return Err(OpError::invalid(
                    "max_cost",
                    format!("{hi} is below min_cost {lo}"),
                ));
            }
        }
        if !(1..=MAX_ITERATIONS).contains(&self.max_iterations) {
            return Err(OpError::invalid(
                "max_iterations",
                format!("{} must be in 1..={MAX_ITERATIONS}", self.max_iterations),
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

impl Operation for GridTomographyRequest {
    const NAME: &'static str = "grid.tomography";

    fn validate(&self, limits: &OpLimits) -> Result<(), OpError> {
        self.check(limits)
    }

    fn dataset_ids(&self) -> Vec<(String, String)> {
        Vec::new()
    }

    /// Arrays: `cost` (f64, the recovered `W`). Document: `{"constant_cost",
    /// "bounds", "misfit": {"constant", "final", "history"}, "objective",
    /// "iterations", "stop", "rms_residual", "predicted", "stats": {"cells",
    /// "sources", "receivers", "solves", "seconds"}}`.
    fn run(
        &self,
        _inputs: &dyn Inputs,
        limits: &OpLimits,
        control: &Control<'_>,
    ) -> Result<OpOutput, OpError> {
        self.check(limits)?;
        let spacing = self
            .spacing
            .clone()
            .unwrap_or_else(|| vec![1.0; self.shape.len()]);
        let grid = Grid::new(&self.shape, &spacing).map_err(|e| grid_error(e, &self.shape))?;
        let times: Vec<f64> = self.times.iter().flatten().copied().collect();
        let sources: Vec<Vec<f64>> = self.sources.iter().map(|s| s.point.clone()).collect();
        let receivers: Vec<Vec<f64>> = self.receivers.iter().map(|r| r.point.clone()).collect();
        let problem = TomographyProblem {
            grid: grid.clone(),
            sources: &sources,
            receivers: &receivers,
            times: &times,
        };
        let options = TomographyOptions {
            alpha: self.alpha,
            min_cost: self.min_cost,
            max_cost: self.max_cost,
            max_iterations: self.max_iterations,
            tolerance: self.tolerance,
            order: if self.order == 2 {
                Order::Second
            } else {
                Order::First
            },
        };
        let started = Instant::now();
        let out = tomography(&problem, &options, control).map_err(|e| match e {
            TomographyError::Cancelled => OpError::Cancelled,
            TomographyError::Eikonal(e) => eikonal_error(e),
            TomographyError::Input { field, reason } => {
                let field = if field == "bounds" { "min_cost" } else { field };
                OpError::invalid(field, reason)
            }
        })?;
        let seconds = started.elapsed().as_secs_f64();
        let nr = self.receivers.len();
        let predicted: Vec<&[f64]> = out.predicted.chunks(nr).collect();
        let rms = (2.0 * out.final_misfit() / times.len() as f64).sqrt();
        let document = serde_json::json!({
            "constant_cost": out.constant,
            "bounds": [out.bounds.0, out.bounds.1],
            "misfit": {
                "constant": out.constant_misfit(),
                "final": out.final_misfit(),
                "history": out.history.iter().map(|i| i.misfit).collect::<Vec<_>>(),
            },
            "objective": out.history.iter().map(|i| i.objective).collect::<Vec<_>>(),
            "iterations": out.history.len() - 1,
            "stop": out.stop.as_str(),
            "rms_residual": rms,
            "predicted": predicted,
            "stats": {
                "cells": grid.len(),
                "sources": self.sources.len(),
                "receivers": nr,
                "solves": out.solves,
                "seconds": seconds,
            },
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
