//! `monovo plot`: the paper's cumulative error plots and per-sequence tables from results.csv.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use eval_metrics::{
    cumulative, markdown_table, parse_csv, summarize, DirectionFilter, Metric, RunRecord,
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
    /// Per-sequence median (min-max) of e_align, e_r and e_s over runs, as a markdown table.
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
}

/// Arguments of `monovo plot table`.
#[derive(clap::Args, Debug)]
pub struct TableArgs {
    /// results.csv from `monovo eval-batch`.
    pub results: PathBuf,
    /// Separate rows for forwards and backwards runs.
    #[arg(long, value_enum)]
    pub split: Option<Split>,
    /// Write the table to this file instead of standard output.
    #[arg(short, long, value_name = "FILE")]
    pub output: Option<PathBuf>,
}

fn load(path: &Path) -> Result<Vec<RunRecord>> {
    let text = dataset_io::read_text(path)?;
    parse_csv(&text).with_context(|| path.display().to_string())
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
            let records = load(&a.results)?;
            let filter = match (a.split, a.direction) {
                (Some(Split::Direction), _) => DirectionFilter::Split,
                (None, Some(Dir::Fwd)) => DirectionFilter::Forward,
                (None, Some(Dir::Bwd)) => DirectionFilter::Backward,
                (None, None) => DirectionFilter::Both,
            };
            let chart = cumulative_chart(&records, a.metric, filter);
            plot::save(&Figure::single(chart, 900, 600), &a.output)?;
            println!("wrote {}", a.output.display());
        }
        What::Table(a) => {
            let records = load(&a.results)?;
            let table = markdown_table(&summarize(&records, a.split.is_some()));
            match &a.output {
                Some(p) => {
                    dataset_io::write_atomic(p, table.as_bytes())?;
                    println!("wrote {}", p.display());
                }
                None => print!("{table}"),
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
