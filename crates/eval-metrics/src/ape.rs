//! The absolute pose error (APE, also ATE) exactly as evo's `evo_ape` defines it: the poses
//! associated by time ([`evo_pairs`]), the estimate aligned ([`align_track`]), then for each
//! pair the error pose `E_i = P_i^-1 Q_i` (estimate `P`, reference `Q`) reduced to one number
//! by the pose relation.

use serde::{Deserialize, Serialize};

use crate::align::{align_track, AlignMode, AlignOptions, AlignTransform};
use crate::association::{evo_pairs, SyncOptions};
use crate::pose::{evo_rotation_angle, PoseTrack, Se3};
use crate::stats::ErrorStats;
use crate::MetricError;

/// Which part of an error pose is measured (evo's `--pose_relation`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PoseRelation {
    /// Length of the translation of the error pose (for APE: the distance between the
    /// positions), in the trajectory's unit.
    #[default]
    TransPart,
    /// Frobenius norm of `R_E - I` (no unit).
    RotPart,
    /// Frobenius norm of `E - I` as a 4x4 matrix (no unit).
    Full,
    /// Rotation angle of `E` in degrees.
    AngleDeg,
    /// Rotation angle of `E` in radians.
    AngleRad,
    /// For APE the distance between the positions; for RPE the difference of the distances
    /// travelled between the two poses of a pair.
    PointDistance,
    /// RPE only: the point distance over the reference's distance, in percent.
    PointDistanceErrorRatio,
}

impl PoseRelation {
    /// evo's command-line name.
    pub fn name(self) -> &'static str {
        match self {
            PoseRelation::TransPart => "trans_part",
            PoseRelation::RotPart => "rot_part",
            PoseRelation::Full => "full",
            PoseRelation::AngleDeg => "angle_deg",
            PoseRelation::AngleRad => "angle_rad",
            PoseRelation::PointDistance => "point_distance",
            PoseRelation::PointDistanceErrorRatio => "point_distance_error_ratio",
        }
    }

    /// evo's description, used in titles.
    pub fn description(self) -> &'static str {
        match self {
            PoseRelation::TransPart => "translation part",
            PoseRelation::RotPart => "rotation part",
            PoseRelation::Full => "full transformation",
            PoseRelation::AngleDeg => "rotation angle in degrees",
            PoseRelation::AngleRad => "rotation angle in radians",
            PoseRelation::PointDistance => "point distance",
            PoseRelation::PointDistanceErrorRatio => "point distance error ratio",
        }
    }

    /// The unit of the errors as evo names it (`m`, `deg`, `rad`, `%`, `unit-less`).
    pub fn unit(self) -> &'static str {
        match self {
            PoseRelation::TransPart | PoseRelation::PointDistance => "m",
            PoseRelation::AngleDeg => "deg",
            PoseRelation::AngleRad => "rad",
            PoseRelation::PointDistanceErrorRatio => "%",
            PoseRelation::RotPart | PoseRelation::Full => "unit-less",
        }
    }

    /// The error of one error pose (not for the point-distance relations of RPE).
    pub(crate) fn of_pose(self, e: &Se3) -> f64 {
        match self {
            PoseRelation::TransPart | PoseRelation::PointDistance => e.translation.norm(),
            PoseRelation::RotPart => (e.rotation - nalgebra::Matrix3::identity()).norm(),
            PoseRelation::Full => e.distance_from_identity(),
            PoseRelation::AngleRad => evo_rotation_angle(&e.rotation),
            PoseRelation::AngleDeg => evo_rotation_angle(&e.rotation).to_degrees(),
            PoseRelation::PointDistanceErrorRatio => f64::NAN,
        }
    }

    /// Whether the relation measures rotation angles (then reflections are refused).
    pub(crate) fn needs_angles(self) -> bool {
        matches!(self, PoseRelation::AngleDeg | PoseRelation::AngleRad)
    }
}

/// APE options: evo's `-r`, `-a`, `-s`, `--n_to_align`, `--align_origin`, `--t_max_diff`,
/// `--t_offset`, `--sync_method`, `--t_start`, `--t_end` (and the 4-DoF alignment).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ApeOptions {
    /// What is measured.
    pub relation: PoseRelation,
    /// How the estimate is aligned.
    pub align: AlignOptions,
    /// How poses are associated.
    pub sync: SyncOptions,
}

/// The APE of one run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ApeResult {
    /// The statistics of the errors.
    pub stats: ErrorStats,
    /// One error per associated pose pair, in time order.
    pub errors: Vec<f64>,
    /// The associated reference poses.
    pub reference: PoseTrack,
    /// The associated estimated poses, aligned.
    pub estimate: PoseTrack,
    /// The alignment applied to the estimate.
    pub alignment: Option<AlignTransform>,
    /// evo's title of the result (metric, unit, alignment).
    pub title: String,
}

/// The alignment part of evo's titles (`\n(with Sim(3) Umeyama alignment)`, ...).
pub(crate) fn alignment_title(a: &AlignOptions) -> String {
    let mut t = match a.mode {
        AlignMode::Se3 => "\n(with SE(3) Umeyama alignment)".to_string(),
        AlignMode::Sim3 => "\n(with Sim(3) Umeyama alignment)".to_string(),
        AlignMode::Scale => "\n(scale corrected)".to_string(),
        AlignMode::PosYaw => "\n(with 4-DoF position and yaw alignment)".to_string(),
        AlignMode::None if !a.origin => "\n(not aligned)".to_string(),
        AlignMode::None => String::new(),
    };
    if a.mode != AlignMode::None {
        if let Some(n) = a.n_to_align {
            t += &format!(" (aligned poses: {n})");
        }
    }
    if a.origin {
        t += "\n(with origin alignment)";
    }
    t
}

/// Refuses reflections where rotation angles are measured.
pub(crate) fn check_rotations(t: &PoseTrack, which: &'static str) -> Result<(), MetricError> {
    for (index, r) in t.rotations.iter().enumerate() {
        let det = r.determinant();
        if det <= 0.0 {
            return Err(MetricError::NotARotation { which, index, det });
        }
    }
    Ok(())
}

/// The absolute pose error of `estimate` against `reference`, as `evo_ape` computes it.
///
/// ```
/// use eval_metrics::{ape, parse_tum, AlignMode, ApeOptions, PoseTrack};
///
/// let gt = "0 0 0 0 0 0 0 1\n1 1 0 0 0 0 0 1\n2 1 1 0 0 0 0 1\n3 0 1 1 0 0 0 1\n";
/// let est = "0 0 0 0 0 0 0 1\n1 2 0 0 0 0 0 1\n2 2 2 0 0 0 0 1\n3 0 2 2 0 0 0 1\n";
/// let (gt, est) = (PoseTrack::from_trajectory(&parse_tum(gt)?),
///                  PoseTrack::from_trajectory(&parse_tum(est)?));
/// let mut opts = ApeOptions::default();
/// opts.align.mode = AlignMode::Sim3; // evo_ape tum gt.txt est.txt -as
/// let r = ape(&gt, &est, &opts)?;
/// assert!(r.stats.rmse < 1e-12 && r.stats.n == 4);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn ape(
    reference: &PoseTrack,
    estimate: &PoseTrack,
    opts: &ApeOptions,
) -> Result<ApeResult, MetricError> {
    if opts.relation == PoseRelation::PointDistanceErrorRatio {
        return Err(MetricError::Option(
            "point_distance_error_ratio is a relative (RPE) measure".into(),
        ));
    }
    let (reference, mut estimate) = evo_pairs(reference, estimate, &opts.sync)?;
    let alignment = align_track(&mut estimate, &reference, &opts.align)?;
    if opts.relation.needs_angles() {
        check_rotations(&reference, "reference")?;
        check_rotations(&estimate, "estimate")?;
    }
    let errors: Vec<f64> = match opts.relation {
        PoseRelation::TransPart | PoseRelation::PointDistance => estimate
            .positions
            .iter()
            .zip(&reference.positions)
            .map(|(p, q)| (p - q).norm())
            .collect(),
        rel => (0..estimate.len())
            .map(|i| rel.of_pose(&estimate.pose(i).relative(&reference.pose(i))))
            .collect(),
    };
    let stats = ErrorStats::of(&errors).ok_or(MetricError::Empty("estimate"))?;
    let title = format!(
        "APE w.r.t. {} ({}){}",
        opts.relation.description(),
        opts.relation.unit(),
        alignment_title(&opts.align)
    );
    Ok(ApeResult {
        stats,
        errors,
        reference,
        estimate,
        alignment,
        title,
    })
}
