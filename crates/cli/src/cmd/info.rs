//! `monovo info`: what a sequence folder holds.

use std::path::PathBuf;

use anyhow::{Context, Result};
use dataset_io::Sequence;

/// Arguments of `monovo info`.
#[derive(clap::Args, Debug)]
#[command(after_help = "\
Example:
  monovo info sequence_01
  monovo info sequence_01 --json

Opening the sequence validates it: one times.txt row per image, increasing timestamps, the
camera's size equal to the images'. Calibration files are parsed and reported.")]
pub struct Args {
    /// The sequence folder (images.zip or images/, times.txt, camera.txt, ...).
    pub sequence: PathBuf,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
}

/// Runs `monovo info`.
pub fn run(args: &Args) -> Result<()> {
    let seq = Sequence::open(&args.sequence)?;
    let rows = &seq.times().rows;
    let n = seq.len();
    let duration = rows[n - 1].timestamp - rows[0].timestamp;
    let mut dts: Vec<f64> = rows
        .windows(2)
        .map(|w| w[1].timestamp - w[0].timestamp)
        .collect();
    dts.sort_by(f64::total_cmp);
    let fps = dts.get(dts.len() / 2).map_or(0.0, |d| 1.0 / d);
    let exposure = seq.times().exposure_range();
    let size = seq.image_size();
    let camera = seq.camera().map(|c| {
        let out = camera_model::output_intrinsics(&c.input, c.input_size, &c.output, c.output_size);
        (c, out)
    });
    let camera_path = args.sequence.join("camera.txt");
    let mut warnings: Vec<String> = seq.times().warnings.clone();
    if let Some(c) = seq.camera() {
        let notes = camera_model::output_notes(&c.input, c.input_size, &c.output, c.output_size);
        for w in c.warnings.iter().chain(&notes) {
            warnings.push(format!("{}: {w}", camera_path.display()));
        }
    }
    let pcalib = seq.pcalib_path.as_ref().map(|p| {
        dataset_io::read_text(p)
            .map_err(anyhow::Error::from)
            .and_then(|t| {
                photometric::InverseResponse::parse_with_notes(&t)
                    .with_context(|| p.display().to_string())
            })
    });
    if let (Some(p), Some(Ok((_, notes)))) = (&seq.pcalib_path, &pcalib) {
        warnings.extend(notes.iter().map(|n| format!("{}: {n}", p.display())));
    }
    let vignette = seq
        .vignette_path
        .as_ref()
        .map(|p| dataset_io::read_gray_map(p));
    let gt = seq
        .ground_truth_path
        .as_ref()
        .map(|p| crate::cmd::eval::load_ground_truth(p));
    if args.json {
        let obj = serde_json::json!({
            "sequence": args.sequence.display().to_string(),
            "frames": n,
            "images": if seq.is_zipped() { "images.zip" } else { "images/" },
            "width": size.width,
            "height": size.height,
            "duration_s": duration,
            "fps": fps,
            "exposure_ms": exposure.map(|(a, b)| serde_json::json!({"min": a, "max": b})),
            "camera": camera.as_ref().map(|(c, out)| serde_json::json!({
                "model": c.input.name(),
                "output": c.output.to_string(),
                "output_width": c.output_size.width,
                "output_height": c.output_size.height,
                "output_camera": out.as_ref().ok().map(|k| serde_json::json!({"fx": k.fx, "fy": k.fy, "cx": k.cx, "cy": k.cy})),
            })),
            "pcalib": pcalib.as_ref().map(|r| r.is_ok()),
            "vignette": vignette.as_ref().map(|r| r.as_ref().ok().map(|(i, bits)| serde_json::json!({"width": i.width(), "height": i.height(), "bits": bits}))),
            "ground_truth": gt.as_ref().and_then(|r| r.as_ref().ok()).map(|g| {
                let (s, e) = g.segment_sizes();
                serde_json::json!({"rows": g.len(), "start_segment": s, "end_segment": e})
            }),
            "warnings": warnings,
        });
        println!("{obj}");
        return Ok(());
    }
    println!("sequence:     {}", args.sequence.display());
    println!(
        "images:       {} frames of {}, {}-bit, in {}",
        n,
        size,
        seq.bits_per_sample(),
        if seq.is_zipped() {
            "images.zip"
        } else {
            "images/"
        }
    );
    println!("time:         {duration:.2} s at {fps:.2} fps (median frame interval)");
    match exposure {
        Some((a, b)) => println!("exposure:     {a:.4} .. {b:.4} ms"),
        None => println!("exposure:     unknown (times.txt has two columns)"),
    }
    match &camera {
        Some((c, Ok(k))) => println!(
            "camera:       {} -> {} {} pinhole fx={:.2} fy={:.2} cx={:.2} cy={:.2}",
            c.input, c.output, c.output_size, k.fx, k.fy, k.cx, k.cy
        ),
        Some((c, Err(e))) => println!("camera:       {} (output: {e})", c.input),
        None => println!("camera:       no camera.txt"),
    }
    match &pcalib {
        Some(Ok((u, _))) => println!(
            "pcalib.txt:   valid inverse response, {} values ({}-bit)",
            u.table().len(),
            u.bits()
        ),
        Some(Err(e)) => println!("pcalib.txt:   INVALID: {e:#}"),
        None => println!("pcalib.txt:   absent"),
    }
    match &vignette {
        Some(Ok((img, bits))) => {
            println!("vignette.png: {}x{}, {bits}-bit", img.width(), img.height(),)
        }
        Some(Err(e)) => println!("vignette.png: INVALID: {e}"),
        None => println!("vignette.png: absent"),
    }
    match &gt {
        Some(Ok(g)) => {
            let (s, e) = g.segment_sizes();
            println!(
                "ground truth: {} rows, {s} poses in the start segment, {e} in the end segment",
                g.len()
            );
        }
        Some(Err(e)) => println!("ground truth: INVALID: {e:#}"),
        None => println!("ground truth: absent"),
    }
    for w in &warnings {
        println!("warning:      {w}");
    }
    Ok(())
}
