//! The vignette `V`: per-pixel attenuation in `[0, 1]`, stored as an 8- or 16-bit grey PNG
//! normalised by its maximum.

use camera_model::Image;

use crate::PhotometricError;

/// A dense vignette map, `max(V) = 1`. Pixels with `V = 0` (for example a black border in the
/// PNG) are masked: the correction marks them invalid instead of dividing by zero.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Vignette {
    v: Image<f32>,
    masked: usize,
}

impl Vignette {
    /// Normalises a map of any scale by its maximum. Fails when no value is positive or a
    /// value is not finite or negative.
    pub fn from_values(values: Image<f32>) -> Result<Vignette, PhotometricError> {
        let (max, valid, masked) = scan(values.data());
        if !valid {
            if let Some(v) = values
                .data()
                .iter()
                .find(|v| !(v.is_finite() && **v >= 0.0))
            {
                return Err(PhotometricError::Vignette(format!(
                    "value {v} is not finite and non-negative"
                )));
            }
        }
        if max <= 0.0 {
            return Err(PhotometricError::Vignette(
                "every pixel is 0 (an empty or failed calibration)".into(),
            ));
        }
        Ok(Vignette {
            v: values.map(|x| x / max),
            masked,
        })
    }

    /// From a 16-bit (or 8-bit widened) grey image.
    pub fn from_u16(img: &Image<u16>) -> Result<Vignette, PhotometricError> {
        Vignette::from_values(img.map(|v| v as f32))
    }

    /// The map.
    pub fn values(&self) -> &Image<f32> {
        &self.v
    }

    /// Width and height.
    pub fn size(&self) -> (usize, usize) {
        self.v.size()
    }

    /// Number of masked (zero) pixels.
    pub fn masked(&self) -> usize {
        self.masked
    }

    /// The map of frames decoded at half their width and height (rounded up): the mean of
    /// each 2x2 block (of the pixels there are at an odd border), masked (0) when one of them
    /// is, scaled to max 1 again.
    pub fn half_size(&self) -> Result<Vignette, PhotometricError> {
        let (w, h) = self.v.size();
        let (hw, hh) = (w.div_ceil(2), h.div_ceil(2));
        let src = self.v.data();
        let mut out = Vec::with_capacity(hw * hh);
        for j in 0..hh {
            for i in 0..hw {
                let (mut sum, mut n, mut masked) = (0.0f32, 0u32, false);
                for y in (2 * j)..(2 * j + 2).min(h) {
                    for x in (2 * i)..(2 * i + 2).min(w) {
                        let v = src[y * w + x];
                        masked |= v == 0.0;
                        sum += v;
                        n += 1;
                    }
                }
                out.push(if masked { 0.0 } else { sum / n as f32 });
            }
        }
        let img = Image::new(hw, hh, out).map_err(|e| PhotometricError::Vignette(e.to_string()))?;
        Vignette::from_values(img)
    }

    /// Smallest positive value.
    pub fn min_positive(&self) -> f32 {
        // in lanes, which the compiler vectorises (a fold of `f32::min` is scalar)
        let mut lanes = [1.0f32; LANES];
        let chunks = self.v.data().chunks_exact(LANES);
        let rest = chunks.remainder();
        for c in chunks {
            for (m, &v) in lanes.iter_mut().zip(c) {
                *m = if v > 0.0 && v < *m { v } else { *m };
            }
        }
        rest.iter()
            .chain(&lanes)
            .copied()
            .filter(|v| *v > 0.0)
            .fold(1.0, f32::min)
    }

    /// The 16-bit image written as vignette.png (`V = 1` at 65535).
    pub fn to_u16(&self) -> Image<u16> {
        self.v
            .map(|x| (x * 65535.0).round().clamp(0.0, 65535.0) as u16)
    }

    /// Checks the map against an image size.
    pub fn check_size(&self, width: usize, height: usize) -> Result<(), PhotometricError> {
        if self.v.size() != (width, height) {
            return Err(PhotometricError::SizeMismatch {
                what: "the vignette",
                width,
                height,
                got_width: self.v.width(),
                got_height: self.v.height(),
            });
        }
        Ok(())
    }
}

/// RMS relative error `(estimate - truth) / truth` of a vignette map over its valid (finite)
/// pixels, and the fraction of pixels that are valid.
pub fn vignette_errors(estimate: &[f32], truth: &[f32]) -> (f64, f64) {
    let mut s = 0.0;
    let mut n = 0usize;
    for (a, b) in estimate.iter().zip(truth) {
        if a.is_finite() {
            let r = (*a as f64 - *b as f64) / *b as f64;
            s += r * r;
            n += 1;
        }
    }
    (
        (s / n.max(1) as f64).sqrt(),
        n as f64 / truth.len().max(1) as f64,
    )
}

/// Values per lane group of the scans below (a 256-bit vector of `f32`).
const LANES: usize = 8;

/// One pass over a map: its largest value, whether every value is finite and non-negative,
/// and how many are 0, kept per lane so that the compiler vectorises the loop (a 1280x1024
/// map in a fraction of a millisecond, a few milliseconds before the first frame otherwise).
fn scan(data: &[f32]) -> (f32, bool, usize) {
    let mut max = [0f32; LANES];
    let mut valid = [true; LANES];
    let mut zeros = [0usize; LANES];
    let chunks = data.chunks_exact(LANES);
    let rest = chunks.remainder();
    for c in chunks {
        for i in 0..LANES {
            let v = c[i];
            max[i] = if v > max[i] { v } else { max[i] };
            // false for NaN, infinities and negative values
            valid[i] &= (0.0..=f32::MAX).contains(&v);
            zeros[i] += (v == 0.0) as usize;
        }
    }
    let mut out = (
        max.iter().copied().fold(0.0, f32::max),
        valid.iter().all(|v| *v),
        zeros.iter().sum(),
    );
    for &v in rest {
        out.0 = out.0.max(v);
        out.1 &= (0.0..=f32::MAX).contains(&v);
        out.2 += (v == 0.0) as usize;
    }
    out
}
