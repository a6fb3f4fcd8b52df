//! The OpenAPI 3.1 contract: document-level information, and reusable
//! problem+json responses (one per status) with examples.
//!
//! The paths come from the `#[utoipa::path]` annotations of the handlers,
//! collected by `utoipa_axum` when the router is built ([`document`]).

use utoipa::{OpenApi, ToResponse};

pub mod clients;

use super::error::Problem;

/// Description shared by the document and the grid operations.
pub const COORDINATES: &str = "Point coordinates are in array index order (axis 0 first), \
in index units (cell centres are at integer indices), with a separate per-axis `spacing` \
giving the physical size of a cell along each axis.";

/// Document-level information, tags and shared components.
#[derive(OpenApi)]
#[openapi(
    info(
        title = "geodex",
        description = "Geodesic distances, minimal paths and segmentations on 2D and 3D grids.\n\n\
Upload arrays as datasets (`POST /v1/datasets`), run operations on them (`POST /v1/grid/distance`), \
and download the results in the format you need (`GET /v1/datasets/{id}/data`).\n\n\
**Conventions** (the same in every operation, its job and its command):\n\n\
- **Points** are in array index order (axis 0 first: `[row, column]` on an image), in index units \
(cell centres at integer indices), with a separate per-axis `spacing` giving the physical size of a \
cell along each axis. Mesh points are `{\"vertex\": v}` or `{\"face\": f, \"bary\": [b0, b1, b2]}`.\n\
- **GeoJSON** is the one exception and follows its standard in every GeoJSON answer (`grid.paths` \
with `format: geojson`, `grid.segment`'s `contours`, `grid.group`'s `geojson`) and input \
(`domain.mesh`'s `polygons`): positions are `[x, y] = [column, row]`, times the spacing in answers; \
outer rings turn counter-clockwise.\n\
- **Paths** run from their source to their end: the first point is the source reached, the last \
the end point (`grid.paths`, `grid.tensor_distance`, `mesh.paths`; `grid.plan` from `start` to \
`goal`; `grid.group` links from `pair[0]` to `pair[1]`; skeleton edges from `source` to `target`).\n\
- **Names**: path end points are `ends` (grids, tensors, meshes); a path's `geodesic_length` is its \
length in the metric (`∫W`, `∫sqrt(γ'ᵀMγ')`, on a mesh the distance `U` at its end) and its \
`euclidean_length` that of its polyline; methods are spelled with underscores (`fast_marching`).\n\
- **Metrics**: an isotropic metric is always the `cost` section (`dataset`, `constant` + `shape`, \
`interpretation`, `design`), a Riemannian one the `metric` section (a tensor field).\n\
- Renamed fields and values (listed in CHANGELOG.md) answer 422 naming the new spelling.\n\n\
Every error is an RFC 9457 `application/problem+json` document naming the offending field.\n\n\
**Authentication**: a service started with `--auth` (or once any key exists) needs an API key on \
every route but `/healthz`, `/readyz`, this document, `/docs` and the playground: \
`Authorization: Bearer gdx_...` (or `X-API-Key`), created by the operator with `geodex keys create \
--tenant NAME`. A missing, unknown or revoked key is a 401; a key's rate limit a 429 with \
`Retry-After`. Datasets, jobs (with their results and idempotency keys) and collections belong to \
the key's tenant: another tenant is answered 404 for them. Requests that change something from a \
browser page of another origin are refused 403 (`Origin`, `Sec-Fetch-Site`).\n\n\
**Try it**: the playground at `/playground` (the service's own page) clicks sources, paths, seeds and \
meshes through these endpoints alone and shows each request as curl; every operation below carries a \
request and an answer example recorded from a real call.",
        license(name = "MIT OR Apache-2.0", identifier = "MIT OR Apache-2.0"),
    ),
    tags(
        (name = "datasets", description = "Upload, inspect, download and delete arrays."),
        (name = "grid", description = "Operations on 2D and 3D grids."),
        (name = "mesh", description = "Geodesics on triangle meshes: distance, Voronoi cells, paths, sampling, distance matrices, canonical forms."),
        (name = "points", description = "Point clouds: Isomap."),
        (name = "operations", description = "Health, readiness and metrics."),
        (name = "jobs", description = "Durable background jobs: submit any operation, poll, cancel, download results."),
        (name = "collections", description = "Shape collections: add meshes by their geodesic descriptors, query the nearest shapes of a mesh."),
    ),
    modifiers(&BearerKey),
    components(
        schemas(Problem, FileBytes),
        responses(
            BadRequest,
            NotFound,
            NotAcceptable,
            PayloadTooLarge,
            UnsupportedMediaType,
            Unprocessable,
            InternalError,
            Busy,
            DeadlineExceeded,
            InsufficientStorage,
            Conflict,
        )
    )
)]
pub struct ApiDoc;

/// The `api_key` security scheme (HTTP bearer), optional on every operation:
/// a service without auth takes requests without it.
struct BearerKey;

impl utoipa::Modify for BearerKey {
    fn modify(&self, openapi: &mut utoipa::openapi::OpenApi) {
        use utoipa::openapi::security::{
            HttpAuthScheme, HttpBuilder, SecurityRequirement, SecurityScheme,
        };
        let components = openapi.components.get_or_insert_with(Default::default);
        components.add_security_scheme(
            "api_key",
            SecurityScheme::Http(
                HttpBuilder::new()
                    .scheme(HttpAuthScheme::Bearer)
                    .bearer_format("gdx_<16 hex>_<64 hex>")
                    .description(Some(
                        "An API key from `geodex keys create`; needed when the service runs \
                         with auth (see the description above).",
                    ))
                    .build(),
            ),
        );
        openapi.security = Some(vec![
            SecurityRequirement::default(),
            SecurityRequirement::new("api_key", Vec::<String>::new()),
        ]);
    }
}

/// The body cannot be parsed: malformed JSON, a corrupt or truncated file, a bad path or query.
#[derive(ToResponse)]
#[response(
    content_type = "application/problem+json",
    example = json!({
        "type": "https://geodex.dev/problems/malformed-request",
        "title": "The request cannot be parsed",
        "status": 400,
        "detail": "body: corrupt Npy file: the header is truncated",
        "instance": "/v1/datasets",
        "request_id": "0192f1b2-7c1e-7d3a-9d55-3c0f2b8a1e44",
        "field": "body"
    })
)]
pub struct BadRequest(#[allow(dead_code)] Problem);

/// A dataset named by the request (or the path) does not exist or has expired.
#[derive(ToResponse)]
#[response(
    content_type = "application/problem+json",
    example = json!({
        "type": "https://geodex.dev/problems/not-found",
        "title": "The resource does not exist",
        "status": 404,
        "detail": "cost.dataset: dataset 'ds_0192f1b27c1e7d3a9d553c0f2b8a1e44' does not exist (or has expired)",
        "instance": "/v1/grid/distance",
        "request_id": "0192f1b2-7c1e-7d3a-9d55-3c0f2b8a1e44",
        "field": "cost.dataset"
    })
)]
pub struct NotFound(#[allow(dead_code)] Problem);

/// The representation asked for (`Accept` or `?format=`) cannot be produced for this array.
#[derive(ToResponse)]
#[response(
    content_type = "application/problem+json",
    example = json!({
        "type": "https://geodex.dev/problems/not-acceptable",
        "title": "The requested representation is not available",
        "status": 406,
        "detail": "json is only offered for arrays of at most 65536 cells; this one has 262144",
        "instance": "/v1/datasets/ds_0192f1b27c1e7d3a9d553c0f2b8a1e44/data",
        "request_id": "0192f1b2-7c1e-7d3a-9d55-3c0f2b8a1e44",
        "field": "Accept"
    })
)]
pub struct NotAcceptable(#[allow(dead_code)] Problem);

/// The body, the array or the grid is larger than the configured limits.
#[derive(ToResponse)]
#[response(
    content_type = "application/problem+json",
    example = json!({
        "type": "https://geodex.dev/problems/too-large",
        "title": "The request is larger than the limits",
        "status": 413,
        "detail": "the body is larger than the configured limit",
        "instance": "/v1/datasets",
        "request_id": "0192f1b2-7c1e-7d3a-9d55-3c0f2b8a1e44",
        "field": "body"
    })
)]
pub struct PayloadTooLarge(#[allow(dead_code)] Problem);

/// The media type of the body is not accepted (or the file format is not recognised).
#[derive(ToResponse)]
#[response(
    content_type = "application/problem+json",
    example = json!({
        "type": "https://geodex.dev/problems/unsupported-media-type",
        "title": "The media type of the body is not supported",
        "status": 415,
        "detail": "text/plain is not an accepted upload type",
        "instance": "/v1/datasets",
        "request_id": "0192f1b2-7c1e-7d3a-9d55-3c0f2b8a1e44",
        "field": "Content-Type"
    })
)]
pub struct UnsupportedMediaType(#[allow(dead_code)] Problem);

/// The request is well-formed but a value is refused (NaN or negative cost, spacing <= 0,
/// a source outside the grid or on an obstacle, a 1D or 4D array, an unknown field).
#[derive(ToResponse)]
#[response(
    content_type = "application/problem+json",
    example = json!({
        "type": "https://geodex.dev/problems/invalid-field",
        "title": "A field of the request is invalid",
        "status": 422,
        "detail": "sources[0]: the point [300.0, 12.0] is outside the grid of shape [256, 256]",
        "instance": "/v1/grid/distance",
        "request_id": "0192f1b2-7c1e-7d3a-9d55-3c0f2b8a1e44",
        "field": "sources[0]"
    })
)]
pub struct Unprocessable(#[allow(dead_code)] Problem);

/// An unexpected failure; the details are in the server log under the request id.
#[derive(ToResponse)]
#[response(
    content_type = "application/problem+json",
    example = json!({
        "type": "https://geodex.dev/problems/internal",
        "title": "Internal server error",
        "status": 500,
        "detail": "the server failed to handle the request; see its logs",
        "instance": "/v1/grid/distance",
        "request_id": "0192f1b2-7c1e-7d3a-9d55-3c0f2b8a1e44"
    })
)]
pub struct InternalError(#[allow(dead_code)] Problem);

/// The solver pool is full (or the service is draining); retry after `Retry-After` seconds.
#[derive(ToResponse)]
#[response(
    content_type = "application/problem+json",
    headers(("Retry-After" = u64, description = "Seconds to wait before retrying.")),
    example = json!({
        "type": "https://geodex.dev/problems/busy",
        "title": "The service is busy",
        "status": 503,
        "detail": "the solver pool is full (8 solves admitted); retry later",
        "instance": "/v1/grid/distance",
        "request_id": "0192f1b2-7c1e-7d3a-9d55-3c0f2b8a1e44"
    })
)]
pub struct Busy(#[allow(dead_code)] Problem);

/// The solve did not finish before the request deadline and was cancelled.
#[derive(ToResponse)]
#[response(
    content_type = "application/problem+json",
    example = json!({
        "type": "https://geodex.dev/problems/deadline-exceeded",
        "title": "The computation did not finish in time",
        "status": 504,
        "detail": "the solve did not finish within 60s and was cancelled",
        "instance": "/v1/grid/distance",
        "request_id": "0192f1b2-7c1e-7d3a-9d55-3c0f2b8a1e44"
    })
)]
pub struct DeadlineExceeded(#[allow(dead_code)] Problem);

/// The storage quota is used up; delete datasets or wait for them to expire.
#[derive(ToResponse)]
#[response(
    content_type = "application/problem+json",
    example = json!({
        "type": "https://geodex.dev/problems/storage-full",
        "title": "The storage quota is used up",
        "status": 507,
        "detail": "storing 524416 bytes would exceed the storage quota (8589672000 of 8589934592 bytes used)",
        "instance": "/v1/grid/distance",
        "request_id": "0192f1b2-7c1e-7d3a-9d55-3c0f2b8a1e44"
    })
)]
pub struct InsufficientStorage(#[allow(dead_code)] Problem);

/// The resource is not in a state that allows this (a job already ended, or has no results yet).
#[derive(ToResponse)]
#[response(
    content_type = "application/problem+json",
    example = json!({
        "type": "https://geodex.dev/problems/job-finished",
        "title": "The job already ended",
        "status": 409,
        "detail": "job 'job_0192f1b27c1e7d3a9d553c0f2b8a1e44' already succeeded; there is nothing to cancel",
        "instance": "/v1/jobs/job_0192f1b27c1e7d3a9d553c0f2b8a1e44/cancel",
        "request_id": "0192f1b2-7c1e-7d3a-9d55-3c0f2b8a1e44",
        "field": "id"
    })
)]
pub struct Conflict(#[allow(dead_code)] Problem);

/// Raw file bytes: the schema of binary request and response bodies
/// (`type: string, format: binary`).
pub struct FileBytes;

impl utoipa::PartialSchema for FileBytes {
    fn schema() -> utoipa::openapi::RefOr<utoipa::openapi::schema::Schema> {
        use utoipa::openapi::schema::{KnownFormat, ObjectBuilder, SchemaFormat, Type};
        ObjectBuilder::new()
            .schema_type(Type::String)
            .format(Some(SchemaFormat::KnownFormat(KnownFormat::Binary)))
            .description(Some("Raw file bytes."))
            .into()
    }
}

impl utoipa::ToSchema for FileBytes {}

/// The whole OpenAPI document (paths from the router, plus [`ApiDoc`]),
/// written for client generators ([`clients::for_clients`]).
pub fn document() -> utoipa::openapi::OpenApi {
    clients::for_clients(super::api_router().into_openapi())
}

/// The document as pretty JSON with a trailing newline (what `api/openapi.json` holds).
pub fn document_json() -> String {
    let mut s = document()
        .to_pretty_json()
        .unwrap_or_else(|e| format!("{{\"error\": \"{e}\"}}"));
    s.push('\n');
    s
}

#[cfg(test)]
mod tests {
    #[test]
    fn tagged_variants_accept_their_tag() {
        let doc = serde_json::to_value(super::document()).expect("json");
        for (schema, tag) in [
            ("IntensitySpec", "kind"),
            ("VesselnessSpec", "kind"),
            ("ConstantTensor", "kind"),
        ] {
            let s = &doc["components"]["schemas"][schema];
            assert_eq!(
                s["additionalProperties"],
                serde_json::json!(false),
                "{schema}"
            );
            assert!(
                s["properties"][tag].is_object(),
                "{schema} must list `{tag}` or no object satisfies its variant"
            );
        }
    }

    /// Rule 1 of `clients`: no union of objects is left without a
    /// discriminator (generators drop such schemas and the endpoints that
    /// use them), and every variant lists its tag as required.
    #[test]
    fn every_tagged_union_has_a_discriminator() {
        let doc = serde_json::to_value(super::document()).expect("json");
        let schemas = doc["components"]["schemas"].as_object().expect("schemas");
        let mut unions = 0;
        for (name, schema) in schemas {
            let Some(items) = schema["oneOf"].as_array() else {
                continue;
            };
            let objects = items
                .iter()
                .filter(|i| i["type"] == "object" || i["allOf"].is_array() || i["$ref"].is_string())
                .count();
            if objects < 2 {
                continue;
            }
            unions += 1;
            let d = &schema["discriminator"];
            let property = d["propertyName"]
                .as_str()
                .unwrap_or_else(|| panic!("{name}"));
            let mapping = d["mapping"].as_object().unwrap_or_else(|| panic!("{name}"));
            assert_eq!(mapping.len(), items.len(), "{name}");
            for (value, target) in mapping {
                let target = target
                    .as_str()
                    .and_then(|t| t.strip_prefix("#/components/schemas/"));
                let variant = &schemas[target.unwrap_or_default()];
                assert_eq!(variant["properties"][property]["enum"][0], *value, "{name}");
                assert!(
                    variant["required"]
                        .as_array()
                        .is_some_and(|r| r.iter().any(|n| n == property)),
                    "{name}: {value} requires {property}"
                );
            }
        }
        assert!(unions >= 5, "only {unions} tagged unions found");
    }

    /// Rule 3 of `clients`: operation ids are unique.
    #[test]
    fn operation_ids_are_unique() {
        let doc = serde_json::to_value(super::document()).expect("json");
        let mut seen = std::collections::HashSet::new();
        for item in doc["paths"].as_object().expect("paths").values() {
            for op in item.as_object().expect("item").values() {
                let id = op["operationId"].as_str().expect("operationId");
                assert!(seen.insert(id.to_string()), "{id} is used twice");
            }
        }
    }
}
