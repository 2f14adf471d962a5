//! Ground truth in the other datasets' own formats: EuRoC's state csv and TUM-VI's mocap csv
//! (`ns, px, py, pz, qw, qx, qy, qz, ...`, the IMU's pose), 4Seasons' `GNSSPoses.txt`
//! (keyframes `ns, tx, ty, tz, qx, qy, qz, qw, scale, ...`: the camera's pose, translation
//! times its scale), KITTI's poses and TUM's `t x y z qx qy qz qw`; and the benchmark's
//! per-frame ground truth made from any of them.

use nalgebra::{Isometry3, Point3, Quaternion, Vector3};
use serde::{Deserialize, Serialize};

use crate::trajectory::{check_quaternion, data_lines, excerpt, parse_fields};
use crate::{EvalError, GroundTruth, Pose, Trajectory};

/// The ground-truth formats [`detect_ground_truth_format`] tells apart.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum GroundTruthFormat {
    /// The benchmark's groundtruthSync.txt, or any TUM-format file (`t x y z qx qy qz qw`).
    Tum,
    /// EuRoC's `state_groundtruth_estimate0/data.csv` (17 columns) or TUM-VI's
    /// `mocap0/data.csv` (8): nanoseconds, position, quaternion w first.
    Euroc,
    /// 4Seasons' `GNSSPoses.txt`.
    GnssPoses,
    /// KITTI's `poses/XX.txt` (12 numbers a line, with the sequence's times.txt).
    Kitti,
}

/// Tells the format of a ground-truth text from its first data line: commas with 9 or more
/// fields whose 9th is a positive scale and 8 fields before it GNSS poses, commas with a
/// nanosecond timestamp EuRoC, 12 numbers KITTI, else TUM.
pub fn detect_ground_truth_format(text: &str) -> GroundTruthFormat {
    let Some((_, line)) = data_lines(text).next() else {
        return GroundTruthFormat::Tum;
    };
    let fields: Vec<&str> = line
        .split(|c: char| c.is_ascii_whitespace() || c == ',')
        .filter(|s| !s.is_empty())
        .collect();
    let ns = fields
        .first()
        .and_then(|f| f.parse::<f64>().ok())
        .is_some_and(|t| t > 1e11);
    let comma = line.contains(',');
    if comma && ns && (fields.len() == 10 || fields.len() == 11) {
        GroundTruthFormat::GnssPoses
    } else if comma && ns {
        GroundTruthFormat::Euroc
    } else if fields.len() == 12 {
        GroundTruthFormat::Kitti
    } else {
        GroundTruthFormat::Tum
    }
}

/// Parses 4Seasons' `GNSSPoses.txt`: a `#` header, then per keyframe
/// `timestamp_ns, tx, ty, tz, qx, qy, qz, qw, scale, fusion_quality[, v3_quality]` (the
/// camera's pose in the GNSS frame, up to the scale of its column): the position is the
/// translation times the scale.
pub fn parse_gnss_poses(text: &str) -> Result<Trajectory, EvalError> {
    let mut poses = Vec::new();
    for (no, line) in data_lines(text) {
        let v = parse_fields::<9>(
            no,
            line,
            "at least 9 comma-separated numbers `timestamp_ns, tx, ty, tz, qx, qy, qz, qw, scale`",
            true,
        )?;
        check_quaternion(no, line, [v[4], v[5], v[6], v[7]])?;
        let scale = v[8];
        if !(scale.is_finite() && scale > 0.0) {
            return Err(EvalError::Parse {
                line: no,
                expected: "a positive scale in column 9",
                found: excerpt(line),
            });
        }
        poses.push(Pose {
            // a division is correctly rounded: whole seconds stay whole
            t: v[0] / 1e9,
            position: Vector3::new(v[1], v[2], v[3]) * scale,
            orientation: Quaternion::new(v[7], v[4], v[5], v[6]),
        });
    }
    Ok(Trajectory { poses })
}

/// Parses a ground truth of any [`GroundTruthFormat`] as a trajectory; KITTI needs the
/// sequence's times.txt.
pub fn parse_ground_truth_trajectory(
    text: &str,
    format: GroundTruthFormat,
    kitti_times: Option<&str>,
) -> Result<Trajectory, EvalError> {
    match format {
        GroundTruthFormat::Tum => crate::parse_tum(text),
        GroundTruthFormat::Euroc => crate::parse_euroc(text),
        GroundTruthFormat::GnssPoses => parse_gnss_poses(text),
        GroundTruthFormat::Kitti => crate::parse_kitti(text, kitti_times.unwrap_or("")),
    }
}

impl GroundTruth {
    /// The benchmark's per-frame ground truth made from a dataset's trajectory: the camera's
    /// positions (`body_from_camera` moves a body/IMU pose to the camera: `world_from_body *
    /// body_from_camera`; `None` when the poses are the camera's), sampled at `frame_times`
    /// by linear interpolation between ground-truth poses at most `max_gap` seconds apart
    /// (NaN elsewhere, as groundtruthSync.txt has outside its segments); with no frame times,
    /// the ground-truth rows themselves. Rows are sorted by time; NaN poses are kept as gaps.
    pub fn from_trajectory(
        traj: &Trajectory,
        body_from_camera: Option<&Isometry3<f64>>,
        frame_times: Option<&[f64]>,
        max_gap: f64,
    ) -> Result<GroundTruth, EvalError> {
        let mut rows: Vec<(f64, Vector3<f64>)> = traj
            .poses
            .iter()
            .map(|p| {
                let pos = match (body_from_camera, p.world_from_camera()) {
                    (Some(b), Some(w)) => (w * b * Point3::origin()).coords,
                    (Some(_), None) => Vector3::repeat(f64::NAN),
                    (None, _) => p.position,
                };
                (p.t, pos)
            })
            .collect();
        rows.sort_by(|a, b| a.0.total_cmp(&b.0));
        rows.dedup_by(|a, b| a.0 == b.0);
        if rows.is_empty() {
            return Err(EvalError::EmptyGroundTruth);
        }
        let Some(frames) = frame_times else {
            let (t, p) = rows.into_iter().unzip();
            return GroundTruth::from_rows(t, p);
        };
        let positions = frames
            .iter()
            .map(|&t| {
                let k = rows.partition_point(|r| r.0 < t);
                let at = |i: usize| rows.get(i).copied();
                match (k.checked_sub(1).and_then(at), at(k)) {
                    (_, Some(b)) if b.0 == t => b.1,
                    (Some(a), Some(b)) if b.0 - a.0 <= max_gap => {
                        let s = (t - a.0) / (b.0 - a.0);
                        a.1 + (b.1 - a.1) * s
                    }
                    _ => Vector3::repeat(f64::NAN),
                }
            })
            .collect();
        GroundTruth::from_rows(frames.to_vec(), positions)
    }
}
