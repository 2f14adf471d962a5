//! PNG encoding of 8-bit grey, 16-bit grey and 8-bit RGB images, written atomically.

use std::path::Path;

use image::codecs::png::{CompressionType, FilterType, PngEncoder};
use image::{ExtendedColorType, ImageEncoder};

use crate::{write_atomic_with, DatasetError};

/// How hard the PNG encoder works: `Fast` for frame sequences, `Default` for plots and maps,
/// `Stored` when time matters more than disk space.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PngSpeed {
    /// Fast compression (fdeflate), Paeth filter: a noisy 640x480 frame in about 1.2 ms to
    /// about half its raw size.
    Fast,
    /// Default compression (zlib level 6), the filter chosen per row.
    Default,
    /// No compression (deflate's stored blocks, no filter): the raw size plus a few bytes
    /// per 64 KB, about 20 times faster than `Fast`; every PNG reader reads it.
    Stored,
}

fn encoder<W: std::io::Write>(w: W, speed: PngSpeed) -> PngEncoder<W> {
    match speed {
        // Paeth alone compresses rectified frames as well as the adaptive choice per row
        // (136 KB for a 640x480 frame of the synthetic sequence) and encodes 15% faster
        PngSpeed::Fast => PngEncoder::new_with_quality(w, CompressionType::Fast, FilterType::Paeth),
        PngSpeed::Default => {
            PngEncoder::new_with_quality(w, CompressionType::Default, FilterType::Adaptive)
        }
        PngSpeed::Stored => {
            PngEncoder::new_with_quality(w, CompressionType::Uncompressed, FilterType::NoFilter)
        }
    }
}

/// A first guess of the encoded size of `raw` bytes in `rows` rows: the raw size and the
/// filter bytes for stored frames, half of it for compressed ones.
fn capacity(raw: usize, rows: usize, speed: PngSpeed) -> usize {
    match speed {
        PngSpeed::Stored => raw + rows + raw / 8192 + 1024,
        _ => raw / 2 + 1024,
    }
}

fn check_len(path: &Path, len: usize, want: usize) -> Result<(), DatasetError> {
    if len != want || want == 0 {
        return Err(DatasetError::invalid(
            path,
            format!("image buffer has {len} bytes, expected {want}"),
        ));
    }
    Ok(())
}

/// The error of an encoder asked to write a buffer that does not hold `width * height *
/// channels` samples (or an unusable size): the encoder is never called with it.
fn dimension_error(
    width: usize,
    height: usize,
    channels: usize,
    samples: usize,
) -> Option<image::ImageError> {
    use image::error::{ParameterError, ParameterErrorKind};
    let want = width
        .checked_mul(height)
        .and_then(|p| p.checked_mul(channels));
    let fits = u32::try_from(width).is_ok() && u32::try_from(height).is_ok();
    if want == Some(samples) && fits && width > 0 && height > 0 {
        return None;
    }
    Some(image::ImageError::Parameter(ParameterError::from_kind(
        ParameterErrorKind::Generic(format!(
            "a {width}x{height} image with {channels} channel(s) needs {} samples, the buffer has {samples}",
            want.map_or("more than usize::MAX".to_string(), |w| w.to_string())
        )),
    )))
}

/// Encodes an image into PNG bytes. `channels` is 1 (grey) or 3 (RGB) for 8-bit data; a
/// buffer of another length than `width * height * channels` is an error.
pub fn encode_png_u8(
    width: usize,
    height: usize,
    channels: usize,
    data: &[u8],
    speed: PngSpeed,
) -> Result<Vec<u8>, image::ImageError> {
    let color = match channels {
        1 => ExtendedColorType::L8,
        3 => ExtendedColorType::Rgb8,
        n => {
            use image::error::{ParameterError, ParameterErrorKind};
            return Err(image::ImageError::Parameter(ParameterError::from_kind(
                ParameterErrorKind::Generic(format!(
                    "{n} channels; 8-bit PNG output is grey (1) or RGB (3)"
                )),
            )));
        }
    };
    if let Some(e) = dimension_error(width, height, channels, data.len()) {
        return Err(e);
    }
    let mut out = Vec::with_capacity(capacity(data.len(), height, speed));
    encoder(&mut out, speed).write_image(data, width as u32, height as u32, color)?;
    Ok(out)
}

/// Encodes a 16-bit grey image into PNG bytes; a buffer of another length than `width *
/// height` is an error.
pub fn encode_png_u16(
    width: usize,
    height: usize,
    data: &[u16],
    speed: PngSpeed,
) -> Result<Vec<u8>, image::ImageError> {
    if let Some(e) = dimension_error(width, height, 1, data.len()) {
        return Err(e);
    }
    // PNG stores 16-bit samples big-endian; the encoder takes native-endian bytes.
    let bytes: Vec<u8> = data.iter().flat_map(|v| v.to_ne_bytes()).collect();
    let mut out = Vec::with_capacity(capacity(bytes.len(), height, speed));
    encoder(&mut out, speed).write_image(
        &bytes,
        width as u32,
        height as u32,
        ExtendedColorType::L16,
    )?;
    Ok(out)
}

/// Writes an 8-bit grey (`channels == 1`) or RGB (`channels == 3`) PNG atomically.
pub fn write_png_u8(
    path: &Path,
    width: usize,
    height: usize,
    channels: usize,
    data: &[u8],
    speed: PngSpeed,
) -> Result<(), DatasetError> {
    check_len(
        path,
        data.len(),
        width.saturating_mul(height).saturating_mul(channels),
    )?;
    let bytes = encode_png_u8(width, height, channels, data, speed)
        .map_err(|e| DatasetError::invalid(path, format!("PNG encoding failed: {e}")))?;
    write_atomic_with(path, |w| std::io::Write::write_all(w, &bytes))
}

/// Writes a 16-bit grey PNG atomically.
pub fn write_png_u16(
    path: &Path,
    width: usize,
    height: usize,
    data: &[u16],
    speed: PngSpeed,
) -> Result<(), DatasetError> {
    check_len(path, data.len(), width.saturating_mul(height))?;
    let bytes = encode_png_u16(width, height, data, speed)
        .map_err(|e| DatasetError::invalid(path, format!("PNG encoding failed: {e}")))?;
    write_atomic_with(path, |w| std::io::Write::write_all(w, &bytes))
}

/// Encodes an 8-bit grey image as JPEG of the given quality (1-100); a buffer of another
/// length than `width * height` is an error.
pub fn encode_jpeg_gray(
    width: usize,
    height: usize,
    data: &[u8],
    quality: u8,
) -> Result<Vec<u8>, image::ImageError> {
    if let Some(e) = dimension_error(width, height, 1, data.len()) {
        return Err(e);
    }
    let mut out = Vec::with_capacity(data.len() / 4);
    let enc = image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, quality.clamp(1, 100));
    enc.write_image(data, width as u32, height as u32, ExtendedColorType::L8)?;
    Ok(out)
}

/// Writes a 16-bit grey PNG atomically with `tEXt` chunks (keyword, text): metadata a reader
/// finds beside the pixels (for example the scale of a map stored in 16 bits).
pub fn write_png_u16_with_text(
    path: &Path,
    width: usize,
    height: usize,
    data: &[u16],
    text: &[(&str, String)],
) -> Result<(), DatasetError> {
    check_len(path, data.len(), width.saturating_mul(height))?;
    let bad = |e: &dyn std::fmt::Display| {
        DatasetError::invalid(path, format!("PNG encoding failed: {e}"))
    };
    let mut bytes = Vec::with_capacity(data.len() + 1024);
    {
        let mut enc = ::png::Encoder::new(&mut bytes, width as u32, height as u32);
        enc.set_color(::png::ColorType::Grayscale);
        enc.set_depth(::png::BitDepth::Sixteen);
        for (k, v) in text {
            enc.add_text_chunk((*k).to_string(), v.clone())
                .map_err(|e| bad(&e))?;
        }
        let mut w = enc.write_header().map_err(|e| bad(&e))?;
        let be: Vec<u8> = data.iter().flat_map(|v| v.to_be_bytes()).collect();
        w.write_image_data(&be).map_err(|e| bad(&e))?;
        w.finish().map_err(|e| bad(&e))?;
    }
    write_atomic_with(path, |w| std::io::Write::write_all(w, &bytes))
}

/// The `tEXt` chunks of a PNG file (keyword, text).
pub fn read_png_text(path: &Path) -> Result<Vec<(String, String)>, DatasetError> {
    let file = std::fs::File::open(path).map_err(|e| DatasetError::io(path, e))?;
    let decoder = ::png::Decoder::new(std::io::BufReader::new(file));
    let reader = decoder
        .read_info()
        .map_err(|e| DatasetError::invalid(path, format!("not a readable PNG: {e}")))?;
    Ok(reader
        .info()
        .uncompressed_latin1_text
        .iter()
        .map(|t| (t.keyword.clone(), t.text.clone()))
        .collect())
}
