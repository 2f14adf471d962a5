//! The camera models: projection of a point in the camera frame to a pixel and back.

use std::f64::consts::{FRAC_PI_2, PI};
use std::fmt;

use crate::sphere;

/// Pinhole intrinsics in pixels.
///
/// Pixel centres sit at integer coordinates: the centre of the top-left pixel is `(0, 0)`,
/// its area spans `[-0.5, 0.5]^2`, and the centre of the bottom-right pixel of a `w x h`
/// image is `(w - 1, h - 1)`.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Intrinsics {
    /// Focal length along x, in pixels.
    pub fx: f64,
    /// Focal length along y, in pixels.
    pub fy: f64,
    /// Principal point x, in pixels (pixel centres at integers).
    pub cx: f64,
    /// Principal point y, in pixels (pixel centres at integers).
    pub cy: f64,
}

impl Intrinsics {
    /// Maps a pixel to normalised image coordinates `((u - cx) / fx, (v - cy) / fy)`.
    #[inline]
    pub fn pixel_to_normalized(&self, pixel: [f64; 2]) -> [f64; 2] {
        [
            (pixel[0] - self.cx) / self.fx,
            (pixel[1] - self.cy) / self.fy,
        ]
    }

    /// Maps normalised image coordinates to a pixel.
    #[inline]
    pub fn normalized_to_pixel(&self, n: [f64; 2]) -> [f64; 2] {
        [self.fx * n[0] + self.cx, self.fy * n[1] + self.cy]
    }

    /// Horizontal and vertical field of view in degrees of a pinhole camera with these
    /// intrinsics and the given image size (edges of the border pixels included).
    pub fn field_of_view_deg(&self, width: usize, height: usize) -> (f64, f64) {
        let left = ((self.cx + 0.5) / self.fx).atan();
        let right = ((width as f64 - 0.5 - self.cx) / self.fx).atan();
        let top = ((self.cy + 0.5) / self.fy).atan();
        let bottom = ((height as f64 - 0.5 - self.cy) / self.fy).atan();
        ((left + right).to_degrees(), (top + bottom).to_degrees())
    }
}

/// A camera model in pixel units.
///
/// All models share the convention of [`Intrinsics`]: pixel centres at integer coordinates.
/// `project` takes a point in the camera frame (`z` along the optical axis, `x` right,
/// `y` down) and `unproject` returns a unit-length viewing direction.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum CameraModel {
    /// Ideal pinhole camera.
    Pinhole(Intrinsics),
    /// The FOV (ATAN) model of Devernay and Faugeras, as used by the benchmark (paper eq. 1-4).
    Fov {
        /// Pinhole part.
        k: Intrinsics,
        /// Field-of-view parameter omega, in radians. Zero means an ideal pinhole.
        omega: f64,
    },
    /// Radial-tangential (OpenCV `k1 k2 p1 p2`) distortion.
    RadTan {
        /// Pinhole part.
        k: Intrinsics,
        /// Radial and tangential coefficients `[k1, k2, p1, p2]`.
        coeffs: [f64; 4],
    },
    /// Equidistant fisheye (DSO's `EquiDistant`): `theta_d = theta (1 + k1 theta^2 + ... + k4 theta^8)`.
    EquiDistant {
        /// Pinhole part.
        k: Intrinsics,
        /// Polynomial coefficients `[k1, k2, k3, k4]`.
        coeffs: [f64; 4],
    },
    /// Kannala-Brandt fisheye (DSO's `KannalaBrandt`), the same polynomial in the angle as
    /// [`CameraModel::EquiDistant`].
    KannalaBrandt {
        /// Pinhole part.
        k: Intrinsics,
        /// Polynomial coefficients `[k0, k1, k2, k3]`.
        coeffs: [f64; 4],
    },
    /// Double Sphere (Usenko, Demmel, Cremers 2018; Basalt's `ds`, Kalibr's `ds`): two unit
    /// spheres `xi` apart, then the unified projection with `alpha`; closed-form inverse.
    DoubleSphere {
        /// Pinhole part.
        k: Intrinsics,
        /// Distance between the two sphere centres.
        xi: f64,
        /// Unified-projection parameter in `[0, 1]`.
        alpha: f64,
    },
    /// Extended Unified Camera Model (Khomutenko et al. 2016, as in Usenko et al. 2018;
    /// Basalt's `eucm`, Kalibr's `eucm`): the unified projection on an ellipsoid `beta`.
    Eucm {
        /// Pinhole part.
        k: Intrinsics,
        /// Unified-projection parameter in `[0, 1]`.
        alpha: f64,
        /// Ellipsoid parameter, positive.
        beta: f64,
    },
    /// The unified model of Mei and Rives (Kalibr's `omni`, OpenCV's `omnidir`): the unit
    /// sphere seen from `xi` behind its centre, then radial-tangential distortion of the
    /// image-plane coordinates (all zero for Kalibr's `omni-none` and Basalt's `ucm`).
    Unified {
        /// Pinhole part (Kalibr's `gamma` focal lengths).
        k: Intrinsics,
        /// Mirror parameter, `>= 0` (0 is a pinhole).
        xi: f64,
        /// Radial-tangential coefficients `[k1, k2, p1, p2]`.
        coeffs: [f64; 4],
    },
}

impl fmt::Display for CameraModel {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let k = self.intrinsics();
        write!(
            f,
            "{} fx={:.3} fy={:.3} cx={:.3} cy={:.3}",
            self.name(),
            k.fx,
            k.fy,
            k.cx,
            k.cy
        )?;
        match self {
            CameraModel::Pinhole(_) => Ok(()),
            CameraModel::Fov { omega, .. } => write!(f, " omega={omega:.6}"),
            CameraModel::RadTan { coeffs: c, .. } => write!(
                f,
                " k1={:.6} k2={:.6} p1={:.6} p2={:.6}",
                c[0], c[1], c[2], c[3]
            ),
            CameraModel::EquiDistant { coeffs: c, .. }
            | CameraModel::KannalaBrandt { coeffs: c, .. } => write!(
                f,
                " k1={:.6} k2={:.6} k3={:.6} k4={:.6}",
                c[0], c[1], c[2], c[3]
            ),
            CameraModel::DoubleSphere { xi, alpha, .. } => {
                write!(f, " xi={xi:.6} alpha={alpha:.6}")
            }
            CameraModel::Eucm { alpha, beta, .. } => write!(f, " alpha={alpha:.6} beta={beta:.6}"),
            CameraModel::Unified { xi, coeffs: c, .. } => write!(
                f,
                " xi={xi:.6} k1={:.6} k2={:.6} p1={:.6} p2={:.6}",
                c[0], c[1], c[2], c[3]
            ),
        }
    }
}

/// Largest viewing angle (from the optical axis) that the fisheye models accept.
const MAX_FISHEYE_THETA: f64 = PI - 1e-6;

impl CameraModel {
    /// The model's name as written in camera.txt (`Pinhole`, `FOV`, `RadTan`, `EquiDistant`,
    /// `KannalaBrandt`; monovo's own `DoubleSphere`, `EUCM` and `Omni`, which DSO cannot read).
    pub fn name(&self) -> &'static str {
        match self {
            CameraModel::Pinhole(_) => "Pinhole",
            CameraModel::Fov { .. } => "FOV",
            CameraModel::RadTan { .. } => "RadTan",
            CameraModel::EquiDistant { .. } => "EquiDistant",
            CameraModel::KannalaBrandt { .. } => "KannalaBrandt",
            CameraModel::DoubleSphere { .. } => "DoubleSphere",
            CameraModel::Eucm { .. } => "EUCM",
            CameraModel::Unified { .. } => "Omni",
        }
    }

    /// The pinhole part of the model.
    pub fn intrinsics(&self) -> Intrinsics {
        match self {
            CameraModel::Pinhole(k)
            | CameraModel::Fov { k, .. }
            | CameraModel::RadTan { k, .. }
            | CameraModel::EquiDistant { k, .. }
            | CameraModel::KannalaBrandt { k, .. }
            | CameraModel::DoubleSphere { k, .. }
            | CameraModel::Eucm { k, .. }
            | CameraModel::Unified { k, .. } => *k,
        }
    }

    /// The distortion parameters after `fx fy cx cy`, as written in camera.txt.
    pub fn distortion(&self) -> Vec<f64> {
        match self {
            CameraModel::Pinhole(_) => vec![0.0],
            CameraModel::Fov { omega, .. } => vec![*omega],
            CameraModel::RadTan { coeffs, .. }
            | CameraModel::EquiDistant { coeffs, .. }
            | CameraModel::KannalaBrandt { coeffs, .. } => coeffs.to_vec(),
            CameraModel::DoubleSphere { xi, alpha, .. } => vec![*xi, *alpha],
            CameraModel::Eucm { alpha, beta, .. } => vec![*alpha, *beta],
            CameraModel::Unified { xi, coeffs, .. } => {
                vec![*xi, coeffs[0], coeffs[1], coeffs[2], coeffs[3]]
            }
        }
    }

    /// Why the model's parameters are unusable (non-finite or non-positive focal lengths, or a
    /// spherical model's parameters outside their range), or `None` when they are fine.
    pub fn parameter_problem(&self) -> Option<String> {
        let k = self.intrinsics();
        if ![k.fx, k.fy, k.cx, k.cy].iter().all(|v| v.is_finite()) || k.fx <= 0.0 || k.fy <= 0.0 {
            return Some(format!(
                "focal lengths must be positive and all intrinsics finite, got fx={} fy={} cx={} cy={}",
                k.fx, k.fy, k.cx, k.cy
            ));
        }
        if let Some(v) = self.distortion().iter().find(|v| !v.is_finite()) {
            return Some(format!("`{v}` is not a finite number"));
        }
        match self {
            CameraModel::DoubleSphere { xi, alpha, .. } => sphere::check_ds(*xi, *alpha),
            CameraModel::Eucm { alpha, beta, .. } => sphere::check_eucm(*alpha, *beta),
            CameraModel::Unified { xi, .. } => sphere::check_unified(*xi),
            _ => None,
        }
    }

    /// Whether this is an ideal pinhole (including FOV with `omega == 0`).
    pub fn is_pinhole(&self) -> bool {
        match self {
            CameraModel::Pinhole(_) => true,
            CameraModel::Fov { omega, .. } => *omega == 0.0,
            CameraModel::RadTan { coeffs, .. } => coeffs.iter().all(|c| *c == 0.0),
            _ => false,
        }
    }

    /// Projects a point in the camera frame to a pixel. `None` when the point has no image
    /// (behind a perspective camera, at the projection centre, or outside a fisheye's range).
    #[inline]
    pub fn project(&self, point_in_camera: [f64; 3]) -> Option<[f64; 2]> {
        let [x, y, z] = point_in_camera;
        if !(x.is_finite() && y.is_finite() && z.is_finite()) {
            return None;
        }
        match self {
            CameraModel::EquiDistant { k, coeffs } | CameraModel::KannalaBrandt { k, coeffs } => {
                let r = (x * x + y * y).sqrt();
                if r == 0.0 && z <= 0.0 {
                    return None;
                }
                let theta = r.atan2(z);
                if theta > MAX_FISHEYE_THETA {
                    return None;
                }
                let theta_d = fisheye_poly(coeffs, theta);
                let m = if r > 1e-300 {
                    [theta_d * x / r, theta_d * y / r]
                } else {
                    [0.0, 0.0]
                };
                Some(k.normalized_to_pixel(m))
            }
            CameraModel::DoubleSphere { k, xi, alpha } => {
                Some(k.normalized_to_pixel(sphere::ds_project(*xi, *alpha, [x, y, z])?))
            }
            CameraModel::Eucm { k, alpha, beta } => {
                Some(k.normalized_to_pixel(sphere::eucm_project(*alpha, *beta, [x, y, z])?))
            }
            CameraModel::Unified { k, xi, coeffs } => {
                let m = sphere::unified_project(*xi, [x, y, z])?;
                let d = if coeffs.iter().all(|c| *c == 0.0) {
                    m
                } else {
                    radtan_distort(coeffs, m).0
                };
                Some(k.normalized_to_pixel(d))
            }
            _ => {
                if z <= 0.0 || !z.is_finite() {
                    return None;
                }
                let n = [x / z, y / z];
                let d = self.distort_normalized(n)?;
                Some(self.intrinsics().normalized_to_pixel(d))
            }
        }
    }

    /// Projects normalised pinhole coordinates `(x/z, y/z)` of a point in front of the camera.
    #[inline]
    pub fn project_normalized(&self, n: [f64; 2]) -> Option<[f64; 2]> {
        self.project([n[0], n[1], 1.0])
    }

    /// Applies the distortion to normalised pinhole coordinates (perspective models only).
    fn distort_normalized(&self, n: [f64; 2]) -> Option<[f64; 2]> {
        match self {
            CameraModel::Pinhole(_) => Some(n),
            CameraModel::Fov { omega, .. } => {
                let f = fov_distort_factor(*omega, (n[0] * n[0] + n[1] * n[1]).sqrt());
                Some([n[0] * f, n[1] * f])
            }
            CameraModel::RadTan { coeffs, .. } => Some(radtan_distort(coeffs, n).0),
            CameraModel::EquiDistant { coeffs, .. } | CameraModel::KannalaBrandt { coeffs, .. } => {
                let r = (n[0] * n[0] + n[1] * n[1]).sqrt();
                let theta = r.atan();
                let s = if r > 1e-300 {
                    fisheye_poly(coeffs, theta) / r
                } else {
                    1.0
                };
                Some([n[0] * s, n[1] * s])
            }
            CameraModel::DoubleSphere { .. }
            | CameraModel::Eucm { .. }
            | CameraModel::Unified { .. } => {
                let p = self.project([n[0], n[1], 1.0])?;
                Some(self.intrinsics().pixel_to_normalized(p))
            }
        }
    }

    /// Whether the distortion is locally one-to-one at the normalised pinhole coordinates
    /// `n`: beyond the fold of a RadTan polynomial (or where a fisheye polynomial stops
    /// increasing) the image repeats mirrored, and such pixels are not a valid view.
    pub(crate) fn unfolded_at(&self, n: [f64; 2]) -> bool {
        match self {
            CameraModel::Pinhole(_) | CameraModel::Fov { .. } => true,
            CameraModel::RadTan { coeffs, .. } => {
                let (_, j) = radtan_distort(coeffs, n);
                j[0] > 0.0 && j[3] > 0.0 && j[0] * j[3] - j[1] * j[2] > 0.0
            }
            CameraModel::EquiDistant { coeffs, .. } | CameraModel::KannalaBrandt { coeffs, .. } => {
                let theta = (n[0] * n[0] + n[1] * n[1]).sqrt().atan();
                fisheye_poly_derivative(coeffs, theta) > 0.0
                    && (theta == 0.0 || fisheye_poly(coeffs, theta) > 0.0)
            }
            CameraModel::DoubleSphere { .. } | CameraModel::Eucm { .. } => {
                self.project([n[0], n[1], 1.0]).is_some()
            }
            CameraModel::Unified { xi, coeffs, .. } => {
                match sphere::unified_project(*xi, [n[0], n[1], 1.0]) {
                    Some(m) if coeffs.iter().any(|c| *c != 0.0) => {
                        let (_, j) = radtan_distort(coeffs, m);
                        j[0] > 0.0 && j[3] > 0.0 && j[0] * j[3] - j[1] * j[2] > 0.0
                    }
                    Some(_) => true,
                    None => false,
                }
            }
        }
    }

    /// Returns the unit-length viewing direction of a pixel, or `None` where the model has
    /// no inverse (outside the FOV model's 90 degree range, or where a fisheye polynomial
    /// or the RadTan iteration does not invert).
    pub fn unproject(&self, pixel: [f64; 2]) -> Option<[f64; 3]> {
        let k = self.intrinsics();
        let m = k.pixel_to_normalized(pixel);
        if !(m[0].is_finite() && m[1].is_finite()) {
            return None;
        }
        let ray = match self {
            CameraModel::Pinhole(_) => [m[0], m[1], 1.0],
            CameraModel::Fov { omega, .. } => {
                let rd = (m[0] * m[0] + m[1] * m[1]).sqrt();
                let f = fov_undistort_factor(*omega, rd)?;
                [m[0] * f, m[1] * f, 1.0]
            }
            CameraModel::RadTan { coeffs, .. } => {
                let n = radtan_undistort(coeffs, m)?;
                [n[0], n[1], 1.0]
            }
            CameraModel::EquiDistant { coeffs, .. } | CameraModel::KannalaBrandt { coeffs, .. } => {
                let theta_d = (m[0] * m[0] + m[1] * m[1]).sqrt();
                if theta_d < 1e-300 {
                    [0.0, 0.0, 1.0]
                } else {
                    let theta = fisheye_invert(coeffs, theta_d)?;
                    let s = theta.sin() / theta_d;
                    [m[0] * s, m[1] * s, theta.cos()]
                }
            }
            CameraModel::DoubleSphere { xi, alpha, .. } => sphere::ds_unproject(*xi, *alpha, m)?,
            CameraModel::Eucm { alpha, beta, .. } => sphere::eucm_unproject(*alpha, *beta, m)?,
            CameraModel::Unified { xi, coeffs, .. } => {
                let u = if coeffs.iter().all(|c| *c == 0.0) {
                    m
                } else {
                    radtan_undistort(coeffs, m)?
                };
                sphere::unified_unproject(*xi, u)?
            }
        };
        let norm = (ray[0] * ray[0] + ray[1] * ray[1] + ray[2] * ray[2]).sqrt();
        if !norm.is_finite() || norm == 0.0 {
            return None;
        }
        Some([ray[0] / norm, ray[1] / norm, ray[2] / norm])
    }

    /// Unprojects a pixel to normalised pinhole coordinates `(x/z, y/z)`; `None` when the
    /// viewing direction is not in front of the camera.
    pub fn unproject_normalized(&self, pixel: [f64; 2]) -> Option<[f64; 2]> {
        let r = self.unproject(pixel)?;
        if r[2] <= 1e-12 {
            return None;
        }
        Some([r[0] / r[2], r[1] / r[2]])
    }

    /// The same model with every pixel-unit quantity scaled for an image resized from
    /// `from` to `to` (pixel centres at integers are kept consistent).
    pub fn rescaled(&self, from: (usize, usize), to: (usize, usize)) -> CameraModel {
        let sx = to.0 as f64 / from.0 as f64;
        let sy = to.1 as f64 / from.1 as f64;
        let k = self.intrinsics();
        let k2 = Intrinsics {
            fx: k.fx * sx,
            fy: k.fy * sy,
            cx: (k.cx + 0.5) * sx - 0.5,
            cy: (k.cy + 0.5) * sy - 0.5,
        };
        self.with_intrinsics(k2)
    }

    /// The same model with other intrinsics.
    pub fn with_intrinsics(&self, k2: Intrinsics) -> CameraModel {
        match self {
            CameraModel::Pinhole(_) => CameraModel::Pinhole(k2),
            CameraModel::Fov { omega, .. } => CameraModel::Fov {
                k: k2,
                omega: *omega,
            },
            CameraModel::RadTan { coeffs, .. } => CameraModel::RadTan {
                k: k2,
                coeffs: *coeffs,
            },
            CameraModel::EquiDistant { coeffs, .. } => CameraModel::EquiDistant {
                k: k2,
                coeffs: *coeffs,
            },
            CameraModel::KannalaBrandt { coeffs, .. } => CameraModel::KannalaBrandt {
                k: k2,
                coeffs: *coeffs,
            },
            CameraModel::DoubleSphere { xi, alpha, .. } => CameraModel::DoubleSphere {
                k: k2,
                xi: *xi,
                alpha: *alpha,
            },
            CameraModel::Eucm { alpha, beta, .. } => CameraModel::Eucm {
                k: k2,
                alpha: *alpha,
                beta: *beta,
            },
            CameraModel::Unified { xi, coeffs, .. } => CameraModel::Unified {
                k: k2,
                xi: *xi,
                coeffs: *coeffs,
            },
        }
    }
}

/// FOV model: factor from undistorted radius `r_u` to distorted radius (paper eq. 1).
#[inline]
fn fov_distort_factor(omega: f64, ru: f64) -> f64 {
    if omega == 0.0 {
        return 1.0;
    }
    let t2 = 2.0 * (omega * 0.5).tan();
    if ru < 1e-10 {
        // limit of atan(ru * t2) / (omega * ru) for ru -> 0
        t2 / omega
    } else {
        (ru * t2).atan() / (omega * ru)
    }
}

/// FOV model: factor from distorted radius `r_d` to undistorted radius (paper eq. 3).
#[inline]
fn fov_undistort_factor(omega: f64, rd: f64) -> Option<f64> {
    if omega == 0.0 {
        return Some(1.0);
    }
    if rd * omega.abs() >= FRAC_PI_2 {
        return None;
    }
    let t2 = 2.0 * (omega * 0.5).tan();
    if rd < 1e-10 {
        Some(omega / t2)
    } else {
        Some((rd * omega).tan() / (rd * t2))
    }
}

/// The FOV model's closed-form map of a distorted normalised radius to the undistorted one,
/// `T(x) = tan(x omega) / (2 tan(omega / 2))`, used for the closed-form output K.
pub(crate) fn fov_undistort_radius(omega: f64, rd: f64) -> Option<f64> {
    fov_undistort_factor(omega, rd).map(|f| f * rd)
}

#[inline]
fn fisheye_poly(c: &[f64; 4], theta: f64) -> f64 {
    let t2 = theta * theta;
    theta * (1.0 + t2 * (c[0] + t2 * (c[1] + t2 * (c[2] + t2 * c[3]))))
}

#[inline]
fn fisheye_poly_derivative(c: &[f64; 4], theta: f64) -> f64 {
    let t2 = theta * theta;
    1.0 + t2 * (3.0 * c[0] + t2 * (5.0 * c[1] + t2 * (7.0 * c[2] + t2 * 9.0 * c[3])))
}

/// Inverts `theta_d = poly(theta)` by safeguarded Newton iteration on `[0, pi)`; `None`
/// when no monotone solution exists.
fn fisheye_invert(c: &[f64; 4], theta_d: f64) -> Option<f64> {
    let mut theta = theta_d.min(MAX_FISHEYE_THETA);
    for _ in 0..50 {
        let f = fisheye_poly(c, theta) - theta_d;
        let df = fisheye_poly_derivative(c, theta);
        if df <= 0.0 || !df.is_finite() {
            return None;
        }
        let step = f / df;
        theta = (theta - step).clamp(0.0, MAX_FISHEYE_THETA);
        if step.abs() < 1e-14 {
            break;
        }
    }
    let residual = (fisheye_poly(c, theta) - theta_d).abs();
    if residual > 1e-9 * theta_d.max(1.0) || fisheye_poly_derivative(c, theta) <= 0.0 {
        return None;
    }
    Some(theta)
}

/// RadTan distortion of normalised coordinates and its 2x2 Jacobian (row-major).
#[inline]
fn radtan_distort(c: &[f64; 4], n: [f64; 2]) -> ([f64; 2], [f64; 4]) {
    let [k1, k2, p1, p2] = *c;
    let [x, y] = n;
    let r2 = x * x + y * y;
    let radial = 1.0 + r2 * (k1 + k2 * r2);
    let d = [
        x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
        y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y,
    ];
    // d radial / d x = (2 k1 + 4 k2 r2) x
    let dr = 2.0 * k1 + 4.0 * k2 * r2;
    let j = [
        radial + x * dr * x + 2.0 * p1 * y + 6.0 * p2 * x,
        x * dr * y + 2.0 * p1 * x + 2.0 * p2 * y,
        y * dr * x + 2.0 * p1 * x + 2.0 * p2 * y,
        radial + y * dr * y + 6.0 * p1 * y + 2.0 * p2 * x,
    ];
    (d, j)
}

/// Inverts RadTan distortion by Newton iteration; `None` when it does not converge.
fn radtan_undistort(c: &[f64; 4], m: [f64; 2]) -> Option<[f64; 2]> {
    let mut n = m;
    for _ in 0..100 {
        let (d, j) = radtan_distort(c, n);
        let e = [d[0] - m[0], d[1] - m[1]];
        let det = j[0] * j[3] - j[1] * j[2];
        if det.abs() < 1e-12 || !det.is_finite() {
            return None;
        }
        let step = [
            (j[3] * e[0] - j[1] * e[1]) / det,
            (-j[2] * e[0] + j[0] * e[1]) / det,
        ];
        n = [n[0] - step[0], n[1] - step[1]];
        if step[0].abs() + step[1].abs() < 1e-15 {
            break;
        }
    }
    let (d, j) = radtan_distort(c, n);
    let err = (d[0] - m[0]).abs() + (d[1] - m[1]).abs();
    // Reject solutions beyond the fold of the distortion (Jacobian no longer positive).
    if err > 1e-10 || j[0] * j[3] - j[1] * j[2] <= 0.0 || j[0] <= 0.0 || j[3] <= 0.0 {
        return None;
    }
    Some(n)
}
