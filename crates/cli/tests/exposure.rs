//! `monovo exposure check` and `monovo exposure estimate` end to end, on synthetic
//! sequences with auto exposure and injected log shifts.
use std::path::Path;

use crate::common::{monovo, stderr, stdout, temp_dir};

fn synth(dir: &Path, extra: &[&str]) {
    let mut args = vec![
        "synth",
        "sequence",
        "-o",
        dir.to_str().unwrap(),
        "--size",
        "320x240",
        "--frames",
        "80",
        "--exposure",
        "auto",
        "--length",
        "3.2",
    ];
    args.extend_from_slice(extra);
    let o = monovo(&args);
    assert!(o.status.success(), "{}", stderr(&o));
}

/// The first column of every line that is not a comment.
fn first_column(path: &Path) -> Vec<usize> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .map(|l| l.split_whitespace().next().unwrap().parse().unwrap())
        .collect()
}

fn exposures(path: &Path) -> Vec<f64> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .map(|l| l.split_whitespace().nth(2).unwrap().parse().unwrap())
        .collect()
}

#[test]
fn check_finds_the_shifts_fixes_and_plots() {
    let d = temp_dir("exposure_check");
    let seq = d.join("seq");
    synth(&seq, &["--shift-exposures", "5", "--seed", "3"]);
    let truth = first_column(&seq.join("truth_shifts.txt"));
    assert_eq!(truth.len(), 5);
    let fixed = d.join("times_fixed.txt");
    let plot = d.join("check.png");
    let o = monovo(&[
        "exposure",
        "check",
        seq.to_str().unwrap(),
        "--json",
        "--fix",
        "-o",
        fixed.to_str().unwrap(),
        "--plot",
        plot.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    let shifted: Vec<usize> = v["shifted"]
        .as_array()
        .unwrap()
        .iter()
        .map(|k| k.as_u64().unwrap() as usize)
        .collect();
    let missed = truth.iter().filter(|k| !shifted.contains(k)).count();
    let false_alarms = shifted.iter().filter(|k| !truth.contains(k)).count();
    assert!(
        missed <= 1 && false_alarms <= 1,
        "truth {truth:?}, flagged {shifted:?}"
    );
    let ratios = v["ratios"].as_array().unwrap();
    assert_eq!(ratios.len(), 79);
    for (i, r) in ratios.iter().enumerate() {
        assert_eq!(r["frame"].as_u64().unwrap() as usize, i);
        assert!(r["logged"].as_f64().unwrap() > 0.0);
        if r["reliable"].as_bool().unwrap() {
            assert!(r["measured"].as_f64().unwrap() > 0.0);
            assert!(r["std_error"].as_f64().unwrap() < 0.01);
        }
    }
    // the fix: flagged lines replaced (close to the truth), every other line as it was
    let original = std::fs::read_to_string(seq.join("times.txt")).unwrap();
    let new = std::fs::read_to_string(&fixed).unwrap();
    let true_t = exposures(&seq.join("truth_times.txt"));
    for (k, (a, b)) in original.lines().zip(new.lines()).enumerate() {
        if shifted.contains(&k) {
            assert_ne!(a, b);
            let t: f64 = b.split_whitespace().nth(2).unwrap().parse().unwrap();
            assert!(
                (t / true_t[k] - 1.0).abs() < 0.01,
                "frame {k}: {t} vs {}",
                true_t[k]
            );
            assert_eq!(
                a.split_whitespace().take(2).collect::<Vec<_>>(),
                b.split_whitespace().take(2).collect::<Vec<_>>()
            );
        } else {
            assert_eq!(a, b);
        }
    }
    crate::figures::check_png(&plot, 1400, 900);
    // the fixed log passes the check
    let fixed_seq = d.join("fixed_seq");
    std::fs::create_dir_all(&fixed_seq).unwrap();
    for f in ["images.zip", "pcalib.txt", "vignette.png", "camera.txt"] {
        std::fs::copy(seq.join(f), fixed_seq.join(f)).unwrap();
    }
    std::fs::copy(&fixed, fixed_seq.join("times.txt")).unwrap();
    let o = monovo(&["exposure", "check", fixed_seq.to_str().unwrap(), "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    assert_eq!(
        v["shifted"].as_array().unwrap().len(),
        0,
        "{}",
        v["shifted"]
    );
    // an existing output is refused before any work, replaced with --force
    let again = |force: bool| {
        let mut args = vec![
            "exposure",
            "check",
            seq.to_str().unwrap(),
            "--fix",
            "-o",
            fixed.to_str().unwrap(),
        ];
        if force {
            args.push("--force");
        }
        monovo(&args)
    };
    let o = again(false);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("times_fixed.txt"), "{}", stderr(&o));
    let o = again(true);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stdout(&o).contains("belong to a neighbouring frame"),
        "{}",
        stdout(&o)
    );
    // --fix needs -o
    let o = monovo(&["exposure", "check", seq.to_str().unwrap(), "--fix"]);
    assert!(!o.status.success());
}

#[test]
fn estimate_without_logged_exposures_and_clear_errors() {
    let d = temp_dir("exposure_estimate");
    let seq = d.join("seq");
    synth(&seq, &["--no-exposures", "--seed", "4"]);
    // check needs logged exposures and says which command measures them
    let o = monovo(&["exposure", "check", seq.to_str().unwrap()]);
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(
        e.contains("times.txt: line 1") && e.contains("monovo exposure estimate"),
        "{e}"
    );
    let out = d.join("times.txt");
    let plot = d.join("estimate.svg");
    let o = monovo(&[
        "exposure",
        "estimate",
        seq.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--reference-ms",
        "8",
        "--plot",
        plot.to_str().unwrap(),
        "--json",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    assert_eq!(v["frames"], 80);
    // three columns, the ids and timestamps of the sequence, median 8 ms
    let text = std::fs::read_to_string(&out).unwrap();
    let truth_text = std::fs::read_to_string(seq.join("truth_times.txt")).unwrap();
    for (a, b) in text.lines().zip(truth_text.lines()) {
        let (a, b): (Vec<&str>, Vec<&str>) = (
            a.split_whitespace().collect(),
            b.split_whitespace().collect(),
        );
        assert_eq!(a.len(), 3);
        assert_eq!(a[..2], b[..2]);
    }
    let est = exposures(&out);
    let truth = exposures(&seq.join("truth_times.txt"));
    let mut sorted = est.clone();
    sorted.sort_by(f64::total_cmp);
    // the median of the log exposures: the geometric mean of the middle two
    assert!(
        ((sorted[39] * sorted[40]).sqrt() - 8.0).abs() < 1e-6,
        "{sorted:?}"
    );
    // within 1% after the global scale (the median), the path's cuts included
    let mut d_log: Vec<f64> = est.iter().zip(&truth).map(|(e, t)| (e / t).ln()).collect();
    let mut s = d_log.clone();
    s.sort_by(f64::total_cmp);
    let offset = s[40];
    for x in &mut d_log {
        *x = (*x - offset).abs();
    }
    d_log.sort_by(f64::total_cmp);
    assert!(d_log[40] < 0.01, "median error {}", d_log[40]);
    // the standard errors beside it: `id std_ms std_rel`
    let std_text = std::fs::read_to_string(d.join("times_std.txt")).unwrap();
    assert_eq!(std_text.lines().count(), 80);
    for l in std_text.lines() {
        let f: Vec<&str> = l.split_whitespace().collect();
        assert_eq!(f.len(), 3);
        assert!(f[1].parse::<f64>().unwrap() >= 0.0 && f[2].parse::<f64>().unwrap() >= 0.0);
    }
    crate::figures::check_svg(
        &plot,
        1400,
        600,
        &["estimated exposure times", "exposure (ms)"],
    );
    // outputs are refused when they exist
    let o = monovo(&[
        "exposure",
        "estimate",
        seq.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    // without pcalib.txt: a clear error
    std::fs::remove_file(seq.join("pcalib.txt")).unwrap();
    let o = monovo(&[
        "exposure",
        "estimate",
        seq.to_str().unwrap(),
        "-o",
        d.join("other.txt").to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("pcalib"), "{}", stderr(&o));
    // a bad --reference-ms
    let o = monovo(&[
        "exposure",
        "estimate",
        seq.to_str().unwrap(),
        "-o",
        d.join("other.txt").to_str().unwrap(),
        "--reference-ms=-3",
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("--reference-ms"), "{}", stderr(&o));
}
