//! `monovo rectify`: rectified (and photometrically corrected) frames as a new sequence.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use camera_model::{output_notes, CameraFile, Image, ImageSize, OutputMode, RectifyMap};
use dataset_io::{GrayImage, PngSpeed, Sequence, SequenceWriter, TimeRow};
use photometric::{
    quantize_u16, quantize_u8, Correction, InverseResponse, QuantizedCorrection, Vignette,
};

use crate::progress;

/// Arguments of `monovo rectify`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The sequence folder.
    pub sequence: PathBuf,
    /// The new sequence folder.
    #[arg(short = 'o', value_name = "OUT")]
    pub output: PathBuf,
    /// Output camera: crop, full, none, or "fx fy cx cy 0" (default: camera.txt line 3).
    #[arg(long = "output", visible_alias = "output-camera", value_name = "MODE")]
    pub camera: Option<OutputMode>,
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
    /// Scale of the quantised photometric output (default: the largest without clipping).
    #[arg(long)]
    pub scale: Option<f32>,
    /// Play backwards.
    #[arg(long)]
    pub reverse: bool,
    /// Frame range A..B (0-based, B exclusive; either end may be omitted).
    #[arg(long, value_name = "A..B")]
    pub range: Option<String>,
    /// Bits per output pixel.
    #[arg(long, default_value_t = 8, value_parser = parse_depth)]
    pub depth: u8,
    /// Write the frames into images.zip instead of images/.
    #[arg(long)]
    pub zip: bool,
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
  monovo rectify sequence_01 -o seq01_f300 --output \"0.46875 0.625 0.5 0.5 0\" --size 640x480
  monovo rectify sequence_01 -o seq01_small --size 424x320           # another resolution
  monovo rectify sequence_01 -o seq01_bwd --reverse                  # backwards playback
  monovo rectify sequence_01 -o seq01_lin --photometric --depth 16   # undo response and vignette

OUT is a new sequence folder that monovo and DSO read: PNG frames in images/ (or images.zip
with --zip), times.txt and a pinhole camera.txt. Without --photometric, pcalib.txt is copied
and the vignette is rectified into vignette.png, so DSO can still correct the frames itself.
With --photometric each pixel is U(I)/V times a scale (printed; chosen so that nothing clips),
and with --irradiance also divided by the exposure time (times.txt then lists exposure 1).
Without vignette.png, --photometric undoes the response alone (V = 1, with a warning).
pcalib.txt may hold 2^k values (256 for 8-bit frames, 65536 for 16-bit); 16-bit PNG frames
are read unscaled, and --bit-depth 10 or 12 says that their values use only the low bits;
the response is looked up exactly at its own bit depth, by full range otherwise.
--reverse writes frames in backwards playback order, renumbered, with timestamps 2e9 - t so
that they increase (the benchmark's convention for backwards runs, understood by
`monovo eval`). OUT must not exist unless --force; a failed run leaves no OUT behind.")]
pub struct Command {
    /// The arguments shared with the library half (see [`Args`]).
    #[command(flatten)]
    pub args: Args,
    /// Bits per pixel of 16-bit input frames that hold fewer (values in the low bits, e.g.
    /// 10 or 12 for such sensors); default: 16 for 16-bit frames, 8 for 8-bit frames.
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

/// Parses `A..B`, `A..`, `..B`.
pub fn parse_range(s: &str, len: usize) -> Result<std::ops::Range<usize>> {
    let Some((a, b)) = s.split_once("..") else {
        bail!("--range: expected A..B (for example 100..500), found `{s}`");
    };
    let a: usize = if a.is_empty() {
        0
    } else {
        a.trim()
            .parse()
            .with_context(|| format!("--range: `{a}` is not a frame number"))?
    };
    let b: usize = if b.is_empty() {
        len
    } else {
        b.trim()
            .parse()
            .with_context(|| format!("--range: `{b}` is not a frame number"))?
    };
    if a >= b || a >= len {
        bail!("--range {s}: empty for a sequence of {len} frames");
    }
    Ok(a..b.min(len))
}

enum Pixels {
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

/// Runs `monovo rectify` (frames at their own bit depth).
pub fn run(args: &Args) -> Result<()> {
    run_with_bit_depth(args, None)
}

/// Runs the `monovo rectify` command line.
pub fn run_command(cmd: &Command) -> Result<()> {
    run_with_bit_depth(&cmd.args, cmd.bit_depth)
}

/// Runs `monovo rectify`; `bit_depth` is the number of bits used by 16-bit input frames.
pub fn run_with_bit_depth(args: &Args, bit_depth: Option<u32>) -> Result<()> {
    let started = Instant::now();
    let seq = Sequence::open(&args.sequence)?;
    let Some(cam) = seq.camera() else {
        bail!(
            "{}: no camera.txt; rectify needs the camera model",
            args.sequence.display()
        );
    };
    let mode = args.camera.unwrap_or(cam.output);
    let out_size = args.size.unwrap_or(cam.output_size);
    let camera_path = args.sequence.join("camera.txt");
    for w in cam
        .warnings
        .iter()
        .chain(&output_notes(&cam.input, cam.input_size, &mode, out_size))
    {
        eprintln!("monovo: warning: {}: {w}", camera_path.display());
    }
    let in_bits = seq.bits_per_sample();
    let bits = bit_depth.unwrap_or(in_bits);
    if in_bits == 8 && bits != 8 {
        bail!(
            "--bit-depth {bits}: the frames of {} are 8-bit; --bit-depth describes 16-bit frames whose values use fewer bits",
            args.sequence.display()
        );
    }
    let deep = in_bits == 16;
    let map =
        RectifyMap::for_mode(&cam.input, cam.input_size, &mode, out_size).with_context(|| {
            format!(
                "{}: output camera `{mode}` at {out_size}",
                args.sequence.join("camera.txt").display()
            )
        })?;
    let k = map.camera();
    let range = match &args.range {
        Some(r) => parse_range(r, seq.len())?,
        None => 0..seq.len(),
    };
    let indices = seq.indices(range, args.reverse);
    let photometric = args.photometric || args.irradiance;
    let response = match &seq.pcalib_path {
        Some(p) => {
            let (u, notes) = InverseResponse::parse_with_notes(&dataset_io::read_text(p)?)
                .with_context(|| p.display().to_string())?;
            for n in notes {
                eprintln!("monovo: warning: {}: {n}", p.display());
            }
            Some(u)
        }
        None => None,
    };
    let vignette = match &seq.vignette_path {
        Some(p) => {
            let (img, _) = dataset_io::read_gray_map(p)?;
            let v = Vignette::from_u16(&img).with_context(|| p.display().to_string())?;
            let (w, h) = v.size();
            if (w, h) != (seq.image_size().width, seq.image_size().height) {
                bail!(
                    "{}: the vignette is {w}x{h} but the images are {}",
                    p.display(),
                    seq.image_size()
                );
            }
            Some(v)
        }
        None => None,
    };
    if args.irradiance && !seq.times().has_exposures() {
        bail!(
            "{}: --irradiance needs a positive exposure time (third column) on every row",
            seq.times_path().display()
        );
    }
    let max16 = if args.depth == 16 { 65535.0 } else { 255.0 };
    let pixels = if photometric {
        let Some(resp) = &response else {
            bail!(
                "{}: --photometric needs pcalib.txt (the inverse response)",
                args.sequence.display()
            );
        };
        if vignette.is_none() {
            eprintln!(
                "monovo: warning: {}: no vignette.png: undoing the response alone (V = 1); DSO refuses its photometric mode without a vignette",
                args.sequence.display()
            );
        }
        let corr = Correction::new(
            resp,
            vignette.as_ref(),
            Some(map.clone()),
            (seq.image_size().width, seq.image_size().height),
            args.mask_saturated,
        )?;
        // largest value: U(white) / (min V [* t_min])
        let t_min = if args.irradiance {
            seq.times().exposure_range().map_or(1.0, |r| r.0)
        } else {
            1.0
        };
        let v_min = vignette.as_ref().map_or(1.0, |v| v.min_positive());
        let max_value = resp.max_value() as f32 / (v_min * t_min as f32);
        let scale = args.scale.unwrap_or(max16 / max_value);
        if deep {
            Pixels::Deep(
                Box::new(corr.with_bit_depth(resp, bits, args.mask_saturated)?),
                scale,
            )
        } else if args.mask_saturated {
            Pixels::Photometric(Box::new(corr), scale)
        } else {
            Pixels::Fast(
                Box::new(QuantizedCorrection::with_vignette(
                    resp,
                    vignette.as_ref(),
                    map.clone(),
                    scale,
                    args.depth,
                )?),
                scale,
            )
        }
    } else {
        Pixels::Geometric(map.clone())
    };
    let mut writer = SequenceWriter::create(&args.output, args.zip, args.force)?;
    writer.add_file(
        "camera.txt",
        CameraFile::rectified(k, out_size).to_text().as_bytes(),
    )?;
    if !photometric {
        if let (Some(p), Some(_)) = (&seq.pcalib_path, &response) {
            writer.add_file("pcalib.txt", dataset_io::read_text(p)?.as_bytes())?;
        }
        if let Some(v) = &vignette {
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
            let bytes = dataset_io::encode_png_u16(
                out_size.width,
                out_size.height,
                &v16,
                PngSpeed::Default,
            )?;
            writer.add_file("vignette.png", &bytes)?;
        }
    }
    // the ground truth is indexed by timestamp: still valid unless the timestamps are mapped
    if let (Some(p), false) = (&seq.ground_truth_path, args.reverse) {
        writer.add_file("groundtruthSync.txt", dataset_io::read_text(p)?.as_bytes())?;
    }
    let ids: Vec<String> = (0..indices.len()).map(|i| format!("{i:05}")).collect();
    let pb = progress::bar(indices.len() as u64, "rectifying");
    let threads = rayon::current_num_threads();
    let mut done = 0usize;
    let depth = args.depth;
    let irradiance = args.irradiance;
    let reverse = args.reverse;
    let sample_max = (1u32 << bits) - 1;
    seq.process_native(
        &indices,
        threads * 4,
        |frame| -> Result<(f64, Option<f64>, Vec<u8>)> {
            let (w, h) = (out_size.width, out_size.height);
            let label = || format!("frame {} ({})", frame.index, frame.name);
            if let GrayImage::U16(img) = &frame.image {
                if let Some(v) = img.data().iter().find(|v| **v as u32 > sample_max) {
                    bail!(
                        "{}: pixel value {v} does not fit in --bit-depth {bits} (at most {sample_max}); are the values in the high bits? then the bit depth is 16",
                        label()
                    );
                }
            }
            let png = match (&pixels, &frame.image) {
                (Pixels::Geometric(m), GrayImage::U8(img)) => {
                    let out = m.remap_u8(img)?;
                    if depth == 16 {
                        let wide: Vec<u16> = out.data().iter().map(|v| *v as u16 * 257).collect();
                        dataset_io::encode_png_u16(w, h, &wide, PngSpeed::Fast)?
                    } else {
                        dataset_io::encode_png_u8(w, h, 1, out.data(), PngSpeed::Fast)?
                    }
                }
                (Pixels::Geometric(m), GrayImage::U16(img)) => {
                    let out = m.remap_u16(img)?;
                    if depth == 16 {
                        // the values keep their bit depth
                        dataset_io::encode_png_u16(w, h, out.data(), PngSpeed::Fast)?
                    } else {
                        let narrow: Vec<u8> = out
                            .data()
                            .iter()
                            .map(|v| rescale_sample(*v, bits, 255.0) as u8)
                            .collect();
                        dataset_io::encode_png_u8(w, h, 1, &narrow, PngSpeed::Fast)?
                    }
                }
                (Pixels::Fast(c, _), GrayImage::U8(img)) => {
                    let exposure = if irradiance { frame.exposure_ms } else { None };
                    if depth == 16 {
                        let mut out = Image::filled(w, h, 0u16);
                        c.apply(img, exposure, &mut out)?;
                        dataset_io::encode_png_u16(w, h, out.data(), PngSpeed::Fast)?
                    } else {
                        let mut out = Image::filled(w, h, 0u8);
                        c.apply(img, exposure, &mut out)?;
                        dataset_io::encode_png_u8(w, h, 1, out.data(), PngSpeed::Fast)?
                    }
                }
                (Pixels::Photometric(c, scale), GrayImage::U8(img)) => {
                    let mut out = Image::filled(w, h, 0f32);
                    let exposure = if irradiance { frame.exposure_ms } else { None };
                    c.apply(img, exposure, &mut out).with_context(label)?;
                    encode_float(&out, *scale, depth)?
                }
                (Pixels::Deep(c, scale), GrayImage::U16(img)) => {
                    let mut out = Image::filled(w, h, 0f32);
                    let exposure = if irradiance { frame.exposure_ms } else { None };
                    c.apply_u16(img, exposure, &mut out).with_context(label)?;
                    encode_float(&out, *scale, depth)?
                }
                (_, image) => bail!(
                    "{}: {}-bit frame in a {in_bits}-bit sequence",
                    label(),
                    image.bits()
                ),
            };
            let t = if reverse {
                eval_metrics::BACKWARDS_EPOCH - frame.timestamp
            } else {
                frame.timestamp
            };
            let e = if irradiance {
                Some(1.0)
            } else {
                frame.exposure_ms
            };
            Ok((t, e, png))
        },
        |(t, e, png)| -> Result<()> {
            writer.add_frame(
                TimeRow {
                    id: ids[done].clone(),
                    timestamp: t,
                    exposure_ms: e,
                },
                &png,
            )?;
            done += 1;
            pb.inc(1);
            Ok(())
        },
    )?;
    pb.finish_and_clear();
    let frames = writer.frames();
    let dir = writer.finish()?;
    let secs = started.elapsed().as_secs_f64();
    let scale = match &pixels {
        Pixels::Photometric(_, s) | Pixels::Fast(_, s) | Pixels::Deep(_, s) => Some(*s),
        Pixels::Geometric(_) => None,
    };
    if args.json {
        println!(
            "{}",
            serde_json::json!({
                "output": dir.display().to_string(), "frames": frames, "seconds": secs,
                "fps": frames as f64 / secs, "width": out_size.width, "height": out_size.height,
                "fx": k.fx, "fy": k.fy, "cx": k.cx, "cy": k.cy, "invalid_pixels": map.invalid_count(),
                "photometric_scale": scale,
            })
        );
    } else {
        println!(
            "wrote {frames} frames ({out_size}, pinhole fx={:.3} fy={:.3} cx={:.3} cy={:.3}) to {} in {secs:.2} s ({:.0} frames/s)",
            k.fx,
            k.fy,
            k.cx,
            k.cy,
            dir.display(),
            frames as f64 / secs
        );
        if let Some(s) = scale {
            println!(
                "pixel value = {s} * U(I) / V{}",
                if args.irradiance {
                    " / exposure_ms"
                } else {
                    ""
                }
            );
        }
        if map.invalid_count() > 0 {
            println!(
                "{} output pixels have no source and are 0",
                map.invalid_count()
            );
        }
    }
    Ok(())
}

/// Quantises a corrected float frame to 8 or 16 bits.
fn encode_float(out: &Image<f32>, scale: f32, depth: u8) -> Result<Vec<u8>> {
    let (w, h) = out.size();
    Ok(if depth == 16 {
        dataset_io::encode_png_u16(w, h, quantize_u16(out, scale).data(), PngSpeed::Fast)?
    } else {
        dataset_io::encode_png_u8(w, h, 1, quantize_u8(out, scale).data(), PngSpeed::Fast)?
    })
}
