//! Similarity transforms and their least-squares fit to corresponding points (Umeyama).

use crate::linalg::{self, Mat3, Vec3};

/// A similarity transform `p -> scale * rotation * p + translation`.
///
/// Named by what it maps, sophus style: `gt_from_est.apply(point_in_est)` gives the point in
/// the ground-truth frame; transforms compose right to left.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sim3 {
    /// Scale factor (positive).
    pub scale: f64,
    /// Rotation matrix (row-major).
    pub rotation: Mat3,
    /// Translation.
    pub translation: Vec3,
}

impl Sim3 {
    /// The identity.
    pub const IDENTITY: Sim3 = Sim3 {
        scale: 1.0,
        rotation: linalg::IDENTITY,
        translation: [0.0; 3],
    };

    /// Applies the transform to a point.
    #[inline]
    pub fn apply(&self, p: Vec3) -> Vec3 {
        linalg::add(
            linalg::scale(linalg::mul_vec(&self.rotation, p), self.scale),
            self.translation,
        )
    }

    /// The inverse transform.
    pub fn inverse(&self) -> Sim3 {
        let rt = linalg::transpose(&self.rotation);
        let s = 1.0 / self.scale;
        Sim3 {
            scale: s,
            rotation: rt,
            translation: linalg::scale(linalg::mul_vec(&rt, self.translation), -s),
        }
    }

    /// `self * other`: apply `other` first, then `self`.
    pub fn compose(&self, other: &Sim3) -> Sim3 {
        Sim3 {
            scale: self.scale * other.scale,
            rotation: linalg::mul(&self.rotation, &other.rotation),
            translation: self.apply(other.translation),
        }
    }

    /// Rotation angle in degrees.
    pub fn rotation_angle_deg(&self) -> f64 {
        linalg::rotation_angle(&self.rotation).to_degrees()
    }
}

/// Why an alignment could not be computed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AlignFailure {
    /// Fewer than three correspondences.
    TooFew(usize),
    /// The estimated (or ground-truth) points are (nearly) collinear or identical, so the
    /// rotation about their line is not determined.
    Degenerate,
}

/// The result of [`align_sim3`]: the transform and the RMSE of the aligned points.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Alignment {
    /// `gt_from_est`.
    pub transform: Sim3,
    /// Root-mean-square distance between the aligned estimate and the ground truth.
    pub rmse: f64,
}

/// Relative size below which the second principal extent of a point set counts as zero.
const DEGENERATE_RATIO: f64 = 1e-10;

/// Least-squares Sim(3) with `gt ~ s R est + t` (Umeyama): SVD of the centred
/// cross-covariance with the reflection fix, and the scale
/// `s = sum <R e_i, g_i> / sum |e_i|^2` over centred points.
pub fn align_sim3(est: &[Vec3], gt: &[Vec3]) -> Result<Alignment, AlignFailure> {
    let n = est.len().min(gt.len());
    if n < 3 {
        return Err(AlignFailure::TooFew(n));
    }
    let inv_n = 1.0 / n as f64;
    let mut me = [0.0; 3];
    let mut mg = [0.0; 3];
    for (e, g) in est.iter().zip(gt) {
        me = linalg::add(me, *e);
        mg = linalg::add(mg, *g);
    }
    me = linalg::scale(me, inv_n);
    mg = linalg::scale(mg, inv_n);
    let mut h = [[0.0; 3]; 3];
    let mut ce = [[0.0; 3]; 3];
    let mut cg = [[0.0; 3]; 3];
    let mut var_e = 0.0;
    for (e, g) in est.iter().zip(gt) {
        let de = linalg::sub(*e, me);
        let dg = linalg::sub(*g, mg);
        var_e += linalg::dot(de, de);
        for i in 0..3 {
            for j in 0..3 {
                h[i][j] += dg[i] * de[j];
                ce[i][j] += de[i] * de[j];
                cg[i][j] += dg[i] * dg[j];
            }
        }
    }
    // Degeneracy: the scatter of either point set must span at least a plane.
    for c in [&ce, &cg] {
        let (_, s, _) = linalg::svd3(c);
        if s[0].is_nan() || s[0] <= 0.0 || s[1] <= DEGENERATE_RATIO * s[0] {
            return Err(AlignFailure::Degenerate);
        }
    }
    let (u, _s, v) = linalg::svd3(&h);
    let d = linalg::det(&u) * linalg::det(&v);
    let fix = if d < 0.0 { -1.0 } else { 1.0 };
    // R = U diag(1, 1, fix) V^T
    let mut r = [[0.0; 3]; 3];
    for (i, row) in r.iter_mut().enumerate() {
        for (j, x) in row.iter_mut().enumerate() {
            *x = u[i][0] * v[j][0] + u[i][1] * v[j][1] + fix * u[i][2] * v[j][2];
        }
    }
    let mut num = 0.0;
    for (e, g) in est.iter().zip(gt) {
        let de = linalg::sub(*e, me);
        let dg = linalg::sub(*g, mg);
        num += linalg::dot(linalg::mul_vec(&r, de), dg);
    }
    let s = num / var_e;
    if !(s.is_finite() && s > 0.0) {
        return Err(AlignFailure::Degenerate);
    }
    let t = linalg::sub(mg, linalg::scale(linalg::mul_vec(&r, me), s));
    let transform = Sim3 {
        scale: s,
        rotation: r,
        translation: t,
    };
    let mut sq = 0.0;
    for (e, g) in est.iter().zip(gt) {
        let d = linalg::sub(transform.apply(*e), *g);
        sq += linalg::dot(d, d);
    }
    Ok(Alignment {
        transform,
        rmse: (sq * inv_n).sqrt(),
    })
}
