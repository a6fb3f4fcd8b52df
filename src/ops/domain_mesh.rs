//! `domain.mesh`: domain meshing (see [`crate::numerics::meshing::domain`]):
//! a planar domain given as a mask dataset or as GeoJSON polygons with
//! holes becomes a triangle mesh, boundary first, relaxed, refined to an
//! angle bound, with an optional isotropic metric as its size field. The
//! mesh is a new mesh dataset (index coordinates, axis 0 first, `z = 0`).

use std::sync::Arc;
use std::time::Instant;

use ndarray::ArrayD;
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::spec::design::array_to_f64;
use super::spec::grid::{check_shape, check_spacing, fetch, mask_of};
use super::spec::mesh::MeshInput;
use super::{Inputs, OpError, OpLimits, OpOutput, Operation, OutputArray, OutputMesh};
use crate::io::mesh::report_of;
use crate::io::ArrayData;
use crate::numerics::mesh::{Topology, TriMesh};
use crate::numerics::meshing::domain::{
    mesh_domain, min_angles, Domain, DomainError, DomainMesh, DomainMeshOptions, MeshSize,
    SizeField, MAX_MIN_ANGLE,
};
use crate::numerics::{Control, Grid};

/// A GeoJSON geometry (RFC 7946): positions are `[x, y]` = `[column, row]`
/// in index units (axis 1, then axis 0). Rings are closed or not; the
/// inside follows the even-odd rule, so their orientation does not matter.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(tag = "type", deny_unknown_fields)]
pub enum DomainGeometry {
    /// One outer ring and its holes.
    Polygon {
        /// Rings of `[x, y]` positions.
        coordinates: Vec<Vec<[f64; 2]>>,
    },
    /// Several polygons.
    MultiPolygon {
        /// Polygons of rings of `[x, y]` positions.
        coordinates: Vec<Vec<Vec<[f64; 2]>>>,
    },
}

/// Request of `domain.mesh` (`POST /v1/domain/mesh`, `geodex mesh-domain`).
/// Give the domain as `mask` or as `polygons`, and `count` or `edge_length`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"polygons": {"type": "Polygon", "coordinates": [[[0, 0], [100, 0], [100, 100], [0, 100]], [[40, 40], [60, 40], [60, 60], [40, 60]]]}, "count": 2000}))]
pub struct DomainMeshRequest {
    /// Id of a 2D mask dataset: the domain is its non-zero cells (cell
    /// `(i, j)` is the unit square centred at `(i, j)`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mask: Option<String>,
    /// The domain as a GeoJSON `Polygon` or `MultiPolygon`, `[x, y]` =
    /// `[column, row]` in index units.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub polygons: Option<DomainGeometry>,
    /// About this many vertices (the mesh reaches it within 5 %).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(minimum = 3)]
    pub count: Option<usize>,
    /// Edges of about this length (physical units; geodesic length under `cost`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(exclusive_minimum = 0.0)]
    pub edge_length: Option<f64>,
    /// Id of a 2D isotropic metric `W` (finite, > 0): edges are about
    /// `edge_length / W` long, so vertices gather where `W` is large. Its
    /// cells are the mask's (same shape), or the index grid of `polygons`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cost: Option<String>,
    /// Smallest angle to reach by refinement, in degrees (0 to 33). Default 25.
    #[serde(default = "twenty_five")]
    #[schema(minimum = 0.0, maximum = 33.0)]
    pub min_angle: f64,
    /// Relaxation sweeps (optimal Delaunay smoothing), 0 to 50. Default 3.
    #[serde(default = "three")]
    #[schema(maximum = 50)]
    pub smoothing: usize,
    /// Tolerance, in cells, within which a mask's cell-edge boundary is
    /// simplified before meshing (0 keeps the staircase). Default 0.36.
    #[serde(default = "tolerance")]
    #[schema(minimum = 0.0, maximum = 2.0)]
    pub simplify: f64,
    /// Physical size of a cell per axis. Default: the mask's (or the
    /// cost's) spacing, else 1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(min_items = 2, max_items = 2)]
    pub spacing: Option<Vec<f64>>,
}

fn twenty_five() -> f64 {
    25.0
}

fn three() -> usize {
    3
}

fn tolerance() -> f64 {
    0.36
}

impl DomainMeshRequest {
    fn size(&self) -> Result<MeshSize, OpError> {
        match (self.count, self.edge_length) {
            (Some(n), None) => Ok(MeshSize::Count(n)),
            (None, Some(h)) => Ok(MeshSize::EdgeLength(h)),
            (Some(_), Some(_)) => Err(OpError::invalid(
                "edge_length",
                "give `count` or `edge_length`, not both",
            )),
            (None, None) => Err(OpError::invalid(
                "count",
                "give `count` (vertices) or `edge_length`",
            )),
        }
    }
}

impl Operation for DomainMeshRequest {
    const NAME: &'static str = "domain.mesh";

    fn validate(&self, limits: &OpLimits) -> Result<(), OpError> {
        match (&self.mask, &self.polygons) {
            (None, None) => {
                return Err(OpError::invalid(
                    "mask",
                    "give the domain as `mask` (a dataset) or `polygons` (GeoJSON)",
                ))
            }
            (Some(_), Some(_)) => {
                return Err(OpError::invalid(
                    "polygons",
                    "give `mask` or `polygons`, not both",
                ))
            }
            _ => {}
        }
        match self.size()? {
            MeshSize::Count(n) if n < 3 => {
                return Err(OpError::invalid("count", "must be >= 3"));
            }
            MeshSize::Count(n) if n > limits.max_cells => {
                return Err(OpError::TooLarge {
                    field: "count".into(),
                    reason: format!("more than {} vertices", limits.max_cells),
                });
            }
            MeshSize::EdgeLength(h) if !(h.is_finite() && h > 0.0) => {
                return Err(OpError::invalid("edge_length", "must be finite and > 0"));
            }
            _ => {}
        }
        if !(self.min_angle.is_finite() && (0.0..=MAX_MIN_ANGLE).contains(&self.min_angle)) {
            return Err(OpError::invalid(
                "min_angle",
                format!("must be between 0 and {MAX_MIN_ANGLE} degrees (Ruppert's refinement may not end above)"),
            ));
        }
        if self.smoothing > 50 {
            return Err(OpError::invalid("smoothing", "at most 50 sweeps"));
        }
        if !(self.simplify.is_finite() && (0.0..=2.0).contains(&self.simplify)) {
            return Err(OpError::invalid(
                "simplify",
                "must be between 0 and 2 cells",
            ));
        }
        check_spacing(&self.spacing)?;
        if let Some(s) = &self.spacing {
            if s.len() != 2 {
                return Err(OpError::invalid(
                    "spacing",
                    "a planar domain has two axes: give two spacings",
                ));
            }
        }
        if let Some(g) = &self.polygons {
            let rings: Vec<&Vec<[f64; 2]>> = match g {
                DomainGeometry::Polygon { coordinates } => coordinates.iter().collect(),
                DomainGeometry::MultiPolygon { coordinates } => {
                    coordinates.iter().flatten().collect()
                }
            };
            if rings.is_empty() {
                return Err(OpError::invalid("polygons.coordinates", "has no ring"));
            }
            let vertices: usize = rings.iter().map(|r| r.len()).sum();
            if vertices > limits.max_cells {
                return Err(OpError::TooLarge {
                    field: "polygons.coordinates".into(),
                    reason: format!("more than {} vertices", limits.max_cells),
                });
            }
        }
        Ok(())
    }

    fn dataset_ids(&self) -> Vec<(String, String)> {
        let mut ids = Vec::new();
        if let Some(id) = &self.mask {
            ids.push(("mask".into(), id.clone()));
        }
        if let Some(id) = &self.cost {
            ids.push(("cost".into(), id.clone()));
        }
        ids
    }

    /// Arrays: `vertices` (f64, `nv × 2`, index coordinates), `triangles`
    /// (int32, `nt × 3`), `boundary_edges` (int32, `nb × 2`, domain on the
    /// left), `min_angles` (f64 per triangle, degrees), `boundary` (f64 per
    /// vertex: 1 on the boundary, 0 inside). Mesh: `mesh`. Document:
    /// `{"stats": {...}}`.
    fn run(
        &self,
        inputs: &dyn Inputs,
        limits: &OpLimits,
        control: &Control<'_>,
    ) -> Result<OpOutput, OpError> {
        self.validate(limits)?;
        let started = Instant::now();
        let mask_input = self
            .mask
            .as_ref()
            .map(|id| fetch(inputs, "mask", id))
            .transpose()?;
        let cost_input = self
            .cost
            .as_ref()
            .map(|id| fetch(inputs, "cost", id))
            .transpose()?;
        let spacing = self
            .spacing
            .clone()
            .or_else(|| mask_input.as_ref().and_then(|m| m.spacing.clone()))
            .or_else(|| cost_input.as_ref().and_then(|m| m.spacing.clone()))
            .unwrap_or_else(|| vec![1.0, 1.0]);
        let sp = [spacing[0], spacing.get(1).copied().unwrap_or(spacing[0])];
        let mut ring_paths: Vec<String> = Vec::new();
        let domain = match (&mask_input, &self.polygons) {
            (Some(m), _) => {
                let shape = m.array.shape().to_vec();
                check_shape(&shape, "mask", limits)?;
                if shape.len() != 2 {
                    return Err(OpError::invalid(
                        "mask",
                        format!("a planar domain has 2 axes; this array has shape {shape:?}"),
                    ));
                }
                let grid = Grid::new(&shape, &sp)
                    .map_err(|e| OpError::invalid("spacing", e.to_string()))?;
                let mask = mask_of(m, "mask", &grid)?;
                Domain::from_mask(&mask, [shape[0], shape[1]], sp, self.simplify, control)
                    .map_err(|e| domain_error(e, "mask", &[]))?
            }
            (None, Some(g)) => {
                let (rings, paths): (Vec<Vec<[f64; 2]>>, Vec<String>) = match g {
                    DomainGeometry::Polygon { coordinates } => coordinates
                        .iter()
                        .enumerate()
                        .map(|(r, ring)| (ring.clone(), format!("polygons.coordinates[{r}]")))
                        .unzip(),
                    DomainGeometry::MultiPolygon { coordinates } => coordinates
                        .iter()
                        .enumerate()
                        .flat_map(|(p, polygon)| {
                            polygon.iter().enumerate().map(move |(r, ring)| {
                                (ring.clone(), format!("polygons.coordinates[{p}][{r}]"))
                            })
                        })
                        .unzip(),
                };
                ring_paths = paths;
                // GeoJSON [x, y] = [column, row] = (axis 1, axis 0).
                let rings = rings
                    .into_iter()
                    .map(|r| r.into_iter().map(|[x, y]| [y * sp[0], x * sp[1]]).collect())
                    .collect();
                Domain::new(rings).map_err(|e| domain_error(e, "polygons", &ring_paths))?
            }
            (None, None) => return Err(OpError::invalid("mask", "give `mask` or `polygons`")),
        };
        let field = match &cost_input {
            None => SizeField::Uniform,
            Some(c) => {
                let shape = c.array.shape().to_vec();
                check_shape(&shape, "cost", limits)?;
                if shape.len() != 2 {
                    return Err(OpError::invalid(
                        "cost",
                        format!("a planar metric has 2 axes; this array has shape {shape:?}"),
                    ));
                }
                if let Some(m) = &mask_input {
                    if m.array.shape() != c.array.shape() {
                        return Err(OpError::invalid(
                            "cost",
                            format!("has shape {shape:?} but the mask has {:?}", m.array.shape()),
                        ));
                    }
                }
                SizeField::from_metric(&array_to_f64(&c.array), [shape[0], shape[1]], sp)
                    .map_err(|e| OpError::invalid("cost", e.to_string()))?
            }
        };
        let options = DomainMeshOptions {
            size: self.size()?,
            field,
            min_angle: self.min_angle,
            smoothing: self.smoothing,
            max_vertices: limits.max_cells,
        };
        let size_field = if self.count.is_some() {
            "count"
        } else {
            "edge_length"
        };
        let mesh = mesh_domain(&domain, &options, control).map_err(|e| {
            let input = if self.mask.is_some() {
                "mask"
            } else {
                "polygons"
            };
            match e {
                DomainError::TooLarge { .. } | DomainError::Size(_) => {
                    OpError::invalid(size_field, e.to_string())
                }
                e => domain_error(e, input, &ring_paths),
            }
        })?;
        let seconds = started.elapsed().as_secs_f64();
        output(mesh, sp, seconds)
    }
}

/// The arrays, the mesh dataset and the statistics of a domain mesh.
fn output(mesh: DomainMesh, sp: [f64; 2], seconds: f64) -> Result<OpOutput, OpError> {
    let angles = min_angles(&mesh.points, &mesh.triangles);
    let nt = angles.len().max(1) as f64;
    let share = |bound: f64| angles.iter().filter(|&&a| a >= bound).count() as f64 / nt;
    let mut sorted = angles.clone();
    sorted.sort_by(f64::total_cmp);
    let median = sorted.get(sorted.len() / 2).copied().unwrap_or(0.0);
    let mut histogram = [0usize; 12];
    for &a in &angles {
        histogram[((a / 5.0) as usize).min(11)] += 1;
    }
    let stats = serde_json::json!({
        "vertices": mesh.points.len(),
        "triangles": mesh.triangles.len(),
        "boundary_vertices": mesh.boundary_vertices,
        "boundary_edges": mesh.boundary_edges.len(),
        "refined": mesh.refined,
        "refinement_complete": mesh.refinement_complete,
        "edge_length": mesh.h0,
        "attempts": mesh.attempts,
        "area": mesh.area,
        "min_angle": {
            "min": sorted.first().copied().unwrap_or(0.0),
            "median": median,
            "mean": angles.iter().sum::<f64>() / nt,
            "share_at_least_25": share(25.0),
            "share_at_least_30": share(30.0),
            "histogram_5_degrees": histogram,
        },
        "seconds": seconds,
    });
    let index: Vec<[f64; 2]> = mesh
        .points
        .iter()
        .map(|p| [p[0] / sp[0], p[1] / sp[1]])
        .collect();
    let nv = index.len();
    let bad = |e: ndarray::ShapeError| OpError::invalid("count", e.to_string());
    let int = |v: Vec<i32>, s: Vec<usize>| {
        ArrayD::from_shape_vec(s, v)
            .map(ArrayData::I32)
            .map_err(bad)
    };
    let tri = TriMesh::new(
        index.iter().map(|p| [p[0], p[1], 0.0]).collect(),
        mesh.triangles.clone(),
    )
    .map_err(|e| OpError::invalid("count", e.to_string()))?;
    let topology = Topology::new(&tri);
    let report = report_of(&tri, &topology);
    let mut on_boundary = vec![0.0; nv];
    for e in &mesh.boundary_edges {
        on_boundary[e[0] as usize] = 1.0;
        on_boundary[e[1] as usize] = 1.0;
    }
    let mut out = OpOutput::new(
        vec![
            OutputArray {
                name: "vertices".into(),
                array: ArrayD::from_shape_vec(
                    vec![nv, 2],
                    index.iter().flatten().copied().collect(),
                )
                .map(ArrayData::F64)
                .map_err(bad)?,
                spacing: None,
            },
            OutputArray {
                name: "triangles".into(),
                array: int(
                    mesh.triangles.iter().flatten().map(|&v| v as i32).collect(),
                    vec![mesh.triangles.len(), 3],
                )?,
                spacing: None,
            },
            OutputArray {
                name: "boundary_edges".into(),
                array: int(
                    mesh.boundary_edges
                        .iter()
                        .flatten()
                        .map(|&v| v as i32)
                        .collect(),
                    vec![mesh.boundary_edges.len(), 2],
                )?,
                spacing: None,
            },
            OutputArray {
                name: "min_angles".into(),
                array: ArrayD::from_shape_vec(vec![angles.len()], angles)
                    .map(ArrayData::F64)
                    .map_err(bad)?,
                spacing: None,
            },
            OutputArray {
                name: "boundary".into(),
                array: ArrayD::from_shape_vec(vec![nv], on_boundary)
                    .map(ArrayData::F64)
                    .map_err(bad)?,
                spacing: None,
            },
        ],
        serde_json::json!({ "stats": stats }),
    );
    out.mesh = Some(OutputMesh {
        name: "mesh".into(),
        mesh: Arc::new(MeshInput {
            mesh: tri,
            topology,
            report,
        }),
        vertex_properties: Vec::new(),
    });
    Ok(out)
}

/// A domain error as an [`OpError`] naming `field` (the domain's field),
/// or the ring's path in the request when `ring_paths` has it.
fn domain_error(e: DomainError, field: &str, ring_paths: &[String]) -> OpError {
    match e {
        DomainError::Cancelled => OpError::Cancelled,
        DomainError::Ring { ring, .. } | DomainError::Crossing { ring, .. }
            if ring < ring_paths.len() =>
        {
            OpError::invalid(ring_paths[ring].clone(), e.to_string())
        }
        DomainError::TooLarge { .. } => OpError::TooLarge {
            field: field.into(),
            reason: e.to_string(),
        },
        e => OpError::invalid(field, e.to_string()),
    }
}
