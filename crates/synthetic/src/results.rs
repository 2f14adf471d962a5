//! Synthetic benchmark results: a dataset of loop-closure ground truths and the runs of
//! several "methods" with known drift behaviour, in the layout `monovo eval-batch` reads
//! (`dataset/sequence_XX/groundtruthSync.txt`, `results/METHOD/sequence_XX/{fwd,bwd}_N.txt`).

use crate::trajectory::{
    benchmark_path, estimate, tum_text, Drift, EstimateConfig, Path, PathConfig,
};
use crate::Rng;

/// How a synthetic method drifts and fails.
#[derive(Clone, Debug)]
pub struct MethodProfile {
    /// Method name (folder name).
    pub name: String,
    /// Per-frame log-scale random walk.
    pub scale_walk: f64,
    /// Per-frame rotation random walk in degrees.
    pub rotation_walk_deg: f64,
    /// White position noise.
    pub position_noise: f64,
    /// Probability that a run has a sudden scale jump (x0.5..x0.8) somewhere.
    pub scale_jump_probability: f64,
    /// Probability that a run loses tracking before the end segment.
    pub lost_probability: f64,
    /// Keep every n-th frame (keyframes).
    pub keyframe_every: usize,
    /// Backwards runs use the `2e9 - t` timestamp convention.
    pub epoch_times_backwards: bool,
}

/// Two methods with clearly different accuracy and robustness.
pub fn default_methods() -> Vec<MethodProfile> {
    vec![
        MethodProfile {
            name: "direct".into(),
            scale_walk: 4e-4,
            rotation_walk_deg: 0.01,
            position_noise: 0.002,
            scale_jump_probability: 0.05,
            lost_probability: 0.03,
            keyframe_every: 1,
            epoch_times_backwards: false,
        },
        MethodProfile {
            name: "feature".into(),
            scale_walk: 1.2e-3,
            rotation_walk_deg: 0.03,
            position_noise: 0.004,
            scale_jump_probability: 0.2,
            lost_probability: 0.12,
            keyframe_every: 3,
            epoch_times_backwards: true,
        },
    ]
}

/// Size of a synthetic results set.
#[derive(Clone, Debug)]
pub struct ResultsConfig {
    /// Number of sequences.
    pub sequences: usize,
    /// Runs per sequence and direction.
    pub runs: usize,
    /// Frames per sequence.
    pub frames: usize,
    /// The methods.
    pub methods: Vec<MethodProfile>,
}

impl Default for ResultsConfig {
    fn default() -> Self {
        ResultsConfig {
            sequences: 50,
            runs: 5,
            frames: 2000,
            methods: default_methods(),
        }
    }
}

/// Name of sequence `i` (1-based as in the dataset): `sequence_01`, ...
pub fn sequence_name(i: usize) -> String {
    format!("sequence_{i:02}")
}

/// The ground-truth path of sequence `i` (frame rates vary between 20 and 50 fps as in the
/// dataset).
pub fn sequence_path(seed: u64, i: usize, frames: usize) -> Path {
    let mut rng = Rng::derive(seed, 1000 + i as u64);
    let fps = [20.0, 25.0, 30.0, 50.0][rng.below(4)];
    benchmark_path(
        seed.wrapping_mul(31).wrapping_add(i as u64),
        &PathConfig {
            frames,
            fps,
            start_time: 1_400_000_000.0 + 100_000.0 * i as f64,
            ..PathConfig::default()
        },
    )
}

/// One run's trajectory text (TUM format).
pub fn run_text(
    seed: u64,
    path: &Path,
    method: &MethodProfile,
    method_index: usize,
    sequence: usize,
    backwards: bool,
    run: usize,
) -> String {
    let stream = ((method_index as u64) << 40)
        ^ ((sequence as u64) << 20)
        ^ ((backwards as u64) << 16)
        ^ run as u64;
    let mut rng = Rng::derive(seed, stream);
    let n = path.len();
    let mut drift = Drift {
        scale_walk: method.scale_walk,
        rotation_walk_deg: method.rotation_walk_deg,
        position_noise: method.position_noise,
        ..Drift::default()
    };
    if rng.uniform() < method.scale_jump_probability {
        let at = n / 4 + rng.below(n / 2);
        drift.scale_jumps.push((at, rng.range(0.5, 0.8)));
    }
    let lost_after = (rng.uniform() < method.lost_probability).then(|| n / 5 + rng.below(n / 2));
    let cfg = EstimateConfig {
        drift,
        keyframe_every: method.keyframe_every,
        lost_after,
        backwards,
        backwards_epoch_times: backwards && method.epoch_times_backwards,
        world_scale: rng.range(0.2, 5.0),
    };
    tum_text(&estimate(path, &cfg, rng.next_u64()))
}
