//! How a pipeline reports progress and warnings to whoever runs it (a progress bar and
//! stderr in the `monovo` command, nothing in tests).

/// Receives a pipeline's warnings and progress. Every method has a default that does
/// nothing; [`Silent`] is the observer that ignores everything.
pub trait Observer: Sync {
    /// A warning (the pipeline continues).
    fn warn(&self, _message: &str) {}
    /// A stage of `len` things of `unit` (plural: "frames", "runs") begins.
    fn begin(&self, _len: u64, _what: &str, _unit: &'static str) {}
    /// `n` more things of the current stage are done (called from any thread).
    fn advance(&self, _n: u64) {}
    /// The state of an open-ended stage, such as an iteration and its convergence measure
    /// (a stage of its own until [`Observer::finish`]).
    fn status(&self, _message: &str) {}
    /// The current stage is over.
    fn finish(&self) {}
}

/// An observer that ignores everything.
#[derive(Clone, Copy, Debug, Default)]
pub struct Silent;

impl Observer for Silent {}
