//! The README's Rust examples: doctests of monovo-pipelines (compiled, not run: two need a
//! sequence folder); the camera example also runs here from the repository's root.
#![allow(unused_variables)]

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

fn repo() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The README's Rust examples are doctests of monovo-pipelines (`cargo test --doc`); this
/// checks that they stay there: three `rust,no_run` blocks, each a whole program.
#[test]
fn readme_rust_examples_are_doctests() {
    let readme = std::fs::read_to_string(repo().join("README.md")).unwrap();
    let blocks: Vec<&str> = readme.split("```rust").skip(1).collect();
    assert_eq!(blocks.len(), 3, "examples in the README");
    for b in blocks {
        assert!(b.starts_with(",no_run\n") && b.contains("fn main()"), "{b}");
    }
    let lib = std::fs::read_to_string(repo().join("crates/pipelines/src/lib.rs")).unwrap();
    assert!(lib.contains("include_str!(\"../../../README.md\")"));
    assert!(readme.contains(CAMERA_EXAMPLE_LINE));
}

/// A line of the camera example below, as the README has it.
const CAMERA_EXAMPLE_LINE: &str =
    "let map = RectifyMap::for_mode(&file.input, file.input_size, &file.output, file.output_size)?;";

/// The camera example runs as written from the repository's root (where `data/` is). No
/// other test of this binary depends on the working directory.
#[test]
fn readme_camera_example_runs() {
    std::env::set_current_dir(repo()).unwrap();
    camera_example().unwrap();
}
