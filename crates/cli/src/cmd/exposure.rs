//! `monovo exposure`: exposure times measured from the images, to check logged ones and to
//! estimate missing ones.

use std::path::PathBuf;

use anyhow::Result;
use monovo_pipelines::exposure::{
    check_sequence, estimate_sequence, measurement_options, with_check_thresholds, CheckJob,
    EstimateJob, ExposureInput,
};
use photometric::exposure::ExposureOptions;

use crate::progress::Bars;

/// Arguments of `monovo exposure`.
#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(subcommand)]
    pub what: What,
}

/// What to do.
#[derive(clap::Subcommand, Debug)]
pub enum What {
    /// Check the logged exposure times against the images: flag every frame whose logged
    /// exposure is its previous or next frame's.
    #[command(after_help = "\
The camera SDK of the benchmark reports exposure times asynchronously, so a logged exposure
sometimes belongs to the neighbouring frame. With pcalib.txt and vignette.png known,
U(I) / V = t B: the ratio t(i+1) / t(i) of consecutive frames follows from corresponding
pixels, since the scene barely changes between frames. monovo aligns each pair (a global
shift found coarse to fine, refined per tile to a smooth displacement field), compares the
corrected pixels that are neither dark nor near saturation, and measures the ratio with its
standard error. For every frame it predicts the exposure from its neighbours' logged
exposures and the measured ratios, and flags the frame when the logged value contradicts the
prediction (by --flag-sigmas standard errors and at least --min-difference percent) and fits
the previous or the next frame's exposure instead. Pairs that cannot be aligned (motion blur,
fast motion, a cut) are reported as unreliable and never flag a frame.

  monovo exposure check sequence_01
  monovo exposure check sequence_01 --json
  monovo exposure check sequence_01 --fix -o sequence_01/times_fixed.txt --plot exposures.png

--json prints one object: \"shifted\" (flagged frames, 0-based in times.txt order),
\"inconsistent\" (frames whose logged exposure contradicts the images but fits no neighbour),
\"undecided\", \"unreliable_pairs\", \"log_lag\" (1 or -1 when the whole log is one
frame late or early), \"ratios\" (one entry per pair i, i+1: \"frame\" i, the
\"logged\" and the \"measured\" ratio t(i+1) / t(i), the \"std_error\" of the measured ratio
relative to it, \"reliable\"), \"checks\" (per frame: logged and predicted exposure in ms, its
standard error, z, verdict) and \"measured_ms\" (the exposures from the images alone, scaled to
the logged ones).

--fix -o FILE writes times.txt with every flagged exposure replaced by its prediction; every
other line is copied as it is.")]
    Check(CheckArgs),
    /// Estimate the exposure times of a sequence from its images (up to one global scale).
    #[command(after_help = "\
For cameras that log no exposure (times.txt with two columns). The ratios of consecutive
frames (and of frames two apart, which bridge a bad frame) are measured as `exposure check`
measures them and chained by weighted least squares with Huber weights; the result is scaled
so that the median exposure is --reference-ms. Where no ratio could be measured (a cut, heavy
motion blur) a weak prior t(i+1) = t(i) bridges the gap: the relative exposure across it is
unknown, its standard error says so, and a warning names it.

  monovo exposure estimate my_sequence -o my_sequence/times_estimated.txt
  monovo exposure estimate my_sequence -o times.txt --reference-ms 8 --plot exposures.png

Writes times.txt with three columns `id timestamp exposure_ms` (ids and timestamps from the
sequence's times.txt) and, beside it, NAME_std.txt: one line per frame `id std_ms std_rel`,
the standard error of the exposure relative to the frame at the median (in ms and relative).")]
    Estimate(EstimateArgs),
}

/// Where the calibration comes from and how frames are read.
#[derive(clap::Args, Debug, Clone)]
pub struct InputArgs {
    /// The inverse response (default: SEQ/pcalib.txt).
    #[arg(long, value_name = "FILE")]
    pub pcalib: Option<PathBuf>,
    /// The vignette (default: SEQ/vignette.png; without one, V = 1 with a warning).
    #[arg(long, value_name = "FILE")]
    pub vignette: Option<PathBuf>,
    /// Bits used by 16-bit frames (10, 12, 16).
    #[arg(long, value_name = "BITS", value_parser = clap::value_parser!(u32).range(1..=16))]
    pub bit_depth: Option<u32>,
    /// Darkest grey value used (8-bit scale).
    #[arg(long, value_name = "GREY", default_value_t = ExposureOptions::default().min_grey)]
    pub min_grey: f64,
    /// Brightest grey value used (8-bit scale).
    #[arg(long, value_name = "GREY", default_value_t = ExposureOptions::default().max_grey)]
    pub max_grey: f64,
    /// Largest standard error (relative) of a reliable ratio.
    #[arg(long, value_name = "REL", default_value_t = ExposureOptions::default().max_std_error)]
    pub max_std_error: f64,
}

/// Arguments of `monovo exposure check`.
#[derive(clap::Args, Debug)]
pub struct CheckArgs {
    /// The sequence folder (images, times.txt with exposures, pcalib.txt, vignette.png).
    pub sequence: PathBuf,
    #[command(flatten)]
    pub input: InputArgs,
    /// Write a corrected times.txt (needs -o).
    #[arg(long, requires = "output")]
    pub fix: bool,
    /// The corrected times.txt to write with --fix.
    #[arg(short, long, value_name = "FILE", requires = "fix")]
    pub output: Option<PathBuf>,
    /// Replace existing outputs.
    #[arg(long)]
    pub force: bool,
    /// Standard errors by which a logged exposure must contradict the images to be flagged.
    #[arg(long, value_name = "SIGMAS", default_value_t = ExposureOptions::default().flag_sigmas)]
    pub flag_sigmas: f64,
    /// Smallest difference between logged and measured exposure that is flagged, percent.
    #[arg(long, value_name = "PERCENT", default_value_t = 100.0 * ExposureOptions::default().min_difference)]
    pub min_difference: f64,
    /// Plot logged and measured exposures over the frames with the flagged frames, and the
    /// residuals (.png or .svg).
    #[arg(long, value_name = "FILE")]
    pub plot: Option<PathBuf>,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
}

/// Arguments of `monovo exposure estimate`.
#[derive(clap::Args, Debug)]
pub struct EstimateArgs {
    /// The sequence folder (images, times.txt, pcalib.txt, vignette.png).
    pub sequence: PathBuf,
    #[command(flatten)]
    pub input: InputArgs,
    /// The times.txt to write; the standard errors go beside it as NAME_std.txt.
    #[arg(short, long, value_name = "FILE")]
    pub output: PathBuf,
    /// The median exposure of the result, in ms (the images fix exposures up to one scale).
    #[arg(long, value_name = "MS", default_value_t = 10.0)]
    pub reference_ms: f64,
    /// Chain only consecutive frames (half the work; no bridge over a bad frame).
    #[arg(long)]
    pub no_skip_pairs: bool,
    /// Replace existing outputs.
    #[arg(long)]
    pub force: bool,
    /// Plot the estimated exposures with their 2-sigma band (and the logged ones, if any)
    /// (.png or .svg).
    #[arg(long, value_name = "FILE")]
    pub plot: Option<PathBuf>,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
}

/// Runs `monovo exposure`.
pub fn run(args: &Args) -> Result<()> {
    let bars = Bars::default();
    let (text, json) = match &args.what {
        What::Check(a) => {
            let opts = with_check_thresholds(a.input.options()?, a.flag_sigmas, a.min_difference)?;
            let report = check_sequence(
                &CheckJob {
                    sequence: a.sequence.clone(),
                    input: a.input.files(),
                    options: opts,
                    fixed: a.output.clone(),
                    plot: a.plot.clone(),
                    force: a.force,
                },
                &bars,
            )?;
            (report.text(), a.json.then(|| report.json()))
        }
        What::Estimate(a) => {
            let mut options = a.input.options()?;
            options.skip_pairs = !a.no_skip_pairs;
            let report = estimate_sequence(
                &EstimateJob {
                    sequence: a.sequence.clone(),
                    input: a.input.files(),
                    options,
                    output: a.output.clone(),
                    reference_ms: a.reference_ms,
                    plot: a.plot.clone(),
                    force: a.force,
                },
                &bars,
            )?;
            (report.text(), a.json.then(|| report.json()))
        }
    };
    match json {
        Some(j) => outln!("{j}")?,
        None => out!("{text}")?,
    }
    Ok(())
}

impl InputArgs {
    fn options(&self) -> Result<ExposureOptions> {
        Ok(measurement_options(
            self.min_grey,
            self.max_grey,
            self.max_std_error,
        )?)
    }
    fn files(&self) -> ExposureInput {
        ExposureInput {
            pcalib: self.pcalib.clone(),
            vignette: self.vignette.clone(),
            bit_depth: self.bit_depth,
        }
    }
}
