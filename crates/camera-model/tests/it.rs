//! Integration tests of camera-model: one binary, one module per topic.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod calibration;
mod common;
mod file;
mod models;
mod rectify;
mod sphere;
