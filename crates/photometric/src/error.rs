//! The error type of photometric.

use thiserror::Error;

/// Errors of the photometric crate. Parse errors carry the 1-based line (the caller adds the
/// file name).
#[derive(Debug, Clone, PartialEq, Error)]
pub enum PhotometricError {
    /// A pcalib.txt line that does not parse.
    #[error("line {line}: expected {expected}, found `{found}`")]
    Parse {
        /// 1-based line.
        line: usize,
        /// What was expected.
        expected: &'static str,
        /// An excerpt.
        found: String,
    },
    /// An inverse response that is not finite.
    #[error("U({index}) = {value} is not a finite number")]
    NotFinite {
        /// Grey value.
        index: usize,
        /// The value.
        value: f64,
    },
    /// An inverse response that is not strictly increasing (DSO rejects these).
    #[error("the inverse response must strictly increase, but U({index}) = {value} <= U({}) = {previous}", index - 1)]
    NotIncreasing {
        /// Grey value.
        index: usize,
        /// U at `index`.
        value: f64,
        /// U at `index - 1`.
        previous: f64,
    },
    /// A vignette that is zero everywhere or not finite.
    #[error("vignette: {0}")]
    Vignette(String),
    /// Images whose sizes do not agree.
    #[error("{what} is {got_width}x{got_height}, expected {width}x{height}")]
    SizeMismatch {
        /// What has the wrong size.
        what: &'static str,
        /// Expected width.
        width: usize,
        /// Expected height.
        height: usize,
        /// Actual width.
        got_width: usize,
        /// Actual height.
        got_height: usize,
    },
    /// An exposure that cannot be used.
    #[error("exposure {0} ms is not a positive number")]
    Exposure(f64),
    /// Calibration data that cannot determine the result.
    #[error("{0}")]
    Calibration(String),
    /// An error of the camera model (rectification).
    #[error(transparent)]
    Camera(#[from] camera_model::CameraError),
}
