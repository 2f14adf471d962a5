//! Dense vignette calibration (paper section 2.3.2): `V` from a video of a planar, matte
//! surface whose pose is known in every frame (from one ArUco marker, or given).
//!
//! The model is the paper's, `U(I_i(x)) = t_i V(x) C(pi_i(x)) + noise`, with the plane
//! irradiance `C` on a grid over the plane (bilinear) and one `V` per pixel, fitted to
//! convergence on all the data:
//!
//! * **Weighted by the noise of every observation**: the variance of `U(I)` follows the
//!   sensor (`read + shot U + adc U'^2`, fitted to the residuals) plus the error that a small
//!   misregistration of the plane makes where `C` changes quickly (marker edges, texture).
//!   Observations far beyond their noise are dropped once the fit has settled.
//! * **Solved to convergence**: block updates of `V` (exact per pixel) and of `C` (a Jacobi
//!   step on the exact bilinear least-squares problem), accelerated by Anderson mixing,
//!   until the relative change of `V` is below the tolerance. Frames are streamed: memory
//!   does not grow with their number.
//! * **Observable or refused**: the pixel-cell graph (two unknowns joined when one observation
//!   links them) must be connected, else the scale of `V` differs between its parts and the
//!   paper's argument for a unique solution fails; image corners the plane never covers are
//!   refused, not invented.
//! * **The paper's map and the one to use**: the raw, unregularised per-pixel map, and a
//!   smoothed map whose smoothing is chosen by cross-validation between the maps of the odd
//!   and of the even frames (see [`crate::smoothing`]).
//! * **With its uncertainty**: per pixel, from the normal equations with the residual scale
//!   checked against the odd/even difference, for both maps.

use camera_model::{CameraModel, Image, ImageSize};
use rayon::prelude::*;

use crate::noise::{fit_noise, NoiseModel};
use crate::smoothing::{choose_smoothing, SmoothingChoice};
use crate::{InverseResponse, PhotometricError};

/// A `camera_from_plane` pose: `point_in_camera = r * point_in_plane + t`, the plane being
/// `z = 0` with the marker the unit square at its origin.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlanePose {
    /// Rotation, row-major.
    pub r: [[f64; 3]; 3],
    /// Translation.
    pub t: [f64; 3],
}

/// One frame of a vignette calibration.
#[derive(Clone, Debug)]
pub struct PlaneFrame {
    /// The raw 8-bit image.
    pub image: Image<u8>,
    /// Exposure in ms.
    pub exposure_ms: f64,
    /// Its plane pose.
    pub pose: PlanePose,
}

/// Where the frames come from (decoded on demand, possibly many times).
pub trait PlaneFrames: Sync {
    /// Number of frames.
    fn len(&self) -> usize;
    /// Whether there is no frame.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Frame `i`.
    fn frame(&self, i: usize) -> Result<PlaneFrame, PhotometricError>;
}

/// Options of [`calibrate_vignette`].
#[derive(Clone, Debug)]
pub struct VignetteOptions {
    /// Iteration limit.
    pub max_iterations: usize,
    /// Stop when the RMS relative change of `V` between iterations is below this.
    pub tolerance: f64,
    /// Plane grid resolution (cells per side).
    pub grid: usize,
    /// Plane grid side in marker widths.
    pub extent: f64,
    /// Once the fit has settled, observations beyond this many noise standard deviations
    /// are dropped as outliers.
    pub outlier_sigmas: f64,
    /// Pixels with fewer observations are invalid in the raw map.
    pub min_observations: u32,
    /// Uncertainty of the plane registration in pixels: where `C` changes quickly, a shift
    /// of this size adds to an observation's error.
    pub registration_px: f64,
    /// Smoothing of the recommended map (standard deviation in pixels); `None` chooses it by
    /// cross-validation.
    pub smoothing_px: Option<f64>,
    /// The marker and this margin around it (marker widths) are left out: its black and
    /// white cells are the sharpest edges on the plane, where the smallest misregistration
    /// makes the largest error. `None` uses the marker too.
    pub marker_margin: Option<f64>,
}

impl Default for VignetteOptions {
    fn default() -> Self {
        VignetteOptions {
            max_iterations: 100,
            tolerance: 2e-5,
            grid: 1000,
            extent: 5.0,
            outlier_sigmas: 5.0,
            min_observations: 8,
            registration_px: 0.25,
            smoothing_px: None,
            marker_margin: None,
        }
    }
}

/// The result of [`calibrate_vignette`].
#[derive(Clone, Debug)]
pub struct VignetteCalibration {
    /// The map recommended for correction: the raw map smoothed as chosen, `max = 1`, finite
    /// everywhere.
    pub vignette: Image<f32>,
    /// The paper's unregularised per-pixel map on the same scale; NaN where a pixel has too
    /// few observations or is defective (hot or dead: far from its neighbourhood in the maps
    /// of both the odd and the even frames).
    pub raw: Image<f32>,
    /// Standard error of `vignette` per pixel.
    pub std_error: Image<f32>,
    /// Standard error of `raw` per pixel (NaN where `raw` is).
    pub raw_std_error: Image<f32>,
    /// Observations per pixel (the coverage).
    pub counts: Image<u32>,
    /// Fraction of pixels with at least `min_observations`.
    pub coverage: f64,
    /// The smoothing of `vignette` and how it was chosen.
    pub smoothing: SmoothingChoice,
    /// Iterations run.
    pub iterations: usize,
    /// Whether the tolerance was reached.
    pub converged: bool,
    /// RMS relative change of `V` per iteration.
    pub change: Vec<f64>,
    /// Relative residual `sqrt(sum (U - t V C)^2 / sum (t V C)^2)`.
    pub rms_relative: f64,
    /// The fitted noise model.
    pub noise: NoiseModel,
    /// Observations dropped as outliers in the last iteration.
    pub outliers: u64,
    /// Connected parts of the pixel-cell graph (1 when the problem is observable).
    pub components: usize,
    /// Things the user should know.
    pub warnings: Vec<String>,
}

/// The per-frame map from a viewing ray to homogeneous plane-grid coordinates: with
/// `H = [r1 r2 t]` (the plane-to-camera homography of `camera_from_plane`), `H^-1 ray` is
/// `(x, y, 1) / lambda`; composed with the affine map to grid cells (cell centres at
/// integers, y up on the plane and down in the grid).
fn ray_to_grid(pose: &PlanePose, grid: usize, extent: f64) -> Option<[[f64; 3]; 3]> {
    let r = &pose.r;
    let h = nalgebra::Matrix3::new(
        r[0][0], r[0][1], pose.t[0], r[1][0], r[1][1], pose.t[1], r[2][0], r[2][1], pose.t[2],
    );
    let inv = h.try_inverse()?;
    if !inv.iter().all(|v| v.is_finite()) {
        return None;
    }
    // gx = (x / extent + 0.5) g - 0.5, gy = (0.5 - y / extent) g - 0.5
    let g = grid as f64;
    let (sx, ox) = (g / extent, 0.5 * g - 0.5);
    let mut m = [[0.0; 3]; 3];
    for k in 0..3 {
        m[0][k] = sx * inv[(0, k)] + ox * inv[(2, k)];
        m[1][k] = -sx * inv[(1, k)] + ox * inv[(2, k)];
        m[2][k] = inv[(2, k)];
    }
    Some(m)
}

/// Plane grid coordinates of a ray through the frame's [`ray_to_grid`] matrix, if the ray
/// hits the plane in front of the camera inside the grid.
#[inline]
fn grid_coords(ray: [f32; 3], m: &[[f64; 3]; 3], grid: usize) -> Option<[f64; 2]> {
    let r = [ray[0] as f64, ray[1] as f64, ray[2] as f64];
    let w = m[2][0] * r[0] + m[2][1] * r[1] + m[2][2] * r[2];
    // w = 1 / lambda: positive in front of the camera (NaN rays fail too)
    if w.is_nan() || w <= 1e-12 {
        return None;
    }
    let iw = 1.0 / w;
    let gx = (m[0][0] * r[0] + m[0][1] * r[1] + m[0][2] * r[2]) * iw;
    let gy = (m[1][0] * r[0] + m[1][1] * r[1] + m[1][2] * r[2]) * iw;
    let g = (grid - 1) as f64;
    (gx >= 0.0 && gy >= 0.0 && gx <= g && gy <= g).then_some([gx, gy])
}

/// Storage index of grid cell `(x, y)`: 8x8 tiles, so that the oblique walks of projected
/// image rows over the plane stay in cache.
#[inline]
fn cell(x: usize, y: usize, grid: usize) -> usize {
    let tiles_x = grid.div_ceil(8);
    (((y >> 3) * tiles_x + (x >> 3)) << 6) + ((y & 7) << 3) + (x & 7)
}

/// Number of stored cells of a `grid x grid` plane (tiles padded to 8).
fn cells(grid: usize) -> usize {
    grid.div_ceil(8) * grid.div_ceil(8) * 64
}

/// The bilinear taps of grid position `g`: storage indices and weights, and the fractions.
#[inline]
fn taps(g: [f64; 2], grid: usize) -> ([usize; 4], [f64; 4], f64, f64) {
    // g is non-negative: truncation is the floor
    let x0 = (g[0] as usize).min(grid - 2);
    let y0 = (g[1] as usize).min(grid - 2);
    let (fx, fy) = (g[0] - x0 as f64, g[1] - y0 as f64);
    (
        [
            cell(x0, y0, grid),
            cell(x0 + 1, y0, grid),
            cell(x0, y0 + 1, grid),
            cell(x0 + 1, y0 + 1, grid),
        ],
        [
            (1.0 - fx) * (1.0 - fy),
            fx * (1.0 - fy),
            (1.0 - fx) * fy,
            fx * fy,
        ],
        fx,
        fy,
    )
}

/// One frame prepared for the passes.
struct Prepared {
    frame: PlaneFrame,
    m: [[f64; 3]; 3],
    /// Grid cells per pixel at the image centre (scales the registration error).
    cells_per_px: f64,
}

/// What every pass needs.
struct Problem<'a> {
    frames: &'a dyn PlaneFrames,
    /// Grid coordinates of the left-out square around the marker (`lo`, `hi`; empty when
    /// `lo > hi`).
    exclude: (f64, f64),
    rays: Vec<[f32; 3]>,
    size: ImageSize,
    u: [f64; 256],
    options: &'a VignetteOptions,
    grid: usize,
}

impl Problem<'_> {
    /// Whether a grid position is in the left-out square around the marker.
    #[inline]
    fn excluded(&self, g: [f64; 2]) -> bool {
        g[0] >= self.exclude.0
            && g[0] <= self.exclude.1
            && g[1] >= self.exclude.0
            && g[1] <= self.exclude.1
    }

    fn prepare(&self, i: usize) -> Result<Option<Prepared>, PhotometricError> {
        let frame = self.frames.frame(i)?;
        check_frame(&frame, self.size)?;
        let Some(m) = ray_to_grid(&frame.pose, self.grid, self.options.extent) else {
            return Ok(None);
        };
        let (w, h) = (self.size.width, self.size.height);
        let c = (h / 2) * w + w / 2;
        let cells_per_px = match (
            grid_coords(self.rays[c], &m, self.grid),
            grid_coords(self.rays[c + 1], &m, self.grid),
        ) {
            (Some(a), Some(b)) => ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt(),
            _ => 1.0,
        };
        Ok(Some(Prepared {
            frame,
            m,
            cells_per_px,
        }))
    }
}

/// The model's state: `V` per pixel, `C` per cell, the noise model and the outlier switch.
struct Model {
    v: Vec<f64>,
    c: Vec<f32>,
    noise: NoiseModel,
    reject: bool,
}

/// The variance of an observation predicted at `pred` (U-units) whose bilinear sample of `C`
/// has gradient magnitude `grad` per cell: sensor noise plus registration error.
#[inline]
fn obs_variance(var_table: &[f64], var_scale: f64, pred: f64, tv: f64, grad: f64, reg: f64) -> f64 {
    let k = ((pred * var_scale) as usize).min(var_table.len() - 1);
    let g = tv * grad * reg;
    var_table[k] + g * g
}

/// Sums of the V step.
struct VSums {
    num: Vec<f64>,
    den: Vec<f64>,
    /// By frame parity, for cross-validation.
    num_odd: Vec<f64>,
    den_odd: Vec<f64>,
    counts: Vec<u32>,
    /// Residual statistics per predicted grey value (for the noise model), U-units squared
    /// scaled to grey levels.
    rss: Vec<f64>,
    rcnt: Vec<f64>,
    /// Weighted squared residuals (normalised), sum of squared predictions and residuals.
    chi2: f64,
    nobs: u64,
    pred2: f64,
    res2: f64,
    outliers: u64,
}

impl VSums {
    fn new(npx: usize) -> VSums {
        VSums {
            num: vec![0.0; npx],
            den: vec![0.0; npx],
            num_odd: vec![0.0; npx],
            den_odd: vec![0.0; npx],
            counts: vec![0; npx],
            rss: vec![0.0; 256],
            rcnt: vec![0.0; 256],
            chi2: 0.0,
            nobs: 0,
            pred2: 0.0,
            res2: 0.0,
            outliers: 0,
        }
    }

    fn add(&mut self, o: &VSums) {
        for (a, b) in self.num.iter_mut().zip(&o.num) {
            *a += b;
        }
        for (a, b) in self.den.iter_mut().zip(&o.den) {
            *a += b;
        }
        for (a, b) in self.num_odd.iter_mut().zip(&o.num_odd) {
            *a += b;
        }
        for (a, b) in self.den_odd.iter_mut().zip(&o.den_odd) {
            *a += b;
        }
        for (a, b) in self.counts.iter_mut().zip(&o.counts) {
            *a += b;
        }
        for k in 0..256 {
            self.rss[k] += o.rss[k];
            self.rcnt[k] += o.rcnt[k];
        }
        self.chi2 += o.chi2;
        self.nobs += o.nobs;
        self.pred2 += o.pred2;
        self.res2 += o.res2;
        self.outliers += o.outliers;
    }
}

/// The variance table of the noise model over the energy (U-units), `VAR_BINS` bins up to
/// `U(255)`.
const VAR_BINS: usize = 1024;

fn variance_table(u: &[f64; 256], noise: &NoiseModel) -> (Vec<f64>, f64) {
    let top = u[255].max(1e-9);
    let scale = (VAR_BINS - 1) as f64 / top;
    let table = (0..VAR_BINS)
        .map(|b| noise.energy_variance(u, b as f64 / scale))
        .collect();
    (table, scale)
}

/// Parallel jobs of a pass over the frames: consecutive frames share their accumulators.
const FRAME_JOBS: usize = 8;

/// The frames of each job: a partition of the frames that does not depend on the number of
/// threads, so that every sum is taken in the same order with any number of threads.
fn frame_jobs(n: usize) -> Vec<std::ops::Range<usize>> {
    let jobs = FRAME_JOBS.clamp(1, n.max(1));
    let per = n.div_ceil(jobs);
    (0..jobs)
        .map(|j| (j * per).min(n)..((j + 1) * per).min(n))
        .filter(|r| !r.is_empty())
        .collect()
}

/// Runs `job` on the frames of every job of [`frame_jobs`], as many at a time as there are
/// threads, and hands the results to `add` in the order of the jobs: the same bits with one
/// thread or many, and at most one job's accumulators per thread in memory.
fn fold_frame_jobs<T: Send>(
    n: usize,
    job: impl Fn(std::ops::Range<usize>) -> Result<T, PhotometricError> + Sync,
    mut add: impl FnMut(T),
) -> Result<(), PhotometricError> {
    let jobs = frame_jobs(n);
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

/// The C step. As the paper (`jacobi = false`): each cell's irradiance is the weighted
/// average of what the observations splatted onto it say, `c = sum b w tV U(I) / sum b w
/// (tV)^2` (`b` the bilinear weights): a slightly blurred `C`. With `jacobi`, the same splat
/// of the residuals corrects the current `C` (`c += sum b w tV r / sum b w (tV)^2`), a Jacobi
/// step that converges, with the iteration, to the exact bilinear least-squares `C`.
fn c_step(
    p: &Problem<'_>,
    model: &Model,
    var: &(Vec<f64>, f64),
    jacobi: bool,
) -> Result<Vec<f32>, PhotometricError> {
    let ncell = cells(p.grid);
    let reg = p.options.registration_px;
    let grid = p.grid;
    let mut num_total = vec![0.0f64; ncell];
    let mut den_total = vec![0.0f64; ncell];
    fold_frame_jobs(
        p.frames.len(),
        |range| -> Result<(Vec<f32>, Vec<f32>), PhotometricError> {
            let mut num = vec![0.0f32; ncell];
            let mut den = vec![0.0f32; ncell];
            for i in range {
                let Some(pf) = p.prepare(i)? else {
                    continue;
                };
                let t = pf.frame.exposure_ms;
                for (px, &k) in pf.frame.image.data().iter().enumerate() {
                    if k == 255 {
                        continue;
                    }
                    let Some(g) = grid_coords(p.rays[px], &pf.m, grid) else {
                        continue;
                    };
                    let (idx, wt, fx, fy) = taps(g, grid);
                    let cs = [
                        model.c[idx[0]] as f64,
                        model.c[idx[1]] as f64,
                        model.c[idx[2]] as f64,
                        model.c[idx[3]] as f64,
                    ];
                    let cq = wt[0] * cs[0] + wt[1] * cs[1] + wt[2] * cs[2] + wt[3] * cs[3];
                    let tv = t * model.v[px];
                    if tv.is_nan() || tv <= 0.0 {
                        continue;
                    }
                    let obs = p.u[k as usize];
                    let pred = tv * cq;
                    let gx = (cs[1] - cs[0]) * (1.0 - fy) + (cs[3] - cs[2]) * fy;
                    let gy = (cs[2] - cs[0]) * (1.0 - fx) + (cs[3] - cs[1]) * fx;
                    let grad = (gx * gx + gy * gy).sqrt() / pf.cells_per_px.max(1e-9);
                    let vr = obs_variance(&var.0, var.1, pred.max(0.0), tv, grad, reg);
                    if model.reject && (obs - pred).powi(2) > p.options.outlier_sigmas.powi(2) * vr
                    {
                        continue;
                    }
                    let target = if jacobi { obs - pred } else { obs };
                    let (a, b) = (tv * target / vr, tv * tv / vr);
                    for j in 0..4 {
                        num[idx[j]] += (wt[j] * a) as f32;
                        den[idx[j]] += (wt[j] * b) as f32;
                    }
                }
            }
            Ok((num, den))
        },
        |(num, den)| {
            for (t, v) in num_total.iter_mut().zip(&num) {
                *t += *v as f64;
            }
            for (t, v) in den_total.iter_mut().zip(&den) {
                *t += *v as f64;
            }
        },
    )?;
    let mut c = model.c.clone();
    for ((cj, nu), de) in c.iter_mut().zip(&num_total).zip(&den_total) {
        if *de > 0.0 {
            let base = if jacobi { *cj as f64 } else { 0.0 };
            *cj = (base + nu / de).max(0.0) as f32;
        }
    }
    Ok(c)
}

/// The V step: `V(x) = sum w tC U(I) / sum w (tC)^2` per pixel with `C` fixed, and the
/// statistics of the residuals.
fn v_step(
    p: &Problem<'_>,
    model: &Model,
    var: &(Vec<f64>, f64),
) -> Result<VSums, PhotometricError> {
    let npx = p.rays.len();
    let reg = p.options.registration_px;
    let u = &p.u;
    let mut total = VSums::new(npx);
    fold_frame_jobs(
        p.frames.len(),
        |range| -> Result<VSums, PhotometricError> {
            let mut acc = VSums::new(npx);
            for i in range {
                let Some(pf) = p.prepare(i)? else {
                    continue;
                };
                let t = pf.frame.exposure_ms;
                let odd = i % 2 == 1;
                for (px, &k) in pf.frame.image.data().iter().enumerate() {
                    if k == 255 {
                        continue;
                    }
                    let Some(g) = grid_coords(p.rays[px], &pf.m, p.grid) else {
                        continue;
                    };
                    if p.excluded(g) {
                        continue;
                    }
                    let (idx, wt, fx, fy) = taps(g, p.grid);
                    let cs = [
                        model.c[idx[0]] as f64,
                        model.c[idx[1]] as f64,
                        model.c[idx[2]] as f64,
                        model.c[idx[3]] as f64,
                    ];
                    let cq = wt[0] * cs[0] + wt[1] * cs[1] + wt[2] * cs[2] + wt[3] * cs[3];
                    if cq.is_nan() || cq <= 0.0 {
                        continue;
                    }
                    let tc = t * cq;
                    let obs = u[k as usize];
                    let vx = model.v[px];
                    let pred = tc * vx;
                    let gx = (cs[1] - cs[0]) * (1.0 - fy) + (cs[3] - cs[2]) * fy;
                    let gy = (cs[2] - cs[0]) * (1.0 - fx) + (cs[3] - cs[1]) * fx;
                    let grad = (gx * gx + gy * gy).sqrt() / pf.cells_per_px.max(1e-9);
                    let vr = obs_variance(&var.0, var.1, pred.max(0.0), t * vx, grad, reg);
                    let r = obs - pred;
                    if model.reject && r * r > p.options.outlier_sigmas.powi(2) * vr {
                        acc.outliers += 1;
                        continue;
                    }
                    let w = 1.0 / vr;
                    acc.num[px] += w * tc * obs;
                    acc.den[px] += w * tc * tc;
                    if odd {
                        acc.num_odd[px] += w * tc * obs;
                        acc.den_odd[px] += w * tc * tc;
                    }
                    acc.counts[px] += 1;
                    acc.chi2 += r * r * w;
                    acc.nobs += 1;
                    acc.pred2 += pred * pred;
                    acc.res2 += r * r;
                    // residual in grey levels by predicted grey value (for the noise model)
                    let kp = u.partition_point(|&x| x <= pred).clamp(1, 255);
                    let slope = (u[kp] - u[kp - 1]).max(1e-9);
                    acc.rss[kp] += (r / slope).powi(2);
                    acc.rcnt[kp] += 1.0;
                }
            }
            Ok(acc)
        },
        |part| total.add(&part),
    )?;
    Ok(total)
}

/// Union-find over pixels and plane cells, on 8x8 pixel blocks and 8x8 cell tiles: the
/// number of connected parts of the observation graph that hold observed pixels.
fn components(p: &Problem<'_>) -> Result<(usize, Vec<u32>), PhotometricError> {
    let (w, h) = (p.size.width, p.size.height);
    let (bw, bh) = (w.div_ceil(8), h.div_ceil(8));
    let tiles = p.grid.div_ceil(8);
    let nodes = bw * bh + tiles * tiles;
    let mut parent: Vec<u32> = (0..nodes as u32).collect();
    fn find(parent: &mut [u32], mut a: u32) -> u32 {
        while parent[a as usize] != a {
            let up = parent[parent[a as usize] as usize];
            parent[a as usize] = up;
            a = up;
        }
        a
    }
    let mut seen = vec![false; bw * bh];
    for i in 0..p.frames.len() {
        let Some(pf) = p.prepare(i)? else {
            continue;
        };
        for by in 0..bh {
            for bx in 0..bw {
                let (x, y) = ((bx * 8 + 4).min(w - 1), (by * 8 + 4).min(h - 1));
                let px = y * w + x;
                if pf.frame.image.data()[px] == 255 {
                    continue;
                }
                if let Some(g) = grid_coords(p.rays[px], &pf.m, p.grid) {
                    let cnode = (bw * bh + (g[1] as usize / 8) * tiles + g[0] as usize / 8) as u32;
                    let pnode = (by * bw + bx) as u32;
                    seen[by * bw + bx] = true;
                    let (ra, rb) = (find(&mut parent, pnode), find(&mut parent, cnode));
                    if ra != rb {
                        parent[ra as usize] = rb;
                    }
                }
            }
        }
    }
    let mut roots = std::collections::BTreeMap::new();
    let mut label = vec![u32::MAX; bw * bh];
    for b in 0..bw * bh {
        if seen[b] {
            let r = find(&mut parent, b as u32);
            let n = roots.len() as u32;
            label[b] = *roots.entry(r).or_insert(n);
        }
    }
    Ok((roots.len(), label))
}

/// Iterations Anderson mixing remembers.
const ANDERSON_MEMORY: usize = 5;

/// Anderson mixing of the fixed-point iteration on `V` (memory `m`): the next iterate
/// combines the last ones so that the combined residual is smallest.
struct Anderson {
    m: usize,
    xs: Vec<Vec<f64>>,
    fs: Vec<Vec<f64>>,
}

impl Anderson {
    fn new(m: usize) -> Anderson {
        Anderson {
            m,
            xs: Vec::new(),
            fs: Vec::new(),
        }
    }

    /// Given the iterate `x` and its image `gx` under the iteration, the next iterate.
    fn step(&mut self, x: &[f64], gx: &[f64]) -> Vec<f64> {
        let f: Vec<f64> = gx.iter().zip(x).map(|(a, b)| a - b).collect();
        self.xs.push(x.to_vec());
        self.fs.push(f.clone());
        if self.xs.len() > self.m + 1 {
            self.xs.remove(0);
            self.fs.remove(0);
        }
        let n = self.fs.len();
        if n < 2 {
            return gx.to_vec();
        }
        // differences of residuals; least squares for the mixing coefficients
        let k = n - 1;
        let df: Vec<Vec<f64>> = (0..k)
            .map(|j| {
                self.fs[j + 1]
                    .iter()
                    .zip(&self.fs[j])
                    .map(|(a, b)| a - b)
                    .collect()
            })
            .collect();
        let mut ata = nalgebra::DMatrix::<f64>::zeros(k, k);
        let mut atb = nalgebra::DVector::<f64>::zeros(k);
        for a in 0..k {
            for b in a..k {
                let d: f64 = df[a].iter().zip(&df[b]).map(|(p, q)| p * q).sum();
                ata[(a, b)] = d;
                ata[(b, a)] = d;
            }
            atb[a] = df[a].iter().zip(&f).map(|(p, q)| p * q).sum();
        }
        let scale = (0..k).map(|a| ata[(a, a)]).fold(0.0, f64::max).max(1e-300);
        for a in 0..k {
            ata[(a, a)] += 1e-10 * scale;
        }
        let Some(gamma) = ata.cholesky().map(|c| c.solve(&atb)) else {
            self.xs.clear();
            self.fs.clear();
            return gx.to_vec();
        };
        // x_next = gx - sum gamma_j (dx_j + df_j), dx_j the differences of the iterates
        let mut out = gx.to_vec();
        for j in 0..k {
            let gj = gamma[j];
            if gj == 0.0 || !gj.is_finite() {
                continue;
            }
            for ((o, (x1, x0)), (f1, f0)) in out
                .iter_mut()
                .zip(self.xs[j + 1].iter().zip(&self.xs[j]))
                .zip(self.fs[j + 1].iter().zip(&self.fs[j]))
            {
                *o -= gj * ((x1 - x0) + (f1 - f0));
            }
        }
        out
    }

    fn reset(&mut self) {
        self.xs.clear();
        self.fs.clear();
    }
}

/// Calibrates the vignette of `camera` (raw images of `size`) from frames of a plane with
/// known poses, given the inverse response. `progress` is called after every iteration with
/// its number and the RMS relative change of `V`.
pub fn calibrate_vignette(
    camera: &CameraModel,
    size: ImageSize,
    response: &InverseResponse,
    frames: &dyn PlaneFrames,
    options: &VignetteOptions,
    progress: &(dyn Fn(usize, f64) + Sync),
) -> Result<VignetteCalibration, PhotometricError> {
    if frames.is_empty() {
        return Err(PhotometricError::Calibration(
            "vignette calibration needs at least one frame with a plane pose".into(),
        ));
    }
    let (w, h) = (size.width, size.height);
    if w < 2 || h < 2 {
        return Err(PhotometricError::Calibration(format!(
            "the images are {w}x{h}; vignette calibration needs at least 2x2 pixels"
        )));
    }
    let npx = w * h;
    let grid = options.grid.max(8);
    let rays: Vec<[f32; 3]> = (0..npx)
        .into_par_iter()
        .map(|i| {
            camera
                .unproject([(i % w) as f64, (i / w) as f64])
                .map_or([f32::NAN; 3], |r| [r[0] as f32, r[1] as f32, r[2] as f32])
        })
        .collect();
    let g = grid as f64;
    let exclude = match options.marker_margin {
        Some(m) => {
            let half = 0.5 + m.max(0.0);
            // gx = (x / extent + 0.5) g - 0.5
            (
                (-half / options.extent + 0.5) * g - 0.5,
                (half / options.extent + 0.5) * g - 0.5,
            )
        }
        None => (1.0, 0.0),
    };
    let problem = Problem {
        frames,
        exclude,
        rays,
        size,
        u: *response.values(),
        options,
        grid,
    };
    // observability: one connected part, image corners covered
    let (parts, labels) = components(&problem)?;
    if parts == 0 {
        return Err(PhotometricError::Calibration(
            "no pixel of any frame sees the calibration plane".into(),
        ));
    }
    let mut warnings = Vec::new();
    let mut outside: Vec<bool> = Vec::new();
    if parts > 1 {
        let (bw, bh) = (w.div_ceil(8), h.div_ceil(8));
        let mut sizes = vec![0usize; parts];
        for &l in &labels {
            if l != u32::MAX {
                sizes[l as usize] += 1;
            }
        }
        let observed: usize = sizes.iter().sum();
        let (big, largest) =
            sizes.iter().enumerate().fold(
                (0usize, 0usize),
                |b, (i, &s)| if s > b.1 { (i, s) } else { b },
            );
        let frac = largest as f64 / observed.max(1) as f64;
        if frac < 0.5 {
            return Err(PhotometricError::Calibration(format!(
                "the observations fall into {parts} unconnected parts (the largest holds {:.0}% of the observed image): V is then determined only up to a separate scale in each part; film the wall so that every image region sees plane areas that other regions see too (move and turn the camera, not only the plane)",
                100.0 * frac
            )));
        }
        // pixels outside the largest part: their scale is unknown, they count as unobserved
        outside = (0..npx)
            .map(|i| {
                let b = (i / w / 8) * bw + (i % w) / 8;
                labels[b] != big as u32
            })
            .collect();
        let _ = bh;
        warnings.push(format!(
            "{:.1}% of the observed image is not connected to the rest (it sees no plane area that the rest sees); it is filled from its neighbourhood",
            100.0 * (1.0 - frac)
        ));
    }
    let u = *response.values();
    let mut model = Model {
        v: vec![1.0; npx],
        c: vec![0.0; cells(grid)],
        noise: NoiseModel {
            read: 1.0,
            shot: 0.1,
            adc: 1.0,
        },
        reject: false,
    };
    // start: C from V = 1 by the paper's splat
    let mut var = variance_table(&u, &model.noise);
    model.c = c_step(&problem, &model, &var, false)?;
    let mut anderson = Anderson::new(ANDERSON_MEMORY);
    let mut change = Vec::new();
    let mut converged = false;
    let mut iterations = 0;
    let ncell = model.c.len();
    const SETTLE: usize = 4;
    for it in 0..options.max_iterations.max(1) {
        iterations = it + 1;
        // V step with the current C
        let vs = v_step(&problem, &model, &var)?;
        if vs.nobs == 0 {
            return Err(PhotometricError::Calibration(
                "no pixel of any frame sees the calibration plane".into(),
            ));
        }
        let mut gv = model.v.clone();
        for (p, g) in gv.iter_mut().enumerate().take(npx) {
            if vs.den[p] > 0.0 {
                *g = vs.num[p] / vs.den[p];
            }
        }
        // the gauge: mean V over observed pixels = 1 (C absorbs the scale)
        let (sum, n) = gv
            .iter()
            .zip(&vs.den)
            .filter(|(_, d)| **d > 0.0)
            .fold((0.0, 0usize), |(s, n), (v, _)| (s + v, n + 1));
        let mean = if n > 0 { sum / n as f64 } else { 1.0 };
        for x in gv.iter_mut() {
            *x /= mean;
        }
        // C step (a Jacobi step towards the exact least squares) with the new V
        let old_v = std::mem::replace(&mut model.v, gv);
        let mut gc = c_step(&problem, &model, &var, true)?;
        for c in gc.iter_mut() {
            *c *= mean as f32;
        }
        // Anderson mixing of the whole iteration (V and C together)
        let mut x: Vec<f64> = old_v.clone();
        x.extend(model.c.iter().map(|&c| c as f64 * mean));
        let mut g: Vec<f64> = model.v.clone();
        g.extend(gc.iter().map(|&c| c as f64));
        let next = if it >= 1 { anderson.step(&x, &g) } else { g };
        let (nv, nc) = next.split_at(npx);
        let mut new_v: Vec<f64> = nv.to_vec();
        for (v, d) in new_v.iter_mut().zip(&vs.den) {
            if !(v.is_finite() && *v > 0.0) || *d <= 0.0 {
                *v = if *d > 0.0 { 1e-3 } else { 1.0 };
            }
        }
        let new_c: Vec<f32> = (0..ncell).map(|j| nc[j].max(0.0) as f32).collect();
        let (s2, n2) = new_v
            .iter()
            .zip(&old_v)
            .zip(&vs.den)
            .filter(|(_, d)| **d > 0.0)
            .fold((0.0, 0usize), |(s, n), ((a, b), _)| {
                (s + ((a - b) / b).powi(2), n + 1)
            });
        let delta = (s2 / n2.max(1) as f64).sqrt();
        model.v = new_v;
        model.c = new_c;
        change.push(delta);
        progress(iterations, delta);
        if std::env::var_os("MONOVO_DEBUG").is_some() {
            eprintln!(
                "it {it} delta {delta:.3e} mean {mean:.4} chi2/n {:.3} rel {:.4} out {}",
                vs.chi2 / vs.nobs as f64,
                (vs.res2 / vs.pred2).sqrt(),
                vs.outliers
            );
        }
        // the noise model follows the residuals; outliers go once the fit has settled
        if let Some(nm) = fit_noise(&u, &vs.rss, &vs.rcnt) {
            model.noise = nm;
            var = variance_table(&u, &model.noise);
        }
        if it + 1 == SETTLE {
            model.reject = true;
            anderson.reset();
        }
        if it + 1 > SETTLE && delta < options.tolerance {
            converged = true;
            break;
        }
    }
    // the final statistics with the final V and C
    let vs = v_step(&problem, &model, &var)?;
    finish(
        &problem,
        model,
        vs,
        Solved {
            iterations,
            converged,
            change,
            outside,
            components: parts,
        },
        warnings,
    )
}

/// How the solver ended.
struct Solved {
    iterations: usize,
    converged: bool,
    change: Vec<f64>,
    /// Pixels outside the largest connected part (empty: all connected).
    outside: Vec<bool>,
    components: usize,
}

/// Normalisation, the odd/even maps, the uncertainty, the smoothing and the checks of the
/// result.
fn finish(
    p: &Problem<'_>,
    model: Model,
    vs: VSums,
    solved: Solved,
    mut warnings: Vec<String>,
) -> Result<VignetteCalibration, PhotometricError> {
    let Solved {
        iterations,
        converged,
        change,
        outside,
        components,
    } = solved;
    let (w, h) = (p.size.width, p.size.height);
    let npx = w * h;
    let min_obs = p.options.min_observations.max(1);
    let valid: Vec<bool> = (0..npx)
        .map(|i| {
            vs.counts[i] >= min_obs && vs.den[i] > 0.0 && !outside.get(i).copied().unwrap_or(false)
        })
        .collect();
    let n_valid = valid.iter().filter(|v| **v).count();
    let coverage = n_valid as f64 / npx as f64;
    if n_valid == 0 {
        return Err(PhotometricError::Calibration(format!(
            "no pixel has {min_obs} observations of the plane; record the plane from more viewpoints"
        )));
    }
    // the corners: a corner the plane never covers cannot be calibrated
    let (cw, ch) = ((w / 20).max(1), (h / 20).max(1));
    for (name, x0, y0) in [
        ("top-left", 0, 0),
        ("top-right", w - cw, 0),
        ("bottom-left", 0, h - ch),
        ("bottom-right", w - cw, h - ch),
    ] {
        let any = (y0..y0 + ch).any(|y| (x0..x0 + cw).any(|x| valid[y * w + x]));
        if !any {
            return Err(PhotometricError::Calibration(format!(
                "the {name} corner of the image ({cw}x{ch} pixels) never sees the plane often enough ({min_obs} observations per pixel): the vignette there cannot be determined; film the wall so that it also fills that corner"
            )));
        }
    }
    if coverage < 0.98 {
        warnings.push(format!(
            "only {:.1}% of the pixels have at least {min_obs} observations; the recommended map fills the rest by smoothing",
            100.0 * coverage
        ));
    }
    // per-pixel maps: the estimate, the odd and even frames' maps, and the information
    let raw: Vec<f64> = (0..npx)
        .map(|i| if valid[i] { model.v[i] } else { f64::NAN })
        .collect();
    let half = |num: &dyn Fn(usize) -> f64, den: &dyn Fn(usize) -> f64| -> Vec<f64> {
        (0..npx)
            .map(|i| {
                let d = den(i);
                if valid[i] && d > 0.0 {
                    num(i) / d
                } else {
                    f64::NAN
                }
            })
            .collect()
    };
    let odd = half(&|i| vs.num_odd[i], &|i| vs.den_odd[i]);
    let even = half(&|i| vs.num[i] - vs.num_odd[i], &|i| {
        vs.den[i] - vs.den_odd[i]
    });
    // variance of V per pixel from the normal equations (1 / sum w (tC)^2), with the scale
    // of the residuals checked against the odd/even difference
    let info: Vec<f64> = vs.den.clone();
    let info_odd = vs.den_odd.clone();
    let info_even: Vec<f64> = (0..npx).map(|i| vs.den[i] - vs.den_odd[i]).collect();
    let mut ratio_sum = 0.0;
    let mut ratio_n = 0usize;
    for i in 0..npx {
        if odd[i].is_finite() && even[i].is_finite() && info_odd[i] > 0.0 && info_even[i] > 0.0 {
            let d = odd[i] - even[i];
            ratio_sum += d * d / (1.0 / info_odd[i] + 1.0 / info_even[i]);
            ratio_n += 1;
        }
    }
    let kappa = if ratio_n > 100 {
        (ratio_sum / ratio_n as f64).max(1e-6)
    } else {
        1.0
    };
    let raw_var: Vec<f64> = (0..npx)
        .map(|i| if valid[i] { kappa / info[i] } else { f64::NAN })
        .collect();
    let choice = choose_smoothing(w, h, &raw, &raw_var, &odd, &even, p.options.smoothing_px)?;
    // scale: the recommended map's maximum is 1
    let max = choice
        .smoothed
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .fold(0.0f64, f64::max);
    if max.is_nan() || max <= 0.0 {
        return Err(PhotometricError::Calibration(
            "the smoothed vignette is zero everywhere; the data do not determine V".into(),
        ));
    }
    // the maximum of a noisy map sits on a noise excursion: the peak of a quadratic fitted
    // around it says by how much, and that scale uncertainty is common to every pixel
    let peak = fitted_peak(
        w,
        h,
        &choice.smoothed,
        &choice.smoothed_std,
        choice.choice.sigma_px,
    );
    let norm_rel = match peak {
        Some((value, sd)) => ((max - value).powi(2) + sd * sd).sqrt() / max,
        None => 0.0,
    };
    let smoothed_std: Vec<f64> = choice
        .smoothed
        .iter()
        .zip(&choice.smoothed_std)
        .map(|(v, s)| (s * s + (norm_rel * v).powi(2)).sqrt())
        .collect();
    let to_img = |v: &[f64], s: f64| -> Result<Image<f32>, PhotometricError> {
        Ok(Image::new(
            w,
            h,
            v.iter().map(|x| (x / s) as f32).collect(),
        )?)
    };
    let vignette = to_img(&choice.smoothed, max)?;
    let std_error = to_img(&smoothed_std, max)?;
    // the raw map leaves out what it cannot say: defective pixels (hot, dead) are NaN there
    // like pixels with too few observations
    let raw: Vec<f64> = (0..npx)
        .map(|i| {
            if choice.defective[i] {
                f64::NAN
            } else {
                raw[i]
            }
        })
        .collect();
    let raw_img = to_img(&raw, max)?;
    let raw_std: Vec<f64> = (0..npx)
        .map(|i| {
            if raw[i].is_finite() {
                (raw_var[i] + (norm_rel * raw[i]).powi(2)).sqrt()
            } else {
                f64::NAN
            }
        })
        .collect();
    let raw_std_error = to_img(&raw_std, max)?;
    let rms_relative = (vs.res2 / vs.pred2.max(1e-300)).sqrt();
    Ok(VignetteCalibration {
        vignette,
        raw: raw_img,
        std_error,
        raw_std_error,
        counts: Image::new(w, h, vs.counts.clone())?,
        coverage,
        smoothing: choice.choice,
        iterations,
        converged,
        change,
        rms_relative,
        noise: model.noise,
        outliers: vs.outliers,
        components,
        warnings,
    })
}

/// The peak of a quadratic surface fitted (weights `1 / sd^2`) to `map` within a disk around
/// its maximum, and the peak's standard error (the pixels of a map smoothed with
/// `sigma_px` share their noise over about `4 pi sigma^2` pixels): the maximum of the
/// underlying smooth map.
fn fitted_peak(w: usize, h: usize, map: &[f64], sd: &[f64], sigma_px: f64) -> Option<(f64, f64)> {
    let (imax, _) = map.iter().enumerate().filter(|(_, v)| v.is_finite()).fold(
        (0usize, f64::NEG_INFINITY),
        |b, (i, &v)| if v > b.1 { (i, v) } else { b },
    );
    let (cx, cy) = ((imax % w) as f64, (imax / w) as f64);
    let r = (w.min(h) as f64 / 10.0).max(6.0);
    let mut ata = nalgebra::SMatrix::<f64, 6, 6>::zeros();
    let mut atb = nalgebra::SVector::<f64, 6>::zeros();
    let (x0, x1) = ((cx - r).max(0.0) as usize, ((cx + r) as usize).min(w - 1));
    let (y0, y1) = ((cy - r).max(0.0) as usize, ((cy + r) as usize).min(h - 1));
    for y in y0..=y1 {
        for x in x0..=x1 {
            let (dx, dy) = ((x as f64 - cx) / r, (y as f64 - cy) / r);
            let i = y * w + x;
            if dx * dx + dy * dy > 1.0 || !map[i].is_finite() || sd[i].is_nan() || sd[i] <= 0.0 {
                continue;
            }
            let f = nalgebra::SVector::<f64, 6>::from([1.0, dx, dy, dx * dx, dx * dy, dy * dy]);
            let wt = 1.0 / (sd[i] * sd[i]);
            ata += f * f.transpose() * wt;
            atb += f * (wt * map[i]);
        }
    }
    let inv = ata.try_inverse()?;
    let c = inv * atb;
    // the vertex of the quadratic, kept inside the disk
    let hm = nalgebra::Matrix2::new(2.0 * c[3], c[4], c[4], 2.0 * c[5]);
    let g = nalgebra::Vector2::new(-c[1], -c[2]);
    let mut v = hm
        .try_inverse()
        .map_or(nalgebra::Vector2::zeros(), |hi| hi * g);
    if v.norm() > 1.0 {
        v /= v.norm();
    }
    let f =
        nalgebra::SVector::<f64, 6>::from([1.0, v[0], v[1], v[0] * v[0], v[0] * v[1], v[1] * v[1]]);
    let value = (f.transpose() * c)[(0, 0)];
    // the fit's variance, scaled by the neighbours' correlation (the smoothed map's pixels
    // are not independent: about the kernel's area shares one noise)
    let area = (4.0 * std::f64::consts::PI * sigma_px * sigma_px).max(1.0);
    let var = (f.transpose() * inv * f)[(0, 0)] * area;
    (value.is_finite() && var >= 0.0).then_some((value, var.sqrt()))
}

fn check_frame(f: &PlaneFrame, size: ImageSize) -> Result<(), PhotometricError> {
    if f.image.size() != (size.width, size.height) {
        return Err(PhotometricError::SizeMismatch {
            what: "a calibration frame",
            width: size.width,
            height: size.height,
            got_width: f.image.width(),
            got_height: f.image.height(),
        });
    }
    if !(f.exposure_ms.is_finite() && f.exposure_ms > 0.0) {
        return Err(PhotometricError::Exposure(f.exposure_ms));
    }
    Ok(())
}
