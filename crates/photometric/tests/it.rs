//! Integration tests of photometric.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

mod correct;
mod exposure;
mod files;
mod marker;
mod plane_frames;
mod response;
mod response_deep;
mod serde_types;
mod vignette;
