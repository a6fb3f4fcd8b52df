//! `mesh.distance`: geodesic distance on a triangle mesh. The request and
//! its solve are shared with `mesh.voronoi` ([`crate::ops::spec::mesh`]).

pub use super::spec::mesh::MeshDistanceRequest;
use super::spec::mesh::{compute, validate_common, vertex_output};
use super::spec::mesh_metric::{mesh_dataset_ids, validate_metric};
use super::{Inputs, OpError, OpLimits, OpOutput, Operation};
use crate::numerics::Control;

impl Operation for MeshDistanceRequest {
    const NAME: &'static str = "mesh.distance";

    fn validate(&self, limits: &OpLimits) -> Result<(), OpError> {
        validate_common(&self.sources, self.max_distance, &self.heat, limits)?;
        validate_metric(self.weights.as_deref(), self.metric.as_ref(), self.method)
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
        let (d, document) = compute(self, inputs, limits, control)?;
        Ok(vertex_output(inputs, &self.mesh, d, document))
    }
}
