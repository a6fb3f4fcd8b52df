//! Multidimensional scaling: points in `R^d` whose Euclidean distances
//! approximate a given distance matrix.
//!
//! * **Classical MDS** (Torgerson): `B = −½ J D⁽²⁾ J` with `J = I − 𝟙𝟙ᵀ/n`
//!   and `D⁽²⁾` the squared distances; with `B`'s top eigenpairs
//!   `(λ_k, u_k)`, `X = [√λ₁ u₁ … √λ_d u_d]`. Exact (up to a rigid motion)
//!   when `D` is Euclidean of rank `≤ d`. The explained variance is
//!   `Σ_{k≤d} λ_k / tr B` (`tr B = Σ_{i<j} D²_ij / n`; above 1 only when `B`
//!   has negative eigenvalues, i.e. `D` is not Euclidean).
//! * **Landmark MDS** (de Silva and Tenenbaum, 2004): classical MDS of the
//!   `k × k` landmark block `Δ` gives `L = [√λ_k u_k]`; every point `a` with
//!   squared landmark distances `δ_a` is placed by distance-based
//!   triangulation `x_a = −½ L^# (δ_a − δ̄)`, `L^#` the rows `u_kᵀ / √λ_k`,
//!   `δ̄` the mean column of `Δ⁽²⁾`. The landmarks land where classical MDS
//!   puts them; the result is then centred and turned to its principal axes.
//!   Cost `O(k n d)` after the `k` distance rows.
//! * **SMACOF** (de Leeuw; Borg and Groenen, ch. 8): minimises the stress
//!   `σ(X) = Σ_{i<j} w_ij (d_ij(X) − δ_ij)²` by the Guttman transform
//!   `X ← V⁺ B(X) X`, `V = Σ_{i<j} w_ij (e_i − e_j)(e_i − e_j)ᵀ`,
//!   `B(X)_ij = −w_ij δ_ij / d_ij(X)` off the diagonal (0 where
//!   `d_ij = 0`), rows summing to 0. Each step minimises a majorising
//!   quadratic touching `σ` at the current `X`, so the stress never
//!   increases. Unit weights give `V⁺ = J / n`; general weights factor
//!   `V + 𝟙𝟙ᵀ` once (Cholesky, `O(n³)`). Each step is `O(n² d)`, parallel
//!   over rows.

use faer::linalg::solvers::Solve;
use faer::{Mat, Side};
use ndarray::{Array1, Array2, ArrayView2, Axis};
use rayon::prelude::*;

use super::eigen::{dense, top_eigen};
use super::ShapeError;
use crate::numerics::Control;

/// Points and how well they explain the distances.
#[derive(Debug, Clone, PartialEq)]
pub struct Embedding {
    /// One point per row (`n × d`).
    pub coords: Array2<f64>,
    /// The top `d` eigenvalues of `B` (largest first).
    pub eigenvalues: Vec<f64>,
    /// `Σ_{k≤d} λ_k / tr B`: above 1 when `B` has negative eigenvalues
    /// (distances that are not Euclidean, such as geodesics on a sphere).
    pub explained_variance: f64,
}

fn check_square(d: ArrayView2<'_, f64>, dim: usize) -> Result<(), ShapeError> {
    let n = d.nrows();
    if d.ncols() != n {
        return Err(ShapeError::InvalidOption {
            option: "distances",
            reason: format!("must be square, got {n} × {}", d.ncols()),
        });
    }
    if dim == 0 || dim >= n.max(1) {
        return Err(ShapeError::InvalidOption {
            option: "dimensions",
            reason: format!(
                "must be between 1 and n - 1 = {}, got {dim}",
                n.saturating_sub(1)
            ),
        });
    }
    if let Some(i) = d.iter().position(|x| !x.is_finite()) {
        return Err(ShapeError::InvalidOption {
            option: "distances",
            reason: format!(
                "entry ({}, {}) is not finite (a disconnected input?)",
                i / n,
                i % n
            ),
        });
    }
    Ok(())
}

/// The double-centred `B = −½ J D⁽²⁾ J` of a square distance matrix.
pub fn double_centre(d: ArrayView2<'_, f64>) -> Array2<f64> {
    let n = d.nrows();
    let mut b = d.mapv(|x| x * x);
    let rows: Array1<f64> = b.mean_axis(Axis(1)).unwrap_or_else(|| Array1::zeros(n));
    let cols: Array1<f64> = b.mean_axis(Axis(0)).unwrap_or_else(|| Array1::zeros(n));
    let all = rows.mean().unwrap_or(0.0);
    b.axis_iter_mut(Axis(0))
        .into_par_iter()
        .enumerate()
        .for_each(|(i, mut row)| {
            for (j, x) in row.iter_mut().enumerate() {
                *x = -0.5 * (*x - rows[i] - cols[j] + all);
            }
        });
    b
}

/// Classical MDS of the symmetric distance matrix `d` into `dim` dimensions.
/// Directions with a non-positive eigenvalue get coordinate 0.
pub fn classical_mds(
    d: ArrayView2<'_, f64>,
    dim: usize,
    control: &Control<'_>,
) -> Result<Embedding, ShapeError> {
    check_square(d, dim)?;
    let b = double_centre(d);
    let trace: f64 = b.diag().sum();
    let top = top_eigen(b.view(), dim, control)?;
    Ok(embed(&top.vectors, &top.values, trace))
}

fn embed(vectors: &Array2<f64>, values: &[f64], trace: f64) -> Embedding {
    let mut coords = vectors.clone();
    for (k, &l) in values.iter().enumerate() {
        let s = l.max(0.0).sqrt();
        coords.column_mut(k).mapv_inplace(|x| x * s);
    }
    let explained = values.iter().map(|l| l.max(0.0)).sum::<f64>() / trace.max(f64::MIN_POSITIVE);
    Embedding {
        coords,
        eigenvalues: values.to_vec(),
        explained_variance: explained,
    }
}

/// Landmark MDS from `rows` (`k × n`: distances from `k` landmarks to every
/// point), `landmark_columns[i]` the column of landmark `i` (its own point).
/// The landmark block must be symmetric (see
/// [`super::matrix::symmetrize_block`]).
pub fn landmark_mds(
    rows: ArrayView2<'_, f64>,
    landmark_columns: &[usize],
    dim: usize,
    control: &Control<'_>,
) -> Result<Embedding, ShapeError> {
    let (k, n) = rows.dim();
    if landmark_columns.len() != k || landmark_columns.iter().any(|&c| c >= n) {
        return Err(ShapeError::InvalidOption {
            option: "landmarks",
            reason: "one column per landmark row, each < n".into(),
        });
    }
    if dim == 0 || dim >= k {
        return Err(ShapeError::InvalidOption {
            option: "landmarks",
            reason: format!(
                "{k} landmarks cannot place {dim} dimensions: give at least {}",
                dim + 1
            ),
        });
    }
    if let Some(i) = rows.iter().position(|x| !x.is_finite()) {
        return Err(ShapeError::InvalidOption {
            option: "distances",
            reason: format!(
                "distance from landmark {} to point {} is not finite (a disconnected input?)",
                i / n,
                i % n
            ),
        });
    }
    let delta = Array2::from_shape_fn((k, k), |(i, j)| rows[[i, landmark_columns[j]]]);
    let b = double_centre(delta.view());
    let trace: f64 = b.diag().sum();
    let top = dense(b.view(), dim)?;
    if control.is_cancelled() {
        return Err(ShapeError::Cancelled);
    }
    // Mean squared distance to each landmark over the landmarks.
    let mean: Vec<f64> = (0..k)
        .map(|i| (0..k).map(|j| delta[[j, i]] * delta[[j, i]]).sum::<f64>() / k as f64)
        .collect();
    // L#: row c is u_c / sqrt(λ_c) (0 for a non-positive λ).
    let pinv: Vec<Vec<f64>> = (0..dim)
        .map(|c| {
            let l = top.values[c];
            (0..k)
                .map(|i| {
                    if l > 0.0 {
                        top.vectors[[i, c]] / l.sqrt()
                    } else {
                        0.0
                    }
                })
                .collect()
        })
        .collect();
    let mut coords = Array2::<f64>::zeros((n, dim));
    coords
        .axis_iter_mut(Axis(0))
        .into_par_iter()
        .enumerate()
        .for_each(|(a, mut x)| {
            for (c, p) in pinv.iter().enumerate() {
                let mut s = 0.0;
                for i in 0..k {
                    let r = rows[[i, a]];
                    s += p[i] * (r * r - mean[i]);
                }
                x[c] = -0.5 * s;
            }
        });
    principal_axes(&mut coords);
    Ok(Embedding {
        coords,
        eigenvalues: top.values.clone(),
        explained_variance: top.values.iter().map(|l| l.max(0.0)).sum::<f64>()
            / trace.max(f64::MIN_POSITIVE),
    })
}

/// Centres the rows and rotates them onto their principal axes (largest
/// variance first).
pub fn principal_axes(coords: &mut Array2<f64>) {
    let (n, d) = coords.dim();
    if n == 0 {
        return;
    }
    let mean = coords
        .mean_axis(Axis(0))
        .unwrap_or_else(|| Array1::zeros(d));
    *coords -= &mean;
    let cov = coords.t().dot(coords);
    if let Ok(e) = dense(cov.view(), d) {
        *coords = coords.dot(&e.vectors);
    }
}

/// Options of [`smacof`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SmacofOptions {
    /// Most Guttman transforms.
    pub max_iterations: usize,
    /// Stop when the stress decreases by less than this fraction of itself.
    pub tolerance: f64,
}

impl Default for SmacofOptions {
    fn default() -> Self {
        Self {
            max_iterations: 300,
            tolerance: 1e-6,
        }
    }
}

/// The result of [`smacof`].
#[derive(Debug, Clone, PartialEq)]
pub struct Smacof {
    /// Final points (`n × d`).
    pub coords: Array2<f64>,
    /// Raw stress `σ` of the start (entry 0) and after every iteration.
    pub stress: Vec<f64>,
    /// Normalised stress `sqrt(σ / Σ_{i<j} w_ij δ_ij²)` at the end.
    pub normalized_stress: f64,
    /// Whether the tolerance was reached before `max_iterations`.
    pub converged: bool,
}

/// Weighted stress `Σ_{i<j} w_ij (|x_i − x_j| − δ_ij)²`, in parallel.
pub fn stress(
    delta: ArrayView2<'_, f64>,
    weights: Option<ArrayView2<'_, f64>>,
    x: &Array2<f64>,
) -> f64 {
    let n = delta.nrows();
    (0..n)
        .into_par_iter()
        .map(|i| {
            let xi = x.row(i);
            let mut s = 0.0;
            for j in i + 1..n {
                let w = weights.map_or(1.0, |w| w[[i, j]]);
                if w == 0.0 {
                    continue;
                }
                let d = dist(xi, x.row(j));
                let r = d - delta[[i, j]];
                s += w * r * r;
            }
            s
        })
        .sum()
}

#[inline]
fn dist(a: ndarray::ArrayView1<'_, f64>, b: ndarray::ArrayView1<'_, f64>) -> f64 {
    a.iter()
        .zip(b.iter())
        .map(|(p, q)| (p - q) * (p - q))
        .sum::<f64>()
        .sqrt()
}

/// SMACOF from `init` (see the module docs). `weights` must be symmetric,
/// `>= 0`, and connect every point (else `V` is singular).
pub fn smacof(
    delta: ArrayView2<'_, f64>,
    weights: Option<ArrayView2<'_, f64>>,
    init: Array2<f64>,
    options: &SmacofOptions,
    control: &Control<'_>,
) -> Result<Smacof, ShapeError> {
    let n = delta.nrows();
    check_square(delta, init.ncols().min(n.saturating_sub(1)).max(1))?;
    if init.nrows() != n {
        return Err(ShapeError::InvalidOption {
            option: "init",
            reason: format!("{} starting points for {n} distances", init.nrows()),
        });
    }
    if let Some(w) = weights {
        if w.dim() != (n, n) || w.iter().any(|x| !(x.is_finite() && *x >= 0.0)) {
            return Err(ShapeError::InvalidOption {
                option: "weights",
                reason: "an n × n matrix of finite values >= 0".into(),
            });
        }
    }
    // (V + 11ᵀ) for general weights, factored once.
    let factor = match weights {
        None => None,
        Some(w) => {
            let v = Mat::from_fn(n, n, |i, j| {
                let off = if i == j {
                    (0..n).filter(|&k| k != i).map(|k| w[[i, k]]).sum::<f64>()
                } else {
                    -w[[i, j]]
                };
                off + 1.0
            });
            Some(v.llt(Side::Lower).map_err(|e| {
                ShapeError::Numerical(format!("the weights do not connect every point ({e:?})"))
            })?)
        }
    };
    let norm2: f64 = (0..n)
        .map(|i| {
            (i + 1..n)
                .map(|j| weights.map_or(1.0, |w| w[[i, j]]) * delta[[i, j]].powi(2))
                .sum::<f64>()
        })
        .sum();
    let mut x = init;
    let mut history = vec![stress(delta, weights, &x)];
    let mut converged = false;
    for it in 0..options.max_iterations {
        if control.is_cancelled() {
            return Err(ShapeError::Cancelled);
        }
        // B(X) X, row by row.
        let dim = x.ncols();
        let mut bx = Array2::<f64>::zeros((n, dim));
        bx.axis_iter_mut(Axis(0))
            .into_par_iter()
            .enumerate()
            .for_each(|(i, mut out)| {
                let xi = x.row(i);
                for j in 0..n {
                    if j == i {
                        continue;
                    }
                    let w = weights.map_or(1.0, |w| w[[i, j]]);
                    let d = dist(xi, x.row(j));
                    if w == 0.0 || d <= 0.0 {
                        continue;
                    }
                    let c = w * delta[[i, j]] / d;
                    for k in 0..dim {
                        out[k] += c * (xi[k] - x[[j, k]]);
                    }
                }
            });
        x = match &factor {
            None => bx / n as f64,
            Some(llt) => {
                let rhs = Mat::from_fn(n, dim, |i, k| bx[[i, k]]);
                let sol = llt.solve(&rhs);
                Array2::from_shape_fn((n, dim), |(i, k)| sol[(i, k)])
            }
        };
        let s = stress(delta, weights, &x);
        let prev = history[history.len() - 1];
        history.push(s);
        control.report((it + 1) as f64 / options.max_iterations as f64);
        if prev - s <= options.tolerance * prev {
            converged = true;
            break;
        }
    }
    let last = history[history.len() - 1];
    Ok(Smacof {
        coords: x,
        normalized_stress: (last / norm2.max(f64::MIN_POSITIVE)).sqrt(),
        stress: history,
        converged,
    })
}

/// Sums over the measured pairs of a distance-row matrix and an embedding:
/// `rows[[i, v]]` (the distance `g` from point `sources[i]` to `v`) against
/// `e = |x_{sources[i]} − x_v|`, over the finite entries with
/// `v ≠ sources[i]` (each unordered pair once when the rows are all pairs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PairStats {
    /// Pairs counted.
    pub pairs: f64,
    sg: f64,
    se: f64,
    sgg: f64,
    see: f64,
    sge: f64,
}

impl PairStats {
    /// The sums, in parallel over the rows.
    pub fn of(rows: ArrayView2<'_, f64>, sources: &[u32], x: ArrayView2<'_, f64>) -> Self {
        let all_pairs = sources.len() == rows.ncols();
        let [pairs, sg, se, sgg, see, sge] = (0..sources.len())
            .into_par_iter()
            .map(|i| {
                let s = sources[i] as usize;
                let xs = x.row(s);
                let mut acc = [0.0f64; 6];
                let start = if all_pairs { s + 1 } else { 0 };
                for v in start..rows.ncols() {
                    let g = rows[[i, v]];
                    if v == s || !g.is_finite() {
                        continue;
                    }
                    let e = dist(xs, x.row(v));
                    acc[0] += 1.0;
                    acc[1] += g;
                    acc[2] += e;
                    acc[3] += g * g;
                    acc[4] += e * e;
                    acc[5] += g * e;
                }
                acc
            })
            .reduce(|| [0.0; 6], |a, b| std::array::from_fn(|k| a[k] + b[k]));
        Self {
            pairs,
            sg,
            se,
            sgg,
            see,
            sge,
        }
    }

    /// `1 − ρ²`, `ρ` the linear correlation of `g` and `e` (Tenenbaum's
    /// residual variance; 0 for a perfect linear fit).
    pub fn residual_variance(&self) -> f64 {
        let m = self.pairs;
        if m < 2.0 {
            return 0.0;
        }
        let cov = self.sge / m - (self.sg / m) * (self.se / m);
        let vg = self.sgg / m - (self.sg / m).powi(2);
        let ve = self.see / m - (self.se / m).powi(2);
        if vg <= 0.0 || ve <= 0.0 {
            return 1.0;
        }
        (1.0 - cov * cov / (vg * ve)).clamp(0.0, 1.0)
    }

    /// Normalised stress `sqrt(Σ (e − g)² / Σ g²)`.
    pub fn normalized_stress(&self) -> f64 {
        let num = (self.sgg - 2.0 * self.sge + self.see).max(0.0);
        (num / self.sgg.max(f64::MIN_POSITIVE)).sqrt()
    }
}

/// The Euclidean distance matrix of the rows of `x`.
pub fn euclidean_distances(x: ArrayView2<'_, f64>) -> Array2<f64> {
    let n = x.nrows();
    let mut d = Array2::<f64>::zeros((n, n));
    d.axis_iter_mut(Axis(0))
        .into_par_iter()
        .enumerate()
        .for_each(|(i, mut row)| {
            for j in 0..n {
                row[j] = dist(x.row(i), x.row(j));
            }
        });
    d
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::numerics::shape::procrustes::align;

    fn cloud(n: usize, d: usize, seed: u64) -> Array2<f64> {
        let mut s = seed;
        Array2::from_shape_fn((n, d), |_| {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 53) as f64 * 10.0 - 5.0
        })
    }

    #[test]
    fn classical_mds_recovers_points_up_to_a_rigid_motion() {
        for (n, seed) in [(60, 7u64), (1500, 11)] {
            // 1500 > DENSE_LIMIT: the subspace iteration path.
            let p = cloud(n, 3, seed);
            let d = euclidean_distances(p.view());
            let e = classical_mds(d.view(), 3, &Control::new()).unwrap();
            assert!(
                (e.explained_variance - 1.0).abs() < 1e-9,
                "{}",
                e.explained_variance
            );
            let a = align(e.coords.view(), p.view(), true).unwrap();
            assert!(a.max_error <= 1e-9, "n = {n}: max error {}", a.max_error);
        }
    }

    #[test]
    fn landmark_mds_places_every_point() {
        let p = cloud(400, 2, 5);
        let d = euclidean_distances(p.view());
        let landmarks: Vec<usize> = (0..400).step_by(40).collect();
        let rows = d.select(Axis(0), &landmarks);
        let e = landmark_mds(rows.view(), &landmarks, 2, &Control::new()).unwrap();
        let a = align(e.coords.view(), p.view(), true).unwrap();
        assert!(a.max_error <= 1e-9, "max error {}", a.max_error);
        assert!(landmark_mds(rows.view(), &landmarks[..3], 2, &Control::new()).is_err());
    }

    #[test]
    fn smacof_stress_never_increases_and_fits_euclidean_data() {
        let p = cloud(80, 2, 3);
        let d = euclidean_distances(p.view());
        // A start near the truth (SMACOF finds a local minimum; from here, the global one).
        let start = &p + &(cloud(80, 2, 99) * 0.1);
        let opts = SmacofOptions {
            max_iterations: 500,
            tolerance: 1e-12,
        };
        let unweighted = smacof(d.view(), None, start.clone(), &opts, &Control::new()).unwrap();
        // Weights: every pair but a band, symmetric.
        let w = Array2::from_shape_fn((80, 80), |(i, j)| {
            if i != j && (i + j) % 5 != 0 {
                1.0 + ((i * j) % 3) as f64
            } else {
                0.0
            }
        });
        let weighted = smacof(d.view(), Some(w.view()), start, &opts, &Control::new()).unwrap();
        for r in [&unweighted, &weighted] {
            assert!(r.stress.len() > 2);
            for s in r.stress.windows(2) {
                assert!(
                    s[1] <= s[0] + 1e-12 * r.stress[0],
                    "stress rose: {} -> {}",
                    s[0],
                    s[1]
                );
            }
            assert!(
                r.stress[r.stress.len() - 1] < 1e-3 * r.stress[0],
                "{:?}",
                &r.stress[r.stress.len() - 3..]
            );
            assert!(r.normalized_stress < 0.01);
        }
        // From the classical solution of exact data the stress is already ~0.
        let e = classical_mds(d.view(), 2, &Control::new()).unwrap();
        let r = smacof(
            d.view(),
            None,
            e.coords,
            &SmacofOptions::default(),
            &Control::new(),
        )
        .unwrap();
        assert!(r.stress[0] < 1e-18 && r.converged);
        let flag = std::sync::atomic::AtomicBool::new(true);
        assert_eq!(
            smacof(
                d.view(),
                None,
                p.clone(),
                &opts,
                &Control::new().with_cancel(&flag)
            ),
            Err(ShapeError::Cancelled)
        );
    }
}
