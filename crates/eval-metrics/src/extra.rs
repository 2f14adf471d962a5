//! The field's other trajectory metrics next to `e_align` in a batch: each run's APE, RPE
//! (evo's or the TUM scripts' definitions) and KITTI segment errors, as columns of
//! results.csv (`ape_rmse`, ..., `rpe_max`, `kitti_t_err`, `kitti_r_err`).

use serde::{Deserialize, Serialize};

use crate::align::{align_track, AlignOptions};
use crate::ape::{ape, ApeOptions};
use crate::association::{evo_pairs, SyncOptions};
use crate::evaluate::{BACKWARDS_DETECT_GAP, BACKWARDS_EPOCH};
use crate::kitti::kitti_errors;
use crate::pose::PoseTrack;
use crate::rpe::{rpe, RpeOptions};
use crate::stats::ErrorStats;
use crate::trajectory::Trajectory;
use crate::tum::{tum_ate, tum_rpe, TumAteOptions, TumRpeOptions};
use crate::MetricError;

/// One of the field's metrics, computed for every run of a batch.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "metric", rename_all = "snake_case")]
pub enum ExtraMetric {
    /// evo's APE: columns `ape_*`.
    Ape(ApeOptions),
    /// evo's RPE: columns `rpe_*`.
    Rpe(RpeOptions),
    /// The TUM RGB-D `evaluate_ate.py`: columns `ape_*`.
    TumAte(TumAteOptions),
    /// The TUM RGB-D `evaluate_rpe.py` (translational errors): columns `rpe_*`.
    TumRpe(TumRpeOptions),
    /// The KITTI devkit's segment errors over the associated poses (the estimate aligned
    /// first as given): columns `kitti_t_err` (percent) and `kitti_r_err` (deg per 100 m).
    Kitti(AlignOptions),
}

/// The APE columns of results.csv.
pub const APE_COLUMNS: [&str; 6] = [
    "ape_rmse",
    "ape_mean",
    "ape_median",
    "ape_std",
    "ape_min",
    "ape_max",
];

/// The RPE columns of results.csv.
pub const RPE_COLUMNS: [&str; 6] = [
    "rpe_rmse",
    "rpe_mean",
    "rpe_median",
    "rpe_std",
    "rpe_min",
    "rpe_max",
];

/// The KITTI columns of results.csv.
pub const KITTI_COLUMNS: [&str; 2] = ["kitti_t_err", "kitti_r_err"];

/// Every column an [`ExtraMetric`] may add, in the order results.csv writes them.
pub const EXTRA_COLUMNS: [&str; 14] = [
    "ape_rmse",
    "ape_mean",
    "ape_median",
    "ape_std",
    "ape_min",
    "ape_max",
    "rpe_rmse",
    "rpe_mean",
    "rpe_median",
    "rpe_std",
    "rpe_min",
    "rpe_max",
    "kitti_t_err",
    "kitti_r_err",
];

fn stats_values(s: &ErrorStats) -> Vec<f64> {
    vec![s.rmse, s.mean, s.median, s.std, s.min, s.max]
}

impl ExtraMetric {
    /// The columns it fills.
    pub fn columns(&self) -> &'static [&'static str] {
        match self {
            ExtraMetric::Ape(_) | ExtraMetric::TumAte(_) => &APE_COLUMNS,
            ExtraMetric::Rpe(_) | ExtraMetric::TumRpe(_) => &RPE_COLUMNS,
            ExtraMetric::Kitti(_) => &KITTI_COLUMNS,
        }
    }

    /// The values of its columns for one run.
    pub fn compute(
        &self,
        reference: &PoseTrack,
        estimate: &PoseTrack,
    ) -> Result<Vec<f64>, MetricError> {
        Ok(match self {
            ExtraMetric::Ape(o) => stats_values(&ape(reference, estimate, o)?.stats),
            ExtraMetric::Rpe(o) => stats_values(&rpe(reference, estimate, o)?.stats),
            ExtraMetric::TumAte(o) => stats_values(&tum_ate(reference, estimate, o)?.translational),
            ExtraMetric::TumRpe(o) => stats_values(&tum_rpe(reference, estimate, o)?.translational),
            ExtraMetric::Kitti(a) => {
                let (r, mut e) = evo_pairs(reference, estimate, &SyncOptions::default())?;
                align_track(&mut e, &r, a)?;
                let k = kitti_errors(&[(r, e)])?;
                vec![k.t_err_percent, k.r_err_deg_per_100m]
            }
        })
    }
}

/// An estimate of a batch as a track: sorted by time, timestamps `2e9 - t` of backwards runs
/// mapped back (as [`crate::evaluate`] does), given the ground truth's first stamp.
pub fn batch_track(est: &Trajectory, gt_first_time: f64) -> PoseTrack {
    let mut t = PoseTrack::from_trajectory(est);
    let Some(times) = t.times.as_mut() else {
        return t;
    };
    if let Some(&first) = times.iter().min_by(|a, b| a.total_cmp(b)) {
        if (first - gt_first_time).abs() > BACKWARDS_DETECT_GAP {
            for x in times.iter_mut() {
                *x = BACKWARDS_EPOCH - *x;
            }
        }
    }
    let mut order: Vec<usize> = (0..times.len()).collect();
    order.sort_by(|&a, &b| times[a].total_cmp(&times[b]));
    t.select(&order)
}
