//! Meshes made from a metric (the monograph's chapter 4): the metric decides
//! where the vertices go (farthest-point sampling), the geodesic Voronoi
//! cells which vertices are neighbours (the geodesic Delaunay dual of
//! [`crate::numerics::sampling::delaunay`]).
//!
//! * [`domain`]: domain meshing (section 4.5): polygons with holes or a
//!   mask, boundary first, constrained Delaunay, relaxation and Ruppert
//!   refinement to an angle bound, under an optional isotropic metric.
//! * [`image`]: image meshing (section 4.3, Bougleux, Peyré and Cohen): a
//!   metric from the image, its triangulation, the piecewise-linear
//!   approximation of the image on it and its L2 error.
//! * [`image_flips`]: data-dependent edge flips that lower that error.
//! * [`image_moves`]: vertex moves (with those flips) that lower it further.
//! * [`surface`]: surface remeshing (sections 4.4 and 4.6): geodesic
//!   sampling, geodesic Lloyd relaxation and the dual of the Voronoi cells.
//! * [`surface_relax`]: the remesh's last step: edge flips and tangential
//!   relaxation of its vertices, projected back onto the input surface.

pub mod cluster_sampling;
pub mod domain;
pub mod image;
pub mod image_flips;
pub mod image_moves;
pub mod surface;
pub mod surface_relax;

pub use image::{
    mesh_image, piecewise_linear, ImageMesh, ImageMeshOptions, ImageMetric, MeshingError,
};
