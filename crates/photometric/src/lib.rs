//! Photometric calibration of the TUM monoVO benchmark (paper section 2.3): the inverse
//! response `U` ([`InverseResponse`], pcalib.txt), the vignette `V` ([`Vignette`],
//! vignette.png), and the correction `I -> U(I) / V` or irradiance `U(I) / (t V)`
//! ([`Correction`]), optionally fused with a rectification map; exposure ratios measured
//! from the images, to check logged exposures and to estimate missing ones ([`exposure`]).
//!
//! # Example
//!
//! ```
//! use camera_model::Image;
//! use photometric::{Correction, InverseResponse, Vignette};
//!
//! // a gamma-like response and a radial vignette on a 64x48 image
//! let mut u = [0.0; 256];
//! for (k, v) in u.iter_mut().enumerate() {
//!     *v = 255.0 * (k as f64 / 255.0).powf(2.2);
//! }
//! let response = InverseResponse::new(u)?;
//! let vig = Vignette::from_values(Image::from_fn(64, 48, |x, y| {
//!     let r2 = ((x as f32 - 31.5).powi(2) + (y as f32 - 23.5).powi(2)) / 1600.0;
//!     1.0 - 0.3 * r2
//! }))?;
//! let corr = Correction::new(&response, Some(&vig), None, (64, 48), true)?;
//! let frame = Image::filled(64, 48, 128u8);
//! let irradiance = corr.correct(&frame, Some(10.0))?; // U(128) / (10 ms * V)
//! assert!(irradiance.get(0, 0).unwrap() > irradiance.get(32, 24).unwrap());
//! # Ok::<(), photometric::PhotometricError>(())
//! ```
#![deny(missing_docs)]

mod correct;
mod error;
pub mod exposure;
pub mod marker;
mod noise;
mod response;
mod response_calib;
mod smoothing;
mod stats;
mod vignette;
mod vignette_calib;

pub use correct::{quantize_u16, quantize_u8, Correction, QuantizedCorrection};
pub use error::PhotometricError;
pub use noise::NoiseModel;
pub use response::InverseResponse;
pub use response_calib::{
    calibrate_response, calibrate_response_deep, CandidateScore, Estimator, HeldOutScores,
    NoiseBin, ResponseCalibration, ResponseOptions, Stop, Weighting, DEFAULT_MAX_PIXELS, MAX_KNOTS,
};
pub use smoothing::SmoothingChoice;
pub use vignette::{vignette_errors, Vignette};
pub use vignette_calib::{
    calibrate_vignette, PlaneFrame, PlaneFrames, PlaneImage, PlanePose, VignetteCalibration,
    VignetteOptions,
};
