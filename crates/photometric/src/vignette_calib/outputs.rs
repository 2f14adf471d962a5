//! Outputs and uncertainty: the raw map, its standard errors, the defects, the smoothed
//! map and its error, from the solved problem.

use camera_model::{Image, ImageSize};

use super::problem::{Model, VSums};
use super::{VignetteCalibration, VignetteOptions};
use crate::smoothing::{choose_smoothing, Smoothed};
use crate::PhotometricError;

/// How the solver ended.
pub(super) struct Solved {
    pub(super) iterations: usize,
    pub(super) converged: bool,
    pub(super) change: Vec<f64>,
    /// Pixels outside the largest connected part (empty: all connected).
    pub(super) outside: Vec<bool>,
    pub(super) components: usize,
}

/// Normalisation, the odd/even maps, the uncertainty, the smoothing and the checks of the
/// result.
pub(super) fn finish(
    size: ImageSize,
    options: &VignetteOptions,
    model: Model,
    vs: VSums,
    solved: Solved,
    mut warnings: Vec<String>,
) -> Result<VignetteCalibration, PhotometricError> {
    let Solved {
        iterations,
        converged,
        change,
        outside,
        components,
    } = solved;
    let (w, h) = (size.width, size.height);
    let npx = w * h;
    let (valid, coverage) = valid_pixels(size, options, &vs, &outside, &mut warnings)?;
    let (raw, odd, even, raw_var) = raw_maps(&valid, &model.v, &vs);
    // what is left of the sums, and of the model, is a few numbers and the counts: the
    // per-pixel sums (and V, copied into `raw`) go before the smoothing
    let VSums {
        num,
        den,
        num_odd,
        den_odd,
        counts,
        res2,
        pred2,
        outliers,
        ..
    } = vs;
    drop((num, den, num_odd, den_odd));
    let noise = model.noise;
    drop(model);
    let choice = choose_smoothing(w, h, &raw, &raw_var, &odd, &even, options.smoothing_px)?;
    // scale: the recommended map's maximum is 1
    let max = choice
        .smoothed
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .fold(0.0f64, f64::max);
    if max.is_nan() || max <= 0.0 {
        return Err(PhotometricError::Calibration(
            "the smoothed vignette is zero everywhere; the data do not determine V".into(),
        ));
    }
    let norm_rel = normalisation_error(size, &choice, max);
    let smoothed_std: Vec<f64> = choice
        .smoothed
        .iter()
        .zip(&choice.smoothed_std)
        .map(|(v, s)| (s * s + (norm_rel * v).powi(2)).sqrt())
        .collect();
    let to_img = |v: &[f64], s: f64| -> Result<Image<f32>, PhotometricError> {
        Ok(Image::new(
            w,
            h,
            v.iter().map(|x| (x / s) as f32).collect(),
        )?)
    };
    let vignette = to_img(&choice.smoothed, max)?;
    let std_error = to_img(&smoothed_std, max)?;
    // the raw map leaves out what it cannot say: defective pixels (hot, dead) are NaN there
    // like pixels with too few observations
    let raw: Vec<f64> = (0..npx)
        .map(|i| {
            if choice.defective[i] {
                f64::NAN
            } else {
                raw[i]
            }
        })
        .collect();
    let (raw, raw_var) = sampled_as_2016((w, h), &raw, &raw_var);
    let raw_img = to_img(&raw, max)?;
    let raw_std: Vec<f64> = (0..npx)
        .map(|i| {
            if raw[i].is_finite() {
                (raw_var[i] + (norm_rel * raw[i]).powi(2)).sqrt()
            } else {
                f64::NAN
            }
        })
        .collect();
    let raw_std_error = to_img(&raw_std, max)?;
    let rms_relative = (res2 / pred2.max(1e-300)).sqrt();
    Ok(VignetteCalibration {
        vignette,
        raw: raw_img,
        std_error,
        raw_std_error,
        counts: Image::new(w, h, counts)?,
        coverage,
        smoothing: choice.choice,
        iterations,
        converged,
        change,
        rms_relative,
        noise,
        outliers,
        components,
        warnings,
    })
}

/// The pixels the raw map keeps: enough observations, observed, connected. Refused when none
/// is, or when an image corner never is; a warning when under 98% of the image is.
fn valid_pixels(
    size: ImageSize,
    options: &VignetteOptions,
    vs: &VSums,
    outside: &[bool],
    warnings: &mut Vec<String>,
) -> Result<(Vec<bool>, f64), PhotometricError> {
    let (w, h) = (size.width, size.height);
    let npx = w * h;
    let min_obs = options.min_observations.max(1);
    let valid: Vec<bool> = (0..npx)
        .map(|i| {
            vs.counts[i] >= min_obs && vs.den[i] > 0.0 && !outside.get(i).copied().unwrap_or(false)
        })
        .collect();
    let n_valid = valid.iter().filter(|v| **v).count();
    let coverage = n_valid as f64 / npx as f64;
    if n_valid == 0 {
        return Err(PhotometricError::Calibration(format!(
            "no pixel has {min_obs} observations of the plane; record the plane from more viewpoints"
        )));
    }
    // the corners: a corner the plane never covers cannot be calibrated
    let (cw, ch) = ((w / 20).max(1), (h / 20).max(1));
    for (name, x0, y0) in [
        ("top-left", 0, 0),
        ("top-right", w - cw, 0),
        ("bottom-left", 0, h - ch),
        ("bottom-right", w - cw, h - ch),
    ] {
        let any = (y0..y0 + ch).any(|y| (x0..x0 + cw).any(|x| valid[y * w + x]));
        if !any {
            return Err(PhotometricError::Calibration(format!(
                "the {name} corner of the image ({cw}x{ch} pixels) never sees the plane often enough ({min_obs} observations per pixel): the vignette there cannot be determined; film the wall so that it also fills that corner"
            )));
        }
    }
    if coverage < 0.98 {
        warnings.push(format!(
            "only {:.1}% of the pixels have at least {min_obs} observations; the recommended map fills the rest by smoothing",
            100.0 * coverage
        ));
    }
    Ok((valid, coverage))
}

/// The raw map, the maps of the odd and of the even frames, and the raw map's variance per
/// pixel from the normal equations (1 / sum w (tC)^2), with the scale of the residuals
/// checked against the odd/even difference. NaN where a pixel is not valid.
fn raw_maps(valid: &[bool], v: &[f64], vs: &VSums) -> (Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>) {
    let npx = valid.len();
    // per-pixel maps: the estimate, the odd and even frames' maps, and the information
    let raw: Vec<f64> = (0..npx)
        .map(|i| if valid[i] { v[i] } else { f64::NAN })
        .collect();
    let half = |num: &dyn Fn(usize) -> f64, den: &dyn Fn(usize) -> f64| -> Vec<f64> {
        (0..npx)
            .map(|i| {
                let d = den(i);
                if valid[i] && d > 0.0 {
                    num(i) / d
                } else {
                    f64::NAN
                }
            })
            .collect()
    };
    let odd = half(&|i| vs.num_odd[i], &|i| vs.den_odd[i]);
    let even = half(&|i| vs.num[i] - vs.num_odd[i], &|i| {
        vs.den[i] - vs.den_odd[i]
    });
    // variance of V per pixel from the normal equations (1 / sum w (tC)^2), with the scale
    // of the residuals checked against the odd/even difference
    let (info, info_odd) = (&vs.den, &vs.den_odd);
    let info_even: Vec<f64> = (0..npx).map(|i| vs.den[i] - vs.den_odd[i]).collect();
    let mut ratio_sum = 0.0;
    let mut ratio_n = 0usize;
    for i in 0..npx {
        if odd[i].is_finite() && even[i].is_finite() && info_odd[i] > 0.0 && info_even[i] > 0.0 {
            let d = odd[i] - even[i];
            ratio_sum += d * d / (1.0 / info_odd[i] + 1.0 / info_even[i]);
            ratio_n += 1;
        }
    }
    let kappa = if ratio_n > 100 {
        (ratio_sum / ratio_n as f64).max(1e-6)
    } else {
        1.0
    };
    let raw_var: Vec<f64> = (0..npx)
        .map(|i| if valid[i] { kappa / info[i] } else { f64::NAN })
        .collect();
    (raw, odd, even, raw_var)
}

/// The relative uncertainty of the normalisation: the maximum of a noisy map sits on a noise
/// excursion; the peak of a quadratic fitted around it says by how much, and that scale
/// uncertainty is common to every pixel.
fn normalisation_error(size: ImageSize, choice: &Smoothed, max: f64) -> f64 {
    let (w, h) = (size.width, size.height);
    let peak = fitted_peak(
        w,
        h,
        &choice.smoothed,
        &choice.smoothed_std,
        choice.choice.sigma_px,
    );
    match peak {
        Some((value, sd)) => ((max - value).powi(2) + sd * sd).sqrt() / max,
        None => 0.0,
    }
}

/// The peak of a quadratic surface fitted (weights `1 / sd^2`) to `map` within a disk around
/// its maximum, and the peak's standard error (the pixels of a map smoothed with
/// `sigma_px` share their noise over about `4 pi sigma^2` pixels): the maximum of the
/// underlying smooth map.
pub(super) fn fitted_peak(
    w: usize,
    h: usize,
    map: &[f64],
    sd: &[f64],
    sigma_px: f64,
) -> Option<(f64, f64)> {
    let (imax, _) = map.iter().enumerate().filter(|(_, v)| v.is_finite()).fold(
        (0usize, f64::NEG_INFINITY),
        |b, (i, &v)| if v > b.1 { (i, v) } else { b },
    );
    let (cx, cy) = ((imax % w) as f64, (imax / w) as f64);
    let r = (w.min(h) as f64 / 10.0).max(6.0);
    let mut ata = nalgebra::SMatrix::<f64, 6, 6>::zeros();
    let mut atb = nalgebra::SVector::<f64, 6>::zeros();
    let (x0, x1) = ((cx - r).max(0.0) as usize, ((cx + r) as usize).min(w - 1));
    let (y0, y1) = ((cy - r).max(0.0) as usize, ((cy + r) as usize).min(h - 1));
    for y in y0..=y1 {
        for x in x0..=x1 {
            let (dx, dy) = ((x as f64 - cx) / r, (y as f64 - cy) / r);
            let i = y * w + x;
            if dx * dx + dy * dy > 1.0 || !map[i].is_finite() || sd[i].is_nan() || sd[i] <= 0.0 {
                continue;
            }
            let f = nalgebra::SVector::<f64, 6>::from([1.0, dx, dy, dx * dx, dx * dy, dy * dy]);
            let wt = 1.0 / (sd[i] * sd[i]);
            ata += f * f.transpose() * wt;
            atb += f * (wt * map[i]);
        }
    }
    let inv = ata.try_inverse()?;
    let c = inv * atb;
    // the vertex of the quadratic, kept inside the disk
    let hm = nalgebra::Matrix2::new(2.0 * c[3], c[4], c[4], 2.0 * c[5]);
    let g = nalgebra::Vector2::new(-c[1], -c[2]);
    let mut v = hm
        .try_inverse()
        .map_or(nalgebra::Vector2::zeros(), |hi| hi * g);
    if v.norm() > 1.0 {
        v /= v.norm();
    }
    let f =
        nalgebra::SVector::<f64, 6>::from([1.0, v[0], v[1], v[0] * v[0], v[0] * v[1], v[1] * v[1]]);
    let value = (f.transpose() * c)[(0, 0)];
    // the fit's variance, scaled by the neighbours' correlation (the smoothed map's pixels
    // are not independent: about the kernel's area shares one noise)
    let area = (4.0 * std::f64::consts::PI * sigma_px * sigma_px).max(1.0);
    let var = (f.transpose() * inv * f)[(0, 0)] * area;
    (value.is_finite() && var >= 0.0).then_some((value, var.sqrt()))
}

/// The weights of a pixel's own estimate and of each neighbour's, per direction, in the map
/// the authors' 2016 tool writes as its raw one: it reads the image bilinearly at a plane
/// point's position and adds the observation bilinearly to the four pixels around it, so
/// that over positions spread evenly between pixels a pixel's data enter its own value with
/// weight `E[(1-f)^2] + E[f^2] = 2/3` and each neighbour's with `E[f (1-f)] = 1/6`.
pub(super) const SAMPLING_2016: [f64; 3] = [1.0 / 6.0, 2.0 / 3.0, 1.0 / 6.0];

/// The per-pixel map `raw` (variance `var`; NaN where a pixel is not valid) sampled as the
/// 2016 tool samples its raw map: filtered with [`SAMPLING_2016`] in x and then in y, and the
/// variance carried through (the pixels' estimates are independent). A pixel that is not
/// valid stays NaN; where a neighbour along a direction is missing (the image's border, a
/// pixel that is not valid) the pixel keeps its own value along that direction: a one-sided
/// filter would shift it by a sixth of the map's slope, several standard errors where a small
/// image's vignette is steep.
pub(super) fn sampled_as_2016(
    (w, h): (usize, usize),
    raw: &[f64],
    var: &[f64],
) -> (Vec<f64>, Vec<f64>) {
    let [side, centre, _] = SAMPLING_2016;
    let pass = |v: &[f64], s2: &[f64], step: usize, len: usize, at: &dyn Fn(usize) -> usize| {
        let mut out = v.to_vec();
        let mut out_var = s2.to_vec();
        for i in 0..v.len() {
            if !v[i].is_finite() {
                out_var[i] = f64::NAN;
                continue;
            }
            let pos = at(i);
            if pos == 0 || pos + 1 >= len {
                continue;
            }
            let (a, b) = (i - step, i + step);
            if v[a].is_finite() && v[b].is_finite() {
                out[i] = side * (v[a] + v[b]) + centre * v[i];
                out_var[i] = side * side * (s2[a] + s2[b]) + centre * centre * s2[i];
            }
        }
        (out, out_var)
    };
    let (x, x_var) = pass(raw, var, 1, w, &|i| i % w);
    pass(&x, &x_var, w, h, &|i| i / w)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Independent errors through the 2016 tool's sampling: a constant map stays constant,
    /// an invalid pixel stays invalid and its neighbours keep their own values along the
    /// direction where it lies, a linear map stays as it is (the border too), the variance of white
    /// noise falls to `(1/36 + 4/9 + 1/36)^2 = 1/4` inside the image, and the errors of
    /// neighbours correlate by `(2 * 1/6 * 2/3) / (1/2) = 4/9` (the 2016 tool's raw maps:
    /// 0.40-0.41 after the high-pass of `xtask/peers/vignette_vs_2016.py`).
    #[test]
    fn the_2016_sampling_quarters_white_noise_and_keeps_holes() {
        let (w, h) = (200, 150);
        let mut state = 0x2545_f491_4f6c_dd1d_u64;
        let mut noise = || {
            // xorshift, then the sum of 12 uniforms less 6: about a standard normal
            (0..12)
                .map(|_| {
                    state ^= state << 13;
                    state ^= state >> 7;
                    state ^= state << 17;
                    (state >> 11) as f64 / (1u64 << 53) as f64
                })
                .sum::<f64>()
                - 6.0
        };
        let sd = 0.01;
        let mut raw: Vec<f64> = (0..w * h).map(|_| 1.0 + sd * noise()).collect();
        raw[75 * w + 100] = f64::NAN;
        let var = vec![sd * sd; w * h];
        let (out, out_var) = sampled_as_2016((w, h), &raw, &var);
        assert!(out[75 * w + 100].is_nan() && out_var[75 * w + 100].is_nan());
        assert!(out[75 * w + 101].is_finite());
        let (flat, _) = sampled_as_2016((w, h), &vec![0.5; w * h], &var);
        assert!(flat.iter().all(|v| (v - 0.5).abs() < 1e-15));
        let slope: Vec<f64> = (0..w * h)
            .map(|i| 0.5 + 1e-3 * (i % w) as f64 - 2e-3 * (i / w) as f64)
            .collect();
        let (linear, _) = sampled_as_2016((w, h), &slope, &var);
        assert!(linear
            .iter()
            .zip(&slope)
            .all(|(a, b)| (a - b).abs() < 1e-12));
        // beside the hole, along x: its own value in x; its neighbours in y filtered in x
        let j = 75 * w + 101;
        let [sd6, c] = [SAMPLING_2016[0], SAMPLING_2016[1]];
        let x_of = |k: usize| sd6 * (raw[k - 1] + raw[k + 1]) + c * raw[k];
        let expected = sd6 * (x_of(j - w) + x_of(j + w)) + c * raw[j];
        assert!((out[j] - expected).abs() < 1e-12, "{} {expected}", out[j]);
        let inner: Vec<usize> = (0..w * h)
            .filter(|i| (2..w - 2).contains(&(i % w)) && (2..h - 2).contains(&(i / w)))
            .filter(|i| out[*i].is_finite() && out[i + 1].is_finite())
            .collect();
        let n = inner.len() as f64;
        let var_out = inner.iter().map(|&i| (out[i] - 1.0).powi(2)).sum::<f64>() / n;
        assert!(
            (var_out / (sd * sd) - 0.25).abs() < 0.02,
            "{}",
            var_out / (sd * sd)
        );
        let corr = inner
            .iter()
            .map(|&i| (out[i] - 1.0) * (out[i + 1] - 1.0))
            .sum::<f64>()
            / n
            / var_out;
        assert!((corr - 4.0 / 9.0).abs() < 0.03, "{corr}");
        // the carried variance says the same
        let predicted = out_var[75 * w + 20] / (sd * sd);
        assert!((predicted - 0.25).abs() < 1e-12, "{predicted}");
    }
}
