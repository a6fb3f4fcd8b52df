//! [`DistanceCache`]: designed costs and distance maps kept between
//! requests, bounded in bytes, least recently used out first, so that a
//! front end following the mouse only pays for the descents.
//!
//! Who fills it: `grid.paths` (its costs and maps), and `grid.distance`
//! (its designed cost and, for point sources solved to completion, its map),
//! so that the map a user just looked at serves the paths that follow. The
//! keys are [`cost_key`] and [`map_key`]: the request's JSON sections, so
//! that two operations asking for the same problem meet on the same entry.

use std::borrow::Cow;
use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use crate::numerics::metric::{CostValues, Interpretation};
use crate::numerics::paths::SourceSet;
use crate::numerics::{Grid, IsotropicCost};
use crate::ops::spec::cost::CostSpec;
use crate::ops::spec::scheme::{ConnectivitySpec, MethodSpec, SourceSpec};
use crate::ops::spec::tensor::TensorSpec;
use crate::ops::OpError;

/// The key of a cost: its `cost`/`metric`, `spacing` and `obstacles` sections.
pub fn cost_key(
    cost: Option<&CostSpec>,
    metric: Option<&TensorSpec>,
    spacing: Option<&[f64]>,
    obstacles: Option<&str>,
) -> String {
    serde_json::json!([cost, metric, spacing, obstacles]).to_string()
}

/// The key of a distance map: its cost's key, its sources and its scheme.
pub fn map_key(
    cost_key: &str,
    sources: &[SourceSpec],
    method: MethodSpec,
    order: u8,
    factoring: bool,
    connectivity: ConnectivitySpec,
) -> String {
    let scheme = serde_json::json!([sources, method, order, factoring, connectivity]);
    format!("{cost_key}|{scheme}")
}

/// A cost ready for solves and descents: the grid and `W` per cell (`+inf` on walls).
#[derive(Debug, Clone)]
pub struct CachedCost {
    /// Shape and spacing.
    pub grid: Grid,
    /// The spacing per caller axis.
    pub spacing: Vec<f64>,
    /// `W` per cell, C order, `+inf` on walls.
    pub w: Vec<f64>,
}

impl CachedCost {
    /// The cost as the solvers take it (`W` as stored, walls included).
    pub fn isotropic(&self) -> Result<IsotropicCost<'_>, OpError> {
        IsotropicCost::new(
            &self.grid,
            CostValues::F64(Cow::Borrowed(&self.w)),
            Interpretation::Cost,
            None,
        )
        .map_err(|e| OpError::invalid("cost", e.to_string()))
    }
}

/// A distance map kept for later descents.
#[derive(Debug)]
pub struct CachedMap {
    /// The cost it was computed on.
    pub cost: Arc<CachedCost>,
    /// Its sources, indexed for the arrival test.
    pub sources: SourceSet,
    /// `U` per cell (`+inf` where not computed).
    pub u: Vec<f64>,
    /// False if the solve stopped early (some cells were not computed).
    pub complete: bool,
    /// Frozen cells and how the solve ended.
    pub frozen: u64,
    /// How the solve ended.
    pub stop: String,
}

/// Where designed costs and distance maps are kept between requests: the
/// service's one memory budget (`datasets::cache::MemoryCache`), or a
/// [`DistanceCache`] of its own (the command line, tests).
pub trait MapCache: Send + Sync {
    /// The cost under `key`, if kept (marked as just used).
    fn cost(&self, key: &str) -> Option<Arc<CachedCost>>;
    /// The map under `key`, if kept (marked as just used).
    fn map(&self, key: &str) -> Option<Arc<CachedMap>>;
    /// Keeps a cost (8 bytes per cell), if the budget allows.
    fn put_cost(&self, key: String, cost: Arc<CachedCost>);
    /// Keeps a map (8 bytes per cell), if the budget allows.
    fn put_map(&self, key: String, map: Arc<CachedMap>);
}

impl MapCache for DistanceCache {
    fn cost(&self, key: &str) -> Option<Arc<CachedCost>> {
        DistanceCache::cost(self, key)
    }

    fn map(&self, key: &str) -> Option<Arc<CachedMap>> {
        DistanceCache::map(self, key)
    }

    fn put_cost(&self, key: String, cost: Arc<CachedCost>) {
        DistanceCache::put_cost(self, key, cost);
    }

    fn put_map(&self, key: String, map: Arc<CachedMap>) {
        DistanceCache::put_map(self, key, map);
    }
}

#[derive(Debug, Default)]
struct CacheInner {
    costs: HashMap<String, (Arc<CachedCost>, u64)>,
    maps: HashMap<String, (Arc<CachedMap>, u64)>,
    bytes: usize,
    tick: u64,
}

/// A bounded in-memory cache of designed costs and distance maps, least
/// recently used out first. Shared between requests (`Arc`), thread-safe.
#[derive(Debug)]
pub struct DistanceCache {
    max_bytes: usize,
    inner: Mutex<CacheInner>,
}

impl DistanceCache {
    /// A cache holding at most `max_bytes` of values (8 bytes per cell for
    /// each cost and each map). `0` disables it.
    pub fn new(max_bytes: usize) -> Self {
        Self {
            max_bytes,
            inner: Mutex::new(CacheInner::default()),
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, CacheInner> {
        self.inner.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The cost under `key`, if kept.
    pub fn cost(&self, key: &str) -> Option<Arc<CachedCost>> {
        let mut g = self.lock();
        g.tick += 1;
        let tick = g.tick;
        g.costs.get_mut(key).map(|e| {
            e.1 = tick;
            e.0.clone()
        })
    }

    /// The map under `key`, if kept.
    pub fn map(&self, key: &str) -> Option<Arc<CachedMap>> {
        let mut g = self.lock();
        g.tick += 1;
        let tick = g.tick;
        g.maps.get_mut(key).map(|e| {
            e.1 = tick;
            e.0.clone()
        })
    }

    /// Keeps a cost.
    pub fn put_cost(&self, key: String, cost: Arc<CachedCost>) {
        let bytes = cost.w.len() * 8;
        self.put(bytes, |g, tick| {
            if let Some((old, _)) = g.costs.insert(key, (cost, tick)) {
                g.bytes = g.bytes.saturating_sub(old.w.len() * 8);
            }
        });
    }

    /// Keeps a map.
    pub fn put_map(&self, key: String, map: Arc<CachedMap>) {
        let bytes = map.u.len() * 8;
        self.put(bytes, |g, tick| {
            if let Some((old, _)) = g.maps.insert(key, (map, tick)) {
                g.bytes = g.bytes.saturating_sub(old.u.len() * 8);
            }
        });
    }

    fn put(&self, bytes: usize, insert: impl FnOnce(&mut CacheInner, u64)) {
        if bytes > self.max_bytes {
            return;
        }
        let mut g = self.lock();
        while g.bytes + bytes > self.max_bytes {
            // Evict the least recently used entry of either kind.
            let oldest_map = g
                .maps
                .iter()
                .min_by_key(|e| e.1 .1)
                .map(|(k, e)| (k.clone(), e.1));
            let oldest_cost = g
                .costs
                .iter()
                .min_by_key(|e| e.1 .1)
                .map(|(k, e)| (k.clone(), e.1));
            match (oldest_map, oldest_cost) {
                (Some((k, a)), Some((_, b))) if a <= b => {
                    if let Some((m, _)) = g.maps.remove(&k) {
                        g.bytes = g.bytes.saturating_sub(m.u.len() * 8);
                    }
                }
                (Some((k, _)), None) => {
                    if let Some((m, _)) = g.maps.remove(&k) {
                        g.bytes = g.bytes.saturating_sub(m.u.len() * 8);
                    }
                }
                (_, Some((k, _))) => {
                    if let Some((c, _)) = g.costs.remove(&k) {
                        g.bytes = g.bytes.saturating_sub(c.w.len() * 8);
                    }
                }
                (None, None) => break,
            }
        }
        g.tick += 1;
        let tick = g.tick;
        insert(&mut g, tick);
        g.bytes += bytes;
    }

    /// Number of kept (costs, maps).
    pub fn len(&self) -> (usize, usize) {
        let g = self.lock();
        (g.costs.len(), g.maps.len())
    }

    /// True if nothing is kept.
    pub fn is_empty(&self) -> bool {
        self.len() == (0, 0)
    }
}
