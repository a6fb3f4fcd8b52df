//! The solver pool: one dedicated rayon thread pool (threads `solver-N`) that
//! runs every solve, so CPU work never blocks the async runtime.
//!
//! * **Admission.** At most `capacity` solves are admitted at once (waiting +
//!   running). [`SolverPool::run`] refuses the next one immediately with
//!   [`PoolError::Busy`] (the HTTP layer answers 503 with `Retry-After`).
//! * **Memory.** Each solve or decode states its estimated peak memory
//!   ([`SolverPool::run_sized`], estimated from shapes and counts known
//!   before anything is allocated), and the estimates of the admitted ones
//!   never add up to more than the memory budget: beyond it the next one is
//!   refused with [`PoolError::NoMemory`] (503 + `Retry-After`), and one
//!   that would not fit even alone with [`PoolError::TooBig`] (413).
//! * **Bridge.** An admitted job is handed to the pool with `spawn` and its
//!   result comes back through a `tokio::sync::oneshot` channel.
//! * **Cancellation.** Each job gets its own cancel flag, passed to the core
//!   through [`Control`]. It is raised when the deadline passes
//!   ([`PoolError::Deadline`]) and when the awaiting future is dropped (the
//!   client went away): a drop guard raises it. A job cancelled while still
//!   waiting never starts; a running one stops at the solver's next poll, and
//!   its admission slot is freed when the closure returns.

use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use tokio::sync::{oneshot, OwnedSemaphorePermit, Semaphore};

use crate::numerics::Control;
use crate::telemetry;

/// Why a job did not produce a result.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PoolError {
    /// Every admission slot is taken; try again later.
    #[error("the solver pool is full ({capacity} solves admitted); retry later")]
    Busy {
        /// The admission capacity.
        capacity: usize,
    },
    /// The solves admitted now hold so much of the memory budget that this
    /// one does not fit; try again later.
    #[error(
        "the solves running now hold {in_use} of the {budget} bytes of memory this service \
         gives them, and this one needs an estimated {needed}; retry later"
    )]
    NoMemory {
        /// Estimated peak bytes of this solve.
        needed: u64,
        /// Bytes held by the admitted ones.
        in_use: u64,
        /// The budget.
        budget: u64,
    },
    /// This solve alone would need more than the whole memory budget.
    #[error(
        "this needs an estimated {needed} bytes of memory, more than the {budget} this \
         service gives all its solves together (--solve-memory-bytes); make it smaller"
    )]
    TooBig {
        /// Estimated peak bytes.
        needed: u64,
        /// The budget.
        budget: u64,
    },
    /// The deadline passed before the job finished; it was cancelled.
    #[error("the solve did not finish within {0:?} and was cancelled")]
    Deadline(Duration),
    /// The job panicked or the pool dropped it.
    #[error("the solve failed unexpectedly")]
    Lost,
}

/// How long a job waited and ran.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JobTiming {
    /// Seconds between admission and the start on a pool thread.
    pub queue_seconds: f64,
    /// Seconds the closure ran.
    pub run_seconds: f64,
}

/// The dedicated solver pool with admission control.
#[derive(Debug)]
pub struct SolverPool {
    pool: rayon::ThreadPool,
    permits: Arc<Semaphore>,
    capacity: usize,
    threads: usize,
    waiting: Arc<AtomicUsize>,
    running: Arc<AtomicUsize>,
    /// Bytes all admitted solves may hold together (estimated peaks).
    memory_budget: u64,
    /// Estimated peak bytes of the solves admitted now.
    memory_held: Arc<AtomicU64>,
}

/// Gives back an admitted solve's estimated bytes when dropped.
struct Held {
    held: Arc<AtomicU64>,
    bytes: u64,
}

impl Drop for Held {
    fn drop(&mut self) {
        self.held.fetch_sub(self.bytes, Ordering::SeqCst);
    }
}

/// Raises the cancel flag when dropped (client gone, deadline, or done).
struct CancelOnDrop(Arc<AtomicBool>);

impl Drop for CancelOnDrop {
    fn drop(&mut self) {
        self.0.store(true, Ordering::Relaxed);
    }
}

/// Decrements a counter and republishes its gauge when dropped.
struct Count {
    counter: Arc<AtomicUsize>,
    gauge: &'static str,
}

impl Count {
    fn enter(counter: &Arc<AtomicUsize>, gauge: &'static str) -> Self {
        let n = counter.fetch_add(1, Ordering::SeqCst) + 1;
        metrics::gauge!(gauge).set(n as f64);
        Count {
            counter: Arc::clone(counter),
            gauge,
        }
    }
}

impl Drop for Count {
    fn drop(&mut self) {
        let n = self.counter.fetch_sub(1, Ordering::SeqCst) - 1;
        metrics::gauge!(self.gauge).set(n as f64);
    }
}

impl SolverPool {
    /// A pool of `threads` threads named `solver-N`, admitting at most
    /// `capacity` solves at once.
    pub fn new(threads: usize, capacity: usize) -> Result<Self, rayon::ThreadPoolBuildError> {
        let threads = threads.max(1);
        let capacity = capacity.max(1);
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .thread_name(|i| format!("solver-{i}"))
            .build()?;
        Ok(Self {
            pool,
            permits: Arc::new(Semaphore::new(capacity)),
            capacity,
            threads,
            waiting: Arc::new(AtomicUsize::new(0)),
            running: Arc::new(AtomicUsize::new(0)),
            memory_budget: u64::MAX,
            memory_held: Arc::new(AtomicU64::new(0)),
        })
    }

    /// The same pool whose admitted solves may hold at most `bytes` of
    /// estimated peak memory together.
    pub fn with_memory_budget(mut self, bytes: u64) -> Self {
        self.memory_budget = bytes.max(1);
        self
    }

    /// The memory budget and the estimated bytes held now.
    pub fn memory(&self) -> (u64, u64) {
        (self.memory_budget, self.memory_held.load(Ordering::SeqCst))
    }

    /// Takes `bytes` of the memory budget, or says why not.
    fn hold(&self, bytes: u64) -> Result<Held, PoolError> {
        if bytes > self.memory_budget {
            return Err(PoolError::TooBig {
                needed: bytes,
                budget: self.memory_budget,
            });
        }
        let mut in_use = self.memory_held.load(Ordering::SeqCst);
        loop {
            if in_use.saturating_add(bytes) > self.memory_budget {
                return Err(PoolError::NoMemory {
                    needed: bytes,
                    in_use,
                    budget: self.memory_budget,
                });
            }
            match self.memory_held.compare_exchange(
                in_use,
                in_use + bytes,
                Ordering::SeqCst,
                Ordering::SeqCst,
            ) {
                Ok(_) => {
                    return Ok(Held {
                        held: Arc::clone(&self.memory_held),
                        bytes,
                    })
                }
                Err(now) => in_use = now,
            }
        }
    }

    /// Admission capacity (waiting + running).
    pub fn capacity(&self) -> usize {
        self.capacity
    }

    /// Pool threads.
    pub fn threads(&self) -> usize {
        self.threads
    }

    /// Solves admitted but not started.
    pub fn waiting(&self) -> usize {
        self.waiting.load(Ordering::SeqCst)
    }

    /// Solves running now.
    pub fn running(&self) -> usize {
        self.running.load(Ordering::SeqCst)
    }

    /// True while the pool can take at least one more solve.
    pub fn has_room(&self) -> bool {
        self.permits.available_permits() > 0
    }

    /// Runs `job` on the pool with a deadline, and records its time under
    /// `operation`. The job receives a [`Control`] whose cancel flag rises at
    /// the deadline or when this future is dropped.
    pub async fn run<T, F>(
        &self,
        operation: &'static str,
        deadline: Duration,
        job: F,
    ) -> Result<(T, JobTiming), PoolError>
    where
        T: Send + 'static,
        F: FnOnce(&Control<'_>) -> T + Send + 'static,
    {
        self.run_sized(operation, deadline, 0, job).await
    }

    /// [`Self::run`] for a job whose peak memory is estimated at `bytes`:
    /// admitted only while the estimates of the admitted jobs, this one's
    /// included, fit in the memory budget.
    pub async fn run_sized<T, F>(
        &self,
        operation: &'static str,
        deadline: Duration,
        bytes: u64,
        job: F,
    ) -> Result<(T, JobTiming), PoolError>
    where
        T: Send + 'static,
        F: FnOnce(&Control<'_>) -> T + Send + 'static,
    {
        let held = self.hold(bytes).inspect_err(|_| {
            metrics::counter!(telemetry::REJECTED).increment(1);
        })?;
        let permit: OwnedSemaphorePermit = match Arc::clone(&self.permits).try_acquire_owned() {
            Ok(p) => p,
            Err(_) => {
                metrics::counter!(telemetry::REJECTED).increment(1);
                return Err(PoolError::Busy {
                    capacity: self.capacity,
                });
            }
        };
        let admitted = Instant::now();
        let flag = Arc::new(AtomicBool::new(false));
        let _guard = CancelOnDrop(Arc::clone(&flag));
        let (tx, rx) = oneshot::channel();
        let waiting = Count::enter(&self.waiting, telemetry::QUEUE_DEPTH);
        let running = Arc::clone(&self.running);
        self.pool.spawn(move || {
            let slot = (permit, held);
            drop(waiting);
            if flag.load(Ordering::Relaxed) {
                return; // cancelled before it started: never run it
            }
            let _running = Count::enter(&running, telemetry::IN_FLIGHT);
            let started = Instant::now();
            let control = Control::new().with_cancel(&flag);
            // A panicking solver must not take the process down (rayon aborts
            // on an uncaught panic in `spawn`): catch it, drop the sender, and
            // the caller sees `PoolError::Lost` (a 500).
            let out = match std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| job(&control)))
            {
                Ok(out) => out,
                Err(_) => {
                    tracing::error!(operation, "a solve panicked");
                    return;
                }
            };
            let run_seconds = started.elapsed().as_secs_f64();
            // The flag is up when the deadline passed or the client left
            // while the job ran (the guard only drops after the result is in).
            let outcome = if flag.load(Ordering::Relaxed) {
                "cancelled"
            } else {
                "completed"
            };
            metrics::histogram!(telemetry::SOLVE_SECONDS, "operation" => operation, "outcome" => outcome)
                .record(run_seconds);
            let timing = JobTiming {
                queue_seconds: started.duration_since(admitted).as_secs_f64(),
                run_seconds,
            };
            // The slot and the memory come back before the result is handed
            // over, so that a caller who sees the result sees them free.
            drop(slot);
            // The receiver is gone when the request was cancelled; nothing to do.
            let _ = tx.send((out, timing));
        });
        match tokio::time::timeout(deadline, rx).await {
            Ok(Ok(result)) => Ok(result),
            Ok(Err(_)) => Err(PoolError::Lost),
            Err(_) => Err(PoolError::Deadline(deadline)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn a_panicking_job_is_lost_and_the_pool_survives() {
        let pool = SolverPool::new(1, 2).unwrap();
        let r: Result<((), JobTiming), PoolError> = pool
            .run("test", Duration::from_secs(5), |_c: &Control<'_>| {
                panic!("boom")
            })
            .await;
        assert_eq!(r.unwrap_err(), PoolError::Lost);
        let (v, _) = pool
            .run("test", Duration::from_secs(5), |_c: &Control<'_>| 7)
            .await
            .unwrap();
        assert_eq!(v, 7);
        assert!(pool.has_room());
    }

    fn spin_until_cancelled(c: &Control<'_>) -> bool {
        let t = Instant::now();
        while !c.is_cancelled() {
            if t.elapsed() > Duration::from_secs(10) {
                return false;
            }
            std::thread::yield_now();
        }
        true
    }

    #[tokio::test]
    async fn admits_up_to_capacity_then_refuses() {
        let pool = Arc::new(SolverPool::new(1, 2).expect("pool"));
        let (a, b) = {
            let p1 = Arc::clone(&pool);
            let p2 = Arc::clone(&pool);
            (
                tokio::spawn(async move {
                    p1.run("t", Duration::from_millis(300), spin_until_cancelled)
                        .await
                }),
                tokio::spawn(async move {
                    p2.run("t", Duration::from_millis(300), spin_until_cancelled)
                        .await
                }),
            )
        };
        // Wait until both are admitted.
        while pool.has_room() {
            tokio::task::yield_now().await;
        }
        let third = pool.run("t", Duration::from_secs(1), |_| 1).await;
        assert_eq!(third.map(|r| r.0), Err(PoolError::Busy { capacity: 2 }));
        for h in [a, b] {
            let r = h.await.expect("join");
            assert_eq!(
                r.map(|r| r.0),
                Err(PoolError::Deadline(Duration::from_millis(300)))
            );
        }
        // Slots are freed once the cancelled jobs return.
        let mut ok = None;
        for _ in 0..200 {
            match pool.run("t", Duration::from_secs(5), |_| 7).await {
                Ok((v, _)) => {
                    ok = Some(v);
                    break;
                }
                Err(PoolError::Busy { .. }) => tokio::time::sleep(Duration::from_millis(10)).await,
                Err(e) => panic!("{e}"),
            }
        }
        assert_eq!(ok, Some(7));
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn admits_by_estimated_memory() {
        let pool = Arc::new(SolverPool::new(2, 8).expect("pool").with_memory_budget(100));
        let (started_tx, started_rx) = std::sync::mpsc::channel();
        let p = Arc::clone(&pool);
        let first = tokio::spawn(async move {
            p.run_sized("t", Duration::from_millis(300), 60, move |c| {
                let _ = started_tx.send(());
                spin_until_cancelled(c)
            })
            .await
        });
        started_rx
            .recv_timeout(Duration::from_secs(10))
            .expect("first job started");
        assert_eq!(pool.memory(), (100, 60));
        // 60 + 60 > 100: refused while the first holds its bytes ...
        let second = pool.run_sized("t", Duration::from_secs(1), 60, |_| 2).await;
        assert_eq!(
            second.map(|r| r.0),
            Err(PoolError::NoMemory {
                needed: 60,
                in_use: 60,
                budget: 100
            })
        );
        // ... a small one fits beside it ...
        let small = pool.run_sized("t", Duration::from_secs(5), 40, |_| 3).await;
        assert_eq!(small.map(|r| r.0), Ok(3));
        // ... and one larger than the budget never fits.
        let huge = pool
            .run_sized("t", Duration::from_secs(1), 101, |_| 4)
            .await;
        assert_eq!(
            huge.map(|r| r.0),
            Err(PoolError::TooBig {
                needed: 101,
                budget: 100
            })
        );
        let _ = first.await.expect("join");
        // The first job's bytes come back when it returns.
        let mut ok = None;
        for _ in 0..200 {
            match pool
                .run_sized("t", Duration::from_secs(5), 100, |_| 5)
                .await
            {
                Ok((v, _)) => {
                    ok = Some(v);
                    break;
                }
                Err(PoolError::NoMemory { .. }) => {
                    tokio::time::sleep(Duration::from_millis(10)).await
                }
                Err(e) => panic!("{e}"),
            }
        }
        assert_eq!(ok, Some(5));
        assert_eq!(pool.memory(), (100, 0));
    }

    #[tokio::test]
    async fn dropping_the_future_cancels_the_job() {
        let pool = SolverPool::new(1, 1).expect("pool");
        let (started_tx, started_rx) = std::sync::mpsc::channel();
        let (seen_tx, seen_rx) = std::sync::mpsc::channel();
        let mut fut = Box::pin(pool.run("t", Duration::from_secs(30), move |c| {
            let _ = started_tx.send(());
            let cancelled = spin_until_cancelled(c);
            let _ = seen_tx.send(cancelled);
        }));
        // Drive the future until the job runs on the pool, then drop it (as
        // hyper does when the client disconnects).
        while started_rx.try_recv().is_err() {
            tokio::select! {
                _ = &mut fut => panic!("the job cannot finish before it is cancelled"),
                () = tokio::time::sleep(Duration::from_millis(5)) => {}
            }
        }
        drop(fut);
        let cancelled = seen_rx
            .recv_timeout(Duration::from_secs(10))
            .expect("job ran");
        assert!(cancelled, "the job saw its cancel flag");
    }
}
