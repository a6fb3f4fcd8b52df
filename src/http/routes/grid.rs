//! `POST /v1/grid/distance`: the geodesic distance map of a cost on a grid.

use std::collections::HashMap;
use std::sync::Arc;
use std::time::Instant;

use axum::extract::{FromRequest, Multipart, Request, State};
use axum::http::{header, HeaderMap, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::Json;
use serde::{Deserialize, Serialize};
use utoipa::{IntoParams, ToSchema};

use super::datasets::{decode_upload, format_from_content_type};
use crate::datasets::{DatasetMeta, SourceFormat};
use crate::http::extract::{ApiJson, ApiQuery};
use crate::http::operation::{add_timing, run, store_output};
use crate::http::AppState;
use crate::io::{self, Format};
use crate::ops::parse::{check_value_count, parse_json, MAX_JSON_VALUES};
use crate::ops::spec::distance::{GridDistanceRequest, SolveStats};
use crate::ops::InputArray;
use crate::problem::ApiError;
use crate::runner::Ran;

/// Id under which the `file` part of a multipart request is visible.
pub const FILE_ID: &str = "file";

/// A stored result.
#[derive(Debug, Serialize, Deserialize, ToSchema)]
pub struct DatasetRef {
    /// Dataset id.
    pub id: String,
    /// URL of its metadata.
    pub url: String,
    /// URL of its values (`?format=npy|tiff|png16|png|json`).
    pub data_url: String,
    /// Shape, axis 0 first (1D for per-vertex or per-triangle results).
    #[schema(min_items = 1, max_items = 3)]
    pub shape: Vec<usize>,
}

impl From<&DatasetMeta> for DatasetRef {
    fn from(m: &DatasetMeta) -> Self {
        let url = format!("/v1/datasets/{}", m.id);
        Self {
            id: m.id.clone(),
            data_url: format!("{url}/data"),
            url,
            shape: m.shape.clone(),
        }
    }
}

/// Statistics of a distance request.
#[derive(Debug, Serialize, ToSchema)]
pub struct DistanceStats {
    /// What the solver reported.
    #[serde(flatten)]
    pub solve: SolveStats,
    /// Seconds the request waited for a pool thread.
    pub queue_seconds: f64,
    /// Seconds from the start of the handler to the answer.
    pub total_seconds: f64,
}

/// Answer of `POST /v1/grid/distance` (JSON form).
#[derive(Debug, Serialize, ToSchema)]
#[schema(example = json!({
    "distance": {"id": "ds_0192f1b27c1e7d3a9d553c0f2b8a1e45", "url": "/v1/datasets/ds_0192f1b27c1e7d3a9d553c0f2b8a1e45",
        "data_url": "/v1/datasets/ds_0192f1b27c1e7d3a9d553c0f2b8a1e45/data", "shape": [256, 256]},
    "labels": {"id": "ds_0192f1b27c1e7d3a9d553c0f2b8a1e46", "url": "/v1/datasets/ds_0192f1b27c1e7d3a9d553c0f2b8a1e46",
        "data_url": "/v1/datasets/ds_0192f1b27c1e7d3a9d553c0f2b8a1e46/data", "shape": [256, 256]},
    "stats": {"cells": 65536, "frozen": 65536, "stop": "completed", "solve_seconds": 0.012,
        "queue_seconds": 0.0001, "total_seconds": 0.02}
}))]
pub struct DistanceResponse {
    /// The distance map `U` (f64; `+inf` where not reached).
    pub distance: DatasetRef,
    /// Voronoi labels (int32; `-1` where not reached), unless `outputs.labels` is false.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub labels: Option<DatasetRef>,
    /// Freeze ranks (int64; `-1` if never frozen), when `outputs.frozen_order` is true.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub frozen_order: Option<DatasetRef>,
    /// Timings and solver statistics.
    pub stats: DistanceStats,
}

/// The one-round-trip form of the request.
#[derive(Debug, ToSchema)]
pub struct DistanceForm {
    /// The cost (or speed) file: NPY, PNG, JPEG, TIFF or NIfTI.
    #[schema(value_type = String, format = Binary)]
    pub file: Vec<u8>,
    /// A `GridDistanceRequest` as JSON; `cost.dataset` omitted or `"file"`.
    #[schema(value_type = String, example = json!("{\"sources\": [{\"point\": [10, 20]}]}"))]
    pub params: String,
}

/// Query of a distance request.
#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct DistanceQuery {
    /// `npy` answers with the distance array bytes directly (like `Accept: application/x-npy`).
    #[param(inline)]
    pub format: Option<DirectFormat>,
}

/// Direct answer format.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum DirectFormat {
    /// The distance as NPY bytes.
    Npy,
    /// The JSON document with dataset links (the default).
    Json,
}

/// The body of a distance request: JSON, or multipart with the cost file.
#[derive(Debug)]
pub struct DistanceBody {
    /// The request.
    pub params: GridDistanceRequest,
    /// The uploaded file and its format hint (multipart only).
    pub file: Option<(bytes::Bytes, Option<Format>)>,
}

pub(super) fn multipart_error(e: axum::extract::multipart::MultipartError) -> ApiError {
    if let Some(p) = crate::http::server::stalled_problem(&e) {
        return p;
    }
    if e.status() == StatusCode::PAYLOAD_TOO_LARGE {
        ApiError::too_large("body", "the body is larger than the configured limit")
    } else {
        ApiError::bad_request("body", format!("body: {}", e.body_text()))
    }
}

impl<S: Send + Sync> FromRequest<S> for DistanceBody {
    type Rejection = ApiError;

    async fn from_request(req: Request, state: &S) -> Result<Self, Self::Rejection> {
        let is_form = crate::http::extract::is_multipart(req.headers());
        if !is_form {
            let ApiJson(params) = ApiJson::<GridDistanceRequest>::from_request(req, state).await?;
            return Ok(Self { params, file: None });
        }
        let mut form = Multipart::from_request(req, state)
            .await
            .map_err(|e| ApiError::bad_request("body", format!("body: {}", e.body_text())))?;
        let mut params = None;
        let mut file = None;
        while let Some(field) = form.next_field().await.map_err(multipart_error)? {
            match field.name().unwrap_or("") {
                "params" => {
                    let bytes = field.bytes().await.map_err(multipart_error)?;
                    let bytes = with_file_cost(&bytes);
                    check_value_count(&bytes, MAX_JSON_VALUES)
                        .map_err(|e| ApiError::from(e).nested_in("params"))?;
                    let parsed = parse_json::<GridDistanceRequest>(&bytes)
                        .map_err(|e| ApiError::from(e).nested_in("params"))?;
                    params = Some(parsed);
                }
                "file" => {
                    let mut headers = HeaderMap::new();
                    if let Some(ct) = field.content_type().and_then(|c| c.parse().ok()) {
                        headers.insert(header::CONTENT_TYPE, ct);
                    }
                    let hint =
                        format_from_content_type(&headers).map_err(|e| e.nested_in("file"))?;
                    file = Some((field.bytes().await.map_err(multipart_error)?, hint));
                }
                other => {
                    return Err(ApiError::invalid_field(
                        other.to_string(),
                        "unknown part; a form has a `file` part and a `params` part",
                    ))
                }
            }
        }
        let params = params.ok_or_else(|| {
            ApiError::invalid_field("params", "the form has no `params` part (the request JSON)")
        })?;
        Ok(Self { params, file })
    }
}

/// In a form, `cost` may be omitted (or lack `dataset` and `constant`): it
/// then names the `file` part. Anything that is not a JSON object is left for
/// the parser to refuse.
fn with_file_cost(bytes: &[u8]) -> Vec<u8> {
    let Ok(serde_json::Value::Object(mut params)) = serde_json::from_slice(bytes) else {
        return bytes.to_vec();
    };
    if params.contains_key("metric") {
        // A tensor metric names its own datasets; the file is not a cost.
        return bytes.to_vec();
    }
    let cost = params
        .entry("cost")
        .or_insert_with(|| serde_json::Value::Object(Default::default()));
    if let serde_json::Value::Object(cost) = cost {
        if !cost.contains_key("dataset") && !cost.contains_key("constant") {
            cost.insert("dataset".into(), FILE_ID.into());
        }
    }
    serde_json::to_vec(&params).unwrap_or_else(|_| bytes.to_vec())
}

fn wants_npy(query: &DistanceQuery, headers: &HeaderMap) -> bool {
    match query.format {
        Some(DirectFormat::Npy) => true,
        Some(DirectFormat::Json) => false,
        None => headers
            .get(header::ACCEPT)
            .and_then(|v| v.to_str().ok())
            .is_some_and(|a| a.to_ascii_lowercase().contains("application/x-npy")),
    }
}

/// Computes a geodesic distance map.
#[utoipa::path(
    post,
    path = "/v1/grid/distance",
    tag = "grid",
    summary = "Geodesic distance map on a grid",
    description = "Solves the eikonal equation |∇U| = W on a 2D or 3D grid with U = 0 at the sources, and \
returns the distance map and the geodesic Voronoi labels as new datasets. \
Point coordinates are in array index order (axis 0 first), in index units (cell centres are at integer \
indices), with a separate per-axis `spacing` giving the physical size of a cell along each axis. \
The cost is a dataset (`cost.dataset`) or a constant over a shape. \
A source is a point, a list of cells, every non-zero cell of a `mask` dataset, or the zero level set of a \
dataset `phi` (`level_set`, located between cells by interpolation as `skfmm.distance(phi, dx)` does); with \
`signed: true` the distance is negative where `phi < 0`: the redistancing of `phi`. \
One-round-trip form: send `multipart/form-data` with a `file` part (the cost array) and a `params` part \
(this JSON with `cost.dataset` omitted or `\"file\"`). With `Accept: application/x-npy` (or `?format=npy`) \
the answer is the distance array itself as NPY. The solve runs on a bounded pool: when it is full the answer \
is 503 with `Retry-After`; a solve that passes the deadline is cancelled (504). \
With `Prefer: respond-async` the request is queued as an `interactive` job instead: the answer is 202 with \
`Location: /v1/jobs/{id}` and `Retry-After` (see `POST /v1/jobs`).",
    params(DistanceQuery),
    request_body(
        description = "The request (JSON), or a multipart form with the cost file and the request.",
        content(
            (GridDistanceRequest = "application/json"),
            (DistanceForm = "multipart/form-data"),
        )
    ),
    responses(
        (status = 200, description = "The distance map (and labels) were computed and stored.",
            content(
                (DistanceResponse = "application/json"),
                (crate::http::openapi::FileBytes = "application/x-npy"),
            )
        ),
        (status = 202, description = "With `Prefer: respond-async`: the request was queued as a job.",
            body = crate::jobs::Job,
            headers(
                ("Location" = String, description = "URL of the job."),
                ("Retry-After" = u64, description = "Seconds to wait before polling."),
            )),
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
pub async fn distance(
    State(state): State<AppState>,
    ApiQuery(query): ApiQuery<DistanceQuery>,
    headers: HeaderMap,
    body: DistanceBody,
) -> Result<Response, ApiError> {
    let started = Instant::now();
    let direct = wants_npy(&query, &headers);
    let DistanceBody { mut params, file } = body;
    params.validate(&state.op_limits)?;
    let upload = match file {
        Some((bytes, hint)) => Some(decode_upload(&state, bytes, hint, "file").await?),
        None => None,
    };
    if super::jobs::prefers_async(&headers) {
        if let Some(decoded) = upload {
            // A job reads datasets only: store the uploaded cost as one first.
            let meta = state
                .store
                .create(
                    Arc::new(decoded.array),
                    decoded.spacing,
                    SourceFormat::from(decoded.format),
                    crate::http::auth::caller().owner,
                )
                .await?;
            if let Some(cost) = params.cost.as_mut() {
                cost.dataset = Some(meta.id);
            }
        }
        return super::jobs::respond_async(&state, &headers, &params).await;
    }

    let mut uploads = HashMap::new();
    if let Some(decoded) = upload {
        uploads.insert(
            FILE_ID.to_string(),
            InputArray {
                array: Arc::new(decoded.array),
                spacing: decoded.spacing,
            },
        );
    }
    let Ran { mut output, timing } = run(&state, Box::new(params), uploads).await?;

    if direct {
        let stop = output.document["stats"]["stop"]
            .as_str()
            .unwrap_or_default()
            .to_string();
        let Some(at) = output.arrays.iter().position(|a| a.name == "distance") else {
            return Err(ApiError::internal("grid.distance returned no distance"));
        };
        let distance = output.arrays.swap_remove(at).array;
        let bytes = tokio::task::spawn_blocking(move || io::encode_npy(&distance))
            .await
            .map_err(ApiError::internal)?
            .map_err(ApiError::internal)?;
        return Ok((
            [
                (header::CONTENT_TYPE, "application/x-npy".to_string()),
                (header::HeaderName::from_static("x-geodex-stop"), stop),
            ],
            bytes,
        )
            .into_response());
    }

    let mut doc = store_output(&state, output).await?;
    add_timing(&mut doc, &timing, started);
    Ok(Json(doc).into_response())
}
