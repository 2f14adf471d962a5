//! `monovo camera`.
use crate::common::{monovo, repo_file, stderr, stdout, temp_dir};

#[test]
fn json_gives_exactly_the_output_camera() {
    let cam = repo_file("data/camera_narrow.txt");
    let o = monovo(&["camera", &cam, "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    // the output camera's six values, then what the input is
    for key in ["fx", "fy", "cx", "cy", "width", "height"] {
        assert!(v[key].is_number(), "{key}");
    }
    assert_eq!(v["input"]["model"], "FOV");
    assert_eq!(v["format"], "camera-txt");
    assert!((v["fx"].as_f64().unwrap() - 277.524).abs() < 1e-3);
    assert!((v["cy"].as_f64().unwrap() - 240.036).abs() < 1e-3);
    assert_eq!(v["width"], 640);
    assert_eq!(v["height"], 480);

    let o = monovo(&["camera", &cam, "--json", "--pinhole", "full"]);
    let v: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    assert!((v["fx"].as_f64().unwrap() - 214.536).abs() < 1e-3);

    let o = monovo(&[
        "camera",
        &cam,
        "--json",
        "--output",
        "0.5 0.5 0.5 0.5 0",
        "--size",
        "320x240",
    ]);
    let v: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    assert_eq!(v["fx"].as_f64().unwrap(), 160.0);
    assert_eq!(v["cx"].as_f64().unwrap(), 159.5);
    assert_eq!(v["width"], 320);
}

#[test]
fn human_output_names_models_and_fields_of_view() {
    let o = monovo(&["camera", &repo_file("data/camera_narrow.txt")]);
    assert!(o.status.success());
    let s = stdout(&o);
    assert!(
        s.contains("FOV") && s.contains("Pinhole") && s.contains("invalid (black) pixels: 0"),
        "{s}"
    );
}

#[test]
fn bad_files_name_file_and_line_and_exit_non_zero() {
    let dir = temp_dir("camera_bad");
    let p = dir.join("camera.txt");
    std::fs::write(&p, "FOV 0,5 0,6 0,5 0,5 0,9\n640 480\ncrop\n640 480\n").unwrap();
    let o = monovo(&["camera", p.to_str().unwrap()]);
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(e.contains("camera.txt") && e.contains("line 1"), "{e}");
    assert_eq!(e.trim().lines().count(), 1, "one-line error: {e}");

    let o = monovo(&["camera", dir.join("missing.txt").to_str().unwrap()]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("missing.txt"));

    // `none` on a distorted camera: the raw image passes through, with warnings
    let o = monovo(&[
        "camera",
        &repo_file("data/camera_narrow.txt"),
        "--output",
        "none",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let e = stderr(&o);
    assert!(
        e.contains("distortion is ignored") && e.contains("resized"),
        "{e}"
    );

    let o = monovo(&[
        "camera",
        &repo_file("data/camera_narrow.txt"),
        "--size",
        "640",
    ]);
    assert_eq!(o.status.code(), Some(2), "clap usage error");
}

/// Lines after line 4 (a stereo baseline, a second camera) are ignored like DSO does: named
/// in the text output, warned about on stderr, and `--json` keeps its exact keys.
#[test]
fn extra_lines_are_ignored_named_and_warned_about() {
    let dir = temp_dir("camera_extra_lines");
    let p = dir.join("camera.txt");
    std::fs::write(
        &p,
        "\u{feff}Pinhole 718.856 718.856 607.1928 185.2157 0 0 0 0\r\n1241 376\r\ncrop\r\n1241 376\r\n0.537165\r\n",
    )
    .unwrap();
    let o = monovo(&["camera", p.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let s = stdout(&o);
    assert!(
        s.contains("line 5: 0.537165") && s.contains("invalid (black) pixels: 0"),
        "{s}"
    );
    let e = stderr(&o);
    assert!(
        e.contains("camera.txt")
            && e.contains("line 5 is ignored")
            && e.contains("byte-order mark"),
        "{e}"
    );
    let o = monovo(&["camera", p.to_str().unwrap(), "--json"]);
    let v: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    assert_eq!(v["input"]["model"], "Pinhole");
    assert_eq!(v["fx"].as_f64().unwrap(), 718.856);
    assert_eq!(v["cx"].as_f64().unwrap(), 607.1928);
}
