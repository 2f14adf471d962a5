//! The inverse camera response `U = G^-1` and its pcalib.txt format: one line of 256 numbers,
//! `U(0) .. U(255)`, finite and strictly increasing.

use crate::PhotometricError;

/// The inverse response `U`: grey value to (relative) irradiance times exposure.
#[derive(Clone, Debug, PartialEq)]
pub struct InverseResponse {
    u: [f64; 256],
}

impl InverseResponse {
    /// Validates 256 values: finite and strictly increasing.
    pub fn new(u: [f64; 256]) -> Result<InverseResponse, PhotometricError> {
        for (i, &v) in u.iter().enumerate() {
            if !v.is_finite() {
                return Err(PhotometricError::NotFinite { index: i, value: v });
            }
            if i > 0 && v <= u[i - 1] {
                return Err(PhotometricError::NotIncreasing {
                    index: i,
                    value: v,
                    previous: u[i - 1],
                });
            }
        }
        Ok(InverseResponse { u })
    }

    /// The linear response `U(k) = k`.
    pub fn linear() -> InverseResponse {
        let mut u = [0.0; 256];
        for (k, v) in u.iter_mut().enumerate() {
            *v = k as f64;
        }
        InverseResponse { u }
    }

    /// Parses pcalib.txt: 256 numbers (whitespace separated, usually on one line).
    pub fn parse(text: &str) -> Result<InverseResponse, PhotometricError> {
        let mut u = [0.0; 256];
        let mut n = 0;
        let mut last_line = 1;
        for (i, line) in text.lines().enumerate() {
            for tok in line.split_whitespace() {
                last_line = i + 1;
                let v = tok.parse::<f64>().map_err(|_| PhotometricError::Parse {
                    line: i + 1,
                    expected: "256 numbers U(0) .. U(255)",
                    found: tok.chars().take(40).collect(),
                })?;
                if n >= 256 {
                    return Err(PhotometricError::Parse {
                        line: i + 1,
                        expected: "exactly 256 numbers, found more",
                        found: tok.chars().take(40).collect(),
                    });
                }
                u[n] = v;
                n += 1;
            }
        }
        if n != 256 {
            return Err(PhotometricError::Parse {
                line: last_line,
                expected: "256 numbers U(0) .. U(255)",
                found: format!("{n} numbers"),
            });
        }
        InverseResponse::new(u)
    }

    /// pcalib.txt text: one line of 256 numbers at full precision.
    pub fn to_text(&self) -> String {
        let parts: Vec<String> = self.u.iter().map(|v| format!("{v}")).collect();
        format!("{}\n", parts.join(" "))
    }

    /// The values `U(0) .. U(255)`.
    pub fn values(&self) -> &[f64; 256] {
        &self.u
    }

    /// `U(k)`.
    #[inline]
    pub fn get(&self, k: u8) -> f64 {
        self.u[k as usize]
    }

    /// The values as an `f32` lookup table.
    pub fn lut(&self) -> [f32; 256] {
        self.u.map(|v| v as f32)
    }

    /// Differences to a reference table over the grey values 0..254: the largest absolute
    /// difference with both as given (normally both scaled to `U(255) = 255`), and the RMS
    /// difference after the least-squares scale of `self` (`U` is only defined up to scale).
    pub fn errors_against(&self, reference: &[f64; 256]) -> (f64, f64) {
        let u = &self.u;
        let max = (0..255)
            .map(|k| (u[k] - reference[k]).abs())
            .fold(0.0, f64::max);
        let num: f64 = (0..255).map(|k| u[k] * reference[k]).sum();
        let den: f64 = (0..255).map(|k| u[k] * u[k]).sum();
        let s = if den > 0.0 { num / den } else { 1.0 };
        let rms = ((0..255)
            .map(|k| (s * u[k] - reference[k]).powi(2))
            .sum::<f64>()
            / 255.0)
            .sqrt();
        (max, rms)
    }

    /// The same response scaled so that `U(255) = 255`.
    pub fn normalized(&self) -> InverseResponse {
        let s = 255.0 / self.u[255];
        InverseResponse {
            u: self.u.map(|v| v * s),
        }
    }
}
