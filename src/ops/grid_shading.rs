//! `grid.shape_from_shading`: the height map of a Lambertian surface under a
//! frontal light, recovered from one image by fast marching (see
//! [`crate::numerics::shading`]).

use std::time::Instant;

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::spec::defaults::default_order;
use super::spec::grid::{fetch, grid_of, mask_of, shaped};
use super::{Inputs, OpError, OpLimits, OpOutput, Operation, OutputArray};
use crate::io::ArrayData;
use crate::numerics::shading::{
    border_cells, shape_from_shading, singular_cells, Direction, ShadingError, ShadingOptions,
    ShadingProblem,
};
use crate::numerics::{Control, Order};

/// Request of `grid.shape_from_shading` (`POST /v1/grid/shape-from-shading`).
///
/// The image is the brightness of a Lambertian surface lit from the camera's
/// direction and seen by an orthographic camera; the answer is its height
/// `z` (in the units of `spacing`), the solution of
/// `|∇z| = sqrt(albedo² / I² - 1)` with the heights of the `anchors`
/// prescribed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"image": "ds_0192f1b27c1e7d3a9d553c0f2b8a1e45", "anchors": {"kind": "border", "height": 0.0}}))]
pub struct GridShadingRequest {
    /// Id of a 2D grey image dataset (any numeric type): the brightness `I >= 0`.
    pub image: String,
    /// Physical size of a pixel along each axis (axis 0 first). Default: the
    /// dataset's, else 1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(min_items = 2, max_items = 2)]
    pub spacing: Option<Vec<f64>>,
    /// The brightness of a surface facing the light (`albedo × light`).
    /// Default: the image's largest value. Brighter pixels are read as flat.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(exclusive_minimum = 0.0)]
    pub albedo: Option<f64>,
    /// Where the height is known. Default: the image border at height 0.
    #[serde(default)]
    pub anchors: AnchorSpec,
    /// Whether the height rises (`up`: the anchors are the lowest points) or
    /// falls (`down`: the anchors are the tops) away from the anchors: the
    /// concave/convex ambiguity of shape from shading. Default: `down` for
    /// `singular` anchors, `up` otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub direction: Option<DirectionSpec>,
    /// Order of the fast-marching scheme, 1 or 2. Default: 2.
    #[serde(default = "default_order")]
    pub order: u8,
    /// The smallest slope used (where the image is at the albedo the slope is
    /// 0, which the solver cannot march). Default: 1e-9.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(exclusive_minimum = 0.0)]
    pub min_slope: Option<f64>,
}

/// The cells whose height is prescribed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum AnchorSpec {
    /// The image border, all at one height (an object on a flat ground).
    Border {
        /// The height of the border. Default: 0.
        #[serde(default)]
        height: f64,
    },
    /// The singular points: the pixels whose brightness is within
    /// `tolerance × albedo` of the albedo (the tops of convex objects).
    Singular {
        /// Relative tolerance. Default: 0.001.
        #[serde(default = "default_tolerance")]
        tolerance: f64,
        /// Their height. Default: 0.
        #[serde(default)]
        height: f64,
    },
    /// The non-zero pixels of a mask dataset of the image's shape, all at one height.
    Mask {
        /// Id of the mask dataset.
        dataset: String,
        /// Their height. Default: 0.
        #[serde(default)]
        height: f64,
    },
    /// Pixels (index pairs, axis 0 first) with one height each.
    Cells {
        /// The pixels.
        cells: Vec<Vec<usize>>,
        /// One finite height per pixel.
        heights: Vec<f64>,
    },
}

impl Default for AnchorSpec {
    fn default() -> Self {
        AnchorSpec::Border { height: 0.0 }
    }
}

fn default_tolerance() -> f64 {
    1e-3
}

/// [`Direction`] in a request.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum DirectionSpec {
    /// The height rises away from the anchors.
    Up,
    /// The height falls away from the anchors.
    Down,
}

impl GridShadingRequest {
    fn check(&self, limits: &OpLimits) -> Result<(), OpError> {
        if self.image.is_empty() {
            return Err(OpError::invalid("image", "a dataset id is required"));
        }
        if let Some(s) = &self.spacing {
            if s.len() != 2 {
                return Err(OpError::invalid(
                    "spacing",
                    format!("an image has 2 axes, got {} spacings", s.len()),
                ));
            }
        }
        super::spec::grid::check_spacing(&self.spacing)?;
        if !matches!(self.order, 1 | 2) {
            return Err(OpError::invalid("order", "must be 1 or 2"));
        }
        for (field, v) in [("albedo", self.albedo), ("min_slope", self.min_slope)] {
            if let Some(v) = v {
                if !(v.is_finite() && v > 0.0) {
                    return Err(OpError::invalid(
                        field,
                        format!("{v} must be finite and > 0"),
                    ));
                }
            }
        }
        match &self.anchors {
            AnchorSpec::Border { height }
            | AnchorSpec::Mask { height, .. }
            | AnchorSpec::Singular { height, .. }
                if !height.is_finite() =>
            {
                Err(OpError::invalid(
                    "anchors.height",
                    format!("{height} must be finite"),
                ))
            }
            AnchorSpec::Singular { tolerance, .. } if !(0.0..1.0).contains(tolerance) => {
                Err(OpError::invalid(
                    "anchors.tolerance",
                    format!("{tolerance} must be in [0, 1)"),
                ))
            }
            AnchorSpec::Mask { dataset, .. } if dataset.is_empty() => Err(OpError::invalid(
                "anchors.dataset",
                "a dataset id is required",
            )),
            AnchorSpec::Cells { cells, heights } => {
                if cells.is_empty() {
                    return Err(OpError::invalid("anchors.cells", "give at least one pixel"));
                }
                if cells.len() > limits.max_sources {
                    return Err(OpError::TooLarge {
                        field: "anchors.cells".into(),
                        reason: format!("more than {} pixels", limits.max_sources),
                    });
                }
                if heights.len() != cells.len() {
                    return Err(OpError::invalid(
                        "anchors.heights",
                        format!("{} heights for {} pixels", heights.len(), cells.len()),
                    ));
                }
                if let Some(k) = cells.iter().position(|c| c.len() != 2) {
                    return Err(OpError::invalid(
                        format!("anchors.cells[{k}]"),
                        "a pixel has 2 indices (row, column)",
                    ));
                }
                if let Some(k) = heights.iter().position(|h| !h.is_finite()) {
                    return Err(OpError::invalid(
                        format!("anchors.heights[{k}]"),
                        "must be finite",
                    ));
                }
                Ok(())
            }
            _ => Ok(()),
        }
    }

    /// The anchors as `(linear index, height)` on `grid`.
    fn anchor_cells(
        &self,
        inputs: &dyn Inputs,
        grid: &crate::numerics::Grid,
        image: &[f64],
        albedo: f64,
    ) -> Result<Vec<(usize, f64)>, OpError> {
        let [_, n0, n1] = grid.shape3();
        let anchors: Vec<(usize, f64)> = match &self.anchors {
            AnchorSpec::Border { height } => border_cells(grid)
                .into_iter()
                .map(|i| (i, *height))
                .collect(),
            AnchorSpec::Singular { tolerance, height } => singular_cells(image, albedo, *tolerance)
                .into_iter()
                .map(|i| (i, *height))
                .collect(),
            AnchorSpec::Mask { dataset, height } => {
                let input = fetch(inputs, "anchors.dataset", dataset)?;
                mask_of(&input, "anchors.dataset", grid)?
                    .into_iter()
                    .enumerate()
                    .filter(|(_, m)| *m)
                    .map(|(i, _)| (i, *height))
                    .collect()
            }
            AnchorSpec::Cells { cells, heights } => {
                let mut out = Vec::with_capacity(cells.len());
                for (k, (c, &h)) in cells.iter().zip(heights).enumerate() {
                    if c[0] >= n0 || c[1] >= n1 {
                        return Err(OpError::invalid(
                            format!("anchors.cells[{k}]"),
                            format!("{c:?} is outside the image of shape [{n0}, {n1}]"),
                        ));
                    }
                    out.push((c[0] * n1 + c[1], h));
                }
                out
            }
        };
        if anchors.is_empty() {
            let way_out = match self.anchors {
                AnchorSpec::Singular { .. } => {
                    "no pixel reaches the albedo: raise `anchors.tolerance`, lower `albedo`, or give `border`, `mask` or `cells` anchors"
                }
                _ => "the mask has no non-zero pixel: give another mask or `border` anchors",
            };
            return Err(OpError::invalid("anchors", way_out));
        }
        Ok(anchors)
    }
}

impl Operation for GridShadingRequest {
    const NAME: &'static str = "grid.shape_from_shading";

    fn validate(&self, limits: &OpLimits) -> Result<(), OpError> {
        self.check(limits)
    }

    fn dataset_ids(&self) -> Vec<(String, String)> {
        let mut ids = vec![("image".to_string(), self.image.clone())];
        if let AnchorSpec::Mask { dataset, .. } = &self.anchors {
            ids.push(("anchors.dataset".into(), dataset.clone()));
        }
        ids
    }

    /// Arrays: `height` (f64, `±inf` behind a shadow). Document: `{"stats":
    /// {"cells", "anchors", "flat", "unreached", "albedo", "min_height",
    /// "max_height", "seconds"}}`.
    fn run(
        &self,
        inputs: &dyn Inputs,
        limits: &OpLimits,
        control: &Control<'_>,
    ) -> Result<OpOutput, OpError> {
        self.check(limits)?;
        let input = fetch(inputs, "image", &self.image)?;
        if input.array.shape().len() != 2 {
            return Err(OpError::invalid(
                "image",
                format!(
                    "shape from shading takes a 2D image, the dataset has shape {:?}",
                    input.array.shape()
                ),
            ));
        }
        let grid = grid_of(&input, "image", &self.spacing, limits)?;
        let image: Vec<f64> = (0..input.array.len())
            .map(|i| input.array.get_f64(i).unwrap_or(f64::NAN))
            .collect();
        if let Some(k) = image.iter().position(|v| !(v.is_finite() && *v >= 0.0)) {
            return Err(OpError::invalid(
                "image",
                format!(
                    "pixel {k} (C order) has brightness {}: a brightness must be finite and >= 0",
                    image[k]
                ),
            ));
        }
        let albedo = match self.albedo {
            Some(a) => a,
            None => image.iter().copied().fold(0.0f64, f64::max),
        };
        if albedo <= 0.0 {
            return Err(OpError::invalid(
                "image",
                "the image is black: nothing is lit (give a lit image or an `albedo`)",
            ));
        }
        let anchors = self.anchor_cells(inputs, &grid, &image, albedo)?;
        let direction = match (self.direction, &self.anchors) {
            (Some(DirectionSpec::Up), _) => Direction::Up,
            (Some(DirectionSpec::Down), _) | (None, AnchorSpec::Singular { .. }) => Direction::Down,
            (None, _) => Direction::Up,
        };
        let problem = ShadingProblem {
            grid: grid.clone(),
            image: &image,
            albedo,
            anchors,
            direction,
            min_slope: self.min_slope.unwrap_or(1e-9),
        };
        let order = if self.order == 1 {
            Order::First
        } else {
            Order::Second
        };
        let started = Instant::now();
        let out = shape_from_shading(&problem, ShadingOptions { order }, control)
            .map_err(shading_error)?;
        let seconds = started.elapsed().as_secs_f64();
        let (lo, hi) = out
            .height
            .iter()
            .filter(|v| v.is_finite())
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
                (lo.min(v), hi.max(v))
            });
        Ok(OpOutput::new(
            vec![OutputArray {
                name: "height".into(),
                array: ArrayData::F64(shaped(&grid, out.height)?),
                spacing: Some(grid.spacing().to_vec()),
            }],
            serde_json::json!({"stats": {
                "cells": grid.len(),
                "anchors": problem.anchors.len(),
                "flat": out.flat,
                "unreached": out.unreached,
                "albedo": albedo,
                "min_height": if lo.is_finite() { Some(lo) } else { None },
                "max_height": if hi.is_finite() { Some(hi) } else { None },
                "seconds": seconds,
            }}),
        ))
    }
}

/// A core error as an [`OpError`] naming the request field.
fn shading_error(e: ShadingError) -> OpError {
    match e {
        ShadingError::Cancelled => OpError::Cancelled,
        ShadingError::Anchor { .. } | ShadingError::NoAnchors => {
            OpError::invalid("anchors", e.to_string())
        }
        ShadingError::Albedo(_) => OpError::invalid("albedo", e.to_string()),
        ShadingError::MinSlope(_) => OpError::invalid("min_slope", e.to_string()),
        ShadingError::NotTwoD(_)
        | ShadingError::Length { .. }
        | ShadingError::Brightness { .. } => OpError::invalid("image", e.to_string()),
    }
}
