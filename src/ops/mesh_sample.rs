//! `mesh.sample`: farthest-point sampling of a mesh and the Voronoi cells of
//! the samples.

use std::time::Instant;

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::spec::errors::mesh_solve_error;
use super::spec::mesh::vertex_output;
use super::spec::mesh::{get_mesh, heat_solver, HeatSpec, MeshMethodSpec, MeshStats};
use super::spec::mesh_metric::{
    mesh_dataset_ids, resolve_metric, validate_metric, SurfaceMetricSpec,
};
use super::{Inputs, OpError, OpLimits, OpOutput, Operation};
use crate::numerics::mesh::sampling::{farthest_point_sampling_in, SamplingOptions};
use crate::numerics::mesh::MeshMethod;
use crate::numerics::Control;

/// Request of `mesh.sample` (`POST /v1/mesh/sample`). Give `count`,
/// `radius` or both (sampling stops at the first reached).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"mesh": "ds_0192f1b27c1e7d3a9d553c0f2b8a1e44", "count": 100}))]
pub struct MeshSampleRequest {
    /// Id of the mesh dataset.
    pub mesh: String,
    /// Number of samples.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(minimum = 1)]
    pub count: Option<usize>,
    /// Stop once every vertex is within this distance of a sample.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(exclusive_minimum = 0.0)]
    pub radius: Option<f64>,
    /// The first sample (a vertex). Default: the vertex farthest from vertex 0.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub first: Option<u32>,
    /// The distance method. Default: `fast_marching`.
    #[serde(default)]
    pub method: MeshMethodSpec,
    /// Id of an array dataset with one weight `W > 0` per vertex: samples
    /// are denser where `W` is large (`fast_marching` only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub weights: Option<String>,
    /// A metric designed on the surface (curvature: denser samples on
    /// ridges; a field) or anisotropic (face tensors: cells stretched by
    /// the metric), instead of `weights` (`fast_marching` only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub metric: Option<SurfaceMetricSpec>,
    /// Heat method options.
    #[serde(default)]
    pub heat: HeatSpec,
}

impl Operation for MeshSampleRequest {
    const NAME: &'static str = "mesh.sample";

    fn validate(&self, limits: &OpLimits) -> Result<(), OpError> {
        match (self.count, self.radius) {
            (None, None) => {
                return Err(OpError::invalid("count", "give `count`, `radius` or both"))
            }
            (Some(0), _) => return Err(OpError::invalid("count", "must be >= 1")),
            (Some(c), _) if c > limits.max_sources => {
                return Err(OpError::TooLarge {
                    field: "count".into(),
                    reason: format!("more than {} samples", limits.max_sources),
                })
            }
            _ => {}
        }
        if let Some(r) = self.radius {
            if !(r.is_finite() && r > 0.0) {
                return Err(OpError::invalid("radius", "must be finite and > 0"));
            }
        }
        if !(self.heat.m.is_finite() && self.heat.m > 0.0) {
            return Err(OpError::invalid("heat.m", "must be finite and > 0"));
        }
        validate_metric(self.weights.as_deref(), self.metric.as_ref(), self.method)?;
        if self.method != MeshMethodSpec::FastMarching {
            if self.metric.is_some() {
                return Err(OpError::invalid(
                    "metric",
                    "sampling under a metric runs with `method: fast_marching`",
                ));
            }
            if self.weights.is_some() {
                return Err(OpError::invalid(
                    "weights",
                    "sampling under weights runs with `method: fast_marching`",
                ));
            }
        }
        Ok(())
    }

    fn dataset_ids(&self) -> Vec<(String, String)> {
        mesh_dataset_ids(&self.mesh, self.weights.as_deref(), self.metric.as_ref())
    }

    fn run(
        &self,
        inputs: &dyn Inputs,
        limits: &OpLimits,
        control: &Control<'_>,
    ) -> Result<OpOutput, OpError> {
        self.validate(limits)?;
        let input = get_mesh(inputs, "mesh", &self.mesh)?;
        if let Some(v) = self.first {
            if v as usize >= input.mesh.num_vertices() {
                return Err(OpError::invalid(
                    "first",
                    format!(
                        "vertex {v} does not exist (the mesh has {} vertices)",
                        input.mesh.num_vertices()
                    ),
                ));
            }
        }
        let method: MeshMethod = self.method.into();
        let heat = if method == MeshMethod::Heat {
            Some(heat_solver(inputs, &self.mesh, &input, &self.heat, control)?.0)
        } else {
            None
        };
        let started = Instant::now();
        let resolved = resolve_metric(
            inputs,
            &input,
            self.weights.as_deref(),
            self.metric.as_ref(),
            control,
        )?;
        let s = farthest_point_sampling_in(
            &input.mesh,
            &input.topology,
            &SamplingOptions {
                count: self.count,
                radius: self.radius,
                first: self.first,
                method,
            },
            resolved.metric(),
            heat.as_deref(),
            control,
        )
        .map_err(mesh_solve_error)?;
        let stats = MeshStats::of(&s.field, started.elapsed().as_secs_f64());
        let document = serde_json::json!({
            "method": self.method,
            "samples": s.samples,
            "covering_radius": s.covering_radius,
            "stats": stats,
        });
        Ok(vertex_output(inputs, &self.mesh, s.field, document))
    }
}
