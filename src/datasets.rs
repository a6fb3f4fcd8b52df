//! The dataset store: arrays kept as canonical NPY files under
//! `<data_dir>/datasets/<id>/` with a `meta.json` beside them.
//!
//! * **Atomic writes.** A dataset is written into a temporary directory and
//!   renamed into place, so a reader never sees a half-written one.
//! * **Quota.** The total `byte_size` of stored datasets never exceeds the
//!   quota; a write that would is refused ([`StoreError::Quota`]).
//! * **Expiry.** Every dataset expires `ttl` after its creation; an expired
//!   one is reported as missing and removed by [`DatasetStore::sweep_expired`].
//! * **Cache.** Decoded arrays are kept in a byte-bounded LRU so repeated
//!   solves on the same input do not re-read files.
//!
//! The `*_blocking` functions do file IO; the async wrappers run them on
//! tokio's blocking pool.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use chrono::{DateTime, Utc};
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use crate::io::mesh::{MeshFormat, MeshReport};
use crate::io::{self, ArrayData, DType, Format, IoError, Limits};
use crate::ops::InputArray;

pub mod cache;
pub mod inputs;
pub mod list;
pub mod mesh;

/// Whether a dataset is 2D or 3D.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum DatasetKind {
    /// A 2D array.
    Image,
    /// A 3D array.
    Volume,
    /// A triangle mesh (stored as binary PLY, with per-vertex results).
    Mesh,
}

/// Where a dataset came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum SourceFormat {
    /// Uploaded as NPY.
    Npy,
    /// Uploaded as PNG.
    Png,
    /// Uploaded as JPEG.
    Jpeg,
    /// Uploaded as TIFF.
    Tiff,
    /// Uploaded as NIfTI.
    Nifti,
    /// Computed by an operation.
    Result,
    /// Uploaded as OBJ.
    Obj,
    /// Uploaded as PLY.
    Ply,
    /// Uploaded as OFF.
    Off,
    /// Uploaded as STL.
    Stl,
}

impl From<MeshFormat> for SourceFormat {
    fn from(f: MeshFormat) -> Self {
        match f {
            MeshFormat::Obj => SourceFormat::Obj,
            MeshFormat::Ply => SourceFormat::Ply,
            MeshFormat::Off => SourceFormat::Off,
            MeshFormat::Stl => SourceFormat::Stl,
        }
    }
}

impl From<Format> for SourceFormat {
    fn from(f: Format) -> Self {
        match f {
            Format::Npy => SourceFormat::Npy,
            Format::Png => SourceFormat::Png,
            Format::Jpeg => SourceFormat::Jpeg,
            Format::Tiff => SourceFormat::Tiff,
            Format::Nifti => SourceFormat::Nifti,
        }
    }
}

/// What the store knows about a dataset (`GET /v1/datasets/{id}`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[schema(example = json!({
    "id": "ds_0192f1b27c1e7d3a9d553c0f2b8a1e44",
    "kind": "image",
    "shape": [256, 256],
    "dtype": "f32",
    "spacing": null,
    "byte_size": 262272,
    "created_at": "2026-11-22T10:00:00Z",
    "expires_at": "2026-11-23T10:00:00Z",
    "source_format": "png"
}))]
pub struct DatasetMeta {
    /// The id (`ds_` followed by 32 hex digits).
    pub id: String,
    /// `image` (2D), `volume` (3D) or `mesh`.
    pub kind: DatasetKind,
    /// Shape, axis 0 first (a mesh: `[vertices, 3]`; results per vertex or
    /// per triangle are 1D).
    #[schema(min_items = 1, max_items = 3)]
    pub shape: Vec<usize>,
    /// Element type.
    pub dtype: DType,
    /// Physical spacing per axis (axis 0 first), when the file carried one.
    #[schema(min_items = 2, max_items = 3)]
    pub spacing: Option<Vec<f64>>,
    /// Bytes it takes in storage (the NPY file).
    pub byte_size: u64,
    /// Creation time (UTC).
    pub created_at: DateTime<Utc>,
    /// Time after which it is deleted (UTC).
    pub expires_at: DateTime<Utc>,
    /// The format it was uploaded in, or `result`.
    pub source_format: SourceFormat,
    /// Meshes only: vertex, face, boundary-loop and component counts and
    /// what reading repaired.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mesh: Option<MeshReport>,
    /// The tenant that owns it (the API key's; absent when auth is off).
    /// Another tenant is answered 404 for it.
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub tenant: String,
}

/// Who owns what a request stores, and how much that tenant may store.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Owner {
    /// The tenant (`""` when auth is off).
    pub tenant: String,
    /// The tenant's own storage quota in bytes, beside the service's.
    pub quota_bytes: Option<u64>,
}

impl Owner {
    /// The owner of everything when auth is off.
    pub fn anonymous() -> Self {
        Self::default()
    }
}

/// Why a store operation failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StoreError {
    /// No dataset with this id (or it expired).
    #[error("dataset '{0}' not found")]
    NotFound(String),
    /// Writing would exceed the storage quota.
    #[error(
        "storing {needed} bytes would exceed the storage quota ({used} of {quota} bytes used)"
    )]
    Quota {
        /// Bytes the write needs.
        needed: u64,
        /// Bytes in use.
        used: u64,
        /// The quota.
        quota: u64,
    },
    /// Writing would exceed the tenant's own quota.
    #[error(
        "storing {needed} bytes would exceed the storage quota of tenant '{tenant}' \
         ({used} of {quota} bytes used)"
    )]
    TenantQuota {
        /// The tenant.
        tenant: String,
        /// Bytes the write needs.
        needed: u64,
        /// Bytes the tenant uses.
        used: u64,
        /// Its quota.
        quota: u64,
    },
    /// The stored file could not be decoded or the array encoded.
    #[error(transparent)]
    Codec(#[from] IoError),
    /// A file-system error.
    #[error("storage IO error: {0}")]
    Io(String),
    /// The disk of the data directory is full (whatever the quota says).
    #[error("the disk of the data directory is full")]
    DiskFull,
}

impl From<std::io::Error> for StoreError {
    fn from(e: std::io::Error) -> Self {
        if e.kind() == std::io::ErrorKind::StorageFull {
            StoreError::DiskFull
        } else {
            StoreError::Io(e.to_string())
        }
    }
}

/// Settings of a [`DatasetStore`].
#[derive(Debug, Clone)]
pub struct StoreConfig {
    /// The data directory; datasets live under `<root>/datasets`.
    pub data_dir: PathBuf,
    /// Largest total `byte_size`.
    pub quota_bytes: u64,
    /// Lifetime of a dataset.
    pub ttl: Duration,
    /// Largest total size of what is kept in memory between requests:
    /// decoded arrays, meshes with their topology, heat factorisations,
    /// designed costs and distance maps (one budget).
    pub cache_bytes: usize,
    /// Of `cache_bytes`, the most for designed costs and distance maps (0:
    /// none are kept).
    pub path_cache_bytes: usize,
    /// Limits applied when reading stored files back.
    pub limits: Limits,
}

#[derive(Debug, Default)]
struct Index {
    entries: HashMap<String, DatasetMeta>,
    used: u64,
    /// Bytes in use per tenant (reserved writes included).
    by_tenant: HashMap<String, u64>,
    /// Each tenant's own quota, as its key said at its latest request (a job
    /// worker, which has no key in hand, applies it to the job's results).
    quotas: HashMap<String, u64>,
}

impl Index {
    /// Counts `bytes` more (or fewer) against the store and `tenant`.
    fn charge(&mut self, tenant: &str, bytes: u64) {
        self.used = self.used.saturating_add(bytes);
        *self.by_tenant.entry(tenant.to_string()).or_default() += bytes;
    }

    fn refund(&mut self, tenant: &str, bytes: u64) {
        self.used = self.used.saturating_sub(bytes);
        if let Some(u) = self.by_tenant.get_mut(tenant) {
            *u = u.saturating_sub(bytes);
        }
    }

    /// Adds a dataset whose bytes were not reserved (found on disk).
    fn add_found(&mut self, meta: DatasetMeta) {
        self.charge(&meta.tenant, meta.byte_size);
        self.entries.insert(meta.id.clone(), meta);
    }
}

/// The dataset store; share it as `Arc<DatasetStore>`.
#[derive(Debug)]
pub struct DatasetStore {
    root: PathBuf,
    config: StoreConfig,
    index: Mutex<Index>,
    /// Decoded arrays, meshes and heat factorisations, in one byte budget.
    memory: cache::MemoryCache,
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    // A poisoned lock only means a panic elsewhere; the data is still consistent
    // because every critical section here is a few plain assignments.
    m.lock().unwrap_or_else(|p| p.into_inner())
}

/// True if `id` has the shape of a dataset id (and so is safe in a path).
pub fn valid_id(id: &str) -> bool {
    id.len() == 35
        && id.starts_with("ds_")
        && id[3..]
            .bytes()
            .all(|b| b.is_ascii_hexdigit() && !b.is_ascii_uppercase())
}

fn new_id() -> String {
    format!("ds_{}", uuid::Uuid::now_v7().simple())
}

impl DatasetStore {
    /// Opens (creating it if needed) the store, loads the metadata of the
    /// datasets already there, and removes leftovers of interrupted writes.
    pub fn open(config: StoreConfig) -> Result<Self, StoreError> {
        let root = config.data_dir.join("datasets");
        std::fs::create_dir_all(&root)?;
        let mut index = Index::default();
        for entry in std::fs::read_dir(&root)? {
            let entry = entry?;
            let name = entry.file_name().to_string_lossy().into_owned();
            if !valid_id(&name) {
                if name.starts_with(".tmp-") || name.starts_with(".del-") {
                    let _ = std::fs::remove_dir_all(entry.path());
                }
                continue;
            }
            let meta = std::fs::read(entry.path().join("meta.json"))
                .ok()
                .and_then(|b| serde_json::from_slice::<DatasetMeta>(&b).ok());
            match meta {
                Some(m) if m.id == name => index.add_found(m),
                _ => {
                    let _ = std::fs::remove_dir_all(entry.path());
                }
            }
        }
        Ok(Self {
            root,
            index: Mutex::new(index),
            memory: cache::MemoryCache::new(config.cache_bytes)
                .with_path_share(config.path_cache_bytes),
            config,
        })
    }

    /// The directory holding the datasets.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// Bytes in use and the quota.
    pub fn usage(&self) -> (u64, u64) {
        (lock(&self.index).used, self.config.quota_bytes)
    }

    /// Bytes `tenant` uses.
    pub fn tenant_usage(&self, tenant: &str) -> u64 {
        lock(&self.index)
            .by_tenant
            .get(tenant)
            .copied()
            .unwrap_or(0)
    }

    /// True if the store directory exists and is a directory.
    pub fn is_usable(&self) -> bool {
        std::fs::metadata(&self.root).is_ok_and(|m| m.is_dir() && !m.permissions().readonly())
    }

    /// The metadata of a live dataset.
    ///
    /// A dataset this process does not know yet is looked up on disk: when
    /// several replicas share the data directory, one of them may have
    /// written it after this one started.
    pub fn meta(&self, id: &str) -> Result<DatasetMeta, StoreError> {
        {
            let index = lock(&self.index);
            match index.entries.get(id) {
                Some(m) if m.expires_at > Utc::now() => return Ok(m.clone()),
                Some(_) => return Err(StoreError::NotFound(id.into())),
                None => {}
            }
        }
        self.discover(id)
    }

    /// The metadata of a live dataset of `tenant`: another tenant's dataset
    /// is [`StoreError::NotFound`], as if it did not exist.
    pub fn meta_of(&self, id: &str, tenant: &str) -> Result<DatasetMeta, StoreError> {
        self.meta(id).and_then(|m| {
            if m.tenant == tenant {
                Ok(m)
            } else {
                Err(StoreError::NotFound(id.into()))
            }
        })
    }

    /// Adds a dataset written by another process sharing the directory.
    fn discover(&self, id: &str) -> Result<DatasetMeta, StoreError> {
        if !valid_id(id) {
            return Err(StoreError::NotFound(id.into()));
        }
        let meta = std::fs::read(self.root.join(id).join("meta.json"))
            .ok()
            .and_then(|b| serde_json::from_slice::<DatasetMeta>(&b).ok())
            .filter(|m| m.id == id && m.expires_at > Utc::now())
            .ok_or_else(|| StoreError::NotFound(id.into()))?;
        let mut index = lock(&self.index);
        if !index.entries.contains_key(id) {
            // Deletion renames the directory under this lock: a dataset
            // whose `meta.json` was read just before is not brought back.
            if !self.root.join(id).is_dir() {
                return Err(StoreError::NotFound(id.into()));
            }
            index.add_found(meta.clone());
        }
        Ok(meta)
    }

    /// Stores an array (blocking): NPY + `meta.json`, written atomically.
    pub fn create_blocking(
        &self,
        array: &ArrayData,
        spacing: Option<Vec<f64>>,
        source_format: SourceFormat,
        owner: &Owner,
    ) -> Result<DatasetMeta, StoreError> {
        let npy = io::encode_npy(array)?;
        let size = npy.len() as u64;
        self.reserve(size, owner)?;
        let id = new_id();
        let result = self.write(&id, &npy, array, spacing, source_format, owner);
        self.settle(id, size, owner, result)
    }

    /// Counts `size` bytes against the service's quota and the owner's,
    /// or says which is full.
    pub(crate) fn reserve(&self, size: u64, owner: &Owner) -> Result<(), StoreError> {
        let mut index = lock(&self.index);
        if index.used.saturating_add(size) > self.config.quota_bytes {
            return Err(StoreError::Quota {
                needed: size,
                used: index.used,
                quota: self.config.quota_bytes,
            });
        }
        if let Some(q) = owner.quota_bytes {
            index.quotas.insert(owner.tenant.clone(), q);
        }
        if let Some(quota) = owner
            .quota_bytes
            .or_else(|| index.quotas.get(&owner.tenant).copied())
        {
            let used = index.by_tenant.get(&owner.tenant).copied().unwrap_or(0);
            if used.saturating_add(size) > quota {
                return Err(StoreError::TenantQuota {
                    tenant: owner.tenant.clone(),
                    needed: size,
                    used,
                    quota,
                });
            }
        }
        index.charge(&owner.tenant, size);
        Ok(())
    }

    /// Gives back `size` reserved bytes (a write that failed or a file removed).
    pub(crate) fn release(&self, size: u64, tenant: &str) {
        lock(&self.index).refund(tenant, size);
    }

    /// Counts bytes stored elsewhere against the quotas without checking
    /// them (the job results found at start-up).
    pub(crate) fn charge_found(&self, size: u64, tenant: &str) {
        lock(&self.index).charge(tenant, size);
    }

    /// Records a written dataset, or gives its reservation back.
    fn settle(
        &self,
        id: String,
        size: u64,
        owner: &Owner,
        result: Result<DatasetMeta, StoreError>,
    ) -> Result<DatasetMeta, StoreError> {
        let mut index = lock(&self.index);
        match result {
            Ok(meta) => {
                index.entries.insert(id, meta.clone());
                Ok(meta)
            }
            Err(e) => {
                index.refund(&owner.tenant, size);
                Err(e)
            }
        }
    }

    fn write(
        &self,
        id: &str,
        npy: &[u8],
        array: &ArrayData,
        spacing: Option<Vec<f64>>,
        source_format: SourceFormat,
        owner: &Owner,
    ) -> Result<DatasetMeta, StoreError> {
        let created_at = Utc::now();
        let ttl = chrono::Duration::from_std(self.config.ttl).unwrap_or(chrono::Duration::MAX);
        let meta = DatasetMeta {
            id: id.into(),
            kind: if array.shape().len() >= 3 {
                DatasetKind::Volume
            } else {
                DatasetKind::Image
            },
            shape: array.shape().to_vec(),
            dtype: array.dtype(),
            spacing,
            byte_size: npy.len() as u64,
            created_at,
            expires_at: created_at
                .checked_add_signed(ttl)
                .unwrap_or(DateTime::<Utc>::MAX_UTC),
            source_format,
            mesh: None,
            tenant: owner.tenant.clone(),
        };
        let tmp = self.root.join(format!(".tmp-{id}"));
        let write = || -> Result<(), StoreError> {
            std::fs::create_dir_all(&tmp)?;
            std::fs::write(tmp.join("data.npy"), npy)?;
            let json =
                serde_json::to_vec_pretty(&meta).map_err(|e| StoreError::Io(e.to_string()))?;
            std::fs::write(tmp.join("meta.json"), json)?;
            std::fs::rename(&tmp, self.root.join(id))?;
            Ok(())
        };
        write().inspect_err(|_| {
            let _ = std::fs::remove_dir_all(&tmp);
        })?;
        Ok(meta)
    }

    /// The NPY bytes of a live dataset (blocking).
    pub fn read_npy_blocking(&self, id: &str) -> Result<Vec<u8>, StoreError> {
        self.meta(id)?;
        std::fs::read(self.root.join(id).join("data.npy")).map_err(|e| match e.kind() {
            std::io::ErrorKind::NotFound => StoreError::NotFound(id.into()),
            _ => e.into(),
        })
    }

    /// The decoded array of a live dataset (blocking), from the cache when
    /// possible.
    pub fn load_blocking(&self, id: &str) -> Result<InputArray, StoreError> {
        let meta = self.meta(id)?;
        if meta.kind == DatasetKind::Mesh {
            return Err(StoreError::Codec(IoError::Unsupported {
                format: Format::Npy,
                reason: format!("dataset '{id}' is a mesh, not an array"),
            }));
        }
        if let Some(cache::CacheValue::Array(input)) =
            self.memory.get(&cache::CacheKey::Array(id.to_string()))
        {
            return Ok(input);
        }
        let bytes = self.read_npy_blocking(id)?;
        let decoded = io::decode(&bytes, Some(Format::Npy), &self.config.limits)?;
        let input = InputArray {
            array: Arc::new(decoded.array),
            spacing: meta.spacing,
        };
        self.cache_insert(id, &input);
        Ok(input)
    }

    fn cache_insert(&self, id: &str, input: &InputArray) {
        self.memory.insert(
            cache::CacheKey::Array(id.to_string()),
            cache::CacheValue::Array(input.clone()),
            input.array.nbytes(),
        );
    }

    /// Bytes of decoded arrays, meshes, factorisations, costs and maps
    /// held in memory.
    pub fn cached_bytes(&self) -> usize {
        self.memory.bytes()
    }

    /// The one memory budget of everything kept between requests.
    pub fn memory_cache(&self) -> &cache::MemoryCache {
        &self.memory
    }

    /// Deletes a dataset (blocking).
    ///
    /// The directory is first renamed to `.del-<id>` while the index is
    /// locked, so that no request (here or in a replica sharing the
    /// directory) can find the dataset half removed and bring it back
    /// through [`Self::discover`]; a dataset whose directory another replica
    /// already removed is [`StoreError::NotFound`].
    pub fn delete_blocking(&self, id: &str) -> Result<(), StoreError> {
        let doomed = self.root.join(format!(".del-{id}"));
        let meta = {
            let mut index = lock(&self.index);
            let meta = index
                .entries
                .remove(id)
                .ok_or_else(|| StoreError::NotFound(id.into()))?;
            index.refund(&meta.tenant, meta.byte_size);
            self.memory.forget(id);
            match std::fs::rename(self.root.join(id), &doomed) {
                Ok(()) => {}
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                    return Err(StoreError::NotFound(id.into()))
                }
                Err(e) => return Err(e.into()),
            }
            meta
        };
        // Leftovers of a failed removal go at the next start (`.del-`).
        let _ = std::fs::remove_dir_all(&doomed);
        if meta.expires_at <= Utc::now() {
            return Err(StoreError::NotFound(id.into()));
        }
        Ok(())
    }

    /// Removes every expired dataset (blocking); returns how many.
    pub fn sweep_expired_blocking(&self) -> usize {
        let now = Utc::now();
        let expired: Vec<String> = lock(&self.index)
            .entries
            .values()
            .filter(|m| m.expires_at <= now)
            .map(|m| m.id.clone())
            .collect();
        for id in &expired {
            // An expired dataset reports NotFound once deleted; IO errors are
            // retried at the next sweep.
            let _ = self.delete_blocking(id);
        }
        expired.len()
    }

    /// Async [`Self::create_blocking`].
    pub async fn create(
        self: &Arc<Self>,
        array: Arc<ArrayData>,
        spacing: Option<Vec<f64>>,
        source_format: SourceFormat,
        owner: Owner,
    ) -> Result<DatasetMeta, StoreError> {
        let store = Arc::clone(self);
        blocking(move || {
            let meta = store.create_blocking(&array, spacing, source_format, &owner)?;
            // A result is usually fetched right away (a picture, an NPY):
            // keep the decoded array, which costs no copy.
            store.cache_insert(
                &meta.id,
                &InputArray {
                    array,
                    spacing: meta.spacing.clone(),
                },
            );
            Ok(meta)
        })
        .await
    }

    /// Async [`Self::load_blocking`].
    pub async fn load(self: &Arc<Self>, id: &str) -> Result<InputArray, StoreError> {
        let store = Arc::clone(self);
        let id = id.to_string();
        blocking(move || store.load_blocking(&id)).await
    }

    /// Async [`Self::delete_blocking`].
    pub async fn delete(self: &Arc<Self>, id: &str) -> Result<(), StoreError> {
        let store = Arc::clone(self);
        let id = id.to_string();
        blocking(move || store.delete_blocking(&id)).await
    }

    /// Async [`Self::sweep_expired_blocking`].
    pub async fn sweep_expired(self: &Arc<Self>) -> usize {
        let store = Arc::clone(self);
        blocking(move || Ok(store.sweep_expired_blocking()))
            .await
            .unwrap_or(0)
    }
}

/// Runs blocking file work on tokio's blocking pool.
pub async fn blocking<T, F>(f: F) -> Result<T, StoreError>
where
    T: Send + 'static,
    F: FnOnce() -> Result<T, StoreError> + Send + 'static,
{
    tokio::task::spawn_blocking(f)
        .await
        .map_err(|e| StoreError::Io(format!("storage task failed: {e}")))?
}

#[cfg(test)]
mod tests {
    use super::*;

    fn open(dir: &Path) -> Arc<DatasetStore> {
        Arc::new(
            DatasetStore::open(StoreConfig {
                path_cache_bytes: 0,
                data_dir: dir.to_path_buf(),
                quota_bytes: 1 << 30,
                ttl: Duration::from_secs(3600),
                cache_bytes: 1 << 20,
                limits: Limits::default(),
            })
            .expect("store"),
        )
    }

    fn create(store: &DatasetStore) -> String {
        let a = ArrayData::F64(ndarray::ArrayD::zeros(vec![2, 2]));
        store
            .create_blocking(&a, None, SourceFormat::Npy, &Owner::anonymous())
            .expect("create")
            .id
    }

    /// Two replicas share a data directory: one deletes, the other, which
    /// knew the dataset, gets a 404 (it used to get an IO error, a 500).
    #[test]
    fn a_dataset_deleted_by_a_replica_is_not_found_not_an_io_error() {
        let dir = tempfile::tempdir().expect("tempdir");
        let (a, b) = (open(dir.path()), open(dir.path()));
        let id = create(&a);
        assert!(b.meta(&id).is_ok(), "the replica discovers it");
        a.delete_blocking(&id).expect("delete");
        assert!(matches!(
            b.delete_blocking(&id),
            Err(StoreError::NotFound(_))
        ));
        assert_eq!(b.usage().0, 0, "the replica's quota is refunded");
        assert!(matches!(b.meta(&id), Err(StoreError::NotFound(_))));
    }

    /// Deletes racing with lookups of the same dataset (two DELETEs at once,
    /// or a GET during a DELETE): each ends in success or not-found, the
    /// dataset is never brought back from its half-removed directory, and
    /// the quota ends at zero. The old order (unindex, then remove the
    /// directory) let a lookup re-read `meta.json` mid-removal, and the
    /// second DELETE then failed on the vanished directory.
    #[test]
    fn racing_deletes_and_lookups_end_in_success_or_not_found() {
        let dir = tempfile::tempdir().expect("tempdir");
        let store = open(dir.path());
        let ids: Vec<String> = (0..300).map(|_| create(&store)).collect();
        let ids = Arc::new(ids);
        let workers: Vec<_> = (0..3)
            .map(|w| {
                let (store, ids) = (Arc::clone(&store), Arc::clone(&ids));
                std::thread::spawn(move || {
                    let mut deleted = 0;
                    for id in ids.iter() {
                        if w == 2 {
                            let _ = store.meta(id);
                            continue;
                        }
                        match store.delete_blocking(id) {
                            Ok(()) => deleted += 1,
                            Err(StoreError::NotFound(_)) => {}
                            Err(e) => panic!("delete {id}: {e}"),
                        }
                    }
                    deleted
                })
            })
            .collect();
        let deleted: usize = workers.into_iter().map(|w| w.join().expect("worker")).sum();
        assert_eq!(deleted, ids.len(), "every dataset deleted exactly once");
        for id in ids.iter() {
            assert!(
                matches!(store.meta(id), Err(StoreError::NotFound(_))),
                "{id}"
            );
        }
        assert_eq!(store.usage().0, 0);
        let left: Vec<_> = std::fs::read_dir(store.root())
            .expect("read_dir")
            .map(|e| e.expect("entry").file_name())
            .collect();
        assert!(left.is_empty(), "nothing left on disk: {left:?}");
    }
}
