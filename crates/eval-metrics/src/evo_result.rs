//! evo's result files (`--save_results res.zip`, read by `evo_res`): a zip of `info.json`
//! (title, reference and estimate names, label), `stats.json` (rmse, mean, median, std, min,
//! max, sse) and one numpy `.npy` file per array (`error_array`, `timestamps`,
//! `seconds_from_start`, `distances_from_start`, `distances`,
//! `alignment_transformation_sim3`). This module makes the entries; writing the zip is the
//! caller's (dataset-io).

use serde::Serialize;

use crate::stats::ErrorStats;

/// The `info.json` of an evo result.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct EvoResultInfo {
    /// Title (metric, unit, alignment), as evo writes it.
    pub title: String,
    /// The reference's name (its path as given).
    pub ref_name: String,
    /// The estimate's name (its path as given).
    pub est_name: String,
    /// Axis label, e.g. `APE (m)`.
    pub label: String,
}

/// One numpy array of a result: its name (without `.npy`), row-major values and shape.
#[derive(Clone, Debug, PartialEq)]
pub struct NamedArray {
    /// File name without the extension.
    pub name: String,
    /// Values, row-major.
    pub values: Vec<f64>,
    /// Shape (one number for a vector).
    pub shape: Vec<usize>,
}

/// A little-endian float64 array in numpy's `.npy` format (version 1.0, header padded to a
/// multiple of 64 bytes), as `np.save` writes it.
///
/// ```
/// let b = eval_metrics::npy_bytes(&[1.0, 2.0], &[2]);
/// assert_eq!(&b[..6], b"\x93NUMPY");
/// assert_eq!((b.len() - 16) % 64, 0); // the header is padded to 64 bytes, then 2 x 8 bytes
/// ```
pub fn npy_bytes(values: &[f64], shape: &[usize]) -> Vec<u8> {
    let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    let shape_text = if dims.len() == 1 {
        format!("({},)", dims[0])
    } else {
        format!("({})", dims.join(", "))
    };
    let mut header = format!("{{'descr': '<f8', 'fortran_order': False, 'shape': {shape_text}, }}");
    // magic (6) + version (2) + length (2) + header + '\n', a multiple of 64
    let total = 10 + header.len() + 1;
    header.push_str(&" ".repeat((64 - total % 64) % 64));
    header.push('\n');
    let mut out = Vec::with_capacity(10 + header.len() + values.len() * 8);
    out.extend_from_slice(b"\x93NUMPY\x01\x00");
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    for v in values {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out
}

/// JSON of a float as Python's `json.dumps` writes it (`NaN`, `Infinity` for the others).
fn py_json_number(v: f64) -> String {
    if v.is_finite() {
        serde_json::to_string(&v).unwrap_or_else(|_| "NaN".into())
    } else if v.is_nan() {
        "NaN".into()
    } else if v > 0.0 {
        "Infinity".into()
    } else {
        "-Infinity".into()
    }
}

/// The entries of an evo result zip, in evo's order: `info.json`, `stats.json`, then the
/// arrays.
pub fn evo_result_entries(
    info: &EvoResultInfo,
    stats: &ErrorStats,
    arrays: &[NamedArray],
) -> Vec<(String, Vec<u8>)> {
    let info_json = serde_json::to_string(info).unwrap_or_default();
    let stats_json = format!(
        "{{\"rmse\": {}, \"mean\": {}, \"median\": {}, \"std\": {}, \"min\": {}, \"max\": {}, \"sse\": {}}}",
        py_json_number(stats.rmse),
        py_json_number(stats.mean),
        py_json_number(stats.median),
        py_json_number(stats.std),
        py_json_number(stats.min),
        py_json_number(stats.max),
        py_json_number(stats.sse)
    );
    let mut out = vec![
        ("info.json".to_string(), info_json.into_bytes()),
        ("stats.json".to_string(), stats_json.into_bytes()),
    ];
    for a in arrays {
        out.push((format!("{}.npy", a.name), npy_bytes(&a.values, &a.shape)));
    }
    out
}
