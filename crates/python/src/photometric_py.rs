//! `monovo.InverseResponse`, `monovo.Vignette` and the calibrations. The calibrations are
//! bound through their serde types: options arrive as JSON text (a dict on the Python side)
//! deserialised into the library's options type, results leave as the library's serialised
//! result, so that options and result fields added to the library reach Python unchanged.

use std::path::PathBuf;

use monovo_pipelines::calib::{ResponseJob, VignetteJob};
use monovo_pipelines::Silent;
use numpy::{PyArray1, PyArray2, PyReadonlyArray1, PyReadonlyArray2};
use photometric::{InverseResponse, ResponseOptions, Vignette, VignetteOptions};
use pyo3::prelude::*;
use serde::de::DeserializeOwned;

use crate::arrays::{image_from_py, image_to_py};
use crate::errors::{Error, Result};

/// The inverse response `U`: grey value to irradiance times exposure.
#[pyclass(module = "monovo", name = "InverseResponse", frozen)]
#[derive(Clone)]
pub struct PyInverseResponse {
    u: InverseResponse,
}

#[pymethods]
impl PyInverseResponse {
    /// From `2^k` values (k from 8 to 16): finite and strictly increasing.
    #[new]
    fn new(values: Vec<f64>) -> PyResult<Self> {
        Ok(PyInverseResponse {
            u: InverseResponse::from_values(values).map_err(Error::from)?,
        })
    }
    /// Reads a pcalib.txt as `monovo rectify --photometric` reads it.
    #[staticmethod]
    fn from_file(path: PathBuf) -> PyResult<Self> {
        let text = dataset_io::read_text(&path).map_err(Error::from)?;
        let u = InverseResponse::parse(&text)
            .map_err(|e| Error::from(e).context(&path.display().to_string()))?;
        Ok(PyInverseResponse { u })
    }
    /// The identity `U(k) = k` on 256 values.
    #[staticmethod]
    fn linear() -> Self {
        PyInverseResponse {
            u: InverseResponse::linear(),
        }
    }
    /// The table `U(0) .. U(2^k - 1)`.
    #[getter]
    fn values<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, self.u.table())
    }
    /// Bits of the grey values it is indexed by (8 for 256 values).
    #[getter]
    fn bits(&self) -> u32 {
        self.u.bits()
    }
    /// pcalib.txt's text (full precision).
    fn to_text(&self) -> String {
        self.u.to_text()
    }
    /// `U` of every pixel of a uint8 (or, for a table of `2^k` values, uint16 of k bits)
    /// image, float64.
    fn __call__<'py>(
        &self,
        py: Python<'py>,
        image: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let table: &[f64] = if image.extract::<PyReadonlyArray2<'_, u8>>().is_ok() {
            self.u.values()
        } else {
            self.u.table()
        };
        let np = py.import("numpy")?;
        let lut = PyArray1::from_slice(py, table);
        let idx = np.call_method1("asarray", (image,))?;
        let kind: String = idx.getattr("dtype")?.getattr("kind")?.extract()?;
        if kind != "u" {
            return Err(
                Error::format("image: expected an array of uint8 or uint16 grey values").into(),
            );
        }
        let top: u64 = idx.call_method0("max")?.extract().unwrap_or(0);
        if top as usize >= table.len() {
            return Err(Error::format(format!(
                "image: grey value {top} beyond the table's {} values",
                table.len()
            ))
            .into());
        }
        lut.call_method1("take", (idx,))
    }
    fn __len__(&self) -> usize {
        self.u.table().len()
    }
    fn __repr__(&self) -> String {
        let t = self.u.table();
        format!(
            "InverseResponse({} values, U(0)={}, U({})={})",
            t.len(),
            t[0],
            t.len() - 1,
            t[t.len() - 1]
        )
    }
    fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyAny>> {
        let py = slf.py();
        (slf.get_type(), (slf.get().u.table().to_vec(),))
            .into_pyobject(py)
            .map(|t| t.into_any())
    }
}

/// The vignette `V` (max 1), per raw pixel.
#[pyclass(module = "monovo", name = "Vignette", frozen)]
pub struct PyVignette {
    v: Vignette,
}

#[pymethods]
impl PyVignette {
    /// From an H x W float32 map of any scale (normalised to max 1; 0 = masked).
    #[new]
    fn new(values: PyReadonlyArray2<'_, f32>) -> PyResult<Self> {
        let img = image_from_py(&values)?;
        Ok(PyVignette {
            v: Vignette::from_values(img).map_err(Error::from)?,
        })
    }
    /// Reads vignette.png (8 or 16 bits, V = value / max).
    #[staticmethod]
    fn from_file(path: PathBuf) -> PyResult<Self> {
        let (img, _) = dataset_io::read_gray_map(&path).map_err(Error::from)?;
        let v = Vignette::from_u16(&img)
            .map_err(|e| Error::from(e).context(&path.display().to_string()))?;
        Ok(PyVignette { v })
    }
    /// The map, H x W float32, max 1.
    #[getter]
    fn values<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f32>> {
        image_to_py(py, self.v.values().clone())
    }
    /// `(width, height)`.
    #[getter]
    fn size(&self) -> (usize, usize) {
        self.v.size()
    }
    /// The 16-bit map written to vignette.png (65535 = 1).
    fn to_u16<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<u16>> {
        image_to_py(py, self.v.to_u16())
    }
    fn __repr__(&self) -> String {
        let (w, h) = self.v.size();
        format!("Vignette({w}x{h}, min V={})", self.v.min_positive())
    }
}

/// The library's options type from JSON text (`None`: the defaults); an unknown or
/// mistyped option is an error naming it.
fn options<T: DeserializeOwned + Default>(json: Option<&str>, what: &str) -> Result<T> {
    match json {
        None => Ok(T::default()),
        Some(j) => {
            serde_json::from_str(j).map_err(|e| Error::format(format!("{what} options: {e}")))
        }
    }
}

fn to_json<T: serde::Serialize>(v: &T) -> Result<String> {
    serde_json::to_string(v).map_err(|e| Error::format(e.to_string()))
}

/// The default options of the response and the vignette calibration, as JSON text.
#[pyfunction]
fn _default_options(kind: &str) -> PyResult<String> {
    Ok(match kind {
        "response" => to_json(&ResponseOptions::default())?,
        _ => to_json(&VignetteOptions::default())?,
    })
}

/// Calibrates the inverse response of a sweep folder (`monovo calib response`), or of
/// frames in memory with their exposures; returns the serialised result.
#[pyfunction]
#[pyo3(signature = (sequence=None, frames=None, exposures_ms=None, options=None, bit_depth=None))]
fn _calibrate_response(
    py: Python<'_>,
    sequence: Option<PathBuf>,
    frames: Option<Vec<Bound<'_, PyAny>>>,
    exposures_ms: Option<PyReadonlyArray1<'_, f64>>,
    options: Option<&str>,
    bit_depth: Option<u32>,
) -> PyResult<(String, usize)> {
    let opts: ResponseOptions = options_checked(options)?;
    if let Some(seq) = sequence {
        let job = ResponseJob {
            sequence: seq,
            bit_depth,
            options: opts,
        };
        let run = py
            .detach(|| monovo_pipelines::calib::calibrate_response_sequence(&job, &Silent))
            .map_err(Error::from)?;
        return Ok((to_json(&run.cal)?, run.frames));
    }
    let (Some(frames), Some(exposures)) = (frames, exposures_ms) else {
        return Err(Error::format("give a sweep folder, or frames and exposures_ms").into());
    };
    let exposures = exposures
        .as_slice()
        .map_err(|e| Error::format(e.to_string()))?
        .to_vec();
    if frames.len() != exposures.len() {
        return Err(Error::format(format!(
            "{} frames but {} exposures",
            frames.len(),
            exposures.len()
        ))
        .into());
    }
    let n = frames.len();
    let cal = if let Some(bits) = bit_depth {
        let imgs = frames
            .iter()
            .map(|f| image_from_py(&f.extract::<PyReadonlyArray2<'_, u16>>()?).map_err(PyErr::from))
            .collect::<PyResult<Vec<_>>>()?;
        py.detach(|| {
            photometric::calibrate_response_deep(&imgs, bits, &exposures, &opts, &|_, _| {})
        })
    } else {
        let mut imgs = frames
            .iter()
            .map(|f| image_from_py(&f.extract::<PyReadonlyArray2<'_, u8>>()?).map_err(PyErr::from))
            .collect::<PyResult<Vec<_>>>()?;
        py.detach(|| photometric::calibrate_response(&mut imgs, &exposures, &opts, &|_, _| {}))
    }
    .map_err(Error::from)?;
    Ok((to_json(&cal)?, n))
}

/// Response options, parsed and checked before any work.
fn options_checked(json: Option<&str>) -> Result<ResponseOptions> {
    let o: ResponseOptions = options(json, "response")?;
    o.check()
        .map_err(|e| Error::from(e).context("response options"))?;
    Ok(o)
}

/// Calibrates the vignette of a sequence folder (`monovo calib vignette`); returns the
/// serialised result and the numbers of frames used and in the sequence.
#[pyfunction]
#[pyo3(signature = (sequence, pcalib=None, poses=None, marker_id=213, bit_depth=None, options=None))]
fn _calibrate_vignette(
    py: Python<'_>,
    sequence: PathBuf,
    pcalib: Option<PathBuf>,
    poses: Option<PathBuf>,
    marker_id: u16,
    bit_depth: Option<u32>,
    options: Option<&str>,
) -> PyResult<(String, usize, usize)> {
    let job = VignetteJob {
        sequence,
        pcalib,
        poses,
        marker_id,
        bit_depth,
        options: self::options(options, "vignette")?,
        scratch: None,
    };
    let run = py
        .detach(|| monovo_pipelines::calib::calibrate_vignette_sequence(&job, &Silent))
        .map_err(Error::from)?;
    Ok((to_json(&run.cal)?, run.used, run.frames))
}

/// Registers the photometric classes and functions.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyInverseResponse>()?;
    m.add_class::<PyVignette>()?;
    m.add_function(wrap_pyfunction!(_default_options, m)?)?;
    m.add_function(wrap_pyfunction!(_calibrate_response, m)?)?;
    m.add_function(wrap_pyfunction!(_calibrate_vignette, m)?)?;
    Ok(())
}
