//! Response calibration of sensors deeper than 8 bits (10 to 16 bits in 16-bit samples)
//! against synthetic sweeps with known truth.
use camera_model::Image;
use photometric::{
    calibrate_response_deep, PhotometricError, ResponseCalibration, ResponseOptions,
};
use synthetic::camera::ResponseCurve;
use synthetic::scene::Sweep;

use crate::response::sweep;
use synthetic::sensor::{NoiseLevel, Sensor};

fn frames(s: &Sweep, bits: u32) -> Vec<Image<u16>> {
    (0..s.exposures_ms.len())
        .map(|i| Image::new(s.width, s.height, s.render_deep(i, bits)).unwrap())
        .collect()
}

fn calibrate(s: &Sweep, bits: u32) -> ResponseCalibration {
    calibrate_response_deep(
        &frames(s, bits),
        bits,
        &s.exposures_ms,
        &ResponseOptions::default(),
        &|_, _| {},
    )
    .unwrap()
}

/// Largest relative error `|U - U_true| / U_true` over the observed range from 1% of the
/// range up (below it a relative error says little: 0.005 of 255 at 8/4095 of an sRGB toe is
/// 12%), and the largest error in 8-bit grey levels (`U` scaled to 255) over all values.
fn errors(cal: &ResponseCalibration, truth: &[f64]) -> (f64, f64) {
    let u = cal.response.table();
    assert_eq!(u.len(), truth.len());
    let (lo, hi) = cal.observed_range;
    let rel = (lo as usize..=hi as usize)
        .filter(|&v| truth[v] > 2.55)
        .map(|v| (u[v] - truth[v]).abs() / truth[v])
        .fold(0.0f64, f64::max);
    let abs = u
        .iter()
        .zip(truth)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f64, f64::max);
    (rel, abs)
}

/// The goal at CI size: a 12-bit sweep of 120 frames calibrates to a relative error of
/// `U` below 0.5% over the observed range, at every noise level, for curves with a toe
/// (dataset), the sRGB curve and a log encoding. (A pure power such as gamma 1.8 has
/// `U'(0) = 0`: there the read noise, which enters before the response, makes the mean grey
/// value of the darkest observations lower than `G(t B')`, and `U` near black is biased by
/// about `(1 - 1/gamma) sigma_read^2 / (2 U)`: 0.004 of 255 with the low-noise sensor, a
/// relative error of a few percent below 2% of the range; see the last test.)
#[test]
fn twelve_bit_sweep_is_accurate_to_half_a_percent() {
    for (seed, level, curve) in [
        (1, NoiseLevel::Typical, ResponseCurve::Dataset),
        (2, NoiseLevel::High, ResponseCurve::Dataset),
        (3, NoiseLevel::Low, ResponseCurve::Srgb),
        (4, NoiseLevel::Typical, ResponseCurve::Log),
    ] {
        let s = sweep(seed, 320, 256, 120, Sensor::preset(level), curve);
        let cal = calibrate(&s, 12);
        let truth = s.response_bits(12);
        let (rel, abs) = errors(&cal, &truth);
        eprintln!(
            "{level} {curve}: observed {:?}, max relative error {:.4}%, max {abs:.4} (of 255), {} iterations",
            cal.observed_range,
            rel * 100.0,
            cal.iterations
        );
        assert!(rel < 0.005, "{level} {curve}: {rel}");
        assert_eq!(cal.response.table().len(), 4096);
        assert_eq!(cal.response.bits(), 12);
        assert!(cal.observed_range.1 > 3500, "{:?}", cal.observed_range);
    }
}

/// A pure power response (`U'(0) = 0`) at 12 bits: the error stays below 0.1 of 255
/// everywhere (its largest part sits just below saturation, where each pixel has few
/// exposures left before it clips) and below 0.5% from 5% of the range up.
#[test]
fn twelve_bit_gamma_is_accurate_above_the_toe() {
    let s = sweep(
        3,
        320,
        256,
        120,
        Sensor::preset(NoiseLevel::Low),
        ResponseCurve::Gamma(1.8),
    );
    let cal = calibrate(&s, 12);
    let truth = s.response_bits(12);
    let (_, abs) = errors(&cal, &truth);
    assert!(abs < 0.1, "{abs}");
    let u = cal.response.table();
    let rel = (205..=cal.observed_range.1 as usize)
        .map(|v| (u[v] - truth[v]).abs() / truth[v])
        .fold(0.0f64, f64::max);
    assert!(rel < 0.005, "{rel}");
}

/// 10 and 16 bits: tables of 1024 and 65536 values, accurate to 0.5% over the observed range.
#[test]
fn ten_and_sixteen_bit_sweeps_are_accurate() {
    for (bits, seed) in [(10, 5), (16, 6)] {
        let s = sweep(
            seed,
            240,
            192,
            60,
            Sensor::preset(NoiseLevel::Typical),
            ResponseCurve::Dataset,
        );
        let cal = calibrate(&s, bits);
        let truth = s.response_bits(bits);
        assert_eq!(cal.response.table().len(), 1 << bits);
        let (rel, abs) = errors(&cal, &truth);
        assert!(rel < 0.005 && abs < 1.0, "{bits} bits: {rel} {abs}");
    }
}

/// An 8-bit sweep through the deep entry point gives the 8-bit calibration exactly.
#[test]
fn eight_bits_through_the_deep_entry_is_the_eight_bit_calibration() {
    let s = sweep(
        7,
        160,
        128,
        24,
        Sensor::preset(NoiseLevel::Typical),
        ResponseCurve::Dataset,
    );
    let deep = calibrate(&s, 8);
    let mut narrow: Vec<Image<u8>> = (0..s.exposures_ms.len())
        .map(|i| Image::new(s.width, s.height, s.render(i)).unwrap())
        .collect();
    let cal = photometric::calibrate_response(
        &mut narrow,
        &s.exposures_ms,
        &ResponseOptions::default(),
        &|_, _| {},
    )
    .unwrap();
    assert_eq!(deep.response, cal.response);
    assert_eq!(deep.std_error, cal.std_error);
}

/// Values that do not fit the bit depth are refused with the frame and the value.
#[test]
fn values_above_the_bit_depth_are_refused() {
    let f = Image::new(4, 4, vec![5000u16; 16]).unwrap();
    let e = calibrate_response_deep(
        &[f.clone(), f],
        12,
        &[1.0, 2.0],
        &ResponseOptions::default(),
        &|_, _| {},
    )
    .unwrap_err();
    let text = e.to_string();
    assert!(
        text.contains("frame 0") && text.contains("5000") && text.contains("4095"),
        "{text}"
    );
    let f = Image::new(4, 4, vec![0u16; 16]).unwrap();
    let e = calibrate_response_deep(
        &[f.clone(), f],
        17,
        &[1.0, 2.0],
        &ResponseOptions::default(),
        &|_, _| {},
    )
    .unwrap_err();
    assert!(matches!(e, PhotometricError::BitDepth(17)), "{e}");
}
