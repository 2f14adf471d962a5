//! The stages of bench-synthetic, each on data with known truth (the response and vignette
//! stages are modules of their own), and the measurements they share: peak memory, median
//! times.

use std::time::Instant;

use anyhow::Result;
use camera_model::{output_intrinsics, CameraFile, Image, ImageSize, OutputMode, RectifyMap};

use crate::Figure;

/// Resets the kernel's peak-RSS counter of this process (Linux); later [`peak_rss_mb`] reads
/// the peak since then. Returns the resident memory at the reset in MB, where the peak starts
/// from: what the process holds already, among it memory that earlier stages freed and the
/// allocator kept (0 where /proc is unavailable).
pub fn reset_peak_rss() -> f64 {
    release_free_memory();
    let _ = std::fs::write("/proc/self/clear_refs", "5");
    status_mb("VmRSS:")
}

/// Gives the pages that the allocator holds free back to the system (glibc's
/// `malloc_trim(0)`), so that the resident memory at a reset is what the process uses: glibc
/// keeps what earlier stages freed in its per-thread arenas, resident, and a stage that
/// allocates as much again reuses it without raising the peak (the rectify stage's freed
/// vignette and frames hid the response calibration's working memory entirely).
#[cfg(all(target_os = "linux", target_env = "gnu"))]
fn release_free_memory() {
    extern "C" {
        fn malloc_trim(pad: usize) -> std::os::raw::c_int;
    }
    // SAFETY: malloc_trim takes no pointer and only hands free memory of the allocator back to
    // the system; glibc allows it at any time, from any thread
    #[allow(unsafe_code)]
    unsafe {
        malloc_trim(0);
    }
}

/// Elsewhere the allocator is not glibc's: nothing to release.
#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
fn release_free_memory() {}

/// Peak resident memory in MB since the last reset (0 where /proc is unavailable).
pub fn peak_rss_mb() -> f64 {
    status_mb("VmHWM:")
}

/// A memory line of /proc/self/status (`key` with its colon) in MB; 0 where it is missing.
fn status_mb(key: &str) -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with(key))
                .and_then(|l| l.split_whitespace().nth(1))
                .and_then(|v| v.parse::<f64>().ok())
        })
        .map_or(0.0, |kb| kb / 1024.0)
}

/// Median wall time of `f` in milliseconds over `n` runs.
pub fn median_ms(n: usize, mut f: impl FnMut()) -> f64 {
    let mut t: Vec<f64> = (0..n)
        .map(|_| {
            let s = Instant::now();
            f();
            s.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    t.sort_by(f64::total_cmp);
    t[t.len() / 2]
}

const DATASET_CAMERA: &str = "0.535719308086809 0.669566858850269 0.493248545285398 0.500408664348414 0.897966326944875\n1280 1024\ncrop\n640 480\n";

/// Demo stage (full runs and `--only demo`; the CI runs the demo itself after the quick
/// benchmark): the README's main job, `monovo demo`, as a user runs it, from start to end,
/// with the release binary built first.
pub fn demo(quick: bool) -> Result<Vec<Figure>> {
    if quick {
        return Ok(Vec::new());
    }
    println!("stage demo: monovo demo, release build, from start to end");
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .ok_or_else(|| anyhow::anyhow!("the workspace root"))?;
    let built = std::process::Command::new(env!("CARGO"))
        .args(["build", "--release", "--locked", "-p", "monovo"])
        .current_dir(root)
        .status()?;
    anyhow::ensure!(built.success(), "cargo build -p monovo failed");
    let out = std::env::temp_dir().join(format!("monovo-bench-demo-{}", std::process::id()));
    let t0 = Instant::now();
    let ran = std::process::Command::new(root.join("target/release/monovo"))
        .args(["demo", "--force", "-o"])
        .arg(&out)
        .stdout(std::process::Stdio::null())
        .status()?;
    let seconds = t0.elapsed().as_secs_f64();
    let _ = std::fs::remove_dir_all(&out);
    anyhow::ensure!(ran.success(), "monovo demo failed");
    println!("  {seconds:.1} s");
    Ok(vec![Figure::lower("demo.seconds", seconds, "s")])
}

/// Camera stage: output K against DESIGN.md's reference numbers, map build and remap speed.
pub fn camera(quick: bool) -> Result<Vec<Figure>> {
    println!("stage camera: FOV 1280x1024 -> pinhole 640x480");
    let file = CameraFile::parse(DATASET_CAMERA)?;
    let out = ImageSize::new(640, 480);
    let crop = output_intrinsics(&file.input, file.input_size, &OutputMode::Crop, out)?;
    let full = output_intrinsics(&file.input, file.input_size, &OutputMode::Full, out)?;
    let want_crop = [277.524, 291.680, 312.474, 240.036];
    let want_full = [214.536, 198.679, 311.353, 240.083];
    let err = [crop.fx, crop.fy, crop.cx, crop.cy]
        .iter()
        .zip(want_crop)
        .chain([full.fx, full.fy, full.cx, full.cy].iter().zip(want_full))
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    reset_peak_rss();
    let build = median_ms(if quick { 3 } else { 10 }, || {
        let _ = RectifyMap::new(&file.input, file.input_size, crop, out);
    });
    let map = RectifyMap::new(&file.input, file.input_size, crop, out)?;
    let raw = Image::from_fn(1280, 1024, |x, y| ((x * 31 + y * 17) % 251) as u8);
    let mut dst = Image::filled(640, 480, 0u8);
    let remap = median_ms(if quick { 50 } else { 300 }, || {
        let _ = map.remap_u8_into(&raw, &mut dst);
    });
    Ok(vec![
        Figure::lower("camera.k_error_px", err, "px"),
        Figure::lower("camera.invalid_pixels_crop", map.invalid_count() as f64, ""),
        Figure::lower("camera.build_map_ms", build, "ms"),
        Figure::lower("camera.remap_u8_640x480_ms", remap, "ms"),
        Figure::lower("camera.peak_rss_mb", peak_rss_mb(), "MB"),
    ])
}

/// Evaluation stage: exactness on known drift, one 10,000-pose run, and a batch of runs
/// (2 methods x sequences x 2 directions x 5 runs) parsed and evaluated in parallel.
pub fn eval(quick: bool) -> Result<Vec<Figure>> {
    use eval_metrics::{evaluate, parse_tum, GroundTruth};
    use rayon::prelude::*;
    use synthetic::results::{default_methods, run_text, sequence_path};
    use synthetic::trajectory::{
        benchmark_path, estimate, tum_text, Drift, EstimateConfig, PathConfig,
    };

    println!("stage eval: drift metrics on synthetic runs with known drift");
    let path = benchmark_path(
        3,
        &PathConfig {
            frames: 10_000,
            ..PathConfig::default()
        },
    );
    let gt = GroundTruth::parse(&path.ground_truth_sync())?;
    let run = |drift: Drift| {
        let cfg = EstimateConfig {
            drift,
            world_scale: 2.5,
            ..EstimateConfig::default()
        };
        parse_tum(&tum_text(&estimate(&path, &cfg, 3)))
    };
    let scale = evaluate(
        &run(Drift {
            scale_jumps: vec![(5000, 0.8)],
            ..Drift::default()
        })?,
        &gt,
    );
    let rot = evaluate(
        &run(Drift {
            rotation_jumps: vec![(5000, [0.3, 0.1, 1.0], 10.0)],
            ..Drift::default()
        })?,
        &gt,
    );
    let e_s_err = (scale.metrics.e_s - 0.8).abs() / 0.8;
    let e_r_err = (rot.metrics.e_r - 10.0).abs();
    let text = tum_text(&estimate(
        &path,
        &EstimateConfig {
            drift: Drift {
                scale_walk: 1e-3,
                ..Drift::default()
            },
            ..EstimateConfig::default()
        },
        4,
    ));
    let single = median_ms(if quick { 5 } else { 20 }, || {
        if let Ok(t) = parse_tum(&text) {
            let _ = evaluate(&t, &gt);
        }
    });
    // batch
    let sequences = if quick { 10 } else { 50 };
    let frames = 2000;
    let methods = default_methods();
    let paths: Vec<_> = (1..=sequences)
        .into_par_iter()
        .map(|i| sequence_path(1, i, frames))
        .collect();
    let gts: Vec<GroundTruth> = paths
        .iter()
        .map(|p| GroundTruth::parse(&p.ground_truth_sync()))
        .collect::<Result<_, _>>()?;
    let mut texts = Vec::new();
    for (mi, m) in methods.iter().enumerate() {
        for (s, p) in paths.iter().enumerate() {
            for bwd in [false, true] {
                for r in 0..5 {
                    texts.push((s, run_text(1, p, m, mi, s + 1, bwd, r)));
                }
            }
        }
    }
    reset_peak_rss();
    let t0 = Instant::now();
    let failed: usize = texts
        .par_iter()
        .map(|(s, t)| match parse_tum(t) {
            Ok(traj) => usize::from(!evaluate(&traj, &gts[*s]).is_ok()),
            Err(_) => 1,
        })
        .sum();
    let batch_ms = t0.elapsed().as_secs_f64() * 1e3;
    println!(
        "  {} runs evaluated, {failed} failed (by design of the synthetic methods)",
        texts.len()
    );
    Ok(vec![
        Figure::lower("eval.e_s_rel_error_scale_jump", e_s_err, ""),
        Figure::lower("eval.e_r_error_rotation_jump_deg", e_r_err, "deg"),
        Figure::lower("eval.single_10k_poses_ms", single, "ms"),
        Figure::lower(
            &format!("eval.batch_{}_runs_ms", texts.len()),
            batch_ms,
            "ms",
        ),
        Figure::lower("eval.batch_peak_rss_mb", peak_rss_mb(), "MB"),
    ])
}

/// Frames per second of `f` over `frames` frames on a pool of `threads` threads.
fn fps_with_threads(threads: usize, frames: usize, f: impl Fn(usize) + Sync) -> Result<f64> {
    use rayon::prelude::*;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()?;
    let t0 = Instant::now();
    pool.install(|| (0..frames).into_par_iter().for_each(&f));
    Ok(frames as f64 / t0.elapsed().as_secs_f64())
}

/// Rectification stage on a synthetic 1280x1024 JPEG (q90) sequence to 640x480: decoding
/// alone, decoding + rectification + photometric correction (writing excluded), and PNG
/// encoding, with one and two threads; and the correction's accuracy on noise-free frames.
pub fn rectify(quick: bool) -> Result<Vec<Figure>> {
    use photometric::{Correction, InverseResponse, Vignette};
    use synthetic::scene::{SequenceConfig, SyntheticSequence};
    println!(
        "stage rectify: 1280x1024 JPEG q90 -> 640x480 pinhole (JPEG decoder: {})",
        dataset_io::JPEG_DECODER
    );
    let n_unique = if quick { 8 } else { 24 };
    let seq = SyntheticSequence::new(
        2,
        SequenceConfig {
            width: 1280,
            height: 1024,
            frames: n_unique.max(8),
            ..SequenceConfig::default()
        },
    );
    let jpegs: Vec<Vec<u8>> = (0..n_unique)
        .map(|i| dataset_io::encode_jpeg_gray(1280, 1024, &seq.render(i), 90))
        .collect::<Result<_, _>>()?;
    let cam = CameraFile::parse(&seq.camera.camera_txt((640, 480)))?;
    let map = RectifyMap::for_mode(
        &cam.input,
        cam.input_size,
        &OutputMode::Crop,
        ImageSize::new(640, 480),
    )?;
    let resp = InverseResponse::new(seq.response)?;
    let vig = Vignette::from_values(Image::new(1280, 1024, seq.vignette.clone())?)?;
    let fast = photometric::QuantizedCorrection::new(&resp, &vig, map.clone(), 100.0, 16)?;
    let frames = if quick { 48 } else { 240 };
    let decode = |i: usize| {
        let _ = dataset_io::decode_gray8(&jpegs[i % jpegs.len()]);
    };
    let full = |i: usize| {
        if let Ok(img) = dataset_io::decode_gray8(&jpegs[i % jpegs.len()]) {
            let mut out = Image::filled(640, 480, 0u16);
            let _ = fast.apply(&img, Some(seq.exposures_ms[i % jpegs.len()]), &mut out);
        }
    };
    let geometric = |i: usize| {
        if let Ok(img) = dataset_io::decode_gray8(&jpegs[i % jpegs.len()]) {
            let _ = map.remap_u8(&img);
        }
    };
    let small = map.remap_u8(&dataset_io::decode_gray8(&jpegs[0]).map_err(anyhow::Error::msg)?)?;
    let png_ms = median_ms(if quick { 10 } else { 50 }, || {
        let _ = dataset_io::encode_png_u8(640, 480, 1, small.data(), dataset_io::PngSpeed::Fast);
    });
    // Alternating rounds, the best of each: the ratios come from neighbouring measurements,
    // so that the machine's drift (its clock, other load) does not enter them.
    let (mut dec1, mut dec2, mut geo1, mut full1, mut full2) = (0f64, 0f64, 0f64, 0f64, 0f64);
    let per_round = frames / 3;
    for _ in 0..3 {
        dec1 = dec1.max(fps_with_threads(1, per_round, decode)?);
        geo1 = geo1.max(fps_with_threads(1, per_round, geometric)?);
        full1 = full1.max(fps_with_threads(1, per_round, full)?);
        dec2 = dec2.max(fps_with_threads(2, per_round, decode)?);
        full2 = full2.max(fps_with_threads(2, per_round, full)?);
    }
    println!(
        "  decode {dec1:.0}/{dec2:.0} fps (1/2 threads), +rectify {geo1:.0} fps, +rectify+photometric {full1:.0}/{full2:.0} fps, PNG {png_ms:.2} ms"
    );
    // accuracy of the correction on a noise-free frame: U(I)/(tV) against the true radiance
    let b_true = 12.0f64;
    let t = 4.0;
    let frame = Image::from_fn(1280, 1024, |x, y| {
        synthetic::camera::response_value(
            &seq.response,
            t * seq.vignette[y * 1280 + x] as f64 * b_true,
        )
        .round() as u8
    });
    let written = written_pipeline(&jpegs, &seq, &resp, &vig, if quick { 60 } else { 300 })?;
    println!(
        "  written sequence ({} threads): decode only {:.0} fps, monovo rectify (zip read, decode, remap, PNG, write) {:.0} fps, ratio {:.2}; --compression none {:.0} fps, ratio {:.2}",
        rayon::current_num_threads(),
        written.decode_fps,
        written.fast_fps,
        written.fast_ratio,
        written.stored_fps,
        written.stored_ratio,
    );
    println!(
        "  fixed cost: a one-frame run takes {:.1} ms (the map, pcalib.txt and vignette.png, the rectified vignette, one frame)",
        written.one_frame_ms
    );
    if let Some((ratio, fps)) = written.half {
        println!(
            "  --half-decode (libjpeg-turbo's DCT-domain half-size decoding, then the remap from it): {fps:.0} fps, {ratio:.2} of decoding the full frames alone"
        );
    }
    let raw = Correction::new(&resp, Some(&vig), None, (1280, 1024), false)?;
    let got = raw.correct(&frame, Some(t))?;
    let rel = got
        .data()
        .iter()
        .map(|v| ((*v as f64 - b_true) / b_true).abs())
        .fold(0.0, f64::max);
    Ok([
        Figure::lower("rectify.decode_ms_1thread", 1e3 / dec1, "ms"),
        Figure {
            key: "rectify.decode_fps_2threads".into(),
            value: dec2,
            unit: "fps",
            lower_is_better: false,
        },
        Figure {
            key: "rectify.full_over_decode_ratio_1thread".into(),
            value: full1 / dec1,
            unit: "",
            lower_is_better: false,
        },
        Figure {
            key: "rectify.geometric_over_decode_ratio_1thread".into(),
            value: geo1 / dec1,
            unit: "",
            lower_is_better: false,
        },
        Figure {
            key: "rectify.full_fps_2threads".into(),
            value: full2,
            unit: "fps",
            lower_is_better: false,
        },
        Figure::lower("rectify.png_encode_over_decode", png_ms / (1e3 / dec1), ""),
        Figure {
            key: "rectify.written_over_decode_ratio".into(),
            value: written.fast_ratio,
            unit: "",
            lower_is_better: false,
        },
        Figure {
            key: "rectify.written_stored_over_decode_ratio".into(),
            value: written.stored_ratio,
            unit: "",
            lower_is_better: false,
        },
        Figure::lower("rectify.one_frame_run_ms", written.one_frame_ms, "ms"),
        Figure::lower("rectify.correction_max_rel_error", rel, ""),
    ]
    .into_iter()
    .chain(written.half.map(|(ratio, _)| Figure {
        key: "rectify.written_half_decode_over_decode_ratio".into(),
        value: ratio,
        unit: "",
        lower_is_better: false,
    }))
    .collect())
}

/// The whole `monovo rectify` against decoding alone, on the current thread pool, in one run:
/// `frames` frames (the `jpegs` in turn) are written as a zipped sequence folder with the
/// sequence's `response` and `vignette` as pcalib.txt and vignette.png, then read
/// and decoded (nothing else), and rectified by `rectify_sequence` into PNG frames on disk,
/// compressed (the default) and stored. Each is run twice, alternately, and the faster run
/// of each counts.
fn written_pipeline(
    jpegs: &[Vec<u8>],
    seq: &synthetic::scene::SyntheticSequence,
    response: &photometric::InverseResponse,
    vignette: &photometric::Vignette,
    frames: usize,
) -> Result<Written> {
    use monovo_pipelines::rectify::{rectify_sequence, FrameCompression, RectifyJob};
    let root = std::env::temp_dir().join(format!("monovo-bench-rectify-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    let input = root.join("sequence");
    std::fs::create_dir_all(&input)?;
    let entries = (0..frames).map(|i| (format!("{i:05}.jpg"), jpegs[i % jpegs.len()].clone()));
    dataset_io::write_images_zip(&input.join("images.zip"), entries)?;
    let rows: Vec<dataset_io::TimeRow> = (0..frames)
        .map(|i| dataset_io::TimeRow {
            id: format!("{i:05}"),
            timestamp: i as f64 * 0.05,
            exposure_ms: Some(seq.exposures_ms[i % seq.exposures_ms.len()]),
            timestamp_ns: None,
        })
        .collect();
    std::fs::write(input.join("times.txt"), dataset_io::times_text(&rows))?;
    std::fs::write(input.join("camera.txt"), seq.camera.camera_txt((640, 480)))?;
    // the calibration files every sequence of the dataset has: the rectified sequence gets
    // the vignette remapped, and reading them is part of a run's fixed cost
    std::fs::write(input.join("pcalib.txt"), response.to_text())?;
    let v16 = vignette.to_u16();
    let (vw, vh) = v16.size();
    std::fs::write(
        input.join("vignette.png"),
        dataset_io::encode_png_u16(vw, vh, v16.data(), dataset_io::PngSpeed::Default)?,
    )?;
    let decode_only = || -> Result<f64> {
        let t0 = Instant::now();
        let s = dataset_io::Sequence::open(&input)?;
        let indices: Vec<usize> = (0..s.len()).collect();
        s.process_native(
            &indices,
            rayon::current_num_threads() * 4,
            |f| Ok::<usize, dataset_io::DatasetError>(f.image.size().0),
            |_| Ok(()),
        )?;
        Ok(t0.elapsed().as_secs_f64())
    };
    let rectify =
        |compression: FrameCompression, half_decode: bool, one_frame: bool| -> Result<f64> {
            let t0 = Instant::now();
            let job = RectifyJob {
                force: true,
                compression,
                half_decode,
                range: one_frame.then(|| "0..1".to_string()),
                ..RectifyJob::new(input.clone(), root.join("rectified"))
            };
            rectify_sequence(&job, &monovo_pipelines::Silent)?;
            Ok(t0.elapsed().as_secs_f64())
        };
    let (mut decode, mut fast, mut stored, mut half) = (f64::MAX, f64::MAX, f64::MAX, f64::MAX);
    for _ in 0..2 {
        decode = decode.min(decode_only()?);
        fast = fast.min(rectify(FrameCompression::Fast, false, false)?);
        stored = stored.min(rectify(FrameCompression::None, false, false)?);
        if dataset_io::HALF_DECODE {
            half = half.min(rectify(FrameCompression::Fast, true, false)?);
        }
    }
    // the fixed cost: a one-frame run (open, map, pcalib.txt and vignette.png, the rectified
    // vignette, one frame), the median of five
    let mut one: Vec<f64> = (0..5)
        .map(|_| rectify(FrameCompression::Fast, false, true))
        .collect::<Result<_>>()?;
    one.sort_by(f64::total_cmp);
    let _ = std::fs::remove_dir_all(&root);
    let f = frames as f64;
    Ok(Written {
        fast_ratio: decode / fast,
        stored_ratio: decode / stored,
        fast_fps: f / fast,
        stored_fps: f / stored,
        decode_fps: f / decode,
        one_frame_ms: one[2] * 1e3,
        half: dataset_io::HALF_DECODE.then(|| (decode / half, f / half)),
    })
}

/// What [`written_pipeline`] measured: throughputs in frames per second and their ratios
/// to decoding alone.
struct Written {
    fast_ratio: f64,
    stored_ratio: f64,
    fast_fps: f64,
    stored_fps: f64,
    decode_fps: f64,
    /// A one-frame run, milliseconds: the run's fixed cost and one frame.
    one_frame_ms: f64,
    /// With `--half-decode` (built with the turbojpeg feature): the ratio to decoding the full
    /// frames alone, and the throughput.
    half: Option<(f64, f64)>,
}

/// In-memory frames of a synthetic plane sequence with their true poses.
pub struct MemoryPlaneFrames {
    /// Rendered images.
    pub images: Vec<photometric::PlaneImage>,
    /// The truth.
    pub seq: synthetic::plane::PlaneSequence,
}

impl photometric::PlaneFrames for MemoryPlaneFrames {
    fn len(&self) -> usize {
        self.images.len()
    }
    fn frame(&self, i: usize) -> Result<photometric::PlaneFrame, photometric::PhotometricError> {
        let p = self.seq.poses[i];
        Ok(photometric::PlaneFrame {
            image: self.images[i].clone(),
            exposure_ms: self.seq.exposures_ms[i],
            pose: photometric::PlanePose { r: p.r, t: p.t },
        })
    }
}
