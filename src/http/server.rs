//! The accept loop: HTTP/1.1 and HTTP/2 (cleartext, prior knowledge) over
//! the router, with the limits a shared service needs and `axum::serve`
//! does not set:
//!
//! - **header timeout**: a client has [`ServerLimits::header_timeout`] to
//!   send its first bytes and then its request headers; the same timer closes
//!   a keep-alive connection that stays idle that long (hyper starts it when
//!   it waits for the next request). An HTTP/2 connection with no stream in
//!   progress and none opened for that long is shut down too (GOAWAY), since
//!   hyper's HTTP/2 server has no idle timer;
//! - **body stall timeout**: a request body that sends nothing for
//!   [`ServerLimits::body_timeout`] fails with [`BodyStalled`], which the
//!   extractors answer 408 (`request-timeout`), and the connection closes;
//! - **connection cap**: at [`ServerLimits::max_connections`] open
//!   connections, a new connection evicts the oldest connection that has no
//!   request in progress (an idle keep-alive, or a client still dribbling
//!   its headers: the slowloris case), and is refused with a 503
//!   problem only when every connection is serving a request. The cap is
//!   lowered to fit the process's open-file limit, so that accepting never
//!   runs out of descriptors because of connections;
//! - **accept errors** (out of descriptors, aborted handshakes) slow the
//!   loop down for 50 ms instead of ending it;
//! - **graceful shutdown**: on the signal the listener closes, idle
//!   connections close, and connections with a request in progress finish it.

use std::collections::HashMap;
use std::future::Future;
use std::pin::Pin;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll};
use std::time::{Duration, Instant};

use axum::body::Body;
use axum::Router;
use bytes::Bytes;
use http_body::{Body as HttpBody, Frame, SizeHint};
use hyper::body::Incoming;
use hyper_util::rt::{TokioExecutor, TokioIo, TokioTimer};
use hyper_util::server::conn::auto::Builder;
use tokio::io::AsyncWriteExt;
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{watch, Notify};
use tower::ServiceExt;

use crate::problem::{Kind, TYPE_BASE};

/// Limits of the accept loop (see the module documentation).
#[derive(Debug, Clone, Copy)]
pub struct ServerLimits {
    /// Time to send the request headers; also the idle keep-alive timeout.
    pub header_timeout: Duration,
    /// Longest pause within a request body.
    pub body_timeout: Duration,
    /// Slowest body accepted, in bytes per second, after a first
    /// `body_timeout` of grace (0: no minimum): a body must have sent
    /// `min_body_rate × (elapsed − body_timeout)` bytes at every moment.
    pub min_body_rate: u64,
    /// Open connections at most (lowered to fit the open-file limit).
    pub max_connections: usize,
}

impl Default for ServerLimits {
    fn default() -> Self {
        Self {
            header_timeout: Duration::from_secs(10),
            body_timeout: Duration::from_secs(30),
            min_body_rate: 0,
            max_connections: 4096,
        }
    }
}

/// The error of a request body that sent nothing for the body timeout.
#[derive(Debug, Clone, Copy, thiserror::Error)]
#[error("the request body sent nothing for {0:?}")]
pub struct BodyStalled(pub Duration);

/// The error of a request body that arrives more slowly than the minimum
/// rate (a client trickling bytes to hold its connection).
#[derive(Debug, Clone, Copy, thiserror::Error)]
#[error(
    "the request body sent {received} bytes in {seconds:.1} s, slower than the minimum of \
     {min_rate} bytes per second after the first {grace:?}"
)]
pub struct BodyTooSlow {
    /// Bytes received.
    pub received: u64,
    /// Seconds since the body was first read.
    pub seconds: f64,
    /// The minimum rate.
    pub min_rate: u64,
    /// The grace period.
    pub grace: Duration,
}

/// The [`BodyStalled`] somewhere in `e`'s chain of sources, if any.
pub fn stalled_in<'a>(e: &'a (dyn std::error::Error + 'static)) -> Option<&'a BodyStalled> {
    let mut cur = Some(e);
    while let Some(err) = cur {
        if let Some(s) = err.downcast_ref::<BodyStalled>() {
            return Some(s);
        }
        cur = err.source();
    }
    None
}

/// The [`BodyTooSlow`] somewhere in `e`'s chain of sources, if any.
fn too_slow_in(e: &(dyn std::error::Error + 'static)) -> Option<BodyTooSlow> {
    let mut cur = Some(e);
    while let Some(err) = cur {
        if let Some(s) = err.downcast_ref::<BodyTooSlow>() {
            return Some(*s);
        }
        cur = err.source();
    }
    None
}

/// The 408 for a body read that failed because the body stalled or came
/// too slowly (a [`BodyStalled`] or [`BodyTooSlow`] in `e`'s sources), for
/// every extractor that reads a body.
pub fn stalled_problem(e: &(dyn std::error::Error + 'static)) -> Option<crate::problem::ApiError> {
    if let Some(slow) = too_slow_in(e) {
        return Some(crate::problem::ApiError::request_timeout(format!(
            "{slow}; send the body faster (the server's --min-body-rate)"
        )));
    }
    stalled_in(e).map(|stalled| {
        crate::problem::ApiError::request_timeout(format!(
            "{stalled}; send the body without pauses that long (the server's --body-timeout-secs)"
        ))
    })
}

/// Descriptors kept free for the database, files and the refusals.
const FD_RESERVE: usize = 256;
/// Refusals (503 written on a fresh connection) in progress at most; beyond
/// it a connection over the cap is closed without an answer.
const MAX_REFUSALS: usize = 64;

/// The connection cap that fits the process's soft open-file limit (read
/// from `/proc/self/limits`; unchanged where that file does not exist).
pub fn effective_cap(wanted: usize) -> usize {
    let soft = std::fs::read_to_string("/proc/self/limits")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("Max open files"))
                .and_then(|l| l.split_whitespace().nth(3).map(str::to_owned))
        })
        .and_then(|v| v.parse::<usize>().ok());
    match soft {
        Some(limit) => wanted.min(limit.saturating_sub(FD_RESERVE).max(16)).max(1),
        None => wanted.max(1),
    }
}

/// One open connection, as the cap sees it.
struct Slot {
    since: Instant,
    /// Requests in progress on it (a response body still streaming counts).
    busy: Arc<AtomicUsize>,
    /// Raised to close it (eviction).
    evict: Arc<Notify>,
}

#[derive(Default)]
struct Registry {
    next: u64,
    open: HashMap<u64, Slot>,
}

enum Admission {
    /// Serve it under this id.
    Admit(u64, Arc<AtomicUsize>, Arc<Notify>),
    /// Every slot is busy.
    Refuse,
}

impl Registry {
    fn admit(&mut self, cap: usize) -> Admission {
        if self.open.len() >= cap {
            let oldest_idle = self
                .open
                .iter()
                .filter(|(_, s)| s.busy.load(Ordering::Acquire) == 0)
                .min_by_key(|(_, s)| s.since)
                .map(|(id, _)| *id);
            match oldest_idle.and_then(|id| self.open.remove(&id)) {
                Some(victim) => {
                    victim.evict.notify_one();
                    metrics::counter!(crate::telemetry::HTTP_CONNECTIONS_EVICTED).increment(1);
                }
                None => return Admission::Refuse,
            }
        }
        self.next += 1;
        let busy = Arc::new(AtomicUsize::new(0));
        let evict = Arc::new(Notify::new());
        self.open.insert(
            self.next,
            Slot {
                since: Instant::now(),
                busy: Arc::clone(&busy),
                evict: Arc::clone(&evict),
            },
        );
        Admission::Admit(self.next, busy, evict)
    }
}

fn lock(r: &Mutex<Registry>) -> std::sync::MutexGuard<'_, Registry> {
    r.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// Serves `router` on `listener` until `signal` completes, then stops
/// accepting and returns once every connection has closed (the caller
/// bounds that wait with its grace period).
pub async fn serve(
    listener: TcpListener,
    router: Router,
    limits: ServerLimits,
    signal: impl Future<Output = ()> + Send,
) -> std::io::Result<()> {
    let cap = effective_cap(limits.max_connections);
    if cap < limits.max_connections {
        tracing::warn!(
            wanted = limits.max_connections,
            cap,
            "the open-file limit lowers --max-connections (raise it with `ulimit -n`)"
        );
    }
    let mut builder = Builder::new(TokioExecutor::new());
    builder
        .http1()
        .timer(TokioTimer::new())
        .header_read_timeout(limits.header_timeout);
    builder
        .http2()
        .timer(TokioTimer::new())
        .max_concurrent_streams(128)
        .keep_alive_interval(Some(Duration::from_secs(30)))
        .keep_alive_timeout(Duration::from_secs(10));
    let builder = Arc::new(builder);
    let registry = Arc::new(Mutex::new(Registry::default()));
    let refusals = Arc::new(AtomicUsize::new(0));
    let (stop_tx, stop_rx) = watch::channel(false);
    let (alive_tx, alive_rx) = watch::channel(());
    tokio::pin!(signal);
    loop {
        let accepted = tokio::select! {
            () = &mut signal => break,
            a = listener.accept() => a,
        };
        let stream = match accepted {
            Ok((stream, _)) => stream,
            Err(e) => {
                if !matches!(
                    e.kind(),
                    std::io::ErrorKind::ConnectionAborted | std::io::ErrorKind::ConnectionReset
                ) {
                    tracing::warn!(error = %e, "accept failed; retrying in 50 ms");
                    tokio::time::sleep(Duration::from_millis(50)).await;
                }
                continue;
            }
        };
        let _ = stream.set_nodelay(true);
        let admission = lock(&registry).admit(cap);
        match admission {
            Admission::Refuse => {
                metrics::counter!(crate::telemetry::HTTP_CONNECTIONS_REFUSED).increment(1);
                if refusals.fetch_add(1, Ordering::AcqRel) < MAX_REFUSALS {
                    let refusals = Arc::clone(&refusals);
                    tokio::spawn(async move {
                        refuse(stream).await;
                        refusals.fetch_sub(1, Ordering::AcqRel);
                    });
                } else {
                    refusals.fetch_sub(1, Ordering::AcqRel);
                }
            }
            Admission::Admit(id, busy, evict) => {
                let conn = Connection {
                    id,
                    busy,
                    evict,
                    registry: Arc::clone(&registry),
                    builder: Arc::clone(&builder),
                    router: router.clone(),
                    limits,
                    stop: stop_rx.clone(),
                    _alive: alive_rx.clone(),
                };
                tokio::spawn(conn.run(stream));
            }
        }
    }
    drop(listener);
    let _ = stop_tx.send(true);
    drop(alive_rx);
    alive_tx.closed().await;
    Ok(())
}

/// Answers 503 on a connection over the cap and closes it.
async fn refuse(mut stream: TcpStream) {
    let kind = Kind::Busy;
    let body = format!(
        "{{\"type\":\"{TYPE_BASE}{}\",\"title\":\"{}\",\"status\":503,\"detail\":\"every \
         connection is serving a request (--max-connections); retry later\"}}",
        kind.slug(),
        kind.title()
    );
    let head = format!(
        "HTTP/1.1 503 Service Unavailable\r\ncontent-type: application/problem+json\r\n\
         retry-after: 1\r\nconnection: close\r\ncontent-length: {}\r\n\r\n",
        body.len()
    );
    let _ = tokio::time::timeout(Duration::from_secs(1), async {
        stream.write_all(head.as_bytes()).await?;
        stream.write_all(body.as_bytes()).await?;
        stream.shutdown().await
    })
    .await;
}

/// One accepted connection and what it needs.
struct Connection {
    id: u64,
    busy: Arc<AtomicUsize>,
    evict: Arc<Notify>,
    registry: Arc<Mutex<Registry>>,
    builder: Arc<Builder<TokioExecutor>>,
    router: Router,
    limits: ServerLimits,
    stop: watch::Receiver<bool>,
    /// Dropped when the connection ends ([`serve`] waits for all).
    _alive: watch::Receiver<()>,
}

impl Connection {
    async fn run(mut self, stream: TcpStream) {
        // hyper's version sniffing (HTTP/1 or the HTTP/2 preface) has no
        // timer of its own: wait for the first bytes here.
        let mut probe = [0u8; 3];
        let first = tokio::select! {
            r = tokio::time::timeout(self.limits.header_timeout, stream.peek(&mut probe)) => {
                match r {
                    Ok(Ok(n)) if n > 0 => Some(n),
                    _ => None,
                }
            }
            () = self.evict.notified() => None,
            _ = self.stop.changed() => None,
        };
        if let Some(n) = first {
            // The HTTP/2 preface starts `PRI`; HTTP/1 keeps hyper's timers.
            let maybe_h2 = b"PRI".starts_with(&probe[..n]);
            self.serve(stream, maybe_h2).await;
        }
        lock(&self.registry).open.remove(&self.id);
    }

    /// Serves the connection; `idle_check_on` arms the idle timeout of
    /// connections that may speak HTTP/2 (hyper has none for them).
    async fn serve(&mut self, stream: TcpStream, idle_check_on: bool) {
        let router = self.router.clone();
        let busy = Arc::clone(&self.busy);
        let served = Arc::new(AtomicUsize::new(0));
        let counted = Arc::clone(&served);
        let body_timeout = self.limits.body_timeout;
        let min_rate = self.limits.min_body_rate;
        let service = hyper::service::service_fn(move |req: hyper::Request<Incoming>| {
            counted.fetch_add(1, Ordering::AcqRel);
            let guard = Busy::enter(&busy);
            let router = router.clone();
            async move {
                let req = req.map(|b| Body::new(Stalling::new(b, body_timeout, min_rate)));
                let res = router.oneshot(req).await;
                res.map(|r| {
                    r.map(|b| {
                        Body::new(Guarded {
                            inner: b,
                            _busy: guard,
                        })
                    })
                })
            }
        });
        let conn = self
            .builder
            .serve_connection_with_upgrades(TokioIo::new(stream), service);
        tokio::pin!(conn);
        let mut draining = *self.stop.borrow();
        if draining {
            conn.as_mut().graceful_shutdown();
        }
        // The idle timeout of HTTP/2: a connection with no request in
        // progress and none started for a whole period is shut down
        // (between one and two periods of idleness): hyper has no timer for
        // it, and a client that answers the pings would otherwise hold its
        // connection forever. HTTP/1 has hyper's header timer, and skips
        // this (19,800 slow HTTP/1 connections do not each need a timer).
        let mut idle_check = tokio::time::interval_at(
            tokio::time::Instant::now() + self.limits.header_timeout,
            self.limits.header_timeout.max(Duration::from_millis(10)),
        );
        let mut seen = 0;
        // An idle connection told to go gets one more period to finish its
        // goodbye (an HTTP/2 client that never acknowledges the GOAWAY's
        // ping would otherwise keep it), then it is dropped.
        let mut goodbye: Option<Pin<Box<tokio::time::Sleep>>> = None;
        loop {
            tokio::select! {
                r = conn.as_mut() => {
                    if let Err(e) = r {
                        tracing::debug!(error = %e, "connection ended with an error");
                    }
                    break;
                }
                () = self.evict.notified() => break,
                _ = self.stop.changed(), if !draining => {
                    draining = true;
                    conn.as_mut().graceful_shutdown();
                }
                _ = idle_check.tick(), if idle_check_on && !draining => {
                    let now = served.load(Ordering::Acquire);
                    if now == seen && self.busy.load(Ordering::Acquire) == 0 {
                        draining = true;
                        conn.as_mut().graceful_shutdown();
                        goodbye = Some(Box::pin(tokio::time::sleep(self.limits.header_timeout)));
                    }
                    seen = now;
                }
                () = async {
                    match goodbye.as_mut() {
                        Some(timer) => timer.await,
                        None => std::future::pending().await,
                    }
                } => {
                    if self.busy.load(Ordering::Acquire) == 0 {
                        break;
                    }
                    goodbye = None;
                }
            }
        }
    }
}

/// Counts a request in progress on its connection until dropped.
struct Busy(Arc<AtomicUsize>);

impl Busy {
    fn enter(busy: &Arc<AtomicUsize>) -> Self {
        busy.fetch_add(1, Ordering::AcqRel);
        Self(Arc::clone(busy))
    }
}

impl Drop for Busy {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::AcqRel);
    }
}

/// A response body that keeps its connection counted busy until sent.
struct Guarded {
    inner: Body,
    _busy: Busy,
}

impl HttpBody for Guarded {
    type Data = Bytes;
    type Error = axum::Error;

    fn poll_frame(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
    ) -> Poll<Option<Result<Frame<Bytes>, axum::Error>>> {
        Pin::new(&mut self.inner).poll_frame(cx)
    }

    fn is_end_stream(&self) -> bool {
        self.inner.is_end_stream()
    }

    fn size_hint(&self) -> SizeHint {
        self.inner.size_hint()
    }
}

/// A request body that fails with [`BodyStalled`] when no frame arrives
/// for `limit` (the timer starts when the body is first polled and restarts
/// at every frame), and with [`BodyTooSlow`] when, `limit` after the first
/// poll, fewer than `min_rate` bytes per second of the time since arrived.
struct Stalling {
    inner: Incoming,
    limit: Duration,
    min_rate: u64,
    started: Option<tokio::time::Instant>,
    received: u64,
    timer: Option<Pin<Box<tokio::time::Sleep>>>,
}

impl Stalling {
    fn new(inner: Incoming, limit: Duration, min_rate: u64) -> Self {
        Self {
            inner,
            limit,
            min_rate,
            started: None,
            received: 0,
            timer: None,
        }
    }

    /// The moment the bytes received so far stop being enough: the grace
    /// period plus `received / min_rate` after the start (never, with no
    /// minimum).
    fn rate_deadline(&self, started: tokio::time::Instant) -> Option<tokio::time::Instant> {
        (self.min_rate > 0).then(|| {
            let earned = Duration::from_secs_f64(self.received as f64 / self.min_rate as f64);
            started + self.limit + earned
        })
    }

    fn too_slow(&self, started: tokio::time::Instant) -> BodyTooSlow {
        BodyTooSlow {
            received: self.received,
            seconds: started.elapsed().as_secs_f64(),
            min_rate: self.min_rate,
            grace: self.limit,
        }
    }
}

impl HttpBody for Stalling {
    type Data = Bytes;
    type Error = axum::BoxError;

    fn poll_frame(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
    ) -> Poll<Option<Result<Frame<Bytes>, axum::BoxError>>> {
        let this = &mut *self;
        let started = *this.started.get_or_insert_with(tokio::time::Instant::now);
        match Pin::new(&mut this.inner).poll_frame(cx) {
            Poll::Ready(frame) => {
                this.timer = None;
                if let Some(Ok(f)) = &frame {
                    if let Some(data) = f.data_ref() {
                        this.received += data.len() as u64;
                    }
                    let late = this
                        .rate_deadline(started)
                        .is_some_and(|d| tokio::time::Instant::now() > d);
                    if late && !this.inner.is_end_stream() {
                        return Poll::Ready(Some(Err(Box::new(this.too_slow(started)))));
                    }
                }
                Poll::Ready(frame.map(|f| f.map_err(Into::into)))
            }
            Poll::Pending => {
                let stall = tokio::time::Instant::now() + this.limit;
                let rate = this.rate_deadline(started);
                let timer = this.timer.get_or_insert_with(|| {
                    Box::pin(tokio::time::sleep_until(
                        rate.map_or(stall, |r| r.min(stall)),
                    ))
                });
                match timer.as_mut().poll(cx) {
                    Poll::Ready(()) => {
                        let slow = rate.is_some_and(|r| tokio::time::Instant::now() >= r);
                        let e: axum::BoxError = if slow {
                            Box::new(this.too_slow(started))
                        } else {
                            Box::new(BodyStalled(this.limit))
                        };
                        Poll::Ready(Some(Err(e)))
                    }
                    Poll::Pending => Poll::Pending,
                }
            }
        }
    }

    fn is_end_stream(&self) -> bool {
        self.inner.is_end_stream()
    }

    fn size_hint(&self) -> SizeHint {
        self.inner.size_hint()
    }
}
