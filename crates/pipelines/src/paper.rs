//! The paper's figures and tables from evaluated runs: cumulative error plots, the
//! per-sequence table, per-method medians, and the metric study.

use std::fmt::Write as _;

use eval_metrics::{
    cumulative, evaluate, Cumulative, DirectionFilter, GroundTruth, Metric, RunRecord,
    SequenceSummary, Stat,
};
use monovo_figures::{Chart, Corner, Figure, Series, PALETTE};
use synthetic::trajectory::{
    benchmark_path, estimate, tum_text, Drift, EstimateConfig, PathConfig,
};

use crate::{json_number, PipelineError, Result};

/// The step curve of a cumulative plot (for each error x, the number of runs below x),
/// extended to `x_max`.
pub fn step_points(values: &[f64], x_max: f64) -> Vec<[f64; 2]> {
    let mut pts = Vec::with_capacity(values.len() * 2 + 2);
    for (i, &v) in values.iter().enumerate() {
        pts.push([v, i as f64]);
        pts.push([v, (i + 1) as f64]);
    }
    if let Some(&last) = values.last() {
        pts.push([x_max.max(last), values.len() as f64]);
    }
    pts
}

/// The x range of cumulative curves on a logarithmic axis: the positive values with a
/// margin (from 1 for the multiplier e'_s).
pub fn cumulative_range<'a>(
    curves: impl IntoIterator<Item = &'a Cumulative>,
    metric: Metric,
) -> [f64; 2] {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in curves
        .into_iter()
        .flat_map(|c| c.values.iter().copied())
        .filter(|v| *v > 0.0 && v.is_finite())
    {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    let (lo, hi) = if lo.is_finite() {
        (lo / 1.5, hi * 1.5)
    } else {
        (0.1, 10.0)
    };
    if metric.is_multiplier() {
        [1.0, hi.max(1.1)]
    } else {
        [lo, hi]
    }
}

/// The cumulative error chart of some records: one line per method (solid), with a
/// direction split backwards runs dashed; logarithmic x axis, as in the paper.
pub fn cumulative_chart(records: &[RunRecord], metric: Metric, filter: DirectionFilter) -> Chart {
    let curves = cumulative(records, metric, filter);
    let [lo, hi] = cumulative_range(&curves, metric);
    let runs = curves.iter().map(|c| c.runs).max().unwrap_or(0);
    let mut chart = Chart::new(
        format!(
            "cumulative {} ({} runs per line at most)",
            metric.name(),
            runs
        ),
        metric.label(),
        "number of runs",
    );
    chart.x_log = true;
    chart.x_range = Some([lo, hi]);
    chart.y_range = Some([0.0, runs.max(1) as f64 * 1.04]);
    chart.legend = Some(Corner::TopLeft);
    chart.y_integer = true;
    let mut methods: Vec<&str> = records.iter().map(|r| r.key.method.as_str()).collect();
    methods.sort_unstable();
    methods.dedup();
    for c in &curves {
        let method = c.label.split(" (").next().unwrap_or(&c.label);
        let i = methods.iter().position(|m| *m == method).unwrap_or(0);
        let mut s = Series::line(
            format!("{} ({}/{} runs)", c.label, c.values.len(), c.runs),
            step_points(&c.values, hi),
            PALETTE[i % PALETTE.len()],
        );
        if filter == DirectionFilter::Split && c.label.ends_with("(bwd)") {
            s = s.dashed();
        }
        chart.series.push(s);
    }
    chart
}

/// The curves of a cumulative plot as `monovo plot cumulative --json` prints them.
pub fn cumulative_json(curves: &[Cumulative]) -> serde_json::Value {
    serde_json::Value::Array(
        curves
            .iter()
            .map(|c| serde_json::json!({"label": c.label, "runs": c.runs, "values": c.values}))
            .collect(),
    )
}

/// The per-sequence summaries as one JSON object (`null` = infinite).
pub fn table_json(summaries: &[SequenceSummary]) -> serde_json::Value {
    let stat = |s: &Stat| serde_json::json!({"median": json_number(s.median), "min": json_number(s.min), "max": json_number(s.max)});
    serde_json::json!({
        "caption": eval_metrics::TABLE_CAPTION,
        "rows": summaries.iter().map(|s| serde_json::json!({
            "sequence": s.sequence,
            "method": s.method,
            "direction": s.direction.map(|d| d.to_string()),
            "runs": s.runs,
            "failed": s.failed,
            "e_align": stat(&s.e_align),
            "e_r_deg": stat(&s.e_r),
            "e_s_prime": stat(&s.e_s_prime),
        })).collect::<Vec<_>>(),
    })
}

/// One method's medians over all its runs (failed runs count as infinite).
#[derive(Clone, Debug, serde::Serialize)]
pub struct MethodMedians {
    /// The method.
    pub method: String,
    /// Its runs.
    pub runs: usize,
    /// Its failed runs.
    pub failed: usize,
    /// Median e_align.
    pub e_align: f64,
    /// Median e_r in degrees.
    pub e_r: f64,
    /// Median e'_s.
    pub e_s_prime: f64,
}

/// The medians of every method, sorted by method name.
pub fn method_medians(records: &[RunRecord]) -> Vec<MethodMedians> {
    cumulative(records, Metric::EAlign, DirectionFilter::Both)
        .into_iter()
        .map(|c| {
            let rs: Vec<&RunRecord> = records.iter().filter(|r| r.key.method == c.label).collect();
            let med = |m: Metric| {
                let v: Vec<f64> = rs.iter().map(|r| m.value(&r.metrics)).collect();
                Stat::of(&v).map_or(f64::NAN, |s| s.median)
            };
            MethodMedians {
                runs: c.runs,
                failed: c.runs - c.values.len(),
                e_align: med(Metric::EAlign),
                e_r: med(Metric::ER),
                e_s_prime: med(Metric::ES),
                method: c.label,
            }
        })
        .collect()
}

fn fmt_stat(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.3}")
    } else {
        "inf".into()
    }
}

const METHOD_HEADER: [&str; 6] = [
    "method",
    "runs",
    "failed",
    "median e_align",
    "median e_r (deg)",
    "median e'_s",
];

/// The medians as a markdown table.
pub fn medians_markdown(lines: &[MethodMedians]) -> String {
    let mut s = format!(
        "| {} |\n|---|--:|--:|--:|--:|--:|\n",
        METHOD_HEADER.join(" | ")
    );
    for l in lines {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {} |",
            l.method,
            l.runs,
            l.failed,
            fmt_stat(l.e_align),
            fmt_stat(l.e_r),
            fmt_stat(l.e_s_prime)
        );
    }
    s
}

/// The medians as aligned text, indented by two spaces.
pub fn medians_text(lines: &[MethodMedians]) -> String {
    let w = lines
        .iter()
        .map(|l| l.method.len())
        .max()
        .unwrap_or(0)
        .max(6);
    let row = |c: [&str; 6]| {
        format!(
            "  {:<w$}  {:>5}  {:>6}  {:>14}  {:>16}  {:>11}\n",
            c[0], c[1], c[2], c[3], c[4], c[5]
        )
    };
    let mut s = row(METHOD_HEADER);
    for l in lines {
        s += &row([
            &l.method,
            &l.runs.to_string(),
            &l.failed.to_string(),
            &fmt_stat(l.e_align),
            &fmt_stat(l.e_r),
            &fmt_stat(l.e_s_prime),
        ]);
    }
    s
}

/// The medians as JSON (`null` = infinite).
pub fn medians_json(lines: &[MethodMedians]) -> serde_json::Value {
    serde_json::Value::Array(
        lines
            .iter()
            .map(|l| {
                serde_json::json!({
                    "method": l.method, "runs": l.runs, "failed": l.failed,
                    "median_e_align": json_number(l.e_align), "median_e_r": json_number(l.e_r),
                    "median_e_s_prime": json_number(l.e_s_prime),
                })
            })
            .collect(),
    )
}

/// The paper's metric study on a synthetic path of 1000 frames from `seed`: a x0.8 scale
/// jump or a 10 degree rotation jump injected at each point in time, and e_align, e_t and
/// e_rmse against where the jump happens.
pub fn metric_study_figure(seed: u64) -> Result<Figure> {
    let p = benchmark_path(
        seed,
        &PathConfig {
            frames: 1000,
            ..PathConfig::default()
        },
    );
    let bad = |e: eval_metrics::EvalError| PipelineError::Invalid(format!("the metric study: {e}"));
    let gt = GroundTruth::parse(&p.ground_truth_sync()).map_err(bad)?;
    let mut lines: Vec<(String, Vec<[f64; 2]>, usize, bool)> = Vec::new();
    for (jump, dashed) in [("scale x0.8", true), ("rotation 10 deg", false)] {
        let (mut ea, mut et, mut er) = (Vec::new(), Vec::new(), Vec::new());
        for f in (p.segment_frames..p.len() - p.segment_frames).step_by(10) {
            let drift = if dashed {
                Drift {
                    scale_jumps: vec![(f, 0.8)],
                    ..Drift::default()
                }
            } else {
                Drift {
                    rotation_jumps: vec![(f, [0.2, 0.3, 1.0], 10.0)],
                    ..Drift::default()
                }
            };
            let cfg = EstimateConfig {
                drift,
                ..EstimateConfig::default()
            };
            let run = eval_metrics::parse_tum(&tum_text(&estimate(&p, &cfg, seed))).map_err(bad)?;
            let e = evaluate(&run, &gt);
            let x = f as f64 / p.len() as f64;
            ea.push([x, e.metrics.e_align]);
            et.push([x, e.metrics.e_t]);
            er.push([x, e.metrics.e_rmse]);
        }
        lines.push((format!("e_align, {jump}"), ea, 0, dashed));
        lines.push((format!("e_t, {jump}"), et, 1, dashed));
        lines.push((format!("e_rmse, {jump}"), er, 2, dashed));
    }
    let mut c = Chart::new(
        "metric study: where the drift happens (dashed: scale x0.8, solid: rotation 10 deg)",
        "time of the jump (fraction of the sequence)",
        "error (ground-truth length unit)",
    );
    c.legend = Some(Corner::TopRight);
    c.x_range = Some([0.0, 1.0]);
    for (label, pts, color, dashed) in lines {
        let mut s = Series::line(label, pts, PALETTE[color]);
        if dashed {
            s = s.dashed();
        }
        c.series.push(s);
    }
    Ok(Figure::single(c, 1000, 600))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Seven runs of one method in both directions, e_s around 1, one failure.
    fn records() -> Vec<RunRecord> {
        let mut csv = format!("{}\n", eval_metrics::CSV_HEADER);
        for i in 0..7 {
            let dir = if i % 2 == 0 { "fwd" } else { "bwd" };
            let e_s = if i % 3 == 0 {
                1.0 / (1.0 + 0.1 * i as f64)
            } else {
                1.0 + 0.05 * i as f64
            };
            csv += &format!("m,sequence_01,{dir},{i},ok,0.{i}5,{e_s},0.5,1,1,0.1,0.1,100,\n");
        }
        csv += "m,sequence_01,fwd,9,failed,inf,inf,inf,inf,inf,inf,inf,0,lost\n";
        eval_metrics::parse_csv(&csv).unwrap()
    }

    #[test]
    fn cumulative_counts_are_integers_and_e_s_starts_at_1() {
        let r = records();
        let c = cumulative_chart(&r, Metric::ES, DirectionFilter::Both);
        assert_eq!(c.x_range.map(|x| x[0]), Some(1.0));
        assert!(c.x_log && c.y_integer);
        assert!(c.x_label.contains("e'_s") && c.y_label == "number of runs");
        let pts = &c.series[0].points;
        assert!(pts.iter().all(|p| p[0] >= 1.0), "{pts:?}");
        assert_eq!(pts.last().map(|p| p[1]), Some(7.0));
        assert!(
            c.series[0].label.contains("7/8 runs"),
            "{}",
            c.series[0].label
        );
        let c = cumulative_chart(&r, Metric::EAlign, DirectionFilter::Split);
        assert!(c.x_range.unwrap()[0] < 0.05);
        assert_eq!(c.series.len(), 2);
        assert!(
            c.series.iter().any(|s| s.dashed),
            "backwards runs are dashed"
        );
        assert!(c.x_label.contains("ground-truth length unit"));
        let c = cumulative_chart(&r, Metric::ER, DirectionFilter::Both);
        assert!(c.x_label.contains("degrees"));
    }

    #[test]
    fn medians_count_failures_as_infinite() {
        let m = method_medians(&records());
        assert_eq!(m.len(), 1);
        assert_eq!((m[0].runs, m[0].failed), (8, 1));
        assert!(m[0].e_align.is_finite());
        let text = medians_text(&m);
        assert!(
            text.contains("median e_align") && text.lines().count() == 2,
            "{text}"
        );
        assert!(medians_markdown(&m).starts_with("| method | runs |"));
    }
}
