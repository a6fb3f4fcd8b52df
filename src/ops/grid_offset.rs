//! `grid.offset`: dilation or erosion of a shape by a Euclidean or geodesic
//! distance `r`, optionally around obstacles (seed §3.5).
//!
//! * `euclidean` without obstacles: the exact EDT (distance between cell centres).
//! * `euclidean` with obstacles: the shortest-path length in the free space
//!   (fast marching with a unit cost, second order, the obstacles as walls).
//! * `geodesic`: fast marching on the given `cost` (default: a unit cost).
//!
//! Dilation keeps `{x : d(x, A) <= r}`; erosion keeps `{x ∈ A : d(x, A^c) > r}`.

use std::time::Instant;

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::spec::cost::{CostSpec, InterpretationSpec};
use super::spec::scheme::SourceSpec;

use super::spec::distance::{self, cost_shape, distance_request};
use super::spec::errors::edt_error;
use super::spec::grid::preload;
use super::spec::grid::{check_non_negative, check_spacing, fetch, grid_of, mask_of, shaped};
use super::{Inputs, OpError, OpLimits, OpOutput, Operation, OutputArray};
use crate::io::ArrayData;
use crate::numerics::segmentation::offset_euclidean;
use crate::numerics::Control;

/// Request of `grid.offset` (`POST /v1/grid/offset`, `geodex offset`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"mask": "ds_0192f1b27c1e7d3a9d553c0f2b8a1e45", "radius": 5.0, "operation": "dilate"}))]
pub struct GridOffsetRequest {
    /// Id of a 2D or 3D mask dataset: the shape is its non-zero cells.
    pub mask: String,
    /// The offset distance `r`, physical units.
    #[schema(minimum = 0.0)]
    pub radius: f64,
    /// Grow or shrink. Default: `dilate`.
    #[serde(default)]
    pub operation: OffsetOperation,
    /// How distance is measured. Default: `euclidean`.
    #[serde(default)]
    pub metric: OffsetMetric,
    /// The metric of `geodesic` (as in `grid.distance`). Default: a unit cost on the mask's grid.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cost: Option<CostSpec>,
    /// Id of a mask dataset whose non-zero cells block the propagation.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub obstacles: Option<String>,
    /// Physical size of a cell along each axis. Default: the mask's, else 1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(min_items = 2, max_items = 3)]
    pub spacing: Option<Vec<f64>>,
}

/// Grow or shrink.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum OffsetOperation {
    /// Every cell within `r` of the shape.
    #[default]
    Dilate,
    /// The cells of the shape farther than `r` from its outside.
    Erode,
}

/// How distance is measured.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum OffsetMetric {
    /// Straight-line distance (exact EDT; shortest path in the free space with obstacles).
    #[default]
    Euclidean,
    /// Geodesic distance of `cost`.
    Geodesic,
}

impl GridOffsetRequest {
    fn check(&self) -> Result<(), OpError> {
        check_spacing(&self.spacing)?;
        check_non_negative(self.radius, "radius")?;
        if self.cost.is_some() && self.metric == OffsetMetric::Euclidean {
            return Err(OpError::invalid(
                "cost",
                "a cost goes with `metric: geodesic`",
            ));
        }
        Ok(())
    }
}

impl Operation for GridOffsetRequest {
    const NAME: &'static str = "grid.offset";

    fn validate(&self, _limits: &OpLimits) -> Result<(), OpError> {
        self.check()
    }

    fn dataset_ids(&self) -> Vec<(String, String)> {
        let mut ids = vec![("mask".to_string(), self.mask.clone())];
        if let Some(id) = self.cost.as_ref().and_then(|c| c.dataset.clone()) {
            ids.push(("cost.dataset".into(), id));
        }
        if let Some(id) = &self.obstacles {
            ids.push(("obstacles".into(), id.clone()));
        }
        ids
    }

    /// Arrays: `offset` (u8 mask), `distance` (f64: to the shape for a
    /// dilation, to its outside for an erosion). Document: `{"stats": {...}}`.
    fn run(
        &self,
        inputs: &dyn Inputs,
        limits: &OpLimits,
        control: &Control<'_>,
    ) -> Result<OpOutput, OpError> {
        self.check()?;
        let started = Instant::now();
        let input = fetch(inputs, "mask", &self.mask)?;
        let grid = grid_of(&input, "mask", &self.spacing, limits)?;
        let mask = mask_of(&input, "mask", &grid)?;
        let dilate = self.operation == OffsetOperation::Dilate;
        let (offset, distance) =
            if self.metric == OffsetMetric::Euclidean && self.obstacles.is_none() {
                offset_euclidean(&grid, &mask, self.radius, dilate, control)
                    .map_err(|e| edt_error(e, "mask"))?
            } else {
                let cost = match &self.cost {
                    Some(c) => {
                        let shape = cost_shape(c, inputs, "cost")?;
                        if shape != grid.shape() {
                            return Err(OpError::invalid(
                                "cost",
                                format!(
                                    "the cost has shape {shape:?} but the mask has shape {:?}",
                                    grid.shape()
                                ),
                            ));
                        }
                        c.clone()
                    }
                    None => CostSpec {
                        dataset: None,
                        constant: Some(1.0),
                        shape: Some(grid.shape().to_vec()),
                        interpretation: InterpretationSpec::Cost,
                        design: None,
                    },
                };
                let off = 3 - grid.ndim();
                let blocked = match &self.obstacles {
                    Some(id) => mask_of(&fetch(inputs, "obstacles", id)?, "obstacles", &grid)?,
                    None => vec![false; grid.len()],
                };
                let mut cells: Vec<Vec<usize>> = Vec::new();
                for c in 0..grid.len() {
                    if c % (1 << 16) == 0 && control.is_cancelled() {
                        return Err(OpError::Cancelled);
                    }
                    if mask[c] == dilate && !blocked[c] {
                        cells.push(grid.unravel(c)[off..].to_vec());
                    }
                }
                if cells.is_empty() {
                    // Nothing to grow from: the dilation is empty, the erosion keeps the shape.
                    let d = vec![f64::INFINITY; grid.len()];
                    let out = if dilate {
                        vec![false; grid.len()]
                    } else {
                        mask.clone()
                    };
                    (out, d)
                } else {
                    let req = distance_request(
                        &cost,
                        &Some(grid.spacing().to_vec()),
                        &self.obstacles,
                        vec![SourceSpec::at_cells(cells)],
                        2,
                        Some(self.radius * (1.0 + 1e-9) + 1e-12),
                    );
                    let shared = preload(inputs, &self.dataset_ids())?;
                    let u: Vec<f64> = distance::execute(&req, &shared, limits, control)
                        .map_err(|e| match e {
                            OpError::Invalid { field, reason } if field.starts_with("sources") => {
                                OpError::invalid("mask", reason)
                            }
                            other => other,
                        })?
                        .distance
                        .into_iter()
                        .collect();
                    let r = self.radius * (1.0 + 1e-12);
                    let out = (0..grid.len())
                        .map(|c| {
                            if dilate {
                                u[c] <= r
                            } else {
                                // `u` is never NaN (unreached: +inf), so this is `!(u <= r)`.
                                mask[c] && u[c] > r
                            }
                        })
                        .collect();
                    (out, u)
                }
            };
        let cell_volume: f64 = grid.spacing().iter().product();
        let before = mask.iter().filter(|&&m| m).count();
        let after = offset.iter().filter(|&&m| m).count();
        let spacing = Some(grid.spacing().to_vec());
        let offset_u8: Vec<u8> = offset.iter().map(|&m| u8::from(m)).collect();
        Ok(OpOutput::new(
            vec![
                OutputArray {
                    name: "offset".into(),
                    array: ArrayData::U8(shaped(&grid, offset_u8)?),
                    spacing: spacing.clone(),
                },
                OutputArray {
                    name: "distance".into(),
                    array: ArrayData::F64(shaped(&grid, distance)?),
                    spacing,
                },
            ],
            serde_json::json!({"stats": {
                "cells_before": before,
                "cells_after": after,
                "area_before": before as f64 * cell_volume,
                "area_after": after as f64 * cell_volume,
                "seconds": started.elapsed().as_secs_f64(),
            }}),
        ))
    }
}
