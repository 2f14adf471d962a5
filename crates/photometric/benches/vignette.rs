//! Criterion benchmark of the vignette calibration's passes: a whole calibration (coarse
//! stage, full-resolution C pass, fused V and C iterations to convergence, final
//! statistics, smoothing by cross-validation) of a synthetic marker-plane video, 48 frames
//! at 320x256 with typical sensor noise and the true plane poses (no marker detection, no
//! decoding: the frames are in memory). Throughput is in frame-pixels (one observation
//! position per frame and pixel); the iterations are the same in every sample, so its
//! changes are the passes' cost. Run with `cargo bench -p photometric --bench vignette`.
#![allow(missing_docs, clippy::unwrap_used)]

#[path = "../tests/plane_frames.rs"]
mod plane_frames;

use camera_model::{CameraFile, ImageSize};
use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use photometric::{calibrate_vignette, InverseResponse, VignetteOptions};
use std::hint::black_box;
use synthetic::sensor::{NoiseLevel, Sensor};

fn bench(c: &mut Criterion) {
    let (w, h, n) = (320, 256, 48);
    let frames = plane_frames::set(1, w, h, n, Sensor::preset(NoiseLevel::Typical));
    let cam = CameraFile::parse(&frames.seq.camera.camera_txt((w, h))).unwrap();
    let response = InverseResponse::new(frames.seq.response).unwrap();
    let options = VignetteOptions::default();
    let run = || {
        calibrate_vignette(
            &cam.input,
            ImageSize::new(w, h),
            &response,
            &frames,
            &options,
            &|_, _| {},
        )
        .unwrap()
    };
    // the work of a sample: say how many iterations it takes
    let first = run();
    eprintln!(
        "vignette calibration of {n} frames at {w}x{h}: {} iterations, converged {}",
        first.iterations, first.converged
    );
    let mut g = c.benchmark_group("vignette");
    g.throughput(Throughput::Elements((n * w * h) as u64));
    g.sample_size(10);
    g.bench_function("calibrate_48x320x256", |b| b.iter(|| black_box(run())));
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
