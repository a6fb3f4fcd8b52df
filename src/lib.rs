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
//! * [`jobs`]: durable background jobs (SQLite or PostgreSQL queue, results
//!   in an object store).
//! * [`http`]: the axum router, problem+json errors, the OpenAPI contract.
//! * [`app`], [`config`], [`telemetry`]: start-up, settings and logs.
//! * [`cli`]: the `geodex` command (serve, distance, bench).

pub mod app;
pub mod cli;
pub mod config;
pub mod datasets;
pub mod http;
pub mod io;
pub mod jobs;
pub mod numerics;
pub mod ops;
pub mod pool;
pub mod problem;
pub mod runner;
pub mod telemetry;
