//! A camera.txt explained: the input model, the output pinhole it rectifies to, fields of
//! view and what DSO would read differently (`monovo camera`).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use camera_model::{
    intrinsics_to_file_values, output_notes, CalibrationFile, CalibrationFormat, CameraFile,
    CameraModel, ImageSize, Intrinsics, OutputMode, RectifyMap,
};

use crate::{PipelineError, Result};

/// Horizontal and vertical field of view (degrees) of any model, measured between the rays
/// through the outer edges of the image at the principal point's row and column.
pub fn model_field_of_view(model: &CameraModel, size: ImageSize) -> Option<(f64, f64)> {
    let k = model.intrinsics();
    let angle = |px: [f64; 2], axis: usize| -> Option<f64> {
        let r = model.unproject(px)?;
        Some(r[axis].atan2(r[2]).abs())
    };
    let cx = k.cx.clamp(0.0, size.width as f64 - 1.0);
    let cy = k.cy.clamp(0.0, size.height as f64 - 1.0);
    let h = angle([-0.5, cy], 0)? + angle([size.width as f64 - 0.5, cy], 0)?;
    let v = angle([cx, -0.5], 1)? + angle([cx, size.height as f64 - 0.5], 1)?;
    Some((h.to_degrees(), v.to_degrees()))
}

/// A camera file with its output camera computed.
#[derive(Debug)]
pub struct CameraSummary {
    /// The file.
    pub path: PathBuf,
    /// Its format (camera.txt, Kalibr, EuRoC, Basalt, KITTI, ETH3D).
    pub format: CalibrationFormat,
    /// The camera read (`--cam N`) and its name in the file.
    pub cam: (usize, String),
    /// What it holds, as a camera.txt.
    pub file: CameraFile,
    /// The output camera (line 3 or the override).
    pub mode: OutputMode,
    /// The output size (line 4 or the override).
    pub size: ImageSize,
    /// The output pinhole in pixels.
    pub camera: Intrinsics,
    /// Output pixels without a source.
    pub invalid: usize,
    /// What DSO reads differently, and the output camera's notes (each names the file).
    pub warnings: Vec<String>,
}

/// The image size of a calibration file that gives none (KITTI's calib.txt, ETH3D's
/// calibration.txt): `size_in`, else the first image of the camera's folder beside the file
/// (`image_N/`, `rgb/`), else twice the principal point (with a warning).
fn size_without_file(
    path: &Path,
    cam: usize,
    k: Intrinsics,
    size_in: Option<ImageSize>,
    warnings: &mut Vec<String>,
) -> ImageSize {
    if let Some(s) = size_in {
        return s;
    }
    let dir = path.parent().unwrap_or(Path::new("."));
    for folder in [dir.join(format!("image_{cam}")), dir.join("rgb")] {
        let Ok(rd) = std::fs::read_dir(&folder) else {
            continue;
        };
        let mut files: Vec<PathBuf> = rd.filter_map(|e| e.ok().map(|e| e.path())).collect();
        files.sort();
        if let Some(img) = files.iter().find_map(|f| dataset_io::read_gray8(f).ok()) {
            return ImageSize::new(img.width(), img.height());
        }
    }
    let guess = ImageSize::new(
        (2.0 * k.cx + 1.0).round().max(2.0) as usize,
        (2.0 * k.cy + 1.0).round().max(2.0) as usize,
    );
    warnings.push(format!(
        "{}: the file gives no image size and no image folder is beside it: {guess} assumed from the principal point (give --size-in WxH)",
        path.display()
    ));
    guess
}

/// Reads a calibration file of any supported format (camera.txt, Kalibr camchain.yaml, EuRoC
/// sensor.yaml, Basalt calibration.json, KITTI calib.txt, ETH3D calibration.txt), takes
/// camera `cam`, and computes its output camera (`mode` and `size` override camera.txt's lines
/// 3 and 4; other formats default to `crop` at the input size). `size_in` gives the image
/// size where the file has none.
pub fn summarize_camera(
    path: &Path,
    cam: usize,
    mode: Option<OutputMode>,
    size: Option<ImageSize>,
    size_in: Option<ImageSize>,
) -> Result<CameraSummary> {
    let text = dataset_io::read_text(path).map_err(|source| PipelineError::Read {
        what: "the camera file",
        source,
    })?;
    let camera_err = |source| PipelineError::Camera {
        context: path.display().to_string(),
        source,
    };
    let cal = CalibrationFile::parse(&text).map_err(camera_err)?;
    let calibrated = cal.camera(cam).map_err(camera_err)?;
    let mut notes = Vec::new();
    let input_size = match calibrated.size {
        Some(s) => s,
        None => size_without_file(
            path,
            cam,
            calibrated.model.intrinsics(),
            size_in,
            &mut notes,
        ),
    };
    let file = cal.camera_file(cam, Some(input_size)).map_err(camera_err)?;
    let mode = mode.unwrap_or(file.output);
    let out_size = size.unwrap_or(file.output_size);
    let mut warnings: Vec<String> = file
        .warnings
        .iter()
        .chain(&output_notes(&file.input, file.input_size, &mode, out_size))
        .map(|w| format!("{}: {w}", path.display()))
        .collect();
    warnings.extend(notes);
    let map =
        RectifyMap::for_mode(&file.input, file.input_size, &mode, out_size).map_err(|source| {
            PipelineError::Camera {
                context: format!("{}: output camera `{mode}` at {out_size}", path.display()),
                source,
            }
        })?;
    let invalid = map.invalid_count();
    if mode == OutputMode::Crop && invalid > 0 {
        warnings.push(format!(
            "{}: `crop` at {out_size} leaves {invalid} output pixels without a source; a smaller --size or another --pinhole avoids them",
            path.display(),
        ));
    }
    Ok(CameraSummary {
        path: path.to_path_buf(),
        format: cal.format,
        cam: (cam, calibrated.name.clone()),
        camera: map.camera(),
        file,
        mode,
        size: out_size,
        invalid,
        warnings,
    })
}

impl CameraSummary {
    /// The output camera as one JSON object (pixels, pixel centres at integers).
    pub fn json(&self) -> serde_json::Value {
        let k = &self.camera;
        let i = self.file.input.intrinsics();
        serde_json::json!({
            "fx": k.fx, "fy": k.fy, "cx": k.cx, "cy": k.cy,
            "width": self.size.width, "height": self.size.height,
            "format": self.format,
            "cam": self.cam.0,
            "name": self.cam.1,
            "input": {
                "model": self.file.input.name(),
                "fx": i.fx, "fy": i.fy, "cx": i.cx, "cy": i.cy,
                "distortion": self.file.input.distortion(),
                "width": self.file.input_size.width, "height": self.file.input_size.height,
            },
            "output": self.mode.to_string(),
            "invalid_pixels": self.invalid,
        })
    }

    /// The summary as text (`monovo camera`).
    pub fn text(&self) -> String {
        let (file, k, out_size, mode) = (&self.file, &self.camera, self.size, &self.mode);
        let mut s = format!(
            "file:   {} ({}, camera {} `{}`)\ninput:  {} ({})\n",
            self.path.display(),
            self.format,
            self.cam.0,
            self.cam.1,
            file.input,
            file.input_size
        );
        if let Some((h, v)) = model_field_of_view(&file.input, file.input_size) {
            let _ = writeln!(s, "        field of view {h:.1} x {v:.1} degrees");
        }
        let _ = writeln!(
            s,
            "output: {mode} -> Pinhole fx={:.3} fy={:.3} cx={:.3} cy={:.3} ({out_size})",
            k.fx, k.fy, k.cx, k.cy
        );
        let (h, v) = k.field_of_view_deg(out_size.width, out_size.height);
        let _ = writeln!(s, "        field of view {h:.1} x {v:.1} degrees");
        let rel = intrinsics_to_file_values(k, out_size);
        let _ = writeln!(
            s,
            "        camera.txt line 3: {} {} {} {} 0",
            rel[0], rel[1], rel[2], rel[3]
        );
        let _ = writeln!(
            s,
            "        invalid (black) pixels: {} ({:.2}%)",
            self.invalid,
            100.0 * self.invalid as f64 / out_size.pixels() as f64
        );
        if !file.ignored_lines.is_empty() {
            s.push_str("ignored (DSO reads only lines 1-4):\n");
            for (no, line) in &file.ignored_lines {
                let shown: String = line.chars().take(70).collect();
                let more = if shown.len() < line.len() { "..." } else { "" };
                let _ = writeln!(s, "        line {no}: {shown}{more}");
            }
        }
        s
    }
}
