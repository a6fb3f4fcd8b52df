//! The flags of one running attempt: the cancel flag its solver polls, why
//! it was raised, and the progress the solver reported.
//!
//! The heartbeat, a cancellation (local or announced by another replica) and
//! SIGTERM raise the flag; the worker reads the reason once the solve has
//! stopped to decide how the attempt ends. Everything is an atomic: the
//! solver's threads, the heartbeat and the listener share it without a lock.

use std::sync::atomic::{AtomicBool, AtomicU64, AtomicU8, Ordering};

/// Why a running attempt's flag was raised.
///
/// Stored in an [`AtomicU8`] as its discriminant (`0` means not raised, so
/// no reason is `0`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub(crate) enum StopReason {
    /// A client asked for cancellation: the job ends `cancelled`.
    Cancel = 1,
    /// The time limit passed: the job ends `failed`.
    TimeLimit = 2,
    /// The lease was lost (another worker owns the job now): nothing is written.
    LeaseLost = 3,
    /// This process is shutting down: the lease is released.
    Shutdown = 4,
}

/// The value of a flag that was not raised.
const NOT_RAISED: u8 = 0;

impl TryFrom<u8> for StopReason {
    /// The value, which names no reason.
    type Error = u8;

    fn try_from(v: u8) -> Result<Self, u8> {
        match v {
            1 => Ok(StopReason::Cancel),
            2 => Ok(StopReason::TimeLimit),
            3 => Ok(StopReason::LeaseLost),
            4 => Ok(StopReason::Shutdown),
            _ => Err(v),
        }
    }
}

/// The cancel flag, stop reason and progress of one running attempt.
#[derive(Debug, Default)]
pub(crate) struct RunFlags {
    /// Polled by the solver (through [`crate::runner::Watch`]).
    flag: AtomicBool,
    /// A [`StopReason`] as `u8`, or [`NOT_RAISED`].
    reason: AtomicU8,
    /// The last fraction reported, as `f64` bits.
    progress: AtomicU64,
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
    pub fn stop(&self, reason: StopReason) {
        let _ = self.reason.compare_exchange(
            NOT_RAISED,
            reason as u8,
            Ordering::SeqCst,
            Ordering::SeqCst,
        );
        self.flag.store(true, Ordering::SeqCst);
    }

    /// Why the flag was raised; `None` while it is not.
    pub fn reason(&self) -> Option<StopReason> {
        StopReason::try_from(self.reason.load(Ordering::SeqCst)).ok()
    }

    /// The last progress fraction the solver reported.
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
        assert_eq!(f.reason(), None);
        assert!(!f.flag.load(Ordering::SeqCst));
        f.stop(StopReason::TimeLimit);
        f.stop(StopReason::Cancel);
        assert_eq!(f.reason(), Some(StopReason::TimeLimit));
        assert!(f.flag.load(Ordering::SeqCst));
    }

    #[test]
    fn reasons_round_trip_through_u8() {
        for r in [
            StopReason::Cancel,
            StopReason::TimeLimit,
            StopReason::LeaseLost,
            StopReason::Shutdown,
        ] {
            assert_ne!(r as u8, NOT_RAISED);
            assert_eq!(StopReason::try_from(r as u8), Ok(r));
        }
        assert_eq!(StopReason::try_from(NOT_RAISED), Err(NOT_RAISED));
        assert_eq!(StopReason::try_from(5), Err(5));
    }
}
