//! `monovo experiment` (and `eval-batch --manifest`) end to end on synthetic results: the
//! repository's example manifest, a manifest whose variation is another results folder, and
//! bad manifests.
use std::path::Path;

use crate::common::{monovo, repo_file, stderr, stdout, temp_dir};
use crate::figures::check_png;

fn synth_results(dir: &Path, name: &str, seed: &str) {
    let out = dir.join(name);
    let o = monovo(&[
        "synth",
        "results",
        "-o",
        out.to_str().unwrap(),
        "--sequences",
        "4",
        "--runs",
        "2",
        "--frames",
        "400",
        "--seed",
        seed,
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
}

#[test]
fn the_example_manifest_draws_grouped_plots_and_tables() {
    let dir = temp_dir("experiment_example");
    synth_results(&dir, "synth", "1");
    let out = dir.join("experiment");
    let o = monovo(&[
        "experiment",
        &repo_file("data/experiment.toml"),
        "--base",
        dir.join("synth").to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--json",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert_eq!(v["runs_evaluated"], 32, "{v}");
    let groups: Vec<(String, String, u64)> = v["groups"]
        .as_array()
        .unwrap()
        .iter()
        .map(|g| {
            (
                g["variation"].as_str().unwrap().to_string(),
                g["method"].as_str().unwrap().to_string(),
                g["runs"].as_u64().unwrap(),
            )
        })
        .collect();
    let want: Vec<(String, String, u64)> = [
        ("forward", "direct"),
        ("forward", "feature"),
        ("backward", "direct"),
        ("backward", "feature"),
    ]
    .iter()
    .map(|(a, b)| (a.to_string(), b.to_string(), 8))
    .collect();
    assert_eq!(groups, want);
    // one figure per metric: two panels of 560x430 side by side and the shared legend
    for m in ["e_align", "e_r", "e_s", "ape_rmse"] {
        check_png(&out.join(format!("cumulative_{m}.png")), 1120, 500);
        // and a box per method in a panel per variation
        check_png(&out.join(format!("box_{m}.png")), 1120, 430);
    }
    let md = std::fs::read_to_string(out.join("summary.md")).unwrap();
    assert!(md.contains("| forward | direct | 8 |"), "{md}");
    assert!(md.contains("| backward | feature | 8 |"), "{md}");
    let csv = std::fs::read_to_string(out.join("summary.csv")).unwrap();
    assert!(
        csv.starts_with(
            "variation,method,runs,failed,median_e_align,median_e_r,median_e_s,median_ape_rmse\n"
        ),
        "{csv}"
    );
    assert_eq!(csv.lines().count(), 5);
    let fwd = std::fs::read_to_string(out.join("results_forward.csv")).unwrap();
    assert_eq!(fwd.lines().count(), 17, "16 forwards runs and the header");
    assert!(fwd.lines().skip(1).all(|l| l.contains(",fwd,")));
    // the APE columns, Sim(3)-aligned over the segments: e_rmse is the same number
    let rows = eval_metrics::parse_csv(&fwd).unwrap();
    for r in rows.iter().filter(|r| r.is_ok()) {
        let ape = r.extra["ape_rmse"];
        assert!(
            (ape - r.metrics.e_rmse).abs() <= 1e-9 * ape,
            "{ape} {}",
            r.metrics.e_rmse
        );
    }
    // the same through eval-batch, refusing the existing folder without --force
    let o = monovo(&[
        "eval-batch",
        "--manifest",
        &repo_file("data/experiment.toml"),
        "--base",
        dir.join("synth").to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(
        !o.status.success() && stderr(&o).contains("already exists"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn a_variation_can_be_another_results_folder_drawn_as_line_styles() {
    let dir = temp_dir("experiment_folders");
    synth_results(&dir, "a", "1");
    synth_results(&dir, "b", "2");
    let manifest = dir.join("exp.toml");
    std::fs::write(
        &manifest,
        "title = \"two result sets\"\ndataset = \"a/dataset\"\nresults = \"a/results\"\nmetrics = [\"e_align\"]\nlayout = \"overlay\"\n\
         [[method]]\nname = \"direct\"\n[[method]]\nname = \"feature\"\n\
         [[variation]]\nname = \"seed1\"\n[[variation]]\nname = \"seed2\"\ndataset = \"b/dataset\"\nresults = \"b/results\"\nsequences = [\"sequence_01\", \"sequence_02\"]\n",
    )
    .unwrap();
    let out = dir.join("out");
    let o = monovo(&[
        "experiment",
        manifest.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = stdout(&o);
    assert!(text.contains("evaluated 64 runs"), "{text}");
    assert!(
        text.lines()
            .any(|l| l.split_whitespace().take(3).eq(["seed2", "feature", "8"])),
        "{text}"
    );
    check_png(&out.join("cumulative_e_align.png"), 1000, 650);
    assert!(!out.join("cumulative_e_r.png").exists());
}

#[test]
fn bad_manifests_name_the_file_line_and_what_was_expected() {
    let dir = temp_dir("experiment_bad");
    synth_results(&dir, "synth", "1");
    let cases: [(&str, &str); 4] = [
        ("dataset = \"synth/dataset\"\nresults = \"synth/results\"\n[[method]]\nname = \"direct\"\ncolour = \"red\"\n", "line 5: unknown field `colour`"),
        ("dataset = \"synth/dataset\"\nresults = \"synth/results\"\nmetrics = [\"e_align\", \"drift\"]\n[[method]]\nname = \"direct\"\n", "line 3: unknown variant `drift`"),
        ("dataset = \"synth/dataset\"\nresults = \"synth/results\"\n[[method]]\nname = \"direkt\"\n", "line 4: method `direkt`: no runs in any variation"),
        ("dataset = \"synth/dataset\"\nresults = \"synth/results\"\n[[method]]\nname = \"direct\"\n[[variation]]\nname = \"v\"\ndirection = \"sideways\"\n", "line 7: unknown variant `sideways`, expected one of `fwd`, `bwd`, `both`"),
    ];
    for (i, (text, want)) in cases.iter().enumerate() {
        let manifest = dir.join(format!("bad{i}.toml"));
        std::fs::write(&manifest, text).unwrap();
        let out = dir.join(format!("out{i}"));
        let o = monovo(&[
            "experiment",
            manifest.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
        ]);
        let e = stderr(&o);
        assert!(!o.status.success(), "{e}");
        assert!(e.contains(&format!("bad{i}.toml: {want}")), "{e}");
        assert!(!out.exists(), "no output for a bad manifest");
    }
}
