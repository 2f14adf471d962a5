//! Reading text and writing files atomically: a temporary name in the same folder, then a
//! rename, so that an interrupted or failed run never leaves a half-written output.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use crate::DatasetError;

/// Reads a whole text file; the error names the file.
pub fn read_text(path: &Path) -> Result<String, DatasetError> {
    std::fs::read_to_string(path).map_err(|e| DatasetError::io(path, e))
}

static COUNTER: AtomicU64 = AtomicU64::new(0);

/// A temporary sibling of `path`: same folder, hidden, unique to this process and call.
pub fn temp_sibling(path: &Path) -> PathBuf {
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    let name = path
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "out".into());
    path.with_file_name(format!(".{name}.tmp-{}-{n}", std::process::id()))
}

/// Writes `bytes` to `path` atomically (temporary sibling, then rename). On any error the
/// temporary file is removed and `path` is untouched.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), DatasetError> {
    write_atomic_with(path, |w| w.write_all(bytes))
}

/// Like [`write_atomic`], with the content produced by a writer callback.
pub fn write_atomic_with(
    path: &Path,
    fill: impl FnOnce(&mut std::io::BufWriter<std::fs::File>) -> std::io::Result<()>,
) -> Result<(), DatasetError> {
    if let Some(parent) = path.parent() {
        if !parent.as_os_str().is_empty() && !parent.is_dir() {
            return Err(DatasetError::invalid(
                path,
                format!("the folder {} does not exist", parent.display()),
            ));
        }
    }
    let tmp = temp_sibling(path);
    let result = (|| {
        let f = std::fs::File::create(&tmp)?;
        let mut w = std::io::BufWriter::new(f);
        fill(&mut w)?;
        let f = w.into_inner().map_err(|e| e.into_error())?;
        f.sync_all()?;
        drop(f);
        std::fs::rename(&tmp, path)
    })();
    if let Err(e) = result {
        let _ = std::fs::remove_file(&tmp);
        return Err(DatasetError::io(path, e));
    }
    Ok(())
}

/// Checks, before any work, that `path` can be written as an output file: an existing file
/// is refused unless `force` (a folder always), and its folder must exist and accept a new
/// file (tried with a temporary file, removed again).
pub fn check_output_file(path: &Path, force: bool) -> Result<(), DatasetError> {
    if path.is_dir() {
        return Err(DatasetError::invalid(
            path,
            "is a folder; expected the path of a file to write",
        ));
    }
    if path.exists() && !force {
        return Err(DatasetError::Exists {
            path: path.to_path_buf(),
        });
    }
    let parent = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    if !parent.is_dir() {
        return Err(DatasetError::invalid(
            path,
            format!("the folder {} does not exist", parent.display()),
        ));
    }
    let probe = temp_sibling(path);
    match std::fs::File::create(&probe) {
        Ok(_) => {
            let _ = std::fs::remove_file(&probe);
            Ok(())
        }
        Err(e) => Err(DatasetError::invalid(
            path,
            format!("cannot write in {}: {e}", parent.display()),
        )),
    }
}
