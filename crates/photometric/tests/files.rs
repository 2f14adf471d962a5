//! pcalib.txt and vignette maps.
use camera_model::Image;
use photometric::{InverseResponse, PhotometricError, Vignette};
use synthetic::camera::ground_truth_response;

#[test]
fn pcalib_round_trips_at_full_precision() {
    let u = InverseResponse::new(ground_truth_response()).unwrap();
    let text = u.to_text();
    assert_eq!(text.lines().count(), 1);
    let back = InverseResponse::parse(&text).unwrap();
    assert_eq!(back, u);
    // several lines are fine too
    let multi = text.replace(' ', "\n");
    assert_eq!(InverseResponse::parse(&multi).unwrap(), u);
}

#[test]
fn bad_pcalib_is_refused_with_the_reason() {
    let mut vals: Vec<String> = (0..256).map(|k| k.to_string()).collect();
    vals[17] = "nan".into();
    let e = InverseResponse::parse(&vals.join(" ")).unwrap_err();
    assert!(
        matches!(e, PhotometricError::NotFinite { index: 17, .. }),
        "{e}"
    );
    let mut vals: Vec<String> = (0..256).map(|k| k.to_string()).collect();
    vals[100] = "98.5".into();
    let e = InverseResponse::parse(&vals.join(" ")).unwrap_err();
    assert!(
        matches!(e, PhotometricError::NotIncreasing { index: 100, .. }),
        "{e}"
    );
    assert!(e.to_string().contains("U(100)"));
    let e = InverseResponse::parse("1 2 3").unwrap_err();
    assert!(e.to_string().contains("3 numbers"), "{e}");
    let e = InverseResponse::parse(&format!(
        "{} x",
        (0..255)
            .map(|k| k.to_string())
            .collect::<Vec<_>>()
            .join(" ")
    ))
    .unwrap_err();
    assert!(matches!(e, PhotometricError::Parse { line: 1, .. }));
    let e = InverseResponse::parse(
        &(0..257)
            .map(|k| k.to_string())
            .collect::<Vec<_>>()
            .join(" "),
    )
    .unwrap_err();
    assert!(e.to_string().contains("more"), "{e}");
}

#[test]
fn vignette_is_normalised_and_zero_pixels_are_masked() {
    let img = Image::from_fn(
        8,
        6,
        |x, _| if x == 0 { 0u16 } else { 1000 + x as u16 * 100 },
    );
    let v = Vignette::from_u16(&img).unwrap();
    assert_eq!(v.values().get(7, 3), Some(1.0));
    assert_eq!(v.masked(), 6);
    assert!((v.min_positive() - 1100.0 / 1700.0).abs() < 1e-6);
    assert_eq!(v.to_u16().get(7, 0), Some(65535));
    assert!(Vignette::from_u16(&Image::filled(4, 4, 0u16)).is_err());
    assert!(Vignette::from_values(Image::filled(4, 4, f32::NAN)).is_err());
    assert!(v.check_size(8, 6).is_ok() && v.check_size(6, 8).is_err());
}

#[test]
fn response_errors_are_scale_aware() {
    let truth = ground_truth_response();
    let u = InverseResponse::new(truth).unwrap();
    assert_eq!(u.errors_against(&truth), (0.0, 0.0));
    // a scaled copy has a max error but no RMS error after the best scale
    let scaled = InverseResponse::new(truth.map(|v| v * 1.05)).unwrap();
    let (max, rms) = scaled.errors_against(&truth);
    assert!((max - 0.05 * truth[254]).abs() < 1e-9, "{max}");
    assert!(rms < 1e-9, "{rms}");
}
