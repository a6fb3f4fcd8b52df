//! Mesh datasets: stored as binary PLY (`data.ply`, with the per-vertex
//! `distance` and `label` of results) beside `meta.json`; decoded meshes and
//! their topology are cached, and so are heat-method factorisations, keyed
//! by dataset id and time-step factor `m`, so that repeated heat queries on
//! one mesh cost two solves each; both count against the store's one
//! memory budget ([`super::cache::MemoryCache`]).

use std::sync::Arc;

use chrono::{DateTime, Utc};

use super::cache::{CacheKey, CacheValue};
use super::{
    lock, new_id, DatasetKind, DatasetMeta, DatasetStore, Owner, SourceFormat, StoreError,
};
use crate::io::mesh::write::{write_ply, VertexProperty};
use crate::io::mesh::{read_mesh, MeshFormat, MeshLimits, MeshReport};
use crate::io::DType;
use crate::numerics::mesh::{HeatOptions, HeatSolver, TriMesh};

pub use crate::ops::spec::mesh::MeshInput;

/// Approximate heap bytes of a decoded mesh and its topology (cache
/// accounting): positions and faces, the half-edge and vertex-face tables,
/// the components.
fn mesh_bytes(input: &MeshInput) -> usize {
    let (v, f) = (input.mesh.num_vertices(), input.mesh.num_faces());
    let t = &input.topology;
    v * 24
        + f * 12
        + (t.opposite.len() + t.vertex_face_offsets.len() + t.vertex_faces.len()) * 4
        + t.component.len() * 4
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
        owner: &Owner,
    ) -> Result<DatasetMeta, StoreError> {
        let ply = write_ply(mesh, props);
        let size = ply.len() as u64;
        self.reserve(size, owner)?;
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
            tenant: owner.tenant.clone(),
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
        let result = write()
            .inspect_err(|_| {
                let _ = std::fs::remove_dir_all(&tmp);
            })
            .map(|()| meta);
        self.settle(id, size, owner, result)
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
        let key = CacheKey::Mesh(id.to_string());
        if let Some(CacheValue::Mesh(m)) = self.memory.get(&key) {
            return Ok(m);
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
        let bytes = mesh_bytes(&input);
        self.memory
            .insert(key, CacheValue::Mesh(Arc::clone(&input)), bytes);
        Ok(input)
    }

    /// The heat solver of mesh dataset `id` with the options `options`
    /// (time-step factor and Laplacian), built by `build` on first use (on
    /// the caller's thread: the solver pool) and kept for later queries.
    pub fn heat_solver<E>(
        &self,
        id: &str,
        options: &HeatOptions,
        build: impl FnOnce() -> Result<HeatSolver, E>,
    ) -> Result<(Arc<HeatSolver>, bool), E> {
        let key = CacheKey::Heat(
            id.to_string(),
            options.m.to_bits(),
            options.laplacian,
            options.adapt,
        );
        let slot = self.memory.heat_slot(key.clone());
        let mut guard = lock(&slot);
        if let Some(s) = guard.as_ref() {
            return Ok((s.clone(), true));
        }
        let solver = Arc::new(build()?);
        *guard = Some(solver.clone());
        drop(guard);
        self.memory.resize(&key, solver.approx_bytes());
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
