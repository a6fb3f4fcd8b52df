//! Durable jobs: every operation can run in the background, survive a crash
//! of the process that ran it, and be shared by several replicas.
//!
//! * [`model`]: what describes a job: the public resource [`Job`] and its
//!   [`JobState`] and [`Priority`], the body of a submission ([`SubmitJob`]),
//!   where results are stored, the problems a job ends with, ids and times.
//! * [`Jobs`] (this module): the job system of one process; its client side
//!   (`queue.rs`: [`Jobs::submit`], [`Jobs::get`], [`Jobs::list`],
//!   [`Jobs::cancel`]) and its workers ([`worker`]) are `impl` blocks of it.
//! * [`db`]: the `geodex_jobs` table (queue and public resource at once) on
//!   SQLite (default, `<data_dir>/jobs.sqlite`, WAL) or PostgreSQL
//!   (`--queue postgres://…`, claims with `FOR UPDATE SKIP LOCKED`).
//! * [`crate::ops::registry`]: operation name → request type.
//! * [`results`]: result arrays in an object store (`--store file:///dir`, or
//!   `s3://…` with the `s3` feature), written with put-if-absent.
//! * [`worker`]: the workers (claim, run on the solver pool, heartbeat that
//!   renews the lease, carries progress and brings back cancellation), the lease
//!   reaper, the retention sweeper and the metrics.
//! * `flags.rs`: the cancel flag, stop reason and progress of one running
//!   attempt, shared by its solver, its heartbeat and cancellation.
//!
//! Life of a job: `queued` → `running` (a worker holds a lease of
//! `--job-lease-secs`, renewed every `--job-poll-ms`) → `succeeded` | `failed`
//! | `cancelled`. A worker that dies leaves its lease to run out; the reaper of
//! any replica then queues the job again (at most `--job-max-attempts` claims,
//! then `failed`). Delivery is at least once; results are idempotent because
//! each attempt writes under its own keys and only the attempt that still holds
//! the lease publishes (see [`db`] on fencing).

pub mod db;
mod flags;
pub mod model;
mod queue;
pub mod results;
pub mod worker;

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use tokio::sync::Notify;

use crate::datasets::DatasetStore;
use crate::io::Limits;
use crate::ops::OpLimits;
use crate::pool::SolverPool;
use crate::problem::ApiError;
use model::ms;

pub use db::{DbError, JobDb, JobRow};
pub(crate) use flags::{RunFlags, StopReason};
pub use model::{
    cancelled_problem, now_ms, problem_json, time_limit_problem, valid_id, Job, JobState, Priority,
    ResultRef, StoredOutput, SubmitJob,
};
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

/// The job system of one process: submission, queries and the workers.
#[derive(Debug)]
pub struct Jobs {
    /// The queue (and the public job records).
    pub(crate) db: JobDb,
    /// Where result arrays are written.
    pub(crate) results: ResultStore,
    /// The settings.
    pub(crate) config: JobsConfig,
    /// `host:pid:random`: the lease owner of this process's claims.
    pub(crate) worker_id: String,
    /// Input datasets of the operations.
    pub(crate) datasets: Arc<DatasetStore>,
    /// The solver pool the jobs run on (its room gates claims).
    pub(crate) pool: Arc<SolverPool>,
    /// Runs an operation on `pool`.
    pub(crate) runner: crate::runner::Runner,
    /// Limits a submitted request is validated against.
    pub(crate) limits: OpLimits,
    /// Limits used to decode stored results.
    pub(crate) io_limits: Limits,
    /// Wakes an idle worker (new or released job).
    pub(crate) wake: Notify,
    /// Set at SIGTERM: workers stop claiming.
    pub(crate) stopping: AtomicBool,
    /// The flags of the attempts this process runs, by job id.
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
        let db = JobDb::open_queue(
            &config.queue,
            &config.data_dir,
            (config.workers as u32) * 2 + 4,
        )
        .await?;
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
        // Published results count against the storage quotas with datasets.
        for (tenant, bytes) in db.result_bytes().await? {
            datasets.charge_found(bytes, &tenant);
        }
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

    /// When a job that ends at `now` is removed, with its results.
    fn expiry(&self, now: i64) -> i64 {
        now.saturating_add(ms(self.config.retention))
    }

    /// Raises the flag of a job if this process runs it (no-op otherwise).
    pub(crate) fn raise_local(&self, id: &str, reason: StopReason) {
        let running = self.running.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(f) = running.get(id) {
            f.stop(reason);
        }
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
