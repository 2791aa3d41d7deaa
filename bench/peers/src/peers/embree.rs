//! Embree 3 (system libembree3 through the `embree` crate's raw `sys` bindings).
//!
//! - Builds: a managed scene with one triangle geometry (shared 16-byte-stride vertex buffer and
//!   the index buffer), scene and geometry build quality LOW / MEDIUM / HIGH; only
//!   `rtcCommitScene` is timed (geometry setup is not). Each thread count gets its own device
//!   (`threads=N`), created after the previous one is released: Embree sizes its task scheduler
//!   to the maximum over all live devices, so two live devices would share the larger count.
//! - Bytes: what the device's memory monitor saw allocated by the commit (BVH8 nodes plus
//!   Triangle4 leaves, allocator blocks included; the shared buffers are the application's).
//! - Trace: `rtcIntersect1`, one ray at a time, on the structure built by the 1-thread device.
//! - Refit: scene LOW + `RTC_SCENE_FLAG_DYNAMIC`, geometry quality REFIT; timed:
//!   `rtcUpdateGeometryBuffer` + `rtcCommitGeometry` + `rtcCommitScene` after the vertices were
//!   rewritten. Without DYNAMIC, Embree 3 silently rebuilds on every commit.
//! - SAH: Embree does not expose a managed scene's tree, so the SAH column is a proxy: the binary
//!   tree that Embree's generic builder `rtcBuildBVH` (same quality, width 2, leaves of up to 8,
//!   C_trav = C_isect = 1) builds over the same triangles. A second proxy is comparable with
//!   the SAH hostas reports of its 8-wide tree: `rtcBuildBVH` with the settings Embree's own
//!   BVH8Triangle4 scene builder uses (width 8, leaf cost counted in blocks of 4 triangles,
//!   leaves of 4 to 28 triangles, C_trav = C_isect = 1), evaluated with the same formula
//!   (a node visit 1, a triangle test 1).

use crate::Cfg;
use crate::paired::Side;
use crate::peers::trace_all;
use crate::rays::{Hit, Ray, RaySet};
use crate::report::{Class, Row};
use crate::sah;
use crate::scene::Scene;
use crate::util::{median_ms, time};
use embree::sys::*;
use std::ffi::{CStr, CString, c_void};
use std::sync::atomic::{AtomicI64, Ordering};
use std::time::Duration;

const INVALID_ID: u32 = u32::MAX;

struct Variant {
    key: &'static str,
    desc: &'static str,
    quality: RTCBuildQuality,
    class: Class,
    slow: bool,
    /// Scene flags: `NONE`, or `ROBUST` for the variant that is traced with Embree's robust
    /// traversal and triangle test (context for the targets, which compare with the default).
    flags: RTCSceneFlags,
}

const VARIANTS: [Variant; 4] = [
    Variant {
        key: "LOW",
        desc: "LOW (two-level, Morton; BVH8+Triangle4)",
        quality: RTCBuildQuality::LOW,
        class: Class::FastBuild,
        slow: false,
        flags: RTCSceneFlags::NONE,
    },
    Variant {
        key: "MEDIUM",
        desc: "MEDIUM (binned SAH; BVH8+Triangle4)",
        quality: RTCBuildQuality::MEDIUM,
        class: Class::Default,
        slow: false,
        flags: RTCSceneFlags::NONE,
    },
    Variant {
        key: "MEDIUM_ROBUST",
        desc: "MEDIUM + RTC_SCENE_FLAG_ROBUST (robust traversal and triangle test)",
        quality: RTCBuildQuality::MEDIUM,
        class: Class::Default,
        slow: false,
        flags: RTCSceneFlags::ROBUST,
    },
    Variant {
        key: "HIGH",
        desc: "HIGH (SAH + spatial splits; BVH8+Triangle4)",
        quality: RTCBuildQuality::HIGH,
        class: Class::FastTrace,
        slow: true,
        flags: RTCSceneFlags::NONE,
    },
];

struct Device {
    dev: RTCDevice,
    mem: Box<AtomicI64>,
}

unsafe extern "C" fn on_error(
    _user: *mut c_void,
    code: RTCError,
    msg: *const std::os::raw::c_char,
) {
    let m = if msg.is_null() {
        String::new()
    } else {
        unsafe { CStr::from_ptr(msg) }
            .to_string_lossy()
            .into_owned()
    };
    eprintln!("embree error {code:?}: {m}");
}

unsafe extern "C" fn on_memory(user: *mut c_void, bytes: ssize_t, _post: bool) -> bool {
    unsafe { &*(user as *const AtomicI64) }.fetch_add(bytes as i64, Ordering::Relaxed);
    true
}

impl Device {
    fn new(threads: usize) -> Device {
        let cfg = CString::new(format!("threads={threads}")).unwrap();
        let dev = unsafe { rtcNewDevice(cfg.as_ptr()) };
        assert!(!dev.is_null(), "rtcNewDevice failed");
        let mem = Box::new(AtomicI64::new(0));
        unsafe {
            rtcSetDeviceErrorFunction(dev, Some(on_error), std::ptr::null_mut());
            rtcSetDeviceMemoryMonitorFunction(
                dev,
                Some(on_memory),
                &*mem as *const AtomicI64 as *mut c_void,
            );
        }
        Device { dev, mem }
    }
    fn allocated(&self) -> i64 {
        self.mem.load(Ordering::Relaxed)
    }
}

impl Drop for Device {
    fn drop(&mut self) {
        unsafe { rtcReleaseDevice(self.dev) };
    }
}

/// "3.13.5" and the like, from a throw-away device.
pub fn version() -> String {
    let d = Device::new(1);
    let v = unsafe { rtcGetDeviceProperty(d.dev, RTCDeviceProperty::VERSION) };
    format!("{}.{}.{}", v / 10000, v / 100 % 100, v % 100)
}

/// A scene over the shared buffers, not yet committed. `verts` must outlive the scene.
fn new_scene(
    d: &Device,
    verts: &[[f32; 4]],
    idx: &[[u32; 3]],
    quality: RTCBuildQuality,
    geom_quality: RTCBuildQuality,
    flags: RTCSceneFlags,
) -> (RTCScene, RTCGeometry) {
    unsafe {
        let scene = rtcNewScene(d.dev);
        rtcSetSceneFlags(scene, flags);
        rtcSetSceneBuildQuality(scene, quality);
        let geom = rtcNewGeometry(d.dev, RTCGeometryType::TRIANGLE);
        // The vertex buffer has one extra padding element: Embree may read 16 bytes at the last
        // vertex.
        rtcSetSharedGeometryBuffer(
            geom,
            RTCBufferType::VERTEX,
            0,
            RTCFormat::FLOAT3,
            verts.as_ptr() as *const c_void,
            0,
            16,
            verts.len() - 1,
        );
        rtcSetSharedGeometryBuffer(
            geom,
            RTCBufferType::INDEX,
            0,
            RTCFormat::UINT3,
            idx.as_ptr() as *const c_void,
            0,
            12,
            idx.len(),
        );
        rtcSetGeometryBuildQuality(geom, geom_quality);
        rtcCommitGeometry(geom);
        rtcAttachGeometry(scene, geom);
        (scene, geom)
    }
}

fn trace(scene: RTCScene, rays: &[Ray], hits: &mut [Hit]) {
    let mut ctx = RTCIntersectContext {
        flags: RTCIntersectContextFlags::INCOHERENT,
        filter: None,
        instID: [INVALID_ID],
    };
    for (r, h) in rays.iter().zip(hits.iter_mut()) {
        let mut rh = RTCRayHit {
            ray: RTCRay {
                org_x: r.o[0],
                org_y: r.o[1],
                org_z: r.o[2],
                tnear: 0.0,
                dir_x: r.d[0],
                dir_y: r.d[1],
                dir_z: r.d[2],
                time: 0.0,
                tfar: f32::INFINITY,
                mask: u32::MAX,
                id: 0,
                flags: 0,
            },
            hit: RTCHit {
                Ng_x: 0.0,
                Ng_y: 0.0,
                Ng_z: 0.0,
                u: 0.0,
                v: 0.0,
                primID: INVALID_ID,
                geomID: INVALID_ID,
                instID: [INVALID_ID],
            },
        };
        unsafe { rtcIntersect1(scene, &mut ctx, &mut rh) };
        *h = if rh.hit.geomID != INVALID_ID {
            Hit {
                t: rh.ray.tfar,
                prim: rh.hit.primID,
            }
        } else {
            Hit::MISS
        };
    }
}

fn verts4(p: &[[f32; 3]]) -> Vec<[f32; 4]> {
    let mut v: Vec<[f32; 4]> = p.iter().map(|p| [p[0], p[1], p[2], 0.0]).collect();
    v.push([0.0; 4]);
    v
}

pub fn run(scene: &Scene, rays: &RaySet, cfg: &Cfg) -> Vec<Row> {
    let variants: Vec<&Variant> = VARIANTS
        .iter()
        .filter(|v| cfg.wants("embree", v.key))
        .collect();
    let do_refit = cfg.refit && cfg.wants("embree", "refit");
    if variants.is_empty() && !do_refit {
        return Vec::new();
    }
    let verts = verts4(&scene.positions);
    let idx = &scene.indices;
    let mut rows: Vec<Row> = variants
        .iter()
        .map(|v| {
            let mut r = Row::new("embree", v.key, v.desc, Some(v.class));
            r.bytes_note =
                "memory monitor: BVH8 nodes + Triangle4 leaves (allocator blocks)".into();
            r
        })
        .collect();
    let mut refit_row = Row::new(
        "embree",
        "refit",
        "refit: scene LOW+DYNAMIC, geometry REFIT",
        Some(Class::Default),
    );

    for &t in &cfg.threads {
        let _cpus = crate::util::cpus_for(t);
        let d = Device::new(t);
        for (v, row) in variants.iter().zip(rows.iter_mut()) {
            let reps = if v.slow { cfg.slow_reps } else { cfg.reps };
            let warm = if v.slow { cfg.slow_warmup } else { cfg.warmup };
            // The last 1-thread build is kept: bytes and tracing come from it.
            let total = warm + reps.max(1);
            let mut rep = 0;
            let mut kept = None;
            let ms = median_ms(warm, reps, || {
                rep += 1;
                let (s, g) = new_scene(&d, &verts, idx, v.quality, v.quality, v.flags);
                let before = d.allocated();
                let ((), dt) = time(|| unsafe { rtcCommitScene(s) });
                if t == 1 && rep == total {
                    kept = Some((s, g, (d.allocated() - before).max(0) as u64));
                } else {
                    unsafe {
                        rtcReleaseGeometry(g);
                        rtcReleaseScene(s);
                    }
                }
                dt
            });
            row.build_ms.insert(t, ms);
            if let Some((s, g, bytes)) = kept {
                row.bytes = Some(bytes);
                if cfg.trace {
                    trace_all(row, rays, cfg.passes, |r, h| trace(s, r, h));
                }
                unsafe {
                    rtcReleaseGeometry(g);
                    rtcReleaseScene(s);
                }
            }
        }
        if do_refit {
            let mut buf = verts.clone();
            let moved = verts4(&crate::scene::deformed(scene));
            let (s, g) = new_scene(
                &d,
                &buf,
                idx,
                RTCBuildQuality::LOW,
                RTCBuildQuality::REFIT,
                RTCSceneFlags::DYNAMIC,
            );
            unsafe { rtcCommitScene(s) };
            let mut flip = false;
            let ms = median_ms(cfg.refit_warmup, cfg.refit_reps, || {
                flip = !flip;
                buf.copy_from_slice(if flip { &moved } else { &verts });
                let ((), dt) = time(|| unsafe {
                    rtcUpdateGeometryBuffer(g, RTCBufferType::VERTEX, 0);
                    rtcCommitGeometry(g);
                    rtcCommitScene(s);
                });
                dt
            });
            refit_row.refit_ms.insert(t, ms);
            if t == 1 && cfg.trace {
                // Check that the refit really follows the vertices: refit to the deformed
                // positions and compare its hits with a fresh MEDIUM build over them.
                buf.copy_from_slice(&moved);
                unsafe {
                    rtcUpdateGeometryBuffer(g, RTCBufferType::VERTEX, 0);
                    rtcCommitGeometry(g);
                    rtcCommitScene(s);
                }
                let rs = &rays.incoherent;
                let mut a = vec![Hit::MISS; rs.len()];
                trace(s, rs, &mut a);
                let (s2, g2) = new_scene(
                    &d,
                    &moved,
                    idx,
                    RTCBuildQuality::MEDIUM,
                    RTCBuildQuality::MEDIUM,
                    RTCSceneFlags::NONE,
                );
                unsafe { rtcCommitScene(s2) };
                let mut b = vec![Hit::MISS; rs.len()];
                trace(s2, rs, &mut b);
                unsafe {
                    rtcReleaseGeometry(g2);
                    rtcReleaseScene(s2);
                }
                let c = crate::report::compare(&b, &a, scene.diagonal());
                refit_row.extra.insert(
                    "refit_check".into(),
                    serde_json::json!({"rays": c.rays, "ties": c.ties, "true_mismatch": c.true_mismatch}),
                );
                if c.true_mismatch > c.rays / 1000 {
                    refit_row.note = format!(
                        "after refit to moved vertices, {} of {} incoherent rays differ from a fresh build",
                        c.true_mismatch, c.rays
                    );
                }
            }
            unsafe {
                rtcReleaseGeometry(g);
                rtcReleaseScene(s);
            }
        }
        drop(d);
    }

    if cfg.sah_proxy != crate::SahProxy::Off && !rows.is_empty() {
        let n = *cfg.threads.last().unwrap();
        let _cpus = crate::util::cpus_for(n);
        let d = Device::new(n);
        for (v, row) in variants.iter().zip(rows.iter_mut()) {
            if v.slow && cfg.sah_proxy != crate::SahProxy::All {
                row.sah_note = "proxy skipped for HIGH (--embree-sah-proxy all)".into();
                continue;
            }
            if v.flags != RTCSceneFlags::NONE {
                // The flag changes the leaves and their test, not the builder's splits.
                row.sah_note = "proxy skipped: the same build quality as MEDIUM".into();
                continue;
            }
            let (s, dt) = time(|| sah_proxy(&d, scene, v.quality, &BINARY));
            let (s8, dt8) = time(|| sah_proxy(&d, scene, v.quality, &BVH8_TRIANGLE4));
            row.sah = Some(s);
            row.sah8 = Some(s8);
            row.sah_note = format!(
                "proxies: rtcBuildBVH {} width 2, leaves <= 8 ({:.0} ms); width 8, blocks of 4, leaves 4..28 ({:.0} ms)",
                v.key,
                dt.as_secs_f64() * 1e3,
                dt8.as_secs_f64() * 1e3
            );
        }
    }
    if do_refit {
        rows.push(refit_row);
    }
    rows
}

/// Embree's side of the paired phase (`crate::paired`): a 1-thread device, builds of one
/// quality timed as in `run` (`rtcCommitScene` only), and `rtcIntersect1` on the kept one.
struct PairSide<'a> {
    kept: Option<(RTCScene, RTCGeometry)>,
    verts: Vec<[f32; 4]>,
    idx: &'a [[u32; 3]],
    quality: RTCBuildQuality,
    flags: RTCSceneFlags,
    // Last: released after the kept scene.
    d: Device,
}

pub fn pair_side<'a>(scene: &'a Scene, key: &str) -> Result<Box<dyn Side + 'a>, String> {
    let v = VARIANTS
        .iter()
        .find(|v| v.key == key)
        .ok_or_else(|| format!("no Embree variant {key}"))?;
    Ok(Box::new(PairSide {
        kept: None,
        verts: verts4(&scene.positions),
        idx: &scene.indices,
        quality: v.quality,
        flags: v.flags,
        d: Device::new(1),
    }))
}

fn release((s, g): (RTCScene, RTCGeometry)) {
    unsafe {
        rtcReleaseGeometry(g);
        rtcReleaseScene(s);
    }
}

impl Side for PairSide<'_> {
    fn build(&mut self, keep: bool) -> Result<Duration, String> {
        let q = self.quality;
        let (s, g) = new_scene(&self.d, &self.verts, self.idx, q, q, self.flags);
        let ((), dt) = time(|| unsafe { rtcCommitScene(s) });
        let err = unsafe { rtcGetDeviceError(self.d.dev) };
        if err != RTCError::NONE {
            release((s, g));
            return Err(format!("rtcCommitScene: {err:?}"));
        }
        if keep {
            if let Some(old) = self.kept.replace((s, g)) {
                release(old);
            }
        } else {
            release((s, g));
        }
        Ok(dt)
    }

    fn trace(&mut self, rays: &[Ray], hits: &mut [Hit]) -> Result<Duration, String> {
        let (s, _) = self.kept.ok_or("no kept structure")?;
        Ok(time(|| trace(s, rays, hits)).1)
    }
}

impl Drop for PairSide<'_> {
    fn drop(&mut self) {
        if let Some(kept) = self.kept.take() {
            release(kept);
        }
    }
}

// ---------------------------------------------------------------------------------------------
// SAH proxy through rtcBuildBVH.

/// The shape of a proxy tree (`rtcBuildBVH` arguments).
struct Shape {
    width: u32,
    sah_block: u32,
    min_leaf: u32,
    max_leaf: u32,
}

/// A binary tree, leaves of up to 8 triangles.
const BINARY: Shape = Shape {
    width: 2,
    sah_block: 1,
    min_leaf: 1,
    max_leaf: 8,
};

/// What Embree's BVH8Triangle4 SAH scene builder (MEDIUM's structure) asks of the same
/// generic builder: 8 children, a leaf's cost counted per block of 4 triangles, leaves of at
/// least 4 and at most 7 blocks.
const BVH8_TRIANGLE4: Shape = Shape {
    width: 8,
    sah_block: 4,
    min_leaf: 4,
    max_leaf: 28,
};

const MAX_WIDTH: usize = 8;

#[repr(C)]
struct BNode {
    leaf_count: u32, // 0 = interior
    child_count: u32,
    children: [*mut BNode; MAX_WIDTH],
    bounds: [RTCBounds; MAX_WIDTH],
}

struct SplitCtx<'a> {
    pos: &'a [[f32; 3]],
    idx: &'a [[u32; 3]],
}

unsafe fn alloc_node(a: RTCThreadLocalAllocator) -> *mut BNode {
    let p = unsafe { rtcThreadLocalAlloc(a, std::mem::size_of::<BNode>(), 16) } as *mut BNode;
    unsafe { p.write(std::mem::zeroed()) };
    p
}

unsafe extern "C" fn create_node(
    a: RTCThreadLocalAllocator,
    _n: u32,
    _u: *mut c_void,
) -> *mut c_void {
    unsafe { alloc_node(a) as *mut c_void }
}

unsafe extern "C" fn set_children(
    node: *mut c_void,
    ch: *mut *mut c_void,
    n: u32,
    _u: *mut c_void,
) {
    let node = unsafe { &mut *(node as *mut BNode) };
    node.child_count = n.min(MAX_WIDTH as u32);
    for i in 0..node.child_count as usize {
        node.children[i] = unsafe { *ch.add(i) } as *mut BNode;
    }
}

unsafe extern "C" fn set_bounds(
    node: *mut c_void,
    b: *mut *const RTCBounds,
    n: u32,
    _u: *mut c_void,
) {
    let node = unsafe { &mut *(node as *mut BNode) };
    for i in 0..(n as usize).min(MAX_WIDTH) {
        node.bounds[i] = unsafe { **b.add(i) };
    }
}

unsafe extern "C" fn create_leaf(
    a: RTCThreadLocalAllocator,
    _p: *const RTCBuildPrimitive,
    n: usize,
    _u: *mut c_void,
) -> *mut c_void {
    let node = unsafe { alloc_node(a) };
    unsafe { (*node).leaf_count = n as u32 };
    node as *mut c_void
}

/// Exact split of a triangle's part inside `prim`'s bounds by the plane `dim = pos`.
unsafe extern "C" fn split_prim(
    prim: *const RTCBuildPrimitive,
    dim: u32,
    pos: f32,
    left: *mut RTCBounds,
    right: *mut RTCBounds,
    user: *mut c_void,
) {
    let ctx = unsafe { &*(user as *const SplitCtx) };
    let p = unsafe { &*prim };
    let tri = ctx.idx[p.primID as usize].map(|i| ctx.pos[i as usize]);
    let dim = dim as usize;
    let mut lb = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
    let mut rb = lb;
    let grow = |b: &mut ([f32; 3], [f32; 3]), v: [f32; 3]| {
        for (k, &x) in v.iter().enumerate() {
            b.0[k] = b.0[k].min(x);
            b.1[k] = b.1[k].max(x);
        }
    };
    for e in 0..3 {
        let (a, b) = (tri[e], tri[(e + 1) % 3]);
        if a[dim] <= pos {
            grow(&mut lb, a);
        }
        if a[dim] >= pos {
            grow(&mut rb, a);
        }
        if (a[dim] < pos && b[dim] > pos) || (a[dim] > pos && b[dim] < pos) {
            let t = (pos - a[dim]) / (b[dim] - a[dim]);
            let mut x = [0, 1, 2].map(|k| a[k] + t * (b[k] - a[k]));
            x[dim] = pos;
            grow(&mut lb, x);
            grow(&mut rb, x);
        }
    }
    let pl = [p.lower_x, p.lower_y, p.lower_z];
    let pu = [p.upper_x, p.upper_y, p.upper_z];
    let clip = |b: ([f32; 3], [f32; 3]), side_left: bool| {
        let mut lo = [0f32; 3];
        let mut hi = [0f32; 3];
        for k in 0..3 {
            lo[k] = b.0[k].max(pl[k]);
            hi[k] = b.1[k].min(pu[k]);
        }
        if side_left {
            hi[dim] = hi[dim].min(pos);
        } else {
            lo[dim] = lo[dim].max(pos);
        }
        RTCBounds {
            lower_x: lo[0],
            lower_y: lo[1],
            lower_z: lo[2],
            align0: 0.0,
            upper_x: hi[0],
            upper_y: hi[1],
            upper_z: hi[2],
            align1: 0.0,
        }
    };
    unsafe {
        *left = clip(lb, true);
        *right = clip(rb, false);
    }
}

fn sah_proxy(d: &Device, scene: &Scene, quality: RTCBuildQuality, shape: &Shape) -> f64 {
    let n = scene.tri_count();
    let cap = if quality == RTCBuildQuality::HIGH {
        2 * n
    } else {
        n
    };
    let mut prims: Vec<RTCBuildPrimitive> = Vec::with_capacity(cap);
    for (i, t) in scene.indices.iter().enumerate() {
        let v = t.map(|k| scene.positions[k as usize]);
        let lo = [0, 1, 2].map(|k| v[0][k].min(v[1][k]).min(v[2][k]));
        let hi = [0, 1, 2].map(|k| v[0][k].max(v[1][k]).max(v[2][k]));
        prims.push(RTCBuildPrimitive {
            lower_x: lo[0],
            lower_y: lo[1],
            lower_z: lo[2],
            geomID: 0,
            upper_x: hi[0],
            upper_y: hi[1],
            upper_z: hi[2],
            primID: i as u32,
        });
    }
    let ctx = SplitCtx {
        pos: &scene.positions,
        idx: &scene.indices,
    };
    unsafe {
        prims.set_len(n);
        let bvh = rtcNewBVH(d.dev);
        let args = RTCBuildArguments {
            byteSize: std::mem::size_of::<RTCBuildArguments>(),
            buildQuality: quality,
            buildFlags: RTCBuildFlags::NONE,
            maxBranchingFactor: shape.width,
            maxDepth: 1024,
            sahBlockSize: shape.sah_block,
            minLeafSize: shape.min_leaf,
            maxLeafSize: shape.max_leaf,
            traversalCost: sah::C_TRAV as f32,
            intersectionCost: sah::C_ISECT as f32,
            bvh,
            primitives: prims.as_mut_ptr(),
            primitiveCount: n,
            primitiveArrayCapacity: cap,
            createNode: Some(create_node),
            setNodeChildren: Some(set_children),
            setNodeBounds: Some(set_bounds),
            createLeaf: Some(create_leaf),
            splitPrimitive: Some(split_prim),
            buildProgress: None,
            userPtr: &ctx as *const SplitCtx as *mut c_void,
        };
        let root = rtcBuildBVH(&args) as *mut BNode;
        let root_area = sah::area(scene.bmin, scene.bmax);
        // Walk: an interior node's area comes from its parent's child bounds; the root's from
        // the scene bounds.
        let mut sum = 0.0;
        let mut stack: Vec<(*mut BNode, f64)> = vec![(root, root_area)];
        while let Some((p, a)) = stack.pop() {
            let node = &*p;
            if node.leaf_count > 0 {
                sum += sah::C_ISECT * a * node.leaf_count as f64;
            } else {
                sum += sah::C_TRAV * a;
                for i in 0..node.child_count as usize {
                    let b = node.bounds[i];
                    let ca = sah::area(
                        [b.lower_x, b.lower_y, b.lower_z],
                        [b.upper_x, b.upper_y, b.upper_z],
                    );
                    stack.push((node.children[i], ca));
                }
            }
        }
        rtcReleaseBVH(bvh);
        sum / root_area
    }
}
