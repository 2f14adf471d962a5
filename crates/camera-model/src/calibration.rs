//! Calibration files of the field's tools, read from their text: DSO's camera.txt, Kalibr's
//! `camchain.yaml`, EuRoC/ASL's `sensor.yaml`, Basalt's `calibration.json` and KITTI's
//! `calib.txt`. [`CalibrationFile::parse`] tells the format from the content.
//!
//! All these tools put pixel centres at integer coordinates (OpenCV's convention), as monovo
//! does, so their intrinsics are used unchanged.

use std::fmt;

use yaml_rust2::{Yaml, YamlLoader};

use crate::{CameraError, CameraFile, CameraModel, ImageSize, Intrinsics, OutputMode};

/// The formats [`CalibrationFile::parse`] reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum CalibrationFormat {
    /// DSO's and the benchmark's camera.txt.
    CameraTxt,
    /// Kalibr's `camchain.yaml` (or `camchain-imucam.yaml`): `cam0:`, `cam1:`, ...
    KalibrCamchain,
    /// EuRoC/ASL `sensor.yaml` of one camera (`intrinsics`, `distortion_model`, `T_BS`).
    EurocSensor,
    /// Basalt's `calibration.json` (`value0` with `intrinsics`, `resolution`, `T_imu_cam`).
    BasaltJson,
    /// KITTI odometry `calib.txt` (`P0:` ... 3x4 projection matrices, already rectified).
    KittiCalib,
    /// ETH3D SLAM's `calibration.txt`: one line `fx fy cx cy` (rectified pinhole).
    Eth3d,
}

impl fmt::Display for CalibrationFormat {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            CalibrationFormat::CameraTxt => "DSO camera.txt",
            CalibrationFormat::KalibrCamchain => "Kalibr camchain.yaml",
            CalibrationFormat::EurocSensor => "EuRoC sensor.yaml",
            CalibrationFormat::BasaltJson => "Basalt calibration.json",
            CalibrationFormat::KittiCalib => "KITTI calib.txt",
            CalibrationFormat::Eth3d => "ETH3D calibration.txt",
        })
    }
}

/// A 4x4 rigid transform, row-major.
pub type Transform = [[f64; 4]; 4];

/// One camera of a calibration file.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct CalibratedCamera {
    /// Its name in the file (`cam0`, `P0`, index in Basalt's lists).
    pub name: String,
    /// The model, in pixels of `size`.
    pub model: CameraModel,
    /// The image size, when the file gives it (KITTI's calib.txt does not).
    pub size: Option<ImageSize>,
    /// The transform from the IMU (body) frame to this camera's frame, when the file gives
    /// it: Kalibr's `T_cam_imu`, the inverse of Basalt's `T_imu_cam` and of EuRoC's `T_BS`.
    pub camera_from_imu: Option<Transform>,
}

/// A parsed calibration file: its format and its cameras in file order.
#[derive(Clone, Debug, PartialEq)]
pub struct CalibrationFile {
    /// The format, told from the content.
    pub format: CalibrationFormat,
    /// The cameras (`--cam N` picks the N-th).
    pub cameras: Vec<CalibratedCamera>,
    /// The whole camera.txt, for that format (its output camera and warnings).
    pub camera_txt: Option<CameraFile>,
}

fn parse_err(line: usize, expected: impl Into<String>, found: impl Into<String>) -> CameraError {
    CameraError::Parse {
        line,
        expected: expected.into(),
        found: found.into(),
    }
}

fn excerpt(s: &str) -> String {
    s.trim().chars().take(80).collect()
}

/// The 1-based line of the first line starting (after blanks) with `key`, after line `from`.
fn line_of(text: &str, key: &str, from: usize) -> usize {
    text.lines()
        .enumerate()
        .skip(from.saturating_sub(1))
        .find(|(_, l)| l.trim_start().starts_with(key))
        .map_or(0, |(i, _)| i + 1)
}

impl CalibrationFile {
    /// Parses a calibration file of any supported format, told from its content: JSON with
    /// `value0` is Basalt's; lines `P0:` are KITTI's; YAML with `cam0:` is Kalibr's, with
    /// `intrinsics:` at the top EuRoC's sensor.yaml; one line of 4 numbers ETH3D's; anything
    /// else is read as camera.txt.
    pub fn parse(original: &str) -> Result<CalibrationFile, CameraError> {
        let text = original.strip_prefix('\u{feff}').unwrap_or(original);
        let t = text.trim_start();
        if t.starts_with('{') {
            return parse_basalt(text);
        }
        if t.starts_with("P0:") || t.starts_with("P0 :") {
            return parse_kitti(text);
        }
        let top_keys = |key: &str| text.lines().any(|l| l.starts_with(key));
        if top_keys("cam0:") {
            return parse_kalibr(text);
        }
        if top_keys("intrinsics:") && (top_keys("camera_model:") || top_keys("T_BS:")) {
            return parse_euroc(text);
        }
        let content: Vec<(usize, &str)> = text
            .lines()
            .enumerate()
            .filter(|(_, l)| !l.trim().is_empty() && !l.trim_start().starts_with('#'))
            .collect();
        if let [(i, only)] = content.as_slice() {
            let nums: Option<Vec<f64>> = only
                .split_whitespace()
                .map(|v| v.parse::<f64>().ok())
                .collect();
            if let Some(n) = nums.filter(|n| n.len() == 4) {
                let model = CameraModel::Pinhole(intrinsics(&n));
                if let Some(message) = model.parameter_problem() {
                    return Err(CameraError::InvalidValue {
                        line: i + 1,
                        message,
                    });
                }
                return Ok(CalibrationFile {
                    format: CalibrationFormat::Eth3d,
                    cameras: vec![CalibratedCamera {
                        name: "camera".into(),
                        model,
                        size: None,
                        camera_from_imu: None,
                    }],
                    camera_txt: None,
                });
            }
        }
        // camera.txt notes a byte-order mark itself
        let file = CameraFile::parse(original)?;
        Ok(CalibrationFile {
            format: CalibrationFormat::CameraTxt,
            cameras: vec![CalibratedCamera {
                name: "camera".into(),
                model: file.input.clone(),
                size: Some(file.input_size),
                camera_from_imu: None,
            }],
            camera_txt: Some(file),
        })
    }

    /// Camera `cam` (`--cam N`), or an error naming the cameras the file has.
    pub fn camera(&self, cam: usize) -> Result<&CalibratedCamera, CameraError> {
        self.cameras
            .get(cam)
            .ok_or_else(|| CameraError::InvalidValue {
                line: 0,
                message: format!(
                    "camera {cam} requested, the {} has {} camera(s): {}",
                    self.format,
                    self.cameras.len(),
                    self.cameras
                        .iter()
                        .map(|c| c.name.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            })
    }

    /// Camera `cam` as a [`CameraFile`] (camera.txt's own file for that format; else output
    /// `crop` at the input size). `size` gives the image size where the file has none
    /// (KITTI) and must agree with the file's where it has one.
    pub fn camera_file(
        &self,
        cam: usize,
        size: Option<ImageSize>,
    ) -> Result<CameraFile, CameraError> {
        if let Some(f) = &self.camera_txt {
            if cam != 0 {
                self.camera(cam)?;
            }
            return Ok(f.clone());
        }
        let c = self.camera(cam)?;
        let input_size = match (c.size, size) {
            (Some(s), _) => s,
            (None, Some(s)) => s,
            (None, None) => {
                return Err(CameraError::InvalidValue {
                    line: 0,
                    message: format!(
                    "the {} gives no image size for {}: give --size-in or read it with its images",
                    self.format, c.name
                ),
                })
            }
        };
        Ok(CameraFile {
            input: c.model.clone(),
            input_size,
            output: OutputMode::Crop,
            output_size: input_size,
            ignored_lines: Vec::new(),
            warnings: Vec::new(),
        })
    }
}

/// A YAML number (integer or real).
fn yaml_f64(v: &Yaml) -> Option<f64> {
    match v {
        Yaml::Real(_) => v.as_f64(),
        Yaml::Integer(i) => Some(*i as f64),
        _ => None,
    }
}

/// A YAML list of numbers (a flow list, or a block list of rows flattened).
fn yaml_numbers(v: &Yaml) -> Option<Vec<f64>> {
    let mut out = Vec::new();
    for item in v.as_vec()? {
        match item {
            Yaml::Array(row) => {
                for x in row {
                    out.push(yaml_f64(x)?);
                }
            }
            x => out.push(yaml_f64(x)?),
        }
    }
    Some(out)
}

fn load_yaml(text: &str) -> Result<Yaml, CameraError> {
    let docs = YamlLoader::load_from_str(text).map_err(|e| {
        let line = e.marker().line();
        let found = text.lines().nth(line.saturating_sub(1)).unwrap_or("");
        parse_err(line, format!("YAML ({})", e.info()), excerpt(found))
    })?;
    docs.into_iter()
        .next()
        .ok_or_else(|| parse_err(1, "a YAML document", ""))
}

/// Reads the numbers of `key` in `node`: exactly `n` of them (any count when `n` is 0).
fn numbers_of(
    node: &Yaml,
    key: &str,
    n: usize,
    text: &str,
    from: usize,
    what: &str,
) -> Result<Vec<f64>, CameraError> {
    let line = line_of(text, &format!("{key}:"), from).max(from);
    let v = &node[key];
    if v.is_badvalue() {
        return Err(parse_err(from, format!("`{key}:` ({what})"), "nothing"));
    }
    let nums = yaml_numbers(v).ok_or_else(|| {
        parse_err(
            line,
            format!("`{key}:` as a list of numbers ({what})"),
            excerpt(text.lines().nth(line.saturating_sub(1)).unwrap_or("")),
        )
    })?;
    if n > 0 && nums.len() != n {
        return Err(parse_err(
            line,
            format!("{n} numbers in `{key}` ({what})"),
            format!("{} numbers", nums.len()),
        ));
    }
    if let Some(bad) = nums.iter().find(|x| !x.is_finite()) {
        return Err(CameraError::InvalidValue {
            line,
            message: format!("`{key}` holds `{bad}`, not a finite number"),
        });
    }
    Ok(nums)
}

fn size_of(nums: &[f64], line: usize) -> Result<ImageSize, CameraError> {
    let ok = |v: f64| v.fract() == 0.0 && (0.0..=1e6).contains(&v);
    if nums.len() != 2 || !ok(nums[0]) || !ok(nums[1]) {
        return Err(parse_err(
            line,
            "a resolution `[width, height]` of two integers",
            format!("{nums:?}"),
        ));
    }
    ImageSize::new(nums[0] as usize, nums[1] as usize)
        .validate()
        .map_err(|e| CameraError::InvalidValue {
            line,
            message: e.to_string(),
        })
}

fn transform_of(nums: &[f64], line: usize, key: &str) -> Result<Transform, CameraError> {
    if nums.len() != 16 {
        return Err(parse_err(
            line,
            format!("16 numbers (4x4) in `{key}`"),
            format!("{} numbers", nums.len()),
        ));
    }
    let mut t = [[0.0; 4]; 4];
    for (i, v) in nums.iter().enumerate() {
        t[i / 4][i % 4] = *v;
    }
    Ok(t)
}

/// The inverse of a rigid transform (rotation transposed).
pub fn invert_rigid(t: &Transform) -> Transform {
    let mut out = [[0.0; 4]; 4];
    for i in 0..3 {
        for j in 0..3 {
            out[i][j] = t[j][i];
        }
        out[i][3] = -(0..3).map(|j| t[j][i] * t[j][3]).sum::<f64>();
    }
    out[3][3] = 1.0;
    out
}

fn intrinsics(v: &[f64]) -> Intrinsics {
    Intrinsics {
        fx: v[0],
        fy: v[1],
        cx: v[2],
        cy: v[3],
    }
}

/// The model of a projection and a distortion as Kalibr names them (`pinhole`, `omni`, `ds`,
/// `eucm`; `none`, `radtan`, `equidistant`, `fov`) and EuRoC (`radial-tangential`).
fn kalibr_model(
    projection: &str,
    distortion: &str,
    intr: &[f64],
    dist: &[f64],
    line: usize,
) -> Result<CameraModel, CameraError> {
    let need = |n: usize, what: &str| -> Result<(), CameraError> {
        if intr.len() == n {
            Ok(())
        } else {
            Err(parse_err(
                line,
                format!("{n} intrinsics `{what}` for `{projection}`"),
                format!("{} numbers", intr.len()),
            ))
        }
    };
    let coeffs = |n: usize| -> Result<[f64; 4], CameraError> {
        if dist.len() != n {
            return Err(parse_err(
                line,
                format!("{n} distortion coefficients for `{distortion}`"),
                format!("{} numbers", dist.len()),
            ));
        }
        let mut c = [0.0; 4];
        c[..n].copy_from_slice(dist);
        Ok(c)
    };
    let dist_kind = match distortion {
        "none" | "" => "none",
        "radtan" | "radial-tangential" | "plumb_bob" => "radtan",
        "equidistant" | "equi" | "fisheye" => "equidistant",
        "fov" => "fov",
        other => {
            return Err(parse_err(
                line,
                "distortion_model `none`, `radtan`, `equidistant` or `fov`",
                other,
            ))
        }
    };
    let model = match (projection, dist_kind) {
        ("pinhole", "none") => {
            need(4, "fu fv pu pv")?;
            CameraModel::Pinhole(intrinsics(intr))
        }
        ("pinhole", "radtan") => {
            need(4, "fu fv pu pv")?;
            CameraModel::RadTan {
                k: intrinsics(intr),
                coeffs: coeffs(4)?,
            }
        }
        ("pinhole", "equidistant") => {
            need(4, "fu fv pu pv")?;
            CameraModel::EquiDistant {
                k: intrinsics(intr),
                coeffs: coeffs(4)?,
            }
        }
        ("pinhole", "fov") => {
            need(4, "fu fv pu pv")?;
            CameraModel::Fov {
                k: intrinsics(intr),
                omega: coeffs(1)?[0],
            }
        }
        ("omni", "none" | "radtan") => {
            need(5, "xi fu fv pu pv")?;
            CameraModel::Unified {
                k: intrinsics(&intr[1..]),
                xi: intr[0],
                coeffs: if dist_kind == "none" { [0.0; 4] } else { coeffs(4)? },
            }
        }
        ("ds", "none") => {
            need(6, "xi alpha fu fv pu pv")?;
            CameraModel::DoubleSphere {
                k: intrinsics(&intr[2..]),
                xi: intr[0],
                alpha: intr[1],
            }
        }
        ("eucm", "none") => {
            need(6, "alpha beta fu fv pu pv")?;
            CameraModel::Eucm {
                k: intrinsics(&intr[2..]),
                alpha: intr[0],
                beta: intr[1],
            }
        }
        (p, d) => {
            return Err(parse_err(
                line,
                "camera_model `pinhole` (distortion none, radtan, equidistant, fov), `omni` (none, radtan), `ds` or `eucm` (none)",
                format!("{p} with {d}"),
            ))
        }
    };
    if let Some(message) = model.parameter_problem() {
        return Err(CameraError::InvalidValue { line, message });
    }
    Ok(model)
}

/// Kalibr's camchain.yaml: `camN:` blocks with `camera_model`, `intrinsics`,
/// `distortion_model`, `distortion_coeffs`, `resolution` and (camchain-imucam) `T_cam_imu`.
fn parse_kalibr(text: &str) -> Result<CalibrationFile, CameraError> {
    let doc = load_yaml(text)?;
    let mut cameras = Vec::new();
    for i in 0.. {
        let name = format!("cam{i}");
        let node = &doc[name.as_str()];
        if node.is_badvalue() {
            break;
        }
        let at = line_of(text, &format!("{name}:"), 1).max(1);
        let projection = node["camera_model"].as_str().unwrap_or("pinhole");
        let distortion = node["distortion_model"].as_str().unwrap_or("none");
        let intr = numbers_of(node, "intrinsics", 0, text, at, "Kalibr intrinsics")?;
        let dist = if node["distortion_coeffs"].is_badvalue() {
            Vec::new()
        } else {
            numbers_of(
                node,
                "distortion_coeffs",
                0,
                text,
                at,
                "distortion coefficients",
            )?
        };
        let model_line = line_of(text, "camera_model:", at).max(at);
        let model = kalibr_model(projection, distortion, &intr, &dist, model_line)?;
        let res_line = line_of(text, "resolution:", at).max(at);
        let size = Some(size_of(
            &numbers_of(node, "resolution", 2, text, at, "image size")?,
            res_line,
        )?);
        let camera_from_imu = if node["T_cam_imu"].is_badvalue() {
            None
        } else {
            let l = line_of(text, "T_cam_imu:", at).max(at);
            Some(transform_of(
                &numbers_of(node, "T_cam_imu", 16, text, at, "4x4 transform")?,
                l,
                "T_cam_imu",
            )?)
        };
        cameras.push(CalibratedCamera {
            name,
            model,
            size,
            camera_from_imu,
        });
    }
    if cameras.is_empty() {
        return Err(parse_err(
            1,
            "a Kalibr camchain with `cam0:`",
            excerpt(text.lines().next().unwrap_or("")),
        ));
    }
    Ok(CalibrationFile {
        format: CalibrationFormat::KalibrCamchain,
        cameras,
        camera_txt: None,
    })
}

/// EuRoC/ASL sensor.yaml of one camera: `camera_model`, `intrinsics [fu fv cu cv]`,
/// `distortion_model`, `distortion_coefficients`, `resolution`, `T_BS` (body from sensor,
/// `cols`, `rows`, `data`).
fn parse_euroc(text: &str) -> Result<CalibrationFile, CameraError> {
    let doc = load_yaml(text)?;
    let projection = doc["camera_model"].as_str().unwrap_or("pinhole");
    let distortion = doc["distortion_model"].as_str().unwrap_or("none");
    let intr = numbers_of(&doc, "intrinsics", 0, text, 1, "fu fv cu cv")?;
    let dist = if doc["distortion_coefficients"].is_badvalue() {
        Vec::new()
    } else {
        numbers_of(
            &doc,
            "distortion_coefficients",
            0,
            text,
            1,
            "distortion coefficients",
        )?
    };
    let model_line = line_of(text, "intrinsics:", 1).max(1);
    let model = kalibr_model(projection, distortion, &intr, &dist, model_line)?;
    let size = Some(size_of(
        &numbers_of(&doc, "resolution", 2, text, 1, "image size")?,
        line_of(text, "resolution:", 1).max(1),
    )?);
    let camera_from_imu = if doc["T_BS"].is_badvalue() {
        None
    } else {
        let l = line_of(text, "T_BS:", 1).max(1);
        let data = numbers_of(
            &doc["T_BS"],
            "data",
            16,
            text,
            l,
            "4x4 transform, row-major",
        )?;
        Some(invert_rigid(&transform_of(&data, l, "T_BS")?))
    };
    Ok(CalibrationFile {
        format: CalibrationFormat::EurocSensor,
        cameras: vec![CalibratedCamera {
            name: "cam".into(),
            model,
            size,
            camera_from_imu,
        }],
        camera_txt: None,
    })
}

/// KITTI's calib.txt: `P0: p00 p01 ... p23` (3x4, row-major); K is its left 3x3.
fn parse_kitti(text: &str) -> Result<CalibrationFile, CameraError> {
    let mut cameras = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let line = i + 1;
        let Some((key, rest)) = raw.split_once(':') else {
            if raw.trim().is_empty() {
                continue;
            }
            return Err(parse_err(
                line,
                "`P0: ` followed by 12 numbers (or another `KEY: values` line)",
                excerpt(raw),
            ));
        };
        let key = key.trim();
        if !(key.starts_with('P') && key[1..].parse::<usize>().is_ok()) {
            continue; // Tr:, R0_rect: ...
        }
        let nums: Result<Vec<f64>, _> = rest.split_whitespace().map(str::parse::<f64>).collect();
        let nums =
            nums.map_err(|_| parse_err(line, format!("12 numbers after `{key}:`"), excerpt(rest)))?;
        if nums.len() != 12 {
            return Err(parse_err(
                line,
                format!("12 numbers after `{key}:` (a 3x4 matrix)"),
                format!("{} numbers", nums.len()),
            ));
        }
        if nums[1] != 0.0 || nums[4] != 0.0 || nums[8] != 0.0 || nums[9] != 0.0 || nums[10] != 1.0 {
            return Err(CameraError::InvalidValue {
                line,
                message: format!(
                    "`{key}` is not a rectified projection `[fx 0 cx tx; 0 fy cy ty; 0 0 1 tz]`"
                ),
            });
        }
        let model = CameraModel::Pinhole(Intrinsics {
            fx: nums[0],
            fy: nums[5],
            cx: nums[2],
            cy: nums[6],
        });
        if let Some(message) = model.parameter_problem() {
            return Err(CameraError::InvalidValue { line, message });
        }
        cameras.push(CalibratedCamera {
            name: key.to_string(),
            model,
            size: None,
            camera_from_imu: None,
        });
    }
    if cameras.is_empty() {
        return Err(parse_err(1, "KITTI calib.txt lines `P0: ...`", ""));
    }
    Ok(CalibrationFile {
        format: CalibrationFormat::KittiCalib,
        cameras,
        camera_txt: None,
    })
}

#[derive(serde::Deserialize)]
struct BasaltRoot {
    value0: BasaltCalib,
}

#[derive(serde::Deserialize)]
struct BasaltCalib {
    #[serde(rename = "T_imu_cam", default)]
    t_imu_cam: Vec<BasaltPose>,
    intrinsics: Vec<BasaltIntrinsics>,
    #[serde(default)]
    resolution: Vec<[u32; 2]>,
}

#[derive(serde::Deserialize)]
struct BasaltPose {
    px: f64,
    py: f64,
    pz: f64,
    qx: f64,
    qy: f64,
    qz: f64,
    qw: f64,
}

#[derive(serde::Deserialize)]
struct BasaltIntrinsics {
    camera_type: String,
    intrinsics: std::collections::BTreeMap<String, f64>,
}

/// The rigid transform of a translation and a unit quaternion (normalised here).
fn pose_matrix(p: &BasaltPose) -> Option<Transform> {
    let n = (p.qw * p.qw + p.qx * p.qx + p.qy * p.qy + p.qz * p.qz).sqrt();
    if !(n.is_finite() && n > 0.0) {
        return None;
    }
    let (w, x, y, z) = (p.qw / n, p.qx / n, p.qy / n, p.qz / n);
    Some([
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
            p.px,
        ],
        [
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
            p.py,
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
            p.pz,
        ],
        [0.0, 0.0, 0.0, 1.0],
    ])
}

/// One camera of Basalt's `intrinsics` list as a model (`line`: its `camera_type` line).
fn basalt_model(cam: &BasaltIntrinsics, line: usize) -> Result<CameraModel, CameraError> {
    let get = |key: &str| -> Result<f64, CameraError> {
        cam.intrinsics.get(key).copied().ok_or_else(|| {
            parse_err(
                line,
                format!(
                    "`{key}` in the intrinsics of a `{}` camera",
                    cam.camera_type
                ),
                "nothing",
            )
        })
    };
    let k = Intrinsics {
        fx: get("fx")?,
        fy: get("fy")?,
        cx: get("cx")?,
        cy: get("cy")?,
    };
    let model = match cam.camera_type.as_str() {
        "pinhole" => CameraModel::Pinhole(k),
        "kb4" => CameraModel::KannalaBrandt {
            k,
            coeffs: [get("k1")?, get("k2")?, get("k3")?, get("k4")?],
        },
        "ds" => CameraModel::DoubleSphere {
            k,
            xi: get("xi")?,
            alpha: get("alpha")?,
        },
        "eucm" => CameraModel::Eucm {
            k,
            alpha: get("alpha")?,
            beta: get("beta")?,
        },
        "ucm" => {
            // Basalt's UCM: m = (x, y) / (alpha d + (1 - alpha) z), the unified model
            // with xi = alpha / (1 - alpha) and focal lengths f / (1 - alpha)
            let alpha = get("alpha")?;
            if !(0.0..1.0).contains(&alpha) {
                return Err(CameraError::InvalidValue {
                    line,
                    message: format!("UCM needs alpha in [0, 1), got {alpha}"),
                });
            }
            let s = 1.0 / (1.0 - alpha);
            CameraModel::Unified {
                k: Intrinsics {
                    fx: k.fx * s,
                    fy: k.fy * s,
                    ..k
                },
                xi: alpha * s,
                coeffs: [0.0; 4],
            }
        }
        "fov" => CameraModel::Fov {
            k,
            omega: get("w")?,
        },
        other => {
            return Err(parse_err(
                line,
                "camera_type `pinhole`, `kb4`, `ds`, `eucm`, `ucm`, `fov` or `pinhole-radtan8`",
                other,
            ))
        }
    };
    Ok(model)
}

/// Basalt's calibration.json: `value0.intrinsics[i]` with `camera_type` `pinhole`, `kb4`,
/// `ds`, `eucm`, `ucm` or `fov`, `value0.resolution[i]`, `value0.T_imu_cam[i]`.
fn parse_basalt(text: &str) -> Result<CalibrationFile, CameraError> {
    let root: BasaltRoot = serde_json::from_str(text).map_err(|e| {
        let line = e.line();
        parse_err(
            line,
            format!("a Basalt calibration.json (`value0` with `intrinsics`, `resolution`, `T_imu_cam`): {e}"),
            excerpt(text.lines().nth(line.saturating_sub(1)).unwrap_or("")),
        )
    })?;
    let c = root.value0;
    let at = |i: usize| {
        // the line of the i-th `camera_type`
        text.lines()
            .enumerate()
            .filter(|(_, l)| l.contains("\"camera_type\""))
            .nth(i)
            .map_or(1, |(n, _)| n + 1)
    };
    let mut cameras = Vec::new();
    for (i, cam) in c.intrinsics.iter().enumerate() {
        let line = at(i);
        let model = basalt_model(cam, line)?;
        if let Some(message) = model.parameter_problem() {
            return Err(CameraError::InvalidValue { line, message });
        }
        let size = match c.resolution.get(i) {
            Some(r) => Some(
                ImageSize::new(r[0] as usize, r[1] as usize)
                    .validate()
                    .map_err(|e| CameraError::InvalidValue {
                        line: line_of(text, "\"resolution\"", 1),
                        message: e.to_string(),
                    })?,
            ),
            None => None,
        };
        let camera_from_imu = match c.t_imu_cam.get(i) {
            Some(p) => Some(invert_rigid(&pose_matrix(p).ok_or_else(|| {
                CameraError::InvalidValue {
                    line: line_of(text, "\"T_imu_cam\"", 1),
                    message: format!("T_imu_cam {i}: the quaternion is zero or not finite"),
                }
            })?)),
            None => None,
        };
        cameras.push(CalibratedCamera {
            name: format!("cam{i}"),
            model,
            size,
            camera_from_imu,
        });
    }
    if cameras.is_empty() {
        return Err(parse_err(
            1,
            "at least one camera in `intrinsics`",
            "an empty list",
        ));
    }
    Ok(CalibrationFile {
        format: CalibrationFormat::BasaltJson,
        cameras,
        camera_txt: None,
    })
}
