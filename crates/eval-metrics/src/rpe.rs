//! The relative pose error (RPE) exactly as evo's `evo_rpe` defines it: pose pairs `(i, j)`
//! chosen by a delta in frames, metres travelled, or degrees / radians turned (on the
//! estimate's path, or the reference's with `pairs_from_reference`), consecutive or all
//! pairs, and the error pose `E = (Q_i^-1 Q_j)^-1 (P_i^-1 P_j)`: both motions compared in the
//! start frame of the pair.

use serde::{Deserialize, Serialize};

use crate::align::{align_track, AlignOptions, AlignTransform};
use crate::ape::{alignment_title, check_rotations, PoseRelation};
use crate::association::{evo_pairs, SyncOptions};
use crate::pose::{evo_rotation_angle, rotvec_angle, scipy_quaternion, PoseTrack};
use crate::stats::ErrorStats;
use crate::MetricError;

/// The unit of the RPE's delta (evo's `--delta_unit`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DeltaUnit {
    /// Poses (`f`).
    #[default]
    Frames,
    /// Metres travelled (`m`).
    Meters,
    /// Degrees turned (`d`).
    Degrees,
    /// Radians turned (`r`).
    Radians,
}

impl DeltaUnit {
    /// evo's name of the unit (`frames`, `m`, `deg`, `rad`).
    pub fn name(self) -> &'static str {
        match self {
            DeltaUnit::Frames => "frames",
            DeltaUnit::Meters => "m",
            DeltaUnit::Degrees => "deg",
            DeltaUnit::Radians => "rad",
        }
    }
}

/// RPE options: evo's `-r`, `-d/--delta`, `-u/--delta_unit`, `-t/--delta_tol`, `--all_pairs`,
/// `--pairs_from_reference` and the alignment and association options of APE.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct RpeOptions {
    /// What is measured.
    pub relation: PoseRelation,
    /// The distance between the poses of a pair.
    pub delta: f64,
    /// Its unit.
    pub delta_unit: DeltaUnit,
    /// Relative tolerance of the delta in all-pairs mode (evo: 0.1).
    pub delta_tol: f64,
    /// Every pair at the delta instead of consecutive ones.
    pub all_pairs: bool,
    /// Choose the pairs on the reference's path instead of the estimate's.
    pub pairs_from_reference: bool,
    /// How the estimate is aligned.
    pub align: AlignOptions,
    /// How poses are associated.
    pub sync: SyncOptions,
}

impl Default for RpeOptions {
    fn default() -> Self {
        RpeOptions {
            relation: PoseRelation::TransPart,
            delta: 1.0,
            delta_unit: DeltaUnit::Frames,
            delta_tol: 0.1,
            all_pairs: false,
            pairs_from_reference: false,
            align: AlignOptions::default(),
            sync: SyncOptions::default(),
        }
    }
}

/// The RPE of one run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RpeResult {
    /// The statistics of the errors.
    pub stats: ErrorStats,
    /// One error per pair.
    pub errors: Vec<f64>,
    /// The pose pairs `(i, j)`, indices into the associated tracks, one per error.
    pub pairs: Vec<(usize, usize)>,
    /// The associated reference poses.
    pub reference: PoseTrack,
    /// The associated estimated poses, aligned.
    pub estimate: PoseTrack,
    /// The alignment applied to the estimate.
    pub alignment: Option<AlignTransform>,
    /// evo's title of the result.
    pub title: String,
}

/// Pairs `(i, j)` at `delta` poses: consecutive `(0, d), (d, 2d), ...` or every `(i, i + d)`.
fn pairs_by_index(n: usize, delta: usize, all_pairs: bool) -> Vec<(usize, usize)> {
    if all_pairs {
        (0..n.saturating_sub(delta))
            .map(|i| (i, i + delta))
            .collect()
    } else {
        let ids: Vec<usize> = (0..n).step_by(delta).collect();
        ids.windows(2).map(|w| (w[0], w[1])).collect()
    }
}

/// Pairs by the distance travelled (evo's `filter_pairs_by_path`).
fn pairs_by_path(t: &PoseTrack, delta: f64, tol: f64, all_pairs: bool) -> Vec<(usize, usize)> {
    let n = t.len();
    let mut pairs = Vec::new();
    if all_pairs {
        let d = t.distances();
        for i in 0..n.saturating_sub(1) {
            // the first index of the smallest |d_j - d_i - delta| for j > i
            let mut best = i + 1;
            let mut best_v = f64::INFINITY;
            for (j, dj) in d.iter().enumerate().skip(i + 1) {
                let v = ((dj - d[i]) - delta).abs();
                if v < best_v {
                    best_v = v;
                    best = j;
                }
            }
            if best_v > tol {
                continue;
            }
            pairs.push((i, best));
        }
    } else {
        let mut ids = vec![0usize];
        let mut path = 0.0;
        for i in 1..n {
            path += (t.positions[i] - t.positions[i - 1]).norm();
            if path >= delta {
                ids.push(i);
                path = 0.0;
            }
        }
        pairs = ids.windows(2).map(|w| (w[0], w[1])).collect();
    }
    pairs
}

/// Pairs by the angle turned (evo's `filter_pairs_by_angle`): consecutive pairs by the angle
/// accumulated along the path, all pairs by the direct angle within the tolerance.
fn pairs_by_angle(
    t: &PoseTrack,
    delta_rad: f64,
    tol_rad: f64,
    all_pairs: bool,
) -> Vec<(usize, usize)> {
    let n = t.len();
    let mut pairs = Vec::new();
    if all_pairs {
        let (lo, hi) = (delta_rad - tol_rad, delta_rad + tol_rad);
        let quats: Vec<[f64; 4]> = t.rotations.iter().map(scipy_quaternion).collect();
        // The angle between unit quaternions p and q is 2 acos(|p.q|): a pair whose cosine
        // is clearly inside or outside [cos(hi / 2), cos(lo / 2)] is decided by it (3 ns
        // instead of 70); those within 1e-12 of a bound take evo's computation.
        let half_cos = |a: f64| (a.clamp(0.0, std::f64::consts::PI) / 2.0).cos();
        let (c_hi, c_lo) = (half_cos(hi), half_cos(lo));
        const MARGIN: f64 = 1e-12;
        for i in 0..n.saturating_sub(1) {
            let p = quats[i];
            let inv = [-p[0], -p[1], -p[2], p[3]];
            for (j, q) in quats.iter().enumerate().skip(i + 1) {
                let c = (p[0] * q[0] + p[1] * q[1] + p[2] * q[2] + p[3] * q[3]).abs();
                let keep = if lo > hi || c > c_lo + MARGIN || c < c_hi - MARGIN {
                    false
                } else if c < c_lo - MARGIN && c > c_hi + MARGIN {
                    true
                } else {
                    let a = rotvec_angle(compose_normalized(&inv, q));
                    lo <= a && a <= hi
                };
                if keep {
                    pairs.push((i, j));
                }
            }
        }
    } else {
        let mut acc = 0.0;
        let mut start = 0;
        for i in 0..n.saturating_sub(1) {
            let rel = t.rotations[i].transpose() * t.rotations[i + 1];
            acc += evo_rotation_angle(&rel);
            if acc >= delta_rad {
                pairs.push((start, i + 1));
                acc = 0.0;
                start = i + 1;
            }
        }
    }
    pairs
}

/// scipy's quaternion composition `p * q` (`x, y, z, w` order), normalised.
fn compose_normalized(p: &[f64; 4], q: &[f64; 4]) -> [f64; 4] {
    let cross = [
        p[1] * q[2] - p[2] * q[1],
        p[2] * q[0] - p[0] * q[2],
        p[0] * q[1] - p[1] * q[0],
    ];
    let r = [
        p[3] * q[0] + q[3] * p[0] + cross[0],
        p[3] * q[1] + q[3] * p[1] + cross[1],
        p[3] * q[2] + q[3] * p[2] + cross[2],
        p[3] * q[3] - p[0] * q[0] - p[1] * q[1] - p[2] * q[2],
    ];
    let n = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2] + r[3] * r[3]).sqrt();
    r.map(|v| v / n)
}

/// The pose pairs of an RPE as evo chooses them on `t`.
pub(crate) fn evo_pairs_from_delta(
    t: &PoseTrack,
    opts: &RpeOptions,
) -> Result<Vec<(usize, usize)>, MetricError> {
    let delta = opts.delta;
    if delta.is_nan() || delta < 0.0 || !delta.is_finite() {
        return Err(MetricError::Option(format!(
            "--delta must be a non-negative number, not {delta}"
        )));
    }
    let pairs = match opts.delta_unit {
        DeltaUnit::Frames => {
            if delta.fract() != 0.0 || delta < 1.0 {
                return Err(MetricError::Option(format!(
                    "--delta must be a whole number of frames of at least 1, not {delta}"
                )));
            }
            pairs_by_index(t.len(), delta as usize, opts.all_pairs)
        }
        DeltaUnit::Meters => pairs_by_path(t, delta, delta * opts.delta_tol, opts.all_pairs),
        DeltaUnit::Degrees | DeltaUnit::Radians => {
            let deg = opts.delta_unit == DeltaUnit::Degrees;
            let bound = if deg { 180.0 } else { std::f64::consts::PI };
            if delta > bound {
                return Err(MetricError::Option(format!(
                    "the delta angle must be within [0, {bound}], not {delta}"
                )));
            }
            let tol = delta * opts.delta_tol;
            let (d, tl) = if deg {
                // numpy's deg2rad multiplies by pi / 180, as to_radians does
                (delta.to_radians(), tol.to_radians())
            } else {
                (delta, tol)
            };
            check_rotations(t, "pair source")?;
            pairs_by_angle(t, d, tl, opts.all_pairs)
        }
    };
    if pairs.is_empty() {
        return Err(MetricError::NoPairs {
            delta,
            unit: opts.delta_unit.name(),
        });
    }
    Ok(pairs)
}

/// The relative pose error of `estimate` against `reference`, as `evo_rpe` computes it.
///
/// ```
/// use eval_metrics::{rpe, parse_tum, PoseTrack, RpeOptions};
///
/// // the estimate moves 1.1 m where the reference moves 1 m, every step
/// let mut gt = String::new();
/// let mut est = String::new();
/// for i in 0..10 {
///     gt += &format!("{i} {i} 0 0 0 0 0 1\n");
///     est += &format!("{i} {} 0 0 0 0 0 1\n", 1.1 * i as f64);
/// }
/// let (gt, est) = (PoseTrack::from_trajectory(&parse_tum(&gt)?),
///                  PoseTrack::from_trajectory(&parse_tum(&est)?));
/// let r = rpe(&gt, &est, &RpeOptions::default())?; // delta 1 frame, consecutive pairs
/// assert_eq!(r.stats.n, 9);
/// assert!((r.stats.mean - 0.1).abs() < 1e-12);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn rpe(
    reference: &PoseTrack,
    estimate: &PoseTrack,
    opts: &RpeOptions,
) -> Result<RpeResult, MetricError> {
    let (reference, mut estimate) = evo_pairs(reference, estimate, &opts.sync)?;
    let alignment = align_track(&mut estimate, &reference, &opts.align)?;
    if opts.relation.needs_angles() {
        check_rotations(&reference, "reference")?;
        check_rotations(&estimate, "estimate")?;
    }
    let source = if opts.pairs_from_reference {
        &reference
    } else {
        &estimate
    };
    let mut pairs = evo_pairs_from_delta(source, opts)?;
    let errors: Vec<f64> = match opts.relation {
        PoseRelation::PointDistance | PoseRelation::PointDistanceErrorRatio => {
            let mut errors = Vec::with_capacity(pairs.len());
            let mut kept = Vec::with_capacity(pairs.len());
            for &(i, j) in &pairs {
                let dr = (reference.positions[i] - reference.positions[j]).norm();
                let de = (estimate.positions[i] - estimate.positions[j]).norm();
                let e = (dr - de).abs();
                if opts.relation == PoseRelation::PointDistance {
                    errors.push(e);
                    kept.push((i, j));
                } else if dr != 0.0 {
                    errors.push(e / dr * 100.0);
                    kept.push((i, j));
                }
            }
            pairs = kept;
            errors
        }
        rel => pairs
            .iter()
            .map(|&(i, j)| {
                let q_rel = reference.pose(i).relative(&reference.pose(j));
                let p_rel = estimate.pose(i).relative(&estimate.pose(j));
                rel.of_pose(&q_rel.relative(&p_rel))
            })
            .collect(),
    };
    let stats = ErrorStats::of(&errors).ok_or(MetricError::NoPairs {
        delta: opts.delta,
        unit: opts.delta_unit.name(),
    })?;
    let delta_text = if opts.delta_unit == DeltaUnit::Frames {
        format!("{}", opts.delta as i64)
    } else {
        format!("{:?}", opts.delta)
    };
    let title = format!(
        "RPE w.r.t. {} ({})\nfor delta = {} ({}) using {} pairs{}",
        opts.relation.description(),
        opts.relation.unit(),
        delta_text,
        opts.delta_unit.name(),
        if opts.all_pairs { "all" } else { "consecutive" },
        alignment_title(&opts.align)
    );
    Ok(RpeResult {
        stats,
        errors,
        pairs,
        reference,
        estimate,
        alignment,
        title,
    })
}
