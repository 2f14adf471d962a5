//! `monovo demo`: the whole benchmark, end to end, on synthetic data with known truth.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use camera_model::{Image, ImageSize};
use dataset_io::{OutputDir, Sequence};
use eval_metrics::{
    cumulative, evaluate, summarize, DirectionFilter, GroundTruth, Metric, RunRecord,
};
use synthetic::trajectory::{
    benchmark_path, estimate, tum_text, Drift, EstimateConfig, PathConfig,
};

use crate::cmd::{calib, eval, eval_batch, plot as plotcmd, rectify, synth};
use crate::plot::{self, Chart, Corner, Figure, Series, PALETTE};

/// Marks a folder as written by `monovo demo`, so that a later demo may replace it.
const MARKER: &str = ".monovo-demo";

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

/// The paper's metric study: a x0.8 scale jump or a 10 degree rotation jump injected at each
/// point in time; e_align, e_t and e_rmse against where the jump happens.
fn metric_study(seed: u64, path: &Path) -> Result<()> {
    let p = benchmark_path(
        seed,
        &PathConfig {
            frames: 1000,
            ..PathConfig::default()
        },
    );
    let gt = GroundTruth::parse(&p.ground_truth_sync())?;
    let mut lines: Vec<(String, Vec<[f64; 2]>, usize, bool)> = Vec::new();
    for (jump, dashed) in [("scale x0.8", true), ("rotation 10 deg", false)] {
        let mut ea = Vec::new();
        let mut et = Vec::new();
        let mut er = Vec::new();
        for f in (p.segment_frames..p.len() - p.segment_frames).step_by(10) {
            let drift = if dashed {
                Drift {
                    scale_jumps: vec![(f, 0.8)],
                    ..Drift::default()
                }
            } else {
                Drift {
                    rotation_jumps: vec![(f, [0.2, 0.3, 1.0], 10.0)],
                    ..Drift::default()
                }
            };
            let cfg = EstimateConfig {
                drift,
                ..EstimateConfig::default()
            };
            let run = eval_metrics::parse_tum(&tum_text(&estimate(&p, &cfg, seed)))?;
            let e = evaluate(&run, &gt);
            let x = f as f64 / p.len() as f64;
            ea.push([x, e.metrics.e_align]);
            et.push([x, e.metrics.e_t]);
            er.push([x, e.metrics.e_rmse]);
        }
        lines.push((format!("e_align, {jump}"), ea, 0, dashed));
        lines.push((format!("e_t, {jump}"), et, 1, dashed));
        lines.push((format!("e_rmse, {jump}"), er, 2, dashed));
    }
    let mut c = Chart::new(
        "metric study: where the drift happens (dashed: scale x0.8, solid: rotation 10 deg)",
        "time of the jump (fraction of the sequence)",
        "error (ground-truth length unit)",
    );
    c.legend = Some(Corner::TopRight);
    c.x_range = Some([0.0, 1.0]);
    for (label, pts, color, dashed) in lines {
        let mut s = Series::line(label, pts, PALETTE[color]);
        if dashed {
            s = s.dashed();
        }
        c.series.push(s);
    }
    plot::save(&Figure::single(c, 1000, 600), path)
}

fn fmt_stat(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.3}")
    } else {
        "inf".into()
    }
}

/// One method's line of the demo's summary.
struct MethodLine {
    method: String,
    runs: usize,
    failed: usize,
    e_align: f64,
    e_r: f64,
    e_s_prime: f64,
}

fn method_lines(records: &[RunRecord]) -> Vec<MethodLine> {
    cumulative(records, Metric::EAlign, DirectionFilter::Both)
        .into_iter()
        .map(|c| {
            let rs: Vec<&RunRecord> = records.iter().filter(|r| r.key.method == c.label).collect();
            let med = |m: Metric| {
                let v: Vec<f64> = rs.iter().map(|r| m.value(&r.metrics)).collect();
                eval_metrics::Stat::of(&v).map_or(f64::NAN, |s| s.median)
            };
            MethodLine {
                runs: c.runs,
                failed: c.runs - c.values.len(),
                e_align: med(Metric::EAlign),
                e_r: med(Metric::ER),
                e_s_prime: med(Metric::ES),
                method: c.label,
            }
        })
        .collect()
}

const METHOD_HEADER: [&str; 6] = [
    "method",
    "runs",
    "failed",
    "median e_align",
    "median e_r (deg)",
    "median e'_s",
];

fn method_markdown(lines: &[MethodLine]) -> String {
    let mut s = format!(
        "| {} |\n|---|--:|--:|--:|--:|--:|\n",
        METHOD_HEADER.join(" | ")
    );
    for l in lines {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {} |",
            l.method,
            l.runs,
            l.failed,
            fmt_stat(l.e_align),
            fmt_stat(l.e_r),
            fmt_stat(l.e_s_prime)
        );
    }
    s
}

fn method_text(lines: &[MethodLine]) -> String {
    let w = lines
        .iter()
        .map(|l| l.method.len())
        .max()
        .unwrap_or(0)
        .max(6);
    let mut s = format!(
        "  {:<w$}  {:>5}  {:>6}  {:>14}  {:>16}  {:>11}\n",
        METHOD_HEADER[0],
        METHOD_HEADER[1],
        METHOD_HEADER[2],
        METHOD_HEADER[3],
        METHOD_HEADER[4],
        METHOD_HEADER[5]
    );
    for l in lines {
        let _ = writeln!(
            s,
            "  {:<w$}  {:>5}  {:>6}  {:>14}  {:>16}  {:>11}",
            l.method,
            l.runs,
            l.failed,
            fmt_stat(l.e_align),
            fmt_stat(l.e_r),
            fmt_stat(l.e_s_prime)
        );
    }
    s
}

/// Checks the demo's folder before any work: it must not exist, or (with --force) have been
/// written by an earlier demo, or be empty.
fn check_target(target: &Path, force: bool) -> Result<()> {
    OutputDir::check(target, force)?;
    if target.exists() {
        let earlier_demo = target.join(MARKER).is_file();
        let empty = std::fs::read_dir(target)
            .map(|mut d| d.next().is_none())
            .unwrap_or(false);
        if !earlier_demo && !empty {
            bail!(
                "{}: exists and was not written by `monovo demo`; refusing to replace it even with --force (choose another folder with -o)",
                target.display()
            );
        }
    }
    Ok(())
}

/// Runs `monovo demo`.
pub fn run(args: &Args) -> Result<()> {
    let started = Instant::now();
    let target = &args.output;
    check_target(target, args.force)?;
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
    let seq_args = synth::SequenceArgs {
        output: dir.join("sequence"),
        seed: args.seed,
        size: ImageSize::new(640, 512),
        frames: 200,
        sensor: demo_sensor(false),
        exposure: synth::SequenceExposureArgs::default(),
        force: false,
    };
    let truth_seq = synth::write_sequence(&seq_out, &seq_args)?;
    seq_out.commit()?;

    // 2. response calibration
    step(
        quiet,
        2,
        "calibrating the response from a synthetic exposure sweep",
    )?;
    let sweep_out = OutputDir::create(&dir.join("sweep"), false)?;
    let sweep_args = synth::SweepArgs {
        output: dir.join("sweep"),
        seed: args.seed,
        size: ImageSize::new(640, 512),
        frames: 60,
        min_exposure: 0.05,
        max_exposure: 20.0,
        step: None,
        bits: 8,
        sensor: demo_sensor(false),
        force: false,
    };
    let sweep = synth::write_sweep(&sweep_out, &sweep_args)?;
    sweep_out.commit()?;
    let sweep_seq = Sequence::open(&dir.join("sweep"))?;
    let (mut frames, exposures) = calib::load_exposed_frames(&sweep_seq)?;
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

    // 3. vignette calibration
    step(
        quiet,
        3,
        "calibrating the vignette from a marker-plane video (ArUco 213, 640x512, 100 frames)",
    )?;
    let vig_out = OutputDir::create(&dir.join("wall"), false)?;
    let vig_args = synth::VignetteArgs {
        output: dir.join("wall"),
        seed: args.seed,
        size: ImageSize::new(640, 512),
        frames: 100,
        sensor: demo_sensor(false),
        force: false,
    };
    let wall = synth::write_vignette_set(&vig_out, &vig_args)?;
    vig_out.commit()?;
    let t = Instant::now();
    let run = calib::calibrate_vignette_sequence(&calib::VignetteArgs {
        sequence: dir.join("wall"),
        output: dir.join("vignette_estimated.png"),
        force: false,
        pcalib: None,
        poses: None,
        marker_id: 213,
        config: None,
        max_iterations: None,
        smoothing: None,
        registration_px: None,
        plot: None,
        json: true,
    })?;
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
    if !quiet {
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

    // 4. rectification and photometric correction
    step(
        quiet,
        4,
        "rectifying the sequence to a 640x480 pinhole and undoing response and vignette",
    )?;
    let rect_args = rectify::Args {
        sequence: dir.join("sequence"),
        output: dir.join("rectified"),
        pinhole: None,
        size: Some(ImageSize::new(640, 480)),
        photometric: true,
        irradiance: false,
        mask_saturated: false,
        scale: None,
        reverse: false,
        range: None,
        depth: 8,
        zip: false,
        force: false,
        json: false,
    };
    let rectified = rectify::run(&rect_args)?;
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
    let rect = Sequence::open(&dir.join("rectified"))?;
    let k = rect
        .camera()
        .map(|c| c.input.intrinsics())
        .context("the rectified sequence has no camera.txt")?;
    let mid = rect.len() / 2;
    let raw_mid = Sequence::open(&dir.join("sequence"))?.decode(mid)?;
    dataset_io::write_png_u8(
        &dir.join("frame_raw.png"),
        raw_mid.width(),
        raw_mid.height(),
        1,
        raw_mid.data(),
        dataset_io::PngSpeed::Default,
    )?;
    let rect_mid = rect.decode(mid)?;
    // stretch the linear output for viewing
    let max = rect_mid.data().iter().copied().max().unwrap_or(1).max(1) as f32;
    let shown: Image<u8> = rect_mid.map(|v| ((v as f32 / max).sqrt() * 255.0) as u8);
    dataset_io::write_png_u8(
        &dir.join("frame_rectified.png"),
        640,
        480,
        1,
        shown.data(),
        dataset_io::PngSpeed::Default,
    )?;
    let _ = writeln!(
        md,
        "## Rectification\n\nFOV camera (omega {:.3}) at 640x512 to the `crop` pinhole at 640x480: fx={:.3} fy={:.3} cx={:.3} cy={:.3}; \
         response and vignette undone (linear output).\n\n![raw](frame_raw.png) ![rectified](frame_rectified.png)\n",
        truth_seq.camera.omega, k.fx, k.fy, k.cx, k.cy
    );

    // 5. results of two methods, evaluated
    step(
        quiet,
        5,
        "generating and evaluating 1000 runs of two synthetic VO methods",
    )?;
    let res_out = OutputDir::create(&dir.join("benchmark"), false)?;
    let res_args = synth::ResultsArgs {
        output: dir.join("benchmark"),
        seed: args.seed,
        sequences: 50,
        runs: 5,
        frames: 2000,
        force: false,
    };
    synth::write_results(&res_out, &res_args)?;
    res_out.commit()?;
    let csv = dir.join("results.csv");
    let batch = eval_batch::evaluate_tree(&eval_batch::Args {
        dataset: dir.join("benchmark/dataset"),
        results: dir.join("benchmark/results"),
        output: csv.clone(),
        force: false,
        keep_going: false,
        json: false,
    })?;
    let eval_secs = batch.seconds;
    let records = batch.records;
    if !quiet {
        outln!("      {} runs evaluated in {eval_secs:.2} s", records.len())?;
    }

    // 6. plots
    step(
        quiet,
        6,
        "plotting: cumulative errors, metric study, alignment figure",
    )?;
    for (metric, file, split) in [
        (
            Metric::EAlign,
            "cumulative_e_align.png",
            DirectionFilter::Both,
        ),
        (Metric::ER, "cumulative_e_r.png", DirectionFilter::Both),
        (Metric::ES, "cumulative_e_s.png", DirectionFilter::Split),
    ] {
        let chart = plotcmd::cumulative_chart(&records, metric, split);
        plot::save(&Figure::single(chart, 900, 600), &dir.join(file))?;
    }
    metric_study(args.seed, &dir.join("metric_study.png"))?;
    let gt_path = dir.join("benchmark/dataset/sequence_01/groundtruthSync.txt");
    let gt = eval::load_ground_truth(&gt_path)?;
    let run_path = dir.join("benchmark/results/feature/sequence_01/fwd_0.txt");
    let run = eval::load_trajectory(&run_path, eval::FormatArg::Auto, None)?;
    let ev = evaluate(&run, &gt);
    if ev.is_ok() {
        eval::alignment_figure(&ev, &gt, &dir.join("alignment.png"))?;
    }
    let table = eval_metrics::markdown_table(&summarize(&records, false));
    dataset_io::write_atomic(&dir.join("table.md"), table.as_bytes())?;

    // 7. summary
    step(quiet, 7, "writing summary.md")?;
    let lines = method_lines(&records);
    let _ = writeln!(
        md,
        "## Evaluation\n\n{} runs (2 methods x 50 sequences x fwd/bwd x 5 runs) evaluated in {eval_secs:.2} s.\n\n{}\n\
         ![e_align](cumulative_e_align.png)\n![e_r](cumulative_e_r.png)\n![e_s](cumulative_e_s.png)\n\n\
         The paper's metric study on one synthetic sequence: e_align depends much less on where the drift happens than e_t and e_rmse.\n\n\
         ![metric study](metric_study.png)\n\n![alignment](alignment.png)\n\nPer-sequence table: [table.md](table.md).\n",
        records.len(),
        method_markdown(&lines)
    );
    let total = started.elapsed().as_secs_f64();
    let _ = writeln!(md, "Total demo time: {total:.1} s.");
    dataset_io::write_atomic(&dir.join("summary.md"), md.as_bytes())?;
    let final_dir = out.commit()?;
    let files: Vec<(&str, &str)> = vec![
        ("summary.md", "the report, with every figure"),
        ("table.md", "the paper's per-sequence table"),
        ("results.csv", "1000 evaluated runs"),
        ("cumulative_e_align.png", "cumulative plots (also e_r, e_s)"),
        ("metric_study.png", "where drift happens vs. the metrics"),
        ("alignment.png", "start- and end-aligned trajectory"),
        ("response.png", "calibrated response vs. truth"),
        ("vignette.png", "calibrated vignette vs. truth"),
        ("frame_raw.png", "a raw frame (and frame_rectified.png)"),
        (
            "sequence/",
            "the synthetic sequence (rectified/: corrected)",
        ),
    ];
    if args.json {
        outln!(
            "{}",
            serde_json::json!({
                "output": final_dir.display().to_string(),
                "seconds": total,
                "seed": args.seed,
                "response": {"iterations": cal.iterations, "max_error_grey": max_err, "seconds": cal_secs},
                "vignette": {"rms_relative_error": vig_rms, "raw_rms_relative_error": raw_rms, "smoothing_px": vig_smoothing, "seconds": vig_secs},
                "rectified": rectified,
                "evaluation": {
                    "runs": records.len(),
                    "seconds": eval_secs,
                    "methods": lines.iter().map(|l| serde_json::json!({
                        "method": l.method, "runs": l.runs, "failed": l.failed,
                        "median_e_align": num(l.e_align), "median_e_r": num(l.e_r), "median_e_s_prime": num(l.e_s_prime),
                    })).collect::<Vec<_>>(),
                },
                "files": files.iter().map(|(f, _)| final_dir.join(f).display().to_string()).collect::<Vec<_>>(),
            })
        )?;
        return Ok(());
    }
    outln!()?;
    outln!("{}", method_text(&lines))?;
    outln!("wrote {} in {total:.0} s:", final_dir.display())?;
    let shown: Vec<(String, &str)> = files
        .iter()
        .map(|(f, what)| (final_dir.join(f).display().to_string(), *what))
        .collect();
    let w = shown.iter().map(|(f, _)| f.len()).max().unwrap_or(0);
    for (f, what) in &shown {
        outln!("  {f:<w$}  {what}")?;
    }
    Ok(())
}

fn num(v: f64) -> serde_json::Value {
    if v.is_finite() {
        serde_json::json!(v)
    } else {
        serde_json::Value::Null
    }
}

/// The demo's synthetic sensor: typical noise, the default response, JPEG 90 (or PNG).
fn demo_sensor(png: bool) -> synth::SensorArgs {
    synth::SensorArgs {
        noise: synthetic::sensor::NoiseLevel::Typical,
        response: synthetic::camera::ResponseCurve::Dataset,
        quality: 90,
        png,
    }
}
