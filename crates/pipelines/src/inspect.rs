//! What a sequence folder holds, and every problem that would stop rectification (or DSO),
//! each with its file and line (`monovo info`).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use camera_model::{CameraFile, ImageSize, Intrinsics};
use dataset_io::Sequence;
use eval_metrics::GroundTruth;
use photometric::{InverseResponse, Vignette};
use rayon::prelude::*;

use crate::eval::load_ground_truth;
use crate::{error_chain, Observer, PipelineError, Result};

/// Reads a vignette.png as rectification uses it: 8- or 16-bit grey, a valid map, at the
/// size of the images.
pub fn read_vignette(path: &Path, images: ImageSize) -> Result<Vignette> {
    let (img, _) = dataset_io::read_gray_map(path)?;
    let v = Vignette::from_u16(&img).map_err(|source| PipelineError::Photometric {
        context: path.display().to_string(),
        source,
    })?;
    let (w, h) = v.size();
    if (w, h) != (images.width, images.height) {
        return Err(PipelineError::Invalid(format!(
            "{}: the vignette is {w}x{h} but the images are {images}",
            path.display()
        )));
    }
    Ok(v)
}

/// Everything `monovo info` reports about a sequence folder.
#[derive(Debug)]
pub struct SequenceInfo {
    /// The folder.
    pub sequence: PathBuf,
    /// The layout it was read as (`monovo`, `tum-vi-dso`, `euroc-asl`, `4seasons`, `kitti`,
    /// `tum-rgbd`).
    pub layout: &'static str,
    /// The camera read (`--cam N`).
    pub cam: usize,
    /// Frames.
    pub frames: usize,
    /// `images.zip`, `images/`, or the layout's image folder.
    pub images: String,
    /// First and last timestamp in integer nanoseconds, when the dataset gives them exactly.
    pub timestamps_ns: Option<(i64, i64)>,
    /// First and last exposure in ms, when every frame has one.
    pub exposure_first_last_ms: Option<(f64, f64)>,
    /// The calibration file the camera came from.
    pub camera_file: Option<PathBuf>,
    /// The dataset's own ground truth file (EuRoC, TUM-VI, 4Seasons, KITTI, TUM RGB-D).
    pub dataset_ground_truth: Option<PathBuf>,
    /// Image size.
    pub size: ImageSize,
    /// Bits per sample.
    pub bits: u32,
    /// From the first to the last timestamp, seconds.
    pub duration_s: f64,
    /// Frames per second (median interval).
    pub fps: f64,
    /// Smallest and largest exposure in ms, if logged.
    pub exposure_ms: Option<(f64, f64)>,
    /// camera.txt and its output camera.
    pub camera: Option<(CameraFile, std::result::Result<Intrinsics, String>)>,
    /// pcalib.txt: its number of values and bits, or why it is invalid.
    pub pcalib: Option<std::result::Result<(usize, u32), String>>,
    /// vignette.png: width, height and bits, or why it is unreadable.
    pub vignette: Option<std::result::Result<(usize, usize, u32), String>>,
    /// groundtruthSync.txt.
    pub ground_truth: Option<std::result::Result<GroundTruth, String>>,
    /// Whether every frame was decoded.
    pub frames_checked: bool,
    /// Frames that do not decode (when checked).
    pub frames_failed: usize,
    /// Problems: each stops rectification.
    pub problems: Vec<String>,
    /// Warnings.
    pub warnings: Vec<String>,
}

/// Decodes every frame in parallel; one problem per frame that does not decode (the first
/// 20, and their number).
fn check_frames(seq: &Sequence, observer: &dyn Observer) -> Vec<String> {
    observer.begin(seq.len() as u64, "checking", "frames");
    let mut problems: Vec<String> = (0..seq.len())
        .into_par_iter()
        .filter_map(|k| {
            let r = seq.decode_native(k).err().map(|e| e.to_string());
            observer.advance(1);
            r
        })
        .collect();
    observer.finish();
    if problems.len() > 20 {
        let more = problems.len() - 20;
        problems.truncate(20);
        problems.push(format!("... and {more} more frames that do not decode"));
    }
    problems
}

/// Opens and checks a sequence folder of any layout, camera `cam`, with the layout's own
/// calibration or `calibration` (every frame decoded unless `quick`). Only a folder that cannot be opened at all is an error; everything else is a
/// problem in the report.
pub fn inspect_sequence(
    dir: &Path,
    cam: usize,
    calibration: Option<&Path>,
    quick: bool,
    observer: &dyn Observer,
) -> Result<SequenceInfo> {
    let seq = Sequence::open_with_calibration(dir, cam, calibration)?;
    let rows = &seq.times().rows;
    let n = seq.len();
    let duration_s = match (rows.first(), rows.last()) {
        (Some(a), Some(b)) => b.timestamp - a.timestamp,
        _ => 0.0,
    };
    let mut dts: Vec<f64> = rows
        .windows(2)
        .map(|w| w[1].timestamp - w[0].timestamp)
        .collect();
    dts.sort_by(f64::total_cmp);
    let fps = dts.get(dts.len() / 2).map_or(0.0, |d| 1.0 / d);
    let size = seq.image_size();
    let mut problems: Vec<String> = Vec::new();
    let camera_path = seq
        .camera_path()
        .map_or_else(|| seq.dir().join("camera.txt"), Path::to_path_buf);
    let mut warnings: Vec<String> = seq.times().warnings.clone();
    warnings.extend(seq.layout_warnings.iter().cloned());
    let camera = seq.camera().map(|c| {
        let out = camera_model::output_intrinsics(&c.input, c.input_size, &c.output, c.output_size);
        let notes = camera_model::output_notes(&c.input, c.input_size, &c.output, c.output_size);
        for w in c.warnings.iter().chain(&notes) {
            warnings.push(format!("{}: {w}", camera_path.display()));
        }
        if let Err(e) = &out {
            problems.push(format!(
                "{}: line 3: output camera `{}` at {}: {e}",
                camera_path.display(),
                c.output,
                c.output_size
            ));
        }
        (c.clone(), out.map_err(|e| e.to_string()))
    });
    if camera.is_none() {
        warnings.push(format!(
            "{}: absent (nor the {} layout's calibration file); rectify and DSO need the camera model",
            camera_path.display(),
            seq.layout().name()
        ));
    }
    let pcalib = seq.pcalib_path.as_ref().map(|p| {
        let parsed = dataset_io::read_text(p)
            .map_err(PipelineError::from)
            .and_then(|t| {
                InverseResponse::parse_with_notes(&t).map_err(|source| {
                    PipelineError::Photometric {
                        context: p.display().to_string(),
                        source,
                    }
                })
            });
        match parsed {
            Ok((u, notes)) => {
                warnings.extend(notes.iter().map(|n| format!("{}: {n}", p.display())));
                if seq.bits_per_sample() == 8 && u.bits() != 8 {
                    warnings.push(format!(
                        "{}: {} values ({}-bit) for 8-bit frames: looked up by full range, not exactly",
                        p.display(),
                        u.table().len(),
                        u.bits()
                    ));
                }
                Ok((u.table().len(), u.bits()))
            }
            Err(e) => {
                let e = error_chain(&e);
                problems.push(e.clone());
                Err(e)
            }
        }
    });
    let vignette = seq.vignette_path.as_ref().map(|p| {
        if let Err(e) = read_vignette(p, size) {
            problems.push(error_chain(&e));
        }
        dataset_io::read_gray_map(p)
            .map(|(i, bits)| (i.width(), i.height(), bits))
            .map_err(|e| e.to_string())
    });
    let ground_truth = seq.ground_truth_path.as_ref().map(|p| {
        load_ground_truth(p).map_err(|e| {
            let e = error_chain(&e);
            problems.push(e.clone());
            e
        })
    });
    let frame_problems = if quick {
        Vec::new()
    } else {
        check_frames(&seq, observer)
    };
    let frames_failed = frame_problems.len();
    problems.extend(frame_problems);
    let images = match seq.image_folder() {
        None => "images.zip".to_string(),
        Some(f) => {
            let rel = f.strip_prefix(dir).unwrap_or(f);
            format!("{}/", rel.display())
        }
    };
    let timestamps_ns = seq
        .timestamps_ns()
        .and_then(|v| Some((*v.first()?, *v.last()?)));
    let exposure_first_last_ms = match (rows.first(), rows.last()) {
        (Some(a), Some(b)) if seq.times().exposure_range().is_some() => {
            a.exposure_ms.zip(b.exposure_ms)
        }
        _ => None,
    };
    Ok(SequenceInfo {
        sequence: dir.to_path_buf(),
        layout: seq.layout().name(),
        cam,
        frames: n,
        images,
        timestamps_ns,
        exposure_first_last_ms,
        camera_file: seq.camera_path().map(Path::to_path_buf),
        dataset_ground_truth: seq.dataset_ground_truth.clone(),
        size,
        bits: seq.bits_per_sample(),
        duration_s,
        fps,
        exposure_ms: seq.times().exposure_range(),
        camera,
        pcalib,
        vignette,
        ground_truth,
        frames_checked: !quick,
        frames_failed,
        problems,
        warnings,
    })
}

impl SequenceInfo {
    /// The report as one JSON object (`monovo info --json`).
    pub fn json(&self) -> serde_json::Value {
        serde_json::json!({
            "sequence": self.sequence.display().to_string(),
            "layout": self.layout,
            "cam": self.cam,
            "frames": self.frames,
            "images": self.images,
            "width": self.size.width,
            "height": self.size.height,
            "bits": self.bits,
            "duration_s": self.duration_s,
            "fps": self.fps,
            "timestamps_ns": self.timestamps_ns.map(|(a, b)| [a, b]),
            "exposure_ms": self.exposure_ms.map(|(a, b)| {
                let (first, last) = self.exposure_first_last_ms.unwrap_or((a, b));
                serde_json::json!({"min": a, "max": b, "first": first, "last": last})
            }),
            "camera": self.camera.as_ref().map(|(c, out)| serde_json::json!({
                "file": self.camera_file.as_ref().map(|p| p.display().to_string()),
                "model": c.input.name(),
                "input": {"fx": c.input.intrinsics().fx, "fy": c.input.intrinsics().fy, "cx": c.input.intrinsics().cx, "cy": c.input.intrinsics().cy, "distortion": c.input.distortion()},
                "output": c.output.to_string(),
                "output_width": c.output_size.width,
                "output_height": c.output_size.height,
                "output_camera": out.as_ref().ok().map(|k| serde_json::json!({"fx": k.fx, "fy": k.fy, "cx": k.cx, "cy": k.cy})),
            })),
            "pcalib": self.pcalib.as_ref().map(|r| r.is_ok()),
            "vignette": self.vignette.as_ref().map(|r| r.as_ref().ok().map(|(w, h, bits)| serde_json::json!({"width": w, "height": h, "bits": bits}))),
            "ground_truth": self.ground_truth.as_ref().and_then(|r| r.as_ref().ok()).map(|g| {
                let (s, e) = g.segment_sizes();
                serde_json::json!({"rows": g.len(), "start_segment": s, "end_segment": e})
            }),
            "dataset_ground_truth": self.dataset_ground_truth.as_ref().map(|p| p.display().to_string()),
            "frames_checked": self.frames_checked,
            "problems": self.problems,
            "warnings": self.warnings,
        })
    }

    /// The report as text (`monovo info`).
    pub fn text(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(s, "sequence:     {}", self.sequence.display());
        let _ = writeln!(s, "layout:       {} (camera {})", self.layout, self.cam);
        let _ = writeln!(
            s,
            "images:       {} frames of {}, {}-bit, in {}",
            self.frames, self.size, self.bits, self.images
        );
        let _ = writeln!(
            s,
            "time:         {:.2} s at {:.2} fps (median frame interval)",
            self.duration_s, self.fps
        );
        if let Some((a, b)) = self.timestamps_ns {
            let _ = writeln!(s, "stamps:       {a} .. {b} ns");
        }
        let _ = match self.exposure_ms {
            Some((a, b)) => writeln!(s, "exposure:     {a:.4} .. {b:.4} ms"),
            None => writeln!(s, "exposure:     unknown (not logged for every frame)"),
        };
        let _ = match &self.camera {
            Some((c, Ok(k))) => writeln!(
                s,
                "camera:       {} -> {} {} pinhole fx={:.2} fy={:.2} cx={:.2} cy={:.2}",
                c.input, c.output, c.output_size, k.fx, k.fy, k.cx, k.cy
            ),
            Some((c, Err(_))) => writeln!(s, "camera:       {} (INVALID output camera)", c.input),
            None => writeln!(s, "camera:       no camera.txt"),
        };
        if let Some(p) = &self.camera_file {
            let _ = writeln!(s, "calibration:  {}", p.display());
        }
        let _ = match &self.pcalib {
            Some(Ok((n, bits))) => writeln!(
                s,
                "pcalib.txt:   valid inverse response, {n} values ({bits}-bit)"
            ),
            Some(Err(_)) => writeln!(s, "pcalib.txt:   INVALID"),
            None => writeln!(s, "pcalib.txt:   absent"),
        };
        let _ = match &self.vignette {
            Some(Ok((w, h, bits))) => writeln!(s, "vignette.png: {w}x{h}, {bits}-bit"),
            Some(Err(_)) => writeln!(s, "vignette.png: INVALID"),
            None => writeln!(s, "vignette.png: absent"),
        };
        let _ = match &self.ground_truth {
            Some(Ok(g)) => {
                let (a, b) = g.segment_sizes();
                writeln!(
                    s,
                    "ground truth: {} rows, {a} poses in the start segment, {b} in the end segment",
                    g.len()
                )
            }
            Some(Err(_)) => writeln!(s, "ground truth: INVALID"),
            None => match &self.dataset_ground_truth {
                Some(p) => writeln!(s, "ground truth: {}", p.display()),
                None => writeln!(s, "ground truth: absent"),
            },
        };
        if !self.frames_checked {
            s.push_str("frames:       not decoded (--quick)\n");
        } else if self.frames_failed == 0 {
            let _ = writeln!(s, "frames:       all {} decode", self.frames);
        }
        for w in &self.warnings {
            let _ = writeln!(s, "warning:      {w}");
        }
        for p in &self.problems {
            let _ = writeln!(s, "PROBLEM:      {p}");
        }
        s
    }
}
