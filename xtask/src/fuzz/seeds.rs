//! The targets and their seeds: the real files of the fixtures (their first few KiB) and small
//! generated files of every format.

use std::io::{Cursor, Write};
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};

use super::runners::{
    estimate_text, ground_truth_text, run_calib_config, run_calibration, run_camera,
    run_camera_values, run_dataset_truth, run_euroc, run_ground_truth, run_jpeg, run_kitti,
    run_kitti_poses, run_listing, run_manifest, run_metrics, run_pcalib, run_plane_poses, run_png,
    run_results_csv, run_times, run_tum, run_zip, text,
};
use super::Target;

/// The first `limit` bytes of a seed, cut at a line end for text.
pub(super) fn head(bytes: Vec<u8>, limit: usize, text: bool) -> Vec<u8> {
    if bytes.len() <= limit {
        return bytes;
    }
    let mut end = limit;
    if text {
        if let Some(p) = bytes[..limit].iter().rposition(|&c| c == b'\n') {
            end = p + 1;
        }
    }
    bytes[..end].to_vec()
}

/// The fixture files of one folder under tests/fixtures/dso-family/, their first `limit`
/// bytes.
pub(super) fn fixtures(
    root: &Path,
    folder: &str,
    text: bool,
    limit: usize,
) -> Result<Vec<Vec<u8>>> {
    let dir = root.join("tests/fixtures/dso-family").join(folder);
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .with_context(|| dir.display().to_string())?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file())
        .collect();
    files.sort();
    files
        .into_iter()
        .map(|p| {
            let b = std::fs::read(&p).with_context(|| p.display().to_string())?;
            Ok(head(b, limit, text))
        })
        .collect()
}

pub(super) fn png_seeds() -> Result<Vec<Vec<u8>>> {
    let (w, h) = (12usize, 9usize);
    let grey: Vec<u8> = (0..w * h).map(|i| (i * 37 % 256) as u8).collect();
    let grey16: Vec<u16> = (0..w * h).map(|i| (i * 4099 % 65536) as u16).collect();
    let rgb: Vec<u8> = (0..w * h * 3).map(|i| (i * 11 % 256) as u8).collect();
    let mut seeds = vec![
        dataset_io::encode_png_u8(w, h, 1, &grey, dataset_io::PngSpeed::Fast)?,
        dataset_io::encode_png_u8(w, h, 3, &rgb, dataset_io::PngSpeed::Fast)?,
        dataset_io::encode_png_u16(w, h, &grey16, dataset_io::PngSpeed::Fast)?,
    ];
    // grey+alpha and RGBA through the image crate
    let la = image::GrayAlphaImage::from_raw(
        w as u32,
        h as u32,
        grey.iter().flat_map(|&v| [v, 255]).collect(),
    )
    .context("grey+alpha")?;
    let mut b = Vec::new();
    image::DynamicImage::ImageLumaA8(la)
        .write_to(&mut Cursor::new(&mut b), image::ImageFormat::Png)?;
    seeds.push(b);
    let rgba = image::RgbaImage::from_raw(
        w as u32,
        h as u32,
        grey.iter().flat_map(|&v| [v, v, v, 9]).collect(),
    )
    .context("rgba")?;
    let mut b = Vec::new();
    image::DynamicImage::ImageRgba8(rgba)
        .write_to(&mut Cursor::new(&mut b), image::ImageFormat::Png)?;
    seeds.push(b);
    Ok(seeds)
}

pub(super) fn jpeg_seeds() -> Result<Vec<Vec<u8>>> {
    let (w, h) = (16usize, 16usize);
    let grey: Vec<u8> = (0..w * h)
        .map(|i| ((i % w) * 13 + (i / w) * 7) as u8)
        .collect();
    let rgb: Vec<u8> = (0..w * h * 3).map(|i| (i * 5 % 256) as u8).collect();
    let mut colour = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut colour, 80).encode(
        &rgb,
        w as u32,
        h as u32,
        image::ExtendedColorType::Rgb8,
    )?;
    Ok(vec![
        dataset_io::encode_jpeg_gray(w, h, &grey, 90)?,
        dataset_io::encode_jpeg_gray(9, 7, &grey[..63], 30)?,
        colour,
    ])
}

pub(super) fn zip_seeds(pngs: &[Vec<u8>], jpegs: &[Vec<u8>]) -> Result<Vec<Vec<u8>>> {
    let mut seeds = Vec::new();
    for (prefix, method, frames) in [
        ("", zip::CompressionMethod::Stored, jpegs),
        ("images/", zip::CompressionMethod::Deflated, pngs),
    ] {
        let mut bytes = Vec::new();
        {
            let mut z = zip::ZipWriter::new(Cursor::new(&mut bytes));
            let opts = zip::write::SimpleFileOptions::default().compression_method(method);
            for (i, f) in frames.iter().take(3).enumerate() {
                let ext = if prefix.is_empty() { "jpg" } else { "png" };
                z.start_file(format!("{prefix}{i:05}.{ext}"), opts)?;
                z.write_all(f)?;
            }
            z.start_file("notes.txt", opts)?;
            z.write_all(b"not an image")?;
            z.finish()?;
        }
        seeds.push(bytes);
    }
    Ok(seeds)
}

pub(super) fn text_seeds_generated() -> (Vec<u8>, Vec<u8>, Vec<u8>, Vec<u8>) {
    // KITTI: 12 numbers a line, then its times
    let mut kitti = String::new();
    let mut times = String::new();
    for i in 0..8 {
        let a = i as f64 * 0.2;
        kitti.push_str(&format!(
            "{} {} 0 {} {} {} 0 {} 0 0 1 {}\n",
            a.cos(),
            -a.sin(),
            i as f64,
            a.sin(),
            a.cos(),
            0.5 * i as f64,
            0.1 * i as f64
        ));
        times.push_str(&format!("{:e}\n", 100.0 + i as f64 * 0.05));
    }
    let kitti = format!("{kitti}---\n{times}");
    // EuRoC csv
    let mut euroc = String::from("#timestamp [ns],p_x,p_y,p_z,q_w,q_x,q_y,q_z\n");
    for i in 0..8 {
        euroc.push_str(&format!(
            "{},{},{},0.5,1,0,0,0\n",
            100_000_000_000u64 + i * 50_000_000,
            i,
            i * 2
        ));
    }
    // results.csv, as eval-batch writes it
    let records: Vec<eval_metrics::RunRecord> = (0..6u32)
        .map(|i| {
            let failed = i % 3 == 1;
            eval_metrics::RunRecord {
                key: eval_metrics::RunKey {
                    method: if i == 5 {
                        "a,b \"c\"".into()
                    } else {
                        "dso".into()
                    },
                    sequence: format!("sequence_{:02}", i % 2 + 1),
                    direction: if i % 2 == 0 {
                        eval_metrics::Direction::Forward
                    } else {
                        eval_metrics::Direction::Backward
                    },
                    run: i,
                },
                failure: failed.then(|| "lost, before the end segment".to_string()),
                metrics: if failed {
                    eval_metrics::Metrics::FAILED
                } else {
                    eval_metrics::Metrics {
                        e_align: 0.5 + f64::from(i),
                        e_s: 1.01,
                        e_r: 0.3,
                        e_t: 0.2,
                        e_rmse: 0.1,
                        rmse_start: 0.01,
                        rmse_end: 0.02,
                    }
                },
                poses: 100,
                // the other metrics' columns: APE and KITTI for some runs
                extra: if i % 2 == 0 {
                    [
                        ("ape_rmse", 0.1),
                        ("ape_max", f64::INFINITY),
                        ("kitti_t_err", 1.5),
                    ]
                    .into_iter()
                    .map(|(k, v)| (k.to_string(), v * f64::from(i + 1)))
                    .collect()
                } else {
                    Default::default()
                },
            }
        })
        .collect();
    let csv = eval_metrics::write_csv(&records);
    // poses of a vignette-calibration set
    let plane = synthetic::plane::PlaneSequence::new(
        3,
        synthetic::plane::PlaneConfig {
            width: 64,
            height: 48,
            frames: 6,
            ..synthetic::plane::PlaneConfig::default()
        },
    );
    (
        kitti.into_bytes(),
        euroc.into_bytes(),
        csv.into_bytes(),
        plane.poses_text().into_bytes(),
    )
}

pub(super) fn targets(root: &Path) -> Result<Vec<Target>> {
    let pngs = {
        let mut p = png_seeds()?;
        // the small real vignettes (a 1280x720 grey+alpha, a 752x480 RGB)
        for v in fixtures(root, "vignette", false, usize::MAX)? {
            if v.len() <= 4096 && v.starts_with(b"\x89PNG") {
                p.push(v);
            }
        }
        p
    };
    let jpegs = jpeg_seeds()?;
    let zips = zip_seeds(&pngs, &jpegs)?;
    let (kitti, euroc, csv, poses) = text_seeds_generated();
    let cameras = fixtures(root, "camera", true, 4096)?;
    let trajectories = fixtures(root, "trajectory", true, 4096)?;
    let values = camera_values(&cameras);
    let mut times = fixtures(root, "times", true, 4096)?;
    times.push(
        b"00000 1.0 5\n00001 1.1 0\n00002 1.2 7\n# comment\n00003 1.3 0\n00004 1.4 0\n".to_vec(),
    );
    times.push(b"1.0\n1.1\n1.2\n".to_vec());
    let mut ground_truths = vec![ground_truth_text().into_bytes()];
    // the real ground truths among the trajectories (TUM rows of 8 numbers)
    ground_truths.extend(
        trajectories
            .iter()
            .filter(|t| {
                text(t)
                    .lines()
                    .find(|l| !l.starts_with('#'))
                    .is_some_and(|l| l.split_whitespace().count() == 8)
            })
            .take(4)
            .cloned(),
    );
    let (calibrations, listings, truths) = dataset_seeds(root)?;
    let mut all = Vec::new();
    all.extend([
        Target {
            id: "calibration",
            what: "calibration files (camchain.yaml, sensor.yaml, calibration.json, calib.txt)",
            seeds: calibrations,
            text: true,
            run: run_calibration,
        },
        Target {
            id: "listing",
            what: "data.csv, exposure.csv, rgb.txt",
            seeds: listings,
            text: true,
            run: run_listing,
        },
        Target {
            id: "dataset-truth",
            what: "ground truth of EuRoC, TUM-VI, 4Seasons, KITTI, TUM",
            seeds: truths,
            text: true,
            run: run_dataset_truth,
        },
        Target {
            id: "camera",
            what: "camera.txt",
            seeds: cameras,
            text: true,
            run: run_camera,
        },
        Target {
            id: "camera-values",
            what: "--pinhole and --size values",
            seeds: values,
            text: true,
            run: run_camera_values,
        },
        Target {
            id: "times",
            what: "times.txt",
            seeds: times,
            text: true,
            run: run_times,
        },
        Target {
            id: "pcalib",
            what: "pcalib.txt",
            // 256 values are 3-5 KiB; the 65536-value table is cut
            seeds: fixtures(root, "pcalib", true, 8192)?,
            text: true,
            run: run_pcalib,
        },
        Target {
            id: "groundtruth",
            what: "groundtruthSync.txt",
            seeds: ground_truths,
            text: true,
            run: run_ground_truth,
        },
    ]);
    all.extend(trajectory_targets(root, trajectories, kitti, euroc)?);
    all.extend([
        Target {
            id: "manifest",
            what: "experiment manifest TOML",
            seeds: vec![
                std::fs::read(root.join("data/experiment.toml"))
                    .context("data/experiment.toml")?,
                b"dataset = \"d\"\nresults = \"r\"\nmetrics = [\"e_align\", \"ape_rmse\", \"rpe_mean\", \"kitti_t_err\"]\n[[method]]\nname = \"a\"\n[ape]\nalign = \"sim3\"\npose_relation = \"angle_deg\"\n[rpe]\ntum = true\ndelta = 1\ndelta_unit = \"s\"\n[kitti]\nalign = \"se3\"\n".to_vec(),
            ],
            text: true,
            run: run_manifest,
        },
        Target {
            id: "poses",
            what: "plane poses (calib vignette --poses)",
            seeds: vec![poses],
            text: true,
            run: run_plane_poses,
        },
        Target {
            id: "calib-config",
            what: "calib --config TOML",
            seeds: {
                let full =
                    std::fs::read(root.join("data/calib.toml")).context("data/calib.toml")?;
                vec![
                    full,
                    b"[vignette]\nsmoothing_px = 2.0\ngrid = 200\n".to_vec(),
                    b"[response]\nmax_iterations = 20\ntolerance = 0.1\nsaturation_border = 0\n"
                        .to_vec(),
                    b"response = { smoothness = 3.0, huber = 2.5, weighting = \"uniform\" }\n".to_vec(),
                ]
            },
            text: true,
            run: run_calib_config,
        },
        Target {
            id: "results-csv",
            what: "results.csv (plot)",
            seeds: vec![csv],
            text: true,
            run: run_results_csv,
        },
    ]);
    all.extend(image_targets(pngs, jpegs, zips));
    Ok(all)
}

/// The seeds of the other datasets' files: calibration files, listings (data.csv,
/// exposure.csv, rgb.txt) and ground truths, from `tests/fixtures/datasets` and written here.
#[allow(clippy::type_complexity)]
fn dataset_seeds(root: &Path) -> Result<(Vec<Vec<u8>>, Vec<Vec<u8>>, Vec<Vec<u8>>)> {
    let datasets = root.join("tests/fixtures/datasets");
    let read_dir = |sub: &str, limit: usize| -> Result<Vec<Vec<u8>>> {
        let dir = datasets.join(sub);
        let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
            .with_context(|| dir.display().to_string())?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.is_file())
            .collect();
        files.sort();
        files
            .into_iter()
            .map(|p| {
                Ok(head(
                    std::fs::read(&p).with_context(|| p.display().to_string())?,
                    limit,
                    true,
                ))
            })
            .collect()
    };
    // Basalt's files are mostly IMU and vignette tables: the seeds keep the cameras' part,
    // compact, so that whole files fit in a seed
    let compact = |b: Vec<u8>| -> Vec<u8> {
        let Ok(mut v) = serde_json::from_slice::<serde_json::Value>(&b) else {
            return b;
        };
        if let Some(c) = v.get_mut("value0").and_then(|c| c.as_object_mut()) {
            c.retain(|k, _| matches!(k.as_str(), "T_imu_cam" | "intrinsics" | "resolution"));
        }
        serde_json::to_vec(&v).unwrap_or(b)
    };
    let mut calibrations: Vec<Vec<u8>> = read_dir("calib", usize::MAX)?
        .into_iter()
        .map(compact)
        .map(|b| head(b, 3072, true))
        .collect();
    calibrations.push(b"726.28741455078 726.28741455078 354.6496887207 186.46566772461\n".to_vec());
    calibrations.extend(
        read_dir("heads", 4096)?
            .into_iter()
            .filter(|h| h.starts_with(b"P0:")),
    );
    let heads = read_dir("heads", 4096)?;
    let listings = vec![
        b"#timestamp [ns],filename\n1403636579763555584,1403636579763555584.png\n1403636579813555456,1403636579813555456.png\n".to_vec(),
        b"#timestamp [ns],exposure [ns]\n1403636579763555584,5000000\n1403636579813555456,5250000\n".to_vec(),
        b"# color images\n1305031102.175304 rgb/1305031102.175304.png\n1305031102.211214 rgb/1305031102.211214.png\n".to_vec(),
        b"1520530308.199447626".to_vec(),
    ];
    let mut truths: Vec<Vec<u8>> = heads.clone();
    truths.push(b"# timestamp, tx, ty, tz, qx, qy, qz, qw, scale, fusion_quality, v3_quality\n1585067782140857088,1.0,2.0,3.0,0,0,0,1,2.5,1,1\n1585067782206857216,1.1,2.0,3.0,0,0,0,1,2.5,1,1\n".to_vec());
    truths.push(b"#timestamp [ns],p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],q_RS_w [],q_RS_x [],q_RS_y [],q_RS_z []\n1520530308199447626,0.88,-0.29,1.20,0.71,0.03,-0.02,-0.69\n1520530308207780959,0.88,-0.29,1.21,0.71,0.03,-0.02,-0.69\n".to_vec());
    Ok((calibrations, listings, truths))
}

/// The `--pinhole` and `--size` values: the modes, a few numbers, and lines 3 and 4 of every
/// camera.txt, as given on the command line.
fn camera_values(cameras: &[Vec<u8>]) -> Vec<Vec<u8>> {
    let mut values: Vec<Vec<u8>> = [
        "crop",
        "full",
        "none",
        "0.5 0.6 0.5 0.5 0",
        "640x480",
        "1280 1024",
        "0,5 0,5 0,5 0,5 0",
    ]
    .iter()
    .map(|s| s.as_bytes().to_vec())
    .collect();
    for c in cameras {
        // line 3 and line 4 of every camera.txt, as given on the command line
        values.extend(
            text(c)
                .lines()
                .skip(2)
                .take(2)
                .map(|l| l.as_bytes().to_vec()),
        );
    }
    values
}

/// The trajectory targets: TUM, EuRoC and KITTI files, KITTI pose files, and TUM files
/// through every metric.
fn trajectory_targets(
    root: &Path,
    trajectories: Vec<Vec<u8>>,
    kitti: Vec<u8>,
    euroc: Vec<u8>,
) -> Result<Vec<Target>> {
    let mut tum = trajectories.clone();
    tum.push(ground_truth_text().into_bytes());
    tum.push(estimate_text().into_bytes());
    Ok(vec![
        Target {
            id: "tum",
            what: "TUM trajectory",
            seeds: tum.clone(),
            text: true,
            run: run_tum,
        },
        Target {
            id: "euroc",
            what: "EuRoC trajectory",
            seeds: {
                let mut s = trajectories.clone();
                s.push(euroc);
                s
            },
            text: true,
            run: run_euroc,
        },
        Target {
            id: "kitti",
            what: "KITTI trajectory and times",
            seeds: vec![kitti.clone()],
            text: true,
            run: run_kitti,
        },
        Target {
            id: "kitti-poses",
            what: "KITTI pose file (ape, rpe, kitti)",
            seeds: {
                let k = String::from_utf8_lossy(&kitti).into_owned();
                let mut s = vec![k.split("\n---\n").next().unwrap_or("").as_bytes().to_vec()];
                s.extend(
                    fixtures(root, "../metrics", true, 8192)?
                        .into_iter()
                        .filter(|f| {
                            f.split(|c| *c == b'\n').next().is_some_and(|l| {
                                l.split(|c| *c == b' ').filter(|w| !w.is_empty()).count() == 12
                            })
                        }),
                );
                s
            },
            text: true,
            run: run_kitti_poses,
        },
        Target {
            id: "metrics",
            what: "TUM trajectory through every metric (ape, rpe, --tum, kitti)",
            seeds: tum,
            text: true,
            run: run_metrics,
        },
    ])
}

/// The binary targets: images.zip, PNG and JPEG frames.
fn image_targets(pngs: Vec<Vec<u8>>, jpegs: Vec<Vec<u8>>, zips: Vec<Vec<u8>>) -> Vec<Target> {
    vec![
        Target {
            id: "zip",
            what: "images.zip",
            seeds: zips,
            text: false,
            run: run_zip,
        },
        Target {
            id: "png",
            what: "PNG frames and vignettes",
            seeds: pngs,
            text: false,
            run: run_png,
        },
        Target {
            id: "jpeg",
            what: "JPEG frames",
            seeds: jpegs,
            text: false,
            run: run_jpeg,
        },
    ]
}
