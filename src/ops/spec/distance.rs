//! The distance section shared by every operation that solves the eikonal
//! equation on a grid: [`GridDistanceRequest`] (the request of
//! `grid.distance`, also built by `grid.segment` and `grid.offset` for their
//! inner solves), its validation and [`execute`], isotropic or tensor.
//!
//! Coordinates are in array index order (axis 0 first) and in index units;
//! physical lengths are index offsets times the per-axis `spacing`.

use std::sync::Arc;
use std::time::Instant;

use ndarray::{ArrayD, ArrayViewD, IxDyn};

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::cost::{resolve_cost, CostSpec};
use super::defaults::{default_order, default_true};
use super::errors::eikonal_error;
use super::map_cache::{cost_key, map_key, CachedCost, CachedMap, MapCache};
use super::scheme::{
    check_metric_choice, level_set_error, metric_dataset_ids, phi_of, resolve_sources,
    source_dataset_ids, stop_name, ConnectivitySpec, MethodSpec, OutputSpec, SourceSpec, StopSpec,
};
use super::tensor::{resolve_tensor, solve_tensor, TensorSolveSpec, TensorSpec};
use crate::numerics::eikonal::{
    level_set_distance, Connectivity, EikonalOptions, EikonalProblem, InterfaceFit,
    LevelSetOptions, Method, Order,
};
use crate::numerics::paths::SourceSet;
use crate::numerics::{self, Control, StopReason};
use crate::ops::spec::grid::fetch;
use crate::ops::{Inputs, OpError, OpLimits};

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
    /// With a `level_set` source: return the signed distance, negative where
    /// `phi < 0`. This is the redistancing of `phi` (`skfmm.distance(phi,
    /// dx)`): a signed distance function with the same zero level set.
    /// Default: false (the unsigned distance).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub signed: bool,
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
        ids.extend(source_dataset_ids(&self.sources));
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
        crate::ops::spec::scheme::check_source_count(&self.sources, limits)?;
        for (i, s) in self.sources.iter().enumerate() {
            s.check(&format!("sources[{i}]"))?;
        }
        if let Some(i) = self.sources.iter().position(|s| s.level_set.is_some()) {
            if self.sources.len() > 1 {
                return Err(OpError::invalid(
                    "sources",
                    format!(
                        "a `level_set` source (sources[{i}]) must be the only source: its zero \
                         level set is the whole source; combine the regions into one phi"
                    ),
                ));
            }
            if self.metric.is_some() {
                return Err(OpError::invalid(
                    format!("sources[{i}].level_set"),
                    "a level set is located in the Euclidean metric of the grid: use an \
                     isotropic `cost`, not a tensor `metric`",
                ));
            }
        } else if self.signed {
            return Err(OpError::invalid(
                "signed",
                "`signed` needs a `level_set` source: the sign is that of phi (negative inside)",
            ));
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

/// Runs `grid.distance`: validates, resolves the datasets through `inputs`,
/// calls the core and packages the result.
pub fn execute(
    req: &GridDistanceRequest,
    inputs: &dyn Inputs,
    limits: &OpLimits,
    control: &Control<'_>,
) -> Result<GridDistanceResult, OpError> {
    execute_sharing(req, inputs, limits, control, false)
}

/// [`execute`]; with `share`, a completed isotropic solve from point sources
/// is also kept in the caller's [`DistanceCache`] (when `inputs` has one),
/// under the keys `grid.paths` looks up: the paths a front end asks for
/// next, from the same sources, descend this very map instead of solving it
/// again. Jobs and the command line have no cache; nothing is kept there.
pub fn execute_sharing(
    req: &GridDistanceRequest,
    inputs: &dyn Inputs,
    limits: &OpLimits,
    control: &Control<'_>,
    share: bool,
) -> Result<GridDistanceResult, OpError> {
    req.validate(limits)?;
    let cost = match (&req.cost, &req.metric) {
        (Some(cost), _) => cost,
        (None, Some(metric)) => return execute_tensor(req, metric, inputs, limits, control),
        (None, None) => return Err(OpError::invalid("cost", "missing")),
    };
    // A cost designed already for this front end (by the paths, or by an
    // earlier map of another source) is taken from the cache: a new source
    // on the same metric solves at once, without designing `W` again (for
    // 1024² with smoothing, a third of the request).
    let cache = inputs.distance_cache().filter(|_| share);
    let cached = cache.and_then(|c| {
        c.cost(&cost_key(
            Some(cost),
            None,
            req.spacing.as_deref(),
            req.obstacles.as_deref(),
        ))
    });
    let resolved;
    let (cost, spacing, grid) = match &cached {
        Some(c) => (c.isotropic()?, c.spacing.clone(), c.grid.clone()),
        None => {
            resolved = resolve_cost(
                cost,
                req.spacing.as_deref(),
                req.obstacles.as_deref(),
                inputs,
                limits,
                control,
            )?;
            (
                resolved.isotropic()?,
                resolved.spacing.clone(),
                resolved.grid.clone(),
            )
        }
    };
    let started;
    let out = match req.sources.iter().position(|s| s.level_set.is_some()) {
        Some(i) => {
            let field = format!("sources[{i}].level_set");
            let id = req.sources[i].level_set.as_deref().unwrap_or_default();
            let phi = phi_of(inputs, &field, id, &grid)?;
            let phi = ArrayViewD::from_shape(IxDyn(grid.shape()), &phi)
                .map_err(|e| OpError::invalid(&field, e.to_string()))?;
            let options = LevelSetOptions {
                fit: InterfaceFit::Quadratic,
                signed: req.signed,
            };
            started = Instant::now();
            level_set_distance(&grid, &cost, &phi, &options, &req.options(), control)
                .map_err(|e| level_set_error(e, &field))?
        }
        None => {
            let sources = resolve_sources(&req.sources, &grid, &cost, inputs, control)?;
            let problem = EikonalProblem {
                grid: grid.clone(),
                cost,
                sources,
            };
            started = Instant::now();
            let out = numerics::solve(&problem, &req.options(), control).map_err(eikonal_error)?;
            if let Some(cache) = cache {
                share_map(cache, req, &spacing, &problem, &out)?;
            }
            out
        }
    };
    let solve_seconds = started.elapsed().as_secs_f64();
    Ok(GridDistanceResult {
        stats: SolveStats {
            cells: grid.len() as u64,
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

/// Keeps the cost and the map of a completed solve from point sources in
/// `cache` (see [`execute_sharing`]); other solves are left out (a partial
/// map, cells, masks or level sets as sources, a tensor metric).
fn share_map(
    cache: &dyn MapCache,
    req: &GridDistanceRequest,
    spacing: &[f64],
    problem: &EikonalProblem<'_>,
    out: &numerics::EikonalOutput,
) -> Result<(), OpError> {
    let points_only = req.sources.iter().all(|s| {
        s.point.is_some() && s.cells.is_none() && s.mask.is_none() && s.level_set.is_none()
    });
    if !(points_only && req.stop == StopSpec::default() && out.stop == StopReason::Completed) {
        return Ok(());
    }
    let key = cost_key(
        req.cost.as_ref(),
        None,
        req.spacing.as_deref(),
        req.obstacles.as_deref(),
    );
    let cost = match cache.cost(&key) {
        Some(c) => c,
        None => {
            let c = Arc::new(CachedCost {
                grid: problem.grid.clone(),
                spacing: spacing.to_vec(),
                w: (0..problem.grid.len())
                    .map(|i| problem.cost.at(i))
                    .collect(),
            });
            cache.put_cost(key.clone(), c.clone());
            c
        }
    };
    let Ok(sources) = SourceSet::new(&problem.grid, &problem.sources) else {
        return Ok(());
    };
    let map = CachedMap {
        cost,
        sources,
        u: out.distance.iter().copied().collect(),
        complete: true,
        frozen: out.frozen as u64,
        stop: stop_name(out.stop).into(),
    };
    let key = map_key(
        &key,
        &req.sources,
        req.method,
        req.order,
        req.factoring,
        req.connectivity,
    );
    cache.put_map(key, Arc::new(map));
    Ok(())
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
    // Masks are cells at 0; walls are the tensor's own (a mask cell on one is refused there).
    let unit = numerics::IsotropicCost::constant(1.0)
        .map_err(|e| OpError::invalid("metric", e.to_string()))?;
    let sources = resolve_sources(&req.sources, &resolved.grid, &unit, inputs, control)?;
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

/// The shape of the grid a cost spec describes.
pub fn cost_shape(
    cost: &CostSpec,
    inputs: &dyn Inputs,
    field: &str,
) -> Result<Vec<usize>, OpError> {
    match (&cost.dataset, &cost.shape) {
        (Some(id), _) => Ok(fetch(inputs, &format!("{field}.dataset"), id)?
            .array
            .shape()
            .to_vec()),
        (None, Some(shape)) => Ok(shape.clone()),
        (None, None) => Err(OpError::invalid(
            field,
            "give either `dataset`, or `constant` with `shape`",
        )),
    }
}

/// A `grid.distance` request from cell or point sources on the given metric.
pub fn distance_request(
    cost: &CostSpec,
    spacing: &Option<Vec<f64>>,
    obstacles: &Option<String>,
    sources: Vec<SourceSpec>,
    order: u8,
    max_distance: Option<f64>,
) -> GridDistanceRequest {
    GridDistanceRequest {
        cost: Some(cost.clone()),
        metric: None,
        spacing: spacing.clone(),
        obstacles: obstacles.clone(),
        sources,
        method: MethodSpec::FastMarching,
        order,
        factoring: true,
        connectivity: ConnectivitySpec::Diagonal,
        stop: StopSpec {
            targets: Vec::new(),
            max_distance,
            max_frozen: None,
        },
        outputs: OutputSpec {
            labels: false,
            frozen_order: false,
        },
        signed: false,
    }
}
