//! Criterion benchmarks: parsing and evaluating a 10,000-pose run.
#![allow(missing_docs, clippy::unwrap_used)]

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use eval_metrics::{evaluate, parse_tum, GroundTruth};
use std::hint::black_box;
use synthetic::trajectory::{
    benchmark_path, estimate, tum_text, Drift, EstimateConfig, PathConfig,
};

fn bench(c: &mut Criterion) {
    let path = benchmark_path(
        1,
        &PathConfig {
            frames: 10_000,
            ..PathConfig::default()
        },
    );
    let gt_text = path.ground_truth_sync();
    let cfg = EstimateConfig {
        drift: Drift {
            scale_walk: 1e-3,
            rotation_walk_deg: 0.01,
            ..Drift::default()
        },
        ..EstimateConfig::default()
    };
    let est_text = tum_text(&estimate(&path, &cfg, 1));
    let gt = GroundTruth::parse(&gt_text).unwrap();
    let est = parse_tum(&est_text).unwrap();
    let mut g = c.benchmark_group("eval");
    g.throughput(Throughput::Elements(10_000));
    g.bench_function("parse_tum_10k", |b| {
        b.iter(|| parse_tum(black_box(&est_text)).unwrap())
    });
    g.bench_function("evaluate_10k", |b| {
        b.iter(|| evaluate(black_box(&est), &gt))
    });
    g.bench_function("parse_and_evaluate_10k", |b| {
        b.iter(|| evaluate(&parse_tum(black_box(&est_text)).unwrap(), &gt))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
