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
  monovo camera dso/camchain.yaml --cam 1 --pinhole \"0.3 0.3 0.5 0.5 0\" --size 512x512
  monovo camera tumvi_512_ds_calib.json --pinhole crop --size 512x512
  monovo camera mav0/cam0/sensor.yaml
  monovo camera sequences/00/calib.txt --cam 0      # size from image_0/ beside it

Reads the file's format from its content: DSO camera.txt, Kalibr camchain.yaml (pinhole,
omni, ds, eucm; distortion none, radtan, equidistant, fov), EuRoC sensor.yaml, Basalt
calibration.json (pinhole, kb4, ds, eucm, ucm, fov), KITTI calib.txt and ETH3D
calibration.txt. Files other than camera.txt default to `crop` at the input size.

The file is read as DSO reads it: lines after line 4 are ignored (listed below the cameras),
extra numbers after a model's parameters too; every such difference is a warning on stderr.
The output pinhole follows DSO's conventions: `crop` is the largest view without black
(invalid) pixels (at least DSO's view on every side), `full` keeps the whole input field of
view, `none` passes the raw image through with the input's fx fy cx cy (a distortion is
ignored, as in DSO), and `fx fy cx cy 0` is an explicit pinhole relative to the output size
(the paper's field-of-view experiments use f = fx * 640 at 640x480).")]
pub struct Args {
    /// The calibration file: camera.txt (DSO/benchmark), Kalibr camchain.yaml, EuRoC
    /// sensor.yaml, Basalt calibration.json, KITTI calib.txt or ETH3D calibration.txt.
    pub camera_txt: PathBuf,
    /// The camera of a file with several (Kalibr camN, Basalt's lists, KITTI's PN).
    #[arg(long, default_value_t = 0, value_name = "N")]
    pub cam: usize,
    /// The input image size WIDTHxHEIGHT, for files that give none (KITTI, ETH3D; default:
    /// the first image of image_N/ or rgb/ beside the file).
    #[arg(long, value_name = "WxH")]
    pub size_in: Option<ImageSize>,
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
    /// Print one JSON object: the output camera (`fx fy cx cy width height`, pixels, pixel
    /// centres at integers), the file's `format` and the `input` camera.
    #[arg(long)]
    pub json: bool,
}

/// Runs `monovo camera`.
pub fn run(args: &Args) -> Result<()> {
    let summary = summarize_camera(
        &args.camera_txt,
        args.cam,
        args.pinhole,
        args.size,
        args.size_in,
    )?;
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
