//! Smoothing of a noisy per-pixel map with a strength chosen from the data: local-linear
//! regression (each pixel's value is the intercept of a weighted plane fitted to its
//! neighbourhood, so that gradients at the image border are not biased as a plain average
//! would bias them) with a Gaussian-like kernel (three box filters, constant cost per pixel
//! whatever the width), weighted by the inverse variance of each pixel.
//!
//! The width is chosen by cross-validation between two independent halves of the data (the
//! maps from the odd and from the even frames): the widest whose smoothing of one half
//! predicts the other half within one standard error of the best prediction (the
//! one-standard-error rule: widths whose scores differ by less than the scores' noise are
//! not told apart by the data), then scaled by `2^(-1/6)` for the full data (the optimal width
//! of a local-linear smoother in two dimensions shrinks as the sixth root of the amount of
//! data).

use rayon::prelude::*;

use crate::stats::small_median;
use crate::PhotometricError;

/// Which smoothing was applied and why.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct SmoothingChoice {
    /// Standard deviation of the kernel in pixels (0: no smoothing).
    pub sigma_px: f64,
    /// Whether it was chosen by cross-validation (else given).
    pub cross_validated: bool,
    /// Candidate widths (pixels, of the half-data maps) and their cross-validation scores
    /// (mean squared prediction error relative to the noise; smaller is better).
    pub scores: Vec<(f64, f64)>,
    /// Pixels left out as defective (far from their neighbourhood in both halves: hot, dead,
    /// dust); the smooth map fills them.
    pub defects: usize,
}

/// A smoothed map with its standard error.
pub(crate) struct Smoothed {
    pub smoothed: Vec<f64>,
    pub smoothed_std: Vec<f64>,
    /// Pixels found defective.
    pub defective: Vec<bool>,
    pub choice: SmoothingChoice,
}

/// Half-size of the neighbourhood against which defective pixels are found.
const DEFECT_RADIUS: usize = 2;

/// A pixel this many standard deviations from its neighbourhood is defective.
const DEFECT_SIGMAS: f64 = 6.0;

/// Box radii of the candidate kernels (`sigma = sqrt(r (r + 1))` for three passes).
const RADII: [usize; 10] = [1, 2, 3, 4, 6, 8, 11, 16, 23, 32];

fn sigma_of_radius(r: usize) -> f64 {
    ((r * (r + 1)) as f64).sqrt()
}

fn radius_for_sigma(sigma: f64) -> usize {
    (((1.0 + 4.0 * sigma * sigma).sqrt() - 1.0) / 2.0)
        .round()
        .max(0.0) as usize
}

/// Rows whose running sums [`box_rows`] takes side by side.
const ROWS_AT_ONCE: usize = 4;

/// Columns that [`box_cols`] takes through its passes at once: a strip of the image that
/// stays in the core's cache (two copies of 1024 rows: 512 KiB).
const COLS_AT_ONCE: usize = 32;

/// `passes` box passes of radius `r` along the rows of `a` (zero outside the image), in
/// place: [`ROWS_AT_ONCE`] rows at a time go through all the passes in a buffer that stays in
/// the core's cache (the image goes through memory once, not once per pass), each pass from
/// the rows' running sums. A row's running sum waits on each of its additions, the sums of
/// several rows are independent and the core overlaps them (the same additions in the same
/// order as one row at a time: the same numbers).
fn box_rows(a: &mut [f64], w: usize, h: usize, r: usize, passes: usize) {
    const K: usize = ROWS_AT_ONCE;
    if w == 0 || h == 0 {
        return;
    }
    // rows[x][i]: row y0 + i at x (rows past the image's last are zeros, never written
    // back); prefix[x][i]: the sum of its first x values (prefix[0] stays 0)
    let mut rows = vec![[0.0f64; K]; w];
    let mut prefix = vec![[0.0f64; K]; w + 1];
    for y0 in (0..h).step_by(K) {
        let k = K.min(h - y0);
        for (i, src) in a[y0 * w..(y0 + k) * w].chunks_exact(w).enumerate() {
            for (dst, v) in rows.iter_mut().zip(src) {
                dst[i] = *v;
            }
        }
        for dst in rows.iter_mut() {
            dst[k..].fill(0.0);
        }
        for _ in 0..passes {
            for x in 0..w {
                let (p, v) = (prefix[x], rows[x]);
                prefix[x + 1] = [p[0] + v[0], p[1] + v[1], p[2] + v[2], p[3] + v[3]];
            }
            for (x, v) in rows.iter_mut().enumerate() {
                let lo = x.saturating_sub(r);
                let hi = (x + r + 1).min(w);
                let (ph, pl) = (prefix[hi], prefix[lo]);
                *v = [ph[0] - pl[0], ph[1] - pl[1], ph[2] - pl[2], ph[3] - pl[3]];
            }
        }
        for (i, dst) in a[y0 * w..(y0 + k) * w].chunks_exact_mut(w).enumerate() {
            for (d, v) in dst.iter_mut().zip(&rows) {
                *d = v[i];
            }
        }
    }
}

/// `passes` box passes of radius `r` along the columns of `a`, in place: a strip of
/// [`COLS_AT_ONCE`] columns at a time goes through all the passes in buffers that stay in the
/// core's cache; in each pass a window of rows slides down the strip (its running sums: the
/// same additions in the same order as down the whole image, the same numbers).
fn box_cols(a: &mut [f64], w: usize, h: usize, r: usize, passes: usize) {
    const S: usize = COLS_AT_ONCE;
    if w == 0 || h == 0 {
        return;
    }
    let mut strip = vec![0.0f64; h * S];
    let mut out = vec![0.0f64; h * S];
    for x0 in (0..w).step_by(S) {
        let s = S.min(w - x0);
        for (y, dst) in strip.chunks_exact_mut(S).enumerate() {
            dst[..s].copy_from_slice(&a[y * w + x0..y * w + x0 + s]);
        }
        for _ in 0..passes {
            let mut acc = [0.0f64; S];
            for row in strip.chunks_exact(S).take(r + 1) {
                for (c, v) in acc.iter_mut().zip(row) {
                    *c += v;
                }
            }
            for y in 0..h {
                out[y * S..(y + 1) * S].copy_from_slice(&acc);
                // the window of row y + 1: rows y + 1 - r ..= y + 1 + r
                if y + r + 1 < h {
                    let add = &strip[(y + r + 1) * S..(y + r + 2) * S];
                    for (c, v) in acc.iter_mut().zip(add) {
                        *c += v;
                    }
                }
                if y >= r {
                    let sub = &strip[(y - r) * S..(y - r + 1) * S];
                    for (c, v) in acc.iter_mut().zip(sub) {
                        *c -= v;
                    }
                }
            }
            std::mem::swap(&mut strip, &mut out);
        }
        for (y, src) in strip.chunks_exact(S).enumerate() {
            a[y * w + x0..y * w + x0 + s].copy_from_slice(&src[..s]);
        }
    }
}

/// Three box passes in each direction: a kernel close to a Gaussian of `sigma_of_radius(r)`
/// (unnormalised: the sums are ratios of smoothed images).
fn blur(src: Vec<f64>, w: usize, h: usize, r: usize) -> Vec<f64> {
    let mut a = src;
    box_rows(&mut a, w, h, r, 3);
    box_cols(&mut a, w, h, r, 3);
    a
}

/// Local-linear smoothing of `v` (NaN = missing) with weights `wt` and box radius `r`;
/// returns the smoothed map and, when `variance` is asked, the variance of each smoothed
/// value for data of variance `1 / wt`.
fn local_linear(
    v: &[f64],
    wt: &[f64],
    w: usize,
    h: usize,
    r: usize,
    variance: bool,
) -> (Vec<f64>, Vec<f64>) {
    local_linear_many(&[(v, variance)], wt, w, h, r)
        .pop()
        .unwrap_or_default()
}

/// [`local_linear`] of several maps with the same weights and radius (each with whether its
/// variance is asked), in one parallel batch of blurs: maps with the same pixels missing
/// share the blurs of the weights' moments (the maps of the odd and of the even frames
/// mostly do), so that only the three moments of their values are blurred for each. The
/// same numbers as one [`local_linear`] per map; a map whose variance is not asked gets an
/// empty variance (a full-size map of NaN would only take memory).
fn local_linear_many(
    maps: &[(&[f64], bool)],
    wt: &[f64],
    w: usize,
    h: usize,
    r: usize,
) -> Vec<(Vec<f64>, Vec<f64>)> {
    let n = w * h;
    if r == 0 {
        return unsmoothed(maps, wt, n);
    }
    let s = (w.max(h) as f64) / 2.0;
    let xs = |i: usize| ((i % w) as f64 - w as f64 / 2.0) / s;
    let ys = |i: usize| ((i / w) as f64 - h as f64 / 2.0) / s;
    // (the same coordinates by column and by row, for the moment images)
    let xcol: Vec<f64> = (0..w).map(xs).collect();
    let yrow: Vec<f64> = (0..h).map(|y| ys(y * w)).collect();
    let (groups, group_of) = weight_groups(maps, wt, n);
    // for the variance: the weights' moments with the squared kernel, a kernel of
    // sigma / sqrt 2 scaled by 1 / (4 pi sigma^2) relative to a unit-sum kernel
    let r2 = radius_for_sigma(sigma_of_radius(r) / 2f64.sqrt()).max(1);
    // the blurs: per group, the six moments of the weights (1, x, y, xx, xy, yy) at r (and
    // at r2 for the variance); per map, the three of its values (1, x, y)
    #[derive(Clone, Copy)]
    enum Src {
        Weights(usize, usize, usize),
        Values(usize, usize),
    }
    let mut tasks = Vec::new();
    for (k, g) in groups.iter().enumerate() {
        tasks.extend((0..6).map(|m| Src::Weights(k, m, r)));
        if g.1 {
            tasks.extend((0..6).map(|m| Src::Weights(k, m, r2)));
        }
    }
    tasks.extend((0..maps.len()).flat_map(|j| (0..3).map(move |m| Src::Values(j, m))));
    // (one loop per kind of moment: the choice is made once per row, not per pixel)
    let moment = |src: Src| -> Vec<f64> {
        // (filled row by row as it is computed: no zeroing of the full-size map first)
        let mut out = Vec::with_capacity(n);
        let (wv, val, m) = match src {
            Src::Weights(k, m, _) => (&groups[k].0, None, m),
            Src::Values(j, m) => (&groups[group_of[j]].0, Some(maps[j].0), m),
        };
        for (y, &yv) in yrow.iter().enumerate() {
            let span = y * w..(y + 1) * w;
            let a = &wv[span.clone()];
            let ax = a.iter().zip(&xcol);
            match (val, m) {
                (None, 0) => out.extend_from_slice(a),
                (None, 1) => out.extend(ax.map(|(a, xv)| a * xv)),
                (None, 2) => out.extend(a.iter().map(|a| a * yv)),
                (None, 3) => out.extend(ax.map(|(a, xv)| a * xv * xv)),
                (None, 4) => out.extend(ax.map(|(a, xv)| a * xv * yv)),
                (None, _) => out.extend(a.iter().map(|a| a * yv * yv)),
                (Some(v), m) => {
                    let finite = |v: &f64| if v.is_finite() { *v } else { 0.0 };
                    let vals = ax.zip(&v[span]);
                    match m {
                        0 => out.extend(vals.map(|((a, _), v)| a * finite(v))),
                        1 => out.extend(vals.map(|((a, xv), v)| a * finite(v) * xv)),
                        _ => out.extend(vals.map(|((a, _), v)| a * finite(v) * yv)),
                    }
                }
            }
        }
        out
    };
    let blurred: Vec<Vec<f64>> = tasks
        .par_iter()
        .map(|&src| {
            let radius = match src {
                Src::Weights(_, _, radius) => radius,
                Src::Values(..) => r,
            };
            blur(moment(src), w, h, radius)
        })
        .collect();
    // where each group's blurs and each map's are in `blurred`
    let mut first = Vec::with_capacity(groups.len());
    let mut at = 0;
    for g in &groups {
        first.push(at);
        at += if g.1 { 12 } else { 6 };
    }
    // kernel sums: sum K = (2r+1)^6, sum K2 (the r2 kernel) = (2 r2 + 1)^6; the squared
    // unit-sum kernel sums to 1 / (4 pi sigma^2)
    let sum_k = ((2 * r + 1) as f64).powi(6);
    let sum_k2 = ((2 * r2 + 1) as f64).powi(6);
    let sig = sigma_of_radius(r);
    let norm2 = sum_k * sum_k / (4.0 * std::f64::consts::PI * sig * sig) / sum_k2;
    maps.iter()
        .enumerate()
        .map(|(j, &(_, variance))| {
            let gw = &blurred[first[group_of[j]]..];
            let gv = &blurred[at + 3 * j..];
            let (s0, sx, sy, sxx, sxy, syy) = (&gw[0], &gw[1], &gw[2], &gw[3], &gw[4], &gw[5]);
            let (sv, svx, svy) = (&gv[0], &gv[1], &gv[2]);
            let q = if variance { &gw[6..12] } else { &[] };
            // each pixel's weighted plane fit (in parallel over the pixels)
            let fit = |i: usize| -> (f64, f64) {
                if s0[i] <= 0.0 {
                    return (f64::NAN, f64::NAN);
                }
                let (xp, yp) = (xs(i), ys(i));
                let a01 = sx[i] - xp * s0[i];
                let a02 = sy[i] - yp * s0[i];
                let a11 = sxx[i] - 2.0 * xp * sx[i] + xp * xp * s0[i];
                let a12 = sxy[i] - xp * sy[i] - yp * sx[i] + xp * yp * s0[i];
                let a22 = syy[i] - 2.0 * yp * sy[i] + yp * yp * s0[i];
                let m = nalgebra::Matrix3::new(s0[i], a01, a02, a01, a11, a12, a02, a12, a22);
                let b = nalgebra::Vector3::new(sv[i], svx[i] - xp * sv[i], svy[i] - yp * sv[i]);
                // a plane needs the neighbourhood to spread in both directions; else a
                // constant
                let det = m.determinant();
                let scale = s0[i] * a11.abs().max(1e-300) * a22.abs().max(1e-300);
                let inv = if det > 1e-9 * scale {
                    m.try_inverse()
                } else {
                    None
                };
                match (inv, q) {
                    (Some(mi), [q0, qx, qy, qxx, qxy, qyy]) => {
                        let c01 = qx[i] - xp * q0[i];
                        let c02 = qy[i] - yp * q0[i];
                        let c11 = qxx[i] - 2.0 * xp * qx[i] + xp * xp * q0[i];
                        let c12 = qxy[i] - xp * qy[i] - yp * qx[i] + xp * yp * q0[i];
                        let c22 = qyy[i] - 2.0 * yp * qy[i] + yp * yp * q0[i];
                        let q =
                            nalgebra::Matrix3::new(q0[i], c01, c02, c01, c11, c12, c02, c12, c22)
                                * norm2;
                        let e = mi.row(0);
                        ((mi * b)[0], (e * q * e.transpose())[(0, 0)].max(0.0))
                    }
                    (Some(mi), _) => ((mi * b)[0], f64::NAN),
                    (None, [q0, ..]) => (sv[i] / s0[i], q0[i] * norm2 / (s0[i] * s0[i])),
                    (None, _) => (sv[i] / s0[i], f64::NAN),
                }
            };
            let pixels = (0..n).into_par_iter().with_min_len(4096);
            if variance {
                pixels.map(fit).unzip()
            } else {
                (pixels.map(|i| fit(i).0).collect(), Vec::new())
            }
        })
        .collect()
}

/// [`local_linear_many`] at radius 0: the maps as they are, each variance `1 / weight`.
fn unsmoothed(maps: &[(&[f64], bool)], wt: &[f64], n: usize) -> Vec<(Vec<f64>, Vec<f64>)> {
    maps.iter()
        .map(|&(v, variance)| {
            let var = if variance {
                (0..n)
                    .map(|i| if wt[i] > 0.0 { 1.0 / wt[i] } else { f64::NAN })
                    .collect()
            } else {
                Vec::new()
            };
            (v.to_vec(), var)
        })
        .collect()
}

/// Each map's weights (0 where it is missing), grouped: maps with the same weights share a
/// group (whose flag says whether any of them needs its variance), and the group of each map.
#[allow(clippy::type_complexity)]
fn weight_groups(
    maps: &[(&[f64], bool)],
    wt: &[f64],
    n: usize,
) -> (Vec<(Vec<f64>, bool)>, Vec<usize>) {
    let mut groups: Vec<(Vec<f64>, bool)> = Vec::new();
    let mut group_of = Vec::with_capacity(maps.len());
    for &(v, variance) in maps {
        let wv: Vec<f64> = (0..n)
            .map(|i| if v[i].is_finite() { wt[i] } else { 0.0 })
            .collect();
        let same =
            |g: &(Vec<f64>, bool)| g.0.iter().zip(&wv).all(|(a, b)| a.to_bits() == b.to_bits());
        match groups.iter().position(same) {
            Some(k) => {
                groups[k].1 |= variance;
                group_of.push(k);
            }
            None => {
                groups.push((wv, variance));
                group_of.push(groups.len() - 1);
            }
        }
    }
    (groups, group_of)
}

/// Side of the neighbourhood of [`find_defects`].
const DEFECT_SIDE: usize = 2 * DEFECT_RADIUS + 1;

/// The defective pixels (hot, dead, a speck of dust) of the map `raw` (`w` x `h`, row-major)
/// whose pixels have the weights `wt` (`1 / variance`; 0: no estimate): those more than
/// [`DEFECT_SIGMAS`] standard deviations (of the difference of two estimates) from what
/// their 5x5 neighbourhood says, which one defect does not move. The neighbourhood says the
/// median of its values with the local slope taken out, the slope being the median of the
/// differences of horizontal (vertical) neighbours: on a plane that is the pixel's value
/// whatever the neighbourhood's shape. A plain median is not: at the border the
/// neighbourhood is one-sided and its median is off by about the map's slope, which on a
/// map with small standard errors (many frames) is several of them per pixel.
pub(crate) fn find_defects(w: usize, h: usize, raw: &[f64], wt: &[f64]) -> Vec<bool> {
    find_defects_screened(w, h, raw, wt, true)
}

/// [`find_defects`], with `screen` the count that spares most pixels the last median: the
/// neighbourhood's value is the median of the detrended neighbours, so when fewer than half
/// of them lie below `raw - t` and fewer than half above `raw + t` (`t` the distance that
/// makes a defect, less a margin far above rounding), the median lies within `t` of the
/// pixel's value and the pixel is not defective, without the median. The pixels that the
/// count does not clear get the median. The result is the same with and without (a test
/// checks it); the count is a third of a pixel's time.
fn find_defects_screened(w: usize, h: usize, raw: &[f64], wt: &[f64], screen: bool) -> Vec<bool> {
    const R: isize = DEFECT_RADIUS as isize;
    const S: usize = DEFECT_SIDE;
    let mut flagged = vec![false; w * h];
    flagged
        .par_chunks_mut(w.max(1))
        .enumerate()
        .for_each(|(y, row)| {
            let mut vals = [[f64::NAN; S]; S];
            let mut buf = [0.0f64; S * S];
            for (x, flag) in row.iter_mut().enumerate() {
                let i = y * w + x;
                if wt[i].is_nan() || wt[i] <= 0.0 {
                    continue;
                }
                // the neighbours with an estimate (NaN: none, outside, or the pixel itself)
                let mut count = 0;
                for (dy, vrow) in (-R..=R).zip(vals.iter_mut()) {
                    for (dx, val) in (-R..=R).zip(vrow.iter_mut()) {
                        let (xx, yy) = (x as isize + dx, y as isize + dy);
                        *val = f64::NAN;
                        if (dx, dy) == (0, 0)
                            || xx < 0
                            || yy < 0
                            || xx >= w as isize
                            || yy >= h as isize
                        {
                            continue;
                        }
                        let j = yy as usize * w + xx as usize;
                        if wt[j] > 0.0 && raw[j].is_finite() {
                            *val = raw[j];
                            count += 1;
                        }
                    }
                }
                if count < 4 {
                    continue;
                }
                // the slope: medians of the neighbours' differences along x and along y
                // (fewer than three: no slope that way)
                let slope = |buf: &mut [f64], n: usize| {
                    if n >= 3 {
                        small_median(&mut buf[..n])
                    } else {
                        0.0
                    }
                };
                let mut n = 0;
                for vrow in &vals {
                    for pair in vrow.windows(2) {
                        let d = pair[1] - pair[0];
                        if d.is_finite() {
                            buf[n] = d;
                            n += 1;
                        }
                    }
                }
                let gx = slope(&mut buf, n);
                n = 0;
                for rows in vals.windows(2) {
                    for (above, below) in rows[0].iter().zip(&rows[1]) {
                        let d = below - above;
                        if d.is_finite() {
                            buf[n] = d;
                            n += 1;
                        }
                    }
                }
                let gy = slope(&mut buf, n);
                n = 0;
                for (dy, vrow) in (-R..=R).zip(&vals) {
                    for (dx, &val) in (-R..=R).zip(vrow) {
                        if val.is_finite() {
                            buf[n] = val - gx * dx as f64 - gy * dy as f64;
                            n += 1;
                        }
                    }
                }
                let scale = (wt[i] / 2.0).sqrt();
                if screen && clearly_not_defective(&buf[..n], raw[i], scale) {
                    continue;
                }
                // (at least four neighbours: never the NaN of no value)
                let reference = small_median(&mut buf[..n]);
                let z = (raw[i] - reference) * scale;
                *flag = z.abs() > DEFECT_SIGMAS;
            }
        });
    flagged
}

/// Whether the median of `d` (as [`median`] takes it: the middle value, or the mean of the
/// two middle ones) is certainly within [`DEFECT_SIGMAS`] / `scale` of `value`, from counts
/// alone: the lower middle value is at least `value - t` when at most its index of the
/// values lie below that, and the upper one at most `value + t` likewise. `t` keeps a
/// relative margin of 1e-6 (rounding is 1e-16), and values where the margin is not far
/// above the rounding of `value` itself are left to the median.
fn clearly_not_defective(d: &[f64], value: f64, scale: f64) -> bool {
    let t = DEFECT_SIGMAS / scale * (1.0 - 1e-6);
    if d.is_empty() || !(value.is_finite() && t.is_finite() && t > 1e-6 * value.abs()) {
        return false;
    }
    let (lo, hi) = (value - t, value + t);
    let (below, above) = d.iter().fold((0usize, 0usize), |(b, a), &x| {
        (b + (x < lo) as usize, a + (x > hi) as usize)
    });
    let n = d.len();
    let mid = n / 2;
    let lower_middle = if n.is_multiple_of(2) { mid - 1 } else { mid };
    below <= lower_middle && above < n - mid
}

/// Chooses the smoothing (or applies `fixed`) and smooths `raw`; NaN pixels of `raw` are
/// filled from their neighbourhood (the widest kernel where the chosen one sees no data).
pub(crate) fn choose_smoothing(
    w: usize,
    h: usize,
    raw: &[f64],
    raw_var: &[f64],
    odd: &[f64],
    even: &[f64],
    fixed: Option<f64>,
) -> Result<Smoothed, PhotometricError> {
    let n = w * h;
    let mut wt: Vec<f64> = (0..n)
        .map(|i| {
            if raw[i].is_finite() && raw_var[i].is_finite() && raw_var[i] > 0.0 {
                1.0 / raw_var[i]
            } else {
                0.0
            }
        })
        .collect();
    // defective pixels (hot, dead, a speck of dust) are real in both halves of the data, so
    // cross-validation would keep them; they are left out of the smooth map
    let flagged = find_defects(w, h, raw, &wt);
    let mut defects = 0usize;
    for i in 0..n {
        if flagged[i] {
            wt[i] = 0.0;
            defects += 1;
        }
    }
    // the halves have about twice the variance: the same relative weights
    let mut scores = Vec::new();
    let (radius, cross_validated) = match fixed {
        Some(s) => (radius_for_sigma(s.max(0.0)), false),
        None => (
            cross_validated_radius(odd, even, &wt, (w, h), &mut scores)?,
            true,
        ),
    };
    // the map, and the halves smoothed as the whole is (for the variance's scale and the
    // bias below)
    // (the halves in a batch of their own: all three at once would hold some 30 full-size
    // blurs; the numbers are the same)
    let halves = (radius > 0).then(|| {
        let mut batch = local_linear_many(&[(odd, false), (even, false)], &wt, w, h, radius);
        let (se, _) = batch.pop().unwrap_or_default();
        let (so, _) = batch.pop().unwrap_or_default();
        (so, se)
    });
    let (mut smoothed, mut var) = local_linear_many(&[(raw, true)], &wt, w, h, radius)
        .pop()
        .unwrap_or_default();
    // the variance above treats pixels as independent; JPEG's 8x8 blocks and the shared
    // plane irradiance correlate neighbours. The same smoothing of the odd and of the even
    // half differs by noise alone: its spread calibrates the smoothed map's variance
    // (each half has about twice the variance of the whole: four times for the difference)
    if let Some((so, se)) = &halves {
        let (mut num, mut den) = (0.0, 0.0);
        for i in 0..n {
            if wt[i] > 0.0 && so[i].is_finite() && se[i].is_finite() && var[i] > 0.0 {
                num += (so[i] - se[i]).powi(2);
                den += 4.0 * var[i];
            }
        }
        if den > 0.0 {
            let kappa = (num / den).clamp(0.25, 100.0);
            for v in var.iter_mut() {
                *v *= kappa;
            }
        }
    }
    // the smoothing's own error: a local plane misses the curvature of V. Smoothing the
    // smoothed map again adds about the same bias once more (S(SV) - SV is the bias of S at
    // V, with the noise already averaged out), and it enters the variance in quadrature
    // (that difference still carries some noise, measured by the same difference of the odd
    // and of the even half and taken out; the squared bias is averaged over the kernel)
    if let Some((so, se)) = &halves {
        let mut again = local_linear_many(
            &[(&smoothed, false), (so, false), (se, false)],
            &wt,
            w,
            h,
            radius,
        );
        let (te, _) = again.pop().unwrap_or_default();
        let (to, _) = again.pop().unwrap_or_default();
        let (tf, _) = again.pop().unwrap_or_default();
        let b2: Vec<f64> = (0..n)
            .map(|i| {
                let d = tf[i] - smoothed[i];
                let e = ((to[i] - so[i]) - (te[i] - se[i])) / 2.0;
                if d.is_finite() && e.is_finite() {
                    d * d - e * e
                } else {
                    0.0
                }
            })
            .collect();
        // (blur sums over its kernel: (2r+1)^2 per box pass, three passes)
        let b2 = blur(b2, w, h, radius);
        let norm = ((2 * radius + 1) as f64).powi(6);
        for (v, b) in var.iter_mut().zip(&b2) {
            *v += (b / norm).max(0.0);
        }
    }
    // fill what the kernel does not reach
    if smoothed.iter().any(|v| !v.is_finite()) {
        let wide = *RADII.last().unwrap_or(&32);
        let (fill, fill_var) = local_linear(raw, &wt, w, h, wide.max(radius), true);
        for i in 0..n {
            if !smoothed[i].is_finite() {
                smoothed[i] = fill[i];
                var[i] = fill_var[i];
            }
        }
    }
    if smoothed.iter().any(|v| !v.is_finite()) {
        return Err(PhotometricError::Calibration(
            "parts of the image are farther than the widest smoothing from any calibrated pixel; film the wall so that it covers the whole image".into(),
        ));
    }
    let smoothed_std = var.iter().map(|v| v.max(0.0).sqrt()).collect();
    Ok(Smoothed {
        smoothed,
        smoothed_std,
        defective: flagged,
        choice: SmoothingChoice {
            sigma_px: if radius == 0 {
                0.0
            } else {
                sigma_of_radius(radius)
            },
            cross_validated,
            scores,
            defects,
        },
    })
}

/// The smoothing radius chosen by cross-validation between the maps of the odd and of the
/// even frames (`scores` gets every candidate's sigma and score): the widest candidate within
/// one standard error of the best, narrowed for the full data.
fn cross_validated_radius(
    odd: &[f64],
    even: &[f64],
    wt: &[f64],
    (w, h): (usize, usize),
    scores: &mut Vec<(f64, f64)>,
) -> Result<usize, PhotometricError> {
    let n = w * h;
    // each candidate's score (mean squared prediction error) and its standard error
    // (the candidates in parallel: each one's sums in the same order with any number
    // of threads)
    let candidates: Vec<usize> = std::iter::once(0).chain(RADII).collect();
    let score_of = |r: usize| -> (usize, f64, f64) {
        let mut halves = local_linear_many(&[(odd, false), (even, false)], wt, w, h, r);
        let (se, _) = halves.pop().unwrap_or_default();
        let (so, _) = halves.pop().unwrap_or_default();
        let (mut s, mut s2, mut cnt) = (0.0, 0.0, 0.0);
        for i in 0..n {
            if odd[i].is_finite() && even[i].is_finite() && wt[i] > 0.0 {
                for (pred, other) in [(so[i], even[i]), (se[i], odd[i])] {
                    if pred.is_finite() {
                        let c = (pred - other).powi(2) * wt[i] / 2.0;
                        s += c;
                        s2 += c * c;
                        cnt += 1.0;
                    }
                }
            }
        }
        let (score, sem) = if cnt > 1.0 {
            let mean = s / cnt;
            let var = (s2 / cnt - mean * mean).max(0.0);
            (mean, (var / (cnt - 1.0)).sqrt())
        } else {
            (f64::INFINITY, 0.0)
        };
        (r, score, sem)
    };
    // (one after the other: each one's blurs are in parallel, and two at once would
    // hold twice the memory, some 20 full-size maps each)
    let scored: Vec<(usize, f64, f64)> = candidates.iter().map(|&r| score_of(r)).collect();
    for &(r, score, _) in &scored {
        scores.push((if r == 0 { 0.0 } else { sigma_of_radius(r) }, score));
    }
    let Some(&(_, min_score, min_sem)) = scored
        .iter()
        .filter(|c| c.1.is_finite())
        .min_by(|a, b| a.1.total_cmp(&b.1))
    else {
        return Err(PhotometricError::Calibration(
            "the odd and the even frames see no pixel in common; the smoothing cannot be chosen (record more frames)".into(),
        ));
    };
    // the one-standard-error rule: the widest candidate whose score is within one
    // standard error of the best; scores that differ by less than their noise do not
    // decide (neighbouring widths often tie, and the argmin would flip between them)
    let best = scored
        .iter()
        .filter(|c| c.1 <= min_score + min_sem)
        .map(|c| c.0)
        .max()
        .unwrap_or(0);
    // the full data: a kernel 2^(-1/6) as wide
    let s_half = if best == 0 {
        0.0
    } else {
        sigma_of_radius(best)
    };
    Ok(radius_for_sigma(s_half * 2f64.powf(-1.0 / 6.0)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_hole_does_not_disturb_a_plane() {
        let (w, h) = (64usize, 48usize);
        let mut v: Vec<f64> = (0..w * h)
            .map(|i| 1.0 + 0.001 * (i % w) as f64 - 0.002 * (i / w) as f64)
            .collect();
        v[20 * w + 30] = f64::NAN;
        let wt: Vec<f64> = v
            .iter()
            .map(|x| if x.is_finite() { 1e5 } else { 0.0 })
            .collect();
        for r in [1, 2, 4, 8] {
            let (s, var) = local_linear(&v, &wt, w, h, r, true);
            for i in 0..w * h {
                let truth = 1.0 + 0.001 * (i % w) as f64 - 0.002 * (i / w) as f64;
                assert!(
                    (s[i] - truth).abs() < 1e-9,
                    "r {r} at {} {}: {} vs {truth}",
                    i % w,
                    i / w,
                    s[i]
                );
                assert!(var[i].is_finite() && var[i] > 0.0);
            }
        }
    }

    #[test]
    fn defects_are_found_on_a_sloped_noisy_map_and_nothing_else() {
        // a vignette-like slope (two standard deviations per pixel) with noise of a known
        // standard deviation (a fixed pseudo-random sequence), one hot and one dead pixel, a
        // pixel without an estimate, and the borders and corners in play
        let (w, h) = (40usize, 30usize);
        let sd = 1e-3;
        let mut rng = synthetic::Rng::new(0x2545_f491_4f6c_dd1d);
        let mut noise = || {
            // the sum of four uniforms: close to normal, never beyond 3.5 sd
            let s: f64 = (0..4).map(|_| rng.uniform() - 0.5).sum();
            s * sd * 3.0f64.sqrt()
        };
        let mut v: Vec<f64> = (0..w * h)
            .map(|i| 0.6 + 0.002 * (i % w) as f64 - 0.001 * (i / w) as f64 + noise())
            .collect();
        let mut wt = vec![1.0 / (sd * sd); w * h];
        let (hot, dead, none) = (7 * w + 11, (h - 1) * w, 3 * w + 3);
        v[hot] += 0.05;
        v[dead] = 0.0;
        wt[none] = 0.0;
        let flagged = find_defects(w, h, &v, &wt);
        let found: Vec<usize> = (0..w * h).filter(|&i| flagged[i]).collect();
        assert_eq!(found, vec![hot, dead]);
    }

    /// The count that spares most pixels the last median changes no pixel's verdict: maps
    /// of every kind of neighbourhood (borders, holes, steep slopes, defects of every size,
    /// pixels just at the threshold, tiny and huge standard errors) give the same pixels
    /// with it and without.
    #[test]
    fn the_screen_changes_no_verdict() {
        let mut rng = synthetic::Rng::new(2024);
        let mut flagged_any = 0;
        for case in 0..60 {
            let (w, h) = (3 + case % 17, 2 + (case * 7) % 23);
            let sd = [1e-9, 1e-6, 1e-4, 1e-2, 0.3][case % 5];
            let (gx, gy) = (rng.uniform() - 0.5, rng.uniform() - 0.5);
            let slope = [0.0, sd, 10.0 * sd, 1.0][case % 4];
            let mut v: Vec<f64> = (0..w * h)
                .map(|i| {
                    let (x, y) = ((i % w) as f64, (i / w) as f64);
                    0.5 + slope * (gx * x + gy * y) + sd * (rng.uniform() - 0.5) * 3.0
                })
                .collect();
            let mut wt = vec![1.0 / (sd * sd); w * h];
            for i in 0..w * h {
                let u = rng.uniform();
                if u < 0.08 {
                    wt[i] = 0.0;
                    v[i] = f64::NAN;
                } else if u < 0.16 {
                    // a defect of any size, some of them near the threshold
                    let k = 12.0 * rng.uniform();
                    v[i] += if rng.uniform() < 0.5 { k } else { -k } * sd;
                } else if u < 0.18 {
                    wt[i] *= 1e6;
                }
            }
            let fast = find_defects_screened(w, h, &v, &wt, true);
            let exact = find_defects_screened(w, h, &v, &wt, false);
            assert_eq!(fast, exact, "case {case}: {w}x{h}, sd {sd}, slope {slope}");
            flagged_any += exact.iter().filter(|f| **f).count();
        }
        assert!(flagged_any > 50, "{flagged_any} pixels flagged in all");
    }

    /// The cache-friendly blur is three plain box sums in each direction (zero outside),
    /// at image sizes around the strip and row-group widths and radii past the image.
    #[test]
    fn blur_is_three_box_sums_each_way() {
        let box_sum = |v: &[f64], w: usize, h: usize, r: usize, along_rows: bool| -> Vec<f64> {
            (0..w * h)
                .map(|i| {
                    let (x, y) = ((i % w) as isize, (i / w) as isize);
                    (-(r as isize)..=r as isize)
                        .map(|d| {
                            let (xx, yy) = if along_rows { (x + d, y) } else { (x, y + d) };
                            if xx < 0 || yy < 0 || xx >= w as isize || yy >= h as isize {
                                0.0
                            } else {
                                v[yy as usize * w + xx as usize]
                            }
                        })
                        .sum()
                })
                .collect()
        };
        let mut rng = synthetic::Rng::new(5);
        for (w, h, r) in [
            (1, 1, 1),
            (3, 7, 2),
            (33, 5, 1),
            (31, 9, 4),
            (65, 13, 3),
            (7, 40, 30),
        ] {
            let v: Vec<f64> = (0..w * h).map(|_| rng.uniform() - 0.3).collect();
            let mut want = v.clone();
            for along_rows in [true, true, true, false, false, false] {
                want = box_sum(&want, w, h, r, along_rows);
            }
            let got = blur(v, w, h, r);
            for (g, e) in got.iter().zip(&want) {
                assert!(
                    (g - e).abs() <= 1e-9 * (1.0 + e.abs()),
                    "{w}x{h} r {r}: {g} vs {e}"
                );
            }
        }
        assert!(blur(Vec::new(), 0, 0, 3).is_empty());
    }

    /// The count decides the usual pixel alone, and never a defect's.
    #[test]
    fn the_screen_clears_ordinary_pixels_only() {
        let d: Vec<f64> = (0..24)
            .map(|k| 1.0 + 1e-3 * ((k * 7 % 11) as f64 - 5.0))
            .collect();
        let scale = 1e3; // a standard deviation of 1e-3: 6 of them are 6e-3
        assert!(clearly_not_defective(&d, 1.0, scale));
        assert!(clearly_not_defective(&d[..23], 1.004, scale));
        assert!(!clearly_not_defective(&d, 1.007, scale));
        assert!(!clearly_not_defective(&d, 0.99, scale));
        assert!(!clearly_not_defective(&d, f64::NAN, scale));
        assert!(!clearly_not_defective(&[], 1.0, scale));
    }

    /// A steep map (up to 10 standard deviations per pixel, in a direction off the axes, as
    /// the corners of a strong vignette calibrated from thousands of frames are) with a
    /// few holes: no pixel is found defective but the two real defects, at the borders and
    /// corners and beside the holes too. A plain median of a one-sided neighbourhood is off
    /// by about the slope there (and by a fraction of it in the interior).
    #[test]
    fn steep_maps_have_no_defects_at_their_borders() {
        let (w, h) = (48usize, 36usize);
        let sd = 1e-3;
        let mut rng = synthetic::Rng::new(77);
        for (gx, gy) in [(0.01, -0.004), (-0.007, 0.007), (0.0, 0.01), (0.003, 0.0)] {
            let mut v: Vec<f64> = (0..w * h)
                .map(|i| {
                    let (x, y) = ((i % w) as f64, (i / w) as f64);
                    let s: f64 = (0..4).map(|_| rng.uniform() - 0.5).sum();
                    0.5 + gx * x + gy * y + s * sd * 3.0f64.sqrt()
                })
                .collect();
            let mut wt = vec![1.0 / (sd * sd); w * h];
            for hole in [0, 5 * w + 1, 20 * w + 20, 20 * w + 21, h * w - 1] {
                wt[hole] = 0.0;
                v[hole] = f64::NAN;
            }
            let (hot, dead) = (w + 30, (h - 2) * w + 2);
            v[hot] += 0.03;
            v[dead] -= 0.03;
            let flagged = find_defects(w, h, &v, &wt);
            let found: Vec<usize> = (0..w * h).filter(|&i| flagged[i]).collect();
            assert_eq!(found, vec![hot, dead], "slope ({gx}, {gy}) per pixel");
        }
    }
}
