//! The TUM RGB-D benchmark's own definitions (Sturm et al. 2012; `evaluate_ate.py` and
//! `evaluate_rpe.py`), each step as the scripts take it:
//!
//! * ATE ([`tum_ate`]): greedy one-to-one association within `max_difference` (0.02 s), the
//!   estimate scaled by a fixed factor, Horn's closed-form SE(3) alignment (never a scale),
//!   the distances between the aligned positions.
//! * RPE ([`tum_rpe`]): pairs `(i, j)` of estimated poses `delta` apart (seconds by default,
//!   or metres, radians, degrees, frames along the estimate; a pair ending at the last pose is
//!   dropped), each pose given the nearest ground-truth stamp (skipped beyond twice the median
//!   ground-truth interval), and the error `dP dQ^-1` with `dP = P_i^-1 P_j`,
//!   `dQ = Q_i^-1 Q_j`: the motions compared in the end frame, where evo compares them in the
//!   start frame. Without a fixed delta every pair is compared, 10,000 random ones (Python 2's
//!   generator, seed 0) beyond 100 poses.
//!
//! A trajectory is read as the scripts read it: one pose per distinct stamp (the last line
//! wins), sorted by time, lines with NaN skipped.

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::align::AlignTransform;
use crate::association::{find_closest_index, tum_associate};
use crate::pose::{PoseTrack, Se3};
use crate::pyrandom::PyRandom;
use crate::sim3::umeyama;
use crate::stats::ErrorStats;
use crate::MetricError;

/// Options of `evaluate_ate.py`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct TumAteOptions {
    /// Largest time difference of an associated pair, exclusive (`--max_difference`, 0.02 s).
    pub max_difference: f64,
    /// Added to the estimate's stamps (`--offset`).
    pub offset: f64,
    /// Fixed factor applied to the estimate's positions (`--scale`).
    pub scale: f64,
}

impl Default for TumAteOptions {
    fn default() -> Self {
        TumAteOptions {
            max_difference: 0.02,
            offset: 0.0,
            scale: 1.0,
        }
    }
}

/// The unit of `evaluate_rpe.py`'s delta.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TumDeltaUnit {
    /// Seconds (`s`, the default).
    #[default]
    Seconds,
    /// Metres travelled by the estimate (`m`).
    Meters,
    /// Radians turned by the estimate (`rad`).
    Radians,
    /// Degrees turned by the estimate (`deg`).
    Degrees,
    /// Poses (`f`).
    Frames,
}

/// Options of `evaluate_rpe.py`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct TumRpeOptions {
    /// Pairs `delta` apart (`--fixed_delta`); otherwise all pairs.
    pub fixed_delta: bool,
    /// The delta (`--delta`, 1).
    pub delta: f64,
    /// Its unit (`--delta_unit`).
    pub delta_unit: TumDeltaUnit,
    /// At most this many pairs, drawn at random beyond (`--max_pairs`, 10,000; 0: all).
    pub max_pairs: usize,
    /// Added to the estimate's stamps (`--offset`).
    pub offset: f64,
    /// Fixed factor applied to the estimate's motions (`--scale`).
    pub scale: f64,
}

impl Default for TumRpeOptions {
    fn default() -> Self {
        TumRpeOptions {
            fixed_delta: true,
            delta: 1.0,
            delta_unit: TumDeltaUnit::Seconds,
            max_pairs: 10_000,
            offset: 0.0,
            scale: 1.0,
        }
    }
}

/// The result of a TUM RGB-D evaluation.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TumResult {
    /// Statistics of the translational errors (`absolute_translational_error.*` or
    /// `translational_error.*`), in the trajectory's unit.
    pub translational: ErrorStats,
    /// RPE only: statistics of the rotational errors in degrees (`rotational_error.*`).
    pub rotational_deg: Option<ErrorStats>,
    /// The translational errors.
    pub translational_errors: Vec<f64>,
    /// RPE only: the rotational errors in radians.
    pub rotational_errors: Vec<f64>,
    /// The estimate's stamp of each error (the first pose of an RPE pair).
    pub stamps: Vec<f64>,
    /// ATE: the associated ground-truth positions.
    pub reference_positions: Vec<Vector3<f64>>,
    /// ATE: the associated estimated positions, scaled and aligned.
    pub estimate_positions: Vec<Vector3<f64>>,
    /// ATE: Horn's alignment of the estimate.
    pub alignment: Option<AlignTransform>,
}

/// A trajectory as the TUM scripts hold it: sorted distinct stamps and their poses.
struct StampedPoses {
    stamps: Vec<f64>,
    poses: Vec<Se3>,
}

impl StampedPoses {
    /// One pose per distinct stamp (the last line wins), sorted, NaN lines skipped.
    fn of(t: &PoseTrack, which: &'static str) -> Result<StampedPoses, MetricError> {
        let Some(times) = &t.times else {
            return Err(MetricError::Unstamped);
        };
        let mut rows: Vec<(f64, usize)> = (0..t.len())
            .filter(|&i| {
                times[i].is_finite()
                    && t.positions[i].iter().all(|v| v.is_finite())
                    && t.rotations[i].iter().all(|v| v.is_finite())
            })
            .map(|i| (times[i], i))
            .collect();
        // stable: equal stamps keep file order, and the last of them wins
        rows.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut out = StampedPoses {
            stamps: Vec::with_capacity(rows.len()),
            poses: Vec::with_capacity(rows.len()),
        };
        for (s, i) in rows {
            if out.stamps.last() == Some(&s) {
                if let Some(last) = out.poses.last_mut() {
                    *last = t.pose(i);
                }
            } else {
                out.stamps.push(s);
                out.poses.push(t.pose(i));
            }
        }
        if out.stamps.is_empty() {
            return Err(MetricError::Empty(which));
        }
        Ok(out)
    }
}

/// The absolute trajectory error as `evaluate_ate.py` computes it.
pub fn tum_ate(
    reference: &PoseTrack,
    estimate: &PoseTrack,
    opts: &TumAteOptions,
) -> Result<TumResult, MetricError> {
    let g = StampedPoses::of(reference, "reference")?;
    let e = StampedPoses::of(estimate, "estimate")?;
    let matches = tum_associate(&g.stamps, &e.stamps, opts.offset, opts.max_difference);
    if matches.len() < 2 {
        return Err(MetricError::TooFewPairs(matches.len()));
    }
    let first: Vec<Vector3<f64>> = matches
        .iter()
        .map(|&(a, _)| g.poses[a].translation)
        .collect();
    let second: Vec<Vector3<f64>> = matches
        .iter()
        .map(|&(_, b)| e.poses[b].translation * opts.scale)
        .collect();
    let fit = umeyama(&second, &first, false).map_err(MetricError::Align)?;
    let r = *fit.rotation.matrix();
    let aligned: Vec<Vector3<f64>> = second.iter().map(|p| r * p + fit.translation).collect();
    let errors: Vec<f64> = aligned
        .iter()
        .zip(&first)
        .map(|(a, f)| (a - f).norm())
        .collect();
    let translational = ErrorStats::of(&errors).ok_or(MetricError::TooFewPairs(0))?;
    Ok(TumResult {
        translational,
        rotational_deg: None,
        translational_errors: errors,
        rotational_errors: Vec::new(),
        stamps: matches.iter().map(|&(_, b)| e.stamps[b]).collect(),
        reference_positions: first,
        estimate_positions: aligned,
        alignment: Some(AlignTransform {
            scale: 1.0,
            rotation: r,
            translation: fit.translation,
        }),
    })
}

/// `arccos(clamp((trace(R) - 1) / 2))`, the scripts' rotation angle.
fn arccos_angle(e: &Se3) -> f64 {
    let r = &e.rotation;
    (((r[(0, 0)] + r[(1, 1)] + r[(2, 2)]) - 1.0) / 2.0)
        .clamp(-1.0, 1.0)
        .acos()
}

/// The position along the estimate that the delta is measured in (`index_est`).
fn delta_index(e: &StampedPoses, unit: TumDeltaUnit) -> Vec<f64> {
    let along = |f: &dyn Fn(&Se3) -> f64| {
        let mut out = vec![0.0];
        let mut sum = 0.0;
        for w in e.poses.windows(2) {
            sum += f(&w[1].relative(&w[0]));
            out.push(sum);
        }
        out
    };
    match unit {
        TumDeltaUnit::Seconds => e.stamps.clone(),
        TumDeltaUnit::Frames => (0..e.poses.len()).map(|i| i as f64).collect(),
        TumDeltaUnit::Meters => along(&|m| m.translation.norm()),
        TumDeltaUnit::Radians => along(&arccos_angle),
        TumDeltaUnit::Degrees => along(&|m| arccos_angle(m) * (180.0 / std::f64::consts::PI)),
    }
}

/// The pairs `evaluate_rpe.py` compares (indices into the estimate).
fn tum_pairs(e: &StampedPoses, opts: &TumRpeOptions) -> Vec<(usize, usize)> {
    let n = e.poses.len();
    let mut rng = PyRandom::new(0);
    if !opts.fixed_delta {
        if opts.max_pairs == 0 || (n as f64) < (opts.max_pairs as f64).sqrt() {
            return (0..n).flat_map(|i| (0..n).map(move |j| (i, j))).collect();
        }
        return (0..opts.max_pairs)
            .map(|_| {
                let i = rng.randint(0, n - 1);
                let j = rng.randint(0, n - 1);
                (i, j)
            })
            .collect();
    }
    let index = delta_index(e, opts.delta_unit);
    let mut pairs: Vec<(usize, usize)> = (0..n)
        .filter_map(|i| {
            let j = find_closest_index(&index, index[i] + opts.delta);
            (j != n - 1).then_some((i, j))
        })
        .collect();
    if opts.max_pairs != 0 && pairs.len() > opts.max_pairs {
        pairs = rng.sample(&pairs, opts.max_pairs);
    }
    pairs
}

/// numpy's median of a list (the mean of the two middle values for an even count).
fn median(v: &[f64]) -> f64 {
    ErrorStats::of(v).map_or(f64::NAN, |s| s.median)
}

/// The relative pose error as `evaluate_rpe.py` computes it.
pub fn tum_rpe(
    reference: &PoseTrack,
    estimate: &PoseTrack,
    opts: &TumRpeOptions,
) -> Result<TumResult, MetricError> {
    let g = StampedPoses::of(reference, "reference")?;
    let e = StampedPoses::of(estimate, "estimate")?;
    let off = opts.offset;
    // the scripts' overlap check: distinct estimated stamps that are each other's nearest
    let mut returned: Vec<usize> = e
        .stamps
        .iter()
        .map(|&t| {
            let t_gt = g.stamps[find_closest_index(&g.stamps, t + off)];
            find_closest_index(&e.stamps, t_gt - off)
        })
        .collect();
    returned.sort_unstable();
    returned.dedup();
    if returned.len() < 2 {
        return Err(MetricError::TooFewPairs(returned.len()));
    }
    let pairs = tum_pairs(&e, opts);
    let intervals: Vec<f64> = g.stamps.windows(2).map(|w| w[1] - w[0]).collect();
    let max_dt = 2.0 * median(&intervals);
    let mut trans = Vec::with_capacity(pairs.len());
    let mut rot = Vec::with_capacity(pairs.len());
    let mut stamps = Vec::with_capacity(pairs.len());
    for (i, j) in pairs {
        let (s0, s1) = (e.stamps[i], e.stamps[j]);
        let g0 = find_closest_index(&g.stamps, s0 + off);
        let g1 = find_closest_index(&g.stamps, s1 + off);
        if (g.stamps[g0] - (s0 + off)).abs() > max_dt || (g.stamps[g1] - (s1 + off)).abs() > max_dt
        {
            continue;
        }
        // ominus(a, b) = a^-1 b; the estimate's motion scaled, then compared
        let mut de = e.poses[j].relative(&e.poses[i]);
        de.translation *= opts.scale;
        let dg = g.poses[g1].relative(&g.poses[g0]);
        let err = de.relative(&dg);
        trans.push(err.translation.norm());
        rot.push(arccos_angle(&err));
        stamps.push(s0);
    }
    if trans.len() < 2 {
        return Err(MetricError::TooFewPairs(trans.len()));
    }
    let translational = ErrorStats::of(&trans).ok_or(MetricError::TooFewPairs(0))?;
    let r = ErrorStats::of(&rot).ok_or(MetricError::TooFewPairs(0))?;
    // the script converts each statistic as `value * 180.0 / pi`
    let deg = |v: f64| v * 180.0 / std::f64::consts::PI;
    let rotational_deg = ErrorStats {
        rmse: deg(r.rmse),
        mean: deg(r.mean),
        median: deg(r.median),
        std: deg(r.std),
        min: deg(r.min),
        max: deg(r.max),
        sse: deg(deg(r.sse)),
        n: r.n,
    };
    Ok(TumResult {
        translational,
        rotational_deg: Some(rotational_deg),
        translational_errors: trans,
        rotational_errors: rot,
        stamps,
        reference_positions: Vec::new(),
        estimate_positions: Vec::new(),
        alignment: None,
    })
}
