//! `POST /v1/grid/tensor-distance` and `POST /v1/grid/tensor-metric`: the
//! anisotropic (Riemannian) operations, thin handlers over
//! [`crate::http::operation`].

use std::time::Instant;

use axum::extract::State;
use axum::Json;
use serde::Serialize;
use serde_json::Value;
use utoipa::ToSchema;

use super::grid::DatasetRef;

use crate::http::extract::ApiJson;
use crate::http::operation::respond;
use crate::http::AppState;
use crate::ops::grid_tensor_distance::{GridTensorDistanceRequest, TensorPath, TensorSolveStats};
use crate::ops::grid_tensor_metric::GridTensorMetricRequest;
use crate::problem::ApiError;

/// Statistics of a tensor distance request.
#[derive(Debug, Serialize, ToSchema)]
pub struct TensorDistanceStats {
    /// What the solver reported.
    #[serde(flatten)]
    pub solve: TensorSolveStats,
    /// Seconds the request waited for a pool thread.
    pub queue_seconds: f64,
    /// Seconds from the start of the handler to the answer.
    pub total_seconds: f64,
}

/// Answer of `POST /v1/grid/tensor-distance`.
#[derive(Debug, Serialize, ToSchema)]
pub struct TensorDistanceResponse {
    /// The distance map `U` (f64; `+inf` where not reached).
    pub distance: DatasetRef,
    /// Voronoi labels (int32; `-1` where not reached), unless `outputs.labels` is false.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub labels: Option<DatasetRef>,
    /// Freeze ranks (int64), when `outputs.frozen_order` is true.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub frozen_order: Option<DatasetRef>,
    /// Timings and solver statistics.
    pub stats: TensorDistanceStats,
    /// One minimal path per start point of `paths`, in order.
    pub paths: Vec<TensorPath>,
}

/// Statistics of a tensor field.
#[derive(Debug, Serialize, ToSchema)]
pub struct TensorMetricStats {
    /// Cells of the grid.
    pub cells: u64,
    /// Largest anisotropy ratio `sqrt(λmax/λmin)`.
    pub max_anisotropy: f64,
}

/// Answer of `POST /v1/grid/tensor-metric`.
#[derive(Debug, Serialize, ToSchema)]
pub struct TensorMetricResponse {
    /// The field: the grid's shape plus a trailing axis of 3 or 6 components (f64).
    pub tensor: DatasetRef,
    /// Statistics.
    pub stats: TensorMetricStats,
}

/// Computes a Riemannian distance map (and minimal paths) for a tensor metric.
#[utoipa::path(
    post,
    path = "/v1/grid/tensor-distance",
    tag = "grid",
    summary = "Riemannian distance map of a tensor metric",
    description = "Solves ‖∇U‖_{M⁻¹} = 1 on a 2D or 3D grid for a symmetric positive definite tensor field M \
(a displacement v costs sqrt(vᵀMv)), with U = 0 at the sources, by fast marching on adaptive stencils \
(Selling's reduction; causal and consistent for any anisotropy, cost growing like its logarithm). \
The `metric` section (the same as `grid.distance`'s) gives the field: a dataset with a trailing component axis (`components`: 3 numbers \
m00, m01, m11 per cell in 2D, 6 numbers m00, m01, m02, m11, m12, m22 in 3D), a `constant`, an `eigen` \
decomposition, `energy_anisotropy` (W and A of the seed's eq. 1.17), a `structure_tensor` design from an \
image (cheap along edges) or a `height_map` (W²(I + ∇h∇hᵀ), geodesics on a terrain). \
A tensor that is not finite or not positive definite is a 400 naming the first bad cell. \
Walls (`obstacles`) are never crossed, however wide the stencil. \
`ends` lists end points whose minimal paths (descent along −M⁻¹∇U) are returned, each from its source to its end. \
Point coordinates are in array index order (axis 0 first), in index units, with a per-axis `spacing`.",
    request_body = GridTensorDistanceRequest,
    responses(
        (status = 200, description = "The distance map (and labels, paths) were computed; arrays are stored as datasets.",
            body = TensorDistanceResponse,
            example = json!({
                "distance": {"id": "ds_0192f1b27c1e7d3a9d553c0f2b8a1e45", "url": "/v1/datasets/ds_0192f1b27c1e7d3a9d553c0f2b8a1e45",
                    "data_url": "/v1/datasets/ds_0192f1b27c1e7d3a9d553c0f2b8a1e45/data", "shape": [256, 256]},
                "labels": {"id": "ds_0192f1b27c1e7d3a9d553c0f2b8a1e46", "url": "/v1/datasets/ds_0192f1b27c1e7d3a9d553c0f2b8a1e46",
                    "data_url": "/v1/datasets/ds_0192f1b27c1e7d3a9d553c0f2b8a1e46/data", "shape": [256, 256]},
                "stats": {"cells": 65536, "frozen": 65536, "stop": "completed", "max_anisotropy": 10.0,
                    "stencil_width": 3, "solve_seconds": 0.05, "queue_seconds": 0.0001, "total_seconds": 0.07},
                "paths": [{"index": 0, "source": 0, "end": [20.0, 200.0], "points": [[128.0, 128.0], [127.6, 128.4], [20.0, 200.0]], "geodesic_length": 123.4, "euclidean_length": 129.6}]
            })
        ),
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
pub async fn tensor_distance(
    State(state): State<AppState>,
    ApiJson(request): ApiJson<GridTensorDistanceRequest>,
) -> Result<Json<Value>, ApiError> {
    let doc = respond(&state, Box::new(request), Instant::now()).await?;
    Ok(Json(Value::Object(doc)))
}

/// Builds a tensor field (a designed metric) and stores it as a dataset.
#[utoipa::path(
    post,
    path = "/v1/grid/tensor-metric",
    tag = "grid",
    summary = "Tensor field of a metric description",
    description = "Evaluates a `metric` section (the same as in `/v1/grid/tensor-distance` and `/v1/grid/distance`) and stores the field \
as an f64 dataset of the grid's shape plus a trailing axis of 3 (2D) or 6 (3D) components, reusable as \
`{\"kind\": \"components\", \"dataset\": id}`.",
    request_body = GridTensorMetricRequest,
    responses(
        (status = 200, description = "The tensor field was stored.", body = TensorMetricResponse,
            example = json!({
                "tensor": {"id": "ds_0192f1b27c1e7d3a9d553c0f2b8a1e47", "url": "/v1/datasets/ds_0192f1b27c1e7d3a9d553c0f2b8a1e47",
                    "data_url": "/v1/datasets/ds_0192f1b27c1e7d3a9d553c0f2b8a1e47/data", "shape": [64, 64, 3]},
                "stats": {"cells": 4096, "max_anisotropy": 4.36}
            })
        ),
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
pub async fn tensor_metric(
    State(state): State<AppState>,
    ApiJson(request): ApiJson<GridTensorMetricRequest>,
) -> Result<Json<Value>, ApiError> {
    let doc = respond(&state, Box::new(request), Instant::now()).await?;
    Ok(Json(Value::Object(doc)))
}
