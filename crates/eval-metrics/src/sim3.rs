//! Similarity transforms and their least-squares fit to corresponding points (Umeyama).

use nalgebra::{
    Matrix3, Rotation3, Similarity3, SymmetricEigen, Translation3, UnitQuaternion, Vector3,
};
use serde::{Deserialize, Serialize};

/// A similarity transform `p -> scale * rotation * p + translation`.
///
/// Named by what it maps, sophus style: `gt_from_est.apply(&point_in_est)` gives the point in
/// the ground-truth frame; transforms compose right to left. Converts to and from
/// [`nalgebra::Similarity3`] (which applies the scale first, then the rotation and the
/// translation: the same map).
///
/// ```
/// use eval_metrics::Sim3;
/// use nalgebra::{Rotation3, Similarity3, Vector3};
///
/// let s = Sim3 {
///     scale: 2.0,
///     rotation: Rotation3::from_axis_angle(&Vector3::z_axis(), 0.5),
///     translation: Vector3::new(1.0, 2.0, 3.0),
/// };
/// let p = Vector3::new(0.3, -0.4, 0.5);
/// let n: Similarity3<f64> = s.into();
/// assert!((n.transform_point(&p.into()).coords - s.apply(&p)).norm() < 1e-12);
/// assert!((Sim3::from(n).rotation_angle_deg() - 0.5f64.to_degrees()).abs() < 1e-9);
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Sim3 {
    /// Scale factor (positive).
    pub scale: f64,
    /// Rotation.
    pub rotation: Rotation3<f64>,
    /// Translation.
    pub translation: Vector3<f64>,
}

impl Default for Sim3 {
    fn default() -> Self {
        Sim3::identity()
    }
}

impl Sim3 {
    /// The identity.
    pub fn identity() -> Sim3 {
        Sim3 {
            scale: 1.0,
            rotation: Rotation3::identity(),
            translation: Vector3::zeros(),
        }
    }

    /// Applies the transform to a point.
    #[inline]
    pub fn apply(&self, p: &Vector3<f64>) -> Vector3<f64> {
        self.rotation * p * self.scale + self.translation
    }

    /// The inverse transform.
    pub fn inverse(&self) -> Sim3 {
        let rt = self.rotation.inverse();
        let s = 1.0 / self.scale;
        Sim3 {
            scale: s,
            rotation: rt,
            translation: -(rt * self.translation) * s,
        }
    }

    /// `self * other`: apply `other` first, then `self`.
    pub fn compose(&self, other: &Sim3) -> Sim3 {
        Sim3 {
            scale: self.scale * other.scale,
            rotation: self.rotation * other.rotation,
            translation: self.apply(&other.translation),
        }
    }

    /// Rotation angle in degrees (see [`rotation_angle`]).
    pub fn rotation_angle_deg(&self) -> f64 {
        rotation_angle(&self.rotation).to_degrees()
    }
}

impl From<Sim3> for Similarity3<f64> {
    fn from(s: Sim3) -> Self {
        Similarity3::from_parts(
            Translation3::from(s.translation),
            UnitQuaternion::from_rotation_matrix(&s.rotation),
            s.scale,
        )
    }
}

impl From<Similarity3<f64>> for Sim3 {
    fn from(s: Similarity3<f64>) -> Self {
        Sim3 {
            scale: s.scaling(),
            rotation: s.isometry.rotation.to_rotation_matrix(),
            translation: s.isometry.translation.vector,
        }
    }
}

/// Rotation angle of a rotation in radians, accurate for tiny and for near-180-degree
/// angles: `atan2(|axis|, (trace - 1) / 2)` with `axis = vee(R - R^T) / 2`.
///
/// nalgebra's [`Rotation3::angle`] uses `acos((trace - 1) / 2)`, which returns 0 for
/// angles below about 1e-8 rad (1e-6 degrees): the drift metric `e_r` needs the atan2 form.
pub fn rotation_angle(r: &Rotation3<f64>) -> f64 {
    let m = r.matrix();
    let axis = Vector3::new(
        m[(2, 1)] - m[(1, 2)],
        m[(0, 2)] - m[(2, 0)],
        m[(1, 0)] - m[(0, 1)],
    ) * 0.5;
    let cos = (m.trace() - 1.0) * 0.5;
    axis.norm().atan2(cos)
}

/// Why an alignment could not be computed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, thiserror::Error)]
pub enum AlignFailure {
    /// Fewer than three correspondences.
    #[error("{0} correspondence(s), at least 3 are needed")]
    TooFew(usize),
    /// The estimated (or ground-truth) points are (nearly) collinear or identical, so the
    /// rotation about their line is not determined.
    #[error("the points are collinear or identical, the alignment is not determined")]
    Degenerate,
    /// The two point lists have different lengths: they do not correspond.
    #[error("{est} estimated points but {gt} ground-truth points")]
    LengthMismatch {
        /// Number of estimated points.
        est: usize,
        /// Number of ground-truth points.
        gt: usize,
    },
    /// A coordinate is NaN or infinite.
    #[error("a point has a NaN or infinite coordinate")]
    NonFinite,
}

/// The result of [`align_sim3`]: the transform and the RMSE of the aligned points.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Alignment {
    /// `gt_from_est`.
    pub transform: Sim3,
    /// Root-mean-square distance between the aligned estimate and the ground truth.
    pub rmse: f64,
}

/// Relative size below which the second principal extent of a point set counts as zero.
const DEGENERATE_RATIO: f64 = 1e-10;

/// Whether the scatter matrix of a point set spans at least a plane: its second largest
/// eigenvalue is not negligible against the largest.
fn spans_a_plane(scatter: Matrix3<f64>) -> bool {
    // nalgebra's eigen solver does not return on NaN or infinite entries
    if !scatter.iter().all(|v| v.is_finite()) {
        return false;
    }
    let mut ev: Vec<f64> = SymmetricEigen::new(scatter)
        .eigenvalues
        .iter()
        .copied()
        .collect();
    ev.sort_by(|a, b| b.total_cmp(a));
    ev[0].is_finite() && ev[0] > 0.0 && ev[1] > DEGENERATE_RATIO * ev[0]
}

/// Least-squares Sim(3) with `gt ~ s R est + t` (Umeyama): SVD of the centred
/// cross-covariance with the reflection fix, and the scale
/// `s = sum <R e_i, g_i> / sum |e_i|^2` over centred points.
///
/// Refuses lists of different lengths, fewer than three points, non-finite coordinates,
/// and point sets (either one) that do not span a plane.
pub fn align_sim3(est: &[Vector3<f64>], gt: &[Vector3<f64>]) -> Result<Alignment, AlignFailure> {
    let transform = umeyama(est, gt, true)?;
    let sq: f64 = est
        .iter()
        .zip(gt)
        .map(|(e, g)| (transform.apply(e) - g).norm_squared())
        .sum();
    Ok(Alignment {
        transform,
        rmse: (sq * (1.0 / est.len() as f64)).sqrt(),
    })
}

/// The least-squares fit `gt ~ s R est + t` of Umeyama (1991), with the scale `s` estimated
/// when `with_scale` (Sim(3)) and fixed at 1 otherwise (SE(3), Horn's and Kabsch's rotation):
/// `R = U diag(1, 1, d) V^T` from the SVD of the centred cross-covariance, `d` the sign of
/// `det U det V` on the smallest singular value, `s = sum <R e_i, g_i> / sum |e_i|^2` (equal
/// to Umeyama's `trace(D S) / sigma^2`), `t = mean(g) - s R mean(e)`.
///
/// The same checks as [`align_sim3`].
pub fn umeyama(
    est: &[Vector3<f64>],
    gt: &[Vector3<f64>],
    with_scale: bool,
) -> Result<Sim3, AlignFailure> {
    if est.len() != gt.len() {
        return Err(AlignFailure::LengthMismatch {
            est: est.len(),
            gt: gt.len(),
        });
    }
    let n = est.len();
    if n < 3 {
        return Err(AlignFailure::TooFew(n));
    }
    if !est
        .iter()
        .chain(gt)
        .all(|p| p.iter().all(|v| v.is_finite()))
    {
        return Err(AlignFailure::NonFinite);
    }
    let inv_n = 1.0 / n as f64;
    let me: Vector3<f64> = est.iter().sum::<Vector3<f64>>() * inv_n;
    let mg: Vector3<f64> = gt.iter().sum::<Vector3<f64>>() * inv_n;
    let mut h = Matrix3::zeros();
    let mut ce = Matrix3::zeros();
    let mut cg = Matrix3::zeros();
    let mut var_e = 0.0;
    for (e, g) in est.iter().zip(gt) {
        let de = e - me;
        let dg = g - mg;
        var_e += de.norm_squared();
        h += dg * de.transpose();
        ce += de * de.transpose();
        cg += dg * dg.transpose();
    }
    // Degeneracy: the scatter of either point set must span at least a plane.
    if !(h.iter().all(|v| v.is_finite()) && spans_a_plane(ce) && spans_a_plane(cg)) {
        return Err(AlignFailure::Degenerate);
    }
    let Some((u, sv, v)) = jacobi_svd3(&h) else {
        return Err(AlignFailure::Degenerate);
    };
    // R = U diag(1, 1, d) V^T, d = sign(det U det V) on the smallest singular value.
    let mut d = Matrix3::identity();
    if u.determinant() * v.determinant() < 0.0 {
        let smallest = sv.imin();
        d[(smallest, smallest)] = -1.0;
    }
    let r = Rotation3::from_matrix_unchecked(u * d * v.transpose());
    let s = if with_scale {
        let num: f64 = est
            .iter()
            .zip(gt)
            .map(|(e, g)| (r * (e - me)).dot(&(g - mg)))
            .sum();
        num / var_e
    } else {
        1.0
    };
    if !(s.is_finite() && s > 0.0) {
        return Err(AlignFailure::Degenerate);
    }
    Ok(Sim3 {
        scale: s,
        rotation: r,
        translation: mg - r * me * s,
    })
}

/// The singular value decomposition `a = U diag(s) V^T` of a 3x3 matrix by one-sided Jacobi
/// rotations (Demmel and Veselic), which is accurate to the last digits even when the singular
/// values are far apart. nalgebra's SVD is not: for the cross-covariance of KITTI sequence
/// 04 (a straight road; singular values 3.6e6, 8.4 and 0.30) its `U S V^T` misses the matrix by
/// 9.1e-6 (2.6e-12 relative, whatever its `eps`), LAPACK's (numpy's) by 4.6e-10 and this one by
/// 3.7e-10, and the Umeyama rotation it gives differs from evo's by 3e-7. `None` for a
/// non-finite matrix.
pub(crate) fn jacobi_svd3(a: &Matrix3<f64>) -> Option<(Matrix3<f64>, Vector3<f64>, Matrix3<f64>)> {
    if !a.iter().all(|v| v.is_finite()) {
        return None;
    }
    let mut b = *a;
    let mut v = Matrix3::identity();
    for _sweep in 0..60 {
        let mut rotated = false;
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            let alpha = b.column(p).norm_squared();
            let beta = b.column(q).norm_squared();
            let gamma = b.column(p).dot(&b.column(q));
            if gamma == 0.0 || gamma.abs() <= f64::EPSILON * (alpha * beta).sqrt() {
                continue;
            }
            rotated = true;
            let zeta = (beta - alpha) / (2.0 * gamma);
            let t = zeta.signum() / (zeta.abs() + zeta.hypot(1.0));
            let c = 1.0 / t.hypot(1.0);
            let s = c * t;
            for m in [&mut b, &mut v] {
                for k in 0..3 {
                    let (x, y) = (m[(k, p)], m[(k, q)]);
                    m[(k, p)] = c * x - s * y;
                    m[(k, q)] = s * x + c * y;
                }
            }
        }
        if !rotated {
            break;
        }
    }
    let sv = Vector3::new(b.column(0).norm(), b.column(1).norm(), b.column(2).norm());
    let mut u = Matrix3::zeros();
    let mut zero = None;
    for i in 0..3 {
        if sv[i] > 0.0 {
            u.set_column(i, &(b.column(i) / sv[i]));
        } else if zero.replace(i).is_some() {
            // two zero singular values: the rotation is not determined
            return None;
        }
    }
    if let Some(i) = zero {
        // complete the basis: the column orthogonal to the other two
        let (j, k) = ((i + 1) % 3, (i + 2) % 3);
        u.set_column(i, &u.column(j).cross(&u.column(k)));
    }
    Some((u, sv, v))
}

/// The two principal axes of a point set (unit vectors spanning the plane of largest
/// spread, the first along the largest spread), from the eigen decomposition of the
/// scatter matrix about the mean. Projecting on them gives a "top-down" view of a
/// trajectory whatever the ground truth's up axis; their signs are arbitrary. Fewer than
/// three points, or collinear ones, still give two orthonormal axes.
pub fn principal_plane(points: &[Vector3<f64>]) -> (Vector3<f64>, Vector3<f64>) {
    let finite: Vec<&Vector3<f64>> = points
        .iter()
        .filter(|p| p.iter().all(|v| v.is_finite()))
        .collect();
    let n = finite.len().max(1) as f64;
    let mean: Vector3<f64> = finite.iter().copied().sum::<Vector3<f64>>() / n;
    let scatter: Matrix3<f64> = finite
        .iter()
        .map(|p| (*p - mean) * (*p - mean).transpose())
        .sum();
    // nalgebra's eigen solver does not return on NaN or infinite entries
    if !scatter.iter().all(|v| v.is_finite()) {
        return (Vector3::x(), Vector3::y());
    }
    let eig = SymmetricEigen::new(scatter);
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
    (
        eig.eigenvectors.column(order[0]).into_owned(),
        eig.eigenvectors.column(order[1]).into_owned(),
    )
}
