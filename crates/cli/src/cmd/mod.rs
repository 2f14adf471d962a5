//! One module per subcommand.

pub mod camera;
