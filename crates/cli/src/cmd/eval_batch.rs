//! `monovo eval-batch`: every run of a results tree, in parallel, into results.csv.

use std::collections::HashMap;
use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use dataset_io::{scan_ground_truths, scan_results, RunFile};
use eval_metrics::{evaluate_batch, write_csv, Direction, GroundTruth, RunKey};
use rayon::prelude::*;
use serde::Serialize;

use crate::cmd::eval::{load_ground_truth, load_trajectory, FormatArg};
use crate::progress;

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

Example:
  monovo eval-batch --dataset tum-mono --results results -o results.csv
  monovo plot cumulative results.csv -o e_align.png")]
pub struct Args {
    /// Folder with one SEQUENCE/groundtruthSync.txt per sequence.
    #[arg(long, value_name = "DATASET")]
    pub dataset: PathBuf,
    /// Folder with METHOD/SEQUENCE/{fwd,bwd}_N.txt trajectories (TUM or EuRoC format).
    #[arg(long, value_name = "RESULTS")]
    pub results: PathBuf,
    /// The results.csv to write (must not exist unless --force).
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

/// Runs and failures of one method in the `--json` summary.
#[derive(Debug, Serialize)]
struct MethodJson {
    runs: usize,
    failed: usize,
}

/// A file of the results tree that was skipped, and why.
#[derive(Debug, Serialize)]
struct StrayJson {
    path: String,
    reason: String,
}

/// The `--json` output of `monovo eval-batch`.
#[derive(Debug, Serialize)]
struct BatchJson {
    runs: usize,
    failed: usize,
    unreadable: usize,
    methods: std::collections::BTreeMap<String, MethodJson>,
    sequences: usize,
    stray: Vec<StrayJson>,
    output: String,
    /// Wall time in seconds.
    seconds: f64,
}

/// What `monovo eval-batch` wrote.
pub struct Batch {
    /// The evaluated runs, as written to results.csv.
    pub records: Vec<eval_metrics::RunRecord>,
    /// Runs that could not be read (counted as failed with --keep-going).
    pub unreadable: usize,
    /// Files skipped, with the reason.
    pub stray: Vec<(PathBuf, String)>,
    /// Number of sequences with a ground truth.
    pub sequences: usize,
    /// The results.csv written.
    pub output: PathBuf,
    /// Wall time in seconds.
    pub seconds: f64,
}

/// Evaluates a results tree into results.csv; warnings (skipped files) go to stderr,
/// nothing to stdout.
pub fn evaluate_tree(args: &Args) -> Result<Batch> {
    let started = std::time::Instant::now();
    // the output location first: no work for an output that cannot be written
    dataset_io::check_output_file(&args.output, args.force)?;
    let gts = scan_ground_truths(&args.dataset)?;
    let tree = scan_results(&args.results)?;
    let loaded: Vec<Result<(String, GroundTruth)>> = gts
        .par_iter()
        .map(|(seq, path)| Ok((seq.clone(), load_ground_truth(path)?)))
        .collect();
    let mut ground_truth = HashMap::new();
    for r in loaded {
        let (seq, gt) = r?;
        ground_truth.insert(seq, gt);
    }
    let mut stray: Vec<(PathBuf, String)> = tree
        .stray
        .iter()
        .map(|(p, why)| (p.clone(), why.to_string()))
        .collect();
    let runs: Vec<&RunFile> = tree
        .runs
        .iter()
        .filter(|r| {
            let known = ground_truth.contains_key(&r.sequence);
            if !known {
                stray.push((
                    r.path.clone(),
                    format!("no {}/groundtruthSync.txt in the dataset", r.sequence),
                ));
            }
            known
        })
        .collect();
    for (p, why) in &stray {
        crate::warn(format_args!("skipping {}: {why}", p.display()));
    }
    if runs.is_empty() {
        bail!(
            "{}: no run files METHOD/SEQUENCE/{{fwd,bwd}}_N.txt for the sequences of {}",
            args.results.display(),
            args.dataset.display()
        );
    }
    let pb = progress::bar(runs.len() as u64, "evaluating", "runs");
    let key = |r: &&RunFile| RunKey {
        method: r.method.clone(),
        sequence: r.sequence.clone(),
        direction: if r.backwards {
            Direction::Backward
        } else {
            Direction::Forward
        },
        run: r.run,
    };
    let results = evaluate_batch(
        &runs,
        key,
        |r| load_trajectory(&r.path, FormatArg::Auto, None),
        |k| ground_truth.get(&k.sequence),
        || pb.inc(1),
    );
    pb.finish_and_clear();
    let mut records = Vec::with_capacity(results.len());
    let mut unreadable = 0;
    for (r, file) in results.into_iter().zip(&runs) {
        match r {
            Ok(rec) => records.push(rec),
            Err(e) if args.keep_going => {
                unreadable += 1;
                crate::warn(format_args!("counting as failed: {e:#}"));
                records.push(eval_metrics::RunRecord {
                    key: key(file),
                    failure: Some(format!("{e:#}")),
                    metrics: eval_metrics::Metrics::FAILED,
                    poses: 0,
                });
            }
            Err(e) => return Err(e).context("use --keep-going to count unreadable runs as failed"),
        }
    }
    dataset_io::write_atomic(&args.output, write_csv(&records).as_bytes())?;
    Ok(Batch {
        records,
        unreadable,
        stray,
        sequences: ground_truth.len(),
        output: args.output.clone(),
        seconds: started.elapsed().as_secs_f64(),
    })
}

/// Runs `monovo eval-batch`.
pub fn run(args: &Args) -> Result<()> {
    let Batch {
        records,
        unreadable,
        stray,
        sequences,
        output,
        seconds,
    } = evaluate_tree(args)?;
    let mut per_method: std::collections::BTreeMap<&str, (usize, usize)> = Default::default();
    for r in &records {
        let e = per_method.entry(r.key.method.as_str()).or_default();
        e.0 += 1;
        if !r.is_ok() {
            e.1 += 1;
        }
    }
    let failed = records.iter().filter(|r| !r.is_ok()).count();
    if args.json {
        let summary = BatchJson {
            runs: records.len(),
            failed,
            unreadable,
            methods: per_method
                .iter()
                .map(|(m, &(runs, failed))| (m.to_string(), MethodJson { runs, failed }))
                .collect(),
            sequences,
            stray: stray
                .iter()
                .map(|(p, why)| StrayJson {
                    path: p.display().to_string(),
                    reason: why.clone(),
                })
                .collect(),
            output: output.display().to_string(),
            seconds,
        };
        outln!("{}", serde_json::to_string(&summary)?)?;
    } else {
        outln!(
            "evaluated {} runs of {} method(s) on {} sequence(s) in {seconds:.2} s: {} failed{}",
            records.len(),
            per_method.len(),
            sequences,
            failed,
            if stray.is_empty() {
                String::new()
            } else {
                format!(", {} stray file(s) skipped", stray.len())
            }
        )?;
        for (m, (n, f)) in &per_method {
            outln!("  {m:<20} {n:>6} runs  {f:>5} failed")?;
        }
        outln!("wrote {}", output.display())?;
    }
    Ok(())
}
