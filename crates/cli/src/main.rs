//! `monovo`: read, rectify, calibrate and evaluate the TUM monoVO benchmark.
//!
//! The binary is thin: it parses arguments, calls the library crates and prints.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

#[macro_use]
mod out;
mod alloc;
mod cmd;
mod interrupt;
mod plot;
mod progress;

/// monovo: the photometrically calibrated monocular VO benchmark, as one fast command.
///
/// Read and rectify the benchmark's sequences, calibrate response and vignetting of your own
/// camera, and score trajectories with the paper's loop-closure drift metrics and the field's
/// other metrics (APE and RPE as evo and the TUM scripts define them, KITTI's segment errors).
#[derive(Parser, Debug)]
#[command(name = "monovo", version, about, long_about = None, propagate_version = true)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Run the whole benchmark end to end on synthetic data with known truth (start here).
    Demo(cmd::demo::Args),
    /// Show a camera.txt: the input model and the output pinhole camera it rectifies to.
    Camera(cmd::camera::Args),
    /// What a sequence folder holds: frames, timing, exposures, camera, calibration, ground truth.
    Info(cmd::info::Args),
    /// Rectify a sequence to a pinhole camera (and undo response and vignetting) as a new sequence.
    Rectify(cmd::rectify::Command),
    /// Calibrate the response (and the vignette) of your own camera.
    Calib(cmd::calib::Args),
    /// Check logged exposure times against the images, or estimate missing ones.
    Exposure(cmd::exposure::Args),
    /// Score one trajectory with the paper's loop-closure drift metrics.
    Eval(cmd::eval::Args),
    /// Absolute pose error (APE/ATE) as evo computes it, or the TUM RGB-D script (--tum).
    Ape(cmd::ape::Args),
    /// Relative pose error (RPE) as evo computes it, or the TUM RGB-D script (--tum).
    Rpe(cmd::rpe::Args),
    /// The KITTI odometry devkit's segment errors (% and deg/100m over 100..800 m).
    Kitti(cmd::kitti::Args),
    /// Score every run of a results tree in parallel into results.csv.
    EvalBatch(cmd::eval_batch::Args),
    /// Evaluate methods and variations named in a TOML manifest into grouped plots and tables.
    Experiment(cmd::experiment::Args),
    /// Draw the paper's cumulative error plots, or print its per-sequence table.
    Plot(cmd::plot::Args),
    /// Generate synthetic data with known ground truth (fixed seed).
    Synth(cmd::synth::Args),
}

/// Prints a warning to stderr (`monovo: warning: ...`).
pub(crate) fn warn(args: std::fmt::Arguments<'_>) {
    use std::io::Write;
    let _ = writeln!(std::io::stderr().lock(), "monovo: warning: {args}");
}

/// The error and its causes, each printed once: a cause whose text the message already ends
/// with (an I/O error that its wrapper prints as well) is left out.
fn error_chain(e: &anyhow::Error) -> String {
    let mut msg = String::new();
    for cause in e.chain() {
        let text = cause.to_string();
        if text.is_empty() || msg.ends_with(&text) {
            continue;
        }
        if !msg.is_empty() {
            msg.push_str(": ");
        }
        msg.push_str(&text);
    }
    msg
}

fn main() -> ExitCode {
    alloc::tune();
    interrupt::install();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Demo(args) => cmd::demo::run(&args),
        Command::Camera(args) => cmd::camera::run(&args),
        Command::Info(args) => cmd::info::run(&args),
        Command::Rectify(args) => cmd::rectify::run_command(&args),
        Command::Calib(args) => cmd::calib::run(&args),
        Command::Exposure(args) => cmd::exposure::run(&args),
        Command::Eval(args) => cmd::eval::run(&args),
        Command::Ape(args) => cmd::ape::run(&args),
        Command::Rpe(args) => cmd::rpe::run(&args),
        Command::Kitti(args) => cmd::kitti::run(&args),
        Command::EvalBatch(args) => cmd::eval_batch::run(&args),
        Command::Experiment(args) => cmd::experiment::run(&args),
        Command::Plot(args) => cmd::plot::run(&args),
        Command::Synth(args) => cmd::synth::run(&args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        // the reader went away (`monovo ... | head`): nothing more to say to anyone
        Err(e) if out::is_broken_pipe(&e) => ExitCode::SUCCESS,
        Err(e) => {
            use std::io::Write;
            let _ = writeln!(
                std::io::stderr().lock(),
                "monovo: error: {}",
                error_chain(&e)
            );
            ExitCode::FAILURE
        }
    }
}
