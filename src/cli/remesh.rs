//! `geodex remesh`: surface remeshing of a mesh file (the request of
//! `POST /v1/mesh/remesh`, run through the same operation).
//!
//! ```text
//! geodex remesh --mesh bunny.ply --count 5000 --out remeshed.ply --stats S.json
//! geodex remesh --mesh part.obj --edge-length 0.5 --adaptation curvature --out part2.obj
//! geodex remesh --mesh pipe.ply --count 2000 --adaptation anisotropic --max-ratio 4 --out pipe2.ply
//! ```

use std::path::PathBuf;
use std::sync::Arc;

use clap::{Args, ValueEnum};

use super::mesh_distance::{load_mesh_file, One};
use super::run::{run_operation, FlagMap};
use crate::io::mesh::write as mesh_write;
use crate::ops::mesh_remesh::{MeshRemeshRequest, RemeshAdaptationSpec, RemeshSamplingSpec};

/// How `geodex remesh` places its samples.
#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum SamplingArg {
    /// Clustered when the input has at least 8 vertices per sample and
    /// the adaptation is not anisotropic, else exact.
    Auto,
    /// Exact farthest-point sampling on the input's vertices.
    Exact,
    /// Farthest-point sampling on clusters of vertices, then one front per sample.
    Clustered,
}

/// The density of `geodex remesh`.
#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum AdaptationArg {
    /// Cells of equal geodesic size.
    Uniform,
    /// Smaller cells where the surface bends.
    Curvature,
    /// Cells elongated along the directions of low curvature.
    Anisotropic,
}

/// Flags of `geodex remesh`.
#[derive(Debug, Clone, Args)]
pub struct RemeshArgs {
    /// The mesh to remesh (PLY, OBJ, OFF, STL).
    #[arg(long, value_name = "MESH")]
    pub mesh: PathBuf,
    /// Target number of vertices.
    #[arg(long, value_name = "K")]
    pub count: Option<usize>,
    /// Target edge length (instead of --count).
    #[arg(long, value_name = "H")]
    pub edge_length: Option<f64>,
    /// The density.
    #[arg(long, value_enum, default_value = "uniform")]
    pub adaptation: AdaptationArg,
    /// Contrast of the curvature adaptation.
    #[arg(long, default_value_t = 2.0, allow_negative_numbers = true)]
    pub strength: f64,
    /// Largest length-to-width ratio of the anisotropic cells.
    #[arg(long, default_value_t = 3.0, allow_negative_numbers = true)]
    pub max_ratio: f64,
    /// Geodesic Lloyd iterations (default 0 when the final relaxation
    /// runs, else 5).
    #[arg(long)]
    pub lloyd_iterations: Option<usize>,
    /// Rounds of edge flips and tangential relaxation on the input surface
    /// (0: vertices stay at input vertices; default `400000 / count`
    /// clamped to 20..=100).
    #[arg(long)]
    pub smoothing_iterations: Option<usize>,
    /// How the samples are placed.
    #[arg(long, value_enum, default_value = "auto")]
    pub sampling: SamplingArg,
    /// Where to write the new mesh: `.ply`, `.obj`, `.json` or `.glb` (glTF binary).
    #[arg(long, value_name = "OUT.ply")]
    pub out: PathBuf,
    /// Where to write the statistics (JSON).
    #[arg(long, value_name = "S.json")]
    pub stats: Option<PathBuf>,
}

/// Runs `geodex remesh`.
pub fn run(args: &RemeshArgs) -> Result<(), String> {
    let input = load_mesh_file(&args.mesh)?;
    let request = MeshRemeshRequest {
        mesh: "file".into(),
        count: args.count,
        edge_length: args.edge_length,
        adaptation: match args.adaptation {
            AdaptationArg::Uniform => RemeshAdaptationSpec::Uniform,
            AdaptationArg::Curvature => RemeshAdaptationSpec::Curvature,
            AdaptationArg::Anisotropic => RemeshAdaptationSpec::Anisotropic,
        },
        strength: args.strength,
        max_ratio: args.max_ratio,
        lloyd_iterations: args.lloyd_iterations,
        smoothing_iterations: args.smoothing_iterations,
        sampling: match args.sampling {
            SamplingArg::Auto => RemeshSamplingSpec::Auto,
            SamplingArg::Exact => RemeshSamplingSpec::Exact,
            SamplingArg::Clustered => RemeshSamplingSpec::Clustered,
        },
        hausdorff: true,
    };
    // Every field of the request is spelled as its flag (`max_ratio`: `--max-ratio`).
    let output = run_operation(Box::new(request), One(Arc::new(input)), &FlagMap::new())
        .map_err(|e| e.to_string())?;
    let Some(mesh) = &output.mesh else {
        return Err("geodex: the operation returned no mesh".into());
    };
    let m = &mesh.mesh.mesh;
    let bytes =
        mesh_write::encode_by_extension(m, &[], &args.out).map_err(|e| format!("--out: {e}"))?;
    std::fs::write(&args.out, bytes)
        .map_err(|e| format!("--out: cannot write '{}': {e}", args.out.display()))?;
    if let Some(p) = &args.stats {
        let text = serde_json::to_vec_pretty(&output.document).map_err(|e| e.to_string())?;
        std::fs::write(p, text)
            .map_err(|e| format!("--stats: cannot write '{}': {e}", p.display()))?;
    }
    let stats = &output.document["stats"];
    println!(
        "geodex: wrote {} ({} vertices, {} triangles, topology kept: {}, Hausdorff/diagonal {}, {:.3} s)",
        args.out.display(),
        stats["vertices"],
        stats["triangles"],
        stats["topology_kept"],
        stats["hausdorff_relative"],
        stats["seconds"].as_f64().unwrap_or(0.0)
    );
    Ok(())
}
