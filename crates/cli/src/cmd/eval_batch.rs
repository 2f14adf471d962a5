//! `monovo eval-batch`: every run of a results tree, in parallel, into results.csv (or an
//! experiment manifest, with `--manifest`).

use std::path::PathBuf;

use anyhow::Result;
use monovo_pipelines::{evaluate_tree, BatchOptions};

use crate::progress::Bars;

/// Arguments of `monovo eval-batch`.
#[derive(clap::Args, Debug)]
#[command(after_help = "\
Layout:
  DATASET/sequence_XX/groundtruthSync.txt
  RESULTS/METHOD/sequence_XX/fwd_N.txt    (forwards runs, N = 0, 1, ...)
  RESULTS/METHOD/sequence_XX/bwd_N.txt    (backwards runs)

Every run is evaluated as `monovo eval` does, in parallel. Files that do not fit the layout
are listed and skipped, never mixed in. results.csv has the columns
method,sequence,direction,run,status,e_align,e_s,e_r,e_t,e_rmse,rmse_start,rmse_end,poses,reason
(failed runs have status `failed`, `inf` metrics and the reason); feed it to `monovo plot`.

--ape, --rpe and --kitti compute the field's other metrics for every run as well, with the
flags of `monovo ape`, `monovo rpe` (evo's, or --tum for the TUM RGB-D scripts) and
`monovo kitti`: more columns in results.csv (ape_rmse, ape_mean, ape_median, ape_std, ape_min,
ape_max, the same for rpe_, kitti_t_err in %, kitti_r_err in deg/100m; infinite where a metric
cannot be computed), their per-method medians in the summary, and `monovo plot cumulative
--metric ape_rmse` / `monovo plot box` draw them. The reference is groundtruthSync.txt's rows
with a pose; backwards runs' 2e9 - t stamps are mapped back and every estimate is sorted by time.

With --manifest FILE, the experiment the manifest describes is run instead (methods and
variations, grouped cumulative plots and tables into the folder -o); see `monovo experiment
--help` for the format.

Example:
  monovo eval-batch --dataset tum-mono --results results -o results.csv
  monovo plot cumulative results.csv -o e_align.png
  monovo eval-batch --dataset tum-mono --results results -o results.csv --ape \"-as\" \\
      --rpe \"-as --delta 10 --delta_unit m\" --kitti=-as
  monovo plot box results.csv --metric ape_rmse -o ape.png
  monovo eval-batch --manifest data/experiment.toml --base synth -o experiment")]
pub struct Args {
    /// Folder with one SEQUENCE/groundtruthSync.txt per sequence.
    #[arg(long, value_name = "DATASET", required_unless_present = "manifest")]
    pub dataset: Option<PathBuf>,
    /// Folder with METHOD/SEQUENCE/{fwd,bwd}_N.txt trajectories (TUM or EuRoC format).
    #[arg(long, value_name = "RESULTS", required_unless_present = "manifest")]
    pub results: Option<PathBuf>,
    /// An experiment manifest (TOML) to run instead of one results tree.
    #[arg(long, value_name = "FILE", conflicts_with_all = ["dataset", "results", "keep_going"])]
    pub manifest: Option<PathBuf>,
    /// With --manifest: the folder the manifest's paths are relative to (default: its own).
    #[arg(long, value_name = "DIR", requires = "manifest")]
    pub base: Option<PathBuf>,
    /// The results.csv to write (must not exist unless --force); with --manifest, the
    /// output folder.
    #[arg(short, long, value_name = "CSV")]
    pub output: PathBuf,
    /// Replace an existing results.csv.
    #[arg(long)]
    pub force: bool,
    /// Record unreadable or malformed run files as failed runs instead of stopping.
    #[arg(long)]
    pub keep_going: bool,
    /// Print a JSON summary (runs, failed, per method, stray files) instead of text.
    #[arg(long)]
    pub json: bool,
    /// Also the APE of every run, with `monovo ape`'s flags (e.g. "-as").
    #[arg(
        long,
        value_name = "FLAGS",
        allow_hyphen_values = true,
        conflicts_with = "manifest"
    )]
    pub ape: Option<String>,
    /// Also the RPE of every run, with `monovo rpe`'s flags (e.g. "-as -d 10 -u m").
    #[arg(
        long,
        value_name = "FLAGS",
        allow_hyphen_values = true,
        conflicts_with = "manifest"
    )]
    pub rpe: Option<String>,
    /// Also the KITTI segment errors of every run (over its associated poses): --kitti, or
    /// --kitti=FLAGS with alignment flags (e.g. --kitti=-as; none by default, as the devkit).
    #[arg(long, value_name = "FLAGS", num_args = 0..=1, require_equals = true, default_missing_value = "", allow_hyphen_values = true, conflicts_with = "manifest")]
    pub kitti: Option<String>,
}

/// Runs `monovo eval-batch`.
pub fn run(args: &Args) -> Result<()> {
    if let Some(m) = &args.manifest {
        return crate::cmd::experiment::run_manifest(
            m,
            args.base.as_deref(),
            &args.output,
            args.force,
            args.json,
        );
    }
    let (Some(dataset), Some(results)) = (&args.dataset, &args.results) else {
        anyhow::bail!("--dataset and --results are needed without --manifest");
    };
    let mut extra = Vec::new();
    if let Some(f) = &args.ape {
        extra.push(crate::cmd::ape::metric_from_flags(f)?);
    }
    if let Some(f) = &args.rpe {
        extra.push(crate::cmd::rpe::metric_from_flags(f)?);
    }
    if let Some(f) = &args.kitti {
        extra.push(crate::cmd::kitti::metric_from_flags(f)?);
    }
    let batch = evaluate_tree(
        &BatchOptions {
            dataset: dataset.clone(),
            results: results.clone(),
            output: Some(args.output.clone()),
            force: args.force,
            keep_going: args.keep_going,
            extra,
        },
        &Bars::default(),
    )?;
    let summary = batch.summary();
    if args.json {
        outln!("{}", serde_json::to_string(&summary)?)?;
    } else {
        out!("{}", summary.text())?;
    }
    Ok(())
}
