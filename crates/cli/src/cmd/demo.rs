//! `monovo demo`: the whole benchmark, end to end, on synthetic data with known truth.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Result;
use camera_model::ImageSize;
use dataset_io::{OutputDir, Sequence};
use monovo_pipelines::demo::{
    check_demo_target, demo_files, demo_files_text, evaluate_benchmark, write_frame_previews,
    MARKER,
};
use monovo_pipelines::paper::{medians_json, medians_text};
use monovo_pipelines::{rectify, synth};

use crate::cmd::calib;
use crate::progress::Bars;

/// Arguments of `monovo demo`.
#[derive(clap::Args, Debug)]
#[command(after_help = "\
Generates a small benchmark with known truth and runs every job on it:
  1. a benchmark-like sequence (textured room, FOV camera, vignette, response, exposures)
  2. a response-calibration sweep; calibrates U and compares it with the truth
  3. a marker-plane video; calibrates the vignette V and compares it with the truth
  4. rectifies the sequence to a pinhole camera and undoes response and vignetting
  5. 1000 runs of two synthetic VO methods (50 sequences x fwd/bwd x 5 runs); evaluates all
  6. the paper's cumulative error plots, its metric study, an alignment figure, a table
and writes summary.md. Takes about a minute on two cores. DIR must not exist unless --force,
and --force replaces only a folder that an earlier demo wrote (or an empty one).")]
pub struct Args {
    /// Output folder (must not exist unless --force).
    #[arg(short, long, default_value = "monovo-demo", value_name = "DIR")]
    pub output: PathBuf,
    /// Replace the folder of an earlier demo.
    #[arg(long)]
    pub force: bool,
    /// Random seed of every synthetic data set.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Print one JSON object (the results and the files) instead of text.
    #[arg(long)]
    pub json: bool,
}

fn step(quiet: bool, n: usize, what: &str) -> Result<()> {
    if !quiet {
        outln!("[{n}/7] {what}")?;
    }
    Ok(())
}

/// Runs `monovo demo`.
pub fn run(args: &Args) -> Result<()> {
    let started = Instant::now();
    let target = &args.output;
    check_demo_target(target, args.force)?;
    let quiet = args.json;
    let out = OutputDir::create(target, args.force)?;
    out.write(MARKER, b"written by monovo demo\n")?;
    let dir = out.path().to_path_buf();
    let mut md = String::new();
    let _ = writeln!(md, "# monovo demo (seed {})\n", args.seed);

    // 1. sequence
    step(
        quiet,
        1,
        "rendering a benchmark-like sequence (640x512, 200 frames, FOV camera)",
    )?;
    let seq_out = OutputDir::create(&dir.join("sequence"), false)?;
    let seq_spec = synth::SequenceSpec {
        seed: args.seed,
        size: ImageSize::new(640, 512),
        frames: 200,
        ..Default::default()
    };
    let truth_seq = synth::write_sequence(&seq_out, &seq_spec, &Bars::default())?;
    seq_out.commit()?;

    // 2. response calibration
    step(
        quiet,
        2,
        "calibrating the response from a synthetic exposure sweep",
    )?;
    let sweep_out = OutputDir::create(&dir.join("sweep"), false)?;
    let sweep_spec = synth::SweepSpec {
        seed: args.seed,
        size: ImageSize::new(640, 512),
        frames: 60,
        ..Default::default()
    };
    let sweep = synth::write_sweep(&sweep_out, &sweep_spec, &Bars::default())?;
    sweep_out.commit()?;
    let sweep_seq = Sequence::open(&dir.join("sweep"))?;
    let (mut frames, exposures) =
        calib::load_exposed_frames(&sweep_seq, &monovo_pipelines::Silent)?;
    let t = Instant::now();
    let cal = photometric::calibrate_response(
        &mut frames,
        &exposures,
        &photometric::ResponseOptions::default(),
        &|_, _| {},
    )?;
    let cal_secs = t.elapsed().as_secs_f64();
    drop(frames);
    dataset_io::write_atomic(
        &dir.join("pcalib_estimated.txt"),
        cal.response.to_text().as_bytes(),
    )?;
    calib::response_figure(&cal, Some(&sweep.response[..]), &dir.join("response.png"))?;
    let (max_err, _) = cal.response.errors_against(&sweep.response);
    if !quiet {
        outln!(
            "      {} iterations, max |U - U_true| = {max_err:.3} grey levels, {cal_secs:.1} s",
            cal.iterations
        )?;
    }
    let _ = writeln!(
        md,
        "## Response calibration\n\n60 exposures of a static scene (640x512, 0.05 to 20 ms, typical sensor noise, JPEG 90): converged in {} iterations \
         ({cal_secs:.1} s); max |U - U_true| over 0..254 = **{max_err:.3}** grey levels, residual RMSE {:.3}.\n\n![response](response.png)\n",
        cal.iterations, cal.rmse
    );

    let vig = vignette_step(args, &dir, &mut md)?;
    let rectified = rectify_step(quiet, &dir, truth_seq.camera.omega, &mut md)?;

    // 5. results of two methods, evaluated
    step(
        quiet,
        5,
        "generating and evaluating 1000 runs of two synthetic VO methods",
    )?;
    let res_out = OutputDir::create(&dir.join("benchmark"), false)?;
    let res_spec = synth::ResultsSpec {
        seed: args.seed,
        ..Default::default()
    };
    synth::write_results(&res_out, &res_spec, &Bars::default())?;
    res_out.commit()?;
    let evaluation = evaluate_benchmark(&dir, &Bars::default())?;
    let (records, eval_secs, lines) =
        (&evaluation.records, evaluation.seconds, &evaluation.medians);
    if !quiet {
        outln!("      {} runs evaluated in {eval_secs:.2} s", records.len())?;
    }
    step(
        quiet,
        6,
        "plotting: cumulative errors, metric study, alignment figure",
    )?;
    evaluation.draw(&dir, args.seed)?;

    // 7. summary
    step(quiet, 7, "writing summary.md")?;
    md.push_str(&evaluation.markdown());
    let total = started.elapsed().as_secs_f64();
    let _ = writeln!(md, "Total demo time: {total:.1} s.");
    dataset_io::write_atomic(&dir.join("summary.md"), md.as_bytes())?;
    let final_dir = out.commit()?;
    if args.json {
        outln!(
            "{}",
            serde_json::json!({
                "output": final_dir.display().to_string(),
                "seconds": total,
                "seed": args.seed,
                "response": {"iterations": cal.iterations, "max_error_grey": max_err, "seconds": cal_secs},
                "vignette": {"rms_relative_error": vig.rms, "raw_rms_relative_error": vig.raw_rms, "smoothing_px": vig.smoothing_px, "seconds": vig.seconds},
                "rectified": rectified,
                "evaluation": {
                    "runs": records.len(),
                    "seconds": eval_secs,
                    "methods": medians_json(lines),
                },
                "files": demo_files(&final_dir),
            })
        )?;
        return Ok(());
    }
    outln!()?;
    outln!("{}", medians_text(lines))?;
    outln!("wrote {} in {total:.0} s:", final_dir.display())?;
    out!("{}", demo_files_text(&final_dir))?;
    Ok(())
}

/// What the vignette step measured.
struct VignetteSummary {
    rms: f64,
    raw_rms: f64,
    smoothing_px: f64,
    seconds: f64,
}

/// Step 3: a marker-plane video, its vignette calibrated and compared with the truth.
fn vignette_step(args: &Args, dir: &Path, md: &mut String) -> Result<VignetteSummary> {
    let dir = dir.to_path_buf();
    step(
        args.json,
        3,
        "calibrating the vignette from a marker-plane video (ArUco 213, 640x512, 100 frames)",
    )?;
    let vig_out = OutputDir::create(&dir.join("wall"), false)?;
    let vig_spec = synth::VignetteSetSpec {
        seed: args.seed,
        size: ImageSize::new(640, 512),
        frames: 100,
        ..Default::default()
    };
    let wall = synth::write_vignette_set(&vig_out, &vig_spec, &Bars::default())?;
    vig_out.commit()?;
    let t = Instant::now();
    let run = calib::calibrate_vignette_sequence(
        &calib::VignetteJob {
            sequence: dir.join("wall"),
            pcalib: None,
            poses: None,
            marker_id: 213,
            bit_depth: None,
            options: photometric::VignetteOptions::default(),
            scratch: Some(dir.clone()),
        },
        &monovo_pipelines::Silent,
    )?;
    let vig_secs = t.elapsed().as_secs_f64();
    let vig_smoothing = run.cal.smoothing.sigma_px;
    let (vig_rms, _) = photometric::vignette_errors(run.cal.vignette.data(), &wall.vignette);
    let (raw_rms, vig_valid) = photometric::vignette_errors(run.cal.raw.data(), &wall.vignette);
    let v16: Vec<u16> = run
        .cal
        .vignette
        .data()
        .iter()
        .map(|v| (v * 65535.0).round().clamp(0.0, 65535.0) as u16)
        .collect();
    let (w, h) = run.cal.vignette.size();
    dataset_io::write_png_u16(
        &dir.join("vignette_estimated.png"),
        w,
        h,
        &v16,
        dataset_io::PngSpeed::Default,
    )?;
    calib::vignette_figure(&run.cal, Some(&wall.vignette), &dir.join("vignette.png"))?;
    if !args.json {
        outln!(
            "      RMS relative error of V: {:.3}% (raw map {:.3}%), smoothing {:.1} px chosen by cross-validation ({vig_secs:.1} s)",
            vig_rms * 100.0,
            raw_rms * 100.0,
            run.cal.smoothing.sigma_px
        )?;
    }
    let _ = writeln!(
        md,
        "## Vignette calibration\n\n100 frames of a bright wall with ArUco marker 213 (poses from the detected marker, {} used): \
         RMS relative error of the recommended V against the truth **{:.3}%**, of the paper's raw map {:.3}% over {:.1}% of the pixels; \
         smoothing {:.1} px chosen by cross-validation ({vig_secs:.1} s).\n\n![vignette](vignette.png)\n",
        run.used,
        vig_rms * 100.0,
        raw_rms * 100.0,
        100.0 * vig_valid,
        run.cal.smoothing.sigma_px
    );

    Ok(VignetteSummary {
        rms: vig_rms,
        raw_rms,
        smoothing_px: vig_smoothing,
        seconds: vig_secs,
    })
}

/// Step 4: the sequence rectified to a 640x480 pinhole, response and vignette undone.
fn rectify_step(
    quiet: bool,
    dir: &Path,
    omega: f64,
    md: &mut String,
) -> Result<rectify::Rectified> {
    step(
        quiet,
        4,
        "rectifying the sequence to a 640x480 pinhole and undoing response and vignette",
    )?;
    let rect_job = rectify::RectifyJob {
        size: Some(ImageSize::new(640, 480)),
        photometric: true,
        ..rectify::RectifyJob::new(dir.join("sequence"), dir.join("rectified"))
    };
    let rectified = rectify::rectify_sequence(&rect_job, &Bars::default())?;
    if !quiet {
        outln!(
            "      {} frames to fx={:.1} fy={:.1} cx={:.1} cy={:.1} in {:.1} s ({:.0} frames/s)",
            rectified.frames,
            rectified.fx,
            rectified.fy,
            rectified.cx,
            rectified.cy,
            rectified.seconds,
            rectified.frames as f64 / rectified.seconds.max(1e-9)
        )?;
    }
    let k = write_frame_previews(dir)?;
    let _ = writeln!(
        md,
        "## Rectification\n\nFOV camera (omega {:.3}) at 640x512 to the `crop` pinhole at 640x480: fx={:.3} fy={:.3} cx={:.3} cy={:.3}; \
         response and vignette undone (linear output).\n\n![raw](frame_raw.png) ![rectified](frame_rectified.png)\n",
        omega, k.fx, k.fy, k.cx, k.cy
    );

    Ok(rectified)
}
