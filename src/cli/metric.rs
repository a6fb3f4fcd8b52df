//! `geodex metric`: the cost `W` designed from an image or a volume (the
//! operation `grid.metric`, [`GridMetricRequest`], as `POST /v1/grid/metric`),
//! written after the extension of `--out`: look at the metric before
//! running a solve on it.
//!
//! ```text
//! geodex metric --image road.png --design edges --out W.png
//! geodex metric --image vessels.nii.gz --design 'vesselness:scales=1;2,polarity=dark' --out W.npy
//! geodex metric --image speed.npy --speed --out W.tiff
//! ```

use std::collections::HashMap;
use std::path::PathBuf;

use clap::Args;

use super::design::DesignFlag;
use super::run::FlagMap;
use super::segment::{
    array, check_outputs, execute, flag, read, write, write_json, SegmentCliError,
};
use super::SpacingFlag;
use crate::ops::grid_metric::GridMetricRequest;
use crate::ops::spec::cost::{CostSpec, InterpretationSpec};

/// Flags of `geodex metric`.
#[derive(Debug, Clone, Args)]
pub struct MetricArgs {
    /// The image or volume (NPY, PNG, TIFF, NIfTI...): designed into W with
    /// --design, else its values are W (or a speed with --speed).
    #[arg(long, value_name = "IMAGE")]
    pub image: PathBuf,
    /// How to design W from the image.
    #[command(flatten)]
    pub design: DesignFlag,
    /// Without --design: read the values as a speed F = 1/W.
    #[arg(long, conflicts_with = "design")]
    pub speed: bool,
    /// Physical size of a cell along each axis (scales of the design are physical).
    #[command(flatten)]
    pub spacing: SpacingFlag,
    /// Where to write W (f64): `.npy`, `.tiff`, `.png` (colour-mapped) or `.png16`.
    #[arg(long, value_name = "W.npy")]
    pub out: PathBuf,
    /// Where to write the statistics (JSON: min, max, mean, design seconds).
    #[arg(long, value_name = "S.json")]
    pub stats: Option<PathBuf>,
}

/// The flags behind the fields of [`GridMetricRequest`].
fn metric_flags() -> FlagMap {
    FlagMap::new().metric("--image")
}

/// Runs `geodex metric`.
pub fn run(args: &MetricArgs) -> Result<(), SegmentCliError> {
    check_outputs(&[("--out", Some(&args.out))])?;
    let design = args.design.spec(true, "--image")?;
    let mut inputs = HashMap::new();
    let request = GridMetricRequest {
        cost: Some(CostSpec {
            dataset: Some(read("--image", &args.image, &mut inputs)?),
            constant: None,
            shape: None,
            interpretation: if args.speed {
                InterpretationSpec::Speed
            } else {
                InterpretationSpec::Cost
            },
            design,
        }),
        metric: None,
        spacing: args.spacing.spacing.clone(),
    };
    let (out, secs) = execute(&request, &inputs, None, &metric_flags())?;
    let Some(w) = array(&out, "metric") else {
        return Err(flag("geodex", "the operation returned no metric"));
    };
    write("--out", &args.out, w)?;
    if let Some(p) = &args.stats {
        write_json("--stats", p, &out.document)?;
    }
    let stats = &out.document["stats"];
    println!(
        "geodex: wrote {} (W in [{}, {}], mean {}, {:.3} s)",
        args.out.display(),
        stats["min"],
        stats["max"],
        stats["mean"],
        secs
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fields_name_the_image_and_the_design() {
        let m = metric_flags();
        assert_eq!(m.flag_of("cost.dataset"), "--image");
        assert_eq!(m.flag_of("cost.design.scales[0]"), "--design");
        assert_eq!(m.flag_of("cost.interpretation"), "--speed");
        assert_eq!(m.flag_of("spacing[0]"), "--spacing value 1");
    }
}
