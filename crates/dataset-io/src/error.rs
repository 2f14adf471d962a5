//! The error type of dataset-io.

use std::path::PathBuf;

use thiserror::Error;

/// Everything that can go wrong reading or writing benchmark files. Every variant names the
/// file; parse errors also name the 1-based line.
#[derive(Debug, Error)]
pub enum DatasetError {
    /// An I/O error on a file or folder.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// A line of a text file that does not have the expected form.
    #[error("{}: line {line}: expected {expected}, found `{found}`", path.display())]
    Parse {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What the line should contain.
        expected: String,
        /// An excerpt of the line.
        found: String,
    },
    /// A file or folder whose content is unusable as a whole.
    #[error("{}: {message}", path.display())]
    Invalid {
        /// The file or folder.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// An output that exists already.
    #[error("{}: already exists (use --force to replace it)", path.display())]
    Exists {
        /// The output.
        path: PathBuf,
    },
}

impl DatasetError {
    /// An [`DatasetError::Io`] for `path`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        DatasetError::Io {
            path: path.into(),
            source,
        }
    }

    /// An [`DatasetError::Invalid`] for `path`.
    pub fn invalid(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        DatasetError::Invalid {
            path: path.into(),
            message: message.into(),
        }
    }
}
