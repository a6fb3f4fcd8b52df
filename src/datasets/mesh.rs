//! Mesh datasets: stored as binary PLY (`data.ply`, with the per-vertex
//! `distance` and `label` of results) beside `meta.json`; decoded meshes and
//! their topology are cached, and so are heat-method factorisations, keyed
//! by dataset id and time-step factor `m`, so that repeated heat queries on
//! one mesh cost two solves each.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use chrono::{DateTime, Utc};

use super::{lock, new_id, DatasetKind, DatasetMeta, DatasetStore, SourceFormat, StoreError};
use crate::io::mesh::write::{write_ply, VertexProperty};
use crate::io::mesh::{read_mesh, MeshFormat, MeshLimits, MeshReport};
use crate::io::DType;
use crate::numerics::mesh::{HeatSolver, TriMesh};

pub use crate::ops::spec::mesh::MeshInput;

/// Most meshes and factorisations kept in memory.
const MESH_CACHE_ENTRIES: usize = 8;
const HEAT_CACHE_ENTRIES: usize = 4;

type HeatSlot = Arc<Mutex<Option<Arc<HeatSolver>>>>;
/// Entries with their last-use tick, and the clock.
type Lru<K, V> = Mutex<(HashMap<K, (V, u64)>, u64)>;

/// Caches of decoded meshes and heat factorisations (least recently used out).
#[derive(Debug, Default)]
pub struct MeshCache {
    meshes: Lru<String, Arc<MeshInput>>,
    /// One slot per (id, m bits): concurrent requests for the same
    /// factorisation wait for one build instead of racing.
    heat: Lru<(String, u64), HeatSlot>,
}

impl MeshCache {
    pub(super) fn forget(&self, id: &str) {
        lock(&self.meshes).0.remove(id);
        lock(&self.heat).0.retain(|k, _| k.0 != id);
    }
}

impl DatasetStore {
    /// Stores a mesh (blocking) as binary PLY with optional per-vertex
    /// properties, written atomically like arrays.
    pub fn create_mesh_blocking(
        &self,
        mesh: &TriMesh,
        report: MeshReport,
        props: &[VertexProperty<'_>],
        source_format: SourceFormat,
    ) -> Result<DatasetMeta, StoreError> {
        let ply = write_ply(mesh, props);
        let size = ply.len() as u64;
        self.reserve(size)?;
        let id = new_id();
        let created_at = Utc::now();
        let ttl = chrono::Duration::from_std(self.config.ttl).unwrap_or(chrono::Duration::MAX);
        let meta = DatasetMeta {
            id: id.clone(),
            kind: DatasetKind::Mesh,
            shape: vec![mesh.num_vertices(), 3],
            dtype: DType::F64,
            spacing: None,
            byte_size: size,
            created_at,
            expires_at: created_at
                .checked_add_signed(ttl)
                .unwrap_or(DateTime::<Utc>::MAX_UTC),
            source_format,
            mesh: Some(report),
        };
        let tmp = self.root.join(format!(".tmp-{id}"));
        let write = || -> Result<(), StoreError> {
            std::fs::create_dir_all(&tmp)?;
            std::fs::write(tmp.join("data.ply"), &ply)?;
            let json =
                serde_json::to_vec_pretty(&meta).map_err(|e| StoreError::Io(e.to_string()))?;
            std::fs::write(tmp.join("meta.json"), json)?;
            std::fs::rename(&tmp, self.root.join(&id))?;
            Ok(())
        };
        let result = write().inspect_err(|_| {
            let _ = std::fs::remove_dir_all(&tmp);
        });
        let mut index = lock(&self.index);
        match result {
            Ok(()) => {
                index.entries.insert(id, meta.clone());
                Ok(meta)
            }
            Err(e) => {
                index.used = index.used.saturating_sub(size);
                Err(e)
            }
        }
    }

    /// The stored PLY bytes of a live mesh dataset (blocking).
    pub fn read_mesh_file_blocking(&self, id: &str) -> Result<Vec<u8>, StoreError> {
        let meta = self.meta(id)?;
        if meta.kind != DatasetKind::Mesh {
            return Err(not_a_mesh(id));
        }
        std::fs::read(self.root.join(id).join("data.ply")).map_err(|e| match e.kind() {
            std::io::ErrorKind::NotFound => StoreError::NotFound(id.into()),
            _ => e.into(),
        })
    }

    /// The decoded mesh of a live dataset (blocking), cached.
    pub fn load_mesh_blocking(&self, id: &str) -> Result<Arc<MeshInput>, StoreError> {
        let meta = self.meta(id)?;
        {
            let mut c = lock(&self.meshes.meshes);
            c.1 += 1;
            let tick = c.1;
            if let Some((m, t)) = c.0.get_mut(id) {
                *t = tick;
                return Ok(m.clone());
            }
        }
        let bytes = self.read_mesh_file_blocking(id)?;
        let limits = MeshLimits::default();
        let loaded = read_mesh(&bytes, Some(MeshFormat::Ply), &limits)
            .map_err(|e| StoreError::Io(format!("stored mesh '{id}' is unreadable: {e}")))?;
        let input = Arc::new(MeshInput {
            mesh: loaded.mesh,
            topology: loaded.topology,
            report: meta.mesh.unwrap_or(loaded.report),
        });
        let mut c = lock(&self.meshes.meshes);
        if c.0.len() >= MESH_CACHE_ENTRIES {
            if let Some(k) =
                c.0.iter()
                    .min_by_key(|(_, (_, t))| *t)
                    .map(|(k, _)| k.clone())
            {
                c.0.remove(&k);
            }
        }
        c.1 += 1;
        let tick = c.1;
        c.0.insert(id.to_string(), (input.clone(), tick));
        Ok(input)
    }

    /// The heat solver of mesh dataset `id` with time-step factor `m`,
    /// built by `build` on first use (on the caller's thread: the solver
    /// pool) and kept for later queries.
    pub fn heat_solver<E>(
        &self,
        id: &str,
        m: f64,
        build: impl FnOnce() -> Result<HeatSolver, E>,
    ) -> Result<(Arc<HeatSolver>, bool), E> {
        let slot = {
            let mut c = lock(&self.meshes.heat);
            c.1 += 1;
            let tick = c.1;
            let key = (id.to_string(), m.to_bits());
            if !c.0.contains_key(&key) && c.0.len() >= HEAT_CACHE_ENTRIES {
                if let Some(k) =
                    c.0.iter()
                        .min_by_key(|(_, (_, t))| *t)
                        .map(|(k, _)| k.clone())
                {
                    c.0.remove(&k);
                }
            }
            let entry =
                c.0.entry(key)
                    .or_insert_with(|| (HeatSlot::default(), tick));
            entry.1 = tick;
            entry.0.clone()
        };
        let mut guard = lock(&slot);
        if let Some(s) = guard.as_ref() {
            return Ok((s.clone(), true));
        }
        let solver = Arc::new(build()?);
        *guard = Some(solver.clone());
        Ok((solver, false))
    }

    /// Async [`Self::load_mesh_blocking`].
    pub async fn load_mesh(self: &Arc<Self>, id: &str) -> Result<Arc<MeshInput>, StoreError> {
        let store = Arc::clone(self);
        let id = id.to_string();
        super::blocking(move || store.load_mesh_blocking(&id)).await
    }
}

fn not_a_mesh(id: &str) -> StoreError {
    StoreError::Codec(crate::io::IoError::Unsupported {
        format: crate::io::Format::Npy,
        reason: format!("dataset '{id}' is not a mesh"),
    })
}
