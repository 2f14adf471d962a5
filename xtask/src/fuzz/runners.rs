//! What a case runs: each target's parser on the input, and what the command-line tools do
//! next with a parsed value (the rectification map, the evaluation, the summaries).

use std::io::Cursor;
use std::path::Path;

use super::fnv1a;

pub(super) fn text(b: &[u8]) -> std::borrow::Cow<'_, str> {
    String::from_utf8_lossy(b)
}

/// A ground truth to evaluate fuzzed trajectories against (and to seed with).
pub(super) fn ground_truth_text() -> String {
    let mut s = String::new();
    for i in 0..40 {
        let t = 100.0 + i as f64 * 0.05;
        let a = i as f64 * 0.3;
        if (10..30).contains(&i) {
            s.push_str(&format!("{t:.6} NaN NaN NaN NaN NaN NaN NaN\n"));
        } else {
            s.push_str(&format!(
                "{t:.6} {} {} {} 0 0 0 1\n",
                a.cos(),
                a.sin(),
                0.1 * a
            ));
        }
    }
    s
}

/// A run that drifts, to evaluate against fuzzed ground truths.
pub(super) fn estimate_text() -> String {
    let mut s = String::new();
    for i in 0..40 {
        let t = 100.0 + i as f64 * 0.05;
        let a = i as f64 * 0.31;
        let h = (0.5 * a).sin_cos();
        s.push_str(&format!(
            "{t:.6} {} {} {} 0 0 {} {}\n",
            1.1 * a.cos(),
            1.1 * a.sin(),
            0.12 * a,
            0.01 * h.0,
            h.1
        ));
    }
    s
}

pub(super) fn gt() -> Option<&'static eval_metrics::GroundTruth> {
    static GT: std::sync::OnceLock<Option<eval_metrics::GroundTruth>> = std::sync::OnceLock::new();
    GT.get_or_init(|| eval_metrics::GroundTruth::parse(&ground_truth_text()).ok())
        .as_ref()
}

pub(super) fn estimate() -> Option<&'static eval_metrics::Trajectory> {
    static EST: std::sync::OnceLock<Option<eval_metrics::Trajectory>> = std::sync::OnceLock::new();
    EST.get_or_init(|| eval_metrics::parse_tum(&estimate_text()).ok())
        .as_ref()
}

/// Cases of camera.txt that also compute the output pinhole and the rectification map: about
/// one in this many (DSO's crop search alone samples 200000 points: about a millisecond).
pub(super) const CAMERA_GEOMETRY_EVERY: u64 = 4;

/// The largest sides the camera geometry is computed at; larger files are scaled down (the
/// model with them), which keeps a case at milliseconds and its memory small.
pub(super) const GEOMETRY_IN_SIDE: usize = 96;

pub(super) const GEOMETRY_OUT_SIDE: usize = 64;

pub(super) fn scaled_size(s: camera_model::ImageSize, by: f64) -> camera_model::ImageSize {
    let side = |v: usize| ((v as f64 / by).round() as usize).max(2);
    camera_model::ImageSize::new(side(s.width), side(s.height))
}

/// The output pinhole, the notes and the rectification map of a parsed camera.txt, at most
/// [`GEOMETRY_IN_SIDE`] / [`GEOMETRY_OUT_SIDE`] pixels a side, and one remap.
pub(super) fn camera_geometry(f: &camera_model::CameraFile) {
    let (i, o) = (f.input_size, f.output_size);
    let by = [
        i.width as f64 / GEOMETRY_IN_SIDE as f64,
        i.height as f64 / GEOMETRY_IN_SIDE as f64,
        o.width as f64 / GEOMETRY_OUT_SIDE as f64,
        o.height as f64 / GEOMETRY_OUT_SIDE as f64,
    ]
    .into_iter()
    .fold(1.0, f64::max);
    let (input, in_size, out_size) = if by > 1.0 {
        let small = scaled_size(i, by);
        (
            f.input
                .rescaled((i.width, i.height), (small.width, small.height)),
            small,
            scaled_size(o, by),
        )
    } else {
        (f.input.clone(), i, o)
    };
    let _ = camera_model::output_notes(&input, in_size, &f.output, out_size);
    if let Ok(map) = camera_model::RectifyMap::for_mode(&input, in_size, &f.output, out_size) {
        let raw = camera_model::Image::from_fn(in_size.width, in_size.height, |x, y| {
            (x * 7 + y * 3) as u8
        });
        let _ = map.remap_u8(&raw);
        let _ = map.valid_mask();
    }
}

/// FNV-1a of an input: picks the cases that also run something expensive.
pub(super) fn input_hash(b: &[u8]) -> u64 {
    fnv1a(b)
}

pub(super) fn run_camera(b: &[u8]) -> bool {
    let Ok(f) = camera_model::CameraFile::parse(&text(b)) else {
        return false;
    };
    let _ = camera_model::output_notes(&f.input, f.input_size, &f.output, f.output_size);
    let _ = camera_model::CameraFile::parse(&f.to_text());
    // the case number is not known here: a hash of the input picks the cases
    if input_hash(b).is_multiple_of(CAMERA_GEOMETRY_EVERY) {
        camera_geometry(&f);
    }
    true
}

/// Every calibration format (Kalibr YAML, EuRoC sensor.yaml, Basalt JSON, KITTI, ETH3D,
/// camera.txt): each camera projects and unprojects, and now and then builds its maps.
pub(super) fn run_calibration(b: &[u8]) -> bool {
    let Ok(cal) = camera_model::CalibrationFile::parse(&text(b)) else {
        return false;
    };
    for (i, c) in cal.cameras.iter().enumerate() {
        for p in [[0.1, -0.2, 1.0], [1.0, 0.5, -0.3], [0.0, 0.0, 1.0]] {
            if let Some(px) = c.model.project(p) {
                let _ = c.model.unproject(px);
            }
        }
        let _ = c.camera_from_imu.as_ref().map(camera_model::invert_rigid);
        // the maps of the first camera of one input in 16 only: the crop search of a wide
        // lens is the cost (22.8 s for 50000 cases at one in 4, most of it there)
        if i == 0 && input_hash(b).is_multiple_of(4 * CAMERA_GEOMETRY_EVERY) {
            if let Ok(f) = cal.camera_file(0, Some(camera_model::ImageSize::new(64, 48))) {
                camera_geometry(&f);
            }
        } else {
            let _ = cal.camera_file(i, Some(camera_model::ImageSize::new(64, 48)));
        }
    }
    true
}

/// The layouts' listings: ASL data.csv, Basalt's exposure.csv, TUM RGB-D's rgb.txt.
pub(super) fn run_listing(b: &[u8]) -> bool {
    let t = text(b);
    let p = Path::new("data.csv");
    let a = dataset_io::parse_data_csv(&t, p).is_ok();
    let e = dataset_io::parse_exposure_csv(&t, p).is_ok();
    let r = dataset_io::parse_rgb_list(&t, p).is_ok();
    if let Some(ns) = dataset_io::seconds_to_ns(&t) {
        let _ = dataset_io::ns_to_seconds_text(ns);
    }
    a || e || r
}

/// Ground truth in the datasets' formats (EuRoC/TUM-VI csv, GNSSPoses, KITTI, TUM), made
/// per frame.
pub(super) fn run_dataset_truth(b: &[u8]) -> bool {
    let t = text(b);
    let f = eval_metrics::detect_ground_truth_format(&t);
    let Ok(traj) = eval_metrics::parse_ground_truth_trajectory(&t, f, Some("0\n1\n2\n")) else {
        return false;
    };
    let body = eval_metrics::nalgebra::Isometry3::translation(0.1, 0.0, 0.0);
    let _ = eval_metrics::GroundTruth::from_trajectory(&traj, Some(&body), None, 0.0);
    let frames: Vec<f64> = traj.poses.iter().take(50).map(|p| p.t + 0.001).collect();
    let _ = eval_metrics::GroundTruth::from_trajectory(&traj, None, Some(&frames), 0.5);
    true
}

pub(super) fn run_camera_values(b: &[u8]) -> bool {
    let t = text(b);
    let mode = t.parse::<camera_model::OutputMode>().is_ok();
    t.parse::<camera_model::ImageSize>().is_ok() || mode
}

pub(super) fn run_times(b: &[u8]) -> bool {
    let Ok(t) = dataset_io::parse_times(&text(b), Path::new("times.txt")) else {
        return false;
    };
    let _ = t.exposure_range();
    let _ = t.first_unknown_exposure();
    let _ = dataset_io::times_text(&t.rows);
    true
}

pub(super) fn run_pcalib(b: &[u8]) -> bool {
    let Ok((u, _)) = photometric::InverseResponse::parse_with_notes(&text(b)) else {
        return false;
    };
    let _ = u.to_text();
    let _ = u.lut();
    let _ = u.table_for_bits(12);
    true
}

pub(super) fn run_ground_truth(b: &[u8]) -> bool {
    let Ok(g) = eval_metrics::GroundTruth::parse(&text(b)) else {
        return false;
    };
    let _ = g.segment_sizes();
    let _ = g.associate(100.5, 0.001);
    if let Some(est) = estimate() {
        let _ = eval_metrics::evaluate(est, &g);
    }
    true
}

pub(super) fn evaluate(t: &eval_metrics::Trajectory) -> bool {
    if let Some(g) = gt() {
        if t.poses.len() <= 4096 {
            let _ = eval_metrics::evaluate(t, g);
        }
    }
    true
}

pub(super) fn run_tum(b: &[u8]) -> bool {
    let t = text(b);
    let _ = eval_metrics::detect_format(&t);
    eval_metrics::parse_tum(&t).is_ok_and(|tr| evaluate(&tr))
}

pub(super) fn run_euroc(b: &[u8]) -> bool {
    eval_metrics::parse_euroc(&text(b)).is_ok_and(|tr| evaluate(&tr))
}

/// KITTI poses and their times file, separated by a line `---`.
pub(super) fn run_kitti(b: &[u8]) -> bool {
    let t = text(b);
    let (poses, times) = t.split_once("\n---\n").unwrap_or((&t, ""));
    eval_metrics::parse_kitti(poses, times).is_ok_and(|tr| evaluate(&tr))
}

/// A KITTI pose file (no times), then the devkit's segment errors and evo's APE and RPE of it
/// against itself (paired by line).
pub(super) fn run_kitti_poses(b: &[u8]) -> bool {
    let Ok(t) = eval_metrics::parse_kitti_poses(&text(b)) else {
        return false;
    };
    if t.len() <= 1024 {
        let _ = eval_metrics::kitti_errors(&[(t.clone(), t.clone())]);
        let mut o = eval_metrics::ApeOptions::default();
        o.align.mode = eval_metrics::AlignMode::Sim3;
        let _ = eval_metrics::ape(&t, &t, &o);
        let _ = eval_metrics::rpe(&t, &t, &eval_metrics::RpeOptions::default());
    }
    true
}

/// A TUM trajectory as the estimate of every metric (evo's APE and RPE with several options,
/// the TUM scripts' ATE and RPE, the KITTI segments) against a reference made from it: moved
/// by a similarity and 1 ms later, so that the poses associate and every step runs.
pub(super) fn run_metrics(b: &[u8]) -> bool {
    let Ok(t) = eval_metrics::parse_tum(&text(b)) else {
        return false;
    };
    if t.poses.len() > 512 {
        return true;
    }
    let est = eval_metrics::PoseTrack::from_trajectory(&t);
    let mut reference = est.clone();
    let r = eval_metrics::nalgebra::Rotation3::from_euler_angles(0.1, -0.2, 0.3);
    for p in &mut reference.positions {
        *p = r * *p * 1.3 + eval_metrics::nalgebra::Vector3::new(1.0, 2.0, 3.0);
    }
    for m in &mut reference.rotations {
        *m = r.matrix() * *m;
    }
    if let Some(times) = reference.times.as_mut() {
        times.iter_mut().for_each(|x| *x += 0.001);
    }
    let reference = &reference;
    let h = input_hash(b);
    let mut ape = eval_metrics::ApeOptions::default();
    ape.align.mode = [
        eval_metrics::AlignMode::None,
        eval_metrics::AlignMode::Se3,
        eval_metrics::AlignMode::Sim3,
        eval_metrics::AlignMode::Scale,
        eval_metrics::AlignMode::PosYaw,
    ][(h % 5) as usize];
    ape.align.origin = h.is_multiple_of(7);
    ape.relation = [
        eval_metrics::PoseRelation::TransPart,
        eval_metrics::PoseRelation::AngleDeg,
        eval_metrics::PoseRelation::Full,
    ][(h % 3) as usize];
    ape.sync.max_diff = 0.03;
    if h.is_multiple_of(2) {
        ape.sync.method = eval_metrics::SyncMethod::Interpolation;
    }
    let _ = eval_metrics::ape(reference, &est, &ape);
    let mut rpe = eval_metrics::RpeOptions {
        align: ape.align,
        sync: ape.sync,
        all_pairs: h.is_multiple_of(3),
        pairs_from_reference: h.is_multiple_of(5),
        ..eval_metrics::RpeOptions::default()
    };
    (rpe.delta_unit, rpe.delta) = [
        (eval_metrics::DeltaUnit::Frames, 2.0),
        (eval_metrics::DeltaUnit::Meters, 0.3),
        (eval_metrics::DeltaUnit::Degrees, 5.0),
        (eval_metrics::DeltaUnit::Radians, 0.1),
    ][(h / 7 % 4) as usize];
    let _ = eval_metrics::rpe(reference, &est, &rpe);
    let _ = eval_metrics::tum_ate(reference, &est, &eval_metrics::TumAteOptions::default());
    let tum = eval_metrics::TumRpeOptions {
        fixed_delta: !h.is_multiple_of(4),
        max_pairs: 500,
        ..eval_metrics::TumRpeOptions::default()
    };
    let _ = eval_metrics::tum_rpe(reference, &est, &tum);
    let _ = eval_metrics::ExtraMetric::Kitti(ape.align).compute(reference, &est);
    true
}

/// An experiment manifest, with the [ape], [rpe] and [kitti] tables of the other metrics.
pub(super) fn run_manifest(b: &[u8]) -> bool {
    monovo_pipelines::Experiment::parse(&text(b), Path::new("exp.toml"), Path::new("base")).is_ok()
}

pub(super) fn run_plane_poses(b: &[u8]) -> bool {
    photometric::marker::parse_plane_poses(&text(b)).is_ok()
}

pub(super) fn run_results_csv(b: &[u8]) -> bool {
    let Ok(r) = eval_metrics::parse_csv(&text(b)) else {
        return false;
    };
    let s = eval_metrics::summarize(&r, true);
    let _ = eval_metrics::summary_table(&s, eval_metrics::TableStyle::Text);
    let _ = eval_metrics::cumulative(
        &r,
        eval_metrics::Metric::ES,
        eval_metrics::DirectionFilter::Split,
    );
    true
}

/// Accepted: the archive opened and at least one entry decoded as an image.
pub(super) fn run_zip(b: &[u8]) -> bool {
    let Ok(mut z) = dataset_io::ImagesZip::new(Cursor::new(b)) else {
        return false;
    };
    let mut decoded = false;
    for k in 0..z.len().min(4) {
        if let Ok(bytes) = z.read(k) {
            decoded |= dataset_io::decode_gray(&bytes).is_ok();
        }
    }
    decoded
}

pub(super) fn run_png(b: &[u8]) -> bool {
    let grey = dataset_io::decode_gray(b).is_ok();
    let _ = dataset_io::decode_gray16(b);
    if let Ok((img, _)) = dataset_io::decode_gray_map(b) {
        let _ = photometric::Vignette::from_u16(&img);
    }
    grey
}

pub(super) fn run_jpeg(b: &[u8]) -> bool {
    let grey = dataset_io::decode_gray8(b).is_ok();
    let _ = dataset_io::decode_gray(b);
    grey
}

/// `monovo calib --config FILE` as the command reads it (`CalibConfig` in
/// crates/cli/src/cmd/calib.rs, a binary crate): a `[response]` and a `[vignette]` table of
/// the library's option types, unknown keys refused.
#[derive(Default, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub(super) struct CalibConfig {
    pub(super) response: photometric::ResponseOptions,
    pub(super) vignette: photometric::VignetteOptions,
}

/// A tiny exposure sweep (32x24, 8 exposures) for the response options of a fuzzed config.
pub(super) fn tiny_sweep() -> &'static (Vec<camera_model::Image<u8>>, Vec<f64>) {
    static SWEEP: std::sync::OnceLock<(Vec<camera_model::Image<u8>>, Vec<f64>)> =
        std::sync::OnceLock::new();
    SWEEP.get_or_init(|| {
        let s = synthetic::scene::Sweep::new(
            4,
            synthetic::scene::SweepConfig {
                width: 32,
                height: 24,
                frames: 8,
                factor: 2.0,
                t0: 0.5,
                ..synthetic::scene::SweepConfig::default()
            },
        );
        let frames = (0..8)
            .filter_map(|i| camera_model::Image::new(32, 24, s.render(i)).ok())
            .collect();
        (frames, s.exposures_ms.clone())
    })
}

/// Cases of the calibration config whose response options, when valid, also calibrate the
/// tiny sweep: about one in this many (picked by a hash of the input).
pub(super) const CONFIG_CALIBRATION_EVERY: u64 = 256;

pub(super) fn run_calib_config(b: &[u8]) -> bool {
    let Ok(c) = toml::from_str::<CalibConfig>(&text(b)) else {
        return false;
    };
    let _ = c.vignette.check();
    // a valid iteration limit may still be 100000 passes: the tiny run keeps to 200
    if c.response.check().is_ok()
        && c.response.max_iterations <= 200
        && input_hash(b).is_multiple_of(CONFIG_CALIBRATION_EVERY)
    {
        let (frames, exposures) = tiny_sweep();
        let mut frames = frames.clone();
        let _ = photometric::calibrate_response(&mut frames, exposures, &c.response, &|_, _| {});
    }
    true
}
