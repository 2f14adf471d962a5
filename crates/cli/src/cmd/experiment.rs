//! `monovo experiment`: methods and variations from a TOML manifest, evaluated and drawn as
//! the paper's grouped cumulative error plots with one command.

use std::path::{Path, PathBuf};

use anyhow::Result;
use monovo_pipelines::{run_experiment, Experiment};

use crate::progress::Bars;

/// Arguments of `monovo experiment`.
#[derive(clap::Args, Debug)]
#[command(after_help = "\
A manifest names the methods and the variations to compare (field of view, resolution,
direction, real-time or not, ...). Each variation is a results folder, a filter, or both:

  title = \"synthetic benchmark\"          # figure titles (optional)
  dataset = \"dataset\"                    # SEQUENCE/groundtruthSync.txt
  results = \"results\"                    # METHOD/SEQUENCE/{fwd,bwd}_N.txt
  metrics = [\"e_align\", \"e_r\", \"e_s\"]    # default; also e_t, e_rmse, rmse_start, rmse_end,
                                         # ape_rmse, ape_mean, ..., rpe_rmse, ..., kitti_t_err,
                                         # kitti_r_err (with the tables below)
  layout = \"panels\"                      # one panel per variation; \"overlay\": one chart,
                                         # line style per variation
  keep_going = false                     # count unreadable run files as failed runs

  [[method]]                             # one per method: its folder in the results trees
  name = \"direct\"
  label = \"direct (DSO-like)\"            # legend text (optional)

  [[variation]]                          # one per group of runs
  name = \"forward\"                       # names files: letters, digits, _ - .
  label = \"forward playback\"             # panel title (optional)
  direction = \"fwd\"                      # fwd, bwd or both (default)
  # results = \"results_fov90\"            # another results folder (default: the top one)
  # dataset = \"dataset_fov90\"            # and its ground truth, if it differs
  # sequences = [\"sequence_01\"]          # only these sequences

  [ape]                                  # APE next to e_align, evo's option names:
  align = \"sim3\"                         # none, se3, sim3, scale, posyaw, origin
  # pose_relation, n_to_align, t_max_diff, t_offset, sync_method; tum = true: evaluate_ate.py
  [rpe]                                  # RPE: also delta, delta_unit (f, m, d, r), delta_tol,
  align = \"sim3\"                         # all_pairs, pairs_from_reference; tum = true:
  delta = 1                              # evaluate_rpe.py (delta_unit s, max_pairs, scale)
  delta_unit = \"m\"
  [kitti]                                # KITTI segment errors over the associated poses
  align = \"sim3\"

Paths are relative to the manifest's folder, or to --base DIR. Every results folder is
evaluated once, in parallel. The output folder -o gets cumulative_METRIC.png per metric
(runs with error below x against x, log x axis, one colour per method), box_METRIC.png (a
box per method and variation, failed runs left out), summary.md and
summary.csv (runs, failures and medians per variation and method; failed runs count as
infinite) and results_VARIATION.csv (the variation's runs, as `eval-batch` writes them). A
bad manifest is an error naming the file, the line and what was expected.

Example (the synthetic data of `monovo synth results`):
  monovo synth results -o synth
  monovo experiment data/experiment.toml --base synth -o experiment")]
pub struct Args {
    /// The experiment manifest (TOML).
    pub manifest: PathBuf,
    /// The folder the manifest's paths are relative to (default: the manifest's folder).
    #[arg(long, value_name = "DIR")]
    pub base: Option<PathBuf>,
    /// The output folder (must not exist unless --force).
    #[arg(short, long, value_name = "DIR")]
    pub output: PathBuf,
    /// Replace an existing output folder.
    #[arg(long)]
    pub force: bool,
    /// Print one JSON object (groups with their medians, figures, tables) instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Runs `monovo experiment`.
pub fn run(args: &Args) -> Result<()> {
    run_manifest(
        &args.manifest,
        args.base.as_deref(),
        &args.output,
        args.force,
        args.json,
    )
}

/// Runs the experiment of a manifest into `output` and prints the report.
pub fn run_manifest(
    manifest: &Path,
    base: Option<&Path>,
    output: &Path,
    force: bool,
    json: bool,
) -> Result<()> {
    let exp = Experiment::load(manifest, base)?;
    let report = run_experiment(&exp, output, force, &Bars::default())?;
    if json {
        outln!("{}", serde_json::to_string(&report)?)?;
    } else {
        out!("{}", report.text())?;
    }
    Ok(())
}
