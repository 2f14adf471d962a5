//! Output pinhole cameras (`crop`, `full`, `none`, explicit) and rectification maps.

use crate::fixed::{packed_weights, FixedMap, LutGain};
use crate::model::fov_undistort_radius;
use crate::{CameraError, CameraModel, Image, ImageSize, Intrinsics, OutputMode};

/// Computes the output pinhole camera for `mode` at `out_size`.
///
/// * `none`: the input's own `fx fy cx cy` (its distortion, if any, is ignored: the raw
///   image passes through, as in DSO); at another output size the image is resized and K
///   scaled with it (pixel areas: `fx * ow / w`, `(cx + 0.5) * ow / w - 0.5`).
/// * A pinhole input under `crop` or `full` keeps its whole view, border pixel centre to
///   border pixel centre (`fx * (ow - 1) / (w - 1)`): at the input size this is the identity.
/// * For the FOV model `crop` and `full` use the reference tools' closed form (axis extents,
///   respectively corner extents, mapped through `T(x) = tan(x omega) / (2 tan(omega / 2))`).
/// * For the other models `crop` finds each of the four sides on its own: it starts from
///   DSO's own crop (its search in 0.5 % steps, `makeOptimalK_crop`), makes it valid for
///   every output pixel, then moves every side outward to the exact limit where an output
///   pixel would leave the input image. The result has no invalid pixel and at least DSO's
///   field of view on every side. `full` is the bounding box of the input border.
/// * An explicit pinhole `fx fy cx cy` is relative to the output size when `cx < 1 && cy < 1`
///   (DSO always reads it as relative), else in pixels.
pub fn output_intrinsics(
    input: &CameraModel,
    in_size: ImageSize,
    mode: &OutputMode,
    out_size: ImageSize,
) -> Result<Intrinsics, CameraError> {
    let in_size = in_size.validate()?;
    let out_size = out_size.validate()?;
    let (w, h) = (in_size.width as f64, in_size.height as f64);
    let (ow, oh) = (out_size.width as f64, out_size.height as f64);
    match mode {
        OutputMode::Pinhole(v) => Ok(crate::camera_file::intrinsics_from_file_values(
            *v, out_size,
        )),
        OutputMode::None => Ok(passthrough_intrinsics(
            input.intrinsics(),
            in_size,
            out_size,
        )),
        _ if input.is_pinhole() => Ok(pinhole_view(input.intrinsics(), in_size, out_size)),
        OutputMode::Crop => {
            if let CameraModel::Fov { k, omega } = input {
                let t = |x: f64| fov_undistort_radius(*omega, x);
                let (l, r) = (k.cx / k.fx, (w - 1.0 - k.cx) / k.fx);
                let (tp, b) = (k.cy / k.fy, (h - 1.0 - k.cy) / k.fy);
                if let (Some(tl), Some(tr), Some(tt), Some(tb)) = (t(l), t(r), t(tp), t(b)) {
                    if l > 0.0 && r > 0.0 && tp > 0.0 && b > 0.0 {
                        let fx = k.fx * ((l + r) / (tl + tr)) * (ow / w);
                        let fy = k.fy * ((tp + b) / (tt + tb)) * (oh / h);
                        return Ok(Intrinsics {
                            fx,
                            fy,
                            cx: tl * fx,
                            cy: tt * fy,
                        });
                    }
                }
            }
            crop_numeric(input, in_size, out_size)
        }
        OutputMode::Full => {
            if let CameraModel::Fov { k, omega } = input {
                let t = |x: f64| fov_undistort_radius(*omega, x);
                let (l, r) = (k.cx / k.fx, (w - 1.0 - k.cx) / k.fx);
                let (tp, b) = (k.cy / k.fy, (h - 1.0 - k.cy) / k.fy);
                let tl_r = l.hypot(tp);
                let tr_r = r.hypot(tp);
                let bl_r = l.hypot(b);
                let br_r = r.hypot(b);
                if let (Some(ttl), Some(ttr), Some(tbl), Some(tbr)) =
                    (t(tl_r), t(tr_r), t(bl_r), t(br_r))
                {
                    if l > 0.0 && r > 0.0 && tp > 0.0 && b > 0.0 {
                        let hor = br_r.max(tr_r) + bl_r.max(tl_r);
                        let vert = tr_r.max(tl_r) + bl_r.max(br_r);
                        let t_hor = tbr.max(ttr) + tbl.max(ttl);
                        let t_vert = ttr.max(ttl) + tbl.max(tbr);
                        let fy = k.fy * (vert / t_vert) * (oh / h);
                        let fx = k.fx * (hor / t_hor) * (ow / w);
                        let cy = (ttl / tl_r).max(ttr / tr_r) * fy * k.cy / k.fy;
                        let cx = (tbl / bl_r).max(ttl / tl_r) * fx * k.cx / k.fx;
                        return Ok(Intrinsics { fx, fy, cx, cy });
                    }
                }
                let (u, v) = first_unbounded_border_pixel(input, in_size);
                return Err(CameraError::FullUnbounded {
                    model: input.name(),
                    u,
                    v,
                });
            }
            full_numeric(input, in_size, out_size)
        }
    }
}

/// What rectifying with `mode` does differently from what a DSO user may expect, one
/// sentence each: `none` ignoring a distortion or resizing, an explicit pinhole in pixels.
pub fn output_notes(
    input: &CameraModel,
    in_size: ImageSize,
    mode: &OutputMode,
    out_size: ImageSize,
) -> Vec<String> {
    let mut notes = Vec::new();
    match mode {
        OutputMode::None => {
            if !input.is_pinhole() {
                notes.push(format!(
                    "output `none` passes the raw image through as a pinhole with the input's fx fy cx cy: the {} distortion is ignored (DSO does the same, silently); use `crop` or `full` to undistort",
                    input.name()
                ));
            }
            if in_size != out_size {
                notes.push(format!(
                    "output `none` at {out_size} from {in_size}: the raw image is resized (DSO refuses `none` with another size)"
                ));
            }
        }
        OutputMode::Pinhole(v) if !(v[2] < 1.0 && v[3] < 1.0) => notes.push(format!(
            "the output pinhole `{} {} {} {}` is read in pixels because cx or cy is 1 or more; DSO always reads it as relative to the output size",
            v[0], v[1], v[2], v[3]
        )),
        _ => {}
    }
    notes
}

/// `none`: the input K, scaled with the image when the output size differs.
fn passthrough_intrinsics(k: Intrinsics, in_size: ImageSize, out_size: ImageSize) -> Intrinsics {
    if in_size == out_size {
        return k;
    }
    CameraModel::Pinhole(k)
        .rescaled(
            (in_size.width, in_size.height),
            (out_size.width, out_size.height),
        )
        .intrinsics()
}

/// The whole view of a pinhole camera, border pixel centres onto border pixel centres.
fn pinhole_view(k: Intrinsics, in_size: ImageSize, out_size: ImageSize) -> Intrinsics {
    let sx = if in_size.width == out_size.width {
        1.0
    } else {
        (out_size.width - 1) as f64 / (in_size.width - 1) as f64
    };
    let sy = if in_size.height == out_size.height {
        1.0
    } else {
        (out_size.height - 1) as f64 / (in_size.height - 1) as f64
    };
    Intrinsics {
        fx: k.fx * sx,
        fy: k.fy * sy,
        cx: k.cx * sx,
        cy: k.cy * sy,
    }
}

/// Pixels along the border of an image, every pixel once.
fn border_pixels(size: ImageSize) -> impl Iterator<Item = [f64; 2]> {
    let (w, h) = (size.width, size.height);
    let top = (0..w).map(move |x| [x as f64, 0.0]);
    let bottom = (0..w).map(move |x| [x as f64, (h - 1) as f64]);
    let left = (1..h - 1).map(move |y| [0.0, y as f64]);
    let right = (1..h - 1).map(move |y| [(w - 1) as f64, y as f64]);
    top.chain(bottom).chain(left).chain(right)
}

fn first_unbounded_border_pixel(input: &CameraModel, in_size: ImageSize) -> (f64, f64) {
    border_pixels(in_size)
        .find(|p| input.unproject_normalized(*p).is_none())
        .map_or((0.0, 0.0), |p| (p[0], p[1]))
}

/// The DSO convention for a normalised rectangle `[x0, x1] x [y0, y1]`: its edges land on the
/// centres of the first and last output pixels.
fn k_from_rect(rect: [f64; 4], out: ImageSize) -> Intrinsics {
    let [x0, x1, y0, y1] = rect;
    let fx = (out.width as f64 - 1.0) / (x1 - x0);
    let fy = (out.height as f64 - 1.0) / (y1 - y0);
    Intrinsics {
        fx,
        fy,
        cx: -x0 * fx,
        cy: -y0 * fy,
    }
}

fn full_numeric(
    input: &CameraModel,
    in_size: ImageSize,
    out_size: ImageSize,
) -> Result<Intrinsics, CameraError> {
    let mut rect = [
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    ];
    for p in border_pixels(in_size) {
        let n = input
            .unproject_normalized(p)
            .ok_or(CameraError::FullUnbounded {
                model: input.name(),
                u: p[0],
                v: p[1],
            })?;
        rect[0] = rect[0].min(n[0]);
        rect[1] = rect[1].max(n[0]);
        rect[2] = rect[2].min(n[1]);
        rect[3] = rect[3].max(n[1]);
    }
    if !(rect[1] > rect[0] && rect[3] > rect[2]) {
        return Err(CameraError::FullUnbounded {
            model: input.name(),
            u: 0.0,
            v: 0.0,
        });
    }
    Ok(k_from_rect(rect, out_size))
}

/// Source positions this close outside the input image (in pixels) are moved onto its border:
/// floating-point round trips (an identity or upscaled pinhole map, a crop side found to the
/// last bit) land there, and a millionth of a pixel changes no interpolated value.
pub(crate) const BORDER_SNAP: f64 = 1e-6;

/// The pixel `src` where the bilinear remap can sample it, moved onto the border when it is
/// at most [`BORDER_SNAP`] outside; `None` outside the image or for NaN.
#[inline]
fn snap_inside(src: [f64; 2], size: ImageSize) -> Option<[f64; 2]> {
    let (w, h) = ((size.width - 1) as f64, (size.height - 1) as f64);
    let ok = src[0] >= -BORDER_SNAP
        && src[1] >= -BORDER_SNAP
        && src[0] <= w + BORDER_SNAP
        && src[1] <= h + BORDER_SNAP;
    ok.then(|| [src[0].clamp(0.0, w), src[1].clamp(0.0, h)])
}

/// Where output pixel `(u, v)` of the pinhole `out_camera` looks in `input`'s raw image
/// (anywhere, not checked against its size). A pinhole input is mapped in closed form
/// (`x_in = a x_out + b` per axis), so that the identity is exact.
fn source_in(
    input: &CameraModel,
    out_camera: Intrinsics,
) -> impl Fn(usize, usize) -> Option<[f64; 2]> + Sync + '_ {
    let linear = input.is_pinhole().then(|| {
        let k = input.intrinsics();
        let (ax, ay) = (k.fx / out_camera.fx, k.fy / out_camera.fy);
        (ax, k.cx - ax * out_camera.cx, ay, k.cy - ay * out_camera.cy)
    });
    move |u, v| match linear {
        Some((ax, bx, ay, by)) => Some([ax * u as f64 + bx, ay * v as f64 + by]),
        None => input.project_normalized(out_camera.pixel_to_normalized([u as f64, v as f64])),
    }
}

/// The raw pixel of a normalised output direction, when it lies in the input image before
/// any fold of the distortion (beyond a fold the image repeats mirrored).
#[inline]
fn source_of(input: &CameraModel, in_size: ImageSize, n: [f64; 2]) -> Option<[f64; 2]> {
    if !input.unfolded_at(n) {
        return None;
    }
    input
        .project_normalized(n)
        .and_then(|p| snap_inside(p, in_size))
}

/// Whether every border pixel of the output pinhole spanning the normalised rectangle
/// `rect = [x0, x1, y0, y1]` has a source in the input image.
fn border_fits(input: &CameraModel, in_size: ImageSize, out: ImageSize, rect: [f64; 4]) -> bool {
    if !(rect[0] < rect[1] && rect[2] < rect[3]) {
        return false;
    }
    let k = k_from_rect(rect, out);
    border_pixels(out).all(|p| source_of(input, in_size, k.pixel_to_normalized(p)).is_some())
}

/// DSO's crop search (`makeOptimalK_crop` in DSO's `src/util/Undistort.cpp`, from its
/// description): the axis extents sampled in steps of 1e-4 over [-5, 5) and enlarged by 1 %,
/// then the sides whose border line leaves the image (tested on the one coordinate across
/// that side, at the output pixel spacing) shrunk by 0.5 % per round, only the wider pair when
/// both pairs are out. `None` when DSO would give up (no valid axis sample, or 500 rounds).
fn dso_crop_rect(input: &CameraModel, in_size: ImageSize, out: ImageSize) -> Option<[f64; 4]> {
    let (wm1, hm1) = ((in_size.width - 1) as f64, (in_size.height - 1) as f64);
    let raw = |x: f64, y: f64| input.project_normalized([x, y]);
    let x_in = |p: Option<[f64; 2]>| p.is_some_and(|p| p[0] > 0.0 && p[0] < wm1);
    let y_in = |p: Option<[f64; 2]>| p.is_some_and(|p| p[1] > 0.0 && p[1] < hm1);
    let mut x_range: Option<(f64, f64)> = None;
    let mut y_range: Option<(f64, f64)> = None;
    for i in 0..100_000 {
        let t = (i as f64 - 50_000.0) / 10_000.0;
        if x_in(raw(t, 0.0)) {
            x_range = Some(x_range.map_or((t, t), |(a, _)| (a, t)));
        }
        if y_in(raw(0.0, t)) {
            y_range = Some(y_range.map_or((t, t), |(a, _)| (a, t)));
        }
    }
    let (x0, x1) = x_range?;
    let (y0, y1) = y_range?;
    let mut r = [x0 * 1.01, x1 * 1.01, y0 * 1.01, y1 * 1.01];
    let (ow, oh) = (out.width, out.height);
    for _ in 0..=500 {
        let mut out_of = [false; 4];
        for j in 0..oh {
            let y = r[2] + (r[3] - r[2]) * j as f64 / (oh - 1) as f64;
            out_of[0] |= !x_in(raw(r[0], y));
            out_of[1] |= !x_in(raw(r[1], y));
        }
        for i in 0..ow {
            let x = r[0] + (r[1] - r[0]) * i as f64 / (ow - 1) as f64;
            out_of[2] |= !y_in(raw(x, r[2]));
            out_of[3] |= !y_in(raw(x, r[3]));
        }
        if (out_of[0] || out_of[1]) && (out_of[2] || out_of[3]) {
            if r[1] - r[0] > r[3] - r[2] {
                out_of[2] = false;
                out_of[3] = false;
            } else {
                out_of[0] = false;
                out_of[1] = false;
            }
        }
        if !out_of.iter().any(|o| *o) {
            return Some(r);
        }
        for (side, out) in r.iter_mut().zip(out_of) {
            if out {
                *side *= 0.995;
            }
        }
    }
    None
}

/// The largest uniform shrink of `rect` towards the optical axis whose border fits.
fn shrink_to_fit(
    input: &CameraModel,
    in_size: ImageSize,
    out: ImageSize,
    rect: [f64; 4],
) -> Option<[f64; 4]> {
    let scaled = |s: f64| rect.map(|v| v * s);
    if border_fits(input, in_size, out, rect) {
        return Some(rect);
    }
    let (mut lo, mut hi) = (0.0, 1.0);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if border_fits(input, in_size, out, scaled(mid)) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    (lo > 0.0).then(|| scaled(lo))
}

/// Moves side `i` of `rect` (0 left, 1 right, 2 top, 3 bottom) outward to the last position
/// where the border still fits: doubling steps out, then bisection to the last bit.
fn grow_side(
    input: &CameraModel,
    in_size: ImageSize,
    out: ImageSize,
    rect: &mut [f64; 4],
    i: usize,
) -> bool {
    let sign = if i.is_multiple_of(2) { -1.0 } else { 1.0 };
    let start = rect[i];
    let fits = |v: f64| {
        let mut r = *rect;
        r[i] = v;
        border_fits(input, in_size, out, r)
    };
    // the largest extent tried: beyond DSO's sampled range [-5, 5) and far beyond any lens
    let cap = (64.0 * start.abs()).max(10.0);
    let mut lo = start;
    let mut step = 1e-3 * start.abs().max(1e-3);
    let mut hi = None;
    while (lo + sign * step).abs() <= cap {
        let cand = lo + sign * step;
        if fits(cand) {
            lo = cand;
            step *= 2.0;
        } else {
            hi = Some(cand);
            break;
        }
    }
    if let Some(mut hi) = hi {
        for _ in 0..80 {
            let mid = 0.5 * (lo + hi);
            if mid == lo || mid == hi {
                break;
            }
            if fits(mid) {
                lo = mid;
            } else {
                hi = mid;
            }
        }
    }
    rect[i] = lo;
    (lo - start).abs() > 1e-12 * start.abs().max(1e-12)
}

fn crop_numeric(
    input: &CameraModel,
    in_size: ImageSize,
    out_size: ImageSize,
) -> Result<Intrinsics, CameraError> {
    let fail = |reason: &str| CameraError::NoValidCrop {
        model: input.name(),
        reason: reason.into(),
    };
    // Start from DSO's crop; when DSO would give up, from a small square around the axis.
    let start = dso_crop_rect(input, in_size, out_size).unwrap_or([-1e-3, 1e-3, -1e-3, 1e-3]);
    if !(start[0] < 0.0 && start[1] > 0.0 && start[2] < 0.0 && start[3] > 0.0) {
        return Err(fail("the principal point is not inside the image"));
    }
    let mut rect = shrink_to_fit(input, in_size, out_size, start)
        .ok_or_else(|| fail("no rectangle around the principal point fits in the image"))?;
    for _round in 0..20 {
        let mut moved = false;
        for i in 0..4 {
            moved |= grow_side(input, in_size, out_size, &mut rect, i);
        }
        if !moved {
            break;
        }
    }
    // The border test implies the interior for well-behaved models; verify every pixel and
    // shrink further if a strongly distorted model folds inward.
    for _ in 0..400 {
        let k = k_from_rect(rect, out_size);
        let map = RectifyMap::new(input, in_size, k, out_size)?;
        if map.invalid_count() == 0 {
            return Ok(k);
        }
        rect = rect.map(|v| v * 0.995);
    }
    Err(fail(&format!(
        "no centred rectangle inside the image (last tried {rect:?})"
    )))
}

/// A precomputed map from every output pixel to its bilinear source in the input image.
///
/// Each output pixel stores the index of the top-left source pixel and the fractional offsets,
/// as `f32` for float images and as 8-bit fixed point for `u8` images. Output pixels whose
/// source falls outside `[0, w-1] x [0, h-1]` are invalid: the remap writes `0` (u8) or NaN
/// (f32) there and [`RectifyMap::valid_mask`] tells which they are.
#[derive(Clone, Debug)]
pub struct RectifyMap {
    input: ImageSize,
    output: ImageSize,
    camera: Intrinsics,
    index: Vec<u32>,
    frac: Vec<[f32; 2]>,
    fixed: FixedMap,
    invalid: usize,
}

impl RectifyMap {
    /// Builds the map from the output pinhole `out_camera` of size `out_size` to `input`.
    ///
    /// A pinhole input is mapped in closed form (`x_in = a x_out + b` per axis), so that the
    /// identity is exact. Sources at most a millionth of a pixel outside the input image are
    /// moved onto its border; farther out they are invalid.
    pub fn new(
        input: &CameraModel,
        in_size: ImageSize,
        out_camera: Intrinsics,
        out_size: ImageSize,
    ) -> Result<RectifyMap, CameraError> {
        RectifyMap::build(in_size, out_size, out_camera, source_in(input, out_camera))
    }

    /// The map of output `none`: the raw image passes through unchanged at the input size;
    /// at another size it is resized (pixel areas, sources clamped to the image like any
    /// image resize). `camera` is the output K (see [`output_intrinsics`]).
    pub fn passthrough(
        in_size: ImageSize,
        camera: Intrinsics,
        out_size: ImageSize,
    ) -> Result<RectifyMap, CameraError> {
        let sx = in_size.width as f64 / out_size.width as f64;
        let sy = in_size.height as f64 / out_size.height as f64;
        let (wm1, hm1) = (
            in_size.width.saturating_sub(1) as f64,
            in_size.height.saturating_sub(1) as f64,
        );
        let same = in_size == out_size;
        RectifyMap::build(in_size, out_size, camera, |u, v| {
            if same {
                Some([u as f64, v as f64])
            } else {
                Some([
                    ((u as f64 + 0.5) * sx - 0.5).clamp(0.0, wm1),
                    ((v as f64 + 0.5) * sy - 0.5).clamp(0.0, hm1),
                ])
            }
        })
    }

    /// The map from `source` (the input position of output pixel `(u, v)`, if any), its
    /// rows computed in parallel (the camera model's trigonometry is most of the cost).
    fn build(
        in_size: ImageSize,
        out_size: ImageSize,
        camera: Intrinsics,
        source: impl Fn(usize, usize) -> Option<[f64; 2]> + Sync,
    ) -> Result<RectifyMap, CameraError> {
        use rayon::prelude::*;
        let in_size = in_size.validate()?;
        let out_size = out_size.validate()?;
        let (wm1, hm1) = (in_size.width - 1, in_size.height - 1);
        let (n, ow) = (out_size.pixels(), out_size.width);
        let mut index = vec![u32::MAX; n];
        let mut frac = vec![[0f32; 2]; n];
        let mut fixed = FixedMap::invalid(n);
        let invalid = index
            .par_chunks_mut(ow)
            .zip(frac.par_chunks_mut(ow))
            .zip(fixed.rows_mut(ow))
            .enumerate()
            .map(|(v, ((index, frac), mut fixed))| {
                let mut invalid = 0;
                for u in 0..ow {
                    let Some(src) = source(u, v).and_then(|s| snap_inside(s, in_size)) else {
                        invalid += 1;
                        continue;
                    };
                    // Keep x0 <= w-2 so that x0 + 1 is in the image; x == w-1 gives fx = 1.
                    let x0 = (src[0].floor() as usize).min(wm1 - 1);
                    let y0 = (src[1].floor() as usize).min(hm1 - 1);
                    let (fx, fy) = (src[0] - x0 as f64, src[1] - y0 as f64);
                    let i = (y0 * in_size.width + x0) as u32;
                    index[u] = i;
                    frac[u] = [fx as f32, fy as f32];
                    fixed.set(u, i, packed_weights(fx, fy));
                }
                invalid
            })
            .sum();
        Ok(RectifyMap {
            input: in_size,
            output: out_size,
            camera,
            index,
            frac,
            fixed,
            invalid,
        })
    }

    /// Builds the map for the output requested by `mode` (see [`output_intrinsics`]); `none`
    /// is [`RectifyMap::passthrough`], whatever the input model.
    pub fn for_mode(
        input: &CameraModel,
        in_size: ImageSize,
        mode: &OutputMode,
        out_size: ImageSize,
    ) -> Result<RectifyMap, CameraError> {
        let k = output_intrinsics(input, in_size, mode, out_size)?;
        match mode {
            OutputMode::None => RectifyMap::passthrough(in_size, k, out_size),
            _ => RectifyMap::new(input, in_size, k, out_size),
        }
    }

    /// The map of [`RectifyMap::for_mode`] (the same output camera, the same valid pixels) for
    /// input frames decoded at half their width and height in the DCT domain (`in_size`
    /// halved, rounded up): pixel `(x, y)` of the full frame is `(x / 2 - 1/4, y / 2 - 1/4)`
    /// of the half frame, whose pixel `i` is centred on full pixels `2i` and `2i + 1`. Sources
    /// within a quarter of a half-frame pixel of its border sample the border. The output must
    /// be at most half the input's width and height (else the full decode is the better
    /// image): an error otherwise, and for `none`.
    pub fn for_mode_half_input(
        input: &CameraModel,
        in_size: ImageSize,
        mode: &OutputMode,
        out_size: ImageSize,
    ) -> Result<RectifyMap, CameraError> {
        let in_size = in_size.validate()?;
        let out_size = out_size.validate()?;
        let half = ImageSize::new(in_size.width.div_ceil(2), in_size.height.div_ceil(2));
        if *mode == OutputMode::None
            || out_size.width > half.width
            || out_size.height > half.height
            || half.width < 2
            || half.height < 2
        {
            return Err(CameraError::InvalidValue {
                line: 0,
                message: format!(
                    "half-size decoding needs an output of at most half the input ({half} for {in_size}), and not `none`; asked for `{mode}` at {out_size}"
                ),
            });
        }
        let k = output_intrinsics(input, in_size, mode, out_size)?;
        let (hw, hh) = ((half.width - 1) as f64, (half.height - 1) as f64);
        let to_half = move |s: [f64; 2]| {
            [
                (0.5 * s[0] - 0.25).clamp(0.0, hw),
                (0.5 * s[1] - 0.25).clamp(0.0, hh),
            ]
        };
        let source = source_in(input, k);
        RectifyMap::build(half, out_size, k, |u, v| {
            source(u, v)
                .and_then(|s| snap_inside(s, in_size))
                .map(to_half)
        })
    }

    /// The output pinhole camera.
    pub fn camera(&self) -> Intrinsics {
        self.camera
    }

    /// The input image size.
    pub fn input_size(&self) -> ImageSize {
        self.input
    }

    /// The output image size.
    pub fn output_size(&self) -> ImageSize {
        self.output
    }

    /// Number of output pixels whose source falls outside the input image.
    pub fn invalid_count(&self) -> usize {
        self.invalid
    }

    /// `true` for output pixels that have a source in the input image.
    pub fn valid_mask(&self) -> Image<bool> {
        Image::from_fn(self.output.width, self.output.height, |x, y| {
            self.index[y * self.output.width + x] != u32::MAX
        })
    }

    /// The source position (input pixel coordinates) of output pixel `(u, v)`, if valid.
    pub fn source(&self, u: usize, v: usize) -> Option<[f64; 2]> {
        if u >= self.output.width || v >= self.output.height {
            return None;
        }
        let i = v * self.output.width + u;
        let idx = self.index[i];
        if idx == u32::MAX {
            return None;
        }
        let idx = idx as usize;
        let f = self.frac[i];
        Some([
            (idx % self.input.width) as f64 + f[0] as f64,
            (idx / self.input.width) as f64 + f[1] as f64,
        ])
    }

    fn check_input<T: Copy>(&self, src: &Image<T>) -> Result<(), CameraError> {
        if src.size() != (self.input.width, self.input.height) {
            return Err(CameraError::ImageSizeMismatch {
                width: self.input.width,
                height: self.input.height,
                got_width: src.width(),
                got_height: src.height(),
            });
        }
        Ok(())
    }

    fn check_output<T: Copy>(&self, dst: &Image<T>) -> Result<(), CameraError> {
        if dst.size() != (self.output.width, self.output.height) {
            return Err(CameraError::ImageSizeMismatch {
                width: self.output.width,
                height: self.output.height,
                got_width: dst.width(),
                got_height: dst.height(),
            });
        }
        Ok(())
    }

    /// Bilinear remap of an 8-bit image with 8-bit fixed-point weights, rounded to nearest
    /// (within one grey level of the exact interpolation); invalid pixels are 0.
    pub fn remap_u8(&self, src: &Image<u8>) -> Result<Image<u8>, CameraError> {
        let mut out = Image::filled(self.output.width, self.output.height, 0u8);
        self.remap_u8_into(src, &mut out)?;
        Ok(out)
    }

    /// [`RectifyMap::remap_u8`] into an existing output image (no allocation).
    pub fn remap_u8_into(&self, src: &Image<u8>, dst: &mut Image<u8>) -> Result<(), CameraError> {
        self.check_input(src)?;
        self.check_output(dst)?;
        self.fixed
            .remap_u8(src.data(), self.input.width, dst.data_mut());
        Ok(())
    }

    /// Bilinear remap of a 16-bit image, rounded to nearest; invalid pixels are 0. Exact
    /// where the source is a pixel centre (an identity map copies the image).
    pub fn remap_u16(&self, src: &Image<u16>) -> Result<Image<u16>, CameraError> {
        self.check_input(src)?;
        let s = src.data();
        let w = self.input.width;
        let mut out = Image::filled(self.output.width, self.output.height, 0u16);
        for ((o, &idx), &[fx, fy]) in out.data_mut().iter_mut().zip(&self.index).zip(&self.frac) {
            if idx == u32::MAX {
                continue;
            }
            let i = idx as usize;
            let (a, b) = (s[i] as f32, s[i + 1] as f32);
            let (c, d) = (s[i + w] as f32, s[i + w + 1] as f32);
            let top = a + fx * (b - a);
            let bottom = c + fx * (d - c);
            *o = (top + fy * (bottom - top)).round().clamp(0.0, 65535.0) as u16;
        }
        Ok(out)
    }

    /// Bilinear remap of a float image; invalid pixels are NaN.
    pub fn remap_f32(&self, src: &Image<f32>) -> Result<Image<f32>, CameraError> {
        let mut out = Image::filled(self.output.width, self.output.height, 0f32);
        self.remap_f32_into(src, &mut out)?;
        Ok(out)
    }

    /// [`RectifyMap::remap_f32`] into an existing output image (no allocation).
    pub fn remap_f32_into(
        &self,
        src: &Image<f32>,
        dst: &mut Image<f32>,
    ) -> Result<(), CameraError> {
        self.check_input(src)?;
        self.check_output(dst)?;
        let s = src.data();
        let w = self.input.width;
        let out = dst.data_mut();
        for ((o, &idx), &[fx, fy]) in out.iter_mut().zip(&self.index).zip(&self.frac) {
            if idx == u32::MAX {
                *o = f32::NAN;
                continue;
            }
            let i = idx as usize;
            let top = s[i] + fx * (s[i + 1] - s[i]);
            let bottom = s[i + w] + fx * (s[i + w + 1] - s[i + w]);
            *o = top + fy * (bottom - top);
        }
        Ok(())
    }

    /// Fused bilinear remap for photometric correction at 8-bit speed: each source value is
    /// looked up in a 16-bit table `lut`, interpolated with the 8-bit fixed-point weights, and
    /// multiplied by the per-output-pixel `gain` (which includes the 1/256 of the weights) and
    /// by `factor`; the result is rounded and clamped to `0..=max`. Invalid pixels are 0.
    #[allow(clippy::too_many_arguments)]
    pub fn remap_lut_gain_into<T: Copy + Default + TryFrom<u32>>(
        &self,
        src: &Image<u8>,
        lut: &[u16; 256],
        gain: &[f32],
        factor: f32,
        max: u32,
        dst: &mut Image<T>,
    ) -> Result<(), CameraError> {
        self.check_input(src)?;
        self.check_output(dst)?;
        if gain.len() != self.fixed.len() {
            return Err(CameraError::BufferLength {
                width: self.output.width,
                height: self.output.height,
                len: gain.len(),
            });
        }
        let g = LutGain {
            lut,
            gain,
            factor,
            max: max as f32,
        };
        self.fixed
            .remap_lut_gain(src.data(), self.input.width, &g, dst.data_mut());
        Ok(())
    }

    /// Bilinear remap of an 8-bit image straight to float, with a per-value lookup table
    /// applied to the four source pixels before interpolation (for example the inverse
    /// response). Invalid pixels are NaN.
    pub fn remap_u8_lut_into(
        &self,
        src: &Image<u8>,
        lut: &[f32; 256],
        dst: &mut Image<f32>,
    ) -> Result<(), CameraError> {
        self.check_input(src)?;
        self.check_output(dst)?;
        let s = src.data();
        let w = self.input.width;
        let out = dst.data_mut();
        for ((o, &idx), &[fx, fy]) in out.iter_mut().zip(&self.index).zip(&self.frac) {
            if idx == u32::MAX {
                *o = f32::NAN;
                continue;
            }
            let i = idx as usize;
            let (a, b) = (lut[s[i] as usize], lut[s[i + 1] as usize]);
            let (c, d) = (lut[s[i + w] as usize], lut[s[i + w + 1] as usize]);
            let top = a + fx * (b - a);
            let bottom = c + fx * (d - c);
            *o = top + fy * (bottom - top);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use crate::fixed::weights;

    #[test]
    fn fixed_point_weights_are_non_negative_and_sum_to_256() {
        for i in 0..=200 {
            for j in 0..=200 {
                let (fx, fy) = (i as f64 / 200.0, j as f64 / 200.0);
                let e = weights(fx, fy);
                assert_eq!(e.iter().map(|&w| w as u32).sum::<u32>(), 256);
                // each weight within one unit of the exact bilinear weight
                let exact = [
                    (1.0 - fx) * (1.0 - fy),
                    fx * (1.0 - fy),
                    (1.0 - fx) * fy,
                    fx * fy,
                ];
                for (w, x) in e.iter().zip(exact) {
                    assert!((*w as f64 - x * 256.0).abs() <= 1.5, "{fx} {fy} {e:?}");
                }
            }
        }
    }
}
