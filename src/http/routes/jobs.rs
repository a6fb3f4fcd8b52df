//! `/v1/jobs`: run any operation as a durable background job.
//!
//! Submit with `POST /v1/jobs` (or send `Prefer: respond-async` to an
//! operation's synchronous endpoint), poll `GET /v1/jobs/{id}` (with
//! `Retry-After` while it is not done), cancel with `POST /v1/jobs/{id}/cancel`,
//! and download each result array from `GET /v1/jobs/{id}/results/{name}`.
//! Every replica answers for every job: the record is in the shared database
//! and the arrays in the shared object store.

use axum::extract::State;
use axum::http::{header, HeaderMap, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::Json;
use serde::{Deserialize, Serialize};
use utoipa::{IntoParams, ToSchema};

use crate::http::auth::caller;
use crate::http::extract::{ApiJson, ApiPath, ApiQuery};
use crate::http::routes::datasets::{cast_float, encode, negotiate, DataQuery, OutputFormat};
use crate::http::AppState;
use crate::io::{self, Format};
use crate::jobs::{Job, JobState, Jobs, Priority, SubmitJob};
use crate::ops::Operation;
use crate::problem::{ApiError, Kind};

/// Header naming a client's idempotency key.
pub const IDEMPOTENCY_KEY: &str = "idempotency-key";

/// Seconds a client should wait between polls of an unfinished job.
pub const RETRY_AFTER_SECS: u64 = 1;

/// The id of a job, in the path.
#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Path)]
pub struct JobPath {
    /// Job id (`job_` followed by 32 hex digits).
    pub id: String,
}

/// A job id and a result name, in the path.
#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Path)]
pub struct ResultPath {
    /// Job id.
    pub id: String,
    /// Name of the output array (`distance`, `labels`, ...).
    pub name: String,
}

/// Query of the job list.
#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct ListQuery {
    /// Only jobs in this state.
    #[param(inline)]
    pub state: Option<JobState>,
    /// Page size, 1 to 1000. Default: 50.
    #[param(minimum = 1, maximum = 1000)]
    pub limit: Option<i64>,
    /// `next_cursor` of the previous page.
    pub cursor: Option<String>,
}

/// A page of jobs, newest first.
#[derive(Debug, Serialize, ToSchema)]
pub struct JobList {
    /// The jobs.
    pub jobs: Vec<Job>,
    /// Pass as `cursor` for the next page; absent on the last page.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub next_cursor: Option<String>,
}

fn idempotency_key(headers: &HeaderMap) -> Result<Option<String>, ApiError> {
    match headers.get(IDEMPOTENCY_KEY) {
        None => Ok(None),
        Some(v) => v.to_str().map(|s| Some(s.trim().to_string())).map_err(|_| {
            ApiError::invalid_field("Idempotency-Key", "must be 1 to 255 ASCII characters")
        }),
    }
}

/// 202 Accepted with `Location`, `Retry-After` and the job.
fn accepted(job: &Job, created: bool) -> Response {
    let mut res = (StatusCode::ACCEPTED, Json(job)).into_response();
    let h = res.headers_mut();
    if let Ok(v) = HeaderValue::from_str(&job.url) {
        h.insert(header::LOCATION, v);
    }
    h.insert(header::RETRY_AFTER, HeaderValue::from(RETRY_AFTER_SECS));
    if !created {
        h.insert("idempotent-replayed", HeaderValue::from_static("true"));
    }
    res
}

/// True if the request carries `Prefer: respond-async` (RFC 7240).
pub fn prefers_async(headers: &HeaderMap) -> bool {
    headers.get_all("prefer").iter().any(|v| {
        v.to_str().is_ok_and(|s| {
            s.split([',', ';'])
                .any(|t| t.trim().eq_ignore_ascii_case("respond-async"))
        })
    })
}

/// The asynchronous form of an operation's synchronous endpoint: queues the
/// request as an `interactive` job and answers 202 with `Location` and
/// `Retry-After` (and `Preference-Applied: respond-async`). Endpoints call it
/// first when [`prefers_async`] is true.
pub async fn respond_async<O: Operation>(
    state: &AppState,
    headers: &HeaderMap,
    request: &O,
) -> Result<Response, ApiError> {
    let params = serde_json::to_value(request).map_err(ApiError::internal)?;
    let submit = SubmitJob {
        operation: O::NAME.to_string(),
        params,
        priority: None,
        time_limit_secs: None,
    };
    let (job, created) = state
        .jobs
        .submit(
            submit,
            idempotency_key(headers)?,
            Priority::Interactive,
            &caller().owner,
        )
        .await?;
    let mut res = accepted(&job, created);
    res.headers_mut().insert(
        "preference-applied",
        HeaderValue::from_static("respond-async"),
    );
    Ok(res)
}

/// Submits a job.
#[utoipa::path(
    post,
    path = "/v1/jobs",
    tag = "jobs",
    summary = "Submit a job",
    description = "Queues an operation to run in the background. `params` is the body of the operation's \
synchronous endpoint (`grid.distance`: the body of `POST /v1/grid/distance`) and is validated now: a bad request \
is refused here (4xx naming `params.<field>`), never after queueing. The answer is 202 with `Location: /v1/jobs/{id}` \
and `Retry-After`. With an `Idempotency-Key` header, sending the same request again returns the first job \
(with `Idempotent-Replayed: true`) instead of queueing a second one; the same key with a different request is \
refused (422). Keys live as long as the job record (the retention period). `interactive` jobs are claimed before \
`batch` jobs (the default). A job that runs past `time_limit_secs` ends `failed`.",
    params(
        ("Idempotency-Key" = Option<String>, Header, description = "A client-chosen key (1 to 255 ASCII characters) that makes the submission idempotent."),
    ),
    request_body(content = SubmitJob, content_type = "application/json"),
    responses(
        (status = 202, description = "The job is queued (or, with a replayed Idempotency-Key, the first job).", body = Job,
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
    )
)]
pub async fn submit(
    State(state): State<AppState>,
    headers: HeaderMap,
    ApiJson(body): ApiJson<SubmitJob>,
) -> Result<Response, ApiError> {
    let key = idempotency_key(&headers)?;
    let (job, created) = state
        .jobs
        .submit(body, key, Priority::Batch, &caller().owner)
        .await?;
    Ok(accepted(&job, created))
}

/// Lists jobs.
#[utoipa::path(
    get,
    path = "/v1/jobs",
    tag = "jobs",
    summary = "List jobs",
    description = "Jobs, newest first, optionally only those in one `state`. Pages of `limit` jobs; pass \
`next_cursor` as `cursor` for the next page.",
    params(ListQuery),
    responses(
        (status = 200, description = "A page of jobs.", body = JobList),
        (status = 400, response = crate::http::openapi::BadRequest),
        (status = 422, response = crate::http::openapi::Unprocessable),
        (status = 500, response = crate::http::openapi::InternalError),
        (status = 503, response = crate::http::openapi::Busy),
    )
)]
pub async fn list(
    State(state): State<AppState>,
    ApiQuery(query): ApiQuery<ListQuery>,
) -> Result<Json<JobList>, ApiError> {
    let limit = super::check_page(
        query.limit,
        query.cursor.as_deref(),
        crate::jobs::valid_id,
        "a job id",
    )?;
    let rows = state
        .jobs
        .list(
            caller().tenant(),
            query.state,
            query.cursor.as_deref(),
            limit + 1,
        )
        .await?;
    let more = rows.len() as i64 > limit;
    let jobs: Vec<Job> = rows.iter().take(limit as usize).map(Job::from).collect();
    let next_cursor = if more {
        jobs.last().map(|j| j.id.clone())
    } else {
        None
    };
    Ok(Json(JobList { jobs, next_cursor }))
}

fn job_not_found(id: &str) -> ApiError {
    ApiError::not_found(
        Some("id"),
        format!("job '{id}' does not exist (or has expired)"),
    )
}

/// Reads a job.
#[utoipa::path(
    get,
    path = "/v1/jobs/{id}",
    tag = "jobs",
    summary = "Read a job",
    description = "State (`queued`, `running`, `succeeded`, `failed`, `cancelled`), progress 0..1 reported \
by the solver, times, attempts, the result (one reference per output array, plus the operation's document) \
when succeeded, and the problem when failed or cancelled. While the job is not done the answer carries \
`Retry-After`.",
    params(JobPath),
    responses(
        (status = 200, description = "The job.", body = Job),
        (status = 404, response = crate::http::openapi::NotFound),
        (status = 500, response = crate::http::openapi::InternalError),
        (status = 503, response = crate::http::openapi::Busy),
    )
)]
pub async fn get(
    State(state): State<AppState>,
    ApiPath(path): ApiPath<JobPath>,
) -> Result<Response, ApiError> {
    let row = state
        .jobs
        .get(&path.id, caller().tenant())
        .await?
        .ok_or_else(|| job_not_found(&path.id))?;
    let job = Job::from(&row);
    let mut res = Json(&job).into_response();
    if !job.state.is_final() {
        res.headers_mut()
            .insert(header::RETRY_AFTER, HeaderValue::from(RETRY_AFTER_SECS));
    }
    Ok(res)
}

/// Cancels a job.
#[utoipa::path(
    post,
    path = "/v1/jobs/{id}/cancel",
    tag = "jobs",
    summary = "Cancel a job",
    description = "A queued job ends `cancelled` at once and never starts (200). A running job is asked to \
stop (202): its solver stops within a second on whichever replica runs it, and the job then ends `cancelled`. \
Cancelling a cancelled job is a no-op (200); a job that already succeeded or failed cannot be cancelled (409).",
    params(JobPath),
    responses(
        (status = 200, description = "The job is cancelled.", body = Job),
        (status = 202, description = "The running job was asked to stop.", body = Job),
        (status = 404, response = crate::http::openapi::NotFound),
        (status = 409, response = crate::http::openapi::Conflict),
        (status = 500, response = crate::http::openapi::InternalError),
        (status = 503, response = crate::http::openapi::Busy),
    )
)]
pub async fn cancel(
    State(state): State<AppState>,
    ApiPath(path): ApiPath<JobPath>,
) -> Result<Response, ApiError> {
    let row = state
        .jobs
        .cancel(&path.id, caller().tenant())
        .await?
        .ok_or_else(|| job_not_found(&path.id))?;
    let job = Job::from(&row);
    match job.state {
        JobState::Cancelled => Ok(Json(&job).into_response()),
        JobState::Queued | JobState::Running => {
            let mut res = (StatusCode::ACCEPTED, Json(&job)).into_response();
            res.headers_mut()
                .insert(header::RETRY_AFTER, HeaderValue::from(RETRY_AFTER_SECS));
            Ok(res)
        }
        JobState::Succeeded | JobState::Failed => Err(ApiError::of(
            Kind::JobFinished,
            format!(
                "job '{}' already {}; there is nothing to cancel",
                job.id,
                job.state.as_str()
            ),
        )
        .with_field("id")),
    }
}

/// Downloads one result array of a job.
#[utoipa::path(
    get,
    path = "/v1/jobs/{id}/results/{name}",
    tag = "jobs",
    summary = "Download a job result",
    description = "One output array of a succeeded job (`distance`, `labels`, ...; the names are the keys \
of the job's `result` that hold a `url`), in the representation named by `?format=`, else by `Accept`, else \
NPY: `npy`, `tiff`, `png16`, `png` or `json` (as for datasets). Any replica serves any result.",
    params(ResultPath, DataQuery),
    responses(
        (status = 200, description = "The array.",
            content(
                (crate::http::openapi::FileBytes = "application/x-npy"),
                (crate::http::openapi::FileBytes = "image/tiff"),
                (crate::http::openapi::FileBytes = "image/png"),
                (crate::http::routes::datasets::ArrayJson = "application/json"),
            )
        ),
        (status = 400, response = crate::http::openapi::BadRequest),
        (status = 404, response = crate::http::openapi::NotFound),
        (status = 406, response = crate::http::openapi::NotAcceptable),
        (status = 409, response = crate::http::openapi::Conflict),
        (status = 500, response = crate::http::openapi::InternalError),
        (status = 503, response = crate::http::openapi::Busy),
    )
)]
pub async fn result(
    State(state): State<AppState>,
    ApiPath(path): ApiPath<ResultPath>,
    ApiQuery(query): ApiQuery<DataQuery>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let row = state
        .jobs
        .get(&path.id, caller().tenant())
        .await?
        .ok_or_else(|| job_not_found(&path.id))?;
    if row.state != JobState::Succeeded {
        return Err(ApiError::of(
            Kind::JobNotSucceeded,
            format!(
                "job '{}' is {}; results exist once it succeeded",
                row.id, row.state
            ),
        )
        .with_field("id"));
    }
    let outputs = Jobs::outputs(&row);
    let out = outputs.get(&path.name).ok_or_else(|| {
        ApiError::not_found(
            Some("name"),
            format!(
                "job '{}' has no result '{}'; it has: {}",
                row.id,
                path.name,
                outputs.keys().cloned().collect::<Vec<_>>().join(", ")
            ),
        )
    })?;
    let bytes = state
        .jobs
        .results()
        .get(&out.key)
        .await
        .map_err(ApiError::internal)?;
    let format = negotiate(query.format, &headers);
    if format == OutputFormat::Npy && query.dtype.is_none() {
        return Ok(([(header::CONTENT_TYPE, "application/x-npy")], bytes).into_response());
    }
    let limits = state.jobs.io_limits();
    let (body, media) = tokio::task::spawn_blocking(move || {
        let decoded = io::decode(&bytes, Some(Format::Npy), &limits).map_err(ApiError::internal)?;
        match query.conversion(format, decoded.array.dtype())? {
            Some(dtype) => encode(&cast_float(&decoded.array, dtype), format),
            None => encode(&decoded.array, format),
        }
    })
    .await
    .map_err(ApiError::internal)??;
    Ok(([(header::CONTENT_TYPE, media)], body).into_response())
}
