//! `grid.distance`: the geodesic distance map `U` (and Voronoi labels) of an
//! isotropic cost or a tensor metric on a 2D or 3D grid. The request and its
//! solve are the shared distance section ([`crate::ops::spec::distance`]);
//! this file makes it an operation.

use super::spec::distance::execute_sharing;
pub use super::spec::distance::{execute, GridDistanceRequest, GridDistanceResult, SolveStats};
use super::{Inputs, OpError, OpLimits, OpOutput, Operation, OutputArray};
use crate::io::ArrayData;
use crate::numerics::Control;

impl Operation for GridDistanceRequest {
    const NAME: &'static str = "grid.distance";

    fn validate(&self, limits: &OpLimits) -> Result<(), OpError> {
        GridDistanceRequest::validate(self, limits)
    }

    fn dataset_ids(&self) -> Vec<(String, String)> {
        GridDistanceRequest::dataset_ids(self)
    }

    /// Arrays: `distance` (f64), `labels` (i32, unless `outputs.labels` is
    /// false), `frozen_order` (i64, when asked for). Document: `{"stats": SolveStats}`.
    fn run(
        &self,
        inputs: &dyn Inputs,
        limits: &OpLimits,
        control: &Control<'_>,
    ) -> Result<OpOutput, OpError> {
        // The map is shared with the paths that follow (see `execute_sharing`).
        let result = execute_sharing(self, inputs, limits, control, true)?;
        let spacing = Some(result.spacing.clone());
        let mut arrays = vec![OutputArray {
            name: "distance".into(),
            array: ArrayData::F64(result.distance),
            spacing: spacing.clone(),
        }];
        if let Some(labels) = result.labels {
            arrays.push(OutputArray {
                name: "labels".into(),
                array: ArrayData::I32(labels),
                spacing: spacing.clone(),
            });
        }
        if let Some(order) = result.frozen_order {
            arrays.push(OutputArray {
                name: "frozen_order".into(),
                array: ArrayData::I64(order),
                spacing,
            });
        }
        let document = serde_json::json!({ "stats": result.stats });
        Ok(OpOutput::new(arrays, document))
    }
}
