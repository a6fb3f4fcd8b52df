//! `grid.shape_embed`: the inner geodesic distances of a 2D or 3D shape
//! given as a mask, and its bending-invariant canonical form (see
//! [`crate::numerics::shape::mask`]): the embedded position of every cell of
//! the shape, optionally the distance rows, and in 2D the shape's pixel mesh
//! at the embedded positions.

use std::sync::Arc;
use std::time::Instant;

use ndarray::Array2;
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::spec::defaults::default_order;
use super::spec::grid::{check_spacing, fetch, grid_of, mask_of};
use super::spec::mesh::MeshInput;
use super::spec::shape::{check_size, matrix_output, shape_error};
use super::{Inputs, OpError, OpLimits, OpOutput, Operation, OutputArray, OutputMesh};
use crate::io::ArrayData;
use crate::numerics::eikonal::Order;
use crate::numerics::mesh::{Topology, TriMesh};
use crate::numerics::shape::mask::{cell_index, mask_embedding, pixel_faces};
use crate::numerics::Control;

fn two() -> usize {
    2
}

/// Request of `grid.shape_embed` (`POST /v1/grid/shape-embed`, `geodex shape-embed`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"mask": "ds_0192f1b27c1e7d3a9d553c0f2b8a1e45", "landmarks": 100}))]
pub struct GridShapeEmbedRequest {
    /// Id of a 2D or 3D mask dataset: the shape is its non-zero cells, in
    /// one piece (cells that touch only at a corner are apart).
    pub mask: String,
    /// Physical size of a cell along each axis. Default: the dataset's, else 1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(min_items = 2, max_items = 3)]
    pub spacing: Option<Vec<f64>>,
    /// Embedding dimension, 2 or 3. Default 2.
    #[serde(default = "two")]
    #[schema(minimum = 2, maximum = 3)]
    pub dimensions: usize,
    /// Farthest-point landmarks (landmark rows, landmark MDS). Default: all
    /// pairs (classical MDS), for shapes of up to 5000 cells.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(minimum = 4)]
    pub landmarks: Option<usize>,
    /// Fast-marching order of the inner distances, 1 or 2. Default 2.
    #[serde(default = "default_order")]
    #[schema(minimum = 1, maximum = 2)]
    pub order: u8,
    /// Also return the distance rows (`landmarks × cells`, or all pairs) as
    /// the array `matrix`. Default false.
    #[serde(default)]
    pub matrix: bool,
}

impl GridShapeEmbedRequest {
    fn check(&self) -> Result<(), OpError> {
        check_spacing(&self.spacing)?;
        if !(2..=3).contains(&self.dimensions) {
            return Err(OpError::invalid("dimensions", "must be 2 or 3"));
        }
        if !(1..=2).contains(&self.order) {
            return Err(OpError::invalid(
                "order",
                format!("{} must be 1 or 2", self.order),
            ));
        }
        if let Some(k) = self.landmarks {
            if k <= self.dimensions {
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
}

impl Operation for GridShapeEmbedRequest {
    const NAME: &'static str = "grid.shape_embed";

    fn validate(&self, _limits: &OpLimits) -> Result<(), OpError> {
        self.check()
    }

    fn dataset_ids(&self) -> Vec<(String, String)> {
        vec![("mask".into(), self.mask.clone())]
    }

    /// Arrays: `coordinates` (`cells × dimensions`, f64), `cells` (`cells ×
    /// ndim`, i64: the index coordinates of each embedded cell, axis 0
    /// first), `matrix` when asked. In 2D a mesh `result`: the pixel mesh
    /// (see [`pixel_faces`]) at the embedded positions, vertex `p` being the
    /// cell `cells[p]`. Document: landmarks (index coordinates),
    /// explained variance, stress, residual variance, asymmetry, stats.
    fn run(
        &self,
        inputs: &dyn Inputs,
        limits: &OpLimits,
        control: &Control<'_>,
    ) -> Result<OpOutput, OpError> {
        self.check()?;
        let input = fetch(inputs, "mask", &self.mask)?;
        let grid = grid_of(&input, "mask", &self.spacing, limits)?;
        let mask = mask_of(&input, "mask", &grid)?;
        let n = mask.iter().filter(|&&m| m).count();
        check_size(n, self.landmarks, "mask")?;
        let started = Instant::now();
        let order = if self.order == 1 {
            Order::First
        } else {
            Order::Second
        };
        let e = mask_embedding(
            &grid,
            &mask,
            self.landmarks,
            self.dimensions,
            order,
            control,
        )
        .map_err(|e| shape_error(e, "mask"))?;
        let seconds = started.elapsed().as_secs_f64();
        let ndim = grid.ndim();
        let index: Vec<Vec<usize>> = e.rows.cells.iter().map(|&c| cell_index(&grid, c)).collect();
        let landmarks: Vec<&Vec<usize>> = if self.landmarks.is_some() {
            e.rows.sources.iter().map(|&s| &index[s as usize]).collect()
        } else {
            Vec::new()
        };
        let document = serde_json::json!({
            "dimensions": self.dimensions,
            "landmarks": landmarks,
            "explained_variance": e.embedding.explained_variance,
            "eigenvalues": e.embedding.eigenvalues,
            "stress": e.stress,
            "residual_variance": e.residual_variance,
            "asymmetry": e.rows.asymmetry,
            "stats": {"cells": n, "rows": e.rows.sources.len(), "solve_seconds": seconds},
        });
        let cells = Array2::from_shape_fn((n, ndim), |(p, a)| index[p][a] as i64);
        let mut arrays = vec![
            matrix_output("coordinates", e.embedding.coords.clone()),
            OutputArray {
                name: "cells".into(),
                array: ArrayData::I64(cells.into_dyn()),
                spacing: None,
            },
        ];
        let faces = pixel_faces(&grid, &e.rows.cells);
        if self.matrix {
            arrays.push(matrix_output("matrix", e.rows.rows));
        }
        let mut out = OpOutput::new(arrays, document);
        if !faces.is_empty() {
            let coords = &e.embedding.coords;
            let positions: Vec<[f64; 3]> = (0..n)
                .map(|p| {
                    let z = if self.dimensions == 3 {
                        coords[[p, 2]]
                    } else {
                        0.0
                    };
                    [coords[[p, 0]], coords[[p, 1]], z]
                })
                .collect();
            let mesh = TriMesh::new(positions, faces)
                .map_err(|e| OpError::invalid("mask", e.to_string()))?;
            let topology = Topology::new(&mesh);
            let report = crate::io::mesh::report_of(&mesh, &topology);
            out.mesh = Some(OutputMesh {
                name: "result".into(),
                mesh: Arc::new(MeshInput {
                    mesh,
                    topology,
                    report,
                }),
                vertex_properties: Vec::new(),
            });
        }
        Ok(out)
    }
}
