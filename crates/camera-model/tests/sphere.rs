//! The Double Sphere, EUCM and unified models: their special cases agree with each other, they
//! see beyond 90 degrees, and they refuse rays outside their valid region.
use camera_model::{CameraModel, Intrinsics};
use proptest::prelude::*;

const K: Intrinsics = Intrinsics {
    fx: 300.0,
    fy: 290.0,
    cx: 320.0,
    cy: 240.0,
};

fn scaled(s: f64) -> Intrinsics {
    Intrinsics {
        fx: K.fx * s,
        fy: K.fy * s,
        ..K
    }
}

proptest! {
    /// Double Sphere with xi = 0 is UCM, and UCM with alpha is Mei's unified model with
    /// xi = alpha / (1 - alpha) and focal lengths f / (1 - alpha); EUCM with beta = 1 is UCM.
    #[test]
    fn special_cases_agree(
        alpha in 0.05f64..0.95,
        theta in 0.0f64..1.5,
        phi in 0.0f64..std::f64::consts::TAU,
    ) {
        let ds = CameraModel::DoubleSphere { k: K, xi: 0.0, alpha };
        let eucm = CameraModel::Eucm { k: K, alpha, beta: 1.0 };
        let mei = CameraModel::Unified {
            k: scaled(1.0 / (1.0 - alpha)),
            xi: alpha / (1.0 - alpha),
            coeffs: [0.0; 4],
        };
        let p = [theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos()];
        let a = ds.project(p).unwrap();
        for other in [&eucm, &mei] {
            let b = other.project(p).unwrap();
            prop_assert!((a[0] - b[0]).abs() < 1e-9 && (a[1] - b[1]).abs() < 1e-9, "{} {:?} {:?}", other.name(), a, b);
        }
    }

    /// Each model's closed-form unprojection inverts its projection over the whole valid
    /// hemisphere and beyond (up to 110 degrees from the axis for these parameters).
    #[test]
    fn closed_form_inverses_round_trip(
        which in 0usize..3,
        theta in 0.0f64..1.9,
        phi in 0.0f64..std::f64::consts::TAU,
    ) {
        let model = [
            CameraModel::DoubleSphere { k: K, xi: -0.2, alpha: 0.6 },
            CameraModel::Eucm { k: K, alpha: 0.6, beta: 1.1 },
            CameraModel::Unified { k: K, xi: 1.3, coeffs: [0.0; 4] },
        ][which].clone();
        let p = [theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos()];
        if let Some(px) = model.project(p) {
            let r = model.unproject(px).unwrap();
            let dot = r[0] * p[0] + r[1] * p[1] + r[2] * p[2];
            prop_assert!(dot > 1.0 - 1e-11, "{} theta {} dot {}", model.name(), theta, dot);
        }
    }
}

/// The paper's Double Sphere equations written out for one point (Usenko et al. 2018,
/// eq. 40-41).
#[test]
fn double_sphere_matches_the_paper_equations() {
    let (xi, alpha) = (-0.17213086034353243, 0.5931177593944744);
    let m = CameraModel::DoubleSphere { k: K, xi, alpha };
    let (x, y, z): (f64, f64, f64) = (0.4, -0.3, 0.8);
    let d1 = (x * x + y * y + z * z).sqrt();
    let d2 = (x * x + y * y + (xi * d1 + z).powi(2)).sqrt();
    let den = alpha * d2 + (1.0 - alpha) * (xi * d1 + z);
    let want = [K.fx * x / den + K.cx, K.fy * y / den + K.cy];
    let got = m.project([x, y, z]).unwrap();
    assert!((got[0] - want[0]).abs() < 1e-9 && (got[1] - want[1]).abs() < 1e-9);
    // a point 100 degrees from the axis projects (the TUM-VI lens sees 195 degrees)
    let t = 100f64.to_radians();
    let side = m.project([t.sin(), 0.0, t.cos()]).unwrap();
    assert!(m.unproject(side).unwrap()[2] < 0.0);
    // straight behind: no image
    assert!(m.project([0.0, 0.0, -1.0]).is_none());
}

/// Outside the image circle of rays (`r^2 > 1 / (2 alpha - 1)`) there is no unprojection.
#[test]
fn outside_the_ray_circle_nothing_unprojects() {
    let ds = CameraModel::DoubleSphere {
        k: K,
        xi: 0.0,
        alpha: 0.8,
    };
    // r = 1.3 > 1 / sqrt(0.6) = 1.29
    assert!(ds.unproject([K.cx + 1.3 * K.fx, K.cy]).is_none());
    assert!(ds.unproject([K.cx + 1.2 * K.fx, K.cy]).is_some());
    let eucm = CameraModel::Eucm {
        k: K,
        alpha: 0.8,
        beta: 2.0,
    };
    // r^2 <= 1 / (beta (2 alpha - 1)) = 0.833
    assert!(eucm.unproject([K.cx + 0.95 * K.fx, K.cy]).is_none());
    assert!(eucm.unproject([K.cx + 0.9 * K.fx, K.cy]).is_some());
}

/// camera.txt carries the new models under monovo's own prefixes, with a warning that DSO
/// cannot read them, and round-trips through `to_text`.
#[test]
fn camera_txt_reads_and_writes_the_new_models() {
    let text =
        "DoubleSphere 158.286 158.274 254.961 256.889 -0.172 0.593\n512 512\ncrop\n512 512\n";
    let f = camera_model::CameraFile::parse(text).unwrap();
    assert_eq!(f.input.name(), "DoubleSphere");
    assert!(f.warnings.iter().any(|w| w.contains("DSO cannot read")));
    let again = camera_model::CameraFile::parse(&f.to_text()).unwrap();
    let (a, b) = (
        f.input.project([0.3, 0.2, 1.0]).unwrap(),
        again.input.project([0.3, 0.2, 1.0]).unwrap(),
    );
    assert!((a[0] - b[0]).abs() < 1e-9 && (a[1] - b[1]).abs() < 1e-9);
    let bad = "EUCM 400 400 320 240 1.5 1.0\n640 480\n";
    let e = camera_model::CameraFile::parse(bad)
        .unwrap_err()
        .to_string();
    assert!(e.contains("line 1") && e.contains("alpha"), "{e}");
}
