//! Service settings: command-line flags with environment-variable fallbacks.

use std::net::SocketAddr;
use std::path::PathBuf;

/// Settings of `geodex serve` (also what a bare `geodex` runs with).
#[derive(Debug, Clone, clap::Args)]
pub struct ServeArgs {
    /// Address to listen on.
    #[arg(long, env = "GEODEX_ADDR", default_value = "127.0.0.1:8080")]
    pub addr: SocketAddr,
    /// Directory for datasets and results (created if missing).
    #[arg(long, env = "GEODEX_DATA_DIR", default_value = "geodex-data")]
    pub data_dir: PathBuf,
}
