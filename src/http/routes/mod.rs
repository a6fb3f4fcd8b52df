//! Endpoints, one module per group.
//!
//! * [`health`]: `/healthz`, `/readyz`, `/metrics`.
//! * [`datasets`]: `/v1/datasets` upload, metadata, data, delete.
//! * [`grid`]: `POST /v1/grid/distance`.
//! * [`docs`]: `/openapi.json` and the Swagger UI at `/docs`.
//! * [`jobs`]: `/v1/jobs`: durable background jobs of any operation.

pub mod datasets;
pub mod docs;
pub mod grid;
pub mod health;
pub mod jobs;
