//! The field's other trajectory metrics for one run, each as its reference defines it: APE and
//! RPE as evo and as the TUM RGB-D scripts compute them, the KITTI devkit's segment errors.
//! Reads the files, runs the metric, and gives the report that `monovo ape`, `monovo rpe`
//! and `monovo kitti` print, the evo result zip and the figure.

use std::path::{Path, PathBuf};

use eval_metrics::{
    ape, detect_format, evo_result_entries, kitti_errors, parse_euroc, parse_kitti_poses,
    parse_tum, rpe, tum_ate, tum_rpe, AlignMode, AlignOptions, AlignTransform, ApeOptions,
    ErrorStats, EvoResultInfo, ExtraMetric, KittiLengthError, KittiResult, MetricError, NamedArray,
    PoseRelation, PoseTrack, RpeOptions, TrajectoryFormat, TumAteOptions, TumRpeOptions,
};
use nalgebra::Vector3;
use serde::Serialize;

use crate::{PipelineError, Result};

/// Reads a trajectory file as full poses: TUM (`t x y z qx qy qz qw`) and EuRoC csv files
/// with their stamps, KITTI pose files (12 numbers a line) without. `format` `None` guesses
/// it from the first data line.
pub fn load_track(path: &Path, format: Option<TrajectoryFormat>) -> Result<PoseTrack> {
    let text = dataset_io::read_text(path).map_err(|source| PipelineError::Read {
        what: "the trajectory",
        source,
    })?;
    let parsed = match format.unwrap_or_else(|| detect_format(&text)) {
        TrajectoryFormat::Tum => parse_tum(&text).map(|t| PoseTrack::from_trajectory(&t)),
        TrajectoryFormat::Euroc => parse_euroc(&text).map(|t| PoseTrack::from_trajectory(&t)),
        TrajectoryFormat::Kitti => parse_kitti_poses(&text),
    };
    parsed.map_err(|source| PipelineError::Eval {
        what: "the trajectory ",
        path: path.to_path_buf(),
        source,
    })
}

/// The error of a metric, naming the trajectories (`[reference, estimate]`).
fn metric_err(what: &str, names: [&str; 2], e: MetricError) -> PipelineError {
    PipelineError::Invalid(format!("{what} of {} against {}: {e}", names[1], names[0]))
}

/// The alignment applied, as reported.
#[derive(Clone, Debug, Serialize)]
pub struct AlignmentReport {
    /// `se3`, `sim3`, `scale`, `posyaw`, `origin` (or `horn` for the TUM scripts).
    pub mode: String,
    /// Scale.
    pub scale: f64,
    /// Rotation, row by row.
    pub rotation: [[f64; 3]; 3],
    /// Translation.
    pub translation: [f64; 3],
}

impl AlignmentReport {
    fn new(mode: &str, a: &AlignTransform) -> AlignmentReport {
        let r = &a.rotation;
        AlignmentReport {
            mode: mode.to_string(),
            scale: a.scale,
            rotation: [
                [r[(0, 0)], r[(0, 1)], r[(0, 2)]],
                [r[(1, 0)], r[(1, 1)], r[(1, 2)]],
                [r[(2, 0)], r[(2, 1)], r[(2, 2)]],
            ],
            translation: [a.translation[0], a.translation[1], a.translation[2]],
        }
    }
}

fn mode_name(a: &AlignOptions) -> &'static str {
    if a.origin && a.mode == AlignMode::None {
        "origin"
    } else {
        a.mode.name()
    }
}

/// What a figure of a metric shows (not part of the JSON).
#[derive(Clone, Debug, Default)]
pub struct PlotData {
    /// The errors.
    pub errors: Vec<f64>,
    /// Seconds from the first associated pose, one per error (empty without stamps).
    pub seconds: Vec<f64>,
    /// Distance along the reference from its first associated pose, one per error.
    pub distances: Vec<f64>,
    /// The reference's associated positions.
    pub reference: Vec<Vector3<f64>>,
    /// The estimate's associated positions, aligned.
    pub estimate: Vec<Vector3<f64>>,
}

/// The report of `monovo ape` / `monovo rpe`: evo's statistics at the top level.
#[derive(Clone, Debug, Serialize)]
pub struct MetricReport {
    /// `ape` or `rpe`.
    pub metric: &'static str,
    /// `evo` or `tum` (the TUM RGB-D scripts).
    pub convention: &'static str,
    /// The title (metric, unit, alignment, as evo writes it).
    pub title: String,
    /// What is measured (evo's pose relation; `trans_part` for the TUM scripts).
    pub pose_relation: &'static str,
    /// The unit of the statistics.
    pub unit: &'static str,
    /// The statistics.
    #[serde(flatten)]
    pub stats: ErrorStats,
    /// TUM RPE: the translational errors' statistics (the same as the top level).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub translational_error: Option<ErrorStats>,
    /// TUM RPE: the rotational errors' statistics in degrees.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rotational_error: Option<ErrorStats>,
    /// Number of compared poses or pose pairs.
    pub compared_pose_pairs: usize,
    /// The alignment applied to the estimate.
    pub alignment: Option<AlignmentReport>,
    /// The reference file.
    pub reference: String,
    /// The estimate file.
    pub estimate: String,
    /// For the figure.
    #[serde(skip)]
    pub plot: PlotData,
    /// For the evo result zip.
    #[serde(skip)]
    pub arrays: Vec<NamedArray>,
}

fn arr(name: &str, values: Vec<f64>) -> NamedArray {
    NamedArray {
        name: name.into(),
        shape: vec![values.len()],
        values,
    }
}

fn alignment_array(a: &Option<AlignTransform>) -> Option<NamedArray> {
    a.as_ref().map(|a| {
        let m = a.matrix();
        NamedArray {
            name: "alignment_transformation_sim3".into(),
            values: (0..16).map(|k| m[(k / 4, k % 4)]).collect(),
            shape: vec![4, 4],
        }
    })
}

fn seconds_of(t: &PoseTrack) -> Vec<f64> {
    t.times
        .as_ref()
        .map(|ts| ts.iter().map(|x| x - ts[0]).collect())
        .unwrap_or_default()
}

/// APE or RPE (evo's, or the TUM RGB-D scripts') of two trajectory files, as `monovo ape` and
/// `monovo rpe` report it. `format` `None` recognises each file by its first line.
pub fn run_metric(
    reference: &Path,
    estimate: &Path,
    format: Option<TrajectoryFormat>,
    metric: &ExtraMetric,
) -> Result<MetricReport> {
    let (r, e) = (
        load_track(reference, format)?,
        load_track(estimate, format)?,
    );
    let names = [reference, estimate].map(|p| p.display().to_string());
    metric_report(&r, &e, [&names[0], &names[1]], metric)
}

/// APE or RPE (evo's, or the TUM RGB-D scripts') of two trajectories, as `monovo ape` and
/// `monovo rpe` report it; `names` (`[reference, estimate]`, their paths) name them in the
/// report and in errors. The KITTI segment errors are [`kitti_report`]'s.
pub fn metric_report(
    reference: &PoseTrack,
    estimate: &PoseTrack,
    names: [&str; 2],
    metric: &ExtraMetric,
) -> Result<MetricReport> {
    match metric {
        ExtraMetric::Ape(o) => ape_report(reference, estimate, names, o),
        ExtraMetric::Rpe(o) => rpe_report(reference, estimate, names, o),
        ExtraMetric::TumAte(o) => tum_ate_report(reference, estimate, names, o),
        ExtraMetric::TumRpe(o) => tum_rpe_report(reference, estimate, names, o),
        ExtraMetric::Kitti(_) => Err(PipelineError::Invalid(
            "the KITTI segment errors have a report of their own (kitti_report)".into(),
        )),
    }
}

/// What an evo-convention report (APE or RPE) is made of: the result's parts, and the poses
/// its arrays and plot are indexed by (`seconds`, `distances` per error; `timestamps` and
/// `estimate_distances` of the estimate when it has stamps).
struct EvoParts {
    metric: &'static str,
    title: String,
    stats: ErrorStats,
    errors: Vec<f64>,
    alignment: Option<AlignTransform>,
    reference: PoseTrack,
    estimate: PoseTrack,
    seconds: Vec<f64>,
    distances: Vec<f64>,
    timestamps: Option<(Vec<f64>, Vec<f64>)>,
}

/// The report of `evo_ape`/`evo_rpe`: the statistics, the alignment and evo's result arrays.
fn evo_report(
    p: EvoParts,
    relation: PoseRelation,
    align: &AlignOptions,
    names: [&str; 2],
) -> MetricReport {
    let mut arrays = vec![arr("error_array", p.errors.clone())];
    if let Some((timestamps, estimate_distances)) = p.timestamps {
        arrays.push(arr("seconds_from_start", p.seconds.clone()));
        arrays.push(arr("timestamps", timestamps));
        arrays.push(arr("distances_from_start", p.distances.clone()));
        arrays.push(arr("distances", estimate_distances));
    }
    arrays.extend(alignment_array(&p.alignment));
    MetricReport {
        metric: p.metric,
        convention: "evo",
        title: p.title,
        pose_relation: relation.name(),
        unit: relation.unit(),
        stats: p.stats,
        translational_error: None,
        rotational_error: None,
        compared_pose_pairs: p.stats.n,
        alignment: p
            .alignment
            .as_ref()
            .map(|a| AlignmentReport::new(mode_name(align), a)),
        reference: names[0].to_string(),
        estimate: names[1].to_string(),
        plot: PlotData {
            errors: p.errors,
            seconds: p.seconds,
            distances: p.distances,
            reference: p.reference.positions,
            estimate: p.estimate.positions,
        },
        arrays,
    }
}

/// APE as `evo_ape` computes it.
fn ape_report(
    r: &PoseTrack,
    e: &PoseTrack,
    names: [&str; 2],
    opts: &ApeOptions,
) -> Result<MetricReport> {
    let res = ape(r, e, opts).map_err(|err| metric_err("APE", names, err))?;
    let timestamps = res
        .estimate
        .times
        .clone()
        .map(|ts| (ts, res.estimate.distances()));
    let parts = EvoParts {
        metric: "ape",
        seconds: seconds_of(&res.estimate),
        distances: res.reference.distances(),
        timestamps,
        title: res.title,
        stats: res.stats,
        errors: res.errors,
        alignment: res.alignment,
        reference: res.reference,
        estimate: res.estimate,
    };
    Ok(evo_report(parts, opts.relation, &opts.align, names))
}

/// RPE as `evo_rpe` computes it.
fn rpe_report(
    r: &PoseTrack,
    e: &PoseTrack,
    names: [&str; 2],
    opts: &RpeOptions,
) -> Result<MetricReport> {
    let res = rpe(r, e, opts).map_err(|err| metric_err("RPE", names, err))?;
    // evo keeps the first pose and the second pose of each pair for its arrays
    let mut ids = vec![0usize];
    ids.extend(res.pairs.iter().map(|p| p.1));
    let sub_ref = res.reference.select(&ids);
    let sub_est = res.estimate.select(&ids);
    let timestamps = sub_est
        .times
        .as_ref()
        .map(|ts| (ts[1..].to_vec(), sub_est.distances()[1..].to_vec()));
    let parts = EvoParts {
        metric: "rpe",
        seconds: seconds_of(&sub_est).into_iter().skip(1).collect(),
        distances: sub_ref.distances().into_iter().skip(1).collect(),
        timestamps,
        title: res.title,
        stats: res.stats,
        errors: res.errors,
        alignment: res.alignment,
        reference: res.reference,
        estimate: res.estimate,
    };
    Ok(evo_report(parts, opts.relation, &opts.align, names))
}

/// The absolute trajectory error as the TUM RGB-D `evaluate_ate.py` computes it.
fn tum_ate_report(
    r: &PoseTrack,
    e: &PoseTrack,
    names: [&str; 2],
    opts: &TumAteOptions,
) -> Result<MetricReport> {
    let res = tum_ate(r, e, opts).map_err(|err| metric_err("ATE (TUM RGB-D)", names, err))?;
    let t0 = res.stamps.first().copied().unwrap_or(0.0);
    let seconds: Vec<f64> = res.stamps.iter().map(|t| t - t0).collect();
    let mut distances = vec![0.0];
    for w in res.reference_positions.windows(2) {
        let last = distances.last().copied().unwrap_or(0.0);
        distances.push(last + (w[1] - w[0]).norm());
    }
    distances.truncate(res.reference_positions.len());
    let mut arrays = vec![
        arr("error_array", res.translational_errors.clone()),
        arr("seconds_from_start", seconds.clone()),
        arr("timestamps", res.stamps.clone()),
        arr("distances_from_start", distances.clone()),
    ];
    arrays.extend(alignment_array(&res.alignment));
    let scale = if opts.scale == 1.0 {
        String::new()
    } else {
        format!(", estimate scaled by {}", opts.scale)
    };
    Ok(MetricReport {
        metric: "ape",
        convention: "tum",
        title: format!(
            "ATE w.r.t. translation part (m)\n(TUM RGB-D evaluate_ate.py: Horn's SE(3) alignment{scale})"
        ),
        pose_relation: "trans_part",
        unit: "m",
        stats: res.translational,
        translational_error: None,
        rotational_error: None,
        compared_pose_pairs: res.translational.n,
        alignment: res
            .alignment
            .as_ref()
            .map(|a| AlignmentReport::new("horn", a)),
        reference: names[0].to_string(),
        estimate: names[1].to_string(),
        plot: PlotData {
            errors: res.translational_errors,
            seconds,
            distances,
            reference: res.reference_positions,
            estimate: res.estimate_positions,
        },
        arrays,
    })
}

/// The relative pose error as the TUM RGB-D `evaluate_rpe.py` computes it.
fn tum_rpe_report(
    r: &PoseTrack,
    e: &PoseTrack,
    names: [&str; 2],
    opts: &TumRpeOptions,
) -> Result<MetricReport> {
    let res = tum_rpe(r, e, opts).map_err(|err| metric_err("RPE (TUM RGB-D)", names, err))?;
    let t0 = res.stamps.iter().copied().fold(f64::INFINITY, f64::min);
    let seconds: Vec<f64> = res.stamps.iter().map(|t| t - t0).collect();
    let arrays = vec![
        arr("error_array", res.translational_errors.clone()),
        arr("seconds_from_start", seconds.clone()),
        arr("timestamps", res.stamps.clone()),
    ];
    let unit = match opts.delta_unit {
        eval_metrics::TumDeltaUnit::Seconds => "s",
        eval_metrics::TumDeltaUnit::Meters => "m",
        eval_metrics::TumDeltaUnit::Radians => "rad",
        eval_metrics::TumDeltaUnit::Degrees => "deg",
        eval_metrics::TumDeltaUnit::Frames => "f",
    };
    let pairs = if opts.fixed_delta {
        format!("delta = {} {unit}", opts.delta)
    } else {
        "all pairs".to_string()
    };
    Ok(MetricReport {
        metric: "rpe",
        convention: "tum",
        title: format!(
            "RPE w.r.t. translation part (m)\n(TUM RGB-D evaluate_rpe.py: {pairs}, error dP dQ^-1)"
        ),
        pose_relation: "trans_part",
        unit: "m",
        stats: res.translational,
        translational_error: Some(res.translational),
        rotational_error: res.rotational_deg,
        compared_pose_pairs: res.translational.n,
        alignment: None,
        reference: names[0].to_string(),
        estimate: names[1].to_string(),
        plot: PlotData {
            errors: res.translational_errors,
            seconds,
            distances: Vec::new(),
            reference: r.positions.clone(),
            estimate: e.positions.clone(),
        },
        arrays,
    })
}

/// Writes a report as an evo result zip (`evo_res` reads it).
pub fn save_evo_result(report: &MetricReport, path: &Path) -> Result<()> {
    let label = format!(
        "{} ({})",
        if report.metric == "ape" { "APE" } else { "RPE" },
        report.unit
    );
    let info = EvoResultInfo {
        title: report.title.clone(),
        ref_name: report.reference.clone(),
        est_name: report.estimate.clone(),
        label,
    };
    let entries = evo_result_entries(&info, &report.stats, &report.arrays);
    dataset_io::write_stored_zip(path, entries)?;
    Ok(())
}

impl MetricReport {
    /// The text `monovo ape` / `monovo rpe` print: the title and the statistics, as evo
    /// prints them.
    pub fn text(&self) -> String {
        let mut s = format!("{}\n\n", self.title);
        let st = &self.stats;
        for (name, v) in [
            ("max", st.max),
            ("mean", st.mean),
            ("median", st.median),
            ("min", st.min),
            ("rmse", st.rmse),
            ("sse", st.sse),
            ("std", st.std),
        ] {
            s += &format!("{name:>10}\t{v:.6}\n");
        }
        if let Some(r) = &self.rotational_error {
            s += "\nrotational error (deg)\n";
            for (name, v) in [
                ("max", r.max),
                ("mean", r.mean),
                ("median", r.median),
                ("min", r.min),
                ("rmse", r.rmse),
                ("std", r.std),
            ] {
                s += &format!("{name:>10}\t{v:.6}\n");
            }
        }
        s += &format!("{:>10}\t{}\n", "n", self.compared_pose_pairs);
        s
    }
}

/// The report of `monovo kitti`.
#[derive(Clone, Debug, Serialize)]
pub struct KittiReport {
    /// Mean translation error, percent.
    pub t_err_percent: f64,
    /// Mean rotation error, degrees per 100 m.
    pub r_err_deg_per_100m: f64,
    /// The devkit's `stats.txt` translation error (per metre).
    pub t_err: f64,
    /// The devkit's `stats.txt` rotation error (radians per metre).
    pub r_err_rad_per_m: f64,
    /// Number of segments.
    pub segments: usize,
    /// Per segment length (lengths with at least 3 segments).
    pub lengths: Vec<KittiLengthError>,
    /// The sequences: `(ground truth, estimate)` files.
    pub sequences: Vec<[String; 2]>,
    /// The alignment applied before (none by default, as the devkit).
    pub alignment: String,
    /// For the figure: each sequence's ground-truth and estimated positions.
    #[serde(skip)]
    pub paths: Vec<[Vec<Vector3<f64>>; 2]>,
}

/// The `(ground truth, estimate)` file pairs of a KITTI evaluation: two files, or two folders
/// whose estimate folder's `NN.txt` files have a ground truth of the same name.
pub fn kitti_pairs(gt: &Path, est: &Path) -> Result<Vec<(PathBuf, PathBuf)>> {
    if !(gt.is_dir() && est.is_dir()) {
        return Ok(vec![(gt.to_path_buf(), est.to_path_buf())]);
    }
    let rd = std::fs::read_dir(est)
        .map_err(|e| PipelineError::Dataset(dataset_io::DatasetError::io(est, e)))?;
    let mut names: Vec<String> = rd
        .filter_map(|d| d.ok())
        .map(|d| d.file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".txt") && gt.join(n).is_file())
        .collect();
    names.sort();
    if names.is_empty() {
        return Err(PipelineError::Invalid(format!(
            "{}: no NN.txt with a ground truth of the same name in {}",
            est.display(),
            gt.display()
        )));
    }
    Ok(names.iter().map(|n| (gt.join(n), est.join(n))).collect())
}

/// The KITTI devkit's segment errors of one or more sequences of files (pooled), the estimate
/// optionally aligned first (by pose line).
pub fn run_kitti(
    pairs: &[(PathBuf, PathBuf)],
    format: Option<TrajectoryFormat>,
    align: &AlignOptions,
) -> Result<KittiReport> {
    let mut seqs = Vec::with_capacity(pairs.len());
    for (g, e) in pairs {
        let names = [g, e].map(|p| p.display().to_string());
        seqs.push((load_track(g, format)?, load_track(e, format)?, names));
    }
    kitti_report(seqs, align)
}

/// The KITTI devkit's segment errors of one or more sequences `(ground truth, estimate,
/// [their names])` (pooled), the estimate optionally aligned first (by pose line).
pub fn kitti_report(
    sequences: Vec<(PoseTrack, PoseTrack, [String; 2])>,
    align: &AlignOptions,
) -> Result<KittiReport> {
    let mut seqs = Vec::with_capacity(sequences.len());
    let mut names = Vec::with_capacity(sequences.len());
    for (gt, mut est, n) in sequences {
        let nm = [n[0].as_str(), n[1].as_str()];
        if gt.len() != est.len() {
            return Err(metric_err(
                "KITTI segment errors",
                nm,
                MetricError::LengthMismatch {
                    reference: gt.len(),
                    estimate: est.len(),
                },
            ));
        }
        eval_metrics::align_track(&mut est, &gt, align)
            .map_err(|err| metric_err("KITTI alignment", nm, err))?;
        seqs.push((gt, est));
        names.push(n);
    }
    let res: KittiResult = kitti_errors(&seqs).map_err(|err| {
        let n = names
            .first()
            .map_or(["", ""], |n| [n[0].as_str(), n[1].as_str()]);
        metric_err("KITTI segment errors", n, err)
    })?;
    Ok(KittiReport {
        t_err_percent: res.t_err_percent,
        r_err_deg_per_100m: res.r_err_deg_per_100m,
        t_err: f64::from(res.t_err),
        r_err_rad_per_m: f64::from(res.r_err),
        segments: res.segments.len(),
        lengths: res.lengths,
        sequences: names,
        alignment: mode_name(align).to_string(),
        paths: seqs
            .into_iter()
            .map(|(g, e)| [g.positions, e.positions])
            .collect(),
    })
}

impl KittiReport {
    /// The text `monovo kitti` prints.
    pub fn text(&self) -> String {
        let mut s = format!(
            "KITTI odometry segment errors ({} sequence(s), {} segments, alignment: {})\n\n",
            self.sequences.len(),
            self.segments,
            self.alignment
        );
        s += &format!("translation error: {:.4} %\n", self.t_err_percent);
        s += &format!(
            "rotation error:    {:.4} deg/100m\n\n",
            self.r_err_deg_per_100m
        );
        s += "  length   t_err (%)   r_err (deg/100m)   segments\n";
        for l in &self.lengths {
            s += &format!(
                "  {:>4.0} m   {:>9.4}   {:>16.4}   {:>8}\n",
                l.length, l.t_err_percent, l.r_err_deg_per_100m, l.segments
            );
        }
        s
    }
}
