//! The camera.txt text format of the benchmark and of DSO.
//!
//! ```text
//! FOV 0.535719308086809 0.669566858850269 0.493248545285398 0.500408664348414 0.897966326944875
//! 1280 1024
//! crop
//! 640 480
//! ```
//!
//! Line 1 is the input model: a DSO prefix (`FOV`, `Pinhole`, `RadTan`, `EquiDistant`,
//! `KannalaBrandt`) followed by `fx fy cx cy` and the distortion parameters, or a legacy line
//! of 5 numbers (FOV, a pinhole when omega is 0) or 8 numbers (RadTan). The values are
//! relative to the image size when `cx < 1 && cy < 1` (then `fx_px = fx * w` and
//! `cx_px = cx * w - 0.5`), else absolute pixels. Line 2 is the input size `w h`. Line 3 the
//! output camera: `crop`, `full`, `none` or an explicit pinhole `fx fy cx cy 0`. Line 4 the
//! output size. When lines 3 and 4 are both absent the output is `crop` at the input size.

use std::fmt;
use std::str::FromStr;

use crate::{CameraError, CameraModel, Intrinsics};

/// An image size in pixels.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct ImageSize {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
}

impl ImageSize {
    /// A size; use [`ImageSize::validate`] before building maps from it.
    pub fn new(width: usize, height: usize) -> Self {
        ImageSize { width, height }
    }

    /// Refuses sizes the bilinear remap cannot use (smaller than 2x2 or absurdly large).
    pub fn validate(self) -> Result<Self, CameraError> {
        let reason = if self.width < 2 || self.height < 2 {
            Some("both sides must be at least 2 pixels")
        } else if self.width > 1 << 16 || self.height > 1 << 16 {
            Some("sides above 65536 pixels are not supported")
        } else {
            None
        };
        match reason {
            Some(reason) => Err(CameraError::InvalidSize {
                width: self.width,
                height: self.height,
                reason,
            }),
            None => Ok(self),
        }
    }

    /// Number of pixels.
    pub fn pixels(self) -> usize {
        self.width * self.height
    }
}

impl fmt::Display for ImageSize {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}x{}", self.width, self.height)
    }
}

impl FromStr for ImageSize {
    type Err = CameraError;

    /// Parses `640x480` (also `640X480` or `640 480`).
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let bad = || CameraError::Parse {
            line: 0,
            expected: "an image size WIDTHxHEIGHT such as 640x480".into(),
            found: s.trim().into(),
        };
        let t = s.trim();
        let parts: Vec<&str> = t
            .split(|c: char| c == 'x' || c == 'X' || c.is_whitespace())
            .filter(|p| !p.is_empty())
            .collect();
        if parts.len() != 2 {
            return Err(bad());
        }
        let w = parts[0].parse::<usize>().map_err(|_| bad())?;
        let h = parts[1].parse::<usize>().map_err(|_| bad())?;
        ImageSize::new(w, h).validate()
    }
}

/// The output camera requested on line 3 of camera.txt.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum OutputMode {
    /// The largest pinhole view without invalid pixels.
    Crop,
    /// A pinhole view that keeps the whole input field of view.
    Full,
    /// Keep the input camera (pinhole inputs only), rescaled to the output size.
    None,
    /// An explicit pinhole `fx fy cx cy`, relative to the output size when `cx < 1 && cy < 1`,
    /// else in pixels.
    Pinhole([f64; 4]),
}

impl fmt::Display for OutputMode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            OutputMode::Crop => f.write_str("crop"),
            OutputMode::Full => f.write_str("full"),
            OutputMode::None => f.write_str("none"),
            OutputMode::Pinhole(p) => write!(f, "{} {} {} {} 0", p[0], p[1], p[2], p[3]),
        }
    }
}

impl FromStr for OutputMode {
    type Err = CameraError;

    /// Parses `crop`, `full`, `none` or `fx fy cx cy 0`.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        parse_output_line(s, 0)
    }
}

fn parse_output_line(s: &str, line: usize) -> Result<OutputMode, CameraError> {
    let t = s.trim();
    match t.to_ascii_lowercase().as_str() {
        "crop" => return Ok(OutputMode::Crop),
        "full" => return Ok(OutputMode::Full),
        "none" => return Ok(OutputMode::None),
        _ => {}
    }
    let expected = "`crop`, `full`, `none` or an explicit pinhole `fx fy cx cy 0`";
    let nums = parse_numbers(t, line, expected)?;
    if !(nums.len() == 4 || (nums.len() == 5 && nums[4] == 0.0)) {
        return Err(CameraError::Parse {
            line,
            expected: expected.into(),
            found: t.into(),
        });
    }
    if nums[0] <= 0.0 || nums[1] <= 0.0 {
        return Err(CameraError::InvalidValue {
            line,
            message: format!(
                "output focal lengths must be positive, got fx={} fy={}",
                nums[0], nums[1]
            ),
        });
    }
    Ok(OutputMode::Pinhole([nums[0], nums[1], nums[2], nums[3]]))
}

fn parse_numbers(t: &str, line: usize, expected: &str) -> Result<Vec<f64>, CameraError> {
    t.split_whitespace()
        .map(|tok| {
            let v = tok.parse::<f64>().map_err(|_| CameraError::Parse {
                line,
                expected: expected.into(),
                found: t.into(),
            })?;
            if v.is_finite() {
                Ok(v)
            } else {
                Err(CameraError::InvalidValue {
                    line,
                    message: format!("`{tok}` is not a finite number"),
                })
            }
        })
        .collect()
}

fn parse_size_line(t: &str, line: usize, what: &str) -> Result<ImageSize, CameraError> {
    let expected = format!("the {what} image size `width height` (two positive integers)");
    let parts: Vec<&str> = t.split_whitespace().collect();
    let bad = || CameraError::Parse {
        line,
        expected: expected.clone(),
        found: t.trim().into(),
    };
    if parts.len() != 2 {
        return Err(bad());
    }
    let w = parts[0].parse::<usize>().map_err(|_| bad())?;
    let h = parts[1].parse::<usize>().map_err(|_| bad())?;
    ImageSize::new(w, h)
        .validate()
        .map_err(|e| CameraError::InvalidValue {
            line,
            message: e.to_string(),
        })
}

/// Converts `fx fy cx cy` as written in a file to pixels: relative values (`cx < 1 && cy < 1`)
/// are scaled by the image size and shifted so that pixel centres sit at integers.
pub fn intrinsics_from_file_values(v: [f64; 4], size: ImageSize) -> Intrinsics {
    if v[2] < 1.0 && v[3] < 1.0 {
        let (w, h) = (size.width as f64, size.height as f64);
        Intrinsics {
            fx: v[0] * w,
            fy: v[1] * h,
            cx: v[2] * w - 0.5,
            cy: v[3] * h - 0.5,
        }
    } else {
        Intrinsics {
            fx: v[0],
            fy: v[1],
            cx: v[2],
            cy: v[3],
        }
    }
}

/// Converts pixel intrinsics to the relative values written in files (the inverse of
/// [`intrinsics_from_file_values`]); falls back to pixels when the principal point lies
/// outside the image, where the relative form would be misread.
pub fn intrinsics_to_file_values(k: &Intrinsics, size: ImageSize) -> [f64; 4] {
    let (w, h) = (size.width as f64, size.height as f64);
    let rel = [k.fx / w, k.fy / h, (k.cx + 0.5) / w, (k.cy + 0.5) / h];
    if rel[2] < 1.0 && rel[3] < 1.0 && k.cx >= 1.0 && k.cy >= 1.0 {
        rel
    } else {
        [k.fx, k.fy, k.cx, k.cy]
    }
}

/// A parsed camera.txt: the input camera and the requested output pinhole.
#[derive(Clone, Debug, PartialEq)]
pub struct CameraFile {
    /// The input camera, in pixels of `input_size`.
    pub input: CameraModel,
    /// The raw image size (line 2).
    pub input_size: ImageSize,
    /// The requested output camera (line 3).
    pub output: OutputMode,
    /// The output image size (line 4).
    pub output_size: ImageSize,
}

const MODEL_EXPECTED: &str = "a camera model: `FOV`, `Pinhole`, `RadTan`, `EquiDistant` or `KannalaBrandt` followed by `fx fy cx cy` and its parameters, or a legacy line of 5 (FOV) or 8 (RadTan) numbers";

impl CameraFile {
    /// Parses the text of a camera.txt file. Locale independent; every number must be finite.
    pub fn parse(text: &str) -> Result<CameraFile, CameraError> {
        let lines: Vec<&str> = text.lines().collect();
        // Trailing blank lines are fine; anything after line 4 is not.
        let last = lines
            .iter()
            .rposition(|l| !l.trim().is_empty())
            .map_or(0, |i| i + 1);
        if last == 0 {
            return Err(CameraError::Parse {
                line: 1,
                expected: MODEL_EXPECTED.into(),
                found: String::new(),
            });
        }
        if last > 4 {
            return Err(CameraError::Parse {
                line: 5,
                expected: "the end of the file (camera.txt has 4 lines)".into(),
                found: lines[4].trim().into(),
            });
        }
        let line_at = |i: usize| lines.get(i).map(|l| l.trim()).unwrap_or("");
        if last < 2 {
            return Err(CameraError::Parse {
                line: 2,
                expected: "the input image size `width height`".into(),
                found: String::new(),
            });
        }
        let input_size = parse_size_line(line_at(1), 2, "input")?;
        let input = parse_model_line(line_at(0), 1, input_size)?;
        let (output, output_size) = match last {
            2 => (OutputMode::Crop, input_size),
            3 => {
                return Err(CameraError::Parse {
                    line: 4,
                    expected: "the output image size `width height`".into(),
                    found: String::new(),
                })
            }
            _ => (
                parse_output_line(line_at(2), 3)?,
                parse_size_line(line_at(3), 4, "output")?,
            ),
        };
        Ok(CameraFile {
            input,
            input_size,
            output,
            output_size,
        })
    }

    /// The text of this file, readable by monovo and by DSO: the input model with its DSO
    /// prefix and relative intrinsics, full precision.
    pub fn to_text(&self) -> String {
        let v = intrinsics_to_file_values(&self.input.intrinsics(), self.input_size);
        let mut line1 = format!("{} {} {} {} {}", self.input.name(), v[0], v[1], v[2], v[3]);
        for p in self.input.distortion() {
            line1.push_str(&format!(" {p}"));
        }
        format!(
            "{line1}\n{} {}\n{}\n{} {}\n",
            self.input_size.width,
            self.input_size.height,
            self.output,
            self.output_size.width,
            self.output_size.height
        )
    }

    /// A camera.txt for an already rectified pinhole sequence: the pinhole as input, `none` as
    /// output, same size. This is what DSO expects next to rectified images.
    pub fn rectified(k: Intrinsics, size: ImageSize) -> CameraFile {
        CameraFile {
            input: CameraModel::Pinhole(k),
            input_size: size,
            output: OutputMode::None,
            output_size: size,
        }
    }
}

impl FromStr for CameraFile {
    type Err = CameraError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        CameraFile::parse(s)
    }
}

fn parse_model_line(t: &str, line: usize, size: ImageSize) -> Result<CameraModel, CameraError> {
    let mut toks = t.split_whitespace();
    let first = toks.next().ok_or_else(|| CameraError::Parse {
        line,
        expected: MODEL_EXPECTED.into(),
        found: t.into(),
    })?;
    let prefix = if first.parse::<f64>().is_ok()
        || first.eq_ignore_ascii_case("nan")
        || first.eq_ignore_ascii_case("inf")
    {
        None
    } else {
        Some(first)
    };
    let rest = match prefix {
        Some(p) => t[t.find(p).map_or(0, |i| i + p.len())..].trim(),
        None => t,
    };
    let nums = parse_numbers(rest, line, MODEL_EXPECTED)?;
    let count_error = |name: &str, want: &str| CameraError::Parse {
        line,
        expected: format!("{name} followed by {want} numbers"),
        found: t.into(),
    };
    let kind = match prefix {
        Some(p) => match p.to_ascii_lowercase().as_str() {
            "fov" => {
                if nums.len() != 5 {
                    return Err(count_error("FOV", "5 (fx fy cx cy omega)"));
                }
                "FOV"
            }
            "pinhole" => {
                if !(nums.len() == 4 || (nums.len() == 5 && nums[4] == 0.0)) {
                    return Err(count_error("Pinhole", "4 or 5 (fx fy cx cy 0)"));
                }
                "Pinhole"
            }
            "radtan" => {
                if nums.len() != 8 {
                    return Err(count_error("RadTan", "8 (fx fy cx cy k1 k2 p1 p2)"));
                }
                "RadTan"
            }
            "equidistant" => {
                if nums.len() != 8 {
                    return Err(count_error("EquiDistant", "8 (fx fy cx cy k1 k2 k3 k4)"));
                }
                "EquiDistant"
            }
            "kannalabrandt" => {
                if nums.len() != 8 {
                    return Err(count_error("KannalaBrandt", "8 (fx fy cx cy k0 k1 k2 k3)"));
                }
                "KannalaBrandt"
            }
            _ => {
                return Err(CameraError::Parse {
                    line,
                    expected: MODEL_EXPECTED.into(),
                    found: t.into(),
                })
            }
        },
        None => match nums.len() {
            5 => "FOV",
            8 => "RadTan",
            _ => {
                return Err(CameraError::Parse {
                    line,
                    expected: MODEL_EXPECTED.into(),
                    found: t.into(),
                })
            }
        },
    };
    if nums[0] <= 0.0 || nums[1] <= 0.0 {
        return Err(CameraError::InvalidValue {
            line,
            message: format!(
                "focal lengths must be positive, got fx={} fy={}",
                nums[0], nums[1]
            ),
        });
    }
    let k = intrinsics_from_file_values([nums[0], nums[1], nums[2], nums[3]], size);
    let p = |i: usize| nums.get(i).copied().unwrap_or(0.0);
    let model = match kind {
        "FOV" => {
            let omega = p(4);
            if !(0.0..std::f64::consts::PI).contains(&omega) {
                return Err(CameraError::InvalidValue {
                    line,
                    message: format!("FOV omega must be in [0, pi) radians, got {omega}"),
                });
            }
            if omega == 0.0 {
                CameraModel::Pinhole(k)
            } else {
                CameraModel::Fov { k, omega }
            }
        }
        "Pinhole" => CameraModel::Pinhole(k),
        "RadTan" => CameraModel::RadTan {
            k,
            coeffs: [p(4), p(5), p(6), p(7)],
        },
        "EquiDistant" => CameraModel::EquiDistant {
            k,
            coeffs: [p(4), p(5), p(6), p(7)],
        },
        _ => CameraModel::KannalaBrandt {
            k,
            coeffs: [p(4), p(5), p(6), p(7)],
        },
    };
    Ok(model)
}
