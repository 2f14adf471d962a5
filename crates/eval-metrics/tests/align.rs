//! Sim(3) alignment (Umeyama on nalgebra's SVD) and the Sim3 type.
use eval_metrics::nalgebra::{Rotation3, Similarity3, Unit, Vector3};
use eval_metrics::{align_sim3, principal_plane, rotation_angle, AlignFailure, Sim3};
use proptest::prelude::*;

fn v(a: [f64; 3]) -> Vector3<f64> {
    Vector3::from(a)
}

fn rot(axis: [f64; 3], angle: f64) -> Rotation3<f64> {
    Rotation3::from_axis_angle(&Unit::new_normalize(v(axis)), angle)
}

/// Three points that span a plane 10 units wide, so that no random addition can make a set
/// degenerate (the second principal extent stays far above 1e-10 of the first).
const ANCHORS: [[f64; 3]; 3] = [[0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [0.0, 10.0, 0.0]];

fn with_anchors(pts: &[[f64; 3]]) -> Vec<Vector3<f64>> {
    ANCHORS.iter().chain(pts).map(|p| v(*p)).collect()
}

proptest! {
    /// Alignment recovers a known similarity (1e-9 relative) from noise-free points that span
    /// a plane; it must not refuse them.
    #[test]
    fn alignment_recovers_a_known_sim3(
        pts in prop::collection::vec(prop::array::uniform3(-10.0f64..10.0), 1..40),
        axis in prop::array::uniform3(-1.0f64..1.0),
        angle in -3.1f64..3.1,
        scale in 0.01f64..100.0,
        t in prop::array::uniform3(-1000.0f64..1000.0),
    ) {
        prop_assume!(axis.iter().map(|v| v * v).sum::<f64>() > 1e-3);
        let pts = with_anchors(&pts);
        let truth = Sim3 { scale, rotation: rot(axis, angle), translation: v(t) };
        let gt: Vec<_> = pts.iter().map(|p| truth.apply(p)).collect();
        let a = align_sim3(&pts, &gt);
        prop_assert!(a.is_ok(), "{a:?}");
        let a = a.unwrap();
        prop_assert!((a.transform.scale - scale).abs() <= 1e-9 * scale);
        let dr = (a.transform.rotation.matrix() - truth.rotation.matrix()).amax();
        prop_assert!(dr <= 1e-9, "rotation off by {dr}");
        prop_assert!(a.rmse <= 1e-8 * (1.0 + scale * 10.0 + 1000.0));
        prop_assert!((a.transform.rotation.matrix().determinant() - 1.0).abs() < 1e-12);
    }

    /// The alignment is a least-squares optimum: perturbing scale, rotation or translation
    /// never lowers the cost.
    #[test]
    fn alignment_is_optimal_under_perturbation(
        pts in prop::collection::vec(prop::array::uniform3(-10.0f64..10.0), 3..30),
        noise in prop::collection::vec(prop::array::uniform3(-0.5f64..0.5), 33),
        which in 0usize..7,
    ) {
        let pts = with_anchors(&pts);
        let truth = Sim3 { scale: 2.0, rotation: rot([0.3, -0.5, 0.8], 0.7), translation: v([1.0, 2.0, 3.0]) };
        let gt: Vec<_> = pts.iter().zip(&noise).map(|(p, n)| truth.apply(p) + v(*n)).collect();
        let a = align_sim3(&pts, &gt);
        prop_assert!(a.is_ok(), "{a:?}");
        let a = a.unwrap();
        let cost = |s: &Sim3| pts.iter().zip(&gt).map(|(p, g)| (s.apply(p) - g).norm_squared()).sum::<f64>();
        let base = cost(&a.transform);
        let mut p = a.transform;
        let h = 1e-4;
        match which {
            0 => p.scale *= 1.0 + h,
            1 => p.scale *= 1.0 - h,
            2..=4 => {
                let mut axis = [0.0; 3];
                axis[which - 2] = 1.0;
                p.rotation = rot(axis, h) * p.rotation;
            }
            5 => p.translation[0] += h,
            _ => p.translation[2] -= h,
        }
        prop_assert!(cost(&p) >= base - 1e-9 * base.max(1e-12));
    }
}

/// A mirror image cannot be reached by a rotation: the reflection fix keeps det R = +1, and
/// the result is the best proper rotation (here the identity on the mirrored plane's axes).
#[test]
fn mirrored_points_give_a_proper_rotation() {
    let pts = with_anchors(&[[1.0, 2.0, 3.0], [-4.0, 1.0, 2.0], [3.0, -3.0, -1.0]]);
    let mirrored: Vec<_> = pts.iter().map(|p| v([p[0], p[1], -p[2]])).collect();
    let a = align_sim3(&pts, &mirrored).unwrap();
    assert!((a.transform.rotation.matrix().determinant() - 1.0).abs() < 1e-12);
    assert!(
        a.rmse > 0.1,
        "a mirror image is not a similarity: {}",
        a.rmse
    );
}

#[test]
fn too_few_collinear_mismatched_and_non_finite_points_are_refused() {
    let p = [v([0.0, 0.0, 0.0]), v([1.0, 0.0, 0.0])];
    assert_eq!(align_sim3(&p, &p), Err(AlignFailure::TooFew(2)));
    let line: Vec<_> = (0..10)
        .map(|i| v([i as f64, 2.0 * i as f64, -(i as f64)]))
        .collect();
    assert_eq!(align_sim3(&line, &line), Err(AlignFailure::Degenerate));
    let same = vec![v([1.0, 1.0, 1.0]); 5];
    assert_eq!(align_sim3(&same, &same), Err(AlignFailure::Degenerate));
    let plane = with_anchors(&[[1.0, 1.0, 1.0]]);
    assert_eq!(
        align_sim3(&plane, &plane[..3]),
        Err(AlignFailure::LengthMismatch { est: 4, gt: 3 })
    );
    let mut bad = plane.clone();
    bad[3][1] = f64::NAN;
    assert_eq!(align_sim3(&plane, &bad), Err(AlignFailure::NonFinite));
    assert_eq!(
        AlignFailure::LengthMismatch { est: 4, gt: 3 }.to_string(),
        "4 estimated points but 3 ground-truth points"
    );
}

#[test]
fn sim3_inverse_compose_and_nalgebra_conversions() {
    let a = Sim3 {
        scale: 1.7,
        rotation: rot([1.0, 2.0, 3.0], 0.4),
        translation: v([1.0, -2.0, 0.5]),
    };
    let b = Sim3 {
        scale: 0.3,
        rotation: rot([-1.0, 0.0, 1.0], 2.0),
        translation: v([0.0, 4.0, 1.0]),
    };
    let p = v([0.3, -0.7, 2.0]);
    let q = a.compose(&b).apply(&p);
    let r = a.apply(&b.apply(&p));
    assert!((q - r).amax() < 1e-12);
    assert!((a.inverse().apply(&a.apply(&p)) - p).amax() < 1e-12);
    // nalgebra's Similarity3 is the same map, both ways
    let n: Similarity3<f64> = a.into();
    assert!((n.transform_point(&p.into()).coords - a.apply(&p)).amax() < 1e-12);
    let back = Sim3::from(n);
    assert!((back.scale - a.scale).abs() < 1e-15);
    assert!((back.rotation.matrix() - a.rotation.matrix()).amax() < 1e-12);
    assert_eq!(back.translation, a.translation);
    let composed: Similarity3<f64> = a.compose(&b).into();
    let product = Similarity3::from(a) * Similarity3::from(b);
    assert!(
        (composed.transform_point(&p.into()) - product.transform_point(&p.into())).amax() < 1e-12
    );
}

/// The atan2 form keeps tiny angles that nalgebra's acos form rounds to zero.
#[test]
fn rotation_angle_is_accurate_for_tiny_and_large_angles() {
    for angle in [1e-12, 1e-9, 1e-6, 0.5, 3.0, std::f64::consts::PI - 1e-7] {
        let r = rot([0.3, -0.2, 0.9], angle);
        let got = rotation_angle(&r);
        assert!(
            (got - angle).abs() <= 1e-9 * angle.max(1e-3),
            "{angle}: {got}"
        );
    }
    assert_eq!(
        rot([0.0, 0.0, 1.0], 1e-9).angle(),
        0.0,
        "acos loses 1e-9 rad"
    );
}

#[test]
fn sim3_serialises_with_serde() {
    let a = Sim3 {
        scale: 2.5,
        rotation: rot([0.0, 1.0, 0.0], 0.25),
        translation: v([1.0, 2.0, 3.0]),
    };
    let json = serde_json::to_string(&a).unwrap();
    let back: Sim3 = serde_json::from_str(&json).unwrap();
    assert_eq!(back, a);
}

/// The principal plane of points on a tilted ellipse: the axes are orthonormal, the first
/// along the long axis, and both lie in the ellipse's plane.
#[test]
fn principal_plane_finds_the_plane_of_a_tilted_ellipse() {
    let tilt = rot([1.0, 0.3, 0.0], 0.7);
    let pts: Vec<Vector3<f64>> = (0..50)
        .map(|i| {
            let a = i as f64 / 50.0 * std::f64::consts::TAU;
            tilt * v([5.0 * a.cos(), 2.0 * a.sin(), 0.0]) + v([1.0, 2.0, 3.0])
        })
        .collect();
    let (ax, ay) = principal_plane(&pts);
    let normal = tilt * v([0.0, 0.0, 1.0]);
    assert!((ax.norm() - 1.0).abs() < 1e-12 && (ay.norm() - 1.0).abs() < 1e-12);
    assert!(ax.dot(&ay).abs() < 1e-12);
    assert!(ax.dot(&normal).abs() < 1e-9 && ay.dot(&normal).abs() < 1e-9);
    assert!(ax.dot(&(tilt * v([1.0, 0.0, 0.0]))).abs() > 1.0 - 1e-9);
}
