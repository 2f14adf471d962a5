//! Full poses (rotation matrix and position) with optional timestamps, as the field's
//! trajectory metrics read them: TUM and EuRoC files give stamped quaternions, KITTI pose
//! files give 3x4 matrices without stamps.
//!
//! Rotations are kept as matrices because that is what the references compute with: a
//! quaternion becomes a matrix by the formula of evo and of the TUM scripts (normalising it on
//! the way), a KITTI matrix is used as written (not re-orthonormalised).

use nalgebra::{Matrix3, Quaternion, Rotation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use crate::trajectory::{data_lines, excerpt, parse_fields, Trajectory};
use crate::EvalError;

/// `4 * f64::EPSILON`, the threshold of the quaternion formulas of evo and the TUM scripts.
pub(crate) const EPS4: f64 = 4.0 * f64::EPSILON;

/// The rotation matrix of a quaternion `(w, x, y, z)` of any norm, computed as evo's
/// `quaternion_matrix` and the TUM scripts' `transform44` do: scaled by `sqrt(2 / |q|^2)`, then
/// the outer-product formula. A quaternion of squared norm below `4 eps` gives the identity.
pub fn quaternion_matrix(q: &Quaternion<f64>) -> Matrix3<f64> {
    let (w, x, y, z) = (q.w, q.i, q.j, q.k);
    let n = w * w + x * x + y * y + z * z;
    if n < EPS4 {
        return Matrix3::identity();
    }
    let s = (2.0 / n).sqrt();
    let (w, x, y, z) = (w * s, x * s, y * s, z * s);
    Matrix3::new(
        1.0 - y * y - z * z,
        x * y - z * w,
        x * z + y * w,
        x * y + z * w,
        1.0 - x * x - z * z,
        y * z - x * w,
        x * z - y * w,
        y * z + x * w,
        1.0 - x * x - y * y,
    )
}

/// A rigid transform as a rotation matrix (not necessarily exactly orthonormal: a KITTI
/// file's matrix is kept as written) and a translation. Composes right to left:
/// `a.compose(&b)` applies `b` first.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Se3 {
    /// Rotation.
    pub rotation: Matrix3<f64>,
    /// Translation.
    pub translation: Vector3<f64>,
}

impl Se3 {
    /// The identity.
    pub fn identity() -> Se3 {
        Se3 {
            rotation: Matrix3::identity(),
            translation: Vector3::zeros(),
        }
    }

    /// The inverse of a rigid transform: `(R^T, -R^T t)` (evo's `se3_inverse`).
    pub fn inverse(&self) -> Se3 {
        let rt = self.rotation.transpose();
        Se3 {
            rotation: rt,
            translation: -(rt * self.translation),
        }
    }

    /// `self * other`.
    pub fn compose(&self, other: &Se3) -> Se3 {
        Se3 {
            rotation: self.rotation * other.rotation,
            translation: self.rotation * other.translation + self.translation,
        }
    }

    /// `self^-1 * other`: the motion from `self` to `other` (evo's `relative_se3`).
    pub fn relative(&self, other: &Se3) -> Se3 {
        self.inverse().compose(other)
    }

    /// Frobenius norm of `[R t; 0 1] - I` (evo's `full` pose relation).
    pub fn distance_from_identity(&self) -> f64 {
        let d = self.rotation - Matrix3::identity();
        (d.norm_squared() + self.translation.norm_squared()).sqrt()
    }
}

/// Poses of one trajectory in file order, with the timestamps when the format has them.
///
/// `quaternions` are the orientations as read (TUM, EuRoC) or of the matrix (KITTI); evo
/// interpolates between them. `rotations` are the matrices every metric computes with.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PoseTrack {
    /// Timestamps in seconds; `None` for KITTI pose files (paired by line).
    pub times: Option<Vec<f64>>,
    /// Positions (camera centres, camera-to-world).
    pub positions: Vec<Vector3<f64>>,
    /// Rotations (camera-to-world).
    pub rotations: Vec<Matrix3<f64>>,
    /// Orientations as quaternions, as read.
    pub quaternions: Vec<Quaternion<f64>>,
}

impl PoseTrack {
    /// Number of poses.
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    /// Whether the track has no pose.
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// Whether the track has timestamps.
    pub fn is_stamped(&self) -> bool {
        self.times.is_some()
    }

    /// Pose `i` as a rigid transform.
    #[inline]
    pub fn pose(&self, i: usize) -> Se3 {
        Se3 {
            rotation: self.rotations[i],
            translation: self.positions[i],
        }
    }

    /// A stamped track from a parsed trajectory (TUM or EuRoC): the quaternions as read,
    /// their matrices by [`quaternion_matrix`].
    pub fn from_trajectory(t: &Trajectory) -> PoseTrack {
        let n = t.poses.len();
        let mut out = PoseTrack {
            times: Some(Vec::with_capacity(n)),
            positions: Vec::with_capacity(n),
            rotations: Vec::with_capacity(n),
            quaternions: Vec::with_capacity(n),
        };
        for p in &t.poses {
            if let Some(times) = out.times.as_mut() {
                times.push(p.t);
            }
            out.positions.push(p.position);
            out.rotations.push(quaternion_matrix(&p.orientation));
            out.quaternions.push(p.orientation);
        }
        out
    }

    /// Keeps the poses at `ids`, in that order (an index may repeat).
    pub fn select(&self, ids: &[usize]) -> PoseTrack {
        PoseTrack {
            times: self
                .times
                .as_ref()
                .map(|t| ids.iter().map(|&i| t[i]).collect()),
            positions: ids.iter().map(|&i| self.positions[i]).collect(),
            rotations: ids.iter().map(|&i| self.rotations[i]).collect(),
            quaternions: ids.iter().map(|&i| self.quaternions[i]).collect(),
        }
    }

    /// The index of the first pose that is not finite (NaN or infinite number, or a
    /// timestamp that is not finite).
    pub fn first_non_finite(&self) -> Option<usize> {
        (0..self.len()).find(|&i| {
            !(self.positions[i].iter().all(|v| v.is_finite())
                && self.rotations[i].iter().all(|v| v.is_finite())
                && self.times.as_ref().is_none_or(|t| t[i].is_finite()))
        })
    }

    /// Distance travelled from the first pose to each pose (evo's `distances`).
    pub fn distances(&self) -> Vec<f64> {
        let mut out = Vec::with_capacity(self.len());
        let mut sum = 0.0;
        out.push(0.0);
        for w in self.positions.windows(2) {
            sum += (w[0] - w[1]).norm();
            out.push(sum);
        }
        out.truncate(self.len());
        out
    }

    /// Path length: the sum of the distances between consecutive positions.
    pub fn path_length(&self) -> f64 {
        self.positions
            .windows(2)
            .map(|w| (w[0] - w[1]).norm())
            .sum()
    }
}

/// Parses a KITTI pose file: 12 numbers a line, the 3x4 matrix `[R | t]` row by row
/// (camera-to-world), kept as written. `#` comments and blank lines are skipped.
pub fn parse_kitti_poses(text: &str) -> Result<PoseTrack, EvalError> {
    let mut out = PoseTrack::default();
    for (no, line) in data_lines(text) {
        let v = parse_fields::<12>(
            no,
            line,
            "12 numbers `r11 r12 r13 tx r21 r22 r23 ty r31 r32 r33 tz`",
            false,
        )?;
        out.push_kitti_row(&v)
            .map_err(|what| EvalError::NotARotation {
                line: no,
                what,
                found: excerpt(line),
            })?;
    }
    Ok(out)
}

impl PoseTrack {
    /// Appends a KITTI pose row `r11 r12 r13 tx r21 r22 r23 ty r31 r32 r33 tz` (unstamped),
    /// the matrix as written. `Err` says what is wrong: a singular rotation matrix.
    pub fn push_kitti_row(&mut self, v: &[f64; 12]) -> Result<(), &'static str> {
        let r = Matrix3::new(v[0], v[1], v[2], v[4], v[5], v[6], v[8], v[9], v[10]);
        let det = r.determinant();
        if det.is_finite() && det.abs() < 1e-6 {
            return Err("the rotation matrix is singular");
        }
        let q = if r.iter().all(|x| x.is_finite()) {
            UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r)).into_inner()
        } else {
            Quaternion::new(f64::NAN, f64::NAN, f64::NAN, f64::NAN)
        };
        self.positions.push(Vector3::new(v[3], v[7], v[11]));
        self.rotations.push(r);
        self.quaternions.push(q);
        Ok(())
    }
}

/// The quaternion `(x, y, z, w)` of a rotation matrix as scipy's `Rotation.from_matrix`
/// computes it: a matrix that is not orthogonal within `1e-12` (its Gram matrix against the
/// identity) is first replaced by its nearest orthogonal matrix `U V^T`, then Markley's method
/// picks the best-conditioned of four formulas, and the result is normalised.
pub fn scipy_quaternion(m: &Matrix3<f64>) -> [f64; 4] {
    if !m.iter().all(|v| v.is_finite()) {
        return [f64::NAN; 4];
    }
    let g = m * m.transpose();
    let orthogonal = (0..3).all(|i| {
        (0..3).all(|j| {
            let e = if i == j { 1.0 } else { 0.0 };
            // numpy's isclose: |a - b| <= atol + rtol |b|, rtol = 1e-5
            (g[(i, j)] - e).abs() <= 1e-12 + 1e-5 * e
        })
    });
    let m = if orthogonal {
        *m
    } else {
        // the polar factor U V^T (scipy: LAPACK's SVD; ours by Jacobi rotations, as accurate)
        match crate::sim3::jacobi_svd3(m) {
            Some((u, _, v)) => u * v.transpose(),
            None => *m,
        }
    };
    let tr = m[(0, 0)] + m[(1, 1)] + m[(2, 2)];
    let decision = [m[(0, 0)], m[(1, 1)], m[(2, 2)], tr];
    // numpy's argmax: the first of equal maxima
    let mut choice = 0;
    for (k, &d) in decision.iter().enumerate().skip(1) {
        if d > decision[choice] {
            choice = k;
        }
    }
    let mut q = [0.0; 4];
    if choice == 3 {
        q[0] = m[(2, 1)] - m[(1, 2)];
        q[1] = m[(0, 2)] - m[(2, 0)];
        q[2] = m[(1, 0)] - m[(0, 1)];
        q[3] = 1.0 + tr;
    } else {
        let i = choice;
        let j = (i + 1) % 3;
        let k = (j + 1) % 3;
        q[i] = 1.0 - tr + 2.0 * m[(i, i)];
        q[j] = m[(j, i)] + m[(i, j)];
        q[k] = m[(k, i)] + m[(i, k)];
        q[3] = m[(k, j)] - m[(j, k)];
    }
    let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    q.map(|v| v / n)
}

/// The angle of a quaternion `(x, y, z, w)` as scipy's `as_rotvec` and evo's `so3_log_angle`
/// compute it: the quaternion made canonical (`w >= 0`), `angle = 2 atan2(|v|, w)`, the
/// rotation vector `v * angle / sin(angle / 2)` (a series below 1e-3 rad) and its norm.
pub fn rotvec_angle(q: [f64; 4]) -> f64 {
    let q = if q[3] < 0.0 || (q[3] == 0.0 && first_nonzero_negative(&q)) {
        q.map(|v| -v)
    } else {
        q
    };
    let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2]).sqrt();
    let angle = 2.0 * n.atan2(q[3]);
    let scale = if angle <= 1e-3 {
        let a2 = angle * angle;
        2.0 + a2 / 12.0 + 7.0 * a2 * a2 / 2880.0
    } else {
        angle / (angle / 2.0).sin()
    };
    let r = [scale * q[0], scale * q[1], scale * q[2]];
    (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt()
}

/// scipy's canonical form for `w == 0`: the first non-zero of x, y, z positive.
fn first_nonzero_negative(q: &[f64; 4]) -> bool {
    q[..3].iter().find(|v| **v != 0.0).is_some_and(|v| *v < 0.0)
}

/// The rotation angle of a matrix in radians, as evo computes it (`so3_log_angle`: scipy's
/// `from_matrix` then `as_rotvec`).
pub fn evo_rotation_angle(m: &Matrix3<f64>) -> f64 {
    rotvec_angle(scipy_quaternion(m))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quaternion_matrix_is_the_rotation() {
        let q = UnitQuaternion::from_euler_angles(0.3, -0.2, 1.1);
        let m = quaternion_matrix(&(q.into_inner() * 2.5));
        assert!((m - q.to_rotation_matrix().into_inner()).norm() < 1e-15);
        assert_eq!(
            quaternion_matrix(&Quaternion::new(0.0, 0.0, 0.0, 0.0)),
            Matrix3::identity()
        );
    }

    #[test]
    fn rotation_angles_match_the_axis_angle() {
        for angle in [0.0, 1e-9, 1e-4, 0.5, 2.0, 3.1, std::f64::consts::PI] {
            let r = Rotation3::from_axis_angle(&Vector3::y_axis(), angle);
            let a = evo_rotation_angle(r.matrix());
            assert!((a - angle).abs() <= 1e-15 + 1e-12 * angle, "{angle}: {a}");
        }
        // a matrix that is not quite orthogonal is orthogonalised first
        let mut m = *Rotation3::from_axis_angle(&Vector3::z_axis(), 0.25).matrix();
        m[(0, 0)] *= 1.0 + 1e-7;
        assert!((evo_rotation_angle(&m) - 0.25).abs() < 1e-7);
    }
}
