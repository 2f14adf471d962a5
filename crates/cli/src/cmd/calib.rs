//! `monovo calib`: photometric calibration of your own camera.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use camera_model::Image;
use dataset_io::Sequence;
use photometric::{calibrate_response, ResponseOptions};

use crate::plot::{self, Chart, Corner, Figure, Panel, Series, PALETTE};
use crate::progress;

/// Arguments of `monovo calib`.
#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(subcommand)]
    pub what: What,
}

/// What to calibrate.
#[derive(clap::Subcommand, Debug)]
pub enum What {
    /// The inverse response U (pcalib.txt) from a static scene at varying, known exposures.
    #[command(after_help = "\
Record a static scene with a wide range of grey values while the exposure changes slowly
(the paper: 1000 images, 120 exposures from 0.05 to 20 ms in steps of 1.05). SEQ holds the
images and times.txt with the exposure of every frame.

  monovo calib response sweep -o pcalib.txt --plot response.png

The method is the paper's alternating least squares (U(k) = mean of t B' over pixels of
value k; B' = sum t U(I) / sum t^2), iterated until the energy changes by less than
--tolerance. Saturated pixels and a small border around them are dropped; observations above
grey value 245 do not enter B' (saturation censors the noise there and would bias it);
values never observed are interpolated or extrapolated; the result is scaled to U(255)=255
and is always finite and strictly increasing. --smoothness adds a second-difference prior
for small data sets (0 = the paper's unregularised method).")]
    Response(ResponseArgs),
    /// A dense vignette map (vignette.png) from a video of a bright planar wall with one
    /// printed ArUco marker (original dictionary) that gives the plane's pose.
    #[command(after_help = "\
Film a bright, matte, planar surface (a white wall) with one printed marker of the original
ArUco dictionary (id 213 by default; the printed marker, black border included, is the unit
of length), from many viewpoints so that every image region sees the wall. SEQ holds the
images, times.txt with exposures, camera.txt (the raw camera; line 3 is the pinhole used to
find the marker) and pcalib.txt (or give --pcalib).

  monovo calib vignette wall -o vignette.png --plot vignette_plot.png

The paper's alternating minimisation of E(C, V) with the plane irradiance C on a 1000x1000 grid
over 5x5 marker widths, bilinear sampling and splatting, outlier rejection in the later
iterations, V scaled to max 1. Frames are streamed from the sequence: memory does not grow
with their number. Pixels with fewer than 8 observations are 0 (invalid) in vignette.png; a
smoothed map is written beside it. --poses FILE replaces the marker detection: one line
per frame `id r11 r12 r13 r21 r22 r23 r31 r32 r33 tx ty tz` (camera_from_plane of the raw
camera, marker corner 0 at (-0.5, 0.5), corner 1 at (0.5, 0.5)).")]
    Vignette(VignetteArgs),
}

/// Arguments of `monovo calib vignette`.
#[derive(clap::Args, Debug)]
pub struct VignetteArgs {
    /// The sequence folder (images, times.txt with exposures, camera.txt).
    pub sequence: PathBuf,
    /// The vignette.png to write (16-bit); the smoothed map goes beside it as *_smooth.png.
    #[arg(short, long, value_name = "FILE")]
    pub output: PathBuf,
    /// The inverse response (default: SEQ/pcalib.txt).
    #[arg(long, value_name = "FILE")]
    pub pcalib: Option<PathBuf>,
    /// Plane poses per frame instead of marker detection.
    #[arg(long, value_name = "FILE")]
    pub poses: Option<PathBuf>,
    /// Id of the marker (original ArUco dictionary).
    #[arg(long, default_value_t = 213)]
    pub marker_id: u16,
    /// Iteration limit.
    #[arg(long, default_value_t = photometric::VignetteOptions::default().max_iterations)]
    pub max_iterations: usize,
    /// Plot the map and its cross-sections (.png or .svg).
    #[arg(long, value_name = "FILE")]
    pub plot: Option<PathBuf>,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
}

/// Arguments of `monovo calib response`.
#[derive(clap::Args, Debug)]
pub struct ResponseArgs {
    /// The sweep sequence folder (images + times.txt with exposures).
    pub sequence: PathBuf,
    /// The pcalib.txt to write.
    #[arg(short, long, value_name = "FILE")]
    pub output: PathBuf,
    /// Iteration limit.
    #[arg(long, default_value_t = ResponseOptions::default().max_iterations)]
    pub max_iterations: usize,
    /// Relative energy change at which the iteration stops.
    #[arg(long, default_value_t = ResponseOptions::default().tolerance)]
    pub tolerance: f64,
    /// Weight of the smoothness prior (relative to the mean observations per grey value).
    #[arg(long, default_value_t = ResponseOptions::default().smoothness)]
    pub smoothness: f64,
    /// Plot U and the histogram of observed values (.png or .svg).
    #[arg(long, value_name = "FILE")]
    pub plot: Option<PathBuf>,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
}

/// Reads every frame of a sequence with its exposure; errors when exposures are missing.
pub fn load_exposed_frames(seq: &Sequence) -> Result<(Vec<Image<u8>>, Vec<f64>)> {
    if !seq.times().has_exposures() {
        bail!(
            "{}: calibration needs the exposure time of every frame (third column, > 0)",
            seq.times_path().display()
        );
    }
    let idx = seq.indices(0..seq.len(), false);
    let pb = progress::bar(idx.len() as u64, "decoding");
    let mut frames = Vec::with_capacity(idx.len());
    let mut exposures = Vec::with_capacity(idx.len());
    seq.process(
        &idx,
        rayon::current_num_threads() * 4,
        Ok::<_, anyhow::Error>,
        |f| {
            exposures.push(f.exposure_ms.unwrap_or(0.0));
            frames.push(f.image);
            pb.inc(1);
            Ok(())
        },
    )?;
    pb.finish_and_clear();
    Ok((frames, exposures))
}

fn run_response(a: &ResponseArgs) -> Result<()> {
    let seq = Sequence::open(&a.sequence)?;
    if seq.len() < 2 {
        bail!(
            "{}: response calibration needs at least 2 frames at different exposures, found {}",
            a.sequence.display(),
            seq.len()
        );
    }
    let (mut frames, exposures) = load_exposed_frames(&seq)?;
    let opts = ResponseOptions {
        max_iterations: a.max_iterations.max(1),
        tolerance: a.tolerance,
        smoothness: a.smoothness.max(0.0),
        ..ResponseOptions::default()
    };
    let pb = progress::bar(opts.max_iterations as u64, "iterating");
    let cal = calibrate_response(&mut frames, &exposures, &opts, &|i, e| {
        pb.set_position(i as u64);
        pb.set_message(format!("E={e:.4e}"));
    })
    .with_context(|| format!("{}", a.sequence.display()))?;
    pb.finish_and_clear();
    dataset_io::write_atomic(&a.output, cal.response.to_text().as_bytes())?;
    if let Some(p) = &a.plot {
        response_figure(&cal, None, p)?;
    }
    if a.json {
        println!(
            "{}",
            serde_json::json!({
                "output": a.output.display().to_string(),
                "iterations": cal.iterations,
                "converged": cal.converged,
                "rmse": cal.rmse,
                "observed_min": cal.observed_range.0,
                "observed_max": cal.observed_range.1,
                "filled": cal.filled,
                "frames": frames.len(),
            })
        );
    } else {
        println!(
            "{} after {} iterations ({}), residual RMSE {:.3} grey values",
            if cal.converged {
                "converged"
            } else {
                "stopped"
            },
            cal.iterations,
            if cal.converged {
                "tolerance reached"
            } else {
                "iteration limit"
            },
            cal.rmse
        );
        println!(
            "observed grey values {}..{}; {} value(s) filled by interpolation/extrapolation",
            cal.observed_range.0,
            cal.observed_range.1,
            cal.filled.len() + 1
        );
        println!("wrote {}", a.output.display());
    }
    Ok(())
}

/// Plots U (and the truth, when known) beside the histogram of observed grey values.
pub fn response_figure(
    cal: &photometric::ResponseCalibration,
    truth: Option<&[f64; 256]>,
    path: &std::path::Path,
) -> Result<()> {
    let u = cal.response.values();
    let mut c1 = Chart::new(
        "inverse response U",
        "grey value I",
        "U(I) (scaled to U(255)=255)",
    );
    c1.legend = Some(Corner::TopLeft);
    c1.x_range = Some([0.0, 255.0]);
    c1.series.push(Series::line(
        "U estimated",
        (0..256).map(|k| [k as f64, u[k]]).collect(),
        PALETTE[0],
    ));
    if let Some(t) = truth {
        c1.series.push(
            Series::line(
                "U true",
                (0..256).map(|k| [k as f64, t[k]]).collect(),
                PALETTE[2],
            )
            .dashed(),
        );
    }
    c1.series
        .push(Series::line("linear", vec![[0.0, 0.0], [255.0, 255.0]], PALETTE[7]).dashed());
    let mut c2 = Chart::new(
        "observed grey values",
        "grey value I",
        "observations (log10)",
    );
    c2.legend = None;
    c2.x_range = Some([0.0, 255.0]);
    let hist: Vec<[f64; 2]> = cal
        .histogram
        .iter()
        .take(255)
        .enumerate()
        .flat_map(|(k, &c)| {
            let v = (c as f64).max(1.0).log10();
            [[k as f64, v], [k as f64 + 1.0, v]]
        })
        .collect();
    c2.series.push(Series::line("", hist, PALETTE[1]));
    let fig = Figure {
        width: 1200,
        height: 500,
        panels: vec![
            (Panel::Chart(c1), [0.0, 0.0, 0.5, 1.0]),
            (Panel::Chart(c2), [0.5, 0.0, 0.5, 1.0]),
        ],
    };
    plot::save(&fig, path)
}

/// Parses a poses file: `id r11 .. r33 tx ty tz` per line.
fn parse_poses(
    path: &std::path::Path,
) -> Result<std::collections::HashMap<String, photometric::PlanePose>> {
    let text = dataset_io::read_text(path)?;
    let mut out = std::collections::HashMap::new();
    for (i, line) in text.lines().enumerate() {
        let t = line.trim();
        if t.is_empty() || t.starts_with('#') {
            continue;
        }
        let f: Vec<&str> = t.split_whitespace().collect();
        let nums: Option<Vec<f64>> = f.get(1..).map(|r| {
            r.iter()
                .filter_map(|x| x.parse::<f64>().ok().filter(|v| v.is_finite()))
                .collect()
        });
        match nums {
            Some(v) if f.len() == 13 && v.len() == 12 => {
                let pose = photometric::PlanePose {
                    r: [[v[0], v[1], v[2]], [v[3], v[4], v[5]], [v[6], v[7], v[8]]],
                    t: [v[9], v[10], v[11]],
                };
                out.insert(f[0].to_string(), pose);
            }
            _ => bail!(
                "{}: line {}: expected `id r11 r12 r13 r21 r22 r23 r31 r32 r33 tx ty tz` (13 fields, finite numbers), found `{}`",
                path.display(),
                i + 1,
                t.chars().take(100).collect::<String>()
            ),
        }
    }
    Ok(out)
}

/// Frames of a sequence with poses: decoded once and kept when they fit in
/// [`DECODED_CACHE_BYTES`], else decoded again on every pass (memory stays flat).
struct SequencePlaneFrames<'a> {
    seq: &'a Sequence,
    frames: Vec<(usize, f64, photometric::PlanePose)>,
    decoded: Vec<Image<u8>>,
}

/// Largest total size of decoded frames kept in memory by `calib vignette`.
const DECODED_CACHE_BYTES: usize = 192 << 20;

impl photometric::PlaneFrames for SequencePlaneFrames<'_> {
    fn len(&self) -> usize {
        self.frames.len()
    }
    fn frame(&self, i: usize) -> Result<photometric::PlaneFrame, photometric::PhotometricError> {
        let (k, exposure_ms, pose) = self.frames[i];
        let image = match self.decoded.get(i) {
            Some(img) => img.clone(),
            None => self
                .seq
                .decode(k)
                .map_err(|e| photometric::PhotometricError::Calibration(e.to_string()))?,
        };
        Ok(photometric::PlaneFrame {
            image,
            exposure_ms,
            pose,
        })
    }
}

/// The vignette map and its cross-sections through the image centre.
pub fn vignette_figure(
    v: &Image<f32>,
    truth: Option<&[f32]>,
    path: &std::path::Path,
) -> Result<()> {
    let (w, h) = v.size();
    let heat = crate::plot::Heatmap {
        title: "vignette V".into(),
        width: w,
        height: h,
        values: v.data().to_vec(),
        range: [0.0, 1.0],
        label: "V (0 = invalid)".into(),
    };
    let mut hc = Chart::new("horizontal cross-section (middle row)", "x (pixels)", "V");
    let mut vc = Chart::new("vertical cross-section (middle column)", "y (pixels)", "V");
    hc.legend = truth.map(|_| Corner::BottomRight);
    vc.legend = truth.map(|_| Corner::BottomRight);
    let row: Vec<[f64; 2]> = (0..w)
        .map(|x| [x as f64, v.get(x, h / 2).map_or(f64::NAN, |q| q as f64)])
        .collect();
    let col: Vec<[f64; 2]> = (0..h)
        .map(|y| [y as f64, v.get(w / 2, y).map_or(f64::NAN, |q| q as f64)])
        .collect();
    hc.series.push(Series::line("estimated", row, PALETTE[0]));
    vc.series.push(Series::line("estimated", col, PALETTE[0]));
    if let Some(t) = truth {
        hc.series.push(
            Series::line(
                "true",
                (0..w)
                    .map(|x| [x as f64, t[h / 2 * w + x] as f64])
                    .collect(),
                PALETTE[2],
            )
            .dashed(),
        );
        vc.series.push(
            Series::line(
                "true",
                (0..h)
                    .map(|y| [y as f64, t[y * w + w / 2] as f64])
                    .collect(),
                PALETTE[2],
            )
            .dashed(),
        );
    }
    let fig = Figure {
        width: 1500,
        height: 520,
        panels: vec![
            (Panel::Heatmap(heat), [0.0, 0.0, 0.4, 1.0]),
            (Panel::Chart(hc), [0.4, 0.0, 0.3, 1.0]),
            (Panel::Chart(vc), [0.7, 0.0, 0.3, 1.0]),
        ],
    };
    plot::save(&fig, path)
}

fn run_vignette(a: &VignetteArgs) -> Result<()> {
    use camera_model::{output_intrinsics, OutputMode, RectifyMap};
    let seq = Sequence::open(&a.sequence)?;
    let cam_path = a.sequence.join("camera.txt");
    let Some(cam) = seq.camera() else {
        bail!(
            "{}: missing; vignette calibration needs the camera model",
            cam_path.display()
        );
    };
    let pcalib_path = a.pcalib.clone().or(seq.pcalib_path.clone()).with_context(|| {
        format!(
            "{}: no pcalib.txt; vignette calibration needs the inverse response (run `monovo calib response` first, or give --pcalib FILE)",
            a.sequence.display()
        )
    })?;
    let response = photometric::InverseResponse::parse(&dataset_io::read_text(&pcalib_path)?)
        .with_context(|| pcalib_path.display().to_string())?;
    if !seq.times().has_exposures() {
        bail!(
            "{}: vignette calibration needs the exposure time of every frame (third column, > 0)",
            seq.times_path().display()
        );
    }
    let rows = &seq.times().rows;
    let mut frames = Vec::new();
    let mut skipped: std::collections::BTreeMap<&'static str, usize> = Default::default();
    if let Some(pp) = &a.poses {
        let poses = parse_poses(pp)?;
        for (k, row) in rows.iter().enumerate() {
            match poses.get(&row.id) {
                Some(p) => frames.push((k, row.exposure_ms.unwrap_or(0.0), *p)),
                None => *skipped.entry("no pose in the poses file").or_default() += 1,
            }
        }
    } else {
        if cam.output == OutputMode::None && !cam.input.is_pinhole() {
            bail!(
                "{}: line 3 is `none`, but the {} camera must be rectified to a pinhole to find the marker; use crop, full or an explicit pinhole (or give --poses)",
                cam_path.display(),
                cam.input.name()
            );
        }
        let k_out = output_intrinsics(&cam.input, cam.input_size, &cam.output, cam.output_size)
            .with_context(|| cam_path.display().to_string())?;
        let map = RectifyMap::new(&cam.input, cam.input_size, k_out, cam.output_size)?;
        let idx = seq.indices(0..seq.len(), false);
        let pb = progress::bar(idx.len() as u64, "markers");
        let mut found: Vec<(usize, Option<photometric::PlanePose>, usize)> = Vec::new();
        seq.process(
            &idx,
            rayon::current_num_threads() * 4,
            |f| -> Result<(usize, Option<photometric::PlanePose>, usize)> {
                let rect = map.remap_u8(&f.image)?;
                let det: Vec<_> = photometric::marker::detect_markers(&rect)
                    .into_iter()
                    .filter(|d| d.id == a.marker_id)
                    .collect();
                let pose = if det.len() == 1 {
                    photometric::marker::marker_pose(&k_out, &det[0].corners)
                } else {
                    None
                };
                Ok((f.index, pose, det.len()))
            },
            |r| {
                found.push(r);
                pb.inc(1);
                Ok(())
            },
        )?;
        pb.finish_and_clear();
        for (k, pose, n) in found {
            match (pose, n) {
                (Some(p), _) => frames.push((k, rows[k].exposure_ms.unwrap_or(0.0), p)),
                (None, 0) => *skipped.entry("no marker").or_default() += 1,
                (None, 1) => *skipped.entry("no pose from the corners").or_default() += 1,
                (None, _) => *skipped.entry("several markers with the id").or_default() += 1,
            }
        }
    }
    if frames.is_empty() {
        bail!(
            "{}: no frame has a plane pose (marker id {} was not found in any of {} frames{}); check --marker-id, the dictionary (original ArUco) and that the marker is fully visible",
            a.sequence.display(),
            a.marker_id,
            seq.len(),
            if a.poses.is_some() { ", or the ids in the poses file" } else { "" }
        );
    }
    let opts = photometric::VignetteOptions {
        max_iterations: a.max_iterations.max(1),
        ..photometric::VignetteOptions::default()
    };
    let bytes = frames.len() * cam.input_size.pixels();
    let decoded = if bytes <= DECODED_CACHE_BYTES {
        let idx: Vec<usize> = frames.iter().map(|f| f.0).collect();
        let mut out = Vec::with_capacity(idx.len());
        seq.process(
            &idx,
            rayon::current_num_threads() * 4,
            |f| Ok::<_, anyhow::Error>(f.image),
            |img| {
                out.push(img);
                Ok(())
            },
        )?;
        out
    } else {
        Vec::new()
    };
    let source = SequencePlaneFrames {
        seq: &seq,
        frames,
        decoded,
    };
    let pb = progress::bar(opts.max_iterations as u64, "iterating");
    let cal = photometric::calibrate_vignette(
        &cam.input,
        cam.input_size,
        &response,
        &source,
        &opts,
        &|i, e| {
            pb.set_position(i as u64);
            pb.set_message(format!("E={e:.3e}"));
        },
    )
    .with_context(|| a.sequence.display().to_string())?;
    pb.finish_and_clear();
    let (w, h) = cal.vignette.size();
    let to16 = |img: &Image<f32>| -> Vec<u16> {
        img.data()
            .iter()
            .map(|v| {
                if v.is_finite() {
                    (v * 65535.0).round().clamp(0.0, 65535.0) as u16
                } else {
                    0
                }
            })
            .collect()
    };
    let smooth_path = {
        let stem = a
            .output
            .file_stem()
            .map_or("vignette".into(), |s| s.to_string_lossy().into_owned());
        a.output.with_file_name(format!("{stem}_smooth.png"))
    };
    let raw16 = to16(&cal.vignette);
    let smooth16 = to16(&cal.smoothed);
    dataset_io::write_png_u16(&a.output, w, h, &raw16, dataset_io::PngSpeed::Default)?;
    dataset_io::write_png_u16(&smooth_path, w, h, &smooth16, dataset_io::PngSpeed::Default)?;
    if let Some(p) = &a.plot {
        vignette_figure(&cal.vignette, None, p)?;
    }
    if cal.coverage < 0.98 {
        eprintln!(
            "monovo: warning: only {:.1}% of the pixels have at least {} observations; film the wall so that it covers every image region",
            cal.coverage * 100.0,
            opts.min_observations
        );
    }
    let used = source.frames.len();
    let skipped_total: usize = skipped.values().sum();
    if a.json {
        println!(
            "{}",
            serde_json::json!({
                "output": a.output.display().to_string(),
                "smoothed": smooth_path.display().to_string(),
                "frames_used": used,
                "frames_skipped": skipped_total,
                "skipped": skipped.iter().map(|(k, v)| (k.to_string(), serde_json::json!(v))).collect::<serde_json::Map<_, _>>(),
                "iterations": cal.iterations,
                "converged": cal.converged,
                "rmse": cal.rms_relative,
                "coverage": cal.coverage,
            })
        );
    } else {
        println!(
            "{used} frames used, {skipped_total} skipped{}",
            if skipped.is_empty() {
                String::new()
            } else {
                format!(
                    " ({})",
                    skipped
                        .iter()
                        .map(|(k, v)| format!("{v}: {k}"))
                        .collect::<Vec<_>>()
                        .join(", ")
                )
            }
        );
        println!(
            "{} iterations ({}), relative residual RMS {:.4}, {:.1}% of the pixels valid",
            cal.iterations,
            if cal.converged {
                "converged"
            } else {
                "iteration limit"
            },
            cal.rms_relative,
            cal.coverage * 100.0
        );
        println!("wrote {} and {}", a.output.display(), smooth_path.display());
    }
    Ok(())
}

/// Runs `monovo calib`.
pub fn run(args: &Args) -> Result<()> {
    match &args.what {
        What::Response(a) => run_response(a),
        What::Vignette(a) => run_vignette(a),
    }
}
