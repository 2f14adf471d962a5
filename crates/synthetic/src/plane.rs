//! Vignette-calibration data (paper section 2.3.2): a bright, mildly textured planar wall with
//! one printed ArUco marker (original dictionary, id 213 by default), filmed from random poses
//! through the FOV camera with the ground-truth vignette, response, random exposures and
//! noise. The true poses are available in `monovo calib vignette --poses` format.

use crate::camera::{ground_truth_vignette, FovCamera, RayCache, ResponseCurve};
use crate::scene::TextureTable;
use crate::sensor::Sensor;
use nalgebra::{Matrix3, Rotation3, Vector3};

use crate::Rng;

/// The four 5-bit row words of the original ArUco dictionary; a marker's id holds 2 bits per
/// row (most significant first), selecting the word of that row. Bit 1 = white.
pub const ARUCO_WORDS: [u8; 4] = [0b10000, 0b10111, 0b01001, 0b01110];

/// The 7x7 cell bitmap of an original-dictionary ArUco marker (`true` = white), with its
/// black border; row 0 is the top.
pub fn aruco_bitmap(id: u16) -> [[bool; 7]; 7] {
    let mut b = [[false; 7]; 7];
    for y in 0..5 {
        let word = ARUCO_WORDS[((id >> (2 * (4 - y))) & 3) as usize];
        for x in 0..5 {
            b[y + 1][x + 1] = (word >> (4 - x)) & 1 == 1;
        }
    }
    b
}

/// A `camera_from_plane` pose: `point_in_camera = r * point_in_plane + t`, stored as plain
/// arrays (the `--poses` file's numbers).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlanePose {
    /// Rotation (row-major).
    pub r: [[f64; 3]; 3],
    /// Translation.
    pub t: [f64; 3],
}

impl PlanePose {
    /// The rotation as a matrix.
    pub fn rotation(&self) -> Matrix3<f64> {
        Matrix3::from_fn(|i, j| self.r[i][j])
    }

    /// The translation as a vector.
    pub fn translation(&self) -> Vector3<f64> {
        Vector3::from(self.t)
    }

    /// A plane point (`z = 0`) in camera coordinates.
    pub fn plane_to_camera(&self, x: f64, y: f64) -> Vector3<f64> {
        self.rotation() * Vector3::new(x, y, 0.0) + self.translation()
    }
}

/// Settings of a marker-plane sequence.
#[derive(Clone, Copy, Debug)]
pub struct PlaneConfig {
    /// Image width.
    pub width: usize,
    /// Image height.
    pub height: usize,
    /// Number of frames.
    pub frames: usize,
    /// Marker id.
    pub marker_id: u16,
    /// The sensor (noise, saturation, defects, compression).
    pub sensor: Sensor,
    /// The camera response.
    pub response: ResponseCurve,
}

impl Default for PlaneConfig {
    fn default() -> Self {
        PlaneConfig {
            width: 640,
            height: 512,
            frames: 150,
            marker_id: 213,
            sensor: Sensor::default(),
            response: ResponseCurve::Dataset,
        }
    }
}

/// A synthetic vignette-calibration sequence with its truth.
#[derive(Clone, Debug)]
pub struct PlaneSequence {
    /// Settings.
    pub config: PlaneConfig,
    /// The camera (the renderer keeps its rays from the first frame on: change it before
    /// rendering, if at all).
    pub camera: FovCamera,
    /// Per-frame `camera_from_plane`.
    pub poses: Vec<PlanePose>,
    /// Per-frame exposure in ms.
    pub exposures_ms: Vec<f64>,
    /// Ground-truth inverse response.
    pub response: [f64; 256],
    /// Ground-truth vignette (max 1).
    pub vignette: Vec<f32>,
    seed: u64,
    rays: RayCache,
    texture: TextureTable,
}

/// Whether the plane point `(x, y)` is on the marker (the unit square centred at the origin).
fn in_marker(x: f64, y: f64) -> bool {
    (-0.5..0.5).contains(&x) && (-0.5..0.5).contains(&y)
}

/// Largest distance (marker widths, in x or y) of a sub-pixel's plane point from the four's
/// mean for which one texture sample at the mean stands for the four: a fortieth of the
/// finest octave's cell (0.2 marker widths), where the difference is ~2e-6 of the radiance
/// (RMS; see the test). At the plane distances of the set (1.3 to 2.4 marker widths) the
/// sub-pixel points are about 0.002 apart; only grazing views near the horizon exceed it.
const WALL_SPREAD: f64 = 0.005;

/// The mean of four sub-pixel plane points when all are on the wall (off the marker) within
/// [`WALL_SPREAD`] of it.
fn wall_mean(hits: &[Option<[f64; 2]>; 4]) -> Option<[f64; 2]> {
    let mut m = [0.0; 2];
    for hit in hits {
        let p = (*hit)?;
        if in_marker(p[0], p[1]) {
            return None;
        }
        m = [m[0] + 0.25 * p[0], m[1] + 0.25 * p[1]];
    }
    let close = hits
        .iter()
        .flatten()
        .all(|p| (p[0] - m[0]).abs() < WALL_SPREAD && (p[1] - m[1]).abs() < WALL_SPREAD);
    close.then_some(m)
}

/// The 2x2 supersampling of the plane renderer (offsets from the pixel centre).
const SUBPIXELS: [(f64, f64); 4] = [(-0.25, -0.25), (0.25, -0.25), (-0.25, 0.25), (0.25, 0.25)];

/// Energy scale of the plane sequences (`U`-units per ms and radiance).
const GAIN: f64 = 34.0;

impl PlaneSequence {
    /// Builds the truth from a seed: poses at 1.3 to 2.4 marker widths from the plane,
    /// within 40 degrees of its normal, looking near the marker, with random roll.
    pub fn new(seed: u64, config: PlaneConfig) -> PlaneSequence {
        let mut rng = Rng::derive(seed, 31);
        let mut poses = Vec::with_capacity(config.frames);
        let mut exposures_ms = Vec::with_capacity(config.frames);
        for _ in 0..config.frames {
            let tilt = rng.range(0.0, 40f64.to_radians());
            let az = rng.range(0.0, std::f64::consts::TAU);
            let d = rng.range(1.3, 2.4);
            let p = Vector3::new(
                d * tilt.sin() * az.cos(),
                d * tilt.sin() * az.sin(),
                d * tilt.cos(),
            );
            let target = Vector3::new(rng.range(-0.25, 0.25), rng.range(-0.25, 0.25), 0.0);
            let z = (target - p).normalize();
            let roll = rng.range(0.0, std::f64::consts::TAU);
            let helper = if z[0].abs() < 0.9 {
                Vector3::x()
            } else {
                Vector3::y()
            };
            let x0 = helper.cross(&z).normalize();
            let y0 = z.cross(&x0);
            let (s, c) = roll.sin_cos();
            let x = x0 * c + y0 * s;
            let y = z.cross(&x);
            // rows of camera_from_plane are the camera axes in plane coordinates
            let r = Rotation3::from_matrix_unchecked(Matrix3::from_rows(&[
                x.transpose(),
                y.transpose(),
                z.transpose(),
            ]));
            let t = -(r * p);
            poses.push(PlanePose {
                r: [0, 1, 2].map(|i| [0, 1, 2].map(|j| r[(i, j)])),
                t: t.into(),
            });
            exposures_ms.push(rng.range(2.0, 6.5));
        }
        PlaneSequence {
            camera: FovCamera::dataset(config.width, config.height),
            poses,
            exposures_ms,
            response: config.response.table(),
            vignette: ground_truth_vignette(config.width, config.height, seed ^ 0x5eed),
            config,
            seed,
            rays: RayCache::default(),
            texture: TextureTable::new(seed ^ 0xBEEF, [-8.0, 8.0], [-8.0, 8.0]),
        }
    }

    /// Radiance of the plane at `(x, y)` (marker widths; the marker is the unit square
    /// centred at the origin, corner 0 of its bitmap at (-0.5, 0.5)).
    pub fn radiance(&self, x: f64, y: f64) -> f64 {
        if in_marker(x, y) {
            let col = ((x + 0.5) * 7.0).floor() as usize;
            let row = ((0.5 - y) * 7.0).floor() as usize;
            let bm = aruco_bitmap(self.config.marker_id);
            if bm[row.min(6)][col.min(6)] {
                0.9
            } else {
                0.04
            }
        } else {
            self.wall(x, y)
        }
    }

    /// Radiance of the wall's texture (the plane outside the marker) at `(x, y)`.
    fn wall(&self, x: f64, y: f64) -> f64 {
        0.78 + 0.12 * (self.texture.texture(x * 0.6, y * 0.6) - 0.5).clamp(-1.0, 1.0)
    }

    /// Renders frame `i` as 8-bit grey, before compression, 2x2 supersampled: the mean
    /// radiance of four sub-pixel rays where one of them is on the marker or off the plane,
    /// elsewhere the wall's texture at the rays' mean point.
    pub fn render(&self, i: usize) -> Vec<u8> {
        let (w, h) = (self.config.width, self.config.height);
        self.config.sensor.capture(
            &self.response,
            w,
            h,
            self.exposures_ms[i],
            self.frame_seed(i),
            self.energy(i),
        )
    }

    /// The ground-truth inverse response of a `bits`-bit sensor (`2^bits` values,
    /// `U(2^bits - 1) = 255`); with 8 bits it is [`PlaneSequence::response`].
    pub fn response_bits(&self, bits: u32) -> Vec<f64> {
        self.config.response.table_bits(bits)
    }

    /// Frame `i` of a `bits`-bit sensor (8 to 16): values `0 ..= 2^bits - 1` in 16-bit
    /// samples, stored losslessly (see [`Sensor::capture_deep`]); the same scene, exposure
    /// and noise streams as [`PlaneSequence::render`].
    pub fn render_deep(&self, i: usize, bits: u32) -> Vec<u16> {
        let (w, h) = (self.config.width, self.config.height);
        self.config.sensor.capture_deep(
            &self.response_bits(bits),
            w,
            h,
            self.exposures_ms[i],
            self.frame_seed(i),
            self.energy(i),
        )
    }

    fn frame_seed(&self, i: usize) -> u64 {
        self.seed ^ 0x9A9A ^ (i as u64) << 20
    }

    /// The expected linear signal `t V B` of pixel `(x, y)` in frame `i` (U-units), 2x2
    /// supersampled: the mean radiance of four sub-pixel rays where one of them is on the
    /// marker or off the plane; elsewhere the wall's texture at the four rays' mean point
    /// (the same to ~2e-6 of the radiance, RMS; see the test).
    fn energy(&self, i: usize) -> impl Fn(usize, usize) -> f64 + Sync + '_ {
        let w = self.config.width;
        let rays = self
            .rays
            .get(&self.camera, (w, self.config.height), &SUBPIXELS);
        let pose = self.poses[i];
        let t = self.exposures_ms[i];
        let (r, tr) = (pose.rotation(), pose.translation());
        // plane normal and offset in the camera frame
        let n = r.column(2).into_owned();
        let nt = n.dot(&tr);
        move |x, y| {
            // where each sub-pixel's ray meets the plane (None: it does not, or the camera
            // has no ray there)
            let mut hits = [None; 4];
            for (hit, ray) in hits
                .iter_mut()
                .zip(&rays[(y * w + x) * SUBPIXELS.len()..][..SUBPIXELS.len()])
            {
                let ray = Vector3::from(*ray);
                let nr = n.dot(&ray);
                let lam = nt / nr;
                if !(ray[0].is_nan() || nr.abs() < 1e-12 || lam <= 0.0) {
                    // plane = R^T (X - t)
                    let plane = r.tr_mul(&(ray * lam - tr));
                    *hit = Some([plane[0], plane[1]]);
                }
            }
            let rad = match wall_mean(&hits) {
                // all four on the wall, close together: its texture is smooth at that
                // scale, so the mean of the four samples is the texture at their mean point,
                // for a quarter of the work
                Some(m) => self.wall(m[0], m[1]),
                None => {
                    let mut rad = 0.0;
                    for hit in hits {
                        rad += 0.25 * hit.map_or(0.05, |p| self.radiance(p[0], p[1]));
                    }
                    rad
                }
            };
            GAIN * t * self.vignette[y * w + x] as f64 * rad
        }
    }

    /// Frame `i` as stored by the camera (after the sensor's JPEG compression, if any).
    pub fn frame(&self, i: usize) -> Result<Vec<u8>, image::ImageError> {
        let (w, h) = (self.config.width, self.config.height);
        self.config.sensor.store(w, h, self.render(i))
    }

    /// The true poses in `--poses` format: `id r11 .. r33 tx ty tz` per frame.
    pub fn poses_text(&self) -> String {
        let mut s = String::new();
        for (i, p) in self.poses.iter().enumerate() {
            let r = p.r;
            s.push_str(&format!(
                "{i:05} {} {} {} {} {} {} {} {} {} {} {} {}\n",
                r[0][0],
                r[0][1],
                r[0][2],
                r[1][0],
                r[1][1],
                r[1][2],
                r[2][0],
                r[2][1],
                r[2][2],
                p.t[0],
                p.t[1],
                p.t[2]
            ));
        }
        s
    }

    /// Pixel positions of the marker's four outline corners in frame `i` (corner 0 = top-left
    /// of the bitmap, then clockwise), through the true camera.
    pub fn marker_corners(&self, i: usize) -> [[f64; 2]; 4] {
        let p = self.poses[i];
        let pts = [[-0.5, 0.5], [0.5, 0.5], [0.5, -0.5], [-0.5, -0.5]];
        pts.map(|[x, y]| {
            self.camera
                .project(p.plane_to_camera(x, y).into())
                .unwrap_or([f64::NAN, f64::NAN])
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The single sample on the wall against the mean of the four sub-pixel samples
    /// everywhere: the same bits where a sub-pixel ray sees the marker or misses the plane;
    /// elsewhere an RMS relative difference of 2e-6 and at most 2.4e-4 (measured at 640x512,
    /// on a few dozen of ~900,000 pixels), against a shot noise of ~3e-3 per pixel on the
    /// wall: 1e-5 and 1e-3 are the tolerances.
    #[test]
    fn one_sample_on_the_wall_is_the_mean_of_four() {
        let seq = PlaneSequence::new(
            3,
            PlaneConfig {
                frames: 3,
                ..PlaneConfig::default()
            },
        );
        let (w, h) = (seq.config.width, seq.config.height);
        let rays = seq.rays.get(&seq.camera, (w, h), &SUBPIXELS);
        let (mut exact, mut worst) = (0usize, 0.0f64);
        let (mut sum2, mut on_wall) = (0.0f64, 0usize);
        for i in 0..3 {
            let energy = seq.energy(i);
            let pose = seq.poses[i];
            let (r, tr) = (pose.rotation(), pose.translation());
            let n = r.column(2).into_owned();
            let nt = n.dot(&tr);
            for y in 0..h {
                for x in 0..w {
                    let mut rad = 0.0;
                    let mut marker_or_off = false;
                    for ray in &rays[(y * w + x) * 4..][..4] {
                        let ray = Vector3::from(*ray);
                        let nr = n.dot(&ray);
                        let lam = nt / nr;
                        rad += 0.25
                            * if ray[0].is_nan() || nr.abs() < 1e-12 || lam <= 0.0 {
                                marker_or_off = true;
                                0.05
                            } else {
                                let p = r.tr_mul(&(ray * lam - tr));
                                marker_or_off |= in_marker(p[0], p[1]);
                                seq.radiance(p[0], p[1])
                            };
                    }
                    let reference =
                        GAIN * seq.exposures_ms[i] * seq.vignette[y * w + x] as f64 * rad;
                    let got = energy(x, y);
                    if marker_or_off {
                        assert_eq!(got.to_bits(), reference.to_bits(), "frame {i} ({x}, {y})");
                        exact += 1;
                    } else {
                        let d = (got / reference - 1.0).abs();
                        worst = worst.max(d);
                        sum2 += d * d;
                        on_wall += 1;
                    }
                }
            }
        }
        assert!(exact > 1000, "the marker is in the frames: {exact} pixels");
        let rms = (sum2 / on_wall.max(1) as f64).sqrt();
        assert!(on_wall > 500_000, "most pixels see the wall: {on_wall}");
        assert!(
            rms > 0.0 && rms < 1e-5,
            "RMS relative difference on the wall {rms:e}"
        );
        assert!(
            worst < 1e-3,
            "largest relative difference on the wall {worst:e}"
        );
    }
}
