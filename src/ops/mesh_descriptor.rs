//! `mesh.descriptor`: the geodesic shape descriptor of a mesh (distance
//! distribution, eccentricity histogram, canonical-form moments; see
//! [`crate::numerics::shape::descriptor`]), the vector that shape
//! collections compare.

use std::time::Instant;

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::spec::mesh::{get_mesh, HeatSpec, MeshMethodSpec};
use super::spec::shape::{check_connected, heat_for, shape_error};
use super::{Inputs, OpError, OpLimits, OpOutput, Operation};
use crate::numerics::mesh::MeshMethod;
use crate::numerics::shape::descriptor::{descriptor, Descriptor, DescriptorOptions};
use crate::numerics::Control;

/// Most landmarks of a descriptor.
pub const MAX_LANDMARKS: usize = 1000;
/// Most bins of each descriptor histogram.
pub const MAX_BINS: usize = 1024;

fn thirty_two() -> usize {
    32
}

/// How descriptors are computed: the part of a request that a shape
/// collection fixes for all its shapes.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct DescriptorSpec {
    /// Farthest-point landmarks the distances are measured from, 4 to 1000.
    /// Default 32.
    #[serde(default = "thirty_two")]
    #[schema(minimum = 4, maximum = 1000)]
    pub landmarks: usize,
    /// Bins of each histogram, 2 to 1024. Default 32.
    #[serde(default = "thirty_two")]
    #[schema(minimum = 2, maximum = 1024)]
    pub bins: usize,
    /// The distance method. Default: `fast_marching`.
    #[serde(default)]
    pub method: MeshMethodSpec,
}

impl Default for DescriptorSpec {
    fn default() -> Self {
        Self {
            landmarks: 32,
            bins: 32,
            method: MeshMethodSpec::default(),
        }
    }
}

impl DescriptorSpec {
    /// Refuses an out-of-range option, naming it under `prefix` (`""` or
    /// `"descriptor."`).
    pub fn validate(&self, prefix: &str) -> Result<(), OpError> {
        if !(4..=MAX_LANDMARKS).contains(&self.landmarks) {
            return Err(OpError::invalid(
                format!("{prefix}landmarks"),
                format!(
                    "{} is out of range: give 4 to {MAX_LANDMARKS} landmarks (the canonical form needs 4)",
                    self.landmarks
                ),
            ));
        }
        if !(2..=MAX_BINS).contains(&self.bins) {
            return Err(OpError::invalid(
                format!("{prefix}bins"),
                format!("{} is out of range: give 2 to {MAX_BINS} bins", self.bins),
            ));
        }
        Ok(())
    }

    /// The core's options.
    pub fn options(&self) -> DescriptorOptions {
        DescriptorOptions {
            landmarks: self.landmarks,
            bins: self.bins,
            method: self.method.into(),
        }
    }
}

/// Request of `mesh.descriptor` (`POST /v1/mesh/descriptor`, `geodex descriptor`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"mesh": "ds_0192f1b27c1e7d3a9d553c0f2b8a1e44", "landmarks": 32, "bins": 32}))]
pub struct MeshDescriptorRequest {
    /// Id of the mesh dataset (one connected component).
    pub mesh: String,
    /// Farthest-point landmarks the distances are measured from, 4 to 1000.
    /// Default 32.
    #[serde(default = "thirty_two")]
    #[schema(minimum = 4, maximum = 1000)]
    pub landmarks: usize,
    /// Bins of each histogram, 2 to 1024. Default 32.
    #[serde(default = "thirty_two")]
    #[schema(minimum = 2, maximum = 1024)]
    pub bins: usize,
    /// The distance method. Default: `fast_marching`.
    #[serde(default)]
    pub method: MeshMethodSpec,
    /// Heat method options.
    #[serde(default)]
    pub heat: HeatSpec,
}

impl MeshDescriptorRequest {
    /// The request of the descriptor of `mesh` with `spec`.
    pub fn new(mesh: String, spec: DescriptorSpec) -> Self {
        Self {
            mesh,
            landmarks: spec.landmarks,
            bins: spec.bins,
            method: spec.method,
            heat: HeatSpec::default(),
        }
    }

    /// Landmarks, bins and method.
    pub fn spec(&self) -> DescriptorSpec {
        DescriptorSpec {
            landmarks: self.landmarks,
            bins: self.bins,
            method: self.method,
        }
    }
}

/// A descriptor in an answer: its blocks, and the vector they make
/// (`distances`, then `eccentricity`, then `moments`), which is what
/// collections store and compare.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct DescriptorValue {
    /// The geodesic distance distribution: `bins` values summing to 1, bin
    /// `b` covering `[b, b + 1) / bins` of the diameter.
    pub distances: Vec<f64>,
    /// The eccentricity histogram (mean distance to the landmarks over the
    /// diameter): `bins` values summing to 1.
    pub eccentricity: Vec<f64>,
    /// The nine canonical-form moments in `[0, 1]`: the three principal
    /// spreads over the diameter, the three skewness magnitudes `s/(1+s)`,
    /// the three kurtoses `(κ−1)/(κ+1)`.
    pub moments: Vec<f64>,
    /// The blocks one after the other (`2·bins + 9` values).
    pub vector: Vec<f64>,
    /// The estimated geodesic diameter, in the mesh's units.
    pub diameter: f64,
    /// The surface area, in the mesh's units squared.
    pub area: f64,
    /// The landmark vertices.
    pub landmarks: Vec<u32>,
}

impl From<&Descriptor> for DescriptorValue {
    fn from(d: &Descriptor) -> Self {
        Self {
            distances: d.distances.clone(),
            eccentricity: d.eccentricity.clone(),
            moments: d.moments.clone(),
            vector: d.to_vector(),
            diameter: d.diameter,
            area: d.area,
            landmarks: d.landmarks.clone(),
        }
    }
}

impl Operation for MeshDescriptorRequest {
    const NAME: &'static str = "mesh.descriptor";

    fn validate(&self, _limits: &OpLimits) -> Result<(), OpError> {
        self.spec().validate("")?;
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
        check_connected(
            &input,
            "mesh",
            "a descriptor",
            "split the mesh and describe each component",
        )?;
        let method: MeshMethod = self.method.into();
        let heat = heat_for(inputs, method, &self.mesh, &input, &self.heat, control)?;
        let started = Instant::now();
        let d = descriptor(
            &input.mesh,
            &input.topology,
            &self.spec().options(),
            heat.as_deref(),
            control,
        )
        .map_err(|e| shape_error(e, "mesh"))?;
        let document = serde_json::json!({
            "method": self.method,
            "bins": self.bins,
            "descriptor": DescriptorValue::from(&d),
            "stats": {"vertices": input.mesh.num_vertices(), "solve_seconds": started.elapsed().as_secs_f64()},
        });
        Ok(OpOutput::new(Vec::new(), document))
    }
}
