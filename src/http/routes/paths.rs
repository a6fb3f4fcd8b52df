//! `POST /v1/grid/paths`: minimal paths (end points, way-points, closed
//! contours) by gradient descent of distance maps, with a cache of maps so
//! that a front end can follow the mouse.

use std::collections::HashMap;
use std::time::Instant;

use axum::extract::State;
use axum::http::header;
use axum::response::{IntoResponse, Response};
use axum::Json;
use serde::Serialize;
use utoipa::ToSchema;

use crate::http::extract::ApiJson;
use crate::http::operation::{add_timing, run};
use crate::http::AppState;
use crate::ops::grid_paths::{ChainOut, GridPathsRequest, PathFormat, PathOut, PathsStats};
use crate::problem::ApiError;
use crate::runner::Ran;

/// Statistics of a paths request.
#[derive(Debug, Serialize, ToSchema)]
pub struct PathsRequestStats {
    /// What the operation reported.
    #[serde(flatten)]
    pub run: PathsStats,
    /// Seconds the request waited for a pool thread.
    pub queue_seconds: f64,
    /// Seconds from the start of the handler to the answer.
    pub total_seconds: f64,
}

/// Answer of `POST /v1/grid/paths` (format `json`).
#[derive(Debug, Serialize, ToSchema)]
#[schema(example = json!({
    "paths": [{"index": 0, "source": 0, "end": [20.0, 5.0], "points": [[2.0, 3.0], [2.4, 3.1], [20.0, 5.0]],
        "world": [[2.0, 3.0], [2.4, 3.1], [20.0, 5.0]], "geodesic_length": 18.1, "euclidean_length": 18.1,
        "continuous_steps": 36, "discrete_steps": 0}],
    "stats": {"cells": 4096, "cost_cached": true, "cost_seconds": 0.0,
        "maps": [{"cached": true, "frozen": 1200, "stop": "targets_reached", "solve_seconds": 0.0}],
        "descent_seconds": 0.0004, "queue_seconds": 0.00002, "total_seconds": 0.0009}
}))]
pub struct PathsResponse {
    /// One path per end point (or per leg), from the source to the end.
    pub paths: Vec<PathOut>,
    /// The joined path through the way-points, or the closed contour.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub chain: Option<ChainOut>,
    /// Timings, cache use and solver statistics.
    pub stats: PathsRequestStats,
}

/// Extracts minimal paths.
#[utoipa::path(
    post,
    path = "/v1/grid/paths",
    tag = "grid",
    summary = "Minimal paths: end points, way-points, closed contours (livewire)",
    description = "Computes the distance map U of the cost from the sources (stopped once the end points are \
frozen, unless `early_stop` is false) and extracts each minimal path by gradient descent of U \
(dγ/dt = −∇U/|∇U|, ∇U interpolated from upwind/centred differences, Runge–Kutta 4 steps of at most half a \
cell; a discrete steepest-descent step on the 8 / 26 neighbours where the gradient vanishes or is undefined; \
never through a wall). Give `sources` with `ends` (one path per end point), or `waypoints` (the chain of \
minimal paths between consecutive points), or `contour` (a closed contour through the points). \
The cost may be designed from an image (`cost.design`: intensity, edges, vesselness). \
Designed costs and distance maps are kept in a bounded cache keyed by the inputs, so a later request with \
the same cost and sources and new end points only runs the descents (`stats.maps[].cached`). \
Paths are ordered from the source to the end point, in index coordinates (axis 0 first) and in world \
coordinates (index × spacing). `format: geojson` answers `application/geo+json` (LineStrings, positions \
[x, y] = [axis 1, axis 0] × spacing); `format: svg` answers `image/svg+xml`, the paths over a grey PNG of \
the image (2D only).",
    request_body = GridPathsRequest,
    responses(
        (status = 200, description = "The paths.",
            content(
                (PathsResponse = "application/json"),
                (serde_json::Value = "application/geo+json"),
                (String = "image/svg+xml"),
            )
        ),
        (status = 400, response = crate::http::openapi::BadRequest),
        (status = 404, response = crate::http::openapi::NotFound),
        (status = 413, response = crate::http::openapi::PayloadTooLarge),
        (status = 415, response = crate::http::openapi::UnsupportedMediaType),
        (status = 422, response = crate::http::openapi::Unprocessable),
        (status = 500, response = crate::http::openapi::InternalError),
        (status = 503, response = crate::http::openapi::Busy),
        (status = 504, response = crate::http::openapi::DeadlineExceeded),
    )
)]
pub async fn paths(
    State(state): State<AppState>,
    ApiJson(request): ApiJson<GridPathsRequest>,
) -> Result<Response, ApiError> {
    let started = Instant::now();
    let format = request.format;
    let Ran { output, timing } = run(&state, Box::new(request), HashMap::new()).await?;
    let mut doc = output.document;
    match format {
        PathFormat::Geojson => {
            let body = doc.get("geojson").cloned().unwrap_or_default().to_string();
            Ok(([(header::CONTENT_TYPE, "application/geo+json")], body).into_response())
        }
        PathFormat::Svg => {
            let body = doc
                .get("svg")
                .and_then(|s| s.as_str())
                .unwrap_or_default()
                .to_string();
            Ok(([(header::CONTENT_TYPE, "image/svg+xml")], body).into_response())
        }
        PathFormat::Json => {
            if let serde_json::Value::Object(map) = &mut doc {
                add_timing(map, &timing, started);
            }
            Ok(Json(doc).into_response())
        }
    }
}
