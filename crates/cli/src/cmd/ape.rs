//! `monovo ape`: the absolute pose error as evo's `evo_ape` (or, with `--tum`, the TUM RGB-D
//! `evaluate_ate.py`) computes it.

use anyhow::Result;
use clap::Parser;
use eval_metrics::ExtraMetric;
use monovo_pipelines::{run_metric, MetricArgs, Spelling};

use super::traj::{AlignArgs, Inputs, OutputArgs, RelationArg, SyncArgs};

/// Arguments of `monovo ape`.
#[derive(clap::Args, Debug)]
// repeated options: the last one wins, as in evo (argparse)
#[command(
    args_override_self = true,
    after_help = "\
Examples (evo's flags, kebab-case or evo's underscores):
  monovo ape groundtruth.txt estimate.txt -as            # evo_ape tum gt est -as
  monovo ape tum gt.txt est.txt -a -r angle_deg --json
  monovo ape gt.txt est.txt -as --n_to_align 100 --plot ape.png --save_results ape.zip
  monovo ape gt.txt vio.txt --posyaw                      # 4-DoF for visual-inertial runs
  monovo ape --tum groundtruth.txt estimate.txt          # evaluate_ate.py

The estimate's poses are associated with the reference by time (evo: each pose of the
trajectory with fewer poses takes the nearest stamp of the other within --t-max-diff;
--sync-method interpolation interpolates the denser one instead). KITTI pose files have no
stamps and pair by line. Then the estimate is aligned (none by default, as evo) and each pair
gives the error pose E = P^-1 Q (estimate P, reference Q), measured by --pose-relation:
trans_part (the distance between the positions, m), rot_part (|R_E - I|), full (|E - I|),
angle_deg, angle_rad. The statistics are evo's: rmse, mean, median, std (population), min,
max, sse, and the count n.

--tum follows evaluate_ate.py instead: greedy one-to-one association within 0.02 s (strictly
below; --t-max-diff, --t-offset), the estimate scaled by --scale, Horn's SE(3) alignment
always, the distances between the positions. See docs/evaluation-metrics.md."
)]
pub struct Args {
    #[command(flatten)]
    pub inputs: Inputs,
    /// What is measured of each error pose.
    #[arg(
        short = 'r',
        long = "pose-relation",
        alias = "pose_relation",
        value_enum,
        default_value = "trans_part"
    )]
    pub pose_relation: RelationArg,
    #[command(flatten)]
    pub align: AlignArgs,
    #[command(flatten)]
    pub sync: SyncArgs,
    /// The TUM RGB-D benchmark's evaluate_ate.py definitions instead of evo's.
    #[arg(long)]
    pub tum: bool,
    /// With --tum: a fixed factor for the estimate's positions (the script's --scale).
    #[arg(long, value_name = "FACTOR", requires = "tum")]
    pub scale: Option<f64>,
    #[command(flatten)]
    pub out: OutputArgs,
}

/// The metric the arguments ask for: evo's APE, or evaluate_ate.py's with --tum.
pub fn metric(args: &Args) -> Result<ExtraMetric> {
    let mut a = MetricArgs {
        pose_relation: args.pose_relation.relation(),
        tum: args.tum,
        scale: args.scale,
        ..MetricArgs::default()
    };
    args.align.apply(&mut a);
    args.sync.apply(&mut a);
    a.ape(Spelling::Flags).map_err(anyhow::Error::msg)
}

/// `monovo ape`'s options alone, for `eval-batch --ape FLAGS`.
#[derive(clap::Parser, Debug)]
#[command(name = "--ape", no_binary_name = true)]
struct Flags {
    #[command(flatten)]
    args: Args,
}

/// The metric of `monovo ape`'s flags given as one string (`"-as -r angle_deg"`).
pub fn metric_from_flags(flags: &str) -> Result<ExtraMetric> {
    let words = ["REF", "EST"].into_iter().chain(flags.split_whitespace());
    let f = Flags::try_parse_from(words).map_err(|e| anyhow::anyhow!("--ape \"{flags}\": {e}"))?;
    metric(&f.args)
}

/// Runs `monovo ape`.
pub fn run(args: &Args) -> Result<()> {
    let (format, reference, estimate) = args.inputs.resolve()?;
    args.out.check()?;
    let report = run_metric(reference, estimate, format, &metric(args)?)?;
    args.out.finish(&report)
}
