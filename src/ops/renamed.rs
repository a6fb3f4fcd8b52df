//! The one table of renamed request fields and values, so that an old
//! spelling is refused with its new name instead of a bare "unknown field".
//!
//! Every way a request arrives (an HTTP body, a multipart form's `params`, a
//! job's `params`) goes through [`crate::ops::parse::parse_json`]; when a
//! request of an operation fails to deserialise, the parser looks the body up
//! here ([`explain`]) and, when it holds an old spelling, answers a data error
//! (422) on the old field whose reason names the new one. A valid request is
//! never looked at, so the table costs nothing on the way of a solve.
//! Each row is listed in `CHANGELOG.md`.

use std::any::TypeId;

use serde_json::Value;

use super::parse::ParseError;
use super::registry;

/// One renamed spelling of one operation's request.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Renamed {
    /// A field moved or renamed: `old` (dot-separated JSON path from the
    /// request's root) is now `new`.
    Field {
        /// The old path (`targets`).
        old: &'static str,
        /// The new path (`ends`).
        new: &'static str,
    },
    /// A value of a string field renamed.
    Value {
        /// The field's path (`method`).
        field: &'static str,
        /// The old value (`fast-marching`).
        old: &'static str,
        /// The new value (`fast_marching`).
        new: &'static str,
    },
}

/// Operation name (or `*` for every operation) and what was renamed in its request.
pub const RENAMED: &[(&str, Renamed)] = &[
    (
        "*",
        Renamed::Value {
            field: "method",
            old: "fast-marching",
            new: "fast_marching",
        },
    ),
    (
        "mesh.paths",
        Renamed::Field {
            old: "targets",
            new: "ends",
        },
    ),
    (
        "grid.metric",
        Renamed::Field {
            old: "dataset",
            new: "cost.dataset",
        },
    ),
    (
        "grid.metric",
        Renamed::Field {
            old: "design",
            new: "cost.design",
        },
    ),
    (
        "grid.tensor_distance",
        Renamed::Field {
            old: "tensor",
            new: "metric",
        },
    ),
    (
        "grid.tensor_distance",
        Renamed::Field {
            old: "paths",
            new: "ends",
        },
    ),
    (
        "grid.tensor_distance",
        Renamed::Field {
            old: "path_step",
            new: "step",
        },
    ),
    (
        "grid.tensor_metric",
        Renamed::Field {
            old: "tensor",
            new: "metric",
        },
    ),
];

/// The rows of one operation (its own and the `*` ones).
pub fn renamed_in(operation: &str) -> impl Iterator<Item = &'static Renamed> + '_ {
    RENAMED
        .iter()
        .filter(move |(op, _)| *op == "*" || *op == operation)
        .map(|(_, r)| r)
}

/// The value at a dot-separated path of `body`.
fn at<'a>(body: &'a Value, path: &str) -> Option<&'a Value> {
    path.split('.').try_fold(body, |v, key| v.get(key))
}

/// The data error naming the first old spelling `body` holds, for the
/// operation whose request type is `type_id` (`None` when the type is no
/// operation's, the body is not JSON, or it holds no old spelling).
pub fn explain(type_id: TypeId, body: &[u8]) -> Option<ParseError> {
    let entry = registry::ENTRIES
        .iter()
        .find(|e| (e.type_id)() == type_id)?;
    let body: Value = serde_json::from_slice(body).ok()?;
    explain_value(entry.name, &body)
}

/// [`explain`] for a parsed body of the operation `operation`.
pub fn explain_value(operation: &str, body: &Value) -> Option<ParseError> {
    renamed_in(operation).find_map(|r| match *r {
        Renamed::Field { old, new } => at(body, old).map(|_| ParseError::Data {
            field: old.to_string(),
            reason: format!("`{old}` was renamed `{new}` (see CHANGELOG.md); send `{new}` instead"),
        }),
        Renamed::Value { field, old, new } => (at(body, field)?.as_str() == Some(old)).then(|| {
            ParseError::Data {
                field: field.to_string(),
                reason: format!(
                    "`{old}` was renamed `{new}` (see CHANGELOG.md); send \"{field}\": \"{new}\" instead"
                ),
            }
        }),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn every_row_names_a_registered_operation() {
        for (op, _) in RENAMED {
            assert!(*op == "*" || registry::find(op).is_some(), "{op}");
        }
    }

    #[test]
    fn old_spellings_are_named_with_the_new_one() {
        let e = explain_value("mesh.paths", &json!({"mesh": "m", "targets": []}));
        let Some(ParseError::Data { field, reason }) = e else {
            panic!("{e:?}")
        };
        assert_eq!(field, "targets");
        assert!(reason.contains("`ends`"), "{reason}");
        let e = explain_value("mesh.distance", &json!({"method": "fast-marching"}));
        let Some(ParseError::Data { field, reason }) = e else {
            panic!("{e:?}")
        };
        assert_eq!(field, "method");
        assert!(reason.contains("fast_marching"), "{reason}");
        assert!(explain_value("mesh.distance", &json!({"method": "heat"})).is_none());
        // `targets` is only an old spelling where it was renamed.
        assert!(explain_value("grid.cost_gradient", &json!({"targets": []})).is_none());
    }
}
