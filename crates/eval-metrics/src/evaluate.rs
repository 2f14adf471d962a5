//! The loop-closure evaluation of one run, exactly as the authors' evaluation code does it
//! (DESIGN.md, paper section 3).

use std::fmt;

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::sim3::{align_sim3, rotation_angle, AlignFailure, Sim3};
use crate::trajectory::{GroundTruth, Trajectory};

/// Maximum time difference, in seconds, between an estimated pose and its ground-truth row.
pub const ASSOCIATION_TOLERANCE: f64 = 0.001;

/// Backwards runs may carry timestamps `BACKWARDS_EPOCH - t`.
pub const BACKWARDS_EPOCH: f64 = 2e9;

/// An estimate whose first timestamp is further than this (seconds) from the ground truth's
/// first one is taken to use the `2e9 - t` convention.
pub const BACKWARDS_DETECT_GAP: f64 = 1000.0;

/// Which segment a failure concerns.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Segment {
    /// The start segment (first half of the ground-truth rows).
    Start,
    /// The end segment (second half).
    End,
}

impl fmt::Display for Segment {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Segment::Start => "start",
            Segment::End => "end",
        })
    }
}

/// Why a run failed. A failed run is a result (all metrics infinite), not an error.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum FailReason {
    /// The estimate has no pose.
    Empty,
    /// A pose contains NaN or an infinity (index in file order and its timestamp).
    NonFinite {
        /// 0-based index of the pose in the file.
        index: usize,
        /// Its timestamp (may itself be non-finite).
        t: f64,
    },
    /// A pose has no ground-truth row within [`ASSOCIATION_TOLERANCE`].
    Unassociated {
        /// The pose's timestamp (after the backwards mapping, if any).
        t: f64,
    },
    /// A segment has fewer than 3 poses with ground truth.
    TooFewPoses {
        /// Which segment.
        segment: Segment,
        /// How many it has.
        count: usize,
    },
    /// A segment's poses are collinear or identical: the alignment is not determined.
    Degenerate {
        /// Which segment.
        segment: Segment,
    },
    /// Some other reason (for example an unreadable file in a batch run with keep-going).
    Other {
        /// The reason.
        message: String,
    },
}

impl fmt::Display for FailReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FailReason::Empty => write!(f, "the estimate has no pose"),
            FailReason::NonFinite { index, t } => {
                write!(f, "pose {} (t={t}) contains NaN or infinity", index + 1)
            }
            FailReason::Unassociated { t } => write!(
                f,
                "pose at t={t:.6} has no ground-truth row within {ASSOCIATION_TOLERANCE} s"
            ),
            FailReason::TooFewPoses { segment, count } => write!(
                f,
                "{segment} segment has {count} pose(s) with ground truth, at least 3 are needed"
            ),
            FailReason::Degenerate { segment } => write!(
                f,
                "{segment} segment poses are collinear or identical, the alignment is not determined"
            ),
            FailReason::Other { message } => f.write_str(message),
        }
    }
}

/// The metrics of one run; infinite where the run failed (JSON writes infinities as `null`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Metrics {
    /// Alignment error: RMS over all estimated positions of the distance between the start-
    /// and the end-aligned trajectory.
    pub e_align: f64,
    /// Scale drift `s_start / s_end` (a multiplier; 1 is perfect).
    pub e_s: f64,
    /// Rotation drift in degrees: the angle of `R_end R_start^T`.
    pub e_r: f64,
    /// Translation drift: `|translation(S_end * S_start^-1)|`.
    pub e_t: f64,
    /// RMSE of one Sim(3) alignment over both segments together.
    pub e_rmse: f64,
    /// RMSE of the start-segment alignment.
    pub rmse_start: f64,
    /// RMSE of the end-segment alignment.
    pub rmse_end: f64,
}

impl Metrics {
    /// All metrics infinite (a failed run).
    pub const FAILED: Metrics = Metrics {
        e_align: f64::INFINITY,
        e_s: f64::INFINITY,
        e_r: f64::INFINITY,
        e_t: f64::INFINITY,
        e_rmse: f64::INFINITY,
        rmse_start: f64::INFINITY,
        rmse_end: f64::INFINITY,
    };

    /// The symmetric scale error of the paper's summaries, `e'_s = max(e_s, 1 / e_s)`.
    pub fn e_s_sym(&self) -> f64 {
        if self.e_s.is_finite() && self.e_s > 0.0 {
            self.e_s.max(1.0 / self.e_s)
        } else {
            f64::INFINITY
        }
    }
}

/// The result of evaluating one run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Evaluation {
    /// `None` when the run succeeded, else why it failed.
    pub failure: Option<FailReason>,
    /// The metrics (infinite when failed; `rmse_start` may be finite when only the end
    /// segment failed).
    pub metrics: Metrics,
    /// Number of estimated poses.
    pub poses: usize,
    /// Poses used for the start alignment.
    pub poses_start: usize,
    /// Poses used for the end alignment.
    pub poses_end: usize,
    /// `gt_from_est` of the start segment.
    pub start: Option<Sim3>,
    /// `gt_from_est` of the end segment.
    pub end: Option<Sim3>,
    /// Whether the timestamps were mapped back from the `2e9 - t` convention.
    pub backwards_time_mapped: bool,
    /// Estimated positions sorted by (mapped) time, as evaluated.
    pub positions: Vec<Vector3<f64>>,
    /// Their timestamps.
    pub times: Vec<f64>,
}

impl Evaluation {
    /// Whether the run succeeded.
    pub fn is_ok(&self) -> bool {
        self.failure.is_none()
    }

    fn failed(reason: FailReason, poses: usize) -> Evaluation {
        Evaluation {
            failure: Some(reason),
            metrics: Metrics::FAILED,
            poses,
            poses_start: 0,
            poses_end: 0,
            start: None,
            end: None,
            backwards_time_mapped: false,
            positions: Vec::new(),
            times: Vec::new(),
        }
    }

    /// The accumulated drift `T_drift = S_end * S_start^-1`.
    pub fn drift(&self) -> Option<Sim3> {
        Some(self.end?.compose(&self.start?.inverse()))
    }
}

fn segment_failure(f: AlignFailure, segment: Segment) -> FailReason {
    match f {
        AlignFailure::TooFew(count) => FailReason::TooFewPoses { segment, count },
        AlignFailure::Degenerate => FailReason::Degenerate { segment },
        // evaluate() pairs every pose with a finite ground-truth row
        other @ (AlignFailure::LengthMismatch { .. } | AlignFailure::NonFinite) => {
            FailReason::Other {
                message: format!("{segment} segment: {other}"),
            }
        }
    }
}

/// Evaluates one estimated trajectory against the loop-closure ground truth.
///
/// Sorts the estimate by time, maps `2e9 - t` timestamps back, associates every pose with
/// the ground-truth row within 1 ms, aligns the start and the end segment separately by
/// Sim(3), and computes every metric. Never fails: problems with the run are reported in
/// [`Evaluation::failure`].
pub fn evaluate(est: &Trajectory, gt: &GroundTruth) -> Evaluation {
    let n = est.poses.len();
    if n == 0 {
        return Evaluation::failed(FailReason::Empty, 0);
    }
    if let Some((index, p)) = est.poses.iter().enumerate().find(|(_, p)| !p.is_finite()) {
        return Evaluation::failed(FailReason::NonFinite { index, t: p.t }, n);
    }
    let mut rows: Vec<(f64, Vector3<f64>)> = est.poses.iter().map(|p| (p.t, p.position)).collect();
    rows.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut mapped = false;
    if (rows[0].0 - gt.times()[0]).abs() > BACKWARDS_DETECT_GAP {
        for r in rows.iter_mut() {
            r.0 = BACKWARDS_EPOCH - r.0;
        }
        rows.reverse();
        mapped = true;
    }
    let (start_last, end_first) = gt.window_bounds();
    let gt_pos = gt.positions();
    type Pairs = (Vec<Vector3<f64>>, Vec<Vector3<f64>>);
    let mut start_pairs: Pairs = (Vec::new(), Vec::new());
    let mut end_pairs: Pairs = (Vec::new(), Vec::new());
    let mut joint_pairs: Pairs = (Vec::new(), Vec::new());
    for &(t, p) in &rows {
        let Some(j) = gt.associate(t, ASSOCIATION_TOLERANCE) else {
            let mut e = Evaluation::failed(FailReason::Unassociated { t }, n);
            e.backwards_time_mapped = mapped;
            return e;
        };
        let g = gt_pos[j];
        if !g.iter().all(|v| v.is_finite()) {
            continue;
        }
        let in_start = j <= start_last;
        let in_end = j >= end_first;
        if in_start {
            start_pairs.0.push(p);
            start_pairs.1.push(g);
        }
        if in_end {
            end_pairs.0.push(p);
            end_pairs.1.push(g);
        }
        if in_start || in_end {
            joint_pairs.0.push(p);
            joint_pairs.1.push(g);
        }
    }
    let times: Vec<f64> = rows.iter().map(|r| r.0).collect();
    let positions: Vec<Vector3<f64>> = rows.iter().map(|r| r.1).collect();
    let mut result = Evaluation {
        failure: None,
        metrics: Metrics::FAILED,
        poses: n,
        poses_start: start_pairs.0.len(),
        poses_end: end_pairs.0.len(),
        start: None,
        end: None,
        backwards_time_mapped: mapped,
        positions,
        times,
    };
    let start = match align_sim3(&start_pairs.0, &start_pairs.1) {
        Ok(a) => a,
        Err(f) => {
            result.failure = Some(segment_failure(f, Segment::Start));
            return result;
        }
    };
    result.start = Some(start.transform);
    result.metrics.rmse_start = start.rmse;
    let end = match align_sim3(&end_pairs.0, &end_pairs.1) {
        Ok(a) => a,
        Err(f) => {
            result.failure = Some(segment_failure(f, Segment::End));
            return result;
        }
    };
    result.end = Some(end.transform);
    let (s, e) = (start.transform, end.transform);
    let drift = e.compose(&s.inverse());
    let sq: f64 = result
        .positions
        .iter()
        .map(|p| (s.apply(p) - e.apply(p)).norm_squared())
        .sum();
    let e_align = (sq / n as f64).sqrt();
    // The joint alignment cannot fail when each segment aligned, except in contrived cases
    // (both segments on one line); then e_rmse stays infinite.
    let e_rmse = align_sim3(&joint_pairs.0, &joint_pairs.1).map_or(f64::INFINITY, |a| a.rmse);
    let rel = e.rotation * s.rotation.inverse();
    result.metrics = Metrics {
        e_align,
        e_s: s.scale / e.scale,
        e_r: rotation_angle(&rel).to_degrees(),
        e_t: drift.translation.norm(),
        e_rmse,
        rmse_start: start.rmse,
        rmse_end: end.rmse,
    };
    result
}
