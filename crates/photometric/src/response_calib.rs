//! Response calibration (paper section 2.3.1): the inverse response `U` from a static scene
//! seen at known, varying exposures.
//!
//! The model is the paper's, `I_i(x) = G(t_i B'(x)) + noise` with `G = U^-1`, fitted so that
//! it holds on a real, noisy sensor:
//!
//! * **The residual is measured where the noise is.** The estimator minimises
//!   `sum w (I_i(x) - G(t_i B'(x)))^2` in grey levels: a regression of the noisy observation
//!   on the model's prediction, which is unbiased, where the paper's `U(k) = mean of t B'`
//!   over the pixels of value `k` regresses the prediction on the noisy value. The forward
//!   response `G` is the piecewise-linear inverse of the table `U(0..255)`.
//! * **Observations are chosen by the model's prediction, never by the observed value.** An
//!   observation enters only where the predicted grey value `G(t_i B'(x))` lies at least
//!   `censor_sigmas` noise standard deviations inside `[0, 255]`, so neither saturation nor
//!   the black level censors its noise. (Choosing by the observed value keeps a bright pixel
//!   only when its noise was negative, and biases `U` low near saturation.) Saturated pixels
//!   and a small border around them are dropped, as in the paper.
//! * **Each observation is weighted by its noise.** The grey-level variance is modelled as
//!   `(read + shot U(p)) / U'(p)^2 + adc` (read, photon shot and ADC noise through the
//!   response) and fitted to the residuals; each pixel's weight is further scaled by its own
//!   residual variance (shrunk towards the model), which down-weights hot pixels and pixels
//!   where JPEG compression adds error.
//! * **Newton steps on the profiled problem.** Each iteration takes a Gauss-Newton step for
//!   every pixel's `B'` and then a Gauss-Newton step for `U` in which `B'` is eliminated
//!   (its Schur complement, accumulated from a subsample of pixels): it converges in a few
//!   passes over the data where the paper's alternation creeps.
//! * **A prior only where the data are blind.** With exposures in constant steps of a ratio
//!   `r`, every `U` multiplied by a function periodic in `log U` with period `log r` fits the
//!   data exactly as well (each pixel's `B'` absorbs it): a sweep determines `U` only up to
//!   such ripples. A third-difference prior on `U` removes them; its weight grows with the
//!   ripple period that the exposure steps allow, so that on the paper's sweep (steps of
//!   1.05) it is weak and on a few widely spaced exposures it is strong. It also continues
//!   `U` where the data say nothing: the few values next to 0 and 255 that the censoring
//!   leaves out follow the quadratic continuation of the well-observed values, never biased
//!   top values. The result is scaled to `U(255) = 255`, finite and strictly increasing.
//! * **With its uncertainty.** The standard error of every `U(k)` (on the `U(255) = 255`
//!   scale) combines the sampling error, from the sandwich covariance of the Newton step with
//!   blocks of 8 image rows as independent units (JPEG's 8x8 blocks correlate neighbouring
//!   pixels), and the error the prior may add, from the change of `U` when the prior is ten
//!   times weaker.

use camera_model::Image;
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

use crate::noise::{fit_noise, interp, slope_at, NoiseModel};
use crate::{InverseResponse, PhotometricError};

/// Most knots of the table the solver estimates: a frame of `k` bits is calibrated on
/// `min(2^k, MAX_KNOTS)` equally spaced knots (every grey value up to 9 bits), and the
/// `2^k`-value table is their linear interpolation.
pub const MAX_KNOTS: usize = 512;

/// Samples of a frame: 8-bit grey values, or `k`-bit values in the low bits of 16-bit ones.
trait Sample: Copy + Send + Sync + 'static {
    /// The raw value.
    fn raw(self) -> u32;
}

impl Sample for u8 {
    #[inline]
    fn raw(self) -> u32 {
        self as u32
    }
}

impl Sample for u16 {
    #[inline]
    fn raw(self) -> u32 {
        self as u32
    }
}

/// The grey values of the frames and the knots of the estimated table.
#[derive(Clone, Copy, Debug)]
struct Levels {
    /// The largest grey value, `2^k - 1` (saturation).
    top: u32,
    /// Number of knots.
    knots: usize,
    /// Knot position per grey value, `(knots - 1) / top`.
    scale: f64,
}

/// The knot whose `U` fixes the scale during the iteration, of a table of `n` knots (128 of
/// 256).
fn gauge(n: usize) -> usize {
    n / 2
}

impl Levels {
    fn new(bits: u32) -> Levels {
        let top = (1u32 << bits) - 1;
        let knots = (top as usize + 1).min(MAX_KNOTS);
        Levels {
            top,
            knots,
            scale: (knots - 1) as f64 / top as f64,
        }
    }

    /// The knot position of a grey value.
    #[inline]
    fn pos(&self, v: u32) -> f64 {
        v as f64 * self.scale
    }

    /// The nearest knot of a grey value.
    #[inline]
    fn knot(&self, v: u32) -> usize {
        ((v as f64 * self.scale).round() as usize).min(self.knots - 1)
    }
}

/// Options of [`calibrate_response`].
///
/// Deserialised fields that are absent keep their defaults; unknown ones are an error.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ResponseOptions {
    /// Iteration limit.
    pub max_iterations: usize,
    /// Stop when the largest change of `U` (scaled to `U(255) = 255`) between two iterations
    /// is below this many grey levels.
    pub tolerance: f64,
    /// The smallest scale, in grey values, over which the third-difference prior smooths
    /// `U` (it smooths over more where the exposure steps leave longer ripples undetermined;
    /// see the module documentation). Smaller values leave more to the data.
    pub smoothness: f64,
    /// Radius (pixels) of the neighbourhood dropped around saturated pixels.
    pub saturation_border: usize,
    /// An observation enters only where the model predicts a grey value at least this many
    /// noise standard deviations away from 0 and from 255.
    pub censor_sigmas: f64,
    /// Grey values with fewer observations count as not determined by the data.
    pub min_count: u64,
}

impl Default for ResponseOptions {
    fn default() -> Self {
        ResponseOptions {
            max_iterations: 50,
            tolerance: 0.01,
            smoothness: 6.0,
            saturation_border: 1,
            censor_sigmas: 3.0,
            min_count: 20,
        }
    }
}

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
        if !(1..=MAX_ITERATIONS_LIMIT).contains(&self.max_iterations) {
            return bad(
                "max_iterations",
                self.max_iterations.to_string(),
                "1 to 100000 iterations",
            );
        }
        if !self.tolerance.is_finite() || self.tolerance < 0.0 {
            return bad(
                "tolerance",
                self.tolerance.to_string(),
                "a finite number of grey levels, 0 or more",
            );
        }
        if !self.smoothness.is_finite() || self.smoothness < 0.0 {
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
        if !self.censor_sigmas.is_finite() || self.censor_sigmas <= 0.0 {
            return bad(
                "censor_sigmas",
                self.censor_sigmas.to_string(),
                "a finite number of standard deviations above 0",
            );
        }
        Ok(())
    }
}

/// The largest `max_iterations` of the calibration options.
pub(crate) const MAX_ITERATIONS_LIMIT: usize = 100_000;

/// The result of [`calibrate_response`].
#[derive(Clone, Debug, serde::Serialize)]
pub struct ResponseCalibration {
    /// The inverse response, `U(255) = 255` (`U(2^k - 1) = 255` for `k`-bit frames),
    /// strictly increasing, one value per grey value of the frames.
    pub response: InverseResponse,
    /// Standard error of each `U(k)` on the same scale (0 at the top, which is fixed):
    /// sampling and systematic parts together (see the module documentation).
    pub std_error: Vec<f64>,
    /// The systematic part: what the prior, the extrapolation and the selection at the ends
    /// may add.
    pub systematic_error: Vec<f64>,
    /// Iterations run.
    pub iterations: usize,
    /// Whether the tolerance was reached.
    pub converged: bool,
    /// Largest change of `U` (grey levels, `U(255) = 255`) in each iteration.
    pub change: Vec<f64>,
    /// Root-mean-square residual `I - G(t B')` of the observations used, in grey levels.
    pub rmse: f64,
    /// Smallest and largest grey value determined by the data (the rest follows from the
    /// prior).
    pub observed_range: (u32, u32),
    /// Grey values not determined by the data (continued by the prior).
    pub filled: Vec<u32>,
    /// Pixels per grey value, over all frames.
    pub histogram: Vec<u64>,
    /// Observations that entered the last iteration, per knot of the estimate (per grey
    /// value for frames of up to 9 bits; see `knot_step`).
    pub used: Vec<u64>,
    /// Predicted grey values in which observations were used.
    pub censor_range: (f64, f64),
    /// Grey values per knot of the estimate: 1 for frames of up to 9 bits, `(2^k - 1) /
    /// (MAX_KNOTS - 1)` for deeper ones.
    pub knot_step: f64,
    /// The fitted noise model, in knots (grey values for frames of up to 9 bits).
    pub noise: NoiseModel,
    /// Weight of the prior relative to the mean information per grey value.
    pub prior_weight: f64,
    /// Pixels whose observations entered the estimate.
    pub pixels_used: usize,
    /// Things the user should know (little data at one end, few exposures).
    pub warnings: Vec<String>,
}

/// The observations next to saturated pixels (within `radius`, the saturated pixels
/// themselves excluded: they are censored observations) as a bitset, one bit per pixel.
fn saturation_mask<T: Sample>(
    frame: &[T],
    top: u32,
    width: usize,
    height: usize,
    radius: usize,
) -> Vec<u64> {
    let mut bits = vec![0u64; frame.len().div_ceil(64)];
    if radius == 0 || width == 0 {
        return bits;
    }
    let sat: Vec<bool> = frame.iter().map(|&v| v.raw() >= top).collect();
    let mut h = vec![false; sat.len()];
    for y in 0..height {
        let row = &sat[y * width..(y + 1) * width];
        for x in 0..width {
            let lo = x.saturating_sub(radius);
            let hi = (x + radius).min(width - 1);
            h[y * width + x] = row[lo..=hi].iter().any(|&s| s);
        }
    }
    for y in 0..height {
        let lo = y.saturating_sub(radius);
        let hi = (y + radius).min(height - 1);
        for x in 0..width {
            let p = y * width + x;
            if !sat[p] && (lo..=hi).any(|yy| h[yy * width + x]) {
                bits[p / 64] |= 1 << (p % 64);
            }
        }
    }
    bits
}

#[inline]
fn masked(bits: &[u64], p: usize) -> bool {
    bits[p / 64] >> (p % 64) & 1 == 1
}

/// The forward response `G = U^-1` of a strictly increasing table, piecewise linear, with a
/// lookup table over `sqrt(energy)` that makes each evaluation a few operations.
struct Forward {
    u: Vec<f64>,
    inv_du: Vec<f64>,
    lut: Vec<u16>,
    lut_scale: f64,
}

const LUT_SIZE: usize = 4096;

impl Forward {
    fn new(u: &[f64]) -> Forward {
        let n = u.len();
        let mut inv_du = vec![0.0; n];
        for j in 0..n - 1 {
            inv_du[j] = 1.0 / (u[j + 1] - u[j]).max(1e-12);
        }
        let top = u[n - 1].max(1e-12);
        let lut_scale = LUT_SIZE as f64 / top.sqrt();
        let mut lut = vec![0u16; LUT_SIZE + 1];
        let mut j = 0usize;
        for (b, slot) in lut.iter_mut().enumerate() {
            let e = (b as f64 / lut_scale).powi(2);
            while j < n - 2 && u[j + 1] <= e {
                j += 1;
            }
            *slot = j as u16;
        }
        Forward {
            u: u.to_vec(),
            inv_du,
            lut,
            lut_scale,
        }
    }

    /// `(j, f)` with `G(e) = j + f` (in knots), `f` in `[0, 1)`; `None` outside
    /// `[U(0), U(top)]`.
    #[inline]
    fn eval(&self, e: f64) -> Option<(usize, f64)> {
        let n = self.u.len();
        if !(e >= self.u[0] && e < self.u[n - 1]) {
            return None;
        }
        let b = ((e.sqrt() * self.lut_scale) as usize).min(LUT_SIZE);
        let mut j = self.lut[b] as usize;
        while j < n - 2 && self.u[j + 1] <= e {
            j += 1;
        }
        let f = ((e - self.u[j]) * self.inv_du[j]).clamp(0.0, 1.0);
        Some((j, f))
    }
}

/// Per-pixel state.
#[derive(Clone, Copy, Debug, Default)]
struct PixelState {
    /// Irradiance `B'` (U-units per ms); NaN when the pixel has no usable observation.
    b: f64,
    /// Relative noise variance of the pixel (1 = as the noise model says).
    s: f64,
    /// Observations selected in the last B step.
    n: u32,
}

/// Sums of one pass over a chunk of pixels, merged in a fixed order (bit-identical results
/// with any number of threads).
#[derive(Clone)]
struct Sums {
    /// Normal matrix of the U step with `B'` held fixed: diagonal and first off-diagonal.
    diag: Vec<f64>,
    off: Vec<f64>,
    /// Gradient `sum w a r`.
    rhs: Vec<f64>,
    /// The profiled normal matrix (`B'` eliminated pixel by pixel: the Schur complement),
    /// dense; filled after the pass from `bins`.
    hess: Vec<f64>,
    /// Pixels by `B'` (log-spaced bins over the selectable range), weighted by `1 / s`.
    bins: Vec<f64>,
    /// Residual sums of squares and counts per predicted grey value (noise model).
    rss: Vec<f64>,
    cnt: Vec<f64>,
    /// Observations used per predicted grey value.
    used: Vec<u64>,
    /// The weighted sum of squared residuals (the objective without the prior).
    sq: f64,
    nobs: u64,
    pixels: usize,
}

impl Sums {
    fn new(n: usize) -> Sums {
        Sums {
            diag: vec![0.0; n],
            off: vec![0.0; n],
            rhs: vec![0.0; n],
            hess: Vec::new(),
            bins: vec![0.0; B_BINS],
            rss: vec![0.0; n],
            cnt: vec![0.0; n],
            used: vec![0; n],
            sq: 0.0,
            nobs: 0,
            pixels: 0,
        }
    }

    fn add(&mut self, o: &Sums) {
        for k in 0..self.diag.len() {
            self.diag[k] += o.diag[k];
            self.off[k] += o.off[k];
            self.rhs[k] += o.rhs[k];
            self.rss[k] += o.rss[k];
            self.cnt[k] += o.cnt[k];
            self.used[k] += o.used[k];
        }
        for (a, b) in self.bins.iter_mut().zip(&o.bins) {
            *a += b;
        }
        self.sq += o.sq;
        self.nobs += o.nobs;
        self.pixels += o.pixels;
    }
}

/// What one iteration needs to know about the current model.
struct Model<'a> {
    fwd: Forward,
    /// Variance per knot, and its inverse (the passes multiply: a division per observation
    /// took a quarter of their time).
    var: Vec<f64>,
    ivar: Vec<f64>,
    /// The frames' grey values and the knots.
    levels: Levels,
    /// Selection range of predicted grey values (reported) and the energies it maps to
    /// (used: frozen with the range, so that changes of `U` near the ends do not move
    /// observations in and out of the problem).
    lo: f64,
    hi: f64,
    e_lo: f64,
    e_hi: f64,
    /// Where the taper of the weights towards the ends of the range begins.
    e_lo_taper: f64,
    e_hi_taper: f64,
    exposures: &'a [f64],
    /// Whether the pixels' relative variances follow the residuals (else frozen).
    adapt: bool,
    /// `B'` range of the bins (log-spaced).
    b_min: f64,
    b_max: f64,
}

/// `3 x^2 - 2 x^3` on `[0, 1]`.
#[inline]
fn smoothstep(x: f64) -> f64 {
    let x = x.clamp(0.0, 1.0);
    x * x * (3.0 - 2.0 * x)
}

/// Log-spaced bins of `B'` for the profiled normal matrix.
const B_BINS: usize = 1024;

/// Pixels with fewer selected observations do not enter the U step.
const MIN_PIXEL_OBS: u32 = 3;

impl Model<'_> {
    /// The observation's predicted grey value as `(knot, fraction)` if it is selected.
    #[inline]
    fn select(&self, t: f64, b: f64) -> Option<(usize, f64, f64)> {
        let e = t * b;
        if !(e > self.e_lo && e < self.e_hi) {
            return None;
        }
        // weights fall smoothly to 0 at the ends of the range: an observation whose
        // prediction moves across an end does not jump in or out of the problem
        let c = if e < self.e_lo_taper {
            smoothstep((e - self.e_lo) / (self.e_lo_taper - self.e_lo))
        } else if e > self.e_hi_taper {
            smoothstep((self.e_hi - e) / (self.e_hi - self.e_hi_taper))
        } else {
            1.0
        };
        let (j, f) = self.fwd.eval(e)?;
        Some((j, f, c))
    }

    #[inline]
    fn var_at(&self, j: usize, f: f64) -> f64 {
        self.var[if f < 0.5 { j } else { j + 1 }]
    }

    /// `1 / var_at(j, f)`.
    #[inline]
    fn ivar_at(&self, j: usize, f: f64) -> f64 {
        self.ivar[if f < 0.5 { j } else { j + 1 }]
    }
}

/// Rows per chunk of the passes: the chunks are also the independent units of the sandwich
/// covariance, tall enough to hold the 8x8 blocks of JPEG compression.
const CHUNK_ROWS: usize = 8;

/// One iteration over the pixels `start..start + state.len()`: a Gauss-Newton step for each
/// pixel's `B'` (or the paper's closed form for pixels without a usable prediction), then,
/// with the new `B'`, the gradient and normal equations of the U step, the residual
/// statistics of the noise model, and for the Hessian subsample the profiled normal matrix.
fn pass_chunk<T: Sample>(
    frames: &[Image<T>],
    masks: &[Vec<u64>],
    model: &Model<'_>,
    start: usize,
    state: &mut [PixelState],
) -> Sums {
    let n = state.len();
    let fwd = &model.fwd;
    let u = &fwd.u;
    let lv = model.levels;
    // B step
    let mut sjr = vec![0.0f64; n];
    let mut sjj = vec![0.0f64; n];
    let mut cnt = vec![0u32; n];
    let mut num0 = vec![0.0f64; n];
    let mut den0 = vec![0.0f64; n];
    let mut cnt0 = vec![0u32; n];
    for (i, (f, &t)) in frames.iter().zip(model.exposures).enumerate() {
        let px = &f.data()[start..start + n];
        let mk = &masks[i];
        for (x, &k) in px.iter().enumerate() {
            let k = k.raw();
            // saturated observations and their neighbours do not enter
            if k >= lv.top || masked(mk, start + x) {
                continue;
            }
            let kf = lv.pos(k);
            let b = state[x].b;
            if b.is_finite() {
                if let Some((j, fr, c)) = model.select(t, b) {
                    let w = c * model.ivar_at(j, fr);
                    let jac = t * fwd.inv_du[j];
                    let r = kf - (j as f64 + fr);
                    sjr[x] += w * jac * r;
                    sjj[x] += w * jac * jac;
                    cnt[x] += 1;
                }
            }
            // for pixels without a usable prediction: the paper's closed form from the
            // observations in range, only to (re)start the pixel
            if kf >= model.lo && kf <= model.hi {
                num0[x] += t * interp(u, kf);
                den0[x] += t * t;
                cnt0[x] += 1;
            }
        }
    }
    for x in 0..n {
        let st = &mut state[x];
        if cnt[x] >= 1 && sjj[x] > 0.0 {
            let nb = st.b + sjr[x] / sjj[x];
            st.b = if nb > 0.0 { nb } else { 0.5 * st.b };
            st.n = cnt[x];
        } else if den0[x] > 0.0 {
            let restart = st.b.is_finite();
            st.b = num0[x] / den0[x];
            // a start enters the U step; a restart (no observation predicted in range any
            // more) only once its prediction is back in range: its B' comes from a selection
            // by the observed value
            st.n = if restart { 0 } else { cnt0[x] };
        } else {
            st.b = f64::NAN;
            st.n = 0;
        }
    }
    // U step sums with the new B', weighted by each pixel's relative variance of the last
    // iteration; the residuals give this iteration's
    let mut sums = Sums::new(lv.knots);
    let mut rr = vec![0.0f64; n];
    let mut rn = vec![0u32; n];
    let inv_s: Vec<f64> = state.iter().map(|st| 1.0 / st.s).collect();
    for (i, (f, &t)) in frames.iter().zip(model.exposures).enumerate() {
        let px = &f.data()[start..start + n];
        let mk = &masks[i];
        for (x, &k) in px.iter().enumerate() {
            let k = k.raw();
            let st = state[x];
            if k >= lv.top || st.n < MIN_PIXEL_OBS || masked(mk, start + x) {
                continue;
            }
            let Some((j, fr, c)) = model.select(t, st.b) else {
                continue;
            };
            let ivar = model.ivar_at(j, fr);
            let r = lv.pos(k) - (j as f64 + fr);
            rr[x] += r * r * ivar;
            rn[x] += 1;
            let w = c * ivar * inv_s[x];
            // the residual's derivatives: d r / d U(j) = (1 - f) / dU, d r / d U(j+1) = f / dU
            let a0 = (1.0 - fr) * fwd.inv_du[j];
            let a1 = fr * fwd.inv_du[j];
            sums.diag[j] += w * a0 * a0;
            sums.diag[j + 1] += w * a1 * a1;
            sums.off[j] += w * a0 * a1;
            sums.rhs[j] += w * a0 * r;
            sums.rhs[j + 1] += w * a1 * r;
            let kp = if fr < 0.5 { j } else { j + 1 };
            sums.rss[kp] += r * r;
            sums.cnt[kp] += 1.0;
            sums.used[kp] += 1;
            sums.sq += w * r * r;
            sums.nobs += 1;
        }
    }
    // the pixels by B' for the profiled normal matrix
    let scale = B_BINS as f64 / (model.b_max / model.b_min).ln();
    for st in state.iter() {
        if st.n >= MIN_PIXEL_OBS && st.b.is_finite() && st.b > 0.0 {
            let pos = (st.b / model.b_min).ln() * scale;
            if pos >= 0.0 && pos < B_BINS as f64 {
                sums.bins[pos as usize] += 1.0 / st.s;
            }
        }
    }
    // the pixels' relative variances for the next iteration (this one used the last's)
    const PRIOR_DOF: f64 = 4.0;
    for x in 0..n {
        let m = rn[x] as f64;
        if m >= 2.0 {
            if model.adapt {
                state[x].s = (PRIOR_DOF + rr[x] * m / (m - 1.0)) / (PRIOR_DOF + m);
            }
            sums.pixels += 1;
        }
    }
    sums
}

/// The profiled normal matrix of the U step: every pixel's block
/// `[[N_x, g_x], [g_x^T, h_x]]` of the joint normal equations contributes its Schur complement
/// `N_x - g_x g_x^T / h_x` (`B'` eliminated). Pixels of (nearly) equal `B'` contribute equal
/// blocks scaled by their weight `1 / s`, so the sum is formed per bin of `B'` from the bin's
/// centre, over every frame: the full-data matrix at the cost of a thousand pixels.
fn profiled_hessian(model: &Model<'_>, bins: &[f64], actual_diag: &[f64]) -> Vec<f64> {
    let fwd = &model.fwd;
    let n = model.levels.knots;
    let mut hess = vec![0.0f64; n * n];
    let mut model_diag = vec![0.0f64; n];
    let mut g = vec![0.0f64; n];
    let step = (model.b_max / model.b_min).ln() / B_BINS as f64;
    for (bin, &weight) in bins.iter().enumerate() {
        if weight <= 0.0 {
            continue;
        }
        let b = model.b_min * ((bin as f64 + 0.5) * step).exp();
        let (mut lo, mut hi, mut h) = (n, 0usize, 0.0);
        for &t in model.exposures {
            let Some((j, fr, c)) = model.select(t, b) else {
                continue;
            };
            let w = c * weight / model.var_at(j, fr);
            let a0 = (1.0 - fr) * fwd.inv_du[j];
            let a1 = fr * fwd.inv_du[j];
            // d r / d B' = -t G'(t B')
            let jb = t * fwd.inv_du[j];
            hess[j * n + j] += w * a0 * a0;
            hess[(j + 1) * n + j + 1] += w * a1 * a1;
            hess[j * n + j + 1] += w * a0 * a1;
            hess[(j + 1) * n + j] += w * a0 * a1;
            model_diag[j] += w * a0 * a0;
            model_diag[j + 1] += w * a1 * a1;
            g[j] -= w * a0 * jb;
            g[j + 1] -= w * a1 * jb;
            h += w * jb * jb;
            lo = lo.min(j);
            hi = hi.max(j + 1);
        }
        if lo > hi {
            continue;
        }
        if h > 0.0 {
            for a in lo..=hi {
                let ga = g[a] / h;
                if ga != 0.0 {
                    let row = &mut hess[a * n..(a + 1) * n];
                    for c in lo..=hi {
                        row[c] -= ga * g[c];
                    }
                }
            }
        }
        for v in &mut g[lo..=hi] {
            *v = 0.0;
        }
    }
    // the model assumes every selected observation exists; the saturation mask and stuck
    // pixels remove some: scale each value's rows and columns to the information the data
    // actually have (a symmetric diagonal scaling keeps the matrix semi-definite)
    let r: Vec<f64> = (0..n)
        .map(|k| {
            if model_diag[k] > 0.0 {
                (actual_diag[k] / model_diag[k]).sqrt()
            } else {
                0.0
            }
        })
        .collect();
    for a in 0..n {
        for c in 0..n {
            hess[a * n + c] *= r[a] * r[c];
        }
    }
    hess
}

/// One pass over all pixels in fixed chunks: the merged sums (in chunk order, so that the
/// result does not depend on the number of threads) and each chunk's gradient.
fn pass<T: Sample>(
    frames: &[Image<T>],
    masks: &[Vec<u64>],
    model: &Model<'_>,
    state: &mut [PixelState],
) -> (Sums, Vec<Vec<f64>>) {
    let chunk = CHUNK_ROWS * frames[0].width().max(1);
    let parts: Vec<Sums> = state
        .par_chunks_mut(chunk)
        .enumerate()
        .map(|(c, st)| pass_chunk(frames, masks, model, c * chunk, st))
        .collect();
    let mut total = Sums::new(model.levels.knots);
    for p in &parts {
        total.add(p);
    }
    let grads = parts.into_iter().map(|p| p.rhs).collect();
    (total, grads)
}

/// The median information per grey value over the values with data.
fn median_info(diag: &[f64]) -> f64 {
    let mut v: Vec<f64> = diag.iter().copied().filter(|&d| d > 0.0).collect();
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// The U step's linear system `A d = b` at `u`: the profiled normal matrix (or, without a
/// Hessian subsample, the one with `B'` fixed) plus `lambda` times the prior, with `U(GAUGE)`
/// held when `B'` is eliminated (scaling `U` then costs nothing).
fn u_system(
    u: &[f64],
    sums: &Sums,
    penalty: &DMatrix<f64>,
    lambda: f64,
) -> (DMatrix<f64>, DVector<f64>) {
    let mut a = penalty * lambda;
    let uv = DVector::from_column_slice(u);
    let pu = penalty * &uv * lambda;
    let n = u.len();
    let gauge = gauge(n);
    let profiled = !sums.hess.is_empty();
    if profiled {
        for r in 0..n {
            for c in 0..n {
                a[(r, c)] += sums.hess[r * n + c];
            }
        }
    } else {
        for k in 0..n {
            a[(k, k)] += sums.diag[k];
            if k + 1 < n {
                a[(k, k + 1)] += sums.off[k];
                a[(k + 1, k)] += sums.off[k];
            }
        }
    }
    // the new model is G - a.d, so the residual becomes r + a.d
    let mut b = DVector::from_fn(n, |k, _| -sums.rhs[k] - pu[k]);
    if profiled {
        for k in 0..n {
            a[(gauge, k)] = 0.0;
            a[(k, gauge)] = 0.0;
        }
        a[(gauge, gauge)] = 1.0;
        b[gauge] = 0.0;
    }
    // a tiny ridge keeps the system definite where neither data nor prior reach
    let ridge = 1e-12 * (0..n).map(|k| a[(k, k)]).fold(0.0, f64::max).max(1e-300);
    for k in 0..n {
        a[(k, k)] += ridge;
    }
    (a, b)
}

fn singular() -> PhotometricError {
    PhotometricError::Calibration(
        "the response step has no unique solution (too little data); record more exposures".into(),
    )
}

/// Solves the U step; returns the step (shortened to a fifth of the range when longer: far
/// from the solution the linearisation is poor).
fn solve_u_step(
    u: &[f64],
    sums: &Sums,
    penalty: &DMatrix<f64>,
    lambda: f64,
    damping: f64,
) -> Result<Vec<f64>, PhotometricError> {
    let n = u.len();
    let (mut a, b) = u_system(u, sums, penalty, lambda);
    // Levenberg-Marquardt: damping relative to each value's information from the data
    for k in 0..n {
        if k != gauge(n) || sums.hess.is_empty() {
            a[(k, k)] += damping * sums.diag[k];
        }
    }
    let d = a.cholesky().ok_or_else(singular)?.solve(&b);
    let range = (u[n - 1] - u[0]).abs().max(1e-12);
    let longest = d.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let alpha = (0.2 * range / longest.max(1e-300)).min(1.0);
    let mut out = u.to_vec();
    for k in 0..n {
        out[k] += alpha * d[k];
    }
    if out.iter().any(|v| !v.is_finite()) {
        return Err(PhotometricError::Calibration(
            "the response step diverged (not finite); the data do not determine U".into(),
        ));
    }
    Ok(out)
}

/// The prior's weight relative to the information per grey value, `scale^6`: the prior then
/// smooths `U` over about `scale` grey values (a ripple of period `P` costs
/// `(2 pi scale / P)^6` times the information) and leaves longer scales to the data. The
/// scale is `smoothness` grey values, or more where the exposure steps leave longer ripples
/// undetermined: `P / (2 pi)` times `RIPPLE_MARGIN` for the longest period
/// `P = log(largest ratio of consecutive exposures) * U / U'` over the data's range.
fn prior_weight(u: &[f64], log_gap: f64, lo: f64, hi: f64, smoothness: f64) -> f64 {
    let (a, b) = (lo.max(1.0) as usize, (hi as usize).clamp(1, u.len() - 2));
    let period = (a..=b.max(a))
        .map(|k| log_gap * u[k] / slope_at(u, k))
        .fold(0.0f64, f64::max);
    let scale = smoothness.max(RIPPLE_MARGIN * period / std::f64::consts::TAU);
    scale.max(0.0).powi(6)
}

/// How far beyond the longest undetermined ripple period the prior reaches.
const RIPPLE_MARGIN: f64 = 1.3;

/// The third-difference operator's normal matrix `D3^T D3` (`n x n`).
fn third_difference_normal(n: usize) -> DMatrix<f64> {
    let mut m = DMatrix::zeros(n, n);
    let c = [-1.0, 3.0, -3.0, 1.0];
    for r in 0..n - 3 {
        for (a, ca) in c.iter().enumerate() {
            for (b, cb) in c.iter().enumerate() {
                m[(r + a, r + b)] += ca * cb;
            }
        }
    }
    m
}

/// The values the data determine: from the first to the last grey value with at least
/// `MIN_DETERMINING` observations predicted there.
fn data_range(used: &[u64]) -> (usize, usize) {
    let n = used.len();
    let enough = |k: usize| used[k] >= MIN_DETERMINING;
    let first = (0..n).find(|&k| enough(k)).unwrap_or(0);
    let last = (0..n).rev().find(|&k| enough(k)).unwrap_or(n - 1);
    (first, last.max(first))
}

/// Observations a grey value needs to count as determined by the data.
const MIN_DETERMINING: u64 = 20;

/// Grey values next to each end of the data's range over which the extrapolation is fitted.
const EXTRAPOLATION_WINDOW: usize = 32;

/// Coefficients `c` with `fit(at) = sum_j c_j y_j` of the least-squares quadratic through
/// `y_lo ..= y_hi` (equal weights).
fn quadratic_coefficients(lo: usize, hi: usize, at: f64) -> Option<Vec<f64>> {
    let centre = 0.5 * (lo + hi) as f64;
    let mut ata = nalgebra::Matrix3::<f64>::zeros();
    for k in lo..=hi {
        let x = k as f64 - centre;
        let f = nalgebra::Vector3::new(1.0, x, x * x);
        ata += f * f.transpose();
    }
    let inv = ata.try_inverse()?;
    let xa = at - centre;
    let row = nalgebra::Vector3::new(1.0, xa, xa * xa).transpose() * inv;
    Some(
        (lo..=hi)
            .map(|k| {
                let x = k as f64 - centre;
                row[0] + row[1] * x + row[2] * x * x
            })
            .collect(),
    )
}

/// `U` with the values outside the data's range `first..=last` extrapolated, and the
/// Jacobian of that map. Above the data, `log U` is continued by the quadratic fitted to the
/// `EXTRAPOLATION_WINDOW` values below `last` (camera responses are close to powers and
/// exponentials, which a quadratic in `log U` follows far better than one in `U`), offset to
/// meet `U(last)`; below, `U` itself is continued the same way (it goes to 0 there). The
/// result is kept at or above 0 and strictly increasing.
fn extrapolate(u: &[f64], first: usize, last: usize) -> (Vec<f64>, DMatrix<f64>) {
    extrapolate_with(u, first, last, EXTRAPOLATION_WINDOW)
}

/// [`extrapolate`] with another window (the extrapolation's sensitivity to it is part of the
/// standard error).
fn extrapolate_with(
    u: &[f64],
    first: usize,
    last: usize,
    window: usize,
) -> (Vec<f64>, DMatrix<f64>) {
    let n = u.len();
    let mut out = u.to_vec();
    let mut jac = DMatrix::<f64>::identity(n, n);
    if last < n - 1 {
        let lo = last.saturating_sub(window - 1).max(first);
        let positive = (lo..=last).all(|k| u[k] > 0.0);
        if let (true, true, Some(at_end)) = (
            last >= lo + 3,
            positive,
            quadratic_coefficients(lo, last, last as f64),
        ) {
            for k in last + 1..n {
                let Some(ck) = quadratic_coefficients(lo, last, k as f64) else {
                    continue;
                };
                // log U(k) = log U(last) + fit(k) - fit(last), fitted to log U
                let mut lv = u[last].ln();
                for (i, j) in (lo..=last).enumerate() {
                    lv += (ck[i] - at_end[i]) * u[j].ln();
                }
                out[k] = lv.exp();
                for c in 0..n {
                    jac[(k, c)] = 0.0;
                }
                jac[(k, last)] += out[k] / u[last];
                for (i, j) in (lo..=last).enumerate() {
                    jac[(k, j)] += out[k] * (ck[i] - at_end[i]) / u[j];
                }
            }
        } else {
            let slope = (u[last] - u[first]) / (last - first).max(1) as f64;
            for (k, o) in out.iter_mut().enumerate().skip(last + 1) {
                *o = u[last] + slope.max(1e-9) * (k - last) as f64;
            }
        }
    }
    if first > 0 {
        let hi = (first + window - 1).min(last);
        if let (true, Some(at_end)) = (
            hi >= first + 3,
            quadratic_coefficients(first, hi, first as f64),
        ) {
            for k in 0..first {
                let Some(ck) = quadratic_coefficients(first, hi, k as f64) else {
                    continue;
                };
                let mut v = u[first];
                for (i, j) in (first..=hi).enumerate() {
                    v += (ck[i] - at_end[i]) * u[j];
                }
                out[k] = v;
                for c in 0..n {
                    jac[(k, c)] = 0.0;
                }
                jac[(k, first)] += 1.0;
                for (i, j) in (first..=hi).enumerate() {
                    jac[(k, j)] += ck[i] - at_end[i];
                }
            }
        }
    }
    for v in out.iter_mut() {
        *v = v.max(0.0);
    }
    make_monotone(&mut out, &vec![1.0; n]);
    (out, jac)
}

/// Makes `u` strictly increasing: weighted isotonic regression (pool adjacent violators)
/// with the information per value as weights, then separation of ties.
fn make_monotone(u: &mut [f64], weight: &[f64]) {
    let n = u.len();
    let mut blocks: Vec<(f64, f64, usize)> = Vec::with_capacity(n);
    for k in 0..n {
        let w = weight[k].max(1e-12);
        blocks.push((u[k], w, 1));
        while blocks.len() > 1 {
            let n = blocks.len();
            if blocks[n - 2].0 < blocks[n - 1].0 {
                break;
            }
            let (v2, w2, c2) = blocks[n - 1];
            let (v1, w1, c1) = blocks[n - 2];
            blocks.truncate(n - 2);
            blocks.push(((v1 * w1 + v2 * w2) / (w1 + w2), w1 + w2, c1 + c2));
        }
    }
    let mut k = 0;
    for (v, _, c) in blocks {
        for _ in 0..c {
            u[k] = v;
            k += 1;
        }
    }
    let eps = ((u[n - 1] - u[0]).abs() / (n - 1) as f64).max(1e-9) * 1e-4;
    for k in 1..n {
        if u[k] <= u[k - 1] {
            u[k] = u[k - 1] + eps;
        }
    }
}

/// The selection range `[lo, hi]` of predicted knot positions: at least `z` standard
/// deviations from the clipping points, half a grey value below 0 and below the top
/// (`half` is half a grey value in knots).
fn censor_range(var: &[f64], z: f64, half: f64) -> (f64, f64) {
    let n = var.len();
    let top = (n - 1) as f64 - half;
    let lo = (0..n)
        .find(|&k| k as f64 - z * var[k].sqrt() >= -half)
        .unwrap_or(0) as f64;
    let hi = (0..n)
        .rev()
        .find(|&k| k as f64 + z * var[k].sqrt() <= top)
        .unwrap_or(n - 2) as f64;
    (lo, hi.max(lo + 1.0))
}

fn variance_table(u: &[f64], noise: &NoiseModel) -> Vec<f64> {
    (0..u.len()).map(|k| noise.variance(u, k as f64)).collect()
}

/// A starting point: a few iterations of the paper's alternation in the energy domain
/// (`B' = sum t U(I) / sum t^2`, `U(k) = mean of t B'` over observations of value `k`) on
/// the observations between grey values 8 and 245. It is biased near the ends (selection by
/// the observed value) but robust from a linear start, which the Newton steps are not for
/// strongly curved responses (sRGB, log).
fn initial_response<T: Sample>(
    frames: &[Image<T>],
    levels: Levels,
    exposures: &[f64],
    iterations: usize,
) -> Vec<f64> {
    let n = levels.knots;
    let top = (n - 1) as f64;
    // grey values 8 to 245 of 255, in knots
    let (lo, hi) = (8.0 * top / 255.0, 245.0 * top / 255.0);
    let mut u: Vec<f64> = (0..n).map(|k| k as f64).collect();
    let npx = frames[0].data().len();
    let chunk = CHUNK_ROWS * frames[0].width().max(1);
    for _ in 0..iterations {
        let parts: Vec<(Vec<f64>, Vec<f64>)> = (0..npx.div_ceil(chunk))
            .into_par_iter()
            .map(|c| {
                let start = c * chunk;
                let m = chunk.min(npx - start);
                let mut num = vec![0.0f64; m];
                let mut den = vec![0.0f64; m];
                for (f, &t) in frames.iter().zip(exposures) {
                    for (x, &k) in f.data()[start..start + m].iter().enumerate() {
                        let p = levels.pos(k.raw());
                        if p >= lo && p <= hi {
                            num[x] += t * interp(&u, p);
                            den[x] += t * t;
                        }
                    }
                }
                let mut sum = vec![0.0f64; n];
                let mut cnt = vec![0.0f64; n];
                // B' per pixel, once (NaN where no observation is in range)
                let bs: Vec<f64> = num
                    .iter()
                    .zip(&den)
                    .map(|(&a, &d)| if d > 0.0 { a / d } else { f64::NAN })
                    .collect();
                for (f, &t) in frames.iter().zip(exposures) {
                    for (x, &k) in f.data()[start..start + m].iter().enumerate() {
                        let p = levels.pos(k.raw());
                        if p >= lo && p <= hi && den[x] > 0.0 {
                            // the observation at its knot position, shared by the two
                            // neighbouring knots
                            let j = (p as usize).min(n - 2);
                            let f = p - j as f64;
                            let e = t * bs[x];
                            sum[j] += (1.0 - f) * e;
                            cnt[j] += 1.0 - f;
                            sum[j + 1] += f * e;
                            cnt[j + 1] += f;
                        }
                    }
                }
                (sum, cnt)
            })
            .collect();
        let mut sum = vec![0.0f64; n];
        let mut cnt = vec![0.0f64; n];
        for (s, c) in &parts {
            for k in 0..n {
                sum[k] += s[k];
                cnt[k] += c[k];
            }
        }
        let observed: Vec<usize> = (0..n).filter(|&k| cnt[k] >= 1.0).collect();
        if observed.len() < 2 {
            break;
        }
        let mut nu = u.clone();
        for &k in &observed {
            nu[k] = sum[k] / cnt[k];
        }
        // unobserved values: linear between observed neighbours, constant slope outside
        let (first, last) = (observed[0], observed[observed.len() - 1]);
        let mut prev = first;
        for &k in &observed[1..] {
            for j in prev + 1..k {
                nu[j] = nu[prev] + (nu[k] - nu[prev]) * (j - prev) as f64 / (k - prev) as f64;
            }
            prev = k;
        }
        let slope_hi = (nu[last] - nu[first]) / (last - first).max(1) as f64;
        for j in last + 1..n {
            nu[j] = nu[last] + slope_hi * (j - last) as f64;
        }
        for j in (0..first).rev() {
            nu[j] = (nu[j + 1] - nu[first] / first.max(1) as f64).max(0.0);
        }
        make_monotone(&mut nu, &cnt);
        let s = 255.0 / nu[n - 1].max(1e-12);
        u = nu.iter().map(|v| v * s).collect();
    }
    u
}

/// The data and settings of one calibration.
struct Solver<'a, T: Sample> {
    frames: &'a [Image<T>],
    levels: Levels,
    /// Per frame, the observations dropped next to saturated pixels (a bit per pixel).
    masks: &'a [Vec<u64>],
    exposures: &'a [f64],
    options: &'a ResponseOptions,
    /// `log` of the largest ratio between consecutive distinct exposures.
    log_gap: f64,
}

/// The converged state.
struct Solution {
    u: Vec<f64>,
    state: Vec<PixelState>,
    /// The table at which `sums` and `grads` were taken (the one before the last step).
    u_prev: Vec<f64>,
    noise: NoiseModel,
    lo: f64,
    hi: f64,
    /// The knot positions between which observations have their full weight (inside the
    /// taper at each end of the selection).
    full: (f64, f64),
    /// Prior weight relative to the mean information.
    prior: f64,
    /// The prior's normal matrix of the last step.
    penalty: DMatrix<f64>,
    sums: Sums,
    grads: Vec<Vec<f64>>,
    iterations: usize,
    converged: bool,
    change: Vec<f64>,
}

/// How much the standard errors exceed the estimate from the sampling and the sensitivities
/// (see [`calibrate_response`]'s uncertainty).
const UNCERTAINTY_FACTOR: f64 = 2.0;

/// The relative floor of the standard errors.
const UNCERTAINTY_FLOOR: f64 = 1e-3;

/// Iterations of the paper's alternation that give the starting point.
const INITIAL_ITERATIONS: usize = 8;

/// Iterations during which the noise model, the selection range and the prior weight follow
/// the data; then they are frozen, so that the iteration converges on a fixed problem.
const ADAPT_ITERATIONS: usize = 6;

/// A converged state to restart from, with its frozen noise model and a new selection.
#[derive(Clone)]
struct Warm {
    u: Vec<f64>,
    state: Vec<PixelState>,
    noise: NoiseModel,
    /// Selection in standard deviations from 0 and 255.
    censor_sigmas: f64,
    iterations: usize,
}

impl<T: Sample> Solver<'_, T> {
    /// Runs the iteration from the paper's alternation's result, or from `warm` with its
    /// noise model frozen.
    fn run(
        &self,
        warm: Option<Warm>,
        progress: &(dyn Fn(usize, f64) + Sync),
    ) -> Result<Solution, PhotometricError> {
        let npx = self.frames[0].data().len();
        let warm_start = warm.is_some();
        let (mut u, mut state, mut noise, z, max_iter) = match warm {
            Some(w) => (w.u, w.state, Some(w.noise), w.censor_sigmas, w.iterations),
            None => {
                let mut u =
                    initial_response(self.frames, self.levels, self.exposures, INITIAL_ITERATIONS);
                let g = 128.0 / u[gauge(self.levels.knots)].max(1e-12);
                for v in u.iter_mut() {
                    *v *= g;
                }
                let state = vec![
                    PixelState {
                        b: f64::NAN,
                        s: 1.0,
                        n: 0
                    };
                    npx
                ];
                (
                    u,
                    state,
                    None,
                    self.options.censor_sigmas,
                    self.options.max_iterations,
                )
            }
        };
        let n = self.levels.knots;
        let top = (n - 1) as f64;
        // half a grey value, and two 8-bit grey values, in knots
        let half = 0.5 * self.levels.scale;
        let two = 2.0 * top / 255.0;
        let mut var = match &noise {
            Some(nm) => variance_table(&u, nm),
            None => vec![1.0; n],
        };
        let (mut lo, mut hi) = match &noise {
            Some(_) => censor_range(&var, z, half),
            None => (8.0 * top / 255.0, 245.0 * top / 255.0),
        };
        let (mut e_lo, mut e_hi) = (interp(&u, lo), interp(&u, hi));
        let (mut e_lo_taper, mut e_hi_taper) = (
            interp(&u, (lo + two).min(hi)),
            interp(&u, (hi - two).max(lo)),
        );
        let mut prior = prior_weight(&u, self.log_gap, lo, hi, self.options.smoothness);
        let (t_min, t_max) = self
            .exposures
            .iter()
            .fold((f64::INFINITY, 0.0f64), |(a, b), &t| (a.min(t), b.max(t)));
        let mut change: Vec<f64> = Vec::new();
        let mut damping = if warm_start { 0.0 } else { 0.3f64 };
        let mut last_objective = f64::INFINITY;
        let mut converged = false;
        let mut iterations = 0;
        let mut last = None;
        for it in 0..max_iter.max(1) {
            iterations = it + 1;
            let adapt = !warm_start && it < ADAPT_ITERATIONS;
            if adapt {
                if let Some(nm) = &noise {
                    var = variance_table(&u, nm);
                    (lo, hi) = censor_range(&var, z, half);
                }
            }
            if adapt {
                (e_lo, e_hi) = (interp(&u, lo), interp(&u, hi));
                // the taper spans one noise standard deviation (at least 2 grey values of
                // 255)
                let d_lo = var[lo as usize].sqrt().max(two);
                let d_hi = var[hi as usize].sqrt().max(two);
                e_lo_taper = interp(&u, (lo + d_lo).min(hi));
                e_hi_taper = interp(&u, (hi - d_hi).max(lo)).max(e_lo_taper);
                prior = prior_weight(&u, self.log_gap, lo, hi, self.options.smoothness);
            }
            let model = Model {
                fwd: Forward::new(&u),
                ivar: var.iter().map(|v| 1.0 / v).collect(),
                var: var.clone(),
                levels: self.levels,
                lo,
                hi,
                e_lo,
                e_hi,
                e_lo_taper,
                e_hi_taper,
                exposures: self.exposures,
                adapt,
                b_min: (e_lo / t_max).max(1e-300),
                b_max: (e_hi / t_min).max(e_lo / t_max * 1.0001),
            };
            let (mut sums, grads) = pass(self.frames, self.masks, &model, &mut state);
            if sums.nobs == 0 {
                return Err(PhotometricError::Calibration(
                    "no pixel has enough unsaturated observations at different exposures".into(),
                ));
            }
            sums.hess = profiled_hessian(&model, &sums.bins, &sums.diag);
            let penalty = third_difference_normal(n) * (prior * median_info(&sums.diag));
            let lambda = 1.0;
            // the objective (with the prior) decides the damping once the problem is frozen
            let uv = DVector::from_column_slice(&u);
            let objective = sums.sq + (uv.transpose() * &penalty * &uv)[(0, 0)];
            if !adapt {
                damping = if objective > last_objective {
                    (damping * 4.0).max(1e-3)
                } else {
                    damping / 3.0
                };
            }
            last_objective = objective;
            let mut nu = solve_u_step(&u, &sums, &penalty, lambda, damping)?;
            let info: Vec<f64> = (0..n).map(|k| sums.diag[k] + penalty[(k, k)]).collect();
            for v in nu.iter_mut() {
                // U(0) is the black level: nothing below zero
                *v = v.max(0.0);
            }
            make_monotone(&mut nu, &info);
            // the gauge: U at the middle knot stays (B' scales with U); U(top) = 255 at the
            // end
            let g = gauge(n);
            let s = u[g] / nu[g];
            for v in nu.iter_mut() {
                *v *= s;
            }
            for st in state.iter_mut() {
                st.b *= s;
            }
            e_lo *= s;
            e_hi *= s;
            e_lo_taper *= s;
            e_hi_taper *= s;
            // the change over the values the data determine, in grey values at the top
            let (k_first, k_last) = data_range(&sums.used);
            let delta = (k_first..=k_last)
                .map(|k| (nu[k] - u[k]).abs())
                .fold(0.0f64, f64::max)
                * (k_last as f64 * 255.0 / top)
                / nu[k_last].max(1e-12);
            change.push(delta);
            if adapt {
                if let Some(nm) = fit_noise(&nu, &sums.rss, &sums.cnt) {
                    noise = Some(nm);
                }
            }
            let u_prev = u;
            u = nu;
            last = Some((u_prev, sums, grads, penalty));
            progress(iterations, delta);
            if delta < self.options.tolerance && (warm_start || it >= ADAPT_ITERATIONS) {
                converged = true;
                break;
            }
        }
        let Some((u_prev, sums, grads, penalty)) = last else {
            return Err(singular());
        };
        let full = {
            let fwd = Forward::new(&u);
            let pos = |e: f64, dflt: f64| fwd.eval(e).map_or(dflt, |(j, f)| j as f64 + f);
            (pos(e_lo_taper, lo), pos(e_hi_taper, hi))
        };
        Ok(Solution {
            u,
            state,
            u_prev,
            noise: noise.unwrap_or(NoiseModel {
                read: 0.0,
                shot: 0.0,
                adc: 1.0,
            }),
            lo,
            hi,
            full,
            prior,
            penalty,
            sums,
            grads,
            iterations,
            converged,
            change,
        })
    }
}

/// `u` scaled to `U(top) = 255` (exactly: the product with the scale can be an ulp off).
fn normalized(u: &[f64]) -> Vec<f64> {
    let s = 255.0 / u[u.len() - 1];
    let mut out: Vec<f64> = u.iter().map(|v| v * s).collect();
    if let Some(last) = out.last_mut() {
        *last = 255.0;
    }
    out
}

/// Standard errors of the normalised table: the sandwich covariance of the last Newton step
/// (chunks of rows as the independent units), through the normalisation `U(255) = 255`, and
/// the prior's part from the step with a ten times weaker prior. Returns (total, prior part).
fn standard_errors(
    sol: &Solution,
    first: usize,
    last: usize,
) -> Result<(Vec<f64>, Vec<f64>), PhotometricError> {
    let (u, ext) = extrapolate(&sol.u, first, last);
    let n = u.len();
    let gauge = gauge(n);
    let penalty = &sol.penalty;
    let (a, _) = u_system(&sol.u_prev, &sol.sums, penalty, 1.0);
    let chol = a.cholesky().ok_or_else(singular)?;
    // meat: centred chunk gradients (GAUGE is held, so its component is zero)
    let c = sol.grads.len();
    let mut meat = DMatrix::<f64>::zeros(n, n);
    if c >= 2 {
        let mean: Vec<f64> = (0..n)
            .map(|k| sol.grads.iter().map(|g| g[k]).sum::<f64>() / c as f64)
            .collect();
        for g in &sol.grads {
            let v = DVector::from_fn(n, |k, _| {
                if k == gauge && !sol.sums.hess.is_empty() {
                    0.0
                } else {
                    g[k] - mean[k]
                }
            });
            meat.ger(1.0, &v, &v, 1.0);
        }
        meat *= c as f64 / (c as f64 - 1.0);
    }
    let x = chol.solve(&meat);
    let cov = &ext * chol.solve(&x.transpose()) * ext.transpose();
    // normalisation: U_n = 255 U / U(top); J = 255 / U_top (I - U e_top^T / U_top)
    let s = 255.0 / u[n - 1];
    let mut jac = DMatrix::<f64>::identity(n, n) * s;
    for k in 0..n {
        jac[(k, n - 1)] -= s * u[k] / u[n - 1];
    }
    let cov_n = &jac * cov * jac.transpose();
    // the prior's part: the change with a ten times weaker prior
    let (a10, b10) = u_system(&sol.u_prev, &sol.sums, penalty, 0.1);
    let (_, b1) = u_system(&sol.u_prev, &sol.sums, penalty, 1.0);
    let d1 = chol.solve(&b1);
    let d10 = a10.cholesky().ok_or_else(singular)?.solve(&b10);
    let mut u1 = sol.u_prev.clone();
    let mut u10 = sol.u_prev.clone();
    for k in 0..n {
        u1[k] += d1[k];
        u10[k] += d10[k];
    }
    let n1 = normalized(&extrapolate(&u1, first, last).0);
    let n10 = normalized(&extrapolate(&u10, first, last).0);
    // the extrapolation's part: the change with half the window
    let nu = normalized(&u);
    let nh = normalized(&extrapolate_with(&sol.u, first, last, EXTRAPOLATION_WINDOW / 2).0);
    let prior_part: Vec<f64> = (0..n)
        .map(|k| {
            let p = (n10[k] - n1[k]).abs() / 0.9;
            let e = (nh[k] - nu[k]).abs();
            (p * p + e * e).sqrt()
        })
        .collect();
    let total = (0..n)
        .map(|k| (cov_n[(k, k)].max(0.0) + prior_part[k] * prior_part[k]).sqrt())
        .collect();
    Ok((total, prior_part))
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
    calibrate(frames, Levels::new(8), exposures_ms, options, progress)
}

/// Calibrates the `2^bits`-value inverse response of a sensor deeper than 8 bits (`bits`
/// from 8 to 16) from frames whose samples hold `bits`-bit values in the low bits
/// (`0 ..= 2^bits - 1`; a 12-bit sensor's 16-bit PNG has values up to 4095). The estimate is
/// taken on `min(2^bits, MAX_KNOTS)` equally spaced knots and interpolated linearly to every
/// value: with many values each observed rarely, the knots pool neighbouring values, and
/// the third-difference prior works on the knots as on the 256 values of an 8-bit frame.
/// All grey values in the result (`observed_range`, `filled`, `histogram`, `censor_range`,
/// `rmse`) are on the frames' own scale; `U(2^bits - 1) = 255`.
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
    let levels = Levels::new(bits);
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

/// [`calibrate_response`] and [`calibrate_response_deep`] on frames of any sample type.
fn calibrate<T: Sample>(
    frames: &[Image<T>],
    levels: Levels,
    exposures_ms: &[f64],
    options: &ResponseOptions,
    progress: &(dyn Fn(usize, f64) + Sync),
) -> Result<ResponseCalibration, PhotometricError> {
    options.check()?;
    let n = frames.len();
    if n < 2 {
        return Err(PhotometricError::Calibration(format!(
            "response calibration needs at least 2 frames, got {n}"
        )));
    }
    if exposures_ms.len() != n {
        return Err(PhotometricError::Calibration(format!(
            "{} exposures for {n} frames",
            exposures_ms.len()
        )));
    }
    if let Some(t) = exposures_ms.iter().find(|t| !(t.is_finite() && **t > 0.0)) {
        return Err(PhotometricError::Exposure(*t));
    }
    let t_min = exposures_ms.iter().copied().fold(f64::INFINITY, f64::min);
    let t_max = exposures_ms.iter().copied().fold(0.0, f64::max);
    if t_max <= t_min * (1.0 + 1e-9) {
        return Err(PhotometricError::Calibration(format!(
            "every frame has the same exposure ({t_min} ms): the response is not observable; record the scene while changing the exposure"
        )));
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
    if distinct.len() < 3 {
        return Err(PhotometricError::Calibration(format!(
            "only {} different exposure times: two exposures determine U only up to a periodic factor; record at least 3 (the paper: 120 from 0.05 to 20 ms)",
            distinct.len()
        )));
    }
    let log_gap = distinct
        .windows(2)
        .map(|p| (p[1] / p[0]).ln())
        .fold(0.0f64, f64::max);
    let nk = levels.knots;
    let top = levels.top;
    // 8-bit grey values as knot indices
    let at = |g: usize| g * (nk - 1) / 255;
    let masks: Vec<Vec<u64>> = frames
        .par_iter()
        .map(|f| saturation_mask(f.data(), top, w, h, options.saturation_border))
        .collect();

    let histogram: Vec<u64> = {
        let parts: Vec<Vec<u64>> = frames
            .par_iter()
            .map(|f| {
                let mut c = vec![0u64; top as usize + 1];
                for &v in f.data() {
                    c[(v.raw() as usize).min(top as usize)] += 1;
                }
                c
            })
            .collect();
        let mut total = vec![0u64; top as usize + 1];
        for p in parts {
            for (t, c) in total.iter_mut().zip(&p) {
                *t += c;
            }
        }
        total
    };
    // counts per knot (nearest), for the checks in 8-bit grey values
    let mut knot_hist = vec![0u64; nk];
    for (v, &c) in histogram.iter().enumerate() {
        knot_hist[levels.knot(v as u32)] += c;
    }
    let min_count = options.min_count.max(1);
    let lo_obs = (0..nk - 1).find(|&k| knot_hist[k] >= min_count);
    let hi_obs = (0..nk - 1).rev().find(|&k| knot_hist[k] >= min_count);
    let (Some(lo_obs), Some(hi_obs)) = (lo_obs, hi_obs) else {
        return Err(PhotometricError::Calibration(
            "no unsaturated pixel in any frame".into(),
        ));
    };
    let grey = |k: usize| (k as f64 / levels.scale).round() as u32;
    if hi_obs - lo_obs < at(16) {
        return Err(PhotometricError::Calibration(format!(
            "only grey values {}..{} are observed; the scene needs a wider range of brightness (dark pixels and bright ones)",
            grey(lo_obs),
            grey(hi_obs)
        )));
    }

    let solver = Solver {
        frames,
        levels,
        masks: &masks,
        exposures: exposures_ms,
        options,
        log_gap,
    };
    let sol = solver.run(None, progress)?;

    // what the data determine
    let used = sol.sums.used.clone();
    let determined: Vec<bool> = (0..nk)
        .map(|k| {
            let a = k.saturating_sub(1);
            let b = (k + 1).min(nk - 1);
            (a..=b).map(|j| used[j]).sum::<u64>() >= min_count
        })
        .collect();
    // determined: enough observations, and inside the taper, where they have their full
    // weight (in the taper the prior and the extrapolation share the say)
    let (full_lo, full_hi) = (sol.full.0.ceil() as usize, sol.full.1.floor() as usize);
    let k_lo = (0..nk)
        .find(|&k| determined[k] && k >= full_lo)
        .unwrap_or(0);
    let k_hi = (0..nk)
        .rev()
        .find(|&k| determined[k] && k <= full_hi)
        .unwrap_or(nk - 1);
    // the grey values between the knots the data determine
    let (g_lo, g_hi) = (grey(k_lo), grey(k_hi));
    let filled: Vec<u32> = (0..=top).filter(|&v| v < g_lo || v > g_hi).collect();
    let s_hi = 250.0 * f64::from(top) / 255.0;
    if k_hi < at(192) {
        return Err(PhotometricError::Calibration(format!(
            "the data determine U only up to grey value {g_hi} of {top}: no pixel is predicted brighter without saturating; record longer exposures or a brighter scene so that grey values up to about {} are observed",
            s_hi.round()
        )));
    }
    if k_lo > at(64) {
        return Err(PhotometricError::Calibration(format!(
            "the data determine U only from grey value {g_lo} up: record shorter exposures or a darker scene so that grey values near 0 are observed"
        )));
    }
    let mut warnings = Vec::new();
    if k_hi < at(240) {
        warnings.push(format!(
            "U above grey value {g_hi} is extrapolated ({} values): longer exposures would determine it",
            top - g_hi
        ));
    }
    if k_lo > at(16) {
        warnings.push(format!(
            "U below grey value {g_lo} is extrapolated: shorter exposures would determine it"
        ));
    }
    if distinct.len() < 8 {
        warnings.push(format!(
            "only {} different exposures: U between them leans on the smoothness prior",
            distinct.len()
        ));
    }
    if !sol.converged {
        warnings.push(format!(
            "not converged after {} iterations (last change {:.3} grey levels)",
            sol.iterations,
            sol.change.last().copied().unwrap_or(f64::NAN)
        ));
    }
    let (first, last) = data_range(&sol.sums.used);
    let (mut std_error, mut prior_error) = standard_errors(&sol, first, last)?;
    // the ends' dependence on where the selection cuts: the estimate with the cut one noise
    // standard deviation further in and further out (restarted from the estimate)
    let base = normalized(&extrapolate(&sol.u, first, last).0);
    let mut cut_part = vec![0.0f64; nk];
    for dz in [-1.0, 1.0] {
        let alt = solver.run(
            Some(Warm {
                u: sol.u.clone(),
                state: sol.state.clone(),
                noise: sol.noise,
                censor_sigmas: (options.censor_sigmas + dz).max(0.5),
                iterations: 3,
            }),
            &|_, _| {},
        )?;
        let (f2, l2) = data_range(&alt.sums.used);
        let other = normalized(&extrapolate(&alt.u, f2, l2).0);
        for k in 0..nk {
            cut_part[k] = cut_part[k].max((other[k] - base[k]).abs());
        }
    }
    // the sensitivities estimate the systematic errors only to within a factor: the band is
    // twice the combined estimate with a floor of 0.1% of U (on synthetic sweeps across
    // responses, noise levels, JPEG and 12 to 120 exposures this holds about 93% of the true
    // errors within two standard errors; `cargo xtask response-study`)
    for k in 0..nk {
        let systematic = prior_error[k].hypot(cut_part[k]);
        let total = std_error[k].hypot(cut_part[k]);
        prior_error[k] = UNCERTAINTY_FACTOR * systematic;
        std_error[k] = (UNCERTAINTY_FACTOR * total).hypot(UNCERTAINTY_FLOOR * base[k]);
        if k == nk - 1 {
            std_error[k] = 0.0;
            prior_error[k] = 0.0;
        }
    }
    let knots_u = normalized(&extrapolate(&sol.u, first, last).0);
    // every grey value of the frames from the knots
    let (table, std_error, prior_error) = if nk == top as usize + 1 {
        (knots_u, std_error, prior_error)
    } else {
        let all = |v: &[f64]| -> Vec<f64> { (0..=top).map(|g| interp(v, levels.pos(g))).collect() };
        (all(&knots_u), all(&std_error), all(&prior_error))
    };
    let response = InverseResponse::from_values(table)?;
    let rmse = (sol.sums.rss.iter().sum::<f64>() / sol.sums.cnt.iter().sum::<f64>().max(1.0))
        .sqrt()
        / levels.scale;
    Ok(ResponseCalibration {
        response,
        std_error,
        systematic_error: prior_error,
        iterations: sol.iterations,
        converged: sol.converged,
        change: sol.change,
        rmse,
        observed_range: (g_lo, g_hi),
        filled,
        histogram,
        used,
        censor_range: (sol.lo / levels.scale, sol.hi / levels.scale),
        knot_step: 1.0 / levels.scale,
        noise: sol.noise,
        prior_weight: sol.prior,
        pixels_used: sol.sums.pixels,
        warnings,
    })
}
