//! Input helpers shared by the mask-based grid operations (`grid.edt`,
//! `grid.segment`, `grid.skeleton`, `grid.offset`, `grid.plan`): fetch a
//! dataset, check its shape, resolve the spacing, build the grid, and turn
//! core errors into [`OpError`]s that name the request field.

use crate::numerics::{Grid, GridError};
use crate::ops::{InputArray, Inputs, OpError, OpLimits};
use std::collections::HashMap;

/// The dataset `id` named by `field`.
pub fn fetch(inputs: &dyn Inputs, field: &str, id: &str) -> Result<InputArray, OpError> {
    inputs.get(id).ok_or_else(|| OpError::UnknownDataset {
        field: field.into(),
        id: id.into(),
    })
}

/// Checks that `shape` is a 2D or 3D grid within the limits.
pub fn check_shape(shape: &[usize], field: &str, limits: &OpLimits) -> Result<(), OpError> {
    if !(2..=3).contains(&shape.len()) {
        return Err(OpError::invalid(
            field,
            format!("the grid must be 2D or 3D, got {} axes", shape.len()),
        ));
    }
    if let Some(k) = shape.iter().position(|&n| n == 0) {
        return Err(OpError::invalid(
            format!("{field}[{k}]"),
            "an axis has length 0",
        ));
    }
    // Three axes of up to 2^64 overflow even u128: saturate.
    let cells = shape
        .iter()
        .fold(1u128, |a, &n| a.saturating_mul(n as u128));
    if cells > limits.max_cells as u128 {
        let count = if cells == u128::MAX {
            "more than 3.4e38".to_string()
        } else {
            cells.to_string()
        };
        return Err(OpError::TooLarge {
            field: field.into(),
            reason: format!("{count} cells, more than the limit of {}", limits.max_cells),
        });
    }
    Ok(())
}

/// Checks a requested spacing (finite, > 0).
pub fn check_spacing(spacing: &Option<Vec<f64>>) -> Result<(), OpError> {
    if let Some(spacing) = spacing {
        if let Some(k) = spacing.iter().position(|h| !(h.is_finite() && *h > 0.0)) {
            return Err(OpError::invalid(
                format!("spacing[{k}]"),
                format!("{} must be finite and > 0", spacing[k]),
            ));
        }
    }
    Ok(())
}

/// The grid of `input` (checked against the limits), with the request's
/// spacing, else the dataset's, else 1.
pub fn grid_of(
    input: &InputArray,
    field: &str,
    spacing: &Option<Vec<f64>>,
    limits: &OpLimits,
) -> Result<Grid, OpError> {
    let shape = input.array.shape().to_vec();
    check_shape(&shape, field, limits)?;
    let spacing = spacing
        .clone()
        .or_else(|| input.spacing.clone())
        .unwrap_or_else(|| vec![1.0; shape.len()]);
    Grid::new(&shape, &spacing).map_err(|e| match e {
        GridError::Spacing { axis, .. } => {
            OpError::invalid(format!("spacing[{axis}]"), e.to_string())
        }
        GridError::SpacingLength { .. } => OpError::invalid("spacing", e.to_string()),
        _ => OpError::invalid(field, e.to_string()),
    })
}

/// A mask dataset of the grid's shape: true where the value is non-zero.
pub fn mask_of(input: &InputArray, field: &str, grid: &Grid) -> Result<Vec<bool>, OpError> {
    if input.array.shape() != grid.shape() {
        return Err(OpError::invalid(
            field,
            format!(
                "the dataset has shape {:?} but the grid has shape {:?}",
                input.array.shape(),
                grid.shape()
            ),
        ));
    }
    if !input.array.is_empty() && input.array.get_f64(0).is_none() {
        return Err(OpError::invalid(
            field,
            "the dataset is not in standard layout",
        ));
    }
    if (0..input.array.len()).any(|i| input.array.get_f64(i).is_some_and(f64::is_nan)) {
        return Err(OpError::invalid(field, "a mask cannot hold NaN"));
    }
    Ok(input.array.to_mask())
}

/// A point (index coordinates, one per axis, finite) named by `field`.
pub fn check_point(p: &[f64], field: &str, ndim: Option<usize>) -> Result<(), OpError> {
    if let Some(k) = p.iter().position(|v| !v.is_finite()) {
        return Err(OpError::invalid(
            format!("{field}[{k}]"),
            "coordinates must be finite",
        ));
    }
    if !(2..=3).contains(&p.len()) || ndim.is_some_and(|d| d != p.len()) {
        return Err(OpError::invalid(
            field,
            format!(
                "a point has {} coordinates but the grid has {} axes",
                p.len(),
                ndim.map_or("2 or 3".to_string(), |d| d.to_string())
            ),
        ));
    }
    Ok(())
}

/// An f64 option that must be finite and >= 0.
pub fn check_non_negative(v: f64, field: &str) -> Result<(), OpError> {
    if !(v.is_finite() && v >= 0.0) {
        return Err(OpError::invalid(
            field,
            format!("{v} must be finite and >= 0"),
        ));
    }
    Ok(())
}

/// A flat vector in the grid's shape as an `ndarray` array.
pub fn shaped<T>(grid: &Grid, v: Vec<T>) -> Result<ndarray::ArrayD<T>, OpError> {
    ndarray::ArrayD::from_shape_vec(grid.shape().to_vec(), v)
        .map_err(|e| OpError::invalid("shape", e.to_string()))
}

/// Copies the datasets a request names into a map that solver threads can share.
pub fn preload(
    inputs: &dyn Inputs,
    ids: &[(String, String)],
) -> Result<HashMap<String, InputArray>, OpError> {
    let mut map = HashMap::new();
    for (field, id) in ids {
        map.insert(id.clone(), fetch(inputs, field, id)?);
    }
    Ok(map)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Schemathesis sent `[2^56, 4.96e17, 11509]` to `grid.tomography`: a
    /// product beyond `u128` panicked (500). It is a 413 naming the field.
    #[test]
    fn a_shape_beyond_u128_is_too_large_not_a_panic() {
        let limits = OpLimits::default();
        let shape = [72057594037927935, 496387267883029248, 11509];
        match check_shape(&shape, "shape", &limits) {
            Err(OpError::TooLarge { field, reason }) => {
                assert_eq!(field, "shape");
                assert!(reason.contains("more than 3.4e38"), "{reason}");
            }
            other => panic!("{other:?}"),
        }
        let huge = [usize::MAX, usize::MAX, usize::MAX];
        assert!(check_shape(&huge, "shape", &limits).is_err());
        assert!(crate::numerics::Grid::unit(&huge).is_err());
    }
}
