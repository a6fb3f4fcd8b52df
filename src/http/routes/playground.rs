//! The playground: a page at `/playground` (and `/`, which redirects to it)
//! that drives the public API from a browser: distance maps, live minimal
//! paths, livewire contours, segmentations, distance transforms, mesh
//! geodesics and jobs, each request shown as a curl command.
//!
//! The assets live in `src/http/playground/` and are compiled into the
//! binary (`include_str!`): no build step, no CDN, works offline. The page
//! calls only the documented endpoints, so it is left out of the OpenAPI
//! document.

use axum::extract::Path;
use axum::http::header;
use axum::response::{IntoResponse, Redirect, Response};
use axum::routing::get;

use crate::http::AppState;

/// One embedded file: its name under `/playground/`, media type, content.
struct Asset {
    name: &'static str,
    media: &'static str,
    body: &'static str,
}

/// An [`Asset`] read from `src/http/playground/` at compile time.
macro_rules! asset {
    ($name:literal, $media:expr) => {
        Asset {
            name: $name,
            media: $media,
            body: include_str!(concat!("../playground/", $name)),
        }
    };
}

const JS: &str = "text/javascript; charset=utf-8";

/// Every file of the playground; `index.html` is also served at `/playground`.
const ASSETS: &[Asset] = &[
    asset!("index.html", "text/html; charset=utf-8"),
    asset!("style.css", "text/css; charset=utf-8"),
    asset!("api.js", JS),
    asset!("samples.js", JS),
    asset!("image.js", JS),
    asset!("viewer.js", JS),
    asset!("mesh.js", JS),
    asset!("jobs.js", JS),
    asset!("main.js", JS),
];

fn serve(name: &str) -> Response {
    match ASSETS.iter().find(|a| a.name == name) {
        Some(a) => (
            [
                (header::CONTENT_TYPE, a.media),
                (header::CACHE_CONTROL, "no-cache"),
            ],
            a.body,
        )
            .into_response(),
        None => crate::problem::ApiError::not_found(
            None,
            format!("no playground file `{name}`; the page is at /playground"),
        )
        .into_response(),
    }
}

/// `GET /playground`: the page.
async fn page() -> Response {
    serve("index.html")
}

/// `GET /playground/{file}`: a script or style sheet of the page.
async fn asset(Path(file): Path<String>) -> Response {
    serve(&file)
}

/// The playground's routes: `/`, `/playground`, `/playground/{file}`.
pub fn router() -> axum::Router<AppState> {
    axum::Router::new()
        .route("/", get(|| async { Redirect::temporary("/playground") }))
        .route("/playground", get(page))
        .route("/playground/", get(page))
        .route("/playground/{file}", get(asset))
}
