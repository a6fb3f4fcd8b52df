//! The `geodex` binary: see [`geodex::cli`].

/// jemalloc, so that memory freed after a burst (a storm of connections, a
/// large solve) goes back to the system: with glibc's malloc the process kept
/// its peak (tests/hostile/hostile.py, slowloris: 19 MB idle, 83 MB under
/// load, still 83 MB 30 s later).
#[cfg(feature = "server")]
#[global_allocator]
static ALLOCATOR: tikv_jemallocator::Jemalloc = tikv_jemallocator::Jemalloc;

fn main() -> std::process::ExitCode {
    // jemalloc purges dirty pages on its decay clock (10 s) only when the
    // process allocates, unless its background thread does it: an idle
    // server after a burst would keep its peak. Best effort: a failure
    // only means the purge waits for the next allocation.
    #[cfg(feature = "server")]
    let _ = tikv_jemalloc_ctl::background_thread::write(true);
    geodex::cli::main()
}
