//! The stages of bench-synthetic, each on data with known truth.

use std::time::Instant;

use anyhow::Result;
use camera_model::{output_intrinsics, CameraFile, Image, ImageSize, OutputMode, RectifyMap};

use crate::Figure;

/// Resets the kernel's peak-RSS counter of this process (Linux); later [`peak_rss_mb`] reads
/// the peak since then.
pub fn reset_peak_rss() {
    let _ = std::fs::write("/proc/self/clear_refs", "5");
}

/// Peak resident memory in MB since the last reset (0 where /proc is unavailable).
pub fn peak_rss_mb() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
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

/// Runs every stage.
pub fn run_all(quick: bool) -> Result<Vec<Figure>> {
    let mut figures = Vec::new();
    figures.extend(camera(quick)?);
    Ok(figures)
}

const DATASET_CAMERA: &str = "0.535719308086809 0.669566858850269 0.493248545285398 0.500408664348414 0.897966326944875\n1280 1024\ncrop\n640 480\n";

/// Camera stage: output K against DESIGN.md's reference numbers, map build and remap speed.
fn camera(quick: bool) -> Result<Vec<Figure>> {
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
