//! The README as a front page and the guide in docs/: the README is short and gives the
//! set-up commands CI runs, every link of the README and of the guide points to a file of
//! the repository, and the guide's Rust examples are doctests of monovo-pipelines (compiled,
//! not run: two need a sequence folder); the camera example also runs here.
#![allow(unused_variables)]

use std::error::Error;
use std::path::{Path, PathBuf};

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

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn read(path: &str) -> String {
    std::fs::read_to_string(repo().join(path)).unwrap()
}

/// The guide's pages, with docs/index.md first.
fn guide_pages() -> Vec<PathBuf> {
    let mut pages: Vec<PathBuf> = std::fs::read_dir(repo().join("docs"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "md"))
        .collect();
    pages.sort();
    pages
}

/// The README is a front page: at most 200 lines, with the set-up commands that CI runs.
#[test]
fn readme_is_a_front_page() {
    let readme = read("README.md");
    assert!(
        readme.lines().count() <= 200,
        "README.md: {} lines",
        readme.lines().count()
    );
    let ci = read(".ci/run");
    for (command, in_ci) in [
        (
            "cargo run --release -p monovo -- demo",
            "cargo run --release --locked -p monovo -- demo",
        ),
        ("cargo test --workspace", "cargo test --workspace --locked"),
        ("pip install .", "pip install"),
    ] {
        assert!(
            readme.contains(command),
            "the README's set-up command `{command}`"
        );
        assert!(ci.contains(in_ci), ".ci/run runs `{in_ci}`");
    }
    for page in [
        "docs/index.md",
        "docs/getting-started.md",
        "docs/datasets-and-formats.md",
        "docs/rectification-and-photometric-correction.md",
        "docs/calibration.md",
        "docs/evaluation.md",
        "docs/python.md",
        "docs/architecture.md",
        "docs/performance.md",
    ] {
        assert!(
            readme.contains(&format!("]({page})")),
            "the README links {page}"
        );
    }
    let index = read("docs/index.md");
    for page in guide_pages() {
        let name = page.file_name().unwrap().to_str().unwrap();
        if name != "index.md" {
            assert!(
                index.contains(&format!("]({name})")),
                "docs/index.md links {name}"
            );
        }
    }
}

/// Every relative link and image of the README and of the guide's pages is a file of the
/// repository (anchors dropped).
#[test]
fn links_point_into_the_repository() {
    let root = repo().canonicalize().unwrap();
    let mut pages = vec![root.join("README.md")];
    pages.extend(guide_pages());
    for page in pages {
        let text = std::fs::read_to_string(&page).unwrap();
        let dir = page.parent().unwrap();
        for (i, _) in text.match_indices("](") {
            let target = &text[i + 2..];
            let target = &target[..target.find(')').unwrap()];
            let file = target.split('#').next().unwrap();
            if target.starts_with("http") || file.is_empty() {
                continue;
            }
            let path = dir.join(file);
            let shown = format!("{}: {target}", page.display());
            assert!(path.is_file(), "{shown} is not a file");
            assert!(
                path.canonicalize().unwrap().starts_with(&root),
                "{shown} leaves the repository"
            );
        }
    }
}

/// The guide's Rust examples are doctests of monovo-pipelines (`cargo test --doc`); this
/// checks that they stay there: three `rust,no_run` blocks, each a whole program.
#[test]
fn guide_rust_examples_are_doctests() {
    let page = read("docs/architecture.md");
    let blocks: Vec<&str> = page.split("```rust").skip(1).collect();
    assert_eq!(blocks.len(), 3, "examples in docs/architecture.md");
    for b in blocks {
        assert!(b.starts_with(",no_run\n") && b.contains("fn main()"), "{b}");
    }
    let lib = read("crates/pipelines/src/lib.rs");
    assert!(lib.contains("include_str!(\"../../../docs/architecture.md\")"));
    assert!(page.contains(CAMERA_EXAMPLE_LINE));
}

/// A line of the camera example below, as the guide has it.
const CAMERA_EXAMPLE_LINE: &str =
    "let map = RectifyMap::for_mode(&file.input, file.input_size, &file.output, file.output_size)?;";

/// The camera example runs as written from the repository's root (where `data/` is). No
/// other test of this binary depends on the working directory.
#[test]
fn guide_camera_example_runs() {
    std::env::set_current_dir(repo()).unwrap();
    camera_example().unwrap();
}
