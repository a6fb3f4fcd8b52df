//! Extractors whose rejections are problem+json ([`ApiError`]) instead of
//! axum's `text/plain` answers.

use axum::extract::rejection::{BytesRejection, JsonRejection, PathRejection, QueryRejection};
use axum::extract::{FromRequest, FromRequestParts, Request};
use axum::http::request::Parts;
use axum::http::StatusCode;
use serde::de::DeserializeOwned;

use super::error::ApiError;

/// A JSON body (`Content-Type: application/json`).
#[derive(Debug, Clone)]
pub struct ApiJson<T>(pub T);

/// Path parameters.
#[derive(Debug, Clone)]
pub struct ApiPath<T>(pub T);

/// Query parameters.
#[derive(Debug, Clone)]
pub struct ApiQuery<T>(pub T);

/// The whole body as bytes, within the configured body limit.
#[derive(Debug, Clone)]
pub struct ApiBytes(pub bytes::Bytes);

impl<T: DeserializeOwned, S: Send + Sync> FromRequest<S> for ApiJson<T> {
    type Rejection = ApiError;

    async fn from_request(req: Request, state: &S) -> Result<Self, Self::Rejection> {
        axum::Json::<T>::from_request(req, state)
            .await
            .map(|axum::Json(v)| ApiJson(v))
            .map_err(json_rejection)
    }
}

impl<T: DeserializeOwned + Send, S: Send + Sync> FromRequestParts<S> for ApiPath<T> {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, state: &S) -> Result<Self, Self::Rejection> {
        axum::extract::Path::<T>::from_request_parts(parts, state)
            .await
            .map(|axum::extract::Path(v)| ApiPath(v))
            .map_err(|e: PathRejection| {
                ApiError::bad_request("path", format!("path: {}", e.body_text()))
            })
    }
}

impl<T: DeserializeOwned, S: Send + Sync> FromRequestParts<S> for ApiQuery<T> {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, state: &S) -> Result<Self, Self::Rejection> {
        axum::extract::Query::<T>::from_request_parts(parts, state)
            .await
            .map(|axum::extract::Query(v)| ApiQuery(v))
            .map_err(|e: QueryRejection| {
                ApiError::bad_request("query", format!("query: {}", e.body_text()))
            })
    }
}

impl<S: Send + Sync> FromRequest<S> for ApiBytes {
    type Rejection = ApiError;

    async fn from_request(req: Request, state: &S) -> Result<Self, Self::Rejection> {
        bytes::Bytes::from_request(req, state)
            .await
            .map(ApiBytes)
            .map_err(bytes_rejection)
    }
}

/// Maps a failure to read the body.
pub fn bytes_rejection(e: BytesRejection) -> ApiError {
    if e.status() == StatusCode::PAYLOAD_TOO_LARGE {
        ApiError::too_large("body", "the body is larger than the configured limit")
    } else {
        ApiError::bad_request("body", format!("body: {}", e.body_text()))
    }
}

/// Maps a JSON rejection, naming the field when serde reported a path.
pub fn json_rejection(e: JsonRejection) -> ApiError {
    let text = e.body_text();
    match e.status() {
        StatusCode::PAYLOAD_TOO_LARGE => {
            ApiError::too_large("body", "the body is larger than the configured limit")
        }
        StatusCode::UNSUPPORTED_MEDIA_TYPE => ApiError::unsupported_media_type(
            "expected `Content-Type: application/json` (or multipart/form-data where documented)",
        ),
        StatusCode::UNPROCESSABLE_ENTITY => {
            let (field, reason) = data_error_field(&text);
            ApiError::invalid_field(field, reason)
        }
        _ => ApiError::bad_request("body", format!("malformed JSON: {}", strip_prefix(&text))),
    }
}

fn strip_prefix(text: &str) -> &str {
    text.split_once("type: ")
        .or_else(|| text.split_once("JSON: "))
        .map_or(text, |(_, rest)| rest)
}

/// Splits axum's data-error text (`...target type: sources[0]: unknown field
/// `x`, expected ... at line 1 column 9`) into the JSON path of the field and
/// the reason. Unknown and missing fields are named in the path.
pub fn data_error_field(text: &str) -> (String, String) {
    let rest = strip_prefix(text);
    let (path, reason) = match rest.split_once(": ") {
        Some((p, r)) if !p.contains(' ') => (p.trim_start_matches('.'), r),
        _ => ("", rest),
    };
    let named = ["unknown field `", "missing field `"]
        .iter()
        .find_map(|pat| reason.split_once(pat))
        .and_then(|(_, after)| after.split_once('`'))
        .map(|(name, _)| name);
    let field = match (path, named) {
        ("", Some(name)) => name.to_string(),
        // serde_path_to_error already ends the path with an unknown field.
        (p, Some(name)) if p == name || p.ends_with(&format!(".{name}")) => p.to_string(),
        (p, Some(name)) => format!("{p}.{name}"),
        ("", None) => "body".to_string(),
        (p, _) => p.to_string(),
    };
    (field, reason.to_string())
}

#[cfg(test)]
mod tests {
    use super::data_error_field;

    #[test]
    fn names_nested_unknown_fields() {
        let (f, r) = data_error_field(
            "Failed to deserialize the JSON body into the target type: sources[0].pt: unknown field `pt`, expected `point` at line 1 column 30",
        );
        assert_eq!(f, "sources[0].pt");
        assert!(r.starts_with("unknown field"));
    }

    #[test]
    fn names_top_level_fields() {
        let (f, _) = data_error_field(
            "Failed to deserialize the JSON body into the target type: bogus: unknown field `bogus`, expected one of `cost` at line 1 column 9",
        );
        assert_eq!(f, "bogus");
        let (f, _) = data_error_field(
            "Failed to deserialize the JSON body into the target type: missing field `sources` at line 1 column 2",
        );
        assert_eq!(f, "sources");
        let (f, _) = data_error_field(
            "Failed to deserialize the JSON body into the target type: order: invalid value: integer `300`, expected u8 at line 1 column 5",
        );
        assert_eq!(f, "order");
    }
}
