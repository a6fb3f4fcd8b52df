//! `grid.skeleton`: the medial axis of a binary shape (2D and 3D) with
//! pruning, its radius function, and in 2D the skeleton graph (see
//! [`crate::numerics::skeleton`]). In 2D the skeleton is one cell thin; in
//! 3D it is a curve skeleton (medial sheets thinned to curves, topology
//! kept).

use std::time::Instant;

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::spec::grid::{check_non_negative, check_spacing, fetch, grid_of, mask_of, shaped};
use super::{Inputs, OpError, OpLimits, OpOutput, Operation, OutputArray};
use crate::io::canvas::Canvas;
use crate::io::mesh_picture::magnification;
use crate::io::ArrayData;
use crate::numerics::skeleton::{self, SkeletonError, SkeletonGraph, SkeletonOptions};
use crate::numerics::Control;

/// Request of `grid.skeleton` (`POST /v1/grid/skeleton`, `geodex skeleton`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"mask": "ds_0192f1b27c1e7d3a9d553c0f2b8a1e45", "min_boundary_fraction": 0.08}))]
pub struct GridSkeletonRequest {
    /// Id of a 2D or 3D mask dataset: the shape is its non-zero cells.
    pub mask: String,
    /// Physical size of a cell along each axis. Default: the dataset's, else 1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(min_items = 2, max_items = 3)]
    pub spacing: Option<Vec<f64>>,
    /// A skeleton branch is kept where its two nearest boundary points are at
    /// least this far apart along the boundary (2D; the chord in 3D), in
    /// physical units. Default: 0.
    #[serde(default)]
    #[schema(minimum = 0.0)]
    pub min_boundary_length: f64,
    /// The same, as a fraction of the length of the boundary curve (2D) or of
    /// the largest inscribed diameter (3D). The larger of the two applies (and
    /// at least 3 cells). Default: 0.08. Set both to 0 to turn pruning off.
    #[serde(default = "default_fraction")]
    #[schema(minimum = 0.0)]
    pub min_boundary_fraction: f64,
}

fn default_fraction() -> f64 {
    SkeletonOptions::default().min_boundary_fraction
}

impl GridSkeletonRequest {
    fn check(&self) -> Result<(), OpError> {
        check_spacing(&self.spacing)?;
        check_non_negative(self.min_boundary_length, "min_boundary_length")?;
        check_non_negative(self.min_boundary_fraction, "min_boundary_fraction")
    }
}

impl Operation for GridSkeletonRequest {
    const NAME: &'static str = "grid.skeleton";

    fn validate(&self, _limits: &OpLimits) -> Result<(), OpError> {
        self.check()
    }

    fn dataset_ids(&self) -> Vec<(String, String)> {
        vec![("mask".into(), self.mask.clone())]
    }

    /// Arrays: `skeleton` (u8 mask), `radius` (f64, the distance to the
    /// nearest outside cell on the skeleton, 0 elsewhere), in 2D `picture`
    /// (u8 RGB, see [`skeleton_picture`]). Document:
    /// `{"graph": {"nodes", "edges"}` (2D), `"stats": {...}}`.
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
        let started = Instant::now();
        let options = SkeletonOptions {
            min_boundary_length: self.min_boundary_length,
            min_boundary_fraction: self.min_boundary_fraction,
        };
        let sk = skeleton::medial_axis(&grid, &mask, &options, control).map_err(|e| match e {
            SkeletonError::Edt(crate::numerics::edt::EdtError::Cancelled) => OpError::Cancelled,
            SkeletonError::Option { field, reason } => OpError::invalid(field, reason),
            other => OpError::invalid("mask", other.to_string()),
        })?;
        let cells = sk.mask.iter().filter(|&&m| m).count();
        let spacing = Some(grid.spacing().to_vec());
        let mut document = serde_json::json!({"stats": {
            "cells": grid.len(),
            "shape_cells": mask.iter().filter(|&&m| m).count(),
            "skeleton_cells": cells,
            "seconds": started.elapsed().as_secs_f64(),
        }});
        if let Some(g) = &sk.graph {
            document["stats"]["nodes"] = g.nodes.len().into();
            document["stats"]["branches"] = g.edges.len().into();
            document["graph"] = graph_json(g);
        }
        let mut arrays = Vec::new();
        if grid.ndim() == 2 {
            let shape = grid.shape();
            let nodes: Vec<[f64; 2]> = sk
                .graph
                .as_ref()
                .map(|g| g.nodes.iter().map(|n| n.point).collect())
                .unwrap_or_default();
            let picture = skeleton_picture([shape[0], shape[1]], &mask, &sk.mask, &nodes)
                .to_array()
                .map_err(|e| OpError::invalid("mask", e.to_string()))?;
            arrays.push(OutputArray {
                name: "picture".into(),
                array: picture,
                spacing: None,
            });
        }
        let sk_u8: Vec<u8> = sk.mask.iter().map(|&m| u8::from(m)).collect();
        Ok(OpOutput::new(
            vec![
                OutputArray {
                    name: "skeleton".into(),
                    array: ArrayData::U8(shaped(&grid, sk_u8)?),
                    spacing: spacing.clone(),
                },
                OutputArray {
                    name: "radius".into(),
                    array: ArrayData::F64(shaped(&grid, sk.radius)?),
                    spacing,
                },
            ]
            .into_iter()
            .chain(arrays)
            .collect(),
            document,
        ))
    }
}

/// Colour of the shape in [`skeleton_picture`].
pub const SHAPE: [u8; 3] = [200, 210, 225];
/// Colour of the skeleton cells.
pub const SKELETON: [u8; 3] = [215, 25, 28];
/// Colour of the graph's nodes (branch ends and junctions).
pub const NODE: [u8; 3] = [30, 90, 220];

/// The skeleton over its shape, for people to look at: cells magnified
/// `s = io::mesh_picture::magnification(rows, cols)` times; outside white,
/// the shape light blue-grey, skeleton cells red, the graph's nodes blue
/// discs ringed in black (index coordinates, axis 0 first).
pub fn skeleton_picture(
    [rows, cols]: [usize; 2],
    shape: &[bool],
    skeleton: &[bool],
    nodes: &[[f64; 2]],
) -> Canvas {
    let s = magnification(rows, cols);
    let mut c = Canvas::new(cols * s, rows * s, [255; 3]);
    for r in 0..rows {
        for q in 0..cols {
            let i = r * cols + q;
            let colour = if skeleton[i] {
                SKELETON
            } else if shape[i] {
                SHAPE
            } else {
                continue;
            };
            c.fill_rect((q * s) as i64, (r * s) as i64, s, s, colour);
        }
    }
    let r = 1.5 + s as f64;
    for p in nodes {
        let (x, y) = ((p[1] + 0.5) * s as f64 - 0.5, (p[0] + 0.5) * s as f64 - 0.5);
        c.disc(x, y, r + 1.0, [0; 3]);
        c.disc(x, y, r, NODE);
    }
    c
}

/// The skeleton graph as the API gives it: `{"nodes": [{"id", "point",
/// "radius", "degree"}], "edges": [{"source", "target", "points" (from the
/// source node to the target node), "radius", "euclidean_length"}]}`, the fields in this order (the numerical core does not
/// depend on serde, so the JSON shape is written here).
fn graph_json(g: &SkeletonGraph) -> serde_json::Value {
    let nodes: Vec<serde_json::Value> = g
        .nodes
        .iter()
        .map(|n| {
            serde_json::json!({
                "id": n.id,
                "point": n.point,
                "radius": n.radius,
                "degree": n.degree,
            })
        })
        .collect();
    let edges: Vec<serde_json::Value> = g
        .edges
        .iter()
        .map(|e| {
            serde_json::json!({
                "source": e.source,
                "target": e.target,
                "points": e.points,
                "radius": e.radius,
                "euclidean_length": e.length,
            })
        })
        .collect();
    serde_json::json!({"nodes": nodes, "edges": edges})
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_skeleton_picture_shows_shape_skeleton_and_nodes() {
        // A 10 × 30 bar; its skeleton row 5, columns 5..25, nodes at both ends.
        let (rows, cols) = (10, 30);
        let shape: Vec<bool> = (0..rows * cols)
            .map(|i| (2..8).contains(&(i / cols)) && (2..28).contains(&(i % cols)))
            .collect();
        let skeleton: Vec<bool> = (0..rows * cols)
            .map(|i| i / cols == 5 && (5..25).contains(&(i % cols)))
            .collect();
        let c = skeleton_picture([rows, cols], &shape, &skeleton, &[[5.0, 5.0], [5.0, 24.0]]);
        let s = magnification(rows, cols);
        let at = |r: usize, q: usize| c.get(q * s + s / 2, r * s + s / 2);
        assert_eq!((c.width, c.height), (cols * s, rows * s));
        assert_eq!(at(0, 0), Some([255; 3]));
        assert_eq!(at(3, 10), Some(SHAPE));
        assert_eq!(at(5, 15), Some(SKELETON));
        assert_eq!(at(5, 5), Some(NODE));
        if std::env::var_os("GEODEX_PICS").is_some() {
            let _ = std::fs::create_dir_all("/tmp/pics");
            let _ = std::fs::write("/tmp/pics/skeleton.png", c.to_png().expect("png"));
        }
    }
    use crate::numerics::skeleton::{SkeletonEdge, SkeletonNode};

    /// The graph types as they were when the numerical core derived
    /// `Serialize` for them: the document must stay what they gave.
    #[derive(Serialize)]
    struct DerivedNode {
        id: usize,
        point: [f64; 2],
        radius: f64,
        degree: usize,
    }

    #[derive(Serialize)]
    struct DerivedEdge {
        source: usize,
        target: usize,
        points: Vec<[f64; 2]>,
        radius: Vec<f64>,
        euclidean_length: f64,
    }

    #[derive(Serialize)]
    struct DerivedGraph {
        nodes: Vec<DerivedNode>,
        edges: Vec<DerivedEdge>,
    }

    #[test]
    fn the_graph_document_is_the_one_the_derived_serialisation_gave() {
        let g = SkeletonGraph {
            nodes: vec![
                SkeletonNode {
                    id: 0,
                    point: [1.0, 2.5],
                    radius: 3.25,
                    degree: 1,
                },
                SkeletonNode {
                    id: 1,
                    point: [4.0, 2.5],
                    radius: 0.1,
                    degree: 1,
                },
            ],
            edges: vec![SkeletonEdge {
                source: 0,
                target: 1,
                points: vec![[1.0, 2.5], [2.0, 2.5], [4.0, 2.5]],
                radius: vec![3.25, 2.0, 0.1],
                length: 3.0,
            }],
        };
        let derived = DerivedGraph {
            nodes: g
                .nodes
                .iter()
                .map(|n| DerivedNode {
                    id: n.id,
                    point: n.point,
                    radius: n.radius,
                    degree: n.degree,
                })
                .collect(),
            edges: g
                .edges
                .iter()
                .map(|e| DerivedEdge {
                    source: e.source,
                    target: e.target,
                    points: e.points.clone(),
                    radius: e.radius.clone(),
                    euclidean_length: e.length,
                })
                .collect(),
        };
        // Through a `Value`, as the document was built: the same text, so
        // the same names in the same order.
        let before = serde_json::to_value(&derived).unwrap().to_string();
        assert_eq!(graph_json(&g).to_string(), before);
    }
}
