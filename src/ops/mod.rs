//! Operations: one request schema per operation, shared by the synchronous
//! HTTP endpoint, the job queue and the command line, and the code that turns
//! a validated request plus its input arrays into a call of the core.
//!
//! Nothing here does IO: input datasets are handed in through [`Inputs`].
//!
//! * [`grid_distance`]: `grid.distance`, the eikonal distance map on a grid.

pub mod grid_distance;

use std::sync::Arc;

use crate::io::ArrayData;

/// An input array with the spacing its file declared (NIfTI voxel size), if any.
#[derive(Debug, Clone)]
pub struct InputArray {
    /// The values.
    pub array: Arc<ArrayData>,
    /// Physical spacing per axis, if the source format carries one.
    pub spacing: Option<Vec<f64>>,
}

/// Where an operation finds the datasets its request names.
pub trait Inputs {
    /// The dataset with this id, if it exists.
    fn get(&self, id: &str) -> Option<InputArray>;
}

impl Inputs for std::collections::HashMap<String, InputArray> {
    fn get(&self, id: &str) -> Option<InputArray> {
        std::collections::HashMap::get(self, id).cloned()
    }
}

/// Why an operation was refused or interrupted. `field` is a JSON path into
/// the request (`sources[2].point`, `cost.dataset`) so that clients can point
/// at the culprit.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum OpError {
    /// The request is well-formed JSON but a value is not acceptable.
    #[error("{field}: {reason}")]
    Invalid {
        /// Path of the offending field.
        field: String,
        /// Why it is refused.
        reason: String,
    },
    /// A dataset named by the request does not exist.
    #[error("{field}: dataset '{id}' not found")]
    UnknownDataset {
        /// Path of the field naming it.
        field: String,
        /// The id given.
        id: String,
    },
    /// The request asks for more than the configured limits allow.
    #[error("{field}: {reason}")]
    TooLarge {
        /// Path of the offending field.
        field: String,
        /// The limit that was exceeded.
        reason: String,
    },
    /// The caller cancelled the computation.
    #[error("cancelled")]
    Cancelled,
}

impl OpError {
    /// Shorthand for [`OpError::Invalid`].
    pub fn invalid(field: impl Into<String>, reason: impl Into<String>) -> Self {
        OpError::Invalid {
            field: field.into(),
            reason: reason.into(),
        }
    }

    /// The field this error points at, if any.
    pub fn field(&self) -> Option<&str> {
        match self {
            OpError::Invalid { field, .. }
            | OpError::UnknownDataset { field, .. }
            | OpError::TooLarge { field, .. } => Some(field),
            OpError::Cancelled => None,
        }
    }
}

/// Limits an operation enforces before it allocates anything.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OpLimits {
    /// Largest grid, in cells.
    pub max_cells: usize,
    /// Most sources in one request.
    pub max_sources: usize,
}

impl Default for OpLimits {
    fn default() -> Self {
        Self {
            max_cells: 512 * 512 * 512,
            max_sources: 100_000,
        }
    }
}
