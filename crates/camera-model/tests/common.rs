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
        (
            // Basalt's TUM-VI cam0 (data/tumvi_512_ds_calib.json)
            CameraModel::DoubleSphere {
                k: Intrinsics {
                    fx: 158.28600034966977,
                    fy: 158.2743455478755,
                    cx: 254.96116578191653,
                    cy: 256.8894394501779,
                },
                xi: -0.17213086034353243,
                alpha: 0.5931177593944744,
            },
            ImageSize::new(512, 512),
        ),
        (
            // Basalt's EuRoC cam0 (data/euroc_eucm_calib.json)
            CameraModel::Eucm {
                k: Intrinsics {
                    fx: 460.76484651566468,
                    fy: 459.4051018049483,
                    cx: 365.8937161309615,
                    cy: 249.33499869752445,
                },
                alpha: 0.5903365915227143,
                beta: 1.127468196965374,
            },
            ImageSize::new(752, 480),
        ),
        (
            // Kalibr's wiki example omni-radtan cam0 (kalibr-wiki Yaml-formats.md)
            CameraModel::Unified {
                k: Intrinsics {
                    fx: 770.7765589675081,
                    fy: 770.5559465743702,
                    cx: 362.1635863019238,
                    cy: 247.88842203540298,
                },
                xi: 0.671111239995445,
                coeffs: [
                    -0.3524047797899213,
                    0.16207450943423096,
                    0.00036919741711283124,
                    0.000988523976270618,
                ],
            },
            ImageSize::new(752, 480),
        ),
    ]
}

/// The number of models in [`all_models`].
pub const MODELS: usize = 8;

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
