//! Synthetic runs with known drift.
use eval_metrics::{parse_tum, GroundTruth, Trajectory};
use synthetic::trajectory::{benchmark_path, estimate, tum_text, EstimateConfig, Path, PathConfig};

pub fn path(seed: u64, frames: usize) -> Path {
    benchmark_path(
        seed,
        &PathConfig {
            frames,
            ..PathConfig::default()
        },
    )
}

pub fn gt_of(path: &Path) -> GroundTruth {
    GroundTruth::parse(&path.ground_truth_sync()).unwrap()
}

pub fn run(path: &Path, cfg: &EstimateConfig, seed: u64) -> Trajectory {
    parse_tum(&tum_text(&estimate(path, cfg, seed))).unwrap()
}

/// Relative difference.
pub fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs().max(1e-300)
}
