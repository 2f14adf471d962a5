//! What `monovo ape`, `monovo rpe` and `monovo kitti` share: the input files, evo's alignment
//! and association options (its underscore spellings accepted as aliases of the kebab-case
//! ones), and the outputs (JSON, figure, evo result zip).

use std::path::{Path, PathBuf};

use anyhow::{bail, Result};
use eval_metrics::{AlignOptions, PoseRelation, SyncMethod, TrajectoryFormat};
use monovo_pipelines::{metric_figure, save_evo_result, MetricArgs, MetricReport, PlotX, Spelling};

use crate::plot;

/// The input files: `[FORMAT] REF EST`.
#[derive(clap::Args, Debug)]
pub struct Inputs {
    /// The reference (ground truth) and the estimate: `REF EST`, optionally preceded by
    /// evo's format word (`tum`, `kitti`, `euroc`). TUM (`t x y z qx qy qz qw`), EuRoC csv
    /// and KITTI pose files (12 numbers a line, paired by line) are recognised by their
    /// first line.
    #[arg(value_name = "[FORMAT] REF EST", num_args = 2..=3, required = true)]
    pub files: Vec<PathBuf>,
}

impl Inputs {
    /// `(format, reference, estimate)`.
    pub fn resolve(&self) -> Result<(Option<TrajectoryFormat>, &Path, &Path)> {
        match self.files.as_slice() {
            [r, e] => Ok((None, r, e)),
            [f, r, e] => {
                let format = match f.to_str() {
                    Some("tum") => Some(TrajectoryFormat::Tum),
                    Some("kitti") => Some(TrajectoryFormat::Kitti),
                    // evo's `euroc` mode: the reference a EuRoC csv, the estimate TUM; the
                    // formats are recognised per file
                    Some("euroc") => None,
                    _ => bail!(
                        "`{}`: expected REF EST, or a format word (tum, kitti, euroc) followed by REF EST",
                        f.display()
                    ),
                };
                Ok((format, r, e))
            }
            _ => bail!("expected REF EST"),
        }
    }
}

/// evo's pose relations.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum RelationArg {
    /// Translation of the error pose (APE: the distance between the positions).
    #[value(name = "trans_part", alias = "trans-part")]
    TransPart,
    /// Frobenius norm of R_E - I.
    #[value(name = "rot_part", alias = "rot-part")]
    RotPart,
    /// Frobenius norm of E - I (4x4).
    Full,
    /// Rotation angle of the error pose in degrees.
    #[value(name = "angle_deg", alias = "angle-deg")]
    AngleDeg,
    /// Rotation angle of the error pose in radians.
    #[value(name = "angle_rad", alias = "angle-rad")]
    AngleRad,
    /// Distance between positions (APE); difference of the distances of a pair (RPE).
    #[value(name = "point_distance", alias = "point-distance")]
    PointDistance,
    /// RPE: the point distance error over the reference's distance, in percent.
    #[value(
        name = "point_distance_error_ratio",
        alias = "point-distance-error-ratio"
    )]
    PointDistanceErrorRatio,
}

impl RelationArg {
    /// The library's relation.
    pub fn relation(self) -> PoseRelation {
        match self {
            RelationArg::TransPart => PoseRelation::TransPart,
            RelationArg::RotPart => PoseRelation::RotPart,
            RelationArg::Full => PoseRelation::Full,
            RelationArg::AngleDeg => PoseRelation::AngleDeg,
            RelationArg::AngleRad => PoseRelation::AngleRad,
            RelationArg::PointDistance => PoseRelation::PointDistance,
            RelationArg::PointDistanceErrorRatio => PoseRelation::PointDistanceErrorRatio,
        }
    }
}

/// evo's alignment options, and the 4-DoF one.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct AlignArgs {
    /// Align the estimate to the reference by least squares, rotation and translation
    /// (Umeyama; `-as` adds the scale: Sim(3)).
    #[arg(short = 'a', long)]
    pub align: bool,
    /// Correct the scale (Umeyama): with -a a Sim(3) alignment, alone only the scale.
    #[arg(short = 's', long = "correct-scale", alias = "correct_scale")]
    pub correct_scale: bool,
    /// Align with the first N pose pairs only (-1: all).
    #[arg(
        long = "n-to-align",
        alias = "n_to_align",
        value_name = "N",
        default_value_t = -1,
        allow_negative_numbers = true
    )]
    pub n_to_align: i64,
    /// Move the first estimated pose onto the first reference pose.
    #[arg(
        long = "align-origin",
        alias = "align_origin",
        conflicts_with = "align"
    )]
    pub align_origin: bool,
    /// 4-DoF alignment of visual-inertial runs: translation and yaw about the reference's
    /// z axis (rpg_trajectory_evaluation's posyaw; with --n-to-align 1 from the first pose).
    #[arg(
        long,
        aliases = ["align-yaw", "align_yaw", "4dof"],
        conflicts_with_all = ["align", "correct_scale", "align_origin"]
    )]
    pub posyaw: bool,
}

impl AlignArgs {
    /// Sets the alignment options.
    pub fn apply(&self, a: &mut MetricArgs) {
        a.align = self.align;
        a.correct_scale = self.correct_scale;
        a.n_to_align = self.n_to_align;
        a.align_origin = self.align_origin;
        a.posyaw = self.posyaw;
    }

    /// The library's alignment options.
    pub fn options(&self) -> Result<AlignOptions> {
        let mut a = MetricArgs::default();
        self.apply(&mut a);
        a.align_options(Spelling::Flags).map_err(anyhow::Error::msg)
    }
}

/// How poses are paired by time.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum SyncArg {
    /// The nearest stamp within --t-max-diff.
    #[default]
    #[value(name = "nearest_time", alias = "nearest-time")]
    NearestTime,
    /// The denser trajectory interpolated at the stamps of the sparser one.
    Interpolation,
}

/// evo's association options.
#[derive(clap::Args, Debug, Clone)]
pub struct SyncArgs {
    /// Largest time difference of an associated pair, seconds (evo: 0.01; --tum: 0.02).
    #[arg(
        long = "t-max-diff",
        aliases = ["t_max_diff", "max_difference", "max-difference"],
        value_name = "S"
    )]
    pub t_max_diff: Option<f64>,
    /// Added to the estimate's timestamps before association, seconds.
    #[arg(
        long = "t-offset",
        aliases = ["t_offset", "offset"],
        value_name = "S",
        default_value_t = 0.0,
        allow_negative_numbers = true
    )]
    pub t_offset: f64,
    /// Nearest stamp, or interpolation of the denser trajectory.
    #[arg(
        long = "sync-method",
        alias = "sync_method",
        value_enum,
        default_value_t
    )]
    pub sync_method: SyncArg,
    /// Only reference poses at or after this time.
    #[arg(
        long = "t-start",
        alias = "t_start",
        value_name = "S",
        allow_negative_numbers = true
    )]
    pub t_start: Option<f64>,
    /// Only reference poses at or before this time.
    #[arg(
        long = "t-end",
        alias = "t_end",
        value_name = "S",
        allow_negative_numbers = true
    )]
    pub t_end: Option<f64>,
}

impl SyncArgs {
    /// Sets the association options.
    pub fn apply(&self, a: &mut MetricArgs) {
        a.t_max_diff = self.t_max_diff;
        a.t_offset = self.t_offset;
        a.sync_method = match self.sync_method {
            SyncArg::NearestTime => SyncMethod::NearestTime,
            SyncArg::Interpolation => SyncMethod::Interpolation,
        };
        a.t_start = self.t_start;
        a.t_end = self.t_end;
    }
}

/// The x axis of the error chart.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum PlotXArg {
    /// Seconds from the first compared pose.
    #[default]
    Seconds,
    /// Distance along the reference.
    Distances,
    /// Error index.
    Index,
}

/// The outputs.
#[derive(clap::Args, Debug, Clone)]
pub struct OutputArgs {
    /// Print exactly one JSON object: rmse, mean, median, std, min, max, sse, n and more.
    #[arg(long)]
    pub json: bool,
    /// Draw the error over time (or distance) and the aligned trajectories (.png or .svg).
    #[arg(long, alias = "save_plot", value_name = "FILE")]
    pub plot: Option<PathBuf>,
    /// The x axis of the error chart.
    #[arg(
        long = "plot-x",
        alias = "plot_x_dimension",
        value_enum,
        default_value_t
    )]
    pub plot_x: PlotXArg,
    /// Write evo's result zip (info.json, stats.json, the error arrays), which `evo_res`
    /// reads to compare runs.
    #[arg(long = "save-results", alias = "save_results", value_name = "FILE.zip")]
    pub save_results: Option<PathBuf>,
    /// Replace existing --plot and --save-results files.
    #[arg(long)]
    pub force: bool,
    /// Accepted for evo compatibility; monovo never asks (existing files need --force).
    #[arg(long = "no-warnings", alias = "no_warnings", hide = true)]
    pub no_warnings: bool,
    /// Accepted for evo compatibility (no effect).
    #[arg(short = 'v', long, hide = true)]
    pub verbose: bool,
    /// Accepted for evo compatibility (no effect).
    #[arg(long, hide = true)]
    pub silent: bool,
}

impl OutputArgs {
    /// Checks every output location before any work.
    pub fn check(&self) -> Result<()> {
        if let Some(p) = &self.plot {
            plot::format_of(p)?;
            dataset_io::check_output_file(p, self.force)?;
        }
        if let Some(p) = &self.save_results {
            if p.extension().and_then(|e| e.to_str()) != Some("zip") {
                bail!(
                    "{}: evo's result files are zip files: use a file name ending in .zip",
                    p.display()
                );
            }
            dataset_io::check_output_file(p, self.force)?;
        }
        Ok(())
    }

    /// Writes the figure and the result zip, then prints the report.
    pub fn finish(&self, report: &MetricReport) -> Result<()> {
        if let Some(p) = &self.plot {
            let x = match self.plot_x {
                PlotXArg::Seconds => PlotX::Seconds,
                PlotXArg::Distances => PlotX::Distances,
                PlotXArg::Index => PlotX::Index,
            };
            plot::save(&metric_figure(report, x), p)?;
        }
        if let Some(p) = &self.save_results {
            save_evo_result(report, p)?;
        }
        if self.json {
            outln!("{}", serde_json::to_string(report)?)?;
        } else {
            out!("{}", report.text())?;
            if let Some(p) = &self.plot {
                outln!("{:>10}\t{}", "plot", p.display())?;
            }
            if let Some(p) = &self.save_results {
                outln!("{:>10}\t{}", "results", p.display())?;
            }
        }
        Ok(())
    }
}
