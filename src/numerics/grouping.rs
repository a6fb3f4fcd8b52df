//! Perceptual grouping by minimal paths (monograph section 4.7; Cohen,
//! "Multiple contour finding and perceptual grouping using minimal paths",
//! JMIV 2001; the anisotropic variant after Bougleux, Peyré and Cohen,
//! ECCV 2008).
//!
//! Given key points `p_1, …, p_n` on a 2D grid and a metric (a cost `W`
//! small along the structures to group, or a tensor field `M` built from
//! the key points' orientations), the grouping is:
//!
//! 1. **Voronoi diagram.** One multi-source march gives `U = min_i U_i`
//!    (`U_i` the geodesic distance to `p_i`) and the label `ℓ(x) = argmin_i
//!    U_i(x)`: the geodesic Voronoi cells.
//! 2. **Saddle points.** Two cells `i`, `j` that touch meet along a
//!    boundary where `U_i = U_j`. The geodesic distance between the two key
//!    points is `d(p_i, p_j) = min_x U_i(x) + U_j(x)`, reached on the minimal
//!    geodesic, which crosses the boundary at the point `s_ij` where `U` is
//!    smallest along it: the saddle point of `U` (the meeting point of the two
//!    fronts). There `d = U_i(s) + U_j(s) = 2 U(s)`.
//!
//!    Scheme (sub-cell along the grid edge): for every grid edge `a → b`
//!    (axis `k`, spacing `h`) with `ℓ(a) = i ≠ j = ℓ(b)`, `U_i` and `U_j` are
//!    extended linearly along the edge, `U_i(a + t e_k) = U(a) + t h g_a`,
//!    `U_j(a + t e_k) = U(b) + (1 − t) h g_b`, with the one-sided slopes
//!    `g_a = (U(a) − U(a − e_k)) / h` (taken inside cell `i`) and
//!    `g_b = (U(b) − U(b + e_k)) / h` (inside cell `j`), clamped to
//!    `[0, ‖e_k‖_x]` (falling back to `‖e_k‖_x`, the metric norm of a unit
//!    step, where the neighbour is not in the same cell). The fronts meet at
//!    `t* = (U(b) − U(a) + h g_b) / (h (g_a + g_b))`, clamped to `[0, 1]`,
//!    and the estimate of `d` through that edge is
//!    `U_i(t*) + U_j(t*)`. The saddle of the pair is the edge of smallest
//!    estimate. For plane-wave fronts (locally linear `U_i`) the estimate is
//!    exact; along the boundary the error is that of sampling `U` at edge
//!    crossings, `O(h² / d)` in a constant metric.
//! 3. **Minimal paths.** The geodesic between `p_i` and `p_j` is the
//!    union of the two descents from the saddle, one in each cell
//!    (`crate::numerics::paths::DistanceMap::descend`). Each descent runs on
//!    `U` restricted to its own cell (the other cells are walls), which keeps
//!    it from slipping across the boundary, where `U` has a ridge.
//! 4. **Selection** ([`Selection`], the default explained there): the cheap
//!    links are kept; the contours are the connected components of the kept
//!    graph, each returned as an ordered chain of key points with the
//!    polyline of its paths, closed when the chain is a cycle; key points
//!    with no kept link (clutter) are left out.
//!
//! # Anisotropic grouping
//!
//! With an orientation `θ_p` per key point (the tangent `τ_p = (cos θ_p,
//! sin θ_p)`, angle from axis 0 towards axis 1, physical coordinates) the
//! metric is a tensor field cheap along the interpolated tangent. The
//! interpolation (our choice, in the spirit of Bougleux–Peyré–Cohen, who
//! interpolate the key points' tensors over the domain) is a Gaussian
//! average of the orientation tensors,
//!
//! ```text
//! S(x) = Σ_p w_p(x) τ_p τ_pᵀ / Σ_p w_p(x),     w_p(x) = exp(−|x − p|² / (2σ²)),
//! ```
//!
//! whose leading eigenvector `τ(x)` is the local tangent and whose
//! coherence `c(x) = λ_1 − λ_2 ∈ [0, 1]` says how well the nearby
//! orientations agree (1: all parallel; 0: crossing at right angles or no key
//! point within `3σ`). The metric is
//!
//! ```text
//! M(x) = W(x)² ( τ τᵀ / a(x)² + τ^⊥ τ^⊥ᵀ ),     a(x) = 1 + (A − 1) c(x),
//! ```
//!
//! so a step along the tangent costs `W / a`, across it `W`: up to `A`
//! ([`GroupingOptions::anisotropy`]) times cheaper along the tangent where the
//! orientations agree, isotropic where they do not. Orientations are axes:
//! `θ` and `θ + π` are the same. It is solved by
//! [`crate::numerics::anisotropic::solve`] and the paths descend `−M⁻¹∇U`.
//!
//! # Examples
//! ```
//! use geodex::numerics::{Control, Grid, IsotropicCost};
//! use geodex::numerics::grouping::{group, GroupingOptions, GroupingProblem};
//! // Five points on a line, constant cost: one open contour through all of them.
//! let problem = GroupingProblem {
//!     grid: Grid::unit(&[40, 60])?,
//!     cost: IsotropicCost::constant(1.0)?,
//!     key_points: (0..5).map(|k| [20.0, 8.0 + 10.0 * k as f64]).collect(),
//!     orientations: None,
//! };
//! let out = group(&problem, &GroupingOptions::default(), &Control::new())?;
//! assert_eq!(out.contours.len(), 1);
//! assert_eq!(out.contours[0].key_points, vec![0, 1, 2, 3, 4]);
//! assert!(!out.contours[0].closed);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use std::collections::HashMap;

use super::anisotropic::descent::Riemannian;
use super::anisotropic::{self, TensorField, TensorOptions, TensorProblem, TensorSolveError};
use super::control::Control;
use super::eikonal::{self, EikonalError, EikonalOptions, EikonalProblem, Order, Source};
use super::grid::Grid;
use super::metric::IsotropicCost;
use super::paths::{
    CellCost, DescentDirection, DescentOptions, DistanceMap, Isotropic, PathError, SourceSet,
};

/// The input of [`group`].
#[derive(Debug, Clone)]
pub struct GroupingProblem<'a> {
    /// The 2D grid and its spacing.
    pub grid: Grid,
    /// The cost `W` (walls included); with orientations it scales the tensor.
    pub cost: IsotropicCost<'a>,
    /// The key points, index coordinates `[row, column]`; at least 2.
    pub key_points: Vec<[f64; 2]>,
    /// One tangent angle per key point (radians, from axis 0 towards axis
    /// 1, physical coordinates), or `None` for the isotropic grouping.
    pub orientations: Option<Vec<f64>>,
}

/// Which links are kept (see [`Selection::keeps`] for the rule and why).
#[derive(Debug, Clone, PartialEq)]
pub struct Selection {
    /// A key point keeps at most its `max_links` cheapest links, and a link
    /// is kept only if it is among the `max_links` cheapest of both its ends.
    /// Default: 2 (contours are chains and cycles).
    pub max_links: usize,
    /// A link is kept only if its cost is at most `ratio` times the cheapest
    /// link of each of its two ends. Default: 2.5.
    pub ratio: f64,
    /// A link is kept only if its cost is at most `relative` times the
    /// typical link cost (the median over the key points of their cheapest
    /// link). `None`: no such bound. Default: 3.
    pub relative: Option<f64>,
    /// A link is kept only if its cost is at most this (absolute, physical
    /// units of `∫ W`). Default: none.
    pub max_cost: Option<f64>,
    /// Contours with fewer key points are dropped (their points count as
    /// isolated). Default: 2.
    pub min_points: usize,
}

impl Default for Selection {
    fn default() -> Self {
        Self {
            max_links: 2,
            ratio: 2.5,
            relative: Some(3.0),
            max_cost: None,
            min_points: 2,
        }
    }
}

impl Selection {
    /// Whether the link of cost `d` between `i` and `j` is kept, given each
    /// end's rank of the link among its own links (0: its cheapest), each
    /// end's cheapest cost `m_i`, `m_j`, and the typical cost `τ`:
    ///
    /// ```text
    /// rank_i < k  and  rank_j < k          (mutual k cheapest: degree <= k)
    /// d <= ratio · m_i  and  d <= ratio · m_j   (not much costlier than each end's best)
    /// d <= relative · τ,   d <= max_cost      (cheap in absolute terms)
    /// ```
    ///
    /// Why: along a contour sampled by key points, each point's two cheapest
    /// links are to its two neighbours on the contour (the cost is small
    /// along it, or the neighbours are nearest), so the mutual two-cheapest
    /// rule links consecutive points and gives every point degree at most 2
    /// (chains and cycles, no branches). At the end of an open contour the
    /// second-cheapest link leaves the contour and costs far more than the
    /// first: the `ratio` test cuts it, so open contours stay open. A
    /// clutter point's links all cost about its distance to the structures
    /// through the expensive background; they fail the `ratio` test of the
    /// contour points they would attach to, and two clutter points that pick
    /// each other fail the `relative` test against the typical spacing along
    /// the contours (the median is a contour link as long as clutter is
    /// fewer than half the key points).
    pub fn keeps(&self, d: f64, rank: [usize; 2], cheapest: [f64; 2], typical: f64) -> bool {
        d.is_finite()
            && rank.iter().all(|&r| r < self.max_links)
            && cheapest.iter().all(|&m| d <= self.ratio * m)
            && self.relative.is_none_or(|r| d <= r * typical)
            && self.max_cost.is_none_or(|c| d <= c)
    }
}

/// Options of [`group`], with documented defaults.
#[derive(Debug, Clone, PartialEq)]
pub struct GroupingOptions {
    /// Which links are kept.
    pub selection: Selection,
    /// With orientations: how many times cheaper a step along the tangent is
    /// than across it where the orientations agree (`A >= 1`). Default: 4.
    pub anisotropy: f64,
    /// With orientations: the width `σ` (physical units) of the Gaussian
    /// that interpolates them. `None`: the median distance from a key point
    /// to its nearest other key point. Default: `None`.
    pub spread: Option<f64>,
    /// Order of the isotropic fast marching. Default: second.
    pub order: Order,
    /// Options of the descents.
    pub descent: DescentOptions,
}

impl Default for GroupingOptions {
    fn default() -> Self {
        Self {
            selection: Selection::default(),
            anisotropy: 4.0,
            spread: None,
            order: Order::Second,
            descent: DescentOptions::default(),
        }
    }
}

/// A pair of Voronoi-adjacent key points and the geodesic between them.
#[derive(Debug, Clone, PartialEq)]
pub struct Link {
    /// The two key points, smaller index first.
    pub pair: [usize; 2],
    /// The saddle point (index coordinates): where the two fronts meet.
    pub saddle: [f64; 2],
    /// `U_i + U_j` at the saddle: the geodesic distance between the two.
    pub cost: f64,
    /// Whether the selection kept it.
    pub kept: bool,
    /// For a kept link: the minimal path from `pair[0]` through the saddle
    /// to `pair[1]` (index coordinates).
    pub path: Option<Vec<[f64; 2]>>,
    /// For a kept link: the length `∫ ‖γ'‖` of `path` (the two descents'
    /// integrated lengths and the linear model across the saddle edge).
    pub path_length: Option<f64>,
}

/// A group of key points: a connected component of the kept links.
#[derive(Debug, Clone, PartialEq)]
pub struct Contour {
    /// The key points: in chain order for a chain or a cycle (a cycle starts
    /// at its smallest index and does not repeat it), sorted for a branched
    /// component.
    pub key_points: Vec<usize>,
    /// Indices into [`GroupingOutput::links`] of its links.
    pub links: Vec<usize>,
    /// True when the chain closes on itself.
    pub closed: bool,
    /// True when some key point has more than two links (possible only with
    /// `max_links > 2`): there is then no single polyline.
    pub branched: bool,
    /// The paths of the chain joined in order (index coordinates); for a
    /// closed contour the last point is the first. `None` when branched.
    pub polyline: Option<Vec<[f64; 2]>>,
}

/// The result of [`group`].
#[derive(Debug, Clone)]
pub struct GroupingOutput {
    /// `U = min_i U_i` per cell (C order), `+inf` where not reached.
    pub distance: Vec<f64>,
    /// The Voronoi label per cell (C order), `-1` where not reached.
    pub labels: Vec<i32>,
    /// Every Voronoi-adjacent pair, by increasing `pair`.
    pub links: Vec<Link>,
    /// The contours, by their smallest key point.
    pub contours: Vec<Contour>,
    /// Key points in no contour (clutter), increasing.
    pub isolated: Vec<usize>,
    /// The typical link cost `τ` (median of the key points' cheapest link).
    pub typical_cost: f64,
    /// Kept links whose minimal path could not be traced by descent on one
    /// side: that half of `path` is the straight segment from the key point
    /// to the saddle's cell (the link stays: its cost is the saddle's).
    pub path_failures: usize,
    /// With orientations: the interpolation width `σ` used.
    pub spread: Option<f64>,
}

/// Why a grouping was refused or interrupted.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GroupingError {
    /// The grid is not 2D.
    #[error("grouping takes a 2D grid, got {0} axes")]
    NotTwoD(usize),
    /// Fewer than 2 key points.
    #[error("give at least 2 key points, got {0}")]
    TooFewPoints(usize),
    /// A key point is outside the grid, not finite, or on a wall.
    #[error("key_points[{index}]: {reason}")]
    KeyPoint {
        /// Its position in the list.
        index: usize,
        /// What is wrong.
        reason: String,
    },
    /// The orientations are not one finite angle per key point.
    #[error("orientations: {0}")]
    Orientations(String),
    /// An option is out of range.
    #[error("{field}: {reason}")]
    Option {
        /// The option.
        field: &'static str,
        /// Why.
        reason: String,
    },
    /// The metric could not be built or solved.
    #[error("{0}")]
    Solve(String),
    /// The caller raised the cancel flag.
    #[error("cancelled")]
    Cancelled,
}

fn option(field: &'static str, reason: String) -> GroupingError {
    GroupingError::Option { field, reason }
}

fn check(problem: &GroupingProblem<'_>, options: &GroupingOptions) -> Result<(), GroupingError> {
    let grid = &problem.grid;
    if grid.ndim() != 2 {
        return Err(GroupingError::NotTwoD(grid.ndim()));
    }
    let n = problem.key_points.len();
    if n < 2 {
        return Err(GroupingError::TooFewPoints(n));
    }
    let shape = grid.shape();
    for (index, p) in problem.key_points.iter().enumerate() {
        let err = |reason: String| GroupingError::KeyPoint { index, reason };
        if !p.iter().all(|v| v.is_finite()) {
            return Err(err("coordinates must be finite".into()));
        }
        if (0..2).any(|k| p[k] < 0.0 || p[k] > (shape[k] - 1) as f64) {
            return Err(err(format!(
                "{p:?} is outside the grid of shape {shape:?} (index coordinates, row first)"
            )));
        }
        let c = nearest(grid, *p);
        if problem.cost.is_wall(c) {
            return Err(err(format!("{p:?} lies on a wall")));
        }
    }
    if let Some(o) = &problem.orientations {
        if o.len() != n {
            return Err(GroupingError::Orientations(format!(
                "{} angles for {n} key points: give one per key point",
                o.len()
            )));
        }
        if let Some(k) = o.iter().position(|v| !v.is_finite()) {
            return Err(GroupingError::Orientations(format!(
                "orientations[{k}] = {} is not finite",
                o[k]
            )));
        }
    }
    let s = &options.selection;
    if s.max_links == 0 {
        return Err(option("max_links", "must be >= 1".into()));
    }
    if !(s.ratio.is_finite() && s.ratio >= 1.0) {
        return Err(option(
            "ratio",
            format!("{} must be finite and >= 1", s.ratio),
        ));
    }
    for (field, v) in [("relative", s.relative), ("max_cost", s.max_cost)] {
        if let Some(v) = v {
            if !(v.is_finite() && v > 0.0) {
                return Err(option(field, format!("{v} must be finite and > 0")));
            }
        }
    }
    if s.min_points < 2 {
        return Err(option("min_points", "must be >= 2".into()));
    }
    if !(options.anisotropy.is_finite() && (1.0..=100.0).contains(&options.anisotropy)) {
        return Err(option(
            "anisotropy",
            format!("{} must be in [1, 100]", options.anisotropy),
        ));
    }
    if let Some(v) = options.spread {
        if !(v.is_finite() && v > 0.0) {
            return Err(option("spread", format!("{v} must be finite and > 0")));
        }
    }
    Ok(())
}

/// The linear index of the cell nearest to `p`.
fn nearest(grid: &Grid, p: [f64; 2]) -> usize {
    let s = grid.shape();
    let r = (p[0].round() as usize).min(s[0] - 1);
    let c = (p[1].round() as usize).min(s[1] - 1);
    r * s[1] + c
}

fn eikonal_error(e: EikonalError) -> GroupingError {
    match e {
        EikonalError::Cancelled => GroupingError::Cancelled,
        EikonalError::Source { index, reason } => GroupingError::KeyPoint { index, reason },
        other => GroupingError::Solve(other.to_string()),
    }
}

fn tensor_error(e: TensorSolveError) -> GroupingError {
    match e {
        TensorSolveError::Solve(e) => eikonal_error(e),
        other => GroupingError::Solve(other.to_string()),
    }
}

/// The metric of the grouping: the cost alone, or the oriented tensor field.
enum Metric<'m, 'a> {
    Iso(&'m IsotropicCost<'a>),
    Tensor(TensorField),
}

/// Groups the key points into contours by minimal paths (see the module docs).
pub fn group(
    problem: &GroupingProblem<'_>,
    options: &GroupingOptions,
    control: &Control<'_>,
) -> Result<GroupingOutput, GroupingError> {
    check(problem, options)?;
    let grid = &problem.grid;
    let inner = control.cancel_only();
    let sources: Vec<Source> = problem
        .key_points
        .iter()
        .map(|p| Source::Point(p.to_vec()))
        .collect();
    control.report(0.0);
    let (metric, spread) = match &problem.orientations {
        None => (Metric::Iso(&problem.cost), None),
        Some(angles) => {
            let sigma = match options.spread {
                Some(s) => s,
                None => typical_spacing(grid, &problem.key_points),
            };
            let field = oriented_metric(
                grid,
                &problem.cost,
                &problem.key_points,
                angles,
                options.anisotropy,
                sigma,
                control,
            )?;
            (Metric::Tensor(field), Some(sigma))
        }
    };
    control.report(0.1);
    let out = match &metric {
        Metric::Iso(cost) => {
            let p = EikonalProblem {
                grid: grid.clone(),
                cost: (*cost).clone(),
                sources: sources.clone(),
            };
            let o = EikonalOptions::DEFAULT.with_order(options.order);
            eikonal::solve(&p, &o, &inner).map_err(eikonal_error)?
        }
        Metric::Tensor(field) => {
            let p = TensorProblem {
                grid: grid.clone(),
                metric: field.clone(),
                sources: sources.clone(),
            };
            anisotropic::solve(&p, &TensorOptions::DEFAULT, &inner)
                .map_err(tensor_error)?
                .output
        }
    };
    let u: Vec<f64> = out.distance.iter().copied().collect();
    let labels: Vec<i32> = out.labels.iter().copied().collect();
    control.report(0.5);
    if control.is_cancelled() {
        return Err(GroupingError::Cancelled);
    }
    let unit_norm = |i: usize, k: usize| -> f64 {
        match &metric {
            Metric::Iso(cost) => cost.at(i),
            Metric::Tensor(field) => {
                let m = field.at(i);
                if k == 0 {
                    m[0].sqrt()
                } else {
                    m[2].sqrt()
                }
            }
        }
    };
    let mut saddles: Vec<([usize; 2], Saddle)> =
        find_saddles(grid, &u, &labels, unit_norm, control)?
            .into_iter()
            .collect();
    saddles.sort_by_key(|a| a.0);
    let mut links: Vec<Link> = saddles
        .iter()
        .map(|&(pair, s)| Link {
            pair,
            saddle: s.point,
            cost: s.cost,
            kept: false,
            path: None,
            path_length: None,
        })
        .collect();
    let n = problem.key_points.len();
    let typical_cost = select(&mut links, n, &options.selection);
    control.report(0.6);
    // Paths of the kept links: per key point, descents on U restricted to its cell.
    let mut halves: HashMap<(usize, usize), Half> = HashMap::new();
    let mut path_failures = 0usize;
    let mut failed = vec![false; links.len()];
    // The cells of each Voronoi cell (counting sort by label), so that the
    // masked map of one key point is filled and cleared in its own cells.
    let mut start_of = vec![0usize; n + 1];
    for &l in &labels {
        if l >= 0 {
            start_of[l as usize + 1] += 1;
        }
    }
    for k in 0..n {
        start_of[k + 1] += start_of[k];
    }
    let mut cells_by_label = vec![0usize; start_of[n]];
    {
        let mut fill = start_of.clone();
        for (i, &l) in labels.iter().enumerate() {
            if l >= 0 {
                cells_by_label[fill[l as usize]] = i;
                fill[l as usize] += 1;
            }
        }
    }
    let mut masked = vec![f64::INFINITY; u.len()];
    let involved: Vec<usize> = {
        let mut v: Vec<usize> = links
            .iter()
            .filter(|l| l.kept)
            .flat_map(|l| l.pair)
            .collect();
        v.sort_unstable();
        v.dedup();
        v
    };
    for (step, &p) in involved.iter().enumerate() {
        if control.is_cancelled() {
            return Err(GroupingError::Cancelled);
        }
        control.report(0.6 + 0.35 * step as f64 / involved.len().max(1) as f64);
        let own = &cells_by_label[start_of[p]..start_of[p + 1]];
        for &i in own {
            masked[i] = u[i];
        }
        let set = SourceSet::new(grid, &sources[p..=p]).map_err(path_solve_error)?;
        let all = SourceSet::new(grid, &sources).map_err(path_solve_error)?;
        for (l, link) in links.iter().enumerate() {
            if !link.kept || !link.pair.contains(&p) {
                continue;
            }
            let edge = saddles[l].1;
            let (start, other) = if edge.label_a == p {
                (edge.a, edge.b)
            } else {
                (edge.b, edge.a)
            };
            // Starts: the boundary cell on `p`'s side, then up to 3 cells
            // further inside along the edge's axis. From each, the descent on
            // U restricted to the cell; failing that (the discrete descent
            // can stall against the boundary where a cell's value was set
            // from a neighbouring cell's front), on the whole map, accepted
            // only if it reaches `p`. The cells skipped are joined straight.
            let step = [start[0] - other[0], start[1] - other[1]];
            let mut traced = None;
            for m in 0..4 {
                let x = [start[0] + m as f64 * step[0], start[1] + m as f64 * step[1]];
                if !(0..2).all(|k| x[k] >= 0.0 && x[k] <= (grid.shape()[k] - 1) as f64)
                    || labels[nearest(grid, x)] != p as i32
                {
                    break;
                }
                let half = match &metric {
                    Metric::Iso(cost) => {
                        descend(grid, &masked, *cost, &Isotropic, &set, x, options).or_else(|| {
                            descend_to(grid, &u, *cost, &Isotropic, &all, x, p, options)
                        })
                    }
                    Metric::Tensor(field) => {
                        let r = Riemannian::new(grid, field);
                        descend(grid, &masked, &r, &r, &set, x, options)
                            .or_else(|| descend_to(grid, &u, &r, &r, &all, x, p, options))
                    }
                };
                if let Some((mut points, mut length)) = half {
                    for back in (0..m).rev() {
                        let y = [
                            start[0] + back as f64 * step[0],
                            start[1] + back as f64 * step[1],
                        ];
                        let c = nearest(grid, y);
                        let k = usize::from(step[1] != 0.0);
                        length += unit_norm(c, k) * grid.spacing()[k];
                        points.push(y);
                    }
                    traced = Some((points, length));
                    break;
                }
            }
            // Last resort: the straight segment from `p` to the boundary
            // cell, of length `U` there (counted in `path_failures`).
            let half = traced.unwrap_or_else(|| {
                failed[l] = true;
                let kp = problem.key_points[p];
                (vec![kp, start], u[nearest(grid, start)])
            });
            halves.insert((l, p), half);
        }
        for &i in own {
            masked[i] = f64::INFINITY;
        }
    }
    for (l, link) in links.iter_mut().enumerate() {
        if !link.kept {
            continue;
        }
        let [i, j] = link.pair;
        if failed[l] {
            path_failures += 1;
        }
        let (Some(hi), Some(hj)) = (halves.get(&(l, i)), halves.get(&(l, j))) else {
            link.kept = false;
            path_failures += usize::from(!failed[l]);
            continue;
        };
        let mut path = hi.0.clone();
        path.push(link.saddle);
        path.extend(hj.0.iter().rev());
        link.path = Some(path);
        link.path_length = Some(hi.1 + hj.1 + saddles[l].1.middle);
    }
    let (contours, isolated) = contours(&links, n, options.selection.min_points);
    control.report(1.0);
    Ok(GroupingOutput {
        distance: u,
        labels,
        links,
        contours,
        isolated,
        typical_cost,
        path_failures,
        spread,
    })
}

fn path_solve_error(e: PathError) -> GroupingError {
    GroupingError::Solve(e.to_string())
}

/// The descent from `start` (a cell of the source's Voronoi cell) to the one
/// source of `set` on the masked map: the path from the source to `start`
/// (2D index coordinates) and its integrated length; `None` if it fails.
fn descend<C: CellCost + ?Sized, D: DescentDirection + ?Sized>(
    grid: &Grid,
    masked: &[f64],
    cost: &C,
    dir: &D,
    set: &SourceSet,
    start: [f64; 2],
    options: &GroupingOptions,
) -> Option<(Vec<[f64; 2]>, f64)> {
    let map = DistanceMap::new(grid, masked, cost).ok()?;
    let path = map.descend(set, &start, dir, &options.descent).ok()?;
    let points = path.points.iter().map(|p| [p[1], p[2]]).collect();
    Some((points, path.geodesic_length))
}

/// One side of a link's path: from the key point to the boundary cell, and its length.
type Half = (Vec<[f64; 2]>, f64);

/// [`descend`] on a map of several sources, accepted only if the path
/// reaches the source `target`.
#[allow(clippy::too_many_arguments)]
fn descend_to<C: CellCost + ?Sized, D: DescentDirection + ?Sized>(
    grid: &Grid,
    u: &[f64],
    cost: &C,
    dir: &D,
    set: &SourceSet,
    start: [f64; 2],
    target: usize,
    options: &GroupingOptions,
) -> Option<(Vec<[f64; 2]>, f64)> {
    let map = DistanceMap::new(grid, u, cost).ok()?;
    let path = map.descend(set, &start, dir, &options.descent).ok()?;
    (path.source == target).then(|| {
        (
            path.points.iter().map(|p| [p[1], p[2]]).collect(),
            path.geodesic_length,
        )
    })
}

/// The saddle of one pair: the best edge `a → b` (cells, index
/// coordinates) crossing the boundary, `label_a` the key point of `a`, and
/// `middle = t h g_a + (1 − t) h g_b`, the linear model's length from `a`
/// through the saddle to `b`.
#[derive(Debug, Clone, Copy)]
struct Saddle {
    point: [f64; 2],
    cost: f64,
    a: [f64; 2],
    b: [f64; 2],
    label_a: usize,
    middle: f64,
}

/// Every pair of Voronoi-adjacent key points with its saddle (see the
/// module docs for the scheme). `unit_norm(i, k)` is the metric norm of a
/// unit physical step along axis `k` at cell `i`.
fn find_saddles(
    grid: &Grid,
    u: &[f64],
    labels: &[i32],
    unit_norm: impl Fn(usize, usize) -> f64,
    control: &Control<'_>,
) -> Result<HashMap<[usize; 2], Saddle>, GroupingError> {
    let s = grid.shape();
    let h = grid.spacing();
    let (n0, n1) = (s[0], s[1]);
    let stride = [n1, 1];
    let mut best: HashMap<[usize; 2], Saddle> = HashMap::new();
    for r in 0..n0 {
        if r % 64 == 0 {
            if control.is_cancelled() {
                return Err(GroupingError::Cancelled);
            }
            control.report(0.5 + 0.1 * r as f64 / n0 as f64);
        }
        for c in 0..n1 {
            let ia = r * n1 + c;
            let la = labels[ia];
            if la < 0 || !u[ia].is_finite() {
                continue;
            }
            for k in 0..2 {
                let pos = [r, c];
                if pos[k] + 1 >= s[k] {
                    continue;
                }
                let ib = ia + stride[k];
                let lb = labels[ib];
                if lb < 0 || lb == la || !u[ib].is_finite() {
                    continue;
                }
                let hk = h[k];
                // One-sided slope of U_la at a along +e_k (inside cell la).
                let wa = unit_norm(ia, k);
                let wb = unit_norm(ib, k);
                let ga = if pos[k] >= 1 && labels[ia - stride[k]] == la {
                    let v = (u[ia] - u[ia - stride[k]]) / hk;
                    if v.is_finite() {
                        v.clamp(0.0, wa)
                    } else {
                        wa
                    }
                } else {
                    wa
                };
                let gb = if pos[k] + 2 < s[k] && labels[ib + stride[k]] == lb {
                    let v = (u[ib] - u[ib + stride[k]]) / hk;
                    if v.is_finite() {
                        v.clamp(0.0, wb)
                    } else {
                        wb
                    }
                } else {
                    wb
                };
                let den = hk * (ga + gb);
                let t = if den > 1e-300 {
                    ((u[ib] - u[ia] + hk * gb) / den).clamp(0.0, 1.0)
                } else {
                    0.5
                };
                let cost = u[ia] + t * hk * ga + u[ib] + (1.0 - t) * hk * gb;
                let mut point = [r as f64, c as f64];
                point[k] += t;
                let key = if la < lb {
                    [la as usize, lb as usize]
                } else {
                    [lb as usize, la as usize]
                };
                let mut b = [r as f64, c as f64];
                b[k] += 1.0;
                let candidate = Saddle {
                    point,
                    cost,
                    a: [r as f64, c as f64],
                    b,
                    label_a: la as usize,
                    middle: t * hk * ga + (1.0 - t) * hk * gb,
                };
                let e = best.entry(key).or_insert(candidate);
                if cost < e.cost {
                    *e = candidate;
                }
            }
        }
    }
    Ok(best)
}

/// Applies the selection to `links` (sorted by pair) and returns the
/// typical cost `τ`.
fn select(links: &mut [Link], n: usize, selection: &Selection) -> f64 {
    let mut incident: Vec<Vec<(f64, usize)>> = vec![Vec::new(); n];
    for (l, link) in links.iter().enumerate() {
        if link.cost.is_finite() {
            for p in link.pair {
                incident[p].push((link.cost, l));
            }
        }
    }
    let mut rank: HashMap<(usize, usize), usize> = HashMap::new();
    let mut cheapest = vec![f64::INFINITY; n];
    for (p, inc) in incident.iter_mut().enumerate() {
        inc.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        for (r, &(_, l)) in inc.iter().enumerate() {
            rank.insert((p, l), r);
        }
        if let Some(&(c, _)) = inc.first() {
            cheapest[p] = c;
        }
    }
    let mut finite: Vec<f64> = cheapest.iter().copied().filter(|c| c.is_finite()).collect();
    finite.sort_by(f64::total_cmp);
    let typical = if finite.is_empty() {
        f64::INFINITY
    } else {
        let m = finite.len();
        if m % 2 == 1 {
            finite[m / 2]
        } else {
            0.5 * (finite[m / 2 - 1] + finite[m / 2])
        }
    };
    for (l, link) in links.iter_mut().enumerate() {
        let [i, j] = link.pair;
        let ranks = [
            rank.get(&(i, l)).copied().unwrap_or(usize::MAX),
            rank.get(&(j, l)).copied().unwrap_or(usize::MAX),
        ];
        link.kept = selection.keeps(link.cost, ranks, [cheapest[i], cheapest[j]], typical);
    }
    typical
}

/// The connected components of the kept links with at least `min_points`
/// key points, ordered as chains where possible, and the other key points.
fn contours(links: &[Link], n: usize, min_points: usize) -> (Vec<Contour>, Vec<usize>) {
    let mut adj: Vec<Vec<(usize, usize)>> = vec![Vec::new(); n];
    for (l, link) in links.iter().enumerate() {
        if link.kept && link.path.is_some() {
            let [i, j] = link.pair;
            adj[i].push((j, l));
            adj[j].push((i, l));
        }
    }
    let mut seen = vec![false; n];
    let mut out = Vec::new();
    let mut isolated = Vec::new();
    for start in 0..n {
        if seen[start] {
            continue;
        }
        // The component of `start`.
        let mut comp = vec![start];
        seen[start] = true;
        let mut q = 0;
        while q < comp.len() {
            let p = comp[q];
            q += 1;
            for &(o, _) in &adj[p] {
                if !seen[o] {
                    seen[o] = true;
                    comp.push(o);
                }
            }
        }
        if comp.len() < min_points || comp.len() < 2 {
            isolated.extend(comp);
            continue;
        }
        comp.sort_unstable();
        let mut comp_links: Vec<usize> = comp
            .iter()
            .flat_map(|&p| adj[p].iter().map(|&(_, l)| l))
            .collect();
        comp_links.sort_unstable();
        comp_links.dedup();
        let branched = comp.iter().any(|&p| adj[p].len() > 2);
        if branched {
            out.push(Contour {
                key_points: comp,
                links: comp_links,
                closed: false,
                branched: true,
                polyline: None,
            });
            continue;
        }
        // A chain starts at an end (degree 1); a cycle at its smallest point.
        let first = comp
            .iter()
            .copied()
            .find(|&p| adj[p].len() == 1)
            .unwrap_or(comp[0]);
        let closed = adj[first].len() == 2;
        let mut order = vec![first];
        let mut chain_links = Vec::new();
        let mut prev_link = usize::MAX;
        let mut cur = first;
        loop {
            let next = adj[cur].iter().find(|&&(_, l)| l != prev_link).copied();
            let Some((o, l)) = next else { break };
            if chain_links.contains(&l) {
                break;
            }
            chain_links.push(l);
            prev_link = l;
            if o == first {
                break;
            }
            order.push(o);
            cur = o;
        }
        let mut polyline: Vec<[f64; 2]> = Vec::new();
        for (step, &l) in chain_links.iter().enumerate() {
            let from = order[step];
            let link = &links[l];
            let Some(path) = &link.path else { continue };
            let mut pts = path.clone();
            if link.pair[0] != from {
                pts.reverse();
            }
            if !polyline.is_empty() {
                pts.remove(0);
            }
            polyline.extend(pts);
        }
        out.push(Contour {
            key_points: order,
            links: chain_links,
            closed,
            branched: false,
            polyline: Some(polyline),
        });
    }
    out.sort_by_key(|c| c.key_points.iter().copied().min().unwrap_or(0));
    isolated.sort_unstable();
    (out, isolated)
}

/// The median over the key points of the physical distance to their
/// nearest other key point (the default interpolation width `σ`).
pub fn typical_spacing(grid: &Grid, points: &[[f64; 2]]) -> f64 {
    let h = grid.spacing();
    // Nearest neighbours by a sweep over the points sorted by row: the scan
    // outwards from a point stops once the row gap alone exceeds the best.
    let mut order: Vec<usize> = (0..points.len()).collect();
    order.sort_by(|&a, &b| points[a][0].total_cmp(&points[b][0]));
    let d = |a: usize, b: usize| {
        (((points[a][0] - points[b][0]) * h[0]).powi(2)
            + ((points[a][1] - points[b][1]) * h[1]).powi(2))
        .sqrt()
    };
    let mut nn: Vec<f64> = Vec::with_capacity(points.len());
    for (r, &a) in order.iter().enumerate() {
        let mut best = f64::INFINITY;
        for &b in order[r + 1..].iter() {
            if (points[b][0] - points[a][0]) * h[0] > best {
                break;
            }
            let v = d(a, b);
            if v > 0.0 {
                best = best.min(v);
            }
        }
        for &b in order[..r].iter().rev() {
            if (points[a][0] - points[b][0]) * h[0] > best {
                break;
            }
            let v = d(a, b);
            if v > 0.0 {
                best = best.min(v);
            }
        }
        if best.is_finite() {
            nn.push(best);
        }
    }
    if nn.is_empty() {
        return h[0].max(h[1]);
    }
    nn.sort_by(f64::total_cmp);
    nn[nn.len() / 2]
}

/// The oriented tensor field of the module docs: `M = W² (τ τᵀ / a² + τ^⊥
/// τ^⊥ᵀ)` from the Gaussian average (width `sigma`, cut at `3σ`) of the key
/// points' orientation tensors; walls of the cost stay walls.
pub fn oriented_metric(
    grid: &Grid,
    cost: &IsotropicCost<'_>,
    points: &[[f64; 2]],
    angles: &[f64],
    anisotropy: f64,
    sigma: f64,
    control: &Control<'_>,
) -> Result<TensorField, GroupingError> {
    if grid.ndim() != 2 {
        return Err(GroupingError::NotTwoD(grid.ndim()));
    }
    if angles.len() != points.len() {
        return Err(GroupingError::Orientations(format!(
            "{} angles for {} key points",
            angles.len(),
            points.len()
        )));
    }
    if !(sigma.is_finite() && sigma > 0.0) {
        return Err(option("spread", format!("{sigma} must be finite and > 0")));
    }
    let s = grid.shape();
    let h = grid.spacing();
    let (n0, n1) = (s[0], s[1]);
    let reach = 3.0 * sigma;
    // Buckets of side `reach` (physical) over the key points.
    let bucket = [(reach / h[0]).max(1.0), (reach / h[1]).max(1.0)];
    let nb = [
        (n0 as f64 / bucket[0]).ceil() as usize + 1,
        (n1 as f64 / bucket[1]).ceil() as usize + 1,
    ];
    let mut buckets: Vec<Vec<usize>> = vec![Vec::new(); nb[0] * nb[1]];
    for (k, p) in points.iter().enumerate() {
        let b0 = ((p[0] / bucket[0]) as usize).min(nb[0] - 1);
        let b1 = ((p[1] / bucket[1]) as usize).min(nb[1] - 1);
        buckets[b0 * nb[1] + b1].push(k);
    }
    let tangents: Vec<[f64; 3]> = angles
        .iter()
        .map(|&t| {
            let (sn, cs) = t.sin_cos();
            [cs * cs, cs * sn, sn * sn]
        })
        .collect();
    let mut values = Vec::with_capacity(grid.len() * 3);
    let mut walls = vec![false; grid.len()];
    for r in 0..n0 {
        if r % 32 == 0 && control.is_cancelled() {
            return Err(GroupingError::Cancelled);
        }
        let br = (r as f64 / bucket[0]) as usize;
        for c in 0..n1 {
            let i = r * n1 + c;
            let w = cost.at(i);
            if !w.is_finite() {
                walls[i] = true;
                values.extend_from_slice(&[1.0, 0.0, 1.0]);
                continue;
            }
            let bc = (c as f64 / bucket[1]) as usize;
            let mut acc = [0.0; 3];
            let mut total = 0.0;
            for b0 in br.saturating_sub(1)..=(br + 1).min(nb[0] - 1) {
                for b1 in bc.saturating_sub(1)..=(bc + 1).min(nb[1] - 1) {
                    for &k in &buckets[b0 * nb[1] + b1] {
                        let p = points[k];
                        let d2 =
                            ((r as f64 - p[0]) * h[0]).powi(2) + ((c as f64 - p[1]) * h[1]).powi(2);
                        if d2 > reach * reach {
                            continue;
                        }
                        let wk = (-d2 / (2.0 * sigma * sigma)).exp();
                        for (a, t) in acc.iter_mut().zip(&tangents[k]) {
                            *a += wk * t;
                        }
                        total += wk;
                    }
                }
            }
            let (tau, coherence) = if total > 0.0 {
                let [a, b, d] = acc.map(|v| v / total);
                let coh = ((a - d).powi(2) + 4.0 * b * b).sqrt().min(1.0);
                let phi = 0.5 * (2.0 * b).atan2(a - d);
                ([phi.cos(), phi.sin()], coh)
            } else {
                ([1.0, 0.0], 0.0)
            };
            let along = 1.0 / (1.0 + (anisotropy - 1.0) * coherence).powi(2);
            // W² (along τ τᵀ + τ⊥ τ⊥ᵀ) = W² (Id − (1 − along) τ τᵀ).
            let w2 = w * w;
            let f = 1.0 - along;
            values.push(w2 * (1.0 - f * tau[0] * tau[0]));
            values.push(-w2 * f * tau[0] * tau[1]);
            values.push(w2 * (1.0 - f * tau[1] * tau[1]));
        }
    }
    let field = TensorField::from_components(grid, values)
        .map_err(|e| GroupingError::Solve(e.to_string()))?;
    if walls.iter().any(|&w| w) {
        field
            .with_walls(grid, walls)
            .map_err(|e| GroupingError::Solve(e.to_string()))
    } else {
        Ok(field)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::AtomicBool;

    fn line_problem(points: Vec<[f64; 2]>) -> GroupingProblem<'static> {
        GroupingProblem {
            grid: Grid::unit(&[41, 61]).unwrap(),
            cost: IsotropicCost::constant(1.0).unwrap(),
            key_points: points,
            orientations: None,
        }
    }

    /// Two points in a constant cost: the Voronoi boundary is the
    /// perpendicular bisector, the saddle is the midpoint, and `U_i + U_j`
    /// there is the Euclidean distance. Off the grid's nodes on purpose.
    #[test]
    fn saddle_of_two_points_is_the_midpoint_at_their_distance() {
        let (p, q) = ([10.3, 12.0], [27.7, 41.4]);
        let out = group(
            &line_problem(vec![p, q]),
            &GroupingOptions::default(),
            &Control::new(),
        )
        .unwrap();
        assert_eq!(out.links.len(), 1);
        let link = &out.links[0];
        let d = ((q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2)).sqrt();
        let mid = [0.5 * (p[0] + q[0]), 0.5 * (p[1] + q[1])];
        let err = (link.cost - d).abs();
        let off = ((link.saddle[0] - mid[0]).powi(2) + (link.saddle[1] - mid[1]).powi(2)).sqrt();
        assert!(
            err < 0.02,
            "cost {} vs distance {d}: error {err}",
            link.cost
        );
        // The boundary is sampled at edge crossings: within a cell of the midpoint.
        assert!(off < 1.0, "saddle {:?} vs midpoint {mid:?}", link.saddle);
        // The two are linked; the path runs from p to q through the saddle.
        assert!(link.kept);
        let path = link.path.as_ref().unwrap();
        assert!((path[0][0] - p[0]).abs() < 1e-9 && (path[0][1] - p[1]).abs() < 1e-9);
        let last = path.last().unwrap();
        assert!((last[0] - q[0]).abs() < 1e-9 && (last[1] - q[1]).abs() < 1e-9);
        let len = link.path_length.unwrap();
        assert!((len - d).abs() < 0.05 * d, "path length {len} vs {d}");
        assert_eq!(out.contours.len(), 1);
        assert_eq!(out.contours[0].key_points, vec![0, 1]);
        assert!(!out.contours[0].closed);
    }

    /// On a node-aligned pair the saddle is exactly the midpoint cell.
    #[test]
    fn aligned_saddle_is_exact() {
        let out = group(
            &line_problem(vec![[20.0, 10.0], [20.0, 30.0]]),
            &GroupingOptions::default(),
            &Control::new(),
        )
        .unwrap();
        let link = &out.links[0];
        assert!((link.cost - 20.0).abs() < 1e-9, "{}", link.cost);
        assert!((link.saddle[0] - 20.0).abs() < 1e-9 && (link.saddle[1] - 20.0).abs() < 1e-9);
    }

    /// Six points on a circle: one closed contour in cycle order; a seventh
    /// far away is clutter.
    #[test]
    fn circle_is_closed_and_far_point_isolated() {
        let mut pts: Vec<[f64; 2]> = (0..6)
            .map(|k| {
                let a = k as f64 * std::f64::consts::TAU / 6.0;
                [20.0 + 10.0 * a.cos(), 20.0 + 10.0 * a.sin()]
            })
            .collect();
        pts.push([20.0, 58.0]);
        let out = group(
            &line_problem(pts),
            &GroupingOptions::default(),
            &Control::new(),
        )
        .unwrap();
        assert_eq!(out.contours.len(), 1, "{:?}", out.contours);
        let c = &out.contours[0];
        assert!(c.closed);
        assert_eq!(c.key_points, vec![0, 1, 2, 3, 4, 5]);
        let poly = c.polyline.as_ref().unwrap();
        assert_eq!(poly.first(), poly.last());
        assert_eq!(out.isolated, vec![6]);
    }

    #[test]
    fn refusals_name_what_is_wrong() {
        let opts = GroupingOptions::default();
        let c = Control::new();
        assert_eq!(
            group(&line_problem(vec![[1.0, 1.0]]), &opts, &c).unwrap_err(),
            GroupingError::TooFewPoints(1)
        );
        assert!(matches!(
            group(&line_problem(vec![[1.0, 1.0], [41.0, 1.0]]), &opts, &c),
            Err(GroupingError::KeyPoint { index: 1, .. })
        ));
        let mut p = line_problem(vec![[1.0, 1.0], [4.0, 1.0]]);
        p.orientations = Some(vec![0.0]);
        assert!(matches!(
            group(&p, &opts, &c),
            Err(GroupingError::Orientations(_))
        ));
        let mut bad = opts.clone();
        bad.selection.ratio = 0.5;
        assert!(matches!(
            group(&line_problem(vec![[1.0, 1.0], [4.0, 1.0]]), &bad, &c),
            Err(GroupingError::Option { field: "ratio", .. })
        ));
    }

    #[test]
    fn a_raised_flag_cancels() {
        let flag = AtomicBool::new(true);
        let c = Control::new().with_cancel(&flag);
        let r = group(
            &line_problem(vec![[1.0, 1.0], [30.0, 40.0]]),
            &GroupingOptions::default(),
            &c,
        );
        assert_eq!(r.unwrap_err(), GroupingError::Cancelled);
    }

    /// The oriented metric: cheap along the tangent where orientations
    /// agree (ratio `A` of the costs), isotropic far from every key point.
    #[test]
    fn oriented_metric_is_cheap_along_the_tangent() {
        let grid = Grid::unit(&[40, 80]).unwrap();
        let cost = IsotropicCost::constant(2.0).unwrap();
        // Points along axis 1, tangent along axis 1 (θ = π/2).
        let pts: Vec<[f64; 2]> = (0..8).map(|k| [10.0, 5.0 + 10.0 * k as f64]).collect();
        let angles = vec![std::f64::consts::FRAC_PI_2; 8];
        let m = oriented_metric(&grid, &cost, &pts, &angles, 4.0, 8.0, &Control::new()).unwrap();
        let at = m.at(10 * 80 + 40);
        // Along axis 1: W / A = 0.5, so m11 = 0.25; across: W² = 4.
        assert!((at[2] - 0.25).abs() < 1e-9, "{at:?}");
        assert!((at[0] - 4.0).abs() < 1e-9 && at[1].abs() < 1e-9, "{at:?}");
        let far = m.at(39 * 80 + 40);
        assert!(
            (far[0] - 4.0).abs() < 1e-9 && (far[2] - 4.0).abs() < 1e-9,
            "{far:?}"
        );
    }
}
