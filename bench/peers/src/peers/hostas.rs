//! hostas adapter.
//!
//! TODO(hostas API): the core crate's public API (`Device`, `quick::build_triangle_blas`,
//! `Scene::trace_closest`, `Device::statistics`, update) does not exist yet. Until it does,
//! this adapter reports a clear error row for every preset, and the cross-check falls back to
//! Embree MEDIUM as the reference.

use crate::Cfg;
use crate::rays::RaySet;
use crate::report::{Class, Row};
use crate::scene::Scene;

pub const PRESETS: [(&str, &str, Class); 4] = [
    ("fast_build", "PREFER_FAST_BUILD", Class::FastBuild),
    ("default", "default (no preference flag)", Class::Default),
    ("fast_trace", "PREFER_FAST_TRACE", Class::FastTrace),
    ("low_memory", "LOW_MEMORY", Class::LowMemory),
];

pub fn run(_scene: &Scene, _rays: &RaySet, cfg: &Cfg) -> Vec<Row> {
    PRESETS
        .iter()
        .filter(|p| cfg.wants("hostas", p.0))
        .map(|p| {
            let mut r = Row::new("hostas", p.0, p.1, Some(p.2));
            r.error = Some("hostas adapter not written yet: the hostas public API is not available (TODO in src/peers/hostas.rs)".into());
            r
        })
        .collect()
}
