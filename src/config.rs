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
    /// Seconds a client may take to send a request's headers; also how long
    /// an idle keep-alive connection is kept open.
    #[arg(long, env = "GEODEX_HEADER_TIMEOUT_SECS", default_value_t = 10.0)]
    pub header_timeout_secs: f64,
    /// Seconds a request body may stall (no bytes arriving) before the
    /// request is answered 408 and the connection closed.
    #[arg(long, env = "GEODEX_BODY_TIMEOUT_SECS", default_value_t = 30.0)]
    pub body_timeout_secs: f64,
    /// Slowest request body accepted, in bytes per second, after a first
    /// `--body-timeout-secs` of grace (0: no minimum); slower gets 408.
    #[arg(long, env = "GEODEX_MIN_BODY_RATE", default_value_t = 1024)]
    pub min_body_rate: u64,
    /// Open connections at most. At the cap a new connection evicts the
    /// oldest one with no request in progress, or is answered 503 when
    /// every connection is busy. Lowered to fit the open-file limit.
    #[arg(long, env = "GEODEX_MAX_CONNECTIONS", default_value_t = 4096)]
    pub max_connections: usize,
    /// Estimated peak memory all admitted solves and upload decodes may hold
    /// together, in bytes; beyond it the next one gets 503 + Retry-After
    /// (413 if it alone is larger). Default: three quarters of the
    /// machine's memory.
    #[arg(long, env = "GEODEX_SOLVE_MEMORY_BYTES")]
    pub solve_memory_bytes: Option<u64>,
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
    /// Bytes kept in memory between requests, in one budget: decoded
    /// arrays, meshes, heat factorisations, and the designed costs and
    /// distance maps of minimal-path requests.
    #[arg(long, env = "GEODEX_CACHE_BYTES", default_value_t = 1 << 30)]
    pub cache_bytes: usize,
    /// Of `--cache-bytes`, the most for designed costs and distance maps kept
    /// for later minimal-path requests (`POST /v1/grid/paths`; 8 bytes per
    /// cell each); 0 keeps none.
    #[arg(long, env = "GEODEX_PATH_CACHE_BYTES", default_value_t = 512 << 20)]
    pub path_cache_bytes: usize,
    /// Allowed CORS origins, comma separated; `*` allows any. Default: none.
    /// These are also the only other origins whose pages may send requests
    /// that change something (uploads, solves, deletions).
    #[arg(long, env = "GEODEX_CORS_ORIGINS", value_delimiter = ',')]
    pub cors_origins: Vec<String>,
    /// Require an API key (`Authorization: Bearer <key>`) on every route but
    /// the probes, the OpenAPI document, the docs and the playground page.
    /// Auth is also on when any key exists (`geodex keys create`). Without
    /// either, the service serves only on a loopback address.
    #[arg(long, env = "GEODEX_AUTH")]
    pub auth: bool,
    /// Storage quota of one tenant in bytes, for keys that set none
    /// (0: only `--storage-quota-bytes` applies).
    #[arg(long, env = "GEODEX_TENANT_QUOTA_BYTES", default_value_t = 0)]
    pub tenant_quota_bytes: u64,
    /// Requests per second of one key, for keys that set none (0: no limit);
    /// beyond it the answer is 429 with Retry-After.
    #[arg(long, env = "GEODEX_RATE_LIMIT_PER_SEC", default_value_t = 0.0)]
    pub rate_limit_per_sec: f64,
    /// Requests one key may send at once above its rate (the token bucket's
    /// size; default: one second's worth, at least 1).
    #[arg(long, env = "GEODEX_RATE_LIMIT_BURST", default_value_t = 0.0)]
    pub rate_limit_burst: f64,
    /// Seconds to let in-flight requests finish after SIGTERM or Ctrl-C.
    #[arg(long, env = "GEODEX_SHUTDOWN_GRACE_SECS", default_value_t = 30)]
    pub shutdown_grace_secs: u64,
    /// Log one JSON object per line instead of human-readable text.
    #[arg(long, env = "GEODEX_LOG_JSON")]
    pub log_json: bool,
    /// The job queue: `sqlite` (the file `<data-dir>/jobs.sqlite`),
    /// `sqlite:///path/jobs.db`, or `postgres://user@host:port/db` to share
    /// one queue between replicas.
    /// Its value is never printed (`--help`, errors and logs hide the password).
    #[arg(
        long,
        env = "GEODEX_QUEUE",
        default_value = "sqlite",
        hide_env_values = true
    )]
    pub queue: String,
    /// Where job results are stored: `file` (`<data-dir>/results`),
    /// `file:///shared/dir`, or `s3://bucket/prefix` (built with `--features s3`).
    #[arg(
        long,
        env = "GEODEX_STORE",
        default_value = "file",
        hide_env_values = true
    )]
    pub store: String,
    /// Jobs this process runs at once; 0 makes it an API-only replica.
    /// Default: the solver pool's threads.
    #[arg(long, env = "GEODEX_JOB_WORKERS")]
    pub job_workers: Option<usize>,
    /// Lease of a running job in seconds (fractions allowed): a job whose
    /// process died runs again this long after its last heartbeat.
    #[arg(long, env = "GEODEX_JOB_LEASE_SECS", default_value_t = 30.0)]
    pub job_lease_secs: f64,
    /// Heartbeat period of a running job in milliseconds: progress writes,
    /// lease renewal and cancellation polling.
    #[arg(long, env = "GEODEX_JOB_POLL_MS", default_value_t = 250)]
    pub job_poll_ms: u64,
    /// Attempts of a job whose process keeps dying before it is failed.
    #[arg(long, env = "GEODEX_JOB_MAX_ATTEMPTS", default_value_t = 3)]
    pub job_max_attempts: u32,
    /// Time limit of a job that names none, in seconds.
    #[arg(long, env = "GEODEX_JOB_TIME_LIMIT_SECS", default_value_t = 3600.0)]
    pub job_time_limit_secs: f64,
    /// Largest time limit a job may ask for, in seconds.
    #[arg(
        long,
        env = "GEODEX_JOB_MAX_TIME_LIMIT_SECS",
        default_value_t = 86400.0
    )]
    pub job_max_time_limit_secs: f64,
    /// How long ended jobs and their results are kept, in seconds.
    #[arg(long, env = "GEODEX_JOB_RETENTION_SECS", default_value_t = 7 * 24 * 3600)]
    pub job_retention_secs: u64,
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
            header_timeout_secs: 10.0,
            body_timeout_secs: 30.0,
            min_body_rate: 1024,
            max_connections: 4096,
            solve_memory_bytes: None,
            max_cells: 512 * 512 * 512,
            storage_quota_bytes: 8 << 30,
            dataset_ttl_secs: 24 * 3600,
            cache_bytes: 1 << 30,
            path_cache_bytes: 512 << 20,
            cors_origins: Vec::new(),
            auth: false,
            tenant_quota_bytes: 0,
            rate_limit_per_sec: 0.0,
            rate_limit_burst: 0.0,
            shutdown_grace_secs: 30,
            log_json: false,
            queue: "sqlite".into(),
            store: "file".into(),
            job_workers: None,
            job_lease_secs: 30.0,
            job_poll_ms: 250,
            job_max_attempts: 3,
            job_time_limit_secs: 3600.0,
            job_max_time_limit_secs: 86400.0,
            job_retention_secs: 7 * 24 * 3600,
        }
    }
}

/// `url` with the password of its user info (`scheme://user:password@host`)
/// replaced by `***`, for messages and logs.
///
/// # Examples
///
/// ```
/// use geodex::config::redact_url;
/// assert_eq!(redact_url("postgres://app:s3cret@db:5432/geo"), "postgres://app:***@db:5432/geo");
/// assert_eq!(redact_url("sqlite"), "sqlite");
/// ```
pub fn redact_url(url: &str) -> String {
    let Some((scheme, rest)) = url.split_once("://") else {
        return url.to_string();
    };
    let authority_end = rest.find(['/', '?', '#']).unwrap_or(rest.len());
    let (authority, tail) = rest.split_at(authority_end);
    match authority.rsplit_once('@') {
        Some((userinfo, host)) => {
            let user = userinfo.split_once(':').map_or(userinfo, |(u, _)| u);
            let hidden = if userinfo.contains(':') { ":***" } else { "" };
            format!("{scheme}://{user}{hidden}@{host}{tail}")
        }
        None => url.to_string(),
    }
}

/// `text` with `url` replaced by [`redact_url`] of it, and its password, if
/// it has one, replaced by `***` wherever else it appears.
pub fn scrub_secret(text: &str, url: &str) -> String {
    let mut out = text.replace(url, &redact_url(url));
    let password = url
        .split_once("://")
        .and_then(|(_, rest)| rest.split(['/', '?', '#']).next())
        .and_then(|authority| authority.rsplit_once('@'))
        .and_then(|(userinfo, _)| userinfo.split_once(':'))
        .map(|(_, p)| p)
        .filter(|p| p.len() >= 3);
    if let Some(p) = password {
        out = out.replace(p, "***");
    }
    out
}

impl ServeArgs {
    /// The defaults of keys that set no limits of their own.
    pub fn key_defaults(&self) -> crate::auth::KeyDefaults {
        crate::auth::KeyDefaults {
            quota_bytes: self.tenant_quota_bytes,
            rate_per_sec: if self.rate_limit_per_sec.is_finite() {
                self.rate_limit_per_sec.max(0.0)
            } else {
                0.0
            },
            burst: if self.rate_limit_burst.is_finite() {
                self.rate_limit_burst.max(0.0)
            } else {
                0.0
            },
        }
    }

    /// Threads of the solver pool, resolved (at least 1).
    pub fn threads(&self) -> usize {
        self.pool_threads
            .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
            .max(1)
    }

    /// The memory budget of the solver pool, resolved: the flag, or three
    /// quarters of the memory `/proc/meminfo` reports (8 GiB if unknown).
    pub fn solve_memory(&self) -> u64 {
        self.solve_memory_bytes.unwrap_or_else(|| {
            std::fs::read_to_string("/proc/meminfo")
                .ok()
                .and_then(|m| {
                    m.lines()
                        .find_map(|l| l.strip_prefix("MemTotal:"))
                        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<u64>().ok())
                })
                .map_or(8 << 30, |kib| kib.saturating_mul(1024) / 4 * 3)
        })
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

    /// Settings of the job system.
    pub fn jobs_config(&self) -> crate::jobs::JobsConfig {
        let secs = |s: f64| {
            std::time::Duration::try_from_secs_f64(s.max(0.001)).unwrap_or(std::time::Duration::MAX)
        };
        crate::jobs::JobsConfig {
            queue: self.queue.clone(),
            store: self.store.clone(),
            data_dir: self.data_dir.clone(),
            workers: self.job_workers.unwrap_or_else(|| self.threads()),
            lease: secs(self.job_lease_secs),
            poll: std::time::Duration::from_millis(self.job_poll_ms.max(10)),
            max_attempts: self.job_max_attempts.max(1),
            default_time_limit: secs(self.job_time_limit_secs),
            max_time_limit: secs(self.job_max_time_limit_secs),
            retention: std::time::Duration::from_secs(self.job_retention_secs.max(1)),
        }
    }
}
