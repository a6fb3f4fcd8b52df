//! Riemannian tensor fields: one symmetric positive definite matrix `M(x)`
//! per cell.
//!
//! The length of a curve γ is `L(γ) = ∫ sqrt(γ'(t)ᵀ M(γ(t)) γ'(t)) dt` (seed
//! eq. 1.9, 1.11) and the distance map solves `‖∇U‖_{M⁻¹} = 1`, i.e.
//! `∇Uᵀ M(x)⁻¹ ∇U = 1`. An isotropic cost `W` is the tensor `W² Id`.
//!
//! Components are stored in array index order (axis 0 first), upper triangle
//! row by row: `[m00, m01, m11]` in 2D and `[m00, m01, m02, m11, m12, m22]`
//! in 3D, in physical units (a displacement `v` in physical units has length
//! `sqrt(vᵀ M v)`).
//!
//! Constructors: [`TensorField::from_components`] (three or six numbers per
//! cell), [`TensorField::constant`], [`TensorField::from_eigen`] (eigenvalues
//! and the direction of `e1`, seed eq. 1.16) and [`energy_anisotropy`] (energy
//! `W` and anisotropy `A`, seed eq. 1.17: `λ1 = W²(1 − A)`, `λ2 = W²(1 + A)`).

use super::super::grid::Grid;
use super::super::metric::unravel_user;

/// Why a tensor field was refused. Cells are named in array index order.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TensorError {
    /// The field does not have 3 (2D) or 6 (3D) numbers per cell.
    #[error("the field has {got} numbers but a {ndim}D grid of {cells} cells needs {expected} ({per_cell} per cell)")]
    Length {
        /// Numbers given.
        got: usize,
        /// Numbers expected.
        expected: usize,
        /// Components per cell (3 or 6).
        per_cell: usize,
        /// Cells of the grid.
        cells: usize,
        /// Dimension of the grid.
        ndim: usize,
    },
    /// A component is NaN or infinite.
    #[error("cell {cell:?}: component {component} = {value} is not finite")]
    NotFinite {
        /// The first bad cell (array index order); empty for a constant tensor.
        cell: Vec<usize>,
        /// Index of the component (`0..3` or `0..6`).
        component: usize,
        /// The value found.
        value: f64,
    },
    /// The matrix is not positive definite.
    #[error("cell {cell:?}: the tensor {components:?} is not positive definite ({reason})")]
    NotPositiveDefinite {
        /// The first bad cell (array index order); empty for a constant tensor.
        cell: Vec<usize>,
        /// Its components.
        components: Vec<f64>,
        /// Which leading minor failed.
        reason: String,
    },
    /// A parameter of a constructor is out of range (eigenvalue, anisotropy...).
    #[error("{field}: {reason}")]
    Parameter {
        /// The parameter.
        field: &'static str,
        /// What is wrong.
        reason: String,
    },
    /// The obstacle mask does not have one entry per cell.
    #[error("the obstacle mask has {got} values but the grid has {expected} cells")]
    MaskLength {
        /// Values given.
        got: usize,
        /// Cells of the grid.
        expected: usize,
    },
    /// The caller raised the cancel flag while a field was being designed
    /// from an image ([`super::structure_tensor`], [`super::height_map`]).
    #[error("cancelled")]
    Cancelled,
}

/// Number of components of a symmetric `d × d` matrix (3 in 2D, 6 in 3D).
pub const fn components(ndim: usize) -> usize {
    ndim * (ndim + 1) / 2
}

/// A validated tensor field on a grid, with optional walls.
///
/// # Examples
/// ```
/// use geodex::numerics::Grid;
/// use geodex::numerics::anisotropic::TensorField;
/// let grid = Grid::unit(&[4, 4])?;
/// // e1 along axis 1, cost 1 along it and 10 across it.
/// let t = TensorField::from_eigen(&grid, &[1.0, 100.0], &[0.0, 1.0])?;
/// let m = t.at(0);
/// assert!((m[0] - 100.0).abs() < 1e-12 && m[1].abs() < 1e-12 && (m[2] - 1.0).abs() < 1e-12);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct TensorField {
    ndim: usize,
    values: Values,
    walls: Option<Vec<bool>>,
}

#[derive(Debug, Clone, PartialEq)]
enum Values {
    Constant([f64; 6]),
    PerCell(Vec<f64>),
}

impl TensorField {
    /// The same tensor on every cell (`[m00, m01, m11]` or six numbers in 3D).
    pub fn constant(grid: &Grid, m: &[f64]) -> Result<Self, TensorError> {
        let nc = components(grid.ndim());
        if m.len() != nc {
            return Err(TensorError::Length {
                got: m.len(),
                expected: nc,
                per_cell: nc,
                cells: 1,
                ndim: grid.ndim(),
            });
        }
        check_spd(m).map_err(|e| e.at_cell(Vec::new()))?;
        let mut c = [0.0; 6];
        c[..nc].copy_from_slice(m);
        Ok(Self {
            ndim: grid.ndim(),
            values: Values::Constant(c),
            walls: None,
        })
    }

    /// Per-cell components in C order with a trailing component axis: the
    /// first non-finite or non positive definite cell is named in the error.
    pub fn from_components(grid: &Grid, values: Vec<f64>) -> Result<Self, TensorError> {
        let nc = components(grid.ndim());
        let expected = grid.len() * nc;
        if values.len() != expected {
            return Err(TensorError::Length {
                got: values.len(),
                expected,
                per_cell: nc,
                cells: grid.len(),
                ndim: grid.ndim(),
            });
        }
        for (i, m) in values.chunks_exact(nc).enumerate() {
            check_spd(m).map_err(|e| e.at_cell(unravel_user(grid, i)))?;
        }
        Ok(Self {
            ndim: grid.ndim(),
            values: Values::PerCell(values),
            walls: None,
        })
    }

    /// The constant tensor `Σ λ_k e_k e_kᵀ` (seed eq. 1.16) with eigenvalues
    /// `lambdas` (`[λ1, λ2]` in 2D; `[λ1, λ2]` in 3D means `λ2` on the whole
    /// plane orthogonal to `e1`) and `e1` along `direction` (normalised;
    /// array index order). `λ1 < λ2` makes `e1` the cheap direction.
    pub fn from_eigen(
        grid: &Grid,
        lambdas: &[f64],
        direction: &[f64],
    ) -> Result<Self, TensorError> {
        let m = eigen_tensor(grid.ndim(), lambdas, direction)?;
        Self::constant(grid, &m)
    }

    /// Builds a per-cell field from a closure returning the components of each
    /// cell (linear index), validating every cell.
    pub fn from_fn(
        grid: &Grid,
        mut f: impl FnMut(usize) -> Result<Vec<f64>, TensorError>,
    ) -> Result<Self, TensorError> {
        let nc = components(grid.ndim());
        let mut values = Vec::with_capacity(grid.len() * nc);
        for i in 0..grid.len() {
            let m = f(i)?;
            if m.len() != nc {
                return Err(TensorError::Length {
                    got: m.len(),
                    expected: nc,
                    per_cell: nc,
                    cells: 1,
                    ndim: grid.ndim(),
                });
            }
            values.extend_from_slice(&m);
        }
        Self::from_components(grid, values)
    }

    /// Adds walls: cells marked `true` are never entered and keep `U = +inf`.
    pub fn with_walls(mut self, grid: &Grid, walls: Vec<bool>) -> Result<Self, TensorError> {
        if walls.len() != grid.len() {
            return Err(TensorError::MaskLength {
                got: walls.len(),
                expected: grid.len(),
            });
        }
        self.walls = walls.iter().any(|&w| w).then_some(walls);
        Ok(self)
    }

    /// Dimension (2 or 3).
    pub fn ndim(&self) -> usize {
        self.ndim
    }

    /// True when the same tensor is on every cell.
    pub fn is_constant(&self) -> bool {
        matches!(self.values, Values::Constant(_))
    }

    /// The components of cell `i` (linear index): 3 or 6 numbers.
    #[inline]
    pub fn at(&self, i: usize) -> &[f64] {
        let nc = components(self.ndim);
        match &self.values {
            Values::Constant(c) => &c[..nc],
            Values::PerCell(v) => &v[i * nc..(i + 1) * nc],
        }
    }

    /// True if cell `i` is a wall.
    #[inline]
    pub fn is_wall(&self, i: usize) -> bool {
        self.walls.as_ref().is_some_and(|w| w[i])
    }

    /// True if there is at least one wall.
    pub fn has_walls(&self) -> bool {
        self.walls.is_some()
    }

    /// The per-cell components as a flat C-order vector with a trailing
    /// component axis (a constant field is expanded to `cells` copies).
    pub fn to_components(&self, cells: usize) -> Vec<f64> {
        match &self.values {
            Values::PerCell(v) => v.clone(),
            Values::Constant(c) => {
                let nc = components(self.ndim);
                c[..nc].repeat(cells)
            }
        }
    }

    /// Largest anisotropy ratio `sqrt(λmax / λmin)` over the cells.
    pub fn max_anisotropy(&self, cells: usize) -> f64 {
        let n = if self.is_constant() { 1 } else { cells };
        (0..n)
            .map(|i| anisotropy_ratio(self.at(i)))
            .fold(1.0, f64::max)
    }
}

/// The tensor `λ1 e1 e1ᵀ + λ2 (Id − e1 e1ᵀ)` as 3 or 6 components. In 2D a
/// third eigenvalue is refused; in 3D `[λ1, λ2, λ3]` is refused too (give
/// the components for a general 3D tensor).
pub fn eigen_tensor(
    ndim: usize,
    lambdas: &[f64],
    direction: &[f64],
) -> Result<Vec<f64>, TensorError> {
    if lambdas.len() != 2 {
        return Err(TensorError::Parameter {
            field: "eigenvalues",
            reason: format!("give 2 eigenvalues [λ1, λ2], got {}", lambdas.len()),
        });
    }
    for (k, &l) in lambdas.iter().enumerate() {
        if !(l.is_finite() && l > 0.0) {
            return Err(TensorError::Parameter {
                field: "eigenvalues",
                reason: format!("λ{} = {l} must be finite and > 0", k + 1),
            });
        }
    }
    if direction.len() != ndim {
        return Err(TensorError::Parameter {
            field: "direction",
            reason: format!("e1 needs {ndim} coordinates, got {}", direction.len()),
        });
    }
    let n = direction.iter().map(|v| v * v).sum::<f64>().sqrt();
    if !(n.is_finite() && n > 0.0) {
        return Err(TensorError::Parameter {
            field: "direction",
            reason: "e1 must be a finite non-zero vector".into(),
        });
    }
    let e: Vec<f64> = direction.iter().map(|v| v / n).collect();
    let (l1, l2) = (lambdas[0], lambdas[1]);
    let mut out = Vec::with_capacity(components(ndim));
    for a in 0..ndim {
        for b in a..ndim {
            let id = if a == b { 1.0 } else { 0.0 };
            out.push(l2 * id + (l1 - l2) * e[a] * e[b]);
        }
    }
    Ok(out)
}

/// The 2D tensor of energy `w` and anisotropy `a ∈ [0, 1)` (seed eq. 1.17)
/// with its cheap direction `e1` at angle `theta` (radians, from axis 0
/// towards axis 1): eigenvalues `λ1 = w²(1 − a)` along `e1`, `λ2 = w²(1 + a)`.
///
/// # Examples
/// ```
/// use geodex::numerics::anisotropic::energy_anisotropy;
/// let m = energy_anisotropy(2.0, 0.0, 0.3)?; // isotropic: W² Id
/// assert!((m[0] - 4.0).abs() < 1e-12 && m[1].abs() < 1e-12 && (m[2] - 4.0).abs() < 1e-12);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn energy_anisotropy(w: f64, a: f64, theta: f64) -> Result<[f64; 3], TensorError> {
    if !(w.is_finite() && w > 0.0) {
        return Err(TensorError::Parameter {
            field: "energy",
            reason: format!("W = {w} must be finite and > 0"),
        });
    }
    if !(a.is_finite() && (0.0..1.0).contains(&a)) {
        return Err(TensorError::Parameter {
            field: "anisotropy",
            reason: format!("A = {a} must be in [0, 1)"),
        });
    }
    if !theta.is_finite() {
        return Err(TensorError::Parameter {
            field: "angle",
            reason: format!("{theta} must be finite"),
        });
    }
    let (l1, l2) = (w * w * (1.0 - a), w * w * (1.0 + a));
    let (c, s) = (theta.cos(), theta.sin());
    Ok([
        l1 * c * c + l2 * s * s,
        (l1 - l2) * c * s,
        l1 * s * s + l2 * c * c,
    ])
}

/// `sqrt(λmax / λmin)` of a 2D or 3D tensor given by its components.
pub fn anisotropy_ratio(m: &[f64]) -> f64 {
    let ev = eigenvalues(m);
    let (lo, hi) = ev.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), &l| {
        (lo.min(l), hi.max(l))
    });
    (hi / lo).sqrt()
}

/// Eigenvalues of a symmetric 2×2 (3 components) or 3×3 (6 components) matrix.
pub fn eigenvalues(m: &[f64]) -> Vec<f64> {
    if m.len() == 3 {
        let (a, b, c) = (m[0], m[1], m[2]);
        let mean = 0.5 * (a + c);
        let r = (0.25 * (a - c) * (a - c) + b * b).sqrt();
        return vec![mean - r, mean + r];
    }
    // Trigonometric solution of the characteristic cubic (Smith 1961).
    let (a, b, c, d, e, f) = (m[0], m[1], m[2], m[3], m[4], m[5]);
    let p1 = b * b + c * c + e * e;
    let q = (a + d + f) / 3.0;
    if p1 <= 1e-300 {
        return vec![a, d, f];
    }
    let p2 = (a - q).powi(2) + (d - q).powi(2) + (f - q).powi(2) + 2.0 * p1;
    let p = (p2 / 6.0).sqrt();
    let (ba, bd, bf) = ((a - q) / p, (d - q) / p, (f - q) / p);
    let (bb, bc, be) = (b / p, c / p, e / p);
    let det = ba * (bd * bf - be * be) - bb * (bb * bf - be * bc) + bc * (bb * be - bd * bc);
    let r = (det / 2.0).clamp(-1.0, 1.0);
    let phi = r.acos() / 3.0;
    let l1 = q + 2.0 * p * phi.cos();
    let l3 = q + 2.0 * p * (phi + 2.0 * std::f64::consts::PI / 3.0).cos();
    vec![l3, 3.0 * q - l1 - l3, l1]
}

struct SpdFailure {
    component: Option<(usize, f64)>,
    components: Vec<f64>,
    reason: String,
}

impl SpdFailure {
    fn at_cell(self, cell: Vec<usize>) -> TensorError {
        match self.component {
            Some((component, value)) => TensorError::NotFinite {
                cell,
                component,
                value,
            },
            None => TensorError::NotPositiveDefinite {
                cell,
                components: self.components,
                reason: self.reason,
            },
        }
    }
}

/// Sylvester's criterion on the leading minors, with a relative tolerance so
/// that a matrix singular up to rounding is refused too.
fn check_spd(m: &[f64]) -> Result<(), SpdFailure> {
    if let Some(k) = m.iter().position(|v| !v.is_finite()) {
        return Err(SpdFailure {
            component: Some((k, m[k])),
            components: m.to_vec(),
            reason: String::new(),
        });
    }
    let fail = |reason: String| SpdFailure {
        component: None,
        components: m.to_vec(),
        reason,
    };
    let tol = 1e-14;
    if m.len() == 3 {
        let (a, b, c) = (m[0], m[1], m[2]);
        if a <= 0.0 {
            return Err(fail(format!("m00 = {a} <= 0")));
        }
        let det = a * c - b * b;
        if det <= tol * a * c.abs() {
            return Err(fail(format!("det = {det} <= 0")));
        }
        return Ok(());
    }
    let (a, b, c, d, e, f) = (m[0], m[1], m[2], m[3], m[4], m[5]);
    if a <= 0.0 {
        return Err(fail(format!("m00 = {a} <= 0")));
    }
    let d2 = a * d - b * b;
    if d2 <= tol * a * d.abs() {
        return Err(fail(format!("the 2×2 leading minor {d2} <= 0")));
    }
    let d3 = a * (d * f - e * e) - b * (b * f - e * c) + c * (b * e - d * c);
    if d3 <= tol * a * d.abs() * f.abs() {
        return Err(fail(format!("det = {d3} <= 0")));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_bad_cell_is_named() {
        let g = Grid::unit(&[2, 3]).unwrap();
        let mut v = [1.0, 0.0, 1.0].repeat(6);
        v[4 * 3 + 1] = 2.0; // cell (1, 1): [1, 2, 1] has det -3
        v[5 * 3] = f64::NAN;
        let e = TensorField::from_components(&g, v).unwrap_err();
        match e {
            TensorError::NotPositiveDefinite { cell, .. } => assert_eq!(cell, vec![1, 1]),
            other => panic!("{other:?}"),
        }
        let mut v = [1.0, 0.0, 1.0].repeat(6);
        v[2 * 3 + 2] = f64::INFINITY;
        let e = TensorField::from_components(&g, v).unwrap_err();
        assert_eq!(
            e,
            TensorError::NotFinite {
                cell: vec![0, 2],
                component: 2,
                value: f64::INFINITY
            }
        );
        assert!(matches!(
            TensorField::from_components(&g, vec![1.0; 5]),
            Err(TensorError::Length { .. })
        ));
        let g3 = Grid::unit(&[2, 2, 2]).unwrap();
        // Positive diagonal but indefinite.
        let bad = [1.0, 0.9, 0.9, 1.0, -0.9, 1.0];
        assert!(matches!(
            TensorField::constant(&g3, &bad),
            Err(TensorError::NotPositiveDefinite { .. })
        ));
    }

    #[test]
    fn eigen_and_energy_forms_agree() {
        let theta: f64 = 0.4;
        let m = energy_anisotropy(1.5, 0.8, theta).unwrap();
        let w2: f64 = 2.25;
        let e = eigen_tensor(2, &[w2 * 0.2, w2 * 1.8], &[theta.cos(), theta.sin()]).unwrap();
        for k in 0..3 {
            assert!((m[k] - e[k]).abs() < 1e-12);
        }
        let ev = eigenvalues(&m);
        assert!((ev[0] - w2 * 0.2).abs() < 1e-12 && (ev[1] - w2 * 1.8).abs() < 1e-12);
        assert!((anisotropy_ratio(&m) - 3.0).abs() < 1e-12);
        assert!(energy_anisotropy(1.0, 1.0, 0.0).is_err());
    }

    #[test]
    fn cubic_eigenvalues() {
        let m = eigen_tensor(3, &[1.0, 25.0], &[1.0, 2.0, 2.0]).unwrap();
        let ev = eigenvalues(&m);
        assert!((ev[0] - 1.0).abs() < 1e-9, "{ev:?}");
        assert!(
            (ev[1] - 25.0).abs() < 1e-9 && (ev[2] - 25.0).abs() < 1e-9,
            "{ev:?}"
        );
        let ev = eigenvalues(&[2.0, 0.0, 0.0, 3.0, 1.0, 3.0]);
        assert!(
            (ev[0] - 2.0).abs() < 1e-7 && (ev[1] - 2.0).abs() < 1e-7 && (ev[2] - 4.0).abs() < 1e-7,
            "{ev:?}"
        );
    }
}
