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
        let mut max = 0.0f32;
        for &v in values.data() {
            if !v.is_finite() || v < 0.0 {
                return Err(PhotometricError::Vignette(format!(
                    "value {v} is not finite and non-negative"
                )));
            }
            max = max.max(v);
        }
        if max <= 0.0 {
            return Err(PhotometricError::Vignette(
                "every pixel is 0 (an empty or failed calibration)".into(),
            ));
        }
        let masked = values.data().iter().filter(|v| **v == 0.0).count();
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
        self.v
            .data()
            .iter()
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
