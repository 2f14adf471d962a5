//! `monovo synth`: synthetic data with known ground truth, from a fixed seed.

use std::path::PathBuf;

use anyhow::Result;
use dataset_io::OutputDir;
use rayon::prelude::*;
use synthetic::results::{run_text, sequence_name, sequence_path, ResultsConfig};

use crate::progress;

/// Arguments of `monovo synth`.
#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(subcommand)]
    pub what: What,
    /// Print one JSON object (what was written) instead of text.
    #[arg(long, global = true)]
    pub json: bool,
}

/// What to generate.
#[derive(clap::Subcommand, Debug)]
pub enum What {
    /// A synthetic benchmark evaluation: DIR/dataset/sequence_XX/groundtruthSync.txt and
    /// DIR/results/METHOD/sequence_XX/{fwd,bwd}_N.txt of two methods with known drift.
    #[command(after_help = "\
Example:
  monovo synth results -o synth
  monovo eval-batch --dataset synth/dataset --results synth/results -o results.csv
  monovo plot cumulative results.csv -o e_align.png

Method `direct` drifts little and rarely fails; method `feature` drifts more, has scale jumps,
loses tracking more often, writes keyframes only and uses the 2e9 - t timestamps backwards.")]
    Results(ResultsArgs),
    /// A benchmark-like sequence: zipped JPEG frames of a textured room seen through the
    /// dataset's FOV camera with vignette, non-gamma response, auto exposure and noise, plus
    /// times.txt, camera.txt, pcalib.txt, vignette.png and groundtruthSync.txt (the truth).
    #[command(after_help = "\
Example: a test set for `monovo exposure check` and `monovo exposure estimate`

  monovo synth sequence -o seq --size 640x480 --frames 200 --exposure auto --length 8 \\
      --shift-exposures 10 --seed 7
  monovo exposure check seq --json

truth_shifts.txt lists the frames whose logged exposure is a neighbour's, truth_times.txt the
true exposures (written when times.txt differs from them).")]
    Sequence(SequenceArgs),
    /// A response-calibration sweep: a static scene at exposures from 0.05 to 20 ms (images.zip,
    /// times.txt with exposures, camera.txt), and the true pcalib.txt as truth_pcalib.txt.
    Sweep(SweepArgs),
    /// A vignette-calibration set: a bright wall with ArUco marker 213 filmed from random poses
    /// (images.zip, times.txt, camera.txt, pcalib.txt), with the truth as poses.txt and
    /// truth_vignette.png.
    Vignette(VignetteArgs),
}

/// The synthetic camera's sensor, response and storage.
#[derive(clap::Args, Debug, Clone)]
pub struct SensorArgs {
    /// Sensor noise: low (full well 20,000 e-, read 3 e-), typical (10,000 e-, 5 e-) or high
    /// (5,000 e-, 8 e-, 1 grey level of ADC noise); every level has shot, read and ADC noise,
    /// full-well and 8-bit saturation, and hot and dead pixels.
    #[arg(long, default_value = "typical", value_name = "LEVEL")]
    pub noise: synthetic::sensor::NoiseLevel,
    /// The true camera response: dataset (toe, linear middle, shoulder), srgb, log, knee or
    /// gammaG (for example gamma2.2).
    #[arg(long, default_value = "dataset", value_name = "CURVE")]
    pub response: synthetic::camera::ResponseCurve,
    /// JPEG quality of the stored frames (the dataset's are about 90).
    #[arg(long, default_value_t = 90, value_parser = clap::value_parser!(u8).range(1..=100))]
    pub quality: u8,
    /// Store the frames losslessly as PNG instead of JPEG.
    #[arg(long)]
    pub png: bool,
}

impl SensorArgs {
    /// The sensor these arguments describe.
    pub fn sensor(&self) -> synthetic::sensor::Sensor {
        let s = synthetic::sensor::Sensor::preset(self.noise);
        if self.png {
            s
        } else {
            s.with_jpeg(self.quality)
        }
    }

    /// The extension of the stored frames.
    fn ext(&self) -> &'static str {
        if self.png {
            "png"
        } else {
            "jpg"
        }
    }

    /// Encodes a rendered frame as the camera stores it.
    fn encode(&self, w: usize, h: usize, frame: &[u8]) -> Result<Vec<u8>> {
        Ok(if self.png {
            dataset_io::encode_png_u8(w, h, 1, frame, dataset_io::PngSpeed::Fast)?
        } else {
            dataset_io::encode_jpeg_gray(w, h, frame, self.quality)?
        })
    }
}

/// Arguments of `monovo synth vignette`.
#[derive(clap::Args, Debug)]
pub struct VignetteArgs {
    /// Output sequence folder (must not exist unless --force).
    #[arg(short, long, value_name = "DIR")]
    pub output: PathBuf,
    /// Random seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Image size.
    #[arg(long, default_value = "640x512", value_name = "WxH")]
    pub size: camera_model::ImageSize,
    /// Number of frames.
    #[arg(long, default_value_t = 150)]
    pub frames: usize,
    #[command(flatten)]
    pub sensor: SensorArgs,
    /// Bits per sample (8 to 16): above 8, 16-bit PNG frames with the values 0..2^K-1 in
    /// the low bits (the same sensor with a finer ADC), and a pcalib.txt of 2^K values.
    #[arg(long, default_value_t = 8, value_name = "K",
          value_parser = clap::value_parser!(u32).range(8..=16))]
    pub bits: u32,
    /// Replace an existing output folder.
    #[arg(long)]
    pub force: bool,
}

/// Writes a synthetic vignette-calibration set into `out`.
pub fn write_vignette_set(
    out: &OutputDir,
    a: &VignetteArgs,
) -> Result<synthetic::plane::PlaneSequence> {
    use synthetic::plane::{PlaneConfig, PlaneSequence};
    let (w, h) = (a.size.width, a.size.height);
    let seq = PlaneSequence::new(
        a.seed,
        PlaneConfig {
            width: w,
            height: h,
            frames: a.frames.max(1),
            sensor: a.sensor.sensor(),
            response: a.sensor.response,
            ..PlaneConfig::default()
        },
    );
    if a.bits > 8 {
        write_frames(&out.file("images.zip")?, seq.poses.len(), "png", |i| {
            Ok(dataset_io::encode_png_u16(
                w,
                h,
                &seq.render_deep(i, a.bits),
                dataset_io::PngSpeed::Fast,
            )?)
        })?;
    } else {
        write_frames(
            &out.file("images.zip")?,
            seq.poses.len(),
            a.sensor.ext(),
            |i| a.sensor.encode(w, h, &seq.render(i)),
        )?;
    }
    let times: String = seq
        .exposures_ms
        .iter()
        .enumerate()
        .map(|(i, e)| format!("{i:05} {:.6} {e}\n", 1_400_000_000.0 + i as f64 * 0.1))
        .collect();
    dataset_io::write_atomic(&out.file("times.txt")?, times.as_bytes())?;
    let cam = seq
        .camera
        .camera_txt((w, h))
        .replace("\ncrop\n", "\nfull\n");
    dataset_io::write_atomic(&out.file("camera.txt")?, cam.as_bytes())?;
    let resp = photometric::InverseResponse::from_values(seq.response_bits(a.bits))?;
    dataset_io::write_atomic(&out.file("pcalib.txt")?, resp.to_text().as_bytes())?;
    dataset_io::write_atomic(&out.file("poses.txt")?, seq.poses_text().as_bytes())?;
    let vig =
        photometric::Vignette::from_values(camera_model::Image::new(w, h, seq.vignette.clone())?)?;
    dataset_io::write_png_u16(
        &out.file("truth_vignette.png")?,
        w,
        h,
        vig.to_u16().data(),
        dataset_io::PngSpeed::Default,
    )?;
    Ok(seq)
}

/// Arguments of `monovo synth sequence`.
#[derive(clap::Args, Debug)]
pub struct SequenceArgs {
    /// Output sequence folder (must not exist unless --force).
    #[arg(short, long, value_name = "DIR")]
    pub output: PathBuf,
    /// Random seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Image size.
    #[arg(long, default_value = "640x512", value_name = "WxH")]
    pub size: camera_model::ImageSize,
    /// Number of frames.
    #[arg(long, default_value_t = 300)]
    pub frames: usize,
    #[command(flatten)]
    pub sensor: SensorArgs,
    #[command(flatten)]
    pub exposure: SequenceExposureArgs,
    /// Replace an existing output folder.
    #[arg(long)]
    pub force: bool,
}

/// The exposures of a synthetic sequence and how they are logged.
#[derive(clap::Args, Debug, Clone)]
pub struct SequenceExposureArgs {
    /// How the exposure changes: smooth (a slow wander between about 2 and 14 ms) or auto
    /// (an auto-exposure controller following the scene's brightness, with metering noise:
    /// a few percent from frame to frame).
    #[arg(long, default_value = "smooth", value_name = "MODE")]
    pub exposure: synthetic::scene::ExposureMode,
    /// Length of the camera path in metres (the dataset's are about 100; walking at 1 m/s at
    /// 25 fps is 0.04 per frame: --length 8 for 200 frames).
    #[arg(long, default_value_t = 100.0, value_name = "M")]
    pub length: f64,
    /// Log this many exposures one frame off in times.txt, as the benchmark camera's
    /// asynchronous SDK does (a frame logs its previous or next frame's exposure); the
    /// frames, drawn from --seed, are listed in truth_shifts.txt and the true exposures are
    /// in truth_times.txt.
    #[arg(long, default_value_t = 0, value_name = "N")]
    pub shift_exposures: usize,
    /// Shifts go only where they change the logged exposure by at least this many percent
    /// (a shift that changes nothing is no error).
    #[arg(long, default_value_t = 2.0, value_name = "PERCENT")]
    pub shift_min_change: f64,
    /// Write times.txt without exposures (two columns), the truth in truth_times.txt: a
    /// sequence for `monovo exposure estimate`.
    #[arg(long)]
    pub no_exposures: bool,
}

impl Default for SequenceExposureArgs {
    fn default() -> Self {
        SequenceExposureArgs {
            exposure: synthetic::scene::ExposureMode::Smooth,
            length: 100.0,
            shift_exposures: 0,
            shift_min_change: 2.0,
            no_exposures: false,
        }
    }
}

/// Arguments of `monovo synth sweep`.
#[derive(clap::Args, Debug)]
pub struct SweepArgs {
    /// Output sequence folder (must not exist unless --force).
    #[arg(short, long, value_name = "DIR")]
    pub output: PathBuf,
    /// Random seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Image size.
    #[arg(long, default_value = "640x512", value_name = "WxH")]
    pub size: camera_model::ImageSize,
    /// Number of exposures (frames).
    #[arg(long, default_value_t = 120)]
    pub frames: usize,
    /// Shortest exposure in ms.
    #[arg(long, default_value_t = 0.05, value_name = "MS")]
    pub min_exposure: f64,
    /// Longest exposure in ms (the exposures are spaced evenly in log between the two).
    #[arg(long, default_value_t = 20.0, value_name = "MS")]
    pub max_exposure: f64,
    /// Exposure step factor instead of --max-exposure (the paper's sweep: 1.05).
    #[arg(long, value_name = "FACTOR")]
    pub step: Option<f64>,
    /// Bits per sample of the sensor (8 to 16). Above 8 the frames are 16-bit PNGs with the
    /// values 0..2^K-1 in the low bits (the same sensor with a finer ADC: full well, shot,
    /// read and ADC noise as a fraction of the full scale are those of 8 bits), and
    /// truth_pcalib.txt has 2^K values; calibrate with `monovo calib response`.
    #[arg(long, default_value_t = 8, value_name = "K", value_parser = clap::value_parser!(u32).range(8..=16))]
    pub bits: u32,
    #[command(flatten)]
    pub sensor: SensorArgs,
    /// Replace an existing output folder.
    #[arg(long)]
    pub force: bool,
}

/// Arguments of `monovo synth results`.
#[derive(clap::Args, Debug)]
pub struct ResultsArgs {
    /// Output folder (must not exist unless --force).
    #[arg(short, long, value_name = "DIR")]
    pub output: PathBuf,
    /// Random seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Number of sequences.
    #[arg(long, default_value_t = 50)]
    pub sequences: usize,
    /// Runs per sequence and direction.
    #[arg(long, default_value_t = 5)]
    pub runs: usize,
    /// Frames per sequence.
    #[arg(long, default_value_t = 2000)]
    pub frames: usize,
    /// Replace an existing output folder.
    #[arg(long)]
    pub force: bool,
}

/// Writes a synthetic results set into `out` (a staging folder); returns the number of runs.
pub fn write_results(out: &OutputDir, a: &ResultsArgs) -> Result<usize> {
    let cfg = ResultsConfig {
        sequences: a.sequences.max(1),
        runs: a.runs.max(1),
        frames: a.frames.max(50),
        ..ResultsConfig::default()
    };
    let paths: Vec<_> = (1..=cfg.sequences)
        .into_par_iter()
        .map(|i| sequence_path(a.seed, i, cfg.frames))
        .collect();
    for (i, p) in paths.iter().enumerate() {
        let f = out.file(&format!(
            "dataset/{}/groundtruthSync.txt",
            sequence_name(i + 1)
        ))?;
        dataset_io::write_atomic(&f, p.ground_truth_sync().as_bytes())?;
    }
    let mut jobs = Vec::new();
    for (mi, _) in cfg.methods.iter().enumerate() {
        for s in 0..cfg.sequences {
            for bwd in [false, true] {
                for r in 0..cfg.runs {
                    jobs.push((mi, s, bwd, r));
                }
            }
        }
    }
    let pb = progress::bar(jobs.len() as u64, "generating", "runs");
    jobs.par_iter()
        .try_for_each(|&(mi, s, bwd, r)| -> Result<()> {
            let m = &cfg.methods[mi];
            let text = run_text(a.seed, &paths[s], m, mi, s + 1, bwd, r);
            let rel = format!(
                "results/{}/{}/{}_{r}.txt",
                m.name,
                sequence_name(s + 1),
                if bwd { "bwd" } else { "fwd" }
            );
            dataset_io::write_atomic(&out.file(&rel)?, text.as_bytes())?;
            pb.inc(1);
            Ok(())
        })?;
    pb.finish_and_clear();
    Ok(jobs.len())
}

/// Encodes frames in parallel chunks and writes them as images.zip.
fn write_frames(
    zip_path: &std::path::Path,
    frames: usize,
    ext: &str,
    render: impl Fn(usize) -> Result<Vec<u8>> + Sync,
) -> Result<()> {
    let pb = progress::bar(frames as u64, "rendering", "frames");
    let encoded: Vec<Result<(String, Vec<u8>)>> = (0..frames)
        .into_par_iter()
        .map(|i| {
            let bytes = render(i)?;
            pb.inc(1);
            Ok((format!("{i:05}.{ext}"), bytes))
        })
        .collect();
    pb.finish_and_clear();
    let entries: Vec<(String, Vec<u8>)> = encoded.into_iter().collect::<Result<_>>()?;
    dataset_io::write_images_zip(zip_path, entries)?;
    Ok(())
}

/// Writes a synthetic benchmark sequence into the folder `out`.
pub fn write_sequence(
    out: &OutputDir,
    a: &SequenceArgs,
) -> Result<synthetic::scene::SyntheticSequence> {
    use synthetic::scene::{SequenceConfig, SyntheticSequence};
    let e = &a.exposure;
    if !(e.length.is_finite() && e.length > 0.0) {
        anyhow::bail!(
            "--length must be a positive number of metres, got {}",
            e.length
        );
    }
    if !(e.shift_min_change.is_finite() && e.shift_min_change >= 0.0) {
        anyhow::bail!(
            "--shift-min-change must be a percentage of at least 0, got {}",
            e.shift_min_change
        );
    }
    if e.shift_exposures > 0 && e.no_exposures {
        anyhow::bail!("--shift-exposures needs logged exposures; leave out --no-exposures");
    }
    let cfg = SequenceConfig {
        width: a.size.width,
        height: a.size.height,
        frames: a.frames.max(8),
        sensor: a.sensor.sensor(),
        response: a.sensor.response,
        exposure: e.exposure,
        path_length: e.length,
        ..SequenceConfig::default()
    };
    let seq = SyntheticSequence::new(a.seed, cfg);
    let (w, h) = (cfg.width, cfg.height);
    write_frames(&out.file("images.zip")?, cfg.frames, a.sensor.ext(), |i| {
        a.sensor.encode(w, h, &seq.render(i))
    })?;
    let rows = seq.times();
    let truth: String = rows
        .iter()
        .map(|(id, t, e)| format!("{id} {t:.6} {e}\n"))
        .collect();
    let (logged, shifts) = synthetic::scene::shift_exposure_log(
        &seq.exposures_ms,
        e.shift_exposures,
        e.shift_min_change / 100.0,
        a.seed,
    );
    if shifts.len() < e.shift_exposures {
        eprintln!(
            "monovo: warning: only {} of {} exposure shifts fit (isolated, changing the log by at least {}%)",
            shifts.len(),
            e.shift_exposures,
            e.shift_min_change
        );
    }
    let times: String = rows
        .iter()
        .zip(&logged)
        .map(|((id, t, _), l)| {
            if e.no_exposures {
                format!("{id} {t:.6}\n")
            } else {
                format!("{id} {t:.6} {l}\n")
            }
        })
        .collect();
    dataset_io::write_atomic(&out.file("times.txt")?, times.as_bytes())?;
    if times != truth {
        dataset_io::write_atomic(&out.file("truth_times.txt")?, truth.as_bytes())?;
    }
    if e.shift_exposures > 0 {
        let mut text = String::from(
            "# frame (0-based) whose logged exposure is another frame's: frame source true_ms logged_ms\n",
        );
        for s in &shifts {
            text.push_str(&format!(
                "{} {} {} {}\n",
                s.frame, s.source, seq.exposures_ms[s.frame], logged[s.frame]
            ));
        }
        dataset_io::write_atomic(&out.file("truth_shifts.txt")?, text.as_bytes())?;
    }
    // the dataset's output camera: 640x480 (4:3 at most 640 wide, as its camera.txt says)
    let out_w = w.clamp(2, 640);
    let out_size = (out_w, (out_w * 3 / 4).max(2));
    dataset_io::write_atomic(
        &out.file("camera.txt")?,
        seq.camera.camera_txt(out_size).as_bytes(),
    )?;
    let pcalib = photometric::InverseResponse::new(seq.response)?;
    dataset_io::write_atomic(&out.file("pcalib.txt")?, pcalib.to_text().as_bytes())?;
    let vig =
        photometric::Vignette::from_values(camera_model::Image::new(w, h, seq.vignette.clone())?)?;
    let v16 = vig.to_u16();
    dataset_io::write_png_u16(
        &out.file("vignette.png")?,
        w,
        h,
        v16.data(),
        dataset_io::PngSpeed::Default,
    )?;
    dataset_io::write_atomic(
        &out.file("groundtruthSync.txt")?,
        seq.path.ground_truth_sync().as_bytes(),
    )?;
    Ok(seq)
}

/// Writes a synthetic response-calibration sweep into the folder `out`.
pub fn write_sweep(out: &OutputDir, a: &SweepArgs) -> Result<synthetic::scene::Sweep> {
    use synthetic::scene::{Sweep, SweepConfig};
    let (w, h) = (a.size.width, a.size.height);
    let frames = a.frames.max(2);
    if !(a.min_exposure.is_finite() && a.min_exposure > 0.0) {
        anyhow::bail!(
            "--min-exposure must be a positive number of ms, got {}",
            a.min_exposure
        );
    }
    let factor = match a.step {
        Some(s) if s.is_finite() && s > 1.0 => s,
        Some(s) => anyhow::bail!("--step must be a factor above 1, got {s}"),
        None if a.max_exposure.is_finite() && a.max_exposure > a.min_exposure => {
            (a.max_exposure / a.min_exposure).powf(1.0 / (frames - 1) as f64)
        }
        None => anyhow::bail!(
            "--max-exposure ({}) must be longer than --min-exposure ({})",
            a.max_exposure,
            a.min_exposure
        ),
    };
    let sweep = Sweep::new(
        a.seed,
        SweepConfig {
            width: w,
            height: h,
            frames,
            t0: a.min_exposure,
            factor,
            sensor: a.sensor.sensor(),
            response: a.sensor.response,
        },
    );
    if a.bits > 8 {
        write_frames(
            &out.file("images.zip")?,
            sweep.exposures_ms.len(),
            "png",
            |i| {
                Ok(dataset_io::encode_png_u16(
                    w,
                    h,
                    &sweep.render_deep(i, a.bits),
                    dataset_io::PngSpeed::Fast,
                )?)
            },
        )?;
    } else {
        write_frames(
            &out.file("images.zip")?,
            sweep.exposures_ms.len(),
            a.sensor.ext(),
            |i| a.sensor.encode(w, h, &sweep.render(i)),
        )?;
    }
    let times: String = sweep
        .exposures_ms
        .iter()
        .enumerate()
        .map(|(i, e)| format!("{i:05} {:.6} {e}\n", 1_400_000_000.0 + i as f64 * 0.05))
        .collect();
    dataset_io::write_atomic(&out.file("times.txt")?, times.as_bytes())?;
    let cam = synthetic::camera::FovCamera::dataset(w, h);
    dataset_io::write_atomic(&out.file("camera.txt")?, cam.camera_txt((w, h)).as_bytes())?;
    let truth = photometric::InverseResponse::from_values(sweep.response_bits(a.bits))?;
    dataset_io::write_atomic(&out.file("truth_pcalib.txt")?, truth.to_text().as_bytes())?;
    Ok(sweep)
}

/// Runs `monovo synth`.
pub fn run(args: &Args) -> Result<()> {
    let (dir, text, json) = match &args.what {
        What::Sequence(a) => {
            let out = OutputDir::create(&a.output, a.force)?;
            let seq = write_sequence(&out, a)?;
            let dir = out.commit()?;
            let c = &seq.config;
            (
                dir,
                format!("a {}x{} sequence of {} frames", c.width, c.height, c.frames),
                serde_json::json!({"kind": "sequence", "width": c.width, "height": c.height, "frames": c.frames}),
            )
        }
        What::Vignette(a) => {
            let out = OutputDir::create(&a.output, a.force)?;
            let seq = write_vignette_set(&out, a)?;
            let dir = out.commit()?;
            let c = &seq.config;
            (
                dir,
                format!(
                    "a {}x{} marker-plane set of {} frames",
                    c.width,
                    c.height,
                    seq.poses.len()
                ),
                serde_json::json!({"kind": "vignette", "width": c.width, "height": c.height, "frames": seq.poses.len()}),
            )
        }
        What::Sweep(a) => {
            let out = OutputDir::create(&a.output, a.force)?;
            let sw = write_sweep(&out, a)?;
            let dir = out.commit()?;
            let lo = sw.exposures_ms.first().copied().unwrap_or(0.0);
            let hi = sw.exposures_ms.last().copied().unwrap_or(0.0);
            (
                dir,
                format!(
                    "a {}x{} sweep of {} exposures ({lo:.3} to {hi:.3} ms)",
                    sw.width,
                    sw.height,
                    sw.exposures_ms.len(),
                ),
                serde_json::json!({"kind": "sweep", "width": sw.width, "height": sw.height, "frames": sw.exposures_ms.len(), "min_exposure_ms": lo, "max_exposure_ms": hi}),
            )
        }
        What::Results(a) => {
            let out = OutputDir::create(&a.output, a.force)?;
            let n = write_results(&out, a)?;
            let dir = out.commit()?;
            (
                dir,
                format!("{n} runs of 2 methods on {} sequences", a.sequences.max(1)),
                serde_json::json!({"kind": "results", "runs": n, "methods": 2, "sequences": a.sequences.max(1)}),
            )
        }
    };
    if args.json {
        let mut v = json;
        v["output"] = serde_json::json!(dir.display().to_string());
        outln!("{v}")?;
    } else {
        outln!("wrote {text} to {}", dir.display())?;
    }
    Ok(())
}
