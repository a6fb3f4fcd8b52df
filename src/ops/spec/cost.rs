//! The `cost` section: an isotropic cost `W` (or speed `F = 1/W`) given as
//! a dataset, a constant over a shape, or designed from an image, and how it
//! becomes a validated grid and values ([`resolve_cost`]). Shared by every
//! operation that takes a `cost`.

use std::borrow::Cow;
use std::sync::Arc;

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::design::{apply_design, array_to_f64, DesignSpec};
use super::errors::grid_error;
use super::grid::{check_shape, fetch};
use crate::io::ArrayData;
use crate::numerics::metric::{CostValues, Interpretation, IsotropicCost, MetricError};
use crate::numerics::{Control, Grid};
use crate::ops::{Inputs, OpError, OpLimits};

/// The cost `W` (cost per unit length, > 0) or speed `F = 1/W`. Give either
/// `dataset` or `constant` with `shape`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct CostSpec {
    /// Id of a 2D or 3D dataset holding one value per cell.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dataset: Option<String>,
    /// A constant value on every cell.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub constant: Option<f64>,
    /// Grid shape (2 or 3 axes) for a constant cost.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(min_items = 2, max_items = 3)]
    pub shape: Option<Vec<usize>>,
    /// Whether the values are a cost `W` (default) or a speed `F = 1/W`.
    #[serde(default)]
    pub interpretation: InterpretationSpec,
    /// Build the cost from the image named by `dataset` instead of reading
    /// it as a cost (intensity, edges or vesselness; see `grid.metric`).
    /// Needs `dataset` and `interpretation: cost`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub design: Option<DesignSpec>,
}

impl CostSpec {
    /// Checks everything that does not need the input arrays. Fields are
    /// named under `cost` (`cost.constant`, `cost.design.epsilon`).
    pub fn validate(&self, limits: &OpLimits) -> Result<(), OpError> {
        match (&self.dataset, self.constant, &self.shape) {
            (Some(_), None, None) => {}
            (None, Some(c), Some(shape)) => {
                if !(c.is_finite() && c > 0.0) {
                    return Err(OpError::invalid(
                        "cost.constant",
                        format!("{c} must be finite and > 0"),
                    ));
                }
                check_shape(shape, "cost.shape", limits)?;
            }
            (Some(_), _, _) => {
                return Err(OpError::invalid(
                    "cost",
                    "give either `dataset`, or `constant` with `shape`, not both",
                ))
            }
            (None, Some(_), None) => {
                return Err(OpError::invalid(
                    "cost.shape",
                    "a constant cost needs the grid shape",
                ))
            }
            (None, None, _) => {
                return Err(OpError::invalid(
                    "cost",
                    "give either `dataset`, or `constant` with `shape`",
                ))
            }
        }
        if let Some(design) = &self.design {
            if self.dataset.is_none() {
                return Err(OpError::invalid(
                    "cost.design",
                    "a design needs the image in `cost.dataset`",
                ));
            }
            if self.interpretation != InterpretationSpec::Cost {
                return Err(OpError::invalid(
                    "cost.interpretation",
                    "a designed metric is a cost; leave `interpretation` out",
                ));
            }
            design.validate("cost.design")?;
        }
        Ok(())
    }
}

/// Where the values of a [`ResolvedCost`] live.
#[derive(Debug, Clone)]
enum ResolvedValues {
    Constant(f64),
    /// An f32 or f64 dataset, shared with the caller (no copy).
    Shared(Arc<ArrayData>),
    /// Converted (integer datasets) or designed values.
    Owned(Vec<f64>),
}

/// A cost resolved from a [`CostSpec`] and its datasets: the grid, the
/// spacing that was used, and the (validated) values and walls, owned so
/// that the caller can keep it (caches) and borrow an [`IsotropicCost`]
/// from it with [`ResolvedCost::isotropic`].
#[derive(Debug, Clone)]
pub struct ResolvedCost {
    /// The grid (shape and spacing).
    pub grid: Grid,
    /// The spacing, per caller axis.
    pub spacing: Vec<f64>,
    values: ResolvedValues,
    interpretation: Interpretation,
    mask: Option<Vec<bool>>,
    from_dataset: bool,
}

impl ResolvedCost {
    /// The cost as the core takes it (borrowing the values; checked when resolved).
    pub fn isotropic(&self) -> Result<IsotropicCost<'_>, OpError> {
        let values = match &self.values {
            ResolvedValues::Constant(c) => CostValues::Constant(*c),
            ResolvedValues::Owned(v) => CostValues::F64(Cow::Borrowed(v)),
            ResolvedValues::Shared(a) => a.as_cost_values().ok_or_else(|| {
                OpError::invalid(
                    "cost.dataset",
                    format!("a {:?} array cannot be a cost", a.dtype()),
                )
            })?,
        };
        IsotropicCost::new(
            &self.grid,
            values,
            self.interpretation,
            self.mask.as_deref().map(Cow::Borrowed),
        )
        .map_err(|e| metric_error(e, self.from_dataset))
    }

    /// The cost `W` of every cell (`+inf` on walls), as a new vector.
    pub fn cost_values(&self) -> Result<Vec<f64>, OpError> {
        let cost = self.isotropic()?;
        Ok((0..self.grid.len()).map(|i| cost.at(i)).collect())
    }
}

/// Resolves a [`CostSpec`] against its datasets: validates it, looks up
/// `cost.dataset` and the `obstacles` mask in `inputs`, applies the
/// `design` if any, and checks every value. `spacing` is the request's
/// spacing (default: the dataset's, else 1). This is the grid and cost
/// construction of `grid.distance`, shared by every operation that takes a
/// `cost` (paths, segmentation). Errors name `cost.*`, `obstacles`, `spacing`.
pub fn resolve_cost(
    cost: &CostSpec,
    spacing: Option<&[f64]>,
    obstacles: Option<&str>,
    inputs: &dyn Inputs,
    limits: &OpLimits,
    control: &Control<'_>,
) -> Result<ResolvedCost, OpError> {
    cost.validate(limits)?;
    let cost_input = match &cost.dataset {
        Some(id) => Some(fetch(inputs, "cost.dataset", id)?),
        None => None,
    };
    let shape: Vec<usize> = match (&cost_input, &cost.shape) {
        (Some(input), _) => {
            let shape = input.array.shape().to_vec();
            check_shape(&shape, "cost.dataset", limits)?;
            shape
        }
        (None, Some(shape)) => shape.clone(),
        (None, None) => return Err(OpError::invalid("cost.shape", "missing")),
    };
    let spacing = spacing
        .map(<[f64]>::to_vec)
        .or_else(|| cost_input.as_ref().and_then(|c| c.spacing.clone()))
        .unwrap_or_else(|| vec![1.0; shape.len()]);
    let grid = Grid::new(&shape, &spacing).map_err(|e| grid_error(e, &shape))?;

    let mask = match obstacles {
        Some(id) => {
            let m = fetch(inputs, "obstacles", id)?;
            if m.array.shape() != shape.as_slice() {
                return Err(OpError::invalid(
                    "obstacles",
                    format!(
                        "the mask has shape {:?} but the grid has shape {:?}",
                        m.array.shape(),
                        shape
                    ),
                ));
            }
            Some(m.array.to_mask())
        }
        None => None,
    };
    let interpretation = match cost.interpretation {
        InterpretationSpec::Cost => Interpretation::Cost,
        InterpretationSpec::Speed => Interpretation::Speed,
    };
    let values = match (&cost_input, cost.constant, &cost.design) {
        (Some(input), _, Some(design)) => ResolvedValues::Owned(apply_design(
            &grid,
            &input.array,
            design,
            "cost.design",
            "cost.dataset",
            control,
        )?),
        (Some(input), _, None) => match &*input.array {
            ArrayData::F32(_) | ArrayData::F64(_) => ResolvedValues::Shared(input.array.clone()),
            ArrayData::Bool(_) => {
                return Err(OpError::invalid(
                    "cost.dataset",
                    format!("a {:?} array cannot be a cost", input.array.dtype()),
                ))
            }
            other => ResolvedValues::Owned(array_to_f64(other)),
        },
        (None, Some(c), _) => ResolvedValues::Constant(c),
        (None, None, _) => return Err(OpError::invalid("cost", "missing")),
    };
    let resolved = ResolvedCost {
        grid,
        spacing,
        values,
        interpretation,
        mask,
        from_dataset: cost_input.is_some(),
    };
    resolved.isotropic()?;
    Ok(resolved)
}

/// How to read the values of the cost.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum InterpretationSpec {
    /// Cost per unit length `W`: +inf marks a wall, NaN and values <= 0 are refused.
    #[default]
    Cost,
    /// Speed `F = 1/W`: 0 marks a wall, NaN, negative and infinite values are refused.
    Speed,
}

/// The way out for a dataset used as a cost with pixels `<= 0` (a
/// photograph's black pixels, most often): the two fixes that work.
const ZERO_PIXEL_FIXES: &str = "an image is not a cost as it stands: take it as a speed \
     (`\"interpretation\": \"speed\"`: bright is fast, 0 is a wall), or derive a positive cost \
     from it with a `design` (`{\"kind\": \"edges\"}` follows contours, \
     `{\"kind\": \"intensity\", \"value\": ...}` follows a grey value; each keeps the cost above \
     its floor `epsilon`)";

fn metric_error(e: MetricError, from_dataset: bool) -> OpError {
    let field = match e {
        MetricError::MaskLength { .. } => "obstacles",
        MetricError::Constant(_) => "cost.constant",
        _ if from_dataset => "cost.dataset",
        _ => "cost",
    };
    match e {
        MetricError::BadValue {
            kind: "cost",
            value,
            ..
        } if from_dataset && value <= 0.0 => {
            OpError::invalid(field, format!("{e}; {ZERO_PIXEL_FIXES}"))
        }
        _ => OpError::invalid(field, e.to_string()),
    }
}
