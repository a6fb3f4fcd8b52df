//! The scheme sections shared by the grid operations: sources, the solver
//! and its order, the Dijkstra neighbourhood, early stopping, optional
//! outputs, and the rule that a request gives exactly one of `cost` and
//! `metric`.

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::cost::CostSpec;
use super::tensor::TensorSpec;
use crate::numerics::eikonal::{Source, StopReason, StopRules};
use crate::ops::spec::defaults::default_true;
use crate::ops::{OpError, OpLimits};

/// One source: give `point`, or `cells` (with optional `values`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct SourceSpec {
    /// A point in index coordinates (axis 0 first), possibly between cells.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(min_items = 2, max_items = 3)]
    pub point: Option<Vec<f64>>,
    /// Cells (index triples or pairs, axis 0 first) that start with a given value.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cells: Option<Vec<Vec<usize>>>,
    /// Initial values of `cells` (default 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub values: Option<Vec<f64>>,
}

impl SourceSpec {
    /// The core source (a validated spec has exactly one of `point` and `cells`).
    pub fn to_source(&self) -> Source {
        match (&self.point, &self.cells) {
            (Some(p), _) => Source::Point(p.clone()),
            (None, Some(c)) => Source::Cells {
                cells: c.clone(),
                values: self.values.clone(),
            },
            (None, None) => Source::Point(Vec::new()),
        }
    }
}

/// The solver.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum MethodSpec {
    /// Fast marching, first or second order.
    #[default]
    FastMarching,
    /// Fast sweeping (Gauss–Seidel sweeps).
    FastSweeping,
    /// Dijkstra on the grid graph (metrication error, see `connectivity`).
    Dijkstra,
}

/// Grid-graph neighbourhood for `dijkstra`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum ConnectivitySpec {
    /// 4 neighbours in 2D, 6 in 3D (worst-case length error 41.4 % / 73.2 %).
    Axial,
    /// 8 neighbours in 2D, 18 in 3D (8.2 % / 22.5 %).
    #[default]
    Diagonal,
    /// 16 neighbours in 2D, 26 in 3D (2.79 % / 12.8 %).
    Extended,
}

/// Early stopping. Cells not computed keep `+inf` and label `-1`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct StopSpec {
    /// Stop once all these points (index coordinates) have their final value.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub targets: Vec<Vec<f64>>,
    /// Stop once the front passes this geodesic distance (a geodesic ball).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(minimum = 0.0)]
    pub max_distance: Option<f64>,
    /// Stop after this many cells have their final value.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_frozen: Option<u64>,
}

impl StopSpec {
    /// The core stopping rules.
    pub fn rules(&self) -> StopRules {
        StopRules {
            targets: self.targets.clone(),
            max_distance: self.max_distance,
            max_frozen: self.max_frozen.map(|n| n as usize),
        }
    }
}

/// Optional outputs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct OutputSpec {
    /// Return the Voronoi labels (int32, -1 where not reached). Default: true.
    #[serde(default = "default_true")]
    pub labels: bool,
    /// Return the rank at which each cell was frozen (int64, -1 if never). Default: false.
    #[serde(default)]
    pub frozen_order: bool,
}

impl Default for OutputSpec {
    fn default() -> Self {
        Self {
            labels: true,
            frozen_order: false,
        }
    }
}

/// Checks the metric of an operation that takes `cost` or `metric`:
/// exactly one of them; a tensor `metric` runs the anisotropic fast
/// marching, so `method` must be `fast_marching` and `connectivity` (a
/// Dijkstra option) must be left at its default. Errors name `cost`,
/// `metric`, `method` or `connectivity`.
pub fn check_metric_choice(
    cost: Option<&CostSpec>,
    metric: Option<&TensorSpec>,
    method: MethodSpec,
    connectivity: ConnectivitySpec,
    limits: &OpLimits,
) -> Result<(), OpError> {
    match (cost, metric) {
        (Some(cost), None) => cost.validate(limits),
        (None, Some(metric)) => {
            metric.validate("metric", limits)?;
            if method != MethodSpec::FastMarching {
                return Err(OpError::invalid(
                    "method",
                    "a tensor `metric` is solved by fast marching only; leave `method` out",
                ));
            }
            if connectivity != ConnectivitySpec::default() {
                return Err(OpError::invalid(
                    "connectivity",
                    "`connectivity` is a Dijkstra option; a tensor `metric` uses adaptive stencils",
                ));
            }
            Ok(())
        }
        (Some(_), Some(_)) => Err(OpError::invalid(
            "metric",
            "give either `cost` (isotropic) or `metric` (a tensor field), not both",
        )),
        (None, None) => Err(OpError::invalid(
            "cost",
            "give either `cost` (isotropic) or `metric` (a tensor field)",
        )),
    }
}

/// The dataset ids of a `cost` or `metric` section, with their JSON paths.
pub fn metric_dataset_ids(
    cost: Option<&CostSpec>,
    metric: Option<&TensorSpec>,
) -> Vec<(String, String)> {
    let mut ids = Vec::new();
    if let Some(id) = cost.and_then(|c| c.dataset.as_ref()) {
        ids.push(("cost.dataset".to_string(), id.clone()));
    }
    if let Some(m) = metric {
        ids.extend(m.dataset_ids("metric"));
    }
    ids
}

/// The wire name of a stop reason.
pub fn stop_name(stop: StopReason) -> &'static str {
    match stop {
        StopReason::Completed => "completed",
        StopReason::TargetsReached => "targets_reached",
        StopReason::MaxDistance => "max_distance",
        StopReason::MaxFrozen => "max_frozen",
        StopReason::SweepLimit => "sweep_limit",
    }
}
