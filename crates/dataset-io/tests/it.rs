//! Integration tests of dataset-io.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

mod files;
mod sequence;
