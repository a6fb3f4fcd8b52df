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
//! * [`anisotropic`]: Riemannian tensor fields, adaptive-stencil fast marching, designed metrics.

pub mod anisotropic;
pub mod control;
pub mod eikonal;
pub mod exact;
pub mod filters;
pub mod grid;
pub mod heap;
pub mod mesh;
pub mod metric;

pub use control::Control;
pub use eikonal::{
    solve, Connectivity, EikonalError, EikonalOptions, EikonalOutput, EikonalProblem, Method,
    Order, Source, StopReason, StopRules,
};
pub use grid::{Grid, GridError};
pub use metric::{IsotropicCost, MetricError};
