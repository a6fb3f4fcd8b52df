//! `grid.paths`: minimal paths on a 2D or 3D grid, by gradient descent of
//! the distance map ([`crate::numerics::paths`]).
//!
//! Three ways to ask, exactly one per request:
//! * `sources` + `ends`: one minimal path from each end point to the
//!   nearest source (one distance map, stopped once every end is frozen);
//! * `waypoints` `[p0, ..., pn]`: the path through the points in order, the
//!   chain of the minimal paths `p(k-1) → pk` (one map per leg, from `p(k-1)`);
//! * `contour` `[p0, ..., p(n-1)]`: a closed contour through the points
//!   (minimal-path active contour, the "livewire"): the chain
//!   `p0 → p1 → ... → p(n-1) → p0`.
//!
//! Every path is ordered from its source to its end point; coordinates are
//! in array index order (axis 0 first) in index units, and in world units
//! (index × spacing). Lengths are physical: the geodesic length `∫ W |γ'|`
//! and the Euclidean length.
//!
//! Interactive reuse: [`execute`] takes an optional [`DistanceCache`]
//! (bounded, least recently used first out) of designed costs and distance
//! maps, keyed by the inputs (dataset ids, design, spacing, obstacles,
//! sources, scheme). A later request with the same inputs and new end points
//! only runs the descents. The HTTP layer holds the cache; jobs and the
//! command line run without one.
//!
//! Tensor metrics (`metric` instead of `cost`): each map is an anisotropic
//! fast-marching solve and each path the shared descent along `−M⁻¹∇U` with
//! its Riemannian length `∫ sqrt(γ'ᵀ M γ')`
//! ([`crate::numerics::anisotropic::descent::Riemannian`]). Such requests
//! **skip the cache** (nothing is looked up or kept; `stats.maps[].cached`
//! is false): a cached cost holds a scalar `W` per cell, not a tensor field.
//! Their `cost_key` includes the metric all the same, so it can never match
//! an isotropic entry.

use std::borrow::Cow;
use std::collections::HashMap;
use std::fmt::Write as _;
use std::sync::{Arc, Mutex};
use std::time::Instant;

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::grid_distance::{
    check_metric_choice, eikonal_error, metric_dataset_ids, resolve_cost, stop_name,
    ConnectivitySpec, CostSpec, GridDistanceRequest, MethodSpec, OutputSpec, SourceSpec, StopSpec,
};
use super::tensor_spec::{resolve_tensor, solve_tensor, TensorSolveSpec, TensorSpec};
use super::{Inputs, OpError, OpLimits, OpOutput, Operation};
use crate::io::{render_png, ArrayData, Colormap, RenderOptions, RenderStyle};
use crate::numerics::anisotropic::descent::Riemannian;
use crate::numerics::metric::{CostValues, Interpretation};
use crate::numerics::paths::{
    CellCost, DescentOptions, DistanceMap, Isotropic, MinimalPath, PathError, SourceSet,
};
use crate::numerics::{self, Control, EikonalProblem, Grid, IsotropicCost, Source, StopRules};

/// Request of `grid.paths` (`POST /v1/grid/paths`, job operation
/// `grid.paths`, and `geodex path` on the command line).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({
    "cost": {"dataset": "ds_0192f1b27c1e7d3a9d553c0f2b8a1e45", "design": {"kind": "intensity", "at": [12.0, 40.0]}},
    "sources": [{"point": [12.0, 40.0]}],
    "ends": [[200.0, 310.0], [150.5, 20.0]]
}))]
pub struct GridPathsRequest {
    /// The isotropic metric: a cost (or speed) dataset, a constant over a
    /// shape, or an image with a `design` (intensity, edges, vesselness).
    /// Give exactly one of `cost` and `metric`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cost: Option<CostSpec>,
    /// A Riemannian metric (tensor field), as in `grid.distance`: paths
    /// descend along `−M⁻¹∇U` and `geodesic_length` is `∫ sqrt(γ'ᵀ M γ')`.
    /// `method` must be `fast_marching`. Not cached. Give exactly one of
    /// `cost` and `metric`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub metric: Option<TensorSpec>,
    /// Physical size of a cell per axis. Default: the dataset's spacing, else 1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(min_items = 2, max_items = 3)]
    pub spacing: Option<Vec<f64>>,
    /// Id of a mask dataset whose non-zero cells are walls.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub obstacles: Option<String>,
    /// The sources (with `ends`), as in `grid.distance`.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub sources: Vec<SourceSpec>,
    /// End points (index coordinates): one path from each to its nearest source.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub ends: Vec<Vec<f64>>,
    /// Way-points (at least 2): the chain of minimal paths between consecutive points.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub waypoints: Vec<Vec<f64>>,
    /// Points of a closed contour (at least 3), in order.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub contour: Vec<Vec<f64>>,
    /// The solver. Default: `fast_marching`.
    #[serde(default)]
    pub method: MethodSpec,
    /// Scheme order, 1 or 2. Default: 2.
    #[serde(default = "default_order")]
    #[schema(minimum = 1, maximum = 2)]
    pub order: u8,
    /// Graph neighbourhood of `dijkstra`. Default: `diagonal`.
    #[serde(default)]
    pub connectivity: ConnectivitySpec,
    /// Source factoring around point sources. Default: true.
    #[serde(default = "default_true")]
    pub factoring: bool,
    /// Stop each distance solve once its end points are frozen. Default: true.
    #[serde(default = "default_true")]
    pub early_stop: bool,
    /// Runge–Kutta step length, in cells, in (0, 0.5]. Default: 0.5.
    #[serde(default = "default_step")]
    #[schema(exclusive_minimum = 0.0, maximum = 0.5)]
    pub step: f64,
    /// Answer format: `json` (default), `geojson` (a FeatureCollection of
    /// LineStrings, 2D) or `svg` (the paths over a PNG of the image, 2D).
    #[serde(default)]
    pub format: PathFormat,
}

fn default_order() -> u8 {
    2
}
fn default_true() -> bool {
    true
}
fn default_step() -> f64 {
    0.5
}

/// The answer format of `grid.paths`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum PathFormat {
    /// Paths as JSON (index and world coordinates, lengths).
    #[default]
    Json,
    /// A GeoJSON FeatureCollection of LineStrings; positions are `[x, y]` =
    /// `[axis 1, axis 0] × spacing` (image convention, y down). 2D only.
    Geojson,
    /// An SVG document: the image (PNG, grey) with the paths drawn over it. 2D only.
    Svg,
}

/// One minimal path in the answer.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct PathOut {
    /// Position of the leg (way-point or contour mode) or of the end point in `ends`.
    pub index: usize,
    /// Index of the source reached (in `sources`; in way-point and contour
    /// modes the leg's starting point, so always 0).
    pub source: usize,
    /// The end point, as given.
    pub end: Vec<f64>,
    /// Vertices from the source to the end, index coordinates (axis 0 first).
    pub points: Vec<Vec<f64>>,
    /// The same vertices in world coordinates (index × spacing).
    pub world: Vec<Vec<f64>>,
    /// `∫ W |γ'|`, physical units.
    pub geodesic_length: f64,
    /// Physical length of the polyline.
    pub euclidean_length: f64,
    /// Runge–Kutta steps.
    pub continuous_steps: u64,
    /// Discrete steepest-descent steps (where the gradient vanished or was undefined).
    pub discrete_steps: u64,
}

impl PathOut {
    /// The answer's form of a descended path (`index` as in [`PathOut::index`]).
    fn new(index: usize, end: &[f64], path: &MinimalPath, grid: &Grid) -> Self {
        Self {
            index,
            source: path.source,
            end: end.to_vec(),
            points: path.index_points(grid),
            world: path.world_points(grid),
            geodesic_length: path.geodesic_length,
            euclidean_length: path.euclidean_length,
            continuous_steps: path.continuous_steps as u64,
            discrete_steps: path.discrete_steps as u64,
        }
    }
}

/// The whole path through way-points, or the closed contour.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct ChainOut {
    /// True for a contour (the last vertex equals the first).
    pub closed: bool,
    /// Vertices, index coordinates.
    pub points: Vec<Vec<f64>>,
    /// Vertices, world coordinates.
    pub world: Vec<Vec<f64>>,
    /// Sum of the legs' geodesic lengths.
    pub geodesic_length: f64,
    /// Sum of the legs' Euclidean lengths.
    pub euclidean_length: f64,
}

/// How one distance map was obtained.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct LegStats {
    /// True if the map came from the cache (no solve).
    pub cached: bool,
    /// Cells with a final value in the map.
    pub frozen: u64,
    /// How its solve ended (`completed`, `targets_reached`, ...).
    pub stop: String,
    /// Seconds of the solve (0 when cached).
    pub solve_seconds: f64,
}

/// Statistics of a paths request.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct PathsStats {
    /// Cells in the grid.
    pub cells: u64,
    /// True if the (designed) cost came from the cache.
    pub cost_cached: bool,
    /// Seconds spent building the cost (design included); 0 when cached.
    pub cost_seconds: f64,
    /// One entry per distance map (one, or one per leg).
    pub maps: Vec<LegStats>,
    /// Seconds spent in the descents.
    pub descent_seconds: f64,
}

/// The result of [`execute`].
#[derive(Debug, Clone)]
pub struct GridPathsResult {
    /// One path per end point, or per leg.
    pub paths: Vec<PathOut>,
    /// The chain, in way-point and contour modes.
    pub chain: Option<ChainOut>,
    /// Statistics.
    pub stats: PathsStats,
    /// The GeoJSON document (format `geojson`).
    pub geojson: Option<serde_json::Value>,
    /// The SVG document (format `svg`).
    pub svg: Option<String>,
}

impl GridPathsResult {
    /// The JSON document of the answer.
    pub fn document(&self) -> serde_json::Value {
        let mut doc = serde_json::json!({ "paths": self.paths, "stats": self.stats });
        if let Some(chain) = &self.chain {
            doc["chain"] = serde_json::json!(chain);
        }
        if let Some(g) = &self.geojson {
            doc["geojson"] = g.clone();
        }
        if let Some(s) = &self.svg {
            doc["svg"] = serde_json::Value::String(s.clone());
        }
        doc
    }
}

/// One distance map and the end points descended on it.
struct Leg {
    sources: Vec<SourceSpec>,
    /// (field of the end point, the point).
    ends: Vec<(String, Vec<f64>)>,
    /// Field naming source `i` of this leg.
    source_field: Box<dyn Fn(usize) -> String>,
}

/// Largest number of way-points or contour points.
pub const MAX_WAYPOINTS: usize = 1000;

impl GridPathsRequest {
    fn mode_points(&self) -> (&'static str, &[Vec<f64>]) {
        if !self.waypoints.is_empty() {
            ("waypoints", &self.waypoints)
        } else if !self.contour.is_empty() {
            ("contour", &self.contour)
        } else {
            ("ends", &self.ends)
        }
    }

    /// Checks everything that does not need the input arrays.
    pub fn validate(&self, limits: &OpLimits) -> Result<(), OpError> {
        check_metric_choice(
            self.cost.as_ref(),
            self.metric.as_ref(),
            self.method,
            self.connectivity,
            limits,
        )?;
        let modes = [
            !self.ends.is_empty() || !self.sources.is_empty(),
            !self.waypoints.is_empty(),
            !self.contour.is_empty(),
        ];
        match modes.iter().filter(|m| **m).count() {
            0 => {
                return Err(OpError::invalid(
                    "ends",
                    "give `sources` with `ends`, or `waypoints`, or `contour`",
                ))
            }
            1 => {}
            _ => {
                return Err(OpError::invalid(
                    "waypoints",
                    "give only one of `sources` with `ends`, `waypoints` or `contour`",
                ))
            }
        }
        if modes[0] {
            if self.sources.is_empty() {
                return Err(OpError::invalid(
                    "sources",
                    "at least one source is required with `ends`",
                ));
            }
            if self.ends.is_empty() {
                return Err(OpError::invalid(
                    "ends",
                    "at least one end point is required with `sources`",
                ));
            }
            if self.ends.len() > limits.max_sources {
                return Err(OpError::TooLarge {
                    field: "ends".into(),
                    reason: format!(
                        "{} end points, more than the limit of {}",
                        self.ends.len(),
                        limits.max_sources
                    ),
                });
            }
            // The sources and the scheme are checked as grid.distance does.
            self.distance_request(self.sources.clone(), Vec::new())
                .validate(limits)?;
        }
        let (field, points) = self.mode_points();
        let least = match field {
            "waypoints" => 2,
            "contour" => 3,
            _ => 1,
        };
        if points.len() < least {
            return Err(OpError::invalid(
                field,
                format!("at least {least} points are required"),
            ));
        }
        if field != "ends" && points.len() > MAX_WAYPOINTS {
            return Err(OpError::TooLarge {
                field: field.into(),
                reason: format!(
                    "{} points, more than the limit of {MAX_WAYPOINTS}",
                    points.len()
                ),
            });
        }
        for (i, p) in points.iter().enumerate() {
            if !(2..=3).contains(&p.len()) {
                return Err(OpError::invalid(
                    format!("{field}[{i}]"),
                    format!("a point has 2 or 3 coordinates, got {}", p.len()),
                ));
            }
            if let Some(k) = p.iter().position(|v| !v.is_finite()) {
                return Err(OpError::invalid(
                    format!("{field}[{i}][{k}]"),
                    "coordinates must be finite",
                ));
            }
        }
        if !(1..=2).contains(&self.order) {
            return Err(OpError::invalid(
                "order",
                format!("{} must be 1 or 2", self.order),
            ));
        }
        if !(self.step.is_finite() && self.step > 0.0 && self.step <= 0.5) {
            return Err(OpError::invalid(
                "step",
                format!("{} must be in (0, 0.5] cells", self.step),
            ));
        }
        if let Some(spacing) = &self.spacing {
            if let Some(k) = spacing.iter().position(|h| !(h.is_finite() && *h > 0.0)) {
                return Err(OpError::invalid(
                    format!("spacing[{k}]"),
                    format!("{} must be finite and > 0", spacing[k]),
                ));
            }
        }
        if self.format != PathFormat::Json {
            let ndim = self
                .cost
                .as_ref()
                .and_then(|c| c.shape.as_ref())
                .map(Vec::len)
                .or_else(|| points.first().map(Vec::len));
            if ndim == Some(3) {
                return Err(OpError::invalid(
                    "format",
                    "geojson and svg are for 2D grids; use json in 3D",
                ));
            }
        }
        Ok(())
    }

    /// The dataset ids this request reads, with the field that names each.
    pub fn dataset_ids(&self) -> Vec<(String, String)> {
        let mut ids = metric_dataset_ids(self.cost.as_ref(), self.metric.as_ref());
        if let Some(id) = &self.obstacles {
            ids.push(("obstacles".into(), id.clone()));
        }
        ids
    }

    /// The `grid.distance` request of one map (its sources, stopped at `targets`).
    fn distance_request(
        &self,
        sources: Vec<SourceSpec>,
        targets: Vec<Vec<f64>>,
    ) -> GridDistanceRequest {
        GridDistanceRequest {
            cost: self.cost.clone(),
            metric: self.metric.clone(),
            spacing: self.spacing.clone(),
            obstacles: self.obstacles.clone(),
            sources,
            method: self.method,
            order: self.order,
            factoring: self.factoring,
            connectivity: self.connectivity,
            stop: StopSpec {
                targets,
                max_distance: None,
                max_frozen: None,
            },
            outputs: OutputSpec {
                labels: false,
                frozen_order: false,
            },
        }
    }

    fn legs(&self) -> Vec<Leg> {
        let point = |p: &Vec<f64>| SourceSpec {
            point: Some(p.clone()),
            cells: None,
            values: None,
        };
        let chain = |field: &'static str, pts: &[Vec<f64>], closed: bool| -> Vec<Leg> {
            let n = pts.len();
            let count = if closed { n } else { n - 1 };
            (0..count)
                .map(|k| {
                    let to = (k + 1) % n;
                    Leg {
                        sources: vec![point(&pts[k])],
                        ends: vec![(format!("{field}[{to}]"), pts[to].clone())],
                        source_field: Box::new(move |_| format!("{field}[{k}]")),
                    }
                })
                .collect()
        };
        if !self.waypoints.is_empty() {
            chain("waypoints", &self.waypoints, false)
        } else if !self.contour.is_empty() {
            chain("contour", &self.contour, true)
        } else {
            vec![Leg {
                sources: self.sources.clone(),
                ends: self
                    .ends
                    .iter()
                    .enumerate()
                    .map(|(i, p)| (format!("ends[{i}]"), p.clone()))
                    .collect(),
                source_field: Box::new(|i| format!("sources[{i}]")),
            }]
        }
    }

    /// Cache key of the cost: everything that determines the metric and the grid.
    pub fn cost_key(&self) -> String {
        serde_json::json!([self.cost, self.metric, self.spacing, self.obstacles]).to_string()
    }

    fn map_key(&self, cost_key: &str, sources: &[SourceSpec]) -> String {
        let scheme = serde_json::json!([
            sources,
            self.method,
            self.order,
            self.factoring,
            self.connectivity
        ]);
        format!("{cost_key}|{scheme}")
    }
}

impl Operation for GridPathsRequest {
    const NAME: &'static str = "grid.paths";

    fn validate(&self, limits: &OpLimits) -> Result<(), OpError> {
        GridPathsRequest::validate(self, limits)
    }

    fn dataset_ids(&self) -> Vec<(String, String)> {
        GridPathsRequest::dataset_ids(self)
    }

    /// No arrays. Document: `{"paths": [PathOut], "chain"?: ChainOut,
    /// "stats": PathsStats, "geojson"?: FeatureCollection, "svg"?: string}`.
    fn run(
        &self,
        inputs: &dyn Inputs,
        limits: &OpLimits,
        control: &Control<'_>,
    ) -> Result<OpOutput, OpError> {
        let result = execute(self, inputs, limits, control, None, None)?;
        Ok(OpOutput {
            arrays: Vec::new(),
            document: result.document(),
        })
    }
}

/// A cost ready for solves and descents: the grid and `W` per cell (`+inf` on walls).
#[derive(Debug, Clone)]
pub struct CachedCost {
    /// Shape and spacing.
    pub grid: Grid,
    /// The spacing per caller axis.
    pub spacing: Vec<f64>,
    /// `W` per cell, C order, `+inf` on walls.
    pub w: Vec<f64>,
}

/// A distance map kept for later descents.
#[derive(Debug)]
pub struct CachedMap {
    /// The cost it was computed on.
    pub cost: Arc<CachedCost>,
    /// Its sources, indexed for the arrival test.
    pub sources: SourceSet,
    /// `U` per cell (`+inf` where not computed).
    pub u: Vec<f64>,
    /// False if the solve stopped early (some cells were not computed).
    pub complete: bool,
    /// Frozen cells and how the solve ended.
    pub frozen: u64,
    /// How the solve ended.
    pub stop: String,
}

#[derive(Debug, Default)]
struct CacheInner {
    costs: HashMap<String, (Arc<CachedCost>, u64)>,
    maps: HashMap<String, (Arc<CachedMap>, u64)>,
    bytes: usize,
    tick: u64,
}

/// A bounded in-memory cache of designed costs and distance maps, least
/// recently used out first. Shared between requests (`Arc`), thread-safe.
#[derive(Debug)]
pub struct DistanceCache {
    max_bytes: usize,
    inner: Mutex<CacheInner>,
}

impl DistanceCache {
    /// A cache holding at most `max_bytes` of values (8 bytes per cell for
    /// each cost and each map). `0` disables it.
    pub fn new(max_bytes: usize) -> Self {
        Self {
            max_bytes,
            inner: Mutex::new(CacheInner::default()),
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, CacheInner> {
        self.inner.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The cost under `key`, if kept.
    pub fn cost(&self, key: &str) -> Option<Arc<CachedCost>> {
        let mut g = self.lock();
        g.tick += 1;
        let tick = g.tick;
        g.costs.get_mut(key).map(|e| {
            e.1 = tick;
            e.0.clone()
        })
    }

    /// The map under `key`, if kept.
    pub fn map(&self, key: &str) -> Option<Arc<CachedMap>> {
        let mut g = self.lock();
        g.tick += 1;
        let tick = g.tick;
        g.maps.get_mut(key).map(|e| {
            e.1 = tick;
            e.0.clone()
        })
    }

    /// Keeps a cost.
    pub fn put_cost(&self, key: String, cost: Arc<CachedCost>) {
        let bytes = cost.w.len() * 8;
        self.put(bytes, |g, tick| {
            if let Some((old, _)) = g.costs.insert(key, (cost, tick)) {
                g.bytes = g.bytes.saturating_sub(old.w.len() * 8);
            }
        });
    }

    /// Keeps a map.
    pub fn put_map(&self, key: String, map: Arc<CachedMap>) {
        let bytes = map.u.len() * 8;
        self.put(bytes, |g, tick| {
            if let Some((old, _)) = g.maps.insert(key, (map, tick)) {
                g.bytes = g.bytes.saturating_sub(old.u.len() * 8);
            }
        });
    }

    fn put(&self, bytes: usize, insert: impl FnOnce(&mut CacheInner, u64)) {
        if bytes > self.max_bytes {
            return;
        }
        let mut g = self.lock();
        while g.bytes + bytes > self.max_bytes {
            // Evict the least recently used entry of either kind.
            let oldest_map = g
                .maps
                .iter()
                .min_by_key(|e| e.1 .1)
                .map(|(k, e)| (k.clone(), e.1));
            let oldest_cost = g
                .costs
                .iter()
                .min_by_key(|e| e.1 .1)
                .map(|(k, e)| (k.clone(), e.1));
            match (oldest_map, oldest_cost) {
                (Some((k, a)), Some((_, b))) if a <= b => {
                    if let Some((m, _)) = g.maps.remove(&k) {
                        g.bytes = g.bytes.saturating_sub(m.u.len() * 8);
                    }
                }
                (Some((k, _)), None) => {
                    if let Some((m, _)) = g.maps.remove(&k) {
                        g.bytes = g.bytes.saturating_sub(m.u.len() * 8);
                    }
                }
                (_, Some((k, _))) => {
                    if let Some((c, _)) = g.costs.remove(&k) {
                        g.bytes = g.bytes.saturating_sub(c.w.len() * 8);
                    }
                }
                (None, None) => break,
            }
        }
        g.tick += 1;
        let tick = g.tick;
        insert(&mut g, tick);
        g.bytes += bytes;
    }

    /// Number of kept (costs, maps).
    pub fn len(&self) -> (usize, usize) {
        let g = self.lock();
        (g.costs.len(), g.maps.len())
    }

    /// True if nothing is kept.
    pub fn is_empty(&self) -> bool {
        self.len() == (0, 0)
    }
}

fn path_error(e: PathError, end_field: &str, source_field: &dyn Fn(usize) -> String) -> OpError {
    match e {
        PathError::EndPoint { reason, .. } => OpError::invalid(end_field, reason),
        PathError::Unreached { .. } => OpError::invalid(
            end_field,
            "the point is not reached from the sources (on a wall, or cut off by walls)",
        ),
        PathError::Source { index, reason } => OpError::invalid(source_field(index), reason),
        PathError::NoSources => OpError::invalid("sources", e.to_string()),
        PathError::Option { field, reason } => OpError::invalid(field, reason),
        PathError::Length { .. } | PathError::Stalled { .. } => {
            OpError::invalid(end_field, e.to_string())
        }
    }
}

/// Runs `grid.paths`. With a `cache`, designed costs and distance maps are
/// looked up there first and kept there afterwards; `cost` is a cost the
/// caller already fetched from that cache (so that it needs no inputs).
pub fn execute(
    req: &GridPathsRequest,
    inputs: &dyn Inputs,
    limits: &OpLimits,
    control: &Control<'_>,
    cache: Option<&DistanceCache>,
    cost: Option<Arc<CachedCost>>,
) -> Result<GridPathsResult, OpError> {
    req.validate(limits)?;
    let cost_spec = match (&req.cost, &req.metric) {
        (Some(c), _) => c,
        (None, Some(metric)) => return execute_tensor(req, metric, inputs, limits, control),
        (None, None) => return Err(OpError::invalid("cost", "missing")),
    };
    let cost_key = req.cost_key();
    let started = Instant::now();
    let cached_cost = cost.or_else(|| cache.and_then(|c| c.cost(&cost_key)));
    let cost_cached = cached_cost.is_some();
    let cost = match cached_cost {
        Some(c) => c,
        None => {
            let resolved = resolve_cost(
                cost_spec,
                req.spacing.as_deref(),
                req.obstacles.as_deref(),
                inputs,
                limits,
                control,
            )?;
            let c = Arc::new(CachedCost {
                w: resolved.cost_values()?,
                grid: resolved.grid,
                spacing: resolved.spacing,
            });
            if let Some(cache) = cache {
                cache.put_cost(cost_key.clone(), c.clone());
            }
            c
        }
    };
    let cost_seconds = if cost_cached {
        0.0
    } else {
        started.elapsed().as_secs_f64()
    };
    let grid = &cost.grid;
    if req.format != PathFormat::Json && grid.ndim() == 3 {
        return Err(OpError::invalid(
            "format",
            "geojson and svg are for 2D grids; use json in 3D",
        ));
    }
    let descent = DescentOptions {
        step: req.step,
        ..DescentOptions::default()
    };
    let mut maps = Vec::new();
    let mut paths = Vec::new();
    let mut descent_seconds = 0.0;
    let chain_mode = req.ends.is_empty();
    for (leg_index, leg) in req.legs().into_iter().enumerate() {
        let key = req.map_key(&cost_key, &leg.sources);
        let ends_reached = |m: &CachedMap| {
            m.complete
                || leg.ends.iter().all(|(_, p)| {
                    grid.point3(p)
                        .ok()
                        .filter(|q| grid.contains_point3(*q))
                        .is_none_or(|q| m.u[grid.linear(q.map(|v| v.round() as usize))].is_finite())
                })
        };
        let hit = cache.and_then(|c| c.map(&key)).filter(|m| ends_reached(m));
        let (map, stats) = match hit {
            Some(m) => {
                let s = LegStats {
                    cached: true,
                    frozen: m.frozen,
                    stop: m.stop.clone(),
                    solve_seconds: 0.0,
                };
                (m, s)
            }
            None => {
                // A miss after a partial map: the user explores, compute all of it.
                let early = req.early_stop && cache.and_then(|c| c.map(&key)).is_none();
                let m = solve_leg(req, &cost, &leg, early, control)?;
                let s = LegStats {
                    cached: false,
                    frozen: m.0.frozen,
                    stop: m.0.stop.clone(),
                    solve_seconds: m.1,
                };
                let m = Arc::new(m.0);
                if let Some(cache) = cache {
                    cache.put_map(key, m.clone());
                }
                (m, s)
            }
        };
        maps.push(stats);
        let t = Instant::now();
        let dm = DistanceMap::new(grid, &map.u, map.cost.w.as_slice())
            .map_err(|e| OpError::invalid("cost", e.to_string()))?;
        for (end_index, (field, end)) in leg.ends.iter().enumerate() {
            if control.is_cancelled() {
                return Err(OpError::Cancelled);
            }
            let path = dm
                .descend(&map.sources, end, &Isotropic, &descent)
                .map_err(|e| path_error(e, field, &*leg.source_field))?;
            let index = if chain_mode { leg_index } else { end_index };
            paths.push(PathOut::new(index, end, &path, grid));
        }
        descent_seconds += t.elapsed().as_secs_f64();
    }
    let stats = PathsStats {
        cells: grid.len() as u64,
        cost_cached,
        cost_seconds,
        maps,
        descent_seconds,
    };
    assemble(req, inputs, &cost, paths, stats)
}

/// `grid.paths` with a tensor `metric`: one anisotropic solve per leg and
/// the descent along `−M⁻¹∇U`, without the cache (see the module docs).
fn execute_tensor(
    req: &GridPathsRequest,
    metric: &TensorSpec,
    inputs: &dyn Inputs,
    limits: &OpLimits,
    control: &Control<'_>,
) -> Result<GridPathsResult, OpError> {
    let started = Instant::now();
    let resolved = resolve_tensor(
        metric,
        "metric",
        req.spacing.as_deref(),
        req.obstacles.as_deref(),
        inputs,
        limits,
        control,
    )?;
    if req.format != PathFormat::Json && resolved.grid.ndim() == 3 {
        return Err(OpError::invalid(
            "format",
            "geojson and svg are for 2D grids; use json in 3D",
        ));
    }
    // A scalar picture of the metric (sqrt(tr M / d), +inf on walls): only
    // the SVG background reads it, so other formats skip the pass over the grid.
    let cost = {
        let w = if req.format == PathFormat::Svg {
            let r = Riemannian::new(&resolved.grid, &resolved.metric);
            (0..resolved.grid.len()).map(|i| r.cost_at(i)).collect()
        } else {
            Vec::new()
        };
        CachedCost {
            w,
            grid: resolved.grid.clone(),
            spacing: resolved.spacing.clone(),
        }
    };
    let cost_seconds = started.elapsed().as_secs_f64();
    let (mut problem, _) = resolved.into_problem(Vec::new());
    let descent = DescentOptions {
        step: req.step,
        ..DescentOptions::default()
    };
    let (mut maps, mut paths, mut descent_seconds) = (Vec::new(), Vec::new(), 0.0);
    let chain_mode = req.ends.is_empty();
    for (leg_index, leg) in req.legs().into_iter().enumerate() {
        let grid = &problem.grid;
        let targets: Vec<Vec<f64>> = if req.early_stop {
            leg.ends
                .iter()
                .filter(|(_, p)| grid.point3(p).is_ok_and(|q| grid.contains_point3(q)))
                .map(|(_, p)| p.clone())
                .collect()
        } else {
            Vec::new()
        };
        problem.sources = leg.sources.iter().map(SourceSpec::to_source).collect();
        let spec = TensorSolveSpec {
            order: req.order,
            factoring: req.factoring,
            stop: StopRules {
                targets,
                ..StopRules::default()
            },
            record_order: false,
        };
        let solved = solve_tensor(&problem, &spec, "metric", control)
            .map_err(|e| rename_leg_source(e, &leg))?;
        let out = &solved.out.output;
        maps.push(LegStats {
            cached: false,
            frozen: out.frozen as u64,
            stop: stop_name(out.stop).to_string(),
            solve_seconds: solved.seconds,
        });
        let t = Instant::now();
        // The solver's array is in standard layout: borrow it, copy only otherwise.
        let owned: Vec<f64>;
        let u: &[f64] = match out.distance.as_slice() {
            Some(u) => u,
            None => {
                owned = out.distance.iter().copied().collect();
                &owned
            }
        };
        let grid = &problem.grid;
        let set = SourceSet::new(grid, &problem.sources)
            .map_err(|e| path_error(e, "ends", &*leg.source_field))?;
        let riemannian = Riemannian::new(grid, &problem.metric);
        let dm = DistanceMap::new(grid, u, &riemannian)
            .map_err(|e| OpError::invalid("metric", e.to_string()))?;
        for (end_index, (field, end)) in leg.ends.iter().enumerate() {
            if control.is_cancelled() {
                return Err(OpError::Cancelled);
            }
            let path = dm
                .descend(&set, end, &riemannian, &descent)
                .map_err(|e| path_error(e, field, &*leg.source_field))?;
            let index = if chain_mode { leg_index } else { end_index };
            paths.push(PathOut::new(index, end, &path, grid));
        }
        descent_seconds += t.elapsed().as_secs_f64();
    }
    let stats = PathsStats {
        cells: problem.grid.len() as u64,
        cost_cached: false,
        cost_seconds,
        maps,
        descent_seconds,
    };
    assemble(req, inputs, &cost, paths, stats)
}

/// Renames a `sources[i]` error of a leg's solve to the leg's own field (a
/// way-point, a contour point).
fn rename_leg_source(e: OpError, leg: &Leg) -> OpError {
    match e.field().and_then(|f| f.strip_prefix("sources[")) {
        Some(rest) => {
            let index = rest
                .split(']')
                .next()
                .and_then(|i| i.parse().ok())
                .unwrap_or(0);
            match e {
                OpError::Invalid { reason, .. } => {
                    OpError::invalid((leg.source_field)(index), reason)
                }
                other => other,
            }
        }
        None => e,
    }
}

/// The answer of [`execute`]: the chain (way-point and contour modes) and
/// the formats, from the paths of every leg.
fn assemble(
    req: &GridPathsRequest,
    inputs: &dyn Inputs,
    cost: &CachedCost,
    paths: Vec<PathOut>,
    stats: PathsStats,
) -> Result<GridPathsResult, OpError> {
    let chain = (!req.waypoints.is_empty() || !req.contour.is_empty()).then(|| {
        let mut points: Vec<Vec<f64>> = Vec::new();
        let mut world: Vec<Vec<f64>> = Vec::new();
        for p in &paths {
            let skip = usize::from(!points.is_empty());
            points.extend(p.points.iter().skip(skip).cloned());
            world.extend(p.world.iter().skip(skip).cloned());
        }
        ChainOut {
            closed: !req.contour.is_empty(),
            points,
            world,
            geodesic_length: paths.iter().map(|p| p.geodesic_length).sum(),
            euclidean_length: paths.iter().map(|p| p.euclidean_length).sum(),
        }
    });
    let geojson = (req.format == PathFormat::Geojson).then(|| geojson(&paths, chain.as_ref()));
    let svg = match req.format {
        PathFormat::Svg => Some(svg(req, inputs, cost, &paths, chain.as_ref())?),
        _ => None,
    };
    Ok(GridPathsResult {
        paths,
        chain,
        stats,
        geojson,
        svg,
    })
}

/// Solves the distance map of one leg; returns it with the solve time.
fn solve_leg(
    req: &GridPathsRequest,
    cost: &Arc<CachedCost>,
    leg: &Leg,
    early: bool,
    control: &Control<'_>,
) -> Result<(CachedMap, f64), OpError> {
    let grid = &cost.grid;
    let targets = if early {
        // Only the targets inside the grid: the others are refused by the descent, naming them.
        leg.ends
            .iter()
            .filter(|(_, p)| grid.point3(p).is_ok_and(|q| grid.contains_point3(q)))
            .map(|(_, p)| p.clone())
            .collect()
    } else {
        Vec::new()
    };
    let dreq = req.distance_request(leg.sources.clone(), targets.clone());
    let mut options = dreq.options();
    options.stop = StopRules {
        targets,
        ..StopRules::default()
    };
    let sources: Vec<Source> = leg.sources.iter().map(SourceSpec::to_source).collect();
    let iso = IsotropicCost::new(
        grid,
        CostValues::F64(Cow::Borrowed(&cost.w)),
        Interpretation::Cost,
        None,
    )
    .map_err(|e| OpError::invalid("cost", e.to_string()))?;
    let problem = EikonalProblem {
        grid: grid.clone(),
        cost: iso,
        sources,
    };
    let started = Instant::now();
    // Source errors name this leg's own field (a way-point, a contour point).
    let out = numerics::solve(&problem, &options, control)
        .map_err(|e| rename_leg_source(eikonal_error(e), leg))?;
    let solve_seconds = started.elapsed().as_secs_f64();
    let sources = SourceSet::new(grid, &problem.sources)
        .map_err(|e| path_error(e, "ends", &*leg.source_field))?;
    let complete = out.stop == numerics::StopReason::Completed;
    Ok((
        CachedMap {
            cost: cost.clone(),
            sources,
            u: out.distance.iter().copied().collect(),
            complete,
            frozen: out.frozen as u64,
            stop: stop_name(out.stop).to_string(),
        },
        solve_seconds,
    ))
}

/// GeoJSON FeatureCollection: one LineString per path (and one for the
/// chain), positions `[x, y] = [axis 1, axis 0] × spacing`.
fn geojson(paths: &[PathOut], chain: Option<&ChainOut>) -> serde_json::Value {
    let line =
        |world: &[Vec<f64>]| -> Vec<[f64; 2]> { world.iter().map(|p| [p[1], p[0]]).collect() };
    let mut features: Vec<serde_json::Value> = paths
        .iter()
        .map(|p| {
            serde_json::json!({
                "type": "Feature",
                "geometry": {"type": "LineString", "coordinates": line(&p.world)},
                "properties": {
                    "kind": "path",
                    "index": p.index,
                    "source": p.source,
                    "end": p.end,
                    "geodesic_length": p.geodesic_length,
                    "euclidean_length": p.euclidean_length,
                }
            })
        })
        .collect();
    if let Some(c) = chain {
        features.push(serde_json::json!({
            "type": "Feature",
            "geometry": {"type": "LineString", "coordinates": line(&c.world)},
            "properties": {
                "kind": if c.closed { "contour" } else { "chain" },
                "closed": c.closed,
                "geodesic_length": c.geodesic_length,
                "euclidean_length": c.euclidean_length,
            }
        }));
    }
    serde_json::json!({"type": "FeatureCollection", "features": features})
}

/// Standard base64 (RFC 4648) with padding.
fn base64(bytes: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for chunk in bytes.chunks(3) {
        let b = [
            chunk[0],
            chunk.get(1).copied().unwrap_or(0),
            chunk.get(2).copied().unwrap_or(0),
        ];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for k in 0..4 {
            if k <= chunk.len() {
                out.push(A[((n >> (18 - 6 * k)) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// SVG document: a grey PNG of the image (the `cost.dataset` array when the
/// inputs hold it, else `W`) with the paths drawn over it, in world units.
fn svg(
    req: &GridPathsRequest,
    inputs: &dyn Inputs,
    cost: &CachedCost,
    paths: &[PathOut],
    chain: Option<&ChainOut>,
) -> Result<String, OpError> {
    let grid = &cost.grid;
    let shape = grid.shape();
    let h = grid.spacing();
    let image = req
        .cost
        .as_ref()
        .and_then(|c| c.dataset.as_deref())
        .and_then(|id| inputs.get(id))
        .map(|a| a.array)
        .filter(|a| a.shape() == shape);
    let w_array;
    let shown: &ArrayData = match &image {
        Some(a) => a,
        None => {
            let w: Vec<f64> = cost
                .w
                .iter()
                .map(|&v| if v.is_finite() { v } else { f64::NAN })
                .collect();
            w_array = ArrayData::F64(
                ndarray::ArrayD::from_shape_vec(ndarray::IxDyn(shape), w)
                    .map_err(|e| OpError::invalid("cost", e.to_string()))?,
            );
            &w_array
        }
    };
    let options = RenderOptions {
        style: RenderStyle::Continuous,
        colormap: Colormap::Grey,
        ..RenderOptions::default()
    };
    // A constant image has no range to map: the paths are drawn alone.
    let png = render_png(shown, &options).ok();
    let (wx, wy) = (shape[1] as f64 * h[1], shape[0] as f64 * h[0]);
    let (x0, y0) = (-0.5 * h[1], -0.5 * h[0]);
    let stroke = 0.004 * wx.max(wy);
    let mut s = String::new();
    // Writing to a String cannot fail.
    let _ = write!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" viewBox="{x0} {y0} {wx} {wy}" width="{}" height="{}">"#,
        shape[1].max(1) as f64 * h[1] / h[0].min(h[1]),
        shape[0].max(1) as f64 * h[0] / h[0].min(h[1]),
    );
    if let Some(png) = png {
        let _ = write!(
            s,
            r#"<image x="{x0}" y="{y0}" width="{wx}" height="{wy}" preserveAspectRatio="none" style="image-rendering:pixelated" href="data:image/png;base64,{}"/>"#,
            base64(&png)
        );
    }
    let polyline = |s: &mut String, world: &[Vec<f64>], colour: &str, closed: bool| {
        let pts: Vec<String> = world.iter().map(|p| format!("{},{}", p[1], p[0])).collect();
        let tag = if closed { "polygon" } else { "polyline" };
        let _ = write!(
            s,
            r#"<{tag} points="{}" fill="none" stroke="{colour}" stroke-width="{stroke}" stroke-linejoin="round"/>"#,
            pts.join(" ")
        );
    };
    match chain {
        Some(c) => polyline(&mut s, &c.world, "#ff3b30", c.closed),
        None => {
            for p in paths {
                polyline(&mut s, &p.world, "#ff3b30", false);
            }
        }
    }
    for p in paths {
        for (q, colour) in [(p.world.first(), "#34c759"), (p.world.last(), "#0a84ff")] {
            if let Some(q) = q {
                let _ = write!(
                    s,
                    r#"<circle cx="{}" cy="{}" r="{}" fill="{colour}"/>"#,
                    q[1],
                    q[0],
                    2.0 * stroke
                );
            }
        }
    }
    s.push_str("</svg>");
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ops::InputArray;

    fn request(v: serde_json::Value) -> GridPathsRequest {
        serde_json::from_value(v).unwrap()
    }

    #[test]
    fn base64_matches_rfc_4648_vectors() {
        for (a, b) in [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ] {
            assert_eq!(base64(a.as_bytes()), b);
        }
    }

    #[test]
    fn modes_are_exclusive_and_fields_are_named() {
        let limits = OpLimits::default();
        let cost = serde_json::json!({"constant": 1.0, "shape": [20, 20]});
        let bad = [
            (serde_json::json!({"cost": cost}), "ends"),
            (
                serde_json::json!({"cost": cost, "sources": [{"point": [1.0, 1.0]}]}),
                "ends",
            ),
            (
                serde_json::json!({"cost": cost, "waypoints": [[1.0, 1.0]]}),
                "waypoints",
            ),
            (
                serde_json::json!({"cost": cost, "contour": [[1.0, 1.0], [2.0, 2.0]]}),
                "contour",
            ),
            (
                serde_json::json!({"cost": cost, "waypoints": [[1.0, 1.0], [2.0, 2.0]], "contour": [[1.0, 1.0], [2.0, 2.0], [3.0, 3.0]]}),
                "waypoints",
            ),
            (
                serde_json::json!({"cost": cost, "sources": [{"point": [1.0, 1.0]}], "ends": [[2.0]]}),
                "ends[0]",
            ),
            (
                serde_json::json!({"cost": cost, "waypoints": [[1.0, 1.0], [2.0, 2.0]], "step": 0.7}),
                "step",
            ),
        ];
        for (v, field) in bad {
            let r = request(v.clone());
            assert_eq!(r.validate(&limits).unwrap_err().field(), Some(field), "{v}");
        }
    }

    #[test]
    fn chains_and_contours_join_their_legs_and_the_cache_skips_solves() {
        let cache = DistanceCache::new(1 << 20);
        let inputs: HashMap<String, InputArray> = HashMap::new();
        let limits = OpLimits::default();
        let r = request(serde_json::json!({
            "cost": {"constant": 1.0, "shape": [40, 40]},
            "contour": [[5.0, 5.0], [5.0, 30.0], [30.0, 20.0]]
        }));
        let out = execute(&r, &inputs, &limits, &Control::new(), Some(&cache), None).unwrap();
        let chain = out.chain.unwrap();
        assert!(chain.closed);
        assert_eq!(chain.points.first(), chain.points.last());
        // A triangle: the sum of its sides.
        let perimeter = 25.0 + (625.0f64 + 100.0).sqrt() + (625.0f64 + 225.0).sqrt();
        assert!((chain.euclidean_length - perimeter).abs() < 0.2);
        assert_eq!(out.paths.len(), 3);
        assert!(out.stats.maps.iter().all(|m| !m.cached));
        // Moving the last point: the two first legs' maps are reused.
        let r2 = request(serde_json::json!({
            "cost": {"constant": 1.0, "shape": [40, 40]},
            "waypoints": [[5.0, 5.0], [5.0, 30.0], [30.0, 21.0]]
        }));
        let out2 = execute(&r2, &inputs, &limits, &Control::new(), Some(&cache), None).unwrap();
        assert!(out2.stats.cost_cached);
        assert!(out2.stats.maps.iter().all(|m| m.cached), "{:?}", out2.stats);
        assert!(!out2.chain.unwrap().closed);
        // The SVG and GeoJSON forms.
        let mut r3 = r2.clone();
        r3.format = PathFormat::Geojson;
        let g = execute(&r3, &inputs, &limits, &Control::new(), Some(&cache), None)
            .unwrap()
            .geojson
            .unwrap();
        assert_eq!(g["features"].as_array().unwrap().len(), 3);
        assert_eq!(g["features"][2]["geometry"]["type"], "LineString");
        r3.format = PathFormat::Svg;
        let s = execute(&r3, &inputs, &limits, &Control::new(), Some(&cache), None)
            .unwrap()
            .svg
            .unwrap();
        assert!(s.starts_with("<svg") && s.contains("<polyline") && s.ends_with("</svg>"));
    }

    #[test]
    fn the_cache_stays_within_its_budget() {
        let cache = DistanceCache::new(3 * 8 * 100);
        let grid = Grid::unit(&[10, 10]).unwrap();
        for k in 0..5 {
            cache.put_cost(
                format!("c{k}"),
                Arc::new(CachedCost {
                    grid: grid.clone(),
                    spacing: vec![1.0, 1.0],
                    w: vec![1.0; 100],
                }),
            );
        }
        assert_eq!(cache.len(), (3, 0));
        assert!(cache.cost("c0").is_none() && cache.cost("c4").is_some());
        let tiny = DistanceCache::new(10);
        tiny.put_cost(
            "x".into(),
            Arc::new(CachedCost {
                grid,
                spacing: vec![1.0, 1.0],
                w: vec![1.0; 100],
            }),
        );
        assert!(tiny.is_empty());
    }
}
