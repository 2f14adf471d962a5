//! Cameras shared by the tests.
use camera_model::{CameraFile, CameraModel, ImageSize, Intrinsics};

/// The benchmark's narrow-lens camera (the DESIGN.md test vector), 1280x1024.
pub const DATASET_CAMERA: &str = "0.535719308086809 0.669566858850269 0.493248545285398 0.500408664348414 0.897966326944875\n1280 1024\ncrop\n640 480\n";

pub fn dataset_camera() -> CameraFile {
    CameraFile::parse(DATASET_CAMERA).unwrap()
}

/// One camera of every model with realistic parameters and its image size.
pub fn all_models() -> Vec<(CameraModel, ImageSize)> {
    let fov = dataset_camera();
    vec![
        (fov.input.clone(), fov.input_size),
        (
            CameraModel::Pinhole(Intrinsics {
                fx: 320.0,
                fy: 310.0,
                cx: 319.5,
                cy: 239.5,
            }),
            ImageSize::new(640, 480),
        ),
        (
            // EuRoC cam0-like radial-tangential camera
            CameraModel::RadTan {
                k: Intrinsics {
                    fx: 458.654,
                    fy: 457.296,
                    cx: 367.215,
                    cy: 248.375,
                },
                coeffs: [-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05],
            },
            ImageSize::new(752, 480),
        ),
        (
            // TUM-VI-like equidistant fisheye
            CameraModel::EquiDistant {
                k: Intrinsics {
                    fx: 190.978,
                    fy: 190.973,
                    cx: 254.932,
                    cy: 256.897,
                },
                coeffs: [0.0034823894, 0.0007150348, -0.0020532361, 0.0002029367],
            },
            ImageSize::new(512, 512),
        ),
        (
            CameraModel::KannalaBrandt {
                k: Intrinsics {
                    fx: 380.0,
                    fy: 380.0,
                    cx: 320.0,
                    cy: 240.0,
                },
                coeffs: [-0.01, 0.002, 0.0, 0.0],
            },
            ImageSize::new(640, 480),
        ),
    ]
}

/// A pixel grid over the whole image, borders included.
pub fn pixel_grid(size: ImageSize, step: usize) -> Vec<[f64; 2]> {
    let mut xs: Vec<usize> = (0..size.width).step_by(step).collect();
    xs.push(size.width - 1);
    let mut ys: Vec<usize> = (0..size.height).step_by(step).collect();
    ys.push(size.height - 1);
    let mut out = Vec::new();
    for &y in &ys {
        for &x in &xs {
            out.push([x as f64, y as f64]);
        }
    }
    out
}
