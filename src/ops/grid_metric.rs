//! `grid.metric`: the metric of a `cost` section (most often `W` designed
//! from an image or a volume: intensity, edges, vesselness) or of a tensor
//! `metric` section, returned as a dataset to look at. The sections are the
//! shared ones ([`crate::ops::spec::cost`], [`crate::ops::spec::design`],
//! [`crate::ops::spec::tensor`]).

use std::time::Instant;

use ndarray::ArrayD;
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::spec::cost::{resolve_cost, CostSpec};
pub use super::spec::design::{
    apply_design, array_to_f64, DesignSpec, EdgeModeSpec, EdgesSpec, IntensitySpec, PolaritySpec,
    VesselnessSpec,
};
use super::spec::grid::check_spacing;
use super::spec::scheme::{check_metric_choice, metric_dataset_ids, ConnectivitySpec, MethodSpec};
use super::spec::tensor::{per_cell, resolve_tensor, TensorSpec};
use super::{Inputs, OpError, OpLimits, OpOutput, Operation, OutputArray};
use crate::io::ArrayData;
use crate::numerics::Control;

/// Request of `grid.metric` (`POST /v1/grid/metric`): the metric a `cost`
/// or `metric` section describes, as a dataset (f64, the grid's shape and
/// spacing; a tensor field with a trailing axis of 3 or 6 components).
/// The sections are those of every other operation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({
    "cost": {"dataset": "ds_0192f1b27c1e7d3a9d553c0f2b8a1e45",
             "design": {"kind": "vesselness", "scales": [1.0, 2.0], "polarity": "dark"}}
}))]
pub struct GridMetricRequest {
    /// The isotropic metric, as in `grid.distance` (an image with a
    /// `design`, a cost or speed dataset, a constant over a shape). The
    /// answer is `W` per cell. Give exactly one of `cost` and `metric`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cost: Option<CostSpec>,
    /// A Riemannian metric (tensor field), as in `grid.distance`. The answer
    /// is its components per cell. Give exactly one of `cost` and `metric`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub metric: Option<TensorSpec>,
    /// Physical size of a cell per axis. Default: the dataset's spacing, else 1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(min_items = 2, max_items = 3)]
    pub spacing: Option<Vec<f64>>,
}

/// Statistics of a designed metric.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct MetricStats {
    /// Smallest `W` (a `cost`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min: Option<f64>,
    /// Largest `W` (a `cost`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max: Option<f64>,
    /// Mean `W` (a `cost`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mean: Option<f64>,
    /// Largest anisotropy ratio `sqrt(λmax/λmin)` (a tensor `metric`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_anisotropy: Option<f64>,
    /// Seconds spent designing.
    pub design_seconds: f64,
}

impl Operation for GridMetricRequest {
    const NAME: &'static str = "grid.metric";

    fn validate(&self, limits: &OpLimits) -> Result<(), OpError> {
        check_metric_choice(
            self.cost.as_ref(),
            self.metric.as_ref(),
            MethodSpec::FastMarching,
            ConnectivitySpec::default(),
            limits,
        )?;
        check_spacing(&self.spacing)
    }

    fn dataset_ids(&self) -> Vec<(String, String)> {
        metric_dataset_ids(self.cost.as_ref(), self.metric.as_ref())
    }

    /// Arrays: `metric` (f64: `W`, or the tensor's components). Document:
    /// `{"stats": MetricStats}`.
    fn run(
        &self,
        inputs: &dyn Inputs,
        limits: &OpLimits,
        control: &Control<'_>,
    ) -> Result<OpOutput, OpError> {
        Operation::validate(self, limits)?;
        let started = Instant::now();
        let (shape, spacing, values, stats) = match (&self.cost, &self.metric) {
            (Some(cost), _) => {
                let resolved =
                    resolve_cost(cost, self.spacing.as_deref(), None, inputs, limits, control)?;
                let w = resolved.cost_values()?;
                let (min, max, sum) = w
                    .iter()
                    .fold((f64::INFINITY, 0.0f64, 0.0), |(a, b, s), &v| {
                        (a.min(v), b.max(v), s + v)
                    });
                let stats = MetricStats {
                    min: Some(min),
                    max: Some(max),
                    mean: Some(sum / w.len() as f64),
                    max_anisotropy: None,
                    design_seconds: started.elapsed().as_secs_f64(),
                };
                (resolved.grid.shape().to_vec(), resolved.spacing, w, stats)
            }
            (None, Some(metric)) => {
                let resolved = resolve_tensor(
                    metric,
                    "metric",
                    self.spacing.as_deref(),
                    None,
                    inputs,
                    limits,
                    control,
                )?;
                let n = resolved.grid.len();
                let mut shape = resolved.grid.shape().to_vec();
                let values = resolved.metric.to_components(n);
                let stats = MetricStats {
                    min: None,
                    max: None,
                    mean: None,
                    max_anisotropy: Some(resolved.metric.max_anisotropy(n)),
                    design_seconds: started.elapsed().as_secs_f64(),
                };
                shape.push(per_cell(shape.len()));
                (shape, resolved.spacing, values, stats)
            }
            (None, None) => return Err(OpError::invalid("cost", "missing")),
        };
        let array = ArrayD::from_shape_vec(ndarray::IxDyn(&shape), values)
            .map_err(|e| OpError::invalid("cost", e.to_string()))?;
        Ok(OpOutput::new(
            vec![OutputArray {
                name: "metric".into(),
                array: ArrayData::F64(array),
                spacing: Some(spacing),
            }],
            serde_json::json!({ "stats": stats }),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ops::InputArray;
    use std::collections::HashMap;
    use std::sync::Arc;

    #[test]
    fn design_sections_parse_with_defaults_and_refuse_unknown_fields() {
        let d: DesignSpec = serde_json::from_str(r#"{"kind": "edges"}"#).unwrap();
        assert_eq!(
            d,
            DesignSpec::Edges(EdgesSpec {
                sigma: 1.0,
                power: 1.0,
                epsilon: 0.01,
                mode: EdgeModeSpec::Follow
            })
        );
        assert!(serde_json::from_str::<DesignSpec>(r#"{"kind": "edges", "sgima": 2}"#).is_err());
        assert!(serde_json::from_str::<DesignSpec>(r#"{"kind": "blobs"}"#).is_err());
        let v: DesignSpec =
            serde_json::from_str(r#"{"kind": "vesselness", "scales": []}"#).unwrap();
        assert_eq!(
            v.validate("cost.design").unwrap_err().field(),
            Some("cost.design.scales")
        );
        let i: DesignSpec =
            serde_json::from_str(r#"{"kind": "intensity", "epsilon": -1}"#).unwrap();
        assert_eq!(
            i.validate("design").unwrap_err().field(),
            Some("design.epsilon")
        );
    }

    #[test]
    fn metric_operation_returns_w_and_names_bad_points() {
        let image =
            ArrayD::from_shape_vec(ndarray::IxDyn(&[2, 3]), vec![0u8, 50, 100, 150, 200, 250])
                .unwrap();
        let mut inputs = HashMap::new();
        inputs.insert(
            "img".to_string(),
            InputArray {
                array: Arc::new(ArrayData::U8(image)),
                spacing: None,
            },
        );
        let req: GridMetricRequest = serde_json::from_value(serde_json::json!({
            "cost": {"dataset": "img", "design": {"kind": "intensity", "value": 250}}
        }))
        .unwrap();
        let out = req
            .run(&inputs, &OpLimits::default(), &Control::new())
            .unwrap();
        let ArrayData::F64(w) = &out.arrays[0].array else {
            panic!("f64 expected")
        };
        assert!((w[[0, 0]] - 1.01).abs() < 1e-12 && (w[[1, 2]] - 0.01).abs() < 1e-12);
        let req: GridMetricRequest = serde_json::from_value(serde_json::json!({
            "cost": {"dataset": "img", "design": {"kind": "intensity", "at": [5.0, 0.0]}}
        }))
        .unwrap();
        let err = req
            .run(&inputs, &OpLimits::default(), &Control::new())
            .unwrap_err();
        assert_eq!(err.field(), Some("cost.design.at"));
    }
}
