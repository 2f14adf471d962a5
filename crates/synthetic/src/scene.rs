//! A textured room rendered through the FOV camera, with vignette, exposure, response and
//! noise: benchmark-like sequences and exposure sweeps with known truth.

use rayon::prelude::*;

use crate::camera::{ground_truth_vignette, FovCamera, RayCache, ResponseCurve};
use crate::float::floor;
use crate::sensor::Sensor;
use nalgebra::Vector3;

use crate::trajectory::{benchmark_path, Path, PathConfig};
use crate::Rng;

fn hash(seed: u64, x: i64, y: i64) -> f64 {
    let mut h = seed
        ^ (x as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ (y as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
    h ^= h >> 33;
    h = h.wrapping_mul(0xFF51_AFD7_ED55_8CCD);
    h ^= h >> 33;
    h = h.wrapping_mul(0xC4CE_B9FE_1A85_EC53);
    h ^= h >> 33;
    (h >> 11) as f64 / (1u64 << 53) as f64
}

/// Lattice values of the texture's octaves.
trait Lattice {
    /// The lattice values of the cell of octave `o` whose lower corner is `(xi, yi)`:
    /// `[(xi, yi), (xi + 1, yi), (xi, yi + 1), (xi + 1, yi + 1)]`.
    fn corners(&self, o: usize, xi: i64, yi: i64) -> [f64; 4];
}

/// Value noise of octave `o` of `lattice` at `(x, y)`.
#[inline(always)]
fn value_noise<L: Lattice>(lattice: &L, o: usize, x: f64, y: f64) -> f64 {
    let (xi, yi) = (floor(x), floor(y));
    let (fx, fy) = (x - xi, y - yi);
    let (sx, sy) = (fx * fx * (3.0 - 2.0 * fx), fy * fy * (3.0 - 2.0 * fy));
    let [a, b, c, d] = lattice.corners(o, xi as i64, yi as i64);
    a + (b - a) * sx + (c - a) * sy + (a - b - c + d) * sx * sy
}

/// The lattice values of [`texture`] of one seed, hashed.
struct Hashed(u64);

impl Lattice for Hashed {
    #[inline(always)]
    fn corners(&self, o: usize, xi: i64, yi: i64) -> [f64; 4] {
        let s = self.0.wrapping_add(OCTAVE_SEEDS[o]);
        [
            hash(s, xi, yi),
            hash(s, xi + 1, yi),
            hash(s, xi, yi + 1),
            hash(s, xi + 1, yi + 1),
        ]
    }
}

/// Octaves of [`texture`] and their lattice seeds (offsets from the texture's seed; the last
/// is the patch layer's).
const OCTAVE_SEEDS: [u64; 5] = [0, 1, 2, 3, 99];

/// Procedural texture with a wide dynamic range: relative radiance in about `[0.05, 1.5]`.
pub fn texture(seed: u64, x: f64, y: f64) -> f64 {
    texture_with(&Hashed(seed), x, y)
}

/// [`texture`] with the lattice values of `lattice`.
#[inline(always)]
fn texture_with<L: Lattice>(lattice: &L, x: f64, y: f64) -> f64 {
    let mut v = 0.0;
    let mut amp = 0.5;
    let mut f = 0.7;
    for o in 0..4 {
        v += amp * value_noise(lattice, o, x * f, y * f);
        amp *= 0.5;
        f *= 2.3;
    }
    // v in ~[0, 0.94]; sharpen into patches of very different brightness
    let patch = value_noise(lattice, 4, x * 0.25, y * 0.25);
    let base = (4.0 * (v - 0.47)).exp() * (0.35 + 1.3 * patch * patch);
    base.clamp(0.03, 3.0) * 0.5
}

/// The lattice frequencies of [`texture`]'s octaves, computed as it computes them.
fn octave_frequencies() -> [f64; 5] {
    let mut fs = [0.25; 5];
    let mut f = 0.7;
    for fo in fs.iter_mut().take(4) {
        *fo = f;
        f *= 2.3;
    }
    fs
}

/// Largest lattice table of one octave (entries); beyond it the octave is hashed.
const MAX_TABLE: usize = 1 << 22;

/// [`texture`] of one seed with its lattice values kept for the lattice points that the
/// texture coordinates `x_range x y_range` reach: the same values, looked up instead of
/// hashed (a renderer evaluates the texture millions of times per frame over a bounded
/// area); points outside are hashed.
#[derive(Clone)]
pub(crate) struct TextureTable {
    seed: u64,
    /// The lattice tables of the octaves.
    octaves: [Octave; 5],
}

/// The lattice values of one octave of a [`TextureTable`] over `nx x ny` points from
/// `(x0, y0)`, row by row (empty: every point is hashed).
#[derive(Clone, Default)]
struct Octave {
    x0: i64,
    y0: i64,
    nx: u64,
    ny: u64,
    /// `nx - 1` and `ny - 1` (0 without a table): the cells whose corners are all in it.
    cells: (u64, u64),
    values: Vec<f64>,
}

impl std::fmt::Debug for TextureTable {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let n: usize = self.octaves.iter().map(|o| o.values.len()).sum();
        write!(f, "TextureTable(seed {}, {n} lattice values)", self.seed)
    }
}

impl TextureTable {
    pub(crate) fn new(seed: u64, x_range: [f64; 2], y_range: [f64; 2]) -> TextureTable {
        let freqs = octave_frequencies();
        let octaves = std::array::from_fn(|k| {
            let (s, f) = (seed.wrapping_add(OCTAVE_SEEDS[k]), freqs[k]);
            // one lattice point of margin either side (and the +1 neighbour); no table
            // for a range that is not finite or too large
            let finite = x_range.iter().chain(&y_range).all(|v| v.abs() < 1e12);
            if !finite {
                return Octave::default();
            }
            let lo = |v: f64| (v * f).floor() as i64 - 1;
            let hi = |v: f64| (v * f).floor() as i64 + 2;
            let (x0, y0) = (lo(x_range[0]), lo(y_range[0]));
            let nx = (hi(x_range[1]) - x0 + 1).max(0) as usize;
            let ny = (hi(y_range[1]) - y0 + 1).max(0) as usize;
            if nx.saturating_mul(ny) > MAX_TABLE {
                return Octave::default();
            }
            let values = (0..nx * ny)
                .map(|i| hash(s, x0 + (i % nx) as i64, y0 + (i / nx) as i64))
                .collect();
            Octave {
                x0,
                y0,
                nx: nx as u64,
                ny: ny as u64,
                cells: ((nx as u64).saturating_sub(1), (ny as u64).saturating_sub(1)),
                values,
            }
        });
        TextureTable { seed, octaves }
    }

    /// [`texture`]`(seed, x, y)`.
    pub(crate) fn texture(&self, x: f64, y: f64) -> f64 {
        texture_with(self, x, y)
    }

    /// The lattice value at `(xi, yi)` of octave `o` (the table's or the hash).
    fn lattice(&self, o: usize, xi: i64, yi: i64) -> f64 {
        let oct = &self.octaves[o];
        let (dx, dy) = (
            xi.wrapping_sub(oct.x0) as u64,
            yi.wrapping_sub(oct.y0) as u64,
        );
        if dx < oct.nx && dy < oct.ny {
            if let Some(&v) = oct.values.get((dy * oct.nx + dx) as usize) {
                return v;
            }
        }
        hash(self.seed.wrapping_add(OCTAVE_SEEDS[o]), xi, yi)
    }
}

impl Lattice for TextureTable {
    /// From the table when the whole cell is in it (one range check), else point by point.
    #[inline(always)]
    fn corners(&self, o: usize, xi: i64, yi: i64) -> [f64; 4] {
        let oct = &self.octaves[o];
        let (dx, dy) = (
            xi.wrapping_sub(oct.x0) as u64,
            yi.wrapping_sub(oct.y0) as u64,
        );
        if dx < oct.cells.0 && dy < oct.cells.1 {
            let (nx, i) = (oct.nx as usize, (dy * oct.nx + dx) as usize);
            if let (Some(r0), Some(r1)) =
                (oct.values.get(i..i + 2), oct.values.get(i + nx..i + nx + 2))
            {
                return [r0[0], r0[1], r1[0], r1[1]];
            }
        }
        [
            self.lattice(o, xi, yi),
            self.lattice(o, xi + 1, yi),
            self.lattice(o, xi, yi + 1),
            self.lattice(o, xi + 1, yi + 1),
        ]
    }
}

/// An axis-aligned room around a path, textured on every face.
#[derive(Clone, Copy, Debug)]
pub struct Room {
    /// Lower corner.
    pub min: Vector3<f64>,
    /// Upper corner.
    pub max: Vector3<f64>,
    /// Texture seed.
    pub seed: u64,
}

impl Room {
    /// A room enclosing `path` with `margin` on every side.
    pub fn around(path: &Path, margin: f64, seed: u64) -> Room {
        let mut min = Vector3::repeat(f64::INFINITY);
        let mut max = Vector3::repeat(f64::NEG_INFINITY);
        for p in &path.positions {
            min = min.inf(p);
            max = max.sup(p);
        }
        Room {
            min: min - Vector3::new(margin, margin, margin * 0.4),
            max: max + Vector3::new(margin, margin, margin * 0.6),
            seed,
        }
    }

    /// Radiance seen from `origin` along `dir` (inside the room).
    pub fn radiance(&self, origin: &Vector3<f64>, dir: &Vector3<f64>) -> f64 {
        match self.hit(origin, dir) {
            Some((face, a, b)) => texture(self.face_seed(face), a * 1.3, b * 1.3),
            None => 0.1,
        }
    }

    /// [`Room::radiance`] with the faces' textures of [`Room::textures`].
    pub(crate) fn radiance_with(
        &self,
        textures: &[TextureTable],
        origin: &Vector3<f64>,
        dir: &Vector3<f64>,
    ) -> f64 {
        match self.hit(origin, dir) {
            Some((face, a, b)) => textures[face].texture(a * 1.3, b * 1.3),
            None => 0.1,
        }
    }

    /// The textures of the six faces (see [`TextureTable`]).
    pub(crate) fn textures(&self) -> Vec<TextureTable> {
        (0..6)
            .map(|face| {
                let axis = face / 2;
                let (ka, kb) = match axis {
                    0 => (1, 2),
                    1 => (0, 2),
                    _ => (0, 1),
                };
                let range = |k: usize| [self.min[k] * 1.3, self.max[k] * 1.3];
                TextureTable::new(self.face_seed(face), range(ka), range(kb))
            })
            .collect()
    }

    fn face_seed(&self, face: usize) -> u64 {
        self.seed.wrapping_add(face as u64 * 1000)
    }

    /// Where the ray from `origin` along `dir` leaves the room: the face (`2 axis + (dir
    /// positive)`) and the hit's coordinates on it.
    fn hit(&self, origin: &Vector3<f64>, dir: &Vector3<f64>) -> Option<(usize, f64, f64)> {
        let mut best = f64::INFINITY;
        let mut axis = 0;
        for k in 0..3 {
            if dir[k].abs() < 1e-12 {
                continue;
            }
            let bound = if dir[k] > 0.0 {
                self.max[k]
            } else {
                self.min[k]
            };
            let t = (bound - origin[k]) / dir[k];
            if t > 0.0 && t < best {
                best = t;
                axis = k;
            }
        }
        if !best.is_finite() {
            return None;
        }
        let hit = origin + dir * best;
        let (a, b) = match axis {
            0 => (hit[1], hit[2]),
            1 => (hit[0], hit[2]),
            _ => (hit[0], hit[1]),
        };
        Some((axis * 2 + usize::from(dir[axis] > 0.0), a, b))
    }
}

/// Settings of a synthetic benchmark sequence.
#[derive(Clone, Copy, Debug)]
pub struct SequenceConfig {
    /// Image width.
    pub width: usize,
    /// Image height.
    pub height: usize,
    /// Number of frames.
    pub frames: usize,
    /// Frame rate.
    pub fps: f64,
    /// The sensor (noise, saturation, defects, compression).
    pub sensor: Sensor,
    /// The camera response.
    pub response: ResponseCurve,
    /// How the exposure changes from frame to frame.
    pub exposure: ExposureMode,
    /// Length of the camera path (the dataset's are normalised to about 100; a walk at
    /// 1 m/s at 25 fps covers 0.04 per frame).
    pub path_length: f64,
}

impl Default for SequenceConfig {
    fn default() -> Self {
        SequenceConfig {
            width: 640,
            height: 512,
            frames: 300,
            fps: 25.0,
            sensor: Sensor::default(),
            response: ResponseCurve::Dataset,
            exposure: ExposureMode::Smooth,
            path_length: 100.0,
        }
    }
}

/// How the exposure time of a synthetic sequence changes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ExposureMode {
    /// A slow, smooth wander between about 2 and 14 ms (three slow and eleven faster
    /// oscillations over the sequence), independent of the scene.
    Smooth,
    /// An auto-exposure controller, as machine-vision cameras run it: from the mean
    /// brightness of frame `i` it sets frame `i + 1`'s exposure halfway (in log) towards the
    /// one that would give a mean of 40% of saturation, with a metering noise of 4% (log
    /// standard deviation) per frame, within 0.05..30 ms. Consecutive exposures differ by a
    /// few percent, more where the view turns to brighter or darker walls.
    Auto,
}

impl ExposureMode {
    /// The mode's name on command lines (`smooth`, `auto`).
    pub fn name(self) -> &'static str {
        match self {
            ExposureMode::Smooth => "smooth",
            ExposureMode::Auto => "auto",
        }
    }
}

impl std::fmt::Display for ExposureMode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for ExposureMode {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim().to_ascii_lowercase().as_str() {
            "smooth" => Ok(ExposureMode::Smooth),
            "auto" => Ok(ExposureMode::Auto),
            other => Err(format!(
                "unknown exposure mode `{other}`: expected smooth or auto"
            )),
        }
    }
}

/// A logged exposure that belongs to a neighbouring frame (see [`shift_exposure_log`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LogShift {
    /// The frame whose logged exposure is wrong.
    pub frame: usize,
    /// The frame whose exposure was logged in its place (`frame - 1` or `frame + 1`).
    pub source: usize,
}

/// Injects `count` one-frame shifts into an exposure log, as an asynchronous camera SDK
/// makes them: the logged exposure of a frame is its previous or next frame's. The shifted
/// frames are drawn from a seed, at least three frames apart (isolated shifts) and only
/// where the shift changes the logged value by at least `min_change` (relative; a shift
/// that changes nothing is no error). Returns the log and the shifts in frame order; fewer
/// shifts than asked when the exposures offer too few such places.
pub fn shift_exposure_log(
    exposures_ms: &[f64],
    count: usize,
    min_change: f64,
    seed: u64,
) -> (Vec<f64>, Vec<LogShift>) {
    let n = exposures_ms.len();
    let mut log = exposures_ms.to_vec();
    let mut shifts: Vec<LogShift> = Vec::new();
    if n < 3 {
        return (log, shifts);
    }
    let mut rng = Rng::derive(seed, 77);
    let changes = |k: usize, s: usize| (exposures_ms[s] / exposures_ms[k]).ln().abs();
    let mut attempts = 0;
    while shifts.len() < count && attempts < 100 * (count + 1) {
        attempts += 1;
        let k = rng.below(n);
        let source = match (k, rng.uniform() < 0.5) {
            (0, _) => 1,
            (k, _) if k == n - 1 => k - 1,
            (k, true) => k - 1,
            (k, false) => k + 1,
        };
        if changes(k, source) < min_change.max(0.0).ln_1p()
            || shifts.iter().any(|s| s.frame.abs_diff(k) < 3)
        {
            continue;
        }
        shifts.push(LogShift { frame: k, source });
    }
    shifts.sort_by_key(|s| s.frame);
    for s in &shifts {
        log[s.frame] = exposures_ms[s.source];
    }
    (log, shifts)
}

/// A synthetic benchmark sequence: everything but the encoded images, which are rendered on
/// demand by [`SyntheticSequence::render`].
#[derive(Clone, Debug)]
pub struct SyntheticSequence {
    /// Settings.
    pub config: SequenceConfig,
    /// The camera (the renderer keeps its rays from the first frame on: change it before
    /// rendering, if at all).
    pub camera: FovCamera,
    /// Ground-truth path (length about 100).
    pub path: Path,
    /// The room.
    pub room: Room,
    /// Exposure per frame in ms.
    pub exposures_ms: Vec<f64>,
    /// Ground-truth inverse response.
    pub response: [f64; 256],
    /// Ground-truth vignette (row-major, max 1).
    pub vignette: Vec<f32>,
    seed: u64,
    rays: RayCache,
    textures: std::sync::OnceLock<Vec<TextureTable>>,
}

/// Energy scale: `U`-units per (ms x radiance).
const GAIN: f64 = 30.0;

impl SyntheticSequence {
    /// Builds the sequence's truth from a seed.
    pub fn new(seed: u64, config: SequenceConfig) -> SyntheticSequence {
        let path = benchmark_path(
            seed,
            &PathConfig {
                frames: config.frames,
                fps: config.fps,
                length: config.path_length,
                ..PathConfig::default()
            },
        );
        let room = Room::around(&path, 8.0, seed);
        let mut rng = Rng::derive(seed, 5);
        let phase = rng.range(0.0, std::f64::consts::TAU);
        let exposures_ms = (0..config.frames)
            .map(|i| {
                let u = i as f64 / config.frames.max(1) as f64;
                // auto exposure wandering between about 2 and 14 ms
                (5.3 + 0.9 * (std::f64::consts::TAU * 3.0 * u + phase).sin()
                    + 0.3 * (std::f64::consts::TAU * 11.0 * u).sin())
                .exp()
                    / 30.0
            })
            .collect();
        let mut seq = SyntheticSequence {
            camera: FovCamera::dataset(config.width, config.height),
            path,
            room,
            exposures_ms,
            response: config.response.table(),
            vignette: ground_truth_vignette(config.width, config.height, seed),
            config,
            seed,
            rays: RayCache::default(),
            textures: Default::default(),
        };
        if config.exposure == ExposureMode::Auto {
            seq.exposures_ms = seq.auto_exposures(&mut rng);
        }
        seq
    }

    /// Mean expected signal per ms of exposure (U-units) of frame `i`, on a grid of rays.
    fn brightness_per_ms(&self, i: usize) -> f64 {
        let (w, h) = (self.config.width, self.config.height);
        let r = self.path.rotations[i];
        let origin = self.path.positions[i];
        let (gx, gy) = (48, 36);
        let (mut sum, mut n) = (0.0, 0usize);
        for yi in 0..gy {
            for xi in 0..gx {
                let x = ((xi as f64 + 0.5) * w as f64 / gx as f64) as usize;
                let y = ((yi as f64 + 0.5) * h as f64 / gy as f64) as usize;
                if let Some(ray) = self.camera.unproject(x as f64, y as f64) {
                    let rad = self.room.radiance(&origin, &(r * Vector3::from(ray)));
                    sum += GAIN * self.vignette[y * w + x] as f64 * rad;
                    n += 1;
                }
            }
        }
        sum / n.max(1) as f64
    }

    /// The exposures of [`ExposureMode::Auto`].
    fn auto_exposures(&self, rng: &mut Rng) -> Vec<f64> {
        let target = 0.4 * 255.0;
        let (lo, hi) = (0.05f64, 30.0f64);
        let n = self.config.frames;
        let rates: Vec<f64> = (0..n)
            .into_par_iter()
            .map(|i| self.brightness_per_ms(i).max(1e-6))
            .collect();
        let mut t = (target / rates[0]).clamp(lo, hi);
        let mut out = Vec::with_capacity(n);
        for rate in rates {
            out.push(t);
            let metered = t * rate * (0.04 * rng.normal()).exp();
            t = (t * (target / metered).sqrt()).clamp(lo, hi);
        }
        out
    }

    /// Renders frame `i` as 8-bit grey, row-major, before compression (the sensor's
    /// `jpeg_quality` is applied by whoever stores it).
    pub fn render(&self, i: usize) -> Vec<u8> {
        let (w, h) = (self.config.width, self.config.height);
        let r = self.path.rotations[i];
        let origin = self.path.positions[i];
        let t = self.exposures_ms[i];
        let rays = self.rays.get(&self.camera, (w, h), &[(0.0, 0.0)]);
        let textures = self.textures.get_or_init(|| self.room.textures());
        self.config.sensor.capture(
            &self.response,
            w,
            h,
            t,
            self.seed ^ (i as u64) << 20,
            |x, y| {
                let ray = rays[y * w + x];
                let rad = if ray[0].is_nan() {
                    0.0
                } else {
                    let dir = r * Vector3::from(ray);
                    self.room.radiance_with(textures, &origin, &dir)
                };
                GAIN * t * self.vignette[y * w + x] as f64 * rad
            },
        )
    }

    /// times.txt rows: `(id, timestamp, exposure_ms)`.
    pub fn times(&self) -> Vec<(String, f64, f64)> {
        (0..self.config.frames)
            .map(|i| (format!("{i:05}"), self.path.times[i], self.exposures_ms[i]))
            .collect()
    }
}

/// Settings of an exposure sweep.
#[derive(Clone, Copy, Debug)]
pub struct SweepConfig {
    /// Image width.
    pub width: usize,
    /// Image height.
    pub height: usize,
    /// Number of frames (exposures).
    pub frames: usize,
    /// Shortest exposure in ms.
    pub t0: f64,
    /// Exposure step factor between frames.
    pub factor: f64,
    /// The sensor.
    pub sensor: Sensor,
    /// The camera response.
    pub response: ResponseCurve,
}

impl Default for SweepConfig {
    /// The paper's sweep: 120 exposures from 0.05 ms in steps of 1.05, 640x512, the typical
    /// sensor, the default response.
    fn default() -> Self {
        SweepConfig {
            width: 640,
            height: 512,
            frames: 120,
            t0: 0.05,
            factor: 1.05,
            sensor: Sensor::default(),
            response: ResponseCurve::Dataset,
        }
    }
}

/// An exposure sweep of a static scene (paper section 2.3.1): one irradiance image `B'` (the
/// vignette absorbed into it) seen at exposures in multiplicative steps.
#[derive(Clone, Debug)]
pub struct Sweep {
    /// Image width.
    pub width: usize,
    /// Image height.
    pub height: usize,
    /// `B'` in `U`-units per ms.
    pub irradiance: Vec<f64>,
    /// Exposure per frame in ms.
    pub exposures_ms: Vec<f64>,
    /// Ground-truth inverse response.
    pub response: [f64; 256],
    /// The sensor.
    pub sensor: Sensor,
    /// The true response curve (for deeper tables, [`Sweep::response_bits`]).
    pub curve: ResponseCurve,
    seed: u64,
}

impl Sweep {
    /// A sweep of a textured wall seen through the vignetted camera.
    pub fn new(seed: u64, config: SweepConfig) -> Sweep {
        let SweepConfig {
            width,
            height,
            frames,
            t0,
            factor,
            ..
        } = config;
        let cam = FovCamera::dataset(width, height);
        let vig = ground_truth_vignette(width, height, seed);
        let room = Room {
            min: Vector3::new(-6.0, -6.0, -4.0),
            max: Vector3::new(6.0, 6.0, 4.0),
            seed,
        };
        let r = crate::trajectory::camera_rotation(0.4, 0.1);
        let mut irradiance = vec![0.0; width * height];
        irradiance
            .par_chunks_mut(width.max(1))
            .enumerate()
            .for_each(|(y, row)| {
                for (x, b) in row.iter_mut().enumerate() {
                    let origin = Vector3::new(0.5, -0.3, 0.2);
                    let rad = cam
                        .unproject(x as f64, y as f64)
                        .map_or(0.0, |ray| room.radiance(&origin, &(r * Vector3::from(ray))));
                    *b = GAIN * vig[y * width + x] as f64 * rad;
                }
            });
        let exposures_ms = (0..frames).map(|i| t0 * factor.powi(i as i32)).collect();
        Sweep {
            width,
            height,
            irradiance,
            exposures_ms,
            response: config.response.table(),
            sensor: config.sensor,
            curve: config.response,
            seed,
        }
    }

    /// Frame `i` as 8-bit grey, before compression.
    pub fn render(&self, i: usize) -> Vec<u8> {
        let t = self.exposures_ms[i];
        self.sensor.capture(
            &self.response,
            self.width,
            self.height,
            t,
            self.seed ^ 0xABCD ^ (i as u64) << 20,
            |x, y| t * self.irradiance[y * self.width + x],
        )
    }

    /// The ground-truth inverse response of a `bits`-bit sensor (`2^bits` values,
    /// `U(2^bits - 1) = 255`).
    pub fn response_bits(&self, bits: u32) -> Vec<f64> {
        self.curve.table_bits(bits)
    }

    /// Frame `i` of a `bits`-bit sensor (8 to 16): values `0 ..= 2^bits - 1` in 16-bit
    /// samples, stored losslessly (see [`Sensor::capture_deep`]). With 8 bits it is
    /// [`Sweep::render`] widened.
    pub fn render_deep(&self, i: usize, bits: u32) -> Vec<u16> {
        let t = self.exposures_ms[i];
        self.sensor.capture_deep(
            &self.response_bits(bits),
            self.width,
            self.height,
            t,
            self.seed ^ 0xABCD ^ (i as u64) << 20,
            |x, y| t * self.irradiance[y * self.width + x],
        )
    }

    /// Frame `i` as stored by the camera (after the sensor's JPEG compression, if any).
    pub fn frame(&self, i: usize) -> Result<Vec<u8>, image::ImageError> {
        self.sensor.store(self.width, self.height, self.render(i))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The room's face tables give the very radiance of the hashing texture.
    #[test]
    fn room_textures_match_the_room() {
        let room = Room {
            min: Vector3::new(-7.0, -5.0, -2.0),
            max: Vector3::new(9.0, 4.0, 3.0),
            seed: 17,
        };
        let textures = room.textures();
        let mut rng = Rng::derive(4, 1);
        for _ in 0..20_000 {
            let origin = Vector3::new(
                rng.range(-6.0, 8.0),
                rng.range(-4.0, 3.0),
                rng.range(-1.0, 2.0),
            );
            let dir = Vector3::new(rng.normal(), rng.normal(), rng.normal());
            let (a, b) = (
                room.radiance_with(&textures, &origin, &dir),
                room.radiance(&origin, &dir),
            );
            assert_eq!(a.to_bits(), b.to_bits(), "from {origin:?} along {dir:?}");
        }
    }

    /// The table gives the very values of the hashing texture, inside its rectangle and out.
    #[test]
    fn texture_table_matches_the_texture() {
        let table = TextureTable::new(0xBEEF, [-2.0, 3.0], [-1.0, 2.5]);
        let mut rng = Rng::derive(3, 1);
        for _ in 0..20_000 {
            // up to well outside the table (the finest octave reaches 8.5 times x)
            let (x, y) = (rng.range(-4.0, 4.0), rng.range(-4.0, 4.0));
            let (a, b) = (table.texture(x, y), texture(0xBEEF, x, y));
            assert_eq!(a.to_bits(), b.to_bits(), "at ({x}, {y})");
        }
        for x in [
            0.0,
            -0.0,
            -1.0,
            1e-300,
            -1e-300,
            2.5,
            -2.5,
            1e17,
            -1e17,
            f64::NAN,
        ] {
            let f = floor(x);
            assert!(
                f == x.floor() || (f.is_nan() && x.floor().is_nan()),
                "floor({x})"
            );
            let (a, b) = (table.texture(x, 0.3), texture(0xBEEF, x, 0.3));
            assert!(
                a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()),
                "at {x}"
            );
        }
    }
}
