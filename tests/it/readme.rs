//! The README's Rust examples, word for word: compiled here, and a test checks that every
//! ```rust block of the README appears in this file unchanged (so neither can drift).
#![allow(dead_code, unused_variables)]
// eval_example and correction_example need a sequence folder: compiled, not run

use std::error::Error;

#[rustfmt::skip]
fn camera_example() -> Result<(), Box<dyn Error>> {
use camera_model::{CameraFile, Image, RectifyMap};

let file = CameraFile::parse(&std::fs::read_to_string("data/camera_narrow.txt")?)?;
let map = RectifyMap::for_mode(&file.input, file.input_size, &file.output, file.output_size)?;
let raw = Image::filled(1280, 1024, 128u8);
let pinhole = map.remap_u8(&raw)?;          // 640x480, bilinear, invalid pixels 0
    assert_eq!((pinhole.width(), pinhole.height()), (640, 480));
    Ok(())
}

#[rustfmt::skip]
fn eval_example() -> Result<(), Box<dyn Error>> {
use eval_metrics::{evaluate, parse_tum, GroundTruth};

let gt = GroundTruth::parse(&std::fs::read_to_string("sequence_01/groundtruthSync.txt")?)?;
let run = evaluate(&parse_tum(&std::fs::read_to_string("fwd_0.txt")?)?, &gt);
match &run.failure {
    None => println!("e_align {:.3} e_s {:.3} e_r {:.2}", run.metrics.e_align, run.metrics.e_s, run.metrics.e_r),
    Some(reason) => println!("failed: {reason}"),
}
    Ok(())
}

#[rustfmt::skip]
fn correction_example() -> Result<(), Box<dyn Error>> {
use dataset_io::Sequence;
use photometric::{Correction, InverseResponse, Vignette};

let seq = Sequence::open("sequence_01".as_ref())?;                 // validates everything
let u = InverseResponse::parse(&std::fs::read_to_string("sequence_01/pcalib.txt")?)?;
let v = Vignette::from_u16(&dataset_io::read_gray_map("sequence_01/vignette.png".as_ref())?.0)?;
let size = seq.image_size();
let corr = Correction::new(&u, Some(&v), None, (size.width, size.height), true)?;
for k in seq.indices(0..seq.len(), true) {                          // backwards
    let f = seq.frame(k)?;
    let irradiance = corr.correct(&f.image, f.exposure_ms)?;        // U(I) / (t V), NaN where saturated
}
    Ok(())
}

fn repo() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// Every ```rust block of the README is one of the examples above, unchanged.
#[test]
fn readme_rust_examples_are_the_compiled_ones() {
    let readme = std::fs::read_to_string(repo().join("README.md")).unwrap();
    let this = include_str!("readme.rs");
    let mut blocks = 0;
    let mut rest = readme.as_str();
    while let Some(start) = rest.find("```rust\n") {
        let body = &rest[start + "```rust\n".len()..];
        let end = body.find("```").unwrap();
        assert!(
            this.contains(&body[..end]),
            "a README example is not compiled in tests/it/readme.rs:\n{}",
            &body[..end]
        );
        blocks += 1;
        rest = &body[end + 3..];
    }
    assert_eq!(blocks, 3, "examples in the README");
}

/// The camera example runs as written from the repository's root (where `data/` is). No
/// other test of this binary depends on the working directory.
#[test]
fn readme_camera_example_runs() {
    std::env::set_current_dir(repo()).unwrap();
    camera_example().unwrap();
}
