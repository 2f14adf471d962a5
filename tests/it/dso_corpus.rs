//! Every real DSO-family file in `tests/fixtures/dso-family` (see its README and SOURCES.tsv)
//! is read by monovo the way DSO reads it, or better.
//!
//! For each camera file the test states what DSO does with it, by the small reference of
//! DSO's rules in `dso_reference.rs`, and checks monovo against it:
//!
//! | DSO | monovo (checked) |
//! |---|---|
//! | reads it, `none` | same model and K (exact), the raw image passes through unchanged |
//! | reads it, explicit K | same model and input K; output K = DSO's (relative 1e-12) |
//! | reads it, `crop` | same model and input K; a crop with no invalid pixel whose view contains DSO's on every side (1e-6 relative: DSO tests borders in `float`) |
//! | reads it, `crop`, FOV model | the authors' closed form (DESIGN.md), no invalid pixel; up to 0.5 % narrower than DSO's numeric crop on the right/bottom (the closed form's `ow / w` scale) |
//! | reads it, `crop`, but DSO's crop has invalid pixels (a RadTan that folds back: DSO's axis search takes the last valid sample, past the fold) | no invalid pixel and no folded (mirrored) pixel; smaller than DSO's by necessity |
//! | `exit(1)`: the crop search fails after 500 rounds (same folding RadTan) | a valid crop |
//! | `exit(1)`: no model on line 1, `Pinhole` + 4 numbers | refuses, naming line 1 |
//! | `exit(1)`: `none` with another output size | resizes the raw image (DESIGN.md: "implement `none` properly"), with a note that DSO refuses |
//! | abort: `full` (`assert(false)`) | the whole field of view: a K whose view contains the crop's, or a clear refusal when the border does not unproject |
//! | crash/UB: 9 numbers on an 8-parameter line | the first 8 when the extra numbers are 0 (a zero k3), else refuses naming line 1 |
//! | crash: CRLF `crop\r`, only 2 lines | reads `crop` (2 lines: `crop` at the input size) |
//! | UB: line 4 unreadable | refuses, naming line 4 |
//!
//! The photometric files, times.txt files and trajectories each get a case in the tests
//! below this one.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use camera_model::{
    output_intrinsics, output_notes, CameraError, CameraFile, CameraModel, Image, ImageSize,
    OutputMode, RectifyMap,
};
use rayon::prelude::*;

use crate::dso_reference::{self as dso, Verdict};

pub fn fixtures(kind: &str) -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("fixtures/dso-family")
        .join(kind);
    let mut v: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    v.sort();
    v
}

pub fn name(p: &Path) -> String {
    p.file_name().unwrap().to_string_lossy().into_owned()
}

/// The line number of a camera-model error.
fn error_line(e: &CameraError) -> Option<usize> {
    match e {
        CameraError::Parse { line, .. }
        | CameraError::InvalidValue { line, .. }
        | CameraError::DecimalComma { line, .. } => Some(*line),
        _ => None,
    }
}

/// What one camera file gave.
struct CameraCase {
    file: String,
    /// DSO's class, e.g. "ok crop RadTan".
    class: String,
    /// Model and mode as DSO reads them (for the coverage check); empty when DSO fails.
    model: &'static str,
    mode: &'static str,
    /// Largest relative difference of monovo's output K to DSO's (`none`, explicit).
    k_diff: f64,
    /// For crop: how much farther monovo's view reaches than DSO's, per side, relative
    /// (left, right, top, bottom); negative would be a smaller view.
    crop_gain: Option<[f64; 4]>,
    failures: Vec<String>,
}

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs().max(1e-300)
}

fn mode_name(m: &OutputMode) -> &'static str {
    match m {
        OutputMode::Crop => "crop",
        OutputMode::Full => "full",
        OutputMode::None => "none",
        OutputMode::Pinhole(_) => "explicit",
    }
}

/// monovo's crop for a file must have no invalid pixel (also by the reference's own
/// projection, 1e-5 px tolerance); returns its normalised rectangle.
fn check_crop(
    f: &CameraFile,
    cam: Option<&dso::Cam>,
    out: ImageSize,
    fail: &mut Vec<String>,
) -> Option<[f64; 4]> {
    let k = match output_intrinsics(&f.input, f.input_size, &OutputMode::Crop, out) {
        Ok(k) => k,
        Err(e) => {
            fail.push(format!("crop refused: {e}"));
            return None;
        }
    };
    let map = RectifyMap::for_mode(&f.input, f.input_size, &OutputMode::Crop, out).unwrap();
    if map.invalid_count() != 0 {
        fail.push(format!("crop has {} invalid pixels", map.invalid_count()));
    }
    let kk = [k.fx, k.fy, k.cx, k.cy];
    if let Some(cam) = cam {
        let bad = dso::invalid_pixels(cam, kk, out.width, out.height, 1e-5);
        if bad != 0 {
            fail.push(format!(
                "by DSO's own projection monovo's crop has {bad} invalid pixels"
            ));
        }
    }
    Some(dso::rect_of_k(kk, out.width, out.height))
}

fn check_camera_file(path: &Path) -> CameraCase {
    let bytes = std::fs::read(path).unwrap();
    let text = String::from_utf8(bytes.clone()).unwrap();
    let verdict = dso::read(&bytes);
    let parsed = CameraFile::parse(&text);
    let mut case = CameraCase {
        file: name(path),
        class: String::new(),
        model: "",
        mode: "",
        k_diff: 0.0,
        crop_gain: None,
        failures: Vec::new(),
    };
    match &verdict {
        Verdict::Ok {
            cam,
            out,
            ow,
            oh,
            extra_lines,
        } => check_dso_read(&mut case, cam, out, (*ow, *oh), *extra_lines, parsed),
        Verdict::Exit { line, why } => check_dso_exit(&mut case, *line, why, parsed),
        Verdict::Abort { why } => check_dso_abort(&mut case, why, parsed),
        Verdict::Crash { line, why } => check_dso_crash(&mut case, *line, why, parsed, &text),
    }
    case
}

/// DSO reads the file: monovo reads the same camera, sizes and output, and its output
/// camera is DSO's (or, for `crop`, at least as wide and valid).
fn check_dso_read(
    case: &mut CameraCase,
    cam: &dso::Cam,
    out: &dso::Out,
    (ow, oh): (usize, usize),
    extra_lines: usize,
    parsed: Result<CameraFile, CameraError>,
) {
    let fail = &mut case.failures;
    case.model = match cam.model {
        dso::Model::Fov(0.0) => "Pinhole",
        _ => cam.model.name(),
    };
    case.mode = match out {
        dso::Out::Crop => "crop",
        dso::Out::Full => "full",
        dso::Out::None => "none",
        dso::Out::Explicit(_) => "explicit",
    };
    case.class = format!("DSO reads: {} {}", case.model, case.mode);
    let f = match parsed {
        Ok(f) => f,
        Err(e) => {
            fail.push(format!("DSO reads it, monovo refuses: {e}"));
            return;
        }
    };
    // the same input camera
    if f.input.name() != case.model {
        fail.push(format!(
            "model {} instead of {}",
            f.input.name(),
            case.model
        ));
    }
    let k = f.input.intrinsics();
    for (a, b) in [k.fx, k.fy, k.cx, k.cy].into_iter().zip(cam.k) {
        if rel(a, b) > 1e-12 {
            fail.push(format!("input K {a} instead of DSO's {b}"));
        }
    }
    let want_dist: Vec<f64> = match &cam.model {
        dso::Model::Pinhole => vec![0.0],
        dso::Model::Fov(o) if *o == 0.0 => vec![0.0],
        dso::Model::Fov(o) => vec![o.abs()],
        dso::Model::RadTan(c) | dso::Model::EquiDistant(c) | dso::Model::KannalaBrandt(c) => {
            c.to_vec()
        }
    };
    if f.input.distortion() != want_dist {
        fail.push(format!(
            "distortion {:?} instead of {want_dist:?}",
            f.input.distortion()
        ));
    }
    if (f.input_size.width, f.input_size.height) != (cam.w, cam.h)
        || (f.output_size.width, f.output_size.height) != (ow, oh)
    {
        fail.push(format!("sizes {} {} differ", f.input_size, f.output_size));
    }
    if f.ignored_lines.len() != extra_lines {
        fail.push(format!(
            "{} ignored lines listed, DSO ignores {extra_lines}",
            f.ignored_lines.len()
        ));
    }
    if mode_name(&f.output) != case.mode {
        fail.push(format!("output {} instead of {}", f.output, case.mode));
    }
    let out_size = ImageSize::new(ow, oh);
    match out {
        dso::Out::None => {
            let mk = output_intrinsics(&f.input, f.input_size, &f.output, out_size).unwrap();
            case.k_diff = [mk.fx, mk.fy, mk.cx, mk.cy]
                .iter()
                .zip(cam.k)
                .map(|(a, b)| rel(*a, b))
                .fold(0.0, f64::max);
            if case.k_diff != 0.0 {
                fail.push(format!("none: K {mk:?} is not the input's {:?}", cam.k));
            }
            let map = RectifyMap::for_mode(&f.input, f.input_size, &f.output, out_size).unwrap();
            let img = Image::from_fn(cam.w, cam.h, |x, y| ((x * 7 + y * 13) % 256) as u8);
            if map.remap_u8(&img).unwrap() != img {
                fail.push("none: the raw image does not pass through unchanged".into());
            }
            let notes = output_notes(&f.input, f.input_size, &f.output, out_size);
            if f.input.is_pinhole() != notes.is_empty() {
                fail.push(format!("none: notes {notes:?}"));
            }
        }
        dso::Out::Explicit(v) => {
            let dk = dso::output_k(cam, out, ow, oh).unwrap();
            let mk = output_intrinsics(&f.input, f.input_size, &f.output, out_size).unwrap();
            let relative = v[2] < 1.0 && v[3] < 1.0;
            case.k_diff = [mk.fx, mk.fy, mk.cx, mk.cy]
                .iter()
                .zip(dk)
                .map(|(a, b)| rel(*a, b))
                .fold(0.0, f64::max);
            // DSO multiplies even pixel values by the size; monovo reads them as pixels
            if relative && case.k_diff > 1e-12 {
                fail.push(format!("explicit K {mk:?} instead of DSO's {dk:?}"));
            }
            let map = RectifyMap::for_mode(&f.input, f.input_size, &f.output, out_size).unwrap();
            assert!(map.output_size() == out_size);
        }
        dso::Out::Crop => {
            check_dso_crop(case, &f, cam, (ow, oh));
        }
        dso::Out::Full => unreachable!("DSO aborts on full"),
    }
}

/// `crop`: monovo's crop is valid, the authors' closed form for FOV, and otherwise contains
/// DSO's crop where DSO's own is valid.
fn check_dso_crop(case: &mut CameraCase, f: &CameraFile, cam: &dso::Cam, (ow, oh): (usize, usize)) {
    let fail = &mut case.failures;
    let dso_rect = dso::crop_rect(cam, ow, oh);
    let mono = check_crop(f, Some(cam), ImageSize::new(ow, oh), fail);
    let fov_omega = match cam.model {
        dso::Model::Fov(o) if o != 0.0 => Some(o),
        _ => None,
    };
    match (dso_rect, mono) {
        (Some(d), Some(m)) => {
            let dk = dso::k_of_rect(d, ow, oh);
            let dso_invalid = dso::invalid_pixels(cam, dk, ow, oh, 0.0);
            case.k_diff = dso::k_of_rect(m, ow, oh)
                .iter()
                .zip(dk)
                .map(|(a, b)| rel(*a, b))
                .fold(0.0, f64::max);
            let gain = [
                m[0] / d[0] - 1.0,
                m[1] / d[1] - 1.0,
                m[2] / d[2] - 1.0,
                m[3] / d[3] - 1.0,
            ];
            match fov_omega {
                // FOV keeps the authors' closed form (DESIGN.md): the axis
                // extents through T(x) = tan(x w) / (2 tan(w / 2)), scaled by
                // ow / w. It is up to 0.5 % narrower than DSO's numeric crop
                // on the right and bottom (the ow / w scale) and wider on the
                // left and top.
                Some(omega) => {
                    let t = |x: f64| (x * omega).tan() / (2.0 * (omega / 2.0).tan());
                    let [fx, fy, cx, cy] = cam.k;
                    let (w, h) = (cam.w as f64, cam.h as f64);
                    let (tl, tr) = (t(cx / fx), t((w - 1.0 - cx) / fx));
                    let (tt, tb) = (t(cy / fy), t((h - 1.0 - cy) / fy));
                    let kfx = ow as f64 / w * (w - 1.0) / (tl + tr);
                    let kfy = oh as f64 / h * (h - 1.0) / (tt + tb);
                    let closed = [kfx, kfy, tl * kfx, tt * kfy];
                    let mk = dso::k_of_rect(m, ow, oh);
                    let closed_diff = mk
                        .iter()
                        .zip(closed)
                        .map(|(a, b)| rel(*a, b))
                        .fold(0.0, f64::max);
                    if closed_diff > 1e-9 {
                        fail.push(format!("FOV crop {mk:?} is not the closed form {closed:?}"));
                    }
                    if gain.iter().any(|g| *g < -0.005) {
                        fail.push(format!("FOV crop far narrower than DSO's: {gain:?}"));
                    }
                }
                // DSO's crop is itself valid: monovo's must contain it
                None if dso_invalid == 0 => {
                    if gain.iter().any(|g| *g < -1e-6) {
                        fail.push(format!(
                            "crop view smaller than DSO's: gains {gain:?} (monovo {m:?}, DSO {d:?})"
                        ));
                    }
                }
                // DSO's crop reaches past the fold of the distortion or out of
                // the image: no valid crop can contain it
                None => case.class.push_str(&format!(
                    " (DSO's own crop has {dso_invalid} invalid pixels)"
                )),
            }
            case.crop_gain = Some(gain);
        }
        (None, Some(_)) => {
            // monovo's valid crop was checked above; DSO gives up
            case.class = format!(
                "DSO exit(1): crop search fails after 500 rounds, {} {}",
                case.model, case.mode
            );
        }
        (_, None) => {}
    }
}

/// DSO exits: monovo refuses at the same line, or resizes `none` with a note.
fn check_dso_exit(
    case: &mut CameraCase,
    line: usize,
    why: &str,
    parsed: Result<CameraFile, CameraError>,
) {
    let fail = &mut case.failures;
    case.class = format!("DSO exit(1), line {line}: {why}");
    if why.starts_with("rectification mode none") {
        // monovo resizes (DESIGN.md), with a note that DSO refuses
        match parsed {
            Ok(f) => {
                let notes = output_notes(&f.input, f.input_size, &f.output, f.output_size);
                if !notes.iter().any(|n| n.contains("DSO refuses")) {
                    fail.push(format!("none with another size: notes {notes:?}"));
                }
                let map =
                    RectifyMap::for_mode(&f.input, f.input_size, &f.output, f.output_size).unwrap();
                if map.invalid_count() != 0 {
                    fail.push("resized none has invalid pixels".into());
                }
            }
            Err(e) => fail.push(format!("none with another size refused: {e}")),
        }
    } else {
        match parsed {
            Ok(f) => fail.push(format!("DSO refuses (line {line}), monovo reads {f:?}")),
            Err(e) if error_line(&e) != Some(line) => {
                fail.push(format!("refused at another line than DSO's {line}: {e}"))
            }
            Err(_) => {}
        }
    }
}

/// DSO aborts on `full`: monovo's full view contains its crop, or is refused as unbounded.
fn check_dso_abort(case: &mut CameraCase, why: &str, parsed: Result<CameraFile, CameraError>) {
    let fail = &mut case.failures;
    case.class = format!("DSO aborts: {why}");
    case.mode = "full";
    match parsed {
        Ok(f) => {
            case.model = f.input.name();
            let out = f.output_size;
            let crop = check_crop(&f, None, out, fail);
            match output_intrinsics(&f.input, f.input_size, &OutputMode::Full, out) {
                Ok(k) => {
                    let full = dso::rect_of_k([k.fx, k.fy, k.cx, k.cy], out.width, out.height);
                    if let Some(c) = crop {
                        let smaller =
                            full[0] > c[0] || full[1] < c[1] || full[2] > c[2] || full[3] < c[3];
                        if smaller {
                            fail.push(format!("full {full:?} does not contain crop {c:?}"));
                        }
                    }
                }
                Err(e @ CameraError::FullUnbounded { .. }) => {
                    case.class.push_str(&format!("; monovo refuses full: {e}"));
                }
                Err(e) => fail.push(format!("full: unexpected error {e}")),
            }
        }
        Err(e) => fail.push(format!("full file refused: {e}")),
    }
}

/// DSO crashes or is undefined: monovo reads what can be read, with a warning, or refuses at
/// the same line.
fn check_dso_crash(
    case: &mut CameraCase,
    line: usize,
    why: &str,
    parsed: Result<CameraFile, CameraError>,
    text: &str,
) {
    let fail = &mut case.failures;
    case.class = format!("DSO crash/UB, line {line}: {why}");
    match (line, parsed) {
        // 9+ numbers on a RadTan line: zero extras are a zero k3
        (1, Ok(f)) => {
            case.model = f.input.name();
            if f.warnings.is_empty() {
                fail.push("extra numbers read without a warning".into());
            }
            check_crop(&f, None, f.output_size, fail);
        }
        (1, Err(e)) => {
            let extra_nonzero = text.lines().next().is_some_and(|l| {
                l.split_whitespace()
                    .skip(8)
                    .any(|t| t.parse::<f64>().is_ok_and(|v| v != 0.0) || t.parse::<f64>().is_err())
            });
            if !extra_nonzero || error_line(&e) != Some(1) {
                fail.push(format!("refused although the extra numbers are 0: {e}"));
            }
        }
        // CRLF keyword, a 2-line file: monovo reads crop
        (3, Ok(f)) => {
            if f.output != OutputMode::Crop {
                fail.push(format!("line 3 read as {}", f.output));
            }
            check_crop(&f, None, f.output_size, fail);
        }
        (l, Err(e)) if error_line(&e) == Some(l) => {}
        (_, r) => fail.push(format!("DSO fails at line {line}; monovo gives {r:?}")),
    }
}

/// All camera files: DSO's verdict by the reference, monovo's reading checked against it.
#[test]
fn every_camera_file_is_read_as_dso_reads_it_or_better() {
    let files = fixtures("camera");
    assert!(files.len() >= 150, "{} camera files", files.len());
    let cases: Vec<CameraCase> = files.par_iter().map(|p| check_camera_file(p)).collect();

    let mut by_class: BTreeMap<String, usize> = BTreeMap::new();
    let mut worst_k: BTreeMap<(String, String), (f64, String)> = BTreeMap::new();
    let mut gains: BTreeMap<String, (f64, f64, f64, String)> = BTreeMap::new();
    let mut failures = Vec::new();
    for c in &cases {
        let class = c.class.split(" (").next().unwrap_or("").to_string();
        *by_class.entry(class).or_default() += 1;
        if matches!(c.mode, "none" | "explicit" | "crop") && c.class.starts_with("DSO reads") {
            let mode = if c.class.contains("invalid pixels") {
                "crop (DSO's crop has invalid pixels)".to_string()
            } else {
                c.mode.to_string()
            };
            let e = worst_k
                .entry((c.model.to_string(), mode))
                .or_insert((0.0, String::new()));
            if c.k_diff >= e.0 {
                *e = (c.k_diff, c.file.clone());
            }
        }
        if let Some(g) = c.crop_gain {
            let lo = g.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = g.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            let key = if c.class.contains("invalid pixels") {
                format!("{} (DSO's crop has invalid pixels)", c.model)
            } else {
                c.model.to_string()
            };
            let e =
                gains
                    .entry(key)
                    .or_insert((f64::INFINITY, f64::NEG_INFINITY, 0.0, String::new()));
            e.0 = e.0.min(lo);
            if hi > e.1 {
                e.1 = hi;
                e.3 = c.file.clone();
            }
            e.2 += 1.0;
        }
        for f in &c.failures {
            failures.push(format!("{}: {} [{}]", c.file, f, c.class));
        }
    }
    println!("camera files by DSO's verdict:");
    for (k, n) in &by_class {
        println!("  {n:4}  {k}");
    }
    println!("largest relative K difference to DSO's K (crop: monovo's exact sides vs DSO's 0.5% steps):");
    for ((m, mode), (d, f)) in &worst_k {
        println!("  {m:13} {mode:9} {d:.2e}  ({f})");
    }
    println!("crop: monovo's view minus DSO's, per side, relative (min .. max over files):");
    for (m, (lo, hi, n, f)) in &gains {
        println!(
            "  {m:13} {n:3} files: {:+.4}% .. {:+.3}%  (max: {f})",
            lo * 100.0,
            hi * 100.0
        );
    }

    // coverage: at least 60 files that DSO reads, every model and every output mode
    let read: Vec<&CameraCase> = cases.iter().filter(|c| !c.model.is_empty()).collect();
    assert!(read.len() >= 60, "only {} camera files read", read.len());
    for model in ["Pinhole", "FOV", "RadTan", "EquiDistant", "KannalaBrandt"] {
        assert!(read.iter().any(|c| c.model == model), "no {model} camera");
    }
    for mode in ["crop", "full", "none", "explicit"] {
        assert!(read.iter().any(|c| c.mode == mode), "no {mode} camera");
    }
    assert!(
        failures.is_empty(),
        "{} failures:\n{}",
        failures.len(),
        failures.join("\n")
    );
}

/// The DESIGN.md test vector (the monoVO camera) is among the real files: crop keeps the
/// authors' closed form.
#[test]
fn the_monovo_camera_keeps_the_closed_form_crop() {
    let p = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("fixtures/dso-family/camera/dso_ros_run__config__dso__camera.txt");
    let f = CameraFile::parse(&std::fs::read_to_string(p).unwrap()).unwrap();
    assert!(matches!(f.input, CameraModel::Fov { .. }));
    let k = output_intrinsics(
        &f.input,
        f.input_size,
        &OutputMode::Crop,
        ImageSize::new(640, 480),
    )
    .unwrap();
    for (got, want) in [
        (k.fx, 277.524),
        (k.fy, 291.680),
        (k.cx, 312.474),
        (k.cy, 240.036),
    ] {
        assert!((got - want).abs() < 1e-3, "{got} {want}");
    }
}

/// Every pcalib.txt: where DSO accepts it monovo reads the same values (DSO normalises to
/// 0..255 by `G[0]` and `G[last]`; monovo keeps the file's scale, equal after the same
/// normalisation to float precision); the two that are not strictly increasing are refused
/// by both, monovo naming the file and line 1. DSO applies a 65536-value table to 8-bit
/// frames through its first 256 entries (wrong); monovo by full range (`U(v * 257)`), and to
/// 16-bit frames exactly, as DM-VIO's `use16Bit` does.
#[test]
fn every_pcalib_is_read_as_dso_reads_it() {
    let files = fixtures("pcalib");
    assert_eq!(files.len(), 9);
    let mut failures = Vec::new();
    let (mut accepted, mut refused) = (0, 0);
    for p in &files {
        let file = name(p);
        let bytes = std::fs::read(p).unwrap();
        let dso = dso::read_pcalib(&bytes);
        let mono = photometric::InverseResponse::parse(&String::from_utf8(bytes).unwrap())
            .map_err(|e| format!("{}: {e}", p.display()));
        match (&dso, &mono) {
            (Ok(g), Ok(u)) => {
                accepted += 1;
                if u.table().len() != g.len() {
                    failures.push(format!(
                        "{file}: {} values, DSO {}",
                        u.table().len(),
                        g.len()
                    ));
                    continue;
                }
                let ng = dso::normalise_pcalib(g);
                let nu = dso::normalise_pcalib(u.table());
                let worst = ng
                    .iter()
                    .zip(&nu)
                    .map(|(a, b)| (a - b).abs())
                    .fold(0.0, f64::max);
                // DSO holds G in float: 255 * 2^-24 relative
                if worst > 1e-4 {
                    failures.push(format!(
                        "{file}: normalised U differs from DSO's G by {worst}"
                    ));
                }
                // exact at its own bit depth, as DSO/DM-VIO index G[pixel]
                if u.table_for_bits(u.bits()).unwrap() != u.table() {
                    failures.push(format!("{file}: not exact at its own bit depth"));
                }
                // 8-bit frames: the 256 values at full range
                let n = u.table().len();
                for v in [0usize, 1, 128, 255] {
                    if u.values()[v] != u.table()[v * (n - 1) / 255] {
                        failures.push(format!("{file}: U8({v}) is not the table at full range"));
                    }
                }
            }
            (Err(why), Err(msg)) => {
                refused += 1;
                let named = msg.contains(&file) && msg.contains("line 1:");
                if !(named && why.contains("increasing") && msg.contains("strictly increase")) {
                    failures.push(format!("{file}: DSO refuses ({why}), monovo says `{msg}`"));
                }
            }
            (d, m) => failures.push(format!("{file}: DSO {d:?}, monovo {m:?}")),
        }
    }
    println!("pcalib: {accepted} read like DSO, {refused} refused like DSO");
    assert_eq!((accepted, refused), (7, 2), "{failures:?}");
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// Every vignette.png: DSO takes a single-channel 16-bit PNG as it is, anything else through
/// OpenCV's conversion to 8-bit grey (grey+alpha: the grey; RGB: luma, which for equal
/// channels is that value), then `V = value / max`. monovo reads 8/16-bit grey, the grey of
/// grey+alpha and equal-channel RGB, and refuses real colour; its V equals DSO's exactly.
#[test]
fn every_vignette_is_read_as_dso_reads_it() {
    let files = fixtures("vignette");
    assert_eq!(files.len(), 8);
    let mut failures = Vec::new();
    let mut kinds = BTreeMap::new();
    for p in &files {
        let file = name(p);
        // the reference: decode the PNG's own samples and apply DSO's rule
        let img = image::open(p).unwrap();
        let kind = format!("{:?}", img.color());
        *kinds.entry(kind.clone()).or_insert(0) += 1;
        let (w, h) = (img.width() as usize, img.height() as usize);
        let dso_values: Option<Vec<f64>> = match &img {
            image::DynamicImage::ImageLuma16(i) => {
                Some(i.as_raw().iter().map(|v| *v as f64).collect())
            }
            image::DynamicImage::ImageLuma8(i) => {
                Some(i.as_raw().iter().map(|v| *v as f64).collect())
            }
            image::DynamicImage::ImageLumaA8(i) => {
                Some(i.as_raw().chunks(2).map(|c| c[0] as f64).collect())
            }
            image::DynamicImage::ImageRgb8(i) => {
                let equal = i.as_raw().chunks(3).all(|c| c[0] == c[1] && c[1] == c[2]);
                equal.then(|| i.as_raw().chunks(3).map(|c| c[0] as f64).collect())
            }
            other => panic!("{file}: no reference for {:?}", other.color()),
        };
        let mono = dataset_io::read_gray_map(p)
            .map_err(|e| e.to_string())
            .and_then(|(m, _)| photometric::Vignette::from_u16(&m).map_err(|e| e.to_string()));
        match (dso_values, mono) {
            (Some(d), Ok(v)) => {
                let max = d.iter().copied().fold(0.0, f64::max);
                let worst = d
                    .iter()
                    .zip(v.values().data())
                    .map(|(a, b)| (a / max - *b as f64).abs())
                    .fold(0.0, f64::max);
                if v.size() != (w, h) || worst > 1e-7 {
                    failures.push(format!("{file} ({kind}): V differs from DSO's by {worst}"));
                }
            }
            (None, Err(e)) if e.contains("must be grey") && e.contains(&file) => {
                *kinds.entry("refused colour".into()).or_insert(0) += 1;
            }
            (d, m) => failures.push(format!(
                "{file} ({kind}): reference {}, monovo {:?}",
                d.is_some(),
                m.map(|_| ())
            )),
        }
    }
    println!("vignette kinds: {kinds:?}");
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// Every times.txt: monovo reads the same timestamps and exposures as DSO (DSO's exposure is
/// a float). The one-column KITTI file (`1.037359e-01` per line) is garbage to DSO: `%d %lf`
/// reads `1` as the id and `.037359e-01` as the timestamp; monovo reads the numbers as
/// written, as timestamps, with a warning.
#[test]
fn every_times_file_is_read_as_dso_reads_it_or_better() {
    let files = fixtures("times");
    assert_eq!(files.len(), 6);
    let mut failures = Vec::new();
    for p in &files {
        let file = name(p);
        let bytes = std::fs::read(p).unwrap();
        let dso_rows = dso::read_times(&bytes);
        let mono = dataset_io::parse_times(&String::from_utf8(bytes.clone()).unwrap(), p);
        let lines = bytes
            .split(|b| *b == b'\n')
            .filter(|l| l.iter().any(|c| !c.is_ascii_whitespace()))
            .count();
        let one_column = std::str::from_utf8(&bytes)
            .unwrap()
            .lines()
            .all(|l| l.split_whitespace().count() <= 1);
        match mono {
            Ok(t) if one_column => {
                // monovo reads the timestamps as written
                let written: Vec<f64> = std::str::from_utf8(&bytes)
                    .unwrap()
                    .split_whitespace()
                    .map(|v| v.parse().unwrap())
                    .collect();
                let got: Vec<f64> = t.rows.iter().map(|r| r.timestamp).collect();
                let ok = t.rows.len() == lines
                    && got == written
                    && t.rows.iter().all(|r| r.exposure_ms.is_none())
                    && t.warnings.iter().any(|w| w.contains("one column"));
                if !ok {
                    failures.push(format!(
                        "{file}: one-column file read as {} rows",
                        t.rows.len()
                    ));
                }
                // DSO's garbage: the fraction after the integer part
                if dso_rows.len() != lines || dso_rows[1].0 == got[1] {
                    failures.push(format!(
                        "{file}: the reference does not show DSO's misreading"
                    ));
                }
            }
            Ok(t) => {
                if t.rows.len() != dso_rows.len() {
                    failures.push(format!(
                        "{file}: {} rows, DSO {}",
                        t.rows.len(),
                        dso_rows.len()
                    ));
                }
                for (r, (ts, e)) in t.rows.iter().zip(&dso_rows) {
                    let me = r.exposure_ms.unwrap_or(0.0);
                    if r.timestamp != *ts || (me - e).abs() > 1e-6 * e.max(1.0) {
                        failures.push(format!(
                            "{file}: row {} {} {me} vs DSO {ts} {e}",
                            r.id, r.timestamp
                        ));
                        break;
                    }
                }
            }
            Err(e) => failures.push(format!("{file}: refused: {e}")),
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// Every trajectory: evo's TUM and KITTI files, rpg_trajectory_evaluation's estimates (with
/// and without a `#` header, scientific timestamps) and DSO's result.txt (double blanks from
/// Eigen's padding, all-zero timestamps without times.txt) parse completely: one pose per
/// data line, the same numbers as a plain reading, unit quaternions; ground truths also parse
/// as such.
#[test]
fn every_trajectory_parses() {
    use eval_metrics::{detect_format, parse_kitti, parse_tum, GroundTruth, TrajectoryFormat};
    let files = fixtures("trajectory");
    assert!(files.len() >= 15);
    let mut failures = Vec::new();
    let mut formats = BTreeMap::new();
    for p in &files {
        let file = name(p);
        let text = std::fs::read_to_string(p).unwrap();
        let data: Vec<Vec<f64>> = text
            .lines()
            .filter(|l| !l.trim().is_empty() && !l.trim_start().starts_with('#'))
            .map(|l| l.split_whitespace().map(|t| t.parse().unwrap()).collect())
            .collect();
        let width = data[0].len();
        let format = detect_format(&text);
        *formats.entry(format!("{format:?}")).or_insert(0) += 1;
        let traj = match (width, format) {
            (8, TrajectoryFormat::Tum) => parse_tum(&text),
            (12, TrajectoryFormat::Kitti) => {
                let times: String = (0..data.len()).map(|i| format!("{i}\n")).collect();
                parse_kitti(&text, &times)
            }
            (w, f) => {
                failures.push(format!("{file}: {w} columns detected as {f:?}"));
                continue;
            }
        };
        let traj = match traj {
            Ok(t) => t,
            Err(e) => {
                failures.push(format!("{file}: {e}"));
                continue;
            }
        };
        if traj.poses.len() != data.len() {
            failures.push(format!(
                "{file}: {} poses for {} lines",
                traj.poses.len(),
                data.len()
            ));
        }
        for (pose, row) in traj.poses.iter().zip(&data) {
            let norm = pose.orientation.norm();
            let pos = if width == 8 {
                [row[1], row[2], row[3]]
            } else {
                [row[3], row[7], row[11]]
            };
            if pose.position != eval_metrics::nalgebra::Vector3::from(pos)
                || (norm - 1.0).abs() > 1e-3
                || !pose.is_finite()
            {
                failures.push(format!("{file}: pose {pose:?} vs line {row:?}"));
                break;
            }
        }
        if file.contains("_gt") || file.contains("groundtruth") {
            if let Err(e) = GroundTruth::parse(&text) {
                failures.push(format!("{file}: as ground truth: {e}"));
            }
        }
    }
    println!("trajectory formats: {formats:?}");
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// A UTF-8 byte-order mark and CRLF line ends change nothing in any real text file: camera,
/// pcalib, times and trajectories read the same with both added (DSO itself cannot read a
/// camera file or pcalib.txt that starts with a byte-order mark).
#[test]
fn byte_order_mark_and_crlf_change_nothing_in_any_real_file() {
    let variants = |t: &str| {
        let crlf = t.replace("\r\n", "\n").replace('\n', "\r\n");
        [
            format!("\u{feff}{t}"),
            crlf.clone(),
            format!("\u{feff}{crlf}"),
        ]
    };
    let mut checked = 0;
    for p in fixtures("camera") {
        let t = std::fs::read_to_string(&p).unwrap();
        let plain = CameraFile::parse(&t).map(|f| (f.input, f.input_size, f.output, f.output_size));
        for v in variants(&t) {
            let other =
                CameraFile::parse(&v).map(|f| (f.input, f.input_size, f.output, f.output_size));
            assert_eq!(plain, other, "{}", p.display());
            checked += 1;
        }
    }
    for p in fixtures("pcalib") {
        let t = std::fs::read_to_string(&p).unwrap();
        let plain = photometric::InverseResponse::parse(&t);
        for v in variants(&t) {
            assert_eq!(
                plain,
                photometric::InverseResponse::parse(&v),
                "{}",
                p.display()
            );
            checked += 1;
        }
    }
    for p in fixtures("times") {
        let t = std::fs::read_to_string(&p).unwrap();
        let plain = dataset_io::parse_times(&t, &p).unwrap().rows;
        for v in variants(&t) {
            assert_eq!(
                plain,
                dataset_io::parse_times(&v, &p).unwrap().rows,
                "{}",
                p.display()
            );
            checked += 1;
        }
    }
    for p in fixtures("trajectory") {
        let t = std::fs::read_to_string(&p).unwrap();
        if eval_metrics::detect_format(&t) != eval_metrics::TrajectoryFormat::Tum {
            continue;
        }
        let plain = eval_metrics::parse_tum(&t).unwrap();
        for v in variants(&t) {
            assert_eq!(
                plain,
                eval_metrics::parse_tum(&v).unwrap(),
                "{}",
                p.display()
            );
            checked += 1;
        }
    }
    assert!(checked > 500, "{checked}");
}
