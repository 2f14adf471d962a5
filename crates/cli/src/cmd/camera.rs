//! `monovo camera`: the input camera and the output pinhole of a camera.txt.

use std::path::PathBuf;

use anyhow::Result;
use camera_model::{ImageSize, OutputMode};
use monovo_pipelines::summarize_camera;

/// Arguments of `monovo camera`.
#[derive(clap::Args, Debug)]
#[command(after_help = "\
Examples:
  monovo camera sequence_01/camera.txt
  monovo camera camera.txt --pinhole full --size 640x480
  monovo camera camera.txt --pinhole \"0.4 0.5333 0.5 0.5 0\" --json

The file is read as DSO reads it: lines after line 4 are ignored (listed below the cameras),
extra numbers after a model's parameters too; every such difference is a warning on stderr.
The output pinhole follows DSO's conventions: `crop` is the largest view without black
(invalid) pixels (at least DSO's view on every side), `full` keeps the whole input field of
view, `none` passes the raw image through with the input's fx fy cx cy (a distortion is
ignored, as in DSO), and `fx fy cx cy 0` is an explicit pinhole relative to the output size
(the paper's field-of-view experiments use f = fx * 640 at 640x480).")]
pub struct Args {
    /// The camera.txt file (DSO/benchmark format, 4 lines).
    pub camera_txt: PathBuf,
    /// The output pinhole camera, overriding line 3: crop, full, none, or "fx fy cx cy 0".
    #[arg(
        long = "pinhole",
        alias = "output",
        alias = "output-camera",
        value_name = "MODE"
    )]
    pub pinhole: Option<OutputMode>,
    /// Output size WIDTHxHEIGHT, overriding line 4.
    #[arg(long, value_name = "WxH")]
    pub size: Option<ImageSize>,
    /// Print only the output camera as one JSON object (pixels, pixel centres at integers).
    #[arg(long)]
    pub json: bool,
}

/// Runs `monovo camera`.
pub fn run(args: &Args) -> Result<()> {
    let summary = summarize_camera(&args.camera_txt, args.pinhole, args.size)?;
    for w in &summary.warnings {
        crate::warn(format_args!("{w}"));
    }
    if args.json {
        outln!("{}", summary.json())?;
    } else {
        out!("{}", summary.text())?;
    }
    Ok(())
}
