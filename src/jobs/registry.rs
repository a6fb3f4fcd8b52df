//! The operations a job can run, by [`Operation::NAME`].
//!
//! Each entry is three functions monomorphised from one request type:
//! parse + validate at submit time (a 4xx naming `params.<field>`), list the
//! datasets it reads, and run it (parse again, then [`Operation::run`]).
//! Adding an operation to the queue is one line in [`ENTRIES`].

use serde_json::Value;

use crate::http::error::ApiError;
use crate::http::extract::json_rejection;
use crate::numerics::Control;
use crate::ops::{Inputs, OpError, OpLimits, OpOutput, Operation};

/// One operation the queue can run.
#[derive(Debug, Clone, Copy)]
pub struct Entry {
    /// [`Operation::NAME`].
    pub name: &'static str,
    /// Parses and validates `params`; returns the canonical JSON and the
    /// dataset ids it reads (each with the field naming it, `params.` prefixed).
    pub prepare: fn(&Value, &OpLimits) -> Result<Prepared, ApiError>,
    /// Runs the operation on already-validated canonical params.
    pub run: fn(&str, &dyn Inputs, &OpLimits, &Control<'_>) -> Result<OpOutput, OpError>,
}

/// A validated request.
#[derive(Debug, Clone, PartialEq)]
pub struct Prepared {
    /// The request re-serialised (defaults filled in).
    pub canonical: String,
    /// `(field, dataset id)` pairs, fields as `params.<path>`.
    pub datasets: Vec<(String, String)>,
}

/// Every operation a job can name. Add new operations here, one line each.
pub const ENTRIES: &[Entry] = &[
    entry::<crate::ops::grid_distance::GridDistanceRequest>(),
    entry::<crate::ops::grid_metric::GridMetricRequest>(),
    entry::<crate::ops::grid_paths::GridPathsRequest>(),
    entry::<crate::ops::grid_edt::GridEdtRequest>(),
    entry::<crate::ops::grid_segment::GridSegmentRequest>(),
    entry::<crate::ops::grid_skeleton::GridSkeletonRequest>(),
    entry::<crate::ops::grid_offset::GridOffsetRequest>(),
    entry::<crate::ops::grid_plan::GridPlanRequest>(),
    entry::<crate::ops::grid_tensor_distance::GridTensorDistanceRequest>(),
    entry::<crate::ops::grid_tensor_metric::GridTensorMetricRequest>(),
    entry::<crate::ops::mesh_distance::MeshDistanceRequest>(),
    entry::<crate::ops::mesh_voronoi::MeshVoronoiRequest>(),
    entry::<crate::ops::mesh_paths::MeshPathsRequest>(),
    entry::<crate::ops::mesh_sample::MeshSampleRequest>(),
];

/// The entry of an operation.
pub const fn entry<O: Operation>() -> Entry {
    Entry {
        name: O::NAME,
        prepare: prepare::<O>,
        run: run::<O>,
    }
}

/// Finds an operation by name.
pub fn find(name: &str) -> Option<&'static Entry> {
    ENTRIES.iter().find(|e| e.name == name)
}

/// The names of every operation, for error messages and docs.
pub fn names() -> Vec<&'static str> {
    ENTRIES.iter().map(|e| e.name).collect()
}

/// Prefixes the field of a problem with `prefix.` (`params.sources[0]`).
pub fn prefix_field(mut e: ApiError, prefix: &str) -> ApiError {
    match e.problem.field.take() {
        Some(f) if f != "body" => {
            if e.problem.detail.starts_with(&f) {
                e.problem.detail = format!("{prefix}.{}", e.problem.detail);
            } else {
                e.problem.detail = format!("{prefix}.{f}: {}", e.problem.detail);
            }
            e.problem.field = Some(format!("{prefix}.{f}"));
        }
        _ => {
            e.problem.detail = format!("{prefix}: {}", e.problem.detail);
            e.problem.field = Some(prefix.to_string());
        }
    }
    e
}

fn parse<O: Operation>(params: &[u8]) -> Result<O, ApiError> {
    // axum's parser reports the JSON path of the offending field.
    axum::Json::<O>::from_bytes(params)
        .map(|j| j.0)
        .map_err(|e| prefix_field(json_rejection(e), "params"))
}

fn prepare<O: Operation>(params: &Value, limits: &OpLimits) -> Result<Prepared, ApiError> {
    let bytes = serde_json::to_vec(params).map_err(ApiError::internal)?;
    let op: O = parse(&bytes)?;
    op.validate(limits)
        .map_err(|e| prefix_field(ApiError::from(e), "params"))?;
    let canonical = serde_json::to_string(&op).map_err(ApiError::internal)?;
    let datasets = op
        .dataset_ids()
        .into_iter()
        .map(|(field, id)| (format!("params.{field}"), id))
        .collect();
    Ok(Prepared {
        canonical,
        datasets,
    })
}

fn run<O: Operation>(
    params: &str,
    inputs: &dyn Inputs,
    limits: &OpLimits,
    control: &Control<'_>,
) -> Result<OpOutput, OpError> {
    let op: O = serde_json::from_str(params)
        .map_err(|e| OpError::invalid("params", format!("stored request unreadable: {e}")))?;
    op.run(inputs, limits, control)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_operation_is_registered_once() {
        let mut names: Vec<&str> = ENTRIES.iter().map(|e| e.name).collect();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), ENTRIES.len(), "duplicate operation names");
        for name in [
            "grid.paths",
            "grid.edt",
            "grid.tensor_distance",
            "mesh.distance",
            "mesh.sample",
        ] {
            assert!(find(name).is_some(), "{name} is not registered");
        }
        // A mesh request names its mesh under `params.mesh`, which is how the worker knows to load a mesh.
        let e = find("mesh.distance").expect("registered");
        let req = serde_json::json!({"mesh": "ds_m", "sources": [{"vertex": 0}]});
        let p = (e.prepare)(&req, &OpLimits::default()).expect("valid");
        assert_eq!(
            p.datasets,
            vec![("params.mesh".to_string(), "ds_m".to_string())]
        );
    }

    #[test]
    fn grid_distance_is_registered_and_validates() {
        let e = find("grid.distance").expect("registered");
        let ok = serde_json::json!({"cost": {"constant": 1.0, "shape": [8, 8]}, "sources": [{"point": [1.0, 1.0]}]});
        let p = (e.prepare)(&ok, &OpLimits::default()).expect("valid");
        assert!(p.canonical.contains("\"order\":2"), "{}", p.canonical);
        assert!(p.datasets.is_empty());
        let bad = serde_json::json!({"cost": {"constant": 1.0, "shape": [8, 8]}, "sources": [{"point": [1.0, 1.0]}], "bogus": 1});
        let err = (e.prepare)(&bad, &OpLimits::default()).expect_err("unknown field");
        assert_eq!(err.problem.field.as_deref(), Some("params.bogus"));
        assert_eq!(err.problem.status, 422);
        let neg = serde_json::json!({"cost": {"constant": -1.0, "shape": [8, 8]}, "sources": [{"point": [1.0, 1.0]}]});
        let err = (e.prepare)(&neg, &OpLimits::default()).expect_err("negative cost");
        assert_eq!(err.problem.field.as_deref(), Some("params.cost.constant"));
        let ds =
            serde_json::json!({"cost": {"dataset": "ds_x"}, "sources": [{"point": [1.0, 1.0]}]});
        let p = (e.prepare)(&ds, &OpLimits::default()).expect("valid");
        assert_eq!(
            p.datasets,
            vec![("params.cost.dataset".to_string(), "ds_x".to_string())]
        );
        assert!(find("nope").is_none());
    }
}
