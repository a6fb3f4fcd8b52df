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
}
