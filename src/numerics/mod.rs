//! The numerical core: pure functions over `ndarray` views and plain structs.
//!
//! Nothing in this module performs IO, spawns threads of its own, knows about
//! HTTP, async runtimes, JSON or storage. Every long computation takes a
//! [`control::Control`] (cancel flag + progress sink) and reports how it
//! stopped. Errors are per-module `thiserror` enums.
//!
//! # Conventions
//! * Point coordinates are in **array index order** (axis 0 first), in
//!   **index units**; the physical position of index `x` along axis `k` is
//!   `x * spacing[k]`.
//! * Grids are 2D or 3D. Internally a 2D grid is a 3D grid whose axis 0 has
//!   length 1 (see [`grid::Grid`]), so every solver has a single code path.
//!
//! # Index
//! * [`grid`]: grid shape, per-axis spacing, linear indexing.
//! * [`metric`]: isotropic cost `W(x)` (or speed `F = 1/W`) and obstacles.
//! * [`control`]: cancellation and progress reporting.
//! * [`heap`]: indexed 4-ary min-heap with decrease-key and per-cell tags (the narrow band).
//! * [`eikonal`]: the eikonal solvers (fast marching, fast sweeping, Dijkstra).
//! * [`exact`]: closed-form geodesic distances used as test oracles and in benchmarks.
//! * [`filters`]: Gaussian smoothing, gradients and Hessians (metric design).
//! * [`mesh`]: triangle meshes and their topology (surface solvers).
//! * [`edt`]: exact Euclidean distance transforms (binary, signed, multi-label, feature transform).
//! * [`contours`]: region boundaries of 2D label images as polygons with holes.
//! * [`skeleton`]: medial axis with pruning, 2D skeleton graphs.
//! * [`segmentation`]: geodesic Voronoi segmentation, Dice, Euclidean offsets.
//! * [`planning`]: motion planning for a disc robot (clearance, widest robot, safe paths).
//! * [`metric_design`]: costs built from images (intensity, edges, Frangi vesselness).
//! * [`paths`]: minimal paths by gradient descent of a distance map, with a discrete fallback.
//! * [`anisotropic`]: Riemannian tensor fields, adaptive-stencil fast marching, designed metrics.
//! * [`sampling`]: farthest-point sampling of grids with local fronts, geodesic
//!   Delaunay triangulations with their repair, Lloyd relaxation.
//! * [`meshing`]: meshes made from a metric (image meshing).
//! * [`shading`]: shape from shading (a Lambertian surface's height from its image) by fast marching.
//! * [`inverse`]: inverse problems through the adjoint of fast marching: travel-time
//!   tomography, metric fitting to example paths.
//! * [`shape`]: distance matrices, MDS, SMACOF, Isomap and canonical forms (chapter 5).

pub mod anisotropic;
pub mod buckets;
pub mod contours;
pub mod control;
pub mod edt;
pub mod eikonal;
pub mod exact;
pub mod filters;
pub mod grid;
pub mod grouping;
pub mod heap;
pub mod inverse;
pub mod mesh;
pub mod meshing;
pub mod metric;
pub mod metric_design;
pub mod paths;
pub mod planning;
pub mod polyline;
pub mod prefetch;
pub mod sampling;
pub mod segmentation;
pub mod shading;
pub mod shape;
pub mod skeleton;

pub use control::Control;
pub use eikonal::{
    solve, Connectivity, EikonalError, EikonalOptions, EikonalOutput, EikonalProblem, Method,
    Order, Source, StopReason, StopRules,
};
pub use grid::{Grid, GridError};
pub use metric::{IsotropicCost, MetricError};
