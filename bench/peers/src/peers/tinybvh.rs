//! tinybvh 1.6.8 (the header bundled by tinybvh-rs 0.1.0-beta.3) through `shim/tb_shim.cpp`.
//!
//! - Builds: BVH2 by `Build` (reference binned SAH, 8 bins), `BuildAVX` or `BuildHQ` (SBVH),
//!   then the conversion `BVH8_CPU::Build` does (PrepareBuild4_8, Compact, MBVH<8>, BVH8_CPU).
//!   The build figure is the total to the traced BVH8_CPU layout; the BVH2 part alone goes to
//!   the JSON (`bvh2_ms`). 1 thread: `threadedBuild = false`; all threads: tinybvh's own job
//!   system (`hardware_concurrency()` threads; the conversion is single-threaded).
//! - Input: a triangle soup of 16-byte vertices, three per triangle (prepared untimed).
//! - SAH: over the BVH2 nodes before widening (the common evaluator; tinybvh's own `SAHCost` is
//!   kept in the JSON as `tinybvh_sahcost` as a check).
//! - Bytes: the BVH8_CPU blocks (256-B nodes and 192-B four-triangle leaves, self-contained).
//! - Trace: `BVH8_CPU::Intersect` (its AVX2 kernel). tinybvh's BVH2 kernel is not used: its
//!   Moller-Trumbore test has an absolute determinant cutoff that misses hits on small
//!   triangles (the bunny).
//! - Refit: `BVH::Refit` on a separate single-threaded `Build` BVH2 (nodes only; the
//!   triangles stay in the caller's buffer); tinybvh's refit has no threaded version.

use crate::Cfg;
use crate::peers::trace_all;
use crate::rays::{Hit, Ray, RaySet};
use crate::report::{Class, Row};
use crate::sah::{self, Node};
use crate::scene::Scene;
use crate::util::{median, median_ms, time};
use serde_json::json;
use std::ffi::c_void;
use std::time::Instant;

unsafe extern "C" {
    fn tbp_new() -> *mut c_void;
    fn tbp_free(h: *mut c_void);
    fn tbp_build_bvh2(h: *mut c_void, verts4: *const f32, tri_count: u32, kind: i32, threaded: i32);
    fn tbp_bvh2_nodes(h: *mut c_void, used: *mut u32, idx_count: *mut u32) -> *const TbNode;
    fn tbp_bvh2_sahcost(h: *mut c_void) -> f32;
    fn tbp_convert_bvh8(h: *mut c_void);
    fn tbp_bvh8_bytes(h: *mut c_void) -> u64;
    fn tbp_trace_bvh8(h: *mut c_void, rays: *const f32, n: u32, t: *mut f32, prim: *mut u32);
    fn tbp_refit_new(verts4: *const f32, tri_count: u32) -> *mut c_void;
    fn tbp_refit(h: *mut c_void);
    fn tbp_refit_free(h: *mut c_void);
}

#[repr(C)]
#[derive(Clone, Copy)]
struct TbNode {
    min: [f32; 3],
    left_first: u32,
    max: [f32; 3],
    tri_count: u32,
}

struct Variant {
    key: &'static str,
    desc: &'static str,
    kind: i32,
    class: Class,
    slow: bool,
}

const VARIANTS: [Variant; 3] = [
    Variant {
        key: "Build",
        desc: "Build (binned SAH) + BVH8_CPU",
        kind: 0,
        class: Class::Default,
        slow: false,
    },
    Variant {
        key: "BuildAVX",
        desc: "BuildAVX (binned SAH) + BVH8_CPU",
        kind: 1,
        class: Class::Default,
        slow: false,
    },
    Variant {
        key: "BuildHQ",
        desc: "BuildHQ (SBVH) + BVH8_CPU",
        kind: 2,
        class: Class::FastTrace,
        slow: true,
    },
];

struct Handle(*mut c_void);

impl Drop for Handle {
    fn drop(&mut self) {
        unsafe { tbp_free(self.0) }
    }
}

fn bvh2_sah(h: &Handle) -> f64 {
    let (mut used, mut idx) = (0u32, 0u32);
    let nodes = unsafe {
        let p = tbp_bvh2_nodes(h.0, &mut used, &mut idx);
        std::slice::from_raw_parts(p, used as usize)
    };
    sah::sah(0, |i| {
        let n = nodes[i];
        let area = sah::area(n.min, n.max);
        if n.tri_count > 0 {
            Node::Leaf {
                area,
                count: n.tri_count,
            }
        } else {
            let l = n.left_first as usize;
            Node::Inner {
                area,
                children: [l, l + 1],
            }
        }
    })
}

fn trace(h: &Handle, rays: &[Ray], hits: &mut [Hit]) {
    let n = rays.len();
    let mut t = vec![0f32; n];
    let mut p = vec![0u32; n];
    unsafe {
        tbp_trace_bvh8(
            h.0,
            rays.as_ptr() as *const f32,
            n as u32,
            t.as_mut_ptr(),
            p.as_mut_ptr(),
        )
    };
    for i in 0..n {
        hits[i] = if p[i] != u32::MAX {
            Hit {
                t: t[i],
                prim: p[i],
            }
        } else {
            Hit::MISS
        };
    }
}

pub fn run(scene: &Scene, rays: &RaySet, cfg: &Cfg) -> Vec<Row> {
    let variants: Vec<&Variant> = VARIANTS
        .iter()
        .filter(|v| cfg.wants("tinybvh", v.key))
        .collect();
    let do_refit = cfg.refit && cfg.wants("tinybvh", "refit");
    if variants.is_empty() && !do_refit {
        return Vec::new();
    }
    let soup = scene.soup4(&scene.positions);
    let n = scene.tri_count() as u32;
    let hw = crate::util::available_threads();
    let mut rows = Vec::new();
    for v in &variants {
        let mut row = Row::new("tinybvh", v.key, v.desc, Some(v.class));
        row.bytes_note = "BVH8_CPU nodes + 4-triangle SoA leaves (self-contained)".into();
        let mut bvh2_ms = serde_json::Map::new();
        let mut kept: Option<Handle> = None;
        for &t in &cfg.threads {
            let _cpus = crate::util::cpus_for(t);
            let (reps, warm) = if v.slow {
                (cfg.slow_reps, cfg.slow_warmup)
            } else {
                (cfg.reps, cfg.warmup)
            };
            let reps = reps.max(1);
            let threaded = (t > 1) as i32;
            let mut b2 = Vec::new();
            let mut tot = Vec::new();
            for rep in 0..warm + reps {
                let h = Handle(unsafe { tbp_new() });
                let t0 = Instant::now();
                unsafe { tbp_build_bvh2(h.0, soup.as_ptr() as *const f32, n, v.kind, threaded) };
                let bvh2 = t0.elapsed();
                let keep = t == 1 && rep + 1 == warm + reps;
                if keep {
                    // The traced structure, SAH (of the BVH2 before widening) and bytes come
                    // from the last 1-thread build; the SAH walk is not timed.
                    row.sah = Some(bvh2_sah(&h));
                    row.extra.insert(
                        "tinybvh_sahcost".into(),
                        json!(unsafe { tbp_bvh2_sahcost(h.0) }),
                    );
                }
                let t1 = Instant::now();
                unsafe { tbp_convert_bvh8(h.0) };
                let total = bvh2 + t1.elapsed();
                if rep >= warm {
                    b2.push(bvh2.as_secs_f64() * 1e3);
                    tot.push(total.as_secs_f64() * 1e3);
                }
                if keep {
                    kept = Some(h);
                }
            }
            row.build_ms.insert(t, median(&mut tot));
            bvh2_ms.insert(t.to_string(), json!(median(&mut b2)));
        }
        if cfg.threads.len() > 1 && hw != *cfg.threads.last().unwrap() {
            row.note = format!("threaded builds use hardware_concurrency() = {hw} threads");
        }
        row.extra
            .insert("bvh2_ms".into(), serde_json::Value::Object(bvh2_ms));
        if v.kind == 0 {
            // Sanity check of the shim: tinybvh-rs's own `BVH::new` runs the same reference
            // builder from the same header; its SAH must match the shim's (untimed).
            if let Ok(b) = tinybvh_rs::bvh::BVH::new(soup.as_slice().into()) {
                let theirs = b.sah_cost(0);
                row.extra.insert("tinybvh_rs_sahcost".into(), json!(theirs));
                let ours = row
                    .extra
                    .get("tinybvh_sahcost")
                    .and_then(|x| x.as_f64())
                    .unwrap_or(f64::NAN);
                if ((ours - theirs as f64) / ours).abs() > 1e-3 {
                    row.note = format!(
                        "shim SAHCost {ours:.3} differs from tinybvh-rs BVH::new {theirs:.3}"
                    );
                }
            }
        }
        let h = kept.expect("1-thread build");
        row.sah_note = "BVH2 before widening".into();
        row.bytes = Some(unsafe { tbp_bvh8_bytes(h.0) });
        if cfg.trace {
            trace_all(&mut row, rays, cfg.passes, |r, hits| trace(&h, r, hits));
        }
        rows.push(row);
    }
    if do_refit {
        let mut row = Row::new(
            "tinybvh",
            "refit",
            "refit: BVH::Refit on a Build BVH2 (1 thread only)",
            Some(Class::Default),
        );
        let mut buf = soup.clone();
        let moved = scene.soup4(&crate::scene::deformed(scene));
        let h = unsafe { tbp_refit_new(buf.as_ptr() as *const f32, n) };
        let mut flip = false;
        let ms = median_ms(cfg.refit_warmup, cfg.refit_reps, || {
            flip = !flip;
            buf.copy_from_slice(if flip { &moved } else { &soup });
            time(|| unsafe { tbp_refit(h) }).1
        });
        unsafe { tbp_refit_free(h) };
        row.refit_ms.insert(1, ms);
        rows.push(row);
    }
    rows
}
