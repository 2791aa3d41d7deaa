//! hostas, through its public API.
//!
//! - Builds: `hostas::quick::build_triangle_blas` (sizes, creates, takes scratch and builds: a
//!   complete, self-contained structure) for each preset flag, timed as a whole, inside a
//!   rayon pool of 1 or all threads; the structure is destroyed untimed. The scratch is the
//!   previous build's (`quick` keeps it, as an application keeps its scratch buffer, and as
//!   malloc gives Embree's temporary arrays back). The structure's memory comes from hostas's
//!   allocator, which reuses the mapping of a structure destroyed in the last 2 s (as it is:
//!   buffer memory's contents are undefined, as after `vkAllocateMemory`, and builds do not
//!   depend on them) rather than have the OS fault in fresh pages: the warm-up build is the
//!   only one that pays for fresh pages.
//! - Trace: `Tracer::closest_batch` (batches of 1024 rays; each ray's hit is the one
//!   `Tracer::closest` gives it) over a single-instance TLAS (identity transform) built with
//!   `quick::build_single_instance_tlas`: ray queries always start at a TLAS in Vulkan, so
//!   hostas pays for one instance level that the peers (which trace the BLAS directly) do not.
//!   Rays that share an origin (the primary rays) are walked in packets of eight; others,
//!   through a structure of 16 MiB or more, eight at a time, interleaved (the 1M-triangle
//!   scenes' and the crown's incoherent rays); every other ray one at a time, as
//!   `Tracer::closest`.
//! - SAH and bytes: what `Device::statistics` reports: `sah_cost` (node visit 1, primitive
//!   test 1, relative to the root box, on hostas's own 8-wide tree, so it is not the same
//!   quantity as the binary-tree SAH of the peers) and `used_bytes` (header, geometry records,
//!   nodes and primitives: what a compacted copy needs).
//! - Refit: the default preset built with `ALLOW_UPDATE`, then `vkBuildAccelerationStructuresKHR`
//!   in mode UPDATE in place with the rewritten vertices (update scratch allocated once,
//!   untimed); checked against a fresh build over the moved vertices.

use crate::Cfg;
use crate::paired::Side;
use crate::peers::trace_all;
use crate::rays::{Hit, Ray, RaySet};
use crate::report::{Class, Row};
use crate::scene::Scene;
use crate::util::{median_ms, pool, time};
use hostas::{AccelerationStructure, BuildGeometryInfo, BuildRangeInfo, Device, Geometry, vk};
use serde_json::json;
use std::sync::OnceLock;
use std::time::Duration;

type Flags = vk::BuildAccelerationStructureFlagsKHR;

pub struct Preset {
    pub key: &'static str,
    pub desc: &'static str,
    pub class: Class,
    pub flags: fn() -> Flags,
}

pub const PRESETS: [Preset; 4] = [
    Preset {
        key: "fast_build",
        desc: "PREFER_FAST_BUILD",
        class: Class::FastBuild,
        flags: || Flags::PREFER_FAST_BUILD,
    },
    Preset {
        key: "default",
        desc: "default (no preference flag)",
        class: Class::Default,
        flags: Flags::empty,
    },
    Preset {
        key: "fast_trace",
        desc: "PREFER_FAST_TRACE",
        class: Class::FastTrace,
        flags: || Flags::PREFER_FAST_TRACE,
    },
    Preset {
        key: "low_memory",
        desc: "LOW_MEMORY",
        class: Class::LowMemory,
        flags: || Flags::LOW_MEMORY,
    },
];

fn build(
    device: &Device,
    pos: &[[f32; 3]],
    idx: &[[u32; 3]],
    flags: Flags,
) -> Result<AccelerationStructure, String> {
    hostas::quick::build_triangle_blas(device, pos, idx, flags)
        .map_err(|e| format!("build failed: {e}"))
}

/// Traces through a single-instance TLAS over `blas`.
fn trace_blas(
    device: &Device,
    blas: AccelerationStructure,
    rays: &RaySet,
    passes: usize,
    row: &mut Row,
) -> Result<(), String> {
    let tlas = hostas::quick::build_single_instance_tlas(device, blas)
        .map_err(|e| format!("TLAS build failed: {e}"))?;
    {
        let scene = device.scene(tlas).map_err(|e| format!("scene: {e}"))?;
        trace_all(row, rays, passes, |rs, hits| trace(&scene, rs, hits));
    }
    let _ = device.destroy_acceleration_structure(tlas);
    Ok(())
}

fn trace(scene: &hostas::Scene, rays: &[Ray], hits: &mut [Hit]) {
    // hostas's batch path: a Tracer reuses its views and stacks across rays, and
    // `closest_batch` walks rays several at once where that measured faster (a camera's rays
    // in packets; other rays interleaved through a bottom level of 16 MiB or more); each
    // ray's hit is the one `Tracer::closest` gives it. Batches of 1024: each permutation's share of a batch is
    // walked eight rays at a time, slower at its end, where fewer than eight remain (batches
    // of 256 lost most of the boxes' gain, 1.34x with 4096), while the batch's rays and hits
    // (about 90 bytes per ray) should stay near the core for the rays traced one at a time
    // (on the meshes, batches of 256 and 64 were no faster: the forty-first session).
    let mut tracer = scene.tracer();
    let mode = interleave_mode();
    let size = batch_size();
    let mut batch = Vec::with_capacity(size);
    let mut found = Vec::with_capacity(size);
    for (rs, hs) in rays.chunks(size).zip(hits.chunks_mut(size)) {
        batch.clear();
        batch.extend(rs.iter().map(|r| hostas::Ray::new(r.o, r.d)));
        tracer
            .closest_batch_with(&batch, &mut found, mode)
            .expect("closest_batch");
        for (h, hit) in hs.iter_mut().zip(&found) {
            *h = if hit.is_hit() {
                Hit {
                    t: hit.t,
                    prim: hit.primitive_index,
                }
            } else {
                Hit::MISS
            };
        }
    }
}

/// How hostas walks each batch: `HOSTAS_INTERLEAVE=always`, `never` or `packets` overrides
/// hostas's own choice (`auto`), to measure the interleaved or packet walk against one ray at
/// a time. Read once, outside the timed passes; any other value stops the benchmark.
fn interleave_mode() -> hostas::Interleave {
    static MODE: OnceLock<hostas::Interleave> = OnceLock::new();
    *MODE.get_or_init(|| match std::env::var("HOSTAS_INTERLEAVE").as_deref() {
        Err(std::env::VarError::NotPresent) | Ok("auto") => hostas::Interleave::Auto,
        Ok("always") => hostas::Interleave::Always,
        Ok("never") => hostas::Interleave::Never,
        Ok("packets") => hostas::Interleave::Packets,
        Ok(v) => panic!("HOSTAS_INTERLEAVE must be auto, always, never or packets, not {v:?}"),
        Err(e) => panic!("HOSTAS_INTERLEAVE: {e}"),
    })
}

/// Rays per [`hostas::Tracer::closest_batch`] call.
const BATCH: usize = 1024;

/// [`BATCH`], or `HOSTAS_BATCH` where set, to measure other batch sizes. Read once, outside
/// the timed passes; anything but a positive number stops the benchmark.
fn batch_size() -> usize {
    static SIZE: OnceLock<usize> = OnceLock::new();
    *SIZE.get_or_init(|| match std::env::var("HOSTAS_BATCH") {
        Err(std::env::VarError::NotPresent) => BATCH,
        v => v
            .ok()
            .and_then(|v| v.parse().ok())
            .filter(|&n: &usize| n > 0)
            .unwrap_or_else(|| panic!("HOSTAS_BATCH must be a positive number of rays")),
    })
}

fn run_preset(
    scene: &Scene,
    rays: &RaySet,
    cfg: &Cfg,
    device: &Device,
    p: &Preset,
) -> Result<Row, String> {
    let mut row = Row::new("hostas", p.key, p.desc, Some(p.class));
    row.sah_wide = true;
    row.sah_note = "reported by hostas: its 8-wide tree (node visit 1, primitive test 1)".into();
    row.bytes_note = "Statistics::used_bytes (self-contained; what a compacted copy needs)".into();
    let flags = (p.flags)();
    let (pos, idx) = (&scene.positions, &scene.indices);
    let mut kept = None;
    for &t in &cfg.threads {
        let _cpus = crate::util::cpus_for(t);
        let pl = pool(t);
        let total = cfg.warmup + cfg.reps;
        let mut rep = 0;
        let mut err = None;
        let ms = pl.install(|| {
            median_ms(cfg.warmup, cfg.reps, || {
                rep += 1;
                let (r, dt) = time(|| build(device, pos, idx, flags));
                match r {
                    Ok(a) if t == 1 && rep == total => kept = Some(a),
                    Ok(a) => {
                        let _ = device.destroy_acceleration_structure(a);
                    }
                    Err(e) => err = Some(e),
                }
                dt
            })
        });
        if let Some(e) = err {
            return Err(e);
        }
        row.build_ms.insert(t, ms);
    }
    let blas = kept.ok_or("no 1-thread build kept")?;
    let st = device
        .statistics(blas)
        .map_err(|e| format!("statistics: {e}"))?;
    row.sah = Some(st.sah_cost as f64);
    row.sah8 = row.sah;
    row.bytes = Some(st.used_bytes);
    row.extra.insert(
        "hostas_stats".into(),
        json!({"preset": st.preset, "node_count": st.node_count, "leaf_count": st.leaf_count, "depth": st.depth,
               "stored_count": st.stored_count, "allocated_bytes": st.allocated_bytes}),
    );
    if cfg.trace {
        trace_blas(device, blas, rays, cfg.passes, &mut row)?;
    }
    let _ = device.destroy_acceleration_structure(blas);
    if p.class == Class::Default && cfg.refit && cfg.wants("hostas", "refit") {
        refit(scene, rays, cfg, device, flags, &mut row)?;
    }
    Ok(row)
}

fn triangles<'a>(pos: &'a [[f32; 3]], idx: &'a [[u32; 3]]) -> [Geometry<'a>; 1] {
    [hostas::quick::triangle_mesh(
        pos,
        idx,
        vk::GeometryFlagsKHR::OPAQUE,
    )]
}

fn update(
    device: &Device,
    blas: AccelerationStructure,
    flags: Flags,
    pos: &[[f32; 3]],
    idx: &[[u32; 3]],
    scratch: &mut [u8],
) -> Result<(), String> {
    let g = triangles(pos, idx);
    let range = [BuildRangeInfo {
        primitive_count: idx.len() as u32,
        ..Default::default()
    }];
    let info = BuildGeometryInfo {
        ty: vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
        flags,
        mode: vk::BuildAccelerationStructureModeKHR::UPDATE,
        src: Some(blas),
        dst: Some(blas),
        geometries: &g,
        scratch: Some(scratch),
    };
    device
        .build_acceleration_structures(&mut [info], &[&range])
        .map_err(|e| format!("update failed: {e}"))
}

fn refit(
    scene: &Scene,
    rays: &RaySet,
    cfg: &Cfg,
    device: &Device,
    flags: Flags,
    row: &mut Row,
) -> Result<(), String> {
    let flags = flags | Flags::ALLOW_UPDATE;
    let (orig, idx) = (&scene.positions, &scene.indices);
    let moved = crate::scene::deformed(scene);
    let blas = build(device, orig, idx, flags)?;
    let g = triangles(orig, idx);
    let probe = BuildGeometryInfo {
        ty: vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
        flags,
        mode: vk::BuildAccelerationStructureModeKHR::UPDATE,
        src: None,
        dst: None,
        geometries: &g,
        scratch: None,
    };
    let sizes = device
        .build_sizes(
            vk::AccelerationStructureBuildTypeKHR::HOST,
            &probe,
            &[idx.len() as u32],
        )
        .map_err(|e| format!("build_sizes: {e}"))?;
    let mut scratch = vec![0u8; sizes.update_scratch_size.max(1) as usize];
    for &t in &cfg.threads {
        let _cpus = crate::util::cpus_for(t);
        let mut flip = false;
        let mut err = None;
        let ms = pool(t).install(|| {
            median_ms(cfg.refit_warmup, cfg.refit_reps, || {
                flip = !flip;
                let p: &[[f32; 3]] = if flip { &moved } else { orig };
                let (r, dt) = time(|| update(device, blas, flags, p, idx, &mut scratch));
                if let Err(e) = r {
                    err = Some(e);
                }
                dt
            })
        });
        if let Some(e) = err {
            return Err(e);
        }
        row.refit_ms.insert(t, ms);
    }
    // Check: update to the moved vertices, compare with a fresh build over them.
    if cfg.trace {
        update(device, blas, flags, &moved, idx, &mut scratch)?;
        let fresh = build(device, &moved, idx, flags)?;
        let mut a = Row::default();
        let mut b = Row::default();
        let one = RaySet {
            primary: Vec::new(),
            incoherent: rays.incoherent.clone(),
        };
        trace_blas(device, blas, &one, 1, &mut a)?;
        trace_blas(device, fresh, &one, 1, &mut b)?;
        let _ = device.destroy_acceleration_structure(fresh);
        let (ha, hb) = (
            a.hits[1].take().unwrap_or_default(),
            b.hits[1].take().unwrap_or_default(),
        );
        let c = crate::report::compare(&hb, &ha, scene.diagonal());
        row.extra.insert(
            "refit_check".into(),
            json!({"rays": c.rays, "ties": c.ties, "true_mismatch": c.true_mismatch}),
        );
        if c.true_mismatch > 0 {
            row.note = format!(
                "after update to moved vertices, {} of {} incoherent rays differ from a fresh build",
                c.true_mismatch, c.rays
            );
        }
    }
    let _ = device.destroy_acceleration_structure(blas);
    let extra = "refit = update (mode UPDATE, in place) of a default + ALLOW_UPDATE build";
    row.note = if row.note.is_empty() {
        extra.to_string()
    } else {
        format!("{extra}; {}", row.note)
    };
    Ok(())
}

pub fn run(scene: &Scene, rays: &RaySet, cfg: &Cfg) -> Vec<Row> {
    let device = Device::new();
    PRESETS
        .iter()
        .filter(|p| cfg.wants("hostas", p.key))
        .map(|p| {
            run_preset(scene, rays, cfg, &device, p).unwrap_or_else(|e| {
                let mut r = Row::new("hostas", p.key, p.desc, Some(p.class));
                r.error = Some(e);
                r
            })
        })
        .collect()
}

/// hostas's side of the paired phase (`crate::paired`): 1-thread builds of one preset, timed as
/// in `run_preset`, and traces of the kept one through a single-instance TLAS, as in
/// `trace_blas`.
struct PairSide<'a> {
    device: Device,
    pool: rayon::ThreadPool,
    scene: &'a Scene,
    flags: Flags,
    /// The kept BLAS and the TLAS over it.
    kept: Option<(AccelerationStructure, AccelerationStructure)>,
}

pub fn pair_side<'a>(scene: &'a Scene, key: &str) -> Result<Box<dyn Side + 'a>, String> {
    let p = PRESETS
        .iter()
        .find(|p| p.key == key)
        .ok_or_else(|| format!("no hostas preset {key}"))?;
    Ok(Box::new(PairSide {
        device: Device::new(),
        pool: pool(1),
        scene,
        flags: (p.flags)(),
        kept: None,
    }))
}

impl PairSide<'_> {
    fn release(&mut self) {
        if let Some((blas, tlas)) = self.kept.take() {
            let _ = self.device.destroy_acceleration_structure(tlas);
            let _ = self.device.destroy_acceleration_structure(blas);
        }
    }
}

impl Side for PairSide<'_> {
    fn build(&mut self, keep: bool) -> Result<Duration, String> {
        let (pos, idx) = (&self.scene.positions, &self.scene.indices);
        let (device, flags) = (&self.device, self.flags);
        let (blas, dt) = self
            .pool
            .install(|| time(|| build(device, pos, idx, flags)));
        let blas = blas?;
        if keep {
            self.release();
            let tlas = hostas::quick::build_single_instance_tlas(&self.device, blas);
            match tlas {
                Ok(tlas) => self.kept = Some((blas, tlas)),
                Err(e) => {
                    let _ = self.device.destroy_acceleration_structure(blas);
                    return Err(format!("TLAS build failed: {e}"));
                }
            }
        } else {
            let _ = self.device.destroy_acceleration_structure(blas);
        }
        Ok(dt)
    }

    fn trace(&mut self, rays: &[Ray], hits: &mut [Hit]) -> Result<Duration, String> {
        let (_, tlas) = self.kept.ok_or("no kept structure")?;
        let scene = self.device.scene(tlas).map_err(|e| format!("scene: {e}"))?;
        Ok(time(|| trace(&scene, rays, hits)).1)
    }
}

impl Drop for PairSide<'_> {
    fn drop(&mut self) {
        self.release();
    }
}
