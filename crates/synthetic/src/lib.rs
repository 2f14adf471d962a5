//! Synthetic data with known ground truth for every monovo stage, always from a fixed seed:
//! benchmark-like camera paths and drifted VO estimates ([`trajectory`]), whole synthetic
//! benchmark results of several methods ([`results`]), the ground-truth camera, response,
//! and vignette ([`camera`]), a realistic sensor with shot, read and ADC noise, saturation,
//! defects and JPEG ([`sensor`]), marker-plane vignette data ([`plane`]), rendered sequences
//! and exposure sweeps ([`scene`]), and a seedable random number generator ([`Rng`]) that gives the same data on every platform.
//!
//! # Example
//!
//! ```
//! use synthetic::trajectory::{benchmark_path, estimate, tum_text, Drift, EstimateConfig, PathConfig};
//!
//! let path = benchmark_path(7, &PathConfig { frames: 500, ..PathConfig::default() });
//! let gt_text = path.ground_truth_sync();           // groundtruthSync.txt, NaN in the middle
//! let cfg = EstimateConfig {
//!     drift: Drift { scale_jumps: vec![(250, 0.8)], ..Drift::default() },
//!     ..EstimateConfig::default()
//! };
//! let est_text = tum_text(&estimate(&path, &cfg, 7)); // a run whose e_s is 0.8
//! assert_eq!(gt_text.lines().count(), 500);
//! assert_eq!(est_text.lines().count(), 500);
//! ```
#![deny(missing_docs)]

pub mod camera;
mod float;
pub mod plane;
pub mod results;
mod rng;
pub mod scene;
pub mod sensor;
pub mod trajectory;

pub use rng::Rng;
