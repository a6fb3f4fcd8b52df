//! `/v1/grid/shape-embed`: the canonical form of a shape given as a mask.

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
use crate::ops::grid_shape_embed::GridShapeEmbedRequest;
use crate::problem::ApiError;

/// Answer of `POST /v1/grid/shape-embed`.
#[derive(Debug, Serialize, ToSchema)]
pub struct ShapeEmbedResponse {
    /// The embedded cells, `cells × dimensions` f64 (on their principal axes).
    pub coordinates: DatasetRef,
    /// The index coordinates of each embedded cell (axis 0 first), `cells × ndim` i64.
    pub cells: DatasetRef,
    /// 2D shapes: the shape's pixel mesh (two triangles per 2 × 2 block of
    /// shape cells) at the embedded positions (PLY); vertex `p` is cell `p`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub result: Option<DatasetRef>,
    /// With `matrix: true`: the inner-distance rows, `landmarks × cells`
    /// (all pairs: `cells × cells`) f64.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub matrix: Option<DatasetRef>,
    /// `dimensions`, `landmarks` (index coordinates), `explained_variance`,
    /// `eigenvalues`, `stress` (normalised, over the measured pairs),
    /// `residual_variance`, `asymmetry`, `stats`.
    #[serde(flatten)]
    #[schema(value_type = Object)]
    pub details: serde_json::Map<String, Value>,
}

/// `POST /v1/grid/shape-embed`.
#[utoipa::path(
    post,
    path = "/v1/grid/shape-embed",
    tag = "grid",
    summary = "Inner distances and canonical form of a shape given as a mask",
    description = "The inner geodesic distance of a 2D or 3D shape (the mask's non-zero cells, in one piece: \
the length of the shortest path that stays inside, by fast marching from each landmark) embedded by \
classical MDS (all pairs, shapes of up to 5000 cells) or landmark MDS (`landmarks` farthest-point landmarks; \
larger shapes get a 413 naming `landmarks`): the bending-invariant canonical form of an articulated shape. \
A shape in several pieces gets a 422 naming `mask`.",
    request_body(content((GridShapeEmbedRequest = "application/json"))),
    responses(
        (status = 200, description = "Computed and stored.", body = ShapeEmbedResponse),
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
pub async fn shape_embed(
    State(state): State<AppState>,
    ApiJson(request): ApiJson<GridShapeEmbedRequest>,
) -> Result<Json<ShapeEmbedResponse>, ApiError> {
    let mut details = respond(&state, Box::new(request), Instant::now()).await?;
    let coordinates = take_ref(&mut details, "coordinates")?;
    let cells = take_ref(&mut details, "cells")?;
    let result = details
        .contains_key("result")
        .then(|| take_ref(&mut details, "result"))
        .transpose()?;
    let matrix = details
        .contains_key("matrix")
        .then(|| take_ref(&mut details, "matrix"))
        .transpose()?;
    details.remove("mesh_report");
    Ok(Json(ShapeEmbedResponse {
        coordinates,
        cells,
        result,
        matrix,
        details,
    }))
}
