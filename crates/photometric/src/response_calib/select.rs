//! The truth-free check that chooses the weights and the prior's strength: the exposures are
//! split into folds (each exposure its own fold when there are few), each candidate fit is
//! repeated without each fold, and the frames of the fold are predicted from the pixels' other
//! frames through the fitted `U`: each pixel's irradiance from its other values by least
//! squares, `B' = sum t U(I) / sum t^2` (the same for all, so that only `U` differs), then
//! `G(t B')` against the value the camera recorded. Measured weights are kept unless uniform
//! weights predict the held-out frames better; a weaker prior only when it predicts them
//! clearly better (a ripple the exposures leave undetermined is invisible to the check, so a
//! tie keeps the prior the ripples need).

use super::model::{Forward, Obs};
use super::samples::Samples;
use super::solver::{solve, Problem, Settings, Start};
use crate::noise::interp;
use crate::PhotometricError;

/// Folds of the check: every distinct exposure its own fold up to this many, else this many
/// interleaved folds (by exposure rank): every exposure is held out once.
const MAX_FOLDS: usize = 8;

/// Iterations of a fold's fit (warm from the fit on all exposures).
const FOLD_ITERATIONS: usize = 6;

/// One candidate fit and its held-out score.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CandidateScore {
    /// Weighted by the measured noise (else uniformly).
    pub measured: bool,
    /// The prior's weight relative to what the exposures' ripples need.
    pub prior_scale: f64,
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

/// The priors the check tries, strongest first.
pub(super) const PRIOR_SCALES: [f64; 3] = [1.0, 0.1, 0.01];

/// How much better (relative RMS) a weaker prior must predict to be chosen.
const WEAKER_PRIOR_MARGIN: f64 = 0.01;

/// The fold of each frame: distinct exposures (relative tolerance 1e-6) in rank order.
pub(super) fn folds(exposures: &[f64]) -> (Vec<usize>, usize) {
    let mut distinct: Vec<f64> = exposures.to_vec();
    distinct.sort_by(f64::total_cmp);
    distinct.dedup_by(|a, b| (*a / *b - 1.0).abs() < 1e-6);
    let k = distinct.len().min(MAX_FOLDS);
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

/// The held-out residuals (grey values) of one candidate, fold by fold, pixel by pixel, frame
/// by frame; NaN where its fit failed.
fn held_out(base: &Problem<'_>, fold: &[usize], k: usize) -> Result<Vec<f32>, PhotometricError> {
    let quiet = |_: usize, _: f64| {};
    let all = solve(
        base,
        Start::Cold,
        &Settings {
            max_iterations: 40,
            tolerance: 0.02,
            tiles: false,
            progress: &quiet,
        },
    )?;
    let s = base.samples;
    let lv = base.levels;
    let per_grey = 1.0 / lv.scale;
    let mut out = Vec::new();
    for f in 0..k {
        let train: Vec<bool> = fold.iter().map(|&g| g != f).collect();
        let p = Problem {
            train: Some(&train),
            log_gap: ripple_period(base.exposures, Some(&train)),
            ..*base
        };
        let fit = solve(
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
                progress: &quiet,
            },
        );
        let u = fit.as_ref().ok().map(|f| (f.u.clone(), Forward::new(&f.u)));
        for px in 0..s.len() {
            let vals = s.pixel(px);
            let inside = |i: usize, v: u16| {
                !s.is_excluded(px, i) && matches!(Obs::of(v as u32, &lv), Obs::Value(_))
            };
            // the least-squares irradiance from the training values
            let (mut num, mut den) = (0.0, 0.0);
            if let Some((table, _)) = &u {
                for (i, &v) in vals.iter().enumerate() {
                    if train[i] && inside(i, v) {
                        let t = base.exposures[i];
                        num += t * interp(table, lv.pos(v as u32));
                        den += t * t;
                    }
                }
            }
            let has = vals
                .iter()
                .enumerate()
                .any(|(i, &v)| train[i] && inside(i, v));
            for (i, &v) in vals.iter().enumerate() {
                if fold[i] != f || !inside(i, v) || !has {
                    continue;
                }
                let r = match &u {
                    Some((_, g)) if den > 0.0 => {
                        let (j, fr) = g.eval(base.exposures[i] * num / den);
                        let mu = (j as f64 + fr).clamp(0.0, (lv.knots - 1) as f64);
                        ((lv.pos(v as u32) - mu) * per_grey) as f32
                    }
                    _ => f32::NAN,
                };
                out.push(r);
            }
        }
    }
    Ok(out)
}

/// Scores the candidates (measured and uniform weights, each with the priors of
/// [`PRIOR_SCALES`] when `priors`) on `samples`; returns the chosen one's weighting and prior
/// scale, with the scores.
pub(super) fn choose(
    base: &Problem<'_>,
    samples: &Samples,
    weightings: &[bool],
    priors: bool,
) -> Result<(bool, f64, HeldOutScores), PhotometricError> {
    let (fold, k) = folds(base.exposures);
    let scales: &[f64] = if priors {
        &PRIOR_SCALES
    } else {
        &PRIOR_SCALES[..1]
    };
    let mut cands = Vec::new();
    let mut residuals = Vec::new();
    for &prior_scale in scales {
        for &measured in weightings {
            let p = Problem {
                measured,
                prior_scale,
                samples,
                ..*base
            };
            residuals.push(held_out(&p, &fold, k)?);
            cands.push((measured, prior_scale));
        }
    }
    let len = residuals.iter().map(Vec::len).min().unwrap_or(0);
    let common: Vec<bool> = (0..len)
        .map(|j| residuals.iter().all(|r| r[j].is_finite()))
        .collect();
    let n = common.iter().filter(|&&c| c).count() as u64;
    let rms: Vec<f64> = residuals
        .iter()
        .map(|r| {
            let ss: f64 = (0..len)
                .filter(|&j| common[j])
                .map(|j| (r[j] as f64).powi(2))
                .sum();
            (ss / n.max(1) as f64).sqrt()
        })
        .collect();
    // the best of each prior; a weaker prior replaces a stronger one only by the margin
    let mut chosen = 0;
    for c in 1..cands.len() {
        let weaker = cands[c].1 < cands[chosen].1;
        let margin = if weaker {
            1.0 - WEAKER_PRIOR_MARGIN
        } else {
            1.0
        };
        if rms[c] < rms[chosen] * margin {
            chosen = c;
        }
    }
    let scores = HeldOutScores {
        candidates: cands
            .iter()
            .zip(&rms)
            .map(|(&(measured, prior_scale), &rms)| CandidateScore {
                measured,
                prior_scale,
                rms,
            })
            .collect(),
        chosen,
        observations: n,
        folds: k,
        pixels: samples.len(),
    };
    Ok((cands[chosen].0, cands[chosen].1, scores))
}
