//! Segmentation endpoints on grids: `POST /v1/grid/edt`, `/v1/grid/segment`,
//! `/v1/grid/skeleton`, `/v1/grid/offset`, `/v1/grid/plan`, and the
//! farthest-point sampling `/v1/grid/sample` and image meshing
//! `/v1/grid/mesh`. Each is the
//! generic synchronous path ([`crate::http::operation`]) over one request
//! struct of [`crate::ops`]; the answer is the operation's JSON document with
//! one dataset reference per output array.

use std::time::Instant;

use axum::extract::State;
use axum::Json;
use serde::Serialize;
use utoipa::ToSchema;

use super::grid::DatasetRef;
use crate::http::extract::ApiJson;
use crate::http::operation::respond;
use crate::http::AppState;
use crate::ops::domain_mesh::DomainMeshRequest;
use crate::ops::grid_edt::GridEdtRequest;
use crate::ops::grid_mesh::GridMeshRequest;
use crate::ops::grid_offset::GridOffsetRequest;
use crate::ops::grid_plan::GridPlanRequest;
use crate::ops::grid_sample::GridSampleRequest;
use crate::ops::grid_segment::GridSegmentRequest;
use crate::ops::grid_skeleton::GridSkeletonRequest;
use crate::ops::Operation;
use crate::problem::ApiError;

async fn run<O: Operation + std::fmt::Debug>(
    state: &AppState,
    request: O,
) -> Result<Json<serde_json::Value>, ApiError> {
    let doc = respond(state, Box::new(request), Instant::now()).await?;
    Ok(Json(serde_json::Value::Object(doc)))
}

/// Answer of `POST /v1/grid/edt`.
#[derive(Debug, Serialize, ToSchema)]
pub struct EdtResponse {
    /// The distance (f64; signed: negative inside; +inf where there is no feature).
    pub distance: DatasetRef,
    /// Linear index of the nearest feature cell (int64, -1 if none), when asked for.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub features: Option<DatasetRef>,
    /// `cells`, `features` (feature cells), `max_distance`, `seconds`, `queue_seconds`.
    pub stats: serde_json::Value,
}

/// Answer of `POST /v1/grid/segment`.
#[derive(Debug, Serialize, ToSchema)]
pub struct SegmentResponse {
    /// Voronoi labels (int32; the seed label, -1 where no seed reaches).
    pub labels: DatasetRef,
    /// Distance to the nearest seed (f64).
    pub distance: DatasetRef,
    /// Distance to the nearest seed of another label (f64, +inf with one label).
    pub second_distance: DatasetRef,
    /// `second_distance - distance` (f64): 0 on the boundaries between labels.
    pub confidence: DatasetRef,
    /// The geodesic ball (uint8), with `max_distance`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ball: Option<DatasetRef>,
    /// Per label: `label`, `cells`, `seeds`.
    pub labels_summary: Option<serde_json::Value>,
    /// 2D: GeoJSON FeatureCollection, one MultiPolygon per label, positions `[x, y] = [column, row] × spacing` (GeoJSON order).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub contours: Option<serde_json::Value>,
    /// `cells`, `solves`, `seconds`, `queue_seconds`.
    pub stats: serde_json::Value,
}

/// Answer of `POST /v1/grid/skeleton`.
#[derive(Debug, Serialize, ToSchema)]
pub struct SkeletonResponse {
    /// The skeleton (uint8 mask).
    pub skeleton: DatasetRef,
    /// The radius function on the skeleton (f64, 0 elsewhere).
    pub radius: DatasetRef,
    /// 2D: the skeleton and its nodes over the shape (u8 RGB; `?format=png`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub picture: Option<DatasetRef>,
    /// 2D: `nodes` (`id`, `point`, `radius`, `degree`) and `edges` (`source`, `target`, `points` from the source node to the target node, `radius`, `euclidean_length`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub graph: Option<serde_json::Value>,
    /// Cell counts, nodes, branches, timings.
    pub stats: serde_json::Value,
}

/// Answer of `POST /v1/grid/offset`.
#[derive(Debug, Serialize, ToSchema)]
pub struct OffsetResponse {
    /// The offset shape (uint8 mask).
    pub offset: DatasetRef,
    /// The distance used (f64).
    pub distance: DatasetRef,
    /// `cells_before`, `cells_after`, `area_before`, `area_after`, timings.
    pub stats: serde_json::Value,
}

/// Answer of `POST /v1/grid/plan`.
#[derive(Debug, Serialize, ToSchema)]
pub struct PlanResponse {
    /// Vertices of the path, index coordinates, start to goal.
    pub path: Vec<Vec<f64>>,
    /// Physical length of the path.
    pub euclidean_length: f64,
    /// Smallest clearance on the path (>= radius).
    pub min_clearance: f64,
    /// The robot's radius.
    pub radius: f64,
    /// The widest robot that can go from start to goal.
    pub widest_radius: f64,
    /// Clearance map (f64).
    pub clearance: DatasetRef,
    /// Distance to the goal in the free space (f64).
    pub distance: DatasetRef,
    /// 2D: the path over the obstacles (u8 RGB; `?format=png`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub picture: Option<DatasetRef>,
}

/// Exact Euclidean distance transform.
#[utoipa::path(
    post,
    path = "/v1/grid/edt",
    tag = "grid",
    summary = "Exact Euclidean distance transform",
    description = "Exact (not chamfer) Euclidean distance transform of a 2D or 3D mask with per-axis \
spacing: `binary` (distance of every cell to the nearest non-zero cell), `signed` (negative inside), or \
`multilabel` (distance to the nearest cell of another value). With `features`, the C-order linear index \
of the nearest feature cell.",
    request_body = GridEdtRequest,
    responses(
        (status = 200, description = "The transform was computed and stored.", body = EdtResponse),
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
pub async fn edt(
    State(state): State<AppState>,
    ApiJson(request): ApiJson<GridEdtRequest>,
) -> Result<Json<serde_json::Value>, ApiError> {
    run(&state, request).await
}

/// Seeded segmentation by geodesic Voronoi cells.
#[utoipa::path(
    post,
    path = "/v1/grid/segment",
    tag = "grid",
    summary = "Seeded segmentation (geodesic Voronoi)",
    description = "Labels every cell with the label of its geodesically nearest seed under the metric \
`cost` (as in `/v1/grid/distance`). Seeds are labelled points or cells, or a label image of scribbles. \
Returns the label map, the distance to the nearest seed, the distance to the nearest seed of another \
label and their difference (a confidence map), the geodesic ball with `max_distance`, and in 2D the \
label contours as GeoJSON polygons. One solve per label.",
    request_body = GridSegmentRequest,
    responses(
        (status = 200, description = "The segmentation was computed and stored.", body = SegmentResponse),
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
pub async fn segment(
    State(state): State<AppState>,
    ApiJson(request): ApiJson<GridSegmentRequest>,
) -> Result<Json<serde_json::Value>, ApiError> {
    run(&state, request).await
}

/// Medial axis of a shape.
#[utoipa::path(
    post,
    path = "/v1/grid/skeleton",
    tag = "grid",
    summary = "Medial axis (skeleton) with pruning",
    description = "The medial axis of a 2D or 3D binary shape from its exact distance and \
nearest-boundary-point maps. A branch is kept where its two nearest boundary points are at least \
`min_boundary_length` (or `min_boundary_fraction` of the boundary length) apart along the boundary \
(2D; the chord in 3D), so boundary noise grows no branch. In 2D the skeleton also comes as a graph of polylines.",
    request_body = GridSkeletonRequest,
    responses(
        (status = 200, description = "The skeleton was computed and stored.", body = SkeletonResponse),
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
pub async fn skeleton(
    State(state): State<AppState>,
    ApiJson(request): ApiJson<GridSkeletonRequest>,
) -> Result<Json<serde_json::Value>, ApiError> {
    run(&state, request).await
}

/// Offset (dilate or erode) a shape.
#[utoipa::path(
    post,
    path = "/v1/grid/offset",
    tag = "grid",
    summary = "Shape offsetting (dilation, erosion)",
    description = "Dilates or erodes a shape by a Euclidean (exact EDT) or geodesic (fast marching on \
`cost`) distance, optionally around obstacles that block the propagation.",
    request_body = GridOffsetRequest,
    responses(
        (status = 200, description = "The offset shape was computed and stored.", body = OffsetResponse),
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
pub async fn offset(
    State(state): State<AppState>,
    ApiJson(request): ApiJson<GridOffsetRequest>,
) -> Result<Json<serde_json::Value>, ApiError> {
    run(&state, request).await
}

/// Path planning for a disc robot.
#[utoipa::path(
    post,
    path = "/v1/grid/plan",
    tag = "grid",
    summary = "Motion planning for a disc robot",
    description = "Grows the obstacles by the robot's radius with the exact distance transform and \
returns a shortest collision-free path from start to goal (clearance >= radius along the whole \
polyline). When there is none the answer is a 422 problem on `radius` that says so and gives the \
widest robot that could pass.",
    request_body = GridPlanRequest,
    responses(
        (status = 200, description = "A path was found.", body = PlanResponse),
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
pub async fn plan(
    State(state): State<AppState>,
    ApiJson(request): ApiJson<GridPlanRequest>,
) -> Result<Json<serde_json::Value>, ApiError> {
    run(&state, request).await
}

/// Answer of `POST /v1/grid/sample`.
#[derive(Debug, Serialize, ToSchema)]
pub struct SampleResponse {
    /// Sample cells, index coordinates (axis 0 first), in the order placed (seeds first).
    pub samples: Vec<Vec<usize>>,
    /// Distance to the nearest sample (f64, +inf where not reached).
    pub distance: DatasetRef,
    /// Index of the nearest sample in `samples` (int32, -1 where not reached).
    pub labels: DatasetRef,
    /// `samples`, `covering_radius`, `radii` (the covering radius after each
    /// sample), `stop` (`count`, `radius` or `exhausted`), `visited` (cells
    /// recomputed by all the fronts), `seconds`, `queue_seconds`.
    pub stats: serde_json::Value,
}

/// Farthest-point sampling of a grid.
#[utoipa::path(
    post,
    path = "/v1/grid/sample",
    tag = "grid",
    summary = "Farthest-point sampling with geodesic Voronoi cells",
    description = "Places samples one at a time, each at the cell farthest (in the geodesic distance of \
the cost W) from those already placed, until `count` samples are placed or every reachable cell is \
within `radius` of one. Each new sample recomputes the distance only where it decreases (a local \
first-order fast march), not on the whole grid. Optional `seeds` are the first samples. Points are \
cells in array index order (axis 0 first); distances use the per-axis `spacing`. Returns the \
samples, the distance to the nearest sample, the Voronoi labels and the covering radius after each sample.",
    request_body = GridSampleRequest,
    responses(
        (status = 200, description = "The grid was sampled.", body = SampleResponse),
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
pub async fn sample(
    State(state): State<AppState>,
    ApiJson(request): ApiJson<GridSampleRequest>,
) -> Result<Json<serde_json::Value>, ApiError> {
    let doc = respond(&state, Box::new(request), Instant::now()).await?;
    Ok(Json(serde_json::Value::Object(doc)))
}

/// Answer of `POST /v1/grid/mesh`.
#[derive(Debug, Serialize, ToSchema)]
pub struct GridMeshResponse {
    /// The mesh (a mesh dataset: vertices in index coordinates with `z = 0`,
    /// the image value per vertex as the `value` property; download it as
    /// PLY, OBJ, JSON or GLB).
    pub mesh: DatasetRef,
    /// The piecewise-linear approximation of the image on the mesh (f64, the image's shape).
    pub approximation: DatasetRef,
    /// The metric `W` the vertices followed (f64, the image's shape).
    pub cost: DatasetRef,
    /// The vertices (f64, `nv × 2`, index coordinates, axis 0 first).
    pub vertices: DatasetRef,
    /// The triangles (int32, `nt × 3`, counter-clockwise in the (axis 0, axis 1) plane).
    pub triangles: DatasetRef,
    /// The mesh drawn over the image (u8 RGB, `(s·rows, s·cols, 3)` with a
    /// magnification `s` of 1 to 4 so that the larger side nears 1024
    /// pixels): download it with `?format=png`.
    pub picture: DatasetRef,
    /// `vertices`, `triangles`, `l2_error` (root mean square of image minus
    /// approximation), `added` (vertices the Delaunay repair added),
    /// `repaired` (defects by kind), `covering_radius`, `seconds`, and with
    /// `compare_uniform` the uniform mesh's `uniform: {vertices, triangles,
    /// l2_error, added}` and `error_ratio` (adapted over uniform).
    pub stats: serde_json::Value,
}

/// Image meshing by geodesic Delaunay triangulation.
#[utoipa::path(
    post,
    path = "/v1/grid/mesh",
    tag = "grid",
    summary = "Mesh an image: vertices placed by a metric, geodesic Delaunay triangles",
    description = "Derives a metric from the image (`gradient`: W = 1 + strength |grad f| / max, \
`hessian`: the same with the Hessian's norm, `uniform`: W = 1), places `count` vertices by \
farthest-point sampling under it (the four corners first), and triangulates them by the dual of \
their geodesic Voronoi cells, repaired (samples added and counted) until it is a valid \
triangulation covering the image. Returns the mesh as a mesh dataset (index coordinates, axis 0 \
first), the piecewise-linear approximation of the image on it, its L2 error, a picture of the mesh \
over the image (`picture`, as PNG with `?format=png`), and by default the error of a uniform mesh \
with the same vertex count.",
    request_body = GridMeshRequest,
    responses(
        (status = 200, description = "The image was meshed.", body = GridMeshResponse),
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
pub async fn mesh(
    State(state): State<AppState>,
    ApiJson(request): ApiJson<GridMeshRequest>,
) -> Result<Json<serde_json::Value>, ApiError> {
    run(&state, request).await
}

/// Answer of `POST /v1/domain/mesh`.
#[derive(Debug, Serialize, ToSchema)]
pub struct DomainMeshResponse {
    /// The mesh (a mesh dataset: vertices in index coordinates with `z = 0`;
    /// download it as PLY, OBJ, JSON or GLB).
    pub mesh: DatasetRef,
    /// The vertices (f64, `nv × 2`, index coordinates, axis 0 first).
    pub vertices: DatasetRef,
    /// The triangles (int32, `nt × 3`, counter-clockwise in the (axis 0, axis 1) plane).
    pub triangles: DatasetRef,
    /// The boundary edges (int32, `nb × 2`, the domain on their left).
    pub boundary_edges: DatasetRef,
    /// The smallest angle of each triangle (f64, degrees).
    pub min_angles: DatasetRef,
    /// 1 on boundary vertices, 0 inside (f64 per vertex).
    pub boundary: DatasetRef,
    /// `vertices`, `triangles`, `boundary_vertices`, `boundary_edges`,
    /// `refined` (vertices the angle refinement added),
    /// `refinement_complete`, `edge_length` (the size used), `attempts`
    /// (meshings made to reach `count`), `area`, `min_angle: {min, median,
    /// mean, share_at_least_25, share_at_least_30, histogram_5_degrees}`,
    /// `seconds`.
    pub stats: serde_json::Value,
}

/// Domain meshing: a mask or polygons with holes, boundary first.
#[utoipa::path(
    post,
    path = "/v1/domain/mesh",
    tag = "grid",
    summary = "Mesh a planar domain (a mask or GeoJSON polygons with holes)",
    description = "Samples the boundary first (every ring vertex kept, each edge cut into pieces \
of about `edge_length`, geodesic under `cost`), triangulates it by constrained Delaunay, fills the \
inside by circumcenter insertion, relaxes the inner vertices by optimal Delaunay smoothing and \
refines by Ruppert's algorithm until every angle is at least `min_angle` (except at sharper input \
corners). No triangle lies outside the domain and every boundary edge lies on an input edge. \
Returns the mesh as a mesh dataset (index coordinates, axis 0 first) and its angle statistics.",
    request_body = DomainMeshRequest,
    responses(
        (status = 200, description = "The domain was meshed.", body = DomainMeshResponse),
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
pub async fn domain_mesh(
    State(state): State<AppState>,
    ApiJson(request): ApiJson<DomainMeshRequest>,
) -> Result<Json<serde_json::Value>, ApiError> {
    run(&state, request).await
}
