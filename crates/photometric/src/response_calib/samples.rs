//! The observations the calibration works on: a random sample of the pixels, with their
//! values in every frame, drawn so that a larger sample contains every smaller one.

use camera_model::Image;
use rayon::prelude::*;

/// Samples of a frame: 8-bit grey values, or `k`-bit values in the low bits of 16-bit ones.
pub(super) trait Sample: Copy + Send + Sync + 'static {
    /// The raw value.
    fn raw(self) -> u32;
}

impl Sample for u8 {
    #[inline]
    fn raw(self) -> u32 {
        self as u32
    }
}

impl Sample for u16 {
    #[inline]
    fn raw(self) -> u32 {
        self as u32
    }
}

/// The grey values of the frames and the knots of the estimated table.
#[derive(Clone, Copy, Debug)]
pub(super) struct Levels {
    /// The largest grey value, `2^k - 1` (saturation).
    pub top: u32,
    /// Values from this one up count as clipped (censored): `top`, or a little below it
    /// for JPEG frames, whose clipped areas decode to values just under the top.
    pub clip: u32,
    /// Number of knots.
    pub knots: usize,
    /// Knot position per grey value, `(knots - 1) / top`.
    pub scale: f64,
}

impl Levels {
    pub fn new(bits: u32, max_knots: usize) -> Levels {
        let top = (1u32 << bits) - 1;
        let knots = (top as usize + 1).min(max_knots);
        Levels {
            top,
            clip: top,
            knots,
            scale: (knots - 1) as f64 / top as f64,
        }
    }

    /// The knot position of a grey value.
    #[inline]
    pub fn pos(&self, v: u32) -> f64 {
        v as f64 * self.scale
    }

    /// The nearest knot of a grey value.
    #[inline]
    pub fn knot(&self, v: u32) -> usize {
        ((v as f64 * self.scale).round() as usize).min(self.knots - 1)
    }

    /// The nearest grey value of a knot.
    pub fn grey(&self, k: usize) -> u32 {
        (k as f64 / self.scale).round() as u32
    }
}

/// Side of the square tiles whose pixels count as one independent unit in the standard errors
/// (JPEG blocks and demosaicing correlate neighbouring pixels).
const TILE: usize = 32;

/// What one scan of the frames tells: the histogram of the values, and the pixels that have
/// at least two values strictly between 0 and saturation (the others say nothing about `U`),
/// ordered by their draw.
pub(super) struct Scan {
    /// Pixels per grey value over all frames.
    pub histogram: Vec<u64>,
    /// The informative pixels, in the order in which samples draw them.
    pub order: Vec<u32>,
}

/// A hash of the pixel index: the random, reproducible order of the draw.
#[inline]
fn draw_key(p: u32) -> u64 {
    let mut h = (p as u64).wrapping_add(0x9E37_79B9_7F4A_7C15);
    h = (h ^ (h >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    h = (h ^ (h >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    h ^ (h >> 31)
}

/// Rows per chunk of the parallel scans.
const SCAN_ROWS: usize = 16;

/// Scans the frames once: the histogram and the informative pixels in draw order.
pub(super) fn scan<T: Sample>(frames: &[Image<T>], top: u32) -> Scan {
    let (w, h) = frames[0].size();
    let chunk = SCAN_ROWS * w.max(1);
    let npx = w * h;
    let parts: Vec<(Vec<u64>, Vec<u32>)> = (0..npx.div_ceil(chunk))
        .into_par_iter()
        .map(|c| {
            let start = c * chunk;
            let m = chunk.min(npx - start);
            let mut count = vec![0u16; m];
            let mut hist = vec![0u64; top as usize + 1];
            for f in frames {
                for (x, &v) in f.data()[start..start + m].iter().enumerate() {
                    let v = v.raw().min(top);
                    hist[v as usize] += 1;
                    count[x] = count[x].saturating_add(u16::from(v > 0 && v < top));
                }
            }
            let keep = (0..m)
                .filter(|&x| count[x] >= 2)
                .map(|x| (start + x) as u32)
                .collect();
            (hist, keep)
        })
        .collect();
    let mut histogram = vec![0u64; top as usize + 1];
    let mut order = Vec::new();
    for (hst, keep) in parts {
        for (a, b) in histogram.iter_mut().zip(&hst) {
            *a += b;
        }
        order.extend(keep);
    }
    order.par_sort_unstable_by_key(|&p| (draw_key(p), p));
    Scan { histogram, order }
}

/// The sampled pixels' values, pixel-major (`values[p * frames + i]`), and which of them do
/// not enter: those next to a saturated pixel of their frame (blooming and the compression's
/// ringing around clipped highlights), as the paper drops them.
pub(super) struct Samples {
    /// Frames per pixel.
    pub frames: usize,
    /// The values: one byte each when the frames have 8 bits.
    pub values: Values,
    /// One bit per value: excluded.
    pub excluded: Vec<u64>,
    /// The tile of each sampled pixel (the units of the standard errors).
    pub tile: Vec<u32>,
    /// Rank of each sampled pixel in the draw (a smaller sample is the pixels of rank below
    /// its size).
    pub rank: Vec<u32>,
}

impl Samples {
    /// No pixels.
    pub fn empty(frames: usize) -> Samples {
        Samples {
            frames,
            values: Values::U8(Vec::new()),
            excluded: Vec::new(),
            tile: Vec::new(),
            rank: Vec::new(),
        }
    }

    /// Number of sampled pixels.
    pub fn len(&self) -> usize {
        self.tile.len()
    }

    /// The values of pixel `p`.
    #[inline]
    pub fn pixel(&self, p: usize) -> Pixel<'_> {
        let r = p * self.frames..(p + 1) * self.frames;
        match &self.values {
            Values::U8(v) => Pixel::U8(&v[r]),
            Values::U16(v) => Pixel::U16(&v[r]),
        }
    }

    /// Whether the observation `i` of pixel `p` is excluded.
    #[inline]
    pub fn is_excluded(&self, p: usize, i: usize) -> bool {
        let k = p * self.frames + i;
        self.excluded[k / 64] >> (k % 64) & 1 == 1
    }
}

/// The sampled values, pixel-major: bytes for 8-bit frames (the samples of a large draw are
/// a good part of the memory), else 16 bits.
pub(super) enum Values {
    /// Values of 8-bit frames.
    U8(Vec<u8>),
    /// Values of deeper frames.
    U16(Vec<u16>),
}

/// The values of one sampled pixel, one per frame.
#[derive(Clone, Copy)]
pub(super) enum Pixel<'a> {
    /// Of 8-bit frames.
    U8(&'a [u8]),
    /// Of deeper frames.
    U16(&'a [u16]),
}

impl<'a> Pixel<'a> {
    /// The values in frame order.
    #[inline]
    pub fn iter(self) -> PixelValues<'a> {
        match self {
            Pixel::U8(s) => PixelValues::U8(s.iter()),
            Pixel::U16(s) => PixelValues::U16(s.iter()),
        }
    }
}

/// The values of a [`Pixel`] in frame order.
pub(super) enum PixelValues<'a> {
    /// Of 8-bit frames.
    U8(std::slice::Iter<'a, u8>),
    /// Of deeper frames.
    U16(std::slice::Iter<'a, u16>),
}

impl Iterator for PixelValues<'_> {
    type Item = u16;
    #[inline]
    fn next(&mut self) -> Option<u16> {
        match self {
            PixelValues::U8(it) => it.next().map(|&v| u16::from(v)),
            PixelValues::U16(it) => it.next().copied(),
        }
    }
}

/// Where the saturation border of each frame comes from: `radius` pixels around the pixels
/// saturated in frame `reference[i]` (see [`border_reference`]) are dropped from frame `i`.
#[derive(Clone, Debug)]
pub(super) struct Border {
    pub radius: usize,
    pub reference: Vec<usize>,
}

impl Border {
    /// `radius` pixels around the saturated pixels of each frame's [`border_reference`].
    pub fn new(radius: usize, exposures: &[f64], own: bool) -> Border {
        Border {
            radius,
            reference: border_reference(exposures, own),
        }
    }
}

/// For each frame, the frame whose saturated pixels decide the border dropped around them.
///
/// - JPEG and deeper frames (`own`): the frame itself. Deciding it elsewhere keeps the values
///   next to a highlight that the compression lowered (a saturated area decodes below the top
///   too), or that the noise after the clip spread below the top.
/// - Lossless 8-bit frames: another frame of the same exposure, else the one of the next
///   shorter exposure (for the shortest, the next longer). A pixel's noise is its own, so the border
///   only has to keep out what a highlight spills into its neighbours, and the frame itself
///   would drop almost every value near the top: on a smooth scene nearly every pixel close
///   to saturation has a saturated neighbour (on a 30-frame sweep, 107 of the 4,273 values
///   predicted at 253-255 stayed). The shorter exposure's highlights are smaller; a little of
///   a longer exposure's spill stays, where `U` is steep and values weigh little.
pub(super) fn border_reference(exposures: &[f64], own: bool) -> Vec<usize> {
    let n = exposures.len();
    if own {
        return (0..n).collect();
    }
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| exposures[a].total_cmp(&exposures[b]).then(a.cmp(&b)));
    let mut refs = vec![0; n];
    for (r, &i) in order.iter().enumerate() {
        let same = |j: usize| exposures[j] == exposures[i];
        refs[i] = if r + 1 < n && same(order[r + 1]) {
            order[r + 1]
        } else if r > 0 {
            order[r - 1]
        } else if r + 1 < n {
            order[r + 1]
        } else {
            i
        };
    }
    refs
}

/// The first `n` pixels of the draw (all informative pixels when `n` is larger), their
/// values ordered by tile, with the observations that have a saturated pixel within the
/// border's radius in the border's reference frame excluded (a saturated value without one
/// stays: it is a censored observation).
pub(super) fn draw<T: Sample>(
    frames: &[Image<T>],
    scan: &Scan,
    top: u32,
    border: &Border,
    n: usize,
) -> Samples {
    let (w, h) = frames[0].size();
    let n = n.min(scan.order.len());
    let tile = tile_size(w, h);
    let across = w.div_ceil(tile);
    let tile_of = |p: u32| {
        let (x, y) = (p as usize % w, p as usize / w);
        ((y / tile) * across + x / tile) as u32
    };
    // ordered by tile, then by pixel: the passes take whole tiles
    let mut chosen: Vec<(u32, u32)> = scan.order[..n]
        .iter()
        .enumerate()
        .map(|(r, &p)| (p, r as u32))
        .collect();
    chosen.sort_unstable_by_key(|&(p, _)| (tile_of(p), p));
    let nf = frames.len();
    // whole words of the bitset per chunk of 64 pixels
    let mut excluded = vec![0u64; (n * nf).div_ceil(64)];
    let values = if top <= u32::from(u8::MAX) {
        let mut v = vec![0u8; n * nf];
        fill(frames, &chosen, &mut v, &mut excluded, top, border);
        Values::U8(v)
    } else {
        let mut v = vec![0u16; n * nf];
        fill(frames, &chosen, &mut v, &mut excluded, top, border);
        Values::U16(v)
    };
    Samples {
        frames: nf,
        values,
        excluded,
        tile: chosen.iter().map(|&(p, _)| tile_of(p)).collect(),
        rank: chosen.iter().map(|&(_, r)| r).collect(),
    }
}

/// Fills the values of the `chosen` pixels (pixel-major) and the bits of the excluded ones.
fn fill<T: Sample, V: TryFrom<u32> + Default + Copy + Send>(
    frames: &[Image<T>],
    chosen: &[(u32, u32)],
    values: &mut [V],
    excluded: &mut [u64],
    top: u32,
    border: &Border,
) {
    let radius = border.radius;
    let (w, h) = frames[0].size();
    let nf = frames.len();
    values
        .par_chunks_mut(nf * 64)
        .zip(excluded.par_chunks_mut(nf))
        .zip(chosen.par_chunks(64))
        .for_each(|((out, bits), ps)| {
            for (k, &(p, _)) in ps.iter().enumerate() {
                let (x, y) = (p as usize % w, p as usize / w);
                let (x0, x1) = (x.saturating_sub(radius), (x + radius).min(w - 1));
                let (y0, y1) = (y.saturating_sub(radius), (y + radius).min(h - 1));
                for (i, f) in frames.iter().enumerate() {
                    let v = f.data()[p as usize].raw().min(top);
                    let d = frames[border.reference.get(i).copied().unwrap_or(i)].data();
                    // a saturated neighbour excludes the value whatever the value is (also
                    // when it is saturated itself): excluding only the unsaturated values
                    // would keep the clipped ones preferentially and bias U near the top
                    let near = radius > 0
                        && (y0..=y1).any(|yy| {
                            (x0..=x1).any(|xx| (xx, yy) != (x, y) && d[yy * w + xx].raw() >= top)
                        });
                    // `v` is at most `top`, which fits `V`
                    out[k * nf + i] = V::try_from(v).unwrap_or_default();
                    if near {
                        let b = k * nf + i;
                        bits[b / 64] |= 1 << (b % 64);
                    }
                }
            }
        });
}

/// The tile side: [`TILE`], smaller for small frames so that there are at least 64 tiles.
fn tile_size(w: usize, h: usize) -> usize {
    let mut t = TILE;
    while t > 4 && w.div_ceil(t) * h.div_ceil(t) < 64 {
        t /= 2;
    }
    t
}

#[cfg(test)]
mod tests {
    use super::{border_reference, draw, scan, Border};
    use camera_model::Image;

    #[test]
    fn the_border_reference_is_the_next_shorter_exposure_of_lossless_frames() {
        // exposures out of order, two frames of 4 ms
        let t = [2.0, 1.0, 4.0, 4.0, 8.0];
        assert_eq!(border_reference(&t, false), vec![1, 0, 3, 2, 3]);
        // the shortest takes the next longer; JPEG frames their own
        assert_eq!(border_reference(&[1.0], false), vec![0]);
        assert_eq!(border_reference(&t, true), vec![0, 1, 2, 3, 4]);
    }

    /// Three 8x8 frames at 2, 1 and 4 ms: one informative pixel at (4, 4); its right
    /// neighbour saturates at 2 and 4 ms. Which of the pixel's values the border drops.
    fn excluded_with(own: bool) -> Vec<bool> {
        let (w, h) = (8, 8);
        let t = [2.0, 1.0, 4.0];
        let frames: Vec<Image<u8>> = (0..3)
            .map(|i| {
                let mut d = vec![0u8; w * h];
                d[4 * w + 4] = 100;
                if i != 1 {
                    d[4 * w + 5] = 255;
                }
                Image::new(w, h, d).expect("8x8")
            })
            .collect();
        let sc = scan(&frames, 255);
        assert_eq!(sc.order.len(), 1);
        let s = draw(&frames, &sc, 255, &Border::new(1, &t, own), 10);
        (0..3).map(|i| s.is_excluded(0, i)).collect()
    }

    #[test]
    fn lossless_frames_drop_the_values_beside_the_shorter_exposures_highlights() {
        // 2 ms: the shorter frame (1 ms) has no highlight, so the value stays although its
        // own neighbour saturated; 1 ms (the shortest: the next longer, 2 ms) and 4 ms (2 ms)
        // are dropped
        assert_eq!(excluded_with(false), vec![false, true, true]);
        // JPEG frames: the frame's own highlights
        assert_eq!(excluded_with(true), vec![true, false, true]);
    }
}
