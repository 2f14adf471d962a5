//! Trajectory text formats: TUM (`t x y z qx qy qz qw`), KITTI (12 numbers a line plus a
//! times file) and EuRoC csv, and the benchmark's `groundtruthSync.txt`.

use nalgebra::{Isometry3, Matrix3, Quaternion, Rotation3, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use crate::EvalError;

/// One camera pose: time, position and orientation of the camera in the world
/// (camera-to-world, `world_from_camera`).
///
/// The orientation is kept as read: the evaluation uses positions only, and a file's
/// quaternion need not be of unit norm. [`Pose::world_from_camera`] gives the rigid
/// transform.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    /// Timestamp in seconds.
    pub t: f64,
    /// Camera centre in world coordinates.
    pub position: Vector3<f64>,
    /// Orientation quaternion as read (TUM order `qx qy qz qw`, see [`Quaternion::coords`]).
    pub orientation: Quaternion<f64>,
}

impl Pose {
    /// Whether every number of the pose is finite.
    pub fn is_finite(&self) -> bool {
        self.t.is_finite()
            && self.position.iter().all(|v| v.is_finite())
            && self.orientation.coords.iter().all(|v| v.is_finite())
    }

    /// The camera-to-world rigid transform (the orientation normalised), or `None` when the
    /// pose is not finite or its quaternion has (nearly) zero norm.
    ///
    /// ```
    /// use eval_metrics::parse_tum;
    /// use nalgebra::Point3;
    ///
    /// // a camera at (1, 2, 3) turned by 90 degrees about z
    /// let t = parse_tum("0 1 2 3 0 0 0.7071067811865476 0.7071067811865476\n")?;
    /// let world_from_camera = t.poses[0].world_from_camera().unwrap();
    /// let p = world_from_camera * Point3::new(1.0, 0.0, 0.0);
    /// assert!((p - Point3::new(1.0, 3.0, 3.0)).norm() < 1e-12);
    /// # Ok::<(), eval_metrics::EvalError>(())
    /// ```
    pub fn world_from_camera(&self) -> Option<Isometry3<f64>> {
        if !self.is_finite() {
            return None;
        }
        let q = UnitQuaternion::try_new(self.orientation, 1e-12)?;
        Some(Isometry3::from_parts(Translation3::from(self.position), q))
    }
}

/// A sequence of poses in file order.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Trajectory {
    /// The poses, in the order of the file.
    pub poses: Vec<Pose>,
}

/// Supported trajectory file formats.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TrajectoryFormat {
    /// `t x y z qx qy qz qw` per line (spaces or commas), `#` comments.
    Tum,
    /// `r11 r12 r13 tx r21 r22 r23 ty r31 r32 r33 tz` per line, timestamps from a times file.
    Kitti,
    /// EuRoC csv: `timestamp_ns, px, py, pz, qw, qx, qy, qz[, ...]`, `#` header.
    Euroc,
}

const MAX_FOUND: usize = 120;

pub(crate) fn excerpt(line: &str) -> String {
    let t = line.trim();
    if t.len() <= MAX_FOUND {
        t.to_string()
    } else {
        let mut end = MAX_FOUND;
        while !t.is_char_boundary(end) {
            end -= 1;
        }
        format!("{}...", &t[..end])
    }
}

/// Iterates the data lines of a text: 1-based line number and content, skipping blank lines
/// and `#` comments (and a UTF-8 byte-order mark at the start).
pub(crate) fn data_lines(text: &str) -> impl Iterator<Item = (usize, &str)> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    text.lines().enumerate().filter_map(|(i, l)| {
        let t = l.trim();
        if t.is_empty() || t.starts_with('#') || t.starts_with("//") || t.starts_with('%') {
            None
        } else {
            Some((i + 1, t))
        }
    })
}

/// The error for a line that did not parse: a hint about the decimal separator when the line
/// has exactly `n` blank-separated words and some of them look like `0,5`.
fn line_error(line_no: usize, line: &str, expected: &'static str, n: usize) -> EvalError {
    let words: Vec<&str> = line.split_ascii_whitespace().collect();
    let decimal_comma = words.len() == n
        && words.iter().any(|w| {
            w.as_bytes()
                .windows(3)
                .any(|t| t[0].is_ascii_digit() && t[1] == b',' && t[2].is_ascii_digit())
        });
    if decimal_comma {
        EvalError::DecimalComma {
            line: line_no,
            found: excerpt(line),
        }
    } else {
        EvalError::Parse {
            line: line_no,
            expected,
            found: excerpt(line),
        }
    }
}

/// Parses exactly `N` numbers (or at least `N` when `allow_more`) separated by whitespace or
/// commas. NaN and infinities parse (the evaluation decides what they mean).
pub(crate) fn parse_fields<const N: usize>(
    line_no: usize,
    line: &str,
    expected: &'static str,
    allow_more: bool,
) -> Result<[f64; N], EvalError> {
    let mut out = [0.0; N];
    let mut count = 0;
    for tok in line
        .split(|c: char| c.is_ascii_whitespace() || c == ',')
        .filter(|s| !s.is_empty())
    {
        if count >= N {
            if allow_more {
                break;
            }
            count += 1;
            break;
        }
        out[count] = tok
            .parse::<f64>()
            .map_err(|_| line_error(line_no, line, expected, N))?;
        count += 1;
    }
    if count != N {
        return Err(line_error(line_no, line, expected, N));
    }
    Ok(out)
}

const TUM_EXPECTED: &str = "8 numbers `t x y z qx qy qz qw`";

/// Refuses a finite quaternion of (nearly) zero norm: no rotation, whatever the position.
pub(crate) fn check_quaternion(line_no: usize, line: &str, q: [f64; 4]) -> Result<(), EvalError> {
    let n2: f64 = q.iter().map(|v| v * v).sum();
    if n2.is_finite() && n2 < 1e-12 {
        return Err(EvalError::NotARotation {
            line: line_no,
            what: "the quaternion is zero",
            found: excerpt(line),
        });
    }
    Ok(())
}

/// Parses a TUM-format trajectory.
pub fn parse_tum(text: &str) -> Result<Trajectory, EvalError> {
    let mut poses = Vec::with_capacity(text.len() / 80);
    for (no, line) in data_lines(text) {
        let v = parse_fields::<8>(no, line, TUM_EXPECTED, false)?;
        check_quaternion(no, line, [v[4], v[5], v[6], v[7]])?;
        poses.push(Pose {
            t: v[0],
            position: Vector3::new(v[1], v[2], v[3]),
            orientation: Quaternion::new(v[7], v[4], v[5], v[6]),
        });
    }
    Ok(Trajectory { poses })
}

/// Parses a KITTI pose file (3x4 `[R | t]` row-major, camera-to-world) with its times file
/// (one timestamp in seconds per line).
pub fn parse_kitti(poses_text: &str, times_text: &str) -> Result<Trajectory, EvalError> {
    let mut times = Vec::new();
    for (no, line) in data_lines(times_text) {
        let v = parse_fields::<1>(no, line, "one timestamp in seconds", false)?;
        times.push(v[0]);
    }
    let mut poses = Vec::with_capacity(times.len());
    for (no, line) in data_lines(poses_text) {
        let v = parse_fields::<12>(
            no,
            line,
            "12 numbers `r11 r12 r13 tx r21 r22 r23 ty r31 r32 r33 tz`",
            false,
        )?;
        let r = Matrix3::new(v[0], v[1], v[2], v[4], v[5], v[6], v[8], v[9], v[10]);
        let det = r.determinant();
        if det.is_finite() && det.abs() < 1e-6 {
            return Err(EvalError::NotARotation {
                line: no,
                what: "the rotation matrix is singular",
                found: excerpt(line),
            });
        }
        let orientation = if r.iter().all(|x| x.is_finite()) {
            // the quaternion of the matrix as written, with qw >= 0
            let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r));
            if q.w < 0.0 {
                -q.into_inner()
            } else {
                q.into_inner()
            }
        } else {
            Quaternion::new(f64::NAN, f64::NAN, f64::NAN, f64::NAN)
        };
        poses.push(Pose {
            t: 0.0,
            position: Vector3::new(v[3], v[7], v[11]),
            orientation,
        });
    }
    if poses.len() != times.len() {
        return Err(EvalError::KittiCount {
            poses: poses.len(),
            times: times.len(),
        });
    }
    for (p, t) in poses.iter_mut().zip(times) {
        p.t = t;
    }
    Ok(Trajectory { poses })
}

/// Parses an EuRoC csv trajectory (`timestamp [ns], p_x, p_y, p_z, q_w, q_x, q_y, q_z`, any
/// further columns ignored).
pub fn parse_euroc(text: &str) -> Result<Trajectory, EvalError> {
    let mut poses = Vec::new();
    for (no, line) in data_lines(text) {
        let v = parse_fields::<8>(
            no,
            line,
            "at least 8 comma-separated numbers `timestamp_ns, px, py, pz, qw, qx, qy, qz`",
            true,
        )?;
        check_quaternion(no, line, [v[4], v[5], v[6], v[7]])?;
        poses.push(Pose {
            // nanoseconds to seconds as evo does (a division: exact for exact values)
            t: v[0] / 1e9,
            position: Vector3::new(v[1], v[2], v[3]),
            orientation: Quaternion::new(v[4], v[5], v[6], v[7]),
        });
    }
    Ok(Trajectory { poses })
}

/// Guesses the format of a trajectory text from its first data line: commas with a
/// nanosecond timestamp mean EuRoC, 12 numbers KITTI, otherwise TUM.
pub fn detect_format(text: &str) -> TrajectoryFormat {
    let Some((_, line)) = data_lines(text).next() else {
        return TrajectoryFormat::Tum;
    };
    let fields: Vec<&str> = line
        .split(|c: char| c.is_ascii_whitespace() || c == ',')
        .filter(|s| !s.is_empty())
        .collect();
    let first_is_ns = fields
        .first()
        .and_then(|f| f.parse::<f64>().ok())
        .is_some_and(|t| t > 1e11);
    if line.contains(',') && first_is_ns {
        TrajectoryFormat::Euroc
    } else if fields.len() == 12 {
        TrajectoryFormat::Kitti
    } else {
        TrajectoryFormat::Tum
    }
}

/// The benchmark's loop-closure ground truth (`groundtruthSync.txt`): one row per frame,
/// `NaN` positions outside the start and end segments.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct GroundTruth {
    times: Vec<f64>,
    positions: Vec<Vector3<f64>>,
    /// Orientations as read (`w, x, y, z`); identity for [`GroundTruth::from_rows`].
    orientations: Vec<Quaternion<f64>>,
}

impl GroundTruth {
    /// Parses `groundtruthSync.txt` (TUM format; NaN rows allowed; timestamps strictly
    /// increasing).
    pub fn parse(text: &str) -> Result<GroundTruth, EvalError> {
        let mut times = Vec::with_capacity(text.len() / 60);
        let mut positions = Vec::with_capacity(text.len() / 60);
        let mut orientations = Vec::with_capacity(text.len() / 60);
        let mut prev: Option<(usize, f64)> = None;
        for (no, line) in data_lines(text) {
            let v = parse_fields::<8>(no, line, TUM_EXPECTED, false)?;
            let t = v[0];
            if !t.is_finite() {
                return Err(EvalError::Parse {
                    line: no,
                    expected: "a finite timestamp",
                    found: excerpt(line),
                });
            }
            if let Some((_, p)) = prev {
                if t <= p {
                    return Err(EvalError::GroundTruthOrder {
                        line: no,
                        t,
                        previous: p,
                    });
                }
            }
            prev = Some((no, t));
            times.push(t);
            positions.push(Vector3::new(v[1], v[2], v[3]));
            orientations.push(Quaternion::new(v[7], v[4], v[5], v[6]));
        }
        if times.is_empty() {
            return Err(EvalError::EmptyGroundTruth);
        }
        Ok(GroundTruth {
            times,
            positions,
            orientations,
        })
    }

    /// Builds a ground truth from times and positions (NaN positions allowed; times must
    /// strictly increase).
    pub fn from_rows(
        times: Vec<f64>,
        positions: Vec<Vector3<f64>>,
    ) -> Result<GroundTruth, EvalError> {
        if times.is_empty() {
            return Err(EvalError::EmptyGroundTruth);
        }
        if times.len() != positions.len() {
            return Err(EvalError::RowCount {
                times: times.len(),
                positions: positions.len(),
            });
        }
        for i in 1..times.len() {
            if times[i].is_nan() || times[i] <= times[i - 1] {
                return Err(EvalError::GroundTruthOrder {
                    line: i + 1,
                    t: times[i],
                    previous: times[i - 1],
                });
            }
        }
        let orientations = vec![Quaternion::identity(); times.len()];
        Ok(GroundTruth {
            times,
            positions,
            orientations,
        })
    }

    /// The rows with a finite pose as a stamped track (for APE, RPE and the KITTI segment
    /// errors); a row with a zero or non-finite quaternion counts as not finite.
    pub fn track(&self) -> crate::PoseTrack {
        let ok: Vec<usize> = (0..self.times.len())
            .filter(|&i| {
                let q = &self.orientations[i];
                self.positions[i].iter().all(|v| v.is_finite())
                    && q.coords.iter().all(|v| v.is_finite())
                    && q.norm_squared() > 1e-12
            })
            .collect();
        let mut t = crate::PoseTrack {
            times: Some(ok.iter().map(|&i| self.times[i]).collect()),
            positions: ok.iter().map(|&i| self.positions[i]).collect(),
            rotations: Vec::with_capacity(ok.len()),
            quaternions: ok.iter().map(|&i| self.orientations[i]).collect(),
        };
        t.rotations = t.quaternions.iter().map(crate::quaternion_matrix).collect();
        t
    }

    /// Row timestamps.
    pub fn times(&self) -> &[f64] {
        &self.times
    }

    /// Row positions (NaN outside the segments).
    pub fn positions(&self) -> &[Vector3<f64>] {
        &self.positions
    }

    /// Number of rows.
    pub fn len(&self) -> usize {
        self.times.len()
    }

    /// Always false: a ground truth has at least one row.
    pub fn is_empty(&self) -> bool {
        self.times.is_empty()
    }

    /// Number of rows with a finite position in the start window and in the end window.
    pub fn segment_sizes(&self) -> (usize, usize) {
        let (s, e) = self.window_bounds();
        let finite = |i: &usize| self.positions[*i].iter().all(|v| v.is_finite());
        (
            (0..=s).filter(finite).count(),
            (e..self.len()).filter(finite).count(),
        )
    }

    /// Last row index of the start window and first row index of the end window (0-based):
    /// with `n` rows the windows are rows `1..=floor(n/2)` and `ceil(n/2)..=n` (1-based).
    pub fn window_bounds(&self) -> (usize, usize) {
        let n = self.len();
        let start_last = (n / 2).max(1) - 1;
        let end_first = n.div_ceil(2).max(1) - 1;
        (start_last, end_first)
    }

    /// Index of the row nearest in time to `t`, if within `tolerance` seconds.
    pub fn associate(&self, t: f64, tolerance: f64) -> Option<usize> {
        let i = self.times.partition_point(|&x| x < t);
        let mut best: Option<(usize, f64)> = None;
        for j in [i.wrapping_sub(1), i] {
            if let Some(&x) = self.times.get(j) {
                let d = (x - t).abs();
                if best.is_none_or(|(_, bd)| d < bd) {
                    best = Some((j, d));
                }
            }
        }
        best.filter(|&(_, d)| d <= tolerance).map(|(j, _)| j)
    }
}
