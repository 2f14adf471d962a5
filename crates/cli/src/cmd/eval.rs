//! `monovo eval`: the loop-closure drift metrics of one run.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use eval_metrics::{
    detect_format, evaluate, parse_euroc, parse_kitti, parse_tum, Evaluation, GroundTruth,
    Trajectory, TrajectoryFormat,
};
use nalgebra::{Matrix3, SymmetricEigen, Vector3};
use serde::Serialize;

use crate::plot::{self, Chart, Corner, Figure, Panel, Series, PALETTE};

/// Trajectory format on the command line.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum FormatArg {
    /// Guess from the first data line.
    Auto,
    /// `t x y z qx qy qz qw`.
    Tum,
    /// 12 numbers a line, with --times.
    Kitti,
    /// EuRoC csv.
    Euroc,
}

/// Arguments of `monovo eval`.
#[derive(clap::Args, Debug)]
#[command(after_help = "\
Examples:
  monovo eval results/dso/sequence_01/fwd_0.txt --gt sequence_01/groundtruthSync.txt
  monovo eval run.txt --gt groundtruthSync.txt --json
  monovo eval run.txt --gt groundtruthSync.txt --plot alignment.png

The estimate is sorted by time, every pose is associated with the ground-truth row within
1 ms, and the start and end segments (the first and second half of the ground-truth rows
that have finite positions) are aligned separately by Sim(3). e_align is the RMS distance
between the start- and the end-aligned trajectory over all poses; e_s = s_start / s_end;
e_r is the angle of R_end R_start^T in degrees; e_t the translation of S_end S_start^-1;
e_rmse the RMSE of one alignment over both segments. A run that cannot be evaluated (empty,
NaN, lost tracking, poses without ground truth) is reported as failed with exit code 0;
only unusable input (a missing file, a malformed line) is an error. Backwards runs may use
original timestamps in reverse order or the 2e9 - t convention.")]
pub struct Args {
    /// The estimated trajectory (camera-to-world poses; keyframes are fine).
    pub trajectory: PathBuf,
    /// The sequence's groundtruthSync.txt.
    #[arg(long, value_name = "FILE")]
    pub gt: PathBuf,
    /// Trajectory format.
    #[arg(long, value_enum, default_value_t = FormatArg::Auto)]
    pub format: FormatArg,
    /// Timestamps file for KITTI-format trajectories (one time in seconds per line).
    #[arg(long, value_name = "FILE")]
    pub times: Option<PathBuf>,
    /// Print exactly one JSON object with every metric (null where infinite).
    #[arg(long)]
    pub json: bool,
    /// Draw the paper's alignment figure (top-down; .png or .svg).
    #[arg(long, value_name = "FILE")]
    pub plot: Option<PathBuf>,
    /// Replace an existing --plot file.
    #[arg(long)]
    pub force: bool,
}

/// Reads and parses a trajectory file in `format` (KITTI needs `times`).
pub fn load_trajectory(path: &Path, format: FormatArg, times: Option<&Path>) -> Result<Trajectory> {
    let text = dataset_io::read_text(path).context("the trajectory")?;
    let fmt = match format {
        FormatArg::Auto => detect_format(&text),
        FormatArg::Tum => TrajectoryFormat::Tum,
        FormatArg::Kitti => TrajectoryFormat::Kitti,
        FormatArg::Euroc => TrajectoryFormat::Euroc,
    };
    let traj = match fmt {
        TrajectoryFormat::Tum => parse_tum(&text),
        TrajectoryFormat::Euroc => parse_euroc(&text),
        TrajectoryFormat::Kitti => {
            let Some(tp) = times else {
                bail!(
                    "{}: looks like a KITTI trajectory (12 numbers a line); give its timestamps with --times FILE",
                    path.display()
                );
            };
            let tt = dataset_io::read_text(tp).context("the --times file")?;
            parse_kitti(&text, &tt)
        }
    };
    traj.with_context(|| format!("the trajectory {}", path.display()))
}

/// Reads groundtruthSync.txt.
pub fn load_ground_truth(path: &Path) -> Result<GroundTruth> {
    let text = dataset_io::read_text(path).context("the ground truth")?;
    GroundTruth::parse(&text).with_context(|| format!("the ground truth {}", path.display()))
}

/// `None` for an infinite or NaN metric (JSON `null`).
fn finite(v: f64) -> Option<f64> {
    v.is_finite().then_some(v)
}

/// The `--json` output of `monovo eval`: one object, metrics `null` where infinite.
#[derive(Debug, Serialize)]
pub struct EvaluationJson {
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

impl From<&Evaluation> for EvaluationJson {
    fn from(e: &Evaluation) -> Self {
        let m = &e.metrics;
        EvaluationJson {
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

/// Runs `monovo eval`.
pub fn run(args: &Args) -> Result<()> {
    if let Some(p) = &args.plot {
        plot::format_of(p)?;
        dataset_io::check_output_file(p, args.force)?;
    }
    let gt = load_ground_truth(&args.gt)?;
    let traj = load_trajectory(&args.trajectory, args.format, args.times.as_deref())?;
    let e = evaluate(&traj, &gt);
    if let Some(p) = &args.plot {
        alignment_figure(&e, &gt, p)?;
    }
    if args.json {
        outln!("{}", serde_json::to_string(&EvaluationJson::from(&e))?)?;
        return Ok(());
    }
    let m = &e.metrics;
    outln!("run:        {}", args.trajectory.display())?;
    outln!(
        "poses:      {} ({} in the start segment, {} in the end segment{})",
        e.poses,
        e.poses_start,
        e.poses_end,
        if e.backwards_time_mapped {
            "; timestamps mapped back from 2e9 - t"
        } else {
            ""
        }
    )?;
    match &e.failure {
        None => outln!("status:     ok")?,
        Some(r) => outln!("status:     FAILED: {r}")?,
    }
    outln!("e_align:    {}", fmt(m.e_align, 4))?;
    outln!(
        "e_s:        {}   (e'_s = max(e_s, 1/e_s) = {})",
        fmt(m.e_s, 4),
        fmt(m.e_s_sym(), 4)
    )?;
    outln!("e_r:        {} deg", fmt(m.e_r, 4))?;
    outln!("e_t:        {}", fmt(m.e_t, 4))?;
    outln!("e_rmse:     {}", fmt(m.e_rmse, 4))?;
    outln!(
        "rmse_start: {}   rmse_end: {}",
        fmt(m.rmse_start, 5),
        fmt(m.rmse_end, 5)
    )?;
    if let Some(p) = &args.plot {
        outln!("plot:       {}", p.display())?;
    }
    Ok(())
}

/// The two principal axes of a point set (the plane of largest spread), by the eigen
/// decomposition of its scatter matrix.
fn top_down_axes(points: &[Vector3<f64>]) -> (Vector3<f64>, Vector3<f64>) {
    let n = points.len().max(1) as f64;
    let mean: Vector3<f64> = points.iter().sum::<Vector3<f64>>() / n;
    let scatter: Matrix3<f64> = points
        .iter()
        .map(|p| (p - mean) * (p - mean).transpose())
        .sum();
    let eig = SymmetricEigen::new(scatter);
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
    (
        eig.eigenvectors.column(order[0]).into_owned(),
        eig.eigenvectors.column(order[1]).into_owned(),
    )
}

/// The paper's alignment figure: ground truth (dashed green), the trajectory aligned to the
/// start segment (blue) and to the end segment (red); the full trajectory and close-ups of
/// the two segments, viewed top-down (the plane of largest spread).
pub fn alignment_figure(e: &Evaluation, gt: &GroundTruth, path: &Path) -> Result<()> {
    let (Some(s), Some(en)) = (e.start, e.end) else {
        bail!(
            "{}: no alignment figure for a failed run ({})",
            path.display(),
            e.failure.as_ref().map_or(String::new(), |f| f.to_string())
        );
    };
    let start_pts: Vec<Vector3<f64>> = e.positions.iter().map(|p| s.apply(p)).collect();
    let end_pts: Vec<Vector3<f64>> = e.positions.iter().map(|p| en.apply(p)).collect();
    let (ax, ay) = top_down_axes(&start_pts);
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
    let split = |rows: &[[f64; 2]], lo: usize, hi: usize| rows[lo..=hi].to_vec();
    let gt_start = split(&gt_rows, 0, start_last);
    let gt_end = split(&gt_rows, end_first, gt_rows.len() - 1);
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
    let fig = Figure {
        width: 1500,
        height: 560,
        panels: vec![
            (Panel::Chart(start_close), [0.0, 0.0, 0.25, 1.0]),
            (Panel::Chart(full), [0.25, 0.0, 0.5, 1.0]),
            (Panel::Chart(end_close), [0.75, 0.0, 0.25, 1.0]),
        ],
    };
    plot::save(&fig, path)
}
