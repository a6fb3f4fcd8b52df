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

mod render;
mod solve;

pub use super::spec::map_cache::{CachedCost, CachedMap, DistanceCache, MapCache};
pub use solve::execute;

use std::sync::Arc;

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::spec::cost::CostSpec;
use super::spec::distance::GridDistanceRequest;
use super::spec::map_cache;
use super::spec::scheme::{
    check_metric_choice, metric_dataset_ids, refuse_dataset_sources, ConnectivitySpec, MethodSpec,
    OutputSpec, SourceSpec, StopSpec,
};
use super::spec::tensor::TensorSpec;
use super::{Inputs, OpError, OpLimits, OpOutput, Operation};
use crate::numerics::paths::MinimalPath;
use crate::numerics::{Control, Grid};
use crate::ops::spec::defaults::default_order;
use crate::ops::spec::defaults::default_step;
use crate::ops::spec::defaults::default_true;

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
    /// Tolerance, in cells, of the Ramer–Douglas–Peucker simplification of
    /// each path's vertices ([`crate::numerics::polyline`]): every dropped
    /// vertex lies within `simplify` cells of the returned polyline. The
    /// lengths are those of the full path. Default: 0, every vertex (one per
    /// `step`). A front end drawing on screen wants about 0.25.
    #[serde(default, skip_serializing_if = "is_zero")]
    #[schema(minimum = 0.0, maximum = 100.0)]
    pub simplify: f64,
    /// Answer format: `json` (default), `geojson` (a FeatureCollection of
    /// LineStrings, 2D) or `svg` (the paths over a PNG of the image, 2D).
    #[serde(default)]
    pub format: PathFormat,
    /// A cached cost taken before the inputs were loaded
    /// ([`Operation::datasets_to_load`]); not part of the request.
    #[serde(skip)]
    pub pinned: PinnedCost,
}

/// A cost taken from the [`DistanceCache`] when the request arrived, so that
/// an eviction between then and the run cannot leave the run without its
/// inputs (which were not loaded). Requests compare equal whatever it holds.
#[derive(Debug, Clone, Default)]
pub struct PinnedCost(pub Option<Arc<CachedCost>>);

impl PartialEq for PinnedCost {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

/// Serde's `skip_serializing_if` for a zero tolerance.
fn is_zero(v: &f64) -> bool {
    *v == 0.0
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
    /// The answer's form of a descended path (`index` as in
    /// [`PathOut::index`]), its vertices simplified to `simplify` cells.
    fn new(index: usize, end: &[f64], path: &MinimalPath, grid: &Grid, simplify: f64) -> Self {
        let simplified;
        let path = if simplify > 0.0 {
            let kept = crate::numerics::polyline::simplify(&path.points, simplify);
            simplified = MinimalPath {
                points: kept.iter().map(|&k| path.points[k]).collect(),
                source: path.source,
                geodesic_length: path.geodesic_length,
                euclidean_length: path.euclidean_length,
                continuous_steps: path.continuous_steps,
                discrete_steps: path.discrete_steps,
            };
            &simplified
        } else {
            path
        };
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
            // Level sets and masks would need their datasets in the map cache's key.
            refuse_dataset_sources(&self.sources, "grid.paths")?;
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
        if !(self.simplify.is_finite() && (0.0..=100.0).contains(&self.simplify)) {
            return Err(OpError::invalid(
                "simplify",
                format!(
                    "{} must be in [0, 100] cells (0 keeps every vertex)",
                    self.simplify
                ),
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
            signed: false,
        }
    }

    fn legs(&self) -> Vec<Leg> {
        let point = |p: &Vec<f64>| SourceSpec::at_point(p.clone());
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
        map_cache::cost_key(
            self.cost.as_ref(),
            self.metric.as_ref(),
            self.spacing.as_deref(),
            self.obstacles.as_deref(),
        )
    }

    fn map_key(&self, cost_key: &str, sources: &[SourceSpec]) -> String {
        map_cache::map_key(
            cost_key,
            sources,
            self.method,
            self.order,
            self.factoring,
            self.connectivity,
        )
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

    /// None when the caller's cache holds the (designed) cost, which is then
    /// pinned; the SVG format still reads the image.
    fn datasets_to_load(&mut self, inputs: &dyn Inputs) -> Vec<(String, String)> {
        if self.cost.is_some() {
            self.pinned = PinnedCost(
                inputs
                    .distance_cache()
                    .and_then(|c| c.cost(&self.cost_key())),
            );
        }
        if self.pinned.0.is_some() && self.format != PathFormat::Svg {
            Vec::new()
        } else {
            self.dataset_ids()
        }
    }

    /// No arrays. Document: `{"paths": [PathOut], "chain"?: ChainOut,
    /// "stats": PathsStats, "geojson"?: FeatureCollection, "svg"?: string}`.
    fn run(
        &self,
        inputs: &dyn Inputs,
        limits: &OpLimits,
        control: &Control<'_>,
    ) -> Result<OpOutput, OpError> {
        let cache = inputs.distance_cache();
        let result = execute(self, inputs, limits, control, cache, self.pinned.0.clone())?;
        Ok(OpOutput::new(Vec::new(), result.document()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ops::InputArray;
    use std::collections::HashMap;

    fn request(v: serde_json::Value) -> GridPathsRequest {
        serde_json::from_value(v).unwrap()
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
            (
                serde_json::json!({"cost": cost, "waypoints": [[1.0, 1.0], [2.0, 2.0]], "simplify": -0.1}),
                "simplify",
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
    fn simplified_paths_keep_their_ends_lengths_and_tolerance() {
        // Straight paths on a constant cost: the full path has a vertex per
        // half cell; the simplified one keeps the ends and the lengths, and
        // stays within the tolerance of every full vertex.
        let inputs: HashMap<String, InputArray> = HashMap::new();
        let limits = OpLimits::default();
        let body = |simplify: f64| {
            request(serde_json::json!({
                "cost": {"constant": 1.0, "shape": [60, 60]},
                "sources": [{"point": [5.0, 5.0]}],
                "ends": [[50.0, 40.0], [7.0, 52.5]],
                "simplify": simplify
            }))
        };
        let full = execute(&body(0.0), &inputs, &limits, &Control::new(), None, None).unwrap();
        let tol = 0.25;
        let simple = execute(&body(tol), &inputs, &limits, &Control::new(), None, None).unwrap();
        for (f, s) in full.paths.iter().zip(&simple.paths) {
            assert!(f.points.len() > 40, "{}", f.points.len());
            assert!(
                s.points.len() * 5 < f.points.len(),
                "{} of {}",
                s.points.len(),
                f.points.len()
            );
            assert_eq!(f.points.first(), s.points.first());
            assert_eq!(f.points.last(), s.points.last());
            assert_eq!(f.geodesic_length, s.geodesic_length);
            assert_eq!(s.points.len(), s.world.len());
            let seg = |p: &[f64], a: &[f64], b: &[f64]| {
                let (ab0, ab1) = (b[0] - a[0], b[1] - a[1]);
                let l2 = ab0 * ab0 + ab1 * ab1;
                let t = if l2 > 0.0 {
                    (((p[0] - a[0]) * ab0 + (p[1] - a[1]) * ab1) / l2).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                (p[0] - a[0] - t * ab0).hypot(p[1] - a[1] - t * ab1)
            };
            for p in &f.points {
                let d = s
                    .points
                    .windows(2)
                    .map(|w| seg(p, &w[0], &w[1]))
                    .fold(f64::INFINITY, f64::min);
                assert!(d <= tol + 1e-12, "{p:?} is {d} from the simplified path");
            }
        }
    }

    /// Inputs with the interactive cache, as the HTTP layer has them.
    struct Cached(HashMap<String, InputArray>, DistanceCache);

    impl Inputs for Cached {
        fn get(&self, id: &str) -> Option<InputArray> {
            self.0.get(id).cloned()
        }
        fn distance_cache(&self) -> Option<&dyn MapCache> {
            Some(&self.1)
        }
    }

    #[test]
    fn a_distance_map_serves_the_paths_that_follow() {
        use crate::ops::grid_distance::GridDistanceRequest;
        let image = ndarray::ArrayD::from_shape_fn(vec![40, 50], |i| {
            if i[1] == 25 && i[0] > 8 {
                10u8
            } else {
                200u8
            }
        });
        let mut arrays = HashMap::new();
        arrays.insert(
            "img".to_string(),
            InputArray {
                array: Arc::new(crate::io::ArrayData::U8(image)),
                spacing: None,
            },
        );
        let inputs = Cached(arrays, DistanceCache::new(1 << 24));
        let limits = OpLimits::default();
        let cost =
            serde_json::json!({"dataset": "img", "design": {"kind": "intensity", "value": 200}});
        let sources = serde_json::json!([{"point": [30.0, 5.0]}]);
        let distance: GridDistanceRequest =
            serde_json::from_value(serde_json::json!({"cost": cost, "sources": sources})).unwrap();
        let shown = Operation::run(&distance, &inputs, &limits, &Control::new()).unwrap();
        assert_eq!(inputs.1.len(), (1, 1), "the cost and the map are kept");
        let paths = request(serde_json::json!({
            "cost": cost, "sources": sources, "ends": [[30.0, 45.0]], "early_stop": false
        }));
        let out = execute(
            &paths,
            &inputs,
            &limits,
            &Control::new(),
            Some(&inputs.1),
            None,
        )
        .unwrap();
        assert!(
            out.stats.cost_cached && out.stats.maps[0].cached,
            "{:?}",
            out.stats
        );
        // The same path as from a map of its own (no cache).
        let plain = execute(&paths, &inputs.0, &limits, &Control::new(), None, None).unwrap();
        assert_eq!(out.paths[0].points, plain.paths[0].points);
        // It goes around the wall's end (row <= 8).
        assert!(out.paths[0].points.iter().any(|p| p[0] <= 9.0));
        // A partial solve (early stop) is not kept, nor a job's (no cache).
        let partial: GridDistanceRequest = serde_json::from_value(serde_json::json!({
            "cost": cost, "sources": [{"point": [3.0, 3.0]}], "stop": {"max_distance": 2.0}
        }))
        .unwrap();
        Operation::run(&partial, &inputs, &limits, &Control::new()).unwrap();
        assert_eq!(inputs.1.len(), (1, 1));
        assert!(shown.arrays.iter().any(|a| a.name == "distance"));
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
