//! obvhs 0.4 (feature `parallel`, rayon): PLOC + reinsertion, converted to CWBVH, traced with
//! its CWBVH traversal and its Moller-Trumbore `Triangle::intersect`.
//!
//! - Builds: `cwbvh::builder::build_cwbvh_from_tris` with a preset, wall-clock (its triangle
//!   AABB pass included), inside a rayon pool of 1 or all threads.
//! - Input: `Vec<Triangle>` (three `Vec3A` per triangle), prepared untimed.
//! - SAH: of obvhs's own BVH2 for the same preset (`build_bvh2_from_tris`, which also collapses
//!   leaves to at most 8 primitives by obvhs's cost), built once untimed; the CWBVH path does
//!   not keep a collapsed BVH2.
//! - Bytes: CWBVH nodes (80 B each) + primitive index array + the triangle array the traversal
//!   reads (48 B per triangle), so that it is self-contained like the others.
//! - No refit: obvhs's `refit_all` only propagates boxes upwards (leaf boxes are the caller's
//!   job) and there is no CWBVH refit.

use crate::Cfg;
use crate::peers::trace_all;
use crate::rays::{Hit, Ray, RaySet};
use crate::report::{Class, Row};
use crate::sah::{self, Node};
use crate::scene::Scene;
use crate::util::{median_ms, pool, time};
use glam::Vec3A;
use obvhs::BvhBuildParams;
use obvhs::bvh2::builder::build_bvh2_from_tris;
use obvhs::cwbvh::CwBvh;
use obvhs::cwbvh::builder::build_cwbvh_from_tris;
use obvhs::cwbvh::node::CwBvhNode;
use obvhs::ray::{Ray as ORay, RayHit};
use obvhs::triangle::Triangle;
use std::time::Duration;

struct Variant {
    key: &'static str,
    desc: &'static str,
    params: fn() -> BvhBuildParams,
    class: Class,
}

const VARIANTS: [Variant; 2] = [
    Variant {
        key: "very_fast",
        desc: "PLOC very_fast_build -> CWBVH",
        params: BvhBuildParams::very_fast_build,
        class: Class::FastBuild,
    },
    Variant {
        key: "medium",
        desc: "PLOC medium_build -> CWBVH",
        params: BvhBuildParams::medium_build,
        class: Class::Default,
    },
];

fn trace(bvh: &CwBvh, tris: &[Triangle], rays: &[Ray], hits: &mut [Hit]) {
    for (r, h) in rays.iter().zip(hits.iter_mut()) {
        let ray = ORay::new_inf(Vec3A::from(r.o), Vec3A::from(r.d));
        let mut hit = RayHit::none();
        *h = if bvh.ray_traverse(ray, &mut hit, |ray, id| {
            tris[bvh.primitive_indices[id] as usize].intersect(ray)
        }) {
            Hit {
                t: hit.t,
                prim: bvh.primitive_indices[hit.primitive_id as usize],
            }
        } else {
            Hit::MISS
        };
    }
}

pub fn run(scene: &Scene, rays: &RaySet, cfg: &Cfg) -> Vec<Row> {
    let variants: Vec<&Variant> = VARIANTS
        .iter()
        .filter(|v| cfg.wants("obvhs", v.key))
        .collect();
    if variants.is_empty() {
        return Vec::new();
    }
    let tris: Vec<Triangle> = scene
        .indices
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| Vec3A::from(scene.positions[i as usize]));
            Triangle {
                v0: a,
                v1: b,
                v2: c,
            }
        })
        .collect();
    let mut rows = Vec::new();
    for v in &variants {
        let mut row = Row::new("obvhs", v.key, v.desc, Some(v.class));
        let mut traced = None;
        for &t in &cfg.threads {
            let _cpus = crate::util::cpus_for(t);
            let p = pool(t);
            let ms = p.install(|| {
                median_ms(cfg.warmup, cfg.reps, || {
                    let mut core = Duration::ZERO;
                    let (bvh, dt) = time(|| build_cwbvh_from_tris(&tris, (v.params)(), &mut core));
                    if t == 1 {
                        traced = Some(bvh);
                    }
                    dt
                })
            });
            row.build_ms.insert(t, ms);
        }
        let bvh = traced.unwrap_or_else(|| {
            build_cwbvh_from_tris(&tris, (v.params)(), &mut Duration::default())
        });
        row.bytes = Some(
            (bvh.nodes.len() * std::mem::size_of::<CwBvhNode>()
                + bvh.primitive_indices.len() * 4
                + tris.len() * std::mem::size_of::<Triangle>()) as u64,
        );
        row.bytes_note = "CWBVH nodes + index array + 48-B triangles".into();
        // SAH of obvhs's BVH2 for the same preset (untimed, all threads).
        let n = *cfg.threads.last().unwrap();
        let _cpus = crate::util::cpus_for(n);
        let bvh2 =
            pool(n).install(|| build_bvh2_from_tris(&tris, (v.params)(), &mut Duration::default()));
        row.sah = Some(sah::sah(0, |i| {
            let n = &bvh2.nodes[i];
            let a = n.aabb();
            let area = sah::area(a.min.into(), a.max.into());
            if n.prim_count > 0 {
                Node::Leaf {
                    area,
                    count: n.prim_count,
                }
            } else {
                let l = n.first_index as usize;
                Node::Inner {
                    area,
                    children: [l, l + 1],
                }
            }
        }));
        row.sah_note = "obvhs BVH2 of the same preset (collapsed leaves)".into();
        drop(bvh2);
        if cfg.trace {
            trace_all(&mut row, rays, cfg.passes, |r, h| trace(&bvh, &tris, r, h));
        }
        rows.push(row);
    }
    rows
}
