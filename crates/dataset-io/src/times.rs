//! `times.txt`: one line per image, `id timestamp_s exposure_ms`; two columns mean unknown
//! exposure. Read like DSO reads it (`%d %lf %f`): columns after the third are ignored, and
//! so are a UTF-8 byte-order mark and CRLF line ends. A file of one column (KITTI's
//! `times.txt`: timestamps only, which DSO misreads: `1.037359e-01` becomes id 1 and
//! timestamp `.037359e-01`) is read as timestamps.

use std::path::Path;

use crate::DatasetError;

/// One row of times.txt.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TimeRow {
    /// The image id as written (usually the file stem, `00000`).
    pub id: String,
    /// Timestamp in seconds.
    pub timestamp: f64,
    /// Exposure time in milliseconds, `None` when the file has no third column.
    pub exposure_ms: Option<f64>,
    /// The timestamp in integer nanoseconds, exact where the file gives it (an id of 16 to 19
    /// digits that agrees with the timestamp, as TUM-VI's and 4Seasons' times.txt have, or a
    /// timestamp with at most 9 decimals); an `f64` cannot hold 1.6e18 ns.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub timestamp_ns: Option<i64>,
}

/// The exact integer nanoseconds of a decimal number of seconds (`1520530308.199447626`;
/// more than 9 decimals are rounded half up; an exponent is read through `f64`). `None` for
/// anything else, or beyond the range of `i64`.
pub fn seconds_to_ns(text: &str) -> Option<i64> {
    let t = text.trim();
    if t.contains(['e', 'E']) {
        let v = t.parse::<f64>().ok()?;
        let ns = (v * 1e9).round();
        return (ns.is_finite() && ns.abs() < 9.2e18).then_some(ns as i64);
    }
    let (neg, t) = match t.strip_prefix('-') {
        Some(r) => (true, r),
        None => (false, t.strip_prefix('+').unwrap_or(t)),
    };
    let (int, frac) = t.split_once('.').unwrap_or((t, ""));
    if int.is_empty() && frac.is_empty()
        || !int.bytes().all(|b| b.is_ascii_digit())
        || !frac.bytes().all(|b| b.is_ascii_digit())
    {
        return None;
    }
    let whole: i64 = if int.is_empty() { 0 } else { int.parse().ok()? };
    let mut digits: Vec<u8> = frac.bytes().map(|b| b - b'0').collect();
    let round_up = digits.len() > 9 && digits[9] >= 5;
    digits.resize(9, 0);
    let mut nanos = digits.iter().fold(0i64, |a, d| a * 10 + *d as i64);
    if round_up {
        nanos += 1;
    }
    let v = whole.checked_mul(1_000_000_000)?.checked_add(nanos)?;
    Some(if neg { -v } else { v })
}

/// The nanoseconds of a row: its id when that is an integer of 16 to 19 digits within 1 ms of
/// the timestamp (TUM-VI, 4Seasons), else the timestamp's text read exactly.
fn row_ns(id: &str, t_text: &str, timestamp: f64) -> Option<i64> {
    if (16..=19).contains(&id.len()) && id.bytes().all(|b| b.is_ascii_digit()) {
        if let Ok(ns) = id.parse::<i64>() {
            if (ns as f64 * 1e-9 - timestamp).abs() < 1e-3 {
                return Some(ns);
            }
        }
    }
    seconds_to_ns(t_text)
}

/// Formats integer nanoseconds as exact decimal seconds (`1520530308.199447626`).
pub fn ns_to_seconds_text(ns: i64) -> String {
    let sign = if ns < 0 { "-" } else { "" };
    let a = ns.unsigned_abs();
    format!("{sign}{}.{:09}", a / 1_000_000_000, a % 1_000_000_000)
}

/// A parsed times.txt, with the notes about what was repaired.
#[derive(Clone, Debug, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct Times {
    /// The rows, in file order.
    pub rows: Vec<TimeRow>,
    /// The 1-based line of the file of each row.
    pub lines: Vec<usize>,
    /// Warnings (for example interpolated zero exposures), each naming the file and line.
    pub warnings: Vec<String>,
}

impl Times {
    /// Whether every row has a positive exposure.
    pub fn has_exposures(&self) -> bool {
        !self.rows.is_empty()
            && self
                .rows
                .iter()
                .all(|r| r.exposure_ms.is_some_and(|e| e > 0.0))
    }

    /// The first row whose exposure is unknown (no third column, or 0 that could not be
    /// interpolated): its index and its 1-based line in the file.
    pub fn first_unknown_exposure(&self) -> Option<(usize, usize)> {
        let k = self
            .rows
            .iter()
            .position(|r| !r.exposure_ms.is_some_and(|e| e > 0.0))?;
        Some((k, self.lines.get(k).copied().unwrap_or(k + 1)))
    }

    /// Smallest and largest exposure in ms, if known.
    pub fn exposure_range(&self) -> Option<(f64, f64)> {
        let mut lo = f64::INFINITY;
        let mut hi = f64::NEG_INFINITY;
        for r in &self.rows {
            let e = r.exposure_ms?;
            lo = lo.min(e);
            hi = hi.max(e);
        }
        lo.is_finite().then_some((lo, hi))
    }
}

fn excerpt(s: &str) -> String {
    s.trim().chars().take(100).collect()
}

/// Parses times.txt. Timestamps must be finite and strictly increasing; exposures finite and
/// non-negative. A zero exposure between two known ones is interpolated (as DSO does) with a
/// warning; other zero exposures are kept (the caller decides whether it needs them).
pub fn parse_times(text: &str, path: &Path) -> Result<Times, DatasetError> {
    let mut rows: Vec<TimeRow> = Vec::new();
    let mut lines: Vec<usize> = Vec::new();
    let mut columns: Option<usize> = None;
    let mut prev: Option<f64> = None;
    let mut warnings = Vec::new();
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut extra_columns = 0usize;
    for (i, line) in text.lines().enumerate() {
        let no = i + 1;
        let t = line.trim();
        if t.is_empty() || t.starts_with('#') {
            continue;
        }
        let mut f: Vec<&str> = t.split_whitespace().collect();
        let comma = f.iter().any(|tok| {
            let b = tok.as_bytes();
            b.windows(3)
                .any(|w| w[0].is_ascii_digit() && w[1] == b',' && w[2].is_ascii_digit())
        });
        let bad = |expected: &str| DatasetError::Parse {
            path: path.to_path_buf(),
            line: no,
            expected: if comma {
                format!("{expected} (the decimal separator must be '.', not ',')")
            } else {
                expected.into()
            },
            found: excerpt(t),
        };
        if f.len() > 3 {
            extra_columns += 1;
            f.truncate(3);
        }
        if let Some(c) = columns {
            if c != f.len() {
                return Err(bad(&format!("{c} columns like the lines before")));
            }
        }
        columns = Some(f.len());
        // one column: timestamps only (KITTI), the id is the row number
        let (id, t_col) = if f.len() == 1 {
            (rows.len().to_string(), 0)
        } else {
            (f[0].to_string(), 1)
        };
        let timestamp = f[t_col]
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| {
                bad(if f.len() == 1 {
                    "`id timestamp_s exposure_ms` (3 columns), `id timestamp_s`, or a timestamp in seconds alone"
                } else {
                    "a finite timestamp in seconds in column 2"
                })
            })?;
        if let Some(p) = prev {
            if timestamp <= p {
                return Err(bad(&format!(
                    "a timestamp after the previous one ({p}); timestamps must strictly increase"
                )));
            }
        }
        prev = Some(timestamp);
        let exposure_ms = match f.get(2) {
            Some(e) => Some(
                e.parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite() && *v >= 0.0)
                    .ok_or_else(|| bad("a finite, non-negative exposure in ms in column 3"))?,
            ),
            None => None,
        };
        let timestamp_ns = row_ns(&id, f[t_col], timestamp);
        rows.push(TimeRow {
            id,
            timestamp,
            exposure_ms,
            timestamp_ns,
        });
        lines.push(no);
    }
    if extra_columns > 0 {
        warnings.push(format!(
            "{}: {extra_columns} lines have more than 3 columns; the columns after `id timestamp exposure` are ignored, as DSO ignores them",
            path.display()
        ));
    }
    if columns == Some(1) {
        warnings.push(format!(
            "{}: one column: read as timestamps in seconds (KITTI's times.txt), exposures unknown; DSO misreads such a file (the digits before the '.' as the id, the rest as the timestamp)",
            path.display()
        ));
    }
    // interpolate isolated zero exposures between two known ones (as DSO does)
    let known = |e: Option<f64>| e.is_some_and(|e| e > 0.0);
    let mut unknown = Vec::new();
    for i in 0..rows.len() {
        if rows[i].exposure_ms != Some(0.0) {
            continue;
        }
        let before = i.checked_sub(1).and_then(|j| rows[j].exposure_ms);
        let after = rows.get(i + 1).and_then(|r| r.exposure_ms);
        match (before, after) {
            (Some(a), Some(b)) if known(Some(a)) && known(Some(b)) => {
                let e = 0.5 * (a + b);
                rows[i].exposure_ms = Some(e);
                warnings.push(format!(
                    "{}: line {}: exposure 0 interpolated to {e} ms from its neighbours (as DSO does)",
                    path.display(),
                    lines[i]
                ));
            }
            _ => unknown.push(lines[i]),
        }
    }
    if let Some(first) = unknown.first() {
        warnings.push(format!(
            "{}: line {first}: exposure 0 with no known exposure on both sides: unknown, not interpolated{}",
            path.display(),
            if unknown.len() > 1 {
                format!(" ({} such lines)", unknown.len())
            } else {
                String::new()
            }
        ));
    }
    Ok(Times {
        rows,
        lines,
        warnings,
    })
}

/// Writes times.txt (`id timestamp exposure`, or two columns when no exposure is known); a
/// row with nanoseconds gets its exact decimal seconds (9 decimals), else 6 decimals.
pub fn times_text(rows: &[TimeRow]) -> String {
    let mut s = String::with_capacity(rows.len() * 40);
    for r in rows {
        let t = match r.timestamp_ns {
            Some(ns) => ns_to_seconds_text(ns),
            None => format!("{:.6}", r.timestamp),
        };
        match r.exposure_ms {
            Some(e) => s.push_str(&format!("{} {t} {}\n", r.id, e)),
            None => s.push_str(&format!("{} {t}\n", r.id)),
        }
    }
    s
}

impl Times {
    /// The timestamps in integer nanoseconds, when every row has them exactly.
    pub fn timestamps_ns(&self) -> Option<Vec<i64>> {
        self.rows.iter().map(|r| r.timestamp_ns).collect()
    }
}
