//! The checks behind the fuzz targets. This directory is also compiled into the regression
//! test `crates/hostas/tests/fuzz_regressions.rs` (through `#[path]`), so it may use only what
//! that test can: `hostas`, `hostas-testkit`, `rand` and `bytemuck` (a hostas dependency).
#![allow(dead_code)]
// Negated comparisons are NaN-aware on purpose: `!(t < t_min)` holds for NaN, `t >= t_min` not.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod build_inputs;
pub mod common;
pub mod deserialize;
pub mod ray_query;
pub mod seeds;
pub mod source;

/// A target's entry point.
pub type Target = fn(&[u8]);

/// The targets by name, as the corpus directories are named.
pub const TARGETS: [(&str, Target); 3] = [
    ("deserialize", deserialize::run),
    ("build_inputs", build_inputs::run),
    ("ray_query", ray_query::run),
];

pub fn target(name: &str) -> Option<Target> {
    TARGETS.iter().find(|(n, _)| *n == name).map(|(_, f)| *f)
}
