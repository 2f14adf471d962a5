//! The inverse camera response `U = G^-1` and its pcalib.txt format: one line of `2^k`
//! numbers (256 for 8-bit images, 65536 for 16-bit images, any `k` from 8 to 16),
//! `U(0) .. U(2^k - 1)`, finite and strictly increasing.
//!
//! **Bit depths.** A table of `2^k` values is indexed by raw pixel values of `k` bits, as
//! DSO and DM-VIO index it (`G[pixel]`). For frames of another bit depth `b` the pixel value
//! `v` is placed on the table's scale by full range, `x = v (2^k - 1) / (2^b - 1)` (0 on 0,
//! white on white, like the usual 8-to-16-bit conversion `v * 257`), and `U` is interpolated
//! linearly between the two neighbouring entries; when `b == k` the lookup is exact.
//! A 12-bit sensor stored in the low 12 bits of a 16-bit PNG therefore has bit depth 12.
//!
//! **Tables that end at the saturation value.** The 16-bit forks of the authors' tools write
//! `saturation value + 1` numbers (4001 for a 12-bit sensor that saturates at 4000) and
//! index them with the raw value. A table of more than 512 values whose length is not a
//! power of two is read that way: its bit depth is the next power of two's (12 for 4001),
//! the values above the saturation value take `U` of it, and [`InverseResponse::to_text`]
//! writes it back with as many values as it was given.

use crate::PhotometricError;

/// The inverse response `U`: grey value to (relative) irradiance times exposure.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct InverseResponse {
    /// `2^k` values, `k` in 8..=16 (a shorter table from a file continued with its last
    /// value, see [`InverseResponse::saturation_value`]).
    table: Vec<f64>,
    /// How many of them the file gave (`2^k`, or the saturation value + 1).
    #[serde(skip)]
    given: usize,
    /// The table at the 256 grey values of 8-bit frames (the table itself when `k == 8`).
    #[serde(skip)]
    u8_table: [f64; 256],
}

/// `U` at the full-range position of sample `v` of a `bits`-bit frame.
fn sample(table: &[f64], v: u32, bits: u32) -> f64 {
    let n = table.len() as u64;
    let max_in = (1u64 << bits) - 1;
    // exact rational position v (n - 1) / max_in
    let num = v as u64 * (n - 1);
    let i = (num / max_in) as usize;
    let rem = num % max_in;
    if rem == 0 || i + 1 >= table.len() {
        table[i.min(table.len() - 1)]
    } else {
        let t = rem as f64 / max_in as f64;
        table[i] + t * (table[i + 1] - table[i])
    }
}

/// Whether a table of `n` values can be read: `2^k` values (`k` from 8 to 16), or more than
/// 512 (a sensor of 10 bits and more) ending at the saturation value.
fn acceptable_len(n: usize) -> bool {
    (n.is_power_of_two() && (256..=65536).contains(&n)) || (513..=65536).contains(&n)
}

impl InverseResponse {
    /// Validates 256 values: finite and strictly increasing.
    pub fn new(u: [f64; 256]) -> Result<InverseResponse, PhotometricError> {
        InverseResponse::from_values(u.to_vec())
    }

    /// Validates `2^k` values (`k` from 8 to 16), or more than 512 values that end at the
    /// saturation value (see [`InverseResponse::saturation_value`]): finite and strictly
    /// increasing.
    pub fn from_values(values: Vec<f64>) -> Result<InverseResponse, PhotometricError> {
        InverseResponse::checked(values, |_| 0)
    }

    fn checked(
        table: Vec<f64>,
        line_of: impl Fn(usize) -> usize,
    ) -> Result<InverseResponse, PhotometricError> {
        let n = table.len();
        if !acceptable_len(n) {
            return Err(PhotometricError::ValueCount {
                line: line_of(n.saturating_sub(1)),
                found: n,
            });
        }
        for (i, &v) in table.iter().enumerate() {
            if !v.is_finite() {
                return Err(PhotometricError::NotFinite {
                    index: i,
                    value: v,
                    line: line_of(i),
                });
            }
            if i > 0 && v <= table[i - 1] {
                return Err(PhotometricError::NotIncreasing {
                    index: i,
                    value: v,
                    previous: table[i - 1],
                    line: line_of(i),
                });
            }
        }
        // a table that ends at the saturation value: the values above it are saturated
        let mut table = table;
        let last = table[n - 1];
        table.resize(n.next_power_of_two(), last);
        let mut u8_table = [0.0; 256];
        for (v, u) in u8_table.iter_mut().enumerate() {
            *u = sample(&table, v as u32, 8);
        }
        Ok(InverseResponse {
            table,
            given: n,
            u8_table,
        })
    }

    /// The linear response `U(k) = k` of 8-bit images.
    pub fn linear() -> InverseResponse {
        let mut u = [0.0; 256];
        for (k, v) in u.iter_mut().enumerate() {
            *v = k as f64;
        }
        InverseResponse {
            table: u.to_vec(),
            given: 256,
            u8_table: u,
        }
    }

    /// Parses pcalib.txt (see [`InverseResponse::parse_with_notes`]).
    pub fn parse(text: &str) -> Result<InverseResponse, PhotometricError> {
        InverseResponse::parse_with_notes(text).map(|(u, _)| u)
    }

    /// Parses pcalib.txt: `2^k` numbers, normally on one line as DSO reads them. A UTF-8
    /// byte-order mark and CRLF are fine; values may continue on further lines; once `2^k`
    /// values are read, a word that is not a number ends the data (DSO reads only line 1, so
    /// a second line like `vis_exponent: 1.0` is ignored, as by DSO). Returns the notes about
    /// what was read differently from a plain one-line file.
    pub fn parse_with_notes(
        text: &str,
    ) -> Result<(InverseResponse, Vec<String>), PhotometricError> {
        let mut notes = Vec::new();
        let text = match text.strip_prefix('\u{feff}') {
            Some(t) => {
                notes.push(
                    "line 1: a UTF-8 byte-order mark starts the file; monovo skips it, DSO cannot read such a file"
                        .to_string(),
                );
                t
            }
            None => text,
        };
        let mut values: Vec<f64> = Vec::with_capacity(256);
        let mut lines_of: Vec<usize> = Vec::with_capacity(256);
        let complete = |n: usize| n.is_power_of_two() && (256..=65536).contains(&n);
        'lines: for (i, line) in text.lines().enumerate() {
            let no = i + 1;
            for tok in line.split_whitespace() {
                match tok.parse::<f64>() {
                    Ok(v) => {
                        values.push(v);
                        lines_of.push(no);
                    }
                    Err(_) => {
                        let b = tok.as_bytes();
                        let comma = b.iter().position(|c| *c == b',');
                        let decimal_comma = comma.is_some_and(|p| {
                            p > 0
                                && b[p - 1].is_ascii_digit()
                                && b.get(p + 1).is_some_and(|c| c.is_ascii_digit())
                        });
                        if decimal_comma {
                            return Err(PhotometricError::DecimalComma {
                                line: no,
                                token: tok.chars().take(40).collect(),
                            });
                        }
                        if complete(values.len()) {
                            notes.push(format!(
                                "line {no}: `{}` and everything after it is ignored (not a number; DSO reads only the numbers at the start of line 1)",
                                tok.chars().take(40).collect::<String>()
                            ));
                            break 'lines;
                        }
                        return Err(PhotometricError::Parse {
                            line: no,
                            expected: "numbers U(0) .. U(2^k - 1) (256 values for 8-bit images, 65536 for 16-bit)",
                            found: tok.chars().take(40).collect(),
                        });
                    }
                }
            }
        }
        let last_line = lines_of.last().copied().unwrap_or(1);
        if last_line > 1 {
            notes.push(format!(
                "the values span lines 1-{last_line}; DSO reads only line 1 and would refuse this file"
            ));
        }
        let u =
            InverseResponse::checked(values, |i| lines_of.get(i).copied().unwrap_or(last_line))?;
        if !u.given.is_power_of_two() {
            notes.push(format!(
                "{} values: read as a {}-bit table that ends at the saturation value {} (as the 16-bit forks of the authors' tools write it); the values above it are saturated and take U({})",
                u.given,
                u.bits(),
                u.given - 1,
                u.given - 1
            ));
        }
        Ok((u, notes))
    }

    /// pcalib.txt text: one line of all `2^k` numbers (or as many as were read, for a table
    /// that ends at the saturation value) at full precision.
    pub fn to_text(&self) -> String {
        let parts: Vec<String> = self.table[..self.given]
            .iter()
            .map(|v| format!("{v}"))
            .collect();
        format!("{}\n", parts.join(" "))
    }

    /// `U` at the 256 grey values of 8-bit frames: the table itself for a 256-value
    /// response, else the table at `v (2^k - 1) / 255` (exact for 65536 values: `v * 257`).
    pub fn values(&self) -> &[f64; 256] {
        &self.u8_table
    }

    /// All `2^k` values as in pcalib.txt.
    pub fn table(&self) -> &[f64] {
        &self.table
    }

    /// `k`: the bit depth the table is indexed by (8 for 256 values, 16 for 65536).
    pub fn bits(&self) -> u32 {
        self.table.len().trailing_zeros()
    }

    /// The largest sample value the table was given for: `2^k - 1`, or `n - 1` for a table of
    /// `n` values that is not a power of two (more than 512 values). The 16-bit forks of the
    /// authors' tools write `saturation value + 1` values (for example 4001 for a 12-bit
    /// sensor that saturates at 4000) and index the table with the raw value, as monovo does;
    /// the values above it take `U` of the saturation value.
    pub fn saturation_value(&self) -> u32 {
        (self.given - 1) as u32
    }

    /// `U` of the brightest value (white), the same at every bit depth.
    pub fn max_value(&self) -> f64 {
        self.table[self.table.len() - 1]
    }

    /// `U(k)` of an 8-bit grey value.
    #[inline]
    pub fn get(&self, k: u8) -> f64 {
        self.u8_table[k as usize]
    }

    /// The 8-bit values as an `f32` lookup table.
    pub fn lut(&self) -> [f32; 256] {
        self.u8_table.map(|v| v as f32)
    }

    /// `U` for every sample value `0 .. 2^bits - 1` of frames with `bits` bits per pixel
    /// (1 to 16): exact when `bits` is the table's own bit depth, else by full range and
    /// linear interpolation (see the module documentation).
    pub fn table_for_bits(&self, bits: u32) -> Result<Vec<f64>, PhotometricError> {
        if !(1..=16).contains(&bits) {
            return Err(PhotometricError::BitDepth(bits));
        }
        if bits == self.bits() {
            return Ok(self.table.clone());
        }
        Ok((0..1u32 << bits)
            .map(|v| sample(&self.table, v, bits))
            .collect())
    }

    /// Differences to a reference table over the grey values 0..254: the largest absolute
    /// difference with both as given (normally both scaled to `U(255) = 255`), and the RMS
    /// difference after the least-squares scale of `self` (`U` is only defined up to scale).
    pub fn errors_against(&self, reference: &[f64; 256]) -> (f64, f64) {
        let u = &self.u8_table;
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

    /// The same response scaled so that `U(white) = 255` (`U(255) = 255` for 8 bits).
    pub fn normalized(&self) -> InverseResponse {
        let s = 255.0 / self.max_value();
        InverseResponse {
            table: self.table.iter().map(|v| v * s).collect(),
            given: self.given,
            u8_table: self.u8_table.map(|v| v * s),
        }
    }
}
