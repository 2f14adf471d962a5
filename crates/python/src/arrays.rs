//! numpy arrays to and from the crates' `Image`: an image handed to Python is moved into the
//! numpy array (no copy); an array handed to Rust is copied once into an owned `Image`
//! (the crates' images own their pixels).

use camera_model::{CameraModel, Image, ImageSize, OutputMode};
use numpy::ndarray::Array2;
use numpy::{Element, IntoPyArray, PyArray2, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;

use crate::errors::{Error, Result};

/// Moves `img` into an H x W numpy array.
pub fn image_to_py<'py, T: Element + Copy>(
    py: Python<'py>,
    img: Image<T>,
) -> Bound<'py, PyArray2<T>> {
    let (w, h) = img.size();
    match Array2::from_shape_vec((h, w), img.into_data()) {
        Ok(a) => a.into_pyarray(py),
        // unreachable: an Image holds w * h pixels
        Err(_) => PyArray2::zeros(py, [0, 0], false),
    }
}

/// Copies an H x W array into an `Image`.
pub fn image_from_py<T: Element + Copy>(a: &PyReadonlyArray2<'_, T>) -> Result<Image<T>> {
    let shape = a.shape();
    let (h, w) = (shape[0], shape[1]);
    let data = match a.as_slice() {
        Ok(s) => s.to_vec(),
        Err(_) => a.as_array().iter().copied().collect(),
    };
    Image::new(w, h, data).map_err(Error::from)
}

/// An image size from `(w, h)`, `[w, h]` or `"WxH"`.
pub fn size_arg(obj: &Bound<'_, PyAny>) -> PyResult<ImageSize> {
    if let Ok(s) = obj.extract::<String>() {
        return Ok(s.parse::<ImageSize>().map_err(Error::from)?);
    }
    let (w, h): (usize, usize) = obj.extract().map_err(|_| {
        Error::format("size: expected (width, height) or \"WIDTHxHEIGHT\" such as \"640x480\"")
    })?;
    Ok(ImageSize::new(w, h).validate().map_err(Error::from)?)
}

/// An output camera from `"crop"`, `"full"`, `"none"`, `"fx fy cx cy 0"` or a sequence of
/// four numbers `fx fy cx cy` (relative to the output size when `cx < 1 and cy < 1`, else
/// pixels), as `--pinhole` reads them.
pub fn output_arg(obj: &Bound<'_, PyAny>) -> PyResult<OutputMode> {
    if let Ok(s) = obj.extract::<String>() {
        return Ok(s.parse::<OutputMode>().map_err(Error::from)?);
    }
    let v: Vec<f64> = obj.extract().map_err(|_| {
        Error::format(
            "pinhole: expected \"crop\", \"full\", \"none\", \"fx fy cx cy 0\" or four numbers (fx, fy, cx, cy)",
        )
    })?;
    match v[..] {
        [fx, fy, cx, cy] | [fx, fy, cx, cy, 0.0] => Ok(format!("{fx} {fy} {cx} {cy} 0")
            .parse::<OutputMode>()
            .map_err(Error::from)?),
        _ => Err(Error::format(format!(
            "pinhole: expected four numbers (fx, fy, cx, cy), got {}",
            v.len()
        ))
        .into()),
    }
}

/// The camera model's parameters in pixels, in the order of [`model_from_params`].
pub fn model_params(m: &CameraModel) -> Vec<f64> {
    let k = m.intrinsics();
    let mut v = vec![k.fx, k.fy, k.cx, k.cy];
    match m {
        CameraModel::Pinhole(_) => {}
        CameraModel::Fov { omega, .. } => v.push(*omega),
        CameraModel::RadTan { coeffs, .. }
        | CameraModel::EquiDistant { coeffs, .. }
        | CameraModel::KannalaBrandt { coeffs, .. } => v.extend(coeffs),
        CameraModel::DoubleSphere { xi, alpha, .. } => v.extend([*xi, *alpha]),
        CameraModel::Eucm { alpha, beta, .. } => v.extend([*alpha, *beta]),
        CameraModel::Unified { xi, coeffs, .. } => {
            v.push(*xi);
            v.extend(coeffs);
        }
    }
    v
}

/// The names `Camera(model, params)` takes, with the parameters each needs after `fx fy cx cy`.
pub const MODELS: &[(&str, &str)] = &[
    ("pinhole", ""),
    ("fov", "omega"),
    ("radtan", "k1 k2 p1 p2"),
    ("equidistant", "k1 k2 k3 k4"),
    ("kannala_brandt", "k0 k1 k2 k3"),
    ("double_sphere", "xi alpha"),
    ("eucm", "alpha beta"),
    ("unified", "xi k1 k2 p1 p2"),
];

/// A camera model from its name and its parameters in pixels (`fx fy cx cy` and the model's).
pub fn model_from_params(name: &str, p: &[f64]) -> Result<CameraModel> {
    let lname = name.to_ascii_lowercase().replace('-', "_");
    let lname = match lname.as_str() {
        "ds" | "doublesphere" => "double_sphere",
        "kb4" | "kannalabrandt" => "kannala_brandt",
        "omni" | "ucm" => "unified",
        "atan" => "fov",
        other => other,
    };
    let Some(&(canon, rest)) = MODELS.iter().find(|(n, _)| *n == lname) else {
        return Err(Error::format(format!(
            "camera model `{name}`: expected one of {}",
            MODELS.iter().map(|m| m.0).collect::<Vec<_>>().join(", ")
        )));
    };
    let need = 4 + rest.split_whitespace().count();
    if p.len() != need {
        return Err(Error::format(format!(
            "camera model `{canon}` takes {need} parameters `fx fy cx cy{}{rest}` in pixels, got {}",
            if rest.is_empty() { "" } else { " " },
            p.len()
        )));
    }
    if let Some(bad) = p.iter().find(|v| !v.is_finite()) {
        return Err(Error::format(format!(
            "camera model `{canon}`: parameter {bad} is not finite"
        )));
    }
    let k = camera_model::Intrinsics {
        fx: p[0],
        fy: p[1],
        cx: p[2],
        cy: p[3],
    };
    let c4 = |i: usize| [p[i], p[i + 1], p[i + 2], p[i + 3]];
    let m = match canon {
        "pinhole" => CameraModel::Pinhole(k),
        "fov" => CameraModel::Fov { k, omega: p[4] },
        "radtan" => CameraModel::RadTan { k, coeffs: c4(4) },
        "equidistant" => CameraModel::EquiDistant { k, coeffs: c4(4) },
        "kannala_brandt" => CameraModel::KannalaBrandt { k, coeffs: c4(4) },
        "double_sphere" => CameraModel::DoubleSphere {
            k,
            xi: p[4],
            alpha: p[5],
        },
        "eucm" => CameraModel::Eucm {
            k,
            alpha: p[4],
            beta: p[5],
        },
        _ => CameraModel::Unified {
            k,
            xi: p[4],
            coeffs: c4(5),
        },
    };
    if let Some(problem) = m.parameter_problem() {
        return Err(Error::format(format!("camera model `{canon}`: {problem}")));
    }
    Ok(m)
}

/// The name of `m` as [`model_from_params`] takes it.
pub fn model_name(m: &CameraModel) -> &'static str {
    match m {
        CameraModel::Pinhole(_) => "pinhole",
        CameraModel::Fov { .. } => "fov",
        CameraModel::RadTan { .. } => "radtan",
        CameraModel::EquiDistant { .. } => "equidistant",
        CameraModel::KannalaBrandt { .. } => "kannala_brandt",
        CameraModel::DoubleSphere { .. } => "double_sphere",
        CameraModel::Eucm { .. } => "eucm",
        CameraModel::Unified { .. } => "unified",
    }
}
