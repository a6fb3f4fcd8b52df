//! The short pass of the fuzzers in the normal `cargo test`: every saved
//! input of every target (`fuzz/corpus/<target>/`, the minimised AFL
//! queues and the seeds, and `fuzz/regressions/<target>/`, the inputs that
//! once crashed or hung) is run through the same entry point the AFL target
//! calls ([`geodex::fuzzing`]), and none may panic. No AFL is needed.
#![cfg(feature = "server")]

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::Path;
use std::time::{Duration, Instant};

use geodex::fuzzing::TARGETS;

/// The files under `fuzz/<kind>/<target>/`, sorted.
fn inputs(kind: &str, target: &str) -> Vec<std::path::PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("fuzz")
        .join(kind)
        .join(target);
    let Ok(entries) = std::fs::read_dir(&dir) else {
        return Vec::new();
    };
    let mut files: Vec<_> = entries
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.is_file())
        .collect();
    files.sort();
    files
}

#[test]
fn every_saved_input_runs_without_a_panic() {
    // The messages of caught panics are collected here, not printed.
    let quiet = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    let mut failures = Vec::new();
    let mut slowest = (Duration::ZERO, String::new());
    let mut count = 0;
    for &(target, run) in TARGETS {
        let corpus = inputs("corpus", target);
        assert!(!corpus.is_empty(), "fuzz/corpus/{target}/ is empty");
        for path in corpus.iter().chain(&inputs("regressions", target)) {
            let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            let name = format!("{target}: {}", path.display());
            let start = Instant::now();
            let outcome = catch_unwind(AssertUnwindSafe(|| run(&bytes)));
            let took = start.elapsed();
            if took > slowest.0 {
                slowest = (took, name.clone());
            }
            if let Err(panic) = outcome {
                let message = panic
                    .downcast_ref::<String>()
                    .cloned()
                    .or_else(|| panic.downcast_ref::<&str>().map(|s| (*s).to_string()))
                    .unwrap_or_default();
                failures.push(format!("{name}: {message}"));
            }
            count += 1;
        }
    }
    std::panic::set_hook(quiet);
    eprintln!(
        "{count} inputs replayed; slowest {:?} ({})",
        slowest.0, slowest.1
    );
    assert!(
        failures.is_empty(),
        "{} of {count} saved fuzz inputs panicked:\n{}",
        failures.len(),
        failures.join("\n")
    );
}
