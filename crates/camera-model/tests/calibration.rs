//! The real calibration files of tests/fixtures/datasets/calib (SOURCES.tsv there): every
//! format read, with the values of the file.
use camera_model::{CalibrationFile, CalibrationFormat, CameraModel, ImageSize};

fn fixture(name: &str) -> String {
    let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/fixtures/datasets")
        .join(name);
    std::fs::read_to_string(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

fn read(name: &str) -> CalibrationFile {
    CalibrationFile::parse(&fixture(name)).unwrap_or_else(|e| panic!("{name}: {e}"))
}

#[test]
fn basalt_json_double_sphere_eucm_and_kb4() {
    let f = read("calib/basalt__tumvi_512_ds_calib.json");
    assert_eq!(f.format, CalibrationFormat::BasaltJson);
    assert_eq!(f.cameras.len(), 2);
    let c = &f.cameras[1];
    assert_eq!(c.size, Some(ImageSize::new(512, 512)));
    match &c.model {
        CameraModel::DoubleSphere { k, xi, alpha } => {
            assert_eq!(k.fx, 157.91830144176309);
            assert_eq!(*xi, -0.17114780716007858);
            assert_eq!(*alpha, 0.5925543396658507);
        }
        m => panic!("{m:?}"),
    }
    // T_imu_cam of cam0 is inverted: camera_from_imu * (p of the camera in the IMU) = 0
    let t = f.cameras[0].camera_from_imu.unwrap();
    let p = [
        0.04548094812071685,
        -0.07145370002838907,
        -0.046315428444919249,
    ];
    for row in t.iter().take(3) {
        let v: f64 = row[0] * p[0] + row[1] * p[1] + row[2] * p[2] + row[3];
        assert!(v.abs() < 1e-12);
    }
    let e = read("calib/basalt__euroc_eucm_calib.json");
    assert!(
        matches!(e.cameras[0].model, CameraModel::Eucm { beta, .. } if beta == 1.127468196965374)
    );
    assert_eq!(e.cameras[0].size, Some(ImageSize::new(752, 480)));
    let t265 = read("calib/basalt__t265_kb4_calib.json");
    assert!(
        matches!(t265.cameras[0].model, CameraModel::KannalaBrandt { coeffs, .. } if coeffs[3] == 0.008374959821591333)
    );
    for name in [
        "calib/basalt__euroc_ds_calib.json",
        "calib/basalt__tumvi_512_eucm_calib.json",
    ] {
        assert_eq!(read(name).cameras.len(), 2);
    }
}

#[test]
fn kalibr_camchains_of_every_model() {
    let f = read("calib/dm-vio__tumvi_calib__camchain.yaml");
    assert_eq!(f.format, CalibrationFormat::KalibrCamchain);
    assert_eq!(f.cameras.len(), 2);
    match &f.cameras[0].model {
        CameraModel::EquiDistant { k, coeffs } => {
            assert_eq!(k.fx, 190.97847715128717);
            assert_eq!(coeffs[3], 0.00020293673591811182);
        }
        m => panic!("{m:?}"),
    }
    let t = f.cameras[0].camera_from_imu.unwrap();
    assert_eq!(t[1][3], -0.047443232143367084);
    // 4Seasons: a top-level T_cam1_cam0 next to the cameras
    let s = read("calib/dm-vio__4seasons_calib__camchain.yaml");
    assert_eq!(s.cameras.len(), 2);
    assert_eq!(s.cameras[0].size, Some(ImageSize::new(800, 400)));
    let omni = read("calib/kalibr-wiki__Yaml-formats__chain.yaml");
    match &omni.cameras[1].model {
        CameraModel::Unified { k, xi, coeffs } => {
            assert_eq!(*xi, 0.7476616047651173);
            assert_eq!(k.cx, 376.61967341034676);
            assert_eq!(coeffs[0], -0.34330808866302887);
        }
        m => panic!("{m:?}"),
    }
    let k = read("calib/kalibr__working_directory__camchain-imucam-camera_imu.yaml");
    assert_eq!(k.cameras.len(), 1);
}

#[test]
fn euroc_sensor_yaml_and_kitti_calib() {
    let f = read("calib/scratch_slam__mav0__cam0__sensor.yaml");
    assert_eq!(f.format, CalibrationFormat::EurocSensor);
    match &f.cameras[0].model {
        CameraModel::RadTan { k, coeffs } => {
            assert_eq!((k.fx, k.cy), (458.654, 248.375));
            assert_eq!(coeffs[3], 1.76187114e-05);
        }
        m => panic!("{m:?}"),
    }
    // T_BS is body_from_sensor: its inverse maps the camera's position in the body to 0
    let t = f.cameras[0].camera_from_imu.unwrap();
    let p = [-0.0216401454975, -0.064676986768, 0.00981073058949];
    for row in t.iter().take(3) {
        let v: f64 = row[0] * p[0] + row[1] * p[1] + row[2] * p[2] + row[3];
        assert!(v.abs() < 1e-9);
    }
    let k = read("heads/kitti__sequences_00__calib.head.txt");
    assert_eq!(k.format, CalibrationFormat::KittiCalib);
    assert_eq!(k.cameras.len(), 3);
    let c = k.camera_file(0, Some(ImageSize::new(1241, 376))).unwrap();
    assert_eq!(c.input.intrinsics().cx, 607.1928);
    assert!(k.camera_file(0, None).is_err());
    assert!(k.camera(5).unwrap_err().to_string().contains("P0, P1, P2"));
}

#[test]
fn camera_txt_is_still_camera_txt() {
    let f = read("calib/dm-vio__tumvi_calib__camera02.txt");
    assert_eq!(f.format, CalibrationFormat::CameraTxt);
    assert_eq!(
        f.camera_file(0, None).unwrap().output_size,
        ImageSize::new(512, 512)
    );
}

#[test]
fn broken_files_name_the_line() {
    let text = fixture("calib/dm-vio__tumvi_calib__camchain.yaml")
        .replace("intrinsics: [190.97847715128717, ", "intrinsics: [");
    let e = CalibrationFile::parse(&text).unwrap_err().to_string();
    assert!(e.contains("4 intrinsics") && e.starts_with("line "), "{e}");
    let e = CalibrationFile::parse("cam0:\n  intrinsics: [1, 2\n")
        .unwrap_err()
        .to_string();
    assert!(e.contains("YAML"), "{e}");
    let json = fixture("calib/basalt__euroc_ds_calib.json").replace("\"ds\"", "\"weird\"");
    let e = CalibrationFile::parse(&json).unwrap_err().to_string();
    assert!(e.contains("weird") && e.contains("line 2"), "{e}");
    let e = CalibrationFile::parse("P0: 1 2 3\n")
        .unwrap_err()
        .to_string();
    assert!(e.contains("line 1") && e.contains("12 numbers"), "{e}");
}

/// The same 3D points through the same real calibrations as OpenCV projects them
/// (xtask/peers/opencv_models.py: cv2.projectPoints for RadTan, cv2.fisheye for EquiDistant and
/// Kannala-Brandt, cv2.omnidir for the unified omni model with radtan; versions in the file).
/// Tolerance 1e-6 px: both evaluate the same closed-form projection in f64.
#[test]
fn projections_match_opencv() {
    let v: serde_json::Value =
        serde_json::from_str(&fixture("peers/opencv_projections.json")).unwrap();
    let mut worst: std::collections::BTreeMap<String, f64> = Default::default();
    for c in v["cases"].as_array().unwrap() {
        let file = read(c["file"].as_str().unwrap());
        let cam = c["cam"].as_u64().unwrap() as usize;
        let model = &file.cameras[cam].model;
        assert_eq!(model.name(), c["model"].as_str().unwrap());
        let pts = c["points"].as_array().unwrap();
        let pxs = c["pixels"].as_array().unwrap();
        for (p, want) in pts.iter().zip(pxs) {
            let p: Vec<f64> = p
                .as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap())
                .collect();
            let want: Vec<f64> = want
                .as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap())
                .collect();
            let got = model.project([p[0], p[1], p[2]]).unwrap();
            let err = (got[0] - want[0]).hypot(got[1] - want[1]);
            let w = worst.entry(model.name().to_string()).or_default();
            *w = w.max(err);
        }
    }
    eprintln!(
        "largest difference from OpenCV {}, px: {worst:?}",
        v["opencv"]
    );
    assert_eq!(worst.len(), 4);
    for (m, e) in worst {
        assert!(e < 1e-6, "{m}: {e} px");
    }
}
