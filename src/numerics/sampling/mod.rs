//! Geodesic sampling of grids (the monograph's section 4.2).
//!
//! * [`farthest`]: farthest-point sampling of a 2D or 3D grid under an
//!   isotropic cost, with local fronts (only the cells that get closer to a
//!   new sample are recomputed), optional fixed seeds, a count or a radius.

pub mod farthest;

pub use farthest::{
    farthest_point_sampling, GridSampling, SamplingError, SamplingOptions, SamplingStop,
};
