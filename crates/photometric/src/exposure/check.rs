//! Checking logged exposures: every frame's exposure predicted from its neighbours' and the
//! measured ratios; a frame whose log contradicts the images and fits a neighbour's is flagged.

use super::estimate::estimate_exposures;
use super::ratio::{PairRatio, RatioMeasurement};
use super::ExposureOptions;
use crate::stats::median;
use crate::PhotometricError;

/// What [`check_exposures`] concludes about one frame's logged exposure.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    /// The logged exposure agrees with the images.
    Consistent,
    /// The logged exposure is the previous frame's.
    ShiftedFromPrevious,
    /// The logged exposure is the next frame's.
    ShiftedFromNext,
    /// The logged exposure contradicts the images, and neither neighbour's exposure fits.
    Inconsistent,
    /// No decision: the ratios around the frame are unreliable or contradict each other.
    Undecided,
}

impl Verdict {
    /// Whether the frame is flagged as shifted by one frame.
    pub fn is_shifted(self) -> bool {
        matches!(
            self,
            Verdict::ShiftedFromPrevious | Verdict::ShiftedFromNext
        )
    }
}

/// The check of one frame's logged exposure.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FrameCheck {
    /// Frame index (0-based, times.txt order).
    pub frame: usize,
    /// The logged exposure in ms.
    pub logged_ms: f64,
    /// The frame's exposure as its neighbours' logged exposures and the measured ratios
    /// predict it, in ms (NaN when undecided).
    pub predicted_ms: f64,
    /// Standard error of `log(predicted_ms)` (with the logging precision).
    pub std_error: f64,
    /// `log(logged / predicted)` in standard errors.
    pub z: f64,
    /// The conclusion.
    pub verdict: Verdict,
    /// Why the frame is undecided (empty otherwise).
    pub note: String,
}

/// The result of [`check_exposures`].
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ExposureCheck {
    /// One entry per frame.
    pub frames: Vec<FrameCheck>,
    /// Frames whose logged exposure is a neighbour's (0-based).
    pub shifted: Vec<usize>,
    /// Frames whose logged exposure contradicts the images otherwise.
    pub inconsistent: Vec<usize>,
    /// Frames without a decision.
    pub undecided: Vec<usize>,
    /// Pairs `(i, i + 1)`, by `i`, whose ratio is unreliable.
    pub unreliable_pairs: Vec<usize>,
    /// The logged exposures with every shifted one replaced by its prediction, in ms.
    pub fixed_ms: Vec<f64>,
    /// The exposures measured from the images alone (the chained ratios), scaled to the
    /// logged ones (median ratio 1 between gaps), in ms.
    pub measured_ms: Vec<f64>,
    /// Whether the log as a whole is one frame off: `1` when every frame logs its previous
    /// frame's exposure, `-1` its next frame's, `0` otherwise (see `lag_scores`).
    pub log_lag: i32,
    /// Median `|measured - logged| / std_error` of the consecutive log ratios with the log
    /// moved by -1, 0 and +1 frames.
    pub lag_scores: [f64; 3],
}

/// A robust estimate from several predictions of one log exposure: the median and its
/// variance (the larger of the propagated one and the spread's).
pub(super) fn robust_prediction(values: &[(f64, f64)]) -> Option<(f64, f64)> {
    let n = values.len();
    if n == 0 {
        return None;
    }
    let mut v: Vec<f64> = values.iter().map(|p| p.0).collect();
    let med = median(&mut v);
    let mean_var = values.iter().map(|p| p.1).sum::<f64>() / n as f64;
    let eff = if n >= 3 {
        std::f64::consts::FRAC_PI_2
    } else {
        1.0
    };
    let mut var = mean_var * eff / n as f64;
    if n >= 3 {
        let mut dev: Vec<f64> = values.iter().map(|p| (p.0 - med).abs()).collect();
        let s = 1.4826 * median(&mut dev);
        var = var.max(s * s * eff / n as f64);
    }
    Some((med, var))
}

/// Checks logged exposures against the measured ratios of consecutive frames (see the
/// module documentation). `logged_ms[i]` is frame `i`'s logged exposure, `ratios[i]` the
/// measurement of `log(t_{i+1} / t_i)`.
pub fn check_exposures(
    logged_ms: &[f64],
    ratios: &[RatioMeasurement],
    opts: &ExposureOptions,
) -> Result<ExposureCheck, PhotometricError> {
    let n = logged_ms.len();
    check_inputs(logged_ms, ratios)?;
    let logs = Logs {
        g: logged_ms.iter().map(|t| t.ln()).collect(),
        logged_ms,
        ratios,
        opts,
        var_g: opts.log_precision * opts.log_precision,
    };
    let g = &logs.g;
    let frames: Vec<FrameCheck> = (0..n).map(|k| logs.check(k)).collect();
    let pick = |f: &dyn Fn(Verdict) -> bool| -> Vec<usize> {
        frames
            .iter()
            .filter(|c| f(c.verdict))
            .map(|c| c.frame)
            .collect()
    };
    let shifted = pick(&|v| v.is_shifted());
    let inconsistent = pick(&|v| v == Verdict::Inconsistent);
    let undecided = pick(&|v| v == Verdict::Undecided);
    let fixed_ms = frames
        .iter()
        .map(|c| {
            if c.verdict.is_shifted() {
                c.predicted_ms
            } else {
                c.logged_ms
            }
        })
        .collect();
    let measured_ms = measured_exposures(g, ratios, opts)?;
    let (log_lag, lag_scores) = logs.lag();
    Ok(ExposureCheck {
        frames,
        shifted,
        inconsistent,
        undecided,
        unreliable_pairs: (0..n - 1).filter(|&i| !logs.ok(i)).collect(),
        fixed_ms,
        measured_ms,
        log_lag,
        lag_scores,
    })
}

/// At least 2 frames, a ratio per consecutive pair, positive logged exposures.
fn check_inputs(logged_ms: &[f64], ratios: &[RatioMeasurement]) -> Result<(), PhotometricError> {
    let n = logged_ms.len();
    if n < 2 {
        return Err(PhotometricError::Calibration(format!(
            "an exposure check needs at least 2 frames, found {n}"
        )));
    }
    if ratios.len() != n - 1 {
        return Err(PhotometricError::Calibration(format!(
            "{n} frames need {} ratios of consecutive frames, found {}",
            n - 1,
            ratios.len()
        )));
    }
    if let Some((frame, &t)) = logged_ms
        .iter()
        .enumerate()
        .find(|(_, t)| !(t.is_finite() && **t > 0.0))
    {
        return Err(PhotometricError::Calibration(format!(
            "frame {frame}: logged exposure {t} ms is not a positive number"
        )));
    }
    Ok(())
}

/// The logged exposures (`g`: their logs) and the measured ratios between them.
struct Logs<'a> {
    g: Vec<f64>,
    logged_ms: &'a [f64],
    ratios: &'a [RatioMeasurement],
    opts: &'a ExposureOptions,
    /// The variance of a logged log exposure.
    var_g: f64,
}

impl Logs<'_> {
    /// Whether the ratio of pair `(i, i + 1)` can be used.
    fn ok(&self, i: usize) -> bool {
        self.ratios[i].reliable && self.ratios[i].log_ratio.is_finite()
    }

    /// The variance of the ratio of pair `(i, i + 1)`.
    fn var_m(&self, i: usize) -> f64 {
        self.ratios[i].std_error * self.ratios[i].std_error
    }

    /// The logs of the frames left of `k` (the previous frame's log exposure, chained up to
    /// `k - 1`) and right of it (the next frame's), up to the window, each with its variance.
    #[allow(clippy::type_complexity)]
    fn sides(&self, k: usize) -> (Vec<(f64, f64)>, Vec<(f64, f64)>) {
        let (g, ratios, n) = (&self.g, self.ratios, self.g.len());
        let w = self.opts.window.max(1);
        let mut left = Vec::new();
        if k >= 1 {
            let (mut acc, mut var) = (0.0, 0.0);
            for j in (k.saturating_sub(w)..k).rev() {
                if j < k - 1 {
                    // pair (j, j + 1) links j to the frames after it
                    if !self.ok(j) {
                        break;
                    }
                    acc += ratios[j].log_ratio;
                    var += self.var_m(j);
                }
                left.push((g[j] + acc, var + self.var_g));
            }
        }
        let mut right = Vec::new();
        if k + 1 < n {
            let (mut acc, mut var) = (0.0, 0.0);
            for j in k + 1..(k + 1 + w).min(n) {
                if j > k + 1 {
                    if !self.ok(j - 1) {
                        break;
                    }
                    acc += ratios[j - 1].log_ratio;
                    var += self.var_m(j - 1);
                }
                right.push((g[j] - acc, var + self.var_g));
            }
        }
        (left, right)
    }

    /// Frame `k`'s check: its exposure predicted from both sides, compared with its log.
    fn check(&self, k: usize) -> FrameCheck {
        let (g, ratios, opts, n) = (&self.g, self.ratios, self.opts, self.g.len());
        let (left, right) = self.sides(k);
        let prev = robust_prediction(&left);
        let next = robust_prediction(&right);
        // predictions of frame k itself through the measured ratios next to it
        let from_left = prev
            .filter(|_| k >= 1 && self.ok(k - 1))
            .map(|(a, va)| (a + ratios[k - 1].log_ratio, va + self.var_m(k - 1)));
        let from_right = next
            .filter(|_| k + 1 < n && self.ok(k))
            .map(|(b, vb)| (b - ratios[k].log_ratio, vb + self.var_m(k)));
        let mut check = FrameCheck {
            frame: k,
            logged_ms: self.logged_ms[k],
            predicted_ms: f64::NAN,
            std_error: f64::NAN,
            z: f64::NAN,
            verdict: Verdict::Undecided,
            note: String::new(),
        };
        let predicted = match (from_left, from_right) {
            (Some((pl, vl)), Some((pr, vr))) => {
                let q = pl - pr;
                let sq = (vl + vr).sqrt();
                if q.abs() > opts.consistency_sigmas * sq && q.abs() > opts.min_difference {
                    check.note = format!(
                        "the neighbours predict exposures {:.2}% apart ({:.1} standard errors): a bad ratio or a neighbour's bad log",
                        100.0 * q.abs(),
                        q.abs() / sq
                    );
                    None
                } else {
                    let wl = 1.0 / vl;
                    let wr = 1.0 / vr;
                    Some(((wl * pl + wr * pr) / (wl + wr), 1.0 / (wl + wr)))
                }
            }
            (Some(p), None) | (None, Some(p)) => {
                let side = if k >= 1 && self.ok(k - 1) {
                    &left
                } else {
                    &right
                };
                if side.len() >= 2 {
                    Some(p)
                } else {
                    check.note = "one neighbour only, and its ratio is the only link".into();
                    None
                }
            }
            (None, None) => {
                check.note = "the ratios on both sides are unreliable".into();
                None
            }
        };
        if let Some((p, vp)) = predicted {
            let s0 = (vp + self.var_g).sqrt();
            let d0 = g[k] - p;
            check.predicted_ms = p.exp();
            check.std_error = s0;
            check.z = d0 / s0;
            let contradicts = d0.abs() > opts.flag_sigmas * s0 && d0.abs() > opts.min_difference;
            check.verdict = if contradicts {
                self.shift_verdict(k, d0, prev, next)
            } else {
                Verdict::Consistent
            };
        }
        check
    }

    /// A contradicting log (off the prediction by `d0`): shifted when it fits the previous
    /// or the next frame's exposure (`prev`, `next`), else inconsistent.
    fn shift_verdict(
        &self,
        k: usize,
        d0: f64,
        prev: Option<(f64, f64)>,
        next: Option<(f64, f64)>,
    ) -> Verdict {
        let fits = |h: Option<(f64, f64)>| {
            h.and_then(|(a, va)| {
                let sh = (va + self.var_g).sqrt();
                let dh = self.g[k] - a;
                (dh.abs() <= self.opts.fit_sigmas * sh + 0.2 * d0.abs()).then_some(dh.abs() / sh)
            })
        };
        match (fits(prev), fits(next)) {
            (Some(zp), Some(zn)) if zn < zp => Verdict::ShiftedFromNext,
            (Some(_), _) => Verdict::ShiftedFromPrevious,
            (None, Some(_)) => Verdict::ShiftedFromNext,
            (None, None) => Verdict::Inconsistent,
        }
    }

    /// The whole log one frame off (logged `g_j` = true `t_{j - lag}`): the lag whose
    /// logged ratios fit the measured ones best, with the median z of each lag -1, 0, 1.
    fn lag(&self) -> (i32, [f64; 3]) {
        let (g, ratios, opts, n) = (&self.g, self.ratios, self.opts, self.g.len());
        let mut lag_scores = [f64::NAN; 3];
        for (slot, lag) in [-1i64, 0, 1].into_iter().enumerate() {
            let mut z: Vec<f64> = (0..n - 1)
                .filter(|&i| self.ok(i))
                .filter_map(|i| {
                    let (a, b) = (i as i64 + lag, i as i64 + 1 + lag);
                    (a >= 0 && b < n as i64).then(|| {
                        let logged = g[b as usize] - g[a as usize];
                        (ratios[i].log_ratio - logged).abs() / ratios[i].std_error
                    })
                })
                .collect();
            lag_scores[slot] = median(&mut z);
        }
        let best = (0..3)
            .filter(|&i| lag_scores[i].is_finite())
            .min_by(|&a, &b| lag_scores[a].total_cmp(&lag_scores[b]));
        let log_lag = match best {
            Some(i)
                if i != 1
                    && lag_scores[1] > opts.flag_sigmas
                    && lag_scores[i] < 0.25 * lag_scores[1] =>
            {
                i as i32 - 1
            }
            _ => 0,
        };
        (log_lag, lag_scores)
    }
}

/// The measured exposures alone, scaled to the logged ones (logs `g`): each stretch between
/// gaps (where no ratio links the frames) scaled to its logs.
fn measured_exposures(
    g: &[f64],
    ratios: &[RatioMeasurement],
    opts: &ExposureOptions,
) -> Result<Vec<f64>, PhotometricError> {
    let n = g.len();
    let pairs = PairRatio::chain(ratios, &[]);
    let est = estimate_exposures(n, &pairs, 1.0, opts)?;
    let mut measured_ms = Vec::with_capacity(n);
    let mut bounds: Vec<usize> = est.gaps.iter().map(|&i| i + 1).collect();
    bounds.push(n);
    let mut from = 0;
    for to in bounds {
        let mut off: Vec<f64> = (from..to)
            .map(|k| g[k] - est.exposures_ms[k].ln())
            .collect();
        let scale = median(&mut off).exp();
        measured_ms.extend((from..to).map(|k| est.exposures_ms[k] * scale));
        from = to;
    }
    Ok(measured_ms)
}
