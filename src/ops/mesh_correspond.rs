//! `mesh.correspond`: a correspondence between two near-isometric meshes
//! (see [`crate::numerics::shape::correspond`]): for every vertex of `a`, a
//! point of `b` (face and barycentric coordinates), its nearest vertex and a
//! confidence, as NPY arrays and as `a`'s mesh carrying them per vertex;
//! the document reports whether an intrinsic symmetry (a mirror flip) makes
//! a second map almost as good.

use std::sync::Arc;
use std::time::Instant;

use ndarray::{Array1, Array2};
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::spec::mesh::{get_mesh, MeshInput};
use super::spec::shape::{check_connected, check_size, matrix_output, shape_error};
use super::{Inputs, OpError, OpLimits, OpOutput, Operation, OutputArray, OutputMesh};
use crate::io::ArrayData;
use crate::numerics::mesh::{MeshMethod, TriMesh};
use crate::numerics::shape::correspond::{correspond, CorrespondOptions, SEPARATION};
use crate::numerics::Control;

/// Largest ratio of the two areas accepted without `scale` (an isometry
/// keeps the area; 20 % covers meshing and near-isometric poses).
pub const AREA_RATIO_LIMIT: f64 = 1.2;

/// Most landmarks.
pub const MAX_LANDMARKS: usize = 500;

fn sixty() -> usize {
    60
}

/// Request of `mesh.correspond` (`POST /v1/mesh/correspond`, `geodex correspond`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"a": "ds_0192f1b27c1e7d3a9d553c0f2b8a1e44", "b": "ds_0192f1b27c1e7d3a9d553c0f2b8a1e45"}))]
pub struct MeshCorrespondRequest {
    /// Id of the first mesh dataset (one connected component): every vertex
    /// of it gets a match.
    pub a: String,
    /// Id of the second mesh dataset (one connected component), a
    /// near-isometric pose of the first.
    pub b: String,
    /// Farthest-point landmarks on each mesh (8 to 500). Default 60.
    #[serde(default = "sixty")]
    #[schema(minimum = 8, maximum = 500)]
    pub landmarks: usize,
    /// Rescale `b` to the area of `a` first (for shapes measured in other
    /// units). Default false: areas differing by more than a factor 1.2 are
    /// refused.
    #[serde(default)]
    pub scale: bool,
}

impl Operation for MeshCorrespondRequest {
    const NAME: &'static str = "mesh.correspond";

    fn validate(&self, _limits: &OpLimits) -> Result<(), OpError> {
        if !(8..=MAX_LANDMARKS).contains(&self.landmarks) {
            return Err(OpError::invalid(
                "landmarks",
                format!("must be between 8 and {MAX_LANDMARKS}"),
            ));
        }
        Ok(())
    }

    fn dataset_ids(&self) -> Vec<(String, String)> {
        vec![
            ("a".to_string(), self.a.clone()),
            ("b".to_string(), self.b.clone()),
        ]
    }

    fn run(
        &self,
        inputs: &dyn Inputs,
        limits: &OpLimits,
        control: &Control<'_>,
    ) -> Result<OpOutput, OpError> {
        self.validate(limits)?;
        let a = get_mesh(inputs, "a", &self.a)?;
        let b = get_mesh(inputs, "b", &self.b)?;
        for (field, m) in [("a", &a), ("b", &b)] {
            check_size(m.mesh.num_vertices(), Some(self.landmarks), field)?;
            check_connected(
                m,
                field,
                "a correspondence",
                "split the mesh and match component to component",
            )?;
        }
        let (area_a, area_b) = (area(&a.mesh), area(&b.mesh));
        if !(area_a > 0.0 && area_b > 0.0) {
            let field = if area_a > 0.0 { "b" } else { "a" };
            return Err(OpError::invalid(field, "the mesh has no area"));
        }
        let ratio = area_a.max(area_b) / area_a.min(area_b);
        let scaled;
        let (mesh_b, topo_b, factor) = if self.scale {
            let f = (area_a / area_b).sqrt();
            let pos = b
                .mesh
                .positions()
                .iter()
                .map(|p| p.map(|x| x * f))
                .collect();
            scaled = TriMesh::new(pos, b.mesh.faces().to_vec())
                .map_err(|e| OpError::invalid("b", format!("rescaled mesh: {e}")))?;
            (&scaled, &b.topology, f)
        } else if ratio > AREA_RATIO_LIMIT {
            return Err(OpError::invalid(
                "b",
                format!(
                    "the areas differ by a factor {ratio:.3} (a: {area_a:.6e}, b: {area_b:.6e}), more than \
                     {AREA_RATIO_LIMIT}: the shapes are not near-isometric; give \"scale\": true to rescale \
                     b to the area of a first"
                ),
            ));
        } else {
            (&b.mesh, &b.topology, 1.0)
        };
        let started = Instant::now();
        let options = CorrespondOptions {
            landmarks: self.landmarks,
            anchors: 12.min(self.landmarks),
            method: MeshMethod::FastMarching,
            ..Default::default()
        };
        let r = correspond(&a.mesh, &a.topology, mesh_b, topo_b, &options, control)
            .map_err(|e| shape_error(e, "a"))?;
        let n = a.mesh.num_vertices();
        let best = r.candidates.first();
        let second = r
            .candidates
            .iter()
            .skip(1)
            .find(|c| c.refined.is_some() && c.separation >= SEPARATION);
        let document = serde_json::json!({
            "landmarks": r.landmarks_a.len(),
            "landmarks_a": r.landmarks_a,
            "landmarks_b": r.landmarks_b,
            "symmetric": r.symmetric,
            "flipped": best.is_some_and(|c| c.determinant < 0.0),
            "distortion": best.and_then(|c| c.refined),
            "alternative_distortion": r.alternative,
            "alternative_flipped": second.map(|c| c.determinant < 0.0),
            "candidates": r.candidates.len(),
            "diameter": r.diameter,
            "confidence_scale": r.confidence_scale,
            "mean_confidence": r.confidence.iter().sum::<f64>() / n.max(1) as f64,
            "area_ratio": ratio,
            "scale_factor": factor,
            "stats": {
                "vertices_a": n,
                "vertices_b": mesh_b.num_vertices(),
                "solve_seconds": started.elapsed().as_secs_f64(),
            },
        });
        let face: Vec<i32> = r.face.iter().map(|&f| f as i32).collect();
        let vertex: Vec<i32> = r.vertex.iter().map(|&v| v as i32).collect();
        let bary = Array2::from_shape_fn((n, 3), |(i, c)| r.bary[i][c]);
        let ints = |name: &str, v: Vec<i32>| OutputArray {
            name: name.into(),
            array: ArrayData::I32(Array1::from(v).into_dyn()),
            spacing: None,
        };
        let floats = |name: &str, v: Vec<f64>| OutputArray {
            name: name.into(),
            array: ArrayData::F64(Array1::from(v).into_dyn()),
            spacing: None,
        };
        let column = |c: usize| r.bary.iter().map(|l| l[c]).collect::<Vec<f64>>();
        let arrays = vec![
            ints("face", face.clone()),
            matrix_output("bary", bary),
            ints("vertex", vertex.clone()),
            floats("confidence", r.confidence.clone()),
            // Copies carried by the mesh as vertex properties.
            ints("mesh_face", face),
            floats("mesh_bary0", column(0)),
            floats("mesh_bary1", column(1)),
            floats("mesh_bary2", column(2)),
            ints("mesh_vertex", vertex),
            floats("mesh_confidence", r.confidence),
        ];
        let mut out = OpOutput::new(arrays, document);
        out.mesh = Some(OutputMesh {
            name: "result".into(),
            mesh: Arc::new(MeshInput {
                mesh: a.mesh.clone(),
                topology: a.topology.clone(),
                report: a.report.clone(),
            }),
            vertex_properties: vec![
                ("match_face", "mesh_face"),
                ("match_bary0", "mesh_bary0"),
                ("match_bary1", "mesh_bary1"),
                ("match_bary2", "mesh_bary2"),
                ("match_vertex", "mesh_vertex"),
                ("confidence", "mesh_confidence"),
            ],
        });
        Ok(out)
    }
}

/// Total area of a mesh.
fn area(m: &TriMesh) -> f64 {
    (0..m.num_faces()).map(|f| m.face_area(f)).sum()
}
