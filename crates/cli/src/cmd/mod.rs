//! One module per subcommand.

pub mod calib;
pub mod camera;
pub mod demo;
pub mod eval;
pub mod eval_batch;
pub mod exposure;
pub mod info;
pub mod plot;
pub mod rectify;
pub mod synth;
