//! Cross-crate integration tests.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod dso_corpus;
mod dso_reference;
mod readme;
mod rectify_roundtrip;
