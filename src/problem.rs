//! RFC 9457 problem details, below every layer that reports them.
//!
//! Every 4xx and 5xx answer of the service, every failed job's `error` and
//! every refusal of the command line is one [`Problem`]: a stable `type` URI,
//! a title, a status, a `detail` naming the field and the way out, and the
//! JSON path of the field at fault. [`ApiError`] carries one through
//! `Result`s (with an optional `Retry-After`).
//!
//! The kinds of problem are one table, [`Kind`]: its slug (the last segment
//! of the type URI), its title and its status. The mappings from the errors of
//! the layers below (operations, codecs, the dataset store, the solver pool)
//! live here too, so `http` only turns an [`ApiError`] into a response and
//! `jobs` stores it as a job's error: neither knows the other.

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use crate::datasets::inputs::InputError;
use crate::datasets::StoreError;
use crate::io::IoError;
use crate::ops::parse::ParseError;
use crate::ops::registry::PrepareError;
use crate::ops::OpError;
use crate::pool::PoolError;

/// Media type of every error body.
pub const PROBLEM_JSON: &str = "application/problem+json";

/// Base of the stable problem type URIs.
pub const TYPE_BASE: &str = "https://geodex.dev/problems/";

/// Every kind of problem the service reports: slug, title and status in one
/// table ([`Kind::ALL`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// 400: the body cannot be parsed (malformed JSON, corrupt file).
    MalformedRequest,
    /// 422: a value is well-formed but not acceptable.
    InvalidField,
    /// 404: a dataset, job or route does not exist.
    NotFound,
    /// 405: the route does not accept the method.
    MethodNotAllowed,
    /// 406: the representation asked for cannot be produced.
    NotAcceptable,
    /// 413: the body or the array is larger than the limits.
    TooLarge,
    /// 415: the body's media type is not accepted here.
    UnsupportedMediaType,
    /// 408: the request body stopped arriving (see `--body-timeout-secs`).
    RequestTimeout,
    /// 409: a job was cancelled before it finished.
    Cancelled,
    /// 409: a job already ended (it cannot be cancelled).
    JobFinished,
    /// 409: a job has no results (it did not succeed).
    JobNotSucceeded,
    /// 500: a bug or an IO failure.
    Internal,
    /// 500: every attempt of a job ended with its worker gone.
    AttemptsExhausted,
    /// 503: the solver pool is full.
    Busy,
    /// 504: a synchronous solve passed its deadline.
    DeadlineExceeded,
    /// 504: a job ran past its time limit.
    TimeLimit,
    /// 507: the storage quota is used up.
    StorageFull,
    /// 401: no API key, or one that is unknown or revoked.
    Unauthorized,
    /// 403: the request is not allowed (a cross-site browser request, an
    /// admin route without an admin key).
    Forbidden,
    /// 429: the key's rate limit is reached.
    RateLimited,
}

impl Kind {
    /// The whole table, for documentation and tests.
    pub const ALL: &'static [Kind] = &[
        Kind::MalformedRequest,
        Kind::InvalidField,
        Kind::NotFound,
        Kind::MethodNotAllowed,
        Kind::NotAcceptable,
        Kind::TooLarge,
        Kind::UnsupportedMediaType,
        Kind::RequestTimeout,
        Kind::Cancelled,
        Kind::JobFinished,
        Kind::JobNotSucceeded,
        Kind::Internal,
        Kind::AttemptsExhausted,
        Kind::Busy,
        Kind::DeadlineExceeded,
        Kind::TimeLimit,
        Kind::StorageFull,
        Kind::Unauthorized,
        Kind::Forbidden,
        Kind::RateLimited,
    ];

    /// `(slug, title, status)` of this kind.
    pub const fn row(self) -> (&'static str, &'static str, u16) {
        match self {
            Kind::MalformedRequest => ("malformed-request", "The request cannot be parsed", 400),
            Kind::InvalidField => ("invalid-field", "A field of the request is invalid", 422),
            Kind::NotFound => ("not-found", "The resource does not exist", 404),
            Kind::MethodNotAllowed => ("method-not-allowed", "Method Not Allowed", 405),
            Kind::NotAcceptable => (
                "not-acceptable",
                "The requested representation is not available",
                406,
            ),
            Kind::TooLarge => ("too-large", "The request is larger than the limits", 413),
            Kind::UnsupportedMediaType => (
                "unsupported-media-type",
                "The media type of the body is not supported",
                415,
            ),
            Kind::RequestTimeout => ("request-timeout", "The request body stopped arriving", 408),
            Kind::Cancelled => ("cancelled", "The job was cancelled", 409),
            Kind::JobFinished => ("job-finished", "The job already ended", 409),
            Kind::JobNotSucceeded => ("job-not-succeeded", "The job has no results", 409),
            Kind::Internal => ("internal", "Internal server error", 500),
            Kind::AttemptsExhausted => (
                "attempts-exhausted",
                "The job's worker stopped too many times",
                500,
            ),
            Kind::Busy => ("busy", "The service is busy", 503),
            Kind::DeadlineExceeded => (
                "deadline-exceeded",
                "The computation did not finish in time",
                504,
            ),
            Kind::TimeLimit => ("time-limit", "The job ran past its time limit", 504),
            Kind::StorageFull => ("storage-full", "The storage quota is used up", 507),
            Kind::Unauthorized => ("unauthorized", "An API key is needed", 401),
            Kind::Forbidden => ("forbidden", "The request is not allowed", 403),
            Kind::RateLimited => ("rate-limited", "Too many requests", 429),
        }
    }

    /// The last segment of the type URI (`invalid-field`).
    pub const fn slug(self) -> &'static str {
        self.row().0
    }

    /// The title, the same for every occurrence.
    pub const fn title(self) -> &'static str {
        self.row().1
    }

    /// The HTTP status.
    pub const fn status(self) -> u16 {
        self.row().2
    }

    /// The kind whose slug is `slug`, if any.
    pub fn from_slug(slug: &str) -> Option<Kind> {
        Kind::ALL.iter().copied().find(|k| k.slug() == slug)
    }
}

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
    /// A problem of kind `kind`.
    pub fn of(kind: Kind, detail: impl Into<String>) -> Self {
        Self::custom(kind.status(), kind.slug(), kind.title(), detail)
    }

    /// A problem outside the table (a bare framework status): prefer [`ApiError::of`].
    pub fn custom(status: u16, slug: &str, title: &str, detail: impl Into<String>) -> Self {
        Self {
            problem: Box::new(Problem {
                type_uri: format!("{TYPE_BASE}{slug}"),
                title: title.into(),
                status,
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

    /// The HTTP status code.
    pub fn status_code(&self) -> u16 {
        self.problem.status
    }

    /// True for a 5xx: the server's fault, worth a retry.
    pub fn is_server_error(&self) -> bool {
        self.problem.status >= 500
    }

    /// 400: the body cannot be parsed (malformed JSON, corrupt file).
    pub fn bad_request(field: &str, detail: impl Into<String>) -> Self {
        Self::of(Kind::MalformedRequest, detail).with_field(field)
    }

    /// 422: a value is well-formed but not acceptable.
    pub fn invalid_field(field: impl Into<String>, detail: impl Into<String>) -> Self {
        let field = field.into();
        let detail = detail.into();
        Self::of(Kind::InvalidField, format!("{field}: {detail}")).with_field(field)
    }

    /// 404: a dataset (or route) does not exist.
    pub fn not_found(field: Option<&str>, detail: impl Into<String>) -> Self {
        let e = Self::of(Kind::NotFound, detail);
        match field {
            Some(f) => e.with_field(f),
            None => e,
        }
    }

    /// 413: the body or the array is larger than the limits.
    pub fn too_large(field: &str, detail: impl Into<String>) -> Self {
        Self::of(Kind::TooLarge, detail).with_field(field)
    }

    /// 408: the body stalled for longer than the body timeout.
    pub fn request_timeout(detail: impl Into<String>) -> Self {
        Self::of(Kind::RequestTimeout, detail).with_field("body")
    }

    /// 415: the body's media type is not accepted here.
    pub fn unsupported_media_type(detail: impl Into<String>) -> Self {
        Self::of(Kind::UnsupportedMediaType, detail).with_field("Content-Type")
    }

    /// 406: the representation asked for cannot be produced.
    pub fn not_acceptable(detail: impl Into<String>) -> Self {
        Self::of(Kind::NotAcceptable, detail).with_field("Accept")
    }

    /// 503: the solver pool is full.
    pub fn busy(detail: impl Into<String>, retry_after: u64) -> Self {
        let mut e = Self::of(Kind::Busy, detail);
        e.retry_after = Some(retry_after);
        e
    }

    /// 504: the solve passed its deadline and was cancelled.
    pub fn deadline(detail: impl Into<String>) -> Self {
        Self::of(Kind::DeadlineExceeded, detail)
    }

    /// 507: the storage quota is used up.
    pub fn insufficient_storage(detail: impl Into<String>) -> Self {
        Self::of(Kind::StorageFull, detail)
    }

    /// 500: a bug or an IO failure; the detail is logged, not sent.
    pub fn internal(detail: impl std::fmt::Display) -> Self {
        tracing::error!(error = %detail, "internal error");
        Self::of(
            Kind::Internal,
            "the server failed to handle the request; see its logs",
        )
    }

    /// Prefixes the field of this problem with `prefix.` (`params.sources[0]`),
    /// for a request nested in another (a job's `params`, a form's part).
    pub fn nested_in(mut self, prefix: &str) -> Self {
        match self.problem.field.take() {
            Some(f) if f != "body" && f != "Content-Type" => {
                if self.problem.detail.starts_with(&f) {
                    self.problem.detail = format!("{prefix}.{}", self.problem.detail);
                } else {
                    self.problem.detail = format!("{prefix}.{f}: {}", self.problem.detail);
                }
                self.problem.field = Some(format!("{prefix}.{f}"));
            }
            _ => {
                self.problem.detail = format!("{prefix}: {}", self.problem.detail);
                self.problem.field = Some(prefix.to_string());
            }
        }
        self
    }

    /// The problem as a JSON string, with `instance` set to `instance` when
    /// not empty (a job's error column).
    pub fn to_json(&self, instance: &str) -> String {
        let mut p = (*self.problem).clone();
        p.instance = (!instance.is_empty()).then(|| instance.to_string());
        serde_json::to_string(&p).unwrap_or_default()
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

impl From<ParseError> for ApiError {
    fn from(e: ParseError) -> Self {
        match e {
            ParseError::Syntax(_) => ApiError::bad_request("body", e.to_string()),
            ParseError::Data { field, reason } => ApiError::invalid_field(field, reason),
            ParseError::TooManyValues { .. } => ApiError::too_large("body", e.to_string()),
        }
    }
}

/// A job's `params` that are not a request: the field is under `params.`.
impl From<PrepareError> for ApiError {
    fn from(e: PrepareError) -> Self {
        match e {
            PrepareError::Parse(e) => ApiError::from(e),
            PrepareError::Invalid(e) => ApiError::from(e),
        }
        .nested_in("params")
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

impl From<InputError> for ApiError {
    fn from(e: InputError) -> Self {
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
            StoreError::Quota { .. } => ApiError::insufficient_storage(format!(
                "{e}; delete datasets you no longer need (DELETE /v1/datasets/{{id}}) or wait \
                 for them to expire"
            )),
            StoreError::TenantQuota { .. } => ApiError::insufficient_storage(format!(
                "{e}; delete datasets you no longer need (DELETE /v1/datasets/{{id}}), or ask \
                 the operator for a larger quota on your key"
            )),
            StoreError::Codec(io) => io_error(io, "body"),
            StoreError::Io(_) => ApiError::internal(e),
            StoreError::DiskFull => ApiError::insufficient_storage(
                "the disk of the data directory is full: nothing was stored; delete datasets \
                 you no longer need, or ask the operator to free space",
            ),
        }
    }
}

impl From<PoolError> for ApiError {
    fn from(e: PoolError) -> Self {
        match e {
            PoolError::Busy { .. } | PoolError::NoMemory { .. } => ApiError::busy(e.to_string(), 1),
            PoolError::TooBig { .. } => ApiError::too_large("body", e.to_string()),
            PoolError::Deadline(_) => ApiError::deadline(e.to_string()),
            PoolError::Lost => ApiError::internal(e),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_table_has_one_row_per_slug_and_sensible_statuses() {
        let mut slugs: Vec<&str> = Kind::ALL.iter().map(|k| k.slug()).collect();
        slugs.sort_unstable();
        slugs.dedup();
        assert_eq!(slugs.len(), Kind::ALL.len(), "a slug is used twice");
        for k in Kind::ALL {
            assert!((400..600).contains(&k.status()), "{k:?}");
            assert_eq!(Kind::from_slug(k.slug()), Some(*k));
        }
    }

    #[test]
    fn nested_fields_are_prefixed_once() {
        let e = ApiError::invalid_field("sources[0]", "outside").nested_in("params");
        assert_eq!(e.problem.field.as_deref(), Some("params.sources[0]"));
        assert_eq!(e.problem.detail, "params.sources[0]: outside");
        let e = ApiError::bad_request("body", "malformed").nested_in("params");
        assert_eq!(e.problem.field.as_deref(), Some("params"));
        assert_eq!(e.problem.detail, "params: malformed");
    }
}
