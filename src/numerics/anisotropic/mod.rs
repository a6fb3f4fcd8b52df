//! Anisotropic (Riemannian) eikonal equations on 2D and 3D grids.
//!
//! A tensor field `M(x)` (symmetric positive definite, [`TensorField`])
//! measures the length of a curve as `∫ sqrt(γ'ᵀ M(γ) γ') dt` (seed eq. 1.9);
//! the distance `U` to the sources is the viscosity solution of
//!
//! ```text
//! ‖∇U(x)‖_{M(x)⁻¹} = sqrt(∇Uᵀ M(x)⁻¹ ∇U) = 1,     U = U_0 on the sources,
//! ```
//!
//! and minimal paths descend along `v = −M⁻¹∇U` (seed eq. 1.26).
//!
//! The solver is fast marching with adaptive stencils (Mirebeau's family:
//! FM-LBR in 2D, Selling / obtuse-superbase stencils in 3D): the dual metric
//! of each cell is decomposed by Selling's reduction ([`selling`]) into
//! non-negative weights on integer offsets, which makes the scheme monotone,
//! causal and consistent for any SPD field, at a cost that grows with the
//! logarithm of the anisotropy (the number of reduction steps), not linearly.
//! See [`fast_marching`] for the scheme (Eulerian form), its second order and
//! source factoring, and [`stencil`] for the walls: an offset whose segment
//! touches a wall cell is absent, so nothing leaks through a wall one cell
//! thick.
//!
//! * [`tensor`]: tensor fields and their validation (first bad cell named).
//! * [`selling`]: Selling's decomposition in 2D and 3D.
//! * [`stencil`]: per-cell stencils, wall tests, reverse stencils.
//! * [`fast_marching`]: the solver.
//! * [`gradient`]: the gradient of the distance with respect to the metric
//!   (the discrete adjoint of the unfactored solver).
//! * [`structure_tensor`]: the edge-following metric of an image (seed 1.3.3).
//! * [`height_map`]: the metric `W²(I + ∇h∇hᵀ)` of a terrain (seed eq. 1.10).
//! * [`descent`]: minimal paths along `−M⁻¹∇U`.

pub mod descent;
pub mod fast_marching;
pub mod gradient;
pub mod height_map;
pub mod selling;
pub mod stencil;
pub mod structure_tensor;
pub mod tensor;

pub use gradient::{metric_distance_gradient, metric_gradient};
pub use tensor::{
    anisotropy_ratio, components, eigen_tensor, energy_anisotropy, TensorError, TensorField,
};

use super::control::Control;
use super::eikonal::{EikonalError, EikonalOutput, Order, Source, StopRules};
use super::grid::Grid;

/// The input of an anisotropic solve.
#[derive(Debug, Clone)]
pub struct TensorProblem {
    /// Shape and spacing.
    pub grid: Grid,
    /// The metric `M` (walls included).
    pub metric: TensorField,
    /// At least one source; the label of a cell is the index of its source here.
    pub sources: Vec<Source>,
}

/// Options of [`solve`], with documented defaults ([`TensorOptions::DEFAULT`]).
#[derive(Debug, Clone, PartialEq)]
pub struct TensorOptions {
    /// Scheme order. Default: second.
    pub order: Order,
    /// Additive source factoring around point sources with the metric of the
    /// source cell. Default: true.
    pub factoring: bool,
    /// Smallest radius, in cells, around a point source inside which cells
    /// receive the exact local value `‖x − p‖_{M(p)}`; the radius used is the
    /// larger of this and half the longest stencil offset of the source cell
    /// (a needle of anisotropy 100 has offsets ~10 cells long, whose
    /// stencils straddle the source). Default: 1.5.
    pub source_radius: f64,
    /// Early stopping.
    pub stop: StopRules,
    /// Also return the rank at which each cell was frozen. Default: false.
    /// The metric gradient ([`metric_gradient`]) of an order-2 solve needs it.
    pub record_order: bool,
}

impl TensorOptions {
    /// The documented defaults.
    pub const DEFAULT: Self = Self {
        order: Order::Second,
        factoring: true,
        source_radius: 1.5,
        stop: StopRules {
            targets: Vec::new(),
            max_distance: None,
            max_frozen: None,
        },
        record_order: false,
    };

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
}

impl Default for TensorOptions {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// What the stencils looked like, reported with the solution.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StencilStats {
    /// Largest offset component used, in cells (the stencil half-width).
    pub max_offset: usize,
    /// Largest `sqrt(λmax / λmin)` over the cells.
    pub max_anisotropy: f64,
}

/// The result of [`solve`].
#[derive(Debug, Clone)]
pub struct TensorOutput {
    /// Distance, labels, freeze ranks and how the solve ended (`sweeps` is `None`).
    pub output: EikonalOutput,
    /// Stencil statistics.
    pub stencil: StencilStats,
}

/// Why an anisotropic solve was refused or interrupted: the tensor field's
/// own errors, and those it shares with the isotropic engine (grid,
/// sources, stop targets, options, cancellation) as an [`EikonalError`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TensorSolveError {
    /// The tensor field is invalid.
    #[error(transparent)]
    Tensor(TensorError),
    /// The field's dimension is not the grid's.
    #[error("the tensor field is {field}D but the grid is {grid}D")]
    Dimension {
        /// The field's dimension.
        field: usize,
        /// The grid's dimension.
        grid: usize,
    },
    /// What the isotropic engine would refuse in the same place (the
    /// positions in `Source` and `Target` index [`TensorProblem::sources`]
    /// and [`StopRules::targets`]).
    #[error(transparent)]
    Solve(#[from] EikonalError),
}

impl TensorSolveError {
    /// An invalid option.
    fn option(field: &'static str, reason: String) -> Self {
        EikonalError::Option { field, reason }.into()
    }
}

/// Computes the Riemannian distance to the sources, with Voronoi labels.
///
/// Cells that cannot be reached get `U = +inf` and label `-1`; `U` is never NaN.
///
/// # Examples
/// ```
/// use geodex::numerics::{Control, Grid, Source};
/// use geodex::numerics::anisotropic::{solve, TensorField, TensorOptions, TensorProblem};
/// let grid = Grid::unit(&[41, 41])?;
/// // Ten times cheaper along the diagonal (1, 1) than across it.
/// let metric = TensorField::from_eigen(&grid, &[1.0, 100.0], &[1.0, 1.0])?;
/// let problem = TensorProblem { grid, metric, sources: vec![Source::Point(vec![20.0, 20.0])] };
/// let out = solve(&problem, &TensorOptions::DEFAULT, &Control::new())?;
/// assert!((out.output.distance[[30, 30]] - 200f64.sqrt()).abs() < 1e-9);
/// assert!((out.output.distance[[30, 10]] - 10.0 * 200f64.sqrt()).abs() < 0.02 * 141.4);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn solve(
    problem: &TensorProblem,
    options: &TensorOptions,
    control: &Control<'_>,
) -> Result<TensorOutput, TensorSolveError> {
    if problem.metric.ndim() != problem.grid.ndim() {
        return Err(TensorSolveError::Dimension {
            field: problem.metric.ndim(),
            grid: problem.grid.ndim(),
        });
    }
    if problem.sources.is_empty() {
        return Err(EikonalError::NoSources.into());
    }
    if problem.sources.len() > i32::MAX as usize {
        return Err(TensorSolveError::option(
            "sources",
            "too many sources".into(),
        ));
    }
    if !(options.source_radius.is_finite() && options.source_radius >= 0.0) {
        return Err(TensorSolveError::option(
            "source_radius",
            format!("{} must be finite and >= 0", options.source_radius),
        ));
    }
    if let Some(d) = options.stop.max_distance {
        if d.is_nan() || d < 0.0 {
            return Err(TensorSolveError::option(
                "stop.max_distance",
                format!("{d} must be >= 0"),
            ));
        }
    }
    let st = stencil::build(&problem.grid, &problem.metric, control)
        .map_err(|_| EikonalError::Cancelled)?;
    let output = fast_marching::solve(problem, &st, options, control)?;
    Ok(TensorOutput {
        output,
        stencil: StencilStats {
            max_offset: st.max_offset.max(0) as usize,
            max_anisotropy: problem.metric.max_anisotropy(problem.grid.len()),
        },
    })
}
