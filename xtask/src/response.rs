//! The response stage of bench-synthetic: calibrations of synthetic exposure sweeps at every
//! noise level, lossless and JPEG, large (the paper's 120 exposures) and small (12), against
//! the truth, with the calibration of the standard errors.

use std::time::Instant;

use anyhow::Result;
use camera_model::Image;
use synthetic::camera::ResponseCurve;
use synthetic::scene::{Sweep, SweepConfig};
use synthetic::sensor::{NoiseLevel, Sensor, SensorFamily};

use crate::stages::{peak_rss_mb, reset_peak_rss};
use crate::Figure;

/// One calibration of a synthetic sweep and its errors against the truth.
pub struct RunResult {
    /// Largest |U - U_true| over 0..254, both scaled to U(255) = 255.
    pub max: f64,
    /// RMS of the difference after the best scale.
    pub rms: f64,
    /// Wall time of the calibration (frames in memory).
    pub seconds: f64,
    /// Iterations.
    pub iterations: usize,
    /// Peak memory in MB.
    pub peak_mb: f64,
    /// What the calibration added to the process's memory at its peak, in MB (the sweep's
    /// frames were in memory before it began).
    pub added_mb: f64,
    /// Strictly increasing.
    pub increasing: bool,
    /// Values 0..254 whose error is within two standard errors, and how many had one.
    pub within_2sigma: (usize, usize),
}

/// Calibrates a sweep of `frames` exposures from 0.05 to 20 ms.
#[allow(clippy::too_many_arguments)]
pub fn run(
    seed: u64,
    width: usize,
    height: usize,
    frames: usize,
    sensor: Sensor,
    curve: ResponseCurve,
    opts: &photometric::ResponseOptions,
) -> Result<RunResult> {
    let factor = (20.0f64 / 0.05).powf(1.0 / (frames - 1) as f64);
    let sweep = Sweep::new(
        seed,
        SweepConfig {
            width,
            height,
            frames,
            t0: 0.05,
            factor,
            sensor,
            response: curve,
        },
    );
    let mut imgs: Vec<Image<u8>> = (0..frames)
        .map(|i| Ok(Image::new(width, height, sweep.frame(i)?)?))
        .collect::<Result<_>>()?;
    let before = reset_peak_rss();
    let t = Instant::now();
    let cal = photometric::calibrate_response(&mut imgs, &sweep.exposures_ms, opts, &|_, _| {})?;
    let seconds = t.elapsed().as_secs_f64();
    let peak_mb = peak_rss_mb();
    let u = cal.response.values();
    let (max, rms) = cal.response.errors_against(&sweep.response);
    let increasing = (1..256).all(|k| u[k] > u[k - 1]);
    let within = (0..255)
        .filter(|&k| cal.std_error.get(k).is_some_and(|s| *s > 0.0))
        .fold((0, 0), |(a, n), k| {
            let ok = (u[k] - sweep.response[k]).abs() <= 2.0 * cal.std_error[k];
            (a + usize::from(ok), n + 1)
        });
    Ok(RunResult {
        max,
        rms,
        seconds,
        iterations: cal.iterations,
        peak_mb,
        added_mb: (peak_mb - before).max(0.0),
        increasing,
        within_2sigma: within,
    })
}

/// One configuration of the stage: its name, the sensor, the response and whether the
/// frames are JPEG (then the options of a JPEG sequence: clipped blocks dropped).
struct Config {
    name: String,
    sensor: Sensor,
    curve: ResponseCurve,
    jpeg: bool,
}

/// The configurations: both sensor families at every noise level, lossless, and typical and
/// high with JPEG 90. The machine family renders the dataset's response; the gain family
/// (photon noise before the response at a fixed gain, a small ADC noise after it) renders
/// measured camera curves of the DoRF database, a different one per level.
fn configs(quick: bool) -> Vec<Config> {
    let mut v = Vec::new();
    for family in SensorFamily::ALL {
        for (k, level) in NoiseLevel::ALL.iter().enumerate() {
            let curve = match family {
                SensorFamily::Machine => ResponseCurve::Dataset,
                SensorFamily::Gain => ResponseCurve::Dorf(DORF_PER_LEVEL[k]),
            };
            let prefix = match family {
                SensorFamily::Machine => String::new(),
                SensorFamily::Gain => "gain_".to_string(),
            };
            let sensor = family.preset(*level);
            v.push(Config {
                name: format!("{prefix}{}", level.name()),
                sensor,
                curve,
                jpeg: false,
            });
            if *level != NoiseLevel::Low {
                v.push(Config {
                    name: format!("{prefix}{}_jpeg", level.name()),
                    sensor: sensor.with_jpeg(90),
                    curve,
                    jpeg: true,
                });
            }
        }
    }
    if quick {
        v.retain(|c| ["low", "high_jpeg", "gain_high"].contains(&c.name.as_str()));
    }
    v
}

/// The DoRF curve of the gain family at each noise level (low, typical, high): a dark, a
/// middle and a bright curve of the subset.
const DORF_PER_LEVEL: [u8; 3] = [3, 8, 12];

/// The stage.
pub fn stage(quick: bool) -> Result<Vec<Figure>> {
    println!("stage response: synthetic exposure sweeps (0.05 to 20 ms) at every noise level");
    let opts = photometric::ResponseOptions::default();
    let (w, h, n) = if quick {
        (640, 512, 60)
    } else {
        (1280, 1024, 120)
    };
    let mut figures = Vec::new();
    // the standard errors' coverage of each family: [machine, gain]
    let mut within = [(0usize, 0usize); 2];
    println!(
        "  {:<14} {:>16} {:>8} {:>8} {:>6} {:>5} {:>7} {:>8}",
        "sensor", "sweep", "max", "rms", "s", "it", "MB", "in 2sd"
    );
    for Config {
        name,
        sensor,
        curve,
        jpeg,
    } in configs(quick)
    {
        let mut opts = opts.clone();
        opts.jpeg = jpeg;
        for (sw, sh, sn, big) in [(w, h, n, true), (320, 256, 12, false)] {
            let r = run(7, sw, sh, sn, sensor, curve, &opts)?;
            println!(
                "  {name:<14} {:>16} {:>8.3} {:>8.3} {:>6.1} {:>5} {:>7.0} {:>4}/{:<3}",
                format!("{sw}x{sh}x{sn}"),
                r.max,
                r.rms,
                r.seconds,
                r.iterations,
                r.peak_mb,
                r.within_2sigma.0,
                r.within_2sigma.1
            );
            let f = usize::from(name.starts_with("gain_"));
            within[f].0 += r.within_2sigma.0;
            within[f].1 += r.within_2sigma.1;
            if big {
                figures.push(Figure::lower(
                    &format!("response.{name}.max_error"),
                    r.max,
                    "grey",
                ));
                figures.push(Figure::lower(
                    &format!("response.{name}.rms_error"),
                    r.rms,
                    "grey",
                ));
                if name == "high_jpeg" {
                    figures.push(Figure::lower("response.seconds", r.seconds, "s"));
                    // the sweep and what the calibration adds to it, over the sweep: not the
                    // rest of the process's memory (the binary, earlier stages' data)
                    let sweep_mb = (sw * sh * sn) as f64 / 1048576.0;
                    figures.push(Figure::lower(
                        "response.peak_memory_over_sweep",
                        (sweep_mb + r.added_mb) / sweep_mb,
                        "",
                    ));
                }
            } else {
                figures.push(Figure::lower(
                    &format!("response.{name}.small_max_error"),
                    r.max,
                    "grey",
                ));
                figures.push(Figure::lower(
                    &format!("response.{name}.small_not_increasing"),
                    f64::from(u8::from(!r.increasing)),
                    "",
                ));
            }
        }
    }
    let frac = within[0].0 as f64 / within[0].1.max(1) as f64;
    println!(
        "  standard errors, machine family: {:.1}% of the true errors within 2 sigma",
        frac * 100.0
    );
    figures.push(Figure {
        key: "response.within_2sigma".into(),
        value: frac,
        unit: "",
        lower_is_better: false,
    });
    if within[1].1 > 0 {
        let gain = within[1].0 as f64 / within[1].1 as f64;
        println!(
            "  standard errors, gain family: {:.1}% of the true errors within 2 sigma",
            gain * 100.0
        );
        figures.push(Figure {
            key: "response.gain.within_2sigma".into(),
            value: gain,
            unit: "",
            lower_is_better: false,
        });
    }
    figures.push(Figure::lower("response.within_2sigma_excess", frac, ""));
    Ok(figures)
}

/// `cargo xtask response-study`: the response calibration over curves, noise levels and sweep
/// lengths (a grid for choosing defaults; prints one line per run and the worst errors).
pub fn study() -> Result<()> {
    let opts = photometric::ResponseOptions::default();
    let all = [
        ResponseCurve::Dataset,
        ResponseCurve::Srgb,
        ResponseCurve::Log,
        ResponseCurve::Knee,
    ];
    let curves: Vec<ResponseCurve> = all.to_vec();
    let sensors = [
        ("typical", Sensor::preset(NoiseLevel::Typical)),
        ("high_jpeg", Sensor::preset(NoiseLevel::High).with_jpeg(90)),
    ];
    let mut worst_small: f64 = 0.0;
    let mut worst_big: f64 = 0.0;
    let mut within = (0usize, 0usize);
    for &curve in &curves {
        for (name, sensor) in sensors {
            for (w, h, n) in [(320, 256, 12), (320, 256, 30), (640, 512, 60)] {
                let r = run(3, w, h, n, sensor, curve, &opts)?;
                println!(
                    "  {:<8} {name:<10} {w}x{h}x{n:<4} max {:>7.3} rms {:>6.3} it {:>3} in2sd {}/{}",
                    curve.name(),
                    r.max,
                    r.rms,
                    r.iterations,
                    r.within_2sigma.0,
                    r.within_2sigma.1
                );
                if n <= 12 {
                    worst_small = worst_small.max(r.max);
                } else {
                    worst_big = worst_big.max(r.max);
                }
                within.0 += r.within_2sigma.0;
                within.1 += r.within_2sigma.1;
            }
        }
    }
    println!(
        "worst max: 12 frames {worst_small:.3}, more frames {worst_big:.3}; within 2 sigma {:.1}%",
        100.0 * within.0 as f64 / within.1.max(1) as f64
    );
    Ok(())
}
