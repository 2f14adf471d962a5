//! Reading a benchmark sequence folder: `images.zip` (flat or with an `images/` prefix inside)
//! or `images/`, `times.txt`, `camera.txt`, and the optional calibration and ground-truth
//! files; random access, forwards and backwards playback, and parallel decoding that keeps
//! the order.

use std::fs::File;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use camera_model::{CalibrationFile, CalibrationFormat, CameraFile, Image, ImageSize, Transform};

use crate::jpeg::{decode_jpeg_gray8, decode_jpeg_gray8_half, is_jpeg};
use crate::layouts::{resolve, Layout, Listed, Resolved};
use crate::ordered::for_each_ordered;
use crate::times::{parse_times, Times};
use crate::zipimages::is_image_name;
use crate::{read_text, DatasetError, ImagesZip};

/// Where the images come from.
#[derive(Debug)]
enum Source {
    Zip {
        path: PathBuf,
        images: Mutex<ImagesZip<File>>,
    },
    Folder {
        files: Vec<PathBuf>,
    },
}

/// One decoded frame.
#[derive(Clone, Debug)]
pub struct Frame {
    /// Index in the sequence (0-based, in name order).
    pub index: usize,
    /// The image's name (zip entry or file name).
    pub name: String,
    /// 8-bit grey pixels.
    pub image: Image<u8>,
    /// Timestamp in seconds (times.txt).
    pub timestamp: f64,
    /// Exposure in ms, when known.
    pub exposure_ms: Option<f64>,
    /// Timestamp in integer nanoseconds, when the dataset gives it exactly.
    pub timestamp_ns: Option<i64>,
}

/// A grey image with the sample type of its file: 8 bits (JPEG, 8-bit PNG/PGM) or 16 bits
/// (16-bit PNG/PGM, values as stored).
#[derive(Clone, Debug, PartialEq)]
pub enum GrayImage {
    /// 8 bits per pixel.
    U8(Image<u8>),
    /// 16 bits per pixel, the stored values unscaled.
    U16(Image<u16>),
}

impl GrayImage {
    /// Width and height.
    pub fn size(&self) -> (usize, usize) {
        match self {
            GrayImage::U8(i) => i.size(),
            GrayImage::U16(i) => i.size(),
        }
    }

    /// Bits per sample of the file: 8 or 16.
    pub fn bits(&self) -> u32 {
        match self {
            GrayImage::U8(_) => 8,
            GrayImage::U16(_) => 16,
        }
    }
}

/// One decoded frame at its file's own bit depth (see [`Sequence::process_native`]).
#[derive(Clone, Debug)]
pub struct NativeFrame {
    /// Index in the sequence (0-based, in name order).
    pub index: usize,
    /// The image's name (zip entry or file name).
    pub name: String,
    /// The pixels, 8 or 16 bits.
    pub image: GrayImage,
    /// Timestamp in seconds (times.txt).
    pub timestamp: f64,
    /// Exposure in ms, when known.
    pub exposure_ms: Option<f64>,
    /// Timestamp in integer nanoseconds, when the dataset gives it exactly.
    pub timestamp_ns: Option<i64>,
}

/// An opened, validated sequence.
#[derive(Debug)]
pub struct Sequence {
    dir: PathBuf,
    layout: Layout,
    camera_path: Option<PathBuf>,
    camera_from_imu: Option<Transform>,
    /// The dataset's own ground truth beside the images (EuRoC's state csv, TUM-VI's mocap
    /// csv, 4Seasons' GNSSPoses.txt, KITTI's poses, TUM RGB-D's groundtruth.txt), if found.
    pub dataset_ground_truth: Option<PathBuf>,
    /// Warnings about the layout (frames without exposure, rows without image, ...).
    pub layout_warnings: Vec<String>,
    source: Source,
    names: Vec<String>,
    times: Times,
    times_path: PathBuf,
    camera: Option<CameraFile>,
    size: ImageSize,
    bits: u32,
    jpeg: bool,
    /// `pcalib.txt`, if present.
    pub pcalib_path: Option<PathBuf>,
    /// `vignette.png`, if present.
    pub vignette_path: Option<PathBuf>,
    /// `groundtruthSync.txt`, if present.
    pub ground_truth_path: Option<PathBuf>,
}

/// Decodes JPEG, PNG or PGM bytes to 8-bit grey (colour images are converted to luma; 16-bit
/// images are scaled down). The error text says what failed.
pub fn decode_gray8(bytes: &[u8]) -> Result<Image<u8>, String> {
    if is_jpeg(bytes) {
        return decode_jpeg_gray8(bytes);
    }
    let img = image::load_from_memory(bytes).map_err(|e| format!("cannot decode image: {e}"))?;
    let g = img.into_luma8();
    let (w, h) = (g.width() as usize, g.height() as usize);
    Image::new(w, h, g.into_raw()).map_err(|e| e.to_string())
}

/// Decodes a PNG (8- or 16-bit grey, or colour converted to luma) to 16-bit grey, and tells
/// whether the file had 16 bits per sample.
pub fn decode_gray16(bytes: &[u8]) -> Result<(Image<u16>, bool), String> {
    let img = image::load_from_memory(bytes).map_err(|e| format!("cannot decode image: {e}"))?;
    let sixteen = matches!(
        img.color(),
        image::ColorType::L16
            | image::ColorType::La16
            | image::ColorType::Rgb16
            | image::ColorType::Rgba16
    );
    let g = img.into_luma16();
    let (w, h) = (g.width() as usize, g.height() as usize);
    let data = if sixteen {
        g.into_raw()
    } else {
        // into_luma16 scales 8-bit values by 257; keep the original 0..255 values
        g.into_raw().into_iter().map(|v| v / 257).collect()
    };
    Image::new(w, h, data)
        .map(|i| (i, sixteen))
        .map_err(|e| e.to_string())
}

/// Decodes JPEG, PNG or PGM bytes to grey at the file's own bit depth: 16-bit files keep
/// their values (a 12-bit sensor's values stay in the low 12 bits), colour is converted to
/// luma. The error text says what failed.
pub fn decode_gray(bytes: &[u8]) -> Result<GrayImage, String> {
    if is_jpeg(bytes) {
        return decode_jpeg_gray8(bytes).map(GrayImage::U8);
    }
    let img = image::load_from_memory(bytes).map_err(|e| format!("cannot decode image: {e}"))?;
    let (w, h) = (img.width() as usize, img.height() as usize);
    let sixteen = matches!(
        img.color(),
        image::ColorType::L16
            | image::ColorType::La16
            | image::ColorType::Rgb16
            | image::ColorType::Rgba16
    );
    let out = if sixteen {
        Image::new(w, h, img.into_luma16().into_raw()).map(GrayImage::U16)
    } else {
        Image::new(w, h, img.into_luma8().into_raw()).map(GrayImage::U8)
    };
    out.map_err(|e| e.to_string())
}

/// Decodes a grey map such as vignette.png, as DESIGN.md and DSO read it: 8- or 16-bit grey;
/// grey+alpha gives the grey channel (the alpha is ignored, as DSO's grey conversion drops
/// it); an RGB(A) image whose three colour channels are equal everywhere is that grey (DSO's
/// conversion to grey gives the same values). A colour image with different channels is
/// refused: a vignette has one value per pixel. Returns the map (8-bit values unscaled) and
/// its bits per sample (8 or 16).
pub fn decode_gray_map(bytes: &[u8]) -> Result<(Image<u16>, u32), String> {
    use image::DynamicImage as D;
    let img = image::load_from_memory(bytes).map_err(|e| format!("cannot decode image: {e}"))?;
    let (w, h) = (img.width() as usize, img.height() as usize);
    let grey = |v: Vec<u16>, bits| {
        Image::new(w, h, v)
            .map(|i| (i, bits))
            .map_err(|e| e.to_string())
    };
    let colour = |raw: Vec<u16>, n: usize, bits| {
        if raw.chunks(n).all(|c| c[0] == c[1] && c[1] == c[2]) {
            grey(raw.chunks(n).map(|c| c[0]).collect(), bits)
        } else {
            Err(format!(
                "{} image whose red, green and blue differ; a vignette must be grey (8 or 16 bits, grey+alpha allowed)",
                if n == 3 { "an RGB" } else { "an RGBA" }
            ))
        }
    };
    let widen = |v: Vec<u8>| v.into_iter().map(u16::from).collect::<Vec<u16>>();
    match img {
        D::ImageLuma8(i) => grey(widen(i.into_raw()), 8),
        D::ImageLuma16(i) => grey(i.into_raw(), 16),
        D::ImageLumaA8(i) => grey(i.into_raw().chunks(2).map(|c| c[0] as u16).collect(), 8),
        D::ImageLumaA16(i) => grey(i.into_raw().chunks(2).map(|c| c[0]).collect(), 16),
        D::ImageRgb8(i) => colour(widen(i.into_raw()), 3, 8),
        D::ImageRgba8(i) => colour(widen(i.into_raw()), 4, 8),
        D::ImageRgb16(i) => colour(i.into_raw(), 3, 16),
        D::ImageRgba16(i) => colour(i.into_raw(), 4, 16),
        _ => {
            Err("unsupported sample format (32-bit float?); a vignette is 8- or 16-bit grey".into())
        }
    }
}

/// Reads a grey map such as vignette.png (see [`decode_gray_map`]).
pub fn read_gray_map(path: &Path) -> Result<(Image<u16>, u32), DatasetError> {
    let bytes = std::fs::read(path).map_err(|e| DatasetError::io(path, e))?;
    decode_gray_map(&bytes).map_err(|m| DatasetError::invalid(path, m))
}

/// Reads an image file as 16-bit grey (see [`decode_gray16`]).
pub fn read_gray16(path: &Path) -> Result<(Image<u16>, bool), DatasetError> {
    let bytes = std::fs::read(path).map_err(|e| DatasetError::io(path, e))?;
    decode_gray16(&bytes).map_err(|m| DatasetError::invalid(path, m))
}

/// Reads an image file as 8-bit grey.
pub fn read_gray8(path: &Path) -> Result<Image<u8>, DatasetError> {
    let bytes = std::fs::read(path).map_err(|e| DatasetError::io(path, e))?;
    decode_gray8(&bytes).map_err(|m| DatasetError::invalid(path, m))
}

/// A warning when the ids of times.txt do not name the images (rows are paired with the
/// images by order, as DSO pairs them): the first mismatch and their number. Ids and image
/// stems that are both numbers compare as numbers (`0` names `000000.png`).
fn id_mismatch(times: &Times, names: &[String], times_path: &Path) -> Option<String> {
    let stem = |name: &str| -> String {
        let base = name.rsplit('/').next().unwrap_or(name);
        match base.rsplit_once('.') {
            Some((s, _)) => s.to_string(),
            None => base.to_string(),
        }
    };
    let same = |id: &str, st: &str| {
        id == st || matches!((id.parse::<u64>(), st.parse::<u64>()), (Ok(a), Ok(b)) if a == b)
    };
    let mut first = None;
    let mut count = 0usize;
    for (k, (row, name)) in times.rows.iter().zip(names).enumerate() {
        if !same(&row.id, &stem(name)) {
            count += 1;
            first.get_or_insert((k, row.id.clone(), name.clone()));
        }
    }
    let (k, id, name) = first?;
    let line = times.lines.get(k).copied().unwrap_or(k + 1);
    Some(format!(
        "{}: line {line}: id `{id}` but image {k} is `{name}` ({count} of {} rows do not name their image); rows are paired with the images in name order, as DSO pairs them",
        times_path.display(),
        names.len()
    ))
}

fn optional(dir: &Path, name: &str) -> Option<PathBuf> {
    let p = dir.join(name);
    p.is_file().then_some(p)
}

impl Sequence {
    /// Opens and validates a sequence folder of any layout (see [`Layout`]) with its first
    /// camera; see [`Sequence::open_camera`].
    pub fn open(dir: &Path) -> Result<Sequence, DatasetError> {
        Sequence::open_camera(dir, 0)
    }

    /// Opens and validates a sequence folder of any layout, camera `cam` where the dataset
    /// has several (`--cam N`): the monovo/DSO folder (`images.zip` preferred, else
    /// `images/`, times.txt with one row per image and increasing timestamps, camera.txt whose
    /// input size must match the images), TUM-VI, EuRoC/ASL, 4Seasons, KITTI or TUM RGB-D /
    /// ETH3D, each with its own calibration file.
    pub fn open_camera(dir: &Path, cam: usize) -> Result<Sequence, DatasetError> {
        Sequence::open_with_calibration(dir, cam, None)
    }

    /// As [`Sequence::open_camera`], with the camera read from `calibration` (any format of
    /// [`CalibrationFile`]) instead of the layout's own file, when given (`--calib FILE`).
    pub fn open_with_calibration(
        dir: &Path,
        cam: usize,
        calibration: Option<&Path>,
    ) -> Result<Sequence, DatasetError> {
        let mut seq = Sequence::open_layout(dir, cam)?;
        if let Some(p) = calibration {
            seq.set_calibration(p, cam)?;
        }
        Ok(seq)
    }

    fn open_layout(dir: &Path, cam: usize) -> Result<Sequence, DatasetError> {
        if !dir.exists() {
            return Err(DatasetError::invalid(dir, "does not exist"));
        }
        if !dir.is_dir() {
            return Err(DatasetError::invalid(
                dir,
                "is a file, not a sequence folder (images.zip or images/, times.txt, ...)",
            ));
        }
        match resolve(dir, cam)? {
            Resolved::Monovo {
                dir: sub,
                layout,
                ground_truth,
                calibration,
            } => {
                let mut seq = Sequence::open_monovo(&sub)?;
                seq.layout = layout;
                seq.dataset_ground_truth = ground_truth;
                if let Some(p) = calibration {
                    // TUM-VI's dso/camchain.yaml: the IMU-to-camera transform
                    let cal = CalibrationFile::parse(&read_text(&p)?)
                        .map_err(|e| DatasetError::invalid(&p, e.to_string()))?;
                    seq.camera_from_imu = cal.cameras.get(cam).and_then(|c| c.camera_from_imu);
                }
                Ok(seq)
            }
            Resolved::Listed(listed) => Sequence::open_listed(dir, *listed, cam),
        }
    }

    /// Reads the camera of calibration file `p` (camera `cam` of a multi-camera file; a
    /// one-camera file serves every camera) for images of this sequence's size.
    fn set_calibration(&mut self, p: &Path, cam: usize) -> Result<(), DatasetError> {
        let cal = CalibrationFile::parse(&read_text(p)?)
            .map_err(|e| DatasetError::invalid(p, e.to_string()))?;
        let index = match cal.format {
            CalibrationFormat::EurocSensor
            | CalibrationFormat::CameraTxt
            | CalibrationFormat::Eth3d => 0,
            _ => cam,
        };
        let file = cal
            .camera_file(index, Some(self.size))
            .map_err(|e| DatasetError::invalid(p, e.to_string()))?;
        if file.input_size != self.size {
            return Err(DatasetError::invalid(
                p,
                format!(
                    "the camera is {} but the images are {} ({})",
                    file.input_size, self.size, self.names[0]
                ),
            ));
        }
        self.camera_from_imu = cal.cameras.get(index).and_then(|c| c.camera_from_imu);
        self.camera = Some(file);
        self.camera_path = Some(p.to_path_buf());
        Ok(())
    }

    /// A listed layout: the images, their rows, and the calibration file read for `cam`.
    fn open_listed(dir: &Path, l: Listed, cam: usize) -> Result<Sequence, DatasetError> {
        let mut seq = Sequence {
            dir: dir.to_path_buf(),
            layout: l.layout,
            camera_path: None,
            camera_from_imu: None,
            dataset_ground_truth: l.ground_truth,
            layout_warnings: l.warnings,
            source: Source::Folder { files: l.files },
            names: l.names,
            times: l.times,
            times_path: l.times_path,
            camera: None,
            size: ImageSize::new(0, 0),
            bits: 8,
            jpeg: false,
            pcalib_path: l.pcalib,
            vignette_path: l.vignette,
            ground_truth_path: None,
        };
        let first = seq.raw(0)?;
        seq.jpeg = is_jpeg(&first);
        let first = decode_gray(&first).map_err(|m| DatasetError::invalid(seq.label(0), m))?;
        let (fw, fh) = first.size();
        seq.size = ImageSize::new(fw, fh);
        seq.bits = first.bits();
        if let Some(p) = l.calibration {
            seq.set_calibration(&p, cam)?;
        }
        Ok(seq)
    }

    /// The monovo/DSO folder.
    fn open_monovo(dir: &Path) -> Result<Sequence, DatasetError> {
        if !dir.exists() {
            return Err(DatasetError::invalid(dir, "does not exist"));
        }
        if !dir.is_dir() {
            return Err(DatasetError::invalid(
                dir,
                "is a file, not a sequence folder (images.zip or images/, times.txt, ...)",
            ));
        }
        let zip_path = dir.join("images.zip");
        let folder = dir.join("images");
        let (source, names) = if zip_path.is_file() {
            let f = File::open(&zip_path).map_err(|e| DatasetError::io(&zip_path, e))?;
            let images = ImagesZip::new(f).map_err(|m| DatasetError::invalid(&zip_path, m))?;
            let names = images.names().to_vec();
            (
                Source::Zip {
                    path: zip_path.clone(),
                    images: Mutex::new(images),
                },
                names,
            )
        } else if folder.is_dir() {
            let rd = std::fs::read_dir(&folder).map_err(|e| DatasetError::io(&folder, e))?;
            let mut files = Vec::new();
            for e in rd {
                let e = e.map_err(|e| DatasetError::io(&folder, e))?;
                let name = e.file_name().to_string_lossy().into_owned();
                if is_image_name(&name) && e.path().is_file() {
                    files.push(e.path());
                }
            }
            files.sort();
            let names = files
                .iter()
                .map(|p| {
                    p.file_name()
                        .map_or(String::new(), |n| n.to_string_lossy().into_owned())
                })
                .collect();
            (Source::Folder { files }, names)
        } else {
            return Err(DatasetError::invalid(
                dir,
                "no images.zip and no images/ folder in this sequence",
            ));
        };
        let images_label = match &source {
            Source::Zip { path, .. } => path.clone(),
            Source::Folder { .. } => folder.clone(),
        };
        if names.is_empty() {
            return Err(DatasetError::invalid(
                &images_label,
                "contains no .jpg or .png images",
            ));
        }
        let times_path = dir.join("times.txt");
        let times = parse_times(&read_text(&times_path)?, &times_path)?;
        if times.rows.len() != names.len() {
            return Err(DatasetError::invalid(
                &times_path,
                format!(
                    "has {} rows but {} has {} images; there must be one row per image",
                    times.rows.len(),
                    images_label.display(),
                    names.len()
                ),
            ));
        }
        let mut times = times;
        if let Some(w) = id_mismatch(&times, &names, &times_path) {
            times.warnings.push(w);
        }
        let mut seq = Sequence {
            dir: dir.to_path_buf(),
            layout: Layout::Monovo,
            camera_path: None,
            camera_from_imu: None,
            dataset_ground_truth: None,
            layout_warnings: Vec::new(),
            source,
            names,
            times,
            times_path,
            camera: None,
            size: ImageSize::new(0, 0),
            bits: 8,
            jpeg: false,
            pcalib_path: optional(dir, "pcalib.txt"),
            vignette_path: optional(dir, "vignette.png"),
            ground_truth_path: optional(dir, "groundtruthSync.txt"),
        };
        let first = seq.raw(0)?;
        seq.jpeg = is_jpeg(&first);
        let first = decode_gray(&first).map_err(|m| DatasetError::invalid(seq.label(0), m))?;
        let (fw, fh) = first.size();
        seq.size = ImageSize::new(fw, fh);
        seq.bits = first.bits();
        let camera_path = dir.join("camera.txt");
        if camera_path.is_file() {
            let cam = CameraFile::parse(&read_text(&camera_path)?)
                .map_err(|e| DatasetError::invalid(&camera_path, e.to_string()))?;
            if cam.input_size != seq.size {
                return Err(DatasetError::invalid(
                    &camera_path,
                    format!(
                        "line 2: the camera is {} but the images are {} ({})",
                        cam.input_size, seq.size, seq.names[0]
                    ),
                ));
            }
            seq.camera = Some(cam);
            seq.camera_path = Some(camera_path);
        }
        Ok(seq)
    }

    /// The sequence folder (for TUM-VI, its `dso/camN` folder).
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The folder of the image files (of the first one), `None` for images.zip.
    pub fn image_folder(&self) -> Option<&Path> {
        match &self.source {
            Source::Zip { .. } => None,
            Source::Folder { files } => files.first().and_then(|f| f.parent()),
        }
    }

    /// The layout the folder was read as.
    pub fn layout(&self) -> Layout {
        self.layout
    }

    /// The calibration file the camera was read from (camera.txt, sensor.yaml, ...).
    pub fn camera_path(&self) -> Option<&Path> {
        self.camera_path.as_deref()
    }

    /// The transform from the IMU (body) frame to the camera, when the calibration gives it.
    pub fn camera_from_imu(&self) -> Option<&Transform> {
        self.camera_from_imu.as_ref()
    }

    /// The timestamps in integer nanoseconds, when the dataset gives every one exactly.
    pub fn timestamps_ns(&self) -> Option<Vec<i64>> {
        self.times.timestamps_ns()
    }

    /// Number of images.
    pub fn len(&self) -> usize {
        self.names.len()
    }

    /// Whether the sequence has no image (never true for an opened sequence).
    pub fn is_empty(&self) -> bool {
        self.names.is_empty()
    }

    /// Image names in playback order.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// times.txt.
    pub fn times(&self) -> &Times {
        &self.times
    }

    /// Path of times.txt.
    pub fn times_path(&self) -> &Path {
        &self.times_path
    }

    /// camera.txt, when present.
    pub fn camera(&self) -> Option<&CameraFile> {
        self.camera.as_ref()
    }

    /// Size of the images (from the first one).
    pub fn image_size(&self) -> ImageSize {
        self.size
    }

    /// Bits per sample of the image files (8, or 16 for 16-bit PNG/PGM), from the first.
    pub fn bits_per_sample(&self) -> u32 {
        self.bits
    }

    /// Whether the image files are JPEG (the first one, as its bytes tell the decoders).
    pub fn is_jpeg(&self) -> bool {
        self.jpeg
    }

    /// Whether the images come from images.zip.
    pub fn is_zipped(&self) -> bool {
        matches!(self.source, Source::Zip { .. })
    }

    fn label(&self, k: usize) -> String {
        match &self.source {
            Source::Zip { path, .. } => format!("{}: {}", path.display(), self.names[k]),
            Source::Folder { files } => files[k].display().to_string(),
        }
    }

    /// The encoded bytes of image `k`.
    pub fn raw(&self, k: usize) -> Result<Vec<u8>, DatasetError> {
        if k >= self.len() {
            return Err(DatasetError::invalid(
                &self.dir,
                format!(
                    "frame {k} requested, the sequence has {} frames",
                    self.len()
                ),
            ));
        }
        match &self.source {
            Source::Zip { path, images } => {
                let mut z = images.lock().map_err(|_| {
                    DatasetError::invalid(path, "zip reader poisoned by an earlier failure")
                })?;
                z.read(k).map_err(|m| DatasetError::invalid(path, m))
            }
            Source::Folder { files } => {
                std::fs::read(&files[k]).map_err(|e| DatasetError::io(&files[k], e))
            }
        }
    }

    /// Decodes image `k` to 8-bit grey; the error names the file or zip entry.
    pub fn decode(&self, k: usize) -> Result<Image<u8>, DatasetError> {
        let bytes = self.raw(k)?;
        let img = decode_gray8(&bytes).map_err(|m| DatasetError::invalid(self.label(k), m))?;
        if self.size.width != 0
            && (img.width(), img.height()) != (self.size.width, self.size.height)
        {
            return Err(DatasetError::invalid(
                self.label(k),
                format!(
                    "is {}x{}, the sequence's images are {}",
                    img.width(),
                    img.height(),
                    self.size
                ),
            ));
        }
        Ok(img)
    }

    /// Decodes image `k` at its own bit depth (see [`decode_gray`]); the error names the
    /// file or zip entry.
    pub fn decode_native(&self, k: usize) -> Result<GrayImage, DatasetError> {
        let bytes = self.raw(k)?;
        let img = decode_gray(&bytes).map_err(|m| DatasetError::invalid(self.label(k), m))?;
        let (w, h) = img.size();
        if self.size.width != 0 && (w, h) != (self.size.width, self.size.height) {
            return Err(DatasetError::invalid(
                self.label(k),
                format!("is {w}x{h}, the sequence's images are {}", self.size),
            ));
        }
        if self.size.width != 0 && img.bits() != self.bits {
            return Err(DatasetError::invalid(
                self.label(k),
                format!(
                    "has {} bits per pixel, the sequence's first image has {}",
                    img.bits(),
                    self.bits
                ),
            ));
        }
        Ok(img)
    }

    /// Decodes JPEG image `k` to 8-bit grey at half its width and height in the DCT domain
    /// (see [`decode_jpeg_gray8_half`]); the error names the zip entry or file.
    pub fn decode_half(&self, k: usize) -> Result<Image<u8>, DatasetError> {
        let bytes = self.raw(k)?;
        let img =
            decode_jpeg_gray8_half(&bytes).map_err(|m| DatasetError::invalid(self.label(k), m))?;
        let want = (self.size.width.div_ceil(2), self.size.height.div_ceil(2));
        if self.size.width != 0 && (img.width(), img.height()) != want {
            return Err(DatasetError::invalid(
                self.label(k),
                format!(
                    "is {}x{} at half size, the sequence's images are {}",
                    img.width(),
                    img.height(),
                    self.size
                ),
            ));
        }
        Ok(img)
    }

    /// Frame `k` at half size (see [`Sequence::decode_half`]).
    pub fn frame_half(&self, k: usize) -> Result<NativeFrame, DatasetError> {
        Ok(self.native_frame(k, GrayImage::U8(self.decode_half(k)?)))
    }

    /// Frame `k` with its decoded `image`, name, timestamp and exposure.
    fn native_frame(&self, k: usize, image: GrayImage) -> NativeFrame {
        let row = &self.times.rows[k];
        NativeFrame {
            index: k,
            name: self.names[k].clone(),
            image,
            timestamp: row.timestamp,
            exposure_ms: row.exposure_ms,
            timestamp_ns: row.timestamp_ns,
        }
    }

    /// As [`Sequence::process_native`], with the frames decoded at half size
    /// ([`Sequence::frame_half`]) when `half`.
    pub fn process_scaled<T, E, W, S>(
        &self,
        indices: &[usize],
        chunk: usize,
        half: bool,
        work: W,
        sink: S,
    ) -> Result<(), E>
    where
        T: Send,
        E: From<DatasetError> + Send,
        W: Fn(NativeFrame) -> Result<T, E> + Sync,
        S: FnMut(T) -> Result<(), E>,
    {
        for_each_ordered(
            indices.len(),
            chunk,
            |i| {
                let k = indices[i];
                work(if half {
                    self.frame_half(k)?
                } else {
                    self.frame_native(k)?
                })
            },
            sink,
        )
    }

    /// Frame `k` at its own bit depth.
    pub fn frame_native(&self, k: usize) -> Result<NativeFrame, DatasetError> {
        Ok(self.native_frame(k, self.decode_native(k)?))
    }

    /// [`Sequence::process`] with frames at their own bit depth (8 or 16 bits).
    pub fn process_native<T, E, W, S>(
        &self,
        indices: &[usize],
        chunk: usize,
        work: W,
        sink: S,
    ) -> Result<(), E>
    where
        T: Send,
        E: From<DatasetError> + Send,
        W: Fn(NativeFrame) -> Result<T, E> + Sync,
        S: FnMut(T) -> Result<(), E>,
    {
        self.process_scaled(indices, chunk, false, work, sink)
    }

    /// Frame `k`: decoded image, timestamp and exposure.
    pub fn frame(&self, k: usize) -> Result<Frame, DatasetError> {
        let image = self.decode(k)?;
        let row = &self.times.rows[k];
        Ok(Frame {
            index: k,
            name: self.names[k].clone(),
            image,
            timestamp: row.timestamp,
            exposure_ms: row.exposure_ms,
            timestamp_ns: row.timestamp_ns,
        })
    }

    /// Frame indices of `range` (clamped to the sequence), forwards or backwards.
    pub fn indices(&self, range: std::ops::Range<usize>, reverse: bool) -> Vec<usize> {
        let r = range.start.min(self.len())..range.end.min(self.len());
        if reverse {
            r.rev().collect()
        } else {
            r.collect()
        }
    }

    /// Decodes the frames `indices` in parallel and hands `work`'s results to `sink` in the
    /// order of `indices`. At most `chunk` frames are in flight at a time (decoded, worked on,
    /// or waiting for their turn), so memory stays flat in the number of frames; `sink` runs
    /// on the calling thread while the next frames are being decoded. Stops at the first
    /// error in the order of `indices`.
    pub fn process<T, E, W, S>(
        &self,
        indices: &[usize],
        chunk: usize,
        work: W,
        sink: S,
    ) -> Result<(), E>
    where
        T: Send,
        E: From<DatasetError> + Send,
        W: Fn(Frame) -> Result<T, E> + Sync,
        S: FnMut(T) -> Result<(), E>,
    {
        for_each_ordered(
            indices.len(),
            chunk,
            |i| work(self.frame(indices[i])?),
            sink,
        )
    }
}
