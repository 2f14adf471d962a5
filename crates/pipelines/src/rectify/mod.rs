//! Rectification of a sequence to a pinhole camera, with the photometric correction, as
//! `monovo rectify` runs it ([`rectify_sequence`]): the output is a new sequence folder that
//! monovo and DSO read (PNG frames, times.txt, camera.txt, and pcalib.txt and the rectified
//! vignette.png when the frames stay uncorrected). Reading the sequence and refusing what
//! cannot work (`input`), the map and the correction it carries (`pixels`), the frame
//! pipeline (`frames`) and the other files of the output (`output`).
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

mod frames;
mod input;
mod output;
mod pixels;

use std::path::PathBuf;
use std::time::Instant;

use camera_model::{ImageSize, OutputMode, RectifyMap};
use dataset_io::{PngSpeed, TimeRow};

use self::frames::{FramePipeline, OutFrame};
use self::input::Input;
use self::pixels::{Calibration, Pixels};
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

/// Rectifies (and photometrically corrects) a sequence into a new sequence folder, as
/// `monovo rectify` does: frames decoded in parallel and written in order, the output folder
/// complete or absent. Warnings and progress go to `observer`.
pub fn rectify_sequence(args: &RectifyJob, observer: &dyn Observer) -> Result<Rectified> {
    let started = Instant::now();
    // the output location first: no work for an output that cannot be written
    dataset_io::OutputDir::check(&args.output, args.force)?;
    input::check_options(args)?;
    let mut input = Input::open(args, observer)?;
    let (mode, out_size, half) = (input.mode, input.out_size, args.half_decode);
    let cam = &input.cam;
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
        || input::read_calibration(&input.seq, half),
    );
    let camera_path = input.camera_path.display().to_string();
    let map =
        map.with_context(|| format!("{camera_path}: output camera `{mode}` at {out_size}"))?;
    if mode == OutputMode::Crop && map.invalid_count() > 0 {
        observer.warn(&format!(
            "{camera_path}: `crop` at {out_size} leaves {} output pixels without a source (0 in every frame); a smaller --size or another --pinhole avoids them",
            map.invalid_count()
        ));
    }
    let (k, invalid_pixels) = (map.camera(), map.invalid_count());
    let range = match &args.range {
        Some(r) => parse_range(r, input.seq.len())?,
        None => 0..input.seq.len(),
    };
    let indices = input.seq.indices(range, args.reverse);
    input.check_exposures(args, &indices, observer)?;
    let (pcalib, vignette) = calibration?;
    if let Some(f) = &pcalib {
        for n in &f.notes {
            observer.warn(&format!("{}: {n}", f.path.display()));
        }
    }
    let response = pcalib.as_ref().map(|f| &f.response);
    let photometric = args.photometric || args.irradiance;
    // 16-bit frames with a 2^k-value table (k < 16) and no --bit-depth: the values are k-bit
    // values in the low bits, as DSO and DM-VIO index the table (`G[pixel]`)
    if let (None, true, true, Some(r)) = (args.bit_depth, input.deep(), photometric, &response) {
        if r.bits() < 16 {
            input.bits = r.bits();
        }
    }
    let calibration = Calibration {
        response,
        vignette: vignette.as_ref(),
    };
    let (pixels, scale_source) =
        pixels::choose(args, &input, map, &calibration, &indices, observer)?;
    let scale = pixels.scale();
    let pixel_value = scale.map(|s| {
        if args.irradiance {
            format!("pixel value = {s} * U(I) / (V * exposure_ms)")
        } else {
            format!("pixel value = {s} * U(I) / V")
        }
    });
    let value = pixel_value.as_deref().zip(scale_source.as_deref());
    let pcalib_text = pcalib
        .as_ref()
        .filter(|_| !photometric)
        .map(|f| f.text.as_str());
    let mut writer = output::create_writer(args, &input.seq, k, out_size, pcalib_text, value)?;
    let pipeline = FramePipeline {
        pixels: &pixels,
        out_size,
        depth: input.out_depth,
        in_bits: input.in_bits,
        bits: input.bits,
        irradiance: args.irradiance,
        reverse: args.reverse,
        speed: args.compression.png(),
    };
    let ids: Vec<String> = (0..indices.len()).map(|i| format!("{i:05}")).collect();
    observer.begin(indices.len() as u64, "rectifying", "frames");
    let threads = rayon::current_num_threads();
    let mut done = 0usize;
    let mut vignette_png = None;
    let work = |frame: dataset_io::NativeFrame| pipeline.process(frame, observer);
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
            scope.spawn(move |_| *slot = Some(output::rectified_vignette(map, v, out_size)));
        }
        input
            .seq
            .process_scaled(&indices, threads * 4, half, work, sink)
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
