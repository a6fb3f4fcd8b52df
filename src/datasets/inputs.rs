//! [`StoreInputs`]: the datasets a request names, loaded from the store, as
//! the [`Inputs`] an operation reads (arrays, meshes, and the store's cache of
//! heat-method factorisations). Used by the HTTP handlers and the job worker
//! alike, so an operation sees the same inputs on both paths.

use std::collections::HashMap;
use std::sync::Arc;

use super::{DatasetStore, StoreError};
use crate::numerics::mesh::{HeatOptions, HeatSolver, MeshSolveError};
use crate::ops::grid_paths::MapCache;
use crate::ops::spec::mesh::MeshInput;
use crate::ops::{InputArray, Inputs};

/// Request fields other than `mesh` that name mesh datasets: the two
/// meshes `a` and `b` of `mesh.correspond`.
pub const OTHER_MESH_FIELDS: &[&str] = &["a", "b"];

/// Why the inputs of a request could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum InputError {
    /// No dataset has this id (or it expired).
    #[error("{field}: dataset '{id}' not found")]
    NotFound {
        /// JSON path of the field naming it.
        field: String,
        /// The id.
        id: String,
    },
    /// The dataset exists but is not of the kind the field needs.
    #[error("{field}: dataset '{id}' is not {expected}")]
    WrongKind {
        /// JSON path of the field naming it.
        field: String,
        /// The id.
        id: String,
        /// "a mesh" or "an array".
        expected: &'static str,
    },
    /// The store failed (IO, quota, ...).
    #[error(transparent)]
    Store(StoreError),
}

/// Arrays and meshes loaded for one request, plus the store's heat cache.
#[derive(Debug)]
pub struct StoreInputs {
    /// Arrays by dataset id.
    pub arrays: HashMap<String, InputArray>,
    /// Meshes by dataset id.
    pub meshes: HashMap<String, Arc<MeshInput>>,
    store: Arc<DatasetStore>,
    /// Whose datasets these may be: another tenant's id is not found.
    tenant: String,
}

impl StoreInputs {
    /// Empty inputs over `store` (arrays may be added, e.g. an uploaded file).
    pub fn new(store: Arc<DatasetStore>) -> Self {
        Self {
            arrays: HashMap::new(),
            meshes: HashMap::new(),
            store,
            tenant: String::new(),
        }
    }

    /// The same inputs for a request of `tenant` (see [`Self::check_access`]).
    pub fn for_tenant(mut self, tenant: &str) -> Self {
        self.tenant = tenant.to_string();
        self
    }

    /// Fails with [`InputError::NotFound`] for the first `(field, id)` that
    /// is not a live dataset of this tenant (ids already present, such as a
    /// request's own upload, pass). The runner calls it for every dataset a
    /// request names, before any cache may stand in for one.
    pub async fn check_access(&self, ids: &[(String, String)]) -> Result<(), InputError> {
        let wanted: Vec<(String, String)> = ids
            .iter()
            .filter(|(_, id)| !self.arrays.contains_key(id) && !self.meshes.contains_key(id))
            .cloned()
            .collect();
        if wanted.is_empty() {
            return Ok(());
        }
        let store = Arc::clone(&self.store);
        let tenant = self.tenant.clone();
        let denied = super::blocking(move || {
            Ok(wanted
                .into_iter()
                .find(|(_, id)| store.meta_of(id, &tenant).is_err()))
        })
        .await
        .map_err(InputError::Store)?;
        match denied {
            Some((field, id)) => Err(InputError::NotFound { field, id }),
            None => Ok(()),
        }
    }

    /// Loads every `(field, id)` not already present: a field named `mesh`
    /// (or ending in `.mesh`, or one of [`OTHER_MESH_FIELDS`]) reads a mesh
    /// dataset, any other an array.
    pub async fn load(&mut self, ids: Vec<(String, String)>) -> Result<(), InputError> {
        for (field, id) in ids {
            if self.arrays.contains_key(&id) || self.meshes.contains_key(&id) {
                continue;
            }
            let is_mesh = field == "mesh"
                || field.ends_with(".mesh")
                || OTHER_MESH_FIELDS.contains(&field.as_str());
            let loaded = if is_mesh {
                self.store
                    .load_mesh(&id)
                    .await
                    .map(|m| drop(self.meshes.insert(id.clone(), m)))
            } else {
                self.store
                    .load(&id)
                    .await
                    .map(|a| drop(self.arrays.insert(id.clone(), a)))
            };
            match loaded {
                Ok(()) => {}
                Err(StoreError::NotFound(_)) => return Err(InputError::NotFound { field, id }),
                Err(StoreError::Codec(_)) => {
                    return Err(InputError::WrongKind {
                        field,
                        id,
                        expected: if is_mesh { "a mesh" } else { "an array" },
                    })
                }
                Err(e) => return Err(InputError::Store(e)),
            }
        }
        Ok(())
    }
}

impl Inputs for StoreInputs {
    fn get(&self, id: &str) -> Option<InputArray> {
        self.arrays.get(id).cloned()
    }

    fn mesh(&self, id: &str) -> Option<Arc<MeshInput>> {
        self.meshes.get(id).cloned()
    }

    fn heat_solver(
        &self,
        id: &str,
        options: &HeatOptions,
        build: &mut dyn FnMut() -> Result<HeatSolver, MeshSolveError>,
    ) -> Result<(Arc<HeatSolver>, bool), MeshSolveError> {
        self.store.heat_solver(id, options, build)
    }

    /// The store's one memory budget keeps the costs and maps.
    fn distance_cache(&self) -> Option<&dyn MapCache> {
        Some(self.store.memory_cache())
    }
}
