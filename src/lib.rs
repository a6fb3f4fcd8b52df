//! geodex: geodesic distances, minimal paths and segmentations for computer
//! vision and graphics, as a library, a command line and an HTTP service.
//!
//! Layers, from the inside out (see `ARCHITECTURE.md`):
//! * [`numerics`]: the numerical core (pure functions over ndarray views).
//! * [`io`]: codecs between bytes and arrays (NPY, PNG, JPEG, TIFF, NIfTI).
//! * [`ops`]: one request schema per operation and its execution, shared by
//!   the HTTP endpoints, the job queue and the command line.
//! * [`pool`]: the shared solver pool (rayon), admission control, deadlines.
//! * [`datasets`]: the dataset store (files under the data directory).
//! * [`auth`]: API keys and tenants (keys in the jobs' database).
//! * [`jobs`]: durable background jobs (SQLite or PostgreSQL queue, results
//!   in an object store).
//! * [`http`]: the axum router, problem+json errors, the OpenAPI contract.
//! * [`app`], [`config`], [`telemetry`]: start-up, settings and logs.
//! * [`cli`]: the `geodex` command (serve, distance, bench).
//! * [`problem`]: RFC 9457 problem details and the one table of their kinds,
//!   below both `http` and `jobs`.
//! * [`runner`]: the one way an operation is run (validate, load inputs,
//!   run on the pool with a deadline and cancellation).
//!
//! Everything but [`numerics`] and [`io`] is behind the default `server`
//! feature: `geodex = { version = "0.1", default-features = false }` is the
//! solvers and codecs alone, without axum, tokio, sqlx, object_store or
//! utoipa.
//!
//! No `unsafe` outside `numerics/prefetch.rs`: the crate denies the
//! `unsafe_code` lint here (and `Cargo.toml`'s `[lints]` for every target),
//! and the one prefetch hint allows it on its own block. `deny` rather than
//! `forbid`: a `forbid` cannot be lifted by an inner `#[allow]`, so it would
//! refuse that one exception too. `tests/layering.rs` checks that no other
//! file holds `unsafe` or allows the lint.

#![deny(unsafe_code)]
// No `unwrap()` outside tests: a panic must not reach a client. Set here and
// not in `Cargo.toml`'s `[lints]`, which would also apply to the integration
// tests and benches; `clippy.toml` lets the unit tests unwrap.
#![warn(clippy::unwrap_used)]

pub mod io;
pub mod numerics;

#[cfg(feature = "server")]
pub mod app;
#[cfg(feature = "server")]
pub mod auth;
#[cfg(feature = "server")]
pub mod cli;
#[cfg(feature = "server")]
pub mod collections;
#[cfg(feature = "server")]
pub mod config;
#[cfg(feature = "server")]
pub mod datasets;
/// Fuzzing entry points, shared by `fuzz/` and `tests/fuzz_corpus.rs`.
#[cfg(feature = "server")]
#[doc(hidden)]
pub mod fuzzing;
#[cfg(feature = "server")]
pub mod http;
#[cfg(feature = "server")]
pub mod jobs;
#[cfg(feature = "server")]
pub mod ops;
#[cfg(feature = "server")]
pub mod pool;
#[cfg(feature = "server")]
pub mod problem;
#[cfg(feature = "server")]
pub mod runner;
#[cfg(feature = "server")]
pub mod telemetry;
