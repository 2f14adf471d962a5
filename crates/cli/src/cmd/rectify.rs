//! `monovo rectify`: rectified (and photometrically corrected) frames as a new sequence.

use std::path::PathBuf;

use anyhow::Result;
use camera_model::{ImageSize, OutputMode};
use monovo_pipelines::rectify::{rectify_sequence, FrameCompression, RectifyJob};

use crate::progress::Bars;

/// Arguments of `monovo rectify`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The sequence folder.
    pub sequence: PathBuf,
    /// The new sequence folder (must not exist unless --force).
    #[arg(short = 'o', long = "output", value_name = "OUT")]
    pub output: PathBuf,
    /// The output pinhole camera: crop, full, none, or "fx fy cx cy 0" (default: camera.txt
    /// line 3).
    #[arg(long = "pinhole", alias = "output-camera", value_name = "MODE")]
    pub pinhole: Option<OutputMode>,
    /// Output size WIDTHxHEIGHT (default: camera.txt line 4).
    #[arg(long, value_name = "WxH")]
    pub size: Option<ImageSize>,
    /// Undo response and vignetting: U(I) / V.
    #[arg(long)]
    pub photometric: bool,
    /// Also divide by the exposure time: irradiance U(I) / (t V). Implies --photometric.
    #[arg(long)]
    pub irradiance: bool,
    /// Mark pixels that touch a saturated (255) input pixel as invalid (0), with --photometric.
    #[arg(long)]
    pub mask_saturated: bool,
    /// Scale of the quantised photometric output (default: the largest without clipping;
    /// for 8-bit irradiance, from the data).
    #[arg(long)]
    pub scale: Option<f32>,
    /// Play backwards.
    #[arg(long)]
    pub reverse: bool,
    /// Frame range A..B (0-based, B exclusive; either end may be omitted).
    #[arg(long, value_name = "A..B")]
    pub range: Option<String>,
    /// Bits per output pixel, 8 or 16 (default: the input's: 16-bit frames stay 16-bit).
    #[arg(long, value_parser = parse_depth)]
    pub depth: Option<u8>,
    /// The camera of a multi-camera dataset (TUM-VI, EuRoC, 4Seasons, KITTI): camN, image_N.
    #[arg(long, default_value_t = 0, value_name = "N")]
    pub cam: usize,
    /// A calibration file to use instead of the folder's own: camera.txt, Kalibr
    /// camchain.yaml, EuRoC sensor.yaml, Basalt calibration.json, KITTI calib.txt, ETH3D
    /// calibration.txt (its camera --cam N where it has several).
    #[arg(long = "calib", value_name = "FILE")]
    pub calibration: Option<PathBuf>,
    /// Write the frames into images.zip instead of images/.
    #[arg(long)]
    pub zip: bool,
    /// PNG compression of the frames: fast (fdeflate, about half the raw size) or none
    /// (stored: twice the disk space, the fastest to write and to read back).
    #[arg(long, default_value_t = FrameCompression::Fast, value_name = "fast|none")]
    pub compression: FrameCompression,
    /// Decode the JPEG frames at half their width and height in the DCT domain (libjpeg-turbo,
    /// in builds with `--features turbojpeg`) and rectify from those: a quarter less decoding
    /// time than zune-jpeg's full decode. For outputs of at most half the input size; the
    /// pixels differ from the full path's by about one grey level on average (no bias; a 2x2
    /// mean instead of a point sample, so hot pixels and fine texture are softer).
    #[arg(long)]
    pub half_decode: bool,
    /// Replace an existing OUT.
    #[arg(long)]
    pub force: bool,
    /// Print a JSON summary.
    #[arg(long)]
    pub json: bool,
}

/// The `monovo rectify` command line: [`Args`] and the bit depth of 16-bit input frames.
#[derive(clap::Args, Debug)]
#[command(after_help = "\
Examples:
  monovo rectify sequence_01 -o seq01_rect                          # camera.txt's output (crop 640x480)
  monovo rectify sequence_01 -o seq01_f300 --pinhole \"0.46875 0.625 0.5 0.5 0\" --size 640x480
  monovo rectify sequence_01 -o seq01_small --size 424x320           # another resolution
  monovo rectify sequence_01 -o seq01_bwd --reverse                  # backwards playback
  monovo rectify sequence_01 -o seq01_lin --photometric --depth 16   # undo response and vignette
  monovo rectify sequence_01 -o seq01_raw --compression none         # stored PNG: fastest, 2x disk
  monovo rectify sequence_01 -o seq01_fast --half-decode             # JPEG decoded at half size
  monovo rectify dataset-room1_512_16 -o room1 --cam 1 --pinhole \"0.3 0.3 0.5 0.5 0\" --size 512x512
  monovo rectify MH_01_easy -o mh01 --pinhole crop --size 752x480    # EuRoC: mav0/cam0, sensor.yaml

The input may be any layout `monovo info` reads: a monovo/DSO folder, TUM-VI (dso/camN or
mav0), EuRoC/ASL (mav0/camN with sensor.yaml, Basalt's exposure.csv), 4Seasons, KITTI
odometry or TUM RGB-D / ETH3D, each with its own calibration file; times.txt then carries the
dataset's own timestamps (exact nanoseconds) and exposures.

OUT is a new sequence folder that monovo and DSO read: PNG frames in images/ (or images.zip
with --zip), times.txt and a pinhole camera.txt. Without --photometric, pcalib.txt is copied
and the vignette is rectified into vignette.png, so DSO can still correct the frames itself.
With --photometric each pixel is U(I)/V times a scale (printed, and in a comment line of
times.txt; chosen so that nothing clips), and with --irradiance also divided by the exposure
time (times.txt then lists exposure 1); 8-bit irradiance takes its scale from the data (the
99.9th percentile of up to 16 frames maps to 255), 16-bit irradiance never clips.
Without vignette.png, --photometric undoes the response alone (V = 1, with a warning).
pcalib.txt may hold 2^k values (256 for 8-bit frames, 65536 for 16-bit); 16-bit PNG frames
are read unscaled, and --bit-depth 10 or 12 says that their values use only the low bits
(with --photometric, a table of 2^k values, k < 16, implies --bit-depth k, as DSO indexes it);
the response is looked up exactly at its own bit depth, by full range otherwise.
--reverse writes frames in backwards playback order, renumbered, with timestamps 2e9 - t so
that they increase (the benchmark's convention for backwards runs, understood by
`monovo eval`). OUT must not exist unless --force; a failed or interrupted run leaves no OUT
behind.")]
pub struct Command {
    /// The arguments shared with the library half (see [`Args`]).
    #[command(flatten)]
    pub args: Args,
    /// Bits per pixel of 16-bit input frames that hold fewer (values in the low bits, e.g.
    /// 10 or 12 for such sensors); default: the bit depth of pcalib.txt with --photometric
    /// on 16-bit frames, else 16 for 16-bit frames and 8 for 8-bit frames.
    #[arg(long, value_name = "BITS", value_parser = clap::value_parser!(u32).range(1..=16))]
    pub bit_depth: Option<u32>,
}

fn parse_depth(s: &str) -> Result<u8, String> {
    match s {
        "8" => Ok(8),
        "16" => Ok(16),
        _ => Err(format!("expected 8 or 16, found `{s}`")),
    }
}

impl Args {
    /// The library's job for these arguments and the bit depth of 16-bit input frames.
    pub fn job(&self, bit_depth: Option<u32>) -> RectifyJob {
        RectifyJob {
            sequence: self.sequence.clone(),
            output: self.output.clone(),
            pinhole: self.pinhole,
            size: self.size,
            photometric: self.photometric,
            irradiance: self.irradiance,
            mask_saturated: self.mask_saturated,
            scale: self.scale,
            reverse: self.reverse,
            range: self.range.clone(),
            depth: self.depth,
            cam: self.cam,
            calibration: self.calibration.clone(),
            zip: self.zip,
            compression: self.compression,
            force: self.force,
            bit_depth,
            half_decode: self.half_decode,
        }
    }
}

/// Runs the `monovo rectify` command line.
pub fn run_command(cmd: &Command) -> Result<()> {
    let r = rectify_sequence(&cmd.args.job(cmd.bit_depth), &Bars::default())?;
    if cmd.args.json {
        outln!("{}", serde_json::to_value(&r)?)?;
        return Ok(());
    }
    outln!(
        "wrote {} frames ({}x{}, pinhole fx={:.3} fy={:.3} cx={:.3} cy={:.3}) to {} in {:.2} s ({:.1} frames/s)",
        r.frames,
        r.width,
        r.height,
        r.fx,
        r.fy,
        r.cx,
        r.cy,
        r.output.display(),
        r.seconds,
        r.fps
    )?;
    if let (Some(f), Some(src)) = (&r.pixel_value, &r.scale_source) {
        outln!("{f} ({src})")?;
    }
    if r.half_decode {
        outln!(
            "frames decoded at half size in the DCT domain ({})",
            r.jpeg_decoder
        )?;
    }
    if r.invalid_pixels > 0 {
        outln!(
            "{} output pixels have no source and are 0",
            r.invalid_pixels
        )?;
    }
    Ok(())
}
