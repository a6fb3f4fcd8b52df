//! Operations: one request schema per operation, shared by the synchronous
//! HTTP endpoint, the job queue and the command line, and the code that turns
//! a validated request plus its input arrays into a call of the core.
//!
//! Nothing here does IO: input datasets are handed in through [`Inputs`].
//!
//! * [`grid_distance`]: `grid.distance`, the eikonal distance map on a grid.
//! * [`grid_edt`], [`grid_segment`], [`grid_skeleton`], [`grid_offset`], [`grid_plan`]: exact distance
//!   transforms, seeded segmentation, medial axes, offsets and disc-robot planning ([`grid_inputs`]: their shared input checks).
//! * [`grid_sample`]: `grid.sample`, farthest-point sampling with geodesic Voronoi labels.
//! * [`grid_mesh`]: `grid.mesh`, image meshing by geodesic Delaunay (a new mesh dataset).
//! * [`domain_mesh`]: `domain.mesh`, domain meshing of a mask or polygons (a new mesh dataset).
//! * [`grid_shading`]: `grid.shape_from_shading`, a surface's height from its image (shape from shading).
//! * [`grid_tomography`]: `grid.tomography`, a slowness map from travel times (adjoint tomography).
//! * [`grid_fit_metric`]: `grid.fit_metric`, an intensity metric fitted to example paths.
//! * [`grid_metric`]: `grid.metric`, a cost designed from an image, and the `cost.design` section.
//! * [`grid_paths`]: `grid.paths`, minimal paths (end points, way-points, closed contours) and their cache.
//! * [`grid_tensor_distance`]: `grid.tensor_distance`, the Riemannian distance map (and paths) of a tensor metric.
//! * [`grid_tensor_metric`]: `grid.tensor_metric`, a tensor field (or a designed metric) as a dataset.
//! * [`tensor_spec`]: the `tensor` section shared by both.
//! * [`mesh_distance`], [`mesh_voronoi`], [`mesh_paths`], [`mesh_sample`]:
//!   geodesics on triangle meshes (shared pieces in [`mesh_common`]).
//! * [`mesh_remesh`]: `mesh.remesh`, surface remeshing (a new mesh dataset).
//! * [`mesh_distance_matrix`], [`mesh_embed`], [`points_isomap`]: shape
//!   analysis: distance matrices, canonical forms, Isomap (shared pieces in
//!   [`spec::shape`]).
//! * [`mesh_correspond`]: `mesh.correspond`, the correspondence between two
//!   near-isometric meshes.

pub mod domain_mesh;
pub mod grid_cost_gradient;
pub mod grid_distance;
pub mod grid_edt;
pub mod grid_fit_metric;
pub mod grid_group;
pub mod grid_mesh;
pub mod grid_metric;
pub mod grid_offset;
pub mod grid_paths;
pub mod grid_plan;
pub mod grid_sample;
pub mod grid_segment;
pub mod grid_shading;
pub mod grid_shape_embed;
pub mod grid_skeleton;
pub mod grid_tensor_distance;
pub mod grid_tensor_metric;
pub mod grid_tomography;
pub mod mesh_correspond;
pub mod mesh_curvature;
pub mod mesh_descriptor;
pub mod mesh_distance;
pub mod mesh_distance_matrix;
pub mod mesh_embed;
pub mod mesh_paths;
pub mod mesh_remesh;
pub mod mesh_sample;
pub mod mesh_voronoi;
pub mod parse;
pub mod points_isomap;
pub mod registry;
pub mod renamed;
pub mod spec;

use std::sync::Arc;

use serde::de::DeserializeOwned;
use serde::Serialize;

use crate::io::ArrayData;
use crate::numerics::mesh::{HeatOptions, HeatSolver, MeshSolveError};
use crate::numerics::Control;

/// One operation of the service: its request schema and how to run it.
///
/// This is the contract shared by the synchronous endpoint, the job queue and
/// the command line. A request is validated without its inputs
/// ([`Operation::validate`], so that it can be refused before it is queued),
/// its datasets are fetched by the caller ([`Operation::dataset_ids`]) and
/// handed in through [`Inputs`], and [`Operation::run`] calls the core on the
/// solver pool. The output is storage-neutral: named arrays that the caller
/// stores as datasets (or files), and a JSON document with everything else
/// (statistics, paths, graphs).
pub trait Operation: Serialize + DeserializeOwned + Send + Sync + 'static {
    /// The operation's name in job requests and metrics (`grid.distance`).
    const NAME: &'static str;

    /// Checks everything that does not need the input datasets.
    fn validate(&self, limits: &OpLimits) -> Result<(), OpError>;

    /// The dataset ids the request reads, each with the JSON path of the field naming it.
    fn dataset_ids(&self) -> Vec<(String, String)>;

    /// The datasets still to load, given what the caller's caches hold (a
    /// hook: `grid.paths` takes its cached cost here and needs no dataset).
    /// Default: every one of [`Operation::dataset_ids`].
    fn datasets_to_load(&mut self, _inputs: &dyn Inputs) -> Vec<(String, String)> {
        self.dataset_ids()
    }

    /// Its estimated peak memory in bytes, from the shapes of its loaded
    /// inputs and of the grid a constant `cost` names, before anything is
    /// allocated: the pool admits solves by it. Default:
    /// [`estimate_peak_bytes`].
    fn peak_bytes(&self, inputs: &dyn Inputs) -> u64 {
        let constant_cells = serde_json::to_value(self)
            .ok()
            .and_then(|v| v.pointer("/cost/shape").cloned())
            .and_then(|s| serde_json::from_value::<Vec<usize>>(s).ok())
            .map_or(0, |shape| {
                shape.iter().fold(1usize, |a, &n| a.saturating_mul(n))
            });
        estimate_peak_bytes(&self.dataset_ids(), inputs, constant_cells)
    }

    /// Runs the operation. Polls `control` for cancellation and reports progress through it.
    fn run(
        &self,
        inputs: &dyn Inputs,
        limits: &OpLimits,
        control: &Control<'_>,
    ) -> Result<OpOutput, OpError>;
}

/// Bytes a grid solve holds per cell at its peak, beyond its inputs: the
/// distance `U` (8), the cost it solves on (8, designed or converted), the
/// labels (4), the state and the heap index (5), heap entries on the front
/// (16 for a front of the whole grid at worst), the outputs' NPY copies
/// (12), and twice that margin for the operations that keep more (the
/// gradient's adjoint, the tensor fields' six coefficients).
pub const PEAK_BYTES_PER_CELL: u64 = 96;

/// Bytes a mesh solve holds per vertex at its peak: positions, topology,
/// the distance and its outputs, and the sparse Cholesky factor of the heat
/// method (about 40 non-zeros per vertex on surface meshes) or the exact
/// method's frames and windows (the largest: 1.13 kB per vertex, process
/// included, measured with the 437k-vertex dragon's propagation forced
/// into two halves, as sphere-like meshes are split by default).
pub const PEAK_BYTES_PER_VERTEX: u64 = 1280;

/// The estimate every operation starts from: for each input array its own
/// bytes plus [`PEAK_BYTES_PER_CELL`] per cell, for each mesh
/// [`PEAK_BYTES_PER_VERTEX`] per vertex, and `extra_cells` grid cells the
/// request names without a dataset (a constant cost's `shape`).
pub fn estimate_peak_bytes(
    ids: &[(String, String)],
    inputs: &dyn Inputs,
    extra_cells: usize,
) -> u64 {
    let mut seen = std::collections::HashSet::new();
    let mut total = (extra_cells as u64).saturating_mul(PEAK_BYTES_PER_CELL);
    for (_, id) in ids {
        if !seen.insert(id.as_str()) {
            continue;
        }
        if let Some(a) = inputs.get(id) {
            let cells: usize = a.array.shape().iter().product();
            total = total
                .saturating_add(a.array.nbytes() as u64)
                .saturating_add((cells as u64).saturating_mul(PEAK_BYTES_PER_CELL));
        } else if let Some(m) = inputs.mesh(id) {
            total = total.saturating_add(
                (m.mesh.num_vertices() as u64).saturating_mul(PEAK_BYTES_PER_VERTEX),
            );
        }
    }
    total
}

/// An [`Operation`] of any type, as the runner, the job queue and the
/// registry hold it (one box instead of one generic copy per caller).
pub trait DynOperation: Send + Sync + std::fmt::Debug {
    /// [`Operation::NAME`].
    fn name(&self) -> &'static str;
    /// [`Operation::validate`].
    fn validate(&self, limits: &OpLimits) -> Result<(), OpError>;
    /// [`Operation::dataset_ids`].
    fn dataset_ids(&self) -> Vec<(String, String)>;
    /// [`Operation::datasets_to_load`].
    fn datasets_to_load(&mut self, inputs: &dyn Inputs) -> Vec<(String, String)>;
    /// [`Operation::peak_bytes`].
    fn peak_bytes(&self, inputs: &dyn Inputs) -> u64;
    /// [`Operation::run`].
    fn run(
        &self,
        inputs: &dyn Inputs,
        limits: &OpLimits,
        control: &Control<'_>,
    ) -> Result<OpOutput, OpError>;
    /// The request as JSON, defaults filled in (what a job stores).
    fn canonical_json(&self) -> Result<String, serde_json::Error>;
}

impl<O: Operation + std::fmt::Debug> DynOperation for O {
    fn name(&self) -> &'static str {
        O::NAME
    }

    fn validate(&self, limits: &OpLimits) -> Result<(), OpError> {
        Operation::validate(self, limits)
    }

    fn dataset_ids(&self) -> Vec<(String, String)> {
        Operation::dataset_ids(self)
    }

    fn datasets_to_load(&mut self, inputs: &dyn Inputs) -> Vec<(String, String)> {
        Operation::datasets_to_load(self, inputs)
    }

    fn peak_bytes(&self, inputs: &dyn Inputs) -> u64 {
        Operation::peak_bytes(self, inputs)
    }

    fn run(
        &self,
        inputs: &dyn Inputs,
        limits: &OpLimits,
        control: &Control<'_>,
    ) -> Result<OpOutput, OpError> {
        Operation::run(self, inputs, limits, control)
    }

    fn canonical_json(&self) -> Result<String, serde_json::Error> {
        serde_json::to_string(self)
    }
}

/// What an operation returns, independent of where it is stored.
#[derive(Debug, Clone)]
pub struct OpOutput {
    /// Arrays to store as datasets, in a stable order (`distance`, `labels`, ...).
    pub arrays: Vec<OutputArray>,
    /// The rest of the answer (statistics, paths, graphs) as a JSON object.
    /// The caller adds one entry per array, named after it, holding the stored dataset's reference.
    pub document: serde_json::Value,
    /// A mesh to store as one dataset carrying some of `arrays` as per-vertex
    /// properties (the synchronous answer of a mesh operation), if any.
    pub mesh: Option<OutputMesh>,
}

impl OpOutput {
    /// Arrays and a document, no mesh.
    pub fn new(arrays: Vec<OutputArray>, document: serde_json::Value) -> Self {
        Self {
            arrays,
            document,
            mesh: None,
        }
    }

    /// The document as a JSON object: an object as it is, `null` as an empty
    /// one, anything else under `result`. Stored outputs are added to it.
    pub fn document_map(&mut self) -> serde_json::Map<String, serde_json::Value> {
        match std::mem::take(&mut self.document) {
            serde_json::Value::Object(map) => map,
            serde_json::Value::Null => serde_json::Map::new(),
            other => {
                let mut map = serde_json::Map::new();
                map.insert("result".into(), other);
                map
            }
        }
    }

    /// The array named `name`, if any.
    pub fn array(&self, name: &str) -> Option<&ArrayData> {
        self.arrays
            .iter()
            .find(|a| a.name == name)
            .map(|a| &a.array)
    }
}

/// A mesh output: the input mesh with per-vertex arrays of the output as
/// properties, stored under `name` in the answer.
#[derive(Debug, Clone)]
pub struct OutputMesh {
    /// Key of its reference in the answer (`result`).
    pub name: String,
    /// The mesh.
    pub mesh: Arc<spec::mesh::MeshInput>,
    /// `(property name, array name)`: which of the output's arrays become
    /// which vertex property (`("label", "labels")`).
    pub vertex_properties: Vec<(&'static str, &'static str)>,
}

/// One named output array.
#[derive(Debug, Clone)]
pub struct OutputArray {
    /// Name of the output (`distance`); the key of its reference in the answer.
    pub name: String,
    /// The values.
    pub array: ArrayData,
    /// Physical spacing per axis (stored with the dataset), if it has one.
    pub spacing: Option<Vec<f64>>,
}

/// An input array with the spacing its file declared (NIfTI voxel size), if any.
#[derive(Debug, Clone)]
pub struct InputArray {
    /// The values.
    pub array: Arc<ArrayData>,
    /// Physical spacing per axis, if the source format carries one.
    pub spacing: Option<Vec<f64>>,
}

/// Where an operation finds the datasets its request names.
pub trait Inputs {
    /// The dataset with this id, if it exists.
    fn get(&self, id: &str) -> Option<InputArray>;

    /// The mesh dataset with this id, if it exists and is a mesh. Default: none.
    fn mesh(&self, _id: &str) -> Option<Arc<spec::mesh::MeshInput>> {
        None
    }

    /// The heat-method solver of mesh `id` with `options`: from the
    /// caller's cache when it keeps one, else built by `build` (the default
    /// builds every time).
    fn heat_solver(
        &self,
        _id: &str,
        _options: &HeatOptions,
        build: &mut dyn FnMut() -> Result<HeatSolver, MeshSolveError>,
    ) -> Result<(Arc<HeatSolver>, bool), MeshSolveError> {
        build().map(|s| (Arc::new(s), false))
    }

    /// The caller's cache of designed costs and distance maps for
    /// interactive paths, if it keeps one. Default: none.
    fn distance_cache(&self) -> Option<&dyn grid_paths::MapCache> {
        None
    }
}

/// Where an operation finds the datasets its request names: those an
/// [`Operation`] reads, plus what the caller keeps between requests.
impl Inputs for std::collections::HashMap<String, InputArray> {
    fn get(&self, id: &str) -> Option<InputArray> {
        std::collections::HashMap::get(self, id).cloned()
    }
}

/// Why an operation was refused or interrupted. `field` is a JSON path into
/// the request (`sources[2].point`, `cost.dataset`) so that clients can point
/// at the culprit.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum OpError {
    /// The request is well-formed JSON but a value is not acceptable.
    #[error("{field}: {reason}")]
    Invalid {
        /// Path of the offending field.
        field: String,
        /// Why it is refused.
        reason: String,
    },
    /// A dataset named by the request does not exist.
    #[error("{field}: dataset '{id}' not found")]
    UnknownDataset {
        /// Path of the field naming it.
        field: String,
        /// The id given.
        id: String,
    },
    /// The request asks for more than the configured limits allow.
    #[error("{field}: {reason}")]
    TooLarge {
        /// Path of the offending field.
        field: String,
        /// The limit that was exceeded.
        reason: String,
    },
    /// The caller cancelled the computation.
    #[error("cancelled")]
    Cancelled,
}

impl OpError {
    /// Shorthand for [`OpError::Invalid`].
    pub fn invalid(field: impl Into<String>, reason: impl Into<String>) -> Self {
        OpError::Invalid {
            field: field.into(),
            reason: reason.into(),
        }
    }

    /// The field this error points at, if any.
    pub fn field(&self) -> Option<&str> {
        match self {
            OpError::Invalid { field, .. }
            | OpError::UnknownDataset { field, .. }
            | OpError::TooLarge { field, .. } => Some(field),
            OpError::Cancelled => None,
        }
    }
}

/// Limits an operation enforces before it allocates anything.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OpLimits {
    /// Largest grid, in cells.
    pub max_cells: usize,
    /// Most sources in one request.
    pub max_sources: usize,
}

impl Default for OpLimits {
    fn default() -> Self {
        Self {
            max_cells: 512 * 512 * 512,
            max_sources: 100_000,
        }
    }
}
