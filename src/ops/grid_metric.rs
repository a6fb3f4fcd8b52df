//! `grid.metric`: the cost `W` designed from an image or a volume
//! (intensity, edges, vesselness), returned as a dataset to look at. The
//! `design` section itself is shared: [`crate::ops::spec::design`].

use std::time::Instant;

use ndarray::ArrayD;
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

pub use super::spec::design::{
    apply_design, array_to_f64, DesignSpec, EdgeModeSpec, EdgesSpec, IntensitySpec, PolaritySpec,
    VesselnessSpec,
};
use super::{Inputs, OpError, OpLimits, OpOutput, Operation, OutputArray};
use crate::io::ArrayData;
use crate::numerics::{Control, Grid};
use crate::ops::spec::errors::grid_error;
use crate::ops::spec::grid::check_shape;
use crate::ops::InputArray;

/// Request of `grid.metric` (`POST /v1/grid/metric`): the designed cost `W`
/// of an image, as a dataset (f64, same shape and spacing).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({
    "dataset": "ds_0192f1b27c1e7d3a9d553c0f2b8a1e45",
    "design": {"kind": "vesselness", "scales": [1.0, 2.0], "polarity": "dark"}
}))]
pub struct GridMetricRequest {
    /// Id of the 2D or 3D image.
    pub dataset: String,
    /// The design.
    pub design: DesignSpec,
    /// Physical size of a cell per axis. Default: the dataset's spacing, else 1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(min_items = 2, max_items = 3)]
    pub spacing: Option<Vec<f64>>,
}

/// Statistics of a designed metric.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct MetricStats {
    /// Smallest `W`.
    pub min: f64,
    /// Largest `W`.
    pub max: f64,
    /// Mean `W`.
    pub mean: f64,
    /// Seconds spent designing.
    pub design_seconds: f64,
}

impl Operation for GridMetricRequest {
    const NAME: &'static str = "grid.metric";

    fn validate(&self, limits: &OpLimits) -> Result<(), OpError> {
        let _ = limits;
        self.design.validate("design")?;
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
        vec![("dataset".into(), self.dataset.clone())]
    }

    /// Arrays: `metric` (f64, `W`). Document: `{"stats": MetricStats}`.
    fn run(
        &self,
        inputs: &dyn Inputs,
        limits: &OpLimits,
        control: &Control<'_>,
    ) -> Result<OpOutput, OpError> {
        Operation::validate(self, limits)?;
        let input: InputArray =
            inputs
                .get(&self.dataset)
                .ok_or_else(|| OpError::UnknownDataset {
                    field: "dataset".into(),
                    id: self.dataset.clone(),
                })?;
        let shape = input.array.shape().to_vec();
        check_shape(&shape, "dataset", limits)?;
        let spacing = self
            .spacing
            .clone()
            .or_else(|| input.spacing.clone())
            .unwrap_or_else(|| vec![1.0; shape.len()]);
        let grid = Grid::new(&shape, &spacing).map_err(|e| grid_error(e, &shape))?;
        let started = Instant::now();
        let w = apply_design(
            &grid,
            &input.array,
            &self.design,
            "design",
            "dataset",
            control,
        )?;
        let design_seconds = started.elapsed().as_secs_f64();
        let (min, max, sum) = w
            .iter()
            .fold((f64::INFINITY, 0.0f64, 0.0), |(a, b, s), &v| {
                (a.min(v), b.max(v), s + v)
            });
        let stats = MetricStats {
            min,
            max,
            mean: sum / w.len() as f64,
            design_seconds,
        };
        let array = ArrayD::from_shape_vec(ndarray::IxDyn(&shape), w)
            .map_err(|e| OpError::invalid("dataset", e.to_string()))?;
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
            "dataset": "img", "design": {"kind": "intensity", "value": 250}
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
            "dataset": "img", "design": {"kind": "intensity", "at": [5.0, 0.0]}
        }))
        .unwrap();
        let err = req
            .run(&inputs, &OpLimits::default(), &Control::new())
            .unwrap_err();
        assert_eq!(err.field(), Some("design.at"));
    }
}
