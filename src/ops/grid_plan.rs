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
use crate::io::canvas::{mix, Canvas};
use crate::io::mesh_picture::magnification;
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
    /// `distance` (f64, to the goal in the free space), in 2D `picture` (u8
    /// RGB, see [`plan_picture`]). Document: `{"path":
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
        let mut arrays = Vec::new();
        if grid.ndim() == 2 {
            let shape = grid.shape();
            let picture = plan_picture(
                [shape[0], shape[1]],
                &obstacles,
                &p.clearance,
                self.radius,
                &p.path,
            )
            .to_array()
            .map_err(|e| OpError::invalid("obstacles", e.to_string()))?;
            arrays.push(OutputArray {
                name: "picture".into(),
                array: picture,
                spacing: None,
            });
        }
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
            ]
            .into_iter()
            .chain(arrays)
            .collect(),
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

/// Colour of obstacle cells in [`plan_picture`].
pub const OBSTACLE: [u8; 3] = [60, 60, 60];
/// Colour of free cells where the robot's centre cannot be (clearance below the radius).
pub const TOO_CLOSE: [u8; 3] = [245, 190, 190];
/// Colour of the path.
pub const PATH: [u8; 3] = [215, 25, 28];
/// Colour of the start marker.
pub const START: [u8; 3] = [30, 160, 60];
/// Colour of the goal marker.
pub const GOAL: [u8; 3] = [30, 90, 220];

/// The plan over the obstacles, for people to look at: cells magnified
/// `s = io::mesh_picture::magnification(rows, cols)` times; obstacles dark
/// grey, free cells the robot's centre cannot reach (clearance below the
/// radius) light red, the others from white (next to the forbidden band)
/// to light blue (the largest clearance); the path in red, the start a
/// green disc and the goal a blue one.
pub fn plan_picture(
    [rows, cols]: [usize; 2],
    obstacles: &[bool],
    clearance: &[f64],
    radius: f64,
    path: &[Vec<f64>],
) -> Canvas {
    let s = magnification(rows, cols);
    let mut c = Canvas::new(cols * s, rows * s, [255; 3]);
    let top = clearance
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .fold(0.0f64, f64::max);
    for r in 0..rows {
        for q in 0..cols {
            let i = r * cols + q;
            let colour = if obstacles[i] {
                OBSTACLE
            } else if clearance[i] < radius {
                TOO_CLOSE
            } else {
                let t = if top > radius {
                    (clearance[i] - radius) / (top - radius)
                } else {
                    0.0
                };
                mix([255; 3], [160, 195, 235], t)
            };
            c.fill_rect((q * s) as i64, (r * s) as i64, s, s, colour);
        }
    }
    let px = |p: &[f64]| [(p[1] + 0.5) * s as f64 - 0.5, (p[0] + 0.5) * s as f64 - 0.5];
    let width = (s as f64 / 3.0).max(0.5);
    for w in path.windows(2) {
        c.segment(px(&w[0]), px(&w[1]), width, PATH);
    }
    let marker = 2.0 + s as f64;
    for (p, colour) in [(path.first(), START), (path.last(), GOAL)] {
        if let Some(p) = p {
            let [x, y] = px(p);
            c.disc(x, y, marker + 1.0, [0; 3]);
            c.disc(x, y, marker, colour);
        }
    }
    c
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_plan_picture_shows_obstacles_path_and_ends() {
        // A 20 × 30 room with a wall at column 15, rows 0..12; the path
        // goes around it.
        let (rows, cols) = (20, 30);
        let obstacles: Vec<bool> = (0..rows * cols)
            .map(|i| i % cols == 15 && i / cols < 12)
            .collect();
        let clearance: Vec<f64> = (0..rows * cols)
            .map(|i| if obstacles[i] { 0.0 } else { 3.0 })
            .collect();
        let path = vec![vec![2.0, 2.0], vec![15.0, 15.0], vec![2.0, 28.0]];
        let c = plan_picture([rows, cols], &obstacles, &clearance, 1.0, &path);
        let s = magnification(rows, cols);
        assert_eq!((c.width, c.height), (cols * s, rows * s));
        let at = |r: f64, q: f64| {
            c.get(
                ((q + 0.5) * s as f64) as usize,
                ((r + 0.5) * s as f64) as usize,
            )
        };
        assert_eq!(at(5.0, 15.0), Some(OBSTACLE));
        assert_eq!(at(2.0, 2.0), Some(START));
        assert_eq!(at(2.0, 28.0), Some(GOAL));
        // Half way along the first leg, (8.5, 8.5), is on the path.
        assert_eq!(at(8.5, 8.5), Some(PATH));
        if std::env::var_os("GEODEX_PICS").is_some() {
            let _ = std::fs::create_dir_all("/tmp/pics");
            let _ = std::fs::write("/tmp/pics/plan.png", c.to_png().expect("png"));
        }
    }
}
