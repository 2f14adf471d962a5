//! The error type of this crate.

use thiserror::Error;

/// Everything that can go wrong when parsing a camera, computing an output camera or
/// remapping an image. Variants carry the offending value; parse errors carry the 1-based
/// line number (the caller adds the file name).
#[derive(Debug, Clone, PartialEq, Error)]
pub enum CameraError {
    /// A line of camera.txt does not have the expected form.
    #[error("{}expected {expected}, found `{found}`", at_line(*line))]
    Parse {
        /// 1-based line number (0 when the value did not come from a file).
        line: usize,
        /// What the line should contain.
        expected: String,
        /// What it contains (trimmed).
        found: String,
    },
    /// A number written with a decimal comma (`0,5`); camera.txt needs a '.'.
    #[error("{}`{token}` in `{text}`: the decimal separator must be '.', not ',' (DSO reads `0,5` as 0)", at_line(*line))]
    DecimalComma {
        /// 1-based line number (0 when the value did not come from a file).
        line: usize,
        /// The offending token.
        token: String,
        /// The line (trimmed).
        text: String,
    },
    /// A value parsed but is not acceptable (non-finite, non-positive focal length, ...).
    #[error("{}{message}", at_line(*line))]
    InvalidValue {
        /// 1-based line number (0 when the value did not come from a file).
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// An image size that cannot be used (the bilinear remap needs at least 2x2 pixels).
    #[error("invalid image size {width}x{height}: {reason}")]
    InvalidSize {
        /// Width in pixels.
        width: usize,
        /// Height in pixels.
        height: usize,
        /// Why it is refused.
        reason: &'static str,
    },
    /// `full` cannot include the whole input field of view (it reaches 90 degrees or more).
    #[error("output camera `full` cannot keep the whole field of view of this {model} camera: the border pixel ({u}, {v}) looks 90 degrees or more away from the optical axis; use `crop` or an explicit pinhole")]
    FullUnbounded {
        /// The input model's name.
        model: &'static str,
        /// Pixel column of the offending border pixel.
        u: f64,
        /// Pixel row of the offending border pixel.
        v: f64,
    },
    /// No output pinhole without invalid pixels could be found.
    #[error("no valid `crop` output camera for this {model} camera: {reason}")]
    NoValidCrop {
        /// The input model's name.
        model: &'static str,
        /// Why the search failed.
        reason: String,
    },
    /// An image whose size does not match what the map or camera expects.
    #[error("image is {got_width}x{got_height}, expected {width}x{height}")]
    ImageSizeMismatch {
        /// Expected width.
        width: usize,
        /// Expected height.
        height: usize,
        /// Width of the image given.
        got_width: usize,
        /// Height of the image given.
        got_height: usize,
    },
    /// A pixel buffer whose length is not `width * height`.
    #[error("image buffer has {len} values, expected {width}x{height} = {}", width * height)]
    BufferLength {
        /// Image width.
        width: usize,
        /// Image height.
        height: usize,
        /// Buffer length given.
        len: usize,
    },
}

/// `"line N: "` for errors that came from a file line, nothing for line 0 (a value from the
/// command line).
fn at_line(line: usize) -> String {
    if line > 0 {
        format!("line {line}: ")
    } else {
        String::new()
    }
}
