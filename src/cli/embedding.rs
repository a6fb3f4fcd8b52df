//! `geodex shape-embed` and `geodex isomap`: canonical forms of a shape
//! given as a mask file, and Isomap of a point-cloud file, for batch users.
//!
//! Each builds the request of its endpoint (`POST /v1/grid/shape-embed`,
//! `POST /v1/points/isomap`) and runs it through the same operation.
//!
//! ```text
//! geodex shape-embed --mask hand.png --landmarks 100 --out X.npy --mesh form.ply
//! geodex isomap --points roll.npy --k 10 --landmarks 500 --out Y.npy
//! ```

use std::collections::HashMap;
use std::path::PathBuf;

use clap::Args;

use super::run::FlagMap;
use super::segment::{
    array, check_outputs, execute, flag, grid_flags, read, save, SegmentCliError,
};
use super::SpacingFlag;
use crate::io::mesh::write::encode_by_extension;
use crate::ops::grid_shape_embed::GridShapeEmbedRequest;
use crate::ops::points_isomap::PointsIsomapRequest;
use crate::ops::spec::defaults::default_order;

/// Flags of `geodex shape-embed`.
#[derive(Debug, Clone, Args)]
pub struct ShapeEmbedArgs {
    /// The shape mask (2D or 3D; non-zero cells are the shape, in one piece).
    #[arg(long, value_name = "M.npy")]
    pub mask: PathBuf,
    /// Physical size of a cell along each axis.
    #[command(flatten)]
    pub spacing: SpacingFlag,
    /// Embedding dimension, 2 or 3.
    #[arg(long, default_value_t = 2)]
    pub dimensions: usize,
    /// Landmark MDS from this many farthest-point landmarks (default: all pairs, up to 5000 cells).
    #[arg(long)]
    pub landmarks: Option<usize>,
    /// Fast-marching order of the inner distances, 1 or 2.
    #[arg(long, default_value_t = default_order())]
    pub order: u8,
    /// Output: the cells × dimensions embedded coordinates (f64; .npy or .tiff).
    #[arg(long, value_name = "X.npy")]
    pub out: PathBuf,
    /// Output: the index coordinates of each embedded cell (cells × ndim, .npy).
    #[arg(long, value_name = "C.npy")]
    pub cells: Option<PathBuf>,
    /// Output: the inner-distance rows (landmarks × cells, .npy).
    #[arg(long, value_name = "D.npy")]
    pub matrix: Option<PathBuf>,
    /// Output (2D): the pixel mesh at the embedded positions (.ply, .obj, .json or .glb).
    #[arg(long, value_name = "FORM.ply")]
    pub mesh: Option<PathBuf>,
}

/// Flags of `geodex isomap`.
#[derive(Debug, Clone, Args)]
pub struct IsomapArgs {
    /// The point cloud: an N × D array, one point per row.
    #[arg(long, value_name = "P.npy")]
    pub points: PathBuf,
    /// Neighbours per point in the k-NN graph.
    #[arg(long, default_value_t = 10)]
    pub k: usize,
    /// Embedding dimension.
    #[arg(long, default_value_t = 2)]
    pub dimensions: usize,
    /// L-Isomap from this many farthest-point landmarks (default: all pairs, up to 5000 points).
    #[arg(long)]
    pub landmarks: Option<usize>,
    /// Output: the N × dimensions embedding (f64; .npy or .tiff).
    #[arg(long, value_name = "Y.npy")]
    pub out: PathBuf,
}

/// Runs `geodex shape-embed`.
pub fn run_shape_embed(args: &ShapeEmbedArgs) -> Result<(), SegmentCliError> {
    check_outputs(&[
        ("--out", Some(&args.out)),
        ("--cells", args.cells.as_deref()),
        ("--matrix", args.matrix.as_deref()),
    ])?;
    let mut inputs = HashMap::new();
    let request = GridShapeEmbedRequest {
        mask: read("--mask", &args.mask, &mut inputs)?,
        spacing: args.spacing.spacing.clone(),
        dimensions: args.dimensions,
        landmarks: args.landmarks,
        order: args.order,
        matrix: args.matrix.is_some(),
    };
    let (out, secs) = execute(&request, &inputs, None, &grid_flags())?;
    save(&out, "coordinates", "--out", &Some(args.out.clone()))?;
    save(&out, "cells", "--cells", &args.cells)?;
    save(&out, "matrix", "--matrix", &args.matrix)?;
    if let Some(path) = &args.mesh {
        let mesh = out
            .mesh
            .as_ref()
            .ok_or_else(|| flag("--mesh", "a mesh is made of 2D shapes only"))?;
        let bytes =
            encode_by_extension(&mesh.mesh.mesh, &[], path).map_err(|e| flag("--mesh", e))?;
        std::fs::write(path, bytes)
            .map_err(|e| flag("--mesh", format!("cannot write '{}': {e}", path.display())))?;
    }
    println!(
        "geodex: wrote {} ({} cells, stress {}, {:.3} s)",
        args.out.display(),
        out.document["stats"]["cells"],
        out.document["stress"],
        secs
    );
    Ok(())
}

/// Runs `geodex isomap`.
pub fn run_isomap(args: &IsomapArgs) -> Result<(), SegmentCliError> {
    check_outputs(&[("--out", Some(&args.out))])?;
    let mut inputs = HashMap::new();
    let request = PointsIsomapRequest {
        points: read("--points", &args.points, &mut inputs)?,
        k: args.k,
        dimensions: args.dimensions,
        landmarks: args.landmarks,
    };
    let (out, secs) = execute(&request, &inputs, None, &FlagMap::new())?;
    if array(&out, "embedding").is_none() {
        return Err(flag("--out", "the operation returned no embedding"));
    }
    save(&out, "embedding", "--out", &Some(args.out.clone()))?;
    println!(
        "geodex: wrote {} ({} points, residual variance {}, {:.3} s)",
        args.out.display(),
        out.document["stats"]["points"],
        out.document["residual_variance"],
        secs
    );
    Ok(())
}
