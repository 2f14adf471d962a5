//! One module per subcommand.

pub mod camera;
pub mod eval;
pub mod eval_batch;
pub mod plot;
pub mod synth;
