//! The `metric` section of the mesh operations (`mesh.distance`,
//! `mesh.voronoi`, `mesh.paths`): a cost designed on the surface (from its
//! curvature or from a per-vertex field) or an anisotropic metric (one
//! tensor per face, from the curvature tensor or given), the surface
//! counterpart of the grids' `design` and `tensor` sections.
//!
//! The formulas are those of [`crate::numerics::mesh::design`] and
//! [`crate::numerics::mesh::curvature`]; face tensors run with
//! `fast_marching` only ([`crate::numerics::mesh::fast_marching`]).

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::mesh::{read_weights, MeshInput, MeshMethodSpec};
use crate::numerics::mesh::curvature::face_tensors_from_curvature;
use crate::numerics::mesh::design::{design, CurvatureFeature, FieldMode, MeshDesign};
use crate::numerics::mesh::fast_marching::{check_tensors, Metric};
use crate::numerics::mesh::MeshSolveError;
use crate::numerics::Control;
use crate::ops::{Inputs, OpError};

/// The metric on the surface. Exclusive with `weights`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum SurfaceMetricSpec {
    /// `W = 1/(ε + g^p)` with `g` the normalised ridge, valley or bend
    /// strength from the principal curvatures: paths follow crests.
    Curvature(CurvatureDesignSpec),
    /// `W` from a per-vertex field (texture, scalar function): cheap at a
    /// value, along its edges, or expensive across them.
    Field(FieldDesignSpec),
    /// Anisotropic: a tensor per face from the curvature tensor, lengths
    /// across strong curvature up to `max_ratio` times those along it
    /// (`fast_marching` only).
    CurvatureTensors(CurvatureTensorsSpec),
    /// Anisotropic: given tensors, one per face or one for all
    /// (`fast_marching` only).
    Tensors(TensorsSpec),
}

/// Which bends a curvature design makes cheap.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum CurvatureFeatureSpec {
    /// Convex creases (`κ₁ > 0` with outward normals).
    Ridges,
    /// Concave creases (`κ₂ < 0`).
    Valleys,
    /// Either (`max(|κ₁|, |κ₂|)`; needs no consistent orientation).
    #[default]
    Both,
}

/// Parameters of the curvature design.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct CurvatureDesignSpec {
    /// Ridges, valleys or both. Default: `both`.
    #[serde(default)]
    pub feature: CurvatureFeatureSpec,
    /// `ε > 0`: the cost ranges over `[1/(1 + ε), 1/ε]`. Default: 0.01.
    #[serde(default = "eps")]
    #[schema(exclusive_minimum = 0.0)]
    pub epsilon: f64,
    /// Exponent `p > 0`. Default: 1.
    #[serde(default = "one")]
    #[schema(exclusive_minimum = 0.0)]
    pub power: f64,
    /// Passes of one-ring smoothing of the curvature tensor (noisy scans
    /// want 2-4). Default: 1.
    #[serde(default = "one_pass")]
    #[schema(maximum = 1024)]
    pub smoothing: usize,
}

/// How a field design reads its field.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum FieldModeSpec {
    /// `W = |f − c|^p + ε` (normalised field), cheap at the value `reference`.
    Value,
    /// `W = 1/(ε + g^p)`, `g` the normalised surface gradient: along edges.
    #[default]
    Follow,
    /// `W = ε + g^p`: crossing an edge of the field is expensive.
    Barrier,
}

/// Parameters of the field design.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct FieldDesignSpec {
    /// Id of an array dataset with one finite value per vertex.
    pub field: String,
    /// How the field is read. Default: `follow`.
    #[serde(default)]
    pub mode: FieldModeSpec,
    /// With `value`: the cheapest value, in the field's units (required).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reference: Option<f64>,
    /// `ε > 0`. Default: 0.01.
    #[serde(default = "eps")]
    #[schema(exclusive_minimum = 0.0)]
    pub epsilon: f64,
    /// Exponent `p > 0`. Default: 1.
    #[serde(default = "one")]
    #[schema(exclusive_minimum = 0.0)]
    pub power: f64,
}

/// Parameters of the curvature tensors.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct CurvatureTensorsSpec {
    /// Largest ratio of lengths across and along, `1 ..= 100`. Default: 10.
    #[serde(default = "ten")]
    #[schema(minimum = 1.0, maximum = 100.0)]
    pub max_ratio: f64,
}

/// Given face tensors: exactly one of `dataset` and `constant`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct TensorsSpec {
    /// Id of an array dataset of shape `[faces, 3, 3]` (symmetric) or
    /// `[faces, 6]` (`xx, xy, xz, yy, yz, zz`): tensors of space, used on
    /// each face's plane, where they must be positive definite.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dataset: Option<String>,
    /// One symmetric 3×3 tensor for every face.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub constant: Option<[[f64; 3]; 3]>,
}

fn eps() -> f64 {
    0.01
}
fn one() -> f64 {
    1.0
}
fn one_pass() -> usize {
    1
}
fn ten() -> f64 {
    10.0
}

/// The metric a mesh solve runs under.
#[derive(Debug, Clone, Default)]
pub(crate) struct ResolvedMeshMetric {
    /// Per-vertex weights (`weights` or a design).
    pub weights: Option<Vec<f64>>,
    /// Per-face tensors.
    pub tensors: Option<Vec<[f64; 6]>>,
}

impl ResolvedMeshMetric {
    /// As the march's [`Metric`]: the tensors if any, else the weights.
    pub fn metric(&self) -> Metric<'_> {
        match &self.tensors {
            Some(t) => Metric::Faces(t),
            None => Metric::Weights(self.weights.as_deref()),
        }
    }
}

impl SurfaceMetricSpec {
    /// True for the anisotropic kinds.
    pub fn is_anisotropic(&self) -> bool {
        matches!(self, Self::CurvatureTensors(_) | Self::Tensors(_))
    }

    /// `(field, dataset id)` of the datasets it reads, fields under `metric`.
    pub fn dataset_ids(&self) -> Vec<(String, String)> {
        match self {
            Self::Field(f) => vec![("metric.field".into(), f.field.clone())],
            Self::Tensors(TensorsSpec {
                dataset: Some(id), ..
            }) => vec![("metric.dataset".into(), id.clone())],
            _ => Vec::new(),
        }
    }
}

/// The `(field, dataset id)` pairs of a mesh request: `mesh`, then
/// `weights` and the datasets its `metric` reads.
pub(crate) fn mesh_dataset_ids(
    mesh: &str,
    weights: Option<&str>,
    metric: Option<&SurfaceMetricSpec>,
) -> Vec<(String, String)> {
    let mut ids = vec![("mesh".to_string(), mesh.to_string())];
    if let Some(w) = weights {
        ids.push(("weights".into(), w.to_string()));
    }
    if let Some(m) = metric {
        ids.extend(m.dataset_ids());
    }
    ids
}

/// Checks the shape of `weights`/`metric` against the method, before any
/// dataset is read.
pub(crate) fn validate_metric(
    weights: Option<&str>,
    metric: Option<&SurfaceMetricSpec>,
    method: MeshMethodSpec,
) -> Result<(), OpError> {
    let Some(metric) = metric else {
        return Ok(());
    };
    if weights.is_some() {
        return Err(OpError::invalid(
            "metric",
            "give `weights` or `metric`, not both (a design replaces the weights)",
        ));
    }
    let weighted = matches!(
        method,
        MeshMethodSpec::FastMarching | MeshMethodSpec::Dijkstra
    );
    if metric.is_anisotropic() && method != MeshMethodSpec::FastMarching {
        return Err(OpError::invalid(
            "metric",
            "face tensors (an anisotropic metric) run with `method: fast_marching` only",
        ));
    }
    if !weighted {
        return Err(OpError::invalid(
            "metric",
            "a designed metric runs with `method: fast_marching` or `dijkstra`",
        ));
    }
    match metric {
        SurfaceMetricSpec::Curvature(c) => {
            positive("metric.epsilon", c.epsilon)?;
            positive("metric.power", c.power)?;
            if c.smoothing > crate::numerics::mesh::curvature::MAX_SMOOTHING {
                return Err(OpError::invalid("metric.smoothing", "at most 1024 passes"));
            }
        }
        SurfaceMetricSpec::Field(f) => {
            positive("metric.epsilon", f.epsilon)?;
            positive("metric.power", f.power)?;
            match (f.mode, f.reference) {
                (FieldModeSpec::Value, None) => {
                    return Err(OpError::invalid(
                        "metric.reference",
                        "`mode: value` needs the cheapest value as `reference`",
                    ))
                }
                (FieldModeSpec::Value, Some(r)) if !r.is_finite() => {
                    return Err(OpError::invalid("metric.reference", "must be finite"))
                }
                _ => {}
            }
        }
        SurfaceMetricSpec::CurvatureTensors(c) => {
            if !(c.max_ratio.is_finite() && (1.0..=100.0).contains(&c.max_ratio)) {
                return Err(OpError::invalid(
                    "metric.max_ratio",
                    "must be finite, >= 1 and <= 100",
                ));
            }
        }
        SurfaceMetricSpec::Tensors(t) => match (&t.dataset, &t.constant) {
            (Some(_), None) => {}
            (None, Some(m)) => {
                if m.iter().flatten().any(|x| !x.is_finite()) {
                    return Err(OpError::invalid(
                        "metric.constant",
                        "entries must be finite",
                    ));
                }
                if !symmetric(m) {
                    return Err(OpError::invalid("metric.constant", "must be symmetric"));
                }
            }
            _ => {
                return Err(OpError::invalid(
                    "metric",
                    "give exactly one of `dataset` and `constant`",
                ))
            }
        },
    }
    Ok(())
}

fn positive(field: &str, x: f64) -> Result<(), OpError> {
    if x.is_finite() && x > 0.0 {
        Ok(())
    } else {
        Err(OpError::invalid(field, "must be finite and > 0"))
    }
}

fn symmetric(m: &[[f64; 3]; 3]) -> bool {
    let scale = m.iter().flatten().map(|x| x.abs()).fold(0.0, f64::max);
    (0..3).all(|i| (0..3).all(|j| (m[i][j] - m[j][i]).abs() <= 1e-9 * scale))
}

fn packed(m: &[[f64; 3]; 3]) -> [f64; 6] {
    [m[0][0], m[0][1], m[0][2], m[1][1], m[1][2], m[2][2]]
}

/// Reads `weights` or builds `metric` on the mesh (after
/// [`validate_metric`]).
pub(crate) fn resolve_metric(
    inputs: &dyn Inputs,
    input: &MeshInput,
    weights: Option<&str>,
    metric: Option<&SurfaceMetricSpec>,
    control: &Control<'_>,
) -> Result<ResolvedMeshMetric, OpError> {
    let mesh = &input.mesh;
    let n = mesh.num_vertices();
    let design_error = |e: MeshSolveError| match e {
        MeshSolveError::Cancelled => OpError::Cancelled,
        MeshSolveError::InvalidOption { option, reason } => {
            OpError::invalid(format!("metric.{option}"), reason)
        }
        other => OpError::invalid("metric", other.to_string()),
    };
    let Some(metric) = metric else {
        return Ok(ResolvedMeshMetric {
            weights: match weights {
                Some(id) => Some(read_weights(inputs, id, n)?),
                None => None,
            },
            tensors: None,
        });
    };
    match metric {
        SurfaceMetricSpec::Curvature(c) => {
            let d = MeshDesign::Curvature {
                feature: match c.feature {
                    CurvatureFeatureSpec::Ridges => CurvatureFeature::Ridges,
                    CurvatureFeatureSpec::Valleys => CurvatureFeature::Valleys,
                    CurvatureFeatureSpec::Both => CurvatureFeature::Both,
                },
                epsilon: c.epsilon,
                power: c.power,
                smoothing: c.smoothing,
            };
            let w = design(mesh, &input.topology, &d, control).map_err(design_error)?;
            Ok(ResolvedMeshMetric {
                weights: Some(w),
                tensors: None,
            })
        }
        SurfaceMetricSpec::Field(f) => {
            let a = inputs
                .get(&f.field)
                .ok_or_else(|| OpError::UnknownDataset {
                    field: "metric.field".into(),
                    id: f.field.clone(),
                })?;
            if a.array.len() != n {
                return Err(OpError::invalid(
                    "metric.field",
                    format!("{} values for {n} vertices", a.array.len()),
                ));
            }
            let values: Vec<f64> = (0..n)
                .map(|i| a.array.get_f64(i).unwrap_or(f64::NAN))
                .collect();
            let mode = match f.mode {
                FieldModeSpec::Value => FieldMode::Value {
                    reference: f.reference.unwrap_or(f64::NAN),
                },
                FieldModeSpec::Follow => FieldMode::Follow,
                FieldModeSpec::Barrier => FieldMode::Barrier,
            };
            let d = MeshDesign::Field {
                values: &values,
                mode,
                epsilon: f.epsilon,
                power: f.power,
            };
            let w = design(mesh, &input.topology, &d, control).map_err(design_error)?;
            Ok(ResolvedMeshMetric {
                weights: Some(w),
                tensors: None,
            })
        }
        SurfaceMetricSpec::CurvatureTensors(c) => Ok(ResolvedMeshMetric {
            weights: None,
            tensors: Some(face_tensors_from_curvature(
                mesh,
                &input.topology,
                c.max_ratio,
            )),
        }),
        SurfaceMetricSpec::Tensors(t) => {
            let nf = mesh.num_faces();
            let tensors: Vec<[f64; 6]> = match (&t.dataset, &t.constant) {
                (_, Some(m)) => vec![packed(m); nf],
                (Some(id), None) => {
                    let field = "metric.dataset";
                    let a = inputs.get(id).ok_or_else(|| OpError::UnknownDataset {
                        field: field.into(),
                        id: id.clone(),
                    })?;
                    let shape = a.array.shape().to_vec();
                    let at = |i: usize| a.array.get_f64(i).unwrap_or(f64::NAN);
                    match shape.as_slice() {
                        [f, 3, 3] if *f == nf => {
                            let mut out = Vec::with_capacity(nf);
                            for face in 0..nf {
                                let m: [[f64; 3]; 3] = std::array::from_fn(|i| {
                                    std::array::from_fn(|j| at(9 * face + 3 * i + j))
                                });
                                if !symmetric(&m) {
                                    return Err(OpError::invalid(
                                        field,
                                        format!("the tensor of face {face} is not symmetric"),
                                    ));
                                }
                                out.push(packed(&m));
                            }
                            out
                        }
                        [f, 6] if *f == nf => (0..nf)
                            .map(|face| std::array::from_fn(|k| at(6 * face + k)))
                            .collect(),
                        _ => {
                            return Err(OpError::invalid(
                                field,
                                format!(
                                    "shape {shape:?}: expected [{nf}, 3, 3] or [{nf}, 6] \
                                     (one tensor per face)"
                                ),
                            ))
                        }
                    }
                }
                (None, None) => {
                    return Err(OpError::invalid(
                        "metric",
                        "give exactly one of `dataset` and `constant`",
                    ))
                }
            };
            let field = if t.constant.is_some() {
                "metric.constant"
            } else {
                "metric.dataset"
            };
            check_tensors(mesh, &tensors).map_err(|e| match e {
                MeshSolveError::InvalidOption { reason, .. } => OpError::invalid(field, reason),
                other => OpError::invalid(field, other.to_string()),
            })?;
            Ok(ResolvedMeshMetric {
                weights: None,
                tensors: Some(tensors),
            })
        }
    }
}
