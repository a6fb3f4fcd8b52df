//! Endpoints, one module per group.
//!
//! * [`health`]: `/healthz`, `/readyz`, `/metrics`.
//! * [`datasets`]: `/v1/datasets` upload, metadata, data, delete.
//! * [`grid`]: `POST /v1/grid/distance`.
//! * [`mesh`]: `POST /v1/mesh/{distance,voronoi,paths,sample}`.
//! * [`docs`]: `/openapi.json` and the Swagger UI at `/docs`.

pub mod datasets;
pub mod docs;
pub mod grid;
pub mod health;
pub mod mesh;
