//! Vignette calibration against synthetic marker-plane videos with known truth.
use camera_model::{CameraFile, Image, ImageSize};
use photometric::{
    calibrate_vignette, vignette_errors, InverseResponse, PhotometricError, PlaneFrame,
    PlaneFrames, PlanePose, VignetteCalibration, VignetteOptions,
};
use synthetic::plane::{PlaneConfig, PlaneSequence};
use synthetic::sensor::{NoiseLevel, Sensor};

struct Frames {
    images: Vec<Image<u8>>,
    seq: PlaneSequence,
}

impl PlaneFrames for Frames {
    fn len(&self) -> usize {
        self.images.len()
    }
    fn frame(&self, i: usize) -> Result<PlaneFrame, PhotometricError> {
        let p = self.seq.poses[i];
        Ok(PlaneFrame {
            image: self.images[i].clone(),
            exposure_ms: self.seq.exposures_ms[i],
            pose: PlanePose { r: p.r, t: p.t },
        })
    }
}

fn set(seed: u64, w: usize, h: usize, n: usize, sensor: Sensor) -> Frames {
    let seq = PlaneSequence::new(
        seed,
        PlaneConfig {
            width: w,
            height: h,
            frames: n,
            sensor,
            ..PlaneConfig::default()
        },
    );
    Frames {
        images: (0..n)
            .map(|i| Image::new(w, h, seq.frame(i).unwrap()).unwrap())
            .collect(),
        seq,
    }
}

fn calibrate(f: &Frames) -> Result<VignetteCalibration, PhotometricError> {
    let (w, h) = (f.seq.config.width, f.seq.config.height);
    let cam = CameraFile::parse(&f.seq.camera.camera_txt((w, h))).unwrap();
    calibrate_vignette(
        &cam.input,
        ImageSize::new(w, h),
        &InverseResponse::new(f.seq.response).unwrap(),
        f,
        &VignetteOptions::default(),
        &|_, _| {},
    )
}

/// High noise and JPEG on a set of CI size (the 640x512 x 150 set runs in `cargo
/// xtask bench-synthetic`): the recommended map within 0.15% RMS, the raw map within 0.8%
/// (fewer frames see each pixel here than in the full set), the standard errors calibrated,
/// every pixel of the recommended map finite and positive.
#[test]
fn high_noise_jpeg_set_is_accurate_and_its_errors_calibrated() {
    let f = set(
        5,
        240,
        192,
        80,
        Sensor::preset(NoiseLevel::High).with_jpeg(90),
    );
    let cal = calibrate(&f).unwrap();
    let truth = &f.seq.vignette;
    let (rms, _) = vignette_errors(cal.vignette.data(), truth);
    let (raw, valid) = vignette_errors(cal.raw.data(), truth);
    assert!(rms < 0.0015, "recommended {rms}");
    assert!(raw < 0.008 && valid > 0.98, "raw {raw} valid {valid}");
    assert!(cal
        .vignette
        .data()
        .iter()
        .all(|v| v.is_finite() && *v > 0.0));
    assert!(cal.converged, "{:?}", cal.change);
    assert!(cal.smoothing.cross_validated && cal.smoothing.sigma_px > 0.0);
    let max = cal.vignette.data().iter().copied().fold(0.0f32, f32::max);
    assert!((max - 1.0).abs() < 1e-6);
    for (est, sd) in [
        (&cal.vignette, &cal.std_error),
        (&cal.raw, &cal.raw_std_error),
    ] {
        let (mut ok, mut n) = (0usize, 0usize);
        for ((e, s), t) in est.data().iter().zip(sd.data()).zip(truth) {
            if e.is_finite() {
                n += 1;
                ok += usize::from((e - t).abs() <= 2.0 * s);
            }
        }
        let frac = ok as f64 / n as f64;
        assert!(
            (0.85..=0.995).contains(&frac),
            "{frac} of the pixels within 2 sigma"
        );
    }
}

/// Threads change nothing: the same bits with one and with two threads (the frames are
/// split into the same jobs and their sums added in the same order).
#[test]
fn results_do_not_depend_on_the_number_of_threads() {
    let f = set(9, 160, 128, 40, Sensor::preset(NoiseLevel::Typical));
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| calibrate(&f).unwrap())
    };
    let (a, b) = (run(1), run(2));
    let bits = |i: &Image<f32>| i.data().iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    assert!(bits(&a.vignette) == bits(&b.vignette), "vignette");
    assert!(bits(&a.raw) == bits(&b.raw), "raw map");
    assert!(bits(&a.std_error) == bits(&b.std_error), "standard error");
    assert_eq!(a.counts.data(), b.counts.data());
    assert_eq!(
        (a.iterations, a.outliers, a.smoothing.sigma_px.to_bits()),
        (b.iterations, b.outliers, b.smoothing.sigma_px.to_bits())
    );
}

/// A corner that never sees the plane is refused, not invented.
#[test]
fn an_uncovered_corner_is_refused() {
    let mut f = set(6, 160, 128, 30, Sensor::preset(NoiseLevel::Low));
    // the plane three times as far away: it fills only the middle of the image
    for p in f.seq.poses.iter_mut() {
        p.t = [p.t[0] * 3.0, p.t[1] * 3.0, p.t[2] * 3.0];
    }
    f.images = (0..30)
        .map(|i| Image::new(160, 128, f.seq.frame(i).unwrap()).unwrap())
        .collect();
    let e = calibrate(&f).unwrap_err();
    assert!(e.to_string().contains("corner"), "{e}");
}

#[test]
fn no_frames_no_plane_bad_exposure() {
    let mut f = set(7, 64, 48, 4, Sensor::preset(NoiseLevel::Low));
    f.images.clear();
    let e = calibrate(&f).unwrap_err();
    assert!(e.to_string().contains("at least one frame"), "{e}");
    let mut f = set(7, 64, 48, 4, Sensor::preset(NoiseLevel::Low));
    f.seq.exposures_ms[2] = 0.0;
    let e = calibrate(&f).unwrap_err();
    assert!(matches!(e, PhotometricError::Exposure(_)), "{e}");
    let mut f = set(7, 64, 48, 4, Sensor::preset(NoiseLevel::Low));
    // the camera looks away from the plane
    for p in f.seq.poses.iter_mut() {
        p.t = [0.0, 0.0, -3.0];
    }
    let e = calibrate(&f).unwrap_err();
    assert!(e.to_string().contains("plane"), "{e}");
}
