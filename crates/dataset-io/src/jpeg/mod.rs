//! JPEG decoding, strict about corrupt data: zune-jpeg (pure Rust, the default) or
//! libjpeg-turbo (the `turbojpeg` feature, which also decodes at half size in the DCT domain).

#[cfg(feature = "turbojpeg")]
mod turbo;

use camera_model::Image;

/// Every 8x8 block of a Huffman-coded scan takes at least one bit (the code of its DC
/// difference); zune-jpeg has no arithmetic decoding, and the libjpeg-turbo build skips this
/// check for arithmetic-coded frames, which can spend less. A frame that declares more
/// blocks than the file has bits ended its scan early (an end-of-image marker where data
/// should be), which zune-jpeg accepts even in strict mode and would fill, for a few hundred
/// bytes, as a mostly empty image of up to 16384x16384 pixels; checked before any allocation.
pub(crate) fn check_jpeg_data_size(w: usize, h: usize, len: usize) -> Result<(), String> {
    let blocks = w.div_ceil(8).saturating_mul(h.div_ceil(8));
    if len.saturating_mul(8) < blocks {
        return Err(format!(
            "corrupt JPEG: a {w}x{h} frame needs at least {} bytes of data, the file has {len}",
            blocks.div_ceil(8),
        ));
    }
    Ok(())
}

/// Decodes a JPEG to 8-bit grey, strictly: truncated or corrupt entropy-coded data is an
/// error instead of a silently grey or smeared frame. zune-jpeg, or libjpeg-turbo with the
/// `turbojpeg` feature.
pub(crate) fn decode_jpeg_gray8(bytes: &[u8]) -> Result<Image<u8>, String> {
    #[cfg(feature = "turbojpeg")]
    return turbo::decode_gray8(bytes, 1);
    #[cfg(not(feature = "turbojpeg"))]
    decode_jpeg_gray8_zune(bytes)
}

/// The pure-Rust decoder, the default.
#[cfg_attr(feature = "turbojpeg", allow(dead_code))]
fn decode_jpeg_gray8_zune(bytes: &[u8]) -> Result<Image<u8>, String> {
    use zune_jpeg::zune_core::bytestream::ZCursor;
    use zune_jpeg::zune_core::colorspace::ColorSpace;
    use zune_jpeg::zune_core::options::DecoderOptions;
    let opts = DecoderOptions::default()
        .set_strict_mode(true)
        .jpeg_set_out_colorspace(ColorSpace::Luma);
    let mut d = zune_jpeg::JpegDecoder::new_with_options(ZCursor::new(bytes), opts);
    d.decode_headers()
        .map_err(|e| format!("corrupt JPEG: {e:?}"))?;
    let (w, h) = d
        .dimensions()
        .ok_or_else(|| "corrupt JPEG: no frame header".to_string())?;
    check_jpeg_data_size(w, h, bytes.len())?;
    let data = d.decode().map_err(|e| format!("corrupt JPEG: {e:?}"))?;
    if data.len() != w * h {
        return Err(format!(
            "corrupt JPEG: {} samples decoded for {w}x{h}",
            data.len()
        ));
    }
    Image::new(w, h, data).map_err(|e| e.to_string())
}

/// The library that decodes JPEG frames in this build: `zune-jpeg`, or `libjpeg-turbo` with
/// the `turbojpeg` feature.
pub const JPEG_DECODER: &str = if cfg!(feature = "turbojpeg") {
    "libjpeg-turbo"
} else {
    "zune-jpeg"
};

/// Whether this build decodes JPEG frames at half size in the DCT domain
/// ([`decode_jpeg_gray8_half`]): built with the `turbojpeg` feature.
pub const HALF_DECODE: bool = cfg!(feature = "turbojpeg");

/// Whether `bytes` start as a JPEG file does (the start-of-image marker): how every decoder
/// here tells JPEG from PNG and PGM.
pub(crate) fn is_jpeg(bytes: &[u8]) -> bool {
    bytes.starts_with(&[0xFF, 0xD8])
}

/// Decodes a JPEG to 8-bit grey at half its width and height (rounded up) in the DCT domain:
/// libjpeg-turbo computes each 8x8 block's inverse DCT at 4x4, so output pixel `(i, j)` is
/// close to the mean of the 2x2 input pixels from `(2i, 2j)`, centred at `(2i + 0.5, 2j +
/// 0.5)` in input pixels. About 10% less CPU time than the full libjpeg-turbo decode (the
/// entropy decoding, most of the time, stays). Needs the `turbojpeg` feature; without it the
/// error says so. Only JPEG.
pub fn decode_jpeg_gray8_half(bytes: &[u8]) -> Result<Image<u8>, String> {
    if !is_jpeg(bytes) {
        return Err("half-size decoding needs JPEG frames (DCT-domain scaling)".into());
    }
    #[cfg(feature = "turbojpeg")]
    return turbo::decode_gray8(bytes, 2);
    #[cfg(not(feature = "turbojpeg"))]
    Err(
        "half-size decoding needs libjpeg-turbo: build with `--features turbojpeg` (cmake and nasm)"
            .into(),
    )
}
