//! The real-bracket stage of bench-synthetic: `monovo calib response` (the library with its
//! defaults, as the command runs it) predicts every exposure of the real brackets in
//! `tests/fixtures/brackets/` from the other exposures, by the protocol of
//! `xtask/peers/bracket_scores.py`, and is compared with the peers' scores committed beside
//! them (`peer_scores.json`: OpenCV's Debevec and Robertson, the authors' 2016 tool).
//!
//! For every distinct exposure `t_j`: `U` is calibrated on the frames of the other
//! exposures; every pixel's irradiance is merged from those frames, `B = sum t U(I) / sum t^2`
//! over their values in 1..254; the left-out values in 1..254 (of pixels with a merged `B`)
//! are predicted as `G(t_j B)`. `ls` is the pooled RMS error in grey levels, `tri` the same
//! with Debevec's triangle weights `min(z, 255 - z)` in the merge and on the errors, `ml` the
//! same as `ls` with `B` merged by least squares in grey levels (`min sum (I - G(t B))^2`,
//! Gauss-Newton from the `ls` value): the merge that suits each table.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use monovo_pipelines::calib::load_exposed_frames;
use monovo_pipelines::Silent;
use photometric::{calibrate_response, ResponseOptions};

use crate::Figure;

/// The folder of the fixtures.
fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures/brackets")
}

/// `G(e)`: the fractional code at which the table reaches `e` (clamped to 0..255).
fn inverse(u: &[f64], e: f64) -> f64 {
    if e <= u[0] {
        return 0.0;
    }
    let k = u.partition_point(|&v| v <= e);
    if k >= u.len() {
        return (u.len() - 1) as f64;
    }
    let (a, b) = (u[k - 1], u[k]);
    (k - 1) as f64 + if b > a { (e - a) / (b - a) } else { 0.0 }
}

/// `B` by least squares in grey levels over the pixel's training values `(t, I)`, by
/// [`GREY_MERGE_STEPS`] Gauss-Newton steps from `b` (each kept above a tenth of the last `B`),
/// through the non-decreasing table `m`.
fn grey_merge(m: &[f64], values: &[(f64, f64)], mut b: f64) -> f64 {
    let top = (m.len() - 1) as f64;
    for _ in 0..GREY_MERGE_STEPS {
        let (mut jr, mut jj) = (0.0, 0.0);
        for &(t, v) in values {
            let g = inverse(m, t * b);
            let j = (g.floor() as usize).min(m.len() - 2);
            let du = m[j + 1] - m[j];
            if g > 0.0 && g < top && du > 0.0 {
                let d = t / du;
                jr += d * (v - g);
                jj += d * d;
            }
        }
        if jj <= 0.0 {
            break;
        }
        b = (b + jr / jj).max(0.1 * b);
    }
    b
}

/// Gauss-Newton steps of the grey-level merge (as `bracket_scores.py`).
const GREY_MERGE_STEPS: usize = 8;

/// Pooled sums of one fold: (squared errors, count, weighted squared errors, weights, squared
/// errors through the grey-level merge).
#[allow(clippy::needless_range_loop)]
fn fold_sums(
    frames: &[&[u8]],
    times: &[f64],
    train: &[usize],
    test: &[usize],
    u: &[f64],
) -> [f64; 5] {
    let mut m = u.to_vec();
    for k in 1..m.len() {
        m[k] = m[k].max(m[k - 1]);
    }
    let ok = |v: u8| (1..=254).contains(&v);
    let hat = |v: u8| f64::from(v.min(255 - v));
    let mut out = [0.0; 5];
    let mut values = Vec::with_capacity(train.len());
    for p in 0..frames[0].len() {
        let (mut n_ls, mut d_ls, mut n_tri, mut d_tri) = (0.0, 0.0, 0.0, 0.0);
        values.clear();
        for &i in train {
            let v = frames[i][p];
            if ok(v) {
                let t = times[i];
                let uv = u[usize::from(v)];
                n_ls += t * uv;
                d_ls += t * t;
                n_tri += hat(v) * t * uv;
                d_tri += hat(v) * t * t;
                values.push((t, f64::from(v)));
            }
        }
        // no training value in 1..254: no merged B
        if values.is_empty() {
            continue;
        }
        let b_ml = grey_merge(&m, &values, n_ls / d_ls);
        for &j in test {
            let v = frames[j][p];
            if !ok(v) {
                continue;
            }
            let o = f64::from(v);
            let r_ls = o - inverse(&m, times[j] * n_ls / d_ls);
            out[0] += r_ls * r_ls;
            out[1] += 1.0;
            if d_tri > 0.0 {
                let r = o - inverse(&m, times[j] * n_tri / d_tri);
                out[2] += hat(v) * r * r;
            }
            out[3] += hat(v);
            let r_ml = o - inverse(&m, times[j] * b_ml);
            out[4] += r_ml * r_ml;
        }
    }
    out
}

/// monovo's `(ls, tri, ml)` on one bracket folder.
pub fn score(folder: &Path) -> Result<(f64, f64, f64)> {
    let seq = dataset_io::Sequence::open(folder).with_context(|| folder.display().to_string())?;
    let (frames, times) = load_exposed_frames(&seq, &Silent)?;
    // distinct exposures (relative tolerance 1e-6), each with its frames
    let mut order: Vec<usize> = (0..times.len()).collect();
    order.sort_by(|&a, &b| times[a].total_cmp(&times[b]));
    let mut groups: Vec<Vec<usize>> = Vec::new();
    for i in order {
        match groups.last_mut() {
            Some(g) if (times[i] / times[g[0]] - 1.0).abs() < 1e-6 => g.push(i),
            _ => groups.push(vec![i]),
        }
    }
    let data: Vec<&[u8]> = frames.iter().map(|f| f.data()).collect();
    let mut acc = [0.0; 5];
    for test in &groups {
        let train: Vec<usize> = (0..frames.len()).filter(|i| !test.contains(i)).collect();
        let mut sub: Vec<_> = train.iter().map(|&i| frames[i].clone()).collect();
        let t: Vec<f64> = train.iter().map(|&i| times[i]).collect();
        let cal = calibrate_response(&mut sub, &t, &ResponseOptions::default(), &|_, _| {})
            .with_context(|| {
                format!(
                    "{}: calibration without exposure {}",
                    folder.display(),
                    times[test[0]]
                )
            })?;
        let s = fold_sums(&data, &times, &train, test, cal.response.values());
        for k in 0..5 {
            acc[k] += s[k];
        }
    }
    Ok((
        (acc[0] / acc[1]).sqrt(),
        (acc[2] / acc[3]).sqrt(),
        (acc[4] / acc[1]).sqrt(),
    ))
}

/// The peers' `ls`, `tri` and `ml` of one set from `peer_scores.json`: the best of OpenCV's
/// two methods, and of every peer that ran; each score on its own (a peer without one still
/// counts for the others).
fn peers(json: &serde_json::Value, set: &str) -> Result<[(f64, f64, f64); 2]> {
    let methods = &json["sets"][set]["methods"];
    let best = |ms: &[&str], k: &str| {
        ms.iter()
            .filter_map(|m| methods[*m][k].as_f64())
            .fold(f64::INFINITY, f64::min)
    };
    let scores = |ms: &[&str]| (best(ms, "ls"), best(ms, "tri"), best(ms, "ml"));
    let opencv = scores(&["debevec", "robertson"]);
    let all = scores(&["debevec", "robertson", "tum2016"]);
    anyhow::ensure!(
        opencv.0.is_finite() && opencv.1.is_finite() && opencv.2.is_finite(),
        "peer_scores.json: no OpenCV ls, tri and ml scores for {set}"
    );
    Ok([opencv, all])
}

/// The stage: per set, monovo's `ls` over the best OpenCV score (threshold 1: at least as good)
/// and over the best of all peers; `tri` and `ml` over the best OpenCV score.
pub fn stage(_quick: bool) -> Result<Vec<Figure>> {
    let dir = fixtures();
    let path = dir.join("peer_scores.json");
    let json: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(&path).with_context(|| path.display().to_string())?,
    )
    .with_context(|| path.display().to_string())?;
    let mut sets: Vec<PathBuf> = std::fs::read_dir(&dir)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.join("times.txt").exists())
        .collect();
    sets.sort();
    let mut figures = Vec::new();
    for folder in sets {
        let name = folder
            .file_name()
            .and_then(|n| n.to_str())
            .unwrap_or("?")
            .to_string();
        let (ls, tri, ml) = score(&folder)?;
        let [opencv, all] = peers(&json, &name)?;
        println!(
            "brackets {name}: monovo ls {ls:.3} tri {tri:.3} ml {ml:.3}; best OpenCV ls {:.3} tri {:.3} ml {:.3}; best peer ls {:.3} tri {:.3} ml {:.3}",
            opencv.0, opencv.1, opencv.2, all.0, all.1, all.2
        );
        figures.push(Figure::lower(
            &format!("brackets.{name}.ls_over_opencv"),
            ls / opencv.0,
            "x",
        ));
        figures.push(Figure::lower(
            &format!("brackets.{name}.ls_over_peers"),
            ls / all.0,
            "x",
        ));
        figures.push(Figure::lower(
            &format!("brackets.{name}.tri_over_opencv"),
            tri / opencv.1,
            "x",
        ));
        figures.push(Figure::lower(
            &format!("brackets.{name}.ml_over_opencv"),
            ml / opencv.2,
            "x",
        ));
    }
    Ok(figures)
}
