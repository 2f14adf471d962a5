//! `monovo rpe`: the relative pose error as evo's `evo_rpe` (or, with `--tum`, the TUM RGB-D
//! `evaluate_rpe.py`) computes it.

use anyhow::Result;
use clap::Parser;
use eval_metrics::ExtraMetric;
use monovo_pipelines::{run_metric, MetricArgs, RpeUnit, Spelling};

use super::traj::{AlignArgs, Inputs, OutputArgs, RelationArg, SyncArgs};

/// The unit of the delta.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum UnitArg {
    /// Poses (frames).
    F,
    /// Degrees turned.
    #[value(alias = "deg")]
    D,
    /// Radians turned.
    #[value(alias = "rad")]
    R,
    /// Metres travelled.
    M,
    /// Seconds (--tum only).
    S,
}

/// Arguments of `monovo rpe`.
#[derive(clap::Args, Debug)]
// repeated options: the last one wins, as in evo (argparse)
#[command(
    args_override_self = true,
    after_help = "\
Examples (evo's flags, kebab-case or evo's underscores):
  monovo rpe gt.txt est.txt                           # evo_rpe tum gt est: 1 frame apart
  monovo rpe gt.txt est.txt -as --delta 10 --delta_unit m --all_pairs --json
  monovo rpe gt.txt est.txt -r angle_deg -d 1 -u m --pairs_from_reference
  monovo rpe --tum groundtruth.txt estimate.txt      # evaluate_rpe.py --fixed_delta, 1 s
  monovo rpe --tum gt.txt est.txt --all-pairs        # evaluate_rpe.py without --fixed_delta

evo: after association and alignment as in `monovo ape`, pairs (i, j) are taken --delta
apart in frames (f), metres travelled (m), degrees (d) or radians (r) turned along the
estimate (the reference with --pairs-from-reference), consecutive pairs or with --all-pairs
every pair within --delta-tol (relative). Each pair gives E = (Q_i^-1 Q_j)^-1 (P_i^-1 P_j): the
estimated motion compared with the reference's in the start frame of the pair.

--tum follows evaluate_rpe.py: pairs --delta apart in seconds (or m, rad, deg, f) along the
estimate, a pair ending at the last pose dropped, each pose given the nearest ground-truth
stamp (skipped beyond twice the median ground-truth interval), the error dP dQ^-1 (motions
compared in the end frame) with translational and rotational (degrees) statistics. With
--all-pairs, every pair, 10,000 random ones (Python 2's generator, seed 0) beyond 100 poses.
See docs/evaluation-metrics.md."
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
    /// The distance between the poses of a pair (evo: 1; --tum: 1).
    #[arg(short = 'd', long, default_value_t = 1.0, value_name = "DELTA")]
    pub delta: f64,
    /// The unit of the delta: f (frames), m (metres), d (degrees), r (radians); s (seconds,
    /// --tum's default).
    #[arg(short = 'u', long = "delta-unit", alias = "delta_unit", value_enum)]
    pub delta_unit: Option<UnitArg>,
    /// Relative tolerance of the delta with --all-pairs (metres and angles).
    #[arg(
        short = 't',
        long = "delta-tol",
        alias = "delta_tol",
        default_value_t = 0.1,
        value_name = "TOL"
    )]
    pub delta_tol: f64,
    /// Every pair at the delta instead of consecutive pairs (--tum: every pair).
    #[arg(long = "all-pairs", alias = "all_pairs")]
    pub all_pairs: bool,
    /// Choose the pairs on the reference's path instead of the estimate's.
    #[arg(long = "pairs-from-reference", alias = "pairs_from_reference")]
    pub pairs_from_reference: bool,
    #[command(flatten)]
    pub align: AlignArgs,
    #[command(flatten)]
    pub sync: SyncArgs,
    /// The TUM RGB-D benchmark's evaluate_rpe.py definitions instead of evo's.
    #[arg(long)]
    pub tum: bool,
    /// With --tum: pairs a fixed delta apart (the default; --all-pairs for every pair).
    #[arg(
        long = "fixed-delta",
        alias = "fixed_delta",
        requires = "tum",
        conflicts_with = "all_pairs"
    )]
    pub fixed_delta: bool,
    /// With --tum: at most this many pairs, drawn at random beyond (0: all) [default: 10000].
    #[arg(
        long = "max-pairs",
        alias = "max_pairs",
        value_name = "N",
        requires = "tum"
    )]
    pub max_pairs: Option<usize>,
    /// With --tum: a fixed factor for the estimate's motions (the script's --scale).
    #[arg(long, value_name = "FACTOR", requires = "tum")]
    pub scale: Option<f64>,
    #[command(flatten)]
    pub out: OutputArgs,
}

/// The metric the arguments ask for: evo's RPE, or evaluate_rpe.py's with --tum.
pub fn metric(args: &Args) -> Result<ExtraMetric> {
    let mut a = MetricArgs {
        pose_relation: args.pose_relation.relation(),
        tum: args.tum,
        scale: args.scale,
        delta: args.delta,
        delta_unit: args.delta_unit.map(|u| match u {
            UnitArg::F => RpeUnit::Frames,
            UnitArg::M => RpeUnit::Meters,
            UnitArg::D => RpeUnit::Degrees,
            UnitArg::R => RpeUnit::Radians,
            UnitArg::S => RpeUnit::Seconds,
        }),
        delta_tol: args.delta_tol,
        all_pairs: args.all_pairs,
        pairs_from_reference: args.pairs_from_reference,
        max_pairs: args.max_pairs,
        ..MetricArgs::default()
    };
    args.align.apply(&mut a);
    args.sync.apply(&mut a);
    a.rpe(Spelling::Flags).map_err(anyhow::Error::msg)
}

/// `monovo rpe`'s options alone, for `eval-batch --rpe FLAGS`.
#[derive(clap::Parser, Debug)]
#[command(name = "--rpe", no_binary_name = true)]
struct Flags {
    #[command(flatten)]
    args: Args,
}

/// The metric of `monovo rpe`'s flags given as one string (`"-as -d 10 -u m"`).
pub fn metric_from_flags(flags: &str) -> Result<ExtraMetric> {
    let words = ["REF", "EST"].into_iter().chain(flags.split_whitespace());
    let f = Flags::try_parse_from(words).map_err(|e| anyhow::anyhow!("--rpe \"{flags}\": {e}"))?;
    metric(&f.args)
}

/// Runs `monovo rpe`.
pub fn run(args: &Args) -> Result<()> {
    let (format, reference, estimate) = args.inputs.resolve()?;
    args.out.check()?;
    let report = run_metric(reference, estimate, format, &metric(args)?)?;
    args.out.finish(&report)
}
