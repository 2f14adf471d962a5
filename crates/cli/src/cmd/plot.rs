//! `monovo plot`: the paper's cumulative error plots and per-sequence tables from results.csv.

use std::path::PathBuf;

use anyhow::Result;
use eval_metrics::{cumulative, summarize, summary_table, DirectionFilter, Metric, TableStyle};
use monovo_pipelines::load_results as load;
use monovo_pipelines::paper::{cumulative_chart, cumulative_json, table_json};
use monovo_pipelines::{method_box_figure, BoxStats};

use crate::plot::{self, Figure};

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
    /// Box plot of a metric over the runs of each method (failed runs left out).
    #[command(after_help = "\
Examples:
  monovo plot box results.csv -o e_align_box.png
  monovo plot box results.csv -o ape.png --metric ape_rmse --json

One box per method: the first to the third quartile, the median, whiskers to the most extreme
values within 1.5 times the box's height and the values beyond as points. The legend gives
each method's count of runs with a value. --json prints the boxes' numbers.")]
    Box(BoxArgs),
}

/// Arguments of `monovo plot box`.
#[derive(clap::Args, Debug)]
pub struct BoxArgs {
    /// results.csv from `monovo eval-batch`.
    pub results: PathBuf,
    /// Output image, .png or .svg.
    #[arg(short, long, value_name = "FILE")]
    pub output: PathBuf,
    /// Metric: e_align, e_r, e_s (as e'_s), e_t, e_rmse, rmse_start, rmse_end, and the
    /// columns of eval-batch --ape/--rpe/--kitti (ape_rmse, rpe_mean, kitti_t_err, ...).
    #[arg(long, default_value = "e_align")]
    pub metric: Metric,
    /// Replace an existing output file.
    #[arg(long)]
    pub force: bool,
    /// Print one JSON object (per method its box) as well.
    #[arg(long)]
    pub json: bool,
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
    /// Metric: e_align, e_r, e_s (as e'_s), e_t, e_rmse, rmse_start, rmse_end, and the
    /// columns of eval-batch --ape/--rpe/--kitti (ape_rmse, rpe_mean, kitti_t_err, ...).
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

/// Refuses a metric that the results do not have (an `eval-batch` without `--ape`, ...).
fn require_metric(
    records: &[eval_metrics::RunRecord],
    m: Metric,
    path: &std::path::Path,
) -> Result<()> {
    if m.is_extra() && !records.iter().any(|r| r.extra.contains_key(m.name())) {
        anyhow::bail!(
            "{}: no column {}; compute it with `monovo eval-batch --{}`",
            path.display(),
            m.name(),
            m.name().split('_').next().unwrap_or("ape")
        );
    }
    Ok(())
}

/// Runs `monovo plot`.
pub fn run(args: &Args) -> Result<()> {
    match &args.what {
        What::Cumulative(a) => {
            plot::format_of(&a.output)?;
            dataset_io::check_output_file(&a.output, a.force)?;
            let records = load(&a.results)?;
            require_metric(&records, a.metric, &a.results)?;
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
                        "lines": cumulative_json(&curves),
                    })
                )?;
            } else {
                outln!("wrote {}", a.output.display())?;
            }
        }
        What::Box(a) => {
            plot::format_of(&a.output)?;
            dataset_io::check_output_file(&a.output, a.force)?;
            let records = load(&a.results)?;
            require_metric(&records, a.metric, &a.results)?;
            plot::save(&method_box_figure(&records, a.metric), &a.output)?;
            if a.json {
                let mut methods: Vec<&str> =
                    records.iter().map(|r| r.key.method.as_str()).collect();
                methods.sort_unstable();
                methods.dedup();
                let boxes: serde_json::Map<String, serde_json::Value> = methods
                    .iter()
                    .map(|m| {
                        let v: Vec<f64> = records
                            .iter()
                            .filter(|r| r.key.method == *m)
                            .map(|r| a.metric.of(r))
                            .collect();
                        (m.to_string(), serde_json::json!(BoxStats::of(&v)))
                    })
                    .collect();
                outln!(
                    "{}",
                    serde_json::json!({
                        "output": a.output.display().to_string(),
                        "metric": a.metric.name(),
                        "boxes": boxes,
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
