//! The map and what it carries: the frames remapped alone, or with the photometric
//! correction (fused and quantised for 8-bit frames, in floats where saturation is masked or
//! the frames are 16-bit), and the scale of the corrected output.

use camera_model::{Image, RectifyMap};
use dataset_io::{GrayImage, PngSpeed, Sequence};
use photometric::{quantize_u16, quantize_u8, Correction, InverseResponse, QuantizedCorrection};

use super::input::Input;
use super::{encode_error, RectifyJob};
use crate::{Observer, PipelineError, Result};

/// How the frames' pixels are made.
pub(super) enum Pixels {
    /// The frames remapped alone, by the job's map.
    Geometric(RectifyMap),
    /// The general float path (needed for saturation masking).
    Photometric(Box<Correction>, f32),
    /// The fused one-pass path.
    Fast(Box<QuantizedCorrection>, f32),
    /// 16-bit input frames: `U` applied exactly at their bit depth, then resampled.
    Deep(Box<Correction>, f32),
}

impl Pixels {
    /// The photometric output's scale (None for geometric output).
    pub fn scale(&self) -> Option<f32> {
        match self {
            Pixels::Photometric(_, s) | Pixels::Fast(_, s) | Pixels::Deep(_, s) => Some(*s),
            Pixels::Geometric(_) => None,
        }
    }
}

/// The photometric calibration the correction needs.
pub(super) struct Calibration<'a> {
    pub response: Option<&'a InverseResponse>,
    pub vignette: Option<&'a photometric::Vignette>,
}

/// The pixels of the job: geometric, or corrected with its scale and where that scale comes
/// from (`--scale`, no clipping, or the data for 8-bit irradiance).
pub(super) fn choose(
    args: &RectifyJob,
    input: &Input,
    map: RectifyMap,
    calibration: &Calibration<'_>,
    indices: &[usize],
    observer: &dyn Observer,
) -> Result<(Pixels, Option<String>)> {
    let (bits, out_depth) = (input.bits, input.out_depth);
    if !(args.photometric || args.irradiance) {
        return Ok((Pixels::Geometric(map), None));
    }
    let Some(resp) = calibration.response else {
        return Err(PipelineError::Invalid(format!(
            "{}: --photometric needs pcalib.txt (the inverse response)",
            args.sequence.display()
        )));
    };
    let vignette = calibration.vignette;
    if vignette.is_none() {
        observer.warn(&format!(
            "{}: no vignette.png: undoing the response alone (V = 1); DSO refuses its photometric mode without a vignette",
            args.sequence.display()
        ));
    }
    let deep = input.deep();
    let in_size = (map.input_size().width, map.input_size().height);
    // the float correction, made only where it is needed (16-bit frames, --mask-saturated,
    // the data's irradiance scale): the 8-bit frames of the others go through the quantised
    // one alone, and each costs a copy of the map and a remap of the vignette before the
    // first frame
    let float_correction = || -> Result<Correction> {
        let corr = Correction::new(
            resp,
            vignette,
            Some(map.clone()),
            in_size,
            args.mask_saturated,
        )?;
        Ok(if deep {
            corr.with_bit_depth(resp, bits, args.mask_saturated)?
        } else {
            corr
        })
    };
    let mut corr = None;
    let max16 = if out_depth == 16 { 65535.0 } else { 255.0 };
    // largest value: U(white) / (min V [* t_min]): nothing clips
    let t_min = if args.irradiance {
        input.seq.times().exposure_range().map_or(1.0, |r| r.0)
    } else {
        1.0
    };
    let v_min = vignette.map_or(1.0, |v| v.min_positive());
    let max_value = resp.max_value() as f32 / (v_min * t_min as f32);
    let (scale, scale_source) = match args.scale {
        Some(s) => (s, "--scale".to_string()),
        None if args.irradiance && out_depth == 8 => {
            let corr = corr.insert(float_correction()?);
            let (w, h) = (input.out_size.width, input.out_size.height);
            let sample = |f: &dataset_io::NativeFrame| -> Result<Image<f32>> {
                let mut out = Image::filled(w, h, 0f32);
                match &f.image {
                    GrayImage::U8(img) => corr.apply(img, f.exposure_ms, &mut out)?,
                    GrayImage::U16(img) => corr.apply_u16(img, f.exposure_ms, &mut out)?,
                }
                Ok(out)
            };
            match irradiance_scale(&input.seq, indices, args.half_decode, &sample, max16)? {
                Some((s, n)) => (
                    s,
                    format!(
                        "from the data: the {}th percentile of {n} sampled frames maps to {max16}",
                        SCALE_QUANTILE * 100.0
                    ),
                ),
                None => (
                    max16 / max_value,
                    "no clipping (no valid sampled pixel)".to_string(),
                ),
            }
        }
        None => (
            max16 / max_value,
            "the largest without clipping".to_string(),
        ),
    };
    let pixels = if deep || args.mask_saturated {
        let corr = match corr {
            Some(c) => c,
            None => float_correction()?,
        };
        if deep {
            Pixels::Deep(Box::new(corr), scale)
        } else {
            Pixels::Photometric(Box::new(corr), scale)
        }
    } else {
        Pixels::Fast(
            Box::new(QuantizedCorrection::with_vignette(
                resp, vignette, map, scale, out_depth,
            )?),
            scale,
        )
    };
    Ok((pixels, Some(scale_source)))
}

/// Number of frames sampled for the 8-bit irradiance scale.
const SCALE_SAMPLE_FRAMES: usize = 16;
/// The fraction of sampled irradiance values at or below the value that maps to 255.
const SCALE_QUANTILE: f64 = 0.999;

/// The scale of 8-bit irradiance output from the data: `max / q` with `q` the
/// [`SCALE_QUANTILE`] quantile of the valid corrected values of up to
/// [`SCALE_SAMPLE_FRAMES`] frames spread over `indices`. A worst-case bound (the brightest
/// value in the darkest vignette corner at the shortest exposure) leaves most frames a few
/// dozen grey levels; the quantile uses the range the frames actually have.
fn irradiance_scale(
    seq: &Sequence,
    indices: &[usize],
    half: bool,
    correct: &(dyn Fn(&dataset_io::NativeFrame) -> Result<Image<f32>> + Sync),
    max: f32,
) -> Result<Option<(f32, usize)>> {
    let n = indices.len().clamp(1, SCALE_SAMPLE_FRAMES);
    let picks: Vec<usize> = (0..n)
        .map(|i| indices[i * indices.len() / n])
        .collect::<std::collections::BTreeSet<_>>()
        .into_iter()
        .collect();
    let mut values: Vec<f32> = Vec::new();
    seq.process_scaled(
        &picks,
        picks.len(),
        half,
        |f| correct(&f),
        |img| {
            values.extend(img.data().iter().copied().filter(|v| v.is_finite()));
            Ok(())
        },
    )?;
    if values.is_empty() {
        return Ok(None);
    }
    let k = (((values.len() - 1) as f64) * SCALE_QUANTILE).round() as usize;
    let (_, q, _) = values.select_nth_unstable_by(k, f32::total_cmp);
    let q = *q;
    Ok((q.is_finite() && q > 0.0).then_some((max / q, picks.len())))
}

/// Scales a `bits`-bit sample value to the full range of `max` (8 or 16 bits out).
pub(super) fn rescale_sample(v: u16, bits: u32, max: f32) -> u16 {
    let top = ((1u32 << bits) - 1) as f32;
    (v as f32 * max / top).round().clamp(0.0, max) as u16
}

/// Quantises a corrected float frame to 8 or 16 bits.
pub(super) fn encode_float(
    out: &Image<f32>,
    scale: f32,
    depth: u8,
    speed: PngSpeed,
) -> Result<Vec<u8>> {
    let (w, h) = out.size();
    Ok(if depth == 16 {
        dataset_io::encode_png_u16(w, h, quantize_u16(out, scale).data(), speed)
            .map_err(encode_error)?
    } else {
        dataset_io::encode_png_u8(w, h, 1, quantize_u8(out, scale).data(), speed)
            .map_err(encode_error)?
    })
}
