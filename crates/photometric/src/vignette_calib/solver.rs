//! The solver and its stopping rule: alternating V and C steps, Anderson-accelerated, on a
//! coarse problem first and then on all pixels, until the change of `V` is below the
//! tolerance or far below the raw map's standard error.

use super::passes::{pass, store_pass, Step, Tables, Visit};
use super::problem::{cells, Model, Problem, VSums};
use super::store::Store;
use crate::noise::{fit_noise, NoiseModel};
use crate::smoothing::find_defects;
use crate::PhotometricError;

/// The coarse stage has every `COARSE_STRIDE`-th pixel in each direction and a grid as
/// much coarser.
pub(super) const COARSE_STRIDE: usize = 4;

/// The coarse stage only needs to bring the fine one near its solution.
pub(super) const COARSE_TOLERANCE: f64 = 2e-4;

/// Iterations Anderson mixing remembers.
pub(super) const ANDERSON_MEMORY: usize = 5;

/// A component of a step (or a residual) more than this many times the 99th percentile of
/// the step's components is erratic ([`erratic_bound`]).
pub(super) const ERRATIC_FACTOR: f64 = 20.0;

/// The least bound of [`erratic_bound`]: a change of `V` by 1% (of the mean) is erratic only
/// when the typical change is a good part of it, not once the iteration has settled to
/// changes a hundred times smaller.
pub(super) const ERRATIC_FLOOR: f64 = 1e-2;

/// The bound above which a value of `values` (by absolute value) is erratic:
/// [`ERRATIC_FACTOR`] times the 99th percentile of the absolute values that are not 0
/// (infinite with fewer than 100 of them: then none is).
///
/// A pixel whose observations lie near the outlier bound (a hot or dead pixel that the
/// defect search has not found, a pixel with few observations) goes in and out of the
/// outlier set as `V` moves: its `V` jumps by up to several times its value from one
/// iteration to the next while every other pixel converges smoothly, the changes of those
/// spread over about a decade (their 99th percentile is some ten times their median, the
/// largest a few times that). A handful of such pixels would make the RMS change and the
/// mixing of [`Anderson`], and with them the iteration, follow them alone.
pub(super) fn erratic_bound(values: impl Iterator<Item = f64>) -> f64 {
    let mut a: Vec<f64> = values
        .map(f64::abs)
        .filter(|a| *a > 0.0 && a.is_finite())
        .collect();
    if a.len() < 100 {
        return f64::INFINITY;
    }
    let k = a.len() * 99 / 100;
    let (_, q, _) = a.select_nth_unstable_by(k, f64::total_cmp);
    (ERRATIC_FACTOR * *q).max(ERRATIC_FLOOR)
}

/// Anderson mixing of the fixed-point iteration on `V` and `C` (memory `m`): the next
/// iterate combines the last ones so that the combined residual is smallest. Only the last
/// iterate and residual are kept in full precision; the history is their differences in
/// `f32` (about 7 significant digits of a step, far below the tolerance), which keeps the
/// memory at `2 m + 2` vectors of half size.
///
/// The vectors are `V` (the first `split` components) and then `C`. The mixing's least
/// squares leave out the erratic pixels ([`erratic_bound`]) of any residual or difference in
/// the history: fitted to those, the coefficients would follow a few jumping pixels and
/// throw the rest about. (Not so the cells of `C`: each sums the observations of many
/// pixels, so that no one observation moves it far; the cells that change most are those
/// slowest to converge, seen by few frames, the ones the mixing must speed up.)
pub(super) struct Anderson {
    pub(super) m: usize,
    pub(super) split: usize,
    pub(super) last: Option<(Vec<f64>, Vec<f64>)>,
    /// Differences of the residuals `f = g(x) - x` of consecutive iterations.
    pub(super) df: std::collections::VecDeque<Vec<f32>>,
    /// Differences of the images `g(x)` (`dx + df`).
    pub(super) dg: std::collections::VecDeque<Vec<f32>>,
    /// The steps so far.
    pub(super) steps: u32,
    /// By pixel, the last step at which it was erratic ([`u32::MAX`]: never).
    pub(super) erratic: Vec<u32>,
}

impl Anderson {
    pub(super) fn new(m: usize, split: usize) -> Anderson {
        Anderson {
            m,
            split,
            last: None,
            df: Default::default(),
            dg: Default::default(),
            steps: 0,
            erratic: Vec::new(),
        }
    }

    /// Marks the erratic pixels of `x` (its `V` part).
    pub(super) fn mark<T: Copy + Into<f64>>(&mut self, x: &[T]) {
        let v = &x[..self.split.min(x.len())];
        let bound = erratic_bound(v.iter().map(|&a| a.into()));
        if !bound.is_finite() {
            return;
        }
        for (e, &a) in self.erratic.iter_mut().zip(v) {
            if a.into().abs() > bound {
                *e = self.steps;
            }
        }
    }

    /// Given the iterate `x` and its image `gx` under the iteration, the next iterate.
    pub(super) fn step(&mut self, x: &[f64], gx: &[f64]) -> Vec<f64> {
        self.steps += 1;
        let split = self.split.min(x.len());
        if self.erratic.len() != split {
            self.erratic = vec![u32::MAX; split];
        }
        let f: Vec<f64> = gx.iter().zip(x).map(|(a, b)| a - b).collect();
        self.mark(&f);
        if let Some((lx, lf)) = self.last.take() {
            if self.df.len() == self.m {
                self.df.pop_front();
                self.dg.pop_front();
            }
            let df: Vec<f32> = f.iter().zip(&lf).map(|(a, b)| (a - b) as f32).collect();
            self.mark(&df);
            self.df.push_back(df);
            self.dg.push_back(
                gx.iter()
                    .zip(&lx)
                    .zip(&lf)
                    .map(|((g, x0), f0)| (g - (x0 + f0)) as f32)
                    .collect(),
            );
        }
        let k = self.df.len();
        let mut out = gx.to_vec();
        self.last = Some((x.to_vec(), f));
        if k == 0 {
            return out;
        }
        let Some((_, f)) = &self.last else {
            return out;
        };
        // the components in the least squares: not erratic in any residual of the history
        // (the oldest difference holds the residual m + 1 steps back)
        let (steps, window) = (self.steps, self.m as u32 + 1);
        let keep: Vec<bool> = self
            .erratic
            .iter()
            .map(|&e| e == u32::MAX || steps - e > window)
            .chain(std::iter::repeat(true))
            .take(x.len())
            .collect();
        // least squares for the mixing coefficients
        let mut ata = nalgebra::DMatrix::<f64>::zeros(k, k);
        let mut atb = nalgebra::DVector::<f64>::zeros(k);
        for a in 0..k {
            for b in a..k {
                let d: f64 = self.df[a]
                    .iter()
                    .zip(&self.df[b])
                    .zip(&keep)
                    .filter(|(_, k)| **k)
                    .map(|((p, q), _)| *p as f64 * *q as f64)
                    .sum();
                ata[(a, b)] = d;
                ata[(b, a)] = d;
            }
            atb[a] = self.df[a]
                .iter()
                .zip(f)
                .zip(&keep)
                .filter(|(_, k)| **k)
                .map(|((p, q), _)| *p as f64 * q)
                .sum();
        }
        let scale = (0..k).map(|a| ata[(a, a)]).fold(0.0, f64::max).max(1e-300);
        for a in 0..k {
            ata[(a, a)] += 1e-10 * scale;
        }
        let Some(gamma) = ata.cholesky().map(|c| c.solve(&atb)) else {
            self.reset();
            return out;
        };
        // x_next = gx - sum gamma_j dg_j; an erratic component takes the plain step (its
        // differences, left out of the fit, would throw it about)
        for (j, dg) in self.dg.iter().enumerate() {
            let gj = gamma[j];
            if gj == 0.0 || !gj.is_finite() {
                continue;
            }
            for ((o, d), k) in out.iter_mut().zip(dg).zip(&keep) {
                if *k {
                    *o -= gj * *d as f64;
                }
            }
        }
        out
    }

    pub(super) fn reset(&mut self) {
        self.last = None;
        self.df.clear();
        self.dg.clear();
    }
}

/// The result of one stage of the solver.
pub(super) struct Stage {
    pub(super) model: Model,
    pub(super) tables: Tables,
    pub(super) iterations: usize,
    pub(super) converged: bool,
    pub(super) change: Vec<f64>,
    /// The statistics of the last iteration, when it took them with the problem fixed (see
    /// [`solve`]).
    pub(super) stats: Option<VSums>,
}

/// Alternates V and C steps (Anderson-accelerated) on `problem` until the RMS relative
/// change of `V` is below `tolerance`. From scratch (`warm = None`) the noise model follows
/// the residuals for the first iterations and outliers are dropped after a few; from a warm
/// start (`V` and the noise model of a coarser stage) both are fixed from the start.
pub(super) fn solve(
    problem: &Problem<'_>,
    store: Option<&Store>,
    warm: Option<(Vec<f64>, NoiseModel)>,
    (tolerance, noise_tolerance): (f64, f64),
    max_iterations: usize,
    progress: &(dyn Fn(usize, f64) + Sync),
) -> Result<Stage, PhotometricError> {
    let u = problem.u;
    let npx = problem.sample.len();
    let warm_start = warm.is_some();
    let (mut model, mut tables) = start(problem, store, warm)?;
    let mut anderson = Anderson::new(ANDERSON_MEMORY, npx);
    let mut change: Vec<f64> = Vec::new();
    let mut converged = false;
    let mut iterations = 0;
    let layout = problem.layout;
    let mut defective = vec![false; npx];
    // outliers are dropped from the SETTLE-th iteration; the noise model follows the
    // residuals for NOISE_FIT_ITERATIONS; from then on the problem is fixed
    const SETTLE: usize = 4;
    const NOISE_FIT_ITERATIONS: usize = 7;
    let mut final_stats = None;
    // the stop rule's bound of the last iteration
    let mut last_enough = f64::INFINITY;
    for it in 0..max_iterations.max(1) {
        iterations = it + 1;
        // whether the problem (noise model, outliers) stays as it is from this iteration on
        let fixed = warm_start || it >= NOISE_FIT_ITERATIONS;
        // the statistics of the residuals while the noise model follows them, and in an
        // iteration that looks like the last ([`looks_last`]): when it is, the result's
        // statistics come from it, with the V and C before its step (which changes V by less
        // than the bound: a few percent of its standard error), instead of from one more pass
        let likely_last = fixed && looks_last(&change, warm_start, last_enough);
        let stats = (!warm_start && it < NOISE_FIT_ITERATIONS) || likely_last;
        // V step with the current C (and, all frames at hand, the C step with its V)
        let (vs, fused_c) = match store {
            Some(st) => {
                let (vs, c) = store_pass(problem, &model, &tables, st, Visit::Fused, stats)?;
                (vs, Some(c))
            }
            None => (pass(problem, &model, &tables, Step::V, stats)?.0, None),
        };
        if vs.nobs == 0 {
            return Err(PhotometricError::Calibration(
                "no pixel of any frame sees the calibration plane".into(),
            ));
        }
        let mut gv = v_step(&model.v, &vs);
        // the defective pixels of the stop rule below (once the noise model, the scale of
        // `den`, is fixed: the rule applies from then on)
        if warm_start || it >= NOISE_FIT_ITERATIONS {
            let found = find_defects(layout.0, layout.1, &gv, &vs.den);
            for (d, f) in defective.iter_mut().zip(found) {
                *d |= f;
            }
        }
        let mean = gauge(&mut gv, &vs.den);
        // C step (a Jacobi step towards the exact least squares) with the new V
        let old_v = std::mem::replace(&mut model.v, gv);
        let gc: Vec<f32> = match fused_c {
            // the C step with the unscaled V: C on the gauge's scale
            Some(c) => c.iter().map(|&c| c * mean as f32).collect(),
            None => {
                let scaled = Model {
                    v: model.v.clone(),
                    c: model.c.iter().map(|&c| c * mean as f32).collect(),
                    noise: model.noise,
                    reject: model.reject,
                };
                pass(problem, &scaled, &tables, Step::C, false)?.1
            }
        };
        let (new_v, new_c) = mix(
            &mut anderson,
            it,
            (&old_v, &model.c),
            (&model.v, &gc),
            &vs.den,
        );
        let delta = v_change(&new_v, &old_v, &vs.den, &defective);
        model.v = new_v;
        model.c = new_c;
        change.push(delta);
        progress(iterations, delta);
        // the noise model follows the residuals until the fit has settled; then outliers go
        // and the problem stays fixed
        if !warm_start && it < NOISE_FIT_ITERATIONS {
            if let Some(nm) = fit_noise(u, &vs.rss, &vs.rcnt) {
                model.noise = nm;
                tables = Tables::new(u, &model.noise);
            }
        }
        if !warm_start && it + 1 == SETTLE {
            model.reject = true;
        }
        if !warm_start && (it + 1 == SETTLE || it + 1 == NOISE_FIT_ITERATIONS) {
            anderson.reset();
        }
        let enough = tolerance.max(noise_tolerance * median_std_error(&model.v, &vs.den));
        if fixed && delta < enough {
            converged = true;
            if stats {
                final_stats = Some(vs);
            }
            break;
        }
        last_enough = enough;
    }
    Ok(Stage {
        model,
        tables,
        iterations,
        converged,
        change,
        stats: final_stats,
    })
}

/// The start of a stage: `V` (warm from the coarse stage, or 1) and the noise model, then
/// `C` from `V` (a Jacobi step from C = 0 is the paper's splat).
fn start(
    problem: &Problem<'_>,
    store: Option<&Store>,
    warm: Option<(Vec<f64>, NoiseModel)>,
) -> Result<(Model, Tables), PhotometricError> {
    let warm_start = warm.is_some();
    let (v0, noise0) = warm.unwrap_or_else(|| {
        (
            vec![1.0; problem.sample.len()],
            NoiseModel {
                read: 1.0,
                shot: 0.1,
                adc: 1.0,
            },
        )
    });
    let mut model = Model {
        v: v0,
        c: vec![0.0; cells(problem.grid)],
        noise: noise0,
        reject: warm_start,
    };
    let tables = Tables::new(problem.u, &model.noise);
    // (without outlier rejection: with C = 0 every observation would be one)
    model.reject = false;
    model.c = match store {
        Some(st) => store_pass(problem, &model, &tables, st, Visit::C, false)?.1,
        None => pass(problem, &model, &tables, Step::C, false)?.1,
    };
    model.reject = warm_start;
    Ok((model, tables))
}

/// The V step: `V = num / den` where a pixel is observed, its old value elsewhere.
fn v_step(v: &[f64], vs: &VSums) -> Vec<f64> {
    let mut gv = v.to_vec();
    for ((g, n), d) in gv.iter_mut().zip(&vs.num).zip(&vs.den) {
        if *d > 0.0 {
            *g = n / d;
        }
    }
    gv
}

/// The gauge: mean V over observed pixels = 1 (C absorbs the scale); returns the mean
/// divided out.
fn gauge(gv: &mut [f64], den: &[f64]) -> f64 {
    let (sum, n) = gv
        .iter()
        .zip(den)
        .filter(|(_, d)| **d > 0.0)
        .fold((0.0, 0usize), |(s, n), (v, _)| (s + v, n + 1));
    let mean = if n > 0 { sum / n as f64 } else { 1.0 };
    for x in gv.iter_mut() {
        *x /= mean;
    }
    mean
}

/// Anderson mixing of the whole iteration, V and C together, from the iterate `(v, c)` and
/// its image `(gv, gc)`; V kept positive where observed (1 elsewhere), C non-negative.
fn mix(
    anderson: &mut Anderson,
    it: usize,
    (v, c): (&[f64], &[f32]),
    (gv, gc): (&[f64], &[f32]),
    den: &[f64],
) -> (Vec<f64>, Vec<f32>) {
    let npx = v.len();
    let mut x: Vec<f64> = v.to_vec();
    x.extend(c.iter().map(|&c| c as f64));
    let mut g: Vec<f64> = gv.to_vec();
    g.extend(gc.iter().map(|&c| c as f64));
    let next = if it >= 1 { anderson.step(&x, &g) } else { g };
    let (nv, nc) = next.split_at(npx);
    let mut new_v: Vec<f64> = nv.to_vec();
    for (v, d) in new_v.iter_mut().zip(den) {
        if !(v.is_finite() && *v > 0.0) || *d <= 0.0 {
            *v = if *d > 0.0 { 1e-3 } else { 1.0 };
        }
    }
    let new_c: Vec<f32> = (0..c.len()).map(|j| nc[j].max(0.0) as f32).collect();
    (new_v, new_c)
}

/// The RMS relative change of V, the stop rule's measure.
fn v_change(new_v: &[f64], old_v: &[f64], den: &[f64], defective: &[bool]) -> f64 {
    // the change of V over the pixels the raw map keeps. Left out: a defective pixel
    // (hot, dead; found so in any iteration of the stage), and a pixel whose change is
    // erratic in this iteration ([`erratic_bound`]): their observations go in and out
    // of the outlier set as V moves, so that they jump by up to several times their
    // value between iterations and would hold up the convergence of the rest (with
    // more than half of the pixels found defective, all of them count)
    let observed: Vec<(f64, bool)> = new_v
        .iter()
        .zip(old_v)
        .zip(den.iter().zip(defective))
        .filter(|(_, (d, _))| **d > 0.0)
        .map(|((a, b), (_, bad))| (((a - b) / b).abs(), *bad))
        .collect();
    let all = 2 * observed.iter().filter(|(_, bad)| !bad).count() <= observed.len();
    let counted = || {
        observed
            .iter()
            .filter(|(_, bad)| all || !bad)
            .map(|(c, _)| *c)
    };
    let bound = erratic_bound(counted());
    let (s2, n2) = counted()
        .filter(|c| *c <= bound)
        .fold((0.0, 0usize), |(s, n), c| (s + c * c, n + 1));
    (s2 / n2.max(1) as f64).sqrt()
}

/// Whether the next iteration looks like the last: its change, extrapolated from the last
/// two of `change` (at the rate between them, at most 1), below twice the stop rule's
/// `bound`. From a warm start the first change is the step from the coarse stage's V to the
/// full one's, a decade above the next: a rate taken from it predicted convergence for the
/// iteration after it on every set measured, where it never was (600 frames of 1280x1024:
/// changes 1.6e-3, 1.0e-4, ...), and the statistics cost a quarter of a pass for nothing; so
/// the rate comes from the changes after it.
pub(super) fn looks_last(change: &[f64], warm_start: bool, bound: f64) -> bool {
    let settled = if warm_start {
        change.get(1..).unwrap_or_default()
    } else {
        change
    };
    match settled {
        [.., a, b] => b * (b / a).min(1.0) < 2.0 * bound,
        _ => false,
    }
}

/// The median relative standard error of the raw map `v` from the normal equations (`1 /
/// sqrt(den)` per pixel), over the pixels with observations.
pub(super) fn median_std_error(v: &[f64], den: &[f64]) -> f64 {
    let mut rel: Vec<f64> = v
        .iter()
        .zip(den)
        .filter(|(v, d)| **d > 0.0 && **v > 0.0)
        .map(|(v, d)| 1.0 / (d.sqrt() * v))
        .collect();
    if rel.is_empty() {
        return 0.0;
    }
    let mid = rel.len() / 2;
    *rel.select_nth_unstable_by(mid, f64::total_cmp).1
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    pub(super) fn the_erratic_bound_is_a_multiple_of_the_99th_percentile_with_a_floor() {
        // fewer than 100 values that are not 0: no bound
        let few = (0..99).map(|i| 1.0 + i as f64).chain([0.0; 50]);
        assert!(erratic_bound(few).is_infinite());
        // 1000 values 1e-4 .. 1e-1, 0 and NaN left out: the 99th percentile is the 991st
        let values: Vec<f64> = (1..=1000)
            .map(|i| -(i as f64) * 1e-4)
            .chain([0.0, f64::NAN])
            .collect();
        let bound = erratic_bound(values.iter().copied());
        assert!((bound - ERRATIC_FACTOR * 991e-4).abs() < 1e-12, "{bound}");
        // small changes: the floor
        let tiny = (1..=1000).map(|i| i as f64 * 1e-9);
        assert_eq!(erratic_bound(tiny), ERRATIC_FLOOR);
    }

    #[test]
    pub(super) fn the_last_iteration_is_foreseen_from_the_rate_after_a_warm_starts_first_step() {
        // the 600 x 1280x1024 set's fine stage (bound 4.96e-5)
        let bound = 4.96e-5;
        let changes = [1.573e-3, 9.989e-5, 9.867e-5, 1.136e-4, 5.792e-5, 2.591e-5];
        let foreseen: Vec<bool> = (0..changes.len())
            .map(|k| looks_last(&changes[..k], true, bound))
            .collect();
        // the rate 1.6e-3 -> 1.0e-4 is the coarse-to-fine step's: no guess for the third
        // iteration (it had said yes, and was wrong); 9.99e-5 -> 9.87e-5 extrapolates to
        // 9.75e-5, under twice the bound (yes; wrong, a stall it cannot tell); after a rise,
        // no; 1.1e-4 -> 5.8e-5 extrapolates to 3.0e-5: yes, the last, as it was
        assert_eq!(foreseen, [false, false, false, true, false, true]);
        // from scratch the first change counts like the others
        assert!(looks_last(&changes[..2], false, bound));
    }

    /// A linear iteration `x -> x* + A (x - x*)` with three rates (Anderson mixing with
    /// memory 5 solves it in a few steps) of which a few pixels jump between two values
    /// whatever `x` is: the mixing must still converge on the rest as fast.
    #[test]
    pub(super) fn anderson_mixing_converges_on_the_rest_while_a_few_pixels_jump() {
        let (nv, nc) = (3000, 800);
        let n = nv + nc;
        let target: Vec<f64> = (0..n)
            .map(|i| 1.0 + 0.3 * ((i as f64) * 0.37).sin())
            .collect();
        let rate = |i: usize| [0.97, 0.9, 0.6][i % 3];
        let jumpers = [17usize, 400, 1234, 2222, 2999];
        let run = |steps: usize| -> f64 {
            let mut anderson = Anderson::new(ANDERSON_MEMORY, nv);
            let mut x = vec![1.0; n];
            for k in 0..steps {
                let mut g: Vec<f64> = (0..n)
                    .map(|i| target[i] + rate(i) * (x[i] - target[i]))
                    .collect();
                for &j in &jumpers {
                    g[j] = target[j] * if k % 2 == 0 { 2.0 } else { 0.5 };
                }
                x = if k >= 1 { anderson.step(&x, &g) } else { g };
            }
            (0..n)
                .filter(|i| !jumpers.contains(i))
                .map(|i| (x[i] - target[i]).abs())
                .fold(0.0, f64::max)
        };
        let start = run(1);
        let end = run(12);
        // the plain iteration would leave 0.97^12 = 70% of the start's error; the mixing
        // fitted to the jumping pixels too about 5e-6 of it, and 2e-9 without them
        assert!(
            end < 1e-7 * start,
            "error {end} after 12 steps, {start} after one"
        );
    }
}
