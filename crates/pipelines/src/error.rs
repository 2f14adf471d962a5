//! The error type of the pipelines.

use std::path::PathBuf;

use thiserror::Error;

/// What can stop a pipeline. Every variant names the file (and, where one is at fault, the
/// line) or the option that is wrong; the causes are chained as `source`s.
#[derive(Debug, Error)]
pub enum PipelineError {
    /// Reading or writing files.
    #[error(transparent)]
    Dataset(#[from] dataset_io::DatasetError),
    /// Drawing or writing a figure.
    #[error(transparent)]
    Figure(#[from] monovo_figures::FigureError),
    /// A file could not be read; `what` says which role it has ("the trajectory").
    #[error("{what}")]
    Read {
        /// The role of the file.
        what: &'static str,
        /// The cause (it names the file).
        #[source]
        source: dataset_io::DatasetError,
    },
    /// A trajectory, ground truth or results table that does not parse.
    #[error("{what}{}", path.display())]
    Eval {
        /// The role of the file, with a trailing space ("the trajectory ").
        what: &'static str,
        /// The file.
        path: PathBuf,
        /// The cause, with the line.
        #[source]
        source: eval_metrics::EvalError,
    },
    /// A photometric computation or file that failed; `context` names the file or sequence.
    #[error("{context}")]
    Photometric {
        /// The file or sequence.
        context: String,
        /// The cause.
        #[source]
        source: photometric::PhotometricError,
    },
    /// A camera file or output camera that is unusable; `context` names the file.
    #[error("{context}")]
    Camera {
        /// The file (and the output camera).
        context: String,
        /// The cause.
        #[source]
        source: camera_model::CameraError,
    },
    /// An experiment manifest that does not parse or names something wrong.
    #[error("{}: {}{message}", path.display(), line.map_or(String::new(), |l| format!("line {l}: ")))]
    Manifest {
        /// The manifest.
        path: PathBuf,
        /// The 1-based line, when known.
        line: Option<usize>,
        /// What was expected and what was found.
        message: String,
    },
    /// Input that cannot be used (a message that names it).
    #[error("{0}")]
    Invalid(String),
    /// An error with a context line in front of it.
    #[error("{context}")]
    Context {
        /// What was being done.
        context: String,
        /// The cause.
        #[source]
        source: Box<PipelineError>,
    },
}

impl PipelineError {
    /// This error with `context` in front.
    pub fn context(self, context: impl Into<String>) -> PipelineError {
        PipelineError::Context {
            context: context.into(),
            source: Box::new(self),
        }
    }
}

/// `Result` with [`PipelineError`].
pub type Result<T, E = PipelineError> = std::result::Result<T, E>;

/// An error and its causes on one line, each cause once: a cause whose text the message
/// already ends with (an I/O error that its wrapper prints as well) is left out.
pub fn error_chain(e: &(dyn std::error::Error + 'static)) -> String {
    let mut msg = String::new();
    let mut cur: Option<&(dyn std::error::Error + 'static)> = Some(e);
    while let Some(c) = cur {
        let text = c.to_string();
        if !text.is_empty() && !msg.ends_with(&text) {
            if !msg.is_empty() {
                msg.push_str(": ");
            }
            msg.push_str(&text);
        }
        cur = c.source();
    }
    msg
}

/// A JSON number, `null` when not finite.
pub fn json_number(v: f64) -> serde_json::Value {
    if v.is_finite() {
        serde_json::json!(v)
    } else {
        serde_json::Value::Null
    }
}

/// `with_context` for the errors of the library crates: the cause keeps its type as the
/// `source` of a [`PipelineError`] whose message is the context.
pub trait WithContext<T> {
    /// The error with `context()` in front.
    fn with_context<C: Into<String>>(self, context: impl FnOnce() -> C) -> Result<T>;
}

impl<T> WithContext<T> for std::result::Result<T, photometric::PhotometricError> {
    fn with_context<C: Into<String>>(self, context: impl FnOnce() -> C) -> Result<T> {
        self.map_err(|source| PipelineError::Photometric {
            context: context().into(),
            source,
        })
    }
}

impl<T> WithContext<T> for std::result::Result<T, camera_model::CameraError> {
    fn with_context<C: Into<String>>(self, context: impl FnOnce() -> C) -> Result<T> {
        self.map_err(|source| PipelineError::Camera {
            context: context().into(),
            source,
        })
    }
}

impl<T> WithContext<T> for std::result::Result<T, PipelineError> {
    fn with_context<C: Into<String>>(self, context: impl FnOnce() -> C) -> Result<T> {
        self.map_err(|e| e.context(context()))
    }
}

impl<T> WithContext<T> for std::result::Result<T, std::num::ParseIntError> {
    fn with_context<C: Into<String>>(self, context: impl FnOnce() -> C) -> Result<T> {
        self.map_err(|e| PipelineError::Invalid(format!("{}: {e}", context().into())))
    }
}

impl From<photometric::PhotometricError> for PipelineError {
    /// The error without a context line (its own message names what failed).
    fn from(source: photometric::PhotometricError) -> Self {
        PipelineError::Photometric {
            context: String::new(),
            source,
        }
    }
}

impl From<camera_model::CameraError> for PipelineError {
    /// The error without a context line (its own message names what failed).
    fn from(source: camera_model::CameraError) -> Self {
        PipelineError::Camera {
            context: String::new(),
            source,
        }
    }
}
