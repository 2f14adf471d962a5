//! The drift metrics on synthetic runs with known drift.
use crate::common::{gt_of, path, rel, run};
use eval_metrics::nalgebra::{Rotation3, Unit, Vector3};
use eval_metrics::{evaluate, FailReason, Segment, Sim3, Trajectory};
use proptest::prelude::*;
use synthetic::trajectory::{Drift, EstimateConfig};

fn jump_cfg(drift: Drift) -> EstimateConfig {
    EstimateConfig {
        drift,
        ..EstimateConfig::default()
    }
}

#[test]
fn a_perfect_run_has_zero_drift() {
    let p = path(1, 600);
    let e = evaluate(
        &run(
            &p,
            &EstimateConfig {
                world_scale: 3.0,
                ..EstimateConfig::default()
            },
            1,
        ),
        &gt_of(&p),
    );
    assert!(e.is_ok(), "{:?}", e.failure);
    let m = e.metrics;
    assert!(m.e_align < 1e-9 && m.e_t < 1e-9 && m.e_rmse < 1e-9 && m.e_r < 1e-9);
    assert!((m.e_s - 1.0).abs() < 1e-12);
    assert_eq!(e.poses, 600);
    assert_eq!(e.poses_start, p.segment_frames);
    assert_eq!(e.poses_end, p.segment_frames);
}

/// The property: a x0.8 scale jump gives e_s = 0.8, a 10 degree rotation jump gives
/// e_r = 10 (both 1e-9 relative: the estimate is exact up to the jump, TUM text keeps full
/// precision, timestamps are written to the microsecond).
#[test]
fn scale_and_rotation_jumps_are_measured_exactly() {
    let p = path(2, 800);
    let gt = gt_of(&p);
    for at in [200, 400, 600] {
        let e = evaluate(
            &run(
                &p,
                &jump_cfg(Drift {
                    scale_jumps: vec![(at, 0.8)],
                    ..Drift::default()
                }),
                3,
            ),
            &gt,
        );
        assert!(rel(e.metrics.e_s, 0.8) < 1e-9, "{}", e.metrics.e_s);
        assert!(e.metrics.e_r < 1e-7);
        assert!(e.metrics.e_align > 0.1);
        let e = evaluate(
            &run(
                &p,
                &jump_cfg(Drift {
                    rotation_jumps: vec![(at, [0.2, -0.4, 1.0], 10.0)],
                    ..Drift::default()
                }),
                3,
            ),
            &gt,
        );
        assert!(rel(e.metrics.e_r, 10.0) < 1e-9, "{}", e.metrics.e_r);
        assert!(rel(e.metrics.e_s, 1.0) < 1e-9);
    }
}

/// e_r stays accurate for tiny angles (acos would lose it entirely below 1e-6 degrees).
#[test]
fn tiny_rotation_drift_is_accurate() {
    let p = path(4, 500);
    let gt = gt_of(&p);
    for deg in [1e-3, 1e-5, 1e-7] {
        let e = evaluate(
            &run(
                &p,
                &jump_cfg(Drift {
                    rotation_jumps: vec![(250, [0.0, 0.0, 1.0], deg)],
                    ..Drift::default()
                }),
                5,
            ),
            &gt,
        );
        assert!(rel(e.metrics.e_r, deg) < 1e-4, "{deg}: {}", e.metrics.e_r);
    }
}

#[test]
fn drift_transform_matches_the_definition() {
    let p = path(6, 700);
    let drift = Drift {
        scale_jumps: vec![(300, 1.3)],
        rotation_jumps: vec![(420, [1.0, 0.0, 0.3], 7.0)],
        ..Drift::default()
    };
    let e = evaluate(&run(&p, &jump_cfg(drift), 6), &gt_of(&p));
    let d = e.drift().unwrap();
    let (s, en) = (e.start.unwrap(), e.end.unwrap());
    assert!(rel(d.scale, en.scale / s.scale) < 1e-12);
    let t = d.translation;
    assert!(
        rel(
            e.metrics.e_t,
            (t[0] * t[0] + t[1] * t[1] + t[2] * t[2]).sqrt()
        ) < 1e-12
    );
    // e_align by its definition over all poses
    let n = e.positions.len() as f64;
    let sum: f64 = e
        .positions
        .iter()
        .map(|q| {
            let (a, b) = (s.apply(q), en.apply(q));
            (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)
        })
        .sum();
    assert!(rel(e.metrics.e_align, (sum / n).sqrt()) < 1e-12);
    assert!(rel(e.metrics.e_s, 1.3) < 1e-9);
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]
    /// Every metric is invariant to a similarity transform of the estimate (1e-6 relative).
    #[test]
    fn metrics_are_invariant_to_a_sim3_of_the_estimate(
        axis in prop::array::uniform3(-1.0f64..1.0),
        angle in -3.0f64..3.0,
        scale in 0.05f64..20.0,
        t in prop::array::uniform3(-100.0f64..100.0),
        seed in 0u64..1000,
    ) {
        prop_assume!(axis.iter().map(|v| v * v).sum::<f64>() > 1e-3);
        let p = path(seed, 300);
        let gt = gt_of(&p);
        let drift = Drift { scale_walk: 0.002, rotation_walk_deg: 0.05, position_noise: 0.01, ..Drift::default() };
        let est = run(&p, &jump_cfg(drift), seed);
        let a = evaluate(&est, &gt);
        let rotation = Rotation3::from_axis_angle(&Unit::new_normalize(Vector3::from(axis)), angle);
        let sim = Sim3 { scale, rotation, translation: Vector3::from(t) };
        let mut moved = est.clone();
        for q in moved.poses.iter_mut() {
            q.position = sim.apply(&q.position);
        }
        let b = evaluate(&moved, &gt);
        prop_assert!(a.is_ok() && b.is_ok());
        let (ma, mb) = (a.metrics, b.metrics);
        for (x, y) in [(ma.e_align, mb.e_align), (ma.e_s, mb.e_s), (ma.e_t, mb.e_t), (ma.e_rmse, mb.e_rmse),
                       (ma.rmse_start, mb.rmse_start), (ma.rmse_end, mb.rmse_end)] {
            prop_assert!(rel(x, y) < 1e-6, "{x} vs {y}");
        }
        prop_assert!((ma.e_r - mb.e_r).abs() < 1e-6 * ma.e_r.max(1e-3));
    }
}

#[test]
fn failures_are_results_with_reasons() {
    let p = path(8, 400);
    let gt = gt_of(&p);
    let e = evaluate(&Trajectory::default(), &gt);
    assert_eq!(e.failure, Some(FailReason::Empty));
    assert!(e.metrics.e_align.is_infinite());

    let mut est = run(&p, &EstimateConfig::default(), 8);
    est.poses[10].position[1] = f64::NAN;
    assert!(matches!(
        evaluate(&est, &gt).failure,
        Some(FailReason::NonFinite { index: 10, .. })
    ));

    let mut est = run(&p, &EstimateConfig::default(), 8);
    est.poses[5].t += 0.0015;
    assert!(matches!(
        evaluate(&est, &gt).failure,
        Some(FailReason::Unassociated { .. })
    ));
    let mut est = run(&p, &EstimateConfig::default(), 8);
    est.poses[5].t += 0.0009; // within 1 ms: fine
    assert!(evaluate(&est, &gt).is_ok());

    // lost tracking in the middle: no end segment, but the start RMSE is still reported
    let est = run(
        &p,
        &EstimateConfig {
            lost_after: Some(200),
            ..EstimateConfig::default()
        },
        8,
    );
    let e = evaluate(&est, &gt);
    assert_eq!(
        e.failure,
        Some(FailReason::TooFewPoses {
            segment: Segment::End,
            count: 0
        })
    );
    assert!(e.metrics.rmse_start < 1e-9 && e.metrics.e_align.is_infinite());

    // a start segment whose estimated poses are collinear
    let mut est = run(&p, &EstimateConfig::default(), 8);
    for (i, q) in est.poses.iter_mut().take(p.segment_frames).enumerate() {
        q.position = Vector3::new(i as f64, 0.0, 0.0);
    }
    assert_eq!(
        evaluate(&est, &gt).failure,
        Some(FailReason::Degenerate {
            segment: Segment::Start
        })
    );
}

#[test]
fn keyframe_subsets_and_backwards_runs() {
    let p = path(9, 900);
    let gt = gt_of(&p);
    let drift = Drift {
        scale_jumps: vec![(450, 0.9)],
        ..Drift::default()
    };
    let kf = evaluate(
        &run(
            &p,
            &EstimateConfig {
                drift: drift.clone(),
                keyframe_every: 7,
                ..EstimateConfig::default()
            },
            9,
        ),
        &gt,
    );
    assert!(kf.is_ok());
    assert!(rel(kf.metrics.e_s, 0.9) < 1e-9);
    assert_eq!(kf.poses, 900usize.div_ceil(7));

    let bwd = EstimateConfig {
        drift: drift.clone(),
        backwards: true,
        ..EstimateConfig::default()
    };
    let a = evaluate(&run(&p, &bwd, 9), &gt);
    assert!(a.is_ok() && !a.backwards_time_mapped);
    // backwards, the end segment is tracked first: the scale jump shows as 1/0.9
    assert!(rel(a.metrics.e_s, 1.0 / 0.9) < 1e-9, "{}", a.metrics.e_s);
    let b = evaluate(
        &run(
            &p,
            &EstimateConfig {
                backwards_epoch_times: true,
                ..bwd
            },
            9,
        ),
        &gt,
    );
    assert!(b.is_ok() && b.backwards_time_mapped);
    assert!(rel(a.metrics.e_align, b.metrics.e_align) < 1e-9);
    assert!(rel(a.metrics.e_s, b.metrics.e_s) < 1e-12);
}

/// The paper's metric study: e_align depends less on where drift happens than e_t.
#[test]
fn e_align_is_less_sensitive_to_where_drift_happens_than_e_t() {
    let p = path(10, 1000);
    let gt = gt_of(&p);
    let (mut ea, mut et) = (Vec::new(), Vec::new());
    for at in (200..=800).step_by(100) {
        let e = evaluate(
            &run(
                &p,
                &jump_cfg(Drift {
                    scale_jumps: vec![(at, 0.8)],
                    ..Drift::default()
                }),
                11,
            ),
            &gt,
        );
        ea.push(e.metrics.e_align);
        et.push(e.metrics.e_t);
    }
    let spread = |v: &[f64]| {
        v.iter().cloned().fold(f64::MIN, f64::max) / v.iter().cloned().fold(f64::MAX, f64::min)
    };
    assert!(
        spread(&ea) < spread(&et),
        "e_align spread {} e_t spread {}",
        spread(&ea),
        spread(&et)
    );
}
