//! `grid.tensor_distance`: the Riemannian distance map `U` (and Voronoi
//! labels, and minimal paths) of a tensor metric on a 2D or 3D grid.
//!
//! The same solve as `grid.distance` with a `metric` (both go through
//! [`super::spec::tensor::resolve_tensor`] and [`super::spec::tensor::solve_tensor`]),
//! kept as its own endpoint with the stencil statistics and source-to-end
//! paths; the paths are the shared descent of [`crate::numerics::paths`]
//! with the Riemannian direction ([`crate::numerics::anisotropic::descent`]).
//!
//! Coordinates are in array index order (axis 0 first) and in index units;
//! physical lengths are index offsets times the per-axis `spacing`.

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::spec::scheme::{
    resolve_sources, source_dataset_ids, stop_name, OutputSpec, SourceSpec, StopSpec,
};
use super::spec::tensor::{resolve_tensor, solve_tensor, TensorSolveSpec, TensorSpec};
use super::{Inputs, OpError, OpLimits, OpOutput, Operation, OutputArray};
use crate::io::ArrayData;
use crate::numerics::anisotropic::descent::minimal_path;
use crate::numerics::paths::DescentOptions;
use crate::numerics::{Control, IsotropicCost, Source};
use crate::ops::spec::cost::CostSpec;
use crate::ops::spec::defaults::default_order;
use crate::ops::spec::defaults::default_step;
use crate::ops::spec::defaults::default_true;
use crate::ops::spec::distance::GridDistanceRequest;

/// Request of `grid.tensor_distance` (`POST /v1/grid/tensor-distance`, job
/// operation `grid.tensor_distance`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({
    "metric": {"kind": "eigen", "shape": [256, 256], "eigenvalues": [1.0, 100.0], "direction": [1.0, 1.0]},
    "sources": [{"point": [128.0, 128.0]}],
    "ends": [[20.0, 200.0]]
}))]
pub struct GridTensorDistanceRequest {
    /// The metric tensor field (the `metric` section of `grid.distance`).
    pub metric: TensorSpec,
    /// Physical size of a cell along each axis (axis 0 first). Default: the
    /// spacing stored with the tensor's dataset, else 1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(min_items = 2, max_items = 3)]
    pub spacing: Option<Vec<f64>>,
    /// Id of a dataset of the grid's shape whose non-zero cells are walls.
    /// No stencil offset crosses a wall cell, however wide.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub obstacles: Option<String>,
    /// The sources; the Voronoi label of a cell is the index of its source here.
    #[schema(min_items = 1)]
    pub sources: Vec<SourceSpec>,
    /// Order of the scheme, 1 or 2. Default: 2.
    #[serde(default = "default_order")]
    #[schema(minimum = 1, maximum = 2)]
    pub order: u8,
    /// Source factoring around point sources. Default: true.
    #[serde(default = "default_true")]
    pub factoring: bool,
    /// Early stopping rules.
    #[serde(default)]
    pub stop: StopSpec,
    /// Which arrays to return besides the distance.
    #[serde(default)]
    pub outputs: OutputSpec,
    /// End points (index coordinates) of minimal paths from the nearest
    /// source, traced along `−M⁻¹∇U`. Default: none.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub ends: Vec<Vec<f64>>,
    /// Step of the path descent, in cells (steps above 0.5 are taken as 0.5). Default: 0.5.
    #[serde(default = "default_step")]
    pub step: f64,
}

/// Statistics of an anisotropic solve.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct TensorSolveStats {
    /// Cells in the grid.
    pub cells: u64,
    /// Cells with a final value.
    pub frozen: u64,
    /// How the solve ended: `completed`, `targets_reached`, `max_distance` or `max_frozen`.
    pub stop: String,
    /// Largest anisotropy ratio `sqrt(λmax/λmin)` of the field.
    pub max_anisotropy: f64,
    /// Largest stencil offset used, in cells.
    pub stencil_width: u64,
    /// Wall time of the solve (stencils and marching), in seconds.
    pub solve_seconds: f64,
}

/// A minimal path.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct TensorPath {
    /// Position of its end point in `ends`.
    pub index: usize,
    /// Index of the source reached (in `sources`).
    pub source: usize,
    /// The end point, as given.
    pub end: Vec<f64>,
    /// Points from the source to the end, index coordinates (axis 0 first).
    pub points: Vec<Vec<f64>>,
    /// Riemannian length of the polyline, `∫ sqrt(γ'ᵀ M γ')`, physical units.
    pub geodesic_length: f64,
    /// Physical length of the polyline.
    pub euclidean_length: f64,
}

impl GridTensorDistanceRequest {
    fn check(&self, limits: &OpLimits) -> Result<(), OpError> {
        self.metric.validate("metric", limits)?;
        let probe = GridDistanceRequest {
            cost: Some(CostSpec {
                dataset: None,
                constant: Some(1.0),
                shape: Some(vec![1, 1]),
                interpretation: Default::default(),
                design: None,
            }),
            metric: None,
            spacing: self.spacing.clone(),
            obstacles: None,
            sources: self.sources.clone(),
            method: Default::default(),
            order: self.order,
            factoring: self.factoring,
            connectivity: Default::default(),
            stop: self.stop.clone(),
            outputs: self.outputs,
            signed: false,
        };
        if let Some(i) = self.sources.iter().position(|s| s.level_set.is_some()) {
            return Err(OpError::invalid(
                format!("sources[{i}].level_set"),
                "a level set is located in the Euclidean metric of the grid: use grid.distance \
                 with an isotropic `cost`",
            ));
        }
        probe.validate(limits)?;
        if !(self.step.is_finite() && self.step > 0.0) {
            return Err(OpError::invalid(
                "step",
                format!("{} must be finite and > 0", self.step),
            ));
        }
        for (i, p) in self.ends.iter().enumerate() {
            if let Some(k) = p.iter().position(|v| !v.is_finite()) {
                return Err(OpError::invalid(
                    format!("ends[{i}][{k}]"),
                    "coordinates must be finite",
                ));
            }
        }
        if self.ends.len() > 10_000 {
            return Err(OpError::TooLarge {
                field: "ends".into(),
                reason: format!(
                    "{} end points, more than the limit of 10000",
                    self.ends.len()
                ),
            });
        }
        Ok(())
    }
}

impl Operation for GridTensorDistanceRequest {
    const NAME: &'static str = "grid.tensor_distance";

    fn validate(&self, limits: &OpLimits) -> Result<(), OpError> {
        self.check(limits)
    }

    fn dataset_ids(&self) -> Vec<(String, String)> {
        let mut ids = self.metric.dataset_ids("metric");
        if let Some(id) = &self.obstacles {
            ids.push(("obstacles".into(), id.clone()));
        }
        ids.extend(source_dataset_ids(&self.sources));
        ids
    }

    /// Arrays: `distance` (f64), `labels` (i32, unless `outputs.labels` is
    /// false), `frozen_order` (i64, when asked for). Document:
    /// `{"stats": TensorSolveStats, "paths": [TensorPath]}`.
    fn run(
        &self,
        inputs: &dyn Inputs,
        limits: &OpLimits,
        control: &Control<'_>,
    ) -> Result<OpOutput, OpError> {
        self.check(limits)?;
        let resolved = resolve_tensor(
            &self.metric,
            "metric",
            self.spacing.as_deref(),
            self.obstacles.as_deref(),
            inputs,
            limits,
            control,
        )?;
        // Masks are cells at 0; walls are the tensor's own (a mask cell on one is refused there).
        let unit =
            IsotropicCost::constant(1.0).map_err(|e| OpError::invalid("metric", e.to_string()))?;
        let sources: Vec<Source> =
            resolve_sources(&self.sources, &resolved.grid, &unit, inputs, control)?;
        let (problem, spacing) = resolved.into_problem(sources);
        let spec = TensorSolveSpec {
            order: self.order,
            factoring: self.factoring,
            stop: self.stop.rules(),
            record_order: self.outputs.frozen_order,
        };
        let solved = solve_tensor(&problem, &spec, "metric", control)?;
        let (out, solve_seconds) = (solved.out, solved.seconds);
        let flat: Vec<f64> = out.output.distance.iter().copied().collect();
        let mut paths = Vec::with_capacity(self.ends.len());
        // The shared descent of numerics::paths takes steps of at most half a cell.
        let descent = DescentOptions {
            step: self.step.min(0.5),
            ..DescentOptions::default()
        };
        for (i, p) in self.ends.iter().enumerate() {
            if control.is_cancelled() {
                return Err(OpError::Cancelled);
            }
            let field = format!("ends[{i}]");
            let path = minimal_path(
                &problem.grid,
                &problem.metric,
                &flat,
                &problem.sources,
                p,
                &descent,
            )
            .map_err(|e| OpError::invalid(field, e.to_string()))?;
            // The descent's vertices run from the source to the end, as every path answers.
            paths.push(TensorPath {
                index: i,
                source: path.source,
                end: p.clone(),
                points: path.index_points(&problem.grid),
                geodesic_length: path.geodesic_length,
                euclidean_length: path.euclidean_length,
            });
        }
        let stats = TensorSolveStats {
            cells: problem.grid.len() as u64,
            frozen: out.output.frozen as u64,
            stop: stop_name(out.output.stop).into(),
            max_anisotropy: out.stencil.max_anisotropy,
            stencil_width: out.stencil.max_offset as u64,
            solve_seconds,
        };
        let spacing = Some(spacing);
        let mut arrays = vec![OutputArray {
            name: "distance".into(),
            array: ArrayData::F64(out.output.distance),
            spacing: spacing.clone(),
        }];
        if self.outputs.labels {
            arrays.push(OutputArray {
                name: "labels".into(),
                array: ArrayData::I32(out.output.labels),
                spacing: spacing.clone(),
            });
        }
        if let Some(order) = out.output.frozen_order {
            arrays.push(OutputArray {
                name: "frozen_order".into(),
                array: ArrayData::I64(order),
                spacing,
            });
        }
        let document = serde_json::json!({ "stats": stats, "paths": paths });
        Ok(OpOutput::new(arrays, document))
    }
}
