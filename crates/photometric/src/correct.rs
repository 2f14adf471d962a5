//! Undoing response and vignetting, per the paper's image formation model
//! `I(x) = G(t V(x) B(x))`: `U(I(x)) / V(x)` is proportional to `t B(x)`, and dividing by the
//! exposure `t` gives the irradiance `B(x)` (up to the common scale of `U` and `V`).

use camera_model::{Image, RectifyMap};

use crate::{InverseResponse, PhotometricError, Vignette};

/// A precomputed photometric correction, optionally fused with a rectification map (the
/// vignette is then remapped once into output coordinates).
#[derive(Clone, Debug)]
pub struct Correction {
    map: Option<RectifyMap>,
    lut: [f32; 256],
    /// `U` for every sample value of deeper frames, with its bit depth (see
    /// [`Correction::with_bit_depth`]).
    deep: Option<(u32, Vec<f32>)>,
    inv_v: Option<Vec<f32>>,
    in_size: (usize, usize),
    out_size: (usize, usize),
}

impl Correction {
    /// Builds the correction. With `mask_saturated`, output pixels that touch a saturated
    /// (255) input pixel become invalid (NaN), since their irradiance is unknown. Masked
    /// vignette pixels are invalid too.
    pub fn new(
        response: &InverseResponse,
        vignette: Option<&Vignette>,
        map: Option<RectifyMap>,
        in_size: (usize, usize),
        mask_saturated: bool,
    ) -> Result<Correction, PhotometricError> {
        let mut lut = response.lut();
        if mask_saturated {
            lut[255] = f32::NAN;
        }
        if let Some(m) = &map {
            let s = m.input_size();
            if (s.width, s.height) != in_size {
                return Err(PhotometricError::SizeMismatch {
                    what: "the rectification map's input",
                    width: in_size.0,
                    height: in_size.1,
                    got_width: s.width,
                    got_height: s.height,
                });
            }
        }
        let out_size = map
            .as_ref()
            .map_or(in_size, |m| (m.output_size().width, m.output_size().height));
        let inv_v = match vignette {
            None => None,
            Some(v) => {
                v.check_size(in_size.0, in_size.1)?;
                // masked (zero) vignette pixels become NaN so that they poison the output
                let vv = v.values().map(|x| if x > 0.0 { x } else { f32::NAN });
                let out = match &map {
                    Some(m) => m.remap_f32(&vv)?,
                    None => vv,
                };
                Some(out.data().iter().map(|x| 1.0 / x).collect())
            }
        };
        Ok(Correction {
            map,
            lut,
            deep: None,
            inv_v,
            in_size,
            out_size,
        })
    }

    /// Prepares [`Correction::apply_u16`] for frames whose samples have `bits` bits (1 to
    /// 16, in the low bits of a 16-bit image): `U` of every sample value, exact when the
    /// response has `2^bits` values (see [`InverseResponse::table_for_bits`]). With
    /// `mask_saturated` the brightest value `2^bits - 1` is invalid.
    pub fn with_bit_depth(
        mut self,
        response: &InverseResponse,
        bits: u32,
        mask_saturated: bool,
    ) -> Result<Correction, PhotometricError> {
        let mut table: Vec<f32> = response
            .table_for_bits(bits)?
            .into_iter()
            .map(|v| v as f32)
            .collect();
        if mask_saturated {
            if let Some(last) = table.last_mut() {
                *last = f32::NAN;
            }
        }
        self.deep = Some((bits, table));
        Ok(self)
    }

    /// Corrects one frame of 16-bit samples (bit depth as given to
    /// [`Correction::with_bit_depth`], 16 if it was not called) into `out`: `U(I) / V`,
    /// divided by the exposure in ms when given. `U` is applied on the raw grid, then the
    /// frame is resampled (as DSO does). Invalid pixels are NaN; a sample beyond the bit
    /// depth is an error.
    pub fn apply_u16(
        &self,
        img: &Image<u16>,
        exposure_ms: Option<f64>,
        out: &mut Image<f32>,
    ) -> Result<(), PhotometricError> {
        let Some((bits, table)) = &self.deep else {
            return Err(PhotometricError::Calibration(
                "Correction::apply_u16 needs Correction::with_bit_depth first".into(),
            ));
        };
        if img.size() != self.in_size {
            return Err(PhotometricError::SizeMismatch {
                what: "the image",
                width: self.in_size.0,
                height: self.in_size.1,
                got_width: img.width(),
                got_height: img.height(),
            });
        }
        if out.size() != self.out_size {
            return Err(PhotometricError::SizeMismatch {
                what: "the output image",
                width: self.out_size.0,
                height: self.out_size.1,
                got_width: out.width(),
                got_height: out.height(),
            });
        }
        let scale = match exposure_ms {
            Some(t) if t > 0.0 && t.is_finite() => (1.0 / t) as f32,
            Some(t) => return Err(PhotometricError::Exposure(t)),
            None => 1.0,
        };
        let mut raw = Vec::with_capacity(img.data().len());
        for &p in img.data() {
            match table.get(p as usize) {
                Some(u) => raw.push(*u),
                None => {
                    return Err(PhotometricError::SampleRange {
                        value: p as u32,
                        bits: *bits,
                    })
                }
            }
        }
        let raw = Image::new(self.in_size.0, self.in_size.1, raw)?;
        match &self.map {
            Some(m) => m.remap_f32_into(&raw, out)?,
            None => out.data_mut().copy_from_slice(raw.data()),
        }
        for (i, o) in out.data_mut().iter_mut().enumerate() {
            let iv = self.inv_v.as_ref().map_or(1.0, |iv| iv[i]);
            *o *= iv * scale;
        }
        Ok(())
    }

    /// Output size.
    pub fn output_size(&self) -> (usize, usize) {
        self.out_size
    }

    /// Corrects one frame into `out` (output size): `U(I) / V`, divided by the exposure in
    /// ms when `exposure_ms` is given. Invalid pixels are NaN.
    pub fn apply(
        &self,
        img: &Image<u8>,
        exposure_ms: Option<f64>,
        out: &mut Image<f32>,
    ) -> Result<(), PhotometricError> {
        if img.size() != self.in_size {
            return Err(PhotometricError::SizeMismatch {
                what: "the image",
                width: self.in_size.0,
                height: self.in_size.1,
                got_width: img.width(),
                got_height: img.height(),
            });
        }
        if out.size() != self.out_size {
            return Err(PhotometricError::SizeMismatch {
                what: "the output image",
                width: self.out_size.0,
                height: self.out_size.1,
                got_width: out.width(),
                got_height: out.height(),
            });
        }
        let scale = match exposure_ms {
            Some(t) if t > 0.0 && t.is_finite() => (1.0 / t) as f32,
            Some(t) => return Err(PhotometricError::Exposure(t)),
            None => 1.0,
        };
        match &self.map {
            Some(m) => m.remap_u8_lut_into(img, &self.lut, out)?,
            None => {
                for (o, &p) in out.data_mut().iter_mut().zip(img.data()) {
                    *o = self.lut[p as usize];
                }
            }
        }
        match &self.inv_v {
            Some(iv) => {
                for (o, &k) in out.data_mut().iter_mut().zip(iv) {
                    *o *= k * scale;
                }
            }
            None if scale != 1.0 => {
                for o in out.data_mut() {
                    *o *= scale;
                }
            }
            None => {}
        }
        Ok(())
    }

    /// Allocating variant of [`Correction::apply`].
    pub fn correct(
        &self,
        img: &Image<u8>,
        exposure_ms: Option<f64>,
    ) -> Result<Image<f32>, PhotometricError> {
        let mut out = Image::filled(self.out_size.0, self.out_size.1, 0f32);
        self.apply(img, exposure_ms, &mut out)?;
        Ok(out)
    }
}

/// The fused fast path of [`Correction`] for quantised output: one pass from the 8-bit frame
/// to 8- or 16-bit output pixels `round(scale * U(I) / (V [t]))`, with `U` held in a 16-bit
/// table (relative precision better than 1e-4 above grey value 8). Needs a rectification map
/// and no saturation masking; invalid pixels are 0.
#[derive(Clone, Debug)]
pub struct QuantizedCorrection {
    map: RectifyMap,
    lut: [u16; 256],
    /// `scale * U(255) / 65535 / 256 / V` per output pixel (0 where invalid).
    base_gain: Vec<f32>,
    max: u32,
}

impl QuantizedCorrection {
    /// Prepares the fused correction; `bits` is 8 or 16 (anything else is an error), `scale`
    /// multiplies `U(I) / V`.
    pub fn new(
        response: &InverseResponse,
        vignette: &Vignette,
        map: RectifyMap,
        scale: f32,
        bits: u8,
    ) -> Result<QuantizedCorrection, PhotometricError> {
        QuantizedCorrection::with_vignette(response, Some(vignette), map, scale, bits)
    }

    /// [`QuantizedCorrection::new`] with an optional vignette: without one `V = 1` (the
    /// response alone is undone).
    pub fn with_vignette(
        response: &InverseResponse,
        vignette: Option<&Vignette>,
        map: RectifyMap,
        scale: f32,
        bits: u8,
    ) -> Result<QuantizedCorrection, PhotometricError> {
        let max = match bits {
            8 => 255,
            16 => 65535,
            other => return Err(PhotometricError::OutputDepth(other)),
        };
        let in_size = map.input_size();
        let u = response.values();
        let u_max = u[255];
        let lut = u.map(|v| (v / u_max * 65535.0).round().clamp(0.0, 65535.0) as u16);
        let vv = match vignette {
            Some(vignette) => {
                vignette.check_size(in_size.width, in_size.height)?;
                vignette
                    .values()
                    .map(|x| if x > 0.0 { x } else { f32::NAN })
            }
            None => Image::filled(in_size.width, in_size.height, 1.0f32),
        };
        let rv = map.remap_f32(&vv)?;
        let k = scale * (u_max / 65535.0 / 256.0) as f32;
        let base_gain = rv
            .data()
            .iter()
            .map(|v| {
                if v.is_finite() && *v > 0.0 {
                    k / v
                } else {
                    0.0
                }
            })
            .collect();
        Ok(QuantizedCorrection {
            map,
            lut,
            base_gain,
            max,
        })
    }

    /// Output size.
    pub fn output_size(&self) -> (usize, usize) {
        let s = self.map.output_size();
        (s.width, s.height)
    }

    /// Corrects one frame; `exposure_ms` divides as well when given (irradiance).
    pub fn apply<T: Copy + Default + TryFrom<u32>>(
        &self,
        img: &Image<u8>,
        exposure_ms: Option<f64>,
        out: &mut Image<T>,
    ) -> Result<(), PhotometricError> {
        let factor = match exposure_ms {
            None => 1.0,
            Some(t) if t > 0.0 && t.is_finite() => (1.0 / t) as f32,
            Some(t) => return Err(PhotometricError::Exposure(t)),
        };
        self.map
            .remap_lut_gain_into(img, &self.lut, &self.base_gain, factor, self.max, out)?;
        Ok(())
    }
}

/// Re-quantises to 8 bits: `round(v * scale)` clamped to 0..255; invalid (NaN) pixels are 0.
pub fn quantize_u8(img: &Image<f32>, scale: f32) -> Image<u8> {
    img.map(|v| {
        if v.is_nan() {
            0
        } else {
            (v * scale).round().clamp(0.0, 255.0) as u8
        }
    })
}

/// Re-quantises to 16 bits: `round(v * scale)` clamped to 0..65535; invalid pixels are 0.
pub fn quantize_u16(img: &Image<f32>, scale: f32) -> Image<u16> {
    img.map(|v| {
        if v.is_nan() {
            0
        } else {
            (v * scale).round().clamp(0.0, 65535.0) as u16
        }
    })
}
