//! The frame pipeline: one decoded frame in, its rectified (and corrected) PNG and its
//! times.txt row out; run on all cores by the sequence reader.

use camera_model::{Image, ImageSize};
use dataset_io::{GrayImage, PngSpeed};

use super::encode_error;
use super::pixels::{encode_float, rescale_sample, Pixels};
use crate::{Observer, PipelineError, Result, WithContext};

/// A rectified frame: timestamp (s, and ns when exact), exposure (ms), PNG bytes.
pub(super) type OutFrame = (f64, Option<i64>, Option<f64>, Vec<u8>);

/// [`eval_metrics::BACKWARDS_EPOCH`] in nanoseconds.
const BACKWARDS_EPOCH_NS: i64 = 2_000_000_000_000_000_000;

/// What every frame goes through.
pub(super) struct FramePipeline<'a> {
    pub pixels: &'a Pixels,
    pub out_size: ImageSize,
    /// Bits per output pixel, 8 or 16.
    pub depth: u8,
    /// Bits per sample of the input frames as stored.
    pub in_bits: u32,
    /// Bits of the values in 16-bit input frames.
    pub bits: u32,
    pub irradiance: bool,
    pub reverse: bool,
    pub speed: PngSpeed,
}

impl FramePipeline<'_> {
    /// The frame's PNG and times.txt row; progress to `observer`.
    pub fn process(
        &self,
        frame: dataset_io::NativeFrame,
        observer: &dyn Observer,
    ) -> Result<OutFrame> {
        let label = || format!("frame {} ({})", frame.index, frame.name);
        let sample_max = (1u32 << self.bits) - 1;
        if let GrayImage::U16(img) = &frame.image {
            if let Some(v) = img.data().iter().find(|v| **v as u32 > sample_max) {
                return Err(PipelineError::Invalid(format!(
                        "{}: pixel value {v} does not fit in --bit-depth {} (at most {sample_max}); are the values in the high bits? then the bit depth is 16",
                        label(),
                        self.bits
                    )));
            }
        }
        let png = self.png(&frame, &label)?;
        let reverse = self.reverse;
        let t = if reverse {
            eval_metrics::BACKWARDS_EPOCH - frame.timestamp
        } else {
            frame.timestamp
        };
        // nanoseconds stay integers, mapped as the seconds are
        let ns = frame
            .timestamp_ns
            .map(|ns| if reverse { BACKWARDS_EPOCH_NS - ns } else { ns });
        let e = if self.irradiance {
            Some(1.0)
        } else {
            frame.exposure_ms
        };
        observer.advance(1);
        Ok((t, ns, e, png))
    }

    /// The frame rectified (and corrected) and encoded.
    fn png(&self, frame: &dataset_io::NativeFrame, label: &dyn Fn() -> String) -> Result<Vec<u8>> {
        let (w, h) = (self.out_size.width, self.out_size.height);
        let (depth, speed, bits) = (self.depth, self.speed, self.bits);
        let exposure = if self.irradiance {
            frame.exposure_ms
        } else {
            None
        };
        Ok(match (self.pixels, &frame.image) {
            (Pixels::Geometric(map), GrayImage::U8(img)) => {
                let out = map.remap_u8(img)?;
                if depth == 16 {
                    let wide: Vec<u16> = out.data().iter().map(|v| *v as u16 * 257).collect();
                    dataset_io::encode_png_u16(w, h, &wide, speed).map_err(encode_error)?
                } else {
                    dataset_io::encode_png_u8(w, h, 1, out.data(), speed).map_err(encode_error)?
                }
            }
            (Pixels::Geometric(map), GrayImage::U16(img)) => {
                let out = map.remap_u16(img)?;
                if depth == 16 {
                    // the values keep their bit depth
                    dataset_io::encode_png_u16(w, h, out.data(), speed).map_err(encode_error)?
                } else {
                    let narrow: Vec<u8> = out
                        .data()
                        .iter()
                        .map(|v| rescale_sample(*v, bits, 255.0) as u8)
                        .collect();
                    dataset_io::encode_png_u8(w, h, 1, &narrow, speed).map_err(encode_error)?
                }
            }
            (Pixels::Fast(c, _), GrayImage::U8(img)) => {
                if depth == 16 {
                    let mut out = Image::filled(w, h, 0u16);
                    c.apply(img, exposure, &mut out).with_context(label)?;
                    dataset_io::encode_png_u16(w, h, out.data(), speed).map_err(encode_error)?
                } else {
                    let mut out = Image::filled(w, h, 0u8);
                    c.apply(img, exposure, &mut out).with_context(label)?;
                    dataset_io::encode_png_u8(w, h, 1, out.data(), speed).map_err(encode_error)?
                }
            }
            (Pixels::Photometric(c, scale), GrayImage::U8(img)) => {
                let mut out = Image::filled(w, h, 0f32);
                c.apply(img, exposure, &mut out).with_context(label)?;
                encode_float(&out, *scale, depth, speed)?
            }
            (Pixels::Deep(c, scale), GrayImage::U16(img)) => {
                let mut out = Image::filled(w, h, 0f32);
                c.apply_u16(img, exposure, &mut out).with_context(label)?;
                encode_float(&out, *scale, depth, speed)?
            }
            (_, image) => {
                return Err(PipelineError::Invalid(format!(
                    "{}: {}-bit frame in a {}-bit sequence",
                    label(),
                    image.bits(),
                    self.in_bits
                )))
            }
        })
    }
}
