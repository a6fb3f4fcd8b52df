//! `grid.shape_from_shading`: the height map of a Lambertian surface
//! recovered from one image (see [`crate::numerics::shading`]): under a
//! frontal light and an orthographic camera by fast marching, under an
//! oblique light or with a perspective camera (light at the optical centre,
//! `1/r²` falloff) by Lax–Friedrichs fast sweeping; the surface also as a
//! mesh.

use std::sync::Arc;
use std::time::Instant;

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::spec::defaults::default_order;
use super::spec::grid::{fetch, grid_of, mask_of, shaped};
use super::spec::mesh::MeshInput;
use super::{Inputs, OpError, OpLimits, OpOutput, Operation, OutputArray, OutputMesh};
use crate::io::mesh::report_of;
use crate::io::ArrayData;
use crate::numerics::mesh::{Topology, TriMesh};
use crate::numerics::shading::{
    border_cells, shape_from_shading, shape_from_shading_general, singular_cells, surface_mesh,
    Camera, Direction, GeneralShadingProblem, ShadingError, ShadingOptions, ShadingProblem,
    SweepOptions, SweepStop,
};
use crate::numerics::{Control, Order};

/// Request of `grid.shape_from_shading` (`POST /v1/grid/shape-from-shading`).
///
/// The image is the brightness of a Lambertian surface. By default it is
/// lit from the camera's direction and seen by an orthographic camera; the
/// answer is its height `z` (in the units of `spacing`), the solution of
/// `|∇z| = sqrt(albedo² / I² - 1)` with the heights of the `anchors`
/// prescribed (fast marching). With an oblique `light` the image equation
/// `I = albedo (l3 - l·∇z) / sqrt(1 + |∇z|²)` is solved for `w = L·P` by
/// Lax–Friedrichs fast sweeping; with a `perspective` camera (light at the
/// optical centre, `I = albedo cos α / r²`) the answer is the `depth`, with
/// no anchors needed (Prados and Faugeras 2005).
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
    /// Where the height is known. Default: the image border at height 0
    /// (orthographic), none (perspective: the heights are then depths `> 0`;
    /// without attenuation anchors are needed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub anchors: Option<AnchorSpec>,
    /// Whether the height rises (`up`: the anchors are the lowest points) or
    /// falls (`down`: the anchors are the tops) away from the anchors: the
    /// concave/convex ambiguity of shape from shading. Default: `down` for
    /// `singular` anchors, `up` otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub direction: Option<DirectionSpec>,
    /// Order of the fast-marching scheme, 1 or 2 (frontal light and
    /// orthographic camera; the sweeping solver is first order). Default: 2.
    #[serde(default = "default_order")]
    pub order: u8,
    /// Direction towards the light `[l1, l2, l3]` (`l1` along axis 0, `l2`
    /// along axis 1, `l3 > 0` towards the camera), normalised. Default:
    /// `[0, 0, 1]`, frontal. Orthographic camera only.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(min_items = 3, max_items = 3)]
    pub light: Option<Vec<f64>>,
    /// The camera. Default: orthographic.
    #[serde(default)]
    pub camera: CameraSpec,
    /// Sweeping solver (oblique light, perspective camera): stop when an
    /// iteration changes no pixel by more than this (in `w`, length units,
    /// or in `ln depth`). Default: 1e-7.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(exclusive_minimum = 0.0)]
    pub tolerance: Option<f64>,
    /// Sweeping solver: the most iterations (four sweeps each). Default: 5000.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(minimum = 1)]
    pub max_iterations: Option<usize>,
    /// Also return the surface as a mesh dataset (`mesh`): a vertex per
    /// reached pixel, two triangles per pixel quad whose corners are all
    /// reached. Default: true.
    #[serde(default = "default_true")]
    pub mesh: bool,
    /// The smallest slope used (where the image is at the albedo the slope is
    /// 0, which the solver cannot march). Default: 1e-9.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(exclusive_minimum = 0.0)]
    pub min_slope: Option<f64>,
}

fn default_true() -> bool {
    true
}

/// The camera of `grid.shape_from_shading`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize, ToSchema)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum CameraSpec {
    /// Parallel projection: pixel `(a, b)` sees `(a h0, b h1, z)`.
    #[default]
    Orthographic,
    /// A pinhole camera with the light at its optical centre. Works in
    /// pixels (`spacing` must be left out); the answer is the depth `Z`,
    /// the surface point of pixel `x` being `Z ((x - c) / focal, 1)`.
    Perspective {
        /// Focal length in pixels, `> 0`.
        focal: f64,
        /// Principal point `[row, column]` in pixels. Default: the image centre.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        #[schema(min_items = 2, max_items = 2)]
        principal_point: Option<Vec<f64>>,
        /// Whether the light falls off as `1/r²` (then the depth is fixed
        /// by the image alone, its unit by `albedo`). Default: true.
        #[serde(default = "default_true")]
        attenuation: bool,
    },
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
        if let Some(t) = self.tolerance {
            if !(t.is_finite() && t > 0.0) {
                return Err(OpError::invalid(
                    "tolerance",
                    format!("{t} must be finite and > 0"),
                ));
            }
        }
        if self.max_iterations == Some(0) {
            return Err(OpError::invalid("max_iterations", "must be >= 1"));
        }
        if let Some(l) = &self.light {
            let norm = l.iter().map(|v| v * v).sum::<f64>().sqrt();
            if l.len() != 3 || !norm.is_finite() || l[2] <= 0.0 {
                return Err(OpError::invalid(
                    "light",
                    format!(
                        "{l:?}: give 3 finite numbers [l1, l2, l3] with l3 > 0 (the light must be in front of the surface)"
                    ),
                ));
            }
        }
        if let CameraSpec::Perspective {
            focal,
            principal_point,
            ..
        } = &self.camera
        {
            if !(focal.is_finite() && *focal > 0.0) {
                return Err(OpError::invalid(
                    "camera.focal",
                    format!("{focal} must be finite and > 0 (pixels)"),
                ));
            }
            if let Some(c) = principal_point {
                if c.len() != 2 || c.iter().any(|v| !v.is_finite()) {
                    return Err(OpError::invalid(
                        "camera.principal_point",
                        format!("{c:?}: give 2 finite numbers [row, column] in pixels"),
                    ));
                }
            }
            if self
                .light
                .as_ref()
                .is_some_and(|l| l[0] != 0.0 || l[1] != 0.0)
            {
                return Err(OpError::invalid(
                    "light",
                    "the perspective camera's light is at its optical centre: leave `light` out",
                ));
            }
            if self.spacing.is_some() {
                return Err(OpError::invalid(
                    "spacing",
                    "the perspective camera works in pixels (focal in pixels): leave `spacing` out",
                ));
            }
            if let Some(
                AnchorSpec::Border { height }
                | AnchorSpec::Mask { height, .. }
                | AnchorSpec::Singular { height, .. },
            ) = &self.anchors
            {
                if *height <= 0.0 {
                    return Err(OpError::invalid(
                        "anchors.height",
                        format!("{height}: with the perspective camera anchors are depths, > 0"),
                    ));
                }
            }
        }
        match self.anchors.as_ref().unwrap_or(&AnchorSpec::default()) {
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
        let spec = match &self.anchors {
            Some(spec) => spec,
            None if matches!(self.camera, CameraSpec::Perspective { .. }) => return Ok(Vec::new()),
            None => &AnchorSpec::default(),
        };
        let anchors: Vec<(usize, f64)> = match spec {
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
            let way_out = match spec {
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
        if let Some(AnchorSpec::Mask { dataset, .. }) = &self.anchors {
            ids.push(("anchors.dataset".into(), dataset.clone()));
        }
        ids
    }

    /// Arrays: `height` (f64, `±inf` behind a shadow; `depth` with the
    /// perspective camera). Mesh: `mesh` (unless `mesh: false`). Document:
    /// `{"stats": {"cells", "anchors", "flat", "unreached", "albedo",
    /// "min_height", "max_height", "seconds"}}`, and with the sweeping
    /// solver `model`, `light`, `iterations`, `change`, `stop`.
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
            (Some(DirectionSpec::Down), _) | (None, Some(AnchorSpec::Singular { .. })) => {
                Direction::Down
            }
            (None, _) => Direction::Up,
        };
        let light = match &self.light {
            Some(l) => {
                let norm = l.iter().map(|v| v * v).sum::<f64>().sqrt();
                [l[0] / norm, l[1] / norm, l[2] / norm]
            }
            None => [0.0, 0.0, 1.0],
        };
        let [_, n0, n1] = grid.shape3();
        let camera = match &self.camera {
            CameraSpec::Orthographic => Camera::Orthographic,
            CameraSpec::Perspective {
                focal,
                principal_point,
                attenuation,
            } => Camera::Perspective {
                focal: *focal,
                principal_point: match principal_point {
                    Some(c) => [c[0], c[1]],
                    None => [(n0 as f64 - 1.0) / 2.0, (n1 as f64 - 1.0) / 2.0],
                },
                attenuation: *attenuation,
            },
        };
        if camera != Camera::Orthographic || light != [0.0, 0.0, 1.0] {
            return self.run_sweeping(
                GeneralShadingProblem {
                    grid,
                    image: &image,
                    albedo,
                    anchors,
                    direction,
                    light,
                    camera,
                },
                control,
            );
        }
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
        let (lo, hi) = finite_range(&out.height);
        let mesh = self.mesh_of(&grid, &out.height, &Camera::Orthographic)?;
        let mut output = OpOutput::new(
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
                "min_height": lo,
                "max_height": hi,
                "seconds": seconds,
            }}),
        );
        output.mesh = mesh;
        Ok(output)
    }
}

/// The smallest and largest finite values, if any.
fn finite_range(v: &[f64]) -> (Option<f64>, Option<f64>) {
    let (lo, hi) = v
        .iter()
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        });
    if lo.is_finite() {
        (Some(lo), Some(hi))
    } else {
        (None, None)
    }
}

impl GridShadingRequest {
    /// Oblique light or perspective camera: the sweeping solver. Arrays:
    /// `height` (orthographic) or `depth` (perspective); stats as the
    /// frontal case's plus `model`, `iterations`, `change`, `stop`
    /// (`converged` or `iteration_cap`).
    fn run_sweeping(
        &self,
        problem: GeneralShadingProblem<'_>,
        control: &Control<'_>,
    ) -> Result<OpOutput, OpError> {
        let defaults = SweepOptions::default();
        let options = SweepOptions {
            tolerance: self.tolerance.unwrap_or(defaults.tolerance),
            max_iterations: self.max_iterations.unwrap_or(defaults.max_iterations),
        };
        let started = Instant::now();
        let out = shape_from_shading_general(&problem, options, control).map_err(shading_error)?;
        let seconds = started.elapsed().as_secs_f64();
        let grid = &problem.grid;
        let (lo, hi) = finite_range(&out.height);
        let mesh = self.mesh_of(grid, &out.height, &problem.camera)?;
        let (name, model) = match problem.camera {
            Camera::Orthographic => ("height", "orthographic_oblique"),
            Camera::Perspective { .. } => ("depth", "perspective"),
        };
        let mut output = OpOutput::new(
            vec![OutputArray {
                name: name.into(),
                array: ArrayData::F64(shaped(grid, out.height)?),
                spacing: Some(grid.spacing().to_vec()),
            }],
            serde_json::json!({"stats": {
                "model": model,
                "light": problem.light,
                "cells": grid.len(),
                "anchors": problem.anchors.len(),
                "unreached": out.unreached,
                "albedo": problem.albedo,
                format!("min_{name}"): lo,
                format!("max_{name}"): hi,
                "iterations": out.iterations,
                "change": out.change,
                "stop": match out.stop {
                    SweepStop::Converged => "converged",
                    SweepStop::IterationCap => "iteration_cap",
                },
                "seconds": seconds,
            }}),
        );
        output.mesh = mesh;
        Ok(output)
    }

    /// The surface mesh, if asked for and not empty.
    fn mesh_of(
        &self,
        grid: &crate::numerics::Grid,
        height: &[f64],
        camera: &Camera,
    ) -> Result<Option<OutputMesh>, OpError> {
        if !self.mesh {
            return Ok(None);
        }
        let (points, triangles) = surface_mesh(grid, height, camera);
        if triangles.is_empty() {
            return Ok(None);
        }
        let tri = TriMesh::new(points, triangles)
            .map_err(|e| OpError::invalid("mesh", format!("{e}: ask for `mesh: false`")))?;
        let topology = Topology::new(&tri);
        let report = report_of(&tri, &topology);
        Ok(Some(OutputMesh {
            name: "mesh".into(),
            mesh: Arc::new(MeshInput {
                mesh: tri,
                topology,
                report,
            }),
            vertex_properties: vec![],
        }))
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
        ShadingError::Light(_) => OpError::invalid("light", e.to_string()),
        ShadingError::Camera(_) => OpError::invalid("camera", e.to_string()),
        ShadingError::Option(_) => OpError::invalid("tolerance", e.to_string()),
        ShadingError::NotTwoD(_)
        | ShadingError::Length { .. }
        | ShadingError::Brightness { .. } => OpError::invalid("image", e.to_string()),
    }
}
