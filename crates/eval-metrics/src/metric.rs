//! The metrics a batch summarises and plots: the paper's loop-closure metrics and the
//! columns of the field's other metrics ([`crate::ExtraMetric`]).

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use crate::evaluate::Metrics;
use crate::record::RunRecord;

/// A metric to summarise or plot.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Metric {
    /// `e_align`.
    #[serde(rename = "e_align")]
    EAlign,
    /// `e_r` in degrees.
    #[serde(rename = "e_r")]
    ER,
    /// `e'_s = max(e_s, 1/e_s)` (the paper's summary of the scale drift).
    #[serde(rename = "e_s")]
    ES,
    /// `e_t`.
    #[serde(rename = "e_t")]
    ET,
    /// `e_rmse`.
    #[serde(rename = "e_rmse")]
    ERmse,
    /// Start-segment RMSE.
    RmseStart,
    /// End-segment RMSE.
    RmseEnd,
    /// APE root mean square (`ape_rmse`).
    ApeRmse,
    /// APE mean.
    ApeMean,
    /// APE median.
    ApeMedian,
    /// APE standard deviation.
    ApeStd,
    /// APE minimum.
    ApeMin,
    /// APE maximum.
    ApeMax,
    /// RPE root mean square (`rpe_rmse`).
    RpeRmse,
    /// RPE mean.
    RpeMean,
    /// RPE median.
    RpeMedian,
    /// RPE standard deviation.
    RpeStd,
    /// RPE minimum.
    RpeMin,
    /// RPE maximum.
    RpeMax,
    /// KITTI translation error in percent (`kitti_t_err`).
    KittiTErr,
    /// KITTI rotation error in degrees per 100 m (`kitti_r_err`).
    KittiRErr,
}

impl Metric {
    /// Every metric.
    pub const ALL: [Metric; 21] = [
        Metric::EAlign,
        Metric::ER,
        Metric::ES,
        Metric::ET,
        Metric::ERmse,
        Metric::RmseStart,
        Metric::RmseEnd,
        Metric::ApeRmse,
        Metric::ApeMean,
        Metric::ApeMedian,
        Metric::ApeStd,
        Metric::ApeMin,
        Metric::ApeMax,
        Metric::RpeRmse,
        Metric::RpeMean,
        Metric::RpeMedian,
        Metric::RpeStd,
        Metric::RpeMin,
        Metric::RpeMax,
        Metric::KittiTErr,
        Metric::KittiRErr,
    ];

    /// The metric's value in a run's loop-closure metrics (infinite when failed; NaN for
    /// the other metrics, which [`Metric::of`] reads).
    pub fn value(self, m: &Metrics) -> f64 {
        match self {
            Metric::EAlign => m.e_align,
            Metric::ER => m.e_r,
            Metric::ES => m.e_s_sym(),
            Metric::ET => m.e_t,
            Metric::ERmse => m.e_rmse,
            Metric::RmseStart => m.rmse_start,
            Metric::RmseEnd => m.rmse_end,
            _ => f64::NAN,
        }
    }

    /// The metric's value in a run: NaN when the run does not have it (the batch did not
    /// compute that metric), infinite when it could not be computed.
    pub fn of(self, r: &RunRecord) -> f64 {
        if self.is_extra() {
            r.extra.get(self.name()).copied().unwrap_or(f64::NAN)
        } else {
            self.value(&r.metrics)
        }
    }

    /// Whether it is one of the field's other metrics (a column of [`crate::ExtraMetric`]).
    pub fn is_extra(self) -> bool {
        !matches!(
            self,
            Metric::EAlign
                | Metric::ER
                | Metric::ES
                | Metric::ET
                | Metric::ERmse
                | Metric::RmseStart
                | Metric::RmseEnd
        )
    }

    /// Short name as used on the command line and in results.csv.
    pub fn name(self) -> &'static str {
        match self {
            Metric::EAlign => "e_align",
            Metric::ER => "e_r",
            Metric::ES => "e_s",
            Metric::ET => "e_t",
            Metric::ERmse => "e_rmse",
            Metric::RmseStart => "rmse_start",
            Metric::RmseEnd => "rmse_end",
            Metric::ApeRmse => "ape_rmse",
            Metric::ApeMean => "ape_mean",
            Metric::ApeMedian => "ape_median",
            Metric::ApeStd => "ape_std",
            Metric::ApeMin => "ape_min",
            Metric::ApeMax => "ape_max",
            Metric::RpeRmse => "rpe_rmse",
            Metric::RpeMean => "rpe_mean",
            Metric::RpeMedian => "rpe_median",
            Metric::RpeStd => "rpe_std",
            Metric::RpeMin => "rpe_min",
            Metric::RpeMax => "rpe_max",
            Metric::KittiTErr => "kitti_t_err",
            Metric::KittiRErr => "kitti_r_err",
        }
    }

    /// Axis label for plots, with the unit: degrees for `e_r`, a multiplier for `e'_s`, and
    /// the ground truth's length unit for the others (APE and RPE in the unit of their pose
    /// relation).
    pub fn label(self) -> String {
        let stat = |n: &str| n.split('_').nth(1).unwrap_or("").to_string();
        match self {
            Metric::EAlign => "alignment error e_align (ground-truth length unit)".into(),
            Metric::ER => "rotation drift e_r (degrees)".into(),
            Metric::ES => "scale drift e'_s = max(e_s, 1/e_s) (multiplier)".into(),
            Metric::ET => "translation drift e_t (ground-truth length unit)".into(),
            Metric::ERmse => "joint alignment RMSE e_rmse (ground-truth length unit)".into(),
            Metric::RmseStart => "start-segment RMSE (ground-truth length unit)".into(),
            Metric::RmseEnd => "end-segment RMSE (ground-truth length unit)".into(),
            Metric::KittiTErr => "KITTI translation error (%)".into(),
            Metric::KittiRErr => "KITTI rotation error (deg/100m)".into(),
            m if m.name().starts_with("ape") => {
                format!("APE {} (unit of the pose relation)", stat(m.name()))
            }
            m => format!("RPE {} (unit of the pose relation)", stat(m.name())),
        }
    }

    /// Whether the metric is a multiplier that is at least 1 (`e'_s`): its axis starts at 1.
    pub fn is_multiplier(self) -> bool {
        self == Metric::ES
    }
}

impl fmt::Display for Metric {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Metric {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Metric::ALL
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| {
                format!(
                    "unknown metric `{s}`, expected one of {}",
                    Metric::ALL.map(|m| m.name()).join(", ")
                )
            })
    }
}
