//! The workers of one process, and the background upkeep of the queue.
//!
//! * **Workers** (`--job-workers`, default the solver pool's threads): each
//!   waits for room on the solver pool, claims one job, runs it and loops. An
//!   idle worker sleeps until a local submission wakes it, a PostgreSQL
//!   `NOTIFY` arrives (another replica submitted), or the poll period passes.
//! * **Heartbeat** (one task per running job, every `--job-poll-ms`): renews
//!   the lease, writes the progress the solver reported, and reads
//!   `cancel_requested`; it raises the solver's cancel flag when cancellation
//!   was asked (on any replica), when the time limit passed, or when the lease
//!   was lost. The solver polls that flag every few thousand cells.
//! * **Upkeep** (one task): re-queues jobs whose lease ran out, removes jobs
//!   and results past their retention, and publishes the per-state gauges.
//! * **Shutdown** (SIGTERM): workers stop claiming, running solves are
//!   stopped and their leases released (the job is queued again at once, its
//!   attempt not counted), so another replica takes it over.

use std::collections::BTreeMap;
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::{Duration, Instant};

use serde_json::Value;
use tokio::task::JoinHandle;

use super::db::{Finish, JobRow, Lease};
use super::model::ms;
use super::{
    cancelled_problem, now_ms, problem_json, time_limit_problem, JobDb, JobState, Jobs,
    ResultStore, RunFlags, StopReason, StoredOutput,
};
use crate::datasets::inputs::StoreInputs;
use crate::io;
use crate::ops::registry;
use crate::ops::{OpError, OpOutput};
use crate::pool::PoolError;
use crate::problem::{ApiError, Kind};
use crate::runner::{Ran, RunError, RunOptions, Watch};
use crate::telemetry::{JOBS, JOB_FAILURES, JOB_QUEUE_WAIT, JOB_RETRIES, JOB_RUN};

/// Handles of the background tasks of [`Jobs::start`].
#[derive(Debug, Default)]
pub struct Workers {
    tasks: Vec<JoinHandle<()>>,
}

impl Jobs {
    /// Starts the workers, the upkeep task and (PostgreSQL) the listener.
    pub fn start(self: &Arc<Self>) -> Workers {
        let mut tasks = Vec::new();
        for i in 0..self.config.workers {
            let jobs = Arc::clone(self);
            tasks.push(tokio::spawn(async move { jobs.worker_loop(i).await }));
        }
        let jobs = Arc::clone(self);
        tasks.push(tokio::spawn(async move { jobs.upkeep_loop().await }));
        if matches!(self.db, JobDb::Postgres(_)) {
            let jobs = Arc::clone(self);
            tasks.push(tokio::spawn(async move { jobs.listen_loop().await }));
        }
        Workers { tasks }
    }

    /// Stops claiming and stops the running solves, whose leases are then
    /// released (SIGTERM). Returns at once; see [`Jobs::shutdown`].
    pub fn begin_shutdown(&self) {
        self.stopping.store(true, Ordering::SeqCst);
        self.wake.notify_waiters();
        let running = self.running.lock().unwrap_or_else(|p| p.into_inner());
        for flags in running.values() {
            flags.stop(StopReason::Shutdown);
        }
    }

    /// [`Jobs::begin_shutdown`], then waits at most `grace` for the leases
    /// to be released, then stops the background tasks.
    pub async fn shutdown(&self, workers: Workers, grace: Duration) {
        self.begin_shutdown();
        let deadline = Instant::now() + grace;
        while self.running_here() > 0 && Instant::now() < deadline {
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
        let left = self.running_here();
        if left > 0 {
            tracing::warn!(
                left,
                "jobs still running at the end of the grace period; their leases will expire"
            );
        }
        for t in workers.tasks {
            t.abort();
        }
    }

    fn is_stopping(&self) -> bool {
        self.stopping.load(Ordering::SeqCst)
    }

    async fn worker_loop(self: Arc<Self>, index: usize) {
        let idle = self.config.poll.max(Duration::from_millis(50)) * 4;
        while !self.is_stopping() {
            if !self.pool.has_room() {
                // Synchronous requests fill the pool: wait for a free slot
                // rather than claim a job we cannot start.
                tokio::time::sleep(Duration::from_millis(20)).await;
                continue;
            }
            let now = now_ms();
            match self
                .db
                .claim(&self.worker_id, now, now + ms(self.config.lease))
                .await
            {
                Ok(Some(row)) => {
                    tracing::debug!(worker = index, job = %row.id, attempt = row.attempts, "claimed");
                    self.run_claimed(row).await;
                }
                Ok(None) => {
                    tokio::select! {
                        () = self.wake.notified() => {}
                        () = tokio::time::sleep(idle) => {}
                    }
                }
                Err(e) => {
                    tracing::warn!(error = %e, "claiming a job failed; retrying");
                    tokio::time::sleep(Duration::from_secs(1)).await;
                }
            }
        }
    }

    async fn listen_loop(self: Arc<Self>) {
        let JobDb::Postgres(pool) = &self.db else {
            return;
        };
        loop {
            let listener = async {
                let mut l = sqlx::postgres::PgListener::connect_with(pool).await?;
                l.listen_all([super::db::CHANNEL_NEW, super::db::CHANNEL_CANCEL])
                    .await?;
                loop {
                    let n = l.recv().await?;
                    if n.channel() == super::db::CHANNEL_CANCEL {
                        self.raise_local(n.payload(), StopReason::Cancel);
                    } else {
                        self.wake.notify_one();
                    }
                }
                #[allow(unreachable_code)]
                Ok::<(), sqlx::Error>(())
            };
            if let Err(e) = listener.await {
                tracing::warn!(error = %e, "LISTEN connection lost; polling until it is back");
            }
            tokio::time::sleep(Duration::from_secs(1)).await;
        }
    }

    async fn upkeep_loop(self: Arc<Self>) {
        let reap_every = self.config.poll.max(Duration::from_millis(100)) * 2;
        let mut last_gauges = Instant::now() - Duration::from_secs(60);
        let mut last_sweep = Instant::now() - Duration::from_secs(3600);
        let sweep_every =
            (self.config.retention / 4).clamp(Duration::from_secs(1), Duration::from_secs(300));
        loop {
            self.reap_once().await;
            if last_gauges.elapsed() >= Duration::from_secs(5) {
                last_gauges = Instant::now();
                self.publish_gauges().await;
            }
            if last_sweep.elapsed() >= sweep_every {
                last_sweep = Instant::now();
                match self.sweep_expired().await {
                    Ok(0) => {}
                    Ok(n) => tracing::info!(removed = n, "expired jobs swept"),
                    Err(e) => tracing::warn!(error = %e, "sweeping expired jobs failed"),
                }
            }
            tokio::time::sleep(reap_every).await;
        }
    }

    async fn reap_once(&self) {
        let now = now_ms();
        let failed = ApiError::of(
            Kind::AttemptsExhausted,
            "every attempt of this job ended with its worker gone (process killed or lost); \
             it was not retried further",
        );
        let r = self
            .db
            .reap(
                now,
                self.expiry(now),
                &problem_json(&cancelled_problem(), ""),
                &problem_json(&failed, ""),
            )
            .await;
        match r {
            Ok(r) => {
                for (id, op) in &r.requeued {
                    tracing::info!(job = %id, "lease expired; job queued again");
                    metrics::counter!(JOB_RETRIES, "operation" => op.clone()).increment(1);
                }
                for (id, op) in &r.failed {
                    tracing::warn!(job = %id, "lease expired after the last attempt; job failed");
                    // The partial files of its killed attempts go with it.
                    if let Err(e) = self.results.remove_job(id, None).await {
                        tracing::warn!(job = %id, error = %e, "removing a failed job's files failed");
                    }
                    metrics::counter!(JOB_FAILURES, "operation" => op.clone(), "reason" => "attempts")
                        .increment(1);
                }
                if !r.requeued.is_empty() {
                    self.wake.notify_one();
                }
            }
            Err(e) => tracing::warn!(error = %e, "reaping expired leases failed"),
        }
    }

    async fn publish_gauges(&self) {
        if let Ok(counts) = self.db.counts().await {
            for state in JobState::ALL {
                let n = counts
                    .iter()
                    .find(|(s, _)| *s == state)
                    .map_or(0, |(_, n)| *n);
                metrics::gauge!(JOBS, "state" => state.as_str()).set(n as f64);
            }
        }
    }

    /// Removes ended jobs past their retention and their results.
    pub async fn sweep_expired(&self) -> Result<usize, super::JobsError> {
        let mut total = 0;
        loop {
            let ids = self.db.expired(now_ms(), 100).await?;
            if ids.is_empty() {
                return Ok(total);
            }
            for id in &ids {
                let row = self.db.get(id).await?;
                self.results.remove_job(id, None).await?;
                self.db.delete(id).await?;
                if let Some(r) = row.filter(|r| r.state == JobState::Succeeded) {
                    let bytes = r.outputs.as_deref().map_or(0, super::db::outputs_bytes);
                    self.datasets.release(bytes, &r.tenant);
                }
            }
            total += ids.len();
        }
    }

    async fn run_claimed(&self, row: JobRow) {
        let lease = Lease {
            id: row.id.clone(),
            owner: self.worker_id.clone(),
            attempt: row.attempts,
        };
        if row.attempts == 1 {
            if let Some(started) = row.started_at {
                metrics::histogram!(JOB_QUEUE_WAIT, "operation" => row.operation.clone())
                    .record((started - row.created_at).max(0) as f64 / 1000.0);
            }
        }
        let flags = Arc::new(RunFlags::default());
        if row.cancel_requested {
            flags.stop(StopReason::Cancel);
        }
        {
            let mut running = self.running.lock().unwrap_or_else(|p| p.into_inner());
            running.insert(row.id.clone(), Arc::clone(&flags));
        }
        if self.is_stopping() {
            // Claimed while SIGTERM arrived: give it back untouched.
            flags.stop(StopReason::Shutdown);
        }
        let started = Instant::now();
        let heartbeat = self.heartbeat(&lease, &flags, row.time_limit_ms);
        let work = self.execute(&row, &lease, &flags);
        tokio::pin!(work);
        tokio::pin!(heartbeat);
        let outcome = tokio::select! {
            o = &mut work => o,
            () = &mut heartbeat => work.await,
        };
        let outcome_name = self.conclude(&row, &lease, &flags, outcome).await;
        metrics::histogram!(JOB_RUN, "operation" => row.operation.clone(), "outcome" => outcome_name)
            .record(started.elapsed().as_secs_f64());
        let mut running = self.running.lock().unwrap_or_else(|p| p.into_inner());
        running.remove(&row.id);
    }

    /// Renews the lease and relays progress and cancellation until the flag
    /// is raised for a reason that ends the attempt.
    async fn heartbeat(&self, lease: &Lease, flags: &RunFlags, time_limit_ms: i64) {
        let started = Instant::now();
        let limit = Duration::from_millis(u64::try_from(time_limit_ms).unwrap_or(0));
        // The claim just wrote the lease: the first heartbeat is one period away.
        let mut tick = tokio::time::interval_at(
            tokio::time::Instant::now() + self.config.poll,
            self.config.poll,
        );
        tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        // The time limit fires on time, not at the next heartbeat: with a
        // period of `poll`, a job could otherwise run up to `poll` past it
        // (and finish, ignoring its limit).
        let deadline = tokio::time::Instant::now() + limit;
        let mut timed_out = false;
        let mut last_ok = Instant::now();
        loop {
            tokio::select! {
                _ = tick.tick() => {}
                _ = tokio::time::sleep_until(deadline), if !timed_out => {
                    timed_out = true;
                    flags.stop(StopReason::TimeLimit);
                    continue;
                }
            }
            if started.elapsed() >= limit {
                flags.stop(StopReason::TimeLimit);
            }
            let now = now_ms();
            match self
                .db
                .heartbeat(lease, flags.progress(), now, now + ms(self.config.lease))
                .await
            {
                Ok(Some(cancel)) => {
                    last_ok = Instant::now();
                    if cancel {
                        flags.stop(StopReason::Cancel);
                    }
                }
                Ok(None) => {
                    tracing::warn!(job = %lease.id, "lease lost; stopping this attempt");
                    flags.stop(StopReason::LeaseLost);
                    return;
                }
                Err(e) => {
                    tracing::warn!(job = %lease.id, error = %e, "heartbeat failed");
                    if last_ok.elapsed() >= self.config.lease {
                        flags.stop(StopReason::LeaseLost);
                        return;
                    }
                }
            }
        }
    }

    async fn execute(&self, row: &JobRow, lease: &Lease, flags: &Arc<RunFlags>) -> Outcome {
        let Some(entry) = registry::find(&row.operation) else {
            return Outcome::Failed(
                ApiError::invalid_field(
                    "operation",
                    format!("this service cannot run '{}'", row.operation),
                ),
                "invalid",
            );
        };
        let op = match (entry.parse)(row.params.as_bytes()) {
            Ok(op) => op,
            Err(e) => return Outcome::Failed(ApiError::from(e).nested_in("params"), "invalid"),
        };
        let inputs = StoreInputs::new(Arc::clone(&self.datasets)).for_tenant(&row.tenant);
        // Backstop only: the heartbeat enforces the time limit through the flag.
        let backstop = Duration::from_millis(u64::try_from(row.time_limit_ms).unwrap_or(0))
            + self.config.lease
            + Duration::from_secs(30);
        let watch: Arc<dyn Watch> = Arc::clone(flags) as Arc<dyn Watch>;
        let options = RunOptions {
            deadline: backstop,
            watch: Some(watch),
        };
        match self.runner.run(op, inputs, options).await {
            Ok(Ran { output, .. }) => match self.store_output(row, lease, output).await {
                Ok((doc, outputs)) => Outcome::Succeeded(doc, outputs),
                // Over the quota or the disk full: running again would not help.
                Err(e) if e.status_code() == 507 => Outcome::Failed(e, "storage"),
                Err(e) => Outcome::Retry(e),
            },
            Err(RunError::Invalid(e)) => {
                Outcome::Failed(ApiError::from(e).nested_in("params"), "invalid")
            }
            Err(RunError::Inputs(e)) if e.is_server_error() => Outcome::Retry(e),
            Err(RunError::Inputs(e)) => Outcome::Failed(e.nested_in("params"), "invalid"),
            Err(RunError::Op(OpError::Cancelled)) => Outcome::Stopped,
            Err(RunError::Op(e)) => Outcome::Failed(ApiError::from(e), "invalid"),
            Err(RunError::Pool(PoolError::Deadline(_))) => {
                flags.stop(StopReason::TimeLimit);
                Outcome::Stopped
            }
            Err(RunError::Pool(PoolError::Busy { .. } | PoolError::NoMemory { .. })) => {
                Outcome::Release
            }
            Err(RunError::Pool(e @ PoolError::TooBig { .. })) => {
                Outcome::Failed(ApiError::from(e), "invalid")
            }
            Err(RunError::Pool(PoolError::Lost)) => Outcome::Failed(
                ApiError::internal(format!("the solve of job {} panicked", row.id)),
                "panic",
            ),
        }
    }

    /// Writes every output array (put-if-absent under this attempt's keys)
    /// and builds the result document; nothing is published yet.
    ///
    /// Each array is counted against the storage quotas (the service's and
    /// the job's tenant's) before it is written: beyond them the attempt
    /// fails with a 507, and whatever it wrote is removed and given back.
    async fn store_output(
        &self,
        row: &JobRow,
        lease: &Lease,
        output: OpOutput,
    ) -> Result<(Value, BTreeMap<String, StoredOutput>), ApiError> {
        let mut charged = 0u64;
        let result = self.write_outputs(row, lease, output, &mut charged).await;
        if result.is_err() {
            self.datasets.release(charged, &row.tenant);
            let _ = self
                .results
                .remove_job_attempt(&row.id, lease.attempt)
                .await;
        }
        result
    }

    async fn write_outputs(
        &self,
        row: &JobRow,
        lease: &Lease,
        mut output: OpOutput,
        charged: &mut u64,
    ) -> Result<(Value, BTreeMap<String, StoredOutput>), ApiError> {
        let owner = crate::datasets::Owner {
            tenant: row.tenant.clone(),
            quota_bytes: None,
        };
        let mut doc = output.document_map();
        let mut stored = BTreeMap::new();
        for out in output.arrays {
            let shape = out.array.shape().to_vec();
            let dtype = out.array.dtype();
            let array = out.array;
            let bytes = tokio::task::spawn_blocking(move || io::encode_npy(&array))
                .await
                .map_err(ApiError::internal)?
                .map_err(ApiError::internal)?;
            let key = ResultStore::key(&row.id, lease.attempt, &out.name);
            let byte_size = bytes.len() as u64;
            self.datasets
                .reserve(byte_size, &owner)
                .map_err(|e| ApiError::from(e).with_field(format!("result.{}", out.name)))?;
            *charged += byte_size;
            self.results
                .put_new(&key, bytes)
                .await
                .map_err(super::results::storage_error)?;
            let reference = super::ResultRef {
                url: format!("/v1/jobs/{}/results/{}", row.id, out.name),
                shape: shape.clone(),
                dtype,
                byte_size,
            };
            doc.insert(
                out.name.clone(),
                serde_json::to_value(reference).map_err(ApiError::internal)?,
            );
            stored.insert(
                out.name,
                StoredOutput {
                    key,
                    shape,
                    dtype,
                    byte_size,
                    spacing: out.spacing,
                },
            );
        }
        Ok((Value::Object(doc), stored))
    }

    /// Writes the end of an attempt; returns the outcome label for metrics.
    async fn conclude(
        &self,
        row: &JobRow,
        lease: &Lease,
        flags: &RunFlags,
        outcome: Outcome,
    ) -> &'static str {
        let now = now_ms();
        let expires_at = self.expiry(now);
        let finish = |state, progress, result, outputs, error| Finish {
            state,
            progress,
            result,
            outputs,
            error,
            now,
            expires_at,
        };
        let reason = flags.reason();
        // The bytes this attempt's results hold against the quotas: kept
        // only if they are published below.
        let charged: u64 = match &outcome {
            Outcome::Succeeded(_, outputs) => outputs.values().map(|o| o.byte_size).sum(),
            _ => 0,
        };
        let (write, label): (Option<Finish>, &'static str) = match outcome {
            Outcome::Succeeded(doc, outputs) => {
                if reason == Some(StopReason::LeaseLost) {
                    (None, "lease_lost")
                } else {
                    let f = finish(
                        JobState::Succeeded,
                        1.0,
                        serde_json::to_string(&doc).ok(),
                        serde_json::to_string(&outputs).ok(),
                        None,
                    );
                    (Some(f), "succeeded")
                }
            }
            Outcome::Failed(e, why) => {
                metrics::counter!(JOB_FAILURES, "operation" => row.operation.clone(), "reason" => why)
                    .increment(1);
                let f = finish(
                    JobState::Failed,
                    flags.progress(),
                    None,
                    None,
                    Some(problem_json(&e, &row.id)),
                );
                (Some(f), "failed")
            }
            Outcome::Stopped => match reason {
                Some(StopReason::Cancel) => (
                    Some(finish(
                        JobState::Cancelled,
                        flags.progress(),
                        None,
                        None,
                        Some(problem_json(&cancelled_problem(), &row.id)),
                    )),
                    "cancelled",
                ),
                Some(StopReason::TimeLimit) => {
                    metrics::counter!(JOB_FAILURES, "operation" => row.operation.clone(), "reason" => "time_limit")
                        .increment(1);
                    let e = time_limit_problem(row.time_limit_ms);
                    (
                        Some(finish(
                            JobState::Failed,
                            flags.progress(),
                            None,
                            None,
                            Some(problem_json(&e, &row.id)),
                        )),
                        "time_limit",
                    )
                }
                Some(StopReason::Shutdown) => {
                    self.release(lease, true).await;
                    return "released";
                }
                Some(StopReason::LeaseLost) | None => (None, "lease_lost"),
            },
            Outcome::Release => {
                self.release(lease, true).await;
                tokio::time::sleep(Duration::from_millis(20)).await;
                return "released";
            }
            Outcome::Retry(e) => {
                tracing::warn!(job = %row.id, problem = %e.problem.detail, "attempt failed; job queued again");
                if row.attempts >= row.max_attempts {
                    metrics::counter!(JOB_FAILURES, "operation" => row.operation.clone(), "reason" => "error")
                        .increment(1);
                    (
                        Some(finish(
                            JobState::Failed,
                            flags.progress(),
                            None,
                            None,
                            Some(problem_json(&e, &row.id)),
                        )),
                        "failed",
                    )
                } else {
                    metrics::counter!(JOB_RETRIES, "operation" => row.operation.clone())
                        .increment(1);
                    self.release(lease, false).await;
                    return "retried";
                }
            }
        };
        let Some(f) = write else {
            self.datasets.release(charged, &row.tenant);
            let _ = self
                .results
                .remove_job_attempt(&row.id, lease.attempt)
                .await;
            return label;
        };
        match self.db.finish(lease, &f).await {
            Ok(true) => {
                // A succeeded job keeps only this attempt's objects; a failed
                // or cancelled one keeps none (partial files of every attempt).
                let keep = (f.state == JobState::Succeeded).then_some(lease.attempt);
                if let Err(e) = self.results.remove_job(&row.id, keep).await {
                    tracing::warn!(job = %row.id, error = %e, "removing stale attempt objects failed");
                }
                tracing::info!(job = %row.id, state = f.state.as_str(), attempt = lease.attempt, "job ended");
                label
            }
            Ok(false) => {
                self.datasets.release(charged, &row.tenant);
                tracing::warn!(job = %row.id, "lease lost before the result was published; discarded");
                let _ = self
                    .results
                    .remove_job_attempt(&row.id, lease.attempt)
                    .await;
                "lease_lost"
            }
            Err(e) => {
                self.datasets.release(charged, &row.tenant);
                tracing::warn!(job = %row.id, error = %e, "writing the job's end failed; its lease will expire");
                "db_error"
            }
        }
    }

    async fn release(&self, lease: &Lease, uncount: bool) {
        match self.db.release(lease, now_ms(), uncount).await {
            Ok(_) => self.wake.notify_one(),
            Err(e) => {
                tracing::warn!(job = %lease.id, error = %e, "releasing a lease failed; it will expire")
            }
        }
    }
}

/// How an attempt ended before it was written back.
enum Outcome {
    /// Done: the document and the stored arrays.
    Succeeded(Value, BTreeMap<String, StoredOutput>),
    /// A client error or a bug: the job fails.
    Failed(ApiError, &'static str),
    /// The solver stopped on its flag (see the flag's reason).
    Stopped,
    /// The pool was full: give the job back untouched.
    Release,
    /// A transient error (storage): run it again if attempts remain.
    Retry(ApiError),
}
