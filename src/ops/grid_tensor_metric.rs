//! `grid.tensor_metric`: the tensor field a `tensor` section describes, as a
//! dataset (to inspect a structure-tensor or height-map design, or to reuse
//! it in later requests as `{"kind": "components", "dataset": ...}`).

use ndarray::{ArrayD, IxDyn};
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::spec::tensor::{per_cell, TensorSpec};
use super::{Inputs, OpError, OpLimits, OpOutput, Operation, OutputArray};
use crate::io::ArrayData;
use crate::numerics::{Control, Grid};

/// Request of `grid.tensor_metric` (`POST /v1/grid/tensor-metric`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({
    "metric": {"kind": "energy_anisotropy", "shape": [64, 64], "energy": 1.0, "anisotropy": 0.9, "angle": 0.5}
}))]
pub struct GridTensorMetricRequest {
    /// The metric tensor field (the `metric` section of `grid.distance`).
    pub metric: TensorSpec,
    /// Physical size of a cell along each axis (used by the designs that
    /// differentiate or smooth). Default: the spacing of the input dataset, else 1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(min_items = 2, max_items = 3)]
    pub spacing: Option<Vec<f64>>,
}

impl Operation for GridTensorMetricRequest {
    const NAME: &'static str = "grid.tensor_metric";

    fn validate(&self, limits: &OpLimits) -> Result<(), OpError> {
        self.metric.validate("metric", limits)?;
        if let Some(spacing) = &self.spacing {
            if let Some(k) = spacing.iter().position(|h| !(h.is_finite() && *h > 0.0)) {
                return Err(OpError::invalid(
                    format!("spacing[{k}]"),
                    format!("{} must be finite and > 0", spacing[k]),
                ));
            }
        }
        Ok(())
    }

    fn dataset_ids(&self) -> Vec<(String, String)> {
        self.metric.dataset_ids("metric")
    }

    /// Arrays: `tensor` (f64, the grid shape plus a trailing axis of 3 or 6).
    /// Document: `{"stats": {"cells", "max_anisotropy"}}`.
    fn run(
        &self,
        inputs: &dyn Inputs,
        limits: &OpLimits,
        control: &Control<'_>,
    ) -> Result<OpOutput, OpError> {
        self.validate(limits)?;
        let shape = self.metric.shape(inputs, "metric", limits)?;
        let spacing = self
            .spacing
            .clone()
            .or_else(|| self.metric.dataset_spacing(inputs))
            .unwrap_or_else(|| vec![1.0; shape.len()]);
        let grid =
            Grid::new(&shape, &spacing).map_err(|e| OpError::invalid("spacing", e.to_string()))?;
        let field = self.metric.build(&grid, inputs, "metric", control)?;
        if control.is_cancelled() {
            return Err(OpError::Cancelled);
        }
        let values = field.to_components(grid.len());
        let mut full = shape.clone();
        full.push(per_cell(shape.len()));
        let array = ArrayD::from_shape_vec(IxDyn(&full), values)
            .map_err(|e| OpError::invalid("metric", e.to_string()))?;
        Ok(OpOutput::new(
            vec![OutputArray {
                name: "tensor".into(),
                array: ArrayData::F64(array),
                spacing: None,
            }],
            serde_json::json!({
                "stats": {"cells": grid.len(), "max_anisotropy": field.max_anisotropy(grid.len())}
            }),
        ))
    }
}
