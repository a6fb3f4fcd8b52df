//! `grid.segment`: seeded segmentation by geodesic Voronoi cells of labelled
//! seeds under a metric (the `cost` of `grid.distance`), with the confidence
//! map, geodesic balls and the label contours as GeoJSON polygons.
//!
//! One eikonal solve per label (in parallel on the solver pool): `U_l` is the
//! distance to the seeds of label `l`; the answer is `argmin_l U_l`, the
//! smallest and the second smallest (other label) distances and their
//! difference (see [`crate::numerics::segmentation`]).

use std::collections::BTreeMap;
use std::time::Instant;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::spec::cost::{resolve_cost, CostSpec};
use super::spec::errors::eikonal_error;
use super::spec::grid::{check_non_negative, check_point, check_spacing, fetch, shaped};
use super::spec::scheme::{check_metric_choice, metric_dataset_ids, ConnectivitySpec, MethodSpec};
use super::spec::tensor::{resolve_tensor, solve_tensor, TensorSolveSpec, TensorSpec};
use super::{Inputs, OpError, OpLimits, OpOutput, Operation, OutputArray};
use crate::io::ArrayData;
use crate::numerics::anisotropic::TensorProblem;
use crate::numerics::contours;
use crate::numerics::eikonal::{EikonalOptions, EikonalProblem, Order, Source, StopRules};
use crate::numerics::segmentation::voronoi;
use crate::numerics::{self, Control};
use crate::ops::spec::defaults::default_order;
use crate::ops::spec::defaults::default_true;

/// Most distinct labels in one request (one eikonal solve each).
pub const MAX_LABELS: usize = 256;

/// Most polygon vertices returned in `contours`; beyond, contours are left out.
pub const MAX_CONTOUR_VERTICES: usize = 2_000_000;

/// Request of `grid.segment` (`POST /v1/grid/segment`, `geodex segment`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({
    "cost": {"dataset": "ds_0192f1b27c1e7d3a9d553c0f2b8a1e45"},
    "seeds": [{"label": 1, "point": [40, 40]}, {"label": 2, "point": [200, 180]}],
    "max_distance": 50.0
}))]
pub struct GridSegmentRequest {
    /// The isotropic metric, exactly as in `grid.distance`. Give exactly one
    /// of `cost` and `metric`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cost: Option<CostSpec>,
    /// A Riemannian metric (tensor field), exactly as in `grid.distance`:
    /// the Voronoi cells of the seeds under `sqrt(vᵀ M v)` (anisotropic fast
    /// marching, one solve per label). Give exactly one of `cost` and `metric`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub metric: Option<TensorSpec>,
    /// Physical size of a cell along each axis. Default: the cost dataset's, else 1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(min_items = 2, max_items = 3)]
    pub spacing: Option<Vec<f64>>,
    /// Id of a mask dataset whose non-zero cells are obstacles.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub obstacles: Option<String>,
    /// Labelled seeds: points or cells.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub seeds: Vec<SeedSpec>,
    /// Id of a label image of the grid's shape (scribbles): every cell with a
    /// non-zero integer value is a seed of that label.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seed_image: Option<String>,
    /// Geodesic ball radius: cells farther than this from every seed get label
    /// -1 and the `ball` output marks the others. Default: none (the whole grid).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(minimum = 0.0)]
    pub max_distance: Option<f64>,
    /// Order of the fast-marching scheme, 1 or 2. Default: 2.
    #[serde(default = "default_order")]
    #[schema(minimum = 1, maximum = 2)]
    pub order: u8,
    /// Return the contours of each label as GeoJSON polygons (2D only). Default: true.
    #[serde(default = "default_true")]
    pub contours: bool,
}

/// One seed: a label (>= 1) and a `point` or `cells`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct SeedSpec {
    /// The label (>= 1) this seed gives its Voronoi cell.
    #[schema(minimum = 1)]
    pub label: i32,
    /// A point in index coordinates (axis 0 first), possibly between cells.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(min_items = 2, max_items = 3)]
    pub point: Option<Vec<f64>>,
    /// Cells (index pairs or triples, axis 0 first): a scribble.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cells: Option<Vec<Vec<usize>>>,
}

impl GridSegmentRequest {
    fn check(&self, limits: &OpLimits) -> Result<(), OpError> {
        check_metric_choice(
            self.cost.as_ref(),
            self.metric.as_ref(),
            MethodSpec::FastMarching,
            ConnectivitySpec::default(),
            limits,
        )?;
        check_spacing(&self.spacing)?;
        if self.seeds.is_empty() && self.seed_image.is_none() {
            return Err(OpError::invalid(
                "seeds",
                "give labelled `seeds`, a `seed_image`, or both",
            ));
        }
        if self.seeds.len() > limits.max_sources {
            return Err(OpError::TooLarge {
                field: "seeds".into(),
                reason: format!("more than {} seeds", limits.max_sources),
            });
        }
        for (i, s) in self.seeds.iter().enumerate() {
            if s.label < 1 {
                return Err(OpError::invalid(
                    format!("seeds[{i}].label"),
                    format!("{} must be >= 1 (0 means no seed in a seed image)", s.label),
                ));
            }
            match (&s.point, &s.cells) {
                (Some(p), None) => check_point(p, &format!("seeds[{i}].point"), None)?,
                (None, Some(c)) if !c.is_empty() => {}
                _ => {
                    return Err(OpError::invalid(
                        format!("seeds[{i}]"),
                        "give exactly one of `point` or a non-empty `cells`",
                    ))
                }
            }
        }
        if let Some(d) = self.max_distance {
            check_non_negative(d, "max_distance")?;
        }
        if !(1..=2).contains(&self.order) {
            return Err(OpError::invalid(
                "order",
                format!("{} must be 1 or 2", self.order),
            ));
        }
        Ok(())
    }
}

/// The metric of a segmentation, resolved once for every label's solve.
enum SegmentMetric {
    Cost(super::spec::cost::ResolvedCost),
    Tensor(super::spec::tensor::ResolvedTensor),
}

/// Renames `sources[k]...` in an inner error to the field of the request that gave source `k`.
fn rename_source_field(e: OpError, origin: &[String]) -> OpError {
    let rename = |field: String| -> String {
        if let Some(rest) = field.strip_prefix("sources[") {
            if let Some((k, tail)) = rest.split_once(']') {
                if let Some(o) = k.parse::<usize>().ok().and_then(|k| origin.get(k)) {
                    return format!("{o}{tail}");
                }
            }
        }
        field
    };
    match e {
        OpError::Invalid { field, reason } => OpError::Invalid {
            field: rename(field),
            reason,
        },
        other => other,
    }
}

/// The polygons (GeoJSON rings of `[x, y]` vertices) and the cell count of one label.
type LabelPolygons = (Vec<Vec<Vec<[f64; 2]>>>, usize);

/// A GeoJSON FeatureCollection with one MultiPolygon per label of a 2D label
/// map (`-1`, unreached, is left out). Positions follow GeoJSON, as every
/// GeoJSON answer: `[x, y] = [column × spacing[1], row × spacing[0]]` (cell
/// `(i, j)` is the square of corners `(i ± 1/2, j ± 1/2)`); outer rings
/// turn counter-clockwise in that plane and holes clockwise (RFC 7946).
pub fn label_contours(
    labels: &[i32],
    shape: [usize; 2],
    spacing: [f64; 2],
    control: &Control<'_>,
) -> Result<serde_json::Value, OpError> {
    let l64: Vec<i64> = labels.iter().map(|&v| i64::from(v)).collect();
    let polys = contours::trace(&l64, shape, Some(-1), control)
        .map_err(|contours::ContourError::Cancelled| OpError::Cancelled)?
        .polygons();
    let vertices: usize = polys
        .iter()
        .map(|p| p.rings.iter().map(Vec::len).sum::<usize>())
        .sum();
    if vertices > MAX_CONTOUR_VERTICES {
        return Ok(serde_json::json!({
            "type": "FeatureCollection",
            "features": [],
            "truncated": format!("{vertices} vertices, more than {MAX_CONTOUR_VERTICES}; fetch the label map instead"),
        }));
    }
    let mut by_label: BTreeMap<i64, LabelPolygons> = BTreeMap::new();
    for p in polys {
        let e = by_label.entry(p.label).or_default();
        // The core's rings are in index order (axis 0, axis 1); swapping the
        // axes mirrors the plane, so each ring is also reversed to keep its turn.
        let rings = p
            .rings
            .iter()
            .map(|ring| {
                ring.iter()
                    .rev()
                    .map(|v| [v[1] * spacing[1], v[0] * spacing[0]])
                    .collect()
            })
            .collect();
        e.0.push(rings);
        e.1 += p.cells;
    }
    let features: Vec<serde_json::Value> = by_label
        .into_iter()
        .map(|(label, (polygons, cells))| {
            serde_json::json!({
                "type": "Feature",
                "properties": {"label": label, "cells": cells, "components": polygons.len()},
                "geometry": {"type": "MultiPolygon", "coordinates": polygons},
            })
        })
        .collect();
    Ok(serde_json::json!({"type": "FeatureCollection", "features": features}))
}

impl Operation for GridSegmentRequest {
    const NAME: &'static str = "grid.segment";

    fn validate(&self, limits: &OpLimits) -> Result<(), OpError> {
        self.check(limits)
    }

    fn dataset_ids(&self) -> Vec<(String, String)> {
        let mut ids = metric_dataset_ids(self.cost.as_ref(), self.metric.as_ref());
        if let Some(id) = &self.obstacles {
            ids.push(("obstacles".to_string(), id.clone()));
        }
        if let Some(id) = &self.seed_image {
            ids.push(("seed_image".to_string(), id.clone()));
        }
        ids
    }

    /// Arrays: `labels` (i32, -1 where no seed reaches), `distance` (f64,
    /// to the nearest seed), `second_distance` (f64, to the nearest seed of
    /// another label), `confidence` (f64, their difference), `ball` (u8, with
    /// `max_distance`). Document: `{"labels": [{"label", "cells", "seeds"}],
    /// "contours": GeoJSON (2D), "stats": {...}}`.
    fn run(
        &self,
        inputs: &dyn Inputs,
        limits: &OpLimits,
        control: &Control<'_>,
    ) -> Result<OpOutput, OpError> {
        self.check(limits)?;
        let started = Instant::now();
        // The metric is built once (design included) and shared by every label's solve.
        let resolved = match (&self.cost, &self.metric) {
            (Some(cost), _) => SegmentMetric::Cost(resolve_cost(
                cost,
                self.spacing.as_deref(),
                self.obstacles.as_deref(),
                inputs,
                limits,
                control,
            )?),
            (None, Some(metric)) => SegmentMetric::Tensor(resolve_tensor(
                metric,
                "metric",
                self.spacing.as_deref(),
                self.obstacles.as_deref(),
                inputs,
                limits,
                control,
            )?),
            (None, None) => return Err(OpError::invalid("cost", "missing")),
        };
        let (grid, spacing) = match &resolved {
            SegmentMetric::Cost(r) => (r.grid.clone(), r.spacing.clone()),
            SegmentMetric::Tensor(r) => (r.grid.clone(), r.spacing.clone()),
        };
        let shape = grid.shape().to_vec();
        let ndim = shape.len();
        // Sources per label, with the field each one came from.
        let mut per_label: BTreeMap<i32, (Vec<Source>, Vec<String>)> = BTreeMap::new();
        for (i, s) in self.seeds.iter().enumerate() {
            let e = per_label.entry(s.label).or_default();
            match (&s.point, &s.cells) {
                (Some(p), _) => {
                    check_point(p, &format!("seeds[{i}].point"), Some(ndim))?;
                    e.0.push(Source::Point(p.clone()));
                }
                (None, Some(c)) => e.0.push(Source::Cells {
                    cells: c.clone(),
                    values: None,
                }),
                (None, None) => return Err(OpError::invalid(format!("seeds[{i}]"), "no seed")),
            }
            e.1.push(format!("seeds[{i}]"));
        }
        if let Some(id) = &self.seed_image {
            let img = fetch(inputs, "seed_image", id)?;
            if img.array.shape() != shape.as_slice() {
                return Err(OpError::invalid(
                    "seed_image",
                    format!(
                        "the seed image has shape {:?} but the grid has shape {:?}",
                        img.array.shape(),
                        shape
                    ),
                ));
            }
            let mut cells: BTreeMap<i32, Vec<Vec<usize>>> = BTreeMap::new();
            for c in 0..img.array.len() {
                let v = img.array.get_f64(c).unwrap_or(0.0);
                if v == 0.0 || v.is_nan() {
                    continue;
                }
                if v.fract() != 0.0 || v < 1.0 || v > f64::from(i32::MAX) {
                    return Err(OpError::invalid(
                        "seed_image",
                        format!("value {v} is not a label (an integer >= 1, or 0 for no seed)"),
                    ));
                }
                let idx = grid.unravel(c);
                cells
                    .entry(v as i32)
                    .or_default()
                    .push(idx[3 - ndim..].to_vec());
            }
            for (label, cells) in cells {
                let e = per_label.entry(label).or_default();
                e.0.push(Source::Cells {
                    cells,
                    values: None,
                });
                e.1.push("seed_image".into());
            }
        }
        if per_label.is_empty() {
            return Err(OpError::invalid("seed_image", "the seed image has no seed"));
        }
        if per_label.len() > MAX_LABELS {
            return Err(OpError::TooLarge {
                field: "seeds".into(),
                reason: format!("{} labels, more than {MAX_LABELS}", per_label.len()),
            });
        }
        let jobs: Vec<(i32, Vec<Source>, Vec<String>, usize)> = per_label
            .into_iter()
            .map(|(l, (s, o))| {
                let n = s.len();
                (l, s, o, n)
            })
            .collect();
        let options = EikonalOptions::DEFAULT
            .with_order(if self.order == 1 {
                Order::First
            } else {
                Order::Second
            })
            .with_stop(StopRules {
                targets: Vec::new(),
                max_distance: self.max_distance,
                max_frozen: None,
            });
        let maps: Vec<Vec<f64>> = match &resolved {
            SegmentMetric::Cost(r) => {
                let cost = r.isotropic()?;
                jobs.par_iter()
                    .map(|(_, sources, origin, _)| {
                        let problem = EikonalProblem {
                            grid: grid.clone(),
                            cost: cost.clone(),
                            sources: sources.clone(),
                        };
                        numerics::solve(&problem, &options, control)
                            .map(|r| r.distance.into_iter().collect())
                            .map_err(|e| rename_source_field(eikonal_error(e), origin))
                    })
                    .collect::<Result<_, _>>()?
            }
            SegmentMetric::Tensor(r) => {
                let spec = TensorSolveSpec {
                    order: self.order,
                    factoring: true,
                    stop: options.stop.clone(),
                    record_order: false,
                };
                jobs.par_iter()
                    .map(|(_, sources, origin, _)| {
                        let problem = TensorProblem {
                            grid: grid.clone(),
                            metric: r.metric.clone(),
                            sources: sources.clone(),
                        };
                        solve_tensor(&problem, &spec, "metric", control)
                            .map(|s| s.out.output.distance.into_iter().collect())
                            .map_err(|e| rename_source_field(e, origin))
                    })
                    .collect::<Result<_, _>>()?
            }
        };
        let label_ids: Vec<i32> = jobs.iter().map(|j| j.0).collect();
        let v = voronoi(&maps, &label_ids);
        drop(maps);
        let mut stats: Vec<serde_json::Value> = Vec::new();
        for (label, _, _, seeds) in &jobs {
            let cells = v.labels.iter().filter(|&&l| l == *label).count();
            stats.push(serde_json::json!({"label": label, "cells": cells, "seeds": seeds}));
        }
        let contours = (self.contours && ndim == 2)
            .then(|| {
                label_contours(
                    &v.labels,
                    [shape[0], shape[1]],
                    [spacing[0], spacing[1]],
                    control,
                )
            })
            .transpose()?;
        let confidence = v.confidence();
        let sp = Some(spacing);
        let mut arrays = vec![OutputArray {
            name: "labels".into(),
            array: ArrayData::I32(shaped(&grid, v.labels.clone())?),
            spacing: sp.clone(),
        }];
        if self.max_distance.is_some() {
            let ball: Vec<u8> = v.labels.iter().map(|&l| u8::from(l >= 0)).collect();
            arrays.push(OutputArray {
                name: "ball".into(),
                array: ArrayData::U8(shaped(&grid, ball)?),
                spacing: sp.clone(),
            });
        }
        arrays.push(OutputArray {
            name: "distance".into(),
            array: ArrayData::F64(shaped(&grid, v.nearest)?),
            spacing: sp.clone(),
        });
        arrays.push(OutputArray {
            name: "second_distance".into(),
            array: ArrayData::F64(shaped(&grid, v.second)?),
            spacing: sp.clone(),
        });
        arrays.push(OutputArray {
            name: "confidence".into(),
            array: ArrayData::F64(shaped(&grid, confidence)?),
            spacing: sp,
        });
        let mut document = serde_json::json!({
            "labels": stats,
            "stats": {"cells": grid.len(), "solves": jobs.len(), "seconds": started.elapsed().as_secs_f64()},
        });
        if let Some(c) = contours {
            document["contours"] = c;
        }
        Ok(OpOutput::new(arrays, document))
    }
}
