//! `POST /v1/grid/metric`: the metric of a `cost` section (most often `W`
//! designed from an image: intensity, edges, vesselness) or of a tensor
//! `metric` section, stored as a dataset to look at before using it.

use std::time::Instant;

use axum::extract::State;
use axum::Json;
use serde::Serialize;
use utoipa::ToSchema;

use super::grid::DatasetRef;
use crate::http::extract::ApiJson;
use crate::http::operation::respond;
use crate::http::AppState;
use crate::ops::grid_metric::{GridMetricRequest, MetricStats};
use crate::problem::ApiError;

/// Answer of `POST /v1/grid/metric`.
#[derive(Debug, Serialize, ToSchema)]
pub struct MetricResponse {
    /// The cost `W` (f64, the grid's shape and spacing), or the tensor
    /// field's components (a trailing axis of 3 or 6).
    pub metric: DatasetRef,
    /// Range of `W` (or the largest anisotropy of a tensor) and the design time.
    pub stats: MetricStats,
}

/// Designs a metric from an image.
#[utoipa::path(
    post,
    path = "/v1/grid/metric",
    tag = "grid",
    summary = "Cost W designed from an image (intensity, edges, vesselness)",
    description = "Builds the cost per unit length `W` of a `cost` section (the one every grid operation takes; \
most often an image with a `design`: `{\"cost\": {\"dataset\": IMAGE, \"design\": {...}}}`), or the tensor \
field of a `metric` section, and stores it as a dataset. \
The image is first mapped affinely to [0, 1]; scales are in physical units. \
`intensity`: W = |f_σ − c|^p + ε with c given (`value`, image units), read at a point (`at`), or the brightest value. \
`edges`: with g = |∇(G_σ * f)| / max|∇(G_σ * f)|, W = 1/(ε + g^p) to follow contours (`mode: follow`) or \
W = ε + g^p so that contours are barriers (`mode: barrier`). \
`vesselness`: Frangi's multi-scale Hessian measure v ∈ [0, 1] for bright or dark tubes in 2D or 3D, W = 1/(ε + v^p). \
The same `design` section is accepted under `cost` by every grid operation \
(`\"cost\": {\"dataset\": IMAGE, \"design\": {\"kind\": \"edges\"}}`).",
    request_body = GridMetricRequest,
    responses(
        (status = 200, description = "The metric was designed and stored.", body = MetricResponse),
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
pub async fn metric(
    State(state): State<AppState>,
    ApiJson(request): ApiJson<GridMetricRequest>,
) -> Result<Json<serde_json::Value>, ApiError> {
    let doc = respond(&state, Box::new(request), Instant::now()).await?;
    Ok(Json(serde_json::Value::Object(doc)))
}
