//! Criterion benchmarks: parsing and evaluating a 10,000-pose run; the field's other metrics
//! (evo's APE and RPE, the TUM RGB-D scripts' RPE, the KITTI segments) on it.
#![allow(missing_docs, clippy::unwrap_used)]

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use eval_metrics::{
    ape, evaluate, kitti_errors, parse_tum, rpe, tum_rpe, AlignMode, ApeOptions, DeltaUnit,
    GroundTruth, PoseTrack, RpeOptions, TumRpeOptions,
};
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

    // The other metrics on the same run against its full ground truth (every row a pose).
    let reference = PoseTrack {
        times: Some(path.times.clone()),
        positions: path.positions.clone(),
        rotations: path.rotations.iter().map(|r| *r.matrix()).collect(),
        quaternions: path
            .rotations
            .iter()
            .map(|r| eval_metrics::nalgebra::UnitQuaternion::from_rotation_matrix(r).into_inner())
            .collect(),
    };
    let estimate = PoseTrack::from_trajectory(&est);
    let mut g = c.benchmark_group("metrics");
    g.throughput(Throughput::Elements(10_000));
    let mut ape_opts = ApeOptions::default();
    ape_opts.align.mode = AlignMode::Sim3;
    g.bench_function("ape_sim3_10k", |b| {
        b.iter(|| ape(black_box(&reference), &estimate, &ape_opts).unwrap())
    });
    let rpe_opts = RpeOptions {
        align: ape_opts.align,
        ..RpeOptions::default()
    };
    g.bench_function("rpe_frames_10k", |b| {
        b.iter(|| rpe(black_box(&reference), &estimate, &rpe_opts).unwrap())
    });
    let rpe_m = RpeOptions {
        delta: 0.5,
        delta_unit: DeltaUnit::Meters,
        all_pairs: true,
        ..rpe_opts
    };
    g.bench_function("rpe_all_pairs_metres_10k", |b| {
        b.iter(|| rpe(black_box(&reference), &estimate, &rpe_m).unwrap())
    });
    g.bench_function("tum_rpe_fixed_delta_10k", |b| {
        b.iter(|| tum_rpe(black_box(&reference), &estimate, &TumRpeOptions::default()).unwrap())
    });
    let seq = [(reference.clone(), estimate.clone())];
    g.bench_function("kitti_10k", |b| b.iter(|| kitti_errors(black_box(&seq))));
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
