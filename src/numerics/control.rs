//! Cooperative cancellation and progress reporting for long computations.

use std::sync::atomic::{AtomicBool, Ordering};

/// What a long computation needs from its caller: a flag that asks it to stop,
/// and a sink for its progress (a fraction in `[0, 1]`).
///
/// Solvers poll [`Control::is_cancelled`] at least every few thousand cells
/// and return their `Cancelled` error soon after the flag is raised.
///
/// # Examples
/// ```
/// use std::sync::atomic::AtomicBool;
/// use geodex::numerics::Control;
/// let flag = AtomicBool::new(false);
/// let control = Control::new().with_cancel(&flag);
/// assert!(!control.is_cancelled());
/// let job = AtomicBool::new(true);
/// assert!(control.with_cancel(&job).is_cancelled());
/// ```
#[derive(Clone, Copy, Default)]
pub struct Control<'a> {
    cancel: Option<&'a AtomicBool>,
    /// A second flag: a job's own (cancel, time limit) beside the pool's (deadline, client gone).
    also: Option<&'a AtomicBool>,
    progress: Option<&'a (dyn Fn(f64) + Sync)>,
}

impl std::fmt::Debug for Control<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Control")
            .field("cancel", &self.cancel)
            .field("also", &self.also)
            .field("progress", &self.progress.is_some())
            .finish()
    }
}

impl<'a> Control<'a> {
    /// A control that never cancels and discards progress.
    pub const fn new() -> Self {
        Self {
            cancel: None,
            also: None,
            progress: None,
        }
    }

    /// Stop when `flag` becomes true. A second call adds a second flag (stop
    /// when either rises); a third replaces the second.
    pub const fn with_cancel(mut self, flag: &'a AtomicBool) -> Self {
        if self.cancel.is_none() {
            self.cancel = Some(flag);
        } else {
            self.also = Some(flag);
        }
        self
    }

    /// Send progress fractions in `[0, 1]` to `sink`.
    pub fn with_progress(mut self, sink: &'a (dyn Fn(f64) + Sync)) -> Self {
        self.progress = Some(sink);
        self
    }

    /// The same cancel flags without the progress sink: for the inner
    /// solves of a computation that reports its own progress (many solves
    /// run in parallel, each would otherwise report its own fraction).
    pub const fn cancel_only(&self) -> Self {
        Self {
            cancel: self.cancel,
            also: self.also,
            progress: None,
        }
    }

    /// True once the caller asked the computation to stop.
    #[inline]
    pub fn is_cancelled(&self) -> bool {
        self.cancel.is_some_and(|c| c.load(Ordering::Relaxed))
            || self.also.is_some_and(|c| c.load(Ordering::Relaxed))
    }

    /// Reports a progress fraction, clamped to `[0, 1]`.
    #[inline]
    pub fn report(&self, fraction: f64) {
        if let Some(sink) = self.progress {
            sink(fraction.clamp(0.0, 1.0));
        }
    }
}
