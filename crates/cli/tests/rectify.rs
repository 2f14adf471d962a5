//! `monovo info` and `monovo rectify` on a generated 1280x1024 zipped JPEG sequence.
use crate::common::{files_of, monovo, stderr, stdout, temp_dir};
use camera_model::{CameraFile, RectifyMap};
use dataset_io::Sequence;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// A synthetic 1280x1024 sequence of 8 frames, generated once per test run.
fn fixture() -> &'static PathBuf {
    static SEQ: OnceLock<PathBuf> = OnceLock::new();
    SEQ.get_or_init(|| {
        // one per process: test runners that run each test in its own process (nextest)
        // would otherwise generate it into the same folder at once
        let d = temp_dir(&format!("rectify_fixture_{}", std::process::id()));
        let seq = d.join("seq");
        let o = monovo(&[
            "synth",
            "sequence",
            "-o",
            seq.to_str().unwrap(),
            "--size",
            "1280x1024",
            "--frames",
            "8",
            "--seed",
            "4",
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        seq
    })
}

/// A copy of the fixture that a test may break.
fn copy_of(name: &str) -> PathBuf {
    let d = temp_dir(name);
    let dst = d.join("seq");
    std::fs::create_dir_all(&dst).unwrap();
    for e in std::fs::read_dir(fixture()).unwrap() {
        let e = e.unwrap();
        std::fs::copy(e.path(), dst.join(e.file_name())).unwrap();
    }
    dst
}

fn leftovers(parent: &Path) -> Vec<String> {
    std::fs::read_dir(parent)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n != "seq")
        .collect()
}

#[test]
fn rectified_frames_equal_rectifying_each_decoded_frame_by_hand() {
    let d = temp_dir("rectify_exact");
    let out = d.join("out");
    let o = monovo(&[
        "rectify",
        fixture().to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--json",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    assert_eq!(v["frames"], 8);
    assert_eq!(v["half_decode"], false);
    assert_eq!(v["jpeg_decoder"], dataset_io::JPEG_DECODER);
    let raw = Sequence::open(fixture()).unwrap();
    let cam = raw.camera().unwrap();
    let map =
        RectifyMap::for_mode(&cam.input, cam.input_size, &cam.output, cam.output_size).unwrap();
    let rect = Sequence::open(&out).unwrap();
    assert_eq!(rect.len(), 8);
    for k in 0..8 {
        let want = map.remap_u8(&raw.decode(k).unwrap()).unwrap();
        assert_eq!(rect.decode(k).unwrap(), want, "frame {k}");
        assert_eq!(
            rect.times().rows[k].timestamp,
            raw.times().rows[k].timestamp
        );
    }
    // the written camera.txt is the pinhole that was used
    let back =
        CameraFile::parse(&std::fs::read_to_string(out.join("camera.txt")).unwrap()).unwrap();
    let (a, b) = (back.input.intrinsics(), map.camera());
    assert!((a.fx - b.fx).abs() < 1e-9 && (a.cy - b.cy).abs() < 1e-9);
    assert!(out.join("pcalib.txt").exists() && out.join("vignette.png").exists());
    assert!(out.join("groundtruthSync.txt").exists());
    let o = monovo(&["info", out.to_str().unwrap(), "--json"]);
    let v: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    assert_eq!(
        (v["width"].as_u64(), v["height"].as_u64()),
        (Some(640), Some(480))
    );
}

#[test]
fn reverse_range_zip_depth_and_photometric() {
    let d = temp_dir("rectify_variants");
    let out = d.join("bwd");
    let o = monovo(&[
        "rectify",
        fixture().to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--reverse",
        "--range",
        "2..6",
        "--zip",
        "--size",
        "320x240",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let raw = Sequence::open(fixture()).unwrap();
    let rect = Sequence::open(&out).unwrap();
    assert!(rect.is_zipped());
    assert_eq!(rect.len(), 4);
    assert_eq!(rect.image_size(), camera_model::ImageSize::new(320, 240));
    let t0 = raw.times().rows[5].timestamp;
    assert!((rect.times().rows[0].timestamp - (2e9 - t0)).abs() < 1e-5);
    assert!(!out.join("groundtruthSync.txt").exists());

    let out = d.join("lin");
    let o = monovo(&[
        "rectify",
        fixture().to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--photometric",
        "--depth",
        "16",
        "--output-camera",
        "0.4 0.5 0.5 0.5 0",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stdout(&o).contains("U(I) / V"));
    assert!(!out.join("pcalib.txt").exists());
    let (img, sixteen) = dataset_io::read_gray16(&out.join("images/00003.png")).unwrap();
    assert!(sixteen && img.width() == 640);

    let out = d.join("irr");
    let o = monovo(&[
        "rectify",
        fixture().to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--irradiance",
        "--mask-saturated",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(std::fs::read_to_string(out.join("times.txt"))
        .unwrap()
        .lines()
        .all(|l| l.ends_with(" 1")));
    // existing OUT is refused without --force
    let o = monovo(&[
        "rectify",
        fixture().to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(!o.status.success() && stderr(&o).contains("--force"));
    let o = monovo(&[
        "rectify",
        fixture().to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--force",
        "--range",
        "0..2",
    ]);
    assert!(o.status.success());
}

fn expect_clean_failure(seq: &Path, extra: &[&str], needles: &[&str]) {
    let out = seq.parent().unwrap().join("out");
    let mut args = vec![
        "rectify",
        seq.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    let o = monovo(&args);
    assert!(!o.status.success());
    let e = stderr(&o);
    assert_eq!(e.trim().lines().count(), 1, "one-line error: {e}");
    for n in needles {
        assert!(e.contains(n), "`{n}` not in: {e}");
    }
    assert!(!out.exists(), "OUT left behind");
    assert!(
        leftovers(seq.parent().unwrap()).is_empty(),
        "staging left: {:?}",
        leftovers(seq.parent().unwrap())
    );
}

#[test]
fn bad_inputs_give_one_line_errors_and_no_output() {
    // a corrupt JPEG
    let s = copy_of("rectify_bad_jpeg");
    let raw = Sequence::open(&s).unwrap();
    let entries: Vec<(String, Vec<u8>)> = (0..raw.len())
        .map(|k| {
            let mut b = raw.raw(k).unwrap();
            if k == 5 {
                // an interrupted copy: the entropy-coded data ends early
                b.truncate(b.len() / 3);
            }
            (raw.names()[k].clone(), b)
        })
        .collect();
    drop(raw);
    dataset_io::write_images_zip(&s.join("images.zip"), entries).unwrap();
    expect_clean_failure(&s, &[], &["images.zip", "00005.jpg"]);

    // times.txt one row short
    let s = copy_of("rectify_bad_times");
    let t = std::fs::read_to_string(s.join("times.txt")).unwrap();
    std::fs::write(
        s.join("times.txt"),
        t.lines()
            .skip(1)
            .map(|l| format!("{l}\n"))
            .collect::<String>(),
    )
    .unwrap();
    expect_clean_failure(&s, &[], &["times.txt", "7 rows", "8 images"]);

    // camera.txt whose size disagrees with the images
    let s = copy_of("rectify_bad_camera");
    let c = std::fs::read_to_string(s.join("camera.txt")).unwrap();
    std::fs::write(s.join("camera.txt"), c.replace("1280 1024", "640 512")).unwrap();
    expect_clean_failure(&s, &[], &["camera.txt", "line 2", "1280x1024"]);

    // pcalib with NaN, and with a dip
    let s = copy_of("rectify_bad_pcalib");
    let p = std::fs::read_to_string(s.join("pcalib.txt")).unwrap();
    let mut v: Vec<String> = p.split_whitespace().map(String::from).collect();
    v[30] = "NaN".into();
    std::fs::write(s.join("pcalib.txt"), v.join(" ")).unwrap();
    expect_clean_failure(&s, &["--photometric"], &["pcalib.txt", "U(30)"]);
    let mut v: Vec<String> = p.split_whitespace().map(String::from).collect();
    v[200] = "1.0".into();
    std::fs::write(s.join("pcalib.txt"), v.join(" ")).unwrap();
    expect_clean_failure(&s, &["--photometric"], &["pcalib.txt", "U(200)"]);

    // irradiance without exposures
    let s = copy_of("rectify_no_exposure");
    let t = std::fs::read_to_string(s.join("times.txt")).unwrap();
    let two: String = t
        .lines()
        .map(|l| l.split_whitespace().take(2).collect::<Vec<_>>().join(" ") + "\n")
        .collect();
    std::fs::write(s.join("times.txt"), two).unwrap();
    expect_clean_failure(&s, &["--irradiance"], &["times.txt", "exposure"]);
}

/// `--photometric` without vignette.png undoes the response alone (V = 1), with a warning.
#[test]
fn photometric_without_vignette_corrects_the_response_alone() {
    let s = copy_of("rectify_no_vignette");
    std::fs::remove_file(s.join("vignette.png")).unwrap();
    let out = s.parent().unwrap().join("out");
    let o = monovo(&[
        "rectify",
        s.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--photometric",
        "--pinhole",
        "none",
        "--size",
        "1280x1024",
        "--depth",
        "16",
        "--scale",
        "100",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let e = stderr(&o);
    assert!(e.contains("no vignette.png") && e.contains("V = 1"), "{e}");
    let raw = Sequence::open(&s).unwrap();
    let u = photometric::InverseResponse::parse(
        &std::fs::read_to_string(s.join("pcalib.txt")).unwrap(),
    )
    .unwrap();
    let frame = raw.decode(2).unwrap();
    let (img, _) = dataset_io::read_gray16(&out.join("images/00002.png")).unwrap();
    for (i, (&v, &o)) in frame.data().iter().zip(img.data()).enumerate().step_by(97) {
        let want = (100.0 * u.get(v)).min(65535.0);
        // the fused path holds U in a 16-bit table: within one unit plus 1e-4 relative
        assert!(
            (o as f64 - want).abs() <= 1.0 + 1e-4 * want,
            "pixel {i}: {o} vs {want}"
        );
    }
}

/// A sequence of 16-bit PNG frames from a 12-bit sensor, with a 4096-value response: the
/// geometric path keeps the values, the photometric path applies U exactly, and a value
/// beyond 12 bits is refused.
#[test]
fn sixteen_bit_frames_with_an_embedded_bit_depth() {
    let d = temp_dir("rectify_16bit");
    let s = d.join("seq");
    std::fs::create_dir_all(s.join("images")).unwrap();
    let (w, h) = (40usize, 30usize);
    let mut times = String::new();
    for i in 0..3usize {
        let vals: Vec<u16> = (0..w * h)
            .map(|p| ((p * 37 + i * 11) % 4096) as u16)
            .collect();
        let png = dataset_io::encode_png_u16(w, h, &vals, dataset_io::PngSpeed::Fast).unwrap();
        std::fs::write(s.join(format!("images/{i:05}.png")), png).unwrap();
        times += &format!("{i:05} {i}.5 10\n");
    }
    std::fs::write(s.join("times.txt"), times).unwrap();
    std::fs::write(
        s.join("camera.txt"),
        "Pinhole 30 30 19.5 14.5 0\n40 30\nnone\n40 30\n",
    )
    .unwrap();
    let table: Vec<String> = (0..4096)
        .map(|k| format!("{}", 2.0 * k as f64 + 1.0))
        .collect();
    std::fs::write(s.join("pcalib.txt"), table.join(" ")).unwrap();

    let out = d.join("geo");
    let o = monovo(&[
        "rectify",
        s.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--depth",
        "16",
        "--bit-depth",
        "12",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let raw = Sequence::open(&s).unwrap();
    assert_eq!(raw.bits_per_sample(), 16);
    let (img, _) = dataset_io::read_gray16(&out.join("images/00001.png")).unwrap();
    match raw.decode_native(1).unwrap() {
        dataset_io::GrayImage::U16(src) => assert_eq!(img, src),
        other => panic!("{other:?}"),
    }

    let out = d.join("lin");
    let o = monovo(&[
        "rectify",
        s.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--photometric",
        "--depth",
        "16",
        "--bit-depth",
        "12",
        "--scale",
        "1",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let (img, _) = dataset_io::read_gray16(&out.join("images/00001.png")).unwrap();
    for (p, &o) in img.data().iter().enumerate() {
        let v = (p * 37 + 11) % 4096;
        assert_eq!(o as f64, 2.0 * v as f64 + 1.0, "pixel {p}");
    }

    // a value of 13 bits with --bit-depth 12
    let vals: Vec<u16> = vec![5000; w * h];
    let png = dataset_io::encode_png_u16(w, h, &vals, dataset_io::PngSpeed::Fast).unwrap();
    std::fs::write(s.join("images/00002.png"), png).unwrap();
    let out = d.join("bad");
    let o = monovo(&[
        "rectify",
        s.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--bit-depth",
        "12",
    ]);
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(
        e.contains("5000") && e.contains("--bit-depth 12") && e.contains("00002"),
        "{e}"
    );
    assert!(!out.exists());
}

/// Every file of a folder, by relative path.
/// The same rectification with 1 and with 2 threads writes bit-identical sequences.
/// Rectifies the fixture with each of `cases` (a name and extra arguments) in the two
/// environments of `runs` (a label and variables to set) and checks that both runs write
/// the same files to the byte.
fn assert_same_outputs(dir: &str, cases: &[(&str, &[&str])], runs: [(&str, &[(&str, &str)]); 2]) {
    let d = temp_dir(dir);
    for (name, extra) in cases {
        let outputs: Vec<_> = runs
            .iter()
            .map(|(label, envs)| {
                let out = d.join(format!("{name}_{label}"));
                let mut args = vec![
                    "rectify",
                    fixture().to_str().unwrap(),
                    "-o",
                    out.to_str().unwrap(),
                ];
                args.extend(*extra);
                let o = std::process::Command::new(env!("CARGO_BIN_EXE_monovo"))
                    .envs(envs.iter().copied())
                    .args(&args)
                    .output()
                    .unwrap();
                assert!(o.status.success(), "{}", stderr(&o));
                files_of(&out)
            })
            .collect();
        assert!(outputs[0].len() >= 3, "{name}");
        assert!(
            outputs[0] == outputs[1],
            "{name}: outputs differ between {} and {}",
            runs[0].0,
            runs[1].0
        );
    }
}

#[test]
fn outputs_are_bit_identical_with_one_and_two_threads() {
    assert_same_outputs(
        "rectify_threads",
        &[
            ("geometric", &["--zip"]),
            ("photometric", &["--irradiance", "--reverse"]),
        ],
        [
            ("1 thread", &[("RAYON_NUM_THREADS", "1")]),
            ("2 threads", &[("RAYON_NUM_THREADS", "2")]),
        ],
    );
}

/// The AVX2 remaps (where the CPU has them) and the portable ones (`MONOVO_NO_AVX2`) write
/// the same files; on a CPU without AVX2 both runs take the portable remaps.
#[test]
fn outputs_are_bit_identical_with_and_without_avx2() {
    assert_same_outputs(
        "rectify_avx2",
        &[
            ("geometric", &[]),
            ("photometric", &["--photometric"]),
            ("irradiance16", &["--irradiance", "--depth", "16"]),
        ],
        [("avx2", &[]), ("portable", &[("MONOVO_NO_AVX2", "1")])],
    );
}

#[test]
fn compression_none_stores_the_same_pixels() {
    let d = temp_dir("rectify_stored");
    let (fast, stored) = (d.join("fast"), d.join("stored"));
    for (out, extra) in [(&fast, vec![]), (&stored, vec!["--compression", "none"])] {
        let mut args = vec![
            "rectify",
            fixture().to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
            "--photometric",
        ];
        args.extend(&extra);
        let o = monovo(&args);
        assert!(o.status.success(), "{}", stderr(&o));
    }
    let (a, b) = (
        Sequence::open(&fast).unwrap(),
        Sequence::open(&stored).unwrap(),
    );
    assert_eq!((a.len(), b.len()), (8, 8));
    for k in 0..8 {
        assert_eq!(a.decode(k).unwrap(), b.decode(k).unwrap(), "frame {k}");
        let size = |s: &Path| {
            std::fs::metadata(s.join(format!("images/{k:05}.png")))
                .unwrap()
                .len()
        };
        // stored: at least the raw 640x480 bytes; the fast deflate well below them
        assert!(size(&stored) >= 640 * 480, "{}", size(&stored));
        assert!(size(&fast) < 640 * 400, "{}", size(&fast));
    }
    let o = monovo(&[
        "rectify",
        fixture().to_str().unwrap(),
        "-o",
        d.join("x").to_str().unwrap(),
        "--compression",
        "zstd",
    ]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("expected fast or none"),
        "{}",
        stderr(&o)
    );
}

/// `--half-decode`: the frames are the half-size decodes (libjpeg-turbo's DCT-domain scaling)
/// rectified by the half-input map, exactly; they differ from the full path's by about a
/// grey level on average (a 2x2 mean against a point sample, no bias), with and without the
/// photometric correction; what it cannot do is refused in one line.
#[cfg(feature = "turbojpeg")]
#[test]
fn half_decode_rectifies_the_half_size_frames() {
    let d = temp_dir("rectify_half");
    let raw = Sequence::open(fixture()).unwrap();
    let cam = raw.camera().unwrap();
    let map =
        RectifyMap::for_mode_half_input(&cam.input, cam.input_size, &cam.output, cam.output_size)
            .unwrap();
    for photometric in [false, true] {
        let (half, full) = (
            d.join(format!("half{photometric}")),
            d.join(format!("full{photometric}")),
        );
        for (out, extra) in [(&half, vec!["--half-decode", "--json"]), (&full, vec![])] {
            let mut args = vec![
                "rectify",
                fixture().to_str().unwrap(),
                "-o",
                out.to_str().unwrap(),
            ];
            args.extend(&extra);
            if photometric {
                args.push("--photometric");
            }
            let o = monovo(&args);
            assert!(o.status.success(), "{}", stderr(&o));
            if out == &half {
                let v: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
                assert_eq!(v["half_decode"], true);
                assert_eq!(v["jpeg_decoder"], "libjpeg-turbo");
            }
        }
        let (h, f) = (
            Sequence::open(&half).unwrap(),
            Sequence::open(&full).unwrap(),
        );
        let (mut abs, mut bias, mut n) = (0.0f64, 0.0f64, 0.0f64);
        for k in 0..8 {
            let hk = h.decode(k).unwrap();
            if !photometric {
                assert_eq!(
                    hk,
                    map.remap_u8(&raw.decode_half(k).unwrap()).unwrap(),
                    "frame {k}"
                );
            }
            for (a, b) in hk.data().iter().zip(f.decode(k).unwrap().data()) {
                let e = *a as f64 - *b as f64;
                abs += e.abs();
                bias += e;
                n += 1.0;
            }
        }
        let (abs, bias) = (abs / n, bias / n);
        assert!(
            abs < 3.0 && bias.abs() < 0.5,
            "photometric {photometric}: mean |e| {abs}, bias {bias}"
        );
    }
    let seq = copy_of("rectify_half_bad");
    expect_clean_failure(
        &seq,
        &["--half-decode", "--size", "800x600"],
        &["half", "640x512"],
    );
    expect_clean_failure(
        &seq,
        &["--half-decode", "--photometric", "--mask-saturated"],
        &["--half-decode", "--mask-saturated"],
    );
}

/// Without libjpeg-turbo, `--half-decode` says how to build it, and writes nothing.
#[cfg(not(feature = "turbojpeg"))]
#[test]
fn half_decode_without_libjpeg_turbo_says_how_to_build_it() {
    let seq = copy_of("rectify_half_missing");
    expect_clean_failure(&seq, &["--half-decode"], &["--features turbojpeg", "cmake"]);
}
