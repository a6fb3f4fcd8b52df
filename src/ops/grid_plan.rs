//! `grid.plan`: a collision-free shortest path for a disc (ball) robot of
//! radius `ρ` among obstacle cells (see [`crate::numerics::planning`]).
//!
//! When no path exists the answer is a 422 problem on `radius` that says so
//! and gives the widest robot that could pass; a start or goal where the
//! robot does not fit is a 422 on that field.

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::spec::grid::{
    check_non_negative, check_point, check_spacing, fetch, grid_of, mask_of, shaped,
};
use super::{Inputs, OpError, OpLimits, OpOutput, Operation, OutputArray};
use crate::io::ArrayData;
use crate::numerics::edt::EdtError;
use crate::numerics::planning::{self, PlanError};
use crate::numerics::{Control, EikonalError};

/// Request of `grid.plan` (`POST /v1/grid/plan`, `geodex plan`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"obstacles": "ds_0192f1b27c1e7d3a9d553c0f2b8a1e45", "radius": 3.0,
    "start": [10, 5], "goal": [50, 55]}))]
pub struct GridPlanRequest {
    /// Id of a 2D or 3D mask dataset whose non-zero cells are obstacles.
    pub obstacles: String,
    /// Radius of the robot, physical units (0: a point robot).
    #[schema(minimum = 0.0)]
    pub radius: f64,
    /// Start cell, index coordinates (axis 0 first; rounded to the nearest cell).
    #[schema(min_items = 2, max_items = 3)]
    pub start: Vec<f64>,
    /// Goal cell, index coordinates.
    #[schema(min_items = 2, max_items = 3)]
    pub goal: Vec<f64>,
    /// Physical size of a cell along each axis. Default: the dataset's, else 1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(min_items = 2, max_items = 3)]
    pub spacing: Option<Vec<f64>>,
}

impl GridPlanRequest {
    fn check(&self) -> Result<(), OpError> {
        check_spacing(&self.spacing)?;
        check_non_negative(self.radius, "radius")?;
        check_point(&self.start, "start", None)?;
        check_point(&self.goal, "goal", None)
    }
}

impl Operation for GridPlanRequest {
    const NAME: &'static str = "grid.plan";

    fn validate(&self, _limits: &OpLimits) -> Result<(), OpError> {
        self.check()
    }

    fn dataset_ids(&self) -> Vec<(String, String)> {
        vec![("obstacles".into(), self.obstacles.clone())]
    }

    /// Arrays: `clearance` (f64, distance to the nearest obstacle cell),
    /// `distance` (f64, to the goal in the free space). Document: `{"path":
    /// [[i, j(, k)], ...] from start to goal, "euclidean_length", "min_clearance", "radius", "widest_radius"}`.
    fn run(
        &self,
        inputs: &dyn Inputs,
        limits: &OpLimits,
        control: &Control<'_>,
    ) -> Result<OpOutput, OpError> {
        self.check()?;
        let input = fetch(inputs, "obstacles", &self.obstacles)?;
        let grid = grid_of(&input, "obstacles", &self.spacing, limits)?;
        let obstacles = mask_of(&input, "obstacles", &grid)?;
        check_point(&self.start, "start", Some(grid.ndim()))?;
        check_point(&self.goal, "goal", Some(grid.ndim()))?;
        let p = planning::plan(
            &grid,
            &obstacles,
            self.radius,
            &self.start,
            &self.goal,
            control,
        )
        .map_err(|e| match e {
            PlanError::Edt(EdtError::Cancelled) | PlanError::Eikonal(EikonalError::Cancelled) => {
                OpError::Cancelled
            }
            PlanError::Point { which, reason } => OpError::invalid(which, reason),
            PlanError::Blocked { which, .. } => OpError::invalid(which, e.to_string()),
            PlanError::Radius(_) | PlanError::NoPath { .. } => {
                OpError::invalid("radius", e.to_string())
            }
            other => OpError::invalid("obstacles", other.to_string()),
        })?;
        let spacing = Some(grid.spacing().to_vec());
        Ok(OpOutput::new(
            vec![
                OutputArray {
                    name: "clearance".into(),
                    array: ArrayData::F64(shaped(&grid, p.clearance)?),
                    spacing: spacing.clone(),
                },
                OutputArray {
                    name: "distance".into(),
                    array: ArrayData::F64(shaped(&grid, p.distance)?),
                    spacing,
                },
            ],
            serde_json::json!({
                "path": p.path,
                "euclidean_length": p.length,
                "min_clearance": p.min_clearance,
                "radius": self.radius,
                "widest_radius": p.widest,
            }),
        ))
    }
}
