//! The folder layouts of the field's other datasets, told from the folder: TUM-VI (`dso/camN/`
//! and `mav0/`), EuRoC/ASL (`mav0/camN/data/`, `data.csv`, `sensor.yaml`, Basalt's
//! `exposure.csv`), 4Seasons (`undistorted_images/camN/`, `times.txt` matched by id), KITTI
//! odometry (`image_N/`, `times.txt`, `calib.txt`) and TUM RGB-D / ETH3D (`rgb.txt`,
//! `calibration.txt`). Each is listed as images, rows of times (nanoseconds kept as integers)
//! and the calibration file that belongs to it; [`crate::Sequence`] does the rest.

use std::path::{Path, PathBuf};

use crate::times::{seconds_to_ns, TimeRow, Times};
use crate::zipimages::is_image_name;
use crate::{read_text, DatasetError};

/// The layout of a sequence folder.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Layout {
    /// The TUM monoVO benchmark's and DSO's own folder: images.zip or images/, times.txt,
    /// camera.txt (also a TUM-VI `dso/camN/` folder named directly).
    Monovo,
    /// TUM-VI's `dso/camN/` export under the dataset folder.
    TumViDso,
    /// EuRoC / ASL `mav0/camN/` (also TUM-VI's `mav0/` and Basalt's recordings).
    Asl,
    /// 4Seasons: `undistorted_images/camN/`, `times.txt`, `calibration/`.
    FourSeasons,
    /// KITTI odometry: `image_N/`, `times.txt`, `calib.txt`.
    Kitti,
    /// TUM RGB-D and ETH3D SLAM: `rgb.txt`, `calibration.txt`.
    TumRgbd,
}

impl Layout {
    /// The layout's name as `monovo info` prints it.
    pub fn name(self) -> &'static str {
        match self {
            Layout::Monovo => "monovo",
            Layout::TumViDso => "tum-vi-dso",
            Layout::Asl => "euroc-asl",
            Layout::FourSeasons => "4seasons",
            Layout::Kitti => "kitti",
            Layout::TumRgbd => "tum-rgbd",
        }
    }
}

/// A listed (non-monovo) sequence: what [`crate::Sequence`] needs to open it.
pub(crate) struct Listed {
    pub layout: Layout,
    pub files: Vec<PathBuf>,
    pub names: Vec<String>,
    pub times: Times,
    pub times_path: PathBuf,
    pub calibration: Option<PathBuf>,
    pub pcalib: Option<PathBuf>,
    pub vignette: Option<PathBuf>,
    pub ground_truth: Option<PathBuf>,
    pub warnings: Vec<String>,
}

/// What a folder is.
pub(crate) enum Resolved {
    /// A monovo/DSO folder at this path (the folder itself, or TUM-VI's `dso/camN`), with the
    /// dataset's ground truth and camchain when found beside it.
    Monovo {
        dir: PathBuf,
        layout: Layout,
        ground_truth: Option<PathBuf>,
        calibration: Option<PathBuf>,
    },
    /// Another dataset's layout.
    Listed(Box<Listed>),
}

fn file(p: PathBuf) -> Option<PathBuf> {
    p.is_file().then_some(p)
}

fn first_file(candidates: impl IntoIterator<Item = PathBuf>) -> Option<PathBuf> {
    candidates.into_iter().find(|p| p.is_file())
}

/// Tells the layout of `dir` and lists it for camera `cam`.
pub(crate) fn resolve(dir: &Path, cam: usize) -> Result<Resolved, DatasetError> {
    if dir.join("images.zip").is_file() || dir.join("images").is_dir() {
        return Ok(Resolved::Monovo {
            dir: dir.to_path_buf(),
            layout: Layout::Monovo,
            ground_truth: None,
            calibration: None,
        });
    }
    if dir.join("dso").join("cam0").is_dir() {
        let sub = dir.join("dso").join(format!("cam{cam}"));
        if !sub.is_dir() {
            return Err(DatasetError::invalid(
                &sub,
                format!("--cam {cam}: this TUM-VI folder has no dso/cam{cam}"),
            ));
        }
        return Ok(Resolved::Monovo {
            dir: sub,
            layout: Layout::TumViDso,
            ground_truth: first_file([
                dir.join("mav0/mocap0/data.csv"),
                dir.join("dso/gt_imu.csv"),
            ]),
            calibration: file(dir.join("dso/camchain.yaml")),
        });
    }
    let mav0 = if dir.join("mav0").is_dir() {
        Some(dir.join("mav0"))
    } else if dir.join("cam0").join("data.csv").is_file() {
        Some(dir.to_path_buf())
    } else {
        None
    };
    if let Some(mav0) = mav0 {
        return asl(dir, &mav0, cam).map(|l| Resolved::Listed(Box::new(l)));
    }
    if dir.join("undistorted_images").is_dir() {
        return four_seasons(dir, cam).map(|l| Resolved::Listed(Box::new(l)));
    }
    if dir.join("image_0").is_dir() || dir.join("image_2").is_dir() {
        return kitti(dir, cam).map(|l| Resolved::Listed(Box::new(l)));
    }
    if dir.join("rgb.txt").is_file() {
        return tum_rgbd(dir).map(|l| Resolved::Listed(Box::new(l)));
    }
    Err(DatasetError::invalid(
        dir,
        "no images.zip and no images/ folder in this sequence, and no other dataset's layout: dso/camN/ or mav0/ (TUM-VI, EuRoC), undistorted_images/ (4Seasons), image_0/ with times.txt (KITTI) or rgb.txt (TUM RGB-D, ETH3D)",
    ))
}

fn parse_err(path: &Path, line: usize, expected: &str, found: &str) -> DatasetError {
    DatasetError::Parse {
        path: path.to_path_buf(),
        line,
        expected: expected.into(),
        found: found.trim().chars().take(100).collect(),
    }
}

/// A file name's stem.
fn stem(name: &str) -> &str {
    name.rsplit_once('.').map_or(name, |(s, _)| s)
}

/// Builds the rows of listed images with their nanoseconds, checking they increase.
fn rows_from_ns(
    stamps: &[(i64, Option<f64>)],
    ids: &[String],
    path: &Path,
    lines: &[usize],
) -> Result<Times, DatasetError> {
    let mut rows = Vec::with_capacity(stamps.len());
    for (k, (ns, exposure_ms)) in stamps.iter().enumerate() {
        if k > 0 && *ns <= stamps[k - 1].0 {
            return Err(parse_err(
                path,
                lines.get(k).copied().unwrap_or(k + 1),
                &format!(
                    "a timestamp after the previous one ({} ns); timestamps must strictly increase",
                    stamps[k - 1].0
                ),
                &ns.to_string(),
            ));
        }
        rows.push(TimeRow {
            id: ids[k].clone(),
            // divided as a ground-truth csv's stamps are (as evo does): equal ns, equal seconds
            timestamp: *ns as f64 / 1e9,
            exposure_ms: *exposure_ms,
            timestamp_ns: Some(*ns),
        });
    }
    Ok(Times {
        rows,
        lines: lines.to_vec(),
        warnings: Vec::new(),
    })
}

/// `data.csv` of an ASL camera: `#timestamp [ns],filename` then `ns,name.png`; returns the
/// nanoseconds, image name and 1-based line of each row (`path` names the file in errors).
pub fn parse_data_csv(text: &str, path: &Path) -> Result<Vec<(i64, String, usize)>, DatasetError> {
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let t = line.trim().trim_start_matches('\u{feff}');
        if t.is_empty() || t.starts_with('#') {
            continue;
        }
        let expected = "`timestamp_ns,filename` (integer nanoseconds, an image name)";
        let (ns, name) = t
            .split_once(',')
            .ok_or_else(|| parse_err(path, i + 1, expected, t))?;
        let ns = ns
            .trim()
            .parse::<i64>()
            .map_err(|_| parse_err(path, i + 1, expected, t))?;
        let name = name.trim();
        if name.is_empty() || name.contains(['/', '\\']) || name.starts_with('.') {
            return Err(parse_err(path, i + 1, expected, t));
        }
        out.push((ns, name.to_string(), i + 1));
    }
    Ok(out)
}

/// Basalt's `exposure.csv`: `#timestamp [ns],exposure [ns]` per frame; returns the exposure
/// in ms of each nanosecond stamp (`path` names the file in errors).
pub fn parse_exposure_csv(
    text: &str,
    path: &Path,
) -> Result<std::collections::HashMap<i64, f64>, DatasetError> {
    let mut out = std::collections::HashMap::new();
    for (i, line) in text.lines().enumerate() {
        let t = line.trim();
        if t.is_empty() || t.starts_with('#') {
            continue;
        }
        let expected = "`timestamp_ns,exposure_ns` (two integers)";
        let mut f = t.split(',').map(str::trim);
        let (Some(a), Some(b)) = (f.next(), f.next()) else {
            return Err(parse_err(path, i + 1, expected, t));
        };
        let ns = a
            .parse::<i64>()
            .map_err(|_| parse_err(path, i + 1, expected, t))?;
        let e = b
            .parse::<f64>()
            .ok()
            .filter(|e| e.is_finite() && *e >= 0.0)
            .ok_or_else(|| parse_err(path, i + 1, expected, t))?;
        out.insert(ns, e * 1e-6);
    }
    Ok(out)
}

/// EuRoC / ASL: `mav0/camN/data.csv` and `data/`, `sensor.yaml` (or a camchain or Basalt
/// calibration beside `mav0`), `exposure.csv` where present.
fn asl(root: &Path, mav0: &Path, cam: usize) -> Result<Listed, DatasetError> {
    let camdir = mav0.join(format!("cam{cam}"));
    let csv = camdir.join("data.csv");
    if !csv.is_file() {
        return Err(DatasetError::invalid(
            &camdir,
            format!("--cam {cam}: no data.csv (EuRoC/ASL layout: mav0/camN/data.csv and data/)"),
        ));
    }
    let listed = parse_data_csv(&read_text(&csv)?, &csv)?;
    let exposures = match first_file([camdir.join("exposure.csv"), mav0.join("exposure.csv")]) {
        Some(p) => Some((parse_exposure_csv(&read_text(&p)?, &p)?, p)),
        None => None,
    };
    let mut warnings = Vec::new();
    let mut files = Vec::new();
    let mut names = Vec::new();
    let mut stamps = Vec::new();
    let mut lines = Vec::new();
    let mut missing_exposure = 0usize;
    for (ns, name, line) in &listed {
        let exposure = exposures.as_ref().and_then(|(m, _)| m.get(ns).copied());
        if exposures.is_some() && exposure.is_none() {
            missing_exposure += 1;
        }
        files.push(camdir.join("data").join(name));
        names.push(name.clone());
        stamps.push((*ns, exposure));
        lines.push(*line);
    }
    if let (Some((_, p)), true) = (&exposures, missing_exposure > 0) {
        warnings.push(format!(
            "{}: no exposure for {missing_exposure} of {} frames",
            p.display(),
            listed.len()
        ));
    }
    let ids: Vec<String> = listed.iter().map(|(ns, _, _)| ns.to_string()).collect();
    let times = rows_from_ns(&stamps, &ids, &csv, &lines)?;
    // a sensor.yaml without intrinsics (only T_BS, as some recordings have) is no camera
    let sensor = camdir.join("sensor.yaml");
    let sensor_has_camera = std::fs::read_to_string(&sensor)
        .is_ok_and(|t| t.lines().any(|l| l.starts_with("intrinsics:")));
    let mut candidates = Vec::new();
    if sensor_has_camera {
        candidates.push(sensor);
    }
    // beside mav0: the folder named, or mav0's parent when mav0 itself was named
    let roots = [root.to_path_buf(), mav0.join("..")];
    for r in &roots {
        candidates.extend([
            r.join("dso/camchain.yaml"),
            r.join("camchain.yaml"),
            r.join("calibration.json"),
            r.join("calib.json"),
        ]);
    }
    let calibration = first_file(candidates);
    let dso = match roots.iter().find(|r| r.join("dso").is_dir()) {
        Some(r) => r.join("dso").join(format!("cam{cam}")),
        None => root.join("dso").join(format!("cam{cam}")),
    };
    Ok(Listed {
        layout: Layout::Asl,
        files,
        names,
        times,
        times_path: csv,
        calibration,
        pcalib: file(dso.join("pcalib.txt")),
        vignette: file(dso.join("vignette.png")),
        ground_truth: first_file([
            mav0.join("state_groundtruth_estimate0/data.csv"),
            mav0.join("mocap0/data.csv"),
        ]),
        warnings,
    })
}

/// The image files of a folder, sorted by name.
fn images_in(folder: &Path) -> Result<Vec<(String, PathBuf)>, DatasetError> {
    let rd = std::fs::read_dir(folder).map_err(|e| DatasetError::io(folder, e))?;
    let mut out = Vec::new();
    for e in rd {
        let e = e.map_err(|e| DatasetError::io(folder, e))?;
        let name = e.file_name().to_string_lossy().into_owned();
        if is_image_name(&name) && e.path().is_file() {
            out.push((name, e.path()));
        }
    }
    out.sort();
    if out.is_empty() {
        return Err(DatasetError::invalid(
            folder,
            "contains no .jpg or .png images",
        ));
    }
    Ok(out)
}

/// 4Seasons: `undistorted_images/camN/<ns>.png`; `times.txt` (`ns t_s exposure_ms`, may list
/// frames that have no image: matched by id); `calibration/undistorted_calib_N.txt`.
fn four_seasons(dir: &Path, cam: usize) -> Result<Listed, DatasetError> {
    let folder = dir.join("undistorted_images").join(format!("cam{cam}"));
    if !folder.is_dir() {
        return Err(DatasetError::invalid(
            &folder,
            format!("--cam {cam}: no such folder in this 4Seasons sequence"),
        ));
    }
    let images = images_in(&folder)?;
    let times_path = dir.join("times.txt");
    let all = crate::parse_times(&read_text(&times_path)?, &times_path)?;
    let by_id: std::collections::HashMap<&str, usize> = all
        .rows
        .iter()
        .enumerate()
        .map(|(k, r)| (r.id.as_str(), k))
        .collect();
    let mut rows = Vec::new();
    let mut lines = Vec::new();
    let mut files = Vec::new();
    let mut names = Vec::new();
    for (name, path) in images {
        let Some(&k) = by_id.get(stem(&name)) else {
            return Err(DatasetError::invalid(
                &times_path,
                format!(
                    "no row with id `{}` for the image {}",
                    stem(&name),
                    path.display()
                ),
            ));
        };
        rows.push(all.rows[k].clone());
        lines.push(all.lines[k]);
        files.push(path);
        names.push(name);
    }
    let mut warnings = all.warnings.clone();
    if all.rows.len() > rows.len() {
        warnings.push(format!(
            "{}: {} rows, {} of them with an image in {} (matched by id)",
            times_path.display(),
            all.rows.len(),
            rows.len(),
            folder.display()
        ));
    }
    let calib_dirs = [dir.join("calibration"), dir.join("../calibration")];
    let calibration = first_file(calib_dirs.iter().flat_map(|c| {
        [
            c.join(format!("undistorted_calib_{cam}.txt")),
            c.join("camchain.yaml"),
        ]
    }));
    Ok(Listed {
        layout: Layout::FourSeasons,
        files,
        names,
        times: Times {
            rows,
            lines,
            warnings: Vec::new(),
        },
        times_path,
        calibration,
        pcalib: None,
        vignette: None,
        ground_truth: file(dir.join("GNSSPoses.txt")),
        warnings,
    })
}

/// KITTI odometry: `image_N/%06d.png`, `times.txt` (seconds, one column), `calib.txt`,
/// ground truth `../../poses/XX.txt`.
fn kitti(dir: &Path, cam: usize) -> Result<Listed, DatasetError> {
    let folder = dir.join(format!("image_{cam}"));
    if !folder.is_dir() {
        return Err(DatasetError::invalid(
            &folder,
            format!("--cam {cam}: no such folder in this KITTI sequence"),
        ));
    }
    let images = images_in(&folder)?;
    let times_path = dir.join("times.txt");
    let text = read_text(&times_path)?;
    let mut stamps = Vec::new();
    let mut lines = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let t = line.trim();
        if t.is_empty() || t.starts_with('#') {
            continue;
        }
        let ns = seconds_to_ns(t)
            .ok_or_else(|| parse_err(&times_path, i + 1, "a timestamp in seconds", t))?;
        stamps.push((ns, None));
        lines.push(i + 1);
    }
    if stamps.len() != images.len() {
        return Err(DatasetError::invalid(
            &times_path,
            format!(
                "has {} timestamps but {} has {} images; there must be one per image",
                stamps.len(),
                folder.display(),
                images.len()
            ),
        ));
    }
    let names: Vec<String> = images.iter().map(|(n, _)| n.clone()).collect();
    let ids: Vec<String> = names.iter().map(|n| stem(n).to_string()).collect();
    let times = rows_from_ns(&stamps, &ids, &times_path, &lines)?;
    let seq_name = dir
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    Ok(Listed {
        layout: Layout::Kitti,
        files: images.into_iter().map(|(_, p)| p).collect(),
        names,
        times,
        times_path,
        calibration: file(dir.join("calib.txt")),
        pcalib: None,
        vignette: None,
        ground_truth: first_file([
            dir.join(format!("../../poses/{seq_name}.txt")),
            dir.join("poses.txt"),
        ]),
        warnings: Vec::new(),
    })
}

/// TUM RGB-D / ETH3D: `rgb.txt` (`timestamp filename` lines, `#` comments), ETH3D's
/// `calibration.txt` (`fx fy cx cy`), `groundtruth.txt`.
fn tum_rgbd(dir: &Path) -> Result<Listed, DatasetError> {
    let list = dir.join("rgb.txt");
    let rows = parse_rgb_list(&read_text(&list)?, &list)?;
    let stamps: Vec<(i64, Option<f64>)> = rows.iter().map(|r| (r.0, None)).collect();
    let lines: Vec<usize> = rows.iter().map(|r| r.2).collect();
    let files: Vec<PathBuf> = rows.iter().map(|r| dir.join(&r.1)).collect();
    let names: Vec<String> = rows.iter().map(|r| r.1.clone()).collect();
    if files.is_empty() {
        return Err(DatasetError::invalid(&list, "lists no image"));
    }
    let ids: Vec<String> = stamps.iter().map(|(ns, _)| ns.to_string()).collect();
    let times = rows_from_ns(&stamps, &ids, &list, &lines)?;
    Ok(Listed {
        layout: Layout::TumRgbd,
        files,
        names,
        times,
        times_path: list,
        calibration: file(dir.join("calibration.txt")),
        pcalib: None,
        vignette: None,
        ground_truth: file(dir.join("groundtruth.txt")),
        warnings: Vec::new(),
    })
}

/// TUM RGB-D's `rgb.txt`: `timestamp_s relative/path.png` lines, `#` comments; returns the
/// nanoseconds, path and 1-based line of each (`path` names the file in errors).
pub fn parse_rgb_list(text: &str, path: &Path) -> Result<Vec<(i64, String, usize)>, DatasetError> {
    let list = path;
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let t = line.trim();
        if t.is_empty() || t.starts_with('#') {
            continue;
        }
        let expected = "`timestamp_s filename` (seconds, a relative image path)";
        let mut f = t.split_whitespace();
        let (Some(ts), Some(name)) = (f.next(), f.next()) else {
            return Err(parse_err(list, i + 1, expected, t));
        };
        let ns = seconds_to_ns(ts).ok_or_else(|| parse_err(list, i + 1, expected, t))?;
        if name.starts_with('/') || name.split('/').any(|c| c == "..") {
            return Err(parse_err(list, i + 1, expected, t));
        }
        out.push((ns, name.to_string(), i + 1));
    }
    Ok(out)
}
