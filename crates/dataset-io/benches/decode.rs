//! Criterion benchmarks: decoding a 1280x1024 JPEG (quality 90) of a synthetic benchmark
//! frame, the physical limit of playback (zune-jpeg; libjpeg-turbo with `--features
//! turbojpeg`, which adds its half-size decode), and encoding a 640x480 PNG.
#![allow(missing_docs, clippy::unwrap_used)]

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use dataset_io::{decode_gray8, encode_jpeg_gray, encode_png_u8, PngSpeed};
use std::hint::black_box;
use synthetic::scene::{SequenceConfig, SyntheticSequence};

fn bench(c: &mut Criterion) {
    let seq = SyntheticSequence::new(
        1,
        SequenceConfig {
            width: 1280,
            height: 1024,
            frames: 10,
            ..SequenceConfig::default()
        },
    );
    let frame = seq.render(5);
    let jpeg = encode_jpeg_gray(1280, 1024, &frame, 90).unwrap();
    let mut g = c.benchmark_group("io");
    g.throughput(Throughput::Elements(1));
    g.bench_function("decode_jpeg_1280x1024_q90", |b| {
        b.iter(|| decode_gray8(black_box(&jpeg)).unwrap())
    });
    if dataset_io::HALF_DECODE {
        g.bench_function("decode_jpeg_1280x1024_q90_half_size", |b| {
            b.iter(|| dataset_io::decode_jpeg_gray8_half(black_box(&jpeg)).unwrap())
        });
    }
    let small: Vec<u8> = frame
        .chunks(1280)
        .step_by(2)
        .take(480)
        .flat_map(|r| r.iter().step_by(2).copied())
        .collect();
    g.bench_function("encode_png_640x480_fast", |b| {
        b.iter(|| encode_png_u8(640, 480, 1, black_box(&small), PngSpeed::Fast).unwrap())
    });
    g.bench_function("encode_png_640x480_stored", |b| {
        b.iter(|| encode_png_u8(640, 480, 1, black_box(&small), PngSpeed::Stored).unwrap())
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
