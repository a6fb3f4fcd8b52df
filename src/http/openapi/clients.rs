//! The document as client generators read it.
//!
//! utoipa writes what serde does, which generators misread in four ways;
//! [`for_clients`] rewrites the document so that openapi-python-client and
//! openapi-typescript cover every operation and every schema without a
//! warning (`.ci/clients.sh` checks both, and calls every operation through
//! the generated Python client):
//!
//! 1. **Tagged unions.** A `#[serde(tag = "kind")]` enum becomes
//!    `oneOf: [allOf: [$ref Variant, {kind: enum [v]}], ...]`, or a `oneOf` of
//!    inline objects; generators drop both (and every schema and endpoint
//!    that uses them). Each union becomes a `oneOf` of `$ref`s with a
//!    `discriminator` whose mapping names every tag value; each variant is a
//!    named schema that lists its tag as a required single-value property
//!    (serde removes the tag before the variant sees the object, so the
//!    variant's `deny_unknown_fields` never meets it).
//! 2. **Binary bodies.** File uploads and downloads are described under
//!    `application/octet-stream` (the one binary type generators know) ahead
//!    of the specific types where bytes are the default answer, so a
//!    generated client reads a download as bytes rather than as the JSON
//!    representation also offered.
//! 3. **Operation ids** are unique: an id used by two operations
//!    (`distance`, `paths`, `sample`, `list`) is prefixed by the operation's
//!    tag (`grid_distance`, `mesh_distance`).
//! 4. **Examples.** Every operation's JSON request and success response
//!    carries an example recorded from a real call of the generated client
//!    (`api/examples.json`, written by
//!    `tests/client/every_operation.py --record`), with the dataset ids
//!    replaced by fixed ones.

use std::collections::{BTreeMap, HashMap};

use utoipa::openapi::content::Content;
use utoipa::openapi::path::Operation;
use utoipa::openapi::schema::{Discriminator, Object, Schema, SchemaType, Type};
use utoipa::openapi::{OpenApi, RefOr};

/// Where component schemas are referenced from.
const SCHEMAS: &str = "#/components/schemas/";

/// The recorded request and response of each operation, by operation id.
const EXAMPLES: &str = include_str!("../../../api/examples.json");

/// The binary media type every generator reads as bytes.
const OCTET_STREAM: &str = "application/octet-stream";

/// Rewrites `doc` for client generators (see the module documentation).
pub fn for_clients(mut doc: OpenApi) -> OpenApi {
    if let Some(components) = doc.components.as_mut() {
        discriminate_unions(&mut components.schemas);
    }
    let mut operations = operations(&mut doc);
    unique_operation_ids(&mut operations);
    for op in &mut operations {
        binary_bodies(op);
    }
    let examples: HashMap<String, Recorded> = serde_json::from_str(EXAMPLES).unwrap_or_default();
    for op in &mut operations {
        if let Some(recorded) = op.operation_id.as_ref().and_then(|id| examples.get(id)) {
            attach_examples(op, recorded);
        }
    }
    borrow_examples(&mut operations);
    doc
}

/// One recorded call: the JSON body sent and the JSON answer.
#[derive(Debug, serde::Deserialize)]
struct Recorded {
    /// The request body, when the operation takes a JSON one.
    #[serde(default)]
    request: Option<serde_json::Value>,
    /// The status of the answer (`"200"`, `"201"`, `"202"`).
    status: String,
    /// The answer's JSON body.
    response: serde_json::Value,
}

/// Every operation of the document, in document order.
fn operations(doc: &mut OpenApi) -> Vec<&mut Operation> {
    doc.paths
        .paths
        .values_mut()
        .flat_map(|item| {
            [
                item.get.as_mut(),
                item.put.as_mut(),
                item.post.as_mut(),
                item.delete.as_mut(),
                item.patch.as_mut(),
            ]
        })
        .flatten()
        .collect()
}

/// Rule 1: every union of tagged variants becomes a `oneOf` of `$ref`s with a
/// discriminator.
fn discriminate_unions(schemas: &mut BTreeMap<String, RefOr<Schema>>) {
    let names: Vec<String> = schemas.keys().cloned().collect();
    for name in names {
        let Some(RefOr::T(Schema::OneOf(one_of))) = schemas.get(&name) else {
            continue;
        };
        let Some(variants) = tagged_variants(&name, &one_of.items, schemas) else {
            continue;
        };
        let mut mapping = BTreeMap::new();
        let mut items = Vec::with_capacity(variants.len());
        let property = variants[0].tag.clone();
        for variant in variants {
            let location = format!("{SCHEMAS}{}", variant.schema);
            let target = match variant.inline {
                Some(object) => schemas
                    .entry(variant.schema.clone())
                    .or_insert(RefOr::T(Schema::Object(object))),
                None => match schemas.get_mut(&variant.schema) {
                    Some(target) => target,
                    None => continue,
                },
            };
            if let RefOr::T(Schema::Object(object)) = target {
                object
                    .properties
                    .insert(variant.tag.clone(), variant.tag_schema);
                if !object.required.contains(&variant.tag) {
                    object.required.push(variant.tag);
                }
            }
            items.push(RefOr::Ref(utoipa::openapi::Ref::new(location.clone())));
            mapping.insert(variant.value, location);
        }
        if let Some(RefOr::T(Schema::OneOf(one_of))) = schemas.get_mut(&name) {
            one_of.items = items;
            let mut discriminator = Discriminator::new(property);
            discriminator.mapping = mapping;
            one_of.discriminator = Some(discriminator);
        }
    }
}

/// One variant of a tagged union.
struct Variant {
    /// The component schema that holds it.
    schema: String,
    /// Its schema, when it was written inline in the union (to be named).
    inline: Option<Object>,
    /// The tag property (`kind`, `type`).
    tag: String,
    /// The tag's value for this variant.
    value: String,
    /// The tag property's schema (a single-value string enum).
    tag_schema: RefOr<Schema>,
}

/// The variants of `items` when every one is tagged by the same property,
/// either as `allOf: [$ref, {tag}]` or as an inline object with its tag.
fn tagged_variants(
    union: &str,
    items: &[RefOr<Schema>],
    schemas: &BTreeMap<String, RefOr<Schema>>,
) -> Option<Vec<Variant>> {
    let mut variants = Vec::with_capacity(items.len());
    for item in items {
        let variant = match item {
            RefOr::T(Schema::AllOf(all_of)) => match all_of.items.as_slice() {
                [RefOr::Ref(target), RefOr::T(Schema::Object(tag))] => {
                    let schema = target.ref_location.strip_prefix(SCHEMAS)?.to_string();
                    let (tag, value, tag_schema) = tag_of(tag)?;
                    Variant {
                        schema,
                        inline: None,
                        tag,
                        value,
                        tag_schema,
                    }
                }
                _ => return None,
            },
            RefOr::T(Schema::Object(object)) => {
                let (tag, value, tag_schema) = tag_of(object)?;
                let schema = format!("{union}{}", pascal_case(&value));
                if schemas.contains_key(&schema) {
                    return None;
                }
                Variant {
                    schema,
                    inline: Some(object.clone()),
                    tag,
                    value,
                    tag_schema,
                }
            }
            _ => return None,
        };
        variants.push(variant);
    }
    let first = variants.first()?;
    variants
        .iter()
        .all(|v| v.tag == first.tag)
        .then_some(variants)
}

/// The tag of an object: a required property whose schema is a string enum
/// of one value; its name, value and schema.
fn tag_of(object: &Object) -> Option<(String, String, RefOr<Schema>)> {
    object.required.iter().find_map(|name| {
        let RefOr::T(Schema::Object(property)) = object.properties.get(name)? else {
            return None;
        };
        if property.schema_type != SchemaType::Type(Type::String) {
            return None;
        }
        match property.enum_values.as_deref() {
            Some([serde_json::Value::String(value)]) => Some((
                name.clone(),
                value.clone(),
                RefOr::T(Schema::Object(property.clone())),
            )),
            _ => None,
        }
    })
}

/// `multi_polygon` and `MultiPolygon` give `MultiPolygon`.
fn pascal_case(value: &str) -> String {
    value
        .split(|c: char| c == '_' || c == '-' || c.is_whitespace())
        .filter(|part| !part.is_empty())
        .map(|part| {
            let mut chars = part.chars();
            chars.next().map_or_else(String::new, |first| {
                first.to_uppercase().chain(chars).collect::<String>()
            })
        })
        .collect()
}

/// True for the schema of raw file bytes.
fn is_file_bytes(content: &RefOr<Content>) -> bool {
    matches!(
        content,
        RefOr::T(Content { schema: Some(RefOr::Ref(r)), .. })
            if r.ref_location.ends_with("/FileBytes")
    )
}

/// Rule 2: a binary request body is `application/octet-stream` (beside any
/// form); an answer whose default representation is binary lists
/// `application/octet-stream` first.
fn binary_bodies(op: &mut Operation) {
    if let Some(RefOr::T(body)) = op.request_body.as_mut() {
        let binary: Vec<String> = body
            .content
            .iter()
            .filter(|(_, c)| is_file_bytes(c))
            .map(|(k, _)| k.clone())
            .collect();
        if let Some(first) = binary.first() {
            let bytes = body.content.get(first).cloned();
            for kind in &binary {
                body.content.remove(kind);
            }
            if let Some(bytes) = bytes {
                body.content.insert(OCTET_STREAM.to_string(), bytes);
            }
        }
    }
    for response in op.responses.responses.values_mut() {
        let RefOr::T(response) = response else {
            continue;
        };
        // Only where bytes are the default answer: an operation that answers
        // JSON unless `Accept` asks for NPY keeps JSON first.
        let bytes = response
            .content
            .values()
            .next()
            .filter(|c| is_file_bytes(c))
            .cloned();
        if let Some(bytes) = bytes {
            if !response.content.contains_key(OCTET_STREAM) {
                let rest = std::mem::take(&mut response.content);
                response.content.insert(OCTET_STREAM.to_string(), bytes);
                response.content.extend(rest);
            }
        }
    }
}

/// Rule 3: an operation id used twice is prefixed by each operation's tag.
fn unique_operation_ids(operations: &mut [&mut Operation]) {
    let mut uses: HashMap<String, usize> = HashMap::new();
    for op in operations.iter() {
        if let Some(id) = &op.operation_id {
            *uses.entry(id.clone()).or_default() += 1;
        }
    }
    for op in operations.iter_mut() {
        let tag = op.tags.as_ref().and_then(|t| t.first()).cloned();
        if let (Some(id), Some(tag)) = (op.operation_id.as_mut(), tag) {
            if uses.get(id.as_str()).is_some_and(|&n| n > 1) {
                *id = format!("{tag}_{id}");
            }
        }
    }
}

/// Rule 4: the recorded request and answer as the JSON media types' examples.
fn attach_examples(op: &mut Operation, recorded: &Recorded) {
    if let (Some(RefOr::T(body)), Some(request)) = (op.request_body.as_mut(), &recorded.request) {
        if let Some(RefOr::T(content)) = body.content.get_mut("application/json") {
            content.example = Some(request.clone());
        }
    }
    if let Some(RefOr::T(response)) = op.responses.responses.get_mut(&recorded.status) {
        if let Some(RefOr::T(content)) = response.content.get_mut("application/json") {
            content.example = Some(recorded.response.clone());
        }
    }
}

/// The `$ref` of a JSON answer's schema, when it has one.
fn json_schema_ref(content: &RefOr<Content>) -> Option<&str> {
    match content {
        RefOr::T(Content {
            schema: Some(RefOr::Ref(r)),
            ..
        }) => Some(r.ref_location.as_str()),
        _ => None,
    }
}

/// A JSON answer left without a recorded example (a `202` job of an
/// operation asked with `Prefer: respond-async`, the JSON form of a job
/// result) takes the recorded example of another answer with the same
/// schema (the `Job` of `POST /v1/jobs`, the `ArrayJson` of a download).
fn borrow_examples(operations: &mut [&mut Operation]) {
    let mut by_schema: HashMap<String, serde_json::Value> = HashMap::new();
    for op in operations.iter() {
        for response in op.responses.responses.values() {
            let RefOr::T(response) = response else {
                continue;
            };
            if let Some(content) = response.content.get("application/json") {
                if let (
                    Some(schema),
                    RefOr::T(Content {
                        example: Some(e), ..
                    }),
                ) = (json_schema_ref(content), content)
                {
                    by_schema
                        .entry(schema.to_string())
                        .or_insert_with(|| e.clone());
                }
            }
        }
    }
    for op in operations.iter_mut() {
        for (status, response) in op.responses.responses.iter_mut() {
            let RefOr::T(response) = response else {
                continue;
            };
            if !status.starts_with('2') {
                continue;
            }
            if let Some(content) = response.content.get_mut("application/json") {
                let borrowed = json_schema_ref(content)
                    .and_then(|s| by_schema.get(s))
                    .cloned();
                if let RefOr::T(content) = content {
                    if content.example.is_none() {
                        content.example = borrowed;
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tag_values_become_schema_names() {
        assert_eq!(pascal_case("multi_polygon"), "MultiPolygon");
        assert_eq!(pascal_case("MultiPolygon"), "MultiPolygon");
        assert_eq!(pascal_case("energy_anisotropy"), "EnergyAnisotropy");
    }

    #[test]
    fn the_recorded_examples_parse() {
        let parsed: Result<HashMap<String, Recorded>, _> = serde_json::from_str(EXAMPLES);
        assert!(parsed.is_ok(), "api/examples.json: {parsed:?}");
    }
}
