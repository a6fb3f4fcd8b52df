//! `/v1/points/*`: point clouds given as `N × D` array datasets.

use std::time::Instant;

use axum::extract::State;
use axum::Json;
use serde::Serialize;
use serde_json::Value;
use utoipa::ToSchema;

use super::grid::DatasetRef;
use super::mesh::take_ref;
use crate::http::extract::ApiJson;
use crate::http::operation::respond;
use crate::http::AppState;
use crate::ops::points_isomap::PointsIsomapRequest;
use crate::problem::ApiError;

/// Answer of `POST /v1/points/isomap`.
#[derive(Debug, Serialize, ToSchema)]
pub struct IsomapResponse {
    /// The embedding, `N × dimensions` f64, rows in the input's order.
    pub embedding: DatasetRef,
    /// `k`, `dimensions`, `residual_variance` (1 − ρ² of graph and embedded
    /// distances), `explained_variance`, `eigenvalues`, `landmarks`,
    /// `edges`, `stats`.
    #[serde(flatten)]
    #[schema(value_type = Object)]
    pub details: serde_json::Map<String, Value>,
}

/// `POST /v1/points/isomap`.
#[utoipa::path(
    post,
    path = "/v1/points/isomap",
    tag = "points",
    summary = "Isomap embedding of a point cloud",
    description = "Geodesic distances of the points as shortest paths in their symmetric k-nearest-neighbour \
graph, embedded by classical MDS (all pairs, up to 5000 points) or landmark MDS (`landmarks` farthest-point \
landmarks; larger clouds get a 413 naming `landmarks`). A graph in several pieces gets a 422 naming `k`.",
    request_body(content((PointsIsomapRequest = "application/json"))),
    responses(
        (status = 200, description = "Computed and stored.", body = IsomapResponse),
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
pub async fn isomap(
    State(state): State<AppState>,
    ApiJson(request): ApiJson<PointsIsomapRequest>,
) -> Result<Json<IsomapResponse>, ApiError> {
    let mut details = respond(&state, Box::new(request), Instant::now()).await?;
    let embedding = take_ref(&mut details, "embedding")?;
    Ok(Json(IsomapResponse { embedding, details }))
}
