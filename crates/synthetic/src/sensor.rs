//! A realistic image sensor: what a real camera does to the light between the lens and the
//! 8-bit frame, so that every calibration is judged on data as hard as a real camera's.
//!
//! The signal chain of one pixel, in order:
//!
//! 1. **Photons to electrons.** The expected signal is `energy = t V B` in *U-units*: the
//!    linear scale on which the full-well capacity is 255 (so `U(255) = 255` is saturation).
//!    The pixel collects `Poisson(energy * full_well / 255)` electrons (photon shot noise),
//!    plus dark current for hot pixels.
//! 2. **Read noise**: Gaussian, `read_noise` electrons RMS.
//! 3. **Saturation**: the charge is clipped to `[0, full_well]` (full-well clipping; negative
//!    values are the black level).
//! 4. **Response**: the linear value `electrons * 255 / full_well` goes through the camera
//!    response `G = U^-1` to a continuous grey value in `[0, 255]`.
//! 5. **ADC**: Gaussian noise of `adc_noise` grey levels is added after the response, then the
//!    value is rounded and clipped to `[0, 255]` (quantisation and a second saturation).
//! 6. **Defects**: hot pixels (half with strong dark current that grows with the exposure time,
//!    half stuck at 255) and dead pixels (stuck at 0), at fixed positions per sensor.
//! 7. **Compression** (optional): the frame is JPEG-compressed at `jpeg_quality`, as the
//!    benchmark's frames are (quality about 90). [`Sensor::capture`] returns the frame before
//!    compression; writers store it as JPEG, and [`jpeg_roundtrip`] gives the decoded frame for
//!    in-memory experiments.
//!
//! Three presets span real machine-vision cameras ([`NoiseLevel`]):
//!
//! | level | full well | read noise | ADC noise | shot noise at mid grey (U = 128) |
//! |---|---|---|---|---|
//! | low | 20,000 e- | 3 e- | 0.3 grey | 0.20 % |
//! | typical | 10,000 e- | 5 e- | 0.5 grey | 0.28 % |
//! | high | 5,000 e- | 8 e- | 1.0 grey | 0.40 % |
//!
//! Hot and dead pixels are 1e-4 of the pixels each in every preset.

use std::fmt;
use std::str::FromStr;

use rayon::prelude::*;

use crate::camera::{response_value, ResponseLookup};
use crate::float::round;
use crate::Rng;

/// A preset noise level of [`Sensor`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum NoiseLevel {
    /// Large pixels, little noise (full well 20,000 e-).
    Low,
    /// A typical machine-vision sensor (full well 10,000 e-).
    Typical,
    /// Small pixels, much noise (full well 5,000 e-, strong read and ADC noise).
    High,
}

impl NoiseLevel {
    /// Every level, from low to high.
    pub const ALL: [NoiseLevel; 3] = [NoiseLevel::Low, NoiseLevel::Typical, NoiseLevel::High];

    /// The level's name as used on command lines (`low`, `typical`, `high`).
    pub fn name(self) -> &'static str {
        match self {
            NoiseLevel::Low => "low",
            NoiseLevel::Typical => "typical",
            NoiseLevel::High => "high",
        }
    }
}

impl fmt::Display for NoiseLevel {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for NoiseLevel {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim().to_ascii_lowercase().as_str() {
            "low" => Ok(NoiseLevel::Low),
            "typical" => Ok(NoiseLevel::Typical),
            "high" => Ok(NoiseLevel::High),
            other => Err(format!(
                "unknown noise level `{other}`: expected low, typical or high"
            )),
        }
    }
}

/// Which family of sensors a preset belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum SensorFamily {
    /// The machine-vision presets ([`Sensor::preset`]): shot, read and ADC noise, defects.
    Machine,
    /// Photon noise at a fixed gain and a small ADC noise, no defects
    /// ([`Sensor::gain_preset`]).
    Gain,
}

impl SensorFamily {
    /// Both families.
    pub const ALL: [SensorFamily; 2] = [SensorFamily::Machine, SensorFamily::Gain];

    /// The family's name on command lines.
    pub fn name(self) -> &'static str {
        match self {
            SensorFamily::Machine => "machine",
            SensorFamily::Gain => "gain",
        }
    }

    /// The family's preset at `level`.
    pub fn preset(self, level: NoiseLevel) -> Sensor {
        match self {
            SensorFamily::Machine => Sensor::preset(level),
            SensorFamily::Gain => Sensor::gain_preset(level),
        }
    }
}

impl fmt::Display for SensorFamily {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for SensorFamily {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim().to_ascii_lowercase().as_str() {
            "machine" => Ok(SensorFamily::Machine),
            "gain" => Ok(SensorFamily::Gain),
            other => Err(format!(
                "unknown sensor family `{other}`: expected machine or gain"
            )),
        }
    }
}

/// The sensor model (see the module documentation for the signal chain).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sensor {
    /// Full-well capacity in electrons: the charge at which the linear signal is 255 U-units.
    pub full_well: f64,
    /// Read noise in electrons RMS.
    pub read_noise: f64,
    /// Noise added after the response, in grey levels RMS (before quantisation).
    pub adc_noise: f64,
    /// Fraction of hot pixels.
    pub hot_pixels: f64,
    /// Dark current of the hot pixels that are not stuck, in electrons per ms.
    pub hot_current: f64,
    /// Fraction of dead pixels (stuck at 0).
    pub dead_pixels: f64,
    /// JPEG quality the frames are stored with (`None`: lossless).
    pub jpeg_quality: Option<u8>,
    /// Seed of the positions of the defective pixels (fixed for one sensor).
    pub defect_seed: u64,
}

impl Default for Sensor {
    /// The typical preset, frames stored losslessly.
    fn default() -> Self {
        Sensor::preset(NoiseLevel::Typical)
    }
}

/// What a pixel of the sensor is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Defect {
    /// A working pixel.
    None,
    /// Strong dark current, growing with the exposure time.
    Hot,
    /// Always 255.
    StuckHigh,
    /// Always 0.
    Dead,
}

fn hash3(seed: u64, x: u64, y: u64) -> f64 {
    let mut h = seed
        ^ x.wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ y.wrapping_mul(0xC2B2_AE3D_27D4_EB4F).rotate_left(29);
    h ^= h >> 33;
    h = h.wrapping_mul(0xFF51_AFD7_ED55_8CCD);
    h ^= h >> 33;
    h = h.wrapping_mul(0xC4CE_B9FE_1A85_EC53);
    h ^= h >> 33;
    (h >> 11) as f64 / (1u64 << 53) as f64
}

/// A Poisson sample of mean `lambda` (inversion for small means, the normal approximation
/// with continuity for means of 30 and more, where it is accurate to far below the noise).
fn poisson(lambda: f64, rng: &mut Rng) -> f64 {
    if lambda <= 0.0 {
        return 0.0;
    }
    if lambda < 30.0 {
        let l = (-lambda).exp();
        let mut k = 0.0;
        let mut p = 1.0;
        loop {
            p *= rng.uniform();
            if p <= l {
                return k;
            }
            k += 1.0;
        }
    }
    round(lambda + lambda.sqrt() * rng.normal()).max(0.0)
}

impl Sensor {
    /// A preset (see the table in the module documentation), frames stored losslessly.
    pub fn preset(level: NoiseLevel) -> Sensor {
        let (full_well, read_noise, adc_noise) = match level {
            NoiseLevel::Low => (20_000.0, 3.0, 0.3),
            NoiseLevel::Typical => (10_000.0, 5.0, 0.5),
            NoiseLevel::High => (5_000.0, 8.0, 1.0),
        };
        Sensor {
            full_well,
            read_noise,
            adc_noise,
            hot_pixels: 1e-4,
            hot_current: 2000.0,
            dead_pixels: 1e-4,
            jpeg_quality: None,
            defect_seed: 0x5E45_04D5,
        }
    }

    /// The second family of sensors, built unlike the presets: photon noise before the
    /// response with a fixed conversion gain (`gain` electrons per U-unit of signal, no read
    /// noise, no defects) and a small ADC noise after it. The levels span bright-light to
    /// low-light gains:
    ///
    /// | level | gain (e- per U) | ADC noise |
    /// |---|---|---|
    /// | low | 160 | 0.2 grey |
    /// | typical | 40 | 0.3 grey |
    /// | high | 10 | 0.5 grey |
    pub fn gain_preset(level: NoiseLevel) -> Sensor {
        let (gain, adc_noise) = match level {
            NoiseLevel::Low => (160.0, 0.2),
            NoiseLevel::Typical => (40.0, 0.3),
            NoiseLevel::High => (10.0, 0.5),
        };
        Sensor {
            full_well: 255.0 * gain,
            read_noise: 0.0,
            adc_noise,
            hot_pixels: 0.0,
            hot_current: 0.0,
            dead_pixels: 0.0,
            jpeg_quality: None,
            defect_seed: 0,
        }
    }

    /// A sensor without noise, defects or compression (quantisation and saturation only).
    pub fn noiseless() -> Sensor {
        Sensor {
            full_well: f64::INFINITY,
            read_noise: 0.0,
            adc_noise: 0.0,
            hot_pixels: 0.0,
            hot_current: 0.0,
            dead_pixels: 0.0,
            jpeg_quality: None,
            defect_seed: 0,
        }
    }

    /// The same sensor with its frames stored as JPEG of `quality`.
    pub fn with_jpeg(mut self, quality: u8) -> Sensor {
        self.jpeg_quality = Some(quality.clamp(1, 100));
        self
    }

    /// The defect of pixel `(x, y)`.
    pub fn defect(&self, x: usize, y: usize) -> Defect {
        if self.hot_pixels <= 0.0 && self.dead_pixels <= 0.0 {
            return Defect::None;
        }
        let r = hash3(self.defect_seed, x as u64, y as u64);
        if r < self.hot_pixels * 0.5 {
            Defect::Hot
        } else if r < self.hot_pixels {
            Defect::StuckHigh
        } else if r < self.hot_pixels + self.dead_pixels {
            Defect::Dead
        } else {
            Defect::None
        }
    }

    /// One noisy observation of a working pixel: the grey value (before compression) for the
    /// expected linear signal `energy` (U-units), with the inverse response `u`.
    pub fn observe(&self, u: &[f64; 256], energy: f64, rng: &mut Rng) -> u8 {
        self.observe_with_dark(&ResponseLookup::plain(u), energy, 0.0, rng) as u8
    }

    /// The grey value `0 ..= u.len() - 1` of one observation; `u` has `2^k` values with
    /// `U(top) = 255`. The ADC noise is the same fraction of the full scale at every bit
    /// depth: a deeper sensor differs from an 8-bit one by its finer quantisation only.
    fn observe_with_dark(
        &self,
        u: &ResponseLookup<'_>,
        energy: f64,
        dark_e: f64,
        rng: &mut Rng,
    ) -> u32 {
        let top = u.top() as f64;
        let linear = if self.full_well.is_finite() {
            let mean_e = energy.max(0.0) * self.full_well / 255.0 + dark_e;
            let electrons = poisson(mean_e, rng) + self.read_noise * rng.normal();
            electrons.clamp(0.0, self.full_well) * 255.0 / self.full_well
        } else {
            energy.clamp(0.0, 255.0)
        };
        let grey = u.value(linear) + self.adc_noise * (top / 255.0) * rng.normal();
        round(grey).clamp(0.0, top) as u32
    }

    /// Standard deviation of a working pixel's grey value for the expected signal `energy`
    /// (U-units), to first order (shot, read and ADC noise, quantisation), ignoring saturation.
    pub fn grey_sigma(&self, u: &[f64; 256], energy: f64) -> f64 {
        let e = energy.clamp(0.0, 255.0);
        let var_linear = if self.full_well.is_finite() {
            let scale = 255.0 / self.full_well;
            e * scale + (self.read_noise * scale).powi(2)
        } else {
            0.0
        };
        let h = 0.5;
        let slope = (response_value(u, (e + h).min(255.0)) - response_value(u, (e - h).max(0.0)))
            / ((e + h).min(255.0) - (e - h).max(0.0));
        (slope * slope * var_linear + self.adc_noise * self.adc_noise + 1.0 / 12.0).sqrt()
    }

    /// Captures one frame of `width x height` (row-major 8-bit grey, before compression):
    /// `energy(x, y)` is the expected linear signal `t V B` of the pixel in U-units, `u` the
    /// inverse response, `exposure_ms` the exposure time (for the dark current of hot pixels)
    /// and `frame_seed` makes the noise of this frame (the same seed gives the same frame).
    pub fn capture(
        &self,
        u: &[f64; 256],
        width: usize,
        height: usize,
        exposure_ms: f64,
        frame_seed: u64,
        energy: impl Fn(usize, usize) -> f64 + Sync,
    ) -> Vec<u8> {
        self.capture_levels(u, width, height, exposure_ms, frame_seed, energy, |v| {
            v as u8
        })
    }

    /// [`Sensor::capture`] for a sensor of `bits` bits (8 to 16): the values `0 ..= 2^bits -
    /// 1` in the low bits of 16-bit samples, with the inverse response `u` of `2^bits` values
    /// (`U(2^bits - 1) = 255`, for example [`crate::camera::ResponseCurve::table_bits`]).
    /// Full well, shot, read and ADC noise (as a fraction of the full scale) are those of
    /// the 8-bit sensor; the quantisation is finer. Deep frames are stored losslessly (16-bit
    /// PNG): the JPEG quality does not apply to them.
    pub fn capture_deep(
        &self,
        u: &[f64],
        width: usize,
        height: usize,
        exposure_ms: f64,
        frame_seed: u64,
        energy: impl Fn(usize, usize) -> f64 + Sync,
    ) -> Vec<u16> {
        self.capture_levels(u, width, height, exposure_ms, frame_seed, energy, |v| {
            v as u16
        })
    }

    #[allow(clippy::too_many_arguments)]
    fn capture_levels<T: Copy + Default + Send>(
        &self,
        u: &[f64],
        width: usize,
        height: usize,
        exposure_ms: f64,
        frame_seed: u64,
        energy: impl Fn(usize, usize) -> f64 + Sync,
        to_sample: impl Fn(u32) -> T + Sync,
    ) -> Vec<T> {
        let top = (u.len() - 1) as u32;
        let u = &ResponseLookup::new(u);
        let mut out = vec![T::default(); width * height];
        out.par_chunks_mut(width.max(1))
            .enumerate()
            .for_each(|(y, row)| {
                let mut rng = Rng::derive(frame_seed, y as u64);
                for (x, px) in row.iter_mut().enumerate() {
                    let e = energy(x, y);
                    *px = to_sample(match self.defect(x, y) {
                        Defect::None => self.observe_with_dark(u, e, 0.0, &mut rng),
                        Defect::Hot => self.observe_with_dark(
                            u,
                            e,
                            self.hot_current * exposure_ms.max(0.0),
                            &mut rng,
                        ),
                        Defect::StuckHigh => top,
                        Defect::Dead => 0,
                    });
                }
            });
        out
    }

    /// The frame as the camera stores it: [`jpeg_roundtrip`] at the sensor's JPEG quality, or
    /// unchanged when it stores losslessly.
    pub fn store(
        &self,
        width: usize,
        height: usize,
        frame: Vec<u8>,
    ) -> Result<Vec<u8>, image::ImageError> {
        match self.jpeg_quality {
            Some(q) => jpeg_roundtrip(width, height, &frame, q),
            None => Ok(frame),
        }
    }
}

/// Encodes an 8-bit grey frame as baseline JPEG of `quality` and decodes it again: the
/// compression artefacts a camera storing JPEG adds.
pub fn jpeg_roundtrip(
    width: usize,
    height: usize,
    frame: &[u8],
    quality: u8,
) -> Result<Vec<u8>, image::ImageError> {
    let bytes = jpeg_encode(width, height, frame, quality)?;
    let img = image::load_from_memory_with_format(&bytes, image::ImageFormat::Jpeg)?;
    Ok(img.into_luma8().into_raw())
}

/// Encodes an 8-bit grey frame as baseline JPEG of `quality` (1-100).
pub fn jpeg_encode(
    width: usize,
    height: usize,
    frame: &[u8],
    quality: u8,
) -> Result<Vec<u8>, image::ImageError> {
    use image::ImageEncoder;
    let mut out = Vec::with_capacity(frame.len() / 4);
    let enc = image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, quality.clamp(1, 100));
    enc.write_image(
        frame,
        width as u32,
        height as u32,
        image::ExtendedColorType::L8,
    )?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::ground_truth_response;

    #[test]
    fn noise_grows_with_the_level_and_matches_the_prediction() {
        let u = ground_truth_response();
        let mut last = 0.0;
        for level in NoiseLevel::ALL {
            let s = Sensor::preset(level);
            let mut rng = Rng::new(3);
            let n = 20_000;
            let vals: Vec<f64> = (0..n)
                .map(|_| s.observe(&u, 100.0, &mut rng) as f64)
                .collect();
            let mean = vals.iter().sum::<f64>() / n as f64;
            let sd = (vals.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n as f64).sqrt();
            let pred = s.grey_sigma(&u, 100.0);
            assert!((sd / pred - 1.0).abs() < 0.05, "{level}: {sd} vs {pred}");
            assert!(sd > last);
            last = sd;
            // unbiased in the middle of the range: the mean is the response of the mean
            let g = response_value(&u, 100.0);
            assert!((mean - g).abs() < 0.05, "{level}: mean {mean} vs {g}");
        }
    }

    #[test]
    fn saturation_clips_at_255_and_black_at_0() {
        let u = ground_truth_response();
        let s = Sensor::preset(NoiseLevel::High);
        let mut rng = Rng::new(1);
        assert!((0..1000).all(|_| s.observe(&u, 1e4, &mut rng) >= 250));
        assert!((0..1000).all(|_| s.observe(&u, 0.0, &mut rng) <= 5));
    }

    #[test]
    fn defects_are_where_the_seed_puts_them() {
        let s = Sensor {
            hot_pixels: 0.01,
            dead_pixels: 0.01,
            ..Sensor::preset(NoiseLevel::Low)
        };
        let u = ground_truth_response();
        let f = s.capture(&u, 200, 100, 5.0, 9, |_, _| 60.0);
        let stuck = (0..100)
            .flat_map(|y| (0..200).map(move |x| (x, y)))
            .filter(|&(x, y)| s.defect(x, y) == Defect::StuckHigh)
            .count();
        assert!(stuck > 20 && stuck < 200, "{stuck}");
        for y in 0..100 {
            for x in 0..200 {
                match s.defect(x, y) {
                    Defect::Dead => assert_eq!(f[y * 200 + x], 0),
                    Defect::StuckHigh => assert_eq!(f[y * 200 + x], 255),
                    Defect::Hot => assert!(f[y * 200 + x] > 150),
                    Defect::None => assert!((50..120).contains(&f[y * 200 + x])),
                }
            }
        }
    }

    #[test]
    fn jpeg_changes_the_frame_a_little() {
        let u = ground_truth_response();
        let s = Sensor::preset(NoiseLevel::Typical).with_jpeg(90);
        let f = s.capture(&u, 64, 48, 5.0, 2, |x, y| 20.0 + x as f64 + y as f64);
        let j = s.store(64, 48, f.clone()).unwrap();
        let diff: f64 = f
            .iter()
            .zip(&j)
            .map(|(a, b)| (*a as f64 - *b as f64).abs())
            .sum::<f64>()
            / f.len() as f64;
        assert!(diff > 0.05 && diff < 3.0, "{diff}");
    }
}
