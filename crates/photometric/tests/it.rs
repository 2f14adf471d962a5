//! Integration tests of photometric.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

mod correct;
mod files;
mod marker;
mod response;
mod serde_types;
mod vignette;
