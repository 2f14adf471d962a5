//! Many runs at once: parallel evaluation, the results CSV, per-sequence median (min-max)
//! tables and the paper's cumulative error curves.

use std::collections::BTreeMap;
use std::fmt;
use std::str::FromStr;

use rayon::prelude::*;

use crate::evaluate::{evaluate, FailReason, Metrics};
use crate::trajectory::{GroundTruth, Trajectory};
use crate::EvalError;

/// Playback direction of a run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Direction {
    /// Played forwards (`fwd`).
    Forward,
    /// Played backwards (`bwd`).
    Backward,
}

impl Direction {
    /// `fwd` or `bwd`.
    pub fn as_str(self) -> &'static str {
        match self {
            Direction::Forward => "fwd",
            Direction::Backward => "bwd",
        }
    }
}

impl fmt::Display for Direction {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for Direction {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "fwd" | "forward" | "forwards" => Ok(Direction::Forward),
            "bwd" | "backward" | "backwards" => Ok(Direction::Backward),
            _ => Err(format!("expected `fwd` or `bwd`, found `{s}`")),
        }
    }
}

/// Identifies one run of a batch.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct RunKey {
    /// Method name (the results tree's first level).
    pub method: String,
    /// Sequence name, e.g. `sequence_01`.
    pub sequence: String,
    /// Playback direction.
    pub direction: Direction,
    /// Run number.
    pub run: u32,
}

/// One evaluated run, as stored in results.csv.
#[derive(Clone, Debug, PartialEq)]
pub struct RunRecord {
    /// Which run.
    pub key: RunKey,
    /// `None` when the run succeeded.
    pub failure: Option<String>,
    /// The metrics (infinite when failed).
    pub metrics: Metrics,
    /// Number of estimated poses.
    pub poses: usize,
}

impl RunRecord {
    /// Whether the run succeeded.
    pub fn is_ok(&self) -> bool {
        self.failure.is_none()
    }
}

/// A metric to summarise or plot.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Metric {
    /// `e_align`.
    EAlign,
    /// `e_r` in degrees.
    ER,
    /// `e'_s = max(e_s, 1/e_s)` (the paper's summary of the scale drift).
    ES,
    /// `e_t`.
    ET,
    /// `e_rmse`.
    ERmse,
    /// Start-segment RMSE.
    RmseStart,
    /// End-segment RMSE.
    RmseEnd,
}

impl Metric {
    /// Every metric.
    pub const ALL: [Metric; 7] = [
        Metric::EAlign,
        Metric::ER,
        Metric::ES,
        Metric::ET,
        Metric::ERmse,
        Metric::RmseStart,
        Metric::RmseEnd,
    ];

    /// The metric's value in a run (infinite when failed).
    pub fn value(self, m: &Metrics) -> f64 {
        match self {
            Metric::EAlign => m.e_align,
            Metric::ER => m.e_r,
            Metric::ES => m.e_s_sym(),
            Metric::ET => m.e_t,
            Metric::ERmse => m.e_rmse,
            Metric::RmseStart => m.rmse_start,
            Metric::RmseEnd => m.rmse_end,
        }
    }

    /// Short name as used on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Metric::EAlign => "e_align",
            Metric::ER => "e_r",
            Metric::ES => "e_s",
            Metric::ET => "e_t",
            Metric::ERmse => "e_rmse",
            Metric::RmseStart => "rmse_start",
            Metric::RmseEnd => "rmse_end",
        }
    }

    /// Axis label for plots.
    pub fn label(self) -> &'static str {
        match self {
            Metric::EAlign => "alignment error e_align",
            Metric::ER => "rotation drift e_r (degrees)",
            Metric::ES => "scale drift e'_s = max(e_s, 1/e_s) (multiplier)",
            Metric::ET => "translation drift e_t",
            Metric::ERmse => "joint alignment RMSE e_rmse",
            Metric::RmseStart => "start-segment RMSE",
            Metric::RmseEnd => "end-segment RMSE",
        }
    }
}

impl FromStr for Metric {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Metric::ALL
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| {
                format!(
                    "unknown metric `{s}`, expected one of {}",
                    Metric::ALL.map(|m| m.name()).join(", ")
                )
            })
    }
}

/// Evaluates many runs in parallel. `load` reads and parses one run's estimate (called from
/// worker threads); `ground_truth` gives the ground truth of a sequence; `on_done` is called
/// after each run (for a progress bar). Results come back in the order of `jobs`; a run
/// whose loader fails yields that error.
pub fn evaluate_batch<'g, J, E, L, G, P>(
    jobs: &[J],
    key: impl Fn(&J) -> RunKey + Sync,
    load: L,
    ground_truth: G,
    on_done: P,
) -> Vec<Result<RunRecord, E>>
where
    J: Sync,
    E: Send,
    L: Fn(&J) -> Result<Trajectory, E> + Sync,
    G: Fn(&RunKey) -> Option<&'g GroundTruth> + Sync,
    P: Fn() + Sync,
{
    jobs.par_iter()
        .map(|job| {
            let key = key(job);
            let out = load(job).map(|traj| match ground_truth(&key) {
                Some(gt) => {
                    let ev = evaluate(&traj, gt);
                    RunRecord {
                        failure: ev.failure.as_ref().map(|f| f.to_string()),
                        metrics: ev.metrics,
                        poses: ev.poses,
                        key,
                    }
                }
                None => RunRecord {
                    failure: Some(
                        FailReason::Other(format!("no ground truth for {}", key.sequence))
                            .to_string(),
                    ),
                    metrics: Metrics::FAILED,
                    poses: traj.poses.len(),
                    key,
                },
            });
            on_done();
            out
        })
        .collect()
}

/// The header of results.csv.
pub const CSV_HEADER: &str =
    "method,sequence,direction,run,status,e_align,e_s,e_r,e_t,e_rmse,rmse_start,rmse_end,poses";

fn csv_num(v: f64) -> String {
    if v.is_finite() {
        format!("{v}")
    } else {
        "inf".into()
    }
}

fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

/// Writes records as results.csv (infinite metrics as `inf`, full precision).
pub fn write_csv(records: &[RunRecord]) -> String {
    let mut out = String::with_capacity(records.len() * 160 + 128);
    out.push_str(CSV_HEADER);
    out.push('\n');
    for r in records {
        let m = &r.metrics;
        out.push_str(&format!(
            "{},{},{},{},{},{},{},{},{},{},{},{},{}\n",
            csv_field(&r.key.method),
            csv_field(&r.key.sequence),
            r.key.direction,
            r.key.run,
            if r.is_ok() { "ok" } else { "failed" },
            csv_num(m.e_align),
            csv_num(m.e_s),
            csv_num(m.e_r),
            csv_num(m.e_t),
            csv_num(m.e_rmse),
            csv_num(m.rmse_start),
            csv_num(m.rmse_end),
            r.poses
        ));
    }
    out
}

fn split_csv_line(line: &str) -> Vec<String> {
    let mut fields = Vec::new();
    let mut cur = String::new();
    let mut quoted = false;
    let mut chars = line.chars().peekable();
    while let Some(c) = chars.next() {
        match (c, quoted) {
            ('"', true) if chars.peek() == Some(&'"') => {
                cur.push('"');
                chars.next();
            }
            ('"', _) => quoted = !quoted,
            (',', false) => fields.push(std::mem::take(&mut cur)),
            _ => cur.push(c),
        }
    }
    fields.push(cur);
    fields
}

/// Reads results.csv as written by [`write_csv`] (columns in any order; the 13 named ones
/// required).
pub fn parse_csv(text: &str) -> Result<Vec<RunRecord>, EvalError> {
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty());
    let Some((_, header)) = lines.next() else {
        return Err(EvalError::Parse {
            line: 1,
            expected: "the results.csv header",
            found: String::new(),
        });
    };
    let names: Vec<String> = split_csv_line(header.trim())
        .into_iter()
        .map(|s| s.trim().to_string())
        .collect();
    let col = |name: &str| names.iter().position(|n| n == name);
    let wanted: Vec<&str> = CSV_HEADER.split(',').collect();
    let mut idx = Vec::with_capacity(wanted.len());
    for w in &wanted {
        idx.push(col(w).ok_or_else(|| EvalError::Parse {
            line: 1,
            expected: "a results.csv header naming method, sequence, direction, run, status, e_align, e_s, e_r, e_t, e_rmse, rmse_start, rmse_end, poses",
            found: header.trim().to_string(),
        })?);
    }
    let mut out = Vec::new();
    for (i, line) in lines {
        let no = i + 1;
        let f = split_csv_line(line.trim());
        let bad = |expected: &'static str| EvalError::Parse {
            line: no,
            expected,
            found: line.trim().chars().take(120).collect(),
        };
        let get = |k: usize| f.get(idx[k]).map(|s| s.trim());
        let num = |k: usize| -> Result<f64, EvalError> {
            get(k)
                .and_then(|s| s.parse::<f64>().ok())
                .ok_or_else(|| bad("a number (or inf) in every metric column"))
        };
        let direction = get(2)
            .and_then(|s| s.parse::<Direction>().ok())
            .ok_or_else(|| bad("direction `fwd` or `bwd`"))?;
        let run = get(3)
            .and_then(|s| s.parse::<u32>().ok())
            .ok_or_else(|| bad("a run number"))?;
        let status = get(4).ok_or_else(|| bad("status `ok` or `failed`"))?;
        let ok = match status {
            "ok" => true,
            "failed" => false,
            _ => return Err(bad("status `ok` or `failed`")),
        };
        let metrics = Metrics {
            e_align: num(5)?,
            e_s: num(6)?,
            e_r: num(7)?,
            e_t: num(8)?,
            e_rmse: num(9)?,
            rmse_start: num(10)?,
            rmse_end: num(11)?,
        };
        let metrics = if ok {
            metrics
        } else {
            Metrics {
                rmse_start: metrics.rmse_start,
                ..Metrics::FAILED
            }
        };
        out.push(RunRecord {
            key: RunKey {
                method: get(0).unwrap_or("").to_string(),
                sequence: get(1).unwrap_or("").to_string(),
                direction,
                run,
            },
            failure: if ok { None } else { Some("failed".into()) },
            metrics,
            poses: get(12)
                .and_then(|s| s.parse::<usize>().ok())
                .ok_or_else(|| bad("a pose count"))?,
        });
    }
    Ok(out)
}

/// Median, minimum and maximum of a set of values (infinities included, as the paper counts
/// failed runs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Stat {
    /// Median (the mean of the two middle values for an even count).
    pub median: f64,
    /// Smallest value.
    pub min: f64,
    /// Largest value.
    pub max: f64,
}

impl Stat {
    /// Computes the statistic; `None` for no values.
    pub fn of(values: &[f64]) -> Option<Stat> {
        if values.is_empty() {
            return None;
        }
        let mut v = values.to_vec();
        v.sort_by(f64::total_cmp);
        let n = v.len();
        let median = if n % 2 == 1 {
            v[n / 2]
        } else {
            let (a, b) = (v[n / 2 - 1], v[n / 2]);
            if a.is_infinite() || b.is_infinite() {
                a.max(b)
            } else {
                0.5 * (a + b)
            }
        };
        Some(Stat {
            median,
            min: v[0],
            max: v[n - 1],
        })
    }
}

/// Per-sequence summary of one method (and direction, when split).
#[derive(Clone, Debug, PartialEq)]
pub struct SequenceSummary {
    /// Method.
    pub method: String,
    /// Sequence.
    pub sequence: String,
    /// The direction, when the summary is split by direction.
    pub direction: Option<Direction>,
    /// Number of runs.
    pub runs: usize,
    /// Number of failed runs.
    pub failed: usize,
    /// `e_align`.
    pub e_align: Stat,
    /// `e_r` in degrees.
    pub e_r: Stat,
    /// `e'_s = max(e_s, 1/e_s)`, the scale drift as a multiplier of at least 1, as the paper
    /// summarises it (failed runs count as infinite).
    pub e_s_prime: Stat,
}

/// Groups the records by method and sequence (and direction when `split_direction`) and
/// computes the median, min and max over runs, failed runs counting as infinite.
pub fn summarize(records: &[RunRecord], split_direction: bool) -> Vec<SequenceSummary> {
    type Group<'a> = Vec<&'a RunRecord>;
    let mut groups: BTreeMap<(String, String, Option<Direction>), Group<'_>> = BTreeMap::new();
    for r in records {
        let d = split_direction.then_some(r.key.direction);
        groups
            .entry((r.key.method.clone(), r.key.sequence.clone(), d))
            .or_default()
            .push(r);
    }
    groups
        .into_iter()
        .filter_map(|((method, sequence, direction), rs)| {
            let col =
                |f: fn(&Metrics) -> f64| -> Vec<f64> { rs.iter().map(|r| f(&r.metrics)).collect() };
            Some(SequenceSummary {
                runs: rs.len(),
                failed: rs.iter().filter(|r| !r.is_ok()).count(),
                e_align: Stat::of(&col(|m| m.e_align))?,
                e_r: Stat::of(&col(|m| m.e_r))?,
                e_s_prime: Stat::of(&col(|m| m.e_s_sym()))?,
                method,
                sequence,
                direction,
            })
        })
        .collect()
}

/// A cumulative error curve: the sorted finite values of one metric over a set of runs, and
/// the total number of runs (failed runs never reach the curve).
#[derive(Clone, Debug, PartialEq)]
pub struct Cumulative {
    /// Curve label (method, and direction when split).
    pub label: String,
    /// Sorted finite values; the curve passes through `(values[i], i + 1)`.
    pub values: Vec<f64>,
    /// Number of runs, failed ones included.
    pub runs: usize,
}

impl Cumulative {
    /// Number of runs with an error below or at `x`.
    pub fn count_at(&self, x: f64) -> usize {
        self.values.partition_point(|&v| v <= x)
    }
}

/// Which runs go into one curve.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DirectionFilter {
    /// Forwards and backwards together (the paper's default).
    Both,
    /// One curve per method and direction.
    Split,
    /// Forwards only.
    Forward,
    /// Backwards only.
    Backward,
}

/// The paper's cumulative error curves, one per method (per method and direction for
/// [`DirectionFilter::Split`]).
pub fn cumulative(
    records: &[RunRecord],
    metric: Metric,
    filter: DirectionFilter,
) -> Vec<Cumulative> {
    let mut groups: BTreeMap<String, (Vec<f64>, usize)> = BTreeMap::new();
    for r in records {
        let keep = match filter {
            DirectionFilter::Both | DirectionFilter::Split => true,
            DirectionFilter::Forward => r.key.direction == Direction::Forward,
            DirectionFilter::Backward => r.key.direction == Direction::Backward,
        };
        if !keep {
            continue;
        }
        let label = match filter {
            DirectionFilter::Split => format!("{} ({})", r.key.method, r.key.direction),
            _ => r.key.method.clone(),
        };
        let g = groups.entry(label).or_default();
        let v = metric.value(&r.metrics);
        if v.is_finite() {
            g.0.push(v);
        }
        g.1 += 1;
    }
    groups
        .into_iter()
        .map(|(label, (mut values, runs))| {
            values.sort_by(f64::total_cmp);
            Cumulative {
                label,
                values,
                runs,
            }
        })
        .collect()
}
