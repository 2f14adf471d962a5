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

With --manifest FILE, the experiment the manifest describes is run instead (methods and
variations, grouped cumulative plots and tables into the folder -o); see `monovo experiment
--help` for the format.

Example:
  monovo eval-batch --dataset tum-mono --results results -o results.csv
  monovo plot cumulative results.csv -o e_align.png
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
    let batch = evaluate_tree(
        &BatchOptions {
            dataset: dataset.clone(),
            results: results.clone(),
            output: Some(args.output.clone()),
            force: args.force,
            keep_going: args.keep_going,
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
