//! `mesh.remesh`: surface remeshing (see [`crate::numerics::meshing::surface`]):
//! geodesic farthest-point sampling (uniform or curvature-adapted), geodesic
//! Lloyd relaxation with its energy per iteration, and the dual of the
//! Voronoi cells, repaired until it is a manifold of the input's topology
//! (or said not to be). The result is a new mesh dataset.

use std::sync::Arc;
use std::time::Instant;

use ndarray::ArrayD;
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::spec::errors::mesh_solve_error;
use super::spec::mesh::{get_mesh, MeshInput};
use super::{Inputs, OpError, OpLimits, OpOutput, Operation, OutputArray, OutputMesh};
use crate::io::mesh::report_of;
use crate::io::ArrayData;
use crate::numerics::mesh::Topology;
use crate::numerics::meshing::surface::{
    bounding_diagonal, hausdorff_distance, remesh, Adaptation, RemeshError, RemeshOptions,
    Sampling, TopologySummary,
};
use crate::numerics::Control;

/// How the vertex density follows the surface.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum RemeshAdaptationSpec {
    /// Cells of equal geodesic size.
    #[default]
    Uniform,
    /// `W = 1 + strength · κ / mean κ`: smaller cells where the surface bends.
    Curvature,
    /// A tensor per triangle from the curvature tensor: cells elongated
    /// along the directions of low curvature, by `sqrt(|κ₁| / |κ₂|)` capped
    /// at `max_ratio`.
    Anisotropic,
}

/// How the samples are placed (step 1 of the remesh).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum RemeshSamplingSpec {
    /// `clustered` when the adaptation is not anisotropic and the input has
    /// at least 8 vertices per sample, else `exact`.
    #[default]
    Auto,
    /// Exact farthest-point sampling on the input's vertices (a front per
    /// sample: about `ln count + 0.6` marches over the input).
    Exact,
    /// Farthest-point sampling on clusters of about `n / (24 count)`
    /// vertices, then one front per sample (about one march over the
    /// input). Not with `adaptation: anisotropic`.
    Clustered,
}

/// Request of `mesh.remesh` (`POST /v1/mesh/remesh`, `geodex remesh`).
/// Give `count` or `edge_length`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"mesh": "ds_0192f1b27c1e7d3a9d553c0f2b8a1e44", "count": 5000}))]
pub struct MeshRemeshRequest {
    /// Id of the mesh dataset (a manifold triangle mesh).
    pub mesh: String,
    /// Target number of vertices (at least 4, at most the input's vertex count).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(minimum = 4)]
    pub count: Option<usize>,
    /// Target edge length: the count becomes `2 A / (√3 h²)` (the vertex
    /// count of an equilateral triangulation of area `A`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(exclusive_minimum = 0.0)]
    pub edge_length: Option<f64>,
    /// Density. Default `uniform`.
    #[serde(default)]
    pub adaptation: RemeshAdaptationSpec,
    /// Contrast of the curvature adaptation (`>= 0`). Default 2.
    #[serde(default = "two")]
    #[schema(minimum = 0.0)]
    pub strength: f64,
    /// Largest length-to-width ratio of the cells of the anisotropic
    /// adaptation (`1 ..= 100`). Default 3.
    #[serde(default = "three")]
    #[schema(minimum = 1.0, maximum = 100.0)]
    pub max_ratio: f64,
    /// Geodesic Lloyd iterations (at most 100). Default 0 when the final
    /// relaxation runs (`smoothing_iterations` not 0, adaptation not
    /// anisotropic), else 5.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(maximum = 100)]
    pub lloyd_iterations: Option<usize>,
    /// Rounds of edge flips and tangential relaxation of the output, its
    /// vertices projected back onto the input surface (at most 100; 0
    /// keeps the vertices at input vertices and the geodesic dual's
    /// connectivity; not applied with `adaptation: anisotropic`). Default:
    /// `400000 / count` clamped to 20..=100.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(maximum = 100)]
    pub smoothing_iterations: Option<usize>,
    /// How the samples are placed. Default `auto`.
    #[serde(default)]
    pub sampling: RemeshSamplingSpec,
    /// Report the Hausdorff distance to the input. Default true.
    #[serde(default = "yes")]
    pub hausdorff: bool,
}

fn two() -> f64 {
    2.0
}

fn three() -> f64 {
    3.0
}

fn yes() -> bool {
    true
}

impl Operation for MeshRemeshRequest {
    const NAME: &'static str = "mesh.remesh";

    fn validate(&self, limits: &OpLimits) -> Result<(), OpError> {
        match (self.count, self.edge_length) {
            (None, None) => return Err(OpError::invalid("count", "give `count` or `edge_length`")),
            (Some(_), Some(_)) => {
                return Err(OpError::invalid(
                    "edge_length",
                    "give `count` or `edge_length`, not both",
                ))
            }
            (Some(c), None) if c < 4 => return Err(OpError::invalid("count", "must be >= 4")),
            (Some(c), None) if c > limits.max_sources => {
                return Err(OpError::TooLarge {
                    field: "count".into(),
                    reason: format!("more than {} vertices", limits.max_sources),
                })
            }
            (None, Some(h)) if !(h.is_finite() && h > 0.0) => {
                return Err(OpError::invalid("edge_length", "must be finite and > 0"))
            }
            _ => {}
        }
        if !(self.strength.is_finite() && self.strength >= 0.0) {
            return Err(OpError::invalid("strength", "must be finite and >= 0"));
        }
        if !(self.max_ratio.is_finite() && (1.0..=100.0).contains(&self.max_ratio)) {
            return Err(OpError::invalid(
                "max_ratio",
                "must be finite, >= 1 and <= 100",
            ));
        }
        if self.lloyd_iterations.is_some_and(|k| k > 100) {
            return Err(OpError::invalid("lloyd_iterations", "must be <= 100"));
        }
        if self.smoothing_iterations.is_some_and(|k| k > 100) {
            return Err(OpError::invalid("smoothing_iterations", "must be <= 100"));
        }
        if self.sampling == RemeshSamplingSpec::Clustered
            && self.adaptation == RemeshAdaptationSpec::Anisotropic
        {
            return Err(OpError::invalid(
                "sampling",
                "clustered sampling measures isotropic lengths: use `auto` or `exact` with `adaptation: anisotropic`",
            ));
        }
        Ok(())
    }

    fn dataset_ids(&self) -> Vec<(String, String)> {
        vec![("mesh".to_string(), self.mesh.clone())]
    }

    /// Arrays: `vertices` (f64, `nv × 3`), `triangles` (int32, `nt × 3`),
    /// `samples` (int32, the input vertex each output vertex was sampled at,
    /// before the relaxation moved it on the surface). Mesh:
    /// `remeshed`. Document: `{"stats": {...}}` with the energies per
    /// Lloyd iteration and both topologies.
    fn run(
        &self,
        inputs: &dyn Inputs,
        limits: &OpLimits,
        control: &Control<'_>,
    ) -> Result<OpOutput, OpError> {
        self.validate(limits)?;
        let input = get_mesh(inputs, "mesh", &self.mesh)?;
        let mesh = &input.mesh;
        let n = mesh.num_vertices();
        let (count, field) = match (self.count, self.edge_length) {
            (Some(c), _) => (c, "count"),
            (None, Some(h)) => {
                let area: f64 = (0..mesh.num_faces()).map(|f| mesh.face_area(f)).sum();
                let c = (2.0 * area / (3f64.sqrt() * h * h)).round();
                (
                    if c.is_finite() {
                        c as usize
                    } else {
                        usize::MAX
                    },
                    "edge_length",
                )
            }
            (None, None) => return Err(OpError::invalid("count", "give `count` or `edge_length`")),
        };
        if count > n {
            return Err(OpError::invalid(
                field,
                format!("asks for {count} vertices, more than the input's {n}"),
            ));
        }
        if count < 4 {
            return Err(OpError::invalid(
                field,
                format!("asks for {count} vertices; at least 4 are needed"),
            ));
        }
        if input.topology.non_manifold_edges > 0 || input.topology.misoriented_edges > 0 {
            return Err(OpError::invalid(
                "mesh",
                format!(
                    "the mesh is not manifold: {} edges in more than two faces, {} edges with inconsistent orientation",
                    input.topology.non_manifold_edges, input.topology.misoriented_edges
                ),
            ));
        }
        let adaptation = match self.adaptation {
            RemeshAdaptationSpec::Uniform => Adaptation::Uniform,
            RemeshAdaptationSpec::Curvature => Adaptation::Curvature {
                strength: self.strength,
            },
            RemeshAdaptationSpec::Anisotropic => Adaptation::Anisotropic {
                max_ratio: self.max_ratio,
            },
        };
        let started = Instant::now();
        let r = remesh(
            mesh,
            &RemeshOptions {
                count,
                adaptation,
                lloyd_iterations: self.lloyd_iterations,
                smoothing_iterations: self.smoothing_iterations,
                sampling: match self.sampling {
                    RemeshSamplingSpec::Auto => Sampling::Auto,
                    RemeshSamplingSpec::Exact => Sampling::Exact,
                    RemeshSamplingSpec::Clustered => Sampling::Clustered,
                },
                ..Default::default()
            },
            control,
        )
        .map_err(|e| remesh_error(e, field))?;
        let seconds = started.elapsed().as_secs_f64();
        let diagonal = bounding_diagonal(mesh);
        let hausdorff = if self.hausdorff {
            Some(hausdorff_distance(mesh, &r.mesh, control).map_err(|e| remesh_error(e, field))?)
        } else {
            None
        };
        let topo_json = |t: &TopologySummary| {
            serde_json::json!({
                "vertices": t.vertices,
                "edges": t.edges,
                "faces": t.faces,
                "components": t.components,
                "boundary_loops": t.boundary_loops,
                "euler_characteristic": t.euler,
                "genus": t.genus,
                "non_manifold_edges": t.non_manifold_edges,
                "misoriented_edges": t.misoriented_edges,
            })
        };
        let note = if r.topology_kept {
            "the output keeps the input's components, boundary loops and genus".to_string()
        } else if r.cleaned.removed_faces > 0 || r.cleaned.dropped_vertices > 0 {
            format!(
                "the dual could not be repaired everywhere: {} triangles were removed to make the output manifold (they leave holes) and {} samples in no triangle were dropped; raise count to keep more of the input's topology",
                r.cleaned.removed_faces, r.cleaned.dropped_vertices
            )
        } else if r.valid {
            "the output is a valid manifold but its topology differs from the input's: the sampling is too coarse for it (raise count)".to_string()
        } else {
            "the dual could not be repaired into a manifold triangulation: raise count".to_string()
        };
        let stats = serde_json::json!({
            "vertices": r.mesh.num_vertices(),
            "triangles": r.mesh.num_faces(),
            "target_count": count,
            "added": r.added,
            "repair_rounds": r.repair_rounds,
            "sampling": {
                "method": if r.sampled.clustered { "clustered" } else { "exact" },
                "clusters": r.sampled.clusters,
                "front_visits": r.sampled.front_visits,
                "restarted": r.sampled.restarted,
            },
            "lloyd_energies": r.energies,
            "lloyd_accepted": r.lloyd_accepted,
            "smoothing_sweeps": r.relaxed.sweeps,
            "edge_flips": r.relaxed.flips,
            "vertex_moves": r.relaxed.moves,
            "vertex_moves_undone": r.relaxed.rejected,
            "covering_moves": r.relaxed.covering_moves,
            "mending_moves": r.relaxed.mending_moves,
            "valid": r.valid,
            "flipped": r.flipped,
            "removed_faces": r.cleaned.removed_faces,
            "dropped_vertices": r.cleaned.dropped_vertices,
            "topology_kept": r.topology_kept,
            "topology_note": note,
            "input_topology": topo_json(&r.input_topology),
            "output_topology": topo_json(&r.output_topology),
            "hausdorff": hausdorff,
            "hausdorff_relative": hausdorff.map(|h| h / diagonal),
            "bounding_diagonal": diagonal,
            "seconds": seconds,
        });
        let nv = r.mesh.num_vertices();
        let bad = |e: ndarray::ShapeError| OpError::invalid("mesh", e.to_string());
        let vertices = ArrayD::from_shape_vec(
            vec![nv, 3],
            r.mesh.positions().iter().flatten().copied().collect(),
        )
        .map_err(bad)?;
        let triangles = ArrayD::from_shape_vec(
            vec![r.mesh.num_faces(), 3],
            r.mesh.faces().iter().flatten().map(|&v| v as i32).collect(),
        )
        .map_err(bad)?;
        let samples = ArrayD::from_shape_vec(
            vec![r.samples.len()],
            r.samples.iter().map(|&v| v as i32).collect(),
        )
        .map_err(bad)?;
        let topology = Topology::new(&r.mesh);
        let report = report_of(&r.mesh, &topology);
        let mut out = OpOutput::new(
            vec![
                OutputArray {
                    name: "vertices".into(),
                    array: ArrayData::F64(vertices),
                    spacing: None,
                },
                OutputArray {
                    name: "triangles".into(),
                    array: ArrayData::I32(triangles),
                    spacing: None,
                },
                OutputArray {
                    name: "samples".into(),
                    array: ArrayData::I32(samples),
                    spacing: None,
                },
            ],
            serde_json::json!({ "stats": stats }),
        );
        out.mesh = Some(OutputMesh {
            name: "remeshed".into(),
            mesh: Arc::new(MeshInput {
                mesh: r.mesh,
                topology,
                report,
            }),
            vertex_properties: vec![],
        });
        Ok(out)
    }
}

/// A remeshing error as an [`OpError`] naming the request field.
fn remesh_error(e: RemeshError, count_field: &'static str) -> OpError {
    match e {
        RemeshError::Cancelled => OpError::Cancelled,
        RemeshError::Solve(s) => mesh_solve_error(s),
        RemeshError::InvalidOption {
            option: "count", ..
        } => OpError::invalid(count_field, e.to_string()),
        RemeshError::InvalidOption { option, .. } => OpError::invalid(option, e.to_string()),
        RemeshError::NonManifold { .. } => OpError::invalid("mesh", e.to_string()),
    }
}
