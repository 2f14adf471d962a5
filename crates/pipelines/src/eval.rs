//! One run: read a trajectory and its ground truth, evaluate, report, draw the paper's
//! alignment figure.

use std::fmt::Write as _;
use std::path::Path;

use eval_metrics::{
    detect_format, detect_ground_truth_format, parse_euroc, parse_ground_truth_trajectory,
    parse_kitti, parse_tum, principal_plane, Evaluation, GroundTruth, GroundTruthFormat,
    Trajectory, TrajectoryFormat,
};
use monovo_figures::{Chart, Corner, Figure, Panel, Series, PALETTE};
use nalgebra::Vector3;
use serde::Serialize;

use crate::{PipelineError, Result};

/// Reads and parses a trajectory file; `format` `None` guesses it from the first data line.
/// KITTI files (12 numbers a line) need `times`, one timestamp in seconds per line.
pub fn load_trajectory(
    path: &Path,
    format: Option<TrajectoryFormat>,
    times: Option<&Path>,
) -> Result<Trajectory> {
    let text = dataset_io::read_text(path).map_err(|source| PipelineError::Read {
        what: "the trajectory",
        source,
    })?;
    let traj = match format.unwrap_or_else(|| detect_format(&text)) {
        TrajectoryFormat::Tum => parse_tum(&text),
        TrajectoryFormat::Euroc => parse_euroc(&text),
        TrajectoryFormat::Kitti => {
            let Some(tp) = times else {
                return Err(PipelineError::Invalid(format!(
                    "{}: looks like a KITTI trajectory (12 numbers a line); give its timestamps with --times FILE",
                    path.display()
                )));
            };
            let tt = dataset_io::read_text(tp).map_err(|source| PipelineError::Read {
                what: "the --times file",
                source,
            })?;
            parse_kitti(&text, &tt)
        }
    };
    traj.map_err(|source| PipelineError::Eval {
        what: "the trajectory ",
        path: path.to_path_buf(),
        source,
    })
}

/// Reads a ground-truth file: groundtruthSync.txt or any TUM-format file, EuRoC's state csv
/// or TUM-VI's mocap csv (the IMU's positions: give the sequence folder to move them to the
/// camera), or 4Seasons' GNSSPoses.txt; or a sequence folder of any layout (see
/// [`load_sequence_ground_truth`]).
pub fn load_ground_truth(path: &Path) -> Result<GroundTruth> {
    if path.is_dir() {
        return load_sequence_ground_truth(path, 0);
    }
    let text = dataset_io::read_text(path).map_err(|source| PipelineError::Read {
        what: "the ground truth",
        source,
    })?;
    let eval_err = |source| PipelineError::Eval {
        what: "the ground truth ",
        path: path.to_path_buf(),
        source,
    };
    match detect_ground_truth_format(&text) {
        GroundTruthFormat::Tum => GroundTruth::parse(&text).map_err(eval_err),
        GroundTruthFormat::Kitti => Err(PipelineError::Invalid(format!(
            "{}: KITTI poses (12 numbers a line) have no timestamps: give the sequence folder (sequences/XX) as --gt",
            path.display()
        ))),
        f => {
            let traj = parse_ground_truth_trajectory(&text, f, None).map_err(eval_err)?;
            GroundTruth::from_trajectory(&traj, None, None, 0.0).map_err(eval_err)
        }
    }
}

/// The ground truth of a sequence folder of any layout, camera `cam`: its groundtruthSync.txt,
/// else the dataset's own file (EuRoC, TUM-VI, 4Seasons, KITTI, TUM RGB-D) moved from the
/// IMU to the camera where the poses are the IMU's (the calibration's IMU-to-camera
/// transform) and sampled at the frames' timestamps by linear interpolation between
/// ground-truth poses at most 3 of their median intervals apart (NaN elsewhere), as
/// groundtruthSync.txt is.
pub fn load_sequence_ground_truth(dir: &Path, cam: usize) -> Result<GroundTruth> {
    let seq =
        dataset_io::Sequence::open_camera(dir, cam).map_err(|source| PipelineError::Read {
            what: "the ground truth's sequence folder",
            source,
        })?;
    if let Some(p) = &seq.ground_truth_path {
        return load_ground_truth(p);
    }
    let Some(path) = seq.dataset_ground_truth.clone() else {
        return Err(PipelineError::Invalid(format!(
            "{}: no ground truth found (groundtruthSync.txt, or the {} layout's own file)",
            dir.display(),
            seq.layout().name()
        )));
    };
    let text = dataset_io::read_text(&path).map_err(|source| PipelineError::Read {
        what: "the ground truth",
        source,
    })?;
    let eval_err = |source| PipelineError::Eval {
        what: "the ground truth ",
        path: path.clone(),
        source,
    };
    let format = detect_ground_truth_format(&text);
    let times: Vec<f64> = seq.times().rows.iter().map(|r| r.timestamp).collect();
    let times_text: String = times.iter().map(|t| format!("{t}\n")).collect();
    let traj = parse_ground_truth_trajectory(&text, format, Some(&times_text)).map_err(eval_err)?;
    // EuRoC's and TUM-VI's csv give the IMU's (body's) pose
    let body_from_camera = match (format, seq.camera_from_imu()) {
        (GroundTruthFormat::Euroc, Some(t)) => Some(isometry(&camera_model::invert_rigid(t))),
        _ => None,
    };
    let mut dts: Vec<f64> = traj
        .poses
        .windows(2)
        .map(|w| (w[1].t - w[0].t).abs())
        .collect();
    dts.sort_by(f64::total_cmp);
    let max_gap = 3.0 * dts.get(dts.len() / 2).copied().unwrap_or(0.0);
    GroundTruth::from_trajectory(&traj, body_from_camera.as_ref(), Some(&times), max_gap)
        .map_err(eval_err)
}

/// A rigid 4x4 transform (row-major) as an isometry (its rotation re-orthonormalised).
fn isometry(t: &camera_model::Transform) -> nalgebra::Isometry3<f64> {
    let r = nalgebra::Matrix3::new(
        t[0][0], t[0][1], t[0][2], t[1][0], t[1][1], t[1][2], t[2][0], t[2][1], t[2][2],
    );
    let q = nalgebra::UnitQuaternion::from_matrix(&r);
    nalgebra::Isometry3::from_parts(nalgebra::Translation3::new(t[0][3], t[1][3], t[2][3]), q)
}

/// `None` for an infinite or NaN metric (JSON `null`).
fn finite(v: f64) -> Option<f64> {
    v.is_finite().then_some(v)
}

/// One evaluated run as `monovo eval --json` prints it: metrics `null` where infinite.
#[derive(Debug, Serialize)]
pub struct EvaluationReport {
    /// `ok` or `failed`.
    pub status: &'static str,
    /// Why the run failed (`null` when it succeeded).
    pub reason: Option<String>,
    /// Alignment error.
    pub e_align: Option<f64>,
    /// Scale drift (multiplier).
    pub e_s: Option<f64>,
    /// Rotation drift in degrees.
    pub e_r: Option<f64>,
    /// Translation drift.
    pub e_t: Option<f64>,
    /// Joint alignment RMSE.
    pub e_rmse: Option<f64>,
    /// Start-segment RMSE.
    pub rmse_start: Option<f64>,
    /// End-segment RMSE.
    pub rmse_end: Option<f64>,
    /// Estimated poses.
    pub poses: usize,
    /// Poses in the start alignment.
    pub poses_start: usize,
    /// Poses in the end alignment.
    pub poses_end: usize,
}

impl From<&Evaluation> for EvaluationReport {
    fn from(e: &Evaluation) -> Self {
        let m = &e.metrics;
        EvaluationReport {
            status: if e.is_ok() { "ok" } else { "failed" },
            reason: e.failure.as_ref().map(|f| f.to_string()),
            e_align: finite(m.e_align),
            e_s: finite(m.e_s),
            e_r: finite(m.e_r),
            e_t: finite(m.e_t),
            e_rmse: finite(m.e_rmse),
            rmse_start: finite(m.rmse_start),
            rmse_end: finite(m.rmse_end),
            poses: e.poses,
            poses_start: e.poses_start,
            poses_end: e.poses_end,
        }
    }
}

fn fmt(v: f64, digits: usize) -> String {
    if v.is_finite() {
        format!("{v:.digits$}")
    } else {
        "inf".into()
    }
}

/// The text report of one run (as `monovo eval` prints it), naming the run file and the
/// figure, if one was drawn.
pub fn evaluation_text(e: &Evaluation, run: &Path, figure: Option<&Path>) -> String {
    let m = &e.metrics;
    let mut s = String::new();
    let _ = writeln!(s, "run:        {}", run.display());
    let _ = writeln!(
        s,
        "poses:      {} ({} in the start segment, {} in the end segment{})",
        e.poses,
        e.poses_start,
        e.poses_end,
        if e.backwards_time_mapped {
            "; timestamps mapped back from 2e9 - t"
        } else {
            ""
        }
    );
    match &e.failure {
        None => s.push_str("status:     ok\n"),
        Some(r) => {
            let _ = writeln!(s, "status:     FAILED: {r}");
        }
    }
    let _ = writeln!(s, "e_align:    {}", fmt(m.e_align, 4));
    let _ = writeln!(
        s,
        "e_s:        {}   (e'_s = max(e_s, 1/e_s) = {})",
        fmt(m.e_s, 4),
        fmt(m.e_s_sym(), 4)
    );
    let _ = writeln!(s, "e_r:        {} deg", fmt(m.e_r, 4));
    let _ = writeln!(s, "e_t:        {}", fmt(m.e_t, 4));
    let _ = writeln!(s, "e_rmse:     {}", fmt(m.e_rmse, 4));
    let _ = writeln!(
        s,
        "rmse_start: {}   rmse_end: {}",
        fmt(m.rmse_start, 5),
        fmt(m.rmse_end, 5)
    );
    if let Some(p) = figure {
        let _ = writeln!(s, "plot:       {}", p.display());
    }
    s
}

/// The paper's alignment figure: ground truth (dashed green), the trajectory aligned to the
/// start segment (blue) and to the end segment (red); the full trajectory and close-ups of
/// the two segments, viewed top-down (the plane of largest spread,
/// [`eval_metrics::principal_plane`]). `None` for a failed run.
pub fn alignment_figure(e: &Evaluation, gt: &GroundTruth) -> Option<Figure> {
    let (s, en) = (e.start?, e.end?);
    let start_pts: Vec<Vector3<f64>> = e.positions.iter().map(|p| s.apply(p)).collect();
    let end_pts: Vec<Vector3<f64>> = e.positions.iter().map(|p| en.apply(p)).collect();
    let (ax, ay) = principal_plane(&start_pts);
    let proj = |p: &Vector3<f64>| [p.dot(&ax), p.dot(&ay)];
    let gt_rows: Vec<[f64; 2]> = gt
        .positions()
        .iter()
        .map(|p| {
            if p.iter().all(|v| v.is_finite()) {
                proj(p)
            } else {
                [f64::NAN, f64::NAN]
            }
        })
        .collect();
    let (start_last, end_first) = gt.window_bounds();
    let gt_start: Vec<[f64; 2]> = gt_rows.iter().take(start_last + 1).copied().collect();
    let gt_end: Vec<[f64; 2]> = gt_rows.iter().skip(end_first).copied().collect();
    let est_start: Vec<[f64; 2]> = start_pts.iter().map(proj).collect();
    let est_end: Vec<[f64; 2]> = end_pts.iter().map(proj).collect();
    let bounds = |pts: &[[f64; 2]]| {
        let mut b = [
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ];
        for p in pts.iter().filter(|p| p[0].is_finite()) {
            b = [
                b[0].min(p[0]),
                b[1].max(p[0]),
                b[2].min(p[1]),
                b[3].max(p[1]),
            ];
        }
        let pad = 0.15 * (b[1] - b[0]).max(b[3] - b[2]).max(1e-9);
        ([b[0] - pad, b[1] + pad], [b[2] - pad, b[3] + pad])
    };
    let mk = |title: &str, range: Option<([f64; 2], [f64; 2])>, legend: bool| {
        let mut c = Chart::new(
            title,
            "top-down x (ground-truth length unit)",
            "top-down y (ground-truth length unit)",
        );
        c.equal_aspect = true;
        c.legend = legend.then_some(Corner::TopRight);
        c.series.push(Series::line(
            "aligned to start",
            est_start.clone(),
            PALETTE[0],
        ));
        c.series
            .push(Series::line("aligned to end", est_end.clone(), PALETTE[1]));
        let mut g1 = Series::line("ground truth", gt_start.clone(), PALETTE[2]).dashed();
        g1.width = 2.5;
        let mut g2 = Series::line("", gt_end.clone(), PALETTE[2]).dashed();
        g2.width = 2.5;
        c.series.push(g1);
        c.series.push(g2);
        if let Some((x, y)) = range {
            c.x_range = Some(x);
            c.y_range = Some(y);
        }
        c
    };
    let m = &e.metrics;
    let full = mk(
        &format!(
            "e_align={:.3}  e_s={:.3}  e_r={:.2} deg",
            m.e_align, m.e_s, m.e_r
        ),
        None,
        true,
    );
    let start_close = mk("start segment", Some(bounds(&gt_start)), false);
    let end_close = mk("end segment", Some(bounds(&gt_end)), false);
    Some(Figure {
        width: 1500,
        height: 560,
        panels: vec![
            (Panel::Chart(start_close), [0.0, 0.0, 0.25, 1.0]),
            (Panel::Chart(full), [0.25, 0.0, 0.5, 1.0]),
            (Panel::Chart(end_close), [0.75, 0.0, 0.25, 1.0]),
        ],
    })
}

/// Draws [`alignment_figure`] into `path` (.png or .svg); a failed run is an error that
/// names the file and the reason.
pub fn save_alignment_figure(e: &Evaluation, gt: &GroundTruth, path: &Path) -> Result<()> {
    let Some(fig) = alignment_figure(e, gt) else {
        return Err(PipelineError::Invalid(format!(
            "{}: no alignment figure for a failed run ({})",
            path.display(),
            e.failure.as_ref().map_or(String::new(), |f| f.to_string())
        )));
    };
    monovo_figures::save(&fig, path)?;
    Ok(())
}
