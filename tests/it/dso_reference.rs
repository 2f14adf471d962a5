//! A small reference of how DSO (JakobEngel/dso 7b0c99f, `src/util/Undistort.cpp`) reads a
//! camera file and computes its output camera, written for this test from the rules in
//! prose (model selection by `sscanf` order, relative/absolute, the five projections,
//! `makeOptimalK_crop`'s search in 0.5 % steps, `none` and explicit K). It is deliberately
//! independent of camera-model: its own number scanner (C's `sscanf`/`strtod` semantics on
//! bytes, lines split on `\n` only so that a CR stays in the line as with `std::getline`),
//! its own distortion formulas in DSO's order of evaluation. DSO computes the distortion in
//! `float`; this reference uses `f64`, so a crop side may differ from a real DSO run by the
//! float rounding of one border test (relative 1e-6), which the test's tolerances cover.

/// DSO's distortion models with their parameters.
#[derive(Clone, Debug, PartialEq)]
pub enum Model {
    /// No distortion (legacy 5 numbers with omega == 0, or `Pinhole`).
    Pinhole,
    /// FOV with omega (any sign, as written).
    Fov(f64),
    /// `k1 k2 r1 r2`.
    RadTan([f64; 4]),
    /// `k1 k2 k3 k4`.
    EquiDistant([f64; 4]),
    /// `k0 k1 k2 k3`.
    KannalaBrandt([f64; 4]),
}

impl Model {
    pub fn name(&self) -> &'static str {
        match self {
            Model::Pinhole => "Pinhole",
            Model::Fov(_) => "FOV",
            Model::RadTan(_) => "RadTan",
            Model::EquiDistant(_) => "EquiDistant",
            Model::KannalaBrandt(_) => "KannalaBrandt",
        }
    }
}

/// The input camera in pixels (after DSO's relative conversion).
#[derive(Clone, Debug)]
pub struct Cam {
    pub model: Model,
    pub k: [f64; 4],
    pub w: usize,
    pub h: usize,
}

/// Line 3 as DSO understands it.
#[derive(Clone, Debug, PartialEq)]
pub enum Out {
    Crop,
    Full,
    None,
    /// The four relative values of an explicit pinhole (the 5th is read and ignored).
    Explicit([f64; 4]),
}

/// What DSO does with a camera file.
#[derive(Clone, Debug)]
pub enum Verdict {
    /// Reads it and rectifies to `out` at `ow x oh`.
    Ok {
        cam: Cam,
        out: Out,
        ow: usize,
        oh: usize,
        /// Lines after line 4 that are not blank (DSO never reads them).
        extra_lines: usize,
    },
    /// Prints a message and calls `exit(1)`; the 1-based line that causes it.
    Exit { line: usize, why: &'static str },
    /// `assert(false)` in `makeOptimalK_full`: abort in a default build.
    Abort { why: &'static str },
    /// Undefined behaviour, or an invalid undistorter that the reader dereferences
    /// (segfault); the 1-based line that causes it.
    Crash { line: usize, why: &'static str },
}

/// C's `strtod` on `s` after skipping white-space: the value and the bytes consumed, or
/// `None` when no number starts there (decimal forms, `inf`, `infinity`, `nan`).
fn strtod(s: &[u8]) -> Option<(f64, usize)> {
    let mut i = 0;
    while i < s.len() && (s[i].is_ascii_whitespace() || s[i] == 0x0b) {
        i += 1;
    }
    let start = i;
    if i < s.len() && (s[i] == b'+' || s[i] == b'-') {
        i += 1;
    }
    let lower: Vec<u8> = s[i..]
        .iter()
        .take(8)
        .map(|c| c.to_ascii_lowercase())
        .collect();
    for word in [&b"infinity"[..], b"inf", b"nan"] {
        if lower.starts_with(word) {
            let neg = s[start] == b'-';
            let v = if word == b"nan" {
                f64::NAN
            } else {
                f64::INFINITY
            };
            return Some((if neg { -v } else { v }, i + word.len()));
        }
    }
    let mut digits = 0;
    while i < s.len() && s[i].is_ascii_digit() {
        i += 1;
        digits += 1;
    }
    if i < s.len() && s[i] == b'.' {
        let mut j = i + 1;
        let mut frac = 0;
        while j < s.len() && s[j].is_ascii_digit() {
            j += 1;
            frac += 1;
        }
        if digits + frac > 0 {
            i = j;
            digits += frac;
        }
    }
    if digits == 0 {
        return None;
    }
    if i < s.len() && (s[i] == b'e' || s[i] == b'E') {
        let mut j = i + 1;
        if j < s.len() && (s[j] == b'+' || s[j] == b'-') {
            j += 1;
        }
        let e0 = j;
        while j < s.len() && s[j].is_ascii_digit() {
            j += 1;
        }
        if j > e0 {
            i = j;
        }
    }
    let text = std::str::from_utf8(&s[start..i]).ok()?;
    Some((text.parse().ok()?, i))
}

/// `sscanf(line, prefix + "%f %f ...")` with `max` conversions: the literal prefix must
/// match byte for byte (its trailing space matches any run of white-space), then numbers
/// are converted until one fails. Returns the converted values (their count is sscanf's
/// return value, EOF aside).
fn scan(line: &[u8], prefix: &str, max: usize) -> Vec<f64> {
    let name = prefix.trim_end().as_bytes();
    if !line.starts_with(name) {
        return Vec::new();
    }
    let mut rest = &line[name.len()..];
    let mut out = Vec::new();
    while out.len() < max {
        match strtod(rest) {
            Some((v, n)) => {
                out.push(v);
                rest = &rest[n..];
            }
            None => break,
        }
    }
    out
}

/// `sscanf(line, "%d %d")`: two integers (C's `strtol`, digits only after an optional sign).
fn scan_two_ints(line: &[u8]) -> Option<(i64, i64)> {
    let int = |s: &[u8]| -> Option<(i64, usize)> {
        let mut i = 0;
        while i < s.len() && s[i].is_ascii_whitespace() {
            i += 1;
        }
        let start = i;
        if i < s.len() && (s[i] == b'+' || s[i] == b'-') {
            i += 1;
        }
        let d0 = i;
        while i < s.len() && s[i].is_ascii_digit() {
            i += 1;
        }
        if i == d0 {
            return None;
        }
        Some((std::str::from_utf8(&s[start..i]).ok()?.parse().ok()?, i))
    };
    let (a, n) = int(line)?;
    let (b, _) = int(&line[n..])?;
    Some((a, b))
}

/// DSO's reading of a camera file (`getUndistorterForFile` then `readFromFile`).
pub fn read(bytes: &[u8]) -> Verdict {
    // std::getline: split on '\n' only; a CR stays at the end of the line
    let lines: Vec<&[u8]> = bytes.split(|b| *b == b'\n').collect();
    let line = |i: usize| -> &[u8] { lines.get(i).copied().unwrap_or(&[]) };
    let l1 = line(0);
    // model selection, in DSO's order, with float conversions ("%f")
    let (model_name, prefix, npars) = if scan(l1, "", 8).len() == 8 {
        ("RadTan", "", 8)
    } else if let Some(v) = Some(scan(l1, "", 5)).filter(|v| v.len() == 5) {
        if v[4] as f32 == 0.0 {
            ("Pinhole", "", 5)
        } else {
            ("FOV", "", 5)
        }
    } else if scan(l1, "KannalaBrandt ", 8).len() == 8 {
        ("KannalaBrandt", "KannalaBrandt ", 8)
    } else if scan(l1, "RadTan ", 8).len() == 8 {
        ("RadTan", "RadTan ", 8)
    } else if scan(l1, "EquiDistant ", 8).len() == 8 {
        ("EquiDistant", "EquiDistant ", 8)
    } else if scan(l1, "FOV ", 5).len() == 5 {
        ("FOV", "FOV ", 5)
    } else if scan(l1, "Pinhole ", 5).len() == 5 {
        ("Pinhole", "Pinhole ", 5)
    } else {
        return Verdict::Exit {
            line: 1,
            why: "could not read calib file: no model matches line 1",
        };
    };
    // readFromFile: "%lf" x5 for 5-parameter models, x10 into 8 targets for the others
    let p = scan(l1, prefix, if npars == 8 { 10 } else { 5 });
    if npars == 8 && p.len() > 8 {
        return Verdict::Crash {
            line: 1,
            why: "more than 8 numbers: sscanf writes through missing arguments (UB), then the file is invalid",
        };
    }
    let Some((w, h)) = scan_two_ints(line(1)) else {
        return Verdict::Crash {
            line: 2,
            why: "line 2 is not two integers: invalid undistorter, null dereference",
        };
    };
    let (w, h) = (w as usize, h as usize);
    let mut k = [p[0], p[1], p[2], p[3]];
    if k[2] < 1.0 && k[3] < 1.0 {
        k = [
            k[0] * w as f64,
            k[1] * h as f64,
            k[2] * w as f64 - 0.5,
            k[3] * h as f64 - 0.5,
        ];
    }
    let model = match model_name {
        "Pinhole" => Model::Pinhole,
        "FOV" => Model::Fov(p[4]),
        "RadTan" => Model::RadTan([p[4], p[5], p[6], p[7]]),
        "EquiDistant" => Model::EquiDistant([p[4], p[5], p[6], p[7]]),
        _ => Model::KannalaBrandt([p[4], p[5], p[6], p[7]]),
    };
    let l3 = line(2);
    let out = match l3 {
        b"crop" => Out::Crop,
        b"full" => Out::Full,
        b"none" => Out::None,
        _ => {
            let v = scan(l3, "", 5);
            if v.len() != 5 {
                return Verdict::Crash {
                    line: 3,
                    why: "line 3 is not exactly crop/full/none nor 5 numbers: invalid undistorter, null dereference",
                };
            }
            Out::Explicit([v[0], v[1], v[2], v[3]])
        }
    };
    let Some((ow, oh)) = scan_two_ints(line(3)) else {
        return Verdict::Crash {
            line: 4,
            why: "line 4 unreadable: continues with uninitialised output size (UB)",
        };
    };
    let (ow, oh) = (ow as usize, oh as usize);
    if out == Out::Full {
        return Verdict::Abort {
            why: "makeOptimalK_full is assert(false)",
        };
    }
    if out == Out::None && (ow, oh) != (w, h) {
        return Verdict::Exit {
            line: 4,
            why: "rectification mode none requires input and output dimensions to match",
        };
    }
    let extra_lines = lines
        .iter()
        .skip(4)
        .filter(|l| l.iter().any(|c| !c.is_ascii_whitespace()))
        .count();
    Verdict::Ok {
        cam: Cam { model, k, w, h },
        out,
        ow,
        oh,
        extra_lines,
    }
}

/// DSO's `distortCoordinates` for one normalised output direction: the raw pixel.
pub fn distort(cam: &Cam, u: f64, v: f64) -> (f64, f64) {
    let (ud, vd) = match &cam.model {
        Model::Pinhole => (u, v),
        Model::Fov(omega) => {
            let r = (u * u + v * v).sqrt();
            let fac = if r == 0.0 || *omega == 0.0 {
                1.0
            } else {
                (r * 2.0 * (omega / 2.0).tan()).atan() / (omega * r)
            };
            (fac * u, fac * v)
        }
        Model::RadTan([k1, k2, r1, r2]) => {
            let (x2, y2, xy) = (u * u, v * v, u * v);
            let rho2 = x2 + y2;
            let rad = k1 * rho2 + k2 * rho2 * rho2;
            (
                u + u * rad + 2.0 * r1 * xy + r2 * (rho2 + 2.0 * x2),
                v + v * rad + 2.0 * r2 * xy + r1 * (rho2 + 2.0 * y2),
            )
        }
        Model::EquiDistant([k1, k2, k3, k4]) => {
            let r = (u * u + v * v).sqrt();
            let th = r.atan();
            let (t2, t4, t6, t8) = (th * th, th.powi(4), th.powi(6), th.powi(8));
            let thd = th * (1.0 + k1 * t2 + k2 * t4 + k3 * t6 + k4 * t8);
            let s = if r > 1e-8 { thd / r } else { 1.0 };
            (s * u, s * v)
        }
        Model::KannalaBrandt([k0, k1, k2, k3]) => {
            let r = (u * u + v * v).sqrt();
            if r < 1e-6 {
                (u, v)
            } else {
                let th = r.atan2(1.0);
                let rd = th + k0 * th.powi(3) + k1 * th.powi(5) + k2 * th.powi(7) + k3 * th.powi(9);
                (rd / r * u, rd / r * v)
            }
        }
    };
    (cam.k[0] * ud + cam.k[2], cam.k[1] * vd + cam.k[3])
}

/// `makeOptimalK_crop`: the normalised rectangle `[min_x, max_x, min_y, max_y]` whose edges
/// land on the centres of the first and last output pixels, or `None` where DSO exits
/// ("FAILED TO COMPUTE GOOD CAMERA MATRIX").
pub fn crop_rect(cam: &Cam, ow: usize, oh: usize) -> Option<[f64; 4]> {
    let (wm1, hm1) = ((cam.w - 1) as f64, (cam.h - 1) as f64);
    let x_ok = |p: (f64, f64)| p.0 > 0.0 && p.0 < wm1;
    let y_ok = |p: (f64, f64)| p.1 > 0.0 && p.1 < hm1;
    let (mut min_x, mut max_x, mut min_y, mut max_y) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    for i in 0..100_000 {
        let t = (i as f64 - 50_000.0) / 10_000.0;
        if x_ok(distort(cam, t, 0.0)) {
            if min_x == 0.0 {
                min_x = t;
            }
            max_x = t;
        }
        if y_ok(distort(cam, 0.0, t)) {
            if min_y == 0.0 {
                min_y = t;
            }
            max_y = t;
        }
    }
    min_x *= 1.01;
    max_x *= 1.01;
    min_y *= 1.01;
    max_y *= 1.01;
    let mut iteration = 0;
    loop {
        let (mut left, mut right, mut top, mut bottom) = (false, false, false, false);
        for y in 0..oh {
            let yy = min_y + (max_y - min_y) * y as f64 / (oh as f64 - 1.0);
            left |= !x_ok(distort(cam, min_x, yy));
            right |= !x_ok(distort(cam, max_x, yy));
        }
        for x in 0..ow {
            let xx = min_x + (max_x - min_x) * x as f64 / (ow as f64 - 1.0);
            top |= !y_ok(distort(cam, xx, min_y));
            bottom |= !y_ok(distort(cam, xx, max_y));
        }
        if (left || right) && (top || bottom) {
            if max_x - min_x > max_y - min_y {
                top = false;
                bottom = false;
            } else {
                left = false;
                right = false;
            }
        }
        if left {
            min_x *= 0.995;
        }
        if right {
            max_x *= 0.995;
        }
        if top {
            min_y *= 0.995;
        }
        if bottom {
            max_y *= 0.995;
        }
        iteration += 1;
        if !(left || right || top || bottom) {
            return Some([min_x, max_x, min_y, max_y]);
        }
        if iteration > 500 {
            return None;
        }
    }
}

/// The output K `[fx, fy, cx, cy]` of a normalised rectangle (DSO's last step of the crop).
pub fn k_of_rect(r: [f64; 4], ow: usize, oh: usize) -> [f64; 4] {
    let fx = (ow as f64 - 1.0) / (r[1] - r[0]);
    let fy = (oh as f64 - 1.0) / (r[3] - r[2]);
    [fx, fy, -r[0] * fx, -r[2] * fy]
}

/// The normalised rectangle spanned by output pixel centres of a K.
pub fn rect_of_k(k: [f64; 4], ow: usize, oh: usize) -> [f64; 4] {
    [
        -k[2] / k[0],
        (ow as f64 - 1.0 - k[2]) / k[0],
        -k[3] / k[1],
        (oh as f64 - 1.0 - k[3]) / k[1],
    ]
}

/// DSO's output K for a camera that DSO reads (`crop`, `none`, explicit; `None` where
/// the crop search fails).
pub fn output_k(cam: &Cam, out: &Out, ow: usize, oh: usize) -> Option<[f64; 4]> {
    match out {
        Out::Crop => crop_rect(cam, ow, oh).map(|r| k_of_rect(r, ow, oh)),
        Out::None => Some(cam.k),
        Out::Explicit(v) => Some([
            v[0] * ow as f64,
            v[1] * oh as f64,
            v[2] * ow as f64 - 0.5,
            v[3] * oh as f64 - 0.5,
        ]),
        Out::Full => None,
    }
}

/// Output pixels of K whose raw source lies more than `tol` pixels outside
/// `[0, w-1] x [0, h-1]`.
pub fn invalid_pixels(cam: &Cam, k: [f64; 4], ow: usize, oh: usize, tol: f64) -> usize {
    let (wm1, hm1) = ((cam.w - 1) as f64 + tol, (cam.h - 1) as f64 + tol);
    let mut n = 0;
    for y in 0..oh {
        for x in 0..ow {
            let (u, v) = ((x as f64 - k[2]) / k[0], (y as f64 - k[3]) / k[1]);
            let p = distort(cam, u, v);
            if !(p.0 >= -tol && p.0 <= wm1 && p.1 >= -tol && p.1 <= hm1) {
                n += 1;
            }
        }
    }
    n
}

/// DSO's reading of pcalib.txt (`PhotometricUndistorter`): the floats at the start of line 1
/// (an `istream_iterator<float>`, which stops at the first character that does not continue
/// a number); valid when there are at least 256 and they strictly increase. Returns the
/// values, or why DSO refuses the file.
pub fn read_pcalib(bytes: &[u8]) -> Result<Vec<f64>, &'static str> {
    let line = bytes.split(|b| *b == b'\n').next().unwrap_or(&[]);
    let mut rest = line;
    let mut g = Vec::new();
    while let Some((v, n)) = strtod(rest).filter(|(v, _)| v.is_finite()) {
        g.push(v as f32 as f64);
        rest = &rest[n..];
    }
    if g.len() < 256 {
        return Err("fewer than 256 values in line 1");
    }
    if g.windows(2).any(|w| w[1] <= w[0]) {
        return Err("G invalid! it has to be strictly increasing");
    }
    Ok(g)
}

/// DSO's normalisation of a valid response: `255 (G - G[0]) / (G[last] - G[0])`.
pub fn normalise_pcalib(g: &[f64]) -> Vec<f64> {
    let (a, b) = (g[0], g[g.len() - 1]);
    g.iter().map(|v| 255.0 * (v - a) / (b - a)).collect()
}

/// DSO's reading of times.txt: per line `%d %lf %f` (3 conversions: timestamp and exposure)
/// or `%d %lf` (exposure 0); other lines are skipped. Returns (timestamp, exposure ms).
pub fn read_times(bytes: &[u8]) -> Vec<(f64, f64)> {
    let mut out = Vec::new();
    for line in bytes.split(|b| *b == b'\n') {
        // "%d": an integer (its value is unused)
        let mut i = 0;
        while i < line.len() && line[i].is_ascii_whitespace() {
            i += 1;
        }
        if i < line.len() && (line[i] == b'+' || line[i] == b'-') {
            i += 1;
        }
        let d0 = i;
        while i < line.len() && line[i].is_ascii_digit() {
            i += 1;
        }
        if i == d0 {
            continue;
        }
        let Some((t, n)) = strtod(&line[i..]) else {
            continue;
        };
        let e = strtod(&line[i + n..]).map_or(0.0, |(e, _)| e as f32 as f64);
        out.push((t, e));
    }
    out
}
