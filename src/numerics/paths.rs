//! Minimal paths: from an end point down the distance map `U` to the source
//! set (seed section 1.5.3, eq. 1.26).
//!
//! The geodesic `γ` from an end point `x_e` to the sources solves
//!
//! ```text
//! dγ/dt = −v(γ) / |v(γ)|,   γ(0) = x_e,   v = ∇U (isotropic), v = T⁻¹∇U (Riemannian)
//! ```
//!
//! # Scheme
//! * `∇U` at a cell: per axis, the centred difference `(U[i+1] − U[i−1]) / 2h`
//!   where `U` is monotone through the cell (second order), else the
//!   one-sided upwind difference towards the smaller neighbour (first order;
//!   at kinks: the medial axis, sources); `0` along an axis where the cell is
//!   a local minimum. Walls and unreached cells (`U = +inf`) are never used.
//! * `∇U` at a point: bilinear (2D) / trilinear (3D) interpolation of the
//!   cell gradients of the `2^d` surrounding cells, over the finite ones.
//! * Steps: classical Runge–Kutta 4 on the unit direction field (in index
//!   space), of length at most half a cell ([`DescentOptions::step`]).
//! * A continuous step is refused when the direction is undefined or zero
//!   (plateaus, the medial axis, ITK's stall), when the segment would enter a
//!   wall or unreached cell, or when the interpolated `U` would not decrease;
//!   the path then takes a **discrete steepest-descent step** to the
//!   neighbour (8 in 2D, 26 in 3D, without cutting a wall corner) of least
//!   `U`. `U` strictly decreases along the path, so it cannot cycle, and a
//!   step budget ([`DescentOptions::max_steps`]) makes a hang impossible.
//! * The descent ends when it is within one cell ([`DescentOptions::arrival`])
//!   of a source, and the path is joined to it (the source point, or the
//!   centre of the source cell).
//!
//! The direction field is generic ([`DescentDirection`]): an anisotropic
//! solver passes `x, ∇U ↦ −T⁻¹(x)∇U` and reuses the whole descent (see
//! [`crate::numerics::anisotropic::descent`]).
//!
//! Lengths: the geodesic length `L = ∫ ‖γ'‖_γ` (physical units; `W |γ'|`
//! for a cost, `sqrt(γ'ᵀ M γ')` for a tensor, [`CellCost::norm_at`]) is
//! integrated with Simpson's rule per segment, with the integrand
//! interpolated like `∇U`; the Euclidean length is the physical polyline length.

use std::collections::HashMap;

use super::eikonal::Source;
use super::grid::Grid;
use super::metric::IsotropicCost;

/// Why a path could not be extracted.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PathError {
    /// The distance map does not have one value per cell.
    #[error("the distance map has {got} values but the grid has {expected} cells")]
    Length {
        /// Values given.
        got: usize,
        /// Cells in the grid.
        expected: usize,
    },
    /// An end point is malformed or outside the grid.
    #[error("end point {point:?}: {reason}")]
    EndPoint {
        /// The point, as given.
        point: Vec<f64>,
        /// What is wrong with it.
        reason: String,
    },
    /// The end point was not reached by the front (a wall, another component, an early stop).
    #[error("end point {point:?} was not reached by the front (wall, unreachable, or beyond an early stop)")]
    Unreached {
        /// The point, as given.
        point: Vec<f64>,
    },
    /// A source is malformed or outside the grid.
    #[error("sources[{index}]: {reason}")]
    Source {
        /// Position in the source list.
        index: usize,
        /// What is wrong with it.
        reason: String,
    },
    /// No sources were given.
    #[error("at least one source is required")]
    NoSources,
    /// An option is out of range.
    #[error("{field}: {reason}")]
    Option {
        /// The option.
        field: &'static str,
        /// Why.
        reason: String,
    },
    /// The descent found a local minimum of `U` that is not a source (the
    /// map is not a distance map of these sources), or used its step budget.
    #[error("the descent stopped at {at:?} after {steps} steps: {reason}")]
    Stalled {
        /// Where it stopped (index coordinates).
        at: Vec<f64>,
        /// Steps taken.
        steps: usize,
        /// Why.
        reason: &'static str,
    },
}

/// The direction of descent at a point, from the interpolated gradient of `U`.
///
/// `x` is the point in padded index coordinates and `grad` the interpolated
/// `∇U(x)` in physical units (per storage axis, component 0 is 0 in 2D). The
/// answer is a physical direction (any positive length; it is normalised),
/// typically `−∇U` (isotropic) or `−T⁻¹(x)∇U` (Riemannian). Return `None`
/// where the direction is undefined: the descent then takes a discrete step.
pub trait DescentDirection {
    /// The descent direction at `x`.
    fn direction(&self, x: [f64; 3], grad: [f64; 3]) -> Option<[f64; 3]>;
}

impl<F> DescentDirection for F
where
    F: Fn([f64; 3], [f64; 3]) -> Option<[f64; 3]>,
{
    fn direction(&self, x: [f64; 3], grad: [f64; 3]) -> Option<[f64; 3]> {
        self(x, grad)
    }
}

/// The isotropic descent direction `−∇U`.
#[derive(Debug, Clone, Copy, Default)]
pub struct Isotropic;

impl DescentDirection for Isotropic {
    #[inline]
    fn direction(&self, _x: [f64; 3], grad: [f64; 3]) -> Option<[f64; 3]> {
        Some([-grad[0], -grad[1], -grad[2]])
    }
}

/// Options of the descent, with documented defaults.
#[derive(Debug, Clone, PartialEq)]
pub struct DescentOptions {
    /// Length of a Runge–Kutta step in cells (index units), in `(0, 0.5]`. Default: 0.5.
    pub step: f64,
    /// The descent ends once within this distance (cells) of a source, in `(0, 2]`. Default: 1.
    pub arrival: f64,
    /// Largest number of steps; `None`: `4 × (cells) + 1000`. Default: `None`.
    pub max_steps: Option<usize>,
}

impl Default for DescentOptions {
    fn default() -> Self {
        Self {
            step: 0.5,
            arrival: 1.0,
            max_steps: None,
        }
    }
}

/// A minimal path, ordered **from the source to the end point**.
#[derive(Debug, Clone, PartialEq)]
pub struct MinimalPath {
    /// Vertices in padded index coordinates (axis 0 is 0 for a 2D grid).
    pub points: Vec<[f64; 3]>,
    /// Index of the source reached (its position in the source list).
    pub source: usize,
    /// `∫ W |γ'|` along the polyline, physical units.
    pub geodesic_length: f64,
    /// Physical length of the polyline.
    pub euclidean_length: f64,
    /// Runge–Kutta steps taken.
    pub continuous_steps: usize,
    /// Discrete steepest-descent steps taken (fallbacks).
    pub discrete_steps: usize,
}

impl MinimalPath {
    /// The vertices in the caller's index coordinates (2 or 3 per point).
    pub fn index_points(&self, grid: &Grid) -> Vec<Vec<f64>> {
        let off = 3 - grid.ndim();
        self.points.iter().map(|p| p[off..].to_vec()).collect()
    }

    /// The vertices in physical coordinates (index times spacing).
    pub fn world_points(&self, grid: &Grid) -> Vec<Vec<f64>> {
        let off = 3 - grid.ndim();
        let h = grid.spacing3();
        self.points
            .iter()
            .map(|p| (off..3).map(|k| p[k] * h[k]).collect())
            .collect()
    }
}

/// The source set, indexed by cell for the arrival test.
#[derive(Debug, Clone)]
pub struct SourceSet {
    /// Source cell (linear index) to the source points attached to it.
    by_cell: HashMap<usize, Vec<(usize, [f64; 3])>>,
    /// The point sources (index, position), for the local solution around them.
    points: Vec<(usize, [f64; 3])>,
    /// Bounding box (index coordinates) of every source point and cell.
    lo: [f64; 3],
    hi: [f64; 3],
}

impl SourceSet {
    /// Indexes the sources of a solve: a point source by its nearest cell
    /// (joined at the point itself), a cell source by each of its cells
    /// (joined at the cell centre).
    pub fn new(grid: &Grid, sources: &[Source]) -> Result<Self, PathError> {
        if sources.is_empty() {
            return Err(PathError::NoSources);
        }
        let mut by_cell: HashMap<usize, Vec<(usize, [f64; 3])>> = HashMap::new();
        let mut points = Vec::new();
        for (index, s) in sources.iter().enumerate() {
            let err = |reason: String| PathError::Source { index, reason };
            match s {
                Source::Point(p) => {
                    let q = grid.point3(p).map_err(|e| err(e.to_string()))?;
                    if !grid.contains_point3(q) {
                        return Err(err(format!("{p:?} is outside the grid")));
                    }
                    let c = grid.linear(q.map(|v| v.round() as usize));
                    by_cell.entry(c).or_default().push((index, q));
                    points.push((index, q));
                }
                Source::Cells { cells, .. } => {
                    for cell in cells {
                        let c3 = grid.index3(cell).map_err(|e| err(e.to_string()))?;
                        if !grid.contains_index3(c3) {
                            return Err(err(format!("cell {cell:?} is outside the grid")));
                        }
                        by_cell
                            .entry(grid.linear(c3))
                            .or_default()
                            .push((index, c3.map(|v| v as f64)));
                    }
                }
            }
        }
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for list in by_cell.values() {
            for (_, p) in list {
                for k in 0..3 {
                    lo[k] = lo[k].min(p[k]);
                    hi[k] = hi[k].max(p[k]);
                }
            }
        }
        Ok(Self {
            by_cell,
            points,
            lo,
            hi,
        })
    }

    /// False when `x` is farther than `radius` from the box of the sources
    /// (no lookup needed: the common case along a long descent).
    #[inline]
    fn may_be_near(&self, x: [f64; 3], radius: f64) -> bool {
        (0..3).all(|k| x[k] >= self.lo[k] - radius && x[k] <= self.hi[k] + radius)
    }

    /// The nearest point source within `radius` (index units) of `x`.
    fn near_point(&self, grid: &Grid, x: [f64; 3], radius: f64) -> Option<[f64; 3]> {
        let d2 = |p: &[f64; 3]| -> f64 { (0..3).map(|k| (p[k] - x[k]).powi(2)).sum() };
        if self.points.is_empty() || !self.may_be_near(x, radius) {
            return None;
        }
        if self.points.len() <= 16 {
            return self
                .points
                .iter()
                .map(|(_, p)| (d2(p), *p))
                .filter(|(d, _)| *d <= radius * radius)
                .min_by(|a, b| a.0.total_cmp(&b.0))
                .map(|(_, p)| p);
        }
        self.near(grid, x, radius)
            .filter(|(index, p)| self.points.iter().any(|(i, q)| i == index && q == p))
            .map(|(_, p)| p)
    }

    /// The nearest source point within `radius` (index units) of `x`, with its index.
    fn near(&self, grid: &Grid, x: [f64; 3], radius: f64) -> Option<(usize, [f64; 3])> {
        if !self.may_be_near(x, radius) {
            return None;
        }
        let shape = grid.shape3();
        let r = radius.ceil() as isize;
        let c = x.map(|v| v.round() as isize);
        let mut best: Option<(f64, usize, [f64; 3])> = None;
        let lo = |k: usize| if shape[k] == 1 { 0 } else { -r };
        let hi = |k: usize| if shape[k] == 1 { 0 } else { r };
        for a in lo(0)..=hi(0) {
            for b in lo(1)..=hi(1) {
                for d in lo(2)..=hi(2) {
                    let q = [c[0] + a, c[1] + b, c[2] + d];
                    if (0..3).any(|k| q[k] < 0 || q[k] >= shape[k] as isize) {
                        continue;
                    }
                    let cell = grid.linear(q.map(|v| v as usize));
                    let Some(list) = self.by_cell.get(&cell) else {
                        continue;
                    };
                    for &(index, p) in list {
                        let d2: f64 = (0..3).map(|k| (p[k] - x[k]).powi(2)).sum();
                        if d2 <= radius * radius && best.is_none_or(|b| d2 < b.0) {
                            best = Some((d2, index, p));
                        }
                    }
                }
            }
        }
        best.map(|(_, i, p)| (i, p))
    }
}

/// The cost `W` of a cell (linear index), `+inf` on walls: an
/// [`IsotropicCost`] or a plain slice of values.
///
/// The two provided methods are what a Riemannian metric `M` overrides (see
/// [`crate::numerics::anisotropic::descent::Riemannian`]): the local norm of a
/// displacement (the integrand of the geodesic length) and the gradient of
/// the exact local solution around a point source.
pub trait CellCost {
    /// `W` of cell `i`.
    fn cost_at(&self, i: usize) -> f64;

    /// The length integrand: the local norm `‖d‖` at cell `i` of a physical
    /// displacement `d` (per storage axis). Default `W |d|`; a tensor metric
    /// gives `sqrt(dᵀ M d)`. `+inf` on walls.
    #[inline]
    fn norm_at(&self, i: usize, d: [f64; 3]) -> f64 {
        scaled_norm(self.cost_at(i), d)
    }

    /// `∇_x ‖x − p‖` at cell `i`, `d = x − p` physical: the gradient of the
    /// solution the solver prescribes around a point source `p`. Default
    /// `W d / |d|`; a tensor metric gives `M d / sqrt(dᵀ M d)`. `None` at
    /// `p` itself (`d = 0`) and on walls.
    #[inline]
    fn local_gradient(&self, i: usize, d: [f64; 3]) -> Option<[f64; 3]> {
        let w = self.cost_at(i);
        let dn = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        (dn > 0.0 && w.is_finite()).then(|| d.map(|v| w * v / dn))
    }
}

/// The length integrand of [`CellCost::norm_at`] and the local gradient of
/// [`CellCost::local_gradient`] for a scalar cost `W`.
#[inline]
fn scaled_norm(w: f64, d: [f64; 3]) -> f64 {
    w * (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
}

impl CellCost for IsotropicCost<'_> {
    #[inline]
    fn cost_at(&self, i: usize) -> f64 {
        self.at(i)
    }
}

impl CellCost for [f64] {
    #[inline]
    fn cost_at(&self, i: usize) -> f64 {
        self[i]
    }
}

/// Radius (cells) around a point source inside which the solver prescribes
/// the exact local solution `W(p)|x − p|` (its default `source_radius`).
pub const LOCAL_RADIUS: f64 = 1.5;

/// A distance map ready for descents: the grid, `U` (flat, C order) and the
/// cost `W` (walls, and the geodesic length).
#[derive(Debug, Clone, Copy)]
pub struct DistanceMap<'a, C: CellCost + ?Sized> {
    grid: &'a Grid,
    u: &'a [f64],
    cost: &'a C,
}

impl<'a, C: CellCost + ?Sized> DistanceMap<'a, C> {
    /// Wraps a solve's output; `u` has one value per cell, `+inf` where
    /// unreached and on every wall (as [`super::solve`] returns it), and
    /// `cost` gives `W` per cell (one value per cell).
    pub fn new(grid: &'a Grid, u: &'a [f64], cost: &'a C) -> Result<Self, PathError> {
        if u.len() != grid.len() {
            return Err(PathError::Length {
                got: u.len(),
                expected: grid.len(),
            });
        }
        Ok(Self { grid, u, cost })
    }

    #[inline]
    fn u_at(&self, c: [isize; 3]) -> f64 {
        let s = self.grid.shape3();
        if (0..3).any(|k| c[k] < 0 || c[k] >= s[k] as isize) {
            return f64::INFINITY;
        }
        // Walls have U = +inf in every solver's output (see [`DistanceMap::new`]).
        self.u[self.grid.linear(c.map(|v| v as usize))]
    }

    /// The upwind / centred gradient of `U` at a cell (see the module docs).
    fn cell_gradient(&self, c: [isize; 3]) -> Option<[f64; 3]> {
        let uc = self.u_at(c);
        if !uc.is_finite() {
            return None;
        }
        let h = self.grid.spacing3();
        let s = self.grid.shape3();
        let mut g = [0.0; 3];
        for k in 0..3 {
            if s[k] == 1 {
                continue;
            }
            let mut m = c;
            m[k] -= 1;
            let mut p = c;
            p[k] += 1;
            let (a, b) = (self.u_at(m), self.u_at(p));
            g[k] = if a.is_finite() && b.is_finite() && ((a < uc && uc < b) || (b < uc && uc < a)) {
                (b - a) / (2.0 * h[k])
            } else if a.min(b) < uc {
                if a <= b {
                    (uc - a) / h[k]
                } else {
                    (b - uc) / h[k]
                }
            } else {
                0.0
            };
        }
        Some(g)
    }

    /// The `2^d` cells around `x` with their multilinear weights.
    fn corners(&self, x: [f64; 3]) -> impl Iterator<Item = ([isize; 3], f64)> {
        let s = self.grid.shape3();
        let mut base = [0isize; 3];
        let mut frac = [0.0; 3];
        for k in 0..3 {
            let f = x[k].floor().clamp(0.0, (s[k] - 1) as f64);
            base[k] = f as isize;
            frac[k] = (x[k] - f).clamp(0.0, 1.0);
        }
        (0..8usize).filter_map(move |m| {
            let mut c = base;
            let mut w = 1.0;
            for k in 0..3 {
                let bit = (m >> (2 - k)) & 1;
                if bit == 1 {
                    if frac[k] == 0.0 || s[k] == 1 {
                        return None;
                    }
                    c[k] += 1;
                    w *= frac[k];
                } else {
                    w *= 1.0 - frac[k];
                }
            }
            (w > 0.0).then_some((c, w))
        })
    }

    /// `∇U(x)`, interpolated over the finite surrounding cells.
    pub fn gradient(&self, x: [f64; 3]) -> Option<[f64; 3]> {
        self.gradient_near(x, None)
    }

    /// `∇U(x)`; the cells within [`LOCAL_RADIUS`] of the point source `near`
    /// (and in its sight) use the gradient of the exact local solution the
    /// solver put there, `∇U = W (x − p) / |x − p|` (physical units), instead
    /// of finite differences across the singularity at `p`.
    fn gradient_near(&self, x: [f64; 3], near: Option<[f64; 3]>) -> Option<[f64; 3]> {
        let h = self.grid.spacing3();
        let mut g = [0.0; 3];
        let mut total = 0.0;
        for (c, w) in self.corners(x) {
            let local = near.and_then(|p| {
                let cf = c.map(|v| v as f64);
                let d: [f64; 3] = [0, 1, 2].map(|k| (cf[k] - p[k]) * h[k]);
                let di2: f64 = (0..3).map(|k| (cf[k] - p[k]).powi(2)).sum();
                if di2 > LOCAL_RADIUS * LOCAL_RADIUS || self.segment_blocked(cf, p) {
                    return None;
                }
                // At p itself the direction is undefined: the corner is skipped.
                Some(
                    self.cost
                        .local_gradient(self.grid.linear(c.map(|v| v as usize)), d),
                )
            });
            let gc = match local {
                Some(local) => local,
                None => self.cell_gradient(c),
            };
            if let Some(gc) = gc {
                for k in 0..3 {
                    g[k] += w * gc[k];
                }
                total += w;
            }
        }
        (total > 0.0).then(|| g.map(|v| v / total))
    }

    /// `U(x)`, interpolated over the finite surrounding cells (`+inf` if none).
    pub fn value(&self, x: [f64; 3]) -> f64 {
        self.interpolate(x, |c| self.u_at(c))
    }

    /// `W(x)`, interpolated over the non-wall surrounding cells (`+inf` if none).
    pub fn cost(&self, x: [f64; 3]) -> f64 {
        self.interpolate(x, |c| {
            let i = self.grid.linear(c.map(|v| v as usize));
            self.cost.cost_at(i)
        })
    }

    fn interpolate(&self, x: [f64; 3], f: impl Fn([isize; 3]) -> f64) -> f64 {
        let mut acc = 0.0;
        let mut total = 0.0;
        for (c, w) in self.corners(x) {
            let v = f(c);
            if v.is_finite() {
                acc += w * v;
                total += w;
            }
        }
        if total > 0.0 {
            acc / total
        } else {
            f64::INFINITY
        }
    }

    /// True if the open segment `a → b` (index coordinates, each axis moving
    /// at most one cell) meets the open box of a wall or an unreached cell.
    fn segment_blocked(&self, a: [f64; 3], b: [f64; 3]) -> bool {
        let lo = [0, 1, 2].map(|k| a[k].min(b[k]).round() as isize);
        let hi = [0, 1, 2].map(|k| a[k].max(b[k]).round() as isize);
        for i in lo[0]..=hi[0] {
            for j in lo[1]..=hi[1] {
                for l in lo[2]..=hi[2] {
                    let c = [i, j, l];
                    if self.u_at(c).is_finite() {
                        continue;
                    }
                    if segment_meets_open_box(a, b, c.map(|v| v as f64)) {
                        return true;
                    }
                }
            }
        }
        false
    }

    /// Extracts the minimal path from `end` (caller index coordinates) to the
    /// nearest source along `U`, with the direction field `dir`: the curve
    /// `γ' = dir(γ, ∇U(γ))` integrated by RK4 (a discrete steepest-descent
    /// step where the gradient is undefined or the step would cross a
    /// wall), until it enters a source cell.
    ///
    /// # Examples
    /// ```
    /// use geodex::numerics::paths::{DescentOptions, DistanceMap, Isotropic, SourceSet};
    /// use geodex::numerics::{solve, Control, EikonalOptions, EikonalProblem, Grid, IsotropicCost, Source};
    /// let (grid, sources) = (Grid::unit(&[32, 32])?, vec![Source::Point(vec![4.0, 4.0])]);
    /// let problem = EikonalProblem { grid: grid.clone(), cost: IsotropicCost::constant(1.0)?, sources: sources.clone() };
    /// let u: Vec<f64> = solve(&problem, &EikonalOptions::DEFAULT, &Control::new())?.distance.iter().copied().collect();
    /// let map = DistanceMap::new(&grid, &u, &problem.cost)?;
    /// let path = map.descend(&SourceSet::new(&grid, &sources)?, &[28.0, 20.0], &Isotropic, &DescentOptions::default())?;
    /// assert!((path.euclidean_length - (24f64.powi(2) + 16f64.powi(2)).sqrt()).abs() < 0.05);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn descend<D: DescentDirection + ?Sized>(
        &self,
        sources: &SourceSet,
        end: &[f64],
        dir: &D,
        options: &DescentOptions,
    ) -> Result<MinimalPath, PathError> {
        check_options(options)?;
        let grid = self.grid;
        let end_err = |reason: String| PathError::EndPoint {
            point: end.to_vec(),
            reason,
        };
        let start = grid.point3(end).map_err(|e| end_err(e.to_string()))?;
        if !grid.contains_point3(start) {
            return Err(end_err(format!("outside the grid {:?}", grid.shape())));
        }
        let start_cell = start.map(|v| v.round() as isize);
        if !self.u_at(start_cell).is_finite() {
            return Err(PathError::Unreached {
                point: end.to_vec(),
            });
        }
        let budget = options
            .max_steps
            .unwrap_or_else(|| grid.len().saturating_mul(4).saturating_add(1000));
        let h = grid.spacing3();
        let shape = grid.shape3();
        let mut points = vec![start];
        let mut x = start;
        let mut ux = self.value(x);
        let (mut continuous, mut discrete) = (0usize, 0usize);
        // The unit index-space direction at y, if defined.
        let mut near: Option<[f64; 3]>;
        let unit = |y: [f64; 3], near: Option<[f64; 3]>| -> Option<[f64; 3]> {
            if !grid.contains_point3(y) {
                return None;
            }
            let g = self.gradient_near(y, near)?;
            let v = dir.direction(y, g)?;
            let mut w = [0.0; 3];
            for k in 0..3 {
                w[k] = if shape[k] == 1 { 0.0 } else { v[k] / h[k] };
            }
            let n = (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt();
            (n.is_finite() && n > 1e-12).then(|| w.map(|v| v / n))
        };
        let source = loop {
            if let Some((index, p)) = sources.near(grid, x, options.arrival) {
                if p != x {
                    points.push(p);
                }
                break index;
            }
            if continuous + discrete >= budget {
                return Err(PathError::Stalled {
                    at: x[3 - grid.ndim()..].to_vec(),
                    steps: continuous + discrete,
                    reason: "the step budget is used up",
                });
            }
            // Runge–Kutta 4 on the unit field.
            let s = options.step;
            near = sources.near_point(grid, x, LOCAL_RADIUS + 2.0);
            let rk = (|| {
                let k1 = unit(x, near)?;
                let k2 = unit(add(x, k1, 0.5 * s), near)?;
                let k3 = unit(add(x, k2, 0.5 * s), near)?;
                let k4 = unit(add(x, k3, s), near)?;
                let mut d = [0.0; 3];
                for k in 0..3 {
                    d[k] = (k1[k] + 2.0 * k2[k] + 2.0 * k3[k] + k4[k]) / 6.0;
                }
                let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                (n > 1e-12).then(|| add(x, d, s / n))
            })();
            let next = rk.filter(|y| {
                grid.contains_point3(*y) && !self.segment_blocked(x, *y) && self.value(*y) < ux
            });
            match next {
                Some(y) => {
                    continuous += 1;
                    x = y;
                    ux = self.value(y);
                }
                None => {
                    let Some((y, uy)) = self.discrete_step(x, ux) else {
                        return Err(PathError::Stalled {
                            at: x[3 - grid.ndim()..].to_vec(),
                            steps: continuous + discrete,
                            reason: "a local minimum of U that is not a source",
                        });
                    };
                    discrete += 1;
                    x = y;
                    ux = uy;
                }
            }
            points.push(x);
        };
        points.reverse();
        let (geodesic_length, euclidean_length) = self.lengths(&points);
        Ok(MinimalPath {
            points,
            source,
            geodesic_length,
            euclidean_length,
            continuous_steps: continuous,
            discrete_steps: discrete,
        })
    }

    /// The neighbour cell of least `U` below `ux` around the cell nearest to
    /// `x` (without cutting wall corners); failing that, below the nearest
    /// cell's own value.
    fn discrete_step(&self, x: [f64; 3], ux: f64) -> Option<([f64; 3], f64)> {
        let c = x.map(|v| v.round() as isize);
        let s = self.grid.shape3();
        let uc = self.u_at(c);
        let mut best: Option<([isize; 3], f64)> = None;
        let r = |k: usize| if s[k] == 1 { 0 } else { 1 };
        for a in -r(0)..=r(0) {
            for b in -r(1)..=r(1) {
                for d in -r(2)..=r(2) {
                    let off = [a, b, d];
                    let q = [c[0] + a, c[1] + b, c[2] + d];
                    let uq = self.u_at(q);
                    if !uq.is_finite() || best.is_some_and(|(_, u)| uq >= u) {
                        continue;
                    }
                    // No corner cutting: every axis-aligned intermediate cell is open.
                    let open = (1..8usize).all(|m| {
                        let mut t = c;
                        let mut any = false;
                        for k in 0..3 {
                            if (m >> k) & 1 == 1 && off[k] != 0 {
                                t[k] += off[k];
                                any = true;
                            }
                        }
                        !any || self.u_at(t).is_finite()
                    });
                    if open {
                        best = Some((q, uq));
                    }
                }
            }
        }
        let (q, uq) = best?;
        let limit = if uq < ux { ux } else { uc };
        (uq < limit).then(|| (q.map(|v| v as f64), uq))
    }

    /// Geodesic and Euclidean lengths. Per segment `a → b` with physical
    /// displacement `d`, Simpson's rule on the length integrand
    /// `‖d‖(x)` ([`CellCost::norm_at`], interpolated over the non-wall cells
    /// around `x`): `(‖d‖(a) + 4‖d‖(m) + ‖d‖(b)) / 6`, which is
    /// `∫ W |γ'|` for a cost and `∫ sqrt(γ'ᵀ M γ')` for a tensor metric.
    fn lengths(&self, points: &[[f64; 3]]) -> (f64, f64) {
        let h = self.grid.spacing3();
        let mut geo = 0.0;
        let mut euc = 0.0;
        for w in points.windows(2) {
            let (a, b) = (w[0], w[1]);
            let d = [0, 1, 2].map(|k| (b[k] - a[k]) * h[k]);
            let m = [0, 1, 2].map(|k| 0.5 * (a[k] + b[k]));
            let norm = |x: [f64; 3]| {
                self.interpolate(x, |c| {
                    self.cost
                        .norm_at(self.grid.linear(c.map(|v| v as usize)), d)
                })
            };
            geo += (norm(a) + 4.0 * norm(m) + norm(b)) / 6.0;
            euc += self.grid.physical_distance3(a, b);
        }
        (geo, euc)
    }
}

#[inline]
fn add(x: [f64; 3], d: [f64; 3], t: f64) -> [f64; 3] {
    [x[0] + t * d[0], x[1] + t * d[1], x[2] + t * d[2]]
}

/// True if the open segment `a → b` meets the open unit box centred on `c`
/// (slab test; touching a face, an edge or a corner does not count).
pub fn segment_meets_open_box(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> bool {
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for k in 0..3 {
        let (lo, hi) = (c[k] - 0.5, c[k] + 0.5);
        let d = b[k] - a[k];
        if d.abs() < 1e-15 {
            if a[k] <= lo || a[k] >= hi {
                return false;
            }
        } else {
            let (mut e0, mut e1) = ((lo - a[k]) / d, (hi - a[k]) / d);
            if e0 > e1 {
                std::mem::swap(&mut e0, &mut e1);
            }
            t0 = t0.max(e0);
            t1 = t1.min(e1);
        }
    }
    t1 - t0 > 1e-12
}

fn check_options(o: &DescentOptions) -> Result<(), PathError> {
    if !(o.step.is_finite() && o.step > 0.0 && o.step <= 0.5) {
        return Err(PathError::Option {
            field: "step",
            reason: format!("{} must be in (0, 0.5] cells", o.step),
        });
    }
    if !(o.arrival.is_finite() && o.arrival > 0.0 && o.arrival <= 2.0) {
        return Err(PathError::Option {
            field: "arrival",
            reason: format!("{} must be in (0, 2] cells", o.arrival),
        });
    }
    Ok(())
}

/// Convenience: the isotropic minimal path from `end` to `sources` on the map `u`.
///
/// # Examples
/// ```
/// use geodex::numerics::{solve, Control, EikonalOptions, EikonalProblem, Grid, IsotropicCost, Source};
/// use geodex::numerics::paths::{minimal_path, DescentOptions};
/// let problem = EikonalProblem {
///     grid: Grid::unit(&[32, 32])?,
///     cost: IsotropicCost::constant(1.0)?,
///     sources: vec![Source::Point(vec![4.0, 4.0])],
/// };
/// let out = solve(&problem, &EikonalOptions::DEFAULT, &Control::new())?;
/// let u: Vec<f64> = out.distance.iter().copied().collect();
/// let path = minimal_path(&problem, &u, &[28.0, 20.0], &DescentOptions::default())?;
/// assert_eq!(path.source, 0);
/// assert!((path.euclidean_length - (24f64.powi(2) + 16f64.powi(2)).sqrt()).abs() < 0.05);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn minimal_path(
    problem: &super::EikonalProblem<'_>,
    u: &[f64],
    end: &[f64],
    options: &DescentOptions,
) -> Result<MinimalPath, PathError> {
    let sources = SourceSet::new(&problem.grid, &problem.sources)?;
    let map = DistanceMap::new(&problem.grid, u, &problem.cost)?;
    map.descend(&sources, end, &Isotropic, options)
}
