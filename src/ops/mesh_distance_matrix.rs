//! `mesh.distance_matrix`: geodesic distances between many vertices of a
//! mesh at once (see [`crate::numerics::shape::matrix`]): all pairs for
//! small meshes, landmark rows (farthest-point landmarks, or given source
//! vertices) for large ones, as one `k × n` f64 matrix dataset.

use std::time::Instant;

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::spec::mesh::{get_mesh, heat_solver, HeatInfo, HeatSpec, MeshMethodSpec};
use super::spec::mesh_metric::{
    mesh_dataset_ids, resolve_metric, validate_metric, SurfaceMetricSpec,
};
use super::spec::shape::{
    check_size, matrix_output, shape_error, SymmetrySpec, MAX_MATRIX_ENTRIES,
};
use super::{Inputs, OpError, OpLimits, OpOutput, Operation};
use crate::numerics::mesh::MeshMethod;
use crate::numerics::shape::matrix::{distance_rows_in, landmarks};
use crate::numerics::Control;

/// Request of `mesh.distance_matrix` (`POST /v1/mesh/distance-matrix`,
/// `geodex distance-matrix`). Rows are the sources: `sources` if given,
/// else `landmarks` farthest-point landmarks, else every vertex (all pairs,
/// up to 5000 vertices).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"mesh": "ds_0192f1b27c1e7d3a9d553c0f2b8a1e44", "landmarks": 500, "method": "heat"}))]
pub struct MeshDistanceMatrixRequest {
    /// Id of the mesh dataset.
    pub mesh: String,
    /// Number of farthest-point landmarks (rows). Default: all pairs.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(minimum = 1)]
    pub landmarks: Option<usize>,
    /// Explicit source vertices (rows), instead of `landmarks`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sources: Option<Vec<u32>>,
    /// The method. Default: `fast_marching`.
    #[serde(default)]
    pub method: MeshMethodSpec,
    /// Id of an array dataset with one weight `W > 0` per vertex: the rows
    /// are `W`-weighted distances (`fast_marching` or `dijkstra`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub weights: Option<String>,
    /// A metric designed on the surface (curvature, a field; `fast_marching`
    /// or `dijkstra`) or anisotropic (face tensors; `fast_marching`), as on
    /// `mesh.distance`, instead of `weights`. Landmarks are still spread by
    /// the surface's own geodesic distance.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub metric: Option<SurfaceMetricSpec>,
    /// How the source block is made symmetric. Default: `average`.
    #[serde(default)]
    pub symmetry: SymmetrySpec,
    /// Heat method options.
    #[serde(default)]
    pub heat: HeatSpec,
}

impl Operation for MeshDistanceMatrixRequest {
    const NAME: &'static str = "mesh.distance_matrix";

    fn validate(&self, limits: &OpLimits) -> Result<(), OpError> {
        if self.landmarks.is_some() && self.sources.is_some() {
            return Err(OpError::invalid(
                "sources",
                "give `sources` or `landmarks`, not both",
            ));
        }
        if let Some(s) = &self.sources {
            if s.is_empty() {
                return Err(OpError::invalid("sources", "at least one source is needed"));
            }
            if s.len() > limits.max_sources {
                return Err(OpError::TooLarge {
                    field: "sources".into(),
                    reason: format!(
                        "{} sources, more than the limit of {}",
                        s.len(),
                        limits.max_sources
                    ),
                });
            }
        }
        if self.landmarks == Some(0) {
            return Err(OpError::invalid("landmarks", "must be >= 1"));
        }
        if !(self.heat.m.is_finite() && self.heat.m > 0.0) {
            return Err(OpError::invalid("heat.m", "must be finite and > 0"));
        }
        validate_metric(self.weights.as_deref(), self.metric.as_ref(), self.method)?;
        if self.weights.is_some()
            && !matches!(
                self.method,
                MeshMethodSpec::FastMarching | MeshMethodSpec::Dijkstra
            )
        {
            return Err(OpError::invalid(
                "weights",
                "weighted rows run with `method: fast_marching` or `dijkstra`",
            ));
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
        let (mesh, topo) = (&input.mesh, &input.topology);
        let n = mesh.num_vertices();
        let started = Instant::now();
        let sources: Vec<u32> = match (&self.sources, self.landmarks) {
            (Some(s), _) => {
                if let Some((i, v)) = s.iter().enumerate().find(|(_, &v)| v as usize >= n) {
                    return Err(OpError::invalid(
                        format!("sources[{i}]"),
                        format!("vertex {v} does not exist (the mesh has {n} vertices)"),
                    ));
                }
                if s.len().saturating_mul(n) > MAX_MATRIX_ENTRIES {
                    return Err(OpError::TooLarge {
                        field: "sources".into(),
                        reason: format!(
                            "{} rows × {n} vertices is more than {MAX_MATRIX_ENTRIES} distances",
                            s.len()
                        ),
                    });
                }
                s.clone()
            }
            (None, lm) => {
                check_size(n, lm, "mesh")?;
                match lm {
                    Some(k) => landmarks(mesh, topo, k, &control.cancel_only())
                        .map_err(|e| shape_error(e, "mesh"))?,
                    None => (0..n as u32).collect(),
                }
            }
        };
        let method: MeshMethod = self.method.into();
        let (heat, info) = if method == MeshMethod::Heat {
            let (solver, cached, secs) =
                heat_solver(inputs, &self.mesh, &input, &self.heat, control)?;
            let info = HeatInfo::of(&solver, self.heat.m, cached, secs);
            (Some(solver), Some(info))
        } else {
            (None, None)
        };
        let resolved = resolve_metric(
            inputs,
            &input,
            self.weights.as_deref(),
            self.metric.as_ref(),
            control,
        )?;
        let r = distance_rows_in(
            mesh,
            topo,
            &sources,
            method,
            resolved.metric(),
            heat.as_deref(),
            self.symmetry.into(),
            control,
        )
        .map_err(|e| shape_error(e, "mesh"))?;
        let finite = r.rows.iter().filter(|x| x.is_finite());
        let max = finite.clone().copied().reduce(f64::max);
        let unreached = r.rows.len() - finite.count();
        let all_pairs = self.sources.is_none() && self.landmarks.is_none();
        let document = serde_json::json!({
            "method": self.method,
            "symmetry": self.symmetry,
            "rows": sources.len(),
            "columns": n,
            "all_pairs": all_pairs,
            // Row i is the distance from vertex sources[i] (every vertex in order for all pairs).
            "sources": if all_pairs { None } else { Some(&sources) },
            // The metric the rows were solved under, as requested.
            "weights": self.weights,
            "metric": self.metric,
            "asymmetry": r.asymmetry,
            "heat": info,
            "stats": {
                "max_distance": max,
                "unreached": unreached,
                "solve_seconds": started.elapsed().as_secs_f64(),
            },
        });
        Ok(OpOutput::new(
            vec![matrix_output("matrix", r.rows)],
            document,
        ))
    }
}
