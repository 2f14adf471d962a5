//! The vignette stage of bench-synthetic: calibrations of synthetic marker-plane videos at
//! every noise level, lossless and JPEG, with the true poses and with detected markers,
//! against the truth, with the calibration of the standard errors.

use std::time::Instant;

use anyhow::Result;
use camera_model::{CameraFile, Image, ImageSize, OutputMode, RectifyMap};
use synthetic::plane::{PlaneConfig, PlaneSequence};
use synthetic::sensor::{NoiseLevel, Sensor};

use crate::stages::{peak_rss_mb, reset_peak_rss, MemoryPlaneFrames};
use crate::Figure;

/// One calibration and its errors against the truth.
pub struct RunResult {
    /// RMS relative error of the recommended map.
    pub rms: f64,
    /// RMS relative error of the raw map (valid pixels).
    pub raw_rms: f64,
    /// Fraction of raw pixels valid.
    pub valid: f64,
    /// Recommended-map pixels whose error is within 2 standard errors (fraction).
    pub within: f64,
    /// The same for the raw map.
    pub raw_within: f64,
    /// Chosen smoothing (px).
    pub sigma: f64,
    /// Iterations.
    pub iterations: usize,
    /// Seconds.
    pub seconds: f64,
    /// Peak memory MB.
    pub peak_mb: f64,
    /// Frames with a detected marker (when detecting).
    pub found: usize,
}

fn within(est: &Image<f32>, sd: &Image<f32>, truth: &[f32]) -> f64 {
    let mut ok = 0usize;
    let mut n = 0usize;
    for ((e, s), t) in est.data().iter().zip(sd.data()).zip(truth) {
        if e.is_finite() && s.is_finite() {
            n += 1;
            if (e - t).abs() <= 2.0 * s {
                ok += 1;
            }
        }
    }
    ok as f64 / n.max(1) as f64
}

/// Renders a set and calibrates it, with the true poses or detected markers.
pub fn run(
    seed: u64,
    (w, h, n): (usize, usize, usize),
    sensor: Sensor,
    detect: bool,
    options: &photometric::VignetteOptions,
) -> Result<RunResult> {
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
    let images: Vec<Image<u8>> = (0..n)
        .map(|i| Ok(Image::new(w, h, seq.frame(i)?)?))
        .collect::<Result<_>>()?;
    let cam = CameraFile::parse(&seq.camera.camera_txt((w, h)))?;
    let resp = photometric::InverseResponse::new(seq.response)?;
    let truth = seq.vignette.clone();
    let mut src = MemoryPlaneFrames {
        images: images.into_iter().map(Into::into).collect(),
        seq,
    };
    let mut found = n;
    if detect {
        let map = RectifyMap::for_mode(
            &cam.input,
            cam.input_size,
            &OutputMode::Full,
            cam.input_size,
        )?;
        let k = map.camera();
        let mut keep = Vec::new();
        for i in 0..n {
            let photometric::PlaneImage::U8(image) = &src.images[i] else {
                anyhow::bail!("the synthetic vignette set has 8-bit frames");
            };
            let rect = map.remap_u8(image)?;
            let det: Vec<_> = photometric::marker::detect_markers(&rect)
                .into_iter()
                .filter(|d| d.id == 213)
                .collect();
            let pose = det
                .first()
                .and_then(|d| photometric::marker::marker_pose(&k, &d.corners));
            if let (1, Some(p)) = (det.len(), pose) {
                src.seq.poses[i] = synthetic::plane::PlanePose { r: p.r, t: p.t };
                keep.push(i);
            }
        }
        found = keep.len();
        src.images = keep.iter().map(|&i| src.images[i].clone()).collect();
        src.seq.poses = keep.iter().map(|&i| src.seq.poses[i]).collect();
        src.seq.exposures_ms = keep.iter().map(|&i| src.seq.exposures_ms[i]).collect();
    }
    reset_peak_rss();
    let t0 = Instant::now();
    let cal = photometric::calibrate_vignette(
        &cam.input,
        ImageSize::new(w, h),
        &resp,
        &src,
        options,
        &|_, _| {},
    )?;
    let seconds = t0.elapsed().as_secs_f64();
    let (rms, _) = photometric::vignette_errors(cal.vignette.data(), &truth);
    let (raw_rms, valid) = photometric::vignette_errors(cal.raw.data(), &truth);
    Ok(RunResult {
        rms,
        raw_rms,
        valid,
        within: within(&cal.vignette, &cal.std_error, &truth),
        raw_within: within(&cal.raw, &cal.raw_std_error, &truth),
        sigma: cal.smoothing.sigma_px,
        iterations: cal.iterations,
        seconds,
        peak_mb: peak_rss_mb(),
        found,
    })
}

/// The stage.
pub fn stage(quick: bool) -> Result<Vec<Figure>> {
    println!("stage vignette: synthetic marker-plane videos at every noise level");
    let size = if quick {
        (320, 256, 80)
    } else {
        (640, 512, 150)
    };
    let opts = photometric::VignetteOptions::default();
    let mut configs: Vec<(String, Sensor, bool)> = NoiseLevel::ALL
        .iter()
        .map(|l| (l.name().to_string(), Sensor::preset(*l), false))
        .collect();
    configs.push((
        "high_jpeg".into(),
        Sensor::preset(NoiseLevel::High).with_jpeg(90),
        false,
    ));
    configs.push((
        "high_jpeg_detected".into(),
        Sensor::preset(NoiseLevel::High).with_jpeg(90),
        true,
    ));
    if quick {
        configs.retain(|(n, _, _)| n == "typical" || n == "high_jpeg_detected");
    }
    println!(
        "  {:<20} {:>9} {:>9} {:>7} {:>7} {:>7} {:>6} {:>4} {:>6} {:>6}",
        "sensor", "rec. rms", "raw rms", "valid", "in2sd", "raw2sd", "sigma", "it", "s", "MB"
    );
    let mut figures = Vec::new();
    let (mut win, mut wn) = (0.0f64, 0.0f64);
    for (name, sensor, detect) in configs {
        let r = run(5, size, sensor, detect, &opts)?;
        println!(
            "  {name:<20} {:>8.3}% {:>8.3}% {:>6.1}% {:>6.1}% {:>6.1}% {:>6.1} {:>4} {:>6.1} {:>6.0}",
            100.0 * r.rms,
            100.0 * r.raw_rms,
            100.0 * r.valid,
            100.0 * r.within,
            100.0 * r.raw_within,
            r.sigma,
            r.iterations,
            r.seconds,
            r.peak_mb
        );
        win += r.within + r.raw_within;
        wn += 2.0;
        figures.push(Figure::lower(
            &format!("vignette.{name}.rms_relative_error"),
            r.rms,
            "",
        ));
        figures.push(Figure::lower(
            &format!("vignette.{name}.raw_rms_relative_error"),
            r.raw_rms,
            "",
        ));
        figures.push(Figure {
            key: format!("vignette.{name}.valid_fraction"),
            value: r.valid,
            unit: "",
            lower_is_better: false,
        });
        if detect {
            figures.push(Figure {
                key: "vignette.detected_frame_fraction".into(),
                value: r.found as f64 / size.2 as f64,
                unit: "",
                lower_is_better: false,
            });
        }
        if name == "high_jpeg" || (name == "typical" && size.0 < 640) {
            figures.push(Figure::lower("vignette.seconds", r.seconds, "s"));
            figures.push(Figure::lower(
                "vignette.seconds_per_100_frames",
                r.seconds * 100.0 / size.2.max(1) as f64,
                "s",
            ));
            figures.push(Figure::lower("vignette.peak_rss_mb", r.peak_mb, "MB"));
        }
    }
    let frac = win / wn.max(1.0);
    println!(
        "  standard errors: {:.1}% of the true errors within 2 sigma",
        100.0 * frac
    );
    figures.push(Figure {
        key: "vignette.within_2sigma".into(),
        value: frac,
        unit: "",
        lower_is_better: false,
    });
    figures.push(Figure::lower("vignette.within_2sigma_excess", frac, ""));
    Ok(figures)
}
