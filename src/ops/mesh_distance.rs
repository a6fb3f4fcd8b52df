//! `mesh.distance`: geodesic distance on a triangle mesh from sources at
//! vertices or inside faces, with nearest-source labels.

use std::time::Instant;

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::mesh_common::{
    check_points, get_mesh, read_weights, run_distance, validate_common, vertex_output, HeatSpec,
    MeshMethodSpec, MeshPointSpec, MeshStats,
};
use super::{Inputs, OpError, OpLimits, OpOutput, Operation};
use crate::numerics::mesh::MeshDistance;
use crate::numerics::Control;

/// Request of `mesh.distance` (`POST /v1/mesh/distance`, job operation
/// `mesh.distance`, `geodex mesh-distance`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({
    "mesh": "ds_0192f1b27c1e7d3a9d553c0f2b8a1e44",
    "sources": [{"vertex": 0}, {"face": 12, "bary": [0.2, 0.3, 0.5]}],
    "method": "heat"
}))]
pub struct MeshDistanceRequest {
    /// Id of the mesh dataset.
    pub mesh: String,
    /// The sources; a vertex's label is the index in this list of its nearest source.
    #[schema(min_items = 1)]
    pub sources: Vec<MeshPointSpec>,
    /// The method. Default: `fast_marching`.
    #[serde(default)]
    pub method: MeshMethodSpec,
    /// Vertices farther than this get no distance (`+inf`, label -1). Default: none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(minimum = 0.0)]
    pub max_distance: Option<f64>,
    /// Id of an array dataset with one weight `W > 0` per vertex (cost per
    /// unit length; `fast_marching` and `dijkstra`). Default: 1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub weights: Option<String>,
    /// Heat method options.
    #[serde(default)]
    pub heat: HeatSpec,
}

/// The shared computation of `mesh.distance` and `mesh.voronoi`.
pub(crate) fn compute(
    req: &MeshDistanceRequest,
    inputs: &dyn Inputs,
    limits: &OpLimits,
    control: &Control<'_>,
) -> Result<(MeshDistance, serde_json::Value), OpError> {
    let points = validate_common(&req.sources, req.max_distance, &req.heat, limits)?;
    let input = get_mesh(inputs, "mesh", &req.mesh)?;
    check_points(&input.mesh, &points, "sources")?;
    let weights = match &req.weights {
        Some(id) => Some(read_weights(inputs, id, input.mesh.num_vertices())?),
        None => None,
    };
    let started = Instant::now();
    let (d, heat) = run_distance(
        inputs,
        &req.mesh,
        &input,
        &points,
        req.method.into(),
        req.max_distance.unwrap_or(f64::INFINITY),
        weights.as_deref(),
        &req.heat,
        control,
    )?;
    let stats = MeshStats::of(&d, started.elapsed().as_secs_f64());
    let doc = serde_json::json!({
        "method": req.method,
        "stats": stats,
        "heat": heat,
        "mesh_report": input.report,
    });
    Ok((d, doc))
}

impl Operation for MeshDistanceRequest {
    const NAME: &'static str = "mesh.distance";

    fn validate(&self, limits: &OpLimits) -> Result<(), OpError> {
        validate_common(&self.sources, self.max_distance, &self.heat, limits).map(|_| ())
    }

    fn dataset_ids(&self) -> Vec<(String, String)> {
        let mut ids = vec![("mesh".to_string(), self.mesh.clone())];
        if let Some(w) = &self.weights {
            ids.push(("weights".into(), w.clone()));
        }
        ids
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
