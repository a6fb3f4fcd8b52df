//! Core errors as [`OpError`]s naming the request field at fault: one place
//! for the mappings shared by several operations.

use crate::numerics::edt::EdtError;
use crate::numerics::mesh::MeshSolveError;
use crate::numerics::{EikonalError, GridError};
use crate::ops::OpError;

pub(crate) fn grid_error(e: GridError, shape: &[usize]) -> OpError {
    match e {
        GridError::Spacing { axis, .. } => {
            OpError::invalid(format!("spacing[{axis}]"), e.to_string())
        }
        GridError::SpacingLength { .. } => OpError::invalid("spacing", e.to_string()),
        GridError::TooLarge(_) => OpError::TooLarge {
            field: "cost".into(),
            reason: e.to_string(),
        },
        _ => OpError::invalid("cost", format!("{e} (shape {shape:?})")),
    }
}

pub(crate) fn eikonal_error(e: EikonalError) -> OpError {
    match e {
        EikonalError::Cancelled => OpError::Cancelled,
        EikonalError::Source { index, reason } => {
            OpError::invalid(format!("sources[{index}]"), reason)
        }
        EikonalError::Target { index, reason } => {
            OpError::invalid(format!("stop.targets[{index}]"), reason)
        }
        EikonalError::NoSources => OpError::invalid("sources", e.to_string()),
        EikonalError::Option { field, reason } => OpError::invalid(field, reason),
        EikonalError::Grid(g) => OpError::invalid("cost", g.to_string()),
        EikonalError::Metric(m) => OpError::invalid("cost", m.to_string()),
        EikonalError::Range { field, reason } => OpError::invalid(field, reason),
    }
}

/// Maps a transform error.
pub fn edt_error(e: EdtError, field: &str) -> OpError {
    match e {
        EdtError::Cancelled => OpError::Cancelled,
        other => OpError::invalid(field, other.to_string()),
    }
}

/// Maps a core error to an operation error.
pub(crate) fn mesh_solve_error(e: MeshSolveError) -> OpError {
    match e {
        MeshSolveError::Cancelled => OpError::Cancelled,
        MeshSolveError::NoSources => OpError::invalid("sources", e.to_string()),
        MeshSolveError::InvalidSource { index, reason } => {
            OpError::invalid(format!("sources[{index}]"), reason)
        }
        MeshSolveError::InvalidOption { option, reason } => {
            let field = if option == "m" { "heat.m" } else { option };
            OpError::invalid(field, reason)
        }
        MeshSolveError::Numerical(reason) => OpError::invalid("mesh", reason),
    }
}
