//! The client side of the queue: submission, queries and cancellation
//! (the `/v1/jobs` endpoints and `Prefer: respond-async` call these).

use std::collections::BTreeMap;
use std::time::Duration;

use super::db::{self, JobRow};
use super::flags::StopReason;
use super::model::{
    cancelled_problem, ms, now_ms, problem_json, valid_id, Job, JobState, Priority, StoredOutput,
    SubmitJob,
};
use super::Jobs;
use crate::datasets::{Owner, StoreError};
use crate::ops::registry;
use crate::problem::ApiError;

impl Jobs {
    /// Validates and queues a job. Returns it and whether it is new (false:
    /// an earlier job with the same `Idempotency-Key`).
    ///
    /// The job belongs to `owner`'s tenant: the datasets it names must be
    /// that tenant's, and its `Idempotency-Key` is that tenant's (another
    /// tenant's same key is another job).
    pub async fn submit(
        &self,
        req: SubmitJob,
        idempotency_key: Option<String>,
        default_priority: Priority,
        owner: &Owner,
    ) -> Result<(Job, bool), ApiError> {
        let entry = registry::find(&req.operation).ok_or_else(|| {
            ApiError::invalid_field(
                "operation",
                format!(
                    "unknown operation '{}'; one of: {}",
                    req.operation,
                    registry::names().join(", ")
                ),
            )
        })?;
        let time_limit = match req.time_limit_secs {
            None => self.config.default_time_limit,
            Some(s) if s.is_finite() && s > 0.0 => Duration::try_from_secs_f64(s)
                .ok()
                .filter(|d| *d <= self.config.max_time_limit)
                .ok_or_else(|| {
                    ApiError::invalid_field(
                        "time_limit_secs",
                        format!(
                            "{s} is above the largest time limit of this service ({} s)",
                            self.config.max_time_limit.as_secs_f64()
                        ),
                    )
                })?,
            Some(s) => {
                return Err(ApiError::invalid_field(
                    "time_limit_secs",
                    format!("{s} must be finite and > 0"),
                ))
            }
        };
        if let Some(key) = &idempotency_key {
            if key.is_empty() || key.len() > 255 || !key.is_ascii() {
                return Err(ApiError::invalid_field(
                    "Idempotency-Key",
                    "must be 1 to 255 ASCII characters",
                ));
            }
        }
        let prepared = entry.prepare(&req.params, &self.limits)?;
        for (field, id) in &prepared.datasets {
            match self.datasets.meta_of(id, &owner.tenant) {
                Ok(_) => {}
                Err(StoreError::NotFound(_)) => {
                    return Err(ApiError::not_found(
                        Some(field),
                        format!("{field}: dataset '{id}' does not exist (or has expired)"),
                    ))
                }
                Err(e) => return Err(e.into()),
            }
        }
        let priority = req.priority.unwrap_or(default_priority);
        let time_limit_ms = ms(time_limit).max(1);
        let hash = fingerprint(&format!(
            "{}\n{}\n{}\n{}",
            entry.name,
            prepared.canonical,
            priority.rank(),
            time_limit_ms
        ));
        let new = db::NewJob {
            id: format!("job_{}", uuid::Uuid::now_v7().simple()),
            operation: entry.name.to_string(),
            params: prepared.canonical,
            priority: priority.rank(),
            time_limit_ms,
            max_attempts: i64::from(self.config.max_attempts.max(1)),
            request_hash: idempotency_key.as_ref().map(|_| hash.clone()),
            // The column is unique across tenants: each tenant's keys live
            // under its own prefix (a tenant name holds no '/').
            idempotency_key: idempotency_key.map(|k| format!("{}/{k}", owner.tenant)),
            now: now_ms(),
            tenant: owner.tenant.clone(),
        };
        let (row, created) = self.db.insert(&new).await?;
        if !created && row.request_hash.as_deref() != Some(hash.as_str()) {
            return Err(ApiError::invalid_field(
                "Idempotency-Key",
                format!(
                    "this key was already used for a different request (job {})",
                    row.id
                ),
            ));
        }
        if created {
            self.wake.notify_one();
        }
        Ok((Job::from(&row), created))
    }

    /// One job of `tenant` (another tenant's job is `None`, as an unknown id).
    pub async fn get(&self, id: &str, tenant: &str) -> Result<Option<JobRow>, ApiError> {
        if !valid_id(id) {
            return Ok(None);
        }
        Ok(self.db.get(id).await?.filter(|r| r.tenant == tenant))
    }

    /// A page of `tenant`'s jobs, newest first.
    pub async fn list(
        &self,
        tenant: &str,
        state: Option<JobState>,
        cursor: Option<&str>,
        limit: i64,
    ) -> Result<Vec<JobRow>, ApiError> {
        Ok(self.db.list(tenant, state, cursor, limit).await?)
    }

    /// Cancels a job of `tenant` (see [`JobDb::cancel`]); another tenant's
    /// job is left alone and reported unknown.
    pub async fn cancel(&self, id: &str, tenant: &str) -> Result<Option<JobRow>, ApiError> {
        if self.get(id, tenant).await?.is_none() {
            return Ok(None);
        }
        let now = now_ms();
        let problem = problem_json(&cancelled_problem(), id);
        let row = self.db.cancel(id, now, self.expiry(now), &problem).await?;
        // A job running in this process stops at once, without waiting for its heartbeat.
        if row.as_ref().is_some_and(|r| r.state == JobState::Running) {
            self.raise_local(id, StopReason::Cancel);
        }
        Ok(row)
    }

    /// The stored outputs of a succeeded job.
    pub fn outputs(row: &JobRow) -> BTreeMap<String, StoredOutput> {
        row.outputs
            .as_deref()
            .and_then(|s| serde_json::from_str(s).ok())
            .unwrap_or_default()
    }
}

/// 64-bit FNV-1a of the canonical request: the fingerprint stored with an
/// `Idempotency-Key` (stable across processes and versions).
fn fingerprint(text: &str) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in text.bytes() {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    format!("{h:016x}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fingerprints() {
        assert_eq!(fingerprint(""), "cbf29ce484222325");
        assert_eq!(fingerprint("a"), "af63dc4c8601ec8c");
        assert_ne!(fingerprint("ab"), fingerprint("ba"));
    }
}
