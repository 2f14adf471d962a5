//! The noise variance as a function of the predicted grey value, measured from the residuals:
//! a robust scale per bin of predicted values (the median absolute residual, so that moving
//! objects and misregistered edges do not inflate it), corrected for the residual's leverage,
//! smoothed across bins. Next to a clipping point the clipping removes one side of the
//! distribution (the values beyond it are censored): there the other side alone measures it
//! (the median of the half-normal is the same).

use super::model::normal_cdf;

/// Bins of predicted values.
pub(super) const BINS: usize = 32;

/// Buckets of `|r|` per bin, log-spaced by [`BUCKET_RATIO`] from [`BUCKET_MIN`] knots.
const BUCKETS: usize = 200;
const BUCKET_MIN: f64 = 1e-3;
const BUCKET_RATIO: f64 = 1.1;

/// Bins with fewer residuals are not measured (they take their neighbours' value).
const MIN_COUNT: u64 = 100;

/// `median(|z|)` of a standard normal.
const MAD_NORMAL: f64 = 0.674_489_750_196_081_7;

/// The residual histograms of one pass (negative and positive residuals apart), merged in a
/// fixed order.
#[derive(Clone)]
pub(super) struct ResidualStats {
    /// `[bin][side][bucket]`, side 0 for residuals below 0.
    counts: Vec<u32>,
    knots: usize,
}

/// Which residuals measure a bin.
#[derive(Clone, Copy)]
enum Side {
    Both,
    Negative,
    Positive,
}

impl ResidualStats {
    pub fn new(knots: usize) -> ResidualStats {
        ResidualStats {
            counts: vec![0; BINS * 2 * BUCKETS],
            knots,
        }
    }

    #[inline]
    fn bin(&self, mu: f64) -> usize {
        let t = mu / (self.knots - 1) as f64;
        ((t * BINS as f64).max(0.0) as usize).min(BINS - 1)
    }

    /// Adds a residual `r` of leverage `h` at prediction `mu` (knots).
    #[inline]
    pub fn add(&mut self, mu: f64, r: f64, h: f64) {
        let a = r.abs() / (1.0 - h).max(0.1).sqrt();
        let k = if a <= BUCKET_MIN {
            0
        } else {
            (((a / BUCKET_MIN).ln() / BUCKET_RATIO.ln()) as usize).min(BUCKETS - 1)
        };
        let b = self.bin(mu);
        let side = usize::from(r > 0.0);
        self.counts[(b * 2 + side) * BUCKETS + k] += 1;
    }

    pub fn merge(&mut self, o: &ResidualStats) {
        for (a, b) in self.counts.iter_mut().zip(&o.counts) {
            *a += b;
        }
    }

    /// Residuals per bin.
    pub fn count(&self, b: usize) -> u64 {
        self.counts[b * 2 * BUCKETS..(b + 1) * 2 * BUCKETS]
            .iter()
            .map(|&c| c as u64)
            .sum()
    }

    /// The robust variance of a bin from the residuals of `side`, `(median |r| / 0.6745)^2`,
    /// or `None` with too few residuals.
    fn robust_variance(&self, b: usize, side: Side) -> Option<f64> {
        let at = |s: usize, k: usize| self.counts[(b * 2 + s) * BUCKETS + k] as u64;
        let h: Vec<u64> = (0..BUCKETS)
            .map(|k| match side {
                Side::Both => at(0, k) + at(1, k),
                Side::Negative => at(0, k),
                Side::Positive => at(1, k),
            })
            .collect();
        let n: u64 = h.iter().sum();
        if n < MIN_COUNT {
            return None;
        }
        let half = n as f64 / 2.0;
        let mut cum = 0.0;
        for (k, &c) in h.iter().enumerate() {
            let next = cum + c as f64;
            if next >= half && c > 0 {
                // geometric interpolation inside the bucket
                let frac = (half - cum) / c as f64;
                let lo = if k == 0 {
                    0.0
                } else {
                    BUCKET_MIN * BUCKET_RATIO.powi(k as i32)
                };
                let hi = BUCKET_MIN * BUCKET_RATIO.powi(k as i32 + 1);
                let med = if lo > 0.0 {
                    lo * (hi / lo).powf(frac)
                } else {
                    hi * frac
                };
                return Some((med / MAD_NORMAL).powi(2));
            }
            cum = next;
        }
        None
    }
}

/// The measured variance: per bin (centre in knots, variance in knots squared, residuals), and
/// the variance at every knot.
#[derive(Clone, Debug)]
pub(super) struct Measured {
    pub bins: Vec<(f64, f64, u64)>,
    pub per_knot: Vec<f64>,
}

/// Measures the variance from the residual statistics. `clip_lo` and `clip_hi` are the
/// clipping points in knots; `floor` the smallest variance. `None` when no bin has enough
/// residuals.
pub(super) fn measure(
    stats: &ResidualStats,
    clip_lo: f64,
    clip_hi: f64,
    floor: f64,
) -> Option<Measured> {
    let knots = stats.knots;
    let width = (knots - 1) as f64 / BINS as f64;
    let centre = |b: usize| (b as f64 + 0.5) * width;
    // robust variances; where the clipping truncates one side (the bin within two standard
    // deviations of a clip), from the other side
    let raw: Vec<Option<f64>> = (0..BINS)
        .map(|b| {
            let both = stats.robust_variance(b, Side::Both)?;
            let sd = both.sqrt();
            let c = centre(b);
            let (lo, hi) = (c - 0.5 * width - 2.0 * sd, c + 0.5 * width + 2.0 * sd);
            match (lo > clip_lo, hi < clip_hi) {
                (true, true) => Some(both),
                (true, false) => stats.robust_variance(b, Side::Negative),
                (false, true) => stats.robust_variance(b, Side::Positive),
                (false, false) => None,
            }
        })
        .collect();
    if raw.iter().all(|v| v.is_none()) {
        return None;
    }
    // smoothing: count-weighted mean of log variance over +-2 bins
    let smooth: Vec<Option<f64>> = (0..BINS)
        .map(|b| {
            raw[b]?;
            let (mut s, mut w) = (0.0, 0.0);
            for (d, v) in raw
                .iter()
                .enumerate()
                .take((b + 3).min(BINS))
                .skip(b.saturating_sub(2))
            {
                if let Some(v) = v {
                    let c = stats.count(d) as f64;
                    s += c * v.ln();
                    w += c;
                }
            }
            Some((s / w).exp())
        })
        .collect();
    // bins without a measurement take the nearest measured bin's value
    let filled: Vec<f64> = (0..BINS)
        .map(|b| {
            (0..BINS)
                .filter_map(|d| smooth[d].map(|v| (d.abs_diff(b), v)))
                .min_by_key(|&(dist, _)| dist)
                .map_or(floor, |(_, v)| v)
                .max(floor)
        })
        .collect();
    let per_knot = (0..knots)
        .map(|k| {
            let x = k as f64 / width - 0.5;
            if x <= 0.0 {
                filled[0]
            } else if x >= (BINS - 1) as f64 {
                filled[BINS - 1]
            } else {
                let b = x as usize;
                let f = x - b as f64;
                // interpolate in log: the variance changes by factors
                (filled[b].ln() * (1.0 - f) + filled[b + 1].ln() * f).exp()
            }
        })
        .collect();
    Some(Measured {
        bins: (0..BINS)
            .map(|b| (centre(b), raw[b].unwrap_or(f64::NAN), stats.count(b)))
            .collect(),
        per_knot,
    })
}

/// Bins of the values of pixels saturated for sure (the solver's `Sums::deep`): values 0 to
/// 15 grey values below the top.
pub(super) const DEEP_BINS: usize = 16;

/// Predictions this many standard deviations beyond the top count as saturated for sure.
pub(super) const DEEP_SD: f64 = 4.0;

/// Of the values the saturation border drops, those of every this many pixels measure the
/// noise after the clip.
pub(super) const DEEP_STRIDE: usize = 8;

/// Values of pixels saturated for sure needed to measure the noise after the clip.
const DEEP_MIN: u64 = 200;

/// The largest total-variation distance (plus `1 / sqrt(values)` for the sampling) between
/// the values of saturated pixels and the noise fitted to them: beyond it the noise after the
/// clip is not measured (the values do not look like one).
const POST_MAX_DISTANCE: f64 = 0.05;

/// A noise after the clip below this (grey values) counts as none.
const POST_MIN: f64 = 0.1;

/// The probability that a Gaussian noise of `sigma` added to the top, rounded and clipped
/// there, reads `k` values below the top.
fn clipped_bin(k: usize, sigma: f64) -> f64 {
    let kf = k as f64;
    if k == 0 {
        normal_cdf(0.5 / sigma)
    } else {
        normal_cdf((0.5 - kf) / sigma) - normal_cdf((-0.5 - kf) / sigma)
    }
}

/// The noise after the clip, in grey values, from the values of pixels saturated for sure
/// (`deep`, by how far below the top they read): the maximum-likelihood standard deviation
/// of a Gaussian noise added to the top, rounded and clipped there, given that the value is
/// within the bins, with 1% of the values anywhere in them (moving objects, hot pixels).
/// `None` with too few values, or values that such a noise does not describe
/// ([`POST_MAX_DISTANCE`]).
pub(super) fn post_clip_noise(deep: &[u64]) -> Option<f64> {
    let total: u64 = deep.iter().sum();
    if total < DEEP_MIN {
        return None;
    }
    let last = deep.len() - 1;
    let loglik = |sigma: f64| -> f64 {
        // the probability of the bins: the value is within them
        let inside = 1.0 - normal_cdf((-0.5 - last as f64) / sigma);
        let mut l = 0.0;
        for (k, &c) in deep.iter().enumerate() {
            if c == 0 {
                continue;
            }
            let prob = clipped_bin(k, sigma);
            l += c as f64 * (0.99 * prob / inside + 0.01 / deep.len() as f64).ln();
        }
        l
    };
    // a fine grid in log sigma from 0.02 to 10 grey values (the likelihood is cheap)
    let (mut best, mut best_l) = (0.0, f64::NEG_INFINITY);
    for i in 0..=300 {
        let sigma = 0.02 * (500f64).powf(i as f64 / 300.0);
        let l = loglik(sigma);
        if l > best_l {
            best_l = l;
            best = sigma;
        }
    }
    // the values must look like that noise: a camera that clips below the top (many read
    // one value under it, few the top) or spreads its highlights otherwise is not described
    let inside = 1.0 - normal_cdf((-0.5 - last as f64) / best);
    let distance: f64 = deep
        .iter()
        .enumerate()
        .map(|(k, &c)| (c as f64 / total as f64 - clipped_bin(k, best) / inside).abs())
        .sum::<f64>()
        / 2.0;
    if distance > POST_MAX_DISTANCE + 1.0 / (total as f64).sqrt() {
        return None;
    }
    Some(if best < POST_MIN { 0.0 } else { best })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Gaussian residuals of a known standard deviation per bin, with 5% gross outliers: the
    /// measured variance is within 15% of the truth away from the clips (the outliers widen
    /// the median by about 7%).
    #[test]
    fn measures_the_variance_robustly() {
        let knots = 256;
        let mut st = ResidualStats::new(knots);
        let mut state = 12345u64;
        let mut uniform = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        };
        let sd_at = |mu: f64| 0.5 + mu / 100.0;
        for i in 0..400_000 {
            let mu = (i % 255) as f64 + 0.5;
            let g = (-2.0 * uniform().ln()).sqrt() * (std::f64::consts::TAU * uniform()).cos();
            let r = if i % 20 == 0 {
                50.0 * (uniform() - 0.5)
            } else {
                g * sd_at(mu)
            };
            st.add(mu, r, 0.0);
        }
        let m = measure(&st, 0.5, 254.5, 1e-3).unwrap();
        for k in [40usize, 100, 200] {
            let want = sd_at(k as f64).powi(2);
            let got = m.per_knot[k];
            assert!((got / want - 1.0).abs() < 0.15, "{k}: {got} {want}");
        }
    }

    /// Counts of a Gaussian noise of `sigma` added to the top, rounded and clipped, in
    /// [`DEEP_BINS`] bins.
    fn clipped_counts(sigma: f64, n: f64) -> Vec<u64> {
        (0..DEEP_BINS)
            .map(|k| (clipped_bin(k, sigma) * n).round() as u64)
            .collect()
    }

    #[test]
    fn the_noise_after_the_clip_is_recovered_from_saturated_values() {
        for sigma in [0.3, 0.5, 1.0, 2.0, 4.0] {
            let got = post_clip_noise(&clipped_counts(sigma, 50_000.0)).expect("measured");
            assert!((got - sigma).abs() < 0.03 * sigma + 0.02, "{sigma}: {got}");
        }
        // too few values: not measured
        assert_eq!(post_clip_noise(&clipped_counts(1.0, 150.0)), None);
        // (almost) every saturated pixel reads the top: none
        let mut top = vec![0u64; DEEP_BINS];
        top[0] = 10_000;
        top[1] = 3;
        assert_eq!(post_clip_noise(&top), Some(0.0));
    }

    #[test]
    fn saturated_values_that_no_such_noise_describes_are_not_measured() {
        // a camera that clips one value under the top (the saturated pixels of a Canon S45
        // bracket: more read 254 than 255), and highlights spread flat over many values (the
        // first six counts are those of a raw converter's night-street export)
        let s45 = [4545, 5774, 414, 119, 28, 10, 9, 6, 3, 1, 2, 1, 0, 2, 0, 0];
        assert_eq!(post_clip_noise(&s45), None);
        let street = [
            187, 153, 149, 101, 98, 131, 120, 90, 70, 60, 50, 40, 30, 20, 10, 5,
        ];
        assert_eq!(post_clip_noise(&street), None);
    }
}
