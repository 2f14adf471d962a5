//! Criterion benchmarks: building the rectification map for the benchmark camera
//! (1280x1024 -> 640x480) and remapping one frame.
#![allow(missing_docs, clippy::unwrap_used)]

use camera_model::{CameraFile, Image, ImageSize, OutputMode, RectifyMap};
use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use std::hint::black_box;

const CAMERA: &str = "0.535719308086809 0.669566858850269 0.493248545285398 0.500408664348414 0.897966326944875\n1280 1024\ncrop\n640 480\n";

fn bench(c: &mut Criterion) {
    let file = CameraFile::parse(CAMERA).unwrap();
    let out = ImageSize::new(640, 480);
    let mut g = c.benchmark_group("rectify");
    g.throughput(Throughput::Elements(out.pixels() as u64));
    g.bench_function("build_map_1280x1024_to_640x480", |b| {
        b.iter(|| {
            RectifyMap::for_mode(
                black_box(&file.input),
                file.input_size,
                &OutputMode::Crop,
                out,
            )
            .unwrap()
        })
    });
    let map = RectifyMap::for_mode(&file.input, file.input_size, &OutputMode::Crop, out).unwrap();
    let raw = Image::from_fn(1280, 1024, |x, y| ((x * 31 + y * 17) % 251) as u8);
    let mut dst = Image::filled(640, 480, 0u8);
    g.bench_function("remap_u8_640x480", |b| {
        b.iter(|| map.remap_u8_into(black_box(&raw), &mut dst).unwrap())
    });
    let rawf = raw.map(|v| v as f32);
    let mut dstf = Image::filled(640, 480, 0f32);
    g.bench_function("remap_f32_640x480", |b| {
        b.iter(|| map.remap_f32_into(black_box(&rawf), &mut dstf).unwrap())
    });
    let mut lut = [0f32; 256];
    for (i, v) in lut.iter_mut().enumerate() {
        *v = (i as f32 / 255.0).powf(2.2) * 255.0;
    }
    g.bench_function("remap_u8_lut_to_f32_640x480", |b| {
        b.iter(|| {
            map.remap_u8_lut_into(black_box(&raw), &lut, &mut dstf)
                .unwrap()
        })
    });
    let mut lut16 = [0u16; 256];
    for (i, v) in lut16.iter_mut().enumerate() {
        *v = ((i as f32 / 255.0).powf(2.2) * 65535.0) as u16;
    }
    let gain = vec![1.0f32 / 256.0 / 257.0; out.pixels()];
    g.bench_function("remap_lut_gain_to_u8_640x480", |b| {
        b.iter(|| {
            map.remap_lut_gain_into(black_box(&raw), &lut16, &gain, 1.0, 255, &mut dst)
                .unwrap()
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
