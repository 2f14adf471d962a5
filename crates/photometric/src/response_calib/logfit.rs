//! The log-domain estimator of Debevec and Malik (1997), a candidate of the held-out check:
//! `g = ln U` and every pixel's `ln B'` by weighted least squares on `g(I) = ln B' + ln t`,
//! with the hat weights `h(I) = min(I, 255 - I) + 1` and a second-difference prior weighted
//! by `h`. Every knot is informed by the values observed there, so a tone-mapping camera
//! (phones, raw converters, film) whose data no global `G` explains cannot leave a plateau
//! in `U` that no prediction visits; the weights trust the middle of the range, where such
//! curves are closest to one global function. It fits the grey-domain model's data worse
//! than the maximum-likelihood fit when the model holds, and the check keeps that fit then.
//!
//! The estimate uses every sampled pixel (not 70) with the values the grey-domain fit uses, or
//! also those it drops next to saturated pixels ([`Data::all`]), the clipped values (0 and
//! saturated) not at all, and `ln B'` profiled out: the normal equations of `g` alone, one `n x n` system.
//! The prior's weight grows with the square root of the pixels, so that `lambda` means what
//! it means in Debevec's 70-pixel solve.

use nalgebra::{DMatrix, DVector};

use super::model::{Forward, Obs};
use super::prior::make_monotone;
use super::samples::{Levels, Samples};
use crate::noise::interp;
use crate::PhotometricError;

/// The pixel count at which `lambda` is Debevec's.
const REFERENCE_PIXELS: f64 = 70.0;

/// A log-domain fit.
pub(super) struct LogFit {
    /// `U` at the knots, strictly increasing, `U(0) = 0`, on the gauge `U(top) = 255`.
    pub u: Vec<f64>,
    /// Standard error of `ln U(k) - ln U(top)` from the residuals' spread (the misfit of the
    /// model included), per knot.
    pub se_log: Vec<f64>,
}

/// The hat weight of a value at knot position `pos` (in 8-bit grey values, 1 at the ends).
#[inline]
fn hat(pos: f64, lv: &Levels) -> f64 {
    let g = pos / (lv.knots - 1) as f64 * 255.0;
    g.min(255.0 - g).max(0.0) + 1.0
}

/// What a log-domain fit sees.
#[derive(Clone, Copy)]
pub(super) struct Data<'a> {
    pub samples: &'a Samples,
    pub exposures: &'a [f64],
    /// Frames that enter (`None`: all).
    pub train: Option<&'a [bool]>,
    pub levels: &'a Levels,
    /// Also the values the grey-domain fit drops (next to saturated pixels, where a sensor
    /// blooms and JPEG rings: on some cameras they carry the bright end, on others no response
    /// describes them; the held-out check decides).
    pub all: bool,
}

/// One pixel's observations that enter: (knot, fraction, weight, ln t).
fn observations(d: &Data<'_>, px: usize, out: &mut Vec<(usize, f64, f64, f64)>) {
    out.clear();
    let (s, lv, exposures) = (d.samples, d.levels, d.exposures);
    let n = lv.knots;
    for (i, v) in s.pixel(px).iter().enumerate() {
        if (!d.all && s.is_excluded(px, i)) || d.train.is_some_and(|t| !t[i]) {
            continue;
        }
        if let Obs::Value(pos) = Obs::of(u32::from(v), lv) {
            let j = (pos as usize).min(n - 2);
            let h = hat(pos, lv);
            out.push((j, pos - j as f64, h * h, exposures[i].ln()));
        }
    }
}

/// The normal equations of `g = ln U` with every pixel's `ln B'` eliminated (no prior yet).
pub(super) struct Normal {
    h: DMatrix<f64>,
    rhs: DVector<f64>,
    /// Pixels with two or more observations, and their observations.
    pixels: usize,
    count: usize,
}

/// The normal equations from the data.
pub(super) fn normal(d: &Data<'_>) -> Result<Normal, PhotometricError> {
    let n = d.levels.knots;
    let mut h = DMatrix::<f64>::zeros(n, n);
    let mut rhs = DVector::<f64>::zeros(n);
    let mut obs = Vec::new();
    let mut a: Vec<(usize, f64)> = Vec::new();
    let mut pixels = 0usize;
    let mut count = 0usize;
    for px in 0..d.samples.len() {
        observations(d, px, &mut obs);
        if obs.len() < 2 {
            continue;
        }
        pixels += 1;
        count += obs.len();
        a.clear();
        let (mut c, mut sw) = (0.0, 0.0);
        for &(j, f, w, lt) in &obs {
            for (k, e) in [(j, 1.0 - f), (j + 1, f)] {
                if e == 0.0 {
                    continue;
                }
                for (k2, e2) in [(j, 1.0 - f), (j + 1, f)] {
                    h[(k, k2)] += w * e * e2;
                }
                rhs[k] += w * e * lt;
                a.push((k, w * e));
            }
            c += w * lt;
            sw += w;
        }
        for &(k, ak) in &a {
            for &(k2, ak2) in &a {
                h[(k, k2)] -= ak * ak2 / sw;
            }
            rhs[k] -= ak * c / sw;
        }
    }
    if pixels == 0 {
        return Err(PhotometricError::Calibration(
            "no pixel has two unsaturated observations".into(),
        ));
    }
    Ok(Normal {
        h,
        rhs,
        pixels,
        count,
    })
}

/// `g` with the prior's `lambda` (0 at the knot of grey value 128), the free knots and the
/// Cholesky factor of their normal matrix, and the matrix's diagonal.
type Solved = (
    Vec<f64>,
    Vec<usize>,
    nalgebra::Cholesky<f64, nalgebra::Dyn>,
    Vec<f64>,
);

fn solve_g(eq: &Normal, lv: &Levels, lambda: f64) -> Result<Solved, PhotometricError> {
    let n = lv.knots;
    let mut h = eq.h.clone();
    // the prior: lambda h(k) g''(k), per 8-bit grey value squared (knots of step `d`: the
    // second difference is d^2 g'', and there are 1/d rows per grey value)
    let d = 255.0 / (n - 1) as f64;
    let s_prior = lambda * (eq.pixels as f64 / REFERENCE_PIXELS).sqrt() * d.powf(-1.5);
    for k in 1..n - 1 {
        let w = s_prior * hat(k as f64, lv);
        let row = [(k - 1, w), (k, -2.0 * w), (k + 1, w)];
        for &(i, wi) in &row {
            for &(j, wj) in &row {
                h[(i, j)] += wi * wj;
            }
        }
    }
    let fixed = lv.knot(128 * lv.top / 255);
    let free: Vec<usize> = (0..n).filter(|&k| k != fixed).collect();
    let m = free.len();
    let hf = DMatrix::from_fn(m, m, |i, j| h[(free[i], free[j])]);
    let trace = (0..m).map(|i| hf[(i, i)]).sum::<f64>() / m as f64;
    let hf = hf + DMatrix::identity(m, m) * (1e-10 * trace.max(1e-300));
    let rf = DVector::from_fn(m, |i, _| eq.rhs[free[i]]);
    let chol = hf.cholesky().ok_or_else(|| {
        PhotometricError::Calibration("the log-domain normal equations are singular".into())
    })?;
    let gf = chol.solve(&rf);
    let mut g = vec![0.0; n];
    for (i, &k) in free.iter().enumerate() {
        g[k] = gf[i];
    }
    if g.iter().any(|v| !v.is_finite()) {
        return Err(PhotometricError::Calibration(
            "the log-domain fit is not finite".into(),
        ));
    }
    let diag = (0..n).map(|k| h[(k, k)].max(1e-12)).collect();
    Ok((g, free, chol, diag))
}

/// `U` from `g`: strictly increasing, `U(0) = 0`, `U(top) = 255`.
fn table(g: &[f64], info: &[f64]) -> Vec<f64> {
    let top = g.len() - 1;
    let mut u: Vec<f64> = g.iter().map(|&v| (v - g[top]).exp() * 255.0).collect();
    u[0] = 0.0;
    make_monotone(&mut u, info);
    let sc = 255.0 / u[top].max(1e-300);
    for v in u.iter_mut() {
        *v *= sc;
    }
    u
}

/// `U` from the normal equations with the prior's `lambda`.
pub(super) fn solve(eq: &Normal, lv: &Levels, lambda: f64) -> Result<Vec<f64>, PhotometricError> {
    let (g, _, _, diag) = solve_g(eq, lv, lambda)?;
    Ok(table(&g, &diag))
}

/// Fits `g = ln U` on the data with the prior's `lambda`, and its standard errors.
pub(super) fn fit(d: &Data<'_>, lambda: f64) -> Result<LogFit, PhotometricError> {
    let eq = normal(d)?;
    let (g, free, chol, diag) = solve_g(&eq, d.levels, lambda)?;
    let n = d.levels.knots;
    let sigma2 = residual_variance(d, &g, eq.count, eq.pixels + free.len());
    // ln U(k) - ln U(top): its variance from the inverse of the normal matrix
    let inv = chol.inverse();
    let top = n - 1;
    let ti = free.iter().position(|&k| k == top);
    let var_at = |i: Option<usize>, j: Option<usize>| match (i, j) {
        (Some(i), Some(j)) => inv[(i, j)],
        _ => 0.0,
    };
    let se_log: Vec<f64> = (0..n)
        .map(|k| {
            let ki = free.iter().position(|&f| f == k);
            let v = var_at(ki, ki) + var_at(ti, ti) - 2.0 * var_at(ki, ti);
            (sigma2 * v.max(0.0)).sqrt()
        })
        .collect();
    Ok(LogFit {
        u: table(&g, &diag),
        se_log,
    })
}

/// The weighted residual variance of the log-domain equations (per unit weight).
fn residual_variance(d: &Data<'_>, g: &[f64], count: usize, params: usize) -> f64 {
    let mut obs = Vec::new();
    let mut ss = 0.0;
    for px in 0..d.samples.len() {
        observations(d, px, &mut obs);
        if obs.len() < 2 {
            continue;
        }
        let at = |j: usize, f: f64| g[j] * (1.0 - f) + g[j + 1] * f;
        let (mut num, mut sw) = (0.0, 0.0);
        for &(j, f, w, lt) in &obs {
            num += w * (at(j, f) - lt);
            sw += w;
        }
        let le = num / sw;
        for &(j, f, w, lt) in &obs {
            let r = at(j, f) - le - lt;
            ss += w * r * r;
        }
    }
    let dof = count.saturating_sub(params).max(1) as f64;
    // per unit weight: the normal matrix carries the weights
    ss / dof
}

/// RMS of `I - G(t B')` over the values that enter (grey values), with every pixel's `B'` by
/// least squares through `u`.
pub(super) fn grey_rmse(d: &Data<'_>, u: &[f64]) -> f64 {
    let (s, lv, exposures) = (d.samples, d.levels, d.exposures);
    let g = Forward::new(u);
    let (mut ss, mut count) = (0.0, 0usize);
    for px in 0..s.len() {
        let vals = s.pixel(px);
        let inside = |i: usize, v: u16| {
            (d.all || !s.is_excluded(px, i)) && matches!(Obs::of(u32::from(v), lv), Obs::Value(_))
        };
        let (mut num, mut den, mut m) = (0.0, 0.0, 0);
        for (i, v) in vals.iter().enumerate() {
            if inside(i, v) {
                num += exposures[i] * interp(u, lv.pos(u32::from(v)));
                den += exposures[i] * exposures[i];
                m += 1;
            }
        }
        if m < 2 {
            continue;
        }
        for (i, v) in vals.iter().enumerate() {
            if inside(i, v) {
                let (j, fr) = g.eval(exposures[i] * num / den);
                let r = lv.pos(u32::from(v)) - (j as f64 + fr);
                ss += r * r;
                count += 1;
            }
        }
    }
    (ss / count.max(1) as f64).sqrt() / lv.scale
}
