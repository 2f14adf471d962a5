//! `monovo ape`, `monovo rpe`, `monovo rpe --tum` and `monovo kitti` against the numbers that
//! evo, the TUM RGB-D scripts and the KITTI devkit compute on the same real files
//! (tests/fixtures/metrics/peers.json, written by xtask/peers/trajectory_metrics.py), and
//! the commands' interface: evo's flag spellings, JSON keys, result zips, figures, errors.

use std::path::Path;

use serde_json::Value;

use crate::common::{monovo, repo_file, stderr, stdout, temp_dir};

fn peers() -> Value {
    let text = std::fs::read_to_string(repo_file("tests/fixtures/metrics/peers.json")).unwrap();
    serde_json::from_str(&text).unwrap()
}

/// `|a - b| <= rel * max(|a|, |b|) + abs`.
fn close(a: f64, b: f64, rel: f64, abs: f64) -> bool {
    (a - b).abs() <= rel * a.abs().max(b.abs()) + abs
}

/// Runs monovo with `args` and `--json` from the repository root; the JSON object.
fn json_of(args: &[String]) -> Result<Value, String> {
    let mut a: Vec<&str> = args.iter().map(String::as_str).collect();
    a.push("--json");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_monovo"))
        .current_dir(repo_file(""))
        .args(&a)
        .output()
        .unwrap();
    if !o.status.success() {
        return Err(stderr(&o));
    }
    serde_json::from_str(&stdout(&o)).map_err(|e| e.to_string())
}

fn strings(v: &Value) -> Vec<String> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|s| s.as_str().unwrap().to_string())
        .collect()
}

/// Runs every case on two threads; the failures.
fn run_cases(cases: &[Value], check: impl Fn(&Value) -> Vec<String> + Sync) -> Vec<String> {
    let half = cases.len().div_ceil(2);
    std::thread::scope(|s| {
        let h: Vec<_> = cases
            .chunks(half.max(1))
            .map(|chunk| s.spawn(|| chunk.iter().flat_map(&check).collect::<Vec<_>>()))
            .collect();
        h.into_iter().flat_map(|h| h.join().unwrap()).collect()
    })
}

// Both compute in f64: 1e-9 relative. The absolute floor 1e-14 is for errors that are zero in
// exact arithmetic (the first pose after --align_origin, a pose pair with itself), where each
// side has its own rounding noise of about 1e-16.
#[test]
fn ape_and_rpe_equal_evo() {
    let p = peers();
    assert_eq!(p["evo"]["evo"], "v1.38.1");
    let cases = p["evo"]["cases"].as_array().unwrap();
    assert!(cases.len() >= 180);
    let failures = run_cases(cases, |c| {
        let tool = if c["tool"] == "evo_ape" { "ape" } else { "rpe" };
        let fmt = if c["id"].as_str().unwrap().starts_with("kitti") {
            "kitti"
        } else {
            "tum"
        };
        let mut args = vec![tool.to_string(), fmt.to_string()];
        args.push(c["reference"].as_str().unwrap().into());
        args.push(c["estimate"].as_str().unwrap().into());
        args.extend(strings(&c["args"]));
        let id = c["id"].as_str().unwrap();
        match (json_of(&args), c.get("error")) {
            (Err(_), Some(_)) => vec![],
            (Ok(_), Some(e)) => vec![format!("{id}: evo refused ({e}), monovo did not")],
            (Err(e), None) => vec![format!("{id}: {e}")],
            (Ok(m), None) => c["stats"]
                .as_object()
                .unwrap()
                .iter()
                .filter(|(k, v)| {
                    !close(
                        m[k.as_str()].as_f64().unwrap(),
                        v.as_f64().unwrap(),
                        1e-9,
                        1e-14,
                    )
                })
                .map(|(k, v)| format!("{id} {:?}: {k} {} vs evo {v}", c["args"], m[k.as_str()]))
                .collect(),
        }
    });
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

// Translations: 1e-9 relative (and 1e-14 m for a pair of a pose with itself, as above).
// Rotations: the scripts take acos((trace R - 1) / 2), which near zero turns the rounding of
// the trace (a few 1e-16) into angles up to about 3e-8 rad (2e-6 deg) of noise, different in
// numpy's LU inverse and in ours: 2e-6 degrees absolute on top of 1e-9 relative.
#[test]
fn tum_conventions_equal_the_tum_scripts() {
    let p = peers();
    assert_eq!(p["tum"]["python"], "2.7.18");
    let cases = p["tum"]["cases"].as_array().unwrap();
    assert!(cases.len() >= 60);
    let failures = run_cases(cases, |c| {
        let tool = if c["tool"] == "tum_ate" { "ape" } else { "rpe" };
        let mut args = vec![tool.to_string(), "--tum".to_string()];
        args.push(c["reference"].as_str().unwrap().into());
        args.push(c["estimate"].as_str().unwrap().into());
        args.extend(strings(&c["args"]));
        let id = c["id"].as_str().unwrap();
        let m = match json_of(&args) {
            Ok(m) => m,
            Err(e) => return vec![format!("{id}: {e}")],
        };
        let mut bad = Vec::new();
        for (k, v) in c["translational"].as_object().unwrap() {
            if !close(
                m[k.as_str()].as_f64().unwrap(),
                v.as_f64().unwrap(),
                1e-9,
                1e-14,
            ) {
                bad.push(format!("{id}: {k} {} vs {v}", m[k.as_str()]));
            }
        }
        if let Some(r) = c.get("rotational_deg") {
            for k in ["rmse", "mean", "median", "std", "min", "max"] {
                let (a, b) = (
                    m["rotational_error"][k].as_f64().unwrap(),
                    r[k].as_f64().unwrap(),
                );
                if !close(a, b, 1e-9, 2e-6) {
                    bad.push(format!("{id}: rotational {k} {a} vs {b}"));
                }
            }
        }
        bad
    });
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

// The devkit computes in f32 and prints 9 significant digits: equal to 1e-8 relative.
#[test]
fn kitti_equals_the_devkit() {
    let p = peers();
    let cases = p["kitti"]["cases"].as_array().unwrap();
    assert_eq!(cases.len(), 3);
    let dir = temp_dir("kitti_pooled");
    for c in cases {
        let seqs = c["sequences"].as_array().unwrap();
        let args: Vec<String> = if seqs.len() == 1 {
            vec![
                "kitti".into(),
                seqs[0][0].as_str().unwrap().into(),
                seqs[0][1].as_str().unwrap().into(),
            ]
        } else {
            // the pooled case: two folders of NN.txt
            for (k, s) in seqs.iter().enumerate() {
                for (side, i) in [("gt", 0), ("est", 1)] {
                    let d = dir.join(side);
                    std::fs::create_dir_all(&d).unwrap();
                    std::fs::copy(
                        repo_file(s[i].as_str().unwrap()),
                        d.join(format!("{k:02}.txt")),
                    )
                    .unwrap();
                }
            }
            vec![
                "kitti".into(),
                dir.join("gt").to_string_lossy().into_owned(),
                dir.join("est").to_string_lossy().into_owned(),
            ]
        };
        let m = json_of(&args).unwrap();
        let id = c["id"].as_str().unwrap();
        assert_eq!(m["segments"], c["segments"], "{id}");
        for (mine, theirs) in [("t_err", "t_err"), ("r_err_rad_per_m", "r_err")] {
            let (a, b) = (m[mine].as_f64().unwrap(), c[theirs].as_f64().unwrap());
            assert!(close(a, b, 1e-8, 0.0), "{id} {mine}: {a} vs {b}");
        }
        let (ml, cl) = (
            m["lengths"].as_array().unwrap(),
            c["lengths"].as_array().unwrap(),
        );
        assert_eq!(ml.len(), cl.len(), "{id}");
        for (a, b) in ml.iter().zip(cl) {
            assert_eq!(a["length"], b["length"]);
            let t = a["t_err_percent"].as_f64().unwrap() / 100.0;
            let r = a["r_err_deg_per_100m"].as_f64().unwrap().to_radians() / 100.0;
            assert!(
                close(t, b["t_err"].as_f64().unwrap(), 1e-8, 0.0),
                "{id}: {a} {b}"
            );
            assert!(
                close(r, b["r_err"].as_f64().unwrap(), 1e-8, 0.0),
                "{id}: {a} {b}"
            );
        }
        let pct = m["t_err_percent"].as_f64().unwrap();
        assert!(close(pct, c["t_err_percent"].as_f64().unwrap(), 1e-8, 0.0));
    }
}

const GT: &str =
    "tests/fixtures/dso-family/trajectory/evo__test__data__freiburg1_xyz-groundtruth.txt";
const EST: &str = "tests/fixtures/metrics/evo__freiburg1_xyz-rgbdslam_drift.txt";

fn run_in_repo(args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_monovo"))
        .current_dir(repo_file(""))
        .args(args)
        .output()
        .unwrap()
}

#[test]
fn evo_spellings_and_combined_flags_agree() {
    let run = |a: &[&str]| {
        let mut v = vec!["rpe", GT, EST];
        v.extend_from_slice(a);
        v.push("--json");
        let o = run_in_repo(&v);
        assert!(o.status.success(), "{a:?}: {}", stderr(&o));
        stdout(&o)
    };
    let base = run(&[
        "-as",
        "--delta",
        "0.2",
        "--delta_unit",
        "m",
        "--pose_relation",
        "angle_deg",
    ]);
    assert_eq!(
        base,
        run(&["-a", "-s", "-d", "0.2", "-u", "m", "-r", "angle_deg"])
    );
    assert_eq!(
        base,
        run(&[
            "--align",
            "--correct-scale",
            "--delta",
            "0.2",
            "--delta-unit",
            "m",
            "--pose-relation",
            "angle-deg"
        ])
    );
    // a repeated option: the last one wins, as in evo
    assert_eq!(
        base,
        run(&[
            "-as",
            "-r",
            "full",
            "-d",
            "0.2",
            "-u",
            "m",
            "-r",
            "angle_deg"
        ])
    );
    // evo's format word and --n_to_align -1 (all)
    let mut v = vec!["ape", "tum", GT, EST, "-as", "--n_to_align", "-1", "--json"];
    let a = stdout(&run_in_repo(&v));
    v.retain(|x| *x != "tum" && *x != "--n_to_align" && *x != "-1");
    assert_eq!(a, stdout(&run_in_repo(&v)));
}

#[test]
fn json_is_one_object_with_evo_statistics() {
    let o = run_in_repo(&["ape", GT, EST, "-as", "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = stdout(&o);
    assert_eq!(text.trim().lines().count(), 1);
    let v: Value = serde_json::from_str(&text).unwrap();
    for k in ["rmse", "mean", "median", "std", "min", "max", "sse"] {
        assert!(v[k].is_f64(), "{k}");
    }
    assert_eq!(v["n"], 785);
    assert_eq!(v["alignment"]["mode"], "sim3");
    let o = run_in_repo(&["rpe", "--tum", GT, EST, "--json"]);
    let v: Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert!(v["rotational_error"]["rmse"].is_f64() && v["translational_error"]["n"].is_u64());
}

/// The evo result zip has evo's entries; a numpy array header is what np.save writes.
#[test]
fn save_results_writes_evo_zip_and_plot_draws() {
    let dir = temp_dir("metrics_outputs");
    let zip = dir.join("ape.zip");
    let png = dir.join("ape.png");
    let (z, p) = (zip.to_string_lossy(), png.to_string_lossy());
    let o = run_in_repo(&["ape", GT, EST, "-as", "--save_results", &z, "--plot", &p]);
    assert!(o.status.success(), "{}", stderr(&o));
    let f = std::fs::File::open(&zip).unwrap();
    let mut a = zip::ZipArchive::new(f).unwrap();
    let names: Vec<String> = a.file_names().map(|n| n.unwrap().to_string()).collect();
    for n in [
        "info.json",
        "stats.json",
        "error_array.npy",
        "timestamps.npy",
        "seconds_from_start.npy",
        "distances_from_start.npy",
        "distances.npy",
        "alignment_transformation_sim3.npy",
    ] {
        assert!(names.iter().any(|x| x == n), "{n} in {names:?}");
    }
    let mut npy = Vec::new();
    std::io::Read::read_to_end(&mut a.by_name("error_array.npy").unwrap(), &mut npy).unwrap();
    assert!(npy.starts_with(b"\x93NUMPY\x01\x00"));
    assert_eq!(npy.len(), 128 + 785 * 8);
    let head = String::from_utf8_lossy(&npy[10..128]).into_owned();
    assert!(head.starts_with("{'descr': '<f8', 'fortran_order': False, 'shape': (785,), }"));
    assert!(std::fs::read(&png).unwrap().starts_with(b"\x89PNG"));
    // existing outputs are refused without --force, before any work
    let o = run_in_repo(&["ape", GT, EST, "--save_results", &z]);
    assert!(
        !o.status.success() && stderr(&o).contains("--force"),
        "{}",
        stderr(&o)
    );
    let o = run_in_repo(&[
        "ape",
        GT,
        EST,
        "--save_results",
        &dir.join("x.txt").to_string_lossy(),
    ]);
    assert!(stderr(&o).contains(".zip"));
}

#[test]
fn bad_input_names_the_file_and_what_is_wrong() {
    let dir = temp_dir("metrics_bad");
    let bad = dir.join("bad.txt");
    std::fs::write(&bad, "1 2 3 4 0 0 0 1\n2 2 3 x 0 0 0 1\n").unwrap();
    let o = monovo(&["ape", &repo_file(GT), &bad.to_string_lossy()]);
    let e = stderr(&o);
    assert!(!o.status.success());
    assert!(e.contains("bad.txt") && e.contains("line 2"), "{e}");
    // no pose within the tolerance
    let far = dir.join("far.txt");
    std::fs::write(&far, "5 0 0 0 0 0 0 1\n6 1 0 0 0 0 0 1\n7 1 1 0 0 0 0 1\n").unwrap();
    let o = monovo(&["ape", &repo_file(GT), &far.to_string_lossy()]);
    assert!(
        stderr(&o).contains("no matching timestamps"),
        "{}",
        stderr(&o)
    );
    // a missing file
    let o = monovo(&["rpe", &repo_file(GT), "/nonexistent/est.txt"]);
    assert!(!o.status.success() && stderr(&o).contains("/nonexistent/est.txt"));
    // KITTI files of different lengths
    let o = run_in_repo(&[
        "kitti",
        "tests/fixtures/metrics/kitti_04_gt.txt",
        "tests/fixtures/metrics/kitti_07_estimate.txt",
    ]);
    assert!(
        stderr(&o).contains("271") && stderr(&o).contains("1101"),
        "{}",
        stderr(&o)
    );
    // seconds are the TUM script's unit only
    let o = run_in_repo(&["rpe", GT, EST, "-u", "s"]);
    assert!(stderr(&o).contains("--tum"), "{}", stderr(&o));
    assert!(Path::new(&repo_file(GT)).is_file());
}

/// eval-batch computes APE, RPE and KITTI next to e_align: more columns in results.csv, the
/// per-method medians in the summary; `plot box` and `plot cumulative` draw them.
#[test]
fn batch_computes_the_other_metrics_next_to_e_align() {
    let dir = temp_dir("metrics_batch");
    let synth = dir.join("synth");
    let o = monovo(&[
        "synth",
        "results",
        "-o",
        synth.to_str().unwrap(),
        "--sequences",
        "2",
        "--runs",
        "2",
        "--frames",
        "400",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let csv = dir.join("results.csv");
    let o = monovo(&[
        "eval-batch",
        "--dataset",
        synth.join("dataset").to_str().unwrap(),
        "--results",
        synth.join("results").to_str().unwrap(),
        "-o",
        csv.to_str().unwrap(),
        "--ape",
        "-as",
        "--rpe=--tum --delta 0.5",
        "--kitti",
        "--json",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: Value = serde_json::from_str(&stdout(&o)).unwrap();
    let st = &v["methods"]["direct"]["statistics"];
    assert!(
        st["ape_rmse"]["median"].is_f64() && st["e_align"]["median"].is_f64(),
        "{v}"
    );
    let text = std::fs::read_to_string(&csv).unwrap();
    let header = text.lines().next().unwrap();
    assert!(header.ends_with("poses,ape_rmse,ape_mean,ape_median,ape_std,ape_min,ape_max,rpe_rmse,rpe_mean,rpe_median,rpe_std,rpe_min,rpe_max,kitti_t_err,kitti_r_err,reason"), "{header}");
    let rows = eval_metrics::parse_csv(&text).unwrap();
    assert_eq!(rows.len(), 16);
    for r in rows.iter().filter(|r| r.is_ok()) {
        // Sim(3) over the start and end segments: APE's rmse is e_rmse
        let ape = r.extra["ape_rmse"];
        assert!(
            (ape - r.metrics.e_rmse).abs() <= 1e-9 * ape,
            "{ape} {}",
            r.metrics.e_rmse
        );
        assert!(r.extra["rpe_rmse"].is_finite());
        // the synthetic paths are shorter than KITTI's 100 m: no segment
        assert!(r.extra["kitti_t_err"].is_infinite());
    }
    let png = dir.join("box.png");
    let o = monovo(&[
        "plot",
        "box",
        csv.to_str().unwrap(),
        "-o",
        png.to_str().unwrap(),
        "--metric",
        "ape_rmse",
        "--json",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert!(v["boxes"]["feature"]["median"].is_f64(), "{v}");
    let o = monovo(&[
        "plot",
        "cumulative",
        csv.to_str().unwrap(),
        "-o",
        dir.join("c.png").to_str().unwrap(),
        "--metric",
        "rpe_mean",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    // a results.csv without the column says how to get it
    let plain = dir.join("plain.csv");
    let o = monovo(&[
        "eval-batch",
        "--dataset",
        synth.join("dataset").to_str().unwrap(),
        "--results",
        synth.join("results").to_str().unwrap(),
        "-o",
        plain.to_str().unwrap(),
    ]);
    assert!(o.status.success());
    let o = monovo(&[
        "plot",
        "box",
        plain.to_str().unwrap(),
        "-o",
        dir.join("b2.png").to_str().unwrap(),
        "--metric",
        "ape_rmse",
    ]);
    assert!(stderr(&o).contains("eval-batch --ape"), "{}", stderr(&o));
    // a bad flag of a metric names it
    let o = monovo(&[
        "eval-batch",
        "--dataset",
        synth.join("dataset").to_str().unwrap(),
        "--results",
        synth.join("results").to_str().unwrap(),
        "-o",
        dir.join("x.csv").to_str().unwrap(),
        "--ape",
        "-as --delta 3",
    ]);
    assert!(
        !o.status.success() && stderr(&o).contains("--ape"),
        "{}",
        stderr(&o)
    );
}
