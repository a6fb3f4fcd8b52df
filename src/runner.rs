//! The one way an operation is run: [`Runner::run`].
//!
//! The synchronous endpoints, the job worker and the command line all hand a
//! request ([`DynOperation`]) and a source of inputs ([`LoadInputs`]) to
//! [`Runner::run`], which
//! 1. validates the request against the limits,
//! 2. asks it which datasets it still needs ([`DynOperation::datasets_to_load`],
//!    the hook through which `grid.paths` takes a cached cost) and loads them,
//! 3. runs it on the shared solver pool under a deadline, with cancellation
//!    (the pool's own flag: deadline and caller gone; plus, for a job, the
//!    job's flag: cancel, time limit, lease lost) and progress,
//! 4. returns its [`OpOutput`] and how long it waited and ran.
//!
//! What differs between callers is only where inputs come from (the dataset
//! store, files, an upload) and how the output is kept (datasets, job
//! results, files): the caller's business before and after this function.

use std::collections::HashMap;
use std::future::Future;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Duration;

use crate::datasets::inputs::StoreInputs;
use crate::ops::{DynOperation, InputArray, Inputs, OpError, OpLimits, OpOutput};
use crate::pool::{JobTiming, PoolError, SolverPool};
use crate::problem::ApiError;

/// Inputs that can be loaded on demand: the dataset store, or files the
/// command line already read.
pub trait LoadInputs: Inputs + Send + Sync + 'static {
    /// Loads every `(field, dataset id)` not already present; an unknown id
    /// is a 404 naming `field`.
    fn load(
        &mut self,
        ids: Vec<(String, String)>,
    ) -> impl Future<Output = Result<(), ApiError>> + Send;

    /// Fails (404 naming the field) unless the caller may read every
    /// `(field, dataset id)`: another tenant's dataset does not exist for it.
    /// Called with every dataset the request names, before a cache may stand
    /// in for one. Default: everything is readable (files of the command line).
    fn check_access(
        &self,
        _ids: &[(String, String)],
    ) -> impl Future<Output = Result<(), ApiError>> + Send {
        async { Ok(()) }
    }
}

impl LoadInputs for StoreInputs {
    async fn load(&mut self, ids: Vec<(String, String)>) -> Result<(), ApiError> {
        StoreInputs::load(self, ids).await.map_err(ApiError::from)
    }

    async fn check_access(&self, ids: &[(String, String)]) -> Result<(), ApiError> {
        StoreInputs::check_access(self, ids)
            .await
            .map_err(ApiError::from)
    }
}

/// Arrays read beforehand (the command line): every id must be there.
impl LoadInputs for HashMap<String, InputArray> {
    async fn load(&mut self, ids: Vec<(String, String)>) -> Result<(), ApiError> {
        match ids.into_iter().find(|(_, id)| !self.contains_key(id)) {
            Some((field, id)) => Err(OpError::UnknownDataset { field, id }.into()),
            None => Ok(()),
        }
    }
}

/// What a caller adds to the pool's own cancellation: a job's flag, raised by
/// its heartbeat, and the sink of its progress.
pub trait Watch: Send + Sync + 'static {
    /// A flag the solver polls besides the pool's.
    fn cancel_flag(&self) -> &AtomicBool;
    /// Receives progress fractions in `[0, 1]`.
    fn report(&self, fraction: f64);
}

/// How one run is bounded and watched.
#[derive(Clone)]
pub struct RunOptions {
    /// The deadline: past it the solve is cancelled ([`PoolError::Deadline`]).
    pub deadline: Duration,
    /// A job's flag and progress, if any.
    pub watch: Option<Arc<dyn Watch>>,
}

impl std::fmt::Debug for RunOptions {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RunOptions")
            .field("deadline", &self.deadline)
            .field("watch", &self.watch.is_some())
            .finish()
    }
}

impl RunOptions {
    /// A run bounded by `deadline` only.
    pub fn deadline(deadline: Duration) -> Self {
        Self {
            deadline,
            watch: None,
        }
    }
}

/// Why a run produced no output, by where it stopped.
#[derive(Debug)]
pub enum RunError {
    /// The request was refused before any input was read.
    Invalid(OpError),
    /// Its inputs could not be loaded (a 404 for an unknown dataset, a 5xx for the store).
    Inputs(ApiError),
    /// The pool refused it (busy), it passed its deadline, or it panicked.
    Pool(PoolError),
    /// The operation itself refused its inputs or was cancelled.
    Op(OpError),
}

impl From<RunError> for ApiError {
    fn from(e: RunError) -> Self {
        match e {
            RunError::Invalid(e) | RunError::Op(e) => e.into(),
            RunError::Inputs(e) => e,
            RunError::Pool(e) => e.into(),
        }
    }
}

/// A finished run.
#[derive(Debug)]
pub struct Ran {
    /// What the operation returned.
    pub output: OpOutput,
    /// How long it waited for a pool thread and ran.
    pub timing: JobTiming,
}

/// Runs operations on the shared solver pool.
#[derive(Debug, Clone)]
pub struct Runner {
    pool: Arc<SolverPool>,
    limits: OpLimits,
}

impl Runner {
    /// A runner over `pool` enforcing `limits`.
    pub fn new(pool: Arc<SolverPool>, limits: OpLimits) -> Self {
        Self { pool, limits }
    }

    /// The limits every request is validated against.
    pub fn limits(&self) -> &OpLimits {
        &self.limits
    }

    /// The pool.
    pub fn pool(&self) -> &Arc<SolverPool> {
        &self.pool
    }

    /// Validates `op`, loads what it needs into `inputs`, and runs it on the
    /// pool under `options` (see the module docs).
    pub async fn run<I: LoadInputs>(
        &self,
        mut op: Box<dyn DynOperation>,
        mut inputs: I,
        options: RunOptions,
    ) -> Result<Ran, RunError> {
        op.validate(&self.limits).map_err(RunError::Invalid)?;
        inputs
            .check_access(&op.dataset_ids())
            .await
            .map_err(RunError::Inputs)?;
        let needed = op.datasets_to_load(&inputs);
        inputs.load(needed).await.map_err(RunError::Inputs)?;
        let limits = self.limits;
        let watch = options.watch;
        let bytes = op.peak_bytes(&inputs);
        let (result, timing) = self
            .pool
            .run_sized(
                op.name(),
                options.deadline,
                bytes,
                move |pool_control| match &watch {
                    Some(w) => {
                        let sink = |p: f64| w.report(p);
                        let control = pool_control
                            .with_cancel(w.cancel_flag())
                            .with_progress(&sink);
                        op.run(&inputs, &limits, &control)
                    }
                    None => op.run(&inputs, &limits, pool_control),
                },
            )
            .await
            .map_err(RunError::Pool)?;
        Ok(Ran {
            output: result.map_err(RunError::Op)?,
            timing,
        })
    }

    /// [`Runner::run`] from synchronous code (the command line): a
    /// current-thread runtime drives the same future.
    pub fn run_blocking<I: LoadInputs>(
        &self,
        op: Box<dyn DynOperation>,
        inputs: I,
        options: RunOptions,
    ) -> Result<Ran, RunError> {
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_time()
            .build()
            .map_err(|_| RunError::Pool(PoolError::Lost))?;
        runtime.block_on(self.run(op, inputs, options))
    }
}
