//! What the data do not say: the third-difference prior against the ripples a sweep leaves
//! undetermined, the continuation of `U` beyond the values the data determine, and the
//! strictly increasing table.

use nalgebra::{DMatrix, DVector};

use crate::noise::slope_at;

/// The prior's weight per row of the third-difference operator (rows `r .. r + 3`), relative
/// to the information about those values: `scale^6`, so that the prior smooths `U` over about
/// `scale` grey values there (a ripple of period `T` costs `(2 pi scale / T)^6` times the
/// information) and leaves longer scales to the data. The scale is `smoothness` grey values,
/// or more where the exposures leave ripples undetermined: `RIPPLE_MARGIN T / (2 pi)` with the
/// local ripple period `T = P U / U'` (a factor periodic in `log U` with period `P`, the
/// exposures' ripple period). The ripples are short where `U` is steep (a camera's shoulder),
/// so the prior is weak there and does not flatten it. `scale` multiplies every weight.
pub(super) fn prior_weights(u: &[f64], log_gap: f64, smoothness: f64, scale: f64) -> Vec<f64> {
    let n = u.len();
    (0..n.saturating_sub(3))
        .map(|r| {
            let k = r + 1;
            let period = log_gap * u[k].max(u[r + 2]) / slope_at(u, k);
            let s = smoothness.max(RIPPLE_MARGIN * period / std::f64::consts::TAU);
            scale * s.powi(6)
        })
        .collect()
}

/// How far beyond the longest undetermined ripple period the prior reaches.
const RIPPLE_MARGIN: f64 = 1.3;

/// The prior `1/2 sum_r c_r (D3 U)_r^2` at a table `u`: its value, gradient and matrix.
pub(super) struct Penalty {
    pub value: f64,
    pub grad: DVector<f64>,
    pub hess: DMatrix<f64>,
}

/// The penalty with per-row weights `c_r = weights[r] * info_r`, `info_r` the data's mean
/// information about the row's four values (at least a hundredth of the median, so that the
/// prior still reaches where the data do not).
pub(super) fn penalty(u: &[f64], info: &[f64], weights: &[f64]) -> Penalty {
    let n = u.len();
    let mut pos: Vec<f64> = info.iter().copied().filter(|&v| v > 0.0).collect();
    pos.sort_by(f64::total_cmp);
    let floor = 1e-2 * pos.get(pos.len() / 2).copied().unwrap_or(0.0);
    let stencil = [-1.0, 3.0, -3.0, 1.0];
    let mut hess = DMatrix::zeros(n, n);
    let mut grad = DVector::zeros(n);
    let mut value = 0.0;
    for (r, &w) in weights.iter().enumerate() {
        let mean_info = info[r..r + 4].iter().sum::<f64>() / 4.0;
        let c = w * mean_info.max(floor);
        let d: f64 = (0..4).map(|a| stencil[a] * u[r + a]).sum();
        value += 0.5 * c * d * d;
        for a in 0..4 {
            grad[r + a] += c * stencil[a] * d;
            for b in 0..4 {
                hess[(r + a, r + b)] += c * stencil[a] * stencil[b];
            }
        }
    }
    Penalty { value, grad, hess }
}

/// The values the data determine: from the first to the last grey value with at least
/// `MIN_DETERMINING` observations predicted there.
pub(super) fn data_range(used: &[u64]) -> (usize, usize) {
    let n = used.len();
    let enough = |k: usize| used[k] >= MIN_DETERMINING;
    let first = (0..n).find(|&k| enough(k)).unwrap_or(0);
    let last = (0..n).rev().find(|&k| enough(k)).unwrap_or(n - 1);
    (first, last.max(first))
}

/// Observations a grey value needs to count as determined by the data.
const MIN_DETERMINING: u64 = 20;

/// Grey values next to each end of the data's range over which the extrapolation is fitted.
pub(super) const EXTRAPOLATION_WINDOW: usize = 32;

/// Coefficients `c` with `fit(at) = sum_j c_j y_j` of the least-squares quadratic through
/// `y_lo ..= y_hi` (equal weights).
fn quadratic_coefficients(lo: usize, hi: usize, at: f64) -> Option<Vec<f64>> {
    let centre = 0.5 * (lo + hi) as f64;
    let mut ata = nalgebra::Matrix3::<f64>::zeros();
    for k in lo..=hi {
        let x = k as f64 - centre;
        let f = nalgebra::Vector3::new(1.0, x, x * x);
        ata += f * f.transpose();
    }
    let inv = ata.try_inverse()?;
    let xa = at - centre;
    let row = nalgebra::Vector3::new(1.0, xa, xa * xa).transpose() * inv;
    Some(
        (lo..=hi)
            .map(|k| {
                let x = k as f64 - centre;
                row[0] + row[1] * x + row[2] * x * x
            })
            .collect(),
    )
}

/// `U` with the values outside the data's range `first..=last` extrapolated, and the
/// Jacobian of that map. Above the data, `log U` is continued by the quadratic fitted to the
/// `EXTRAPOLATION_WINDOW` values below `last` (camera responses are close to powers and
/// exponentials, which a quadratic in `log U` follows far better than one in `U`), offset to
/// meet `U(last)`; below, `U` itself is continued the same way (it goes to 0 there), with
/// `U(0) = 0` held. The result is kept at or above 0 and strictly increasing.
pub(super) fn extrapolate(u: &[f64], first: usize, last: usize) -> (Vec<f64>, DMatrix<f64>) {
    extrapolate_with(u, first, last, EXTRAPOLATION_WINDOW)
}

/// [`extrapolate`] with another window (the extrapolation's sensitivity to it is part of the
/// standard error).
pub(super) fn extrapolate_with(
    u: &[f64],
    first: usize,
    last: usize,
    window: usize,
) -> (Vec<f64>, DMatrix<f64>) {
    let n = u.len();
    let mut out = u.to_vec();
    let mut jac = DMatrix::<f64>::identity(n, n);
    if last < n - 1 {
        let lo = last.saturating_sub(window - 1).max(first);
        let positive = (lo..=last).all(|k| u[k] > 0.0);
        if let (true, true, Some(at_end)) = (
            last >= lo + 3,
            positive,
            quadratic_coefficients(lo, last, last as f64),
        ) {
            for k in last + 1..n {
                let Some(ck) = quadratic_coefficients(lo, last, k as f64) else {
                    continue;
                };
                // log U(k) = log U(last) + fit(k) - fit(last), fitted to log U
                let mut lv = u[last].ln();
                for (i, j) in (lo..=last).enumerate() {
                    lv += (ck[i] - at_end[i]) * u[j].ln();
                }
                out[k] = lv.exp();
                for c in 0..n {
                    jac[(k, c)] = 0.0;
                }
                jac[(k, last)] += out[k] / u[last];
                for (i, j) in (lo..=last).enumerate() {
                    jac[(k, j)] += out[k] * (ck[i] - at_end[i]) / u[j];
                }
            }
        } else {
            let slope = (u[last] - u[first]) / (last - first).max(1) as f64;
            for (k, o) in out.iter_mut().enumerate().skip(last + 1) {
                *o = u[last] + slope.max(1e-9) * (k - last) as f64;
            }
        }
    }
    if first > 0 {
        let hi = (first + window - 1).min(last);
        if let (true, Some(at_end)) = (
            hi >= first + 3,
            quadratic_coefficients(first, hi, first as f64),
        ) {
            for k in 0..first {
                let Some(ck) = quadratic_coefficients(first, hi, k as f64) else {
                    continue;
                };
                let mut v = u[first];
                for (i, j) in (first..=hi).enumerate() {
                    v += (ck[i] - at_end[i]) * u[j];
                }
                out[k] = v;
                for c in 0..n {
                    jac[(k, c)] = 0.0;
                }
                jac[(k, first)] += 1.0;
                for (i, j) in (first..=hi).enumerate() {
                    jac[(k, j)] += ck[i] - at_end[i];
                }
            }
        }
    }
    if first > 0 {
        // the model's U(0) = 0 (no light reads 0), whatever the continuation says
        out[0] = 0.0;
        for c in 0..n {
            jac[(0, c)] = 0.0;
        }
    }
    for v in out.iter_mut() {
        *v = v.max(0.0);
    }
    make_monotone(&mut out, &vec![1.0; n]);
    (out, jac)
}

/// Makes `u` strictly increasing: weighted isotonic regression (pool adjacent violators)
/// with the information per value as weights, then separation of ties.
pub(super) fn make_monotone(u: &mut [f64], weight: &[f64]) {
    let n = u.len();
    let mut blocks: Vec<(f64, f64, usize)> = Vec::with_capacity(n);
    for k in 0..n {
        let w = weight[k].max(1e-12);
        blocks.push((u[k], w, 1));
        while blocks.len() > 1 {
            let n = blocks.len();
            if blocks[n - 2].0 < blocks[n - 1].0 {
                break;
            }
            let (v2, w2, c2) = blocks[n - 1];
            let (v1, w1, c1) = blocks[n - 2];
            blocks.truncate(n - 2);
            blocks.push(((v1 * w1 + v2 * w2) / (w1 + w2), w1 + w2, c1 + c2));
        }
    }
    let mut k = 0;
    for (v, _, c) in blocks {
        for _ in 0..c {
            u[k] = v;
            k += 1;
        }
    }
    let eps = ((u[n - 1] - u[0]).abs() / (n - 1) as f64).max(1e-9) * 1e-4;
    for k in 1..n {
        if u[k] <= u[k - 1] {
            u[k] = u[k - 1] + eps;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{extrapolate, make_monotone};

    fn strictly_increasing(u: &[f64]) -> bool {
        u.windows(2).all(|w| w[1] > w[0])
    }

    #[test]
    fn monotone_pools_violators_by_weight() {
        let mut u = vec![0.0, 3.0, 1.0, 4.0];
        make_monotone(&mut u, &[1.0, 1.0, 3.0, 1.0]);
        // 3 and 1 pool to their weighted mean 1.5, then the tie is separated
        assert_eq!(u[0], 0.0);
        assert!((u[1] - 1.5).abs() < 1e-12 && u[2] > u[1] && u[2] - u[1] < 1e-3);
        assert_eq!(u[3], 4.0);
    }

    #[test]
    fn the_continuation_below_the_data_keeps_u0_at_zero() {
        // data from grey value 10 on, on a line that meets 0 at -90: the continuation reaches
        // 91..99 at 1..9, but U(0) stays 0 (no light reads 0)
        let u: Vec<f64> = (0..256).map(|k| 100.0 + k as f64).collect();
        let (out, jac) = extrapolate(&u, 10, 255);
        assert_eq!(out[0], 0.0);
        assert!((out[5] - 105.0).abs() < 1e-6, "{}", out[5]);
        assert!(strictly_increasing(&out));
        assert!((0..256).all(|c| jac[(0, c)] == 0.0));
        // with data down to 0, the table is left alone
        let (same, _) = extrapolate(&u, 0, 255);
        assert_eq!(same, u);
    }
}
