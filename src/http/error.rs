//! RFC 9457 problem details: every 4xx and 5xx answer of the service is an
//! `application/problem+json` [`Problem`].
//!
//! Handlers return [`ApiError`]; the [`finalize`] middleware then fills in
//! `instance` (the request path) and `request_id`, and turns any other error
//! answer (a 405 from the router, a 413 from a body limit) into a problem too.

use axum::body::Body;
use axum::extract::Request;
use axum::http::{header, HeaderValue, StatusCode};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use crate::datasets::StoreError;
use crate::io::IoError;
use crate::ops::OpError;
use crate::pool::PoolError;

/// Media type of every error body.
pub const PROBLEM_JSON: &str = "application/problem+json";

/// Base of the stable problem type URIs.
pub const TYPE_BASE: &str = "https://geodex.dev/problems/";

/// An RFC 9457 problem details object.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[schema(example = json!({
    "type": "https://geodex.dev/problems/invalid-field",
    "title": "A field of the request is invalid",
    "status": 422,
    "detail": "spacing[1]: -1 must be finite and > 0",
    "instance": "/v1/grid/distance",
    "request_id": "0192f1b2-7c1e-7d3a-9d55-3c0f2b8a1e44",
    "field": "spacing[1]"
}))]
pub struct Problem {
    /// A stable URI naming the kind of problem.
    #[serde(rename = "type")]
    pub type_uri: String,
    /// A short summary of the kind of problem (the same for every occurrence).
    pub title: String,
    /// The HTTP status code.
    pub status: u16,
    /// What went wrong this time, naming the field and the reason.
    pub detail: String,
    /// The path of the request.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub instance: Option<String>,
    /// The `x-request-id` of the request (also in the response header).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub request_id: Option<String>,
    /// JSON path of the offending field, when known (`sources[0].point`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub field: Option<String>,
}

/// An error answer: a problem plus an optional `Retry-After`.
#[derive(Debug, Clone, PartialEq)]
pub struct ApiError {
    /// The problem body (boxed: errors travel in `Result`s).
    pub problem: Box<Problem>,
    /// Seconds for the `Retry-After` header (503).
    pub retry_after: Option<u64>,
}

impl ApiError {
    /// A problem of kind `slug` (the last segment of its type URI).
    pub fn new(status: StatusCode, slug: &str, title: &str, detail: impl Into<String>) -> Self {
        Self {
            problem: Box::new(Problem {
                type_uri: format!("{TYPE_BASE}{slug}"),
                title: title.into(),
                status: status.as_u16(),
                detail: detail.into(),
                instance: None,
                request_id: None,
                field: None,
            }),
            retry_after: None,
        }
    }

    /// Names the offending field.
    pub fn with_field(mut self, field: impl Into<String>) -> Self {
        self.problem.field = Some(field.into());
        self
    }

    /// The HTTP status.
    pub fn status(&self) -> StatusCode {
        StatusCode::from_u16(self.problem.status).unwrap_or(StatusCode::INTERNAL_SERVER_ERROR)
    }

    /// 400: the body cannot be parsed (malformed JSON, corrupt file).
    pub fn bad_request(field: &str, detail: impl Into<String>) -> Self {
        Self::new(
            StatusCode::BAD_REQUEST,
            "malformed-request",
            "The request cannot be parsed",
            detail,
        )
        .with_field(field)
    }

    /// 422: a value is well-formed but not acceptable.
    pub fn invalid_field(field: impl Into<String>, detail: impl Into<String>) -> Self {
        let field = field.into();
        let detail = detail.into();
        Self::new(
            StatusCode::UNPROCESSABLE_ENTITY,
            "invalid-field",
            "A field of the request is invalid",
            format!("{field}: {detail}"),
        )
        .with_field(field)
    }

    /// 404: a dataset (or route) does not exist.
    pub fn not_found(field: Option<&str>, detail: impl Into<String>) -> Self {
        let e = Self::new(
            StatusCode::NOT_FOUND,
            "not-found",
            "The resource does not exist",
            detail,
        );
        match field {
            Some(f) => e.with_field(f),
            None => e,
        }
    }

    /// 413: the body or the array is larger than the limits.
    pub fn too_large(field: &str, detail: impl Into<String>) -> Self {
        Self::new(
            StatusCode::PAYLOAD_TOO_LARGE,
            "too-large",
            "The request is larger than the limits",
            detail,
        )
        .with_field(field)
    }

    /// 415: the body's media type is not accepted here.
    pub fn unsupported_media_type(detail: impl Into<String>) -> Self {
        Self::new(
            StatusCode::UNSUPPORTED_MEDIA_TYPE,
            "unsupported-media-type",
            "The media type of the body is not supported",
            detail,
        )
        .with_field("Content-Type")
    }

    /// 406: the representation asked for cannot be produced.
    pub fn not_acceptable(detail: impl Into<String>) -> Self {
        Self::new(
            StatusCode::NOT_ACCEPTABLE,
            "not-acceptable",
            "The requested representation is not available",
            detail,
        )
        .with_field("Accept")
    }

    /// 503: the solver pool is full.
    pub fn busy(detail: impl Into<String>, retry_after: u64) -> Self {
        let mut e = Self::new(
            StatusCode::SERVICE_UNAVAILABLE,
            "busy",
            "The service is busy",
            detail,
        );
        e.retry_after = Some(retry_after);
        e
    }

    /// 504: the solve passed its deadline and was cancelled.
    pub fn deadline(detail: impl Into<String>) -> Self {
        Self::new(
            StatusCode::GATEWAY_TIMEOUT,
            "deadline-exceeded",
            "The computation did not finish in time",
            detail,
        )
    }

    /// 507: the storage quota is used up.
    pub fn insufficient_storage(detail: impl Into<String>) -> Self {
        Self::new(
            StatusCode::INSUFFICIENT_STORAGE,
            "storage-full",
            "The storage quota is used up",
            detail,
        )
    }

    /// 500: a bug or an IO failure; the detail is logged, not sent.
    pub fn internal(detail: impl std::fmt::Display) -> Self {
        tracing::error!(error = %detail, "internal error");
        Self::new(
            StatusCode::INTERNAL_SERVER_ERROR,
            "internal",
            "Internal server error",
            "the server failed to handle the request; see its logs",
        )
    }

    /// The generic problem for a bare status from the framework.
    pub fn from_status(status: StatusCode) -> Self {
        let reason = status.canonical_reason().unwrap_or("Error");
        let (slug, detail) = match status {
            StatusCode::NOT_FOUND => ("not-found", "no route matches this path".to_string()),
            StatusCode::METHOD_NOT_ALLOWED => (
                "method-not-allowed",
                "this route does not accept this method; see the Allow header".to_string(),
            ),
            StatusCode::PAYLOAD_TOO_LARGE => (
                "too-large",
                "the body is larger than the configured limit".to_string(),
            ),
            StatusCode::UNSUPPORTED_MEDIA_TYPE => (
                "unsupported-media-type",
                "unsupported media type".to_string(),
            ),
            StatusCode::NOT_ACCEPTABLE => {
                ("not-acceptable", "no acceptable representation".to_string())
            }
            s if s.is_server_error() => ("internal", reason.to_lowercase()),
            _ => ("http-error", reason.to_lowercase()),
        };
        Self::new(status, slug, reason, detail)
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let status = self.status();
        let body = serde_json::to_vec(&self.problem).unwrap_or_default();
        let mut res = (status, body).into_response();
        res.headers_mut()
            .insert(header::CONTENT_TYPE, HeaderValue::from_static(PROBLEM_JSON));
        if let Some(secs) = self.retry_after {
            res.headers_mut()
                .insert(header::RETRY_AFTER, HeaderValue::from(secs));
        }
        res.extensions_mut().insert(*self.problem);
        res
    }
}

impl From<OpError> for ApiError {
    fn from(e: OpError) -> Self {
        match e {
            OpError::Invalid { field, reason } => ApiError::invalid_field(field, reason),
            OpError::UnknownDataset { field, id } => ApiError::not_found(
                Some(&field),
                format!("{field}: dataset '{id}' does not exist (or has expired)"),
            ),
            OpError::TooLarge { field, reason } => {
                let detail = format!("{field}: {reason}");
                ApiError::too_large(&field, detail)
            }
            OpError::Cancelled => {
                ApiError::deadline("the computation was cancelled before it finished")
            }
        }
    }
}

/// Maps a decoding error of the input named `field`.
pub fn io_error(e: IoError, field: &str) -> ApiError {
    match e {
        IoError::UnknownFormat(_) => ApiError::unsupported_media_type(format!(
            "{field}: {e}; send NPY, PNG, JPEG, TIFF or NIfTI, or name it with ?format="
        ))
        .with_field(field),
        IoError::Corrupt { .. } => ApiError::bad_request(field, format!("{field}: {e}")),
        IoError::Unsupported { .. } | IoError::Encode(_) => {
            ApiError::invalid_field(field, e.to_string())
        }
        IoError::TooLarge { .. } => ApiError::too_large(field, format!("{field}: {e}")),
    }
}

impl From<crate::datasets::inputs::InputError> for ApiError {
    fn from(e: crate::datasets::inputs::InputError) -> Self {
        use crate::datasets::inputs::InputError;
        match e {
            InputError::NotFound { field, id } => OpError::UnknownDataset { field, id }.into(),
            InputError::WrongKind {
                field,
                id,
                expected,
            } => OpError::invalid(field, format!("dataset '{id}' is not {expected}")).into(),
            InputError::Store(e) => e.into(),
        }
    }
}

impl From<StoreError> for ApiError {
    fn from(e: StoreError) -> Self {
        match e {
            StoreError::NotFound(id) => ApiError::not_found(
                Some("id"),
                format!("dataset '{id}' does not exist (or has expired)"),
            ),
            StoreError::Quota { .. } => ApiError::insufficient_storage(e.to_string()),
            StoreError::Codec(io) => io_error(io, "body"),
            StoreError::Io(_) => ApiError::internal(e),
        }
    }
}

impl From<PoolError> for ApiError {
    fn from(e: PoolError) -> Self {
        match e {
            PoolError::Busy { .. } => ApiError::busy(e.to_string(), 1),
            PoolError::Deadline(_) => ApiError::deadline(e.to_string()),
            PoolError::Lost => ApiError::internal(e),
        }
    }
}

/// Middleware: completes problem bodies with `instance` and `request_id`, and
/// turns bare framework error answers (>= 400, not problem+json) into problems.
pub async fn finalize(req: Request, next: Next) -> Response {
    let instance = req.uri().path().to_string();
    let request_id = req
        .headers()
        .get("x-request-id")
        .and_then(|v| v.to_str().ok())
        .map(str::to_string);
    let res = next.run(req).await;
    let status = res.status();
    if !(status.is_client_error() || status.is_server_error()) {
        return res;
    }
    let (mut parts, body) = res.into_parts();
    let mut problem = match parts.extensions.remove::<Problem>() {
        Some(p) => p,
        None => {
            let is_problem = parts
                .headers
                .get(header::CONTENT_TYPE)
                .is_some_and(|v| v.as_bytes().starts_with(PROBLEM_JSON.as_bytes()));
            if is_problem {
                return Response::from_parts(parts, body);
            }
            *ApiError::from_status(status).problem
        }
    };
    problem.instance = Some(instance);
    problem.request_id = request_id;
    let bytes = serde_json::to_vec(&problem).unwrap_or_default();
    parts
        .headers
        .insert(header::CONTENT_TYPE, HeaderValue::from_static(PROBLEM_JSON));
    parts.headers.remove(header::CONTENT_LENGTH);
    parts.headers.remove(header::CONTENT_ENCODING);
    Response::from_parts(parts, Body::from(bytes))
}

/// Body of a caught panic (for `CatchPanicLayer::custom`): a 500 problem.
pub fn panic_response(_err: Box<dyn std::any::Any + Send + 'static>) -> Response {
    ApiError::internal("a handler panicked").into_response()
}

/// Fallback for unknown routes: a 404 problem.
pub async fn fallback() -> ApiError {
    ApiError::not_found(None, "no route matches this path; see /docs")
}
