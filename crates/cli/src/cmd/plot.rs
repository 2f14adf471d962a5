//! `monovo plot`: the paper's cumulative error plots and per-sequence tables from results.csv.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use eval_metrics::{
    cumulative, parse_csv, summarize, summary_table, DirectionFilter, Metric, RunRecord, TableStyle,
};

use crate::plot::{self, Chart, Corner, Figure, Series, PALETTE};

/// Arguments of `monovo plot`.
#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(subcommand)]
    pub what: What,
}

/// What to draw.
#[derive(clap::Subcommand, Debug)]
pub enum What {
    /// Cumulative error plot: for each error x, the number of runs with error below x.
    #[command(after_help = "\
Examples:
  monovo plot cumulative results.csv -o e_align.png
  monovo plot cumulative results.csv -o e_r.svg --metric e_r --split direction

One line per method (and per direction with --split direction) over all its runs; failed
runs never reach the curve, so a method's robustness shows as its final height. The x axis is
logarithmic, as in the paper. e_s is summarised as e'_s = max(e_s, 1/e_s).")]
    Cumulative(CumulativeArgs),
    /// Per-sequence median (min-max) over the runs of e_align, e_r (degrees) and
    /// e'_s = max(e_s, 1/e_s) (a multiplier), as the paper's table.
    #[command(after_help = "\
Examples:
  monovo plot table results.csv                 # aligned text for the terminal
  monovo plot table results.csv -o table.md     # a markdown table (.md), text otherwise
  monovo plot table results.csv --json          # one JSON object, null = infinite

One row per sequence and method (and direction with --split direction). Failed runs count as
infinite, so a median of inf means that half the runs or more failed.")]
    Table(TableArgs),
}

/// Which runs go into the curves.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Split {
    /// One line per method and direction.
    Direction,
}

/// Direction filter.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Dir {
    /// Forwards runs only.
    Fwd,
    /// Backwards runs only.
    Bwd,
}

/// Arguments of `monovo plot cumulative`.
#[derive(clap::Args, Debug)]
pub struct CumulativeArgs {
    /// results.csv from `monovo eval-batch`.
    pub results: PathBuf,
    /// Output image, .png or .svg.
    #[arg(short, long, value_name = "FILE")]
    pub output: PathBuf,
    /// Metric: e_align, e_r, e_s (as e'_s), e_t, e_rmse, rmse_start, rmse_end.
    #[arg(long, default_value = "e_align")]
    pub metric: Metric,
    /// Split each method's line by playback direction.
    #[arg(long, value_enum)]
    pub split: Option<Split>,
    /// Only forwards or only backwards runs.
    #[arg(long, value_enum, conflicts_with = "split")]
    pub direction: Option<Dir>,
    /// Replace an existing output file.
    #[arg(long)]
    pub force: bool,
    /// Print one JSON object (the curves: per line its sorted finite values and its runs).
    #[arg(long)]
    pub json: bool,
}

/// Arguments of `monovo plot table`.
#[derive(clap::Args, Debug)]
pub struct TableArgs {
    /// results.csv from `monovo eval-batch`.
    pub results: PathBuf,
    /// Separate rows for forwards and backwards runs.
    #[arg(long, value_enum)]
    pub split: Option<Split>,
    /// Write the table to this file instead of standard output (markdown for .md, aligned
    /// text otherwise).
    #[arg(short, long, value_name = "FILE")]
    pub output: Option<PathBuf>,
    /// A markdown table instead of aligned text.
    #[arg(long)]
    pub markdown: bool,
    /// Replace an existing output file.
    #[arg(long)]
    pub force: bool,
    /// Print one JSON object with the summaries (null = infinite) instead of a table.
    #[arg(long)]
    pub json: bool,
}

fn load(path: &Path) -> Result<Vec<RunRecord>> {
    let text = dataset_io::read_text(path).context("the results")?;
    parse_csv(&text).with_context(|| path.display().to_string())
}

fn num(v: f64) -> serde_json::Value {
    if v.is_finite() {
        serde_json::json!(v)
    } else {
        serde_json::Value::Null
    }
}

/// The summaries as one JSON object.
fn table_json(summaries: &[eval_metrics::SequenceSummary]) -> serde_json::Value {
    let stat = |s: &eval_metrics::Stat| serde_json::json!({"median": num(s.median), "min": num(s.min), "max": num(s.max)});
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

/// The step curve of a cumulative plot, extended to `x_max`.
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

/// The cumulative error chart of some records.
pub fn cumulative_chart(records: &[RunRecord], metric: Metric, filter: DirectionFilter) -> Chart {
    let curves = cumulative(records, metric, filter);
    let all: Vec<f64> = curves
        .iter()
        .flat_map(|c| c.values.iter().copied())
        .filter(|v| *v > 0.0)
        .collect();
    let lo = all.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = all.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let (lo, hi) = if lo.is_finite() {
        (lo / 1.5, hi * 1.5)
    } else {
        (0.1, 10.0)
    };
    // e'_s is a multiplier of at least 1: its axis starts at 1
    let (lo, hi) = if metric.is_multiplier() {
        (1.0, hi.max(1.1))
    } else {
        (lo, hi)
    };
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
    // one colour per method; with a direction split, backwards runs are dashed
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

/// Runs `monovo plot`.
pub fn run(args: &Args) -> Result<()> {
    match &args.what {
        What::Cumulative(a) => {
            plot::format_of(&a.output)?;
            dataset_io::check_output_file(&a.output, a.force)?;
            let records = load(&a.results)?;
            let filter = match (a.split, a.direction) {
                (Some(Split::Direction), _) => DirectionFilter::Split,
                (None, Some(Dir::Fwd)) => DirectionFilter::Forward,
                (None, Some(Dir::Bwd)) => DirectionFilter::Backward,
                (None, None) => DirectionFilter::Both,
            };
            let chart = cumulative_chart(&records, a.metric, filter);
            plot::save(&Figure::single(chart, 900, 600), &a.output)?;
            if a.json {
                let curves = cumulative(&records, a.metric, filter);
                outln!(
                    "{}",
                    serde_json::json!({
                        "output": a.output.display().to_string(),
                        "metric": a.metric.name(),
                        "lines": curves.iter().map(|c| serde_json::json!({
                            "label": c.label, "runs": c.runs, "values": c.values,
                        })).collect::<Vec<_>>(),
                    })
                )?;
            } else {
                outln!("wrote {}", a.output.display())?;
            }
        }
        What::Table(a) => {
            if let Some(p) = &a.output {
                dataset_io::check_output_file(p, a.force)?;
            }
            let records = load(&a.results)?;
            let summaries = summarize(&records, a.split.is_some());
            let to_md = a.markdown
                || a.output
                    .as_ref()
                    .is_some_and(|p| p.extension().is_some_and(|e| e.eq_ignore_ascii_case("md")));
            let style = if to_md {
                TableStyle::Markdown
            } else {
                TableStyle::Text
            };
            let table = summary_table(&summaries, style);
            match &a.output {
                Some(p) => {
                    dataset_io::write_atomic(p, table.as_bytes())?;
                    if a.json {
                        let mut v = table_json(&summaries);
                        v["output"] = serde_json::json!(p.display().to_string());
                        outln!("{v}")?;
                    } else {
                        outln!("wrote {}", p.display())?;
                    }
                }
                None if a.json => outln!("{}", table_json(&summaries))?,
                None => out!("{table}")?,
            }
        }
    }
    Ok(())
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
        parse_csv(&csv).unwrap()
    }

    #[test]
    fn cumulative_counts_are_integers_and_e_s_starts_at_1() {
        let r = records();
        let c = cumulative_chart(&r, Metric::ES, DirectionFilter::Both);
        assert_eq!(c.x_range.map(|x| x[0]), Some(1.0));
        assert!(c.x_log && c.y_integer);
        assert!(c.x_label.contains("e'_s") && c.y_label == "number of runs");
        // the step curve of e'_s starts at or right of 1 and reaches the 7 successful runs
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
}
