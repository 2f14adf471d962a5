//! Dense vignette calibration (paper section 2.3.2): alternating minimisation of
//! `E(C, V) = sum_i sum_x (t_i V(x) C(pi_i^-1(x)) - U(I_i(x)))^2` over the plane irradiance `C`
//! (a grid over 5x5 marker widths) and the per-pixel vignette `V`, with bilinear sampling and
//! splatting on the plane grid. Frames are streamed: memory does not grow with their number.

use camera_model::{CameraModel, Image, ImageSize};
use rayon::prelude::*;

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
    /// Stop when the relative energy change falls below this.
    pub tolerance: f64,
    /// Plane grid resolution (cells per side).
    pub grid: usize,
    /// Plane grid side in marker widths.
    pub extent: f64,
    /// In the second half of the iterations, observations whose residual exceeds this fraction
    /// of the prediction are dropped as outliers.
    pub outlier: f64,
    /// Pixels with fewer observations are invalid (0 in the map).
    pub min_observations: u32,
    /// Standard deviation (pixels) of the smoothing for the smoothed map.
    pub smooth_sigma: f64,
    /// Over-relaxation factor of the V update (1 = plain alternation).
    pub relaxation: f64,
}

impl Default for VignetteOptions {
    fn default() -> Self {
        VignetteOptions {
            max_iterations: 8,
            tolerance: 1e-5,
            grid: 1000,
            extent: 5.0,
            outlier: 0.15,
            min_observations: 8,
            smooth_sigma: 3.0,
            relaxation: 1.8,
        }
    }
}

/// The result of [`calibrate_vignette`].
#[derive(Clone, Debug)]
pub struct VignetteCalibration {
    /// The vignette, scaled so that the smoothed map has maximum 1; NaN where invalid.
    pub vignette: Image<f32>,
    /// The smoothed vignette (normalised Gaussian smoothing of the valid pixels).
    pub smoothed: Image<f32>,
    /// Observations per pixel in the last iteration.
    pub counts: Image<u32>,
    /// Fraction of pixels with a valid value.
    pub coverage: f64,
    /// Iterations run.
    pub iterations: usize,
    /// Whether the tolerance was reached.
    pub converged: bool,
    /// Relative residual `sqrt(sum (U - t V C)^2 / sum (t V C)^2)` in the last iteration.
    pub rms_relative: f64,
    /// Energy per iteration.
    pub energy: Vec<f64>,
}

/// The per-frame map from a viewing ray to homogeneous plane-grid coordinates: with
/// `H = [r1 r2 t]` (the plane-to-camera homography of `camera_from_plane`), `H^-1 ray` is
/// `(x, y, 1) / lambda`; composed with the affine map to grid cells (cell centres at
/// integers, y up on the plane and down in the grid).
fn ray_to_grid(pose: &PlanePose, grid: usize, extent: f64) -> Option<[[f64; 3]; 3]> {
    let r = &pose.r;
    let h = [
        [r[0][0], r[0][1], pose.t[0]],
        [r[1][0], r[1][1], pose.t[1]],
        [r[2][0], r[2][1], pose.t[2]],
    ];
    let det = h[0][0] * (h[1][1] * h[2][2] - h[1][2] * h[2][1])
        - h[0][1] * (h[1][0] * h[2][2] - h[1][2] * h[2][0])
        + h[0][2] * (h[1][0] * h[2][1] - h[1][1] * h[2][0]);
    if !det.is_finite() || det.abs() < 1e-12 {
        return None;
    }
    let inv = [
        [
            (h[1][1] * h[2][2] - h[1][2] * h[2][1]) / det,
            (h[0][2] * h[2][1] - h[0][1] * h[2][2]) / det,
            (h[0][1] * h[1][2] - h[0][2] * h[1][1]) / det,
        ],
        [
            (h[1][2] * h[2][0] - h[1][0] * h[2][2]) / det,
            (h[0][0] * h[2][2] - h[0][2] * h[2][0]) / det,
            (h[0][2] * h[1][0] - h[0][0] * h[1][2]) / det,
        ],
        [
            (h[1][0] * h[2][1] - h[1][1] * h[2][0]) / det,
            (h[0][1] * h[2][0] - h[0][0] * h[2][1]) / det,
            (h[0][0] * h[1][1] - h[0][1] * h[1][0]) / det,
        ],
    ];
    // gx = (x / extent + 0.5) g - 0.5, gy = (0.5 - y / extent) g - 0.5
    let g = grid as f64;
    let (sx, ox) = (g / extent, 0.5 * g - 0.5);
    let mut m = [[0.0; 3]; 3];
    for k in 0..3 {
        m[0][k] = sx * inv[0][k] + ox * inv[2][k];
        m[1][k] = -sx * inv[1][k] + ox * inv[2][k];
        m[2][k] = inv[2][k];
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

/// Bilinear taps `(storage index, weight)` of grid position `g`.
#[inline]
fn taps(g: [f64; 2], grid: usize) -> [(usize, f64); 4] {
    // g is non-negative: truncation is the floor
    let x0 = (g[0] as usize).min(grid - 2);
    let y0 = (g[1] as usize).min(grid - 2);
    let (fx, fy) = (g[0] - x0 as f64, g[1] - y0 as f64);
    [
        (cell(x0, y0, grid), (1.0 - fx) * (1.0 - fy)),
        (cell(x0 + 1, y0, grid), fx * (1.0 - fy)),
        (cell(x0, y0 + 1, grid), (1.0 - fx) * fy),
        (cell(x0 + 1, y0 + 1, grid), fx * fy),
    ]
}

fn add_into(a: &mut [f64], b: &[f64]) {
    for (x, y) in a.iter_mut().zip(b) {
        *x += y;
    }
}

/// Normalised Gaussian smoothing of the finite values of `img` (NaN elsewhere stays NaN
/// only where no finite value lies within three sigma).
pub fn smooth_masked(img: &Image<f32>, sigma: f64) -> Image<f32> {
    let (w, h) = img.size();
    if sigma <= 0.0 {
        return img.clone();
    }
    let r = (3.0 * sigma).ceil() as usize;
    let kernel: Vec<f64> = (0..=2 * r)
        .map(|i| {
            let d = i as f64 - r as f64;
            (-0.5 * d * d / (sigma * sigma)).exp()
        })
        .collect();
    let val: Vec<f64> = img
        .data()
        .iter()
        .map(|v| if v.is_finite() { *v as f64 } else { 0.0 })
        .collect();
    let wt: Vec<f64> = img
        .data()
        .iter()
        .map(|v| if v.is_finite() { 1.0 } else { 0.0 })
        .collect();
    let pass = |src: &[f64], horizontal: bool| -> Vec<f64> {
        let mut out = vec![0.0; w * h];
        out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
            for (x, o) in row.iter_mut().enumerate() {
                let mut s = 0.0;
                for (k, kv) in kernel.iter().enumerate() {
                    let off = k as isize - r as isize;
                    let (xx, yy) = if horizontal {
                        (x as isize + off, y as isize)
                    } else {
                        (x as isize, y as isize + off)
                    };
                    if xx >= 0 && yy >= 0 && (xx as usize) < w && (yy as usize) < h {
                        s += kv * src[yy as usize * w + xx as usize];
                    }
                }
                *o = s;
            }
        });
        out
    };
    let v = pass(&pass(&val, true), false);
    let c = pass(&pass(&wt, true), false);
    let data = v
        .iter()
        .zip(&c)
        .map(|(a, b)| if *b > 1e-6 { (a / b) as f32 } else { f32::NAN })
        .collect();
    Image::new(w, h, data).unwrap_or_else(|_| img.clone())
}

/// Calibrates the vignette of `camera` (raw images of `size`) from frames of a plane with
/// known poses, given the inverse response.
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
    let npx = w * h;
    let grid = options.grid.max(2);
    let rays: Vec<[f32; 3]> = (0..npx)
        .into_par_iter()
        .map(|i| {
            camera
                .unproject([(i % w) as f64, (i / w) as f64])
                .map_or([f32::NAN; 3], |r| [r[0] as f32, r[1] as f32, r[2] as f32])
        })
        .collect();
    let u = response.values();
    let mut v = vec![1.0f64; npx];
    let mut c = vec![0.0f32; cells(grid)];
    let mut energy_hist = Vec::new();
    let mut prev = f64::INFINITY;
    let mut converged = false;
    let mut iterations = 0;
    let mut counts = vec![0u32; npx];
    let mut rms_rel = 0.0;
    let chunk = frames
        .len()
        .div_ceil(rayon::current_num_threads().max(1))
        .max(1);
    // phase 1 without outlier rejection until converged or half the iterations; phase 2 with
    let mut reject = false;
    for it in 0..options.max_iterations.max(1) {
        iterations = it + 1;
        if !reject && it >= options.max_iterations / 2 && it > 0 {
            reject = true;
            prev = f64::INFINITY;
        }
        // C step: splat t V U and (t V)^2 onto the plane grid
        let c_acc = (0..frames.len())
            .into_par_iter()
            .with_min_len(chunk)
            .try_fold(
                || vec![[0.0f32; 2]; cells(grid)],
                |mut acc, i| -> Result<_, PhotometricError> {
                    let f = frames.frame(i)?;
                    check_frame(&f, size)?;
                    let t = f.exposure_ms;
                    let Some(m) = ray_to_grid(&f.pose, grid, options.extent) else {
                        return Ok(acc);
                    };
                    // C has far fewer unknowns than there are observations: half of the
                    // pixels (a checkerboard whose parity alternates with frame and
                    // iteration) determine it as well and halve this pass
                    let data = f.image.data();
                    let pixels = (0..h).flat_map(|y| {
                        let first = (y + i + it) % 2;
                        (first..w).step_by(2).map(move |x| y * w + x)
                    });
                    for p in pixels {
                        let k = data[p];
                        if k == 255 {
                            continue;
                        }
                        let Some(g) = grid_coords(rays[p], &m, grid) else {
                            continue;
                        };
                        let tv = t * v[p];
                        let obs = u[k as usize];
                        let tp = taps(g, grid);
                        if reject {
                            let pred: f64 =
                                tp.iter().map(|(j, wgt)| wgt * c[*j] as f64).sum::<f64>() * tv;
                            if (obs - pred).abs() > options.outlier * pred.abs() {
                                continue;
                            }
                        }
                        let (a, b) = ((tv * obs) as f32, (tv * tv) as f32);
                        for (j, wgt) in tp {
                            let e = &mut acc[j];
                            e[0] += wgt as f32 * a;
                            e[1] += wgt as f32 * b;
                        }
                    }
                    Ok(acc)
                },
            )
            .try_reduce(
                || vec![[0.0f32; 2]; cells(grid)],
                |mut a, b| {
                    for (x, y) in a.iter_mut().zip(&b) {
                        x[0] += y[0];
                        x[1] += y[1];
                    }
                    Ok(a)
                },
            )?;
        let c_prev = std::mem::take(&mut c);
        c = c_acc
            .iter()
            .zip(&c_prev)
            .map(|(nd, old)| if nd[1] > 1e-12 { nd[0] / nd[1] } else { *old })
            .collect();
        // V step: per pixel, with bilinear samples of C; energy with the previous V
        let v_acc = (0..frames.len())
            .into_par_iter()
            .with_min_len(chunk)
            .try_fold(
                || {
                    (
                        vec![0.0f64; npx],
                        vec![0.0f64; npx],
                        vec![0u32; npx],
                        0.0f64,
                        0.0f64,
                        0u64,
                    )
                },
                |(mut num, mut den, mut cnt, mut e, mut rel2, mut nobs),
                 i|
                 -> Result<_, PhotometricError> {
                    let f = frames.frame(i)?;
                    let t = f.exposure_ms;
                    let Some(m) = ray_to_grid(&f.pose, grid, options.extent) else {
                        return Ok((num, den, cnt, e, rel2, nobs));
                    };
                    for (p, &k) in f.image.data().iter().enumerate() {
                        if k == 255 {
                            continue;
                        }
                        let Some(g) = grid_coords(rays[p], &m, grid) else {
                            continue;
                        };
                        let cq: f64 = taps(g, grid)
                            .iter()
                            .map(|(j, wgt)| wgt * c[*j] as f64)
                            .sum();
                        if cq <= 0.0 {
                            continue;
                        }
                        let obs = u[k as usize];
                        let pred = t * v[p] * cq;
                        let r = obs - pred;
                        if reject && r.abs() > options.outlier * pred.abs() {
                            continue;
                        }
                        e += r * r;
                        // sum of squared predictions: the relative RMS without a division
                        rel2 += pred * pred;
                        nobs += 1;
                        num[p] += t * cq * obs;
                        den[p] += t * cq * t * cq;
                        cnt[p] += 1;
                    }
                    Ok((num, den, cnt, e, rel2, nobs))
                },
            )
            .try_reduce(
                || {
                    (
                        vec![0.0f64; npx],
                        vec![0.0f64; npx],
                        vec![0u32; npx],
                        0.0,
                        0.0,
                        0,
                    )
                },
                |mut a, b| {
                    add_into(&mut a.0, &b.0);
                    add_into(&mut a.1, &b.1);
                    for (x, y) in a.2.iter_mut().zip(&b.2) {
                        *x += y;
                    }
                    Ok((a.0, a.1, a.2, a.3 + b.3, a.4 + b.4, a.5 + b.5))
                },
            )?;
        let (num, den, cnt, energy, rel2, nobs) = v_acc;
        if nobs == 0 {
            return Err(PhotometricError::Calibration(
                "no pixel of any frame sees the calibration plane".into(),
            ));
        }
        // over-relaxed update: the alternation creeps along the weakly constrained smooth
        // mode shared by V and C; stepping past the block optimum speeds that up
        let omega = if it == 0 { 1.0 } else { options.relaxation };
        for p in 0..npx {
            if den[p] > 0.0 {
                let ls = num[p] / den[p];
                v[p] += omega * (ls - v[p]);
            }
        }
        // gauge: mean V over observed pixels = 1 (C absorbs the scale)
        let (sum, n_obs) = v
            .iter()
            .zip(&cnt)
            .filter(|(_, c)| **c > 0)
            .fold((0.0, 0usize), |(s, n), (x, _)| (s + x, n + 1));
        let mean = if n_obs > 0 { sum / n_obs as f64 } else { 1.0 };
        if mean > 0.0 {
            for x in v.iter_mut() {
                *x /= mean;
            }
            for x in c.iter_mut() {
                *x *= mean as f32;
            }
        }
        counts = cnt;
        rms_rel = (energy / rel2.max(1e-300)).sqrt();
        energy_hist.push(energy);
        progress(iterations, energy);
        if (prev - energy).abs() / energy.max(1e-300) < options.tolerance {
            if reject {
                converged = true;
                break;
            }
            // phase 1 converged: continue with outlier rejection
            reject = true;
            prev = f64::INFINITY;
            continue;
        }
        prev = energy;
    }
    let valid = |p: usize| counts[p] >= options.min_observations;
    let raw = Image::new(
        w,
        h,
        (0..npx)
            .map(|p| if valid(p) { v[p] as f32 } else { f32::NAN })
            .collect(),
    )?;
    let smoothed = smooth_masked(&raw, options.smooth_sigma);
    let max = smoothed
        .data()
        .iter()
        .zip(raw.data())
        .filter(|(_, r)| r.is_finite())
        .map(|(s, _)| *s)
        .fold(0.0f32, f32::max);
    if max <= 0.0 {
        return Err(PhotometricError::Calibration(
            "no pixel has enough observations; record the plane from more viewpoints".into(),
        ));
    }
    let vignette = raw.map(|x| x / max);
    let smoothed = smoothed.map(|x| x / max);
    let n_valid = (0..npx).filter(|&p| valid(p)).count();
    Ok(VignetteCalibration {
        vignette,
        smoothed,
        counts: Image::new(w, h, counts)?,
        coverage: n_valid as f64 / npx as f64,
        iterations,
        converged,
        rms_relative: rms_rel,
        energy: energy_hist,
    })
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
