//! Other datasets in their own layouts (TUM-VI, EuRoC, 4Seasons, KITTI, TUM RGB-D): small
//! synthetic sequences rendered through the real calibration files of
//! tests/fixtures/datasets with a known scene, read by `monovo info` and rectified by
//! `monovo rectify`, whose output is checked against the scene seen by the output pinhole.
use std::path::{Path, PathBuf};

use camera_model::{CalibrationFile, CameraModel, ImageSize, Intrinsics};

use crate::common::{monovo, stderr, stdout, temp_dir};

fn fixture(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/fixtures/datasets")
        .join(rel)
}

fn copy(rel: &str, to: &Path) {
    std::fs::create_dir_all(to.parent().unwrap()).unwrap();
    std::fs::copy(fixture(rel), to).unwrap();
}

/// The scene: a smooth pattern on the sphere of viewing directions (grey values 20..235), so
/// that a bilinear remap reproduces it to a fraction of a grey level.
fn scene(ray: [f64; 3]) -> f64 {
    let n = (ray[0] * ray[0] + ray[1] * ray[1] + ray[2] * ray[2]).sqrt();
    let (x, y, z) = (ray[0] / n, ray[1] / n, ray[2] / n);
    127.5 + 60.0 * (4.0 * x + 1.0).sin() * (3.0 * y).cos() + 40.0 * (2.5 * z + x * y).cos()
}

/// A frame of `model` seeing the scene (0 where a pixel has no ray), `scale` 1 for 8-bit,
/// 257 for 16-bit values.
fn render(model: &CameraModel, size: ImageSize, scale: f64) -> Vec<u16> {
    let mut out = Vec::with_capacity(size.pixels());
    for v in 0..size.height {
        for u in 0..size.width {
            let g = model
                .unproject([u as f64, v as f64])
                .map_or(0.0, |r| scene(r) * scale);
            out.push(g.round().clamp(0.0, 65535.0) as u16);
        }
    }
    out
}

fn write_png(path: &Path, size: ImageSize, values: &[u16], sixteen: bool) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    let f = std::fs::File::create(path).unwrap();
    let mut e = png::Encoder::new(f, size.width as u32, size.height as u32);
    e.set_color(png::ColorType::Grayscale);
    e.set_depth(if sixteen {
        png::BitDepth::Sixteen
    } else {
        png::BitDepth::Eight
    });
    let mut w = e.write_header().unwrap();
    let bytes: Vec<u8> = if sixteen {
        values.iter().flat_map(|v| v.to_be_bytes()).collect()
    } else {
        values.iter().map(|v| *v as u8).collect()
    };
    w.write_image_data(&bytes).unwrap();
}

fn camera_of(rel: &str, cam: usize) -> (CameraModel, ImageSize) {
    let cal = CalibrationFile::parse(&std::fs::read_to_string(fixture(rel)).unwrap()).unwrap();
    let f = cal
        .camera_file(cam, Some(ImageSize::new(1241, 376)))
        .unwrap();
    (f.input, f.input_size)
}

fn info(dir: &Path, extra: &[&str]) -> serde_json::Value {
    let mut args = vec!["info", dir.to_str().unwrap(), "--json"];
    args.extend_from_slice(extra);
    let o = monovo(&args);
    assert!(o.status.success(), "{}\n{}", stdout(&o), stderr(&o));
    serde_json::from_str(stdout(&o).trim()).unwrap()
}

/// Rectifies `dir` to the pinhole `rel` (relative to the output size) and compares every
/// valid output pixel with the scene as that pinhole sees it: mean absolute difference and
/// the share within 2 grey levels (of 8 bits).
fn rectify_matches_scene(dir: &Path, extra: &[&str], rel: [f64; 4], out: ImageSize) -> f64 {
    let o_dir = dir.with_extension("rect");
    let _ = std::fs::remove_dir_all(&o_dir);
    let pinhole = format!("{} {} {} {} 0", rel[0], rel[1], rel[2], rel[3]);
    let size = format!("{}x{}", out.width, out.height);
    let mut args = vec![
        "rectify",
        dir.to_str().unwrap(),
        "-o",
        o_dir.to_str().unwrap(),
        "--pinhole",
        &pinhole,
        "--size",
        &size,
    ];
    args.extend_from_slice(extra);
    let o = monovo(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    let seq = dataset_io::Sequence::open(&o_dir).unwrap();
    let img = seq.decode_native(0).unwrap();
    let (w, h) = (out.width as f64, out.height as f64);
    let k = Intrinsics {
        fx: rel[0] * w,
        fy: rel[1] * h,
        cx: rel[2] * w - 0.5,
        cy: rel[3] * h - 0.5,
    };
    let (mut sum, mut n, mut close) = (0.0, 0usize, 0usize);
    for v in 0..out.height {
        for u in 0..out.width {
            let got = match &img {
                dataset_io::GrayImage::U8(i) => i.get(u, v).unwrap() as f64,
                dataset_io::GrayImage::U16(i) => i.get(u, v).unwrap() as f64 / 257.0,
            };
            if got == 0.0 {
                continue; // no source (outside the raw image)
            }
            let m = k.pixel_to_normalized([u as f64, v as f64]);
            let d = (got - scene([m[0], m[1], 1.0])).abs();
            sum += d;
            n += 1;
            close += usize::from(d <= 2.0);
        }
    }
    assert!(n > out.pixels() / 2, "{n} valid pixels");
    let mean = sum / n as f64;
    eprintln!(
        "{}: mean |difference| {mean:.4} grey levels, {:.4}% within 2, {n} pixels",
        dir.display(),
        100.0 * close as f64 / n as f64
    );
    assert!(mean <= 0.5, "{}: mean difference {mean}", dir.display());
    assert!(
        close as f64 >= 0.999 * n as f64,
        "{}: {close} of {n} within 2",
        dir.display()
    );
    mean
}

const TUMVI_NS: [i64; 3] = [
    1520530308199447626,
    1520530308249448626,
    1520530308299450626,
];

/// TUM-VI's dso/camN export (16-bit frames, EquiDistant camera.txt, the real times.txt head)
/// and its mav0 layout with Basalt's Double Sphere calibration.
#[test]
fn tum_vi_dso_and_mav0() {
    let root = temp_dir("datasets_tumvi");
    let (model, size) = camera_of("calib/dm-vio__tumvi_calib__camera02.txt", 0);
    let times = std::fs::read_to_string(fixture(
        "heads/dm-vio-python-tools__tumvi_room1_512_16__times.head.txt",
    ))
    .unwrap();
    let head: String = times.lines().take(4).map(|l| format!("{l}\n")).collect();
    for cam in 0..2 {
        let d = root.join(format!("dso/cam{cam}"));
        std::fs::create_dir_all(&d).unwrap();
        std::fs::write(d.join("times.txt"), &head).unwrap();
        copy(
            "calib/dm-vio__tumvi_calib__camera02.txt",
            &d.join("camera.txt"),
        );
        for ns in TUMVI_NS {
            let path = d.join(format!("images/{ns}.png"));
            write_png(&path, size, &render(&model, size, 257.0), true);
        }
    }
    copy(
        "calib/dm-vio__tumvi_calib__camchain.yaml",
        &root.join("dso/camchain.yaml"),
    );
    let v = info(&root, &["--cam", "1"]);
    assert_eq!(v["layout"], "tum-vi-dso");
    assert_eq!(
        (v["frames"].as_u64(), v["bits"].as_u64()),
        (Some(3), Some(16))
    );
    assert_eq!(
        (v["width"].as_u64(), v["height"].as_u64()),
        (Some(512), Some(512))
    );
    assert_eq!(v["timestamps_ns"][0].as_i64(), Some(TUMVI_NS[0]));
    assert_eq!(v["timestamps_ns"][1].as_i64(), Some(TUMVI_NS[2]));
    assert_eq!(v["exposure_ms"]["first"].as_f64(), Some(1.462315));
    // both folders carry DM-VIO's camera.txt (cam0's EquiDistant values), as rendered
    rectify_matches_scene(
        &root,
        &["--cam", "1"],
        [0.3, 0.3, 0.5, 0.5],
        ImageSize::new(256, 256),
    );
    let out = std::fs::read_to_string(root.with_extension("rect").join("times.txt")).unwrap();
    assert!(out.contains("1520530308.199447626 1.462315"), "{out}");
    let rect = dataset_io::Sequence::open(&root.with_extension("rect")).unwrap();
    assert_eq!(rect.bits_per_sample(), 16, "16-bit frames stay 16-bit");
    // --calib reads another calibration file for the same frames
    let ds = fixture("calib/basalt__tumvi_512_ds_calib.json");
    let v = info(&root, &["--cam", "1", "--calib", ds.to_str().unwrap()]);
    assert_eq!(v["camera"]["model"], "DoubleSphere");
    assert_eq!(
        v["camera"]["input"]["cx"].as_f64(),
        Some(252.56547609702953)
    );

    // mav0 layout with Basalt's Double Sphere calibration beside it
    let m = temp_dir("datasets_tumvi_mav0");
    let (ds, ds_size) = camera_of("calib/basalt__tumvi_512_ds_calib.json", 0);
    let mut csv = String::from("#timestamp [ns],filename\n");
    for ns in TUMVI_NS {
        csv.push_str(&format!("{ns},{ns}.png\n"));
        let p = m.join(format!("mav0/cam0/data/{ns}.png"));
        write_png(&p, ds_size, &render(&ds, ds_size, 257.0), true);
    }
    std::fs::write(m.join("mav0/cam0/data.csv"), csv).unwrap();
    copy(
        "calib/basalt__tumvi_512_ds_calib.json",
        &m.join("calibration.json"),
    );
    // a sensor.yaml with only the extrinsics is no camera: the calibration.json beside mav0 is
    std::fs::write(
        m.join("mav0/cam0/sensor.yaml"),
        "sensor_type: camera\nT_BS:\n  cols: 4\n  rows: 4\n  data: [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]\n",
    )
    .unwrap();
    let named = info(&m.join("mav0"), &[]);
    assert_eq!(named["camera"]["model"], "DoubleSphere");
    let v = info(&m, &[]);
    assert_eq!(v["layout"], "euroc-asl");
    assert_eq!(v["camera"]["model"], "DoubleSphere");
    assert!(v["exposure_ms"].is_null());
    assert_eq!(v["timestamps_ns"][1].as_i64(), Some(TUMVI_NS[2]));
    rectify_matches_scene(&m, &[], [0.35, 0.35, 0.5, 0.5], ImageSize::new(200, 200));
}

/// EuRoC: mav0/cam0 with the real sensor.yaml (RadTan), Basalt's exposure.csv, ground truth.
#[test]
fn euroc_asl_with_sensor_yaml_and_exposures() {
    let root = temp_dir("datasets_euroc");
    let (model, size) = camera_of("calib/scratch_slam__mav0__cam0__sensor.yaml", 0);
    let stamps = [
        1403636579763555584i64,
        1403636579813555456,
        1403636579863555584,
    ];
    let mut csv = String::from("#timestamp [ns],filename\n");
    let mut exp = String::from("#timestamp [ns],exposure [ns]\n");
    for (i, ns) in stamps.iter().enumerate() {
        csv.push_str(&format!("{ns},{ns}.png\n"));
        exp.push_str(&format!("{ns},{}\n", 5_000_000 + i * 250_000));
        let p = root.join(format!("mav0/cam0/data/{ns}.png"));
        write_png(&p, size, &render(&model, size, 1.0), false);
    }
    std::fs::write(root.join("mav0/cam0/data.csv"), csv).unwrap();
    std::fs::write(root.join("mav0/cam0/exposure.csv"), exp).unwrap();
    copy(
        "calib/scratch_slam__mav0__cam0__sensor.yaml",
        &root.join("mav0/cam0/sensor.yaml"),
    );
    let v = info(&root, &[]);
    assert_eq!(v["layout"], "euroc-asl");
    assert_eq!(v["camera"]["model"], "RadTan");
    assert_eq!(v["timestamps_ns"][0].as_i64(), Some(stamps[0]));
    assert_eq!(v["exposure_ms"]["max"].as_f64(), Some(5.5));
    assert_eq!(v["bits"].as_u64(), Some(8));
    rectify_matches_scene(&root, &[], [0.5, 0.6, 0.5, 0.5], ImageSize::new(376, 240));
    let out = std::fs::read_to_string(root.with_extension("rect").join("times.txt")).unwrap();
    assert!(out.contains("00002 1403636579.863555584 5.5"), "{out}");
    // --cam 1 is not there: the error names the folder
    let o = monovo(&["info", root.to_str().unwrap(), "--cam", "1"]);
    assert!(
        !o.status.success() && stderr(&o).contains("cam1"),
        "{}",
        stderr(&o)
    );
}

/// 4Seasons: times.txt lists more frames than there are images (matched by id), the real
/// DM-VIO calibration, and the omni camera of Kalibr's wiki in an ASL folder.
#[test]
fn four_seasons_and_kalibr_omni() {
    let root = temp_dir("datasets_4seasons");
    let times =
        fixture("heads/dm-vio-python-tools__4seasons_office_2020-03-24_17-36-22__times.head.txt");
    std::fs::copy(&times, root.join("times.txt")).unwrap();
    copy(
        "calib/dm-vio__4seasons_calib__undistorted_calib304.txt",
        &root.join("calibration/undistorted_calib_0.txt"),
    );
    let (model, size) = camera_of("calib/dm-vio__4seasons_calib__undistorted_calib304.txt", 0);
    let ids = ["1585067782140857088", "1585067782206857216"];
    for id in ids {
        let p = root.join(format!("undistorted_images/cam0/{id}.png"));
        write_png(&p, size, &render(&model, size, 1.0), false);
    }
    let v = info(&root, &[]);
    assert_eq!(v["layout"], "4seasons");
    assert_eq!(v["frames"].as_u64(), Some(2));
    assert_eq!(v["timestamps_ns"][1].as_i64(), Some(1585067782206857216));
    assert_eq!(v["exposure_ms"]["first"].as_f64(), Some(0.3843120039));
    assert!(v["warnings"].to_string().contains("matched by id"));
    rectify_matches_scene(&root, &[], [0.5, 0.8, 0.5, 0.5], ImageSize::new(400, 200));

    let omni = temp_dir("datasets_omni");
    let (m, s) = camera_of("calib/kalibr-wiki__Yaml-formats__chain.yaml", 1);
    std::fs::create_dir_all(omni.join("mav0/cam1/data")).unwrap();
    std::fs::write(
        omni.join("mav0/cam1/data.csv"),
        "#timestamp [ns],filename\n10,a.png\n20,b.png\n",
    )
    .unwrap();
    for n in ["a", "b"] {
        write_png(
            &omni.join(format!("mav0/cam1/data/{n}.png")),
            s,
            &render(&m, s, 1.0),
            false,
        );
    }
    copy(
        "calib/kalibr-wiki__Yaml-formats__chain.yaml",
        &omni.join("camchain.yaml"),
    );
    let v = info(&omni, &["--cam", "1"]);
    assert_eq!(v["camera"]["model"], "Omni");
    assert_eq!(v["timestamps_ns"][0].as_i64(), Some(10));
    rectify_matches_scene(
        &omni,
        &["--cam", "1"],
        [0.6, 0.9, 0.5, 0.5],
        ImageSize::new(376, 240),
    );
}

/// KITTI odometry (calib.txt P0, one-column times.txt) and TUM RGB-D / ETH3D (rgb.txt,
/// calibration.txt).
#[test]
fn kitti_and_tum_rgbd() {
    let root = temp_dir("datasets_kitti");
    let seq = root.join("sequences/00");
    copy(
        "heads/kitti__sequences_00__calib.head.txt",
        &seq.join("calib.txt"),
    );
    let k = CameraModel::Pinhole(Intrinsics {
        fx: 718.856,
        fy: 718.856,
        cx: 607.1928,
        cy: 185.2157,
    });
    let size = ImageSize::new(1241, 376);
    for i in 0..2 {
        write_png(
            &seq.join(format!("image_0/{i:06}.png")),
            size,
            &render(&k, size, 1.0),
            false,
        );
    }
    std::fs::write(seq.join("times.txt"), "0.000000e+00\n1.037359e-01\n").unwrap();
    let v = info(&seq, &[]);
    assert_eq!(v["layout"], "kitti");
    assert_eq!(v["timestamps_ns"][1].as_i64(), Some(103_735_900));
    assert_eq!(v["camera"]["input"]["cx"].as_f64(), Some(607.1928));
    rectify_matches_scene(&seq, &[], [0.6, 1.9, 0.5, 0.5], ImageSize::new(620, 188));

    let t = temp_dir("datasets_tumrgbd");
    let k = Intrinsics {
        fx: 726.28741455078,
        fy: 726.28741455078,
        cx: 354.6496887207,
        cy: 186.46566772461,
    };
    let size = ImageSize::new(739, 458);
    std::fs::write(
        t.join("rgb.txt"),
        "# color images\n# timestamp filename\n1305031102.175304 rgb/1305031102.175304.png\n1305031102.211214 rgb/1305031102.211214.png\n",
    )
    .unwrap();
    std::fs::write(
        t.join("calibration.txt"),
        format!("{} {} {} {}\n", k.fx, k.fy, k.cx, k.cy),
    )
    .unwrap();
    for n in ["1305031102.175304", "1305031102.211214"] {
        write_png(
            &t.join(format!("rgb/{n}.png")),
            size,
            &render(&CameraModel::Pinhole(k), size, 1.0),
            false,
        );
    }
    let v = info(&t, &[]);
    assert_eq!(v["layout"], "tum-rgbd");
    assert_eq!(v["timestamps_ns"][0].as_i64(), Some(1305031102175304000));
    rectify_matches_scene(&t, &[], [1.0, 1.5, 0.5, 0.5], ImageSize::new(370, 229));
}

/// `monovo eval --gt DIR` on EuRoC: the state csv (the IMU's poses, 17 columns) moved to the
/// camera by sensor.yaml's T_BS and sampled at the frames; an estimate that is a similarity
/// of the camera's true path scores zero error, and reading the IMU's path instead would not.
#[test]
fn eval_reads_euroc_ground_truth_at_the_frames() {
    let root = temp_dir("datasets_euroc_eval");
    let (model, size) = camera_of("calib/scratch_slam__mav0__cam0__sensor.yaml", 0);
    let frame = render(&model, size, 1.0);
    let t0 = 1403636579763555584i64;
    let mut csv = String::from("#timestamp [ns],filename\n");
    for i in 0..16 {
        let ns = t0 + i * 50_000_000;
        csv.push_str(&format!("{ns},{ns}.png\n"));
        write_png(
            &root.join(format!("mav0/cam0/data/{ns}.png")),
            size,
            &frame,
            false,
        );
    }
    std::fs::write(root.join("mav0/cam0/data.csv"), csv).unwrap();
    copy(
        "calib/scratch_slam__mav0__cam0__sensor.yaml",
        &root.join("mav0/cam0/sensor.yaml"),
    );
    let cal = CalibrationFile::parse(
        &std::fs::read_to_string(fixture("calib/scratch_slam__mav0__cam0__sensor.yaml")).unwrap(),
    )
    .unwrap();
    let imu_from_cam = camera_model::invert_rigid(&cal.cameras[0].camera_from_imu.unwrap());
    // the IMU on a helix, turning three times as fast (yaw = 3 t): the camera's path is then
    // no similarity of the IMU's
    let imu = |t: f64| {
        let (s, c) = ((3.0 * t).sin(), (3.0 * t).cos());
        (
            [t.cos(), t.sin(), 0.1 * t],
            [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]],
        )
    };
    let mut gt = String::from("#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z [], v_RS_R_x [m s^-1], v_RS_R_y [m s^-1], v_RS_R_z [m s^-1], b_w_RS_S_x [rad s^-1], b_w_RS_S_y [rad s^-1], b_w_RS_S_z [rad s^-1], b_a_RS_S_x [m s^-2], b_a_RS_S_y [m s^-2], b_a_RS_S_z [m s^-2]\n");
    for k in -20..180i64 {
        let ns = t0 + k * 5_000_000;
        let t = (ns - t0) as f64 * 1e-9;
        let (p, _) = imu(t);
        let (qw, qz) = ((1.5 * t).cos(), (1.5 * t).sin());
        gt.push_str(&format!(
            "{ns},{},{},{},{qw},0,0,{qz},0,0,0,0,0,0,0,0,0\n",
            p[0], p[1], p[2]
        ));
    }
    let gt_dir = root.join("mav0/state_groundtruth_estimate0");
    std::fs::create_dir_all(&gt_dir).unwrap();
    std::fs::write(gt_dir.join("data.csv"), gt).unwrap();
    // the estimate: the camera's true centres, scaled by 2 and shifted
    let mut est = String::new();
    for i in 0..16 {
        let ns = t0 + i * 50_000_000;
        let t = (ns - t0) as f64 * 1e-9;
        let (p, r) = imu(t);
        let c: Vec<f64> = (0..3)
            .map(|a| p[a] + (0..3).map(|b| r[a][b] * imu_from_cam[b][3]).sum::<f64>())
            .collect();
        est.push_str(&format!(
            "{:.9} {} {} {} 0 0 0 1\n",
            ns as f64 * 1e-9,
            2.0 * c[0] + 1.0,
            2.0 * c[1],
            2.0 * c[2] - 3.0
        ));
    }
    let est_path = root.join("est.txt");
    std::fs::write(&est_path, est).unwrap();
    let o = monovo(&[
        "eval",
        est_path.to_str().unwrap(),
        "--gt",
        root.to_str().unwrap(),
        "--json",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    assert_eq!(v["status"], "ok", "{v}");
    let rmse = v["e_rmse"].as_f64().unwrap();
    assert!(rmse < 1e-9, "{v}");
    // the IMU's own csv as --gt (no transform): the same estimate no longer fits exactly
    let o = monovo(&[
        "eval",
        est_path.to_str().unwrap(),
        "--gt",
        gt_dir.join("data.csv").to_str().unwrap(),
        "--json",
    ]);
    let v: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    assert!(v["e_rmse"].as_f64().unwrap() > 1e-3, "{v}");
}

/// Basalt's EUCM (EuRoC) and kb4 (T265) calibrations beside an ASL folder.
#[test]
fn basalt_eucm_and_kb4_in_asl_folders() {
    for (name, calib, rel, out) in [
        (
            "datasets_eucm",
            "calib/basalt__euroc_eucm_calib.json",
            [0.5, 0.6, 0.5, 0.5],
            ImageSize::new(376, 240),
        ),
        (
            "datasets_kb4",
            "calib/basalt__t265_kb4_calib.json",
            [0.3, 0.3, 0.5, 0.5],
            ImageSize::new(212, 200),
        ),
    ] {
        let root = temp_dir(name);
        let (model, size) = camera_of(calib, 1);
        std::fs::create_dir_all(root.join("mav0/cam1/data")).unwrap();
        std::fs::write(
            root.join("mav0/cam1/data.csv"),
            "#timestamp [ns],filename\n1000,a.png\n2000,b.png\n",
        )
        .unwrap();
        let frame = render(&model, size, 1.0);
        for n in ["a", "b"] {
            write_png(
                &root.join(format!("mav0/cam1/data/{n}.png")),
                size,
                &frame,
                false,
            );
        }
        copy(calib, &root.join("calibration.json"));
        let v = info(&root, &["--cam", "1"]);
        assert_eq!(v["camera"]["model"], model.name());
        rectify_matches_scene(&root, &["--cam", "1"], rel, out);
    }
}
