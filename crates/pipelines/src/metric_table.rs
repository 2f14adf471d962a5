//! The `[ape]`, `[rpe]` and `[kitti]` tables of an experiment manifest: the field's other
//! metrics to compute next to e_align, with evo's option names (`monovo ape --help`).
//!
//! ```toml
//! [ape]                      # APE columns ape_rmse, ape_mean, ... (evo_ape)
//! align = "sim3"             # none, se3, sim3, scale, posyaw, origin (-a, -as, -s, ...)
//! pose_relation = "trans_part"
//!
//! [rpe]                      # RPE columns rpe_rmse, ... (evo_rpe; tum = true: evaluate_rpe.py)
//! align = "sim3"
//! delta = 1
//! delta_unit = "m"           # f, m, d, r (and s with tum = true)
//!
//! [kitti]                    # kitti_t_err (%), kitti_r_err (deg/100m) over the associated poses
//! align = "sim3"
//! ```

use eval_metrics::{ExtraMetric, PoseRelation, SyncMethod};
use serde::Deserialize;

use crate::metric_args::{MetricArgs, Spelling};

/// One metric table of a manifest.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MetricTable {
    /// The TUM RGB-D scripts' definitions instead of evo's.
    #[serde(default)]
    pub tum: bool,
    /// `none`, `se3`, `sim3`, `scale`, `posyaw` or `origin`.
    pub align: Option<String>,
    /// Align with the first N pose pairs.
    pub n_to_align: Option<usize>,
    /// evo's pose relation.
    pub pose_relation: Option<PoseRelation>,
    /// Association tolerance, seconds.
    pub t_max_diff: Option<f64>,
    /// Added to the estimate's stamps, seconds.
    pub t_offset: Option<f64>,
    /// `nearest_time` or `interpolation`.
    pub sync_method: Option<SyncMethod>,
    /// RPE: the delta.
    pub delta: Option<f64>,
    /// RPE: `f`, `m`, `d`, `r` (`s` with `tum`).
    pub delta_unit: Option<String>,
    /// RPE: the relative tolerance of all pairs.
    pub delta_tol: Option<f64>,
    /// RPE: all pairs.
    #[serde(default)]
    pub all_pairs: bool,
    /// RPE: pairs on the reference's path.
    #[serde(default)]
    pub pairs_from_reference: bool,
    /// TUM RPE: at most this many pairs.
    pub max_pairs: Option<usize>,
    /// TUM: a fixed factor for the estimate.
    pub scale: Option<f64>,
}

impl MetricTable {
    /// The table as the options of `monovo ape/rpe/kitti` (`align = "sim3"` is `-as`).
    pub fn args(&self) -> Result<MetricArgs, String> {
        let mut a = MetricArgs::default();
        match self.align.as_deref().unwrap_or("none") {
            "none" => {}
            "se3" => a.align = true,
            "sim3" => (a.align, a.correct_scale) = (true, true),
            "scale" => a.correct_scale = true,
            "posyaw" => a.posyaw = true,
            "origin" => a.align_origin = true,
            other => {
                return Err(format!(
                    "align = \"{other}\": expected none, se3, sim3, scale, posyaw or origin"
                ))
            }
        }
        if let Some(n) = self.n_to_align {
            a.n_to_align = i64::try_from(n).unwrap_or(i64::MAX);
        }
        a.tum = self.tum;
        a.pose_relation = self.pose_relation.unwrap_or_default();
        a.t_max_diff = self.t_max_diff;
        a.t_offset = self.t_offset.unwrap_or(0.0);
        a.sync_method = self.sync_method.unwrap_or_default();
        a.delta = self.delta.unwrap_or(a.delta);
        a.delta_unit = self.delta_unit.as_deref().map(str::parse).transpose()?;
        a.delta_tol = self.delta_tol.unwrap_or(a.delta_tol);
        a.all_pairs = self.all_pairs;
        a.pairs_from_reference = self.pairs_from_reference;
        a.max_pairs = self.max_pairs;
        a.scale = self.scale;
        Ok(a)
    }

    /// The `[ape]` table's metric.
    pub fn ape(&self) -> Result<ExtraMetric, String> {
        self.args()?.ape(Spelling::Names)
    }

    /// The `[rpe]` table's metric.
    pub fn rpe(&self) -> Result<ExtraMetric, String> {
        self.args()?.rpe(Spelling::Names)
    }

    /// The `[kitti]` table's metric.
    pub fn kitti(&self) -> Result<ExtraMetric, String> {
        self.args()?.kitti(Spelling::Names)
    }
}
