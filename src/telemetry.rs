//! Logs and metrics.
//!
//! * Logs: `tracing` with an `EnvFilter` (`RUST_LOG`, default `info`), as text
//!   or one JSON object per line.
//! * Metrics: one process-wide Prometheus recorder, installed on first use
//!   ([`metrics_handle`]); several applications in one process (tests) share it.
//!
//! Metric names:
//! * `geodex_http_request_duration_seconds{route,method,status}` (histogram)
//! * `geodex_solve_seconds{operation,outcome}` (histogram; outcome `completed`
//!   or `cancelled` when the deadline passed or the client left during the solve)
//! * `geodex_pool_queue_depth` (gauge: admitted solves not yet started)
//! * `geodex_pool_in_flight` (gauge: solves running on the pool)
//! * `geodex_pool_rejected_total` (counter: solves refused with 503)
//! * `geodex_jobs{state}` (gauge: jobs in each state, read from the job database)
//! * `geodex_job_queue_wait_seconds{operation}` (histogram: submission to first start)
//! * `geodex_job_run_seconds{operation,outcome}` (histogram: one attempt)
//! * `geodex_job_failures_total{operation,reason}` (counter: jobs that ended `failed`)
//! * `geodex_job_retries_total{operation}` (counter: jobs run again after their worker died)

use std::sync::OnceLock;

use metrics_exporter_prometheus::{Matcher, PrometheusBuilder, PrometheusHandle};

/// Request latency histogram.
pub const HTTP_DURATION: &str = "geodex_http_request_duration_seconds";
/// Solve time histogram.
pub const SOLVE_SECONDS: &str = "geodex_solve_seconds";
/// Admitted solves waiting for a pool thread.
pub const QUEUE_DEPTH: &str = "geodex_pool_queue_depth";
/// Solves running on the pool.
pub const IN_FLIGHT: &str = "geodex_pool_in_flight";
/// Solves refused because the pool was full.
pub const REJECTED: &str = "geodex_pool_rejected_total";
/// Connections closed to make room at the connection cap (the oldest idle).
pub const HTTP_CONNECTIONS_EVICTED: &str = "geodex_http_connections_evicted_total";
/// Connections refused with a 503 at the cap (every connection busy).
pub const HTTP_CONNECTIONS_REFUSED: &str = "geodex_http_connections_refused_total";

/// Metric: jobs in each state (gauge, label `state`), from the database.
pub const JOBS: &str = "geodex_jobs";
/// Metric: seconds from submission to the start of the first attempt (histogram, label `operation`).
pub const JOB_QUEUE_WAIT: &str = "geodex_job_queue_wait_seconds";
/// Metric: seconds an attempt ran (histogram, labels `operation`, `outcome`).
pub const JOB_RUN: &str = "geodex_job_run_seconds";
/// Metric: jobs that ended `failed` (counter, labels `operation`, `reason`).
pub const JOB_FAILURES: &str = "geodex_job_failures_total";
/// Metric: jobs queued again after their worker's lease ran out (counter, label `operation`).
pub const JOB_RETRIES: &str = "geodex_job_retries_total";
/// Histogram buckets of the job metrics (seconds).
const JOB_BUCKETS: &[f64] = &[
    0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0, 30.0, 60.0, 300.0, 900.0, 3600.0,
];

const HTTP_BUCKETS: &[f64] = &[
    0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0, 30.0, 60.0,
];
const SOLVE_BUCKETS: &[f64] = &[
    0.001, 0.01, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0, 30.0, 60.0, 120.0, 300.0,
];

/// Installs the log subscriber once per process (later calls do nothing).
pub fn init_logging(json: bool) {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    // Colour codes only on a terminal: redirected logs stay plain text.
    let ansi = std::io::IsTerminal::is_terminal(&std::io::stdout());
    let builder = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_ansi(ansi);
    // An error only means a subscriber is already installed (tests).
    let _ = if json {
        builder.json().try_init()
    } else {
        builder.try_init()
    };
}

/// The process-wide Prometheus handle; installs the recorder on first call.
/// If another recorder was installed first, metrics from this crate are not
/// recorded but `/metrics` still renders (an empty registry).
pub fn metrics_handle() -> PrometheusHandle {
    static HANDLE: OnceLock<PrometheusHandle> = OnceLock::new();
    HANDLE
        .get_or_init(|| {
            let builder = PrometheusBuilder::new()
                .set_buckets_for_metric(Matcher::Full(HTTP_DURATION.into()), HTTP_BUCKETS)
                .and_then(|b| {
                    b.set_buckets_for_metric(Matcher::Full(SOLVE_SECONDS.into()), SOLVE_BUCKETS)
                })
                .and_then(|b| {
                    b.set_buckets_for_metric(Matcher::Prefix("geodex_job_".into()), JOB_BUCKETS)
                });
            let builder = match builder {
                Ok(b) => b,
                Err(e) => {
                    tracing::warn!(error = %e, "histogram buckets refused; using summaries");
                    PrometheusBuilder::new()
                }
            };
            let recorder = builder.build_recorder();
            let handle = recorder.handle();
            if metrics::set_global_recorder(recorder).is_err() {
                tracing::warn!("a metrics recorder was already installed");
            }
            handle
        })
        .clone()
}
