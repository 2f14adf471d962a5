//! `monovo calib response`.
use crate::common::{monovo, stderr, stdout, temp_dir};

#[test]
fn response_calibration_end_to_end_and_bad_sweeps() {
    let d = temp_dir("calib_response");
    let sweep = d.join("sweep");
    let o = monovo(&[
        "synth",
        "sweep",
        "-o",
        sweep.to_str().unwrap(),
        "--size",
        "320x256",
        "--frames",
        "30",
        "--step",
        "1.2",
        "--png",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let pcalib = d.join("pcalib.txt");
    let plot = d.join("response.svg");
    let o = monovo(&[
        "calib",
        "response",
        sweep.to_str().unwrap(),
        "-o",
        pcalib.to_str().unwrap(),
        "--plot",
        plot.to_str().unwrap(),
        "--json",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    assert_eq!(v["converged"], true);
    let got =
        photometric::InverseResponse::parse(&std::fs::read_to_string(&pcalib).unwrap()).unwrap();
    let truth = photometric::InverseResponse::parse(
        &std::fs::read_to_string(sweep.join("truth_pcalib.txt")).unwrap(),
    )
    .unwrap();
    let max = (0..255)
        .map(|k| (got.values()[k] - truth.values()[k]).abs())
        .fold(0.0, f64::max);
    assert!(max < 3.0, "max error {max}");
    assert!(std::fs::read_to_string(&plot).unwrap().contains("<svg"));

    // all frames at one exposure: a clear error and no output
    let same = d.join("same");
    std::fs::create_dir_all(&same).unwrap();
    std::fs::copy(sweep.join("images.zip"), same.join("images.zip")).unwrap();
    let t: String = std::fs::read_to_string(sweep.join("times.txt"))
        .unwrap()
        .lines()
        .map(|l| {
            let f: Vec<&str> = l.split_whitespace().collect();
            format!("{} {} 5.0\n", f[0], f[1])
        })
        .collect();
    std::fs::write(same.join("times.txt"), &t).unwrap();
    let out = d.join("same_pcalib.txt");
    let o = monovo(&[
        "calib",
        "response",
        same.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("same exposure"), "{}", stderr(&o));
    assert!(!out.exists());

    // no exposures
    let t2: String = t
        .lines()
        .map(|l| l.split_whitespace().take(2).collect::<Vec<_>>().join(" ") + "\n")
        .collect();
    std::fs::write(same.join("times.txt"), t2).unwrap();
    let o = monovo(&[
        "calib",
        "response",
        same.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("times.txt") && stderr(&o).contains("exposure"),
        "{}",
        stderr(&o)
    );
    assert!(!out.exists());
}

fn write_png16_reader(p: &std::path::Path) -> Vec<f32> {
    let (img, _) = dataset_io::read_gray16(p).unwrap();
    let max = *img.data().iter().max().unwrap() as f32;
    img.data().iter().map(|v| *v as f32 / max).collect()
}

#[test]
fn vignette_calibration_with_markers_and_with_poses() {
    let d = temp_dir("calib_vignette");
    let set = d.join("wall");
    let o = monovo(&[
        "synth",
        "vignette",
        "-o",
        set.to_str().unwrap(),
        "--size",
        "320x256",
        "--frames",
        "60",
        "--png",
        "--seed",
        "3",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let truth = write_png16_reader(&set.join("truth_vignette.png"));
    for (name, extra) in [
        ("detected", Vec::<String>::new()),
        (
            "poses",
            vec![
                "--poses".to_string(),
                set.join("poses.txt").to_str().unwrap().to_string(),
            ],
        ),
    ] {
        let out = d.join(format!("{name}.png"));
        let plot = d.join(format!("{name}_plot.png"));
        let mut args = vec![
            "calib".to_string(),
            "vignette".into(),
            set.to_str().unwrap().into(),
            "-o".into(),
            out.to_str().unwrap().into(),
            "--json".into(),
            "--plot".into(),
            plot.to_str().unwrap().into(),
        ];
        args.extend(extra);
        let a: Vec<&str> = args.iter().map(|s| s.as_str()).collect();
        let o = monovo(&a);
        assert!(o.status.success(), "{}", stderr(&o));
        let v: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
        assert!(v["frames_used"].as_u64().unwrap() >= 55, "{v}");
        assert!(v["coverage"].as_f64().unwrap() >= 0.98, "{v}");
        // the written 16-bit map against the truth, over its valid pixels: tolerance 1% here
        // (60 frames of 320x256; bench-synthetic checks 0.5% on 150 frames of 640x512)
        let got: Vec<f32> = write_png16_reader(&out)
            .into_iter()
            .map(|v| if v > 0.0 { v } else { f32::NAN })
            .collect();
        let (rms, _) = photometric::vignette_errors(&got, &truth);
        assert!(rms < 0.01, "{name}: rms relative error {rms}");
        assert!(d.join(format!("{name}_smooth.png")).exists());
        assert!(std::fs::metadata(&plot).unwrap().len() > 5000);
    }
}

#[test]
fn vignette_bad_inputs_fail_clearly_without_output() {
    let d = temp_dir("calib_vignette_bad");
    let set = d.join("wall");
    let o = monovo(&[
        "synth",
        "vignette",
        "-o",
        set.to_str().unwrap(),
        "--size",
        "160x128",
        "--frames",
        "4",
        "--png",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = d.join("v.png");
    let run = |extra: &[&str]| {
        let mut a = vec![
            "calib",
            "vignette",
            set.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
        ];
        a.extend_from_slice(extra);
        let o = monovo(&a);
        assert!(!o.status.success(), "{extra:?} should fail");
        assert!(!out.exists(), "no output after a failure");
        stderr(&o)
    };
    let e = run(&["--marker-id", "7"]);
    assert!(e.contains("marker id 7") && e.contains("not found"), "{e}");
    std::fs::rename(set.join("pcalib.txt"), d.join("pcalib.txt")).unwrap();
    let e = run(&[]);
    assert!(e.contains("pcalib"), "{e}");
    std::fs::rename(d.join("pcalib.txt"), set.join("pcalib.txt")).unwrap();
    let cam = std::fs::read_to_string(set.join("camera.txt")).unwrap();
    std::fs::write(set.join("camera.txt"), cam.replace("\nfull\n", "\nnone\n")).unwrap();
    let e = run(&[]);
    assert!(e.contains("camera.txt") && e.contains("none"), "{e}");
    std::fs::write(set.join("camera.txt"), cam).unwrap();
    let t = std::fs::read_to_string(set.join("times.txt")).unwrap();
    let two: String = t
        .lines()
        .map(|l| l.split_whitespace().take(2).collect::<Vec<_>>().join(" ") + "\n")
        .collect();
    std::fs::write(set.join("times.txt"), two).unwrap();
    let e = run(&[]);
    assert!(e.contains("times.txt") && e.contains("exposure"), "{e}");
}
