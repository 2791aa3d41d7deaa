//! Library side of the `hostas` command: loading triangle meshes from disk and writing
//! images, kept apart from the command-line front end so that both can be tested.

pub mod image;
pub mod mesh;
