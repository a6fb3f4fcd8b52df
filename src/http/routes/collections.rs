//! `/v1/collections`: shape collections (issue 19, item 4). A collection
//! holds the geodesic descriptors of meshes (`mesh.descriptor`, computed
//! on the solver pool through the one runner) and ranks them against a
//! query mesh, nearest first. Stored in the jobs' database
//! ([`crate::collections`]), so collections survive restarts and every
//! replica answers for every collection.

use std::collections::HashMap;
use std::time::Instant;

use axum::extract::State;
use axum::http::{header, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::Json;
use serde::{Deserialize, Serialize};
use serde_json::Value;
use utoipa::{IntoParams, ToSchema};

use crate::collections::{valid_id, Collection, CollectionShape, Match, NewShape};
use crate::http::auth::caller;
use crate::http::extract::{ApiJson, ApiPath, ApiQuery};
use crate::http::operation::{add_timing, run};
use crate::http::routes::mesh::take_descriptor;
use crate::http::AppState;
use crate::ops::mesh_descriptor::{DescriptorSpec, DescriptorValue, MeshDescriptorRequest};
use crate::problem::ApiError;
use crate::runner::Ran;

/// Longest collection, shape name or label, in characters.
pub const MAX_NAME: usize = 200;
/// Most neighbours a query returns.
pub const MAX_K: usize = 1000;

/// The id of a collection, in the path.
#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Path)]
pub struct CollectionPath {
    /// Collection id (`col_` followed by 32 hex digits).
    pub id: String,
}

/// Body of `POST /v1/collections`.
#[derive(Debug, Clone, Deserialize, Serialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"name": "poses", "descriptor": {"landmarks": 32, "bins": 32, "method": "fast_marching"}}))]
pub struct CreateCollection {
    /// A name, 1 to 200 characters.
    pub name: String,
    /// How descriptors are computed, the same for every shape of the
    /// collection. Default: 32 landmarks, 32 bins, fast marching.
    #[serde(default)]
    pub descriptor: DescriptorSpec,
}

/// Body of `POST /v1/collections/{id}/shapes`.
#[derive(Debug, Clone, Deserialize, Serialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"mesh": "ds_0192f1b27c1e7d3a9d553c0f2b8a1e44", "name": "cat-3", "label": "cat"}))]
pub struct AddShape {
    /// Id of the mesh dataset (one connected component).
    pub mesh: String,
    /// A name for the shape, up to 200 characters.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// A class label for the shape, up to 200 characters.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub label: Option<String>,
}

fn five() -> usize {
    5
}

/// Body of `POST /v1/collections/{id}/query`.
#[derive(Debug, Clone, Deserialize, Serialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"mesh": "ds_0192f1b27c1e7d3a9d553c0f2b8a1e44", "k": 5}))]
pub struct QueryCollection {
    /// Id of the query mesh dataset (one connected component).
    pub mesh: String,
    /// How many nearest shapes to return, 1 to 1000. Default 5.
    #[serde(default = "five")]
    #[schema(minimum = 1, maximum = 1000)]
    pub k: usize,
}

/// Query of the collection list.
#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct CollectionListQuery {
    /// Page size, 1 to 1000. Default: 50.
    #[param(minimum = 1, maximum = 1000)]
    pub limit: Option<i64>,
    /// `next_cursor` of the previous page.
    pub cursor: Option<String>,
}

/// A page of collections, newest first.
#[derive(Debug, Serialize, ToSchema)]
pub struct CollectionList {
    /// The collections.
    pub collections: Vec<Collection>,
    /// Pass as `cursor` for the next page; absent on the last page.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub next_cursor: Option<String>,
}

/// A collection and its shapes.
#[derive(Debug, Serialize, ToSchema)]
pub struct CollectionDetail {
    /// The collection.
    pub collection: Collection,
    /// Its shapes, oldest first.
    pub shapes: Vec<CollectionShape>,
}

/// Answer of `POST /v1/collections/{id}/shapes`.
#[derive(Debug, Serialize, ToSchema)]
pub struct AddedShape {
    /// The new shape.
    pub shape: CollectionShape,
    /// Its descriptor.
    pub descriptor: DescriptorValue,
    /// `solve_seconds`, `queue_seconds`, `total_seconds`, `vertices`.
    #[schema(value_type = Object)]
    pub stats: Value,
}

/// Answer of `POST /v1/collections/{id}/query`.
#[derive(Debug, Serialize, ToSchema)]
pub struct QueryAnswer {
    /// The collection.
    pub collection: String,
    /// The `k` nearest shapes (fewer if the collection holds fewer), nearest first.
    pub matches: Vec<Match>,
    /// `solve_seconds`, `queue_seconds`, `total_seconds`, `vertices` (of the query).
    #[schema(value_type = Object)]
    pub stats: Value,
}

fn not_found(id: &str) -> ApiError {
    ApiError::not_found(
        Some("id"),
        format!("collection '{id}' does not exist (list them with GET /v1/collections)"),
    )
}

fn check_name(field: &str, value: &str) -> Result<(), ApiError> {
    let n = value.chars().count();
    if n == 0 || n > MAX_NAME || value.chars().any(char::is_control) {
        return Err(ApiError::invalid_field(
            field,
            format!("give 1 to {MAX_NAME} characters without control characters (got {n})"),
        ));
    }
    Ok(())
}

async fn collection(state: &AppState, id: &str) -> Result<Collection, ApiError> {
    if !valid_id(id, "col_") {
        return Err(not_found(id));
    }
    state
        .collections
        .get(id, caller().tenant())
        .await?
        .ok_or_else(|| not_found(id))
}

/// Runs `mesh.descriptor` on `mesh` with the collection's options: the
/// descriptor and the stats of the run.
async fn describe(
    state: &AppState,
    mesh: &str,
    spec: DescriptorSpec,
    started: Instant,
) -> Result<(DescriptorValue, Value), ApiError> {
    let request = MeshDescriptorRequest::new(mesh.to_string(), spec);
    let Ran { mut output, timing } = run(state, Box::new(request), HashMap::new()).await?;
    let mut doc = output.document_map();
    add_timing(&mut doc, &timing, started);
    let descriptor = take_descriptor(&mut doc)?;
    let stats = doc.remove("stats").unwrap_or(Value::Null);
    Ok((descriptor, stats))
}

/// Creates a collection.
#[utoipa::path(
    post,
    path = "/v1/collections",
    tag = "collections",
    summary = "Create a shape collection",
    description = "An empty collection of shapes compared by their geodesic descriptors \
(`POST /v1/mesh/descriptor`). `descriptor` fixes how every shape's descriptor is computed (landmarks, bins, \
method), so that all are comparable. The answer is 201 with `Location`. Collections are stored in the jobs' \
database (SQLite, or PostgreSQL when scaled out) and survive restarts; they do not expire.",
    request_body(content = CreateCollection, content_type = "application/json"),
    responses(
        (status = 201, description = "Created.", body = Collection,
            headers(("Location" = String, description = "URL of the collection."))),
        (status = 400, response = crate::http::openapi::BadRequest),
        (status = 413, response = crate::http::openapi::PayloadTooLarge),
        (status = 415, response = crate::http::openapi::UnsupportedMediaType),
        (status = 422, response = crate::http::openapi::Unprocessable),
        (status = 500, response = crate::http::openapi::InternalError),
        (status = 503, response = crate::http::openapi::Busy),
    )
)]
pub async fn create_collection(
    State(state): State<AppState>,
    ApiJson(body): ApiJson<CreateCollection>,
) -> Result<Response, ApiError> {
    check_name("name", &body.name)?;
    body.descriptor.validate("descriptor.")?;
    let c = state
        .collections
        .create(&body.name, body.descriptor, caller().tenant())
        .await?;
    let mut res = (StatusCode::CREATED, Json(&c)).into_response();
    if let Ok(v) = HeaderValue::from_str(&c.url) {
        res.headers_mut().insert(header::LOCATION, v);
    }
    Ok(res)
}

/// Lists collections.
#[utoipa::path(
    get,
    path = "/v1/collections",
    tag = "collections",
    summary = "List shape collections",
    description = "Collections, newest first, with their shape counts. Pages of `limit`; pass `next_cursor` \
as `cursor` for the next page.",
    params(CollectionListQuery),
    responses(
        (status = 200, description = "A page of collections.", body = CollectionList),
        (status = 400, response = crate::http::openapi::BadRequest),
        (status = 422, response = crate::http::openapi::Unprocessable),
        (status = 500, response = crate::http::openapi::InternalError),
        (status = 503, response = crate::http::openapi::Busy),
    )
)]
pub async fn list_collections(
    State(state): State<AppState>,
    ApiQuery(query): ApiQuery<CollectionListQuery>,
) -> Result<Json<CollectionList>, ApiError> {
    let limit = super::check_page(
        query.limit,
        query.cursor.as_deref(),
        |c| valid_id(c, "col_"),
        "a collection id",
    )?;
    let mut collections = state
        .collections
        .list(caller().tenant(), query.cursor.as_deref(), limit + 1)
        .await?;
    let more = collections.len() as i64 > limit;
    collections.truncate(limit as usize);
    let next_cursor = if more {
        collections.last().map(|c| c.id.clone())
    } else {
        None
    };
    Ok(Json(CollectionList {
        collections,
        next_cursor,
    }))
}

/// Reads a collection.
#[utoipa::path(
    get,
    path = "/v1/collections/{id}",
    tag = "collections",
    summary = "Read a shape collection",
    description = "The collection, its descriptor options and its shapes (names, labels, source datasets), \
oldest first.",
    params(CollectionPath),
    responses(
        (status = 200, description = "The collection.", body = CollectionDetail),
        (status = 404, response = crate::http::openapi::NotFound),
        (status = 500, response = crate::http::openapi::InternalError),
        (status = 503, response = crate::http::openapi::Busy),
    )
)]
pub async fn get_collection(
    State(state): State<AppState>,
    ApiPath(path): ApiPath<CollectionPath>,
) -> Result<Json<CollectionDetail>, ApiError> {
    let collection = collection(&state, &path.id).await?;
    let shapes = state.collections.shapes(&path.id).await?;
    Ok(Json(CollectionDetail { collection, shapes }))
}

/// Deletes a collection.
#[utoipa::path(
    delete,
    path = "/v1/collections/{id}",
    tag = "collections",
    summary = "Delete a shape collection",
    description = "Removes the collection and every shape descriptor in it (the mesh datasets stay).",
    params(CollectionPath),
    responses(
        (status = 204, description = "Deleted."),
        (status = 404, response = crate::http::openapi::NotFound),
        (status = 500, response = crate::http::openapi::InternalError),
        (status = 503, response = crate::http::openapi::Busy),
    )
)]
pub async fn delete_collection(
    State(state): State<AppState>,
    ApiPath(path): ApiPath<CollectionPath>,
) -> Result<StatusCode, ApiError> {
    if !valid_id(&path.id, "col_")
        || !state
            .collections
            .delete(&path.id, caller().tenant())
            .await?
    {
        return Err(not_found(&path.id));
    }
    Ok(StatusCode::NO_CONTENT)
}

/// Adds a shape to a collection.
#[utoipa::path(
    post,
    path = "/v1/collections/{id}/shapes",
    tag = "collections",
    summary = "Add a mesh to a shape collection",
    description = "Computes the descriptor of the mesh dataset `mesh` with the collection's options \
(`mesh.descriptor`, on the solver pool under the request deadline) and stores it with the optional `name` \
and `label`. The descriptor is kept when the dataset expires. An unknown collection or mesh is a 404 naming \
`id` or `mesh`; a mesh of several components a 422 naming `mesh`.",
    params(CollectionPath),
    request_body(content = AddShape, content_type = "application/json"),
    responses(
        (status = 201, description = "Added.", body = AddedShape),
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
pub async fn add_shape(
    State(state): State<AppState>,
    ApiPath(path): ApiPath<CollectionPath>,
    ApiJson(body): ApiJson<AddShape>,
) -> Result<Response, ApiError> {
    let started = Instant::now();
    for (field, value) in [("name", &body.name), ("label", &body.label)] {
        if let Some(v) = value {
            check_name(field, v)?;
        }
    }
    let c = collection(&state, &path.id).await?;
    let (descriptor, stats) = describe(&state, &body.mesh, c.descriptor, started).await?;
    let vertices = stats.get("vertices").and_then(Value::as_i64).unwrap_or(0);
    let shape = state
        .collections
        .add(
            &c.id,
            NewShape {
                name: body.name,
                label: body.label,
                dataset: body.mesh,
                vertices,
                descriptor: descriptor.vector.clone(),
            },
        )
        .await?
        .ok_or_else(|| not_found(&c.id))?;
    let answer = AddedShape {
        shape,
        descriptor,
        stats,
    };
    Ok((StatusCode::CREATED, Json(answer)).into_response())
}

/// Queries a collection.
#[utoipa::path(
    post,
    path = "/v1/collections/{id}/query",
    tag = "collections",
    summary = "Find the shapes of a collection nearest to a mesh",
    description = "Computes the descriptor of the mesh dataset `mesh` with the collection's options and \
returns the `k` shapes of the collection with the smallest descriptor distance, nearest first, each with its \
`distance` in [0, 1] and `score = 1 − distance`. Invariant to rigid motion, scale, bending (pose) and \
remeshing of the query.",
    params(CollectionPath),
    request_body(content = QueryCollection, content_type = "application/json"),
    responses(
        (status = 200, description = "The nearest shapes.", body = QueryAnswer),
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
pub async fn query_collection(
    State(state): State<AppState>,
    ApiPath(path): ApiPath<CollectionPath>,
    ApiJson(body): ApiJson<QueryCollection>,
) -> Result<Json<QueryAnswer>, ApiError> {
    let started = Instant::now();
    if !(1..=MAX_K).contains(&body.k) {
        return Err(ApiError::invalid_field(
            "k",
            format!("{} is out of range: ask for 1 to {MAX_K} shapes", body.k),
        ));
    }
    let c = collection(&state, &path.id).await?;
    let (descriptor, mut stats) = describe(&state, &body.mesh, c.descriptor, started).await?;
    let matches = state
        .collections
        .nearest(&c.id, descriptor.vector, body.k)
        .await?;
    if let Some(s) = stats.as_object_mut() {
        s.insert(
            "total_seconds".into(),
            started.elapsed().as_secs_f64().into(),
        );
    }
    Ok(Json(QueryAnswer {
        collection: c.id,
        matches,
        stats,
    }))
}
