//! `/openapi.json` and the Swagger UI at `/docs` (assets embedded at build time).

use utoipa_swagger_ui::SwaggerUi;

use crate::http::AppState;

/// Serves the document and the UI.
pub fn router(doc: utoipa::openapi::OpenApi) -> axum::Router<AppState> {
    axum::Router::from(SwaggerUi::new("/docs").url("/openapi.json", doc))
}
