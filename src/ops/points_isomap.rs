//! `points.isomap`: Isomap of a point cloud given as an `N × D` array
//! dataset (see [`crate::numerics::shape::isomap`]): the `N × dimensions`
//! embedding, its residual and explained variance.

use std::time::Instant;

use ndarray::Array2;
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::spec::shape::{check_size, matrix_output, shape_error};
use super::{Inputs, OpError, OpLimits, OpOutput, Operation};
use crate::numerics::shape::isomap::{isomap, IsomapOptions};
use crate::numerics::Control;

fn ten() -> usize {
    10
}

fn two() -> usize {
    2
}

/// Request of `points.isomap` (`POST /v1/points/isomap`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"points": "ds_0192f1b27c1e7d3a9d553c0f2b8a1e44", "k": 10, "dimensions": 2}))]
pub struct PointsIsomapRequest {
    /// Id of an `N × D` array dataset: one point per row.
    pub points: String,
    /// Neighbours per point in the k-NN graph. Default 10.
    #[serde(default = "ten")]
    #[schema(minimum = 1)]
    pub k: usize,
    /// Embedding dimension. Default 2.
    #[serde(default = "two")]
    #[schema(minimum = 1)]
    pub dimensions: usize,
    /// Farthest-point landmarks (L-Isomap). Default: all pairs (up to 5000 points).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(minimum = 2)]
    pub landmarks: Option<usize>,
}

impl Operation for PointsIsomapRequest {
    const NAME: &'static str = "points.isomap";

    fn validate(&self, _limits: &OpLimits) -> Result<(), OpError> {
        if self.k == 0 {
            return Err(OpError::invalid("k", "must be >= 1"));
        }
        if self.dimensions == 0 {
            return Err(OpError::invalid("dimensions", "must be >= 1"));
        }
        if let Some(l) = self.landmarks {
            if l <= self.dimensions {
                return Err(OpError::invalid(
                    "landmarks",
                    format!(
                        "at least dimensions + 1 = {} landmarks are needed",
                        self.dimensions + 1
                    ),
                ));
            }
        }
        Ok(())
    }

    fn dataset_ids(&self) -> Vec<(String, String)> {
        vec![("points".to_string(), self.points.clone())]
    }

    fn run(
        &self,
        inputs: &dyn Inputs,
        limits: &OpLimits,
        control: &Control<'_>,
    ) -> Result<OpOutput, OpError> {
        self.validate(limits)?;
        let data = inputs
            .get(&self.points)
            .ok_or_else(|| OpError::UnknownDataset {
                field: "points".into(),
                id: self.points.clone(),
            })?;
        let shape = data.array.shape().to_vec();
        let [n, d] = shape[..] else {
            return Err(OpError::invalid(
                "points",
                format!("an N × D array is needed (one point per row), got shape {shape:?}"),
            ));
        };
        if n < 3 || d == 0 {
            return Err(OpError::invalid(
                "points",
                format!("at least 3 points of dimension >= 1, got {n} × {d}"),
            ));
        }
        if self.k >= n {
            return Err(OpError::invalid(
                "k",
                format!("must be less than the number of points ({n})"),
            ));
        }
        if self.dimensions >= n {
            return Err(OpError::invalid(
                "dimensions",
                format!("must be less than the number of points ({n})"),
            ));
        }
        check_size(n, self.landmarks, "points")?;
        let values: Vec<f64> = (0..n * d)
            .map(|i| data.array.get_f64(i).unwrap_or(f64::NAN))
            .collect();
        let points = Array2::from_shape_vec((n, d), values)
            .map_err(|e| OpError::invalid("points", e.to_string()))?;
        let started = Instant::now();
        let r = isomap(
            points.view(),
            &IsomapOptions {
                neighbours: self.k,
                dimensions: self.dimensions,
                landmarks: self.landmarks,
            },
            control,
        )
        .map_err(|e| shape_error(e, "points"))?;
        let document = serde_json::json!({
            "k": self.k,
            "dimensions": self.dimensions,
            "residual_variance": r.residual_variance,
            "explained_variance": r.embedding.explained_variance,
            "eigenvalues": r.embedding.eigenvalues,
            "landmarks": r.landmarks,
            "edges": r.edges,
            "stats": {"points": n, "solve_seconds": started.elapsed().as_secs_f64()},
        });
        Ok(OpOutput::new(
            vec![matrix_output("embedding", r.embedding.coords)],
            document,
        ))
    }
}
