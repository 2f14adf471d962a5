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

Checks what `monovo rectify` checks: one times.txt row per image, increasing timestamps,
exposures (zeros that are interpolated or unknown), ids that name the images, camera.txt and
its output camera, the camera's size equal to the images', pcalib.txt (2^k finite, strictly
increasing values), vignette.png (grey, at the images' size), groundtruthSync.txt, and that
every frame decodes (a truncated or corrupt JPEG). Each problem is listed with its file (and
line); the exit code is non-zero when there is one. Warnings do not change the exit code.")]
pub struct Args {
    /// The sequence folder (images.zip or images/, times.txt, camera.txt, ...).
    pub sequence: PathBuf,
    /// Print one JSON object (with the lists `problems` and `warnings`).
    #[arg(long)]
    pub json: bool,
    /// Do not decode every frame (only the first, as opening the sequence does).
    #[arg(long)]
    pub quick: bool,
}

/// Runs `monovo info`.
pub fn run(args: &Args) -> Result<()> {
    let info = inspect_sequence(&args.sequence, args.quick, &Bars::default())?;
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
