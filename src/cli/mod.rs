//! The `geodex` command line: `serve` (the default), `distance` and `bench`.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

use crate::config::ServeArgs;

pub mod bench;
pub mod distance;
mod usage;

/// geodex: geodesic distances, minimal paths and segmentations.
#[derive(Debug, Parser)]
#[command(name = "geodex", version, about)]
pub struct Cli {
    /// What to do; `serve` when omitted.
    #[command(subcommand)]
    pub command: Option<Command>,
}

/// Subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Run the HTTP service (the default).
    Serve(ServeArgs),
    /// Compute a distance map from NPY files (batch use).
    Distance(distance::DistanceArgs),
    /// Time the solvers on fixed problems (see `geodex bench --help`).
    Bench(bench::BenchArgs),
}

/// Entry point of the binary.
pub fn main() -> ExitCode {
    let cli = usage::parse_or_exit::<Cli>();
    let result = match cli.command {
        Some(Command::Serve(args)) => crate::app::serve(args),
        Some(Command::Distance(args)) => distance::run(&args).map_err(Into::into),
        Some(Command::Bench(args)) => bench::run(&args).map_err(Into::into),
        None => match Cli::try_parse_from(["geodex", "serve"]) {
            Ok(Cli {
                command: Some(Command::Serve(args)),
            }) => crate::app::serve(args),
            Ok(_) => Ok(()),
            Err(e) => e.exit(),
        },
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("geodex: {e:#}");
            ExitCode::FAILURE
        }
    }
}
