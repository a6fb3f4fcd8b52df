//! The scheme sections shared by the grid operations: sources, the solver
//! and its order, the Dijkstra neighbourhood, early stopping, optional
//! outputs, and the rule that a request gives exactly one of `cost` and
//! `metric`.

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use ndarray::{ArrayViewD, IxDyn};

use super::cost::CostSpec;
use super::design::array_to_f64;
use super::errors::eikonal_error;
use super::grid::{fetch, mask_of};
use super::tensor::TensorSpec;
use crate::io::ArrayData;
use crate::numerics::eikonal::{mask_source, LevelSetError, Source, StopReason, StopRules};
use crate::numerics::{Control, Grid, IsotropicCost};
use crate::ops::spec::defaults::default_true;
use crate::ops::{Inputs, OpError, OpLimits};

/// One source: give `point`, or `cells` (with optional `values`), or
/// `level_set`, or `mask`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize, ToSchema)]
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
    /// Id of a dataset `phi` of the grid's shape (negative inside, positive
    /// outside): the source is its zero level set, located between cells by
    /// interpolation (a local quadratic fit of `phi`; `|∇phi| = 1` is not
    /// assumed), as `skfmm.distance(phi, dx)` does. The cells next to the
    /// interface start at their distance to it (times the cost there). It
    /// must be the only source; with `signed: true` the distance is negative
    /// where `phi < 0` (the redistancing of `phi`). Isotropic `cost` only.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub level_set: Option<String>,
    /// Id of a dataset of the grid's shape: every non-zero cell is a source
    /// cell of value 0 (cells on obstacles are left out).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mask: Option<String>,
}

impl SourceSpec {
    /// A point source.
    pub fn at_point(point: Vec<f64>) -> Self {
        Self {
            point: Some(point),
            ..Self::default()
        }
    }

    /// A cell source of value 0.
    pub fn at_cells(cells: Vec<Vec<usize>>) -> Self {
        Self {
            cells: Some(cells),
            ..Self::default()
        }
    }

    /// Checks that exactly one of `point`, `cells`, `level_set` and `mask`
    /// is given (and `values` only with `cells`, finite coordinates);
    /// `field` is the source's JSON path (`sources[2]`).
    pub fn check(&self, field: &str) -> Result<(), OpError> {
        let given = [
            self.point.is_some(),
            self.cells.is_some(),
            self.level_set.is_some(),
            self.mask.is_some(),
        ];
        if given.iter().filter(|g| **g).count() != 1 {
            return Err(OpError::invalid(
                field,
                "give exactly one of `point`, `cells`, `level_set` or `mask`",
            ));
        }
        if self.values.is_some() && self.cells.is_none() {
            return Err(OpError::invalid(
                format!("{field}.values"),
                "values go with `cells`, not with `point`, `level_set` or `mask`",
            ));
        }
        if let Some(p) = &self.point {
            if let Some(k) = p.iter().position(|v| !v.is_finite()) {
                return Err(OpError::invalid(
                    format!("{field}.point[{k}]"),
                    "coordinates must be finite",
                ));
            }
        }
        Ok(())
    }

    /// True for a `level_set` or `mask` source (a dataset to load).
    pub fn is_dataset(&self) -> bool {
        self.level_set.is_some() || self.mask.is_some()
    }

    /// The core source of a `point` or `cells` spec (a `level_set` or
    /// `mask` needs its dataset: see [`resolve_sources`]).
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

/// Refuses more source points than `limits.max_sources`, counting every
/// cell of a `cells` list as one (a 16M-cell list is as heavy as 16M point
/// sources); a large seed region belongs in a `mask` dataset.
pub fn check_source_count(sources: &[SourceSpec], limits: &OpLimits) -> Result<(), OpError> {
    let count: usize = sources
        .iter()
        .map(|s| s.cells.as_ref().map_or(1, Vec::len))
        .fold(0, usize::saturating_add);
    if count > limits.max_sources {
        return Err(OpError::TooLarge {
            field: "sources".into(),
            reason: format!(
                "{count} sources (each cell of a `cells` list counts as one), more than the                  limit of {}: give a large seed region as a `mask` dataset",
                limits.max_sources
            ),
        });
    }
    Ok(())
}

/// The dataset ids named by `level_set` and `mask` sources, with their
/// JSON paths (`sources[1].mask`).
pub fn source_dataset_ids(sources: &[SourceSpec]) -> Vec<(String, String)> {
    let mut ids = Vec::new();
    for (i, s) in sources.iter().enumerate() {
        if let Some(id) = &s.level_set {
            ids.push((format!("sources[{i}].level_set"), id.clone()));
        }
        if let Some(id) = &s.mask {
            ids.push((format!("sources[{i}].mask"), id.clone()));
        }
    }
    ids
}

/// Refuses `level_set` and `mask` sources in an operation that cannot take
/// them, naming the first one and saying what to do instead.
pub fn refuse_dataset_sources(sources: &[SourceSpec], operation: &str) -> Result<(), OpError> {
    match sources.iter().position(SourceSpec::is_dataset) {
        Some(i) => {
            let kind = if sources[i].level_set.is_some() {
                "level_set"
            } else {
                "mask"
            };
            Err(OpError::invalid(
                format!("sources[{i}].{kind}"),
                format!(
                    "{operation} takes `point` and `cells` sources only; \
                     compute the distance from a `{kind}` with grid.distance"
                ),
            ))
        }
        None => Ok(()),
    }
}

/// The core sources of `specs` on `grid`: points and cells as given, each
/// `mask` as its non-zero cells at value 0 (cells on walls of `cost` left
/// out). A `level_set` is solved by [`crate::numerics::eikonal::level_set_distance`]
/// and is refused here. Errors name `sources[i].mask`.
pub fn resolve_sources(
    specs: &[SourceSpec],
    grid: &Grid,
    cost: &IsotropicCost<'_>,
    inputs: &dyn Inputs,
    control: &Control<'_>,
) -> Result<Vec<Source>, OpError> {
    specs
        .iter()
        .enumerate()
        .map(|(i, s)| match (&s.mask, &s.level_set) {
            (Some(id), _) => {
                let field = format!("sources[{i}].mask");
                let input = fetch(inputs, &field, id)?;
                let mask = mask_of(&input, &field, grid)?;
                let view = ArrayViewD::from_shape(IxDyn(grid.shape()), &mask)
                    .map_err(|e| OpError::invalid(&field, e.to_string()))?;
                mask_source(grid, cost, &view, control).map_err(|e| level_set_error(e, &field))
            }
            (None, Some(_)) => Err(OpError::invalid(
                format!("sources[{i}].level_set"),
                "a `level_set` source must be the only source",
            )),
            (None, None) => Ok(s.to_source()),
        })
        .collect()
}

/// The values of the `level_set` dataset named by `field` on `grid`, as f64
/// in C order; errors name `field` (shape, a boolean array).
pub fn phi_of(
    inputs: &dyn Inputs,
    field: &str,
    id: &str,
    grid: &Grid,
) -> Result<Vec<f64>, OpError> {
    let input = fetch(inputs, field, id)?;
    if input.array.shape() != grid.shape() {
        return Err(OpError::invalid(
            field,
            format!(
                "the dataset has shape {:?} but the grid has shape {:?}; phi must have the grid's shape",
                input.array.shape(),
                grid.shape()
            ),
        ));
    }
    if matches!(&*input.array, ArrayData::Bool(_)) {
        return Err(OpError::invalid(
            field,
            "a boolean array is not a level set: give phi (negative inside, positive outside), \
             or use `mask` for a region of source cells",
        ));
    }
    Ok(array_to_f64(&input.array))
}

/// A level-set or mask error as an [`OpError`] naming `field`.
pub fn level_set_error(e: LevelSetError, field: &str) -> OpError {
    match e {
        LevelSetError::Eikonal(e) => eikonal_error(e),
        LevelSetError::NoInterface { .. } => OpError::invalid(
            field,
            format!(
                "{e}; check the sign convention, or give the region as a `mask` source, \
                 or its boundary as `cells`"
            ),
        ),
        other => OpError::invalid(field, other.to_string()),
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
