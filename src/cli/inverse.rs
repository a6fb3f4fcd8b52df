//! `geodex tomography` and `geodex fit-metric`: the inverse problems of
//! `grid.tomography` and `grid.fit_metric` from files.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use clap::Args;

use super::run::FlagMap;
use super::segment::{check_outputs, execute, flag, read, write, write_json, SegmentCliError};
use super::SpacingFlag;
use crate::ops::grid_fit_metric::GridFitMetricRequest;
use crate::ops::grid_tomography::{GridTomographyRequest, SurveyPoint};
use crate::ops::spec::design::{DesignSpec, IntensitySpec};

/// Flags of `geodex tomography`.
#[derive(Debug, Clone, Args)]
pub struct TomographyArgs {
    /// The data (JSON): `{"sources": [{"point": [i, j]}, ...], "receivers": [{"point": [i, j]}, ...],
    /// "times": [[t, ...], ...]}`, index coordinates, one row of times per source.
    #[arg(long, value_name = "DATA.json")]
    pub data: PathBuf,
    /// Grid shape `N0,N1[,N2]`.
    #[arg(long, value_name = "N0,N1[,N2]", value_delimiter = ',')]
    pub shape: Vec<usize>,
    /// Physical size of a cell along each axis.
    #[command(flatten)]
    pub spacing: SpacingFlag,
    /// Weight of the smoothness term.
    #[arg(long, default_value_t = 0.0)]
    pub alpha: f64,
    /// Lower bound of the cost (default: a tenth of the best constant).
    #[arg(long)]
    pub min_cost: Option<f64>,
    /// Upper bound of the cost (default: ten times the best constant).
    #[arg(long)]
    pub max_cost: Option<f64>,
    /// Largest number of descent steps.
    #[arg(long, default_value_t = 50)]
    pub max_iterations: usize,
    /// Order of the fast marching (1 or 2).
    #[arg(long, default_value_t = 1)]
    pub order: u8,
    /// Where to write the recovered cost (.npy, .tiff, .png or .png16).
    #[arg(long, value_name = "COST.npy")]
    pub out: PathBuf,
    /// Where to write the report (JSON: misfit history, best constant); stdout when omitted.
    #[arg(long, value_name = "R.json")]
    pub report: Option<PathBuf>,
}

/// Flags of `geodex fit-metric`.
#[derive(Debug, Clone, Args)]
pub struct FitMetricArgs {
    /// The image.
    #[arg(long, value_name = "IMAGE")]
    pub image: PathBuf,
    /// The example paths (JSON): `[[[i, j], ...], ...]`, each from its start to its end.
    #[arg(long, value_name = "EXAMPLES.json")]
    pub examples: PathBuf,
    /// Physical size of a cell along each axis.
    #[command(flatten)]
    pub spacing: SpacingFlag,
    /// The initial reference grey value (image units; default: the brightest).
    #[arg(long)]
    pub value: Option<f64>,
    /// The initial exponent, in [1, 4].
    #[arg(long, default_value_t = 2.0)]
    pub power: f64,
    /// The fixed floor epsilon of the cost.
    #[arg(long, default_value_t = 0.01)]
    pub epsilon: f64,
    /// Gaussian pre-smoothing of the image (physical units).
    #[arg(long, default_value_t = 0.0)]
    pub sigma: f64,
    /// Also fit the exponent.
    #[arg(long)]
    pub fit_power: bool,
    /// Largest number of descent steps.
    #[arg(long, default_value_t = 30)]
    pub max_iterations: usize,
    /// Where to write the fitted cost (.npy, .tiff, .png or .png16).
    #[arg(long, value_name = "COST.npy")]
    pub out: Option<PathBuf>,
    /// Where to write the report (JSON: fitted design, loss, distances); stdout when omitted.
    #[arg(long, value_name = "R.json")]
    pub report: Option<PathBuf>,
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct Data {
    sources: Vec<SurveyPoint>,
    receivers: Vec<SurveyPoint>,
    times: Vec<Vec<f64>>,
}

fn read_json<T: serde::de::DeserializeOwned>(
    name: &str,
    path: &Path,
) -> Result<T, SegmentCliError> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| flag(name, format!("cannot read '{}': {e}", path.display())))?;
    serde_json::from_str(&text).map_err(|e| flag(name, format!("'{}': {e}", path.display())))
}

fn report(args_report: &Option<PathBuf>, doc: &serde_json::Value) -> Result<(), SegmentCliError> {
    match args_report {
        Some(p) => write_json("--report", p, doc),
        None => {
            println!("{doc}");
            Ok(())
        }
    }
}

/// `geodex tomography`.
pub fn run_tomography(args: &TomographyArgs) -> Result<(), SegmentCliError> {
    check_outputs(&[("--out", Some(&args.out))])?;
    let data: Data = read_json("--data", &args.data)?;
    let request = GridTomographyRequest {
        shape: args.shape.clone(),
        spacing: args.spacing.spacing.clone(),
        sources: data.sources,
        receivers: data.receivers,
        times: data.times,
        alpha: args.alpha,
        min_cost: args.min_cost,
        max_cost: args.max_cost,
        max_iterations: args.max_iterations,
        tolerance: 1e-6,
        order: args.order,
    };
    let flags = FlagMap::new()
        .values("spacing", "--spacing")
        .values("shape", "--shape")
        .field("sources", "--data")
        .field("receivers", "--data")
        .field("times", "--data");
    let (out, seconds) = execute(&request, &HashMap::new(), None, &flags)?;
    if let Some(cost) = out.array("cost") {
        write("--out", &args.out, cost)?;
    }
    eprintln!(
        "geodex: misfit {} (best constant {}) -> {} after {} steps ({}), {seconds:.2} s; wrote {}",
        out.document["misfit"]["constant"],
        out.document["constant_cost"],
        out.document["misfit"]["final"],
        out.document["iterations"],
        out.document["stop"],
        args.out.display()
    );
    report(&args.report, &out.document)
}

/// `geodex fit-metric`.
pub fn run_fit_metric(args: &FitMetricArgs) -> Result<(), SegmentCliError> {
    check_outputs(&[("--out", args.out.as_deref())])?;
    let mut inputs = HashMap::new();
    let image = read("--image", &args.image, &mut inputs)?;
    let examples: Vec<Vec<Vec<f64>>> = read_json("--examples", &args.examples)?;
    let request = GridFitMetricRequest {
        image,
        spacing: args.spacing.spacing.clone(),
        examples,
        design: DesignSpec::Intensity(IntensitySpec {
            value: args.value,
            at: None,
            power: args.power,
            epsilon: args.epsilon,
            sigma: args.sigma,
        }),
        fit_power: args.fit_power,
        max_iterations: args.max_iterations,
        tolerance: 1e-6,
        order: 1,
    };
    let flags = FlagMap::new()
        .values("spacing", "--spacing")
        .field("design.value", "--value")
        .field("design.power", "--power")
        .field("design.epsilon", "--epsilon")
        .field("design.sigma", "--sigma")
        .field("design", "--value");
    let (out, seconds) = execute(&request, &inputs, None, &flags)?;
    if let (Some(p), Some(cost)) = (&args.out, out.array("cost")) {
        write("--out", p, cost)?;
    }
    eprintln!(
        "geodex: fitted {} (loss {} -> {}, {} steps, {seconds:.2} s)",
        out.document["design"],
        out.document["loss"]["initial"],
        out.document["loss"]["final"],
        out.document["iterations"],
    );
    report(&args.report, &out.document)
}
