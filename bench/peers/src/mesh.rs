//! Mesh loading: `hostas_cli::mesh::load` when the `cli-mesh` feature is on (the default once
//! hostas-cli has it), else the stand-in loader of this crate.

#[cfg(feature = "cli-mesh")]
pub use hostas_cli::mesh::load;

#[cfg(not(feature = "cli-mesh"))]
pub use crate::meshload_standin::load;

pub const LOADER: &str = if cfg!(feature = "cli-mesh") {
    "hostas_cli::mesh"
} else {
    "stand-in loader (meshload_standin.rs)"
};
