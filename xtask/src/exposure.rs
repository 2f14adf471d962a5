//! `cargo xtask exposure-study`: the exposure check and estimate on synthetic sequences with
//! auto exposure and injected one-frame log shifts, against the truth: recall and precision
//! of the check, accuracy of the estimate, and the time per frame against the JPEG decode.

use std::time::Instant;

use anyhow::{bail, Context, Result};
use camera_model::Image;
use photometric::exposure::{
    check_exposures, estimate_exposures, measure_ratio, ExposureMeter, ExposureOptions,
    MeteredFrame, PairRatio,
};
use synthetic::scene::{shift_exposure_log, ExposureMode, SequenceConfig, SyntheticSequence};
use synthetic::sensor::{NoiseLevel, Sensor};

/// The settings of one study.
struct StudyConfig {
    seeds: u64,
    frames: usize,
    size: (usize, usize),
    noise: NoiseLevel,
    shifts: usize,
    min_change: f64,
}

/// The outcome on one sequence.
struct SeedResult {
    hits: usize,
    injected: usize,
    flagged: usize,
    /// Median |relative error| of the estimate after the global scale, all frames.
    median_error: f64,
    /// The same within the path's exploring loop (between its two cuts).
    median_error_loop: f64,
    /// RMS error of the reliable consecutive log ratios.
    pair_rms: f64,
    unreliable: usize,
    /// Milliseconds per frame, one thread: decode, check (meter + 1 ratio), estimate
    /// (meter + 2 ratios).
    ms: (f64, f64, f64),
}

fn median_abs_error(est: &[f64], truth: &[f64]) -> f64 {
    let mut d: Vec<f64> = est.iter().zip(truth).map(|(e, t)| (e / t).ln()).collect();
    let mut s = d.clone();
    s.sort_by(f64::total_cmp);
    let offset = s[s.len() / 2];
    for x in &mut d {
        *x = (*x - offset).abs();
    }
    d.sort_by(f64::total_cmp);
    d[d.len() / 2]
}

fn run_seed(seed: u64, c: &StudyConfig, opts: &ExposureOptions) -> Result<SeedResult> {
    let (w, h) = c.size;
    let seq = SyntheticSequence::new(
        seed,
        SequenceConfig {
            width: w,
            height: h,
            frames: c.frames,
            sensor: Sensor::preset(c.noise).with_jpeg(90),
            exposure: ExposureMode::Auto,
            path_length: 0.04 * c.frames as f64,
            ..SequenceConfig::default()
        },
    );
    let jpegs: Vec<Vec<u8>> = {
        use rayon::prelude::*;
        (0..c.frames)
            .into_par_iter()
            .map(|i| Ok(dataset_io::encode_jpeg_gray(w, h, &seq.render(i), 90)?))
            .collect::<Result<_>>()?
    };
    let t = Instant::now();
    let decoded: Vec<Image<u8>> = jpegs
        .iter()
        .map(|b| dataset_io::decode_gray8(b).map_err(anyhow::Error::msg))
        .collect::<Result<_>>()?;
    let decode_s = t.elapsed().as_secs_f64();
    let u = photometric::InverseResponse::new(seq.response)?;
    let v = photometric::Vignette::from_values(Image::new(w, h, seq.vignette.clone())?)?;
    let meter = ExposureMeter::new(&u, Some(&v), (w, h), opts)?;
    let t = Instant::now();
    let metered: Vec<MeteredFrame> = decoded
        .iter()
        .map(|f| meter.frame_u8(f))
        .collect::<Result<_, _>>()?;
    let meter_s = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let consecutive: Vec<_> = (0..c.frames - 1)
        .map(|i| measure_ratio(&metered[i], &metered[i + 1], opts))
        .collect();
    let consecutive_s = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let skip: Vec<_> = (0..c.frames - 2)
        .map(|i| measure_ratio(&metered[i], &metered[i + 2], opts))
        .collect();
    let skip_s = t.elapsed().as_secs_f64();
    let errors: Vec<f64> = consecutive
        .iter()
        .enumerate()
        .filter(|(_, m)| m.reliable)
        .map(|(i, m)| m.log_ratio - (seq.exposures_ms[i + 1] / seq.exposures_ms[i]).ln())
        .collect();
    let pair_rms = (errors.iter().map(|e| e * e).sum::<f64>() / errors.len().max(1) as f64).sqrt();
    let (log, shifts) = shift_exposure_log(&seq.exposures_ms, c.shifts, c.min_change, seed);
    let check = check_exposures(&log, &consecutive, opts)?;
    let truth: Vec<usize> = shifts.iter().map(|s| s.frame).collect();
    let hits = truth.iter().filter(|k| check.shifted.contains(k)).count();
    for k in check.shifted.iter().filter(|k| !truth.contains(k)) {
        let f = &check.frames[*k];
        println!(
            "  seed {seed}: false alarm at frame {k}: logged {:.4} ms, predicted {:.4}, true {:.4}",
            f.logged_ms, f.predicted_ms, seq.exposures_ms[*k]
        );
    }
    for k in truth.iter().filter(|k| !check.shifted.contains(k)) {
        let f = &check.frames[*k];
        println!(
            "  seed {seed}: missed frame {k} ({:?}): logged {:.4} ms, predicted {:.4}, true {:.4} {}",
            f.verdict, f.logged_ms, f.predicted_ms, seq.exposures_ms[*k], f.note
        );
    }
    let est = estimate_exposures(c.frames, &PairRatio::chain(&consecutive, &skip), 10.0, opts)?;
    let median_error = median_abs_error(&est.exposures_ms, &seq.exposures_ms);
    // the exploring loop alone: frames between the path's cuts
    let k = seq.path.segment_frames;
    let inner = k + 1..c.frames - k - 1;
    let inner_pairs: Vec<PairRatio> = PairRatio::chain(&consecutive, &skip)
        .into_iter()
        .filter(|p| inner.contains(&p.from) && inner.contains(&p.to))
        .map(|mut p| {
            p.from -= inner.start;
            p.to -= inner.start;
            p
        })
        .collect();
    let est_inner = estimate_exposures(inner.len(), &inner_pairs, 10.0, opts)?;
    let median_error_loop =
        median_abs_error(&est_inner.exposures_ms, &seq.exposures_ms[inner.clone()]);
    let n = c.frames as f64;
    Ok(SeedResult {
        hits,
        injected: truth.len(),
        flagged: check.shifted.len(),
        median_error,
        median_error_loop,
        pair_rms,
        unreliable: check.unreliable_pairs.len(),
        ms: (
            1e3 * decode_s / n,
            1e3 * (meter_s + consecutive_s) / n,
            1e3 * (meter_s + consecutive_s + skip_s) / n,
        ),
    })
}

fn usage() -> &'static str {
    "usage: cargo xtask exposure-study [--seeds N] [--frames N] [--size WxH] [--noise LEVEL] \
     [--shifts N] [--min-change FRACTION]"
}

/// `cargo xtask exposure-study`.
pub fn study(mut args: impl Iterator<Item = String>) -> Result<()> {
    let mut c = StudyConfig {
        seeds: 5,
        frames: 200,
        size: (640, 480),
        noise: NoiseLevel::Typical,
        shifts: 10,
        min_change: 0.02,
    };
    while let Some(a) = args.next() {
        let mut value = || args.next().with_context(|| format!("{a} needs a value"));
        match a.as_str() {
            "--seeds" => c.seeds = value()?.parse()?,
            "--frames" => c.frames = value()?.parse()?,
            "--shifts" => c.shifts = value()?.parse()?,
            "--min-change" => c.min_change = value()?.parse()?,
            "--noise" => c.noise = value()?.parse().map_err(anyhow::Error::msg)?,
            "--size" => {
                let v = value()?;
                let (a, b) = v.split_once('x').context("--size WxH")?;
                c.size = (a.parse()?, b.parse()?);
            }
            "-h" | "--help" => {
                println!("{}", usage());
                return Ok(());
            }
            other => bail!("unknown argument `{other}`\n{}", usage()),
        }
    }
    if c.frames < 40 || c.seeds == 0 {
        bail!("at least 40 frames and 1 seed");
    }
    let opts = ExposureOptions::default();
    println!(
        "{} seeds, {} frames of {}x{}, {} noise, JPEG 90, auto exposure, {} shifts of at least {:.0}% each",
        c.seeds,
        c.frames,
        c.size.0,
        c.size.1,
        c.noise,
        c.shifts,
        100.0 * c.min_change
    );
    let (mut hits, mut injected, mut flagged) = (0, 0, 0);
    let (mut errors, mut errors_loop) = (Vec::new(), Vec::new());
    let mut ms = (0.0, 0.0, 0.0);
    for seed in 1..=c.seeds {
        let r = run_seed(seed, &c, &opts)?;
        println!(
            "seed {seed}: found {}/{}, flagged {}; pair RMS {:.2e}, {} unreliable pairs; estimate median error {:.3}% ({:.3}% within the loop); ms/frame: decode {:.2}, check {:.2}, estimate {:.2}",
            r.hits,
            r.injected,
            r.flagged,
            r.pair_rms,
            r.unreliable,
            100.0 * r.median_error,
            100.0 * r.median_error_loop,
            r.ms.0,
            r.ms.1,
            r.ms.2
        );
        hits += r.hits;
        injected += r.injected;
        flagged += r.flagged;
        errors.push(r.median_error);
        errors_loop.push(r.median_error_loop);
        ms = (ms.0 + r.ms.0, ms.1 + r.ms.1, ms.2 + r.ms.2);
    }
    let s = c.seeds as f64;
    let max = |v: &[f64]| v.iter().copied().fold(0.0, f64::max);
    println!(
        "recall {:.3} ({hits}/{injected}), precision {:.3} ({hits}/{flagged}); estimate: median error at most {:.3}% ({:.3}% within the loop); one thread: decode {:.2} ms/frame, check {:.2}, estimate {:.2}",
        hits as f64 / injected.max(1) as f64,
        hits as f64 / flagged.max(1) as f64,
        100.0 * max(&errors),
        100.0 * max(&errors_loop),
        ms.0 / s,
        ms.1 / s,
        ms.2 / s
    );
    Ok(())
}
