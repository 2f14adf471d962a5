//! Rectification of a sequence to a pinhole camera, with the photometric correction, as
//! `monovo rectify` runs it ([`rectify_sequence`]): the output is a new sequence folder that
//! monovo and DSO read (PNG frames, times.txt, camera.txt, and pcalib.txt and the rectified
//! vignette.png when the frames stay uncorrected).
//!
//! ```no_run
//! use monovo_pipelines::rectify::{rectify_sequence, RectifyJob};
//!
//! let job = RectifyJob {
//!     photometric: true,
//!     ..RectifyJob::new("sequence_01".into(), "sequence_01_rect".into())
//! };
//! let done = rectify_sequence(&job, &monovo_pipelines::Silent)?;
//! println!("{} frames at {:.0} frames/s", done.frames, done.fps);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use std::path::{Path, PathBuf};
use std::time::Instant;

use camera_model::{output_notes, CameraFile, Image, ImageSize, OutputMode, RectifyMap};
use dataset_io::{GrayImage, PngSpeed, Sequence, SequenceWriter, TimeRow};
use photometric::{quantize_u16, quantize_u8, Correction, InverseResponse, QuantizedCorrection};

use crate::{Observer, PipelineError, Result, WithContext};

/// What to rectify and how: see [`rectify_sequence`].
#[derive(Clone, Debug)]
pub struct RectifyJob {
    /// The sequence folder.
    pub sequence: PathBuf,
    /// The new sequence folder (must not exist unless `force`).
    pub output: PathBuf,
    /// The output pinhole camera (default: camera.txt line 3).
    pub pinhole: Option<OutputMode>,
    /// Output size (default: camera.txt line 4).
    pub size: Option<ImageSize>,
    /// Undo response and vignetting: `U(I) / V`.
    pub photometric: bool,
    /// Also divide by the exposure time (implies `photometric`).
    pub irradiance: bool,
    /// Mark pixels that touch a saturated input pixel as invalid (0), with `photometric`.
    pub mask_saturated: bool,
    /// Scale of the quantised photometric output (default: the largest without clipping;
    /// for 8-bit irradiance, from the data).
    pub scale: Option<f32>,
    /// Play backwards.
    pub reverse: bool,
    /// Frame range `A..B` (0-based, B exclusive; either end may be omitted).
    pub range: Option<String>,
    /// Bits per output pixel (8 or 16); default: the input's (16-bit frames stay 16-bit).
    pub depth: Option<u8>,
    /// The camera of a multi-camera dataset (`--cam N`, TUM-VI, EuRoC, 4Seasons, KITTI).
    pub cam: usize,
    /// A calibration file to use instead of the layout's own (`--calib FILE`).
    pub calibration: Option<PathBuf>,
    /// Write the frames into images.zip instead of images/.
    pub zip: bool,
    /// How the PNG frames are compressed.
    pub compression: FrameCompression,
    /// Replace an existing output.
    pub force: bool,
    /// Bits per pixel of 16-bit input frames (default: the table's depth with
    /// `photometric`, else 16).
    pub bit_depth: Option<u32>,
    /// Decode the JPEG frames at half their width and height in the DCT domain and rectify
    /// from those (the output must be at most half the input; see
    /// [`dataset_io::decode_jpeg_gray8_half`] and
    /// [`camera_model::RectifyMap::for_mode_half_input`]). Needs the `turbojpeg` feature.
    pub half_decode: bool,
}

impl RectifyJob {
    /// Rectifies `sequence` into `output` as camera.txt says, 8-bit, forwards.
    pub fn new(sequence: PathBuf, output: PathBuf) -> RectifyJob {
        RectifyJob {
            sequence,
            output,
            pinhole: None,
            size: None,
            photometric: false,
            irradiance: false,
            mask_saturated: false,
            scale: None,
            reverse: false,
            range: None,
            depth: None,
            cam: 0,
            calibration: None,
            zip: false,
            compression: FrameCompression::Fast,
            force: false,
            bit_depth: None,
            half_decode: false,
        }
    }
}

/// How `monovo rectify` compresses its PNG frames.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum FrameCompression {
    /// fdeflate with the Paeth filter: about half the raw size (a noisy 640x480 frame in
    /// about 140 KB), at about a quarter of the time of decoding a 1280x1024 JPEG.
    #[default]
    Fast,
    /// Stored: the raw size (300 KB at 640x480), nearly free to write and to read back.
    None,
}

impl FrameCompression {
    fn png(self) -> PngSpeed {
        match self {
            FrameCompression::Fast => PngSpeed::Fast,
            FrameCompression::None => PngSpeed::Stored,
        }
    }
}

impl std::str::FromStr for FrameCompression {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "fast" => Ok(FrameCompression::Fast),
            "none" => Ok(FrameCompression::None),
            _ => Err(format!("expected fast or none, found `{s}`")),
        }
    }
}

impl std::fmt::Display for FrameCompression {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            FrameCompression::Fast => "fast",
            FrameCompression::None => "none",
        })
    }
}

fn encode_error(e: impl std::fmt::Display) -> PipelineError {
    PipelineError::Invalid(format!("encoding a PNG frame: {e}"))
}

/// Parses `A..B`, `A..`, `..B` for a sequence of `len` frames.
pub fn parse_range(s: &str, len: usize) -> Result<std::ops::Range<usize>> {
    let Some((a, b)) = s.split_once("..") else {
        return Err(PipelineError::Invalid(format!(
            "--range: expected A..B (for example 100..500), found `{s}`"
        )));
    };
    let a: usize = if a.is_empty() {
        0
    } else {
        a.trim()
            .parse::<usize>()
            .with_context(|| format!("--range: `{a}` is not a frame number"))?
    };
    let b: usize = if b.is_empty() {
        len
    } else {
        b.trim()
            .parse::<usize>()
            .with_context(|| format!("--range: `{b}` is not a frame number"))?
    };
    if a >= b || a >= len {
        return Err(PipelineError::Invalid(format!(
            "--range {s}: empty for a sequence of {len} frames (0..{len})"
        )));
    }
    if b > len {
        return Err(PipelineError::Invalid(format!(
            "--range {s}: beyond the end of the sequence, which has {len} frames (0..{len})"
        )));
    }
    Ok(a..b)
}

enum Pixels {
    /// The frames remapped alone, by the job's map.
    Geometric(RectifyMap),
    /// The general float path (needed for saturation masking).
    Photometric(Box<Correction>, f32),
    /// The fused one-pass path.
    Fast(Box<QuantizedCorrection>, f32),
    /// 16-bit input frames: `U` applied exactly at their bit depth, then resampled.
    Deep(Box<Correction>, f32),
}

/// Scales a `bits`-bit sample value to the full range of `max` (8 or 16 bits out).
fn rescale_sample(v: u16, bits: u32, max: f32) -> u16 {
    let top = ((1u32 << bits) - 1) as f32;
    (v as f32 * max / top).round().clamp(0.0, max) as u16
}

/// What `monovo rectify` wrote.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Rectified {
    /// The new sequence folder.
    pub output: PathBuf,
    /// Frames written.
    pub frames: usize,
    /// Wall time in seconds.
    pub seconds: f64,
    /// Frames per second over the whole command.
    pub fps: f64,
    /// Output width.
    pub width: usize,
    /// Output height.
    pub height: usize,
    /// The output pinhole, pixels.
    pub fx: f64,
    /// The output pinhole, pixels.
    pub fy: f64,
    /// The output pinhole, pixels.
    pub cx: f64,
    /// The output pinhole, pixels.
    pub cy: f64,
    /// Output pixels without a source (0 in every frame).
    pub invalid_pixels: usize,
    /// Pixel value = scale * U(I) / V [/ exposure_ms] (photometric output only).
    pub photometric_scale: Option<f32>,
    /// Where the scale comes from.
    pub scale_source: Option<String>,
    /// The pixel value the scale maps, as a formula.
    pub pixel_value: Option<String>,
    /// Whether the frames were decoded at half size (`--half-decode`).
    pub half_decode: bool,
    /// The library that decodes JPEG frames in this build (`zune-jpeg` or `libjpeg-turbo`).
    pub jpeg_decoder: &'static str,
}

/// Number of frames sampled for the 8-bit irradiance scale.
const SCALE_SAMPLE_FRAMES: usize = 16;
/// The fraction of sampled irradiance values at or below the value that maps to 255.
const SCALE_QUANTILE: f64 = 0.999;

/// The scale of 8-bit irradiance output from the data: `max / q` with `q` the
/// [`SCALE_QUANTILE`] quantile of the valid corrected values of up to
/// [`SCALE_SAMPLE_FRAMES`] frames spread over `indices`. A worst-case bound (the brightest
/// value in the darkest vignette corner at the shortest exposure) leaves most frames a few
/// dozen grey levels; the quantile uses the range the frames actually have.
fn irradiance_scale(
    seq: &Sequence,
    indices: &[usize],
    half: bool,
    correct: &(dyn Fn(&dataset_io::NativeFrame) -> Result<Image<f32>> + Sync),
    max: f32,
) -> Result<Option<(f32, usize)>> {
    let n = indices.len().clamp(1, SCALE_SAMPLE_FRAMES);
    let picks: Vec<usize> = (0..n)
        .map(|i| indices[i * indices.len() / n])
        .collect::<std::collections::BTreeSet<_>>()
        .into_iter()
        .collect();
    let mut values: Vec<f32> = Vec::new();
    seq.process_scaled(
        &picks,
        picks.len(),
        half,
        |f| correct(&f),
        |img| {
            values.extend(img.data().iter().copied().filter(|v| v.is_finite()));
            Ok(())
        },
    )?;
    if values.is_empty() {
        return Ok(None);
    }
    let k = (((values.len() - 1) as f64) * SCALE_QUANTILE).round() as usize;
    let (_, q, _) = values.select_nth_unstable_by(k, f32::total_cmp);
    let q = *q;
    Ok((q.is_finite() && q > 0.0).then_some((max / q, picks.len())))
}

/// The vignette of the rectified frames: `v` remapped, as a 16-bit PNG with V = 1 at 65535
/// (65535 where the map has no source, whose frame pixels are 0, and never below 1 elsewhere,
/// so that nothing is divided by 0). Written with fdeflate: a 640x480 map takes 0.46 MB
/// instead of zlib's 0.19 MB, in a fifth of the time.
fn rectified_vignette(
    map: &RectifyMap,
    v: &photometric::Vignette,
    out_size: ImageSize,
) -> Result<Vec<u8>> {
    let rv = map.remap_f32(v.values())?;
    let v16: Vec<u16> = rv
        .data()
        .iter()
        .map(|x| {
            if x.is_nan() {
                65535
            } else {
                (x * 65535.0).round().clamp(1.0, 65535.0) as u16
            }
        })
        .collect();
    dataset_io::encode_png_u16(out_size.width, out_size.height, &v16, PngSpeed::Fast)
        .map_err(encode_error)
}

/// A sequence's `pcalib.txt`, read once: its text (copied as it is into a geometric output),
/// the inverse response and the parser's notes.
struct ResponseFile {
    path: PathBuf,
    text: String,
    response: InverseResponse,
    notes: Vec<String>,
}

/// The sequence's `pcalib.txt` and `vignette.png`, each when it has them; for frames decoded
/// at half size, the vignette averaged over the same 2x2 blocks.
fn read_calibration(
    seq: &Sequence,
    half: bool,
) -> Result<(Option<ResponseFile>, Option<photometric::Vignette>)> {
    let response = match &seq.pcalib_path {
        Some(p) => {
            let text = dataset_io::read_text(p)?;
            let (response, notes) = InverseResponse::parse_with_notes(&text)
                .with_context(|| p.display().to_string())?;
            Some(ResponseFile {
                path: p.clone(),
                text,
                response,
                notes,
            })
        }
        None => None,
    };
    let vignette = match &seq.vignette_path {
        Some(p) => {
            let v = crate::read_vignette(p, seq.image_size())?;
            Some(if half {
                v.half_size().with_context(|| p.display().to_string())?
            } else {
                v
            })
        }
        None => None,
    };
    Ok((response, vignette))
}

/// Rectifies (and photometrically corrects) a sequence into a new sequence folder, as
/// `monovo rectify` does: frames decoded in parallel and written in order, the output folder
/// complete or absent. Warnings and progress go to `observer`.
pub fn rectify_sequence(args: &RectifyJob, observer: &dyn Observer) -> Result<Rectified> {
    let bit_depth = args.bit_depth;
    let started = Instant::now();
    // the output location first: no work for an output that cannot be written
    dataset_io::OutputDir::check(&args.output, args.force)?;
    let photometric = args.photometric || args.irradiance;
    if !photometric {
        if args.scale.is_some() {
            return Err(PipelineError::Invalid(
                "--scale sets the scale of photometric output: add --photometric or --irradiance"
                    .into(),
            ));
        }
        if args.mask_saturated {
            return Err(PipelineError::Invalid(
                "--mask-saturated masks photometric output: add --photometric or --irradiance"
                    .into(),
            ));
        }
    }
    if let Some(s) = args.scale {
        if !(s.is_finite() && s > 0.0) {
            return Err(PipelineError::Invalid(format!(
                "--scale {s}: must be a positive number"
            )));
        }
    }
    let seq =
        Sequence::open_with_calibration(&args.sequence, args.cam, args.calibration.as_deref())?;
    for w in seq.times().warnings.iter().chain(&seq.layout_warnings) {
        observer.warn(w);
    }
    let Some(cam) = seq.camera() else {
        return Err(PipelineError::Invalid(format!(
            "{}: no camera.txt (or the {} layout's calibration file); rectify needs the camera model",
            args.sequence.display(),
            seq.layout().name()
        )));
    };
    let mode = args.pinhole.unwrap_or(cam.output);
    let out_size = args.size.unwrap_or(cam.output_size);
    let camera_path = seq
        .camera_path()
        .map_or_else(|| args.sequence.join("camera.txt"), Path::to_path_buf);
    for w in cam
        .warnings
        .iter()
        .chain(&output_notes(&cam.input, cam.input_size, &mode, out_size))
    {
        observer.warn(&format!("{}: {w}", camera_path.display()));
    }
    let in_bits = seq.bits_per_sample();
    let out_depth = args.depth.unwrap_or(if in_bits == 16 { 16 } else { 8 });
    let mut bits = bit_depth.unwrap_or(in_bits);
    if in_bits == 8 && bits != 8 {
        return Err(PipelineError::Invalid(format!(
            "--bit-depth {bits}: the frames of {} are 8-bit; --bit-depth describes 16-bit frames whose values use fewer bits",
            args.sequence.display()
        )));
    }
    let deep = in_bits == 16;
    let half = args.half_decode;
    if half {
        if !dataset_io::HALF_DECODE {
            return Err(PipelineError::Invalid(
                "--half-decode needs libjpeg-turbo: this monovo was built without it (build it with `cargo build --release -p monovo --features turbojpeg`, which needs cmake and nasm)".into(),
            ));
        }
        if deep {
            return Err(PipelineError::Invalid(format!(
                "--half-decode: the frames of {} are 16-bit; half-size decoding is for JPEG frames",
                args.sequence.display()
            )));
        }
        if args.mask_saturated {
            return Err(PipelineError::Invalid(
                "--half-decode with --mask-saturated: a half-size pixel averages 2x2 pixels, and which of them saturated is lost; drop one of the two".into(),
            ));
        }
    }
    // the map (its rows in parallel) and the photometric files (a serial PNG decode, about
    // as long as the map on two cores) at once: both come before the first frame
    let (map, calibration) = rayon::join(
        || {
            if half {
                RectifyMap::for_mode_half_input(&cam.input, cam.input_size, &mode, out_size)
            } else {
                RectifyMap::for_mode(&cam.input, cam.input_size, &mode, out_size)
            }
        },
        || read_calibration(&seq, half),
    );
    let map = map.with_context(|| {
        format!(
            "{}: output camera `{mode}` at {out_size}",
            camera_path.display()
        )
    })?;
    if mode == OutputMode::Crop && map.invalid_count() > 0 {
        observer.warn(&format!(
            "{}: `crop` at {out_size} leaves {} output pixels without a source (0 in every frame); a smaller --size or another --pinhole avoids them",
            camera_path.display(),
            map.invalid_count()
        ));
    }
    let k = map.camera();
    let invalid_pixels = map.invalid_count();
    let range = match &args.range {
        Some(r) => parse_range(r, seq.len())?,
        None => 0..seq.len(),
    };
    let indices = seq.indices(range, args.reverse);
    if args.irradiance {
        let times = seq.times();
        if let Some(&i) = indices
            .iter()
            .find(|&&i| !times.rows[i].exposure_ms.is_some_and(|e| e > 0.0))
        {
            return Err(PipelineError::Invalid(format!(
                "{}: line {}: the exposure of frame {i} ({}) is unknown (0 or missing); --irradiance divides by the exposure time of every frame",
                seq.times_path().display(),
                times.lines.get(i).copied().unwrap_or(i + 1),
                seq.names()[i]
            )));
        }
    } else if photometric {
        if let Some((i, line)) = seq.times().first_unknown_exposure() {
            observer.warn(&format!(
                "{}: line {line}: frame {i} has no known exposure; the photometric output keeps the exposure column as it is (--irradiance would refuse)",
                seq.times_path().display()
            ));
        }
    }
    let (pcalib, vignette) = calibration?;
    if let Some(f) = &pcalib {
        for n in &f.notes {
            observer.warn(&format!("{}: {n}", f.path.display()));
        }
    }
    let response = pcalib.as_ref().map(|f| &f.response);
    // 16-bit frames with a 2^k-value table (k < 16) and no --bit-depth: the values are k-bit
    // values in the low bits, as DSO and DM-VIO index the table (`G[pixel]`)
    if let (None, true, true, Some(r)) = (bit_depth, deep, photometric, &response) {
        if r.bits() < 16 {
            bits = r.bits();
        }
    }
    let max16 = if out_depth == 16 { 65535.0 } else { 255.0 };
    let mut scale_source = None;
    let pixels = if photometric {
        let Some(resp) = &response else {
            return Err(PipelineError::Invalid(format!(
                "{}: --photometric needs pcalib.txt (the inverse response)",
                args.sequence.display()
            )));
        };
        if vignette.is_none() {
            observer.warn(&format!(
                "{}: no vignette.png: undoing the response alone (V = 1); DSO refuses its photometric mode without a vignette",
                args.sequence.display()
            ));
        }
        let in_size = (map.input_size().width, map.input_size().height);
        // the float correction, made only where it is needed (16-bit frames,
        // --mask-saturated, the data's irradiance scale): the 8-bit frames of the others go
        // through the quantised one alone, and each costs a copy of the map and a remap of
        // the vignette before the first frame
        let float_correction = || -> Result<Correction> {
            let corr = Correction::new(
                resp,
                vignette.as_ref(),
                Some(map.clone()),
                in_size,
                args.mask_saturated,
            )?;
            Ok(if deep {
                corr.with_bit_depth(resp, bits, args.mask_saturated)?
            } else {
                corr
            })
        };
        let mut corr = None;
        // largest value: U(white) / (min V [* t_min]): nothing clips
        let t_min = if args.irradiance {
            seq.times().exposure_range().map_or(1.0, |r| r.0)
        } else {
            1.0
        };
        let v_min = vignette.as_ref().map_or(1.0, |v| v.min_positive());
        let max_value = resp.max_value() as f32 / (v_min * t_min as f32);
        let scale = match args.scale {
            Some(s) => {
                scale_source = Some("--scale".to_string());
                s
            }
            None if args.irradiance && out_depth == 8 => {
                let corr = corr.insert(float_correction()?);
                let (w, h) = (out_size.width, out_size.height);
                let sample = |f: &dataset_io::NativeFrame| -> Result<Image<f32>> {
                    let mut out = Image::filled(w, h, 0f32);
                    match &f.image {
                        GrayImage::U8(img) => corr.apply(img, f.exposure_ms, &mut out)?,
                        GrayImage::U16(img) => corr.apply_u16(img, f.exposure_ms, &mut out)?,
                    }
                    Ok(out)
                };
                match irradiance_scale(&seq, &indices, half, &sample, max16)? {
                    Some((s, n)) => {
                        scale_source = Some(format!(
                            "from the data: the {}th percentile of {n} sampled frames maps to {max16}",
                            SCALE_QUANTILE * 100.0
                        ));
                        s
                    }
                    None => {
                        scale_source = Some("no clipping (no valid sampled pixel)".to_string());
                        max16 / max_value
                    }
                }
            }
            None => {
                scale_source = Some("the largest without clipping".to_string());
                max16 / max_value
            }
        };
        if deep || args.mask_saturated {
            let corr = match corr {
                Some(c) => c,
                None => float_correction()?,
            };
            if deep {
                Pixels::Deep(Box::new(corr), scale)
            } else {
                Pixels::Photometric(Box::new(corr), scale)
            }
        } else {
            Pixels::Fast(
                Box::new(QuantizedCorrection::with_vignette(
                    resp,
                    vignette.as_ref(),
                    map,
                    scale,
                    out_depth,
                )?),
                scale,
            )
        }
    } else {
        Pixels::Geometric(map)
    };
    let scale = match &pixels {
        Pixels::Photometric(_, s) | Pixels::Fast(_, s) | Pixels::Deep(_, s) => Some(*s),
        Pixels::Geometric(_) => None,
    };
    let pixel_value = scale.map(|s| {
        if args.irradiance {
            format!("pixel value = {s} * U(I) / (V * exposure_ms)")
        } else {
            format!("pixel value = {s} * U(I) / V")
        }
    });
    let mut writer = SequenceWriter::create(&args.output, args.zip, args.force)?;
    if let (Some(f), Some(src)) = (&pixel_value, &scale_source) {
        writer.add_times_comment(&format!(
            "monovo rectify --{}: {f}; scale {src}{}",
            if args.irradiance {
                "irradiance"
            } else {
                "photometric"
            },
            if args.irradiance {
                "; the exposure column is 1"
            } else {
                ""
            }
        ));
    }
    writer.add_file(
        "camera.txt",
        CameraFile::rectified(k, out_size).to_text().as_bytes(),
    )?;
    if !photometric {
        if let Some(f) = &pcalib {
            writer.add_file("pcalib.txt", f.text.as_bytes())?;
        }
    }
    // the ground truth is indexed by timestamp: still valid unless the timestamps are mapped
    if let (Some(p), false) = (&seq.ground_truth_path, args.reverse) {
        writer.add_file("groundtruthSync.txt", dataset_io::read_text(p)?.as_bytes())?;
    }
    let ids: Vec<String> = (0..indices.len()).map(|i| format!("{i:05}")).collect();
    observer.begin(indices.len() as u64, "rectifying", "frames");
    let threads = rayon::current_num_threads();
    let mut done = 0usize;
    let depth = out_depth;
    let irradiance = args.irradiance;
    let reverse = args.reverse;
    let sample_max = (1u32 << bits) - 1;
    let speed = args.compression.png();
    let mut vignette_png = None;
    let work = |frame: dataset_io::NativeFrame| -> Result<OutFrame> {
        let (w, h) = (out_size.width, out_size.height);
        let label = || format!("frame {} ({})", frame.index, frame.name);
        if let GrayImage::U16(img) = &frame.image {
            if let Some(v) = img.data().iter().find(|v| **v as u32 > sample_max) {
                return Err(PipelineError::Invalid(format!(
                        "{}: pixel value {v} does not fit in --bit-depth {bits} (at most {sample_max}); are the values in the high bits? then the bit depth is 16",
                        label()
                    )));
            }
        }
        let png = match (&pixels, &frame.image) {
            (Pixels::Geometric(map), GrayImage::U8(img)) => {
                let out = map.remap_u8(img)?;
                if depth == 16 {
                    let wide: Vec<u16> = out.data().iter().map(|v| *v as u16 * 257).collect();
                    dataset_io::encode_png_u16(w, h, &wide, speed).map_err(encode_error)?
                } else {
                    dataset_io::encode_png_u8(w, h, 1, out.data(), speed).map_err(encode_error)?
                }
            }
            (Pixels::Geometric(map), GrayImage::U16(img)) => {
                let out = map.remap_u16(img)?;
                if depth == 16 {
                    // the values keep their bit depth
                    dataset_io::encode_png_u16(w, h, out.data(), speed).map_err(encode_error)?
                } else {
                    let narrow: Vec<u8> = out
                        .data()
                        .iter()
                        .map(|v| rescale_sample(*v, bits, 255.0) as u8)
                        .collect();
                    dataset_io::encode_png_u8(w, h, 1, &narrow, speed).map_err(encode_error)?
                }
            }
            (Pixels::Fast(c, _), GrayImage::U8(img)) => {
                let exposure = if irradiance { frame.exposure_ms } else { None };
                if depth == 16 {
                    let mut out = Image::filled(w, h, 0u16);
                    c.apply(img, exposure, &mut out).with_context(label)?;
                    dataset_io::encode_png_u16(w, h, out.data(), speed).map_err(encode_error)?
                } else {
                    let mut out = Image::filled(w, h, 0u8);
                    c.apply(img, exposure, &mut out).with_context(label)?;
                    dataset_io::encode_png_u8(w, h, 1, out.data(), speed).map_err(encode_error)?
                }
            }
            (Pixels::Photometric(c, scale), GrayImage::U8(img)) => {
                let mut out = Image::filled(w, h, 0f32);
                let exposure = if irradiance { frame.exposure_ms } else { None };
                c.apply(img, exposure, &mut out).with_context(label)?;
                encode_float(&out, *scale, depth, speed)?
            }
            (Pixels::Deep(c, scale), GrayImage::U16(img)) => {
                let mut out = Image::filled(w, h, 0f32);
                let exposure = if irradiance { frame.exposure_ms } else { None };
                c.apply_u16(img, exposure, &mut out).with_context(label)?;
                encode_float(&out, *scale, depth, speed)?
            }
            (_, image) => {
                return Err(PipelineError::Invalid(format!(
                    "{}: {}-bit frame in a {in_bits}-bit sequence",
                    label(),
                    image.bits()
                )))
            }
        };
        let t = if reverse {
            eval_metrics::BACKWARDS_EPOCH - frame.timestamp
        } else {
            frame.timestamp
        };
        // nanoseconds stay integers, mapped as the seconds are
        let ns = frame
            .timestamp_ns
            .map(|ns| if reverse { BACKWARDS_EPOCH_NS - ns } else { ns });
        let e = if irradiance {
            Some(1.0)
        } else {
            frame.exposure_ms
        };
        observer.advance(1);
        Ok((t, ns, e, png))
    };
    let sink = |(t, ns, e, png): OutFrame| -> Result<()> {
        writer.add_frame(
            TimeRow {
                id: ids[done].clone(),
                timestamp: t,
                exposure_ms: e,
                timestamp_ns: ns,
            },
            &png,
        )?;
        done += 1;
        Ok(())
    };
    let written = rayon::in_place_scope(|scope| {
        // the rectified vignette (geometric output only) is made by one of the pool's threads
        // while the other decodes the first frames, off the path to the first frame
        if let (Pixels::Geometric(map), Some(v)) = (&pixels, &vignette) {
            let slot = &mut vignette_png;
            scope.spawn(move |_| *slot = Some(rectified_vignette(map, v, out_size)));
        }
        seq.process_scaled(&indices, threads * 4, half, work, sink)
    });
    observer.finish();
    written?;
    if let Some(png) = vignette_png {
        writer.add_file("vignette.png", &png?)?;
    }
    let frames = writer.frames();
    let dir = writer.finish()?;
    let seconds = started.elapsed().as_secs_f64();
    Ok(Rectified {
        output: dir,
        frames,
        seconds,
        fps: frames as f64 / seconds.max(1e-9),
        width: out_size.width,
        height: out_size.height,
        fx: k.fx,
        fy: k.fy,
        cx: k.cx,
        cy: k.cy,
        invalid_pixels,
        photometric_scale: scale,
        scale_source,
        pixel_value,
        half_decode: half,
        jpeg_decoder: dataset_io::JPEG_DECODER,
    })
}

/// A rectified frame: timestamp (s, and ns when exact), exposure (ms), PNG bytes.
type OutFrame = (f64, Option<i64>, Option<f64>, Vec<u8>);

/// [`eval_metrics::BACKWARDS_EPOCH`] in nanoseconds.
const BACKWARDS_EPOCH_NS: i64 = 2_000_000_000_000_000_000;

/// Quantises a corrected float frame to 8 or 16 bits.
fn encode_float(out: &Image<f32>, scale: f32, depth: u8, speed: PngSpeed) -> Result<Vec<u8>> {
    let (w, h) = out.size();
    Ok(if depth == 16 {
        dataset_io::encode_png_u16(w, h, quantize_u16(out, scale).data(), speed)
            .map_err(encode_error)?
    } else {
        dataset_io::encode_png_u8(w, h, 1, quantize_u8(out, scale).data(), speed)
            .map_err(encode_error)?
    })
}
