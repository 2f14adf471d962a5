//! Detection of square fiducials of the original ArUco dictionary (1024 ids, 5x5 bits, each
//! row one of four 5-bit words) in a pinhole image, with sub-pixel corner refinement, and the
//! plane pose from the four corners.
//!
//! Corner order follows the marker bitmap: corner 0 is its top-left, then clockwise. The
//! printed marker, black border included, is the unit square of the plane centred at the
//! origin, x to the right along the bitmap rows and y towards the bitmap's top: corner 0 at
//! (-0.5, 0.5), corner 1 at (0.5, 0.5).

use camera_model::{Image, Intrinsics};
use nalgebra::{Matrix3, Rotation3, SMatrix, SVector, Vector3};

use crate::PlanePose;

/// The four row words of the original ArUco dictionary (bit 1 = white, most significant bit
/// is the leftmost cell); a row's word index is two bits of the id, the top row the most
/// significant.
pub const ARUCO_WORDS: [u8; 4] = [0b10000, 0b10111, 0b01001, 0b01110];

/// A detected marker.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MarkerDetection {
    /// Its id (0..1024).
    pub id: u16,
    /// Pixel corners: bitmap top-left, top-right, bottom-right, bottom-left.
    pub corners: [[f64; 2]; 4],
}

/// The 5x5 inner bits of a marker id (`true` = white), row 0 at the top.
pub fn aruco_bits(id: u16) -> [[bool; 5]; 5] {
    let mut b = [[false; 5]; 5];
    for (y, row) in b.iter_mut().enumerate() {
        let word = ARUCO_WORDS[((id >> (2 * (4 - y))) & 3) as usize];
        for (x, v) in row.iter_mut().enumerate() {
            *v = (word >> (4 - x)) & 1 == 1;
        }
    }
    b
}

/// Decodes 5x5 bits (already rotated upright) to an id, if every row is a dictionary word.
fn decode_upright(bits: &[[bool; 5]; 5]) -> Option<u16> {
    let mut id = 0u16;
    for row in bits {
        let word = row.iter().fold(0u8, |w, &b| (w << 1) | u8::from(b));
        let k = ARUCO_WORDS.iter().position(|&x| x == word)?;
        id = (id << 2) | k as u16;
    }
    Some(id)
}

#[inline]
fn sample(img: &Image<u8>, x: f64, y: f64) -> f64 {
    let (w, h) = img.size();
    if !(x >= 0.0 && y >= 0.0 && x <= (w - 1) as f64 && y <= (h - 1) as f64) {
        return f64::NAN;
    }
    let x0 = (x as usize).min(w - 2);
    let y0 = (y as usize).min(h - 2);
    let (fx, fy) = (x - x0 as f64, y - y0 as f64);
    let d = img.data();
    let p = |xx: usize, yy: usize| d[yy * w + xx] as f64;
    let top = p(x0, y0) + fx * (p(x0 + 1, y0) - p(x0, y0));
    let bot = p(x0, y0 + 1) + fx * (p(x0 + 1, y0 + 1) - p(x0, y0 + 1));
    top + fy * (bot - top)
}

/// Homography (row-major 3x3, `h22 = 1`) mapping `src[i]` to `dst[i]` for four
/// correspondences: the 8x8 linear system of the direct linear transform, solved by LU with
/// partial pivoting. `None` when three of the points are collinear (the system is singular).
pub fn homography(src: &[[f64; 2]; 4], dst: &[[f64; 2]; 4]) -> Option<[[f64; 3]; 3]> {
    let mut a = SMatrix::<f64, 8, 8>::zeros();
    let mut b = SVector::<f64, 8>::zeros();
    for i in 0..4 {
        let ([x, y], [u, v]) = (src[i], dst[i]);
        a.set_row(
            2 * i,
            &SMatrix::<f64, 1, 8>::from_row_slice(&[x, y, 1.0, 0.0, 0.0, 0.0, -u * x, -u * y]),
        );
        a.set_row(
            2 * i + 1,
            &SMatrix::<f64, 1, 8>::from_row_slice(&[0.0, 0.0, 0.0, x, y, 1.0, -v * x, -v * y]),
        );
        b[2 * i] = u;
        b[2 * i + 1] = v;
    }
    let lu = a.lu();
    // relative pivot threshold: a (nearly) singular system has no unique homography
    let u = lu.u();
    let scale = a.amax().max(1e-300);
    if (0..8).any(|k| u[(k, k)].abs() < 1e-12 * scale) {
        return None;
    }
    let h = lu.solve(&b)?;
    h.iter().all(|v| v.is_finite()).then_some([
        [h[0], h[1], h[2]],
        [h[3], h[4], h[5]],
        [h[6], h[7], 1.0],
    ])
}

#[inline]
fn apply_h(h: &[[f64; 3]; 3], p: [f64; 2]) -> [f64; 2] {
    let w = h[2][0] * p[0] + h[2][1] * p[1] + h[2][2];
    [
        (h[0][0] * p[0] + h[0][1] * p[1] + h[0][2]) / w,
        (h[1][0] * p[0] + h[1][1] * p[1] + h[1][2]) / w,
    ]
}

/// Dark connected components of an adaptive threshold, as pixel lists.
fn dark_components(img: &Image<u8>, min_area: usize) -> Vec<Vec<u32>> {
    let (w, h) = img.size();
    let d = img.data();
    // integral image for the local mean
    let mut integ = vec![0u64; (w + 1) * (h + 1)];
    for y in 0..h {
        let mut row = 0u64;
        for x in 0..w {
            row += d[y * w + x] as u64;
            integ[(y + 1) * (w + 1) + x + 1] = integ[y * (w + 1) + x + 1] + row;
        }
    }
    let r = (w.max(h) / 24).max(7);
    let mut dark = vec![false; w * h];
    for y in 0..h {
        let (y0, y1) = (y.saturating_sub(r), (y + r + 1).min(h));
        for x in 0..w {
            let (x0, x1) = (x.saturating_sub(r), (x + r + 1).min(w));
            let s = integ[y1 * (w + 1) + x1] + integ[y0 * (w + 1) + x0]
                - integ[y0 * (w + 1) + x1]
                - integ[y1 * (w + 1) + x0];
            let mean = s as f64 / ((x1 - x0) * (y1 - y0)) as f64;
            dark[y * w + x] = (d[y * w + x] as f64) < mean - 7.0;
        }
    }
    let mut seen = vec![false; w * h];
    let mut out = Vec::new();
    let mut stack = Vec::new();
    for start in 0..w * h {
        if !dark[start] || seen[start] {
            continue;
        }
        let mut comp = Vec::new();
        seen[start] = true;
        stack.push(start);
        while let Some(p) = stack.pop() {
            comp.push(p as u32);
            let (x, y) = (p % w, p / w);
            let mut push = |q: usize| {
                if dark[q] && !seen[q] {
                    seen[q] = true;
                    stack.push(q);
                }
            };
            if x > 0 {
                push(p - 1);
            }
            if x + 1 < w {
                push(p + 1);
            }
            if y > 0 {
                push(p - w);
            }
            if y + 1 < h {
                push(p + w);
            }
        }
        if comp.len() >= min_area {
            out.push(comp);
        }
    }
    out
}

fn cross(o: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
}

/// Convex hull (Andrew's monotone chain), counter-clockwise in image coordinates.
fn convex_hull(mut pts: Vec<[f64; 2]>) -> Vec<[f64; 2]> {
    pts.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    pts.dedup();
    if pts.len() < 3 {
        return pts;
    }
    let mut lower: Vec<[f64; 2]> = Vec::new();
    for &p in &pts {
        while lower.len() >= 2 && cross(lower[lower.len() - 2], lower[lower.len() - 1], p) <= 0.0 {
            lower.pop();
        }
        lower.push(p);
    }
    let mut upper: Vec<[f64; 2]> = Vec::new();
    for &p in pts.iter().rev() {
        while upper.len() >= 2 && cross(upper[upper.len() - 2], upper[upper.len() - 1], p) <= 0.0 {
            upper.pop();
        }
        upper.push(p);
    }
    lower.pop();
    upper.pop();
    lower.extend(upper);
    lower
}

fn dist2(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)
}

/// The quadrilateral of a convex hull: its diameter's ends and the farthest hull points on
/// either side of the diameter, in hull order.
fn hull_quad(hull: &[[f64; 2]]) -> Option<[[f64; 2]; 4]> {
    let n = hull.len();
    if n < 4 {
        return None;
    }
    let (mut ia, mut ic, mut best) = (0, 0, 0.0);
    for i in 0..n {
        for j in i + 1..n {
            let d = dist2(hull[i], hull[j]);
            if d > best {
                (ia, ic, best) = (i, j, d);
            }
        }
    }
    let (a, c) = (hull[ia], hull[ic]);
    let side = |p: [f64; 2]| cross(a, c, p);
    let ib = (ia + 1..ic).max_by(|&i, &j| side(hull[i]).abs().total_cmp(&side(hull[j]).abs()))?;
    let id = (ic + 1..n)
        .chain(0..ia)
        .max_by(|&i, &j| side(hull[i]).abs().total_cmp(&side(hull[j]).abs()))?;
    Some([a, hull[ib], c, hull[id]])
}

fn poly_area(q: &[[f64; 2]]) -> f64 {
    let n = q.len();
    (0..n)
        .map(|i| q[i][0] * q[(i + 1) % n][1] - q[(i + 1) % n][0] * q[i][1])
        .sum::<f64>()
        .abs()
        / 2.0
}

/// Reads the 7x7 cells of a candidate quad (visually clockwise in image coordinates) and
/// returns the id and the index of the quad corner that is the bitmap's top-left.
fn read_marker(img: &Image<u8>, quad: &[[f64; 2]; 4]) -> Option<(u16, usize)> {
    for start in 0..4 {
        let q = [0, 1, 2, 3].map(|k| quad[(start + k) % 4]);
        if let Some(id) = read_upright(img, &q) {
            return Some((id, start));
        }
    }
    None
}

/// Reads the marker with `quad[0]` as the bitmap's top-left corner.
fn read_upright(img: &Image<u8>, quad: &[[f64; 2]; 4]) -> Option<u16> {
    let cells = [[0.0, 0.0], [7.0, 0.0], [7.0, 7.0], [0.0, 7.0]];
    let h = homography(&cells, quad)?;
    let mut v = [[0.0f64; 7]; 7];
    for (r, row) in v.iter_mut().enumerate() {
        for (c, val) in row.iter_mut().enumerate() {
            let mut s = 0.0;
            for (dx, dy) in [
                (0.35, 0.35),
                (0.65, 0.35),
                (0.35, 0.65),
                (0.65, 0.65),
                (0.5, 0.5),
            ] {
                let p = apply_h(&h, [c as f64 + dx, r as f64 + dy]);
                let x = sample(img, p[0], p[1]);
                if x.is_nan() {
                    return None;
                }
                s += x;
            }
            *val = s / 5.0;
        }
    }
    let all: Vec<f64> = v.iter().flatten().copied().collect();
    let (lo, hi) = all
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), &x| (a.min(x), b.max(x)));
    if hi - lo < 20.0 {
        return None;
    }
    let thr = 0.5 * (lo + hi);
    for i in 0..7 {
        for (r, c) in [(0, i), (6, i), (i, 0), (i, 6)] {
            if v[r][c] > thr {
                return None;
            }
        }
    }
    let mut bits = [[false; 5]; 5];
    for (y, row) in bits.iter_mut().enumerate() {
        for (x, b) in row.iter_mut().enumerate() {
            *b = v[y + 1][x + 1] > thr;
        }
    }
    decode_upright(&bits)
}

/// Refines the quad's corners to sub-pixel accuracy: each edge is located along its normal at
/// the midpoint between the dark inside and the bright outside, a line is fitted through the
/// edge points, and corners are intersections of adjacent lines.
fn refine_corners(img: &Image<u8>, quad: [[f64; 2]; 4]) -> [[f64; 2]; 4] {
    let mut q = quad;
    for _ in 0..3 {
        let centre = [
            q.iter().map(|p| p[0]).sum::<f64>() / 4.0,
            q.iter().map(|p| p[1]).sum::<f64>() / 4.0,
        ];
        let mut lines: Vec<Option<([f64; 2], [f64; 2])>> = Vec::with_capacity(4);
        for k in 0..4 {
            let (a, b) = (q[k], q[(k + 1) % 4]);
            let len = dist2(a, b).sqrt();
            let dir = [(b[0] - a[0]) / len, (b[1] - a[1]) / len];
            let mut nrm = [-dir[1], dir[0]];
            let mid = [(a[0] + b[0]) / 2.0, (a[1] + b[1]) / 2.0];
            if (centre[0] - mid[0]) * nrm[0] + (centre[1] - mid[1]) * nrm[1] > 0.0 {
                nrm = [-nrm[0], -nrm[1]]; // point outwards
            }
            let reach = (len / 14.0).clamp(2.0, 8.0);
            let mut pts = Vec::new();
            let n = 24;
            for i in 0..n {
                let s = 0.15 + 0.7 * i as f64 / (n - 1) as f64;
                let base = [a[0] + s * (b[0] - a[0]), a[1] + s * (b[1] - a[1])];
                // profile from inside (dark) to outside (bright)
                let steps = (reach * 8.0) as i32;
                let prof: Vec<f64> = (-steps..=steps)
                    .map(|j| {
                        let o = j as f64 / 8.0;
                        sample(img, base[0] + o * nrm[0], base[1] + o * nrm[1])
                    })
                    .collect();
                if prof.iter().any(|x| x.is_nan()) {
                    continue;
                }
                let inside = prof[..4].iter().sum::<f64>() / 4.0;
                let outside = prof[prof.len() - 4..].iter().sum::<f64>() / 4.0;
                if outside - inside < 15.0 {
                    continue;
                }
                let mid_level = 0.5 * (inside + outside);
                // first crossing from the inside
                if let Some(j) =
                    (1..prof.len()).find(|&j| prof[j - 1] < mid_level && prof[j] >= mid_level)
                {
                    let f = (mid_level - prof[j - 1]) / (prof[j] - prof[j - 1]);
                    let o = ((j - 1) as f64 + f - steps as f64) / 8.0;
                    pts.push([base[0] + o * nrm[0], base[1] + o * nrm[1]]);
                }
            }
            lines.push(fit_line(&pts));
        }
        let mut next = q;
        for k in 0..4 {
            // corner k joins edge k-1 and edge k
            if let (Some(l1), Some(l2)) = (lines[(k + 3) % 4], lines[k]) {
                if let Some(p) = intersect(l1, l2) {
                    if dist2(p, q[k]) < 25.0 {
                        next[k] = p;
                    }
                }
            }
        }
        q = next;
    }
    q
}

/// Total-least-squares line through points: (a point, a unit direction).
fn fit_line(pts: &[[f64; 2]]) -> Option<([f64; 2], [f64; 2])> {
    if pts.len() < 5 {
        return None;
    }
    let n = pts.len() as f64;
    let m = [
        pts.iter().map(|p| p[0]).sum::<f64>() / n,
        pts.iter().map(|p| p[1]).sum::<f64>() / n,
    ];
    let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
    for p in pts {
        let (dx, dy) = (p[0] - m[0], p[1] - m[1]);
        sxx += dx * dx;
        sxy += dx * dy;
        syy += dy * dy;
    }
    let theta = 0.5 * (2.0 * sxy).atan2(sxx - syy);
    Some((m, [theta.cos(), theta.sin()]))
}

fn intersect(l1: ([f64; 2], [f64; 2]), l2: ([f64; 2], [f64; 2])) -> Option<[f64; 2]> {
    let (p, r) = l1;
    let (q, s) = l2;
    let den = r[0] * s[1] - r[1] * s[0];
    if den.abs() < 1e-9 {
        return None;
    }
    let t = ((q[0] - p[0]) * s[1] - (q[1] - p[1]) * s[0]) / den;
    Some([p[0] + t * r[0], p[1] + t * r[1]])
}

/// Detects original-dictionary ArUco markers in a (pinhole) grey image.
pub fn detect_markers(img: &Image<u8>) -> Vec<MarkerDetection> {
    let (w, h) = img.size();
    let min_area = ((w * h) / 4000).max(64);
    let mut out = Vec::new();
    for comp in dark_components(img, min_area) {
        // skip components touching the image border
        if comp.iter().any(|&p| {
            let (x, y) = (p as usize % w, p as usize / w);
            x == 0 || y == 0 || x == w - 1 || y == h - 1
        }) {
            continue;
        }
        let pts: Vec<[f64; 2]> = comp
            .iter()
            .map(|&p| [(p as usize % w) as f64, (p as usize / w) as f64])
            .collect();
        let hull = convex_hull(pts);
        let Some(mut quad) = hull_quad(&hull) else {
            continue;
        };
        // visually clockwise (positive shoelace sum with y down)
        let signed: f64 = (0..4)
            .map(|i| quad[i][0] * quad[(i + 1) % 4][1] - quad[(i + 1) % 4][0] * quad[i][1])
            .sum();
        if signed < 0.0 {
            quad.swap(1, 3);
        }
        let (ha, qa) = (poly_area(&hull), poly_area(&quad));
        if qa < min_area as f64 || qa < 0.9 * ha {
            continue;
        }
        // pixel centres lie half a pixel inside the outline: grow the quad by 0.5 px
        let c = [
            quad.iter().map(|p| p[0]).sum::<f64>() / 4.0,
            quad.iter().map(|p| p[1]).sum::<f64>() / 4.0,
        ];
        let grown = quad.map(|p| {
            let d = [p[0] - c[0], p[1] - c[1]];
            let l = (d[0] * d[0] + d[1] * d[1]).sqrt().max(1e-9);
            [p[0] + 0.7 * d[0] / l, p[1] + 0.7 * d[1] / l]
        });
        let Some((id, start)) = read_marker(img, &grown) else {
            continue;
        };
        let refined = refine_corners(img, grown);
        let corners = [0, 1, 2, 3].map(|k| refined[(start + k) % 4]);
        out.push(MarkerDetection { id, corners });
    }
    out
}

/// The plane points of the marker's corners (corner 0 at (-0.5, 0.5), clockwise).
pub const MARKER_CORNERS: [[f64; 2]; 4] = [[-0.5, 0.5], [0.5, 0.5], [0.5, -0.5], [-0.5, -0.5]];

/// `camera_from_plane` of a marker seen by the pinhole `k`: homography decomposition, then
/// Gauss-Newton on the reprojection error of the four corners (analytic Jacobian, rotation
/// updated on the left by the exponential map, normal equations solved by Cholesky).
pub fn marker_pose(k: &Intrinsics, corners: &[[f64; 2]; 4]) -> Option<PlanePose> {
    let n = corners.map(|p| k.pixel_to_normalized(p));
    let h = Matrix3::from_row_slice(&homography(&MARKER_CORNERS, &n)?.concat());
    let (h1, h2, h3) = (h.column(0), h.column(1), h.column(2));
    let mut lam = 2.0 / (h1.norm() + h2.norm());
    if h3[2] * lam < 0.0 {
        lam = -lam;
    }
    // orthonormalise [r1 r2 r1xr2] (Gram-Schmidt)
    let a = (h1 * lam).normalize();
    let r2 = h2 * lam;
    let b = (r2 - a * a.dot(&r2)).normalize();
    let c = a.cross(&b);
    let mut r = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[a, b, c]));
    let mut t: Vector3<f64> = h3 * lam;
    let plane: [Vector3<f64>; 4] = MARKER_CORNERS.map(|[x, y]| Vector3::new(x, y, 0.0));
    for _ in 0..10 {
        // residuals and Jacobian with respect to (w, dt): R <- exp(w) R, t <- t + dt
        let mut e = SVector::<f64, 8>::zeros();
        let mut jac = SMatrix::<f64, 8, 6>::zeros();
        for i in 0..4 {
            let rx = r * plane[i];
            let pc = rx + t;
            let iz = 1.0 / pc[2];
            e[2 * i] = pc[0] * iz - n[i][0];
            e[2 * i + 1] = pc[1] * iz - n[i][1];
            // d projection / d pc
            let dproj =
                SMatrix::<f64, 2, 3>::new(iz, 0.0, -pc[0] * iz * iz, 0.0, iz, -pc[1] * iz * iz);
            // d pc / d w = -[R X]x, d pc / d t = I
            let jw = dproj * (-rx.cross_matrix());
            jac.fixed_view_mut::<2, 3>(2 * i, 0).copy_from(&jw);
            jac.fixed_view_mut::<2, 3>(2 * i, 3).copy_from(&dproj);
        }
        let dx = (jac.transpose() * jac)
            .cholesky()?
            .solve(&(-jac.transpose() * e));
        r = Rotation3::new(dx.fixed_rows::<3>(0).into_owned()) * r;
        t += dx.fixed_rows::<3>(3);
        if dx.amax() < 1e-12 {
            break;
        }
    }
    let m = r.matrix();
    (t[2] > 0.0 && t.iter().all(|v| v.is_finite()) && m.iter().all(|v| v.is_finite())).then(|| {
        PlanePose {
            r: [0, 1, 2].map(|i| [0, 1, 2].map(|j| m[(i, j)])),
            t: t.into(),
        }
    })
}

/// What the marker of one frame gave.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub enum PoseFromMarker {
    /// The plane pose.
    Found(PlanePose),
    /// No marker with the id.
    NoMarker,
    /// The marker was found but its corners give no pose.
    NoPose,
    /// More than one marker with the id.
    Several(usize),
}

/// The plane pose of a raw frame from its marker: the frame is rectified to the pinhole `k`
/// by `map`, the marker `id` detected, and the pose computed (`camera_from_plane` of the
/// rectified camera, which shares the raw camera's frame).
pub fn pose_from_marker(
    map: &camera_model::RectifyMap,
    k: &Intrinsics,
    frame: &Image<u8>,
    id: u16,
) -> Result<PoseFromMarker, crate::PhotometricError> {
    let rect = map.remap_u8(frame)?;
    let found: Vec<MarkerDetection> = detect_markers(&rect)
        .into_iter()
        .filter(|d| d.id == id)
        .collect();
    Ok(match found.len() {
        0 => PoseFromMarker::NoMarker,
        1 => match marker_pose(k, &found[0].corners) {
            Some(p) => PoseFromMarker::Found(p),
            None => PoseFromMarker::NoPose,
        },
        n => PoseFromMarker::Several(n),
    })
}

/// Parses a plane-poses file: one line per frame, `id r11 r12 r13 r21 r22 r23 r31 r32 r33 tx
/// ty tz` (`camera_from_plane` of the raw camera, the marker the unit square at the origin);
/// `#` comments and blank lines are skipped. Errors name the line.
pub fn parse_plane_poses(text: &str) -> Result<Vec<(String, PlanePose)>, crate::PhotometricError> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut out: Vec<(String, PlanePose)> = Vec::new();
    let mut seen = std::collections::HashMap::new();
    for (i, line) in text.lines().enumerate() {
        let t = line.trim();
        if t.is_empty() || t.starts_with('#') {
            continue;
        }
        let f: Vec<&str> = t.split_whitespace().collect();
        let bad = || {
            crate::PhotometricError::Parse {
            line: i + 1,
            expected: "`id r11 r12 r13 r21 r22 r23 r31 r32 r33 tx ty tz` (13 fields, finite numbers after the id)",
            found: t.chars().take(100).collect(),
        }
        };
        if f.len() != 13 {
            return Err(bad());
        }
        let mut v = [0.0f64; 12];
        for (slot, tok) in v.iter_mut().zip(&f[1..]) {
            *slot = tok
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(bad)?;
        }
        if let Some(first) = seen.insert(f[0].to_string(), i + 1) {
            return Err(crate::PhotometricError::Parse {
                line: i + 1,
                expected: "each frame id once",
                found: format!("`{}` again (first on line {first})", f[0]),
            });
        }
        out.push((
            f[0].to_string(),
            PlanePose {
                r: [[v[0], v[1], v[2]], [v[3], v[4], v[5]], [v[6], v[7], v[8]]],
                t: [v[9], v[10], v[11]],
            },
        ));
    }
    Ok(out)
}
