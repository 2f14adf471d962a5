//! The KITTI odometry benchmark's segment errors, exactly as its devkit
//! (`evaluate_odometry.cpp`) computes them, including its single-precision arithmetic.
//!
//! Poses pair by line. Every 10th frame starts segments of 100, 200, ..., 800 m; a segment
//! ends at the first frame whose ground-truth distance from the start exceeds the length
//! (distances summed in `f32`). The error pose `E = (P_a^-1 P_b)^-1 (Q_a^-1 Q_b)` (estimate
//! `P`, ground truth `Q`, 4x4 inverses by the devkit's Gauss-Jordan elimination) gives
//! `t_err = |t_E| / L` and `r_err = acos((trace R_E - 1) / 2) / L` with the nominal length
//! `L`, in `f32`. The result is the mean over all segments pooled (also over sequences),
//! reported in percent and in degrees per 100 m; per length, the means of the lengths with
//! at least three segments (the devkit's plot files).

use serde::{Deserialize, Serialize};

use crate::pose::PoseTrack;
use crate::MetricError;

/// The devkit's segment lengths in metres.
pub const KITTI_LENGTHS: [f32; 8] = [100.0, 200.0, 300.0, 400.0, 500.0, 600.0, 700.0, 800.0];

/// One segment of the devkit (a line of its `errors/NN.txt`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct KittiSegment {
    /// First frame (0-based line).
    pub first_frame: usize,
    /// Rotation error per metre, radians.
    pub r_err: f32,
    /// Translation error per metre (a fraction).
    pub t_err: f32,
    /// Nominal length in metres.
    pub len: f32,
    /// Speed in m/s assuming 10 frames per second (the devkit's).
    pub speed: f32,
}

/// Mean errors of one segment length.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct KittiLengthError {
    /// Segment length in metres.
    pub length: f64,
    /// Mean translation error in percent.
    pub t_err_percent: f64,
    /// Mean rotation error in degrees per 100 m.
    pub r_err_deg_per_100m: f64,
    /// Number of segments.
    pub segments: usize,
}

/// The devkit's result over one or more sequences.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct KittiResult {
    /// Mean translation error over all segments, percent (the leaderboard's figure).
    pub t_err_percent: f64,
    /// Mean rotation error over all segments, degrees per 100 m.
    pub r_err_deg_per_100m: f64,
    /// The devkit's `stats.txt` values as computed (`f32`): translation error per metre.
    pub t_err: f32,
    /// Rotation error in radians per metre, as in `stats.txt`.
    pub r_err: f32,
    /// Per segment length, the lengths with at least 3 segments.
    pub lengths: Vec<KittiLengthError>,
    /// Every segment, sequence after sequence.
    pub segments: Vec<KittiSegment>,
}

/// A 4x4 matrix computed as the devkit's `Matrix` class does.
#[derive(Clone, Copy)]
struct Mat4([[f64; 4]; 4]);

impl Mat4 {
    fn pose(t: &PoseTrack, i: usize) -> Mat4 {
        let (r, p) = (&t.rotations[i], &t.positions[i]);
        Mat4([
            [r[(0, 0)], r[(0, 1)], r[(0, 2)], p[0]],
            [r[(1, 0)], r[(1, 1)], r[(1, 2)], p[1]],
            [r[(2, 0)], r[(2, 1)], r[(2, 2)], p[2]],
            [0.0, 0.0, 0.0, 1.0],
        ])
    }

    /// `A * B`, each entry summed from zero over k in order.
    fn mul(&self, b: &Mat4) -> Mat4 {
        let mut c = [[0.0; 4]; 4];
        for (i, row) in c.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                for k in 0..4 {
                    *v += self.0[i][k] * b.0[k][j];
                }
            }
        }
        Mat4(c)
    }

    /// The inverse by Gauss-Jordan elimination with full pivoting (the devkit's
    /// `Matrix::inv`, which solves `A X = I`); `None` when a pivot is below 1e-20.
    fn inv(&self) -> Option<Mat4> {
        let mut a = self.0;
        let mut b = [[0.0; 4]; 4];
        for (i, row) in b.iter_mut().enumerate() {
            row[i] = 1.0;
        }
        let mut ipiv = [0u8; 4];
        let (mut irow, mut icol) = (0usize, 0usize);
        for _ in 0..4 {
            let mut big = 0.0;
            for j in 0..4 {
                if ipiv[j] != 1 {
                    for k in 0..4 {
                        if ipiv[k] == 0 && a[j][k].abs() >= big {
                            big = a[j][k].abs();
                            irow = j;
                            icol = k;
                        }
                    }
                }
            }
            ipiv[icol] += 1;
            if irow != icol {
                a.swap(irow, icol);
                b.swap(irow, icol);
            }
            let pivot = a[icol][icol].abs();
            if pivot.is_nan() || pivot < 1e-20 {
                return None;
            }
            let pivinv = 1.0 / a[icol][icol];
            a[icol][icol] = 1.0;
            for v in a[icol].iter_mut() {
                *v *= pivinv;
            }
            for v in b[icol].iter_mut() {
                *v *= pivinv;
            }
            for ll in 0..4 {
                if ll != icol {
                    let dum = a[ll][icol];
                    a[ll][icol] = 0.0;
                    let (arow, brow) = (a[icol], b[icol]);
                    for (x, p) in a[ll].iter_mut().zip(arow) {
                        *x -= p * dum;
                    }
                    for (x, p) in b[ll].iter_mut().zip(brow) {
                        *x -= p * dum;
                    }
                }
            }
        }
        Some(Mat4(b))
    }
}

/// Distances along the ground truth, summed in `f32` (`trajectoryDistances`).
fn trajectory_distances(gt: &PoseTrack) -> Vec<f32> {
    let mut dist = Vec::with_capacity(gt.len());
    if gt.is_empty() {
        return dist;
    }
    dist.push(0.0f32);
    for i in 1..gt.len() {
        let (p1, p2) = (&gt.positions[i - 1], &gt.positions[i]);
        let dx = (p1[0] - p2[0]) as f32;
        let dy = (p1[1] - p2[1]) as f32;
        let dz = (p1[2] - p2[2]) as f32;
        dist.push(dist[i - 1] + (dx * dx + dy * dy + dz * dz).sqrt());
    }
    dist
}

/// The segments of one sequence (`calcSequenceErrors`).
fn sequence_errors(gt: &PoseTrack, est: &PoseTrack) -> Result<Vec<KittiSegment>, MetricError> {
    let dist = trajectory_distances(gt);
    let singular = |which: &'static str, index: usize| MetricError::NotARotation {
        which,
        index,
        det: 0.0,
    };
    let mut err = Vec::new();
    for first in (0..gt.len()).step_by(10) {
        for &len in &KITTI_LENGTHS {
            let target = dist[first] + len;
            // the first frame past the length (the distances never decrease: a binary search
            // finds the frame the devkit's linear scan finds)
            let last = first + dist[first..].partition_point(|&d| d <= target);
            if last >= dist.len() {
                continue;
            }
            let g0 = Mat4::pose(gt, first)
                .inv()
                .ok_or_else(|| singular("reference", first))?;
            let e0 = Mat4::pose(est, first)
                .inv()
                .ok_or_else(|| singular("estimate", first))?;
            let delta_gt = g0.mul(&Mat4::pose(gt, last));
            let delta_est = e0.mul(&Mat4::pose(est, last));
            let e = delta_est
                .inv()
                .ok_or_else(|| singular("estimate", last))?
                .mul(&delta_gt);
            let (a, b, c) = (e.0[0][0] as f32, e.0[1][1] as f32, e.0[2][2] as f32);
            let d = (0.5 * (f64::from(a + b + c) - 1.0)) as f32;
            let r_err = d.clamp(-1.0, 1.0).acos();
            let (dx, dy, dz) = (e.0[0][3] as f32, e.0[1][3] as f32, e.0[2][3] as f32);
            let t_err = (dx * dx + dy * dy + dz * dz).sqrt();
            let num_frames = (last - first + 1) as f32;
            let speed = (f64::from(len) / (0.1 * f64::from(num_frames))) as f32;
            err.push(KittiSegment {
                first_frame: first,
                r_err: r_err / len,
                t_err: t_err / len,
                len,
                speed,
            });
        }
    }
    Ok(err)
}

/// The devkit's errors over one or more sequences of `(ground truth, estimate)` tracks,
/// paired by line (the counts must agree in each sequence).
///
/// ```
/// use eval_metrics::{kitti_errors, PoseTrack};
/// use nalgebra::{Matrix3, Vector3};
///
/// // a straight 300 m drive, the estimate 1% too long
/// let track = |k: f64| PoseTrack {
///     times: None,
///     positions: (0..400).map(|i| Vector3::new(0.0, 0.0, k * i as f64)).collect(),
///     rotations: vec![Matrix3::identity(); 400],
///     quaternions: vec![Default::default(); 400],
/// };
/// let r = kitti_errors(&[(track(1.0), track(1.01))])?;
/// assert_eq!(r.lengths.len(), 3); // 100, 200 and 300 m
/// // a segment ends past its length (at 101 m for 100 m) and is divided by the nominal length
/// assert!((r.lengths[0].t_err_percent - 1.01).abs() < 1e-4);
/// assert!((r.lengths[2].t_err_percent - 1.01 * 301.0 / 303.0).abs() < 1e-4);
/// # Ok::<(), eval_metrics::MetricError>(())
/// ```
pub fn kitti_errors(sequences: &[(PoseTrack, PoseTrack)]) -> Result<KittiResult, MetricError> {
    let mut all = Vec::new();
    for (gt, est) in sequences {
        if gt.is_empty() {
            return Err(MetricError::Empty("reference"));
        }
        if gt.len() != est.len() {
            return Err(MetricError::LengthMismatch {
                reference: gt.len(),
                estimate: est.len(),
            });
        }
        for (which, t) in [("reference", gt), ("estimate", est)] {
            if let Some(index) = t.first_non_finite() {
                return Err(MetricError::NonFinite { which, index });
            }
        }
        all.extend(sequence_errors(gt, est)?);
    }
    if all.is_empty() {
        return Err(MetricError::Option(
            "no segment of 100 m or more: the ground truth is too short for the KITTI metric"
                .into(),
        ));
    }
    let (mut t, mut r) = (0.0f32, 0.0f32);
    for s in &all {
        t += s.t_err;
        r += s.r_err;
    }
    let num = all.len() as f32;
    let (t, r) = (t / num, r / num);
    let to_deg_100 = |v: f32| f64::from(v) * (180.0 / std::f64::consts::PI) * 100.0;
    let mut lengths = Vec::new();
    for &len in &KITTI_LENGTHS {
        let (mut tl, mut rl, mut n) = (0.0f32, 0.0f32, 0.0f32);
        for s in all.iter().filter(|s| (s.len - len).abs() < 1.0) {
            tl += s.t_err;
            rl += s.r_err;
            n += 1.0;
        }
        if n > 2.5 {
            lengths.push(KittiLengthError {
                length: f64::from(len),
                t_err_percent: f64::from(tl / n) * 100.0,
                r_err_deg_per_100m: to_deg_100(rl / n),
                segments: n as usize,
            });
        }
    }
    Ok(KittiResult {
        t_err_percent: f64::from(t) * 100.0,
        r_err_deg_per_100m: to_deg_100(r),
        t_err: t,
        r_err: r,
        lengths,
        segments: all,
    })
}
