//! Exposure ratios, the check of logged exposures and the estimate, on synthetic sequences
//! with auto exposure and injected one-frame log shifts (known truth).
use camera_model::Image;
use photometric::exposure::{
    check_exposures, estimate_exposures, measure_ratio, ExposureMeter, ExposureOptions,
    MeteredFrame, PairRatio, RatioMeasurement, Verdict,
};
use photometric::{InverseResponse, Vignette};
use synthetic::scene::{shift_exposure_log, ExposureMode, SequenceConfig, SyntheticSequence};
use synthetic::sensor::{jpeg_roundtrip, NoiseLevel, Sensor};

/// A 320x240 sequence with auto exposure, walking pace, typical noise, JPEG 90: its truth,
/// its frames as stored, and a meter with the true response and vignette.
fn sequence(seed: u64, frames: usize) -> (SyntheticSequence, Vec<Image<u8>>, ExposureMeter) {
    let (w, h) = (320, 240);
    let seq = SyntheticSequence::new(
        seed,
        SequenceConfig {
            width: w,
            height: h,
            frames,
            sensor: Sensor::preset(NoiseLevel::Typical).with_jpeg(90),
            exposure: ExposureMode::Auto,
            path_length: 0.04 * frames as f64,
            ..SequenceConfig::default()
        },
    );
    let images = (0..frames)
        .map(|i| {
            let stored = jpeg_roundtrip(w, h, &seq.render(i), 90).unwrap();
            Image::new(w, h, stored).unwrap()
        })
        .collect();
    let u = InverseResponse::new(seq.response).unwrap();
    let v = Vignette::from_values(Image::new(w, h, seq.vignette.clone()).unwrap()).unwrap();
    let meter = ExposureMeter::new(&u, Some(&v), (w, h), &ExposureOptions::default()).unwrap();
    (seq, images, meter)
}

fn metered(meter: &ExposureMeter, images: &[Image<u8>]) -> Vec<MeteredFrame> {
    images.iter().map(|f| meter.frame_u8(f).unwrap()).collect()
}

fn consecutive(frames: &[MeteredFrame], opts: &ExposureOptions) -> Vec<RatioMeasurement> {
    frames
        .windows(2)
        .map(|p| measure_ratio(&p[0], &p[1], opts))
        .collect()
}

/// A smooth texture, moved by `(dx, dy)` pixels and exposed `t`, through a linear response.
fn textured(w: usize, h: usize, t: f64, dx: f64, dy: f64) -> Image<u8> {
    Image::from_fn(w, h, |x, y| {
        let v = synthetic::scene::texture(5, (x as f64 + dx) / 30.0, (y as f64 + dy) / 30.0);
        (t * (20.0 + 150.0 * v)).round().clamp(0.0, 255.0) as u8
    })
}

#[test]
fn ratio_of_a_moved_frame_is_accurate_and_antisymmetric() {
    let opts = ExposureOptions::default();
    let meter = ExposureMeter::new(&InverseResponse::linear(), None, (320, 240), &opts).unwrap();
    for (t, dx, dy) in [(1.1, 7.3, -2.6), (0.8, -21.4, 5.2), (1.0, 0.0, 0.0)] {
        let a = meter.frame_u8(&textured(320, 240, 1.0, 0.0, 0.0)).unwrap();
        let b = meter.frame_u8(&textured(320, 240, t, dx, dy)).unwrap();
        let ab = measure_ratio(&a, &b, &opts);
        let ba = measure_ratio(&b, &a, &opts);
        assert!(ab.reliable && ba.reliable, "{ab:?}");
        // 8-bit rounding of values 20..170 limits the accuracy to about 1e-3
        assert!(
            (ab.log_ratio - t.ln()).abs() < 1.5e-3,
            "t {t}: measured {} true {}",
            ab.log_ratio,
            t.ln()
        );
        assert!(
            (ab.log_ratio + ba.log_ratio).abs() < 2e-4,
            "{} {}",
            ab.log_ratio,
            ba.log_ratio
        );
        assert!(
            (ab.shift[0] - dx).abs() < 0.5 && (ab.shift[1] - dy).abs() < 0.5,
            "{:?}",
            ab.shift
        );
        assert!(
            ab.std_error > 0.0 && ab.std_error < 0.002,
            "{}",
            ab.std_error
        );
    }
}

#[test]
fn pairs_that_cannot_be_aligned_are_unreliable_not_wrong() {
    let opts = ExposureOptions::default();
    let meter = ExposureMeter::new(&InverseResponse::linear(), None, (320, 240), &opts).unwrap();
    let a = meter.frame_u8(&textured(320, 240, 1.0, 0.0, 0.0)).unwrap();
    // a different scene: nothing corresponds
    let other = Image::from_fn(320, 240, |x, y| {
        let v = synthetic::scene::texture(99, x as f64 / 30.0, y as f64 / 30.0);
        (20.0 + 150.0 * v).round().clamp(0.0, 255.0) as u8
    });
    let m = measure_ratio(&a, &meter.frame_u8(&other).unwrap(), &opts);
    assert!(!m.reliable, "{m:?}");
    assert!(!m.note.is_empty());
    // black and saturated frames: no usable pixel
    for v in [0u8, 255] {
        let flat = meter.frame_u8(&Image::filled(320, 240, v)).unwrap();
        assert_eq!(flat.usable_fraction(), 0.0);
        let m = measure_ratio(&a, &flat, &opts);
        assert!(!m.reliable && m.log_ratio.is_nan() && m.std_error.is_infinite());
    }
    // frames of another size
    let small = ExposureMeter::new(&InverseResponse::linear(), None, (160, 120), &opts)
        .unwrap()
        .frame_u8(&Image::filled(160, 120, 100))
        .unwrap();
    assert!(!measure_ratio(&a, &small, &opts).reliable);
    assert!(meter.frame_u8(&Image::filled(160, 120, 100)).is_err());
    // too small to measure
    assert!(ExposureMeter::new(&InverseResponse::linear(), None, (20, 20), &opts).is_err());
    // 16-bit frames: a sample beyond the bit depth is an error
    let deep = Image::filled(320, 240, 5000u16);
    assert!(meter.frame_u16(&deep, 12).is_err());
    assert!(meter.frame_u16(&deep, 16).is_ok());
}

/// Recall and precision of the check over several seeds, each sequence with 8 injected
/// one-frame shifts (of at least 2%) and the path's two cuts (where the camera jumps between
/// the loops of the benchmark-like path: pairs that cannot be aligned).
#[test]
fn check_finds_injected_shifts_without_false_alarms() {
    let opts = ExposureOptions::default();
    let (mut hits, mut injected, mut flagged) = (0, 0, 0);
    for seed in 1..=3 {
        let (seq, images, meter) = sequence(seed, 100);
        let ratios = consecutive(&metered(&meter, &images), &opts);
        // the cuts are unreliable pairs
        assert!(
            ratios.iter().filter(|m| !m.reliable).count() <= 4,
            "seed {seed}"
        );
        let (log, shifts) = shift_exposure_log(&seq.exposures_ms, 8, 0.02, seed);
        assert_eq!(shifts.len(), 8);
        let check = check_exposures(&log, &ratios, &opts).unwrap();
        let truth: Vec<usize> = shifts.iter().map(|s| s.frame).collect();
        hits += truth.iter().filter(|k| check.shifted.contains(k)).count();
        injected += truth.len();
        flagged += check.shifted.len();
        // the direction of the shift is found too, and the fix restores the true exposure
        for s in &shifts {
            let c = &check.frames[s.frame];
            if c.verdict.is_shifted() {
                let expected = if s.source < s.frame {
                    Verdict::ShiftedFromPrevious
                } else {
                    Verdict::ShiftedFromNext
                };
                assert_eq!(c.verdict, expected, "seed {seed} frame {}", s.frame);
                let fixed = check.fixed_ms[s.frame];
                let truth = seq.exposures_ms[s.frame];
                assert!((fixed / truth - 1.0).abs() < 0.005, "{fixed} {truth}");
            }
        }
        // the same log without shifts: nothing flagged
        let clean = check_exposures(&seq.exposures_ms, &ratios, &opts).unwrap();
        assert!(clean.shifted.is_empty(), "seed {seed}: {:?}", clean.shifted);
        assert!(
            clean.inconsistent.is_empty(),
            "seed {seed}: {:?}",
            clean.inconsistent
        );
        assert_eq!(clean.log_lag, 0, "{:?}", clean.lag_scores);
        // the whole log one frame late (every frame logs its previous frame's exposure) or
        // early
        let late: Vec<f64> = (0..seq.exposures_ms.len())
            .map(|k| seq.exposures_ms[k.saturating_sub(1)])
            .collect();
        let c = check_exposures(&late, &ratios, &opts).unwrap();
        assert_eq!(c.log_lag, 1, "{:?}", c.lag_scores);
        let early: Vec<f64> = (0..seq.exposures_ms.len())
            .map(|k| seq.exposures_ms[(k + 1).min(seq.exposures_ms.len() - 1)])
            .collect();
        let c = check_exposures(&early, &ratios, &opts).unwrap();
        assert_eq!(c.log_lag, -1, "{:?}", c.lag_scores);
    }
    let recall = hits as f64 / injected as f64;
    let precision = hits as f64 / flagged.max(1) as f64;
    assert!(recall >= 0.95, "recall {recall} ({hits}/{injected})");
    assert!(
        precision >= 0.95,
        "precision {precision} ({hits}/{flagged})"
    );
}

/// Motion blur lowers the confidence of the pairs around the blurred frames; it never flags
/// a frame whose log is right.
#[test]
fn motion_blur_raises_no_false_alarm() {
    let opts = ExposureOptions::default();
    let (seq, mut images, meter) = sequence(4, 60);
    // a strong horizontal blur (21 pixels) on frames 20, 21 and 40
    for k in [20, 21, 40] {
        let img = &images[k];
        let (w, h) = img.size();
        images[k] = Image::from_fn(w, h, |x, y| {
            let (lo, hi) = (x.saturating_sub(10), (x + 10).min(w - 1));
            let s: u32 = (lo..=hi).map(|xx| img.get(xx, y).unwrap_or(0) as u32).sum();
            (s / (hi - lo + 1) as u32) as u8
        });
    }
    let ratios = consecutive(&metered(&meter, &images), &opts);
    let sharp: Vec<f64> = ratios
        .iter()
        .enumerate()
        .filter(|(i, _)| ![19, 20, 21, 39, 40].contains(i))
        .map(|(_, m)| m.std_error)
        .collect();
    let median_sharp = {
        let mut v = sharp.clone();
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    // the standard error grows where the blur is (or the pair is unreliable)
    assert!(ratios[39].std_error > median_sharp, "{ratios:?}");
    let check = check_exposures(&seq.exposures_ms, &ratios, &opts).unwrap();
    assert!(check.shifted.is_empty(), "{:?}", check.shifted);
    // and a shift right at a blurred frame is still not a false alarm elsewhere
    let mut log = seq.exposures_ms.clone();
    log[30] = log[29];
    let check = check_exposures(&log, &ratios, &opts).unwrap();
    assert!(
        check.shifted.iter().all(|&k| k == 30),
        "{:?}",
        check.shifted
    );
}

/// The estimate of a sequence without logged exposures, within the path's exploring loop (no
/// cut): within 1% after the global scale, with honest standard errors.
#[test]
fn estimate_recovers_exposures_to_one_percent() {
    let opts = ExposureOptions::default();
    for seed in [5, 6] {
        let (seq, images, meter) = sequence(seed, 100);
        // frames 16..84 lie between the path's cuts
        let range = 16..84;
        let n = range.len();
        let frames = metered(&meter, &images[range.clone()]);
        let mut pairs = Vec::new();
        for i in 0..n {
            for j in [i + 1, i + 2] {
                if j < n {
                    pairs.push(PairRatio {
                        from: i,
                        to: j,
                        measurement: measure_ratio(&frames[i], &frames[j], &opts),
                    });
                }
            }
        }
        let est = estimate_exposures(n, &pairs, 10.0, &opts).unwrap();
        assert!(est.gaps.is_empty(), "{:?}", est.gaps);
        let mut sorted = est.exposures_ms.clone();
        sorted.sort_by(f64::total_cmp);
        assert!((sorted[n / 2] - 10.0).abs() < 1e-9 || n % 2 == 0);
        let truth = &seq.exposures_ms[range];
        let mut d: Vec<f64> = est
            .exposures_ms
            .iter()
            .zip(truth)
            .map(|(e, t)| (e / t).ln())
            .collect();
        let mut s = d.clone();
        s.sort_by(f64::total_cmp);
        let offset = s[n / 2];
        for x in &mut d {
            *x -= offset;
        }
        let mut abs: Vec<f64> = d.iter().map(|x| x.abs()).collect();
        abs.sort_by(f64::total_cmp);
        assert!(
            abs[n / 2] < 0.01,
            "seed {seed}: median error {}",
            abs[n / 2]
        );
        assert!(
            abs[n - 1] < 0.03,
            "seed {seed}: largest error {}",
            abs[n - 1]
        );
        // errors relative to the anchor within three standard errors (plus 0.1%)
        let da = d[est.anchor];
        for (k, (x, se)) in d.iter().zip(&est.log_std_error).enumerate() {
            assert!(
                (x - da).abs() <= 3.0 * se + 1e-3,
                "seed {seed} frame {k}: {x} {se}"
            );
        }
        assert_eq!(est.log_std_error[est.anchor], 0.0);
    }
}

fn exact_pair(from: usize, to: usize, log: &[f64], se: f64) -> PairRatio {
    PairRatio {
        from,
        to,
        measurement: RatioMeasurement {
            log_ratio: log[to] - log[from],
            std_error: se,
            shift: [0.0; 2],
            tiles: 10,
            pixel_spread: 0.01,
            reliable: true,
            note: String::new(),
        },
    }
}

/// The chain solver against a dense solution: exact ratios give the exposures back, and the
/// standard errors are the square roots of the dense covariance's diagonal.
#[test]
fn estimate_solves_the_chain_exactly() {
    let n = 9;
    let log: Vec<f64> = (0..n).map(|i| (0.3 * i as f64).sin()).collect();
    let mut pairs = Vec::new();
    for i in 0..n - 1 {
        pairs.push(exact_pair(i, i + 1, &log, 0.01 + 0.002 * i as f64));
        if i + 2 < n {
            pairs.push(exact_pair(i, i + 2, &log, 0.02));
        }
    }
    // one outlier pair, which the Huber weights take out
    let mut bad = exact_pair(3, 5, &log, 0.02);
    bad.measurement.log_ratio += 0.5;
    pairs.push(bad);
    // a gap prior so weak that the dense system below may leave it out
    let opts = ExposureOptions {
        gap_prior: 1e3,
        ..ExposureOptions::default()
    };
    let est = estimate_exposures(n, &pairs, 7.0, &opts).unwrap();
    let mut sorted = est.exposures_ms.clone();
    sorted.sort_by(f64::total_cmp);
    assert!((sorted[n / 2] - 7.0).abs() < 1e-9);
    let shift = est.exposures_ms[0].ln() - log[0];
    for (e, l) in est.exposures_ms.iter().zip(&log) {
        assert!((e.ln() - l - shift).abs() < 1e-9, "{e} {l}");
    }
    assert!(est.outliers.contains(&(3, 5)), "{:?}", est.outliers);
    // the dense covariance with the anchor fixed, without the outlier
    let a = est.anchor;
    let idx: Vec<usize> = (0..n).filter(|&i| i != a).collect();
    let mut m = nalgebra::DMatrix::<f64>::zeros(n - 1, n - 1);
    for p in &pairs[..pairs.len() - 1] {
        let w = 1.0 / (p.measurement.std_error * p.measurement.std_error);
        let (i, j) = (
            idx.iter().position(|&k| k == p.from),
            idx.iter().position(|&k| k == p.to),
        );
        if let Some(i) = i {
            m[(i, i)] += w;
        }
        if let Some(j) = j {
            m[(j, j)] += w;
        }
        if let (Some(i), Some(j)) = (i, j) {
            m[(i, j)] -= w;
            m[(j, i)] -= w;
        }
    }
    let cov = m.try_inverse().unwrap();
    for (r, &k) in idx.iter().enumerate() {
        let dense = cov[(r, r)].sqrt();
        let got = est.log_std_error[k];
        assert!(
            (got / dense - 1.0).abs() < 1e-6,
            "frame {k}: {got} vs {dense}"
        );
    }
}

#[test]
fn bad_inputs_are_errors_not_panics() {
    let opts = ExposureOptions::default();
    let m = |r: f64| RatioMeasurement {
        log_ratio: r,
        std_error: 0.001,
        shift: [0.0; 2],
        tiles: 10,
        pixel_spread: 0.01,
        reliable: true,
        note: String::new(),
    };
    assert!(check_exposures(&[1.0], &[], &opts).is_err());
    assert!(check_exposures(&[1.0, 2.0, 3.0], &[m(0.1)], &opts).is_err());
    assert!(check_exposures(&[1.0, 0.0, 3.0], &[m(0.1), m(0.1)], &opts).is_err());
    assert!(check_exposures(&[1.0, f64::NAN, 3.0], &[m(0.1), m(0.1)], &opts).is_err());
    assert!(estimate_exposures(1, &[], 10.0, &opts).is_err());
    assert!(estimate_exposures(3, &[], -1.0, &opts).is_err());
    let backwards = PairRatio {
        from: 2,
        to: 1,
        measurement: m(0.1),
    };
    assert!(estimate_exposures(3, &[backwards], 10.0, &opts).is_err());
    // nothing measured at all: the prior alone, with huge standard errors
    let est = estimate_exposures(4, &[], 10.0, &opts).unwrap();
    assert_eq!(est.gaps, vec![0, 1, 2]);
    assert!(est.exposures_ms.iter().all(|e| (e - 10.0).abs() < 1e-9));
    assert!(est.log_std_error.iter().filter(|s| **s >= 0.99).count() == 3);
    // unreliable everywhere: every frame undecided, no flag
    let mut bad = m(f64::NAN);
    bad.reliable = false;
    let c = check_exposures(
        &[1.0, 2.0, 3.0, 4.0],
        &[bad.clone(), bad.clone(), bad],
        &opts,
    )
    .unwrap();
    assert!(c.shifted.is_empty());
    assert_eq!(c.undecided, vec![0, 1, 2, 3]);
}
