//! The figures of the `monovo-figures` crate, with `save` returning the command's error.

pub use monovo_figures::{format_of, Figure};

/// Writes the figure as PNG or SVG by the extension of `path` (atomically).
pub fn save(fig: &Figure, path: &std::path::Path) -> anyhow::Result<()> {
    Ok(monovo_figures::save(fig, path)?)
}
