//! Benchmark-like camera paths and synthetic VO estimates with known drift.
//!
//! A path starts and ends with slow, loopy motion over the same place (the start and end
//! segments, where the benchmark has loop-closure ground truth) and explores a large loop in
//! between; its length is normalised to about 100, as in the dataset. Estimates are built from
//! the path's motion increments with injected drift (scale and rotation jumps, random walk),
//! an arbitrary similarity of the whole estimate, keyframe subsets, lost tracking and
//! backwards playback.

use std::fmt::Write as _;

use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, Unit, UnitQuaternion, Vector3};

use crate::rng::Rng;

/// A 3-vector given as an array (drift axes).
pub type Vec3 = [f64; 3];

/// Rotation about an axis (normalised here) by `angle` radians.
pub fn rotation(axis: Vec3, angle: f64) -> Rotation3<f64> {
    Rotation3::from_axis_angle(&Unit::new_normalize(Vector3::from(axis)), angle)
}

/// A ground-truth camera path, one pose per frame.
#[derive(Clone, Debug)]
pub struct Path {
    /// Frame timestamps in seconds.
    pub times: Vec<f64>,
    /// Camera centres in the world (world z is up).
    pub positions: Vec<Vector3<f64>>,
    /// `world_from_camera` rotations (camera x right, y down, z forward).
    pub rotations: Vec<Rotation3<f64>>,
    /// Frames in the start segment (the first ones) and in the end segment (the last ones).
    pub segment_frames: usize,
}

/// Parameters of [`benchmark_path`].
#[derive(Clone, Copy, Debug, serde::Serialize, serde::Deserialize)]
pub struct PathConfig {
    /// Number of frames.
    pub frames: usize,
    /// Frame rate in Hz.
    pub fps: f64,
    /// Timestamp of the first frame (the dataset's are Unix times around 1.4e9 s).
    pub start_time: f64,
    /// Fraction of the frames in each of the start and end segments.
    pub segment_fraction: f64,
    /// Total path length after normalisation.
    pub length: f64,
}

impl Default for PathConfig {
    fn default() -> Self {
        PathConfig {
            frames: 1000,
            fps: 25.0,
            start_time: 1_400_000_000.0,
            segment_fraction: 0.15,
            length: 100.0,
        }
    }
}

/// A benchmark-like path: loopy start segment, exploring loop, loopy end segment over the
/// start's place; length normalised to `config.length`.
pub fn benchmark_path(seed: u64, config: &PathConfig) -> Path {
    let mut rng = Rng::derive(seed, 1);
    let n = config.frames.max(8);
    let k = ((n as f64 * config.segment_fraction).round() as usize).clamp(3, n / 2 - 1);
    let tau = std::f64::consts::TAU;
    // small Lissajous loops, zero at both ends
    let (a1, a2, a3) = (
        rng.range(0.8, 1.4),
        rng.range(0.5, 0.9),
        rng.range(0.25, 0.45),
    );
    let (b1, b2, b3) = (
        rng.range(0.8, 1.4),
        rng.range(0.5, 0.9),
        rng.range(0.25, 0.45),
    );
    let loop_a = |u: f64| {
        Vector3::new(
            a1 * (tau * 2.0 * u).sin(),
            a2 * (tau * 3.0 * u).sin(),
            a3 * (tau * u).sin(),
        )
    };
    let loop_b = |u: f64| {
        Vector3::new(
            b1 * (tau * 3.0 * u).sin(),
            b2 * (tau * 2.0 * u).sin(),
            b3 * (tau * u).sin(),
        )
    };
    // the exploring loop: a large closed curve from the origin back to it with random harmonics
    let radius = rng.range(8.0, 12.0);
    let aspect = rng.range(0.6, 1.0);
    let harm: Vec<(f64, f64, f64)> = (0..3)
        .map(|i| {
            (
                rng.range(-0.15, 0.15) * radius,
                (i + 2) as f64,
                rng.range(-0.5, 0.5),
            )
        })
        .collect();
    let explore = |v: f64| {
        let mut p = Vector3::new(
            radius * (1.0 - (tau * v).cos()),
            aspect * radius * (tau * v).sin(),
            0.8 * (tau * 2.0 * v).sin(),
        );
        for &(amp, f, zf) in &harm {
            let w = (std::f64::consts::PI * f * v).sin();
            p[1] += amp * w * (tau * v).sin();
            p[2] += zf * w * (tau * v).sin();
        }
        p
    };
    let mut positions = Vec::with_capacity(n);
    for i in 0..n {
        let p = if i < k {
            loop_a(i as f64 / (k - 1) as f64)
        } else if i >= n - k {
            loop_b((i - (n - k)) as f64 / (k - 1) as f64)
        } else {
            explore((i - k + 1) as f64 / (n - 2 * k + 1) as f64)
        };
        positions.push(p);
    }
    // normalise the length
    let len: f64 = positions.windows(2).map(|w| (w[1] - w[0]).norm()).sum();
    let s = config.length / len.max(1e-12);
    for p in positions.iter_mut() {
        *p *= s;
    }
    // orientation: heading follows the exploring motion, wiggles in the segments
    let heading0 = rng.range(0.0, tau);
    let mut rotations = Vec::with_capacity(n);
    let mut heading = heading0;
    for i in 0..n {
        if i >= k && i < n - k && i + 1 < n {
            let d = [
                positions[i + 1][0] - positions[i][0],
                positions[i + 1][1] - positions[i][1],
            ];
            if d[0].hypot(d[1]) > 1e-9 {
                heading = d[1].atan2(d[0]);
            }
        } else {
            let u = i as f64 / n as f64;
            heading = heading0 + 0.35 * (tau * 7.0 * u).sin();
        }
        let pitch = 0.08 * (tau * 5.0 * i as f64 / n as f64).sin();
        rotations.push(camera_rotation(heading, pitch));
    }
    let times = (0..n)
        .map(|i| config.start_time + i as f64 / config.fps)
        .collect();
    Path {
        times,
        positions,
        rotations,
        segment_frames: k,
    }
}

/// `world_from_camera` for a camera looking horizontally along `heading` (radians about the
/// world z axis, which points up), tilted by `pitch`.
pub fn camera_rotation(heading: f64, pitch: f64) -> Rotation3<f64> {
    let (sh, ch) = heading.sin_cos();
    let fwd = Vector3::new(ch, sh, 0.0);
    let right = Vector3::new(sh, -ch, 0.0);
    let down = Vector3::new(0.0, 0.0, -1.0);
    // the camera's axes are the columns
    let base = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[right, down, fwd]));
    // pitch about the camera's x axis
    base * Rotation3::from_axis_angle(&Vector3::x_axis(), pitch)
}

impl Path {
    /// Number of frames.
    pub fn len(&self) -> usize {
        self.times.len()
    }

    /// Whether the path has no frame.
    pub fn is_empty(&self) -> bool {
        self.times.is_empty()
    }

    /// The `world_from_camera` pose of frame `i`.
    pub fn world_from_camera(&self, i: usize) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::from(self.positions[i]),
            UnitQuaternion::from_rotation_matrix(&self.rotations[i]),
        )
    }

    /// Whether frame `i` lies in the start or end segment.
    pub fn in_segment(&self, i: usize) -> bool {
        i < self.segment_frames || i >= self.len() - self.segment_frames
    }

    /// The `groundtruthSync.txt` text: one row per frame, NaN outside the segments.
    pub fn ground_truth_sync(&self) -> String {
        let mut s = String::with_capacity(self.len() * 90);
        for i in 0..self.len() {
            let t = self.times[i];
            if self.in_segment(i) {
                let p = self.positions[i];
                let q = canonical(UnitQuaternion::from_rotation_matrix(&self.rotations[i]));
                let _ = writeln!(
                    s,
                    "{t:.6} {} {} {} {} {} {} {}",
                    p[0], p[1], p[2], q.i, q.j, q.k, q.w
                );
            } else {
                let _ = writeln!(s, "{t:.6} NaN NaN NaN NaN NaN NaN NaN");
            }
        }
        s
    }
}

/// Drift injected into a synthetic estimate.
#[derive(Clone, Debug, Default, serde::Serialize, serde::Deserialize)]
pub struct Drift {
    /// `(frame, factor)`: from this frame of the playback on, motion is scaled by `factor`.
    pub scale_jumps: Vec<(usize, f64)>,
    /// `(frame, axis, degrees)`: from this frame on, motion is rotated by this much more.
    pub rotation_jumps: Vec<(usize, Vec3, f64)>,
    /// Standard deviation of the per-frame log-scale random walk.
    pub scale_walk: f64,
    /// Standard deviation of the per-frame rotation random walk, degrees.
    pub rotation_walk_deg: f64,
    /// Standard deviation of white position noise added to every pose.
    pub position_noise: f64,
}

/// How a synthetic estimate is produced and written.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct EstimateConfig {
    /// The drift.
    pub drift: Drift,
    /// Keep every n-th frame only (keyframes); 1 keeps all.
    pub keyframe_every: usize,
    /// Tracking is lost after this many played frames (the rest has no pose).
    pub lost_after: Option<usize>,
    /// Play the sequence backwards (drift accumulates from its end).
    pub backwards: bool,
    /// Write backwards runs with the `2e9 - t` timestamp convention.
    pub backwards_epoch_times: bool,
    /// Scale of the estimate's arbitrary world frame.
    pub world_scale: f64,
}

impl Default for EstimateConfig {
    fn default() -> Self {
        EstimateConfig {
            drift: Drift::default(),
            keyframe_every: 1,
            lost_after: None,
            backwards: false,
            backwards_epoch_times: false,
            world_scale: 1.0,
        }
    }
}

/// One estimated pose.
#[derive(Clone, Copy, Debug)]
pub struct EstimatedPose {
    /// Timestamp as written.
    pub t: f64,
    /// Position in the estimate's world.
    pub position: Vector3<f64>,
    /// Orientation (`world_from_camera`), with `w >= 0`.
    pub orientation: UnitQuaternion<f64>,
}

/// The quaternion with `w >= 0` (of the two that give a rotation).
fn canonical(q: UnitQuaternion<f64>) -> UnitQuaternion<f64> {
    if q.w < 0.0 {
        UnitQuaternion::new_unchecked(-q.into_inner())
    } else {
        q
    }
}

/// Builds a drifted estimate of `path` in playback order.
pub fn estimate(path: &Path, config: &EstimateConfig, seed: u64) -> Vec<EstimatedPose> {
    let mut rng = Rng::derive(seed, 2);
    let n = path.len();
    let order: Vec<usize> = if config.backwards {
        (0..n).rev().collect()
    } else {
        (0..n).collect()
    };
    // arbitrary frame of the estimate
    let g_axis = [rng.normal(), rng.normal(), rng.normal()];
    let g_rot = rotation(g_axis, rng.range(0.0, std::f64::consts::PI));
    let g_t = Vector3::new(
        rng.range(-5.0, 5.0),
        rng.range(-5.0, 5.0),
        rng.range(-5.0, 5.0),
    );
    let g_s = config.world_scale;
    let mut s_acc = 1.0;
    let mut r_acc = Rotation3::identity();
    let mut out = Vec::with_capacity(n);
    let mut cur = path.positions[order[0]];
    for (step, &i) in order.iter().enumerate() {
        if let Some(l) = config.lost_after {
            if step >= l {
                break;
            }
        }
        if step > 0 {
            for &(f, factor) in &config.drift.scale_jumps {
                if f == step {
                    s_acc *= factor;
                }
            }
            for &(f, axis, deg) in &config.drift.rotation_jumps {
                if f == step {
                    r_acc = rotation(axis, deg.to_radians()) * r_acc;
                }
            }
            if config.drift.scale_walk > 0.0 {
                s_acc *= (config.drift.scale_walk * rng.normal()).exp();
            }
            if config.drift.rotation_walk_deg > 0.0 {
                let axis = [rng.normal(), rng.normal(), rng.normal()];
                let ang = (config.drift.rotation_walk_deg * rng.normal()).to_radians();
                r_acc = rotation(axis, ang) * r_acc;
            }
            let d = path.positions[i] - path.positions[order[step - 1]];
            cur += r_acc * d * s_acc;
        }
        if step % config.keyframe_every.max(1) != 0 {
            continue;
        }
        let noise = config.drift.position_noise;
        let noisy = cur
            + Vector3::new(
                noise * rng.normal(),
                noise * rng.normal(),
                noise * rng.normal(),
            );
        let position = g_rot * noisy * g_s + g_t;
        let rot = g_rot * r_acc * path.rotations[i];
        let t = if config.backwards && config.backwards_epoch_times {
            2e9 - path.times[i]
        } else {
            path.times[i]
        };
        out.push(EstimatedPose {
            t,
            position,
            orientation: canonical(UnitQuaternion::from_rotation_matrix(&rot)),
        });
    }
    out
}

/// TUM-format text of an estimate (`t x y z qx qy qz qw`, full precision).
pub fn tum_text(poses: &[EstimatedPose]) -> String {
    let mut s = String::with_capacity(poses.len() * 120);
    for p in poses {
        let q = p.orientation;
        let _ = writeln!(
            s,
            "{:.6} {} {} {} {} {} {} {}",
            p.t, p.position[0], p.position[1], p.position[2], q.i, q.j, q.k, q.w
        );
    }
    s
}
