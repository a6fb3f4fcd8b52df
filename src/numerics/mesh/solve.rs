//! One entry point over the surface distance methods.

use super::dijkstra::dijkstra_distance;
use super::fast_marching::{fast_marching_distance, FastMarchingOptions};
use super::heat::{HeatOptions, HeatSolver};
use super::{MeshDistance, MeshSolveError, SurfacePoint, Topology, TriMesh};
use crate::numerics::Control;

/// A surface distance method.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum MeshMethod {
    /// Kimmel–Sethian fast marching (first order, `O(n log n)`).
    FastMarching,
    /// The heat method (first order; prefactored, two solves per query).
    Heat,
    /// Exact polyhedral distance (window propagation).
    Exact,
    /// Dijkstra on the edge graph (baseline; does not converge).
    Dijkstra,
}

/// Options common to every method.
#[derive(Debug, Clone, Copy)]
pub struct MeshDistanceOptions<'a> {
    /// The method.
    pub method: MeshMethod,
    /// Vertices farther than this get `+inf` and label -1.
    pub max_distance: f64,
    /// Per-vertex weight `W` (fast marching and Dijkstra only).
    pub weights: Option<&'a [f64]>,
    /// One tensor per face, an anisotropic metric (fast marching only,
    /// exclusive with `weights`; see [`super::fast_marching`]).
    pub tensors: Option<&'a [[f64; 6]]>,
    /// Heat method options.
    pub heat: HeatOptions,
}

impl Default for MeshDistanceOptions<'_> {
    fn default() -> Self {
        Self {
            method: MeshMethod::FastMarching,
            max_distance: f64::INFINITY,
            weights: None,
            tensors: None,
            heat: HeatOptions::default(),
        }
    }
}

/// Distance and nearest-source labels from `sources` with the chosen
/// method. `heat` may hand in a prefactored solver for this mesh (it is
/// built on the spot otherwise).
///
/// `U(v)` is the length of the shortest path on the surface from `v` to the
/// nearest source (weighted by `W` for fast marching and Dijkstra); the
/// exact method gives the polyhedral distance itself, the others converge to
/// it (except Dijkstra, which measures along edges).
///
/// # Examples
/// ```
/// use geodex::numerics::mesh::{mesh_distance, shapes, MeshDistanceOptions, MeshMethod, SurfacePoint, Topology};
/// use geodex::numerics::Control;
/// let mesh = shapes::flat_square(8, 1.0, 0.0); // [0, 1]² in 8 × 8 cells
/// let options = MeshDistanceOptions { method: MeshMethod::Exact, ..Default::default() };
/// let out = mesh_distance(&mesh, &Topology::new(&mesh), &[SurfacePoint::Vertex(0)], &options, None, &Control::new())?;
/// // On a flat mesh the polyhedral distance is the Euclidean one: (1, 1) is √2 away.
/// let far = mesh.positions().iter().position(|p| p[0] == 1.0 && p[1] == 1.0).unwrap_or(0);
/// assert!((out.distance[far] - 2f64.sqrt()).abs() < 1e-12);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn mesh_distance(
    mesh: &TriMesh,
    topo: &Topology,
    sources: &[SurfacePoint],
    options: &MeshDistanceOptions<'_>,
    heat: Option<&HeatSolver>,
    control: &Control<'_>,
) -> Result<MeshDistance, MeshSolveError> {
    if options.max_distance.is_nan() || options.max_distance < 0.0 {
        return Err(MeshSolveError::InvalidOption {
            option: "max_distance",
            reason: "must be >= 0".into(),
        });
    }
    if options.weights.is_some() && matches!(options.method, MeshMethod::Heat | MeshMethod::Exact) {
        return Err(MeshSolveError::InvalidOption {
            option: "weights",
            reason: "weights are supported by fast_marching and dijkstra only".into(),
        });
    }
    if options.tensors.is_some() && options.method != MeshMethod::FastMarching {
        return Err(MeshSolveError::InvalidOption {
            option: "tensors",
            reason: "face tensors (an anisotropic metric) are supported by fast_marching only"
                .into(),
        });
    }
    match options.method {
        MeshMethod::FastMarching => fast_marching_distance(
            mesh,
            topo,
            sources,
            &FastMarchingOptions {
                weights: options.weights,
                tensors: options.tensors,
                max_distance: options.max_distance,
                ..Default::default()
            },
            control,
        ),
        MeshMethod::Dijkstra => dijkstra_distance(
            mesh,
            sources,
            options.weights,
            options.max_distance,
            control,
        ),
        MeshMethod::Heat => match heat {
            Some(solver) => solver.distance(mesh, sources, options.max_distance, control),
            None => HeatSolver::new(mesh, topo, &options.heat, control)?.distance(
                mesh,
                sources,
                options.max_distance,
                control,
            ),
        },
        MeshMethod::Exact => exact(mesh, topo, sources, options.max_distance, control),
    }
}

/// The exact polyhedral distance (window propagation, `exact.rs`).
fn exact(
    mesh: &TriMesh,
    topo: &Topology,
    sources: &[SurfacePoint],
    max_distance: f64,
    control: &Control<'_>,
) -> Result<MeshDistance, MeshSolveError> {
    super::exact::exact_distance(mesh, topo, sources, max_distance, control)
}
