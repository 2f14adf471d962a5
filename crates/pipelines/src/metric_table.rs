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

use eval_metrics::{
    AlignMode, AlignOptions, ApeOptions, DeltaUnit, ExtraMetric, PoseRelation, RpeOptions,
    SyncMethod, SyncOptions, TumAteOptions, TumDeltaUnit, TumRpeOptions,
};
use serde::Deserialize;

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

fn align_options(t: &MetricTable) -> Result<AlignOptions, String> {
    let (mode, origin) = match t.align.as_deref().unwrap_or("none") {
        "none" => (AlignMode::None, false),
        "se3" => (AlignMode::Se3, false),
        "sim3" => (AlignMode::Sim3, false),
        "scale" => (AlignMode::Scale, false),
        "posyaw" => (AlignMode::PosYaw, false),
        "origin" => (AlignMode::None, true),
        other => {
            return Err(format!(
                "align = \"{other}\": expected none, se3, sim3, scale, posyaw or origin"
            ))
        }
    };
    Ok(AlignOptions {
        mode,
        n_to_align: t.n_to_align,
        origin,
    })
}

fn sync_options(t: &MetricTable) -> SyncOptions {
    let d = SyncOptions::default();
    SyncOptions {
        max_diff: t.t_max_diff.unwrap_or(d.max_diff),
        offset: t.t_offset.unwrap_or(0.0),
        method: t.sync_method.unwrap_or_default(),
        t_start: None,
        t_end: None,
    }
}

impl MetricTable {
    /// The `[ape]` table's metric.
    pub fn ape(&self) -> Result<ExtraMetric, String> {
        if self.tum {
            return Ok(ExtraMetric::TumAte(TumAteOptions {
                max_difference: self.t_max_diff.unwrap_or(0.02),
                offset: self.t_offset.unwrap_or(0.0),
                scale: self.scale.unwrap_or(1.0),
            }));
        }
        Ok(ExtraMetric::Ape(ApeOptions {
            relation: self.pose_relation.unwrap_or_default(),
            align: align_options(self)?,
            sync: sync_options(self),
        }))
    }

    /// The `[rpe]` table's metric.
    pub fn rpe(&self) -> Result<ExtraMetric, String> {
        let unit = self.delta_unit.as_deref();
        if self.tum {
            let delta_unit = match unit.unwrap_or("s") {
                "s" => TumDeltaUnit::Seconds,
                "m" => TumDeltaUnit::Meters,
                "r" | "rad" => TumDeltaUnit::Radians,
                "d" | "deg" => TumDeltaUnit::Degrees,
                "f" => TumDeltaUnit::Frames,
                u => {
                    return Err(format!(
                        "delta_unit = \"{u}\": expected s, m, rad, deg or f"
                    ))
                }
            };
            return Ok(ExtraMetric::TumRpe(TumRpeOptions {
                fixed_delta: !self.all_pairs,
                delta: self.delta.unwrap_or(1.0),
                delta_unit,
                max_pairs: self.max_pairs.unwrap_or(10_000),
                offset: self.t_offset.unwrap_or(0.0),
                scale: self.scale.unwrap_or(1.0),
            }));
        }
        let delta_unit = match unit.unwrap_or("f") {
            "f" => DeltaUnit::Frames,
            "m" => DeltaUnit::Meters,
            "d" | "deg" => DeltaUnit::Degrees,
            "r" | "rad" => DeltaUnit::Radians,
            u => {
                return Err(format!(
                    "delta_unit = \"{u}\": expected f, m, d or r (s needs tum = true)"
                ))
            }
        };
        Ok(ExtraMetric::Rpe(RpeOptions {
            relation: self.pose_relation.unwrap_or_default(),
            delta: self.delta.unwrap_or(1.0),
            delta_unit,
            delta_tol: self.delta_tol.unwrap_or(0.1),
            all_pairs: self.all_pairs,
            pairs_from_reference: self.pairs_from_reference,
            align: align_options(self)?,
            sync: sync_options(self),
        }))
    }

    /// The `[kitti]` table's metric.
    pub fn kitti(&self) -> Result<ExtraMetric, String> {
        Ok(ExtraMetric::Kitti(align_options(self)?))
    }
}
