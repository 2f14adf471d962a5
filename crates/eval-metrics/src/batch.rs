//! Many runs at once: parallel evaluation, the results CSV, per-sequence median (min-max)
//! tables and the paper's cumulative error curves.

use std::collections::BTreeMap;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::evaluate::{evaluate, FailReason, Metrics};
use crate::extra::{batch_track, ExtraMetric, EXTRA_COLUMNS};
use crate::metric::Metric;
use crate::record::{Direction, RunKey, RunRecord};
use crate::trajectory::{GroundTruth, Trajectory};
use crate::EvalError;

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
    evaluate_batch_with(jobs, key, load, ground_truth, &[], on_done)
}

/// [`evaluate_batch`] with the field's other metrics computed for every run as well (their
/// columns in [`RunRecord::extra`]; infinite where a metric cannot be computed).
pub fn evaluate_batch_with<'g, J, E, L, G, P>(
    jobs: &[J],
    key: impl Fn(&J) -> RunKey + Sync,
    load: L,
    ground_truth: G,
    extra: &[ExtraMetric],
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
                        extra: extra_values(extra, &traj, gt),
                        key,
                    }
                }
                None => RunRecord {
                    failure: Some(
                        FailReason::Other {
                            message: format!("no ground truth for {}", key.sequence),
                        }
                        .to_string(),
                    ),
                    metrics: Metrics::FAILED,
                    poses: traj.poses.len(),
                    extra: failed_extra(extra),
                    key,
                },
            });
            on_done();
            out
        })
        .collect()
}

/// The columns of the extra metrics, all infinite (a failed run).
pub fn failed_extra(extra: &[ExtraMetric]) -> BTreeMap<String, f64> {
    extra
        .iter()
        .flat_map(|m| m.columns().iter().map(|c| (c.to_string(), f64::INFINITY)))
        .collect()
}

/// The extra metrics of one run.
fn extra_values(
    extra: &[ExtraMetric],
    traj: &Trajectory,
    gt: &GroundTruth,
) -> BTreeMap<String, f64> {
    let mut out = failed_extra(extra);
    if extra.is_empty() || traj.poses.is_empty() {
        return out;
    }
    let reference = gt.track();
    let estimate = batch_track(traj, gt.times()[0]);
    for m in extra {
        if let Ok(values) = m.compute(&reference, &estimate) {
            for (c, v) in m.columns().iter().zip(values) {
                out.insert(c.to_string(), v);
            }
        }
    }
    out
}

/// The header of results.csv: one row per run; `reason` says why a failed run failed.
pub const CSV_HEADER: &str = "method,sequence,direction,run,status,e_align,e_s,e_r,e_t,e_rmse,rmse_start,rmse_end,poses,reason";

/// Whether a run succeeded, as results.csv writes it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
enum Status {
    Ok,
    Failed,
}

/// One row of results.csv (columns by name, so any order reads; unknown columns are
/// ignored). Metrics are written at full precision, infinities as `inf`.
#[derive(Debug, Serialize, Deserialize)]
struct CsvRow {
    method: String,
    sequence: String,
    direction: Direction,
    run: u32,
    status: Status,
    #[serde(with = "csv_float")]
    e_align: f64,
    #[serde(with = "csv_float")]
    e_s: f64,
    #[serde(with = "csv_float")]
    e_r: f64,
    #[serde(with = "csv_float")]
    e_t: f64,
    #[serde(with = "csv_float")]
    e_rmse: f64,
    #[serde(with = "csv_float")]
    rmse_start: f64,
    #[serde(with = "csv_float")]
    rmse_end: f64,
    poses: usize,
    #[serde(default)]
    reason: String,
}

/// Floats as text: shortest round-trip form, `inf`/`-inf`/`NaN` for the others.
mod csv_float {
    use serde::{Deserialize, Deserializer, Serializer};

    /// A float as results.csv writes it.
    pub fn text(v: f64) -> String {
        if v.is_finite() {
            format!("{v}")
        } else if v.is_nan() {
            "NaN".into()
        } else if v > 0.0 {
            "inf".into()
        } else {
            "-inf".into()
        }
    }

    pub fn serialize<S: Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(&text(*v))
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        let text = <std::borrow::Cow<'de, str>>::deserialize(d)?;
        text.trim()
            .parse::<f64>()
            .map_err(|_| serde::de::Error::custom(format!("`{text}` is not a number (or inf)")))
    }
}

impl From<&RunRecord> for CsvRow {
    fn from(r: &RunRecord) -> Self {
        let m = &r.metrics;
        CsvRow {
            method: r.key.method.clone(),
            sequence: r.key.sequence.clone(),
            direction: r.key.direction,
            run: r.key.run,
            status: if r.is_ok() {
                Status::Ok
            } else {
                Status::Failed
            },
            e_align: m.e_align,
            e_s: m.e_s,
            e_r: m.e_r,
            e_t: m.e_t,
            e_rmse: m.e_rmse,
            rmse_start: m.rmse_start,
            rmse_end: m.rmse_end,
            poses: r.poses,
            reason: r.failure.clone().unwrap_or_default(),
        }
    }
}

impl From<CsvRow> for RunRecord {
    fn from(r: CsvRow) -> Self {
        RunRecord {
            key: RunKey {
                method: r.method,
                sequence: r.sequence,
                direction: r.direction,
                run: r.run,
            },
            failure: match r.status {
                Status::Ok => None,
                Status::Failed => Some(r.reason),
            },
            metrics: Metrics {
                e_align: r.e_align,
                e_s: r.e_s,
                e_r: r.e_r,
                e_t: r.e_t,
                e_rmse: r.e_rmse,
                rmse_start: r.rmse_start,
                rmse_end: r.rmse_end,
            },
            poses: r.poses,
            extra: BTreeMap::new(),
        }
    }
}

fn csv_error(e: &csv::Error) -> EvalError {
    EvalError::Csv {
        line: e.position().map_or(0, |p| p.line()),
        message: match e.kind() {
            csv::ErrorKind::Deserialize { err, .. } => match err.field() {
                Some(f) => format!("column {}: {}", f + 1, err.kind()),
                None => err.kind().to_string(),
            },
            _ => e.to_string(),
        },
    }
}

/// Writes records as results.csv (RFC 4180 quoting, so commas, quotes and line breaks in
/// names and reasons survive; metrics at full precision, infinities as `inf`). The columns of
/// the field's other metrics that any record has ([`crate::EXTRA_COLUMNS`]) come before
/// `reason`; without them the header is exactly [`CSV_HEADER`].
pub fn write_csv(records: &[RunRecord]) -> String {
    let extras: Vec<&str> = EXTRA_COLUMNS
        .into_iter()
        .filter(|c| records.iter().any(|r| r.extra.contains_key(*c)))
        .collect();
    let mut w = csv::WriterBuilder::new()
        .has_headers(false)
        .from_writer(Vec::with_capacity(
            records.len() * (160 + 20 * extras.len()) + 128,
        ));
    let mut out = String::with_capacity(records.len() * 160 + 128);
    out.push_str(CSV_HEADER.trim_end_matches(",reason"));
    for c in &extras {
        out.push(',');
        out.push_str(c);
    }
    out.push_str(",reason\n");
    for r in records {
        let row = CsvRow::from(r);
        let m = &r.metrics;
        let mut fields: Vec<String> = vec![
            row.method,
            row.sequence,
            row.direction.as_str().to_string(),
            row.run.to_string(),
            if r.is_ok() { "ok" } else { "failed" }.to_string(),
        ];
        for v in [
            m.e_align,
            m.e_s,
            m.e_r,
            m.e_t,
            m.e_rmse,
            m.rmse_start,
            m.rmse_end,
        ] {
            fields.push(csv_float::text(v));
        }
        fields.push(r.poses.to_string());
        for c in &extras {
            fields.push(
                r.extra
                    .get(*c)
                    .map_or(String::new(), |v| csv_float::text(*v)),
            );
        }
        fields.push(row.reason);
        // Writing to a Vec cannot fail.
        if let Err(e) = w.write_record(&fields) {
            unreachable!("writing a results row to memory: {e}");
        }
    }
    match w.into_inner() {
        Ok(bytes) => out.push_str(&String::from_utf8_lossy(&bytes)),
        Err(e) => unreachable!("flushing a results table to memory: {e}"),
    }
    out
}

/// Reads results.csv as written by [`write_csv`]: columns by name in any order, the 13 of
/// [`CSV_HEADER`] before `reason` required, `reason` optional (a failed run without one gets
/// an empty reason, never an invented one), the columns of the field's other metrics read
/// where present (an empty cell: not computed). Errors name the line.
pub fn parse_csv(text: &str) -> Result<Vec<RunRecord>, EvalError> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut rd = csv::ReaderBuilder::new()
        .trim(csv::Trim::Headers)
        .from_reader(text.as_bytes());
    let headers = rd.headers().map_err(|e| csv_error(&e))?.clone();
    let missing: Vec<&str> = CSV_HEADER
        .split(',')
        .filter(|c| *c != "reason" && !headers.iter().any(|h| h == *c))
        .collect();
    if !missing.is_empty() {
        return Err(EvalError::Parse {
            line: 1,
            expected: "a results.csv header naming method, sequence, direction, run, status, e_align, e_s, e_r, e_t, e_rmse, rmse_start, rmse_end, poses (and reason)",
            found: headers.iter().collect::<Vec<_>>().join(","),
        });
    }
    let extras: Vec<(usize, &str)> = EXTRA_COLUMNS
        .into_iter()
        .filter_map(|c| headers.iter().position(|h| h == c).map(|i| (i, c)))
        .collect();
    let mut out = Vec::new();
    for rec in rd.records() {
        let rec = rec.map_err(|e| csv_error(&e))?;
        let row: CsvRow = rec.deserialize(Some(&headers)).map_err(|e| csv_error(&e))?;
        let mut r = RunRecord::from(row);
        for &(i, c) in &extras {
            let cell = rec.get(i).unwrap_or("").trim();
            if cell.is_empty() {
                continue;
            }
            let v = cell.parse::<f64>().map_err(|_| EvalError::Csv {
                line: rec.position().map_or(0, |p| p.line()),
                message: format!("column {c}: `{cell}` is not a number (or inf)"),
            })?;
            r.extra.insert(c.to_string(), v);
        }
        out.push(r);
    }
    Ok(out)
}

/// Median, minimum and maximum of a set of values (infinities included, as the paper counts
/// failed runs).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
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
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
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
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
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
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
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
        let v = metric.of(r);
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
