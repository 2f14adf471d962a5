//! Properties of the field's other metrics (APE, RPE, the TUM scripts', KITTI's) on synthetic
//! tracks with known truth; their agreement with the reference tools on real files is
//! checked by crates/cli/tests/metrics.rs.

use eval_metrics::nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};
use eval_metrics::{
    ape, kitti_errors, rpe, tum_rpe, AlignMode, ApeOptions, PoseRelation, PoseTrack, RpeOptions,
    SyncMethod, TumRpeOptions,
};

/// A winding 3D path of `n` poses at 20 Hz, turning as it goes.
fn track(n: usize) -> PoseTrack {
    let mut t = PoseTrack {
        times: Some((0..n).map(|i| 1000.0 + i as f64 * 0.05).collect()),
        ..PoseTrack::default()
    };
    for i in 0..n {
        let a = i as f64 * 0.02;
        t.positions
            .push(Vector3::new(10.0 * a.cos(), 6.0 * (1.3 * a).sin(), 0.5 * a));
        let q = UnitQuaternion::from_euler_angles(0.1 * a.sin(), 0.2 * a.cos(), a);
        t.rotations.push(*q.to_rotation_matrix().matrix());
        t.quaternions.push(q.into_inner());
    }
    t
}

/// `track` moved by `p -> s R p + t` (orientations rotated by `R`).
fn moved(t: &PoseTrack, r: Rotation3<f64>, s: f64, tr: Vector3<f64>) -> PoseTrack {
    let mut o = t.clone();
    let q = UnitQuaternion::from_rotation_matrix(&r);
    for p in &mut o.positions {
        *p = r * *p * s + tr;
    }
    for m in &mut o.rotations {
        *m = r.matrix() * *m;
    }
    for x in &mut o.quaternions {
        *x = q.into_inner() * *x;
    }
    o
}

#[test]
fn alignment_recovers_known_similarities_and_yaw() {
    let gt = track(400);
    let r = Rotation3::from_euler_angles(0.3, -0.2, 1.1);
    let est = moved(&gt, r.inverse(), 0.4, Vector3::new(1.0, -2.0, 3.0));
    let mut o = ApeOptions::default();
    o.align.mode = AlignMode::Sim3;
    assert!(ape(&gt, &est, &o).unwrap().stats.rmse < 1e-12);
    // SE(3) cannot undo the scale, scale alone not the rotation
    o.align.mode = AlignMode::Se3;
    assert!(ape(&gt, &est, &o).unwrap().stats.rmse > 0.1);
    // 4-DoF: a yaw and a translation are recovered, a roll is not
    let yaw = Rotation3::from_axis_angle(&Vector3::z_axis(), 2.0);
    let est = moved(&gt, yaw, 1.0, Vector3::new(5.0, 1.0, -1.0));
    o.align.mode = AlignMode::PosYaw;
    let a = ape(&gt, &est, &o).unwrap();
    assert!(a.stats.rmse < 1e-12, "{}", a.stats.rmse);
    o.relation = PoseRelation::AngleDeg;
    assert!(ape(&gt, &est, &o).unwrap().stats.max < 1e-9);
    let roll = Rotation3::from_axis_angle(&Vector3::x_axis(), 0.3);
    o.relation = PoseRelation::TransPart;
    assert!(
        ape(&gt, &moved(&gt, roll, 1.0, Vector3::zeros()), &o)
            .unwrap()
            .stats
            .rmse
            > 0.05
    );
    // with one pose, from that pose's position and yaw
    o.align.n_to_align = Some(1);
    assert!(ape(&gt, &est, &o).unwrap().stats.rmse < 1e-9);
}

#[test]
fn relative_errors_ignore_a_rigid_motion_and_see_drift() {
    let gt = track(300);
    let est = moved(
        &gt,
        Rotation3::from_euler_angles(0.5, 0.1, -0.7),
        1.0,
        Vector3::new(3.0, 2.0, 1.0),
    );
    for relation in [
        PoseRelation::TransPart,
        PoseRelation::AngleDeg,
        PoseRelation::Full,
    ] {
        let o = RpeOptions {
            relation,
            delta: 7.0,
            ..RpeOptions::default()
        };
        assert!(rpe(&gt, &est, &o).unwrap().stats.max < 1e-9, "{relation:?}");
    }
    assert!(
        tum_rpe(&gt, &est, &TumRpeOptions::default())
            .unwrap()
            .translational
            .max
            < 1e-9
    );
    // a scale drift of 10% shows as 10% of every step, in both conventions
    let scaled = moved(&gt, Rotation3::identity(), 1.1, Vector3::zeros());
    let steps: Vec<f64> = gt
        .positions
        .windows(2)
        .map(|w| (w[1] - w[0]).norm())
        .collect();
    let r = rpe(&gt, &scaled, &RpeOptions::default()).unwrap();
    for (e, s) in r.errors.iter().zip(&steps) {
        assert!((e - 0.1 * s).abs() < 1e-12);
    }
    let t = tum_rpe(
        &gt,
        &scaled,
        &TumRpeOptions {
            delta: 1.0,
            delta_unit: eval_metrics::TumDeltaUnit::Frames,
            ..TumRpeOptions::default()
        },
    )
    .unwrap();
    assert!((t.translational.max - 0.1 * steps.iter().copied().fold(0.0, f64::max)).abs() < 1e-12);
}

/// evo compares the motions where a pair starts, the TUM script where it ends: with the
/// estimate's orientation drifting (its positions exact), their translational errors differ.
#[test]
fn evo_and_tum_rpe_differ_under_rotation_drift() {
    let gt = track(200);
    let mut est = gt.clone();
    for (i, m) in est.rotations.iter_mut().enumerate() {
        *m *= *Rotation3::from_axis_angle(&Vector3::y_axis(), 0.002 * i as f64).matrix();
    }
    let evo = rpe(&gt, &est, &RpeOptions::default()).unwrap();
    let tum = tum_rpe(
        &gt,
        &est,
        &TumRpeOptions {
            delta: 1.0,
            delta_unit: eval_metrics::TumDeltaUnit::Frames,
            ..TumRpeOptions::default()
        },
    )
    .unwrap();
    let (a, b) = (evo.stats.mean, tum.translational.mean);
    assert!(a > 1e-4 && b > 1e-4 && (a - b).abs() > 1e-3 * a, "{a} {b}");
    // without the drift both are zero
    let same = rpe(&gt, &gt, &RpeOptions::default()).unwrap();
    assert!(same.stats.max < 1e-12);
}

#[test]
fn interpolation_associates_a_shifted_copy() {
    let gt = track(400);
    let mut est = gt.clone();
    // the estimate's stamps half a frame later, its poses where the reference is then
    let shifted: Vec<f64> = gt
        .times
        .as_ref()
        .unwrap()
        .iter()
        .map(|t| t + 0.025)
        .collect();
    est = eval_metrics::interpolate(&est, &shifted).unwrap();
    let mut o = ApeOptions::default();
    o.sync.max_diff = 0.03;
    o.sync.method = SyncMethod::Interpolation;
    let a = ape(&gt, &est, &o).unwrap();
    // the reference interpolated at the estimate's stamps is the estimate, but past its end
    // (clamped to the last pose)
    assert_eq!(a.stats.n, 400);
    assert!(a.stats.median < 1e-12 && a.errors[..399].iter().all(|e| *e < 1e-12));
    // the nearest stamp instead: half a frame of motion apart
    o.sync.method = SyncMethod::NearestTime;
    assert!(ape(&gt, &est, &o).unwrap().stats.median > 1e-3);
}

#[test]
fn kitti_of_the_ground_truth_itself_is_zero() {
    let mut gt = PoseTrack::default();
    for i in 0..1500 {
        let a = i as f64 * 0.002;
        gt.positions
            .push(Vector3::new(300.0 * a.sin(), 0.0, 300.0 * (1.0 - a.cos())));
        gt.rotations.push(Matrix3::identity());
        gt.quaternions.push(UnitQuaternion::identity().into_inner());
    }
    let r = kitti_errors(&[(gt.clone(), gt)]).unwrap();
    assert!(r.t_err_percent < 1e-12 && r.r_err_deg_per_100m.abs() < 1e-9);
    assert_eq!(r.lengths.len(), 8);
}
