//! `monovo info`: what a sequence folder holds, and every problem that would stop
//! `monovo rectify` (or DSO), each with its file and line.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use dataset_io::Sequence;

use crate::progress;

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

/// Decodes every frame in parallel; the problems, one per frame that does not decode (the
/// first 20, and their number).
fn check_frames(seq: &Sequence) -> Vec<String> {
    use rayon::prelude::*;
    let pb = progress::bar(seq.len() as u64, "checking", "frames");
    let mut problems: Vec<String> = (0..seq.len())
        .into_par_iter()
        .filter_map(|k| {
            let r = seq.decode_native(k).err().map(|e| e.to_string());
            pb.inc(1);
            r
        })
        .collect();
    pb.finish_and_clear();
    if problems.len() > 20 {
        let more = problems.len() - 20;
        problems.truncate(20);
        problems.push(format!("... and {more} more frames that do not decode"));
    }
    problems
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
    let mut problems: Vec<String> = Vec::new();
    let camera_path = args.sequence.join("camera.txt");
    let camera = seq.camera().map(|c| {
        let out = camera_model::output_intrinsics(&c.input, c.input_size, &c.output, c.output_size);
        (c, out)
    });
    let mut warnings: Vec<String> = seq.times().warnings.clone();
    match &camera {
        Some((c, out)) => {
            let notes =
                camera_model::output_notes(&c.input, c.input_size, &c.output, c.output_size);
            for w in c.warnings.iter().chain(&notes) {
                warnings.push(format!("{}: {w}", camera_path.display()));
            }
            if let Err(e) = out {
                problems.push(format!(
                    "{}: line 3: output camera `{}` at {}: {e}",
                    camera_path.display(),
                    c.output,
                    c.output_size
                ));
            }
        }
        None => warnings.push(format!(
            "{}: absent; rectify and DSO need the camera model",
            camera_path.display()
        )),
    }
    let pcalib = seq.pcalib_path.as_ref().map(|p| {
        dataset_io::read_text(p)
            .map_err(anyhow::Error::from)
            .and_then(|t| {
                photometric::InverseResponse::parse_with_notes(&t)
                    .with_context(|| p.display().to_string())
            })
    });
    match (&seq.pcalib_path, &pcalib) {
        (Some(p), Some(Ok((u, notes)))) => {
            warnings.extend(notes.iter().map(|n| format!("{}: {n}", p.display())));
            let want = seq.bits_per_sample();
            if want == 8 && u.bits() != 8 {
                warnings.push(format!(
                    "{}: {} values ({}-bit) for 8-bit frames: looked up by full range, not exactly",
                    p.display(),
                    u.table().len(),
                    u.bits()
                ));
            }
        }
        (_, Some(Err(e))) => problems.push(format!("{e:#}")),
        _ => {}
    }
    let vignette = seq
        .vignette_path
        .as_ref()
        .map(|p| dataset_io::read_gray_map(p).map_err(anyhow::Error::from));
    if let Some(p) = &seq.vignette_path {
        if let Err(e) = crate::cmd::read_vignette(p, size) {
            problems.push(crate::error_chain(&e));
        }
    }
    let gt = seq
        .ground_truth_path
        .as_ref()
        .map(|p| crate::cmd::eval::load_ground_truth(p));
    if let Some(Err(e)) = &gt {
        problems.push(crate::error_chain(e));
    }
    let frame_problems = if args.quick {
        Vec::new()
    } else {
        check_frames(&seq)
    };
    let frames_ok = frame_problems.is_empty();
    problems.extend(frame_problems);
    if args.json {
        let obj = serde_json::json!({
            "sequence": args.sequence.display().to_string(),
            "frames": n,
            "images": if seq.is_zipped() { "images.zip" } else { "images/" },
            "width": size.width,
            "height": size.height,
            "bits": seq.bits_per_sample(),
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
            "frames_checked": !args.quick,
            "problems": problems,
            "warnings": warnings,
        });
        outln!("{obj}")?;
    } else {
        outln!("sequence:     {}", args.sequence.display())?;
        outln!(
            "images:       {} frames of {}, {}-bit, in {}",
            n,
            size,
            seq.bits_per_sample(),
            if seq.is_zipped() {
                "images.zip"
            } else {
                "images/"
            }
        )?;
        outln!("time:         {duration:.2} s at {fps:.2} fps (median frame interval)")?;
        match exposure {
            Some((a, b)) => outln!("exposure:     {a:.4} .. {b:.4} ms")?,
            None => outln!("exposure:     unknown (times.txt has two columns)")?,
        }
        match &camera {
            Some((c, Ok(k))) => outln!(
                "camera:       {} -> {} {} pinhole fx={:.2} fy={:.2} cx={:.2} cy={:.2}",
                c.input,
                c.output,
                c.output_size,
                k.fx,
                k.fy,
                k.cx,
                k.cy
            )?,
            Some((c, Err(_))) => outln!("camera:       {} (INVALID output camera)", c.input)?,
            None => outln!("camera:       no camera.txt")?,
        }
        match &pcalib {
            Some(Ok((u, _))) => outln!(
                "pcalib.txt:   valid inverse response, {} values ({}-bit)",
                u.table().len(),
                u.bits()
            )?,
            Some(Err(_)) => outln!("pcalib.txt:   INVALID")?,
            None => outln!("pcalib.txt:   absent")?,
        }
        match &vignette {
            Some(Ok((img, bits))) => {
                outln!("vignette.png: {}x{}, {bits}-bit", img.width(), img.height())?
            }
            Some(Err(_)) => outln!("vignette.png: INVALID")?,
            None => outln!("vignette.png: absent")?,
        }
        match &gt {
            Some(Ok(g)) => {
                let (s, e) = g.segment_sizes();
                outln!(
                    "ground truth: {} rows, {s} poses in the start segment, {e} in the end segment",
                    g.len()
                )?;
            }
            Some(Err(_)) => outln!("ground truth: INVALID")?,
            None => outln!("ground truth: absent")?,
        }
        if args.quick {
            outln!("frames:       not decoded (--quick)")?;
        } else if frames_ok {
            outln!("frames:       all {n} decode")?;
        }
        for w in &warnings {
            outln!("warning:      {w}")?;
        }
        for p in &problems {
            outln!("PROBLEM:      {p}")?;
        }
    }
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
