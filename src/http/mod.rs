//! The HTTP layer: router, problem+json errors, extractors, the OpenAPI contract.
//!
//! Handlers only decode, validate, call an operation on the solver pool and
//! encode; the work itself lives in [`crate::ops`], [`crate::datasets`] and
//! [`crate::pool`].
//!
//! * [`error`]: [`error::Problem`] (RFC 9457) and [`error::ApiError`].
//! * [`auth`]: API keys, tenants, the browser-origin check, rate limits.
//! * [`extract`]: extractors whose rejections are problems.
//! * [`openapi`]: document metadata and reusable error responses.
//! * [`operation`]: the generic synchronous path of an operation (load inputs, run on the pool, store outputs).
//! * [`layers`]: middleware (request metrics, the tower stack).
//! * [`server`]: the accept loop (header and body timeouts, the connection cap).
//! * [`routes`]: one module per group of endpoints.

pub mod auth;
pub mod error;
pub mod extract;
pub mod layers;
pub mod openapi;
pub mod operation;
pub mod routes;
pub mod server;

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use metrics_exporter_prometheus::PrometheusHandle;
use utoipa::OpenApi;
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

use crate::datasets::DatasetStore;
use crate::io::Limits;
use crate::ops::OpLimits;
use crate::pool::SolverPool;

/// What every handler can reach.
#[derive(Debug, Clone)]
pub struct AppState {
    /// Stored datasets.
    pub store: Arc<DatasetStore>,
    /// The solver pool.
    pub pool: Arc<SolverPool>,
    /// Limits of operations.
    pub op_limits: OpLimits,
    /// Limits of the codecs.
    pub io_limits: Limits,
    /// Deadline of one solve.
    pub solve_timeout: Duration,
    /// Raised on SIGTERM / Ctrl-C: `/readyz` answers 503.
    pub draining: Arc<AtomicBool>,
    /// The Prometheus registry.
    pub metrics: PrometheusHandle,

    /// Runs every operation (on `pool`, against `op_limits`).
    pub runner: crate::runner::Runner,

    /// The durable job queue.
    pub jobs: Arc<crate::jobs::Jobs>,

    /// Shape collections, in the jobs' database.
    pub collections: Arc<crate::collections::Collections>,

    /// API keys (when auth is on), rate limits, allowed browser origins.
    pub auth: Arc<auth::Auth>,
}

impl AppState {
    /// True once shutdown began.
    pub fn is_draining(&self) -> bool {
        self.draining.load(Ordering::Relaxed)
    }
}

/// The routes that the OpenAPI document describes.
pub fn api_router() -> OpenApiRouter<AppState> {
    OpenApiRouter::with_openapi(openapi::ApiDoc::openapi())
        .routes(routes!(routes::datasets::upload, routes::datasets::list))
        .routes(routes!(
            routes::datasets::get_meta,
            routes::datasets::delete
        ))
        .routes(routes!(routes::datasets::get_data))
        .routes(routes!(routes::grid::distance))
        .routes(routes!(routes::segment::edt))
        .routes(routes!(routes::segment::segment))
        .routes(routes!(routes::segment::skeleton))
        .routes(routes!(routes::segment::offset))
        .routes(routes!(routes::segment::plan))
        .routes(routes!(routes::segment::sample))
        .routes(routes!(routes::segment::mesh))
        .routes(routes!(routes::segment::domain_mesh))
        .routes(routes!(routes::shading::shape_from_shading))
        .routes(routes!(routes::shape::shape_embed))
        .routes(routes!(routes::gradient::cost_gradient))
        .routes(routes!(routes::inverse::tomography))
        .routes(routes!(routes::inverse::fit_metric))
        .routes(routes!(routes::group::group))
        .routes(routes!(routes::metric::metric))
        .routes(routes!(routes::paths::paths))
        .routes(routes!(routes::tensor::tensor_distance))
        .routes(routes!(routes::tensor::tensor_metric))
        .routes(routes!(routes::mesh::distance))
        .routes(routes!(routes::mesh::voronoi))
        .routes(routes!(routes::mesh::curvature))
        .routes(routes!(routes::mesh::paths))
        .routes(routes!(routes::mesh::sample))
        .routes(routes!(routes::mesh::remesh))
        .routes(routes!(routes::mesh::distance_matrix))
        .routes(routes!(routes::mesh::embed))
        .routes(routes!(routes::mesh::descriptor))
        .routes(routes!(routes::mesh::correspond))
        .routes(routes!(routes::points::isomap))
        .routes(routes!(routes::health::healthz))
        .routes(routes!(routes::health::readyz))
        .routes(routes!(routes::health::metrics))
        .routes(routes!(routes::jobs::submit, routes::jobs::list))
        .routes(routes!(routes::jobs::get))
        .routes(routes!(routes::jobs::cancel))
        .routes(routes!(routes::jobs::result))
        .routes(routes!(
            routes::collections::create_collection,
            routes::collections::list_collections
        ))
        .routes(routes!(
            routes::collections::get_collection,
            routes::collections::delete_collection
        ))
        .routes(routes!(routes::collections::add_shape))
        .routes(routes!(routes::collections::query_collection))
}

/// The complete application: API routes, `/openapi.json`, `/docs`, the
/// playground, the fallback and every middleware layer.
pub fn router(state: AppState, settings: &crate::config::ServeArgs) -> axum::Router {
    let (api, doc) = api_router().split_for_parts();
    let doc = openapi::clients::for_clients(doc);
    let app = api
        .merge(routes::docs::router(doc))
        .merge(routes::playground::router())
        .fallback(error::fallback)
        .with_state(state.clone());
    layers::apply(app, settings, state.auth)
}
