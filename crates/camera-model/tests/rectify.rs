//! Output cameras (DESIGN.md test vectors) and rectification maps.
use crate::common::{all_models, dataset_camera};
use camera_model::{
    output_intrinsics, output_notes, CameraError, CameraModel, Image, ImageSize, Intrinsics,
    OutputMode, RectifyMap,
};

/// DESIGN.md: the dataset camera at 1280x1024 to 640x480. Tolerance 1e-3 px, the precision
/// the reference numbers are given to.
#[test]
fn fov_crop_and_full_match_the_reference_test_vectors() {
    let f = dataset_camera();
    let out = ImageSize::new(640, 480);
    let crop = output_intrinsics(&f.input, f.input_size, &OutputMode::Crop, out).unwrap();
    for (got, want) in [
        (crop.fx, 277.524),
        (crop.fy, 291.680),
        (crop.cx, 312.474),
        (crop.cy, 240.036),
    ] {
        assert!((got - want).abs() < 1e-3, "crop: got {got}, want {want}");
    }
    let map = RectifyMap::new(&f.input, f.input_size, crop, out).unwrap();
    assert_eq!(map.invalid_count(), 0, "crop must leave no invalid pixel");
    let full = output_intrinsics(&f.input, f.input_size, &OutputMode::Full, out).unwrap();
    for (got, want) in [
        (full.fx, 214.536),
        (full.fy, 198.679),
        (full.cx, 311.353),
        (full.cy, 240.083),
    ] {
        assert!((got - want).abs() < 1e-3, "full: got {got}, want {want}");
    }
}

/// `full` keeps the whole input field of view: every input border pixel centre lands inside
/// the output image area `[-0.5, W-0.5] x [-0.5, H-0.5]`. Tolerance 0.5 px for the FOV model,
/// whose closed form is the reference tool's (DESIGN.md's test vector): it scales by `W/w`
/// and mixes corner radii, which puts the far corner 0.04 px past the edge at 640x480 and
/// 0.27 px at 320x320; 1e-6 px for the numeric search of the other models.
fn assert_full_keeps_border(model: &CameraModel, size: ImageSize, k: Intrinsics, out: ImageSize) {
    let mut worst: f64 = f64::NEG_INFINITY;
    for x in 0..size.width {
        for y in [0, size.height - 1] {
            let n = model.unproject_normalized([x as f64, y as f64]).unwrap();
            let p = k.normalized_to_pixel(n);
            worst = worst.max(-0.5 - p[0]).max(p[0] - (out.width as f64 - 0.5));
            worst = worst.max(-0.5 - p[1]).max(p[1] - (out.height as f64 - 0.5));
        }
    }
    for y in 0..size.height {
        for x in [0, size.width - 1] {
            let n = model.unproject_normalized([x as f64, y as f64]).unwrap();
            let p = k.normalized_to_pixel(n);
            worst = worst.max(-0.5 - p[0]).max(p[0] - (out.width as f64 - 0.5));
            worst = worst.max(-0.5 - p[1]).max(p[1] - (out.height as f64 - 0.5));
        }
    }
    let tol = if model.name() == "FOV" { 0.5 } else { 1e-6 };
    assert!(
        worst <= tol,
        "{}: border pixel {worst} px outside the output",
        model.name()
    );
}

#[test]
fn crop_has_no_invalid_pixel_and_full_keeps_the_field_of_view_for_every_model() {
    for (model, size) in all_models() {
        for out in [ImageSize::new(640, 480), ImageSize::new(320, 320), size] {
            let crop = output_intrinsics(&model, size, &OutputMode::Crop, out).unwrap();
            let map = RectifyMap::new(&model, size, crop, out).unwrap();
            assert_eq!(map.invalid_count(), 0, "{} crop to {out}", model.name());
            if let Ok(full) = output_intrinsics(&model, size, &OutputMode::Full, out) {
                assert_full_keeps_border(&model, size, full, out);
                // full sees at least as much as crop
                assert!(full.fx <= crop.fx * (out.width as f64 + 1.0) / out.width as f64);
            } else {
                // the fisheye and spherical models see 90 degrees or more at the border
                assert!(matches!(
                    model,
                    CameraModel::EquiDistant { .. }
                        | CameraModel::KannalaBrandt { .. }
                        | CameraModel::DoubleSphere { .. }
                        | CameraModel::Eucm { .. }
                        | CameraModel::Unified { .. }
                ));
            }
        }
    }
}

#[test]
fn none_keeps_the_input_camera_and_passes_the_raw_image_through() {
    let k = Intrinsics {
        fx: 320.0,
        fy: 310.0,
        cx: 319.5,
        cy: 239.5,
    };
    let pin = CameraModel::Pinhole(k);
    let same = output_intrinsics(
        &pin,
        ImageSize::new(640, 480),
        &OutputMode::None,
        ImageSize::new(640, 480),
    )
    .unwrap();
    assert_eq!(same, k);
    let half = output_intrinsics(
        &pin,
        ImageSize::new(640, 480),
        &OutputMode::None,
        ImageSize::new(320, 240),
    )
    .unwrap();
    assert_eq!(
        (half.fx, half.fy, half.cx, half.cy),
        (160.0, 155.0, 159.5, 119.5)
    );
    // a distorted model: K is the input's, the distortion is ignored, the image copied
    let f = dataset_camera();
    let k = output_intrinsics(&f.input, f.input_size, &OutputMode::None, f.input_size).unwrap();
    assert_eq!(k, f.input.intrinsics());
    let map =
        RectifyMap::for_mode(&f.input, f.input_size, &OutputMode::None, f.input_size).unwrap();
    let img = Image::from_fn(1280, 1024, |x, y| ((x * 3 + y * 5) % 251) as u8);
    assert_eq!(map.remap_u8(&img).unwrap(), img);
    let notes = output_notes(&f.input, f.input_size, &OutputMode::None, f.input_size);
    assert!(
        notes.len() == 1 && notes[0].contains("distortion is ignored"),
        "{notes:?}"
    );
    // at another size the image is resized, no pixel is lost
    let map =
        RectifyMap::for_mode(&f.input, f.input_size, &OutputMode::None, f.output_size).unwrap();
    assert_eq!(map.invalid_count(), 0);
    assert_eq!(
        output_notes(&f.input, f.input_size, &OutputMode::None, f.output_size).len(),
        2
    );
    let up = RectifyMap::for_mode(
        &pin,
        ImageSize::new(640, 480),
        &OutputMode::None,
        ImageSize::new(1280, 960),
    )
    .unwrap();
    assert_eq!(up.invalid_count(), 0);
}

#[test]
fn explicit_pinhole_is_relative_to_the_output_size() {
    let f = dataset_camera();
    let out = ImageSize::new(640, 480);
    let k = output_intrinsics(
        &f.input,
        f.input_size,
        &OutputMode::Pinhole([0.5, 0.6, 0.5, 0.5]),
        out,
    )
    .unwrap();
    assert_eq!((k.fx, k.fy, k.cx, k.cy), (320.0, 288.0, 319.5, 239.5));
    let k = output_intrinsics(
        &f.input,
        f.input_size,
        &OutputMode::Pinhole([300.0, 300.0, 320.0, 240.0]),
        out,
    )
    .unwrap();
    assert_eq!((k.fx, k.cx), (300.0, 320.0));
}

/// The remap of a smooth synthetic image equals the analytic function at the analytically
/// projected source position. Tolerance 0.045 at worst: the bilinear interpolation error is
/// at most (|f_xx| + |f_yy|) / 8 = (50/15^2 + 50/21^2) / 8 = 0.042; RMS below 0.02.
#[test]
fn remap_matches_the_analytic_projection() {
    let f = dataset_camera();
    let g = |x: f64, y: f64| 100.0 + 50.0 * (x / 15.0).sin() * (y / 21.0).cos();
    let raw = Image::from_fn(1280, 1024, |x, y| g(x as f64, y as f64) as f32);
    let map =
        RectifyMap::for_mode(&f.input, f.input_size, &OutputMode::Crop, f.output_size).unwrap();
    let out = map.remap_f32(&raw).unwrap();
    let k = map.camera();
    let (mut sum, mut n) = (0.0, 0.0);
    for v in (0..480).step_by(3) {
        for u in (0..640).step_by(3) {
            let src = f
                .input
                .project_normalized(k.pixel_to_normalized([u as f64, v as f64]))
                .unwrap();
            let err = (out.get(u, v).unwrap() as f64 - g(src[0], src[1])).abs();
            assert!(err < 0.045, "({u},{v}) err {err}");
            sum += err * err;
            n += 1.0;
        }
    }
    assert!((sum / n).sqrt() < 0.02);
    // the 8-bit remap agrees with the float one to rounding
    let raw8 = raw.map(|v| v.round() as u8);
    let out8 = map.remap_u8(&raw8).unwrap();
    let outf = map.remap_f32(&raw8.map(|v| v as f32)).unwrap();
    for (a, b) in out8.data().iter().zip(outf.data()) {
        assert!((*a as f32 - b).abs() <= 1.0, "{a} vs {b}");
    }
}

#[test]
fn invalid_pixels_are_zero_or_nan_and_masked() {
    let f = dataset_camera();
    // a very wide explicit pinhole sees beyond the raw image
    let map = RectifyMap::for_mode(
        &f.input,
        f.input_size,
        &OutputMode::Pinhole([0.1, 0.1, 0.5, 0.5]),
        ImageSize::new(64, 48),
    )
    .unwrap();
    assert!(map.invalid_count() > 0);
    let mask = map.valid_mask();
    let out = map.remap_u8(&Image::filled(1280, 1024, 200u8)).unwrap();
    let outf = map.remap_f32(&Image::filled(1280, 1024, 2.0f32)).unwrap();
    let mut invalid = 0;
    for i in 0..64 * 48 {
        if mask.data()[i] {
            assert_eq!(out.data()[i], 200);
            assert!((outf.data()[i] - 2.0).abs() < 1e-6);
        } else {
            invalid += 1;
            assert_eq!(out.data()[i], 0);
            assert!(outf.data()[i].is_nan());
        }
    }
    assert_eq!(invalid, map.invalid_count());
    assert!(mask.get(32, 24).unwrap());
    assert!(!mask.get(0, 0).unwrap());
}

#[test]
fn remap_refuses_images_of_the_wrong_size() {
    let f = dataset_camera();
    let map = RectifyMap::for_mode(
        &f.input,
        f.input_size,
        &OutputMode::Crop,
        ImageSize::new(64, 48),
    )
    .unwrap();
    let e = map.remap_u8(&Image::filled(640, 480, 0u8)).unwrap_err();
    assert!(matches!(
        e,
        CameraError::ImageSizeMismatch {
            width: 1280,
            height: 1024,
            ..
        }
    ));
    assert!(RectifyMap::for_mode(
        &f.input,
        f.input_size,
        &OutputMode::Crop,
        ImageSize::new(1, 48)
    )
    .is_err());
}

/// Borders: source coordinates exactly at w-1 / h-1 are valid and interpolate to the last pixel.
#[test]
fn identity_map_reproduces_the_image_exactly() {
    let k = Intrinsics {
        fx: 50.0,
        fy: 50.0,
        cx: 15.5,
        cy: 9.5,
    };
    let m = CameraModel::Pinhole(k);
    let size = ImageSize::new(32, 20);
    let map = RectifyMap::for_mode(&m, size, &OutputMode::None, size).unwrap();
    assert_eq!(map.invalid_count(), 0);
    let img = Image::from_fn(32, 20, |x, y| (x * 7 + y * 3) as u8);
    assert_eq!(map.remap_u8(&img).unwrap(), img);
    let img16 = Image::from_fn(32, 20, |x, y| (x * 2000 + y * 7) as u16);
    assert_eq!(map.remap_u16(&img16).unwrap(), img16);
    // crop and full of a pinhole at the input size are the identity too
    for mode in [OutputMode::Crop, OutputMode::Full] {
        let map = RectifyMap::for_mode(&m, size, &mode, size).unwrap();
        assert_eq!(map.camera(), k);
        assert_eq!(map.remap_u8(&img).unwrap(), img, "{mode}");
    }
}

/// Pinhole cameras whose round trip lands a hair outside the image: nothing may go black.
#[test]
fn pinhole_maps_have_no_black_border() {
    for (k, size) in [
        // KITTI-like and EuRoC-like absolute pinholes
        (
            Intrinsics {
                fx: 718.856,
                fy: 718.856,
                cx: 607.1928,
                cy: 185.2157,
            },
            ImageSize::new(1241, 376),
        ),
        (
            Intrinsics {
                fx: 458.654,
                fy: 457.296,
                cx: 367.215,
                cy: 248.375,
            },
            ImageSize::new(752, 480),
        ),
        (
            Intrinsics {
                fx: 0.1 * 1280.0 + 0.3,
                fy: 913.1,
                cx: 0.7 * 1279.0 / 3.0,
                cy: 0.1,
            },
            ImageSize::new(1280, 720),
        ),
    ] {
        let m = CameraModel::Pinhole(k);
        let img = Image::from_fn(size.width, size.height, |x, y| {
            ((x * 7 + y * 13) % 256) as u8
        });
        let map = RectifyMap::for_mode(&m, size, &OutputMode::None, size).unwrap();
        assert_eq!(map.remap_u8(&img).unwrap(), img);
        for out in [
            ImageSize::new(1920, 704),
            ImageSize::new(640, 480),
            ImageSize::new(3000, 2000),
            size,
        ] {
            for mode in [OutputMode::Crop, OutputMode::Full, OutputMode::None] {
                let map = RectifyMap::for_mode(&m, size, &mode, out).unwrap();
                assert_eq!(map.invalid_count(), 0, "{k:?} {mode} {out}");
            }
        }
    }
}

/// `crop` of the distorted models finds every side to its exact limit: moving any one side
/// outward by a millionth leaves an output pixel without a source.
#[test]
fn crop_sides_are_each_at_their_exact_limit() {
    for (model, size) in all_models() {
        if model.is_pinhole() || matches!(model, CameraModel::Fov { .. }) {
            continue;
        }
        for out in [ImageSize::new(640, 480), size] {
            let k = output_intrinsics(&model, size, &OutputMode::Crop, out).unwrap();
            let rect = [
                -k.cx / k.fx,
                (out.width as f64 - 1.0 - k.cx) / k.fx,
                -k.cy / k.fy,
                (out.height as f64 - 1.0 - k.cy) / k.fy,
            ];
            for side in 0..4 {
                let mut r = rect;
                r[side] *= 1.0 + 1e-6;
                let fx = (out.width as f64 - 1.0) / (r[1] - r[0]);
                let fy = (out.height as f64 - 1.0) / (r[3] - r[2]);
                let grown = Intrinsics {
                    fx,
                    fy,
                    cx: -r[0] * fx,
                    cy: -r[2] * fy,
                };
                let map = RectifyMap::new(&model, size, grown, out).unwrap();
                assert!(
                    map.invalid_count() > 0,
                    "{} to {out}: side {side} could grow",
                    model.name()
                );
            }
        }
    }
}

/// A half-size frame whose pixel `(i, j)` holds the full frame's value at `(2i + 1/2, 2j +
/// 1/2)`, the centre of its 2x2 block (a DCT-domain half-size decode). On a linear ramp,
/// bilinear sampling is exact, so the half-input map must give the full map's values (the
/// source coordinate itself, for a ramp in x and one in y) wherever the source is at least a
/// full pixel inside the border (nearer, it samples the half frame's border). Tolerance 1e-3
/// px (f32 rounding of coordinates up to 1280); a source off by a quarter pixel, the
/// centre convention's size, would fail it. The same pixels are valid in both, for every
/// model and for crop and full.
#[test]
fn the_half_input_map_samples_the_same_points_as_the_full_map() {
    for (model, size) in all_models() {
        let out = ImageSize::new(size.width / 2 - 3, size.height / 2 - 5);
        let (hw, hh) = (size.width.div_ceil(2), size.height.div_ceil(2));
        let ramps = |axis: usize| {
            let coord = |x: f64, y: f64| (if axis == 0 { x } else { y }) as f32;
            let full = Image::new(
                size.width,
                size.height,
                (0..size.pixels())
                    .map(|p| coord((p % size.width) as f64, (p / size.width) as f64))
                    .collect(),
            )
            .unwrap();
            let half = Image::new(
                hw,
                hh,
                (0..hw * hh)
                    .map(|p| coord(2.0 * (p % hw) as f64 + 0.5, 2.0 * (p / hw) as f64 + 0.5))
                    .collect(),
            )
            .unwrap();
            (full, half)
        };
        let (fx, hx) = ramps(0);
        let (fy, hy) = ramps(1);
        for mode in [OutputMode::Crop, OutputMode::Full] {
            let Ok(full) = RectifyMap::for_mode(&model, size, &mode, out) else {
                continue; // `full` of a camera that sees 90 degrees or more: refused alike
            };
            let half = RectifyMap::for_mode_half_input(&model, size, &mode, out).unwrap();
            assert_eq!(half.camera(), full.camera(), "{} {mode}", model.name());
            assert_eq!(half.invalid_count(), full.invalid_count());
            assert_eq!(half.input_size(), ImageSize::new(hw, hh));
            let (ax, bx) = (full.remap_f32(&fx).unwrap(), half.remap_f32(&hx).unwrap());
            let (ay, by) = (full.remap_f32(&fy).unwrap(), half.remap_f32(&hy).unwrap());
            let mut compared = 0;
            for p in 0..out.pixels() {
                let (x, y) = (ax.data()[p], ay.data()[p]);
                assert_eq!(x.is_nan(), bx.data()[p].is_nan());
                let inside = x >= 1.0
                    && x <= size.width as f32 - 2.0
                    && y >= 1.0
                    && y <= size.height as f32 - 2.0;
                if x.is_finite() && inside {
                    let (ex, ey) = ((x - bx.data()[p]).abs(), (y - by.data()[p]).abs());
                    assert!(
                        ex < 1e-3 && ey < 1e-3,
                        "{} {mode}: source ({x}, {y}), from the half frame ({}, {})",
                        model.name(),
                        bx.data()[p],
                        by.data()[p]
                    );
                    compared += 1;
                }
            }
            assert!(compared > out.pixels() / 2, "{compared}");
        }
    }
}

/// Half-size decoding is for outputs of at most half the input, and never for `none`.
#[test]
fn the_half_input_map_refuses_an_output_larger_than_half_the_input() {
    let f = dataset_camera();
    for (mode, out) in [
        (OutputMode::Crop, ImageSize::new(641, 480)),
        (OutputMode::Crop, ImageSize::new(640, 513)),
        (OutputMode::None, ImageSize::new(1280, 1024)),
    ] {
        let e = RectifyMap::for_mode_half_input(&f.input, f.input_size, &mode, out)
            .unwrap_err()
            .to_string();
        assert!(e.contains("half") && e.contains("640x512"), "{e}");
    }
    assert!(RectifyMap::for_mode_half_input(
        &f.input,
        f.input_size,
        &OutputMode::Crop,
        ImageSize::new(640, 512)
    )
    .is_ok());
}
