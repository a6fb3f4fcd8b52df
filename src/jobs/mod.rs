//! Durable jobs: every operation can run in the background, survive a crash
//! of the process that ran it, and be shared by several replicas.
//!
//! * [`db`]: the `geodex_jobs` table (queue and public resource at once) on
//!   SQLite (default, `<data_dir>/jobs.sqlite`, WAL) or PostgreSQL
//!   (`--queue postgres://…`, claims with `FOR UPDATE SKIP LOCKED`).
//! * [`crate::ops::registry`]: operation name → request type.
//! * [`results`]: result arrays in an object store (`--store file:///dir`, or
//!   `s3://…` with the `s3` feature), written with put-if-absent.
//! * [`worker`]: the workers (claim, run on the solver pool, heartbeat that
//!   renews the lease, carries progress and brings back cancellation), the lease
//!   reaper, the retention sweeper and the metrics.
//!
//! Life of a job: `queued` → `running` (a worker holds a lease of
//! `--job-lease-secs`, renewed every `--job-poll-ms`) → `succeeded` | `failed`
//! | `cancelled`. A worker that dies leaves its lease to run out; the reaper of
//! any replica then queues the job again (at most `--job-max-attempts` claims,
//! then `failed`). Delivery is at least once; results are idempotent because
//! each attempt writes under its own keys and only the attempt that still holds
//! the lease publishes (see [`db`] on fencing).

pub mod db;
pub mod results;
pub mod worker;

use std::collections::{BTreeMap, HashMap};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicU8, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use chrono::{DateTime, TimeZone, Utc};
use serde::{Deserialize, Serialize};
use serde_json::Value;
use tokio::sync::Notify;
use utoipa::ToSchema;

use crate::datasets::{DatasetStore, StoreError};
use crate::io::{DType, Limits};
use crate::ops::registry;
use crate::ops::OpLimits;
use crate::pool::SolverPool;
use crate::problem::{ApiError, Kind, Problem};

pub use db::{DbError, JobDb, JobRow};
pub use results::{ResultStore, ResultStoreError};

/// An error of the job system outside a request.
#[derive(Debug, thiserror::Error)]
pub enum JobsError {
    /// The database failed.
    #[error(transparent)]
    Db(#[from] DbError),
    /// The result store failed.
    #[error(transparent)]
    Results(#[from] ResultStoreError),
}

impl From<DbError> for ApiError {
    fn from(e: DbError) -> Self {
        tracing::error!(error = %e, "job database error");
        ApiError::busy("the job database is not reachable; retry later", 2)
    }
}

/// Settings of the job system (from `geodex serve` flags).
#[derive(Debug, Clone)]
pub struct JobsConfig {
    /// `sqlite` (the file `<data_dir>/jobs.sqlite`), `sqlite:///path/file.db`
    /// or `postgres://user@host:port/db`.
    pub queue: String,
    /// `file` (`<data_dir>/results`), `file:///dir` or `s3://bucket/prefix`.
    pub store: String,
    /// The data directory.
    pub data_dir: PathBuf,
    /// Jobs run at once by this process (0: this replica only serves the API).
    pub workers: usize,
    /// Lease length: how long a dead worker's job waits before it is run again.
    pub lease: Duration,
    /// Heartbeat period: progress writes, lease renewal and cancellation polling.
    pub poll: Duration,
    /// Claims allowed before a job whose worker keeps dying is failed.
    pub max_attempts: u32,
    /// Time limit of a job that names none.
    pub default_time_limit: Duration,
    /// Largest time limit a job may ask for.
    pub max_time_limit: Duration,
    /// How long ended jobs and their results are kept.
    pub retention: Duration,
}

/// Priority of a job: interactive jobs are claimed before batch jobs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum Priority {
    /// Someone is waiting: claimed first.
    Interactive,
    /// Background work (the default of `POST /v1/jobs`).
    Batch,
}

impl Priority {
    fn rank(self) -> i64 {
        match self {
            Priority::Interactive => 1,
            Priority::Batch => 0,
        }
    }

    fn from_rank(r: i64) -> Self {
        if r > 0 {
            Priority::Interactive
        } else {
            Priority::Batch
        }
    }
}

/// State of a job.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum JobState {
    /// Waiting for a worker.
    Queued,
    /// A worker runs it.
    Running,
    /// Done; `result` holds the answer.
    Succeeded,
    /// Ended with `error`.
    Failed,
    /// Cancelled on request; `error` says so.
    Cancelled,
}

impl JobState {
    /// The wire (and database) name.
    pub fn as_str(self) -> &'static str {
        match self {
            JobState::Queued => "queued",
            JobState::Running => "running",
            JobState::Succeeded => "succeeded",
            JobState::Failed => "failed",
            JobState::Cancelled => "cancelled",
        }
    }

    fn parse(s: &str) -> Self {
        match s {
            "running" => JobState::Running,
            "succeeded" => JobState::Succeeded,
            "failed" => JobState::Failed,
            "cancelled" => JobState::Cancelled,
            _ => JobState::Queued,
        }
    }

    /// True once the job can no longer change.
    pub fn is_final(self) -> bool {
        matches!(
            self,
            JobState::Succeeded | JobState::Failed | JobState::Cancelled
        )
    }
}

/// Body of `POST /v1/jobs`.
#[derive(Debug, Clone, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({
    "operation": "grid.distance",
    "params": {"cost": {"constant": 1.0, "shape": [256, 256]}, "sources": [{"point": [128.0, 128.0]}]},
    "priority": "batch",
    "time_limit_secs": 600
}))]
pub struct SubmitJob {
    /// The operation: `grid.distance`, `grid.metric`, `grid.paths`, `grid.edt`, `grid.segment`,
    /// `grid.skeleton`, `grid.offset`, `grid.plan`, `grid.tensor_distance`, `grid.tensor_metric`,
    /// `mesh.distance`, `mesh.voronoi`, `mesh.paths` or `mesh.sample`.
    pub operation: String,
    /// The same body as the operation's synchronous endpoint.
    #[schema(value_type = Object)]
    pub params: Value,
    /// `interactive` jobs are claimed before `batch` ones. Default: `batch`.
    #[serde(default)]
    pub priority: Option<Priority>,
    /// Time limit of one attempt in seconds; past it the job ends `failed`.
    /// Default: the service's `--job-time-limit-secs`.
    #[serde(default)]
    #[schema(minimum = 0.0)]
    pub time_limit_secs: Option<f64>,
}

/// A stored result array of a job.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct ResultRef {
    /// URL of the array (`?format=npy|tiff|png16|png|json`, default NPY).
    pub url: String,
    /// Shape, axis 0 first.
    pub shape: Vec<usize>,
    /// Element type.
    pub dtype: DType,
    /// Bytes of the NPY object.
    pub byte_size: u64,
}

/// Where an output array is stored (the `outputs` column).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StoredOutput {
    /// Object key.
    pub key: String,
    /// Shape.
    pub shape: Vec<usize>,
    /// Element type.
    pub dtype: DType,
    /// Bytes.
    pub byte_size: u64,
    /// Physical spacing, if any.
    pub spacing: Option<Vec<f64>>,
}

/// A job, as `GET /v1/jobs/{id}` shows it.
#[derive(Debug, Clone, Serialize, ToSchema)]
#[schema(example = json!({
    "id": "job_0192f1b27c1e7d3a9d553c0f2b8a1e44",
    "url": "/v1/jobs/job_0192f1b27c1e7d3a9d553c0f2b8a1e44",
    "operation": "grid.distance",
    "state": "succeeded",
    "priority": "batch",
    "progress": 1.0,
    "attempts": 1,
    "max_attempts": 3,
    "time_limit_secs": 3600.0,
    "cancel_requested": false,
    "created_at": "2026-11-22T10:00:00Z",
    "started_at": "2026-11-22T10:00:00.010Z",
    "finished_at": "2026-11-22T10:00:02Z",
    "expires_at": "2026-11-29T10:00:02Z",
    "params": {"cost": {"constant": 1.0, "shape": [256, 256]}, "sources": [{"point": [128.0, 128.0]}]},
    "result": {
        "distance": {"url": "/v1/jobs/job_0192f1b27c1e7d3a9d553c0f2b8a1e44/results/distance", "shape": [256, 256], "dtype": "f64", "byte_size": 524416},
        "stats": {"cells": 65536, "frozen": 65536, "stop": "completed", "solve_seconds": 0.012}
    }
}))]
pub struct Job {
    /// `job_` followed by 32 hex digits.
    pub id: String,
    /// This resource.
    pub url: String,
    /// The operation.
    pub operation: String,
    /// `queued`, `running`, `succeeded`, `failed` or `cancelled`.
    pub state: JobState,
    /// `interactive` or `batch`.
    pub priority: Priority,
    /// Fraction done, 0..1, reported by the solver (1 when succeeded).
    pub progress: f64,
    /// Attempts started (more than 1 when a worker died and the job ran again).
    pub attempts: i64,
    /// Attempts allowed.
    pub max_attempts: i64,
    /// Time limit of one attempt, seconds.
    pub time_limit_secs: f64,
    /// Cancellation was asked for.
    pub cancel_requested: bool,
    /// Submission time (UTC).
    pub created_at: DateTime<Utc>,
    /// Start of the latest attempt.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub started_at: Option<DateTime<Utc>>,
    /// End time.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub finished_at: Option<DateTime<Utc>>,
    /// When the record and its results are removed.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub expires_at: Option<DateTime<Utc>>,
    /// The request.
    #[schema(value_type = Object)]
    pub params: Value,
    /// When succeeded: the operation's document, with one [`ResultRef`] per
    /// output array under the array's name.
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schema(value_type = Object)]
    pub result: Option<Value>,
    /// When failed or cancelled: why, as a problem.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<Problem>,
}

fn time(ms: i64) -> DateTime<Utc> {
    Utc.timestamp_millis_opt(ms).single().unwrap_or_default()
}

impl From<&JobRow> for Job {
    fn from(r: &JobRow) -> Self {
        Job {
            url: format!("/v1/jobs/{}", r.id),
            id: r.id.clone(),
            operation: r.operation.clone(),
            state: JobState::parse(&r.state),
            priority: Priority::from_rank(r.priority),
            progress: r.progress,
            attempts: r.attempts,
            max_attempts: r.max_attempts,
            time_limit_secs: r.time_limit_ms as f64 / 1000.0,
            cancel_requested: r.cancel_requested,
            created_at: time(r.created_at),
            started_at: r.started_at.map(time),
            finished_at: r.finished_at.map(time),
            expires_at: r.expires_at.map(time),
            params: serde_json::from_str(&r.params).unwrap_or(Value::Null),
            result: r
                .result
                .as_deref()
                .and_then(|s| serde_json::from_str(s).ok()),
            error: r
                .error
                .as_deref()
                .and_then(|s| serde_json::from_str(s).ok()),
        }
    }
}

/// Milliseconds since the epoch, now.
pub fn now_ms() -> i64 {
    Utc::now().timestamp_millis()
}

fn ms(d: Duration) -> i64 {
    i64::try_from(d.as_millis()).unwrap_or(i64::MAX)
}

/// True if `id` has the shape of a job id (and so is safe in a key).
pub fn valid_id(id: &str) -> bool {
    id.len() == 36
        && id.starts_with("job_")
        && id[4..]
            .bytes()
            .all(|b| b.is_ascii_hexdigit() && !b.is_ascii_uppercase())
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

/// Builds the problem stored in a job record.
pub fn problem_json(e: &ApiError, job: &str) -> String {
    let mut p = (*e.problem).clone();
    p.instance = (!job.is_empty()).then(|| format!("/v1/jobs/{job}"));
    serde_json::to_string(&p).unwrap_or_default()
}

/// The problem of a cancelled job.
pub fn cancelled_problem() -> ApiError {
    ApiError::of(
        Kind::Cancelled,
        "the job was cancelled on request before it finished",
    )
}

/// Why a running attempt's flag was raised.
pub(crate) mod stop {
    /// Not raised.
    pub const NONE: u8 = 0;
    /// A client asked for cancellation.
    pub const CANCEL: u8 = 1;
    /// The time limit passed.
    pub const TIME_LIMIT: u8 = 2;
    /// The lease was lost (another worker owns the job now).
    pub const LEASE_LOST: u8 = 3;
    /// This process is shutting down: release the lease.
    pub const SHUTDOWN: u8 = 4;
}

/// The cancel flag, stop reason and progress of one running attempt.
#[derive(Debug, Default)]
pub(crate) struct RunFlags {
    pub flag: AtomicBool,
    pub reason: AtomicU8,
    pub progress: AtomicU64,
}

impl crate::runner::Watch for RunFlags {
    fn cancel_flag(&self) -> &AtomicBool {
        &self.flag
    }

    fn report(&self, fraction: f64) {
        self.progress.store(fraction.to_bits(), Ordering::Relaxed);
    }
}

impl RunFlags {
    /// Raises the flag with a reason (the first reason wins).
    pub fn stop(&self, reason: u8) {
        let _ =
            self.reason
                .compare_exchange(stop::NONE, reason, Ordering::SeqCst, Ordering::SeqCst);
        self.flag.store(true, Ordering::SeqCst);
    }

    pub fn reason(&self) -> u8 {
        self.reason.load(Ordering::SeqCst)
    }

    pub fn progress(&self) -> f64 {
        f64::from_bits(self.progress.load(Ordering::Relaxed))
    }
}

/// The job system of one process: submission, queries and the workers.
#[derive(Debug)]
pub struct Jobs {
    pub(crate) db: JobDb,
    pub(crate) results: ResultStore,
    pub(crate) config: JobsConfig,
    pub(crate) worker_id: String,
    pub(crate) datasets: Arc<DatasetStore>,
    pub(crate) pool: Arc<SolverPool>,
    pub(crate) runner: crate::runner::Runner,
    pub(crate) limits: OpLimits,
    pub(crate) io_limits: Limits,
    pub(crate) wake: Notify,
    pub(crate) stopping: AtomicBool,
    pub(crate) running: Mutex<HashMap<String, Arc<RunFlags>>>,
}

impl Jobs {
    /// Opens the queue and the result store named by `config` and migrates
    /// the schema. Workers start with [`Jobs::start`].
    pub async fn open(
        config: JobsConfig,
        datasets: Arc<DatasetStore>,
        pool: Arc<SolverPool>,
        limits: OpLimits,
        io_limits: Limits,
    ) -> Result<Self, JobsError> {
        let db = if config.queue.starts_with("postgres://")
            || config.queue.starts_with("postgresql://")
        {
            JobDb::open_postgres(&config.queue, (config.workers as u32) * 2 + 4).await?
        } else if config.queue == "sqlite" {
            JobDb::open_sqlite(&config.data_dir.join("jobs.sqlite")).await?
        } else if let Some(path) = config.queue.strip_prefix("sqlite://") {
            JobDb::open_sqlite(std::path::Path::new(path)).await?
        } else {
            return Err(DbError::Url(format!(
                "'{}': expected sqlite, sqlite:///path/jobs.db or postgres://user@host:port/db",
                config.queue
            ))
            .into());
        };
        let results = if config.store == "file" {
            ResultStore::local(&config.data_dir.join("results"))?
        } else {
            ResultStore::open(&config.store)?
        };
        let host = std::env::var("HOSTNAME").unwrap_or_else(|_| "geodex".into());
        let worker_id = format!(
            "{host}:{}:{}",
            std::process::id(),
            &uuid::Uuid::new_v4().simple().to_string()[..8]
        );
        tracing::info!(queue = db.engine(), store = results.description(), worker = %worker_id,
            workers = config.workers, "job queue open");
        Ok(Self {
            db,
            results,
            config,
            worker_id,
            datasets,
            runner: crate::runner::Runner::new(Arc::clone(&pool), limits),
            pool,
            limits,
            io_limits,
            wake: Notify::new(),
            stopping: AtomicBool::new(false),
            running: Mutex::new(HashMap::new()),
        })
    }

    /// The database.
    pub fn db(&self) -> &JobDb {
        &self.db
    }

    /// The result store.
    pub fn results(&self) -> &ResultStore {
        &self.results
    }

    /// This process's worker id (`host:pid:random`).
    pub fn worker_id(&self) -> &str {
        &self.worker_id
    }

    /// Retention of ended jobs.
    pub fn retention(&self) -> Duration {
        self.config.retention
    }

    fn expiry(&self, now: i64) -> i64 {
        now.saturating_add(ms(self.config.retention))
    }

    /// Validates and queues a job. Returns it and whether it is new (false:
    /// an earlier job with the same `Idempotency-Key`).
    pub async fn submit(
        &self,
        req: SubmitJob,
        idempotency_key: Option<String>,
        default_priority: Priority,
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
            match self.datasets.meta(id) {
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
            idempotency_key,
            now: now_ms(),
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

    /// One job.
    pub async fn get(&self, id: &str) -> Result<Option<JobRow>, ApiError> {
        if !valid_id(id) {
            return Ok(None);
        }
        Ok(self.db.get(id).await?)
    }

    /// A page of jobs, newest first.
    pub async fn list(
        &self,
        state: Option<JobState>,
        cursor: Option<&str>,
        limit: i64,
    ) -> Result<Vec<JobRow>, ApiError> {
        Ok(self
            .db
            .list(state.map(JobState::as_str), cursor, limit)
            .await?)
    }

    /// Cancels a job (see [`JobDb::cancel`]).
    pub async fn cancel(&self, id: &str) -> Result<Option<JobRow>, ApiError> {
        if !valid_id(id) {
            return Ok(None);
        }
        let now = now_ms();
        let problem = problem_json(&cancelled_problem(), id);
        let row = self.db.cancel(id, now, self.expiry(now), &problem).await?;
        // A job running in this process stops at once, without waiting for its heartbeat.
        if row.as_ref().is_some_and(|r| r.state == "running") {
            self.raise_local(id, stop::CANCEL);
        }
        Ok(row)
    }

    pub(crate) fn raise_local(&self, id: &str, reason: u8) {
        let running = self.running.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(f) = running.get(id) {
            f.stop(reason);
        }
    }

    /// The stored outputs of a succeeded job.
    pub fn outputs(row: &JobRow) -> BTreeMap<String, StoredOutput> {
        row.outputs
            .as_deref()
            .and_then(|s| serde_json::from_str(s).ok())
            .unwrap_or_default()
    }

    /// Jobs in this process's hands now.
    pub fn running_here(&self) -> usize {
        self.running.lock().map_or(0, |r| r.len())
    }

    /// Limits used to decode stored results.
    pub fn io_limits(&self) -> Limits {
        self.io_limits
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_and_fingerprints() {
        assert!(valid_id("job_0192f1b27c1e7d3a9d553c0f2b8a1e44"));
        assert!(!valid_id("job_0192F1B27C1E7D3A9D553C0F2B8A1E44"));
        assert!(!valid_id("job_../../etc"));
        assert_eq!(fingerprint(""), "cbf29ce484222325");
        assert_eq!(fingerprint("a"), "af63dc4c8601ec8c");
        assert_ne!(fingerprint("ab"), fingerprint("ba"));
    }

    #[test]
    fn first_stop_reason_wins() {
        let f = RunFlags::default();
        assert_eq!(f.reason(), stop::NONE);
        f.stop(stop::TIME_LIMIT);
        f.stop(stop::CANCEL);
        assert_eq!(f.reason(), stop::TIME_LIMIT);
        assert!(f.flag.load(Ordering::SeqCst));
    }
}
