//! `monovo eval`, `monovo eval-batch`, `monovo plot`.
use crate::common::{monovo, stderr, stdout, temp_dir};
use std::path::Path;
use synthetic::trajectory::{
    benchmark_path, estimate, tum_text, Drift, EstimateConfig, PathConfig,
};

fn write(p: &Path, s: &str) {
    std::fs::create_dir_all(p.parent().unwrap()).unwrap();
    std::fs::write(p, s).unwrap();
}

/// DATASET with two sequences, RESULTS with two methods x fwd/bwd x 2 runs, plus strays.
fn fixture(dir: &Path) {
    for seq in 1..=2u64 {
        let path = benchmark_path(
            seq,
            &PathConfig {
                frames: 400,
                ..PathConfig::default()
            },
        );
        let name = format!("sequence_{seq:02}");
        write(
            &dir.join("data").join(&name).join("groundtruthSync.txt"),
            &path.ground_truth_sync(),
        );
        for (method, factor) in [("good", 0.97), ("bad", 0.6)] {
            for bwd in [false, true] {
                for run in 0..2u32 {
                    let cfg = EstimateConfig {
                        drift: Drift {
                            scale_jumps: vec![(200, factor)],
                            ..Drift::default()
                        },
                        backwards: bwd,
                        backwards_epoch_times: bwd && run == 1,
                        lost_after: (method == "bad" && run == 1 && !bwd).then_some(150),
                        ..EstimateConfig::default()
                    };
                    let text = tum_text(&estimate(&path, &cfg, seq * 10 + run as u64));
                    let file = format!("{}_{run}.txt", if bwd { "bwd" } else { "fwd" });
                    write(&dir.join("res").join(method).join(&name).join(file), &text);
                }
            }
        }
    }
    write(&dir.join("res/good/sequence_01/notes.txt"), "stray");
    write(
        &dir.join("res/good/sequence_09/fwd_0.txt"),
        "1 0 0 0 0 0 0 1\n",
    );
}

#[test]
fn eval_json_has_exactly_the_documented_keys() {
    let d = temp_dir("eval_json");
    fixture(&d);
    let gt = d.join("data/sequence_01/groundtruthSync.txt");
    let run = d.join("res/good/sequence_01/fwd_0.txt");
    let o = monovo(&[
        "eval",
        run.to_str().unwrap(),
        "--gt",
        gt.to_str().unwrap(),
        "--json",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    let mut keys: Vec<_> = v.as_object().unwrap().keys().cloned().collect();
    keys.sort();
    assert_eq!(
        keys,
        [
            "e_align",
            "e_r",
            "e_rmse",
            "e_s",
            "e_t",
            "poses",
            "poses_end",
            "poses_start",
            "reason",
            "rmse_end",
            "rmse_start",
            "status"
        ]
    );
    assert_eq!(v["status"], "ok");
    assert!((v["e_s"].as_f64().unwrap() - 0.97).abs() < 1e-9);
    assert_eq!(v["poses"], 400);

    // a failed run is a result: exit 0, status failed, null metrics
    let lost = d.join("res/bad/sequence_01/fwd_1.txt");
    let o = monovo(&[
        "eval",
        lost.to_str().unwrap(),
        "--gt",
        gt.to_str().unwrap(),
        "--json",
    ]);
    assert!(o.status.success());
    let v: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    assert_eq!(v["status"], "failed");
    assert!(v["e_align"].is_null());
    assert!(v["reason"].as_str().unwrap().contains("end segment"));
}

#[test]
fn eval_plot_and_bad_input() {
    let d = temp_dir("eval_plot");
    fixture(&d);
    let gt = d.join("data/sequence_02/groundtruthSync.txt");
    let run = d.join("res/bad/sequence_02/bwd_1.txt");
    let png = d.join("align.png");
    let o = monovo(&[
        "eval",
        run.to_str().unwrap(),
        "--gt",
        gt.to_str().unwrap(),
        "--plot",
        png.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stdout(&o).contains("2e9 - t"));
    crate::figures::check_png(&png, 1500, 560);
    let svg = d.join("align.svg");
    let o = monovo(&[
        "eval",
        run.to_str().unwrap(),
        "--gt",
        gt.to_str().unwrap(),
        "--plot",
        svg.to_str().unwrap(),
    ]);
    assert!(o.status.success());
    crate::figures::check_svg(
        &svg,
        1500,
        560,
        &[
            "top-down x (ground-truth length unit)",
            "top-down y (ground-truth length unit)",
            "start segment",
            "aligned to start",
        ],
    );
    // another extension is refused by name, and nothing is written
    let jpg = d.join("align.jpg");
    let o = monovo(&[
        "eval",
        run.to_str().unwrap(),
        "--gt",
        gt.to_str().unwrap(),
        "--plot",
        jpg.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains(".png or .svg"), "{}", stderr(&o));
    assert!(!jpg.exists());

    let bad = d.join("bad.txt");
    write(&bad, "1 2 3 4 5 6 7 8\n1 2 three 4 5 6 7 8\n");
    let o = monovo(&["eval", bad.to_str().unwrap(), "--gt", gt.to_str().unwrap()]);
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(e.contains("bad.txt") && e.contains("line 2"), "{e}");
    let o = monovo(&[
        "eval",
        bad.to_str().unwrap(),
        "--gt",
        d.join("none.txt").to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("none.txt"));
}

#[test]
fn batch_csv_table_and_cumulative_plots() {
    let d = temp_dir("eval_batch");
    fixture(&d);
    let csv = d.join("results.csv");
    let o = monovo(&[
        "eval-batch",
        "--dataset",
        d.join("data").to_str().unwrap(),
        "--results",
        d.join("res").to_str().unwrap(),
        "-o",
        csv.to_str().unwrap(),
        "--json",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    assert_eq!(v["runs"], 16);
    assert_eq!(v["failed"], 2);
    assert_eq!(v["stray"].as_array().unwrap().len(), 2);
    assert!(stderr(&o).contains("notes.txt") && stderr(&o).contains("sequence_09"));
    let text = std::fs::read_to_string(&csv).unwrap();
    assert_eq!(text.lines().count(), 17);
    assert!(text.starts_with("method,sequence,direction,run,status,e_align,e_s,e_r,e_t,e_rmse,rmse_start,rmse_end,poses,reason\n"));

    for (metric, split, file) in [
        ("e_align", None, "a.png"),
        ("e_s", Some("direction"), "s.svg"),
        ("e_r", None, "r.png"),
    ] {
        let out = d.join(file);
        let mut args = vec![
            "plot",
            "cumulative",
            csv.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
            "--metric",
            metric,
        ];
        if let Some(s) = split {
            args.extend(["--split", s]);
        }
        let o = monovo(&args);
        assert!(o.status.success(), "{}", stderr(&o));
        if file.ends_with(".png") {
            crate::figures::check_png(&out, 900, 600);
        } else {
            crate::figures::check_svg(
                &out,
                900,
                600,
                &[
                    "number of runs",
                    "scale drift e'_s = max(e_s, 1/e_s) (multiplier)",
                    // e'_s from 1 upwards: the first tick is 1
                    "1",
                ],
            );
        }
    }
    let o = monovo(&["plot", "table", csv.to_str().unwrap()]);
    assert!(o.status.success());
    let t = stdout(&o);
    // aligned text for a terminal: a caption with the units, a header, one row per sequence
    // and method, e'_s as the paper summarises it
    assert!(!t.contains('|') && !t.contains("<br>"), "{t}");
    assert!(
        t.contains("e_r (deg)") && t.contains("e'_s = max(e_s, 1/e_s)"),
        "{t}"
    );
    assert_eq!(t.lines().count(), 3 + 1 + 1 + 4, "{t}");
    let o = monovo(&["plot", "table", csv.to_str().unwrap(), "--json"]);
    let v: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    assert_eq!(v["rows"].as_array().unwrap().len(), 4, "{v}");
    assert!(
        v["rows"][0]["e_s_prime"]["min"].as_f64().unwrap() >= 1.0,
        "{v}"
    );
    // the same batch with 1 and with 2 threads: bit-identical results.csv
    let mut csvs = Vec::new();
    for threads in ["1", "2"] {
        let out = d.join(format!("threads{threads}.csv"));
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_monovo"))
            .env("RAYON_NUM_THREADS", threads)
            .args([
                "eval-batch",
                "--dataset",
                d.join("data").to_str().unwrap(),
                "--results",
                d.join("res").to_str().unwrap(),
                "-o",
                out.to_str().unwrap(),
            ])
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", stderr(&o));
        csvs.push(std::fs::read(&out).unwrap());
    }
    assert_eq!(
        csvs[0], csvs[1],
        "results.csv differs between 1 and 2 threads"
    );

    // a malformed run stops the batch with the file and line, unless --keep-going
    write(&d.join("res/good/sequence_02/fwd_7.txt"), "1 2 3\n");
    let o = monovo(&[
        "eval-batch",
        "--dataset",
        d.join("data").to_str().unwrap(),
        "--results",
        d.join("res").to_str().unwrap(),
        "-o",
        d.join("r2.csv").to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("fwd_7.txt") && stderr(&o).contains("line 1"),
        "{}",
        stderr(&o)
    );
    assert!(!d.join("r2.csv").exists(), "no partial output");
    let o = monovo(&[
        "eval-batch",
        "--keep-going",
        "--dataset",
        d.join("data").to_str().unwrap(),
        "--results",
        d.join("res").to_str().unwrap(),
        "-o",
        d.join("r2.csv").to_str().unwrap(),
    ]);
    assert!(o.status.success());
    assert!(stdout(&o).contains("17 runs"));
    // the unreadable run is failed with its reason in the table, read back as written
    let rows =
        eval_metrics::parse_csv(&std::fs::read_to_string(d.join("r2.csv")).unwrap()).unwrap();
    let bad = rows.iter().find(|r| r.key.run == 7).unwrap();
    let reason = bad.failure.as_deref().unwrap();
    assert!(
        reason.contains("fwd_7.txt") && reason.contains("line 1"),
        "{reason}"
    );
}
