//! `/v1/mesh/*`: distance, Voronoi cells, paths and farthest-point sampling
//! on mesh datasets. The handlers load the mesh (cached), run the operation
//! on the solver pool with the store's heat-factorisation cache, and store
//! the mesh with its per-vertex `distance` and `label` as a new PLY dataset.
//! Shape analysis: distance matrices (`/v1/mesh/distance-matrix`, an NPY
//! matrix dataset) and canonical forms (`/v1/mesh/embed`, a mesh dataset).

use std::collections::HashMap;
use std::time::Instant;

use axum::extract::State;
use axum::Json;
use serde::Serialize;
use serde_json::Value;
use utoipa::ToSchema;

use crate::http::extract::ApiJson;
use crate::http::operation::{respond, run, store_output};
use crate::http::routes::grid::DatasetRef;
use crate::http::AppState;
use crate::ops::mesh_correspond::MeshCorrespondRequest;
use crate::ops::mesh_curvature::MeshCurvatureRequest;
use crate::ops::mesh_descriptor::{DescriptorValue, MeshDescriptorRequest};
use crate::ops::mesh_distance_matrix::MeshDistanceMatrixRequest;
use crate::ops::mesh_embed::MeshEmbedRequest;
use crate::ops::mesh_paths::MeshPathsRequest;
use crate::ops::mesh_remesh::MeshRemeshRequest;
use crate::ops::mesh_sample::MeshSampleRequest;
use crate::ops::mesh_voronoi::MeshVoronoiRequest;
use crate::ops::spec::mesh::MeshDistanceRequest;
use crate::ops::Operation;
use crate::problem::ApiError;
use crate::runner::Ran;

/// The answer of a mesh operation.
#[derive(Debug, Serialize, ToSchema)]
pub struct MeshResponse {
    /// The mesh with per-vertex `distance` (double) and `label` (int) as a
    /// PLY dataset (`data_url?format=ply|obj|json`); absent for paths.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub result: Option<DatasetRef>,
    /// Method, statistics, heat-method details, and the operation's own
    /// fields (`cells`, `paths`, `samples`).
    #[serde(flatten)]
    #[schema(value_type = Object)]
    pub details: serde_json::Map<String, Value>,
}

async fn run_mesh_op<O: Operation + std::fmt::Debug>(
    state: &AppState,
    request: O,
) -> Result<Json<MeshResponse>, ApiError> {
    let Ran { output, .. } = run(state, Box::new(request), HashMap::new()).await?;
    let mut details = store_output(state, output).await?;
    let result = details
        .remove("result")
        .map(serde_json::from_value)
        .transpose();
    let result = result.map_err(ApiError::internal)?;
    // The repairs of the stored mesh are in its dataset's metadata.
    details.remove("mesh_report");
    Ok(Json(MeshResponse { result, details }))
}

/// `POST /v1/mesh/distance`.
#[utoipa::path(
    post,
    path = "/v1/mesh/distance",
    tag = "mesh",
    summary = "Geodesic distance on a triangle mesh",
    description = "Distance from sources at vertices or inside faces (`{\"vertex\": i}` or \
`{\"face\": f, \"bary\": [b0, b1, b2]}`) over a mesh dataset, with `method` `fast_marching` (default), `heat` (factorisation cached per dataset and `heat.m`: later queries cost two solves), \
`exact` or `dijkstra`. The result is a new mesh dataset (PLY) with per-vertex `distance` (+inf where unreached: \
other components, beyond `max_distance`) and `label` (index of the nearest source, -1 where unreached).",
    request_body(content((MeshDistanceRequest = "application/json"))),
    responses(
        (status = 200, description = "Computed and stored.", body = MeshResponse),
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
    ApiJson(request): ApiJson<MeshDistanceRequest>,
) -> Result<Json<MeshResponse>, ApiError> {
    run_mesh_op(&state, request).await
}

/// `POST /v1/mesh/voronoi`.
#[utoipa::path(
    post,
    path = "/v1/mesh/voronoi",
    tag = "mesh",
    summary = "Geodesic Voronoi cells on a triangle mesh",
    description = "The fields of `/v1/mesh/distance`; the answer adds `cells` (vertices and area per source) \
and the stored mesh carries the cell of every vertex in `label`.",
    request_body(content((MeshVoronoiRequest = "application/json"))),
    responses(
        (status = 200, description = "Computed and stored.", body = MeshResponse),
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
pub async fn voronoi(
    State(state): State<AppState>,
    ApiJson(request): ApiJson<MeshVoronoiRequest>,
) -> Result<Json<MeshResponse>, ApiError> {
    run_mesh_op(&state, request).await
}

/// `POST /v1/mesh/curvature`.
#[utoipa::path(
    post,
    path = "/v1/mesh/curvature",
    tag = "mesh",
    summary = "Principal, mean and Gaussian curvature of a triangle mesh",
    description = "Per vertex: the principal curvatures `k1 >= k2` (positive where the surface bends away from its \
normal, so `1/r` on a sphere of radius `r` with outward normals), their directions `d1`, `d2` and the `normal` \
(`[vertices, 3]` arrays), the `gaussian_curvature` `k1 k2`, and the mean curvature `(k1 + k2)/2`, carried \
by the `result` mesh as its `value` vertex property (download `?format=npy&property=value` for the values \
alone); from the least-squares second fundamental form of the edges' normal curvatures after `smoothing` \
passes of one-ring averaging of the tensor. `stats` gives the minimum, median and maximum of each.",
    request_body(content((MeshCurvatureRequest = "application/json"))),
    responses(
        (status = 200, description = "Computed and stored.", body = MeshResponse),
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
pub async fn curvature(
    State(state): State<AppState>,
    ApiJson(request): ApiJson<MeshCurvatureRequest>,
) -> Result<Json<MeshResponse>, ApiError> {
    run_mesh_op(&state, request).await
}

/// `POST /v1/mesh/paths`.
#[utoipa::path(
    post,
    path = "/v1/mesh/paths",
    tag = "mesh",
    summary = "Geodesic paths on a triangle mesh",
    description = "A path from the nearest source to each point of `ends`, by steepest descent of the distance \
field across faces (or, with `method: exact`, backtracked through the exact windows): 3D polylines from the \
source to the end whose points name their `vertex`, `edge` or `face`, with `geodesic_length` (the distance at \
the end), `euclidean_length` (the polyline's length) and `traced` (`windows`, or `descent`: an exact path \
that could not be followed back across near-degenerate faces descends the exact field instead, and `note` \
says why). Under face tensors (`metric`) the descent follows `−M⁻¹∇U`.",
    request_body(content((MeshPathsRequest = "application/json"))),
    responses(
        (status = 200, description = "The paths.", body = MeshResponse),
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
    ApiJson(request): ApiJson<MeshPathsRequest>,
) -> Result<Json<MeshResponse>, ApiError> {
    run_mesh_op(&state, request).await
}

/// `POST /v1/mesh/sample`.
#[utoipa::path(
    post,
    path = "/v1/mesh/sample",
    tag = "mesh",
    summary = "Farthest-point sampling of a triangle mesh",
    description = "Adds the vertex farthest from the samples so far until `count` samples are placed or every \
vertex is within `radius`; returns the samples and stores the mesh with the distance to the nearest sample \
and its Voronoi cell (`label`).",
    request_body(content((MeshSampleRequest = "application/json"))),
    responses(
        (status = 200, description = "Computed and stored.", body = MeshResponse),
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
    ApiJson(request): ApiJson<MeshSampleRequest>,
) -> Result<Json<MeshResponse>, ApiError> {
    run_mesh_op(&state, request).await
}

/// Answer of `POST /v1/mesh/remesh`.
#[derive(Debug, Serialize, ToSchema)]
pub struct RemeshResponse {
    /// The new mesh (a mesh dataset: download it as PLY, OBJ or JSON).
    pub remeshed: DatasetRef,
    /// The vertices (f64, `nv × 3`).
    pub vertices: DatasetRef,
    /// The triangles (int32, `nt × 3`, oriented like the input).
    pub triangles: DatasetRef,
    /// The input vertex of each output vertex (int32).
    pub samples: DatasetRef,
    /// `vertices`, `triangles`, `target_count`, `added` (samples the dual
    /// repair added), `repair_rounds`, `lloyd_energies` (the energy
    /// `Σ A_v d²` after sampling and after each accepted Lloyd iteration,
    /// non-increasing), `valid`, `flipped`, `topology_kept` and
    /// `topology_note`, `input_topology` and `output_topology` (components,
    /// boundary loops, Euler characteristic, genus), `hausdorff` and
    /// `hausdorff_relative` (over the bounding-box diagonal), `seconds`.
    pub stats: serde_json::Value,
}

/// `POST /v1/mesh/remesh`.
#[utoipa::path(
    post,
    path = "/v1/mesh/remesh",
    tag = "mesh",
    summary = "Remesh a surface: geodesic sampling, Lloyd relaxation, dual of the Voronoi cells",
    description = "Places `count` vertices (or as many as `edge_length` asks) on the mesh by \
farthest-point sampling under a uniform or curvature-adapted metric, relaxes them by geodesic \
Lloyd iterations (each kept only if the energy decreases; the energies are returned), and \
triangulates them by the dual of their geodesic Voronoi cells, repaired (samples added and \
counted) until it is a manifold with the input's topology. Says whether the components, boundary \
loops and genus were kept, and the Hausdorff distance to the input. Runs as a job with progress \
through `POST /v1/jobs`.",
    request_body(content((MeshRemeshRequest = "application/json"))),
    responses(
        (status = 200, description = "The surface was remeshed.", body = RemeshResponse),
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
pub async fn remesh(
    State(state): State<AppState>,
    ApiJson(request): ApiJson<MeshRemeshRequest>,
) -> Result<Json<Value>, ApiError> {
    let doc = respond(&state, Box::new(request), Instant::now()).await?;
    Ok(Json(Value::Object(doc)))
}

/// Answer of `POST /v1/mesh/distance-matrix`.
#[derive(Debug, Serialize, ToSchema)]
pub struct DistanceMatrixResponse {
    /// The `rows × columns` f64 matrix (`data_url?format=npy`): row `i` holds
    /// the distance from vertex `sources[i]` (every vertex in order for all
    /// pairs) to every vertex, `+inf` in other components.
    pub matrix: DatasetRef,
    /// `method`, `symmetry`, `rows`, `columns`, `all_pairs`, `sources`,
    /// `asymmetry` (largest |D[i, sⱼ] − D[j, sᵢ]| before symmetrisation),
    /// `heat`, `stats`.
    #[serde(flatten)]
    #[schema(value_type = Object)]
    pub details: serde_json::Map<String, Value>,
}

/// `POST /v1/mesh/distance-matrix`.
#[utoipa::path(
    post,
    path = "/v1/mesh/distance-matrix",
    tag = "mesh",
    summary = "Geodesic distance matrix of a triangle mesh",
    description = "Distances between many vertices at once, every row a single-source solve sharing one setup \
(one topology, one heat factorisation) and the rows running in parallel. Rows: `sources` if given, else \
`landmarks` farthest-point landmarks, else every vertex (all pairs, meshes of up to 5000 vertices; larger \
meshes get a 413 naming `landmarks`). The source block is made symmetric by `symmetry` (`average` by \
default, `min`, or `none`). The matrix is stored as an f64 dataset (NPY).",
    request_body(content((MeshDistanceMatrixRequest = "application/json"))),
    responses(
        (status = 200, description = "Computed and stored.", body = DistanceMatrixResponse),
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
pub async fn distance_matrix(
    State(state): State<AppState>,
    ApiJson(request): ApiJson<MeshDistanceMatrixRequest>,
) -> Result<Json<DistanceMatrixResponse>, ApiError> {
    let mut details = respond(&state, Box::new(request), Instant::now()).await?;
    let matrix = take_ref(&mut details, "matrix")?;
    Ok(Json(DistanceMatrixResponse { matrix, details }))
}

/// Answer of `POST /v1/mesh/embed`.
#[derive(Debug, Serialize, ToSchema)]
pub struct EmbedResponse {
    /// The canonical form: the input's faces at the embedded positions (PLY).
    pub result: DatasetRef,
    /// The embedded points, `vertices × dimensions` f64.
    pub coordinates: DatasetRef,
    /// `method`, `dimensions`, `landmarks`, `explained_variance`, `stress`
    /// (normalised, over the measured pairs), `smacof_stress` (per
    /// iteration), `asymmetry`, `stats`.
    #[serde(flatten)]
    #[schema(value_type = Object)]
    pub details: serde_json::Map<String, Value>,
}

/// `POST /v1/mesh/embed`.
#[utoipa::path(
    post,
    path = "/v1/mesh/embed",
    tag = "mesh",
    summary = "Bending-invariant canonical form of a triangle mesh",
    description = "Embeds the geodesic distances of a connected mesh in 3D (or 2D) so that bent poses of one \
surface get one shape (Elad and Kimmel): classical MDS of all pairs (meshes of up to 5000 vertices), \
optionally refined by SMACOF (`smacof`), or landmark MDS from `landmarks` farthest-point landmarks. \
A mesh of several components gets a 422 naming `mesh`.",
    request_body(content((MeshEmbedRequest = "application/json"))),
    responses(
        (status = 200, description = "Computed and stored.", body = EmbedResponse),
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
pub async fn embed(
    State(state): State<AppState>,
    ApiJson(request): ApiJson<MeshEmbedRequest>,
) -> Result<Json<EmbedResponse>, ApiError> {
    let mut details = respond(&state, Box::new(request), Instant::now()).await?;
    let result = take_ref(&mut details, "result")?;
    let coordinates = take_ref(&mut details, "coordinates")?;
    details.remove("mesh_report");
    Ok(Json(EmbedResponse {
        result,
        coordinates,
        details,
    }))
}

/// Answer of `POST /v1/mesh/descriptor`.
#[derive(Debug, Serialize, ToSchema)]
pub struct DescriptorResponse {
    /// The descriptor.
    pub descriptor: DescriptorValue,
    /// `method`, `bins`, `stats`.
    #[serde(flatten)]
    #[schema(value_type = Object)]
    pub details: serde_json::Map<String, Value>,
}

/// Takes the descriptor out of a `mesh.descriptor` document.
pub(crate) fn take_descriptor(
    doc: &mut serde_json::Map<String, Value>,
) -> Result<DescriptorValue, ApiError> {
    let v = doc
        .remove("descriptor")
        .ok_or_else(|| ApiError::internal("the descriptor is missing from the answer"))?;
    serde_json::from_value(v).map_err(ApiError::internal)
}

/// `POST /v1/mesh/descriptor`.
#[utoipa::path(
    post,
    path = "/v1/mesh/descriptor",
    tag = "mesh",
    summary = "Geodesic shape descriptor of a triangle mesh",
    description = "The descriptor that shape collections compare (`/v1/collections`): from `landmarks` \
farthest-point landmarks and their geodesic distances, the area-weighted histogram of distances over the \
geodesic diameter, the histogram of eccentricities (mean distance to the landmarks over the diameter), and \
nine moments of the landmark-MDS canonical form. Invariant to rigid motion, scale, bending and remeshing. \
A mesh of several components gets a 422 naming `mesh`.",
    request_body(content((MeshDescriptorRequest = "application/json"))),
    responses(
        (status = 200, description = "Computed.", body = DescriptorResponse),
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
pub async fn descriptor(
    State(state): State<AppState>,
    ApiJson(request): ApiJson<MeshDescriptorRequest>,
) -> Result<Json<DescriptorResponse>, ApiError> {
    let mut details = respond(&state, Box::new(request), Instant::now()).await?;
    let descriptor = take_descriptor(&mut details)?;
    Ok(Json(DescriptorResponse {
        descriptor,
        details,
    }))
}

/// Answer of `POST /v1/mesh/correspond`.
#[derive(Debug, Serialize, ToSchema)]
pub struct CorrespondResponse {
    /// The mesh `a` with per-vertex `match_face`, `match_vertex` (int),
    /// `match_bary0..2` and `confidence` (double) (PLY).
    pub result: DatasetRef,
    /// For each vertex of `a`, the face of `b` holding its match (int32).
    pub face: DatasetRef,
    /// The barycentric coordinates of the match in that face, `n × 3` f64.
    pub bary: DatasetRef,
    /// The vertex of `b` nearest the match (int32).
    pub vertex: DatasetRef,
    /// The confidence of each match in `(0, 1]` (f64).
    pub confidence: DatasetRef,
    /// `landmarks`, `landmarks_a`, `landmarks_b`, `symmetric`, `flipped`,
    /// `distortion`, `alternative_distortion`, `alternative_flipped`,
    /// `candidates`, `diameter`, `confidence_scale`, `mean_confidence`,
    /// `area_ratio`, `scale_factor`, `stats`.
    #[serde(flatten)]
    #[schema(value_type = Object)]
    pub details: serde_json::Map<String, Value>,
}

/// `POST /v1/mesh/correspond`.
#[utoipa::path(
    post,
    path = "/v1/mesh/correspond",
    tag = "mesh",
    summary = "Correspondence between two near-isometric triangle meshes",
    description = "Matches every vertex of mesh `a` to a point of mesh `b` (face and barycentric coordinates) \
with a confidence, from geodesic distances only: landmark-MDS canonical forms of both, rigid alignment over every \
flip of their principal axes, then refinement by the geodesic distances to matched landmarks. `symmetric` reports \
an intrinsic symmetry (a mirror flip) that makes a second map almost as good, with both distortions. A mesh of \
several components gets a 422 naming `a` or `b`; areas differing by more than a factor 1.2 get a 422 naming `b` \
(give `scale: true` to rescale `b` first).",
    request_body(content((MeshCorrespondRequest = "application/json"))),
    responses(
        (status = 200, description = "Computed and stored.", body = CorrespondResponse),
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
pub async fn correspond(
    State(state): State<AppState>,
    ApiJson(request): ApiJson<MeshCorrespondRequest>,
) -> Result<Json<CorrespondResponse>, ApiError> {
    let mut details = respond(&state, Box::new(request), Instant::now()).await?;
    let result = take_ref(&mut details, "result")?;
    let face = take_ref(&mut details, "face")?;
    let bary = take_ref(&mut details, "bary")?;
    let vertex = take_ref(&mut details, "vertex")?;
    let confidence = take_ref(&mut details, "confidence")?;
    details.remove("mesh_report");
    Ok(Json(CorrespondResponse {
        result,
        face,
        bary,
        vertex,
        confidence,
        details,
    }))
}

/// Removes the stored output `name` from an answer document.
pub(crate) fn take_ref(
    doc: &mut serde_json::Map<String, Value>,
    name: &str,
) -> Result<DatasetRef, ApiError> {
    let value = doc
        .remove(name)
        .ok_or_else(|| ApiError::internal(format!("the output `{name}` was not stored")))?;
    serde_json::from_value(value).map_err(ApiError::internal)
}
