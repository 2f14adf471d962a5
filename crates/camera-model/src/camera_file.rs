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
//!
//! The file is read as DSO reads it (`src/util/Undistort.cpp`): lines after line 4 are
//! ignored (stereo forks put a baseline there), numbers are read like C's `sscanf` (a model
//! name followed by more numbers than it needs uses the first ones, a legacy line of 6 or 7
//! numbers is FOV by its 5th), and `none` passes the raw image through. Where DSO crashes or
//! is undefined (CRLF on line 3, 9 numbers on a RadTan line, a missing line 4) monovo reads
//! the sensible thing or says what is wrong; [`CameraFile::warnings`] lists every difference
//! from a plain 4-line file.

use std::fmt;
use std::str::FromStr;

use crate::{CameraError, CameraModel, Intrinsics};

/// An image size in pixels.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
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
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
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
    parse_output_line_noted(s, line, &mut Vec::new())
}

/// Line 3: `crop`, `full`, `none` (any case, surrounding blanks and a CR allowed) or an
/// explicit pinhole. DSO reads 5 numbers and ignores the 5th and anything after it; monovo
/// does the same, also accepts 4 numbers, and notes what it ignored.
fn parse_output_line_noted(
    s: &str,
    line: usize,
    notes: &mut Vec<String>,
) -> Result<OutputMode, CameraError> {
    let t = s.trim();
    match t.to_ascii_lowercase().as_str() {
        "crop" => return Ok(OutputMode::Crop),
        "full" => return Ok(OutputMode::Full),
        "none" => return Ok(OutputMode::None),
        _ => {}
    }
    let expected = "`crop`, `full`, `none` or an explicit pinhole `fx fy cx cy 0`";
    let scan = scan_numbers(t, line, t)?;
    let nums = &scan.values;
    if nums.len() < 4 {
        return Err(CameraError::Parse {
            line,
            expected: expected.into(),
            found: t.into(),
        });
    }
    check_finite(&nums[..nums.len().min(5)], line)?;
    if nums.len() >= 5 && nums[4] != 0.0 {
        notes.push(format!(
            "line {line}: the 5th number of the output pinhole ({}) is ignored, as DSO ignores it",
            nums[4]
        ));
    }
    if nums.len() > 5 || !scan.rest.is_empty() {
        notes.push(format!(
            "line {line}: `{}` after `fx fy cx cy 0` is ignored, as DSO ignores it",
            scan.after(5)
        ));
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

/// The numbers at the start of a text as C's `sscanf("%f %f ...")` reads them: white-space
/// separated, reading stops at the first token that is not a number; a token with a number
/// followed by other characters (`-0.11,`) gives its number and stops the reading. A decimal
/// comma (`0,5`) is an error rather than a silent 0.
struct Scan<'a> {
    values: Vec<f64>,
    /// Tokens of each value, to quote what was ignored.
    tokens: Vec<&'a str>,
    /// What follows the last value read (trimmed; empty when the line ended).
    rest: &'a str,
}

impl Scan<'_> {
    /// The text after the first `n` values (values and the unread rest), for messages.
    fn after(&self, n: usize) -> String {
        let mut parts: Vec<&str> = self.tokens.iter().skip(n).copied().collect();
        if !self.rest.is_empty() {
            parts.push(self.rest);
        }
        parts.join(" ")
    }
}

/// Length of the longest prefix of `tok` that C's `strtod` would read as a decimal number.
fn numeric_prefix_len(tok: &str) -> usize {
    let b = tok.as_bytes();
    let mut i = 0;
    if i < b.len() && (b[i] == b'+' || b[i] == b'-') {
        i += 1;
    }
    let int_start = i;
    while i < b.len() && b[i].is_ascii_digit() {
        i += 1;
    }
    let mut digits = i - int_start;
    if i < b.len() && b[i] == b'.' {
        let frac_start = i + 1;
        let mut j = frac_start;
        while j < b.len() && b[j].is_ascii_digit() {
            j += 1;
        }
        digits += j - frac_start;
        if digits > 0 {
            i = j;
        }
    }
    if digits == 0 {
        return 0;
    }
    if i < b.len() && (b[i] == b'e' || b[i] == b'E') {
        let mut j = i + 1;
        if j < b.len() && (b[j] == b'+' || b[j] == b'-') {
            j += 1;
        }
        let exp_start = j;
        while j < b.len() && b[j].is_ascii_digit() {
            j += 1;
        }
        if j > exp_start {
            i = j;
        }
    }
    i
}

fn scan_numbers<'a>(text: &'a str, line: usize, whole: &str) -> Result<Scan<'a>, CameraError> {
    let mut values = Vec::new();
    let mut tokens = Vec::new();
    let mut rest = text.trim_start();
    while !rest.is_empty() {
        let end = rest.find(char::is_whitespace).unwrap_or(rest.len());
        let tok = &rest[..end];
        if let Ok(v) = tok.parse::<f64>() {
            values.push(v);
            tokens.push(tok);
            rest = rest[end..].trim_start();
            continue;
        }
        let n = numeric_prefix_len(tok);
        let tail = &tok[n..];
        if n > 0 && tail.starts_with(',') && tail[1..].starts_with(|c: char| c.is_ascii_digit()) {
            return Err(CameraError::DecimalComma {
                line,
                token: tok.into(),
                text: whole.trim().into(),
            });
        }
        if n > 0 {
            if let Ok(v) = tok[..n].parse::<f64>() {
                values.push(v);
                tokens.push(&tok[..n]);
                rest = rest[n..].trim();
            }
        }
        break;
    }
    Ok(Scan {
        values,
        tokens,
        rest: rest.trim(),
    })
}

fn check_finite(values: &[f64], line: usize) -> Result<(), CameraError> {
    match values.iter().find(|v| !v.is_finite()) {
        Some(v) => Err(CameraError::InvalidValue {
            line,
            message: format!("`{v}` is not a finite number"),
        }),
        None => Ok(()),
    }
}

/// Line 2 or 4: `width height`. DSO reads two integers (`%d %d`) and ignores what follows;
/// so does monovo, with a note.
fn parse_size_line(
    t: &str,
    line: usize,
    what: &str,
    notes: &mut Vec<String>,
) -> Result<ImageSize, CameraError> {
    let t = t.trim();
    let expected = format!("the {what} image size `width height` (two positive integers)");
    let parts: Vec<&str> = t.split_whitespace().collect();
    let bad = || CameraError::Parse {
        line,
        expected: expected.clone(),
        found: t.into(),
    };
    if parts.len() < 2 {
        return Err(bad());
    }
    let w = parts[0].parse::<usize>().map_err(|_| bad())?;
    let h = parts[1].parse::<usize>().map_err(|_| bad())?;
    if parts.len() > 2 {
        notes.push(format!(
            "line {line}: `{}` after the {what} size is ignored, as DSO ignores it",
            parts[2..].join(" ")
        ));
    }
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
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CameraFile {
    /// The input camera, in pixels of `input_size`.
    pub input: CameraModel,
    /// The raw image size (line 2).
    pub input_size: ImageSize,
    /// The requested output camera (line 3).
    pub output: OutputMode,
    /// The output image size (line 4).
    pub output_size: ImageSize,
    /// Non-blank lines after line 4, which DSO never reads (stereo baselines, a second
    /// camera, comments): 1-based line number and text.
    pub ignored_lines: Vec<(usize, String)>,
    /// What was read differently from a plain 4-line file (ignored numbers, a byte-order
    /// mark, a negative FOV omega, ...), one sentence each starting with the line number.
    pub warnings: Vec<String>,
}

const MODEL_EXPECTED: &str = "a camera model: `FOV`, `Pinhole`, `RadTan`, `EquiDistant` or `KannalaBrandt` followed by `fx fy cx cy` and its parameters, or a legacy line of 5 (FOV) or 8 (RadTan) numbers";

impl CameraFile {
    /// Parses the text of a camera.txt file exactly as DSO reads it: the model on line 1
    /// (DSO's prefixes and legacy number lines, numbers read like C's `sscanf`), the sizes on
    /// lines 2 and 4, the output on line 3; lines after line 4 are ignored (listed in
    /// [`CameraFile::ignored_lines`]). Beyond DSO: a UTF-8 byte-order mark, CRLF line ends,
    /// blanks around keywords and any case of `crop`/`full`/`none` are accepted, numbers must
    /// be finite, and a file of only lines 1-2 means `crop` at the input size. Everything read
    /// differently from a plain file is noted in [`CameraFile::warnings`].
    pub fn parse(text: &str) -> Result<CameraFile, CameraError> {
        let mut warnings = Vec::new();
        let text = match text.strip_prefix('\u{feff}') {
            Some(t) => {
                warnings.push(
                    "line 1: a UTF-8 byte-order mark starts the file; monovo skips it, DSO cannot read such a file".to_string(),
                );
                t
            }
            None => text,
        };
        let lines: Vec<&str> = text.lines().collect();
        let line_at = |i: usize| lines.get(i).map(|l| l.trim()).unwrap_or("");
        let ignored_lines: Vec<(usize, String)> = lines
            .iter()
            .enumerate()
            .skip(4)
            .filter(|(_, l)| !l.trim().is_empty())
            .map(|(i, l)| (i + 1, l.trim().to_string()))
            .collect();
        if line_at(0).is_empty() {
            return Err(CameraError::Parse {
                line: 1,
                expected: MODEL_EXPECTED.into(),
                found: String::new(),
            });
        }
        if line_at(1).is_empty() {
            return Err(CameraError::Parse {
                line: 2,
                expected: "the input image size `width height`".into(),
                found: String::new(),
            });
        }
        let input_size = parse_size_line(line_at(1), 2, "input", &mut warnings)?;
        let input = parse_model_line(lines[0], 1, input_size, &mut warnings)?;
        let (output, output_size) = match (line_at(2).is_empty(), line_at(3).is_empty()) {
            (true, true) => (OutputMode::Crop, input_size),
            (true, false) => {
                return Err(CameraError::Parse {
                    line: 3,
                    expected: "the output camera: `crop`, `full`, `none` or `fx fy cx cy 0`".into(),
                    found: String::new(),
                })
            }
            (false, true) => {
                return Err(CameraError::Parse {
                    line: 4,
                    expected: "the output image size `width height`".into(),
                    found: String::new(),
                })
            }
            (false, false) => (
                parse_output_line_noted(line_at(2), 3, &mut warnings)?,
                parse_size_line(line_at(3), 4, "output", &mut warnings)?,
            ),
        };
        if let Some((first, _)) = ignored_lines.first() {
            let last = ignored_lines.last().map_or(*first, |l| l.0);
            let which = if last == *first {
                format!("line {first} is")
            } else {
                format!("lines {first}-{last} are")
            };
            warnings.push(format!(
                "{which} ignored: DSO reads only lines 1-4 of camera.txt"
            ));
        }
        Ok(CameraFile {
            input,
            input_size,
            output,
            output_size,
            ignored_lines,
            warnings,
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
            ignored_lines: Vec::new(),
            warnings: Vec::new(),
        }
    }
}

impl FromStr for CameraFile {
    type Err = CameraError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        CameraFile::parse(s)
    }
}

/// The model names DSO recognises, with their number of parameters after `fx fy cx cy`.
const MODELS: [(&str, usize); 8] = [
    ("KannalaBrandt", 4),
    ("DoubleSphere", 2),
    ("EUCM", 2),
    ("Omni", 5),
    ("RadTan", 4),
    ("EquiDistant", 4),
    ("FOV", 1),
    ("Pinhole", 1),
];

/// Line 1, as DSO reads it: a legacy line of 8 or more numbers is RadTan, of 5 to 7 numbers
/// FOV (a pinhole when the 5th is 0); else a model name followed by at least its number of
/// values. Numbers beyond those DSO reads are ignored with a note, except on 8-parameter
/// models, where DSO's behaviour is undefined: there extra numbers must be 0 (a zero `k3`).
fn parse_model_line(
    raw: &str,
    line: usize,
    size: ImageSize,
    notes: &mut Vec<String>,
) -> Result<CameraModel, CameraError> {
    let t = raw.trim();
    let named = MODELS.iter().find_map(|&(name, n)| {
        let head = t.get(..name.len())?;
        head.eq_ignore_ascii_case(name).then_some((name, n, head))
    });
    if named.is_some() && raw.starts_with(char::is_whitespace) {
        notes.push(format!(
            "line {line}: blanks before the model name are skipped; DSO cannot read such a line"
        ));
    }
    let (name, n_dist, values) = match named {
        Some((name, n, head)) => {
            if head != name {
                notes.push(format!(
                    "line {line}: `{head}` read as `{name}`; DSO needs exactly `{name}`"
                ));
            }
            let scan = scan_numbers(&t[name.len()..], line, t)?;
            (name, n, scan)
        }
        None => {
            let scan = scan_numbers(t, line, t)?;
            match scan.values.len() {
                n if n >= 8 => ("RadTan", 4, scan),
                5..=7 => ("FOV", 1, scan),
                _ => {
                    return Err(CameraError::Parse {
                        line,
                        expected: MODEL_EXPECTED.into(),
                        found: t.into(),
                    })
                }
            }
        }
    };
    let want = 4 + n_dist;
    let nums = &values.values;
    if nums.len() < want {
        let what = match name {
            "FOV" => "5 numbers `fx fy cx cy omega`",
            "Pinhole" => "5 numbers `fx fy cx cy 0` (DSO refuses 4)",
            "RadTan" => "8 numbers `fx fy cx cy k1 k2 p1 p2`",
            "EquiDistant" => "8 numbers `fx fy cx cy k1 k2 k3 k4`",
            "DoubleSphere" => "6 numbers `fx fy cx cy xi alpha`",
            "EUCM" => "6 numbers `fx fy cx cy alpha beta`",
            "Omni" => "9 numbers `fx fy cx cy xi k1 k2 p1 p2`",
            _ => "8 numbers `fx fy cx cy k0 k1 k2 k3`",
        };
        return Err(CameraError::Parse {
            line,
            expected: format!("{name} followed by {what}"),
            found: t.into(),
        });
    }
    check_finite(&nums[..want], line)?;
    if nums.len() > want || !values.rest.is_empty() {
        let extra = &nums[want..];
        if n_dist == 4 && !extra.is_empty() {
            // DSO's reader has 10 conversions for 8 destinations here: undefined behaviour.
            if extra.iter().any(|v| *v != 0.0) || !values.rest.is_empty() {
                return Err(CameraError::Parse {
                    line,
                    expected: format!(
                        "exactly 8 numbers for {name} (DSO's behaviour with more is undefined; a 5th distortion coefficient like k3 = {} cannot be represented)",
                        values.after(want)
                    ),
                    found: t.into(),
                });
            }
            notes.push(format!(
                "line {line}: the zero(s) `{}` after the 8 numbers of {name} are ignored (DSO's behaviour with more than 8 numbers is undefined)",
                values.after(want)
            ));
        } else {
            notes.push(format!(
                "line {line}: `{}` after the {want} numbers of {name} is ignored, as DSO ignores it",
                values.after(want)
            ));
        }
    }
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
    let model = model_of(name, k, nums, line, notes)?;
    if let Some(message) = model.parameter_problem() {
        return Err(CameraError::InvalidValue { line, message });
    }
    if matches!(name, "DoubleSphere" | "EUCM" | "Omni") {
        notes.push(format!(
            "line {line}: `{name}` is monovo's extension of camera.txt; DSO cannot read it"
        ));
    }
    Ok(model)
}

/// The model `name` with intrinsics `k` and the parameters `nums[4..]` of line `line`.
fn model_of(
    name: &str,
    k: Intrinsics,
    nums: &[f64],
    line: usize,
    notes: &mut Vec<String>,
) -> Result<CameraModel, CameraError> {
    let p = |i: usize| nums[i];
    Ok(match name {
        "FOV" => {
            let mut omega = p(4);
            if omega < 0.0 {
                notes.push(format!(
                    "line {line}: FOV omega {omega} is negative; the FOV model is even in omega, so it acts as {} (as in DSO)",
                    -omega
                ));
                omega = -omega;
            }
            if omega >= std::f64::consts::PI {
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
        "Pinhole" => {
            if p(4) != 0.0 {
                notes.push(format!(
                    "line {line}: the 5th number of Pinhole ({}) is ignored, as DSO ignores it",
                    p(4)
                ));
            }
            CameraModel::Pinhole(k)
        }
        "RadTan" => CameraModel::RadTan {
            k,
            coeffs: [p(4), p(5), p(6), p(7)],
        },
        "EquiDistant" => CameraModel::EquiDistant {
            k,
            coeffs: [p(4), p(5), p(6), p(7)],
        },
        "DoubleSphere" => CameraModel::DoubleSphere {
            k,
            xi: p(4),
            alpha: p(5),
        },
        "EUCM" => CameraModel::Eucm {
            k,
            alpha: p(4),
            beta: p(5),
        },
        "Omni" => CameraModel::Unified {
            k,
            xi: p(4),
            coeffs: [p(5), p(6), p(7), p(8)],
        },
        _ => CameraModel::KannalaBrandt {
            k,
            coeffs: [p(4), p(5), p(6), p(7)],
        },
    })
}
