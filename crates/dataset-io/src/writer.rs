//! Writing a sequence folder that monovo and DSO read back: PNG frames in `images/` or in
//! `images.zip`, a matching `times.txt`, a pinhole `camera.txt`, optional calibration files.
//! Everything goes to a staging folder that appears whole at [`SequenceWriter::finish`].

use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};

use crate::temporaries::creating;
use crate::times::{times_text, TimeRow};
use crate::{DatasetError, OutputDir};

enum Images {
    Folder(PathBuf),
    Zip(Box<zip::ZipWriter<std::io::BufWriter<File>>>, PathBuf),
}

/// Writes a sequence folder frame by frame.
pub struct SequenceWriter {
    out: OutputDir,
    images: Images,
    rows: Vec<TimeRow>,
    comments: Vec<String>,
}

impl SequenceWriter {
    /// Starts writing the sequence folder `target` (refused when it exists, unless `force`);
    /// frames go to `images.zip` when `zipped`, else to `images/`.
    pub fn create(
        target: &Path,
        zipped: bool,
        force: bool,
    ) -> Result<SequenceWriter, DatasetError> {
        let out = OutputDir::create(target, force)?;
        let images = if zipped {
            let p = out.file("images.zip")?;
            let f = {
                let _gate = creating();
                File::create(&p).map_err(|e| DatasetError::io(&p, e))?
            };
            Images::Zip(Box::new(zip::ZipWriter::new(std::io::BufWriter::new(f))), p)
        } else {
            Images::Folder(out.folder("images")?)
        };
        Ok(SequenceWriter {
            out,
            images,
            rows: Vec::new(),
            comments: Vec::new(),
        })
    }

    /// The staging folder (for extra files written before [`SequenceWriter::finish`]).
    pub fn staging(&self) -> &OutputDir {
        &self.out
    }

    /// Adds one encoded frame named `id` + `.png` and its times.txt row.
    pub fn add_frame(&mut self, row: TimeRow, png: &[u8]) -> Result<(), DatasetError> {
        let name = format!("{}.png", row.id);
        match &mut self.images {
            Images::Folder(d) => {
                let p = d.join(&name);
                let _gate = creating();
                std::fs::write(&p, png).map_err(|e| DatasetError::io(&p, e))?;
            }
            Images::Zip(z, p) => {
                let opts = zip::write::SimpleFileOptions::default()
                    .compression_method(zip::CompressionMethod::Stored)
                    .large_file(false);
                z.start_file(name.as_str(), opts)
                    .map_err(|e| DatasetError::invalid(p.as_path(), format!("zip: {e}")))?;
                z.write_all(png)
                    .map_err(|e| DatasetError::io(p.as_path(), e))?;
            }
        }
        self.rows.push(row);
        Ok(())
    }

    /// Adds a `# comment` line at the top of times.txt (DSO and monovo skip such lines):
    /// where a reader finds what the values mean, for example the scale of the pixels.
    pub fn add_times_comment(&mut self, comment: &str) {
        self.comments
            .extend(comment.lines().map(|l| l.trim_end().to_string()));
    }

    /// Number of frames added.
    pub fn frames(&self) -> usize {
        self.rows.len()
    }

    /// Writes a further file (camera.txt, pcalib.txt, ...) into the sequence folder.
    pub fn add_file(&self, name: &str, bytes: &[u8]) -> Result<(), DatasetError> {
        self.out.write(name, bytes).map(|_| ())
    }

    /// Writes times.txt, closes the zip and moves the folder into place.
    pub fn finish(self) -> Result<PathBuf, DatasetError> {
        if let Images::Zip(z, p) = self.images {
            let mut w = z
                .finish()
                .map_err(|e| DatasetError::invalid(p.as_path(), format!("zip: {e}")))?;
            w.flush().map_err(|e| DatasetError::io(p.as_path(), e))?;
        }
        let mut text = String::new();
        for c in &self.comments {
            text.push_str("# ");
            text.push_str(c);
            text.push('\n');
        }
        text.push_str(&times_text(&self.rows));
        self.out.write("times.txt", text.as_bytes())?;
        self.out.commit()
    }
}

/// Writes an images.zip of already encoded images (stored, in the given order).
pub fn write_images_zip(
    path: &Path,
    entries: impl IntoIterator<Item = (String, Vec<u8>)>,
) -> Result<(), DatasetError> {
    write_stored_zip(path, entries)
}

/// Writes a zip of named files, stored (not compressed) in the given order, atomically: an
/// images.zip, or an evo result zip (`info.json`, `stats.json`, `*.npy`).
pub fn write_stored_zip(
    path: &Path,
    entries: impl IntoIterator<Item = (String, Vec<u8>)>,
) -> Result<(), DatasetError> {
    crate::write_atomic_with(path, |w| {
        let mut z = zip::ZipWriter::new(&mut *w);
        for (name, bytes) in entries {
            let opts = zip::write::SimpleFileOptions::default()
                .compression_method(zip::CompressionMethod::Stored);
            z.start_file(name.as_str(), opts)
                .map_err(std::io::Error::other)?;
            z.write_all(&bytes)?;
        }
        z.finish().map_err(std::io::Error::other)?;
        Ok(())
    })
}
