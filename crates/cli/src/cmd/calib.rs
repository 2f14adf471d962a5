//! `monovo calib`: photometric calibration of your own camera.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use camera_model::Image;
use dataset_io::Sequence;
use photometric::{calibrate_response, ResponseOptions};

use crate::plot::{self, Chart, Corner, Figure, Panel, Series, PALETTE};
use crate::progress;

/// Arguments of `monovo calib`.
#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(subcommand)]
    pub what: What,
}

/// What to calibrate.
#[derive(clap::Subcommand, Debug)]
pub enum What {
    /// The inverse response U (pcalib.txt) from a static scene at varying, known exposures.
    #[command(after_help = "\
Record a static scene with a wide range of grey values while the exposure changes slowly
(the paper: 1000 images, 120 exposures from 0.05 to 20 ms in steps of 1.05). SEQ holds the
images and times.txt with the exposure of every frame.

  monovo calib response sweep -o pcalib.txt --plot response.png

The method is the paper's alternating least squares (U(k) = mean of t B' over pixels of
value k; B' = sum t U(I) / sum t^2), iterated until the energy changes by less than
--tolerance. Saturated pixels and a small border around them are dropped; observations above
grey value 245 do not enter B' (saturation censors the noise there and would bias it);
values never observed are interpolated or extrapolated; the result is scaled to U(255)=255
and is always finite and strictly increasing. --smoothness adds a second-difference prior
for small data sets (0 = the paper's unregularised method).")]
    Response(ResponseArgs),
}

/// Arguments of `monovo calib response`.
#[derive(clap::Args, Debug)]
pub struct ResponseArgs {
    /// The sweep sequence folder (images + times.txt with exposures).
    pub sequence: PathBuf,
    /// The pcalib.txt to write.
    #[arg(short, long, value_name = "FILE")]
    pub output: PathBuf,
    /// Iteration limit.
    #[arg(long, default_value_t = ResponseOptions::default().max_iterations)]
    pub max_iterations: usize,
    /// Relative energy change at which the iteration stops.
    #[arg(long, default_value_t = ResponseOptions::default().tolerance)]
    pub tolerance: f64,
    /// Weight of the smoothness prior (relative to the mean observations per grey value).
    #[arg(long, default_value_t = ResponseOptions::default().smoothness)]
    pub smoothness: f64,
    /// Plot U and the histogram of observed values (.png or .svg).
    #[arg(long, value_name = "FILE")]
    pub plot: Option<PathBuf>,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
}

/// Reads every frame of a sequence with its exposure; errors when exposures are missing.
pub fn load_exposed_frames(seq: &Sequence) -> Result<(Vec<Image<u8>>, Vec<f64>)> {
    if !seq.times().has_exposures() {
        bail!(
            "{}: calibration needs the exposure time of every frame (third column, > 0)",
            seq.times_path().display()
        );
    }
    let idx = seq.indices(0..seq.len(), false);
    let pb = progress::bar(idx.len() as u64, "decoding");
    let mut frames = Vec::with_capacity(idx.len());
    let mut exposures = Vec::with_capacity(idx.len());
    seq.process(
        &idx,
        rayon::current_num_threads() * 4,
        Ok::<_, anyhow::Error>,
        |f| {
            exposures.push(f.exposure_ms.unwrap_or(0.0));
            frames.push(f.image);
            pb.inc(1);
            Ok(())
        },
    )?;
    pb.finish_and_clear();
    Ok((frames, exposures))
}

fn run_response(a: &ResponseArgs) -> Result<()> {
    let seq = Sequence::open(&a.sequence)?;
    if seq.len() < 2 {
        bail!(
            "{}: response calibration needs at least 2 frames at different exposures, found {}",
            a.sequence.display(),
            seq.len()
        );
    }
    let (mut frames, exposures) = load_exposed_frames(&seq)?;
    let opts = ResponseOptions {
        max_iterations: a.max_iterations.max(1),
        tolerance: a.tolerance,
        smoothness: a.smoothness.max(0.0),
        ..ResponseOptions::default()
    };
    let pb = progress::bar(opts.max_iterations as u64, "iterating");
    let cal = calibrate_response(&mut frames, &exposures, &opts, &|i, e| {
        pb.set_position(i as u64);
        pb.set_message(format!("E={e:.4e}"));
    })
    .with_context(|| format!("{}", a.sequence.display()))?;
    pb.finish_and_clear();
    dataset_io::write_atomic(&a.output, cal.response.to_text().as_bytes())?;
    if let Some(p) = &a.plot {
        response_figure(&cal, None, p)?;
    }
    if a.json {
        println!(
            "{}",
            serde_json::json!({
                "output": a.output.display().to_string(),
                "iterations": cal.iterations,
                "converged": cal.converged,
                "rmse": cal.rmse,
                "observed_min": cal.observed_range.0,
                "observed_max": cal.observed_range.1,
                "filled": cal.filled,
                "frames": frames.len(),
            })
        );
    } else {
        println!(
            "{} after {} iterations ({}), residual RMSE {:.3} grey values",
            if cal.converged {
                "converged"
            } else {
                "stopped"
            },
            cal.iterations,
            if cal.converged {
                "tolerance reached"
            } else {
                "iteration limit"
            },
            cal.rmse
        );
        println!(
            "observed grey values {}..{}; {} value(s) filled by interpolation/extrapolation",
            cal.observed_range.0,
            cal.observed_range.1,
            cal.filled.len() + 1
        );
        println!("wrote {}", a.output.display());
    }
    Ok(())
}

/// Plots U (and the truth, when known) beside the histogram of observed grey values.
pub fn response_figure(
    cal: &photometric::ResponseCalibration,
    truth: Option<&[f64; 256]>,
    path: &std::path::Path,
) -> Result<()> {
    let u = cal.response.values();
    let mut c1 = Chart::new(
        "inverse response U",
        "grey value I",
        "U(I) (scaled to U(255)=255)",
    );
    c1.legend = Some(Corner::TopLeft);
    c1.x_range = Some([0.0, 255.0]);
    c1.series.push(Series::line(
        "U estimated",
        (0..256).map(|k| [k as f64, u[k]]).collect(),
        PALETTE[0],
    ));
    if let Some(t) = truth {
        c1.series.push(
            Series::line(
                "U true",
                (0..256).map(|k| [k as f64, t[k]]).collect(),
                PALETTE[2],
            )
            .dashed(),
        );
    }
    c1.series
        .push(Series::line("linear", vec![[0.0, 0.0], [255.0, 255.0]], PALETTE[7]).dashed());
    let mut c2 = Chart::new(
        "observed grey values",
        "grey value I",
        "observations (log10)",
    );
    c2.legend = None;
    c2.x_range = Some([0.0, 255.0]);
    let hist: Vec<[f64; 2]> = cal
        .histogram
        .iter()
        .take(255)
        .enumerate()
        .flat_map(|(k, &c)| {
            let v = (c as f64).max(1.0).log10();
            [[k as f64, v], [k as f64 + 1.0, v]]
        })
        .collect();
    c2.series.push(Series::line("", hist, PALETTE[1]));
    let fig = Figure {
        width: 1200,
        height: 500,
        panels: vec![
            (Panel::Chart(c1), [0.0, 0.0, 0.5, 1.0]),
            (Panel::Chart(c2), [0.5, 0.0, 0.5, 1.0]),
        ],
    };
    plot::save(&fig, path)
}

/// Runs `monovo calib`.
pub fn run(args: &Args) -> Result<()> {
    match &args.what {
        What::Response(a) => run_response(a),
    }
}
