//! Experiment manifests: a TOML file that names methods and variations (field of view,
//! resolution, direction, real-time or not: each a results folder, a filter, or both), and
//! the one job that evaluates them all and draws the paper's grouped cumulative error plots.
//!
//! ```toml
//! title = "synthetic benchmark"
//! dataset = "dataset"            # SEQUENCE/groundtruthSync.txt; paths are relative to the base
//! results = "results"            # METHOD/SEQUENCE/{fwd,bwd}_N.txt (a variation may override)
//! metrics = ["e_align", "e_r", "e_s"]
//! layout = "panels"              # one panel per variation; "overlay": line style per variation
//!
//! [[method]]
//! name = "direct"                # the method's folder in the results tree
//! label = "direct (DSO-like)"    # legend text (default: the name)
//!
//! [[variation]]
//! name = "forward"
//! direction = "fwd"              # fwd, bwd or both (default)
//!
//! [[variation]]
//! name = "fov90"
//! results = "results_fov90"      # another results folder (and `dataset`, if it differs)
//! sequences = ["sequence_01"]    # only these sequences (default: all)
//! ```

use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use dataset_io::OutputDir;
use eval_metrics::{cumulative, Direction, DirectionFilter, ExtraMetric, Metric, RunRecord, Stat};
use monovo_figures::{Chart, Corner, Figure, Panel, Series, PALETTE};
use serde::{Deserialize, Serialize};
use toml::Spanned;

use crate::batch::{evaluate_tree, BatchOptions};
use crate::metric_table::MetricTable;
use crate::paper::{cumulative_range, step_points};
use crate::{json_number, Observer, PipelineError, Result};

/// How the groups are drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Layout {
    /// One panel per variation, one colour per method (shared axes).
    Panels,
    /// One chart: one colour per method, one line style per variation.
    Overlay,
}

/// Which playback direction a variation keeps.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum DirectionChoice {
    /// Forwards runs.
    Fwd,
    /// Backwards runs.
    Bwd,
    /// Both.
    Both,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ManifestFile {
    title: Option<String>,
    dataset: Spanned<String>,
    results: Option<Spanned<String>>,
    metrics: Option<Vec<Metric>>,
    layout: Option<Layout>,
    keep_going: Option<bool>,
    #[serde(rename = "method")]
    methods: Option<Vec<MethodFile>>,
    #[serde(rename = "variation")]
    variations: Option<Vec<Spanned<VariationFile>>>,
    ape: Option<Spanned<MetricTable>>,
    rpe: Option<Spanned<MetricTable>>,
    kitti: Option<Spanned<MetricTable>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct MethodFile {
    name: Spanned<String>,
    label: Option<String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct VariationFile {
    name: Spanned<String>,
    label: Option<String>,
    dataset: Option<String>,
    results: Option<String>,
    direction: Option<DirectionChoice>,
    sequences: Option<Vec<String>>,
}

/// A method of an experiment.
#[derive(Clone, Debug, Serialize)]
pub struct ExperimentMethod {
    /// Its folder in the results trees.
    pub name: String,
    /// Its legend text.
    pub label: String,
    /// The manifest line that names it.
    pub line: usize,
}

/// A variation of an experiment: which runs it takes.
#[derive(Clone, Debug, Serialize)]
pub struct Variation {
    /// Its name (file names, tables).
    pub name: String,
    /// Its title in the figures.
    pub label: String,
    /// The ground-truth folder.
    pub dataset: PathBuf,
    /// The results folder.
    pub results: PathBuf,
    /// Which direction it keeps.
    pub direction: DirectionChoice,
    /// The sequences it keeps (empty: all).
    pub sequences: Vec<String>,
    /// The manifest line where it starts.
    pub line: usize,
}

/// A parsed experiment manifest with its paths resolved.
#[derive(Clone, Debug, Serialize)]
pub struct Experiment {
    /// The manifest file.
    pub path: PathBuf,
    /// Title of the figures.
    pub title: String,
    /// Metrics to plot and tabulate.
    pub metrics: Vec<Metric>,
    /// How the groups are drawn.
    pub layout: Layout,
    /// Count unreadable run files as failed runs instead of stopping.
    pub keep_going: bool,
    /// The methods, in the manifest's order (the order of colours).
    pub methods: Vec<ExperimentMethod>,
    /// The variations, in the manifest's order.
    pub variations: Vec<Variation>,
    /// The field's other metrics computed next to e_align (the `[ape]`, `[rpe]` and
    /// `[kitti]` tables).
    pub extra: Vec<ExtraMetric>,
}

/// 1-based line of a byte offset.
fn line_of(text: &str, offset: usize) -> usize {
    text.get(..offset.min(text.len()))
        .map_or(1, |t| t.bytes().filter(|b| *b == b'\n').count() + 1)
}

fn is_plain_name(s: &str) -> bool {
    !s.is_empty()
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.'))
}

impl Experiment {
    /// Parses a manifest; relative paths are resolved against `base`. Errors name `path`,
    /// the line and what was expected.
    pub fn parse(text: &str, path: &Path, base: &Path) -> Result<Experiment> {
        let err = |line: Option<usize>, message: String| PipelineError::Manifest {
            path: path.to_path_buf(),
            line,
            message,
        };
        let file: ManifestFile = toml::from_str(text).map_err(|e| {
            let line = e.span().map(|s| line_of(text, s.start));
            err(line, e.message().trim_end().to_string())
        })?;
        let at = |s: &std::ops::Range<usize>| Some(line_of(text, s.start));
        let resolve = |p: &str| base.join(p);
        let metrics = file
            .metrics
            .unwrap_or_else(|| vec![Metric::EAlign, Metric::ER, Metric::ES]);
        if metrics.is_empty() {
            return Err(err(
                None,
                "`metrics` is empty; expected a list such as [\"e_align\", \"e_r\", \"e_s\"]"
                    .into(),
            ));
        }
        let mut methods: Vec<ExperimentMethod> = Vec::new();
        for m in file.methods.unwrap_or_default() {
            let line = line_of(text, m.name.span().start);
            let name = m.name.into_inner();
            if !is_plain_name(&name) {
                return Err(err(Some(line), format!("method name `{name}`: expected the name of a method's folder in the results tree")));
            }
            if methods.iter().any(|o| o.name == name) {
                return Err(err(Some(line), format!("method `{name}` is listed twice")));
            }
            methods.push(ExperimentMethod {
                label: m.label.unwrap_or_else(|| name.clone()),
                name,
                line,
            });
        }
        if methods.is_empty() {
            return Err(err(
                None,
                "no methods; expected at least one [[method]] table with a `name`".into(),
            ));
        }
        let default_results = file.results.as_ref().map(|r| resolve(r.get_ref()));
        let dataset = resolve(file.dataset.get_ref());
        let mut variations: Vec<Variation> = Vec::new();
        let list = file.variations.unwrap_or_default();
        for v in list {
            let line = line_of(text, v.span().start);
            let v = v.into_inner();
            let name_line = at(&v.name.span());
            let name = v.name.into_inner();
            if !is_plain_name(&name) {
                return Err(err(name_line, format!("variation name `{name}`: expected letters, digits, '_', '-' or '.' (it names files)")));
            }
            if variations.iter().any(|o| o.name == name) {
                return Err(err(
                    name_line,
                    format!("variation `{name}` is listed twice"),
                ));
            }
            let results = match (v.results, &default_results) {
                (Some(r), _) => resolve(&r),
                (None, Some(r)) => r.clone(),
                (None, None) => return Err(err(Some(line), format!("variation `{name}` has no `results` folder and the manifest none at the top"))),
            };
            variations.push(Variation {
                label: v.label.unwrap_or_else(|| name.clone()),
                name,
                dataset: v.dataset.map_or_else(|| dataset.clone(), |d| resolve(&d)),
                results,
                direction: v.direction.unwrap_or(DirectionChoice::Both),
                sequences: v.sequences.unwrap_or_default(),
                line,
            });
        }
        if variations.is_empty() {
            // no variations: every run of the top-level results folder
            let Some(results) = default_results else {
                return Err(err(None, "no `results` folder and no [[variation]] tables; expected at least one of them".into()));
            };
            variations.push(Variation {
                name: "all".into(),
                label: "all runs".into(),
                dataset,
                results,
                direction: DirectionChoice::Both,
                sequences: Vec::new(),
                line: 1,
            });
        }
        let mut extra = Vec::new();
        for (table, which) in [
            (&file.ape, "ape"),
            (&file.rpe, "rpe"),
            (&file.kitti, "kitti"),
        ] {
            if let Some(t) = table {
                let m = match which {
                    "ape" => t.get_ref().ape(),
                    "rpe" => t.get_ref().rpe(),
                    _ => t.get_ref().kitti(),
                }
                .map_err(|m| err(at(&t.span()), format!("[{which}]: {m}")))?;
                extra.push(m);
            }
        }
        for m in metrics.iter().filter(|m| m.is_extra()) {
            let table = m.name().split('_').next().unwrap_or("");
            if !extra.iter().any(|x| x.columns().contains(&m.name())) {
                return Err(err(
                    None,
                    format!(
                        "metric `{}` needs an [{table}] table (evo's options, e.g. align = \"sim3\"); see `monovo experiment --help`",
                        m.name()
                    ),
                ));
            }
        }
        Ok(Experiment {
            path: path.to_path_buf(),
            title: file.title.unwrap_or_default(),
            metrics,
            layout: file.layout.unwrap_or(Layout::Panels),
            keep_going: file.keep_going.unwrap_or(false),
            methods,
            variations,
            extra,
        })
    }

    /// Reads and parses a manifest; relative paths are resolved against `base`, by default
    /// the manifest's folder.
    pub fn load(path: &Path, base: Option<&Path>) -> Result<Experiment> {
        let text = dataset_io::read_text(path).map_err(|source| PipelineError::Read {
            what: "the experiment manifest",
            source,
        })?;
        let dir = path.parent().unwrap_or(Path::new(""));
        Experiment::parse(&text, path, base.unwrap_or(dir))
    }
}

/// One method in one variation.
#[derive(Clone, Debug, Serialize)]
pub struct GroupResult {
    /// The variation's name.
    pub variation: String,
    /// The method's name.
    pub method: String,
    /// Runs.
    pub runs: usize,
    /// Failed runs.
    pub failed: usize,
    /// Median of each metric of the experiment, in its order (failed runs count as
    /// infinite; `null` in JSON).
    #[serde(serialize_with = "ser_medians")]
    pub medians: Vec<f64>,
}

fn ser_medians<S: serde::Serializer>(v: &[f64], s: S) -> std::result::Result<S::Ok, S::Error> {
    use serde::ser::SerializeSeq;
    let mut seq = s.serialize_seq(Some(v.len()))?;
    for x in v {
        seq.serialize_element(&json_number(*x))?;
    }
    seq.end()
}

/// What [`run_experiment`] wrote.
#[derive(Clone, Debug, Serialize)]
pub struct ExperimentReport {
    /// The output folder.
    pub output: PathBuf,
    /// The metrics, by name.
    pub metrics: Vec<&'static str>,
    /// One entry per variation and method.
    pub groups: Vec<GroupResult>,
    /// The figures (one per metric).
    pub figures: Vec<PathBuf>,
    /// The tables: summary.md, summary.csv and one results CSV per variation.
    pub tables: Vec<PathBuf>,
    /// Runs evaluated (each results folder once).
    pub runs_evaluated: usize,
    /// Wall time in seconds.
    pub seconds: f64,
}

fn keeps(v: &Variation, r: &RunRecord) -> bool {
    let dir_ok = match v.direction {
        DirectionChoice::Both => true,
        DirectionChoice::Fwd => r.key.direction == Direction::Forward,
        DirectionChoice::Bwd => r.key.direction == Direction::Backward,
    };
    dir_ok && (v.sequences.is_empty() || v.sequences.contains(&r.key.sequence))
}

fn fmt_median(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.3}")
    } else {
        "inf".into()
    }
}

/// Evaluates every results folder of the experiment once (in parallel), takes each
/// variation's runs of each method, and writes into the folder `output` (whole or not at
/// all; an existing one only with `force`): one figure per metric
/// (`cumulative_METRIC.png`, grouped by variation as the manifest's `layout` says),
/// `summary.md` and `summary.csv` (runs, failures and medians per variation and method) and
/// `results_VARIATION.csv` (the evaluated runs of each variation).
pub fn run_experiment(
    exp: &Experiment,
    output: &Path,
    force: bool,
    observer: &dyn Observer,
) -> Result<ExperimentReport> {
    let started = std::time::Instant::now();
    OutputDir::check(output, force)?;
    let manifest_err = |line: usize, message: String| PipelineError::Manifest {
        path: exp.path.clone(),
        line: Some(line),
        message,
    };
    // each (dataset, results) pair once
    let mut evaluated: HashMap<(PathBuf, PathBuf), Vec<RunRecord>> = HashMap::new();
    let mut runs_evaluated = 0;
    for v in &exp.variations {
        let key = (v.dataset.clone(), v.results.clone());
        if evaluated.contains_key(&key) {
            continue;
        }
        let batch = evaluate_tree(
            &BatchOptions {
                dataset: v.dataset.clone(),
                results: v.results.clone(),
                output: None,
                force: false,
                keep_going: exp.keep_going,
                extra: exp.extra.clone(),
            },
            observer,
        )
        .map_err(|e| {
            e.context(format!(
                "{}: line {}: variation `{}`",
                exp.path.display(),
                v.line,
                v.name
            ))
        })?;
        runs_evaluated += batch.records.len();
        evaluated.insert(key, batch.records);
    }
    // the runs of each variation and method
    let mut per_variation: Vec<Vec<RunRecord>> = Vec::new();
    for v in &exp.variations {
        let all = evaluated
            .get(&(v.dataset.clone(), v.results.clone()))
            .map_or(&[][..], |r| r.as_slice());
        let kept: Vec<RunRecord> = all
            .iter()
            .filter(|r| keeps(v, r) && exp.methods.iter().any(|m| m.name == r.key.method))
            .cloned()
            .collect();
        for s in &v.sequences {
            if !all.iter().any(|r| &r.key.sequence == s) {
                return Err(manifest_err(
                    v.line,
                    format!(
                        "variation `{}`: no runs of sequence `{s}` in {}",
                        v.name,
                        v.results.display()
                    ),
                ));
            }
        }
        for m in &exp.methods {
            if !kept.iter().any(|r| r.key.method == m.name) {
                observer.warn(&format!(
                    "{}: variation `{}`: no runs of method `{}` in {}",
                    exp.path.display(),
                    v.name,
                    m.name,
                    v.results.display()
                ));
            }
        }
        per_variation.push(kept);
    }
    for m in &exp.methods {
        if !per_variation
            .iter()
            .flatten()
            .any(|r| r.key.method == m.name)
        {
            return Err(manifest_err(
                m.line,
                format!(
                    "method `{}`: no runs in any variation; expected a folder {}/{} in the results",
                    m.name, m.name, m.name
                ),
            ));
        }
    }
    let out = OutputDir::create(output, force)?;
    let final_dir = output.to_path_buf();
    let mut groups = Vec::new();
    let mut tables = Vec::new();
    for (v, records) in exp.variations.iter().zip(&per_variation) {
        let name = format!("results_{}.csv", v.name);
        out.write(&name, eval_metrics::write_csv(records).as_bytes())?;
        tables.push(final_dir.join(name));
        for m in &exp.methods {
            let rs: Vec<&RunRecord> = records.iter().filter(|r| r.key.method == m.name).collect();
            let medians = exp
                .metrics
                .iter()
                .map(|metric| {
                    let vals: Vec<f64> = rs.iter().map(|r| metric.of(r)).collect();
                    Stat::of(&vals).map_or(f64::NAN, |s| s.median)
                })
                .collect();
            groups.push(GroupResult {
                variation: v.name.clone(),
                method: m.name.clone(),
                runs: rs.len(),
                failed: rs.iter().filter(|r| !r.is_ok()).count(),
                medians,
            });
        }
    }
    let (md, csv) = summary_tables(exp, &groups);
    out.write("summary.md", md.as_bytes())?;
    out.write("summary.csv", csv.as_bytes())?;
    tables.insert(0, final_dir.join("summary.csv"));
    tables.insert(0, final_dir.join("summary.md"));
    let mut figures = Vec::new();
    for &metric in &exp.metrics {
        let fig = grouped_figure(exp, &per_variation, metric);
        let name = format!("cumulative_{}.png", metric.name());
        monovo_figures::save(&fig, &out.path().join(&name))?;
        figures.push(final_dir.join(name));
        let fig = grouped_box_figure(exp, &per_variation, metric);
        let name = format!("box_{}.png", metric.name());
        monovo_figures::save(&fig, &out.path().join(&name))?;
        figures.push(final_dir.join(name));
    }
    out.commit()?;
    Ok(ExperimentReport {
        output: final_dir,
        metrics: exp.metrics.iter().map(|m| m.name()).collect(),
        groups,
        figures,
        tables,
        runs_evaluated,
        seconds: started.elapsed().as_secs_f64(),
    })
}

/// summary.md and summary.csv.
fn summary_tables(exp: &Experiment, groups: &[GroupResult]) -> (String, String) {
    let names: Vec<String> = exp
        .metrics
        .iter()
        .map(|m| match m {
            Metric::ES => "e'_s".to_string(),
            Metric::ER => "e_r (deg)".to_string(),
            m => m.name().to_string(),
        })
        .collect();
    let mut md = String::new();
    if !exp.title.is_empty() {
        let _ = writeln!(md, "# {}\n", exp.title);
    }
    let _ = writeln!(
        md,
        "Median over the runs of each method in each variation; failed runs count as infinite.\n"
    );
    let _ = writeln!(
        md,
        "| variation | method | runs | failed | {} |",
        names
            .iter()
            .map(|n| format!("median {n}"))
            .collect::<Vec<_>>()
            .join(" | ")
    );
    let _ = writeln!(md, "|---|---|--:|--:|{}", "--:|".repeat(names.len()));
    let mut csv = format!(
        "variation,method,runs,failed,{}\n",
        exp.metrics
            .iter()
            .map(|m| format!("median_{}", m.name()))
            .collect::<Vec<_>>()
            .join(",")
    );
    for g in groups {
        let meds: Vec<String> = g.medians.iter().map(|v| fmt_median(*v)).collect();
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} | {} |",
            g.variation,
            g.method,
            g.runs,
            g.failed,
            meds.join(" | ")
        );
        let _ = writeln!(
            csv,
            "{},{},{},{},{}",
            g.variation,
            g.method,
            g.runs,
            g.failed,
            meds.join(",")
        );
    }
    (md, csv)
}

/// Line styles of the variations in the overlay layout.
fn styled(s: Series, i: usize) -> Series {
    match i % 4 {
        0 => s,
        1 => s.dashed(),
        2 => s.dotted(),
        _ => s.dash_pattern(14.0, 4.0),
    }
}

/// The cumulative error figure of one metric, grouped by variation.
pub fn grouped_figure(
    exp: &Experiment,
    per_variation: &[Vec<RunRecord>],
    metric: Metric,
) -> Figure {
    // one curve per (variation, method), on common axes
    let curves: Vec<Vec<(usize, eval_metrics::Cumulative)>> = per_variation
        .iter()
        .map(|records| {
            exp.methods
                .iter()
                .enumerate()
                .filter_map(|(i, m)| {
                    let rs: Vec<RunRecord> = records
                        .iter()
                        .filter(|r| r.key.method == m.name)
                        .cloned()
                        .collect();
                    cumulative(&rs, metric, DirectionFilter::Both)
                        .into_iter()
                        .next()
                        .map(|c| (i, c))
                })
                .collect()
        })
        .collect();
    let [lo, hi] = cumulative_range(curves.iter().flatten().map(|(_, c)| c), metric);
    let runs = curves
        .iter()
        .flatten()
        .map(|(_, c)| c.runs)
        .max()
        .unwrap_or(0)
        .max(1);
    let chart = |title: String| {
        let mut c = Chart::new(title, metric.label(), "number of runs");
        c.x_log = true;
        c.x_range = Some([lo, hi]);
        c.y_range = Some([0.0, runs as f64 * 1.04]);
        c.y_integer = true;
        c.legend = Some(Corner::TopLeft);
        c
    };
    let short = if metric == Metric::ES {
        "e'_s"
    } else {
        metric.name()
    };
    let heading = |what: &str| {
        if exp.title.is_empty() {
            what.to_string()
        } else {
            format!("{}: {what}", exp.title)
        }
    };
    let series = |i: usize, c: &eval_metrics::Cumulative, label: String| {
        Series::line(
            format!("{label} ({}/{} runs)", c.values.len(), c.runs),
            step_points(&c.values, hi),
            PALETTE[i % PALETTE.len()],
        )
    };
    match exp.layout {
        Layout::Overlay => {
            let mut c = chart(heading(&format!("cumulative {short}")));
            for (vi, (v, cs)) in exp.variations.iter().zip(&curves).enumerate() {
                for (i, cur) in cs {
                    let label = format!("{}, {}", exp.methods[*i].label, v.label);
                    c.series.push(styled(series(*i, cur, label), vi));
                }
            }
            Figure::single(c, 1000, 650)
        }
        Layout::Panels => {
            // a grid of panels without legends and one legend of the methods below them
            let n = exp.variations.len().max(1);
            let cols = n.min(3);
            let rows = n.div_ceil(cols);
            let (pw, ph, legend_h) = (560u32, 430u32, 70u32);
            let height = ph * rows as u32 + legend_h;
            let grid = f64::from(ph * rows as u32) / f64::from(height);
            let mut panels: Vec<(Panel, [f64; 4])> = exp
                .variations
                .iter()
                .zip(&curves)
                .enumerate()
                .map(|(k, (v, cs))| {
                    let mut c = chart(heading(&format!("{}: cumulative {short}", v.label)));
                    c.legend = None;
                    for (i, cur) in cs {
                        c.series
                            .push(series(*i, cur, exp.methods[*i].label.clone()));
                    }
                    let (col, row) = ((k % cols) as f64, (k / cols) as f64);
                    let (fw, fh) = (1.0 / cols as f64, grid / rows as f64);
                    (Panel::Chart(c), [col * fw, row * fh, fw, fh])
                })
                .collect();
            let mut legend = chart(String::new());
            for (i, m) in exp.methods.iter().enumerate() {
                legend.series.push(Series::line(
                    m.label.clone(),
                    Vec::new(),
                    PALETTE[i % PALETTE.len()],
                ));
            }
            panels.push((Panel::Legend(legend), [0.0, grid, 1.0, 1.0 - grid]));
            Figure {
                width: pw * cols as u32,
                height,
                panels,
            }
        }
    }
}

/// The box plot of one metric: a panel per variation, a box per method (failed runs left
/// out), one legend below.
pub fn grouped_box_figure(
    exp: &Experiment,
    per_variation: &[Vec<RunRecord>],
    metric: Metric,
) -> Figure {
    let short = if metric == Metric::ES {
        "e'_s"
    } else {
        metric.name()
    };
    let n = exp.variations.len().max(1);
    let cols = n.min(3);
    let rows = n.div_ceil(cols);
    let (pw, ph) = (560u32, 430u32);
    let panels = exp
        .variations
        .iter()
        .zip(per_variation)
        .enumerate()
        .map(|(k, (v, records))| {
            let groups: Vec<(String, Vec<f64>)> = exp
                .methods
                .iter()
                .map(|m| {
                    let vals = records
                        .iter()
                        .filter(|r| r.key.method == m.name)
                        .map(|r| metric.of(r))
                        .collect();
                    (m.label.clone(), vals)
                })
                .collect();
            let title = if exp.title.is_empty() {
                format!("{}: {short}", v.label)
            } else {
                format!("{}: {}: {short}", exp.title, v.label)
            };
            let c = crate::boxplot::box_chart(&title, metric, &groups);
            let (col, row) = ((k % cols) as f64, (k / cols) as f64);
            let (fw, fh) = (1.0 / cols as f64, 1.0 / rows as f64);
            (Panel::Chart(c), [col * fw, row * fh, fw, fh])
        })
        .collect();
    Figure {
        width: pw * cols as u32,
        height: ph * rows as u32,
        panels,
    }
}

impl ExperimentReport {
    /// The report as text (`monovo eval-batch --manifest`).
    pub fn text(&self) -> String {
        let mut s = format!(
            "evaluated {} runs in {:.2} s\n",
            self.runs_evaluated, self.seconds
        );
        let w = self
            .groups
            .iter()
            .map(|g| g.variation.len())
            .max()
            .unwrap_or(0)
            .max(9);
        let m = self
            .groups
            .iter()
            .map(|g| g.method.len())
            .max()
            .unwrap_or(0)
            .max(6);
        let _ = write!(
            s,
            "  {:<w$}  {:<m$}  {:>5}  {:>6}",
            "variation", "method", "runs", "failed"
        );
        for name in &self.metrics {
            let name = if *name == "e_s" { "e'_s" } else { name };
            let _ = write!(s, "  {:>14}", format!("median {name}"));
        }
        s.push('\n');
        for g in &self.groups {
            let _ = write!(
                s,
                "  {:<w$}  {:<m$}  {:>5}  {:>6}",
                g.variation, g.method, g.runs, g.failed
            );
            for v in &g.medians {
                let _ = write!(s, "  {:>14}", fmt_median(*v));
            }
            s.push('\n');
        }
        let _ = writeln!(s, "wrote {}:", self.output.display());
        for p in self.figures.iter().chain(&self.tables) {
            let _ = writeln!(s, "  {}", p.display());
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Experiment> {
        Experiment::parse(text, Path::new("exp.toml"), Path::new("base"))
    }

    #[test]
    fn a_manifest_resolves_paths_and_defaults() {
        let e = parse(
            "dataset = \"d\"\nresults = \"r\"\n[[method]]\nname = \"a\"\n[[variation]]\nname = \"fwd\"\ndirection = \"fwd\"\n[[variation]]\nname = \"other\"\nresults = \"r2\"\n",
        )
        .unwrap();
        assert_eq!(e.metrics, [Metric::EAlign, Metric::ER, Metric::ES]);
        assert_eq!(e.layout, Layout::Panels);
        assert_eq!(e.variations[0].results, Path::new("base/r"));
        assert_eq!(e.variations[0].direction, DirectionChoice::Fwd);
        assert_eq!(e.variations[1].results, Path::new("base/r2"));
        assert_eq!(e.variations[1].line, 8);
        assert_eq!(e.methods[0].label, "a");
    }

    #[test]
    fn bad_manifests_name_the_file_and_line() {
        let e = parse("dataset = \"d\"\nresults = \"r\"\n[[method]]\nname = \"a\"\nlabl = \"x\"\n")
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("exp.toml: line 5:") && e.contains("labl"),
            "{e}"
        );
        let e = parse("dataset = \"d\"\nresults = \"r\"\nmetrics = [\"e_align\", \"e_q\"]\n[[method]]\nname = \"a\"\n")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("line 3") && e.contains("e_q") && e.contains("e_align"),
            "{e}"
        );
        let e = parse("dataset = \"d\"\n[[method]]\nname = \"a\"\n[[variation]]\nname = \"v\"\ndirection = \"up\"\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 6") && e.contains("fwd"), "{e}");
        let e = parse("dataset = \"d\"\nresults = \"r\"\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("[[method]]"), "{e}");
        let e = parse("results = \"r\"\n[[method]]\nname = \"a\"\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("dataset"), "{e}");
        // the other metrics need their table, whose options are checked
        let e = parse("dataset = \"d\"\nresults = \"r\"\nmetrics = [\"rpe_rmse\"]\n[[method]]\nname = \"a\"\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("[rpe]"), "{e}");
        let e = parse(
            "dataset = \"d\"\nresults = \"r\"\n[[method]]\nname = \"a\"\n[ape]\nalign = \"sim4\"\n",
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("line 5") && e.contains("sim4") && e.contains("sim3"),
            "{e}"
        );
        let e = parse("dataset = \"d\"\nresults = \"r\"\n[[method]]\nname = \"a\"\n[kitti]\naling = \"se3\"\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("aling"), "{e}");
    }
}
