//! Integration tests of eval-metrics: one binary, one module per topic.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

mod align;
mod batch;
mod common;
mod dataset_truth;
mod metrics;
mod other_metrics;
mod parse;
