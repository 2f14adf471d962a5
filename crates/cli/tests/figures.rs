//! Checks on the figures the commands write: a PNG decodes at the expected size and shows a
//! drawing with smoothed text; an SVG is well-formed XML whose text holds the axis labels.
use std::path::Path;

/// Decodes an 8-bit RGB PNG: `(width, height, pixels)`.
pub fn read_rgb(path: &Path) -> (u32, u32, Vec<u8>) {
    let file = std::fs::File::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut reader = png::Decoder::new(std::io::BufReader::new(file))
        .read_info()
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut buf = vec![0; reader.output_buffer_size().expect("PNG size")];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!(info.color_type, png::ColorType::Rgb, "{}", path.display());
    assert_eq!(info.bit_depth, png::BitDepth::Eight, "{}", path.display());
    buf.truncate(info.buffer_size());
    (info.width, info.height, buf)
}

/// The PNG figure at `path` has the given size, a white background, a drawing (a good share
/// of coloured and dark pixels) and anti-aliased edges (many grey levels between black and
/// white, which a 1-bit font and aliased lines do not make).
pub fn check_png(path: &Path, width: u32, height: u32) {
    let (w, h, rgb) = read_rgb(path);
    assert_eq!((w, h), (width, height), "{}", path.display());
    let n = (w * h) as usize;
    let white = rgb
        .chunks(3)
        .filter(|p| p.iter().all(|&v| v == 255))
        .count();
    assert!(white > n / 4, "{}: {white} of {n} white", path.display());
    let dark = rgb.chunks(3).filter(|p| p.iter().all(|&v| v < 80)).count();
    assert!(
        dark > n / 500,
        "{}: {dark} dark pixels of {n}",
        path.display()
    );
    let coloured = rgb
        .chunks(3)
        .filter(|p| p.iter().max().unwrap() - p.iter().min().unwrap() > 60)
        .count();
    assert!(
        coloured > n / 500,
        "{}: {coloured} coloured pixels",
        path.display()
    );
    let mut greys = [false; 256];
    for p in rgb.chunks(3) {
        if p[0] == p[1] && p[1] == p[2] {
            greys[p[0] as usize] = true;
        }
    }
    let levels = greys[40..220].iter().filter(|&&g| g).count();
    assert!(levels > 60, "{}: {levels} grey levels", path.display());
}

/// The SVG figure at `path` parses as XML, is an `svg` document of the given nominal size,
/// and its text elements include every one of `labels`.
pub fn check_svg(path: &Path, width: u32, height: u32, labels: &[&str]) {
    let text = std::fs::read_to_string(path).unwrap();
    let doc = roxmltree::Document::parse(&text)
        .unwrap_or_else(|e| panic!("{}: not XML: {e}", path.display()));
    let root = doc.root_element();
    assert_eq!(root.tag_name().name(), "svg", "{}", path.display());
    assert_eq!(root.attribute("width"), Some(width.to_string().as_str()));
    assert_eq!(root.attribute("height"), Some(height.to_string().as_str()));
    let texts: Vec<String> = doc
        .descendants()
        .filter(|n| n.has_tag_name("text"))
        .map(|n| n.text().unwrap_or("").trim().to_string())
        .collect();
    for label in labels {
        assert!(
            texts.iter().any(|t| t == label),
            "{}: no text `{label}` among {texts:?}",
            path.display()
        );
    }
    let drawn = doc
        .descendants()
        .filter(|n| n.has_tag_name("polyline") || n.has_tag_name("rect"))
        .count();
    assert!(drawn > 10, "{}: {drawn} elements", path.display());
}
