//! API keys and tenants: who a request acts for, and what it may see.
//!
//! * **Keys.** A key is `gdx_<id>_<secret>`: `key_<id>` (16 hex digits) is
//!   its public half, shown by `geodex keys list` and in logs; the secret
//!   (64 hex digits, 244 random bits from the operating system) is shown once,
//!   when the key is created. The database keeps only the SHA-256 of the
//!   secret (`geodex_api_keys`, `migrations/0003_tenants.sql`, in the jobs'
//!   database: SQLite or PostgreSQL). A random secret of that length needs no
//!   slow hash: SHA-256 cannot be inverted and there is nothing to guess.
//! * **Tenants.** Every key belongs to one tenant. Every dataset, job (with
//!   its results and its idempotency key) and collection records the tenant
//!   of the request that made it, and another tenant is answered 404 for it,
//!   as if it did not exist. With auth off every request acts for the empty
//!   tenant `""`.
//! * **Limits per key.** A token bucket (`rate_per_sec`, `burst`) answered
//!   429 + `Retry-After` when empty ([`rate::Buckets`]), and a storage quota
//!   of the tenant (datasets; [`crate::datasets::Owner`]).
//!
//! This module knows nothing of HTTP: `http::auth` reads the header, asks
//! [`Keys::verify`] and answers.

pub mod rate;

use std::collections::HashMap;
use std::sync::Mutex;
use std::time::{Duration, Instant};

use sha2::{Digest, Sha256};
use sqlx::Row;

use crate::datasets::Owner;
use crate::jobs::db::on_pool;
use crate::jobs::{DbError, JobDb};

/// How long a verified key is trusted without asking the database again: a
/// revoked key stops working within this time on every replica.
pub const VERIFY_CACHE: Duration = Duration::from_secs(2);

/// Who a request acts for.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Caller {
    /// The tenant and its storage quota.
    pub owner: Owner,
    /// `key_<id>` of the key used (`None` with auth off).
    pub key_id: Option<String>,
    /// May read `/metrics` and the details of `/readyz`. Everybody may, with
    /// auth off.
    pub admin: bool,
    /// The key's token bucket: refill per second and size.
    pub rate: Option<(f64, f64)>,
}

impl Caller {
    /// The caller of every request when auth is off: the empty tenant, no
    /// quota of its own, allowed everything.
    pub fn anonymous() -> Self {
        Self {
            admin: true,
            ..Self::default()
        }
    }

    /// The tenant (`""` with auth off).
    pub fn tenant(&self) -> &str {
        &self.owner.tenant
    }
}

/// A stored key, as `geodex keys list` shows it (never with its secret).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct KeyRecord {
    /// `key_<16 hex>`.
    pub id: String,
    /// Its tenant.
    pub tenant: String,
    /// The operator's label.
    pub name: String,
    /// May read `/metrics` and `/readyz` details.
    pub admin: bool,
    /// Storage quota of the tenant in bytes, if the key sets one.
    pub quota_bytes: Option<i64>,
    /// Requests per second (token bucket refill), if the key sets one.
    pub rate_per_sec: Option<f64>,
    /// Token bucket size, if the key sets one.
    pub burst: Option<i64>,
    /// ms since the epoch.
    pub created_at: i64,
    /// ms since the epoch, when revoked.
    pub revoked_at: Option<i64>,
}

/// What a new key gets (`geodex keys create`).
#[derive(Debug, Clone, Default)]
pub struct NewKey {
    /// Its tenant ([`valid_tenant`]).
    pub tenant: String,
    /// A label.
    pub name: String,
    /// May read `/metrics` and `/readyz` details.
    pub admin: bool,
    /// Storage quota of the tenant in bytes.
    pub quota_bytes: Option<u64>,
    /// Requests per second.
    pub rate_per_sec: Option<f64>,
    /// Token bucket size.
    pub burst: Option<u64>,
}

/// Why a key operation failed.
#[derive(Debug, thiserror::Error)]
pub enum KeyError {
    /// The database failed.
    #[error(transparent)]
    Db(#[from] DbError),
    /// A field of a new key is not acceptable.
    #[error("{0}")]
    Invalid(String),
}

impl From<sqlx::Error> for KeyError {
    fn from(e: sqlx::Error) -> Self {
        KeyError::Db(DbError::Sqlx(e))
    }
}

/// Why a presented key was refused (all of them are a 401; the message says which).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Refusal {
    /// Not of the form `gdx_<16 hex>_<64 hex>`.
    Malformed,
    /// No key with this id, or the secret does not match.
    Unknown,
    /// The key was revoked.
    Revoked,
}

/// True if `tenant` is 1 to 64 of `[a-z0-9_.-]` (it is part of stored keys
/// and file metadata, so no separators or spaces).
pub fn valid_tenant(tenant: &str) -> bool {
    (1..=64).contains(&tenant.len())
        && tenant
            .bytes()
            .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b"_.-".contains(&b))
}

/// The two halves of a presented key: `(key_<id>, secret)`.
fn split_key(key: &str) -> Option<(String, &str)> {
    let rest = key.strip_prefix("gdx_")?;
    let (id, secret) = rest.split_once('_')?;
    let hex = |s: &str, n: usize| {
        s.len() == n
            && s.bytes()
                .all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b))
    };
    (hex(id, 16) && hex(secret, 64)).then(|| (format!("key_{id}"), secret))
}

fn sha256_hex(secret: &str) -> String {
    Sha256::digest(secret.as_bytes())
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// Compares two equal-length strings in time independent of where they differ.
fn same(a: &str, b: &str) -> bool {
    a.len() == b.len()
        && a.bytes()
            .zip(b.bytes())
            .fold(0u8, |acc, (x, y)| acc | (x ^ y))
            == 0
}

/// 32 random hex digits from the operating system (a v4 UUID's 122 random
/// bits, the version and variant digits replaced by more random ones).
fn random_hex() -> String {
    let a = uuid::Uuid::new_v4().simple().to_string();
    let b = uuid::Uuid::new_v4().simple().to_string();
    // Positions 12 and 16 of a v4 UUID are fixed (version, variant): drop them.
    let strip = |s: &str| -> String {
        s.char_indices()
            .filter(|(i, _)| *i != 12 && *i != 16)
            .map(|(_, c)| c)
            .collect()
    };
    let mut out = strip(&a);
    out.push_str(&strip(&b));
    out.truncate(32);
    out
}

const KEY_COLUMNS: &str =
    "id, tenant, name, secret_sha256, admin, quota_bytes, rate_per_sec, burst, created_at, revoked_at";

/// Decodes a key row of either engine: the record and the stored hash.
macro_rules! key_row {
    ($r:expr) => {{
        let r = $r;
        (
            KeyRecord {
                id: r.try_get("id")?,
                tenant: r.try_get("tenant")?,
                name: r.try_get("name")?,
                admin: r.try_get("admin")?,
                quota_bytes: r.try_get("quota_bytes")?,
                rate_per_sec: r.try_get("rate_per_sec")?,
                burst: r.try_get("burst")?,
                created_at: r.try_get("created_at")?,
                revoked_at: r.try_get("revoked_at")?,
            },
            r.try_get::<String, _>("secret_sha256")?,
        )
    }};
}

/// The defaults of a key that sets no limits of its own (`geodex serve` flags).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KeyDefaults {
    /// Storage quota of a tenant, bytes (0: only the service's quota).
    pub quota_bytes: u64,
    /// Requests per second (0: no rate limit).
    pub rate_per_sec: f64,
    /// Token bucket size.
    pub burst: f64,
}

impl Default for KeyDefaults {
    fn default() -> Self {
        Self {
            quota_bytes: 0,
            rate_per_sec: 0.0,
            burst: 0.0,
        }
    }
}

/// A cached answer of [`Keys::verify`] and when it was given.
type Verified = (Instant, Result<Caller, Refusal>);

/// The key table, with a short-lived cache of verified keys.
#[derive(Debug)]
pub struct Keys {
    db: JobDb,
    defaults: KeyDefaults,
    verified: Mutex<HashMap<String, Verified>>,
}

impl Keys {
    /// The keys in `db` (migrated by [`JobDb`]'s opening).
    pub fn new(db: JobDb, defaults: KeyDefaults) -> Self {
        Self {
            db,
            defaults,
            verified: Mutex::new(HashMap::new()),
        }
    }

    /// Creates a key; returns its record and the full key, which is shown
    /// once and never stored.
    pub async fn create(&self, new: &NewKey) -> Result<(KeyRecord, String), KeyError> {
        if !valid_tenant(&new.tenant) {
            return Err(KeyError::Invalid(format!(
                "--tenant '{}': 1 to 64 of a-z, 0-9, '_', '.', '-'",
                new.tenant
            )));
        }
        if new
            .rate_per_sec
            .is_some_and(|r| !(r.is_finite() && r > 0.0))
        {
            return Err(KeyError::Invalid(
                "--rate-per-sec: must be finite and > 0".into(),
            ));
        }
        let public = random_hex()[..16].to_string();
        let secret = format!("{}{}", random_hex(), random_hex());
        let record = KeyRecord {
            id: format!("key_{public}"),
            tenant: new.tenant.clone(),
            name: new.name.clone(),
            admin: new.admin,
            quota_bytes: new.quota_bytes.map(|q| q.min(i64::MAX as u64) as i64),
            rate_per_sec: new.rate_per_sec,
            burst: new.burst.map(|b| b.min(i64::MAX as u64) as i64),
            created_at: crate::jobs::now_ms(),
            revoked_at: None,
        };
        let q =
            "INSERT INTO geodex_api_keys (id, tenant, name, secret_sha256, admin, quota_bytes, \
                 rate_per_sec, burst, created_at) VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9)";
        on_pool!(&self.db, p => sqlx::query(q)
            .bind(&record.id)
            .bind(&record.tenant)
            .bind(&record.name)
            .bind(sha256_hex(&secret))
            .bind(record.admin)
            .bind(record.quota_bytes)
            .bind(record.rate_per_sec)
            .bind(record.burst)
            .bind(record.created_at)
            .execute(p)
            .await?
            .rows_affected());
        Ok((record, format!("gdx_{public}_{secret}")))
    }

    /// Every key, oldest first (revoked ones too).
    pub async fn list(&self) -> Result<Vec<KeyRecord>, KeyError> {
        let q = sqlx::AssertSqlSafe(format!(
            "SELECT {KEY_COLUMNS} FROM geodex_api_keys ORDER BY created_at, id"
        ));
        Ok(on_pool!(&self.db, p => {
            let mut out = Vec::new();
            for r in sqlx::query(q).fetch_all(p).await? {
                out.push(key_row!(&r).0);
            }
            out
        }))
    }

    /// True if at least one key is not revoked.
    pub async fn any_active(&self) -> Result<bool, KeyError> {
        let q = "SELECT COUNT(*) AS n FROM geodex_api_keys WHERE revoked_at IS NULL";
        let n: i64 = on_pool!(&self.db, p => sqlx::query(q).fetch_one(p).await?.try_get("n")?);
        Ok(n > 0)
    }

    /// Revokes a key (`key_<id>`, or the full key); returns its id, or
    /// `None` if there is no such active key.
    pub async fn revoke(&self, id: &str) -> Result<Option<String>, KeyError> {
        let id = split_key(id).map_or_else(|| id.to_string(), |(id, _)| id);
        let q = "UPDATE geodex_api_keys SET revoked_at = $1 WHERE id = $2 AND revoked_at IS NULL";
        let n = on_pool!(&self.db, p => sqlx::query(q)
            .bind(crate::jobs::now_ms())
            .bind(&id)
            .execute(p)
            .await?
            .rows_affected());
        self.verified
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .retain(|k, _| split_key(k).is_none_or(|(kid, _)| kid != id));
        Ok((n == 1).then_some(id))
    }

    /// The caller a presented key stands for. Answers from a cache for
    /// [`VERIFY_CACHE`]; a database failure is an error, not a refusal.
    pub async fn verify(&self, key: &str) -> Result<Result<Caller, Refusal>, KeyError> {
        {
            let cache = self.verified.lock().unwrap_or_else(|p| p.into_inner());
            if let Some((at, answer)) = cache.get(key) {
                if at.elapsed() < VERIFY_CACHE {
                    return Ok(answer.clone());
                }
            }
        }
        let answer = self.verify_uncached(key).await?;
        let mut cache = self.verified.lock().unwrap_or_else(|p| p.into_inner());
        if cache.len() > 10_000 {
            // Many different wrong keys: forget them all rather than grow.
            cache.clear();
        }
        cache.insert(key.to_string(), (Instant::now(), answer.clone()));
        Ok(answer)
    }

    async fn verify_uncached(&self, key: &str) -> Result<Result<Caller, Refusal>, KeyError> {
        let Some((id, secret)) = split_key(key) else {
            return Ok(Err(Refusal::Malformed));
        };
        let q = sqlx::AssertSqlSafe(format!(
            "SELECT {KEY_COLUMNS} FROM geodex_api_keys WHERE id = $1"
        ));
        let row = on_pool!(&self.db, p => {
            match sqlx::query(q).bind(&id).fetch_optional(p).await? {
                Some(r) => Some(key_row!(&r)),
                None => None,
            }
        });
        let Some((record, hash)) = row else {
            return Ok(Err(Refusal::Unknown));
        };
        if !same(&hash, &sha256_hex(secret)) {
            return Ok(Err(Refusal::Unknown));
        }
        if record.revoked_at.is_some() {
            return Ok(Err(Refusal::Revoked));
        }
        let quota = record
            .quota_bytes
            .map(|q| q.max(0) as u64)
            .or((self.defaults.quota_bytes > 0).then_some(self.defaults.quota_bytes));
        let rate = record
            .rate_per_sec
            .or((self.defaults.rate_per_sec > 0.0).then_some(self.defaults.rate_per_sec))
            .map(|r| {
                let burst = record
                    .burst
                    .map(|b| b.max(1) as f64)
                    .unwrap_or(self.defaults.burst.max(r).max(1.0));
                (r, burst)
            });
        Ok(Ok(Caller {
            owner: Owner {
                tenant: record.tenant,
                quota_bytes: quota,
            },
            key_id: Some(record.id),
            admin: record.admin,
            rate,
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_split_only_when_well_formed() {
        let id = "0123456789abcdef";
        let secret = "a".repeat(64);
        let key = format!("gdx_{id}_{secret}");
        assert_eq!(
            split_key(&key),
            Some((format!("key_{id}"), secret.as_str()))
        );
        assert_eq!(split_key(&key[..key.len() - 1]), None);
        assert_eq!(split_key(&key.replace("gdx_", "gdy_")), None);
        assert_eq!(split_key(&key.to_uppercase()), None);
        assert_eq!(split_key(""), None);
    }

    #[test]
    fn random_hex_is_hex_and_differs() {
        let (a, b) = (random_hex(), random_hex());
        assert_eq!(a.len(), 32);
        assert!(a.bytes().all(|c| c.is_ascii_hexdigit()));
        assert_ne!(a, b);
    }

    #[test]
    fn tenants_are_plain_names() {
        assert!(valid_tenant("acme"));
        assert!(valid_tenant("team-7.lab_a"));
        assert!(!valid_tenant(""));
        assert!(!valid_tenant("a/b"));
        assert!(!valid_tenant("Acme"));
        assert!(!valid_tenant(&"a".repeat(65)));
    }

    #[test]
    fn the_hash_is_sha256() {
        assert_eq!(
            sha256_hex("abc"),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
        assert!(same("abc", "abc") && !same("abc", "abd") && !same("abc", "ab"));
    }
}
