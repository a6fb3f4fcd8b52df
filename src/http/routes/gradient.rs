//! `POST /v1/grid/cost-gradient`: the sensitivity of geodesic distances to
//! the cost of every cell (the generic synchronous path over
//! [`GridCostGradientRequest`]).

use std::time::Instant;

use axum::extract::State;
use axum::Json;
use serde::Serialize;
use utoipa::ToSchema;

use super::grid::DatasetRef;
use crate::http::extract::ApiJson;
use crate::http::operation::respond;
use crate::http::AppState;
use crate::ops::grid_cost_gradient::GridCostGradientRequest;
use crate::problem::ApiError;

/// Answer of `POST /v1/grid/cost-gradient`.
#[derive(Debug, Serialize, ToSchema)]
pub struct CostGradientResponse {
    /// `∂J/∂W` per cell (f64, the grid's shape), or `∂J/∂F` when the cost
    /// was given as a speed; 0 on walls and unreached cells.
    pub gradient: DatasetRef,
    /// The distance map of the forward solve (unless `distance: false`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub distance: Option<DatasetRef>,
    /// `kind` (`sum` or `misfit`) and `value`, the objective `J`.
    pub objective: serde_json::Value,
    /// Per target: `distance` (`U` there) and `residual` (`U − observed`, when observed).
    pub targets: serde_json::Value,
    /// `cost` or `speed`: what the gradient is taken with respect to.
    pub with_respect_to: String,
    /// `cells`, `frozen`, `stop`, `order`, `solve_seconds`, `gradient_seconds`, `seconds`, `queue_seconds`.
    pub stats: serde_json::Value,
}

/// Gradient of a geodesic distance with respect to the cost.
#[utoipa::path(
    post,
    path = "/v1/grid/cost-gradient",
    tag = "grid",
    summary = "Gradient of geodesic distances with respect to the cost (the discrete adjoint of fast marching)",
    description = "Solves the eikonal equation |∇U| = W by unfactored fast marching of order 1 or 2, \
then returns the gradient of J = Σ w_m U(y_m) (objective `sum`) or J = ½ Σ w_m (U(y_m) − T_m)² \
(objective `misfit`, T_m the observed travel times) with respect to the cost W of every cell, by one \
backward sweep over the solve's freezing order (the discrete adjoint: the exact derivative of the \
discrete solution, about the cost of one more solve). With one target of weight 1 this is the \
sensitivity of the length of the minimal path from that target to the sources. Where U is not \
differentiable (the cut locus, Voronoi boundaries) the answer is the one-sided derivative of the \
solver's choice. Bad targets (outside the grid, unreached) are 422s naming `targets[m].point`.",
    request_body = GridCostGradientRequest,
    responses(
        (status = 200, description = "The gradient was computed.", body = CostGradientResponse),
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
pub async fn cost_gradient(
    State(state): State<AppState>,
    ApiJson(request): ApiJson<GridCostGradientRequest>,
) -> Result<Json<serde_json::Value>, ApiError> {
    let doc = respond(&state, Box::new(request), Instant::now()).await?;
    Ok(Json(serde_json::Value::Object(doc)))
}
