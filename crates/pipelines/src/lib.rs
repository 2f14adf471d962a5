//! The end-to-end jobs of the monovo toolkit, composed from the library crates and callable
//! from Rust: evaluate a results tree into results.csv ([`evaluate_tree`]), run an experiment
//! manifest into the paper's grouped cumulative plots and tables ([`run_experiment`]), check
//! and estimate exposure times from the images ([`exposure`]), inspect a sequence folder
//! ([`inspect_sequence`]), explain a camera.txt ([`summarize_camera`]), and draw the paper's
//! figures ([`paper`], [`alignment_figure`]). The `monovo` command is a thin layer over this
//! crate: it parses arguments, prints the reports' text or JSON and shows progress through an
//! [`Observer`].
//!
//! ```
//! use monovo_pipelines::{cumulative_chart, Experiment};
//! use eval_metrics::{parse_csv, DirectionFilter, Metric, CSV_HEADER};
//!
//! let csv = format!("{CSV_HEADER}\nm,sequence_01,fwd,0,ok,0.5,1.1,2,1,1,0.1,0.1,100,\n");
//! let chart = cumulative_chart(&parse_csv(&csv)?, Metric::EAlign, DirectionFilter::Both);
//! assert_eq!(chart.series.len(), 1);
//!
//! let manifest = "dataset = \"dataset\"\nresults = \"results\"\n[[method]]\nname = \"m\"\n";
//! let exp = Experiment::parse(manifest, "exp.toml".as_ref(), "synth".as_ref())?;
//! assert_eq!(exp.variations[0].results, std::path::Path::new("synth/results"));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

#![deny(missing_docs)]

mod batch;
mod boxplot;
pub mod calib;
pub mod camera;
pub mod demo;
mod error;
mod eval;
pub mod experiment;
pub mod exposure;
mod inspect;
mod metric_args;
mod metric_figures;
mod metric_table;
mod observe;
pub mod paper;
pub mod rectify;
pub mod synth;
mod traj_metrics;

pub use batch::{
    computed_metrics, evaluate_tree, load_results, Batch, BatchOptions, BatchSummary, MethodCount,
    StrayFile,
};
pub use boxplot::{box_chart, method_box_figure, BoxStats};
pub use camera::{summarize_camera, CameraSummary};
pub use error::{error_chain, json_number, PipelineError, Result, WithContext};
pub use eval::{
    alignment_figure, evaluation_text, load_ground_truth, load_sequence_ground_truth,
    load_trajectory, save_alignment_figure, EvaluationReport,
};
pub use experiment::{run_experiment, Experiment, ExperimentReport, Layout};
pub use inspect::{inspect_sequence, read_vignette, SequenceInfo};
pub use metric_args::{MetricArgs, RpeUnit, Spelling};
pub use metric_figures::{kitti_figure, metric_figure, PlotX};
pub use metric_table::MetricTable;
pub use monovo_figures as figures;
pub use observe::{Observer, Silent};
pub use paper::{cumulative_chart, method_medians, metric_study_figure, MethodMedians};
pub use traj_metrics::{
    kitti_pairs, kitti_report, load_track, metric_report, run_kitti, run_metric, save_evo_result,
    AlignmentReport, KittiReport, MetricReport, PlotData,
};

/// The guide's Rust examples (docs/architecture.md), compiled as doctests of this crate
/// (which depends on every crate they use).
#[cfg(doctest)]
#[doc = include_str!("../../../docs/architecture.md")]
pub struct GuideDoctests;
