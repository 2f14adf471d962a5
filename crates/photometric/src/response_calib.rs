//! Response calibration (paper section 2.3.1): the inverse response `U` from a static scene
//! seen at known, varying exposures, by alternating least squares on
//! `E(U, B') = sum_i sum_x (U(I_i(x)) - t_i B'(x))^2` (equations 6-8), iterated to convergence.
//!
//! Differences to the reference tool, each measured on synthetic sweeps with known truth:
//! * it iterates until the relative change of the energy falls below a tolerance instead of a
//!   fixed 10 iterations;
//! * saturation is censoring: a pixel just below 255 in a bright frame is there because its
//!   noise happened to be negative, so observations above `censor_level` do not enter the
//!   irradiance estimate `B'` (they still enter `U`, whose values there are then unbiased);
//! * values never observed are filled by monotone interpolation / extrapolation, and the
//!   result is made strictly increasing, so it is never NaN and DSO accepts it;
//! * an optional smoothness prior on `U` (Debevec-Malik style) for small data sets.

use camera_model::Image;
use rayon::prelude::*;

use crate::{InverseResponse, PhotometricError};

/// Options of [`calibrate_response`].
#[derive(Clone, Debug)]
pub struct ResponseOptions {
    /// Iteration limit.
    pub max_iterations: usize,
    /// Stop when the relative change of the energy between iterations is below this.
    pub tolerance: f64,
    /// Weight of the second-difference smoothness prior, relative to the mean number of
    /// observations per grey value (0 = the paper's unregularised method).
    pub smoothness: f64,
    /// Radius (pixels) of the neighbourhood dropped around saturated pixels.
    pub saturation_border: usize,
    /// Observations above this grey value do not enter the irradiance estimate.
    pub censor_level: u8,
    /// Grey values observed fewer times than this count as unobserved.
    pub min_count: u64,
}

impl Default for ResponseOptions {
    fn default() -> Self {
        ResponseOptions {
            max_iterations: 200,
            tolerance: 1e-6,
            smoothness: 0.5,
            saturation_border: 1,
            censor_level: 245,
            min_count: 20,
        }
    }
}

/// The result of [`calibrate_response`].
#[derive(Clone, Debug)]
pub struct ResponseCalibration {
    /// The inverse response, `U(255) = 255`, strictly increasing.
    pub response: InverseResponse,
    /// Iterations run.
    pub iterations: usize,
    /// Whether the tolerance was reached.
    pub converged: bool,
    /// Root-mean-square residual `U(I) - t B'` in grey-value units (U scaled to 255).
    pub rmse: f64,
    /// Smallest and largest grey value with at least `min_count` observations.
    pub observed_range: (u8, u8),
    /// Grey values filled by interpolation or extrapolation.
    pub filled: Vec<u8>,
    /// Observations per grey value.
    pub histogram: Vec<u64>,
    /// Energy after each iteration (U scaled to 255).
    pub energy: Vec<f64>,
}

/// Sets saturated pixels and their neighbourhood of `radius` to 255 (= ignored), in place.
fn mask_saturation(frame: &mut [u8], width: usize, height: usize, radius: usize) {
    if radius == 0 {
        return;
    }
    let sat: Vec<bool> = frame.iter().map(|&v| v == 255).collect();
    // horizontal then vertical dilation
    let mut h = vec![false; sat.len()];
    for y in 0..height {
        let row = &sat[y * width..(y + 1) * width];
        for x in 0..width {
            let lo = x.saturating_sub(radius);
            let hi = (x + radius).min(width - 1);
            h[y * width + x] = row[lo..=hi].iter().any(|&s| s);
        }
    }
    for y in 0..height {
        let lo = y.saturating_sub(radius);
        let hi = (y + radius).min(height - 1);
        for x in 0..width {
            if (lo..=hi).any(|yy| h[yy * width + x]) {
                frame[y * width + x] = 255;
            }
        }
    }
}

/// Solves `a x = b` for a dense symmetric positive (semi-)definite system by Gaussian
/// elimination with partial pivoting; `None` when singular.
fn solve_dense(mut a: Vec<Vec<f64>>, mut b: Vec<f64>) -> Option<Vec<f64>> {
    let n = b.len();
    for c in 0..n {
        let p = (c..n).max_by(|&i, &j| a[i][c].abs().total_cmp(&a[j][c].abs()))?;
        if a[p][c].abs() < 1e-300 {
            return None;
        }
        a.swap(c, p);
        b.swap(c, p);
        for r in c + 1..n {
            let f = a[r][c] / a[c][c];
            if f == 0.0 {
                continue;
            }
            let (top, bottom) = a.split_at_mut(r);
            for (x, p) in bottom[0][c..].iter_mut().zip(&top[c][c..]) {
                *x -= f * p;
            }
            b[r] -= f * b[c];
        }
    }
    let mut x = vec![0.0; n];
    for r in (0..n).rev() {
        let s: f64 = (r + 1..n).map(|k| a[r][k] * x[k]).sum();
        x[r] = (b[r] - s) / a[r][r];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// Fills unobserved values by linear interpolation between observed neighbours and linear
/// extrapolation at the ends, then makes the table strictly increasing (pool-adjacent-
/// violators, then a tiny ramp where values tie).
fn fill_and_make_monotone(u: &mut [f64; 256], observed: &[bool; 256]) -> Vec<u8> {
    let obs: Vec<usize> = (0..256).filter(|&k| observed[k]).collect();
    let mut filled = Vec::new();
    for k in 0..256 {
        if observed[k] {
            continue;
        }
        filled.push(k as u8);
        let below = obs.iter().rev().find(|&&j| j < k).copied();
        let above = obs.iter().find(|&&j| j > k).copied();
        u[k] = match (below, above) {
            (Some(a), Some(b)) => u[a] + (u[b] - u[a]) * (k - a) as f64 / (b - a) as f64,
            (Some(a), None) => {
                // extrapolate with the slope over the last observed values
                let a0 = obs
                    .iter()
                    .rev()
                    .nth(8.min(obs.len() - 1))
                    .copied()
                    .unwrap_or(a);
                let slope = if a > a0 {
                    (u[a] - u[a0]) / (a - a0) as f64
                } else {
                    1.0
                };
                u[a] + slope.max(1e-6) * (k - a) as f64
            }
            (None, Some(b)) => {
                let b1 = obs.get(8.min(obs.len() - 1)).copied().unwrap_or(b);
                let slope = if b1 > b {
                    (u[b1] - u[b]) / (b1 - b) as f64
                } else {
                    1.0
                };
                (u[b] - slope.max(1e-6) * (b - k) as f64).max(0.0)
            }
            (None, None) => k as f64,
        };
    }
    // isotonic regression (pool adjacent violators), unweighted
    let mut blocks: Vec<(f64, usize)> = Vec::with_capacity(256);
    for &v in u.iter() {
        blocks.push((v, 1));
        while blocks.len() > 1 {
            let n = blocks.len();
            if blocks[n - 2].0 <= blocks[n - 1].0 {
                break;
            }
            let (v2, c2) = blocks[n - 1];
            let (v1, c1) = blocks[n - 2];
            blocks.truncate(n - 2);
            blocks.push((
                (v1 * c1 as f64 + v2 * c2 as f64) / (c1 + c2) as f64,
                c1 + c2,
            ));
        }
    }
    let mut k = 0;
    for (v, c) in blocks {
        for _ in 0..c {
            u[k] = v;
            k += 1;
        }
    }
    // strictly increasing: separate ties by a small fraction of the typical step
    let eps = ((u[255] - u[0]).abs() / 255.0).max(1e-9) * 1e-3;
    for k in 1..256 {
        if u[k] <= u[k - 1] {
            u[k] = u[k - 1] + eps;
        }
    }
    filled
}

/// Calibrates the inverse response from `frames` (8-bit grey, all the same size) taken at
/// `exposures_ms`. Frames are modified in place (saturated neighbourhoods set to 255).
/// `progress` is called after every iteration with the iteration number and energy.
pub fn calibrate_response(
    frames: &mut [Image<u8>],
    exposures_ms: &[f64],
    options: &ResponseOptions,
    progress: &(dyn Fn(usize, f64) + Sync),
) -> Result<ResponseCalibration, PhotometricError> {
    let n = frames.len();
    if n < 2 {
        return Err(PhotometricError::Calibration(format!(
            "response calibration needs at least 2 frames, got {n}"
        )));
    }
    if exposures_ms.len() != n {
        return Err(PhotometricError::Calibration(format!(
            "{} exposures for {n} frames",
            exposures_ms.len()
        )));
    }
    if let Some(t) = exposures_ms.iter().find(|t| !(t.is_finite() && **t > 0.0)) {
        return Err(PhotometricError::Exposure(*t));
    }
    let t_min = exposures_ms.iter().copied().fold(f64::INFINITY, f64::min);
    let t_max = exposures_ms.iter().copied().fold(0.0, f64::max);
    if t_max <= t_min * (1.0 + 1e-9) {
        return Err(PhotometricError::Calibration(format!(
            "every frame has the same exposure ({t_min} ms): the response is not observable; record the scene while changing the exposure"
        )));
    }
    let (w, h) = frames[0].size();
    for (i, f) in frames.iter().enumerate() {
        if f.size() != (w, h) {
            return Err(PhotometricError::SizeMismatch {
                what: if i == 0 { "frame 0" } else { "a frame" },
                width: w,
                height: h,
                got_width: f.width(),
                got_height: f.height(),
            });
        }
    }
    frames
        .par_iter_mut()
        .for_each(|f| mask_saturation(f.data_mut(), w, h, options.saturation_border));

    let npx = w * h;
    let censor = options.censor_level.min(254) as usize;
    // histogram of usable observations
    let histogram: Vec<u64> = frames
        .par_iter()
        .map(|f| {
            let mut c = vec![0u64; 256];
            for &v in f.data() {
                c[v as usize] += 1;
            }
            c
        })
        .reduce(
            || vec![0u64; 256],
            |a, b| a.iter().zip(&b).map(|(x, y)| x + y).collect(),
        );
    let mut observed = [false; 256];
    for k in 0..255 {
        observed[k] = histogram[k] >= options.min_count.max(1);
    }
    let lo = (0..255).find(|&k| observed[k]);
    let hi = (0..255).rev().find(|&k| observed[k]);
    let (Some(lo), Some(hi)) = (lo, hi) else {
        return Err(PhotometricError::Calibration(
            "no unsaturated pixel in any frame".into(),
        ));
    };
    if hi - lo < 16 {
        return Err(PhotometricError::Calibration(format!(
            "only grey values {lo}..{hi} are observed; the scene needs a wider range of brightness (dark pixels and bright ones)"
        )));
    }

    let mut u = [0.0f64; 256];
    for (k, v) in u.iter_mut().enumerate() {
        *v = k as f64;
    }
    let mut b = vec![0f32; npx];
    let rows_per_chunk = (16384 / w.max(1)).max(1);
    let mut energy_hist = Vec::new();
    let mut prev_energy = f64::INFINITY;
    let mut iterations = 0;
    let mut converged = false;
    let total_obs: u64 = histogram[..255].iter().sum();
    let lambda = options.smoothness * total_obs as f64 / 255.0;
    loop {
        iterations += 1;
        // B' step (eq. 8), from uncensored observations only
        b.par_chunks_mut(rows_per_chunk * w)
            .enumerate()
            .for_each(|(ci, bchunk)| {
                let start = ci * rows_per_chunk * w;
                let mut num = vec![0f64; bchunk.len()];
                let mut den = vec![0f64; bchunk.len()];
                for (f, &t) in frames.iter().zip(exposures_ms) {
                    let px = &f.data()[start..start + bchunk.len()];
                    for ((&k, nu), de) in px.iter().zip(num.iter_mut()).zip(den.iter_mut()) {
                        let k = k as usize;
                        if k <= censor {
                            *nu += t * u[k];
                            *de += t * t;
                        }
                    }
                }
                for ((o, nu), de) in bchunk.iter_mut().zip(&num).zip(&den) {
                    *o = if *de > 0.0 {
                        (nu / de) as f32
                    } else {
                        f32::NAN
                    };
                }
            });
        // U step (eq. 7) and the energy with the U of this iteration
        let (sum, cnt, energy) = frames
            .par_iter()
            .zip(exposures_ms)
            .map(|(f, &t)| {
                let mut s = vec![0f64; 256];
                let mut c = vec![0f64; 256];
                let mut e = 0.0;
                for (&k, &bx) in f.data().iter().zip(&b) {
                    if k == 255 || bx.is_nan() {
                        continue;
                    }
                    let tb = t * bx as f64;
                    s[k as usize] += tb;
                    c[k as usize] += 1.0;
                    let r = u[k as usize] - tb;
                    e += r * r;
                }
                (s, c, e)
            })
            .reduce(
                || (vec![0f64; 256], vec![0f64; 256], 0.0),
                |a, b| {
                    (
                        a.0.iter().zip(&b.0).map(|(x, y)| x + y).collect(),
                        a.1.iter().zip(&b.1).map(|(x, y)| x + y).collect(),
                        a.2 + b.2,
                    )
                },
            );
        let mut new_u = u;
        if lambda > 0.0 {
            // (diag(cnt) + lambda D^T D) U = sum, D the second difference over 0..254
            let m = 255;
            let mut a = vec![vec![0.0; m]; m];
            let mut rhs = vec![0.0; m];
            for (k, row) in a.iter_mut().enumerate() {
                row[k] += cnt[k];
            }
            rhs.copy_from_slice(&sum[..m]);
            for k in 1..m - 1 {
                let idx = [k - 1, k, k + 1];
                let coef = [1.0, -2.0, 1.0];
                for (i, &r) in idx.iter().enumerate() {
                    for (j, &c) in idx.iter().enumerate() {
                        a[r][c] += lambda * coef[i] * coef[j];
                    }
                }
            }
            if let Some(x) = solve_dense(a, rhs) {
                new_u[..m].copy_from_slice(&x);
            }
        } else {
            for k in 0..255 {
                if cnt[k] > 0.0 {
                    new_u[k] = sum[k] / cnt[k];
                }
            }
        }
        // fix the gauge U(hi) = hi, so that energies of successive iterations compare
        let s = if new_u[hi] > 0.0 {
            hi as f64 / new_u[hi]
        } else {
            1.0
        };
        for v in new_u.iter_mut() {
            *v *= s;
        }
        for v in b.iter_mut() {
            *v *= s as f32;
        }
        u = new_u;
        energy_hist.push(energy);
        progress(iterations, energy);
        let rel = (prev_energy - energy).abs() / energy.max(1e-300);
        if rel < options.tolerance {
            converged = true;
            break;
        }
        if iterations >= options.max_iterations {
            break;
        }
        prev_energy = energy;
    }
    let filled = fill_and_make_monotone(&mut u, &observed);
    // U(255) is never observed: it was extrapolated with the other unobserved values
    let s = 255.0 / u[255];
    let u = u.map(|v| v * s);
    let response = InverseResponse::new(u)?;
    let rmse = (energy_hist.last().copied().unwrap_or(0.0) / total_obs.max(1) as f64).sqrt() * s;
    let energy_hist = energy_hist.iter().map(|e| e * s * s).collect();
    Ok(ResponseCalibration {
        response,
        iterations,
        converged,
        rmse,
        observed_range: (lo as u8, hi as u8),
        filled: filled.into_iter().filter(|&k| k != 255).collect(),
        histogram,
        energy: energy_hist,
    })
}
