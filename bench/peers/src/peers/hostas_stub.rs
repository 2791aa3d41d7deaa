//! Stand-in for the hostas adapter when the crate is built without the `hostas` feature
//! (`PEERS_FEATURES=""`, for when the core does not compile): every preset reports an error
//! row, and the hit cross-check falls back to Embree MEDIUM as the reference.

use crate::Cfg;
use crate::paired::Side;
use crate::rays::RaySet;
use crate::report::{Class, Row};
use crate::scene::Scene;

const PRESETS: [(&str, &str, Class); 4] = [
    ("fast_build", "PREFER_FAST_BUILD", Class::FastBuild),
    ("default", "default (no preference flag)", Class::Default),
    ("fast_trace", "PREFER_FAST_TRACE", Class::FastTrace),
    ("low_memory", "LOW_MEMORY", Class::LowMemory),
];

const MISSING: &str = "built without the `hostas` feature (PEERS_FEATURES did not include it)";

pub fn pair_side<'a>(_scene: &'a Scene, _key: &str) -> Result<Box<dyn Side + 'a>, String> {
    Err(MISSING.into())
}

pub fn run(_scene: &Scene, _rays: &RaySet, cfg: &Cfg) -> Vec<Row> {
    PRESETS
        .iter()
        .filter(|p| cfg.wants("hostas", p.0))
        .map(|p| {
            let mut r = Row::new("hostas", p.0, p.1, Some(p.2));
            r.error = Some(MISSING.into());
            r
        })
        .collect()
}
