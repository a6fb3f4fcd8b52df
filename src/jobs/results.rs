//! Job results in an object store (`object_store`): a local directory by
//! default, a shared directory or S3 (cargo feature `s3`) to scale out.
//!
//! Keys are `results/<job id>/<attempt>/<name>.npy`. Each array is written
//! with `PutMode::Create` (put-if-absent; the local store writes a temporary
//! file and renames it), so an object is complete or absent, never half
//! written, and two attempts of one job never share a key. The job record
//! references the keys only after every array is written (write, then
//! publish); objects of attempts that never published are removed when an
//! attempt succeeds and when the job expires. In a local directory that
//! includes the temporary files of writes that a killed worker left half
//! done (not objects, so never listed): the attempt's directory goes whole.

use std::sync::Arc;

use futures::StreamExt;
use object_store::path::Path as ObjectPath;
use object_store::{ObjectStore, ObjectStoreExt, PutMode, PutOptions, PutPayload};

/// An error of the result store.
#[derive(Debug, thiserror::Error)]
pub enum ResultStoreError {
    /// The store refused or failed.
    #[error("result store: {0}")]
    Store(#[from] object_store::Error),
    /// `--store` is not a recognised URL.
    #[error("--store: {0}")]
    Url(String),
}

/// The problem of a failed result write: a full disk is a 507 (the job
/// fails; running it again would fill the disk again), anything else a 500
/// (the attempt is retried).
pub fn storage_error(e: ResultStoreError) -> crate::problem::ApiError {
    let full = match &e {
        ResultStoreError::Store(object_store::Error::Generic { source, .. }) => {
            is_disk_full(source.as_ref())
        }
        _ => false,
    } || e.to_string().contains("No space left on device");
    if full {
        crate::problem::ApiError::insufficient_storage(
            "the disk of the result store is full; the operator must free space or move \
             --store, then the job can be submitted again",
        )
    } else {
        crate::problem::ApiError::internal(e)
    }
}

/// True if `e` or one of its sources is an IO error for a full disk.
fn is_disk_full(e: &(dyn std::error::Error + 'static)) -> bool {
    let mut next = Some(e);
    while let Some(err) = next {
        if err
            .downcast_ref::<std::io::Error>()
            .is_some_and(|io| io.kind() == std::io::ErrorKind::StorageFull)
        {
            return true;
        }
        next = err.source();
    }
    false
}

/// Where job results live.
#[derive(Debug, Clone)]
pub struct ResultStore {
    store: Arc<dyn ObjectStore>,
    description: String,
    /// The directory of a local store.
    local_root: Option<std::path::PathBuf>,
}

impl ResultStore {
    /// Opens the store named by `url`: `file:///dir` (created if missing) or,
    /// with the `s3` cargo feature, `s3://bucket[/prefix]` (credentials and
    /// region from the usual `AWS_*` environment variables).
    pub fn open(url: &str) -> Result<Self, ResultStoreError> {
        if let Some(dir) = url.strip_prefix("file://") {
            if dir.is_empty() || !dir.starts_with('/') {
                return Err(ResultStoreError::Url(format!(
                    "'{url}': a file store needs an absolute path (file:///srv/geodex)"
                )));
            }
            return Self::local(std::path::Path::new(dir));
        }
        if url.starts_with("s3://") {
            return Self::s3(url);
        }
        Err(ResultStoreError::Url(format!(
            "'{url}': expected file:///absolute/dir or s3://bucket/prefix"
        )))
    }

    /// A store in a local (or shared, NFS) directory.
    pub fn local(dir: &std::path::Path) -> Result<Self, ResultStoreError> {
        std::fs::create_dir_all(dir)
            .map_err(|e| ResultStoreError::Url(format!("{}: {e}", dir.display())))?;
        let store = object_store::local::LocalFileSystem::new_with_prefix(dir)?
            .with_automatic_cleanup(true);
        Ok(Self {
            store: Arc::new(store),
            description: format!("file://{}", dir.display()),
            local_root: Some(dir.to_path_buf()),
        })
    }

    #[cfg(feature = "s3")]
    fn s3(url: &str) -> Result<Self, ResultStoreError> {
        let rest = url.trim_start_matches("s3://");
        let (bucket, prefix) = rest.split_once('/').unwrap_or((rest, ""));
        let s3 = object_store::aws::AmazonS3Builder::from_env()
            .with_bucket_name(bucket)
            .build()?;
        let store: Arc<dyn ObjectStore> = if prefix.trim_matches('/').is_empty() {
            Arc::new(s3)
        } else {
            Arc::new(object_store::prefix::PrefixStore::new(
                s3,
                prefix.trim_matches('/'),
            ))
        };
        Ok(Self {
            store,
            description: url.to_string(),
            local_root: None,
        })
    }

    #[cfg(not(feature = "s3"))]
    fn s3(url: &str) -> Result<Self, ResultStoreError> {
        Err(ResultStoreError::Url(format!(
            "'{url}': this build has no S3 support; rebuild with `--features s3`"
        )))
    }

    /// The URL it was opened with.
    pub fn description(&self) -> &str {
        &self.description
    }

    /// The key of one array of one attempt.
    pub fn key(job: &str, attempt: i64, name: &str) -> String {
        format!("results/{job}/{attempt}/{name}.npy")
    }

    /// Writes an object if it does not exist yet; returns its ETag.
    pub async fn put_new(
        &self,
        key: &str,
        bytes: Vec<u8>,
    ) -> Result<Option<String>, ResultStoreError> {
        let opts = PutOptions {
            mode: PutMode::Create,
            ..Default::default()
        };
        let r = self
            .store
            .put_opts(&ObjectPath::from(key), PutPayload::from(bytes), opts)
            .await?;
        Ok(r.e_tag)
    }

    /// Reads a whole object.
    pub async fn get(&self, key: &str) -> Result<bytes::Bytes, ResultStoreError> {
        let r = self.store.get(&ObjectPath::from(key)).await?;
        Ok(r.bytes().await?)
    }

    /// Deletes every object under `results/<job>/` except those of `keep`
    /// (an attempt number); returns how many were removed.
    pub async fn remove_job(
        &self,
        job: &str,
        keep: Option<i64>,
    ) -> Result<usize, ResultStoreError> {
        let keep = keep.map(|a| format!("results/{job}/{a}/"));
        self.remove_under(&format!("results/{job}"), keep.as_deref())
            .await
    }

    /// Deletes the objects of one attempt (an attempt that will not publish).
    pub async fn remove_job_attempt(
        &self,
        job: &str,
        attempt: i64,
    ) -> Result<usize, ResultStoreError> {
        self.remove_under(&format!("results/{job}/{attempt}"), None)
            .await
    }

    async fn remove_under(
        &self,
        prefix: &str,
        keep: Option<&str>,
    ) -> Result<usize, ResultStoreError> {
        let prefix = ObjectPath::from(prefix);
        let mut listing = self.store.list(Some(&prefix));
        let mut doomed = Vec::new();
        while let Some(meta) = listing.next().await {
            let meta = meta?;
            let loc = meta.location.to_string();
            if keep.is_some_and(|k| loc.starts_with(k)) {
                continue;
            }
            doomed.push(meta.location);
        }
        for loc in &doomed {
            match self.store.delete(loc).await {
                Ok(()) | Err(object_store::Error::NotFound { .. }) => {}
                Err(e) => return Err(e.into()),
            }
        }
        if let Some(root) = &self.local_root {
            let dir = root.join(prefix.as_ref());
            let keep = keep.map(|k| root.join(k.trim_end_matches('/')));
            // File system work off the async threads; best effort (see
            // `remove_stale_dirs`).
            let _ =
                tokio::task::spawn_blocking(move || remove_stale_dirs(&dir, keep.as_deref())).await;
        }
        Ok(doomed.len())
    }

    /// True if an object can be written and removed (readiness).
    pub async fn is_usable(&self) -> bool {
        let key = ObjectPath::from(format!(".probe/{}", uuid::Uuid::now_v7().simple()));
        if self
            .store
            .put(&key, PutPayload::from_static(b"ok"))
            .await
            .is_err()
        {
            return false;
        }
        self.store.delete(&key).await.is_ok()
    }
}

/// Removes what a local store keeps under `dir` besides `keep` (an attempt
/// directory): the directories of attempts whose worker was killed in the
/// middle of a write still hold its temporary file, which is not an object
/// (the listing skips it), so deleting the objects left them behind. `dir`
/// is either one attempt's directory (removed whole unless it is `keep`) or
/// a job's (its attempt directories but `keep` are removed, then `dir`
/// itself if it is empty). Errors other than "not found" are ignored: the
/// objects are gone already, and the job's expiry sweeps again.
fn remove_stale_dirs(dir: &std::path::Path, keep: Option<&std::path::Path>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    if keep.is_some_and(|k| k.parent() == Some(dir)) {
        for e in entries.flatten() {
            let path = e.path();
            if Some(path.as_path()) != keep && path.is_dir() {
                let _ = std::fs::remove_dir_all(&path);
            }
        }
    } else if keep.is_none() {
        drop(entries);
        let _ = std::fs::remove_dir_all(dir);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn put_if_absent_then_remove_other_attempts() {
        let dir = tempfile::tempdir().unwrap();
        let url = format!("file://{}", dir.path().display());
        let s = ResultStore::open(&url).unwrap();
        let k1 = ResultStore::key("job_a", 1, "distance");
        let k2 = ResultStore::key("job_a", 2, "distance");
        s.put_new(&k1, vec![1, 2, 3]).await.unwrap();
        assert!(
            s.put_new(&k1, vec![9]).await.is_err(),
            "second write refused"
        );
        assert_eq!(&s.get(&k1).await.unwrap()[..], &[1, 2, 3]);
        s.put_new(&k2, vec![4]).await.unwrap();
        assert_eq!(s.remove_job("job_a", Some(2)).await.unwrap(), 1);
        assert!(s.get(&k1).await.is_err());
        assert_eq!(&s.get(&k2).await.unwrap()[..], &[4]);
        assert_eq!(s.remove_job("job_a", None).await.unwrap(), 1);
        assert!(!dir.path().join("results/job_a").exists());
        assert!(ResultStore::open("file://relative").is_err());
        assert!(ResultStore::open("ftp://x").is_err());
        assert!(s.is_usable().await);
    }

    /// A worker killed in the middle of a write leaves a temporary file in
    /// its attempt's directory; the attempt that succeeds removes it with
    /// the directory, and the job's removal removes everything.
    #[tokio::test]
    async fn half_written_attempts_of_killed_workers_are_removed() {
        let dir = tempfile::tempdir().unwrap();
        let s = ResultStore::local(dir.path()).unwrap();
        let job = dir.path().join("results/job_b");
        std::fs::create_dir_all(job.join("1")).unwrap();
        std::fs::write(job.join("1/distance.npy#1"), b"half").unwrap();
        s.put_new(&ResultStore::key("job_b", 2, "distance"), vec![4])
            .await
            .unwrap();
        assert_eq!(s.remove_job("job_b", Some(2)).await.unwrap(), 0);
        assert!(!job.join("1").exists(), "the killed attempt's directory");
        assert!(job.join("2/distance.npy").exists(), "the kept attempt");
        std::fs::create_dir_all(job.join("3")).unwrap();
        std::fs::write(job.join("3/distance.npy#7"), b"half").unwrap();
        assert_eq!(s.remove_job_attempt("job_b", 3).await.unwrap(), 0);
        assert!(!job.join("3").exists());
        assert_eq!(s.remove_job("job_b", None).await.unwrap(), 1);
        assert!(!job.exists());
    }
}
