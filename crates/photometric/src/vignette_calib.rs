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
//!   until the relative change of `V` (over the pixels that are not defective) is below the
//!   tolerance, or below a small fraction of the raw map's standard error (the iteration's
//!   error is then far below the noise's).
//!   Frames are streamed: memory does not grow with their number.
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
use crate::smoothing::{choose_smoothing, find_defects, SmoothingChoice};
use crate::{InverseResponse, PhotometricError};

/// A `camera_from_plane` pose: `point_in_camera = r * point_in_plane + t`, the plane being
/// `z = 0` with the marker the unit square at its origin.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PlanePose {
    /// Rotation, row-major.
    pub r: [[f64; 3]; 3],
    /// Translation.
    pub t: [f64; 3],
}

/// The raw samples of a calibration frame.
#[derive(Clone, Debug)]
pub enum PlaneImage {
    /// 8-bit samples; `U` is the inverse response at the 256 grey values
    /// ([`InverseResponse::values`]).
    U8(Image<u8>),
    /// Samples of `bits` bits (8 to 16): the values `0 ..= 2^bits - 1` in the low bits of
    /// 16-bit samples; `U` is the response table for that depth
    /// ([`InverseResponse::table_for_bits`]: the table itself when it has `2^bits` values).
    U16 {
        /// The samples.
        image: Image<u16>,
        /// Bits per sample.
        bits: u32,
    },
}

impl PlaneImage {
    /// Width and height.
    pub fn size(&self) -> (usize, usize) {
        match self {
            PlaneImage::U8(i) => i.size(),
            PlaneImage::U16 { image, .. } => image.size(),
        }
    }

    /// Bits per sample.
    pub fn bits(&self) -> u32 {
        match self {
            PlaneImage::U8(_) => 8,
            PlaneImage::U16 { bits, .. } => *bits,
        }
    }
}

impl From<Image<u8>> for PlaneImage {
    fn from(image: Image<u8>) -> Self {
        PlaneImage::U8(image)
    }
}

/// One frame of a vignette calibration.
#[derive(Clone, Debug)]
pub struct PlaneFrame {
    /// The raw image (8-bit, or deeper samples in 16 bits).
    pub image: PlaneImage,
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
    /// A new, empty file, read and written at offsets, for the frames' samples when they do
    /// not fit in [`VignetteOptions::memory_mb`] (one byte per pixel and frame, two above 8
    /// bits): the iterations then read them from it instead of decoding the frames on every
    /// pass, faster at the same memory. The calibration only reads and writes it; whoever
    /// makes it sees that it is removed (an unlinked file, say). `Ok(None)`, the default:
    /// none, decode on every pass.
    fn scratch(&self) -> std::io::Result<Option<std::fs::File>> {
        Ok(None)
    }
}

/// Options of [`calibrate_vignette`].
///
/// Deserialised fields that are absent keep their defaults; unknown ones are an error.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct VignetteOptions {
    /// Iteration limit.
    pub max_iterations: usize,
    /// Stop when the RMS relative change of `V` between iterations is below this.
    pub tolerance: f64,
    /// Stop as well when the RMS relative change of `V` is below this fraction of the
    /// median standard error of the raw (per-pixel) map: the error left by the iteration is
    /// then far below the statistical one (0: only `tolerance` decides).
    pub noise_tolerance: f64,
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
    /// The frames' samples are kept in memory for the iterations when they fit in this many
    /// MiB (one byte per pixel and frame, two above 8 bits); beyond, in the scratch file of
    /// [`PlaneFrames::scratch`], or where the source has none, every pass decodes the frames
    /// again. Either way memory does not grow with their number (0: never in memory).
    pub memory_mb: usize,
}

impl Default for VignetteOptions {
    fn default() -> Self {
        VignetteOptions {
            max_iterations: 100,
            tolerance: 2e-5,
            noise_tolerance: 0.03,
            grid: 1000,
            extent: 5.0,
            outlier_sigmas: 5.0,
            min_observations: 8,
            registration_px: 0.25,
            smoothing_px: None,
            memory_mb: 80,
        }
    }
}

impl VignetteOptions {
    /// Refuses options outside the values they can take (a config file or a caller may give
    /// anything): what [`calibrate_vignette`] checks before any work. The plane grid is at
    /// most 4096 cells a side (the paper's is 1000; the memory grows with its square).
    pub fn check(&self) -> Result<(), PhotometricError> {
        let bad = |name, value: String, expected| {
            Err(PhotometricError::InvalidOption {
                name,
                value,
                expected,
            })
        };
        let non_negative = |v: f64| v.is_finite() && v >= 0.0;
        if !(1..=crate::response_calib::MAX_ITERATIONS_LIMIT).contains(&self.max_iterations) {
            return bad(
                "max_iterations",
                self.max_iterations.to_string(),
                "1 to 100000 iterations",
            );
        }
        if !non_negative(self.tolerance) {
            return bad(
                "tolerance",
                self.tolerance.to_string(),
                "a finite relative change, 0 or more",
            );
        }
        if !non_negative(self.noise_tolerance) || self.noise_tolerance > 1.0 {
            return bad(
                "noise_tolerance",
                self.noise_tolerance.to_string(),
                "a fraction of the standard error from 0 to 1",
            );
        }
        if !(8..=4096).contains(&self.grid) {
            return bad("grid", self.grid.to_string(), "8 to 4096 cells per side");
        }
        if !self.extent.is_finite() || self.extent <= 0.0 {
            return bad(
                "extent",
                self.extent.to_string(),
                "a finite number of marker widths above 0",
            );
        }
        if self.outlier_sigmas.is_nan() || self.outlier_sigmas <= 0.0 {
            return bad(
                "outlier_sigmas",
                self.outlier_sigmas.to_string(),
                "a number of standard deviations above 0",
            );
        }
        if !non_negative(self.registration_px) {
            return bad(
                "registration_px",
                self.registration_px.to_string(),
                "a finite number of pixels, 0 or more",
            );
        }
        if let Some(s) = self.smoothing_px {
            if !non_negative(s) || s > 1000.0 {
                return bad("smoothing_px", s.to_string(), "0 to 1000 pixels");
            }
        }
        Ok(())
    }
}

/// The result of [`calibrate_vignette`].
#[derive(Clone, Debug, serde::Serialize)]
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

/// Storage index of grid cell `(x, y)`: row by row (the passes visit the pixels in small
/// tiles whose footprint on the plane is a few rows of cells).
#[inline]
fn cell(x: usize, y: usize, grid: usize) -> usize {
    y * grid + x
}

/// Number of stored cells of a `grid x grid` plane.
fn cells(grid: usize) -> usize {
    grid * grid
}

/// The storage indices of the four bilinear taps whose first is `at` (see [`cell`]): the
/// neighbours in x, in y and in both.
#[inline]
fn taps(at: usize, grid: usize) -> [usize; 4] {
    [at, at + 1, at + grid, at + grid + 1]
}

/// The Morton (Z-order) index of `(x, y)`: near cells get near indices.
fn morton(x: u32, y: u32) -> u64 {
    let spread = |v: u32| {
        let mut v = v as u64 & 0xffff_ffff;
        v = (v | (v << 16)) & 0x0000_ffff_0000_ffff;
        v = (v | (v << 8)) & 0x00ff_00ff_00ff_00ff;
        v = (v | (v << 4)) & 0x0f0f_0f0f_0f0f_0f0f;
        v = (v | (v << 2)) & 0x3333_3333_3333_3333;
        (v | (v << 1)) & 0x5555_5555_5555_5555
    };
    spread(x) | (spread(y) << 1)
}

/// The samples of a frame, row-major.
enum Samples {
    U8(Vec<u8>),
    U16(Vec<u16>),
}

impl Samples {
    fn get(&self, i: usize) -> u16 {
        match self {
            Samples::U8(d) => d[i] as u16,
            Samples::U16(d) => d[i],
        }
    }
}

/// One frame prepared for the passes.
struct Prepared {
    /// The raw samples (checked to be at most the problem's `top`).
    samples: Samples,
    pose: PlanePose,
    geom: Geom,
}

/// What a pass needs of a frame besides its samples.
#[derive(Clone, Copy)]
struct Geom {
    exposure_ms: f64,
    /// The frame's [`ray_to_grid`] matrix.
    m: [[f64; 3]; 3],
    /// Grid cells per pixel at the image centre (scales the registration error).
    cells_per_px: f64,
}

/// What every pass needs.
struct Problem<'a> {
    frames: &'a dyn PlaneFrames,
    rays: &'a [[f32; 3]],
    /// The pixels the problem has, as indices into the image (all of them, or a coarse
    /// sample); `V` is indexed by their position here.
    sample: Vec<u32>,
    /// The sample as a grid (width, height), row-major: the neighbours of a position.
    layout: (usize, usize),
    /// The order in which the passes visit the sample (positions in it): image tiles of
    /// [`TILE_W`] x [`TILE_H`] pixels, row by row (see [`tile_order`]).
    order: Vec<u32>,
    /// The rays (x, y and z apart) and the pixel indices in the visiting order: the passes
    /// read them in a row.
    ordered_rays: [Vec<f32>; 3],
    ordered_pix: Vec<u32>,
    /// Blocks of at most [`BATCH`] consecutive positions of the order inside one band of
    /// tiles: a pass over frames in memory visits every frame for one block before the next.
    blocks: Vec<std::ops::Range<usize>>,
    /// The parallel jobs of such a pass: ranges of blocks made of whole bands (a job's
    /// pixels are a range of positions), [`PIXEL_JOBS`] of them.
    jobs: Vec<std::ops::Range<usize>>,
    size: ImageSize,
    /// `U` at every sample value of the frames' bit depth.
    u: &'a [f64],
    options: &'a VignetteOptions,
    grid: usize,
}

impl<'a> Problem<'a> {
    /// The problem on the pixels `sample` (image indices), with its visiting order.
    #[allow(clippy::too_many_arguments)]
    fn new(
        frames: &'a dyn PlaneFrames,
        rays: &'a [[f32; 3]],
        (sample, layout): (Vec<u32>, (usize, usize)),
        size: ImageSize,
        u: &'a [f64],
        options: &'a VignetteOptions,
        grid: usize,
    ) -> Problem<'a> {
        let order = tile_order(&sample, size.width);
        let (ordered_rays, ordered_pix) = ordered(rays, &sample, &order);
        let (blocks, jobs) = blocks_and_jobs(&ordered_pix, size.width);
        Problem {
            frames,
            rays,
            sample,
            layout,
            order,
            ordered_rays,
            ordered_pix,
            blocks,
            jobs,
            size,
            u,
            options,
            grid,
        }
    }

    /// The saturated sample value, `2^bits - 1`.
    fn top(&self) -> u16 {
        (self.u.len() - 1) as u16
    }

    fn prepare(&self, i: usize) -> Result<Option<Prepared>, PhotometricError> {
        let frame = self.frames.frame(i)?;
        check_frame(&frame, self.size, self.u.len(), i)?;
        let Some(geom) = self.geom(&frame.pose, frame.exposure_ms) else {
            return Ok(None);
        };
        let samples = match frame.image {
            PlaneImage::U8(i) => Samples::U8(i.into_data()),
            PlaneImage::U16 { image, .. } => Samples::U16(image.into_data()),
        };
        Ok(Some(Prepared {
            samples,
            pose: frame.pose,
            geom,
        }))
    }

    /// What the passes need of a frame with plane pose `pose` besides its samples, on this
    /// problem's grid (`None` for a pose that does not map the image onto the plane).
    fn geom(&self, pose: &PlanePose, exposure_ms: f64) -> Option<Geom> {
        let m = ray_to_grid(pose, self.grid, self.options.extent)?;
        let (w, h) = (self.size.width, self.size.height);
        let c = (h / 2) * w + w / 2;
        let cells_per_px = match (
            grid_coords(self.rays[c], &m, self.grid),
            grid_coords(self.rays[c + 1], &m, self.grid),
        ) {
            (Some(a), Some(b)) => ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt(),
            _ => 1.0,
        };
        Some(Geom {
            exposure_ms,
            m,
            cells_per_px,
        })
    }
}

/// The model's state: `V` per pixel, `C` per cell, the noise model and the outlier switch.
struct Model {
    v: Vec<f64>,
    c: Vec<f32>,
    noise: NoiseModel,
    reject: bool,
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
    fn new(npx: usize, levels: usize) -> VSums {
        VSums {
            num: vec![0.0; npx],
            den: vec![0.0; npx],
            num_odd: vec![0.0; npx],
            den_odd: vec![0.0; npx],
            counts: vec![0; npx],
            rss: vec![0.0; levels],
            rcnt: vec![0.0; levels],
            chi2: 0.0,
            nobs: 0,
            pred2: 0.0,
            res2: 0.0,
            outliers: 0,
        }
    }

    /// Adds `o`, whose per-pixel sums are those of the pixels from `offset` on.
    fn add_range(&mut self, o: &VSums, offset: usize) {
        let n = o.num.len();
        let r = offset..offset + n;
        self.num[r.clone()].copy_from_slice(&o.num);
        self.den[r.clone()].copy_from_slice(&o.den);
        self.num_odd[r.clone()].copy_from_slice(&o.num_odd);
        self.den_odd[r.clone()].copy_from_slice(&o.den_odd);
        self.counts[r].copy_from_slice(&o.counts);
        self.add_statistics(o);
    }

    /// Adds the residual statistics of `o`.
    fn add_statistics(&mut self, o: &VSums) {
        for (a, b) in self.rss.iter_mut().zip(&o.rss) {
            *a += b;
        }
        for (a, b) in self.rcnt.iter_mut().zip(&o.rcnt) {
            *a += b;
        }
        self.chi2 += o.chi2;
        self.nobs += o.nobs;
        self.pred2 += o.pred2;
        self.res2 += o.res2;
        self.outliers += o.outliers;
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
        self.add_statistics(o);
    }
}

/// Bins of the lookup tables over the energy (U-units) up to `U` of the saturated value.
const VAR_BINS: usize = 2048;

/// Per energy bin: the noise model's variance of `U(I)`, the grey value, and the inverse
/// slope of `U` there (residuals in grey values for the noise model's fit).
struct Tables {
    /// (an array: its length is known where the passes index it)
    var: Box<[f64; VAR_BINS]>,
    grey: Vec<u16>,
    inv_slope: Vec<f64>,
    scale: f64,
}

impl Tables {
    fn new(u: &[f64], noise: &NoiseModel) -> Tables {
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
    fn bin(&self, e: f64) -> usize {
        // (a branch-free conversion: `as usize` saturates in several instructions)
        let b = (e * self.scale).clamp(0.0, (VAR_BINS - 1) as f64);
        round_small(if b.is_nan() { 0.0 } else { b }) as usize
    }
}

/// `x` rounded to the nearest integer (ties to even), for `0 <= x < 2^31`: the low bits of
/// `x + 2^52` (a branch-free conversion; `as` saturates in several instructions).
#[inline]
fn round_small(x: f64) -> u32 {
    (x + 4_503_599_627_370_496.0).to_bits() as u32
}

/// Asks the core to bring the cache line at `p` into its cache ahead of its use: a hint,
/// which never faults (`p` may point anywhere) and changes no result; nothing off x86-64.
#[inline(always)]
fn prefetch<T>(p: *const T) {
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
fn prefetch_taps<T>(cells: &[T], at: usize, grid: usize) {
    let p = cells.as_ptr().wrapping_add(at);
    prefetch(p);
    prefetch(p.wrapping_add(grid));
}

/// How many observations ahead the lookups of `C` ([`PassCtx::dense`]) and the additions
/// to the C step's sums ([`Splats::add`]) ask for their cells: both wait on cache misses
/// (the plane's arrays are megabytes). 2-3% of a calibration (150 frames of 640x512, eight
/// paired runs, each faster); 8 and 32 were no better.
const PREFETCH_AHEAD: usize = 16;

/// The floor of `x`, for `0 <= x < 2^31` (see [`round_small`]).
#[inline]
fn floor_small(x: f64) -> i32 {
    let r = round_small(x) as i32;
    r - (r as f64 > x) as i32
}

/// Parallel jobs of a pass over the frames: consecutive frames share their accumulators.
const FRAME_JOBS: usize = 8;

/// The decoded frames one job holds at a time stay under this many bytes (at least one
/// frame per job): memory does not grow with the number of frames.
const JOB_FRAME_BYTES: usize = 32 << 20;

/// Pixels per block of a pass: the pass visits every frame of its job for one block of
/// pixels before the next, so that the block's sums, rays and `V` stay in the core's cache
/// while the frames stream by (frame by frame, these per-pixel arrays would come from
/// memory once per frame).
const PIXEL_BLOCK: usize = 4096;

/// The frames of each job: a partition of the frames that depends on their number and size
/// only, not on the number of threads, so that every sum is taken in the same order with
/// any number of threads.
fn frame_jobs(n: usize, frame_bytes: usize) -> Vec<std::ops::Range<usize>> {
    let per = n
        .div_ceil(FRAME_JOBS)
        .min(JOB_FRAME_BYTES / frame_bytes.max(1))
        .max(1);
    (0..n).step_by(per).map(|s| s..(s + per).min(n)).collect()
}

/// Runs `job` on the frames of every job of [`frame_jobs`], as many at a time as there are
/// threads, and hands the results to `add` in the order of the jobs: the same bits with one
/// thread or many, and at most one job's accumulators per thread in memory.
fn fold_frame_jobs<T: Send>(
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
enum Step {
    /// The V step's per-pixel sums and the residual statistics.
    V,
    /// The C step's per-cell sums.
    C,
}

/// What one pass holds fixed: the problem, the model, the noise tables and the constants
/// of the weights.
struct PassCtx<'a, 'p> {
    p: &'a Problem<'p>,
    model: &'a Model,
    tables: &'a Tables,
    reg2: f64,
    out2: f64,
    top: u16,
    step: Step,
    /// Whether the V step takes the statistics too (see [`PassCtx::v_sums`]).
    stats: bool,
    /// Whether the kernels run with 256-bit vectors (see [`wide_vectors`]).
    wide: bool,
}

/// Whether the passes' kernels ([`PassCtx::dense`], [`PassCtx::stages`]) run compiled for
/// AVX2: four `f64` to a vector instead of two, the same operations in the same order (no
/// fused multiply-add), so the same results to the bit, faster where the arithmetic is the
/// bound (the plane positions, about twice). On when the CPU has AVX2, unless the
/// environment variable `MONOVO_NO_AVX2` is set (to compare, or to rule it out).
fn wide_vectors() -> bool {
    camera_model::avx2_enabled()
}

/// The sums of one job: the V step's per pixel, or the C step's per cell (numerator and
/// denominator side by side: one cache line).
struct JobSums {
    v: VSums,
    cacc: Vec<[f32; 2]>,
}

/// The splats of the C step visit the observations of a batch this many apart (see
/// [`PassCtx::splat_dense`]).
const SPLAT_STRIDE: usize = 4;

/// Observations per batch of a pass's stages.
const BATCH: usize = 256;

/// The observations of one batch of pixels of one frame, stage by stage (structure of
/// arrays): each stage is a short loop whose iterations do not depend on each other, so
/// that the core overlaps them and the compiler can use vector instructions (one loop doing
/// all of an observation's work in a row waits on a chain of divisions, loads and table
/// lookups).
struct Batch {
    /// Plane grid coordinates of every pixel of the batch, and whether they are inside.
    gx: Vec<f64>,
    gy: Vec<f64>,
    inside: Vec<bool>,
    /// The observations kept (the first `n` entries): the pixel's position in the problem's
    /// sample, the sample value, the storage indices of the four bilinear taps, and the
    /// fractions of the position between them.
    n: usize,
    pos: Vec<u32>,
    k: Vec<u16>,
    idx: Vec<[u32; 4]>,
    frac: Vec<[f64; 2]>,
    /// `C` at the position, and the squared norm of its gradient (per cell).
    cq: Vec<f64>,
    grad2: Vec<f64>,
}

impl Batch {
    fn new() -> Batch {
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
    fn new(
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
    fn observe<S: Copy + Into<u16>>(
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
    fn stages<S: Copy + Into<u16>>(
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
    fn stages_avx2<S: Copy + Into<u16>>(
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
    fn stages_body<S: Copy + Into<u16>>(
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
    fn v_sums<const STATS: bool>(
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
    fn c_sums(&self, pf: &Geom, b: &Batch, acc: &mut JobSums) {
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
    fn c_one(
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
struct Dense {
    at: Vec<u32>,
    fx: Vec<f64>,
    fy: Vec<f64>,
    wo: Vec<f32>,
    wc: Vec<f32>,
    w: Vec<f32>,
    /// The kernel's arrays between its loops (kept here: fresh ones cost a zeroing of 18 KiB
    /// per block and frame).
    scratch: Box<Scratch>,
}

/// The arrays between the loops of [`PassCtx::dense`], by position in the block: `C` at the
/// four taps, `U` of the sample, `C` at the position, its squared gradient, the noise bin of
/// the prediction and the variance there.
struct Scratch {
    taps: [[f64; BATCH]; 4],
    obs: [f64; BATCH],
    cqs: [f64; BATCH],
    grad2s: [f64; BATCH],
    bins: [u32; BATCH],
    var: [f64; BATCH],
}

impl Dense {
    /// Room for `views` frames of a block of at most [`BATCH`] positions.
    fn with_views(views: usize) -> Dense {
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
struct BlockSums {
    num: Vec<f64>,
    den: Vec<f64>,
    num_odd: Vec<f64>,
    den_odd: Vec<f64>,
    counts: Vec<u32>,
}

impl BlockSums {
    fn new() -> BlockSums {
        BlockSums {
            num: vec![0.0; BATCH],
            den: vec![0.0; BATCH],
            num_odd: vec![0.0; BATCH],
            den_odd: vec![0.0; BATCH],
            counts: vec![0; BATCH],
        }
    }

    /// Zero for the next block.
    fn clear(&mut self) {
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
    fn dense<S: Copy + Into<u16>>(
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
    fn dense_avx2<S: Copy + Into<u16>>(
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

    /// The body of [`PassCtx::dense`] (inlined into both of its builds).
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn dense_body<S: Copy + Into<u16>>(
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
        let (g_last, g_max) = ((grid - 1) as f64, (grid - 2) as f64);
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
    fn splat_dense(
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
struct Splat {
    at: u32,
    fx: f32,
    fy: f32,
    num: f32,
    den: f32,
}

/// The C step's splats gathered by band of cells before they are added: the observations
/// of a block come from frames all over the plane, and added at once their updates miss the
/// cache (the plane's sums are megabytes); a band's splats are added together, within a
/// part of the sums that stays in the core's cache.
struct Splats {
    grid: usize,
    /// Cells per band (a power of two: the band of a cell is `at >> shift`).
    shift: u32,
    /// Splats a band holds before they are added.
    cap: usize,
    pending: Vec<Splat>,
    fill: Vec<usize>,
    /// The cells reached so far: the smallest and one past the largest (`(usize::MAX, 0)`:
    /// none).
    touched: (usize, usize),
}

/// log2 of the cells per band of [`Splats`] (16384 cells: 128 KiB of sums).
const SPLAT_BAND_SHIFT: u32 = 14;

/// Splats a band of [`Splats`] holds (40 KiB; 2.5 MiB for the 62 bands of a 1000x1000 grid).
const SPLAT_BAND_CAP: usize = 2048;

impl Splats {
    fn new(ncell: usize, grid: usize) -> Splats {
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
    fn push(&mut self, s: Splat, cacc: &mut [[f32; 2]]) {
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
    fn add(&mut self, b: usize, cacc: &mut [[f32; 2]]) {
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
    fn finish(&mut self, cacc: &mut [[f32; 2]]) -> std::ops::Range<usize> {
        for b in 0..self.fill.len() {
            self.add(b, cacc);
        }
        let (lo, hi) = self.touched;
        lo.min(hi)..hi.min(cacc.len())
    }
}

/// A frame with a plane pose as the passes over the store see it: its number and what the
/// passes need of it.
struct View {
    i: usize,
    geom: Geom,
}

/// The samples of every frame with a plane pose in the visiting order of a problem, block
/// by block ([`Problem::blocks`]) and in a block frame by frame: a pass over a block reads
/// them in a row. In memory when they fit in [`VignetteOptions::memory_mb`], else in the
/// scratch file of [`PlaneFrames::scratch`] when there is one (read back a chunk of blocks
/// at a time: memory stays flat at any number of frames); without either, every pass
/// decodes the frames again.
struct Store {
    views: Vec<View>,
    /// Frames the layout has room for (every frame of the source: those without a pose
    /// leave their room empty).
    room: usize,
    data: StoreData,
}

enum StoreData {
    U8(Vec<u8>),
    U16(Vec<u16>),
    /// In a file of `bytes`, little-endian samples of one byte or (`wide`) two.
    File {
        file: std::fs::File,
        wide: bool,
        bytes: usize,
    },
}

/// The samples of one block of one frame, or of all frames of a block.
#[derive(Clone, Copy)]
enum SamplesRef<'a> {
    U8(&'a [u8]),
    U16(&'a [u16]),
}

impl SamplesRef<'_> {
    /// The samples `range` of these.
    fn slice(&self, range: std::ops::Range<usize>) -> SamplesRef<'_> {
        match self {
            SamplesRef::U8(d) => SamplesRef::U8(&d[range]),
            SamplesRef::U16(d) => SamplesRef::U16(&d[range]),
        }
    }
}

/// Samples a job reads from a store's file at a time (whole blocks, at least one).
const CHUNK_SAMPLES: usize = 4 << 20;

/// The part of a file-backed store a job has read ([`Store::block`]).
#[derive(Default)]
struct Chunk {
    /// The position in the store of the first sample held.
    start: usize,
    bytes: Vec<u8>,
    wide: Vec<u16>,
}

/// The error of the scratch file.
fn scratch_error(what: &str, bytes: usize, e: std::io::Error) -> PhotometricError {
    PhotometricError::Scratch(format!(
        "{what} the scratch file that holds the frames' samples ({} MiB in all; raise memory_mb to keep them in memory, or free disk space): {e}",
        bytes.div_ceil(1 << 20)
    ))
}

#[cfg(unix)]
fn read_at(file: &std::fs::File, buf: &mut [u8], offset: u64) -> std::io::Result<()> {
    std::os::unix::fs::FileExt::read_exact_at(file, buf, offset)
}

#[cfg(unix)]
fn write_at(file: &std::fs::File, buf: &[u8], offset: u64) -> std::io::Result<()> {
    std::os::unix::fs::FileExt::write_all_at(file, buf, offset)
}

#[cfg(windows)]
fn read_at(file: &std::fs::File, mut buf: &mut [u8], mut offset: u64) -> std::io::Result<()> {
    while !buf.is_empty() {
        match std::os::windows::fs::FileExt::seek_read(file, buf, offset)? {
            0 => return Err(std::io::ErrorKind::UnexpectedEof.into()),
            n => {
                buf = &mut buf[n..];
                offset += n as u64;
            }
        }
    }
    Ok(())
}

#[cfg(windows)]
fn write_at(file: &std::fs::File, mut buf: &[u8], mut offset: u64) -> std::io::Result<()> {
    while !buf.is_empty() {
        match std::os::windows::fs::FileExt::seek_write(file, buf, offset)? {
            0 => return Err(std::io::ErrorKind::WriteZero.into()),
            n => {
                buf = &buf[n..];
                offset += n as u64;
            }
        }
    }
    Ok(())
}

impl Store {
    /// An empty store for the frames of `p` with `bits`-bit samples: in memory if it fits in
    /// `budget` bytes, else in the scratch file of `p`'s frames, if they give one.
    fn new(p: &Problem<'_>, bits: u32, budget: usize) -> Result<Option<Store>, PhotometricError> {
        let room = p.frames.len();
        let wide = bits > 8;
        let Some(bytes) = room
            .checked_mul(p.order.len())
            .and_then(|n| n.checked_mul(if wide { 2 } else { 1 }))
        else {
            return Ok(None);
        };
        let n = room * p.order.len();
        let data = if bytes <= budget {
            if wide {
                StoreData::U16(vec![0; n])
            } else {
                StoreData::U8(vec![0; n])
            }
        } else {
            let Some(file) = p
                .frames
                .scratch()
                .map_err(|e| scratch_error("cannot open", bytes, e))?
            else {
                return Ok(None);
            };
            // the room of frames without a pose is never written: the file has its size
            file.set_len(bytes as u64)
                .map_err(|e| scratch_error("cannot size", bytes, e))?;
            StoreData::File { file, wide, bytes }
        };
        Ok(Some(Store {
            views: Vec::with_capacity(room),
            room,
            data,
        }))
    }

    /// The bytes the store holds in memory.
    fn memory_bytes(&self) -> usize {
        match &self.data {
            StoreData::U8(d) => d.len(),
            StoreData::U16(d) => 2 * d.len(),
            StoreData::File { .. } => 0,
        }
    }

    /// Where the samples of view `v` of `block` start.
    fn at(&self, block: &std::ops::Range<usize>, v: usize) -> usize {
        block.start * self.room + v * block.len()
    }

    /// The samples of every view of `block` (view `v` at `v * block.len()`), from memory or
    /// through `chunk` from the file, which reads ahead up to the block ending at `end`.
    fn block<'b>(
        &'b self,
        block: &std::ops::Range<usize>,
        end: usize,
        chunk: &'b mut Chunk,
    ) -> Result<SamplesRef<'b>, PhotometricError> {
        let (a, n) = (self.at(block, 0), block.len() * self.room);
        match &self.data {
            StoreData::U8(d) => Ok(SamplesRef::U8(&d[a..a + n])),
            StoreData::U16(d) => Ok(SamplesRef::U16(&d[a..a + n])),
            StoreData::File { file, wide, bytes } => {
                let held = if *wide {
                    chunk.wide.len()
                } else {
                    chunk.bytes.len()
                };
                if a < chunk.start || a + n > chunk.start + held {
                    let to = (a + CHUNK_SAMPLES.max(n)).min(end * self.room).max(a + n);
                    let size = if *wide { 2 } else { 1 };
                    chunk.start = a;
                    chunk.bytes.resize((to - a) * size, 0);
                    read_at(file, &mut chunk.bytes, (a * size) as u64)
                        .map_err(|e| scratch_error("cannot read", *bytes, e))?;
                    if *wide {
                        chunk.wide.clear();
                        chunk.wide.extend(
                            chunk
                                .bytes
                                .chunks_exact(2)
                                .map(|b| u16::from_le_bytes([b[0], b[1]])),
                        );
                    }
                }
                let r = a - chunk.start..a - chunk.start + n;
                Ok(if *wide {
                    SamplesRef::U16(&chunk.wide[r])
                } else {
                    SamplesRef::U8(&chunk.bytes[r])
                })
            }
        }
    }

    /// Adds the prepared frames `frames` (frame index, samples, and their geometry on this
    /// store's problem `p`) as the next views.
    fn add(
        &mut self,
        p: &Problem<'_>,
        frames: &[(usize, &Samples, Geom)],
    ) -> Result<(), PhotometricError> {
        let (first, room) = (self.views.len(), self.room);
        match &mut self.data {
            StoreData::U8(d) => fill_blocks(d, p, room, first, frames, |v| v as u8),
            StoreData::U16(d) => fill_blocks(d, p, room, first, frames, |v| v),
            StoreData::File { file, wide, bytes } => {
                let (file, wide, total) = (&*file, *wide, *bytes);
                let size = if wide { 2 } else { 1 };
                p.blocks.par_iter().try_for_each(|b| {
                    let pix = &p.ordered_pix[b.clone()];
                    let mut bytes = Vec::with_capacity(frames.len() * b.len() * size);
                    for (_, samples, _) in frames {
                        for &q in pix {
                            let v = samples.get(q as usize);
                            if wide {
                                bytes.extend_from_slice(&v.to_le_bytes());
                            } else {
                                bytes.push(v as u8);
                            }
                        }
                    }
                    let at = b.start * room + first * b.len();
                    write_at(file, &bytes, (at * size) as u64)
                        .map_err(|e| scratch_error("cannot write", total, e))
                })?;
            }
        }
        self.views
            .extend(frames.iter().map(|&(i, _, geom)| View { i, geom }));
        Ok(())
    }
}

/// Writes the samples of `frames` into the store `data` of problem `p` (room for `room`
/// frames) as views `first ..`: the blocks own disjoint parts of the data, filled in
/// parallel.
fn fill_blocks<T: Copy + Send>(
    data: &mut [T],
    p: &Problem<'_>,
    room: usize,
    first: usize,
    frames: &[(usize, &Samples, Geom)],
    conv: impl Fn(u16) -> T + Sync,
) {
    let mut parts = Vec::with_capacity(p.blocks.len());
    let mut rest = data;
    for b in &p.blocks {
        let (head, tail) = rest.split_at_mut(b.len() * room);
        parts.push((b, head));
        rest = tail;
    }
    parts.into_par_iter().for_each(|(b, part)| {
        let pix = &p.ordered_pix[b.clone()];
        for (k, (_, samples, _)) in frames.iter().enumerate() {
            let v = first + k;
            let dst = &mut part[v * b.len()..(v + 1) * b.len()];
            for (d, &q) in dst.iter_mut().zip(pix) {
                *d = conv(samples.get(q as usize));
            }
        }
    });
}

/// Frames decoded at a time while the stores are filled.
const LOAD_CHUNK: usize = 16;

/// The number of connected parts of the observation graph and the part of every 8x8 pixel
/// block (`u32::MAX`: never observed); see [`Graph`].
type Parts = (usize, Vec<u32>);

/// One visit of the frames before the iterations: the observation graph's connected parts
/// (see [`Graph`]) and the stores of `problems` that fit in `budget` bytes together (the
/// first problems first). Every frame is decoded once.
fn load(
    graph_problem: &Problem<'_>,
    problems: &[&Problem<'_>],
    budget: usize,
) -> Result<(Parts, Vec<Option<Store>>), PhotometricError> {
    let n = graph_problem.frames.len();
    let bits = graph_problem.u.len().trailing_zeros();
    let mut left = budget;
    let mut stores: Vec<Option<Store>> = Vec::with_capacity(problems.len());
    for p in problems {
        let s = Store::new(p, bits, left)?;
        left -= s.as_ref().map_or(0, Store::memory_bytes);
        stores.push(s);
    }
    let mut graph = Graph::new(graph_problem);
    let indices: Vec<usize> = (0..n).collect();
    for chunk in indices.chunks(LOAD_CHUNK.max(rayon::current_num_threads())) {
        let prepared: Vec<(usize, Prepared)> = chunk
            .par_iter()
            .map(|&i| Ok(graph_problem.prepare(i)?.map(|pf| (i, pf))))
            .collect::<Result<Vec<_>, PhotometricError>>()?
            .into_iter()
            .flatten()
            .collect();
        for (_, pf) in &prepared {
            graph.add(pf);
        }
        for (store, p) in stores.iter_mut().zip(problems) {
            let Some(store) = store else {
                continue;
            };
            let frames: Vec<(usize, &Samples, Geom)> = prepared
                .iter()
                .filter_map(|(i, pf)| {
                    p.geom(&pf.pose, pf.geom.exposure_ms)
                        .map(|g| (*i, &pf.samples, g))
                })
                .collect();
            store.add(p, &frames)?;
        }
    }
    Ok((graph.finish(), stores))
}

/// Width and height of the image tiles in which the passes visit the pixels: a tile's
/// footprint on the plane is compact in every frame, so that the loads of `C` and the sums
/// of the C step stay in the core's cache (a whole row of pixels walks across many cache
/// lines of the plane grid), and a tile's rows are whole cache lines of the frames' samples
/// (64x4 is a third faster than 16x16 tiles, whose rows use a quarter of each line).
const TILE_W: usize = 64;
const TILE_H: usize = 4;

/// Parallel jobs of the fused iteration (consecutive bands of tiles share their
/// accumulators).
const PIXEL_JOBS: usize = 16;

/// The positions of `sample` (pixel indices of an image `width` wide) in the order of the
/// image's tiles of [`TILE_W`] x [`TILE_H`] pixels (tiles row by row, pixels row by row in
/// a tile).
fn tile_order(sample: &[u32], width: usize) -> Vec<u32> {
    let mut order: Vec<u32> = (0..sample.len() as u32).collect();
    order.sort_by_key(|&q| {
        let pix = sample[q as usize] as usize;
        let (x, y) = (pix % width, pix / width);
        (y / TILE_H, x / TILE_W, q)
    });
    order
}

/// The rays (x, y, z apart) and pixel indices of `sample` in the visiting `order`.
fn ordered(rays: &[[f32; 3]], sample: &[u32], order: &[u32]) -> ([Vec<f32>; 3], Vec<u32>) {
    let pix: Vec<u32> = order.iter().map(|&q| sample[q as usize]).collect();
    let axis = |k: usize| pix.iter().map(|&i| rays[i as usize][k]).collect();
    ([axis(0), axis(1), axis(2)], pix)
}

/// The blocks and jobs of a problem whose visiting order has the pixels `ordered_pix` (see
/// [`Problem::blocks`]).
fn blocks_and_jobs(
    ordered_pix: &[u32],
    width: usize,
) -> (Vec<std::ops::Range<usize>>, Vec<std::ops::Range<usize>>) {
    let band = |k: usize| ordered_pix[k] as usize / width / TILE_H;
    // where each band starts in the order
    let mut starts: Vec<usize> = (0..ordered_pix.len())
        .filter(|&k| k == 0 || band(k) != band(k - 1))
        .collect();
    starts.push(ordered_pix.len());
    let bands = starts.len() - 1;
    let per = bands.div_ceil(PIXEL_JOBS).max(1);
    let mut blocks = Vec::new();
    let mut jobs = Vec::new();
    for first in (0..bands).step_by(per) {
        let from = blocks.len();
        for b in first..(first + per).min(bands) {
            let (s, e) = (starts[b], starts[b + 1]);
            blocks.extend((s..e).step_by(BATCH).map(|k| k..(k + BATCH).min(e)));
        }
        jobs.push(from..blocks.len());
    }
    (blocks, jobs)
}

/// What a pass over the store computes.
#[derive(Clone, Copy, PartialEq)]
enum Visit {
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
type StoreJob = (
    std::ops::Range<usize>,
    VSums,
    Vec<[f32; 2]>,
    std::ops::Range<usize>,
);

/// Adds a job's C step sums to the totals.
fn add_cells(num: &mut [f64], den: &mut [f64], cacc: &[[f32; 2]]) {
    for ((n, d), c) in num.iter_mut().zip(den.iter_mut()).zip(cacc) {
        *n += c[0] as f64;
        *d += c[1] as f64;
    }
}

/// A pass over the frames in `store` (see [`Visit`]): the V step's sums (with the
/// statistics when `stats`), and the new `C` of the C step (`model.c` for [`Visit::V`]).
fn store_pass(
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
fn c_step(c: &[f32], num: &[f64], den: &[f64]) -> Vec<f32> {
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
fn pass(
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

/// Union-find over pixels and plane cells, on 8x8 pixel blocks and 8x8 cell tiles (two
/// unknowns joined when one observation links them): the connected parts of the
/// observation graph that hold observed pixels. Frames are added one at a time.
struct Graph<'p, 'a> {
    p: &'p Problem<'a>,
    parent: Vec<u32>,
    seen: Vec<bool>,
}

impl<'p, 'a> Graph<'p, 'a> {
    fn new(p: &'p Problem<'a>) -> Self {
        let (bw, bh) = (p.size.width.div_ceil(8), p.size.height.div_ceil(8));
        let tiles = p.grid.div_ceil(8);
        Graph {
            p,
            parent: (0..(bw * bh + tiles * tiles) as u32).collect(),
            seen: vec![false; bw * bh],
        }
    }

    fn find(&mut self, mut a: u32) -> u32 {
        let parent = &mut self.parent;
        while parent[a as usize] != a {
            let up = parent[parent[a as usize] as usize];
            parent[a as usize] = up;
            a = up;
        }
        a
    }

    /// Joins what the frame `pf` (prepared on the graph's problem) observes.
    fn add(&mut self, pf: &Prepared) {
        let p = self.p;
        let (w, h) = (p.size.width, p.size.height);
        let (bw, bh) = (w.div_ceil(8), h.div_ceil(8));
        let tiles = p.grid.div_ceil(8);
        for by in 0..bh {
            for bx in 0..bw {
                let (x, y) = ((bx * 8 + 4).min(w - 1), (by * 8 + 4).min(h - 1));
                let px = y * w + x;
                if pf.samples.get(px) == p.top() {
                    continue;
                }
                if let Some(g) = grid_coords(p.rays[px], &pf.geom.m, p.grid) {
                    let cnode = (bw * bh + (g[1] as usize / 8) * tiles + g[0] as usize / 8) as u32;
                    let pnode = (by * bw + bx) as u32;
                    self.seen[by * bw + bx] = true;
                    let (ra, rb) = (self.find(pnode), self.find(cnode));
                    if ra != rb {
                        self.parent[ra as usize] = rb;
                    }
                }
            }
        }
    }

    /// The connected parts.
    fn finish(mut self) -> Parts {
        let mut roots = std::collections::BTreeMap::new();
        let mut label = vec![u32::MAX; self.seen.len()];
        let seen = std::mem::take(&mut self.seen);
        for (b, _) in seen.iter().enumerate().filter(|(_, s)| **s) {
            let r = self.find(b as u32);
            let n = roots.len() as u32;
            label[b] = *roots.entry(r).or_insert(n);
        }
        (roots.len(), label)
    }
}

/// The coarse stage has every `COARSE_STRIDE`-th pixel in each direction and a grid as
/// much coarser.
const COARSE_STRIDE: usize = 4;

/// The coarse stage only needs to bring the fine one near its solution.
const COARSE_TOLERANCE: f64 = 2e-4;

/// Iterations Anderson mixing remembers.
const ANDERSON_MEMORY: usize = 5;

/// A component of a step (or a residual) more than this many times the 99th percentile of
/// the step's components is erratic ([`erratic_bound`]).
const ERRATIC_FACTOR: f64 = 20.0;

/// The least bound of [`erratic_bound`]: a change of `V` by 1% (of the mean) is erratic only
/// when the typical change is a good part of it, not once the iteration has settled to
/// changes a hundred times smaller.
const ERRATIC_FLOOR: f64 = 1e-2;

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
fn erratic_bound(values: impl Iterator<Item = f64>) -> f64 {
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
struct Anderson {
    m: usize,
    split: usize,
    last: Option<(Vec<f64>, Vec<f64>)>,
    /// Differences of the residuals `f = g(x) - x` of consecutive iterations.
    df: std::collections::VecDeque<Vec<f32>>,
    /// Differences of the images `g(x)` (`dx + df`).
    dg: std::collections::VecDeque<Vec<f32>>,
    /// The steps so far.
    steps: u32,
    /// By pixel, the last step at which it was erratic ([`u32::MAX`]: never).
    erratic: Vec<u32>,
}

impl Anderson {
    fn new(m: usize, split: usize) -> Anderson {
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
    fn mark<T: Copy + Into<f64>>(&mut self, x: &[T]) {
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
    fn step(&mut self, x: &[f64], gx: &[f64]) -> Vec<f64> {
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

    fn reset(&mut self) {
        self.last = None;
        self.df.clear();
        self.dg.clear();
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
    options.check()?;
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
    // U at every sample value of the frames' bit depth (frame 0 tells it; every frame is
    // checked to agree)
    let bits = frames.frame(0)?.image.bits();
    let table: Vec<f64> = match bits {
        8 => response.values().to_vec(),
        9..=16 => response.table_for_bits(bits)?,
        _ => return Err(PhotometricError::BitDepth(bits)),
    };
    let u = &table[..];
    // coarse to fine: the alternation creeps along smooth trades between V and C, which a
    // problem on every 4th pixel in each direction and a 4x coarser grid resolves at a
    // sixteenth of the cost; its V starts the full problem
    let stride = COARSE_STRIDE;
    let coarse_ok = w >= 16 * stride && h >= 16 * stride && grid >= 64;
    let (cw, ch) = (w.div_ceil(stride), h.div_ceil(stride));
    let coarse = coarse_ok.then(|| {
        let sample: Vec<u32> = (0..ch)
            .flat_map(|y| {
                (0..cw).map(move |x| {
                    let (px, py) = (
                        (x * stride + stride / 2).min(w - 1),
                        (y * stride + stride / 2).min(h - 1),
                    );
                    (py * w + px) as u32
                })
            })
            .collect();
        Problem::new(
            frames,
            &rays,
            (sample, (cw, ch)),
            size,
            u,
            options,
            grid / stride,
        )
    });
    let all = (0..npx as u32).collect();
    let problem = Problem::new(frames, &rays, (all, (w, h)), size, u, options, grid);
    // one visit of the frames: the observation graph, and the frames in memory for the
    // iterations where they fit (the coarse stage's first)
    let stages: Vec<&Problem<'_>> = coarse.iter().chain([&problem]).collect();
    let ((parts, labels), mut stores) =
        load(&problem, &stages, options.memory_mb.saturating_mul(1 << 20))?;
    let store = stores.pop().flatten();
    let coarse_store = stores.pop().flatten();
    // observability: one connected part, image corners covered
    if parts == 0 {
        return Err(PhotometricError::Calibration(
            "no pixel of any frame sees the calibration plane".into(),
        ));
    }
    let mut warnings = Vec::new();
    let mut outside: Vec<bool> = Vec::new();
    if parts > 1 {
        let bw = w.div_ceil(8);
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
        warnings.push(format!(
            "{:.1}% of the observed image is not connected to the rest (it sees no plane area that the rest sees); it is filled from its neighbourhood",
            100.0 * (1.0 - frac)
        ));
    }
    let mut warm: Option<(Vec<f64>, NoiseModel)> = None;
    let mut coarse_iterations = 0;
    if let Some(coarse) = &coarse {
        let stage = solve(
            coarse,
            coarse_store.as_ref(),
            None,
            (COARSE_TOLERANCE, 0.0),
            options.max_iterations,
            &|_, _| {},
        )?;
        coarse_iterations = stage.iterations;
        // V at every pixel from the coarse one (bilinear between the sample points)
        let cv = &stage.model.v;
        let full_v: Vec<f64> = (0..npx)
            .map(|i| {
                let fx = ((i % w) as f64 - (stride / 2) as f64) / stride as f64;
                let fy = ((i / w) as f64 - (stride / 2) as f64) / stride as f64;
                let x0 = (fx.floor().max(0.0) as usize).min(cw - 1);
                let y0 = (fy.floor().max(0.0) as usize).min(ch - 1);
                let (x1, y1) = ((x0 + 1).min(cw - 1), (y0 + 1).min(ch - 1));
                let ax = (fx - x0 as f64).clamp(0.0, 1.0);
                let ay = (fy - y0 as f64).clamp(0.0, 1.0);
                let v = |x: usize, y: usize| cv[y * cw + x];
                (1.0 - ay) * ((1.0 - ax) * v(x0, y0) + ax * v(x1, y0))
                    + ay * ((1.0 - ax) * v(x0, y1) + ax * v(x1, y1))
            })
            .collect();
        warm = Some((full_v, stage.model.noise));
    }
    drop(coarse_store);
    let stage = solve(
        &problem,
        store.as_ref(),
        warm,
        (options.tolerance, options.noise_tolerance),
        options.max_iterations,
        &|i, d| progress(coarse_iterations + i, d),
    )?;
    let Stage {
        model,
        tables,
        iterations,
        converged,
        change,
        stats,
    } = stage;
    let iterations = iterations + coarse_iterations;
    // the final statistics: of the last iteration, or from a pass with the final V and C
    let vs = match (stats, &store) {
        (Some(vs), _) => vs,
        (None, Some(st)) => store_pass(&problem, &model, &tables, st, Visit::V, true)?.0,
        (None, None) => pass(&problem, &model, &tables, Step::V, true)?.0,
    };
    drop(store);
    // the problem's arrays (the rays, the visiting order, the coarse stage's) are not
    // needed any more: gone before the smoothing, the run's largest use of memory after
    // the solver
    drop(problem);
    drop(coarse);
    drop(rays);
    finish(
        size,
        options,
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

/// The result of one stage of the solver.
struct Stage {
    model: Model,
    tables: Tables,
    iterations: usize,
    converged: bool,
    change: Vec<f64>,
    /// The statistics of the last iteration, when it took them with the problem fixed (see
    /// [`solve`]).
    stats: Option<VSums>,
}

/// Alternates V and C steps (Anderson-accelerated) on `problem` until the RMS relative
/// change of `V` is below `tolerance`. From scratch (`warm = None`) the noise model follows
/// the residuals for the first iterations and outliers are dropped after a few; from a warm
/// start (`V` and the noise model of a coarser stage) both are fixed from the start.
fn solve(
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
    let (v0, noise0) = warm.unwrap_or_else(|| {
        (
            vec![1.0; npx],
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
    // start: C from V (a Jacobi step from C = 0 is the paper's splat)
    let mut tables = Tables::new(u, &model.noise);
    // (without outlier rejection: with C = 0 every observation would be one)
    model.reject = false;
    model.c = match store {
        Some(st) => store_pass(problem, &model, &tables, st, Visit::C, false)?.1,
        None => pass(problem, &model, &tables, Step::C, false)?.1,
    };
    model.reject = warm_start;
    let mut anderson = Anderson::new(ANDERSON_MEMORY, npx);
    let mut change: Vec<f64> = Vec::new();
    let mut converged = false;
    let mut iterations = 0;
    let ncell = model.c.len();
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
        let mut gv = model.v.clone();
        for ((g, n), d) in gv.iter_mut().zip(&vs.num).zip(&vs.den) {
            if *d > 0.0 {
                *g = n / d;
            }
        }
        // the defective pixels of the stop rule below (once the noise model, the scale of
        // `den`, is fixed: the rule applies from then on)
        if warm_start || it >= NOISE_FIT_ITERATIONS {
            let found = find_defects(layout.0, layout.1, &gv, &vs.den);
            for (d, f) in defective.iter_mut().zip(found) {
                *d |= f;
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
        // Anderson mixing of the whole iteration (V and C together)
        let mut x: Vec<f64> = old_v.clone();
        x.extend(model.c.iter().map(|&c| c as f64));
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
        // the change of V over the pixels the raw map keeps. Left out: a defective pixel
        // (hot, dead; found so in any iteration of the stage), and a pixel whose change is
        // erratic in this iteration ([`erratic_bound`]): their observations go in and out
        // of the outlier set as V moves, so that they jump by up to several times their
        // value between iterations and would hold up the convergence of the rest (with
        // more than half of the pixels found defective, all of them count)
        let observed: Vec<(f64, bool)> = new_v
            .iter()
            .zip(&old_v)
            .zip(vs.den.iter().zip(&defective))
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
        let delta = (s2 / n2.max(1) as f64).sqrt();
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

/// Whether the next iteration looks like the last: its change, extrapolated from the last
/// two of `change` (at the rate between them, at most 1), below twice the stop rule's
/// `bound`. From a warm start the first change is the step from the coarse stage's V to the
/// full one's, a decade above the next: a rate taken from it predicted convergence for the
/// iteration after it on every set measured, where it never was (600 frames of 1280x1024:
/// changes 1.6e-3, 1.0e-4, ...), and the statistics cost a quarter of a pass for nothing; so
/// the rate comes from the changes after it.
fn looks_last(change: &[f64], warm_start: bool, bound: f64) -> bool {
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
fn median_std_error(v: &[f64], den: &[f64]) -> f64 {
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

/// Normalisation, the odd/even maps, the uncertainty, the smoothing and the checks of the
/// result.
fn finish(
    size: ImageSize,
    options: &VignetteOptions,
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
    let (w, h) = (size.width, size.height);
    let npx = w * h;
    let min_obs = options.min_observations.max(1);
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
    let (info, info_odd) = (&vs.den, &vs.den_odd);
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
    // what is left of the sums, and of the model, is a few numbers and the counts: the
    // per-pixel sums (and V, copied into `raw`) go before the smoothing
    drop(info_even);
    let VSums {
        num,
        den,
        num_odd,
        den_odd,
        counts,
        res2,
        pred2,
        outliers,
        ..
    } = vs;
    drop((num, den, num_odd, den_odd));
    let noise = model.noise;
    drop(model);
    let choice = choose_smoothing(w, h, &raw, &raw_var, &odd, &even, options.smoothing_px)?;
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
    let rms_relative = (res2 / pred2.max(1e-300)).sqrt();
    Ok(VignetteCalibration {
        vignette,
        raw: raw_img,
        std_error,
        raw_std_error,
        counts: Image::new(w, h, counts)?,
        coverage,
        smoothing: choice.choice,
        iterations,
        converged,
        change,
        rms_relative,
        noise,
        outliers,
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

/// Checks frame `i` against the image size and the bit depth of the problem (`levels`
/// sample values).
fn check_frame(
    f: &PlaneFrame,
    size: ImageSize,
    levels: usize,
    i: usize,
) -> Result<(), PhotometricError> {
    let (got_width, got_height) = f.image.size();
    if (got_width, got_height) != (size.width, size.height) {
        return Err(PhotometricError::SizeMismatch {
            what: "a calibration frame",
            width: size.width,
            height: size.height,
            got_width,
            got_height,
        });
    }
    let bits = f.image.bits();
    if !(8..=16).contains(&bits) {
        return Err(PhotometricError::BitDepth(bits));
    }
    if 1usize << bits != levels {
        return Err(PhotometricError::Calibration(format!(
            "frame {i} has {bits}-bit samples, frame 0 has {}-bit samples; every frame of a calibration has the same bit depth",
            levels.trailing_zeros()
        )));
    }
    // (8-bit samples always fit)
    if let PlaneImage::U16 { image, .. } = &f.image {
        let top = (levels - 1) as u16;
        if let Some(&v) = image.data().iter().find(|&&v| v > top) {
            return Err(PhotometricError::Calibration(format!(
                "frame {i} has the value {v}, more than a {bits}-bit sample holds (at most {top}); if the values are in the high bits of the 16-bit samples, shift them down or use bit depth 16"
            )));
        }
    }
    if !(f.exposure_ms.is_finite() && f.exposure_ms > 0.0) {
        return Err(PhotometricError::Exposure(f.exposure_ms));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_erratic_bound_is_a_multiple_of_the_99th_percentile_with_a_floor() {
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
    fn the_last_iteration_is_foreseen_from_the_rate_after_a_warm_starts_first_step() {
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
    fn anderson_mixing_converges_on_the_rest_while_a_few_pixels_jump() {
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
