//! One module per subcommand.

pub mod bench;
pub mod build;
pub mod demo;
pub mod info;
pub mod render;
pub mod trace;
