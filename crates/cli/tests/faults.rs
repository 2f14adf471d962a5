//! Bad input refused or warned about instead of accepted silently, and messages that name
//! the file, the line and the argument.
use crate::common::{monovo, repo_file, stderr, stdout, temp_dir};
use std::path::{Path, PathBuf};

/// A small synthetic sequence (JPEG frames in images.zip), made once per test that asks.
fn small_sequence(d: &Path) -> PathBuf {
    let seq = d.join("seq");
    let o = monovo(&[
        "synth",
        "sequence",
        "-o",
        seq.to_str().unwrap(),
        "--size",
        "160x128",
        "--frames",
        "10",
        "--seed",
        "5",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    seq
}

fn set_times(seq: &Path, f: impl Fn(usize, &str) -> String) {
    let t = std::fs::read_to_string(seq.join("times.txt")).unwrap();
    let new: String = t.lines().enumerate().map(|(i, l)| f(i, l) + "\n").collect();
    std::fs::write(seq.join("times.txt"), new).unwrap();
}

fn with_exposure(line: &str, e: &str) -> String {
    let w: Vec<&str> = line.split_whitespace().collect();
    format!("{} {} {e}", w[0], w[1])
}

#[test]
fn info_lists_every_problem_with_its_file_and_line_and_fails() {
    let d = temp_dir("faults_info");
    let seq = small_sequence(&d);
    let o = monovo(&["info", seq.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stdout(&o).contains("all 10 decode"), "{}", stdout(&o));
    // a dip in pcalib.txt, a vignette of the wrong size, a truncated JPEG
    let p = std::fs::read_to_string(seq.join("pcalib.txt")).unwrap();
    let mut v: Vec<String> = p.split_whitespace().map(String::from).collect();
    v[100] = "1.0".into();
    std::fs::write(seq.join("pcalib.txt"), v.join(" ") + "\n").unwrap();
    dataset_io::write_png_u8(
        &seq.join("vignette.png"),
        40,
        30,
        1,
        &[200u8; 1200],
        dataset_io::PngSpeed::Fast,
    )
    .unwrap();
    let raw = dataset_io::Sequence::open(&seq).unwrap();
    let entries: Vec<(String, Vec<u8>)> = (0..raw.len())
        .map(|k| {
            let mut b = raw.raw(k).unwrap();
            if k == 7 {
                b.truncate(b.len() / 3);
            }
            (raw.names()[k].clone(), b)
        })
        .collect();
    drop(raw);
    dataset_io::write_images_zip(&seq.join("images.zip"), entries).unwrap();
    let o = monovo(&["info", seq.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    let s = stdout(&o);
    let problems: Vec<&str> = s.lines().filter(|l| l.starts_with("PROBLEM")).collect();
    assert_eq!(problems.len(), 3, "{s}");
    assert!(
        problems
            .iter()
            .any(|p| p.contains("pcalib.txt") && p.contains("line 1") && p.contains("U(100)")),
        "{s}"
    );
    assert!(
        problems
            .iter()
            .any(|p| p.contains("vignette.png") && p.contains("40x30") && p.contains("160x128")),
        "{s}"
    );
    assert!(
        problems
            .iter()
            .any(|p| p.contains("images.zip") && p.contains("00007.jpg")),
        "{s}"
    );
    assert!(stderr(&o).contains("3 problem(s)"), "{}", stderr(&o));
    // --json: exactly one object, the problems listed, still non-zero
    let o = monovo(&["info", seq.to_str().unwrap(), "--json"]);
    assert_eq!(o.status.code(), Some(1));
    let v: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    assert_eq!(v["problems"].as_array().unwrap().len(), 3, "{v}");
    // --quick does not decode the frames
    let o = monovo(&["info", seq.to_str().unwrap(), "--quick", "--json"]);
    let v: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    assert_eq!(v["problems"].as_array().unwrap().len(), 2, "{v}");

    let o = monovo(&["info", d.join("nonexistent").to_str().unwrap()]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("does not exist"), "{}", stderr(&o));
}

#[test]
fn zero_exposures_are_warned_about_and_irradiance_refuses_unknown_ones() {
    let d = temp_dir("faults_exposure");
    let seq = small_sequence(&d);
    // an isolated zero (row 3, line 4): interpolated, with a warning everywhere
    set_times(&seq, |i, l| {
        if i == 3 {
            with_exposure(l, "0")
        } else {
            l.into()
        }
    });
    for args in [
        vec!["info", seq.to_str().unwrap(), "--quick"],
        vec![
            "rectify",
            seq.to_str().unwrap(),
            "-o",
            d.join("a").to_str().unwrap(),
        ],
    ] {
        let o = monovo(&args);
        assert!(o.status.success(), "{}", stderr(&o));
        let all = stdout(&o) + &stderr(&o);
        assert!(
            all.contains("line 4") && all.contains("interpolated"),
            "{args:?}: {all}"
        );
    }
    // two adjacent zeros (rows 5 and 6): unknown; irradiance refuses naming the line
    set_times(&seq, |i, l| {
        if i == 5 || i == 6 {
            with_exposure(l, "0")
        } else {
            l.into()
        }
    });
    let out = d.join("irr");
    let o = monovo(&[
        "rectify",
        seq.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--irradiance",
    ]);
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(
        e.contains("times.txt") && e.contains("line 6") && e.contains("unknown"),
        "{e}"
    );
    assert!(!out.exists());
    let o = monovo(&[
        "rectify",
        seq.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--photometric",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("line 6"), "{}", stderr(&o));
    // the range decides: frames 0..5 have known exposures
    let o = monovo(&[
        "rectify",
        seq.to_str().unwrap(),
        "-o",
        d.join("irr2").to_str().unwrap(),
        "--irradiance",
        "--range",
        "0..5",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
}

/// 8-bit irradiance takes its scale from the data, and says so in times.txt and --json.
#[test]
fn eight_bit_irradiance_uses_the_grey_levels() {
    let d = temp_dir("faults_irradiance");
    let seq = small_sequence(&d);
    let out = d.join("irr");
    let o = monovo(&[
        "rectify",
        seq.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--irradiance",
        "--json",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    let scale = v["photometric_scale"].as_f64().unwrap();
    assert!(
        v["scale_source"].as_str().unwrap().contains("percentile"),
        "{v}"
    );
    let times = std::fs::read_to_string(out.join("times.txt")).unwrap();
    let first = times.lines().next().unwrap();
    assert!(
        first.starts_with('#') && first.contains(&format!("{}", scale as f32)),
        "{first}"
    );
    // the frames use most of the 8-bit range
    let rect = dataset_io::Sequence::open(&out).unwrap();
    let mut levels = std::collections::BTreeSet::new();
    for k in 0..rect.len() {
        levels.extend(rect.decode(k).unwrap().data().iter().copied());
    }
    assert!(levels.len() > 100, "{} grey levels", levels.len());
}

#[test]
fn refused_instead_of_accepted_silently() {
    let d = temp_dir("faults_refused");
    let seq = small_sequence(&d);
    let s = seq.to_str().unwrap();
    let out = d.join("out");
    let o_ = out.to_str().unwrap();
    for (args, needle) in [
        (
            vec!["rectify", s, "-o", o_, "--scale", "2"],
            "--photometric",
        ),
        (
            vec!["rectify", s, "-o", o_, "--mask-saturated"],
            "--photometric",
        ),
        (
            vec!["rectify", s, "-o", o_, "--range", "0..100"],
            "10 frames",
        ),
    ] {
        let o = monovo(&args);
        assert!(!o.status.success(), "{args:?}");
        assert!(stderr(&o).contains(needle), "{args:?}: {}", stderr(&o));
        assert!(!out.exists());
    }
    // times.txt ids that do not name the images: a warning with the line
    set_times(&seq, |i, l| {
        if i == 2 {
            l.replacen("00002", "00099", 1)
        } else {
            l.into()
        }
    });
    let o = monovo(&["info", s, "--quick"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stdout(&o).contains("line 3: id `00099` but image 2 is `00002.jpg`"),
        "{}",
        stdout(&o)
    );
    // a trajectory whose quaternions are all zero
    let gt = seq.join("groundtruthSync.txt");
    let zeros: String = std::fs::read_to_string(&gt)
        .unwrap()
        .lines()
        .filter(|l| !l.contains("NaN"))
        .map(|l| {
            let w: Vec<&str> = l.split_whitespace().collect();
            format!("{} {} {} {} 0 0 0 0\n", w[0], w[1], w[2], w[3])
        })
        .collect();
    let traj = d.join("zeros.txt");
    std::fs::write(&traj, zeros).unwrap();
    let o = monovo(&["eval", traj.to_str().unwrap(), "--gt", gt.to_str().unwrap()]);
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(
        e.contains("zeros.txt") && e.contains("line 1") && e.contains("not a rotation"),
        "{e}"
    );
    // a crop size that leaves pixels without a source
    let o = monovo(&[
        "camera",
        &repo_file("data/camera_narrow.txt"),
        "--size",
        "2000x2000",
    ]);
    assert!(o.status.success());
    assert!(stderr(&o).contains("without a source"), "{}", stderr(&o));
}

#[test]
fn messages_name_the_argument_once_and_no_line_zero() {
    let d = temp_dir("faults_messages");
    let dir = d.to_str().unwrap();
    let gt = d.join("gt.txt");
    std::fs::write(&gt, "0 0 0 0 0 0 0 1\n1 1 0 0 0 0 0 1\n").unwrap();
    let o = monovo(&["eval", dir, "--gt", gt.to_str().unwrap()]);
    let e = stderr(&o);
    assert!(
        e.contains("the trajectory") && e.contains("os error 21"),
        "{e}"
    );
    assert_eq!(e.matches("os error").count(), 1, "{e}");
    // a folder as --gt is a dataset whose ground truth is read: this one is none
    let o = monovo(&["eval", gt.to_str().unwrap(), "--gt", dir]);
    let e = stderr(&o);
    assert!(
        !o.status.success()
            && e.contains("the ground truth's sequence folder")
            && e.contains("no images.zip"),
        "{e}"
    );
    let cam = repo_file("data/camera_narrow.txt");
    for args in [
        vec!["camera", cam.as_str(), "--pinhole", "0,5 0,5 0,5 0,5 0"],
        vec!["camera", cam.as_str(), "--size", "640"],
        vec!["rectify", dir, "-o", "x", "--size", "-3x2"],
    ] {
        let o = monovo(&args);
        assert!(!o.status.success());
        assert!(!stderr(&o).contains("line 0"), "{args:?}: {}", stderr(&o));
    }
    // `--out` is not taken for the camera: -o/--output is the output path everywhere
    let o = monovo(&["rectify", dir, "--out", "x"]);
    assert_eq!(o.status.code(), Some(2));
    let e = stderr(&o);
    assert!(
        e.contains("'--output'") && !e.contains("camera") && !e.contains("MODE"),
        "{e}"
    );
    let o = monovo(&["rectify", dir, "-o", "x", "--output", "crop"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    // the old spelling of the camera flag still works, hidden
    let o = monovo(&["camera", cam.as_str(), "--output", "full", "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = monovo(&["rectify", "--help"]);
    assert!(stdout(&o).contains("--pinhole") && !stdout(&o).contains("--output-camera"));
}

/// The README's examples: `synth sequence` writes the dataset's 640x480 output camera,
/// `synth vignette` the poses file that `--poses` names, the camera flag is `--pinhole`, and
/// every link (DESIGN.md included) points inside the repository.
#[test]
fn readme_examples_hold() {
    let d = temp_dir("faults_readme");
    let seq = d.join("sequence_01");
    let o = monovo(&[
        "synth",
        "sequence",
        "-o",
        seq.to_str().unwrap(),
        "--frames",
        "8",
        "--json",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    assert_eq!(
        (v["width"].as_u64(), v["height"].as_u64()),
        (Some(640), Some(512))
    );
    let cam = std::fs::read_to_string(seq.join("camera.txt")).unwrap();
    assert_eq!(cam.lines().nth(3), Some("640 480"), "{cam}");
    let wall = d.join("wall");
    let o = monovo(&[
        "synth",
        "vignette",
        "-o",
        wall.to_str().unwrap(),
        "--frames",
        "2",
        "--size",
        "160x128",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(wall.join("poses.txt").is_file());
    let readme = std::fs::read_to_string(repo_file("README.md")).unwrap();
    assert!(readme.contains("--poses wall/poses.txt"));
    // the output camera is --pinhole in the examples (--output is the output path)
    assert!(
        !readme.contains("--output full") && !readme.contains("--output \""),
        "README"
    );
    // every link and image of the README points to a file of the repository
    let mut links = 0;
    for (i, _) in readme.match_indices("](") {
        let target = &readme[i + 2..];
        let target = &target[..target.find(')').unwrap()];
        // (an anchor names a heading of the page: the page is the file)
        let target = target.split('#').next().unwrap();
        if target.starts_with("http") {
            continue;
        }
        links += 1;
        assert!(!target.contains(".."), "{target} leaves the repository");
        assert!(
            std::path::Path::new(&repo_file(target)).is_file(),
            "{target} is not a file of the repository"
        );
    }
    assert!(
        links >= 8 && readme.contains("](docs/DESIGN.md)"),
        "{links}"
    );
}
