//! Shape from shading by fast marching (monograph section 3.7).
//!
//! A Lambertian surface `z(x)` of albedo `ρ`, lit by a light in the viewing
//! direction and seen by an orthographic camera, has the brightness
//!
//! ```text
//! I(x) = ρ n(x)·ℓ = ρ / sqrt(1 + |∇z(x)|²),      ℓ = (0, 0, 1),
//! ```
//!
//! so its height solves the eikonal equation (Rouy and Tourin 1992)
//!
//! ```text
//! |∇z(x)| = f(x) = sqrt(ρ² / I(x)² - 1),
//! ```
//!
//! a geodesic distance whose cost `W = f` is read from the image (Kimmel and
//! Sethian 2001 solve it by fast marching, as here). `f` vanishes at the
//! *singular points* (`I = ρ`, where the surface faces the light: its tops,
//! bottoms and saddles) and is infinite where `I <= 0` (shadows and occluding
//! contours, which become walls).
//!
//! The equation alone does not fix the surface: heights must be prescribed
//! on a set of *anchor* cells (the image border of an object standing on a
//! flat ground, the singular points, a mask drawn by the user). Given the
//! anchors' heights `h_s`, the surface is the viscosity solution
//!
//! * [`Direction::Up`]: `z = U` where `U` solves `|∇U| = f`, `U = h_s` on the
//!   anchors: the height rises away from them (the anchors are the lowest
//!   points, as the border of a bump);
//! * [`Direction::Down`]: `z = -U` where `U` solves `|∇U| = f`, `U = -h_s`:
//!   the height falls away from them (the anchors are the highest points, as
//!   the singular point on top of a convex object).
//!
//! Both are the maximal (resp. minimal) solutions: `U(x)` is the infimum over
//! paths from an anchor of `h_s + ∫ f`, which equals the true surface when
//! every point has a path of steepest descent (resp. ascent) to an anchor,
//! e.g. a sum of bumps over a flat ground seen with its border as anchors.
//! The concave/convex ambiguity of shape from shading is what
//! [`Direction`] chooses.
//!
//! The scheme is the grid fast marching of [`crate::numerics::eikonal`] (first
//! or second order), so the height error is `O(h)` or `O(h²)` where the
//! surface is smooth, and first order at its kinks.
//!
//! # Examples
//! ```
//! use geodex::numerics::{Control, Grid};
//! use geodex::numerics::shading::{shape_from_shading, border_cells, Direction, ShadingProblem};
//! // A plane of slope 1 along axis 1: I = 1/sqrt(2) everywhere.
//! let grid = Grid::unit(&[8, 8])?;
//! let image = vec![0.5f64.sqrt(); 64];
//! let left: Vec<usize> = (0..8).map(|i| i * 8).collect();
//! let problem = ShadingProblem {
//!     grid: grid.clone(),
//!     image: &image,
//!     albedo: 1.0,
//!     anchors: left.iter().map(|&i| (i, 0.0)).collect(),
//!     direction: Direction::Up,
//!     min_slope: 1e-9,
//! };
//! let out = shape_from_shading(&problem, Default::default(), &Control::new())?;
//! assert!((out.height[3 * 8 + 7] - 7.0).abs() < 1e-9);
//! # let _ = border_cells(&grid);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use std::borrow::Cow;

use super::control::Control;
use super::eikonal::{self, EikonalError, EikonalOptions, EikonalProblem, Order, Source};
use super::grid::Grid;
use super::metric::{CostValues, Interpretation, IsotropicCost, MetricError};

/// Whether the height rises or falls away from the anchors (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Direction {
    /// `z = U`: the anchors are the lowest points (the border of a bump).
    #[default]
    Up,
    /// `z = -U`: the anchors are the highest points (the top of a convex object).
    Down,
}

/// The input of [`shape_from_shading`].
#[derive(Debug, Clone)]
pub struct ShadingProblem<'a> {
    /// The image's grid (2D; a 3D grid is refused) and its physical spacing.
    pub grid: Grid,
    /// Brightness per cell in C order, `I >= 0`; `I <= 0` is a shadow (a wall).
    pub image: &'a [f64],
    /// The albedo `ρ > 0`: the brightness of a surface facing the light.
    /// Brighter cells are clipped to it (slope 0).
    pub albedo: f64,
    /// `(linear cell index, height)` of every anchor cell; at least one.
    pub anchors: Vec<(usize, f64)>,
    /// Rising or falling away from the anchors.
    pub direction: Direction,
    /// The slope used where `f` is smaller (the fast marching needs a cost
    /// `> 0`); it bounds the height error across flat regions by
    /// `min_slope × their width`.
    pub min_slope: f64,
}

/// Options of [`shape_from_shading`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ShadingOptions {
    /// Order of the fast-marching scheme. Default: second.
    pub order: Order,
}

/// The recovered surface.
#[derive(Debug, Clone)]
pub struct ShadingOutput {
    /// Height per cell in C order (the image's units of length along the
    /// axes); `+inf` (for [`Direction::Up`]) or `-inf` (for
    /// [`Direction::Down`]) where no anchor reaches, never NaN.
    pub height: Vec<f64>,
    /// Cells that no anchor reaches (behind a shadow).
    pub unreached: usize,
    /// Cells whose slope is below `min_slope` (singular or flat).
    pub flat: usize,
}

/// Why a shape-from-shading problem was refused or interrupted.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ShadingError {
    /// The image is not 2D.
    #[error("shape from shading takes a 2D image, got {0} axes")]
    NotTwoD(usize),
    /// The image does not have one value per cell.
    #[error("the image has {got} values but the grid has {expected} cells")]
    Length {
        /// Values given.
        got: usize,
        /// Cells in the grid.
        expected: usize,
    },
    /// A brightness is NaN or infinite.
    #[error("cell {index:?} has brightness {value}: a brightness must be finite")]
    Brightness {
        /// The cell, axis 0 first.
        index: Vec<usize>,
        /// The value found.
        value: f64,
    },
    /// The albedo is not finite and > 0.
    #[error("albedo {0} must be finite and > 0")]
    Albedo(f64),
    /// `min_slope` is not finite and > 0.
    #[error("min_slope {0} must be finite and > 0")]
    MinSlope(f64),
    /// No anchor was given (or found).
    #[error("at least one anchor cell is needed: its height fixes the surface")]
    NoAnchors,
    /// An anchor is outside the grid, has a non-finite height or lies in a shadow.
    #[error("anchors[{index}]: {reason}")]
    Anchor {
        /// Position in [`ShadingProblem::anchors`].
        index: usize,
        /// What is wrong with it.
        reason: String,
    },
    /// The light direction is not a unit vector with `l3 > 0`.
    #[error("light: {0}")]
    Light(String),
    /// The camera's focal length, principal point or the grid's spacing is refused.
    #[error("camera: {0}")]
    Camera(String),
    /// A solver option (tolerance, iteration cap) is refused.
    #[error("{0}")]
    Option(String),
    /// The caller raised the cancel flag.
    #[error("cancelled")]
    Cancelled,
}

/// The slope `f = sqrt(ρ²/I² - 1)` of a Lambertian surface of albedo `ρ`
/// seen with brightness `I` under a frontal light: `0` for `I >= ρ`, `+inf`
/// for `I <= 0`.
///
/// # Examples
/// ```
/// use geodex::numerics::shading::slope_from_brightness;
/// assert_eq!(slope_from_brightness(1.0, 1.0), 0.0);
/// assert!((slope_from_brightness(0.5f64.sqrt(), 1.0) - 1.0).abs() < 1e-12);
/// assert_eq!(slope_from_brightness(0.0, 1.0), f64::INFINITY);
/// ```
pub fn slope_from_brightness(brightness: f64, albedo: f64) -> f64 {
    if brightness <= 0.0 {
        return f64::INFINITY;
    }
    let r = albedo / brightness;
    if r <= 1.0 {
        0.0
    } else {
        // sqrt(r² - 1) = sqrt((r - 1)(r + 1)), without cancellation near r = 1.
        ((r - 1.0) * (r + 1.0)).sqrt()
    }
}

/// The brightness `ρ / sqrt(1 + |g|²)` of a surface of gradient `g` under a
/// frontal light (the forward model of [`shape_from_shading`]).
pub fn lambertian(gradient: &[f64], albedo: f64) -> f64 {
    albedo / (1.0 + gradient.iter().map(|g| g * g).sum::<f64>()).sqrt()
}

/// Linear indices of the cells on the border of a 2D grid (each once).
pub fn border_cells(grid: &Grid) -> Vec<usize> {
    let [_, n0, n1] = grid.shape3();
    (0..n0 * n1)
        .filter(|&i| {
            let (a, b) = (i / n1, i % n1);
            a == 0 || b == 0 || a + 1 == n0 || b + 1 == n1
        })
        .collect()
}

/// The singular cells of an image: those whose brightness is within
/// `tolerance × ρ` of the albedo (where the surface faces the light).
pub fn singular_cells(image: &[f64], albedo: f64, tolerance: f64) -> Vec<usize> {
    let threshold = albedo * (1.0 - tolerance);
    image
        .iter()
        .enumerate()
        .filter(|(_, &v)| v >= threshold)
        .map(|(i, _)| i)
        .collect()
}

/// Recovers the height map of a Lambertian surface under a frontal light from
/// its image (see the module docs for the equation, the anchors and the
/// direction).
///
/// Polls `control` through the fast marching.
pub fn shape_from_shading(
    problem: &ShadingProblem<'_>,
    options: ShadingOptions,
    control: &Control<'_>,
) -> Result<ShadingOutput, ShadingError> {
    let grid = &problem.grid;
    if grid.ndim() != 2 {
        return Err(ShadingError::NotTwoD(grid.ndim()));
    }
    if problem.image.len() != grid.len() {
        return Err(ShadingError::Length {
            got: problem.image.len(),
            expected: grid.len(),
        });
    }
    if !(problem.albedo.is_finite() && problem.albedo > 0.0) {
        return Err(ShadingError::Albedo(problem.albedo));
    }
    if !(problem.min_slope.is_finite() && problem.min_slope > 0.0) {
        return Err(ShadingError::MinSlope(problem.min_slope));
    }
    if problem.anchors.is_empty() {
        return Err(ShadingError::NoAnchors);
    }
    let mut flat = 0usize;
    let mut cost = Vec::with_capacity(grid.len());
    for (i, &v) in problem.image.iter().enumerate() {
        if !v.is_finite() {
            return Err(ShadingError::Brightness {
                index: user_index(grid, i),
                value: v,
            });
        }
        let f = slope_from_brightness(v, problem.albedo);
        if f < problem.min_slope {
            flat += 1;
        }
        cost.push(f.max(problem.min_slope));
    }
    let sign = match problem.direction {
        Direction::Up => 1.0,
        Direction::Down => -1.0,
    };
    let mut cells = Vec::with_capacity(problem.anchors.len());
    let mut values = Vec::with_capacity(problem.anchors.len());
    for (index, &(cell, height)) in problem.anchors.iter().enumerate() {
        let reason = if cell >= grid.len() {
            Some(format!(
                "cell {cell} is outside the grid of {} cells",
                grid.len()
            ))
        } else if !height.is_finite() {
            Some(format!("height {height} must be finite"))
        } else if cost[cell].is_infinite() {
            Some(format!(
                "cell {:?} is in a shadow (brightness <= 0)",
                user_index(grid, cell)
            ))
        } else {
            None
        };
        if let Some(reason) = reason {
            return Err(ShadingError::Anchor { index, reason });
        }
        cells.push(user_index(grid, cell));
        values.push(sign * height);
    }
    let cost = IsotropicCost::new(
        grid,
        CostValues::F64(Cow::Owned(cost)),
        Interpretation::Cost,
        None,
    )
    .map_err(metric_error)?;
    let eikonal = EikonalProblem {
        grid: grid.clone(),
        cost,
        sources: vec![Source::Cells {
            cells,
            values: Some(values),
        }],
    };
    let solved = eikonal::solve(
        &eikonal,
        &EikonalOptions::DEFAULT
            .with_order(options.order)
            .with_factoring(false),
        control,
    )
    .map_err(eikonal_error)?;
    let mut unreached = 0usize;
    let height = solved
        .distance
        .iter()
        .map(|&u| {
            if u.is_infinite() {
                unreached += 1;
            }
            sign * u
        })
        .collect();
    Ok(ShadingOutput {
        height,
        unreached,
        flat,
    })
}

/// The light of [`shape_from_shading_general`]: a unit vector
/// `L = (l1, l2, l3)` pointing from the surface towards the light, `l1`
/// along axis 0, `l2` along axis 1, `l3 > 0` towards the camera.
/// `[0, 0, 1]` is the frontal light of [`shape_from_shading`].
pub type LightDirection = [f64; 3];

/// The camera of [`shape_from_shading_general`].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Camera {
    /// Parallel projection along `-z`: pixel `(a, b)` sees the point
    /// `(a h0, b h1, z)`.
    #[default]
    Orthographic,
    /// A pinhole camera at the origin looking along `+Z`, the light at its
    /// optical centre (Prados and Faugeras 2005). Pixel `x` (in pixels,
    /// relative to the principal point) sees `P = Z(x) (x / f, 1)`.
    Perspective {
        /// Focal length in pixels, `> 0`.
        focal: f64,
        /// Principal point `(row, column)` in pixels.
        principal_point: [f64; 2],
        /// Whether the light falls off as `1 / r²` (`I = ρ cos α / r²`)
        /// or not (`I = ρ cos α`).
        attenuation: bool,
    },
}

/// Stopping rule of the iterative solver of [`shape_from_shading_general`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SweepOptions {
    /// Stop when one iteration (four sweeps) changes no cell by more than
    /// this (absolute, in the solved unknown: `w` of the oblique model in
    /// length units, `ln Z` of the perspective one). Default: `1e-7`.
    pub tolerance: f64,
    /// Stop after this many iterations at most. Default: 5000.
    pub max_iterations: usize,
}

impl Default for SweepOptions {
    fn default() -> Self {
        Self {
            tolerance: 1e-7,
            max_iterations: 5000,
        }
    }
}

/// Why the iterative solver stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SweepStop {
    /// The last iteration changed no cell by more than the tolerance.
    Converged,
    /// The iteration cap was reached first.
    IterationCap,
}

/// The input of [`shape_from_shading_general`].
#[derive(Debug, Clone)]
pub struct GeneralShadingProblem<'a> {
    /// The image's grid (2D). The perspective camera works in pixels: its
    /// spacing must be 1.
    pub grid: Grid,
    /// Brightness per cell in C order; `I <= 0` is a shadow (a wall).
    pub image: &'a [f64],
    /// The albedo `ρ > 0` (perspective with attenuation: `ρ` in
    /// `I = ρ cos α / r²`, which sets the depth's unit). Brighter cells are
    /// clipped to it.
    pub albedo: f64,
    /// `(linear cell index, value)`: heights (orthographic) or depths `> 0`
    /// (perspective). Needed except for the perspective camera with
    /// attenuation.
    pub anchors: Vec<(usize, f64)>,
    /// Orthographic: whether `w = L·P` rises or falls away from the
    /// anchors. Perspective: ignored (the depth is the maximal solution).
    pub direction: Direction,
    /// The light (orthographic camera; the perspective light is at the
    /// optical centre).
    pub light: LightDirection,
    /// The camera.
    pub camera: Camera,
}

/// The surface recovered by [`shape_from_shading_general`].
#[derive(Debug, Clone)]
pub struct GeneralShadingOutput {
    /// Orthographic: the height `z` per cell; perspective: the depth `Z`
    /// (distance along the optical axis). `±inf` where no anchor reaches.
    pub height: Vec<f64>,
    /// Cells not reached (behind a shadow).
    pub unreached: usize,
    /// Iterations (of four sweeps each) run.
    pub iterations: usize,
    /// The largest change of the last iteration.
    pub change: f64,
    /// How the iteration stopped.
    pub stop: SweepStop,
}

/// What a cell is to the sweeping solver.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Free,
    Fixed,
    Wall,
}

/// Recovers a Lambertian surface from its image under an oblique light
/// (orthographic camera) or with a perspective camera whose light sits at
/// the optical centre, by Lax–Friedrichs fast sweeping (Kao, Osher and
/// Qian 2004) on a convex Hamiltonian.
///
/// **Oblique light, orthographic camera.** With `n = (-∇z, 1) / sqrt(1 +
/// |∇z|²)` the image equation is `I = ρ (l3 - l·∇z) / sqrt(1 + |∇z|²)`,
/// `l = (l1, l2)`. It is solved for the height along the light, `w = L·P =
/// l·x + l3 z` (the coordinate of Kimmel and Bruckstein's rotation into the
/// light's frame): `∇z = (∇w - l) / l3` turns it into
///
/// ```text
/// H(x, p) = I sqrt(l3² + |p - l|²) + ρ l·p - ρ = 0,     p = ∇w,
/// ```
///
/// convex in `p` with `H(x, 0) = I - ρ <= 0`, zero only at the singular
/// points (`n = L`): the same structure as the frontal eikonal equation,
/// whose tops and anchors carry over (`w` rises from the anchors for
/// [`Direction::Up`], falls for [`Direction::Down`]), while the equation
/// in `z` has `H(x, 0) > 0` wherever the surface tilts towards the light
/// and no such structure. `|∂H/∂p_i| <= I + ρ |l_i|` bounds the
/// Lax–Friedrichs viscosity.
///
/// **Perspective camera, light at the optical centre** (Prados and
/// Faugeras 2005). With `P = Z (x / f, 1)` the normal is `∝ (f ∇Z, -(Z +
/// x·∇Z))`, and with `v = ln Z`, `p = ∇v`,
///
/// ```text
/// H(x, v, p) = J(x) sqrt(f² |p|² + (1 + x·p)²) - e^{-2v} = 0,
/// J(x) = I(x) (|x|² + f²)^{3/2} / (ρ f³)
/// ```
///
/// (without attenuation `J = I sqrt(|x|² + f²) / (ρ f)` and `e^{-2v}`
/// becomes 1). With attenuation `H` is strictly increasing in `v`, which
/// makes the problem well-posed without anchors and without the
/// concave/convex ambiguity: the iteration starts from the supersolution
/// `v0 = max_x(-ln J(x) / 2)` and decreases monotonically to the maximal
/// solution. `|∂H/∂p_i| <= J sqrt(f² + x_i²)`.
///
/// **Scheme.** Local Lax–Friedrichs: at each free cell, central differences
/// `p_i = (u_{i+} - u_{i-}) / 2h_i` and
/// `H(u_c, p) - Σ_i σ_i (u_{i+} - 2u_c + u_{i-}) / 2h_i = 0` solved for
/// `u_c` (exactly when `H` does not depend on `u`, by Newton's method
/// otherwise), `σ_i` the largest `|∂H/∂p_i|` between the one-sided
/// differences (at one of them, `H` being convex; at least 1 % of the
/// global bound above), which keeps the scheme monotone with the least
/// numerical viscosity; Gauss–Seidel sweeps in the four orderings, `u_c ←
/// min(u_c, update)` from an upper bound. First order: the height error is
/// `O(h)`, the numerical viscosity smooths kinks. A neighbour outside the
/// image or in a shadow is replaced by the mirror of the opposite one (a
/// zero normal derivative there). The iteration stops when one iteration
/// changes no cell by more than [`SweepOptions::tolerance`], or at
/// [`SweepOptions::max_iterations`]; `control` is polled every row of every sweep.
pub fn shape_from_shading_general(
    problem: &GeneralShadingProblem<'_>,
    options: SweepOptions,
    control: &Control<'_>,
) -> Result<GeneralShadingOutput, ShadingError> {
    let grid = &problem.grid;
    if grid.ndim() != 2 {
        return Err(ShadingError::NotTwoD(grid.ndim()));
    }
    if problem.image.len() != grid.len() {
        return Err(ShadingError::Length {
            got: problem.image.len(),
            expected: grid.len(),
        });
    }
    if !(problem.albedo.is_finite() && problem.albedo > 0.0) {
        return Err(ShadingError::Albedo(problem.albedo));
    }
    if !(options.tolerance.is_finite() && options.tolerance > 0.0) {
        return Err(ShadingError::Option(format!(
            "tolerance {} must be finite and > 0",
            options.tolerance
        )));
    }
    if options.max_iterations == 0 {
        return Err(ShadingError::Option("max_iterations must be >= 1".into()));
    }
    for (i, &v) in problem.image.iter().enumerate() {
        if !v.is_finite() {
            return Err(ShadingError::Brightness {
                index: user_index(grid, i),
                value: v,
            });
        }
    }
    match problem.camera {
        Camera::Orthographic => oblique(problem, options, control),
        Camera::Perspective {
            focal,
            principal_point,
            attenuation,
        } => perspective(
            problem,
            focal,
            principal_point,
            attenuation,
            options,
            control,
        ),
    }
}

/// Checks the anchors' cells and values; `(cell, value)` with `value`
/// mapped by `map` (which may refuse it).
fn checked_anchors(
    problem: &GeneralShadingProblem<'_>,
    map: impl Fn(f64) -> Result<f64, String>,
) -> Result<Vec<(usize, f64)>, ShadingError> {
    let grid = &problem.grid;
    let mut out = Vec::with_capacity(problem.anchors.len());
    for (index, &(cell, value)) in problem.anchors.iter().enumerate() {
        let mapped = if cell >= grid.len() {
            Err(format!(
                "cell {cell} is outside the grid of {} cells",
                grid.len()
            ))
        } else if !value.is_finite() {
            Err(format!("height {value} must be finite"))
        } else if problem.image[cell] <= 0.0 {
            Err(format!(
                "cell {:?} is in a shadow (brightness <= 0)",
                user_index(grid, cell)
            ))
        } else {
            map(value)
        };
        match mapped {
            Ok(v) => out.push((cell, v)),
            Err(reason) => return Err(ShadingError::Anchor { index, reason }),
        }
    }
    Ok(out)
}

fn oblique(
    problem: &GeneralShadingProblem<'_>,
    options: SweepOptions,
    control: &Control<'_>,
) -> Result<GeneralShadingOutput, ShadingError> {
    let grid = &problem.grid;
    let [l1, l2, l3] = problem.light;
    let norm = (l1 * l1 + l2 * l2 + l3 * l3).sqrt();
    if !(norm.is_finite() && (norm - 1.0).abs() <= 1e-6 && l3 > 0.0) {
        return Err(ShadingError::Light(format!(
            "{:?} must be a unit vector with l3 > 0 (|L| = {norm})",
            problem.light
        )));
    }
    if problem.anchors.is_empty() {
        return Err(ShadingError::NoAnchors);
    }
    let [_, n0, n1] = grid.shape3();
    let [_, h0, h1] = grid.spacing3();
    let rho = problem.albedo;
    let image: Vec<f64> = problem.image.iter().map(|&v| v.min(rho)).collect();
    let sign = match problem.direction {
        Direction::Up => 1.0,
        Direction::Down => -1.0,
    };
    let lx = |i: usize| l1 * (i / n1) as f64 * h0 + l2 * (i % n1) as f64 * h1;
    let anchors = checked_anchors(problem, Ok)?;
    let mut kind: Vec<Kind> = image
        .iter()
        .map(|&v| if v <= 0.0 { Kind::Wall } else { Kind::Free })
        .collect();
    // An upper bound of U = sign w: |∇z| <= tan(angle(n, L) + angle(L, V)).
    let theta = l3.min(1.0).acos();
    let mut slope = 0.0f64;
    for &v in &image {
        if v > 0.0 {
            let angle = ((v / rho).min(1.0).acos() + theta).min(89f64.to_radians());
            slope = slope.max(angle.tan());
        }
    }
    let diameter = ((n0 as f64 * h0).powi(2) + (n1 as f64 * h1).powi(2)).sqrt();
    let mut top = f64::NEG_INFINITY;
    let mut u = vec![0.0; grid.len()];
    for &(cell, z) in &anchors {
        kind[cell] = Kind::Fixed;
        u[cell] = sign * (lx(cell) + l3 * z);
        top = top.max(u[cell]);
    }
    let ceiling = top + diameter * ((l1 * l1 + l2 * l2).sqrt() + l3 * slope) + 1.0;
    for (c, k) in kind.iter().enumerate() {
        match k {
            Kind::Free => u[c] = ceiling,
            Kind::Wall => u[c] = f64::INFINITY,
            Kind::Fixed => {}
        }
    }
    let sigma: Vec<[f64; 2]> = image
        .iter()
        .map(|&v| [v + rho * l1.abs(), v + rho * l2.abs()])
        .collect();
    let ham = |c: usize, _u: f64, p: [f64; 2]| {
        let (q0, q1) = (sign * p[0] - l1, sign * p[1] - l2);
        let root = (l3 * l3 + q0 * q0 + q1 * q1).sqrt();
        let h = image[c] * root + rho * (l1 * (q0 + l1) + l2 * (q1 + l2)) - rho;
        [
            h,
            0.0,
            sign * (image[c] * q0 / root + rho * l1),
            sign * (image[c] * q1 / root + rho * l2),
        ]
    };
    let report = sweep(
        [n0, n1],
        [h0, h1],
        &mut u,
        &kind,
        &sigma,
        &ham,
        options,
        control,
    )?;
    let mut unreached = 0usize;
    let height = u
        .iter()
        .zip(&kind)
        .enumerate()
        .map(|(c, (&v, k))| {
            if *k == Kind::Wall || (*k == Kind::Free && v >= ceiling) {
                unreached += 1;
                sign * f64::INFINITY
            } else {
                (sign * v - lx(c)) / l3
            }
        })
        .collect();
    Ok(GeneralShadingOutput {
        height,
        unreached,
        iterations: report.0,
        change: report.1,
        stop: report.2,
    })
}

fn perspective(
    problem: &GeneralShadingProblem<'_>,
    focal: f64,
    principal_point: [f64; 2],
    attenuation: bool,
    options: SweepOptions,
    control: &Control<'_>,
) -> Result<GeneralShadingOutput, ShadingError> {
    let grid = &problem.grid;
    if !(focal.is_finite() && focal > 0.0) {
        return Err(ShadingError::Camera(format!(
            "focal {focal} must be finite and > 0"
        )));
    }
    if principal_point.iter().any(|c| !c.is_finite()) {
        return Err(ShadingError::Camera(format!(
            "principal point {principal_point:?} must be finite"
        )));
    }
    if grid.spacing().iter().any(|&h| h != 1.0) {
        return Err(ShadingError::Camera(
            "the perspective camera works in pixels: the spacing must be 1".into(),
        ));
    }
    if !attenuation && problem.anchors.is_empty() {
        return Err(ShadingError::NoAnchors);
    }
    let [_, n0, n1] = grid.shape3();
    let rho = problem.albedo;
    let f2 = focal * focal;
    let offset = |c: usize| {
        [
            (c / n1) as f64 - principal_point[0],
            (c % n1) as f64 - principal_point[1],
        ]
    };
    let j: Vec<f64> = problem
        .image
        .iter()
        .enumerate()
        .map(|(c, &v)| {
            let x = offset(c);
            let r2 = x[0] * x[0] + x[1] * x[1] + f2;
            if attenuation {
                v.max(0.0) * r2 * r2.sqrt() / (rho * f2 * focal)
            } else {
                (v.max(0.0) * r2.sqrt() / (rho * focal)).min(r2.sqrt() / focal)
            }
        })
        .collect();
    let anchors = checked_anchors(problem, |d| {
        if d > 0.0 {
            Ok(d.ln())
        } else {
            Err(format!("depth {d} must be > 0"))
        }
    })?;
    let mut kind: Vec<Kind> = j
        .iter()
        .map(|&v| if v <= 0.0 { Kind::Wall } else { Kind::Free })
        .collect();
    let mut u = vec![0.0; grid.len()];
    let mut top = f64::NEG_INFINITY;
    for &(cell, v) in &anchors {
        kind[cell] = Kind::Fixed;
        u[cell] = v;
        top = top.max(v);
    }
    let ceiling = if attenuation {
        // A constant v0 with J - e^{-2 v0} >= 0 everywhere is a supersolution.
        let v0 = j
            .iter()
            .filter(|&&v| v > 0.0)
            .map(|&v| -0.5 * v.ln())
            .fold(f64::NEG_INFINITY, f64::max);
        v0.max(top) + 1e-3
    } else {
        top + (1e6f64).ln()
    };
    for (c, k) in kind.iter().enumerate() {
        match k {
            Kind::Free => u[c] = ceiling,
            Kind::Wall => u[c] = f64::INFINITY,
            Kind::Fixed => {}
        }
    }
    let sigma: Vec<[f64; 2]> = j
        .iter()
        .enumerate()
        .map(|(c, &jc)| {
            let x = offset(c);
            [
                jc * (f2 + x[0] * x[0]).sqrt(),
                jc * (f2 + x[1] * x[1]).sqrt(),
            ]
        })
        .collect();
    let ham = |c: usize, v: f64, p: [f64; 2]| {
        let x = offset(c);
        let xp = 1.0 + x[0] * p[0] + x[1] * p[1];
        let root = (f2 * (p[0] * p[0] + p[1] * p[1]) + xp * xp).sqrt();
        let s = j[c] * root;
        let g0 = j[c] * (f2 * p[0] + xp * x[0]) / root;
        let g1 = j[c] * (f2 * p[1] + xp * x[1]) / root;
        if attenuation {
            let e = (-2.0 * v).exp();
            [s - e, 2.0 * e, g0, g1]
        } else {
            [s - 1.0, 0.0, g0, g1]
        }
    };
    let report = sweep(
        [n0, n1],
        [1.0, 1.0],
        &mut u,
        &kind,
        &sigma,
        &ham,
        options,
        control,
    )?;
    let mut unreached = 0usize;
    let height = u
        .iter()
        .zip(&kind)
        .map(|(&v, k)| {
            let stuck = !attenuation && *k == Kind::Free && v >= ceiling;
            if *k == Kind::Wall || stuck {
                unreached += 1;
                f64::INFINITY
            } else {
                v.exp()
            }
        })
        .collect();
    Ok(GeneralShadingOutput {
        height,
        unreached,
        iterations: report.0,
        change: report.1,
        stop: report.2,
    })
}

/// The least Lax–Friedrichs viscosity, as a fraction of the global bound
/// of `|∂H/∂p_i|` (where the surface faces the light `∂H/∂p` vanishes).
const VISCOSITY_FLOOR: f64 = 0.01;

/// Local Lax–Friedrichs Gauss–Seidel sweeps (see
/// [`shape_from_shading_general`]): `ham(cell, u, p)` returns `H`, `∂H/∂u`,
/// `∂H/∂p0`, `∂H/∂p1`; `sigma` holds global bounds of `|∂H/∂p_i|`, of
/// which [`VISCOSITY_FLOOR`] is the least viscosity used. Returns the
/// iterations, the last change and why it stopped.
#[allow(clippy::too_many_arguments)]
fn sweep(
    shape: [usize; 2],
    h: [f64; 2],
    u: &mut [f64],
    kind: &[Kind],
    sigma: &[[f64; 2]],
    ham: &dyn Fn(usize, f64, [f64; 2]) -> [f64; 4],
    options: SweepOptions,
    control: &Control<'_>,
) -> Result<(usize, f64, SweepStop), ShadingError> {
    let [n0, n1] = shape;
    let mut change = f64::INFINITY;
    for iteration in 0..options.max_iterations {
        change = 0.0f64;
        for order in 0..4 {
            for ra in 0..n0 {
                if control.is_cancelled() {
                    return Err(ShadingError::Cancelled);
                }
                let a = if order & 1 == 0 { ra } else { n0 - 1 - ra };
                for rb in 0..n1 {
                    let b = if order & 2 == 0 { rb } else { n1 - 1 - rb };
                    let c = a * n1 + b;
                    if kind[c] != Kind::Free {
                        continue;
                    }
                    let value = |ok: bool, k: usize| {
                        if ok && u[k].is_finite() {
                            Some(u[k])
                        } else {
                            None
                        }
                    };
                    let axes = [
                        (value(a > 0, c.wrapping_sub(n1)), value(a + 1 < n0, c + n1)),
                        (value(b > 0, c.wrapping_sub(1)), value(b + 1 < n1, c + 1)),
                    ];
                    let old = u[c];
                    let mut p = [0.0; 2];
                    let mut sides = [None; 2];
                    for (i, pair) in axes.iter().enumerate() {
                        let (lo, hi) = match *pair {
                            (Some(lo), Some(hi)) => (lo, hi),
                            (Some(x), None) | (None, Some(x)) => (x, x),
                            (None, None) => continue,
                        };
                        p[i] = (hi - lo) / (2.0 * h[i]);
                        sides[i] = Some((lo, hi));
                    }
                    // Local viscosity: H is convex, so the largest |∂H/∂p_i|
                    // between the one-sided differences is at one of them.
                    let (mut num, mut den) = (0.0, 0.0);
                    for (i, side) in sides.iter().enumerate() {
                        let Some((lo, hi)) = *side else { continue };
                        let mut s = VISCOSITY_FLOOR * sigma[c][i];
                        for d in [(old - lo) / h[i], (hi - old) / h[i]] {
                            let mut q = p;
                            q[i] = d;
                            let g = ham(c, old, q)[2 + i].abs();
                            if g.is_finite() {
                                s = s.max(g);
                            } else {
                                s = s.max(sigma[c][i]);
                            }
                        }
                        let s = s.min(sigma[c][i]).max(VISCOSITY_FLOOR * sigma[c][i]);
                        num += s * (lo + hi) / (2.0 * h[i]);
                        den += s / h[i];
                    }
                    if den <= 0.0 {
                        continue;
                    }
                    // Solve u den + H(u, p) - num = 0 (increasing in u).
                    let mut x = old;
                    for _ in 0..20 {
                        let [hv, dh, _, _] = ham(c, x, p);
                        let step = (x * den + hv - num) / (den + dh);
                        x -= step;
                        if step.abs() <= 1e-14 * (1.0 + x.abs()) {
                            break;
                        }
                    }
                    if x.is_finite() && x < old {
                        change = change.max(old - x);
                        u[c] = x;
                    }
                }
            }
        }
        control.report((iteration + 1) as f64 / options.max_iterations as f64);
        if change <= options.tolerance {
            return Ok((iteration + 1, change, SweepStop::Converged));
        }
    }
    Ok((options.max_iterations, change, SweepStop::IterationCap))
}

/// The surface as a triangle mesh: one vertex per reached cell used by a
/// triangle, two triangles per pixel quad whose four corners are reached
/// (none across unreached or shadowed cells). Orthographic vertices are
/// `(a h0, b h1, z)`; perspective ones the back-projected points
/// `Z ((a - c0) / f, (b - c1) / f, 1)`.
///
/// # Examples
/// ```
/// use geodex::numerics::Grid;
/// use geodex::numerics::shading::{surface_mesh, Camera};
/// let grid = Grid::unit(&[3, 4])?;
/// let (points, triangles) = surface_mesh(&grid, &[0.0; 12], &Camera::Orthographic);
/// assert_eq!((points.len(), triangles.len()), (12, 2 * 2 * 3));
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn surface_mesh(
    grid: &Grid,
    height: &[f64],
    camera: &Camera,
) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let [_, n0, n1] = grid.shape3();
    let [_, h0, h1] = grid.spacing3();
    let ok = |c: usize| height.get(c).is_some_and(|v| v.is_finite());
    let mut index = vec![u32::MAX; height.len()];
    let mut points = Vec::new();
    let mut triangles = Vec::new();
    let mut vertex = |c: usize, points: &mut Vec<[f64; 3]>| -> u32 {
        if index[c] == u32::MAX {
            let (a, b) = ((c / n1) as f64, (c % n1) as f64);
            let z = height[c];
            points.push(match camera {
                Camera::Orthographic => [a * h0, b * h1, z],
                Camera::Perspective {
                    focal,
                    principal_point,
                    ..
                } => [
                    z * (a - principal_point[0]) / focal,
                    z * (b - principal_point[1]) / focal,
                    z,
                ],
            });
            index[c] = (points.len() - 1) as u32;
        }
        index[c]
    };
    for a in 0..n0.saturating_sub(1) {
        for b in 0..n1.saturating_sub(1) {
            let c00 = a * n1 + b;
            let (c01, c10, c11) = (c00 + 1, c00 + n1, c00 + n1 + 1);
            if !(ok(c00) && ok(c01) && ok(c10) && ok(c11)) {
                continue;
            }
            let v00 = vertex(c00, &mut points);
            let v01 = vertex(c01, &mut points);
            let v10 = vertex(c10, &mut points);
            let v11 = vertex(c11, &mut points);
            triangles.push([v00, v10, v11]);
            triangles.push([v00, v11, v01]);
        }
    }
    (points, triangles)
}

/// A cell's index in array index order (2D: two numbers).
fn user_index(grid: &Grid, i: usize) -> Vec<usize> {
    let [_, a, b] = grid.unravel(i);
    vec![a, b]
}

fn metric_error(e: MetricError) -> ShadingError {
    match e {
        MetricError::Length { got, expected } => ShadingError::Length { got, expected },
        MetricError::BadValue { index, value, .. } => ShadingError::Brightness { index, value },
        // The cost is built here from checked brightnesses: these cannot occur.
        MetricError::Constant(v) => ShadingError::Brightness {
            index: Vec::new(),
            value: v,
        },
        MetricError::MaskLength { got, expected } => ShadingError::Length { got, expected },
    }
}

fn eikonal_error(e: EikonalError) -> ShadingError {
    match e {
        EikonalError::Cancelled => ShadingError::Cancelled,
        EikonalError::Source { reason, .. } => ShadingError::Anchor { index: 0, reason },
        other => ShadingError::Anchor {
            index: 0,
            reason: other.to_string(),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::AtomicBool;

    /// A surface given by its height and gradient on `[-1, 1]²`, sampled on
    /// `n × n` cell centres (spacing `2 / (n - 1)`).
    struct Scene {
        grid: Grid,
        height: Vec<f64>,
        image: Vec<f64>,
    }

    fn scene(n: usize, surface: impl Fn(f64, f64) -> (f64, [f64; 2])) -> Scene {
        let h = 2.0 / (n - 1) as f64;
        let grid = Grid::new(&[n, n], &[h, h]).unwrap();
        let mut height = Vec::with_capacity(n * n);
        let mut image = Vec::with_capacity(n * n);
        for a in 0..n {
            for b in 0..n {
                let (z, g) = surface(-1.0 + a as f64 * h, -1.0 + b as f64 * h);
                height.push(z);
                image.push(lambertian(&g, 1.0));
            }
        }
        Scene {
            grid,
            height,
            image,
        }
    }

    /// Sphere of radius 1 cut at height `sqrt(1 - 0.8²)`, on a flat ground.
    fn sphere_cap(x: f64, y: f64) -> (f64, [f64; 2]) {
        let r2 = x * x + y * y;
        if r2 >= 0.64 {
            return (0.0, [0.0, 0.0]);
        }
        let s = (1.0 - r2).sqrt();
        (s - 0.6, [-x / s, -y / s])
    }

    fn gaussian(x: f64, y: f64, cx: f64, cy: f64, a: f64, w: f64) -> (f64, [f64; 2]) {
        let (dx, dy) = (x - cx, y - cy);
        let z = a * (-(dx * dx + dy * dy) / (w * w)).exp();
        (z, [-2.0 * dx / (w * w) * z, -2.0 * dy / (w * w) * z])
    }

    fn bumps(x: f64, y: f64) -> (f64, [f64; 2]) {
        let mut z = 0.0;
        let mut g = [0.0, 0.0];
        for (cx, cy, a, w) in [
            (-0.4, -0.3, 0.5, 0.35),
            (0.35, 0.4, 0.35, 0.3),
            (0.3, -0.45, 0.25, 0.25),
        ] {
            let (zi, gi) = gaussian(x, y, cx, cy, a, w);
            z += zi;
            g[0] += gi[0];
            g[1] += gi[1];
        }
        (z, g)
    }

    /// Border anchors at their true heights, rising inwards.
    fn from_border(s: &Scene, order: Order) -> Vec<f64> {
        let anchors = border_cells(&s.grid)
            .into_iter()
            .map(|i| (i, s.height[i]))
            .collect();
        let problem = ShadingProblem {
            grid: s.grid.clone(),
            image: &s.image,
            albedo: 1.0,
            anchors,
            direction: Direction::Up,
            min_slope: 1e-9,
        };
        shape_from_shading(&problem, ShadingOptions { order }, &Control::new())
            .unwrap()
            .height
    }

    /// RMS height error relative to the depth range.
    fn relative_rms(s: &Scene, z: &[f64]) -> f64 {
        let (lo, hi) = s
            .height
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
                (lo.min(v), hi.max(v))
            });
        let mse = s
            .height
            .iter()
            .zip(z)
            .map(|(a, b)| (a - b) * (a - b))
            .sum::<f64>()
            / z.len() as f64;
        mse.sqrt() / (hi - lo)
    }

    #[test]
    fn sphere_cap_gaussian_and_bumps_within_two_percent_at_256() {
        for (name, surface) in [
            ("sphere cap", sphere_cap as fn(f64, f64) -> (f64, [f64; 2])),
            ("gaussian", |x, y| gaussian(x, y, 0.1, -0.05, 0.6, 0.4)),
            ("bumps", bumps),
        ] {
            let s = scene(256, surface);
            for order in [Order::First, Order::Second] {
                let e = relative_rms(&s, &from_border(&s, order));
                eprintln!("{name} {order:?} 256²: RMS {e:.5} of the depth range");
                assert!(e <= 0.02, "{name} {order:?}: RMS {e:.4} of the range");
            }
        }
    }

    #[test]
    fn error_decreases_with_resolution() {
        for surface in [sphere_cap as fn(f64, f64) -> (f64, [f64; 2]), bumps] {
            let errors: Vec<f64> = [64, 128, 256]
                .iter()
                .map(|&n| {
                    let s = scene(n, surface);
                    relative_rms(&s, &from_border(&s, Order::Second))
                })
                .collect();
            eprintln!("RMS at 64², 128², 256²: {errors:?}");
            assert!(
                errors[1] < errors[0] && errors[2] < errors[1],
                "errors {errors:?} must decrease with resolution"
            );
        }
    }

    #[test]
    fn singular_point_of_a_convex_bump_anchors_it_from_the_top() {
        let s = scene(129, |x, y| gaussian(x, y, 0.0, 0.0, 0.6, 0.45));
        let top = s.height.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
        let anchors = singular_cells(&s.image, 1.0, 1e-9)
            .into_iter()
            // The flat ground far from the bump is singular too: keep the
            // top's plateau (the cells higher than half the bump).
            .filter(|&i| s.height[i] > 0.3)
            .map(|i| (i, top))
            .collect::<Vec<_>>();
        assert!(!anchors.is_empty());
        let problem = ShadingProblem {
            grid: s.grid.clone(),
            image: &s.image,
            albedo: 1.0,
            anchors,
            direction: Direction::Down,
            min_slope: 1e-9,
        };
        let z = shape_from_shading(&problem, ShadingOptions::default(), &Control::new())
            .unwrap()
            .height;
        // Compare on the bump (where the surface has a descent path to the
        // top); the ground far away is flat and reached across the rim.
        let mut worst = 0.0f64;
        for (i, (&t, &r)) in s.height.iter().zip(&z).enumerate() {
            if t > 0.05 {
                worst = worst.max((t - r).abs());
            }
            assert!(!r.is_nan(), "cell {i} is NaN");
        }
        eprintln!("singular anchors: max error {worst:.5} on the bump (height 0.6)");
        assert!(worst <= 0.02 * 0.6, "max error {worst} on the bump");
    }

    #[test]
    fn shadows_are_walls_and_anchor_errors_name_the_anchor() {
        let grid = Grid::unit(&[4, 4]).unwrap();
        let mut image = vec![1.0; 16];
        // A column of shadow cuts the right half off.
        for a in 0..4 {
            image[a * 4 + 2] = 0.0;
        }
        let problem = ShadingProblem {
            grid: grid.clone(),
            image: &image,
            albedo: 1.0,
            anchors: vec![(0, 0.0)],
            direction: Direction::Up,
            min_slope: 1e-9,
        };
        let out = shape_from_shading(&problem, ShadingOptions::default(), &Control::new()).unwrap();
        assert_eq!(out.unreached, 8);
        assert!(out.height[3].is_infinite() && out.height[1] < 1e-6);
        let bad = ShadingProblem {
            anchors: vec![(0, 0.0), (2, 0.0)],
            ..problem.clone()
        };
        let e = shape_from_shading(&bad, ShadingOptions::default(), &Control::new()).unwrap_err();
        assert!(matches!(e, ShadingError::Anchor { index: 1, .. }), "{e}");
        let nan = vec![f64::NAN; 16];
        let e = shape_from_shading(
            &ShadingProblem {
                image: &nan,
                ..problem.clone()
            },
            ShadingOptions::default(),
            &Control::new(),
        )
        .unwrap_err();
        assert!(matches!(e, ShadingError::Brightness { .. }), "{e}");
        let three = Grid::unit(&[2, 2, 4]).unwrap();
        let e = shape_from_shading(
            &ShadingProblem {
                grid: three,
                ..problem
            },
            ShadingOptions::default(),
            &Control::new(),
        )
        .unwrap_err();
        assert_eq!(e, ShadingError::NotTwoD(3));
    }

    #[test]
    fn a_raised_flag_stops_it() {
        let s = scene(64, bumps);
        let flag = AtomicBool::new(true);
        let problem = ShadingProblem {
            grid: s.grid.clone(),
            image: &s.image,
            albedo: 1.0,
            anchors: vec![(0, 0.0)],
            direction: Direction::Up,
            min_slope: 1e-9,
        };
        let e = shape_from_shading(
            &problem,
            ShadingOptions::default(),
            &Control::new().with_cancel(&flag),
        )
        .unwrap_err();
        assert_eq!(e, ShadingError::Cancelled);
    }
    /// The oblique image `ρ max(0, l3 - l·∇z) / sqrt(1 + |∇z|²)` of a surface.
    fn oblique_scene(
        n: usize,
        light: [f64; 3],
        surface: impl Fn(f64, f64) -> (f64, [f64; 2]),
    ) -> Scene {
        let mut s = scene(n, &surface);
        let h = 2.0 / (n - 1) as f64;
        for a in 0..n {
            for b in 0..n {
                let (_, g) = surface(-1.0 + a as f64 * h, -1.0 + b as f64 * h);
                let lit = light[2] - light[0] * g[0] - light[1] * g[1];
                s.image[a * n + b] = lit.max(0.0) / (1.0 + g[0] * g[0] + g[1] * g[1]).sqrt();
            }
        }
        s
    }

    fn unit(v: [f64; 3]) -> [f64; 3] {
        let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        [v[0] / n, v[1] / n, v[2] / n]
    }

    fn general(
        s: &Scene,
        light: [f64; 3],
        camera: Camera,
        anchors: Vec<(usize, f64)>,
    ) -> GeneralShadingOutput {
        let problem = GeneralShadingProblem {
            grid: s.grid.clone(),
            image: &s.image,
            albedo: 1.0,
            anchors,
            direction: Direction::Up,
            light,
            camera,
        };
        shape_from_shading_general(&problem, SweepOptions::default(), &Control::new()).unwrap()
    }

    fn border_anchors(s: &Scene) -> Vec<(usize, f64)> {
        border_cells(&s.grid)
            .into_iter()
            .map(|i| (i, s.height[i]))
            .collect()
    }

    #[test]
    fn oblique_light_recovers_a_gaussian_and_a_sphere_cap_converging() {
        let light = unit([0.25, -0.15, 1.0]);
        for (name, surface, bound) in [
            (
                "gaussian",
                (|x, y| gaussian(x, y, 0.1, -0.05, 0.6, 0.4)) as fn(f64, f64) -> (f64, [f64; 2]),
                0.005,
            ),
            // The rim's kink is smoothed by the numerical viscosity and
            // converges slowly (measured 0.106, 0.089, 0.077).
            ("sphere cap", sphere_cap, 0.08),
        ] {
            let mut errors = Vec::new();
            for n in [64, 128, 256] {
                let s = oblique_scene(n, light, surface);
                let out = general(&s, light, Camera::Orthographic, border_anchors(&s));
                assert_eq!(out.stop, SweepStop::Converged, "{name} {n}: {out:?}");
                assert_eq!(out.unreached, 0);
                let e = relative_rms(&s, &out.height);
                eprintln!(
                    "oblique {name} {n}²: RMS {e:.5} of the depth range, {} iterations",
                    out.iterations
                );
                errors.push(e);
            }
            assert!(errors[2] <= bound, "{name}: RMS {errors:?} (bound {bound})");
            assert!(
                errors[1] < errors[0] && errors[2] < errors[1],
                "{name}: errors {errors:?} must decrease with resolution"
            );
        }
    }

    #[test]
    fn oblique_solver_under_a_frontal_light_agrees_with_fast_marching() {
        let s = scene(96, bumps);
        let out = general(
            &s,
            [0.0, 0.0, 1.0],
            Camera::Orthographic,
            border_anchors(&s),
        );
        let e = relative_rms(&s, &out.height);
        let fm = relative_rms(&s, &from_border(&s, Order::First));
        eprintln!("frontal by sweeping {e:.5}, by fast marching {fm:.5}");
        assert!(e <= 0.02, "RMS {e}");
    }

    /// A Gaussian dent towards the camera in front of a fronto-parallel
    /// plane at depth 3, `Z(x) = 3 - exp(-|x/f|² / 0.2²)`, seen by a camera
    /// of focal `f = n` pixels, lit from its centre with `1 / r²` falloff.
    fn perspective_scene(n: usize) -> (Scene, Camera) {
        let f = n as f64;
        let c = (n - 1) as f64 / 2.0;
        let grid = Grid::unit(&[n, n]).unwrap();
        let (mut height, mut image) = (Vec::new(), Vec::new());
        for a in 0..n {
            for b in 0..n {
                let x = [a as f64 - c, b as f64 - c];
                let r2 = (x[0] * x[0] + x[1] * x[1]) / (f * f);
                let bump = (-r2 / 0.04).exp();
                let z = 3.0 - bump;
                // ∇Z in pixels, p = ∇ ln Z.
                let g = [
                    bump * 2.0 * x[0] / (0.04 * f * f),
                    bump * 2.0 * x[1] / (0.04 * f * f),
                ];
                let p = [g[0] / z, g[1] / z];
                let xp = 1.0 + x[0] * p[0] + x[1] * p[1];
                let s = (f * f * (p[0] * p[0] + p[1] * p[1]) + xp * xp).sqrt();
                let d2 = x[0] * x[0] + x[1] * x[1] + f * f;
                image.push(f.powi(3) / (z * z * d2 * d2.sqrt() * s));
                height.push(z);
            }
        }
        let camera = Camera::Perspective {
            focal: f,
            principal_point: [c, c],
            attenuation: true,
        };
        (
            Scene {
                grid,
                height,
                image,
            },
            camera,
        )
    }

    #[test]
    fn perspective_model_recovers_a_perspective_image_where_orthographic_does_not() {
        let (s, camera) = perspective_scene(128);
        // No anchors: the attenuation makes the problem well-posed.
        let out = general(&s, [0.0, 0.0, 1.0], camera, Vec::new());
        assert_eq!(out.stop, SweepStop::Converged, "{out:?}");
        let persp = relative_rms(&s, &out.height);
        // The orthographic reading, anchored on the border, compared after
        // the best affine map of its height onto the depth.
        let max = s.image.iter().cloned().fold(0.0, f64::max);
        let problem = ShadingProblem {
            grid: s.grid.clone(),
            image: &s.image,
            albedo: max,
            anchors: border_cells(&s.grid)
                .into_iter()
                .map(|i| (i, 0.0))
                .collect(),
            direction: Direction::Up,
            min_slope: 1e-9,
        };
        let z = shape_from_shading(&problem, ShadingOptions::default(), &Control::new())
            .unwrap()
            .height;
        let nf = z.len() as f64;
        let (mz, md) = (
            z.iter().sum::<f64>() / nf,
            s.height.iter().sum::<f64>() / nf,
        );
        let cov: f64 = z
            .iter()
            .zip(&s.height)
            .map(|(a, b)| (a - mz) * (b - md))
            .sum();
        let var: f64 = z.iter().map(|a| (a - mz) * (a - mz)).sum();
        let fitted: Vec<f64> = z.iter().map(|a| md + cov / var * (a - mz)).collect();
        let ortho = relative_rms(&s, &fitted);
        eprintln!(
            "perspective image 128²: perspective RMS {persp:.5}, orthographic (best affine fit) {ortho:.5} of the depth range, {} iterations",
            out.iterations
        );
        assert!(persp <= 0.03, "perspective RMS {persp}");
        assert!(
            ortho >= 3.0 * persp && ortho >= 0.08,
            "orthographic RMS {ortho} vs {persp}"
        );
        // Resolution: the error falls from 64² to 128².
        let (s64, c64) = perspective_scene(64);
        let e64 = relative_rms(
            &s64,
            &general(&s64, [0.0, 0.0, 1.0], c64, Vec::new()).height,
        );
        assert!(persp < e64, "64²: {e64}, 128²: {persp}");
    }

    #[test]
    fn surface_mesh_skips_quads_around_unreached_cells() {
        let (s, camera) = perspective_scene(16);
        let out = general(&s, [0.0, 0.0, 1.0], camera, Vec::new());
        let (points, triangles) = surface_mesh(&s.grid, &out.height, &camera);
        assert_eq!(points.len(), 256);
        assert_eq!(triangles.len(), 2 * 15 * 15);
        assert!(points.iter().flatten().all(|v| v.is_finite()));
        // The centre's back-projection is on the optical axis at its depth.
        let mut height = out.height.clone();
        height[5 * 16 + 5] = f64::INFINITY;
        let (points, triangles) = surface_mesh(&s.grid, &height, &Camera::Orthographic);
        assert_eq!(points.len(), 255);
        assert_eq!(triangles.len(), 2 * (15 * 15 - 4));
        assert!(triangles
            .iter()
            .flatten()
            .all(|&v| (v as usize) < points.len()));
    }

    #[test]
    fn sweeping_stops_on_the_cap_and_on_a_raised_flag_and_refuses_bad_input() {
        let light = unit([0.3, 0.0, 1.0]);
        let s = oblique_scene(32, light, bumps);
        let problem = GeneralShadingProblem {
            grid: s.grid.clone(),
            image: &s.image,
            albedo: 1.0,
            anchors: border_anchors(&s),
            direction: Direction::Up,
            light,
            camera: Camera::Orthographic,
        };
        let capped = SweepOptions {
            tolerance: 1e-12,
            max_iterations: 2,
        };
        let out = shape_from_shading_general(&problem, capped, &Control::new()).unwrap();
        assert_eq!((out.stop, out.iterations), (SweepStop::IterationCap, 2));
        assert!(out.change > 1e-12);
        let flag = AtomicBool::new(true);
        let cancelled = Control::new().with_cancel(&flag);
        let e =
            shape_from_shading_general(&problem, SweepOptions::default(), &cancelled).unwrap_err();
        assert_eq!(e, ShadingError::Cancelled);
        let (ps, camera) = perspective_scene(32);
        let perspective = GeneralShadingProblem {
            grid: ps.grid.clone(),
            image: &ps.image,
            anchors: Vec::new(),
            camera,
            ..problem.clone()
        };
        let e = shape_from_shading_general(&perspective, SweepOptions::default(), &cancelled)
            .unwrap_err();
        assert_eq!(e, ShadingError::Cancelled);
        let bad_light = GeneralShadingProblem {
            light: [0.0, 0.6, 0.6],
            ..problem.clone()
        };
        let e = shape_from_shading_general(&bad_light, SweepOptions::default(), &Control::new())
            .unwrap_err();
        assert!(matches!(e, ShadingError::Light(_)), "{e}");
        let no_anchor = GeneralShadingProblem {
            camera: Camera::Perspective {
                focal: 32.0,
                principal_point: [16.0, 16.0],
                attenuation: false,
            },
            anchors: Vec::new(),
            ..perspective.clone()
        };
        let e = shape_from_shading_general(&no_anchor, SweepOptions::default(), &Control::new())
            .unwrap_err();
        assert_eq!(e, ShadingError::NoAnchors);
        let deep = GeneralShadingProblem {
            anchors: vec![(0, -1.0)],
            ..perspective
        };
        let e = shape_from_shading_general(&deep, SweepOptions::default(), &Control::new())
            .unwrap_err();
        assert!(matches!(e, ShadingError::Anchor { index: 0, .. }), "{e}");
    }

    #[test]
    fn perspective_without_attenuation_keeps_its_anchors_and_is_the_maximal_solution() {
        // The plane Z = 3 without attenuation: I = cos α = f / sqrt(|x|² + f²).
        // Without the 1/r² term the model keeps the concave/convex
        // ambiguity: H(x, 0) = 0 everywhere here, the plane is a subsolution
        // and the answer (the maximal solution) bulges away from the camera
        // from its border anchors, never nearer than the plane.
        let n = 24;
        let f = 24.0;
        let c = (n - 1) as f64 / 2.0;
        let grid = Grid::unit(&[n, n]).unwrap();
        let image: Vec<f64> = (0..n * n)
            .map(|i| {
                let x = [(i / n) as f64 - c, (i % n) as f64 - c];
                f / (x[0] * x[0] + x[1] * x[1] + f * f).sqrt()
            })
            .collect();
        let problem = GeneralShadingProblem {
            grid: grid.clone(),
            image: &image,
            albedo: 1.0,
            anchors: border_cells(&grid).into_iter().map(|i| (i, 3.0)).collect(),
            direction: Direction::Up,
            light: [0.0, 0.0, 1.0],
            camera: Camera::Perspective {
                focal: f,
                principal_point: [c, c],
                attenuation: false,
            },
        };
        let out =
            shape_from_shading_general(&problem, SweepOptions::default(), &Control::new()).unwrap();
        // It creeps towards the maximal solution: the cap (5000 iterations)
        // ends it with changes of ~2e-7.
        assert!(out.change < 1e-5, "{out:?}");
        let nearest = out.height.iter().cloned().fold(f64::INFINITY, f64::min);
        let farthest = out.height.iter().cloned().fold(0.0, f64::max);
        eprintln!("plane without attenuation: depth in [{nearest}, {farthest}]");
        assert!((nearest - 3.0).abs() <= 1e-9, "nearest {nearest}");
        assert!(
            farthest.is_finite() && farthest >= 3.0,
            "farthest {farthest}"
        );
        for i in border_cells(&grid) {
            assert_eq!(out.height[i], 3.0f64.ln().exp());
        }
    }
}
