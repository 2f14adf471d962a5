//! Developer tasks of the monovo workspace: `cargo xtask bench-synthetic [--quick] [--json FILE]
//! [--report FILE]`, `cargo xtask fuzz [--cases N] [--quick] [--target NAME]`, `cargo xtask
//! house`, `cargo xtask response-study` and `cargo xtask exposure-study`.
//!
//! bench-synthetic runs every stage on synthetic data with known truth, prints accuracy
//! against the truth and throughput / wall time / peak memory per stage, and fails when a
//! figure is worse than the thresholds committed in `xtask/thresholds.json`. fuzz feeds every
//! parser arbitrary and mutated bytes and fails on a panic (see `fuzz/`). house keeps the code
//! readable: file and function lengths, no import circles (see `house.rs`).
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod brackets;
mod exposure;
mod fuzz;
mod house;
mod report;
mod response;
mod seeds;
mod stages;
mod vignette;

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{bail, Context, Result};

/// One measured figure of a stage.
pub struct Figure {
    /// `stage.name`, the key in thresholds.json.
    pub key: String,
    /// The measured value.
    pub value: f64,
    /// Unit for display.
    pub unit: &'static str,
    /// Whether smaller is better (errors, times, memory) or larger (throughput).
    pub lower_is_better: bool,
}

impl Figure {
    /// A figure where smaller is better.
    pub fn lower(key: &str, value: f64, unit: &'static str) -> Figure {
        Figure {
            key: key.into(),
            value,
            unit,
            lower_is_better: true,
        }
    }
}

/// Runs every stage of bench-synthetic, or the one `only` names.
fn run_stages(quick: bool, only: Option<&str>) -> Result<Vec<Figure>> {
    type Stage = fn(bool) -> Result<Vec<Figure>>;
    let stages: [(&str, Stage); 8] = [
        ("camera", stages::camera),
        ("eval", stages::eval),
        ("rectify", stages::rectify),
        ("response", response::stage),
        ("seeds", seeds::stage),
        ("brackets", brackets::stage),
        ("vignette", vignette::stage),
        ("demo", stages::demo),
    ];
    if let Some(o) = only {
        if !stages.iter().any(|(n, _)| *n == o) {
            bail!("unknown stage `{o}`");
        }
    }
    let mut figures = Vec::new();
    for (name, stage) in stages {
        if only.is_none_or(|o| o == name) {
            figures.extend(stage(quick)?);
        }
    }
    Ok(figures)
}

/// Whether a figure keeps its threshold; a figure without one fails: every figure the stages
/// report is checked.
pub fn within(f: &Figure, limit: Option<f64>) -> bool {
    match limit {
        Some(l) if f.lower_is_better => f.value <= l,
        Some(l) => f.value >= l,
        None => false,
    }
}

/// A figure's value for display: 4 decimals, or 3 significant digits when tiny.
pub fn shown(value: f64) -> String {
    if value != 0.0 && value.abs() < 1e-3 {
        format!("{value:.3e}")
    } else {
        format!("{value:.4}")
    }
}

fn usage() -> &'static str {
    "usage: cargo xtask bench-synthetic [--quick] [--only STAGE] [--json FILE] [--report FILE]\n       \
     cargo xtask fuzz [--cases N] [--quick] [--seed S] [--target NAME] (see fuzz --help)\n       \
     cargo xtask house\n\n\
     bench-synthetic runs every stage on synthetic data (and the real exposure brackets of\n\
     tests/fixtures/brackets against the peers' scores), prints accuracy, speed and memory, and\n\
     fails when a figure is worse than xtask/thresholds.json. --quick is the CI variant\n\
     (smaller data, no demo stage); --only runs one stage: camera, eval, rectify, response,\n\
     seeds, brackets, vignette or demo (monovo demo from start to end). --report docs/performance.md writes\n\
     the performance page from the run (machine, date, ratios, every figure).\n\
     fuzz feeds every parser arbitrary and mutated bytes and fails on a panic.\n\
     house fails on a source file over 1500 lines, a function over 150 lines or an import\n\
     circle between the modules of a crate, naming file:line."
}

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("xtask: error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn run() -> Result<()> {
    let mut args = std::env::args().skip(1);
    let Some(task) = args.next() else {
        println!("{}", usage());
        return Ok(());
    };
    if task == "response-study" {
        return response::study();
    }
    if task == "exposure-study" {
        return exposure::study(args);
    }
    if task == "fuzz" {
        return fuzz::run(args);
    }
    if task == "house" {
        return house::run();
    }
    if task != "bench-synthetic" {
        bail!("unknown task `{task}`\n{}", usage());
    }
    let mut quick = false;
    let mut only: Option<String> = None;
    let mut json: Option<PathBuf> = None;
    let mut report: Option<PathBuf> = None;
    while let Some(a) = args.next() {
        match a.as_str() {
            "--quick" => quick = true,
            "--only" => only = Some(args.next().context("--only needs a stage name")?),
            "--json" => json = Some(args.next().context("--json needs a file")?.into()),
            "--report" => report = Some(args.next().context("--report needs a file")?.into()),
            "-h" | "--help" => {
                println!("{}", usage());
                return Ok(());
            }
            other => bail!("unknown argument `{other}`\n{}", usage()),
        }
    }
    let thresholds_path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("thresholds.json");
    let thresholds: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(&thresholds_path)
            .with_context(|| format!("reading {}", thresholds_path.display()))?,
    )
    .with_context(|| format!("parsing {}", thresholds_path.display()))?;
    let mode = if quick { "quick" } else { "full" };
    let figures = run_stages(quick, only.as_deref())?;
    println!(
        "\n{:<44} {:>14} {:>14}  status",
        "figure", "value", "threshold"
    );
    let mut failed = Vec::new();
    let mut out = serde_json::Map::new();
    for f in &figures {
        let limit = thresholds
            .get(mode)
            .and_then(|m| m.get(&f.key))
            .and_then(|v| v.as_f64());
        let ok = within(f, limit);
        if !ok {
            failed.push(f.key.clone());
        }
        let lim = limit.map_or("(none)".to_string(), |l| format!("{l}"));
        println!(
            "{:<44} {:>10} {:<3} {:>14}  {}",
            f.key,
            shown(f.value),
            f.unit,
            lim,
            if ok { "ok" } else { "WORSE" }
        );
        out.insert(
            f.key.clone(),
            serde_json::json!({"value": f.value, "unit": f.unit, "threshold": limit}),
        );
    }
    if let Some(path) = json {
        std::fs::write(&path, serde_json::to_string_pretty(&out)?)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    if let Some(path) = report {
        report::write(&path, mode, &figures, &thresholds)?;
    }
    if !failed.is_empty() {
        bail!(
            "{} figure(s) worse than their threshold: {}",
            failed.len(),
            failed.join(", ")
        );
    }
    Ok(())
}
