//! Exposure times from the images of a sequence: check the logged ones (`monovo exposure
//! check`) or estimate missing ones (`monovo exposure estimate`), around
//! [`photometric::exposure`].

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use dataset_io::{GrayImage, Sequence};
use monovo_figures::{Chart, Corner, Figure, Panel, Series, PALETTE};
use photometric::exposure::{
    check_exposures, estimate_exposures, measure_ratio, ExposureCheck, ExposureEstimate,
    ExposureMeter, ExposureOptions, MeteredFrame, PairRatio, RatioMeasurement, Verdict,
};
use photometric::{InverseResponse, Vignette};
use rayon::prelude::*;

use crate::{json_number as num, Observer, PipelineError, Result};

/// Where the calibration comes from and how frames are read.
#[derive(Clone, Debug, Default)]
pub struct ExposureInput {
    /// The inverse response (default: SEQ/pcalib.txt).
    pub pcalib: Option<PathBuf>,
    /// The vignette (default: SEQ/vignette.png; without one, V = 1 with a warning).
    pub vignette: Option<PathBuf>,
    /// Bits used by 16-bit frames (10, 12, 16).
    pub bit_depth: Option<u32>,
}

/// The measurement options from the values of `--min-grey`, `--max-grey` and
/// `--max-std-error`, checked (an error names the option).
pub fn measurement_options(
    min_grey: f64,
    max_grey: f64,
    max_std_error: f64,
) -> Result<ExposureOptions> {
    if !(min_grey.is_finite() && max_grey.is_finite() && 0.0 <= min_grey)
        || min_grey >= max_grey
        || max_grey > 255.0
    {
        return Err(PipelineError::Invalid(format!(
            "--min-grey {min_grey} and --max-grey {max_grey} must lie in 0..255, the first below the second"
        )));
    }
    if !(max_std_error.is_finite() && max_std_error > 0.0) {
        return Err(PipelineError::Invalid(format!(
            "--max-std-error must be a positive number, got {max_std_error}"
        )));
    }
    Ok(ExposureOptions {
        min_grey,
        max_grey,
        max_std_error,
        ..ExposureOptions::default()
    })
}

/// Sets the check's thresholds from `--flag-sigmas` and `--min-difference` (percent),
/// checked.
pub fn with_check_thresholds(
    mut opts: ExposureOptions,
    flag_sigmas: f64,
    min_difference_percent: f64,
) -> Result<ExposureOptions> {
    if !(flag_sigmas.is_finite() && flag_sigmas > 0.0) {
        return Err(PipelineError::Invalid(format!(
            "--flag-sigmas must be positive, got {flag_sigmas}"
        )));
    }
    if !(min_difference_percent.is_finite() && min_difference_percent >= 0.0) {
        return Err(PipelineError::Invalid(format!(
            "--min-difference must be a percentage of at least 0, got {min_difference_percent}"
        )));
    }
    opts.flag_sigmas = flag_sigmas;
    opts.min_difference = (min_difference_percent / 100.0).ln_1p();
    Ok(opts)
}

fn photometric_err(context: String) -> impl FnOnce(photometric::PhotometricError) -> PipelineError {
    move |source| PipelineError::Photometric { context, source }
}

/// The meter of a sequence: its response and vignette (or the given files), and the bits
/// its frames use.
pub fn meter_for(
    seq: &Sequence,
    input: &ExposureInput,
    opts: &ExposureOptions,
    observer: &dyn Observer,
) -> Result<(ExposureMeter, u32)> {
    let pcalib = match (&input.pcalib, &seq.pcalib_path) {
        (Some(p), _) | (None, Some(p)) => p.clone(),
        (None, None) => return Err(PipelineError::Invalid(format!(
            "{}: no pcalib.txt: measuring exposure ratios needs the inverse response (give --pcalib FILE, or calibrate it with `monovo calib response`)",
            seq.dir().display()
        ))),
    };
    let (u, notes) = InverseResponse::parse_with_notes(&dataset_io::read_text(&pcalib)?)
        .map_err(photometric_err(pcalib.display().to_string()))?;
    for n in notes {
        observer.warn(&format!("{}: {n}", pcalib.display()));
    }
    let size = seq.image_size();
    let vignette = match input.vignette.as_ref().or(seq.vignette_path.as_ref()) {
        Some(p) => {
            let (img, _) = dataset_io::read_gray_map(p)?;
            let v = Vignette::from_u16(&img).map_err(photometric_err(p.display().to_string()))?;
            let (w, h) = v.size();
            if (w, h) != (size.width, size.height) {
                return Err(PipelineError::Invalid(format!(
                    "{}: the vignette is {w}x{h} but the images are {size}",
                    p.display()
                )));
            }
            Some(v)
        }
        None => {
            observer.warn(&format!(
                "{}: no vignette.png: V = 1 (the vignetting then biases every ratio of frames that move)",
                seq.dir().display()
            ));
            None
        }
    };
    let in_bits = seq.bits_per_sample();
    let bits = match input.bit_depth {
        Some(b) if in_bits == 8 && b != 8 => return Err(PipelineError::Invalid(format!(
            "--bit-depth {b}: the frames of {} are 8-bit; --bit-depth describes 16-bit frames whose values use fewer bits",
            seq.dir().display()
        ))),
        Some(b) => b,
        None => in_bits,
    };
    let meter = ExposureMeter::new(&u, vignette.as_ref(), (size.width, size.height), opts)
        .map_err(photometric_err(seq.dir().display().to_string()))?;
    Ok((meter, bits))
}

/// The measured ratios of consecutive frames and (with `skip`) of frames two apart.
#[derive(Clone, Debug)]
pub struct Ratios {
    /// Ratio of frame i+1 to frame i.
    pub consecutive: Vec<RatioMeasurement>,
    /// Ratio of frame i+2 to frame i (empty without `skip`).
    pub skip: Vec<RatioMeasurement>,
    /// Seconds spent.
    pub seconds: f64,
}

/// Decodes and meters every frame in parallel chunks (memory stays flat) and measures the
/// pairs; one progress step per frame.
pub fn measure(
    seq: &Sequence,
    meter: &ExposureMeter,
    bits: u32,
    opts: &ExposureOptions,
    skip: bool,
    observer: &dyn Observer,
) -> Result<Ratios> {
    let start = Instant::now();
    let n = seq.len();
    observer.begin(n as u64, "measuring", "frames");
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
                .map_err(photometric_err(format!(
                    "{}: frame {k} ({})",
                    seq.dir().display(),
                    seq.names()[k]
                )))?;
                Ok((k, m))
            })
            .collect::<Result<_>>()?;
        let mut all = std::mem::take(&mut carry);
        all.extend(metered);
        let first = all.first().map_or(0, |f| f.0);
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
        observer.advance(part.len() as u64);
        let keep = all.len().saturating_sub(2);
        carry = all.split_off(keep);
    }
    observer.finish();
    let fill = |v: Vec<Option<RatioMeasurement>>| -> Vec<RatioMeasurement> {
        v.into_iter()
            .map(|m| m.unwrap_or_else(|| RatioMeasurement::failed("not measured")))
            .collect()
    };
    Ok(Ratios {
        consecutive: fill(consecutive),
        skip: fill(skipped),
        seconds: start.elapsed().as_secs_f64(),
    })
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

/// Opens a sequence for the exposure jobs, passing times.txt's warnings on.
fn open(dir: &Path, observer: &dyn Observer) -> Result<Sequence> {
    let seq = Sequence::open(dir)?;
    for w in &seq.times().warnings {
        observer.warn(w);
    }
    Ok(seq)
}

/// What `monovo exposure check` does: the sequence, the options, and the optional outputs
/// (checked before any work).
#[derive(Clone, Debug)]
pub struct CheckJob {
    /// The sequence folder.
    pub sequence: PathBuf,
    /// Calibration files and bit depth.
    pub input: ExposureInput,
    /// Measurement and check options.
    pub options: ExposureOptions,
    /// A corrected times.txt to write.
    pub fixed: Option<PathBuf>,
    /// A figure to draw.
    pub plot: Option<PathBuf>,
    /// Replace existing outputs.
    pub force: bool,
}

/// The result of [`check_sequence`].
#[derive(Clone, Debug)]
pub struct CheckReport {
    /// The job.
    pub job: CheckJob,
    /// The check.
    pub check: ExposureCheck,
    /// The measured ratios of consecutive frames.
    pub ratios: Vec<RatioMeasurement>,
    /// The logged exposures in ms.
    pub logged: Vec<f64>,
    /// times.txt's ids.
    pub ids: Vec<String>,
    /// Measuring time per frame in ms.
    pub ms_per_frame: f64,
}

/// Checks the logged exposures of a sequence against its images; writes the corrected
/// times.txt and the figure when the job asks for them.
pub fn check_sequence(job: &CheckJob, observer: &dyn Observer) -> Result<CheckReport> {
    if let Some(p) = &job.plot {
        monovo_figures::format_of(p)?;
    }
    for p in job.fixed.iter().chain(&job.plot) {
        dataset_io::check_output_file(p, job.force)?;
    }
    let seq = open(&job.sequence, observer)?;
    let times_text = dataset_io::read_text(seq.times_path())?;
    let lines = data_lines(&times_text);
    let mut logged = Vec::with_capacity(seq.len());
    for (k, row) in seq.times().rows.iter().enumerate() {
        let line = lines.get(k).copied().unwrap_or(k + 1);
        match row.exposure_ms {
            Some(t) if t > 0.0 => logged.push(t),
            Some(t) => return Err(PipelineError::Invalid(format!(
                "{}: line {line}: exposure {t} ms; `exposure check` needs a positive exposure on every line (`monovo exposure estimate` measures them from the images)",
                seq.times_path().display()
            ))),
            None => return Err(PipelineError::Invalid(format!(
                "{}: line {line}: no exposure (third column); `exposure check` compares logged exposures with the images; for a sequence without them, `monovo exposure estimate {} -o times.txt` measures them",
                seq.times_path().display(),
                job.sequence.display()
            ))),
        }
    }
    if seq.len() < 3 {
        return Err(PipelineError::Invalid(format!(
            "{}: {} frames; checking exposures needs at least 3",
            job.sequence.display(),
            seq.len()
        )));
    }
    let opts = &job.options;
    let (meter, bits) = meter_for(&seq, &job.input, opts, observer)?;
    let ratios = measure(&seq, &meter, bits, opts, false, observer)?;
    let check = check_exposures(&logged, &ratios.consecutive, opts)
        .map_err(photometric_err(job.sequence.display().to_string()))?;
    if let Some(out) = &job.fixed {
        let fixed = fixed_times(&times_text, &lines, &check)?;
        dataset_io::write_atomic(out, fixed.as_bytes())?;
    }
    if let Some(p) = &job.plot {
        monovo_figures::save(&check_figure(&check, &ratios.consecutive, &logged), p)?;
    }
    Ok(CheckReport {
        job: job.clone(),
        ms_per_frame: 1e3 * ratios.seconds / seq.len() as f64,
        check,
        ratios: ratios.consecutive,
        logged,
        ids: seq.times().rows.iter().map(|r| r.id.clone()).collect(),
    })
}

impl CheckReport {
    /// The report as one JSON object (`monovo exposure check --json`).
    pub fn json(&self) -> serde_json::Value {
        let (check, logged) = (&self.check, &self.logged);
        let ratio_json: Vec<serde_json::Value> = self
            .ratios
            .iter()
            .enumerate()
            .map(|(i, m)| {
                serde_json::json!({
                    "frame": i,
                    "logged": logged.get(i + 1).zip(logged.get(i)).map_or(f64::NAN, |(b, a)| b / a),
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
        serde_json::json!({
            "sequence": self.job.sequence.display().to_string(),
            "frames": self.logged.len(),
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
            "fixed": self.job.fixed.as_ref().map(|p| p.display().to_string()),
            "plot": self.job.plot.as_ref().map(|p| p.display().to_string()),
            "ms_per_frame": self.ms_per_frame,
        })
    }

    /// The report as text (`monovo exposure check`).
    pub fn text(&self) -> String {
        let check = &self.check;
        let mut s = String::new();
        let reliable = self.ratios.iter().filter(|m| m.reliable).count();
        let _ = writeln!(
            s,
            "{} frames, {} of {} consecutive ratios measured reliably ({:.1} ms per frame)",
            self.logged.len(),
            reliable,
            self.ratios.len(),
            self.ms_per_frame
        );
        if !check.unreliable_pairs.is_empty() {
            let _ = writeln!(
                s,
                "unreliable pairs (motion blur, fast motion or a cut; no frame is flagged on them): {}",
                list(&check.unreliable_pairs, 12)
            );
        }
        match check.log_lag {
            1 => {
                let _ = writeln!(s,
                    "the whole log is one frame late: every frame's logged exposure fits its previous frame (median {:.1} standard errors as logged, {:.1} moved)",
                    check.lag_scores[1], check.lag_scores[2]
                );
            }
            -1 => {
                let _ = writeln!(s,
                    "the whole log is one frame early: every frame's logged exposure fits its next frame (median {:.1} standard errors as logged, {:.1} moved)",
                    check.lag_scores[1], check.lag_scores[0]
                );
            }
            _ => {}
        }
        if check.shifted.is_empty() {
            s.push_str("no logged exposure is shifted by a frame\n");
        } else {
            let _ = writeln!(
                s,
                "{} logged exposure(s) belong to a neighbouring frame:",
                check.shifted.len()
            );
            for &k in &check.shifted {
                let Some(c) = check.frames.get(k) else {
                    continue;
                };
                let from = match c.verdict {
                    Verdict::ShiftedFromPrevious => "the previous frame's",
                    _ => "the next frame's",
                };
                let _ = writeln!(s,
                    "  frame {k} ({}): logged {:.4} ms, measured {:.4} ms ({:+.1}%, {:.0} standard errors); the log is {from}",
                    self.ids.get(k).map_or("?", |i| i.as_str()),
                    c.logged_ms,
                    c.predicted_ms,
                    100.0 * (c.logged_ms / c.predicted_ms - 1.0),
                    c.z.abs()
                );
            }
        }
        if !check.inconsistent.is_empty() {
            let _ = writeln!(
                s,
                "logged exposures that contradict the images but fit no neighbour: frames {}",
                list(&check.inconsistent, 20)
            );
        }
        if !check.undecided.is_empty() {
            let _ = writeln!(
                s,
                "no decision for {} frame(s) (unreliable or contradictory ratios around them): {}",
                check.undecided.len(),
                list(&check.undecided, 20)
            );
        }
        if let Some(o) = &self.job.fixed {
            let _ = writeln!(
                s,
                "wrote {} ({} exposure(s) replaced)",
                o.display(),
                check.shifted.len()
            );
        }
        if let Some(p) = &self.job.plot {
            let _ = writeln!(s, "wrote {}", p.display());
        }
        s
    }
}

/// What `monovo exposure estimate` does.
#[derive(Clone, Debug)]
pub struct EstimateJob {
    /// The sequence folder.
    pub sequence: PathBuf,
    /// Calibration files and bit depth.
    pub input: ExposureInput,
    /// Measurement options (`skip_pairs` chains frames two apart too).
    pub options: ExposureOptions,
    /// The times.txt to write; the standard errors go beside it as NAME_std.txt.
    pub output: PathBuf,
    /// The median exposure of the result, in ms.
    pub reference_ms: f64,
    /// A figure to draw.
    pub plot: Option<PathBuf>,
    /// Replace existing outputs.
    pub force: bool,
}

/// `NAME_std.EXT` beside `NAME.EXT`.
pub fn std_path(output: &Path) -> PathBuf {
    let stem = output
        .file_stem()
        .map_or("out".into(), |s| s.to_string_lossy().into_owned());
    let ext = output
        .extension()
        .map_or(String::new(), |e| format!(".{}", e.to_string_lossy()));
    output.with_file_name(format!("{stem}_std{ext}"))
}

/// The result of [`estimate_sequence`].
#[derive(Clone, Debug)]
pub struct EstimateReport {
    /// The job.
    pub job: EstimateJob,
    /// The estimate.
    pub estimate: ExposureEstimate,
    /// Whether times.txt logs exposures too.
    pub logged: bool,
    /// Measuring time per frame in ms.
    pub ms_per_frame: f64,
}

/// Estimates the exposures of a sequence from its images; writes times.txt, NAME_std.txt and
/// the figure. Gaps that no ratio bridges are warnings.
pub fn estimate_sequence(job: &EstimateJob, observer: &dyn Observer) -> Result<EstimateReport> {
    let stds = std_path(&job.output);
    if let Some(p) = &job.plot {
        monovo_figures::format_of(p)?;
    }
    for p in [&job.output, &stds].into_iter().chain(&job.plot) {
        dataset_io::check_output_file(p, job.force)?;
    }
    if !(job.reference_ms.is_finite() && job.reference_ms > 0.0) {
        return Err(PipelineError::Invalid(format!(
            "--reference-ms must be a positive number of ms, got {}",
            job.reference_ms
        )));
    }
    let opts = &job.options;
    let seq = open(&job.sequence, observer)?;
    if seq.len() < 2 {
        return Err(PipelineError::Invalid(format!(
            "{}: {} frame; estimating exposures needs at least 2",
            job.sequence.display(),
            seq.len()
        )));
    }
    let (meter, bits) = meter_for(&seq, &job.input, opts, observer)?;
    let ratios = measure(&seq, &meter, bits, opts, opts.skip_pairs, observer)?;
    let pairs = PairRatio::chain(&ratios.consecutive, &ratios.skip);
    let est = estimate_exposures(seq.len(), &pairs, job.reference_ms, opts)
        .map_err(photometric_err(job.sequence.display().to_string()))?;
    let rows = &seq.times().rows;
    let (mut times, mut std_text) = (String::new(), String::new());
    for ((r, t), s) in rows.iter().zip(&est.exposures_ms).zip(&est.log_std_error) {
        let _ = writeln!(times, "{} {:.6} {}", r.id, r.timestamp, t);
        let _ = writeln!(std_text, "{} {} {}", r.id, t * s, s);
    }
    dataset_io::write_atomic(&job.output, times.as_bytes())?;
    dataset_io::write_atomic(&stds, std_text.as_bytes())?;
    let logged: Option<Vec<f64>> = rows
        .iter()
        .map(|r| r.exposure_ms.filter(|t| *t > 0.0))
        .collect();
    if let Some(p) = &job.plot {
        monovo_figures::save(&estimate_figure(&est, logged.as_deref()), p)?;
    }
    for &g in &est.gaps {
        observer.warn(&format!(
            "frames {g} and {}: no ratio measured across them (a cut, heavy blur or fast motion); their relative exposure is unknown (standard error {:.0}% beyond)",
            g + 1,
            100.0 * opts.gap_prior
        ));
    }
    Ok(EstimateReport {
        job: job.clone(),
        ms_per_frame: 1e3 * ratios.seconds / seq.len() as f64,
        estimate: est,
        logged: logged.is_some(),
    })
}

impl EstimateReport {
    /// The report as one JSON object (`monovo exposure estimate --json`).
    pub fn json(&self) -> serde_json::Value {
        let est = &self.estimate;
        serde_json::json!({
            "output": self.job.output.display().to_string(),
            "std_output": std_path(&self.job.output).display().to_string(),
            "plot": self.job.plot.as_ref().map(|p| p.display().to_string()),
            "frames": est.exposures_ms.len(),
            "reference_ms": self.job.reference_ms,
            "anchor": est.anchor,
            "exposures_ms": est.exposures_ms,
            "log_std_error": est.log_std_error,
            "pairs_used": est.pairs_used,
            "pairs_unreliable": est.pairs_unreliable,
            "gaps": est.gaps,
            "outliers": est.outliers,
            "ms_per_frame": self.ms_per_frame,
        })
    }

    /// The report as text (`monovo exposure estimate`).
    pub fn text(&self) -> String {
        let est = &self.estimate;
        let lo = est
            .exposures_ms
            .iter()
            .copied()
            .fold(f64::INFINITY, f64::min);
        let hi = est.exposures_ms.iter().copied().fold(0.0, f64::max);
        let max_se = est.log_std_error.iter().copied().fold(0.0, f64::max);
        let mut s = format!(
            "{} frames, {} ratios used, {} unreliable ({:.1} ms per frame)\n",
            est.exposures_ms.len(),
            est.pairs_used,
            est.pairs_unreliable,
            self.ms_per_frame
        );
        let _ = writeln!(s,
            "exposures {lo:.4} .. {hi:.4} ms (median {} ms at frame {}); largest standard error {:.2}% relative to it",
            self.job.reference_ms,
            est.anchor,
            100.0 * max_se
        );
        if self.logged {
            s.push_str("(times.txt logs exposures too; `monovo exposure check` compares them with the images)\n");
        }
        let _ = writeln!(
            s,
            "wrote {} and {}",
            self.job.output.display(),
            std_path(&self.job.output).display()
        );
        if let Some(p) = &self.job.plot {
            let _ = writeln!(s, "wrote {}", p.display());
        }
        s
    }
}

/// The 1-based line numbers of times.txt's data rows (blank and `#` lines are skipped, as
/// the parser skips them).
pub fn data_lines(text: &str) -> Vec<usize> {
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

/// times.txt with every shifted frame's exposure replaced by its prediction; other lines as
/// they were.
pub fn fixed_times(text: &str, lines: &[usize], check: &ExposureCheck) -> Result<String> {
    let had_bom = text.starts_with('\u{feff}');
    let body = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut replace = std::collections::HashMap::new();
    for &k in &check.shifted {
        let Some(&line) = lines.get(k) else {
            return Err(PipelineError::Invalid(format!("times.txt has no row {k}")));
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
                    return Err(PipelineError::Invalid(format!(
                        "times.txt line {}: no exposure column to fix",
                        i + 1
                    )));
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
pub fn check_figure(check: &ExposureCheck, ratios: &[RatioMeasurement], logged: &[f64]) -> Figure {
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
    Figure {
        width: 1400,
        height: 900,
        panels: vec![
            (Panel::Chart(c1), [0.0, 0.0, 1.0, 0.55]),
            (Panel::Chart(c2), [0.0, 0.55, 1.0, 0.45]),
        ],
    }
}

/// The estimated exposures with their 2-sigma band, and the logged ones scaled to them.
pub fn estimate_figure(est: &ExposureEstimate, logged: Option<&[f64]>) -> Figure {
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
        let s = off.get(off.len() / 2).map_or(1.0, |v| v.exp());
        c.series.push(
            Series::line(
                "logged (scaled to the estimate)",
                (0..n).map(|k| [k as f64, l[k] * s]).collect(),
                PALETTE[1],
            )
            .dashed(),
        );
    }
    Figure::single(c, 1400, 600)
}
