//! Reading: the job's options checked, the sequence opened with its camera and calibration
//! files, the exposures the job needs checked; everything that can refuse the job comes
//! before the first frame.

use std::path::{Path, PathBuf};

use camera_model::{output_notes, CameraFile, ImageSize, OutputMode};
use dataset_io::Sequence;
use photometric::InverseResponse;

use super::RectifyJob;
use crate::{Observer, PipelineError, Result, WithContext};

/// The options that contradict each other, refused before the sequence is read.
pub(super) fn check_options(args: &RectifyJob) -> Result<()> {
    let photometric = args.photometric || args.irradiance;
    if !photometric {
        if args.scale.is_some() {
            return Err(PipelineError::Invalid(
                "--scale sets the scale of photometric output: add --photometric or --irradiance"
                    .into(),
            ));
        }
        if args.mask_saturated {
            return Err(PipelineError::Invalid(
                "--mask-saturated masks photometric output: add --photometric or --irradiance"
                    .into(),
            ));
        }
    }
    if let Some(s) = args.scale {
        if !(s.is_finite() && s > 0.0) {
            return Err(PipelineError::Invalid(format!(
                "--scale {s}: must be a positive number"
            )));
        }
    }
    Ok(())
}

/// The opened sequence with its camera, the output camera and the bit depths.
pub(super) struct Input {
    pub seq: Sequence,
    pub cam: CameraFile,
    pub camera_path: PathBuf,
    /// The output pinhole.
    pub mode: OutputMode,
    pub out_size: ImageSize,
    /// Bits per sample of the frames as stored (8 or 16).
    pub in_bits: u32,
    /// Bits of the values in 16-bit frames (`--bit-depth`, else the stored bits; set to the
    /// table's depth for photometric output once pcalib.txt is read).
    pub bits: u32,
    /// Bits per output pixel, 8 or 16.
    pub out_depth: u8,
}

impl Input {
    /// Opens the sequence and its camera, warns about what DSO would read differently, and
    /// checks the bit depth and `--half-decode` against the frames.
    pub fn open(args: &RectifyJob, observer: &dyn Observer) -> Result<Input> {
        let seq =
            Sequence::open_with_calibration(&args.sequence, args.cam, args.calibration.as_deref())?;
        for w in seq.times().warnings.iter().chain(&seq.layout_warnings) {
            observer.warn(w);
        }
        let Some(cam) = seq.camera() else {
            return Err(PipelineError::Invalid(format!(
                "{}: no camera.txt (or the {} layout's calibration file); rectify needs the camera model",
                args.sequence.display(),
                seq.layout().name()
            )));
        };
        let cam = cam.clone();
        let mode = args.pinhole.unwrap_or(cam.output);
        let out_size = args.size.unwrap_or(cam.output_size);
        let camera_path = seq
            .camera_path()
            .map_or_else(|| args.sequence.join("camera.txt"), Path::to_path_buf);
        for w in
            cam.warnings
                .iter()
                .chain(&output_notes(&cam.input, cam.input_size, &mode, out_size))
        {
            observer.warn(&format!("{}: {w}", camera_path.display()));
        }
        let in_bits = seq.bits_per_sample();
        let bits = args.bit_depth.unwrap_or(in_bits);
        if in_bits == 8 && bits != 8 {
            return Err(PipelineError::Invalid(format!(
                "--bit-depth {bits}: the frames of {} are 8-bit; --bit-depth describes 16-bit frames whose values use fewer bits",
                args.sequence.display()
            )));
        }
        if args.half_decode {
            check_half_decode(args, in_bits == 16)?;
        }
        Ok(Input {
            seq,
            cam,
            camera_path,
            mode,
            out_size,
            in_bits,
            bits,
            out_depth: args.depth.unwrap_or(if in_bits == 16 { 16 } else { 8 }),
        })
    }

    /// Whether the frames are 16-bit.
    pub fn deep(&self) -> bool {
        self.in_bits == 16
    }

    /// The frames' exposures where the job needs them: `--irradiance` refuses a frame
    /// without one, `--photometric` warns.
    pub fn check_exposures(
        &self,
        args: &RectifyJob,
        indices: &[usize],
        observer: &dyn Observer,
    ) -> Result<()> {
        let seq = &self.seq;
        if args.irradiance {
            let times = seq.times();
            if let Some(&i) = indices
                .iter()
                .find(|&&i| !times.rows[i].exposure_ms.is_some_and(|e| e > 0.0))
            {
                return Err(PipelineError::Invalid(format!(
                    "{}: line {}: the exposure of frame {i} ({}) is unknown (0 or missing); --irradiance divides by the exposure time of every frame",
                    seq.times_path().display(),
                    times.lines.get(i).copied().unwrap_or(i + 1),
                    seq.names()[i]
                )));
            }
        } else if args.photometric {
            if let Some((i, line)) = seq.times().first_unknown_exposure() {
                observer.warn(&format!(
                    "{}: line {line}: frame {i} has no known exposure; the photometric output keeps the exposure column as it is (--irradiance would refuse)",
                    seq.times_path().display()
                ));
            }
        }
        Ok(())
    }
}

/// `--half-decode` needs libjpeg-turbo, 8-bit JPEG frames and no saturation mask.
fn check_half_decode(args: &RectifyJob, deep: bool) -> Result<()> {
    if !dataset_io::HALF_DECODE {
        return Err(PipelineError::Invalid(
            "--half-decode needs libjpeg-turbo: this monovo was built without it (build it with `cargo build --release -p monovo --features turbojpeg`, which needs cmake and nasm)".into(),
        ));
    }
    if deep {
        return Err(PipelineError::Invalid(format!(
            "--half-decode: the frames of {} are 16-bit; half-size decoding is for JPEG frames",
            args.sequence.display()
        )));
    }
    if args.mask_saturated {
        return Err(PipelineError::Invalid(
            "--half-decode with --mask-saturated: a half-size pixel averages 2x2 pixels, and which of them saturated is lost; drop one of the two".into(),
        ));
    }
    Ok(())
}

/// A sequence's `pcalib.txt`, read once: its text (copied as it is into a geometric output),
/// the inverse response and the parser's notes.
pub(super) struct ResponseFile {
    pub path: PathBuf,
    pub text: String,
    pub response: InverseResponse,
    pub notes: Vec<String>,
}

/// The sequence's `pcalib.txt` and `vignette.png`, each when it has them; for frames decoded
/// at half size, the vignette averaged over the same 2x2 blocks.
pub(super) fn read_calibration(
    seq: &Sequence,
    half: bool,
) -> Result<(Option<ResponseFile>, Option<photometric::Vignette>)> {
    let response = match &seq.pcalib_path {
        Some(p) => {
            let text = dataset_io::read_text(p)?;
            let (response, notes) = InverseResponse::parse_with_notes(&text)
                .with_context(|| p.display().to_string())?;
            Some(ResponseFile {
                path: p.clone(),
                text,
                response,
                notes,
            })
        }
        None => None,
    };
    let vignette = match &seq.vignette_path {
        Some(p) => {
            let v = crate::read_vignette(p, seq.image_size())?;
            Some(if half {
                v.half_size().with_context(|| p.display().to_string())?
            } else {
                v
            })
        }
        None => None,
    };
    Ok((response, vignette))
}
