//! Farthest-point sampling of a 2D or 3D grid under an isotropic cost
//! (Peyré & Cohen 2006; the monograph's section 4.2).
//!
//! # Math
//!
//! Given samples `S = {s_0, ..., s_{k-1}}`, let `U_S(x) = min_i d_W(x, s_i)`
//! be the geodesic distance to the set (`|∇U_S| = W`, `U_S = 0` on `S`) and
//! `ℓ_S(x)` the index of the nearest sample (the geodesic Voronoi label).
//! Farthest-point sampling adds
//!
//! ```text
//! s_k = argmax_x U_S(x)        (over the cells with a finite U_S)
//! ```
//!
//! and the covering radius after `k + 1` samples is `r_k = max_x U_{S ∪ {s_k}}(x)`.
//! Since `U_{S ∪ {s}} = min(U_S, d_W(·, s))`, `r_k` never increases. For a
//! constant cost on a domain of area `A` the best covering of `N` points is
//! the hexagonal one, of radius `r_hex = sqrt(2A / (3 sqrt(3) N))`; farthest
//! points are within a factor 2 of the best covering (Gonzalez 1985) and in
//! practice close to `r_hex`.
//!
//! # Local fronts
//!
//! Adding `s` does not solve the eikonal equation again: `U` can only go down,
//! and only inside the new Voronoi cell of `s`. A fast march is started at
//! `s` (`U(s) = 0`) over the current map: a neighbour `j` of a frozen cell is
//! recomputed with the first-order upwind update of
//! [`crate::numerics::eikonal`] (the general update with labels, the one the
//! multi-source fast marching uses, applied to the current values: a cell
//! a front has labelled is known; its arithmetic is the first-order
//! kernel's, `first_order_by`) and enters the band only if the new value is
//! below its current `U` (by more than a relative `1e-12`, so that rounding
//! does not reopen cells). The march stops when the band is empty: it visits
//! the cells whose value decreases and their neighbours, not the grid. The
//! result is, up to rounding, the first-order fast-marching solution from
//! all the samples at once: the cells a front did not reopen already satisfy
//! the discrete equation with the new sample. The exception is a few cells
//! next to Voronoi boundaries: the multi-source update takes the smallest
//! of one update per label of the known neighbours, which is not monotone
//! when a neighbour changes label, and a cell the new sample does not lower
//! keeps its value where the full march would compute a slightly larger one
//! (`tests/sampling.rs` measures it: 1-3 % of the cells, nearly all on a
//! Voronoi boundary and mostly lower, by less than half a step `h W`). `U`
//! never increases from one sample to the next.
//!
//! The farthest cell is kept per chunk of 64 cells in a tournament tree
//! (`farthest_cell`): a front marks the chunks it lowers and each is
//! scanned once when the front ends, `O(64 + log n)` per chunk touched
//! instead of a heap sift per visited cell. Sampling `k` points of a grid of
//! `n` cells visits about `n log k` cells in all on a well-spread set.
//!
//! # Clustered sampling
//!
//! [`SamplingMethod::Clustered`] trades the exact farthest cell for speed:
//! farthest points on the grid of blocks of cells, then one front per
//! sample from the coarse map's bound (`super::clustered`), about 2.5 full
//! maps instead of 10 for `10⁴` samples on a 1024² grid.
//!
//! # Conventions
//!
//! Samples are cells, in index coordinates (axis 0 first). Cells that cannot
//! be reached from the samples (walls, components cut off by walls) keep
//! `U = +inf` and label `-1` and never become samples. Without seeds the
//! first sample is the cell farthest from the first open cell in C order (one
//! extra march).

use super::farthest_cell::FarthestCell;
use crate::numerics::control::Control;
use crate::numerics::eikonal::update::{first_order_by, neighbour_labels, one_axis_root, Stencil};
use crate::numerics::grid::Grid;
use crate::numerics::heap::{IndexedHeap, ABSENT, FIRST_TAG};
use crate::numerics::metric::IsotropicCost;

/// Band tag: the cell's value was fixed by the current front.
const DONE: u32 = FIRST_TAG;
/// Band tag: a wall, never entered.
const WALL: u32 = FIRST_TAG + 1;
/// Cancellation is polled every this many cells of a front (and per sample).
const CANCEL_EVERY: usize = 4096;
/// A cell reopens only if its value goes below `IMPROVE ×` its current value.
const IMPROVE: f64 = 1.0 - 1e-12;

/// Options of [`farthest_point_sampling`]. Give `count`, `radius` or both.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SamplingOptions {
    /// Stop once this many samples (seeds included) are placed.
    pub count: Option<usize>,
    /// Stop once every reachable cell is within this distance of a sample.
    pub radius: Option<f64>,
    /// Fixed first samples: cells in index coordinates (axis 0 first), kept
    /// in this order; they count towards `count`.
    pub seeds: Vec<Vec<usize>>,
    /// Exact farthest points (the default) or farthest points of blocks of
    /// cells ([`super::clustered`]); under a tensor metric only `Exact` and
    /// `Auto` (which is then exact) are accepted.
    pub method: SamplingMethod,
}

/// How [`farthest_point_sampling`] places its samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SamplingMethod {
    /// Each sample is the cell farthest from the previous ones: a local
    /// front per sample, `n (ln k + γ)` cell visits for `k` samples.
    #[default]
    Exact,
    /// Farthest points of a grid coarser by a block of `b` cells per axis,
    /// then one front per sample on the fine grid started on an upper bound
    /// ([`super::clustered`]): about `1.3 n` visits plus the coarse
    /// sampling's `n (ln k + γ) / b^d`. The covering radius is within a few
    /// per cent of exact sampling's when blocks hold at least 8 cells per
    /// sample.
    Clustered,
    /// `Clustered` when the cost has no walls, varies by at most a factor 2
    /// inside a block, and the grid holds at least 8 blocks of 3 (or 2)
    /// cells per axis per sample, with 64 samples or more; else `Exact`.
    Auto,
}

/// Why sampling stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SamplingStop {
    /// `count` samples were placed.
    Count,
    /// Every reachable cell is within `radius` of a sample.
    Radius,
    /// Every reachable cell is a sample.
    Exhausted,
}

/// The samples, their distance map and Voronoi labels.
#[derive(Debug, Clone, PartialEq)]
pub struct GridSampling {
    /// Sample cells in index coordinates (axis 0 first), in the order placed
    /// (seeds first).
    pub samples: Vec<Vec<usize>>,
    /// `U`: distance to the nearest sample per cell (C order), `+inf` where
    /// not reached.
    pub distance: Vec<f64>,
    /// Index in `samples` of the nearest sample per cell, `-1` where not reached.
    pub labels: Vec<i32>,
    /// `radii[k]`: the covering radius (largest finite `U`) after `k + 1`
    /// samples. Under [`SamplingMethod::Clustered`] the entries of the coarse
    /// samples are the coarse grid's radii, except the last of them, which is
    /// the grid's (so they may rise once there).
    pub radii: Vec<f64>,
    /// The final covering radius (the last of `radii`).
    pub covering_radius: f64,
    /// Why it stopped.
    pub stop: SamplingStop,
    /// Cells fixed by all the local fronts together (the work done).
    pub visited: usize,
    /// How the clustered method ran, `None` for exact sampling.
    pub clustered: Option<ClusteredReport>,
}

/// What [`SamplingMethod::Clustered`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ClusteredReport {
    /// Cells per block along each axis (`b`).
    pub block: usize,
    /// Cells of the coarse grid.
    pub coarse_cells: usize,
    /// Cells the upper bound kept every front out of, marched again from
    /// their neighbours (0 when the bound held everywhere).
    pub repaired: usize,
    /// Samples added by exact fronts on the fine grid after the coarse ones
    /// (to reach the radius, or the count when the coarse grid ran out).
    pub refined: usize,
}

/// Why sampling was refused or interrupted.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SamplingError {
    /// Neither a count nor a radius.
    #[error("give a count, a radius or both")]
    NoStopRule,
    /// The count is 0 or larger than the number of cells.
    #[error("count {count} must be between 1 and the number of cells ({cells})")]
    Count {
        /// The count given.
        count: usize,
        /// Cells of the grid.
        cells: usize,
    },
    /// Fewer samples asked for than seeds given.
    #[error("count {count} is smaller than the number of seeds ({seeds})")]
    FewerThanSeeds {
        /// The count given.
        count: usize,
        /// Seeds given.
        seeds: usize,
    },
    /// The radius is not finite and positive.
    #[error("radius {0} must be finite and > 0")]
    Radius(f64),
    /// A seed is malformed, outside the grid, on a wall or repeated.
    #[error("seeds[{index}]: {reason}")]
    Seed {
        /// Position in [`SamplingOptions::seeds`].
        index: usize,
        /// What is wrong with it.
        reason: String,
    },
    /// Every cell is a wall: there is nothing to sample.
    #[error("every cell is a wall")]
    NoOpenCell,
    /// The tensor field's dimension is not the grid's.
    #[error("the tensor field is {field}D but the grid is {grid}D")]
    Dimension {
        /// The field's dimension.
        field: usize,
        /// The grid's dimension.
        grid: usize,
    },
    /// A method the metric does not support.
    #[error("{0}")]
    Method(&'static str),
    /// The caller raised the cancel flag.
    #[error("cancelled")]
    Cancelled,
}

/// Farthest-point sampling of `grid` under `cost`; see the module docs.
///
/// Polls `control` per sample and every 4096 cells of a front; reports
/// `samples / count` as progress (with a radius only, `(radius / r)^d`
/// for the current covering radius `r` in `d` dimensions).
///
/// # Examples
/// ```
/// use geodex::numerics::sampling::{farthest_point_sampling, SamplingOptions};
/// use geodex::numerics::{Control, Grid, IsotropicCost};
/// let grid = Grid::unit(&[32, 32])?;
/// let options = SamplingOptions { count: Some(10), ..Default::default() };
/// let s = farthest_point_sampling(&grid, &IsotropicCost::constant(1.0)?, &options, &Control::new())?;
/// assert_eq!(s.samples.len(), 10);
/// assert!(s.radii.windows(2).all(|w| w[1] <= w[0]));
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn farthest_point_sampling(
    grid: &Grid,
    cost: &IsotropicCost<'_>,
    options: &SamplingOptions,
    control: &Control<'_>,
) -> Result<GridSampling, SamplingError> {
    check_options(options, grid.len())?;
    if let Some(block) = super::clustered::block_for(grid, cost, options, control) {
        return super::clustered::clustered_sampling(grid, cost, options, block, control);
    }
    sample_with(grid, Sampler::new(grid, cost), options, control)
}

/// What the farthest-point driver ([`sample_with`]) and the geodesic
/// Delaunay repair need of a local-front sampler: the isotropic [`Sampler`]
/// and the Riemannian one of [`super::tensor_farthest`].
pub(crate) trait Front {
    /// `U` per cell.
    fn distance(&self) -> &[f64];
    /// Labels per cell.
    fn labels(&self) -> &[i32];
    /// The largest finite `U` (0 before any sample).
    fn covering_radius(&self) -> f64;
    /// The cell with the largest finite `U`.
    fn farthest(&self) -> Option<usize>;
    /// Forgets every sample.
    fn clear(&mut self);
    /// Adds the sample `s` with label `label` by a local front that only lowers `U`.
    fn add(&mut self, s: usize, label: i32, control: &Control<'_>) -> Result<(), SamplingError>;
    /// Hands back `U`, the labels and the cells visited.
    fn into_parts(self) -> (Vec<f64>, Vec<i32>, usize);
    /// True if cell `i` is a wall.
    fn is_wall(&self, i: usize) -> bool;
}

impl Front for Sampler<'_> {
    fn distance(&self) -> &[f64] {
        &self.u
    }
    fn labels(&self) -> &[i32] {
        &self.labels
    }
    fn covering_radius(&self) -> f64 {
        Sampler::covering_radius(self)
    }
    fn farthest(&self) -> Option<usize> {
        Sampler::farthest(self)
    }
    fn clear(&mut self) {
        Sampler::clear(self);
    }
    fn add(&mut self, s: usize, label: i32, control: &Control<'_>) -> Result<(), SamplingError> {
        Sampler::add(self, s, label, control)
    }
    fn into_parts(self) -> (Vec<f64>, Vec<i32>, usize) {
        Sampler::into_parts(self)
    }
    fn is_wall(&self, i: usize) -> bool {
        self.cost.is_wall(i)
    }
}

/// The farthest-point loop over any local-front sampler `s` (fresh, of
/// `grid`'s size): seeds, the first sample, then the farthest cell until
/// the count or the radius. The options must have passed [`check_options`].
pub(crate) fn sample_with<F: Front>(
    grid: &Grid,
    mut s: F,
    options: &SamplingOptions,
    control: &Control<'_>,
) -> Result<GridSampling, SamplingError> {
    let n = grid.len();
    let first_open = (0..n)
        .find(|&i| !s.is_wall(i))
        .ok_or(SamplingError::NoOpenCell)?;
    let seeds = seed_cells(grid, |i| s.is_wall(i), &options.seeds)?;
    let mut samples: Vec<usize> = Vec::new();
    let mut radii: Vec<f64> = Vec::new();
    for i in seeds {
        if control.is_cancelled() {
            return Err(SamplingError::Cancelled);
        }
        s.add(i, samples.len() as i32, control)?;
        samples.push(i);
        radii.push(s.covering_radius());
        report_progress(grid, options, control, samples.len(), s.covering_radius());
    }
    if samples.is_empty() {
        // The first sample: the cell farthest from the first open cell.
        s.add(first_open, 0, control)?;
        let first = s.farthest().unwrap_or(first_open);
        s.clear();
        s.add(first, 0, control)?;
        samples.push(first);
        radii.push(s.covering_radius());
        report_progress(grid, options, control, 1, s.covering_radius());
    }
    finish(grid, s, samples, radii, options, control)
}

/// Reports `placed / count` (with a radius only, `(radius / r)^d` for the
/// covering radius `r` in `d` dimensions).
fn report_progress(
    grid: &Grid,
    options: &SamplingOptions,
    control: &Control<'_>,
    placed: usize,
    r: f64,
) {
    let fraction = match (options.count, options.radius) {
        (Some(c), _) => placed as f64 / c as f64,
        (None, Some(radius)) if r > 0.0 => (radius / r).powi(grid.ndim() as i32),
        _ => 1.0,
    };
    control.report(fraction.clamp(0.0, 1.0));
}

/// The linear indices of the seeds, checked: inside the grid, not on a
/// wall, not repeated.
pub(crate) fn seed_cells(
    grid: &Grid,
    is_wall: impl Fn(usize) -> bool,
    seeds: &[Vec<usize>],
) -> Result<Vec<usize>, SamplingError> {
    let mut cells: Vec<usize> = Vec::with_capacity(seeds.len());
    for (index, seed) in seeds.iter().enumerate() {
        let bad = |reason: String| SamplingError::Seed { index, reason };
        let idx = grid.index3(seed).map_err(|e| bad(e.to_string()))?;
        if !grid.contains_index3(idx) {
            return Err(bad(format!(
                "cell {seed:?} is outside the grid of shape {:?}",
                grid.shape()
            )));
        }
        let i = grid.linear(idx);
        if is_wall(i) {
            return Err(bad(format!("cell {seed:?} is a wall")));
        }
        if cells.contains(&i) {
            return Err(bad(format!("cell {seed:?} is already a seed")));
        }
        cells.push(i);
    }
    Ok(cells)
}

/// Adds the farthest cell until the count or the radius (the loop of
/// [`sample_with`], also the refinement of the clustered method), then
/// hands back the sampling.
pub(crate) fn finish<F: Front>(
    grid: &Grid,
    mut s: F,
    mut samples: Vec<usize>,
    mut radii: Vec<f64>,
    options: &SamplingOptions,
    control: &Control<'_>,
) -> Result<GridSampling, SamplingError> {
    let target = options.count.unwrap_or(usize::MAX);
    let stop = loop {
        let r = s.covering_radius();
        if samples.len() >= target {
            break SamplingStop::Count;
        }
        if options.radius.is_some_and(|radius| r <= radius) {
            break SamplingStop::Radius;
        }
        let Some(next) = s.farthest().filter(|_| r > 0.0) else {
            break SamplingStop::Exhausted;
        };
        if control.is_cancelled() {
            return Err(SamplingError::Cancelled);
        }
        s.add(next, samples.len() as i32, control)?;
        samples.push(next);
        radii.push(s.covering_radius());
        report_progress(grid, options, control, samples.len(), s.covering_radius());
    };
    control.report(1.0);
    let covering_radius = s.covering_radius();
    let ndim = grid.ndim();
    let (distance, labels, visited) = s.into_parts();
    Ok(GridSampling {
        samples: samples
            .into_iter()
            .map(|i| grid.unravel(i)[3 - ndim..].to_vec())
            .collect(),
        distance,
        labels,
        radii,
        covering_radius,
        stop,
        visited,
        clustered: None,
    })
}

pub(crate) fn check_options(options: &SamplingOptions, cells: usize) -> Result<(), SamplingError> {
    if options.count.is_none() && options.radius.is_none() {
        return Err(SamplingError::NoStopRule);
    }
    if let Some(count) = options.count {
        if count == 0 || count > cells {
            return Err(SamplingError::Count { count, cells });
        }
        if count < options.seeds.len() {
            return Err(SamplingError::FewerThanSeeds {
                count,
                seeds: options.seeds.len(),
            });
        }
    }
    if let Some(r) = options.radius {
        if !(r.is_finite() && r > 0.0) {
            return Err(SamplingError::Radius(r));
        }
    }
    Ok(())
}

/// The working state: `U`, labels, the band of the current front and the
/// heap of the farthest cells. Crate-visible so that the geodesic Delaunay
/// repair and Lloyd relaxation add samples with the same local fronts.
pub(crate) struct Sampler<'a> {
    st: Stencil,
    cost: &'a IsotropicCost<'a>,
    /// Distance to the samples so far (`+inf` where not reached).
    u: Vec<f64>,
    /// Nearest sample (`-1` where not reached).
    labels: Vec<i32>,
    /// Label of each cell while it waits in the band.
    band_label: Vec<i32>,
    /// The band of the current front; tags `DONE` and `WALL`.
    band: IndexedHeap,
    /// Every reached cell keyed by `−U`: the top is the farthest cell.
    far: FarthestCell,
    /// Cells fixed by the current front (their `DONE` tags are cleared after it).
    touched: Vec<u32>,
    visited: usize,
    /// Whether fronts keep `far` up to date (not while `U` is a bound).
    track_far: bool,
    /// A uniform cost and its one-axis roots per axis.
    uniform: Option<(f64, [f64; 3])>,
    /// The stencil's trailing axes (2 or 3), for unrolled updates.
    trailing: Option<usize>,
}

impl<'a> Sampler<'a> {
    pub(crate) fn new(grid: &Grid, cost: &'a IsotropicCost<'a>) -> Self {
        let n = grid.len();
        let mut band = IndexedHeap::new(n);
        if !cost.is_uniform() {
            for i in 0..n {
                if cost.is_wall(i) {
                    band.tag(i as u32, WALL);
                }
            }
        }
        let st = Stencil::new(grid);
        let uniform = cost.uniform_value().map(|w| {
            let mut roots = [0.0; 3];
            for (k, r) in roots.iter_mut().enumerate() {
                *r = one_axis_root(&st, k, w);
            }
            (w, roots)
        });
        let trailing = st.trailing().filter(|&a| a == 2 || a == 3);
        Self {
            st,
            cost,
            u: vec![f64::INFINITY; n],
            labels: vec![-1; n],
            band_label: vec![-1; n],
            band,
            far: FarthestCell::new(n),
            touched: Vec::new(),
            visited: 0,
            track_far: true,
            uniform,
            trailing,
        }
    }

    /// Resumes from a finished sampling's distance and labels (of `grid`'s size).
    pub(crate) fn resume(
        grid: &Grid,
        cost: &'a IsotropicCost<'a>,
        distance: Vec<f64>,
        labels: Vec<i32>,
    ) -> Self {
        let mut s = Self::new(grid, cost);
        s.far.rebuild(&distance);
        s.u = distance;
        s.labels = labels;
        s
    }

    /// `U` per cell.
    pub(crate) fn distance(&self) -> &[f64] {
        &self.u
    }

    /// Labels per cell.
    pub(crate) fn labels(&self) -> &[i32] {
        &self.labels
    }

    /// Hands back `U` and the labels.
    pub(crate) fn into_parts(self) -> (Vec<f64>, Vec<i32>, usize) {
        (self.u, self.labels, self.visited)
    }

    /// The largest finite `U` (0 before any sample).
    pub(crate) fn covering_radius(&self) -> f64 {
        self.far.peek().map_or(0.0, |(_, u)| u)
    }

    /// The cell with the largest finite `U`.
    fn farthest(&self) -> Option<usize> {
        self.far.peek().map(|(i, _)| i)
    }

    /// Forgets every sample.
    pub(crate) fn clear(&mut self) {
        self.u.fill(f64::INFINITY);
        self.labels.fill(-1);
        self.far.clear();
    }

    /// Adds the sample `s` (an open cell with `U(s) > 0`) with label `label`:
    /// a fast march from `s` restricted to the cells whose value it lowers.
    pub(crate) fn add(
        &mut self,
        s: usize,
        label: i32,
        control: &Control<'_>,
    ) -> Result<(), SamplingError> {
        self.band.push(s as u32, 0.0);
        self.band_label[s] = label;
        self.march(control)
    }

    /// A sampler of `grid` whose `U` starts on `bound`, an upper bound of the
    /// distance to samples not placed yet, without labels: fronts
    /// ([`Sampler::add`]) enter a cell only below its bound, and a cell
    /// counts as known to the upwind update once a front has labelled it.
    /// The farthest cell is not tracked until [`Sampler::settle`].
    pub(crate) fn from_bound(grid: &Grid, cost: &'a IsotropicCost<'a>, bound: Vec<f64>) -> Self {
        let mut s = Self::new(grid, cost);
        s.u = bound;
        s.track_far = false;
        s
    }

    /// Ends the fronts started on a bound: the open cells no front labelled
    /// (the bound was below their distance) are marched again from their
    /// labelled neighbours, cells no sample reaches get `U = +inf`, and the
    /// farthest cell is tracked again. Returns the cells marched again.
    pub(crate) fn settle(&mut self, control: &Control<'_>) -> Result<usize, SamplingError> {
        let mut holes = Vec::new();
        for (i, (u, &l)) in self.u.iter_mut().zip(&self.labels).enumerate() {
            if i % (16 * CANCEL_EVERY) == 0 && control.is_cancelled() {
                return Err(SamplingError::Cancelled);
            }
            if l < 0 && *u < f64::INFINITY {
                *u = f64::INFINITY;
                holes.push(i);
            }
        }
        let (shape, strides) = (self.st.shape, self.st.strides);
        for &j in &holes {
            if self.cost.is_wall(j) {
                continue;
            }
            let idx = self.st.unravel(j);
            let next_to_known = (0..3).any(|k| {
                shape[k] > 1
                    && ((idx[k] > 0 && self.labels[j - strides[k]] >= 0)
                        || (idx[k] + 1 < shape[k] && self.labels[j + strides[k]] >= 0))
            });
            if next_to_known {
                self.relax(j);
            }
        }
        let before = self.visited;
        self.march(control)?;
        self.track_far = true;
        self.far.rebuild(&self.u);
        Ok(self.visited - before)
    }

    /// Runs the band to its end: each cell popped is frozen with its value
    /// and label, and its neighbours are recomputed.
    fn march(&mut self, control: &Control<'_>) -> Result<(), SamplingError> {
        let (shape, strides) = (self.st.shape, self.st.strides);
        while let Some((id, v)) = self.band.pop() {
            if self.touched.len() % CANCEL_EVERY == CANCEL_EVERY - 1 && control.is_cancelled() {
                self.band.clear();
                self.end_front();
                return Err(SamplingError::Cancelled);
            }
            let i = id as usize;
            self.u[i] = v;
            self.labels[i] = self.band_label[i];
            self.band.tag(id, DONE);
            self.touched.push(id);
            if self.track_far {
                self.far.mark(i);
            }
            let idx = self.st.unravel(i);
            for k in 0..3 {
                if shape[k] < 2 {
                    continue;
                }
                if idx[k] > 0 {
                    self.relax(i - strides[k]);
                }
                if idx[k] + 1 < shape[k] {
                    self.relax(i + strides[k]);
                }
            }
        }
        self.end_front();
        Ok(())
    }

    /// Recomputes cell `j` from the current values; it enters the band if
    /// its value goes down.
    fn relax(&mut self, j: usize) {
        let state = self.band.state(j as u32);
        if state == DONE || state == WALL {
            return;
        }
        let jdx = self.st.unravel(j);
        let u = &self.u;
        let (st, cost, uniform, labels) = (&self.st, self.cost, self.uniform, &self.labels);
        let found = match self.trailing {
            Some(2) => label_update::<2>(st, j, jdx, cost, uniform, u, labels),
            Some(3) => label_update::<3>(st, j, jdx, cost, uniform, u, labels),
            _ => label_update::<0>(st, j, jdx, cost, uniform, u, labels),
        };
        let Some((v, l)) = found else {
            return;
        };
        // The latest value replaces the band's (as in the full march: a
        // neighbour that changed label can raise it), but never above the
        // current `U`: a cell that stops improving leaves with its old value.
        if v < u[j] * IMPROVE {
            self.band.set_key_at(j as u32, state, v);
            self.band_label[j] = l;
        } else if state < FIRST_TAG {
            self.band.set_key_at(j as u32, state, u[j]);
            self.band_label[j] = self.labels[j];
        }
    }

    /// Clears the `DONE` tags of the front that just ended.
    fn end_front(&mut self) {
        if self.track_far {
            self.far.flush(&self.u);
        }
        self.visited += self.touched.len();
        for &i in &self.touched {
            self.band.tag(i, ABSENT);
        }
        self.touched.clear();
    }
}

/// The first-order upwind update of cell `j` from its labelled neighbours
/// (a cell is known once a front labelled it: under a bound,
/// [`Sampler::from_bound`], a finite `U` is not yet a distance). When the
/// neighbours carry several labels, each label's neighbours give their own
/// value and the smallest wins (the first label met among equals), as in the
/// multi-source fast marching's update (`update` with `multi`), with the
/// same arithmetic ([`first_order_by`]).
#[inline(always)]
fn label_update<const A: usize>(
    st: &Stencil,
    j: usize,
    jdx: [usize; 3],
    cost: &IsotropicCost<'_>,
    uniform: Option<(f64, [f64; 3])>,
    u: &[f64],
    labels: &[i32],
) -> Option<(f64, i32)> {
    let (ls, nl) = neighbour_labels::<A>(st, j, jdx, |x| {
        let l = labels[x];
        (l >= 0).then_some(l)
    });
    let (w, roots) = match uniform {
        Some((w, roots)) => (w, Some(roots)),
        None => (cost.at(j), None),
    };
    let one = |k: usize| match roots {
        Some(r) => r[k],
        None => one_axis_root(st, k, w),
    };
    let mut best: Option<(f64, i32)> = None;
    for &l in &ls[..nl] {
        let value = |x: usize| if labels[x] == l { u[x] } else { f64::INFINITY };
        if let Some(v) = first_order_by::<A>(st, j, jdx, w, value, one) {
            if best.is_none_or(|b| v < b.0) {
                best = Some((v, l));
            }
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::numerics::metric::{CostValues, Interpretation};
    use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

    fn unit() -> IsotropicCost<'static> {
        IsotropicCost::constant(1.0).expect("valid")
    }

    #[test]
    fn seeds_are_kept_first_and_in_order() {
        let grid = Grid::unit(&[40, 30]).expect("grid");
        let options = SamplingOptions {
            count: Some(6),
            seeds: vec![vec![5, 5], vec![30, 20]],
            ..Default::default()
        };
        let s = farthest_point_sampling(&grid, &unit(), &options, &Control::new()).expect("ok");
        assert_eq!(s.samples.len(), 6);
        assert_eq!(s.samples[0], vec![5, 5]);
        assert_eq!(s.samples[1], vec![30, 20]);
        assert_eq!(s.stop, SamplingStop::Count);
        for (k, p) in s.samples.iter().enumerate() {
            let i = grid.linear(grid.index3(p).expect("2D"));
            assert_eq!(s.distance[i], 0.0);
            assert_eq!(s.labels[i], k as i32);
        }
        assert_eq!(s.radii.len(), 6);
        assert_eq!(s.covering_radius, s.radii[5]);
    }

    #[test]
    fn stops_at_a_radius_and_works_in_3d() {
        let grid = Grid::new(&[12, 14, 10], &[1.0, 1.0, 2.0]).expect("grid");
        let options = SamplingOptions {
            radius: Some(4.0),
            ..Default::default()
        };
        let s = farthest_point_sampling(&grid, &unit(), &options, &Control::new()).expect("ok");
        assert_eq!(s.stop, SamplingStop::Radius);
        assert!(s.covering_radius <= 4.0);
        assert!(s.radii[s.radii.len() - 2] > 4.0);
        assert!(s.samples.iter().all(|p| p.len() == 3));
        assert!(s.labels.iter().all(|&l| l >= 0));
        let max = s.distance.iter().copied().fold(0.0, f64::max);
        assert_eq!(max, s.covering_radius);
    }

    #[test]
    fn walls_are_never_sampled_nor_reached() {
        let grid = Grid::unit(&[20, 20]).expect("grid");
        // A wall column cuts off the last 5 columns.
        let v: Vec<f64> = (0..400)
            .map(|i| if i % 20 == 14 { f64::INFINITY } else { 1.0 })
            .collect();
        let cost = IsotropicCost::new(&grid, CostValues::F64(v.into()), Interpretation::Cost, None)
            .expect("cost");
        let options = SamplingOptions {
            count: Some(400),
            ..Default::default()
        };
        let s = farthest_point_sampling(&grid, &cost, &options, &Control::new()).expect("ok");
        assert_eq!(s.stop, SamplingStop::Exhausted);
        assert_eq!(s.samples.len(), 20 * 14);
        assert!(s.samples.iter().all(|p| p[1] < 14));
        assert!((0..400)
            .filter(|i| i % 20 >= 14)
            .all(|i| s.distance[i] == f64::INFINITY && s.labels[i] == -1));
        assert_eq!(s.covering_radius, 0.0);
    }

    #[test]
    fn refuses_bad_options_and_seeds() {
        let grid = Grid::unit(&[4, 4]).expect("grid");
        let run = |o: SamplingOptions| farthest_point_sampling(&grid, &unit(), &o, &Control::new());
        assert_eq!(
            run(SamplingOptions::default()),
            Err(SamplingError::NoStopRule)
        );
        assert!(matches!(
            run(SamplingOptions {
                count: Some(17),
                ..Default::default()
            }),
            Err(SamplingError::Count {
                count: 17,
                cells: 16
            })
        ));
        assert!(matches!(
            run(SamplingOptions {
                radius: Some(-1.0),
                ..Default::default()
            }),
            Err(SamplingError::Radius(_))
        ));
        assert!(matches!(
            run(SamplingOptions {
                count: Some(3),
                seeds: vec![vec![0, 0], vec![4, 0]],
                ..Default::default()
            }),
            Err(SamplingError::Seed { index: 1, .. })
        ));
        assert!(matches!(
            run(SamplingOptions {
                count: Some(3),
                seeds: vec![vec![1, 1], vec![1, 1]],
                ..Default::default()
            }),
            Err(SamplingError::Seed { index: 1, .. })
        ));
        assert!(matches!(
            run(SamplingOptions {
                count: Some(1),
                seeds: vec![vec![1, 1], vec![2, 2]],
                ..Default::default()
            }),
            Err(SamplingError::FewerThanSeeds { .. })
        ));
    }

    #[test]
    fn cancellation_stops_it_and_progress_is_samples_over_count() {
        let grid = Grid::unit(&[64, 64]).expect("grid");
        let cancel = AtomicBool::new(false);
        let calls = AtomicUsize::new(0);
        let last = std::sync::Mutex::new(0.0f64);
        let sink = |p: f64| {
            // Cancel once a quarter of the samples are placed.
            if p >= 0.25 {
                cancel.store(true, Ordering::Relaxed);
            }
            calls.fetch_add(1, Ordering::Relaxed);
            if let Ok(mut l) = last.lock() {
                *l = p;
            }
        };
        let control = Control::new().with_cancel(&cancel).with_progress(&sink);
        let options = SamplingOptions {
            count: Some(40),
            ..Default::default()
        };
        let r = farthest_point_sampling(&grid, &unit(), &options, &control);
        assert_eq!(r, Err(SamplingError::Cancelled));
        // Stopped right after the 10th of 40 samples.
        assert_eq!(calls.load(Ordering::Relaxed), 10);
        assert_eq!(*last.lock().expect("lock"), 0.25);
    }
}
