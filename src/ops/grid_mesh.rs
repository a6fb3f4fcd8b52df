//! `grid.mesh`: image meshing (see [`crate::numerics::meshing::image`]): a
//! metric from the image, farthest-point sampling, the conforming geodesic
//! Delaunay triangulation, the piecewise-linear approximation of the image
//! and its L2 error, side by side with a uniform mesh of the same vertex
//! count. The mesh is a new mesh dataset (index coordinates, `z = 0`) with
//! the image value per vertex.

use std::sync::Arc;
use std::time::Instant;

use ndarray::ArrayD;
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::spec::design::array_to_f64;
use super::spec::errors::grid_error;
use super::spec::grid::check_shape;
use super::spec::mesh::MeshInput;
use super::{Inputs, OpError, OpLimits, OpOutput, Operation, OutputArray, OutputMesh};
use crate::io::mesh::report_of;
use crate::io::mesh_picture::mesh_picture;
use crate::io::ArrayData;
use crate::numerics::mesh::{Topology, TriMesh};
use crate::numerics::meshing::{
    mesh_image, ImageMesh, ImageMeshOptions, ImageMetric, MeshingError,
};
use crate::numerics::{Control, Grid};

/// The metric the vertices follow.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum MeshMetricSpec {
    /// `W = 1`: uniform vertices.
    Uniform,
    /// `W = 1 + strength · |∇(G_σ * f)| / max`: vertices along edges.
    #[default]
    Gradient,
    /// `W = 1 + strength · ‖Hessian(G_σ * f)‖ / max`: vertices where the image bends.
    Hessian,
    /// Anisotropic: `M = det(|H|)^(-1/6) |H|`, the L2-optimal metric of the
    /// absolute Hessian of `G_σ * f` with its eigenvalues at least
    /// `max |λ| / strength` and element length-to-width ratios at most
    /// `anisotropy`: long thin triangles along edges and ridges.
    AnisotropicHessian,
    /// Anisotropic: `M = Id + strength · J / max`, `J` the structure tensor
    /// (noise scale `sigma`, integration scale `rho`), length-to-width
    /// ratios at most `anisotropy`.
    StructureTensor,
    /// Anisotropic with the `gradient` metric's vertex density:
    /// `M = W² R diag(a, 1/a) Rᵀ`, `W` the gradient metric, `R` the
    /// structure tensor's eigenvectors (integration scale `rho`) and
    /// `a = 1 + (anisotropy − 1) · coherence`: elements up to `anisotropy`
    /// times longer than wide along coherent edges, isotropic elsewhere.
    EdgeTensor,
}

/// Request of `grid.mesh` (`POST /v1/grid/mesh`, `geodex mesh`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"dataset": "ds_0192f1b27c1e7d3a9d553c0f2b8a1e45", "count": 2000, "metric": "hessian"}))]
pub struct GridMeshRequest {
    /// Id of the 2D image to mesh.
    pub dataset: String,
    /// Target number of vertices (at least 4, at most the number of cells).
    #[schema(minimum = 4)]
    pub count: usize,
    /// The metric. Default: `gradient`.
    #[serde(default)]
    pub metric: MeshMetricSpec,
    /// Smoothing scale `σ` of the derivatives (physical units). Default 1.
    #[serde(default = "one")]
    #[schema(minimum = 0.0)]
    pub sigma: f64,
    /// Contrast of the metric: `W` ranges over `[1, 1 + strength]`
    /// (`gradient`, `hessian`, `structure_tensor`); for
    /// `anisotropic_hessian` the ratio of the largest `|λ|` of the Hessian to
    /// the floor of every `|λ|` (at least 1). Default 8.
    #[serde(default = "eight")]
    #[schema(minimum = 0.0)]
    pub strength: f64,
    /// Anisotropic metrics: the largest ratio of an element's length to its
    /// width (at least 1). Default 8 (`anisotropic_hessian`,
    /// `structure_tensor`), 1.5 (`edge_tensor`: 2 lowers the error further
    /// on a photograph at 500 vertices and more, but higher ratios fold the
    /// dual where edges turn, and the repair then adds many vertices).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(minimum = 1.0)]
    pub anisotropy: Option<f64>,
    /// `structure_tensor`, `edge_tensor`: the integration scale `ρ` (physical units). Default 2.
    #[serde(default = "two")]
    #[schema(minimum = 0.0)]
    pub rho: f64,
    /// After the geodesic Delaunay dual, flip edges while that lowers the
    /// L2 error of the interpolation (a data-dependent triangulation of the
    /// same vertices; the uniform comparison mesh gets the same). Default false.
    #[serde(default)]
    pub flips: bool,
    /// After the dual, move vertices (to nearby grid cells) and flip edges
    /// while that lowers the L2 error: the same vertex count, placed by the
    /// image itself; implies `flips`; the uniform comparison mesh gets the
    /// same. Slower (seconds on a 512² image). Default false.
    #[serde(default)]
    pub moves: bool,
    /// Also mesh uniformly with the same vertex count and report its error. Default true.
    #[serde(default = "yes")]
    pub compare_uniform: bool,
    /// Physical size of a cell per axis. Default: the dataset's spacing, else 1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(min_items = 2, max_items = 2)]
    pub spacing: Option<Vec<f64>>,
}

fn one() -> f64 {
    1.0
}

fn eight() -> f64 {
    8.0
}

fn two() -> f64 {
    2.0
}

fn yes() -> bool {
    true
}

impl GridMeshRequest {
    /// `anisotropy`, or the metric's default.
    fn anisotropy(&self) -> f64 {
        self.anisotropy.unwrap_or(match self.metric {
            MeshMetricSpec::EdgeTensor => 1.5,
            _ => 8.0,
        })
    }

    fn metric(&self) -> ImageMetric {
        let (sigma, strength) = (self.sigma, self.strength);
        match self.metric {
            MeshMetricSpec::Uniform => ImageMetric::Uniform,
            MeshMetricSpec::Gradient => ImageMetric::Gradient { sigma, strength },
            MeshMetricSpec::Hessian => ImageMetric::Hessian { sigma, strength },
            MeshMetricSpec::AnisotropicHessian => ImageMetric::HessianTensor {
                sigma,
                strength,
                anisotropy: self.anisotropy(),
            },
            MeshMetricSpec::StructureTensor => ImageMetric::StructureTensor {
                sigma,
                rho: self.rho,
                strength,
                anisotropy: self.anisotropy(),
            },
            MeshMetricSpec::EdgeTensor => ImageMetric::EdgeTensor {
                sigma,
                rho: self.rho,
                strength,
                anisotropy: self.anisotropy(),
            },
        }
    }
}

impl Operation for GridMeshRequest {
    const NAME: &'static str = "grid.mesh";

    fn validate(&self, limits: &OpLimits) -> Result<(), OpError> {
        if self.count < 4 {
            return Err(OpError::invalid(
                "count",
                "must be >= 4 (the corners are vertices)",
            ));
        }
        if self.count > limits.max_sources {
            return Err(OpError::TooLarge {
                field: "count".into(),
                reason: format!("more than {} vertices", limits.max_sources),
            });
        }
        if !(self.sigma.is_finite() && self.sigma >= 0.0) {
            return Err(OpError::invalid("sigma", "must be finite and >= 0"));
        }
        if !(self.strength.is_finite() && self.strength >= 0.0) {
            return Err(OpError::invalid("strength", "must be finite and >= 0"));
        }
        if self.metric == MeshMetricSpec::AnisotropicHessian && self.strength < 1.0 {
            return Err(OpError::invalid(
                "strength",
                "must be >= 1 for `anisotropic_hessian` (the ratio of the largest |λ| to the floor)",
            ));
        }
        if !(self.anisotropy().is_finite() && self.anisotropy() >= 1.0) {
            return Err(OpError::invalid("anisotropy", "must be finite and >= 1"));
        }
        if !(self.rho.is_finite() && self.rho >= 0.0) {
            return Err(OpError::invalid("rho", "must be finite and >= 0"));
        }
        if let Some(spacing) = &self.spacing {
            if spacing.len() != 2 {
                return Err(OpError::invalid(
                    "spacing",
                    "an image has two axes: give two spacings",
                ));
            }
            if let Some(k) = spacing.iter().position(|h| !(h.is_finite() && *h > 0.0)) {
                return Err(OpError::invalid(
                    format!("spacing[{k}]"),
                    "must be finite and > 0",
                ));
            }
        }
        Ok(())
    }

    fn dataset_ids(&self) -> Vec<(String, String)> {
        vec![("dataset".into(), self.dataset.clone())]
    }

    /// Arrays: `approximation` (f64, the piecewise-linear image), `cost`
    /// (f64, the metric `W`), `vertices` (f64, `nv × 2`, index coordinates),
    /// `triangles` (int32, `nt × 3`), `values` (f64 per vertex, on the mesh
    /// as the `value` property), `picture` (u8 RGB, the mesh drawn over the
    /// image, see [`crate::io::mesh_picture`]). Mesh: `mesh` (what a job's result lacks:
    /// it has `vertices` and `triangles`). Document: `{"stats": {...}}`.
    fn run(
        &self,
        inputs: &dyn Inputs,
        limits: &OpLimits,
        control: &Control<'_>,
    ) -> Result<OpOutput, OpError> {
        self.validate(limits)?;
        let input = inputs
            .get(&self.dataset)
            .ok_or_else(|| OpError::UnknownDataset {
                field: "dataset".into(),
                id: self.dataset.clone(),
            })?;
        let shape = input.array.shape().to_vec();
        check_shape(&shape, "dataset", limits)?;
        if shape.len() != 2 {
            return Err(OpError::invalid(
                "dataset",
                format!("an image has 2 axes; this array has shape {shape:?}"),
            ));
        }
        let cells: usize = shape.iter().product();
        if self.count > cells {
            return Err(OpError::invalid(
                "count",
                format!(
                    "{} is larger than the number of cells ({cells})",
                    self.count
                ),
            ));
        }
        let spacing = self
            .spacing
            .clone()
            .or_else(|| input.spacing.clone())
            .unwrap_or_else(|| vec![1.0; 2]);
        let grid = Grid::new(&shape, &spacing).map_err(|e| grid_error(e, &shape))?;
        let image = array_to_f64(&input.array);
        let started = Instant::now();
        let run = |metric| {
            mesh_image(
                &grid,
                &image,
                &ImageMeshOptions {
                    count: self.count,
                    metric,
                    flips: self.flips,
                    moves: self.moves,
                },
                control,
            )
            .map_err(meshing_error)
        };
        let mesh = run(self.metric())?;
        let seconds = started.elapsed().as_secs_f64();
        let uniform = match (self.compare_uniform, self.metric) {
            (true, MeshMetricSpec::Uniform) | (false, _) => None,
            (true, _) => Some(run(ImageMetric::Uniform)?),
        };
        let summary = |m: &ImageMesh| {
            serde_json::json!({
                "vertices": m.points.len(),
                "triangles": m.triangles.len(),
                "l2_error": m.l2_error,
                "added": m.added,
                "flips": m.flips,
                "moves": m.moves,
            })
        };
        let mut stats = serde_json::json!({
            "vertices": mesh.points.len(),
            "triangles": mesh.triangles.len(),
            "l2_error": mesh.l2_error,
            "added": mesh.added,
            "repaired": {
                "double_contact": mesh.repaired.double_contact,
                "split_cell": mesh.repaired.split_cell,
                "missing_triangle": mesh.repaired.missing_triangle,
                "invalid": mesh.repaired.invalid,
                "boundary": mesh.repaired.boundary,
            },
            "covering_radius": mesh.covering_radius,
            "flips": mesh.flips,
            "moves": mesh.moves,
            "seconds": seconds,
        });
        if let Some(u) = &uniform {
            stats["uniform"] = summary(u);
            stats["error_ratio"] = serde_json::json!(mesh.l2_error / u.l2_error);
        }
        let tri = TriMesh::new(
            mesh.points.iter().map(|p| [p[0], p[1], 0.0]).collect(),
            mesh.triangles.clone(),
        )
        .map_err(|e| OpError::invalid("dataset", e.to_string()))?;
        let picture = mesh_picture(&image, shape[0], shape[1], &mesh.points, &mesh.triangles)
            .map_err(|e| OpError::invalid("dataset", e.to_string()))?;
        let topology = Topology::new(&tri);
        let report = report_of(&tri, &topology);
        let nv = mesh.points.len();
        let shaped = |v: Vec<f64>, s: Vec<usize>| {
            ArrayD::from_shape_vec(s, v)
                .map(ArrayData::F64)
                .map_err(|e| OpError::invalid("dataset", e.to_string()))
        };
        let mut out = OpOutput::new(
            vec![
                OutputArray {
                    name: "approximation".into(),
                    array: shaped(mesh.approximation, shape.clone())?,
                    spacing: Some(spacing.clone()),
                },
                OutputArray {
                    name: "cost".into(),
                    array: shaped(mesh.cost, shape)?,
                    spacing: Some(spacing),
                },
                OutputArray {
                    name: "vertices".into(),
                    array: shaped(mesh.points.iter().flatten().copied().collect(), vec![nv, 2])?,
                    spacing: None,
                },
                OutputArray {
                    name: "triangles".into(),
                    array: ArrayData::I32(
                        ArrayD::from_shape_vec(
                            vec![mesh.triangles.len(), 3],
                            mesh.triangles.iter().flatten().map(|&v| v as i32).collect(),
                        )
                        .map_err(|e| OpError::invalid("dataset", e.to_string()))?,
                    ),
                    spacing: None,
                },
                OutputArray {
                    name: "values".into(),
                    array: shaped(mesh.values, vec![nv])?,
                    spacing: None,
                },
                OutputArray {
                    name: "picture".into(),
                    array: picture,
                    spacing: None,
                },
            ],
            serde_json::json!({ "stats": stats }),
        );
        out.mesh = Some(OutputMesh {
            name: "mesh".into(),
            mesh: Arc::new(MeshInput {
                mesh: tri,
                topology,
                report,
            }),
            vertex_properties: vec![("value", "values")],
        });
        Ok(out)
    }
}

/// A meshing error as an [`OpError`] naming the request field.
fn meshing_error(e: MeshingError) -> OpError {
    match e {
        MeshingError::Cancelled
        | MeshingError::Sampling(crate::numerics::sampling::SamplingError::Cancelled)
        | MeshingError::Delaunay(crate::numerics::sampling::delaunay::DelaunayError::Cancelled) => {
            OpError::Cancelled
        }
        MeshingError::Count { .. } => OpError::invalid("count", e.to_string()),
        MeshingError::Metric(_) => OpError::invalid("metric", e.to_string()),
        MeshingError::Delaunay(_) => OpError::invalid(
            "count",
            format!("{e}: raise `count`, or lower `strength` or `anisotropy`"),
        ),
        MeshingError::NotPlanar(_) | MeshingError::Image(_) | MeshingError::Sampling(_) => {
            OpError::invalid("dataset", e.to_string())
        }
    }
}
