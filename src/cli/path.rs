//! `geodex path`: minimal paths from the command line. The flags of
//! `geodex distance` (the metric, the sources, the scheme) plus `--to`
//! (repeatable end points) and `--out PATHS.json`.
//!
//! The command builds a [`GridPathsRequest`], the schema of `POST
//! /v1/grid/paths` and of the job queue, and runs it with
//! [`grid_paths::execute`] (without a cache).
//!
//! ```text
//! geodex path --cost W.npy --source 10,20 --to 200,31.5 --to 90,90 --out paths.json
//! geodex path --cost road.png --design '{"kind": "intensity", "at": [10, 20]}' \
//!     --source 10,20 --to 200,31.5 --format svg --out road.svg
//! geodex path --cost img.png --design '{"kind": "edges"}' --contour 10,10 --contour 10,90 \
//!     --contour 80,50 --out contour.json
//! geodex path --tensor T.npy --source 10,20 --to 200,31.5 --out paths.json
//! ```
//!
//! `--tensor` is the Riemannian metric of `geodex distance --tensor`; the
//! paths then descend along `−M⁻¹∇U` and their geodesic length is
//! `∫ sqrt(γ'ᵀ M γ')`.

use std::path::PathBuf;

use clap::{ArgGroup, Args, ValueEnum};

use super::distance::{flag, parse_points, point_sources, DistanceError, SchemeFlags};
use super::run::{run_operation, FlagMap};
use crate::ops::grid_paths::{GridPathsRequest, PathFormat, PathOut};

/// Flags of `geodex path`.
#[derive(Debug, Clone, Args)]
#[command(group(ArgGroup::new("metric").required(true).args(["cost", "shape", "tensor"])))]
pub struct PathArgs {
    /// Cost per unit length W (or a speed with --speed, or an image with
    /// --design): a 2D or 3D array (NPY, PNG, TIFF, NIfTI...). +inf marks a wall.
    #[arg(long, value_name = "COST.npy")]
    pub cost: Option<PathBuf>,
    /// A Riemannian metric instead of a cost: (N, M, 3) holding m11, m12, m22
    /// (2D) or (N, M, P, 6) holding m11, m12, m13, m22, m23, m33 (3D).
    #[arg(long, value_name = "T.npy", conflicts_with_all = ["speed", "design", "method", "connectivity"])]
    pub tensor: Option<PathBuf>,
    /// Grid shape for a unit cost, instead of --cost.
    #[arg(long, value_name = "N,M[,P]", value_delimiter = ',')]
    pub shape: Option<Vec<usize>>,
    /// A point source (index coordinates, axis 0 first); repeatable.
    #[arg(long = "source", value_name = "I,J[,K]", allow_hyphen_values = true)]
    pub sources: Vec<String>,
    /// An end point: one path from it to the nearest source; repeatable.
    #[arg(long = "to", value_name = "I,J[,K]", allow_hyphen_values = true)]
    pub to: Vec<String>,
    /// A way-point (instead of --source/--to): the path through them in order; repeatable.
    #[arg(long = "waypoint", value_name = "I,J[,K]", allow_hyphen_values = true)]
    pub waypoints: Vec<String>,
    /// A point of a closed contour (instead of --source/--to); repeatable, at least 3.
    #[arg(long = "contour", value_name = "I,J[,K]", allow_hyphen_values = true)]
    pub contour: Vec<String>,
    /// Spacing, scheme, speed, design and obstacles (as in `geodex distance`).
    #[command(flatten)]
    pub scheme: SchemeFlags,
    /// Compute the whole distance map instead of stopping at the end points.
    #[arg(long)]
    pub no_early_stop: bool,
    /// Simplify each path to this tolerance in cells (Ramer–Douglas–Peucker;
    /// every dropped vertex within it of the polyline). 0 keeps every vertex.
    #[arg(long, default_value_t = 0.0, value_name = "CELLS")]
    pub simplify: f64,
    /// Output format.
    #[arg(long, value_enum, default_value_t = FormatArg::Json)]
    pub format: FormatArg,
    /// Where to write the paths (JSON, GeoJSON or SVG).
    #[arg(long, value_name = "PATHS.json")]
    pub out: PathBuf,
}

/// `--format`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum FormatArg {
    /// The paths as JSON (index and world coordinates, lengths, statistics).
    Json,
    /// A GeoJSON FeatureCollection of LineStrings (2D).
    Geojson,
    /// An SVG of the paths over the image (2D).
    Svg,
}

/// The flags behind the fields of [`GridPathsRequest`].
fn path_flags(cost_flag: &str) -> FlagMap {
    FlagMap::new()
        .each("sources", "--source")
        .each("ends", "--to")
        .each("waypoints", "--waypoint")
        .each("contour", "--contour")
        .field("early_stop", "--no-early-stop")
        .metric(cost_flag)
}

/// Runs `geodex path`.
pub fn run(args: &PathArgs) -> Result<(), DistanceError> {
    let sources = parse_points("--source", &args.sources)?;
    let ends = parse_points("--to", &args.to)?;
    let waypoints = parse_points("--waypoint", &args.waypoints)?;
    let contour = parse_points("--contour", &args.contour)?;
    let scheme = &args.scheme;
    let design = scheme.design.spec(args.cost.is_some(), "--cost")?;
    let metric = scheme.metric(
        args.cost.as_deref(),
        args.shape.as_deref(),
        args.tensor.as_deref(),
    );
    let (inputs, cost, tensor) = metric.load(design)?;
    let cost_flag = metric.flag();
    let request = GridPathsRequest {
        cost,
        metric: tensor,
        spacing: scheme.spacing.spacing.clone(),
        obstacles: scheme.obstacles_id(),
        sources: point_sources(sources),
        ends,
        waypoints,
        contour,
        method: scheme.method_spec(),
        order: scheme.order,
        connectivity: scheme.connectivity_spec(),
        factoring: !scheme.no_factoring,
        early_stop: !args.no_early_stop,
        step: 0.5,
        simplify: args.simplify,
        format: match args.format {
            FormatArg::Json => PathFormat::Json,
            FormatArg::Geojson => PathFormat::Geojson,
            FormatArg::Svg => PathFormat::Svg,
        },
        pinned: Default::default(),
    };
    let output = run_operation(Box::new(request), inputs, &path_flags(cost_flag))?;
    let doc = output.document;
    let body = match args.format {
        FormatArg::Json => {
            serde_json::to_string_pretty(&doc).map_err(|e| flag("--out", e.to_string()))?
        }
        FormatArg::Geojson => doc.get("geojson").cloned().unwrap_or_default().to_string(),
        FormatArg::Svg => doc
            .get("svg")
            .and_then(|s| s.as_str())
            .unwrap_or_default()
            .to_string(),
    };
    std::fs::write(&args.out, body).map_err(|e| {
        flag(
            "--out",
            format!("cannot write '{}': {e}", args.out.display()),
        )
    })?;
    let paths: Vec<PathOut> =
        serde_json::from_value(doc["paths"].clone()).map_err(|e| flag("--out", e.to_string()))?;
    for p in &paths {
        println!(
            "geodex: path {} to source {}: {} vertices, geodesic length {:.6}, euclidean length {:.6}",
            p.index,
            p.source,
            p.points.len(),
            p.geodesic_length,
            p.euclidean_length
        );
    }
    println!("geodex: wrote {}", args.out.display());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn request_fields_map_to_path_flags() {
        let m = path_flags("--cost");
        assert_eq!(m.flag_of("ends[1]"), "--to 2");
        assert_eq!(m.flag_of("waypoints[0]"), "--waypoint 1");
        assert_eq!(m.flag_of("contour[2]"), "--contour 3");
        assert_eq!(m.flag_of("cost.design.scales[0]"), "--design");
        assert_eq!(m.flag_of("sources[0]"), "--source 1");
        assert_eq!(m.flag_of("format"), "--format");
    }
}
