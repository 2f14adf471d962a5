//! `monovo rectify`: rectified (and photometrically corrected) frames as a new sequence.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use camera_model::{output_notes, CameraFile, Image, ImageSize, OutputMode, RectifyMap};
use dataset_io::{GrayImage, PngSpeed, Sequence, SequenceWriter, TimeRow};
use photometric::{quantize_u16, quantize_u8, Correction, InverseResponse, QuantizedCorrection};

use crate::progress;

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
  monovo rectify sequence_01 -o seq01_f300 --pinhole \"0.46875 0.625 0.5 0.5 0\" --size 640x480
  monovo rectify sequence_01 -o seq01_small --size 424x320           # another resolution
  monovo rectify sequence_01 -o seq01_bwd --reverse                  # backwards playback
  monovo rectify sequence_01 -o seq01_lin --photometric --depth 16   # undo response and vignette

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
        bail!("--range {s}: empty for a sequence of {len} frames (0..{len})");
    }
    if b > len {
        bail!("--range {s}: beyond the end of the sequence, which has {len} frames (0..{len})");
    }
    Ok(a..b)
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
}

/// Runs `monovo rectify` (frames at their own bit depth).
pub fn run(args: &Args) -> Result<Rectified> {
    run_with_bit_depth(args, None)
}

/// Runs the `monovo rectify` command line.
pub fn run_command(cmd: &Command) -> Result<()> {
    let r = run_with_bit_depth(&cmd.args, cmd.bit_depth)?;
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
    if r.invalid_pixels > 0 {
        outln!(
            "{} output pixels have no source and are 0",
            r.invalid_pixels
        )?;
    }
    Ok(())
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
    seq.process_native(
        &picks,
        picks.len(),
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

/// Runs `monovo rectify`; `bit_depth` is the number of bits used by 16-bit input frames.
/// Prints warnings to stderr, nothing to stdout.
pub fn run_with_bit_depth(args: &Args, bit_depth: Option<u32>) -> Result<Rectified> {
    let started = Instant::now();
    // the output location first: no work for an output that cannot be written
    dataset_io::OutputDir::check(&args.output, args.force)?;
    let photometric = args.photometric || args.irradiance;
    if !photometric {
        if args.scale.is_some() {
            bail!(
                "--scale sets the scale of photometric output: add --photometric or --irradiance"
            );
        }
        if args.mask_saturated {
            bail!("--mask-saturated masks photometric output: add --photometric or --irradiance");
        }
    }
    if let Some(s) = args.scale {
        if !(s.is_finite() && s > 0.0) {
            bail!("--scale {s}: must be a positive number");
        }
    }
    let seq = crate::cmd::open_sequence(&args.sequence)?;
    let Some(cam) = seq.camera() else {
        bail!(
            "{}: no camera.txt; rectify needs the camera model",
            args.sequence.display()
        );
    };
    let mode = args.pinhole.unwrap_or(cam.output);
    let out_size = args.size.unwrap_or(cam.output_size);
    let camera_path = args.sequence.join("camera.txt");
    for w in cam
        .warnings
        .iter()
        .chain(&output_notes(&cam.input, cam.input_size, &mode, out_size))
    {
        crate::warn(format_args!("{}: {w}", camera_path.display()));
    }
    let in_bits = seq.bits_per_sample();
    let mut bits = bit_depth.unwrap_or(in_bits);
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
                camera_path.display()
            )
        })?;
    if mode == OutputMode::Crop && map.invalid_count() > 0 {
        crate::warn(format_args!(
            "{}: `crop` at {out_size} leaves {} output pixels without a source (0 in every frame); a smaller --size or another --pinhole avoids them",
            camera_path.display(),
            map.invalid_count()
        ));
    }
    let k = map.camera();
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
            bail!(
                "{}: line {}: the exposure of frame {i} ({}) is unknown (0 or missing); --irradiance divides by the exposure time of every frame",
                seq.times_path().display(),
                times.lines.get(i).copied().unwrap_or(i + 1),
                seq.names()[i]
            );
        }
    } else if photometric {
        if let Some((i, line)) = seq.times().first_unknown_exposure() {
            crate::warn(format_args!(
                "{}: line {line}: frame {i} has no known exposure; the photometric output keeps the exposure column as it is (--irradiance would refuse)",
                seq.times_path().display()
            ));
        }
    }
    let response = match &seq.pcalib_path {
        Some(p) => {
            let (u, notes) = InverseResponse::parse_with_notes(&dataset_io::read_text(p)?)
                .with_context(|| p.display().to_string())?;
            for n in notes {
                crate::warn(format_args!("{}: {n}", p.display()));
            }
            Some(u)
        }
        None => None,
    };
    // 16-bit frames with a 2^k-value table (k < 16) and no --bit-depth: the values are k-bit
    // values in the low bits, as DSO and DM-VIO index the table (`G[pixel]`)
    if let (None, true, true, Some(r)) = (bit_depth, deep, photometric, &response) {
        if r.bits() < 16 {
            bits = r.bits();
        }
    }
    let vignette = match &seq.vignette_path {
        Some(p) => Some(crate::cmd::read_vignette(p, seq.image_size())?),
        None => None,
    };
    let max16 = if args.depth == 16 { 65535.0 } else { 255.0 };
    let mut scale_source = None;
    let pixels = if photometric {
        let Some(resp) = &response else {
            bail!(
                "{}: --photometric needs pcalib.txt (the inverse response)",
                args.sequence.display()
            );
        };
        if vignette.is_none() {
            crate::warn(format_args!(
                "{}: no vignette.png: undoing the response alone (V = 1); DSO refuses its photometric mode without a vignette",
                args.sequence.display()
            ));
        }
        let in_size = (seq.image_size().width, seq.image_size().height);
        let corr = Correction::new(
            resp,
            vignette.as_ref(),
            Some(map.clone()),
            in_size,
            args.mask_saturated,
        )?;
        let corr = if deep {
            corr.with_bit_depth(resp, bits, args.mask_saturated)?
        } else {
            corr
        };
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
            None if args.irradiance && args.depth == 8 => {
                let (w, h) = (out_size.width, out_size.height);
                let sample = |f: &dataset_io::NativeFrame| -> Result<Image<f32>> {
                    let mut out = Image::filled(w, h, 0f32);
                    match &f.image {
                        GrayImage::U8(img) => corr.apply(img, f.exposure_ms, &mut out)?,
                        GrayImage::U16(img) => corr.apply_u16(img, f.exposure_ms, &mut out)?,
                    }
                    Ok(out)
                };
                match irradiance_scale(&seq, &indices, &sample, max16)? {
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
        if deep {
            Pixels::Deep(Box::new(corr), scale)
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
    let pb = progress::bar(indices.len() as u64, "rectifying", "frames");
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
                        c.apply(img, exposure, &mut out).with_context(label)?;
                        dataset_io::encode_png_u16(w, h, out.data(), PngSpeed::Fast)?
                    } else {
                        let mut out = Image::filled(w, h, 0u8);
                        c.apply(img, exposure, &mut out).with_context(label)?;
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
            pb.inc(1);
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
            Ok(())
        },
    )?;
    pb.finish_and_clear();
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
        invalid_pixels: map.invalid_count(),
        photometric_scale: scale,
        scale_source,
        pixel_value,
    })
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
