//! Geodesic Lloyd relaxation (centroidal Voronoi tessellation) of a grid
//! sampling (the monograph's section 4.6).
//!
//! # Math
//!
//! The energy of samples `S` with geodesic Voronoi cells `V_i` is
//!
//! ```text
//! E(S) = Σ_i ∫_{V_i} d_W(x, s_i)² dx = ∫ U_S(x)² dx,
//! ```
//!
//! discretised as `Σ_cells U² · h_0 h_1 (h_2)`. One Lloyd iteration moves each
//! sample to the centroid of its cell, `c_i = argmin_c ∫_{V_i} d_W(x, c)² dx`,
//! then recomputes the cells: both steps lower `E`. The centroid is taken
//! as the mean position of the cell's grid cells, snapped to the nearest grid
//! cell of the cell (exact for a constant metric, where `d_W` is `W` times
//! the Euclidean distance; an approximation otherwise). Because snapping
//! and a non-constant metric can make a full step raise `E`, a step that
//! does is halved (then quartered); when none of them lowers the energy
//! the relaxation stops (`Converged`): `E` never increases from one
//! accepted iteration to the next. The cells are recomputed with the local
//! fronts of [`super::farthest`] (one front per sample).

use std::collections::HashSet;

use super::farthest::{GridSampling, Sampler, SamplingError, SamplingStop};
use crate::numerics::control::Control;
use crate::numerics::grid::Grid;
use crate::numerics::metric::IsotropicCost;

/// Options of [`lloyd`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LloydOptions {
    /// Most iterations.
    pub iterations: usize,
    /// The first `fixed` samples do not move (seeds, boundary samples).
    pub fixed: usize,
    /// Stop once an iteration lowers the energy by less than this fraction.
    pub tolerance: f64,
}

impl Default for LloydOptions {
    fn default() -> Self {
        Self {
            iterations: 30,
            fixed: 0,
            tolerance: 1e-4,
        }
    }
}

/// Why the relaxation stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LloydStop {
    /// `iterations` were run.
    Iterations,
    /// No sample moved.
    Stationary,
    /// The energy decreased by less than the tolerance, or no step lowered it.
    Converged,
}

/// The relaxed sampling and its energy per iteration.
#[derive(Debug, Clone, PartialEq)]
pub struct Relaxed {
    /// The samples (same order and labels as the input), their distance and cells.
    pub sampling: GridSampling,
    /// `energies[0]` is the input's energy, `energies[k]` after iteration `k`.
    pub energies: Vec<f64>,
    /// Samples moved per iteration.
    pub moved: Vec<usize>,
    /// Why it stopped.
    pub stop: LloydStop,
}

/// Geodesic Lloyd relaxation of `sampling` on `grid` under `cost`; see the
/// module docs. Polls `control` per sample's front; reports
/// `iteration / iterations`.
pub fn lloyd(
    grid: &Grid,
    cost: &IsotropicCost<'_>,
    sampling: GridSampling,
    options: &LloydOptions,
    control: &Control<'_>,
) -> Result<Relaxed, SamplingError> {
    let ndim = grid.ndim();
    let sp = grid.spacing3();
    let volume: f64 = grid.spacing().iter().product();
    let energy = |u: &[f64]| {
        u.iter()
            .filter(|x| x.is_finite())
            .map(|x| x * x)
            .sum::<f64>()
            * volume
    };
    let mut cells: Vec<usize> = sampling
        .samples
        .iter()
        .map(|p| grid.index3(p).map(|idx| grid.linear(idx)))
        .collect::<Result<_, _>>()
        .map_err(|e| SamplingError::Seed {
            index: 0,
            reason: e.to_string(),
        })?;
    let mut u = sampling.distance;
    let mut labels = sampling.labels;
    let mut energies = vec![energy(&u)];
    let mut moved = Vec::new();
    let mut sampler = Sampler::new(grid, cost);
    let mut stop = LloydStop::Iterations;
    for it in 0..options.iterations {
        if control.is_cancelled() {
            return Err(SamplingError::Cancelled);
        }
        // Centroids of the cells, in index coordinates.
        let mut sum = vec![[0.0f64; 3]; cells.len()];
        let mut count = vec![0usize; cells.len()];
        for (i, &l) in labels.iter().enumerate() {
            if l >= 0 {
                let idx = grid.unravel(i);
                for (s, &x) in sum[l as usize].iter_mut().zip(&idx) {
                    *s += x as f64;
                }
                count[l as usize] += 1;
            }
        }
        let centroid: Vec<[f64; 3]> = sum
            .iter()
            .zip(&count)
            .map(|(s, &c)| s.map(|x| x / c.max(1) as f64))
            .collect();
        let current = energies[energies.len() - 1];
        let mut accepted = None;
        let mut any_move = false;
        for step in [1.0, 0.5, 0.25] {
            let (candidate, k) = moves(
                grid,
                cost,
                &cells,
                &centroid,
                &labels,
                options.fixed,
                step,
                sp,
            );
            if k == 0 {
                break;
            }
            any_move = true;
            sampler.clear();
            for (label, &c) in candidate.iter().enumerate() {
                sampler.add(c, label as i32, control)?;
            }
            let e = energy(sampler.distance());
            if e <= current {
                accepted = Some((candidate, k, e));
                break;
            }
        }
        control.report((it + 1) as f64 / options.iterations.max(1) as f64);
        let Some((candidate, k, e)) = accepted else {
            stop = if any_move {
                LloydStop::Converged
            } else {
                LloydStop::Stationary
            };
            break;
        };
        cells = candidate;
        u = sampler.distance().to_vec();
        labels = sampler.labels().to_vec();
        energies.push(e);
        moved.push(k);
        if current - e < options.tolerance * current {
            stop = LloydStop::Converged;
            break;
        }
    }
    let covering_radius = u
        .iter()
        .copied()
        .filter(|x| x.is_finite())
        .fold(0.0, f64::max);
    let visited = sampling.visited;
    Ok(Relaxed {
        sampling: GridSampling {
            samples: cells
                .iter()
                .map(|&i| grid.unravel(i)[3 - ndim..].to_vec())
                .collect(),
            distance: u,
            labels,
            radii: vec![covering_radius],
            covering_radius,
            stop: SamplingStop::Count,
            visited,
            clustered: None,
        },
        energies,
        moved,
        stop,
    })
}

/// The samples moved a fraction `step` of the way to their centroids, each
/// snapped to the nearest grid cell of its own Voronoi cell that no other
/// sample holds; the first `fixed` stay. Returns them and how many moved.
#[allow(clippy::too_many_arguments)]
fn moves(
    grid: &Grid,
    cost: &IsotropicCost<'_>,
    cells: &[usize],
    centroid: &[[f64; 3]],
    labels: &[i32],
    fixed: usize,
    step: f64,
    sp: [f64; 3],
) -> (Vec<usize>, usize) {
    let shape = grid.shape3();
    let mut taken: HashSet<usize> = cells.iter().copied().collect();
    let mut out = cells.to_vec();
    let mut count = 0;
    for (k, &c) in cells.iter().enumerate().skip(fixed) {
        let at = grid.unravel(c);
        let target: [f64; 3] =
            [0, 1, 2].map(|a| at[a] as f64 + step * (centroid[k][a] - at[a] as f64));
        let rounded: [usize; 3] =
            [0, 1, 2].map(|a| (target[a].round().max(0.0) as usize).min(shape[a] - 1));
        let mut best = grid.linear(rounded);
        if labels[best] != k as i32 || cost.is_wall(best) {
            // The cell's own grid cell nearest to the target (a small window first).
            best = nearest_member(grid, labels, k as i32, target, sp).unwrap_or(c);
        }
        if best != c && !taken.contains(&best) {
            taken.remove(&c);
            taken.insert(best);
            out[k] = best;
            count += 1;
        }
    }
    (out, count)
}

/// The grid cell with label `label` nearest to `target` (physical distance).
fn nearest_member(
    grid: &Grid,
    labels: &[i32],
    label: i32,
    target: [f64; 3],
    sp: [f64; 3],
) -> Option<usize> {
    labels
        .iter()
        .enumerate()
        .filter(|(_, &l)| l == label)
        .map(|(i, _)| {
            let idx = grid.unravel(i);
            let d: f64 = (0..3)
                .map(|a| ((idx[a] as f64 - target[a]) * sp[a]).powi(2))
                .sum();
            (i, d)
        })
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(i, _)| i)
}
