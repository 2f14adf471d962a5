//! The noise of an observed grey value, shared by the response and vignette calibrations:
//! photon shot and read noise before the response, ADC noise and quantisation after it.

use nalgebra::{DMatrix, DVector};

/// The grey-level noise of one observation as a function of its expected grey value `p`:
/// variance `(read + shot U(p)) / U'(p)^2 + adc` (grey levels squared), with `U'` the
/// slope of the inverse response per grey level.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct NoiseModel {
    /// Signal-independent noise before the response (read noise), in U-units squared.
    pub read: f64,
    /// Photon shot noise: variance per U-unit of signal.
    pub shot: f64,
    /// Noise after the response (ADC, quantisation), in grey levels squared.
    pub adc: f64,
}

impl NoiseModel {
    /// The variance at expected grey value `p` for the inverse response `u` (a table of at
    /// least 4 values).
    pub fn variance(&self, u: &[f64], p: f64) -> f64 {
        let top = u.len() - 1;
        let p = p.clamp(0.0, top as f64);
        let k = (p.round() as usize).min(top);
        let slope = slope_at(u, k);
        let up = interp(u, p).max(0.0);
        ((self.read + self.shot * up) / (slope * slope) + self.adc).max(1e-3)
    }
}

/// `U'` at grey value `k`: the secant over `k - 3 ..= k + 3` (shortened at the ends), at
/// least a twentieth of the mean slope (noise in `U` must not make the noise model explode).
pub(crate) fn slope_at(u: &[f64], k: usize) -> f64 {
    let top = u.len() - 1;
    let a = k.saturating_sub(3);
    let b = (k + 3).min(top);
    let s = (u[b] - u[a]) / (b - a) as f64;
    let mean = (u[top] - u[0]).abs() / top as f64;
    s.max(0.05 * mean).max(1e-12)
}

/// `U` at a fractional grey value (linear interpolation).
pub(crate) fn interp(u: &[f64], p: f64) -> f64 {
    let top = u.len() - 1;
    let p = p.clamp(0.0, top as f64);
    let j = (p as usize).min(top - 1);
    let f = p - j as f64;
    u[j] + f * (u[j + 1] - u[j])
}

/// Fits the noise model to residual variances per predicted grey value (non-negative least
/// squares on the relative error of the bins with enough data).
pub(crate) fn fit_noise(u: &[f64], rss: &[f64], cnt: &[f64]) -> Option<NoiseModel> {
    let rows: Vec<(f64, [f64; 3], f64)> = (0..u.len())
        .filter(|&k| cnt[k] >= 50.0)
        .map(|k| {
            let v = rss[k] / cnt[k];
            let s = slope_at(u, k);
            let feats = [1.0 / (s * s), u[k].max(0.0) / (s * s), 1.0];
            // relative error: weight by count / v^2
            (v, feats, cnt[k] / (v * v).max(1e-6))
        })
        .collect();
    if rows.len() < 8 {
        return None;
    }
    let mut best: Option<(f64, [f64; 3])> = None;
    // all non-empty active sets of the three non-negative terms
    for mask in 1u8..8 {
        let idx: Vec<usize> = (0..3).filter(|i| mask >> i & 1 == 1).collect();
        let m = idx.len();
        let mut ata = DMatrix::<f64>::zeros(m, m);
        let mut atb = DVector::<f64>::zeros(m);
        for (v, f, w) in &rows {
            for (a, &ia) in idx.iter().enumerate() {
                atb[a] += w * f[ia] * v;
                for (b, &ib) in idx.iter().enumerate() {
                    ata[(a, b)] += w * f[ia] * f[ib];
                }
            }
        }
        let Some(sol) = ata.cholesky().map(|c| c.solve(&atb)) else {
            continue;
        };
        if sol.iter().any(|&x| !x.is_finite() || x < 0.0) {
            continue;
        }
        let mut coef = [0.0; 3];
        for (a, &ia) in idx.iter().enumerate() {
            coef[ia] = sol[a];
        }
        let cost: f64 = rows
            .iter()
            .map(|(v, f, w)| {
                let pred = coef[0] * f[0] + coef[1] * f[1] + coef[2] * f[2];
                w * (v - pred).powi(2)
            })
            .sum();
        if best.as_ref().is_none_or(|(c, _)| cost < *c) {
            best = Some((cost, coef));
        }
    }
    best.map(|(_, c)| NoiseModel {
        read: c[0],
        shot: c[1],
        adc: c[2],
    })
}

impl NoiseModel {
    /// The variance of `U(I)` (U-units squared) for an observation whose expected value is
    /// the energy `e` (U-units): `read + shot e + adc U'^2`.
    pub fn energy_variance(&self, u: &[f64], e: f64) -> f64 {
        let k = u.partition_point(|&v| v <= e).clamp(1, u.len() - 1);
        let slope = slope_at(u, k);
        (self.read + self.shot * e.max(0.0) + self.adc * slope * slope).max(1e-9)
    }
}
