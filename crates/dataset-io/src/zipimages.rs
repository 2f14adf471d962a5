//! `images.zip`: the image entries of a zip archive (flat, or under a folder such as
//! `images/`), sorted by name, read one at a time. A corrupt archive is an error, never an
//! abort: entry sizes declared in the archive are not trusted for allocation.

use std::io::{Read, Seek};

/// Image extensions of a sequence (lower case).
pub(crate) const IMAGE_EXTS: [&str; 4] = ["jpg", "jpeg", "png", "pgm"];

/// Whether a file or zip entry name is an image of a sequence (not hidden, not macOS
/// metadata).
pub(crate) fn is_image_name(name: &str) -> bool {
    let lower = name.to_ascii_lowercase();
    let base = lower.rsplit('/').next().unwrap_or(&lower);
    !base.starts_with('.')
        && !lower.starts_with("__macosx")
        && IMAGE_EXTS.iter().any(|e| base.ends_with(&format!(".{e}")))
}

/// Preallocation for an entry is at most this much; larger entries grow as they are read
/// (a corrupt size field must not ask for terabytes).
const MAX_PREALLOCATION: u64 = 64 << 20;

/// The image entries of a zip archive.
///
/// ```
/// use std::io::{Cursor, Write};
/// let mut bytes = Vec::new();
/// {
///     let mut z = zip::ZipWriter::new(Cursor::new(&mut bytes));
///     z.start_file("00001.png", zip::write::SimpleFileOptions::default()).unwrap();
///     z.write_all(b"second").unwrap();
///     z.start_file("00000.png", zip::write::SimpleFileOptions::default()).unwrap();
///     z.write_all(b"first").unwrap();
///     z.finish().unwrap();
/// }
/// let mut images = dataset_io::ImagesZip::new(Cursor::new(bytes)).unwrap();
/// assert_eq!(images.names(), ["00000.png", "00001.png"]);
/// assert_eq!(images.read(0).unwrap(), b"first");
/// ```
#[derive(Debug)]
pub struct ImagesZip<R> {
    archive: zip::ZipArchive<R>,
    /// (name, archive index), sorted by name.
    entries: Vec<(String, usize)>,
    names: Vec<String>,
}

impl<R: Read + Seek> ImagesZip<R> {
    /// Reads the archive's directory and lists its image entries sorted by name. The error
    /// says what is wrong with the archive.
    pub fn new(reader: R) -> Result<ImagesZip<R>, String> {
        let archive =
            zip::ZipArchive::new(reader).map_err(|e| format!("not a readable zip: {e}"))?;
        let mut entries: Vec<(String, usize)> = (0..archive.len())
            .filter_map(|i| {
                let name = archive.name_for_index(i)?.ok()?.to_string();
                is_image_name(&name).then_some((name, i))
            })
            .collect();
        entries.sort();
        let names = entries.iter().map(|e| e.0.clone()).collect();
        Ok(ImagesZip {
            archive,
            entries,
            names,
        })
    }

    /// The image entries' names, sorted.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// Number of image entries.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// Whether there is no image entry.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// The bytes of image `k` (in name order). The error says what failed.
    pub fn read(&mut self, k: usize) -> Result<Vec<u8>, String> {
        let (name, index) = self
            .entries
            .get(k)
            .ok_or_else(|| format!("image {k} requested, the zip has {}", self.entries.len()))?;
        let mut f = self
            .archive
            .by_index(*index)
            .map_err(|e| format!("{name}: unreadable entry: {e}"))?;
        let mut buf = Vec::with_capacity(f.size().min(MAX_PREALLOCATION) as usize);
        f.read_to_end(&mut buf)
            .map_err(|e| format!("{name}: truncated or corrupt entry: {e}"))?;
        Ok(buf)
    }
}
