//! One memory budget for everything the service keeps in memory between
//! requests: decoded arrays, meshes (with their topology), heat-method
//! factorisations, and the designed costs and distance maps of interactive
//! paths ([`MapCache`]), accounted in bytes against `--cache-bytes` and
//! evicted least recently used first, whatever their kind. Costs and maps
//! together also stay under their own share (`--path-cache-bytes`).
//!
//! A heat factorisation enters as an empty slot (so that concurrent
//! requests for the same one wait for a single build) and is re-sized once
//! built ([`MemoryCache::resize`]); anything larger than the whole budget
//! is used by its request and not kept.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use super::lock;
use crate::numerics::mesh::{HeatSolver, Laplacian};
use crate::ops::grid_paths::{CachedCost, CachedMap, MapCache};
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
    /// (`m`'s bits), one Laplacian and whether the time step adapts to the
    /// curvature.
    Heat(String, u64, Laplacian, bool),
    /// A designed cost (`ops::spec::map_cache::cost_key`).
    Cost(String),
    /// A distance map (`ops::spec::map_cache::map_key`).
    Map(String),
}

impl CacheKey {
    /// The dataset the entry was decoded from (`None` for costs and maps,
    /// which are keyed by their request).
    fn dataset(&self) -> Option<&str> {
        match self {
            CacheKey::Array(id) | CacheKey::Mesh(id) | CacheKey::Heat(id, ..) => Some(id),
            CacheKey::Cost(_) | CacheKey::Map(_) => None,
        }
    }

    /// True for the entries of interactive paths (their own share).
    fn is_path(&self) -> bool {
        matches!(self, CacheKey::Cost(_) | CacheKey::Map(_))
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
    /// See [`CacheKey::Cost`].
    Cost(Arc<CachedCost>),
    /// See [`CacheKey::Map`].
    Map(Arc<CachedMap>),
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
    /// Bytes of costs and maps (part of `bytes`).
    path_bytes: usize,
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
            match oldest.and_then(|k| self.entries.remove(&k).map(|e| (k, e))) {
                Some((k, old)) => self.forget_bytes(&k, old.bytes),
                None => break,
            }
        }
    }

    /// Evicts least recently used costs and maps until `extra` more bytes of
    /// them fit in `share`.
    fn make_path_room(&mut self, extra: usize, share: usize) {
        while self.path_bytes + extra > share {
            let oldest = self
                .entries
                .iter()
                .filter(|(k, _)| k.is_path())
                .min_by_key(|(_, e)| e.used)
                .map(|(k, _)| k.clone());
            match oldest.and_then(|k| self.entries.remove(&k).map(|e| (k, e))) {
                Some((k, old)) => self.forget_bytes(&k, old.bytes),
                None => break,
            }
        }
    }

    /// Takes a removed entry's bytes off the counts.
    fn forget_bytes(&mut self, key: &CacheKey, bytes: usize) {
        self.bytes -= bytes;
        if key.is_path() {
            self.path_bytes -= bytes;
        }
    }
}

/// The byte-bounded cache (see the module documentation).
#[derive(Debug)]
pub struct MemoryCache {
    budget: usize,
    /// Most bytes of costs and maps within `budget` (0: none kept).
    path_share: usize,
    inner: Mutex<Inner>,
}

impl MemoryCache {
    /// An empty cache holding at most `budget` bytes.
    pub fn new(budget: usize) -> Self {
        Self {
            budget,
            path_share: budget,
            inner: Mutex::new(Inner::default()),
        }
    }

    /// The same cache keeping at most `bytes` of costs and maps (within its
    /// budget; 0 keeps none).
    pub fn with_path_share(mut self, bytes: usize) -> Self {
        self.path_share = bytes.min(self.budget);
        self
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
        let path = key.is_path();
        if bytes > self.budget || (path && bytes > self.path_share) {
            return;
        }
        let mut inner = lock(&self.inner);
        if let Some(old) = inner.entries.remove(&key) {
            inner.forget_bytes(&key, old.bytes);
        }
        if path {
            inner.make_path_room(bytes, self.path_share);
        }
        inner.make_room(bytes, self.budget, None);
        inner.tick += 1;
        let used = inner.tick;
        inner.bytes += bytes;
        if path {
            inner.path_bytes += bytes;
        }
        inner.entries.insert(key, Entry { value, bytes, used });
    }

    /// Bytes of costs and maps held.
    pub fn path_bytes(&self) -> usize {
        lock(&self.inner).path_bytes
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
            .filter(|k| k.dataset() == Some(id))
            .cloned()
            .collect();
        for k in gone {
            if let Some(e) = inner.entries.remove(&k) {
                inner.bytes -= e.bytes;
            }
        }
    }

    /// The byte budget every entry counts against.
    pub fn budget(&self) -> usize {
        self.budget
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

/// The designed costs and distance maps of interactive paths, in the one
/// budget (8 bytes per cell each).
impl MapCache for MemoryCache {
    fn cost(&self, key: &str) -> Option<Arc<CachedCost>> {
        match self.get(&CacheKey::Cost(key.to_string())) {
            Some(CacheValue::Cost(c)) => Some(c),
            _ => None,
        }
    }

    fn map(&self, key: &str) -> Option<Arc<CachedMap>> {
        match self.get(&CacheKey::Map(key.to_string())) {
            Some(CacheValue::Map(m)) => Some(m),
            _ => None,
        }
    }

    fn put_cost(&self, key: String, cost: Arc<CachedCost>) {
        let bytes = cost.w.len() * 8;
        self.insert(CacheKey::Cost(key), CacheValue::Cost(cost), bytes);
    }

    fn put_map(&self, key: String, map: Arc<CachedMap>) {
        let bytes = map.u.len() * 8;
        self.insert(CacheKey::Map(key), CacheValue::Map(map), bytes);
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
        let heat = CacheKey::Heat("m".into(), 1, Laplacian::Robust, true);
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

    fn cost(cells: usize) -> Arc<CachedCost> {
        Arc::new(CachedCost {
            grid: crate::numerics::Grid::new(&[1, cells], &[1.0, 1.0]).expect("grid"),
            spacing: vec![1.0],
            w: vec![1.0; cells],
        })
    }

    /// Costs and maps live in the same budget as decoded arrays (one LRU
    /// across kinds), and within their own share of it.
    #[test]
    fn costs_share_the_budget_and_their_own_cap() {
        let c = MemoryCache::new(1000).with_path_share(500);
        c.insert(CacheKey::Array("a".into()), array(1), 400);
        c.put_cost("k1".into(), cost(25)); // 200 bytes
        c.put_cost("k2".into(), cost(25)); // 200 bytes: 800 in all
        assert_eq!((c.bytes(), c.path_bytes()), (800, 400));
        assert!(MapCache::cost(&c, "k1").is_some()); // k1 newer than k2
                                                     // A third cost passes the share of 500: the oldest cost goes, the array stays.
        c.put_cost("k3".into(), cost(25));
        assert!(MapCache::cost(&c, "k2").is_none());
        assert!(MapCache::cost(&c, "k1").is_some() && MapCache::cost(&c, "k3").is_some());
        assert!(c.get(&CacheKey::Array("a".into())).is_some());
        assert_eq!((c.bytes(), c.path_bytes()), (800, 400));
        // An array that needs room evicts the least recently used entry,
        // whatever its kind: k1 (the array was read after it) then k3.
        c.insert(CacheKey::Array("b".into()), array(1), 500);
        assert!(MapCache::cost(&c, "k1").is_none() && MapCache::cost(&c, "k3").is_none());
        assert_eq!((c.bytes(), c.path_bytes()), (900, 0));
        // A share of 0 keeps no cost at all.
        let none = MemoryCache::new(1000).with_path_share(0);
        none.put_cost("k".into(), cost(1));
        assert!(MapCache::cost(&none, "k").is_none());
    }
}
