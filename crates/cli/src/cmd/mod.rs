//! One module per subcommand, and what several of them share.

pub mod ape;
pub mod calib;
pub mod camera;
pub mod demo;
pub mod eval;
pub mod eval_batch;
pub mod experiment;
pub mod exposure;
pub mod info;
pub mod kitti;
pub mod plot;
pub mod rectify;
pub mod rpe;
pub mod synth;
pub mod traj;
