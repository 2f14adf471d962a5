//! The correction recovers the irradiance of synthetic frames.
use camera_model::{CameraFile, Image, OutputMode, RectifyMap};
use photometric::{quantize_u8, Correction, InverseResponse, Vignette};
use synthetic::camera::{ground_truth_response, ground_truth_vignette, response_value};

/// Frames made noise-free by the ground-truth model `I = G(t V B)` (continuous, then rounded)
/// are mapped back to `B` within the quantisation error of one grey level.
#[test]
fn correction_inverts_the_image_formation_model() {
    let (w, h) = (80, 60);
    let u = ground_truth_response();
    let vig = ground_truth_vignette(w, h, 3);
    let b =
        |x: usize, y: usize| 2.0 + 10.0 * ((x as f64 * 0.3).sin() * (y as f64 * 0.2).cos()).abs();
    let t = 7.5;
    let frame = Image::from_fn(w, h, |x, y| {
        response_value(&u, t * vig[y * w + x] as f64 * b(x, y)).round() as u8
    });
    let corr = Correction::new(
        &InverseResponse::new(u).unwrap(),
        Some(&Vignette::from_values(Image::new(w, h, vig.clone()).unwrap()).unwrap()),
        None,
        (w, h),
        false,
    )
    .unwrap();
    let out = corr.correct(&frame, Some(t)).unwrap();
    for y in 0..h {
        for x in 0..w {
            let want = b(x, y);
            let got = out.get(x, y).unwrap() as f64;
            // one grey level of U's slope at most, divided by t V
            let k = frame.get(x, y).unwrap() as usize;
            let slope = if k < 255 {
                u[k + 1] - u[k]
            } else {
                u[255] - u[254]
            };
            let tol = 0.5 * slope / (t * vig[y * w + x] as f64) + 1e-6;
            assert!(
                (got - want).abs() <= tol,
                "({x},{y}) {got} vs {want} tol {tol}"
            );
        }
    }
}

#[test]
fn saturated_pixels_and_quantisation() {
    let u = InverseResponse::linear();
    let corr = Correction::new(&u, None, None, (4, 1), true).unwrap();
    let img = Image::new(4, 1, vec![0u8, 10, 254, 255]).unwrap();
    let out = corr.correct(&img, None).unwrap();
    assert_eq!(&out.data()[..3], &[0.0, 10.0, 254.0]);
    assert!(out.data()[3].is_nan());
    assert_eq!(quantize_u8(&out, 0.5).data(), &[0, 5, 127, 0]);
    assert!(corr.correct(&img, Some(0.0)).is_err());
    assert!(corr.correct(&Image::filled(3, 1, 0u8), None).is_err());
}

/// Fused with rectification, the correction equals rectifying the corrected raw frame.
#[test]
fn fused_rectification_equals_correct_then_remap() {
    let cam =
        CameraFile::parse("FOV 0.5357 0.6696 0.4932 0.5004 0.898\n160 128\ncrop\n80 60\n").unwrap();
    let map = RectifyMap::for_mode(
        &cam.input,
        cam.input_size,
        &OutputMode::Crop,
        cam.output_size,
    )
    .unwrap();
    let mut uu = [0.0; 256];
    for (k, v) in uu.iter_mut().enumerate() {
        *v = (k as f64 / 255.0).powf(2.0) * 255.0 + k as f64 * 0.01;
    }
    let u = InverseResponse::new(uu).unwrap();
    let vig = Vignette::from_values(Image::from_fn(160, 128, |x, y| {
        1.0 - 0.002 * ((x as f32 - 80.0).abs() + (y as f32 - 64.0).abs())
    }))
    .unwrap();
    let frame = Image::from_fn(160, 128, |x, y| ((x * 7 + y * 13) % 256) as u8);
    let fused = Correction::new(&u, Some(&vig), Some(map.clone()), (160, 128), false).unwrap();
    let raw = Correction::new(&u, Some(&vig), None, (160, 128), false).unwrap();
    let a = fused.correct(&frame, Some(2.0)).unwrap();
    // remap(U(I)) / remap(V) vs remap(U(I) / V): bilinear interpolation of a product differs
    // from the product of interpolations by at most 2 * (1/4) * max|dU| * max|d(1/V)|
    // (neighbour differences along x and y), divided by the exposure (2 ms); the division by
    // remap(V) instead of remapping 1/V adds a second-order term far below that.
    let b = map
        .remap_f32(&raw.correct(&frame, Some(2.0)).unwrap())
        .unwrap();
    let uf = frame.map(|p| u.get(p) as f32);
    let iv = vig.values().map(|v| 1.0 / v);
    let max_diff = |img: &Image<f32>| {
        let mut m = 0f32;
        for y in 0..img.height() {
            for x in 0..img.width() {
                let p = img.get(x, y).unwrap();
                if let Some(q) = img.get(x + 1, y) {
                    m = m.max((p - q).abs());
                }
                if let Some(q) = img.get(x, y + 1) {
                    m = m.max((p - q).abs());
                }
            }
        }
        m
    };
    let tol = 0.5 * max_diff(&uf) * max_diff(&iv) / 2.0 * 1.1 + 1e-3;
    for (x, y) in a.data().iter().zip(b.data()) {
        assert!((x - y).abs() <= tol, "{x} {y} tol {tol}");
    }
}

/// The fused 16-bit path agrees with the float path followed by quantisation: within one
/// output unit, plus the 16-bit table's rounding (1/65535 of U(255) per tap), plus the 8-bit
/// fixed-point bilinear weights (each within 1/256, times the largest neighbour difference
/// of U, 255 for this saw-tooth frame), all scaled by `scale / (V t)`.
#[test]
fn fused_quantized_path_matches_the_float_path() {
    use photometric::{quantize_u16, QuantizedCorrection};
    let cam =
        CameraFile::parse("FOV 0.5357 0.6696 0.4932 0.5004 0.898\n160 128\ncrop\n80 60\n").unwrap();
    let map = RectifyMap::for_mode(
        &cam.input,
        cam.input_size,
        &OutputMode::Crop,
        cam.output_size,
    )
    .unwrap();
    let u = InverseResponse::new(ground_truth_response()).unwrap();
    let vig =
        Vignette::from_values(Image::new(160, 128, ground_truth_vignette(160, 128, 2)).unwrap())
            .unwrap();
    let frame = Image::from_fn(160, 128, |x, y| ((x * 7 + y * 13) % 256) as u8);
    let scale = 65535.0 * vig.min_positive() / 255.0 * 2.0;
    let slow = Correction::new(&u, Some(&vig), Some(map.clone()), (160, 128), false).unwrap();
    let fast = QuantizedCorrection::new(&u, &vig, map, scale, 16).unwrap();
    let want = quantize_u16(&slow.correct(&frame, Some(2.0)).unwrap(), scale);
    let mut got = Image::filled(80, 60, 0u16);
    fast.apply(&frame, Some(2.0), &mut got).unwrap();
    let gain = scale / vig.min_positive() / 2.0;
    let tol = 1.0 + gain * 255.0 / 65535.0 + gain * 255.0 / 256.0;
    for (a, b) in got.data().iter().zip(want.data()) {
        assert!((*a as f32 - *b as f32).abs() <= tol, "{a} {b} tol {tol}");
    }
}

/// 16-bit frames with an embedded bit depth: a 65536-value response is applied exactly to
/// 16-bit samples, a 4096-value one exactly to 12-bit samples; values beyond the depth are an
/// error, not garbage.
#[test]
fn deep_frames_are_corrected_exactly() {
    let n = 65536usize;
    let table: Vec<f64> = (0..n).map(|i| (i as f64).powf(1.5) + i as f64).collect();
    let u = InverseResponse::from_values(table.clone()).unwrap();
    let (w, h) = (6, 2);
    let vig = Vignette::from_values(Image::from_fn(w, h, |x, _| 1.0 - 0.1 * x as f32)).unwrap();
    let corr = Correction::new(&u, Some(&vig), None, (w, h), false)
        .unwrap()
        .with_bit_depth(&u, 16, false)
        .unwrap();
    let img = Image::from_fn(w, h, |x, y| (x * 10007 + y * 3 + 1) as u16);
    let mut out = Image::filled(w, h, 0f32);
    corr.apply_u16(&img, Some(2.0), &mut out).unwrap();
    for y in 0..h {
        for x in 0..w {
            let want = table[img.get(x, y).unwrap() as usize]
                / (2.0 * vig.values().get(x, y).unwrap() as f64);
            let got = out.get(x, y).unwrap() as f64;
            assert!((got - want).abs() <= 1e-6 * want.max(1.0), "{got} {want}");
        }
    }
    // 12-bit samples with a 4096-value response: exact; a sample of 4096 is refused
    let t12: Vec<f64> = (0..4096).map(|i| 3.0 * i as f64 + 1.0).collect();
    let u12 = InverseResponse::from_values(t12).unwrap();
    let corr = Correction::new(&u12, None, None, (w, h), false)
        .unwrap()
        .with_bit_depth(&u12, 12, false)
        .unwrap();
    let img = Image::from_fn(w, h, |x, y| (x * 700 + y) as u16);
    corr.apply_u16(&img, None, &mut out).unwrap();
    assert_eq!(out.get(5, 1), Some(3.0 * 3501.0 + 1.0));
    let bad = Image::filled(w, h, 4096u16);
    let e = corr.apply_u16(&bad, None, &mut out).unwrap_err();
    assert!(
        e.to_string().contains("4096") && e.to_string().contains("12 bits"),
        "{e}"
    );
    // an 8-bit response on 16-bit samples: full range, 65535 -> U(255)
    let lin = InverseResponse::linear();
    let corr = Correction::new(&lin, None, None, (w, h), false)
        .unwrap()
        .with_bit_depth(&lin, 16, false)
        .unwrap();
    corr.apply_u16(&Image::filled(w, h, 65535u16), None, &mut out)
        .unwrap();
    assert_eq!(out.get(0, 0), Some(255.0));
}

/// The fused path writes 8 or 16 bits; any other depth is an error, never 8 bits in disguise.
#[test]
fn fused_path_refuses_other_output_depths() {
    use photometric::{PhotometricError, QuantizedCorrection};
    let cam =
        CameraFile::parse("FOV 0.5357 0.6696 0.4932 0.5004 0.898\n160 128\ncrop\n80 60\n").unwrap();
    let map = RectifyMap::for_mode(
        &cam.input,
        cam.input_size,
        &OutputMode::Crop,
        cam.output_size,
    )
    .unwrap();
    let u = InverseResponse::new(ground_truth_response()).unwrap();
    for bits in [0u8, 1, 10, 12, 32] {
        assert!(matches!(
            QuantizedCorrection::with_vignette(&u, None, map.clone(), 1.0, bits),
            Err(PhotometricError::OutputDepth(b)) if b == bits
        ));
    }
    assert!(QuantizedCorrection::with_vignette(&u, None, map, 1.0, 8).is_ok());
}
