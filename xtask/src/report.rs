//! `bench-synthetic --report FILE`: the performance page (docs/performance.md) written from
//! one run, with the machine, the date and every figure of that run, so that the guide
//! quotes measurements, not a diary.

use std::fmt::Write as _;
use std::path::Path;

use anyhow::{Context, Result};

use crate::Figure;

/// The ratios the page leads with: throughputs of whole jobs against decoding alone, measured
/// in alternating rounds of the same run (key, what it compares).
const HEADLINE: [(&str, &str); 6] = [
    (
        "rectify.written_over_decode_ratio",
        "`monovo rectify` (zip read, decode, remap, PNG, write) against decoding the frames alone, 2 threads",
    ),
    (
        "rectify.written_stored_over_decode_ratio",
        "the same with `--compression none` (stored PNG)",
    ),
    (
        "rectify.written_half_decode_over_decode_ratio",
        "the same with `--half-decode` (turbojpeg builds) against decoding the full frames",
    ),
    (
        "rectify.full_over_decode_ratio_1thread",
        "decode + rectify + photometric correction against decode alone, 1 thread",
    ),
    (
        "rectify.geometric_over_decode_ratio_1thread",
        "decode + rectify against decode alone, 1 thread",
    ),
    (
        "rectify.png_encode_over_decode",
        "PNG encoding of a 640x480 frame against decoding a 1280x1024 JPEG (lower is better)",
    ),
];

/// Writes the page to `path` (whole or not at all: a temporary file renamed).
pub fn write(
    path: &Path,
    mode: &str,
    figures: &[Figure],
    thresholds: &serde_json::Value,
) -> Result<()> {
    let page = render(mode, figures, thresholds);
    let tmp = path.with_extension("md.tmp");
    std::fs::write(&tmp, page).with_context(|| format!("writing {}", tmp.display()))?;
    std::fs::rename(&tmp, path).with_context(|| format!("writing {}", path.display()))?;
    println!("report: {}", path.display());
    Ok(())
}

fn render(mode: &str, figures: &[Figure], thresholds: &serde_json::Value) -> String {
    let mut s = String::new();
    let command = if mode == "quick" {
        "cargo xtask bench-synthetic --quick --report docs/performance.md"
    } else {
        "cargo xtask bench-synthetic --report docs/performance.md"
    };
    let _ = writeln!(
        s,
        "# Performance\n\n\
         Written by `{command}` from one run; do not edit by hand, run it again. Every figure \
         is measured on synthetic data with known truth (see [architecture.md](architecture.md)); \
         speed is given as ratios measured in alternating rounds of the same run where it \
         can be, because a shared machine's absolute speed varies from hour to hour.\n"
    );
    let _ = writeln!(s, "| | |\n|---|---|");
    for (k, v) in machine(mode) {
        let _ = writeln!(s, "| {k} | {v} |");
    }
    let _ = writeln!(s, "\n## Ratios measured in this run\n");
    let _ = writeln!(s, "| ratio | what | value |\n|---|---|---:|");
    for (key, what) in HEADLINE {
        if let Some(f) = figures.iter().find(|f| f.key == key) {
            let _ = writeln!(s, "| `{key}` | {what} | {:.2} |", f.value);
        }
    }
    let _ = writeln!(
        s,
        "\nAgainst the peers, measured side by side on the same machine with the scripts that \
         say how: the authors' `playDataset` and `vignetteCalib` \
         ([reference-tools.md](reference-tools.md)), OpenCV's Debevec and Robertson response \
         calibrations ([response-peers.md](response-peers.md)), evo and the TUM RGB-D scripts \
         ([evaluation-metrics.md](evaluation-metrics.md#speed)), evo's Python API \
         ([python.md](python.md#speed)).\n"
    );
    let _ = writeln!(s, "## Every figure of the run\n");
    let _ = writeln!(
        s,
        "Each figure against its threshold in `xtask/thresholds.json` ({mode} mode); `WORSE` \
         fails the run.\n"
    );
    let _ = writeln!(
        s,
        "| figure | value | unit | threshold | status |\n|---|---:|---|---:|---|"
    );
    for f in figures {
        let limit = thresholds
            .get(mode)
            .and_then(|m| m.get(&f.key))
            .and_then(|v| v.as_f64());
        let ok = crate::within(f, limit);
        let lim = limit.map_or("(none)".to_string(), |l| format!("{l}"));
        let _ = writeln!(
            s,
            "| `{}` | {} | {} | {lim} | {} |",
            f.key,
            crate::shown(f.value),
            f.unit,
            if ok { "ok" } else { "WORSE" }
        );
    }
    s
}

/// The machine and the run: date, CPU, cores, memory, OS, build.
fn machine(mode: &str) -> Vec<(&'static str, String)> {
    let cpuinfo = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
    let cpu = cpuinfo
        .lines()
        .find(|l| l.starts_with("model name"))
        .and_then(|l| l.split(':').nth(1))
        .map_or("unknown".to_string(), |m| m.trim().to_string());
    let cores = std::thread::available_parallelism().map_or(0, |n| n.get());
    let mem_gb = std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|m| {
            m.lines()
                .find(|l| l.starts_with("MemTotal:"))
                .and_then(|l| l.split_whitespace().nth(1))
                .and_then(|v| v.parse::<f64>().ok())
        })
        .map_or("unknown".to_string(), |kb| {
            format!("{:.1} GB", kb / 1048576.0)
        });
    let os = std::fs::read_to_string("/proc/sys/kernel/osrelease")
        .map_or(std::env::consts::OS.to_string(), |r| {
            format!("{} {}", std::env::consts::OS, r.trim())
        });
    let avx2 = if camera_model::avx2_enabled() {
        "AVX2 kernels in use"
    } else {
        "portable kernels (no AVX2, or MONOVO_NO_AVX2)"
    };
    vec![
        ("date (UTC)", today()),
        ("mode", mode_text(mode)),
        ("CPU", format!("{cpu}; {avx2}")),
        ("cores the run could use", cores.to_string()),
        ("memory", mem_gb),
        ("OS", os),
        ("JPEG decoder", dataset_io::JPEG_DECODER.to_string()),
        ("commit", commit()),
    ]
}

fn mode_text(mode: &str) -> String {
    if mode == "quick" {
        "quick (`--quick`: the CI's smaller data; the full mode's figures differ, the ratios \
         less than the times)"
            .into()
    } else {
        "full".into()
    }
}

/// The commit the run was built from, `+ changes` when the work tree differs from it.
fn commit() -> String {
    let git = |args: &[&str]| {
        std::process::Command::new("git")
            .args(args)
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .output()
            .ok()
            .filter(|o| o.status.success())
            .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
    };
    match git(&["rev-parse", "--short", "HEAD"]) {
        Some(c) if git(&["status", "--porcelain"]).is_some_and(|s| !s.is_empty()) => {
            format!("{c} + changes")
        }
        Some(c) => c,
        None => "unknown".into(),
    }
}

/// Today's date in UTC, `YYYY-MM-DD` (the civil calendar from days since 1970).
fn today() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let (y, m, d) = civil_from_days((secs / 86400) as i64);
    format!("{y:04}-{m:02}-{d:02}")
}

/// Year, month, day of `z` days after 1970-01-01 (proleptic Gregorian calendar).
fn civil_from_days(z: i64) -> (i64, u32, u32) {
    let z = z + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    (yoe + era * 400 + i64::from(m <= 2), m, d)
}

#[cfg(test)]
mod tests {
    use super::civil_from_days;

    #[test]
    fn calendar() {
        assert_eq!(civil_from_days(0), (1970, 1, 1));
        assert_eq!(civil_from_days(11_016), (2000, 2, 29));
        assert_eq!(civil_from_days(20_454), (2026, 1, 1));
    }
}
