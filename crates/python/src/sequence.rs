//! `monovo.Sequence` and `monovo.Frame`: a sequence folder of any layout that dataset-io
//! reads, frame by frame, raw or rectified, optionally photometrically corrected, decoded in
//! parallel with the GIL released.

use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use camera_model::{CameraModel, Image, ImageSize, OutputMode, RectifyMap};
use dataset_io::{GrayImage, Sequence};
use numpy::{PyArray1, PyArrayMethods};
use photometric::{Correction, InverseResponse};
use pyo3::prelude::*;
use pyo3::types::{PySlice, PySliceMethods};
use rayon::prelude::*;

use crate::arrays::{image_to_py, output_arg, size_arg};
use crate::camera::PyCamera;
use crate::errors::{Error, Result};

/// What the frames go through.
enum Pixels {
    /// As decoded, at the file's bit depth.
    Native,
    /// Rectified (bilinear), same bit depth.
    Geometric(RectifyMap),
    /// `U(I) / V` (divided by the exposure in ms for irradiance), float32, rectified when
    /// the correction has a map.
    Photometric(Box<Correction>),
}

/// The options of a `Sequence`, kept for pickling.
#[derive(Clone, Debug, Default)]
struct Options {
    cam: usize,
    calib: Option<PathBuf>,
    rectify: bool,
    pinhole: Option<OutputMode>,
    size: Option<ImageSize>,
    photometric: bool,
    irradiance: bool,
    mask_saturated: bool,
    bit_depth: Option<u32>,
}

/// The opened sequence and what its frames go through.
struct Inner {
    path: PathBuf,
    opts: Options,
    seq: Sequence,
    pixels: Pixels,
    /// The camera of the frames returned (the pinhole when rectified).
    camera: Option<PyCamera>,
    /// Bits of the samples (16-bit frames may hold fewer).
    bits: u32,
    warnings: Vec<String>,
}

/// A decoded frame, before it becomes Python objects.
struct FrameData {
    index: usize,
    name: String,
    image: Pix,
    timestamp: f64,
    exposure_ms: Option<f64>,
    timestamp_ns: Option<i64>,
}

enum Pix {
    U8(Image<u8>),
    U16(Image<u16>),
    F32(Image<f32>),
}

impl Inner {
    /// Opens `path` with the checks of `monovo rectify` for the options that need them.
    fn open(path: PathBuf, opts: Options) -> Result<Inner> {
        let seq = Sequence::open_with_calibration(&path, opts.cam, opts.calib.as_deref())?;
        let mut warnings: Vec<String> = seq
            .times()
            .warnings
            .iter()
            .chain(&seq.layout_warnings)
            .cloned()
            .collect();
        let rectify = opts.rectify || opts.pinhole.is_some() || opts.size.is_some();
        let photometric = opts.photometric || opts.irradiance;
        let in_bits = seq.bits_per_sample();
        let mut bits = opts.bit_depth.unwrap_or(in_bits);
        if in_bits == 8 && bits != 8 {
            return Err(Error::format(format!(
                "bit_depth={bits}: the frames of {} are 8-bit; bit_depth describes 16-bit frames whose values use fewer bits",
                path.display()
            )));
        }
        if opts.mask_saturated && !photometric {
            return Err(Error::format(
                "mask_saturated masks photometric output: add photometric=True or irradiance=True",
            ));
        }
        let camera_path = seq
            .camera_path()
            .map_or_else(|| path.join("camera.txt"), Path::to_path_buf);
        let map = if rectify {
            let Some(cam) = seq.camera() else {
                return Err(Error::format(format!(
                    "{}: no camera.txt (or the {} layout's calibration file); rectify needs the camera model",
                    path.display(),
                    seq.layout().name()
                )));
            };
            let mode = opts.pinhole.unwrap_or(cam.output);
            let out_size = opts.size.unwrap_or(cam.output_size);
            for w in cam.warnings.iter().chain(&camera_model::output_notes(
                &cam.input,
                cam.input_size,
                &mode,
                out_size,
            )) {
                warnings.push(format!("{}: {w}", camera_path.display()));
            }
            let map =
                RectifyMap::for_mode(&cam.input, cam.input_size, &mode, out_size).map_err(|e| {
                    Error::from(e).context(&format!(
                        "{}: output camera `{mode}` at {out_size}",
                        camera_path.display()
                    ))
                })?;
            if mode == OutputMode::Crop && map.invalid_count() > 0 {
                warnings.push(format!(
                    "{}: `crop` at {out_size} leaves {} output pixels without a source (0 in every frame); a smaller size or another pinhole avoids them",
                    camera_path.display(),
                    map.invalid_count()
                ));
            }
            Some(map)
        } else {
            None
        };
        let camera = match (&map, seq.camera()) {
            (Some(m), _) => Some(PyCamera {
                model: CameraModel::Pinhole(m.camera()),
                size: Some(m.output_size()),
            }),
            (None, Some(c)) => Some(PyCamera {
                model: c.input.clone(),
                size: Some(c.input_size),
            }),
            (None, None) => None,
        };
        let pixels = if photometric {
            let (corr, b) = correction(&path, &seq, map, &opts, bits, &mut warnings)?;
            bits = b;
            Pixels::Photometric(Box::new(corr))
        } else {
            match map {
                Some(m) => Pixels::Geometric(m),
                None => Pixels::Native,
            }
        };
        Ok(Inner {
            path,
            opts,
            seq,
            pixels,
            camera,
            bits,
            warnings,
        })
    }

    /// Frame `k`, decoded and processed.
    fn frame(&self, k: usize) -> Result<FrameData> {
        let f = self.seq.frame_native(k)?;
        let label = || format!("frame {} ({})", f.index, f.name);
        if let (GrayImage::U16(img), true) = (&f.image, self.bits < 16) {
            let top = (1u32 << self.bits) - 1;
            if let Some(v) = img.data().iter().find(|v| **v as u32 > top) {
                return Err(Error::format(format!(
                    "{}: pixel value {v} does not fit in bit depth {} (at most {top}); are the values in the high bits? then the bit depth is 16",
                    label(),
                    self.bits
                )));
            }
        }
        let image = match (&self.pixels, f.image) {
            (Pixels::Native, GrayImage::U8(i)) => Pix::U8(i),
            (Pixels::Native, GrayImage::U16(i)) => Pix::U16(i),
            (Pixels::Geometric(m), GrayImage::U8(i)) => Pix::U8(m.remap_u8(&i)?),
            (Pixels::Geometric(m), GrayImage::U16(i)) => Pix::U16(m.remap_u16(&i)?),
            (Pixels::Photometric(c), img) => {
                let (w, h) = c.output_size();
                let mut out = Image::filled(w, h, 0f32);
                let t = if self.opts.irradiance {
                    f.exposure_ms
                } else {
                    None
                };
                match &img {
                    GrayImage::U8(i) => c.apply(i, t, &mut out),
                    GrayImage::U16(i) => c.apply_u16(i, t, &mut out),
                }
                .map_err(|e| Error::from(e).context(&label()))?;
                Pix::F32(out)
            }
        };
        Ok(FrameData {
            index: f.index,
            name: f.name,
            image,
            timestamp: f.timestamp,
            exposure_ms: f.exposure_ms,
            timestamp_ns: f.timestamp_ns,
        })
    }

    /// Frames `indices` decoded in parallel (GIL released by the caller), in order.
    fn frames(&self, indices: &[usize]) -> Vec<Result<FrameData>> {
        indices.par_iter().map(|&k| self.frame(k)).collect()
    }
}

/// The photometric correction of the sequence's frames (with the rectification `map`, when
/// rectifying), as `monovo rectify --photometric` builds it; and the bit depth of the samples.
fn correction(
    path: &Path,
    seq: &Sequence,
    map: Option<RectifyMap>,
    opts: &Options,
    mut bits: u32,
    warnings: &mut Vec<String>,
) -> Result<(Correction, u32)> {
    let Some(p) = &seq.pcalib_path else {
        return Err(Error::format(format!(
            "{}: photometric correction needs pcalib.txt (the inverse response)",
            path.display()
        )));
    };
    let text = dataset_io::read_text(p)?;
    let (response, notes) = InverseResponse::parse_with_notes(&text)
        .map_err(|e| Error::from(e).context(&p.display().to_string()))?;
    warnings.extend(notes.into_iter().map(|n| format!("{}: {n}", p.display())));
    let vignette = match &seq.vignette_path {
        Some(v) => Some(monovo_pipelines::read_vignette(v, seq.image_size())?),
        None => {
            warnings.push(format!(
                "{}: no vignette.png: undoing the response alone (V = 1)",
                path.display()
            ));
            None
        }
    };
    if opts.irradiance {
        if let Some((i, line)) = seq.times().first_unknown_exposure() {
            return Err(Error::format(format!(
                "{}: line {line}: the exposure of frame {i} ({}) is unknown (0 or missing); irradiance divides by the exposure time of every frame",
                seq.times_path().display(),
                seq.names()[i]
            )));
        }
    }
    let deep = seq.bits_per_sample() == 16;
    if deep && opts.bit_depth.is_none() && response.bits() < 16 {
        bits = response.bits();
    }
    let size = seq.image_size();
    let corr = Correction::new(
        &response,
        vignette.as_ref(),
        map,
        (size.width, size.height),
        opts.mask_saturated,
    )?;
    let corr = if deep {
        corr.with_bit_depth(&response, bits, opts.mask_saturated)?
    } else {
        corr
    };
    Ok((corr, bits))
}

/// One frame.
#[pyclass(module = "monovo", name = "Frame", frozen, get_all)]
pub struct PyFrame {
    /// The pixels: H x W uint8 or uint16 as decoded or rectified, float32 when corrected.
    image: Py<PyAny>,
    /// Timestamp in seconds.
    timestamp: f64,
    /// Exposure time in ms, or `None` where the dataset does not give it.
    exposure_ms: Option<f64>,
    /// Index in the sequence (0-based, in name order).
    index: usize,
    /// The image's name (file name or zip entry).
    name: String,
    /// The timestamp in integer nanoseconds, where the dataset gives it exactly.
    timestamp_ns: Option<i64>,
}

#[pymethods]
impl PyFrame {
    fn __repr__(&self, py: Python<'_>) -> String {
        let img = self.image.bind(py);
        let shape = img.getattr("shape").map_or("?".into(), |s| s.to_string());
        let dtype = img.getattr("dtype").map_or("?".into(), |s| s.to_string());
        let exposure = self
            .exposure_ms
            .map_or("None".to_string(), |e| format!("{e:?}"));
        format!(
            "Frame(index={}, name={:?}, timestamp={:?}, exposure_ms={exposure}, image={dtype}{shape})",
            self.index, self.name, self.timestamp
        )
    }
}

impl FrameData {
    fn into_py(self, py: Python<'_>) -> PyFrame {
        let image = match self.image {
            Pix::U8(i) => image_to_py(py, i).into_any().unbind(),
            Pix::U16(i) => image_to_py(py, i).into_any().unbind(),
            Pix::F32(i) => image_to_py(py, i).into_any().unbind(),
        };
        PyFrame {
            image,
            timestamp: self.timestamp,
            exposure_ms: self.exposure_ms,
            index: self.index,
            name: self.name,
            timestamp_ns: self.timestamp_ns,
        }
    }
}

/// A sequence folder of any layout monovo reads (monoVO/DSO, TUM-VI, EuRoC/ASL, 4Seasons,
/// KITTI, TUM RGB-D), camera `cam`, frame by frame.
///
/// `len(seq)`, `seq[k]` (negative indices too), `seq[a:b]` (a list, decoded in parallel),
/// `for frame in seq` and `seq.frames(start, stop, reverse)` (decoded ahead in parallel).
/// A frame's `image` is H x W: uint8 or uint16 as decoded (or rectified); float32 with
/// `photometric=True` (`U(I) / V`) or `irradiance=True` (`U(I) / (V * exposure_ms)`).
///
/// `rectify=True` rectifies to the sequence's output camera (camera.txt's lines 3 and 4);
/// `pinhole` (`"crop"`, `"full"`, `"none"`, `"fx fy cx cy 0"` or four numbers, as
/// `--pinhole`) and `size` (`(w, h)` or `"WxH"`) choose another and imply it. `camera` is
/// the camera of the frames returned (`camera.K`). `calib` reads the camera from another
/// calibration file (`--calib`); `bit_depth` tells the bits of 16-bit frames;
/// `mask_saturated` makes corrected pixels that touch a saturated one NaN.
///
/// The GIL is released while frames are decoded and processed. A sequence pickles by path
/// and options (PyTorch DataLoader workers each reopen it).
#[pyclass(module = "monovo", name = "Sequence", frozen)]
pub struct PySequence {
    inner: Arc<Inner>,
}

/// Frames decoded ahead in parallel, handed out in order.
#[pyclass(module = "monovo", name = "FrameIterator")]
pub struct FrameIterator {
    inner: Arc<Inner>,
    indices: Vec<usize>,
    next: usize,
    chunk: usize,
    ready: VecDeque<Result<FrameData>>,
}

#[pymethods]
impl FrameIterator {
    fn __iter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }

    fn __next__(&mut self, py: Python<'_>) -> PyResult<Option<PyFrame>> {
        if self.ready.is_empty() && self.next < self.indices.len() {
            let end = (self.next + self.chunk).min(self.indices.len());
            let batch = &self.indices[self.next..end];
            let inner = &self.inner;
            let frames = py.detach(|| inner.frames(batch));
            self.ready.extend(frames);
            self.next = end;
        }
        match self.ready.pop_front() {
            None => Ok(None),
            Some(Ok(f)) => Ok(Some(f.into_py(py))),
            Some(Err(e)) => {
                // the iteration ends with the error
                self.ready.clear();
                self.next = self.indices.len();
                Err(e.into())
            }
        }
    }

    fn __len__(&self) -> usize {
        self.ready.len() + self.indices.len() - self.next
    }
}

fn opt_size(obj: Option<&Bound<'_, PyAny>>) -> PyResult<Option<ImageSize>> {
    obj.filter(|o| !o.is_none()).map(size_arg).transpose()
}

#[pymethods]
impl PySequence {
    #[new]
    #[pyo3(signature = (path, cam=0, calib=None, rectify=false, pinhole=None, size=None,
                        photometric=false, irradiance=false, mask_saturated=false, bit_depth=None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        path: PathBuf,
        cam: usize,
        calib: Option<PathBuf>,
        rectify: bool,
        pinhole: Option<&Bound<'_, PyAny>>,
        size: Option<&Bound<'_, PyAny>>,
        photometric: bool,
        irradiance: bool,
        mask_saturated: bool,
        bit_depth: Option<u32>,
    ) -> PyResult<PySequence> {
        let opts = Options {
            cam,
            calib,
            rectify,
            pinhole: pinhole
                .filter(|o| !o.is_none())
                .map(output_arg)
                .transpose()?,
            size: opt_size(size)?,
            photometric,
            irradiance,
            mask_saturated,
            bit_depth,
        };
        let inner = py.detach(|| Inner::open(path, opts))?;
        Ok(PySequence {
            inner: Arc::new(inner),
        })
    }

    fn __len__(&self) -> usize {
        self.inner.seq.len()
    }

    fn __getitem__(&self, py: Python<'_>, key: &Bound<'_, PyAny>) -> PyResult<Py<PyAny>> {
        let n = self.inner.seq.len();
        if let Ok(slice) = key.cast::<PySlice>() {
            let ind = slice.indices(n as isize)?;
            let mut indices = Vec::with_capacity(ind.slicelength);
            let mut i = ind.start;
            for _ in 0..ind.slicelength {
                indices.push(i as usize);
                i += ind.step;
            }
            let inner = &self.inner;
            let frames = py.detach(|| inner.frames(&indices));
            let mut out = Vec::with_capacity(frames.len());
            for f in frames {
                out.push(f?.into_py(py));
            }
            return Ok(out.into_pyobject(py)?.into_any().unbind());
        }
        let k: isize = key.extract()?;
        let idx = if k < 0 { k + n as isize } else { k };
        if idx < 0 || idx as usize >= n {
            return Err(pyo3::exceptions::PyIndexError::new_err(format!(
                "frame {k} requested, the sequence has {n} frames"
            )));
        }
        let inner = &self.inner;
        let f = py.detach(|| inner.frame(idx as usize))?;
        Ok(Py::new(py, f.into_py(py))?.into_any())
    }

    fn __iter__(&self) -> FrameIterator {
        self.frames(None, None, false, None)
    }

    /// Frames `start` to `stop` (all by default), backwards with `reverse`, decoded `prefetch`
    /// at a time in parallel (4 per core by default).
    #[pyo3(signature = (start=None, stop=None, reverse=false, prefetch=None))]
    fn frames(
        &self,
        start: Option<usize>,
        stop: Option<usize>,
        reverse: bool,
        prefetch: Option<usize>,
    ) -> FrameIterator {
        let n = self.inner.seq.len();
        let indices = self
            .inner
            .seq
            .indices(start.unwrap_or(0)..stop.unwrap_or(n), reverse);
        FrameIterator {
            inner: self.inner.clone(),
            indices,
            next: 0,
            chunk: prefetch.unwrap_or(4 * rayon::current_num_threads()).max(1),
            ready: VecDeque::new(),
        }
    }

    /// The folder.
    #[getter]
    fn path(&self) -> PathBuf {
        self.inner.path.clone()
    }
    /// The layout it was read as (`monovo`, `tum-vi-dso`, `euroc-asl`, `4seasons`, `kitti`,
    /// `tum-rgbd`).
    #[getter]
    fn layout(&self) -> &'static str {
        self.inner.seq.layout().name()
    }
    /// Image names in frame order.
    #[getter]
    fn names(&self) -> Vec<String> {
        self.inner.seq.names().to_vec()
    }
    /// Timestamps in seconds, shape (N,).
    #[getter]
    fn timestamps<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        let t: Vec<f64> = self
            .inner
            .seq
            .times()
            .rows
            .iter()
            .map(|r| r.timestamp)
            .collect();
        PyArray1::from_vec(py, t)
    }
    /// Timestamps in integer nanoseconds, shape (N,) int64, when the dataset gives every one
    /// exactly; else `None`.
    #[getter]
    fn timestamps_ns<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray1<i64>>> {
        self.inner
            .seq
            .timestamps_ns()
            .map(|v| PyArray1::from_vec(py, v))
    }
    /// Exposure times in ms, shape (N,), NaN where unknown.
    #[getter]
    fn exposures_ms<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        let e: Vec<f64> = self
            .inner
            .seq
            .times()
            .rows
            .iter()
            .map(|r| r.exposure_ms.unwrap_or(f64::NAN))
            .collect();
        PyArray1::from_vec(py, e)
    }
    /// The camera of the frames returned: the output pinhole when rectifying, else the
    /// sequence's own camera model (`None` when the sequence has no calibration).
    #[getter]
    fn camera(&self) -> Option<PyCamera> {
        self.inner.camera.clone()
    }
    /// The sequence's own (raw) camera model, or `None`.
    #[getter]
    fn raw_camera(&self) -> Option<PyCamera> {
        self.inner.seq.camera().map(|c| PyCamera {
            model: c.input.clone(),
            size: Some(c.input_size),
        })
    }
    /// The raw image size `(width, height)`.
    #[getter]
    fn raw_size(&self) -> (usize, usize) {
        let s = self.inner.seq.image_size();
        (s.width, s.height)
    }
    /// The size of the frames returned `(width, height)`.
    #[getter]
    fn size(&self) -> (usize, usize) {
        match &self.inner.pixels {
            Pixels::Native => self.raw_size(),
            Pixels::Geometric(m) => (m.output_size().width, m.output_size().height),
            Pixels::Photometric(c) => c.output_size(),
        }
    }
    /// Bits per sample of the image files (8 or 16).
    #[getter]
    fn bits(&self) -> u32 {
        self.inner.seq.bits_per_sample()
    }
    /// The dtype of the frames returned: `uint8`, `uint16` or `float32`.
    #[getter]
    fn dtype(&self) -> &'static str {
        match (&self.inner.pixels, self.inner.seq.bits_per_sample()) {
            (Pixels::Photometric(_), _) => "float32",
            (_, 16) => "uint16",
            _ => "uint8",
        }
    }
    /// pcalib.txt, vignette.png, the ground truth (groundtruthSync.txt or the dataset's own
    /// file) and the calibration file, each path or `None`.
    #[getter]
    fn files(&self) -> std::collections::BTreeMap<&'static str, Option<PathBuf>> {
        let s = &self.inner.seq;
        [
            ("pcalib", s.pcalib_path.clone()),
            ("vignette", s.vignette_path.clone()),
            (
                "ground_truth",
                s.ground_truth_path
                    .clone()
                    .or(s.dataset_ground_truth.clone()),
            ),
            ("calibration", s.camera_path().map(Path::to_path_buf)),
            ("times", Some(s.times_path().to_path_buf())),
        ]
        .into_iter()
        .collect()
    }
    /// What was read differently from a plain folder (as the CLI's warnings).
    #[getter]
    fn warnings(&self) -> Vec<String> {
        self.inner.warnings.clone()
    }
    /// The ground truth at the frames, as `monovo eval --gt DIR --cam N` reads it: an N x 4
    /// array `t x y z` (NaN outside the segments that have ground truth).
    fn ground_truth<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let (path, cam) = (&self.inner.path, self.inner.opts.cam);
        let gt = py
            .detach(|| monovo_pipelines::load_sequence_ground_truth(path, cam))
            .map_err(Error::from)?;
        let flat: Vec<f64> = gt
            .times()
            .iter()
            .zip(gt.positions())
            .flat_map(|(t, p)| [*t, p.x, p.y, p.z])
            .collect();
        let a = PyArray1::from_vec(py, flat);
        Ok(a.reshape([gt.len(), 4])?.into_any())
    }

    fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyAny>> {
        let py = slf.py();
        let o = &slf.get().inner.opts;
        let args = (
            slf.get().inner.path.clone(),
            o.cam,
            o.calib.clone(),
            o.rectify,
            o.pinhole.map(|m| m.to_string()),
            o.size.map(|s| (s.width, s.height)),
            o.photometric,
            o.irradiance,
            o.mask_saturated,
            o.bit_depth,
        );
        (slf.get_type(), args)
            .into_pyobject(py)
            .map(|t| t.into_any())
    }

    fn __repr__(&self) -> String {
        let (w, h) = self.size();
        format!(
            "Sequence({:?}, layout={:?}, frames={}, {}x{} {})",
            self.inner.path.display().to_string(),
            self.layout(),
            self.__len__(),
            w,
            h,
            self.dtype()
        )
    }
}

/// Registers the sequence classes.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PySequence>()?;
    m.add_class::<PyFrame>()?;
    m.add_class::<FrameIterator>()?;
    Ok(())
}
