//! `POST /v1/grid/group`: perceptual grouping of key points into contours
//! by minimal paths (the generic synchronous path over [`GridGroupRequest`]).

use std::time::Instant;

use axum::extract::State;
use axum::Json;
use serde::Serialize;
use utoipa::ToSchema;

use super::grid::DatasetRef;
use crate::http::extract::ApiJson;
use crate::http::operation::respond;
use crate::http::AppState;
use crate::ops::grid_group::GridGroupRequest;
use crate::problem::ApiError;

/// Answer of `POST /v1/grid/group`.
#[derive(Debug, Serialize, ToSchema)]
pub struct GroupResponse {
    /// Every pair of key points whose geodesic Voronoi cells touch: `pair`
    /// (the two key points, smaller first), `saddle` (index coordinates
    /// `[row, column]` of the point where their fronts meet), `geodesic_length`
    /// (`U_i + U_j` there: the geodesic distance between them), `kept`, and for a
    /// kept link `path` (the minimal path from `pair[0]` through the saddle
    /// to `pair[1]`, index coordinates) and `euclidean_length` (its polyline's length).
    pub links: Vec<serde_json::Value>,
    /// The connected components of the kept links: `key_points` (in chain
    /// order), `links` (indices into `links`), `closed`, `branched` (a point
    /// with more than two links, only with `max_links > 2`), `polyline` (the
    /// paths joined in order, index coordinates; null when branched).
    pub contours: Vec<serde_json::Value>,
    /// Key points in no contour (clutter).
    pub isolated: Vec<usize>,
    /// The contours as a GeoJSON FeatureCollection of LineStrings, positions
    /// `[x, y] = [column, row] × spacing`.
    pub geojson: serde_json::Value,
    /// The geodesic Voronoi cell of each pixel (int32: the index of its key
    /// point, -1 where not reached).
    pub labels: DatasetRef,
    /// The distance to the nearest key point (f64, +inf where not reached).
    pub distance: DatasetRef,
    /// `key_points`, `candidates` (links), `kept`, `contours`, `closed`,
    /// `isolated`, `typical_cost` (median of the key points' cheapest link),
    /// `path_failures`, `anisotropic`, `spread` (σ used), `seconds`,
    /// `queue_seconds`.
    pub stats: serde_json::Value,
}

/// Perceptual grouping by minimal paths.
#[utoipa::path(
    post,
    path = "/v1/grid/group",
    tag = "grid",
    summary = "Group key points into contours by minimal paths (perceptual grouping)",
    description = "Computes the geodesic Voronoi diagram of the key points under the cost W (one \
multi-source fast marching), the saddle point of every pair of adjacent cells (where U is smallest \
on their common boundary: U_i + U_j there is the geodesic distance between the two points), and the \
minimal path through it. The cheap links are kept: each key point keeps at most `max_links` (mutually), \
within `ratio` of its own cheapest link and `relative` of the typical one (and under `max_cost`). The \
contours are the connected components, returned as ordered chains of key points with their polylines, \
`closed` when a chain closes on itself; isolated points (clutter) are left out. With `orientations` \
(one tangent angle per key point) the metric is a tensor field up to `anisotropy` times cheaper along \
the interpolated tangents (Bougleux, Peyré and Cohen), solved by anisotropic fast marching, so that \
links follow the tangents. Cohen, JMIV 2001; monograph section 4.7.",
    request_body = GridGroupRequest,
    responses(
        (status = 200, description = "The key points were grouped.", body = GroupResponse),
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
pub async fn group(
    State(state): State<AppState>,
    ApiJson(request): ApiJson<GridGroupRequest>,
) -> Result<Json<serde_json::Value>, ApiError> {
    let doc = respond(&state, Box::new(request), Instant::now()).await?;
    Ok(Json(serde_json::Value::Object(doc)))
}
