//! The response stage of bench-synthetic: calibrations of synthetic exposure sweeps at every
//! noise level, lossless and JPEG, large (the paper's 120 exposures) and small (12), against
//! the truth, with the calibration of the standard errors.

use std::time::Instant;

use anyhow::Result;
use camera_model::Image;
use synthetic::camera::ResponseCurve;
use synthetic::scene::{Sweep, SweepConfig};
use synthetic::sensor::{NoiseLevel, Sensor};

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
    reset_peak_rss();
    let t = Instant::now();
    let cal = photometric::calibrate_response(&mut imgs, &sweep.exposures_ms, opts, &|_, _| {})?;
    let seconds = t.elapsed().as_secs_f64();
    let u = cal.response.values();
    let (max, rms) = cal.response.errors_against(&sweep.response);
    let increasing = (1..256).all(|k| u[k] > u[k - 1]);
    if let Ok(path) = std::env::var("MONOVO_DUMP") {
        use std::io::Write;
        let mut f = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(path)?;
        for (k, uk) in u.iter().enumerate().take(256) {
            writeln!(
                f,
                "{} {} {} {} {}",
                width * height * frames,
                k,
                uk - sweep.response[k],
                cal.std_error[k],
                sweep.response[k]
            )?;
        }
    }
    if std::env::var_os("MONOVO_DEBUG_ERR").is_some() {
        for k in (0..256).step_by(8) {
            eprintln!(
                "    k {k:3} err {:+.4} std {:.4}",
                u[k] - sweep.response[k],
                cal.std_error.get(k).copied().unwrap_or(f64::NAN)
            );
        }
    }
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
        peak_mb: peak_rss_mb(),
        increasing,
        within_2sigma: within,
    })
}

/// The configurations: every noise level lossless, and typical and high with JPEG 90.
fn configs(quick: bool) -> Vec<(String, Sensor)> {
    let mut v: Vec<(String, Sensor)> = NoiseLevel::ALL
        .iter()
        .map(|l| (l.name().to_string(), Sensor::preset(*l)))
        .collect();
    v.push((
        "typical_jpeg".into(),
        Sensor::preset(NoiseLevel::Typical).with_jpeg(90),
    ));
    v.push((
        "high_jpeg".into(),
        Sensor::preset(NoiseLevel::High).with_jpeg(90),
    ));
    if quick {
        v.retain(|(n, _)| n == "low" || n == "high_jpeg");
    }
    if let Ok(only) = std::env::var("MONOVO_ONLY_CFG") {
        v.retain(|(n, _)| *n == only);
    }
    v
}

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
    let mut within = (0usize, 0usize);
    println!(
        "  {:<14} {:>16} {:>8} {:>8} {:>6} {:>5} {:>7} {:>8}",
        "sensor", "sweep", "max", "rms", "s", "it", "MB", "in 2sd"
    );
    for (name, sensor) in configs(quick) {
        for (sw, sh, sn, big) in [(w, h, n, true), (320, 256, 12, false)] {
            let r = run(7, sw, sh, sn, sensor, ResponseCurve::Dataset, &opts)?;
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
            within.0 += r.within_2sigma.0;
            within.1 += r.within_2sigma.1;
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
                    let sweep_mb = (sw * sh * sn) as f64 / 1048576.0;
                    figures.push(Figure::lower(
                        "response.peak_memory_over_sweep",
                        r.peak_mb / sweep_mb,
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
    let frac = within.0 as f64 / within.1.max(1) as f64;
    println!(
        "  standard errors: {:.1}% of the true errors within 2 sigma",
        frac * 100.0
    );
    figures.push(Figure {
        key: "response.within_2sigma".into(),
        value: frac,
        unit: "",
        lower_is_better: false,
    });
    figures.push(Figure::lower("response.within_2sigma_excess", frac, ""));
    Ok(figures)
}

/// `cargo xtask response-study`: the response calibration over curves, noise levels and sweep
/// lengths (a grid for choosing defaults; prints one line per run and the worst errors).
pub fn study() -> Result<()> {
    if let Ok(seeds) = std::env::var("MONOVO_SEEDS") {
        let n: u64 = seeds.parse()?;
        let level: NoiseLevel = std::env::var("MONOVO_LEVEL")
            .unwrap_or("high".into())
            .parse()
            .map_err(anyhow::Error::msg)?;
        let q: u8 = std::env::var("MONOVO_Q")
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(90);
        let mut sensor = if q > 100 {
            Sensor::preset(level)
        } else {
            Sensor::preset(level).with_jpeg(q)
        };
        if let Some(v) = std::env::var("MONOVO_FW").ok().and_then(|v| v.parse().ok()) {
            sensor.full_well = v;
        }
        if let Some(v) = std::env::var("MONOVO_ADC")
            .ok()
            .and_then(|v| v.parse().ok())
        {
            sensor.adc_noise = v;
        }
        if let Some(v) = std::env::var("MONOVO_READ")
            .ok()
            .and_then(|v| v.parse().ok())
        {
            sensor.read_noise = v;
        }
        sensor.hot_pixels = 0.0;
        sensor.dead_pixels = 0.0;
        let curve: ResponseCurve = std::env::var("MONOVO_CURVE")
            .unwrap_or("dataset".into())
            .parse()
            .map_err(anyhow::Error::msg)?;
        let opts = photometric::ResponseOptions::default();
        let nf: usize = std::env::var("MONOVO_FRAMES")
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(30);
        for seed in 0..n {
            let factor = (20.0f64 / 0.05).powf(1.0 / (nf - 1) as f64);
            let sweep = Sweep::new(
                seed + 100,
                SweepConfig {
                    width: 320,
                    height: 256,
                    frames: nf,
                    t0: 0.05,
                    factor,
                    sensor,
                    response: curve,
                },
            );
            let mut imgs: Vec<Image<u8>> = (0..nf)
                .map(|i| Ok(Image::new(320, 256, sweep.frame(i)?)?))
                .collect::<Result<_>>()?;
            if std::env::var_os("MONOVO_ORACLE").is_some() {
                let mut sum = vec![0.0f64; 256];
                let mut cnt = vec![0.0f64; 256];
                for (i, f) in imgs.iter().enumerate() {
                    let t = sweep.exposures_ms[i];
                    for (p, &k) in f.data().iter().enumerate() {
                        let e = t * sweep.irradiance[p];
                        let g = synthetic::camera::response_value(&sweep.response, e);
                        if g < 250.0 && k < 255 {
                            let b = g.round() as usize;
                            sum[b] += k as f64 - g;
                            cnt[b] += 1.0;
                        }
                    }
                }
                for b in [100usize, 200, 220, 230, 235, 240, 243, 246, 248] {
                    eprintln!(
                        "  oracle G={b}: mean(I - G(e)) = {:+.4} over {}",
                        sum[b] / cnt[b].max(1.0),
                        cnt[b]
                    );
                }
            }
            let cal =
                photometric::calibrate_response(&mut imgs, &sweep.exposures_ms, &opts, &|_, _| {})?;
            let mut u = *cal.response.values();
            if std::env::var_os("MONOVO_JACK").is_some() {
                let mut halves = Vec::new();
                for par in 0..2 {
                    let mut fr: Vec<Image<u8>> = imgs
                        .iter()
                        .enumerate()
                        .filter(|(i, _)| i % 2 == par)
                        .map(|(_, f)| f.clone())
                        .collect();
                    let ex: Vec<f64> = sweep
                        .exposures_ms
                        .iter()
                        .enumerate()
                        .filter(|(i, _)| i % 2 == par)
                        .map(|(_, e)| *e)
                        .collect();
                    halves.push(
                        *photometric::calibrate_response(&mut fr, &ex, &opts, &|_, _| {})?
                            .response
                            .values(),
                    );
                }
                for k in 0..256 {
                    u[k] = 2.0 * u[k] - 0.5 * (halves[0][k] + halves[1][k]);
                }
            }
            let g = sweep.response[128] / u[128];
            eprintln!(
                "censor {:?} observed {:?}",
                cal.censor_range, cal.observed_range
            );
            let line: Vec<String> = [
                8usize, 32, 64, 96, 160, 192, 200, 208, 216, 224, 228, 232, 236, 240, 244, 248,
                252, 255,
            ]
            .iter()
            .map(|&k| format!("{k}:{:+.3}%", 100.0 * (u[k] * g / sweep.response[k] - 1.0)))
            .collect();
            println!("seed {seed}: {}", line.join(" "));
        }
        return Ok(());
    }
    let opts = photometric::ResponseOptions::default();
    let all = [
        ResponseCurve::Dataset,
        ResponseCurve::Srgb,
        ResponseCurve::Log,
        ResponseCurve::Knee,
    ];
    let curves: Vec<ResponseCurve> = match std::env::var("MONOVO_CURVE") {
        Ok(c) => vec![c.parse().map_err(anyhow::Error::msg)?],
        Err(_) => all.to_vec(),
    };
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
