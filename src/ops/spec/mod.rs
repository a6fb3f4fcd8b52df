//! The request pieces shared by several operations, each defined once with
//! its defaults and validation. Operation files (`ops/grid_*.rs`,
//! `ops/mesh_*.rs`) import these and never each other.
//!
//! * [`cost`]: the `cost` section (dataset, constant, speed, design) and
//!   [`cost::resolve_cost`].
//! * [`design`]: the `design` section (intensity, edges, vesselness).
//! * [`tensor`]: the `tensor`/`metric` section (Riemannian metrics) and the
//!   anisotropic solve.
//! * [`scheme`]: sources, method, order, connectivity, stop rules, outputs.
//! * [`distance`]: the distance request and its solve, shared by
//!   `grid.distance`, `grid.segment` and `grid.offset`.
//! * [`grid`]: input checks of the grid operations (fetch, shapes, spacing,
//!   masks).
//! * [`mesh`]: surface points, mesh methods, the mesh input and the
//!   distance solve shared by the mesh operations.
//! * [`mesh_metric`]: the `metric` section of the mesh operations (designs
//!   from curvature or a field, face tensors) and its resolution.
//! * [`shape`]: size limits, symmetrisation and errors of the shape operations.
//! * [`map_cache`]: designed costs and distance maps kept between requests
//!   (`grid.paths`, `grid.distance`), with their keys.
//! * [`errors`]: core errors as [`crate::ops::OpError`]s naming the field.
//! * [`defaults`]: the serde defaults.

pub mod cost;
pub mod defaults;
pub mod design;
pub mod distance;
pub mod errors;
pub mod grid;
pub mod map_cache;
pub mod mesh;
pub mod mesh_metric;
pub mod scheme;
pub mod shape;
pub mod tensor;
