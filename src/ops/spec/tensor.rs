//! The `tensor` section of the anisotropic operations: how a client gives a
//! Riemannian metric `M(x)` (a dataset of components, a constant, an eigen
//! decomposition, energy and anisotropy, or a design from an image or a
//! height map), and how it becomes a validated [`TensorField`].

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use std::time::Instant;

use super::errors::eikonal_error;
use super::grid::{check_shape, fetch};
use crate::numerics::anisotropic::height_map::height_map_metric;
use crate::numerics::anisotropic::structure_tensor::edge_metric;
use crate::numerics::anisotropic::{
    components, eigen_tensor, energy_anisotropy, solve, TensorError, TensorField, TensorOptions,
    TensorOutput, TensorProblem, TensorSolveError,
};
use crate::numerics::{Control, EikonalError, Grid, GridError, Order, Source, StopRules};
use crate::ops::{Inputs, OpError, OpLimits};

/// The metric tensor field `M(x)` (symmetric positive definite; a
/// displacement `v` costs `sqrt(vᵀ M v)`). Components are in array index
/// order (axis 0 first), upper triangle row by row: `[m00, m01, m11]` in 2D,
/// `[m00, m01, m02, m11, m12, m22]` in 3D.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum TensorSpec {
    /// A dataset of shape `(n0, n1, 3)` (2D) or `(n0, n1, n2, 6)` (3D).
    Components(ComponentsTensor),
    /// The same tensor on every cell of `shape`.
    Constant(ConstantTensor),
    /// `λ1 e1e1ᵀ + λ2 (Id − e1e1ᵀ)` on every cell (seed eq. 1.16).
    Eigen(EigenTensor),
    /// 2D: energy `W` and anisotropy `A` (seed eq. 1.17), `e1` at `angle`;
    /// each a number or a dataset id.
    EnergyAnisotropy(EnergyAnisotropyTensor),
    /// The edge-following metric of an image's structure tensor (seed 1.3.3).
    StructureTensor(StructureTensorSpec),
    /// `W² (Id + ∇h∇hᵀ)`: geodesics on the terrain `z = h(x)` (seed eq. 1.10).
    HeightMap(HeightMapSpec),
}

/// Components from a dataset.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct ComponentsTensor {
    /// Id of a dataset with a trailing component axis of 3 (2D) or 6 (3D).
    pub dataset: String,
}

/// A constant tensor.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct ConstantTensor {
    /// Grid shape (2 or 3 axes).
    #[schema(min_items = 2, max_items = 3)]
    pub shape: Vec<usize>,
    /// 3 (2D) or 6 (3D) components.
    #[schema(min_items = 3, max_items = 6)]
    pub components: Vec<f64>,
}

/// A constant tensor from its eigen-decomposition.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct EigenTensor {
    /// Grid shape (2 or 3 axes).
    #[schema(min_items = 2, max_items = 3)]
    pub shape: Vec<usize>,
    /// `[λ1, λ2]`, both > 0: `λ1` along `e1`, `λ2` on its orthogonal complement.
    #[schema(min_items = 2, max_items = 2)]
    pub eigenvalues: Vec<f64>,
    /// The direction of `e1` (array index order; normalised).
    #[schema(min_items = 2, max_items = 3)]
    pub direction: Vec<f64>,
}

/// A number on every cell, or the id of a dataset with one value per cell.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(untagged)]
pub enum ScalarField {
    /// The same value everywhere.
    Value(f64),
    /// A dataset id.
    Dataset(String),
}

/// 2D metric of energy `W` and anisotropy `A`: eigenvalues `W²(1 − A)`
/// along `e1 = (cos θ, sin θ)` (θ from axis 0 towards axis 1) and `W²(1 + A)` across.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct EnergyAnisotropyTensor {
    /// Grid shape; optional when a field is a dataset (its shape is used).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(min_items = 2, max_items = 2)]
    pub shape: Option<Vec<usize>>,
    /// `W > 0`. Default 1.
    #[serde(default = "one")]
    pub energy: ScalarField,
    /// `A ∈ [0, 1)`.
    pub anisotropy: ScalarField,
    /// θ in radians. Default 0.
    #[serde(default = "zero")]
    pub angle: ScalarField,
}

fn one() -> ScalarField {
    ScalarField::Value(1.0)
}

fn zero() -> ScalarField {
    ScalarField::Value(0.0)
}

fn default_sigma() -> f64 {
    1.0
}

fn default_rho() -> f64 {
    2.0
}

fn default_energy() -> f64 {
    1.0
}

/// `W² (Id + A (d J / tr J − Id))` with `J = G_ρ * (∇f_σ ∇f_σᵀ)`: cheap along
/// the edges of the image, isotropic where it is flat and as `A → 0`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct StructureTensorSpec {
    /// Id of the image (2D or 3D).
    pub image: String,
    /// Noise scale σ (physical units). Default 1.
    #[serde(default = "default_sigma")]
    #[schema(minimum = 0.0)]
    pub sigma: f64,
    /// Integration scale ρ (physical units). Default 2.
    #[serde(default = "default_rho")]
    #[schema(minimum = 0.0)]
    pub rho: f64,
    /// Energy `W > 0`. Default 1.
    #[serde(default = "default_energy")]
    pub energy: f64,
    /// Anisotropy `A ∈ [0, 1)`: `W²(1 − A)` along coherent edges.
    pub anisotropy: f64,
}

/// The first fundamental form of the graph of `h`, times `W²`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct HeightMapSpec {
    /// Id of the height map (same length unit as the spacing).
    pub heights: String,
    /// Cost `W > 0` per unit of surface length (number or dataset). Default 1.
    #[serde(default = "one")]
    pub energy: ScalarField,
    /// Gaussian smoothing of the heights before differentiation (physical units). Default 0.
    #[serde(default)]
    #[schema(minimum = 0.0)]
    pub sigma: f64,
}

impl TensorSpec {
    /// The dataset ids this section reads, with their JSON paths (under `prefix`).
    pub fn dataset_ids(&self, prefix: &str) -> Vec<(String, String)> {
        let mut ids = Vec::new();
        let mut push_field = |name: &str, f: &ScalarField| {
            if let ScalarField::Dataset(id) = f {
                ids.push((format!("{prefix}.{name}"), id.clone()));
            }
        };
        match self {
            TensorSpec::Components(c) => {
                return vec![(format!("{prefix}.dataset"), c.dataset.clone())]
            }
            TensorSpec::EnergyAnisotropy(e) => {
                push_field("energy", &e.energy);
                push_field("anisotropy", &e.anisotropy);
                push_field("angle", &e.angle);
            }
            TensorSpec::StructureTensor(s) => {
                return vec![(format!("{prefix}.image"), s.image.clone())]
            }
            TensorSpec::HeightMap(h) => {
                ids.push((format!("{prefix}.heights"), h.heights.clone()));
                if let ScalarField::Dataset(id) = &h.energy {
                    ids.push((format!("{prefix}.energy"), id.clone()));
                }
            }
            TensorSpec::Constant(_) | TensorSpec::Eigen(_) => {}
        }
        ids
    }

    /// Checks what does not need the datasets.
    pub fn validate(&self, prefix: &str, limits: &OpLimits) -> Result<(), OpError> {
        let bad = |f: &str, r: String| OpError::invalid(format!("{prefix}.{f}"), r);
        match self {
            TensorSpec::Components(_) => Ok(()),
            TensorSpec::Constant(c) => {
                check_shape(&c.shape, &format!("{prefix}.shape"), limits)?;
                let grid = Grid::unit(&c.shape).map_err(|e| bad("shape", e.to_string()))?;
                TensorField::constant(&grid, &c.components)
                    .map(|_| ())
                    .map_err(|e| bad("components", e.to_string()))
            }
            TensorSpec::Eigen(e) => {
                check_shape(&e.shape, &format!("{prefix}.shape"), limits)?;
                eigen_tensor(e.shape.len(), &e.eigenvalues, &e.direction)
                    .map(|_| ())
                    .map_err(|err| tensor_error(err, prefix))
            }
            TensorSpec::EnergyAnisotropy(e) => {
                if let Some(s) = &e.shape {
                    check_shape(s, &format!("{prefix}.shape"), limits)?;
                    if s.len() != 2 {
                        return Err(bad("shape", "the energy / anisotropy form is 2D".into()));
                    }
                }
                let all_values = [&e.energy, &e.anisotropy, &e.angle]
                    .iter()
                    .all(|f| matches!(f, ScalarField::Value(_)));
                if all_values && e.shape.is_none() {
                    return Err(bad(
                        "shape",
                        "give the grid shape, or one field as a dataset".into(),
                    ));
                }
                let w = match e.energy {
                    ScalarField::Value(v) => v,
                    _ => 1.0,
                };
                let a = match e.anisotropy {
                    ScalarField::Value(v) => v,
                    _ => 0.0,
                };
                let t = match e.angle {
                    ScalarField::Value(v) => v,
                    _ => 0.0,
                };
                energy_anisotropy(w, a, t)
                    .map(|_| ())
                    .map_err(|err| tensor_error(err, prefix))
            }
            TensorSpec::StructureTensor(s) => {
                if !(s.sigma.is_finite() && s.sigma >= 0.0) {
                    return Err(bad("sigma", format!("{} must be finite and >= 0", s.sigma)));
                }
                if !(s.rho.is_finite() && s.rho >= 0.0) {
                    return Err(bad("rho", format!("{} must be finite and >= 0", s.rho)));
                }
                if !(s.energy.is_finite() && s.energy > 0.0) {
                    return Err(bad(
                        "energy",
                        format!("{} must be finite and > 0", s.energy),
                    ));
                }
                if !(s.anisotropy.is_finite() && (0.0..1.0).contains(&s.anisotropy)) {
                    return Err(bad(
                        "anisotropy",
                        format!("{} must be in [0, 1)", s.anisotropy),
                    ));
                }
                Ok(())
            }
            TensorSpec::HeightMap(h) => {
                if !(h.sigma.is_finite() && h.sigma >= 0.0) {
                    return Err(bad("sigma", format!("{} must be finite and >= 0", h.sigma)));
                }
                if let ScalarField::Value(w) = h.energy {
                    if !(w.is_finite() && w > 0.0) {
                        return Err(bad("energy", format!("{w} must be finite and > 0")));
                    }
                }
                Ok(())
            }
        }
    }

    /// The grid shape this section implies (from its datasets or its `shape`).
    pub fn shape(
        &self,
        inputs: &dyn Inputs,
        prefix: &str,
        limits: &OpLimits,
    ) -> Result<Vec<usize>, OpError> {
        let shape = match self {
            TensorSpec::Components(c) => {
                let field = format!("{prefix}.dataset");
                let a = fetch(inputs, &field, &c.dataset)?;
                let s = a.array.shape();
                let nc = *s.last().unwrap_or(&0);
                let grid = &s[..s.len().saturating_sub(1)];
                let ok = (grid.len() == 2 && nc == 3) || (grid.len() == 3 && nc == 6);
                if !ok {
                    return Err(OpError::invalid(
                        field,
                        format!(
                            "shape {s:?}: a tensor dataset has a trailing axis of 3 (2D grid) or 6 (3D grid)"
                        ),
                    ));
                }
                grid.to_vec()
            }
            TensorSpec::Constant(c) => c.shape.clone(),
            TensorSpec::Eigen(e) => e.shape.clone(),
            TensorSpec::EnergyAnisotropy(e) => {
                let mut shape = e.shape.clone();
                for (name, f) in [
                    ("energy", &e.energy),
                    ("anisotropy", &e.anisotropy),
                    ("angle", &e.angle),
                ] {
                    if let ScalarField::Dataset(id) = f {
                        let field = format!("{prefix}.{name}");
                        let s = fetch(inputs, &field, id)?.array.shape().to_vec();
                        match &shape {
                            Some(prev) if *prev != s => {
                                return Err(OpError::invalid(
                                    field,
                                    format!("shape {s:?} differs from the grid shape {prev:?}"),
                                ))
                            }
                            _ => shape = Some(s),
                        }
                    }
                }
                let shape =
                    shape.ok_or_else(|| OpError::invalid(format!("{prefix}.shape"), "missing"))?;
                if shape.len() != 2 {
                    return Err(OpError::invalid(
                        prefix.to_string(),
                        "the energy / anisotropy form is 2D",
                    ));
                }
                shape
            }
            TensorSpec::StructureTensor(s) => fetch(inputs, &format!("{prefix}.image"), &s.image)?
                .array
                .shape()
                .to_vec(),
            TensorSpec::HeightMap(h) => fetch(inputs, &format!("{prefix}.heights"), &h.heights)?
                .array
                .shape()
                .to_vec(),
        };
        let field = match self {
            TensorSpec::Components(_) => format!("{prefix}.dataset"),
            TensorSpec::StructureTensor(_) => format!("{prefix}.image"),
            TensorSpec::HeightMap(_) => format!("{prefix}.heights"),
            _ => format!("{prefix}.shape"),
        };
        check_shape(&shape, &field, limits)?;
        Ok(shape)
    }

    /// The spacing stored with the first dataset of this section, if any.
    pub fn dataset_spacing(&self, inputs: &dyn Inputs) -> Option<Vec<f64>> {
        let id = match self {
            TensorSpec::Components(c) => &c.dataset,
            TensorSpec::StructureTensor(s) => &s.image,
            TensorSpec::HeightMap(h) => &h.heights,
            _ => return None,
        };
        let a = inputs.get(id)?;
        let mut s = a.spacing?;
        if matches!(self, TensorSpec::Components(_)) {
            s.truncate(a.array.shape().len().saturating_sub(1));
        }
        Some(s)
    }

    /// Builds and validates the field on `grid`.
    pub fn build(
        &self,
        grid: &Grid,
        inputs: &dyn Inputs,
        prefix: &str,
        control: &Control<'_>,
    ) -> Result<TensorField, OpError> {
        let values = |field: &str, id: &str| -> Result<Vec<f64>, OpError> {
            let a = fetch(inputs, field, id)?;
            let n = a.array.len();
            let v: Option<Vec<f64>> = (0..n).map(|i| a.array.get_f64(i)).collect();
            match (a.array.dtype(), v) {
                (crate::io::DType::Bool, _) | (_, None) => Err(OpError::invalid(
                    field,
                    format!("a {:?} array cannot hold numbers here", a.array.dtype()),
                )),
                (_, Some(v)) => Ok(v),
            }
        };
        let scalar = |name: &str, f: &ScalarField| -> Result<Vec<f64>, OpError> {
            match f {
                ScalarField::Value(v) => Ok(vec![*v]),
                ScalarField::Dataset(id) => {
                    let field = format!("{prefix}.{name}");
                    let v = values(&field, id)?;
                    if v.len() != grid.len() {
                        return Err(OpError::invalid(
                            field,
                            format!("{} values for a grid of {} cells", v.len(), grid.len()),
                        ));
                    }
                    Ok(v)
                }
            }
        };
        let err = |e: TensorError| tensor_error(e, prefix);
        match self {
            TensorSpec::Components(c) => {
                let field = format!("{prefix}.dataset");
                let v = values(&field, &c.dataset)?;
                TensorField::from_components(grid, v)
                    .map_err(|e| OpError::invalid(field, e.to_string()))
            }
            TensorSpec::Constant(c) => TensorField::constant(grid, &c.components)
                .map_err(|e| OpError::invalid(format!("{prefix}.components"), e.to_string())),
            TensorSpec::Eigen(e) => {
                TensorField::from_eigen(grid, &e.eigenvalues, &e.direction).map_err(err)
            }
            TensorSpec::EnergyAnisotropy(e) => {
                let w = scalar("energy", &e.energy)?;
                let a = scalar("anisotropy", &e.anisotropy)?;
                let t = scalar("angle", &e.angle)?;
                let pick = |v: &[f64], i: usize| if v.len() == 1 { v[0] } else { v[i] };
                let mut out = Vec::with_capacity(grid.len() * 3);
                for i in 0..grid.len() {
                    let m =
                        energy_anisotropy(pick(&w, i), pick(&a, i), pick(&t, i)).map_err(|e| {
                            OpError::invalid(
                                format!("{prefix}.{}", param_field(&e)),
                                format!(
                                    "cell {:?}: {e}",
                                    crate::numerics::metric::unravel_user(grid, i)
                                ),
                            )
                        })?;
                    out.extend_from_slice(&m);
                }
                TensorField::from_components(grid, out).map_err(err)
            }
            TensorSpec::StructureTensor(s) => {
                let img = values(&format!("{prefix}.image"), &s.image)?;
                edge_metric(grid, &img, s.sigma, s.rho, s.energy, s.anisotropy, control)
                    .map_err(err)
            }
            TensorSpec::HeightMap(h) => {
                let heights = values(&format!("{prefix}.heights"), &h.heights)?;
                let w = scalar("energy", &h.energy)?;
                height_map_metric(grid, &heights, &w, h.sigma, control).map_err(err)
            }
        }
    }
}

fn param_field(e: &TensorError) -> &'static str {
    match e {
        TensorError::Parameter { field, .. } => field,
        _ => "components",
    }
}

/// A core tensor error as an [`OpError`] under `prefix`.
pub fn tensor_error(e: TensorError, prefix: &str) -> OpError {
    if matches!(e, TensorError::Cancelled) {
        return OpError::Cancelled;
    }
    let field = match &e {
        TensorError::Parameter { field, .. } => match *field {
            "eigenvalues" | "direction" | "energy" | "anisotropy" | "angle" | "sigma"
            | "heights" | "image" => {
                format!("{prefix}.{field}")
            }
            _ => prefix.to_string(),
        },
        TensorError::MaskLength { .. } => "obstacles".to_string(),
        _ => prefix.to_string(),
    };
    OpError::invalid(field, e.to_string())
}

/// Components per cell of a grid of this dimension (re-exported for callers).
pub fn per_cell(ndim: usize) -> usize {
    components(ndim)
}

/// A tensor metric resolved against its datasets: the grid, the spacing
/// that was used and the validated field, walls (`obstacles`) included.
/// Shared by every operation that takes a tensor (`grid.distance`,
/// `grid.segment`, `grid.paths` with `metric`, and `grid.tensor_distance`).
#[derive(Debug, Clone)]
pub struct ResolvedTensor {
    /// Shape and spacing.
    pub grid: Grid,
    /// The spacing per caller axis.
    pub spacing: Vec<f64>,
    /// The SPD field with its walls.
    pub metric: TensorField,
}

/// Builds the field of `spec` (named `prefix` in errors): the grid shape
/// from its datasets or `shape`, the spacing (`spacing`, else the first
/// dataset's, else 1), every cell checked (the first bad cell is named),
/// and the non-zero cells of the `obstacles` mask as walls.
pub fn resolve_tensor(
    spec: &TensorSpec,
    prefix: &str,
    spacing: Option<&[f64]>,
    obstacles: Option<&str>,
    inputs: &dyn Inputs,
    limits: &OpLimits,
    control: &Control<'_>,
) -> Result<ResolvedTensor, OpError> {
    spec.validate(prefix, limits)?;
    let shape = spec.shape(inputs, prefix, limits)?;
    let spacing = spacing
        .map(<[f64]>::to_vec)
        .or_else(|| spec.dataset_spacing(inputs))
        .unwrap_or_else(|| vec![1.0; shape.len()]);
    let grid = Grid::new(&shape, &spacing).map_err(|e| match e {
        GridError::Spacing { axis, .. } => {
            OpError::invalid(format!("spacing[{axis}]"), e.to_string())
        }
        _ => OpError::invalid("spacing", e.to_string()),
    })?;
    let mut metric = spec.build(&grid, inputs, prefix, control)?;
    if let Some(id) = obstacles {
        let m = fetch(inputs, "obstacles", id)?;
        if m.array.shape() != shape.as_slice() {
            return Err(OpError::invalid(
                "obstacles",
                format!(
                    "the mask has shape {:?} but the grid has shape {:?}",
                    m.array.shape(),
                    shape
                ),
            ));
        }
        metric = metric
            .with_walls(&grid, m.array.to_mask())
            .map_err(|e| tensor_error(e, prefix))?;
    }
    Ok(ResolvedTensor {
        grid,
        spacing,
        metric,
    })
}

/// The scheme of an anisotropic solve, as the requests give it.
#[derive(Debug, Clone, Default)]
pub struct TensorSolveSpec {
    /// 1 or 2 (anything but 1 is second order).
    pub order: u8,
    /// Source factoring around point sources.
    pub factoring: bool,
    /// Early stopping.
    pub stop: StopRules,
    /// Record the freeze rank of each cell.
    pub record_order: bool,
}

/// A solve of [`solve_tensor`] and its wall time.
#[derive(Debug, Clone)]
pub struct TensorSolved {
    /// The distance, labels, stop reason and stencil statistics.
    pub out: TensorOutput,
    /// Seconds of the solve (stencils and marching).
    pub seconds: f64,
}

impl ResolvedTensor {
    /// The problem of a solve from `sources` (moves the grid and the field).
    pub fn into_problem(self, sources: Vec<Source>) -> (TensorProblem, Vec<f64>) {
        (
            TensorProblem {
                grid: self.grid,
                metric: self.metric,
                sources,
            },
            self.spacing,
        )
    }
}

/// Runs the anisotropic fast marching on `problem`; errors name
/// `sources[i]`, `stop.targets[i]` or the metric section `prefix`.
pub fn solve_tensor(
    problem: &TensorProblem,
    spec: &TensorSolveSpec,
    prefix: &str,
    control: &Control<'_>,
) -> Result<TensorSolved, OpError> {
    let mut options = TensorOptions::DEFAULT
        .with_order(if spec.order == 1 {
            Order::First
        } else {
            Order::Second
        })
        .with_factoring(spec.factoring)
        .with_stop(spec.stop.clone());
    options.record_order = spec.record_order;
    let started = Instant::now();
    let out = solve(problem, &options, control).map_err(|e| tensor_solve_error(e, prefix))?;
    Ok(TensorSolved {
        out,
        seconds: started.elapsed().as_secs_f64(),
    })
}

/// A core anisotropic solve error as an [`OpError`]; the metric is named `prefix`.
pub fn tensor_solve_error(e: TensorSolveError, prefix: &str) -> OpError {
    match e {
        TensorSolveError::Tensor(t) => tensor_error(t, prefix),
        TensorSolveError::Dimension { .. } => OpError::invalid(prefix, e.to_string()),
        TensorSolveError::Solve(EikonalError::Grid(g)) => OpError::invalid(prefix, g.to_string()),
        TensorSolveError::Solve(e) => eikonal_error(e),
    }
}
