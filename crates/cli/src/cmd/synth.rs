//! `monovo synth`: synthetic data with known ground truth, from a fixed seed.

use std::path::PathBuf;

use anyhow::Result;
use dataset_io::OutputDir;
use monovo_pipelines::synth::{
    write_results, write_sequence, write_sweep, write_vignette_set, ResultsSpec, SensorSpec,
    SequenceSpec, SweepSpec, VignetteSetSpec,
};

use crate::progress::Bars;

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
    /// The family of sensors: machine (the levels above) or gain (photon noise at a fixed
    /// gain of 160, 40 or 10 electrons per U-unit and 0.2, 0.3 or 0.5 grey levels of ADC noise
    /// for low, typical and high; no read noise, no defects).
    #[arg(long, default_value = "machine", value_name = "FAMILY")]
    pub sensor: synthetic::sensor::SensorFamily,
    /// The true camera response: dataset (toe, linear middle, shoulder), srgb, log, knee,
    /// gammaG (for example gamma2.2) or dorfN (N from 0 to 15: a real camera's or film's
    /// measured response from the DoRF database, from expansive to strongly compressive).
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
    /// The library's sensor description.
    pub fn spec(&self) -> SensorSpec {
        SensorSpec {
            family: self.sensor,
            noise: self.noise,
            response: self.response,
            jpeg_quality: (!self.png).then_some(self.quality),
        }
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

impl SequenceArgs {
    /// The library's description of the sequence.
    pub fn spec(&self) -> SequenceSpec {
        let e = &self.exposure;
        SequenceSpec {
            seed: self.seed,
            size: self.size,
            frames: self.frames,
            sensor: self.sensor.spec(),
            exposure: e.exposure,
            length: e.length,
            shift_exposures: e.shift_exposures,
            shift_min_change: e.shift_min_change,
            no_exposures: e.no_exposures,
        }
    }
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

/// Runs `monovo synth`.
pub fn run(args: &Args) -> Result<()> {
    let (dir, text, json) = match &args.what {
        What::Sequence(a) => {
            let out = OutputDir::create(&a.output, a.force)?;
            let seq = write_sequence(&out, &a.spec(), &Bars::default())?;
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
            let seq = write_vignette_set(
                &out,
                &VignetteSetSpec {
                    seed: a.seed,
                    size: a.size,
                    frames: a.frames,
                    bits: a.bits,
                    sensor: a.sensor.spec(),
                },
                &Bars::default(),
            )?;
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
            let spec = SweepSpec {
                seed: a.seed,
                size: a.size,
                frames: a.frames,
                min_exposure: a.min_exposure,
                max_exposure: a.max_exposure,
                step: a.step,
                bits: a.bits,
                sensor: a.sensor.spec(),
            };
            let sw = write_sweep(&out, &spec, &Bars::default())?;
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
            let spec = ResultsSpec {
                seed: a.seed,
                sequences: a.sequences,
                runs: a.runs,
                frames: a.frames,
            };
            let n = write_results(&out, &spec, &Bars::default())?;
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
