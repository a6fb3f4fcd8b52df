//! Orthogonal Procrustes: the rigid motion that best maps one point set
//! onto another with known correspondences.
//!
//! Minimise `Σ_i |R a_i + t − b_i|²` over orthogonal `R` and `t`: centre
//! both sets, `M = Aᵀ B = U Σ Vᵀ` (SVD), `R = U Vᵀ` acting on row vectors
//! (`a R`), `t = b̄ − ā R` (Schönemann 1966; Kabsch 1976). A proper rotation
//! is forced (`det R = +1`) by flipping the singular vector of the smallest
//! singular value when `det(U Vᵀ) < 0`; an embedding is only defined up to
//! reflections, so callers comparing embeddings allow them.

use faer::Mat;
use ndarray::{Array1, Array2, ArrayView2, Axis};

use super::ShapeError;

/// The motion and the residuals of [`align`].
#[derive(Debug, Clone, PartialEq)]
pub struct Alignment {
    /// `d × d` orthogonal matrix acting on row vectors.
    pub rotation: Array2<f64>,
    /// Translation added after the rotation.
    pub translation: Array1<f64>,
    /// `a R + t`.
    pub aligned: Array2<f64>,
    /// Root mean square distance between aligned points and targets.
    pub rms: f64,
    /// Largest distance between an aligned point and its target.
    pub max_error: f64,
}

/// Aligns the rows of `a` onto the rows of `b` (same shape `n × d`).
pub fn align(
    a: ArrayView2<'_, f64>,
    b: ArrayView2<'_, f64>,
    allow_reflection: bool,
) -> Result<Alignment, ShapeError> {
    let (n, d) = a.dim();
    if b.dim() != (n, d) || n == 0 || d == 0 {
        return Err(ShapeError::InvalidOption {
            option: "points",
            reason: format!(
                "two non-empty sets of the same shape, got {:?} and {:?}",
                a.dim(),
                b.dim()
            ),
        });
    }
    let (ma, mb) = (mean(a), mean(b));
    let ac = &a - &ma;
    let bc = &b - &mb;
    let m = ac.t().dot(&bc);
    let svd = Mat::from_fn(d, d, |i, j| m[[i, j]])
        .svd()
        .map_err(|e| ShapeError::Numerical(format!("SVD: {e:?}")))?;
    let (u, v) = (svd.U(), svd.V());
    let mut uu = Array2::from_shape_fn((d, d), |(i, j)| u[(i, j)]);
    let vv = Array2::from_shape_fn((d, d), |(i, j)| v[(i, j)]);
    let mut r = uu.dot(&vv.t());
    if !allow_reflection && determinant(&r) < 0.0 {
        // Singular values come in decreasing order: flip the last pair.
        uu.column_mut(d - 1).mapv_inplace(|x| -x);
        r = uu.dot(&vv.t());
    }
    let t = &mb - &ma.dot(&r);
    let aligned = a.dot(&r) + &t;
    let errors: Vec<f64> = aligned
        .axis_iter(Axis(0))
        .zip(b.axis_iter(Axis(0)))
        .map(|(p, q)| {
            p.iter()
                .zip(q.iter())
                .map(|(x, y)| (x - y) * (x - y))
                .sum::<f64>()
                .sqrt()
        })
        .collect();
    let rms = (errors.iter().map(|e| e * e).sum::<f64>() / n as f64).sqrt();
    let max_error = errors.iter().fold(0.0f64, |m, &e| m.max(e));
    Ok(Alignment {
        rotation: r,
        translation: t,
        aligned,
        rms,
        max_error,
    })
}

fn mean(a: ArrayView2<'_, f64>) -> Array1<f64> {
    a.mean_axis(Axis(0))
        .unwrap_or_else(|| Array1::zeros(a.ncols()))
}

/// Determinant by Gaussian elimination with partial pivoting.
fn determinant(m: &Array2<f64>) -> f64 {
    let mut a = m.clone();
    let n = a.nrows();
    let mut det = 1.0;
    for c in 0..n {
        let p = (c..n)
            .max_by(|&i, &j| a[[i, c]].abs().total_cmp(&a[[j, c]].abs()))
            .unwrap_or(c);
        if a[[p, c]] == 0.0 {
            return 0.0;
        }
        if p != c {
            for k in 0..n {
                a.swap([p, k], [c, k]);
            }
            det = -det;
        }
        det *= a[[c, c]];
        for i in c + 1..n {
            let f = a[[i, c]] / a[[c, c]];
            for k in c..n {
                a[[i, k]] -= f * a[[c, k]];
            }
        }
    }
    det
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_a_known_motion_and_detects_reflections() {
        let a = Array2::from_shape_fn((20, 3), |(i, j)| {
            ((i * 3 + j * 7) % 11) as f64 - 0.3 * j as f64
        });
        let (c, s) = (0.3f64.cos(), 0.3f64.sin());
        let rot = ndarray::arr2(&[[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]);
        let b = a.dot(&rot) + &ndarray::arr1(&[1.0, -2.0, 5.0]);
        let al = align(a.view(), b.view(), false).unwrap();
        assert!(al.max_error < 1e-12, "{}", al.max_error);
        assert!((&al.rotation - &rot).iter().all(|x| x.abs() < 1e-12));
        // A mirror image: exact with reflections allowed, not without.
        let mut m = b.clone();
        m.column_mut(2).mapv_inplace(|x| -x);
        assert!(align(a.view(), m.view(), true).unwrap().max_error < 1e-12);
        assert!(align(a.view(), m.view(), false).unwrap().max_error > 0.1);
        assert!((determinant(&rot) - 1.0).abs() < 1e-12);
    }
}
