//! The exposure ratio of two frames: a global shift coarse to fine, refined per tile to a
//! smooth displacement field, then a Huber mean of the tiles' ratios with its standard error.

use super::meter::{sample_patch, Level, MeteredFrame};
use super::ExposureOptions;
use crate::stats::median;

/// The measured exposure ratio of two frames.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RatioMeasurement {
    /// `log(t_b / t_a)`; NaN when nothing could be measured.
    pub log_ratio: f64,
    /// Standard error of `log_ratio` (infinite when nothing could be measured).
    pub std_error: f64,
    /// Image motion from the first frame to the second in raw pixels, `(x, y)` (the second
    /// frame at `p` shows what the first shows at `p + shift`).
    pub shift: [f64; 2],
    /// Tiles that entered the estimate.
    pub tiles: usize,
    /// Robust spread (1.4826 MAD) of the per-pixel log ratios: how well the frames match.
    pub pixel_spread: f64,
    /// Whether the ratio may be used (enough tiles, small standard error).
    pub reliable: bool,
    /// Why the ratio is unreliable (empty when reliable).
    pub note: String,
}

impl RatioMeasurement {
    /// A measurement that could not be made: no ratio, unreliable, with the reason.
    pub fn failed(note: impl Into<String>) -> RatioMeasurement {
        RatioMeasurement {
            log_ratio: f64::NAN,
            std_error: f64::INFINITY,
            shift: [f64::NAN; 2],
            tiles: 0,
            pixel_spread: f64::NAN,
            reliable: false,
            note: note.into(),
        }
    }
}

/// Variance of `b(x) - a(x + d)` over the window `[x0, x1) x [y0, y1)` of `b`, with the
/// count of pixels where both are finite and the mean.
pub(super) fn shift_cost(
    a: &Level,
    b: &Level,
    d: (isize, isize),
    win: (usize, usize, usize, usize),
) -> (f64, usize, f64) {
    let (x0, y0, x1, y1) = win;
    // clip the window so that x + d stays inside a
    let xs = (x0 as isize).max(-d.0).max(0) as usize;
    let xe = (x1 as isize).min(a.w as isize - d.0).max(0) as usize;
    let ys = (y0 as isize).max(-d.1).max(0) as usize;
    let ye = (y1 as isize).min(a.h as isize - d.1).max(0) as usize;
    if xe <= xs || ye <= ys {
        return (f64::INFINITY, 0, f64::NAN);
    }
    let (mut s, mut s2, mut n) = (0.0f64, 0.0f64, 0usize);
    for y in ys..ye {
        let rb = &b.data[y * b.w + xs..y * b.w + xe];
        let ya = (y as isize + d.1) as usize;
        let start = (ya * a.w) as isize + xs as isize + d.0;
        let ra = &a.data[start as usize..start as usize + rb.len()];
        // eight independent lanes, NaN masked by a select: the loop vectorises
        let (mut ls, mut ls2, mut ln) = ([0.0f32; 8], [0.0f32; 8], [0.0f32; 8]);
        let (cb, ca) = (rb.chunks_exact(8), ra.chunks_exact(8));
        let (tb, ta) = (cb.remainder(), ca.remainder());
        for (pb, pa) in cb.zip(ca) {
            for k in 0..8 {
                let r = pb[k] - pa[k];
                let ok = r.is_finite();
                let r = if ok { r } else { 0.0 };
                ls[k] += r;
                ls2[k] += r * r;
                ln[k] += if ok { 1.0 } else { 0.0 };
            }
        }
        for (k, (vb, va)) in tb.iter().zip(ta).enumerate() {
            let r = vb - va;
            if r.is_finite() {
                ls[k] += r;
                ls2[k] += r * r;
                ln[k] += 1.0;
            }
        }
        let ls: f32 = ls.iter().sum();
        let ls2: f32 = ls2.iter().sum();
        let ln = ln.iter().sum::<f32>() as usize;
        s += ls as f64;
        s2 += ls2 as f64;
        n += ln;
    }
    if n < 2 {
        return (f64::INFINITY, n, f64::NAN);
    }
    let mean = s / n as f64;
    ((s2 / n as f64 - mean * mean).max(0.0), n, mean)
}

/// The best integer shift within `radius` of `centre` by [`shift_cost`], with its cost and
/// mean log ratio. `None` when no shift has `min_count` pixels.
pub(super) fn search(
    a: &Level,
    b: &Level,
    centre: (isize, isize),
    radius: isize,
    win: (usize, usize, usize, usize),
    min_count: usize,
) -> Option<((isize, isize), f64, f64)> {
    let mut best: Option<((isize, isize), f64, f64)> = None;
    for dy in -radius..=radius {
        for dx in -radius..=radius {
            let d = (centre.0 + dx, centre.1 + dy);
            let (c, n, mean) = shift_cost(a, b, d, win);
            if n >= min_count && c.is_finite() && best.is_none_or(|(_, bc, _)| c < bc) {
                best = Some((d, c, mean));
            }
        }
    }
    best
}

/// Sub-pixel refinement of an integer minimum by parabolas through the costs at `d - 1`,
/// `d`, `d + 1` along each axis.
pub(super) fn subpixel(
    a: &Level,
    b: &Level,
    d: (isize, isize),
    c0: f64,
    win: (usize, usize, usize, usize),
) -> (f64, f64) {
    let fit = |cm: f64, cp: f64| {
        let den = cm - 2.0 * c0 + cp;
        if cm.is_finite() && cp.is_finite() && den > 1e-12 {
            (0.5 * (cm - cp) / den).clamp(-0.5, 0.5)
        } else {
            0.0
        }
    };
    let fx = fit(
        shift_cost(a, b, (d.0 - 1, d.1), win).0,
        shift_cost(a, b, (d.0 + 1, d.1), win).0,
    );
    let fy = fit(
        shift_cost(a, b, (d.0, d.1 - 1), win).0,
        shift_cost(a, b, (d.0, d.1 + 1), win).0,
    );
    (d.0 as f64 + fx, d.1 as f64 + fy)
}

/// Gauss-Newton refinement of a tile's shift `d` (frame b at `p` shows frame a at `p + d`)
/// on level 0, symmetric in the two frames (b sampled at `p - d/2`, a at `p + d/2`, so that
/// `m(a, b) = -m(b, a)` exactly), with the log ratio `c` as a third unknown and Huber
/// weights. Returns the start when the refinement leaves the neighbourhood of the start.
pub(super) fn refine(
    la: &Level,
    lb: &Level,
    win: (usize, usize, usize, usize),
    start: (f64, f64),
    c0: f64,
    buf: &mut (Vec<f32>, Vec<f32>),
) -> (f64, f64) {
    let (pw, ph) = (win.2 - win.0 + 2, win.3 - win.1 + 2);
    let (x0, y0) = (win.0 as isize - 1, win.1 as isize - 1);
    let (mut dx, mut dy, mut c) = (start.0, start.1, c0 as f32);
    if !c.is_finite() {
        return start;
    }
    for _ in 0..2 {
        sample_patch(lb, x0, y0, pw, ph, -0.5 * dx, -0.5 * dy, &mut buf.0);
        sample_patch(la, x0, y0, pw, ph, 0.5 * dx, 0.5 * dy, &mut buf.1);
        let (pb, pa) = (&buf.0, &buf.1);
        let mut h = [0.0f32; 6];
        let mut g = [0.0f32; 3];
        let mut n = 0usize;
        for j in 1..ph - 1 {
            let (up, down) = (
                (j - 1) * pw + 1..j * pw - 1,
                (j + 1) * pw + 1..(j + 2) * pw - 1,
            );
            let (bu, bd) = (&pb[up.clone()], &pb[down.clone()]);
            let (au, ad) = (&pa[up], &pa[down]);
            let (bm, am) = (&pb[j * pw..(j + 1) * pw], &pa[j * pw..(j + 1) * pw]);
            let vertical = bu.iter().zip(bd).zip(au.iter().zip(ad));
            for ((wb, wa), ((ub, db), (ua, da))) in bm.windows(3).zip(am.windows(3)).zip(vertical) {
                let r = wb[1] - wa[1] - c;
                let jx = -0.25 * (wb[2] - wb[0] + wa[2] - wa[0]);
                let jy = -0.25 * (db - ub + da - ua);
                if !(r + jx + jy).is_finite() {
                    continue;
                }
                let w = (0.05 / r.abs()).min(1.0);
                let (wx, wy) = (w * jx, w * jy);
                h[0] += wx * jx;
                h[1] += wx * jy;
                h[2] -= wx;
                h[3] += wy * jy;
                h[4] -= wy;
                h[5] += w;
                g[0] += wx * r;
                g[1] += wy * r;
                g[2] -= w * r;
                n += 1;
            }
        }
        if n < 16 {
            return start;
        }
        let m = nalgebra::Matrix3::new(
            h[0] as f64,
            h[1] as f64,
            h[2] as f64,
            h[1] as f64,
            h[3] as f64,
            h[4] as f64,
            h[2] as f64,
            h[4] as f64,
            h[5] as f64,
        );
        let rhs = nalgebra::Vector3::new(g[0] as f64, g[1] as f64, g[2] as f64);
        let Some(step) = m.cholesky().map(|ch| ch.solve(&rhs)) else {
            return start;
        };
        dx -= step[0];
        dy -= step[1];
        c -= step[2] as f32;
    }
    if dx.is_finite()
        && dy.is_finite()
        && (dx - start.0).abs() <= 0.75
        && (dy - start.1).abs() <= 0.75
    {
        (dx, dy)
    } else {
        start
    }
}

/// Median of `f32` values (reordered) as `f64`; NaN when empty.
pub(super) fn median_f32(v: &mut [f32]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let mid = v.len() / 2;
    let (_, m, _) = v.select_nth_unstable_by(mid, f32::total_cmp);
    *m as f64
}

/// Huber M-estimate of location with its sandwich standard error; the scale is 1.4826 MAD
/// (at least `min_scale`).
pub(super) fn huber(values: &[f64], min_scale: f64) -> (f64, f64, f64) {
    let n = values.len();
    let mut tmp = values.to_vec();
    let mut mu = median(&mut tmp);
    let mut dev: Vec<f64> = values.iter().map(|v| (v - mu).abs()).collect();
    let scale = (1.4826 * median(&mut dev)).max(min_scale);
    let k = 1.5;
    for _ in 0..20 {
        let (mut num, mut den) = (0.0, 0.0);
        for &v in values {
            let u = (v - mu) / scale;
            let w = if u.abs() <= k { 1.0 } else { k / u.abs() };
            num += w * v;
            den += w;
        }
        let next = num / den;
        let done = (next - mu).abs() < 1e-9 * scale;
        mu = next;
        if done {
            break;
        }
    }
    let (mut psi2, mut dpsi) = (0.0, 0.0);
    for &v in values {
        let u = (v - mu) / scale;
        if u.abs() <= k {
            psi2 += u * u;
            dpsi += 1.0;
        } else {
            psi2 += k * k;
        }
    }
    // small-sample correction n / (n - 1)
    let se = if dpsi > 0.0 && n > 1 {
        scale * (psi2 * n as f64 / (n - 1) as f64).sqrt() / dpsi
    } else {
        f64::INFINITY
    };
    (mu, se, scale)
}

/// Measures `log(t_b / t_a)` of two frames prepared by the same [`ExposureMeter`] (see the
/// module documentation). Never fails: a pair that cannot be measured is returned
/// unreliable, with a note.
pub fn measure_ratio(
    a: &MeteredFrame,
    b: &MeteredFrame,
    opts: &ExposureOptions,
) -> RatioMeasurement {
    if a.levels.len() != b.levels.len() || a.analysis_size() != b.analysis_size() {
        return RatioMeasurement::failed("the frames differ in size");
    }
    let top = a.levels.len() - 1;
    let (w0, h0) = a.analysis_size();
    let last = top.min(1);
    let d = match global_shift(a, b, opts) {
        Ok(d) => d,
        Err(m) => return m,
    };
    let (la, lb) = (&a.levels[0], &b.levels[0]);
    let ds = a.downsample as f64;
    let tiles = Tiles::new(opts.tile, w0, h0);
    let (t, nx, ny) = (tiles.t, tiles.nx, tiles.ny);
    let min_count = t * t / 4;
    let (grid, offsets) = tile_starts(a, b, &tiles, last, d, min_count);
    let found: Vec<(f64, f64)> = grid.iter().flatten().copied().collect();
    if found.is_empty() {
        let f = (1usize << last) as f64 * ds;
        let mut m = RatioMeasurement::failed("the alignment failed in every tile");
        m.shift = [d.0 as f64 * f, d.1 as f64 * f];
        return m;
    }
    let global = median2(&found);
    let shift = [global.0 * ds, global.1 * ds];
    let mut field = smooth_field(&grid, global, nx, ny);
    // each tile's shift refined where the frames match best, then a smooth displacement
    // field between the tile centres (a rotation or a zoom is not one shift per tile)
    let mut buf = (Vec::new(), Vec::new());
    let mut mean_offsets: Vec<f64> = offsets.iter().copied().filter(|v| v.is_finite()).collect();
    let global_offset = median(&mut mean_offsets);
    for ty in 0..ny {
        for tx in 0..nx {
            let k = ty * nx + tx;
            let c0 = if offsets[k].is_finite() {
                offsets[k]
            } else {
                global_offset
            };
            field[k] = refine(la, lb, tiles.window(tx, ty), field[k], c0, &mut buf);
        }
    }
    let (tile_values, mut spreads) = tile_ratios(a, b, &tiles, &field, min_count, &mut buf);
    let tiles = tile_values.len();
    if tiles < opts.min_tiles.max(2) {
        let mut m = RatioMeasurement::failed(format!(
            "{tiles} usable tiles, at least {} needed",
            opts.min_tiles.max(2)
        ));
        m.shift = shift;
        return m;
    }
    let (mu, se, _) = huber(&tile_values, 1e-5);
    let pixel_spread = median(&mut spreads);
    let std_error = (se * se + opts.systematic_error * opts.systematic_error).sqrt();
    let reliable = std_error <= opts.max_std_error;
    RatioMeasurement {
        log_ratio: mu,
        std_error,
        shift,
        tiles,
        pixel_spread,
        reliable,
        note: if reliable {
            String::new()
        } else {
            format!(
                "standard error {std_error:.4} above {} (motion blur, large motion or a scene change)",
                opts.max_std_error
            )
        },
    }
}

/// The global shift of `b` against `a`, coarse to fine: exhaustive at the coarsest level,
/// +-1 below, down to level 1 (the tiles refine on level 0). Err: the pair cannot be
/// measured.
fn global_shift(
    a: &MeteredFrame,
    b: &MeteredFrame,
    opts: &ExposureOptions,
) -> Result<(isize, isize), RatioMeasurement> {
    let top = a.levels.len() - 1;
    let (w0, _) = a.analysis_size();
    let full_radius = (opts.max_motion.clamp(0.0, 1.0) * w0 as f64).ceil() as isize;
    let last = top.min(1);
    let mut d = (0isize, 0isize);
    for l in (last..=top).rev() {
        let (la, lb) = (&a.levels[l], &b.levels[l]);
        let min_count = (la.w * la.h / 8).max(16);
        let win = (0, 0, lb.w, lb.h);
        let (centre, radius) = if l == top {
            ((0, 0), (full_radius >> l) + 1)
        } else {
            ((2 * d.0, 2 * d.1), 1)
        };
        match search(la, lb, centre, radius, win, min_count) {
            Some((best, _, _)) => d = best,
            None => {
                return Err(RatioMeasurement::failed(
                    "too few usable pixels in common (dark, saturated or out of view)",
                ))
            }
        }
    }
    Ok(d)
}

/// The tiles of the analysis frame: `nx` x `ny` squares of `t` pixels, centred.
struct Tiles {
    t: usize,
    nx: usize,
    ny: usize,
    ox: usize,
    oy: usize,
}

impl Tiles {
    fn new(tile: usize, w0: usize, h0: usize) -> Tiles {
        let t = tile.max(8) & !1;
        let (nx, ny) = ((w0 / t).max(1), (h0 / t).max(1));
        let t = t.min(w0).min(h0);
        let (ox, oy) = ((w0 - nx * t) / 2, (h0 - ny * t) / 2);
        Tiles { t, nx, ny, ox, oy }
    }

    /// The tile's window `(x0, y0, x1, y1)`.
    fn window(&self, tx: usize, ty: usize) -> (usize, usize, usize, usize) {
        let (t, ox, oy) = (self.t, self.ox, self.oy);
        (
            ox + tx * t,
            oy + ty * t,
            ox + (tx + 1) * t,
            oy + (ty + 1) * t,
        )
    }

    /// The displacement at `(x, y)`, bilinear between the tile centres' shifts in `field`.
    fn displacement(&self, field: &[(f64, f64)], x: f64, y: f64) -> (f64, f64) {
        let (t, nx) = (self.t, self.nx);
        let half = (t as f64 - 1.0) / 2.0;
        let axis = |p: f64, o: usize, n: usize| {
            let u = ((p - o as f64 - half) / t as f64).clamp(0.0, (n - 1) as f64);
            let i = (u as usize).min(n.saturating_sub(2));
            (i, (i + 1).min(n - 1), u - i as f64)
        };
        let (i0, i1, fx) = axis(x, self.ox, nx);
        let (j0, j1, fy) = axis(y, self.oy, self.ny);
        let f = |i: usize, j: usize| field[j * nx + i];
        let (a00, a10, a01, a11) = (f(i0, j0), f(i1, j0), f(i0, j1), f(i1, j1));
        let top = (a00.0 + fx * (a10.0 - a00.0), a00.1 + fx * (a10.1 - a00.1));
        let bot = (a01.0 + fx * (a11.0 - a01.0), a01.1 + fx * (a11.1 - a01.1));
        (top.0 + fy * (bot.0 - top.0), top.1 + fy * (bot.1 - top.1))
    }
}

/// A start for every tile's shift: +-2 pixels of level 1 around the global shift `d` with a
/// sub-pixel fit (level 0 when the frames are too small for a pyramid), and the tile's mean
/// log ratio there; None and NaN where the search fails.
fn tile_starts(
    a: &MeteredFrame,
    b: &MeteredFrame,
    tiles: &Tiles,
    last: usize,
    d: (isize, isize),
    min_count: usize,
) -> (Vec<Option<(f64, f64)>>, Vec<f64>) {
    let (nx, ny) = (tiles.nx, tiles.ny);
    let mut grid: Vec<Option<(f64, f64)>> = vec![None; nx * ny];
    let mut offsets = vec![f64::NAN; nx * ny];
    for ty in 0..ny {
        for tx in 0..nx {
            let win = tiles.window(tx, ty);
            // the coarser level suffices for a start: the refinement on level 0 follows
            let (l, centre, radius, scale) = if last == 1 {
                (1, d, 2, 2.0)
            } else {
                (0, d, 1, 1.0)
            };
            let (sa, sb) = (&a.levels[l], &b.levels[l]);
            let f = 1usize << l;
            let win_l = (win.0 / f, win.1 / f, win.2 / f, win.3 / f);
            if let Some((best, c, mean)) =
                search(sa, sb, centre, radius, win_l, min_count / (f * f))
            {
                let (sx, sy) = subpixel(sa, sb, best, c, win_l);
                grid[ty * nx + tx] = Some((sx * scale, sy * scale));
                offsets[ty * nx + tx] = mean;
            }
        }
    }
    (grid, offsets)
}

/// The medians of the x and of the y shifts.
fn median2(v: &[(f64, f64)]) -> (f64, f64) {
    let mut xs: Vec<f64> = v.iter().map(|s| s.0).collect();
    let mut ys: Vec<f64> = v.iter().map(|s| s.1).collect();
    (median(&mut xs), median(&mut ys))
}

/// A smooth displacement field: a tile's shift that differs from the median of its
/// neighbourhood by more than a pixel (a failed local search), or is missing, is replaced.
fn smooth_field(
    grid: &[Option<(f64, f64)>],
    global: (f64, f64),
    nx: usize,
    ny: usize,
) -> Vec<(f64, f64)> {
    let mut field = vec![global; nx * ny];
    for ty in 0..ny {
        for tx in 0..nx {
            let mut near = Vec::with_capacity(9);
            for yy in ty.saturating_sub(1)..(ty + 2).min(ny) {
                for xx in tx.saturating_sub(1)..(tx + 2).min(nx) {
                    if let Some(s) = grid[yy * nx + xx] {
                        near.push(s);
                    }
                }
            }
            let own = grid[ty * nx + tx];
            field[ty * nx + tx] = if near.len() >= 3 {
                let m = median2(&near);
                match own {
                    Some(s) if (s.0 - m.0).abs() <= 1.0 && (s.1 - m.1).abs() <= 1.0 => s,
                    _ => m,
                }
            } else {
                own.unwrap_or(global)
            };
        }
    }
    field
}

/// Every usable tile's log ratio (of its sums of `U / V` over the pixels whose log ratio is
/// not an outlier) and the spread of its pixels' log ratios; the frames sampled in blocks of
/// 8 x 8 pixels at the field's displacement.
fn tile_ratios(
    a: &MeteredFrame,
    b: &MeteredFrame,
    tiles: &Tiles,
    field: &[(f64, f64)],
    min_count: usize,
    buf: &mut (Vec<f32>, Vec<f32>),
) -> (Vec<f64>, Vec<f64>) {
    let (la, lb) = (&a.levels[0], &b.levels[0]);
    let t = tiles.t;
    // blocks of BLOCK x BLOCK pixels, each sampled at the field's displacement at its centre
    const BLOCK: usize = 8;
    let mut tile_values = Vec::new();
    let mut spreads = Vec::new();
    let mut samples: Vec<(f32, f32, f32)> = Vec::with_capacity(t * t);
    let mut residuals: Vec<f32> = Vec::with_capacity(t * t);
    let (mut lin_b, mut lin_a) = (Vec::new(), Vec::new());
    for ty in 0..tiles.ny {
        for tx in 0..tiles.nx {
            let win = tiles.window(tx, ty);
            samples.clear();
            for by in (win.1..win.3).step_by(BLOCK) {
                for bx in (win.0..win.2).step_by(BLOCK) {
                    let (bw, bh) = (BLOCK.min(win.2 - bx), BLOCK.min(win.3 - by));
                    let (sx, sy) = tiles.displacement(
                        field,
                        bx as f64 + (bw as f64 - 1.0) / 2.0,
                        by as f64 + (bh as f64 - 1.0) / 2.0,
                    );
                    // both frames half the displacement from the pixel centres, so that both
                    // are interpolated alike
                    let (x0, y0) = (bx as isize, by as isize);
                    sample_patch(lb, x0, y0, bw, bh, -0.5 * sx, -0.5 * sy, &mut buf.0);
                    sample_patch(la, x0, y0, bw, bh, 0.5 * sx, 0.5 * sy, &mut buf.1);
                    sample_patch(&b.linear, x0, y0, bw, bh, -0.5 * sx, -0.5 * sy, &mut lin_b);
                    sample_patch(&a.linear, x0, y0, bw, bh, 0.5 * sx, 0.5 * sy, &mut lin_a);
                    for k in 0..buf.0.len() {
                        let r = buf.0[k] - buf.1[k];
                        if r.is_finite() {
                            samples.push((r, lin_b[k], lin_a[k]));
                        }
                    }
                }
            }
            if samples.len() < min_count {
                continue;
            }
            // centre and spread of the log ratios from every fourth sample
            residuals.clear();
            residuals.extend(samples.iter().step_by(4).map(|s| s.0));
            let med = median_f32(&mut residuals) as f32;
            for r in residuals.iter_mut() {
                *r = (*r - med).abs();
            }
            let spread = 1.4826 * median_f32(&mut residuals);
            // the ratio of the tile's sums of U / V (immune to the bias that a changed pixel
            // footprint gives a mean of logs), over the pixels whose log ratio is not an
            // outlier
            let cut = (4.0 * spread).max(1e-3) as f32;
            let (mut sb, mut sa) = (0.0f64, 0.0f64);
            for &(r, vb, va) in &samples {
                if (r - med).abs() <= cut {
                    sb += vb as f64;
                    sa += va as f64;
                }
            }
            if !(sa > 0.0 && sb > 0.0) {
                continue;
            }
            spreads.push(spread);
            tile_values.push((sb / sa).ln());
        }
    }
    (tile_values, spreads)
}

/// A measured ratio between two frames for [`estimate_exposures`]: `log(t_to / t_from)`.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PairRatio {
    /// The first frame (0-based).
    pub from: usize,
    /// The second frame (0-based, after `from`).
    pub to: usize,
    /// The measurement.
    pub measurement: RatioMeasurement,
}

impl PairRatio {
    /// The pairs of a sequence's measurements for [`estimate_exposures`]: `consecutive[i]`
    /// links frames `i` and `i + 1`, `skip[i]` frames `i` and `i + 2`.
    pub fn chain(consecutive: &[RatioMeasurement], skip: &[RatioMeasurement]) -> Vec<PairRatio> {
        let pair = |step: usize| {
            move |(i, m): (usize, &RatioMeasurement)| PairRatio {
                from: i,
                to: i + step,
                measurement: m.clone(),
            }
        };
        consecutive
            .iter()
            .enumerate()
            .map(pair(1))
            .chain(skip.iter().enumerate().map(pair(2)))
            .collect()
    }
}
