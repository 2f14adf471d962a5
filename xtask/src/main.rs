//! Developer tasks of the monovo workspace: `cargo xtask bench-synthetic [--quick] [--json FILE]`,
//! `cargo xtask fuzz [--cases N] [--quick] [--target NAME]`, `cargo xtask response-study` and
//! `cargo xtask exposure-study`.
//!
//! bench-synthetic runs every stage on synthetic data with known truth, prints accuracy
//! against the truth and throughput / wall time / peak memory per stage, and fails when a
//! figure is worse than the thresholds committed in `xtask/thresholds.json`. fuzz feeds every
//! parser arbitrary and mutated bytes and fails on a panic (see `fuzz.rs`).
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod exposure;
mod fuzz;
mod response;
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

fn usage() -> &'static str {
    "usage: cargo xtask bench-synthetic [--quick] [--only STAGE] [--json FILE]\n       \
     cargo xtask fuzz [--cases N] [--quick] [--seed S] [--target NAME] (see fuzz --help)\n\n\
     bench-synthetic runs every stage on synthetic data, prints accuracy, speed and memory, and\n\
     fails when a figure is worse than xtask/thresholds.json. --quick is the CI variant\n\
     (smaller data, no demo stage); --only runs one stage: camera, eval, rectify, response,\n\
     vignette or demo (monovo demo from start to end).\n\
     fuzz feeds every parser arbitrary and mutated bytes and fails on a panic."
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
    if task != "bench-synthetic" {
        bail!("unknown task `{task}`\n{}", usage());
    }
    let mut quick = false;
    let mut only: Option<String> = None;
    let mut json: Option<PathBuf> = None;
    while let Some(a) = args.next() {
        match a.as_str() {
            "--quick" => quick = true,
            "--only" => only = Some(args.next().context("--only needs a stage name")?),
            "--json" => json = Some(args.next().context("--json needs a file")?.into()),
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
    let figures = stages::run_all(quick, only.as_deref())?;
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
        // a figure without a threshold fails: every figure the stages report is checked
        let ok = match limit {
            Some(l) if f.lower_is_better => f.value <= l,
            Some(l) => f.value >= l,
            None => false,
        };
        if !ok {
            failed.push(f.key.clone());
        }
        let lim = limit.map_or("(none)".to_string(), |l| format!("{l}"));
        let shown = if f.value != 0.0 && f.value.abs() < 1e-3 {
            format!("{:.3e}", f.value)
        } else {
            format!("{:.4}", f.value)
        };
        println!(
            "{:<44} {:>10} {:<3} {:>14}  {}",
            f.key,
            shown,
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
    if !failed.is_empty() {
        bail!(
            "{} figure(s) worse than their threshold: {}",
            failed.len(),
            failed.join(", ")
        );
    }
    Ok(())
}
