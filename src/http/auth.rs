//! The HTTP side of [`crate::auth`]: who a request acts for, and the checks
//! every request passes before its handler.
//!
//! [`authenticate`] (a middleware, inside the problem finalizer) does, in order:
//! 1. **Browser origin.** A state-changing request (any method but `GET`,
//!    `HEAD`, `OPTIONS`) from a browser page of another origin is refused
//!    403, with or without auth: its `Origin` must be this service's own
//!    (the `Host` it was sent to) or one of `--cors-origins`, and a
//!    `Sec-Fetch-Site` of `cross-site` or `same-site` without such an
//!    `Origin` is refused. So no page on the web can make a visitor's
//!    browser upload to, or start work on, a geodex it can reach (a "simple"
//!    form post needs no CORS preflight). Clients that are not browsers send
//!    neither header and pass.
//! 2. **Key.** With auth on, every route but the public ones (`/healthz`,
//!    `/readyz`, `/openapi.json`, `/docs`, the playground's page and assets)
//!    needs `Authorization: Bearer <key>` (or `X-API-Key: <key>`); a missing,
//!    malformed, unknown or revoked key is a 401 that says which. `/metrics`
//!    needs an admin key (403 otherwise), and `/readyz` shows its details
//!    only to one.
//! 3. **Rate.** The key's token bucket; empty: 429 + `Retry-After`.
//! 4. The handler runs with the [`Caller`] in a task-local ([`caller`]):
//!    the dataset, job and collection handlers and [`super::operation`]
//!    scope everything they read or write to its tenant.

use std::sync::Arc;
use std::time::Instant;

use axum::extract::{Request, State};
use axum::http::{header, HeaderMap, HeaderValue, Method};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};

use crate::auth::{rate::Buckets, Caller, Keys, Refusal};
use crate::problem::{ApiError, Kind};

tokio::task_local! {
    static CALLER: Caller;
}

/// The caller of the request being handled. Outside a request (or if the
/// middleware did not run) this is a caller of the empty tenant with no
/// admin rights: never more than auth-off data, never an admin.
pub fn caller() -> Caller {
    CALLER.try_with(Caller::clone).unwrap_or_default()
}

/// Whether requests need a key, and the keys.
#[derive(Debug)]
pub struct Auth {
    /// The keys; `None` when auth is off (every request is
    /// [`Caller::anonymous`]).
    pub keys: Option<Arc<Keys>>,
    /// Per-key token buckets.
    pub buckets: Buckets,
    /// Browser origins allowed besides the service's own (`--cors-origins`;
    /// `*` allows any).
    pub allowed_origins: Vec<String>,
}

impl Auth {
    /// True if requests need a key.
    pub fn is_on(&self) -> bool {
        self.keys.is_some()
    }
}

/// Routes that answer without a key (the health probes, the contract, the
/// documentation and the playground page, which asks for a key itself).
fn is_public(path: &str) -> bool {
    matches!(path, "/" | "/healthz" | "/readyz" | "/openapi.json")
        || path == "/docs"
        || path.starts_with("/docs/")
        || path == "/playground"
        || path.starts_with("/playground/")
}

/// Why a browser request is refused as cross-site, if it is.
fn cross_site(method: &Method, headers: &HeaderMap, allowed: &[String]) -> Option<String> {
    if matches!(*method, Method::GET | Method::HEAD | Method::OPTIONS) {
        return None;
    }
    let text = |name: &str| headers.get(name).and_then(|v| v.to_str().ok());
    let site = text("sec-fetch-site");
    match text("origin") {
        Some(origin) => {
            let host = text("host").unwrap_or("");
            let own = origin
                .split_once("://")
                .is_some_and(|(_, rest)| !host.is_empty() && rest.eq_ignore_ascii_case(host));
            let listed = allowed
                .iter()
                .any(|a| a == "*" || a.trim_end_matches('/').eq_ignore_ascii_case(origin));
            (!own && !listed).then(|| {
                format!(
                    "Origin: {origin} is not this service's origin and not one of its \
                     --cors-origins; a page of another site cannot change anything here. \
                     The operator may allow that origin with --cors-origins"
                )
            })
        }
        None => matches!(site, Some("cross-site" | "same-site")).then(|| {
            format!(
                "Sec-Fetch-Site: {} without an allowed Origin: a page of another site cannot \
                 change anything here",
                site.unwrap_or_default()
            )
        }),
    }
}

/// The key a request presents, if any.
fn presented_key(headers: &HeaderMap) -> Option<&str> {
    if let Some(v) = headers
        .get(header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
    {
        let (scheme, key) = v.trim().split_once(' ')?;
        return scheme.eq_ignore_ascii_case("bearer").then(|| key.trim());
    }
    headers
        .get("x-api-key")
        .and_then(|v| v.to_str().ok())
        .map(str::trim)
}

fn unauthorized(detail: &str) -> Response {
    let mut res = ApiError::of(Kind::Unauthorized, detail)
        .with_field("Authorization")
        .into_response();
    res.headers_mut().insert(
        header::WWW_AUTHENTICATE,
        HeaderValue::from_static("Bearer realm=\"geodex\""),
    );
    res
}

/// The middleware (see the module documentation).
pub async fn authenticate(State(auth): State<Arc<Auth>>, req: Request, next: Next) -> Response {
    if let Some(reason) = cross_site(req.method(), req.headers(), &auth.allowed_origins) {
        return ApiError::of(Kind::Forbidden, reason)
            .with_field("Origin")
            .into_response();
    }
    let Some(keys) = &auth.keys else {
        return CALLER.scope(Caller::anonymous(), next.run(req)).await;
    };
    let path = req.uri().path();
    let public = is_public(path);
    let caller = match presented_key(req.headers()) {
        None if public => Caller::default(),
        None => {
            return unauthorized(
                "this service needs an API key: send `Authorization: Bearer <key>`; the \
                 operator creates keys with `geodex keys create --tenant NAME`",
            )
        }
        Some(key) => match keys.verify(key).await {
            Ok(Ok(caller)) => caller,
            Ok(Err(refusal)) => {
                return unauthorized(match refusal {
                    Refusal::Malformed => {
                        "the API key is malformed: a key is gdx_ followed by 16 and 64 \
                         hex digits, as `geodex keys create` printed it"
                    }
                    Refusal::Unknown => "the API key is not known to this service",
                    Refusal::Revoked => "the API key was revoked; ask the operator for a new one",
                })
            }
            Err(e) => {
                tracing::error!(error = %e, "verifying an API key");
                return ApiError::busy("the key database is not reachable; retry later", 2)
                    .into_response();
            }
        },
    };
    if path == "/metrics" && !caller.admin {
        return ApiError::of(
            Kind::Forbidden,
            "the metrics need an admin key (`geodex keys create --admin`)",
        )
        .with_field("Authorization")
        .into_response();
    }
    if let (Some((rate, burst)), Some(id)) = (caller.rate, &caller.key_id) {
        if let Err(wait) = auth.buckets.take(id, rate, burst, Instant::now()) {
            let mut e = ApiError::of(
                Kind::RateLimited,
                format!(
                    "the rate limit of key {id} ({rate} requests per second, bursts of \
                     {burst}) is reached; retry after the Retry-After seconds"
                ),
            );
            e.retry_after = Some(wait.as_secs_f64().ceil().max(1.0) as u64);
            return e.into_response();
        }
    }
    CALLER.scope(caller, next.run(req)).await
}

#[cfg(test)]
mod tests {
    use super::*;

    fn headers(pairs: &[(&'static str, &'static str)]) -> HeaderMap {
        let mut h = HeaderMap::new();
        for (k, v) in pairs {
            h.insert(*k, HeaderValue::from_static(v));
        }
        h
    }

    #[test]
    fn only_cross_site_browser_writes_are_refused() {
        let none: Vec<String> = Vec::new();
        let post = Method::POST;
        // curl, scripts: no browser headers.
        assert!(cross_site(&post, &headers(&[("host", "h:1")]), &none).is_none());
        // The playground, same origin.
        let same = headers(&[
            ("host", "127.0.0.1:8080"),
            ("origin", "http://127.0.0.1:8080"),
            ("sec-fetch-site", "same-origin"),
        ]);
        assert!(cross_site(&post, &same, &none).is_none());
        // A form on another site.
        let evil = headers(&[
            ("host", "127.0.0.1:8080"),
            ("origin", "https://evil.example"),
            ("sec-fetch-site", "cross-site"),
        ]);
        assert!(cross_site(&post, &evil, &none).is_some());
        assert!(cross_site(&Method::DELETE, &evil, &none).is_some());
        // Reading is not refused here (CORS keeps the answer from the page).
        assert!(cross_site(&Method::GET, &evil, &none).is_none());
        // Unless the operator allows that origin.
        let allowed = vec!["https://evil.example".to_string()];
        assert!(cross_site(&post, &evil, &allowed).is_none());
        // A sandboxed page sends `Origin: null`.
        let null = headers(&[("host", "h:1"), ("origin", "null")]);
        assert!(cross_site(&post, &null, &none).is_some());
        // Sec-Fetch-Site alone.
        let site = headers(&[("host", "h:1"), ("sec-fetch-site", "same-site")]);
        assert!(cross_site(&post, &site, &none).is_some());
    }

    #[test]
    fn keys_are_read_from_either_header() {
        let bearer = headers(&[("authorization", "Bearer gdx_x")]);
        assert_eq!(presented_key(&bearer), Some("gdx_x"));
        let lower = headers(&[("authorization", "bearer  gdx_x ")]);
        assert_eq!(presented_key(&lower), Some("gdx_x"));
        let basic = headers(&[("authorization", "Basic abc")]);
        assert_eq!(presented_key(&basic), None);
        let api = headers(&[("x-api-key", "gdx_y")]);
        assert_eq!(presented_key(&api), Some("gdx_y"));
        assert_eq!(presented_key(&HeaderMap::new()), None);
    }

    #[test]
    fn the_probes_and_pages_are_public() {
        for p in [
            "/healthz",
            "/readyz",
            "/openapi.json",
            "/docs",
            "/docs/x",
            "/playground/a.js",
            "/",
        ] {
            assert!(is_public(p), "{p}");
        }
        for p in [
            "/metrics",
            "/v1/datasets",
            "/v1/jobs",
            "/playgroundx",
            "/docsx",
        ] {
            assert!(!is_public(p), "{p}");
        }
    }
}
