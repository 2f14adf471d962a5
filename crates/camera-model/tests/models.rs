//! Projection / unprojection properties of every model.
use crate::common::{all_models, pixel_grid, MODELS};
use camera_model::{CameraModel, Intrinsics};
use proptest::prelude::*;

/// Round trip pixel -> ray -> pixel over a grid including the borders. Tolerance 1e-6 px:
/// the inverses are closed form (FOV, pinhole) or Newton iterations run to 1e-14.
#[test]
fn unproject_then_project_returns_the_pixel_for_every_model() {
    for (model, size) in all_models() {
        for p in pixel_grid(size, 7) {
            let ray = model
                .unproject(p)
                .unwrap_or_else(|| panic!("{} cannot unproject {p:?}", model.name()));
            let norm = (ray[0] * ray[0] + ray[1] * ray[1] + ray[2] * ray[2]).sqrt();
            assert!((norm - 1.0).abs() < 1e-12);
            let back = model.project(ray).unwrap();
            let err = (back[0] - p[0]).hypot(back[1] - p[1]);
            assert!(err < 1e-6, "{}: {p:?} -> {back:?} ({err} px)", model.name());
            // scaling the point along its ray does not move the pixel
            let far = model
                .project([ray[0] * 37.0, ray[1] * 37.0, ray[2] * 37.0])
                .unwrap();
            assert!((far[0] - back[0]).abs() < 1e-9 && (far[1] - back[1]).abs() < 1e-9);
        }
    }
}

/// The FOV model matches the paper's equation 1 written out directly.
#[test]
fn fov_projection_matches_the_paper_equation() {
    let k = Intrinsics {
        fx: 685.7,
        fy: 685.6,
        cx: 630.9,
        cy: 511.9,
    };
    let omega: f64 = 0.897966326944875;
    let m = CameraModel::Fov { k, omega };
    for &(x, y, z) in &[
        (0.3, -0.2, 1.0),
        (1.0, 0.7, 0.9),
        (-2.0, 0.1, 1.5),
        (1e-9, 0.0, 1.0),
    ] {
        let (xn, yn): (f64, f64) = (x / z, y / z);
        let ru = (xn * xn + yn * yn).sqrt();
        let f = (2.0 * ru * (omega / 2.0).tan()).atan() / (ru * omega);
        let want = [k.fx * f * xn + k.cx, k.fy * f * yn + k.cy];
        let got = m.project([x, y, z]).unwrap();
        assert!((got[0] - want[0]).abs() < 1e-6 && (got[1] - want[1]).abs() < 1e-6);
    }
    assert!(m.project([0.0, 0.0, -1.0]).is_none());
    assert!(m.project([1.0, 0.0, 0.0]).is_none());
}

#[test]
fn fisheye_models_see_beyond_ninety_degrees() {
    let m = CameraModel::EquiDistant {
        k: Intrinsics {
            fx: 200.0,
            fy: 200.0,
            cx: 400.0,
            cy: 400.0,
        },
        coeffs: [0.0; 4],
    };
    let p = m.project([1.0, 0.0, -0.2]).unwrap();
    let ray = m.unproject(p).unwrap();
    assert!(ray[2] < 0.0);
    assert!((ray[0] / ray[2] - (1.0 / -0.2)).abs() < 1e-9);
}

#[test]
fn unproject_rejects_non_finite_pixels() {
    for (model, _) in all_models() {
        assert!(model.unproject([f64::NAN, 1.0]).is_none());
        assert!(model.unproject([f64::INFINITY, 1.0]).is_none());
        assert!(model.project([f64::NAN, 0.0, 1.0]).is_none());
    }
}

proptest! {
    /// Any point in front of the camera within 60 degrees of the axis projects and unprojects
    /// back onto its own ray (angle below 1e-9 rad).
    #[test]
    fn project_then_unproject_keeps_the_ray(
        which in 0usize..MODELS,
        theta in 0.0f64..1.0,
        phi in 0.0f64..std::f64::consts::TAU,
        depth in 0.1f64..100.0,
    ) {
        let (model, _) = all_models().swap_remove(which);
        let p = [depth * theta.sin() * phi.cos(), depth * theta.sin() * phi.sin(), depth * theta.cos()];
        let px = model.project(p);
        prop_assert!(px.is_some(), "{} does not project {:?}", model.name(), p);
        let ray = model.unproject(px.unwrap());
        prop_assert!(ray.is_some(), "{} does not unproject {:?}", model.name(), px);
        let ray = ray.unwrap();
        let dot = (ray[0] * p[0] + ray[1] * p[1] + ray[2] * p[2]) / depth;
        prop_assert!(dot > 1.0 - 1e-12, "{} {:?} dot {}", model.name(), p, dot);
    }

    /// Pixels anywhere in the image survive the round trip (1e-6 px).
    #[test]
    fn random_pixels_round_trip(which in 0usize..MODELS, fx in 0.0f64..1.0, fy in 0.0f64..1.0) {
        let (model, size) = all_models().swap_remove(which);
        let p = [fx * (size.width - 1) as f64, fy * (size.height - 1) as f64];
        let back = model.project(model.unproject(p).unwrap()).unwrap();
        prop_assert!((back[0] - p[0]).hypot(back[1] - p[1]) < 1e-6);
    }
}
