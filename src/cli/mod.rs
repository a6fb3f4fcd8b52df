//! The `geodex` command line: `serve` (the default), the grid and mesh
//! commands (`distance`, `metric`, `path`, `segment`, ...) and `bench`.
//!
//! A bare `geodex` (with or without serve flags) runs `geodex serve`.
//! Shared pieces: [`SpacingFlag`], [`design::DesignFlag`] (`--design`), the
//! array writer `output` (format by extension), the runner's way in `run`
//! with its progress bar (`progress`) and the field-to-flag tables of errors
//! (`flags`).

use std::process::ExitCode;

use clap::{Parser, Subcommand};

use crate::config::ServeArgs;

pub mod bench;
mod bench_tensor;
pub mod design;
pub mod distance;
pub mod embedding;
mod flags;
pub use flags::CliError;
pub mod gradient;
pub mod inverse;
pub mod keys;
pub mod metric;
mod output;
pub mod path;
mod progress;
mod run;
pub mod segment;

pub mod mesh_distance;
pub mod remesh;
pub mod shape;
mod usage;

/// `--spacing`, shared by every grid command.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct SpacingFlag {
    /// Physical size of a cell along each axis, axis 0 first. Default: 1 (or
    /// the voxel size of a NIfTI input).
    #[arg(
        long,
        value_name = "H[,H..]",
        value_delimiter = ',',
        allow_negative_numbers = true
    )]
    pub spacing: Option<Vec<f64>>,
}

/// geodex: geodesic distances, minimal paths and segmentations.
#[derive(Debug, Parser)]
#[command(
    name = "geodex",
    version,
    about,
    args_conflicts_with_subcommands = true
)]
pub struct Cli {
    /// What to do; `serve` when omitted.
    #[command(subcommand)]
    pub command: Option<Command>,
    /// Settings of the default `serve` command.
    #[command(flatten)]
    pub serve: ServeArgs,
}

/// Subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Run the HTTP service (the default).
    Serve(ServeArgs),
    /// Create, list or revoke API keys (in the service's job database).
    Keys(keys::KeysArgs),
    /// Compute a distance map from NPY files (batch use).
    Distance(distance::DistanceArgs),
    /// The cost W designed from an image (edges, intensity, vesselness), to look at.
    Metric(metric::MetricArgs),
    /// Time the solvers on fixed problems (see `geodex bench --help`).
    Bench(bench::BenchArgs),
    /// Exact Euclidean distance transform of a mask (binary, signed or multi-label).
    Edt(segment::EdtArgs),
    /// Seeded segmentation (geodesic Voronoi cells of labelled seeds).
    Segment(segment::SegmentArgs),
    /// Medial axis of a shape, with pruning.
    Skeleton(segment::SkeletonArgs),
    /// Dilate or erode a shape by a Euclidean or geodesic distance.
    Offset(segment::OffsetArgs),
    /// Collision-free path of a disc robot among obstacles.
    Plan(segment::PlanArgs),
    /// Farthest-point sampling of a grid (samples, distance, Voronoi labels).
    Sample(segment::SampleArgs),
    /// Mesh an image: vertices placed by a metric, geodesic Delaunay triangles.
    Mesh(segment::MeshArgs),
    /// Mesh a planar domain (a mask or GeoJSON polygons with holes): boundary first, angles >= 25 deg.
    MeshDomain(segment::DomainMeshArgs),
    /// Gradient of geodesic distances with respect to the cost (the discrete adjoint of fast marching).
    CostGradient(gradient::CostGradientArgs),
    /// Recover a slowness map from travel times (first-arrival tomography).
    Tomography(inverse::TomographyArgs),
    /// Fit an intensity metric so that its minimal paths follow example paths.
    FitMetric(inverse::FitMetricArgs),
    /// Shape from shading: a Lambertian surface's height (or perspective depth) from one image, and its mesh.
    ShapeFromShading(segment::ShadingArgs),
    /// Group key points into contours by minimal paths (perceptual grouping).
    Group(segment::GroupArgs),
    /// Extract minimal paths from NPY / image files (batch use).
    Path(path::PathArgs),

    /// Geodesic distance on a triangle mesh file (batch use), written as NPY.
    MeshDistance(mesh_distance::MeshDistanceArgs),
    /// Principal, mean and Gaussian curvature of a mesh file, as a PLY (or JSON, GLB) with vertex properties.
    MeshCurvature(mesh_distance::MeshCurvatureArgs),
    /// Remesh a surface: geodesic sampling, Lloyd relaxation, dual of the Voronoi cells.
    Remesh(remesh::RemeshArgs),
    /// Geodesic distance matrix of a mesh file (all pairs or landmark rows), written as NPY.
    DistanceMatrix(shape::DistanceMatrixArgs),
    /// Bending-invariant canonical form of a mesh file (MDS of its geodesic distances), written as PLY.
    Embed(shape::EmbedArgs),
    /// Canonical form of a shape given as a mask file (MDS of its inner geodesic distances).
    ShapeEmbed(embedding::ShapeEmbedArgs),
    /// Isomap embedding of a point-cloud file (an N × D array).
    Isomap(embedding::IsomapArgs),
    /// Geodesic shape descriptor of a mesh file (distance and eccentricity histograms, canonical-form moments), as JSON.
    Descriptor(shape::DescriptorArgs),
    /// Correspondence between two near-isometric mesh files (a point of the second for each vertex of the first).
    Correspond(shape::CorrespondArgs),
}

/// Entry point of the binary.
pub fn main() -> ExitCode {
    let cli = usage::parse_or_exit::<Cli>();
    let result = match cli.command {
        Some(Command::Serve(args)) => crate::app::serve(args),
        Some(Command::Keys(args)) => keys::run(&args),
        Some(Command::Distance(args)) => distance::run(&args).map_err(Into::into),
        Some(Command::Metric(args)) => metric::run(&args).map_err(Into::into),
        Some(Command::Bench(args)) => bench::run(&args).map_err(Into::into),
        Some(Command::Edt(args)) => segment::run_edt(&args).map_err(Into::into),
        Some(Command::Segment(args)) => segment::run_segment(&args).map_err(Into::into),
        Some(Command::Skeleton(args)) => segment::run_skeleton(&args).map_err(Into::into),
        Some(Command::Offset(args)) => segment::run_offset(&args).map_err(Into::into),
        Some(Command::Plan(args)) => segment::run_plan(&args).map_err(Into::into),
        Some(Command::Sample(args)) => segment::run_sample(&args).map_err(Into::into),
        Some(Command::Mesh(args)) => segment::run_mesh(&args).map_err(Into::into),
        Some(Command::MeshDomain(args)) => segment::run_domain_mesh(&args).map_err(Into::into),
        Some(Command::CostGradient(args)) => gradient::run(&args).map_err(Into::into),
        Some(Command::Tomography(args)) => inverse::run_tomography(&args).map_err(Into::into),
        Some(Command::FitMetric(args)) => inverse::run_fit_metric(&args).map_err(Into::into),
        Some(Command::ShapeFromShading(args)) => {
            segment::run_shape_from_shading(&args).map_err(Into::into)
        }
        Some(Command::Group(args)) => segment::run_group(&args).map_err(Into::into),
        Some(Command::Path(args)) => path::run(&args).map_err(Into::into),

        Some(Command::MeshDistance(args)) => mesh_distance::run(&args).map_err(anyhow::Error::msg),
        Some(Command::MeshCurvature(args)) => {
            mesh_distance::run_curvature(&args).map_err(anyhow::Error::msg)
        }
        Some(Command::Remesh(args)) => remesh::run(&args).map_err(anyhow::Error::msg),
        Some(Command::DistanceMatrix(args)) => {
            shape::run_distance_matrix(&args).map_err(anyhow::Error::msg)
        }
        Some(Command::Embed(args)) => shape::run_embed(&args).map_err(anyhow::Error::msg),
        Some(Command::ShapeEmbed(args)) => embedding::run_shape_embed(&args).map_err(Into::into),
        Some(Command::Isomap(args)) => embedding::run_isomap(&args).map_err(Into::into),
        Some(Command::Descriptor(args)) => shape::run_descriptor(&args).map_err(anyhow::Error::msg),
        Some(Command::Correspond(args)) => shape::run_correspond(&args).map_err(anyhow::Error::msg),
        None => crate::app::serve(cli.serve),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("geodex: {e:#}");
            ExitCode::FAILURE
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bare_flags_and_serve_subcommand_both_parse() {
        let cli = Cli::try_parse_from(["geodex", "--addr", "127.0.0.1:9", "--cors-origins", "a,b"])
            .expect("bare flags");
        assert!(cli.command.is_none());
        assert_eq!(cli.serve.addr.port(), 9);
        assert_eq!(cli.serve.cors_origins, ["a", "b"]);
        let cli = Cli::try_parse_from(["geodex", "serve", "--request-timeout-secs", "0.5"])
            .expect("serve");
        match cli.command {
            Some(Command::Serve(a)) => assert_eq!(a.request_timeout_secs, 0.5),
            other => panic!("{other:?}"),
        }
    }
}
