//! Exposure times measured from the images: the ratio `t_{i+1} / t_i` of consecutive frames
//! follows from corresponding pixels once the response and the vignette are undone, because
//! `U(I(x)) / V(x) = t B(x)` and the scene `B` barely changes between frames at 20-50 fps.
//!
//! * **Measuring a ratio** ([`ExposureMeter`], [`measure_ratio`]). Each frame is corrected
//!   to `U(I) / V` at a reduced resolution (2x2 means), pixels that are dark or near
//!   saturation excluded (grey values outside `min_grey..=max_grey` on the 8-bit scale). A
//!   global image shift is found coarse to fine on a pyramid of the log image (exhaustive
//!   search at the coarsest level; the cost is the variance of the log difference, which the
//!   unknown ratio does not change). The raw images are distorted, so a rotation is not one
//!   shift: each tile (`tile` pixels square) searches around the global shift and refines
//!   its shift by Gauss-Newton with both frames sampled half a shift from the pixel centres
//!   (so both are interpolated alike and `m(a, b) = -m(b, a)` exactly); a tile whose shift
//!   disagrees with its neighbours' takes their median, and a displacement field bilinear
//!   between the tile centres is sampled in blocks of 8x8 pixels. Each tile's value is the
//!   log of the ratio of its sums of `U / V` over the matching pixels (outliers of the log
//!   ratio left out): a ratio of sums, not a mean of logs, because the mean of logs depends
//!   on how much texture a pixel averages, which changes with the motion. The tiles are
//!   combined by a Huber M-estimate; its sandwich standard error counts tiles, not pixels,
//!   as the independent units, plus `systematic_error` in quadrature. A pair with too few
//!   usable tiles, or a standard error above `max_std_error` (motion blur, large motion, a
//!   cut), is *unreliable*: reported, and never used to flag or to chain.
//! * **Checking logged exposures** ([`check_exposures`]). The camera SDK of the benchmark
//!   reports exposures asynchronously, so a logged exposure sometimes belongs to the
//!   neighbouring frame. For every frame `k` the true log exposure of the frame before and of
//!   the frame after are estimated from the *other* frames' logged exposures and the
//!   measured ratios (medians over a window, so one bad log does not matter), and three
//!   hypotheses are compared: the logged `t_k` is `t_k` (predicted by both neighbours and
//!   the measured ratios), or it is `t_{k-1}`, or `t_{k+1}`. A frame is flagged when the
//!   logged value contradicts the measured one by more than `flag_sigmas` standard errors
//!   and at least `min_difference`, one shift hypothesis fits it, and the hypotheses are
//!   distinguishable (the neighbour's exposure differs from the frame's by as much). When
//!   the two neighbours' predictions of `t_k` disagree with each other, the measurement
//!   around `k` is broken (a moving object, a bad pair) and `k` is left undecided. A log that
//!   is one frame off as a whole is reported as such (`log_lag`).
//! * **Estimating exposures** ([`estimate_exposures`]). Without logged exposures the
//!   measured log ratios of consecutive frames (and of frames two apart, which bridge a bad
//!   frame) are chained by weighted least squares with Huber weights, a very weak prior
//!   `t_{i+1} = t_i` (standard deviation `gap_prior` in log) keeping the chain connected
//!   where no pair could be measured. The result is anchored so that the median exposure
//!   is the reference, with the standard error of every frame relative to the frame at the
//!   median (from the band-limited inverse of the normal equations).
//!
//! # Example
//!
//! ```
//! use camera_model::Image;
//! use photometric::exposure::{measure_ratio, ExposureMeter, ExposureOptions};
//! use photometric::InverseResponse;
//!
//! // a textured scene seen at 4 ms and, moved by 3 pixels, at 5 ms, linear response
//! let scene = |x: f64, y: f64| {
//!     6.0 + 2.0 * (0.002 * x * x + 0.1 * y).sin() + 1.5 * (0.003 * y * y - 0.07 * x).cos()
//! };
//! let frame = |t: f64, dx: f64| {
//!     Image::from_fn(320, 240, |x, y| (t * scene(x as f64 + dx, y as f64)).round() as u8)
//! };
//! let opts = ExposureOptions::default();
//! let meter = ExposureMeter::new(&InverseResponse::linear(), None, (320, 240), &opts)?;
//! let a = meter.frame_u8(&frame(4.0, 0.0))?;
//! let b = meter.frame_u8(&frame(5.0, 3.0))?;
//! let m = measure_ratio(&a, &b, &opts);
//! assert!(m.reliable);
//! assert!((m.log_ratio - (5.0f64 / 4.0).ln()).abs() < 0.005);
//! assert!((m.shift[0] - 3.0).abs() < 0.5 && m.shift[1].abs() < 0.5);
//! # Ok::<(), photometric::PhotometricError>(())
//! ```

use camera_model::Image;

use crate::stats::median;
use crate::{InverseResponse, PhotometricError, Vignette};

/// Options of the exposure measurement, check and estimate.
///
/// Deserialised fields that are absent keep their defaults; unknown ones are an error.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ExposureOptions {
    /// Darkest usable grey value, on the 8-bit scale (deeper frames scale it by full range).
    pub min_grey: f64,
    /// Brightest usable grey value, on the 8-bit scale (saturation and the values just below
    /// it are excluded).
    pub max_grey: f64,
    /// Reduction of the frames before the analysis (2: 2x2 means).
    pub downsample: usize,
    /// Side of a tile in pixels of the reduced frames.
    pub tile: usize,
    /// Largest image motion between two frames that the search covers, as a fraction of the
    /// image width.
    pub max_motion: f64,
    /// Fewest tiles for a reliable ratio.
    pub min_tiles: usize,
    /// Largest standard error (of the log ratio) of a reliable ratio.
    pub max_std_error: f64,
    /// Standard error added in quadrature to every measured log ratio: what the statistics
    /// of one pair do not see (an imperfect response or vignette, scene changes).
    pub systematic_error: f64,
    /// Relative precision of the logged exposures.
    pub log_precision: f64,
    /// Frames on each side whose logged exposures predict a frame's neighbours.
    pub window: usize,
    /// Standard errors by which a logged exposure must contradict the measurement to be
    /// flagged.
    pub flag_sigmas: f64,
    /// Smallest relative difference (in log) between the logged and the measured exposure
    /// that is flagged, and between the hypotheses that tell a shift.
    pub min_difference: f64,
    /// Standard errors within which a shift hypothesis must fit the logged value.
    pub fit_sigmas: f64,
    /// Standard errors beyond which the two neighbours' predictions of a frame disagree
    /// (the measurement around the frame is broken: no decision).
    pub consistency_sigmas: f64,
    /// Use the ratios of frames two apart too (the estimate).
    pub skip_pairs: bool,
    /// Standard deviation (log) of the prior `t_{i+1} = t_i` that connects the chain where
    /// no ratio was measured.
    pub gap_prior: f64,
}

impl Default for ExposureOptions {
    fn default() -> Self {
        ExposureOptions {
            min_grey: 12.0,
            max_grey: 250.0,
            downsample: 2,
            tile: 32,
            max_motion: 0.15,
            min_tiles: 6,
            max_std_error: 0.01,
            systematic_error: 0.0005,
            log_precision: 0.001,
            window: 3,
            flag_sigmas: 5.0,
            min_difference: 0.01,
            fit_sigmas: 4.0,
            consistency_sigmas: 5.0,
            skip_pairs: true,
            gap_prior: 1.0,
        }
    }
}

/// One level of a frame's pyramid: `log(U(I) / V)`, NaN where unusable.
#[derive(Clone, Debug)]
struct Level {
    w: usize,
    h: usize,
    data: Vec<f32>,
}

impl Level {
    /// The next coarser level: 2x2 means of the finite values (at least two).
    fn reduce(&self) -> Level {
        let (w, h) = (self.w / 2, self.h / 2);
        let mut data = vec![f32::NAN; w * h];
        for y in 0..h {
            for x in 0..w {
                let mut s = 0.0;
                let mut n = 0;
                for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    let v = self.data[(2 * y + dy) * self.w + 2 * x + dx];
                    if v.is_finite() {
                        s += v;
                        n += 1;
                    }
                }
                if n >= 2 {
                    data[y * w + x] = s / n as f32;
                }
            }
        }
        Level { w, h, data }
    }
}

/// Samples `l` on the `pw x ph` pixel grid whose first pixel is `(x0 + dx, y0 + dy)`
/// (bilinear at one sub-pixel offset for the whole grid) into `out`, row by row; NaN
/// outside the level or where a neighbour is NaN.
#[allow(clippy::too_many_arguments)]
fn sample_patch(
    l: &Level,
    x0: isize,
    y0: isize,
    pw: usize,
    ph: usize,
    dx: f64,
    dy: f64,
    out: &mut Vec<f32>,
) {
    out.clear();
    // floor without libm (the offsets are far above -1024)
    let fx = (dx + 1024.0) as isize - 1024;
    let fy = (dy + 1024.0) as isize - 1024;
    let (ax, ay) = ((dx - fx as f64) as f32, (dy - fy as f64) as f32);
    let xs = x0 + fx;
    let lo = (-xs).clamp(0, pw as isize) as usize;
    let hi = (l.w as isize - 1 - xs).clamp(lo as isize, pw as isize) as usize;
    out.resize(pw * ph, f32::NAN);
    for (j, o) in out.chunks_exact_mut(pw).enumerate() {
        let yy = y0 + j as isize + fy;
        if yy < 0 || yy + 1 >= l.h as isize || hi == lo {
            o.fill(f32::NAN);
            continue;
        }
        let row = yy as usize * l.w;
        let base = (xs + lo as isize) as usize;
        let r0 = &l.data[row + base..row + base + (hi - lo) + 1];
        let r1 = &l.data[row + l.w + base..row + l.w + base + (hi - lo) + 1];
        o[..lo].fill(f32::NAN);
        o[hi..].fill(f32::NAN);
        for ((v, p), q) in o[lo..hi].iter_mut().zip(r0.windows(2)).zip(r1.windows(2)) {
            let top = p[0] + ax * (p[1] - p[0]);
            let bottom = q[0] + ax * (q[1] - q[0]);
            *v = top + ay * (bottom - top);
        }
    }
}

/// A frame prepared for [`measure_ratio`]: its corrected log image at the analysis
/// resolution and a pyramid for the alignment.
#[derive(Clone, Debug)]
pub struct MeteredFrame {
    levels: Vec<Level>,
    /// `U(I) / V` at the analysis resolution (level 0 before the log).
    linear: Level,
    /// Raw pixels per analysis pixel along each axis.
    downsample: usize,
    /// Usable fraction of the analysis pixels.
    usable: f64,
}

impl MeteredFrame {
    /// The fraction of the analysis pixels that are usable (neither dark nor saturated).
    pub fn usable_fraction(&self) -> f64 {
        self.usable
    }

    /// Width and height at the analysis resolution.
    pub fn analysis_size(&self) -> (usize, usize) {
        (self.levels[0].w, self.levels[0].h)
    }
}

/// Prepares frames for [`measure_ratio`]: `U` with the unusable grey values masked and
/// `1 / V` per pixel.
#[derive(Clone, Debug)]
pub struct ExposureMeter {
    /// `U` per 8-bit grey value, NaN outside `min_grey..=max_grey`.
    lut8: Vec<f32>,
    response: InverseResponse,
    inv_v: Vec<f32>,
    width: usize,
    height: usize,
    downsample: usize,
    min_grey: f64,
    max_grey: f64,
}

fn masked_table(table: &[f64], bits: u32, min_grey: f64, max_grey: f64) -> Vec<f32> {
    let full = ((1u64 << bits) - 1) as f64;
    table
        .iter()
        .enumerate()
        .map(|(k, &u)| {
            let g = k as f64 * 255.0 / full;
            if g >= min_grey && g <= max_grey && u > 0.0 {
                u as f32
            } else {
                f32::NAN
            }
        })
        .collect()
}

impl ExposureMeter {
    /// A meter for frames of `size` (the raw size, that of the vignette).
    pub fn new(
        response: &InverseResponse,
        vignette: Option<&Vignette>,
        size: (usize, usize),
        opts: &ExposureOptions,
    ) -> Result<ExposureMeter, PhotometricError> {
        let (width, height) = size;
        let downsample = opts.downsample.max(1);
        if width / downsample < 16 || height / downsample < 16 {
            return Err(PhotometricError::SizeMismatch {
                what: "the frames (too small to measure exposure ratios)",
                width: 16 * downsample,
                height: 16 * downsample,
                got_width: width,
                got_height: height,
            });
        }
        let bad_range = !(opts.min_grey.is_finite()
            && opts.max_grey.is_finite()
            && opts.min_grey >= 0.0
            && opts.max_grey <= 255.0
            && opts.min_grey < opts.max_grey);
        if bad_range {
            return Err(PhotometricError::Calibration(format!(
                "usable grey values {}..{} must lie in 0..255 with the first below the second",
                opts.min_grey, opts.max_grey
            )));
        }
        let inv_v = match vignette {
            Some(v) => {
                v.check_size(width, height)?;
                v.values()
                    .data()
                    .iter()
                    .map(|&x| if x > 0.0 { 1.0 / x } else { f32::NAN })
                    .collect()
            }
            None => vec![1.0; width * height],
        };
        Ok(ExposureMeter {
            lut8: masked_table(response.values(), 8, opts.min_grey, opts.max_grey),
            response: response.clone(),
            inv_v,
            width,
            height,
            downsample,
            min_grey: opts.min_grey,
            max_grey: opts.max_grey,
        })
    }

    fn check(&self, w: usize, h: usize) -> Result<(), PhotometricError> {
        if (w, h) != (self.width, self.height) {
            return Err(PhotometricError::SizeMismatch {
                what: "the frame",
                width: self.width,
                height: self.height,
                got_width: w,
                got_height: h,
            });
        }
        Ok(())
    }

    /// Prepares an 8-bit frame.
    pub fn frame_u8(&self, img: &Image<u8>) -> Result<MeteredFrame, PhotometricError> {
        self.check(img.width(), img.height())?;
        Ok(self.build(|i| self.lut8[img.data()[i] as usize]))
    }

    /// Prepares a frame of `bits`-bit samples (1 to 16, in the low bits of 16); `U` is
    /// looked up as [`InverseResponse::table_for_bits`] does. A sample beyond the bit depth
    /// is an error.
    pub fn frame_u16(&self, img: &Image<u16>, bits: u32) -> Result<MeteredFrame, PhotometricError> {
        self.check(img.width(), img.height())?;
        let table = masked_table(
            &self.response.table_for_bits(bits)?,
            bits,
            self.min_grey,
            self.max_grey,
        );
        if let Some(&p) = img.data().iter().find(|&&p| p as usize >= table.len()) {
            return Err(PhotometricError::SampleRange {
                value: p as u32,
                bits,
            });
        }
        Ok(self.build(|i| table[img.data()[i] as usize]))
    }

    /// `log` of the 2x2 (or `downsample`) means of `U(I) / V`, NaN when any pixel of the
    /// block is unusable; then the pyramid.
    fn build(&self, u_of: impl Fn(usize) -> f32) -> MeteredFrame {
        let s = self.downsample;
        let (w, h) = (self.width / s, self.height / s);
        let mut lin = vec![f32::NAN; w * h];
        let mut data = vec![f32::NAN; w * h];
        let norm = 1.0 / (s * s) as f32;
        let mut usable = 0usize;
        for y in 0..h {
            for x in 0..w {
                let mut sum = 0.0f32;
                for dy in 0..s {
                    let row = (y * s + dy) * self.width + x * s;
                    for i in row..row + s {
                        sum += u_of(i) * self.inv_v[i];
                    }
                }
                // NaN (an unusable pixel) propagates through the sum
                if sum.is_finite() && sum > 0.0 {
                    let v = sum * norm;
                    lin[y * w + x] = v;
                    data[y * w + x] = v.ln();
                    usable += 1;
                }
            }
        }
        let linear = Level { w, h, data: lin };
        let mut levels = vec![Level { w, h, data }];
        while let Some(last) = levels.last() {
            if last.w < 64 || last.h < 48 {
                break;
            }
            let next = last.reduce();
            levels.push(next);
        }
        MeteredFrame {
            levels,
            linear,
            downsample: s,
            usable: usable as f64 / (w * h).max(1) as f64,
        }
    }
}

/// The measured exposure ratio of two frames.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RatioMeasurement {
    /// `log(t_b / t_a)`; NaN when nothing could be measured.
    pub log_ratio: f64,
    /// Standard error of `log_ratio` (infinite when nothing could be measured).
    pub std_error: f64,
    /// Image motion from the first frame to the second in raw pixels, `(x, y)` (the second
    /// frame at `p` shows what the first shows at `p + shift`).
    pub shift: [f64; 2],
    /// Tiles that entered the estimate.
    pub tiles: usize,
    /// Robust spread (1.4826 MAD) of the per-pixel log ratios: how well the frames match.
    pub pixel_spread: f64,
    /// Whether the ratio may be used (enough tiles, small standard error).
    pub reliable: bool,
    /// Why the ratio is unreliable (empty when reliable).
    pub note: String,
}

impl RatioMeasurement {
    /// A measurement that could not be made: no ratio, unreliable, with the reason.
    pub fn failed(note: impl Into<String>) -> RatioMeasurement {
        RatioMeasurement {
            log_ratio: f64::NAN,
            std_error: f64::INFINITY,
            shift: [f64::NAN; 2],
            tiles: 0,
            pixel_spread: f64::NAN,
            reliable: false,
            note: note.into(),
        }
    }
}

/// Variance of `b(x) - a(x + d)` over the window `[x0, x1) x [y0, y1)` of `b`, with the
/// count of pixels where both are finite and the mean.
fn shift_cost(
    a: &Level,
    b: &Level,
    d: (isize, isize),
    win: (usize, usize, usize, usize),
) -> (f64, usize, f64) {
    let (x0, y0, x1, y1) = win;
    // clip the window so that x + d stays inside a
    let xs = (x0 as isize).max(-d.0).max(0) as usize;
    let xe = (x1 as isize).min(a.w as isize - d.0).max(0) as usize;
    let ys = (y0 as isize).max(-d.1).max(0) as usize;
    let ye = (y1 as isize).min(a.h as isize - d.1).max(0) as usize;
    if xe <= xs || ye <= ys {
        return (f64::INFINITY, 0, f64::NAN);
    }
    let (mut s, mut s2, mut n) = (0.0f64, 0.0f64, 0usize);
    for y in ys..ye {
        let rb = &b.data[y * b.w + xs..y * b.w + xe];
        let ya = (y as isize + d.1) as usize;
        let start = (ya * a.w) as isize + xs as isize + d.0;
        let ra = &a.data[start as usize..start as usize + rb.len()];
        // eight independent lanes, NaN masked by a select: the loop vectorises
        let (mut ls, mut ls2, mut ln) = ([0.0f32; 8], [0.0f32; 8], [0.0f32; 8]);
        let (cb, ca) = (rb.chunks_exact(8), ra.chunks_exact(8));
        let (tb, ta) = (cb.remainder(), ca.remainder());
        for (pb, pa) in cb.zip(ca) {
            for k in 0..8 {
                let r = pb[k] - pa[k];
                let ok = r.is_finite();
                let r = if ok { r } else { 0.0 };
                ls[k] += r;
                ls2[k] += r * r;
                ln[k] += if ok { 1.0 } else { 0.0 };
            }
        }
        for (k, (vb, va)) in tb.iter().zip(ta).enumerate() {
            let r = vb - va;
            if r.is_finite() {
                ls[k] += r;
                ls2[k] += r * r;
                ln[k] += 1.0;
            }
        }
        let ls: f32 = ls.iter().sum();
        let ls2: f32 = ls2.iter().sum();
        let ln = ln.iter().sum::<f32>() as usize;
        s += ls as f64;
        s2 += ls2 as f64;
        n += ln;
    }
    if n < 2 {
        return (f64::INFINITY, n, f64::NAN);
    }
    let mean = s / n as f64;
    ((s2 / n as f64 - mean * mean).max(0.0), n, mean)
}

/// The best integer shift within `radius` of `centre` by [`shift_cost`], with its cost and
/// mean log ratio. `None` when no shift has `min_count` pixels.
fn search(
    a: &Level,
    b: &Level,
    centre: (isize, isize),
    radius: isize,
    win: (usize, usize, usize, usize),
    min_count: usize,
) -> Option<((isize, isize), f64, f64)> {
    let mut best: Option<((isize, isize), f64, f64)> = None;
    for dy in -radius..=radius {
        for dx in -radius..=radius {
            let d = (centre.0 + dx, centre.1 + dy);
            let (c, n, mean) = shift_cost(a, b, d, win);
            if n >= min_count && c.is_finite() && best.is_none_or(|(_, bc, _)| c < bc) {
                best = Some((d, c, mean));
            }
        }
    }
    best
}

/// Sub-pixel refinement of an integer minimum by parabolas through the costs at `d - 1`,
/// `d`, `d + 1` along each axis.
fn subpixel(
    a: &Level,
    b: &Level,
    d: (isize, isize),
    c0: f64,
    win: (usize, usize, usize, usize),
) -> (f64, f64) {
    let fit = |cm: f64, cp: f64| {
        let den = cm - 2.0 * c0 + cp;
        if cm.is_finite() && cp.is_finite() && den > 1e-12 {
            (0.5 * (cm - cp) / den).clamp(-0.5, 0.5)
        } else {
            0.0
        }
    };
    let fx = fit(
        shift_cost(a, b, (d.0 - 1, d.1), win).0,
        shift_cost(a, b, (d.0 + 1, d.1), win).0,
    );
    let fy = fit(
        shift_cost(a, b, (d.0, d.1 - 1), win).0,
        shift_cost(a, b, (d.0, d.1 + 1), win).0,
    );
    (d.0 as f64 + fx, d.1 as f64 + fy)
}

/// Gauss-Newton refinement of a tile's shift `d` (frame b at `p` shows frame a at `p + d`)
/// on level 0, symmetric in the two frames (b sampled at `p - d/2`, a at `p + d/2`, so that
/// `m(a, b) = -m(b, a)` exactly), with the log ratio `c` as a third unknown and Huber
/// weights. Returns the start when the refinement leaves the neighbourhood of the start.
fn refine(
    la: &Level,
    lb: &Level,
    win: (usize, usize, usize, usize),
    start: (f64, f64),
    c0: f64,
    buf: &mut (Vec<f32>, Vec<f32>),
) -> (f64, f64) {
    let (pw, ph) = (win.2 - win.0 + 2, win.3 - win.1 + 2);
    let (x0, y0) = (win.0 as isize - 1, win.1 as isize - 1);
    let (mut dx, mut dy, mut c) = (start.0, start.1, c0 as f32);
    if !c.is_finite() {
        return start;
    }
    for _ in 0..2 {
        sample_patch(lb, x0, y0, pw, ph, -0.5 * dx, -0.5 * dy, &mut buf.0);
        sample_patch(la, x0, y0, pw, ph, 0.5 * dx, 0.5 * dy, &mut buf.1);
        let (pb, pa) = (&buf.0, &buf.1);
        let mut h = [0.0f32; 6];
        let mut g = [0.0f32; 3];
        let mut n = 0usize;
        for j in 1..ph - 1 {
            let (up, down) = (
                (j - 1) * pw + 1..j * pw - 1,
                (j + 1) * pw + 1..(j + 2) * pw - 1,
            );
            let (bu, bd) = (&pb[up.clone()], &pb[down.clone()]);
            let (au, ad) = (&pa[up], &pa[down]);
            let (bm, am) = (&pb[j * pw..(j + 1) * pw], &pa[j * pw..(j + 1) * pw]);
            let vertical = bu.iter().zip(bd).zip(au.iter().zip(ad));
            for ((wb, wa), ((ub, db), (ua, da))) in bm.windows(3).zip(am.windows(3)).zip(vertical) {
                let r = wb[1] - wa[1] - c;
                let jx = -0.25 * (wb[2] - wb[0] + wa[2] - wa[0]);
                let jy = -0.25 * (db - ub + da - ua);
                if !(r + jx + jy).is_finite() {
                    continue;
                }
                let w = (0.05 / r.abs()).min(1.0);
                let (wx, wy) = (w * jx, w * jy);
                h[0] += wx * jx;
                h[1] += wx * jy;
                h[2] -= wx;
                h[3] += wy * jy;
                h[4] -= wy;
                h[5] += w;
                g[0] += wx * r;
                g[1] += wy * r;
                g[2] -= w * r;
                n += 1;
            }
        }
        if n < 16 {
            return start;
        }
        let m = nalgebra::Matrix3::new(
            h[0] as f64,
            h[1] as f64,
            h[2] as f64,
            h[1] as f64,
            h[3] as f64,
            h[4] as f64,
            h[2] as f64,
            h[4] as f64,
            h[5] as f64,
        );
        let rhs = nalgebra::Vector3::new(g[0] as f64, g[1] as f64, g[2] as f64);
        let Some(step) = m.cholesky().map(|ch| ch.solve(&rhs)) else {
            return start;
        };
        dx -= step[0];
        dy -= step[1];
        c -= step[2] as f32;
    }
    if dx.is_finite()
        && dy.is_finite()
        && (dx - start.0).abs() <= 0.75
        && (dy - start.1).abs() <= 0.75
    {
        (dx, dy)
    } else {
        start
    }
}

/// Median of `f32` values (reordered) as `f64`; NaN when empty.
fn median_f32(v: &mut [f32]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let mid = v.len() / 2;
    let (_, m, _) = v.select_nth_unstable_by(mid, f32::total_cmp);
    *m as f64
}

/// Huber M-estimate of location with its sandwich standard error; the scale is 1.4826 MAD
/// (at least `min_scale`).
fn huber(values: &[f64], min_scale: f64) -> (f64, f64, f64) {
    let n = values.len();
    let mut tmp = values.to_vec();
    let mut mu = median(&mut tmp);
    let mut dev: Vec<f64> = values.iter().map(|v| (v - mu).abs()).collect();
    let scale = (1.4826 * median(&mut dev)).max(min_scale);
    let k = 1.5;
    for _ in 0..20 {
        let (mut num, mut den) = (0.0, 0.0);
        for &v in values {
            let u = (v - mu) / scale;
            let w = if u.abs() <= k { 1.0 } else { k / u.abs() };
            num += w * v;
            den += w;
        }
        let next = num / den;
        let done = (next - mu).abs() < 1e-9 * scale;
        mu = next;
        if done {
            break;
        }
    }
    let (mut psi2, mut dpsi) = (0.0, 0.0);
    for &v in values {
        let u = (v - mu) / scale;
        if u.abs() <= k {
            psi2 += u * u;
            dpsi += 1.0;
        } else {
            psi2 += k * k;
        }
    }
    // small-sample correction n / (n - 1)
    let se = if dpsi > 0.0 && n > 1 {
        scale * (psi2 * n as f64 / (n - 1) as f64).sqrt() / dpsi
    } else {
        f64::INFINITY
    };
    (mu, se, scale)
}

/// Measures `log(t_b / t_a)` of two frames prepared by the same [`ExposureMeter`] (see the
/// module documentation). Never fails: a pair that cannot be measured is returned
/// unreliable, with a note.
pub fn measure_ratio(
    a: &MeteredFrame,
    b: &MeteredFrame,
    opts: &ExposureOptions,
) -> RatioMeasurement {
    if a.levels.len() != b.levels.len() || a.analysis_size() != b.analysis_size() {
        return RatioMeasurement::failed("the frames differ in size");
    }
    let top = a.levels.len() - 1;
    let (w0, h0) = a.analysis_size();
    // coarse to fine: exhaustive at the coarsest level, +-1 below, down to level 1 (the
    // tiles refine on level 0)
    let full_radius = (opts.max_motion.clamp(0.0, 1.0) * w0 as f64).ceil() as isize;
    let last = top.min(1);
    let mut d = (0isize, 0isize);
    for l in (last..=top).rev() {
        let (la, lb) = (&a.levels[l], &b.levels[l]);
        let min_count = (la.w * la.h / 8).max(16);
        let win = (0, 0, lb.w, lb.h);
        let (centre, radius) = if l == top {
            ((0, 0), (full_radius >> l) + 1)
        } else {
            ((2 * d.0, 2 * d.1), 1)
        };
        match search(la, lb, centre, radius, win, min_count) {
            Some((best, _, _)) => d = best,
            None => {
                return RatioMeasurement::failed(
                    "too few usable pixels in common (dark, saturated or out of view)",
                )
            }
        }
    }
    let (la, lb) = (&a.levels[0], &b.levels[0]);
    let ds = a.downsample as f64;
    // a start for every tile's shift: +-2 pixels of level 1 around the global shift with a
    // sub-pixel fit (level 0 when the frames are too small for a pyramid)
    let t = opts.tile.max(8) & !1;
    let (nx, ny) = ((w0 / t).max(1), (h0 / t).max(1));
    let t = t.min(w0).min(h0);
    let (ox, oy) = ((w0 - nx * t) / 2, (h0 - ny * t) / 2);
    let win_of = |tx: usize, ty: usize| {
        (
            ox + tx * t,
            oy + ty * t,
            ox + (tx + 1) * t,
            oy + (ty + 1) * t,
        )
    };
    let min_count = t * t / 4;
    let mut grid: Vec<Option<(f64, f64)>> = vec![None; nx * ny];
    let mut offsets = vec![f64::NAN; nx * ny];
    for ty in 0..ny {
        for tx in 0..nx {
            let win = win_of(tx, ty);
            // the coarser level suffices for a start: the refinement on level 0 follows
            let (l, centre, radius, scale) = if last == 1 {
                (1, d, 2, 2.0)
            } else {
                (0, d, 1, 1.0)
            };
            let (sa, sb) = (&a.levels[l], &b.levels[l]);
            let f = 1usize << l;
            let win_l = (win.0 / f, win.1 / f, win.2 / f, win.3 / f);
            if let Some((best, c, mean)) =
                search(sa, sb, centre, radius, win_l, min_count / (f * f))
            {
                let (sx, sy) = subpixel(sa, sb, best, c, win_l);
                grid[ty * nx + tx] = Some((sx * scale, sy * scale));
                offsets[ty * nx + tx] = mean;
            }
        }
    }
    let found: Vec<(f64, f64)> = grid.iter().flatten().copied().collect();
    if found.is_empty() {
        let f = (1usize << last) as f64 * ds;
        let mut m = RatioMeasurement::failed("the alignment failed in every tile");
        m.shift = [d.0 as f64 * f, d.1 as f64 * f];
        return m;
    }
    let med2 = |v: &[(f64, f64)]| {
        let mut xs: Vec<f64> = v.iter().map(|s| s.0).collect();
        let mut ys: Vec<f64> = v.iter().map(|s| s.1).collect();
        (median(&mut xs), median(&mut ys))
    };
    let global = med2(&found);
    let shift = [global.0 * ds, global.1 * ds];
    // a smooth displacement field: a tile's shift that differs from the median of its
    // neighbourhood by more than a pixel (a failed local search), or is missing, is replaced
    let mut field = vec![global; nx * ny];
    for ty in 0..ny {
        for tx in 0..nx {
            let mut near = Vec::with_capacity(9);
            for yy in ty.saturating_sub(1)..(ty + 2).min(ny) {
                for xx in tx.saturating_sub(1)..(tx + 2).min(nx) {
                    if let Some(s) = grid[yy * nx + xx] {
                        near.push(s);
                    }
                }
            }
            let own = grid[ty * nx + tx];
            field[ty * nx + tx] = if near.len() >= 3 {
                let m = med2(&near);
                match own {
                    Some(s) if (s.0 - m.0).abs() <= 1.0 && (s.1 - m.1).abs() <= 1.0 => s,
                    _ => m,
                }
            } else {
                own.unwrap_or(global)
            };
        }
    }
    // each tile's shift refined where the frames match best, then a smooth displacement
    // field between the tile centres (a rotation or a zoom is not one shift per tile)
    let mut buf = (Vec::new(), Vec::new());
    let mut mean_offsets: Vec<f64> = offsets.iter().copied().filter(|v| v.is_finite()).collect();
    let global_offset = median(&mut mean_offsets);
    for ty in 0..ny {
        for tx in 0..nx {
            let k = ty * nx + tx;
            let c0 = if offsets[k].is_finite() {
                offsets[k]
            } else {
                global_offset
            };
            field[k] = refine(la, lb, win_of(tx, ty), field[k], c0, &mut buf);
        }
    }
    let half = (t as f64 - 1.0) / 2.0;
    let axis = |p: f64, o: usize, n: usize| {
        let u = ((p - o as f64 - half) / t as f64).clamp(0.0, (n - 1) as f64);
        let i = (u as usize).min(n.saturating_sub(2));
        (i, (i + 1).min(n - 1), u - i as f64)
    };
    let displacement = |x: f64, y: f64| {
        let (i0, i1, fx) = axis(x, ox, nx);
        let (j0, j1, fy) = axis(y, oy, ny);
        let f = |i: usize, j: usize| field[j * nx + i];
        let (a00, a10, a01, a11) = (f(i0, j0), f(i1, j0), f(i0, j1), f(i1, j1));
        let top = (a00.0 + fx * (a10.0 - a00.0), a00.1 + fx * (a10.1 - a00.1));
        let bot = (a01.0 + fx * (a11.0 - a01.0), a01.1 + fx * (a11.1 - a01.1));
        (top.0 + fy * (bot.0 - top.0), top.1 + fy * (bot.1 - top.1))
    };
    // blocks of BLOCK x BLOCK pixels, each sampled at the field's displacement at its centre
    const BLOCK: usize = 8;
    let mut tile_values = Vec::new();
    let mut spreads = Vec::new();
    let mut samples: Vec<(f32, f32, f32)> = Vec::with_capacity(t * t);
    let mut residuals: Vec<f32> = Vec::with_capacity(t * t);
    let (mut lin_b, mut lin_a) = (Vec::new(), Vec::new());
    for ty in 0..ny {
        for tx in 0..nx {
            let win = win_of(tx, ty);
            samples.clear();
            for by in (win.1..win.3).step_by(BLOCK) {
                for bx in (win.0..win.2).step_by(BLOCK) {
                    let (bw, bh) = (BLOCK.min(win.2 - bx), BLOCK.min(win.3 - by));
                    let (sx, sy) = displacement(
                        bx as f64 + (bw as f64 - 1.0) / 2.0,
                        by as f64 + (bh as f64 - 1.0) / 2.0,
                    );
                    // both frames half the displacement from the pixel centres, so that both
                    // are interpolated alike
                    let (x0, y0) = (bx as isize, by as isize);
                    sample_patch(lb, x0, y0, bw, bh, -0.5 * sx, -0.5 * sy, &mut buf.0);
                    sample_patch(la, x0, y0, bw, bh, 0.5 * sx, 0.5 * sy, &mut buf.1);
                    sample_patch(&b.linear, x0, y0, bw, bh, -0.5 * sx, -0.5 * sy, &mut lin_b);
                    sample_patch(&a.linear, x0, y0, bw, bh, 0.5 * sx, 0.5 * sy, &mut lin_a);
                    for k in 0..buf.0.len() {
                        let r = buf.0[k] - buf.1[k];
                        if r.is_finite() {
                            samples.push((r, lin_b[k], lin_a[k]));
                        }
                    }
                }
            }
            if samples.len() < min_count {
                continue;
            }
            // centre and spread of the log ratios from every fourth sample
            residuals.clear();
            residuals.extend(samples.iter().step_by(4).map(|s| s.0));
            let med = median_f32(&mut residuals) as f32;
            for r in residuals.iter_mut() {
                *r = (*r - med).abs();
            }
            let spread = 1.4826 * median_f32(&mut residuals);
            // the ratio of the tile's sums of U / V (immune to the bias that a changed pixel
            // footprint gives a mean of logs), over the pixels whose log ratio is not an
            // outlier
            let cut = (4.0 * spread).max(1e-3) as f32;
            let (mut sb, mut sa) = (0.0f64, 0.0f64);
            for &(r, vb, va) in &samples {
                if (r - med).abs() <= cut {
                    sb += vb as f64;
                    sa += va as f64;
                }
            }
            if !(sa > 0.0 && sb > 0.0) {
                continue;
            }
            spreads.push(spread);
            tile_values.push((sb / sa).ln());
        }
    }
    let tiles = tile_values.len();
    if tiles < opts.min_tiles.max(2) {
        let mut m = RatioMeasurement::failed(format!(
            "{tiles} usable tiles, at least {} needed",
            opts.min_tiles.max(2)
        ));
        m.shift = shift;
        return m;
    }
    let (mu, se, _) = huber(&tile_values, 1e-5);
    let pixel_spread = median(&mut spreads);
    let std_error = (se * se + opts.systematic_error * opts.systematic_error).sqrt();
    let reliable = std_error <= opts.max_std_error;
    RatioMeasurement {
        log_ratio: mu,
        std_error,
        shift,
        tiles,
        pixel_spread,
        reliable,
        note: if reliable {
            String::new()
        } else {
            format!(
                "standard error {std_error:.4} above {} (motion blur, large motion or a scene change)",
                opts.max_std_error
            )
        },
    }
}

/// A measured ratio between two frames for [`estimate_exposures`]: `log(t_to / t_from)`.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PairRatio {
    /// The first frame (0-based).
    pub from: usize,
    /// The second frame (0-based, after `from`).
    pub to: usize,
    /// The measurement.
    pub measurement: RatioMeasurement,
}

impl PairRatio {
    /// The pairs of a sequence's measurements for [`estimate_exposures`]: `consecutive[i]`
    /// links frames `i` and `i + 1`, `skip[i]` frames `i` and `i + 2`.
    pub fn chain(consecutive: &[RatioMeasurement], skip: &[RatioMeasurement]) -> Vec<PairRatio> {
        let pair = |step: usize| {
            move |(i, m): (usize, &RatioMeasurement)| PairRatio {
                from: i,
                to: i + step,
                measurement: m.clone(),
            }
        };
        consecutive
            .iter()
            .enumerate()
            .map(pair(1))
            .chain(skip.iter().enumerate().map(pair(2)))
            .collect()
    }
}

/// What [`check_exposures`] concludes about one frame's logged exposure.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    /// The logged exposure agrees with the images.
    Consistent,
    /// The logged exposure is the previous frame's.
    ShiftedFromPrevious,
    /// The logged exposure is the next frame's.
    ShiftedFromNext,
    /// The logged exposure contradicts the images, and neither neighbour's exposure fits.
    Inconsistent,
    /// No decision: the ratios around the frame are unreliable or contradict each other.
    Undecided,
}

impl Verdict {
    /// Whether the frame is flagged as shifted by one frame.
    pub fn is_shifted(self) -> bool {
        matches!(
            self,
            Verdict::ShiftedFromPrevious | Verdict::ShiftedFromNext
        )
    }
}

/// The check of one frame's logged exposure.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FrameCheck {
    /// Frame index (0-based, times.txt order).
    pub frame: usize,
    /// The logged exposure in ms.
    pub logged_ms: f64,
    /// The frame's exposure as its neighbours' logged exposures and the measured ratios
    /// predict it, in ms (NaN when undecided).
    pub predicted_ms: f64,
    /// Standard error of `log(predicted_ms)` (with the logging precision).
    pub std_error: f64,
    /// `log(logged / predicted)` in standard errors.
    pub z: f64,
    /// The conclusion.
    pub verdict: Verdict,
    /// Why the frame is undecided (empty otherwise).
    pub note: String,
}

/// The result of [`check_exposures`].
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ExposureCheck {
    /// One entry per frame.
    pub frames: Vec<FrameCheck>,
    /// Frames whose logged exposure is a neighbour's (0-based).
    pub shifted: Vec<usize>,
    /// Frames whose logged exposure contradicts the images otherwise.
    pub inconsistent: Vec<usize>,
    /// Frames without a decision.
    pub undecided: Vec<usize>,
    /// Pairs `(i, i + 1)`, by `i`, whose ratio is unreliable.
    pub unreliable_pairs: Vec<usize>,
    /// The logged exposures with every shifted one replaced by its prediction, in ms.
    pub fixed_ms: Vec<f64>,
    /// The exposures measured from the images alone (the chained ratios), scaled to the
    /// logged ones (median ratio 1 between gaps), in ms.
    pub measured_ms: Vec<f64>,
    /// Whether the log as a whole is one frame off: `1` when every frame logs its previous
    /// frame's exposure, `-1` its next frame's, `0` otherwise (see `lag_scores`).
    pub log_lag: i32,
    /// Median `|measured - logged| / std_error` of the consecutive log ratios with the log
    /// moved by -1, 0 and +1 frames.
    pub lag_scores: [f64; 3],
}

/// A robust estimate from several predictions of one log exposure: the median and its
/// variance (the larger of the propagated one and the spread's).
fn robust_prediction(values: &[(f64, f64)]) -> Option<(f64, f64)> {
    let n = values.len();
    if n == 0 {
        return None;
    }
    let mut v: Vec<f64> = values.iter().map(|p| p.0).collect();
    let med = median(&mut v);
    let mean_var = values.iter().map(|p| p.1).sum::<f64>() / n as f64;
    let eff = if n >= 3 {
        std::f64::consts::FRAC_PI_2
    } else {
        1.0
    };
    let mut var = mean_var * eff / n as f64;
    if n >= 3 {
        let mut dev: Vec<f64> = values.iter().map(|p| (p.0 - med).abs()).collect();
        let s = 1.4826 * median(&mut dev);
        var = var.max(s * s * eff / n as f64);
    }
    Some((med, var))
}

/// Checks logged exposures against the measured ratios of consecutive frames (see the
/// module documentation). `logged_ms[i]` is frame `i`'s logged exposure, `ratios[i]` the
/// measurement of `log(t_{i+1} / t_i)`.
pub fn check_exposures(
    logged_ms: &[f64],
    ratios: &[RatioMeasurement],
    opts: &ExposureOptions,
) -> Result<ExposureCheck, PhotometricError> {
    let n = logged_ms.len();
    if n < 2 {
        return Err(PhotometricError::Calibration(format!(
            "an exposure check needs at least 2 frames, found {n}"
        )));
    }
    if ratios.len() != n - 1 {
        return Err(PhotometricError::Calibration(format!(
            "{n} frames need {} ratios of consecutive frames, found {}",
            n - 1,
            ratios.len()
        )));
    }
    if let Some((frame, &t)) = logged_ms
        .iter()
        .enumerate()
        .find(|(_, t)| !(t.is_finite() && **t > 0.0))
    {
        return Err(PhotometricError::Calibration(format!(
            "frame {frame}: logged exposure {t} ms is not a positive number"
        )));
    }
    let g: Vec<f64> = logged_ms.iter().map(|t| t.ln()).collect();
    let var_g = opts.log_precision * opts.log_precision;
    let ok = |i: usize| ratios[i].reliable && ratios[i].log_ratio.is_finite();
    let var_m = |i: usize| ratios[i].std_error * ratios[i].std_error;
    let w = opts.window.max(1);
    let mut frames = Vec::with_capacity(n);
    for k in 0..n {
        // the previous frame's log exposure from the logs left of k (chained up to k - 1)
        let mut left = Vec::new();
        if k >= 1 {
            let (mut acc, mut var) = (0.0, 0.0);
            for j in (k.saturating_sub(w)..k).rev() {
                if j < k - 1 {
                    // pair (j, j + 1) links j to the frames after it
                    if !ok(j) {
                        break;
                    }
                    acc += ratios[j].log_ratio;
                    var += var_m(j);
                }
                left.push((g[j] + acc, var + var_g));
            }
        }
        let mut right = Vec::new();
        if k + 1 < n {
            let (mut acc, mut var) = (0.0, 0.0);
            for j in k + 1..(k + 1 + w).min(n) {
                if j > k + 1 {
                    if !ok(j - 1) {
                        break;
                    }
                    acc += ratios[j - 1].log_ratio;
                    var += var_m(j - 1);
                }
                right.push((g[j] - acc, var + var_g));
            }
        }
        let prev = robust_prediction(&left);
        let next = robust_prediction(&right);
        // predictions of frame k itself through the measured ratios next to it
        let from_left = prev
            .filter(|_| k >= 1 && ok(k - 1))
            .map(|(a, va)| (a + ratios[k - 1].log_ratio, va + var_m(k - 1)));
        let from_right = next
            .filter(|_| k + 1 < n && ok(k))
            .map(|(b, vb)| (b - ratios[k].log_ratio, vb + var_m(k)));
        let mut check = FrameCheck {
            frame: k,
            logged_ms: logged_ms[k],
            predicted_ms: f64::NAN,
            std_error: f64::NAN,
            z: f64::NAN,
            verdict: Verdict::Undecided,
            note: String::new(),
        };
        let predicted = match (from_left, from_right) {
            (Some((pl, vl)), Some((pr, vr))) => {
                let q = pl - pr;
                let sq = (vl + vr).sqrt();
                if q.abs() > opts.consistency_sigmas * sq && q.abs() > opts.min_difference {
                    check.note = format!(
                        "the neighbours predict exposures {:.2}% apart ({:.1} standard errors): a bad ratio or a neighbour's bad log",
                        100.0 * q.abs(),
                        q.abs() / sq
                    );
                    None
                } else {
                    let wl = 1.0 / vl;
                    let wr = 1.0 / vr;
                    Some(((wl * pl + wr * pr) / (wl + wr), 1.0 / (wl + wr)))
                }
            }
            (Some(p), None) | (None, Some(p)) => {
                let side = if k >= 1 && ok(k - 1) { &left } else { &right };
                if side.len() >= 2 {
                    Some(p)
                } else {
                    check.note = "one neighbour only, and its ratio is the only link".into();
                    None
                }
            }
            (None, None) => {
                check.note = "the ratios on both sides are unreliable".into();
                None
            }
        };
        if let Some((p, vp)) = predicted {
            let s0 = (vp + var_g).sqrt();
            let d0 = g[k] - p;
            check.predicted_ms = p.exp();
            check.std_error = s0;
            check.z = d0 / s0;
            let contradicts = d0.abs() > opts.flag_sigmas * s0 && d0.abs() > opts.min_difference;
            check.verdict = if contradicts {
                let fits = |h: Option<(f64, f64)>| {
                    h.and_then(|(a, va)| {
                        let sh = (va + var_g).sqrt();
                        let dh = g[k] - a;
                        (dh.abs() <= opts.fit_sigmas * sh + 0.2 * d0.abs()).then_some(dh.abs() / sh)
                    })
                };
                match (fits(prev), fits(next)) {
                    (Some(zp), Some(zn)) if zn < zp => Verdict::ShiftedFromNext,
                    (Some(_), _) => Verdict::ShiftedFromPrevious,
                    (None, Some(_)) => Verdict::ShiftedFromNext,
                    (None, None) => Verdict::Inconsistent,
                }
            } else {
                Verdict::Consistent
            };
        }
        frames.push(check);
    }
    let pick = |f: &dyn Fn(Verdict) -> bool| -> Vec<usize> {
        frames
            .iter()
            .filter(|c| f(c.verdict))
            .map(|c| c.frame)
            .collect()
    };
    let shifted = pick(&|v| v.is_shifted());
    let inconsistent = pick(&|v| v == Verdict::Inconsistent);
    let undecided = pick(&|v| v == Verdict::Undecided);
    let fixed_ms = frames
        .iter()
        .map(|c| {
            if c.verdict.is_shifted() {
                c.predicted_ms
            } else {
                c.logged_ms
            }
        })
        .collect();
    // the measured exposures alone, scaled to the logged ones
    let pairs = PairRatio::chain(ratios, &[]);
    let est = estimate_exposures(n, &pairs, 1.0, opts)?;
    // each stretch between gaps (where no ratio links the frames) scaled to its logs
    let mut measured_ms = Vec::with_capacity(n);
    let mut bounds: Vec<usize> = est.gaps.iter().map(|&i| i + 1).collect();
    bounds.push(n);
    let mut from = 0;
    for to in bounds {
        let mut off: Vec<f64> = (from..to)
            .map(|k| g[k] - est.exposures_ms[k].ln())
            .collect();
        let scale = median(&mut off).exp();
        measured_ms.extend((from..to).map(|k| est.exposures_ms[k] * scale));
        from = to;
    }
    // the whole log one frame off: logged g_j = true t_{j - lag}
    let mut lag_scores = [f64::NAN; 3];
    for (slot, lag) in [-1i64, 0, 1].into_iter().enumerate() {
        let mut z: Vec<f64> = (0..n - 1)
            .filter(|&i| ok(i))
            .filter_map(|i| {
                let (a, b) = (i as i64 + lag, i as i64 + 1 + lag);
                (a >= 0 && b < n as i64).then(|| {
                    let logged = g[b as usize] - g[a as usize];
                    (ratios[i].log_ratio - logged).abs() / ratios[i].std_error
                })
            })
            .collect();
        lag_scores[slot] = median(&mut z);
    }
    let best = (0..3)
        .filter(|&i| lag_scores[i].is_finite())
        .min_by(|&a, &b| lag_scores[a].total_cmp(&lag_scores[b]));
    let log_lag = match best {
        Some(i)
            if i != 1
                && lag_scores[1] > opts.flag_sigmas
                && lag_scores[i] < 0.25 * lag_scores[1] =>
        {
            i as i32 - 1
        }
        _ => 0,
    };
    Ok(ExposureCheck {
        frames,
        shifted,
        inconsistent,
        undecided,
        unreliable_pairs: (0..n - 1).filter(|&i| !ok(i)).collect(),
        fixed_ms,
        measured_ms,
        log_lag,
        lag_scores,
    })
}

/// The result of [`estimate_exposures`].
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ExposureEstimate {
    /// Exposure per frame in ms, the median equal to the reference.
    pub exposures_ms: Vec<f64>,
    /// Standard error of `log(exposure)` per frame (relative), with respect to the anchor.
    pub log_std_error: Vec<f64>,
    /// The frame at the median whose standard error is 0.
    pub anchor: usize,
    /// Measured pairs that entered.
    pub pairs_used: usize,
    /// Pairs left out as unreliable.
    pub pairs_unreliable: usize,
    /// Pairs down-weighted as outliers, `(from, to)`.
    pub outliers: Vec<(usize, usize)>,
    /// Frames `i` whose step to `i + 1` no reliable ratio spans (only the weak prior links
    /// them: their relative exposure is unknown).
    pub gaps: Vec<usize>,
}

/// A symmetric positive-definite band matrix, lower band stored by rows:
/// `band[i * (p + 1) + d]` is `A[i][i - d]`.
///
/// Why a band solver of our own: the standard errors need the diagonal of `A^-1`, and no
/// crate of the stack computes a selected inverse. nalgebra's dense Cholesky and inverse of
/// such a matrix (bandwidth 4) took 0.35 s for 1,000 frames, 5.9 s for 2,000 and 60 s and
/// 256 MB for 4,000 (nalgebra 0.35, release build, 2-core machine); the dataset's sequences
/// have up to several thousand frames and a user's may have tens of thousands.
/// nalgebra-sparse and faer factor sparse matrices but do not give the inverse's diagonal,
/// and one solve per frame would cost `O(n^2 p)`. LDL^T in the band with Takahashi's
/// recurrence costs `O(n p^2)` time and `O(n p)` memory.
struct Band {
    n: usize,
    p: usize,
    a: Vec<f64>,
}

impl Band {
    fn new(n: usize, p: usize) -> Band {
        Band {
            n,
            p,
            a: vec![0.0; n * (p + 1)],
        }
    }

    /// Adds `v` to `A[i][j]` (and `A[j][i]`), `|i - j| <= p`.
    fn add(&mut self, i: usize, j: usize, v: f64) {
        let (r, c) = if i >= j { (i, j) } else { (j, i) };
        self.a[r * (self.p + 1) + (r - c)] += v;
    }

    /// LDL^T in place: afterwards `a[i][0]` is `D_i` and `a[i][d]` is `L[i][i - d]`.
    fn factor(&mut self) -> Result<(), PhotometricError> {
        let p = self.p;
        let q = p + 1;
        for i in 0..self.n {
            let lo = i.saturating_sub(p);
            for j in lo..i {
                // L[i][j] = (A[i][j] - sum_k L[i][k] D_k L[j][k]) / D_j, k in max(lo, j-p)..j
                let mut s = self.a[i * q + (i - j)];
                for k in lo.max(j.saturating_sub(p))..j {
                    s -= self.a[i * q + (i - k)] * self.a[k * q] * self.a[j * q + (j - k)];
                }
                self.a[i * q + (i - j)] = s / self.a[j * q];
            }
            let mut dv = self.a[i * q];
            for k in lo..i {
                let l = self.a[i * q + (i - k)];
                dv -= l * l * self.a[k * q];
            }
            if !(dv.is_finite() && dv > 0.0) {
                return Err(PhotometricError::Calibration(
                    "the exposure chain is singular".into(),
                ));
            }
            self.a[i * q] = dv;
        }
        Ok(())
    }

    /// Solves `A x = b` with the factors.
    fn solve(&self, b: &[f64]) -> Vec<f64> {
        let (p, q) = (self.p, self.p + 1);
        let mut x = b.to_vec();
        for i in 0..self.n {
            for k in i.saturating_sub(p)..i {
                x[i] -= self.a[i * q + (i - k)] * x[k];
            }
        }
        for (i, xi) in x.iter_mut().enumerate() {
            *xi /= self.a[i * q];
        }
        for i in (0..self.n).rev() {
            for k in i + 1..(i + q).min(self.n) {
                x[i] -= self.a[k * q + (k - i)] * x[k];
            }
        }
        x
    }

    /// The diagonal of `A^-1` from the factors (Takahashi's recurrence inside the band).
    fn inverse_diagonal(&self) -> Vec<f64> {
        let (n, p, q) = (self.n, self.p, self.p + 1);
        // z[i * q + d] = Z[i + d][i] for d = 0..=p (lower band by columns)
        let mut z = vec![0.0; n * q];
        let zat = |z: &[f64], i: usize, j: usize| -> f64 {
            let (r, c) = if i >= j { (i, j) } else { (j, i) };
            z[c * q + (r - c)]
        };
        for i in (0..n).rev() {
            let hi = (i + p).min(n - 1);
            for j in (i + 1..=hi).rev() {
                let mut s = 0.0;
                for k in i + 1..=hi {
                    s -= self.a[k * q + (k - i)] * zat(&z, k, j);
                }
                z[i * q + (j - i)] = s;
            }
            let mut s = 1.0 / self.a[i * q];
            for k in i + 1..=hi {
                s -= self.a[k * q + (k - i)] * z[i * q + (k - i)];
            }
            z[i * q] = s;
        }
        (0..n).map(|i| z[i * q]).collect()
    }
}

/// Weighted least squares of log exposures with frame `gauge` fixed at 0: the solution and
/// the variance of every frame relative to the gauge.
fn solve_chain(
    n: usize,
    obs: &[(usize, usize, f64, f64)],
    gauge: usize,
) -> Result<(Vec<f64>, Vec<f64>), PhotometricError> {
    let p = obs.iter().map(|o| o.1 - o.0).max().unwrap_or(1).max(1);
    let idx = |i: usize| {
        if i < gauge {
            Some(i)
        } else if i > gauge {
            Some(i - 1)
        } else {
            None
        }
    };
    let mut band = Band::new(n - 1, p);
    let mut rhs = vec![0.0; n - 1];
    for &(i, j, m, w) in obs {
        // residual x_j - x_i - m
        match (idx(i), idx(j)) {
            (Some(a), Some(b)) => {
                band.add(a, a, w);
                band.add(b, b, w);
                band.add(a, b, -w);
                rhs[b] += w * m;
                rhs[a] -= w * m;
            }
            (None, Some(b)) => {
                band.add(b, b, w);
                rhs[b] += w * m;
            }
            (Some(a), None) => {
                band.add(a, a, w);
                rhs[a] -= w * m;
            }
            (None, None) => {}
        }
    }
    band.factor()?;
    let sol = band.solve(&rhs);
    let dia = band.inverse_diagonal();
    let mut x = Vec::with_capacity(n);
    let mut var = Vec::with_capacity(n);
    for i in 0..n {
        match idx(i) {
            Some(a) => {
                x.push(sol[a]);
                var.push(dia[a].max(0.0));
            }
            None => {
                x.push(0.0);
                var.push(0.0);
            }
        }
    }
    Ok((x, var))
}

/// Estimates the exposures of `n` frames from measured ratios (see the module
/// documentation), anchored so that the median exposure is `reference_ms`.
pub fn estimate_exposures(
    n: usize,
    pairs: &[PairRatio],
    reference_ms: f64,
    opts: &ExposureOptions,
) -> Result<ExposureEstimate, PhotometricError> {
    if n < 2 {
        return Err(PhotometricError::Calibration(format!(
            "an exposure estimate needs at least 2 frames, found {n}"
        )));
    }
    if !(reference_ms.is_finite() && reference_ms > 0.0) {
        return Err(PhotometricError::Exposure(reference_ms));
    }
    if let Some(bad) = pairs.iter().find(|p| p.to <= p.from || p.to >= n) {
        return Err(PhotometricError::Calibration(format!(
            "pair ({}, {}) is not two frames of 0..{n} in order",
            bad.from, bad.to
        )));
    }
    let gap_prior = opts.gap_prior.max(1e-3);
    let used: Vec<&PairRatio> = pairs
        .iter()
        .filter(|p| {
            let m = &p.measurement;
            p.to - p.from <= 8 && m.reliable && m.log_ratio.is_finite() && m.std_error > 0.0
        })
        .collect();
    let mut spans = vec![false; n - 1];
    for p in &used {
        for s in &mut spans[p.from..p.to] {
            *s = true;
        }
    }
    let gaps: Vec<usize> = (0..n - 1).filter(|&i| !spans[i]).collect();
    let mut robust = vec![1.0; used.len()];
    let build = |robust: &[f64]| -> Vec<(usize, usize, f64, f64)> {
        let mut obs: Vec<(usize, usize, f64, f64)> = used
            .iter()
            .zip(robust)
            .map(|(p, r)| {
                let s = p.measurement.std_error;
                (p.from, p.to, p.measurement.log_ratio, r / (s * s))
            })
            .collect();
        for i in 0..n - 1 {
            obs.push((i, i + 1, 0.0, 1.0 / (gap_prior * gap_prior)));
        }
        obs
    };
    let mut x = vec![0.0; n];
    // Huber reweighting; it changes something only where pairs overlap
    for _ in 0..20 {
        let (sol, _) = solve_chain(n, &build(&robust), 0)?;
        x = sol;
        let mut change = 0.0f64;
        for (r, p) in robust.iter_mut().zip(&used) {
            let m = &p.measurement;
            let u = ((x[p.to] - x[p.from] - m.log_ratio) / m.std_error).abs();
            // Huber, and a pair 8 standard errors off is out
            let nr = if u <= 2.5 {
                1.0
            } else if u <= 8.0 {
                2.5 / u
            } else {
                0.0
            };
            change = change.max((nr - *r).abs());
            *r = nr;
        }
        if change < 1e-3 {
            break;
        }
    }
    // anchor: the frame at the median
    let mut sorted: Vec<(f64, usize)> = x.iter().copied().zip(0..).collect();
    sorted.sort_by(|a, b| a.0.total_cmp(&b.0));
    let anchor = sorted[(n - 1) / 2].1;
    let (x, var) = solve_chain(n, &build(&robust), anchor)?;
    let mut xs = x.clone();
    let med = median(&mut xs);
    let offset = reference_ms.ln() - med;
    let outliers = used
        .iter()
        .zip(&robust)
        .filter(|(_, r)| **r < 1.0)
        .map(|(p, _)| (p.from, p.to))
        .collect();
    Ok(ExposureEstimate {
        exposures_ms: x.iter().map(|v| (v + offset).exp()).collect(),
        log_std_error: var.iter().map(|v| v.sqrt()).collect(),
        anchor,
        pairs_used: used.len(),
        pairs_unreliable: pairs.len() - used.len(),
        outliers,
        gaps,
    })
}
