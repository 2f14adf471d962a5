//! `monovo exposure`: exposure times measured from the images, to check logged ones and to
//! estimate missing ones.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use dataset_io::{GrayImage, Sequence};
use photometric::exposure::{
    check_exposures, estimate_exposures, measure_ratio, ExposureCheck, ExposureEstimate,
    ExposureMeter, ExposureOptions, MeteredFrame, PairRatio, RatioMeasurement, Verdict,
};
use photometric::{InverseResponse, Vignette};
use rayon::prelude::*;

use crate::plot::{self, Chart, Corner, Figure, Panel, Series, PALETTE};
use crate::progress;

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
    match &args.what {
        What::Check(a) => run_check(a),
        What::Estimate(a) => run_estimate(a),
    }
}

/// The options from the shared arguments.
fn options(i: &InputArgs) -> Result<ExposureOptions> {
    let mut o = ExposureOptions::default();
    if !(i.min_grey.is_finite() && i.max_grey.is_finite() && 0.0 <= i.min_grey)
        || i.min_grey >= i.max_grey
        || i.max_grey > 255.0
    {
        bail!(
            "--min-grey {} and --max-grey {} must lie in 0..255, the first below the second",
            i.min_grey,
            i.max_grey
        );
    }
    if !(i.max_std_error.is_finite() && i.max_std_error > 0.0) {
        bail!(
            "--max-std-error must be a positive number, got {}",
            i.max_std_error
        );
    }
    o.min_grey = i.min_grey;
    o.max_grey = i.max_grey;
    o.max_std_error = i.max_std_error;
    Ok(o)
}

/// The 1-based line numbers of times.txt's data rows (blank and `#` lines are skipped, as
/// the parser skips them).
fn data_lines(text: &str) -> Vec<usize> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    text.lines()
        .enumerate()
        .filter(|(_, l)| {
            let t = l.trim();
            !t.is_empty() && !t.starts_with('#')
        })
        .map(|(i, _)| i + 1)
        .collect()
}

/// The meter of a sequence: its response and vignette (or the given files).
fn meter_for(
    seq: &Sequence,
    input: &InputArgs,
    opts: &ExposureOptions,
) -> Result<(ExposureMeter, u32)> {
    let pcalib = match (&input.pcalib, &seq.pcalib_path) {
        (Some(p), _) => p.clone(),
        (None, Some(p)) => p.clone(),
        (None, None) => bail!(
            "{}: no pcalib.txt: measuring exposure ratios needs the inverse response (give --pcalib FILE, or calibrate it with `monovo calib response`)",
            seq.dir().display()
        ),
    };
    let (u, notes) = InverseResponse::parse_with_notes(&dataset_io::read_text(&pcalib)?)
        .with_context(|| pcalib.display().to_string())?;
    for n in notes {
        eprintln!("monovo: warning: {}: {n}", pcalib.display());
    }
    let size = seq.image_size();
    let vig_path = input.vignette.clone().or_else(|| seq.vignette_path.clone());
    let vignette = match &vig_path {
        Some(p) => {
            let (img, _) = dataset_io::read_gray_map(p)?;
            let v = Vignette::from_u16(&img).with_context(|| p.display().to_string())?;
            let (w, h) = v.size();
            if (w, h) != (size.width, size.height) {
                bail!(
                    "{}: the vignette is {w}x{h} but the images are {size}",
                    p.display()
                );
            }
            Some(v)
        }
        None => {
            eprintln!(
                "monovo: warning: {}: no vignette.png: V = 1 (the vignetting then biases every ratio of frames that move)",
                seq.dir().display()
            );
            None
        }
    };
    let in_bits = seq.bits_per_sample();
    let bits = match input.bit_depth {
        Some(b) if in_bits == 8 && b != 8 => bail!(
            "--bit-depth {b}: the frames of {} are 8-bit; --bit-depth describes 16-bit frames whose values use fewer bits",
            seq.dir().display()
        ),
        Some(b) => b,
        None => in_bits,
    };
    let meter = ExposureMeter::new(&u, vignette.as_ref(), (size.width, size.height), opts)
        .with_context(|| seq.dir().display().to_string())?;
    Ok((meter, bits))
}

/// The measured ratios of consecutive frames and (with `skip`) of frames two apart.
struct Ratios {
    consecutive: Vec<RatioMeasurement>,
    skip: Vec<RatioMeasurement>,
    /// Seconds spent.
    seconds: f64,
}

/// Decodes and meters every frame in parallel chunks (memory stays flat) and measures the
/// pairs.
fn measure(
    seq: &Sequence,
    meter: &ExposureMeter,
    bits: u32,
    opts: &ExposureOptions,
    skip: bool,
) -> Result<Ratios> {
    let start = Instant::now();
    let n = seq.len();
    let pb = progress::bar(n as u64, "measuring", "frames");
    let chunk = (rayon::current_num_threads() * 4).max(8);
    let mut consecutive = vec![None; n.saturating_sub(1)];
    let mut skipped = vec![None; if skip { n.saturating_sub(2) } else { 0 }];
    // the last two metered frames of the previous chunk, with their indices
    let mut carry: Vec<(usize, MeteredFrame)> = Vec::new();
    let indices: Vec<usize> = (0..n).collect();
    for part in indices.chunks(chunk) {
        let metered: Vec<(usize, MeteredFrame)> = part
            .par_iter()
            .map(|&k| -> Result<(usize, MeteredFrame)> {
                let img = seq.decode_native(k)?;
                let m = match &img {
                    GrayImage::U8(i) => meter.frame_u8(i),
                    GrayImage::U16(i) => meter.frame_u16(i, bits),
                }
                .with_context(|| {
                    format!("{}: frame {k} ({})", seq.dir().display(), seq.names()[k])
                })?;
                Ok((k, m))
            })
            .collect::<Result<_>>()?;
        let mut all = std::mem::take(&mut carry);
        all.extend(metered);
        let first = all[0].0;
        let at = |k: usize| &all[k - first].1;
        let mut jobs: Vec<(usize, usize)> = Vec::new();
        for &k in part {
            if k >= 1 {
                jobs.push((k - 1, k));
            }
            if skip && k >= 2 {
                jobs.push((k - 2, k));
            }
        }
        let results: Vec<((usize, usize), RatioMeasurement)> = jobs
            .par_iter()
            .map(|&(i, j)| ((i, j), measure_ratio(at(i), at(j), opts)))
            .collect();
        for ((i, j), m) in results {
            if j == i + 1 {
                consecutive[i] = Some(m);
            } else {
                skipped[i] = Some(m);
            }
        }
        pb.inc(part.len() as u64);
        let keep = all.len().saturating_sub(2);
        carry = all.split_off(keep);
    }
    pb.finish_and_clear();
    let unwrap = |v: Vec<Option<RatioMeasurement>>| -> Vec<RatioMeasurement> {
        v.into_iter()
            .map(|m| m.unwrap_or_else(|| empty_measurement("not measured")))
            .collect()
    };
    Ok(Ratios {
        consecutive: unwrap(consecutive),
        skip: unwrap(skipped),
        seconds: start.elapsed().as_secs_f64(),
    })
}

fn empty_measurement(note: &str) -> RatioMeasurement {
    RatioMeasurement {
        log_ratio: f64::NAN,
        std_error: f64::INFINITY,
        shift: [f64::NAN; 2],
        tiles: 0,
        pixel_spread: f64::NAN,
        reliable: false,
        note: note.into(),
    }
}

/// A number for JSON: `null` when not finite.
fn num(v: f64) -> serde_json::Value {
    if v.is_finite() {
        serde_json::json!(v)
    } else {
        serde_json::Value::Null
    }
}

/// Lists at most `max` items, then how many more.
fn list(v: &[usize], max: usize) -> String {
    let shown: Vec<String> = v.iter().take(max).map(|k| k.to_string()).collect();
    if v.len() > max {
        format!("{} and {} more", shown.join(", "), v.len() - max)
    } else {
        shown.join(", ")
    }
}

fn check_outputs(paths: &[&Path], force: bool) -> Result<()> {
    for p in paths {
        dataset_io::check_output_file(p, force)?;
    }
    Ok(())
}

fn run_check(a: &CheckArgs) -> Result<()> {
    let mut outs: Vec<&Path> = Vec::new();
    if let Some(o) = &a.output {
        outs.push(o);
    }
    if let Some(p) = &a.plot {
        plot::format_of(p)?;
        outs.push(p);
    }
    check_outputs(&outs, a.force)?;
    let mut opts = options(&a.input)?;
    if !(a.flag_sigmas.is_finite() && a.flag_sigmas > 0.0) {
        bail!("--flag-sigmas must be positive, got {}", a.flag_sigmas);
    }
    if !(a.min_difference.is_finite() && a.min_difference >= 0.0) {
        bail!(
            "--min-difference must be a percentage of at least 0, got {}",
            a.min_difference
        );
    }
    opts.flag_sigmas = a.flag_sigmas;
    opts.min_difference = (a.min_difference / 100.0).ln_1p();
    let seq = Sequence::open(&a.sequence)?;
    for w in &seq.times().warnings {
        eprintln!("monovo: warning: {w}");
    }
    let times_text = dataset_io::read_text(seq.times_path())?;
    let lines = data_lines(&times_text);
    let mut logged = Vec::with_capacity(seq.len());
    for (k, row) in seq.times().rows.iter().enumerate() {
        let line = lines.get(k).copied().unwrap_or(k + 1);
        match row.exposure_ms {
            Some(t) if t > 0.0 => logged.push(t),
            Some(t) => bail!(
                "{}: line {line}: exposure {t} ms; `exposure check` needs a positive exposure on every line (`monovo exposure estimate` measures them from the images)",
                seq.times_path().display()
            ),
            None => bail!(
                "{}: line {line}: no exposure (third column); `exposure check` compares logged exposures with the images; for a sequence without them, `monovo exposure estimate {} -o times.txt` measures them",
                seq.times_path().display(),
                a.sequence.display()
            ),
        }
    }
    if seq.len() < 3 {
        bail!(
            "{}: {} frames; checking exposures needs at least 3",
            a.sequence.display(),
            seq.len()
        );
    }
    let (meter, bits) = meter_for(&seq, &a.input, &opts)?;
    let ratios = measure(&seq, &meter, bits, &opts, false)?;
    let check = check_exposures(&logged, &ratios.consecutive, &opts)
        .with_context(|| a.sequence.display().to_string())?;
    if let Some(out) = &a.output {
        let fixed = fixed_times(&times_text, &lines, &check)?;
        dataset_io::write_atomic(out, fixed.as_bytes())?;
    }
    if let Some(p) = &a.plot {
        check_figure(&check, &ratios.consecutive, &logged, p)?;
    }
    let per_frame_ms = 1e3 * ratios.seconds / seq.len() as f64;
    if a.json {
        let ratio_json: Vec<serde_json::Value> = ratios
            .consecutive
            .iter()
            .enumerate()
            .map(|(i, m)| {
                serde_json::json!({
                    "frame": i,
                    "logged": logged[i + 1] / logged[i],
                    "measured": num(m.log_ratio.exp()),
                    "std_error": num(m.std_error),
                    "reliable": m.reliable,
                    "shift_px": [num(m.shift[0]), num(m.shift[1])],
                    "tiles": m.tiles,
                    "note": m.note,
                })
            })
            .collect();
        let checks: Vec<serde_json::Value> = check
            .frames
            .iter()
            .map(|c| {
                serde_json::json!({
                    "frame": c.frame,
                    "logged_ms": c.logged_ms,
                    "predicted_ms": num(c.predicted_ms),
                    "std_error": num(c.std_error),
                    "z": num(c.z),
                    "verdict": c.verdict,
                    "note": c.note,
                })
            })
            .collect();
        println!(
            "{}",
            serde_json::json!({
                "sequence": a.sequence.display().to_string(),
                "frames": seq.len(),
                "shifted": check.shifted,
                "inconsistent": check.inconsistent,
                "undecided": check.undecided,
                "unreliable_pairs": check.unreliable_pairs,
                "log_lag": check.log_lag,
                "lag_scores": {
                    "-1": num(check.lag_scores[0]),
                    "0": num(check.lag_scores[1]),
                    "1": num(check.lag_scores[2]),
                },
                "ratios": ratio_json,
                "checks": checks,
                "measured_ms": check.measured_ms.iter().map(|v| num(*v)).collect::<Vec<_>>(),
                "fixed": a.output.as_ref().map(|p| p.display().to_string()),
                "plot": a.plot.as_ref().map(|p| p.display().to_string()),
                "ms_per_frame": per_frame_ms,
            })
        );
        return Ok(());
    }
    let reliable = ratios.consecutive.iter().filter(|m| m.reliable).count();
    println!(
        "{} frames, {} of {} consecutive ratios measured reliably ({:.1} ms per frame)",
        seq.len(),
        reliable,
        ratios.consecutive.len(),
        per_frame_ms
    );
    if !check.unreliable_pairs.is_empty() {
        println!(
            "unreliable pairs (motion blur, fast motion or a cut; no frame is flagged on them): {}",
            list(&check.unreliable_pairs, 12)
        );
    }
    match check.log_lag {
        1 => println!(
            "the whole log is one frame late: every frame's logged exposure fits its previous frame (median {:.1} standard errors as logged, {:.1} moved)",
            check.lag_scores[1], check.lag_scores[2]
        ),
        -1 => println!(
            "the whole log is one frame early: every frame's logged exposure fits its next frame (median {:.1} standard errors as logged, {:.1} moved)",
            check.lag_scores[1], check.lag_scores[0]
        ),
        _ => {}
    }
    if check.shifted.is_empty() {
        println!("no logged exposure is shifted by a frame");
    } else {
        println!(
            "{} logged exposure(s) belong to a neighbouring frame:",
            check.shifted.len()
        );
        for &k in &check.shifted {
            let c = &check.frames[k];
            let from = match c.verdict {
                Verdict::ShiftedFromPrevious => "the previous frame's",
                _ => "the next frame's",
            };
            println!(
                "  frame {k} ({}): logged {:.4} ms, measured {:.4} ms ({:+.1}%, {:.0} standard errors); the log is {from}",
                seq.times().rows[k].id,
                c.logged_ms,
                c.predicted_ms,
                100.0 * (c.logged_ms / c.predicted_ms - 1.0),
                c.z.abs()
            );
        }
    }
    if !check.inconsistent.is_empty() {
        println!(
            "logged exposures that contradict the images but fit no neighbour: frames {}",
            list(&check.inconsistent, 20)
        );
    }
    if !check.undecided.is_empty() {
        println!(
            "no decision for {} frame(s) (unreliable or contradictory ratios around them): {}",
            check.undecided.len(),
            list(&check.undecided, 20)
        );
    }
    if let Some(o) = &a.output {
        println!(
            "wrote {} ({} exposure(s) replaced)",
            o.display(),
            check.shifted.len()
        );
    }
    if let Some(p) = &a.plot {
        println!("wrote {}", p.display());
    }
    Ok(())
}

/// times.txt with every shifted frame's exposure replaced by its prediction; other lines as
/// they were.
fn fixed_times(text: &str, lines: &[usize], check: &ExposureCheck) -> Result<String> {
    let had_bom = text.starts_with('\u{feff}');
    let body = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut replace = std::collections::HashMap::new();
    for &k in &check.shifted {
        let Some(&line) = lines.get(k) else {
            bail!("times.txt has no row {k}");
        };
        replace.insert(line, check.frames[k].predicted_ms);
    }
    let mut out = String::with_capacity(text.len());
    if had_bom {
        out.push('\u{feff}');
    }
    for (i, l) in body.split_inclusive('\n').enumerate() {
        match replace.get(&(i + 1)) {
            Some(t) => {
                let end = if l.ends_with("\r\n") {
                    "\r\n"
                } else if l.ends_with('\n') {
                    "\n"
                } else {
                    ""
                };
                let mut tokens: Vec<String> = l.split_whitespace().map(|s| s.to_string()).collect();
                if tokens.len() < 3 {
                    bail!("times.txt line {}: no exposure column to fix", i + 1);
                }
                tokens[2] = format!("{t}");
                out.push_str(&tokens.join(" "));
                out.push_str(end);
            }
            None => out.push_str(l),
        }
    }
    Ok(out)
}

/// Logged and measured exposures over the frames with the flagged ones, and the residuals.
fn check_figure(
    check: &ExposureCheck,
    ratios: &[RatioMeasurement],
    logged: &[f64],
    path: &Path,
) -> Result<()> {
    let n = logged.len();
    let mut c1 = Chart::new("exposure times", "frame (times.txt order)", "exposure (ms)");
    c1.legend = Some(Corner::TopRight);
    c1.series.push(Series::line(
        "logged",
        (0..n).map(|k| [k as f64, logged[k]]).collect(),
        PALETTE[0],
    ));
    c1.series.push(
        Series::line(
            "measured from the images (scaled to the log)",
            (0..n).map(|k| [k as f64, check.measured_ms[k]]).collect(),
            PALETTE[2],
        )
        .dashed(),
    );
    let flagged: Vec<[f64; 2]> = check
        .shifted
        .iter()
        .map(|&k| [k as f64, logged[k]])
        .collect();
    let predicted: Vec<[f64; 2]> = check
        .shifted
        .iter()
        .map(|&k| [k as f64, check.frames[k].predicted_ms])
        .collect();
    c1.series.push(Series::points(
        format!("flagged: logged value ({})", check.shifted.len()),
        flagged,
        PALETTE[1],
    ));
    c1.series.push(Series::points(
        "flagged: predicted value",
        predicted,
        PALETTE[3],
    ));
    let mut c2 = Chart::new(
        "logged against predicted exposure",
        "frame (times.txt order)",
        "log(logged / predicted) (%)",
    );
    c2.legend = Some(Corner::TopRight);
    let resid: Vec<[f64; 2]> = check
        .frames
        .iter()
        .map(|c| [c.frame as f64, 100.0 * (c.logged_ms / c.predicted_ms).ln()])
        .collect();
    let band = |sign: f64| -> Vec<[f64; 2]> {
        check
            .frames
            .iter()
            .map(|c| [c.frame as f64, sign * 200.0 * c.std_error])
            .collect()
    };
    c2.series.push(Series::band(
        "2 standard errors",
        band(-1.0),
        band(1.0),
        PALETTE[0],
    ));
    c2.series.push(Series::line("residual", resid, PALETTE[0]));
    c2.series.push(Series::points(
        "flagged",
        check
            .shifted
            .iter()
            .map(|&k| {
                let c = &check.frames[k];
                [k as f64, 100.0 * (c.logged_ms / c.predicted_ms).ln()]
            })
            .collect(),
        PALETTE[1],
    ));
    let unreliable: Vec<[f64; 2]> = ratios
        .iter()
        .enumerate()
        .filter(|(_, m)| !m.reliable)
        .map(|(i, _)| [i as f64 + 0.5, 0.0])
        .collect();
    if !unreliable.is_empty() {
        c2.series.push(Series::points(
            format!("unreliable pair ({})", unreliable.len()),
            unreliable,
            PALETTE[7],
        ));
    }
    let fig = Figure {
        width: 1400,
        height: 900,
        panels: vec![
            (Panel::Chart(c1), [0.0, 0.0, 1.0, 0.55]),
            (Panel::Chart(c2), [0.0, 0.55, 1.0, 0.45]),
        ],
    };
    plot::save(&fig, path)
}

fn run_estimate(a: &EstimateArgs) -> Result<()> {
    let std_path = crate::cmd::calib::sibling(&a.output, "_std");
    let mut outs: Vec<&Path> = vec![&a.output, &std_path];
    if let Some(p) = &a.plot {
        plot::format_of(p)?;
        outs.push(p);
    }
    check_outputs(&outs, a.force)?;
    if !(a.reference_ms.is_finite() && a.reference_ms > 0.0) {
        bail!(
            "--reference-ms must be a positive number of ms, got {}",
            a.reference_ms
        );
    }
    let mut opts = options(&a.input)?;
    opts.skip_pairs = !a.no_skip_pairs;
    let seq = Sequence::open(&a.sequence)?;
    for w in &seq.times().warnings {
        eprintln!("monovo: warning: {w}");
    }
    if seq.len() < 2 {
        bail!(
            "{}: {} frame; estimating exposures needs at least 2",
            a.sequence.display(),
            seq.len()
        );
    }
    let (meter, bits) = meter_for(&seq, &a.input, &opts)?;
    let ratios = measure(&seq, &meter, bits, &opts, opts.skip_pairs)?;
    let mut pairs: Vec<PairRatio> = ratios
        .consecutive
        .iter()
        .enumerate()
        .map(|(i, m)| PairRatio {
            from: i,
            to: i + 1,
            measurement: m.clone(),
        })
        .collect();
    pairs.extend(ratios.skip.iter().enumerate().map(|(i, m)| PairRatio {
        from: i,
        to: i + 2,
        measurement: m.clone(),
    }));
    let est = estimate_exposures(seq.len(), &pairs, a.reference_ms, &opts)
        .with_context(|| a.sequence.display().to_string())?;
    let rows = &seq.times().rows;
    let mut times = String::with_capacity(rows.len() * 40);
    let mut stds = String::with_capacity(rows.len() * 30);
    for (k, r) in rows.iter().enumerate() {
        let t = est.exposures_ms[k];
        let s = est.log_std_error[k];
        times.push_str(&format!("{} {:.6} {}\n", r.id, r.timestamp, t));
        stds.push_str(&format!("{} {} {}\n", r.id, t * s, s));
    }
    dataset_io::write_atomic(&a.output, times.as_bytes())?;
    dataset_io::write_atomic(&std_path, stds.as_bytes())?;
    let logged: Option<Vec<f64>> = rows
        .iter()
        .map(|r| r.exposure_ms.filter(|t| *t > 0.0))
        .collect();
    if let Some(p) = &a.plot {
        estimate_figure(&est, logged.as_deref(), p)?;
    }
    for &g in &est.gaps {
        eprintln!(
            "monovo: warning: frames {g} and {}: no ratio measured across them (a cut, heavy blur or fast motion); their relative exposure is unknown (standard error {:.0}% beyond)",
            g + 1,
            100.0 * opts.gap_prior
        );
    }
    let per_frame_ms = 1e3 * ratios.seconds / seq.len() as f64;
    let max_se = est.log_std_error.iter().copied().fold(0.0, f64::max);
    if a.json {
        println!(
            "{}",
            serde_json::json!({
                "output": a.output.display().to_string(),
                "std_output": std_path.display().to_string(),
                "plot": a.plot.as_ref().map(|p| p.display().to_string()),
                "frames": seq.len(),
                "reference_ms": a.reference_ms,
                "anchor": est.anchor,
                "exposures_ms": est.exposures_ms,
                "log_std_error": est.log_std_error,
                "pairs_used": est.pairs_used,
                "pairs_unreliable": est.pairs_unreliable,
                "gaps": est.gaps,
                "outliers": est.outliers,
                "ms_per_frame": per_frame_ms,
            })
        );
        return Ok(());
    }
    let lo = est
        .exposures_ms
        .iter()
        .copied()
        .fold(f64::INFINITY, f64::min);
    let hi = est.exposures_ms.iter().copied().fold(0.0, f64::max);
    println!(
        "{} frames, {} ratios used, {} unreliable ({:.1} ms per frame)",
        seq.len(),
        est.pairs_used,
        est.pairs_unreliable,
        per_frame_ms
    );
    println!(
        "exposures {lo:.4} .. {hi:.4} ms (median {} ms at frame {}); largest standard error {:.2}% relative to it",
        a.reference_ms,
        est.anchor,
        100.0 * max_se
    );
    if logged.is_some() {
        println!(
            "(times.txt logs exposures too; `monovo exposure check` compares them with the images)"
        );
    }
    println!("wrote {} and {}", a.output.display(), std_path.display());
    if let Some(p) = &a.plot {
        println!("wrote {}", p.display());
    }
    Ok(())
}

/// The estimated exposures with their 2-sigma band, and the logged ones scaled to them.
fn estimate_figure(est: &ExposureEstimate, logged: Option<&[f64]>, path: &Path) -> Result<()> {
    let e = &est.exposures_ms;
    let n = e.len();
    let mut c = Chart::new(
        "estimated exposure times",
        "frame (times.txt order)",
        "exposure (ms)",
    );
    c.legend = Some(Corner::TopRight);
    // the axis covers the estimates; bands beyond a gap (unknown relative exposure) are cut
    let lo = e.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = e.iter().copied().fold(0.0, f64::max);
    let pad = 0.15 * (hi - lo).max(0.02 * hi);
    c.y_range = Some([(lo - pad).max(0.0), hi + pad]);
    let band = |sign: f64| -> Vec<[f64; 2]> {
        (0..n)
            .map(|k| [k as f64, e[k] * (sign * 2.0 * est.log_std_error[k]).exp()])
            .collect()
    };
    c.series.push(Series::band(
        "2 standard errors",
        band(-1.0),
        band(1.0),
        PALETTE[0],
    ));
    c.series.push(Series::line(
        "estimated",
        (0..n).map(|k| [k as f64, e[k]]).collect(),
        PALETTE[0],
    ));
    if let Some(l) = logged {
        let mut off: Vec<f64> = l.iter().zip(e).map(|(a, b)| (b / a).ln()).collect();
        off.sort_by(f64::total_cmp);
        let s = off[off.len() / 2].exp();
        c.series.push(
            Series::line(
                "logged (scaled to the estimate)",
                (0..n).map(|k| [k as f64, l[k] * s]).collect(),
                PALETTE[1],
            )
            .dashed(),
        );
    }
    plot::save(&Figure::single(c, 1400, 600), path)
}
