//! `monovo camera`: the input camera and the output pinhole of a camera.txt.

use std::path::PathBuf;

use anyhow::{Context, Result};
use camera_model::{
    intrinsics_to_file_values, output_notes, CameraFile, CameraModel, ImageSize, OutputMode,
    RectifyMap,
};

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

/// Horizontal and vertical field of view (degrees) of any model, measured between the rays
/// through the outer edges of the image at the principal point's row and column.
fn model_field_of_view(model: &CameraModel, size: ImageSize) -> Option<(f64, f64)> {
    let k = model.intrinsics();
    let angle = |px: [f64; 2], axis: usize| -> Option<f64> {
        let r = model.unproject(px)?;
        Some(r[axis].atan2(r[2]).abs())
    };
    let cx = k.cx.clamp(0.0, size.width as f64 - 1.0);
    let cy = k.cy.clamp(0.0, size.height as f64 - 1.0);
    let h = angle([-0.5, cy], 0)? + angle([size.width as f64 - 0.5, cy], 0)?;
    let v = angle([cx, -0.5], 1)? + angle([cx, size.height as f64 - 0.5], 1)?;
    Some((h.to_degrees(), v.to_degrees()))
}

/// Runs `monovo camera`.
pub fn run(args: &Args) -> Result<()> {
    let path = &args.camera_txt;
    let text = dataset_io::read_text(path).context("the camera file")?;
    let file = CameraFile::parse(&text).with_context(|| format!("{}", path.display()))?;
    let mode = args.pinhole.unwrap_or(file.output);
    let out_size = args.size.unwrap_or(file.output_size);
    for w in
        file.warnings
            .iter()
            .chain(&output_notes(&file.input, file.input_size, &mode, out_size))
    {
        crate::warn(format_args!("{}: {w}", path.display()));
    }
    let map = RectifyMap::for_mode(&file.input, file.input_size, &mode, out_size)
        .with_context(|| format!("{}: output camera `{mode}` at {out_size}", path.display()))?;
    let k = map.camera();
    if mode == OutputMode::Crop && map.invalid_count() > 0 {
        crate::warn(format_args!(
            "{}: `crop` at {out_size} leaves {} output pixels without a source; a smaller --size or another --pinhole avoids them",
            path.display(),
            map.invalid_count()
        ));
    }
    if args.json {
        let obj = serde_json::json!({
            "fx": k.fx, "fy": k.fy, "cx": k.cx, "cy": k.cy,
            "width": out_size.width, "height": out_size.height,
        });
        outln!("{obj}")?;
        return Ok(());
    }
    outln!("input:  {} ({})", file.input, file.input_size)?;
    if let Some((h, v)) = model_field_of_view(&file.input, file.input_size) {
        outln!("        field of view {h:.1} x {v:.1} degrees")?;
    }
    outln!(
        "output: {mode} -> Pinhole fx={:.3} fy={:.3} cx={:.3} cy={:.3} ({out_size})",
        k.fx,
        k.fy,
        k.cx,
        k.cy
    )?;
    let (h, v) = k.field_of_view_deg(out_size.width, out_size.height);
    outln!("        field of view {h:.1} x {v:.1} degrees")?;
    let rel = intrinsics_to_file_values(&k, out_size);
    outln!(
        "        camera.txt line 3: {} {} {} {} 0",
        rel[0],
        rel[1],
        rel[2],
        rel[3]
    )?;
    let invalid = map.invalid_count();
    outln!(
        "        invalid (black) pixels: {invalid} ({:.2}%)",
        100.0 * invalid as f64 / out_size.pixels() as f64
    )?;
    if !file.ignored_lines.is_empty() {
        outln!("ignored (DSO reads only lines 1-4):")?;
        for (no, line) in &file.ignored_lines {
            let shown: String = line.chars().take(70).collect();
            let more = if shown.len() < line.len() { "..." } else { "" };
            outln!("        line {no}: {shown}{more}")?;
        }
    }
    Ok(())
}
