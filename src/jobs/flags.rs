//! The flags of one running attempt: the cancel flag its solver polls, why
//! it was raised, and the progress the solver reported.
//!
//! The heartbeat, a cancellation (local or announced by another replica) and
//! SIGTERM raise the flag; the worker reads the reason once the solve has
//! stopped to decide how the attempt ends.

use std::sync::atomic::{AtomicBool, AtomicU64, AtomicU8, Ordering};

/// Why a running attempt's flag was raised.
pub(crate) mod stop {
    /// Not raised.
    pub const NONE: u8 = 0;
    /// A client asked for cancellation.
    pub const CANCEL: u8 = 1;
    /// The time limit passed.
    pub const TIME_LIMIT: u8 = 2;
    /// The lease was lost (another worker owns the job now).
    pub const LEASE_LOST: u8 = 3;
    /// This process is shutting down: release the lease.
    pub const SHUTDOWN: u8 = 4;
}

/// The cancel flag, stop reason and progress of one running attempt.
#[derive(Debug, Default)]
pub(crate) struct RunFlags {
    pub flag: AtomicBool,
    pub reason: AtomicU8,
    pub progress: AtomicU64,
}

impl crate::runner::Watch for RunFlags {
    fn cancel_flag(&self) -> &AtomicBool {
        &self.flag
    }

    fn report(&self, fraction: f64) {
        self.progress.store(fraction.to_bits(), Ordering::Relaxed);
    }
}

impl RunFlags {
    /// Raises the flag with a reason (the first reason wins).
    pub fn stop(&self, reason: u8) {
        let _ =
            self.reason
                .compare_exchange(stop::NONE, reason, Ordering::SeqCst, Ordering::SeqCst);
        self.flag.store(true, Ordering::SeqCst);
    }

    pub fn reason(&self) -> u8 {
        self.reason.load(Ordering::SeqCst)
    }

    pub fn progress(&self) -> f64 {
        f64::from_bits(self.progress.load(Ordering::Relaxed))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_stop_reason_wins() {
        let f = RunFlags::default();
        assert_eq!(f.reason(), stop::NONE);
        f.stop(stop::TIME_LIMIT);
        f.stop(stop::CANCEL);
        assert_eq!(f.reason(), stop::TIME_LIMIT);
        assert!(f.flag.load(Ordering::SeqCst));
    }
}
