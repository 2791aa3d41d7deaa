//! Library side of the `hostas` command: mesh loading, image writing, the `hostas build` file
//! format, tracing and rendering helpers, and the subcommands themselves, kept apart from the
//! binary's `main` so that everything can be tested.
//!
//! Subcommands (see `hostas --help`): `demo`, `build`, `info`, `render`, `trace`, `bench`.
//! The file format of `hostas build` is described in [`container`]; the ray and hit records of
//! `hostas trace` in [`records`].

pub mod cli;
pub mod cmd;
pub mod container;
pub mod geom;
pub mod image;
pub mod input;
pub mod mesh;
pub mod ops;
pub mod progress;
pub mod records;
pub mod render;
pub mod report;
pub mod shade;
pub mod shapes;
