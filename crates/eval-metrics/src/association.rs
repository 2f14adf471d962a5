//! Pairing the poses of two trajectories by time, as each reference does it.
//!
//! * evo ([`evo_sync`]): every pose of the trajectory with fewer poses takes the nearest stamp
//!   of the other within `max_diff` (not one-to-one: two poses may take the same partner);
//!   with [`SyncMethod::Interpolation`] the denser trajectory is interpolated at the stamps of
//!   the matched poses instead (positions linearly, orientations by slerp).
//! * TUM RGB-D `associate.py` ([`tum_associate`]): greedy one-to-one, the closest candidate
//!   pairs (difference strictly below `max_difference`) first.
//! * TUM RGB-D `evaluate_rpe.py` ([`find_closest_index`]): its binary search for the nearest
//!   stamp.

use nalgebra::{Quaternion, Vector3};
use serde::{Deserialize, Serialize};

use crate::pose::{quaternion_matrix, PoseTrack, EPS4};
use crate::MetricError;

/// How evo pairs two stamped trajectories (`--sync_method`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SyncMethod {
    /// The nearest stamp within `max_diff` (evo's default).
    #[default]
    NearestTime,
    /// The matched stamps of the sparser trajectory, the denser one interpolated there.
    Interpolation,
}

/// evo's time association options.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct SyncOptions {
    /// Largest time difference of a pair in seconds (`--t_max_diff`, default 0.01).
    pub max_diff: f64,
    /// Added to the estimate's stamps before pairing (`--t_offset`, default 0).
    pub offset: f64,
    /// Nearest stamp or interpolation (`--sync_method`).
    pub method: SyncMethod,
    /// Only reference poses at or after this time (`--t_start`).
    pub t_start: Option<f64>,
    /// Only reference poses at or before this time (`--t_end`).
    pub t_end: Option<f64>,
}

impl Default for SyncOptions {
    fn default() -> Self {
        SyncOptions {
            max_diff: 0.01,
            offset: 0.0,
            method: SyncMethod::NearestTime,
            t_start: None,
            t_end: None,
        }
    }
}

/// For each stamp of `stamps_1`, the nearest of `stamps_2 + offset` within `max_diff`, as
/// evo's `matching_time_indices`: a binary search when `stamps_2` is sorted (ties go to the
/// earlier stamp), a linear search for the first minimum otherwise. Returns the matched
/// indices into both lists.
pub fn matching_time_indices(
    stamps_1: &[f64],
    stamps_2: &[f64],
    max_diff: f64,
    offset: f64,
) -> (Vec<usize>, Vec<usize>) {
    let s2: Vec<f64> = stamps_2.iter().map(|t| t + offset).collect();
    let mut m1 = Vec::with_capacity(stamps_1.len());
    let mut m2 = Vec::with_capacity(stamps_1.len());
    if s2.is_empty() {
        return (m1, m2);
    }
    let sorted = s2.windows(2).all(|w| w[1] - w[0] >= 0.0);
    if !sorted {
        for (i, &t) in stamps_1.iter().enumerate() {
            let mut best = 0;
            let mut best_d = f64::NAN;
            for (j, &u) in s2.iter().enumerate() {
                let d = (u - t).abs();
                // numpy's argmin: the first minimum, NaN wins
                if j == 0 || d < best_d || (d.is_nan() && !best_d.is_nan()) {
                    best = j;
                    best_d = d;
                }
            }
            if best_d <= max_diff {
                m1.push(i);
                m2.push(best);
            }
        }
        return (m1, m2);
    }
    let (first, last) = (s2[0], s2[s2.len() - 1]);
    // sorted stamps_1 (the usual case) walk s2 once instead of a binary search each: the same
    // insertion points
    let walk = stamps_1.windows(2).all(|w| w[1] >= w[0]);
    let mut cursor = 0;
    for (i, &t) in stamps_1.iter().enumerate() {
        if t < first - max_diff || t > last + max_diff {
            continue;
        }
        let mut k = if walk {
            while cursor < s2.len() && s2[cursor] <= t {
                cursor += 1;
            }
            cursor
        } else {
            s2.partition_point(|&x| x <= t)
        };
        if k >= s2.len() {
            k = s2.len() - 1;
        }
        let diff_ub = s2[k] - t;
        let diff_lb = if k > 0 { t - s2[k - 1] } else { f64::INFINITY };
        let best = if diff_ub <= max_diff && diff_ub < diff_lb {
            k
        } else if diff_lb <= max_diff && diff_lb <= diff_ub {
            k - 1
        } else {
            continue;
        };
        m1.push(i);
        m2.push(best);
    }
    (m1, m2)
}

/// Pairs a reference and an estimate by time as evo's `associate_trajectories` does: the
/// trajectory with fewer poses (the estimate when both have as many) keeps each pose that
/// has a partner; the other is reduced to the partners, or interpolated at their stamps.
/// Returns `(reference, estimate)` with equally many poses.
pub fn evo_sync(
    reference: &PoseTrack,
    estimate: &PoseTrack,
    opts: &SyncOptions,
) -> Result<(PoseTrack, PoseTrack), MetricError> {
    let (Some(t_ref), Some(t_est)) = (&reference.times, &estimate.times) else {
        return Err(MetricError::Unstamped);
    };
    let second_longer = estimate.len() > reference.len();
    let (short, long, t_short, t_long, offset) = if second_longer {
        (reference, estimate, t_ref, t_est, opts.offset)
    } else {
        (estimate, reference, t_est, t_ref, -opts.offset)
    };
    let (ms, ml) = matching_time_indices(t_short, t_long, opts.max_diff, offset);
    if ms.is_empty() {
        return Err(MetricError::NoMatches {
            max_diff: opts.max_diff,
            offset: opts.offset,
        });
    }
    let short = short.select(&ms);
    let long = match opts.method {
        SyncMethod::NearestTime => long.select(&ml),
        SyncMethod::Interpolation => {
            let at: Vec<f64> = short.times.iter().flatten().map(|t| t - offset).collect();
            interpolate(long, &at)?
        }
    };
    Ok(if second_longer {
        (short, long)
    } else {
        (long, short)
    })
}

/// The pose pairs evo measures: two stamped tracks are associated by [`evo_sync`] (the
/// reference first cut to `t_start..=t_end` when either is given and not zero, as evo does);
/// when either track has no stamps (a KITTI pose file), poses pair by line and the counts must
/// agree. Non-finite poses are refused (evo would return NaN statistics).
pub fn evo_pairs(
    reference: &PoseTrack,
    estimate: &PoseTrack,
    opts: &SyncOptions,
) -> Result<(PoseTrack, PoseTrack), MetricError> {
    for (which, t) in [("reference", reference), ("estimate", estimate)] {
        if t.is_empty() {
            return Err(MetricError::Empty(which));
        }
        if let Some(index) = t.first_non_finite() {
            return Err(MetricError::NonFinite { which, index });
        }
    }
    if !(reference.is_stamped() && estimate.is_stamped()) {
        if reference.len() != estimate.len() {
            return Err(MetricError::LengthMismatch {
                reference: reference.len(),
                estimate: estimate.len(),
            });
        }
        return Ok((reference.clone(), estimate.clone()));
    }
    let nonzero = |v: Option<f64>| v.is_some_and(|x| x != 0.0);
    if !(nonzero(opts.t_start) || nonzero(opts.t_end)) {
        return evo_sync(reference, estimate, opts);
    }
    let reference = {
        let times = reference.times.as_deref().unwrap_or_default();
        let lo = opts.t_start.unwrap_or(times[0]);
        let hi = opts.t_end.unwrap_or(times[times.len() - 1]);
        if lo > hi {
            return Err(MetricError::Option(format!(
                "--t_start {lo} is after --t_end {hi}"
            )));
        }
        let ids: Vec<usize> = (0..times.len())
            .filter(|&i| times[i] >= lo && times[i] <= hi)
            .collect();
        if ids.is_empty() {
            return Err(MetricError::Empty("reference within --t_start..--t_end"));
        }
        reference.select(&ids)
    };
    evo_sync(&reference, estimate, opts)
}

/// Interpolates a stamped track at `times` as evo's `PoseTrajectory3D.interpolate` does:
/// positions linearly, orientations by slerp, times outside the track clamped to its ends.
pub fn interpolate(track: &PoseTrack, times: &[f64]) -> Result<PoseTrack, MetricError> {
    let Some(ts) = &track.times else {
        return Err(MetricError::Unstamped);
    };
    let n = ts.len();
    if n < 2 {
        return Err(MetricError::TooFewToInterpolate(n));
    }
    let mut out = PoseTrack {
        times: Some(times.to_vec()),
        positions: Vec::with_capacity(times.len()),
        rotations: Vec::with_capacity(times.len()),
        quaternions: Vec::with_capacity(times.len()),
    };
    for &t in times {
        let idx = ts.partition_point(|&x| x < t).clamp(1, n - 1);
        let (t0, t1) = (ts[idx - 1], ts[idx]);
        let dt = t1 - t0;
        let frac = if dt > 0.0 {
            ((t - t0) / dt).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let (p0, p1) = (track.positions[idx - 1], track.positions[idx]);
        let p: Vector3<f64> = p0 + (p1 - p0) * frac;
        let q = slerp(&track.quaternions[idx - 1], &track.quaternions[idx], frac);
        out.positions.push(p);
        out.rotations.push(quaternion_matrix(&q));
        out.quaternions.push(q);
    }
    Ok(out)
}

/// Spherical linear interpolation of two quaternions of any norm (normalised first), the
/// shortest way, as `transformations.quaternion_slerp` computes it.
pub fn slerp(a: &Quaternion<f64>, b: &Quaternion<f64>, fraction: f64) -> Quaternion<f64> {
    let unit = |q: &Quaternion<f64>| {
        let c = q.coords;
        // w, x, y, z order as the reference sums them
        let n = (q.w * q.w + c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt();
        Quaternion::new(q.w / n, c[0] / n, c[1] / n, c[2] / n)
    };
    let q0 = unit(a);
    let mut q1 = unit(b);
    if fraction == 0.0 {
        return q0;
    }
    if fraction == 1.0 {
        return q1;
    }
    let mut d = q0.w * q1.w + q0.i * q1.i + q0.j * q1.j + q0.k * q1.k;
    if (d.abs() - 1.0).abs() < EPS4 {
        return q0;
    }
    if d < 0.0 {
        d = -d;
        q1 = -q1;
    }
    let angle = d.acos();
    if angle.abs() < EPS4 {
        return q0;
    }
    let isin = 1.0 / angle.sin();
    let s0 = ((1.0 - fraction) * angle).sin() * isin;
    let s1 = (fraction * angle).sin() * isin;
    Quaternion::new(
        q0.w * s0 + q1.w * s1,
        q0.i * s0 + q1.i * s1,
        q0.j * s0 + q1.j * s1,
        q0.k * s0 + q1.k * s1,
    )
}

/// Greedy one-to-one association of two sorted lists of distinct stamps, as the TUM RGB-D
/// `associate.py` (and rpg_trajectory_evaluation) do: every pair with
/// `|a - (b + offset)| < max_difference` is a candidate, candidates are taken by increasing
/// difference (then by `a`, then by `b`) while both stamps are free. Returns index pairs
/// `(i_first, i_second)` sorted by the first.
pub fn tum_associate(
    first: &[f64],
    second: &[f64],
    offset: f64,
    max_difference: f64,
) -> Vec<(usize, usize)> {
    let mut candidates: Vec<(f64, usize, usize)> = Vec::new();
    for (jb, &b) in second.iter().enumerate() {
        let c = b + offset;
        // a window a little wider than the tolerance, then the exact test
        let lo = first.partition_point(|&a| a < c - max_difference * 1.5 - 1e-9);
        for (ia, &a) in first.iter().enumerate().skip(lo) {
            if a > c + max_difference * 1.5 + 1e-9 {
                break;
            }
            let d = (a - c).abs();
            if d < max_difference {
                candidates.push((d, ia, jb));
            }
        }
    }
    // the stamps are sorted, so ordering by index is ordering by value
    candidates.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)).then(x.2.cmp(&y.2)));
    let mut used_a = vec![false; first.len()];
    let mut used_b = vec![false; second.len()];
    let mut matches = Vec::new();
    for (_, ia, jb) in candidates {
        if !used_a[ia] && !used_b[jb] {
            used_a[ia] = true;
            used_b[jb] = true;
            matches.push((ia, jb));
        }
    }
    matches.sort_unstable();
    matches
}

/// The index of the stamp of a sorted list closest to `t`, found as `evaluate_rpe.py`'s
/// `find_closest_index` finds it: a binary search that keeps the best of the visited
/// elements (the first visited wins a tie) and stops at an exact hit.
pub fn find_closest_index(list: &[f64], t: f64) -> usize {
    let Some(&first) = list.first() else {
        return 0;
    };
    let mut beginning = 0usize;
    let mut difference = (first - t).abs();
    let mut best = 0usize;
    let mut end = list.len();
    while beginning < end {
        let middle = (end + beginning) / 2;
        let d = (list[middle] - t).abs();
        if d < difference {
            difference = d;
            best = middle;
        }
        if t == list[middle] {
            return middle;
        } else if list[middle] > t {
            end = middle;
        } else {
            beginning = middle + 1;
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_stamps_are_not_one_to_one() {
        let (a, b) =
            matching_time_indices(&[0.0, 0.004, 1.0, 2.0], &[0.001, 1.02, 2.005], 0.01, 0.0);
        assert_eq!(a, [0, 1, 3]);
        assert_eq!(b, [0, 0, 2]);
        // a tie between two neighbours goes to the earlier one
        let (_, b) = matching_time_indices(&[1.0], &[0.5, 1.5], 1.0, 0.0);
        assert_eq!(b, [0]);
    }

    #[test]
    fn greedy_association_is_one_to_one() {
        let m = tum_associate(&[0.0, 0.01, 0.02], &[0.004, 0.0061], 0.0, 0.02);
        assert_eq!(m, [(0, 0), (1, 1)]);
    }

    #[test]
    fn closest_index_agrees_with_a_linear_search() {
        let list: Vec<f64> = (0..37)
            .map(|i| (i as f64 * 0.37).sin() * 0.1 + i as f64)
            .collect();
        for k in -10..400 {
            let t = k as f64 * 0.1 - 1.0;
            let i = find_closest_index(&list, t);
            let d = (list[i] - t).abs();
            assert!(list.iter().all(|x| (x - t).abs() >= d), "{t}");
        }
    }

    #[test]
    fn slerp_halves_the_angle() {
        let a = Quaternion::new(1.0, 0.0, 0.0, 0.0);
        let b = Quaternion::new(0.0, 0.0, 0.0, 2.0);
        let m = slerp(&a, &b, 0.5);
        let h = std::f64::consts::FRAC_1_SQRT_2;
        assert!((m.w - h).abs() < 1e-15 && (m.k - h).abs() < 1e-15);
    }
}
