//! Pieces shared by the shape operations (`mesh.distance_matrix`,
//! `mesh.embed`, `points.isomap`): the size limits of all-pairs matrices,
//! the symmetrisation rule, the landmark count, and the mapping of the
//! core's [`ShapeError`].

use ndarray::Array2;
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use std::sync::Arc;

use super::errors::mesh_solve_error;
use super::mesh::{heat_solver, HeatSpec, MeshInput};
use crate::io::ArrayData;
use crate::numerics::mesh::{HeatSolver, MeshMethod};
use crate::numerics::shape::matrix::Symmetry;
use crate::numerics::shape::ShapeError;
use crate::numerics::Control;
use crate::ops::{Inputs, OpError, OutputArray};

/// Most points (vertices) an all-pairs matrix or embedding takes: `n²`
/// doubles, 200 MB at the limit. Above it, landmark rows are required.
pub const ALL_PAIRS_LIMIT: usize = 5000;

/// Most entries of a landmark-row matrix (`landmarks × n`): 512 MB of doubles.
pub const MAX_MATRIX_ENTRIES: usize = 1 << 26;

/// How a distance matrix is made symmetric where the method is not.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum SymmetrySpec {
    /// `(D[i, j] + D[j, i]) / 2`: the closest symmetric matrix (default).
    #[default]
    Average,
    /// `min(D[i, j], D[j, i])`: for methods that only overestimate.
    Min,
    /// As solved.
    None,
}

impl From<SymmetrySpec> for Symmetry {
    fn from(s: SymmetrySpec) -> Self {
        match s {
            SymmetrySpec::Average => Symmetry::Average,
            SymmetrySpec::Min => Symmetry::Min,
            SymmetrySpec::None => Symmetry::None,
        }
    }
}

/// Checks a landmark count (`None`: all pairs) against the number of
/// points `n` and the limits; `field` names the input (`mesh`, `points`).
pub(crate) fn check_size(n: usize, landmarks: Option<usize>, field: &str) -> Result<(), OpError> {
    match landmarks {
        None if n > ALL_PAIRS_LIMIT => Err(OpError::TooLarge {
            field: "landmarks".into(),
            reason: format!(
                "the {field} has {n} points and all pairs are limited to {ALL_PAIRS_LIMIT} \
                 ({n}² distances): give `landmarks` (for example 500) to compute landmark rows instead"
            ),
        }),
        Some(0) => Err(OpError::invalid("landmarks", "must be >= 1")),
        Some(k) if k.saturating_mul(n) > MAX_MATRIX_ENTRIES => Err(OpError::TooLarge {
            field: "landmarks".into(),
            reason: format!(
                "{k} landmarks × {n} points is more than {MAX_MATRIX_ENTRIES} distances: give fewer landmarks"
            ),
        }),
        _ => Ok(()),
    }
}

/// Maps a core error; `disconnected` names the field whose change connects
/// the input (`mesh`, or `k` for a neighbour graph).
pub(crate) fn shape_error(e: ShapeError, input: &str) -> OpError {
    match e {
        ShapeError::Cancelled => OpError::Cancelled,
        ShapeError::InvalidOption { option, reason } => OpError::invalid(option, reason),
        ShapeError::Disconnected { what, .. } => {
            // The neighbour graph of a point cloud is connected by raising `k`;
            // a mesh or a mask is the input itself.
            let field = if what == "neighbour graph" {
                "k"
            } else {
                input
            };
            OpError::invalid(field, e.to_string())
        }
        ShapeError::Solve(s) => mesh_solve_error(s),
        ShapeError::Numerical(reason) => OpError::invalid(input, reason),
    }
}

/// A 2D f64 output array.
pub(crate) fn matrix_output(name: &str, a: Array2<f64>) -> OutputArray {
    OutputArray {
        name: name.into(),
        array: ArrayData::F64(a.into_dyn()),
        spacing: None,
    }
}

/// Refuses a mesh of several components for a shape operation, whose
/// distances between components would be infinite: `field` names the mesh,
/// `result` what needs one component ("an embedding"), `way_out` what to do
/// instead ("split the mesh and embed each component").
pub(crate) fn check_connected(
    input: &MeshInput,
    field: &str,
    result: &str,
    way_out: &str,
) -> Result<(), OpError> {
    if input.topology.components > 1 {
        return Err(OpError::invalid(
            field,
            format!(
                "the mesh has {} connected components (its report counts {} isolated vertices): \
                 {result} needs one; {way_out}",
                input.topology.components, input.report.isolated_vertices
            ),
        ));
    }
    Ok(())
}

/// The mesh's (cached) heat solver when `method` is the heat method.
pub(crate) fn heat_for(
    inputs: &dyn Inputs,
    method: MeshMethod,
    mesh_id: &str,
    input: &MeshInput,
    heat: &HeatSpec,
    control: &Control<'_>,
) -> Result<Option<Arc<HeatSolver>>, OpError> {
    if method != MeshMethod::Heat {
        return Ok(None);
    }
    Ok(Some(heat_solver(inputs, mesh_id, input, heat, control)?.0))
}
