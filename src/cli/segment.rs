//! `geodex edt`, `segment`, `skeleton`, `offset`, `plan`, `sample` and `mesh`: the
//! segmentation, sampling and meshing operations on NPY files (or any format geodex reads) for batch users.
//!
//! Each command builds the request struct the HTTP service uses
//! (`ops::grid_*`) and runs it with [`Operation::run`], so both accept and
//! refuse the same inputs. Errors are one line naming the flag at fault
//! (each command's [`FlagMap`]). Array outputs are written after their
//! extension (`.npy`, `.tiff`, `.png`, `.png16`: [`super::output`]); a
//! command that reads a cost designs it from an image with `--design`.
//!
//! ```text
//! geodex edt --mask M.npy --spacing 1,0.5 --signed --out D.npy --features F.npy
//! geodex segment --cost W.npy --seed 1:40,40 --seed 2:200,180 --out L.npy --contours L.geojson
//! geodex segment --cost cells.png --design edges:mode=barrier --seed 1:40,40 --seed 2:90,90 --out L.png
//! geodex skeleton --mask M.npy --out S.npy --graph G.json
//! geodex offset --mask M.npy --radius 5 --out O.npy
//! geodex plan --obstacles O.npy --radius 3 --start 10,5 --goal 50,55 --out path.json
//! geodex sample --cost W.npy --count 500 --out U.npy --labels L.npy --samples S.json
//! geodex mesh --image I.png --count 2000 --metric hessian --out M.ply --stats S.json
//! geodex shape-from-shading --image I.png --light 0.3,0,1 --out Z.npy --mesh Z.ply
//! geodex shape-from-shading --image I.png --focal 512 --out D.npy --mesh D.glb
//! ```

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use clap::Args;

use super::design::DesignFlag;
use super::output;
use super::SpacingFlag;

use super::run::{run_on, CliError, FlagMap};
use crate::io::mesh::write as mesh_write;
use crate::io::{self, ArrayData, Limits};
use crate::numerics::grid::MAX_CELLS;
use crate::ops::domain_mesh::{DomainGeometry, DomainMeshRequest};
use crate::ops::grid_edt::{EdtMode, GridEdtRequest};
use crate::ops::grid_group::GridGroupRequest;
use crate::ops::grid_mesh::{GridMeshRequest, MeshMetricSpec};
use crate::ops::grid_offset::{GridOffsetRequest, OffsetMetric, OffsetOperation};
use crate::ops::grid_plan::GridPlanRequest;
use crate::ops::grid_sample::{GridSampleRequest, GridSamplingSpec};
use crate::ops::grid_segment::{GridSegmentRequest, SeedSpec};
use crate::ops::grid_shading::{AnchorSpec, CameraSpec, DirectionSpec, GridShadingRequest};
use crate::ops::grid_skeleton::GridSkeletonRequest;
use crate::ops::spec::cost::{CostSpec, InterpretationSpec};
use crate::ops::spec::tensor::{ComponentsTensor, TensorSpec};
use crate::ops::{InputArray, OpOutput, Operation};

/// A command-line mistake or a refused request, naming the flag.
pub type SegmentCliError = CliError;

/// The table of the commands whose fields are their flags' names (and
/// `spacing[k]` the k-th value of `--spacing`).
pub(super) fn grid_flags() -> FlagMap {
    FlagMap::new().values("spacing", "--spacing")
}

/// The flag that gives the cost: `--cost`, else `--shape`.
fn cost_flag(cost: &Option<PathBuf>) -> &'static str {
    if cost.is_some() {
        "--cost"
    } else {
        "--shape"
    }
}

pub(super) fn flag(name: impl Into<String>, reason: impl Into<String>) -> SegmentCliError {
    CliError::Flag {
        flag: name.into(),
        reason: reason.into(),
    }
}

/// Flags of `geodex edt`.
#[derive(Debug, Clone, Args)]
pub struct EdtArgs {
    /// The mask: 2D or 3D, boolean or numbers (non-zero cells are the features).
    #[arg(long, value_name = "M.npy")]
    pub mask: PathBuf,
    /// Physical size of a cell along each axis.
    #[command(flatten)]
    pub spacing: SpacingFlag,
    /// Signed distance: negative inside the mask.
    #[arg(long, conflicts_with = "multilabel")]
    pub signed: bool,
    /// Read --mask as labels: distance to the nearest cell of another value.
    #[arg(long)]
    pub multilabel: bool,
    /// Threads (default: all cores).
    #[arg(long, value_name = "N")]
    pub threads: Option<usize>,
    /// Where to write the distance (f64; .npy, .tiff, .png or .png16).
    #[arg(long, value_name = "D.npy")]
    pub out: PathBuf,
    /// Where to write the feature transform (int64 by extension as --out: C-order linear index
    /// of the nearest feature cell, -1 if none).
    #[arg(long, value_name = "F.npy")]
    pub features: Option<PathBuf>,
}

/// Flags of `geodex segment`.
#[derive(Debug, Clone, Args)]
pub struct SegmentArgs {
    /// The metric W (cost per unit length), as in `geodex distance`.
    #[arg(long, value_name = "W.npy", conflicts_with = "shape")]
    pub cost: Option<PathBuf>,
    /// Grid shape for a unit cost, instead of --cost.
    #[arg(long, value_name = "N,M[,P]", value_delimiter = ',')]
    pub shape: Option<Vec<usize>>,
    /// Design the cost from the --cost image.
    #[command(flatten)]
    pub design: DesignFlag,
    /// A labelled seed point `LABEL:I,J[,K]`; repeat.
    #[arg(long = "seed", value_name = "LABEL:I,J[,K]")]
    pub seeds: Vec<String>,
    /// A label image of scribbles (non-zero integers are seeds of that label).
    #[arg(long, value_name = "S.npy")]
    pub seed_image: Option<PathBuf>,
    /// Obstacle mask.
    #[arg(long, value_name = "O.npy")]
    pub obstacles: Option<PathBuf>,
    /// Geodesic ball radius (cells beyond get label -1).
    #[arg(long, value_name = "D")]
    pub max_distance: Option<f64>,
    /// Physical size of a cell along each axis.
    #[command(flatten)]
    pub spacing: SpacingFlag,
    /// Where to write the labels (int32; .npy, .tiff, .png or .png16).
    #[arg(long, value_name = "L.npy")]
    pub out: PathBuf,
    /// Where to write the distance to the nearest seed.
    #[arg(long, value_name = "U.npy")]
    pub distance: Option<PathBuf>,
    /// Where to write the confidence (second distance minus distance).
    #[arg(long, value_name = "C.npy")]
    pub confidence: Option<PathBuf>,
    /// Where to write the label contours (GeoJSON, 2D).
    #[arg(long, value_name = "L.geojson")]
    pub contours: Option<PathBuf>,
}

/// Flags of `geodex skeleton`.
#[derive(Debug, Clone, Args)]
pub struct SkeletonArgs {
    /// The shape mask.
    #[arg(long, value_name = "M.npy")]
    pub mask: PathBuf,
    /// Physical size of a cell along each axis.
    #[command(flatten)]
    pub spacing: SpacingFlag,
    /// Smallest boundary length between the two nearest boundary points of a branch.
    #[arg(long, default_value_t = 0.0, value_name = "L")]
    pub min_boundary_length: f64,
    /// The same as a fraction of the boundary length (2D) or inscribed diameter (3D).
    #[arg(long, default_value_t = 0.08, value_name = "F")]
    pub min_boundary_fraction: f64,
    /// Where to write the skeleton (uint8; .npy, .tiff, .png or .png16).
    #[arg(long, value_name = "S.npy")]
    pub out: PathBuf,
    /// Where to write the radius function (f64; .npy, .tiff, .png or .png16).
    #[arg(long, value_name = "R.npy")]
    pub radius: Option<PathBuf>,
    /// Where to write the skeleton graph (JSON, 2D).
    #[arg(long, value_name = "G.json")]
    pub graph: Option<PathBuf>,
}

/// Flags of `geodex offset`.
#[derive(Debug, Clone, Args)]
pub struct OffsetArgs {
    /// The shape mask.
    #[arg(long, value_name = "M.npy")]
    pub mask: PathBuf,
    /// Offset distance (physical units).
    #[arg(long, value_name = "R")]
    pub radius: f64,
    /// Erode instead of dilate.
    #[arg(long)]
    pub erode: bool,
    /// Geodesic distance of --cost (default unit cost) instead of Euclidean.
    #[arg(long)]
    pub geodesic: bool,
    /// The metric of --geodesic.
    #[arg(long, value_name = "W.npy", requires = "geodesic")]
    pub cost: Option<PathBuf>,
    /// Design the cost from the --cost image.
    #[command(flatten)]
    pub design: DesignFlag,
    /// Obstacle mask (blocks the propagation).
    #[arg(long, value_name = "O.npy")]
    pub obstacles: Option<PathBuf>,
    /// Physical size of a cell along each axis.
    #[command(flatten)]
    pub spacing: SpacingFlag,
    /// Where to write the offset shape (uint8; .npy, .tiff, .png or .png16).
    #[arg(long, value_name = "O.npy")]
    pub out: PathBuf,
}

/// Flags of `geodex plan`.
#[derive(Debug, Clone, Args)]
pub struct PlanArgs {
    /// Obstacle mask.
    #[arg(long, value_name = "O.npy")]
    pub obstacles: PathBuf,
    /// Robot radius (physical units).
    #[arg(long, value_name = "R")]
    pub radius: f64,
    /// Start cell `I,J[,K]`.
    #[arg(
        long,
        value_name = "I,J[,K]",
        value_delimiter = ',',
        allow_negative_numbers = true
    )]
    pub start: Vec<f64>,
    /// Goal cell `I,J[,K]`.
    #[arg(
        long,
        value_name = "I,J[,K]",
        value_delimiter = ',',
        allow_negative_numbers = true
    )]
    pub goal: Vec<f64>,
    /// Physical size of a cell along each axis.
    #[command(flatten)]
    pub spacing: SpacingFlag,
    /// Where to write the answer (JSON); stdout when omitted.
    #[arg(long, value_name = "PATH.json")]
    pub out: Option<PathBuf>,
}

/// Flags of `geodex sample`.
#[derive(Debug, Clone, Args)]
pub struct SampleArgs {
    /// The metric W (cost per unit length), as in `geodex distance`.
    #[arg(long, value_name = "W.npy", conflicts_with = "shape")]
    pub cost: Option<PathBuf>,
    /// Grid shape for a unit cost, instead of --cost.
    #[arg(
        long,
        value_name = "N,M[,P]",
        value_delimiter = ',',
        conflicts_with = "tensor"
    )]
    pub shape: Option<Vec<usize>>,
    /// A Riemannian metric instead of a cost, as in `geodex distance`: an
    /// array of shape (N, M, 3) with m11, m12, m22 per cell, or (N, M, P, 6)
    /// in 3D; every cell symmetric positive definite.
    #[arg(long, value_name = "T.npy", conflicts_with_all = ["cost", "design"])]
    pub tensor: Option<PathBuf>,
    /// Design the cost from the --cost image.
    #[command(flatten)]
    pub design: DesignFlag,
    /// Number of samples.
    #[arg(long, value_name = "K")]
    pub count: Option<usize>,
    /// Stop once every cell is within this distance of a sample.
    #[arg(long, value_name = "R", allow_negative_numbers = true)]
    pub radius: Option<f64>,
    /// Obstacle mask (never sampled).
    #[arg(long, value_name = "O.npy")]
    pub obstacles: Option<PathBuf>,
    /// Physical size of a cell along each axis.
    #[command(flatten)]
    pub spacing: SpacingFlag,
    /// Where to write the distance to the nearest sample (f64; .npy, .tiff, .png or .png16).
    #[arg(long, value_name = "U.npy")]
    pub out: PathBuf,
    /// Where to write the Voronoi labels (int32; .npy, .tiff, .png or .png16).
    #[arg(long, value_name = "L.npy")]
    pub labels: Option<PathBuf>,
    /// Where to write the samples and statistics (JSON).
    #[arg(long, value_name = "S.json")]
    pub samples: Option<PathBuf>,
    /// How the samples are placed.
    #[arg(long, value_enum, default_value = "auto")]
    pub sampling: GridSamplingArg,
}

/// How `geodex sample` places its samples.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum GridSamplingArg {
    /// Clustered for 64 samples or more on a cost without walls that
    /// varies little within blocks of 3 cells, else exact.
    Auto,
    /// Each sample is the cell farthest from the previous ones.
    Exact,
    /// Farthest points on blocks of 3 (or 2) cells per axis, then one front
    /// per sample (not with --tensor).
    Clustered,
}

/// Flags of `geodex group`.
#[derive(Debug, Clone, Args)]
pub struct GroupArgs {
    /// The cost W (2D NPY or image), as in `geodex distance`.
    #[arg(long, value_name = "W.npy", conflicts_with = "shape")]
    pub cost: Option<PathBuf>,
    /// Grid shape for a unit cost, instead of --cost.
    #[arg(long, value_name = "N,M", value_delimiter = ',')]
    pub shape: Option<Vec<usize>>,
    /// Design the cost from the --cost image.
    #[command(flatten)]
    pub design: DesignFlag,
    /// The key points: a JSON array of [row, column] pairs, or an object
    /// {"key_points": [...], "orientations": [...]} (tangent angles in
    /// radians, from axis 0 towards axis 1) for the anisotropic grouping.
    #[arg(long, value_name = "K.json")]
    pub key_points: PathBuf,
    /// With orientations: how many times cheaper along the tangent.
    #[arg(long, default_value_t = 4.0, allow_negative_numbers = true)]
    pub anisotropy: f64,
    /// Each key point keeps at most this many links (mutually).
    #[arg(long, default_value_t = 2)]
    pub max_links: usize,
    /// A link costs at most this times the cheapest link of each end.
    #[arg(long, default_value_t = 2.5, allow_negative_numbers = true)]
    pub ratio: f64,
    /// A link costs at most this times the typical link (0: no bound).
    #[arg(long, default_value_t = 3.0, allow_negative_numbers = true)]
    pub relative: f64,
    /// A link costs at most this (units of the integrated cost).
    #[arg(long, allow_negative_numbers = true)]
    pub max_cost: Option<f64>,
    /// Contours with fewer key points are dropped.
    #[arg(long, default_value_t = 2)]
    pub min_points: usize,
    /// Obstacle mask (walls).
    #[arg(long, value_name = "O.npy")]
    pub obstacles: Option<PathBuf>,
    /// Physical size of a cell along each axis.
    #[command(flatten)]
    pub spacing: SpacingFlag,
    /// Where to write the links, contours and statistics (JSON).
    #[arg(long, value_name = "G.json")]
    pub out: PathBuf,
    /// Where to write the contours as GeoJSON.
    #[arg(long, value_name = "C.geojson")]
    pub geojson: Option<PathBuf>,
    /// Where to write the Voronoi labels (int32; .npy, .tiff, .png or .png16).
    #[arg(long, value_name = "L.npy")]
    pub labels: Option<PathBuf>,
    /// Where to write the distance to the nearest key point (f64; .npy, .tiff, .png or .png16).
    #[arg(long, value_name = "U.npy")]
    pub distance: Option<PathBuf>,
}

/// The metric of `geodex mesh`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum MeshMetricArg {
    /// W = 1.
    Uniform,
    /// W from the gradient's magnitude.
    Gradient,
    /// W from the Hessian's norm.
    Hessian,
    /// Anisotropic: det(|H|)^(-1/6) |H| from the absolute Hessian.
    AnisotropicHessian,
    /// Anisotropic: Id + strength J / max from the structure tensor J.
    StructureTensor,
    /// Anisotropic with the gradient metric's density, elongated along the
    /// structure tensor's edges.
    EdgeTensor,
}

/// Flags of `geodex mesh`.
#[derive(Debug, Clone, Args)]
pub struct MeshArgs {
    /// The 2D image to mesh (NPY, PNG, TIFF, ...).
    #[arg(long, value_name = "IMAGE")]
    pub image: PathBuf,
    /// Target number of vertices.
    #[arg(long, value_name = "K")]
    pub count: usize,
    /// The metric the vertices follow.
    #[arg(long, value_enum, default_value = "gradient")]
    pub metric: MeshMetricArg,
    /// Smoothing scale of the derivatives.
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true)]
    pub sigma: f64,
    /// Contrast of the metric (W in [1, 1 + strength]; anisotropic-hessian:
    /// largest |λ| over the floor of every |λ|).
    #[arg(long, default_value_t = 8.0, allow_negative_numbers = true)]
    pub strength: f64,
    /// Anisotropic metrics: largest length-to-width ratio of an element
    /// [default: 8; edge-tensor: 1.5].
    #[arg(long, allow_negative_numbers = true)]
    pub anisotropy: Option<f64>,
    /// structure-tensor, edge-tensor: integration scale.
    #[arg(long, default_value_t = 2.0, allow_negative_numbers = true)]
    pub rho: f64,
    /// Skip the uniform mesh of the same vertex count.
    #[arg(long)]
    pub no_compare: bool,
    /// Flip edges while that lowers the L2 error (a data-dependent
    /// triangulation of the same vertices; the uniform mesh too).
    #[arg(long)]
    pub flips: bool,
    /// Also move vertices to nearby grid cells while that lowers the L2
    /// error (implies --flips; the uniform mesh too).
    #[arg(long)]
    pub moves: bool,
    /// Physical size of a cell along each axis.
    #[command(flatten)]
    pub spacing: SpacingFlag,
    /// Where to write the mesh: `.ply` (with the image value per vertex), `.obj`, `.json` or `.glb` (glTF binary).
    #[arg(long, value_name = "MESH.ply")]
    pub out: PathBuf,
    /// Where to write the piecewise-linear approximation of the image (f64; .npy, .tiff, .png or .png16).
    #[arg(long, value_name = "A.npy")]
    pub approximation: Option<PathBuf>,
    /// Where to write a PNG of the mesh drawn over the image.
    #[arg(long, value_name = "P.png")]
    pub picture: Option<PathBuf>,
    /// Where to write the statistics (JSON).
    #[arg(long, value_name = "S.json")]
    pub stats: Option<PathBuf>,
}

/// `geodex mesh-domain`: mesh a mask or GeoJSON polygons.
#[derive(Debug, Args)]
pub struct DomainMeshArgs {
    /// The domain as a 2D mask (NPY, PNG, ...): its non-zero cells.
    #[arg(long, value_name = "MASK", conflicts_with = "polygons")]
    pub mask: Option<PathBuf>,
    /// The domain as a GeoJSON file (a Polygon or MultiPolygon geometry, or a
    /// Feature holding one), `[x, y]` = `[column, row]` in index units.
    #[arg(long, value_name = "DOMAIN.geojson")]
    pub polygons: Option<PathBuf>,
    /// About this many vertices.
    #[arg(long, value_name = "N", conflicts_with = "edge_length")]
    pub count: Option<usize>,
    /// Edges of about this length (physical units).
    #[arg(long, value_name = "H", allow_negative_numbers = true)]
    pub edge_length: Option<f64>,
    /// An isotropic metric W (2D, > 0): edges about edge_length / W.
    #[arg(long, value_name = "W.npy")]
    pub cost: Option<PathBuf>,
    /// Smallest angle the refinement reaches, in degrees (0 to 33).
    #[arg(long, default_value_t = 25.0, allow_negative_numbers = true)]
    pub min_angle: f64,
    /// Relaxation sweeps.
    #[arg(long, default_value_t = 3)]
    pub smoothing: usize,
    /// Tolerance (cells) of the mask boundary's simplification.
    #[arg(long, default_value_t = 0.36, allow_negative_numbers = true)]
    pub simplify: f64,
    /// Physical size of a cell along each axis.
    #[command(flatten)]
    pub spacing: SpacingFlag,
    /// Where to write the mesh: `.ply`, `.obj`, `.json` or `.glb` (glTF binary).
    #[arg(long, value_name = "MESH.ply")]
    pub out: PathBuf,
    /// Where to write the statistics (JSON).
    #[arg(long, value_name = "S.json")]
    pub stats: Option<PathBuf>,
}

/// Where `geodex shape-from-shading` knows the height.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum ShadingAnchorArg {
    /// The image border.
    Border,
    /// The pixels at the albedo (the tops of convex objects).
    Singular,
}

/// Flags of `geodex shape-from-shading`.
#[derive(Debug, Clone, Args)]
pub struct ShadingArgs {
    /// The grey image (NPY, PNG, TIFF, ...): the brightness of a Lambertian surface.
    #[arg(long, value_name = "IMAGE")]
    pub image: PathBuf,
    /// Direction towards the light, l1 (axis 0), l2 (axis 1), l3 > 0 (towards the camera). Default: 0,0,1.
    #[arg(
        long,
        value_name = "L1,L2,L3",
        value_delimiter = ',',
        allow_negative_numbers = true
    )]
    pub light: Option<Vec<f64>>,
    /// Perspective camera of this focal length in pixels, the light at its optical centre (default: orthographic).
    #[arg(long, value_name = "F", allow_negative_numbers = true)]
    pub focal: Option<f64>,
    /// Perspective: principal point row,column in pixels (default: the image centre).
    #[arg(
        long,
        value_name = "R,C",
        value_delimiter = ',',
        allow_negative_numbers = true
    )]
    pub principal_point: Option<Vec<f64>>,
    /// Perspective: no 1/r² falloff of the light (anchors are then needed).
    #[arg(long)]
    pub no_attenuation: bool,
    /// The brightness of a surface facing the light (default: the image's largest value).
    #[arg(long, allow_negative_numbers = true)]
    pub albedo: Option<f64>,
    /// Where the height is known (default: the border, or none with --focal).
    #[arg(long, value_enum)]
    pub anchors: Option<ShadingAnchorArg>,
    /// The anchors' height (a depth > 0 with --focal).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub anchor_height: f64,
    /// The height falls away from the anchors (default: rises, falls for singular anchors).
    #[arg(long)]
    pub down: bool,
    /// Sweeping solver: stop when an iteration changes no pixel by more than this.
    #[arg(long, allow_negative_numbers = true)]
    pub tolerance: Option<f64>,
    /// Sweeping solver: the most iterations.
    #[arg(long)]
    pub max_iterations: Option<usize>,
    /// Physical size of a pixel along each axis (orthographic).
    #[command(flatten)]
    pub spacing: SpacingFlag,
    /// Where to write the height (orthographic) or depth (perspective), f64 (.npy, .tiff, .png or .png16).
    #[arg(long, value_name = "Z.npy")]
    pub out: PathBuf,
    /// Where to write the surface mesh: `.ply`, `.obj`, `.json` or `.glb`.
    #[arg(long, value_name = "MESH.ply")]
    pub mesh: Option<PathBuf>,
    /// Where to write the statistics (JSON).
    #[arg(long, value_name = "S.json")]
    pub stats: Option<PathBuf>,
}

/// `geodex shape-from-shading`.
pub fn run_shape_from_shading(args: &ShadingArgs) -> Result<(), SegmentCliError> {
    check_outputs(&[("--out", Some(&args.out))])?;
    let mut inputs = HashMap::new();
    let height = args.anchor_height;
    let request = GridShadingRequest {
        image: read("--image", &args.image, &mut inputs)?,
        spacing: args.spacing.spacing.clone(),
        albedo: args.albedo,
        anchors: args.anchors.map(|a| match a {
            ShadingAnchorArg::Border => AnchorSpec::Border { height },
            ShadingAnchorArg::Singular => AnchorSpec::Singular {
                tolerance: 1e-3,
                height,
            },
        }),
        direction: args.down.then_some(DirectionSpec::Down),
        order: 2,
        min_slope: None,
        light: args.light.clone(),
        camera: match args.focal {
            None => CameraSpec::Orthographic,
            Some(focal) => CameraSpec::Perspective {
                focal,
                principal_point: args.principal_point.clone(),
                attenuation: !args.no_attenuation,
            },
        },
        tolerance: args.tolerance,
        max_iterations: args.max_iterations,
        mesh: args.mesh.is_some(),
    };
    let flags = grid_flags()
        .field("image", "--image")
        .field("camera.principal_point", "--principal-point")
        .field("camera.attenuation", "--no-attenuation")
        .field("camera", "--focal")
        .field("anchors.height", "--anchor-height")
        .field("direction", "--down");
    let (out, secs) = execute(&request, &inputs, None, &flags)?;
    let name = if args.focal.is_some() {
        "depth"
    } else {
        "height"
    };
    let Some(values) = array(&out, name) else {
        return Err(flag("geodex", "the operation returned no height"));
    };
    write("--out", &args.out, values)?;
    if let Some(p) = &args.mesh {
        let Some(mesh) = &out.mesh else {
            return Err(flag("--mesh", "no pixel quad is reached: no mesh to write"));
        };
        let bytes = mesh_write::encode_by_extension(&mesh.mesh.mesh, &[], p)
            .map_err(|e| flag("--mesh", e))?;
        std::fs::write(p, bytes)
            .map_err(|e| flag("--mesh", format!("cannot write '{}': {e}", p.display())))?;
    }
    if let Some(p) = &args.stats {
        write_json("--stats", p, &out.document)?;
    }
    let stats = &out.document["stats"];
    println!(
        "geodex: wrote {} ({} {}..{}, {} unreached, {} iterations, {}, {:.3} s)",
        args.out.display(),
        name,
        stats[format!("min_{name}")],
        stats[format!("max_{name}")],
        stats["unreached"],
        stats["iterations"],
        stats["stop"].as_str().unwrap_or("fast marching"),
        secs
    );
    Ok(())
}

pub(super) fn read(
    name: &str,
    path: &Path,
    inputs: &mut HashMap<String, InputArray>,
) -> Result<String, SegmentCliError> {
    let bytes = std::fs::read(path)
        .map_err(|e| flag(name, format!("cannot read '{}': {e}", path.display())))?;
    let limits = Limits {
        max_cells: MAX_CELLS,
        max_bytes: usize::MAX,
    };
    let d = io::decode(&bytes, None, &limits)
        .map_err(|e| flag(name, format!("'{}': {e}", path.display())))?;
    let id = name.trim_start_matches('-').to_string();
    inputs.insert(
        id.clone(),
        InputArray {
            array: Arc::new(d.array),
            spacing: d.spacing,
        },
    );
    Ok(id)
}

/// Writes an array output after its extension ([`output::write_array`]).
pub(super) fn write(name: &str, path: &Path, array: &ArrayData) -> Result<(), SegmentCliError> {
    Ok(output::write_array(name, path, array)?)
}

/// Checks the extensions of a command's array outputs before it runs.
pub(super) fn check_outputs(outputs: &[(&str, Option<&Path>)]) -> Result<(), SegmentCliError> {
    for (name, path) in outputs {
        output::check(name, *path)?;
    }
    Ok(())
}

pub(super) fn write_json(
    name: &str,
    path: &Path,
    v: &serde_json::Value,
) -> Result<(), SegmentCliError> {
    let s = serde_json::to_string(v).map_err(|e| flag(name, e.to_string()))?;
    std::fs::write(path, s)
        .map_err(|e| flag(name, format!("cannot write '{}': {e}", path.display())))
}

/// Runs `request` through the runner; a refusal names the flag `flags`
/// gives for its field. The output and the seconds it ran.
pub(super) fn execute<O: Operation + Clone + std::fmt::Debug>(
    request: &O,
    inputs: &HashMap<String, InputArray>,
    threads: Option<usize>,
    flags: &FlagMap,
) -> Result<(OpOutput, f64), SegmentCliError> {
    let ran = run_on(
        Box::new(request.clone()),
        inputs.clone(),
        threads.map(|n| n.max(1)),
        flags,
    )?;
    Ok((ran.output, ran.timing.run_seconds))
}

pub(super) fn array<'a>(out: &'a OpOutput, name: &str) -> Option<&'a ArrayData> {
    out.arrays.iter().find(|a| a.name == name).map(|a| &a.array)
}

pub(super) fn save(
    out: &OpOutput,
    name: &str,
    flag_name: &str,
    path: &Option<PathBuf>,
) -> Result<(), SegmentCliError> {
    if let (Some(p), Some(a)) = (path, array(out, name)) {
        write(flag_name, p, a)?;
    }
    Ok(())
}

/// The `cost` of a request from `--cost W.npy` (designed with `--design`)
/// or `--shape N,M[,P]` (unit cost).
pub(super) fn cost_of(
    cost: &Option<PathBuf>,
    shape: &Option<Vec<usize>>,
    design: &DesignFlag,
    inputs: &mut HashMap<String, InputArray>,
) -> Result<CostSpec, SegmentCliError> {
    let design = design.spec(cost.is_some(), "--cost")?;
    Ok(match (cost, shape) {
        (Some(p), _) => CostSpec {
            dataset: Some(read("--cost", p, inputs)?),
            constant: None,
            shape: None,
            interpretation: InterpretationSpec::Cost,
            design,
        },
        (None, Some(s)) => CostSpec {
            dataset: None,
            constant: Some(1.0),
            shape: Some(s.clone()),
            interpretation: InterpretationSpec::Cost,
            design: None,
        },
        (None, None) => return Err(flag("--cost", "give --cost, --shape or --tensor")),
    })
}

/// `geodex edt`.
pub fn run_edt(args: &EdtArgs) -> Result<(), SegmentCliError> {
    check_outputs(&[
        ("--out", Some(&args.out)),
        ("--features", args.features.as_deref()),
    ])?;
    let mut inputs = HashMap::new();
    let id = read("--mask", &args.mask, &mut inputs)?;
    let request = GridEdtRequest {
        mask: id,
        spacing: args.spacing.spacing.clone(),
        mode: if args.signed {
            EdtMode::Signed
        } else if args.multilabel {
            EdtMode::Multilabel
        } else {
            EdtMode::Binary
        },
        features: args.features.is_some(),
    };
    let flags = grid_flags().field("mode", "--signed");
    let (out, secs) = execute(&request, &inputs, args.threads, &flags)?;
    save(&out, "distance", "--out", &Some(args.out.clone()))?;
    save(&out, "features", "--features", &args.features)?;
    let transform = out.document["stats"]["seconds"].as_f64().unwrap_or(secs);
    println!(
        "geodex: wrote {} (transform {:.3} s, total {:.3} s)",
        args.out.display(),
        transform,
        secs
    );
    Ok(())
}

/// The flags behind the fields of [`GridSegmentRequest`].
fn segment_flags(cost: &Option<PathBuf>) -> FlagMap {
    grid_flags()
        .each("seeds", "--seed")
        .field("seed_image", "--seed-image")
        .metric(cost_flag(cost))
}

/// `geodex segment`.
pub fn run_segment(args: &SegmentArgs) -> Result<(), SegmentCliError> {
    check_outputs(&[
        ("--out", Some(&args.out)),
        ("--distance", args.distance.as_deref()),
        ("--confidence", args.confidence.as_deref()),
    ])?;
    let mut inputs = HashMap::new();
    let cost = cost_of(&args.cost, &args.shape, &args.design, &mut inputs)?;
    let mut seeds = Vec::new();
    for (i, s) in args.seeds.iter().enumerate() {
        let bad = || {
            flag(
                format!("--seed {}", i + 1),
                format!("'{s}' is not LABEL:I,J[,K]"),
            )
        };
        let (label, point) = s.split_once(':').ok_or_else(bad)?;
        let label: i32 = label.trim().parse().map_err(|_| bad())?;
        let point: Vec<f64> = point
            .split(',')
            .map(|v| v.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .map_err(|_| bad())?;
        seeds.push(SeedSpec {
            label,
            point: Some(point),
            cells: None,
        });
    }
    let request = GridSegmentRequest {
        cost: Some(cost),
        metric: None,
        spacing: args.spacing.spacing.clone(),
        obstacles: match &args.obstacles {
            Some(p) => Some(read("--obstacles", p, &mut inputs)?),
            None => None,
        },
        seeds,
        seed_image: match &args.seed_image {
            Some(p) => Some(read("--seed-image", p, &mut inputs)?),
            None => None,
        },
        max_distance: args.max_distance,
        order: 2,
        contours: args.contours.is_some(),
    };
    let (out, secs) = execute(&request, &inputs, None, &segment_flags(&args.cost))?;
    save(&out, "labels", "--out", &Some(args.out.clone()))?;
    save(&out, "distance", "--distance", &args.distance)?;
    save(&out, "confidence", "--confidence", &args.confidence)?;
    if let (Some(p), Some(c)) = (&args.contours, out.document.get("contours")) {
        write_json("--contours", p, c)?;
    }
    println!(
        "geodex: wrote {} ({} labels, {:.3} s)",
        args.out.display(),
        out.document["labels"].as_array().map_or(0, Vec::len),
        secs
    );
    Ok(())
}

/// `geodex skeleton`.
pub fn run_skeleton(args: &SkeletonArgs) -> Result<(), SegmentCliError> {
    check_outputs(&[
        ("--out", Some(&args.out)),
        ("--radius", args.radius.as_deref()),
    ])?;
    let mut inputs = HashMap::new();
    let request = GridSkeletonRequest {
        mask: read("--mask", &args.mask, &mut inputs)?,
        spacing: args.spacing.spacing.clone(),
        min_boundary_length: args.min_boundary_length,
        min_boundary_fraction: args.min_boundary_fraction,
    };
    let (out, secs) = execute(&request, &inputs, None, &grid_flags())?;
    save(&out, "skeleton", "--out", &Some(args.out.clone()))?;
    save(&out, "radius", "--radius", &args.radius)?;
    if let (Some(p), Some(g)) = (&args.graph, out.document.get("graph")) {
        write_json("--graph", p, g)?;
    }
    println!(
        "geodex: wrote {} ({} skeleton cells, {:.3} s)",
        args.out.display(),
        out.document["stats"]["skeleton_cells"],
        secs
    );
    Ok(())
}

/// `geodex offset`.
pub fn run_offset(args: &OffsetArgs) -> Result<(), SegmentCliError> {
    check_outputs(&[("--out", Some(&args.out))])?;
    let design = args.design.spec(args.cost.is_some(), "--cost")?;
    let mut inputs = HashMap::new();
    let request = GridOffsetRequest {
        mask: read("--mask", &args.mask, &mut inputs)?,
        radius: args.radius,
        operation: if args.erode {
            OffsetOperation::Erode
        } else {
            OffsetOperation::Dilate
        },
        metric: if args.geodesic {
            OffsetMetric::Geodesic
        } else {
            OffsetMetric::Euclidean
        },
        cost: match &args.cost {
            Some(p) => Some(CostSpec {
                dataset: Some(read("--cost", p, &mut inputs)?),
                constant: None,
                shape: None,
                interpretation: InterpretationSpec::Cost,
                design,
            }),
            None => None,
        },
        obstacles: match &args.obstacles {
            Some(p) => Some(read("--obstacles", p, &mut inputs)?),
            None => None,
        },
        spacing: args.spacing.spacing.clone(),
    };
    let flags = grid_flags()
        .field("operation", "--erode")
        .field("metric", "--geodesic")
        .field("cost.design", "--design")
        .field("cost", "--cost");
    let (out, secs) = execute(&request, &inputs, None, &flags)?;
    save(&out, "offset", "--out", &Some(args.out.clone()))?;
    println!(
        "geodex: wrote {} ({} -> {} cells, {:.3} s)",
        args.out.display(),
        out.document["stats"]["cells_before"],
        out.document["stats"]["cells_after"],
        secs
    );
    Ok(())
}

/// `geodex plan`.
pub fn run_plan(args: &PlanArgs) -> Result<(), SegmentCliError> {
    let mut inputs = HashMap::new();
    let request = GridPlanRequest {
        obstacles: read("--obstacles", &args.obstacles, &mut inputs)?,
        radius: args.radius,
        start: args.start.clone(),
        goal: args.goal.clone(),
        spacing: args.spacing.spacing.clone(),
    };
    let (out, _) = execute(&request, &inputs, None, &grid_flags())?;
    match &args.out {
        Some(p) => {
            write_json("--out", p, &out.document)?;
            println!(
                "geodex: wrote {} (length {}, {} vertices)",
                p.display(),
                out.document["euclidean_length"],
                out.document["path"].as_array().map_or(0, Vec::len)
            );
        }
        None => println!("{}", out.document),
    }
    Ok(())
}

/// `geodex sample`.
pub fn run_sample(args: &SampleArgs) -> Result<(), SegmentCliError> {
    check_outputs(&[
        ("--out", Some(&args.out)),
        ("--labels", args.labels.as_deref()),
    ])?;
    let mut inputs = HashMap::new();
    let (cost, metric) = match &args.tensor {
        Some(p) => (
            None,
            Some(TensorSpec::Components(ComponentsTensor {
                dataset: read("--tensor", p, &mut inputs)?,
            })),
        ),
        None => (
            Some(cost_of(&args.cost, &args.shape, &args.design, &mut inputs)?),
            None,
        ),
    };
    let request = GridSampleRequest {
        cost,
        metric,
        spacing: args.spacing.spacing.clone(),
        obstacles: match &args.obstacles {
            Some(p) => Some(read("--obstacles", p, &mut inputs)?),
            None => None,
        },
        count: args.count,
        radius: args.radius,
        seeds: Vec::new(),
        sampling: match args.sampling {
            GridSamplingArg::Auto => GridSamplingSpec::Auto,
            GridSamplingArg::Exact => GridSamplingSpec::Exact,
            GridSamplingArg::Clustered => GridSamplingSpec::Clustered,
        },
    };
    let flags = grid_flags()
        .field("count", "--count")
        .field("radius", "--radius")
        .field("sampling", "--sampling")
        .metric(cost_flag(&args.cost));
    let (out, secs) = execute(&request, &inputs, None, &flags)?;
    save(&out, "distance", "--out", &Some(args.out.clone()))?;
    save(&out, "labels", "--labels", &args.labels)?;
    if let Some(p) = &args.samples {
        write_json("--samples", p, &out.document)?;
    }
    println!(
        "geodex: wrote {} ({} samples, covering radius {}, {:.3} s)",
        args.out.display(),
        out.document["stats"]["samples"],
        out.document["stats"]["covering_radius"],
        secs
    );
    Ok(())
}

/// `geodex group`.
pub fn run_group(args: &GroupArgs) -> Result<(), SegmentCliError> {
    check_outputs(&[
        ("--labels", args.labels.as_deref()),
        ("--distance", args.distance.as_deref()),
    ])?;
    let mut inputs = HashMap::new();
    let text = std::fs::read(&args.key_points).map_err(|e| {
        flag(
            "--key-points",
            format!("cannot read '{}': {e}", args.key_points.display()),
        )
    })?;
    let value: serde_json::Value = serde_json::from_slice(&text).map_err(|e| {
        flag(
            "--key-points",
            format!("'{}': {e}", args.key_points.display()),
        )
    })?;
    let (points, orientations) = match &value {
        serde_json::Value::Object(o) => (
            o.get("key_points").cloned().unwrap_or_default(),
            o.get("orientations").cloned(),
        ),
        other => (other.clone(), None),
    };
    let key_points: Vec<Vec<f64>> = serde_json::from_value(points).map_err(|e| {
        flag(
            "--key-points",
            format!("expected an array of [row, column] pairs: {e}"),
        )
    })?;
    let orientations: Option<Vec<f64>> = match orientations {
        None | Some(serde_json::Value::Null) => None,
        Some(v) => Some(serde_json::from_value(v).map_err(|e| {
            flag(
                "--key-points",
                format!("`orientations` must be an array of angles: {e}"),
            )
        })?),
    };
    let request = GridGroupRequest {
        cost: cost_of(&args.cost, &args.shape, &args.design, &mut inputs)?,
        spacing: args.spacing.spacing.clone(),
        obstacles: match &args.obstacles {
            Some(p) => Some(read("--obstacles", p, &mut inputs)?),
            None => None,
        },
        key_points,
        orientations,
        anisotropy: args.anisotropy,
        spread: None,
        max_links: args.max_links,
        ratio: args.ratio,
        relative: (args.relative != 0.0).then_some(args.relative),
        max_cost: args.max_cost,
        min_points: args.min_points,
        order: 2,
    };
    let flags = grid_flags()
        .field("key_points", "--key-points")
        .field("orientations", "--key-points")
        .metric(cost_flag(&args.cost));
    let (out, secs) = execute(&request, &inputs, None, &flags)?;
    write_json("--out", &args.out, &out.document)?;
    if let Some(p) = &args.geojson {
        write_json("--geojson", p, &out.document["geojson"])?;
    }
    save(&out, "labels", "--labels", &args.labels)?;
    save(&out, "distance", "--distance", &args.distance)?;
    let stats = &out.document["stats"];
    println!(
        "geodex: wrote {} ({} contours, {} closed, {} isolated key points, {} of {} links kept, {:.3} s)",
        args.out.display(),
        stats["contours"],
        stats["closed"],
        stats["isolated"],
        stats["kept"],
        stats["candidates"],
        secs
    );
    Ok(())
}

/// `geodex mesh-domain`.
pub fn run_domain_mesh(args: &DomainMeshArgs) -> Result<(), SegmentCliError> {
    let mut inputs = HashMap::new();
    let polygons = match &args.polygons {
        None => None,
        Some(p) => {
            let text = std::fs::read(p)
                .map_err(|e| flag("--polygons", format!("cannot read '{}': {e}", p.display())))?;
            let mut value: serde_json::Value = serde_json::from_slice(&text)
                .map_err(|e| flag("--polygons", format!("'{}': {e}", p.display())))?;
            if value["type"] == "Feature" {
                value = value["geometry"].take();
            }
            let geometry: DomainGeometry = serde_json::from_value(value).map_err(|e| {
                flag(
                    "--polygons",
                    format!(
                        "'{}' is not a GeoJSON Polygon or MultiPolygon: {e}",
                        p.display()
                    ),
                )
            })?;
            Some(geometry)
        }
    };
    let request = DomainMeshRequest {
        mask: match &args.mask {
            Some(p) => Some(read("--mask", p, &mut inputs)?),
            None => None,
        },
        polygons,
        count: args.count,
        edge_length: args.edge_length,
        cost: match &args.cost {
            Some(p) => Some(read("--cost", p, &mut inputs)?),
            None => None,
        },
        min_angle: args.min_angle,
        smoothing: args.smoothing,
        simplify: args.simplify,
        spacing: args.spacing.spacing.clone(),
    };
    let (out, secs) = execute(&request, &inputs, None, &grid_flags())?;
    let Some(mesh) = &out.mesh else {
        return Err(flag("geodex", "the operation returned no mesh"));
    };
    let boundary: Vec<f64> = match array(&out, "boundary") {
        Some(ArrayData::F64(a)) => a.iter().copied().collect(),
        _ => Vec::new(),
    };
    let props = [mesh_write::VertexProperty::F64("boundary", &boundary)];
    write_mesh_file(&mesh.mesh.mesh, &props, &args.out)?;
    if let Some(p) = &args.stats {
        write_json("--stats", p, &out.document)?;
    }
    let stats = &out.document["stats"];
    println!(
        "geodex: wrote {} ({} vertices, {} triangles, smallest angle {:.1} deg, {:.1} % >= 25 deg, {:.3} s)",
        args.out.display(),
        stats["vertices"],
        stats["triangles"],
        stats["min_angle"]["min"].as_f64().unwrap_or(0.0),
        100.0 * stats["min_angle"]["share_at_least_25"].as_f64().unwrap_or(0.0),
        secs
    );
    Ok(())
}

/// Writes a mesh as `.ply`, `.obj`, `.json` or `.glb` after `out`'s extension.
fn write_mesh_file(
    m: &crate::numerics::mesh::TriMesh,
    props: &[mesh_write::VertexProperty<'_>],
    out: &Path,
) -> Result<(), SegmentCliError> {
    let bytes = mesh_write::encode_by_extension(m, props, out).map_err(|e| flag("--out", e))?;
    std::fs::write(out, bytes)
        .map_err(|e| flag("--out", format!("cannot write '{}': {e}", out.display())))
}

/// `geodex mesh`.
pub fn run_mesh(args: &MeshArgs) -> Result<(), SegmentCliError> {
    check_outputs(&[
        ("--approximation", args.approximation.as_deref()),
        ("--picture", args.picture.as_deref()),
    ])?;
    let mut inputs = HashMap::new();
    let request = GridMeshRequest {
        dataset: read("--image", &args.image, &mut inputs)?,
        count: args.count,
        metric: match args.metric {
            MeshMetricArg::Uniform => MeshMetricSpec::Uniform,
            MeshMetricArg::Gradient => MeshMetricSpec::Gradient,
            MeshMetricArg::Hessian => MeshMetricSpec::Hessian,
            MeshMetricArg::AnisotropicHessian => MeshMetricSpec::AnisotropicHessian,
            MeshMetricArg::StructureTensor => MeshMetricSpec::StructureTensor,
            MeshMetricArg::EdgeTensor => MeshMetricSpec::EdgeTensor,
        },
        sigma: args.sigma,
        strength: args.strength,
        anisotropy: args.anisotropy,
        rho: args.rho,
        compare_uniform: !args.no_compare,
        flips: args.flips,
        moves: args.moves,
        spacing: args.spacing.spacing.clone(),
    };
    let flags = grid_flags()
        .field("dataset", "--image")
        .field("flips", "--flips")
        .field("moves", "--moves")
        .field("compare_uniform", "--no-compare");
    let (out, secs) = execute(&request, &inputs, None, &flags)?;
    let Some(mesh) = &out.mesh else {
        return Err(flag("geodex", "the operation returned no mesh"));
    };
    let values: Vec<f64> = match array(&out, "values") {
        Some(ArrayData::F64(a)) => a.iter().copied().collect(),
        _ => Vec::new(),
    };
    let props = [mesh_write::VertexProperty::F64("value", &values)];
    write_mesh_file(&mesh.mesh.mesh, &props, &args.out)?;
    save(
        &out,
        "approximation",
        "--approximation",
        &args.approximation,
    )?;
    save(&out, "picture", "--picture", &args.picture)?;
    if let Some(p) = &args.stats {
        write_json("--stats", p, &out.document)?;
    }
    let stats = &out.document["stats"];
    println!(
        "geodex: wrote {} ({} vertices, {} triangles, L2 error {}, uniform {}, {:.3} s)",
        args.out.display(),
        stats["vertices"],
        stats["triangles"],
        stats["l2_error"],
        stats["uniform"]["l2_error"],
        secs
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn segment_fields_map_to_flags_and_reasons_to_flags_too() {
        let m = segment_flags(&Some(PathBuf::from("w.npy")));
        assert_eq!(m.flag_of("seeds[1].point[0]"), "--seed 2");
        assert_eq!(m.flag_of("seeds"), "--seed");
        assert_eq!(m.flag_of("seed_image"), "--seed-image");
        assert_eq!(m.flag_of("cost.dataset"), "--cost");
        assert_eq!(m.flag_of("cost.design.sigma"), "--design");
        assert_eq!(m.flag_of("spacing[1]"), "--spacing value 2");
        assert_eq!(m.flag_of("max_distance"), "--max-distance");
        assert_eq!(
            m.reword("give labelled `seeds`, a `seed_image`, or both"),
            "give labelled `--seed`, a `--seed-image`, or both"
        );
        assert_eq!(
            segment_flags(&None).flag_of("cost.shape[0]"),
            "--shape value 1"
        );
    }

    #[test]
    fn other_grid_commands_map_their_renamed_fields() {
        assert_eq!(grid_flags().flag_of("mask"), "--mask");
        assert_eq!(
            grid_flags().flag_of("min_boundary_fraction"),
            "--min-boundary-fraction"
        );
        assert_eq!(grid_flags().flag_of("radius"), "--radius");
    }
}
