//! Integration tests of photometric.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

mod correct;
mod exposure;
mod files;
mod marker;
mod response;
mod response_deep;
mod serde_types;
mod vignette;
