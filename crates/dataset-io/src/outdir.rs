//! Output folders that appear whole or not at all: everything is written into a hidden
//! staging folder next to the target, which is renamed into place by [`OutputDir::commit`].
//! Dropping an uncommitted `OutputDir` (an error, a panic, Ctrl-C unwinding) removes the
//! staging folder; the target is never touched before the commit.

use std::path::{Path, PathBuf};

use crate::{temp_sibling, DatasetError};

/// A staging folder for an output folder.
#[derive(Debug)]
pub struct OutputDir {
    target: PathBuf,
    staging: PathBuf,
    force: bool,
    committed: bool,
}

impl OutputDir {
    /// Prepares to write the folder `target`. Fails when it exists, unless `force` (then it is
    /// replaced at commit time). The target's parent must exist.
    pub fn create(target: &Path, force: bool) -> Result<OutputDir, DatasetError> {
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
        let staging = temp_sibling(target);
        std::fs::create_dir(&staging).map_err(|e| DatasetError::io(&staging, e))?;
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
            std::fs::create_dir_all(parent).map_err(|e| DatasetError::io(parent, e))?;
        }
        Ok(p)
    }

    /// Moves the finished folder into place (replacing an existing one with `force`).
    pub fn commit(mut self) -> Result<PathBuf, DatasetError> {
        if self.target.exists() {
            if !self.force {
                return Err(DatasetError::Exists {
                    path: self.target.clone(),
                });
            }
            std::fs::remove_dir_all(&self.target).map_err(|e| DatasetError::io(&self.target, e))?;
        }
        std::fs::rename(&self.staging, &self.target)
            .map_err(|e| DatasetError::io(&self.target, e))?;
        self.committed = true;
        Ok(self.target.clone())
    }
}

impl Drop for OutputDir {
    fn drop(&mut self) {
        if !self.committed {
            let _ = std::fs::remove_dir_all(&self.staging);
        }
    }
}
