//! Aligning an estimated track to its reference before the errors are measured, as evo
//! (`-a`, `-s`, `-as`, `--n_to_align`, `--align_origin`) and rpg_trajectory_evaluation
//! (`posyaw`, the 4-DoF alignment of visual-inertial runs) do it. The least-squares fits are
//! [`umeyama`]'s.

use nalgebra::{Matrix3, Matrix4, Vector3};
use serde::{Deserialize, Serialize};

use crate::pose::{PoseTrack, Se3};
use crate::sim3::umeyama;
use crate::MetricError;

/// Which transform aligns the estimate to the reference.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AlignMode {
    /// No alignment (evo's default).
    #[default]
    None,
    /// Rotation and translation, least squares (evo `-a`; Horn's method).
    Se3,
    /// Scale, rotation and translation, least squares (evo `-as`).
    Sim3,
    /// Only the scale of the least-squares Sim(3) (evo `-s` without `-a`).
    Scale,
    /// Translation and rotation about the reference's z axis (gravity), least squares: the
    /// 4-DoF alignment of visual-inertial odometry (rpg_trajectory_evaluation's `posyaw`).
    PosYaw,
}

impl AlignMode {
    /// The name used in titles and results (`none`, `se3`, `sim3`, `scale`, `posyaw`).
    pub fn name(self) -> &'static str {
        match self {
            AlignMode::None => "none",
            AlignMode::Se3 => "se3",
            AlignMode::Sim3 => "sim3",
            AlignMode::Scale => "scale",
            AlignMode::PosYaw => "posyaw",
        }
    }
}

/// How to align.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default)]
pub struct AlignOptions {
    /// The fit.
    pub mode: AlignMode,
    /// Fit to the first `n` pose pairs only (`--n_to_align`; `None`: all).
    pub n_to_align: Option<usize>,
    /// Then move the first estimated pose onto the first reference pose (`--align_origin`).
    pub origin: bool,
}

/// The transform applied to the estimate: `p -> scale * rotation * p + translation` on
/// positions, `rotation * R` on orientations.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct AlignTransform {
    /// Scale.
    pub scale: f64,
    /// Rotation (as computed; a KITTI-based origin alignment keeps the file's matrices).
    pub rotation: Matrix3<f64>,
    /// Translation.
    pub translation: Vector3<f64>,
}

impl AlignTransform {
    /// The 4x4 matrix `[s R | t]` (evo's `alignment_transformation_sim3`).
    pub fn matrix(&self) -> Matrix4<f64> {
        let mut m = Matrix4::identity();
        m.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&(self.rotation * self.scale));
        m.fixed_view_mut::<3, 1>(0, 3).copy_from(&self.translation);
        m
    }
}

/// The rotation of `theta` about z, as `transformations.rotation_matrix(theta, [0, 0, 1])`
/// computes it.
fn rot_z(theta: f64) -> Matrix3<f64> {
    let (s, c) = theta.sin_cos();
    Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, c + (1.0 - c))
}

/// The yaw maximising `trace(Rz(theta) C)` (rpg's `get_best_yaw`).
fn best_yaw(c: &Matrix3<f64>) -> f64 {
    let a = c[(0, 1)] - c[(1, 0)];
    let b = c[(0, 0)] + c[(1, 1)];
    std::f64::consts::FRAC_PI_2 - b.atan2(a)
}

/// The 4-DoF fit `gt ~ Rz(theta) est + t` by least squares over corresponding positions
/// (rpg's `align_umeyama(..., known_scale=True, yaw_only=True)`).
pub fn align_yaw(est: &[Vector3<f64>], gt: &[Vector3<f64>]) -> Result<Se3, MetricError> {
    let n = est.len().min(gt.len());
    if n == 0 {
        return Err(MetricError::Align(crate::AlignFailure::TooFew(0)));
    }
    if !est[..n]
        .iter()
        .chain(&gt[..n])
        .all(|p| p.iter().all(|v| v.is_finite()))
    {
        return Err(MetricError::Align(crate::AlignFailure::NonFinite));
    }
    let me: Vector3<f64> = est[..n].iter().sum::<Vector3<f64>>() / n as f64;
    let mg: Vector3<f64> = gt[..n].iter().sum::<Vector3<f64>>() / n as f64;
    let mut c = Matrix3::zeros();
    for (e, g) in est[..n].iter().zip(&gt[..n]) {
        c += (e - me) * (g - mg).transpose();
    }
    let r = rot_z(best_yaw(&c));
    let translation = mg - r * me;
    if !(r.iter().all(|v| v.is_finite()) && translation.iter().all(|v| v.is_finite())) {
        return Err(MetricError::Align(crate::AlignFailure::NonFinite));
    }
    Ok(Se3 {
        rotation: r,
        translation,
    })
}

/// Aligns `est` to `reference` (equally many poses, paired by index) in place, as evo's
/// `ape`/`rpe` do before measuring: the least-squares fit of the first `n_to_align` positions
/// (for [`AlignMode::Scale`] only its scale is applied), then the origin alignment. Returns
/// the transform applied (`None` when nothing was), as evo reports it: for a scale-only
/// alignment the whole fit, of which only the scale was used.
pub fn align_track(
    est: &mut PoseTrack,
    reference: &PoseTrack,
    opts: &AlignOptions,
) -> Result<Option<AlignTransform>, MetricError> {
    let n = opts
        .n_to_align
        .map_or(est.len(), |k| k.min(est.len()))
        .min(reference.len());
    if opts.n_to_align == Some(0) {
        return Err(MetricError::Option(
            "--n_to_align must be at least 1 (or -1 for all poses)".into(),
        ));
    }
    let mut applied = None;
    match opts.mode {
        AlignMode::None => {}
        AlignMode::Se3 | AlignMode::Sim3 | AlignMode::Scale => {
            let with_scale = opts.mode != AlignMode::Se3;
            let fit = umeyama(&est.positions[..n], &reference.positions[..n], with_scale)
                .map_err(MetricError::Align)?;
            let r = *fit.rotation.matrix();
            let s = fit.scale;
            let t = fit.translation;
            match opts.mode {
                AlignMode::Scale => {
                    for p in &mut est.positions {
                        *p *= s;
                    }
                }
                AlignMode::Sim3 => transform(est, &r, &t, s),
                _ => transform(est, &r, &t, 1.0),
            }
            applied = Some(AlignTransform {
                scale: s,
                rotation: r,
                translation: t,
            });
        }
        AlignMode::PosYaw => {
            let fit = if n == 1 {
                // rpg: one pose aligns by its position and the yaw between the orientations
                let c = est.rotations[0] * reference.rotations[0].transpose();
                let r = rot_z(best_yaw(&c));
                Se3 {
                    rotation: r,
                    translation: reference.positions[0] - r * est.positions[0],
                }
            } else {
                align_yaw(&est.positions[..n], &reference.positions[..n])?
            };
            transform(est, &fit.rotation, &fit.translation, 1.0);
            applied = Some(AlignTransform {
                scale: 1.0,
                rotation: fit.rotation,
                translation: fit.translation,
            });
        }
    }
    if opts.origin {
        if est.is_empty() || reference.is_empty() {
            return Err(MetricError::Empty("a trajectory"));
        }
        let to_ref = reference.pose(0).compose(&est.pose(0).inverse());
        transform(est, &to_ref.rotation, &to_ref.translation, 1.0);
        applied = Some(AlignTransform {
            scale: 1.0,
            rotation: to_ref.rotation,
            translation: to_ref.translation,
        });
    }
    Ok(applied)
}

/// Applies `p -> R (s p) + t`, `R_i -> R R_i` to every pose (evo's `scale` then `transform`),
/// keeping the quaternions in step.
fn transform(track: &mut PoseTrack, r: &Matrix3<f64>, t: &Vector3<f64>, s: f64) {
    for p in &mut track.positions {
        *p = r * (*p * s) + t;
    }
    for m in &mut track.rotations {
        *m = r * *m;
    }
    // closed form (nalgebra's iterative `from_matrix` does not return on NaN)
    let q = nalgebra::UnitQuaternion::from_rotation_matrix(
        &nalgebra::Rotation3::from_matrix_unchecked(*r),
    )
    .into_inner();
    for x in &mut track.quaternions {
        *x = q * *x;
    }
}
