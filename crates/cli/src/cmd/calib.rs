//! `monovo calib`: photometric calibration of your own camera.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use camera_model::Image;
use dataset_io::Sequence;
use photometric::{calibrate_response, ResponseOptions};

use crate::plot::{self, Chart, Corner, Figure, Panel, Series, PALETTE};
use crate::progress;

/// Arguments of `monovo calib`.
#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(subcommand)]
    pub what: What,
}

/// What to calibrate.
#[derive(clap::Subcommand, Debug)]
pub enum What {
    /// The inverse response U (pcalib.txt) from a static scene at varying, known exposures,
    /// with the standard error of every U(k).
    #[command(after_help = "\
Record a static scene with a wide range of grey values while the exposure changes (the
paper: 1000 images, 120 exposures from 0.05 to 20 ms in steps of 1.05). SEQ holds the images
and times.txt with the exposure of every frame.

  monovo calib response sweep -o pcalib.txt --plot response.png

Writes pcalib.txt (U scaled to U(255) = 255, strictly increasing, as DSO reads it) and
pcalib_std.txt beside it (one line of 256 standard errors on the same scale).

The model is the paper's, I = G(t B') + noise with G = U^-1, fitted where the noise is: in
grey values, each observation weighted by its noise (shot, read and ADC noise, fitted to the
residuals), with Newton steps in which each pixel's B' is eliminated. Observations enter by
the model's prediction, never by their observed value: only where the predicted grey value is
--censor-sigmas noise standard deviations inside 0..255, so saturation does not bias the
bright values. Saturated pixels and a --saturation-border around them are dropped. Exposures
in constant ratios leave U undetermined up to ripples with the period of the ratio; a
third-difference prior removes them, smoothing over --smoothness grey values or more when the
ratio is large, and continues U to the few values the data leave out (the top is continued
as a quadratic in log U). The standard errors combine the sampling error with the
sensitivities to the prior and to the selection; on synthetic sweeps about 93% of the true
errors lie within two of them.")]
    Response(ResponseArgs),
    /// A dense vignette map (vignette.png) from a video of a bright planar wall with one
    /// printed ArUco marker (original dictionary) that gives the plane's pose, with the
    /// paper's unregularised map, the standard error and the coverage beside it.
    #[command(after_help = "\
Film a bright, matte, planar surface (a white wall) with one printed marker of the original
ArUco dictionary (id 213 by default; the printed marker, black border included, is the unit
of length), from many viewpoints so that every image region, the corners included, sees the
wall. SEQ holds the images, times.txt with exposures, camera.txt (the raw camera; line 3 is the
pinhole used to find the marker) and pcalib.txt (or give --pcalib).

  monovo calib vignette wall -o vignette.png --plot vignette_plot.png

Writes, all 16-bit grey PNG at the raw resolution:
  vignette.png           the map to use (V = value / 65535, max 1): the paper's map smoothed
                         with a strength chosen by cross-validation between the maps of the
                         odd and of the even frames (printed; --smoothing sets it)
  vignette_raw.png       the paper's unregularised per-pixel map on the same scale (pixels
                         without enough observations, and defective ones, take the value of
                         vignette.png; the coverage image tells which)
  vignette_std.png       the standard error of vignette.png per pixel; the value that 65535
                         stands for is in the PNG's text chunk `monovo:std_scale` and in --json
  vignette_coverage.png  observations per pixel (0: none)

The model is the paper's, U(I) = t V(x) C(plane point) + noise, with C on a 1000x1000 grid over
5x5 marker widths and bilinear sampling, weighted by each observation's noise and by the
error a misregistration of --registration-px makes where C has edges, solved to convergence
(alternating V and C, accelerated) with outliers dropped once it settles. Frames are streamed:
memory does not grow with their number. Refused when the data cannot determine V: no marker,
an image corner never covered, or observations that fall into unconnected parts.

--poses FILE replaces the marker detection: one line per frame `id r11 r12 r13 r21 r22 r23
r31 r32 r33 tx ty tz` (camera_from_plane of the raw camera, marker corner 0 at (-0.5, 0.5),
corner 1 at (0.5, 0.5)).")]
    Vignette(VignetteArgs),
}

/// Arguments of `monovo calib response`.
#[derive(clap::Args, Debug)]
pub struct ResponseArgs {
    /// The sweep sequence folder (images + times.txt with exposures).
    pub sequence: PathBuf,
    /// The pcalib.txt to write; the standard errors go beside it as NAME_std.txt.
    #[arg(short, long, value_name = "FILE")]
    pub output: PathBuf,
    /// Replace existing outputs.
    #[arg(long)]
    pub force: bool,
    /// Calibration options from a TOML file (its `[response]` table; see data/calib.toml);
    /// the flags below win over it.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Iteration limit.
    #[arg(long, value_name = "N", help = with_default(
        "Iteration limit",
        ResponseOptions::default().max_iterations,
    ))]
    pub max_iterations: Option<usize>,
    /// Stop when U changes by less than this many grey values between iterations.
    #[arg(long, value_name = "GREY", help = with_default(
        "Stop when U changes by less than this many grey values between iterations",
        ResponseOptions::default().tolerance,
    ))]
    pub tolerance: Option<f64>,
    /// Smallest smoothing scale of the prior, in grey values.
    #[arg(long, value_name = "GREY", help = with_default(
        "Smallest smoothing scale of the prior, in grey values",
        ResponseOptions::default().smoothness,
    ))]
    pub smoothness: Option<f64>,
    /// Observations enter only where the model predicts a grey value this many noise
    /// standard deviations inside 0..255.
    #[arg(long, value_name = "SIGMAS", help = with_default(
        "Observations enter only where the model predicts a grey value this many noise \
         standard deviations inside 0..255",
        ResponseOptions::default().censor_sigmas,
    ))]
    pub censor_sigmas: Option<f64>,
    /// Radius (pixels) dropped around saturated pixels.
    #[arg(long, value_name = "PX", help = with_default(
        "Radius (pixels) dropped around saturated pixels",
        ResponseOptions::default().saturation_border,
    ))]
    pub saturation_border: Option<usize>,
    /// Plot U with its 2-sigma band, the standard errors and the observations (.png or .svg).
    #[arg(long, value_name = "FILE")]
    pub plot: Option<PathBuf>,
    /// Bits per sample of 16-bit frames (8 to 16). Default: the fewest bits that hold the
    /// brightest value (a 12-bit sensor's values 0..4095 give 12). Values in the low bits
    /// are used as they are; when every value is a multiple of 2^(16-K) and some exceed
    /// 2^K - 1, the sensor's K bits are in the high bits and are shifted down (as the
    /// trueBitDepth option of the 16-bit forks of the authors' tools reads them).
    #[arg(long, value_name = "K", value_parser = clap::value_parser!(u32).range(8..=16))]
    pub bit_depth: Option<u32>,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
}

/// Arguments of `monovo calib vignette`.
#[derive(clap::Args, Debug)]
pub struct VignetteArgs {
    /// The sequence folder (images, times.txt with exposures, camera.txt).
    pub sequence: PathBuf,
    /// The vignette.png to write (16-bit); NAME_raw.png, NAME_std.png and NAME_coverage.png
    /// go beside it.
    #[arg(short, long, value_name = "FILE")]
    pub output: PathBuf,
    /// Replace existing outputs.
    #[arg(long)]
    pub force: bool,
    /// The inverse response (default: SEQ/pcalib.txt).
    #[arg(long, value_name = "FILE")]
    pub pcalib: Option<PathBuf>,
    /// Plane poses per frame instead of marker detection.
    #[arg(long, value_name = "FILE")]
    pub poses: Option<PathBuf>,
    /// Id of the marker (original ArUco dictionary).
    #[arg(long, default_value_t = 213)]
    pub marker_id: u16,
    /// Calibration options from a TOML file (its `[vignette]` table; see data/calib.toml);
    /// the flags below win over it.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Iteration limit.
    #[arg(long, value_name = "N", help = with_default(
        "Iteration limit",
        photometric::VignetteOptions::default().max_iterations,
    ))]
    pub max_iterations: Option<usize>,
    /// Smoothing of vignette.png (Gaussian standard deviation in pixels) instead of the one
    /// chosen by cross-validation; 0 writes the raw map.
    #[arg(long, value_name = "PX")]
    pub smoothing: Option<f64>,
    /// Registration uncertainty of the plane in pixels (weights observations at edges of
    /// the plane's texture).
    #[arg(long, value_name = "PX", help = with_default(
        "Registration uncertainty of the plane in pixels (weights observations at edges of \
         the plane's texture)",
        photometric::VignetteOptions::default().registration_px,
    ))]
    pub registration_px: Option<f64>,
    /// Plot the maps, their cross-sections with 2-sigma bands, the standard error and the
    /// coverage (.png or .svg).
    #[arg(long, value_name = "FILE")]
    pub plot: Option<PathBuf>,
    /// Bits per sample of 16-bit frames (8 to 16). Default: the bit depth of pcalib.txt
    /// when its table has more than 256 values (a 4096-value table is indexed by 12-bit
    /// values, as DSO indexes it), else the fewest bits that hold the brightest value. K-bit
    /// values in the high bits (every value a multiple of 2^(16-K)) are shifted down.
    #[arg(long, value_name = "K", value_parser = clap::value_parser!(u32).range(8..=16))]
    pub bit_depth: Option<u32>,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
}

/// A flag's help with the default it takes when neither the flag nor `--config` sets it.
fn with_default(text: &str, default: impl std::fmt::Display) -> String {
    format!("{text} [default: {default}, or from --config]")
}

/// The options of `--config FILE`: a `[response]` and a `[vignette]` table with any fields
/// of [`ResponseOptions`] and [`photometric::VignetteOptions`] (data/calib.toml lists them
/// all with their defaults). Absent fields and tables keep the defaults; an unknown field is
/// an error naming it.
#[derive(Debug, Default, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CalibConfig {
    /// Options of `monovo calib response`.
    pub response: ResponseOptions,
    /// Options of `monovo calib vignette`.
    pub vignette: photometric::VignetteOptions,
}

impl CalibConfig {
    /// Parses a config file's text.
    pub fn parse(text: &str) -> Result<CalibConfig, toml::de::Error> {
        toml::from_str(text)
    }

    /// Reads the config file, or gives the defaults without one.
    pub fn load(path: Option<&Path>) -> Result<CalibConfig> {
        let Some(path) = path else {
            return Ok(CalibConfig::default());
        };
        let text = dataset_io::read_text(path)?;
        CalibConfig::parse(&text).map_err(|e| {
            anyhow::anyhow!(
                "{}: not a calibration config: {}",
                path.display(),
                e.to_string().trim_end()
            )
        })
    }
}

/// The response options: the defaults, then `--config`, then the flags; clamped to sane
/// values.
pub fn response_options(a: &ResponseArgs) -> Result<ResponseOptions> {
    let mut o = CalibConfig::load(a.config.as_deref())?.response;
    if let Some(v) = a.max_iterations {
        o.max_iterations = v;
    }
    if let Some(v) = a.tolerance {
        o.tolerance = v;
    }
    if let Some(v) = a.smoothness {
        o.smoothness = v;
    }
    if let Some(v) = a.censor_sigmas {
        o.censor_sigmas = v;
    }
    if let Some(v) = a.saturation_border {
        o.saturation_border = v;
    }
    o.max_iterations = o.max_iterations.max(1);
    o.smoothness = o.smoothness.max(0.0);
    o.censor_sigmas = o.censor_sigmas.max(0.5);
    o.check()
        .with_context(|| options_source(a.config.as_deref()))?;
    Ok(o)
}

/// The vignette options: the defaults, then `--config`, then the flags; clamped to sane
/// values.
pub fn vignette_options(a: &VignetteArgs) -> Result<photometric::VignetteOptions> {
    let mut o = CalibConfig::load(a.config.as_deref())?.vignette;
    if let Some(v) = a.max_iterations {
        o.max_iterations = v;
    }
    if let Some(v) = a.smoothing {
        o.smoothing_px = Some(v);
    }
    if let Some(v) = a.registration_px {
        o.registration_px = v;
    }
    o.max_iterations = o.max_iterations.max(1);
    o.smoothing_px = o.smoothing_px.map(|s| s.max(0.0));
    o.registration_px = o.registration_px.max(0.0);
    o.check()
        .with_context(|| options_source(a.config.as_deref()))?;
    Ok(o)
}

/// Where the calibration options came from, for an error about one of them.
fn options_source(config: Option<&Path>) -> String {
    match config {
        Some(p) => format!("the calibration options (the flags and {})", p.display()),
        None => "the calibration options".into(),
    }
}

/// `stem_suffix.ext` beside `path` (`vignette.png` -> `vignette_raw.png`).
pub fn sibling(path: &Path, suffix: &str) -> PathBuf {
    let stem = path
        .file_stem()
        .map_or("out".into(), |s| s.to_string_lossy().into_owned());
    let ext = path
        .extension()
        .map_or(String::new(), |e| format!(".{}", e.to_string_lossy()));
    path.with_file_name(format!("{stem}{suffix}{ext}"))
}

/// Checks every output path before any work.
fn check_outputs(paths: &[&Path], force: bool) -> Result<()> {
    for p in paths {
        dataset_io::check_output_file(p, force)?;
    }
    Ok(())
}

/// Reads every frame of a sequence at its own bit depth with its exposure; errors when
/// exposures are missing.
fn load_exposed_native(seq: &Sequence) -> Result<(Vec<dataset_io::GrayImage>, Vec<f64>)> {
    if let Some((k, line)) = seq.times().first_unknown_exposure() {
        bail!(
            "{}: line {line}: the exposure of frame {k} is unknown (0 or missing); calibration needs the exposure time of every frame (third column, > 0)",
            seq.times_path().display()
        );
    }
    let idx = seq.indices(0..seq.len(), false);
    let pb = progress::bar(idx.len() as u64, "decoding", "frames");
    let mut frames = Vec::with_capacity(idx.len());
    let mut exposures = Vec::with_capacity(idx.len());
    seq.process_native(
        &idx,
        rayon::current_num_threads() * 4,
        |f| {
            pb.inc(1);
            Ok::<_, anyhow::Error>(f)
        },
        |f| {
            exposures.push(f.exposure_ms.unwrap_or(0.0));
            frames.push(f.image);
            Ok(())
        },
    )?;
    pb.finish_and_clear();
    Ok((frames, exposures))
}

/// The frames of `seq` (read by [`load_exposed_native`]) as one sample type; a frame of the
/// other depth is an error naming it.
fn same_depth<T>(
    seq: &Sequence,
    frames: Vec<dataset_io::GrayImage>,
    pick: impl Fn(dataset_io::GrayImage) -> Option<Image<T>>,
) -> Result<Vec<Image<T>>> {
    let bits = seq.bits_per_sample();
    frames
        .into_iter()
        .enumerate()
        .map(|(i, f)| {
            let other = f.bits();
            pick(f).with_context(|| {
                format!(
                    "{}: a {other}-bit frame in a {bits}-bit sequence",
                    seq.names()[i]
                )
            })
        })
        .collect()
}

/// Reads every frame of an 8-bit sequence with its exposure; errors when exposures are
/// missing.
pub fn load_exposed_frames(seq: &Sequence) -> Result<(Vec<Image<u8>>, Vec<f64>)> {
    let (frames, exposures) = load_exposed_native(seq)?;
    let frames = same_depth(seq, frames, |f| match f {
        dataset_io::GrayImage::U8(i) => Some(i),
        dataset_io::GrayImage::U16(_) => None,
    })?;
    Ok((frames, exposures))
}

/// Reads every frame of a 16-bit sequence with its exposure, with the values as `bits`-bit
/// samples (see [`deep_layout`]); returns the frames, exposures and bit depth.
pub fn load_exposed_deep_frames(
    seq: &Sequence,
    bit_depth: Option<u32>,
) -> Result<(Vec<Image<u16>>, Vec<f64>, u32)> {
    let (frames, exposures) = load_exposed_native(seq)?;
    let mut frames = same_depth(seq, frames, |f| match f {
        dataset_io::GrayImage::U16(i) => Some(i),
        dataset_io::GrayImage::U8(_) => None,
    })?;
    let (bits, shift) = deep_layout(&frames, bit_depth)?;
    if shift > 0 {
        crate::warn(format_args!(
            "the {bits}-bit values are in the high bits of the 16-bit samples (every value is a multiple of {}); shifted down by {shift} bits",
            1u32 << shift
        ));
        for f in &mut frames {
            for v in f.data_mut() {
                *v >>= shift;
            }
        }
    }
    Ok((frames, exposures, bits))
}

/// The bit depth of 16-bit frames and the shift that brings their values to the low bits:
/// `bit_depth` or the fewest bits (at least 8) that hold the brightest value, and a shift
/// when the given depth's values sit in the high bits.
pub fn deep_layout(frames: &[Image<u16>], bit_depth: Option<u32>) -> Result<(u32, u32)> {
    let summary = frames
        .iter()
        .fold((0u16, 0u16), |acc, f| sample_summary(acc, f.data()));
    layout_of(summary, bit_depth)
}

/// The largest value and the bitwise OR of all values, added to `acc`.
fn sample_summary(acc: (u16, u16), data: &[u16]) -> (u16, u16) {
    data.iter().fold(acc, |(m, o), &v| (m.max(v), o | v))
}

/// [`deep_layout`] from the largest value and the OR of all values of the frames.
fn layout_of((max, or): (u16, u16), bit_depth: Option<u32>) -> Result<(u32, u32)> {
    let needed = (16 - max.leading_zeros()).max(8);
    let Some(k) = bit_depth else {
        return Ok((needed, 0));
    };
    if needed <= k {
        return Ok((k, 0));
    }
    let shift = 16 - k;
    if or & ((1u16 << shift) - 1) == 0 {
        return Ok((k, shift));
    }
    bail!(
        "--bit-depth {k}: the frames have the value {max}, more than {k} bits hold (at most {}), and their low bits are not all zero (so the values are not {k}-bit values in the high bits either); the frames need at least {needed} bits",
        (1u32 << k) - 1
    )
}

/// What the sweep offers before calibrating: exposures and grey values (`top` is the
/// saturated value, 255 for 8-bit frames).
fn sweep_report<T: Copy + Into<u32>>(frames: &[Image<T>], top: u32, exposures: &[f64]) -> String {
    let mut sorted: Vec<f64> = exposures.to_vec();
    sorted.sort_by(f64::total_cmp);
    sorted.dedup_by(|a, b| (*a / *b - 1.0).abs() < 1e-6);
    let step = sorted
        .windows(2)
        .map(|p| p[1] / p[0])
        .fold(1.0f64, f64::max);
    let top = top as usize;
    let mut hist = vec![0u64; top + 1];
    for f in frames {
        for &v in f.data() {
            hist[(v.into() as usize).min(top)] += 1;
        }
    }
    let total: u64 = hist.iter().sum();
    let lo = (0..=top).find(|&k| hist[k] > 0).unwrap_or(0);
    let hi = (0..top).rev().find(|&k| hist[k] > 0).unwrap_or(0);
    let rare = (lo..=hi).filter(|&k| hist[k] < 100).count();
    format!(
        "{} frames, {} exposures from {:.4} to {:.4} ms (largest step x{:.3}); grey values {lo}..{hi} observed ({} of them fewer than 100 times), {:.2}% of the observations saturated",
        frames.len(),
        sorted.len(),
        sorted.first().copied().unwrap_or(0.0),
        sorted.last().copied().unwrap_or(0.0),
        step,
        rare,
        100.0 * hist[top] as f64 / total.max(1) as f64
    )
}

fn run_response(a: &ResponseArgs) -> Result<()> {
    let std_path = sibling(&a.output, "_std");
    let mut outs: Vec<&Path> = vec![&a.output, &std_path];
    if let Some(p) = &a.plot {
        plot::format_of(p)?;
        outs.push(p);
    }
    check_outputs(&outs, a.force)?;
    let opts = response_options(a)?;
    let seq = crate::cmd::open_sequence(&a.sequence)?;
    if seq.len() < 2 {
        bail!(
            "{}: response calibration needs at least 2 frames at different exposures, found {}",
            a.sequence.display(),
            seq.len()
        );
    }
    let pb = progress::spinner("calibrating");
    let tick = |i: usize, change: f64| {
        pb.set_message(format!(
            "iteration {i}, U changed by {change:.4} grey values"
        ));
        pb.tick();
    };
    let (cal, nframes) = if seq.bits_per_sample() == 16 {
        let (frames, exposures, bits) = load_exposed_deep_frames(&seq, a.bit_depth)?;
        if !a.json {
            outln!("{}", sweep_report(&frames, (1u32 << bits) - 1, &exposures))?;
            outln!(
                "{bits}-bit frames: U is estimated on {} knots and written as {} values",
                (1usize << bits).min(photometric::MAX_KNOTS),
                1u32 << bits
            )?;
        }
        let cal = photometric::calibrate_response_deep(&frames, bits, &exposures, &opts, &tick)
            .with_context(|| format!("{}", a.sequence.display()))?;
        (cal, frames.len())
    } else {
        if let Some(k) = a.bit_depth.filter(|&k| k != 8) {
            bail!(
                "--bit-depth {k}: the frames of {} are 8-bit; --bit-depth describes 16-bit frames",
                a.sequence.display()
            );
        }
        let (mut frames, exposures) = load_exposed_frames(&seq)?;
        let report = sweep_report(&frames, 255, &exposures);
        if !a.json {
            outln!("{report}")?;
        }
        let cal = calibrate_response(&mut frames, &exposures, &opts, &tick)
            .with_context(|| format!("{}", a.sequence.display()))?;
        (cal, frames.len())
    };
    pb.finish_and_clear();
    for w in &cal.warnings {
        crate::warn(format_args!("{w}"));
    }
    dataset_io::write_atomic(&a.output, cal.response.to_text().as_bytes())?;
    let std_text = cal
        .std_error
        .iter()
        .map(|v| format!("{v}"))
        .collect::<Vec<_>>()
        .join(" ");
    dataset_io::write_atomic(&std_path, format!("{std_text}\n").as_bytes())?;
    if let Some(p) = &a.plot {
        response_figure(&cal, None, p)?;
    }
    let top = cal.std_error.len() - 1;
    let max_std = cal.std_error[..top].iter().copied().fold(0.0, f64::max);
    if a.json {
        outln!(
            "{}",
            serde_json::json!({
                "output": a.output.display().to_string(),
                "std_output": std_path.display().to_string(),
                "plot": a.plot.as_ref().map(|p| p.display().to_string()),
                "frames": nframes,
                "bits": cal.response.bits(),
                "knot_step": cal.knot_step,
                "iterations": cal.iterations,
                "converged": cal.converged,
                "change": cal.change,
                "rmse": cal.rmse,
                "observed_min": cal.observed_range.0,
                "observed_max": cal.observed_range.1,
                "filled": cal.filled,
                "censor_range": [cal.censor_range.0, cal.censor_range.1],
                "noise": {"read": cal.noise.read, "shot": cal.noise.shot, "adc": cal.noise.adc},
                "prior_weight": cal.prior_weight,
                "pixels_used": cal.pixels_used,
                "u": cal.response.table(),
                "std_error": cal.std_error,
                "systematic_error": cal.systematic_error,
                "histogram": cal.histogram,
                "warnings": cal.warnings,
            })
        )?;
    } else {
        outln!(
            "{} after {} iterations (last change {:.4} grey values); residual RMS {:.3} grey values",
            if cal.converged {
                "converged"
            } else {
                "stopped"
            },
            cal.iterations,
            cal.change.last().copied().unwrap_or(f64::NAN),
            cal.rmse
        )?;
        outln!(
            "noise: read {:.3} U^2, shot {:.4} U per U, ADC {:.3} grey^2; observations used where the prediction is {:.0}..{:.0}",
            cal.noise.read, cal.noise.shot, cal.noise.adc, cal.censor_range.0, cal.censor_range.1
        )?;
        outln!(
            "U determined by the data for grey values {}..{}; {} value(s) continued by the prior; largest standard error {:.3} grey values",
            cal.observed_range.0,
            cal.observed_range.1,
            cal.filled.len(),
            max_std
        )?;
        outln!("wrote {} and {}", a.output.display(), std_path.display())?;
    }
    Ok(())
}

/// Plots U with its 2-sigma band (and the truth, when known), the standard errors, and the
/// observations per grey value, for a table of any bit depth (`truth` has as many values).
pub fn response_figure(
    cal: &photometric::ResponseCalibration,
    truth: Option<&[f64]>,
    path: &Path,
) -> Result<()> {
    let u = cal.response.table();
    let n = u.len();
    let top = (n - 1) as f64;
    let sd = &cal.std_error;
    // at most about 1024 points per curve
    let stride = (n / 1024).max(1);
    let idx: Vec<usize> = (0..n).step_by(stride).chain([n - 1]).collect();
    let below_top: Vec<usize> = idx.iter().copied().filter(|&k| k < n - 1).collect();
    let curve = |ks: &[usize], f: &dyn Fn(usize) -> f64| -> Vec<[f64; 2]> {
        ks.iter().map(|&k| [k as f64, f(k)]).collect()
    };
    let scale = format!("U({}) = 255", n - 1);
    let mut c1 = Chart::new(
        "inverse response U",
        "grey value I",
        format!("U(I) (scaled to {scale})"),
    );
    c1.legend = Some(Corner::TopLeft);
    c1.x_range = Some([0.0, top]);
    c1.series.push(Series::band(
        "2-sigma band",
        curve(&idx, &|k| u[k] - 2.0 * sd[k]),
        curve(&idx, &|k| u[k] + 2.0 * sd[k]),
        PALETTE[0],
    ));
    c1.series.push(Series::line(
        "U estimated",
        curve(&idx, &|k| u[k]),
        PALETTE[0],
    ));
    if let Some(t) = truth {
        c1.series
            .push(Series::line("U true", curve(&idx, &|k| t[k]), PALETTE[2]).dashed());
    }
    c1.series
        .push(Series::line("linear", vec![[0.0, 0.0], [top, 255.0]], PALETTE[7]).dashed());
    let mut c2 = Chart::new(
        "uncertainty of U",
        "grey value I",
        format!("grey values ({scale} scale)"),
    );
    c2.legend = Some(Corner::TopLeft);
    c2.x_range = Some([0.0, top]);
    c2.series.push(Series::line(
        "standard error",
        curve(&below_top, &|k| sd[k]),
        PALETTE[0],
    ));
    c2.series.push(
        Series::line(
            "its systematic part",
            curve(&below_top, &|k| cal.systematic_error[k]),
            PALETTE[3],
        )
        .dashed(),
    );
    if let Some(t) = truth {
        c2.series.push(Series::line(
            "|U - U true|",
            curve(&below_top, &|k| (u[k] - t[k]).abs()),
            PALETTE[2],
        ));
    }
    let mut c3 = Chart::new(
        "observations",
        "grey value I",
        "log10 of the number of observations",
    );
    c3.legend = Some(Corner::TopRight);
    c3.x_range = Some([0.0, top]);
    // counts in bins of `width` grey values (below the top value), as steps
    let steps = |h: &[u64], width: f64| -> Vec<[f64; 2]> {
        let group = ((n / 256).max(1) as f64 / width).round().max(1.0) as usize;
        let last = ((top / width).ceil() as usize).min(h.len());
        h[..last]
            .chunks(group)
            .enumerate()
            .flat_map(|(i, c)| {
                let v = (c.iter().sum::<u64>() as f64).max(1.0).log10();
                let x0 = (i * group) as f64 * width;
                [[x0, v], [(x0 + group as f64 * width).min(top), v]]
            })
            .collect()
    };
    let per = if n > 256 {
        format!(" (per {} values)", n / 256)
    } else {
        String::new()
    };
    c3.series.push(Series::line(
        format!("observed values{per}"),
        steps(&cal.histogram, 1.0),
        PALETTE[1],
    ));
    c3.series.push(Series::line(
        format!("used (by prediction){per}"),
        steps(&cal.used, cal.knot_step),
        PALETTE[4],
    ));
    let fig = Figure {
        width: 1650,
        height: 520,
        panels: vec![
            (Panel::Chart(c1), [0.0, 0.0, 0.34, 1.0]),
            (Panel::Chart(c2), [0.34, 0.0, 0.33, 1.0]),
            (Panel::Chart(c3), [0.67, 0.0, 0.33, 1.0]),
        ],
    };
    plot::save(&fig, path)
}

/// Frames of a sequence with poses: decoded once and kept when they fit in
/// [`DECODED_CACHE_BYTES`], else decoded again on every pass (memory stays flat). 16-bit
/// frames are `bits`-bit samples after a right shift by `shift` (see [`deep_layout`]).
struct SequencePlaneFrames<'a> {
    seq: &'a Sequence,
    frames: Vec<(usize, f64, photometric::PlanePose)>,
    deep: Option<DeepLayout>,
    decoded: Vec<photometric::PlaneImage>,
}

/// The bit depth of the samples of a 16-bit sequence and the shift that brings them to the
/// low bits.
#[derive(Clone, Copy, Debug)]
struct DeepLayout {
    bits: u32,
    shift: u32,
}

impl DeepLayout {
    /// A frame as the calibration reads it.
    fn plane_image(&self, image: dataset_io::GrayImage) -> photometric::PlaneImage {
        match image {
            dataset_io::GrayImage::U8(i) => photometric::PlaneImage::U8(i),
            dataset_io::GrayImage::U16(mut image) => {
                if self.shift > 0 {
                    for v in image.data_mut() {
                        *v >>= self.shift;
                    }
                }
                photometric::PlaneImage::U16 {
                    image,
                    bits: self.bits,
                }
            }
        }
    }

    /// A frame as 8-bit grey for the marker detector (full range: `v 255 / (2^bits - 1)`).
    fn eight_bit(&self, image: &dataset_io::GrayImage) -> Image<u8> {
        match image {
            dataset_io::GrayImage::U8(i) => i.clone(),
            dataset_io::GrayImage::U16(i) => {
                let top = ((1u32 << self.bits) - 1) as f32;
                let scale = 255.0 / top;
                i.map(|v| ((v >> self.shift) as f32 * scale).round().min(255.0) as u8)
            }
        }
    }
}

/// Largest total size of decoded frames kept in memory by `calib vignette`.
const DECODED_CACHE_BYTES: usize = 192 << 20;

impl SequencePlaneFrames<'_> {
    fn decode(&self, k: usize) -> Result<photometric::PlaneImage> {
        Ok(match self.deep {
            Some(d) => d.plane_image(self.seq.decode_native(k)?),
            None => photometric::PlaneImage::U8(self.seq.decode(k)?),
        })
    }
}

impl photometric::PlaneFrames for SequencePlaneFrames<'_> {
    fn len(&self) -> usize {
        self.frames.len()
    }
    fn frame(&self, i: usize) -> Result<photometric::PlaneFrame, photometric::PhotometricError> {
        let (k, exposure_ms, pose) = self.frames[i];
        let image = match self.decoded.get(i) {
            Some(img) => img.clone(),
            None => self
                .decode(k)
                .map_err(|e| photometric::PhotometricError::Calibration(format!("{e:#}")))?,
        };
        Ok(photometric::PlaneFrame {
            image,
            exposure_ms,
            pose,
        })
    }
}

/// The maps, their cross-sections through the image centre with 2-sigma bands (and the
/// truth, when known), the standard error and the coverage.
pub fn vignette_figure(
    cal: &photometric::VignetteCalibration,
    truth: Option<&[f32]>,
    path: &Path,
) -> Result<()> {
    let v = &cal.vignette;
    let (w, h) = v.size();
    let heat = |title: &str, values: Vec<f32>, range: [f32; 2], label: &str| {
        Panel::Heatmap(crate::plot::Heatmap {
            title: title.into(),
            width: w,
            height: h,
            values,
            range,
            label: label.into(),
        })
    };
    let sd = cal.std_error.data();
    // the colour scale of the standard error ends at its 99th percentile: a few border
    // pixels with little data would otherwise leave the rest of the map one colour
    let mut sd_sorted: Vec<f32> = sd.iter().copied().filter(|v| v.is_finite()).collect();
    sd_sorted.sort_unstable_by(f32::total_cmp);
    let sd_max = sd_sorted
        .get(sd_sorted.len() * 99 / 100)
        .copied()
        .unwrap_or(0.0)
        .max(1e-6);
    let counts: Vec<f32> = cal.counts.data().iter().map(|&c| c as f32).collect();
    let c_max = counts.iter().copied().fold(0.0f32, f32::max).max(1.0);
    let section = |title: &str, axis: &str, n: usize, at: &dyn Fn(usize) -> usize, legend: bool| {
        let mut c = Chart::new(title, axis, "V");
        // one legend for both cross-sections
        c.legend = legend.then_some(Corner::BottomRight);
        let val = |img: &Image<f32>, i: usize| img.data()[at(i)] as f64;
        c.series.push(Series::band(
            "recommended, 2 sigma",
            (0..n)
                .map(|i| [i as f64, val(v, i) - 2.0 * sd[at(i)] as f64])
                .collect(),
            (0..n)
                .map(|i| [i as f64, val(v, i) + 2.0 * sd[at(i)] as f64])
                .collect(),
            PALETTE[0],
        ));
        let mut raw = Series::line(
            "raw (the paper's)",
            (0..n).map(|i| [i as f64, val(&cal.raw, i)]).collect(),
            PALETTE[7],
        );
        raw.width = 1.0;
        c.series.push(raw);
        c.series.push(Series::line(
            "recommended",
            (0..n).map(|i| [i as f64, val(v, i)]).collect(),
            PALETTE[0],
        ));
        if let Some(t) = truth {
            c.series.push(
                Series::line(
                    "true",
                    (0..n).map(|i| [i as f64, t[at(i)] as f64]).collect(),
                    PALETTE[2],
                )
                .dashed(),
            );
        }
        Panel::Chart(c)
    };
    let fig = Figure {
        width: 1650,
        height: 900,
        panels: vec![
            (
                heat(
                    &format!("recommended V (smoothing {:.1} px)", cal.smoothing.sigma_px),
                    v.data().to_vec(),
                    [0.0, 1.0],
                    "V",
                ),
                [0.0, 0.0, 0.34, 0.42],
            ),
            (
                heat(
                    "standard error of V (colours clipped at 99%)",
                    sd.to_vec(),
                    [0.0, sd_max],
                    "standard error",
                ),
                [0.34, 0.0, 0.33, 0.42],
            ),
            (
                heat("coverage", counts, [0.0, c_max], "observations per pixel"),
                [0.67, 0.0, 0.33, 0.42],
            ),
            (
                section("middle row", "x (pixels)", w, &|x| (h / 2) * w + x, true),
                [0.0, 0.42, 0.5, 0.58],
            ),
            (
                section("middle column", "y (pixels)", h, &|y| y * w + w / 2, false),
                [0.5, 0.42, 0.5, 0.58],
            ),
        ],
    };
    plot::save(&fig, path)
}

/// Frames with a plane pose (index, exposure in ms, pose) and the count of skipped frames
/// per reason.
/// The bit depth of a 16-bit sequence's samples for `calib vignette`: `--bit-depth`, else
/// the depth of a table of more than 256 values, else the fewest bits that hold the
/// brightest value; one pass over the frames tells whether the values sit in the high bits.
fn sequence_layout(
    seq: &Sequence,
    bit_depth: Option<u32>,
    response: &photometric::InverseResponse,
) -> Result<DeepLayout> {
    let idx = seq.indices(0..seq.len(), false);
    let pb = progress::bar(idx.len() as u64, "bit depth", "frames");
    let mut summary = (0u16, 0u16);
    seq.process_native(
        &idx,
        rayon::current_num_threads() * 4,
        |f| {
            pb.inc(1);
            Ok::<_, anyhow::Error>(match f.image {
                dataset_io::GrayImage::U16(i) => sample_summary((0, 0), i.data()),
                dataset_io::GrayImage::U8(i) => {
                    (i.data().iter().copied().max().unwrap_or(0) as u16, 0xFF)
                }
            })
        },
        |s| {
            summary = (summary.0.max(s.0), summary.1 | s.1);
            Ok(())
        },
    )?;
    pb.finish_and_clear();
    let table_bits = response.bits();
    let wanted = bit_depth.or((table_bits > 8).then_some(table_bits));
    let (bits, shift) = layout_of(summary, wanted).with_context(|| {
        if bit_depth.is_none() && wanted.is_some() {
            format!(
                "the bit depth {table_bits} of the pcalib.txt table (give --bit-depth to override)"
            )
        } else {
            seq.dir().display().to_string()
        }
    })?;
    if shift > 0 {
        crate::warn(format_args!(
            "the {bits}-bit values are in the high bits of the 16-bit samples (every value is a multiple of {}); shifted down by {shift} bits",
            1u32 << shift
        ));
    }
    if table_bits > 8 && table_bits != bits {
        crate::warn(format_args!(
            "pcalib.txt has {} values ({table_bits}-bit) but the frames are taken as {bits}-bit: the table is read by full range",
            1u32 << table_bits
        ));
    }
    Ok(DeepLayout { bits, shift })
}

type PosedFrames = (
    Vec<(usize, f64, photometric::PlanePose)>,
    std::collections::BTreeMap<&'static str, usize>,
);

/// The plane pose of every frame: from a poses file, or from the marker.
fn plane_poses(
    a: &VignetteArgs,
    seq: &Sequence,
    cam: &camera_model::CameraFile,
    deep: Option<DeepLayout>,
) -> Result<PosedFrames> {
    use camera_model::{output_intrinsics, OutputMode, RectifyMap};
    use photometric::marker::PoseFromMarker;
    let rows = &seq.times().rows;
    let mut frames = Vec::new();
    let mut skipped: std::collections::BTreeMap<&'static str, usize> = Default::default();
    if let Some(pp) = &a.poses {
        let poses: std::collections::HashMap<String, photometric::PlanePose> =
            photometric::marker::parse_plane_poses(&dataset_io::read_text(pp)?)
                .with_context(|| pp.display().to_string())?
                .into_iter()
                .collect();
        for (k, row) in rows.iter().enumerate() {
            match poses.get(&row.id) {
                Some(p) => frames.push((k, row.exposure_ms.unwrap_or(0.0), *p)),
                None => *skipped.entry("no pose in the poses file").or_default() += 1,
            }
        }
        return Ok((frames, skipped));
    }
    let cam_path = a.sequence.join("camera.txt");
    if cam.output == OutputMode::None && !cam.input.is_pinhole() {
        bail!(
            "{}: line 3 is `none`, but the {} camera must be rectified to a pinhole to find the marker; use crop, full or an explicit pinhole (or give --poses)",
            cam_path.display(),
            cam.input.name()
        );
    }
    let k_out = output_intrinsics(&cam.input, cam.input_size, &cam.output, cam.output_size)
        .with_context(|| cam_path.display().to_string())?;
    let map = RectifyMap::new(&cam.input, cam.input_size, k_out, cam.output_size)?;
    let idx = seq.indices(0..seq.len(), false);
    let pb = progress::bar(idx.len() as u64, "markers", "frames");
    let mut found: Vec<(usize, PoseFromMarker)> = Vec::new();
    let detect = |index: usize, image: &Image<u8>| -> Result<(usize, PoseFromMarker)> {
        let r = photometric::marker::pose_from_marker(&map, &k_out, image, a.marker_id)?;
        pb.inc(1);
        Ok((index, r))
    };
    let sink = |r| {
        found.push(r);
        Ok(())
    };
    let chunk = rayon::current_num_threads() * 4;
    match deep {
        // deep frames are scaled to 8 bits by their bit depth (a 12-bit frame read as 8
        // bits of 16 would be black)
        Some(d) => seq.process_native(
            &idx,
            chunk,
            |f| detect(f.index, &d.eight_bit(&f.image)),
            sink,
        )?,
        None => seq.process(&idx, chunk, |f| detect(f.index, &f.image), sink)?,
    }
    pb.finish_and_clear();
    for (k, result) in found {
        match result {
            PoseFromMarker::Found(p) => frames.push((k, rows[k].exposure_ms.unwrap_or(0.0), p)),
            PoseFromMarker::NoMarker => *skipped.entry("no marker").or_default() += 1,
            PoseFromMarker::NoPose => *skipped.entry("no pose from the corners").or_default() += 1,
            PoseFromMarker::Several(_) => {
                *skipped.entry("several markers with the id").or_default() += 1
            }
        }
    }
    Ok((frames, skipped))
}

/// A vignette calibration of a sequence, as `monovo calib vignette` runs it.
pub struct VignetteRun {
    /// The calibration.
    pub cal: photometric::VignetteCalibration,
    /// Frames with a plane pose.
    pub used: usize,
    /// Frames without one, by reason.
    pub skipped: std::collections::BTreeMap<&'static str, usize>,
    /// The options used.
    pub options: photometric::VignetteOptions,
    /// Bits per sample the frames were read with (8, or the depth of 16-bit frames).
    pub bits: u32,
}

/// Poses (from the marker or `--poses`) and the calibration, without writing anything.
pub fn calibrate_vignette_sequence(a: &VignetteArgs) -> Result<VignetteRun> {
    let opts = vignette_options(a)?;
    let seq = crate::cmd::open_sequence(&a.sequence)?;
    let cam_path = a.sequence.join("camera.txt");
    let Some(cam) = seq.camera() else {
        bail!(
            "{}: missing; vignette calibration needs the camera model",
            cam_path.display()
        );
    };
    let pcalib_path = a.pcalib.clone().or(seq.pcalib_path.clone()).with_context(|| {
        format!(
            "{}: no pcalib.txt; vignette calibration needs the inverse response (run `monovo calib response` first, or give --pcalib FILE)",
            a.sequence.display()
        )
    })?;
    let response = photometric::InverseResponse::parse(&dataset_io::read_text(&pcalib_path)?)
        .with_context(|| pcalib_path.display().to_string())?;
    if let Some((k, line)) = seq.times().first_unknown_exposure() {
        bail!(
            "{}: line {line}: the exposure of frame {k} is unknown (0 or missing); vignette calibration needs the exposure time of every frame (third column, > 0)",
            seq.times_path().display()
        );
    }
    let deep = if seq.bits_per_sample() == 16 {
        Some(sequence_layout(&seq, a.bit_depth, &response)?)
    } else {
        if let Some(k) = a.bit_depth {
            bail!(
                "--bit-depth {k}: the frames of {} are 8-bit; --bit-depth describes 16-bit frames",
                a.sequence.display()
            );
        }
        None
    };
    let (frames, skipped) = plane_poses(a, &seq, cam, deep)?;
    if frames.is_empty() {
        bail!(
            "{}: no frame has a plane pose (marker id {} was not found in any of {} frames{}); check --marker-id, the dictionary (original ArUco) and that the marker is fully visible",
            a.sequence.display(),
            a.marker_id,
            seq.len(),
            if a.poses.is_some() { ", or the ids in the poses file" } else { "" }
        );
    }
    if !a.json {
        outln!(
            "{} of {} frames have a plane pose{}",
            frames.len(),
            seq.len(),
            if skipped.is_empty() {
                String::new()
            } else {
                format!(
                    " ({})",
                    skipped
                        .iter()
                        .map(|(k, v)| format!("{v}: {k}"))
                        .collect::<Vec<_>>()
                        .join(", ")
                )
            }
        )?;
    }
    let sample_bytes = if deep.is_some() { 2 } else { 1 };
    let bytes = frames.len() * cam.input_size.pixels() * sample_bytes;
    let mut source = SequencePlaneFrames {
        seq: &seq,
        frames,
        deep,
        decoded: Vec::new(),
    };
    if bytes <= DECODED_CACHE_BYTES {
        let idx: Vec<usize> = source.frames.iter().map(|f| f.0).collect();
        let mut out = Vec::with_capacity(idx.len());
        let pb = progress::bar(idx.len() as u64, "decoding", "frames");
        for part in idx.chunks(rayon::current_num_threads() * 4) {
            use rayon::prelude::*;
            let images: Vec<Result<photometric::PlaneImage>> = part
                .par_iter()
                .map(|&k| {
                    let r = source.decode(k);
                    pb.inc(1);
                    r
                })
                .collect();
            for image in images {
                out.push(image?);
            }
        }
        pb.finish_and_clear();
        source.decoded = out;
    }
    let pb = progress::spinner("calibrating");
    let cal = photometric::calibrate_vignette(
        &cam.input,
        cam.input_size,
        &response,
        &source,
        &opts,
        &|i, change| {
            pb.set_message(format!(
                "iteration {i}, V changed by {:.4}%",
                100.0 * change
            ));
            pb.tick();
        },
    )
    .with_context(|| a.sequence.display().to_string())?;
    pb.finish_and_clear();
    Ok(VignetteRun {
        cal,
        used: source.frames.len(),
        skipped,
        options: opts,
        bits: deep.map_or(8, |d| d.bits),
    })
}

fn run_vignette(a: &VignetteArgs) -> Result<()> {
    let raw_path = sibling(&a.output, "_raw");
    let std_path = sibling(&a.output, "_std");
    let cov_path = sibling(&a.output, "_coverage");
    let mut outs: Vec<&Path> = vec![&a.output, &raw_path, &std_path, &cov_path];
    if let Some(p) = &a.plot {
        plot::format_of(p)?;
        outs.push(p);
    }
    check_outputs(&outs, a.force)?;
    let VignetteRun {
        cal,
        used,
        skipped,
        options,
        bits,
    } = calibrate_vignette_sequence(a)?;
    let skipped_total: usize = skipped.values().sum();
    for w in &cal.warnings {
        crate::warn(format_args!("{w}"));
    }
    let (w, h) = cal.vignette.size();
    let to16 = |values: &[f32], scale: f32| -> Vec<u16> {
        values
            .iter()
            .map(|v| (v / scale * 65535.0).round().clamp(0.0, 65535.0) as u16)
            .collect()
    };
    let rec = cal.vignette.data();
    // the raw map as written: its unknown pixels take the recommended value
    let raw_filled: Vec<f32> = cal
        .raw
        .data()
        .iter()
        .zip(rec)
        .map(|(r, s)| if r.is_finite() { *r } else { *s })
        .collect();
    let raw_max = raw_filled.iter().copied().fold(1.0f32, f32::max);
    let std_scale = cal
        .std_error
        .data()
        .iter()
        .copied()
        .fold(0.0f32, f32::max)
        .max(1e-9) as f64;
    dataset_io::write_png_u16_with_text(
        &a.output,
        w,
        h,
        &to16(rec, 1.0),
        &[(
            "monovo:map",
            "recommended vignette, V = value / 65535".into(),
        )],
    )?;
    dataset_io::write_png_u16_with_text(
        &raw_path,
        w,
        h,
        &to16(&raw_filled, raw_max),
        &[(
            "monovo:map",
            format!(
                "raw vignette (the paper's), V = value / 65535 * {raw_max} on the scale of the recommended map"
            ),
        )],
    )?;
    dataset_io::write_png_u16_with_text(
        &std_path,
        w,
        h,
        &to16(cal.std_error.data(), std_scale as f32),
        &[
            ("monovo:std_scale", format!("{std_scale}")),
            (
                "monovo:map",
                format!("standard error of the recommended vignette = value / 65535 * {std_scale}"),
            ),
        ],
    )?;
    let cov: Vec<u16> = cal
        .counts
        .data()
        .iter()
        .map(|&c| c.min(65535) as u16)
        .collect();
    dataset_io::write_png_u16_with_text(
        &cov_path,
        w,
        h,
        &cov,
        &[("monovo:map", "observations per pixel".into())],
    )?;
    if let Some(p) = &a.plot {
        vignette_figure(&cal, None, p)?;
    }
    let sd = cal.std_error.data();
    let sd_median = {
        let mut v: Vec<f32> = sd.to_vec();
        v.sort_by(f32::total_cmp);
        v.get(v.len() / 2).copied().unwrap_or(0.0)
    };
    if a.json {
        outln!(
            "{}",
            serde_json::json!({
                "output": a.output.display().to_string(),
                "raw": raw_path.display().to_string(),
                "std": std_path.display().to_string(),
                "coverage_image": cov_path.display().to_string(),
                "plot": a.plot.as_ref().map(|p| p.display().to_string()),
                "std_scale": std_scale,
                "raw_scale": raw_max,
                "frames_used": used,
                "frames_skipped": skipped_total,
                "bits": bits,
                "skipped": skipped.iter().map(|(k, v)| (k.to_string(), serde_json::json!(v))).collect::<serde_json::Map<_, _>>(),
                "iterations": cal.iterations,
                "converged": cal.converged,
                "change": cal.change,
                "rms_relative": cal.rms_relative,
                "coverage": cal.coverage,
                "components": cal.components,
                "smoothing_px": cal.smoothing.sigma_px,
                "smoothing_cross_validated": cal.smoothing.cross_validated,
                "smoothing_scores": cal.smoothing.scores,
                "defective_pixels": cal.smoothing.defects,
                "outliers": cal.outliers,
                "std_median": sd_median,
                "noise": {"read": cal.noise.read, "shot": cal.noise.shot, "adc": cal.noise.adc},
                "warnings": cal.warnings,
            })
        )?;
    } else {
        outln!(
            "{} after {} iterations (last change {:.4}%); relative residual RMS {:.4}; {} outliers dropped",
            if cal.converged {
                "converged"
            } else {
                "stopped"
            },
            cal.iterations,
            100.0 * cal.change.last().copied().unwrap_or(f64::NAN),
            cal.rms_relative,
            cal.outliers
        )?;
        outln!(
            "{:.1}% of the pixels observed {} times or more; {} defective pixel(s) left out",
            100.0 * cal.coverage,
            options.min_observations,
            cal.smoothing.defects
        )?;
        outln!(
            "smoothing of {}: {:.1} px ({}); median standard error {:.3}%",
            a.output.display(),
            cal.smoothing.sigma_px,
            if cal.smoothing.cross_validated {
                "chosen by cross-validation between odd and even frames"
            } else {
                "given"
            },
            100.0 * sd_median
        )?;
        outln!(
            "wrote {}, {}, {} and {}",
            a.output.display(),
            raw_path.display(),
            std_path.display(),
            cov_path.display()
        )?;
    }
    Ok(())
}

/// Runs `monovo calib`.
pub fn run(args: &Args) -> Result<()> {
    match &args.what {
        What::Response(a) => run_response(a),
        What::Vignette(a) => run_vignette(a),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    /// The example config in the repository.
    const EXAMPLE: &str = include_str!("../../../../data/calib.toml");

    #[derive(clap::Parser)]
    struct Response {
        #[command(flatten)]
        args: ResponseArgs,
    }

    #[derive(clap::Parser)]
    struct Vignette {
        #[command(flatten)]
        args: VignetteArgs,
    }

    fn json<T: serde::Serialize>(v: &T) -> serde_json::Value {
        serde_json::to_value(v).unwrap()
    }

    #[test]
    fn the_example_config_lists_every_option_with_its_default() {
        let c = CalibConfig::parse(EXAMPLE).unwrap();
        assert_eq!(json(&c.response), json(&ResponseOptions::default()));
        assert_eq!(
            json(&c.vignette),
            json(&photometric::VignetteOptions::default())
        );
        // a new option must be added to the example (commented out when it has no value)
        for (table, options) in [
            ("response", json(&ResponseOptions::default())),
            ("vignette", json(&photometric::VignetteOptions::default())),
        ] {
            let section = EXAMPLE.split(&format!("[{table}]")).nth(1).unwrap();
            let section = section.split("\n[").next().unwrap();
            for key in options.as_object().unwrap().keys() {
                assert!(
                    section.contains(&format!("\n{key} = "))
                        || section.contains(&format!("\n# {key} = ")),
                    "data/calib.toml has no `{key}` in [{table}]"
                );
            }
        }
    }

    #[test]
    fn unknown_keys_and_wrong_types_are_errors_that_name_them() {
        let e = CalibConfig::parse("[response]\nmax_iteration = 3\n").unwrap_err();
        assert!(e.to_string().contains("max_iteration"), "{e}");
        let e = CalibConfig::parse("[respons]\ntolerance = 0.1\n").unwrap_err();
        assert!(e.to_string().contains("respons"), "{e}");
        let e = CalibConfig::parse("[vignette]\ngrid = \"fine\"\n").unwrap_err();
        assert!(e.to_string().contains("grid"), "{e}");
        // an empty file is the defaults
        let c = CalibConfig::parse("").unwrap();
        assert_eq!(
            json(&c.vignette),
            json(&photometric::VignetteOptions::default())
        );
    }

    #[test]
    fn flags_win_over_the_config_and_the_config_over_the_defaults() {
        let dir = std::env::temp_dir().join(format!("monovo_calib_config_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("calib.toml");
        std::fs::write(
            &file,
            "[response]\nmax_iterations = 7\nmin_count = 3\ntolerance = 0.5\n\n\
             [vignette]\ngrid = 400\nsmoothing_px = 1.5\nregistration_px = 0.5\n",
        )
        .unwrap();
        let f = file.to_str().unwrap();
        let r = Response::parse_from([
            "t",
            "sweep",
            "-o",
            "p.txt",
            "--config",
            f,
            "--tolerance",
            "0.2",
        ]);
        let o = response_options(&r.args).unwrap();
        assert_eq!((o.max_iterations, o.min_count), (7, 3), "from the file");
        assert_eq!(o.tolerance, 0.2, "the flag wins");
        assert_eq!(
            o.smoothness,
            ResponseOptions::default().smoothness,
            "the default"
        );
        let r = Response::parse_from(["t", "sweep", "-o", "p.txt"]);
        assert_eq!(
            json(&response_options(&r.args).unwrap()),
            json(&ResponseOptions::default())
        );
        let v = Vignette::parse_from([
            "t",
            "wall",
            "-o",
            "v.png",
            "--config",
            f,
            "--smoothing",
            "0",
        ]);
        let o = vignette_options(&v.args).unwrap();
        assert_eq!((o.grid, o.registration_px), (400, 0.5));
        assert_eq!(o.smoothing_px, Some(0.0));
        assert_eq!(
            o.max_iterations,
            photometric::VignetteOptions::default().max_iterations
        );
        // a missing file is named
        let v = Vignette::parse_from([
            "t",
            "wall",
            "-o",
            "v.png",
            "--config",
            "/nonexistent/c.toml",
        ]);
        let e = vignette_options(&v.args).unwrap_err();
        assert!(format!("{e:#}").contains("/nonexistent/c.toml"), "{e:#}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
