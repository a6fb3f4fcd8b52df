//! Every operation by [`Operation::NAME`]: how a job request (`operation`
//! and `params`) becomes a request of the right type.
//!
//! Each entry is one function monomorphised from one request type that
//! parses JSON into a boxed [`DynOperation`]. Adding an operation to the
//! service is one line in [`ENTRIES`] (plus its endpoint and CLI, which build
//! the typed request themselves).

use serde_json::Value;

use super::parse::{parse_json, ParseError};
use super::{DynOperation, OpError, OpLimits, Operation};

/// Parses a request of one operation from JSON.
pub type ParseFn = fn(&[u8]) -> Result<Box<dyn DynOperation>, ParseError>;

/// One operation the service can run by name.
#[derive(Debug, Clone, Copy)]
pub struct Entry {
    /// [`Operation::NAME`].
    pub name: &'static str,
    /// Parses a request of this operation from JSON.
    pub parse: ParseFn,
    /// The request type's id (how the parser finds an operation's renamed
    /// fields, [`super::renamed`]).
    pub type_id: fn() -> std::any::TypeId,
}

/// A validated request.
#[derive(Debug)]
pub struct Prepared {
    /// The request.
    pub operation: Box<dyn DynOperation>,
    /// The request re-serialised (defaults filled in).
    pub canonical: String,
    /// `(field, dataset id)` pairs, fields as `params.<path>`.
    pub datasets: Vec<(String, String)>,
}

/// Why `params` are not a request of the operation, with fields as
/// `params.<path>`.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PrepareError {
    /// Not a request of this shape.
    #[error(transparent)]
    Parse(ParseError),
    /// A request, but a value is refused.
    #[error(transparent)]
    Invalid(OpError),
}

/// Every operation a job can name. Add new operations here, one line each.
pub const ENTRIES: &[Entry] = &[
    entry::<super::grid_distance::GridDistanceRequest>(),
    entry::<super::grid_metric::GridMetricRequest>(),
    entry::<super::grid_paths::GridPathsRequest>(),
    entry::<super::grid_edt::GridEdtRequest>(),
    entry::<super::grid_segment::GridSegmentRequest>(),
    entry::<super::grid_skeleton::GridSkeletonRequest>(),
    entry::<super::grid_offset::GridOffsetRequest>(),
    entry::<super::grid_plan::GridPlanRequest>(),
    entry::<super::grid_sample::GridSampleRequest>(),
    entry::<super::grid_mesh::GridMeshRequest>(),
    entry::<super::domain_mesh::DomainMeshRequest>(),
    entry::<super::grid_shading::GridShadingRequest>(),
    entry::<super::grid_shape_embed::GridShapeEmbedRequest>(),
    entry::<super::grid_cost_gradient::GridCostGradientRequest>(),
    entry::<super::grid_tomography::GridTomographyRequest>(),
    entry::<super::grid_fit_metric::GridFitMetricRequest>(),
    entry::<super::grid_group::GridGroupRequest>(),
    entry::<super::grid_tensor_distance::GridTensorDistanceRequest>(),
    entry::<super::grid_tensor_metric::GridTensorMetricRequest>(),
    entry::<super::mesh_distance::MeshDistanceRequest>(),
    entry::<super::mesh_voronoi::MeshVoronoiRequest>(),
    entry::<super::mesh_curvature::MeshCurvatureRequest>(),
    entry::<super::mesh_paths::MeshPathsRequest>(),
    entry::<super::mesh_sample::MeshSampleRequest>(),
    entry::<super::mesh_remesh::MeshRemeshRequest>(),
    entry::<super::mesh_distance_matrix::MeshDistanceMatrixRequest>(),
    entry::<super::mesh_embed::MeshEmbedRequest>(),
    entry::<super::mesh_descriptor::MeshDescriptorRequest>(),
    entry::<super::mesh_correspond::MeshCorrespondRequest>(),
    entry::<super::points_isomap::PointsIsomapRequest>(),
];

/// The entry of an operation.
pub const fn entry<O: Operation + std::fmt::Debug>() -> Entry {
    Entry {
        name: O::NAME,
        parse: parse::<O>,
        type_id: std::any::TypeId::of::<O>,
    }
}

fn parse<O: Operation + std::fmt::Debug>(
    bytes: &[u8],
) -> Result<Box<dyn DynOperation>, ParseError> {
    Ok(Box::new(parse_json::<O>(bytes)?))
}

/// Finds an operation by name.
pub fn find(name: &str) -> Option<&'static Entry> {
    ENTRIES.iter().find(|e| e.name == name)
}

/// The names of every operation, for error messages and docs.
pub fn names() -> Vec<&'static str> {
    ENTRIES.iter().map(|e| e.name).collect()
}

impl Entry {
    /// Parses and validates `params`: the request, its canonical JSON and the
    /// datasets it reads (fields prefixed `params.`).
    pub fn prepare(&self, params: &Value, limits: &OpLimits) -> Result<Prepared, PrepareError> {
        let bytes = serde_json::to_vec(params)
            .map_err(|e| PrepareError::Parse(ParseError::Syntax(e.to_string())))?;
        let operation = (self.parse)(&bytes).map_err(PrepareError::Parse)?;
        operation.validate(limits).map_err(PrepareError::Invalid)?;
        let canonical = operation
            .canonical_json()
            .map_err(|e| PrepareError::Parse(ParseError::Syntax(e.to_string())))?;
        let datasets = operation
            .dataset_ids()
            .into_iter()
            .map(|(field, id)| (format!("params.{field}"), id))
            .collect();
        Ok(Prepared {
            operation,
            canonical,
            datasets,
        })
    }
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
        let p = e.prepare(&req, &OpLimits::default()).expect("valid");
        assert_eq!(
            p.datasets,
            vec![("params.mesh".to_string(), "ds_m".to_string())]
        );
    }

    #[test]
    fn grid_distance_is_registered_and_validates() {
        let e = find("grid.distance").expect("registered");
        let ok = serde_json::json!({"cost": {"constant": 1.0, "shape": [8, 8]}, "sources": [{"point": [1.0, 1.0]}]});
        let p = e.prepare(&ok, &OpLimits::default()).expect("valid");
        assert!(p.canonical.contains("\"order\":2"), "{}", p.canonical);
        assert!(p.datasets.is_empty());
        let bad = serde_json::json!({"cost": {"constant": 1.0, "shape": [8, 8]}, "sources": [{"point": [1.0, 1.0]}], "bogus": 1});
        let err = e
            .prepare(&bad, &OpLimits::default())
            .expect_err("unknown field");
        let err = crate::problem::ApiError::from(err);
        assert_eq!(err.problem.field.as_deref(), Some("params.bogus"));
        assert_eq!(err.problem.status, 422);
        let neg = serde_json::json!({"cost": {"constant": -1.0, "shape": [8, 8]}, "sources": [{"point": [1.0, 1.0]}]});
        let err = e
            .prepare(&neg, &OpLimits::default())
            .expect_err("negative cost");
        let err = crate::problem::ApiError::from(err);
        assert_eq!(err.problem.field.as_deref(), Some("params.cost.constant"));
        let ds =
            serde_json::json!({"cost": {"dataset": "ds_x"}, "sources": [{"point": [1.0, 1.0]}]});
        let p = e.prepare(&ds, &OpLimits::default()).expect("valid");
        assert_eq!(
            p.datasets,
            vec![("params.cost.dataset".to_string(), "ds_x".to_string())]
        );
        assert!(find("nope").is_none());
    }

    #[test]
    fn canonical_json_reads_back_to_the_same_floats() {
        // Without serde_json's `float_roundtrip` these read back one ulp
        // off, and so did a request's canonical JSON (found by fuzzing).
        let e = find("grid.distance").expect("registered");
        let body = br#"{"cost": {"constant": 2.2201838057111728e-13, "shape": [8, 8]},
            "sources": [{"point": [1.1362275116276523e-8, 4.897745441634975e-53]}]}"#;
        let request = (e.parse)(body).expect("parses");
        let canonical = request.canonical_json().expect("serialises");
        for float in [
            "2.2201838057111728e-13",
            "1.1362275116276523e-8",
            "4.897745441634975e-53",
        ] {
            assert!(canonical.contains(float), "{float} lost in {canonical}");
        }
        let again = (e.parse)(canonical.as_bytes()).expect("parses again");
        assert_eq!(again.canonical_json().expect("serialises"), canonical);
    }
}
