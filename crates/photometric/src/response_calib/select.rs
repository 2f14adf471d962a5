//! The truth-free check that chooses the weights and the prior's strength: the exposures are
//! split into folds (each exposure its own fold when there are few), each candidate fit is
//! repeated without each fold, and the frames of the fold are predicted from the pixels' other
//! frames through the fitted `U`: each pixel's irradiance from its other values by least
//! squares, `B' = sum t U(I) / sum t^2` (the same for all, so that only `U` differs), then
//! `G(t B')` against the value the camera recorded. Measured weights are kept unless uniform
//! weights predict the held-out frames clearly better (by [`UNIFORM_MARGIN`]: on long sweeps
//! the two tie to 0.1%, and a tie keeps the weights of the model); a weaker prior only when it
//! predicts them clearly better (a ripple the exposures leave undetermined is invisible to the
//! check, so a tie keeps the prior the ripples need).
//!
//! The log-domain fit (`logfit`) competes too: its candidates are refitted from scratch in
//! every fold, and so is the chosen grey-domain candidate for the comparison (its fold fits
//! above start from the fit on all exposures, which has seen the held-out frames); it is taken
//! when its residuals are smaller by 1% (RMS) and beyond 2 standard errors, clustered by tiles.

use super::logfit;
use super::model::{Estimator, Forward, Obs};
use super::samples::Samples;
use super::solver::{solve, Problem, Settings, Start};
use crate::noise::interp;
use crate::PhotometricError;
use rayon::prelude::*;

/// Folds of the check: every distinct exposure its own fold up to [`LOEO_FOLDS`] exposures
/// (a bracket: leave one exposure out), else this many interleaved folds (by exposure rank):
/// every exposure is held out once.
const MAX_FOLDS: usize = 8;

/// Up to this many distinct exposures, each is a fold of its own.
const LOEO_FOLDS: usize = 16;

/// Iterations of a fold's fit (warm from the fit on all exposures).
const FOLD_ITERATIONS: usize = 6;

/// One candidate fit and its held-out score.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CandidateScore {
    /// The estimator: [`Estimator::Grey`] or [`Estimator::Log`].
    #[serde(default = "grey")]
    pub estimator: Estimator,
    /// Weighted by the measured noise (else uniformly; the grey-domain fit).
    pub measured: bool,
    /// The grey-domain fit: the prior's weight relative to what the exposures' ripples need.
    /// The log-domain fit: Debevec's `lambda` (the prior's weight at 70 pixels).
    pub prior_scale: f64,
    /// The fold fits started afresh (the log-domain fit and the grey-domain one it competes
    /// with); else from the fit on all exposures.
    #[serde(default)]
    pub cold: bool,
    /// The log-domain fit also took the values next to saturated pixels (which the
    /// grey-domain fit drops, and which are never scored).
    #[serde(default)]
    pub all_values: bool,
    /// RMS prediction error of the held-out frames, grey values.
    pub rms: f64,
}

/// The held-out check: every candidate's score over the same observations, and the choice.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct HeldOutScores {
    /// The candidates, in the order of preference.
    pub candidates: Vec<CandidateScore>,
    /// Index of the chosen one.
    pub chosen: usize,
    /// Held-out observations scored.
    pub observations: u64,
    /// Folds of exposures.
    pub folds: usize,
    /// Pixels of the check.
    pub pixels: usize,
}

fn grey() -> Estimator {
    Estimator::Grey
}

/// What the check chose.
#[derive(Clone, Copy, Debug)]
pub(super) struct Choice {
    /// [`Estimator::Grey`] or [`Estimator::Log`].
    pub estimator: Estimator,
    /// The grey-domain fit's weights.
    pub measured: bool,
    /// The grey-domain fit's prior scale, or the log-domain fit's `lambda`.
    pub prior_scale: f64,
    /// The fold fits started afresh.
    pub cold: bool,
    /// The log-domain fit on every value between the clipping points (also those next to
    /// saturated pixels).
    pub all_values: bool,
}

/// The log-domain fit's `lambda`s the check tries: Debevec's 10, and half a decade either
/// side.
pub(super) const LOG_LAMBDAS: [f64; 3] = [3.0, 10.0, 30.0];

/// The priors the check tries, strongest first.
pub(super) const PRIOR_SCALES: [f64; 3] = [1.0, 0.1, 0.01];

/// How much better (relative RMS) a weaker prior must predict to be chosen.
const WEAKER_PRIOR_MARGIN: f64 = 0.01;

/// How much better (relative RMS) uniform weights must predict to replace measured ones.
const UNIFORM_MARGIN: f64 = 0.01;

/// The fold of each frame: distinct exposures (relative tolerance 1e-6) in rank order.
pub(super) fn folds(exposures: &[f64]) -> (Vec<usize>, usize) {
    let mut distinct: Vec<f64> = exposures.to_vec();
    distinct.sort_by(f64::total_cmp);
    distinct.dedup_by(|a, b| (*a / *b - 1.0).abs() < 1e-6);
    let k = if distinct.len() <= LOEO_FOLDS {
        distinct.len()
    } else {
        MAX_FOLDS
    };
    let fold = exposures
        .iter()
        .map(|&t| {
            let rank = distinct.partition_point(|&d| d < t * (1.0 - 1e-6));
            rank % k
        })
        .collect();
    (fold, k)
}

/// The longest period (in log exposure) of the ripples that the exposures among `keep` leave
/// undetermined: the largest `P` such that every distinct exposure lies within
/// [`GRID_TOLERANCE`] periods of a geometric grid of ratio `e^P` (a sweep in constant steps
/// of `r`: `log r`; 1/3-stop brackets: `log 2 / 3`, also with a frame missing). Without such a
/// grid no ripple fits every exposure; the smallest step bounds the ripples that come close.
pub(super) fn ripple_period(exposures: &[f64], keep: Option<&[bool]>) -> f64 {
    let mut x: Vec<f64> = exposures
        .iter()
        .enumerate()
        .filter(|(i, _)| keep.is_none_or(|k| k[*i]))
        .map(|(_, &t)| t.ln())
        .collect();
    x.sort_by(f64::total_cmp);
    x.dedup_by(|a, b| (*a - *b).abs() < 1e-6);
    let steps: Vec<f64> = x.windows(2).map(|p| p[1] - p[0]).collect();
    let smallest = steps.iter().copied().fold(f64::INFINITY, f64::min);
    if !smallest.is_finite() {
        return 0.0;
    }
    let mut candidates: Vec<f64> = steps
        .iter()
        .flat_map(|&d| (1..=4).map(move |m| d / m as f64))
        .filter(|&p| p >= 0.5 * smallest)
        .collect();
    candidates.sort_by(|a, b| b.total_cmp(a));
    candidates
        .into_iter()
        .find(|&p| {
            x.iter().all(|&xi| {
                let r = (xi - x[0]) / p;
                (r - r.round()).abs() <= GRID_TOLERANCE
            })
        })
        .unwrap_or(smallest)
}

/// How far (in periods) an exposure may lie off the grid of a ripple that counts as
/// undetermined.
const GRID_TOLERANCE: f64 = 0.15;

/// The held-out residuals (grey values) of one grey-domain candidate, fold by fold, pixel by
/// pixel, frame by frame; NaN where its fit failed. The fold fits start from the fit on all
/// exposures and take a few steps (`cold`: from the start every fit takes, to convergence, so
/// that nothing of the held-out frames leaks into them).
fn held_out(
    base: &Problem<'_>,
    fold: &[usize],
    k: usize,
    cold: bool,
) -> Result<Vec<f32>, PhotometricError> {
    let quiet = |_: usize, _: f64| {};
    // a fit from the start every fit takes
    let fresh = Settings {
        max_iterations: 40,
        tolerance: 0.02,
        tiles: false,
        settle: false,
        progress: &quiet,
    };
    // the warm start of the fold fits (a cold check fits every fold from scratch and needs none)
    let all = if cold {
        None
    } else {
        Some(solve(base, Start::Cold, &fresh)?)
    };
    // the folds are independent: fitted side by side, their residuals joined in fold order
    let per_fold: Vec<Vec<f32>> = (0..k)
        .into_par_iter()
        .map(|f| {
            let train: Vec<bool> = fold.iter().map(|&g| g != f).collect();
            let p = Problem {
                train: Some(&train),
                log_gap: ripple_period(base.exposures, Some(&train)),
                ..*base
            };
            let fit = match &all {
                None => solve(&p, Start::Cold, &fresh),
                Some(all) => solve(
                    &p,
                    Start::Warm {
                        u: all.u.clone(),
                        b: all.b.clone(),
                        noise: all.noise.clone(),
                        measured: None,
                    },
                    &Settings {
                        max_iterations: FOLD_ITERATIONS,
                        tolerance: 0.05,
                        tiles: false,
                        settle: false,
                        progress: &quiet,
                    },
                ),
            };
            let u = fit.ok().map(|f| f.u);
            let mut out = Vec::new();
            fold_residuals(base, fold, f, &train, u.as_deref(), cold, &mut out, None);
            out
        })
        .collect();
    Ok(per_fold.concat())
}

/// The held-out residuals of the log-domain estimator with each of `lambdas` (on the values the
/// grey-domain fit uses, or on `all` of them), in the order of [`held_out`]'s.
fn held_out_log(
    base: &Problem<'_>,
    fold: &[usize],
    k: usize,
    lambdas: &[f64],
    all: bool,
) -> Vec<Vec<f32>> {
    // per fold (side by side), per lambda
    let per_fold: Vec<Vec<Vec<f32>>> = (0..k)
        .into_par_iter()
        .map(|f| {
            let train: Vec<bool> = fold.iter().map(|&g| g != f).collect();
            let eq = logfit::normal(&logfit::Data {
                samples: base.samples,
                exposures: base.exposures,
                train: Some(&train),
                levels: &base.levels,
                all,
            });
            lambdas
                .iter()
                .map(|&lambda| {
                    let u = eq
                        .as_ref()
                        .ok()
                        .and_then(|eq| logfit::solve(eq, &base.levels, lambda).ok());
                    let mut o = Vec::new();
                    fold_residuals(base, fold, f, &train, u.as_deref(), true, &mut o, None);
                    o
                })
                .collect()
        })
        .collect();
    (0..lambdas.len())
        .map(|l| per_fold.iter().flat_map(|f| f[l].iter().copied()).collect())
        .collect()
}

/// The tile of every held-out residual, in the order of [`held_out`]'s.
fn residual_tiles(base: &Problem<'_>, fold: &[usize], k: usize) -> Vec<u32> {
    let mut r = Vec::new();
    let mut tiles = Vec::new();
    for f in 0..k {
        let train: Vec<bool> = fold.iter().map(|&g| g != f).collect();
        fold_residuals(base, fold, f, &train, None, true, &mut r, Some(&mut tiles));
    }
    tiles
}

/// Appends the residuals of fold `f`'s frames predicted through the table `u` fitted without
/// them (NaN for each when there is no table): each pixel's irradiance from its training
/// values, by least squares in `U` (`B' = sum t U(I) / sum t^2`), or with `grey_merge` by
/// least squares in grey values (`min sum (I - G(t B'))^2`, Gauss-Newton from the former: each
/// table predicts as well as it can, so that no table wins by taming the noise the first merge
/// carries from bright values); then `G(t B')` against the recorded value. The values the
/// grey-domain fit drops (next to saturated pixels: blooming, the compression's ringing) are
/// neither merged nor scored: no global response describes them. With `tiles`, the tile of
/// each residual is appended there.
#[allow(clippy::too_many_arguments)]
fn fold_residuals(
    base: &Problem<'_>,
    fold: &[usize],
    f: usize,
    train: &[bool],
    u: Option<&[f64]>,
    grey_merge: bool,
    out: &mut Vec<f32>,
    mut tiles: Option<&mut Vec<u32>>,
) {
    let s = base.samples;
    let lv = base.levels;
    let per_grey = 1.0 / lv.scale;
    let top = (lv.knots - 1) as f64;
    let g = u.map(Forward::new);
    let predict = |g: &Forward, t: f64, b: f64| {
        let (j, fr) = g.eval(t * b);
        (j, (j as f64 + fr).clamp(0.0, top))
    };
    for px in 0..s.len() {
        let vals = s.pixel(px);
        let inside = |i: usize, v: u16| {
            !s.is_excluded(px, i) && matches!(Obs::of(v as u32, &lv), Obs::Value(_))
        };
        // the least-squares irradiance from the training values
        let (mut num, mut den) = (0.0, 0.0);
        let mut has = false;
        for (i, v) in vals.iter().enumerate() {
            if train[i] && inside(i, v) {
                has = true;
                if let Some(table) = u {
                    let t = base.exposures[i];
                    num += t * interp(table, lv.pos(v as u32));
                    den += t * t;
                }
            }
        }
        let mut b = if den > 0.0 { num / den } else { f64::NAN };
        if let (true, Some(g), Some(table)) = (grey_merge && b.is_finite(), &g, u) {
            for _ in 0..GREY_MERGE_STEPS {
                let (mut jr, mut jj) = (0.0, 0.0);
                for (i, v) in vals.iter().enumerate() {
                    if train[i] && inside(i, v) {
                        let t = base.exposures[i];
                        let (j, mu) = predict(g, t, b);
                        let du = table[j + 1] - table[j];
                        let d = if mu > 0.0 && mu < top && du > 0.0 {
                            t / du
                        } else {
                            0.0
                        };
                        jr += d * (lv.pos(v as u32) - mu);
                        jj += d * d;
                    }
                }
                if jj <= 0.0 {
                    break;
                }
                b = (b + jr / jj).max(0.1 * b);
            }
        }
        for (i, v) in vals.iter().enumerate() {
            if fold[i] != f || !inside(i, v) || !has {
                continue;
            }
            let r = match &g {
                Some(g) if b.is_finite() => {
                    let (_, mu) = predict(g, base.exposures[i], b);
                    ((lv.pos(v as u32) - mu) * per_grey) as f32
                }
                _ => f32::NAN,
            };
            out.push(r);
            if let Some(t) = tiles.as_deref_mut() {
                t.push(s.tile[px]);
            }
        }
    }
}

/// Gauss-Newton steps of the grey-domain merge.
const GREY_MERGE_STEPS: usize = 4;

/// Scores the candidates (measured and uniform weights, each with the priors of
/// [`PRIOR_SCALES`] when `priors`; the log-domain fit with the `lambda`s of [`LOG_LAMBDAS`]
/// unless `estimator` is [`Estimator::Grey`]) on `samples`; returns the choice and the scores.
pub(super) fn choose(
    base: &Problem<'_>,
    samples: &Samples,
    weightings: &[bool],
    priors: bool,
    estimator: Estimator,
) -> Result<(Choice, HeldOutScores), PhotometricError> {
    let (fold, k) = folds(base.exposures);
    let scales: &[f64] = if priors {
        &PRIOR_SCALES
    } else {
        &PRIOR_SCALES[..1]
    };
    let mut cands = Vec::new();
    let mut residuals = Vec::new();
    let p0 = Problem { samples, ..*base };
    if estimator != Estimator::Log {
        for &prior_scale in scales {
            for &measured in weightings {
                cands.push(Choice {
                    estimator: Estimator::Grey,
                    measured,
                    prior_scale,
                    cold: false,
                    all_values: false,
                });
            }
        }
        // the candidates are independent: scored side by side, kept in order
        let scored: Vec<Result<Vec<f32>, PhotometricError>> = cands
            .par_iter()
            .map(|c| {
                let p = Problem {
                    measured: c.measured,
                    prior_scale: c.prior_scale,
                    ..p0
                };
                held_out(&p, &fold, k, false)
            })
            .collect();
        for r in scored {
            residuals.push(r?);
        }
    }
    // the grey-domain choice, and its honest score against the log-domain fits: fold fits
    // that start afresh
    let pre = common_rms(&residuals);
    let mut chosen = pick(&cands, &pre.0, &|_, _| false);
    if estimator != Estimator::Grey {
        let grey = cands.get(chosen).copied();
        if let Some(g) = grey {
            let p = Problem {
                measured: g.measured,
                prior_scale: g.prior_scale,
                ..p0
            };
            residuals.push(held_out(&p, &fold, k, true)?);
            cands.push(Choice { cold: true, ..g });
        }
        for all in [false, true] {
            residuals.extend(held_out_log(&p0, &fold, k, &LOG_LAMBDAS, all));
            for &lambda in &LOG_LAMBDAS {
                cands.push(Choice {
                    estimator: Estimator::Log,
                    measured: false,
                    prior_scale: lambda,
                    cold: true,
                    all_values: all,
                });
            }
        }
    }
    let rms = common_rms(&residuals);
    if estimator != Estimator::Grey {
        let tiles = residual_tiles(&p0, &fold, k);
        let better =
            |a: usize, b: usize| significantly_better(&residuals[a], &residuals[b], &rms.2, &tiles);
        chosen = pick(&cands, &rms.0, &better);
    }
    let scores = HeldOutScores {
        candidates: cands
            .iter()
            .zip(&rms.0)
            .map(|(c, &rms)| CandidateScore {
                estimator: c.estimator,
                measured: c.measured,
                prior_scale: c.prior_scale,
                cold: c.cold,
                all_values: c.all_values,
                rms,
            })
            .collect(),
        chosen,
        observations: rms.1,
        folds: k,
        pixels: samples.len(),
    };
    Ok((cands[chosen], scores))
}

/// Every candidate's RMS over the residuals that all of them have, their number, and which
/// they are.
fn common_rms(residuals: &[Vec<f32>]) -> (Vec<f64>, u64, Vec<bool>) {
    let len = residuals.iter().map(Vec::len).min().unwrap_or(0);
    let common: Vec<bool> = (0..len)
        .map(|j| residuals.iter().all(|r| r[j].is_finite()))
        .collect();
    let n = common.iter().filter(|&&c| c).count() as u64;
    let rms = residuals
        .iter()
        .map(|r| {
            let ss: f64 = (0..len)
                .filter(|&j| common[j])
                .map(|j| (r[j] as f64).powi(2))
                .sum();
            (ss / n.max(1) as f64).sqrt()
        })
        .collect();
    (rms, n, common)
}

/// Whether candidate `a`'s held-out residuals are smaller than `b`'s beyond chance: the mean
/// of `r_b^2 - r_a^2` over the common residuals exceeds [`SIGNIFICANCE`] standard errors,
/// clustered by the tiles of `tiles` (one per residual: neighbouring pixels share misfit,
/// JPEG blocks and misregistration).
fn significantly_better(a: &[f32], b: &[f32], common: &[bool], tiles: &[u32]) -> bool {
    let idx = || (0..common.len()).filter(|&j| common[j]);
    let n = idx().count();
    if n < 2 {
        return false;
    }
    let d = |j: usize| f64::from(b[j]).powi(2) - f64::from(a[j]).powi(2);
    let mean = idx().map(d).sum::<f64>() / n as f64;
    let mut per_tile = std::collections::BTreeMap::<u32, f64>::new();
    for j in idx() {
        *per_tile.entry(tiles[j]).or_default() += d(j) - mean;
    }
    let var = per_tile.values().map(|v| v * v).sum::<f64>() / (n as f64 * n as f64);
    mean > SIGNIFICANCE * var.sqrt()
}

/// Standard errors by which the log-domain fit must predict better than the grey-domain one.
const SIGNIFICANCE: f64 = 2.0;

/// How much better (relative RMS) the log-domain fit must predict, besides beyond chance: with
/// a hundred thousand held-out values a 0.3% gain is significant, but the check's merge (least
/// squares in `U`) rewards a table bent at the top by that much on sweeps that follow the
/// camera model, where the grey-domain fit is the right one.
const LOG_MARGIN: f64 = 0.01;

/// The choice: the best grey-domain candidate (a weaker prior replaces a stronger one only by
/// [`WEAKER_PRIOR_MARGIN`]); when the log-domain fit competes, the best of its candidates
/// replaces it only if it predicts better by [`LOG_MARGIN`] and `better_log(log, cold)` than
/// the same grey-domain candidate refitted afresh in every fold.
fn pick(cands: &[Choice], rms: &[f64], better_log: &dyn Fn(usize, usize) -> bool) -> usize {
    let better = |c: usize, than: usize, margin: f64| rms[c] < rms[than] * (1.0 - margin);
    let mut grey: Option<usize> = None;
    let mut cold: Option<usize> = None;
    let mut log: Option<usize> = None;
    for (c, cand) in cands.iter().enumerate() {
        match (cand.estimator, cand.cold) {
            (Estimator::Log, _) => {
                if log.is_none_or(|l| better(c, l, 0.0)) {
                    log = Some(c);
                }
            }
            (_, true) => cold = Some(c),
            (_, false) => match grey {
                None => grey = Some(c),
                Some(g) => {
                    let weaker = cand.prior_scale < cands[g].prior_scale;
                    let unweighted = !cand.measured && cands[g].measured;
                    let margin = if weaker { WEAKER_PRIOR_MARGIN } else { 0.0 }
                        + if unweighted { UNIFORM_MARGIN } else { 0.0 };
                    if better(c, g, margin) {
                        grey = Some(c);
                    }
                }
            },
        }
    }
    match (grey, cold, log) {
        (Some(_), Some(c), Some(l)) if better(l, c, LOG_MARGIN) && better_log(l, c) => l,
        (Some(g), _, _) => g,
        (None, _, Some(l)) => l,
        (None, _, None) => 0,
    }
}

#[cfg(test)]
mod tests {
    use super::{pick, significantly_better, Choice, Estimator, PRIOR_SCALES};

    /// The grey-domain candidates in the check's order (each prior: measured, uniform).
    fn grey_candidates() -> Vec<Choice> {
        PRIOR_SCALES
            .iter()
            .flat_map(|&prior_scale| {
                [true, false].map(|measured| Choice {
                    estimator: Estimator::Grey,
                    measured,
                    prior_scale,
                    cold: false,
                    all_values: false,
                })
            })
            .collect()
    }

    #[test]
    fn uniform_weights_and_a_weaker_prior_must_each_win_by_the_margin() {
        let c = grey_candidates();
        let never = |_: usize, _: usize| false;
        // a tie, or uniform weights better by less than 1%: the measured ones stay
        assert_eq!(pick(&c, &[1.0, 1.0, 1.0, 1.0, 1.0, 1.0], &never), 0);
        assert_eq!(pick(&c, &[1.0, 0.995, 1.0, 0.995, 1.0, 0.995], &never), 0);
        // better by 2%: uniform weights
        assert_eq!(pick(&c, &[1.0, 0.98, 1.0, 1.0, 1.0, 1.0], &never), 1);
        // once uniform weights are chosen, measured ones with a weaker prior need only the
        // weaker prior's margin
        assert_eq!(pick(&c, &[1.0, 0.98, 0.979, 1.0, 1.0, 1.0], &never), 1);
        assert_eq!(pick(&c, &[1.0, 0.98, 0.96, 1.0, 1.0, 1.0], &never), 2);
        // uniform weights with a weaker prior against measured ones: both margins
        assert_eq!(pick(&c, &[1.0, 1.0, 1.0, 0.985, 1.0, 1.0], &never), 0);
        assert_eq!(pick(&c, &[1.0, 1.0, 1.0, 0.975, 1.0, 1.0], &never), 3);
    }

    /// 400 pseudo-random residuals (uniform in -scale..scale) from `seed`.
    fn residuals(scale: f32, seed: u64) -> Vec<f32> {
        let mut x = seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1;
        (0..400)
            .map(|_| {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                scale * ((x >> 40) as f32 / (1u64 << 23) as f32 - 1.0)
            })
            .collect()
    }

    #[test]
    fn only_a_clear_improvement_counts() {
        let tiles: Vec<u32> = (0..400).map(|j| j / 10).collect();
        let all = vec![true; 400];
        let a = residuals(1.0, 3);
        // the same residuals: no improvement, in either direction
        assert!(!significantly_better(&a, &a, &all, &tiles));
        // half the size everywhere: better, and not the other way round
        let half = residuals(0.5, 3);
        assert!(significantly_better(&half, &a, &all, &tiles));
        assert!(!significantly_better(&a, &half, &all, &tiles));
        // 1% smaller, but other residuals of the same spread: within chance
        let other = residuals(0.99, 57);
        assert!(!significantly_better(&other, &a, &all, &tiles));
        // nothing in common: no evidence
        assert!(!significantly_better(&half, &a, &[false; 400], &tiles));
    }
}
