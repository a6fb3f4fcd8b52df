//! `POST /v1/grid/shape-from-shading`: the height map of a Lambertian surface
//! recovered from one image (the generic synchronous path over
//! [`GridShadingRequest`]).

use std::time::Instant;

use axum::extract::State;
use axum::Json;
use serde::Serialize;
use utoipa::ToSchema;

use super::grid::DatasetRef;
use crate::http::extract::ApiJson;
use crate::http::operation::respond;
use crate::http::AppState;
use crate::ops::grid_shading::GridShadingRequest;
use crate::problem::ApiError;

/// Answer of `POST /v1/grid/shape-from-shading`.
#[derive(Debug, Serialize, ToSchema)]
pub struct ShadingResponse {
    /// The height per pixel (f64, in the units of `spacing`; `+inf` or `-inf`
    /// behind a shadow, where no anchor reaches).
    pub height: DatasetRef,
    /// `cells`, `anchors` (pixels whose height was prescribed), `flat`
    /// (pixels at the albedo: slope 0), `unreached`, `albedo` (the one used),
    /// `min_height`, `max_height`, `seconds`, `queue_seconds`.
    pub stats: serde_json::Value,
}

/// Shape from shading.
#[utoipa::path(
    post,
    path = "/v1/grid/shape-from-shading",
    tag = "grid",
    summary = "Height map of a Lambertian surface from one image (shape from shading)",
    description = "Reads the image as the brightness I of a Lambertian surface lit from the camera's \
direction and seen by an orthographic camera, I = albedo / sqrt(1 + |∇z|²), and recovers its height z \
as the viscosity solution of the eikonal equation |∇z| = sqrt(albedo²/I² - 1) by fast marching \
(Rouy-Tourin, Kimmel-Sethian). The heights of the `anchors` are prescribed: the image border \
(default, an object on a flat ground), the singular points (the brightest pixels, the tops of a convex \
object), a mask, or listed pixels; `direction` chooses between the concave and the convex reading. \
Pixels with I = 0 are shadows and stay unreached.",
    request_body = GridShadingRequest,
    responses(
        (status = 200, description = "The surface was recovered.", body = ShadingResponse),
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
pub async fn shape_from_shading(
    State(state): State<AppState>,
    ApiJson(request): ApiJson<GridShadingRequest>,
) -> Result<Json<serde_json::Value>, ApiError> {
    let doc = respond(&state, Box::new(request), Instant::now()).await?;
    Ok(Json(serde_json::Value::Object(doc)))
}
