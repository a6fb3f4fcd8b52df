//! `mesh.voronoi`: geodesic Voronoi cells of sources on a mesh (labels,
//! distance, and per-cell vertex counts and areas).

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::spec::mesh::get_mesh;
use super::spec::mesh::vertex_output;
use super::spec::mesh::{compute, MeshDistanceRequest};
use super::{Inputs, OpError, OpLimits, OpOutput, Operation};
use crate::numerics::Control;

/// Request of `mesh.voronoi` (`POST /v1/mesh/voronoi`): the fields of
/// `mesh.distance`; the answer adds one entry per cell.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(transparent)]
pub struct MeshVoronoiRequest(pub MeshDistanceRequest);

/// One Voronoi cell.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct VoronoiCell {
    /// Index of the source.
    pub source: usize,
    /// Vertices labelled with it.
    pub vertices: usize,
    /// Area of the cell: a third of each face's area per vertex of the cell.
    pub area: f64,
}

impl Operation for MeshVoronoiRequest {
    const NAME: &'static str = "mesh.voronoi";

    fn validate(&self, limits: &OpLimits) -> Result<(), OpError> {
        self.0.validate(limits)
    }

    fn dataset_ids(&self) -> Vec<(String, String)> {
        self.0.dataset_ids()
    }

    fn run(
        &self,
        inputs: &dyn Inputs,
        limits: &OpLimits,
        control: &Control<'_>,
    ) -> Result<OpOutput, OpError> {
        let (d, mut document) = compute(&self.0, inputs, limits, control)?;
        let input = get_mesh(inputs, "mesh", &self.0.mesh)?;
        let mut cells: Vec<VoronoiCell> = (0..self.0.sources.len())
            .map(|source| VoronoiCell {
                source,
                vertices: 0,
                area: 0.0,
            })
            .collect();
        for &l in &d.labels {
            if let Some(c) = usize::try_from(l).ok().and_then(|l| cells.get_mut(l)) {
                c.vertices += 1;
            }
        }
        for (f, face) in input.mesh.faces().iter().enumerate() {
            let a = input.mesh.face_area(f) / 3.0;
            for &v in face {
                if let Some(c) = usize::try_from(d.labels[v as usize])
                    .ok()
                    .and_then(|l| cells.get_mut(l))
                {
                    c.area += a;
                }
            }
        }
        if let Some(obj) = document.as_object_mut() {
            obj.insert(
                "cells".into(),
                serde_json::to_value(&cells).unwrap_or_default(),
            );
        }
        Ok(vertex_output(inputs, &self.0.mesh, d, document))
    }
}
