//! Requests from JSON bytes, naming the field at fault by its JSON path.
//!
//! One parser for every way a request arrives: an HTTP body, a multipart
//! form's `params` part, a job's stored `params`. Data errors (a value of
//! the wrong type, an unknown or missing field) name the field
//! (`sources[0].pt`); syntax errors are the body's as a whole.

use serde::de::DeserializeOwned;

/// Why bytes are not a request.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ParseError {
    /// Not JSON at all (or trailing characters): the body as a whole.
    #[error("malformed JSON: {0}")]
    Syntax(String),
    /// JSON, but not of the request's shape.
    #[error("{field}: {reason}")]
    Data {
        /// JSON path of the field (`sources[0].pt`; `body` when unknown).
        field: String,
        /// What serde said of it.
        reason: String,
    },
    /// More values than a body from the network may hold
    /// ([`check_value_count`]).
    #[error(
        "the JSON body holds more than {limit} values (numbers, strings, arrays, objects): \
         large arrays go in datasets; upload them (POST /v1/datasets, e.g. as NPY) and name \
         them by id (a `cost.dataset`, a `mask` source, ...)"
    )]
    TooManyValues {
        /// The limit.
        limit: usize,
    },
}

/// Most values a JSON body from the network may hold: 4,194,304, at least
/// 8 MB of the most compact JSON. A body of tiny values costs far more
/// memory parsed than on the wire (a 75 MB list of 12.5M cells took the
/// process to 1 GB, `tests/hostile/hostile.py` json-storm), and its millions of small
/// allocations leave the allocator's bookkeeping behind; arrays belong in
/// datasets.
pub const MAX_JSON_VALUES: usize = 4 << 20;

/// Refuses `bytes` if they hold more than `limit` JSON values, before
/// anything is parsed or allocated.
///
/// One pass outside strings: every value starts the document or follows a
/// `,`, `[` or `:`, so `1 + #, + #[ + #:` bounds the count from above (it
/// overcounts: an object's `,` and `:` both count its members; an empty
/// container counts one). The scan stops at the limit.
///
/// # Examples
/// ```
/// use geodex::ops::parse::check_value_count;
/// assert!(check_value_count(br#"{"a": [1, 2, "x,y"]}"#, 5).is_ok());
/// assert!(check_value_count(br#"{"a": [1, 2, "x,y"]}"#, 4).is_err());
/// ```
pub fn check_value_count(bytes: &[u8], limit: usize) -> Result<(), ParseError> {
    let mut count = 1usize;
    let mut in_string = false;
    let mut escaped = false;
    for &b in bytes {
        if in_string {
            if escaped {
                escaped = false;
            } else if b == b'\\' {
                escaped = true;
            } else if b == b'"' {
                in_string = false;
            }
            continue;
        }
        match b {
            b'"' => in_string = true,
            b',' | b'[' | b':' => {
                count += 1;
                if count > limit {
                    return Err(ParseError::TooManyValues { limit });
                }
            }
            _ => {}
        }
    }
    Ok(())
}

/// Parses a request of type `T` from JSON bytes.
///
/// # Examples
/// ```
/// use geodex::ops::parse::{parse_json, ParseError};
/// use geodex::ops::grid_distance::GridDistanceRequest;
/// let err = parse_json::<GridDistanceRequest>(br#"{"sources": [{"pt": [1, 2]}]}"#).unwrap_err();
/// assert!(matches!(err, ParseError::Data { ref field, .. } if field == "sources[0].pt"));
/// ```
///
/// When `T` is an operation's request and the body holds a spelling that
/// was renamed ([`crate::ops::renamed::RENAMED`]), the error names the old
/// field and says its new name.
pub fn parse_json<T: DeserializeOwned + 'static>(bytes: &[u8]) -> Result<T, ParseError> {
    let mut de = serde_json::Deserializer::from_slice(bytes);
    let value: T = match serde_path_to_error::deserialize(&mut de) {
        Ok(v) => v,
        Err(err) => {
            let text = err.to_string();
            return Err(match err.inner().classify() {
                serde_json::error::Category::Data => {
                    match crate::ops::renamed::explain(std::any::TypeId::of::<T>(), bytes) {
                        Some(renamed) => renamed,
                        None => {
                            let (field, reason) = field_and_reason(&text);
                            ParseError::Data { field, reason }
                        }
                    }
                }
                _ => ParseError::Syntax(text),
            });
        }
    };
    de.end().map_err(|e| ParseError::Syntax(e.to_string()))?;
    Ok(value)
}

/// Splits serde_path_to_error's text (`sources[0].pt: unknown field `pt`,
/// expected ... at line 1 column 9`) into the JSON path of the field and the
/// reason. Unknown and missing fields are named in the path.
fn field_and_reason(text: &str) -> (String, String) {
    let (path, reason) = match text.split_once(": ") {
        Some((p, r)) if !p.contains(' ') => (p.trim_start_matches('.'), r),
        _ => ("", text),
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
    use super::*;
    use crate::ops::grid_distance::GridDistanceRequest;

    fn data(bytes: &str) -> (String, String) {
        match parse_json::<GridDistanceRequest>(bytes.as_bytes()) {
            Err(ParseError::Data { field, reason }) => (field, reason),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn names_nested_unknown_fields() {
        let (f, r) =
            data(r#"{"cost": {"constant": 1, "shape": [4, 4]}, "sources": [{"pt": [1, 2]}]}"#);
        assert_eq!(f, "sources[0].pt");
        assert!(r.starts_with("unknown field"), "{r}");
    }

    #[test]
    fn names_top_level_and_missing_fields() {
        let (f, _) = data(r#"{"bogus": 1}"#);
        assert_eq!(f, "bogus");
        let (f, _) = data(r#"{"cost": {"constant": 1, "shape": [4, 4]}}"#);
        assert_eq!(f, "sources");
        let (f, _) = data(
            r#"{"cost": {"constant": 1, "shape": [4, 4]}, "sources": [{"point": [1, 2]}], "order": 300}"#,
        );
        assert_eq!(f, "order");
    }

    #[test]
    fn syntax_errors_are_the_bodys() {
        assert!(matches!(
            parse_json::<GridDistanceRequest>(b"{\"sources\": "),
            Err(ParseError::Syntax(_))
        ));
        assert!(matches!(
            parse_json::<serde_json::Value>(b"{} x"),
            Err(ParseError::Syntax(_))
        ));
    }
}
