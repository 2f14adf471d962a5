//! The observation model `I = clip(round(G(t B') + n))`: the forward response `G`, the noise
//! `n` as measured from the residuals, and each observation's term of the likelihood:
//! Gaussian where the value is inside `1 ..= top - 1`, the probability of clipping where it is
//! `0` or `top` (censored), with a bounded influence for outliers.

use super::samples::Levels;

/// The forward response `G = U^-1` of a strictly increasing table, piecewise linear, with a
/// lookup table over `sqrt(energy)` that makes each evaluation a few operations.
pub(super) struct Forward {
    pub u: Vec<f64>,
    pub inv_du: Vec<f64>,
    lut: Vec<u16>,
    lut_scale: f64,
}

const LUT_SIZE: usize = 4096;

impl Forward {
    pub fn new(u: &[f64]) -> Forward {
        let n = u.len();
        let mut inv_du = vec![0.0; n];
        for j in 0..n - 1 {
            inv_du[j] = 1.0 / (u[j + 1] - u[j]).max(1e-12);
        }
        inv_du[n - 1] = inv_du[n - 2];
        let top = u[n - 1].max(1e-12);
        let lut_scale = LUT_SIZE as f64 / top.sqrt();
        let mut lut = vec![0u16; LUT_SIZE + 1];
        let mut j = 0usize;
        for (b, slot) in lut.iter_mut().enumerate() {
            let e = (b as f64 / lut_scale).powi(2);
            while j < n - 2 && u[j + 1] <= e {
                j += 1;
            }
            *slot = j as u16;
        }
        Forward {
            u: u.to_vec(),
            inv_du,
            lut,
            lut_scale,
        }
    }

    /// `(j, f)` with `G(e) = j + f` (in knots): `f` in `[0, 1)` inside `[U(0), U(top)]`, and
    /// the first or last segment continued linearly outside (so that a prediction beyond the
    /// table still has a slope that pulls it back).
    #[inline]
    pub fn eval(&self, e: f64) -> (usize, f64) {
        let n = self.u.len();
        if e.is_nan() || e < self.u[0] {
            return (0, (e - self.u[0]) * self.inv_du[0]);
        }
        if e >= self.u[n - 1] {
            let j = n - 2;
            return (j, (e - self.u[j]) * self.inv_du[j]);
        }
        let b = ((e.sqrt() * self.lut_scale) as usize).min(LUT_SIZE);
        let mut j = self.lut[b] as usize;
        while j < n - 2 && self.u[j + 1] <= e {
            j += 1;
        }
        (j, ((e - self.u[j]) * self.inv_du[j]).clamp(0.0, 1.0))
    }
}

/// How an observation is weighted.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Weighting {
    /// Choose by the predictive score of held-out exposures (measured unless uniform predicts
    /// them better).
    Auto,
    /// Each observation weighted by the inverse of the noise variance measured at its
    /// predicted grey value.
    Measured,
    /// Every observation weighted alike.
    Uniform,
}

/// The noise at every knot as the calibration uses it: its standard deviation (knots), which
/// says how far off a value is and how likely clipping is, and the weight of an observation
/// predicted there (the inverse variance, or the same everywhere).
#[derive(Clone, Debug)]
pub(super) struct Noise {
    pub sd: Vec<f64>,
    pub weight: Vec<f64>,
}

impl Noise {
    /// Weights by the variance `var` (knots squared) itself.
    pub fn measured(var: &[f64]) -> Noise {
        Noise {
            sd: var.iter().map(|v| v.sqrt()).collect(),
            weight: var.iter().map(|v| 1.0 / v).collect(),
        }
    }

    /// The noise `var`, every observation weighted as one of variance `uniform`.
    pub fn uniform(var: &[f64], uniform: f64) -> Noise {
        Noise {
            sd: var.iter().map(|v| v.sqrt()).collect(),
            weight: vec![1.0 / uniform; var.len()],
        }
    }

    #[inline]
    pub fn at(&self, j: usize, f: f64) -> usize {
        let k = if f < 0.5 { j } else { j + 1 };
        k.min(self.sd.len() - 1)
    }
}

/// What a value says: a grey value, or clipping at the top or at 0.
#[derive(Clone, Copy, Debug)]
pub(super) enum Obs {
    /// A value strictly inside the range, in knots.
    Value(f64),
    /// Saturated: the noisy value reached the top (in knots, half a grey value below it).
    Above(f64),
    /// Clipped to 0: the noisy value stayed below half a grey value (in knots).
    Below(f64),
}

impl Obs {
    #[inline]
    pub fn of(v: u32, lv: &Levels) -> Obs {
        if v >= lv.clip {
            Obs::Above(lv.pos(lv.clip) - 0.5 * lv.scale)
        } else if v == 0 {
            Obs::Below(0.5 * lv.scale)
        } else {
            Obs::Value(lv.pos(v))
        }
    }
}

/// `phi(z) / Phi(z)` (the inverse Mills ratio), accurate for every `z`.
#[inline]
pub(super) fn mills(z: f64) -> f64 {
    if z < -30.0 {
        // asymptotic: -z + 1/z ... (the ratio of the tails)
        let iz = 1.0 / z;
        return -z - iz + 2.0 * iz * iz * iz;
    }
    let phi = (-0.5 * z * z).exp() * 0.398_942_280_401_432_7;
    let cdf = 0.5 * libm::erfc(-z * std::f64::consts::FRAC_1_SQRT_2);
    phi / cdf.max(1e-300)
}

/// `Phi(z)`.
#[inline]
pub(super) fn normal_cdf(z: f64) -> f64 {
    0.5 * libm::erfc(-z * std::f64::consts::FRAC_1_SQRT_2)
}

/// The Gauss-Newton terms of one observation with prediction `mu` and noise `sd` (knots),
/// weighted as an observation of variance `1 / weight`: `(w, r)` such that `w` is the
/// curvature of its (weighted) negative log-likelihood in `mu` and `w r` minus its slope (for
/// a value, `r` is the residual and `w = weight`). Influence beyond `huber` standard
/// deviations is bounded (Huber): moving objects, misregistration and hot pixels then pull no
/// harder than an observation that far off.
#[inline]
pub(super) fn term(obs: Obs, mu: f64, sd: f64, ivar: f64, huber: f64) -> (f64, f64) {
    match obs {
        Obs::Value(v) => {
            let r = v - mu;
            let z = r.abs() / sd;
            let w = if z > huber { ivar * huber / z } else { ivar };
            (w, r)
        }
        Obs::Above(c) => censored((mu - c) / sd, sd, ivar, huber),
        Obs::Below(c) => {
            let (w, r) = censored((c - mu) / sd, sd, ivar, huber);
            (w, -r)
        }
    }
}

/// The terms of `-log Phi(z)`, `z = (mu - c) / sd`: slope `-lambda / sd` and curvature
/// `lambda (z + lambda) / sd^2` in `mu` (`lambda` the inverse Mills ratio); the slope bounded
/// like a value's.
#[inline]
fn censored(z: f64, sd: f64, ivar: f64, huber: f64) -> (f64, f64) {
    let lambda = mills(z);
    let curv = (lambda * (z + lambda)).clamp(1e-12, 1.0);
    let damp = if lambda > huber { huber / lambda } else { 1.0 };
    // w r = lambda / sd  =>  r = lambda sd / curv
    (ivar * curv * damp, lambda * sd / curv)
}

/// The expected curvature of an observation's term at prediction `mu` when the value is clipped
/// at `lo` and `hi` (knots): Gaussian inside, the censored terms' curvature towards the clips.
#[inline]
pub(super) fn expected_curvature(mu: f64, sd: f64, ivar: f64, lo: f64, hi: f64) -> f64 {
    let up = (mu - hi) / sd;
    let down = (lo - mu) / sd;
    let p_up = normal_cdf(up);
    let p_down = normal_cdf(down);
    let inside = (1.0 - p_up - p_down).max(0.0);
    let cu = |z: f64| {
        let l = mills(z);
        (l * (z + l)).clamp(0.0, 1.0)
    };
    ivar * (inside + p_up * cu(up) + p_down * cu(down))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mills_ratio_matches_its_definition_and_tails() {
        for z in [-40.0, -31.0, -29.0, -10.0, -3.0, -1.0, 0.0, 1.0, 3.0, 8.0] {
            let m = mills(z);
            assert!(m.is_finite() && m > 0.0, "{z}: {m}");
            if z > -25.0 {
                let phi = (-0.5 * z * z).exp() / (2.0 * std::f64::consts::PI).sqrt();
                let want = phi / normal_cdf(z);
                assert!((m - want).abs() <= 1e-9 * want, "{z}: {m} {want}");
            }
            // lambda(z) > -z and lambda(z) (z + lambda(z)) in (0, 1)
            assert!(m > -z);
            let c = m * (z + m);
            assert!(c > 0.0 && c < 1.0, "{z}: {c}");
        }
        assert!((mills(0.0) - 0.797_884_560_802_865_4).abs() < 1e-12);
    }

    #[test]
    fn a_censored_term_far_below_the_clip_acts_as_a_value_at_the_clip() {
        let (w, r) = censored(-8.0, 2.0, 0.25, f64::INFINITY);
        // prediction 16 below the clip: pulled up by about 16 with the full weight (the
        // Mills ratio is -z - 1/z + ...: half a grey value more at z = -8)
        assert!((w - 0.25).abs() < 0.01 && (r - 16.0).abs() < 0.6, "{w} {r}");
        let (w, _) = censored(6.0, 2.0, 0.25, f64::INFINITY);
        assert!(w < 1e-6);
    }
}
