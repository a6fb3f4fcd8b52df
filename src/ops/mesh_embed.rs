//! `mesh.embed`: the bending-invariant canonical form of a mesh (Elad and
//! Kimmel; see [`crate::numerics::shape::canonical`]), as a mesh dataset
//! with the input's faces at the embedded positions, plus the `n × d`
//! coordinates.

use std::sync::Arc;
use std::time::Instant;

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::spec::mesh::{get_mesh, HeatSpec, MeshInput, MeshMethodSpec};
use super::spec::shape::{check_connected, check_size, heat_for, matrix_output, shape_error};
use super::{Inputs, OpError, OpLimits, OpOutput, Operation, OutputMesh};
use crate::numerics::mesh::MeshMethod;
use crate::numerics::shape::canonical::{canonical_form, CanonicalOptions};
use crate::numerics::shape::mds::SmacofOptions;
use crate::numerics::Control;

/// SMACOF refinement of an all-pairs embedding.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct SmacofSpec {
    /// Most iterations. Default 100.
    #[serde(default = "hundred")]
    #[schema(minimum = 1)]
    pub iterations: usize,
    /// Stop when the stress falls by less than this fraction. Default 1e-6.
    #[serde(default = "micro")]
    #[schema(exclusive_minimum = 0.0)]
    pub tolerance: f64,
}

fn hundred() -> usize {
    100
}

fn micro() -> f64 {
    1e-6
}

fn three() -> usize {
    3
}

/// Request of `mesh.embed` (`POST /v1/mesh/embed`, `geodex embed`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"mesh": "ds_0192f1b27c1e7d3a9d553c0f2b8a1e44", "landmarks": 300}))]
pub struct MeshEmbedRequest {
    /// Id of the mesh dataset (one connected component).
    pub mesh: String,
    /// Embedding dimension, 2 or 3. Default 3.
    #[serde(default = "three")]
    #[schema(minimum = 2, maximum = 3)]
    pub dimensions: usize,
    /// Farthest-point landmarks for landmark MDS. Default: all pairs
    /// (classical MDS, meshes of up to 5000 vertices).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(minimum = 4)]
    pub landmarks: Option<usize>,
    /// Refine the all-pairs embedding by SMACOF. Default: none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub smacof: Option<SmacofSpec>,
    /// The distance method. Default: `fast_marching`.
    #[serde(default)]
    pub method: MeshMethodSpec,
    /// Heat method options.
    #[serde(default)]
    pub heat: HeatSpec,
}

impl Operation for MeshEmbedRequest {
    const NAME: &'static str = "mesh.embed";

    fn validate(&self, _limits: &OpLimits) -> Result<(), OpError> {
        if !(2..=3).contains(&self.dimensions) {
            return Err(OpError::invalid("dimensions", "must be 2 or 3"));
        }
        if let Some(k) = self.landmarks {
            if k <= self.dimensions {
                return Err(OpError::invalid(
                    "landmarks",
                    format!(
                        "at least dimensions + 1 = {} landmarks are needed",
                        self.dimensions + 1
                    ),
                ));
            }
            if self.smacof.is_some() {
                return Err(OpError::invalid(
                    "smacof",
                    "SMACOF refines all-pairs embeddings only: drop `landmarks` or `smacof`",
                ));
            }
        }
        if let Some(s) = &self.smacof {
            if s.iterations == 0 {
                return Err(OpError::invalid("smacof.iterations", "must be >= 1"));
            }
            if !(s.tolerance.is_finite() && s.tolerance > 0.0) {
                return Err(OpError::invalid(
                    "smacof.tolerance",
                    "must be finite and > 0",
                ));
            }
        }
        if !(self.heat.m.is_finite() && self.heat.m > 0.0) {
            return Err(OpError::invalid("heat.m", "must be finite and > 0"));
        }
        Ok(())
    }

    fn dataset_ids(&self) -> Vec<(String, String)> {
        vec![("mesh".to_string(), self.mesh.clone())]
    }

    fn run(
        &self,
        inputs: &dyn Inputs,
        limits: &OpLimits,
        control: &Control<'_>,
    ) -> Result<OpOutput, OpError> {
        self.validate(limits)?;
        let input = get_mesh(inputs, "mesh", &self.mesh)?;
        check_size(input.mesh.num_vertices(), self.landmarks, "mesh")?;
        check_connected(
            &input,
            "mesh",
            "an embedding",
            "split the mesh and embed each component",
        )?;
        let method: MeshMethod = self.method.into();
        let heat = heat_for(inputs, method, &self.mesh, &input, &self.heat, control)?;
        let started = Instant::now();
        let form = canonical_form(
            &input.mesh,
            &input.topology,
            &CanonicalOptions {
                method,
                dimensions: self.dimensions,
                landmarks: self.landmarks,
                smacof: self.smacof.map(|s| SmacofOptions {
                    max_iterations: s.iterations,
                    tolerance: s.tolerance,
                }),
            },
            heat.as_deref(),
            control,
        )
        .map_err(|e| shape_error(e, "mesh"))?;
        let document = serde_json::json!({
            "method": self.method,
            "dimensions": self.dimensions,
            "landmarks": form.landmarks,
            "explained_variance": form.explained_variance,
            "stress": form.stress,
            "smacof_stress": form.smacof_stress,
            "asymmetry": form.asymmetry,
            "stats": {"vertices": input.mesh.num_vertices(), "solve_seconds": started.elapsed().as_secs_f64()},
        });
        let mut out = OpOutput::new(vec![matrix_output("coordinates", form.coords)], document);
        out.mesh = Some(OutputMesh {
            name: "result".into(),
            mesh: Arc::new(MeshInput {
                mesh: form.mesh,
                topology: input.topology.clone(),
                report: input.report.clone(),
            }),
            vertex_properties: Vec::new(),
        });
        Ok(out)
    }
}
