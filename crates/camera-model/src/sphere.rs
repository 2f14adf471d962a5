//! The spherical wide-angle models with closed-form inverses: Double Sphere and the Extended
//! Unified Camera Model (Usenko, Demmel, Cremers, "The Double Sphere Camera Model", 3DV 2018,
//! equations 40-47 and 27-31, as Basalt defines them), and the unified model of Mei and Rives
//! (Kalibr's `omni`, optionally with radial-tangential distortion of its image-plane
//! coordinates; Basalt's `ucm` is the same model with `alpha = xi / (1 + xi)`).
//!
//! Each function works on normalised image coordinates `m = ((u - cx) / fx, (v - cy) / fy)`:
//! `*_project` maps a point in the camera frame to `m` (or `None` outside the model's valid
//! half-space), `*_unproject` maps `m` to a unit-length ray (or `None` outside the image
//! circle of rays the model can represent).

/// The bound `w` of the valid region `z > -w |p|` of the unified projection with parameter
/// `alpha` (the paper's equation 43, shared by UCM and EUCM): beyond it the projection folds.
#[inline]
fn unified_w(alpha: f64) -> f64 {
    if alpha <= 0.5 {
        alpha / (1.0 - alpha)
    } else {
        (1.0 - alpha) / alpha
    }
}

#[inline]
fn normalize(r: [f64; 3]) -> Option<[f64; 3]> {
    let n = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
    (n.is_finite() && n > 0.0).then(|| [r[0] / n, r[1] / n, r[2] / n])
}

/// Double Sphere projection (paper eq. 40-43): `d1 = |p|`, `d2 = |(x, y, xi d1 + z)|`,
/// `m = (x, y) / (alpha d2 + (1 - alpha)(xi d1 + z))`, valid where `z > -w2 d1`.
#[inline]
#[allow(clippy::neg_cmp_op_on_partial_ord)] // NaN must fail the test
pub(crate) fn ds_project(xi: f64, alpha: f64, p: [f64; 3]) -> Option<[f64; 2]> {
    let [x, y, z] = p;
    let r2 = x * x + y * y;
    let d1 = (r2 + z * z).sqrt();
    let k = xi * d1 + z;
    let d2 = (r2 + k * k).sqrt();
    let w1 = unified_w(alpha);
    let w2 = (w1 + xi) / (2.0 * w1 * xi + xi * xi + 1.0).sqrt();
    let denom = alpha * d2 + (1.0 - alpha) * k;
    if !(z > -w2 * d1 && denom > 0.0) {
        return None;
    }
    Some([x / denom, y / denom])
}

/// Double Sphere unprojection in closed form (paper eq. 44-47); `None` outside the image
/// circle `r^2 <= 1 / (2 alpha - 1)` when `alpha > 0.5`.
#[inline]
pub(crate) fn ds_unproject(xi: f64, alpha: f64, m: [f64; 2]) -> Option<[f64; 3]> {
    let r2 = m[0] * m[0] + m[1] * m[1];
    let s = 1.0 - (2.0 * alpha - 1.0) * r2;
    if s < 0.0 {
        return None;
    }
    let mz = (1.0 - alpha * alpha * r2) / (alpha * s.sqrt() + 1.0 - alpha);
    let disc = mz * mz + (1.0 - xi * xi) * r2;
    if disc < 0.0 {
        return None;
    }
    let f = (mz * xi + disc.sqrt()) / (mz * mz + r2);
    normalize([f * m[0], f * m[1], f * mz - xi])
}

/// EUCM projection (paper eq. 27-28): `rho = sqrt(beta (x^2 + y^2) + z^2)`,
/// `m = (x, y) / (alpha rho + (1 - alpha) z)`, valid where `z > -w rho`.
#[inline]
#[allow(clippy::neg_cmp_op_on_partial_ord)] // NaN must fail the test
pub(crate) fn eucm_project(alpha: f64, beta: f64, p: [f64; 3]) -> Option<[f64; 2]> {
    let [x, y, z] = p;
    let rho = (beta * (x * x + y * y) + z * z).sqrt();
    let denom = alpha * rho + (1.0 - alpha) * z;
    if !(z > -unified_w(alpha) * rho && denom > 0.0) {
        return None;
    }
    Some([x / denom, y / denom])
}

/// EUCM unprojection in closed form (paper eq. 29-31); `None` outside
/// `r^2 <= 1 / (beta (2 alpha - 1))` when `alpha > 0.5`.
#[inline]
pub(crate) fn eucm_unproject(alpha: f64, beta: f64, m: [f64; 2]) -> Option<[f64; 3]> {
    let r2 = m[0] * m[0] + m[1] * m[1];
    let s = 1.0 - (2.0 * alpha - 1.0) * beta * r2;
    if s < 0.0 {
        return None;
    }
    let mz = (1.0 - beta * alpha * alpha * r2) / (alpha * s.sqrt() + 1.0 - alpha);
    normalize([m[0], m[1], mz])
}

/// Mei's unified projection (Kalibr's `omni` before distortion): `m = (x, y) / (z + xi |p|)`,
/// valid where `z > -min(xi, 1/xi) |p|` (the fold of the projection for `xi > 1`).
#[inline]
#[allow(clippy::neg_cmp_op_on_partial_ord)] // NaN must fail the test
pub(crate) fn unified_project(xi: f64, p: [f64; 3]) -> Option<[f64; 2]> {
    let [x, y, z] = p;
    let d = (x * x + y * y + z * z).sqrt();
    let w = if xi <= 1.0 { xi } else { 1.0 / xi };
    let denom = z + xi * d;
    if !(z > -w * d && denom > 0.0) {
        return None;
    }
    Some([x / denom, y / denom])
}

/// Mei's unified unprojection in closed form: with `r^2 = |m|^2`, the ray is
/// `(f m, f - xi)` for `f = (xi + sqrt(1 + (1 - xi^2) r^2)) / (1 + r^2)`.
#[inline]
pub(crate) fn unified_unproject(xi: f64, m: [f64; 2]) -> Option<[f64; 3]> {
    let r2 = m[0] * m[0] + m[1] * m[1];
    let disc = 1.0 + (1.0 - xi * xi) * r2;
    if disc < 0.0 {
        return None;
    }
    let f = (xi + disc.sqrt()) / (1.0 + r2);
    let ray = [f * m[0], f * m[1], f - xi];
    // for xi > 1 the '+' root still needs the ray on the unfolded side
    let w = if xi <= 1.0 { xi } else { 1.0 / xi };
    let n = normalize(ray)?;
    (n[2] > -w - 1e-12).then_some(n)
}

/// Checks the parameters of the models: `None` when valid, else what is wrong.
pub(crate) fn check_ds(xi: f64, alpha: f64) -> Option<String> {
    if !(xi.is_finite() && alpha.is_finite()) {
        return Some(format!(
            "Double Sphere parameters must be finite, got xi={xi} alpha={alpha}"
        ));
    }
    if !(0.0..=1.0).contains(&alpha) || !(-1.0..=1.0).contains(&xi) {
        return Some(format!(
            "Double Sphere needs alpha in [0, 1] and xi in [-1, 1], got xi={xi} alpha={alpha}"
        ));
    }
    None
}

/// See [`check_ds`].
pub(crate) fn check_eucm(alpha: f64, beta: f64) -> Option<String> {
    if !(beta.is_finite() && (0.0..=1.0).contains(&alpha) && beta > 0.0) {
        return Some(format!(
            "EUCM needs alpha in [0, 1] and beta > 0, got alpha={alpha} beta={beta}"
        ));
    }
    None
}

/// See [`check_ds`].
pub(crate) fn check_unified(xi: f64) -> Option<String> {
    if !xi.is_finite() || xi < 0.0 {
        return Some(format!(
            "the unified (omni) model needs xi >= 0, got xi={xi}"
        ));
    }
    None
}
