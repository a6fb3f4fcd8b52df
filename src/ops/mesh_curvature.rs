//! `mesh.curvature`: principal curvatures and directions, mean and
//! Gaussian curvature of every vertex of a mesh
//! ([`crate::numerics::mesh::curvature`]).

use std::time::Instant;

use ndarray::ArrayD;
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::spec::errors::mesh_solve_error;
use super::spec::mesh::get_mesh;
use super::{Inputs, OpError, OpLimits, OpOutput, Operation, OutputArray, OutputMesh};
use crate::io::ArrayData;
use crate::numerics::mesh::curvature::{curvature, MAX_SMOOTHING};
use crate::numerics::Control;

/// Request of `mesh.curvature` (`POST /v1/mesh/curvature`, job operation
/// `mesh.curvature`, `geodex mesh-curvature`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"mesh": "ds_0192f1b27c1e7d3a9d553c0f2b8a1e44", "smoothing": 2}))]
pub struct MeshCurvatureRequest {
    /// Id of the mesh dataset.
    pub mesh: String,
    /// Passes of one-ring smoothing of the curvature tensor, `0 ..= 1024`
    /// (noisy scans want 2-4). Default: 1.
    #[serde(default = "one")]
    #[schema(maximum = 1024)]
    pub smoothing: usize,
}

fn one() -> usize {
    1
}

/// Summary of one per-vertex quantity over the vertices used by faces.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct CurvatureStats {
    /// Smallest value.
    pub min: f64,
    /// Median.
    pub median: f64,
    /// Largest value.
    pub max: f64,
}

impl CurvatureStats {
    fn of(values: impl Iterator<Item = f64>) -> Option<Self> {
        let mut v: Vec<f64> = values.collect();
        if v.is_empty() {
            return None;
        }
        v.sort_by(f64::total_cmp);
        Some(Self {
            min: v[0],
            median: v[v.len() / 2],
            max: v[v.len() - 1],
        })
    }
}

impl Operation for MeshCurvatureRequest {
    const NAME: &'static str = "mesh.curvature";

    fn validate(&self, _limits: &OpLimits) -> Result<(), OpError> {
        if self.smoothing > MAX_SMOOTHING {
            return Err(OpError::invalid(
                "smoothing",
                format!("at most {MAX_SMOOTHING} passes"),
            ));
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
        let started = Instant::now();
        let c = curvature(&input.mesh, &input.topology, self.smoothing, control)
            .map_err(mesh_solve_error)?;
        let n = c.len();
        let used: Vec<bool> = (0..n)
            .map(|v| !input.topology.faces_of(v as u32).is_empty())
            .collect();
        let column = |f: &dyn Fn(usize) -> f64| -> Vec<f64> { (0..n).map(f).collect() };
        let k1 = column(&|v| c[v].k1);
        let k2 = column(&|v| c[v].k2);
        let mean = column(&|v| c[v].mean_curvature());
        let gaussian = column(&|v| c[v].gauss_curvature());
        let stats = |x: &[f64]| {
            CurvatureStats::of(x.iter().zip(&used).filter(|(_, &u)| u).map(|(&v, _)| v))
        };
        let document = serde_json::json!({
            "smoothing": self.smoothing,
            "vertices": n,
            "stats": {
                "k1": stats(&k1),
                "k2": stats(&k2),
                "mean": stats(&mean),
                "gaussian": stats(&gaussian),
            },
            "seconds": started.elapsed().as_secs_f64(),
        });
        let vector = |d: &dyn Fn(usize) -> [f64; 3]| {
            ArrayD::from_shape_vec(vec![n, 3], (0..n).flat_map(d).collect())
        };
        let mut arrays = Vec::new();
        for (name, values) in [
            ("k1", k1),
            ("k2", k2),
            ("mean_curvature", mean),
            ("gaussian_curvature", gaussian),
        ] {
            if let Ok(a) = ArrayD::from_shape_vec(vec![n], values) {
                arrays.push(OutputArray {
                    name: name.into(),
                    array: ArrayData::F64(a),
                    spacing: None,
                });
            }
        }
        for (name, a) in [
            ("d1", vector(&|v| c[v].d1)),
            ("d2", vector(&|v| c[v].d2)),
            ("normal", vector(&|v| c[v].normal)),
        ] {
            if let Ok(a) = a {
                arrays.push(OutputArray {
                    name: name.into(),
                    array: ArrayData::F64(a),
                    spacing: None,
                });
            }
        }
        let mut out = OpOutput::new(arrays, document);
        out.mesh = Some(OutputMesh {
            name: "result".into(),
            mesh: input,
            // A stored mesh carries one float property, `value`: the mean
            // curvature (what viewers colour by).
            vertex_properties: vec![("value", "mean_curvature")],
        });
        Ok(out)
    }
}
