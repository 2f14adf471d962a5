//! `monovo.evaluate`, `monovo.evaluate_many`, `monovo.read_trajectory` and the `Evaluation`
//! result: the loop-closure metrics exactly as `monovo eval` computes them.

use std::collections::HashMap;
use std::path::PathBuf;

use eval_metrics::{evaluate as eval_run, Evaluation, GroundTruth, Pose, Trajectory};
use monovo_pipelines::{load_ground_truth, load_sequence_ground_truth, load_trajectory};
use nalgebra::{Quaternion, Vector3};
use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyArray1, PyArray2, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;
use rayon::prelude::*;

use crate::errors::{Error, Result};

/// A trajectory given from Python: a file, or rows `t x y z qx qy qz qw`.
pub enum Input {
    /// A file (or, for a ground truth, a sequence folder).
    Path(PathBuf),
    /// The rows of an N x 8 array.
    Rows(Vec<[f64; 8]>),
}

/// A path, or a 2-D array of numbers as float64 rows.
pub enum Arg {
    /// A file or folder.
    Path(PathBuf),
    /// `rows` x `cols` numbers, row by row.
    Matrix {
        /// Number of rows.
        rows: usize,
        /// Number of columns.
        cols: usize,
        /// The numbers, row-major.
        data: Vec<f64>,
    },
}

/// A path (`str` or `os.PathLike`) or a 2-D array of numbers (any dtype numpy can make
/// float64 of, lists too); `expected` describes the array in errors.
pub fn extract_arg(obj: &Bound<'_, PyAny>, what: &str, expected: &str) -> PyResult<Arg> {
    if let Ok(p) = obj.extract::<PathBuf>() {
        return Ok(Arg::Path(p));
    }
    let array = match obj.extract::<PyReadonlyArray2<'_, f64>>() {
        Ok(a) => a,
        Err(_) => {
            let np = obj.py().import("numpy")?;
            let a = np
                .call_method1("asarray", (obj, np.getattr("float64")?))
                .map_err(|e| {
                    Error::format(format!(
                        "{what}: expected a path or {expected}, got {} ({e})",
                        obj.get_type().name().map_or("?".into(), |n| n.to_string())
                    ))
                })?;
            if a.getattr("ndim")?.extract::<usize>()? != 2 {
                return Err(Error::format(format!(
                    "{what}: expected {expected}, got shape {}",
                    a.getattr("shape")?.str()?
                ))
                .into());
            }
            a.extract::<PyReadonlyArray2<'_, f64>>()?
        }
    };
    let shape = array.shape();
    Ok(Arg::Matrix {
        rows: shape[0],
        cols: shape[1],
        data: array.as_array().iter().copied().collect(),
    })
}

/// An N x 8 array's description in errors.
const ROWS_8: &str = "an N x 8 array `t x y z qx qy qz qw`";

/// A path or an N x 8 array of numbers (any dtype numpy can make float64 of).
pub fn extract_input(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<Input> {
    match extract_arg(obj, what, ROWS_8)? {
        Arg::Path(p) => Ok(Input::Path(p)),
        Arg::Matrix { cols: 8, data, .. } => Ok(Input::Rows(rows_of(&data))),
        Arg::Matrix { rows, cols, .. } => Err(Error::format(format!(
            "{what}: expected {ROWS_8}, got shape ({rows}, {cols})"
        ))
        .into()),
    }
}

/// Row-major numbers as rows of `N`.
pub fn rows_of<const N: usize>(data: &[f64]) -> Vec<[f64; N]> {
    data.chunks_exact(N)
        .map(|r| std::array::from_fn(|j| r[j]))
        .collect()
}

/// The options of reading an estimate file.
#[derive(Clone, Debug)]
pub struct ReadOptions {
    /// `tum`, `kitti`, `euroc`, or guessed.
    pub format: Option<eval_metrics::TrajectoryFormat>,
    /// KITTI's times file.
    pub times: Option<PathBuf>,
    /// The camera of a multi-camera ground-truth folder.
    pub cam: usize,
}

/// Parses the `format` argument.
pub fn parse_format(format: Option<&str>) -> Result<Option<eval_metrics::TrajectoryFormat>> {
    use eval_metrics::TrajectoryFormat as F;
    match format.map(str::to_ascii_lowercase).as_deref() {
        None | Some("auto") => Ok(None),
        Some("tum") => Ok(Some(F::Tum)),
        Some("kitti") => Ok(Some(F::Kitti)),
        Some("euroc") => Ok(Some(F::Euroc)),
        Some(f) => Err(Error::format(format!(
            "format `{f}`: expected `tum`, `kitti`, `euroc` or `auto`"
        ))),
    }
}

/// The estimate: a file read as `monovo eval` reads it, or rows checked as its parser checks
/// them.
pub fn trajectory(input: &Input, opts: &ReadOptions) -> Result<Trajectory> {
    match input {
        Input::Path(p) => Ok(load_trajectory(p, opts.format, opts.times.as_deref())?),
        Input::Rows(rows) => rows_trajectory(rows, "the estimate"),
    }
}

/// Rows `t x y z qx qy qz qw` as a trajectory, checked as the TUM parser checks a file (a zero
/// quaternion is an error); `what` names it in errors.
pub fn rows_trajectory(rows: &[[f64; 8]], what: &str) -> Result<Trajectory> {
    let mut poses = Vec::with_capacity(rows.len());
    for (i, v) in rows.iter().enumerate() {
        let n2: f64 = v[4..].iter().map(|x| x * x).sum();
        if n2.is_finite() && n2 < 1e-12 {
            return Err(Error::format(format!(
                "{what}: row {i}: not a rotation: the quaternion is zero"
            )));
        }
        poses.push(Pose {
            t: v[0],
            position: Vector3::new(v[1], v[2], v[3]),
            orientation: Quaternion::new(v[7], v[4], v[5], v[6]),
        });
    }
    Ok(Trajectory { poses })
}

/// The ground truth: a file or a sequence folder read as `monovo eval --gt` reads it, or
/// rows (finite, strictly increasing timestamps; NaN positions outside the segments).
pub fn ground_truth(input: &Input, cam: usize) -> Result<GroundTruth> {
    match input {
        Input::Path(p) if p.is_dir() => Ok(load_sequence_ground_truth(p, cam)?),
        Input::Path(p) => Ok(load_ground_truth(p)?),
        Input::Rows(rows) => {
            if let Some(i) = rows.iter().position(|r| !r[0].is_finite()) {
                return Err(Error::format(format!(
                    "the ground truth: row {i}: expected a finite timestamp, found {}",
                    rows[i][0]
                )));
            }
            let times = rows.iter().map(|r| r[0]).collect();
            let positions = rows
                .iter()
                .map(|r| Vector3::new(r[1], r[2], r[3]))
                .collect();
            GroundTruth::from_rows(times, positions)
                .map_err(|e| Error::from_chain(&e).context("the ground truth"))
        }
    }
}

/// One evaluated run. Its attributes are the keys of `monovo eval --json` (`status`,
/// `reason`, `e_align`, `e_s`, `e_r`, `e_t`, `e_rmse`, `rmse_start`, `rmse_end`, `poses`,
/// `poses_start`, `poses_end`), the metrics `inf` where the JSON has `null`; `to_json()`
/// gives that JSON object itself. Also `ok`, `e_s_sym`, the evaluated `times` and
/// `positions`, and the start and end alignments `start`, `end` (4 x 4 `gt_from_est`).
#[pyclass(module = "monovo", name = "Evaluation", frozen)]
pub struct PyEvaluation {
    e: Evaluation,
}

/// `Sim3` as a 4 x 4 matrix `[s R | t; 0 0 0 1]`.
fn sim3_matrix<'py>(py: Python<'py>, s: &eval_metrics::Sim3) -> Bound<'py, PyArray2<f64>> {
    let m = s.rotation.matrix() * s.scale;
    let mut a = Array2::<f64>::zeros((4, 4));
    for r in 0..3 {
        for c in 0..3 {
            a[[r, c]] = m[(r, c)];
        }
        a[[r, 3]] = s.translation[r];
    }
    a[[3, 3]] = 1.0;
    a.into_pyarray(py)
}

#[pymethods]
impl PyEvaluation {
    /// `"ok"` or `"failed"`.
    #[getter]
    fn status(&self) -> &'static str {
        if self.e.is_ok() {
            "ok"
        } else {
            "failed"
        }
    }
    /// Why the run failed (`None` when it succeeded).
    #[getter]
    fn reason(&self) -> Option<String> {
        self.e.failure.as_ref().map(|f| f.to_string())
    }
    /// Whether the run succeeded.
    #[getter]
    fn ok(&self) -> bool {
        self.e.is_ok()
    }
    /// RMS distance between the start- and the end-aligned trajectory (inf when failed).
    #[getter]
    fn e_align(&self) -> f64 {
        self.e.metrics.e_align
    }
    /// Scale drift `s_start / s_end` (inf when failed).
    #[getter]
    fn e_s(&self) -> f64 {
        self.e.metrics.e_s
    }
    /// The paper's symmetric scale error `max(e_s, 1 / e_s)`.
    #[getter]
    fn e_s_sym(&self) -> f64 {
        self.e.metrics.e_s_sym()
    }
    /// Rotation drift in degrees (inf when failed).
    #[getter]
    fn e_r(&self) -> f64 {
        self.e.metrics.e_r
    }
    /// Translation drift `|t(S_end S_start^-1)|` (inf when failed).
    #[getter]
    fn e_t(&self) -> f64 {
        self.e.metrics.e_t
    }
    /// RMSE of one Sim(3) alignment over both segments (inf when failed).
    #[getter]
    fn e_rmse(&self) -> f64 {
        self.e.metrics.e_rmse
    }
    /// RMSE of the start segment's alignment.
    #[getter]
    fn rmse_start(&self) -> f64 {
        self.e.metrics.rmse_start
    }
    /// RMSE of the end segment's alignment.
    #[getter]
    fn rmse_end(&self) -> f64 {
        self.e.metrics.rmse_end
    }
    /// Number of estimated poses.
    #[getter]
    fn poses(&self) -> usize {
        self.e.poses
    }
    /// Poses in the start alignment.
    #[getter]
    fn poses_start(&self) -> usize {
        self.e.poses_start
    }
    /// Poses in the end alignment.
    #[getter]
    fn poses_end(&self) -> usize {
        self.e.poses_end
    }
    /// Whether the timestamps were mapped back from the `2e9 - t` convention.
    #[getter]
    fn backwards_time_mapped(&self) -> bool {
        self.e.backwards_time_mapped
    }
    /// The evaluated timestamps (sorted, mapped back), shape (N,).
    #[getter]
    fn times<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, &self.e.times)
    }
    /// The evaluated positions in the estimate's frame, shape (N, 3).
    #[getter]
    fn positions<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let flat: Vec<f64> = self
            .e
            .positions
            .iter()
            .flat_map(|p| [p.x, p.y, p.z])
            .collect();
        Array2::from_shape_vec((self.e.positions.len(), 3), flat)
            .unwrap_or_default()
            .into_pyarray(py)
    }
    /// `gt_from_est` of the start segment as a 4 x 4 similarity `[s R | t]`, or `None`.
    #[getter]
    fn start<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray2<f64>>> {
        self.e.start.as_ref().map(|s| sim3_matrix(py, s))
    }
    /// `gt_from_est` of the end segment as a 4 x 4 similarity `[s R | t]`, or `None`.
    #[getter]
    fn end<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray2<f64>>> {
        self.e.end.as_ref().map(|s| sim3_matrix(py, s))
    }
    /// The object `monovo eval --json` prints, as JSON text (`null` where infinite).
    fn to_json(&self) -> PyResult<String> {
        serde_json::to_string(&monovo_pipelines::EvaluationReport::from(&self.e))
            .map_err(|e| Error::format(e.to_string()).into())
    }
    fn __repr__(&self) -> String {
        let m = &self.e.metrics;
        match &self.e.failure {
            None => format!(
                "Evaluation(status='ok', e_align={}, e_s={}, e_r={}, e_t={}, e_rmse={}, poses={})",
                m.e_align, m.e_s, m.e_r, m.e_t, m.e_rmse, self.e.poses
            ),
            Some(r) => format!("Evaluation(status='failed', reason={:?})", r.to_string()),
        }
    }
}

/// Evaluates one run (`monovo.evaluate` documents it).
#[pyfunction]
#[pyo3(signature = (estimate, groundtruth, format=None, times=None, cam=0))]
fn evaluate(
    py: Python<'_>,
    estimate: &Bound<'_, PyAny>,
    groundtruth: &Bound<'_, PyAny>,
    format: Option<&str>,
    times: Option<PathBuf>,
    cam: usize,
) -> PyResult<PyEvaluation> {
    let est = extract_input(estimate, "estimate")?;
    let gt = extract_input(groundtruth, "groundtruth")?;
    let opts = ReadOptions {
        format: parse_format(format)?,
        times,
        cam,
    };
    let e = py.detach(|| -> Result<Evaluation> {
        let g = ground_truth(&gt, opts.cam)?;
        Ok(eval_run(&trajectory(&est, &opts)?, &g))
    })?;
    Ok(PyEvaluation { e })
}

/// Evaluates many runs in parallel (`monovo.evaluate_many` documents it).
#[pyfunction]
#[pyo3(signature = (pairs, threads=None, format=None, cam=0))]
fn evaluate_many(
    py: Python<'_>,
    pairs: &Bound<'_, PyAny>,
    threads: Option<usize>,
    format: Option<&str>,
    cam: usize,
) -> PyResult<Vec<PyEvaluation>> {
    let opts = ReadOptions {
        format: parse_format(format)?,
        times: None,
        cam,
    };
    // every ground-truth file is read once however many runs refer to it
    let mut gts: Vec<Input> = Vec::new();
    let mut by_path: HashMap<PathBuf, usize> = HashMap::new();
    let mut jobs: Vec<(Input, usize)> = Vec::new();
    for (i, pair) in pairs.try_iter()?.enumerate() {
        let pair = pair?;
        let (est, gt): (Bound<'_, PyAny>, Bound<'_, PyAny>) = pair.extract().map_err(|_| {
            Error::format(format!(
                "pairs[{i}]: expected a pair (estimate, groundtruth)"
            ))
        })?;
        let est = extract_input(&est, &format!("pairs[{i}] estimate"))?;
        let g = match extract_input(&gt, &format!("pairs[{i}] groundtruth"))? {
            Input::Path(p) => *by_path.entry(p.clone()).or_insert_with(|| {
                gts.push(Input::Path(p));
                gts.len() - 1
            }),
            rows => {
                gts.push(rows);
                gts.len() - 1
            }
        };
        jobs.push((est, g));
    }
    let run = || -> Result<Vec<Evaluation>> {
        let truths: Vec<GroundTruth> = gts
            .par_iter()
            .map(|g| ground_truth(g, opts.cam))
            .collect::<Result<_>>()?;
        jobs.par_iter()
            .enumerate()
            .map(|(i, (est, g))| {
                let t = trajectory(est, &opts).map_err(|e| e.context(&format!("pairs[{i}]")))?;
                Ok(eval_run(&t, &truths[*g]))
            })
            .collect()
    };
    let results = py.detach(|| -> Result<Vec<Evaluation>> {
        match threads {
            Some(0) => Err(Error::format(
                "threads=0: give at least 1, or None for all cores",
            )),
            Some(n) => rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .build()
                .map_err(|e| Error::format(e.to_string()))?
                .install(run),
            None => run(),
        }
    })?;
    Ok(results.into_iter().map(|e| PyEvaluation { e }).collect())
}

/// Reads a trajectory file (TUM, KITTI with `times`, EuRoC csv) as `monovo eval` reads it,
/// into an N x 8 array `t x y z qx qy qz qw` in file order.
#[pyfunction]
#[pyo3(signature = (path, format=None, times=None))]
fn read_trajectory<'py>(
    py: Python<'py>,
    path: PathBuf,
    format: Option<&str>,
    times: Option<PathBuf>,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let format = parse_format(format)?;
    let t = py
        .detach(|| load_trajectory(&path, format, times.as_deref()))
        .map_err(Error::from)?;
    let flat: Vec<f64> = t
        .poses
        .iter()
        .flat_map(|p| {
            let q = p.orientation.coords; // i j k w
            [
                p.t,
                p.position.x,
                p.position.y,
                p.position.z,
                q[0],
                q[1],
                q[2],
                q[3],
            ]
        })
        .collect();
    Ok(Array2::from_shape_vec((t.poses.len(), 8), flat)
        .unwrap_or_default()
        .into_pyarray(py))
}

/// Registers the evaluation's functions and class.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyEvaluation>()?;
    m.add_function(wrap_pyfunction!(evaluate, m)?)?;
    m.add_function(wrap_pyfunction!(evaluate_many, m)?)?;
    m.add_function(wrap_pyfunction!(read_trajectory, m)?)?;
    Ok(())
}
