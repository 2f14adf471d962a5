//! Rust errors as Python exceptions: `monovo.FileError` (an `OSError`) when a file could not
//! be read or written, `monovo.FormatError` (a `ValueError`) for everything else that is
//! wrong with the input; the message is the error chain as the `monovo` command prints it.

use pyo3::prelude::*;
use pyo3::sync::PyOnceLock;
use pyo3::types::PyType;

static FILE_ERROR: PyOnceLock<Py<PyType>> = PyOnceLock::new();
static FORMAT_ERROR: PyOnceLock<Py<PyType>> = PyOnceLock::new();

/// The exception class `name` of `monovo._errors` (defined in Python, where a class can
/// derive from both `monovo.Error` and `ValueError` or `OSError`).
fn class<'py>(
    py: Python<'py>,
    cell: &'static PyOnceLock<Py<PyType>>,
    name: &str,
) -> PyResult<&'py Bound<'py, PyType>> {
    cell.get_or_try_init(py, || {
        let t = py.import("monovo._errors")?.getattr(name)?;
        Ok::<_, PyErr>(t.cast_into::<PyType>()?.unbind())
    })
    .map(|t| t.bind(py))
}

/// What kind of exception an error chain is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// A file that could not be read or written (or a path that does not exist).
    File,
    /// Anything else: malformed content, a bad value or option.
    Format,
}

/// An error ready to become a Python exception once the GIL is held again.
#[derive(Debug)]
pub struct Error {
    /// The exception class.
    pub kind: Kind,
    /// The message.
    pub message: String,
}

impl Error {
    /// A `FormatError` with `message`.
    pub fn format(message: impl Into<String>) -> Error {
        Error {
            kind: Kind::Format,
            message: message.into(),
        }
    }

    /// The error chain of `e`, as the CLI prints it, and its kind: `File` when a link of the
    /// chain is an I/O error of dataset-io, or says that a path does not exist.
    pub fn from_chain(e: &(dyn std::error::Error + 'static)) -> Error {
        let mut kind = Kind::Format;
        let mut cur: Option<&(dyn std::error::Error + 'static)> = Some(e);
        while let Some(c) = cur {
            match c.downcast_ref::<dataset_io::DatasetError>() {
                Some(dataset_io::DatasetError::Io { .. }) => kind = Kind::File,
                Some(dataset_io::DatasetError::Invalid { message, .. })
                    if message == "does not exist" =>
                {
                    kind = Kind::File
                }
                _ => {}
            }
            if c.is::<std::io::Error>() {
                kind = Kind::File;
            }
            cur = c.source();
        }
        Error {
            kind,
            message: monovo_pipelines::error_chain(e),
        }
    }

    /// Prefixes the message (`pairs[3]: ...`).
    pub fn context(mut self, prefix: &str) -> Error {
        self.message = format!("{prefix}: {}", self.message);
        self
    }
}

impl From<monovo_pipelines::PipelineError> for Error {
    fn from(e: monovo_pipelines::PipelineError) -> Self {
        Error::from_chain(&e)
    }
}

impl From<dataset_io::DatasetError> for Error {
    fn from(e: dataset_io::DatasetError) -> Self {
        Error::from_chain(&e)
    }
}

impl From<camera_model::CameraError> for Error {
    fn from(e: camera_model::CameraError) -> Self {
        Error::from_chain(&e)
    }
}

impl From<photometric::PhotometricError> for Error {
    fn from(e: photometric::PhotometricError) -> Self {
        Error::from_chain(&e)
    }
}

impl From<Error> for PyErr {
    fn from(e: Error) -> PyErr {
        Python::attach(|py| {
            let (cell, name) = match e.kind {
                Kind::File => (&FILE_ERROR, "FileError"),
                Kind::Format => (&FORMAT_ERROR, "FormatError"),
            };
            match class(py, cell, name) {
                Ok(t) => PyErr::from_type(t.clone(), e.message),
                Err(err) => err,
            }
        })
    }
}

/// `Result` with [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;
