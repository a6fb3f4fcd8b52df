//! The command line's way into the one runner ([`crate::runner::Runner`]):
//! the same validation, input resolution and solver pool as the service,
//! driven to completion from synchronous code, with the files a command read
//! as its inputs. Every run gets a progress bar on stderr
//! ([`super::progress::Progress`], drawn only on a terminal after a second),
//! and every refusal is reported on the command's flags through its
//! [`FlagMap`].

use std::collections::HashMap;
use std::sync::Arc;
use std::time::Duration;

pub use super::flags::CliError;
pub(crate) use super::flags::FlagMap;
use super::progress::Progress;
use crate::numerics::grid::MAX_CELLS;
use crate::ops::{DynOperation, InputArray, OpLimits, OpOutput};
use crate::pool::SolverPool;
use crate::problem::ApiError;
use crate::runner::{LoadInputs, Ran, RunError, RunOptions, Runner};

/// The input arrays of a command, keyed by the dataset ids its request names.
pub(crate) type CliInputs = HashMap<String, InputArray>;

/// The limits of the command line: the largest grid the codecs accept, any
/// number of sources.
pub(crate) const CLI_LIMITS: OpLimits = OpLimits {
    max_cells: MAX_CELLS,
    max_sources: usize::MAX,
};

/// Runs `op` on a solver pool of this machine's threads, without deadline;
/// a refusal names the flag `flags` gives for its field.
pub(crate) fn run_operation(
    op: Box<dyn DynOperation>,
    inputs: impl LoadInputs,
    flags: &FlagMap,
) -> Result<OpOutput, CliError> {
    run_on(op, inputs, None, flags).map(|ran| ran.output)
}

/// Runs `op` on a solver pool of `threads` threads (default: this
/// machine's), without deadline, with a progress bar; the output and how
/// long it ran.
pub(crate) fn run_on(
    op: Box<dyn DynOperation>,
    inputs: impl LoadInputs,
    threads: Option<usize>,
    flags: &FlagMap,
) -> Result<Ran, CliError> {
    let threads =
        threads.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    let pool = SolverPool::new(threads, 1).map_err(|e| CliError::Other(e.to_string()))?;
    let runner = Runner::new(Arc::new(pool), CLI_LIMITS);
    let progress = Progress::start(op.name());
    let options = RunOptions {
        deadline: Duration::MAX,
        watch: Some(progress.watch()),
    };
    let result = runner.run_blocking(op, inputs, options);
    progress.finish();
    match result {
        Ok(ran) => Ok(ran),
        Err(RunError::Invalid(e) | RunError::Op(e)) => Err(flags.error(e)),
        Err(other) => Err(CliError::Other(ApiError::from(other).problem.detail)),
    }
}
