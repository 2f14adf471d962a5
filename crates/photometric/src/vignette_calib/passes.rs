//! The passes over the observations: for every frame and pixel, the residual of
//! `U(I) = t V C` with its noise weight, summed into the V step's and the C step's sums;
//! frames in memory are visited block by block, on all cores, with the AVX2 kernels where
//! the CPU has them.

use rayon::prelude::*;

use super::problem::{
    cell, cells, grid_coords, morton, taps, Geom, Model, Problem, Samples, VSums, BATCH,
};
use super::store::{Chunk, SamplesRef, Store};
use crate::noise::NoiseModel;
use crate::PhotometricError;

/// Bins of the lookup tables over the energy (U-units) up to `U` of the saturated value.
pub(super) const VAR_BINS: usize = 2048;

/// Per energy bin: the noise model's variance of `U(I)`, the grey value, and the inverse
/// slope of `U` there (residuals in grey values for the noise model's fit).
pub(super) struct Tables {
    /// (an array: its length is known where the passes index it)
    pub(super) var: Box<[f64; VAR_BINS]>,
    pub(super) grey: Vec<u16>,
    pub(super) inv_slope: Vec<f64>,
    pub(super) scale: f64,
}

impl Tables {
    pub(super) fn new(u: &[f64], noise: &NoiseModel) -> Tables {
        let last = u.len() - 1;
        let top = u[last].max(1e-9);
        let scale = (VAR_BINS - 1) as f64 / top;
        let mut t = Tables {
            var: Box::new([0.0; VAR_BINS]),
            grey: Vec::with_capacity(VAR_BINS),
            inv_slope: Vec::with_capacity(VAR_BINS),
            scale,
        };
        for b in 0..VAR_BINS {
            let e = b as f64 / scale;
            t.var[b] = noise.energy_variance(u, e);
            let k = u.partition_point(|&x| x <= e).clamp(1, last);
            t.grey.push(k as u16);
            t.inv_slope.push(1.0 / (u[k] - u[k - 1]).max(1e-9));
        }
        t
    }

    /// The bin of energy `e` (the nearest; NaN gives bin 0).
    #[inline]
    pub(super) fn bin(&self, e: f64) -> usize {
        // (a branch-free conversion: `as usize` saturates in several instructions)
        let b = (e * self.scale).clamp(0.0, (VAR_BINS - 1) as f64);
        round_small(if b.is_nan() { 0.0 } else { b }) as usize
    }
}

/// `x` rounded to the nearest integer (ties to even), for `0 <= x < 2^31`: the low bits of
/// `x + 2^52` (a branch-free conversion; `as` saturates in several instructions).
#[inline]
pub(super) fn round_small(x: f64) -> u32 {
    (x + 4_503_599_627_370_496.0).to_bits() as u32
}

/// Asks the core to bring the cache line at `p` into its cache ahead of its use: a hint,
/// which never faults (`p` may point anywhere) and changes no result; nothing off x86-64.
#[inline(always)]
pub(super) fn prefetch<T>(p: *const T) {
    // SAFETY: a prefetch reads nothing the program sees and does not fault on any address
    // (SSE, which it needs, is part of every x86-64 CPU)
    #[cfg(target_arch = "x86_64")]
    #[allow(unsafe_code)]
    unsafe {
        std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(p.cast())
    };
    #[cfg(not(target_arch = "x86_64"))]
    let _ = p;
}

/// [`prefetch`]es the two rows of the bilinear taps whose first is `cells[at]`, `grid`
/// cells per row.
#[inline(always)]
pub(super) fn prefetch_taps<T>(cells: &[T], at: usize, grid: usize) {
    let p = cells.as_ptr().wrapping_add(at);
    prefetch(p);
    prefetch(p.wrapping_add(grid));
}

/// How many observations ahead the lookups of `C` ([`PassCtx::dense`]) and the additions
/// to the C step's sums ([`Splats::add`]) ask for their cells: both wait on cache misses
/// (the plane's arrays are megabytes). 2-3% of a calibration (150 frames of 640x512, eight
/// paired runs, each faster); 8 and 32 were no better.
pub(super) const PREFETCH_AHEAD: usize = 16;

/// The floor of `x`, for `0 <= x < 2^31` (see [`round_small`]).
#[inline]
pub(super) fn floor_small(x: f64) -> i32 {
    let r = round_small(x) as i32;
    r - (r as f64 > x) as i32
}

/// Parallel jobs of a pass over the frames: consecutive frames share their accumulators.
pub(super) const FRAME_JOBS: usize = 8;

/// The decoded frames one job holds at a time stay under this many bytes (at least one
/// frame per job): memory does not grow with the number of frames.
pub(super) const JOB_FRAME_BYTES: usize = 32 << 20;

/// Pixels per block of a pass: the pass visits every frame of its job for one block of
/// pixels before the next, so that the block's sums, rays and `V` stay in the core's cache
/// while the frames stream by (frame by frame, these per-pixel arrays would come from
/// memory once per frame).
pub(super) const PIXEL_BLOCK: usize = 4096;

/// The frames of each job: a partition of the frames that depends on their number and size
/// only, not on the number of threads, so that every sum is taken in the same order with
/// any number of threads.
pub(super) fn frame_jobs(n: usize, frame_bytes: usize) -> Vec<std::ops::Range<usize>> {
    let per = n
        .div_ceil(FRAME_JOBS)
        .min(JOB_FRAME_BYTES / frame_bytes.max(1))
        .max(1);
    (0..n).step_by(per).map(|s| s..(s + per).min(n)).collect()
}

/// Runs `job` on the frames of every job of [`frame_jobs`], as many at a time as there are
/// threads, and hands the results to `add` in the order of the jobs: the same bits with one
/// thread or many, and at most one job's accumulators per thread in memory.
pub(super) fn fold_frame_jobs<T: Send>(
    jobs: &[std::ops::Range<usize>],
    job: impl Fn(std::ops::Range<usize>) -> Result<T, PhotometricError> + Sync,
    mut add: impl FnMut(T),
) -> Result<(), PhotometricError> {
    let wave = rayon::current_num_threads().max(1);
    for chunk in jobs.chunks(wave) {
        let parts: Vec<T> = chunk
            .par_iter()
            .map(|range| job(range.clone()))
            .collect::<Result<_, _>>()?;
        parts.into_iter().for_each(&mut add);
    }
    Ok(())
}

/// Which sums a pass takes.
#[derive(Clone, Copy, PartialEq)]
pub(super) enum Step {
    /// The V step's per-pixel sums and the residual statistics.
    V,
    /// The C step's per-cell sums.
    C,
}

/// What one pass holds fixed: the problem, the model, the noise tables and the constants
/// of the weights.
pub(super) struct PassCtx<'a, 'p> {
    pub(super) p: &'a Problem<'p>,
    pub(super) model: &'a Model,
    pub(super) tables: &'a Tables,
    pub(super) reg2: f64,
    pub(super) out2: f64,
    pub(super) top: u16,
    pub(super) step: Step,
    /// Whether the V step takes the statistics too (see [`PassCtx::v_sums`]).
    pub(super) stats: bool,
    /// Whether the kernels run with 256-bit vectors (see [`wide_vectors`]).
    pub(super) wide: bool,
}

/// Whether the passes' kernels ([`PassCtx::dense`], [`PassCtx::stages`]) run compiled for
/// AVX2: four `f64` to a vector instead of two, the same operations in the same order (no
/// fused multiply-add), so the same results to the bit, faster where the arithmetic is the
/// bound (the plane positions, about twice). On when the CPU has AVX2, unless the
/// environment variable `MONOVO_NO_AVX2` is set (to compare, or to rule it out).
pub(super) fn wide_vectors() -> bool {
    camera_model::avx2_enabled()
}

/// The sums of one job: the V step's per pixel, or the C step's per cell (numerator and
/// denominator side by side: one cache line).
pub(super) struct JobSums {
    pub(super) v: VSums,
    pub(super) cacc: Vec<[f32; 2]>,
}

/// The splats of the C step visit the observations of a batch this many apart (see
/// [`PassCtx::splat_dense`]).
pub(super) const SPLAT_STRIDE: usize = 4;

/// The observations of one batch of pixels of one frame, stage by stage (structure of
/// arrays): each stage is a short loop whose iterations do not depend on each other, so
/// that the core overlaps them and the compiler can use vector instructions (one loop doing
/// all of an observation's work in a row waits on a chain of divisions, loads and table
/// lookups).
pub(super) struct Batch {
    /// Plane grid coordinates of every pixel of the batch, and whether they are inside.
    pub(super) gx: Vec<f64>,
    pub(super) gy: Vec<f64>,
    pub(super) inside: Vec<bool>,
    /// The observations kept (the first `n` entries): the pixel's position in the problem's
    /// sample, the sample value, the storage indices of the four bilinear taps, and the
    /// fractions of the position between them.
    pub(super) n: usize,
    pub(super) pos: Vec<u32>,
    pub(super) k: Vec<u16>,
    pub(super) idx: Vec<[u32; 4]>,
    pub(super) frac: Vec<[f64; 2]>,
    /// `C` at the position, and the squared norm of its gradient (per cell).
    pub(super) cq: Vec<f64>,
    pub(super) grad2: Vec<f64>,
}

impl Batch {
    pub(super) fn new() -> Batch {
        Batch {
            gx: vec![0.0; BATCH],
            gy: vec![0.0; BATCH],
            inside: vec![false; BATCH],
            n: 0,
            pos: vec![0; BATCH],
            k: vec![0; BATCH],
            idx: vec![[0; 4]; BATCH],
            frac: vec![[0.0; 2]; BATCH],
            cq: vec![0.0; BATCH],
            grad2: vec![0.0; BATCH],
        }
    }
}

impl<'a, 'p> PassCtx<'a, 'p> {
    pub(super) fn new(
        p: &'a Problem<'p>,
        model: &'a Model,
        tables: &'a Tables,
        step: Step,
        stats: bool,
    ) -> Self {
        PassCtx {
            p,
            model,
            tables,
            reg2: p.options.registration_px * p.options.registration_px,
            out2: p.options.outlier_sigmas * p.options.outlier_sigmas,
            top: p.top(),
            step,
            stats,
            wide: wide_vectors(),
        }
    }

    /// The observations of frame `pf` (frame `i`) at the pixels `block` (positions in the
    /// problem's sample) into `acc`.
    pub(super) fn observe<S: Copy + Into<u16>>(
        &self,
        i: usize,
        pf: &Geom,
        data: &[S],
        block: std::ops::Range<usize>,
        acc: &mut JobSums,
        b: &mut Batch,
    ) {
        for start in block.clone().step_by(BATCH) {
            self.stages(pf, data, start..(start + BATCH).min(block.end), b);
            // stage 4: the weighted residuals into the sums
            match self.step {
                Step::V if self.stats => self.v_sums::<true>(i, pf, b, &mut acc.v, 0),
                Step::V => self.v_sums::<false>(i, pf, b, &mut acc.v, 0),
                Step::C => self.c_sums(pf, b, acc),
            }
        }
    }

    /// Stages 1 to 3 of the observations of frame `pf` (its samples `data`, row-major) at
    /// the pixels `ks` (at most [`BATCH`] positions in the problem's sample) into `b`.
    pub(super) fn stages<S: Copy + Into<u16>>(
        &self,
        pf: &Geom,
        data: &[S],
        ks: std::ops::Range<usize>,
        b: &mut Batch,
    ) {
        #[cfg(target_arch = "x86_64")]
        if self.wide {
            // SAFETY: `wide` is true only on a CPU with AVX2 (see `wide_vectors`), the one
            // requirement of calling a function compiled for it
            #[allow(unsafe_code)]
            return unsafe { self.stages_avx2(pf, data, ks, b) };
        }
        self.stages_body(pf, data, ks, b)
    }

    /// [`PassCtx::stages`] compiled for AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    pub(super) fn stages_avx2<S: Copy + Into<u16>>(
        &self,
        pf: &Geom,
        data: &[S],
        ks: std::ops::Range<usize>,
        b: &mut Batch,
    ) {
        self.stages_body(pf, data, ks, b)
    }

    /// The body of [`PassCtx::stages`] (inlined into both of its builds).
    #[inline(always)]
    pub(super) fn stages_body<S: Copy + Into<u16>>(
        &self,
        pf: &Geom,
        data: &[S],
        ks: std::ops::Range<usize>,
        b: &mut Batch,
    ) {
        let p = self.p;
        let grid = p.grid;
        let g_last = (grid - 1) as f64;
        let g_max = (grid - 2) as f64;
        let m = &pf.m;
        {
            let [rx, ry, rz] = &p.ordered_rays;
            let (rx, ry, rz) = (&rx[ks.clone()], &ry[ks.clone()], &rz[ks.clone()]);
            let (gxs, gys, inside) = (
                &mut b.gx[..rx.len()],
                &mut b.gy[..rx.len()],
                &mut b.inside[..rx.len()],
            );
            // stage 1: the rays' positions on the plane (H^-1 ray, see ray_to_grid)
            for j in 0..rx.len() {
                let r = [rx[j] as f64, ry[j] as f64, rz[j] as f64];
                let w = m[2][0] * r[0] + m[2][1] * r[1] + m[2][2] * r[2];
                let iw = 1.0 / w;
                let gx = (m[0][0] * r[0] + m[0][1] * r[1] + m[0][2] * r[2]) * iw;
                let gy = (m[1][0] * r[0] + m[1][1] * r[1] + m[1][2] * r[2]) * iw;
                // in front of the camera (w = 1 / depth > 0) and inside the grid; NaN fails
                inside[j] = w > 1e-12 && gx >= 0.0 && gy >= 0.0 && gx <= g_last && gy <= g_last;
                gxs[j] = gx;
                gys[j] = gy;
            }
            // stage 2: the observations kept (not saturated, on the plane) and their taps
            let mut n = 0;
            let (order, pix) = (&p.order[ks.clone()], &p.ordered_pix[ks]);
            for (j, (&pos, &px)) in order.iter().zip(pix).enumerate() {
                let k = data[px as usize].into();
                if k == self.top || !b.inside[j] {
                    continue;
                }
                let (gx, gy) = (b.gx[j], b.gy[j]);
                // non-negative: truncation is the floor
                let x0 = gx.min(g_max) as u32 as usize;
                let y0 = gy.min(g_max) as u32 as usize;
                let at = cell(x0, y0, grid);
                b.pos[n] = pos;
                b.k[n] = k;
                b.idx[n] = taps(at, grid).map(|i| i as u32);
                b.frac[n] = [gx - x0 as f64, gy - y0 as f64];
                n += 1;
            }
            b.n = n;
            // stage 3: C there and its gradient
            let c = &self.model.c;
            for j in 0..n {
                let (idx, [fx, fy]) = (b.idx[j], b.frac[j]);
                let c0 = c[idx[0] as usize] as f64;
                let c1 = c[idx[1] as usize] as f64;
                let c2 = c[idx[2] as usize] as f64;
                let c3 = c[idx[3] as usize] as f64;
                let top = c0 + (c1 - c0) * fx;
                let bottom = c2 + (c3 - c2) * fx;
                b.cq[j] = top + (bottom - top) * fy;
                let gx = (c1 - c0) * (1.0 - fy) + (c3 - c2) * fy;
                let gy = bottom - top;
                b.grad2[j] = gx * gx + gy * gy;
            }
        }
    }

    /// The V step's sums of a batch.
    /// `vs` holds the pixels from position `offset` on. With `STATS`, also the per-pixel
    /// counts, the odd frames' sums and the residual statistics (the noise model's fit and
    /// the result need them; the iterations with a fixed noise model do not).
    pub(super) fn v_sums<const STATS: bool>(
        &self,
        i: usize,
        pf: &Geom,
        b: &Batch,
        vs: &mut VSums,
        offset: usize,
    ) {
        let (model, tables, u) = (self.model, self.tables, self.p.u);
        let t = pf.exposure_ms;
        let odd = i % 2 == 1;
        let reg = self.reg2 / (pf.cells_per_px * pf.cells_per_px).max(1e-18);
        let reject = model.reject;
        for j in 0..b.n {
            let pos = b.pos[j] as usize;
            let (cq, vx) = (b.cq[j], model.v[pos]);
            let px = pos - offset;
            let tv = t * vx;
            // (observations where C is 0 count for the C step: it moves C from there)
            if !(tv > 0.0 && cq >= 0.0) {
                continue;
            }
            let tc = t * cq;
            let obs = u[b.k[j] as usize];
            let pred = tc * vx;
            let bin = tables.bin(pred);
            // sensor noise plus the error a misregistration makes where C has edges
            let vr = tables.var[bin] + tv * tv * b.grad2[j] * reg;
            let r = obs - pred;
            if reject && r * r > self.out2 * vr {
                if STATS && cq > 0.0 {
                    vs.outliers += 1;
                }
                continue;
            }
            let w = 1.0 / vr;
            if cq == 0.0 {
                continue;
            }
            let wtc = w * tc;
            vs.num[px] += wtc * obs;
            vs.den[px] += wtc * tc;
            vs.nobs += 1;
            if STATS {
                if odd {
                    vs.num_odd[px] += wtc * obs;
                    vs.den_odd[px] += wtc * tc;
                }
                vs.counts[px] += 1;
                vs.chi2 += r * r * w;
                vs.pred2 += pred * pred;
                vs.res2 += r * r;
                let kp = tables.grey[bin] as usize;
                vs.rss[kp] += (r * tables.inv_slope[bin]).powi(2);
                vs.rcnt[kp] += 1.0;
            }
        }
    }

    /// The C step's sums of a batch (observations where `C` is 0 count too: the step
    /// moves `C` from there).
    pub(super) fn c_sums(&self, pf: &Geom, b: &Batch, acc: &mut JobSums) {
        let reg = self.reg2 / (pf.cells_per_px * pf.cells_per_px).max(1e-18);
        let interleaved = (0..SPLAT_STRIDE).flat_map(|s| (s..b.n).step_by(SPLAT_STRIDE));
        for j in interleaved {
            let vx = self.model.v[b.pos[j] as usize];
            let o = (b.k[j], b.idx[j], b.frac[j], b.cq[j], b.grad2[j]);
            self.c_one(pf.exposure_ms, reg, vx, o, &mut acc.cacc);
        }
    }

    /// One observation's share of the C step: sample `k`, taps `idx` at fractions `frac`,
    /// `C` there and its squared gradient, with `V = vx`.
    #[inline]
    pub(super) fn c_one(
        &self,
        t: f64,
        reg: f64,
        vx: f64,
        (k, idx, [fx, fy], cq, grad2): (u16, [u32; 4], [f64; 2], f64, f64),
        cacc: &mut [[f32; 2]],
    ) {
        let tables = self.tables;
        let tv = t * vx;
        if !(tv > 0.0 && cq >= 0.0) {
            return;
        }
        let obs = self.p.u[k as usize];
        let pred = t * cq * vx;
        let vr = tables.var[tables.bin(pred)] + tv * tv * grad2 * reg;
        let r = obs - pred;
        if self.model.reject && r * r > self.out2 * vr {
            return;
        }
        let w = 1.0 / vr;
        let (num, den) = ((w * tv * r) as f32, (w * tv * tv) as f32);
        let wt = [
            ((1.0 - fx) * (1.0 - fy)) as f32,
            (fx * (1.0 - fy)) as f32,
            ((1.0 - fx) * fy) as f32,
            (fx * fy) as f32,
        ];
        for (&at, wt) in idx.iter().zip(wt) {
            let c = &mut cacc[at as usize];
            c[0] += wt * num;
            c[1] += wt * den;
        }
    }
}

/// The observations of one block of one frame for the iterations whose noise model is
/// fixed ([`PassCtx::dense`]), one entry per position of the block: the first bilinear tap,
/// the fractions between the taps, and what the C step needs (weight times `U`, weight times
/// `C`, and the weight, 0 for a position without an observation).
pub(super) struct Dense {
    pub(super) at: Vec<u32>,
    pub(super) fx: Vec<f64>,
    pub(super) fy: Vec<f64>,
    pub(super) wo: Vec<f32>,
    pub(super) wc: Vec<f32>,
    pub(super) w: Vec<f32>,
    /// The kernel's arrays between its loops (kept here: fresh ones cost a zeroing of 18 KiB
    /// per block and frame).
    pub(super) scratch: Box<Scratch>,
}

/// The arrays between the loops of [`PassCtx::dense`], by position in the block: `C` at the
/// four taps, `U` of the sample, `C` at the position, its squared gradient, the noise bin of
/// the prediction and the variance there.
pub(super) struct Scratch {
    pub(super) taps: [[f64; BATCH]; 4],
    pub(super) obs: [f64; BATCH],
    pub(super) cqs: [f64; BATCH],
    pub(super) grad2s: [f64; BATCH],
    pub(super) bins: [u32; BATCH],
    pub(super) var: [f64; BATCH],
}

impl Dense {
    /// Room for `views` frames of a block of at most [`BATCH`] positions.
    pub(super) fn with_views(views: usize) -> Dense {
        let n = views * BATCH;
        Dense {
            at: vec![0; n],
            fx: vec![0.0; n],
            fy: vec![0.0; n],
            wo: vec![0.0; n],
            wc: vec![0.0; n],
            w: vec![0.0; n],
            scratch: Box::new(Scratch {
                taps: [[0.0; BATCH]; 4],
                obs: [0.0; BATCH],
                cqs: [0.0; BATCH],
                grad2s: [0.0; BATCH],
                bins: [0; BATCH],
                var: [0.0; BATCH],
            }),
        }
    }
}

/// The V step's sums of one block by position in it (the statistics' too, in a pass that
/// takes them).
pub(super) struct BlockSums {
    pub(super) num: Vec<f64>,
    pub(super) den: Vec<f64>,
    pub(super) num_odd: Vec<f64>,
    pub(super) den_odd: Vec<f64>,
    pub(super) counts: Vec<u32>,
}

impl BlockSums {
    pub(super) fn new() -> BlockSums {
        BlockSums {
            num: vec![0.0; BATCH],
            den: vec![0.0; BATCH],
            num_odd: vec![0.0; BATCH],
            den_odd: vec![0.0; BATCH],
            counts: vec![0; BATCH],
        }
    }

    /// Zero for the next block.
    pub(super) fn clear(&mut self) {
        self.num.fill(0.0);
        self.den.fill(0.0);
        self.num_odd.fill(0.0);
        self.den_odd.fill(0.0);
        self.counts.fill(0);
    }
}

impl PassCtx<'_, '_> {
    /// The V step's sums of one block (`ks`, positions of the order) of one frame (`pf`,
    /// its samples `samples` in the block's order) into `blk` (by position in the block),
    /// with `stats` (the pass's sums, and whether the frame is odd) also the statistics; the
    /// observations go to `out` from `slot` on (one entry per position). Returns the number
    /// of observations. The same sums as [`PassCtx::stages`] and [`PassCtx::v_sums`], the
    /// V step's written without branches so that the compiler vectorises them: every
    /// position is computed, and one without an observation weighs 0.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn dense<S: Copy + Into<u16>>(
        &self,
        pf: &Geom,
        samples: &[S],
        ks: std::ops::Range<usize>,
        v_ord: &[f64],
        blk: &mut BlockSums,
        stats: Option<(&mut VSums, bool)>,
        out: &mut Dense,
        slot: usize,
    ) -> u64 {
        #[cfg(target_arch = "x86_64")]
        if self.wide {
            // SAFETY: `wide` is true only on a CPU with AVX2 (see `wide_vectors`), the one
            // requirement of calling a function compiled for it
            #[allow(unsafe_code)]
            return unsafe { self.dense_avx2(pf, samples, ks, v_ord, blk, stats, out, slot) };
        }
        self.dense_body(pf, samples, ks, v_ord, blk, stats, out, slot)
    }

    /// [`PassCtx::dense`] compiled for AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[allow(clippy::too_many_arguments)]
    pub(super) fn dense_avx2<S: Copy + Into<u16>>(
        &self,
        pf: &Geom,
        samples: &[S],
        ks: std::ops::Range<usize>,
        v_ord: &[f64],
        blk: &mut BlockSums,
        stats: Option<(&mut VSums, bool)>,
        out: &mut Dense,
        slot: usize,
    ) -> u64 {
        self.dense_body(pf, samples, ks, v_ord, blk, stats, out, slot)
    }

    /// The first loops of [`PassCtx::dense`]: every position's first (top-left) tap on the
    /// plane grid, `at`, and its fractions, `fxs` and `fys`; a negative `fxs` marks a
    /// position without an observation (off the plane, or a saturated sample).
    #[inline(always)]
    pub(super) fn first_taps<S: Copy + Into<u16>>(
        &self,
        m: &[[f64; 3]; 3],
        [rx, ry, rz]: [&[f32]; 3],
        samples: &[S],
        at: &mut [u32],
        fxs: &mut [f64],
        fys: &mut [f64],
    ) {
        let n = samples.len();
        let grid = self.p.grid;
        let (g_last, g_max) = ((grid - 1) as f64, (grid - 2) as f64);
        // the taps' positions on the plane, and whether they are on it: floating point
        // alone, so that the loop is vectorised
        for j in 0..n {
            let r = [rx[j] as f64, ry[j] as f64, rz[j] as f64];
            let w = m[2][0] * r[0] + m[2][1] * r[1] + m[2][2] * r[2];
            let iw = 1.0 / w;
            let gx = (m[0][0] * r[0] + m[0][1] * r[1] + m[0][2] * r[2]) * iw;
            let gy = (m[1][0] * r[0] + m[1][1] * r[1] + m[1][2] * r[2]) * iw;
            // in front of the camera (w = 1 / depth > 0) and inside the grid; NaN fails.
            // Off the plane: -1, a valid tap weighed 0 below
            let inside = w > 1e-12 && gx >= 0.0 && gy >= 0.0 && gx <= g_last && gy <= g_last;
            fxs[j] = if inside { gx.min(g_max) } else { -1.0 };
            fys[j] = if inside { gy.min(g_max) } else { 0.0 };
        }
        // the first tap and the fractions; saturated samples are no observation either
        let top = self.top;
        for j in 0..n {
            let gx = if samples[j].into() == top {
                -1.0
            } else {
                fxs[j]
            };
            let gy = fys[j];
            let (x0, y0) = (floor_small(gx.max(0.0)), floor_small(gy));
            at[j] = (y0 * grid as i32 + x0) as u32;
            // a negative fraction marks the position without an observation
            fxs[j] = gx - x0 as f64;
            fys[j] = gy - y0 as f64;
        }
    }

    /// The body of [`PassCtx::dense`] (inlined into both of its builds).
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    pub(super) fn dense_body<S: Copy + Into<u16>>(
        &self,
        pf: &Geom,
        samples: &[S],
        ks: std::ops::Range<usize>,
        v_ord: &[f64],
        blk: &mut BlockSums,
        stats: Option<(&mut VSums, bool)>,
        out: &mut Dense,
        slot: usize,
    ) -> u64 {
        let p = self.p;
        let n = ks.len();
        let grid = p.grid;
        let m = &pf.m;
        let [rx, ry, rz] = &p.ordered_rays;
        let (rx, ry, rz) = (&rx[ks.clone()], &ry[ks.clone()], &rz[ks]);
        let samples = &samples[..n];
        let v_ord = &v_ord[..n];
        let (num, den) = (&mut blk.num[..n], &mut blk.den[..n]);
        let range = slot..slot + n;
        let at = &mut out.at[range.clone()];
        let fxs = &mut out.fx[range.clone()];
        let fys = &mut out.fy[range.clone()];
        self.first_taps(m, [rx, ry, rz], samples, at, fxs, fys);
        let c = &self.model.c[..];
        // the four taps of any first tap stay inside C
        let at_max = c.len().saturating_sub(grid + 2);
        let u = self.p.u;
        let u_last = u.len() - 1;
        let tables = self.tables;
        let t = pf.exposure_ms;
        let reg = self.reg2 / (pf.cells_per_px * pf.cells_per_px).max(1e-18);
        let (reject, out2) = (self.model.reject, self.out2);
        let wo = &mut out.wo[range.clone()];
        let wc = &mut out.wc[range.clone()];
        let ws = &mut out.w[range];
        // in four loops, so that the two without table lookups are vectorised: the
        // lookups of C at the taps and of U; C there, its gradient, the prediction and its
        // noise bin; the lookup of the variance; the weights and the sums
        let sc = &mut *out.scratch;
        let [t0, t1, t2, t3] = &mut sc.taps;
        let (t0, t1, t2, t3) = (&mut t0[..n], &mut t1[..n], &mut t2[..n], &mut t3[..n]);
        let obs = &mut sc.obs[..n];
        for j in 0..n {
            if let Some(&ahead) = at.get(j + PREFETCH_AHEAD) {
                prefetch_taps(c, ahead as usize, grid);
            }
            let a = (at[j] as usize).min(at_max);
            t0[j] = c[a] as f64;
            t1[j] = c[a + 1] as f64;
            t2[j] = c[a + grid] as f64;
            t3[j] = c[a + grid + 1] as f64;
            obs[j] = u[(samples[j].into() as usize).min(u_last)];
        }
        let cqs = &mut sc.cqs[..n];
        let grad2s = &mut sc.grad2s[..n];
        let bins = &mut sc.bins[..n];
        for j in 0..n {
            let (fx, fy) = (fxs[j], fys[j]);
            let (c0, c1, c2, c3) = (t0[j], t1[j], t2[j], t3[j]);
            let upper = c0 + (c1 - c0) * fx;
            let lower = c2 + (c3 - c2) * fx;
            let cq = upper + (lower - upper) * fy;
            let gx = (c1 - c0) * (1.0 - fy) + (c3 - c2) * fy;
            let gy = lower - upper;
            cqs[j] = cq;
            grad2s[j] = gx * gx + gy * gy;
            let pred = t * cq * v_ord[j];
            bins[j] = tables.bin(pred) as u32;
        }
        let var = &mut sc.var[..n];
        for j in 0..n {
            // (bins are at most VAR_BINS - 1, a power of two less one: the mask only
            // spares the bounds check)
            var[j] = tables.var[bins[j] as usize & (VAR_BINS - 1)];
        }
        let mut count = 0u64;
        for j in 0..n {
            let (fx, cq, obs) = (fxs[j], cqs[j], obs[j]);
            let vx = v_ord[j];
            let tv = t * vx;
            let tc = t * cq;
            let pred = tc * vx;
            // sensor noise plus the error a misregistration makes where C has edges
            let vr = var[j] + tv * tv * grad2s[j] * reg;
            let r = obs - pred;
            // (observations where C is 0 count for the C step: it moves C from there)
            let kept = fx >= 0.0 && tv > 0.0 && cq >= 0.0 && !(reject && r * r > out2 * vr);
            let w = if kept { 1.0 / vr } else { 0.0 };
            wo[j] = (w * obs) as f32;
            wc[j] = (w * cq) as f32;
            ws[j] = w as f32;
            let wsum = if cq > 0.0 { w } else { 0.0 };
            let wtc = wsum * tc;
            num[j] += wtc * obs;
            den[j] += wtc * tc;
            count += (wsum > 0.0) as u64;
        }
        // the statistics (the noise model's fit and the result need them): the same
        // observations again, one by one (the odd frame's sums, the counts, the outliers and
        // the residuals, whose histogram by grey value is a scatter)
        let Some((vs, odd)) = stats else {
            return count;
        };
        for j in 0..n {
            let (fx, cq, obs) = (fxs[j], cqs[j], obs[j]);
            let vx = v_ord[j];
            let tv = t * vx;
            if !(fx >= 0.0 && tv > 0.0 && cq > 0.0) {
                continue;
            }
            let tc = t * cq;
            let pred = tc * vx;
            let vr = var[j] + tv * tv * grad2s[j] * reg;
            let r = obs - pred;
            if reject && r * r > out2 * vr {
                vs.outliers += 1;
                continue;
            }
            let w = 1.0 / vr;
            let wtc = w * tc;
            if odd {
                blk.num_odd[j] += wtc * obs;
                blk.den_odd[j] += wtc * tc;
            }
            blk.counts[j] += 1;
            vs.chi2 += r * r * w;
            vs.pred2 += pred * pred;
            vs.res2 += r * r;
            let bin = bins[j] as usize & (VAR_BINS - 1);
            let kp = tables.grey[bin] as usize;
            vs.rss[kp] += (r * tables.inv_slope[bin]).powi(2);
            vs.rcnt[kp] += 1.0;
        }
        count
    }

    /// The C step's share of one frame's observations `d[slot .. slot + n]` (exposure `t`)
    /// with the new `V` of their block (`new_v`, by position in the block; the C visit's
    /// `V` as it is), handed to `splats` (which adds them to `cacc` band by band).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn splat_dense(
        &self,
        d: &Dense,
        slot: usize,
        n: usize,
        t: f64,
        new_v: &[f64],
        splats: &mut Splats,
        cacc: &mut [[f32; 2]],
    ) {
        let (at, fx, fy) = (
            &d.at[slot..slot + n],
            &d.fx[slot..slot + n],
            &d.fy[slot..slot + n],
        );
        let (wo, wc, ws) = (
            &d.wo[slot..slot + n],
            &d.wc[slot..slot + n],
            &d.w[slot..slot + n],
        );
        let new_v = &new_v[..n];
        // neighbouring observations share taps: visited a few apart, consecutive updates of
        // one cell do not wait on each other
        for first in 0..SPLAT_STRIDE.min(n) {
            for j in (first..n).step_by(SPLAT_STRIDE) {
                let (w, tv) = (ws[j], t * new_v[j]);
                // (a NaN V fails too)
                if w == 0.0 || tv.is_nan() || tv <= 0.0 {
                    continue;
                }
                // w tV r and w tV^2, with r = U - tV C
                let num = (tv * (wo[j] as f64 - tv * wc[j] as f64)) as f32;
                let den = (w as f64 * tv * tv) as f32;
                let rec = Splat {
                    at: at[j],
                    fx: fx[j] as f32,
                    fy: fy[j] as f32,
                    num,
                    den,
                };
                splats.push(rec, cacc);
            }
        }
    }
}

/// One observation's share of the C step: the first bilinear tap, the fractions, and the
/// numerator and denominator to spread over the four taps.
#[derive(Clone, Copy, Default)]
pub(super) struct Splat {
    pub(super) at: u32,
    pub(super) fx: f32,
    pub(super) fy: f32,
    pub(super) num: f32,
    pub(super) den: f32,
}

/// The C step's splats gathered by band of cells before they are added: the observations
/// of a block come from frames all over the plane, and added at once their updates miss the
/// cache (the plane's sums are megabytes); a band's splats are added together, within a
/// part of the sums that stays in the core's cache.
pub(super) struct Splats {
    pub(super) grid: usize,
    /// Cells per band (a power of two: the band of a cell is `at >> shift`).
    pub(super) shift: u32,
    /// Splats a band holds before they are added.
    pub(super) cap: usize,
    pub(super) pending: Vec<Splat>,
    pub(super) fill: Vec<usize>,
    /// The cells reached so far: the smallest and one past the largest (`(usize::MAX, 0)`:
    /// none).
    pub(super) touched: (usize, usize),
}

/// log2 of the cells per band of [`Splats`] (16384 cells: 128 KiB of sums).
pub(super) const SPLAT_BAND_SHIFT: u32 = 14;

/// Splats a band of [`Splats`] holds (40 KiB; 2.5 MiB for the 62 bands of a 1000x1000 grid).
pub(super) const SPLAT_BAND_CAP: usize = 2048;

impl Splats {
    pub(super) fn new(ncell: usize, grid: usize) -> Splats {
        let bands = (ncell >> SPLAT_BAND_SHIFT) + 1;
        Splats {
            grid,
            shift: SPLAT_BAND_SHIFT,
            cap: SPLAT_BAND_CAP,
            pending: vec![Splat::default(); bands * SPLAT_BAND_CAP],
            fill: vec![0; bands],
            touched: (usize::MAX, 0),
        }
    }

    #[inline]
    pub(super) fn push(&mut self, s: Splat, cacc: &mut [[f32; 2]]) {
        let b = (s.at >> self.shift) as usize;
        let Some(f) = self.fill.get_mut(b) else {
            return;
        };
        let i = *f;
        self.pending[b * self.cap + i] = s;
        *f = i + 1;
        if i + 1 == self.cap {
            self.add(b, cacc);
        }
    }

    /// Adds band `b`'s pending splats to `cacc`.
    pub(super) fn add(&mut self, b: usize, cacc: &mut [[f32; 2]]) {
        let grid = self.grid;
        let n = std::mem::take(&mut self.fill[b]);
        let (mut lo, mut hi) = self.touched;
        let pending = &self.pending[b * self.cap..b * self.cap + n];
        for (i, s) in pending.iter().enumerate() {
            if let Some(ahead) = pending.get(i + PREFETCH_AHEAD) {
                prefetch_taps(cacc, ahead.at as usize, grid);
            }
            let a = s.at as usize;
            lo = lo.min(a);
            hi = hi.max(a + grid + 2);
            // the two taps of a row are neighbours in memory: one update of four values
            for (row, wy) in [(a, 1.0 - s.fy), (a + grid, s.fy)] {
                let (w0, w1) = ((1.0 - s.fx) * wy, s.fx * wy);
                if let Some([p0, p1]) = cacc.get_mut(row..row + 2) {
                    p0[0] += w0 * s.num;
                    p0[1] += w0 * s.den;
                    p1[0] += w1 * s.num;
                    p1[1] += w1 * s.den;
                }
            }
        }
        self.touched = (lo, hi);
    }

    /// Adds every pending splat; returns the range of cells reached.
    pub(super) fn finish(&mut self, cacc: &mut [[f32; 2]]) -> std::ops::Range<usize> {
        for b in 0..self.fill.len() {
            self.add(b, cacc);
        }
        let (lo, hi) = self.touched;
        lo.min(hi)..hi.min(cacc.len())
    }
}

/// What a pass over the store computes.
#[derive(Clone, Copy, PartialEq)]
pub(super) enum Visit {
    /// The V step's sums.
    V,
    /// The C step's sums with `V` as it is.
    C,
    /// One iteration's V step and C step in one visit of the data: the pixels in blocks,
    /// each block over all frames; the block's V step is exact (all its observations are
    /// there), and its observations, kept, give their share of the C step with the block's
    /// new `V`. The sums of a V pass followed by a C pass with the new `V`, at the cost of
    /// one pass, but for two things: the C step weighs the observations and drops outliers
    /// as the V step did, with the `V` before the step (the C step's own, with the new `V`,
    /// differ by the step's change: the same at the solution), and it is done with the
    /// V step's `V` before the gauge is fixed (the same `C` up to the gauge's scale: `C`
    /// comes back unscaled).
    Fused,
}

/// What a job of [`store_pass`] hands back: its pixels' positions, their V step's sums, the
/// C step's numerator and denominator per cell, and the range of cells they reach.
pub(super) type StoreJob = (
    std::ops::Range<usize>,
    VSums,
    Vec<[f32; 2]>,
    std::ops::Range<usize>,
);

/// Adds a job's C step sums to the totals.
pub(super) fn add_cells(num: &mut [f64], den: &mut [f64], cacc: &[[f32; 2]]) {
    for ((n, d), c) in num.iter_mut().zip(den.iter_mut()).zip(cacc) {
        *n += c[0] as f64;
        *d += c[1] as f64;
    }
}

/// A pass over the frames in `store` (see [`Visit`]): the V step's sums (with the
/// statistics when `stats`), and the new `C` of the C step (`model.c` for [`Visit::V`]).
pub(super) fn store_pass(
    p: &Problem<'_>,
    model: &Model,
    tables: &Tables,
    store: &Store,
    visit: Visit,
    stats: bool,
) -> Result<(VSums, Vec<f32>), PhotometricError> {
    let ncell = cells(p.grid);
    let levels = p.u.len();
    let step = if visit == Visit::C { Step::C } else { Step::V };
    let ctx = PassCtx::new(p, model, tables, step, stats);
    let views = &store.views;
    let (npx, cells_needed) = match visit {
        Visit::V => (p.sample.len(), 0),
        Visit::C => (0, ncell),
        Visit::Fused => (p.sample.len(), ncell),
    };
    let mut total = VSums::new(npx, levels);
    let mut num_total = vec![0.0f64; cells_needed];
    let mut den_total = vec![0.0f64; cells_needed];
    // the branch-free kernel ([`PassCtx::dense`]) reads V in the visiting order (the C
    // visit splats its observations with that V)
    let v_ord: Vec<f64> = p.order.iter().map(|&q| model.v[q as usize]).collect();
    fold_frame_jobs(
        &p.jobs,
        |job| -> Result<StoreJob, PhotometricError> {
            let blocks = &p.blocks[job];
            let range = blocks.first().map_or(0, |b| b.start)..blocks.last().map_or(0, |b| b.end);
            let order = &p.order[range.clone()];
            // the positions of the job's pixels (whole bands: a range)
            let start = order.iter().min().map_or(0, |&q| q as usize);
            let end = order.iter().max().map_or(0, |&q| q as usize + 1);
            let mut acc = JobSums {
                v: VSums::new(if npx > 0 { end - start } else { 0 }, levels),
                cacc: vec![[0.0f32; 2]; cells_needed],
            };
            let mut view_order: Vec<(u64, u32)> = Vec::with_capacity(views.len());
            let mut blk = BlockSums::new();
            let mut new_v_blk = vec![0.0f64; BATCH];
            let mut dense = Dense::with_views(if visit == Visit::Fused {
                views.len()
            } else {
                1
            });
            let mut splats = Splats::new(if visit != Visit::V { cells_needed } else { 0 }, p.grid);
            let mut chunk = Chunk::default();
            let job_end = range.end;
            for block in blocks {
                let samples = store.block(block, job_end, &mut chunk)?;
                // the views in the order of where the block lands on the plane (a Morton
                // order of its first pixel's cell tile): neighbouring views gather and splat
                // on neighbouring cells
                let ray = p.rays[p.ordered_pix[block.start] as usize];
                view_order.clear();
                view_order.extend(views.iter().enumerate().map(|(vi, v)| {
                    let key = grid_coords(ray, &v.geom.m, p.grid)
                        .map_or(u64::MAX, |g| morton(g[0] as u32 >> 3, g[1] as u32 >> 3));
                    (key, vi as u32)
                }));
                view_order.sort_unstable();
                let len = block.len();
                blk.clear();
                let v_blk = &v_ord[block.clone()];
                for (vo, &(_, vi)) in view_order.iter().enumerate() {
                    let view = &views[vi as usize];
                    let geom = &view.geom;
                    // (the V step alone needs no observation after its sums)
                    let slot = if visit == Visit::Fused { vo * len } else { 0 };
                    let st = stats.then_some((&mut acc.v, view.i % 2 == 1));
                    let (b, out) = (&mut blk, &mut dense);
                    let nobs = match samples.slice(vi as usize * len..(vi as usize + 1) * len) {
                        SamplesRef::U8(d) => {
                            ctx.dense(geom, d, block.clone(), v_blk, b, st, out, slot)
                        }
                        SamplesRef::U16(d) => {
                            ctx.dense(geom, d, block.clone(), v_blk, b, st, out, slot)
                        }
                    };
                    acc.v.nobs += nobs;
                    if visit == Visit::C {
                        // the C step with V as it is: the view's splats at once
                        let t = geom.exposure_ms;
                        ctx.splat_dense(&dense, 0, len, t, v_blk, &mut splats, &mut acc.cacc);
                    }
                }
                if visit == Visit::C {
                    continue;
                }
                for (j, &q) in p.order[block.clone()].iter().enumerate() {
                    let a = q as usize - start;
                    acc.v.num[a] += blk.num[j];
                    acc.v.den[a] += blk.den[j];
                    if stats {
                        acc.v.num_odd[a] += blk.num_odd[j];
                        acc.v.den_odd[a] += blk.den_odd[j];
                        acc.v.counts[a] += blk.counts[j];
                    }
                }
                if visit == Visit::Fused {
                    // the block's new V (unscaled), and its observations' share of the C step
                    for j in 0..len {
                        new_v_blk[j] = if blk.den[j] > 0.0 {
                            blk.num[j] / blk.den[j]
                        } else {
                            v_blk[j]
                        };
                    }
                    for (vo, &(_, vi)) in view_order.iter().enumerate() {
                        let t = views[vi as usize].geom.exposure_ms;
                        let (d, nv) = (&dense, &new_v_blk);
                        ctx.splat_dense(d, vo * len, len, t, nv, &mut splats, &mut acc.cacc);
                    }
                }
            }
            // the splats say which cells they reached (only those are added to the totals)
            let reached = splats.finish(&mut acc.cacc);
            Ok((start..end, acc.v, acc.cacc, reached))
        },
        |(range, vs, cacc, reached)| {
            if npx > 0 {
                total.add_range(&vs, range.start);
            } else {
                total.add_statistics(&vs);
            }
            let r = reached;
            add_cells(
                &mut num_total[r.clone()],
                &mut den_total[r.clone()],
                &cacc[r],
            );
        },
    )?;
    let c = if cells_needed > 0 {
        c_step(&model.c, &num_total, &den_total)
    } else {
        model.c.clone()
    };
    Ok((total, c))
}

/// The C step's new `C` from its sums per cell: `c + num / den` where a cell has any,
/// at least 0.
pub(super) fn c_step(c: &[f32], num: &[f64], den: &[f64]) -> Vec<f32> {
    c.iter()
        .zip(num)
        .zip(den)
        .map(|((&c, nu), de)| {
            if *de > 0.0 {
                (c as f64 + nu / de).max(0.0) as f32
            } else {
                c
            }
        })
        .collect()
}

/// One pass over the data with `V` and `C` as they are: the sums of the V step (the exact
/// per-pixel least squares with `C` fixed, and the statistics of the residuals) or the new
/// `C` of the C step (a Jacobi step towards the exact bilinear least-squares `C` with `V`
/// fixed: the residuals splatted onto the cells, `c += sum b w tV r / sum b w (tV)^2`).
pub(super) fn pass(
    p: &Problem<'_>,
    model: &Model,
    tables: &Tables,
    step: Step,
    stats: bool,
) -> Result<(VSums, Vec<f32>), PhotometricError> {
    let ncell = cells(p.grid);
    let u = p.u;
    let ctx = PassCtx::new(p, model, tables, step, stats);
    let (npx, cells_needed) = match step {
        Step::V => (p.sample.len(), 0),
        Step::C => (0, ncell),
    };
    let mut total = VSums::new(npx, u.len());
    let mut num_total = vec![0.0f64; cells_needed];
    let mut den_total = vec![0.0f64; cells_needed];
    let sample_bytes = if u.len() > 256 { 2 } else { 1 };
    let jobs = frame_jobs(p.frames.len(), p.size.width * p.size.height * sample_bytes);
    fold_frame_jobs(
        &jobs,
        |range| -> Result<JobSums, PhotometricError> {
            let mut prepared = Vec::with_capacity(range.len());
            for i in range {
                if let Some(pf) = p.prepare(i)? {
                    prepared.push((i, pf));
                }
            }
            let mut acc = JobSums {
                v: VSums::new(npx, u.len()),
                cacc: vec![[0.0f32; 2]; cells_needed],
            };
            let mut batch = Batch::new();
            for start in (0..p.order.len()).step_by(PIXEL_BLOCK) {
                let block = start..(start + PIXEL_BLOCK).min(p.order.len());
                for (i, pf) in &prepared {
                    match &pf.samples {
                        Samples::U8(d) => {
                            ctx.observe(*i, &pf.geom, d, block.clone(), &mut acc, &mut batch)
                        }
                        Samples::U16(d) => {
                            ctx.observe(*i, &pf.geom, d, block.clone(), &mut acc, &mut batch)
                        }
                    }
                }
            }
            Ok(acc)
        },
        |acc| {
            total.add(&acc.v);
            add_cells(&mut num_total, &mut den_total, &acc.cacc);
        },
    )?;
    Ok((total, c_step(&model.c, &num_total, &den_total)))
}
