//! camera.txt parsing and writing.
use crate::common::{dataset_camera, DATASET_CAMERA};
use camera_model::{CameraError, CameraFile, CameraModel, ImageSize, OutputMode};

#[test]
fn legacy_fov_line_is_relative_and_shifted_by_half_a_pixel() {
    let f = dataset_camera();
    let k = f.input.intrinsics();
    assert_eq!(f.input.name(), "FOV");
    assert!((k.fx - 0.535719308086809 * 1280.0).abs() < 1e-12);
    assert!((k.cx - (0.493248545285398 * 1280.0 - 0.5)).abs() < 1e-12);
    assert!((k.cy - (0.500408664348414 * 1024.0 - 0.5)).abs() < 1e-12);
    assert_eq!(f.input_size, ImageSize::new(1280, 1024));
    assert_eq!(f.output, OutputMode::Crop);
    assert_eq!(f.output_size, ImageSize::new(640, 480));
}

#[test]
fn dso_prefixes_and_absolute_values() {
    let f = CameraFile::parse("RadTan 458.654 457.296 367.215 248.375 -0.28 0.07 0.0002 0.00002\n752 480\nfull\n752 480\n").unwrap();
    match f.input {
        CameraModel::RadTan { k, coeffs } => {
            assert_eq!(k.fx, 458.654);
            assert_eq!(k.cx, 367.215);
            assert_eq!(coeffs, [-0.28, 0.07, 0.0002, 0.00002]);
        }
        other => panic!("{other:?}"),
    }
    assert_eq!(f.output, OutputMode::Full);
    for (text, name) in [
        (
            "Pinhole 0.5 0.6 0.5 0.5 0\n640 480\nnone\n640 480",
            "Pinhole",
        ),
        (
            "EquiDistant 0.37 0.37 0.5 0.5 0.01 0 0 0\n512 512\ncrop\n512 512",
            "EquiDistant",
        ),
        (
            "KannalaBrandt 0.37 0.37 0.5 0.5 0.01 0 0 0\r\n512 512\r\ncrop\r\n512 512\r\n",
            "KannalaBrandt",
        ),
        (
            "FOV 0.5 0.6 0.5 0.5 0.9\n640 480\n0.4 0.5 0.5 0.5 0\n640 480\n\n\n",
            "FOV",
        ),
        ("0.5 0.6 0.5 0.5 0\n640 480\ncrop\n640 480", "Pinhole"),
        (
            "300 300 320 240 -0.1 0.01 0 0\n640 480\ncrop\n640 480",
            "RadTan",
        ),
    ] {
        let f = CameraFile::parse(text).unwrap_or_else(|e| panic!("{text}: {e}"));
        assert_eq!(f.input.name(), name, "{text}");
    }
}

#[test]
fn explicit_output_pinhole_and_two_line_files() {
    let f = CameraFile::parse("FOV 0.5 0.6 0.5 0.5 0.9\n640 480\n0.4 0.5 0.5 0.5 0\n320 240\n")
        .unwrap();
    assert_eq!(f.output, OutputMode::Pinhole([0.4, 0.5, 0.5, 0.5]));
    let f = CameraFile::parse("FOV 0.5 0.6 0.5 0.5 0.9\n640 480\n").unwrap();
    assert_eq!(f.output, OutputMode::Crop);
    assert_eq!(f.output_size, ImageSize::new(640, 480));
}

fn err_line(text: &str) -> (usize, String) {
    match CameraFile::parse(text) {
        Err(e @ CameraError::Parse { line, .. })
        | Err(e @ CameraError::InvalidValue { line, .. }) => (line, e.to_string()),
        other => panic!("{text:?}: expected a line error, got {other:?}"),
    }
}

#[test]
fn malformed_files_name_the_line_and_what_was_expected() {
    assert_eq!(err_line("").0, 1);
    assert_eq!(err_line("FOV 1 2 3\n640 480\ncrop\n640 480").0, 1);
    assert_eq!(
        err_line("FOV 0,5 0,6 0,5 0,5 0,9\n640 480\ncrop\n640 480").0,
        1
    );
    assert_eq!(err_line("Fisheye 1 2 3 4 5\n640 480\ncrop\n640 480").0, 1);
    assert_eq!(err_line("1 2 3 4 5 6\n640 480\ncrop\n640 480").0, 1);
    assert_eq!(
        err_line("FOV 0.5 0.6 0.5 0.5 nan\n640 480\ncrop\n640 480").0,
        1
    );
    assert_eq!(
        err_line("FOV -0.5 0.6 0.5 0.5 0.9\n640 480\ncrop\n640 480").0,
        1
    );
    assert_eq!(
        err_line("FOV 0.5 0.6 0.5 0.5 4\n640 480\ncrop\n640 480").0,
        1
    );
    assert_eq!(err_line("FOV 0.5 0.6 0.5 0.5 0.9\n640\ncrop\n640 480").0, 2);
    assert_eq!(
        err_line("FOV 0.5 0.6 0.5 0.5 0.9\n640 x\ncrop\n640 480").0,
        2
    );
    assert_eq!(
        err_line("FOV 0.5 0.6 0.5 0.5 0.9\n0 480\ncrop\n640 480").0,
        2
    );
    assert_eq!(
        err_line("FOV 0.5 0.6 0.5 0.5 0.9\n640 480\ncrap\n640 480").0,
        3
    );
    assert_eq!(
        err_line("FOV 0.5 0.6 0.5 0.5 0.9\n640 480\n1 2 3 4 5\n640 480").0,
        3
    );
    assert_eq!(err_line("FOV 0.5 0.6 0.5 0.5 0.9\n640 480\ncrop\n").0, 4);
    assert_eq!(
        err_line("FOV 0.5 0.6 0.5 0.5 0.9\n640 480\ncrop\n640 -480").0,
        4
    );
    assert_eq!(
        err_line("FOV 0.5 0.6 0.5 0.5 0.9\n640 480\ncrop\n640 480\nextra").0,
        5
    );
    let (_, msg) = err_line("FOV 0,5 0,6 0,5 0,5 0,9\n640 480\ncrop\n640 480");
    assert!(
        msg.contains("line 1") && msg.contains("FOV") && msg.contains("0,5"),
        "{msg}"
    );
}

#[test]
fn written_files_read_back_identically() {
    let f = dataset_camera();
    let again = CameraFile::parse(&f.to_text()).unwrap();
    assert_eq!(again.input.name(), "FOV");
    let (a, b) = (f.input.intrinsics(), again.input.intrinsics());
    for (x, y) in [(a.fx, b.fx), (a.fy, b.fy), (a.cx, b.cx), (a.cy, b.cy)] {
        assert!((x - y).abs() < 1e-9, "{x} {y}");
    }
    assert_eq!(again.output, f.output);
    assert_eq!(again.output_size, f.output_size);
    assert!(DATASET_CAMERA.starts_with("0.535719308086809"));
}

#[test]
fn image_size_parses_the_cli_forms() {
    assert_eq!(
        "640x480".parse::<ImageSize>().unwrap(),
        ImageSize::new(640, 480)
    );
    assert_eq!(
        " 640 480 ".parse::<ImageSize>().unwrap(),
        ImageSize::new(640, 480)
    );
    assert!("640".parse::<ImageSize>().is_err());
    assert!("1x480".parse::<ImageSize>().is_err());
    assert!("-3x4".parse::<ImageSize>().is_err());
}
