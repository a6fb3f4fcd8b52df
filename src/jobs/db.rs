//! The job table over sqlx: SQLite (embedded default) or PostgreSQL (scale-out).
//!
//! One table, `geodex_jobs`, is both the queue and the public job resource
//! (`migrations/0001_jobs.sql`, the same portable SQL for both engines). Every
//! statement here is written once with `$n` placeholders, which both drivers
//! accept; only the claim differs (`FOR UPDATE SKIP LOCKED` on PostgreSQL).
//!
//! **Leases and fencing.** A claim sets `state = 'running'`, the worker id in
//! `lease_owner`, `lease_until = now + lease` and increments `attempts`. Every
//! later write of that worker (heartbeat, result, release) is conditional on
//! `(id, lease_owner, attempts, state = 'running')`: a worker whose lease ran
//! out and whose job was claimed again cannot overwrite the new attempt.
//!
//! **States.** The `state` column holds [`JobState::as_str`]; rows decode it
//! back into a [`JobState`], and the statements name states through the
//! constants below, so the names are spelled in one place.

use std::borrow::Cow;
use std::str::FromStr;
use std::time::Duration;

use sqlx::migrate::{Migration, MigrationType, Migrator};
use sqlx::postgres::{PgConnectOptions, PgPool, PgPoolOptions};
use sqlx::sqlite::{
    SqliteConnectOptions, SqliteJournalMode, SqlitePool, SqlitePoolOptions, SqliteSynchronous,
};
use sqlx::{Row, SqlSafeStr};

use super::model::JobState;

/// Name of the PostgreSQL notification channel that announces new jobs.
pub const CHANNEL_NEW: &str = "geodex_jobs";
/// Name of the PostgreSQL notification channel that announces cancellations.
pub const CHANNEL_CANCEL: &str = "geodex_jobs_cancel";

/// [`JobState::Queued`] in statements.
const QUEUED: &str = JobState::Queued.as_str();
/// [`JobState::Running`] in statements.
const RUNNING: &str = JobState::Running.as_str();
/// [`JobState::Succeeded`] in statements.
const SUCCEEDED: &str = JobState::Succeeded.as_str();
/// [`JobState::Failed`] in statements.
const FAILED: &str = JobState::Failed.as_str();
/// [`JobState::Cancelled`] in statements.
const CANCELLED: &str = JobState::Cancelled.as_str();

/// A database error of the job store.
#[derive(Debug, thiserror::Error)]
pub enum DbError {
    /// The driver failed (connection, query, constraint).
    #[error("job database: {0}")]
    Sqlx(#[from] sqlx::Error),
    /// The schema migration failed.
    #[error("job database migration: {0}")]
    Migrate(#[from] sqlx::migrate::MigrateError),
    /// `--queue` is not a recognised URL.
    #[error("--queue: {0}")]
    Url(String),
}

/// One row of `geodex_jobs`.
#[derive(Debug, Clone, PartialEq)]
pub struct JobRow {
    /// `job_` + 32 hex digits.
    pub id: String,
    /// Operation name.
    pub operation: String,
    /// Canonical JSON of the request.
    pub params: String,
    /// Where the job is in its life.
    pub state: JobState,
    /// 1 interactive, 0 batch.
    pub priority: i64,
    /// Time limit of one attempt, ms.
    pub time_limit_ms: i64,
    /// Claims so far.
    pub attempts: i64,
    /// Claims allowed.
    pub max_attempts: i64,
    /// Worker holding the lease.
    pub lease_owner: Option<String>,
    /// End of the lease, ms.
    pub lease_until: Option<i64>,
    /// Cancellation asked for.
    pub cancel_requested: bool,
    /// 0..1.
    pub progress: f64,
    /// Client's `Idempotency-Key`.
    pub idempotency_key: Option<String>,
    /// Fingerprint of the request sent with the key.
    pub request_hash: Option<String>,
    /// Result document (JSON).
    pub result: Option<String>,
    /// Stored arrays (JSON).
    pub outputs: Option<String>,
    /// Problem (JSON).
    pub error: Option<String>,
    /// ms since the epoch.
    pub created_at: i64,
    /// Start of the latest attempt, ms.
    pub started_at: Option<i64>,
    /// End, ms.
    pub finished_at: Option<i64>,
    /// Last write, ms.
    pub updated_at: i64,
    /// Removal time, ms.
    pub expires_at: Option<i64>,
    /// The tenant that submitted it (`''` when auth is off).
    pub tenant: String,
}

/// A new job to insert.
#[derive(Debug, Clone)]
pub struct NewJob {
    /// Its id.
    pub id: String,
    /// Operation name.
    pub operation: String,
    /// Canonical JSON of the request.
    pub params: String,
    /// 1 interactive, 0 batch.
    pub priority: i64,
    /// Per-attempt time limit, ms.
    pub time_limit_ms: i64,
    /// Claims allowed.
    pub max_attempts: i64,
    /// `Idempotency-Key`, if any.
    pub idempotency_key: Option<String>,
    /// Fingerprint of the request.
    pub request_hash: Option<String>,
    /// ms since the epoch.
    pub now: i64,
    /// The submitting tenant.
    pub tenant: String,
}

/// How a finished attempt is written back.
#[derive(Debug, Clone)]
pub struct Finish {
    /// [`JobState::Succeeded`], [`JobState::Failed`] or [`JobState::Cancelled`].
    pub state: JobState,
    /// Final progress.
    pub progress: f64,
    /// Result document.
    pub result: Option<String>,
    /// Stored arrays.
    pub outputs: Option<String>,
    /// Problem.
    pub error: Option<String>,
    /// ms since the epoch.
    pub now: i64,
    /// When the record and its results are removed.
    pub expires_at: i64,
}

/// The lease a worker holds: its fencing token.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Lease {
    /// Job id.
    pub id: String,
    /// Worker id.
    pub owner: String,
    /// Attempt number of this claim.
    pub attempt: i64,
}

/// What the lease reaper did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Reaped {
    /// Jobs put back in the queue: (id, operation).
    pub requeued: Vec<(String, String)>,
    /// Jobs failed after their last attempt: (id, operation).
    pub failed: Vec<(String, String)>,
    /// Jobs whose cancellation was asked while their worker died.
    pub cancelled: usize,
}

const COLUMNS: &str = "id, operation, params, state, priority, time_limit_ms, attempts, max_attempts, \
lease_owner, lease_until, cancel_requested, progress, idempotency_key, request_hash, result, outputs, \
error, created_at, started_at, finished_at, updated_at, expires_at, tenant";

/// The total `byte_size` of an `outputs` column (0 if it cannot be read).
pub fn outputs_bytes(outputs: &str) -> u64 {
    serde_json::from_str::<std::collections::BTreeMap<String, serde_json::Value>>(outputs)
        .map(|m| {
            m.values()
                .filter_map(|o| o.get("byte_size").and_then(serde_json::Value::as_u64))
                .sum()
        })
        .unwrap_or(0)
}

/// A statement assembled from constant parts only (never from input).
macro_rules! sql {
    ($fmt:literal) => {
        sqlx::AssertSqlSafe(format!($fmt))
    };
}

/// Reads a `state` value; a name that is no [`JobState`] is a decoding error
/// of the column.
fn decode_state(name: String) -> Result<JobState, sqlx::Error> {
    name.parse().map_err(|e| sqlx::Error::ColumnDecode {
        index: "state".into(),
        source: Box::new(e),
    })
}

macro_rules! decode_row {
    ($row:expr) => {{
        let r = $row;
        JobRow {
            id: r.try_get("id")?,
            operation: r.try_get("operation")?,
            params: r.try_get("params")?,
            state: decode_state(r.try_get("state")?)?,
            priority: r.try_get("priority")?,
            time_limit_ms: r.try_get("time_limit_ms")?,
            attempts: r.try_get("attempts")?,
            max_attempts: r.try_get("max_attempts")?,
            lease_owner: r.try_get("lease_owner")?,
            lease_until: r.try_get("lease_until")?,
            cancel_requested: r.try_get("cancel_requested")?,
            progress: r.try_get("progress")?,
            idempotency_key: r.try_get("idempotency_key")?,
            request_hash: r.try_get("request_hash")?,
            result: r.try_get("result")?,
            outputs: r.try_get("outputs")?,
            error: r.try_get("error")?,
            created_at: r.try_get("created_at")?,
            started_at: r.try_get("started_at")?,
            finished_at: r.try_get("finished_at")?,
            updated_at: r.try_get("updated_at")?,
            expires_at: r.try_get("expires_at")?,
            tenant: r.try_get("tenant")?,
        }
    }};
}

/// Runs the same code against whichever pool this is: `$body` is written
/// once and compiled for each engine (the jobs, the collections and the
/// API keys all share this database).
macro_rules! on_pool {
    ($db:expr, $p:ident => $body:expr) => {
        match $db {
            $crate::jobs::db::JobDb::Sqlite($p) => $body,
            $crate::jobs::db::JobDb::Postgres($p) => $body,
        }
    };
}
pub(crate) use on_pool;

/// The job table on one engine.
#[derive(Debug, Clone)]
pub enum JobDb {
    /// The embedded default: a SQLite file in WAL mode.
    Sqlite(SqlitePool),
    /// Scale-out: a PostgreSQL database shared by every replica.
    Postgres(PgPool),
}

fn migrator() -> Migrator {
    let mut m = Migrator::with_migrations(vec![
        Migration::new(
            1,
            Cow::Borrowed("jobs"),
            MigrationType::Simple,
            include_str!("../../migrations/0001_jobs.sql").into_sql_str(),
            false,
        ),
        // The shape collections (`crate::collections`) share the database.
        Migration::new(
            2,
            Cow::Borrowed("collections"),
            MigrationType::Simple,
            include_str!("../../migrations/0002_collections.sql").into_sql_str(),
            false,
        ),
        // API keys (`crate::auth`) and the tenant of jobs and collections.
        Migration::new(
            3,
            Cow::Borrowed("tenants"),
            MigrationType::Simple,
            include_str!("../../migrations/0003_tenants.sql").into_sql_str(),
            false,
        ),
    ]);
    m.dangerous_set_table_name("geodex_migrations");
    m
}

impl JobDb {
    /// Opens a SQLite database file (created if missing) in WAL mode with a
    /// busy timeout, and migrates it.
    pub async fn open_sqlite(path: &std::path::Path) -> Result<Self, DbError> {
        let options = SqliteConnectOptions::new()
            .filename(path)
            .create_if_missing(true)
            .journal_mode(SqliteJournalMode::Wal)
            .synchronous(SqliteSynchronous::Normal)
            .busy_timeout(Duration::from_secs(10));
        let pool = SqlitePoolOptions::new()
            .max_connections(4)
            .connect_with(options)
            .await?;
        migrator().run(&pool).await?;
        Ok(JobDb::Sqlite(pool))
    }

    /// Connects to PostgreSQL (`postgres://user@host:port/db`, options such
    /// as `?options[search_path]=schema` allowed) and migrates the schema.
    pub async fn open_postgres(url: &str, max_connections: u32) -> Result<Self, DbError> {
        let options = PgConnectOptions::from_str(url).map_err(|e| DbError::Url(e.to_string()))?;
        let pool = PgPoolOptions::new()
            .max_connections(max_connections.max(2))
            .acquire_timeout(Duration::from_secs(10))
            .connect_with(options)
            .await?;
        migrator().run(&pool).await?;
        Ok(JobDb::Postgres(pool))
    }

    /// Opens the database named by `--queue`: `sqlite` (the file
    /// `<data_dir>/jobs.sqlite`), `sqlite:///path/jobs.db`, or
    /// `postgres://user@host:port/db` (at most `max_connections`). A failure
    /// never repeats the URL's password.
    pub async fn open_queue(
        queue: &str,
        data_dir: &std::path::Path,
        max_connections: u32,
    ) -> Result<Self, DbError> {
        let hidden = crate::config::redact_url(queue);
        let scrub = |m: String| crate::config::scrub_secret(&m, queue);
        let redacted = |e: DbError| match e {
            DbError::Url(m) => DbError::Url(scrub(m)),
            DbError::Sqlx(s) => DbError::Url(scrub(s.to_string())),
            other => other,
        };
        if queue.starts_with("postgres://") || queue.starts_with("postgresql://") {
            JobDb::open_postgres(queue, max_connections)
                .await
                .map_err(redacted)
        } else if queue == "sqlite" {
            JobDb::open_sqlite(&data_dir.join("jobs.sqlite")).await
        } else if let Some(path) = queue.strip_prefix("sqlite://") {
            JobDb::open_sqlite(std::path::Path::new(path)).await
        } else {
            Err(DbError::Url(format!(
                "'{hidden}': expected sqlite, sqlite:///path/jobs.db or postgres://user@host:port/db"
            )))
        }
    }

    /// `sqlite` or `postgres`.
    pub fn engine(&self) -> &'static str {
        match self {
            JobDb::Sqlite(_) => "sqlite",
            JobDb::Postgres(_) => "postgres",
        }
    }

    /// Inserts a job. With an idempotency key already used, inserts nothing
    /// and returns the existing job and `false`.
    pub async fn insert(&self, job: &NewJob) -> Result<(JobRow, bool), DbError> {
        let insert = sql!(
            "INSERT INTO geodex_jobs (id, operation, params, state, priority, time_limit_ms, \
             attempts, max_attempts, cancel_requested, progress, idempotency_key, request_hash, \
             created_at, updated_at, tenant) \
             VALUES ($1, $2, $3, '{QUEUED}', $4, $5, 0, $6, FALSE, 0, $7, $8, $9, $9, $10) \
             ON CONFLICT (idempotency_key) DO NOTHING"
        );
        let done = on_pool!(self, p => sqlx::query(insert)
            .bind(&job.id)
            .bind(&job.operation)
            .bind(&job.params)
            .bind(job.priority)
            .bind(job.time_limit_ms)
            .bind(job.max_attempts)
            .bind(&job.idempotency_key)
            .bind(&job.request_hash)
            .bind(job.now)
            .bind(&job.tenant)
            .execute(p)
            .await?
            .rows_affected());
        if done == 1 {
            if let JobDb::Postgres(p) = self {
                sqlx::query("SELECT pg_notify($1, $2)")
                    .bind(CHANNEL_NEW)
                    .bind(&job.id)
                    .execute(p)
                    .await?;
            }
            let row = self.get(&job.id).await?;
            return row
                .map(|r| (r, true))
                .ok_or_else(|| DbError::Sqlx(sqlx::Error::RowNotFound));
        }
        let key = job.idempotency_key.clone().unwrap_or_default();
        let q = sql!("SELECT {COLUMNS} FROM geodex_jobs WHERE idempotency_key = $1");
        let row = on_pool!(self, p => {
            let r = sqlx::query(q).bind(&key).fetch_one(p).await?;
            decode_row!(&r)
        });
        Ok((row, false))
    }

    /// The job with this id.
    pub async fn get(&self, id: &str) -> Result<Option<JobRow>, DbError> {
        let q = sql!("SELECT {COLUMNS} FROM geodex_jobs WHERE id = $1");
        Ok(on_pool!(self, p => {
            match sqlx::query(q).bind(id).fetch_optional(p).await? {
                Some(r) => Some(decode_row!(&r)),
                None => None,
            }
        }))
    }

    /// Jobs of `tenant`, newest first, optionally of one state, with ids
    /// below `before`.
    pub async fn list(
        &self,
        tenant: &str,
        state: Option<JobState>,
        before: Option<&str>,
        limit: i64,
    ) -> Result<Vec<JobRow>, DbError> {
        let q = sql!(
            "SELECT {COLUMNS} FROM geodex_jobs WHERE tenant = $1 AND ($2 IS NULL OR state = $2) \
             AND ($3 IS NULL OR id < $3) ORDER BY id DESC LIMIT $4"
        );
        Ok(on_pool!(self, p => {
            let rows = sqlx::query(q)
                .bind(tenant)
                .bind(state.map(JobState::as_str))
                .bind(before)
                .bind(limit)
                .fetch_all(p)
                .await?;
            let mut out = Vec::with_capacity(rows.len());
            for r in &rows {
                out.push(decode_row!(r));
            }
            out
        }))
    }

    /// Claims the next queued job (interactive before batch, then oldest
    /// first) for `owner` until `lease_until`.
    pub async fn claim(
        &self,
        owner: &str,
        now: i64,
        lease_until: i64,
    ) -> Result<Option<JobRow>, DbError> {
        let lock = match self {
            JobDb::Sqlite(_) => "",
            JobDb::Postgres(_) => " FOR UPDATE SKIP LOCKED",
        };
        let q = sql!(
            "UPDATE geodex_jobs SET state = '{RUNNING}', lease_owner = $1, lease_until = $2, \
             attempts = attempts + 1, started_at = $3, updated_at = $3, progress = 0 \
             WHERE state = '{QUEUED}' AND id = (SELECT id FROM geodex_jobs WHERE state = '{QUEUED}' \
             ORDER BY priority DESC, id LIMIT 1{lock}) RETURNING {COLUMNS}"
        );
        Ok(on_pool!(self, p => {
            match sqlx::query(q)
                .bind(owner)
                .bind(lease_until)
                .bind(now)
                .fetch_optional(p)
                .await?
            {
                Some(r) => Some(decode_row!(&r)),
                None => None,
            }
        }))
    }

    /// Renews a lease and records progress. Returns `Some(cancel_requested)`,
    /// or `None` when the lease is no longer this worker's.
    pub async fn heartbeat(
        &self,
        lease: &Lease,
        progress: f64,
        now: i64,
        lease_until: i64,
    ) -> Result<Option<bool>, DbError> {
        let q = sql!(
            "UPDATE geodex_jobs SET lease_until = $1, progress = $2, updated_at = $3 \
             WHERE id = $4 AND lease_owner = $5 AND attempts = $6 AND state = '{RUNNING}' \
             RETURNING cancel_requested"
        );
        Ok(on_pool!(self, p => {
            match sqlx::query(q)
                .bind(lease_until)
                .bind(progress)
                .bind(now)
                .bind(&lease.id)
                .bind(&lease.owner)
                .bind(lease.attempt)
                .fetch_optional(p)
                .await?
            {
                Some(r) => Some(r.try_get::<bool, _>("cancel_requested")?),
                None => None,
            }
        }))
    }

    /// Writes the end of an attempt. False when the lease was lost (nothing written).
    pub async fn finish(&self, lease: &Lease, f: &Finish) -> Result<bool, DbError> {
        let q = sql!(
            "UPDATE geodex_jobs SET state = $1, progress = $2, result = $3, outputs = $4, \
             error = $5, finished_at = $6, updated_at = $6, expires_at = $7, lease_owner = NULL, \
             lease_until = NULL \
             WHERE id = $8 AND lease_owner = $9 AND attempts = $10 AND state = '{RUNNING}'"
        );
        let n = on_pool!(self, p => sqlx::query(q)
            .bind(f.state.as_str())
            .bind(f.progress)
            .bind(&f.result)
            .bind(&f.outputs)
            .bind(&f.error)
            .bind(f.now)
            .bind(f.expires_at)
            .bind(&lease.id)
            .bind(&lease.owner)
            .bind(lease.attempt)
            .execute(p)
            .await?
            .rows_affected());
        Ok(n == 1)
    }

    /// Puts a claimed job back in the queue. `uncount` gives the attempt
    /// back (shutdown, full pool): the job did not fail.
    pub async fn release(&self, lease: &Lease, now: i64, uncount: bool) -> Result<bool, DbError> {
        let q = sql!(
            "UPDATE geodex_jobs SET state = '{QUEUED}', lease_owner = NULL, lease_until = NULL, \
             attempts = attempts - $1, progress = 0, updated_at = $2 \
             WHERE id = $3 AND lease_owner = $4 AND attempts = $5 AND state = '{RUNNING}'"
        );
        let n = on_pool!(self, p => sqlx::query(q)
            .bind(i64::from(uncount))
            .bind(now)
            .bind(&lease.id)
            .bind(&lease.owner)
            .bind(lease.attempt)
            .execute(p)
            .await?
            .rows_affected());
        if n == 1 {
            if let JobDb::Postgres(p) = self {
                sqlx::query("SELECT pg_notify($1, $2)")
                    .bind(CHANNEL_NEW)
                    .bind(&lease.id)
                    .execute(p)
                    .await?;
            }
        }
        Ok(n == 1)
    }

    /// Asks for cancellation: a queued job ends `cancelled` at once (and never
    /// starts), a running one gets `cancel_requested` for its worker's
    /// heartbeat. Returns the job after the change, or `None` if unknown.
    pub async fn cancel(
        &self,
        id: &str,
        now: i64,
        expires_at: i64,
        problem: &str,
    ) -> Result<Option<JobRow>, DbError> {
        let queued = sql!(
            "UPDATE geodex_jobs SET state = '{CANCELLED}', cancel_requested = TRUE, \
             finished_at = $1, updated_at = $1, expires_at = $2, error = $3 \
             WHERE id = $4 AND state = '{QUEUED}'"
        );
        let running = sql!(
            "UPDATE geodex_jobs SET cancel_requested = TRUE, updated_at = $1 \
             WHERE id = $2 AND state = '{RUNNING}'"
        );
        let n = on_pool!(self, p => sqlx::query(queued)
            .bind(now)
            .bind(expires_at)
            .bind(problem)
            .bind(id)
            .execute(p)
            .await?
            .rows_affected());
        if n == 0 {
            let m = on_pool!(self, p => sqlx::query(running)
                .bind(now)
                .bind(id)
                .execute(p)
                .await?
                .rows_affected());
            if m == 1 {
                if let JobDb::Postgres(p) = self {
                    sqlx::query("SELECT pg_notify($1, $2)")
                        .bind(CHANNEL_CANCEL)
                        .bind(id)
                        .execute(p)
                        .await?;
                }
            }
        }
        self.get(id).await
    }

    /// Handles jobs whose lease ran out (their worker died): cancelled if
    /// that was asked, failed after the last attempt, else queued again.
    pub async fn reap(
        &self,
        now: i64,
        expires_at: i64,
        cancelled_problem: &str,
        failed_problem: &str,
    ) -> Result<Reaped, DbError> {
        let cancel = sql!(
            "UPDATE geodex_jobs SET state = '{CANCELLED}', finished_at = $1, updated_at = $1, \
             expires_at = $2, error = $3, lease_owner = NULL, lease_until = NULL \
             WHERE state = '{RUNNING}' AND lease_until < $1 AND cancel_requested = TRUE"
        );
        let fail = sql!(
            "UPDATE geodex_jobs SET state = '{FAILED}', finished_at = $1, updated_at = $1, \
             expires_at = $2, error = $3, lease_owner = NULL, lease_until = NULL \
             WHERE state = '{RUNNING}' AND lease_until < $1 AND attempts >= max_attempts \
             RETURNING id, operation"
        );
        let requeue = sql!(
            "UPDATE geodex_jobs SET state = '{QUEUED}', lease_owner = NULL, \
             lease_until = NULL, progress = 0, updated_at = $1 \
             WHERE state = '{RUNNING}' AND lease_until < $1 RETURNING id, operation"
        );
        let (cancelled, failed, requeued) = on_pool!(self, p => {
            let cancelled = sqlx::query(cancel)
                .bind(now)
                .bind(expires_at)
                .bind(cancelled_problem)
                .execute(p)
                .await?
                .rows_affected() as usize;
            let mut failed = Vec::new();
            for r in sqlx::query(fail)
                .bind(now)
                .bind(expires_at)
                .bind(failed_problem)
                .fetch_all(p)
                .await?
            {
                failed.push((r.try_get::<String, _>("id")?, r.try_get::<String, _>("operation")?));
            }
            let mut requeued = Vec::new();
            for r in sqlx::query(requeue).bind(now).fetch_all(p).await? {
                requeued.push((r.try_get::<String, _>("id")?, r.try_get::<String, _>("operation")?));
            }
            (cancelled, failed, requeued)
        });
        if !requeued.is_empty() {
            if let JobDb::Postgres(p) = self {
                sqlx::query("SELECT pg_notify($1, '')")
                    .bind(CHANNEL_NEW)
                    .execute(p)
                    .await?;
            }
        }
        Ok(Reaped {
            requeued,
            failed,
            cancelled,
        })
    }

    /// Ids of ended jobs whose retention has passed (at most `limit`).
    pub async fn expired(&self, now: i64, limit: i64) -> Result<Vec<String>, DbError> {
        let q = "SELECT id FROM geodex_jobs WHERE expires_at IS NOT NULL AND expires_at < $1 \
                 ORDER BY expires_at LIMIT $2";
        Ok(on_pool!(self, p => {
            let mut ids = Vec::new();
            for r in sqlx::query(q).bind(now).bind(limit).fetch_all(p).await? {
                ids.push(r.try_get::<String, _>("id")?);
            }
            ids
        }))
    }

    /// Deletes one job record.
    pub async fn delete(&self, id: &str) -> Result<(), DbError> {
        on_pool!(self, p => sqlx::query("DELETE FROM geodex_jobs WHERE id = $1")
            .bind(id)
            .execute(p)
            .await?
            .rows_affected());
        Ok(())
    }

    /// Bytes of the published results of succeeded jobs, per tenant (the
    /// `byte_size` of each entry of `outputs`).
    pub async fn result_bytes(&self) -> Result<Vec<(String, u64)>, DbError> {
        let q = sql!(
            "SELECT tenant, outputs FROM geodex_jobs WHERE state = '{SUCCEEDED}' \
             AND outputs IS NOT NULL"
        );
        let rows: Vec<(String, String)> = on_pool!(self, p => {
            let mut out = Vec::new();
            for r in sqlx::query(q).fetch_all(p).await? {
                out.push((r.try_get("tenant")?, r.try_get("outputs")?));
            }
            out
        });
        let mut by_tenant: std::collections::BTreeMap<String, u64> = Default::default();
        for (tenant, outputs) in rows {
            *by_tenant.entry(tenant).or_default() += outputs_bytes(&outputs);
        }
        Ok(by_tenant.into_iter().collect())
    }

    /// Number of jobs in each state.
    pub async fn counts(&self) -> Result<Vec<(JobState, i64)>, DbError> {
        let q = "SELECT state, COUNT(*) AS n FROM geodex_jobs GROUP BY state";
        Ok(on_pool!(self, p => {
            let mut out = Vec::new();
            for r in sqlx::query(q).fetch_all(p).await? {
                out.push((decode_state(r.try_get("state")?)?, r.try_get::<i64, _>("n")?));
            }
            out
        }))
    }

    /// True if the database answers.
    pub async fn ping(&self) -> bool {
        on_pool!(self, p => sqlx::query("SELECT 1").execute(p).await.is_ok())
    }
}
