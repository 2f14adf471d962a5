//! The seeds stage of bench-synthetic: the response calibration over many seeds of small, hard
//! sweeps. The response stage draws one sweep per configuration; a calibration that lands in
//! the wrong optimum on one draw in four passes it unseen. Here every configuration is drawn
//! with several seeds, and the figures are the median and the worst error and the share of
//! failures (an error above [`FAILURE_GREY`] grey values).

use anyhow::Result;
use synthetic::camera::ResponseCurve;
use synthetic::sensor::{NoiseLevel, Sensor, SensorFamily};

use crate::response::run;
use crate::Figure;

/// A calibration whose largest error exceeds this many grey values failed.
const FAILURE_GREY: f64 = 2.0;

/// One configuration: name, sensor, response, JPEG, frame size and number of exposures.
struct Config {
    name: &'static str,
    sensor: Sensor,
    curve: ResponseCurve,
    jpeg: bool,
    size: (usize, usize),
    frames: usize,
}

/// The configurations: high noise stored as JPEG 90 with the dataset's response over 30
/// exposures and a gamma 2.2 response over 8 (exposure steps of x2.35), typical noise as JPEG
/// over 12, and the gain family's high level (a measured DoRF curve, lossless) over 30.
fn configs() -> Vec<Config> {
    let jpeg = |level| Sensor::preset(level).with_jpeg(90);
    vec![
        Config {
            name: "high_jpeg_30",
            sensor: jpeg(NoiseLevel::High),
            curve: ResponseCurve::Dataset,
            jpeg: true,
            size: (320, 256),
            frames: 30,
        },
        Config {
            name: "high_jpeg_gamma_8",
            sensor: jpeg(NoiseLevel::High),
            curve: ResponseCurve::Gamma(2.2),
            jpeg: true,
            size: (640, 512),
            frames: 8,
        },
        Config {
            name: "typical_jpeg_12",
            sensor: jpeg(NoiseLevel::Typical),
            curve: ResponseCurve::Dataset,
            jpeg: true,
            size: (320, 256),
            frames: 12,
        },
        Config {
            name: "gain_high_30",
            sensor: SensorFamily::Gain.preset(NoiseLevel::High),
            curve: ResponseCurve::Dorf(12),
            jpeg: false,
            size: (320, 256),
            frames: 30,
        },
    ]
}

/// The stage: 12 seeds per configuration (6 with `quick`).
pub fn stage(quick: bool) -> Result<Vec<Figure>> {
    let seeds: u64 = if quick { 6 } else { 12 };
    println!(
        "stage seeds: {seeds} seeds of each small sweep (0.05 to 20 ms); failure: largest error above {FAILURE_GREY} grey values"
    );
    let mut figures = Vec::new();
    for c in configs() {
        let opts = photometric::ResponseOptions {
            jpeg: c.jpeg,
            ..Default::default()
        };
        let mut max = Vec::new();
        for seed in 1..=seeds {
            let r = run(
                1000 + seed,
                c.size.0,
                c.size.1,
                c.frames,
                c.sensor,
                c.curve,
                &opts,
            )?;
            max.push(r.max);
        }
        let failures = max.iter().filter(|&&m| m > FAILURE_GREY).count();
        let listed: Vec<String> = max.iter().map(|m| format!("{m:.2}")).collect();
        // the upper of the two middle values for an even number of seeds
        max.sort_by(f64::total_cmp);
        let (median, worst) = (max[max.len() / 2], max[max.len() - 1]);
        println!(
            "  {:<18} {:>12} median {median:>7.3} worst {worst:>8.3} failures {failures}/{seeds}: {}",
            c.name,
            format!("{}x{}x{}", c.size.0, c.size.1, c.frames),
            listed.join(" ")
        );
        let key = |what: &str| format!("response.seeds.{}.{what}", c.name);
        figures.push(Figure::lower(&key("median_max_error"), median, "grey"));
        figures.push(Figure::lower(&key("worst_max_error"), worst, "grey"));
        figures.push(Figure::lower(
            &key("failure_share"),
            failures as f64 / seeds as f64,
            "",
        ));
    }
    Ok(figures)
}
