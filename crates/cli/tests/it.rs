//! End-to-end tests of the `monovo` binary: one test binary, one module per command.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

mod calib;
mod camera;
mod common;
mod datasets;
mod eval;
mod experiment;
mod exposure;
mod faults;
mod figures;
mod metrics;
mod rectify;
mod terminal;
