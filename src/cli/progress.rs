//! The progress bar of a long command: a [`Watch`] handed to the runner
//! ([`crate::cli::run`]) that draws on stderr, only when stderr is a
//! terminal and only once the run has lasted a second. Otherwise it draws
//! nothing at all (pipes, files, tests).
//!
//! The solver reports fractions through [`Watch::report`], which only stores
//! the latest in an atomic (the solve's threads never wait for the
//! terminal); a drawing thread wakes after the first second, then ten times
//! a second, and shows either a bar (once a fraction came) or a spinner with
//! the elapsed time (operations that report no progress).

use std::io::IsTerminal;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{self, RecvTimeoutError, Sender};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

use crate::runner::Watch;

/// How long a run goes before anything is drawn.
const QUIET_FOR: Duration = Duration::from_secs(1);
/// How often the bar is redrawn.
const TICK: Duration = Duration::from_millis(100);
/// Steps of the bar (per mille).
const STEPS: u64 = 1000;
/// No fraction reported yet.
const NONE: u64 = u64::MAX;

/// The shared state: the cancel flag the runner wants (never raised: an
/// interrupt ends the process) and the latest fraction in per mille.
#[derive(Debug)]
struct State {
    cancel: AtomicBool,
    per_mille: AtomicU64,
}

impl Watch for State {
    fn cancel_flag(&self) -> &AtomicBool {
        &self.cancel
    }

    fn report(&self, fraction: f64) {
        if fraction.is_finite() {
            // In 0..=STEPS after the clamp, so the cast is exact.
            let v = (fraction.clamp(0.0, 1.0) * STEPS as f64).round() as u64;
            self.per_mille.store(v, Ordering::Relaxed);
        }
    }
}

/// A progress reporter for one run; [`Progress::finish`] (or dropping it)
/// clears what it drew.
#[derive(Debug)]
pub(crate) struct Progress {
    state: Arc<State>,
    /// Closing it (dropping the sender) stops the drawing thread.
    stop: Option<Sender<()>>,
    drawer: Option<JoinHandle<()>>,
}

impl Progress {
    /// A reporter for the operation `name`: draws on stderr after a second
    /// when stderr is a terminal, never otherwise.
    pub(crate) fn start(name: &str) -> Self {
        Self::start_if(name, std::io::stderr().is_terminal())
    }

    /// [`Progress::start`] with the terminal test given.
    fn start_if(name: &str, draw: bool) -> Self {
        let state = Arc::new(State {
            cancel: AtomicBool::new(false),
            per_mille: AtomicU64::new(NONE),
        });
        if !draw {
            return Self {
                state,
                stop: None,
                drawer: None,
            };
        }
        let (stop, stopped) = mpsc::channel::<()>();
        let shared = Arc::clone(&state);
        let name = name.to_string();
        let drawer = std::thread::Builder::new()
            .name("geodex-progress".into())
            .spawn(move || draw_until_stopped(&name, &shared, &stopped))
            .ok();
        Self {
            state,
            stop: Some(stop),
            drawer,
        }
    }

    /// The [`Watch`] to hand to the runner.
    pub(crate) fn watch(&self) -> Arc<dyn Watch> {
        Arc::clone(&self.state) as Arc<dyn Watch>
    }

    /// Stops drawing and clears the bar.
    pub(crate) fn finish(mut self) {
        self.stop_drawing();
    }

    fn stop_drawing(&mut self) {
        drop(self.stop.take());
        if let Some(drawer) = self.drawer.take() {
            // A panicking drawer only loses its bar.
            let _ = drawer.join();
        }
    }
}

impl Drop for Progress {
    fn drop(&mut self) {
        self.stop_drawing();
    }
}

/// The drawing thread: nothing for [`QUIET_FOR`], then a bar or a spinner
/// redrawn every [`TICK`] until the channel closes.
fn draw_until_stopped(name: &str, state: &State, stopped: &mpsc::Receiver<()>) {
    if !matches!(
        stopped.recv_timeout(QUIET_FOR),
        Err(RecvTimeoutError::Timeout)
    ) {
        return;
    }
    // The elapsed time counts the quiet second too.
    let bar = ProgressBar::with_draw_target(Some(STEPS), ProgressDrawTarget::stderr())
        .with_elapsed(QUIET_FOR);
    let spinner = ProgressStyle::with_template("{spinner} geodex {msg}: {elapsed}")
        .unwrap_or_else(|_| ProgressStyle::default_spinner());
    let barred =
        ProgressStyle::with_template("geodex {msg} [{bar:30}] {percent:>3}% {elapsed} (eta {eta})")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> ");
    bar.set_style(spinner);
    bar.set_message(name.to_string());
    let mut has_fraction = false;
    loop {
        let v = state.per_mille.load(Ordering::Relaxed);
        if v != NONE {
            if !has_fraction {
                bar.set_style(barred.clone());
                has_fraction = true;
            }
            bar.set_position(v);
        } else {
            bar.tick();
        }
        if !matches!(stopped.recv_timeout(TICK), Err(RecvTimeoutError::Timeout)) {
            break;
        }
    }
    bar.finish_and_clear();
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reports_are_stored_clamped_and_a_silent_reporter_spawns_nothing() {
        let p = Progress::start_if("grid.distance", false);
        assert!(p.drawer.is_none());
        let w = p.watch();
        assert_eq!(p.state.per_mille.load(Ordering::Relaxed), NONE);
        w.report(0.25);
        assert_eq!(p.state.per_mille.load(Ordering::Relaxed), 250);
        w.report(7.0);
        assert_eq!(p.state.per_mille.load(Ordering::Relaxed), STEPS);
        w.report(f64::NAN);
        assert_eq!(p.state.per_mille.load(Ordering::Relaxed), STEPS);
        assert!(!w.cancel_flag().load(Ordering::Relaxed));
        p.finish();
    }

    #[test]
    fn a_drawing_reporter_stops_at_once_when_the_run_ends_early() {
        let started = std::time::Instant::now();
        let p = Progress::start_if("grid.distance", true);
        p.watch().report(0.5);
        p.finish();
        assert!(started.elapsed() < QUIET_FOR, "{:?}", started.elapsed());
    }
}
