//! Reading text and writing files atomically: a temporary name in the same folder, then a
//! rename, so that an interrupted or failed run never leaves a half-written output.

use std::io::Write;
use std::path::{Path, PathBuf};

use crate::temporaries::{self, creating, temp_sibling};
use crate::DatasetError;

/// Reads a whole text file; the error names the file.
pub fn read_text(path: &Path) -> Result<String, DatasetError> {
    std::fs::read_to_string(path).map_err(|e| DatasetError::io(path, e))
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
    temporaries::remove_stale(path);
    let tmp = temp_sibling(path);
    let result = (|| {
        let f = {
            let _gate = creating();
            temporaries::register(&tmp);
            std::fs::File::create(&tmp)?
        };
        let mut w = std::io::BufWriter::new(f);
        fill(&mut w)?;
        let f = w.into_inner().map_err(|e| e.into_error())?;
        f.sync_all()?;
        drop(f);
        let _gate = creating();
        std::fs::rename(&tmp, path)
    })();
    if let Err(e) = result {
        let _ = std::fs::remove_file(&tmp);
        temporaries::unregister(&tmp);
        return Err(DatasetError::io(path, e));
    }
    temporaries::unregister(&tmp);
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
    probe_folder(path, &parent)
}

/// Tries to create (and removes again) a temporary file in `parent` for the output `path`.
pub(crate) fn probe_folder(path: &Path, parent: &Path) -> Result<(), DatasetError> {
    temporaries::remove_stale(path);
    let probe = temp_sibling(path);
    let created = {
        let _gate = creating();
        temporaries::register(&probe);
        std::fs::File::create(&probe)
    };
    let _ = std::fs::remove_file(&probe);
    temporaries::unregister(&probe);
    match created {
        Ok(_) => Ok(()),
        Err(e) => Err(DatasetError::invalid(
            path,
            format!("cannot write in the folder {}: {e}", parent.display()),
        )),
    }
}

/// Opens a new scratch file in the folder `dir` (read and write, empty) for data too large
/// for memory, such as the frames' samples of a long vignette calibration. It leaves nothing
/// behind: on Unix its name (`.monovo-scratch.tmp-PID-N`) is removed as soon as it is open,
/// the data staying reachable through the handle until it is closed; elsewhere the file is
/// deleted when closed, and an interrupt in between removes it like any other temporary.
pub fn scratch_file(dir: &Path) -> Result<std::fs::File, DatasetError> {
    let dir = if dir.as_os_str().is_empty() {
        Path::new(".")
    } else {
        dir
    };
    let path = temp_sibling(&dir.join("monovo-scratch"));
    let _gate = creating();
    temporaries::register(&path);
    let mut options = std::fs::OpenOptions::new();
    options.read(true).write(true).create_new(true);
    #[cfg(windows)]
    {
        use std::os::windows::fs::OpenOptionsExt;
        // FILE_FLAG_DELETE_ON_CLOSE
        options.custom_flags(0x0400_0000);
    }
    let opened = options.open(&path);
    #[cfg(unix)]
    if opened.is_ok() {
        if let Err(e) = std::fs::remove_file(&path) {
            temporaries::unregister(&path);
            return Err(DatasetError::io(&path, e));
        }
    }
    if cfg!(unix) || opened.is_err() {
        temporaries::unregister(&path);
    }
    opened.map_err(|e| DatasetError::io(&path, e))
}
