//! A results tree, evaluated in parallel into results.csv.

use std::collections::{BTreeMap, HashMap};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use dataset_io::{scan_ground_truths, scan_results, RunFile};
use eval_metrics::{
    evaluate_batch_with, failed_extra, write_csv, Direction, ExtraMetric, GroundTruth, Metric,
    RunKey, RunRecord, Stat,
};
use rayon::prelude::*;
use serde::Serialize;

use crate::eval::{load_ground_truth, load_trajectory};
use crate::{error_chain, Observer, PipelineError, Result};

/// What to evaluate and where to write it.
#[derive(Clone, Debug)]
pub struct BatchOptions {
    /// Folder with one SEQUENCE/groundtruthSync.txt per sequence.
    pub dataset: PathBuf,
    /// Folder with METHOD/SEQUENCE/{fwd,bwd}_N.txt trajectories.
    pub results: PathBuf,
    /// The results.csv to write (`None`: nothing is written).
    pub output: Option<PathBuf>,
    /// Replace an existing results.csv.
    pub force: bool,
    /// Record unreadable or malformed run files as failed runs instead of stopping.
    pub keep_going: bool,
    /// The field's other metrics to compute for every run (APE, RPE, KITTI), as more
    /// columns of results.csv.
    pub extra: Vec<ExtraMetric>,
}

/// An evaluated results tree.
#[derive(Debug)]
pub struct Batch {
    /// The evaluated runs, as written to results.csv.
    pub records: Vec<RunRecord>,
    /// Runs that could not be read (counted as failed with `keep_going`).
    pub unreadable: usize,
    /// Files skipped, with the reason.
    pub stray: Vec<(PathBuf, String)>,
    /// Number of sequences with a ground truth.
    pub sequences: usize,
    /// The results.csv written.
    pub output: Option<PathBuf>,
    /// Wall time in seconds.
    pub seconds: f64,
}

/// Evaluates every run of a results tree in parallel (as `monovo eval` evaluates one) and
/// writes results.csv. Skipped files are warnings to `observer`, which also sees one
/// progress step per run. The output location is checked before any work.
pub fn evaluate_tree(opts: &BatchOptions, observer: &dyn Observer) -> Result<Batch> {
    let started = std::time::Instant::now();
    if let Some(o) = &opts.output {
        dataset_io::check_output_file(o, opts.force)?;
    }
    let gts = scan_ground_truths(&opts.dataset)?;
    let tree = scan_results(&opts.results)?;
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
        observer.warn(&format!("skipping {}: {why}", p.display()));
    }
    if runs.is_empty() {
        return Err(PipelineError::Invalid(format!(
            "{}: no run files METHOD/SEQUENCE/{{fwd,bwd}}_N.txt for the sequences of {}",
            opts.results.display(),
            opts.dataset.display()
        )));
    }
    observer.begin(runs.len() as u64, "evaluating", "runs");
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
    let results = evaluate_batch_with(
        &runs,
        key,
        |r| load_trajectory(&r.path, None, None),
        |k| ground_truth.get(&k.sequence),
        &opts.extra,
        || observer.advance(1),
    );
    observer.finish();
    let mut records = Vec::with_capacity(results.len());
    let mut unreadable = 0;
    for (r, file) in results.into_iter().zip(&runs) {
        match r {
            Ok(rec) => records.push(rec),
            Err(e) if opts.keep_going => {
                unreadable += 1;
                let why = error_chain(&e);
                observer.warn(&format!("counting as failed: {why}"));
                records.push(RunRecord {
                    key: key(file),
                    failure: Some(why),
                    metrics: eval_metrics::Metrics::FAILED,
                    poses: 0,
                    extra: failed_extra(&opts.extra),
                });
            }
            Err(e) => {
                return Err(PipelineError::Context {
                    context: "use --keep-going to count unreadable runs as failed".into(),
                    source: Box::new(e),
                })
            }
        }
    }
    if let Some(o) = &opts.output {
        dataset_io::write_atomic(o, write_csv(&records).as_bytes())?;
    }
    Ok(Batch {
        records,
        unreadable,
        stray,
        sequences: ground_truth.len(),
        output: opts.output.clone(),
        seconds: started.elapsed().as_secs_f64(),
    })
}

/// Runs, failures and statistics of one method.
#[derive(Debug, Serialize)]
pub struct MethodCount {
    /// Runs.
    pub runs: usize,
    /// Failed runs.
    pub failed: usize,
    /// Median, minimum and maximum over the runs of e_align, e_r, e'_s and of every other
    /// metric computed (failed runs count as infinite; JSON `null`).
    pub statistics: BTreeMap<&'static str, Stat>,
}

/// A file of the results tree that was skipped, and why.
#[derive(Debug, Serialize)]
pub struct StrayFile {
    /// The file.
    pub path: String,
    /// Why it was skipped.
    pub reason: String,
}

/// What `monovo eval-batch --json` prints.
#[derive(Debug, Serialize)]
pub struct BatchSummary {
    /// Runs evaluated.
    pub runs: usize,
    /// Failed runs.
    pub failed: usize,
    /// Runs that could not be read.
    pub unreadable: usize,
    /// Per method.
    pub methods: BTreeMap<String, MethodCount>,
    /// Sequences with a ground truth.
    pub sequences: usize,
    /// Skipped files.
    pub stray: Vec<StrayFile>,
    /// The results.csv written.
    pub output: String,
    /// Wall time in seconds.
    pub seconds: f64,
}

impl Batch {
    /// The summary of the batch.
    pub fn summary(&self) -> BatchSummary {
        let mut methods: BTreeMap<String, MethodCount> = BTreeMap::new();
        for r in &self.records {
            let e = methods.entry(r.key.method.clone()).or_insert(MethodCount {
                runs: 0,
                failed: 0,
                statistics: BTreeMap::new(),
            });
            e.runs += 1;
            e.failed += usize::from(!r.is_ok());
        }
        for (m, c) in methods.iter_mut() {
            let rs: Vec<&RunRecord> = self.records.iter().filter(|r| &r.key.method == m).collect();
            for metric in computed_metrics(&self.records) {
                let v: Vec<f64> = rs.iter().map(|r| metric.of(r)).collect();
                if let Some(st) = Stat::of(&v) {
                    c.statistics.insert(metric.name(), st);
                }
            }
        }
        BatchSummary {
            runs: self.records.len(),
            failed: self.records.iter().filter(|r| !r.is_ok()).count(),
            unreadable: self.unreadable,
            methods,
            sequences: self.sequences,
            stray: self
                .stray
                .iter()
                .map(|(p, why)| StrayFile {
                    path: p.display().to_string(),
                    reason: why.clone(),
                })
                .collect(),
            output: self
                .output
                .as_deref()
                .map_or(String::new(), |p| p.display().to_string()),
            seconds: self.seconds,
        }
    }
}

impl BatchSummary {
    /// The text `monovo eval-batch` prints.
    pub fn text(&self) -> String {
        let mut s = format!(
            "evaluated {} runs of {} method(s) on {} sequence(s) in {:.2} s: {} failed{}\n",
            self.runs,
            self.methods.len(),
            self.sequences,
            self.seconds,
            self.failed,
            if self.stray.is_empty() {
                String::new()
            } else {
                format!(", {} stray file(s) skipped", self.stray.len())
            }
        );
        for (m, c) in &self.methods {
            let _ = write!(s, "  {m:<20} {:>6} runs  {:>5} failed", c.runs, c.failed);
            // the headline figures; --json has every statistic
            for name in [
                "e_align",
                "e_r",
                "e_s",
                "ape_rmse",
                "rpe_rmse",
                "kitti_t_err",
                "kitti_r_err",
            ] {
                if let Some(st) = c.statistics.get(name) {
                    let name = if name == "e_s" { "e'_s" } else { name };
                    let _ = write!(s, "  {name} {}", fmt_stat(st.median));
                }
            }
            s.push('\n');
        }
        if self.methods.values().any(|c| !c.statistics.is_empty()) {
            s.push_str("  (medians over the runs; failed runs count as infinite)\n");
        }
        if !self.output.is_empty() {
            let _ = writeln!(s, "wrote {}", self.output);
        }
        s
    }
}

/// The metrics the records have: e_align, e_r, e'_s, and the other metrics' columns present.
pub fn computed_metrics(records: &[RunRecord]) -> Vec<Metric> {
    Metric::ALL
        .into_iter()
        .filter(|m| match m {
            Metric::EAlign | Metric::ER | Metric::ES => true,
            m if m.is_extra() => records.iter().any(|r| r.extra.contains_key(m.name())),
            _ => false,
        })
        .collect()
}

fn fmt_stat(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.4}")
    } else {
        "inf".into()
    }
}

/// Reads a results.csv.
pub fn load_results(path: &Path) -> Result<Vec<RunRecord>> {
    let text = dataset_io::read_text(path).map_err(|source| PipelineError::Read {
        what: "the results",
        source,
    })?;
    eval_metrics::parse_csv(&text).map_err(|source| PipelineError::Eval {
        what: "",
        path: path.to_path_buf(),
        source,
    })
}
