//! Geodesic sampling of grids (the monograph's section 4.2).
//!
//! * [`farthest`]: farthest-point sampling of a 2D or 3D grid under an
//!   isotropic cost, with local fronts (only the cells that get closer to a
//!   new sample are recomputed), optional fixed seeds, a count or a radius.
//! * `clustered`: the same through a grid of blocks of cells, one exact
//!   front per sample from the coarse map's bound (several times faster for
//!   thousands of samples).
//! * [`tensor_farthest`]: the same under a Riemannian metric (a tensor
//!   field), with the anisotropic solver's adaptive stencils.
//! * [`delaunay`]: geodesic Voronoi adjacency and vertices, the dual
//!   (geodesic Delaunay) triangulation and the repair of its failure modes.
//! * `farthest_cell`: the farthest cell of a map that local fronts lower
//!   (chunk maxima in a tournament tree), shared by both samplers.
//! * [`lloyd`]: geodesic Lloyd (centroidal Voronoi) relaxation.
//! * [`triangulation`]: the validity checker of planar triangulations.

mod clustered;
pub mod delaunay;
pub mod farthest;
mod farthest_cell;
pub mod lloyd;
pub mod tensor_farthest;
pub mod triangulation;

pub use farthest::{
    farthest_point_sampling, ClusteredReport, GridSampling, SamplingError, SamplingMethod,
    SamplingOptions, SamplingStop,
};
pub use tensor_farthest::tensor_farthest_point_sampling;
