//! `grid.skeleton`: the medial axis of a binary shape (2D and 3D) with
//! pruning, its radius function, and in 2D the skeleton graph (see
//! [`crate::numerics::skeleton`]). In 2D the skeleton is one cell thin; in
//! 3D it is a curve skeleton (medial sheets thinned to curves, topology
//! kept).

use std::time::Instant;

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::spec::grid::{check_non_negative, check_spacing, fetch, grid_of, mask_of, shaped};
use super::{Inputs, OpError, OpLimits, OpOutput, Operation, OutputArray};
use crate::io::ArrayData;
use crate::numerics::skeleton::{self, SkeletonError, SkeletonOptions};
use crate::numerics::Control;

/// Request of `grid.skeleton` (`POST /v1/grid/skeleton`, `geodex skeleton`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"mask": "ds_0192f1b27c1e7d3a9d553c0f2b8a1e45", "min_boundary_fraction": 0.08}))]
pub struct GridSkeletonRequest {
    /// Id of a 2D or 3D mask dataset: the shape is its non-zero cells.
    pub mask: String,
    /// Physical size of a cell along each axis. Default: the dataset's, else 1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(min_items = 2, max_items = 3)]
    pub spacing: Option<Vec<f64>>,
    /// A skeleton branch is kept where its two nearest boundary points are at
    /// least this far apart along the boundary (2D; the chord in 3D), in
    /// physical units. Default: 0.
    #[serde(default)]
    #[schema(minimum = 0.0)]
    pub min_boundary_length: f64,
    /// The same, as a fraction of the length of the boundary curve (2D) or of
    /// the largest inscribed diameter (3D). The larger of the two applies (and
    /// at least 3 cells). Default: 0.08. Set both to 0 to turn pruning off.
    #[serde(default = "default_fraction")]
    #[schema(minimum = 0.0)]
    pub min_boundary_fraction: f64,
}

fn default_fraction() -> f64 {
    SkeletonOptions::default().min_boundary_fraction
}

impl GridSkeletonRequest {
    fn check(&self) -> Result<(), OpError> {
        check_spacing(&self.spacing)?;
        check_non_negative(self.min_boundary_length, "min_boundary_length")?;
        check_non_negative(self.min_boundary_fraction, "min_boundary_fraction")
    }
}

impl Operation for GridSkeletonRequest {
    const NAME: &'static str = "grid.skeleton";

    fn validate(&self, _limits: &OpLimits) -> Result<(), OpError> {
        self.check()
    }

    fn dataset_ids(&self) -> Vec<(String, String)> {
        vec![("mask".into(), self.mask.clone())]
    }

    /// Arrays: `skeleton` (u8 mask), `radius` (f64, the distance to the
    /// nearest outside cell on the skeleton, 0 elsewhere). Document:
    /// `{"graph": {"nodes", "edges"}` (2D), `"stats": {...}}`.
    fn run(
        &self,
        inputs: &dyn Inputs,
        limits: &OpLimits,
        control: &Control<'_>,
    ) -> Result<OpOutput, OpError> {
        self.check()?;
        let input = fetch(inputs, "mask", &self.mask)?;
        let grid = grid_of(&input, "mask", &self.spacing, limits)?;
        let mask = mask_of(&input, "mask", &grid)?;
        let started = Instant::now();
        let options = SkeletonOptions {
            min_boundary_length: self.min_boundary_length,
            min_boundary_fraction: self.min_boundary_fraction,
        };
        let sk = skeleton::medial_axis(&grid, &mask, &options, control).map_err(|e| match e {
            SkeletonError::Edt(crate::numerics::edt::EdtError::Cancelled) => OpError::Cancelled,
            SkeletonError::Option { field, reason } => OpError::invalid(field, reason),
            other => OpError::invalid("mask", other.to_string()),
        })?;
        let cells = sk.mask.iter().filter(|&&m| m).count();
        let spacing = Some(grid.spacing().to_vec());
        let mut document = serde_json::json!({"stats": {
            "cells": grid.len(),
            "shape_cells": mask.iter().filter(|&&m| m).count(),
            "skeleton_cells": cells,
            "seconds": started.elapsed().as_secs_f64(),
        }});
        if let Some(g) = &sk.graph {
            document["stats"]["nodes"] = g.nodes.len().into();
            document["stats"]["branches"] = g.edges.len().into();
            document["graph"] =
                serde_json::to_value(g).map_err(|e| OpError::invalid("mask", e.to_string()))?;
        }
        let sk_u8: Vec<u8> = sk.mask.iter().map(|&m| u8::from(m)).collect();
        Ok(OpOutput::new(
            vec![
                OutputArray {
                    name: "skeleton".into(),
                    array: ArrayData::U8(shaped(&grid, sk_u8)?),
                    spacing: spacing.clone(),
                },
                OutputArray {
                    name: "radius".into(),
                    array: ArrayData::F64(shaped(&grid, sk.radius)?),
                    spacing,
                },
            ],
            document,
        ))
    }
}
