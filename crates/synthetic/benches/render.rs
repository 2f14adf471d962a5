//! Criterion benchmarks of the synthetic renderers' per-frame kernels: the sensor model alone
//! (shot, read and ADC noise, the response, defects) on a precomputed textured energy image,
//! and a whole 640x512 frame of the benchmark-like sequence (ray, room texture, vignette,
//! sensor). Throughput is in pixels.
#![allow(missing_docs, clippy::unwrap_used)]

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use std::hint::black_box;
use synthetic::camera::ResponseCurve;
use synthetic::scene::{texture, SequenceConfig, SyntheticSequence};
use synthetic::sensor::{NoiseLevel, Sensor};

fn bench(c: &mut Criterion) {
    let (w, h) = (640, 512);
    let u = ResponseCurve::Dataset.table();
    let sensor = Sensor::preset(NoiseLevel::Typical);
    // the room's texture at a few pixels per lattice cell: energies over the whole range of
    // the response in no order a branch predictor could follow, as in a rendered frame
    let energy: Vec<f64> = (0..w * h)
        .map(|i| 150.0 * texture(3, (i % w) as f64 / 6.0, (i / w) as f64 / 6.0))
        .collect();
    let seq = SyntheticSequence::new(
        1,
        SequenceConfig {
            width: w,
            height: h,
            frames: 4,
            ..SequenceConfig::default()
        },
    );
    // the first frame builds the rays and texture tables once
    black_box(seq.render(0));
    let mut g = c.benchmark_group("synthetic");
    g.throughput(Throughput::Elements((w * h) as u64));
    g.sample_size(20);
    g.bench_function("sensor_capture_640x512", |b| {
        b.iter(|| sensor.capture(&u, w, h, 5.0, black_box(7), |x, y| energy[y * w + x]))
    });
    g.bench_function("render_sequence_frame_640x512", |b| {
        b.iter(|| seq.render(black_box(2)))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
