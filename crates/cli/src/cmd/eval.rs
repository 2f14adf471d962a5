//! `monovo eval`: the loop-closure drift metrics of one run.

use std::path::PathBuf;

use anyhow::Result;
use eval_metrics::{evaluate, TrajectoryFormat};
use monovo_pipelines::{
    evaluation_text, load_ground_truth, load_sequence_ground_truth, load_trajectory,
    save_alignment_figure, EvaluationReport,
};

use crate::plot;

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
  monovo eval run.txt --gt dataset-room1_512_16 --cam 0     # TUM-VI: mocap moved to cam0
  monovo eval run.txt --gt MH_01_easy                       # EuRoC: state csv at the frames
  monovo eval run.txt --gt recording_2020-03-24_17-36-22     # 4Seasons: GNSSPoses.txt

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
    /// The ground truth: groundtruthSync.txt, a TUM-format file, EuRoC's state csv, TUM-VI's
    /// mocap csv, 4Seasons' GNSSPoses.txt; or a sequence folder of any layout, whose own
    /// ground truth is moved to the camera and sampled at its frames.
    #[arg(long, value_name = "FILE|DIR")]
    pub gt: PathBuf,
    /// The camera of a multi-camera dataset given as --gt DIR.
    #[arg(long, default_value_t = 0, value_name = "N")]
    pub cam: usize,
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

impl FormatArg {
    /// The library's format (`None`: guess).
    pub fn format(self) -> Option<TrajectoryFormat> {
        match self {
            FormatArg::Auto => None,
            FormatArg::Tum => Some(TrajectoryFormat::Tum),
            FormatArg::Kitti => Some(TrajectoryFormat::Kitti),
            FormatArg::Euroc => Some(TrajectoryFormat::Euroc),
        }
    }
}

/// Runs `monovo eval`.
pub fn run(args: &Args) -> Result<()> {
    if let Some(p) = &args.plot {
        plot::format_of(p)?;
        dataset_io::check_output_file(p, args.force)?;
    }
    let gt = if args.gt.is_dir() {
        load_sequence_ground_truth(&args.gt, args.cam)?
    } else {
        load_ground_truth(&args.gt)?
    };
    let traj = load_trajectory(
        &args.trajectory,
        args.format.format(),
        args.times.as_deref(),
    )?;
    let e = evaluate(&traj, &gt);
    if let Some(p) = &args.plot {
        save_alignment_figure(&e, &gt, p)?;
    }
    if args.json {
        outln!("{}", serde_json::to_string(&EvaluationReport::from(&e))?)?;
    } else {
        out!(
            "{}",
            evaluation_text(&e, &args.trajectory, args.plot.as_deref())
        )?;
    }
    Ok(())
}
