//! Output folders that appear whole or not at all: everything is written into a hidden
//! staging folder next to the target, `.NAME.tmp-PID-N`, which is renamed into place by
//! [`OutputDir::commit`]. Dropping an uncommitted `OutputDir` (an error, a panic) removes the
//! staging folder, and so does an interrupt (see [`crate::remove_temporaries_and_block`]);
//! staging folders of processes that no longer run are removed by the next run that writes
//! the same target. The target is never touched before the commit.

use std::path::{Path, PathBuf};

use crate::temporaries::{self, creating, temp_sibling};
use crate::DatasetError;

/// A staging folder for an output folder.
#[derive(Debug)]
pub struct OutputDir {
    target: PathBuf,
    staging: PathBuf,
    force: bool,
    committed: bool,
}

impl OutputDir {
    /// Checks, before any work, that the folder `target` can be written: refused when it
    /// exists, unless `force` (an existing file is always refused); its parent folder must
    /// exist and accept a new entry (tried with a temporary file, removed again).
    pub fn check(target: &Path, force: bool) -> Result<(), DatasetError> {
        if target.exists() && !force {
            return Err(DatasetError::Exists {
                path: target.to_path_buf(),
            });
        }
        if target.exists() && !target.is_dir() {
            return Err(DatasetError::invalid(
                target,
                "exists and is not a folder; refusing to replace it",
            ));
        }
        let parent = target
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        if !parent.is_dir() {
            return Err(DatasetError::invalid(
                target,
                format!("the folder {} does not exist", parent.display()),
            ));
        }
        crate::atomic::probe_folder(target, parent)
    }

    /// Prepares to write the folder `target`. Fails when it exists, unless `force` (then it is
    /// replaced at commit time). The target's parent must exist. Staging folders of `target`
    /// left by processes that no longer run are removed.
    pub fn create(target: &Path, force: bool) -> Result<OutputDir, DatasetError> {
        OutputDir::check(target, force)?;
        let staging = temp_sibling(target);
        {
            let _gate = creating();
            temporaries::register(&staging);
            if let Err(e) = std::fs::create_dir(&staging) {
                temporaries::unregister(&staging);
                return Err(DatasetError::io(&staging, e));
            }
        }
        Ok(OutputDir {
            target: target.to_path_buf(),
            staging,
            force,
            committed: false,
        })
    }

    /// Where to write now (the staging folder).
    pub fn path(&self) -> &Path {
        &self.staging
    }

    /// The final folder.
    pub fn target(&self) -> &Path {
        &self.target
    }

    /// A path inside the staging folder, with its parent folders created.
    pub fn file(&self, relative: &str) -> Result<PathBuf, DatasetError> {
        let p = self.staging.join(relative);
        if let Some(parent) = p.parent() {
            let _gate = creating();
            if !self.staging.is_dir() {
                return Err(DatasetError::invalid(
                    &self.staging,
                    "the staging folder was removed",
                ));
            }
            std::fs::create_dir_all(parent).map_err(|e| DatasetError::io(parent, e))?;
        }
        Ok(p)
    }

    /// A folder inside the staging folder, created (with its parents).
    pub fn folder(&self, relative: &str) -> Result<PathBuf, DatasetError> {
        let p = self.staging.join(relative);
        let _gate = creating();
        if !self.staging.is_dir() {
            return Err(DatasetError::invalid(
                &self.staging,
                "the staging folder was removed",
            ));
        }
        std::fs::create_dir_all(&p).map_err(|e| DatasetError::io(&p, e))?;
        Ok(p)
    }

    /// Writes `bytes` to the file `relative` inside the staging folder (parents created).
    pub fn write(&self, relative: &str, bytes: &[u8]) -> Result<PathBuf, DatasetError> {
        let p = self.file(relative)?;
        let _gate = creating();
        std::fs::write(&p, bytes).map_err(|e| DatasetError::io(&p, e))?;
        Ok(p)
    }

    /// Moves the finished folder into place (replacing an existing one with `force`).
    pub fn commit(mut self) -> Result<PathBuf, DatasetError> {
        let old = {
            let _gate = creating();
            let old = if self.target.exists() {
                if !self.force {
                    return Err(DatasetError::Exists {
                        path: self.target.clone(),
                    });
                }
                if !self.target.is_dir() {
                    return Err(DatasetError::invalid(
                        &self.target,
                        "exists and is not a folder; refusing to replace it",
                    ));
                }
                // the old output moves aside (listed, so an interrupt removes it) and the new
                // one takes its place: the target is never missing or half-written
                let aside = temp_sibling(&self.target);
                temporaries::register(&aside);
                std::fs::rename(&self.target, &aside)
                    .map_err(|e| DatasetError::io(&self.target, e))?;
                Some(aside)
            } else {
                None
            };
            if let Err(e) = std::fs::rename(&self.staging, &self.target) {
                if let Some(a) = &old {
                    let _ = std::fs::rename(a, &self.target);
                    temporaries::unregister(a);
                }
                return Err(DatasetError::io(&self.target, e));
            }
            temporaries::unregister(&self.staging);
            self.committed = true;
            old
        };
        if let Some(a) = old {
            let _ = std::fs::remove_dir_all(&a);
            temporaries::unregister(&a);
        }
        Ok(self.target.clone())
    }
}

impl Drop for OutputDir {
    fn drop(&mut self) {
        if !self.committed {
            let _ = std::fs::remove_dir_all(&self.staging);
            temporaries::unregister(&self.staging);
        }
    }
}
