//! `POST /v1/grid/tomography` and `POST /v1/grid/fit-metric`: the inverse
//! problems over the adjoint of fast marching (the generic synchronous path
//! over [`GridTomographyRequest`] and [`GridFitMetricRequest`]). Both are
//! long runs: `POST /v1/jobs` with their operation name runs them in the
//! background with progress.

use std::time::Instant;

use axum::extract::State;
use axum::Json;
use serde::Serialize;
use utoipa::ToSchema;

use super::grid::DatasetRef;
use crate::http::extract::ApiJson;
use crate::http::operation::respond;
use crate::http::AppState;
use crate::ops::grid_fit_metric::GridFitMetricRequest;
use crate::ops::grid_tomography::GridTomographyRequest;
use crate::problem::ApiError;

/// Answer of `POST /v1/grid/tomography`.
#[derive(Debug, Serialize, ToSchema)]
pub struct TomographyResponse {
    /// The recovered cost (slowness) `W` per cell (f64).
    pub cost: DatasetRef,
    /// The best constant cost, the start.
    pub constant_cost: f64,
    /// The bounds `[min_cost, max_cost]` used.
    pub bounds: Vec<f64>,
    /// `constant` (the misfit `½ Σ (U − T)²` of the best constant map),
    /// `final`, and `history` (one value per iterate, the constant first;
    /// never increasing).
    pub misfit: serde_json::Value,
    /// The objective (misfit plus smoothness) per iterate.
    pub objective: Vec<f64>,
    /// Descent steps taken.
    pub iterations: usize,
    /// `max_iterations`, `tolerance`, `stationary` or `line_search`.
    pub stop: String,
    /// `sqrt(2 misfit / count)`: the root mean square time residual.
    pub rms_residual: f64,
    /// The recovered map's travel times, one row per source.
    pub predicted: Vec<Vec<f64>>,
    /// `cells`, `sources`, `receivers`, `solves` (forward solves), `seconds`, `queue_seconds`.
    pub stats: serde_json::Value,
}

/// Travel-time tomography.
#[utoipa::path(
    post,
    path = "/v1/grid/tomography",
    tag = "grid",
    summary = "Recover a slowness map from travel times (first-arrival tomography)",
    description = "Minimises ½ Σ_s Σ_r (U_s(y_r) − T_sr)² + (α/2) ‖∇W‖² over the cost W in \
[min_cost, max_cost], U_s the first- or second-order unfactored fast-marching distance from \
source s, starting from the best constant map (closed form, by the homogeneity of U in W). The \
gradient is the discrete adjoint of fast marching (one forward solve and one adjoint sweep per \
source, sources in parallel); the descent is the spectral projected gradient with a monotone \
backtracking line search, so the misfit never increases. A long run: submit it as a job \
(`POST /v1/jobs` with `\"operation\": \"grid.tomography\"`) to follow its progress.",
    request_body = GridTomographyRequest,
    responses(
        (status = 200, description = "The map was recovered.", body = TomographyResponse),
        (status = 400, response = crate::http::openapi::BadRequest),
        (status = 413, response = crate::http::openapi::PayloadTooLarge),
        (status = 415, response = crate::http::openapi::UnsupportedMediaType),
        (status = 422, response = crate::http::openapi::Unprocessable),
        (status = 500, response = crate::http::openapi::InternalError),
        (status = 503, response = crate::http::openapi::Busy),
        (status = 504, response = crate::http::openapi::DeadlineExceeded),
        (status = 507, response = crate::http::openapi::InsufficientStorage),
    )
)]
pub async fn tomography(
    State(state): State<AppState>,
    ApiJson(request): ApiJson<GridTomographyRequest>,
) -> Result<Json<serde_json::Value>, ApiError> {
    let doc = respond(&state, Box::new(request), Instant::now()).await?;
    Ok(Json(serde_json::Value::Object(doc)))
}

/// Answer of `POST /v1/grid/fit-metric`.
#[derive(Debug, Serialize, ToSchema)]
pub struct FitMetricResponse {
    /// The fitted cost `W` per cell (f64).
    pub cost: DatasetRef,
    /// The fitted metric as a `cost.design` section (`kind`, `value` in the
    /// image's units, `power`, `epsilon`, `sigma`).
    pub design: serde_json::Value,
    /// The fitted reference `c` on the image's `[0, 1]` scale.
    pub reference: f64,
    /// The fitted (or kept) exponent `p`.
    pub power: f64,
    /// `initial`, `final`, `history` (one value per iterate; never increasing).
    pub loss: serde_json::Value,
    /// Descent steps taken.
    pub iterations: usize,
    /// `max_iterations`, `tolerance`, `stationary` or `line_search`.
    pub stop: String,
    /// Per example: `loss_before`, `loss_after`, `before` and `after`
    /// (`mean` and `hausdorff` distances in index units between the example
    /// and the minimal path between its ends), `path` (the fitted metric's
    /// minimal path, index coordinates, start first).
    pub examples: Vec<serde_json::Value>,
    /// `cells`, `seconds`, `queue_seconds`.
    pub stats: serde_json::Value,
}

/// Metric fitting to example paths.
#[utoipa::path(
    post,
    path = "/v1/grid/fit-metric",
    tag = "grid",
    summary = "Fit an intensity metric so that its minimal paths follow example paths",
    description = "Fits the reference value c (and, with `fit_power`, the exponent p) of the \
intensity metric W = ε + |f − c|^p (f the image mapped to [0, 1] and smoothed by `sigma`; ε fixed, \
which fixes the scale) by minimising the structured margin L = Σ_k [∫_{γ_k} W ds − U^{(k)}(end_k)] \
/ length_k, the excess of each example's cost over the minimal cost between its ends (0 iff each \
example is a minimal path). The gradient is the integral of ∂W/∂θ along the example minus the \
discrete adjoint of fast marching. Reports the loss per step, the fitted `design` (usable as \
`cost.design`), and per example the mean and Hausdorff distances to the minimal path before and \
after.",
    request_body = GridFitMetricRequest,
    responses(
        (status = 200, description = "The metric was fitted.", body = FitMetricResponse),
        (status = 400, response = crate::http::openapi::BadRequest),
        (status = 404, response = crate::http::openapi::NotFound),
        (status = 413, response = crate::http::openapi::PayloadTooLarge),
        (status = 415, response = crate::http::openapi::UnsupportedMediaType),
        (status = 422, response = crate::http::openapi::Unprocessable),
        (status = 500, response = crate::http::openapi::InternalError),
        (status = 503, response = crate::http::openapi::Busy),
        (status = 504, response = crate::http::openapi::DeadlineExceeded),
        (status = 507, response = crate::http::openapi::InsufficientStorage),
    )
)]
pub async fn fit_metric(
    State(state): State<AppState>,
    ApiJson(request): ApiJson<GridFitMetricRequest>,
) -> Result<Json<serde_json::Value>, ApiError> {
    let doc = respond(&state, Box::new(request), Instant::now()).await?;
    Ok(Json(serde_json::Value::Object(doc)))
}
