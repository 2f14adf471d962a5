//! `monovo camera`.
use crate::common::{monovo, repo_file, stderr, stdout, temp_dir};

#[test]
fn json_gives_exactly_the_output_camera() {
    let cam = repo_file("data/camera_narrow.txt");
    let o = monovo(&["camera", &cam, "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    let obj = v.as_object().unwrap();
    assert_eq!(obj.len(), 6);
    assert!((v["fx"].as_f64().unwrap() - 277.524).abs() < 1e-3);
    assert!((v["cy"].as_f64().unwrap() - 240.036).abs() < 1e-3);
    assert_eq!(v["width"], 640);
    assert_eq!(v["height"], 480);

    let o = monovo(&["camera", &cam, "--json", "--output", "full"]);
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

    let o = monovo(&[
        "camera",
        &repo_file("data/camera_narrow.txt"),
        "--output",
        "none",
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("none"));

    let o = monovo(&[
        "camera",
        &repo_file("data/camera_narrow.txt"),
        "--size",
        "640",
    ]);
    assert_eq!(o.status.code(), Some(2), "clap usage error");
}
