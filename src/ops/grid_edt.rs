//! `grid.edt`: the exact Euclidean distance transform of a mask (binary or
//! signed) or of a label image (multi-label), with its feature transform.

use std::time::Instant;

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::spec::grid::{check_spacing, fetch, grid_of, mask_of, shaped};
use super::{Inputs, OpError, OpLimits, OpOutput, Operation, OutputArray};
use crate::io::ArrayData;
use crate::numerics::edt::{self, EdtOptions, EdtOutput, NO_FEATURE};
use crate::numerics::Control;
use crate::ops::spec::errors::edt_error;

/// Request of `grid.edt` (`POST /v1/grid/edt`, `geodex edt`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"mask": "ds_0192f1b27c1e7d3a9d553c0f2b8a1e45", "mode": "signed", "features": true}))]
pub struct GridEdtRequest {
    /// Id of a 2D or 3D dataset: the mask (non-zero cells are the features),
    /// or with `mode: multilabel` the label image.
    pub mask: String,
    /// Physical size of a cell along each axis (axis 0 first). Default: the
    /// dataset's spacing (NIfTI voxel size), else 1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(min_items = 2, max_items = 3)]
    pub spacing: Option<Vec<f64>>,
    /// Which transform. Default: `binary`.
    #[serde(default)]
    pub mode: EdtMode,
    /// Also return the feature transform: the C-order linear index of the
    /// nearest feature cell (`numpy.unravel_index` gives its coordinates),
    /// -1 where there is none. Default: false.
    #[serde(default)]
    pub features: bool,
}

/// The transform.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum EdtMode {
    /// Distance of every cell to the nearest non-zero cell (0 on them; +inf if there is none).
    #[default]
    Binary,
    /// Outside the mask the distance to it, inside minus the distance to the outside.
    Signed,
    /// Distance of every cell to the nearest cell with another value.
    Multilabel,
}

impl GridEdtRequest {
    fn check(&self) -> Result<(), OpError> {
        if self.mask.is_empty() {
            return Err(OpError::invalid("mask", "a dataset id is required"));
        }
        check_spacing(&self.spacing)
    }
}

impl Operation for GridEdtRequest {
    const NAME: &'static str = "grid.edt";

    fn validate(&self, _limits: &OpLimits) -> Result<(), OpError> {
        self.check()
    }

    fn dataset_ids(&self) -> Vec<(String, String)> {
        vec![("mask".into(), self.mask.clone())]
    }

    /// Arrays: `distance` (f64), `features` (i64, when asked for).
    /// Document: `{"stats": {"cells", "features", "max_distance", "seconds"}}`.
    fn run(
        &self,
        inputs: &dyn Inputs,
        limits: &OpLimits,
        control: &Control<'_>,
    ) -> Result<OpOutput, OpError> {
        self.check()?;
        let input = fetch(inputs, "mask", &self.mask)?;
        let grid = grid_of(&input, "mask", &self.spacing, limits)?;
        let options = EdtOptions::default().with_features(self.features);
        let started = Instant::now();
        let (out, feature_cells): (EdtOutput, usize) = match self.mode {
            EdtMode::Binary | EdtMode::Signed => {
                let mask = match direct_mask(&input.array, &grid) {
                    Some(m) => m,
                    None => mask_of(&input, "mask", &grid)?,
                };
                let count = mask.iter().filter(|&&m| m).count();
                let out = if self.mode == EdtMode::Binary {
                    edt::edt(&grid, &mask, &options, control)
                } else {
                    edt::signed_edt(&grid, &mask, &options, control)
                };
                (out.map_err(|e| edt_error(e, "mask"))?, count)
            }
            EdtMode::Multilabel => {
                let out = match narrow_labels(&input.array, &grid) {
                    Some(labels) => edt::multilabel_edt(&grid, &labels, &options, control),
                    None => {
                        let a = &input.array;
                        let mut labels = Vec::with_capacity(a.len());
                        for i in 0..a.len() {
                            let v = a.get_f64(i).unwrap_or(f64::NAN);
                            if v.is_nan() {
                                return Err(OpError::invalid(
                                    "mask",
                                    "a label image cannot hold NaN",
                                ));
                            }
                            labels.push((v + 0.0).to_bits());
                        }
                        edt::multilabel_edt(&grid, &labels, &options, control)
                    }
                }
                .map_err(|e| edt_error(e, "mask"))?;
                (out, grid.len())
            }
        };
        let seconds = started.elapsed().as_secs_f64();
        let max_distance = out
            .distance
            .iter()
            .copied()
            .filter(|d| d.is_finite())
            .fold(0.0f64, |a, d| a.max(d.abs()));
        let spacing = Some(grid.spacing().to_vec());
        let mut arrays = vec![OutputArray {
            name: "distance".into(),
            array: ArrayData::F64(shaped(&grid, out.distance)?),
            spacing: spacing.clone(),
        }];
        if let Some(f) = out.features {
            let f: Vec<i64> = f
                .into_iter()
                .map(|v| if v == NO_FEATURE { -1 } else { i64::from(v) })
                .collect();
            arrays.push(OutputArray {
                name: "features".into(),
                array: ArrayData::I64(shaped(&grid, f)?),
                spacing,
            });
        }
        Ok(OpOutput::new(
            arrays,
            serde_json::json!({"stats": {
                "cells": grid.len(),
                "features": feature_cells,
                "max_distance": max_distance,
                "seconds": seconds,
            }}),
        ))
    }
}

/// The mask of a boolean or integer dataset of the grid's shape in standard
/// layout (non-zero is true), read straight from its slice; `None` sends the
/// caller to the general checks of [`mask_of`].
fn direct_mask(a: &ArrayData, grid: &crate::numerics::Grid) -> Option<Vec<bool>> {
    if a.shape() != grid.shape() {
        return None;
    }
    match a {
        ArrayData::Bool(a) => Some(a.as_slice()?.to_vec()),
        ArrayData::U8(a) => Some(a.as_slice()?.iter().map(|&v| v != 0).collect()),
        ArrayData::U16(a) => Some(a.as_slice()?.iter().map(|&v| v != 0).collect()),
        ArrayData::I32(a) => Some(a.as_slice()?.iter().map(|&v| v != 0).collect()),
        ArrayData::I64(a) => Some(a.as_slice()?.iter().map(|&v| v != 0).collect()),
        _ => None,
    }
}

/// Integer labels of the grid's shape as `u32` (a bijection of every value
/// that fits), read straight from the dataset's slice; `None` for floating
/// point labels, 64-bit labels outside the `u32` range or a non-standard
/// layout (the caller then keys labels by their `f64` bits).
fn narrow_labels(a: &ArrayData, grid: &crate::numerics::Grid) -> Option<Vec<u32>> {
    if a.shape() != grid.shape() {
        return None;
    }
    match a {
        ArrayData::Bool(a) => Some(a.as_slice()?.iter().map(|&v| u32::from(v)).collect()),
        ArrayData::U8(a) => Some(a.as_slice()?.iter().map(|&v| u32::from(v)).collect()),
        ArrayData::U16(a) => Some(a.as_slice()?.iter().map(|&v| u32::from(v)).collect()),
        ArrayData::I32(a) => Some(a.as_slice()?.iter().map(|&v| v as u32).collect()),
        ArrayData::I64(a) => a
            .as_slice()?
            .iter()
            .map(|&v| u32::try_from(v).ok())
            .collect(),
        _ => None,
    }
}
