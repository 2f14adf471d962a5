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
        | Err(e @ CameraError::InvalidValue { line, .. })
        | Err(e @ CameraError::DecimalComma { line, .. }) => (line, e.to_string()),
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
        err_line("FOV 0.5 0.6 0.5 0.5 0.9\n640 480\n1 2 3\n640 480").0,
        3
    );
    assert_eq!(err_line("FOV 0.5 0.6 0.5 0.5 0.9\n640 480\ncrop\n").0, 4);
    assert_eq!(
        err_line("FOV 0.5 0.6 0.5 0.5 0.9\n640 480\ncrop\n640 -480").0,
        4
    );
    assert_eq!(
        err_line("Pinhole 500 500 320 240\n640 480\ncrop\n640 480").0,
        1
    );
    assert_eq!(err_line("500 500 320 240\n640 480\ncrop\n640 480").0, 1);
    assert_eq!(
        err_line("RadTan 500 500 320 240 0.1 0 0\n640 480\ncrop\n640 480").0,
        1
    );
    assert_eq!(err_line("FOV 0.5 0.6 0.5 0.5 0.9\n640 480\n\n640 480").0, 3);
    let (_, msg) = err_line("FOV 0,5 0,6 0,5 0,5 0,9\n640 480\ncrop\n640 480");
    assert!(
        msg.contains("line 1")
            && msg.contains("FOV")
            && msg.contains("0,5")
            && msg.contains("decimal separator must be '.'"),
        "{msg}"
    );
    // a decimal comma in the 5th number only would make DSO read a pinhole silently
    let (line, msg) = err_line("500 500 320 240 0,9\n640 480\ncrop\n640 480");
    assert!(line == 1 && msg.contains("0,9"), "{msg}");
    let (line, msg) = err_line("FOV 0.5 0.6 0.5 0.5 0.9\n640 480\n0,5 0,5 0,5 0,5 0\n640 480");
    assert!(line == 3 && msg.contains("decimal"), "{msg}");
}

/// DSO reads lines 1-4 only; stereo forks put a baseline on line 5, others a second camera.
#[test]
fn lines_after_line_4_are_ignored_and_listed() {
    let f = CameraFile::parse(
        "Pinhole 718.856 718.856 607.1928 185.2157 0\n1241 376\ncrop\n1241 376\n0.537165\n",
    )
    .unwrap();
    assert_eq!(f.ignored_lines, vec![(5, "0.537165".to_string())]);
    assert!(
        f.warnings.iter().any(|w| w.contains("line 5 is ignored")),
        "{:?}",
        f.warnings
    );
    let f = CameraFile::parse(
        "0.9 1.6 0.25 0.96 0\n1280 720\ncrop\n640 360\n\n0.5 0.5 0.5 0.5 0\n1280 720\ncrop\n640 360\n",
    )
    .unwrap();
    assert_eq!(f.ignored_lines.len(), 4);
    assert_eq!(f.ignored_lines[0].0, 6);
    assert!(f
        .warnings
        .iter()
        .any(|w| w.contains("lines 6-9 are ignored")));
    let plain = CameraFile::parse("0.9 1.6 0.25 0.96 0\n1280 720\ncrop\n640 360\n\n\n").unwrap();
    assert!(plain.ignored_lines.is_empty() && plain.warnings.is_empty());
}

/// Numbers are read like C's sscanf: a model followed by more numbers uses the first ones.
#[test]
fn extra_numbers_are_read_like_dso() {
    // DM-VIO 4Seasons: Pinhole followed by 8 numbers
    let f =
        CameraFile::parse("Pinhole 501.48 501.21 421.23 167.58 0 0 0 0\n800 400\nnone\n800 400\n")
            .unwrap();
    assert_eq!(f.input.name(), "Pinhole");
    assert_eq!(f.input.intrinsics().fx, 501.48);
    assert!(
        f.warnings
            .iter()
            .any(|w| w.contains("`0 0 0` after the 5 numbers")),
        "{:?}",
        f.warnings
    );
    // 6 or 7 legacy numbers: FOV by the 5th, like DSO
    let f = CameraFile::parse("500 500 320 240 0.9 0.1\n640 480\ncrop\n640 480").unwrap();
    assert_eq!(f.input.name(), "FOV");
    // a comma ends the numbers (DM-VIO's M300 file): FOV with omega = |-0.1195|
    let f = CameraFile::parse(
        "547.165 544.955 636.887 478.484 -0.1195, -0.0111\n1280 960\ncrop\n1280 960\n",
    )
    .unwrap();
    match f.input {
        CameraModel::Fov { omega, .. } => assert_eq!(omega, 0.1195),
        other => panic!("{other:?}"),
    }
    assert!(f.warnings.iter().any(|w| w.contains("negative")));
    assert!(f.warnings.iter().any(|w| w.contains("-0.0111")));
    // 9 numbers on a RadTan line: DSO is undefined; a zero k3 is harmless, another is refused
    let f = CameraFile::parse("500 500 350 240 0 0 0 0 0\n752 480\ncrop\n640 480\n").unwrap();
    assert_eq!(f.input.name(), "RadTan");
    assert!(!f.warnings.is_empty());
    let (line, msg) = err_line(
        "0.863 1.550 0.473 0.520 -0.31 -0.24 -0.003 0.004 0.437\r\n640 360\r\ncrop\r\n640 360",
    );
    assert!(line == 1 && msg.contains("0.437"), "{msg}");
    // explicit output: the 5th number is ignored, 4 numbers are enough
    let f =
        CameraFile::parse("FOV 0.5 0.6 0.5 0.5 0.9\n640 480\n0.4 0.5 0.5 0.5 1\n640 480").unwrap();
    assert_eq!(f.output, OutputMode::Pinhole([0.4, 0.5, 0.5, 0.5]));
    assert!(!f.warnings.is_empty());
    let f =
        CameraFile::parse("FOV 0.5 0.6 0.5 0.5 0.9\n640 480\n0.4 0.5 0.5 0.5\n640 480").unwrap();
    assert_eq!(f.output, OutputMode::Pinhole([0.4, 0.5, 0.5, 0.5]));
    // line 2 and 4: two integers, the rest ignored
    let f = CameraFile::parse("FOV 0.5 0.6 0.5 0.5 0.9\n640 480 # raw\ncrop\n640\t480\n").unwrap();
    assert_eq!(f.input_size, ImageSize::new(640, 480));
    assert_eq!(f.warnings.len(), 1);
}

/// A UTF-8 byte-order mark and CRLF line ends do not matter.
#[test]
fn byte_order_mark_and_crlf_are_fine() {
    let plain = CameraFile::parse(DATASET_CAMERA).unwrap();
    let bom =
        CameraFile::parse(&format!("\u{feff}{}", DATASET_CAMERA.replace('\n', "\r\n"))).unwrap();
    assert_eq!(
        (bom.input, bom.output, bom.output_size),
        (plain.input, plain.output, plain.output_size)
    );
    assert!(bom.warnings[0].contains("byte-order mark"));
    let f = CameraFile::parse("\u{feff}RadTan 458.654 457.296 367.215 248.375 -0.28 0.07 0.0002 0.00002\r\n752 480\r\ncrop\r\n752 480\r\n").unwrap();
    assert_eq!(f.input.name(), "RadTan");
    assert_eq!(f.output, OutputMode::Crop);
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
