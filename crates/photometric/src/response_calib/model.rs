//! The observation model `I = clip(round(G(t B') + n))`: the forward response `G`, the noise
//! `n` as measured from the residuals, and each observation's term of the likelihood:
//! Gaussian where the value is inside `1 ..= top - 1`, the probability of clipping where it is
//! `0` or `top` (censored), with a bounded influence for outliers.

use super::samples::Levels;

/// The forward response `G = U^-1` of a strictly increasing table, piecewise linear, with a
/// lookup table over the leading bits of the energy (a logarithmic grid: `2^LUT_BITS` steps per
/// octave) that starts each evaluation's search at most a knot or two below its segment,
/// without a square root.
pub(super) struct Forward {
    pub u: Vec<f64>,
    pub inv_du: Vec<f64>,
    lut: Vec<u16>,
    /// Energies up to this one share the first entry (segment 0).
    floor: f64,
    /// The leading bits of `floor`.
    key_floor: u64,
}

/// Steps per octave of the lookup table: `2^LUT_BITS`.
const LUT_BITS: u32 = 9;

/// Octaves below the top of the table the lookup table spans (below, the search starts at 0).
const LUT_OCTAVES: i32 = 24;

/// The bits of an `f64` below the lookup table's.
const LUT_SHIFT: u32 = 52 - LUT_BITS;

impl Forward {
    pub fn new(u: &[f64]) -> Forward {
        let n = u.len();
        let mut inv_du = vec![0.0; n];
        for j in 0..n - 1 {
            inv_du[j] = 1.0 / (u[j + 1] - u[j]).max(1e-12);
        }
        inv_du[n - 1] = inv_du[n - 2];
        let top = u[n - 1].max(1e-300);
        let key_floor = (top * 2f64.powi(-LUT_OCTAVES)).to_bits() >> LUT_SHIFT;
        let floor = f64::from_bits(key_floor << LUT_SHIFT);
        let len = ((LUT_OCTAVES as usize + 1) << LUT_BITS) + 1;
        let mut lut = vec![0u16; len];
        let mut j = 0usize;
        // entry `b` covers the energies from `floor`'s key plus `b` up: its segment is the
        // last whose start is at or below that key's smallest energy (entry 0: everything up
        // to `floor`, from segment 0)
        for (b, slot) in lut.iter_mut().enumerate().skip(1) {
            let e = f64::from_bits((key_floor + b as u64) << LUT_SHIFT);
            while j < n - 2 && u[j + 1] <= e {
                j += 1;
            }
            *slot = j as u16;
        }
        Forward {
            u: u.to_vec(),
            inv_du,
            lut,
            floor,
            key_floor,
        }
    }

    /// `(j, f)` with `G(e) = j + f` (in knots): `f` in `[0, 1)` inside `[U(0), U(top)]`, and
    /// the first or last segment continued linearly outside (so that a prediction beyond the
    /// table still has a slope that pulls it back).
    #[inline(always)]
    pub fn eval(&self, e: f64) -> (usize, f64) {
        let n = self.u.len();
        if e.is_nan() || e < self.u[0] {
            return (0, (e - self.u[0]) * self.inv_du[0]);
        }
        if e >= self.u[n - 1] {
            let j = n - 2;
            return (j, (e - self.u[j]) * self.inv_du[j]);
        }
        let b = if e > self.floor {
            (((e.to_bits() >> LUT_SHIFT) - self.key_floor) as usize).min(self.lut.len() - 1)
        } else {
            0
        };
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
    /// them better by 1%).
    Auto,
    /// Each observation weighted by the inverse of the noise variance measured at its
    /// predicted grey value.
    Measured,
    /// Every observation weighted alike.
    Uniform,
}

/// Why the iteration of the response fit stopped.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Stop {
    /// The step fell below the tolerance.
    Tolerance,
    /// What the iteration would still move lies within the standard errors.
    Settled,
    /// The last step tried made the objective worse and lay within the standard errors: the
    /// state before it is kept (shorter steps cannot gain what the data resolve; the step is
    /// last in `change` but was taken back). Only in the fits that start from an earlier one
    /// (the growing sample's later stages).
    RefusedWithinNoise,
    /// No shorter step lowered the objective any more: the last state that did is kept (the
    /// steps tried then are in `change` but were taken back).
    NoImprovement,
    /// The objective stopped falling for several steps in a row.
    Flat,
    /// The iteration limit was reached first (not converged).
    Limit,
}

/// Which estimator fits `U`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Estimator {
    /// Choose by the predictive score of held-out exposures: the grey-domain fit unless the
    /// log-domain one predicts them better beyond chance (2 standard errors).
    #[default]
    Auto,
    /// Maximum likelihood in grey values (the camera's model: noise, clipping, censoring).
    Grey,
    /// Debevec and Malik's least squares on `ln U` with hat weights (for tone-mapping
    /// cameras whose data no global response explains).
    Log,
}

/// The noise at every knot as the calibration uses it: its standard deviation (knots), which
/// says how far off a value is and how likely clipping is, and the weight of an observation
/// predicted there (the inverse variance, or the same everywhere).
#[derive(Clone, Debug)]
pub(super) struct Noise {
    pub sd: Vec<f64>,
    pub weight: Vec<f64>,
    /// The noise after the clip (knots; 0 when none is measured): a saturated pixel reads
    /// `top` plus this noise, so it can read a little below the top ([`TopModel`]).
    pub post: f64,
}

impl Noise {
    /// Weights by the variance `var` (knots squared) itself.
    pub fn measured(var: &[f64]) -> Noise {
        Noise {
            sd: var.iter().map(|v| v.sqrt()).collect(),
            weight: var.iter().map(|v| 1.0 / v).collect(),
            post: 0.0,
        }
    }

    /// The noise `var`, every observation weighted as one of variance `uniform`.
    pub fn uniform(var: &[f64], uniform: f64) -> Noise {
        Noise {
            sd: var.iter().map(|v| v.sqrt()).collect(),
            weight: vec![1.0 / uniform; var.len()],
            post: 0.0,
        }
    }

    /// The same noise with `post` (knots) after the clip.
    pub fn with_post(self, post: f64) -> Noise {
        Noise { post, ..self }
    }

    #[inline]
    pub fn at(&self, j: usize, f: f64) -> usize {
        // without a branch: `f` is as often below a half as above (NaN: the upper knot)
        (j + usize::from(f >= 0.5 || f.is_nan())).min(self.sd.len() - 1)
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
            // compared as `|r| > huber sd`: the division only for the few beyond (it
            // stalled every observation's pass)
            let a = r.abs();
            let w = if a > huber * sd {
                ivar * huber / (a / sd)
            } else {
                ivar
            };
            (w, r)
        }
        Obs::Above(c) => censored((mu - c) / sd, sd, ivar, huber),
        Obs::Below(c) => {
            let (w, r) = censored((c - mu) / sd, sd, ivar, huber);
            (w, -r)
        }
    }
}

/// The likelihood near the top when a noise after the clip is measured (`post`, knots): a
/// pixel's signal plus the noise before the clip (`s1`) saturates at the top `T`, then the
/// noise after the clip is added and the value rounded and clipped. A saturated pixel can
/// then read a little below the top, and a pixel just below saturation reads the top less
/// often than one noise `sd` would say. Per code within reach of the noise after the clip
/// (the top itself, counted as clipped, and the codes below it) and per prediction `mu` of the
/// signal before the clip in `[T - 6 s1, T + 6 s1]`, a table of the exact negative
/// log-likelihood, its slope and the share of the saturated branch (integrated over the noise
/// before the clip); elsewhere the plain terms hold. Built once per pass.
pub(super) struct TopModel {
    top: f64,
    sd: f64,
    step: f64,
    lo: f64,
    dx: f64,
    n: usize,
    /// Codes tabulated: `top - d step` for `d` in `0..codes` (`d = 0` the clipped top).
    codes: usize,
    /// Per code and grid point: negative log-likelihood (a value's relative to its density,
    /// as [`term`]'s are), its slope and curvature in `mu`, share of the saturated branch.
    table: Vec<[f64; 4]>,
}

/// The smallest curvature weight of a near-top term (a plain value's is 1).
const MIN_TOP_CURVATURE: f64 = 0.05;

/// Grid points of [`TopModel`] per `s1`.
const TOP_GRID: f64 = 20.0;

impl TopModel {
    /// The tables for the noise `sd` at the top (knots), `post` after the clip, codes `step`
    /// knots wide, the top at `top`; `None` without a noise after the clip.
    pub fn new(top: f64, sd: f64, post: f64, step: f64) -> Option<TopModel> {
        if !(post > 0.0 && sd > 0.0 && step > 0.0) {
            return None;
        }
        let s1 = (sd * sd - post * post).max(0.09 * sd * sd).sqrt();
        let codes = ((6.0 * post / step).ceil() as usize + 1).clamp(2, 64);
        let lo = top - 6.0 * s1;
        let n = (12.0 * TOP_GRID) as usize + 1;
        let dx = 12.0 * s1 / (n - 1) as f64;
        // nodes over the signal `y` before the noise after the clip: where that noise reaches
        // any tabulated code, and the prediction's noise reaches
        let y_lo = (top - (codes as f64 - 0.5) * step - 7.0 * post).max(lo - 8.0 * s1);
        let width = top - y_lo;
        let intervals = ((width / s1.min(post) * 6.0).ceil() as usize).clamp(48, 4096) & !1;
        let h = width / intervals as f64;
        let ys: Vec<f64> = (0..=intervals).map(|i| y_lo + i as f64 * h).collect();
        let simpson = |i: usize| -> f64 {
            let c = if i == 0 || i == intervals {
                1.0
            } else if i % 2 == 1 {
                4.0
            } else {
                2.0
            };
            c * h / 3.0
        };
        let mut table = vec![[0.0; 4]; codes * n];
        for d in 0..codes {
            let v = top - d as f64 * step;
            // the probability that the noise after the clip takes signal `y` to code `v`
            let reach = |y: f64| -> f64 {
                let upper = if d == 0 {
                    1.0
                } else {
                    normal_cdf((v + 0.5 * step - y) / post)
                };
                (upper - normal_cdf((v - 0.5 * step - y) / post)).max(0.0)
            };
            let dy: Vec<f64> = ys
                .iter()
                .enumerate()
                .map(|(i, &y)| reach(y) * simpson(i))
                .collect();
            let at_top = reach(top);
            for i in 0..n {
                let mu = lo + i as f64 * dx;
                let (mut p, mut dp) = (0.0, 0.0);
                for (&y, &w) in ys.iter().zip(&dy) {
                    let z = (y - mu) / s1;
                    let g = (-0.5 * z * z).exp() * 0.398_942_280_401_432_7 / s1;
                    p += w * g;
                    dp += w * g * z / s1;
                }
                let zt = (mu - top) / s1;
                let sat = normal_cdf(zt) * at_top;
                p += sat;
                dp += (-0.5 * zt * zt).exp() * 0.398_942_280_401_432_7 / s1 * at_top;
                let p = p.max(1e-300);
                // a value's term is relative to its density (`0.5 z^2`), the top's a probability
                let norm = if d == 0 {
                    1.0
                } else {
                    (2.0 * std::f64::consts::PI).sqrt() * sd / step
                };
                table[d * n + i] = [-(p * norm).ln(), -dp / p, sat / p, 0.0];
            }
            // the curvature, from the exact slopes of the neighbouring points
            let row = &mut table[d * n..(d + 1) * n];
            for i in 0..n {
                let (a, b) = (i.saturating_sub(1), (i + 1).min(n - 1));
                row[i][3] = (row[b][1] - row[a][1]) / ((b - a) as f64 * dx);
            }
        }
        Some(TopModel {
            top,
            sd,
            step,
            lo,
            dx,
            n,
            codes,
            table,
        })
    }

    /// The tabulated code of the value `v` (knots, `None` for the clipped top) and the grid
    /// position of `mu` (the last point beyond the grid: saturated for sure); `None` outside
    /// the tables.
    #[inline]
    fn locate(&self, v: Option<f64>, mu: f64) -> Option<(usize, usize, f64)> {
        let d = match v {
            None => 0,
            Some(v) => {
                // most values are far below the tabulated codes: one comparison
                let d = (self.top - v) / self.step + 0.5;
                if !(d >= 1.0 && d < self.codes as f64) {
                    return None;
                }
                d as usize
            }
        };
        let x = ((mu - self.lo) / self.dx).min((self.n - 1) as f64);
        // below the grid, or NaN
        if x.is_nan() || x < 0.0 {
            return None;
        }
        let i = (x as usize).min(self.n - 2);
        Some((d, i, x - i as f64))
    }

    /// The table at grid interval `i`, fraction `f`: the log-likelihood and its slope by cubic
    /// Hermite interpolation (each with its exact derivative at the points: the objective stays
    /// smooth and its slope consistent to the fourth order), the curvature and the share
    /// linearly.
    #[inline]
    fn at(&self, d: usize, i: usize, f: f64) -> [f64; 4] {
        let a = self.table[d * self.n + i];
        let b = self.table[d * self.n + i + 1];
        let h = self.dx;
        let hermite = |y0: f64, m0: f64, y1: f64, m1: f64| {
            let (f2, f3) = (f * f, f * f * f);
            (2.0 * f3 - 3.0 * f2 + 1.0) * y0
                + (f3 - 2.0 * f2 + f) * h * m0
                + (-2.0 * f3 + 3.0 * f2) * y1
                + (f3 - f2) * h * m1
        };
        [
            hermite(a[0], a[1], b[0], b[1]),
            hermite(a[1], a[3], b[1], b[3]),
            a[3] + f * (b[3] - a[3]),
            a[2] + f * (b[2] - a[2]),
        ]
    }

    /// The Gauss-Newton terms `(w, r)` of [`term`] and the saturated share of a value `v`
    /// (knots; `None`: the clipped top) whose signal before the clip is predicted at `raw`
    /// (not clamped to the top: beyond it the pixel saturates more often), weighted as an
    /// observation of variance `1 / ivar`; `None` where the plain terms hold. Beyond the grid
    /// the pixel saturated for sure and the value says nothing (`w = 0`).
    #[inline]
    pub fn term(&self, v: Option<f64>, raw: f64, ivar: f64) -> Option<(f64, f64, f64)> {
        let (d, i, f) = self.locate(v, raw)?;
        if raw >= self.lo + (self.n - 1) as f64 * self.dx {
            return Some((0.0, 0.0, 1.0));
        }
        let [_, slope, curv, share] = self.at(d, i, f);
        // the observed curvature where the likelihood is convex, a small one where the mixture
        // of the two branches is not (the damping of the steps handles those)
        let w = (curv * self.sd * self.sd).max(MIN_TOP_CURVATURE);
        // w r = ivar sd^2 (-slope): the objective is ivar sd^2 times the log-likelihood
        Some((ivar * w, -slope * self.sd * self.sd / w, share))
    }

    /// The negative log-likelihood (as [`TopModel::term`] scales it), `None` where the plain
    /// one holds.
    #[inline]
    pub fn nll(&self, v: Option<f64>, raw: f64) -> Option<f64> {
        let (d, i, f) = self.locate(v, raw)?;
        Some(self.at(d, i, f)[0])
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

    /// The segment a plain search over the table finds (`None` outside it).
    fn searched(u: &[f64], e: f64) -> Option<(usize, f64)> {
        let n = u.len();
        if !(e >= u[0] && e < u[n - 1]) {
            return None;
        }
        let j = (u.partition_point(|&x| x <= e) - 1).min(n - 2);
        Some((j, ((e - u[j]) / (u[j + 1] - u[j])).clamp(0.0, 1.0)))
    }

    proptest::proptest! {
        /// The lookup table only says where the search starts: on increasing tables of every
        /// shape (steep at the start as a gamma curve, with tiny or negative first values,
        /// 256 to 4096 knots) the segment is the one a plain search finds, at knots, between
        /// them, at the ends and far below the table's top.
        #[test]
        fn the_forward_response_finds_the_segment_a_search_finds(
            steps in proptest::collection::vec(0.01f64..1.0, 256..=4096),
            start in proptest::prop_oneof![
                1 => proptest::strategy::Just(0.0f64),
                1 => -1.0f64..1.0,
                1 => 0.0f64..1e-12,
            ],
            power in 1.0f64..4.0,
            at in proptest::collection::vec(0.0f64..1.0, 64),
        ) {
            // a power of an increasing sequence: tiny first steps for the larger powers
            let mut sum = 0.0;
            let u: Vec<f64> = steps
                .iter()
                .map(|s| {
                    sum += s;
                    start + sum.powf(power)
                })
                .collect();
            proptest::prop_assume!(u.windows(2).all(|w| w[1] - w[0] >= 1e-12));
            let g = Forward::new(&u);
            let n = u.len();
            let mut energies: Vec<f64> = at
                .iter()
                .map(|a| u[0] + a * a * a * (u[n - 1] - u[0]))
                .collect();
            energies.extend(u.iter().copied());
            energies.extend(u.iter().map(|x| x * (1.0 + 1e-15) + 1e-300));
            energies.extend([g.floor, g.floor * 0.999, g.floor * 1.001, 0.0, -0.0]);
            for e in energies {
                let got = g.eval(e);
                match searched(&u, e) {
                    Some((j, f)) => {
                        proptest::prop_assert_eq!(got.0, j, "energy {}", e);
                        proptest::prop_assert!((got.1 - f).abs() <= 1e-9, "energy {}", e);
                    }
                    None => proptest::prop_assert!(got.0 == 0 || got.0 == n - 2),
                }
            }
        }
    }

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

    /// The near-top likelihood against a simulation of the sensor it describes (noise before
    /// the clip, the clip, noise after it, rounding), and its slope against finite differences.
    #[test]
    fn the_near_top_likelihood_is_the_sensor_s_probability_and_its_slope_is_exact() {
        let (top, s1, post) = (255.0, 2.5f64, 1.0f64);
        let sd = (s1 * s1 + post * post).sqrt();
        let m = TopModel::new(top, sd, post, 1.0).expect("a model");
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut uniform = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut normal = || {
            let (a, b) = (uniform().max(1e-300), uniform());
            (-2.0 * a.ln()).sqrt() * (2.0 * std::f64::consts::PI * b).cos()
        };
        for mu in [249.0, 253.0, 255.0, 257.5] {
            let n = 400_000;
            let mut counts = [0u32; 4];
            for _ in 0..n {
                let y = (mu + s1 * normal()).min(top);
                let v = (y + post * normal()).round().min(top);
                let d = (top - v) as usize;
                if d < 4 {
                    counts[d] += 1;
                }
            }
            for (d, &c) in counts.iter().enumerate() {
                let v = if d == 0 { None } else { Some(top - d as f64) };
                let l = m.nll(v, mu).expect("tabulated");
                let norm = if d == 0 {
                    1.0
                } else {
                    (2.0 * std::f64::consts::PI).sqrt() * sd
                };
                let p = (-l).exp() / norm;
                let want = c as f64 / n as f64;
                let tol = 4.0 * (want * (1.0 - want) / n as f64).sqrt() + 1e-3 * want;
                assert!((p - want).abs() <= tol, "mu {mu} d {d}: {p} {want}");
                // slope: r w / (ivar sd^2) is minus the slope
                let h = 1e-3;
                let fd =
                    (m.nll(v, mu + h).expect("in") - m.nll(v, mu - h).expect("in")) / (2.0 * h);
                let (w, r, _) = m.term(v, mu, 1.0).expect("in");
                assert!(
                    (-(w * r) / (sd * sd) - fd).abs() < 1e-3 * (1.0 + fd.abs()),
                    "{mu} {d}"
                );
            }
        }
    }
}
