//! Integration tests of dataset-io.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

mod files;
mod sequence;

/// A fresh folder under the system's temporary folder, removed with everything in it when
/// the test ends (passed or failed), so that test runs leave nothing behind.
pub struct TempDir(std::path::PathBuf);

impl TempDir {
    /// `dataset-io-{group}-{pid}-{name}`, emptied if a killed run left it.
    pub fn new(group: &str, name: &str) -> TempDir {
        let d =
            std::env::temp_dir().join(format!("dataset-io-{group}-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        TempDir(d)
    }
}

impl std::ops::Deref for TempDir {
    type Target = std::path::Path;
    fn deref(&self) -> &std::path::Path {
        &self.0
    }
}

impl AsRef<std::path::Path> for TempDir {
    fn as_ref(&self) -> &std::path::Path {
        &self.0
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}
