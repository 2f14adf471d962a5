//! Ground-truth photometric and geometric camera: a FOV lens, camera responses (the default
//! one is not a gamma curve), and a vignette that is not radially symmetric. The sensor noise
//! is in [`crate::sensor`].

use std::fmt;
use std::str::FromStr;

use crate::Rng;

/// The benchmark's narrow-lens camera in relative units (DESIGN.md test vector).
pub const DATASET_CAMERA_RELATIVE: [f64; 5] = [
    0.535719308086809,
    0.669566858850269,
    0.493248545285398,
    0.500408664348414,
    0.897966326944875,
];

/// The viewing rays of every pixel of a camera (at sub-pixel offsets), computed on first use
/// and kept: the renderers look up the same rays in every frame instead of unprojecting
/// them again (NaN where the camera has no ray).
#[derive(Clone, Default)]
pub(crate) struct RayCache(std::sync::OnceLock<Vec<[f64; 3]>>);

impl fmt::Debug for RayCache {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let n = self.0.get().map_or(0, Vec::len);
        write!(f, "RayCache({n} rays)")
    }
}

impl RayCache {
    /// The rays of pixel `(x, y)` at `offsets`, at `(y w + x) offsets.len() + k`.
    pub(crate) fn get(
        &self,
        camera: &FovCamera,
        (w, h): (usize, usize),
        offsets: &[(f64, f64)],
    ) -> &[[f64; 3]] {
        use rayon::prelude::*;
        self.0.get_or_init(|| {
            (0..w * h)
                .into_par_iter()
                .flat_map_iter(|i| {
                    offsets.iter().map(move |&(dx, dy)| {
                        camera
                            .unproject((i % w) as f64 + dx, (i / w) as f64 + dy)
                            .unwrap_or([f64::NAN; 3])
                    })
                })
                .collect()
        })
    }
}

/// A FOV camera in pixels for a `width x height` image, built from the relative dataset
/// camera (pixel centres at integers).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FovCamera {
    /// Focal length x (px).
    pub fx: f64,
    /// Focal length y (px).
    pub fy: f64,
    /// Principal point x (px).
    pub cx: f64,
    /// Principal point y (px).
    pub cy: f64,
    /// FOV parameter.
    pub omega: f64,
    /// Image width.
    pub width: usize,
    /// Image height.
    pub height: usize,
}

impl FovCamera {
    /// The dataset camera scaled to `width x height`.
    pub fn dataset(width: usize, height: usize) -> FovCamera {
        let r = DATASET_CAMERA_RELATIVE;
        FovCamera {
            fx: r[0] * width as f64,
            fy: r[1] * height as f64,
            cx: r[2] * width as f64 - 0.5,
            cy: r[3] * height as f64 - 0.5,
            omega: r[4],
            width,
            height,
        }
    }

    /// camera.txt text as the dataset's own files have it: line 1 the relative FOV camera as
    /// five bare numbers (no model name: the form DSO reads as FOV and the only one the
    /// authors' 2016 tools read), output `crop` at `out`.
    pub fn camera_txt(&self, out: (usize, usize)) -> String {
        self.camera_txt_with(out, "crop")
    }

    /// camera.txt text (as [`FovCamera::camera_txt`]) with the output camera `mode` (line 3:
    /// `crop`, `full`, `none` or a pinhole `fx fy cx cy 0`) at `out`.
    pub fn camera_txt_with(&self, out: (usize, usize), mode: &str) -> String {
        let (w, h) = (self.width as f64, self.height as f64);
        format!(
            "{} {} {} {} {}\n{} {}\n{mode}\n{} {}\n",
            self.fx / w,
            self.fy / h,
            (self.cx + 0.5) / w,
            (self.cy + 0.5) / h,
            self.omega,
            self.width,
            self.height,
            out.0,
            out.1
        )
    }

    /// Viewing ray (not normalised, z = 1) of pixel `(u, v)`; `None` beyond 90 degrees.
    pub fn unproject(&self, u: f64, v: f64) -> Option<[f64; 3]> {
        let (mx, my) = ((u - self.cx) / self.fx, (v - self.cy) / self.fy);
        let rd = (mx * mx + my * my).sqrt();
        if rd * self.omega >= std::f64::consts::FRAC_PI_2 {
            return None;
        }
        let f = if rd < 1e-12 {
            self.omega / (2.0 * (self.omega / 2.0).tan())
        } else {
            (rd * self.omega).tan() / (2.0 * rd * (self.omega / 2.0).tan())
        };
        Some([mx * f, my * f, 1.0])
    }

    /// Pixel of a point in the camera frame (`None` behind the camera).
    pub fn project(&self, p: [f64; 3]) -> Option<[f64; 2]> {
        if p[2] <= 1e-9 {
            return None;
        }
        let (x, y) = (p[0] / p[2], p[1] / p[2]);
        let ru = (x * x + y * y).sqrt();
        let f = if ru < 1e-12 {
            2.0 * (self.omega / 2.0).tan() / self.omega
        } else {
            (2.0 * ru * (self.omega / 2.0).tan()).atan() / (self.omega * ru)
        };
        Some([self.fx * f * x + self.cx, self.fy * f * y + self.cy])
    }
}

/// The ground-truth inverse response `U(0..255)` with `U(255) = 255`: a smooth, strictly
/// increasing curve that is not a gamma curve (a toe, a linear middle and a shoulder).
pub fn ground_truth_response() -> [f64; 256] {
    ResponseCurve::Dataset.table()
}

/// Inverse response curves of real kinds of cameras, for judging calibrations on more than
/// one shape. Each is smooth and strictly increasing with `U(0) = 0` and `U(255) = 255`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ResponseCurve {
    /// The default ground truth ([`ground_truth_response`]): a toe, a linear middle and a
    /// shoulder; not a gamma curve.
    Dataset,
    /// The sRGB transfer curve (a linear toe and a 2.4 power).
    Srgb,
    /// A log-encoding camera: `U(x) = ((1 + a)^x - 1) / a` with `a = 30` (strongly convex).
    Log,
    /// Linear up to 70% of the range, then a highlight knee that compresses the brightest
    /// third of the irradiances.
    Knee,
    /// A pure power `U(x) = x^gamma`.
    Gamma(f64),
    /// A real camera's or film's measured response: curve `i` (0 to [`DORF_CURVES`] - 1) of
    /// the subset of the DoRF database in `data/dorf.txt` (Grossberg and Nayar, "Modeling
    /// the space of camera response functions", PAMI 2004), ordered from expansive to
    /// strongly compressive.
    Dorf(u8),
}

/// How many DoRF curves [`ResponseCurve::Dorf`] offers.
pub const DORF_CURVES: usize = 16;

/// The DoRF subset: per curve the brightness at the irradiances `i / 1023`.
fn dorf_curves() -> &'static [Vec<f64>] {
    static CURVES: std::sync::OnceLock<Vec<Vec<f64>>> = std::sync::OnceLock::new();
    CURVES.get_or_init(|| {
        include_str!("../data/dorf.txt")
            .lines()
            .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
            .map(|l| {
                l.split_whitespace()
                    .skip(1)
                    .map(|v| v.parse::<f64>().unwrap_or(f64::NAN))
                    .collect()
            })
            .collect()
    })
}

/// The irradiance at which a sampled, strictly increasing brightness curve reaches `x`.
fn invert_sampled(b: &[f64], x: f64) -> f64 {
    let n = b.len();
    let k = b.partition_point(|&v| v < x).clamp(1, n - 1);
    let (b0, b1) = (b[k - 1], b[k]);
    let f = if b1 > b0 { (x - b0) / (b1 - b0) } else { 0.0 };
    ((k - 1) as f64 + f.clamp(0.0, 1.0)) / (n - 1) as f64
}

impl ResponseCurve {
    /// Every named curve (and a gamma of 1.8).
    pub const ALL: [ResponseCurve; 5] = [
        ResponseCurve::Dataset,
        ResponseCurve::Srgb,
        ResponseCurve::Log,
        ResponseCurve::Knee,
        ResponseCurve::Gamma(1.8),
    ];

    /// The normalised inverse response at `x` in `[0, 1]` (`U(0) = 0`, `U(1) = 1`).
    pub fn inverse(self, x: f64) -> f64 {
        let x = x.clamp(0.0, 1.0);
        let raw = |x: f64| match self {
            ResponseCurve::Dataset => {
                0.55 * x.powf(1.9)
                    + 0.3 * x
                    + 0.15 * (1.0 - (-3.0 * x).exp()) / (1.0 - (-3.0f64).exp())
            }
            ResponseCurve::Srgb => {
                if x <= 0.04045 {
                    x / 12.92
                } else {
                    ((x + 0.055) / 1.055).powf(2.4)
                }
            }
            ResponseCurve::Log => (31f64.powf(x) - 1.0) / 30.0,
            ResponseCurve::Knee => {
                let k = (x - 0.7).max(0.0);
                x + 2.2 * k * k
            }
            ResponseCurve::Gamma(g) => x.powf(g.max(0.05)),
            ResponseCurve::Dorf(i) => dorf_curves()
                .get(i as usize)
                .map_or(x, |b| invert_sampled(b, x)),
        };
        raw(x) / raw(1.0)
    }

    /// The table `U(0) .. U(2^bits - 1)` of a `bits`-bit sensor (1 to 16), scaled to
    /// `U(2^bits - 1) = 255`: the same curve at a finer step.
    pub fn table_bits(self, bits: u32) -> Vec<f64> {
        let top = ((1u32 << bits.clamp(1, 16)) - 1) as f64;
        (0..=top as u32)
            .map(|k| 255.0 * self.inverse(k as f64 / top))
            .collect()
    }

    /// The table `U(0) .. U(255)`, scaled to `U(255) = 255`.
    pub fn table(self) -> [f64; 256] {
        let mut u = [0.0; 256];
        for (k, v) in u.iter_mut().enumerate() {
            *v = 255.0 * self.inverse(k as f64 / 255.0);
        }
        u
    }

    /// The curve's name as used on command lines.
    pub fn name(self) -> String {
        match self {
            ResponseCurve::Dataset => "dataset".into(),
            ResponseCurve::Srgb => "srgb".into(),
            ResponseCurve::Log => "log".into(),
            ResponseCurve::Knee => "knee".into(),
            ResponseCurve::Gamma(g) => format!("gamma{g}"),
            ResponseCurve::Dorf(i) => format!("dorf{i}"),
        }
    }
}

impl fmt::Display for ResponseCurve {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.name())
    }
}

impl FromStr for ResponseCurve {
    type Err = String;

    /// `dataset`, `srgb`, `log`, `knee`, `gammaG` (for example `gamma2.2`) or `dorfN`.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let t = s.trim().to_ascii_lowercase();
        match t.as_str() {
            "dataset" => Ok(ResponseCurve::Dataset),
            "srgb" => Ok(ResponseCurve::Srgb),
            "log" => Ok(ResponseCurve::Log),
            "knee" => Ok(ResponseCurve::Knee),
            _ => match (
                t.strip_prefix("gamma").map(str::parse::<f64>),
                t.strip_prefix("dorf").map(str::parse::<u8>),
            ) {
                (Some(Ok(g)), _) if g.is_finite() && g > 0.05 && g < 20.0 => {
                    Ok(ResponseCurve::Gamma(g))
                }
                (_, Some(Ok(i))) if (i as usize) < DORF_CURVES => Ok(ResponseCurve::Dorf(i)),
                _ => Err(format!(
                    "unknown response curve `{}`: expected dataset, srgb, log, knee, gammaG (for example gamma2.2) or dorfN (a measured camera response, N from 0 to {})",
                    s.trim(),
                    DORF_CURVES - 1
                )),
            },
        }
    }
}

/// The camera response `G = U^-1` as a continuous value in `[0, n - 1]` for a table of `n`
/// values (`[0, 255]` for 8 bits; before noise and quantisation): linear interpolation of
/// the inverse of `u`.
pub fn response_value(u: &[f64], energy: f64) -> f64 {
    let top = u.len() - 1;
    if energy <= u[0] {
        return 0.0;
    }
    if energy >= u[top] {
        return top as f64;
    }
    let k = u.partition_point(|&x| x <= energy).clamp(1, top);
    let (a, b) = (u[k - 1], u[k]);
    (k - 1) as f64 + (energy - a) / (b - a)
}

/// [`response_value`] for many energies with the same table: an index of where the table
/// crosses evenly spaced energies narrows each search to a few entries (the same values as
/// [`response_value`], which searches all of the table: eight to sixteen unpredictable
/// branches per pixel).
pub struct ResponseLookup<'a> {
    u: &'a [f64],
    /// `bins[j]`: the number of table entries at most `u[0] + j / scale`.
    bins: Vec<u32>,
    scale: f64,
}

impl<'a> ResponseLookup<'a> {
    /// The index of the increasing table `u`.
    pub fn new(u: &'a [f64]) -> ResponseLookup<'a> {
        // at least 4096 bins: for an 8-bit table, 16 bins per entry on average, so that the
        // search below mostly looks at no entry or one (with one bin per entry, this search
        // took a third of the sensor model's time per pixel)
        let n = u.len().max(4096);
        let span = u[u.len() - 1] - u[0];
        let scale = if span > 0.0 && span.is_finite() {
            n as f64 / span
        } else {
            0.0
        };
        let bins = (0..=n + 1)
            .map(|j| {
                let e = u[0] + j as f64 / scale;
                u.partition_point(|&x| x <= e) as u32
            })
            .collect();
        ResponseLookup { u, bins, scale }
    }

    /// No index: every value searches the whole table (for a few values).
    pub fn plain(u: &'a [f64]) -> ResponseLookup<'a> {
        ResponseLookup {
            u,
            bins: Vec::new(),
            scale: 0.0,
        }
    }

    /// The largest grey value, `u.len() - 1`.
    pub fn top(&self) -> usize {
        self.u.len() - 1
    }

    /// [`response_value`]`(u, energy)`.
    #[inline]
    pub fn value(&self, energy: f64) -> f64 {
        let u = self.u;
        let top = u.len() - 1;
        if energy.is_nan() || self.scale == 0.0 {
            return response_value(u, energy);
        }
        if energy <= u[0] {
            return 0.0;
        }
        if energy >= u[top] {
            return top as f64;
        }
        // the entries at most `energy` are those below bins[j - 1] and some up to
        // bins[j + 2] (one bin either side for the rounding of j)
        let last = self.bins.len() - 1;
        let j = (((energy - u[0]) * self.scale) as usize).min(last);
        let (lo, hi) = (
            self.bins[j.saturating_sub(1)] as usize,
            self.bins[(j + 2).min(last)] as usize,
        );
        let k = (lo + u[lo..hi].partition_point(|&x| x <= energy)).clamp(1, top);
        let (a, b) = (u[k - 1], u[k]);
        (k - 1) as f64 + (energy - a) / (b - a)
    }
}

/// A ground-truth vignette at `width x height`, `max = 1`, not radially symmetric: an
/// off-centre radial fall-off of fourth order times a tilt.
pub fn ground_truth_vignette(width: usize, height: usize, seed: u64) -> Vec<f32> {
    let mut rng = Rng::derive(seed, 77);
    let (cx, cy) = (
        width as f64 * rng.range(0.46, 0.54),
        height as f64 * rng.range(0.45, 0.55),
    );
    let norm = (width as f64).hypot(height as f64) / 2.0;
    let (a, b) = (rng.range(0.35, 0.45), rng.range(0.1, 0.2));
    let (tx, ty) = (rng.range(-0.06, 0.06), rng.range(-0.06, 0.06));
    let mut v = Vec::with_capacity(width * height);
    for y in 0..height {
        for x in 0..width {
            let dx = (x as f64 - cx) / norm;
            let dy = (y as f64 - cy) / norm * 1.1;
            let r2 = dx * dx + dy * dy;
            let tilt = 1.0
                + tx * (x as f64 / width as f64 - 0.5) * 2.0
                + ty * (y as f64 / height as f64 - 0.5) * 2.0;
            v.push(((1.0 - a * r2 - b * r2 * r2) * tilt).max(0.05));
        }
    }
    let max = v.iter().copied().fold(0.0, f64::max);
    v.into_iter().map(|x| (x / max) as f32).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The indexed search gives the very values of the full one, at every bit depth and at
    /// the ends of the table.
    #[test]
    fn response_lookup_matches_response_value() {
        let mut rng = Rng::derive(5, 2);
        for (curve, bits) in [
            (ResponseCurve::Dataset, 8),
            (ResponseCurve::Dataset, 12),
            (ResponseCurve::Gamma(2.2), 10),
            (ResponseCurve::Gamma(2.2), 16),
        ] {
            let u = curve.table_bits(bits);
            let lookup = ResponseLookup::new(&u);
            let mut energies: Vec<f64> = (0..20_000).map(|_| rng.range(-5.0, 260.0)).collect();
            energies.extend(u.iter().copied());
            energies.extend([0.0, 255.0, f64::MIN_POSITIVE, f64::INFINITY]);
            for e in energies {
                let (a, b) = (lookup.value(e), response_value(&u, e));
                assert_eq!(a.to_bits(), b.to_bits(), "{curve:?} {bits} bits at {e}");
            }
            assert!(lookup.value(f64::NAN).is_nan());
        }
    }
}
