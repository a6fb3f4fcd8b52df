//! One memory budget for everything the store keeps decoded: arrays,
//! meshes (with their topology) and heat-method factorisations, accounted
//! in bytes against `--cache-bytes` and evicted least recently used first,
//! whatever their kind.
//!
//! A heat factorisation enters as an empty slot (so that concurrent
//! requests for the same one wait for a single build) and is re-sized once
//! built ([`MemoryCache::resize`]); anything larger than the whole budget
//! is used by its request and not kept.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use super::lock;
use crate::numerics::mesh::{HeatSolver, Laplacian};
use crate::ops::spec::mesh::MeshInput;
use crate::ops::InputArray;

/// A heat factorisation being built or built (see [`MemoryCache::resize`]).
pub type HeatSlot = Arc<Mutex<Option<Arc<HeatSolver>>>>;

/// What an entry is for.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum CacheKey {
    /// The decoded array of a dataset.
    Array(String),
    /// The decoded mesh of a dataset.
    Mesh(String),
    /// The heat factorisation of a mesh dataset for one time-step factor
    /// (`m`'s bits) and one Laplacian.
    Heat(String, u64, Laplacian),
}

impl CacheKey {
    fn dataset(&self) -> &str {
        match self {
            CacheKey::Array(id) | CacheKey::Mesh(id) | CacheKey::Heat(id, ..) => id,
        }
    }
}

/// A cached value.
#[derive(Debug, Clone)]
pub enum CacheValue {
    /// See [`CacheKey::Array`].
    Array(InputArray),
    /// See [`CacheKey::Mesh`].
    Mesh(Arc<MeshInput>),
    /// See [`CacheKey::Heat`].
    Heat(HeatSlot),
}

#[derive(Debug)]
struct Entry {
    value: CacheValue,
    bytes: usize,
    used: u64,
}

#[derive(Debug, Default)]
struct Inner {
    entries: HashMap<CacheKey, Entry>,
    bytes: usize,
    tick: u64,
}

impl Inner {
    /// Evicts least recently used entries (never `keep`) until `extra`
    /// more bytes fit in `budget`.
    fn make_room(&mut self, extra: usize, budget: usize, keep: Option<&CacheKey>) {
        while self.bytes + extra > budget {
            let oldest = self
                .entries
                .iter()
                .filter(|(k, _)| Some(*k) != keep)
                .min_by_key(|(_, e)| e.used)
                .map(|(k, _)| k.clone());
            match oldest.and_then(|k| self.entries.remove(&k)) {
                Some(old) => self.bytes -= old.bytes,
                None => break,
            }
        }
    }
}

/// The byte-bounded cache (see the module documentation).
#[derive(Debug)]
pub struct MemoryCache {
    budget: usize,
    inner: Mutex<Inner>,
}

impl MemoryCache {
    /// An empty cache holding at most `budget` bytes.
    pub fn new(budget: usize) -> Self {
        Self {
            budget,
            inner: Mutex::new(Inner::default()),
        }
    }

    /// The entry for `key`, marked as just used.
    pub fn get(&self, key: &CacheKey) -> Option<CacheValue> {
        let mut inner = lock(&self.inner);
        inner.tick += 1;
        let tick = inner.tick;
        inner.entries.get_mut(key).map(|e| {
            e.used = tick;
            e.value.clone()
        })
    }

    /// Keeps `value` under `key`, accounted as `bytes`, evicting the least
    /// recently used entries to make room; not kept when it alone exceeds
    /// the budget.
    pub fn insert(&self, key: CacheKey, value: CacheValue, bytes: usize) {
        if bytes > self.budget {
            return;
        }
        let mut inner = lock(&self.inner);
        if let Some(old) = inner.entries.remove(&key) {
            inner.bytes -= old.bytes;
        }
        inner.make_room(bytes, self.budget, None);
        inner.tick += 1;
        let used = inner.tick;
        inner.bytes += bytes;
        inner.entries.insert(key, Entry { value, bytes, used });
    }

    /// The heat slot for `key`, created empty (zero bytes) if missing.
    pub fn heat_slot(&self, key: CacheKey) -> HeatSlot {
        let mut inner = lock(&self.inner);
        inner.tick += 1;
        let used = inner.tick;
        if let Some(e) = inner.entries.get_mut(&key) {
            e.used = used;
            if let CacheValue::Heat(slot) = &e.value {
                return Arc::clone(slot);
            }
        }
        let slot = HeatSlot::default();
        inner.entries.insert(
            key,
            Entry {
                value: CacheValue::Heat(Arc::clone(&slot)),
                bytes: 0,
                used,
            },
        );
        slot
    }

    /// Accounts `key` (already present) as `bytes` now, evicting others to
    /// make room, or dropping it when it alone exceeds the budget.
    pub fn resize(&self, key: &CacheKey, bytes: usize) {
        let mut inner = lock(&self.inner);
        let Some(old) = inner.entries.get(key).map(|e| e.bytes) else {
            return;
        };
        if bytes > self.budget {
            if let Some(e) = inner.entries.remove(key) {
                inner.bytes -= e.bytes;
            }
            return;
        }
        inner.bytes -= old;
        inner.make_room(bytes, self.budget, Some(key));
        inner.bytes += bytes;
        if let Some(e) = inner.entries.get_mut(key) {
            e.bytes = bytes;
        }
    }

    /// Drops every entry of dataset `id`.
    pub fn forget(&self, id: &str) {
        let mut inner = lock(&self.inner);
        let gone: Vec<CacheKey> = inner
            .entries
            .keys()
            .filter(|k| k.dataset() == id)
            .cloned()
            .collect();
        for k in gone {
            if let Some(e) = inner.entries.remove(&k) {
                inner.bytes -= e.bytes;
            }
        }
    }

    /// Bytes accounted now.
    pub fn bytes(&self) -> usize {
        lock(&self.inner).bytes
    }

    /// Entries now.
    pub fn len(&self) -> usize {
        lock(&self.inner).entries.len()
    }

    /// True when nothing is cached.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::ArrayData;

    fn array(n: usize) -> CacheValue {
        CacheValue::Array(InputArray {
            array: Arc::new(ArrayData::F64(ndarray::ArrayD::zeros(vec![n]))),
            spacing: None,
        })
    }

    #[test]
    fn evicts_least_recently_used_across_kinds_by_bytes() {
        let c = MemoryCache::new(100);
        c.insert(CacheKey::Array("a".into()), array(1), 40);
        c.insert(CacheKey::Array("b".into()), array(1), 40);
        assert!(c.get(&CacheKey::Array("a".into())).is_some()); // a is now newer than b
        let heat = CacheKey::Heat("m".into(), 1, Laplacian::Robust);
        let _slot = c.heat_slot(heat.clone());
        assert_eq!(c.bytes(), 80);
        c.resize(&heat, 50); // b goes, a stays
        assert_eq!(c.bytes(), 90);
        assert!(c.get(&CacheKey::Array("b".into())).is_none());
        assert!(c.get(&CacheKey::Array("a".into())).is_some());
        c.resize(&heat, 500); // larger than the budget: not kept
        assert!(c.get(&heat).is_none());
        assert_eq!(c.bytes(), 40);
        c.insert(CacheKey::Array("big".into()), array(1), 101);
        assert!(c.get(&CacheKey::Array("big".into())).is_none());
        c.insert(CacheKey::Mesh("a".into()), array(1), 10);
        c.forget("a");
        assert!(c.is_empty());
        assert_eq!(c.bytes(), 0);
    }
}
