//! `cargo xtask fuzz`: every parser of the workspace fed arbitrary and mutated bytes, with a
//! seeded random generator (reproducible: a case is its target, the seed and its number,
//! whatever the number of threads), on stable Rust. A case passes when the parser returns,
//! with a value or an error; a panic is caught (`catch_unwind` per case), its input written
//! to `target/fuzz-failures/` with the command that reproduces it, and the run fails.
//!
//! Inputs are, in turn: random bytes, random text from the alphabet of the formats, and
//! mutations (bit flips, interesting bytes and 32-bit values, insertions, deletions,
//! duplications, truncation, numbers replaced by extreme ones, lines deleted, duplicated or
//! swapped, splices of two seeds, PNG chunks whose CRC is made valid again) of seeds: the
//! real files under `tests/fixtures/dso-family/` (their first few KiB) and small generated
//! files (a sequence's times.txt and images.zip, PNG and JPEG frames of every kind, poses,
//! results.csv; the calibration config `data/calib.toml`).
//!
//! What a case exercises beyond the parser: what the command-line tools do next with a
//! parsed value (camera.txt: the output pinhole and the rectification map, on about one case
//! in four, picked by a hash of the input, and at a reduced size, so that a million cases
//! stay minutes; trajectories and ground truths: the evaluation; results.csv: the summaries;
//! PNG: the vignette).
//!
//! A process abort (out of memory, stack overflow) cannot be caught: it ends the run without a
//! report; `--case N` reruns one case (`--save FILE` writes its input) to find it.

use std::io::{Cursor, IsTerminal, Write};
use std::panic::AssertUnwindSafe;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use rayon::prelude::*;
use synthetic::Rng;

/// One parser under test: its name, its seeds and the function that feeds it one input.
struct Target {
    /// Short name, for `--target` and file names.
    id: &'static str,
    /// What is parsed.
    what: &'static str,
    seeds: Vec<Vec<u8>>,
    /// Text formats get text mutations (numbers, lines) and text from their alphabet.
    text: bool,
    /// Feeds one input; `true` when the parser accepted it.
    run: fn(&[u8]) -> bool,
}

fn text(b: &[u8]) -> std::borrow::Cow<'_, str> {
    String::from_utf8_lossy(b)
}

/// A ground truth to evaluate fuzzed trajectories against (and to seed with).
fn ground_truth_text() -> String {
    let mut s = String::new();
    for i in 0..40 {
        let t = 100.0 + i as f64 * 0.05;
        let a = i as f64 * 0.3;
        if (10..30).contains(&i) {
            s.push_str(&format!("{t:.6} NaN NaN NaN NaN NaN NaN NaN\n"));
        } else {
            s.push_str(&format!(
                "{t:.6} {} {} {} 0 0 0 1\n",
                a.cos(),
                a.sin(),
                0.1 * a
            ));
        }
    }
    s
}

/// A run that drifts, to evaluate against fuzzed ground truths.
fn estimate_text() -> String {
    let mut s = String::new();
    for i in 0..40 {
        let t = 100.0 + i as f64 * 0.05;
        let a = i as f64 * 0.31;
        let h = (0.5 * a).sin_cos();
        s.push_str(&format!(
            "{t:.6} {} {} {} 0 0 {} {}\n",
            1.1 * a.cos(),
            1.1 * a.sin(),
            0.12 * a,
            0.01 * h.0,
            h.1
        ));
    }
    s
}

fn gt() -> Option<&'static eval_metrics::GroundTruth> {
    static GT: std::sync::OnceLock<Option<eval_metrics::GroundTruth>> = std::sync::OnceLock::new();
    GT.get_or_init(|| eval_metrics::GroundTruth::parse(&ground_truth_text()).ok())
        .as_ref()
}

fn estimate() -> Option<&'static eval_metrics::Trajectory> {
    static EST: std::sync::OnceLock<Option<eval_metrics::Trajectory>> = std::sync::OnceLock::new();
    EST.get_or_init(|| eval_metrics::parse_tum(&estimate_text()).ok())
        .as_ref()
}

/// Cases of camera.txt that also compute the output pinhole and the rectification map: about
/// one in this many (DSO's crop search alone samples 200000 points: about a millisecond).
const CAMERA_GEOMETRY_EVERY: u64 = 4;

/// The largest sides the camera geometry is computed at; larger files are scaled down (the
/// model with them), which keeps a case at milliseconds and its memory small.
const GEOMETRY_IN_SIDE: usize = 96;
const GEOMETRY_OUT_SIDE: usize = 64;

fn scaled_size(s: camera_model::ImageSize, by: f64) -> camera_model::ImageSize {
    let side = |v: usize| ((v as f64 / by).round() as usize).max(2);
    camera_model::ImageSize::new(side(s.width), side(s.height))
}

/// The output pinhole, the notes and the rectification map of a parsed camera.txt, at most
/// [`GEOMETRY_IN_SIDE`] / [`GEOMETRY_OUT_SIDE`] pixels a side, and one remap.
fn camera_geometry(f: &camera_model::CameraFile) {
    let (i, o) = (f.input_size, f.output_size);
    let by = [
        i.width as f64 / GEOMETRY_IN_SIDE as f64,
        i.height as f64 / GEOMETRY_IN_SIDE as f64,
        o.width as f64 / GEOMETRY_OUT_SIDE as f64,
        o.height as f64 / GEOMETRY_OUT_SIDE as f64,
    ]
    .into_iter()
    .fold(1.0, f64::max);
    let (input, in_size, out_size) = if by > 1.0 {
        let small = scaled_size(i, by);
        (
            f.input
                .rescaled((i.width, i.height), (small.width, small.height)),
            small,
            scaled_size(o, by),
        )
    } else {
        (f.input.clone(), i, o)
    };
    let _ = camera_model::output_notes(&input, in_size, &f.output, out_size);
    if let Ok(map) = camera_model::RectifyMap::for_mode(&input, in_size, &f.output, out_size) {
        let raw = camera_model::Image::from_fn(in_size.width, in_size.height, |x, y| {
            (x * 7 + y * 3) as u8
        });
        let _ = map.remap_u8(&raw);
        let _ = map.valid_mask();
    }
}

/// FNV-1a of an input: picks the cases that also run something expensive.
fn input_hash(b: &[u8]) -> u64 {
    fnv1a(b)
}

fn run_camera(b: &[u8]) -> bool {
    let Ok(f) = camera_model::CameraFile::parse(&text(b)) else {
        return false;
    };
    let _ = camera_model::output_notes(&f.input, f.input_size, &f.output, f.output_size);
    let _ = camera_model::CameraFile::parse(&f.to_text());
    // the case number is not known here: a hash of the input picks the cases
    if input_hash(b).is_multiple_of(CAMERA_GEOMETRY_EVERY) {
        camera_geometry(&f);
    }
    true
}

/// Every calibration format (Kalibr YAML, EuRoC sensor.yaml, Basalt JSON, KITTI, ETH3D,
/// camera.txt): each camera projects and unprojects, and now and then builds its maps.
fn run_calibration(b: &[u8]) -> bool {
    let Ok(cal) = camera_model::CalibrationFile::parse(&text(b)) else {
        return false;
    };
    for (i, c) in cal.cameras.iter().enumerate() {
        for p in [[0.1, -0.2, 1.0], [1.0, 0.5, -0.3], [0.0, 0.0, 1.0]] {
            if let Some(px) = c.model.project(p) {
                let _ = c.model.unproject(px);
            }
        }
        let _ = c.camera_from_imu.as_ref().map(camera_model::invert_rigid);
        // the maps of the first camera of one input in 16 only: the crop search of a wide
        // lens is the cost (22.8 s for 50000 cases at one in 4, most of it there)
        if i == 0 && input_hash(b).is_multiple_of(4 * CAMERA_GEOMETRY_EVERY) {
            if let Ok(f) = cal.camera_file(0, Some(camera_model::ImageSize::new(64, 48))) {
                camera_geometry(&f);
            }
        } else {
            let _ = cal.camera_file(i, Some(camera_model::ImageSize::new(64, 48)));
        }
    }
    true
}

/// The layouts' listings: ASL data.csv, Basalt's exposure.csv, TUM RGB-D's rgb.txt.
fn run_listing(b: &[u8]) -> bool {
    let t = text(b);
    let p = Path::new("data.csv");
    let a = dataset_io::parse_data_csv(&t, p).is_ok();
    let e = dataset_io::parse_exposure_csv(&t, p).is_ok();
    let r = dataset_io::parse_rgb_list(&t, p).is_ok();
    if let Some(ns) = dataset_io::seconds_to_ns(&t) {
        let _ = dataset_io::ns_to_seconds_text(ns);
    }
    a || e || r
}

/// Ground truth in the datasets' formats (EuRoC/TUM-VI csv, GNSSPoses, KITTI, TUM), made
/// per frame.
fn run_dataset_truth(b: &[u8]) -> bool {
    let t = text(b);
    let f = eval_metrics::detect_ground_truth_format(&t);
    let Ok(traj) = eval_metrics::parse_ground_truth_trajectory(&t, f, Some("0\n1\n2\n")) else {
        return false;
    };
    let body = eval_metrics::nalgebra::Isometry3::translation(0.1, 0.0, 0.0);
    let _ = eval_metrics::GroundTruth::from_trajectory(&traj, Some(&body), None, 0.0);
    let frames: Vec<f64> = traj.poses.iter().take(50).map(|p| p.t + 0.001).collect();
    let _ = eval_metrics::GroundTruth::from_trajectory(&traj, None, Some(&frames), 0.5);
    true
}

fn run_camera_values(b: &[u8]) -> bool {
    let t = text(b);
    let mode = t.parse::<camera_model::OutputMode>().is_ok();
    t.parse::<camera_model::ImageSize>().is_ok() || mode
}

fn run_times(b: &[u8]) -> bool {
    let Ok(t) = dataset_io::parse_times(&text(b), Path::new("times.txt")) else {
        return false;
    };
    let _ = t.exposure_range();
    let _ = t.first_unknown_exposure();
    let _ = dataset_io::times_text(&t.rows);
    true
}

fn run_pcalib(b: &[u8]) -> bool {
    let Ok((u, _)) = photometric::InverseResponse::parse_with_notes(&text(b)) else {
        return false;
    };
    let _ = u.to_text();
    let _ = u.lut();
    let _ = u.table_for_bits(12);
    true
}

fn run_ground_truth(b: &[u8]) -> bool {
    let Ok(g) = eval_metrics::GroundTruth::parse(&text(b)) else {
        return false;
    };
    let _ = g.segment_sizes();
    let _ = g.associate(100.5, 0.001);
    if let Some(est) = estimate() {
        let _ = eval_metrics::evaluate(est, &g);
    }
    true
}

fn evaluate(t: &eval_metrics::Trajectory) -> bool {
    if let Some(g) = gt() {
        if t.poses.len() <= 4096 {
            let _ = eval_metrics::evaluate(t, g);
        }
    }
    true
}

fn run_tum(b: &[u8]) -> bool {
    let t = text(b);
    let _ = eval_metrics::detect_format(&t);
    eval_metrics::parse_tum(&t).is_ok_and(|tr| evaluate(&tr))
}

fn run_euroc(b: &[u8]) -> bool {
    eval_metrics::parse_euroc(&text(b)).is_ok_and(|tr| evaluate(&tr))
}

/// KITTI poses and their times file, separated by a line `---`.
fn run_kitti(b: &[u8]) -> bool {
    let t = text(b);
    let (poses, times) = t.split_once("\n---\n").unwrap_or((&t, ""));
    eval_metrics::parse_kitti(poses, times).is_ok_and(|tr| evaluate(&tr))
}

/// A KITTI pose file (no times), then the devkit's segment errors and evo's APE and RPE of it
/// against itself (paired by line).
fn run_kitti_poses(b: &[u8]) -> bool {
    let Ok(t) = eval_metrics::parse_kitti_poses(&text(b)) else {
        return false;
    };
    if t.len() <= 1024 {
        let _ = eval_metrics::kitti_errors(&[(t.clone(), t.clone())]);
        let mut o = eval_metrics::ApeOptions::default();
        o.align.mode = eval_metrics::AlignMode::Sim3;
        let _ = eval_metrics::ape(&t, &t, &o);
        let _ = eval_metrics::rpe(&t, &t, &eval_metrics::RpeOptions::default());
    }
    true
}

/// A TUM trajectory as the estimate of every metric (evo's APE and RPE with several options,
/// the TUM scripts' ATE and RPE, the KITTI segments) against a reference made from it: moved
/// by a similarity and 1 ms later, so that the poses associate and every step runs.
fn run_metrics(b: &[u8]) -> bool {
    let Ok(t) = eval_metrics::parse_tum(&text(b)) else {
        return false;
    };
    if t.poses.len() > 512 {
        return true;
    }
    let est = eval_metrics::PoseTrack::from_trajectory(&t);
    let mut reference = est.clone();
    let r = eval_metrics::nalgebra::Rotation3::from_euler_angles(0.1, -0.2, 0.3);
    for p in &mut reference.positions {
        *p = r * *p * 1.3 + eval_metrics::nalgebra::Vector3::new(1.0, 2.0, 3.0);
    }
    for m in &mut reference.rotations {
        *m = r.matrix() * *m;
    }
    if let Some(times) = reference.times.as_mut() {
        times.iter_mut().for_each(|x| *x += 0.001);
    }
    let reference = &reference;
    let h = input_hash(b);
    let mut ape = eval_metrics::ApeOptions::default();
    ape.align.mode = [
        eval_metrics::AlignMode::None,
        eval_metrics::AlignMode::Se3,
        eval_metrics::AlignMode::Sim3,
        eval_metrics::AlignMode::Scale,
        eval_metrics::AlignMode::PosYaw,
    ][(h % 5) as usize];
    ape.align.origin = h.is_multiple_of(7);
    ape.relation = [
        eval_metrics::PoseRelation::TransPart,
        eval_metrics::PoseRelation::AngleDeg,
        eval_metrics::PoseRelation::Full,
    ][(h % 3) as usize];
    ape.sync.max_diff = 0.03;
    if h.is_multiple_of(2) {
        ape.sync.method = eval_metrics::SyncMethod::Interpolation;
    }
    let _ = eval_metrics::ape(reference, &est, &ape);
    let mut rpe = eval_metrics::RpeOptions {
        align: ape.align,
        sync: ape.sync,
        all_pairs: h.is_multiple_of(3),
        pairs_from_reference: h.is_multiple_of(5),
        ..eval_metrics::RpeOptions::default()
    };
    (rpe.delta_unit, rpe.delta) = [
        (eval_metrics::DeltaUnit::Frames, 2.0),
        (eval_metrics::DeltaUnit::Meters, 0.3),
        (eval_metrics::DeltaUnit::Degrees, 5.0),
        (eval_metrics::DeltaUnit::Radians, 0.1),
    ][(h / 7 % 4) as usize];
    let _ = eval_metrics::rpe(reference, &est, &rpe);
    let _ = eval_metrics::tum_ate(reference, &est, &eval_metrics::TumAteOptions::default());
    let tum = eval_metrics::TumRpeOptions {
        fixed_delta: !h.is_multiple_of(4),
        max_pairs: 500,
        ..eval_metrics::TumRpeOptions::default()
    };
    let _ = eval_metrics::tum_rpe(reference, &est, &tum);
    let _ = eval_metrics::ExtraMetric::Kitti(ape.align).compute(reference, &est);
    true
}

/// An experiment manifest, with the [ape], [rpe] and [kitti] tables of the other metrics.
fn run_manifest(b: &[u8]) -> bool {
    monovo_pipelines::Experiment::parse(&text(b), Path::new("exp.toml"), Path::new("base")).is_ok()
}

fn run_plane_poses(b: &[u8]) -> bool {
    photometric::marker::parse_plane_poses(&text(b)).is_ok()
}

fn run_results_csv(b: &[u8]) -> bool {
    let Ok(r) = eval_metrics::parse_csv(&text(b)) else {
        return false;
    };
    let s = eval_metrics::summarize(&r, true);
    let _ = eval_metrics::summary_table(&s, eval_metrics::TableStyle::Text);
    let _ = eval_metrics::cumulative(
        &r,
        eval_metrics::Metric::ES,
        eval_metrics::DirectionFilter::Split,
    );
    true
}

/// Accepted: the archive opened and at least one entry decoded as an image.
fn run_zip(b: &[u8]) -> bool {
    let Ok(mut z) = dataset_io::ImagesZip::new(Cursor::new(b)) else {
        return false;
    };
    let mut decoded = false;
    for k in 0..z.len().min(4) {
        if let Ok(bytes) = z.read(k) {
            decoded |= dataset_io::decode_gray(&bytes).is_ok();
        }
    }
    decoded
}

fn run_png(b: &[u8]) -> bool {
    let grey = dataset_io::decode_gray(b).is_ok();
    let _ = dataset_io::decode_gray16(b);
    if let Ok((img, _)) = dataset_io::decode_gray_map(b) {
        let _ = photometric::Vignette::from_u16(&img);
    }
    grey
}

fn run_jpeg(b: &[u8]) -> bool {
    let grey = dataset_io::decode_gray8(b).is_ok();
    let _ = dataset_io::decode_gray(b);
    grey
}

/// `monovo calib --config FILE` as the command reads it (`CalibConfig` in
/// crates/cli/src/cmd/calib.rs, a binary crate): a `[response]` and a `[vignette]` table of
/// the library's option types, unknown keys refused.
#[derive(Default, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
struct CalibConfig {
    response: photometric::ResponseOptions,
    vignette: photometric::VignetteOptions,
}

/// A tiny exposure sweep (32x24, 8 exposures) for the response options of a fuzzed config.
fn tiny_sweep() -> &'static (Vec<camera_model::Image<u8>>, Vec<f64>) {
    static SWEEP: std::sync::OnceLock<(Vec<camera_model::Image<u8>>, Vec<f64>)> =
        std::sync::OnceLock::new();
    SWEEP.get_or_init(|| {
        let s = synthetic::scene::Sweep::new(
            4,
            synthetic::scene::SweepConfig {
                width: 32,
                height: 24,
                frames: 8,
                factor: 2.0,
                t0: 0.5,
                ..synthetic::scene::SweepConfig::default()
            },
        );
        let frames = (0..8)
            .filter_map(|i| camera_model::Image::new(32, 24, s.render(i)).ok())
            .collect();
        (frames, s.exposures_ms.clone())
    })
}

/// Cases of the calibration config whose response options, when valid, also calibrate the
/// tiny sweep: about one in this many (picked by a hash of the input).
const CONFIG_CALIBRATION_EVERY: u64 = 256;

fn run_calib_config(b: &[u8]) -> bool {
    let Ok(c) = toml::from_str::<CalibConfig>(&text(b)) else {
        return false;
    };
    let _ = c.vignette.check();
    // a valid iteration limit may still be 100000 passes: the tiny run keeps to 200
    if c.response.check().is_ok()
        && c.response.max_iterations <= 200
        && input_hash(b).is_multiple_of(CONFIG_CALIBRATION_EVERY)
    {
        let (frames, exposures) = tiny_sweep();
        let mut frames = frames.clone();
        let _ = photometric::calibrate_response(&mut frames, exposures, &c.response, &|_, _| {});
    }
    true
}

/// The first `limit` bytes of a seed, cut at a line end for text.
fn head(bytes: Vec<u8>, limit: usize, text: bool) -> Vec<u8> {
    if bytes.len() <= limit {
        return bytes;
    }
    let mut end = limit;
    if text {
        if let Some(p) = bytes[..limit].iter().rposition(|&c| c == b'\n') {
            end = p + 1;
        }
    }
    bytes[..end].to_vec()
}

/// The fixture files of one folder under tests/fixtures/dso-family/, their first `limit`
/// bytes.
fn fixtures(root: &Path, folder: &str, text: bool, limit: usize) -> Result<Vec<Vec<u8>>> {
    let dir = root.join("tests/fixtures/dso-family").join(folder);
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .with_context(|| dir.display().to_string())?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file())
        .collect();
    files.sort();
    files
        .into_iter()
        .map(|p| {
            let b = std::fs::read(&p).with_context(|| p.display().to_string())?;
            Ok(head(b, limit, text))
        })
        .collect()
}

fn png_seeds() -> Result<Vec<Vec<u8>>> {
    let (w, h) = (12usize, 9usize);
    let grey: Vec<u8> = (0..w * h).map(|i| (i * 37 % 256) as u8).collect();
    let grey16: Vec<u16> = (0..w * h).map(|i| (i * 4099 % 65536) as u16).collect();
    let rgb: Vec<u8> = (0..w * h * 3).map(|i| (i * 11 % 256) as u8).collect();
    let mut seeds = vec![
        dataset_io::encode_png_u8(w, h, 1, &grey, dataset_io::PngSpeed::Fast)?,
        dataset_io::encode_png_u8(w, h, 3, &rgb, dataset_io::PngSpeed::Fast)?,
        dataset_io::encode_png_u16(w, h, &grey16, dataset_io::PngSpeed::Fast)?,
    ];
    // grey+alpha and RGBA through the image crate
    let la = image::GrayAlphaImage::from_raw(
        w as u32,
        h as u32,
        grey.iter().flat_map(|&v| [v, 255]).collect(),
    )
    .context("grey+alpha")?;
    let mut b = Vec::new();
    image::DynamicImage::ImageLumaA8(la)
        .write_to(&mut Cursor::new(&mut b), image::ImageFormat::Png)?;
    seeds.push(b);
    let rgba = image::RgbaImage::from_raw(
        w as u32,
        h as u32,
        grey.iter().flat_map(|&v| [v, v, v, 9]).collect(),
    )
    .context("rgba")?;
    let mut b = Vec::new();
    image::DynamicImage::ImageRgba8(rgba)
        .write_to(&mut Cursor::new(&mut b), image::ImageFormat::Png)?;
    seeds.push(b);
    Ok(seeds)
}

fn jpeg_seeds() -> Result<Vec<Vec<u8>>> {
    let (w, h) = (16usize, 16usize);
    let grey: Vec<u8> = (0..w * h)
        .map(|i| ((i % w) * 13 + (i / w) * 7) as u8)
        .collect();
    let rgb: Vec<u8> = (0..w * h * 3).map(|i| (i * 5 % 256) as u8).collect();
    let mut colour = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut colour, 80).encode(
        &rgb,
        w as u32,
        h as u32,
        image::ExtendedColorType::Rgb8,
    )?;
    Ok(vec![
        dataset_io::encode_jpeg_gray(w, h, &grey, 90)?,
        dataset_io::encode_jpeg_gray(9, 7, &grey[..63], 30)?,
        colour,
    ])
}

fn zip_seeds(pngs: &[Vec<u8>], jpegs: &[Vec<u8>]) -> Result<Vec<Vec<u8>>> {
    let mut seeds = Vec::new();
    for (prefix, method, frames) in [
        ("", zip::CompressionMethod::Stored, jpegs),
        ("images/", zip::CompressionMethod::Deflated, pngs),
    ] {
        let mut bytes = Vec::new();
        {
            let mut z = zip::ZipWriter::new(Cursor::new(&mut bytes));
            let opts = zip::write::SimpleFileOptions::default().compression_method(method);
            for (i, f) in frames.iter().take(3).enumerate() {
                let ext = if prefix.is_empty() { "jpg" } else { "png" };
                z.start_file(format!("{prefix}{i:05}.{ext}"), opts)?;
                z.write_all(f)?;
            }
            z.start_file("notes.txt", opts)?;
            z.write_all(b"not an image")?;
            z.finish()?;
        }
        seeds.push(bytes);
    }
    Ok(seeds)
}

fn text_seeds_generated() -> (Vec<u8>, Vec<u8>, Vec<u8>, Vec<u8>) {
    // KITTI: 12 numbers a line, then its times
    let mut kitti = String::new();
    let mut times = String::new();
    for i in 0..8 {
        let a = i as f64 * 0.2;
        kitti.push_str(&format!(
            "{} {} 0 {} {} {} 0 {} 0 0 1 {}\n",
            a.cos(),
            -a.sin(),
            i as f64,
            a.sin(),
            a.cos(),
            0.5 * i as f64,
            0.1 * i as f64
        ));
        times.push_str(&format!("{:e}\n", 100.0 + i as f64 * 0.05));
    }
    let kitti = format!("{kitti}---\n{times}");
    // EuRoC csv
    let mut euroc = String::from("#timestamp [ns],p_x,p_y,p_z,q_w,q_x,q_y,q_z\n");
    for i in 0..8 {
        euroc.push_str(&format!(
            "{},{},{},0.5,1,0,0,0\n",
            100_000_000_000u64 + i * 50_000_000,
            i,
            i * 2
        ));
    }
    // results.csv, as eval-batch writes it
    let records: Vec<eval_metrics::RunRecord> = (0..6u32)
        .map(|i| {
            let failed = i % 3 == 1;
            eval_metrics::RunRecord {
                key: eval_metrics::RunKey {
                    method: if i == 5 {
                        "a,b \"c\"".into()
                    } else {
                        "dso".into()
                    },
                    sequence: format!("sequence_{:02}", i % 2 + 1),
                    direction: if i % 2 == 0 {
                        eval_metrics::Direction::Forward
                    } else {
                        eval_metrics::Direction::Backward
                    },
                    run: i,
                },
                failure: failed.then(|| "lost, before the end segment".to_string()),
                metrics: if failed {
                    eval_metrics::Metrics::FAILED
                } else {
                    eval_metrics::Metrics {
                        e_align: 0.5 + f64::from(i),
                        e_s: 1.01,
                        e_r: 0.3,
                        e_t: 0.2,
                        e_rmse: 0.1,
                        rmse_start: 0.01,
                        rmse_end: 0.02,
                    }
                },
                poses: 100,
                // the other metrics' columns: APE and KITTI for some runs
                extra: if i % 2 == 0 {
                    [
                        ("ape_rmse", 0.1),
                        ("ape_max", f64::INFINITY),
                        ("kitti_t_err", 1.5),
                    ]
                    .into_iter()
                    .map(|(k, v)| (k.to_string(), v * f64::from(i + 1)))
                    .collect()
                } else {
                    Default::default()
                },
            }
        })
        .collect();
    let csv = eval_metrics::write_csv(&records);
    // poses of a vignette-calibration set
    let plane = synthetic::plane::PlaneSequence::new(
        3,
        synthetic::plane::PlaneConfig {
            width: 64,
            height: 48,
            frames: 6,
            ..synthetic::plane::PlaneConfig::default()
        },
    );
    (
        kitti.into_bytes(),
        euroc.into_bytes(),
        csv.into_bytes(),
        plane.poses_text().into_bytes(),
    )
}

fn targets(root: &Path) -> Result<Vec<Target>> {
    let pngs = {
        let mut p = png_seeds()?;
        // the small real vignettes (a 1280x720 grey+alpha, a 752x480 RGB)
        for v in fixtures(root, "vignette", false, usize::MAX)? {
            if v.len() <= 4096 && v.starts_with(b"\x89PNG") {
                p.push(v);
            }
        }
        p
    };
    let jpegs = jpeg_seeds()?;
    let zips = zip_seeds(&pngs, &jpegs)?;
    let (kitti, euroc, csv, poses) = text_seeds_generated();
    let cameras = fixtures(root, "camera", true, 4096)?;
    let trajectories = fixtures(root, "trajectory", true, 4096)?;
    let mut tum = trajectories.clone();
    tum.push(ground_truth_text().into_bytes());
    tum.push(estimate_text().into_bytes());
    let mut values: Vec<Vec<u8>> = [
        "crop",
        "full",
        "none",
        "0.5 0.6 0.5 0.5 0",
        "640x480",
        "1280 1024",
        "0,5 0,5 0,5 0,5 0",
    ]
    .iter()
    .map(|s| s.as_bytes().to_vec())
    .collect();
    for c in &cameras {
        // line 3 and line 4 of every camera.txt, as given on the command line
        values.extend(
            text(c)
                .lines()
                .skip(2)
                .take(2)
                .map(|l| l.as_bytes().to_vec()),
        );
    }
    let mut times = fixtures(root, "times", true, 4096)?;
    times.push(
        b"00000 1.0 5\n00001 1.1 0\n00002 1.2 7\n# comment\n00003 1.3 0\n00004 1.4 0\n".to_vec(),
    );
    times.push(b"1.0\n1.1\n1.2\n".to_vec());
    let mut ground_truths = vec![ground_truth_text().into_bytes()];
    // the real ground truths among the trajectories (TUM rows of 8 numbers)
    ground_truths.extend(
        trajectories
            .iter()
            .filter(|t| {
                text(t)
                    .lines()
                    .find(|l| !l.starts_with('#'))
                    .is_some_and(|l| l.split_whitespace().count() == 8)
            })
            .take(4)
            .cloned(),
    );
    let datasets = root.join("tests/fixtures/datasets");
    let read_dir = |sub: &str, limit: usize| -> Result<Vec<Vec<u8>>> {
        let dir = datasets.join(sub);
        let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
            .with_context(|| dir.display().to_string())?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.is_file())
            .collect();
        files.sort();
        files
            .into_iter()
            .map(|p| {
                Ok(head(
                    std::fs::read(&p).with_context(|| p.display().to_string())?,
                    limit,
                    true,
                ))
            })
            .collect()
    };
    // Basalt's files are mostly IMU and vignette tables: the seeds keep the cameras' part,
    // compact, so that whole files fit in a seed
    let compact = |b: Vec<u8>| -> Vec<u8> {
        let Ok(mut v) = serde_json::from_slice::<serde_json::Value>(&b) else {
            return b;
        };
        if let Some(c) = v.get_mut("value0").and_then(|c| c.as_object_mut()) {
            c.retain(|k, _| matches!(k.as_str(), "T_imu_cam" | "intrinsics" | "resolution"));
        }
        serde_json::to_vec(&v).unwrap_or(b)
    };
    let mut calibrations: Vec<Vec<u8>> = read_dir("calib", usize::MAX)?
        .into_iter()
        .map(compact)
        .map(|b| head(b, 3072, true))
        .collect();
    calibrations.push(b"726.28741455078 726.28741455078 354.6496887207 186.46566772461\n".to_vec());
    calibrations.extend(
        read_dir("heads", 4096)?
            .into_iter()
            .filter(|h| h.starts_with(b"P0:")),
    );
    let heads = read_dir("heads", 4096)?;
    let listings = vec![
        b"#timestamp [ns],filename\n1403636579763555584,1403636579763555584.png\n1403636579813555456,1403636579813555456.png\n".to_vec(),
        b"#timestamp [ns],exposure [ns]\n1403636579763555584,5000000\n1403636579813555456,5250000\n".to_vec(),
        b"# color images\n1305031102.175304 rgb/1305031102.175304.png\n1305031102.211214 rgb/1305031102.211214.png\n".to_vec(),
        b"1520530308.199447626".to_vec(),
    ];
    let mut truths: Vec<Vec<u8>> = heads.clone();
    truths.push(b"# timestamp, tx, ty, tz, qx, qy, qz, qw, scale, fusion_quality, v3_quality\n1585067782140857088,1.0,2.0,3.0,0,0,0,1,2.5,1,1\n1585067782206857216,1.1,2.0,3.0,0,0,0,1,2.5,1,1\n".to_vec());
    truths.push(b"#timestamp [ns],p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],q_RS_w [],q_RS_x [],q_RS_y [],q_RS_z []\n1520530308199447626,0.88,-0.29,1.20,0.71,0.03,-0.02,-0.69\n1520530308207780959,0.88,-0.29,1.21,0.71,0.03,-0.02,-0.69\n".to_vec());
    Ok(vec![
        Target {
            id: "calibration",
            what: "calibration files (camchain.yaml, sensor.yaml, calibration.json, calib.txt)",
            seeds: calibrations,
            text: true,
            run: run_calibration,
        },
        Target {
            id: "listing",
            what: "data.csv, exposure.csv, rgb.txt",
            seeds: listings,
            text: true,
            run: run_listing,
        },
        Target {
            id: "dataset-truth",
            what: "ground truth of EuRoC, TUM-VI, 4Seasons, KITTI, TUM",
            seeds: truths,
            text: true,
            run: run_dataset_truth,
        },
        Target {
            id: "camera",
            what: "camera.txt",
            seeds: cameras,
            text: true,
            run: run_camera,
        },
        Target {
            id: "camera-values",
            what: "--pinhole and --size values",
            seeds: values,
            text: true,
            run: run_camera_values,
        },
        Target {
            id: "times",
            what: "times.txt",
            seeds: times,
            text: true,
            run: run_times,
        },
        Target {
            id: "pcalib",
            what: "pcalib.txt",
            // 256 values are 3-5 KiB; the 65536-value table is cut
            seeds: fixtures(root, "pcalib", true, 8192)?,
            text: true,
            run: run_pcalib,
        },
        Target {
            id: "groundtruth",
            what: "groundtruthSync.txt",
            seeds: ground_truths,
            text: true,
            run: run_ground_truth,
        },
        Target {
            id: "tum",
            what: "TUM trajectory",
            seeds: tum.clone(),
            text: true,
            run: run_tum,
        },
        Target {
            id: "euroc",
            what: "EuRoC trajectory",
            seeds: {
                let mut s = trajectories.clone();
                s.push(euroc);
                s
            },
            text: true,
            run: run_euroc,
        },
        Target {
            id: "kitti",
            what: "KITTI trajectory and times",
            seeds: vec![kitti.clone()],
            text: true,
            run: run_kitti,
        },
        Target {
            id: "kitti-poses",
            what: "KITTI pose file (ape, rpe, kitti)",
            seeds: {
                let k = String::from_utf8_lossy(&kitti).into_owned();
                let mut s = vec![k.split("\n---\n").next().unwrap_or("").as_bytes().to_vec()];
                s.extend(fixtures(root, "../metrics", true, 8192)?.into_iter().filter(|f| {
                    f.split(|c| *c == b'\n').next().is_some_and(|l| {
                        l.split(|c| *c == b' ').filter(|w| !w.is_empty()).count() == 12
                    })
                }));
                s
            },
            text: true,
            run: run_kitti_poses,
        },
        Target {
            id: "metrics",
            what: "TUM trajectory through every metric (ape, rpe, --tum, kitti)",
            seeds: tum,
            text: true,
            run: run_metrics,
        },
        Target {
            id: "manifest",
            what: "experiment manifest TOML",
            seeds: vec![
                std::fs::read(root.join("data/experiment.toml"))
                    .context("data/experiment.toml")?,
                b"dataset = \"d\"\nresults = \"r\"\nmetrics = [\"e_align\", \"ape_rmse\", \"rpe_mean\", \"kitti_t_err\"]\n[[method]]\nname = \"a\"\n[ape]\nalign = \"sim3\"\npose_relation = \"angle_deg\"\n[rpe]\ntum = true\ndelta = 1\ndelta_unit = \"s\"\n[kitti]\nalign = \"se3\"\n".to_vec(),
            ],
            text: true,
            run: run_manifest,
        },
        Target {
            id: "poses",
            what: "plane poses (calib vignette --poses)",
            seeds: vec![poses],
            text: true,
            run: run_plane_poses,
        },
        Target {
            id: "calib-config",
            what: "calib --config TOML",
            seeds: {
                let full =
                    std::fs::read(root.join("data/calib.toml")).context("data/calib.toml")?;
                vec![
                    full,
                    b"[vignette]\nsmoothing_px = 2.0\ngrid = 200\n".to_vec(),
                    b"[response]\nmax_iterations = 20\ntolerance = 0.1\nsaturation_border = 0\n"
                        .to_vec(),
                    b"response = { smoothness = 3.0, huber = 2.5, weighting = \"uniform\" }\n"
                        .to_vec(),
                ]
            },
            text: true,
            run: run_calib_config,
        },
        Target {
            id: "results-csv",
            what: "results.csv (plot)",
            seeds: vec![csv],
            text: true,
            run: run_results_csv,
        },
        Target {
            id: "zip",
            what: "images.zip",
            seeds: zips,
            text: false,
            run: run_zip,
        },
        Target {
            id: "png",
            what: "PNG frames and vignettes",
            seeds: pngs,
            text: false,
            run: run_png,
        },
        Target {
            id: "jpeg",
            what: "JPEG frames",
            seeds: jpegs,
            text: false,
            run: run_jpeg,
        },
    ])
}

// ---------------------------------------------------------------------------------------
// inputs

const INTERESTING_BYTES: [u8; 14] = [
    0, 0xFF, 0x7F, 0x80, b'0', b'9', b'-', b'.', b'\n', b'\r', b' ', b',', b'e', b'#',
];
const INTERESTING_U32: [u32; 9] = [
    0,
    1,
    0x7F,
    0xFF,
    0xFFFF,
    0x7FFF_FFFF,
    0x8000_0000,
    0xFFFF_FFFF,
    0x0001_0000,
];
const INTERESTING_NUMBERS: [&str; 22] = [
    "0",
    "-0",
    "1",
    "-1",
    "0.5",
    "1e308",
    "-1e308",
    "1e-320",
    "nan",
    "NaN",
    "inf",
    "-inf",
    "65535",
    "65536",
    "4294967296",
    "18446744073709551616",
    "1e9",
    "999999999999999999999",
    "0x10",
    "1,5",
    "",
    "2e9",
];
const ALPHABET: &[u8] = b"0123456789.-+eE naNIif#,\n\n\r\t:xX/%";

fn is_number_byte(c: u8) -> bool {
    c.is_ascii_digit() || matches!(c, b'.' | b'-' | b'+' | b'e' | b'E')
}

/// Replaces one number token with an interesting number.
fn replace_number(rng: &mut Rng, b: &mut Vec<u8>) {
    let starts: Vec<usize> = (0..b.len())
        .filter(|&i| is_number_byte(b[i]) && (i == 0 || !is_number_byte(b[i - 1])))
        .collect();
    if starts.is_empty() {
        return;
    }
    let s = starts[rng.below(starts.len())];
    let mut e = s;
    while e < b.len() && is_number_byte(b[e]) {
        e += 1;
    }
    let n = INTERESTING_NUMBERS[rng.below(INTERESTING_NUMBERS.len())];
    b.splice(s..e, n.bytes());
}

fn line_ranges(b: &[u8]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut s = 0;
    for (i, &c) in b.iter().enumerate() {
        if c == b'\n' {
            out.push((s, i + 1));
            s = i + 1;
        }
    }
    if s < b.len() {
        out.push((s, b.len()));
    }
    out
}

/// Deletes, duplicates or swaps whole lines.
fn mutate_lines(rng: &mut Rng, b: &mut Vec<u8>) {
    let lines = line_ranges(b);
    if lines.is_empty() {
        return;
    }
    let (s, e) = lines[rng.below(lines.len())];
    match rng.below(3) {
        0 => {
            b.drain(s..e);
        }
        1 => {
            let l = b[s..e].to_vec();
            b.splice(e..e, l);
        }
        _ => {
            let (s2, e2) = lines[rng.below(lines.len())];
            if (s2, e2) != (s, e) {
                let (a, c) = if s < s2 {
                    ((s, e), (s2, e2))
                } else {
                    ((s2, e2), (s, e))
                };
                let first = b[a.0..a.1].to_vec();
                let second = b[c.0..c.1].to_vec();
                b.splice(c.0..c.1, first);
                b.splice(a.0..a.1, second);
            }
        }
    }
}

/// Makes the CRC of every complete PNG chunk valid again, so that mutations reach the
/// decoder past the checksum.
fn fix_png_crcs(b: &mut [u8]) {
    if !b.starts_with(b"\x89PNG\r\n\x1a\n") {
        return;
    }
    let mut at = 8;
    while at + 12 <= b.len() {
        let len = u32::from_be_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]]) as usize;
        let Some(end) = (at + 8).checked_add(len) else {
            return;
        };
        if end + 4 > b.len() {
            return;
        }
        let crc = crc32fast::hash(&b[at + 4..end]);
        b[end..end + 4].copy_from_slice(&crc.to_be_bytes());
        at = end + 4;
    }
}

fn mutate(rng: &mut Rng, seeds: &[Vec<u8>], text: bool, mut b: Vec<u8>) -> Vec<u8> {
    // mostly one or two mutations, so that many inputs still parse and reach what follows
    let rounds = [1, 1, 1, 2, 2, 3, 4, 8][rng.below(8)];
    for _ in 0..rounds {
        let len = b.len();
        // text: a third of the mutations replace a number, which keeps the format
        let op = if text && rng.below(3) == 0 {
            10
        } else {
            rng.below(if text { 12 } else { 10 })
        };
        match op {
            0 if len > 0 => {
                let i = rng.below(len);
                b[i] ^= 1 << rng.below(8);
            }
            1 if len > 0 => {
                let i = rng.below(len);
                b[i] = INTERESTING_BYTES[rng.below(INTERESTING_BYTES.len())];
            }
            2 => {
                let i = rng.below(len + 1);
                let n = 1 + rng.below(8);
                let ins: Vec<u8> = (0..n).map(|_| rng.next_u64() as u8).collect();
                b.splice(i..i, ins);
            }
            3 if len > 0 => {
                let i = rng.below(len);
                let n = (1 + rng.below(16)).min(len - i);
                b.drain(i..i + n);
            }
            4 if len > 0 => {
                let i = rng.below(len);
                let n = (1 + rng.below(64)).min(len - i);
                let chunk = b[i..i + n].to_vec();
                let j = rng.below(b.len() + 1);
                b.splice(j..j, chunk);
            }
            5 if len > 0 => b.truncate(rng.below(len)),
            6 if len >= 4 => {
                let i = rng.below(len - 3);
                let v = INTERESTING_U32[rng.below(INTERESTING_U32.len())];
                let bytes = if rng.below(2) == 0 {
                    v.to_le_bytes()
                } else {
                    v.to_be_bytes()
                };
                b[i..i + 4].copy_from_slice(&bytes);
            }
            7 if !seeds.is_empty() => {
                let other = &seeds[rng.below(seeds.len())];
                let cut = rng.below(b.len() + 1);
                let from = rng.below(other.len() + 1);
                b.truncate(cut);
                b.extend_from_slice(&other[from..]);
            }
            8 if len > 0 => {
                // a large range deleted or overwritten with one byte
                let i = rng.below(len);
                let n = rng.below(len - i + 1);
                if rng.below(2) == 0 {
                    b.drain(i..i + n);
                } else {
                    let v = INTERESTING_BYTES[rng.below(INTERESTING_BYTES.len())];
                    b[i..i + n].fill(v);
                }
            }
            9 => fix_png_crcs(&mut b),
            10 => replace_number(rng, &mut b),
            11 => mutate_lines(rng, &mut b),
            _ => {}
        }
    }
    if !text && rng.below(2) == 0 {
        fix_png_crcs(&mut b);
    }
    b
}

/// The input of case `case` of the target whose name hashes to `key`.
fn input(seed: u64, key: u64, case: u64, t: &Target) -> Vec<u8> {
    let mut rng = Rng::derive(seed ^ key, case);
    let kind = rng.below(20);
    if kind == 0 || t.seeds.is_empty() {
        let n = rng.below(512);
        return (0..n).map(|_| rng.next_u64() as u8).collect();
    }
    if kind == 1 && t.text {
        let n = rng.below(512);
        return (0..n)
            .map(|_| ALPHABET[rng.below(ALPHABET.len())])
            .collect();
    }
    let base = t.seeds[rng.below(t.seeds.len())].clone();
    mutate(&mut rng, &t.seeds, t.text, base)
}

// ---------------------------------------------------------------------------------------
// running

thread_local! {
    /// Where the last panic on this thread happened, set by the panic hook.
    static PANIC_AT: std::cell::RefCell<Option<String>> = const { std::cell::RefCell::new(None) };
}

/// A panic found: the target, the case and its input.
struct Finding {
    case: u64,
    message: String,
    input: Vec<u8>,
}

/// The outcome of one target.
struct Outcome {
    cases: u64,
    /// Inputs the parser accepted (the rest were errors).
    accepted: u64,
    seconds: f64,
    /// The slowest case: its duration and number.
    slowest: (Duration, u64),
    findings: Vec<Finding>,
}

fn usage() -> &'static str {
    "usage: cargo xtask fuzz [--cases N] [--quick] [--seed S] [--target NAME[,NAME..]]\n       \
     \x20               [--case N [--save FILE] | --input FILE] [--list]\n\n\
     Feeds every parser arbitrary and mutated bytes (seeded, reproducible, the same inputs with\n\
     any number of threads) and fails on a panic, writing the input and the command that\n\
     reproduces it to target/fuzz-failures/. --cases is per target (default 1000000); --quick\n\
     is 20000; --target runs the named targets (--list shows them); --case N runs case N only\n\
     (--save FILE writes its input); --input FILE runs the targets on the bytes of FILE.\n\
     RAYON_NUM_THREADS sets the number of threads."
}

struct Options {
    cases: u64,
    seed: u64,
    only: Option<Vec<String>>,
    case: Option<u64>,
    input: Option<PathBuf>,
    list: bool,
    /// With `--case`: where to write the case's input.
    save: Option<PathBuf>,
}

fn number(args: &mut dyn Iterator<Item = String>, flag: &str) -> Result<u64> {
    let v = args
        .next()
        .with_context(|| format!("{flag} needs a number"))?;
    v.replace('_', "")
        .parse()
        .with_context(|| format!("{flag} needs a number, not `{v}`"))
}

fn options(mut args: impl Iterator<Item = String>) -> Result<Option<Options>> {
    let mut o = Options {
        cases: 1_000_000,
        seed: 1,
        only: None,
        case: None,
        input: None,
        list: false,
        save: None,
    };
    while let Some(a) = args.next() {
        match a.as_str() {
            "--quick" => o.cases = 20_000,
            "--cases" => o.cases = number(&mut args, "--cases")?,
            "--seed" => o.seed = number(&mut args, "--seed")?,
            "--case" => o.case = Some(number(&mut args, "--case")?),
            "--target" | "--only" => {
                let names = args.next().context("--target needs a name (see --list)")?;
                o.only = Some(names.split(',').map(|s| s.trim().to_string()).collect());
            }
            "--input" => o.input = Some(args.next().context("--input needs a file")?.into()),
            "--list" => o.list = true,
            "--save" => o.save = Some(args.next().context("--save needs a file")?.into()),
            "-h" | "--help" => {
                println!("{}", usage());
                return Ok(None);
            }
            other => bail!("unknown argument `{other}`\n{}", usage()),
        }
    }
    Ok(Some(o))
}

/// A stable number for a target's name: its cases do not change when targets are added.
fn name_hash(id: &str) -> u64 {
    fnv1a(id.as_bytes())
}

/// FNV-1a, 64 bits.
fn fnv1a(b: &[u8]) -> u64 {
    b.iter().fold(0xCBF2_9CE4_8422_2325u64, |h, &c| {
        (h ^ c as u64).wrapping_mul(0x0000_0100_0000_01B3)
    })
}

/// Runs one input through a target: whether the parser accepted it, or the panic's message
/// and location.
fn run_case(t: &Target, bytes: &[u8]) -> std::result::Result<bool, String> {
    let r = std::panic::catch_unwind(AssertUnwindSafe(|| (t.run)(bytes)));
    let at = PANIC_AT.with(|p| p.borrow_mut().take());
    match r {
        Ok(accepted) => Ok(accepted),
        Err(payload) => {
            let msg = payload
                .downcast_ref::<&str>()
                .map(|s| (*s).to_string())
                .or_else(|| payload.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "panic".into());
            Err(format!("{msg}{}", at.unwrap_or_default()))
        }
    }
}

/// Runs `cases` cases of a target in parallel, with a live progress line on a terminal.
fn run_target(t: &Target, seed: u64, cases: u64, first: u64) -> Outcome {
    let started = Instant::now();
    let found: Mutex<Vec<Finding>> = Mutex::new(Vec::new());
    let panics = AtomicUsize::new(0);
    let done = AtomicU64::new(0);
    let accepted = AtomicU64::new(0);
    let finished = AtomicBool::new(false);
    let key = name_hash(t.id);
    let show = std::io::stderr().is_terminal() && cases > 1;
    let slowest = std::thread::scope(|s| {
        if show {
            s.spawn(|| {
                while !finished.load(Ordering::Relaxed) {
                    std::thread::sleep(Duration::from_millis(250));
                    let n = done.load(Ordering::Relaxed);
                    let secs = started.elapsed().as_secs_f64();
                    eprint!(
                        "\r{:<14} {n:>9}/{cases} cases {:>9.0} cases/s  ",
                        t.id,
                        n as f64 / secs.max(1e-9)
                    );
                }
                eprint!("\r{:<72}\r", "");
            });
        }
        let slowest = (first..first + cases)
            .into_par_iter()
            .map(|case| {
                // after 5 panics the rest of the target is skipped
                if panics.load(Ordering::Relaxed) >= 5 {
                    return (Duration::ZERO, case);
                }
                let bytes = input(seed, key, case, t);
                let t0 = Instant::now();
                let r = run_case(t, &bytes);
                let took = t0.elapsed();
                done.fetch_add(1, Ordering::Relaxed);
                if r == Ok(true) {
                    accepted.fetch_add(1, Ordering::Relaxed);
                }
                if let Err(message) = r {
                    panics.fetch_add(1, Ordering::Relaxed);
                    if let Ok(mut f) = found.lock() {
                        f.push(Finding {
                            case,
                            message,
                            input: bytes,
                        });
                    }
                }
                (took, case)
            })
            .reduce(
                || (Duration::ZERO, u64::MAX),
                |a, b| if b.0 > a.0 { b } else { a },
            );
        finished.store(true, Ordering::Relaxed);
        slowest
    });
    let mut findings = found.into_inner().unwrap_or_else(|e| e.into_inner());
    findings.sort_by_key(|f| f.case);
    Outcome {
        cases,
        accepted: accepted.into_inner(),
        seconds: started.elapsed().as_secs_f64(),
        slowest,
        findings,
    }
}

fn safe_name(s: &str) -> String {
    s.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// Writes a finding's input and a note with the message and the command that reproduces
/// it; returns the input's path.
fn write_finding(dir: &Path, t: &Target, seed: u64, f: &Finding) -> Result<PathBuf> {
    std::fs::create_dir_all(dir).with_context(|| dir.display().to_string())?;
    let stem = format!("{}-seed{seed}-case{}", safe_name(t.id), f.case);
    let file = dir.join(format!("{stem}.bin"));
    std::fs::write(&file, &f.input).with_context(|| file.display().to_string())?;
    let note = dir.join(format!("{stem}.txt"));
    std::fs::write(
        &note,
        format!(
            "target: {} ({})\ncase: {} of seed {seed}\npanic: {}\n\nreproduce:\n  \
             cargo xtask fuzz --target {} --seed {seed} --case {}\n  \
             cargo xtask fuzz --target {} --input {}\n",
            t.id,
            t.what,
            f.case,
            f.message,
            t.id,
            f.case,
            t.id,
            file.display()
        ),
    )
    .with_context(|| note.display().to_string())?;
    Ok(file)
}

/// Runs `cargo xtask fuzz` with its arguments.
pub fn run(args: impl Iterator<Item = String>) -> Result<()> {
    let Some(opts) = options(args)? else {
        return Ok(());
    };
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let all = targets(&root)?;
    if opts.list {
        for t in &all {
            println!("{:<14} {} ({} seeds)", t.id, t.what, t.seeds.len());
        }
        return Ok(());
    }
    let chosen: Vec<&Target> = match &opts.only {
        None => all.iter().collect(),
        Some(names) => {
            for n in names {
                if !all.iter().any(|t| t.id == n) {
                    bail!(
                        "no fuzz target `{n}`; the targets are: {}",
                        all.iter().map(|t| t.id).collect::<Vec<_>>().join(", ")
                    );
                }
            }
            all.iter()
                .filter(|t| names.iter().any(|n| n == t.id))
                .collect()
        }
    };
    // panics are caught and reported by run_case, not printed by the default hook
    std::panic::set_hook(Box::new(|info| {
        let at = info
            .location()
            .map(|l| format!(" at {}:{}", l.file(), l.line()))
            .unwrap_or_default();
        PANIC_AT.with(|p| *p.borrow_mut() = Some(at));
    }));
    if let Some(file) = &opts.input {
        let bytes = std::fs::read(file).with_context(|| file.display().to_string())?;
        let mut failed = 0;
        for t in &chosen {
            match run_case(t, &bytes) {
                Ok(accepted) => println!(
                    "{:<14} ok ({})",
                    t.id,
                    if accepted { "accepted" } else { "an error" }
                ),
                Err(m) => {
                    failed += 1;
                    println!("{:<14} PANIC: {m}", t.id);
                }
            }
        }
        if failed > 0 {
            bail!("{} made {failed} target(s) panic", file.display());
        }
        return Ok(());
    }
    if let Some(file) = &opts.save {
        let (Some(case), [t]) = (opts.case, chosen.as_slice()) else {
            bail!("--save FILE needs --case N and one --target");
        };
        let bytes = input(opts.seed, name_hash(t.id), case, t);
        std::fs::write(file, bytes).with_context(|| file.display().to_string())?;
    }
    let (first, cases) = match opts.case {
        Some(c) => (c, 1),
        None => (0, opts.cases),
    };
    let seed = opts.seed;
    let out_dir = root.join("target/fuzz-failures");
    println!(
        "fuzzing {} targets, {cases} cases each, seed {seed}, {} threads",
        chosen.len(),
        rayon::current_num_threads()
    );
    let started = Instant::now();
    let mut failures = 0;
    for t in &chosen {
        let o = run_target(t, seed, cases, first);
        println!(
            "{:<14} {:>9} cases {:>7.1} s {:>9.0} cases/s {:>5.1}% accepted  slowest {:>6.1} ms (case {})  {}",
            t.id,
            o.cases,
            o.seconds,
            o.cases as f64 / o.seconds.max(1e-9),
            100.0 * o.accepted as f64 / o.cases.max(1) as f64,
            o.slowest.0.as_secs_f64() * 1e3,
            o.slowest.1,
            if o.findings.is_empty() {
                "ok".to_string()
            } else {
                format!("{} PANIC(S)", o.findings.len())
            }
        );
        std::io::stdout().flush().ok();
        for f in &o.findings {
            failures += 1;
            let file = write_finding(&out_dir, t, seed, f)?;
            let shown: String = f
                .input
                .iter()
                .take(200)
                .flat_map(|b| std::ascii::escape_default(*b))
                .map(char::from)
                .collect();
            println!(
                "  PANIC in {} ({}), case {} of seed {seed}: {}\n    input ({} bytes, in {}): {shown}\n    \
                 reproduce: cargo xtask fuzz --target {} --seed {seed} --case {}",
                t.id,
                t.what,
                f.case,
                f.message,
                f.input.len(),
                file.display(),
                t.id,
                f.case
            );
        }
    }
    println!("total {:.1} s", started.elapsed().as_secs_f64());
    if failures > 0 {
        bail!(
            "{failures} input(s) made a parser panic; inputs and notes in {}",
            out_dir.display()
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn root() -> PathBuf {
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
    }

    /// A case's input depends on the seed, the target and the case number only: the same
    /// with 1 and with 2 threads and in any order.
    #[test]
    fn inputs_do_not_depend_on_threads_or_order() {
        let all = targets(&root()).unwrap();
        for t in &all {
            let key = name_hash(t.id);
            let one: Vec<Vec<u8>> = rayon::ThreadPoolBuilder::new()
                .num_threads(1)
                .build()
                .unwrap()
                .install(|| {
                    (0..200usize)
                        .into_par_iter()
                        .map(|c| input(7, key, c as u64, t))
                        .collect()
                });
            let two: Vec<Vec<u8>> = rayon::ThreadPoolBuilder::new()
                .num_threads(2)
                .build()
                .unwrap()
                .install(|| {
                    (0..200usize)
                        .into_par_iter()
                        .rev()
                        .map(|c| input(7, key, c as u64, t))
                        .collect::<Vec<_>>()
                        .into_iter()
                        .rev()
                        .collect()
                });
            assert!(one == two, "{}", t.id);
            // and the inputs vary
            assert!(one.iter().any(|i| i != &one[0]), "{}", t.id);
        }
    }

    /// Every target runs a short burst without a panic, and a panicking target is caught.
    #[test]
    fn a_short_run_passes_and_panics_are_caught() {
        let all = targets(&root()).unwrap();
        for t in &all {
            let o = run_target(t, 3, 300, 0);
            assert!(o.findings.is_empty(), "{}: {}", t.id, o.findings[0].message);
        }
        fn boom(b: &[u8]) -> bool {
            if b.len() > 3 {
                panic!("boom");
            }
            true
        }
        let t = Target {
            id: "boom",
            what: "a target that panics",
            seeds: vec![b"0123456789".to_vec()],
            text: true,
            run: boom,
        };
        let prev = std::panic::take_hook();
        std::panic::set_hook(Box::new(|_| {}));
        let o = run_target(&t, 1, 50, 0);
        std::panic::set_hook(prev);
        assert!(!o.findings.is_empty() && o.findings.len() <= 50);
        assert!(o.findings[0].message.contains("boom"));
        let d = std::env::temp_dir().join(format!("monovo-fuzz-test-{}", std::process::id()));
        let f = write_finding(&d, &t, 1, &o.findings[0]).unwrap();
        assert_eq!(std::fs::read(&f).unwrap(), o.findings[0].input);
        let note = std::fs::read_to_string(f.with_extension("txt")).unwrap();
        assert!(note.contains("--target boom --seed 1 --case"), "{note}");
        std::fs::remove_dir_all(&d).ok();
    }
}
