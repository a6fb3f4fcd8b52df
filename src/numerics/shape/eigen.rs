//! The largest eigenpairs of a dense symmetric matrix, as MDS needs them.
//!
//! Up to [`DENSE_LIMIT`] rows: faer's dense self-adjoint eigendecomposition
//! (tridiagonalisation + divide and conquer, `O(n³)`, every pair exact to
//! rounding). Above: block subspace iteration with Rayleigh–Ritz
//! (Rutishauser): `W = A Q`, `T = Qᵀ W`, `T = S Θ Sᵀ`, `Q ← orth(W S)`, with
//! a block of `p = d + 10` columns, until the top `d` Ritz pairs have
//! relative residuals `|A x − θ x| / |θ₁| ≤ tol`. It converges like
//! `(|λ_{p+1}| / |λ_d|)^iteration`: fast for the low-rank matrices of MDS,
//! whose spectrum drops sharply after the embedding dimension. The block
//! captures the eigenvalues largest in *magnitude*; the `d` algebraically
//! largest of its Ritz values are returned (MDS wants the top positive ones,
//! and the negative eigenvalues of a near-Euclidean distance matrix are
//! small). Each product `A Q` runs over row blocks in parallel on the
//! caller's pool.

use faer::{Mat, Side};
use ndarray::{s, Array2, ArrayView2, Axis};
use rayon::prelude::*;

use super::ShapeError;
use crate::numerics::Control;

/// Largest size decomposed densely.
pub const DENSE_LIMIT: usize = 1200;

/// The top `d` eigenpairs: values in decreasing order, vectors as the
/// columns of an `n × d` array (unit norm).
#[derive(Debug, Clone, PartialEq)]
pub struct TopEigen {
    /// Eigenvalues, largest first.
    pub values: Vec<f64>,
    /// Eigenvectors, one per column.
    pub vectors: Array2<f64>,
    /// Subspace iterations used (0 for the dense decomposition).
    pub iterations: usize,
}

/// The `d` algebraically largest eigenpairs of the symmetric matrix `a`.
pub fn top_eigen(
    a: ArrayView2<'_, f64>,
    d: usize,
    control: &Control<'_>,
) -> Result<TopEigen, ShapeError> {
    let n = a.nrows();
    if a.ncols() != n || d == 0 || d > n {
        return Err(ShapeError::InvalidOption {
            option: "dimensions",
            reason: format!(
                "need 1 <= d <= n for an n × n matrix, got d = {d}, {n} × {}",
                a.ncols()
            ),
        });
    }
    if n <= DENSE_LIMIT {
        dense(a, d)
    } else {
        subspace(a, d, 1e-10, 1000, control)
    }
}

fn to_faer(a: ArrayView2<'_, f64>) -> Mat<f64> {
    Mat::from_fn(a.nrows(), a.ncols(), |i, j| a[[i, j]])
}

/// Eigenpairs of a small symmetric matrix, largest first.
pub(crate) fn dense(a: ArrayView2<'_, f64>, d: usize) -> Result<TopEigen, ShapeError> {
    let n = a.nrows();
    let evd = to_faer(a)
        .self_adjoint_eigen(Side::Lower)
        .map_err(|e| ShapeError::Numerical(format!("eigendecomposition: {e:?}")))?;
    let (u, sv) = (evd.U(), evd.S().column_vector());
    let values: Vec<f64> = (0..d).map(|k| sv[n - 1 - k]).collect();
    let vectors = Array2::from_shape_fn((n, d), |(i, k)| u[(i, n - 1 - k)]);
    Ok(TopEigen {
        values,
        vectors,
        iterations: 0,
    })
}

/// `a · q` over row blocks in parallel.
fn product(a: ArrayView2<'_, f64>, q: &Array2<f64>) -> Array2<f64> {
    let n = a.nrows();
    let mut w = Array2::<f64>::zeros((n, q.ncols()));
    const BLOCK: usize = 128;
    w.axis_chunks_iter_mut(Axis(0), BLOCK)
        .into_par_iter()
        .enumerate()
        .for_each(|(b, mut out)| {
            let r0 = b * BLOCK;
            let r1 = (r0 + BLOCK).min(n);
            out.assign(&a.slice(s![r0..r1, ..]).dot(q));
        });
    w
}

/// Orthonormalises the columns in place (modified Gram–Schmidt, twice);
/// a column that vanishes is replaced by a fresh pseudo-random one.
///
/// "Vanishes" is relative: a column that loses all but `1e-8` of its norm to
/// the projections lay (to rounding) in the span of the columns before it,
/// and what is left is rounding noise, which normalising would turn into a
/// direction far from orthogonal to them. This is the common case of MDS,
/// whose matrices have a rank near the embedding dimension: the block's
/// extra columns all fall into the range after one product.
fn orthonormalize(q: &mut Array2<f64>, seed: &mut u64) {
    let (n, p) = q.dim();
    for _pass in 0..2 {
        for j in 0..p {
            for _retry in 0..3 {
                let before = q.column(j).dot(&q.column(j)).sqrt();
                for i in 0..j {
                    let dot = q.column(i).dot(&q.column(j));
                    let ci = q.column(i).to_owned();
                    q.column_mut(j).scaled_add(-dot, &ci);
                }
                let nrm = q.column(j).dot(&q.column(j)).sqrt();
                if nrm > 1e-8 * before && nrm > 0.0 && nrm.is_finite() {
                    q.column_mut(j).mapv_inplace(|x| x / nrm);
                    break;
                }
                for i in 0..n {
                    q[[i, j]] = random(seed);
                }
            }
        }
    }
}

fn random(s: &mut u64) -> f64 {
    *s ^= *s << 13;
    *s ^= *s >> 7;
    *s ^= *s << 17;
    (*s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
}

/// Block subspace iteration (see the module docs).
pub(crate) fn subspace(
    a: ArrayView2<'_, f64>,
    d: usize,
    tol: f64,
    max_iter: usize,
    control: &Control<'_>,
) -> Result<TopEigen, ShapeError> {
    let n = a.nrows();
    let p = (d + 10).min(n);
    let mut seed = 0x9e37_79b9_7f4a_7c15_u64;
    let mut q = Array2::from_shape_fn((n, p), |_| random(&mut seed));
    orthonormalize(&mut q, &mut seed);
    for it in 1..=max_iter {
        if control.is_cancelled() {
            return Err(ShapeError::Cancelled);
        }
        let w = product(a, &q);
        let t = q.t().dot(&w);
        let t = (&t + &t.t()) * 0.5;
        let ritz = dense(t.view(), p)?;
        // Ritz vectors x = Q s and A x = W s.
        let x = q.dot(&ritz.vectors);
        let ax = w.dot(&ritz.vectors);
        let scale = ritz
            .values
            .iter()
            .fold(0.0f64, |m, v| m.max(v.abs()))
            .max(f64::MIN_POSITIVE);
        // The d algebraically largest: Ritz values come sorted largest first.
        let mut worst = 0.0f64;
        for k in 0..d {
            let r = &ax.column(k) - &(&x.column(k) * ritz.values[k]);
            worst = worst.max(r.dot(&r).sqrt() / scale);
        }
        control.report(it as f64 / max_iter as f64);
        if worst <= tol || it == max_iter {
            if worst > 1e-6 {
                return Err(ShapeError::Numerical(format!(
                    "subspace iteration did not converge (residual {worst:.2e} after {it} iterations)"
                )));
            }
            return Ok(TopEigen {
                values: ritz.values[..d].to_vec(),
                vectors: x.slice(s![.., ..d]).to_owned(),
                iterations: it,
            });
        }
        q = ax;
        orthonormalize(&mut q, &mut seed);
    }
    Err(ShapeError::Numerical(
        "subspace iteration: no iterations".into(),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `Σ λ_k u_k u_kᵀ` with known orthonormal u (a scaled Householder reflector's columns).
    fn known(n: usize, values: &[f64]) -> Array2<f64> {
        let mut v = Array2::from_shape_fn((n, 1), |(i, _)| ((i * 7 + 3) % 11) as f64 - 5.0);
        let nrm = v.column(0).dot(&v.column(0)).sqrt();
        v.mapv_inplace(|x| x / nrm);
        let h = Array2::<f64>::eye(n) - 2.0 * v.dot(&v.t());
        let mut a = Array2::<f64>::zeros((n, n));
        for (k, &l) in values.iter().enumerate() {
            let u = h.column(k).to_owned().insert_axis(Axis(1));
            a = a + l * u.dot(&u.t());
        }
        a
    }

    /// Indefinite and of rank 6, below the block size (13): the extra
    /// columns vanish after one product, which an absolute test of a
    /// vanished column missed (the Ritz values then exceeded the spectrum).
    #[test]
    fn dense_and_subspace_agree_with_a_known_spectrum() {
        let n = 300;
        let vals = [50.0, 20.0, 7.0, -3.0, 1.0, 0.5];
        let a = known(n, &vals);
        let top_d = dense(a.view(), 3).unwrap();
        let top_s = subspace(a.view(), 3, 1e-12, 500, &Control::new()).unwrap();
        for (k, &want) in vals.iter().enumerate().take(3) {
            assert!((top_d.values[k] - want).abs() < 1e-10, "{:?}", top_d.values);
            assert!((top_s.values[k] - want).abs() < 1e-9, "{:?}", top_s.values);
            let c = top_d.vectors.column(k).dot(&top_s.vectors.column(k)).abs();
            assert!((c - 1.0).abs() < 1e-9, "vector {k}: |cos| = {c}");
        }
        assert!(top_eigen(a.view(), 0, &Control::new()).is_err());
    }
}
