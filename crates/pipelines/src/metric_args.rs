//! The options of the field's other metrics under evo's names, turned into a metric in one
//! place: the defaults (evo's, or the TUM scripts' with `tum`) and the combinations that do not
//! apply, for `monovo ape/rpe/kitti`, the experiment manifests' `[ape]`, `[rpe]` and
//! `[kitti]` tables and the Python package's `monovo.ape/rpe/kitti`.

use std::str::FromStr;

use eval_metrics::{
    AlignMode, AlignOptions, ApeOptions, DeltaUnit, ExtraMetric, PoseRelation, RpeOptions,
    SyncMethod, SyncOptions, TumAteOptions, TumDeltaUnit, TumRpeOptions,
};

/// How error messages spell an option: as a command-line flag (`--t-max-diff`) or as a name
/// (`t_max_diff`: manifests, Python keyword arguments).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Spelling {
    /// `--t-max-diff`.
    Flags,
    /// `t_max_diff`.
    #[default]
    Names,
}

impl Spelling {
    fn of(self, name: &str) -> String {
        match self {
            Spelling::Flags => format!("--{}", name.replace('_', "-")),
            Spelling::Names => name.to_string(),
        }
    }

    /// `a, b and c`, each spelled.
    fn list(self, names: &[&str]) -> String {
        let v: Vec<String> = names.iter().map(|n| self.of(n)).collect();
        match v.split_last() {
            Some((last, rest)) if !rest.is_empty() => format!("{} and {last}", rest.join(", ")),
            _ => v.join(""),
        }
    }
}

/// The unit of an RPE delta: evo's `f`, `m`, `d`, `r`, and the TUM script's `s`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RpeUnit {
    /// Poses.
    Frames,
    /// Metres travelled.
    Meters,
    /// Degrees turned.
    Degrees,
    /// Radians turned.
    Radians,
    /// Seconds (the TUM script only).
    Seconds,
}

impl FromStr for RpeUnit {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Ok(match s {
            "f" => RpeUnit::Frames,
            "m" => RpeUnit::Meters,
            "d" | "deg" => RpeUnit::Degrees,
            "r" | "rad" => RpeUnit::Radians,
            "s" => RpeUnit::Seconds,
            u => {
                return Err(format!(
                    "delta_unit `{u}`: expected f (frames), m, d (deg), r (rad), or s with tum"
                ))
            }
        })
    }
}

/// The options of `monovo ape`, `monovo rpe` and `monovo kitti` under evo's names; `Default`
/// is evo's defaults (no alignment, `trans_part`, nearest stamps within 0.01 s, a delta of one
/// frame).
#[derive(Clone, Debug, PartialEq)]
pub struct MetricArgs {
    /// What is measured of each error pose.
    pub pose_relation: PoseRelation,
    /// Least-squares rotation and translation (`-a`).
    pub align: bool,
    /// Least-squares scale (`-s`; with `align` a Sim(3)).
    pub correct_scale: bool,
    /// Align with the first N pose pairs (-1: all).
    pub n_to_align: i64,
    /// Move the first estimated pose onto the first reference pose.
    pub align_origin: bool,
    /// 4-DoF alignment (translation and yaw).
    pub posyaw: bool,
    /// Association tolerance, seconds (evo 0.01, `tum` 0.02).
    pub t_max_diff: Option<f64>,
    /// Added to the estimate's stamps, seconds.
    pub t_offset: f64,
    /// Nearest stamp or interpolation.
    pub sync_method: SyncMethod,
    /// Only reference poses at or after this time.
    pub t_start: Option<f64>,
    /// Only reference poses at or before this time.
    pub t_end: Option<f64>,
    /// The TUM RGB-D scripts' definitions instead of evo's.
    pub tum: bool,
    /// `tum`: a fixed factor for the estimate.
    pub scale: Option<f64>,
    /// RPE: the distance between the poses of a pair.
    pub delta: f64,
    /// RPE: its unit (evo: frames; `tum`: seconds).
    pub delta_unit: Option<RpeUnit>,
    /// RPE: the relative tolerance of all pairs.
    pub delta_tol: f64,
    /// RPE: every pair instead of consecutive ones (`tum`: the script's all-pairs mode).
    pub all_pairs: bool,
    /// RPE: pairs on the reference's path.
    pub pairs_from_reference: bool,
    /// `tum` RPE: at most this many pairs (10,000; 0: all).
    pub max_pairs: Option<usize>,
}

impl Default for MetricArgs {
    fn default() -> Self {
        MetricArgs {
            pose_relation: PoseRelation::TransPart,
            align: false,
            correct_scale: false,
            n_to_align: -1,
            align_origin: false,
            posyaw: false,
            t_max_diff: None,
            t_offset: 0.0,
            sync_method: SyncMethod::NearestTime,
            t_start: None,
            t_end: None,
            tum: false,
            scale: None,
            delta: 1.0,
            delta_unit: None,
            delta_tol: 0.1,
            all_pairs: false,
            pairs_from_reference: false,
            max_pairs: None,
        }
    }
}

impl MetricArgs {
    /// Whether any alignment option is set.
    pub fn aligns(&self) -> bool {
        self.align
            || self.correct_scale
            || self.align_origin
            || self.posyaw
            || self.n_to_align != -1
    }

    /// The alignment: `-a` SE(3), `-as` Sim(3), `-s` scale, posyaw, origin.
    pub fn align_options(&self, sp: Spelling) -> Result<AlignOptions, String> {
        if self.posyaw && (self.align || self.correct_scale || self.align_origin) {
            return Err(format!(
                "{} is an alignment of its own: {} do not combine with it",
                sp.of("posyaw"),
                sp.list(&["align", "correct_scale", "align_origin"])
            ));
        }
        if self.align_origin && self.align {
            return Err(format!(
                "{} moves the first pose instead of {}: give one of them",
                sp.of("align_origin"),
                sp.of("align")
            ));
        }
        let mode = match (self.align, self.correct_scale, self.posyaw) {
            (_, _, true) => AlignMode::PosYaw,
            (true, true, _) => AlignMode::Sim3,
            (true, false, _) => AlignMode::Se3,
            (false, true, _) => AlignMode::Scale,
            (false, false, _) => AlignMode::None,
        };
        let n_to_align = match self.n_to_align {
            -1 => None,
            n if n >= 1 => Some(n as usize),
            n => {
                return Err(format!(
                    "{} {n}: expected a number of poses of at least 1, or -1 for all",
                    sp.of("n_to_align")
                ))
            }
        };
        Ok(AlignOptions {
            mode,
            n_to_align,
            origin: self.align_origin,
        })
    }

    /// evo's association.
    pub fn sync_options(&self) -> SyncOptions {
        SyncOptions {
            max_diff: self.t_max_diff.unwrap_or(SyncOptions::default().max_diff),
            offset: self.t_offset,
            method: self.sync_method,
            t_start: self.t_start,
            t_end: self.t_end,
        }
    }

    fn only_with_tum(&self, sp: Spelling, rpe: bool) -> Result<(), String> {
        let mut given = Vec::new();
        if self.scale.is_some() {
            given.push("scale");
        }
        if rpe && self.max_pairs.is_some() {
            given.push("max_pairs");
        }
        if given.is_empty() {
            return Ok(());
        }
        Err(format!(
            "{} {} the TUM RGB-D script's: add {} (evo's least-squares scale is {})",
            sp.list(&given),
            if given.len() == 1 { "is" } else { "are" },
            sp.of("tum"),
            sp.of("correct_scale")
        ))
    }

    /// The APE: evo's, or `evaluate_ate.py`'s with `tum`.
    pub fn ape(&self, sp: Spelling) -> Result<ExtraMetric, String> {
        if !self.tum {
            self.only_with_tum(sp, false)?;
            return Ok(ExtraMetric::Ape(ApeOptions {
                relation: self.pose_relation,
                align: self.align_options(sp)?,
                sync: self.sync_options(),
            }));
        }
        let tum = sp.of("tum");
        if self.correct_scale || self.align_origin || self.posyaw || self.n_to_align != -1 {
            return Err(format!(
                "{tum} aligns as evaluate_ate.py does (Horn's SE(3) over all pairs, no scale): {} do not apply; use {} for a fixed factor",
                sp.list(&["correct_scale", "align_origin", "posyaw", "n_to_align"]),
                sp.of("scale")
            ));
        }
        if !matches!(
            self.pose_relation,
            PoseRelation::TransPart | PoseRelation::PointDistance
        ) {
            return Err(format!(
                "{tum} measures translations only (evaluate_ate.py): {} does not apply",
                sp.of("pose_relation")
            ));
        }
        if self.sync_method != SyncMethod::NearestTime
            || self.t_start.is_some()
            || self.t_end.is_some()
        {
            return Err(format!(
                "{tum} associates as associate.py does: {} do not apply",
                sp.list(&["sync_method", "t_start", "t_end"])
            ));
        }
        Ok(ExtraMetric::TumAte(TumAteOptions {
            max_difference: self
                .t_max_diff
                .unwrap_or(TumAteOptions::default().max_difference),
            offset: self.t_offset,
            scale: self.scale.unwrap_or(1.0),
        }))
    }

    /// The RPE: evo's, or `evaluate_rpe.py`'s with `tum`.
    pub fn rpe(&self, sp: Spelling) -> Result<ExtraMetric, String> {
        if !self.tum {
            self.only_with_tum(sp, true)?;
            let delta_unit = match self.delta_unit.unwrap_or(RpeUnit::Frames) {
                RpeUnit::Frames => DeltaUnit::Frames,
                RpeUnit::Meters => DeltaUnit::Meters,
                RpeUnit::Degrees => DeltaUnit::Degrees,
                RpeUnit::Radians => DeltaUnit::Radians,
                RpeUnit::Seconds => {
                    return Err(format!(
                        "{} s: evo has no delta in seconds; use f, m, d or r, or {} for evaluate_rpe.py",
                        sp.of("delta_unit"),
                        sp.of("tum")
                    ))
                }
            };
            return Ok(ExtraMetric::Rpe(RpeOptions {
                relation: self.pose_relation,
                delta: self.delta,
                delta_unit,
                delta_tol: self.delta_tol,
                all_pairs: self.all_pairs,
                pairs_from_reference: self.pairs_from_reference,
                align: self.align_options(sp)?,
                sync: self.sync_options(),
            }));
        }
        let tum = sp.of("tum");
        if self.aligns() {
            return Err(format!(
                "{tum} compares motions as evaluate_rpe.py does, without alignment: {} do not apply; use {} for a fixed factor",
                sp.list(&["align", "correct_scale", "align_origin", "posyaw", "n_to_align"]),
                sp.of("scale")
            ));
        }
        if self.pose_relation != PoseRelation::TransPart {
            return Err(format!(
                "{tum} reports the translational and the rotational error together (evaluate_rpe.py): {} does not apply",
                sp.of("pose_relation")
            ));
        }
        if self.pairs_from_reference
            || self.t_max_diff.is_some()
            || self.sync_method != SyncMethod::NearestTime
            || self.t_start.is_some()
            || self.t_end.is_some()
        {
            return Err(format!(
                "{tum} pairs poses as evaluate_rpe.py does: {} do not apply",
                sp.list(&[
                    "pairs_from_reference",
                    "t_max_diff",
                    "sync_method",
                    "t_start",
                    "t_end"
                ])
            ));
        }
        let delta_unit = match self.delta_unit.unwrap_or(RpeUnit::Seconds) {
            RpeUnit::Seconds => TumDeltaUnit::Seconds,
            RpeUnit::Meters => TumDeltaUnit::Meters,
            RpeUnit::Radians => TumDeltaUnit::Radians,
            RpeUnit::Degrees => TumDeltaUnit::Degrees,
            RpeUnit::Frames => TumDeltaUnit::Frames,
        };
        Ok(ExtraMetric::TumRpe(TumRpeOptions {
            fixed_delta: !self.all_pairs,
            delta: self.delta,
            delta_unit,
            max_pairs: self.max_pairs.unwrap_or(TumRpeOptions::default().max_pairs),
            offset: self.t_offset,
            scale: self.scale.unwrap_or(1.0),
        }))
    }

    /// The KITTI segment errors: only the alignment applies (the devkit has none).
    pub fn kitti(&self, sp: Spelling) -> Result<ExtraMetric, String> {
        Ok(ExtraMetric::Kitti(self.align_options(sp)?))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_evo_s_and_the_tum_scripts() {
        let a = MetricArgs::default();
        let ExtraMetric::Ape(o) = a.ape(Spelling::Names).unwrap() else {
            panic!()
        };
        assert_eq!(o.sync.max_diff, 0.01);
        assert_eq!(o.align.mode, AlignMode::None);
        let tum = MetricArgs {
            tum: true,
            ..MetricArgs::default()
        };
        let ExtraMetric::TumAte(o) = tum.ape(Spelling::Names).unwrap() else {
            panic!()
        };
        assert_eq!(o.max_difference, 0.02);
        let ExtraMetric::TumRpe(o) = tum.rpe(Spelling::Names).unwrap() else {
            panic!()
        };
        assert!(o.fixed_delta && o.delta_unit == TumDeltaUnit::Seconds && o.max_pairs == 10_000);
    }

    #[test]
    fn options_that_do_not_apply_are_named_in_the_caller_s_spelling() {
        let a = MetricArgs {
            tum: true,
            correct_scale: true,
            ..MetricArgs::default()
        };
        let e = a.ape(Spelling::Flags).unwrap_err();
        assert!(
            e.starts_with("--tum aligns") && e.contains("--n-to-align"),
            "{e}"
        );
        let e = a.rpe(Spelling::Names).unwrap_err();
        assert!(
            e.starts_with("tum compares") && e.contains("correct_scale,"),
            "{e}"
        );
        let a = MetricArgs {
            posyaw: true,
            align: true,
            ..MetricArgs::default()
        };
        assert!(a.ape(Spelling::Names).unwrap_err().contains("posyaw"));
        let a = MetricArgs {
            delta_unit: Some(RpeUnit::Seconds),
            ..MetricArgs::default()
        };
        assert!(a.rpe(Spelling::Flags).unwrap_err().contains("--tum"));
        let a = MetricArgs {
            scale: Some(2.0),
            ..MetricArgs::default()
        };
        assert!(a.ape(Spelling::Names).unwrap_err().contains("add tum"));
        let a = MetricArgs {
            n_to_align: 0,
            ..MetricArgs::default()
        };
        assert!(a
            .kitti(Spelling::Names)
            .unwrap_err()
            .contains("n_to_align 0"));
        assert!("x"
            .parse::<RpeUnit>()
            .unwrap_err()
            .contains("delta_unit `x`"));
    }
}
