//! Service settings: command-line flags with environment-variable fallbacks.
//!
//! Every flag has a default, so a bare `geodex` starts with zero
//! configuration on `127.0.0.1:8080` with its data under `./geodex-data`.

use std::net::SocketAddr;
use std::path::PathBuf;

/// Settings of `geodex serve` (also what a bare `geodex` runs with).
#[derive(Debug, Clone, clap::Args)]
pub struct ServeArgs {
    /// Address to listen on (port 0 picks a free port).
    #[arg(long, env = "GEODEX_ADDR", default_value = "127.0.0.1:8080")]
    pub addr: SocketAddr,
    /// Directory for datasets and results (created if missing).
    #[arg(long, env = "GEODEX_DATA_DIR", default_value = "geodex-data")]
    pub data_dir: PathBuf,
    /// Threads of the solver pool. Default: the number of cores.
    #[arg(long, env = "GEODEX_POOL_THREADS")]
    pub pool_threads: Option<usize>,
    /// Solves admitted at once (waiting + running); beyond that the service
    /// answers 503 with Retry-After. Default: 2 x pool threads.
    #[arg(long, env = "GEODEX_QUEUE_CAPACITY")]
    pub queue_capacity: Option<usize>,
    /// Deadline of one solve in seconds (fractions allowed), counted from
    /// admission; past it the solve is cancelled and the answer is 504.
    #[arg(long, env = "GEODEX_REQUEST_TIMEOUT_SECS", default_value_t = 60.0)]
    pub request_timeout_secs: f64,
    /// Largest request body in bytes (uploads, multipart forms, JSON).
    #[arg(long, env = "GEODEX_MAX_BODY_BYTES", default_value_t = 256 << 20)]
    pub max_body_bytes: usize,
    /// Largest grid or array, in cells.
    #[arg(long, env = "GEODEX_MAX_CELLS", default_value_t = 512 * 512 * 512)]
    pub max_cells: usize,
    /// Total bytes of stored datasets; uploads and results beyond it get 507.
    #[arg(long, env = "GEODEX_STORAGE_QUOTA_BYTES", default_value_t = 8 << 30)]
    pub storage_quota_bytes: u64,
    /// Lifetime of a dataset in seconds; expired datasets answer 404 and are
    /// swept periodically.
    #[arg(long, env = "GEODEX_DATASET_TTL_SECS", default_value_t = 24 * 3600)]
    pub dataset_ttl_secs: u64,
    /// Bytes of decoded arrays kept in memory for repeated solves.
    #[arg(long, env = "GEODEX_CACHE_BYTES", default_value_t = 1 << 30)]
    pub cache_bytes: usize,
    /// Bytes of designed costs and distance maps kept for later minimal-path
    /// requests (`POST /v1/grid/paths`; 8 bytes per cell each); 0 disables it.
    #[arg(long, env = "GEODEX_PATH_CACHE_BYTES", default_value_t = 512 << 20)]
    pub path_cache_bytes: usize,
    /// Allowed CORS origins, comma separated; `*` allows any. Default: none.
    #[arg(long, env = "GEODEX_CORS_ORIGINS", value_delimiter = ',')]
    pub cors_origins: Vec<String>,
    /// Seconds to let in-flight requests finish after SIGTERM or Ctrl-C.
    #[arg(long, env = "GEODEX_SHUTDOWN_GRACE_SECS", default_value_t = 30)]
    pub shutdown_grace_secs: u64,
    /// Log one JSON object per line instead of human-readable text.
    #[arg(long, env = "GEODEX_LOG_JSON")]
    pub log_json: bool,
}

impl Default for ServeArgs {
    /// The same values as the command-line defaults, without reading the
    /// environment (for tests and embedding).
    fn default() -> Self {
        Self {
            addr: SocketAddr::from(([127, 0, 0, 1], 8080)),
            data_dir: PathBuf::from("geodex-data"),
            pool_threads: None,
            queue_capacity: None,
            request_timeout_secs: 60.0,
            max_body_bytes: 256 << 20,
            max_cells: 512 * 512 * 512,
            storage_quota_bytes: 8 << 30,
            dataset_ttl_secs: 24 * 3600,
            cache_bytes: 1 << 30,
            path_cache_bytes: 512 << 20,
            cors_origins: Vec::new(),
            shutdown_grace_secs: 30,
            log_json: false,
        }
    }
}

impl ServeArgs {
    /// Threads of the solver pool, resolved (at least 1).
    pub fn threads(&self) -> usize {
        self.pool_threads
            .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
            .max(1)
    }

    /// Admission capacity, resolved (at least 1).
    pub fn capacity(&self) -> usize {
        self.queue_capacity.unwrap_or(2 * self.threads()).max(1)
    }

    /// The solve deadline.
    pub fn request_timeout(&self) -> std::time::Duration {
        std::time::Duration::try_from_secs_f64(self.request_timeout_secs.max(0.0))
            .unwrap_or(std::time::Duration::MAX)
    }
}
