//! The `monovo` Python package's native module, `monovo._monovo`: the crates of the workspace
//! behind a thin pyo3 layer (stable ABI, CPython 3.9 and later). The package's pure-Python
//! part (`python/monovo`) re-exports it, adds the conversions to and from evo and the
//! PyTorch dataset, and documents the API in its stubs; docs/python.md is the guide.
//!
//! Every call that decodes, rectifies or evaluates releases the GIL. Errors become
//! `monovo.FormatError` (a `ValueError`) or `monovo.FileError` (an `OSError`) carrying the
//! message that the `monovo` command prints.

use pyo3::prelude::*;

mod arrays;
mod camera;
mod errors;
mod eval;
mod metrics;
mod photometric_py;
mod sequence;

/// The native module.
#[pymodule]
fn _monovo(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("JPEG_DECODER", dataset_io::JPEG_DECODER)?;
    eval::register(m)?;
    metrics::register(m)?;
    sequence::register(m)?;
    camera::register(m)?;
    photometric_py::register(m)?;
    Ok(())
}
