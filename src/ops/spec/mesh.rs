//! Pieces shared by the mesh operations (`mesh.distance`, `mesh.voronoi`,
//! `mesh.paths`, `mesh.sample`): points on a surface, the method name, the
//! mesh input handed in by the caller, and the call of the core.

use std::sync::Arc;

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use ndarray::ArrayD;

use super::errors::mesh_solve_error;
use super::mesh_metric::{resolve_metric, validate_metric, ResolvedMeshMetric, SurfaceMetricSpec};
use crate::io::mesh::MeshReport;
use crate::io::ArrayData;
use crate::numerics::mesh::{
    mesh_distance, HeatOptions, HeatSolver, Laplacian, MeshDistance, MeshDistanceOptions,
    MeshMethod, SurfacePoint, Topology, TriMesh,
};
use crate::numerics::Control;
use crate::ops::{Inputs, OpError, OpLimits, OpOutput, OutputArray, OutputMesh};
use std::time::Instant;

/// A decoded mesh dataset, as operations receive it.
#[derive(Debug)]
pub struct MeshInput {
    /// The mesh.
    pub mesh: TriMesh,
    /// Its adjacency.
    pub topology: Topology,
    /// Its report (counts, repairs).
    pub report: MeshReport,
}

/// A point on the surface: `{"vertex": 12}` or
/// `{"face": 3, "bary": [0.2, 0.3, 0.5]}` (barycentric coordinates in the
/// order of the face's vertices, >= 0, summing to 1).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct MeshPointSpec {
    /// A vertex index (0-based, in the dataset's vertex order).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub vertex: Option<u32>,
    /// A face index (0-based); needs `bary`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub face: Option<u32>,
    /// Barycentric coordinates inside `face`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bary: Option<[f64; 3]>,
}

impl MeshPointSpec {
    /// The core's point, checked for shape (not yet against a mesh).
    pub fn to_point(&self, field: &str) -> Result<SurfacePoint, OpError> {
        match (self.vertex, self.face, self.bary) {
            (Some(v), None, None) => Ok(SurfacePoint::Vertex(v)),
            (None, Some(face), Some(bary)) => Ok(SurfacePoint::Face { face, bary }),
            (None, Some(_), None) => Err(OpError::invalid(
                format!("{field}.bary"),
                "a face point needs `bary`",
            )),
            _ => Err(OpError::invalid(
                field,
                "give either `vertex`, or `face` with `bary`",
            )),
        }
    }
}

/// The surface distance method (the old spelling `fast-marching` is refused,
/// naming `fast_marching`: [`crate::ops::renamed`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum MeshMethodSpec {
    /// Kimmel–Sethian fast marching, first order, with unfolding of obtuse triangles.
    #[default]
    FastMarching,
    /// The heat method: prefactored per mesh dataset, two solves per query.
    Heat,
    /// Exact polyhedral distance (window propagation).
    Exact,
    /// Dijkstra on the edges (baseline; overestimates).
    Dijkstra,
}

impl From<MeshMethodSpec> for MeshMethod {
    fn from(m: MeshMethodSpec) -> Self {
        match m {
            MeshMethodSpec::FastMarching => MeshMethod::FastMarching,
            MeshMethodSpec::Heat => MeshMethod::Heat,
            MeshMethodSpec::Exact => MeshMethod::Exact,
            MeshMethodSpec::Dijkstra => MeshMethod::Dijkstra,
        }
    }
}

/// The Laplacian of the heat method.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum LaplacianSpec {
    /// The intrinsic Delaunay Laplacian of the mollified mesh (its tufted
    /// cover when non-manifold): accurate on scans with needles, slivers,
    /// zero-area faces and non-manifold edges (Sharp & Crane 2020).
    #[default]
    Robust,
    /// The plain cotangent Laplacian of the mesh's own triangles.
    Cotangent,
}

impl From<LaplacianSpec> for Laplacian {
    fn from(l: LaplacianSpec) -> Self {
        match l {
            LaplacianSpec::Robust => Laplacian::Robust,
            LaplacianSpec::Cotangent => Laplacian::Cotangent,
        }
    }
}

/// Options of the heat method.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct HeatSpec {
    /// Time step factor `m` in `t = m·h²` (`h` the mean edge length). Default 1.
    #[serde(default = "one")]
    #[schema(exclusive_minimum = 0.0)]
    pub m: f64,
    /// The Laplacian. Default `robust`.
    #[serde(default)]
    pub laplacian: LaplacianSpec,
    /// Lower the time step on surfaces curved at the scale of their edges:
    /// `t = m·h²·clamp(√(ρ₀/ρ), ½, 1)`, `ρ` the mean distance of the Gaussian
    /// curvature, smoothed over about four edges, from its mean over the
    /// surface, in units of `h⁻²` (reported as `heat.roughness`),
    /// `ρ₀ = 0.003`. Smoothing by a time step of `h²`
    /// bends the distance's gradient on scans whose features are a few
    /// edges across (a bias that grows with `t`) while a smooth surface
    /// keeps `t = m·h²`. Default true; false gives `t = m·h²`.
    #[serde(default = "yes")]
    pub adapt: bool,
}

impl Default for HeatSpec {
    fn default() -> Self {
        Self {
            m: 1.0,
            laplacian: LaplacianSpec::Robust,
            adapt: true,
        }
    }
}

impl HeatSpec {
    /// The core's options.
    pub fn options(&self) -> HeatOptions {
        HeatOptions {
            m: self.m,
            laplacian: self.laplacian.into(),
            adapt: self.adapt,
            ..Default::default()
        }
    }
}

fn one() -> f64 {
    1.0
}

fn yes() -> bool {
    true
}

/// Checks the common fields.
pub(crate) fn validate_common(
    sources: &[MeshPointSpec],
    max_distance: Option<f64>,
    heat: &HeatSpec,
    limits: &OpLimits,
) -> Result<Vec<SurfacePoint>, OpError> {
    if sources.is_empty() {
        return Err(OpError::invalid("sources", "at least one source is needed"));
    }
    if sources.len() > limits.max_sources {
        return Err(OpError::TooLarge {
            field: "sources".into(),
            reason: format!(
                "{} sources, more than the limit of {}",
                sources.len(),
                limits.max_sources
            ),
        });
    }
    if let Some(d) = max_distance {
        if d.is_nan() || d < 0.0 {
            return Err(OpError::invalid("max_distance", "must be >= 0"));
        }
    }
    if !(heat.m.is_finite() && heat.m > 0.0) {
        return Err(OpError::invalid("heat.m", "must be finite and > 0"));
    }
    sources
        .iter()
        .enumerate()
        .map(|(i, s)| s.to_point(&format!("sources[{i}]")))
        .collect()
}

/// The mesh named by `id`, or the error naming `field`.
pub(crate) fn get_mesh(
    inputs: &dyn Inputs,
    field: &str,
    id: &str,
) -> Result<Arc<MeshInput>, OpError> {
    inputs.mesh(id).ok_or_else(|| OpError::UnknownDataset {
        field: field.into(),
        id: id.into(),
    })
}

/// Checks points against the mesh.
pub(crate) fn check_points(
    mesh: &TriMesh,
    points: &[SurfacePoint],
    field: &str,
) -> Result<(), OpError> {
    for (i, p) in points.iter().enumerate() {
        p.validate(mesh)
            .map_err(|reason| OpError::invalid(format!("{field}[{i}]"), reason))?;
    }
    Ok(())
}

/// What the heat method reports.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct HeatInfo {
    /// The time step used.
    pub t: f64,
    /// The factor `m`.
    pub m: f64,
    /// The curvature roughness `ρ` that lowered the time step (see
    /// `heat.adapt`; 0 when not adapted).
    pub roughness: f64,
    /// The Laplacian used.
    pub laplacian: LaplacianSpec,
    /// Intrinsic edge flips made by the robust Laplacian (0 for `cotangent`).
    pub flips: usize,
    /// True when the tufted cover was used (non-manifold or inconsistently
    /// oriented mesh).
    pub tufted: bool,
    /// Length added to every edge by the mollification (0 when no
    /// triangle was nearly degenerate).
    pub mollified: f64,
    /// True when the factorisation came from the cache.
    pub cached: bool,
    /// Seconds spent factoring in this request (0 when cached).
    pub factor_seconds: f64,
    /// Seconds of each setup phase when the solver was built (kept with
    /// it: the same figures when cached).
    pub setup: SetupPhasesOut,
}

/// The phases of the heat method's setup, in seconds.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct SetupPhasesOut {
    /// Dijkstra eccentricities of the underflow guard.
    pub underflow_guard_seconds: f64,
    /// Triangulation (flips, mollification, tufted cover) and assembly.
    pub laplacian_seconds: f64,
    /// The curvature roughness estimate, beside the symbolic factorisation.
    pub curvature_seconds: f64,
    /// Symbolic and numeric Cholesky factorisations.
    pub factorisation_seconds: f64,
}

impl HeatInfo {
    /// What `solver` reports, with the request's `m`.
    pub(crate) fn of(solver: &HeatSolver, m: f64, cached: bool, factor_seconds: f64) -> Self {
        Self {
            t: solver.t(),
            m,
            roughness: solver.roughness(),
            laplacian: match solver.laplacian() {
                Laplacian::Robust => LaplacianSpec::Robust,
                Laplacian::Cotangent => LaplacianSpec::Cotangent,
            },
            flips: solver.flips(),
            tufted: solver.tufted(),
            mollified: solver.mollified(),
            cached,
            factor_seconds,
            setup: {
                let p = solver.phases();
                SetupPhasesOut {
                    underflow_guard_seconds: p.underflow_guard,
                    laplacian_seconds: p.laplacian,
                    curvature_seconds: p.curvature,
                    factorisation_seconds: p.factorisation,
                }
            },
        }
    }
}

/// Runs the chosen method, using (and filling) the caller's heat cache.
#[allow(clippy::too_many_arguments)]
pub(crate) fn run_distance(
    inputs: &dyn Inputs,
    mesh_id: &str,
    input: &MeshInput,
    sources: &[SurfacePoint],
    method: MeshMethod,
    max_distance: f64,
    metric: &ResolvedMeshMetric,
    heat: &HeatSpec,
    control: &Control<'_>,
) -> Result<(MeshDistance, Option<HeatInfo>), OpError> {
    let opts = MeshDistanceOptions {
        method,
        max_distance,
        weights: metric.weights.as_deref(),
        tensors: metric.tensors.as_deref(),
        heat: heat.options(),
    };
    if method == MeshMethod::Heat {
        let (solver, cached, secs) = heat_solver(inputs, mesh_id, input, heat, control)?;
        let d = mesh_distance(
            &input.mesh,
            &input.topology,
            sources,
            &opts,
            Some(&solver),
            control,
        )
        .map_err(mesh_solve_error)?;
        let info = HeatInfo::of(&solver, heat.m, cached, secs);
        return Ok((d, Some(info)));
    }
    let d = mesh_distance(&input.mesh, &input.topology, sources, &opts, None, control)
        .map_err(mesh_solve_error)?;
    Ok((d, None))
}

/// The (cached) heat solver of a mesh dataset.
pub(crate) fn heat_solver(
    inputs: &dyn Inputs,
    mesh_id: &str,
    input: &MeshInput,
    heat: &HeatSpec,
    control: &Control<'_>,
) -> Result<(Arc<HeatSolver>, bool, f64), OpError> {
    let started = std::time::Instant::now();
    let options = heat.options();
    let mut build = || HeatSolver::new(&input.mesh, &input.topology, &options, control);
    let (solver, cached) = inputs
        .heat_solver(mesh_id, &options, &mut build)
        .map_err(mesh_solve_error)?;
    let secs = if cached {
        0.0
    } else {
        started.elapsed().as_secs_f64()
    };
    Ok((solver, cached, secs))
}

/// Summary of a per-vertex distance.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct MeshStats {
    /// Number of vertices.
    pub vertices: usize,
    /// Vertices with a finite distance.
    pub reached: usize,
    /// Largest finite distance (`null` if none).
    pub max_distance: Option<f64>,
    /// Seconds spent in the solver.
    pub solve_seconds: f64,
}

impl MeshStats {
    pub(crate) fn of(d: &MeshDistance, seconds: f64) -> Self {
        let finite = d.distance.iter().filter(|x| x.is_finite());
        Self {
            vertices: d.distance.len(),
            reached: finite.clone().count(),
            max_distance: finite.copied().reduce(f64::max),
            solve_seconds: seconds,
        }
    }
}

/// Reads a per-vertex weight dataset (any shape with one value per vertex).
pub(crate) fn read_weights(inputs: &dyn Inputs, id: &str, n: usize) -> Result<Vec<f64>, OpError> {
    let w = inputs.get(id).ok_or_else(|| OpError::UnknownDataset {
        field: "weights".into(),
        id: id.into(),
    })?;
    if w.array.len() != n {
        return Err(OpError::invalid(
            "weights",
            format!("{} values for {n} vertices", w.array.len()),
        ));
    }
    let v: Vec<f64> = (0..n)
        .map(|i| w.array.get_f64(i).unwrap_or(f64::NAN))
        .collect();
    if let Some(i) = v.iter().position(|x| !(x.is_finite() && *x > 0.0)) {
        return Err(OpError::invalid(
            "weights",
            format!("weight of vertex {i} is {} (must be finite and > 0)", v[i]),
        ));
    }
    Ok(v)
}

/// The per-vertex outputs as 1D arrays.
pub(crate) fn arrays(d: MeshDistance) -> Vec<OutputArray> {
    let n = d.distance.len();
    let dist = ArrayD::from_shape_vec(vec![n], d.distance).map(ArrayData::F64);
    let lab = ArrayD::from_shape_vec(vec![n], d.labels).map(ArrayData::I32);
    let mut out = Vec::new();
    if let Ok(a) = dist {
        out.push(OutputArray {
            name: "distance".into(),
            array: a,
            spacing: None,
        });
    }
    if let Ok(a) = lab {
        out.push(OutputArray {
            name: "labels".into(),
            array: a,
            spacing: None,
        });
    }
    out
}

/// The output of a per-vertex operation: the arrays of [`arrays`], and the
/// mesh `mesh` carrying them as `distance` and `label` vertex properties.
pub(crate) fn vertex_output(
    inputs: &dyn Inputs,
    mesh: &str,
    d: MeshDistance,
    document: serde_json::Value,
) -> OpOutput {
    let mut out = OpOutput::new(arrays(d), document);
    out.mesh = inputs.mesh(mesh).map(|m| OutputMesh {
        name: "result".into(),
        mesh: m,
        vertex_properties: vec![("distance", "distance"), ("label", "labels")],
    });
    out
}

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
    /// A metric designed on the surface (curvature, field) or anisotropic
    /// (face tensors, `fast_marching` only), instead of `weights`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub metric: Option<SurfaceMetricSpec>,
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
    validate_metric(req.weights.as_deref(), req.metric.as_ref(), req.method)?;
    let input = get_mesh(inputs, "mesh", &req.mesh)?;
    check_points(&input.mesh, &points, "sources")?;
    let started = Instant::now();
    let metric = resolve_metric(
        inputs,
        &input,
        req.weights.as_deref(),
        req.metric.as_ref(),
        control,
    )?;
    let (d, heat) = run_distance(
        inputs,
        &req.mesh,
        &input,
        &points,
        req.method.into(),
        req.max_distance.unwrap_or(f64::INFINITY),
        &metric,
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
