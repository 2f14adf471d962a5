//! Synthetic data with known ground truth, written as the benchmark's files, as `monovo
//! synth` writes it: benchmark-like sequences ([`write_sequence`]), response sweeps
//! ([`write_sweep`]), marker-plane sets for the vignette ([`write_vignette_set`]) and
//! results trees of synthetic VO methods ([`write_results`]). Every writer fills a staging
//! [`OutputDir`] that the caller commits; the same seed gives the same files.
//!
//! ```no_run
//! use dataset_io::OutputDir;
//! use monovo_pipelines::synth::{write_sweep, SensorSpec, SweepSpec};
//!
//! let out = OutputDir::create("sweep".as_ref(), false)?;
//! let spec = SweepSpec { frames: 30, ..SweepSpec::default() };
//! let sweep = write_sweep(&out, &spec, &monovo_pipelines::Silent)?;
//! out.commit()?;
//! assert_eq!(sweep.exposures_ms.len(), 30);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use camera_model::ImageSize;
use dataset_io::OutputDir;
use rayon::prelude::*;
use synthetic::camera::{FovCamera, ResponseCurve};
use synthetic::results::{run_text, sequence_name, sequence_path, ResultsConfig};
use synthetic::scene::ExposureMode;
use synthetic::sensor::{NoiseLevel, Sensor, SensorFamily};

use crate::{Observer, PipelineError, Result};

/// The synthetic camera's sensor, response and storage.
#[derive(Clone, Copy, Debug)]
pub struct SensorSpec {
    /// The family of sensors.
    pub family: SensorFamily,
    /// Noise level of the sensor.
    pub noise: NoiseLevel,
    /// The true camera response.
    pub response: ResponseCurve,
    /// JPEG quality of the stored frames, `None` for lossless PNG.
    pub jpeg_quality: Option<u8>,
}

impl Default for SensorSpec {
    /// Typical noise, the dataset-like response, JPEG 90 (about the dataset's quality).
    fn default() -> Self {
        SensorSpec {
            family: SensorFamily::Machine,
            noise: NoiseLevel::Typical,
            response: ResponseCurve::Dataset,
            jpeg_quality: Some(90),
        }
    }
}

impl SensorSpec {
    /// The sensor this describes.
    pub fn sensor(&self) -> Sensor {
        let s = self.family.preset(self.noise);
        match self.jpeg_quality {
            Some(q) => s.with_jpeg(q),
            None => s,
        }
    }

    /// The extension of the stored frames.
    fn ext(&self) -> &'static str {
        if self.jpeg_quality.is_some() {
            "jpg"
        } else {
            "png"
        }
    }

    /// Encodes a rendered 8-bit frame as the camera stores it.
    fn encode(&self, w: usize, h: usize, frame: &[u8]) -> Result<Vec<u8>> {
        match self.jpeg_quality {
            Some(q) => dataset_io::encode_jpeg_gray(w, h, frame, q).map_err(encode_error),
            None => dataset_io::encode_png_u8(w, h, 1, frame, dataset_io::PngSpeed::Fast)
                .map_err(encode_error),
        }
    }
}

fn encode_error(e: impl std::fmt::Display) -> PipelineError {
    PipelineError::Invalid(format!("encoding a synthetic frame: {e}"))
}

fn photometric_error(
    what: &'static str,
) -> impl Fn(photometric::PhotometricError) -> PipelineError {
    move |source| PipelineError::Photometric {
        context: what.into(),
        source,
    }
}

/// Encodes a `bits`-bit frame (values in the low bits) as 16-bit PNG.
fn encode_deep(w: usize, h: usize, frame: &[u16]) -> Result<Vec<u8>> {
    dataset_io::encode_png_u16(w, h, frame, dataset_io::PngSpeed::Fast).map_err(encode_error)
}

/// Encodes frames in parallel and writes them as images.zip.
fn write_frames(
    zip_path: &std::path::Path,
    frames: usize,
    ext: &str,
    observer: &dyn Observer,
    render: impl Fn(usize) -> Result<Vec<u8>> + Sync,
) -> Result<()> {
    observer.begin(frames as u64, "rendering", "frames");
    let encoded: Vec<Result<(String, Vec<u8>)>> = (0..frames)
        .into_par_iter()
        .map(|i| {
            let bytes = render(i)?;
            observer.advance(1);
            Ok((format!("{i:05}.{ext}"), bytes))
        })
        .collect();
    observer.finish();
    let entries: Vec<(String, Vec<u8>)> = encoded.into_iter().collect::<Result<_>>()?;
    dataset_io::write_images_zip(zip_path, entries)?;
    Ok(())
}

/// times.txt of frames `00000 ..` at `period` seconds from 1.4e9 s with their exposures.
fn times_text(exposures_ms: &[f64], period: f64) -> String {
    exposures_ms
        .iter()
        .enumerate()
        .map(|(i, e)| format!("{i:05} {:.6} {e}\n", 1_400_000_000.0 + i as f64 * period))
        .collect()
}

/// A benchmark-like sequence: see [`write_sequence`].
#[derive(Clone, Copy, Debug)]
pub struct SequenceSpec {
    /// Random seed.
    pub seed: u64,
    /// Image size.
    pub size: ImageSize,
    /// Number of frames (at least 8).
    pub frames: usize,
    /// The sensor.
    pub sensor: SensorSpec,
    /// How the exposure changes.
    pub exposure: ExposureMode,
    /// Length of the camera path in metres.
    pub length: f64,
    /// Exposures logged one frame off in times.txt (listed in truth_shifts.txt).
    pub shift_exposures: usize,
    /// Shifts go only where they change the logged exposure by at least this many percent.
    pub shift_min_change: f64,
    /// Write times.txt without exposures (two columns).
    pub no_exposures: bool,
}

impl Default for SequenceSpec {
    fn default() -> Self {
        SequenceSpec {
            seed: 1,
            size: ImageSize::new(640, 512),
            frames: 300,
            sensor: SensorSpec::default(),
            exposure: ExposureMode::Smooth,
            length: 100.0,
            shift_exposures: 0,
            shift_min_change: 2.0,
            no_exposures: false,
        }
    }
}

/// Writes a benchmark-like sequence into `out`: images.zip (the sensor's JPEG or PNG),
/// times.txt, camera.txt (FOV, output 640x480 at most), pcalib.txt, vignette.png and
/// groundtruthSync.txt, plus truth_times.txt when times.txt differs from the true
/// exposures and truth_shifts.txt when exposures were shifted.
pub fn write_sequence(
    out: &OutputDir,
    e: &SequenceSpec,
    observer: &dyn Observer,
) -> Result<synthetic::scene::SyntheticSequence> {
    use synthetic::scene::{SequenceConfig, SyntheticSequence};
    let invalid = |m: String| Err(PipelineError::Invalid(m));
    if !(e.length.is_finite() && e.length > 0.0) {
        return invalid(format!(
            "--length must be a positive number of metres, got {}",
            e.length
        ));
    }
    if !(e.shift_min_change.is_finite() && e.shift_min_change >= 0.0) {
        return invalid(format!(
            "--shift-min-change must be a percentage of at least 0, got {}",
            e.shift_min_change
        ));
    }
    if e.shift_exposures > 0 && e.no_exposures {
        return invalid(
            "--shift-exposures needs logged exposures; leave out --no-exposures".into(),
        );
    }
    let cfg = SequenceConfig {
        width: e.size.width,
        height: e.size.height,
        frames: e.frames.max(8),
        sensor: e.sensor.sensor(),
        response: e.sensor.response,
        exposure: e.exposure,
        path_length: e.length,
        ..SequenceConfig::default()
    };
    let seq = SyntheticSequence::new(e.seed, cfg);
    let (w, h) = (cfg.width, cfg.height);
    write_frames(
        &out.file("images.zip")?,
        cfg.frames,
        e.sensor.ext(),
        observer,
        |i| e.sensor.encode(w, h, &seq.render(i)),
    )?;
    let rows = seq.times();
    let truth: String = rows
        .iter()
        .map(|(id, t, e)| format!("{id} {t:.6} {e}\n"))
        .collect();
    let (logged, shifts) = synthetic::scene::shift_exposure_log(
        &seq.exposures_ms,
        e.shift_exposures,
        e.shift_min_change / 100.0,
        e.seed,
    );
    if shifts.len() < e.shift_exposures {
        observer.warn(&format!(
            "only {} of {} exposure shifts fit (isolated, changing the log by at least {}%)",
            shifts.len(),
            e.shift_exposures,
            e.shift_min_change
        ));
    }
    let times: String = rows
        .iter()
        .zip(&logged)
        .map(|((id, t, _), l)| {
            if e.no_exposures {
                format!("{id} {t:.6}\n")
            } else {
                format!("{id} {t:.6} {l}\n")
            }
        })
        .collect();
    dataset_io::write_atomic(&out.file("times.txt")?, times.as_bytes())?;
    if times != truth {
        dataset_io::write_atomic(&out.file("truth_times.txt")?, truth.as_bytes())?;
    }
    if e.shift_exposures > 0 {
        let mut text = String::from(
            "# frame (0-based) whose logged exposure is another frame's: frame source true_ms logged_ms\n",
        );
        for s in &shifts {
            text.push_str(&format!(
                "{} {} {} {}\n",
                s.frame, s.source, seq.exposures_ms[s.frame], logged[s.frame]
            ));
        }
        dataset_io::write_atomic(&out.file("truth_shifts.txt")?, text.as_bytes())?;
    }
    // the dataset's output camera: 640x480 (4:3 at most 640 wide, as its camera.txt says)
    let out_w = w.clamp(2, 640);
    let out_size = (out_w, (out_w * 3 / 4).max(2));
    dataset_io::write_atomic(
        &out.file("camera.txt")?,
        seq.camera.camera_txt(out_size).as_bytes(),
    )?;
    let pcalib = photometric::InverseResponse::new(seq.response)
        .map_err(photometric_error("the synthetic response"))?;
    dataset_io::write_atomic(&out.file("pcalib.txt")?, pcalib.to_text().as_bytes())?;
    write_vignette_png(&out.file("vignette.png")?, w, h, &seq.vignette)?;
    dataset_io::write_atomic(
        &out.file("groundtruthSync.txt")?,
        seq.path.ground_truth_sync().as_bytes(),
    )?;
    Ok(seq)
}

/// Writes a vignette (any scale) as 16-bit vignette.png with maximum 65535.
fn write_vignette_png(path: &std::path::Path, w: usize, h: usize, v: &[f32]) -> Result<()> {
    let image =
        camera_model::Image::new(w, h, v.to_vec()).map_err(|source| PipelineError::Camera {
            context: "the synthetic vignette".into(),
            source,
        })?;
    let vig = photometric::Vignette::from_values(image)
        .map_err(photometric_error("the synthetic vignette"))?;
    dataset_io::write_png_u16(
        path,
        w,
        h,
        vig.to_u16().data(),
        dataset_io::PngSpeed::Default,
    )?;
    Ok(())
}

/// A response-calibration sweep: see [`write_sweep`].
#[derive(Clone, Copy, Debug)]
pub struct SweepSpec {
    /// Random seed.
    pub seed: u64,
    /// Image size.
    pub size: ImageSize,
    /// Number of exposures (at least 2).
    pub frames: usize,
    /// Shortest exposure in ms.
    pub min_exposure: f64,
    /// Longest exposure in ms (evenly spaced in log between the two).
    pub max_exposure: f64,
    /// Exposure step factor instead of `max_exposure`.
    pub step: Option<f64>,
    /// Bits per sample (8 to 16; above 8, 16-bit PNG frames with the values in the low bits).
    pub bits: u32,
    /// The sensor.
    pub sensor: SensorSpec,
}

impl Default for SweepSpec {
    fn default() -> Self {
        SweepSpec {
            seed: 1,
            size: ImageSize::new(640, 512),
            frames: 120,
            min_exposure: 0.05,
            max_exposure: 20.0,
            step: None,
            bits: 8,
            sensor: SensorSpec::default(),
        }
    }
}

/// Writes a response-calibration sweep into `out`: a static scene at exposures from
/// `min_exposure` up (images.zip, times.txt with exposures, camera.txt), and the true
/// inverse response as truth_pcalib.txt (`2^bits` values).
pub fn write_sweep(
    out: &OutputDir,
    a: &SweepSpec,
    observer: &dyn Observer,
) -> Result<synthetic::scene::Sweep> {
    use synthetic::scene::{Sweep, SweepConfig};
    let (w, h) = (a.size.width, a.size.height);
    let frames = a.frames.max(2);
    let invalid = |m: String| Err(PipelineError::Invalid(m));
    if !(8..=16).contains(&a.bits) {
        return invalid(format!("--bits must be 8 to 16, got {}", a.bits));
    }
    if !(a.min_exposure.is_finite() && a.min_exposure > 0.0) {
        return invalid(format!(
            "--min-exposure must be a positive number of ms, got {}",
            a.min_exposure
        ));
    }
    let factor = match a.step {
        Some(s) if s.is_finite() && s > 1.0 => s,
        Some(s) => return invalid(format!("--step must be a factor above 1, got {s}")),
        None if a.max_exposure.is_finite() && a.max_exposure > a.min_exposure => {
            (a.max_exposure / a.min_exposure).powf(1.0 / (frames - 1) as f64)
        }
        None => {
            return invalid(format!(
                "--max-exposure ({}) must be longer than --min-exposure ({})",
                a.max_exposure, a.min_exposure
            ))
        }
    };
    let sweep = Sweep::new(
        a.seed,
        SweepConfig {
            width: w,
            height: h,
            frames,
            t0: a.min_exposure,
            factor,
            sensor: a.sensor.sensor(),
            response: a.sensor.response,
        },
    );
    let zip = out.file("images.zip")?;
    let n = sweep.exposures_ms.len();
    if a.bits > 8 {
        write_frames(&zip, n, "png", observer, |i| {
            encode_deep(w, h, &sweep.render_deep(i, a.bits))
        })?;
    } else {
        write_frames(&zip, n, a.sensor.ext(), observer, |i| {
            a.sensor.encode(w, h, &sweep.render(i))
        })?;
    }
    dataset_io::write_atomic(
        &out.file("times.txt")?,
        times_text(&sweep.exposures_ms, 0.05).as_bytes(),
    )?;
    let cam = FovCamera::dataset(w, h);
    dataset_io::write_atomic(&out.file("camera.txt")?, cam.camera_txt((w, h)).as_bytes())?;
    let truth = photometric::InverseResponse::from_values(sweep.response_bits(a.bits))
        .map_err(photometric_error("the synthetic response"))?;
    dataset_io::write_atomic(&out.file("truth_pcalib.txt")?, truth.to_text().as_bytes())?;
    Ok(sweep)
}

/// A vignette-calibration set: see [`write_vignette_set`].
#[derive(Clone, Copy, Debug)]
pub struct VignetteSetSpec {
    /// Random seed.
    pub seed: u64,
    /// Image size.
    pub size: ImageSize,
    /// Number of frames (at least 1).
    pub frames: usize,
    /// Bits per sample (8 to 16; above 8, 16-bit PNG frames with the values in the low bits
    /// and a pcalib.txt of `2^bits` values).
    pub bits: u32,
    /// The sensor.
    pub sensor: SensorSpec,
}

impl Default for VignetteSetSpec {
    fn default() -> Self {
        VignetteSetSpec {
            seed: 1,
            size: ImageSize::new(640, 512),
            frames: 150,
            bits: 8,
            sensor: SensorSpec::default(),
        }
    }
}

/// Writes a vignette-calibration set into `out`: a bright wall with ArUco marker 213 filmed
/// from random poses (images.zip, times.txt, camera.txt with output `full`, pcalib.txt), with
/// the truth as poses.txt and truth_vignette.png.
pub fn write_vignette_set(
    out: &OutputDir,
    a: &VignetteSetSpec,
    observer: &dyn Observer,
) -> Result<synthetic::plane::PlaneSequence> {
    use synthetic::plane::{PlaneConfig, PlaneSequence};
    if !(8..=16).contains(&a.bits) {
        return Err(PipelineError::Invalid(format!(
            "--bits must be 8 to 16, got {}",
            a.bits
        )));
    }
    let (w, h) = (a.size.width, a.size.height);
    let seq = PlaneSequence::new(
        a.seed,
        PlaneConfig {
            width: w,
            height: h,
            frames: a.frames.max(1),
            sensor: a.sensor.sensor(),
            response: a.sensor.response,
            ..PlaneConfig::default()
        },
    );
    let zip = out.file("images.zip")?;
    let n = seq.poses.len();
    if a.bits > 8 {
        write_frames(&zip, n, "png", observer, |i| {
            encode_deep(w, h, &seq.render_deep(i, a.bits))
        })?;
    } else {
        write_frames(&zip, n, a.sensor.ext(), observer, |i| {
            a.sensor.encode(w, h, &seq.render(i))
        })?;
    }
    dataset_io::write_atomic(
        &out.file("times.txt")?,
        times_text(&seq.exposures_ms, 0.1).as_bytes(),
    )?;
    // the whole image is rectified for the marker: output `full`
    let cam = seq.camera.camera_txt_with((w, h), "full");
    dataset_io::write_atomic(&out.file("camera.txt")?, cam.as_bytes())?;
    let resp = photometric::InverseResponse::from_values(seq.response_bits(a.bits))
        .map_err(photometric_error("the synthetic response"))?;
    dataset_io::write_atomic(&out.file("pcalib.txt")?, resp.to_text().as_bytes())?;
    dataset_io::write_atomic(&out.file("poses.txt")?, seq.poses_text().as_bytes())?;
    write_vignette_png(&out.file("truth_vignette.png")?, w, h, &seq.vignette)?;
    Ok(seq)
}

/// A results tree: see [`write_results`].
#[derive(Clone, Copy, Debug)]
pub struct ResultsSpec {
    /// Random seed.
    pub seed: u64,
    /// Number of sequences (at least 1).
    pub sequences: usize,
    /// Runs per sequence and direction (at least 1).
    pub runs: usize,
    /// Frames per sequence (at least 50).
    pub frames: usize,
}

impl Default for ResultsSpec {
    fn default() -> Self {
        ResultsSpec {
            seed: 1,
            sequences: 50,
            runs: 5,
            frames: 2000,
        }
    }
}

/// Writes a synthetic benchmark evaluation into `out`: dataset/sequence_XX/groundtruthSync.txt
/// and results/METHOD/sequence_XX/{fwd,bwd}_N.txt of two methods with known drift; returns
/// the number of runs.
pub fn write_results(out: &OutputDir, a: &ResultsSpec, observer: &dyn Observer) -> Result<usize> {
    let cfg = ResultsConfig {
        sequences: a.sequences.max(1),
        runs: a.runs.max(1),
        frames: a.frames.max(50),
        ..ResultsConfig::default()
    };
    let paths: Vec<_> = (1..=cfg.sequences)
        .into_par_iter()
        .map(|i| sequence_path(a.seed, i, cfg.frames))
        .collect();
    // the files go straight into the staging folder, which appears whole at the commit: a
    // temporary, an fsync and a rename per file (as `write_atomic` does for a lone file)
    // took half the time of writing the 1000 runs
    for (i, p) in paths.iter().enumerate() {
        out.write(
            &format!("dataset/{}/groundtruthSync.txt", sequence_name(i + 1)),
            p.ground_truth_sync().as_bytes(),
        )?;
    }
    let mut jobs = Vec::new();
    for (mi, _) in cfg.methods.iter().enumerate() {
        for s in 0..cfg.sequences {
            for bwd in [false, true] {
                for r in 0..cfg.runs {
                    jobs.push((mi, s, bwd, r));
                }
            }
        }
    }
    observer.begin(jobs.len() as u64, "generating", "runs");
    let written = jobs
        .par_iter()
        .try_for_each(|&(mi, s, bwd, r)| -> Result<()> {
            let m = &cfg.methods[mi];
            let text = run_text(a.seed, &paths[s], m, mi, s + 1, bwd, r);
            let rel = format!(
                "results/{}/{}/{}_{r}.txt",
                m.name,
                sequence_name(s + 1),
                if bwd { "bwd" } else { "fwd" }
            );
            out.write(&rel, text.as_bytes())?;
            observer.advance(1);
            Ok(())
        });
    observer.finish();
    written?;
    Ok(jobs.len())
}
