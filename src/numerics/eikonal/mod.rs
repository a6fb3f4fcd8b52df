//! Solvers of the isotropic eikonal equation on 2D and 3D grids.
//!
//! Given a cost `W(x) > 0` and sources `S`, the geodesic distance `U` is the
//! viscosity solution of
//!
//! ```text
//! |∇U(x)| = W(x)  in the domain,     U = U_0  on S
//! ```
//!
//! (seed eq. 1.22 and section 2.1). Every solver here also returns the
//! geodesic Voronoi partition `ℓ(x)`: the index of the source whose front
//! reached `x` first (seed eq. 1.19).
//!
//! Methods, chosen with [`EikonalOptions::method`]:
//! * [`Method::FastMarching`]: Sethian / Tsitsiklis fast marching with the
//!   upwind quadratic update; first or second order ([`Order`]), with static
//!   source factoring around point sources. `O(N log N)`.
//! * [`Method::FastSweeping`]: Gauss–Seidel sweeps of the same upwind update in
//!   the `2^d` axis orderings until the largest change is below a tolerance.
//! * [`Method::Dijkstra`]: shortest paths on the grid graph, the graph
//!   baseline, with metrication error (see [`Connectivity`]).
//!
//! Level sets and masks as sources ([`level_set_distance`], [`mask_source`]):
//! the distance to the zero level set of `phi`, located at sub-cell accuracy,
//! signed on request (redistancing), and every non-zero cell of a mask as a
//! source of value 0.
//!
//! Sensitivity to the cost ([`cost_gradient`], [`distance_gradient`]): the
//! gradient of `J = Σ w_m U(y_m)` with respect to `W` at every cell, the
//! discrete adjoint of first-order fast marching (one backward sweep in
//! decreasing `U`, seed section 2.9).

mod dijkstra;
mod fast_marching;
mod fast_sweeping;
mod gradient;
mod level_set;
mod sources;
// Crate-visible: farthest-point sampling (`numerics::sampling`) marches
// its local fronts with the same update as the multi-source fast marching.
pub(crate) mod update;

pub use gradient::{adjoint_options, cost_gradient, distance_gradient, probe_values, Probe};
pub(crate) use gradient::{backward_order, point_corners, probe_weights};
pub use level_set::{
    level_set_distance, locate_interface, mask_source, Interface, InterfaceFit, LevelSetError,
    LevelSetOptions,
};
pub use sources::{nearest_cell, target_cells, InitialFront, SeedCell, SeedPoint};

use ndarray::ArrayD;

use super::control::Control;
use super::grid::{Grid, GridError};
use super::metric::{IsotropicCost, MetricError};

/// A source of the front: `U` is prescribed there and its label is its
/// position in [`EikonalProblem::sources`].
#[derive(Debug, Clone, PartialEq)]
pub enum Source {
    /// A point in index coordinates (axis 0 first), possibly between cells.
    /// The cells within [`EikonalOptions::source_radius`] of it are initialised
    /// with the exact local solution `U(x) = W(p) |x - p|`, so a point source
    /// has no `O(h)` bias.
    Point(Vec<f64>),
    /// A set of cells with initial values (a curve, the boundary of a region).
    Cells {
        /// Cell indices in array index order.
        cells: Vec<Vec<usize>>,
        /// One finite initial value per cell, or `None` for all zeros.
        values: Option<Vec<f64>>,
    },
}

/// The input of a solve: domain, metric and sources.
#[derive(Debug, Clone)]
pub struct EikonalProblem<'a> {
    /// Shape and spacing.
    pub grid: Grid,
    /// The cost `W` (walls included).
    pub cost: IsotropicCost<'a>,
    /// At least one source; the label of a cell is the index of its source here.
    pub sources: Vec<Source>,
}

/// Which algorithm solves the problem.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Method {
    /// Fast marching (default).
    #[default]
    FastMarching,
    /// Fast sweeping (Gauss–Seidel in the `2^d` orderings).
    FastSweeping,
    /// Dijkstra on the grid graph.
    Dijkstra,
}

/// Order of the finite-difference scheme (fast marching and fast sweeping).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Order {
    /// One-sided first-order differences.
    First,
    /// Second-order one-sided differences where both upwind neighbours are
    /// known and the discriminant is non-negative; first order elsewhere.
    #[default]
    Second,
}

/// Neighbourhood of the grid graph used by [`Method::Dijkstra`].
///
/// Worst-case relative metrication error of a graph path against the
/// Euclidean length (Goodchild): 41.4 % (4 neighbours), 8.2 % (8), 2.79 % (16)
/// in 2D; 73.2 % (6), 22.5 % (18), 12.8 % (26) in 3D.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Connectivity {
    /// 4 neighbours in 2D, 6 in 3D.
    Axial,
    /// 8 neighbours in 2D, 18 in 3D (face and edge diagonals).
    #[default]
    Diagonal,
    /// 16 neighbours in 2D (adds the knight moves), 26 in 3D (the full cube).
    Extended,
}

/// When to stop before every reachable cell is computed.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct StopRules {
    /// Stop once every one of these points (index coordinates) is frozen;
    /// a point between cells counts as frozen when its nearest cell is.
    pub targets: Vec<Vec<f64>>,
    /// Stop once the front passes this distance: cells beyond keep `+inf` (a geodesic ball).
    pub max_distance: Option<f64>,
    /// Stop after this many cells are frozen.
    pub max_frozen: Option<usize>,
}

/// Options of [`solve`], with documented defaults ([`EikonalOptions::DEFAULT`]).
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub struct EikonalOptions {
    /// Algorithm. Default: fast marching.
    pub method: Method,
    /// Scheme order (fast marching, fast sweeping). Default: second.
    pub order: Order,
    /// Additive source factoring for point sources (fast marching and fast
    /// sweeping, both orders, on the whole domain): the scheme solves for
    /// `V = U - U_0` with `U_0 = W(p)|x - p|`, which removes the singularity
    /// of `U` at `p` (exact for a constant cost). Default: true.
    pub factoring: bool,
    /// Radius, in cells, around a point source inside which cells receive the
    /// exact local value `W(p)|x - p|`. Default: 1.5.
    pub source_radius: f64,
    /// Graph neighbourhood for Dijkstra. Default: diagonal (8 / 18).
    pub connectivity: Connectivity,
    /// Early stopping.
    pub stop: StopRules,
    /// Also return the rank at which each cell was frozen. Default: false.
    pub record_order: bool,
    /// Fast sweeping stops when the largest change of a sweep is below this. Default: 1e-12.
    pub sweep_tolerance: f64,
    /// Fast sweeping gives up after this many full rounds of `2^d` sweeps. Default: 100.
    pub max_sweeps: usize,
}

impl EikonalOptions {
    /// The documented defaults.
    pub const DEFAULT: Self = Self {
        method: Method::FastMarching,
        order: Order::Second,
        factoring: true,
        source_radius: 1.5,
        connectivity: Connectivity::Diagonal,
        stop: StopRules {
            targets: Vec::new(),
            max_distance: None,
            max_frozen: None,
        },
        record_order: false,
        sweep_tolerance: 1e-12,
        max_sweeps: 100,
    };

    /// Defaults with another method.
    pub fn with_method(mut self, method: Method) -> Self {
        self.method = method;
        self
    }

    /// Defaults with another order.
    pub fn with_order(mut self, order: Order) -> Self {
        self.order = order;
        self
    }

    /// Enables or disables source factoring.
    pub fn with_factoring(mut self, factoring: bool) -> Self {
        self.factoring = factoring;
        self
    }

    /// Sets the stopping rules.
    pub fn with_stop(mut self, stop: StopRules) -> Self {
        self.stop = stop;
        self
    }

    /// Sets the Dijkstra neighbourhood.
    pub fn with_connectivity(mut self, connectivity: Connectivity) -> Self {
        self.connectivity = connectivity;
        self
    }
}

impl Default for EikonalOptions {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// How a solve ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StopReason {
    /// Every reachable cell has its final value.
    Completed,
    /// Every target was frozen.
    TargetsReached,
    /// The front passed [`StopRules::max_distance`].
    MaxDistance,
    /// [`StopRules::max_frozen`] cells were frozen.
    MaxFrozen,
    /// Fast sweeping hit [`EikonalOptions::max_sweeps`] before its tolerance.
    SweepLimit,
}

/// The result of a solve.
#[derive(Debug, Clone)]
pub struct EikonalOutput {
    /// The distance `U`, in the caller's shape; `+inf` where not reached, never NaN.
    pub distance: ArrayD<f64>,
    /// Index of the source that reached each cell; `-1` where not reached.
    pub labels: ArrayD<i32>,
    /// Rank at which each cell was frozen (`-1` if never), when asked for.
    pub frozen_order: Option<ArrayD<i64>>,
    /// Number of cells with a final value.
    pub frozen: usize,
    /// How the solve ended.
    pub stop: StopReason,
    /// Fast sweeping: the number of single sweeps done.
    pub sweeps: Option<usize>,
}

/// Why a solve was refused or interrupted.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EikonalError {
    /// The grid is invalid.
    #[error(transparent)]
    Grid(#[from] GridError),
    /// The cost is invalid.
    #[error(transparent)]
    Metric(#[from] MetricError),
    /// No source was given.
    #[error("at least one source is required")]
    NoSources,
    /// A source is outside the grid, on a wall, or malformed.
    #[error("sources[{index}]: {reason}")]
    Source {
        /// Position in [`EikonalProblem::sources`].
        index: usize,
        /// What is wrong with it.
        reason: String,
    },
    /// A stop target is outside the grid or malformed.
    #[error("stop.targets[{index}]: {reason}")]
    Target {
        /// Position in [`StopRules::targets`].
        index: usize,
        /// What is wrong with it.
        reason: String,
    },
    /// An option is out of its range.
    #[error("{field}: {reason}")]
    Option {
        /// The option's name.
        field: &'static str,
        /// What is wrong with it.
        reason: String,
    },
    /// The distances this problem can reach do not fit in an `f64`: they
    /// would overflow to `+inf`, which means "unreached".
    #[error("{reason}")]
    Range {
        /// `"cost"` or `"spacing"`: the larger factor of the bound.
        field: &'static str,
        /// The bound and the way out.
        reason: String,
    },
    /// The caller raised the cancel flag.
    #[error("cancelled")]
    Cancelled,
}

/// Largest distance bound a solve accepts: far below `f64::MAX` (1.8e308),
/// so that sums of a few distances and the squares of the quadratic update's
/// differences (handled by its one-sided fallback) stay meaningful.
pub const MAX_DISTANCE_BOUND: f64 = 1e300;

/// Refuses a problem whose distances could overflow.
///
/// No minimal path visits a cell twice, so every finite distance is at most
/// `B = W_max · h_max · 2 · N` (the largest finite cost, the largest
/// spacing, at most `N` steps of length at most `2 h_max` through the `N`
/// cells; diagonal and extended stencils stay within that). `B` must stay
/// below [`MAX_DISTANCE_BOUND`]; otherwise a reached cell could read as
/// `+inf`, unreached, and the solve would still say "completed".
pub fn check_range(grid: &Grid, cost: &IsotropicCost<'_>) -> Result<(), EikonalError> {
    // A uniform cost is its own maximum: no scan of the grid.
    let w_max = cost
        .uniform_value()
        .or_else(|| cost.max_finite(grid))
        .unwrap_or(0.0);
    let h_max = grid.spacing().iter().copied().fold(0.0_f64, f64::max);
    let steps = 2.0 * grid.len() as f64;
    let bound = w_max * h_max * steps;
    if bound.is_finite() && bound <= MAX_DISTANCE_BOUND {
        return Ok(());
    }
    let field = if h_max > w_max { "spacing" } else { "cost" };
    Err(EikonalError::Range {
        field,
        reason: format!(
            "distances on this grid could reach {w_max:e} (largest finite cost) x {h_max:e}              (largest spacing) x {steps:e} (steps through its cells) = {bound:e}, beyond the              {MAX_DISTANCE_BOUND:e} an f64 distance map can hold meaningfully (it would              overflow to +inf, which means unreached): scale the {field} down; distances              scale linearly with it"
        ),
    })
}

/// Computes the geodesic distance to the sources, with Voronoi labels.
///
/// Dispatches on [`EikonalOptions::method`]. Cells that cannot be reached get
/// `U = +inf` and label `-1`; `U` is never NaN.
///
/// # Examples
/// ```
/// use geodex::numerics::{solve, Control, EikonalOptions, EikonalProblem, Grid, IsotropicCost, Source};
/// let problem = EikonalProblem {
///     grid: Grid::unit(&[5, 5])?,
///     cost: IsotropicCost::constant(1.0)?,
///     sources: vec![Source::Point(vec![0.0, 0.0])],
/// };
/// let out = solve(&problem, &EikonalOptions::DEFAULT, &Control::new())?;
/// assert!((out.distance[[4, 4]] - 32f64.sqrt()).abs() < 0.05);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn solve(
    problem: &EikonalProblem<'_>,
    options: &EikonalOptions,
    control: &Control<'_>,
) -> Result<EikonalOutput, EikonalError> {
    validate_options(options)?;
    check_range(&problem.grid, &problem.cost)?;
    let front = InitialFront::build(problem, options.source_radius, control)?;
    match options.method {
        Method::FastMarching => fast_marching::solve(problem, &front, options, control),
        Method::FastSweeping => fast_sweeping::solve(problem, &front, options, control),
        Method::Dijkstra => dijkstra::solve(problem, &front, options, control),
    }
}

/// Packages the flat (C-order) working arrays of a solver as an [`EikonalOutput`]
/// in the caller's shape.
pub(crate) fn finish(
    grid: &Grid,
    distance: Vec<f64>,
    labels: Vec<i32>,
    frozen_order: Option<Vec<i64>>,
    frozen: usize,
    stop: StopReason,
    sweeps: Option<usize>,
) -> EikonalOutput {
    let shape = ndarray::IxDyn(grid.shape());
    let reshape = |v: Vec<f64>| ArrayD::from_shape_vec(shape.clone(), v);
    // The lengths are the grid's by construction; a mismatch is a solver bug.
    let distance = reshape(distance).expect("solver produced one distance per cell");
    let labels = ArrayD::from_shape_vec(shape.clone(), labels).expect("one label per cell");
    let frozen_order =
        frozen_order.map(|o| ArrayD::from_shape_vec(shape.clone(), o).expect("one rank per cell"));
    EikonalOutput {
        distance,
        labels,
        frozen_order,
        frozen,
        stop,
        sweeps,
    }
}

fn validate_options(options: &EikonalOptions) -> Result<(), EikonalError> {
    if !(options.source_radius.is_finite() && options.source_radius >= 0.0) {
        return Err(EikonalError::Option {
            field: "source_radius",
            reason: format!("{} must be finite and >= 0", options.source_radius),
        });
    }
    if let Some(d) = options.stop.max_distance {
        if d.is_nan() || d < 0.0 {
            return Err(EikonalError::Option {
                field: "stop.max_distance",
                reason: format!("{d} must be >= 0"),
            });
        }
    }
    if !(options.sweep_tolerance.is_finite() && options.sweep_tolerance >= 0.0) {
        return Err(EikonalError::Option {
            field: "sweep_tolerance",
            reason: format!("{} must be finite and >= 0", options.sweep_tolerance),
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::numerics::Source;

    fn solve_on(shape: &[usize], spacing: f64, w: f64) -> Result<EikonalOutput, EikonalError> {
        let problem = EikonalProblem {
            grid: Grid::new(shape, &vec![spacing; shape.len()]).unwrap(),
            cost: IsotropicCost::constant(w).unwrap(),
            sources: vec![Source::Point(vec![0.0, 0.0])],
        };
        solve(&problem, &EikonalOptions::DEFAULT, &Control::new())
    }

    #[test]
    fn distances_that_could_overflow_are_refused_naming_the_larger_factor() {
        // 1e306 x 1 x 2 x 10,000 cells = 2e310: beyond f64.
        match solve_on(&[100, 100], 1.0, 1e306) {
            Err(EikonalError::Range { field, reason }) => {
                assert_eq!(field, "cost");
                assert!(reason.contains("scale the cost down"), "{reason}");
            }
            other => panic!("{other:?}"),
        }
        match solve_on(&[100, 100], 1e299, 1.0) {
            Err(EikonalError::Range { field, .. }) => assert_eq!(field, "spacing"),
            other => panic!("{other:?}"),
        }
        // Large but representable: every cell is reached, none reads +inf.
        let out = solve_on(&[100, 100], 1.0, 1e290).unwrap();
        assert!(out.distance.iter().all(|u| u.is_finite()));
        assert!((out.distance[[99, 0]] / 1e290 - 99.0).abs() < 1e-9);
    }
}
