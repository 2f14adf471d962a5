//! Camera models of the TUM monoVO benchmark and of DSO, the camera.txt format, and
//! rectification of fisheye frames to a pinhole camera of any field of view and size.
//!
//! * [`CameraModel`]: FOV (ATAN, the benchmark's model, with its closed-form inverse),
//!   Pinhole, RadTan, EquiDistant and KannalaBrandt, and the wide-angle Double Sphere, EUCM and
//!   unified (omni) models with closed-form inverses; [`CameraModel::project`] and
//!   [`CameraModel::unproject`].
//! * [`CameraFile`]: parse and write camera.txt (DSO prefixes and legacy lines, relative and
//!   absolute intrinsics, output `crop`, `full`, `none` or an explicit pinhole).
//! * [`CalibrationFile`]: the calibration files of the field's tools (Kalibr camchain.yaml,
//!   EuRoC sensor.yaml, Basalt calibration.json, KITTI calib.txt, and camera.txt), the format
//!   told from the content.
//! * [`output_intrinsics`] and [`RectifyMap`]: the output pinhole and a precomputed bilinear
//!   map that remaps `u8` or `f32` [`Image`]s.
//!
//! **Pixel convention.** Pixel centres sit at integer coordinates: the top-left pixel's
//! centre is `(0, 0)` and covers `[-0.5, 0.5]^2`. Relative intrinsics in files are converted
//! with `fx_px = fx * w`, `cx_px = cx * w - 0.5`. Points in the camera frame have `x` to the
//! right, `y` down and `z` along the optical axis.
//!
//! # Example
//!
//! ```
//! use camera_model::{CameraFile, RectifyMap, Image};
//!
//! let file = CameraFile::parse(
//!     "FOV 0.535719308086809 0.669566858850269 0.493248545285398 0.500408664348414 0.897966326944875\n\
//!      1280 1024\ncrop\n640 480\n",
//! )?;
//! let map = RectifyMap::for_mode(&file.input, file.input_size, &file.output, file.output_size)?;
//! let k = map.camera();
//! assert!((k.fx - 277.524).abs() < 1e-3 && (k.cy - 240.036).abs() < 1e-3);
//! assert_eq!(map.invalid_count(), 0);
//!
//! let raw = Image::from_fn(1280, 1024, |x, y| ((x + y) % 256) as u8);
//! let rectified = map.remap_u8(&raw)?;
//! assert_eq!(rectified.size(), (640, 480));
//! # Ok::<(), camera_model::CameraError>(())
//! ```
#![deny(missing_docs)]

mod calibration;
mod camera_file;
mod error;
mod fixed;
mod image;
mod model;
mod rectify;
mod sphere;

pub use calibration::{
    invert_rigid, CalibratedCamera, CalibrationFile, CalibrationFormat, Transform,
};
pub use camera_file::{
    intrinsics_from_file_values, intrinsics_to_file_values, CameraFile, ImageSize, OutputMode,
};
pub use error::CameraError;
pub use fixed::avx2_enabled;
pub use image::Image;
pub use model::{CameraModel, Intrinsics};
pub use rectify::{output_intrinsics, output_notes, RectifyMap};
