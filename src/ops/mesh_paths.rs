//! `mesh.paths`: geodesic paths from the nearest source to each end point,
//! as 3D polylines with the vertex, edge or face of every point (traced from
//! the end down the distance field, answered from the source to the end).

use std::time::Instant;

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::spec::errors::mesh_solve_error;
use super::spec::mesh::{
    check_points, get_mesh, run_distance, validate_common, HeatSpec, MeshMethodSpec, MeshPointSpec,
};
use super::spec::mesh_metric::{
    mesh_dataset_ids, resolve_metric, validate_metric, SurfaceMetricSpec,
};
use super::{Inputs, OpError, OpLimits, OpOutput, Operation};
use crate::numerics::mesh::exact::exact_paths;
use crate::numerics::mesh::paths::{trace_path_in, PathLocation};
use crate::numerics::mesh::{MeshMethod, SurfacePoint};
use crate::numerics::Control;

/// Request of `mesh.paths` (`POST /v1/mesh/paths`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({
    "mesh": "ds_0192f1b27c1e7d3a9d553c0f2b8a1e44",
    "sources": [{"vertex": 0}],
    "ends": [{"vertex": 500}, {"face": 40, "bary": [0.3, 0.3, 0.4]}]
}))]
pub struct MeshPathsRequest {
    /// Id of the mesh dataset.
    pub mesh: String,
    /// The sources.
    #[schema(min_items = 1)]
    pub sources: Vec<MeshPointSpec>,
    /// The end points; each path runs from its nearest source to its end.
    #[schema(min_items = 1)]
    pub ends: Vec<MeshPointSpec>,
    /// The method. `exact` backtracks the exact method's windows: each path
    /// is a shortest path (straight in every face and across every edge
    /// once unfolded) whose length equals the exact distance; the other
    /// methods descend their distance field. Default: `fast_marching`.
    #[serde(default)]
    pub method: MeshMethodSpec,
    /// Id of an array dataset with one weight `W > 0` per vertex (cost per
    /// unit length; `fast_marching` and `dijkstra`). Default: 1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub weights: Option<String>,
    /// A metric designed on the surface (curvature, field) or anisotropic
    /// (face tensors, `fast_marching` only: the path then follows the
    /// characteristic direction `−M⁻¹∇U`), instead of `weights`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub metric: Option<SurfaceMetricSpec>,
    /// Heat method options.
    #[serde(default)]
    pub heat: HeatSpec,
}

/// One point of a path.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct PathPointOut {
    /// Position `[x, y, z]`.
    pub position: [f64; 3],
    /// The vertex, when the point is one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub vertex: Option<u32>,
    /// The edge `[a, b]`, when the point lies on one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub edge: Option<[u32; 2]>,
    /// The face, when the point lies inside one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub face: Option<u32>,
}

/// How a path was traced.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum TracedSpec {
    /// Backtracked through the exact method's windows: a shortest path
    /// whose length is the exact distance.
    Windows,
    /// Descent of the distance field across faces (every method but
    /// `exact`, and `exact` where its windows could not be followed back).
    Descent,
}

/// One path.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct PathOut {
    /// Position of its end point in `ends`.
    pub index: usize,
    /// Index of the source reached (`null` if the descent stopped short).
    pub source: Option<usize>,
    /// How it was traced.
    pub traced: TracedSpec,
    /// Why an `exact` path fell back to the descent, when it did.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub note: Option<String>,
    /// The geodesic distance `U` of the end point in the field that was
    /// descended (with `exact`, the polyline's length).
    pub geodesic_length: f64,
    /// Length of the polyline in 3D.
    pub euclidean_length: f64,
    /// The polyline, from the source to the end point.
    pub points: Vec<PathPointOut>,
}

impl Operation for MeshPathsRequest {
    const NAME: &'static str = "mesh.paths";

    fn validate(&self, limits: &OpLimits) -> Result<(), OpError> {
        validate_common(&self.sources, None, &self.heat, limits)?;
        validate_metric(self.weights.as_deref(), self.metric.as_ref(), self.method)?;
        if self.ends.is_empty() {
            return Err(OpError::invalid("ends", "at least one end point is needed"));
        }
        if self.ends.len() > limits.max_sources {
            return Err(OpError::TooLarge {
                field: "ends".into(),
                reason: format!("more than {} end points", limits.max_sources),
            });
        }
        for (i, t) in self.ends.iter().enumerate() {
            t.to_point(&format!("ends[{i}]"))?;
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
        let sources = validate_common(&self.sources, None, &self.heat, limits)?;
        let targets = self
            .ends
            .iter()
            .enumerate()
            .map(|(i, t)| t.to_point(&format!("ends[{i}]")))
            .collect::<Result<Vec<_>, _>>()?;
        let input = get_mesh(inputs, "mesh", &self.mesh)?;
        check_points(&input.mesh, &sources, "sources")?;
        check_points(&input.mesh, &targets, "ends")?;
        let started = Instant::now();
        let method: MeshMethod = self.method.into();
        let metric = resolve_metric(
            inputs,
            &input,
            self.weights.as_deref(),
            self.metric.as_ref(),
            control,
        )?;
        // The exact method backtracks its windows: exact paths. The others
        // descend their distance field.
        let (d, heat, exact) = if method == MeshMethod::Exact {
            let (d, paths) = exact_paths(&input.mesh, &input.topology, &sources, &targets, control)
                .map_err(mesh_solve_error)?;
            (d, None, Some(paths))
        } else {
            let (d, heat) = run_distance(
                inputs,
                &self.mesh,
                &input,
                &sources,
                method,
                f64::INFINITY,
                &metric,
                &self.heat,
                control,
            )?;
            (d, heat, None)
        };
        let mut exact = exact.map(|p| p.into_iter());
        let mut paths = Vec::with_capacity(targets.len());
        for (i, t) in targets.iter().enumerate() {
            if control.is_cancelled() {
                return Err(OpError::Cancelled);
            }
            let descend = || {
                trace_path_in(
                    &input.mesh,
                    &input.topology,
                    &d.distance,
                    &sources,
                    *t,
                    metric.tensors.as_deref(),
                )
            };
            let reached = match *t {
                SurfacePoint::Vertex(v) => d.distance[v as usize].is_finite(),
                SurfacePoint::Face { face, .. } => input.mesh.faces()[face as usize]
                    .iter()
                    .any(|&v| d.distance[v as usize].is_finite()),
            };
            let (path, traced, note) = match exact.as_mut().and_then(|p| p.next()) {
                Some(Ok(p)) => (Ok(p), TracedSpec::Windows, None),
                // The windows could not be followed back (near-degenerate
                // faces): the descent of the exact distance, said so.
                Some(Err(e)) if reached => (descend(), TracedSpec::Descent, Some(e.to_string())),
                Some(Err(e)) => (Err(e), TracedSpec::Windows, None),
                None => (descend(), TracedSpec::Descent, None),
            };
            let path = path.map_err(|e| OpError::invalid(format!("ends[{i}]"), e.to_string()))?;
            let distance = match *t {
                SurfacePoint::Vertex(v) => d.distance[v as usize],
                // The exact distance of a point inside a face is the length
                // of its exact path; the others interpolate.
                SurfacePoint::Face { .. } if traced == TracedSpec::Windows => path.length,
                SurfacePoint::Face { face, bary } => {
                    let f = input.mesh.faces()[face as usize];
                    (0..3).map(|k| bary[k] * d.distance[f[k] as usize]).sum()
                }
            };
            paths.push(PathOut {
                index: i,
                source: path.source,
                traced,
                note,
                geodesic_length: distance,
                euclidean_length: path.length,
                // The core traces from the end down to the source.
                points: path
                    .points
                    .iter()
                    .rev()
                    .map(|p| {
                        let mut o = PathPointOut {
                            position: p.position,
                            vertex: None,
                            edge: None,
                            face: None,
                        };
                        match p.location {
                            PathLocation::Vertex(v) => o.vertex = Some(v),
                            PathLocation::Edge(a, b, _) => o.edge = Some([a, b]),
                            PathLocation::Face(f) => o.face = Some(f),
                        }
                        o
                    })
                    .collect(),
            });
        }
        let document = serde_json::json!({
            "method": self.method,
            "heat": heat,
            "solve_seconds": started.elapsed().as_secs_f64(),
            "paths": paths,
        });
        Ok(OpOutput::new(Vec::new(), document))
    }
}
