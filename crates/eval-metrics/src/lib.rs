//! The loop-closure drift metrics of the TUM monoVO benchmark (Engel, Usenko, Cremers,
//! section 3), exact and fast, for one run or thousands.
//!
//! * [`parse_tum`], [`parse_kitti`], [`parse_euroc`] read estimated trajectories;
//!   [`GroundTruth::parse`] reads `groundtruthSync.txt`.
//! * [`evaluate`] sorts, associates (1 ms), aligns the start and end segments by Sim(3)
//!   ([`align_sim3`], Umeyama) and returns `e_align`, `e_s`, `e_r`, `e_t`, `e_rmse` and the
//!   segment RMSEs. A run that cannot be evaluated is a *failed* result, not an error.
//! * [`evaluate_batch`], [`summarize`], [`cumulative`], [`summary_table`], and the
//!   results.csv format ([`write_csv`], [`parse_csv`]) for the paper's tables and plots.
//! * The field's other trajectory metrics, each exactly as its reference computes it, on
//!   [`PoseTrack`]s: evo's [`ape`] and [`rpe`] (association [`evo_pairs`], alignment
//!   [`align_track`] including 4-DoF), the TUM RGB-D scripts' [`tum_ate`] and [`tum_rpe`], the
//!   KITTI devkit's [`kitti_errors`], with evo's [`ErrorStats`] and result files
//!   ([`evo_result_entries`]); [`ExtraMetric`] computes them per run of a batch.
//!
//! Geometry is [`nalgebra`]'s: positions are `Vector3<f64>`, [`Sim3`] converts to and from
//! `Similarity3<f64>`, and [`Pose::world_from_camera`] gives an `Isometry3<f64>`. Every
//! result and option type is `serde`-serialisable.
//!
//! # Example
//!
//! ```
//! use eval_metrics::{evaluate, parse_tum, GroundTruth};
//!
//! // A ground truth of 8 rows: a loop of 4 poses at the start and 4 at the end.
//! let mut gt = String::new();
//! let mut est = String::new();
//! let pts = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.5]];
//! for (i, p) in pts.iter().chain(pts.iter()).enumerate() {
//!     gt += &format!("{i} {} {} {} 0 0 0 1\n", p[0], p[1], p[2]);
//!     // the estimate is the ground truth at twice the scale
//!     est += &format!("{i} {} {} {} 0 0 0 1\n", 2.0 * p[0], 2.0 * p[1], 2.0 * p[2]);
//! }
//! let run = evaluate(&parse_tum(&est)?, &GroundTruth::parse(&gt)?);
//! assert!(run.is_ok());
//! assert!(run.metrics.e_align < 1e-12);
//! assert!((run.metrics.e_s - 1.0).abs() < 1e-12);
//! # Ok::<(), eval_metrics::EvalError>(())
//! ```
#![deny(missing_docs)]

mod align;
mod ape;
mod association;
mod batch;
mod dataset_truth;
mod evaluate;
mod evo_result;
mod extra;
mod kitti;
mod metric;
mod pose;
mod pyrandom;
mod record;
mod rpe;
mod sim3;
mod stats;
mod table;
mod trajectory;
mod tum;

pub use nalgebra;

pub use align::{align_track, align_yaw, AlignMode, AlignOptions, AlignTransform};
pub use ape::{ape, ApeOptions, ApeResult, PoseRelation};
pub use association::{
    evo_pairs, evo_sync, find_closest_index, interpolate, matching_time_indices, slerp,
    tum_associate, SyncMethod, SyncOptions,
};
pub use batch::{
    cumulative, evaluate_batch, evaluate_batch_with, failed_extra, parse_csv, summarize, write_csv,
    Cumulative, DirectionFilter, SequenceSummary, Stat, CSV_HEADER,
};
pub use dataset_truth::{
    detect_ground_truth_format, parse_gnss_poses, parse_ground_truth_trajectory, GroundTruthFormat,
};
pub use evaluate::{
    evaluate, Evaluation, FailReason, Metrics, Segment, ASSOCIATION_TOLERANCE, BACKWARDS_EPOCH,
};
pub use evo_result::{evo_result_entries, npy_bytes, EvoResultInfo, NamedArray};
pub use extra::{batch_track, ExtraMetric, APE_COLUMNS, EXTRA_COLUMNS, KITTI_COLUMNS, RPE_COLUMNS};
pub use kitti::{kitti_errors, KittiLengthError, KittiResult, KittiSegment, KITTI_LENGTHS};
pub use metric::Metric;
pub use pose::{
    evo_rotation_angle, parse_kitti_poses, quaternion_matrix, rotvec_angle, scipy_quaternion,
    PoseTrack, Se3,
};
pub use pyrandom::PyRandom;
pub use record::{Direction, RunKey, RunRecord};
pub use rpe::{rpe, DeltaUnit, RpeOptions, RpeResult};
pub use sim3::{
    align_sim3, principal_plane, rotation_angle, umeyama, AlignFailure, Alignment, Sim3,
};
pub use stats::{pairwise_sum, ErrorStats};
pub use table::{markdown_table, summary_table, TableStyle, TABLE_CAPTION};
pub use trajectory::{
    detect_format, parse_euroc, parse_kitti, parse_tum, GroundTruth, Pose, Trajectory,
    TrajectoryFormat,
};
pub use tum::{tum_ate, tum_rpe, TumAteOptions, TumDeltaUnit, TumResult, TumRpeOptions};

/// Errors for unusable input (a malformed line, an empty or disordered ground truth). A run
/// that is merely bad (empty, NaN, lost tracking) is not an error: see [`FailReason`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EvalError {
    /// A line that does not have the expected form.
    #[error("line {line}: expected {expected}, found `{found}`")]
    Parse {
        /// 1-based line number.
        line: usize,
        /// What the line should contain.
        expected: &'static str,
        /// An excerpt of the line.
        found: String,
    },
    /// A line whose numbers are written with a decimal comma (`0,5`).
    #[error("line {line}: `{found}`: the decimal separator must be '.', not ','")]
    DecimalComma {
        /// 1-based line number.
        line: usize,
        /// An excerpt of the line.
        found: String,
    },
    /// Ground-truth timestamps that do not strictly increase.
    #[error(
        "line {line}: ground-truth timestamps must strictly increase, but {t} follows {previous}"
    )]
    GroundTruthOrder {
        /// 1-based line number.
        line: usize,
        /// The offending timestamp.
        t: f64,
        /// The timestamp before it.
        previous: f64,
    },
    /// A pose whose orientation is not a rotation: a quaternion of norm 0 (all zeros) or a
    /// singular rotation matrix. NaN stays allowed (the run failed).
    #[error("line {line}: `{found}`: the orientation is not a rotation ({what}); a pose needs a unit quaternion (or a rotation matrix)")]
    NotARotation {
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        what: &'static str,
        /// An excerpt of the line.
        found: String,
    },
    /// A ground truth without rows.
    #[error("the ground truth has no rows")]
    EmptyGroundTruth,
    /// Ground-truth times and positions of different counts.
    #[error("{times} ground-truth times but {positions} positions")]
    RowCount {
        /// Number of timestamps.
        times: usize,
        /// Number of positions.
        positions: usize,
    },
    /// A results.csv that does not read (bad quoting, a wrong value in a column).
    #[error("line {line}: {message}")]
    Csv {
        /// 1-based line number (0 when unknown).
        line: u64,
        /// What is wrong.
        message: String,
    },
    /// KITTI poses and timestamps of different counts.
    #[error("{poses} KITTI poses but {times} timestamps in the times file")]
    KittiCount {
        /// Number of pose lines.
        poses: usize,
        /// Number of timestamp lines.
        times: usize,
    },
}

/// Why a trajectory metric (APE, RPE, the KITTI segment errors) could not be computed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MetricError {
    /// A trajectory without poses.
    #[error("the {0} has no poses")]
    Empty(&'static str),
    /// A pose with a NaN or infinite number.
    #[error("the {which}'s pose {} (in file order) contains NaN or infinity", index + 1)]
    NonFinite {
        /// `reference` or `estimate`.
        which: &'static str,
        /// 0-based index of the pose.
        index: usize,
    },
    /// Association by time needs timestamps.
    #[error("the trajectories have no timestamps to associate (KITTI pose files pair by line)")]
    Unstamped,
    /// No pose of one trajectory has a partner in the other.
    #[error("found no matching timestamps between the reference and the estimate with max. time difference {max_diff} s and time offset {offset} s")]
    NoMatches {
        /// The tolerance.
        max_diff: f64,
        /// The offset added to the estimate's stamps.
        offset: f64,
    },
    /// Poses paired by line (no timestamps) need as many in both trajectories.
    #[error("the reference has {reference} poses and the estimate {estimate}; without timestamps poses pair by line and the counts must agree")]
    LengthMismatch {
        /// Reference poses.
        reference: usize,
        /// Estimated poses.
        estimate: usize,
    },
    /// Interpolation needs two poses.
    #[error("cannot interpolate a trajectory of {0} pose(s)")]
    TooFewToInterpolate(usize),
    /// The alignment failed.
    #[error("alignment: {0}")]
    Align(AlignFailure),
    /// No pose pairs for the relative error.
    #[error("delta = {delta} ({unit}) produced no pose pairs; try a smaller delta or a looser tolerance")]
    NoPairs {
        /// The delta.
        delta: f64,
        /// Its unit.
        unit: &'static str,
    },
    /// Too few compared pairs (the TUM scripts need two).
    #[error("only {0} pose pair(s) could be compared, at least 2 are needed")]
    TooFewPairs(usize),
    /// A rotation matrix with a non-positive determinant (a reflection), where an angle is
    /// needed.
    #[error("pose {} of the {which} has a rotation matrix with non-positive determinant {det}", index + 1)]
    NotARotation {
        /// `reference` or `estimate`.
        which: &'static str,
        /// 0-based index of the pose.
        index: usize,
        /// The determinant.
        det: f64,
    },
    /// An option value that cannot be used.
    #[error("{0}")]
    Option(String),
}
