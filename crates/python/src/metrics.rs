//! `monovo.ape`, `monovo.rpe` and `monovo.kitti`: the field's other trajectory metrics as
//! `monovo ape/rpe/kitti --json` compute them, from files or arrays, with the commands'
//! options as keyword arguments under evo's names. The native functions return the
//! command's JSON text and evo's result arrays; `python/monovo/_metrics.py` wraps them.

use eval_metrics::{
    ExtraMetric, NamedArray, PoseRelation, PoseTrack, SyncMethod, TrajectoryFormat,
};
use monovo_pipelines::{
    kitti_pairs, kitti_report, load_track, metric_report, run_kitti, MetricArgs, Spelling,
};
use numpy::ndarray::ArrayD;
use numpy::IntoPyArray;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::errors::{Error, Result};
use crate::eval::{extract_arg, parse_format, rows_of, rows_trajectory, Arg};

/// The arrays these functions read.
const TRACK_ROWS: &str =
    "an N x 8 array `t x y z qx qy qz qw` or an N x 12 array of KITTI poses `r11 r12 r13 tx .. r33 tz`";

/// The name a report gives a trajectory: its path, or evo's name for one in memory.
fn name_of(arg: &Arg, memory_name: &str) -> String {
    match arg {
        Arg::Path(p) => p.display().to_string(),
        Arg::Matrix { .. } => memory_name.to_string(),
    }
}

/// A trajectory file (`format` `None`: recognised by its first line), or the rows of an
/// N x 8 (stamped) or N x 12 (KITTI, paired by line) array; `what` names it in errors.
fn track(arg: &Arg, format: Option<TrajectoryFormat>, what: &str) -> Result<PoseTrack> {
    match arg {
        Arg::Path(p) => Ok(load_track(p, format)?),
        Arg::Matrix { cols: 8, data, .. } => Ok(PoseTrack::from_trajectory(&rows_trajectory(
            &rows_of::<8>(data),
            what,
        )?)),
        Arg::Matrix { cols: 12, data, .. } => {
            let mut t = PoseTrack::default();
            for (i, row) in rows_of::<12>(data).iter().enumerate() {
                t.push_kitti_row(row)
                    .map_err(|e| Error::format(format!("{what}: row {i}: not a rotation: {e}")))?;
            }
            Ok(t)
        }
        Arg::Matrix { rows, cols, .. } => Err(Error::format(format!(
            "{what}: expected {TRACK_ROWS}, got shape ({rows}, {cols})"
        ))),
    }
}

/// The options every metric takes (the alignment), then APE's, then RPE's only.
const ALIGN_KEYS: [&str; 5] = [
    "align",
    "correct_scale",
    "n_to_align",
    "align_origin",
    "posyaw",
];
const APE_KEYS: [&str; 8] = [
    "pose_relation",
    "t_max_diff",
    "t_offset",
    "sync_method",
    "t_start",
    "t_end",
    "tum",
    "scale",
];
const RPE_KEYS: [&str; 6] = [
    "delta",
    "delta_unit",
    "delta_tol",
    "all_pairs",
    "pairs_from_reference",
    "max_pairs",
];

const RELATIONS: [PoseRelation; 7] = [
    PoseRelation::TransPart,
    PoseRelation::RotPart,
    PoseRelation::Full,
    PoseRelation::AngleDeg,
    PoseRelation::AngleRad,
    PoseRelation::PointDistance,
    PoseRelation::PointDistanceErrorRatio,
];

/// One keyword argument's value as `T`, or an error naming it and the type expected.
fn value<'py, T: FromPyObjectOwned<'py>>(
    key: &str,
    v: &Bound<'py, PyAny>,
    expected: &str,
) -> Result<T> {
    v.extract::<T>().map_err(|_| {
        Error::format(format!(
            "{key}: expected {expected}, got {}",
            v.repr().map_or("?".into(), |r| r.to_string())
        ))
    })
}

/// Keyword arguments (evo's option names) as [`MetricArgs`]; `allowed` are the names the
/// function takes. `None` keeps an option's default.
fn metric_args(options: Option<&Bound<'_, PyDict>>, allowed: &[&str]) -> Result<MetricArgs> {
    let mut a = MetricArgs::default();
    let Some(options) = options else {
        return Ok(a);
    };
    for (k, v) in options.iter() {
        let key: String = value("option", &k, "a name")?;
        if !allowed.contains(&key.as_str()) {
            return Err(Error::format(format!(
                "unknown option `{key}`: expected one of {}",
                allowed.join(", ")
            )));
        }
        if v.is_none() {
            continue;
        }
        let num = || value::<f64>(&key, &v, "a number");
        let flag = || value::<bool>(&key, &v, "True or False");
        match key.as_str() {
            "align" => a.align = flag()?,
            "correct_scale" => a.correct_scale = flag()?,
            "n_to_align" => a.n_to_align = value(&key, &v, "an integer")?,
            "align_origin" => a.align_origin = flag()?,
            "posyaw" => a.posyaw = flag()?,
            "pose_relation" => {
                let s: String = value(&key, &v, "a string")?;
                a.pose_relation = RELATIONS
                    .into_iter()
                    .find(|r| r.name() == s.replace('-', "_"))
                    .ok_or_else(|| {
                        Error::format(format!(
                            "pose_relation `{s}`: expected one of {}",
                            RELATIONS.map(|r| r.name()).join(", ")
                        ))
                    })?;
            }
            "t_max_diff" => a.t_max_diff = Some(num()?),
            "t_offset" => a.t_offset = num()?,
            "sync_method" => {
                let s: String = value(&key, &v, "a string")?;
                a.sync_method = match s.as_str() {
                    "nearest_time" => SyncMethod::NearestTime,
                    "interpolation" => SyncMethod::Interpolation,
                    _ => {
                        return Err(Error::format(format!(
                            "sync_method `{s}`: expected nearest_time or interpolation"
                        )))
                    }
                };
            }
            "t_start" => a.t_start = Some(num()?),
            "t_end" => a.t_end = Some(num()?),
            "tum" => a.tum = flag()?,
            "scale" => a.scale = Some(num()?),
            "delta" => a.delta = num()?,
            "delta_unit" => {
                let s: String = value(&key, &v, "a string")?;
                a.delta_unit = Some(s.parse().map_err(Error::format)?);
            }
            "delta_tol" => a.delta_tol = num()?,
            "all_pairs" => a.all_pairs = flag()?,
            "pairs_from_reference" => a.pairs_from_reference = flag()?,
            "max_pairs" => a.max_pairs = Some(value(&key, &v, "a non-negative integer")?),
            _ => unreachable!("every allowed option is matched"),
        }
    }
    Ok(a)
}

/// evo's result arrays (`error_array`, `timestamps`, ...) as numpy arrays.
fn arrays_dict<'py>(py: Python<'py>, arrays: Vec<NamedArray>) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    for a in arrays {
        let array = ArrayD::from_shape_vec(a.shape, a.values)
            .map_err(|e| Error::format(format!("{}: {e}", a.name)))?;
        d.set_item(a.name, array.into_pyarray(py))?;
    }
    Ok(d)
}

/// APE or RPE: the command's JSON and evo's arrays.
fn ape_or_rpe<'py>(
    py: Python<'py>,
    reference: &Bound<'py, PyAny>,
    estimate: &Bound<'py, PyAny>,
    format: Option<&str>,
    metric: ExtraMetric,
) -> PyResult<(String, Bound<'py, PyDict>)> {
    let r = extract_arg(reference, "reference", TRACK_ROWS)?;
    let e = extract_arg(estimate, "estimate", TRACK_ROWS)?;
    // as the command's format word: `euroc` is a EuRoC reference and a TUM estimate, each
    // file recognised by its first line
    let format = parse_format(format)?.filter(|f| *f != TrajectoryFormat::Euroc);
    let report = py.detach(|| -> Result<_> {
        let names = [name_of(&r, "reference"), name_of(&e, "estimate")];
        let (rt, et) = (
            track(&r, format, "the reference")?,
            track(&e, format, "the estimate")?,
        );
        let mut report = metric_report(&rt, &et, [&names[0], &names[1]], &metric)?;
        let json = serde_json::to_string(&report).map_err(|e| Error::format(e.to_string()))?;
        Ok((json, std::mem::take(&mut report.arrays)))
    })?;
    Ok((report.0, arrays_dict(py, report.1)?))
}

/// `monovo ape` (`monovo.ape` documents it).
#[pyfunction]
#[pyo3(signature = (reference, estimate, format=None, **options))]
fn _ape<'py>(
    py: Python<'py>,
    reference: &Bound<'py, PyAny>,
    estimate: &Bound<'py, PyAny>,
    format: Option<&str>,
    options: Option<&Bound<'py, PyDict>>,
) -> PyResult<(String, Bound<'py, PyDict>)> {
    let keys: Vec<&str> = ALIGN_KEYS.iter().chain(&APE_KEYS).copied().collect();
    let metric = metric_args(options, &keys)?
        .ape(Spelling::Names)
        .map_err(Error::format)?;
    ape_or_rpe(py, reference, estimate, format, metric)
}

/// `monovo rpe` (`monovo.rpe` documents it).
#[pyfunction]
#[pyo3(signature = (reference, estimate, format=None, **options))]
fn _rpe<'py>(
    py: Python<'py>,
    reference: &Bound<'py, PyAny>,
    estimate: &Bound<'py, PyAny>,
    format: Option<&str>,
    options: Option<&Bound<'py, PyDict>>,
) -> PyResult<(String, Bound<'py, PyDict>)> {
    let keys: Vec<&str> = ALIGN_KEYS
        .iter()
        .chain(&APE_KEYS)
        .chain(&RPE_KEYS)
        .copied()
        .collect();
    let metric = metric_args(options, &keys)?
        .rpe(Spelling::Names)
        .map_err(Error::format)?;
    ape_or_rpe(py, reference, estimate, format, metric)
}

/// `monovo kitti` (`monovo.kitti` documents it): the command's JSON.
#[pyfunction]
#[pyo3(signature = (groundtruth, estimate, **options))]
fn _kitti(
    py: Python<'_>,
    groundtruth: &Bound<'_, PyAny>,
    estimate: &Bound<'_, PyAny>,
    options: Option<&Bound<'_, PyDict>>,
) -> PyResult<String> {
    let align = metric_args(options, &ALIGN_KEYS)?
        .align_options(Spelling::Names)
        .map_err(Error::format)?;
    let g = extract_arg(groundtruth, "groundtruth", TRACK_ROWS)?;
    let e = extract_arg(estimate, "estimate", TRACK_ROWS)?;
    let json = py.detach(|| -> Result<String> {
        let report = match (&g, &e) {
            // files, or folders of NN.txt pooled, as the command reads them
            (Arg::Path(gp), Arg::Path(ep)) => run_kitti(&kitti_pairs(gp, ep)?, None, &align)?,
            _ => {
                let names = [name_of(&g, "groundtruth"), name_of(&e, "estimate")];
                let (gt, est) = (
                    track(&g, None, "the ground truth")?,
                    track(&e, None, "the estimate")?,
                );
                kitti_report(vec![(gt, est, names)], &align)?
            }
        };
        serde_json::to_string(&report).map_err(|e| Error::format(e.to_string()))
    })?;
    Ok(json)
}

/// Registers the metrics' functions.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(_ape, m)?)?;
    m.add_function(wrap_pyfunction!(_rpe, m)?)?;
    m.add_function(wrap_pyfunction!(_kitti, m)?)?;
    Ok(())
}
