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

mod check;
mod estimate;
mod meter;
mod ratio;

pub use self::check::{check_exposures, ExposureCheck, FrameCheck, Verdict};
pub use self::estimate::{estimate_exposures, ExposureEstimate};
pub use self::meter::{ExposureMeter, MeteredFrame};
pub use self::ratio::{measure_ratio, PairRatio, RatioMeasurement};

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
