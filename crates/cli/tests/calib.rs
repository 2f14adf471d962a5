//! `monovo calib response`.
use crate::common::{files_of, monovo, monovo_threads, stderr, stdout, temp_dir};

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
        "--noise",
        "high",
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
    let stop = v["stop"].as_str().unwrap();
    assert!(
        [
            "tolerance",
            "settled",
            "refused_within_noise",
            "no_improvement",
            "flat"
        ]
        .contains(&stop),
        "{stop}"
    );
    assert_eq!(v["std_error"].as_array().unwrap().len(), 256);
    // the standard errors beside the table: one line of 256 numbers
    let std_text = std::fs::read_to_string(d.join("pcalib_std.txt")).unwrap();
    let sd: Vec<f64> = std_text
        .split_whitespace()
        .map(|t| t.parse().unwrap())
        .collect();
    assert_eq!(sd.len(), 256);
    // U(0) = 0 and U(255) = 255 are held
    assert!(sd[1..255].iter().all(|s| *s > 0.0) && sd[0] == 0.0 && sd[255] == 0.0);
    let got =
        photometric::InverseResponse::parse(&std::fs::read_to_string(&pcalib).unwrap()).unwrap();
    let truth = photometric::InverseResponse::parse(
        &std::fs::read_to_string(sweep.join("truth_pcalib.txt")).unwrap(),
    )
    .unwrap();
    let max = (0..255)
        .map(|k| (got.values()[k] - truth.values()[k]).abs())
        .fold(0.0, f64::max);
    assert!(max < 1.0, "max error {max}");
    crate::figures::check_svg(
        &plot,
        1650,
        520,
        &[
            "inverse response U",
            "grey value I",
            "U(I) (scaled to U(255) = 255)",
            "log10 of the number of observations",
            "U estimated",
        ],
    );

    // options from --config, a flag over the file, and a bad file refused before any work
    let config = d.join("calib.toml");
    std::fs::write(
        &config,
        "[response]\nmax_iterations = 2\ntolerance = 1e-9\n",
    )
    .unwrap();
    let iterations = |extra: &[&str]| {
        let out = d.join("config_pcalib.txt");
        let mut args = vec![
            "calib",
            "response",
            sweep.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
            "--force",
            "--json",
            "--config",
            config.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        let o = monovo(&args);
        assert!(o.status.success(), "{}", stderr(&o));
        let v: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
        v["iterations"].as_u64().unwrap()
    };
    assert_eq!(iterations(&[]), 2);
    assert_eq!(iterations(&["--max-iterations", "1"]), 1);
    std::fs::write(&config, "[response]\nmax_iterations = 2\nsmoothnes = 1\n").unwrap();
    let bad_out = d.join("bad_config_pcalib.txt");
    let o = monovo(&[
        "calib",
        "response",
        sweep.to_str().unwrap(),
        "-o",
        bad_out.to_str().unwrap(),
        "--config",
        config.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(e.contains("calib.toml") && e.contains("smoothnes"), "{e}");
    assert!(!bad_out.exists());

    // outputs are not replaced without --force, and nothing is computed before that check
    let o = monovo(&[
        "calib",
        "response",
        sweep.to_str().unwrap(),
        "-o",
        pcalib.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("already exists"), "{}", stderr(&o));
    let o = monovo(&[
        "calib",
        "response",
        sweep.to_str().unwrap(),
        "-o",
        d.join("missing/dir/pcalib.txt").to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("does not exist"), "{}", stderr(&o));

    bad_sweeps_are_refused(&d, &sweep);
}

/// A sweep whose frames share one exposure, and one without exposures: a clear error and
/// no output.
fn bad_sweeps_are_refused(d: &std::path::Path, sweep: &std::path::Path) {
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

/// The vignette calibration's kernels compiled for AVX2 (where the CPU has it) and the
/// portable ones (`MONOVO_NO_AVX2`) give the same files to the byte: the same operations in
/// the same order, only more of them to a vector (8-bit and 12-bit samples). On a CPU
/// without AVX2 both runs take the portable kernels.
#[test]
fn vignette_calibration_is_the_same_with_and_without_avx2() {
    let d = temp_dir("calib_vignette_avx2");
    for bits in ["8", "12"] {
        let set = d.join(format!("wall{bits}"));
        let o = monovo(&[
            "synth",
            "vignette",
            "-o",
            set.to_str().unwrap(),
            "--size",
            "240x192",
            "--frames",
            "50",
            "--seed",
            "3",
            "--bits",
            bits,
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        let run = |name: &str, portable: bool| {
            let out = d.join(format!("{name}{bits}"));
            std::fs::create_dir_all(&out).unwrap();
            let mut c = std::process::Command::new(env!("CARGO_BIN_EXE_monovo"));
            c.args(["calib", "vignette", set.to_str().unwrap(), "-o"])
                .arg(out.join("v.png"))
                .arg("--json");
            if portable {
                c.env("MONOVO_NO_AVX2", "1");
            } else {
                c.env_remove("MONOVO_NO_AVX2");
            }
            let o = c.output().unwrap();
            assert!(o.status.success(), "{}", stderr(&o));
            let json = stdout(&o).replace(out.to_str().unwrap(), "OUT");
            (files_of(&out), json)
        };
        let (wide, portable) = (run("wide", false), run("portable", true));
        assert_eq!(wide.0.len(), 4, "four maps written");
        assert!(wide.0 == portable.0, "{bits}-bit: the maps differ");
        assert_eq!(wide.1, portable.1, "{bits}-bit: the reports differ");
    }
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
        assert_eq!(v["smoothing_cross_validated"], true, "{v}");
        // `synth vignette` stores JPEG frames (quality 90), whose compression the defect
        // count then includes (the text output says so)
        assert_eq!(v["jpeg_frames"], true, "{v}");
        // the written maps against the truth: the recommended one within 0.3% here (60
        // frames of 320x256; bench-synthetic checks 0.15% on 150 frames of 640x512), the raw
        // one within 1.5%
        let got = write_png16_reader(&out);
        let (rms, _) = photometric::vignette_errors(&got, &truth);
        assert!(rms < 0.003, "{name}: rms relative error {rms}");
        let raw = write_png16_reader(&d.join(format!("{name}_raw.png")));
        let (raw_rms, _) = photometric::vignette_errors(&raw, &truth);
        assert!(raw_rms < 0.015, "{name}: raw rms relative error {raw_rms}");
        assert!(got.iter().all(|v| *v > 0.0), "no black pixel in the map");
        // the standard error map and its scale in the PNG text chunk and in --json
        let std_path = d.join(format!("{name}_std.png"));
        let text = dataset_io::read_png_text(&std_path).unwrap();
        let scale: f64 = text
            .iter()
            .find(|(k, _)| k == "monovo:std_scale")
            .map(|(_, v)| v.parse().unwrap())
            .unwrap();
        assert!((scale - v["std_scale"].as_f64().unwrap()).abs() < 1e-9 * scale);
        assert!(scale > 0.0 && scale < 0.05, "{scale}");
        assert!(d.join(format!("{name}_coverage.png")).exists());
        crate::figures::check_png(&plot, 1650, 900);
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

/// Synthetic sweeps and walls, and both calibrations (marker detection included), with 1 and
/// with 2 threads: bit-identical files.
#[test]
fn synth_and_calibrations_are_bit_identical_with_one_and_two_threads() {
    let d = temp_dir("calib_threads");
    let mut outputs = Vec::new();
    for threads in [1, 2] {
        let base = d.join(format!("threads{threads}"));
        std::fs::create_dir_all(&base).unwrap();
        let p = |n: &str| base.join(n).to_str().unwrap().to_string();
        let (sweep, wall) = (p("sweep"), p("wall"));
        let (pcalib, vignette) = (p("pcalib.txt"), p("vignette.png"));
        let steps: [&[&str]; 4] = [
            &[
                "synth", "sweep", "-o", &sweep, "--size", "160x128", "--frames", "16",
            ],
            &["calib", "response", &sweep, "-o", &pcalib],
            &[
                "synth", "vignette", "-o", &wall, "--size", "320x256", "--frames", "40", "--seed",
                "9",
            ],
            &["calib", "vignette", &wall, "-o", &vignette],
        ];
        for args in steps {
            let o = monovo_threads(threads, args);
            assert!(o.status.success(), "{args:?}: {}", stderr(&o));
        }
        outputs.push(files_of(&base));
    }
    let names = |o: &[(String, Vec<u8>)]| o.iter().map(|f| f.0.clone()).collect::<Vec<_>>();
    assert_eq!(names(&outputs[0]), names(&outputs[1]));
    assert!(outputs[0].len() >= 12, "{:?}", names(&outputs[0]));
    let differ: Vec<&String> = outputs[0]
        .iter()
        .zip(&outputs[1])
        .filter(|(a, b)| a.1 != b.1)
        .map(|(a, _)| &a.0)
        .collect();
    assert!(
        differ.is_empty(),
        "differ between 1 and 2 threads: {differ:?}"
    );
}

/// Options outside the values they can take, from --config or from a flag, are refused before
/// any work (the sequence is not even opened), naming the option and the file.
#[test]
fn absurd_calibration_options_are_refused_before_any_work() {
    let d = temp_dir("calib_options");
    let missing = d.join("no-such-sequence");
    let missing = missing.to_str().unwrap();
    for (what, config, flag, name) in [
        ("vignette", "[vignette]\ngrid = 100000\n", None, "grid"),
        (
            "vignette",
            "[vignette]\nsmoothing_px = 1e300\n",
            None,
            "smoothing_px",
        ),
        ("vignette", "[vignette]\nextent = 0.0\n", None, "extent"),
        (
            "response",
            "[response]\nsaturation_border = 100000\n",
            None,
            "saturation_border",
        ),
        ("response", "", Some(["--tolerance", "nan"]), "tolerance"),
        ("response", "[response]\nhuber = inf\n", None, "huber"),
    ] {
        let cfg = d.join("options.toml");
        std::fs::write(&cfg, config).unwrap();
        let out = d.join("out.png");
        let mut args = vec![
            "calib",
            what,
            missing,
            "-o",
            out.to_str().unwrap(),
            "--config",
            cfg.to_str().unwrap(),
        ];
        args.extend(flag.iter().flatten());
        let o = monovo(&args);
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(1), "{what} {name}: {e}");
        assert!(
            e.contains(&format!("`{name}`"))
                && e.contains("options.toml")
                && !e.contains("no-such"),
            "{what} {name}: {e}"
        );
        assert!(!out.exists());
    }
}

/// A 12-bit sensor end to end: `synth sweep --bits 12` writes 16-bit PNG frames, `calib
/// response` finds the bit depth, writes 4096 values within 0.5% of the truth over the
/// observed range, and `rectify --photometric` indexes the table with the 12-bit values.
#[test]
fn twelve_bit_sweep_end_to_end() {
    let d = temp_dir("calib_response_12bit");
    let sweep = d.join("sweep");
    let o = monovo(&[
        "synth",
        "sweep",
        "-o",
        sweep.to_str().unwrap(),
        "--size",
        "240x192",
        "--frames",
        "60",
        "--bits",
        "12",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let pcalib = d.join("pcalib.txt");
    let o = monovo(&[
        "calib",
        "response",
        sweep.to_str().unwrap(),
        "-o",
        pcalib.to_str().unwrap(),
        "--json",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    assert_eq!(v["bits"], 12);
    assert_eq!(v["std_error"].as_array().unwrap().len(), 4096);
    let read = |p: &std::path::Path| {
        photometric::InverseResponse::parse(&std::fs::read_to_string(p).unwrap()).unwrap()
    };
    let got = read(&pcalib);
    let truth = read(&sweep.join("truth_pcalib.txt"));
    assert_eq!(got.table().len(), 4096);
    let (lo, hi) = (
        v["observed_min"].as_u64().unwrap() as usize,
        v["observed_max"].as_u64().unwrap() as usize,
    );
    assert!(lo < 200 && hi > 3800, "{lo}..{hi}");
    let rel = (lo..=hi)
        .map(|k| (got.table()[k] - truth.table()[k]).abs() / truth.table()[k])
        .fold(0.0, f64::max);
    assert!(rel < 0.005, "max relative error {rel}");
    // rectify --photometric on the 16-bit frames with the 4096-value table
    std::fs::copy(&pcalib, sweep.join("pcalib.txt")).unwrap();
    let out = d.join("rect");
    let o = monovo(&[
        "rectify",
        sweep.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--photometric",
        "--range",
        "0..2",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(files_of(&out.join("images")).len(), 2);
    // a value above 4095 with the table's bit depth is refused, naming the bit depth
    let o = monovo(&[
        "calib",
        "response",
        sweep.to_str().unwrap(),
        "-o",
        d.join("p10.txt").to_str().unwrap(),
        "--bit-depth",
        "10",
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("--bit-depth 10"), "{}", stderr(&o));
    assert!(!d.join("p10.txt").exists());
}

/// A 12-bit vignette set end to end: `synth vignette --bits 12` writes 16-bit PNG frames and
/// a 4096-value pcalib.txt; `calib vignette` finds the marker in the deep frames, reads them
/// as 12-bit samples (the table's depth) and recovers the vignette; the same values in the
/// high bits give the same map (with a warning); a --bit-depth too small for them is refused.
#[test]
fn twelve_bit_vignette_end_to_end() {
    let d = temp_dir("calib_vignette_12bit");
    let set = d.join("wall");
    let o = monovo(&[
        "synth",
        "vignette",
        "-o",
        set.to_str().unwrap(),
        "--size",
        "240x192",
        "--frames",
        "50",
        "--bits",
        "12",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let pcalib = std::fs::read_to_string(set.join("pcalib.txt")).unwrap();
    assert_eq!(pcalib.split_whitespace().count(), 4096);
    let out = d.join("v.png");
    let o = monovo(&[
        "calib",
        "vignette",
        set.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stdout(&o).contains("50 of 50 frames have a plane pose"),
        "{}",
        stdout(&o)
    );
    // lossless (16-bit PNG) frames: no word of JPEG in the defect count
    assert!(!stdout(&o).contains("JPEG"), "{}", stdout(&o));
    let read = |p: &std::path::Path| {
        let map = dataset_io::read_gray_map(p).unwrap().0;
        photometric::Vignette::from_u16(&map).unwrap()
    };
    let (got, truth) = (read(&out), read(&set.join("truth_vignette.png")));
    let (rms, _) = photometric::vignette_errors(got.values().data(), truth.values().data());
    assert!(rms < 0.003, "RMS relative error {rms}");
    // the same 12-bit values in the high bits of the samples
    let high = d.join("wall_high");
    std::fs::create_dir_all(&high).unwrap();
    for f in ["times.txt", "camera.txt", "pcalib.txt"] {
        std::fs::copy(set.join(f), high.join(f)).unwrap();
    }
    let low = dataset_io::Sequence::open(&set).unwrap();
    let shifted = (0..low.len()).map(|k| {
        let (img, sixteen) = dataset_io::decode_gray16(&low.raw(k).unwrap()).unwrap();
        assert!(sixteen);
        let (w, h) = img.size();
        let values: Vec<u16> = img.data().iter().map(|&v| v << 4).collect();
        let png = dataset_io::encode_png_u16(w, h, &values, dataset_io::PngSpeed::Fast).unwrap();
        (low.names()[k].clone(), png)
    });
    dataset_io::write_images_zip(&high.join("images.zip"), shifted).unwrap();
    let out_high = d.join("v_high.png");
    let o = monovo(&[
        "calib",
        "vignette",
        high.to_str().unwrap(),
        "-o",
        out_high.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("shifted down by 4 bits"),
        "{}",
        stderr(&o)
    );
    assert_eq!(
        std::fs::read(&out).unwrap(),
        std::fs::read(&out_high).unwrap()
    );
    let o = monovo(&[
        "calib",
        "vignette",
        high.to_str().unwrap(),
        "-o",
        d.join("v10.png").to_str().unwrap(),
        "--bit-depth",
        "10",
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("--bit-depth 10"), "{}", stderr(&o));
    assert!(!d.join("v10.png").exists());
}
