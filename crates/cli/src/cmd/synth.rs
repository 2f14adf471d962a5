//! `monovo synth`: synthetic data with known ground truth, from a fixed seed.

use std::path::PathBuf;

use anyhow::Result;
use dataset_io::OutputDir;
use rayon::prelude::*;
use synthetic::results::{run_text, sequence_name, sequence_path, ResultsConfig};

use crate::progress;

/// Arguments of `monovo synth`.
#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(subcommand)]
    pub what: What,
}

/// What to generate.
#[derive(clap::Subcommand, Debug)]
pub enum What {
    /// A synthetic benchmark evaluation: DIR/dataset/sequence_XX/groundtruthSync.txt and
    /// DIR/results/METHOD/sequence_XX/{fwd,bwd}_N.txt of two methods with known drift.
    #[command(after_help = "\
Example:
  monovo synth results -o synth
  monovo eval-batch --dataset synth/dataset --results synth/results -o results.csv
  monovo plot cumulative results.csv -o e_align.png

Method `direct` drifts little and rarely fails; method `feature` drifts more, has scale jumps,
loses tracking more often, writes keyframes only and uses the 2e9 - t timestamps backwards.")]
    Results(ResultsArgs),
}

/// Arguments of `monovo synth results`.
#[derive(clap::Args, Debug)]
pub struct ResultsArgs {
    /// Output folder (must not exist unless --force).
    #[arg(short, long, value_name = "DIR")]
    pub output: PathBuf,
    /// Random seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Number of sequences.
    #[arg(long, default_value_t = 50)]
    pub sequences: usize,
    /// Runs per sequence and direction.
    #[arg(long, default_value_t = 5)]
    pub runs: usize,
    /// Frames per sequence.
    #[arg(long, default_value_t = 2000)]
    pub frames: usize,
    /// Replace an existing output folder.
    #[arg(long)]
    pub force: bool,
}

/// Writes a synthetic results set into `out` (a staging folder); returns the number of runs.
pub fn write_results(out: &OutputDir, a: &ResultsArgs) -> Result<usize> {
    let cfg = ResultsConfig {
        sequences: a.sequences.max(1),
        runs: a.runs.max(1),
        frames: a.frames.max(50),
        ..ResultsConfig::default()
    };
    let paths: Vec<_> = (1..=cfg.sequences)
        .into_par_iter()
        .map(|i| sequence_path(a.seed, i, cfg.frames))
        .collect();
    for (i, p) in paths.iter().enumerate() {
        let f = out.file(&format!(
            "dataset/{}/groundtruthSync.txt",
            sequence_name(i + 1)
        ))?;
        dataset_io::write_atomic(&f, p.ground_truth_sync().as_bytes())?;
    }
    let mut jobs = Vec::new();
    for (mi, _) in cfg.methods.iter().enumerate() {
        for s in 0..cfg.sequences {
            for bwd in [false, true] {
                for r in 0..cfg.runs {
                    jobs.push((mi, s, bwd, r));
                }
            }
        }
    }
    let pb = progress::bar(jobs.len() as u64, "generating");
    jobs.par_iter()
        .try_for_each(|&(mi, s, bwd, r)| -> Result<()> {
            let m = &cfg.methods[mi];
            let text = run_text(a.seed, &paths[s], m, mi, s + 1, bwd, r);
            let rel = format!(
                "results/{}/{}/{}_{r}.txt",
                m.name,
                sequence_name(s + 1),
                if bwd { "bwd" } else { "fwd" }
            );
            dataset_io::write_atomic(&out.file(&rel)?, text.as_bytes())?;
            pb.inc(1);
            Ok(())
        })?;
    pb.finish_and_clear();
    Ok(jobs.len())
}

/// Runs `monovo synth`.
pub fn run(args: &Args) -> Result<()> {
    match &args.what {
        What::Results(a) => {
            let out = OutputDir::create(&a.output, a.force)?;
            let n = write_results(&out, a)?;
            let dir = out.commit()?;
            println!(
                "wrote {n} runs of 2 methods on {} sequences to {}",
                a.sequences.max(1),
                dir.display()
            );
        }
    }
    Ok(())
}
