//! Farthest-point sampling of a 2D or 3D grid under a Riemannian metric
//! (a [`TensorField`]; the monograph's section 4.2, Peyré & Cohen 2006 and
//! Bougleux, Peyré & Cohen 2008 for the anisotropic case).
//!
//! # Math
//!
//! With the metric `M(x)` (symmetric positive definite), the distance to a
//! set of samples `S` is the viscosity solution of
//!
//! ```text
//! ‖∇U_S(x)‖_{M(x)⁻¹} = sqrt(∇U_Sᵀ M(x)⁻¹ ∇U_S) = 1,    U_S = 0 on S,
//! ```
//!
//! and, as in the isotropic case ([`super::farthest`]), the next sample is
//! `s_k = argmax U_S`, the label of a cell is its nearest sample (the
//! geodesic Voronoi cell in the metric) and the covering radius
//! `r_k = max U_{S ∪ {s_k}}` never increases. For a constant metric `M` the
//! distance is `‖x − y‖_M = sqrt((x − y)ᵀ M (x − y))`: the map
//! `x ↦ M^{1/2} x` is an isometry onto the Euclidean plane, so the Voronoi
//! cells are the Euclidean ones pulled back, ellipses stretched by
//! `sqrt(λ_max / λ_min)` along the cheap eigenvector, and the best covering
//! radius of `N` points is the hexagonal one of the area measured in the
//! metric, `A_M = sqrt(det M) A`: `r_hex = sqrt(2 A_M / (3 sqrt(3) N))`.
//!
//! # Scheme and local fronts
//!
//! Each new sample starts a fast march over the current map that only
//! lowers `U`, as in [`super::farthest`], with the update of the
//! anisotropic solver's adaptive stencils
//! ([`crate::numerics::anisotropic::stencil`], Selling's decomposition
//! `D̃(x) = Σ_k ρ_k e_k e_kᵀ` of the dual metric in index units): the
//! first-order Eulerian scheme
//!
//! ```text
//! Σ_k ρ_k max(0, U(x) − U(x − e_k), U(x) − U(x + e_k))² = 1
//! ```
//!
//! over the known values (those of earlier fronts and the cells already
//! fixed by this one), with the semi-Lagrangian fallback on incomplete
//! stencils (`anisotropic::fast_marching::first_order_update`). When a cell
//! is fixed, the cells whose stencil holds it (the reverse stencil) are
//! recomputed; one enters the band only if its value drops below its
//! current `U` (by a relative `1e-12`). Walls are the field's: never
//! entered, and no stencil offset crosses one. Cells cut off keep
//! `U = +inf` and label `-1`.
//!
//! The scheme is first order without source factoring: near each sample
//! the values carry the usual `O(h |log h|)` error of the point source,
//! which is small against cells of tens of grid steps.

use super::farthest::{
    check_options, sample_with, Front, GridSampling, SamplingError, SamplingMethod,
};
use super::farthest_cell::FarthestCell;
use super::SamplingOptions;
use crate::numerics::anisotropic::fast_marching::first_order_update;
use crate::numerics::anisotropic::stencil::{self, Stencils};
use crate::numerics::anisotropic::TensorField;
use crate::numerics::control::Control;
use crate::numerics::grid::Grid;
use crate::numerics::heap::{IndexedHeap, ABSENT, FIRST_TAG};

/// Band tag: the cell's value was fixed by the current front.
const DONE: u32 = FIRST_TAG;
/// Band tag: a wall, never entered.
const WALL: u32 = FIRST_TAG + 1;
/// Cancellation is polled every this many cells of a front.
const CANCEL_EVERY: usize = 4096;
/// A cell reopens only if its value goes below `IMPROVE ×` its current value.
const IMPROVE: f64 = 1.0 - 1e-12;

/// Farthest-point sampling of `grid` under the Riemannian `metric` (walls
/// included); see the module docs. Same options, result and errors as the
/// isotropic [`super::farthest_point_sampling`]; the distances are
/// Riemannian lengths in physical units.
///
/// Polls `control` while the stencils are built, per sample and every 4096
/// cells of a front; reports `samples / count` as progress (with a radius
/// only, `(radius / r)^d`).
///
/// # Examples
/// ```
/// use geodex::numerics::anisotropic::TensorField;
/// use geodex::numerics::sampling::{tensor_farthest_point_sampling, SamplingOptions};
/// use geodex::numerics::{Control, Grid};
/// let grid = Grid::unit(&[40, 40])?;
/// // Four times dearer (in squared length) across the diagonal than along it.
/// let metric = TensorField::from_eigen(&grid, &[1.0, 4.0], &[1.0, 1.0])?;
/// let options = SamplingOptions { count: Some(12), ..Default::default() };
/// let s = tensor_farthest_point_sampling(&grid, &metric, &options, &Control::new())?;
/// assert_eq!(s.samples.len(), 12);
/// assert!(s.radii.windows(2).all(|w| w[1] <= w[0]));
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn tensor_farthest_point_sampling(
    grid: &Grid,
    metric: &TensorField,
    options: &SamplingOptions,
    control: &Control<'_>,
) -> Result<GridSampling, SamplingError> {
    check_options(options, grid.len())?;
    if options.method == SamplingMethod::Clustered {
        return Err(SamplingError::Method(
            "clustered sampling needs an isotropic cost: under a tensor metric use exact or auto",
        ));
    }
    if metric.ndim() != grid.ndim() {
        return Err(SamplingError::Dimension {
            field: metric.ndim(),
            grid: grid.ndim(),
        });
    }
    let sampler = TensorSampler::new(grid, metric, control)?;
    sample_with(grid, sampler, options, control)
}

/// The working state of the Riemannian local fronts (see the module docs).
/// Crate-visible so that the geodesic Delaunay repair adds samples with
/// the same fronts.
pub(crate) struct TensorSampler<'a> {
    grid: &'a Grid,
    metric: &'a TensorField,
    st: Stencils,
    u: Vec<f64>,
    labels: Vec<i32>,
    band_label: Vec<i32>,
    band: IndexedHeap,
    far: FarthestCell,
    touched: Vec<u32>,
    visited: usize,
}

impl<'a> TensorSampler<'a> {
    /// A sampler with no sample; builds the stencils (polling `control`).
    pub(crate) fn new(
        grid: &'a Grid,
        metric: &'a TensorField,
        control: &Control<'_>,
    ) -> Result<Self, SamplingError> {
        let n = grid.len();
        let st = stencil::build(grid, metric, control).map_err(|_| SamplingError::Cancelled)?;
        let mut band = IndexedHeap::new(n);
        if metric.has_walls() {
            for i in 0..n {
                if metric.is_wall(i) {
                    band.tag(i as u32, WALL);
                }
            }
        }
        Ok(Self {
            grid,
            metric,
            st,
            u: vec![f64::INFINITY; n],
            labels: vec![-1; n],
            band_label: vec![-1; n],
            band,
            far: FarthestCell::new(n),
            touched: Vec::new(),
            visited: 0,
        })
    }

    /// Resumes from a finished sampling's distance and labels (of `grid`'s size).
    pub(crate) fn resume(
        grid: &'a Grid,
        metric: &'a TensorField,
        distance: Vec<f64>,
        labels: Vec<i32>,
        control: &Control<'_>,
    ) -> Result<Self, SamplingError> {
        let mut s = Self::new(grid, metric, control)?;
        s.far.rebuild(&distance);
        s.u = distance;
        s.labels = labels;
        Ok(s)
    }

    /// Recomputes cell `j` from the known values; it enters the band if its
    /// value goes down (the rule of [`super::farthest`]'s `relax`).
    fn relax(&mut self, j: usize) {
        let state = self.band.state(j as u32);
        if state == DONE || state == WALL {
            return;
        }
        let u = &self.u;
        let known = |x: usize| u[x] < f64::INFINITY;
        let Some((v, l)) =
            first_order_update(self.grid, self.metric, &self.st, j, u, &self.labels, &known)
        else {
            return;
        };
        if v < u[j] * IMPROVE {
            self.band.set_key_at(j as u32, state, v);
            self.band_label[j] = l;
        } else if state < FIRST_TAG {
            self.band.set_key_at(j as u32, state, u[j]);
            self.band_label[j] = self.labels[j];
        }
    }

    /// Starts the front of sample `s`: `U(s) = 0`, and the cells within
    /// `max(1.5, half the longest stencil offset of s)` cells of `s` (none
    /// behind a wall) get the exact local value `‖x − s‖_{M(s)}` where it
    /// lowers theirs, as the anisotropic solver's point sources do: a wide
    /// stencil would otherwise reach past the cells next to `s`, which could
    /// take other labels and cut the sample off its own Voronoi cell.
    fn seed_front(&mut self, s: usize, label: i32) {
        let p = self.grid.unravel(s);
        let m = crate::numerics::anisotropic::fast_marching::index_metric_of(
            self.grid,
            self.metric.at(s),
        );
        let k = self.st.k;
        let mut reach2 = 2.25f64;
        for &j in &self.st.nb[s * 2 * k..(s + 1) * 2 * k] {
            if j != stencil::NONE {
                let y = self.grid.unravel(j as usize);
                let d2: f64 = (0..3).map(|a| (y[a] as f64 - p[a] as f64).powi(2)).sum();
                reach2 = reach2.max(0.25 * d2);
            }
        }
        let r = reach2.sqrt();
        let shape = self.grid.shape3();
        let mut lo = [0usize; 3];
        let mut hi = [0usize; 3];
        for a in 0..3 {
            let ra = if shape[a] == 1 { 0 } else { r.floor() as usize };
            lo[a] = p[a].saturating_sub(ra);
            hi[a] = (p[a] + ra).min(shape[a] - 1);
        }
        let start = |this: &mut Self, i: usize, v: f64| {
            let state = this.band.state(i as u32);
            if state == WALL || state == DONE {
                return;
            }
            if v == 0.0 || v < this.u[i] * IMPROVE {
                this.u[i] = v;
                this.labels[i] = label;
                this.band_label[i] = label;
                this.band.set_key_at(i as u32, state, v);
            }
        };
        start(self, s, 0.0);
        for a in lo[0]..=hi[0] {
            for b in lo[1]..=hi[1] {
                for c in lo[2]..=hi[2] {
                    let x = [a, b, c];
                    let z = [0, 1, 2].map(|q| x[q] as f64 - p[q] as f64);
                    if z.iter().map(|v| v * v).sum::<f64>() > reach2 || x == p {
                        continue;
                    }
                    let i = self.grid.linear(x);
                    if self.metric.is_wall(i) || self.crosses_wall(p, x) {
                        continue;
                    }
                    let mut q = 0.0;
                    for u in 0..3 {
                        for w in 0..3 {
                            q += z[u] * m[u][w] * z[w];
                        }
                    }
                    start(self, i, q.max(0.0).sqrt());
                }
            }
        }
    }

    /// True when the segment from cell `p` to cell `x` passes through a
    /// wall cell (sampled at a tenth of a cell).
    fn crosses_wall(&self, p: [usize; 3], x: [usize; 3]) -> bool {
        if !self.metric.has_walls() {
            return false;
        }
        let len = (0..3)
            .map(|k| (x[k] as f64 - p[k] as f64).abs())
            .fold(0.0, f64::max);
        let steps = (len * 10.0).ceil().max(1.0) as usize;
        (0..=steps).any(|t| {
            let t = t as f64 / steps as f64;
            let q =
                [0, 1, 2].map(|k| (p[k] as f64 + t * (x[k] as f64 - p[k] as f64)).round() as usize);
            self.metric.is_wall(self.grid.linear(q))
        })
    }

    fn end_front(&mut self) {
        self.far.flush(&self.u);
        self.visited += self.touched.len();
        for &i in &self.touched {
            self.band.tag(i, ABSENT);
        }
        self.touched.clear();
    }
}

impl Front for TensorSampler<'_> {
    fn distance(&self) -> &[f64] {
        &self.u
    }

    fn labels(&self) -> &[i32] {
        &self.labels
    }

    fn covering_radius(&self) -> f64 {
        self.far.peek().map_or(0.0, |(_, u)| u)
    }

    fn farthest(&self) -> Option<usize> {
        self.far.peek().map(|(i, _)| i)
    }

    fn clear(&mut self) {
        self.u.fill(f64::INFINITY);
        self.labels.fill(-1);
        self.far.clear();
    }

    fn add(&mut self, s: usize, label: i32, control: &Control<'_>) -> Result<(), SamplingError> {
        self.seed_front(s, label);
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
            self.far.mark(i);
            let (start, end) = (self.st.rev_start[i], self.st.rev_start[i + 1]);
            for r in start..end {
                let y = self.st.rev[r] as usize;
                self.relax(y);
            }
        }
        self.end_front();
        Ok(())
    }

    fn into_parts(self) -> (Vec<f64>, Vec<i32>, usize) {
        (self.u, self.labels, self.visited)
    }

    fn is_wall(&self, i: usize) -> bool {
        self.metric.is_wall(i)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::numerics::sampling::SamplingStop;
    use std::sync::atomic::{AtomicBool, Ordering};

    #[test]
    fn an_identity_metric_samples_like_the_isotropic_sampler() {
        let grid = Grid::unit(&[40, 30]).expect("grid");
        let metric = TensorField::constant(&grid, &[1.0, 0.0, 1.0]).expect("metric");
        let options = SamplingOptions {
            count: Some(8),
            seeds: vec![vec![5, 5], vec![30, 20]],
            ..Default::default()
        };
        let s =
            tensor_farthest_point_sampling(&grid, &metric, &options, &Control::new()).expect("ok");
        assert_eq!(s.samples[0], vec![5, 5]);
        assert_eq!(s.samples[1], vec![30, 20]);
        assert_eq!(s.samples.len(), 8);
        assert!(s.radii.windows(2).all(|w| w[1] <= w[0]));
        assert!(s.labels.iter().all(|&l| l >= 0));
        // The Selling stencil of the identity is the 4-neighbour one, so the
        // values are those of the isotropic first-order march from the same
        // samples (given as seeds: which of the cells tied within rounding
        // each sampler picks is not the point).
        let cost = crate::numerics::IsotropicCost::constant(1.0).expect("cost");
        let same = SamplingOptions {
            count: Some(8),
            seeds: s.samples.clone(),
            ..Default::default()
        };
        let iso = super::super::farthest_point_sampling(&grid, &cost, &same, &Control::new())
            .expect("ok");
        let worst = s
            .distance
            .iter()
            .zip(&iso.distance)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(worst < 0.35, "{worst}");
    }

    #[test]
    fn walls_radius_and_3d() {
        let grid = Grid::unit(&[20, 20]).expect("grid");
        let walls: Vec<bool> = (0..400).map(|i| i % 20 == 14).collect();
        let metric = TensorField::from_eigen(&grid, &[1.0, 4.0], &[1.0, 0.5])
            .expect("metric")
            .with_walls(&grid, walls)
            .expect("walls");
        let options = SamplingOptions {
            count: Some(400),
            ..Default::default()
        };
        let s =
            tensor_farthest_point_sampling(&grid, &metric, &options, &Control::new()).expect("ok");
        assert_eq!(s.stop, SamplingStop::Exhausted);
        assert_eq!(s.samples.len(), 20 * 14);
        assert!(s.samples.iter().all(|p| p[1] < 14));
        assert!((0..400)
            .filter(|i| i % 20 >= 14)
            .all(|i| s.distance[i] == f64::INFINITY && s.labels[i] == -1));

        let grid = Grid::unit(&[12, 14, 10]).expect("grid");
        let metric = TensorField::from_eigen(&grid, &[1.0, 4.0], &[1.0, 1.0, 0.0]).expect("metric");
        let options = SamplingOptions {
            radius: Some(4.0),
            ..Default::default()
        };
        let s =
            tensor_farthest_point_sampling(&grid, &metric, &options, &Control::new()).expect("ok");
        assert_eq!(s.stop, SamplingStop::Radius);
        assert!(s.covering_radius <= 4.0);
        assert!(s.radii[s.radii.len() - 2] > 4.0);
        assert!(s.samples.iter().all(|p| p.len() == 3));
        assert!(s.labels.iter().all(|&l| l >= 0));
    }

    #[test]
    fn refuses_a_field_of_another_dimension_and_stops_when_cancelled() {
        let grid = Grid::unit(&[16, 16]).expect("grid");
        let grid3 = Grid::unit(&[4, 4, 4]).expect("grid");
        let metric3 = TensorField::constant(&grid3, &[1.0, 0.0, 0.0, 1.0, 0.0, 1.0]).expect("m");
        let options = SamplingOptions {
            count: Some(4),
            ..Default::default()
        };
        assert!(matches!(
            tensor_farthest_point_sampling(&grid, &metric3, &options, &Control::new()),
            Err(SamplingError::Dimension { field: 3, grid: 2 })
        ));
        let metric = TensorField::constant(&grid, &[1.0, 0.0, 1.0]).expect("m");
        let cancel = AtomicBool::new(false);
        let sink = |p: f64| {
            if p >= 0.5 {
                cancel.store(true, Ordering::Relaxed);
            }
        };
        let control = Control::new().with_cancel(&cancel).with_progress(&sink);
        let options = SamplingOptions {
            count: Some(10),
            ..Default::default()
        };
        assert_eq!(
            tensor_farthest_point_sampling(&grid, &metric, &options, &control),
            Err(SamplingError::Cancelled)
        );
    }
}
