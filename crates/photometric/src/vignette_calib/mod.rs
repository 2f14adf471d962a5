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
//! * **The paper's map and the one to use**: the raw map, unregularised but sampled as the
//!   authors' 2016 tool samples its own (the per-pixel estimate read and spread bilinearly:
//!   `[1/6 2/3 1/6]` in x and in y, which halves its noise), and a smoothed map whose
//!   smoothing is chosen by cross-validation between the per-pixel maps of the odd and of
//!   the even frames (see [`crate::smoothing`]; no smoothing gives the per-pixel map).
//! * **With its uncertainty**: per pixel, from the normal equations with the residual scale
//!   checked against the odd/even difference, for both maps.

mod outputs;
mod passes;
mod problem;
mod solver;
mod store;

use camera_model::{CameraModel, Image, ImageSize};
use rayon::prelude::*;

use self::outputs::{finish, Solved};
use self::passes::{pass, store_pass, Step, Visit};
use self::problem::Problem;
use self::solver::{solve, Stage, COARSE_STRIDE, COARSE_TOLERANCE};
use self::store::load;
use crate::noise::NoiseModel;
use crate::smoothing::SmoothingChoice;
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
    /// The paper's unregularised map on the same scale, sampled as the authors' 2016 tool
    /// samples its raw map (the per-pixel estimate filtered with `[1/6 2/3 1/6]` in x and in
    /// y, over the valid neighbours; `smoothing_px = Some(0.0)` gives the per-pixel map as
    /// [`VignetteCalibration::vignette`]); NaN where a pixel has too
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
    let table = response_table(response, frames)?;
    let u = &table[..];
    // coarse to fine: the alternation creeps along smooth trades between V and C, which a
    // problem on every 4th pixel in each direction and a 4x coarser grid resolves at a
    // sixteenth of the cost; its V starts the full problem
    let stride = COARSE_STRIDE;
    let coarse_ok = w >= 16 * stride && h >= 16 * stride && grid >= 64;
    let (cw, ch) = (w.div_ceil(stride), h.div_ceil(stride));
    let coarse = coarse_ok.then(|| {
        let sample = coarse_sample(size, stride);
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
    let (outside, warnings) = connected(parts, &labels, size)?;
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
        let full_v = coarse_to_full(&stage.model.v, size, (cw, ch), stride);
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

/// `U` at every sample value of the frames' bit depth (frame 0 tells it; every frame is
/// checked to agree).
fn response_table(
    response: &InverseResponse,
    frames: &dyn PlaneFrames,
) -> Result<Vec<f64>, PhotometricError> {
    let bits = frames.frame(0)?.image.bits();
    Ok(match bits {
        8 => response.values().to_vec(),
        9..=16 => response.table_for_bits(bits)?,
        _ => return Err(PhotometricError::BitDepth(bits)),
    })
}

/// The coarse problem's pixels: the centre of every `stride` x `stride` block, row-major.
fn coarse_sample(size: ImageSize, stride: usize) -> Vec<u32> {
    let (w, h) = (size.width, size.height);
    let (cw, ch) = (w.div_ceil(stride), h.div_ceil(stride));
    (0..ch)
        .flat_map(|y| {
            (0..cw).map(move |x| {
                let (px, py) = (
                    (x * stride + stride / 2).min(w - 1),
                    (y * stride + stride / 2).min(h - 1),
                );
                (py * w + px) as u32
            })
        })
        .collect()
}

/// Observability from the observation graph's `parts` and the part of every 8x8 block
/// (`labels`): refused when no part holds half of the observed image; otherwise the pixels
/// outside the largest part (their scale is unknown: they count as unobserved) and a warning.
fn connected(
    parts: usize,
    labels: &[u32],
    size: ImageSize,
) -> Result<(Vec<bool>, Vec<String>), PhotometricError> {
    let (w, npx) = (size.width, size.width * size.height);
    let mut warnings = Vec::new();
    let mut outside: Vec<bool> = Vec::new();
    if parts > 1 {
        let bw = w.div_ceil(8);
        let mut sizes = vec![0usize; parts];
        for &l in labels {
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
    Ok((outside, warnings))
}

/// `V` at every pixel from the coarse problem's (bilinear between its sample points).
fn coarse_to_full(
    cv: &[f64],
    size: ImageSize,
    (cw, ch): (usize, usize),
    stride: usize,
) -> Vec<f64> {
    let (w, npx) = (size.width, size.width * size.height);
    // V at every pixel from the coarse one (bilinear between the sample points)
    (0..npx)
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
        .collect()
}
