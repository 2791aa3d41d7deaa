pub mod embree;
#[cfg(feature = "hostas")]
pub mod hostas;
#[cfg(not(feature = "hostas"))]
#[path = "hostas_stub.rs"]
pub mod hostas;
pub mod obvhs;
pub mod tinybvh;

use crate::rays::{Hit, Kind, Ray, RaySet};
use crate::report::Row;
use crate::util::median;
use std::time::Instant;

/// One untimed pass that records the hits (and warms caches), then `passes` timed passes;
/// returns the median ms of a pass and the hits.
pub fn trace_kind(
    passes: usize,
    rays: &[Ray],
    mut f: impl FnMut(&[Ray], &mut [Hit]),
) -> (f64, Vec<Hit>) {
    let mut hits = vec![Hit::MISS; rays.len()];
    f(rays, &mut hits);
    let mut scratch = vec![Hit::MISS; rays.len()];
    let mut v: Vec<f64> = (0..passes.max(1))
        .map(|_| {
            let t = Instant::now();
            f(rays, &mut scratch);
            t.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    (median(&mut v), hits)
}

/// Traces both ray kinds into `row` (a kind without rays, left out by `--kinds`, is skipped).
pub fn trace_all(
    row: &mut Row,
    rays: &RaySet,
    passes: usize,
    mut f: impl FnMut(&[Ray], &mut [Hit]),
) {
    for kind in Kind::ALL.into_iter().filter(|&k| !rays.get(k).is_empty()) {
        let (ms, hits) = trace_kind(passes, rays.get(kind), &mut f);
        row.set_trace(kind, ms, hits);
    }
}
