//! Endpoints, one module per group.
//!
//! * [`health`]: `/healthz`, `/readyz`, `/metrics`.
//! * [`datasets`]: `/v1/datasets` upload, metadata, data, delete.
//! * [`grid`]: `POST /v1/grid/distance`.
//! * [`segment`]: `POST /v1/grid/{edt,segment,skeleton,offset,plan,sample}`.
//! * [`metric`]: `POST /v1/grid/metric`.
//! * [`group`]: `POST /v1/grid/group`.
//! * [`shading`]: `POST /v1/grid/shape-from-shading`.
//! * [`shape`]: `POST /v1/grid/shape-embed`.
//! * [`gradient`]: `POST /v1/grid/cost-gradient`.
//! * [`paths`]: `POST /v1/grid/paths`.
//! * [`inverse`]: `POST /v1/grid/tomography`, `POST /v1/grid/fit-metric`.
//! * [`tensor`]: `POST /v1/grid/tensor-distance`, `POST /v1/grid/tensor-metric`.
//! * [`mesh`]: `POST /v1/mesh/{distance,voronoi,curvature,paths,sample,distance-matrix,embed,descriptor}`.
//! * [`points`]: `POST /v1/points/isomap`.
//! * [`docs`]: `/openapi.json` and the Swagger UI at `/docs`.
//! * [`jobs`]: `/v1/jobs`: durable background jobs of any operation.
//! * [`collections`]: `/v1/collections`: shape collections and their nearest-shape queries.
//! * [`playground`]: the interactive page at `/playground` (`/` redirects to it).

pub mod collections;
pub mod datasets;
pub mod docs;
pub mod gradient;
pub mod grid;
pub mod group;
pub mod health;
pub mod inverse;
pub mod jobs;
pub mod mesh;
pub mod metric;
pub mod paths;
pub mod playground;
pub mod points;
pub mod segment;
pub mod shading;
pub mod shape;
pub mod tensor;

/// Checks the paging parameters of a listing (`GET /v1/jobs`,
/// `GET /v1/collections`): `limit` in 1..=1000 (default 50), and a `cursor`
/// that this service returned (`valid` accepts it; `what` names what a
/// cursor is, for the message). The limit to use.
pub(crate) fn check_page(
    limit: Option<i64>,
    cursor: Option<&str>,
    valid: impl Fn(&str) -> bool,
    what: &str,
) -> Result<i64, crate::problem::ApiError> {
    let limit = limit.unwrap_or(50);
    if !(1..=1000).contains(&limit) {
        return Err(crate::problem::ApiError::invalid_field(
            "limit",
            format!("{limit} must be between 1 and 1000"),
        ));
    }
    if cursor.is_some_and(|c| !valid(c)) {
        return Err(crate::problem::ApiError::invalid_field(
            "cursor",
            format!("not a cursor returned by this service ({what})"),
        ));
    }
    Ok(limit)
}
