//! The problem and its frames: the plane grid and the rays onto it, the frames prepared for
//! the passes, the order in which the passes visit the pixels, the model's unknowns and their
//! sums, and the observation graph whose connectedness makes `V` observable.

use camera_model::ImageSize;

use super::{PlaneFrame, PlaneFrames, PlaneImage, PlanePose, VignetteOptions};
use crate::noise::NoiseModel;
use crate::PhotometricError;

/// The per-frame map from a viewing ray to homogeneous plane-grid coordinates: with
/// `H = [r1 r2 t]` (the plane-to-camera homography of `camera_from_plane`), `H^-1 ray` is
/// `(x, y, 1) / lambda`; composed with the affine map to grid cells (cell centres at
/// integers, y up on the plane and down in the grid).
pub(super) fn ray_to_grid(pose: &PlanePose, grid: usize, extent: f64) -> Option<[[f64; 3]; 3]> {
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
pub(super) fn grid_coords(ray: [f32; 3], m: &[[f64; 3]; 3], grid: usize) -> Option<[f64; 2]> {
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
pub(super) fn cell(x: usize, y: usize, grid: usize) -> usize {
    y * grid + x
}

/// Number of stored cells of a `grid x grid` plane.
pub(super) fn cells(grid: usize) -> usize {
    grid * grid
}

/// The storage indices of the four bilinear taps whose first is `at` (see [`cell`]): the
/// neighbours in x, in y and in both.
#[inline]
pub(super) fn taps(at: usize, grid: usize) -> [usize; 4] {
    [at, at + 1, at + grid, at + grid + 1]
}

/// The Morton (Z-order) index of `(x, y)`: near cells get near indices.
pub(super) fn morton(x: u32, y: u32) -> u64 {
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
pub(super) enum Samples {
    U8(Vec<u8>),
    U16(Vec<u16>),
}

impl Samples {
    pub(super) fn get(&self, i: usize) -> u16 {
        match self {
            Samples::U8(d) => d[i] as u16,
            Samples::U16(d) => d[i],
        }
    }
}

/// One frame prepared for the passes.
pub(super) struct Prepared {
    /// The raw samples (checked to be at most the problem's `top`).
    pub(super) samples: Samples,
    pub(super) pose: PlanePose,
    pub(super) geom: Geom,
}

/// What a pass needs of a frame besides its samples.
#[derive(Clone, Copy)]
pub(super) struct Geom {
    pub(super) exposure_ms: f64,
    /// The frame's [`ray_to_grid`] matrix.
    pub(super) m: [[f64; 3]; 3],
    /// Grid cells per pixel at the image centre (scales the registration error).
    pub(super) cells_per_px: f64,
}

/// What every pass needs.
pub(super) struct Problem<'a> {
    pub(super) frames: &'a dyn PlaneFrames,
    pub(super) rays: &'a [[f32; 3]],
    /// The pixels the problem has, as indices into the image (all of them, or a coarse
    /// sample); `V` is indexed by their position here.
    pub(super) sample: Vec<u32>,
    /// The sample as a grid (width, height), row-major: the neighbours of a position.
    pub(super) layout: (usize, usize),
    /// The order in which the passes visit the sample (positions in it): image tiles of
    /// [`TILE_W`] x [`TILE_H`] pixels, row by row (see [`tile_order`]).
    pub(super) order: Vec<u32>,
    /// The rays (x, y and z apart) and the pixel indices in the visiting order: the passes
    /// read them in a row.
    pub(super) ordered_rays: [Vec<f32>; 3],
    pub(super) ordered_pix: Vec<u32>,
    /// Blocks of at most [`BATCH`] consecutive positions of the order inside one band of
    /// tiles: a pass over frames in memory visits every frame for one block before the next.
    pub(super) blocks: Vec<std::ops::Range<usize>>,
    /// The parallel jobs of such a pass: ranges of blocks made of whole bands (a job's
    /// pixels are a range of positions), [`PIXEL_JOBS`] of them.
    pub(super) jobs: Vec<std::ops::Range<usize>>,
    pub(super) size: ImageSize,
    /// `U` at every sample value of the frames' bit depth.
    pub(super) u: &'a [f64],
    pub(super) options: &'a VignetteOptions,
    pub(super) grid: usize,
}

impl<'a> Problem<'a> {
    /// The problem on the pixels `sample` (image indices), with its visiting order.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn new(
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
    pub(super) fn top(&self) -> u16 {
        (self.u.len() - 1) as u16
    }

    pub(super) fn prepare(&self, i: usize) -> Result<Option<Prepared>, PhotometricError> {
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
    pub(super) fn geom(&self, pose: &PlanePose, exposure_ms: f64) -> Option<Geom> {
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
pub(super) struct Model {
    pub(super) v: Vec<f64>,
    pub(super) c: Vec<f32>,
    pub(super) noise: NoiseModel,
    pub(super) reject: bool,
}

/// Sums of the V step.
pub(super) struct VSums {
    pub(super) num: Vec<f64>,
    pub(super) den: Vec<f64>,
    /// By frame parity, for cross-validation.
    pub(super) num_odd: Vec<f64>,
    pub(super) den_odd: Vec<f64>,
    pub(super) counts: Vec<u32>,
    /// Residual statistics per predicted grey value (for the noise model), U-units squared
    /// scaled to grey levels.
    pub(super) rss: Vec<f64>,
    pub(super) rcnt: Vec<f64>,
    /// Weighted squared residuals (normalised), sum of squared predictions and residuals.
    pub(super) chi2: f64,
    pub(super) nobs: u64,
    pub(super) pred2: f64,
    pub(super) res2: f64,
    pub(super) outliers: u64,
}

impl VSums {
    pub(super) fn new(npx: usize, levels: usize) -> VSums {
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
    pub(super) fn add_range(&mut self, o: &VSums, offset: usize) {
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
    pub(super) fn add_statistics(&mut self, o: &VSums) {
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

    pub(super) fn add(&mut self, o: &VSums) {
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

/// Width and height of the image tiles in which the passes visit the pixels: a tile's
/// footprint on the plane is compact in every frame, so that the loads of `C` and the sums
/// of the C step stay in the core's cache (a whole row of pixels walks across many cache
/// lines of the plane grid), and a tile's rows are whole cache lines of the frames' samples
/// (64x4 is a third faster than 16x16 tiles, whose rows use a quarter of each line).
pub(super) const TILE_W: usize = 64;
pub(super) const TILE_H: usize = 4;

/// Parallel jobs of the fused iteration (consecutive bands of tiles share their
/// accumulators).
pub(super) const PIXEL_JOBS: usize = 16;

/// The positions of `sample` (pixel indices of an image `width` wide) in the order of the
/// image's tiles of [`TILE_W`] x [`TILE_H`] pixels (tiles row by row, pixels row by row in
/// a tile).
pub(super) fn tile_order(sample: &[u32], width: usize) -> Vec<u32> {
    let mut order: Vec<u32> = (0..sample.len() as u32).collect();
    order.sort_by_key(|&q| {
        let pix = sample[q as usize] as usize;
        let (x, y) = (pix % width, pix / width);
        (y / TILE_H, x / TILE_W, q)
    });
    order
}

/// The rays (x, y, z apart) and pixel indices of `sample` in the visiting `order`.
pub(super) fn ordered(
    rays: &[[f32; 3]],
    sample: &[u32],
    order: &[u32],
) -> ([Vec<f32>; 3], Vec<u32>) {
    let pix: Vec<u32> = order.iter().map(|&q| sample[q as usize]).collect();
    let axis = |k: usize| pix.iter().map(|&i| rays[i as usize][k]).collect();
    ([axis(0), axis(1), axis(2)], pix)
}

/// The blocks and jobs of a problem whose visiting order has the pixels `ordered_pix` (see
/// [`Problem::blocks`]).
pub(super) fn blocks_and_jobs(
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

/// Union-find over pixels and plane cells, on 8x8 pixel blocks and 8x8 cell tiles (two
/// unknowns joined when one observation links them): the connected parts of the
/// observation graph that hold observed pixels. Frames are added one at a time.
pub(super) struct Graph<'p, 'a> {
    pub(super) p: &'p Problem<'a>,
    pub(super) parent: Vec<u32>,
    pub(super) seen: Vec<bool>,
}

impl<'p, 'a> Graph<'p, 'a> {
    pub(super) fn new(p: &'p Problem<'a>) -> Self {
        let (bw, bh) = (p.size.width.div_ceil(8), p.size.height.div_ceil(8));
        let tiles = p.grid.div_ceil(8);
        Graph {
            p,
            parent: (0..(bw * bh + tiles * tiles) as u32).collect(),
            seen: vec![false; bw * bh],
        }
    }

    pub(super) fn find(&mut self, mut a: u32) -> u32 {
        let parent = &mut self.parent;
        while parent[a as usize] != a {
            let up = parent[parent[a as usize] as usize];
            parent[a as usize] = up;
            a = up;
        }
        a
    }

    /// Joins what the frame `pf` (prepared on the graph's problem) observes.
    pub(super) fn add(&mut self, pf: &Prepared) {
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
    pub(super) fn finish(mut self) -> Parts {
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

/// Checks frame `i` against the image size and the bit depth of the problem (`levels`
/// sample values).
pub(super) fn check_frame(
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

/// The number of connected parts of the observation graph and the part of every 8x8 pixel
/// block (`u32::MAX`: never observed); see [`Graph`].
pub(super) type Parts = (usize, Vec<u32>);

/// Observations per batch of a pass's stages.
pub(super) const BATCH: usize = 256;
