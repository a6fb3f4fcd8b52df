//! `geodex distance`: the distance map of a cost file (or a unit cost on a
//! shape, or a cost designed from an image with `--design`) for batch users,
//! written as NPY, TIFF, a colour-mapped PNG or a 16-bit PNG after the
//! extension of `--out` ([`super::output`]).
//!
//! The command builds a [`GridDistanceRequest`], the schema the HTTP service
//! and the job queue use, and runs it with [`grid_distance::execute`], so the
//! command line and the service accept and refuse exactly the same inputs.
//! Points are in array index order (axis 0 first) and in index units.
//!
//! ```text
//! geodex distance --cost W.npy --source 10,20 --source 200,31.5 --out U.npy --labels L.npy
//! geodex distance --shape 128,128,128 --source 64,64,64 --spacing 1,1,2 --out U.npy
//! geodex distance --tensor T.npy --source 10,20 --out U.npy
//! geodex distance --phi PHI.npy --signed --out D.npy       # redistancing, as skfmm.distance(phi)
//! geodex distance --source-mask REGION.npy --cost W.npy --out U.npy
//! geodex distance --cost road.png --design edges --source 10,20 --out U.png
//! ```
//!
//! `--tensor T.npy` gives a Riemannian metric instead of a cost: shape
//! `(n0, n1, 3)` holding `m11, m12, m22` per cell (2D), or `(n0, n1, n2, 6)`
//! holding `m11, m12, m13, m22, m23, m33` (3D), axis 0 first; it is solved
//! by the anisotropic fast marching. A cell that is not finite or not
//! positive definite is refused, naming the first such cell.
//!
//! Errors are one line on stderr naming the flag at fault, e.g.
//! `geodex: --source 2: point [300.0, 4.0] is outside the grid of shape [256, 256] ...`,
//! and a non-zero exit status.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use clap::{ArgGroup, Args, ValueEnum};

use super::design::DesignFlag;
use super::output;
use super::SpacingFlag;

use super::run::{run_operation, CliError, CliInputs, FlagMap};
use crate::io::{self, Limits};
use crate::numerics::grid::MAX_CELLS;
use crate::ops::spec::cost::{CostSpec, InterpretationSpec};
use crate::ops::spec::distance::GridDistanceRequest;
use crate::ops::spec::scheme::{ConnectivitySpec, MethodSpec, OutputSpec, SourceSpec, StopSpec};
use crate::ops::spec::tensor::{ComponentsTensor, TensorSpec};
use crate::ops::InputArray;

/// Flags of `geodex distance`.
#[derive(Debug, Clone, Args)]
#[command(group(ArgGroup::new("metric").args(["cost", "shape", "tensor"])))]
#[command(group(ArgGroup::new("source_kind").required(true).multiple(true).args(["sources", "phi", "source_mask"])))]
pub struct DistanceArgs {
    /// Cost per unit length W (or a speed with --speed): a 2D or 3D array,
    /// f32 or f64 (NPY, or any format geodex reads). +inf marks a wall.
    #[arg(long, value_name = "COST.npy")]
    pub cost: Option<PathBuf>,
    /// A Riemannian metric instead of a cost: an array of shape (N, M, 3)
    /// holding m11, m12, m22 per cell (2D) or (N, M, P, 6) holding m11, m12,
    /// m13, m22, m23, m33 (3D); every cell symmetric positive definite.
    #[arg(long, value_name = "T.npy", conflicts_with_all = ["speed", "design", "method", "connectivity"])]
    pub tensor: Option<PathBuf>,
    /// Grid shape for a unit cost, instead of --cost.
    #[arg(long, value_name = "N,M[,P]", value_delimiter = ',')]
    pub shape: Option<Vec<usize>>,
    /// A point source in index coordinates, axis 0 first; repeat for several
    /// sources (label i-1 for the i-th).
    #[arg(long = "source", value_name = "I,J[,K]", allow_hyphen_values = true)]
    pub sources: Vec<String>,
    /// A level set phi (2D or 3D array, negative inside): the source is its
    /// zero level set, located between cells (as `skfmm.distance`). It must
    /// be the only source. Without --cost, --shape or --tensor the cost is 1
    /// on phi's grid.
    #[arg(long, value_name = "PHI.npy", conflicts_with_all = ["sources", "source_mask", "tensor"])]
    pub phi: Option<PathBuf>,
    /// With --phi: write the signed distance, negative where phi < 0 (the
    /// redistancing of phi).
    #[arg(long, requires = "phi")]
    pub signed: bool,
    /// A mask of the grid's shape whose non-zero cells are sources of value
    /// 0 (after the --source points, so its label is their count). Without
    /// --cost, --shape or --tensor the cost is 1 on the mask's grid.
    #[arg(long, value_name = "MASK.npy")]
    pub source_mask: Option<PathBuf>,
    /// Spacing, scheme, speed and obstacles (shared with `geodex path`).
    #[command(flatten)]
    pub scheme: SchemeFlags,
    /// Stop once the front passes this distance (cells beyond stay +inf).
    #[arg(long, value_name = "D", allow_negative_numbers = true)]
    pub max_distance: Option<f64>,
    /// Stop once these points (index coordinates) are reached; repeatable.
    #[arg(long = "target", value_name = "I,J[,K]", allow_hyphen_values = true)]
    pub targets: Vec<String>,
    /// Where to write the distance U (f64, +inf where not reached): `.npy`,
    /// `.tiff` (f32), `.png` (colour-mapped picture) or `.png16` (16-bit grey).
    #[arg(long, value_name = "U.npy")]
    pub out: PathBuf,
    /// Where to write the Voronoi labels (i32, -1 where not reached), by
    /// extension as --out.
    #[arg(long, value_name = "L.npy")]
    pub labels: Option<PathBuf>,
}

/// The flags of `geodex distance` and `geodex path` that shape the solve
/// itself: spacing, scheme, speed and obstacles.
#[derive(Debug, Clone, Args)]
pub struct SchemeFlags {
    /// Physical size of a cell along each axis.
    #[command(flatten)]
    pub spacing: SpacingFlag,
    /// The solver: fast_marching, fast_sweeping or dijkstra.
    #[arg(long, value_parser = method_value::<MethodArg>, default_value = "fast_marching")]
    pub method: MethodArg,
    /// Order of the finite-difference scheme.
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u8).range(1..=2))]
    pub order: u8,
    /// Turn off source factoring around point sources (fast marching and
    /// fast sweeping, both orders).
    #[arg(long)]
    pub no_factoring: bool,
    /// Graph neighbourhood of --method dijkstra.
    #[arg(long, value_enum, default_value_t = ConnectivityArg::Diagonal)]
    pub connectivity: ConnectivityArg,
    /// Read the values of --cost as a speed F = 1/W (0 marks a wall).
    #[arg(long)]
    pub speed: bool,
    /// Design the cost from the --cost image.
    #[command(flatten)]
    pub design: DesignFlag,
    /// A mask of the grid's shape whose non-zero cells are obstacles.
    #[arg(long, value_name = "MASK.npy")]
    pub obstacles: Option<PathBuf>,
}

impl SchemeFlags {
    /// The metric flags, with the command's own `--cost`, `--shape`, `--tensor`.
    pub(crate) fn metric<'a>(
        &'a self,
        cost: Option<&'a Path>,
        shape: Option<&'a [usize]>,
        tensor: Option<&'a Path>,
    ) -> MetricFlags<'a> {
        MetricFlags {
            cost,
            shape,
            tensor,
            obstacles: self.obstacles.as_deref(),
            speed: self.speed,
        }
    }

    /// `--method` in the request's terms.
    pub(crate) fn method_spec(&self) -> MethodSpec {
        match self.method {
            MethodArg::FastMarching => MethodSpec::FastMarching,
            MethodArg::FastSweeping => MethodSpec::FastSweeping,
            MethodArg::Dijkstra => MethodSpec::Dijkstra,
        }
    }

    /// `--connectivity` in the request's terms.
    pub(crate) fn connectivity_spec(&self) -> ConnectivitySpec {
        match self.connectivity {
            ConnectivityArg::Axial => ConnectivitySpec::Axial,
            ConnectivityArg::Diagonal => ConnectivitySpec::Diagonal,
            ConnectivityArg::Extended => ConnectivitySpec::Extended,
        }
    }

    /// The dataset id of `--obstacles` in the request.
    pub(crate) fn obstacles_id(&self) -> Option<String> {
        self.obstacles.as_ref().map(|_| "obstacles".to_string())
    }
}

/// Point sources (index coordinates) as the request's source sections.
pub(crate) fn point_sources(points: Vec<Vec<f64>>) -> Vec<SourceSpec> {
    points.into_iter().map(SourceSpec::at_point).collect()
}

/// A `--method` value, spelled as in the request JSON (`fast_marching`).
/// The old command-line spellings with a dash (`fast-marching`) are
/// refused with the new name, as the service refuses them
/// ([`crate::ops::renamed`]).
pub(crate) fn method_value<E: ValueEnum>(s: &str) -> Result<E, String> {
    if let Ok(v) = E::from_str(s, false) {
        return Ok(v);
    }
    let snake = s.replace('-', "_");
    if E::from_str(&snake, false).is_ok() {
        return Err(format!(
            "`{s}` was renamed `{snake}` (see CHANGELOG.md); pass --method {snake}"
        ));
    }
    let names: Vec<String> = E::value_variants()
        .iter()
        .filter_map(|v| v.to_possible_value().map(|p| p.get_name().to_string()))
        .collect();
    Err(format!("unknown method `{s}`; one of {}", names.join(", ")))
}

/// `--method`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
#[value(rename_all = "snake_case")]
pub enum MethodArg {
    /// Fast marching.
    FastMarching,
    /// Fast sweeping.
    FastSweeping,
    /// Dijkstra on the grid graph.
    Dijkstra,
}

/// `--connectivity`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ConnectivityArg {
    /// 4 neighbours in 2D, 6 in 3D.
    Axial,
    /// 8 neighbours in 2D, 18 in 3D.
    Diagonal,
    /// 16 neighbours in 2D, 26 in 3D.
    Extended,
}

/// Why `geodex distance` (and `geodex path`) failed: always names the flag
/// at fault.
pub type DistanceError = CliError;

pub(crate) fn flag(flag: impl Into<String>, reason: impl Into<String>) -> DistanceError {
    CliError::Flag {
        flag: flag.into(),
        reason: reason.into(),
    }
}

/// Runs `geodex distance`.
pub fn run(args: &DistanceArgs) -> Result<(), DistanceError> {
    output::check("--out", Some(&args.out))?;
    output::check("--labels", args.labels.as_deref())?;
    let sources = parse_points("--source", &args.sources)?;
    let targets = parse_points("--target", &args.targets)?;
    let scheme = &args.scheme;
    let metric = scheme.metric(
        args.cost.as_deref(),
        args.shape.as_deref(),
        args.tensor.as_deref(),
    );
    let design = scheme.design.spec(args.cost.is_some(), "--cost")?;
    let (mut inputs, mut cost, tensor) = metric.load(design)?;
    let mut cost_flag = metric.flag();
    let mut spacing = scheme.spacing.spacing.clone();
    let mut sources = point_sources(sources);
    // --phi and --source-mask: datasets named `phi` and `source_mask`.
    for (name, path, id) in [
        ("--phi", &args.phi, "phi"),
        ("--source-mask", &args.source_mask, "source_mask"),
    ] {
        let Some(path) = path else { continue };
        let decoded = read_array(name, path)?;
        if args.cost.is_none() && args.shape.is_none() && args.tensor.is_none() {
            // A unit cost on the source's grid, with its stored spacing.
            cost = Some(CostSpec {
                dataset: None,
                constant: Some(1.0),
                shape: Some(decoded.array.shape().to_vec()),
                interpretation: InterpretationSpec::Cost,
                design: None,
            });
            cost_flag = name;
            if spacing.is_none() {
                spacing = decoded.spacing.clone();
            }
        }
        inputs.insert(
            id.into(),
            InputArray {
                array: Arc::new(decoded.array),
                spacing: decoded.spacing,
            },
        );
        sources.push(SourceSpec {
            level_set: (id == "phi").then(|| id.to_string()),
            mask: (id == "source_mask").then(|| id.to_string()),
            ..SourceSpec::default()
        });
    }
    if cost.is_none() && tensor.is_none() {
        return Err(flag(
            "--cost",
            "give the metric: --cost, --shape or --tensor (or --phi / --source-mask for a unit cost on their grid)",
        ));
    }
    let point_count = args.sources.len();
    let flags = FlagMap::new()
        .each_in("sources", "--source", 0..point_count)
        .all_in(
            "sources",
            if args.phi.is_some() {
                "--phi"
            } else {
                "--source-mask"
            },
            point_count..usize::MAX,
        )
        .field("sources", "--source")
        .each("stop.targets", "--target")
        .field("stop.max_distance", "--max-distance")
        .field("outputs.labels", "--labels")
        .metric(cost_flag);

    let request = GridDistanceRequest {
        cost,
        metric: tensor,
        spacing,
        obstacles: scheme.obstacles_id(),
        sources,
        method: scheme.method_spec(),
        order: scheme.order,
        factoring: !scheme.no_factoring,
        connectivity: scheme.connectivity_spec(),
        stop: StopSpec {
            targets,
            max_distance: args.max_distance,
            max_frozen: None,
        },
        outputs: OutputSpec {
            labels: args.labels.is_some(),
            frozen_order: false,
        },
        signed: args.signed,
    };
    let mut output = run_operation(Box::new(request), inputs, &flags)?;
    let stats = std::mem::take(&mut output.document["stats"]);
    for out in output.arrays {
        match (out.name.as_str(), &args.labels) {
            ("distance", _) => output::write_array("--out", &args.out, &out.array)?,
            ("labels", Some(path)) => output::write_array("--labels", path, &out.array)?,
            _ => {}
        }
    }
    println!(
        "geodex: wrote {} ({} of {} cells reached, stop: {}, solve {:.3} s)",
        args.out.display(),
        stats["frozen"],
        stats["cells"],
        stats["stop"].as_str().unwrap_or_default(),
        stats["solve_seconds"].as_f64().unwrap_or_default()
    );
    Ok(())
}

/// The metric flags shared by `geodex distance` and `geodex path`:
/// `--cost` (or `--shape`) or `--tensor`, `--obstacles`, `--speed`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct MetricFlags<'a> {
    pub cost: Option<&'a Path>,
    pub shape: Option<&'a [usize]>,
    pub tensor: Option<&'a Path>,
    pub obstacles: Option<&'a Path>,
    pub speed: bool,
}

impl MetricFlags<'_> {
    /// The flag that gives the metric (errors on `cost.*` / `metric.*` name it).
    pub(crate) fn flag(&self) -> &'static str {
        if self.tensor.is_some() {
            "--tensor"
        } else if self.cost.is_some() {
            "--cost"
        } else {
            "--shape"
        }
    }

    /// Reads the files (`cost`, `tensor`, `obstacles` datasets; a cost or
    /// tensor file keeps its stored spacing) and builds the `cost` or
    /// `metric` section of the request (`design` goes with `--cost`).
    pub(crate) fn load(
        &self,
        design: Option<crate::ops::grid_metric::DesignSpec>,
    ) -> Result<(CliInputs, Option<CostSpec>, Option<TensorSpec>), DistanceError> {
        let mut inputs = CliInputs::new();
        let mut put = |name: &str, id: &str, path: &Path, keep_spacing: bool| {
            let decoded = read_array(name, path)?;
            inputs.insert(
                id.into(),
                InputArray {
                    array: Arc::new(decoded.array),
                    spacing: decoded.spacing.filter(|_| keep_spacing),
                },
            );
            Ok::<(), DistanceError>(())
        };
        if let Some(path) = self.cost {
            put("--cost", "cost", path, true)?;
        }
        if let Some(path) = self.tensor {
            put("--tensor", "tensor", path, true)?;
        }
        if let Some(path) = self.obstacles {
            put("--obstacles", "obstacles", path, false)?;
        }
        if self.tensor.is_some() {
            let metric = TensorSpec::Components(ComponentsTensor {
                dataset: "tensor".into(),
            });
            return Ok((inputs, None, Some(metric)));
        }
        let cost = CostSpec {
            dataset: self.cost.map(|_| "cost".to_string()),
            constant: self.shape.map(|_| 1.0),
            shape: self.shape.map(<[usize]>::to_vec),
            interpretation: if self.speed {
                InterpretationSpec::Speed
            } else {
                InterpretationSpec::Cost
            },
            design,
        };
        Ok((inputs, Some(cost), None))
    }
}

/// Parses repeated `I,J[,K]` values; errors name the occurrence (1-based).
pub(crate) fn parse_points(name: &str, values: &[String]) -> Result<Vec<Vec<f64>>, DistanceError> {
    values
        .iter()
        .enumerate()
        .map(|(i, v)| {
            let bad = || {
                flag(
                    format!("{name} {}", i + 1),
                    format!(
                        "'{v}' is not a point: expected 2 or 3 comma-separated finite numbers \
                         (index coordinates, axis 0 first)"
                    ),
                )
            };
            let p = v
                .split(',')
                .map(|x| x.trim().parse::<f64>().ok().filter(|x| x.is_finite()))
                .collect::<Option<Vec<f64>>>()
                .ok_or_else(bad)?;
            if !(2..=3).contains(&p.len()) {
                return Err(bad());
            }
            Ok(p)
        })
        .collect()
}

pub(crate) fn read_array(name: &str, path: &Path) -> Result<io::Decoded, DistanceError> {
    let bytes = std::fs::read(path)
        .map_err(|e| flag(name, format!("cannot read '{}': {e}", path.display())))?;
    let limits = Limits {
        max_cells: MAX_CELLS,
        max_bytes: usize::MAX,
    };
    io::decode(&bytes, None, &limits).map_err(|e| flag(name, format!("'{}': {e}", path.display())))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn points_parse_or_name_their_occurrence() {
        let ok = parse_points("--source", &["1,2.5".into(), " 3, 4 ,5".into()]).unwrap();
        assert_eq!(ok, vec![vec![1.0, 2.5], vec![3.0, 4.0, 5.0]]);
        for bad in ["1", "1,2,3,4", "1,x", "1,nan", ""] {
            let e = parse_points("--source", &["0,0".into(), bad.into()]).unwrap_err();
            assert!(e.to_string().starts_with("--source 2: "), "{e}");
        }
    }
}
