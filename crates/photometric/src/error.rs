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
    /// A number written with a decimal comma (`0,5`); pcalib.txt needs a '.'.
    #[error("line {line}: `{token}`: the decimal separator must be '.', not ','")]
    DecimalComma {
        /// 1-based line.
        line: usize,
        /// The offending token.
        token: String,
    },
    /// An inverse response with a number of values that is neither a power of two from 256 to
    /// 65536 nor a deep sensor's table ending at its saturation value (513 to 65536 values).
    #[error("{}expected 2^k values (256 for 8-bit, 65536 for 16-bit images, or 513 to 65536 for a deeper table that ends at the saturation value), found {found} numbers", at_line(*line))]
    ValueCount {
        /// 1-based line of the last value (0 when not from a file).
        line: usize,
        /// How many values there are.
        found: usize,
    },
    /// An inverse response that is not finite.
    #[error("{}U({index}) = {value} is not a finite number", at_line(*line))]
    NotFinite {
        /// Grey value.
        index: usize,
        /// The value.
        value: f64,
        /// 1-based line of the value in pcalib.txt (0 when not from a file).
        line: usize,
    },
    /// An inverse response that is not strictly increasing (DSO rejects these).
    #[error("{}the inverse response must strictly increase, but U({index}) = {value} <= U({}) = {previous}", at_line(*line), index - 1)]
    NotIncreasing {
        /// Grey value.
        index: usize,
        /// U at `index`.
        value: f64,
        /// U at `index - 1`.
        previous: f64,
        /// 1-based line of the value in pcalib.txt (0 when not from a file).
        line: usize,
    },
    /// A pixel value beyond the bit depth the frames are declared to have.
    #[error("pixel value {value} does not fit in {bits} bits (at most {}); are the values in the high bits? then the bit depth is 16", (1u32 << bits) - 1)]
    SampleRange {
        /// The value found.
        value: u32,
        /// The declared bit depth.
        bits: u32,
    },
    /// A bit depth outside 1..=16.
    #[error("bit depth {0} is not supported (1 to 16 bits per pixel)")]
    BitDepth(u32),
    /// An output bit depth other than 8 or 16.
    #[error("output depth {0} bits is not supported (8 or 16 bits per pixel)")]
    OutputDepth(u8),
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
    /// A calibration option outside the values it can take.
    #[error("calibration option `{name}` = {value}: expected {expected}")]
    InvalidOption {
        /// The option (the field of the options, the key of a config file).
        name: &'static str,
        /// The value given.
        value: String,
        /// What it can be.
        expected: &'static str,
    },
    /// The scratch file of a calibration could not be written or read.
    #[error("{0}")]
    Scratch(String),
    /// An error of the camera model (rectification).
    #[error(transparent)]
    Camera(#[from] camera_model::CameraError),
}

/// `"line N: "` for errors that came from a file line, nothing for line 0.
fn at_line(line: usize) -> String {
    if line > 0 {
        format!("line {line}: ")
    } else {
        String::new()
    }
}
