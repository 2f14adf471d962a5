//! Response calibration (paper section 2.3.1): the inverse response `U` from a static scene
//! seen at known, varying exposures.
//!
//! The model is the paper's, `I_i(x) = G(t_i B'(x)) + noise` with `G = U^-1`, fitted by
//! maximum likelihood on what a real camera records, `I = clip(round(G(t B') + n))`:
//!
//! * **The residual is measured where the noise is**, in grey values: a regression of the
//!   noisy value on the model's prediction (the paper's `U(k) = mean of t B'` over the pixels
//!   of value `k` regresses the other way and is biased).
//! * **Saturation is information.** A value at the top (or at 0) is a censored observation:
//!   it enters through the probability that the noisy value clipped, given the prediction.
//!   Every observation enters, none is chosen by its observed value (which biases bright
//!   pixels low), no band below saturation is dropped, and `U` is determined up to the top
//!   code wherever long exposures saturate. Only the pixels next to a saturated one are
//!   dropped, as in the paper (blooming, the compression's ringing): saturated in the same
//!   frame for JPEG and deeper frames, in the frame of the next shorter exposure for lossless
//!   8-bit ones.
//! * **Noise from the data.** The variance of an observation as a function of its predicted
//!   grey value is measured from the residuals (a robust scale per bin, corrected for
//!   leverage, smoothed). The weights follow it, or are uniform: a held-out check decides
//!   (the frames of each fold of exposures are predicted from the fit without them), so the
//!   weights are never worse than uniform ones on data that does not follow any noise model.
//!   The shot/read/ADC model is fitted to the measurement to describe it, never to weight.
//! * **Cameras that tone-map.** Phones, raw converters and film record data that no global
//!   `G` explains; there the grey-domain fit can leave a plateau in `U` that no prediction
//!   visits. The held-out check also scores Debevec and Malik's least squares on `ln U` (hat
//!   weights, every sampled pixel; `logfit`) and takes it only when it predicts the held-out
//!   exposures better beyond 2 standard errors than the grey-domain fit refitted afresh.
//! * **Outliers pull with bounded force** (Huber beyond 3 standard deviations): moving
//!   people and cars, misregistered edges, hot pixels.
//! * **Newton steps on the profiled problem**: a step for every pixel's `B'`, then a
//!   Gauss-Newton step for `U` with `B'` eliminated (its Schur complement): a few passes.
//! * **As many pixels as the accuracy needs.** The pixels are drawn at random (reproducibly);
//!   the draw grows until the sampling standard error of `U` is below
//!   [`ResponseOptions::target_std_error`] (or every pixel is in), so a sweep of 157 million
//!   observations takes a few seconds.
//! * **A prior only where the data are blind.** With exposures in constant steps of a ratio
//!   `r`, `U` times any function periodic in `log U` with period `log r` fits the data as well
//!   (each pixel's `B'` absorbs it). A third-difference prior removes these ripples; its
//!   weight grows with the ripple period the exposure steps allow. It also continues `U`
//!   where the data say nothing (no dark pixels): the quadratic continuation of the
//!   well-observed values. The result is scaled to `U(255) = 255`, finite and strictly
//!   increasing.
//! * **With its uncertainty**: the standard error of every `U(k)` combines the sampling error
//!   (sandwich covariance with tiles of 32x32 pixels as the independent units: JPEG blocks and
//!   demosaicing correlate neighbours) and what the prior and the continuation may add.

mod logfit;
mod measured;
mod model;
mod prior;
mod samples;
mod select;
mod solver;
mod uncertainty;

use camera_model::Image;

pub use model::{Estimator, Stop, Weighting};
pub use select::{CandidateScore, HeldOutScores};

use crate::noise::{fit_noise, NoiseModel};
use crate::{InverseResponse, PhotometricError};
use measured::Measured;
use prior::{data_range, extrapolate};
use samples::{draw, scan, Border, Levels, Sample, Samples};
use solver::{solve, Fit, Problem, Settings, Start};
use uncertainty::{normalized, standard_errors};

/// Most knots of the table the solver estimates: a frame of `k` bits is calibrated on
/// `min(2^k, MAX_KNOTS)` equally spaced knots (every grey value up to 9 bits), and the
/// `2^k`-value table is their linear interpolation.
pub const MAX_KNOTS: usize = 512;

/// Options of [`calibrate_response`].
///
/// Deserialised fields that are absent keep their defaults; unknown ones are an error.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ResponseOptions {
    /// Iteration limit of each fit.
    pub max_iterations: usize,
    /// Stop when the largest change of `U` (scaled to `U(255) = 255`) between two iterations
    /// is below this many grey levels.
    pub tolerance: f64,
    /// The smallest scale, in grey values, over which the third-difference prior smooths
    /// `U` (it smooths over more where the exposure steps leave longer ripples undetermined;
    /// see the module documentation). Smaller values leave more to the data.
    pub smoothness: f64,
    /// Radius (pixels) of the neighbourhood of a saturated pixel whose observations are
    /// dropped. With [`ResponseOptions::jpeg`], and for frames deeper than 8 bits, the
    /// saturated pixels of the same frame decide it; for lossless 8-bit frames those of the
    /// frame of the next shorter exposure (a lossless frame's noise is each pixel's own, and
    /// the frame itself would drop nearly every value just below saturation on a smooth
    /// scene).
    pub saturation_border: usize,
    /// JPEG frames: values within 2 grey values of the top (8-bit) count as clipped. Only
    /// [`ResponseOptions::saturation_border`] drops values around a saturated pixel, not its
    /// whole 8x8 block: whether a block holds a saturated pixel depends on the compression
    /// error its pixels share, so keeping only the blocks without one would keep the values
    /// that the compression lowered.
    pub jpeg: bool,
    /// Grey values with fewer observations count as not determined by the data.
    pub min_count: u64,
    /// How observations are weighted: `auto` (by the measured noise unless uniform weights
    /// predict held-out exposures better by 1%), `measured` (by the noise measured from the
    /// residuals) or `uniform`.
    pub weighting: Weighting,
    /// Let the held-out check also try a 10 and a 100 times weaker prior (taken only when it
    /// predicts held-out exposures clearly better: real cameras' curves have features the
    /// prior the exposures' ripples need would smooth away).
    pub choose_prior: bool,
    /// Residuals beyond this many noise standard deviations pull with bounded force (Huber).
    pub huber: f64,
    /// The pixel sample grows until the RMS sampling standard error of the determined
    /// `U(k)` is below this many grey values (on the `U(255) = 255` scale), up to every
    /// pixel or samples of a quarter of the frames' memory (8-bit frames; half of it for
    /// deeper ones).
    pub target_std_error: f64,
    /// Most pixels drawn (0: every pixel if the standard errors need them).
    pub max_pixels: usize,
    /// The estimator: `auto` (the grey-domain maximum likelihood unless the log-domain fit
    /// predicts held-out exposures better beyond chance), `grey` or `log`.
    pub estimator: Estimator,
}

impl Default for ResponseOptions {
    fn default() -> Self {
        ResponseOptions {
            max_iterations: 100,
            tolerance: 0.01,
            smoothness: 3.0,
            saturation_border: 2,
            jpeg: false,
            min_count: 20,
            weighting: Weighting::Auto,
            choose_prior: true,
            huber: 5.0,
            target_std_error: 0.03,
            max_pixels: DEFAULT_MAX_PIXELS,
            estimator: Estimator::Auto,
        }
    }
}

/// The largest `max_iterations` of the calibration options.
pub(crate) const MAX_ITERATIONS_LIMIT: usize = 100_000;

impl ResponseOptions {
    /// Refuses options outside the values they can take (a config file or a caller may give
    /// anything): what [`calibrate_response`] checks before any work.
    pub fn check(&self) -> Result<(), PhotometricError> {
        let bad = |name, value: String, expected| {
            Err(PhotometricError::InvalidOption {
                name,
                value,
                expected,
            })
        };
        let finite_nonneg = |v: f64| v.is_finite() && v >= 0.0;
        if !(1..=MAX_ITERATIONS_LIMIT).contains(&self.max_iterations) {
            return bad(
                "max_iterations",
                self.max_iterations.to_string(),
                "1 to 100000 iterations",
            );
        }
        if !finite_nonneg(self.tolerance) {
            return bad(
                "tolerance",
                self.tolerance.to_string(),
                "a finite number of grey levels, 0 or more",
            );
        }
        if !finite_nonneg(self.smoothness) {
            return bad(
                "smoothness",
                self.smoothness.to_string(),
                "a finite number of grey values, 0 or more",
            );
        }
        if self.saturation_border > 256 {
            return bad(
                "saturation_border",
                self.saturation_border.to_string(),
                "0 to 256 pixels",
            );
        }
        if !(self.huber.is_finite() && self.huber >= 1.0) {
            return bad(
                "huber",
                self.huber.to_string(),
                "a finite number of standard deviations, 1 or more",
            );
        }
        if !(self.target_std_error.is_finite() && self.target_std_error > 0.0) {
            return bad(
                "target_std_error",
                self.target_std_error.to_string(),
                "a finite number of grey values above 0",
            );
        }
        Ok(())
    }
}

/// The measured noise in one bin of predicted grey values.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct NoiseBin {
    /// The bin's centre (grey value of the frames).
    pub grey: f64,
    /// The robust variance of the residuals (grey values squared; NaN where not measured:
    /// too few residuals, or truncated by the clipping).
    pub variance: f64,
    /// Residuals in the bin.
    pub count: u64,
}

/// The result of [`calibrate_response`].
#[derive(Clone, Debug, serde::Serialize)]
pub struct ResponseCalibration {
    /// The inverse response, `U(255) = 255` (`U(2^k - 1) = 255` for `k`-bit frames),
    /// strictly increasing, one value per grey value of the frames.
    pub response: InverseResponse,
    /// Standard error of each `U(k)` on the same scale (0 at the top, which is fixed):
    /// sampling and systematic parts together.
    pub std_error: Vec<f64>,
    /// The systematic part: what the prior and the continuation beyond the data may add (for
    /// the log-domain fit: its distance from the grey-domain fit on the same data).
    pub systematic_error: Vec<f64>,
    /// Iterations run (all fits of the growing sample together).
    pub iterations: usize,
    /// Whether the iteration converged (stopped for any reason but the iteration limit).
    pub converged: bool,
    /// Why the iteration stopped.
    pub stop: Stop,
    /// The fit comes from the second start, whose `U` above grey value 245 goes on as a
    /// quadratic in `log U` (a strongly compressive response): the first start's iteration
    /// ended where no step lowered the objective, and this one converged.
    pub restarted: bool,
    /// Largest change of `U` (grey levels, `U(255) = 255`) in each iteration.
    pub change: Vec<f64>,
    /// Root-mean-square residual `I - G(t B')` of the values (not clipped), in grey levels.
    pub rmse: f64,
    /// Smallest and largest grey value determined by the data (the rest is continued).
    pub observed_range: (u32, u32),
    /// Grey values not determined by the data (continued).
    pub filled: Vec<u32>,
    /// Pixels per grey value, over all frames.
    pub histogram: Vec<u64>,
    /// Values of the sample (not clipped) predicted at each knot of the estimate (per grey
    /// value for frames of up to 9 bits; see `knot_step`).
    pub used: Vec<u64>,
    /// Grey values per knot of the estimate: 1 for frames of up to 9 bits, `(2^k - 1) /
    /// (MAX_KNOTS - 1)` for deeper ones.
    pub knot_step: f64,
    /// The noise measured from the residuals, per bin of predicted grey values.
    pub measured_noise: Vec<NoiseBin>,
    /// The shot/read/ADC model fitted to the measured noise (a description; in grey values,
    /// `U` on the `U(255) = 255` scale; `None` when it could not be fitted).
    pub noise: Option<NoiseModel>,
    /// The noise after the clip, in grey values (0 when none was measured: JPEG and deeper
    /// frames, and values of saturated pixels that such a noise does not describe): measured
    /// from the values of pixels saturated for sure, which read the top plus this noise.
    /// Values within its reach of the top enter as a mixture of a saturated pixel and an
    /// unsaturated one.
    pub noise_after_clip: f64,
    /// The estimator used: [`Estimator::Grey`] or [`Estimator::Log`] (then `weighting`,
    /// `noise` and `prior_scale` describe the grey-domain fit that determined the range, and
    /// `log_lambda` the prior of the table).
    pub estimator: Estimator,
    /// Debevec's `lambda` of the log-domain fit, when it made the table.
    pub log_lambda: Option<f64>,
    /// The log-domain fit took every value between the clipping points (also those next to
    /// saturated pixels, which the grey-domain fit drops).
    pub log_all_values: bool,
    /// The weights used.
    pub weighting: Weighting,
    /// The prior's weight relative to what the exposures' ripples need (1, or what the
    /// held-out check chose).
    pub prior_scale: f64,
    /// The held-out check that chose the weights and the prior (when there was a choice).
    pub held_out: Option<HeldOutScores>,
    /// The prior's median weight relative to the information per grey value (`scale^6`).
    pub prior_weight: f64,
    /// Pixels drawn, and how many had at least two values inside the range.
    pub pixels_sampled: usize,
    /// Pixels with at least two values strictly between 0 and saturation.
    pub pixels_available: usize,
    /// RMS sampling standard error of the determined `U(k)` (grey values).
    pub sampling_error: f64,
    /// Things the user should know (little data at one end, few exposures).
    pub warnings: Vec<String>,
}

/// Calibrates the inverse response from `frames` (8-bit grey, all the same size) taken at
/// `exposures_ms`. The frames are not changed (the mutable borrow is kept for
/// compatibility). `progress` is called after every iteration with the iteration number and
/// the largest change of `U` in grey levels (on the `U(255) = 255` scale).
pub fn calibrate_response(
    frames: &mut [Image<u8>],
    exposures_ms: &[f64],
    options: &ResponseOptions,
    progress: &(dyn Fn(usize, f64) + Sync),
) -> Result<ResponseCalibration, PhotometricError> {
    calibrate(
        frames,
        Levels::new(8, MAX_KNOTS),
        exposures_ms,
        options,
        progress,
    )
}

/// Calibrates the `2^bits`-value inverse response of a sensor deeper than 8 bits (`bits`
/// from 8 to 16) from frames whose samples hold `bits`-bit values in the low bits
/// (`0 ..= 2^bits - 1`; a 12-bit sensor's 16-bit PNG has values up to 4095). The estimate is
/// taken on `min(2^bits, MAX_KNOTS)` equally spaced knots and interpolated linearly to every
/// value. All grey values in the result are on the frames' own scale; `U(2^bits - 1) = 255`.
///
/// A sample above `2^bits - 1` is an error naming the frame and the value (values in the
/// high bits of a 16-bit sample have bit depth 16, or must be shifted down first).
pub fn calibrate_response_deep(
    frames: &[Image<u16>],
    bits: u32,
    exposures_ms: &[f64],
    options: &ResponseOptions,
    progress: &(dyn Fn(usize, f64) + Sync),
) -> Result<ResponseCalibration, PhotometricError> {
    if !(8..=16).contains(&bits) {
        return Err(PhotometricError::BitDepth(bits));
    }
    let levels = Levels::new(bits, MAX_KNOTS);
    for (i, f) in frames.iter().enumerate() {
        if let Some(&v) = f.data().iter().find(|&&v| v as u32 > levels.top) {
            return Err(PhotometricError::Calibration(format!(
                "frame {i} has the value {v}, more than a {bits}-bit sample holds (at most {}); if the values are in the high bits of the 16-bit samples, shift them down or use bit depth 16",
                levels.top
            )));
        }
    }
    calibrate(frames, levels, exposures_ms, options, progress)
}

fn invalid(msg: String) -> PhotometricError {
    PhotometricError::Calibration(msg)
}

/// The checks on the frames and exposures before any work; returns the distinct exposures.
fn check_input<T: Sample>(
    frames: &[Image<T>],
    exposures_ms: &[f64],
) -> Result<Vec<f64>, PhotometricError> {
    let n = frames.len();
    if n < 2 {
        return Err(invalid(format!(
            "response calibration needs at least 2 frames, got {n}"
        )));
    }
    if exposures_ms.len() != n {
        return Err(invalid(format!(
            "{} exposures for {n} frames",
            exposures_ms.len()
        )));
    }
    if let Some(t) = exposures_ms.iter().find(|t| !(t.is_finite() && **t > 0.0)) {
        return Err(PhotometricError::Exposure(*t));
    }
    let (w, h) = frames[0].size();
    for (i, f) in frames.iter().enumerate() {
        if f.size() != (w, h) {
            return Err(PhotometricError::SizeMismatch {
                what: if i == 0 { "frame 0" } else { "a frame" },
                width: w,
                height: h,
                got_width: f.width(),
                got_height: f.height(),
            });
        }
    }
    let mut distinct: Vec<f64> = exposures_ms.to_vec();
    distinct.sort_by(f64::total_cmp);
    distinct.dedup_by(|a, b| (*a / *b - 1.0).abs() < 1e-6);
    if distinct.len() < 2 {
        return Err(invalid(format!(
            "every frame has the same exposure ({} ms): the response is not observable; record the scene while changing the exposure",
            distinct[0]
        )));
    }
    if distinct.len() < 3 {
        return Err(invalid(format!(
            "only {} different exposure times: two exposures determine U only up to a periodic factor; record at least 3 (the paper: 120 from 0.05 to 20 ms)",
            distinct.len()
        )));
    }
    Ok(distinct)
}

/// With JPEG frames ([`ResponseOptions::jpeg`]), values this many 8-bit grey values below the
/// top count as clipped: a saturated area decodes to values just under the top (quality
/// 90: 253 and 254 besides 255).
const JPEG_CLIP: u32 = 2;

/// Pixels in the first draw.
const FIRST_DRAW: usize = 1 << 15;

/// Most pixels drawn by default: 131,072 pixels of 120 frames are 16 million observations,
/// which determine 256 values far beyond the systematic errors (a 1280x1024 sweep of the
/// high-noise sensor: 0.08 grey values largest error with every pixel, 0.17 with these).
pub const DEFAULT_MAX_PIXELS: usize = 1 << 17;

/// Most pixels of the held-out check, and the observations it aims at (fewer pixels for
/// longer sweeps).
const CHECK_PIXELS: usize = 1 << 13;
const CHECK_OBSERVATIONS: usize = 1 << 17;

/// A fit on the growing sample, and the sampling error of the determined values.
struct Grown {
    fit: Fit,
    samples: Samples,
    iterations: usize,
    change: Vec<f64>,
    sampling_error: f64,
    /// The fit comes from the steep start (the first did not converge).
    restarted: bool,
}

/// The RMS sampling standard error over the determined knots (the ends, where few
/// observations fall, are larger; their share in it grows the sample too).
fn sampling_error(fit: &Fit) -> Result<f64, PhotometricError> {
    let (first, last) = data_range(&fit.sums.used);
    let e = standard_errors(fit, first, last)?;
    let v = &e.sampling[first..=last.min(e.sampling.len() - 2)];
    Ok((v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt())
}

/// Fits on a draw that grows until the sampling error is below the target.
fn fit_growing<T: Sample>(
    frames: &[Image<T>],
    base: &Problem<'_>,
    scan: &samples::Scan,
    options: &ResponseOptions,
    progress: &(dyn Fn(usize, f64) + Sync),
) -> Result<Grown, PhotometricError> {
    let available = scan.order.len();
    // the samples stay within a quarter of the frames' memory with a byte per value of 8-bit
    // frames, within half of it with two bytes per value of deeper ones
    let (w, h) = frames[0].size();
    let memory_cap = (w * h * std::mem::size_of::<T>() / 4).max(2 * FIRST_DRAW);
    let limit = if options.max_pixels == 0 {
        available
    } else {
        options.max_pixels.min(available)
    }
    .min(memory_cap);
    let border = saturation_border(options, base);
    let draw_n = |n| draw(frames, scan, base.levels.top, &border, n);
    let mut n = FIRST_DRAW.min(limit);
    let mut samples = draw_n(n);
    let mut start = Start::Cold;
    let mut iterations = 0;
    let mut change = Vec::new();
    let mut restarted = false;
    loop {
        let p = Problem {
            samples: &samples,
            ..*base
        };
        let cold = matches!(start, Start::Cold);
        let run = |start: Start, done: usize| {
            solve(
                &p,
                start,
                &Settings {
                    // the growth stages share the iteration budget
                    max_iterations: options.max_iterations.saturating_sub(done).max(1),
                    tolerance: options.tolerance,
                    tiles: true,
                    settle: true,
                    progress: &|i, d| progress(done + i, d),
                },
            )
        };
        let mut fit = run(start, iterations)?;
        iterations += fit.iterations;
        if cold && fit.stop == Stop::NoImprovement {
            // a start far from the optimum can leave the iteration where no step helps (a
            // strongly compressive response started too low at the top): the steep start's
            // fit is taken when it converges properly
            let steep = run(Start::ColdSteep, iterations)?;
            iterations += steep.iterations;
            restarted = matches!(steep.stop, Stop::Tolerance | Stop::Settled);
            let dropped = if restarted {
                std::mem::replace(&mut fit, steep)
            } else {
                steep
            };
            // every iteration run is in `change`, the kept fit's last
            change.extend_from_slice(&dropped.change);
        }
        change.extend_from_slice(&fit.change);
        let se = sampling_error(&fit)?;
        if se <= options.target_std_error || n >= limit || iterations >= options.max_iterations {
            return Ok(Grown {
                fit,
                samples,
                iterations,
                change,
                sampling_error: se,
                restarted,
            });
        }
        // the error falls with the square root of the pixels
        let want = (n as f64 * (se / options.target_std_error).powi(2) * 1.2).ceil() as usize;
        let next = want.clamp(2 * n, limit.max(2 * n)).min(limit);
        // the smaller draw goes before the bigger one is made (peak memory)
        let ranks = std::mem::take(&mut samples.rank);
        drop(samples);
        let bigger = draw_n(next);
        let b = carry_over(&ranks, &bigger, &fit.b);
        start = Start::Warm {
            u: fit.u,
            b,
            noise: fit.noise,
            measured: fit.measured,
        };
        samples = bigger;
        n = next;
    }
}

/// The `B'` of the pixels of the draw of `old_ranks` at their places in `new` (NaN for the new
/// pixels).
fn carry_over(old_ranks: &[u32], new: &Samples, b: &[f64]) -> Vec<f64> {
    let mut map = std::collections::HashMap::with_capacity(old_ranks.len());
    for (q, &r) in old_ranks.iter().enumerate() {
        map.insert(r, b[q]);
    }
    new.rank
        .iter()
        .map(|r| map.get(r).copied().unwrap_or(f64::NAN))
        .collect()
}

/// [`calibrate_response`] and [`calibrate_response_deep`] on frames of any sample type.
fn calibrate<T: Sample>(
    frames: &[Image<T>],
    levels: Levels,
    exposures_ms: &[f64],
    options: &ResponseOptions,
    progress: &(dyn Fn(usize, f64) + Sync),
) -> Result<ResponseCalibration, PhotometricError> {
    options.check()?;
    // JPEG frames: values within JPEG_CLIP of the top count as clipped
    let levels = Levels {
        clip: if options.jpeg {
            levels.top - JPEG_CLIP * levels.top / 255
        } else {
            levels.top
        },
        ..levels
    };
    let distinct = check_input(frames, exposures_ms)?;
    let nk = levels.knots;
    let top = levels.top;
    let sc = scan(frames, top);
    check_brightness(&sc.histogram, levels, options.min_count)?;
    if sc.order.is_empty() {
        return Err(invalid(
            "no pixel has two unsaturated values at different exposures: record exposures that overlap in brightness".into(),
        ));
    }
    let empty = Samples::empty(frames.len());
    let mut base = Problem {
        samples: &empty,
        exposures: exposures_ms,
        train: None,
        levels,
        log_gap: select::ripple_period(exposures_ms, None),
        smoothness: options.smoothness,
        huber: options.huber,
        measured: options.weighting != Weighting::Uniform,
        prior_scale: 1.0,
    };
    let (held_out, log_choice) = held_out_check(frames, &sc, &mut base, options)?;
    let grown = fit_growing(frames, &base, &sc, options, progress)?;
    let fit = &grown.fit;

    // what the data determine
    let used = fit.sums.used.clone();
    let min_count = options.min_count.max(1);
    let determined: Vec<bool> = (0..nk)
        .map(|k| {
            let a = k.saturating_sub(1);
            let b = (k + 1).min(nk - 1);
            (a..=b).map(|j| used[j]).sum::<u64>() >= min_count
        })
        .collect();
    let k_lo = (0..nk).find(|&k| determined[k]).unwrap_or(0);
    let k_hi = (0..nk).rev().find(|&k| determined[k]).unwrap_or(nk - 1);
    let (g_lo, g_hi) = (levels.grey(k_lo), levels.grey(k_hi));
    let filled: Vec<u32> = (0..=top).filter(|&v| v < g_lo || v > g_hi).collect();
    let warnings = check_range(&levels, k_lo, k_hi, &distinct, fit, &grown)?;

    let data = |all| logfit::Data {
        samples: &grown.samples,
        exposures: exposures_ms,
        train: None,
        levels: &levels,
        all,
    };
    let (base_u, std_error, systematic, rmse, sampling_error) = match log_choice {
        Some((lambda, all)) => {
            let ((u, se, sys), rmse, sampling) = log_tables(fit, &data(all), lambda, (k_lo, k_hi))?;
            (u, se, sys, rmse, sampling)
        }
        None => {
            let border = border_sensitivity(frames, &sc, &base, options, &grown)?;
            let (u, se, sys) = grey_tables(fit, border.as_deref())?;
            let rmse = (fit.sums.ss / fit.sums.nres.max(1) as f64).sqrt() / levels.scale;
            (u, se, sys, rmse, grown.sampling_error)
        }
    };
    let (table, std_error, systematic) = if nk == top as usize + 1 {
        (base_u, std_error, systematic)
    } else {
        let all = |v: &[f64]| -> Vec<f64> {
            (0..=top)
                .map(|g| crate::noise::interp(v, levels.pos(g)))
                .collect()
        };
        (all(&base_u), all(&std_error), all(&systematic))
    };
    let response = InverseResponse::from_values(table)?;
    let (measured_noise, noise) = describe_noise(fit.measured.as_ref(), &fit.u, levels);
    Ok(ResponseCalibration {
        response,
        std_error,
        systematic_error: systematic,
        iterations: grown.iterations,
        converged: fit.stop != Stop::Limit,
        stop: fit.stop,
        restarted: grown.restarted,
        change: grown.change,
        rmse,
        observed_range: (g_lo, g_hi),
        filled,
        used,
        knot_step: 1.0 / levels.scale,
        measured_noise,
        noise,
        noise_after_clip: fit.noise.post / levels.scale,
        estimator: if log_choice.is_some() {
            Estimator::Log
        } else {
            Estimator::Grey
        },
        log_lambda: log_choice.map(|c| c.0),
        log_all_values: log_choice.is_some_and(|c| c.1),
        weighting: if base.measured {
            Weighting::Measured
        } else {
            Weighting::Uniform
        },
        held_out,
        prior_scale: base.prior_scale,
        prior_weight: median(&fit.prior),
        pixels_sampled: grown.samples.len(),
        pixels_available: sc.order.len(),
        histogram: sc.histogram,
        sampling_error,
        warnings,
    })
}

/// The held-out check, when there is a choice: sets the grey-domain fit's weights and prior in
/// `base`, and returns the scores and the log-domain fit's `lambda` and value choice when that
/// fit was chosen.
#[allow(clippy::type_complexity)]
fn held_out_check<T: Sample>(
    frames: &[Image<T>],
    sc: &samples::Scan,
    base: &mut Problem<'_>,
    options: &ResponseOptions,
) -> Result<(Option<HeldOutScores>, Option<(f64, bool)>), PhotometricError> {
    let weightings: &[bool] = match options.weighting {
        Weighting::Auto => &[true, false],
        Weighting::Measured => &[true],
        Weighting::Uniform => &[false],
    };
    if weightings.len() == 1 && !options.choose_prior && options.estimator == Estimator::Grey {
        return Ok((None, None));
    }
    // fewer pixels for longer sweeps: the check's cost grows with the observations
    let n = (CHECK_OBSERVATIONS / frames.len()).clamp(1024, CHECK_PIXELS);
    let check = draw(
        frames,
        sc,
        base.levels.top,
        &saturation_border(options, base),
        n,
    );
    let (choice, scores) = select::choose(
        base,
        &check,
        weightings,
        options.choose_prior,
        options.estimator,
    )?;
    if choice.estimator == Estimator::Log {
        return Ok((Some(scores), Some((choice.prior_scale, choice.all_values))));
    }
    base.measured = choice.measured;
    base.prior_scale = choice.prior_scale;
    Ok((Some(scores), None))
}

/// Whether the saturation border of a frame comes from the frame itself
/// ([`samples::border_reference`]): for JPEG frames, and for frames deeper than 8 bits,
/// whose saturated pixels the noise after the clip spreads over many values below the top
/// (with the border from the shorter exposure, a 12-bit gamma sweep at low noise was 0.20 off
/// instead of 0.05, of 255).
fn own_border(options: &ResponseOptions, top: u32) -> bool {
    options.jpeg || top > u32::from(u8::MAX)
}

/// The saturation border the fit uses ([`own_border`]).
fn saturation_border(options: &ResponseOptions, base: &Problem<'_>) -> Border {
    Border::new(
        options.saturation_border,
        base.exposures,
        own_border(options, base.levels.top),
    )
}

/// A table, its standard errors and their systematic part.
type Bands = (Vec<f64>, Vec<f64>, Vec<f64>);

/// The grey-domain fit's table (`U(top) = 255`, continued beyond the data), its standard
/// errors and their systematic part.
fn grey_tables(fit: &Fit, border: Option<&[f64]>) -> Result<Bands, PhotometricError> {
    let nk = fit.u.len();
    let (first, last) = data_range(&fit.sums.used);
    let mut errors = standard_errors(fit, first, last)?;
    if let Some(b) = border {
        for (e, d) in errors.systematic.iter_mut().zip(b) {
            *e = e.hypot(*d);
        }
    }
    let base_u = grey_table(fit);
    // the sensitivities estimate the systematic errors only to within a factor: the band is
    // UNCERTAINTY_FACTOR times the combined estimate, with a floor of 0.1% of U
    let mut std_error = vec![0.0; nk];
    let mut systematic = vec![0.0; nk];
    for k in 0..nk - 1 {
        systematic[k] = UNCERTAINTY_FACTOR * errors.systematic[k];
        let total = errors.sampling[k].hypot(errors.systematic[k]);
        std_error[k] = (UNCERTAINTY_FACTOR * total).hypot(UNCERTAINTY_FLOOR * base_u[k]);
    }
    Ok((base_u, std_error, systematic))
}

/// Passes of the refit with the frames' own saturation borders ([`border_sensitivity`]).
const BORDER_ITERATIONS: usize = 2;

/// How far the grey-domain fit moves when each frame's saturation border comes from the frame
/// itself instead of the next shorter exposure (lossless 8-bit frames; `None` where the border
/// is the frame's own anyway): a warm refit of [`BORDER_ITERATIONS`] passes on the same
/// pixels, per knot of the normalised table. The two borders keep different values next to
/// the highlights, where a camera's response is steepest and the clip least well modelled
/// (values of saturated pixels that the noise after the clip puts below the top); the
/// difference is a part of the systematic error, as the prior's and the continuation's are.
fn border_sensitivity<T: Sample>(
    frames: &[Image<T>],
    scan: &samples::Scan,
    base: &Problem<'_>,
    options: &ResponseOptions,
    grown: &Grown,
) -> Result<Option<Vec<f64>>, PhotometricError> {
    if own_border(options, base.levels.top) || options.saturation_border == 0 {
        return Ok(None);
    }
    let border = Border::new(options.saturation_border, base.exposures, true);
    let samples = draw(frames, scan, base.levels.top, &border, grown.samples.len());
    let p = Problem {
        samples: &samples,
        ..*base
    };
    let fit = &grown.fit;
    let start = Start::Warm {
        u: fit.u.clone(),
        b: fit.b.clone(),
        noise: fit.noise.clone(),
        measured: fit.measured.clone(),
    };
    let settings = Settings {
        max_iterations: BORDER_ITERATIONS,
        tolerance: 0.0,
        tiles: false,
        settle: false,
        progress: &|_, _| {},
    };
    let own = solve(&p, start, &settings)?;
    let (a, b) = (grey_table(fit), grey_table(&own));
    Ok(Some(a.iter().zip(&b).map(|(x, y)| (x - y).abs()).collect()))
}

/// The grey-domain fit's table alone (`U(top) = 255`, continued beyond the data).
fn grey_table(fit: &Fit) -> Vec<f64> {
    let (first, last) = data_range(&fit.sums.used);
    normalized(&extrapolate(&fit.u, first, last).0)
}

/// The log-domain fit's table, its standard errors and their systematic part, its residual
/// RMS (grey values) and the RMS sampling error over `range`. The sampling part comes from the
/// spread of its residuals; the systematic part is how far it lies from the grey-domain fit
/// `fit` on the same data (the two estimators' disagreement: the log-domain prior's bias
/// where the data follow the camera model, the model's misfit where they do not).
fn log_tables(
    fit: &Fit,
    data: &logfit::Data<'_>,
    lambda: f64,
    range: (usize, usize),
) -> Result<(Bands, f64, f64), PhotometricError> {
    let nk = data.levels.knots;
    let lf = logfit::fit(data, lambda)?;
    let rmse = logfit::grey_rmse(data, &lf.u);
    let grey = grey_table(fit);
    let band = &lf.u[range.0..=range.1];
    let sampling = (band
        .iter()
        .zip(&lf.se_log[range.0..=range.1])
        .map(|(u, e)| (u * e).powi(2))
        .sum::<f64>()
        / band.len().max(1) as f64)
        .sqrt();
    let mut se = vec![0.0; nk];
    let mut systematic = vec![0.0; nk];
    // (0 at the top, the gauge)
    for k in 0..nk - 1 {
        systematic[k] = (lf.u[k] - grey[k]).abs();
        let e = UNCERTAINTY_FACTOR * lf.u[k] * lf.se_log[k];
        se[k] = e.hypot(systematic[k]).hypot(UNCERTAINTY_FLOOR * lf.u[k]);
    }
    Ok(((lf.u, se, systematic), rmse, sampling))
}

/// The median of the prior's per-row weights (reported).
fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    s.get(s.len() / 2).copied().unwrap_or(0.0)
}

/// How much the standard errors exceed the estimate from the sampling and the sensitivities.
const UNCERTAINTY_FACTOR: f64 = 1.25;

/// The relative floor of the standard errors.
const UNCERTAINTY_FLOOR: f64 = 1e-3;

/// Refuses frames whose values span too little of the range.
fn check_brightness(
    histogram: &[u64],
    levels: Levels,
    min_count: u64,
) -> Result<(), PhotometricError> {
    let nk = levels.knots;
    let mut knot_hist = vec![0u64; nk];
    for (v, &c) in histogram.iter().enumerate() {
        knot_hist[levels.knot(v as u32)] += c;
    }
    let min_count = min_count.max(1);
    let lo = (0..nk - 1).find(|&k| knot_hist[k] >= min_count);
    let hi = (0..nk - 1).rev().find(|&k| knot_hist[k] >= min_count);
    let (Some(lo), Some(hi)) = (lo, hi) else {
        return Err(invalid("no unsaturated pixel in any frame".into()));
    };
    if hi - lo < 16 * (nk - 1) / 255 {
        return Err(invalid(format!(
            "only grey values {}..{} are observed; the scene needs a wider range of brightness (dark pixels and bright ones)",
            levels.grey(lo),
            levels.grey(hi)
        )));
    }
    Ok(())
}

/// Refuses a fit whose data determine too little of `U`, and says what the user should know.
fn check_range(
    levels: &Levels,
    k_lo: usize,
    k_hi: usize,
    distinct: &[f64],
    fit: &Fit,
    grown: &Grown,
) -> Result<Vec<String>, PhotometricError> {
    let nk = levels.knots;
    let top = levels.top;
    let at = |g: usize| g * (nk - 1) / 255;
    let (g_lo, g_hi) = (levels.grey(k_lo), levels.grey(k_hi));
    if k_hi < at(192) {
        return Err(invalid(format!(
            "the data determine U only up to grey value {g_hi} of {top}: no pixel is predicted brighter; record longer exposures or a brighter scene so that grey values up to about {} are observed",
            (250.0 * f64::from(top) / 255.0).round()
        )));
    }
    if k_lo > at(64) {
        return Err(invalid(format!(
            "the data determine U only from grey value {g_lo} up: record shorter exposures or a darker scene so that grey values near 0 are observed"
        )));
    }
    let mut warnings = Vec::new();
    if k_hi < nk - 1 {
        warnings.push(format!(
            "U above grey value {g_hi} is continued beyond the data ({} values): longer exposures or brighter pixels would determine it",
            top - g_hi
        ));
    }
    if k_lo > 0 {
        warnings.push(format!(
            "U below grey value {g_lo} is continued beyond the data: shorter exposures or darker pixels would determine it"
        ));
    }
    if distinct.len() < 8 {
        warnings.push(format!(
            "only {} different exposures: U between them leans on the smoothness prior",
            distinct.len()
        ));
    }
    if fit.stop == Stop::Limit {
        warnings.push(format!(
            "not converged after {} iterations (last change {:.3} grey levels)",
            fit.iterations,
            fit.change.last().copied().unwrap_or(f64::NAN)
        ));
    }
    let _ = grown;
    Ok(warnings)
}

/// The measured noise in grey values, and the shot/read/ADC model fitted to it.
fn describe_noise(
    measured: Option<&Measured>,
    u: &[f64],
    levels: Levels,
) -> (Vec<NoiseBin>, Option<NoiseModel>) {
    let Some(m) = measured else {
        return (Vec::new(), None);
    };
    let per_grey = 1.0 / levels.scale;
    let bins: Vec<NoiseBin> = m
        .bins
        .iter()
        .map(|&(c, v, n)| NoiseBin {
            grey: c * per_grey,
            variance: v * per_grey * per_grey,
            count: n,
        })
        .collect();
    // the model in knots on the U(top) = 255 scale, fitted to the measured bins
    let un = normalized(u);
    let n = un.len();
    let mut rss = vec![0.0; n];
    let mut cnt = vec![0.0; n];
    for &(c, v, count) in &m.bins {
        if v.is_finite() {
            let k = (c.round() as usize).min(n - 1);
            rss[k] += v * count as f64;
            cnt[k] += count as f64;
        }
    }
    let model = fit_noise(&un, &rss, &cnt).map(|nm| NoiseModel {
        read: nm.read,
        shot: nm.shot,
        adc: nm.adc * per_grey * per_grey,
    });
    (bins, model)
}
