//! Estimating missing exposures: the measured ratios chained by weighted least squares with
//! Huber weights, anchored at a reference exposure, with standard errors.

use super::ratio::PairRatio;
use super::ExposureOptions;
use crate::stats::median;
use crate::PhotometricError;

/// The result of [`estimate_exposures`].
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ExposureEstimate {
    /// Exposure per frame in ms, the median equal to the reference.
    pub exposures_ms: Vec<f64>,
    /// Standard error of `log(exposure)` per frame (relative), with respect to the anchor.
    pub log_std_error: Vec<f64>,
    /// The frame at the median whose standard error is 0.
    pub anchor: usize,
    /// Measured pairs that entered.
    pub pairs_used: usize,
    /// Pairs left out as unreliable.
    pub pairs_unreliable: usize,
    /// Pairs down-weighted as outliers, `(from, to)`.
    pub outliers: Vec<(usize, usize)>,
    /// Frames `i` whose step to `i + 1` no reliable ratio spans (only the weak prior links
    /// them: their relative exposure is unknown).
    pub gaps: Vec<usize>,
}

/// A symmetric positive-definite band matrix, lower band stored by rows:
/// `band[i * (p + 1) + d]` is `A[i][i - d]`.
///
/// Why a band solver of our own: the standard errors need the diagonal of `A^-1`, and no
/// crate of the stack computes a selected inverse. nalgebra's dense Cholesky and inverse of
/// such a matrix (bandwidth 4) took 0.35 s for 1,000 frames, 5.9 s for 2,000 and 60 s and
/// 256 MB for 4,000 (nalgebra 0.35, release build, 2-core machine); the dataset's sequences
/// have up to several thousand frames and a user's may have tens of thousands.
/// nalgebra-sparse and faer factor sparse matrices but do not give the inverse's diagonal,
/// and one solve per frame would cost `O(n^2 p)`. LDL^T in the band with Takahashi's
/// recurrence costs `O(n p^2)` time and `O(n p)` memory.
pub(super) struct Band {
    pub(super) n: usize,
    pub(super) p: usize,
    pub(super) a: Vec<f64>,
}

impl Band {
    pub(super) fn new(n: usize, p: usize) -> Band {
        Band {
            n,
            p,
            a: vec![0.0; n * (p + 1)],
        }
    }

    /// Adds `v` to `A[i][j]` (and `A[j][i]`), `|i - j| <= p`.
    pub(super) fn add(&mut self, i: usize, j: usize, v: f64) {
        let (r, c) = if i >= j { (i, j) } else { (j, i) };
        self.a[r * (self.p + 1) + (r - c)] += v;
    }

    /// LDL^T in place: afterwards `a[i][0]` is `D_i` and `a[i][d]` is `L[i][i - d]`.
    pub(super) fn factor(&mut self) -> Result<(), PhotometricError> {
        let p = self.p;
        let q = p + 1;
        for i in 0..self.n {
            let lo = i.saturating_sub(p);
            for j in lo..i {
                // L[i][j] = (A[i][j] - sum_k L[i][k] D_k L[j][k]) / D_j, k in max(lo, j-p)..j
                let mut s = self.a[i * q + (i - j)];
                for k in lo.max(j.saturating_sub(p))..j {
                    s -= self.a[i * q + (i - k)] * self.a[k * q] * self.a[j * q + (j - k)];
                }
                self.a[i * q + (i - j)] = s / self.a[j * q];
            }
            let mut dv = self.a[i * q];
            for k in lo..i {
                let l = self.a[i * q + (i - k)];
                dv -= l * l * self.a[k * q];
            }
            if !(dv.is_finite() && dv > 0.0) {
                return Err(PhotometricError::Calibration(
                    "the exposure chain is singular".into(),
                ));
            }
            self.a[i * q] = dv;
        }
        Ok(())
    }

    /// Solves `A x = b` with the factors.
    pub(super) fn solve(&self, b: &[f64]) -> Vec<f64> {
        let (p, q) = (self.p, self.p + 1);
        let mut x = b.to_vec();
        for i in 0..self.n {
            for k in i.saturating_sub(p)..i {
                x[i] -= self.a[i * q + (i - k)] * x[k];
            }
        }
        for (i, xi) in x.iter_mut().enumerate() {
            *xi /= self.a[i * q];
        }
        for i in (0..self.n).rev() {
            for k in i + 1..(i + q).min(self.n) {
                x[i] -= self.a[k * q + (k - i)] * x[k];
            }
        }
        x
    }

    /// The diagonal of `A^-1` from the factors (Takahashi's recurrence inside the band).
    pub(super) fn inverse_diagonal(&self) -> Vec<f64> {
        let (n, p, q) = (self.n, self.p, self.p + 1);
        // z[i * q + d] = Z[i + d][i] for d = 0..=p (lower band by columns)
        let mut z = vec![0.0; n * q];
        let zat = |z: &[f64], i: usize, j: usize| -> f64 {
            let (r, c) = if i >= j { (i, j) } else { (j, i) };
            z[c * q + (r - c)]
        };
        for i in (0..n).rev() {
            let hi = (i + p).min(n - 1);
            for j in (i + 1..=hi).rev() {
                let mut s = 0.0;
                for k in i + 1..=hi {
                    s -= self.a[k * q + (k - i)] * zat(&z, k, j);
                }
                z[i * q + (j - i)] = s;
            }
            let mut s = 1.0 / self.a[i * q];
            for k in i + 1..=hi {
                s -= self.a[k * q + (k - i)] * z[i * q + (k - i)];
            }
            z[i * q] = s;
        }
        (0..n).map(|i| z[i * q]).collect()
    }
}

/// Weighted least squares of log exposures with frame `gauge` fixed at 0: the solution and
/// the variance of every frame relative to the gauge.
pub(super) fn solve_chain(
    n: usize,
    obs: &[(usize, usize, f64, f64)],
    gauge: usize,
) -> Result<(Vec<f64>, Vec<f64>), PhotometricError> {
    let p = obs.iter().map(|o| o.1 - o.0).max().unwrap_or(1).max(1);
    let idx = |i: usize| {
        if i < gauge {
            Some(i)
        } else if i > gauge {
            Some(i - 1)
        } else {
            None
        }
    };
    let mut band = Band::new(n - 1, p);
    let mut rhs = vec![0.0; n - 1];
    for &(i, j, m, w) in obs {
        // residual x_j - x_i - m
        match (idx(i), idx(j)) {
            (Some(a), Some(b)) => {
                band.add(a, a, w);
                band.add(b, b, w);
                band.add(a, b, -w);
                rhs[b] += w * m;
                rhs[a] -= w * m;
            }
            (None, Some(b)) => {
                band.add(b, b, w);
                rhs[b] += w * m;
            }
            (Some(a), None) => {
                band.add(a, a, w);
                rhs[a] -= w * m;
            }
            (None, None) => {}
        }
    }
    band.factor()?;
    let sol = band.solve(&rhs);
    let dia = band.inverse_diagonal();
    let mut x = Vec::with_capacity(n);
    let mut var = Vec::with_capacity(n);
    for i in 0..n {
        match idx(i) {
            Some(a) => {
                x.push(sol[a]);
                var.push(dia[a].max(0.0));
            }
            None => {
                x.push(0.0);
                var.push(0.0);
            }
        }
    }
    Ok((x, var))
}

/// Estimates the exposures of `n` frames from measured ratios (see the module
/// documentation), anchored so that the median exposure is `reference_ms`.
pub fn estimate_exposures(
    n: usize,
    pairs: &[PairRatio],
    reference_ms: f64,
    opts: &ExposureOptions,
) -> Result<ExposureEstimate, PhotometricError> {
    if n < 2 {
        return Err(PhotometricError::Calibration(format!(
            "an exposure estimate needs at least 2 frames, found {n}"
        )));
    }
    if !(reference_ms.is_finite() && reference_ms > 0.0) {
        return Err(PhotometricError::Exposure(reference_ms));
    }
    if let Some(bad) = pairs.iter().find(|p| p.to <= p.from || p.to >= n) {
        return Err(PhotometricError::Calibration(format!(
            "pair ({}, {}) is not two frames of 0..{n} in order",
            bad.from, bad.to
        )));
    }
    let gap_prior = opts.gap_prior.max(1e-3);
    let used: Vec<&PairRatio> = pairs
        .iter()
        .filter(|p| {
            let m = &p.measurement;
            p.to - p.from <= 8 && m.reliable && m.log_ratio.is_finite() && m.std_error > 0.0
        })
        .collect();
    let mut spans = vec![false; n - 1];
    for p in &used {
        for s in &mut spans[p.from..p.to] {
            *s = true;
        }
    }
    let gaps: Vec<usize> = (0..n - 1).filter(|&i| !spans[i]).collect();
    let mut robust = vec![1.0; used.len()];
    let build = |robust: &[f64]| -> Vec<(usize, usize, f64, f64)> {
        let mut obs: Vec<(usize, usize, f64, f64)> = used
            .iter()
            .zip(robust)
            .map(|(p, r)| {
                let s = p.measurement.std_error;
                (p.from, p.to, p.measurement.log_ratio, r / (s * s))
            })
            .collect();
        for i in 0..n - 1 {
            obs.push((i, i + 1, 0.0, 1.0 / (gap_prior * gap_prior)));
        }
        obs
    };
    let mut x = vec![0.0; n];
    // Huber reweighting; it changes something only where pairs overlap
    for _ in 0..20 {
        let (sol, _) = solve_chain(n, &build(&robust), 0)?;
        x = sol;
        let mut change = 0.0f64;
        for (r, p) in robust.iter_mut().zip(&used) {
            let m = &p.measurement;
            let u = ((x[p.to] - x[p.from] - m.log_ratio) / m.std_error).abs();
            // Huber, and a pair 8 standard errors off is out
            let nr = if u <= 2.5 {
                1.0
            } else if u <= 8.0 {
                2.5 / u
            } else {
                0.0
            };
            change = change.max((nr - *r).abs());
            *r = nr;
        }
        if change < 1e-3 {
            break;
        }
    }
    // anchor: the frame at the median
    let mut sorted: Vec<(f64, usize)> = x.iter().copied().zip(0..).collect();
    sorted.sort_by(|a, b| a.0.total_cmp(&b.0));
    let anchor = sorted[(n - 1) / 2].1;
    let (x, var) = solve_chain(n, &build(&robust), anchor)?;
    let mut xs = x.clone();
    let med = median(&mut xs);
    let offset = reference_ms.ln() - med;
    let outliers = used
        .iter()
        .zip(&robust)
        .filter(|(_, r)| **r < 1.0)
        .map(|(p, _)| (p.from, p.to))
        .collect();
    Ok(ExposureEstimate {
        exposures_ms: x.iter().map(|v| (v + offset).exp()).collect(),
        log_std_error: var.iter().map(|v| v.sqrt()).collect(),
        anchor,
        pairs_used: used.len(),
        pairs_unreliable: pairs.len() - used.len(),
        outliers,
        gaps,
    })
}
