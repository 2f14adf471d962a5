//! `monovo.Camera` (the models, vectorised project and unproject) and `monovo.Rectifier`
//! (the rectification map and remap of `monovo rectify`).

use std::path::PathBuf;

use camera_model::{
    CalibrationFile, CalibrationFormat, CameraModel, ImageSize, OutputMode, RectifyMap,
};
use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyArray2, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;

use crate::arrays::{
    image_from_py, image_to_py, model_from_params, model_name, model_params, output_arg, size_arg,
};
use crate::errors::{Error, Result};

/// A camera model in pixels (pixel centres at integer coordinates: the top-left pixel's
/// centre is (0, 0)) and, when known, its image size.
///
/// `Camera(model, params, size=None)` with `model` one of `pinhole`, `fov`, `radtan`,
/// `equidistant`, `kannala_brandt`, `double_sphere` (`ds`), `eucm`, `unified` (`omni`) and
/// `params` = `fx fy cx cy` and the model's own (`omega`; `k1 k2 p1 p2`; `k1 k2 k3 k4`;
/// `k0 k1 k2 k3`; `xi alpha`; `alpha beta`; `xi k1 k2 p1 p2`); `Camera.from_file` reads any
/// calibration file monovo reads. `project` and `unproject` work on N x 3 and N x 2 arrays
/// (NaN where there is no result); `K` is the 3 x 3 pinhole part.
#[pyclass(module = "monovo", name = "Camera", frozen)]
#[derive(Clone)]
pub struct PyCamera {
    pub(crate) model: CameraModel,
    pub(crate) size: Option<ImageSize>,
}

/// Reads camera `cam` of a calibration file of any format (camera.txt, Kalibr camchain.yaml,
/// EuRoC sensor.yaml, Basalt calibration.json, KITTI calib.txt, ETH3D calibration.txt).
pub fn read_camera_file(
    path: &std::path::Path,
    cam: usize,
    size: Option<ImageSize>,
) -> Result<camera_model::CameraFile> {
    let text = dataset_io::read_text(path)?;
    let ctx = |e: camera_model::CameraError| Error::from(e).context(&path.display().to_string());
    let cal = CalibrationFile::parse(&text).map_err(ctx)?;
    let index = match cal.format {
        CalibrationFormat::EurocSensor
        | CalibrationFormat::CameraTxt
        | CalibrationFormat::Eth3d => 0,
        _ => cam,
    };
    cal.camera_file(index, size).map_err(ctx)
}

/// `(N, k)` rows of an array that may also be a single point of shape `(k,)`.
fn rows_of(obj: &Bound<'_, PyAny>, k: usize, what: &str) -> PyResult<(Vec<f64>, bool)> {
    let np = obj.py().import("numpy")?;
    let a = np.call_method1("asarray", (obj, np.getattr("float64")?))?;
    let ndim: usize = a.getattr("ndim")?.extract()?;
    let single = ndim == 1;
    let a = if single {
        a.call_method1("reshape", ((1, -1),))?
    } else {
        a
    };
    let arr: PyReadonlyArray2<'_, f64> = a
        .extract()
        .map_err(|_| Error::format(format!("{what}: expected an N x {k} array of numbers")))?;
    if arr.shape()[1] != k {
        return Err(Error::format(format!(
            "{what}: expected an N x {k} array, got shape {}",
            a.getattr("shape")?.str()?
        ))
        .into());
    }
    let data = match arr.as_slice() {
        Ok(s) => s.to_vec(),
        Err(_) => arr.as_array().iter().copied().collect(),
    };
    Ok((data, single))
}

/// `n` rows of `k` values as an array of shape (n, k), or (k,) for a single point.
fn rows_to_py<'py>(
    py: Python<'py>,
    data: Vec<f64>,
    k: usize,
    single: bool,
) -> PyResult<Bound<'py, PyAny>> {
    let n = data.len() / k;
    let a = Array2::from_shape_vec((n, k), data).map_err(|e| Error::format(e.to_string()))?;
    let a = a.into_pyarray(py).into_any();
    if single {
        a.call_method1("reshape", (k,))
    } else {
        Ok(a)
    }
}

#[pymethods]
impl PyCamera {
    /// A camera from its model name and parameters in pixels (see `monovo.Camera`).
    #[new]
    #[pyo3(signature = (model, params, size=None))]
    fn new(model: &str, params: Vec<f64>, size: Option<&Bound<'_, PyAny>>) -> PyResult<PyCamera> {
        Ok(PyCamera {
            model: model_from_params(model, &params)?,
            size: size.map(size_arg).transpose()?,
        })
    }

    /// Camera `cam` of a calibration file of any format that monovo reads.
    #[staticmethod]
    #[pyo3(signature = (path, cam=0, size=None))]
    fn from_file(path: PathBuf, cam: usize, size: Option<&Bound<'_, PyAny>>) -> PyResult<PyCamera> {
        let size = size.map(size_arg).transpose()?;
        let f = read_camera_file(&path, cam, size)?;
        Ok(PyCamera {
            model: f.input,
            size: Some(f.input_size),
        })
    }

    /// An ideal pinhole camera.
    #[staticmethod]
    #[pyo3(signature = (fx, fy, cx, cy, size=None))]
    fn pinhole(
        fx: f64,
        fy: f64,
        cx: f64,
        cy: f64,
        size: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<PyCamera> {
        PyCamera::new("pinhole", vec![fx, fy, cx, cy], size)
    }

    /// The model's name (`pinhole`, `fov`, `radtan`, `equidistant`, `kannala_brandt`,
    /// `double_sphere`, `eucm`, `unified`).
    #[getter]
    fn model(&self) -> &'static str {
        model_name(&self.model)
    }
    /// The parameters in pixels: `fx fy cx cy` and the model's own.
    #[getter]
    fn params(&self) -> Vec<f64> {
        model_params(&self.model)
    }
    /// The pinhole part as a 3 x 3 matrix `[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`.
    #[getter(K)]
    fn k<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let k = self.model.intrinsics();
        let a = numpy::ndarray::arr2(&[[k.fx, 0.0, k.cx], [0.0, k.fy, k.cy], [0.0, 0.0, 1.0]]);
        a.into_pyarray(py)
    }
    /// The image size `(width, height)`, or `None`.
    #[getter]
    fn size(&self) -> Option<(usize, usize)> {
        self.size.map(|s| (s.width, s.height))
    }
    /// Image width, or `None`.
    #[getter]
    fn width(&self) -> Option<usize> {
        self.size.map(|s| s.width)
    }
    /// Image height, or `None`.
    #[getter]
    fn height(&self) -> Option<usize> {
        self.size.map(|s| s.height)
    }

    /// Projects points in the camera frame, shape (N, 3) or (3,), to pixels, (N, 2) or (2,);
    /// NaN where a point does not project (behind the camera, outside the model's domain).
    fn project<'py>(
        &self,
        py: Python<'py>,
        points: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (data, single) = rows_of(points, 3, "points")?;
        let m = &self.model;
        let out = py.detach(|| {
            data.chunks_exact(3)
                .flat_map(|p| m.project([p[0], p[1], p[2]]).unwrap_or([f64::NAN; 2]))
                .collect::<Vec<f64>>()
        });
        rows_to_py(py, out, 2, single)
    }

    /// Unprojects pixels, shape (N, 2) or (2,), to unit-length rays in the camera frame,
    /// (N, 3) or (3,); NaN where a pixel has no ray in the model.
    fn unproject<'py>(
        &self,
        py: Python<'py>,
        pixels: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (data, single) = rows_of(pixels, 2, "pixels")?;
        let m = &self.model;
        let out = py.detach(|| {
            data.chunks_exact(2)
                .flat_map(|p| m.unproject([p[0], p[1]]).unwrap_or([f64::NAN; 3]))
                .collect::<Vec<f64>>()
        });
        rows_to_py(py, out, 3, single)
    }

    fn __repr__(&self) -> String {
        let size = self.size.map_or(String::new(), |s| {
            format!(", size=({}, {})", s.width, s.height)
        });
        format!(
            "Camera({:?}, {:?}{size})",
            model_name(&self.model),
            model_params(&self.model)
        )
    }

    fn __eq__(&self, other: &PyCamera) -> bool {
        self.model == other.model && self.size == other.size
    }

    fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyAny>> {
        let py = slf.py();
        let me = slf.get();
        let cls = slf.get_type();
        let size = me.size();
        (cls, (me.model(), me.params(), size))
            .into_pyobject(py)
            .map(|t| t.into_any())
    }
}

/// The rectification of `monovo rectify`: a map from a camera to a pinhole view, applied to
/// images by bilinear interpolation (invalid pixels 0).
#[pyclass(module = "monovo", name = "Rectifier", frozen)]
pub struct PyRectifier {
    pub(crate) map: RectifyMap,
    input: PyCamera,
    output: OutputMode,
}

impl PyRectifier {
    /// The map for `camera` (with its size) to `output` at `size` (the input size when `None`).
    pub fn build(
        py: Python<'_>,
        camera: PyCamera,
        output: OutputMode,
        size: Option<ImageSize>,
    ) -> PyResult<PyRectifier> {
        let Some(in_size) = camera.size else {
            return Err(Error::format(
                "the camera has no image size: give it (Camera(..., size=(w, h))) to rectify",
            )
            .into());
        };
        let out_size = size.unwrap_or(in_size);
        let model = camera.model.clone();
        let map = py
            .detach(|| RectifyMap::for_mode(&model, in_size, &output, out_size))
            .map_err(|e| {
                Error::from(e).context(&format!("output camera `{output}` at {out_size}"))
            })?;
        Ok(PyRectifier {
            map,
            input: camera,
            output,
        })
    }
}

#[pymethods]
impl PyRectifier {
    /// A rectifier from `camera` to `pinhole` (`"crop"`, `"full"`, `"none"`, `"fx fy cx cy 0"`
    /// or four numbers) at `size` (the camera's size when `None`).
    #[new]
    #[pyo3(signature = (camera, pinhole=None, size=None))]
    fn new(
        py: Python<'_>,
        camera: PyRef<'_, PyCamera>,
        pinhole: Option<&Bound<'_, PyAny>>,
        size: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<PyRectifier> {
        let output = pinhole
            .map(output_arg)
            .transpose()?
            .unwrap_or(OutputMode::Crop);
        let size = size.map(size_arg).transpose()?;
        PyRectifier::build(py, camera.clone(), output, size)
    }

    /// The rectifier a calibration file asks for: camera.txt's lines 3 and 4 (`crop` at the
    /// input size for other formats), unless `pinhole` or `size` are given.
    #[staticmethod]
    #[pyo3(signature = (path, cam=0, pinhole=None, size=None))]
    fn from_file(
        py: Python<'_>,
        path: PathBuf,
        cam: usize,
        pinhole: Option<&Bound<'_, PyAny>>,
        size: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<PyRectifier> {
        let f = read_camera_file(&path, cam, None)?;
        let output = pinhole.map(output_arg).transpose()?.unwrap_or(f.output);
        let size = size.map(size_arg).transpose()?.unwrap_or(f.output_size);
        let camera = PyCamera {
            model: f.input,
            size: Some(f.input_size),
        };
        PyRectifier::build(py, camera, output, Some(size))
            .map_err(|e| Error::format(format!("{}: {e}", path.display())).into())
    }

    /// The output pinhole camera (with its size).
    #[getter]
    fn camera(&self) -> PyCamera {
        PyCamera {
            model: CameraModel::Pinhole(self.map.camera()),
            size: Some(self.map.output_size()),
        }
    }
    /// The input camera.
    #[getter]
    fn input_camera(&self) -> PyCamera {
        self.input.clone()
    }
    /// The output pinhole's 3 x 3 matrix.
    #[getter(K)]
    fn k<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        self.camera().k(py)
    }
    /// The requested output, as `--pinhole` writes it.
    #[getter]
    fn pinhole(&self) -> String {
        self.output.to_string()
    }
    /// Output pixels without a source (0 in every image).
    #[getter]
    fn invalid_pixels(&self) -> usize {
        self.map.invalid_count()
    }
    /// Which output pixels have a source, H x W bool.
    #[getter]
    fn valid_mask<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<bool>> {
        image_to_py(py, self.map.valid_mask())
    }
    /// The source position (x, y) in the input image of every output pixel, H x W x 2,
    /// NaN where there is none.
    #[getter]
    fn sources<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let s = self.map.output_size();
        let map = &self.map;
        let data: Vec<f64> = py.detach(|| {
            (0..s.height)
                .flat_map(|v| (0..s.width).map(move |u| (u, v)))
                .flat_map(|(u, v)| map.source(u, v).unwrap_or([f64::NAN; 2]))
                .collect()
        });
        let a = numpy::ndarray::Array3::from_shape_vec((s.height, s.width, 2), data)
            .map_err(|e| Error::format(e.to_string()))?;
        Ok(a.into_pyarray(py).into_any())
    }

    /// Rectifies an H x W image of uint8, uint16 or float32 (same dtype out; float32 NaN
    /// stays NaN and poisons its neighbours, as the photometric correction needs).
    fn __call__<'py>(
        &self,
        py: Python<'py>,
        image: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let map = &self.map;
        if let Ok(a) = image.extract::<PyReadonlyArray2<'_, u8>>() {
            let img = image_from_py(&a)?;
            let out = py.detach(|| map.remap_u8(&img)).map_err(Error::from)?;
            return Ok(image_to_py(py, out).into_any());
        }
        if let Ok(a) = image.extract::<PyReadonlyArray2<'_, u16>>() {
            let img = image_from_py(&a)?;
            let out = py.detach(|| map.remap_u16(&img)).map_err(Error::from)?;
            return Ok(image_to_py(py, out).into_any());
        }
        if let Ok(a) = image.extract::<PyReadonlyArray2<'_, f32>>() {
            let img = image_from_py(&a)?;
            let out = py.detach(|| map.remap_f32(&img)).map_err(Error::from)?;
            return Ok(image_to_py(py, out).into_any());
        }
        Err(
            Error::format("image: expected a 2-D numpy array of uint8, uint16 or float32 (H x W)")
                .into(),
        )
    }

    fn __repr__(&self) -> String {
        let k = self.map.camera();
        let s = self.map.output_size();
        format!(
            "Rectifier({} -> pinhole fx={} fy={} cx={} cy={} at {}x{}, {} invalid pixels)",
            model_name(&self.input.model),
            k.fx,
            k.fy,
            k.cx,
            k.cy,
            s.width,
            s.height,
            self.map.invalid_count()
        )
    }
}

/// Registers the camera classes.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyCamera>()?;
    m.add_class::<PyRectifier>()?;
    Ok(())
}
