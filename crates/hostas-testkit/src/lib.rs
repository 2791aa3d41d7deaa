//! Test support for hostas (unpublished): scene descriptions that build into real hostas
//! structures through the public API, random and adversarial scene generators, and a
//! brute-force oracle that traces the same description without any tree.

pub mod generate;
pub mod oracle;
pub mod scene;

pub use oracle::{Candidate, Oracle};
pub use scene::{BlasDesc, BuiltScene, GeometryDesc, InstanceDesc, SceneDesc};
