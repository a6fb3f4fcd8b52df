//! Medial axis (skeleton) of a binary shape in 2D and 3D, with pruning by a
//! length that has a geometric meaning, and in 2D the skeleton as a graph of
//! polylines.
//!
//! # Method
//! Let `D` be the distance from a cell of the shape to the nearest cell
//! outside it and `F` the nearest-boundary-point map (the exact transform and
//! feature transform of [`crate::numerics::edt`]; the grid is padded by one
//! empty cell so that the outside of the grid counts as outside the shape).
//! The medial axis is where `D` is not differentiable: where two neighbouring
//! cells `x`, `y` have nearest boundary points `a = F(x)`, `b = F(y)` far
//! apart (seed §1.4.2, §2.6.2). The pair is kept when the two points are far
//! apart *along the boundary*:
//! * 2D: `ℓ(a, b)`, the length of the shorter arc of the boundary curve from
//!   `a` to `b` (measured on the polygon through the midpoints of the cell
//!   edges that separate the shape from the outside; infinite when `a` and `b`
//!   lie on different boundary curves, e.g. around a hole), must be at least
//!   `τ = max(min_boundary_length, min_boundary_fraction · |C|, 3 h_max)`,
//!   where `|C|` is the length of that boundary curve. A bump of the boundary
//!   whose perimeter is below `τ` grows no branch; the branch toward a corner
//!   of angle `θ` starts where the distance to the corner's sides exceeds `τ/2`.
//! * 3D: the chord `|a - b|` must be at least
//!   `τ = max(min_boundary_length, min_boundary_fraction · 2 max D, 3 h_max)`
//!   (the λ-medial axis of Chazal–Lieutier).
//!
//! Of the two cells of a kept pair, the one nearer to the bisector of `a` and
//! `b` (smaller `|x - b| - |x - a|`) is marked. In 2D the marks are thinned to
//! one cell (Zhang–Suen, which keeps end points and connectivity). In 3D the
//! marks are the anchors of a topology-preserving thinning of the whole shape
//! (removal of simple points in the (26, 6) connectivity, shallowest first,
//! peeled from the six directions in turn, never the end of a curve that is
//! a mark): the result is a curve skeleton, one cell thin, with the topology
//! of the shape (26-components, tunnels; a cavity keeps a closed surface
//! around it), whose curves end on medial cells (see `thin_3d`). Pruning acts
//! through the marks: a branch survives only where it ends on a kept mark.
//! The radius
//! function is `D` on the skeleton (distance between cell centres; the
//! inscribed disc reaches the boundary edges at `D - h/2`).
//!
//! Cost: one EDT plus `O(N)`.
//!
//! # Files
//! * `medial_axis.rs`: padding, the pairs rule and the medial cells, the
//!   crop back to the caller's grid ([`medial_axis`]).
//! * `thinning_2d.rs`: Zhang–Suen thinning of the 2D marks.
//! * `thinning_3d.rs` and `simple_points.rs`: the 3D curve-skeleton thinning
//!   and its simple-point test in the (26, 6) connectivity.
//! * `graph.rs`: the 2D skeleton as a graph ([`graph_2d`]).

mod graph;
mod medial_axis;
mod simple_points;
mod thinning_2d;
mod thinning_3d;

pub use graph::{graph_2d, SkeletonEdge, SkeletonGraph, SkeletonNode};
pub use medial_axis::medial_axis;

use super::edt::EdtError;

/// Options of [`medial_axis`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SkeletonOptions {
    /// Smallest boundary length (2D: arc, 3D: chord) between the two nearest
    /// boundary points of a kept pair, in physical units. Default: 0.
    pub min_boundary_length: f64,
    /// Smallest length as a fraction of the boundary curve's length (2D) or of
    /// the largest inscribed diameter (3D). Default: 0.08. Setting both to 0
    /// turns pruning off (the floor of 3 cells that filters pixel noise stays).
    pub min_boundary_fraction: f64,
}

impl Default for SkeletonOptions {
    fn default() -> Self {
        Self {
            min_boundary_length: 0.0,
            min_boundary_fraction: 0.08,
        }
    }
}

impl SkeletonOptions {
    /// No pruning beyond the 3-cell floor.
    pub const OFF: Self = Self {
        min_boundary_length: 0.0,
        min_boundary_fraction: 0.0,
    };
}

/// Why a skeleton was refused or interrupted.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SkeletonError {
    /// The distance transform failed.
    #[error(transparent)]
    Edt(#[from] EdtError),
    /// The mask does not have one value per cell.
    #[error("the mask has {got} values but the grid has {expected} cells")]
    Length {
        /// Values given.
        got: usize,
        /// Cells.
        expected: usize,
    },
    /// An option is out of range.
    #[error("{field}: {reason}")]
    Option {
        /// The option.
        field: &'static str,
        /// Why.
        reason: String,
    },
}

/// The medial axis of a shape.
#[derive(Debug, Clone, PartialEq)]
pub struct Skeleton {
    /// Skeleton cells (C order).
    pub mask: Vec<bool>,
    /// Distance to the nearest cell outside the shape on skeleton cells, 0 elsewhere.
    pub radius: Vec<f64>,
    /// The distance to the nearest outside cell on the whole grid (0 outside the shape).
    pub distance: Vec<f64>,
    /// 2D only: the skeleton as a graph (in 3D, `mask` holds a curve skeleton).
    pub graph: Option<SkeletonGraph>,
}
