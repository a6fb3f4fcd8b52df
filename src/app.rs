//! Start-up: builds the application from its settings and serves it.
//!
//! ```no_run
//! # async fn run() -> anyhow::Result<()> {
//! let settings = geodex::config::ServeArgs {
//!     addr: "127.0.0.1:0".parse()?,
//!     ..Default::default()
//! };
//! let app = geodex::app::Application::build(settings).await?;
//! println!("listening on port {}", app.port());
//! app.run_until_stopped().await?;
//! # Ok(()) }
//! ```

use std::future::Future;
use std::net::SocketAddr;
use std::pin::Pin;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use anyhow::Context;
use tokio::net::TcpListener;

use crate::auth::Keys;
use crate::config::ServeArgs;
use crate::datasets::{DatasetStore, StoreConfig};
use crate::http::{self, AppState};
use crate::io::Limits;
use crate::jobs::Jobs;
use crate::ops::OpLimits;
use crate::pool::SolverPool;
use crate::telemetry;

type Signal = Pin<Box<dyn Future<Output = ()> + Send>>;

/// A bound, ready-to-run service.
pub struct Application {
    listener: TcpListener,
    router: axum::Router,
    state: AppState,
    limits: http::server::ServerLimits,
    grace: Duration,
    sweep_every: Duration,
    shutdown: Signal,
}

impl std::fmt::Debug for Application {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Application")
            .field("addr", &self.listener.local_addr().ok())
            .finish_non_exhaustive()
    }
}

impl Application {
    /// Opens the data directory, starts the solver pool and binds the listener
    /// (port 0 picks a free port). Does not serve yet.
    pub async fn build(settings: ServeArgs) -> anyhow::Result<Self> {
        let metrics = telemetry::metrics_handle();
        let store = DatasetStore::open(StoreConfig {
            data_dir: settings.data_dir.clone(),
            quota_bytes: settings.storage_quota_bytes,
            ttl: Duration::from_secs(settings.dataset_ttl_secs),
            cache_bytes: settings.cache_bytes,
            path_cache_bytes: settings.path_cache_bytes,
            limits: io_limits(&settings),
        })
        .with_context(|| format!("opening the data directory {}", settings.data_dir.display()))?;
        let pool = SolverPool::new(settings.threads(), settings.capacity())
            .context("starting the solver pool")?
            .with_memory_budget(settings.solve_memory());
        let store = Arc::new(store);
        let pool = Arc::new(pool);
        let op_limits = op_limits(&settings);
        let jobs = Jobs::open(
            settings.jobs_config(),
            Arc::clone(&store),
            Arc::clone(&pool),
            op_limits,
            io_limits(&settings),
        )
        .await
        .context("opening the job queue")?;
        let auth = Arc::new(open_auth(&settings, &jobs).await?);
        let state = AppState {
            store,
            runner: crate::runner::Runner::new(Arc::clone(&pool), op_limits),
            pool,
            op_limits,
            io_limits: io_limits(&settings),
            solve_timeout: settings.request_timeout(),
            draining: Arc::new(AtomicBool::new(false)),
            metrics,

            collections: Arc::new(crate::collections::Collections::new(jobs.db().clone())),
            jobs: Arc::new(jobs),
            auth,
        };
        let router = http::router(state.clone(), &settings);
        let listener = TcpListener::bind(settings.addr)
            .await
            .with_context(|| format!("binding {}", settings.addr))?;
        let ttl = settings.dataset_ttl_secs.max(1);
        Ok(Self {
            listener,
            router,
            state,
            limits: http::server::ServerLimits {
                header_timeout: secs(settings.header_timeout_secs),
                body_timeout: secs(settings.body_timeout_secs),
                min_body_rate: settings.min_body_rate,
                max_connections: settings.max_connections.max(1),
            },
            grace: Duration::from_secs(settings.shutdown_grace_secs),
            sweep_every: Duration::from_secs((ttl / 4).clamp(1, 300)),
            shutdown: Box::pin(shutdown_signal()),
        })
    }

    /// The bound port.
    pub fn port(&self) -> u16 {
        self.local_addr().map_or(0, |a| a.port())
    }

    /// The bound address.
    pub fn local_addr(&self) -> std::io::Result<SocketAddr> {
        self.listener.local_addr()
    }

    /// Replaces the shutdown trigger (default: SIGTERM or Ctrl-C).
    pub fn with_shutdown(mut self, signal: impl Future<Output = ()> + Send + 'static) -> Self {
        self.shutdown = Box::pin(signal);
        self
    }

    /// Serves until the shutdown signal, then stops accepting connections and
    /// lets in-flight requests finish within the grace period.
    pub async fn run_until_stopped(self) -> anyhow::Result<()> {
        let addr = self.local_addr()?;
        tracing::info!(api = %format!("http://{addr}/v1"), docs = %format!("http://{addr}/docs"),
            openapi = %format!("http://{addr}/openapi.json"), "geodex listening");
        let sweeper = tokio::spawn(sweep(self.state.clone(), self.sweep_every));
        let jobs = Arc::clone(&self.state.jobs);
        let workers = jobs.start();
        let draining = Arc::clone(&self.state.draining);
        let stop_jobs = Arc::clone(&self.state.jobs);
        let (stop_tx, stop_rx) = tokio::sync::watch::channel(false);
        let shutdown = self.shutdown;
        let signal = async move {
            shutdown.await;
            tracing::info!("shutting down: draining in-flight requests");
            draining.store(true, Ordering::SeqCst);
            stop_jobs.begin_shutdown();
            let _ = stop_tx.send(true);
        };
        let server = http::server::serve(self.listener, self.router, self.limits, signal);
        let grace = self.grace;
        let mut stop_rx = stop_rx;
        let deadline = async move {
            let _ = stop_rx.wait_for(|stopped| *stopped).await;
            tokio::time::sleep(grace).await;
        };
        let result = tokio::select! {
            r = server => r.context("serving HTTP"),
            () = deadline => {
                tracing::warn!(?grace, "grace period over; dropping the remaining requests");
                Ok(())
            }
        };
        sweeper.abort();
        // SIGTERM releases the leases of running jobs: another replica (or
        // this one after a restart) runs them again at once.
        jobs.shutdown(workers, Duration::from_secs(5).min(grace))
            .await;
        result
    }
}

/// Decides whether requests need a key: yes with `--auth` or when any key
/// exists. Without, the service serves only on a loopback address (as
/// Redis's protected mode), and says in the log that auth is off.
async fn open_auth(settings: &ServeArgs, jobs: &Jobs) -> anyhow::Result<http::auth::Auth> {
    let keys = Arc::new(Keys::new(jobs.db().clone(), settings.key_defaults()));
    let any_key = keys.any_active().await.context("reading the API keys")?;
    let on = settings.auth || any_key;
    let addr = settings.addr;
    if !on && !addr.ip().is_loopback() {
        anyhow::bail!(
            "refusing to serve on {addr} without authentication: anyone who can reach it could \
             read and delete every dataset and job. Create a key with `geodex keys create \
             --tenant NAME` (same --data-dir / --queue) and start with --auth, or listen on a \
             loopback address such as 127.0.0.1"
        );
    }
    if !on {
        tracing::warn!(%addr, "auth is off: no API key exists and the address is a loopback \
            one, so every process of this machine can use the service; `geodex keys create \
            --tenant NAME` and --auth turn it on");
    } else if !any_key {
        tracing::warn!(
            "auth is on but no API key exists yet: every request but the probes \
            is answered 401; create one with `geodex keys create --tenant NAME`"
        );
    } else {
        tracing::info!("auth is on: requests need an API key");
    }
    Ok(http::auth::Auth {
        keys: on.then_some(keys),
        buckets: Default::default(),
        allowed_origins: settings.cors_origins.clone(),
    })
}

/// The limits the service validates requests against (also what
/// [`crate::fuzzing`] runs the request parsers with).
pub(crate) fn op_limits(settings: &ServeArgs) -> OpLimits {
    OpLimits {
        max_cells: settings.max_cells,
        ..OpLimits::default()
    }
}

/// The limits the service decodes uploads with (also what
/// [`crate::fuzzing`] runs the decoders with).
pub(crate) fn io_limits(settings: &ServeArgs) -> Limits {
    Limits {
        max_cells: settings.max_cells,
        max_bytes: settings.max_cells.saturating_mul(8),
    }
}

async fn sweep(state: AppState, every: Duration) {
    let mut tick = tokio::time::interval(every);
    loop {
        tick.tick().await;
        let n = state.store.sweep_expired().await;
        if n > 0 {
            tracing::info!(removed = n, "expired datasets swept");
        }
    }
}

async fn shutdown_signal() {
    let ctrl_c = async {
        if tokio::signal::ctrl_c().await.is_err() {
            std::future::pending::<()>().await;
        }
    };
    #[cfg(unix)]
    let term = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    #[cfg(not(unix))]
    let term = std::future::pending::<()>();
    tokio::select! {
        () = ctrl_c => {},
        () = term => {},
    }
}

/// A duration from seconds given on the command line (negative: zero;
/// non-finite or huge: no limit in practice).
fn secs(s: f64) -> Duration {
    Duration::try_from_secs_f64(s.max(0.0)).unwrap_or(Duration::from_secs(u32::MAX.into()))
}

/// Runs the service until SIGTERM or Ctrl-C (the `geodex serve` command).
pub fn serve(args: ServeArgs) -> anyhow::Result<()> {
    telemetry::init_logging(args.log_json);
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    let result = runtime.block_on(async move {
        let app = Application::build(args).await?;
        app.run_until_stopped().await
    });
    // Idle blocking-pool threads would otherwise keep the process alive a few seconds.
    runtime.shutdown_timeout(Duration::from_secs(1));
    tracing::info!("stopped");
    result
}
