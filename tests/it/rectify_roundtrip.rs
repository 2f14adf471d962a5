//! The rectified-camera contract: what monovo writes next to rectified frames reads back as
//! the same pinhole, and `none` on it is the identity.
use camera_model::{CameraFile, Image, ImageSize, OutputMode, RectifyMap};

const DATASET_CAMERA: &str = "0.535719308086809 0.669566858850269 0.493248545285398 0.500408664348414 0.897966326944875\n1280 1024\ncrop\n640 480\n";

#[test]
fn rectified_camera_file_reads_back_and_none_is_identity() {
    let raw_cam = CameraFile::parse(DATASET_CAMERA).unwrap();
    let map = RectifyMap::for_mode(
        &raw_cam.input,
        raw_cam.input_size,
        &raw_cam.output,
        raw_cam.output_size,
    )
    .unwrap();
    let out = CameraFile::rectified(map.camera(), map.output_size());
    let text = out.to_text();
    assert!(text.starts_with("Pinhole "), "{text}");
    assert!(text.contains("\nnone\n640 480\n"), "{text}");
    let back = CameraFile::parse(&text).unwrap();
    let (a, b) = (map.camera(), back.input.intrinsics());
    assert!((a.fx - b.fx).abs() < 1e-9 && (a.cx - b.cx).abs() < 1e-9);
    assert!((a.fy - b.fy).abs() < 1e-9 && (a.cy - b.cy).abs() < 1e-9);
    assert_eq!(back.output, OutputMode::None);
    let ident =
        RectifyMap::for_mode(&back.input, back.input_size, &back.output, back.output_size).unwrap();
    let img = map
        .remap_u8(&Image::from_fn(1280, 1024, |x, y| ((x ^ y) & 255) as u8))
        .unwrap();
    assert_eq!(ident.remap_u8(&img).unwrap(), img);
    assert_eq!(back.output_size, ImageSize::new(640, 480));
}
