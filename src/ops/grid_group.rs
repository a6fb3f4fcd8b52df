//! `grid.group`: perceptual grouping of key points into contours by minimal
//! paths (see [`crate::numerics::grouping`]): the geodesic Voronoi diagram
//! of the key points, the saddle point and minimal path of every pair of
//! adjacent cells, the cheap links, and their connected components as
//! open or closed polylines.

use std::time::Instant;

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::spec::cost::{resolve_cost, CostSpec};
use super::spec::defaults::default_order;
use super::spec::grid::{check_point, check_spacing, shaped};
use super::{Inputs, OpError, OpLimits, OpOutput, Operation, OutputArray};
use crate::io::ArrayData;
use crate::numerics::grouping::{
    group, GroupingError, GroupingOptions, GroupingProblem, Selection,
};
use crate::numerics::{Control, Order};

/// Request of `grid.group` (`POST /v1/grid/group`, `geodex group`).
///
/// The key points are linked through the metric: each pair of points whose
/// geodesic Voronoi cells touch is a candidate link, whose cost is the
/// geodesic distance between them (`U_i + U_j` at the saddle point where
/// their fronts meet). The cheap links are kept (each point keeps at most
/// `max_links`, mutually, within `ratio` of its cheapest and `relative` of
/// the typical link), and the contours are the connected components.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"cost": {"constant": 1.0, "shape": [64, 64]}, "key_points": [[10.0, 10.0], [10.0, 20.0], [10.0, 30.0], [50.0, 50.0]]}))]
pub struct GridGroupRequest {
    /// The isotropic cost `W` (2D), exactly as in `grid.distance`: small
    /// along the structures to group (e.g. `design: edges`), or a constant.
    pub cost: CostSpec,
    /// Physical size of a cell along each axis. Default: the cost dataset's, else 1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(min_items = 2, max_items = 2)]
    pub spacing: Option<Vec<f64>>,
    /// Id of a mask dataset whose non-zero cells are walls.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub obstacles: Option<String>,
    /// The key points, index coordinates `[row, column]` (may lie between
    /// cells); at least 2.
    pub key_points: Vec<Vec<f64>>,
    /// One tangent angle per key point (radians, from axis 0 towards axis 1;
    /// `θ` and `θ + π` are the same): the anisotropic grouping, whose metric
    /// is up to `anisotropy` times cheaper along the interpolated tangents.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub orientations: Option<Vec<f64>>,
    /// With orientations: how many times cheaper a step along the tangent is
    /// than across it where nearby orientations agree, in `[1, 100]`. Default: 4.
    #[serde(default = "default_anisotropy")]
    pub anisotropy: f64,
    /// With orientations: the width `σ` (physical units) of the Gaussian
    /// that interpolates them. Default: the median distance from a key point
    /// to its nearest other key point.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(exclusive_minimum = 0.0)]
    pub spread: Option<f64>,
    /// Each key point keeps at most this many links (mutually: a link is kept
    /// only if it is among the `max_links` cheapest of both ends). 2 gives
    /// chains and cycles. Default: 2.
    #[serde(default = "default_max_links")]
    #[schema(minimum = 1)]
    pub max_links: usize,
    /// A link is kept only if it costs at most `ratio` times the cheapest
    /// link of each of its ends (>= 1). Default: 2.5.
    #[serde(default = "default_ratio")]
    pub ratio: f64,
    /// A link is kept only if it costs at most `relative` times the typical
    /// link (the median of the key points' cheapest link); `null`: no such
    /// bound. Default: 3.
    #[serde(default = "default_relative")]
    pub relative: Option<f64>,
    /// A link is kept only if it costs at most this (units of `∫ W`). Default: none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(exclusive_minimum = 0.0)]
    pub max_cost: Option<f64>,
    /// Contours with fewer key points are dropped (>= 2). Default: 2.
    #[serde(default = "default_min_points")]
    #[schema(minimum = 2)]
    pub min_points: usize,
    /// Order of the isotropic fast marching, 1 or 2. Default: 2.
    #[serde(default = "default_order")]
    pub order: u8,
}

fn default_anisotropy() -> f64 {
    4.0
}
fn default_max_links() -> usize {
    2
}
fn default_ratio() -> f64 {
    2.5
}
#[allow(clippy::unnecessary_wraps)]
fn default_relative() -> Option<f64> {
    Some(3.0)
}
fn default_min_points() -> usize {
    2
}

impl GridGroupRequest {
    fn options(&self) -> GroupingOptions {
        GroupingOptions {
            selection: Selection {
                max_links: self.max_links,
                ratio: self.ratio,
                relative: self.relative,
                max_cost: self.max_cost,
                min_points: self.min_points,
            },
            anisotropy: self.anisotropy,
            spread: self.spread,
            order: if self.order == 1 {
                Order::First
            } else {
                Order::Second
            },
            ..GroupingOptions::default()
        }
    }
}

impl Operation for GridGroupRequest {
    const NAME: &'static str = "grid.group";

    fn validate(&self, limits: &OpLimits) -> Result<(), OpError> {
        self.cost.validate(limits)?;
        if let Some(shape) = &self.cost.shape {
            if shape.len() != 2 {
                return Err(OpError::invalid(
                    "cost.shape",
                    format!("grouping works on 2D grids, got {} axes", shape.len()),
                ));
            }
        }
        check_spacing(&self.spacing)?;
        if let Some(s) = &self.spacing {
            if s.len() != 2 {
                return Err(OpError::invalid(
                    "spacing",
                    format!("a 2D grid has 2 spacings, got {}", s.len()),
                ));
            }
        }
        let n = self.key_points.len();
        if n < 2 {
            return Err(OpError::invalid(
                "key_points",
                format!("give at least 2 key points to group, got {n}"),
            ));
        }
        if n > limits.max_sources {
            return Err(OpError::TooLarge {
                field: "key_points".into(),
                reason: format!("more than {} key points", limits.max_sources),
            });
        }
        for (k, p) in self.key_points.iter().enumerate() {
            check_point(p, &format!("key_points[{k}]"), Some(2))?;
        }
        if let Some(shape) = &self.cost.shape {
            for (k, p) in self.key_points.iter().enumerate() {
                if (0..2).any(|a| p[a] < 0.0 || p[a] > (shape[a] - 1) as f64) {
                    return Err(OpError::invalid(
                        format!("key_points[{k}]"),
                        format!("{p:?} is outside the grid of shape {shape:?} (row, column)"),
                    ));
                }
            }
        }
        if let Some(o) = &self.orientations {
            if o.len() != n {
                return Err(OpError::invalid(
                    "orientations",
                    format!(
                        "{} angles for {n} key points: give one tangent angle per key point, or leave `orientations` out",
                        o.len()
                    ),
                ));
            }
            if let Some(k) = o.iter().position(|v| !v.is_finite()) {
                return Err(OpError::invalid(
                    format!("orientations[{k}]"),
                    "an angle must be finite (radians)",
                ));
            }
        }
        if !(self.anisotropy.is_finite() && (1.0..=100.0).contains(&self.anisotropy)) {
            return Err(OpError::invalid(
                "anisotropy",
                format!("{} must be in [1, 100]", self.anisotropy),
            ));
        }
        for (field, v) in [
            ("spread", self.spread),
            ("relative", self.relative),
            ("max_cost", self.max_cost),
        ] {
            if let Some(v) = v {
                if !(v.is_finite() && v > 0.0) {
                    return Err(OpError::invalid(
                        field,
                        format!("{v} must be finite and > 0"),
                    ));
                }
            }
        }
        if self.max_links == 0 {
            return Err(OpError::invalid(
                "max_links",
                "must be >= 1 (2 gives chains and cycles)",
            ));
        }
        if !(self.ratio.is_finite() && self.ratio >= 1.0) {
            return Err(OpError::invalid(
                "ratio",
                format!("{} must be finite and >= 1", self.ratio),
            ));
        }
        if self.min_points < 2 {
            return Err(OpError::invalid("min_points", "must be >= 2"));
        }
        if !matches!(self.order, 1 | 2) {
            return Err(OpError::invalid("order", "must be 1 or 2"));
        }
        Ok(())
    }

    fn dataset_ids(&self) -> Vec<(String, String)> {
        let mut ids = Vec::new();
        if let Some(id) = &self.cost.dataset {
            ids.push(("cost.dataset".to_string(), id.clone()));
        }
        if let Some(id) = &self.obstacles {
            ids.push(("obstacles".to_string(), id.clone()));
        }
        ids
    }

    /// Arrays: `labels` (int32, the geodesic Voronoi cell of each pixel:
    /// the index of its key point, -1 where not reached), `distance` (f64,
    /// to the nearest key point). Document: `{"links": [{"pair", "saddle",
    /// "geodesic_length", "kept", "path"? (from `pair[0]` to `pair[1]`), "euclidean_length"?}], "contours": [{"key_points",
    /// "links", "closed", "branched", "polyline"?}], "isolated": [...],
    /// "geojson": FeatureCollection, "stats": {...}}`.
    fn run(
        &self,
        inputs: &dyn Inputs,
        limits: &OpLimits,
        control: &Control<'_>,
    ) -> Result<OpOutput, OpError> {
        self.validate(limits)?;
        let resolved = resolve_cost(
            &self.cost,
            self.spacing.as_deref(),
            self.obstacles.as_deref(),
            inputs,
            limits,
            control,
        )?;
        if resolved.grid.ndim() != 2 {
            return Err(OpError::invalid(
                "cost.dataset",
                format!(
                    "grouping works on 2D grids, the cost has shape {:?}",
                    resolved.grid.shape()
                ),
            ));
        }
        let cost = resolved.isotropic()?;
        let problem = GroupingProblem {
            grid: resolved.grid.clone(),
            cost,
            key_points: self.key_points.iter().map(|p| [p[0], p[1]]).collect(),
            orientations: self.orientations.clone(),
        };
        let started = Instant::now();
        let out = group(&problem, &self.options(), control).map_err(grouping_error)?;
        let seconds = started.elapsed().as_secs_f64();
        let grid = &resolved.grid;
        let h = grid.spacing().to_vec();
        let world = |line: &[[f64; 2]]| -> Vec<[f64; 2]> {
            line.iter().map(|p| [p[1] * h[1], p[0] * h[0]]).collect()
        };
        let links: Vec<serde_json::Value> = out
            .links
            .iter()
            .map(|l| {
                let mut v = serde_json::json!({
                    "pair": l.pair,
                    "saddle": l.saddle,
                    "geodesic_length": l.cost,
                    "kept": l.kept,
                });
                if let (Some(p), Some(len)) = (&l.path, l.path_length) {
                    v["path"] = serde_json::json!(p);
                    v["euclidean_length"] = serde_json::json!(len);
                }
                v
            })
            .collect();
        let contours: Vec<serde_json::Value> = out
            .contours
            .iter()
            .map(|c| {
                serde_json::json!({
                    "key_points": c.key_points,
                    "links": c.links,
                    "closed": c.closed,
                    "branched": c.branched,
                    "polyline": c.polyline,
                })
            })
            .collect();
        let features: Vec<serde_json::Value> = out
            .contours
            .iter()
            .enumerate()
            .filter_map(|(k, c)| {
                let line = c.polyline.as_ref()?;
                Some(serde_json::json!({
                    "type": "Feature",
                    "geometry": {"type": "LineString", "coordinates": world(line)},
                    "properties": {
                        "kind": if c.closed { "closed_contour" } else { "open_contour" },
                        "contour": k,
                        "closed": c.closed,
                        "key_points": c.key_points,
                    }
                }))
            })
            .collect();
        let kept = out.links.iter().filter(|l| l.kept).count();
        let document = serde_json::json!({
            "links": links,
            "contours": contours,
            "isolated": out.isolated,
            "geojson": {"type": "FeatureCollection", "features": features},
            "stats": {
                "key_points": self.key_points.len(),
                "candidates": out.links.len(),
                "kept": kept,
                "contours": out.contours.len(),
                "closed": out.contours.iter().filter(|c| c.closed).count(),
                "isolated": out.isolated.len(),
                "typical_cost": if out.typical_cost.is_finite() { Some(out.typical_cost) } else { None },
                "path_failures": out.path_failures,
                "anisotropic": self.orientations.is_some(),
                "spread": out.spread,
                "seconds": seconds,
            },
        });
        let spacing = Some(resolved.spacing.clone());
        Ok(OpOutput::new(
            vec![
                OutputArray {
                    name: "labels".into(),
                    array: ArrayData::I32(shaped(grid, out.labels)?),
                    spacing: spacing.clone(),
                },
                OutputArray {
                    name: "distance".into(),
                    array: ArrayData::F64(shaped(grid, out.distance)?),
                    spacing,
                },
            ],
            document,
        ))
    }
}

/// A core error as an [`OpError`] naming the request field.
fn grouping_error(e: GroupingError) -> OpError {
    match e {
        GroupingError::Cancelled => OpError::Cancelled,
        GroupingError::KeyPoint { index, reason } => {
            OpError::invalid(format!("key_points[{index}]"), reason)
        }
        GroupingError::TooFewPoints(_) => OpError::invalid("key_points", e.to_string()),
        GroupingError::Orientations(_) => OpError::invalid("orientations", e.to_string()),
        GroupingError::Option { field, .. } => OpError::invalid(field, e.to_string()),
        GroupingError::NotTwoD(_) => OpError::invalid("cost", e.to_string()),
        GroupingError::Solve(_) => OpError::invalid("cost", e.to_string()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn request(points: Vec<Vec<f64>>) -> GridGroupRequest {
        serde_json::from_value(serde_json::json!({
            "cost": {"constant": 1.0, "shape": [40, 40]},
            "key_points": points,
        }))
        .unwrap()
    }

    #[test]
    fn refusals_name_the_field() {
        let limits = OpLimits::default();
        let field = |r: &GridGroupRequest| {
            r.validate(&limits)
                .unwrap_err()
                .field()
                .unwrap_or_default()
                .to_string()
        };
        assert_eq!(field(&request(vec![vec![1.0, 1.0]])), "key_points");
        assert_eq!(
            field(&request(vec![vec![1.0, 1.0], vec![1.0, 40.0]])),
            "key_points[1]"
        );
        let mut r = request(vec![vec![1.0, 1.0], vec![1.0, 4.0]]);
        r.orientations = Some(vec![0.0]);
        assert_eq!(field(&r), "orientations");
        let mut r = request(vec![vec![1.0, 1.0], vec![1.0, 4.0]]);
        r.ratio = 0.5;
        assert_eq!(field(&r), "ratio");
        let r = request(vec![vec![1.0, 1.0], vec![1.0, 4.0]]);
        assert!(r.validate(&limits).is_ok());
        assert_eq!(r.relative, Some(3.0));
    }
}
