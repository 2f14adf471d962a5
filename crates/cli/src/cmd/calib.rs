//! `monovo calib`: photometric calibration of your own camera.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use photometric::ResponseOptions;

pub use monovo_pipelines::calib::{
    calibrate_response_sequence, calibrate_vignette_sequence, load_exposed_frames, response_figure,
    sibling, vignette_figure, write_response, write_vignette_maps, CalibConfig, MapScales,
    ResponseJob, ResponseRun, VignetteFiles, VignetteJob, VignetteRun,
};

use crate::plot;
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

The model is the paper's, I = G(t B') + noise with G = U^-1, fitted by maximum likelihood
in grey values, with Newton steps in which each pixel's B' is eliminated:
  - saturated values (and values at 0) are censored observations: they enter through the
    probability that the noisy value clipped, so U is determined up to the top wherever long
    exposures saturate; only a --saturation-border around saturated pixels is dropped
    (around those of the same frame for JPEG frames, whose compression lowers the values
    beside a highlight, and for frames deeper than 8 bits; of the next shorter exposure for
    lossless 8-bit ones, so that the values just below saturation stay);
  - lossless 8-bit frames: the noise after the clip (a saturated pixel reading a little below
    the top) is measured from the pixels saturated for sure, and the values near the top
    enter through their exact likelihood under it (`noise_after_clip` in --json); not where
    the saturated values do not look like such a noise (a camera that clips below the top);
  - the noise variance per predicted grey value is measured from the residuals; --weighting
    auto (the default) weights by it unless uniform weights predict held-out exposures
    better by 1% (the choice and both scores are printed), measured or uniform force one;
  - residuals beyond --huber standard deviations pull with bounded force (moving objects,
    misregistration, hot pixels);
  - pixels are drawn at random until the sampling standard error of every determined U(k)
    is below --target-std-error grey values (or all are in; --max-pixels caps the draw).
Exposures in constant ratios leave U undetermined up to ripples with the period of the
ratio; a third-difference prior removes them, smoothing over --smoothness grey values or
more when the ratio is large, and continues U where the data end. The standard errors
combine the sampling error with the sensitivities to the prior and the continuation.

Cameras that tone-map (phones, raw converters, film scans) produce data that no global G
explains. --estimator auto (the default) also scores Debevec and Malik's least squares on
ln U (hat weights, every sampled pixel, lambda 3, 10 or 30) on the held-out exposures, and
takes it when it predicts them better beyond 2 standard errors than the grey-domain fit
refitted afresh in every fold; grey or log force one. The printed fit line says which was
taken and every score.

--plot draws U with its 2-sigma band, the standard errors, the observations, and the noise
variance measured from the residuals beside the shot/read/ADC model fitted to it.")]
    Response(ResponseArgs),
    /// A dense vignette map (vignette.png) from a video of a bright planar wall with one
    /// printed ArUco marker (original dictionary) that gives the plane's pose, with the
    /// paper's raw map, the standard error and the coverage beside it.
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
  vignette_raw.png       the paper's unregularised map on the same scale, sampled as the
                         authors' 2016 tool samples its raw map: the per-pixel estimate
                         filtered with [1/6 2/3 1/6] in x and y (--smoothing 0 writes the
                         per-pixel map itself as vignette.png). Pixels without enough
                         observations, and defective ones, take the value of vignette.png;
                         the coverage image tells which
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
    /// The estimator: auto, grey or log.
    #[arg(long, value_name = "WHICH", value_parser = parse_estimator, help = with_default(
        "The estimator: grey (maximum likelihood in grey values under the camera's noise, \
         with clipping as censoring), log (Debevec and Malik's least squares on ln U with hat \
         weights, for tone-mapping cameras), or auto: grey unless log predicts held-out \
         exposures better beyond chance",
        "auto",
    ))]
    pub estimator: Option<photometric::Estimator>,
    /// How observations are weighted: auto, measured or uniform.
    #[arg(long, value_name = "HOW", value_parser = parse_weighting, help = with_default(
        "How observations are weighted: by the noise measured from the residuals \
         (measured), alike (uniform), or auto: measured unless uniform weights predict \
         held-out exposures better by 1%",
        "auto",
    ))]
    pub weighting: Option<photometric::Weighting>,
    /// Residuals beyond this many standard deviations pull with bounded force (Huber).
    #[arg(long, value_name = "SIGMAS", help = with_default(
        "Residuals beyond this many noise standard deviations pull with bounded force (Huber)",
        ResponseOptions::default().huber,
    ))]
    pub huber: Option<f64>,
    /// The pixel draw grows until the sampling standard error of U is below this.
    #[arg(long, value_name = "GREY", help = with_default(
        "Pixels are drawn until the sampling standard error of every determined U(k) is \
         below this many grey values",
        ResponseOptions::default().target_std_error,
    ))]
    pub target_std_error: Option<f64>,
    /// Most pixels drawn (0: no limit).
    #[arg(long, value_name = "N", help = with_default(
        "Most pixels drawn (0: all if the standard errors need them)",
        ResponseOptions::default().max_pixels,
    ))]
    pub max_pixels: Option<usize>,
    /// Radius (pixels) dropped around saturated pixels (of the same frame for JPEG and deeper
    /// frames, of the next shorter exposure for lossless 8-bit ones).
    #[arg(long, value_name = "PX", help = with_default(
        "Radius (pixels) dropped around saturated pixels (of the same frame for JPEG and deeper frames, of the next shorter exposure for lossless 8-bit ones)",
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
    /// chosen by cross-validation; 0 writes the per-pixel map (unregularised, unsampled).
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

/// `--estimator`'s values.
fn parse_estimator(s: &str) -> Result<photometric::Estimator, String> {
    match s {
        "auto" => Ok(photometric::Estimator::Auto),
        "grey" => Ok(photometric::Estimator::Grey),
        "log" => Ok(photometric::Estimator::Log),
        other => Err(format!("`{other}`: expected auto, grey or log")),
    }
}

/// `--weighting`'s values.
fn parse_weighting(s: &str) -> Result<photometric::Weighting, String> {
    match s {
        "auto" => Ok(photometric::Weighting::Auto),
        "measured" => Ok(photometric::Weighting::Measured),
        "uniform" => Ok(photometric::Weighting::Uniform),
        other => Err(format!("`{other}`: expected auto, measured or uniform")),
    }
}

/// A flag's help with the default it takes when neither the flag nor `--config` sets it.
fn with_default(text: &str, default: impl std::fmt::Display) -> String {
    format!("{text} [default: {default}, or from --config]")
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
    if let Some(v) = a.estimator {
        o.estimator = v;
    }
    if let Some(v) = a.weighting {
        o.weighting = v;
    }
    if let Some(v) = a.huber {
        o.huber = v;
    }
    if let Some(v) = a.target_std_error {
        o.target_std_error = v;
    }
    if let Some(v) = a.max_pixels {
        o.max_pixels = v;
    }
    if let Some(v) = a.saturation_border {
        o.saturation_border = v;
    }
    o.max_iterations = o.max_iterations.max(1);
    o.smoothness = o.smoothness.max(0.0);
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

/// Checks every output path before any work.
fn check_outputs(paths: &[&Path], force: bool) -> Result<()> {
    for p in paths {
        dataset_io::check_output_file(p, force)?;
    }
    Ok(())
}

fn run_response(a: &ResponseArgs) -> Result<()> {
    let std_path = sibling(&a.output, "_std");
    let mut outs: Vec<&Path> = vec![&a.output, &std_path];
    if let Some(p) = &a.plot {
        plot::format_of(p)?;
        outs.push(p);
    }
    check_outputs(&outs, a.force)?;
    let job = ResponseJob {
        sequence: a.sequence.clone(),
        bit_depth: a.bit_depth,
        options: response_options(a)?,
    };
    let ResponseRun {
        cal,
        frames: nframes,
        report,
    } = calibrate_response_sequence(&job, &progress::Bars::default())?;
    if !a.json {
        outln!("{report}")?;
    }
    for w in &cal.warnings {
        crate::warn(format_args!("{w}"));
    }
    write_response(&cal, &a.output, &std_path)?;
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
                "stop": cal.stop,
                "restarted": cal.restarted,
                "change": cal.change,
                "rmse": cal.rmse,
                "observed_min": cal.observed_range.0,
                "observed_max": cal.observed_range.1,
                "filled": cal.filled,
                "estimator": cal.estimator,
                "log_lambda": cal.log_lambda,
                "log_all_values": cal.log_all_values,
                "weighting": cal.weighting,
                "held_out": cal.held_out,
                "prior_scale": cal.prior_scale,
                "measured_noise": cal.measured_noise,
                "noise": cal.noise,
                "noise_after_clip": cal.noise_after_clip,
                "prior_weight": cal.prior_weight,
                "pixels_sampled": cal.pixels_sampled,
                "pixels_available": cal.pixels_available,
                "sampling_error": cal.sampling_error,
                "u": cal.response.table(),
                "std_error": cal.std_error,
                "systematic_error": cal.systematic_error,
                "histogram": cal.histogram,
                "warnings": cal.warnings,
            })
        )?;
    } else {
        outln!(
            "{}; residual RMS {:.3} grey values",
            stop_line(cal.stop, cal.iterations, &cal.change, cal.restarted),
            cal.rmse
        )?;
        outln!("{}", weighting_line(&cal))?;
        outln!("{}", noise_line(&cal))?;
        outln!(
            "pixels: {} of the {} with two unsaturated values drawn; RMS sampling standard error of U {:.3} grey values",
            cal.pixels_sampled, cal.pixels_available, cal.sampling_error
        )?;
        outln!(
            "U determined by the data for grey values {}..{}; {} value(s) continued beyond them; largest standard error {:.3} grey values",
            cal.observed_range.0,
            cal.observed_range.1,
            cal.filled.len(),
            max_std
        )?;
        outln!("wrote {} and {}", a.output.display(), std_path.display())?;
    }
    Ok(())
}

/// How the response fit's iteration ended, for the text output.
fn stop_line(
    stop: photometric::Stop,
    iterations: usize,
    change: &[f64],
    restarted: bool,
) -> String {
    use photometric::Stop;
    let last = change.last().copied().unwrap_or(f64::NAN);
    let line = match stop {
        Stop::Tolerance => {
            format!("converged after {iterations} iterations (last change {last:.4} grey values)")
        }
        Stop::Settled => format!(
            "converged after {iterations} iterations: what the iteration would still move lies \
             within the standard errors (last change {last:.4} grey values)"
        ),
        Stop::RefusedWithinNoise => format!(
            "converged after {iterations} iterations: the last step tried made the objective \
             worse and moved U within the standard errors, so the state before it is kept (the \
             step, taken back, moved U by {last:.4} grey values)"
        ),
        Stop::NoImprovement => format!(
            "converged after {iterations} iterations: no shorter step lowered the objective, so \
             the last state that did is kept (the last step tried, taken back, moved U by \
             {last:.4} grey values)"
        ),
        Stop::Flat => format!(
            "converged after {iterations} iterations: the objective stopped falling (last change \
             {last:.4} grey values)"
        ),
        Stop::Limit => format!(
            "not converged: stopped at the iteration limit, {iterations} iterations (last change \
             {last:.4} grey values)"
        ),
    };
    if restarted {
        format!(
            "{line}; from the second start (U above grey value 245 continued as a quadratic in \
             log U), after the first start's iteration ended where no step lowered the objective"
        )
    } else {
        line
    }
}

/// The estimator, weights and prior used, and the held-out check that chose them.
fn weighting_line(cal: &photometric::ResponseCalibration) -> String {
    let what = match cal.log_lambda {
        Some(lambda) => format!(
            "log-domain (Debevec-Malik) least squares, lambda {lambda}{}",
            if cal.log_all_values {
                ", also the values next to saturated pixels"
            } else {
                ""
            }
        ),
        None => format!(
            "grey-domain maximum likelihood, {} weights, prior x{}",
            match cal.weighting {
                photometric::Weighting::Uniform => "uniform",
                _ => "measured-noise",
            },
            cal.prior_scale
        ),
    };
    match &cal.held_out {
        Some(h) => {
            let scores: Vec<String> = h
                .candidates
                .iter()
                .map(|c| match c.estimator {
                    photometric::Estimator::Log => format!(
                        "log lambda {}{} {:.3}",
                        c.prior_scale,
                        if c.all_values { " all values" } else { "" },
                        c.rms
                    ),
                    _ => format!(
                        "{} x{}{} {:.3}",
                        if c.measured { "measured" } else { "uniform" },
                        c.prior_scale,
                        if c.cold { " (fold fits afresh)" } else { "" },
                        c.rms
                    ),
                })
                .collect();
            format!(
                "fit: {what}, chosen by predicting held-out exposures ({} folds, {} pixels; RMS error in grey values: {})",
                h.folds,
                h.pixels,
                scores.join(", ")
            )
        }
        None => format!("fit: {what} (as asked)"),
    }
}

/// The noise measured from the residuals, and the model fitted to it.
fn noise_line(cal: &photometric::ResponseCalibration) -> String {
    let sds: Vec<(f64, f64)> = cal
        .measured_noise
        .iter()
        .filter(|b| b.variance.is_finite())
        .map(|b| (b.grey, b.variance.sqrt()))
        .collect();
    let range = match (sds.first(), sds.last()) {
        (Some(a), Some(b)) => format!(
            "standard deviation {:.2} at grey value {:.0} to {:.2} at {:.0}",
            a.1, a.0, b.1, b.0
        ),
        _ => "not measured".into(),
    };
    let after = if cal.noise_after_clip > 0.0 {
        format!(
            "; {:.2} after the clip (a saturated pixel reads the top plus this noise, rounded and clipped)",
            cal.noise_after_clip
        )
    } else {
        String::new()
    };
    match &cal.noise {
        Some(m) => format!(
            "noise measured from the residuals: {range}{after}; shot/read/ADC model fitted to it: read {:.3} U^2, shot {:.4} U per U, ADC {:.3} grey^2",
            m.read, m.shot, m.adc
        ),
        None => format!("noise measured from the residuals: {range}{after}"),
    }
}

/// The library's vignette job for these arguments (options from flags and `--config`).
pub fn vignette_job(a: &VignetteArgs) -> Result<VignetteJob> {
    Ok(VignetteJob {
        sequence: a.sequence.clone(),
        pcalib: a.pcalib.clone(),
        poses: a.poses.clone(),
        marker_id: a.marker_id,
        bit_depth: a.bit_depth,
        options: vignette_options(a)?,
        // beside the output: a place the user chose to write to
        scratch: Some(
            a.output
                .parent()
                .map_or_else(|| ".".into(), |d| d.to_path_buf()),
        ),
    })
}

fn run_vignette(a: &VignetteArgs) -> Result<()> {
    let files = VignetteFiles::beside(&a.output);
    let mut outs: Vec<&Path> = files.all().to_vec();
    if let Some(p) = &a.plot {
        plot::format_of(p)?;
        outs.push(p);
    }
    check_outputs(&outs, a.force)?;
    let job = vignette_job(a)?;
    let run = calibrate_vignette_sequence(&job, &progress::Bars::default())?;
    if !a.json {
        outln!("{}", run.poses_text())?;
    }
    let options = &job.options;
    let VignetteRun {
        cal,
        used,
        skipped,
        bits,
        jpeg,
        ..
    } = run;
    let skipped_total: usize = skipped.values().sum();
    for w in &cal.warnings {
        crate::warn(format_args!("{w}"));
    }
    let MapScales {
        raw_scale: raw_max,
        std_scale,
    } = write_vignette_maps(&cal, &files)?;
    let (raw_path, std_path, cov_path) = (&files.raw, &files.std, &files.coverage);
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
                "jpeg_frames": jpeg,
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
            "{:.1}% of the pixels observed {} times or more; {} defective pixel(s) left out{}",
            100.0 * cal.coverage,
            options.min_observations,
            cal.smoothing.defects,
            if jpeg && cal.smoothing.defects > 0 {
                " (hot, dead, or biased by the JPEG compression)"
            } else {
                ""
            }
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
