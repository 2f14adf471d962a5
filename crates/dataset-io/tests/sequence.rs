//! Opening, validating and reading sequence folders.
use camera_model::Image;
use dataset_io::{
    encode_jpeg_gray, encode_png_u8, parse_times, write_images_zip, DatasetError, PngSpeed,
    Sequence, SequenceWriter, TimeRow,
};
use std::path::Path;

fn tmp(name: &str) -> crate::TempDir {
    crate::TempDir::new("seq", name)
}

fn pattern(i: usize, w: usize, h: usize) -> Vec<u8> {
    (0..w * h)
        .map(|p| ((p % w) * 3 + (p / w) * 5 + i * 40) as u8)
        .collect()
}

const CAMERA: &str = "FOV 0.5357 0.6696 0.4932 0.5004 0.898\n64 48\ncrop\n32 24\n";

/// A sequence folder of `n` 64x48 JPEG frames in images.zip under `prefix`.
fn make(dir: &Path, n: usize, prefix: &str) {
    std::fs::create_dir_all(dir).unwrap();
    let entries = (0..n).map(|i| {
        (
            format!("{prefix}{i:05}.jpg"),
            encode_jpeg_gray(64, 48, &pattern(i, 64, 48), 95).unwrap(),
        )
    });
    write_images_zip(&dir.join("images.zip"), entries).unwrap();
    let times: String = (0..n)
        .map(|i| format!("{i:05} {} {}\n", 100.0 + i as f64 * 0.05, 5.0 + i as f64))
        .collect();
    std::fs::write(dir.join("times.txt"), times).unwrap();
    std::fs::write(dir.join("camera.txt"), CAMERA).unwrap();
}

#[test]
fn zipped_flat_prefixed_and_folder_sequences_read_the_same() {
    let d = tmp("layouts");
    make(&d.join("flat"), 5, "");
    make(&d.join("prefixed"), 5, "images/");
    let folder = d.join("folder");
    std::fs::create_dir_all(folder.join("images")).unwrap();
    for i in 0..5 {
        std::fs::write(
            folder.join(format!("images/{i:05}.png")),
            encode_png_u8(64, 48, 1, &pattern(i, 64, 48), PngSpeed::Fast).unwrap(),
        )
        .unwrap();
    }
    std::fs::copy(d.join("flat/times.txt"), folder.join("times.txt")).unwrap();
    let a = Sequence::open(&d.join("flat")).unwrap();
    let b = Sequence::open(&d.join("prefixed")).unwrap();
    let c = Sequence::open(&folder).unwrap();
    assert_eq!(a.len(), 5);
    assert!(a.is_zipped() && !c.is_zipped());
    assert_eq!(a.image_size(), camera_model::ImageSize::new(64, 48));
    assert_eq!(a.decode(3).unwrap(), b.decode(3).unwrap());
    // the PNG folder is lossless
    assert_eq!(
        c.decode(2).unwrap(),
        Image::new(64, 48, pattern(2, 64, 48)).unwrap()
    );
    let f = a.frame(4).unwrap();
    assert_eq!((f.index, f.timestamp, f.exposure_ms), (4, 100.2, Some(9.0)));
    assert!(a.camera().is_some() && c.camera().is_none());
    assert_eq!(a.indices(1..4, true), vec![3, 2, 1]);
    assert_eq!(a.indices(3..99, false), vec![3, 4]);
}

#[test]
fn parallel_processing_keeps_the_order() {
    let d = tmp("order");
    make(&d, 23, "");
    let s = Sequence::open(&d).unwrap();
    let idx = s.indices(0..23, true);
    let mut seen = Vec::new();
    s.process(
        &idx,
        4,
        |f| Ok::<_, DatasetError>(f.index),
        |i| {
            seen.push(i);
            Ok(())
        },
    )
    .unwrap();
    assert_eq!(seen, idx);
}

fn open_err(dir: &Path) -> String {
    Sequence::open(dir).unwrap_err().to_string()
}

#[test]
fn bad_sequences_name_the_file_and_what_is_wrong() {
    let d = tmp("bad");
    // one times.txt row too few
    make(&d.join("short"), 4, "");
    let t = std::fs::read_to_string(d.join("short/times.txt")).unwrap();
    std::fs::write(
        d.join("short/times.txt"),
        t.lines()
            .take(3)
            .map(|l| format!("{l}\n"))
            .collect::<String>(),
    )
    .unwrap();
    let e = open_err(&d.join("short"));
    assert!(
        e.contains("times.txt") && e.contains("3 rows") && e.contains("4 images"),
        "{e}"
    );
    // camera size disagrees
    make(&d.join("cam"), 3, "");
    std::fs::write(
        d.join("cam/camera.txt"),
        CAMERA.replace("64 48", "1280 1024"),
    )
    .unwrap();
    let e = open_err(&d.join("cam"));
    assert!(
        e.contains("camera.txt") && e.contains("line 2") && e.contains("64x48"),
        "{e}"
    );
    // non-monotone timestamps
    make(&d.join("order"), 3, "");
    std::fs::write(d.join("order/times.txt"), "0 1.0 5\n1 0.5 5\n2 2.0 5\n").unwrap();
    let e = open_err(&d.join("order"));
    assert!(e.contains("times.txt") && e.contains("line 2"), "{e}");
    // a corrupt JPEG is reported with its entry name when decoded
    make(&d.join("corrupt"), 3, "");
    let entries = (0..3).map(|i| {
        let mut b = encode_jpeg_gray(64, 48, &pattern(i, 64, 48), 95).unwrap();
        if i == 2 {
            b.truncate(100);
        }
        (format!("{i:05}.jpg"), b)
    });
    write_images_zip(&d.join("corrupt/images.zip"), entries).unwrap();
    let s = Sequence::open(&d.join("corrupt")).unwrap();
    let e = s.decode(2).unwrap_err().to_string();
    assert!(e.contains("images.zip") && e.contains("00002.jpg"), "{e}");
    // not a zip at all
    make(&d.join("notzip"), 2, "");
    std::fs::write(d.join("notzip/images.zip"), b"garbage").unwrap();
    let e = open_err(&d.join("notzip"));
    assert!(e.contains("images.zip") && e.contains("zip"), "{e}");
    // no images at all
    std::fs::create_dir_all(d.join("empty")).unwrap();
    assert!(open_err(&d.join("empty")).contains("no images.zip"));
}

#[test]
fn times_txt_rules() {
    let p = Path::new("times.txt");
    let t = parse_times("0 1.0 5\n1 1.1 0\n2 1.2 7\n", p).unwrap();
    assert_eq!(t.rows[1].exposure_ms, Some(6.0));
    assert_eq!(t.warnings.len(), 1);
    assert!(t.has_exposures());
    let t = parse_times("0 1.0\n1 1.1\n", p).unwrap();
    assert!(!t.has_exposures() && t.exposure_range().is_none());
    for (bad, line) in [
        ("0 1.0 5\n1 1.1\n", 2),
        ("0 x 5\n", 1),
        ("0 1.0 -1\n", 1),
        ("0 1.0 nan\n", 1),
        ("0 1.0 5\n1.5\n", 2),
    ] {
        match parse_times(bad, p) {
            Err(DatasetError::Parse { line: l, .. }) => assert_eq!(l, line, "{bad}"),
            other => panic!("{bad}: {other:?}"),
        }
    }
    // like DSO: columns after the third ignored (with a warning), BOM and CRLF fine
    let t = parse_times("\u{feff}0 1.0 5 extra\r\n1 1.1 6 x\r\n", p).unwrap();
    assert_eq!(t.rows.len(), 2);
    assert_eq!(
        (t.rows[0].id.as_str(), t.rows[1].exposure_ms),
        ("0", Some(6.0))
    );
    assert!(
        t.warnings[0].contains("more than 3 columns"),
        "{:?}",
        t.warnings
    );
    // KITTI: one timestamp per line
    let t = parse_times("0.000000e+00\n1.037359e-01\n", p).unwrap();
    assert_eq!(t.rows[1].timestamp, 0.1037359);
    assert_eq!(t.rows[1].id, "1");
    assert!(t.warnings[0].contains("KITTI"));
    // a decimal comma gets a hint
    let e = parse_times("00001 1659071542,71 16,7\n", p)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("line 1") && e.contains("decimal separator must be '.'"),
        "{e}"
    );
}

/// 16-bit PNG frames keep their values; vignettes of every real kind read as grey.
#[test]
fn native_bit_depth_and_grey_maps() {
    use dataset_io::{decode_gray, decode_gray_map, encode_png_u16, GrayImage};
    let vals: Vec<u16> = (0..12).map(|i| i * 300 + 7).collect();
    let png = encode_png_u16(4, 3, &vals, PngSpeed::Fast).unwrap();
    match decode_gray(&png).unwrap() {
        GrayImage::U16(i) => assert_eq!(i.data(), &vals[..]),
        other => panic!("{other:?}"),
    }
    let png8 = encode_png_u8(4, 3, 1, &[9u8; 12], PngSpeed::Fast).unwrap();
    assert!(matches!(decode_gray(&png8).unwrap(), GrayImage::U8(_)));
    assert_eq!(
        decode_gray_map(&png).unwrap(),
        (camera_model::Image::new(4, 3, vals).unwrap(), 16)
    );
    // grey stored as RGB is that grey; real colour is refused
    let rgb: Vec<u8> = (0..12u8).flat_map(|v| [v, v, v]).collect();
    let (g, bits) =
        decode_gray_map(&encode_png_u8(4, 3, 3, &rgb, PngSpeed::Fast).unwrap()).unwrap();
    assert_eq!((g.get(3, 2), bits), (Some(11), 8));
    let mut colour = rgb.clone();
    colour[4] = 200;
    let e = decode_gray_map(&encode_png_u8(4, 3, 3, &colour, PngSpeed::Fast).unwrap()).unwrap_err();
    assert!(e.contains("must be grey"), "{e}");
}

/// A sequence of 16-bit PNG frames reports 16 bits and decodes them unscaled.
#[test]
fn sixteen_bit_sequences() {
    use dataset_io::{encode_png_u16, GrayImage};
    let d = tmp("sixteen");
    let dir = d.join("seq");
    std::fs::create_dir_all(dir.join("images")).unwrap();
    let mut times = String::new();
    for i in 0..3u16 {
        let vals: Vec<u16> = (0..64 * 48).map(|p| (p as u16 % 4096) + i).collect();
        let png = encode_png_u16(64, 48, &vals, PngSpeed::Fast).unwrap();
        std::fs::write(dir.join(format!("images/{i:05}.png")), png).unwrap();
        times += &format!("{i:05} {}.0 10\n", i);
    }
    std::fs::write(dir.join("times.txt"), times).unwrap();
    let s = Sequence::open(&dir).unwrap();
    assert_eq!(s.bits_per_sample(), 16);
    match s.decode_native(2).unwrap() {
        GrayImage::U16(i) => assert_eq!(i.get(5, 0), Some(7)),
        other => panic!("{other:?}"),
    }
    let mut seen = Vec::new();
    s.process_native(
        &[2, 0],
        4,
        |f| Ok::<_, DatasetError>((f.index, f.image.bits())),
        |r| {
            seen.push(r);
            Ok(())
        },
    )
    .unwrap();
    assert_eq!(seen, vec![(2, 16), (0, 16)]);
}

#[test]
fn written_sequences_read_back() {
    let d = tmp("write");
    for zipped in [false, true] {
        let out = d.join(if zipped { "z" } else { "f" });
        let mut w = SequenceWriter::create(&out, zipped, false).unwrap();
        for i in 0..4 {
            let png = encode_png_u8(64, 48, 1, &pattern(i, 64, 48), PngSpeed::Fast).unwrap();
            w.add_frame(
                TimeRow {
                    id: format!("{i:05}"),
                    timestamp: i as f64,
                    exposure_ms: Some(2.0),
                    timestamp_ns: None,
                },
                &png,
            )
            .unwrap();
        }
        w.add_file("camera.txt", CAMERA.as_bytes()).unwrap();
        w.finish().unwrap();
        let s = Sequence::open(&out).unwrap();
        assert_eq!(s.len(), 4);
        assert_eq!(s.is_zipped(), zipped);
        assert_eq!(s.decode(3).unwrap().data(), &pattern(3, 64, 48)[..]);
        assert!(SequenceWriter::create(&out, zipped, false).is_err());
    }
}

#[test]
fn zero_exposures_name_their_file_lines() {
    let p = Path::new("times.txt");
    // an isolated zero is interpolated; two adjacent zeros stay unknown; lines count the
    // comments and blank lines of the file
    let t = parse_times(
        "# comment\n0 1.0 5\n1 1.1 0\n2 1.2 7\n\n3 1.3 0\n4 1.4 0\n5 1.5 8\n",
        p,
    )
    .unwrap();
    assert_eq!(t.lines, vec![2, 3, 4, 6, 7, 8]);
    assert_eq!(t.rows[1].exposure_ms, Some(6.0));
    assert!(t.warnings[0].contains("line 3") && t.warnings[0].contains("interpolated"));
    assert!(
        t.warnings[1].contains("line 6") && t.warnings[1].contains("unknown"),
        "{:?}",
        t.warnings
    );
    assert_eq!(t.first_unknown_exposure(), Some((3, 6)));
    assert!(!t.has_exposures());
}

/// A zip whose entry declares a size far beyond the archive: an error or the bytes there
/// are, never an allocation of the declared size.
#[test]
fn a_corrupt_zip_entry_size_is_not_trusted() {
    use std::io::{Cursor, Write};
    let mut bytes = Vec::new();
    {
        let mut z = zip::ZipWriter::new(Cursor::new(&mut bytes));
        let opts = zip::write::SimpleFileOptions::default()
            .compression_method(zip::CompressionMethod::Stored);
        z.start_file("00000.png", opts).unwrap();
        z.write_all(&[7u8; 100]).unwrap();
        z.finish().unwrap();
    }
    // the central directory's and the local header's uncompressed size: 4 GiB - 16
    let patch = |b: &mut Vec<u8>, sig: [u8; 4], offset: usize| {
        let at = b.windows(4).position(|w| w == sig).unwrap();
        b[at + offset..at + offset + 4].copy_from_slice(&0xFFFF_FFF0u32.to_le_bytes());
    };
    patch(&mut bytes, [0x50, 0x4b, 0x01, 0x02], 24);
    patch(&mut bytes, [0x50, 0x4b, 0x03, 0x04], 22);
    match dataset_io::ImagesZip::new(Cursor::new(bytes)) {
        Ok(mut z) => {
            assert_eq!(z.names(), ["00000.png"]);
            if let Ok(b) = z.read(0) {
                assert!(b.len() <= 100);
            }
        }
        Err(e) => assert!(e.contains("zip"), "{e}"),
    }
}

/// A JPEG whose frame header declares far more 8x8 blocks than its scan can hold (the scan
/// ends early at an end-of-image marker) is corrupt, not a large empty image.
#[test]
fn a_jpeg_too_short_for_its_size_is_corrupt() {
    let good = encode_jpeg_gray(16, 16, &pattern(0, 16, 16), 90).unwrap();
    assert_eq!(
        dataset_io::decode_gray8(&good).unwrap().width(),
        16,
        "the unchanged frame decodes"
    );
    // the frame header (SOF0: FF C0, length, precision, height, width): 12336x2305
    let sof = good.windows(2).position(|w| w == [0xFF, 0xC0]).unwrap();
    let mut big = good.clone();
    big[sof + 5..sof + 9].copy_from_slice(&[0x30, 0x30, 0x09, 0x01]);
    for decode in [
        |b: &[u8]| dataset_io::decode_gray8(b).map(|_| ()),
        |b: &[u8]| dataset_io::decode_gray(b).map(|_| ()),
        #[cfg(feature = "turbojpeg")]
        |b: &[u8]| dataset_io::decode_jpeg_gray8_half(b).map(|_| ()),
    ] {
        let e = decode(&big).unwrap_err();
        assert!(
            e.contains("corrupt JPEG") && e.contains("2305x12336"),
            "{e}"
        );
    }
}

#[test]
fn encoders_refuse_a_buffer_of_the_wrong_length() {
    use dataset_io::{encode_jpeg_gray, encode_png_u16, encode_png_u8, PngSpeed};
    assert!(encode_png_u8(4, 4, 1, &[0u8; 15], PngSpeed::Fast).is_err());
    assert!(encode_png_u8(4, 4, 3, &[0u8; 16], PngSpeed::Fast).is_err());
    assert!(encode_png_u8(4, 4, 2, &[0u8; 32], PngSpeed::Fast).is_err());
    assert!(encode_png_u8(usize::MAX, 2, 1, &[0u8; 4], PngSpeed::Fast).is_err());
    assert!(encode_png_u16(4, 4, &[0u16; 17], PngSpeed::Fast).is_err());
    assert!(encode_jpeg_gray(4, 4, &[0u8; 3], 90).is_err());
    assert!(encode_png_u8(4, 4, 1, &[0u8; 16], PngSpeed::Fast).is_ok());
    assert!(encode_png_u16(4, 4, &[0u16; 16], PngSpeed::Fast).is_ok());
}

/// A smooth 8-bit test image (no detail finer than 8 pixels), whose 2x2 block means a
/// DCT-domain half-size decode reproduces closely.
#[cfg(feature = "turbojpeg")]
fn smooth(w: usize, h: usize) -> Vec<u8> {
    (0..w * h)
        .map(|p| {
            let (x, y) = ((p % w) as f64, (p / w) as f64);
            (128.0 + 60.0 * (x / 9.0).sin() * (y / 11.0).cos() + 0.3 * x - 0.2 * y)
                .round()
                .clamp(0.0, 255.0) as u8
        })
        .collect()
}

/// libjpeg-turbo's half-size decode, pixel by pixel, is the mean of the 2x2 block of the full
/// decode (its DCT-domain scaling keeps the low frequencies): within 2 grey levels on a smooth
/// image at quality 95, odd sizes rounded up. A truncated frame is an error that names the
/// entry, as with the full decode.
#[cfg(feature = "turbojpeg")]
#[test]
fn half_size_decoding_gives_the_2x2_means() {
    const { assert!(dataset_io::HALF_DECODE) };
    for (w, h) in [(64, 48), (65, 49), (128, 96)] {
        let jpeg = encode_jpeg_gray(w, h, &smooth(w, h), 95).unwrap();
        let full = dataset_io::decode_gray8(&jpeg).unwrap();
        let half = dataset_io::decode_jpeg_gray8_half(&jpeg).unwrap();
        assert_eq!(half.size(), (w.div_ceil(2), h.div_ceil(2)));
        let mut worst = 0.0f64;
        for j in 0..h / 2 {
            for i in 0..w / 2 {
                let f = |x: usize, y: usize| full.data()[y * w + x] as f64;
                let mean = (f(2 * i, 2 * j)
                    + f(2 * i + 1, 2 * j)
                    + f(2 * i, 2 * j + 1)
                    + f(2 * i + 1, 2 * j + 1))
                    / 4.0;
                worst = worst.max((half.data()[j * half.width() + i] as f64 - mean).abs());
            }
        }
        assert!(worst <= 2.0, "{w}x{h}: worst {worst}");
    }
    let d = tmp("half");
    make(&d, 3, "");
    let s = Sequence::open(&d).unwrap();
    assert_eq!(s.decode_half(1).unwrap().size(), (32, 24));
    let entries = (0..3).map(|i| {
        let mut b = encode_jpeg_gray(64, 48, &pattern(i, 64, 48), 95).unwrap();
        if i == 2 {
            b.truncate(b.len() / 2);
        }
        (format!("{i:05}.jpg"), b)
    });
    write_images_zip(&d.join("images.zip"), entries).unwrap();
    let s = Sequence::open(&d).unwrap();
    for e in [
        s.decode_half(2).unwrap_err().to_string(),
        s.decode(2).unwrap_err().to_string(),
    ] {
        assert!(e.contains("00002.jpg") && e.contains("corrupt JPEG"), "{e}");
    }
}

/// Without libjpeg-turbo, asking for half-size decoding says how to build it.
#[cfg(not(feature = "turbojpeg"))]
#[test]
fn half_size_decoding_without_libjpeg_turbo_says_how_to_get_it() {
    const { assert!(!dataset_io::HALF_DECODE) };
    let jpeg = encode_jpeg_gray(16, 16, &pattern(0, 16, 16), 90).unwrap();
    let e = dataset_io::decode_jpeg_gray8_half(&jpeg).unwrap_err();
    assert!(e.contains("--features turbojpeg"), "{e}");
}

/// Half-size decoding is for JPEG (DCT-domain scaling); a PNG frame is refused, not decoded
/// at full size.
#[test]
fn half_size_decoding_refuses_a_png() {
    let png = encode_png_u8(16, 16, 1, &pattern(0, 16, 16), PngSpeed::Fast).unwrap();
    let e = dataset_io::decode_jpeg_gray8_half(&png).unwrap_err();
    assert!(e.contains("JPEG"), "{e}");
}

/// A frame wider than 16384 pixels is refused before any allocation by both decoders
/// (zune-jpeg's limit, kept by the libjpeg-turbo build), with the size in the error.
#[test]
fn a_jpeg_wider_than_16384_is_refused() {
    let good = encode_jpeg_gray(16, 16, &pattern(0, 16, 16), 90).unwrap();
    let sof = good.windows(2).position(|w| w == [0xFF, 0xC0]).unwrap();
    let mut wide = good.clone();
    // height 8, width 16400: 2050 blocks, which the file's bits could hold
    wide[sof + 5..sof + 9].copy_from_slice(&[0x00, 0x08, 0x40, 0x10]);
    assert!(good.len() * 8 >= 2050, "{}", good.len());
    let e = dataset_io::decode_gray8(&wide).unwrap_err();
    assert!(e.contains("16384") && e.contains("16400"), "{e}");
}

/// A corrupt frame leaves nothing behind in the decoder: the good frames before and after it
/// decode the same (libjpeg-turbo's handle, reused per thread, would otherwise keep failing
/// with the corrupt frame's error), here on one thread, in every order.
#[test]
fn a_corrupt_jpeg_does_not_spoil_the_next_frame() {
    let good = encode_jpeg_gray(16, 16, &pattern(0, 16, 16), 90).unwrap();
    let want = dataset_io::decode_gray8(&good).unwrap();
    let mut flipped = good.clone();
    let n = flipped.len();
    flipped[n - 20] ^= 0x10;
    let truncated = &good[..good.len() / 2];
    for bad in [&[0xFF, 0xD8, 1, 2, 3][..], truncated, &flipped, &good[..2]] {
        let _ = dataset_io::decode_gray8(bad);
        assert_eq!(dataset_io::decode_gray8(&good).unwrap(), want);
        let _ = dataset_io::decode_jpeg_gray8_half(bad);
        assert_eq!(dataset_io::decode_gray8(&good).unwrap(), want);
        if dataset_io::HALF_DECODE {
            assert_eq!(
                dataset_io::decode_jpeg_gray8_half(&good).unwrap().size(),
                (8, 8)
            );
        }
    }
}
