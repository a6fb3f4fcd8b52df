//! `geodex cost-gradient`: the gradient of geodesic distances with respect to
//! the cost, on NPY files (or any format geodex reads), through the request
//! of `POST /v1/grid/cost-gradient` ([`GridCostGradientRequest`]).
//!
//! ```text
//! geodex cost-gradient --cost W.npy --source 64,10 --target 64,118 --out G.npy
//! geodex cost-gradient --cost W.npy --source 0,0 --targets Y.npy --observed T.npy --misfit --out G.npy
//! geodex cost-gradient --tensor M.npy --source 0,0 --target 30,40 --out G.npy   # G: (N, M, 3)
//! ```
//!
//! It prints the objective, the time of the forward solve and of the
//! adjoint sweep (the figure `tests/bench/compare_agd_gradient.py` reads).

use std::collections::HashMap;
use std::path::PathBuf;

use clap::Args;

use super::design::DesignFlag;
use super::run::{run_on, FlagMap};
use super::segment::{
    array, check_outputs, cost_of, flag, read, write, write_json, SegmentCliError,
};
use super::SpacingFlag;
use crate::ops::grid_cost_gradient::{GridCostGradientRequest, ObjectiveSpec, TargetSpec};
use crate::ops::spec::cost::InterpretationSpec;
use crate::ops::spec::scheme::SourceSpec;
use crate::ops::spec::tensor::{ComponentsTensor, TensorSpec};
use crate::ops::InputArray;

/// Flags of `geodex cost-gradient`.
#[derive(Debug, Clone, Args)]
pub struct CostGradientArgs {
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
    /// array of shape (N, M, 3) with m00, m01, m11 per cell, or (N, M, P, 6)
    /// in 3D. The gradient then has one more axis: one value per component.
    #[arg(long, value_name = "T.npy", conflicts_with_all = ["cost", "speed", "design"])]
    pub tensor: Option<PathBuf>,
    /// Design the cost from the --cost image; the gradient is then with
    /// respect to the designed cost.
    #[command(flatten)]
    pub design: DesignFlag,
    /// Read --cost as a speed F = 1/W; the gradient is then with respect to F.
    #[arg(long)]
    pub speed: bool,
    /// Physical size of a cell along each axis.
    #[command(flatten)]
    pub spacing: SpacingFlag,
    /// Obstacle mask (non-zero cells are walls).
    #[arg(long, value_name = "O.npy")]
    pub obstacles: Option<PathBuf>,
    /// A source point `I,J[,K]` (index coordinates); repeat.
    #[arg(long = "source", value_name = "I,J[,K]", required = true)]
    pub sources: Vec<String>,
    /// A target point `I,J[,K]` with an optional weight `I,J[,K]:W`; repeat.
    #[arg(long = "target", value_name = "I,J[,K][:W]")]
    pub target: Vec<String>,
    /// Target points as an (m, d) array, one point per row (after any --target).
    #[arg(long, value_name = "Y.npy")]
    pub targets: Option<PathBuf>,
    /// The weight of each target of --targets (length m; default 1).
    #[arg(long, value_name = "W.npy", requires = "targets")]
    pub weights: Option<PathBuf>,
    /// The observed distance (travel time) of every target, in order: the
    /// --target ones first, then the --targets rows.
    #[arg(long, value_name = "T.npy")]
    pub observed: Option<PathBuf>,
    /// Differentiate the misfit ½ Σ w (U − T)² (needs --observed) instead of Σ w U.
    #[arg(long, requires = "observed")]
    pub misfit: bool,
    /// Order of the scheme, 1 or 2.
    #[arg(long, default_value_t = 2, value_name = "1|2")]
    pub order: u8,
    /// Threads of the solver pool (default: all cores; the solve itself is sequential).
    #[arg(long, value_name = "N")]
    pub threads: Option<usize>,
    /// Where to write the gradient (f64, the grid's shape; .npy, .tiff, .png or .png16).
    #[arg(long, value_name = "G.npy")]
    pub out: PathBuf,
    /// Where to write the distance map of the forward solve.
    #[arg(long, value_name = "U.npy")]
    pub distance: Option<PathBuf>,
    /// Where to write the answer's document (objective, per-target distances, timings) as JSON.
    #[arg(long, value_name = "R.json")]
    pub json: Option<PathBuf>,
}

fn point_of(s: &str, name: &str) -> Result<Vec<f64>, SegmentCliError> {
    s.split(',')
        .map(|v| v.trim().parse::<f64>())
        .collect::<Result<Vec<_>, _>>()
        .map_err(|_| flag(name, format!("'{s}' is not I,J[,K]")))
}

/// The values of a 1D or 2D array read by `read` as f64 rows of `width`.
fn rows_of(
    inputs: &HashMap<String, InputArray>,
    id: &str,
    name: &str,
    width: Option<usize>,
) -> Result<Vec<Vec<f64>>, SegmentCliError> {
    let a = &inputs.get(id).ok_or_else(|| flag(name, "not read"))?.array;
    let shape = a.shape().to_vec();
    let values: Vec<f64> = (0..a.len())
        .map(|i| a.get_f64(i).unwrap_or(f64::NAN))
        .collect();
    let w = match (width, shape.as_slice()) {
        (None, [_]) => 1,
        (Some(w), [_, c]) if *c == w => w,
        (Some(_), [_, c]) if (2..=3).contains(c) => *c,
        _ => {
            return Err(flag(
                name,
                format!(
                    "an array of shape {shape:?}: give {}",
                    if width.is_some() {
                        "one point per row, (m, 2) or (m, 3)"
                    } else {
                        "one value per target, shape (m,)"
                    }
                ),
            ))
        }
    };
    Ok(values.chunks(w).map(<[f64]>::to_vec).collect())
}

/// The flags behind the fields of [`GridCostGradientRequest`]; the first
/// `given` targets came from `--target`, the others from `--targets` rows.
fn gradient_flags(given: usize, cost_flag: &str) -> FlagMap {
    FlagMap::new()
        .each("sources", "--source")
        .field("targets[].observed", "--observed")
        .each_in("targets", "--target", 0..given)
        .field("targets[].weight", "--weights")
        .rows_from("targets", "--targets", given)
        .field("targets", "--target")
        .field("objective", "--misfit")
        .metric(cost_flag)
}

/// `geodex cost-gradient`.
pub fn run(args: &CostGradientArgs) -> Result<(), SegmentCliError> {
    check_outputs(&[
        ("--out", Some(&args.out)),
        ("--distance", args.distance.as_deref()),
    ])?;
    let mut inputs = HashMap::new();
    let (cost, metric) = match &args.tensor {
        Some(p) => (
            None,
            Some(TensorSpec::Components(ComponentsTensor {
                dataset: read("--tensor", p, &mut inputs)?,
            })),
        ),
        None => {
            let mut cost = cost_of(&args.cost, &args.shape, &args.design, &mut inputs)?;
            if args.speed {
                cost.interpretation = InterpretationSpec::Speed;
            }
            (Some(cost), None)
        }
    };
    let obstacles = match &args.obstacles {
        Some(p) => Some(read("--obstacles", p, &mut inputs)?),
        None => None,
    };
    let sources = args
        .sources
        .iter()
        .enumerate()
        .map(|(i, s)| point_of(s, &format!("--source {}", i + 1)).map(SourceSpec::at_point))
        .collect::<Result<Vec<_>, _>>()?;
    let mut targets = Vec::new();
    for (m, s) in args.target.iter().enumerate() {
        let name = format!("--target {}", m + 1);
        let (p, w) = match s.split_once(':') {
            Some((p, w)) => (
                p,
                w.trim()
                    .parse::<f64>()
                    .map_err(|_| flag(&name, format!("'{w}' is not a weight")))?,
            ),
            None => (s.as_str(), 1.0),
        };
        targets.push(TargetSpec {
            point: point_of(p, &name)?,
            weight: w,
            observed: None,
        });
    }
    let given = targets.len();
    if let Some(path) = &args.targets {
        let id = read("--targets", path, &mut inputs)?;
        let rows = rows_of(&inputs, &id, "--targets", Some(2))?;
        let weights = match &args.weights {
            Some(p) => {
                let wid = read("--weights", p, &mut inputs)?;
                let w = rows_of(&inputs, &wid, "--weights", None)?;
                if w.len() != rows.len() {
                    return Err(flag(
                        "--weights",
                        format!("{} weights for {} targets", w.len(), rows.len()),
                    ));
                }
                w.into_iter().map(|r| r[0]).collect()
            }
            None => vec![1.0; rows.len()],
        };
        targets.extend(
            rows.into_iter()
                .zip(weights)
                .map(|(point, weight)| TargetSpec {
                    point,
                    weight,
                    observed: None,
                }),
        );
    }
    if targets.is_empty() {
        return Err(flag("--target", "give --target or --targets"));
    }
    if let Some(p) = &args.observed {
        let id = read("--observed", p, &mut inputs)?;
        let t = rows_of(&inputs, &id, "--observed", None)?;
        if t.len() != targets.len() {
            return Err(flag(
                "--observed",
                format!("{} observed values for {} targets", t.len(), targets.len()),
            ));
        }
        for (target, t) in targets.iter_mut().zip(t) {
            target.observed = Some(t[0]);
        }
    }
    let request = GridCostGradientRequest {
        cost,
        metric,
        spacing: args.spacing.spacing.clone(),
        obstacles,
        sources,
        targets,
        objective: if args.misfit {
            ObjectiveSpec::Misfit
        } else {
            ObjectiveSpec::Sum
        },
        order: args.order,
        distance: args.distance.is_some(),
    };
    let cost_flag = if args.cost.is_some() {
        "--cost"
    } else {
        "--shape"
    };
    let flags = gradient_flags(given, cost_flag);
    let ran = run_on(
        Box::new(request),
        inputs,
        args.threads.map(|n| n.max(1)),
        &flags,
    )?;
    let out = ran.output;
    if let Some(g) = array(&out, "gradient") {
        write("--out", &args.out, g)?;
    }
    if let (Some(p), Some(u)) = (&args.distance, array(&out, "distance")) {
        write("--distance", p, u)?;
    }
    if let Some(p) = &args.json {
        write_json("--json", p, &out.document)?;
    }
    let stats = &out.document["stats"];
    let solve = stats["solve_seconds"].as_f64().unwrap_or(0.0);
    let adjoint = stats["gradient_seconds"].as_f64().unwrap_or(0.0);
    eprintln!(
        "geodex: J = {} ({}), forward solve {solve:.4} s, adjoint {adjoint:.4} s ({:.2}x the solve)",
        out.document["objective"]["value"],
        out.document["objective"]["kind"].as_str().unwrap_or("sum"),
        if solve > 0.0 { adjoint / solve } else { 0.0 },
    );
    println!("geodex: wrote {}", args.out.display());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn targets_name_the_flag_or_the_row_that_gave_them() {
        let m = gradient_flags(2, "--cost");
        assert_eq!(m.flag_of("sources[0].point"), "--source 1");
        assert_eq!(m.flag_of("targets[1].point[0]"), "--target 2");
        assert_eq!(m.flag_of("targets[1].weight"), "--target 2");
        assert_eq!(m.flag_of("targets[3].weight"), "--weights");
        assert_eq!(m.flag_of("targets[3].point"), "--targets (row 1)");
        assert_eq!(m.flag_of("targets[0].observed"), "--observed");
        assert_eq!(m.flag_of("metric"), "--tensor");
    }
}
