//! Listing the store, a page at a time (`GET /v1/datasets`).
//!
//! Datasets are listed by id, descending. Ids are UUIDv7 (`ds_` + 32 hex
//! digits, the first 12 of them the creation time in milliseconds), so this
//! is newest first, and ties within a millisecond are broken by the random
//! part: a total order that does not change while the store changes. A page
//! ends with the cursor `next`, the last id it holds; the next page is the
//! datasets whose id is smaller than the cursor. A dataset created while a
//! client pages sorts before every cursor and so is not seen by that walk;
//! one deleted or expired is skipped; none is listed twice or skipped
//! otherwise.

use chrono::Utc;

use super::{lock, DatasetMeta, DatasetStore};

/// One page of the listing.
#[derive(Debug, Clone, PartialEq)]
pub struct Page {
    /// The datasets, id descending (newest first).
    pub items: Vec<DatasetMeta>,
    /// The cursor of the next page: the last id of this one, when more follow.
    pub next: Option<String>,
}

impl DatasetStore {
    /// At most `limit` live datasets whose id is below `after` (all when
    /// `None`), id descending. The store's index holds every dataset this
    /// process created, found at start-up, or was asked about; a dataset
    /// that another replica wrote since is listed once it was asked for.
    /// Only `tenant`'s datasets are listed.
    pub fn list(&self, tenant: &str, limit: usize, after: Option<&str>) -> Page {
        let now = Utc::now();
        let index = lock(&self.index);
        let mut live: Vec<&DatasetMeta> = index
            .entries
            .values()
            .filter(|m| m.expires_at > now && m.tenant == tenant)
            .filter(|m| after.is_none_or(|c| m.id.as_str() < c))
            .collect();
        live.sort_unstable_by(|a, b| b.id.cmp(&a.id));
        let more = live.len() > limit;
        let items: Vec<DatasetMeta> = live.into_iter().take(limit).cloned().collect();
        let next = if more {
            items.last().map(|m| m.id.clone())
        } else {
            None
        };
        Page { items, next }
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use super::*;
    use crate::datasets::{SourceFormat, StoreConfig};
    use crate::io::{ArrayData, Limits};

    #[test]
    fn pages_walk_every_dataset_once_newest_first() {
        let dir = tempfile::tempdir().expect("tempdir");
        let store = Arc::new(
            DatasetStore::open(StoreConfig {
                path_cache_bytes: 0,
                data_dir: dir.path().to_path_buf(),
                quota_bytes: 1 << 30,
                ttl: std::time::Duration::from_secs(3600),
                cache_bytes: 1 << 20,
                limits: Limits::default(),
            })
            .expect("store"),
        );
        let a = ArrayData::F64(ndarray::ArrayD::zeros(vec![2, 2]));
        let mut ids = Vec::new();
        for _ in 0..7 {
            let meta = store
                .create_blocking(
                    &a,
                    None,
                    SourceFormat::Npy,
                    &crate::datasets::Owner::anonymous(),
                )
                .expect("create");
            ids.push(meta.id);
        }
        ids.reverse();
        let mut seen = Vec::new();
        let mut cursor: Option<String> = None;
        let mut pages = 0;
        loop {
            let page = store.list("", 3, cursor.as_deref());
            pages += 1;
            seen.extend(page.items.iter().map(|m| m.id.clone()));
            match page.next {
                Some(c) => cursor = Some(c),
                None => break,
            }
        }
        assert_eq!(pages, 3);
        assert_eq!(seen, ids);
    }
}
