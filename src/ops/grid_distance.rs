//! `grid.distance`: the geodesic distance map `U` (and Voronoi labels) of an
//! isotropic cost on a 2D or 3D grid.
//!
//! Coordinates are in array index order (axis 0 first) and in index units;
//! physical lengths are index offsets times the per-axis `spacing`.

use std::borrow::Cow;
use std::sync::Arc;
use std::time::Instant;

use ndarray::ArrayD;
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::grid_inputs::{check_shape, fetch};
use super::grid_metric::{apply_design, array_to_f64, DesignSpec};
use super::tensor_spec::{resolve_tensor, solve_tensor, TensorSolveSpec, TensorSpec};
use super::{Inputs, OpError, OpLimits, OpOutput, Operation, OutputArray};
use crate::io::ArrayData;
use crate::numerics::eikonal::{
    Connectivity, EikonalError, EikonalOptions, EikonalProblem, Method, Order, Source, StopReason,
    StopRules,
};
use crate::numerics::metric::{CostValues, Interpretation, IsotropicCost, MetricError};
use crate::numerics::{self, Control, Grid, GridError};

/// Request of `grid.distance` (`POST /v1/grid/distance`, job operation
/// `grid.distance`, and `geodex distance` on the command line).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({
    "cost": {"constant": 1.0, "shape": [256, 256]},
    "sources": [{"point": [128.0, 128.0]}],
    "method": "fast_marching",
    "order": 2
}))]
pub struct GridDistanceRequest {
    /// The isotropic metric: a cost (or speed) dataset, or a constant over a
    /// shape. Give exactly one of `cost` and `metric`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cost: Option<CostSpec>,
    /// A Riemannian metric (tensor field `M`, `kind`: `components`,
    /// `constant`, `eigen`, `energy_anisotropy`, `structure_tensor`,
    /// `height_map`) instead of `cost`: solved by the anisotropic fast
    /// marching (adaptive stencils), so `method` must be `fast_marching`
    /// and `connectivity` is not used. Give exactly one of `cost` and `metric`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub metric: Option<TensorSpec>,
    /// Physical size of a cell along each axis (axis 0 first). Default: the
    /// spacing stored with the cost dataset (NIfTI voxel size), else 1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(min_items = 2, max_items = 3)]
    pub spacing: Option<Vec<f64>>,
    /// Id of a dataset of the same shape whose non-zero cells are obstacles.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub obstacles: Option<String>,
    /// The sources. The Voronoi label of a cell is the index of the source
    /// that reaches it first, in this list.
    #[schema(min_items = 1)]
    pub sources: Vec<SourceSpec>,
    /// The solver. Default: `fast_marching`.
    #[serde(default)]
    pub method: MethodSpec,
    /// Order of the finite-difference scheme, 1 or 2. Default: 2.
    #[serde(default = "default_order")]
    #[schema(minimum = 1, maximum = 2)]
    pub order: u8,
    /// Source factoring around point sources (fast marching). Default: true.
    #[serde(default = "default_true")]
    pub factoring: bool,
    /// Graph neighbourhood of `dijkstra`. Default: `diagonal`.
    #[serde(default)]
    pub connectivity: ConnectivitySpec,
    /// Early stopping rules.
    #[serde(default)]
    pub stop: StopSpec,
    /// Which arrays to return besides the distance.
    #[serde(default)]
    pub outputs: OutputSpec,
}

fn default_order() -> u8 {
    2
}

fn default_true() -> bool {
    true
}

/// The cost `W` (cost per unit length, > 0) or speed `F = 1/W`. Give either
/// `dataset` or `constant` with `shape`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct CostSpec {
    /// Id of a 2D or 3D dataset holding one value per cell.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dataset: Option<String>,
    /// A constant value on every cell.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub constant: Option<f64>,
    /// Grid shape (2 or 3 axes) for a constant cost.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(min_items = 2, max_items = 3)]
    pub shape: Option<Vec<usize>>,
    /// Whether the values are a cost `W` (default) or a speed `F = 1/W`.
    #[serde(default)]
    pub interpretation: InterpretationSpec,
    /// Build the cost from the image named by `dataset` instead of reading
    /// it as a cost (intensity, edges or vesselness; see `grid.metric`).
    /// Needs `dataset` and `interpretation: cost`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub design: Option<DesignSpec>,
}

impl CostSpec {
    /// Checks everything that does not need the input arrays. Fields are
    /// named under `cost` (`cost.constant`, `cost.design.epsilon`).
    pub fn validate(&self, limits: &OpLimits) -> Result<(), OpError> {
        match (&self.dataset, self.constant, &self.shape) {
            (Some(_), None, None) => {}
            (None, Some(c), Some(shape)) => {
                if !(c.is_finite() && c > 0.0) {
                    return Err(OpError::invalid(
                        "cost.constant",
                        format!("{c} must be finite and > 0"),
                    ));
                }
                check_shape(shape, "cost.shape", limits)?;
            }
            (Some(_), _, _) => {
                return Err(OpError::invalid(
                    "cost",
                    "give either `dataset`, or `constant` with `shape`, not both",
                ))
            }
            (None, Some(_), None) => {
                return Err(OpError::invalid(
                    "cost.shape",
                    "a constant cost needs the grid shape",
                ))
            }
            (None, None, _) => {
                return Err(OpError::invalid(
                    "cost",
                    "give either `dataset`, or `constant` with `shape`",
                ))
            }
        }
        if let Some(design) = &self.design {
            if self.dataset.is_none() {
                return Err(OpError::invalid(
                    "cost.design",
                    "a design needs the image in `cost.dataset`",
                ));
            }
            if self.interpretation != InterpretationSpec::Cost {
                return Err(OpError::invalid(
                    "cost.interpretation",
                    "a designed metric is a cost; leave `interpretation` out",
                ));
            }
            design.validate("cost.design")?;
        }
        Ok(())
    }
}

/// Where the values of a [`ResolvedCost`] live.
#[derive(Debug, Clone)]
enum ResolvedValues {
    Constant(f64),
    /// An f32 or f64 dataset, shared with the caller (no copy).
    Shared(Arc<ArrayData>),
    /// Converted (integer datasets) or designed values.
    Owned(Vec<f64>),
}

/// A cost resolved from a [`CostSpec`] and its datasets: the grid, the
/// spacing that was used, and the (validated) values and walls, owned so
/// that the caller can keep it (caches) and borrow an [`IsotropicCost`]
/// from it with [`ResolvedCost::isotropic`].
#[derive(Debug, Clone)]
pub struct ResolvedCost {
    /// The grid (shape and spacing).
    pub grid: Grid,
    /// The spacing, per caller axis.
    pub spacing: Vec<f64>,
    values: ResolvedValues,
    interpretation: Interpretation,
    mask: Option<Vec<bool>>,
    from_dataset: bool,
}

impl ResolvedCost {
    /// The cost as the core takes it (borrowing the values; checked when resolved).
    pub fn isotropic(&self) -> Result<IsotropicCost<'_>, OpError> {
        let values = match &self.values {
            ResolvedValues::Constant(c) => CostValues::Constant(*c),
            ResolvedValues::Owned(v) => CostValues::F64(Cow::Borrowed(v)),
            ResolvedValues::Shared(a) => a.as_cost_values().ok_or_else(|| {
                OpError::invalid(
                    "cost.dataset",
                    format!("a {:?} array cannot be a cost", a.dtype()),
                )
            })?,
        };
        IsotropicCost::new(
            &self.grid,
            values,
            self.interpretation,
            self.mask.as_deref().map(Cow::Borrowed),
        )
        .map_err(|e| metric_error(e, self.from_dataset))
    }

    /// The cost `W` of every cell (`+inf` on walls), as a new vector.
    pub fn cost_values(&self) -> Result<Vec<f64>, OpError> {
        let cost = self.isotropic()?;
        Ok((0..self.grid.len()).map(|i| cost.at(i)).collect())
    }
}

/// Resolves a [`CostSpec`] against its datasets: validates it, looks up
/// `cost.dataset` and the `obstacles` mask in `inputs`, applies the
/// `design` if any, and checks every value. `spacing` is the request's
/// spacing (default: the dataset's, else 1). This is the grid and cost
/// construction of `grid.distance`, shared by every operation that takes a
/// `cost` (paths, segmentation). Errors name `cost.*`, `obstacles`, `spacing`.
pub fn resolve_cost(
    cost: &CostSpec,
    spacing: Option<&[f64]>,
    obstacles: Option<&str>,
    inputs: &dyn Inputs,
    limits: &OpLimits,
    control: &Control<'_>,
) -> Result<ResolvedCost, OpError> {
    cost.validate(limits)?;
    let cost_input = match &cost.dataset {
        Some(id) => Some(fetch(inputs, "cost.dataset", id)?),
        None => None,
    };
    let shape: Vec<usize> = match (&cost_input, &cost.shape) {
        (Some(input), _) => {
            let shape = input.array.shape().to_vec();
            check_shape(&shape, "cost.dataset", limits)?;
            shape
        }
        (None, Some(shape)) => shape.clone(),
        (None, None) => return Err(OpError::invalid("cost.shape", "missing")),
    };
    let spacing = spacing
        .map(<[f64]>::to_vec)
        .or_else(|| cost_input.as_ref().and_then(|c| c.spacing.clone()))
        .unwrap_or_else(|| vec![1.0; shape.len()]);
    let grid = Grid::new(&shape, &spacing).map_err(|e| grid_error(e, &shape))?;

    let mask = match obstacles {
        Some(id) => {
            let m = fetch(inputs, "obstacles", id)?;
            if m.array.shape() != shape.as_slice() {
                return Err(OpError::invalid(
                    "obstacles",
                    format!(
                        "the mask has shape {:?} but the grid has shape {:?}",
                        m.array.shape(),
                        shape
                    ),
                ));
            }
            Some(m.array.to_mask())
        }
        None => None,
    };
    let interpretation = match cost.interpretation {
        InterpretationSpec::Cost => Interpretation::Cost,
        InterpretationSpec::Speed => Interpretation::Speed,
    };
    let values = match (&cost_input, cost.constant, &cost.design) {
        (Some(input), _, Some(design)) => ResolvedValues::Owned(apply_design(
            &grid,
            &input.array,
            design,
            "cost.design",
            "cost.dataset",
            control,
        )?),
        (Some(input), _, None) => match &*input.array {
            ArrayData::F32(_) | ArrayData::F64(_) => ResolvedValues::Shared(input.array.clone()),
            ArrayData::Bool(_) => {
                return Err(OpError::invalid(
                    "cost.dataset",
                    format!("a {:?} array cannot be a cost", input.array.dtype()),
                ))
            }
            other => ResolvedValues::Owned(array_to_f64(other)),
        },
        (None, Some(c), _) => ResolvedValues::Constant(c),
        (None, None, _) => return Err(OpError::invalid("cost", "missing")),
    };
    let resolved = ResolvedCost {
        grid,
        spacing,
        values,
        interpretation,
        mask,
        from_dataset: cost_input.is_some(),
    };
    resolved.isotropic()?;
    Ok(resolved)
}

/// How to read the values of the cost.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum InterpretationSpec {
    /// Cost per unit length `W`: +inf marks a wall, NaN and values <= 0 are refused.
    #[default]
    Cost,
    /// Speed `F = 1/W`: 0 marks a wall, NaN, negative and infinite values are refused.
    Speed,
}

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

/// What a solve reports besides its arrays.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct SolveStats {
    /// Cells in the grid.
    pub cells: u64,
    /// Cells with a final value.
    pub frozen: u64,
    /// How the solve ended: `completed`, `targets_reached`, `max_distance`, `max_frozen` or `sweep_limit`.
    pub stop: String,
    /// Single sweeps done (fast sweeping only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sweeps: Option<u64>,
    /// Wall time of the solve alone, in seconds.
    pub solve_seconds: f64,
    /// With `metric`: the largest anisotropy ratio `sqrt(λmax/λmin)` of the field.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_anisotropy: Option<f64>,
    /// With `metric`: the widest stencil offset used, in cells.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stencil_width: Option<u64>,
}

/// The arrays and statistics of a solve.
#[derive(Debug, Clone)]
pub struct GridDistanceResult {
    /// The distance `U` (f64, `+inf` where not reached).
    pub distance: ArrayD<f64>,
    /// Voronoi labels, when asked for.
    pub labels: Option<ArrayD<i32>>,
    /// Freeze ranks, when asked for.
    pub frozen_order: Option<ArrayD<i64>>,
    /// The spacing that was used.
    pub spacing: Vec<f64>,
    /// Statistics.
    pub stats: SolveStats,
}

impl GridDistanceRequest {
    /// The dataset ids this request reads, with the field that names each.
    pub fn dataset_ids(&self) -> Vec<(String, String)> {
        let mut ids = metric_dataset_ids(self.cost.as_ref(), self.metric.as_ref());
        if let Some(id) = &self.obstacles {
            ids.push(("obstacles".into(), id.clone()));
        }
        ids
    }

    /// Checks everything that does not need the input arrays, so that a
    /// request can be refused before it is queued.
    pub fn validate(&self, limits: &OpLimits) -> Result<(), OpError> {
        check_metric_choice(
            self.cost.as_ref(),
            self.metric.as_ref(),
            self.method,
            self.connectivity,
            limits,
        )?;
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
            match (&s.point, &s.cells) {
                (Some(p), None) => {
                    if s.values.is_some() {
                        return Err(OpError::invalid(
                            format!("sources[{i}].values"),
                            "values go with `cells`, not with `point`",
                        ));
                    }
                    if let Some(k) = p.iter().position(|v| !v.is_finite()) {
                        return Err(OpError::invalid(
                            format!("sources[{i}].point[{k}]"),
                            "coordinates must be finite",
                        ));
                    }
                }
                (None, Some(_)) => {}
                _ => {
                    return Err(OpError::invalid(
                        format!("sources[{i}]"),
                        "give exactly one of `point` or `cells`",
                    ))
                }
            }
        }
        if !(1..=2).contains(&self.order) {
            return Err(OpError::invalid(
                "order",
                format!("{} must be 1 or 2", self.order),
            ));
        }
        if let Some(d) = self.stop.max_distance {
            if d.is_nan() || d < 0.0 {
                return Err(OpError::invalid(
                    "stop.max_distance",
                    format!("{d} must be >= 0"),
                ));
            }
        }
        if let Some(spacing) = &self.spacing {
            if let Some(k) = spacing.iter().position(|h| !(h.is_finite() && *h > 0.0)) {
                return Err(OpError::invalid(
                    format!("spacing[{k}]"),
                    format!("{} must be finite and > 0", spacing[k]),
                ));
            }
        }
        Ok(())
    }

    /// The core options this request asks for.
    pub fn options(&self) -> EikonalOptions {
        let mut o = EikonalOptions::DEFAULT
            .with_method(match self.method {
                MethodSpec::FastMarching => Method::FastMarching,
                MethodSpec::FastSweeping => Method::FastSweeping,
                MethodSpec::Dijkstra => Method::Dijkstra,
            })
            .with_order(if self.order == 1 {
                Order::First
            } else {
                Order::Second
            })
            .with_factoring(self.factoring)
            .with_connectivity(match self.connectivity {
                ConnectivitySpec::Axial => Connectivity::Axial,
                ConnectivitySpec::Diagonal => Connectivity::Diagonal,
                ConnectivitySpec::Extended => Connectivity::Extended,
            })
            .with_stop(self.stop.rules());
        o.record_order = self.outputs.frozen_order;
        o
    }
}

impl Operation for GridDistanceRequest {
    const NAME: &'static str = "grid.distance";

    fn validate(&self, limits: &OpLimits) -> Result<(), OpError> {
        GridDistanceRequest::validate(self, limits)
    }

    fn dataset_ids(&self) -> Vec<(String, String)> {
        GridDistanceRequest::dataset_ids(self)
    }

    /// Arrays: `distance` (f64), `labels` (i32, unless `outputs.labels` is
    /// false), `frozen_order` (i64, when asked for). Document: `{"stats": SolveStats}`.
    fn run(
        &self,
        inputs: &dyn Inputs,
        limits: &OpLimits,
        control: &Control<'_>,
    ) -> Result<OpOutput, OpError> {
        let result = execute(self, inputs, limits, control)?;
        let spacing = Some(result.spacing.clone());
        let mut arrays = vec![OutputArray {
            name: "distance".into(),
            array: ArrayData::F64(result.distance),
            spacing: spacing.clone(),
        }];
        if let Some(labels) = result.labels {
            arrays.push(OutputArray {
                name: "labels".into(),
                array: ArrayData::I32(labels),
                spacing: spacing.clone(),
            });
        }
        if let Some(order) = result.frozen_order {
            arrays.push(OutputArray {
                name: "frozen_order".into(),
                array: ArrayData::I64(order),
                spacing,
            });
        }
        let document = serde_json::json!({ "stats": result.stats });
        Ok(OpOutput { arrays, document })
    }
}

/// Runs `grid.distance`: validates, resolves the datasets through `inputs`,
/// calls the core and packages the result.
pub fn execute(
    req: &GridDistanceRequest,
    inputs: &dyn Inputs,
    limits: &OpLimits,
    control: &Control<'_>,
) -> Result<GridDistanceResult, OpError> {
    req.validate(limits)?;
    let cost = match (&req.cost, &req.metric) {
        (Some(cost), _) => cost,
        (None, Some(metric)) => return execute_tensor(req, metric, inputs, limits, control),
        (None, None) => return Err(OpError::invalid("cost", "missing")),
    };
    let resolved = resolve_cost(
        cost,
        req.spacing.as_deref(),
        req.obstacles.as_deref(),
        inputs,
        limits,
        control,
    )?;
    let cost = resolved.isotropic()?;
    let spacing = resolved.spacing.clone();
    let sources = req.sources.iter().map(SourceSpec::to_source).collect();
    let problem = EikonalProblem {
        grid: resolved.grid.clone(),
        cost,
        sources,
    };
    let started = Instant::now();
    let out = numerics::solve(&problem, &req.options(), control).map_err(eikonal_error)?;
    let solve_seconds = started.elapsed().as_secs_f64();
    Ok(GridDistanceResult {
        stats: SolveStats {
            cells: problem.grid.len() as u64,
            frozen: out.frozen as u64,
            stop: stop_name(out.stop).into(),
            sweeps: out.sweeps.map(|s| s as u64),
            solve_seconds,
            max_anisotropy: None,
            stencil_width: None,
        },
        labels: req.outputs.labels.then_some(out.labels),
        frozen_order: out.frozen_order,
        distance: out.distance,
        spacing,
    })
}

/// `grid.distance` with a tensor `metric`: the anisotropic solve of
/// [`solve_tensor`] on the field of [`resolve_tensor`].
fn execute_tensor(
    req: &GridDistanceRequest,
    metric: &TensorSpec,
    inputs: &dyn Inputs,
    limits: &OpLimits,
    control: &Control<'_>,
) -> Result<GridDistanceResult, OpError> {
    let resolved = resolve_tensor(
        metric,
        "metric",
        req.spacing.as_deref(),
        req.obstacles.as_deref(),
        inputs,
        limits,
        control,
    )?;
    let spec = TensorSolveSpec {
        order: req.order,
        factoring: req.factoring,
        stop: req.stop.rules(),
        record_order: req.outputs.frozen_order,
    };
    let sources = req.sources.iter().map(SourceSpec::to_source).collect();
    let (problem, spacing) = resolved.into_problem(sources);
    let solved = solve_tensor(&problem, &spec, "metric", control)?;
    let out = solved.out;
    Ok(GridDistanceResult {
        stats: SolveStats {
            cells: problem.grid.len() as u64,
            frozen: out.output.frozen as u64,
            stop: stop_name(out.output.stop).into(),
            sweeps: None,
            solve_seconds: solved.seconds,
            max_anisotropy: Some(out.stencil.max_anisotropy),
            stencil_width: Some(out.stencil.max_offset as u64),
        },
        labels: req.outputs.labels.then_some(out.output.labels),
        frozen_order: out.output.frozen_order,
        distance: out.output.distance,
        spacing,
    })
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

pub(crate) fn grid_error(e: GridError, shape: &[usize]) -> OpError {
    match e {
        GridError::Spacing { axis, .. } => {
            OpError::invalid(format!("spacing[{axis}]"), e.to_string())
        }
        GridError::SpacingLength { .. } => OpError::invalid("spacing", e.to_string()),
        GridError::TooLarge(_) => OpError::TooLarge {
            field: "cost".into(),
            reason: e.to_string(),
        },
        _ => OpError::invalid("cost", format!("{e} (shape {shape:?})")),
    }
}

fn metric_error(e: MetricError, from_dataset: bool) -> OpError {
    let field = match e {
        MetricError::MaskLength { .. } => "obstacles",
        MetricError::Constant(_) => "cost.constant",
        _ if from_dataset => "cost.dataset",
        _ => "cost",
    };
    OpError::invalid(field, e.to_string())
}

pub(crate) fn eikonal_error(e: EikonalError) -> OpError {
    match e {
        EikonalError::Cancelled => OpError::Cancelled,
        EikonalError::Source { index, reason } => {
            OpError::invalid(format!("sources[{index}]"), reason)
        }
        EikonalError::Target { index, reason } => {
            OpError::invalid(format!("stop.targets[{index}]"), reason)
        }
        EikonalError::NoSources => OpError::invalid("sources", e.to_string()),
        EikonalError::Option { field, reason } => OpError::invalid(field, reason),
        EikonalError::Grid(g) => OpError::invalid("cost", g.to_string()),
        EikonalError::Metric(m) => OpError::invalid("cost", m.to_string()),
    }
}
