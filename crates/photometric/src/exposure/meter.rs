//! Frames made ready for measuring: corrected (`U(I) / V`), averaged over 2x2 blocks, with
//! dark and near-saturated pixels masked, in a pyramid for the coarse-to-fine alignment.

use camera_model::Image;

use super::ExposureOptions;
use crate::{InverseResponse, PhotometricError, Vignette};

/// One level of a frame's pyramid: `log(U(I) / V)`, NaN where unusable.
#[derive(Clone, Debug)]
pub(super) struct Level {
    pub(super) w: usize,
    pub(super) h: usize,
    pub(super) data: Vec<f32>,
}

impl Level {
    /// The next coarser level: 2x2 means of the finite values (at least two).
    pub(super) fn reduce(&self) -> Level {
        let (w, h) = (self.w / 2, self.h / 2);
        let mut data = vec![f32::NAN; w * h];
        for y in 0..h {
            for x in 0..w {
                let mut s = 0.0;
                let mut n = 0;
                for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    let v = self.data[(2 * y + dy) * self.w + 2 * x + dx];
                    if v.is_finite() {
                        s += v;
                        n += 1;
                    }
                }
                if n >= 2 {
                    data[y * w + x] = s / n as f32;
                }
            }
        }
        Level { w, h, data }
    }
}

/// Samples `l` on the `pw x ph` pixel grid whose first pixel is `(x0 + dx, y0 + dy)`
/// (bilinear at one sub-pixel offset for the whole grid) into `out`, row by row; NaN
/// outside the level or where a neighbour is NaN.
#[allow(clippy::too_many_arguments)]
pub(super) fn sample_patch(
    l: &Level,
    x0: isize,
    y0: isize,
    pw: usize,
    ph: usize,
    dx: f64,
    dy: f64,
    out: &mut Vec<f32>,
) {
    out.clear();
    // floor without libm (the offsets are far above -1024)
    let fx = (dx + 1024.0) as isize - 1024;
    let fy = (dy + 1024.0) as isize - 1024;
    let (ax, ay) = ((dx - fx as f64) as f32, (dy - fy as f64) as f32);
    let xs = x0 + fx;
    let lo = (-xs).clamp(0, pw as isize) as usize;
    let hi = (l.w as isize - 1 - xs).clamp(lo as isize, pw as isize) as usize;
    out.resize(pw * ph, f32::NAN);
    for (j, o) in out.chunks_exact_mut(pw).enumerate() {
        let yy = y0 + j as isize + fy;
        if yy < 0 || yy + 1 >= l.h as isize || hi == lo {
            o.fill(f32::NAN);
            continue;
        }
        let row = yy as usize * l.w;
        let base = (xs + lo as isize) as usize;
        let r0 = &l.data[row + base..row + base + (hi - lo) + 1];
        let r1 = &l.data[row + l.w + base..row + l.w + base + (hi - lo) + 1];
        o[..lo].fill(f32::NAN);
        o[hi..].fill(f32::NAN);
        for ((v, p), q) in o[lo..hi].iter_mut().zip(r0.windows(2)).zip(r1.windows(2)) {
            let top = p[0] + ax * (p[1] - p[0]);
            let bottom = q[0] + ax * (q[1] - q[0]);
            *v = top + ay * (bottom - top);
        }
    }
}

/// A frame prepared for [`measure_ratio`]: its corrected log image at the analysis
/// resolution and a pyramid for the alignment.
#[derive(Clone, Debug)]
pub struct MeteredFrame {
    pub(super) levels: Vec<Level>,
    /// `U(I) / V` at the analysis resolution (level 0 before the log).
    pub(super) linear: Level,
    /// Raw pixels per analysis pixel along each axis.
    pub(super) downsample: usize,
    /// Usable fraction of the analysis pixels.
    pub(super) usable: f64,
}

impl MeteredFrame {
    /// The fraction of the analysis pixels that are usable (neither dark nor saturated).
    pub fn usable_fraction(&self) -> f64 {
        self.usable
    }

    /// Width and height at the analysis resolution.
    pub fn analysis_size(&self) -> (usize, usize) {
        (self.levels[0].w, self.levels[0].h)
    }
}

/// Prepares frames for [`measure_ratio`]: `U` with the unusable grey values masked and
/// `1 / V` per pixel.
#[derive(Clone, Debug)]
pub struct ExposureMeter {
    /// `U` per 8-bit grey value, NaN outside `min_grey..=max_grey`.
    pub(super) lut8: Vec<f32>,
    pub(super) response: InverseResponse,
    pub(super) inv_v: Vec<f32>,
    pub(super) width: usize,
    pub(super) height: usize,
    pub(super) downsample: usize,
    pub(super) min_grey: f64,
    pub(super) max_grey: f64,
}

pub(super) fn masked_table(table: &[f64], bits: u32, min_grey: f64, max_grey: f64) -> Vec<f32> {
    let full = ((1u64 << bits) - 1) as f64;
    table
        .iter()
        .enumerate()
        .map(|(k, &u)| {
            let g = k as f64 * 255.0 / full;
            if g >= min_grey && g <= max_grey && u > 0.0 {
                u as f32
            } else {
                f32::NAN
            }
        })
        .collect()
}

impl ExposureMeter {
    /// A meter for frames of `size` (the raw size, that of the vignette).
    pub fn new(
        response: &InverseResponse,
        vignette: Option<&Vignette>,
        size: (usize, usize),
        opts: &ExposureOptions,
    ) -> Result<ExposureMeter, PhotometricError> {
        let (width, height) = size;
        let downsample = opts.downsample.max(1);
        if width / downsample < 16 || height / downsample < 16 {
            return Err(PhotometricError::SizeMismatch {
                what: "the frames (too small to measure exposure ratios)",
                width: 16 * downsample,
                height: 16 * downsample,
                got_width: width,
                got_height: height,
            });
        }
        let bad_range = !(opts.min_grey.is_finite()
            && opts.max_grey.is_finite()
            && opts.min_grey >= 0.0
            && opts.max_grey <= 255.0
            && opts.min_grey < opts.max_grey);
        if bad_range {
            return Err(PhotometricError::Calibration(format!(
                "usable grey values {}..{} must lie in 0..255 with the first below the second",
                opts.min_grey, opts.max_grey
            )));
        }
        let inv_v = match vignette {
            Some(v) => {
                v.check_size(width, height)?;
                v.values()
                    .data()
                    .iter()
                    .map(|&x| if x > 0.0 { 1.0 / x } else { f32::NAN })
                    .collect()
            }
            None => vec![1.0; width * height],
        };
        Ok(ExposureMeter {
            lut8: masked_table(response.values(), 8, opts.min_grey, opts.max_grey),
            response: response.clone(),
            inv_v,
            width,
            height,
            downsample,
            min_grey: opts.min_grey,
            max_grey: opts.max_grey,
        })
    }

    pub(super) fn check(&self, w: usize, h: usize) -> Result<(), PhotometricError> {
        if (w, h) != (self.width, self.height) {
            return Err(PhotometricError::SizeMismatch {
                what: "the frame",
                width: self.width,
                height: self.height,
                got_width: w,
                got_height: h,
            });
        }
        Ok(())
    }

    /// Prepares an 8-bit frame.
    pub fn frame_u8(&self, img: &Image<u8>) -> Result<MeteredFrame, PhotometricError> {
        self.check(img.width(), img.height())?;
        Ok(self.build(|i| self.lut8[img.data()[i] as usize]))
    }

    /// Prepares a frame of `bits`-bit samples (1 to 16, in the low bits of 16); `U` is
    /// looked up as [`InverseResponse::table_for_bits`] does. A sample beyond the bit depth
    /// is an error.
    pub fn frame_u16(&self, img: &Image<u16>, bits: u32) -> Result<MeteredFrame, PhotometricError> {
        self.check(img.width(), img.height())?;
        let table = masked_table(
            &self.response.table_for_bits(bits)?,
            bits,
            self.min_grey,
            self.max_grey,
        );
        if let Some(&p) = img.data().iter().find(|&&p| p as usize >= table.len()) {
            return Err(PhotometricError::SampleRange {
                value: p as u32,
                bits,
            });
        }
        Ok(self.build(|i| table[img.data()[i] as usize]))
    }

    /// `log` of the 2x2 (or `downsample`) means of `U(I) / V`, NaN when any pixel of the
    /// block is unusable; then the pyramid.
    pub(super) fn build(&self, u_of: impl Fn(usize) -> f32) -> MeteredFrame {
        let s = self.downsample;
        let (w, h) = (self.width / s, self.height / s);
        let mut lin = vec![f32::NAN; w * h];
        let mut data = vec![f32::NAN; w * h];
        let norm = 1.0 / (s * s) as f32;
        let mut usable = 0usize;
        for y in 0..h {
            for x in 0..w {
                let mut sum = 0.0f32;
                for dy in 0..s {
                    let row = (y * s + dy) * self.width + x * s;
                    for i in row..row + s {
                        sum += u_of(i) * self.inv_v[i];
                    }
                }
                // NaN (an unusable pixel) propagates through the sum
                if sum.is_finite() && sum > 0.0 {
                    let v = sum * norm;
                    lin[y * w + x] = v;
                    data[y * w + x] = v.ln();
                    usable += 1;
                }
            }
        }
        let linear = Level { w, h, data: lin };
        let mut levels = vec![Level { w, h, data }];
        while let Some(last) = levels.last() {
            if last.w < 64 || last.h < 48 {
                break;
            }
            let next = last.reduce();
            levels.push(next);
        }
        MeteredFrame {
            levels,
            linear,
            downsample: s,
            usable: usable as f64 / (w * h).max(1) as f64,
        }
    }
}
