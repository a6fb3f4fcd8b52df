//! The command line's way into the one runner ([`crate::runner::Runner`]):
//! the same validation, input resolution and solver pool as the service,
//! driven to completion from synchronous code, with the files a command read
//! as its inputs.

use std::collections::HashMap;
use std::sync::Arc;
use std::time::Duration;

use crate::numerics::grid::MAX_CELLS;
use crate::ops::{DynOperation, InputArray, OpError, OpLimits, OpOutput};
use crate::pool::SolverPool;
use crate::problem::ApiError;
use crate::runner::{LoadInputs, Ran, RunError, RunOptions, Runner};

/// The input arrays of a command, keyed by the dataset ids its request names.
pub(crate) type CliInputs = HashMap<String, InputArray>;

/// Why a command's operation produced nothing.
#[derive(Debug)]
pub(crate) enum CliRunError {
    /// The request (built from the flags) or its inputs were refused: the
    /// field says which flag.
    Op(OpError),
    /// Anything else (the pool could not start, the solve panicked).
    Other(String),
}

/// The limits of the command line: the largest grid the codecs accept, any
/// number of sources.
pub(crate) const CLI_LIMITS: OpLimits = OpLimits {
    max_cells: MAX_CELLS,
    max_sources: usize::MAX,
};

/// Runs `op` on a solver pool of this machine's threads, without deadline.
pub(crate) fn run_operation(
    op: Box<dyn DynOperation>,
    inputs: impl LoadInputs,
) -> Result<OpOutput, CliRunError> {
    run_on(op, inputs, None).map(|ran| ran.output)
}

/// Runs `op` on a solver pool of `threads` threads (default: this
/// machine's), without deadline; the output and how long it ran.
pub(crate) fn run_on(
    op: Box<dyn DynOperation>,
    inputs: impl LoadInputs,
    threads: Option<usize>,
) -> Result<Ran, CliRunError> {
    let threads =
        threads.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    let pool = SolverPool::new(threads, 1).map_err(|e| CliRunError::Other(e.to_string()))?;
    let runner = Runner::new(Arc::new(pool), CLI_LIMITS);
    match runner.run_blocking(op, inputs, RunOptions::deadline(Duration::MAX)) {
        Ok(ran) => Ok(ran),
        Err(RunError::Invalid(e) | RunError::Op(e)) => Err(CliRunError::Op(e)),
        Err(other) => Err(CliRunError::Other(ApiError::from(other).problem.detail)),
    }
}
