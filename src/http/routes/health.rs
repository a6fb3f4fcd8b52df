//! Liveness, readiness and metrics. None of them touches the solver pool.

use axum::extract::State;
use axum::http::{header, StatusCode};
use axum::response::IntoResponse;
use axum::Json;
use serde::Serialize;
use utoipa::ToSchema;

use crate::http::AppState;
use crate::problem::ApiError;

/// Liveness answer.
#[derive(Debug, Serialize, ToSchema)]
pub struct Health {
    /// Always `ok`.
    pub status: &'static str,
}

/// Readiness answer.
#[derive(Debug, Serialize, ToSchema)]
pub struct Ready {
    /// `ready`.
    pub status: &'static str,
    /// Pool threads. The details below are shown when auth is off, or to an
    /// admin key.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pool_threads: Option<usize>,
    /// Admission capacity (waiting + running solves).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pool_capacity: Option<usize>,
    /// Solves waiting for a thread.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub queued: Option<usize>,
    /// Solves running.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub running: Option<usize>,
    /// Bytes of stored datasets.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub storage_used_bytes: Option<u64>,
    /// Storage quota in bytes.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub storage_quota_bytes: Option<u64>,
    /// The solves' and uploads' memory budget in bytes (`--solve-memory-bytes`):
    /// admission is by estimated peak memory against it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub solve_memory_budget_bytes: Option<u64>,
    /// Estimated peak bytes of the solves and decodes admitted now.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub solve_memory_held_bytes: Option<u64>,
    /// The in-memory cache's budget in bytes (`--cache-bytes`): decoded
    /// arrays and meshes, heat factorisations, designed costs and distance maps.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cache_budget_bytes: Option<u64>,
    /// Bytes the cache holds now.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cache_bytes: Option<u64>,
}

/// Liveness: the process answers. Instant; never touches the pool or storage.
#[utoipa::path(
    get,
    path = "/healthz",
    tag = "operations",
    summary = "Liveness probe",
    description = "Answers 200 as long as the process serves HTTP. It never waits for the solver pool or storage.",
    responses(
        (status = 200, description = "The process is alive.", body = Health, example = json!({"status": "ok"})),
        (status = 500, response = crate::http::openapi::InternalError),
    )
)]
pub async fn healthz() -> Json<Health> {
    Json(Health { status: "ok" })
}

/// Readiness: storage is usable, the service is not draining, and the pool
/// has a free admission slot.
#[utoipa::path(
    get,
    path = "/readyz",
    tag = "operations",
    summary = "Readiness probe",
    description = "Answers 200 when the solver pool can admit a solve and the dataset storage is usable (with the pool's, the storage's and the memory budgets' figures when auth is off or the key is an admin's), and 503 while the service drains after SIGTERM, when storage is unusable, or while every admission slot of the pool is taken (a long or stuck solve: new work would be refused).",
    responses(
        (status = 200, description = "Ready to take requests.", body = Ready, example = json!({
            "status": "ready", "pool_threads": 8, "pool_capacity": 16, "queued": 0, "running": 1,
            "storage_used_bytes": 1048576, "storage_quota_bytes": 8589934592u64,
            "solve_memory_budget_bytes": 25769803776u64, "solve_memory_held_bytes": 402653184,
            "cache_budget_bytes": 2147483648u64, "cache_bytes": 16777216
        })),
        (status = 500, response = crate::http::openapi::InternalError),
        (status = 503, response = crate::http::openapi::Busy),
    )
)]
pub async fn readyz(State(state): State<AppState>) -> Result<Json<Ready>, ApiError> {
    if state.is_draining() {
        return Err(ApiError::busy("the service is shutting down", 5));
    }
    let store = state.store.clone();
    let usable = tokio::task::spawn_blocking(move || store.is_usable())
        .await
        .unwrap_or(false);
    if !usable {
        return Err(ApiError::busy("the dataset storage is not usable", 5));
    }
    let (queued, running, capacity) = (
        state.pool.waiting(),
        state.pool.running(),
        state.pool.capacity(),
    );
    if queued + running >= capacity {
        // A load balancer should send new work elsewhere: this replica
        // would answer it 503 (a stuck or long solve holds every slot).
        return Err(ApiError::busy(
            format!(
                "the solver pool is full: {running} running and {queued} waiting of {capacity} \
                 admitted at once"
            ),
            1,
        ));
    }
    if !crate::http::auth::caller().admin {
        return Ok(Json(Ready {
            status: "ready",
            pool_threads: None,
            pool_capacity: None,
            queued: None,
            running: None,
            storage_used_bytes: None,
            storage_quota_bytes: None,
            solve_memory_budget_bytes: None,
            solve_memory_held_bytes: None,
            cache_budget_bytes: None,
            cache_bytes: None,
        }));
    }
    let (used, quota) = state.store.usage();
    let (memory_budget, memory_held) = state.pool.memory();
    let cache = state.store.memory_cache();
    Ok(Json(Ready {
        status: "ready",
        pool_threads: Some(state.pool.threads()),
        pool_capacity: Some(state.pool.capacity()),
        queued: Some(queued),
        running: Some(running),
        storage_used_bytes: Some(used),
        storage_quota_bytes: Some(quota),
        solve_memory_budget_bytes: Some(memory_budget),
        solve_memory_held_bytes: Some(memory_held),
        cache_budget_bytes: Some(cache.budget() as u64),
        cache_bytes: Some(cache.bytes() as u64),
    }))
}

/// Prometheus metrics in the text exposition format.
#[utoipa::path(
    get,
    path = "/metrics",
    tag = "operations",
    summary = "Prometheus metrics",
    description = "Request latency by route and status (`geodex_http_request_duration_seconds`), solve time by operation (`geodex_solve_seconds`), pool queue depth (`geodex_pool_queue_depth`), solves in flight (`geodex_pool_in_flight`) and refusals (`geodex_pool_rejected_total`).",
    responses(
        (status = 200, description = "Metrics in the Prometheus text format.", body = String, content_type = "text/plain",
            example = json!("# TYPE geodex_pool_in_flight gauge\ngeodex_pool_in_flight 1\n")),
        (status = 500, response = crate::http::openapi::InternalError),
    )
)]
pub async fn metrics(State(state): State<AppState>) -> impl IntoResponse {
    (
        StatusCode::OK,
        [(header::CONTENT_TYPE, "text/plain; version=0.0.4")],
        state.metrics.render(),
    )
}
