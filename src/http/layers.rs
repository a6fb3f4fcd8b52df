//! Middleware: request metrics and the tower stack around the router.
//!
//! Order, outermost first: request id (set), trace span, request id
//! (propagate), CORS, request metrics, problem finalizer, gzip, panic catcher,
//! authentication (browser origin, API key, rate limit: [`super::auth`]),
//! declared length (413 before reading), body limit.

use std::time::Instant;

use axum::extract::{MatchedPath, Request};
use axum::http::{HeaderName, HeaderValue, Method};
use axum::middleware::{self, Next};
use axum::response::{IntoResponse, Response};
use axum::Router;
use tower_http::catch_panic::CatchPanicLayer;
use tower_http::compression::predicate::{DefaultPredicate, NotForContentType, Predicate};
use tower_http::compression::{CompressionLayer, CompressionLevel};
use tower_http::cors::{AllowOrigin, Any, CorsLayer};
use tower_http::request_id::{MakeRequestUuid, PropagateRequestIdLayer, SetRequestIdLayer};
use tower_http::trace::{DefaultOnResponse, TraceLayer};
use tower_http::LatencyUnit;
use tracing::Level;

use super::error;
use crate::config::ServeArgs;
use crate::telemetry;

/// Records `geodex_http_request_duration_seconds{route,method,status}`.
pub async fn track(req: Request, next: Next) -> Response {
    let route = req
        .extensions()
        .get::<MatchedPath>()
        .map_or_else(|| "unmatched".to_string(), |p| p.as_str().to_string());
    let method = req.method().to_string();
    let started = Instant::now();
    let res = next.run(req).await;
    metrics::histogram!(
        telemetry::HTTP_DURATION,
        "route" => route,
        "method" => method,
        "status" => res.status().as_u16().to_string()
    )
    .record(started.elapsed().as_secs_f64());
    res
}

fn cors(origins: &[String]) -> Option<CorsLayer> {
    let origins: Vec<&str> = origins
        .iter()
        .map(|s| s.trim())
        .filter(|s| !s.is_empty())
        .collect();
    if origins.is_empty() {
        return None;
    }
    let allow = if origins.contains(&"*") {
        AllowOrigin::from(Any)
    } else {
        AllowOrigin::list(
            origins
                .iter()
                .filter_map(|o| HeaderValue::from_str(o).ok())
                .collect::<Vec<_>>(),
        )
    };
    Some(
        CorsLayer::new()
            .allow_origin(allow)
            .allow_methods([Method::GET, Method::POST, Method::DELETE, Method::OPTIONS])
            .allow_headers(Any)
            .expose_headers([
                HeaderName::from_static("x-request-id"),
                HeaderName::from_static("location"),
                HeaderName::from_static("retry-after"),
            ]),
    )
}

/// gzip for clients that ask for it, at the fastest level: an interactive
/// path answer (~200 KB of JSON) takes ~30 ms to compress at zlib's default
/// level 6 and ~5 ms at level 1 for nearly the same size (109 KB vs 103 KB),
/// and the front end is waiting. NPY arrays (binary floats, megabytes, little
/// to gain) are never compressed; neither are the images and streams that
/// tower-http's default predicate already skips.
fn compression() -> CompressionLayer<impl Predicate> {
    CompressionLayer::new()
        .gzip(true)
        .quality(CompressionLevel::Fastest)
        .compress_when(
            DefaultPredicate::new().and(NotForContentType::const_new("application/x-npy")),
        )
}

/// Answers 413 at once when the declared `Content-Length` exceeds the body
/// limit, before a byte of the body is read (the body limit itself is
/// enforced as the bytes arrive, for bodies sent without a length).
async fn declared_length(req: Request, next: Next, limit: usize) -> Response {
    let declared = req
        .headers()
        .get(axum::http::header::CONTENT_LENGTH)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.trim().parse::<u64>().ok());
    match declared {
        Some(n) if n > limit as u64 => crate::problem::ApiError::too_large(
            "body",
            format!(
                "the body declares {n} bytes, more than the limit of {limit} \
                 (the server's --max-body-bytes); nothing was read"
            ),
        )
        .into_response(),
        _ => next.run(req).await,
    }
}

/// Wraps the router in every layer.
pub fn apply(app: Router, settings: &ServeArgs, auth: std::sync::Arc<super::auth::Auth>) -> Router {
    let x_request_id = HeaderName::from_static("x-request-id");
    let max_body = settings.max_body_bytes;
    let app = app
        .layer(axum::extract::DefaultBodyLimit::max(
            settings.max_body_bytes,
        ))
        .layer(middleware::from_fn(move |req: Request, next: Next| {
            declared_length(req, next, max_body)
        }))
        .layer(middleware::from_fn_with_state(
            auth,
            super::auth::authenticate,
        ))
        .layer(CatchPanicLayer::custom(error::panic_response))
        .layer(compression())
        .layer(middleware::from_fn(error::finalize))
        .layer(middleware::from_fn(track));
    let app = match cors(&settings.cors_origins) {
        Some(c) => app.layer(c),
        None => app,
    };
    app.layer(PropagateRequestIdLayer::new(x_request_id.clone()))
        .layer(
            TraceLayer::new_for_http().make_span_with(|req: &Request| {
                let id = req
                    .headers()
                    .get("x-request-id")
                    .and_then(|v| v.to_str().ok())
                    .unwrap_or("-");
                tracing::info_span!("request", method = %req.method(), uri = %req.uri(), request_id = %id)
            })
            .on_response(DefaultOnResponse::new().level(Level::INFO).latency_unit(LatencyUnit::Micros)),
        )
        .layer(SetRequestIdLayer::new(x_request_id, MakeRequestUuid))
}
