//! Metric design: a cost `W(x) > 0` built from an image or a volume `f`, so
//! that minimal paths follow roads, contours or vessels (seed section 1.1.1
//! and chapter 3).
//!
//! Every design first maps the finite values of `f` affinely to `[0, 1]`
//! (minimum to 0, maximum to 1, [`filters::normalize_unit`]), so that its
//! parameters do not depend on the bit depth or the units of the image. All
//! scales (`sigma`, `scales`) are in **physical units** (a scale `s` is
//! `s / spacing[k]` cells along axis `k`). Every returned cost is finite and
//! `>= epsilon`-bounded away from 0, so it is a valid [`super::IsotropicCost`].
//!
//! * [`intensity`]: `W = |f_σ(x) − c|^p + ε` (seed eq. 1.1 with an exponent):
//!   cheap where the image has the grey value `c` of the structure.
//! * [`edges`]: with `g = |∇(G_σ * f)| / max |∇(G_σ * f)|` in `[0, 1]`,
//!   [`EdgeMode::Follow`] gives `W = 1 / (ε + g^p)` (paths run along
//!   contours, the livewire metric) and [`EdgeMode::Barrier`] its inverse
//!   `W = ε + g^p` (crossing a contour is expensive: regions stay apart).
//! * [`vesselness`]: Frangi's multi-scale Hessian vesselness `v ∈ [0, 1]` in
//!   2D and 3D for bright or dark tubes, and [`design`] with
//!   [`MetricDesign::Vesselness`] gives `W = 1 / (ε + v^p)`.
//!
//! # Examples
//! ```
//! use geodex::numerics::{Grid, metric_design::{self, MetricDesign, IntensityDesign, Reference}};
//! let grid = Grid::unit(&[1, 5])?;
//! let f = vec![0.0, 10.0, 20.0, 30.0, 40.0];
//! // The grey value of cell (0, 4) is the reference: W = |f - 1| + 0.01 there.
//! let design = MetricDesign::Intensity(IntensityDesign {
//!     reference: Reference::Point(vec![0.0, 4.0]),
//!     ..IntensityDesign::default()
//! });
//! let w = metric_design::design(&grid, &f, &design, &Default::default())?;
//! assert!((w[4] - 0.01).abs() < 1e-12 && (w[0] - 1.01).abs() < 1e-12);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use rayon::prelude::*;

use super::control::Control;
use super::filters::{self, FilterError};
use super::grid::Grid;

/// Why a metric could not be designed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DesignError {
    /// A filter refused its input (length, scale). A cancelled filter is
    /// [`DesignError::Cancelled`], not this.
    #[error(transparent)]
    Filter(FilterError),
    /// A parameter is out of its range; `name` is the parameter's name.
    #[error("{name}: {reason}")]
    Parameter {
        /// The parameter (`epsilon`, `scales[1]`, `reference.point`).
        name: String,
        /// Why it is refused.
        reason: String,
    },
    /// The image has a NaN or infinite value.
    #[error("the image has the non-finite value {value} at cell {index:?}")]
    NonFinite {
        /// The cell, in array index order.
        index: Vec<usize>,
        /// The value found.
        value: f64,
    },
    /// The caller cancelled the computation.
    #[error("cancelled")]
    Cancelled,
}

impl From<FilterError> for DesignError {
    fn from(e: FilterError) -> Self {
        match e {
            FilterError::Cancelled => DesignError::Cancelled,
            other => DesignError::Filter(other),
        }
    }
}

fn param(name: impl Into<String>, reason: impl Into<String>) -> DesignError {
    DesignError::Parameter {
        name: name.into(),
        reason: reason.into(),
    }
}

/// Where the reference grey value `c` of [`intensity`] comes from.
#[derive(Debug, Clone, PartialEq)]
pub enum Reference {
    /// A grey value in the image's own units (mapped to `[0, 1]` by the same
    /// affine map as the image).
    Value(f64),
    /// The (smoothed, normalised) value of the cell nearest to this point
    /// (index coordinates, axis 0 first), e.g. a point clicked on the road.
    Point(Vec<f64>),
}

/// Parameters of the intensity metric `W = |f_σ − c|^p + ε`.
#[derive(Debug, Clone, PartialEq)]
pub struct IntensityDesign {
    /// The grey value `c` of the structure. Default: `Value(+inf)`, which
    /// stands for the largest value of the image (bright structures;
    /// `Value(-inf)` is the smallest); see [`Reference`].
    pub reference: Reference,
    /// Exponent `p > 0` of `|f − c|`. Default: 1 (seed eq. 1.1).
    pub power: f64,
    /// `ε > 0`, the cost where `f = c`, which keeps `W` away from 0. Default: 0.01.
    pub epsilon: f64,
    /// Standard deviation (physical units) of a Gaussian pre-smoothing of `f`,
    /// `0` for none. Default: 0.
    pub sigma: f64,
}

impl Default for IntensityDesign {
    fn default() -> Self {
        Self {
            reference: Reference::Value(f64::INFINITY),
            power: 1.0,
            epsilon: 0.01,
            sigma: 0.0,
        }
    }
}

/// Which way the edge metric steers paths.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum EdgeMode {
    /// `W = 1 / (ε + g^p)`: cheap on strong edges, paths follow contours.
    #[default]
    Follow,
    /// `W = ε + g^p`: expensive on strong edges, paths (and fronts) do not cross them.
    Barrier,
}

/// Parameters of the edge metric.
#[derive(Debug, Clone, PartialEq)]
pub struct EdgeDesign {
    /// Standard deviation (physical units) of the Gaussian before the
    /// gradient; `0` differentiates the raw image. Default: 1.
    pub sigma: f64,
    /// Exponent `p > 0` of the normalised gradient magnitude `g`. Default: 1.
    pub power: f64,
    /// `ε > 0`. Default: 0.01 (so `W` spans `[1/1.01, 100]` in follow mode).
    pub epsilon: f64,
    /// Follow contours or treat them as barriers. Default: follow.
    pub mode: EdgeMode,
}

impl Default for EdgeDesign {
    fn default() -> Self {
        Self {
            sigma: 1.0,
            power: 1.0,
            epsilon: 0.01,
            mode: EdgeMode::Follow,
        }
    }
}

/// Whether the tubes to find are brighter or darker than their background.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Polarity {
    /// Bright tubes on a dark background (contrast-enhanced vessels, roads).
    #[default]
    Bright,
    /// Dark tubes on a bright background (vessels in fundus images, cracks).
    Dark,
}

/// Parameters of Frangi's vesselness and of `W = 1 / (ε + v^p)`.
///
/// At each scale `σ`, `H = σ² ∇²(G_σ * f)` (scale-normalised Hessian) has
/// eigenvalues sorted by magnitude, `|λ1| <= |λ2| [<= |λ3|]`.
///
/// * 3D: `R_A = |λ2|/|λ3|` (plate vs line), `R_B = |λ1|/sqrt(|λ2 λ3|)` (blob
///   vs line), `S = sqrt(Σ λ_i²)` (structure), and
///   `v_σ = (1 − exp(−R_A²/2α²)) exp(−R_B²/2β²) (1 − exp(−S²/2c²))`,
///   set to 0 unless `λ2, λ3 < 0` (bright) or `> 0` (dark).
/// * 2D: `R_B = |λ1|/|λ2|`, `v_σ = exp(−R_B²/2β²) (1 − exp(−S²/2c²))`, set to
///   0 unless `λ2 < 0` (bright) or `> 0` (dark).
///
/// `v = max_σ v_σ`, divided by its maximum over the image so that `v ∈ [0, 1]`.
#[derive(Debug, Clone, PartialEq)]
pub struct VesselnessDesign {
    /// Scales `σ` in physical units; a tube of radius `r` responds best near
    /// `σ ≈ r / sqrt(2)` to `r`. Default: `[1, 2, 3]`.
    pub scales: Vec<f64>,
    /// Bright or dark tubes. Default: bright.
    pub polarity: Polarity,
    /// `α` (3D only), sensitivity to `R_A`. Default: 0.5.
    pub alpha: f64,
    /// `β`, sensitivity to `R_B`. Default: 0.5.
    pub beta: f64,
    /// `c`, sensitivity to `S`; `None` uses half of the largest `S` at each
    /// scale (Frangi's choice). Default: `None`.
    pub c: Option<f64>,
    /// Exponent `p > 0` of `v` in `W`. Default: 1.
    pub power: f64,
    /// `ε > 0` in `W = 1 / (ε + v^p)`. Default: 0.01.
    pub epsilon: f64,
}

impl Default for VesselnessDesign {
    fn default() -> Self {
        Self {
            scales: vec![1.0, 2.0, 3.0],
            polarity: Polarity::Bright,
            alpha: 0.5,
            beta: 0.5,
            c: None,
            power: 1.0,
            epsilon: 0.01,
        }
    }
}

/// One of the designs.
#[derive(Debug, Clone, PartialEq)]
pub enum MetricDesign {
    /// [`intensity`].
    Intensity(IntensityDesign),
    /// [`edges`].
    Edges(EdgeDesign),
    /// `W = 1 / (ε + v^p)` with `v` from [`vesselness`].
    Vesselness(VesselnessDesign),
}

/// The cost `W` (one value per cell, C order) of `design` applied to the image `f`.
pub fn design(
    grid: &Grid,
    f: &[f64],
    design: &MetricDesign,
    control: &Control<'_>,
) -> Result<Vec<f64>, DesignError> {
    match design {
        MetricDesign::Intensity(d) => intensity(grid, f, d, control),
        MetricDesign::Edges(d) => edges(grid, f, d, control),
        MetricDesign::Vesselness(d) => {
            check_positive("power", d.power)?;
            check_positive("epsilon", d.epsilon)?;
            let v = vesselness(grid, f, d, control)?;
            Ok(v.iter()
                .map(|&v| 1.0 / (d.epsilon + power(v, d.power)))
                .collect())
        }
    }
}

/// `v^p` for `v >= 0`; `p = 1` (the default of every design) skips `powf`,
/// whose result is then `v` exactly anyway.
#[inline]
fn power(v: f64, p: f64) -> f64 {
    if p == 1.0 {
        v
    } else {
        v.powf(p)
    }
}

fn check_positive(name: &str, v: f64) -> Result<(), DesignError> {
    if !(v.is_finite() && v > 0.0) {
        return Err(param(name, format!("{v} must be finite and > 0")));
    }
    Ok(())
}

fn check_sigma(name: &str, v: f64) -> Result<(), DesignError> {
    if !(v.is_finite() && v >= 0.0) {
        return Err(param(name, format!("{v} must be finite and >= 0")));
    }
    Ok(())
}

/// Checks the length and finiteness of `f` and maps it to `[0, 1]`.
/// Returns the normalised image and the affine map `(lo, span)`.
fn normalised(grid: &Grid, f: &[f64]) -> Result<(Vec<f64>, f64, f64), DesignError> {
    if f.len() != grid.len() {
        return Err(FilterError::Length {
            got: f.len(),
            expected: grid.len(),
        }
        .into());
    }
    if let Some(i) = f.iter().position(|v| !v.is_finite()) {
        return Err(DesignError::NonFinite {
            index: super::metric::unravel_user(grid, i),
            value: f[i],
        });
    }
    let lo = f.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = f.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    Ok((filters::normalize_unit(f), lo, hi - lo))
}

/// The intensity metric `W = |f_σ(x) − c|^p + ε` (seed eq. 1.1 with an
/// exponent), on the image normalised to `[0, 1]`. `W ∈ [ε, 1 + ε]`.
///
/// With `reference = Value(+inf)` (the default) `c` is the largest value
/// (1 after normalisation, bright structures); `Value(-inf)` gives 0 (dark).
pub fn intensity(
    grid: &Grid,
    f: &[f64],
    d: &IntensityDesign,
    control: &Control<'_>,
) -> Result<Vec<f64>, DesignError> {
    check_positive("power", d.power)?;
    check_positive("epsilon", d.epsilon)?;
    check_sigma("sigma", d.sigma)?;
    let (f, lo, span) = normalised(grid, f)?;
    let f = filters::gaussian_smooth(grid, &f, d.sigma, control)?;
    let c = match &d.reference {
        Reference::Value(v) if v.is_nan() => {
            return Err(param("reference.value", "must not be NaN"));
        }
        Reference::Value(v) if *v == f64::INFINITY => 1.0,
        Reference::Value(v) if *v == f64::NEG_INFINITY => 0.0,
        Reference::Value(v) => {
            if span > 0.0 {
                (v - lo) / span
            } else {
                0.0
            }
        }
        Reference::Point(p) => {
            let cell = nearest_cell(grid, p).map_err(|r| param("reference.point", r))?;
            f[grid.linear(cell)]
        }
    };
    Ok(f.iter()
        .map(|&v| power((v - c).abs(), d.power) + d.epsilon)
        .collect())
}

/// The cell nearest to a caller point, or why the point is refused.
fn nearest_cell(grid: &Grid, p: &[f64]) -> Result<[usize; 3], String> {
    let q = grid.point3(p).map_err(|e| e.to_string())?;
    if !grid.contains_point3(q) {
        return Err(format!("{p:?} is outside the grid {:?}", grid.shape()));
    }
    Ok([0, 1, 2].map(|k| q[k].round() as usize))
}

/// The normalised gradient magnitude `g = |∇(G_σ * f)| / max |∇(G_σ * f)|`
/// (physical units, so anisotropic spacing is honoured), in `[0, 1]`.
pub fn edge_strength(
    grid: &Grid,
    f: &[f64],
    sigma: f64,
    control: &Control<'_>,
) -> Result<Vec<f64>, DesignError> {
    check_sigma("sigma", sigma)?;
    let (f, _, _) = normalised(grid, f)?;
    let s = filters::gaussian_smooth(grid, &f, sigma, control)?;
    let g: Vec<f64> = filters::gradient(grid, &s, control)?
        .iter()
        .map(|d| (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt())
        .collect();
    let max = g.iter().copied().fold(0.0, f64::max);
    Ok(if max > 0.0 {
        g.iter().map(|v| v / max).collect()
    } else {
        g
    })
}

/// The edge metric, see [`EdgeDesign`]: `W = 1 / (ε + g^p)` (follow) or
/// `W = ε + g^p` (barrier) with `g` from [`edge_strength`].
pub fn edges(
    grid: &Grid,
    f: &[f64],
    d: &EdgeDesign,
    control: &Control<'_>,
) -> Result<Vec<f64>, DesignError> {
    check_positive("power", d.power)?;
    check_positive("epsilon", d.epsilon)?;
    let g = edge_strength(grid, f, d.sigma, control)?;
    Ok(g.iter()
        .map(|&g| {
            let t = d.epsilon + power(g, d.power);
            match d.mode {
                EdgeMode::Follow => 1.0 / t,
                EdgeMode::Barrier => t,
            }
        })
        .collect())
}

/// Eigenvalues of the symmetric 2×2 matrix `[[a, b], [b, c]]`.
#[inline]
fn eig_sym2(a: f64, b: f64, c: f64) -> [f64; 2] {
    let m = 0.5 * (a + c);
    let r = (0.25 * (a - c) * (a - c) + b * b).sqrt();
    [m - r, m + r]
}

/// Eigenvalues of the symmetric 3×3 matrix `[h00, h11, h22, h01, h02, h12]`
/// (trigonometric solution of the characteristic cubic, Smith 1961).
#[inline]
fn eig_sym3(h: [f64; 6]) -> [f64; 3] {
    let [a00, a11, a22, a01, a02, a12] = h;
    let p1 = a01 * a01 + a02 * a02 + a12 * a12;
    let q = (a00 + a11 + a22) / 3.0;
    let d0 = a00 - q;
    let d1 = a11 - q;
    let d2 = a22 - q;
    let p2 = d0 * d0 + d1 * d1 + d2 * d2 + 2.0 * p1;
    if p2 <= f64::MIN_POSITIVE {
        return [a00, a11, a22];
    }
    let p = (p2 / 6.0).sqrt();
    // det((A - qI) / p) / 2
    let (b00, b11, b22, b01, b02, b12) = (d0 / p, d1 / p, d2 / p, a01 / p, a02 / p, a12 / p);
    let det = b00 * (b11 * b22 - b12 * b12) - b01 * (b01 * b22 - b12 * b02)
        + b02 * (b01 * b12 - b11 * b02);
    let r = (0.5 * det).clamp(-1.0, 1.0);
    let phi = r.acos() / 3.0;
    let e1 = q + 2.0 * p * phi.cos();
    let e3 = q + 2.0 * p * (phi + 2.0 * std::f64::consts::PI / 3.0).cos();
    [e1, 3.0 * q - e1 - e3, e3]
}

/// Frangi's multi-scale vesselness `v ∈ [0, 1]` (see [`VesselnessDesign`]
/// for the formulas), on the image normalised to `[0, 1]`. 2D grids use the
/// 2D measure, 3D grids the 3D one.
pub fn vesselness(
    grid: &Grid,
    f: &[f64],
    d: &VesselnessDesign,
    control: &Control<'_>,
) -> Result<Vec<f64>, DesignError> {
    if d.scales.is_empty() {
        return Err(param("scales", "at least one scale is required"));
    }
    for (k, &s) in d.scales.iter().enumerate() {
        check_positive(&format!("scales[{k}]"), s)?;
    }
    check_positive("alpha", d.alpha)?;
    check_positive("beta", d.beta)?;
    if let Some(c) = d.c {
        check_positive("c", c)?;
    }
    let (f, _, _) = normalised(grid, f)?;
    let three_d = grid.ndim() == 3;
    let sign = match d.polarity {
        Polarity::Bright => 1.0,
        Polarity::Dark => -1.0,
    };
    let mut best = vec![0.0f64; f.len()];
    for (k, &sigma) in d.scales.iter().enumerate() {
        if control.is_cancelled() {
            return Err(DesignError::Cancelled);
        }
        let smooth = filters::gaussian_smooth(grid, &f, sigma, control)?;
        let s2 = sigma * sigma;
        // Eigenvalues sorted by magnitude, of the scale-normalised Hessian.
        let eig: Vec<[f64; 3]> = filters::hessian(grid, &smooth, control)?
            .par_iter()
            .map(|h| {
                let mut e = if three_d {
                    eig_sym3(h.map(|v| v * s2))
                } else {
                    let [a, b] = eig_sym2(h[1] * s2, h[5] * s2, h[2] * s2);
                    [0.0, a, b]
                };
                if three_d {
                    e.sort_by(|x, y| x.abs().total_cmp(&y.abs()));
                } else if e[1].abs() > e[2].abs() {
                    e.swap(1, 2);
                }
                e
            })
            .collect();
        let structure = |e: &[f64; 3]| (e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).sqrt();
        let c = match d.c {
            Some(c) => c,
            None => 0.5 * eig.par_iter().map(structure).reduce(|| 0.0, f64::max),
        };
        if c <= 0.0 {
            continue; // a flat image at this scale: no tube anywhere.
        }
        let (a2, b2, c2) = (2.0 * d.alpha * d.alpha, 2.0 * d.beta * d.beta, 2.0 * c * c);
        best.par_iter_mut().zip(eig.par_iter()).for_each(|(b, e)| {
            let s = structure(e);
            let v = if three_d {
                let [l1, l2, l3] = *e;
                // Bright tubes: negative curvature across (λ2, λ3 < 0).
                if sign * l2 >= 0.0 || sign * l3 >= 0.0 {
                    0.0
                } else {
                    let ra = l2.abs() / l3.abs();
                    let rb = l1.abs() / (l2 * l3).abs().sqrt();
                    (1.0 - (-ra * ra / a2).exp())
                        * (-rb * rb / b2).exp()
                        * (1.0 - (-s * s / c2).exp())
                }
            } else {
                let (l1, l2) = (e[1], e[2]);
                if sign * l2 >= 0.0 {
                    0.0
                } else {
                    let rb = l1 / l2;
                    (-rb * rb / b2).exp() * (1.0 - (-s * s / c2).exp())
                }
            };
            if v > *b {
                *b = v;
            }
        });
        control.report((k + 1) as f64 / d.scales.len() as f64);
    }
    let max = best.iter().copied().fold(0.0, f64::max);
    if max > 0.0 {
        best.iter_mut().for_each(|v| *v /= max);
    }
    Ok(best)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn symmetric_eigenvalues_match_known_matrices() {
        let mut e = eig_sym3([2.0, 3.0, 4.0, 0.0, 0.0, 0.0]);
        e.sort_by(f64::total_cmp);
        assert!((e[0] - 2.0).abs() < 1e-12 && (e[1] - 3.0).abs() < 1e-12);
        // [[2,1,0],[1,2,0],[0,0,5]] has eigenvalues 1, 3, 5.
        let mut e = eig_sym3([2.0, 2.0, 5.0, 1.0, 0.0, 0.0]);
        e.sort_by(f64::total_cmp);
        for (a, b) in e.iter().zip([1.0, 3.0, 5.0]) {
            assert!((a - b).abs() < 1e-12, "{e:?}");
        }
        // [[4,1,2],[1,3,0],[2,0,5]]: trace 12, det 4(15) - 1(5) + 2(-6) = 43.
        let e = eig_sym3([4.0, 3.0, 5.0, 1.0, 2.0, 0.0]);
        assert!((e.iter().sum::<f64>() - 12.0).abs() < 1e-12);
        assert!((e.iter().product::<f64>() - 43.0).abs() < 1e-9);
        let [a, b] = eig_sym2(1.0, 2.0, 1.0);
        assert!((a + 1.0).abs() < 1e-12 && (b - 3.0).abs() < 1e-12);
    }

    #[test]
    fn intensity_follows_equation_1_1() {
        let grid = Grid::unit(&[1, 5]).unwrap();
        let f = [0.0, 25.0, 50.0, 75.0, 100.0];
        let d = IntensityDesign {
            reference: Reference::Value(25.0),
            power: 2.0,
            epsilon: 0.1,
            sigma: 0.0,
        };
        let w = intensity(&grid, &f, &d, &Control::new()).unwrap();
        let want = [0.0625 + 0.1, 0.1, 0.0625 + 0.1, 0.25 + 0.1, 0.5625 + 0.1];
        for (a, b) in w.iter().zip(want) {
            assert!((a - b).abs() < 1e-12, "{w:?}");
        }
        let bad = IntensityDesign {
            epsilon: 0.0,
            ..IntensityDesign::default()
        };
        assert!(matches!(
            intensity(&grid, &f, &bad, &Control::new()),
            Err(DesignError::Parameter { ref name, .. }) if name == "epsilon"
        ));
        let outside = IntensityDesign {
            reference: Reference::Point(vec![0.0, 9.0]),
            ..IntensityDesign::default()
        };
        assert!(intensity(&grid, &f, &outside, &Control::new()).is_err());
        assert!(matches!(
            intensity(&grid, &[0.0, f64::NAN, 0.0, 0.0, 0.0], &d, &Control::new()),
            Err(DesignError::NonFinite { ref index, .. }) if index == &vec![0, 1]
        ));
    }

    #[test]
    fn edge_metric_is_cheapest_on_the_step() {
        // A vertical step edge between columns 9 and 10.
        let grid = Grid::unit(&[20, 20]).unwrap();
        let f: Vec<f64> = (0..400)
            .map(|i| if i % 20 >= 10 { 1.0 } else { 0.0 })
            .collect();
        let w = edges(&grid, &f, &EdgeDesign::default(), &Control::new()).unwrap();
        let row = &w[200..220];
        let (argmin, _) = row
            .iter()
            .enumerate()
            .min_by(|a, b| a.1.total_cmp(b.1))
            .unwrap();
        assert!(argmin == 9 || argmin == 10, "{row:?}");
        // g = 1 at the edge: W = 1 / (0.01 + 1).
        assert!((row[argmin] - 1.0 / 1.01).abs() < 1e-9);
        // Far from the edge g ≈ 0: W ≈ 1 / ε.
        assert!(row[0] > 90.0 && row[19] > 90.0);
        let barrier = EdgeDesign {
            mode: EdgeMode::Barrier,
            ..EdgeDesign::default()
        };
        let wb = edges(&grid, &f, &barrier, &Control::new()).unwrap();
        for (a, b) in w.iter().zip(&wb) {
            assert!((a * b - 1.0).abs() < 1e-12);
        }
    }

    /// A bright (or dark) line of Gaussian profile of width `r` along axis 1.
    fn line_image(grid: &Grid, r: f64, dark: bool) -> Vec<f64> {
        (0..grid.len())
            .map(|i| {
                let [a, b, c] = grid.unravel(i);
                let (y, z) = if grid.ndim() == 2 {
                    (b as f64 - 15.0, 0.0)
                } else {
                    (a as f64 - 10.0, c as f64 - 10.0)
                };
                let v = (-(y * y + z * z) / (2.0 * r * r)).exp();
                if dark {
                    1.0 - v
                } else {
                    v
                }
            })
            .collect()
    }

    #[test]
    fn vesselness_peaks_on_the_centreline_in_2d_and_3d() {
        let grid = Grid::unit(&[31, 31]).unwrap();
        for dark in [false, true] {
            let f = line_image(&grid, 2.0, dark);
            let d = VesselnessDesign {
                polarity: if dark {
                    Polarity::Dark
                } else {
                    Polarity::Bright
                },
                ..VesselnessDesign::default()
            };
            let v = vesselness(&grid, &f, &d, &Control::new()).unwrap();
            // The line is the row axis 0 = 15; column 15 crosses it.
            let row: Vec<f64> = (0..31).map(|j| v[grid.linear([0, 15, j])]).collect();
            assert!(
                row.iter().all(|&x| (x - row[0]).abs() < 1e-9),
                "along the line"
            );
            let across: Vec<f64> = (0..31).map(|b| v[grid.linear([0, b, 15])]).collect();
            assert!(
                across[15] > 0.9 && across[15] >= across[12] && across[5] < 0.05,
                "{across:?}"
            );
            // The wrong polarity sees nothing on the centreline.
            let wrong = VesselnessDesign {
                polarity: if dark {
                    Polarity::Bright
                } else {
                    Polarity::Dark
                },
                ..d
            };
            let v = vesselness(&grid, &f, &wrong, &Control::new()).unwrap();
            assert!(v[grid.linear([0, 15, 15])] < 1e-9);
        }
        let grid = Grid::unit(&[21, 16, 21]).unwrap();
        let f = line_image(&grid, 2.0, false);
        let v = vesselness(&grid, &f, &VesselnessDesign::default(), &Control::new()).unwrap();
        let centre = v[grid.linear([10, 8, 10])];
        assert!(centre > 0.9, "{centre}");
        assert!(v[grid.linear([10, 8, 16])] < 0.3 * centre);
        assert!(v[grid.linear([3, 8, 10])] < 0.05);
        let w = design(
            &grid,
            &f,
            &MetricDesign::Vesselness(VesselnessDesign::default()),
            &Control::new(),
        )
        .unwrap();
        let i = grid.linear([10, 8, 10]);
        assert!((w[i] - 1.0 / (0.01 + v[i])).abs() < 1e-9);
    }

    #[test]
    fn a_raised_flag_stops_every_design() {
        let grid = Grid::unit(&[8, 8]).unwrap();
        let f: Vec<f64> = (0..64).map(f64::from).collect();
        let flag = std::sync::atomic::AtomicBool::new(true);
        let c = Control::new().with_cancel(&flag);
        let smoothed = IntensityDesign {
            sigma: 1.0,
            ..IntensityDesign::default()
        };
        assert_eq!(
            intensity(&grid, &f, &smoothed, &c),
            Err(DesignError::Cancelled)
        );
        assert_eq!(
            edges(&grid, &f, &EdgeDesign::default(), &c),
            Err(DesignError::Cancelled)
        );
        assert_eq!(
            edge_strength(&grid, &f, 0.0, &c),
            Err(DesignError::Cancelled)
        );
        let v = MetricDesign::Vesselness(VesselnessDesign::default());
        assert_eq!(design(&grid, &f, &v, &c), Err(DesignError::Cancelled));
    }
}
