//! `monovo kitti`: the KITTI odometry devkit's segment errors (translation in percent,
//! rotation in degrees per 100 m over 100..800 m segments).

use std::path::PathBuf;

use anyhow::Result;
use clap::Parser;
use eval_metrics::ExtraMetric;
use monovo_pipelines::{kitti_figure, kitti_pairs, run_kitti};

use super::traj::AlignArgs;
use crate::plot;

/// Arguments of `monovo kitti`.
#[derive(clap::Args, Debug)]
// repeated options: the last one wins, as in evo (argparse)
#[command(
    args_override_self = true,
    after_help = "\
Examples:
  monovo kitti poses/00.txt results/00.txt
  monovo kitti poses/ results/ --json             # every NN.txt of results/, pooled
  monovo kitti poses/00.txt mono/00.txt -as --plot kitti.png

As the devkit's evaluate_odometry.cpp: poses pair by line (the counts must agree); every 10th
frame starts segments of 100, 200, ..., 800 m, each ending at the first frame whose
ground-truth distance exceeds the length; the error pose of a segment gives the translation
error |t| / L and the rotation error angle / L; the means over all segments (of all
sequences) are reported in percent and in degrees per 100 m, with the per-length means of the
lengths that have at least 3 segments. The arithmetic is the devkit's single precision.
The devkit does not align; -a / -s / -as (evo's Umeyama over all poses) may be given for
monocular runs."
)]
pub struct Args {
    /// The ground truth: a KITTI pose file, or a folder of NN.txt.
    pub gt: PathBuf,
    /// The estimate: a pose file, or a folder of NN.txt (each with a ground truth of the same
    /// name).
    pub estimate: PathBuf,
    #[command(flatten)]
    pub align: AlignArgs,
    /// Print exactly one JSON object: t_err_percent, r_err_deg_per_100m, the per-length
    /// errors.
    #[arg(long)]
    pub json: bool,
    /// Draw the errors per segment length and the paths (.png or .svg).
    #[arg(long, alias = "save_plot", value_name = "FILE")]
    pub plot: Option<PathBuf>,
    /// Replace an existing --plot file.
    #[arg(long)]
    pub force: bool,
}

/// `monovo kitti`'s alignment flags alone, for `eval-batch --kitti FLAGS`.
#[derive(clap::Parser, Debug)]
#[command(name = "--kitti", no_binary_name = true)]
struct Flags {
    #[command(flatten)]
    align: AlignArgs,
}

/// The KITTI metric of alignment flags given as one string (`""`, `"-as"`).
pub fn metric_from_flags(flags: &str) -> Result<ExtraMetric> {
    let f = Flags::try_parse_from(flags.split_whitespace())
        .map_err(|e| anyhow::anyhow!("--kitti \"{flags}\": {e}"))?;
    Ok(ExtraMetric::Kitti(f.align.options()?))
}

/// Runs `monovo kitti`.
pub fn run(args: &Args) -> Result<()> {
    if let Some(p) = &args.plot {
        plot::format_of(p)?;
        dataset_io::check_output_file(p, args.force)?;
    }
    let pairs = kitti_pairs(&args.gt, &args.estimate)?;
    let report = run_kitti(&pairs, None, &args.align.options()?)?;
    if let Some(p) = &args.plot {
        plot::save(&kitti_figure(&report), p)?;
    }
    if args.json {
        outln!("{}", serde_json::to_string(&report)?)?;
    } else {
        out!("{}", report.text())?;
        if let Some(p) = &args.plot {
            outln!("plot: {}", p.display())?;
        }
    }
    Ok(())
}
