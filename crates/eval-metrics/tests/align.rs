//! SVD and Sim(3) alignment.
use eval_metrics::linalg::{axis_angle, det, mul, svd3, transpose, Mat3};
use eval_metrics::{align_sim3, AlignFailure, Sim3};
use proptest::prelude::*;

fn close(a: &Mat3, b: &Mat3, tol: f64) -> bool {
    (0..3).all(|i| (0..3).all(|j| (a[i][j] - b[i][j]).abs() <= tol))
}

proptest! {
    /// U diag(s) V^T reproduces the matrix; U and V are orthogonal; s sorted, non-negative.
    #[test]
    fn svd_reconstructs(m in prop::array::uniform3(prop::array::uniform3(-100.0f64..100.0))) {
        let (u, s, v) = svd3(&m);
        let us = [[u[0][0]*s[0], u[0][1]*s[1], u[0][2]*s[2]],
                  [u[1][0]*s[0], u[1][1]*s[1], u[1][2]*s[2]],
                  [u[2][0]*s[0], u[2][1]*s[1], u[2][2]*s[2]]];
        let back = mul(&us, &transpose(&v));
        prop_assert!(close(&back, &m, 1e-10 * (1.0 + s[0])));
        let id = [[1.0,0.0,0.0],[0.0,1.0,0.0],[0.0,0.0,1.0]];
        prop_assert!(close(&mul(&transpose(&u), &u), &id, 1e-12));
        prop_assert!(close(&mul(&transpose(&v), &v), &id, 1e-12));
        prop_assert!(s[0] >= s[1] && s[1] >= s[2] && s[2] >= 0.0);
    }

    /// Alignment recovers a known similarity exactly (1e-9 relative) from noise-free points.
    #[test]
    fn alignment_recovers_a_known_sim3(
        pts in prop::collection::vec(prop::array::uniform3(-10.0f64..10.0), 4..40),
        axis in prop::array::uniform3(-1.0f64..1.0),
        angle in -3.1f64..3.1,
        scale in 0.01f64..100.0,
        t in prop::array::uniform3(-1000.0f64..1000.0),
    ) {
        prop_assume!(axis.iter().map(|v| v * v).sum::<f64>() > 1e-3);
        let truth = Sim3 { scale, rotation: axis_angle(axis, angle), translation: t };
        let gt: Vec<_> = pts.iter().map(|p| truth.apply(*p)).collect();
        match align_sim3(&pts, &gt) {
            Ok(a) => {
                prop_assert!((a.transform.scale - scale).abs() <= 1e-9 * scale);
                prop_assert!(close(&a.transform.rotation, &truth.rotation, 1e-9));
                prop_assert!(a.rmse <= 1e-8 * (1.0 + scale * 10.0 + 1000.0));
                prop_assert!((det(&a.transform.rotation) - 1.0).abs() < 1e-12);
            }
            Err(AlignFailure::Degenerate) => {} // random points can be nearly collinear
            Err(e) => prop_assert!(false, "{e:?}"),
        }
    }

    /// The alignment is a least-squares optimum: perturbing scale, rotation or translation
    /// never lowers the cost.
    #[test]
    fn alignment_is_optimal_under_perturbation(
        pts in prop::collection::vec(prop::array::uniform3(-10.0f64..10.0), 6..30),
        noise in prop::collection::vec(prop::array::uniform3(-0.5f64..0.5), 30),
        which in 0usize..7,
    ) {
        let truth = Sim3 { scale: 2.0, rotation: axis_angle([0.3, -0.5, 0.8], 0.7), translation: [1.0, 2.0, 3.0] };
        let gt: Vec<_> = pts.iter().zip(&noise).map(|(p, n)| {
            let q = truth.apply(*p);
            [q[0] + n[0], q[1] + n[1], q[2] + n[2]]
        }).collect();
        let Ok(a) = align_sim3(&pts, &gt) else { return Ok(()); };
        let cost = |s: &Sim3| pts.iter().zip(&gt).map(|(p, g)| {
            let q = s.apply(*p);
            (q[0]-g[0]).powi(2) + (q[1]-g[1]).powi(2) + (q[2]-g[2]).powi(2)
        }).sum::<f64>();
        let base = cost(&a.transform);
        let mut p = a.transform;
        let h = 1e-4;
        match which {
            0 => p.scale *= 1.0 + h,
            1 => p.scale *= 1.0 - h,
            2..=4 => p.rotation = mul(&axis_angle([(which == 2) as u8 as f64, (which == 3) as u8 as f64, (which == 4) as u8 as f64], h), &p.rotation),
            5 => p.translation[0] += h,
            _ => p.translation[2] -= h,
        }
        prop_assert!(cost(&p) >= base - 1e-9 * base.max(1e-12));
    }
}

#[test]
fn too_few_and_collinear_points_are_refused() {
    let p = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]];
    assert_eq!(align_sim3(&p, &p), Err(AlignFailure::TooFew(2)));
    let line: Vec<_> = (0..10)
        .map(|i| [i as f64, 2.0 * i as f64, -(i as f64)])
        .collect();
    assert_eq!(align_sim3(&line, &line), Err(AlignFailure::Degenerate));
    let same = vec![[1.0, 1.0, 1.0]; 5];
    assert_eq!(align_sim3(&same, &same), Err(AlignFailure::Degenerate));
}

#[test]
fn sim3_inverse_and_compose() {
    let a = Sim3 {
        scale: 1.7,
        rotation: axis_angle([1.0, 2.0, 3.0], 0.4),
        translation: [1.0, -2.0, 0.5],
    };
    let b = Sim3 {
        scale: 0.3,
        rotation: axis_angle([-1.0, 0.0, 1.0], 2.0),
        translation: [0.0, 4.0, 1.0],
    };
    let p = [0.3, -0.7, 2.0];
    let q = a.compose(&b).apply(p);
    let r = a.apply(b.apply(p));
    for i in 0..3 {
        assert!((q[i] - r[i]).abs() < 1e-12);
    }
    let back = a.inverse().apply(a.apply(p));
    for i in 0..3 {
        assert!((back[i] - p[i]).abs() < 1e-12);
    }
}
