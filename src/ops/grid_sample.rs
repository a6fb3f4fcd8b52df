//! `grid.sample`: farthest-point sampling of a grid under an isotropic cost
//! (see [`crate::numerics::sampling::farthest`]) or a Riemannian metric
//! (a tensor field, [`crate::numerics::sampling::tensor_farthest`]): the
//! samples, the distance to the nearest sample and the geodesic Voronoi
//! labels.

use std::time::Instant;

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::spec::cost::{resolve_cost, CostSpec};
use super::spec::grid::{check_spacing, shaped};
use super::spec::scheme::metric_dataset_ids;
use super::spec::tensor::{resolve_tensor, TensorSpec};
use super::{Inputs, OpError, OpLimits, OpOutput, Operation, OutputArray};
use crate::io::ArrayData;
use crate::numerics::sampling::{
    farthest_point_sampling, tensor_farthest_point_sampling, SamplingError, SamplingMethod,
    SamplingOptions, SamplingStop,
};
use crate::numerics::Control;

/// How `grid.sample` places its samples.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum GridSamplingSpec {
    /// `clustered` under a `cost` without obstacles or infinite cells that
    /// varies by at most a factor 2 within blocks of 3 cells, when the grid
    /// holds at least 8 blocks of 3 (or 2) cells per axis per sample and 64
    /// samples or more are asked; else `exact`.
    #[default]
    Auto,
    /// Each sample is the cell farthest from the previous ones (a local
    /// front per sample: about `ln count + 0.6` full maps of work).
    Exact,
    /// Exact farthest points on the grid of blocks of 3 (or 2) cells per
    /// axis, then one front per sample on the grid from the coarse map's
    /// bound (about 1.3 full maps plus the coarse sampling); then exact
    /// samples if the covering radius is still above `radius`. Covers
    /// within a few per cent of `exact`. Not with `metric`.
    Clustered,
}

/// Request of `grid.sample` (`POST /v1/grid/sample`, `geodex sample`). Give
/// `count`, `radius` or both (sampling stops at the first reached).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"cost": {"constant": 1.0, "shape": [256, 256]}, "count": 100}))]
pub struct GridSampleRequest {
    /// The isotropic metric, exactly as in `grid.distance`. Give exactly one
    /// of `cost` and `metric`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cost: Option<CostSpec>,
    /// A Riemannian metric (tensor field `M`, exactly as `metric` in
    /// `grid.distance` and `tensor` in `grid.tensor_distance`) instead of
    /// `cost`: the fronts use the anisotropic solver's adaptive stencils
    /// (first order), the Voronoi cells are those of the metric. Give
    /// exactly one of `cost` and `metric`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub metric: Option<TensorSpec>,
    /// Physical size of a cell along each axis. Default: the cost dataset's, else 1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(min_items = 2, max_items = 3)]
    pub spacing: Option<Vec<f64>>,
    /// Id of a mask dataset whose non-zero cells are obstacles (never sampled).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub obstacles: Option<String>,
    /// Number of samples, seeds included (at most the number of cells).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(minimum = 1)]
    pub count: Option<usize>,
    /// Stop once every reachable cell is within this geodesic distance of a sample.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(exclusive_minimum = 0.0)]
    pub radius: Option<f64>,
    /// Fixed first samples: cells in index coordinates (axis 0 first), kept
    /// in this order. Default: none (the first sample is the cell farthest
    /// from the first open cell).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub seeds: Vec<Vec<usize>>,
    /// How the samples are placed. Default `auto`.
    #[serde(default)]
    pub sampling: GridSamplingSpec,
}

impl Operation for GridSampleRequest {
    const NAME: &'static str = "grid.sample";

    fn validate(&self, limits: &OpLimits) -> Result<(), OpError> {
        let shape: Option<Vec<usize>> = match (&self.cost, &self.metric) {
            (Some(cost), None) => {
                cost.validate(limits)?;
                cost.shape.clone()
            }
            (None, Some(metric)) => {
                metric.validate("metric", limits)?;
                if self.sampling == GridSamplingSpec::Clustered {
                    return Err(OpError::invalid(
                        "sampling",
                        "clustered sampling needs an isotropic `cost`: use `auto` or `exact` with `metric`",
                    ));
                }
                match metric {
                    TensorSpec::Constant(c) => Some(c.shape.clone()),
                    TensorSpec::Eigen(e) => Some(e.shape.clone()),
                    _ => None,
                }
            }
            (Some(_), Some(_)) => {
                return Err(OpError::invalid(
                    "metric",
                    "give either `cost` (isotropic) or `metric` (a tensor field), not both",
                ))
            }
            (None, None) => {
                return Err(OpError::invalid(
                    "cost",
                    "missing: give `cost` (isotropic) or `metric` (a tensor field)",
                ))
            }
        };
        check_spacing(&self.spacing)?;
        let cells = shape
            .as_ref()
            .map(|s| s.iter().fold(1usize, |a, &n| a.saturating_mul(n)));
        match (self.count, self.radius) {
            (None, None) => {
                return Err(OpError::invalid("count", "give `count`, `radius` or both"))
            }
            (Some(0), _) => return Err(OpError::invalid("count", "must be >= 1")),
            (Some(c), _) if c > limits.max_sources => {
                return Err(OpError::TooLarge {
                    field: "count".into(),
                    reason: format!("more than {} samples", limits.max_sources),
                })
            }
            (Some(c), _) if cells.is_some_and(|n| c > n) => {
                return Err(OpError::invalid(
                    "count",
                    format!(
                        "{c} is larger than the number of cells ({})",
                        cells.unwrap_or(0)
                    ),
                ))
            }
            (Some(c), _) if c < self.seeds.len() => {
                return Err(OpError::invalid(
                    "count",
                    format!(
                        "{c} is smaller than the number of seeds ({})",
                        self.seeds.len()
                    ),
                ))
            }
            _ => {}
        }
        if let Some(r) = self.radius {
            if !(r.is_finite() && r > 0.0) {
                return Err(OpError::invalid(
                    "radius",
                    format!("{r} must be finite and > 0"),
                ));
            }
        }
        if self.seeds.len() > limits.max_sources {
            return Err(OpError::TooLarge {
                field: "seeds".into(),
                reason: format!("more than {} seeds", limits.max_sources),
            });
        }
        let ndim = shape.as_ref().map(Vec::len);
        for (i, seed) in self.seeds.iter().enumerate() {
            if !(2..=3).contains(&seed.len()) || ndim.is_some_and(|d| d != seed.len()) {
                return Err(OpError::invalid(
                    format!("seeds[{i}]"),
                    format!("a cell has 2 or 3 indices, one per axis of the grid; got {seed:?}"),
                ));
            }
        }
        Ok(())
    }

    fn dataset_ids(&self) -> Vec<(String, String)> {
        let mut ids = metric_dataset_ids(self.cost.as_ref(), self.metric.as_ref());
        if let Some(id) = &self.obstacles {
            ids.push(("obstacles".to_string(), id.clone()));
        }
        ids
    }

    /// Arrays: `distance` (f64, to the nearest sample, +inf where not
    /// reached), `labels` (int32, index of the nearest sample, -1 where not
    /// reached). Document: `{"samples": [[i, j(, k)], ...], "stats":
    /// {"samples", "covering_radius", "radii", "stop", "visited",
    /// "sampling": {"method", and for `clustered`: "block", "coarse_cells",
    /// "repaired", "refined"}, "seconds"}}`. Under `clustered` the `radii`
    /// of the coarse samples are the coarse grid's; the last is the grid's.
    fn run(
        &self,
        inputs: &dyn Inputs,
        limits: &OpLimits,
        control: &Control<'_>,
    ) -> Result<OpOutput, OpError> {
        self.validate(limits)?;
        let options = SamplingOptions {
            count: self.count,
            radius: self.radius,
            seeds: self.seeds.clone(),
            method: match self.sampling {
                GridSamplingSpec::Auto => SamplingMethod::Auto,
                GridSamplingSpec::Exact => SamplingMethod::Exact,
                GridSamplingSpec::Clustered => SamplingMethod::Clustered,
            },
        };
        let (grid, spacing, s, seconds) = match (&self.cost, &self.metric) {
            (Some(cost), _) => {
                let resolved = resolve_cost(
                    cost,
                    self.spacing.as_deref(),
                    self.obstacles.as_deref(),
                    inputs,
                    limits,
                    control,
                )?;
                let iso = resolved.isotropic()?;
                let started = Instant::now();
                let s = farthest_point_sampling(&resolved.grid, &iso, &options, control)
                    .map_err(|e| sampling_error(e, "cost"))?;
                let seconds = started.elapsed().as_secs_f64();
                (resolved.grid.clone(), resolved.spacing.clone(), s, seconds)
            }
            (None, Some(metric)) => {
                let resolved = resolve_tensor(
                    metric,
                    "metric",
                    self.spacing.as_deref(),
                    self.obstacles.as_deref(),
                    inputs,
                    limits,
                    control,
                )?;
                let started = Instant::now();
                let s = tensor_farthest_point_sampling(
                    &resolved.grid,
                    &resolved.metric,
                    &options,
                    control,
                )
                .map_err(|e| sampling_error(e, "metric"))?;
                let seconds = started.elapsed().as_secs_f64();
                (resolved.grid, resolved.spacing, s, seconds)
            }
            (None, None) => return Err(OpError::invalid("cost", "missing")),
        };
        let grid = &grid;
        let spacing = Some(spacing);
        let document = serde_json::json!({
            "samples": s.samples,
            "stats": {
                "samples": s.samples.len(),
                "covering_radius": s.covering_radius,
                "radii": s.radii,
                "stop": match s.stop {
                    SamplingStop::Count => "count",
                    SamplingStop::Radius => "radius",
                    SamplingStop::Exhausted => "exhausted",
                },
                "visited": s.visited,
                "sampling": match &s.clustered {
                    Some(c) => serde_json::json!({
                        "method": "clustered",
                        "block": c.block,
                        "coarse_cells": c.coarse_cells,
                        "repaired": c.repaired,
                        "refined": c.refined,
                    }),
                    None => serde_json::json!({"method": "exact"}),
                },
                "seconds": seconds,
            },
        });
        Ok(OpOutput::new(
            vec![
                OutputArray {
                    name: "distance".into(),
                    array: ArrayData::F64(shaped(grid, s.distance)?),
                    spacing: spacing.clone(),
                },
                OutputArray {
                    name: "labels".into(),
                    array: ArrayData::I32(shaped(grid, s.labels)?),
                    spacing,
                },
            ],
            document,
        ))
    }
}

/// A sampling error as an [`OpError`] naming the request field (`metric_field`:
/// `cost` or `metric`, where the metric is at fault).
fn sampling_error(e: SamplingError, metric_field: &str) -> OpError {
    match e {
        SamplingError::Cancelled => OpError::Cancelled,
        SamplingError::Seed { index, reason } => {
            OpError::invalid(format!("seeds[{index}]"), reason)
        }
        SamplingError::Radius(_) => OpError::invalid("radius", e.to_string()),
        SamplingError::Method(_) => OpError::invalid("sampling", e.to_string()),
        SamplingError::NoOpenCell | SamplingError::Dimension { .. } => {
            OpError::invalid(metric_field, e.to_string())
        }
        SamplingError::NoStopRule
        | SamplingError::Count { .. }
        | SamplingError::FewerThanSeeds { .. } => OpError::invalid("count", e.to_string()),
    }
}
