//! `monovo info`: what a sequence folder holds, and every problem that would stop
//! `monovo rectify` (or DSO), each with its file and line.

use std::path::PathBuf;

use anyhow::{bail, Result};
use monovo_pipelines::inspect_sequence;

use crate::progress::Bars;

/// Arguments of `monovo info`.
#[derive(clap::Args, Debug)]
#[command(after_help = "\
Example:
  monovo info sequence_01
  monovo info sequence_01 --json
  monovo info sequence_01 --quick          # without decoding every frame
  monovo info dataset-room1_512_16 --cam 1 # TUM-VI: dso/cam1 (or mav0/cam1)
  monovo info MH_01_easy --json            # EuRoC: mav0/cam0, sensor.yaml

Reads every layout of docs/datasets.md: monovo/DSO folders, TUM-VI, EuRoC/ASL, 4Seasons,
KITTI odometry and TUM RGB-D / ETH3D; --json gives `layout`, `timestamps_ns` [first, last]
(exact integers) and `exposure_ms` (null where the dataset logs none).

Checks what `monovo rectify` checks: one times.txt row per image, increasing timestamps,
exposures (zeros that are interpolated or unknown), ids that name the images, camera.txt and
its output camera, the camera's size equal to the images', pcalib.txt (2^k finite, strictly
increasing values), vignette.png (grey, at the images' size), groundtruthSync.txt, and that
every frame decodes (a truncated or corrupt JPEG). Each problem is listed with its file (and
line); the exit code is non-zero when there is one. Warnings do not change the exit code.")]
pub struct Args {
    /// The sequence folder (images.zip or images/, times.txt, camera.txt, ...; or a TUM-VI,
    /// EuRoC, 4Seasons, KITTI, TUM RGB-D folder).
    pub sequence: PathBuf,
    /// Print one JSON object (with the lists `problems` and `warnings`).
    #[arg(long)]
    pub json: bool,
    /// Do not decode every frame (only the first, as opening the sequence does).
    #[arg(long)]
    pub quick: bool,
    /// The camera of a multi-camera dataset (TUM-VI, EuRoC, 4Seasons, KITTI): camN, image_N.
    #[arg(long, default_value_t = 0, value_name = "N")]
    pub cam: usize,
    /// A calibration file to use instead of the folder's own (any format `monovo camera`
    /// reads).
    #[arg(long = "calib", value_name = "FILE")]
    pub calibration: Option<PathBuf>,
}

/// Runs `monovo info`.
pub fn run(args: &Args) -> Result<()> {
    let info = inspect_sequence(
        &args.sequence,
        args.cam,
        args.calibration.as_deref(),
        args.quick,
        &Bars::default(),
    )?;
    if args.json {
        outln!("{}", info.json())?;
    } else {
        out!("{}", info.text())?;
    }
    let problems = &info.problems;
    if !problems.is_empty() {
        bail!(
            "{}: {} problem(s){}",
            args.sequence.display(),
            problems.len(),
            if args.json {
                format!(": {}", problems.join("; "))
            } else {
                " (listed above)".to_string()
            }
        );
    }
    Ok(())
}
