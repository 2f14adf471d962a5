//! The small amount of 3D linear algebra the evaluation needs: 3-vectors, 3x3 matrices, an
//! accurate 3x3 SVD (one-sided Jacobi), rotation angles and quaternions.

/// A 3-vector.
pub type Vec3 = [f64; 3];
/// A row-major 3x3 matrix.
pub type Mat3 = [[f64; 3]; 3];

/// The identity matrix.
pub const IDENTITY: Mat3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// `a + b`.
#[inline]
pub fn add(a: Vec3, b: Vec3) -> Vec3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// `a - b`.
#[inline]
pub fn sub(a: Vec3, b: Vec3) -> Vec3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// `s * a`.
#[inline]
pub fn scale(a: Vec3, s: f64) -> Vec3 {
    [a[0] * s, a[1] * s, a[2] * s]
}

/// Dot product.
#[inline]
pub fn dot(a: Vec3, b: Vec3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Euclidean norm.
#[inline]
pub fn norm(a: Vec3) -> f64 {
    dot(a, a).sqrt()
}

/// `m * v`.
#[inline]
pub fn mul_vec(m: &Mat3, v: Vec3) -> Vec3 {
    [dot(m[0], v), dot(m[1], v), dot(m[2], v)]
}

/// `a * b`.
pub fn mul(a: &Mat3, b: &Mat3) -> Mat3 {
    let mut r = [[0.0; 3]; 3];
    for (i, row) in r.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j];
        }
    }
    r
}

/// Transpose.
pub fn transpose(a: &Mat3) -> Mat3 {
    [
        [a[0][0], a[1][0], a[2][0]],
        [a[0][1], a[1][1], a[2][1]],
        [a[0][2], a[1][2], a[2][2]],
    ]
}

/// Determinant.
pub fn det(a: &Mat3) -> f64 {
    a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1])
        - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
        + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0])
}

/// Singular value decomposition `a = u * diag(s) * v^T` with `s` sorted decreasingly and
/// `u`, `v` orthogonal (one-sided Jacobi; accurate to a few ulps for 3x3).
pub fn svd3(a: &Mat3) -> (Mat3, Vec3, Mat3) {
    // Work on the columns of w = a * v.
    let mut w = *a;
    let mut v = IDENTITY;
    for _sweep in 0..60 {
        let mut off = 0.0f64;
        for (p, q) in [(0usize, 1usize), (0, 2), (1, 2)] {
            let (mut alpha, mut beta, mut gamma) = (0.0, 0.0, 0.0);
            for row in &w {
                alpha += row[p] * row[p];
                beta += row[q] * row[q];
                gamma += row[p] * row[q];
            }
            if gamma == 0.0 {
                continue;
            }
            let denom = (alpha * beta).sqrt();
            if denom > 0.0 {
                off = off.max(gamma.abs() / denom);
            }
            if gamma.abs() <= 1e-300 {
                continue;
            }
            let zeta = (beta - alpha) / (2.0 * gamma);
            let t = zeta.signum() / (zeta.abs() + (1.0 + zeta * zeta).sqrt());
            let t = if zeta == 0.0 { 1.0 } else { t };
            let c = 1.0 / (1.0 + t * t).sqrt();
            let s = c * t;
            for row in w.iter_mut().chain(v.iter_mut()) {
                let (x, y) = (row[p], row[q]);
                row[p] = c * x - s * y;
                row[q] = s * x + c * y;
            }
        }
        if off < 1e-15 {
            break;
        }
    }
    let mut sv = [0.0; 3];
    for (j, s) in sv.iter_mut().enumerate() {
        *s = (w[0][j] * w[0][j] + w[1][j] * w[1][j] + w[2][j] * w[2][j]).sqrt();
    }
    // sort decreasingly
    let mut order = [0usize, 1, 2];
    order.sort_by(|&i, &j| sv[j].total_cmp(&sv[i]));
    let mut u = [[0.0; 3]; 3];
    let mut vs = [[0.0; 3]; 3];
    let mut s_sorted = [0.0; 3];
    for (k, &j) in order.iter().enumerate() {
        s_sorted[k] = sv[j];
        for i in 0..3 {
            vs[i][k] = v[i][j];
            u[i][k] = if sv[j] > 0.0 { w[i][j] / sv[j] } else { 0.0 };
        }
    }
    // Complete u to an orthonormal basis where singular values vanish.
    complete_basis(&mut u, &s_sorted);
    (u, s_sorted, vs)
}

fn column(m: &Mat3, j: usize) -> Vec3 {
    [m[0][j], m[1][j], m[2][j]]
}

fn set_column(m: &mut Mat3, j: usize, c: Vec3) {
    for (i, row) in m.iter_mut().enumerate() {
        row[j] = c[i];
    }
}

fn cross(a: Vec3, b: Vec3) -> Vec3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn complete_basis(u: &mut Mat3, s: &Vec3) {
    let tiny = s[0] * 1e-300;
    if s[0] <= 0.0 {
        *u = IDENTITY;
        return;
    }
    if s[1] <= tiny {
        let a = column(u, 0);
        // any vector not parallel to a
        let e = if a[0].abs() < 0.9 {
            [1.0, 0.0, 0.0]
        } else {
            [0.0, 1.0, 0.0]
        };
        let b = cross(a, e);
        let b = scale(b, 1.0 / norm(b));
        set_column(u, 1, b);
    }
    if s[2] <= tiny || norm(column(u, 2)) < 0.5 {
        let c = cross(column(u, 0), column(u, 1));
        set_column(u, 2, c);
    }
}

/// Rotation angle of a rotation matrix in radians, accurate for tiny and for near-180-degree
/// angles: `atan2(|axis|, (trace - 1) / 2)` with `axis = vee(R - R^T) / 2`.
pub fn rotation_angle(r: &Mat3) -> f64 {
    let axis = [
        (r[2][1] - r[1][2]) * 0.5,
        (r[0][2] - r[2][0]) * 0.5,
        (r[1][0] - r[0][1]) * 0.5,
    ];
    let cos = (r[0][0] + r[1][1] + r[2][2] - 1.0) * 0.5;
    norm(axis).atan2(cos)
}

/// Rotation matrix of a unit quaternion `(qx, qy, qz, qw)` (normalised first).
pub fn quat_to_matrix(q: [f64; 4]) -> Mat3 {
    let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    let (x, y, z, w) = (q[0] / n, q[1] / n, q[2] / n, q[3] / n);
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - z * w),
            2.0 * (x * z + y * w),
        ],
        [
            2.0 * (x * y + z * w),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - x * w),
        ],
        [
            2.0 * (x * z - y * w),
            2.0 * (y * z + x * w),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
}

/// Unit quaternion `(qx, qy, qz, qw)` of a rotation matrix (Shepperd's method), `qw >= 0`.
pub fn matrix_to_quat(r: &Mat3) -> [f64; 4] {
    let tr = r[0][0] + r[1][1] + r[2][2];
    let q = if tr > 0.0 {
        let s = (tr + 1.0).sqrt() * 2.0;
        [
            (r[2][1] - r[1][2]) / s,
            (r[0][2] - r[2][0]) / s,
            (r[1][0] - r[0][1]) / s,
            0.25 * s,
        ]
    } else if r[0][0] > r[1][1] && r[0][0] > r[2][2] {
        let s = (1.0 + r[0][0] - r[1][1] - r[2][2]).sqrt() * 2.0;
        [
            0.25 * s,
            (r[0][1] + r[1][0]) / s,
            (r[0][2] + r[2][0]) / s,
            (r[2][1] - r[1][2]) / s,
        ]
    } else if r[1][1] > r[2][2] {
        let s = (1.0 + r[1][1] - r[0][0] - r[2][2]).sqrt() * 2.0;
        [
            (r[0][1] + r[1][0]) / s,
            0.25 * s,
            (r[1][2] + r[2][1]) / s,
            (r[0][2] - r[2][0]) / s,
        ]
    } else {
        let s = (1.0 + r[2][2] - r[0][0] - r[1][1]).sqrt() * 2.0;
        [
            (r[0][2] + r[2][0]) / s,
            (r[1][2] + r[2][1]) / s,
            0.25 * s,
            (r[1][0] - r[0][1]) / s,
        ]
    };
    let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    let sign = if q[3] < 0.0 { -1.0 } else { 1.0 };
    [
        q[0] / n * sign,
        q[1] / n * sign,
        q[2] / n * sign,
        q[3] / n * sign,
    ]
}

/// Rotation about a unit axis by `angle` radians (Rodrigues).
pub fn axis_angle(axis: Vec3, angle: f64) -> Mat3 {
    let n = norm(axis);
    let [x, y, z] = scale(axis, 1.0 / n);
    let (s, c) = angle.sin_cos();
    let t = 1.0 - c;
    [
        [t * x * x + c, t * x * y - s * z, t * x * z + s * y],
        [t * x * y + s * z, t * y * y + c, t * y * z - s * x],
        [t * x * z - s * y, t * y * z + s * x, t * z * z + c],
    ]
}
