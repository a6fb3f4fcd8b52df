//! The HTTP side of RFC 9457 problem details ([`crate::problem`]): an
//! [`ApiError`] becomes an `application/problem+json` response here.
//!
//! Handlers return [`ApiError`]; the [`finalize`] middleware then fills in
//! `instance` (the request path) and `request_id`, and turns any other error
//! answer (a 405 from the router, a 413 from a body limit) into a problem too.

use axum::body::Body;
use axum::extract::Request;
use axum::http::{header, HeaderValue, StatusCode};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};

pub use crate::problem::{ApiError, Kind, Problem, PROBLEM_JSON};

/// The HTTP status of a problem.
pub fn status_of(e: &ApiError) -> StatusCode {
    StatusCode::from_u16(e.status_code()).unwrap_or(StatusCode::INTERNAL_SERVER_ERROR)
}

/// The generic problem for a bare status from the framework.
pub fn from_status(status: StatusCode) -> ApiError {
    let reason = status.canonical_reason().unwrap_or("Error");
    let (slug, detail) = match status {
        StatusCode::NOT_FOUND => (
            Kind::NotFound.slug(),
            "no route matches this path".to_string(),
        ),
        StatusCode::METHOD_NOT_ALLOWED => (
            Kind::MethodNotAllowed.slug(),
            "this route does not accept this method; see the Allow header".to_string(),
        ),
        StatusCode::PAYLOAD_TOO_LARGE => (
            Kind::TooLarge.slug(),
            "the body is larger than the configured limit".to_string(),
        ),
        StatusCode::UNSUPPORTED_MEDIA_TYPE => (
            Kind::UnsupportedMediaType.slug(),
            "unsupported media type".to_string(),
        ),
        StatusCode::NOT_ACCEPTABLE => (
            Kind::NotAcceptable.slug(),
            "no acceptable representation".to_string(),
        ),
        s if s.is_server_error() => (Kind::Internal.slug(), reason.to_lowercase()),
        _ => ("http-error", reason.to_lowercase()),
    };
    ApiError::custom(status.as_u16(), slug, reason, detail)
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let status = status_of(&self);
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
            *from_status(status).problem
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
