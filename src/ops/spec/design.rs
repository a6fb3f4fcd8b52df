//! The `design` section that every request with a `cost` accepts
//! (`"cost": {"dataset": IMAGE, "design": {"kind": "edges"}}`), and
//! `grid.metric` returns as a dataset: the cost `W` designed from an image or
//! a volume (intensity, edges, vesselness).
//!
//! The formulas and their defaults are those of
//! [`crate::numerics::metric_design`]: the image is first mapped affinely to
//! `[0, 1]`; scales are in physical units (times the spacing).

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use crate::io::ArrayData;
use crate::numerics::metric_design::{
    self, DesignError, EdgeDesign, EdgeMode, IntensityDesign, MetricDesign, Polarity, Reference,
    VesselnessDesign,
};
use crate::numerics::{Control, Grid};
use crate::ops::OpError;

/// How to build the cost `W` from the image named by `cost.dataset`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum DesignSpec {
    /// `W = |f_σ − c|^p + ε` (seed eq. 1.1): cheap where the image has the grey value `c`.
    Intensity(IntensitySpec),
    /// `g = |∇(G_σ * f)| / max|∇(G_σ * f)|`; `W = 1/(ε + g^p)` (follow contours) or `ε + g^p` (barrier).
    Edges(EdgesSpec),
    /// Frangi's multi-scale Hessian vesselness `v ∈ [0, 1]`; `W = 1/(ε + v^p)`.
    Vesselness(VesselnessSpec),
}

/// Parameters of the intensity metric `W = |f_σ(x) − c|^p + ε`, with `f`
/// normalised to `[0, 1]`. `c` is `value` (image units), or the value at
/// the cell nearest to `at`, or (neither given) the brightest value.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct IntensitySpec {
    /// The reference grey value `c` in the image's own units.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub value: Option<f64>,
    /// Read `c` at this point (index coordinates, axis 0 first), e.g. a point on the road.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(min_items = 2, max_items = 3)]
    pub at: Option<Vec<f64>>,
    /// Exponent `p > 0`. Default: 1.
    #[serde(default = "one")]
    #[schema(exclusive_minimum = 0.0)]
    pub power: f64,
    /// `ε > 0`, the cost on the structure. Default: 0.01.
    #[serde(default = "eps")]
    #[schema(exclusive_minimum = 0.0)]
    pub epsilon: f64,
    /// Gaussian pre-smoothing, physical units (0: none). Default: 0.
    #[serde(default)]
    #[schema(minimum = 0.0)]
    pub sigma: f64,
}

/// Parameters of the edge metric.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct EdgesSpec {
    /// Gaussian scale before the gradient, physical units. Default: 1.
    #[serde(default = "one")]
    #[schema(minimum = 0.0)]
    pub sigma: f64,
    /// Exponent `p > 0` of the normalised gradient magnitude. Default: 1.
    #[serde(default = "one")]
    #[schema(exclusive_minimum = 0.0)]
    pub power: f64,
    /// `ε > 0`. Default: 0.01.
    #[serde(default = "eps")]
    #[schema(exclusive_minimum = 0.0)]
    pub epsilon: f64,
    /// `follow` (`W = 1/(ε + g^p)`, paths run along contours) or `barrier`
    /// (`W = ε + g^p`, crossing a contour is expensive). Default: `follow`.
    #[serde(default)]
    pub mode: EdgeModeSpec,
}

/// Which way the edge metric steers paths.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum EdgeModeSpec {
    /// `W = 1/(ε + g^p)`.
    #[default]
    Follow,
    /// `W = ε + g^p`.
    Barrier,
}

/// Bright or dark tubes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum PolaritySpec {
    /// Tubes brighter than their background.
    #[default]
    Bright,
    /// Tubes darker than their background.
    Dark,
}

/// Parameters of Frangi's vesselness. At each scale σ the Hessian
/// `σ² ∇²(G_σ * f)` has eigenvalues `|λ1| <= |λ2| <= |λ3|`; in 3D
/// `v = (1 − e^{−R_A²/2α²}) e^{−R_B²/2β²} (1 − e^{−S²/2c²})` with
/// `R_A = |λ2/λ3|`, `R_B = |λ1|/sqrt|λ2 λ3|`, `S = |λ|`; in 2D
/// `v = e^{−R_B²/2β²}(1 − e^{−S²/2c²})` with `R_B = λ1/λ2`; 0 where the
/// signs do not fit the polarity. Maximum over scales, divided by its maximum.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct VesselnessSpec {
    /// Scales σ in physical units (≈ the tube radii). Default: `[1, 2, 3]`.
    #[serde(default = "default_scales")]
    #[schema(min_items = 1)]
    pub scales: Vec<f64>,
    /// Bright or dark tubes. Default: `bright`.
    #[serde(default)]
    pub polarity: PolaritySpec,
    /// α (3D), sensitivity to `R_A`. Default: 0.5.
    #[serde(default = "half")]
    #[schema(exclusive_minimum = 0.0)]
    pub alpha: f64,
    /// β, sensitivity to `R_B`. Default: 0.5.
    #[serde(default = "half")]
    #[schema(exclusive_minimum = 0.0)]
    pub beta: f64,
    /// c, sensitivity to `S`. Default: half of the largest `S` at each scale.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(exclusive_minimum = 0.0)]
    pub c: Option<f64>,
    /// Exponent `p > 0` of `v`. Default: 1.
    #[serde(default = "one")]
    #[schema(exclusive_minimum = 0.0)]
    pub power: f64,
    /// `ε > 0`. Default: 0.01.
    #[serde(default = "eps")]
    #[schema(exclusive_minimum = 0.0)]
    pub epsilon: f64,
}

fn one() -> f64 {
    1.0
}
fn eps() -> f64 {
    0.01
}
fn half() -> f64 {
    0.5
}
fn default_scales() -> Vec<f64> {
    vec![1.0, 2.0, 3.0]
}

impl DesignSpec {
    /// The core description of this design.
    pub fn to_core(&self) -> MetricDesign {
        match self {
            DesignSpec::Intensity(s) => MetricDesign::Intensity(IntensityDesign {
                reference: match (&s.at, s.value) {
                    (Some(p), _) => Reference::Point(p.clone()),
                    (None, Some(v)) => Reference::Value(v),
                    (None, None) => Reference::Value(f64::INFINITY),
                },
                power: s.power,
                epsilon: s.epsilon,
                sigma: s.sigma,
            }),
            DesignSpec::Edges(s) => MetricDesign::Edges(EdgeDesign {
                sigma: s.sigma,
                power: s.power,
                epsilon: s.epsilon,
                mode: match s.mode {
                    EdgeModeSpec::Follow => EdgeMode::Follow,
                    EdgeModeSpec::Barrier => EdgeMode::Barrier,
                },
            }),
            DesignSpec::Vesselness(s) => MetricDesign::Vesselness(VesselnessDesign {
                scales: s.scales.clone(),
                polarity: match s.polarity {
                    PolaritySpec::Bright => Polarity::Bright,
                    PolaritySpec::Dark => Polarity::Dark,
                },
                alpha: s.alpha,
                beta: s.beta,
                c: s.c,
                power: s.power,
                epsilon: s.epsilon,
            }),
        }
    }

    /// Checks the parameters that do not need the image; `field` is the JSON
    /// path of this section (`cost.design`).
    pub fn validate(&self, field: &str) -> Result<(), OpError> {
        let positive = |name: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(OpError::invalid(
                    format!("{field}.{name}"),
                    format!("{v} must be finite and > 0"),
                ))
            }
        };
        let sigma = |v: f64| {
            if v.is_finite() && v >= 0.0 {
                Ok(())
            } else {
                Err(OpError::invalid(
                    format!("{field}.sigma"),
                    format!("{v} must be finite and >= 0"),
                ))
            }
        };
        match self {
            DesignSpec::Intensity(s) => {
                positive("power", s.power)?;
                positive("epsilon", s.epsilon)?;
                sigma(s.sigma)?;
                if s.value.is_some() && s.at.is_some() {
                    return Err(OpError::invalid(
                        field,
                        "give `value` or `at` for the reference grey value, not both",
                    ));
                }
                if let Some(v) = s.value {
                    if !v.is_finite() {
                        return Err(OpError::invalid(format!("{field}.value"), "must be finite"));
                    }
                }
                if let Some(p) = &s.at {
                    if let Some(k) = p.iter().position(|v| !v.is_finite()) {
                        return Err(OpError::invalid(
                            format!("{field}.at[{k}]"),
                            "coordinates must be finite",
                        ));
                    }
                }
            }
            DesignSpec::Edges(s) => {
                positive("power", s.power)?;
                positive("epsilon", s.epsilon)?;
                sigma(s.sigma)?;
            }
            DesignSpec::Vesselness(s) => {
                if s.scales.is_empty() {
                    return Err(OpError::invalid(
                        format!("{field}.scales"),
                        "at least one scale is required",
                    ));
                }
                if s.scales.len() > 16 {
                    return Err(OpError::TooLarge {
                        field: format!("{field}.scales"),
                        reason: format!("{} scales, more than the limit of 16", s.scales.len()),
                    });
                }
                for (k, &v) in s.scales.iter().enumerate() {
                    positive(&format!("scales[{k}]"), v)?;
                }
                positive("alpha", s.alpha)?;
                positive("beta", s.beta)?;
                if let Some(c) = s.c {
                    positive("c", c)?;
                }
                positive("power", s.power)?;
                positive("epsilon", s.epsilon)?;
            }
        }
        Ok(())
    }
}

/// The values of an array as f64, in C order (booleans as 0 / 1).
pub fn array_to_f64(array: &ArrayData) -> Vec<f64> {
    match array {
        ArrayData::F64(a) => a.iter().copied().collect(),
        ArrayData::F32(a) => a.iter().map(|&v| f64::from(v)).collect(),
        _ => (0..array.len())
            .map(|i| array.get_f64(i).unwrap_or(f64::NAN))
            .collect(),
    }
}

/// Applies `spec` to `image` on `grid`; errors name fields under `field`
/// (the JSON path of the design section) or `image_field` (the dataset).
pub fn apply_design(
    grid: &Grid,
    image: &ArrayData,
    spec: &DesignSpec,
    field: &str,
    image_field: &str,
    control: &Control<'_>,
) -> Result<Vec<f64>, OpError> {
    if image.dtype() == crate::io::DType::Bool {
        return Err(OpError::invalid(
            image_field,
            "a boolean mask is not an image to design a metric from",
        ));
    }
    let f = array_to_f64(image);
    metric_design::design(grid, &f, &spec.to_core(), control).map_err(|e| match e {
        DesignError::Cancelled => OpError::Cancelled,
        DesignError::Parameter { name, reason } => {
            let name = match name.as_str() {
                "reference.point" => "at".to_string(),
                "reference.value" => "value".to_string(),
                _ => name,
            };
            OpError::invalid(format!("{field}.{name}"), reason)
        }
        DesignError::NonFinite { .. } | DesignError::Filter(_) => {
            OpError::invalid(image_field, e.to_string())
        }
    })
}
