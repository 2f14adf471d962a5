//! The 8-bit remap's table in fixed point and its kernels: a portable one and, on CPUs with
//! AVX2, one that gathers eight output pixels' sources at once. Both give the same bits.

/// Bits of the fixed-point bilinear weights of the 8-bit remap.
pub(crate) const FRAC_BITS: u32 = 8;
const FRAC_ONE: u32 = 1 << FRAC_BITS;

/// Whether monovo's AVX2 kernels run: the CPU has AVX2 and the environment variable
/// `MONOVO_NO_AVX2` is not set (it forces the portable kernels, which give the same bits).
/// Checked once per process.
pub fn avx2_enabled() -> bool {
    static WIDE: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *WIDE.get_or_init(|| {
        #[cfg(target_arch = "x86_64")]
        let avx2 = std::arch::is_x86_feature_detected!("avx2");
        #[cfg(not(target_arch = "x86_64"))]
        let avx2 = false;
        avx2 && std::env::var_os("MONOVO_NO_AVX2").is_none()
    })
}

/// The four bilinear weights of one source position in 8-bit fixed point, non-negative and
/// summing to exactly 256 so that a weighted sum of 8-bit values fits 16 bits; in the order
/// top-left, top-right, bottom-left, bottom-right.
pub(crate) fn weights(fx: f64, fy: f64) -> [u16; 4] {
    let one = FRAC_ONE as f64;
    let w11 = (fx * fy * one).round();
    let w01 = (fx * one).round() - w11;
    let w10 = (fy * one).round() - w11;
    let mut w = [one - w01 - w10 - w11, w01, w10, w11];
    // Rounding can push the smallest weight to -1; move that unit to the largest one so
    // the weights stay non-negative and sum to exactly 256.
    for i in 0..4 {
        if w[i] < 0.0 {
            let deficit = -w[i];
            w[i] = 0.0;
            let j = (0..4).fold(0, |m, k| if w[k] > w[m] { k } else { m });
            w[j] -= deficit;
        }
    }
    w.map(|v| v as u16)
}

/// [`weights`] packed in pairs as [`FixedMap`] keeps them.
pub(crate) fn packed_weights(fx: f64, fy: f64) -> [u32; 2] {
    let w = weights(fx, fy);
    [
        w[0] as u32 | (w[1] as u32) << 16,
        w[2] as u32 | (w[3] as u32) << 16,
    ]
}

/// Per output pixel, the index of its top-left source pixel and its weights packed in pairs
/// (`top-left | top-right << 16`, `bottom-left | bottom-right << 16`), as three arrays so
/// that eight pixels load in one vector each. An invalid pixel has index 0 and all weights
/// 0 (so that it comes out 0 without a test). Every valid index `i` has `i + width + 1`
/// inside the input image.
#[derive(Clone, Debug, Default)]
pub(crate) struct FixedMap {
    index: Vec<u32>,
    top: Vec<u32>,
    bottom: Vec<u32>,
}

/// The photometric part of [`FixedMap::remap_lut_gain`]: the table the source values are
/// looked up in, the gain per output pixel and the frame's factor, and the largest output.
#[derive(Clone, Copy)]
pub(crate) struct LutGain<'a> {
    pub(crate) lut: &'a [u16; 256],
    pub(crate) gain: &'a [f32],
    pub(crate) factor: f32,
    pub(crate) max: f32,
}

/// One row of a [`FixedMap`] being filled.
pub(crate) struct FixedRow<'a> {
    index: &'a mut [u32],
    top: &'a mut [u32],
    bottom: &'a mut [u32],
}

impl FixedRow<'_> {
    /// Makes pixel `u` of the row valid: its source index and [`packed_weights`].
    pub(crate) fn set(&mut self, u: usize, index: u32, [top, bottom]: [u32; 2]) {
        self.index[u] = index;
        self.top[u] = top;
        self.bottom[u] = bottom;
    }
}

impl FixedMap {
    /// `n` invalid pixels.
    pub(crate) fn invalid(n: usize) -> FixedMap {
        FixedMap {
            index: vec![0; n],
            top: vec![0; n],
            bottom: vec![0; n],
        }
    }

    /// The map in rows of `width` pixels, to be filled in parallel.
    pub(crate) fn rows_mut(
        &mut self,
        width: usize,
    ) -> impl rayon::iter::IndexedParallelIterator<Item = FixedRow<'_>> {
        use rayon::prelude::*;
        self.index
            .par_chunks_mut(width)
            .zip(self.top.par_chunks_mut(width))
            .zip(self.bottom.par_chunks_mut(width))
            .map(|((index, top), bottom)| FixedRow { index, top, bottom })
    }

    pub(crate) fn len(&self) -> usize {
        self.index.len()
    }

    /// The 8-bit bilinear remap of `s` (row length `w`, as many pixels as the map's input)
    /// into `out` (one value per map entry), rounded to nearest; invalid pixels are 0.
    pub(crate) fn remap_u8(&self, s: &[u8], w: usize, out: &mut [u8]) {
        #[cfg(target_arch = "x86_64")]
        if avx2_enabled() && w >= 2 && s.len() >= 2 * w && s.len() <= i32::MAX as usize {
            // SAFETY: the CPU has AVX2 (`avx2_enabled`), and the kernel's gathers stay
            // inside `s`: see `remap_u8_avx2`
            #[allow(unsafe_code)]
            unsafe {
                self.remap_u8_avx2(s, w, out)
            };
            return;
        }
        self.remap_u8_scalar(s, w, out, 0);
    }

    fn remap_u8_scalar(&self, s: &[u8], w: usize, out: &mut [u8], from: usize) {
        let entries = self.index.iter().zip(&self.top).zip(&self.bottom);
        for (o, ((&i, &a), &b)) in out.iter_mut().zip(entries).skip(from) {
            let i = i as usize;
            // Only a corrupt table fails this test; it lets the compiler drop the four
            // bounds checks below. (An invalid pixel reads pixel 0 with weights 0.)
            if i + w + 1 >= s.len() {
                *o = 0;
                continue;
            }
            let v = s[i] as u32 * (a & 0xffff)
                + s[i + 1] as u32 * (a >> 16)
                + s[i + w] as u32 * (b & 0xffff)
                + s[i + w + 1] as u32 * (b >> 16);
            *o = ((v + (1 << (FRAC_BITS - 1))) >> FRAC_BITS) as u8;
        }
    }

    /// The fused photometric remap: each source value looked up in `lut`, interpolated,
    /// times `gain[k] * factor`, rounded and clamped to `0..=max` (as `f32`, in this order of
    /// operations); invalid pixels are `T::default()`. `gain` has one value per entry.
    pub(crate) fn remap_lut_gain<T: Copy + Default + TryFrom<u32>>(
        &self,
        s: &[u8],
        w: usize,
        g: &LutGain<'_>,
        out: &mut [T],
    ) {
        #[cfg(target_arch = "x86_64")]
        if avx2_enabled() && w >= 2 && s.len() >= 2 * w && s.len() <= i32::MAX as usize {
            // SAFETY: the CPU has AVX2 (`avx2_enabled`); the gathers stay inside `s` and
            // the table: see `remap_lut_gain_avx2`
            #[allow(unsafe_code)]
            unsafe {
                self.remap_lut_gain_avx2(s, w, g, out)
            };
            return;
        }
        self.remap_lut_gain_scalar(s, w, g, out, 0);
    }

    fn remap_lut_gain_scalar<T: Copy + Default + TryFrom<u32>>(
        &self,
        s: &[u8],
        w: usize,
        g: &LutGain<'_>,
        out: &mut [T],
        from: usize,
    ) {
        let LutGain {
            lut,
            gain,
            factor,
            max,
        } = *g;
        let entries = self.index.iter().zip(&self.top).zip(&self.bottom);
        for ((o, &g), ((&i, &a), &b)) in out.iter_mut().zip(gain).zip(entries).skip(from) {
            let i = i as usize;
            if a | b == 0 || i + w + 1 >= s.len() {
                *o = T::default();
                continue;
            }
            let v = lut[s[i] as usize] as u32 * (a & 0xffff)
                + lut[s[i + 1] as usize] as u32 * (a >> 16)
                + lut[s[i + w] as usize] as u32 * (b & 0xffff)
                + lut[s[i + w + 1] as usize] as u32 * (b >> 16);
            *o = T::try_from((v as f32 * (g * factor) + 0.5).min(max) as u32).unwrap_or_default();
        }
    }

    /// [`FixedMap::remap_lut_gain`] eight pixels at a time: the source pairs gathered as in
    /// [`FixedMap::remap_u8_avx2`], their four bytes spread to 32-bit lanes and looked up by
    /// gathers in the table widened to 32 bits, the weighted sum in integers and the gain in
    /// `f32` with the scalar loop's operations in its order (no fused multiply-add): the
    /// same bits. (`min` with `max` in that order also maps NaN to `max`, as `f32::min`.)
    ///
    /// # Safety
    ///
    /// As [`FixedMap::remap_u8_avx2`]; the table gathers read entries 0 to 255 of a
    /// 256-entry table.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[allow(unsafe_code)]
    unsafe fn remap_lut_gain_avx2<T: Copy + Default + TryFrom<u32>>(
        &self,
        s: &[u8],
        w: usize,
        g: &LutGain<'_>,
        out: &mut [T],
    ) {
        use std::arch::x86_64::*;
        let LutGain {
            lut,
            gain,
            factor,
            max,
        } = *g;
        let n = self.len().min(out.len()).min(gain.len());
        let (index, top, bottom) = (&self.index[..n], &self.top[..n], &self.bottom[..n]);
        let wide: [i32; 256] = lut.map(i32::from);
        let table = wide.as_ptr();
        let base = s.as_ptr() as *const i32;
        let below = _mm256_set1_epi32(w as i32 - 2);
        let byte = _mm256_set1_epi32(0xff);
        let low16 = _mm256_set1_epi32(0xffff);
        let vfactor = _mm256_set1_ps(factor);
        let (half, vmax) = (_mm256_set1_ps(0.5), _mm256_set1_ps(max));
        let mut q = [0u32; 8];
        let mut k = 0;
        while k + 8 <= n {
            let i = _mm256_loadu_si256(index.as_ptr().add(k) as *const __m256i);
            let wt = _mm256_loadu_si256(top.as_ptr().add(k) as *const __m256i);
            let wb = _mm256_loadu_si256(bottom.as_ptr().add(k) as *const __m256i);
            let t = _mm256_i32gather_epi32::<1>(base, i);
            let b = _mm256_i32gather_epi32::<1>(base, _mm256_add_epi32(i, below));
            let la = _mm256_i32gather_epi32::<4>(table, _mm256_and_si256(t, byte));
            let lb = _mm256_i32gather_epi32::<4>(
                table,
                _mm256_and_si256(_mm256_srli_epi32::<8>(t), byte),
            );
            let lc = _mm256_i32gather_epi32::<4>(
                table,
                _mm256_and_si256(_mm256_srli_epi32::<16>(b), byte),
            );
            let ld = _mm256_i32gather_epi32::<4>(table, _mm256_srli_epi32::<24>(b));
            let v = _mm256_add_epi32(
                _mm256_add_epi32(
                    _mm256_mullo_epi32(la, _mm256_and_si256(wt, low16)),
                    _mm256_mullo_epi32(lb, _mm256_srli_epi32::<16>(wt)),
                ),
                _mm256_add_epi32(
                    _mm256_mullo_epi32(lc, _mm256_and_si256(wb, low16)),
                    _mm256_mullo_epi32(ld, _mm256_srli_epi32::<16>(wb)),
                ),
            );
            let g = _mm256_mul_ps(_mm256_loadu_ps(gain.as_ptr().add(k)), vfactor);
            let x = _mm256_add_ps(_mm256_mul_ps(_mm256_cvtepi32_ps(v), g), half);
            // `x.min(max) as u32` for x >= 0 (the sum and the gains are not negative)
            let x = _mm256_cvttps_epi32(_mm256_min_ps(x, vmax));
            _mm256_storeu_si256(q.as_mut_ptr() as *mut __m256i, x);
            // the invalid pixels (all weights 0), whatever their gain
            let zero = _mm256_cmpeq_epi32(_mm256_or_si256(wt, wb), _mm256_setzero_si256());
            let invalid = _mm256_movemask_ps(_mm256_castsi256_ps(zero));
            for (j, (o, &v)) in out[k..k + 8].iter_mut().zip(&q).enumerate() {
                *o = if invalid >> j & 1 == 1 {
                    T::default()
                } else {
                    T::try_from(v).unwrap_or_default()
                };
            }
            k += 8;
        }
        self.remap_lut_gain_scalar(s, w, g, out, k);
    }

    /// [`FixedMap::remap_u8`] sixteen pixels at a time: per eight pixels one gather of the
    /// four bytes at `i` (the top pair in the low two) and one of the four at `i + w - 2`
    /// (the bottom pair in the high two), the pairs spread to 16-bit lanes and multiplied
    /// with their packed weights by `madd`. The same integer sums as the scalar loop.
    ///
    /// # Safety
    ///
    /// The CPU must have AVX2, and `w >= 2`, `2 w <= s.len() <= i32::MAX`. Then every gather
    /// is inside `s`: a valid index has `i + w + 1 < s.len()`, so bytes `i..i + 4` (as
    /// `i + 3 <= i + w + 1`) and `i + w - 2..i + w + 2` are inside; an invalid one is 0 and
    /// reads bytes `0..4` and `w - 2..w + 2`, inside as `s.len() >= 2 w >= w + 2`.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[allow(unsafe_code)]
    unsafe fn remap_u8_avx2(&self, s: &[u8], w: usize, out: &mut [u8]) {
        use std::arch::x86_64::*;
        let n = self.len().min(out.len());
        let (index, top, bottom) = (&self.index[..n], &self.top[..n], &self.bottom[..n]);
        let base = s.as_ptr() as *const i32;
        let z = -128i8; // a shuffle index with the high bit set writes 0
        #[rustfmt::skip]
        let low_pair = _mm256_setr_epi8(
            0, z, 1, z, 4, z, 5, z, 8, z, 9, z, 12, z, 13, z,
            0, z, 1, z, 4, z, 5, z, 8, z, 9, z, 12, z, 13, z,
        );
        #[rustfmt::skip]
        let high_pair = _mm256_setr_epi8(
            2, z, 3, z, 6, z, 7, z, 10, z, 11, z, 14, z, 15, z,
            2, z, 3, z, 6, z, 7, z, 10, z, 11, z, 14, z, 15, z,
        );
        let below = _mm256_set1_epi32(w as i32 - 2);
        let half = _mm256_set1_epi32(1 << (FRAC_BITS - 1));
        // eight output pixels from `k` (`k + 8 <= n`: the loads read inside the three
        // arrays; the gathers are inside `s` by the function's contract)
        macro_rules! eight {
            ($k:expr) => {{
                let i = _mm256_loadu_si256(index.as_ptr().add($k) as *const __m256i);
                let wt = _mm256_loadu_si256(top.as_ptr().add($k) as *const __m256i);
                let wb = _mm256_loadu_si256(bottom.as_ptr().add($k) as *const __m256i);
                let t = _mm256_i32gather_epi32::<1>(base, i);
                let b = _mm256_i32gather_epi32::<1>(base, _mm256_add_epi32(i, below));
                let t = _mm256_madd_epi16(_mm256_shuffle_epi8(t, low_pair), wt);
                let b = _mm256_madd_epi16(_mm256_shuffle_epi8(b, high_pair), wb);
                _mm256_srli_epi32::<{ FRAC_BITS as i32 }>(_mm256_add_epi32(
                    _mm256_add_epi32(t, b),
                    half,
                ))
            }};
        }
        let mut k = 0;
        while k + 16 <= n {
            let (a, b) = (eight!(k), eight!(k + 8));
            // 16 x u16, in the order a0-3 b0-3 a4-7 b4-7; the permutation puts a before b
            let p = _mm256_permute4x64_epi64::<0b11_01_10_00>(_mm256_packus_epi32(a, b));
            let bytes =
                _mm_packus_epi16(_mm256_castsi256_si128(p), _mm256_extracti128_si256::<1>(p));
            _mm_storeu_si128(out.as_mut_ptr().add(k) as *mut __m128i, bytes);
            k += 16;
        }
        self.remap_u8_scalar(s, w, out, k);
    }
}

#[cfg(test)]
mod tests {
    use super::{packed_weights, FixedMap, LutGain};

    /// A small deterministic generator (the tests' own: no dependency for a test).
    fn lcg(state: &mut u64) -> u64 {
        *state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        *state >> 33
    }

    #[test]
    fn the_vector_remap_gives_the_scalar_bits() {
        // odd sizes, invalid pixels, sources on every border, and a tail of 16k + 7 pixels
        for (w, h, n) in [
            (2usize, 2usize, 7usize),
            (37, 23, 1031),
            (640, 480, 16 * 50 + 7),
        ] {
            let mut state = (w * h) as u64;
            let s: Vec<u8> = (0..w * h).map(|_| lcg(&mut state) as u8).collect();
            let mut map = FixedMap::invalid(n);
            use rayon::prelude::*;
            let mut rows = map.rows_mut(n).collect::<Vec<_>>();
            let row = &mut rows[0];
            for k in 0..n {
                let r = lcg(&mut state);
                if r.is_multiple_of(7) {
                    continue;
                }
                let (x, y) = match k % 5 {
                    0 => (w - 2, h - 2),
                    1 => (0, 0),
                    _ => ((r as usize / 7) % (w - 1), (r as usize / 101) % (h - 1)),
                };
                let (fx, fy) = (
                    (r % 1000) as f64 / 999.0,
                    ((r / 1000) % 1000) as f64 / 999.0,
                );
                row.set(k, (y * w + x) as u32, packed_weights(fx, fy));
            }
            drop(rows);
            let (mut fast, mut slow) = (vec![1u8; n], vec![2u8; n]);
            map.remap_u8(&s, w, &mut fast);
            map.remap_u8_scalar(&s, w, &mut slow, 0);
            assert_eq!(fast, slow, "{w}x{h}");
            // the fused photometric remap, 8- and 16-bit out: gains that clip, NaN, zero
            let mut lut = [0u16; 256];
            for (i, v) in lut.iter_mut().enumerate() {
                *v = ((i as f64 / 255.0).powf(1.7) * 65535.0).round() as u16;
            }
            let gain: Vec<f32> = (0..n)
                .map(|k| match k % 97 {
                    0 => f32::NAN,
                    1 => 0.0,
                    2 => 1e30,
                    _ => (lcg(&mut state) % 1000) as f32 * 1e-6,
                })
                .collect();
            for max in [255u32, 65535] {
                let g = LutGain {
                    lut: &lut,
                    gain: &gain,
                    factor: 0.7,
                    max: max as f32,
                };
                let (mut fast, mut slow) = (vec![1u16; n], vec![2u16; n]);
                map.remap_lut_gain(&s, w, &g, &mut fast);
                map.remap_lut_gain_scalar(&s, w, &g, &mut slow, 0);
                assert_eq!(fast, slow, "{w}x{h} to {max}");
                let (mut fast, mut slow) = (vec![1u8; n], vec![2u8; n]);
                map.remap_lut_gain(&s, w, &g, &mut fast);
                map.remap_lut_gain_scalar(&s, w, &g, &mut slow, 0);
                assert_eq!(fast, slow, "{w}x{h} to {max}, 8-bit");
            }
        }
    }
}
