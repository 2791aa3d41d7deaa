//! Batch tracing without the ray-query state machine: closest hit and any hit with the
//! semantics of `traceRayEXT` when no any-hit or intersection shader is bound (every
//! candidate that survives culling is accepted; an AABB is hit where the ray enters it).
//!
//! This is the hot path of rendering and benchmarks, so it keeps per-ray work to the
//! traversal itself: the views are made once per tracer, the stack is reused across rays,
//! candidates are not materialized, and the ids of the hit are looked up once at the end.
//! The oracle tests check it against the brute-force tracer just like `RayQuery`.

use super::interleaved;
use super::packet::{self, Packets, Walked, fell_apart};
use super::query::{
    ANY_AXES, BoxRay, Entry, STACK_CAPACITY, descend, opacity_culled, prune_limit, resolve_opacity,
};
use super::scene::{Hit, HitKind, Scene};
use super::screen::{self, RootBox, Screened};
use super::tile::{self, Blocks};
use super::triangle::{ShearedRay, TriangleHit, by_permutation, permutation};
use super::{Ray, RayFlags};
use crate::error::Result;
use crate::layout::triangles::{Indexed, TriangleSource, Triangles};
use crate::layout::view::View;
use crate::layout::{INSTANCE_IDENTITY, InstanceRecord, LEAF_BIT, PrimKind};
use crate::math::{Affine, Vec3, lanes};
use ash::vk;
use std::borrow::Borrow;
use wide::{f32x4, f32x8};

thread_local! {
    static STACKS: std::cell::RefCell<Vec<Vec<Entry>>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// Traces many rays through one [`Scene`], reusing its views and stack.
pub struct Tracer<'s> {
    scene: &'s Scene,
    tlas: Option<View<'s>>,
    /// The bottom-level view used last (consecutive instances often share one).
    cached: Option<(u32, View<'s>)>,
    stack: Vec<Entry>,
    /// The top level's only instance, when it is the identity: rays go straight to its
    /// bottom level, resolved once here.
    direct: Option<Direct<'s>>,
    /// [`Tracer::closest_batch`]'s rays by class and its stacks, kept for the next batch.
    order: Vec<u32>,
    classes: Vec<u8>,
    stacks: Vec<BlasStack>,
    /// What [`Tracer::closest_batch`]'s packets work in for batches shorter than
    /// [`LOCAL_PACKETS_FROM`], kept for the next.
    packet_work: Option<Box<Packets>>,
    /// Rays of packets traced again on their own, having met a tie (for the tests).
    retraced: usize,
    /// Rays traced one at a time, the packets before them in their batch (or in a recent
    /// batch) having fallen apart (for the tests).
    alone_after_judging: usize,
    /// Whether [`Interleave::Auto`] walks a camera's next batch in blocks of pixels: its last
    /// batch's packets held together to their leaves but split often on the way
    /// ([`packet::split_often`]).
    in_blocks: bool,
    /// Batches still to trace one at a time without judging their packets, the last judged
    /// batch's having fallen apart (see [`APART_FOR`]).
    apart_for: u32,
}

/// A top level that holds one identity instance of a non-empty bottom level. Its only box
/// is the instance's world box, which the bottom level's root test covers: walking the top
/// level would only add its cost.
struct Direct<'s> {
    view: View<'s>,
    inst: &'s InstanceRecord,
    /// The instance's mask (its low 8 bits), which a ray's cull mask must meet.
    mask: u32,
    /// The flag that skips the bottom level's kind of primitive (`SKIP_TRIANGLES` or
    /// `SKIP_AABBS`: the only kinds that go direct).
    skip: u32,
    /// Whether [`Tracer::closest_batch`] walks its rays several at a time (see
    /// [`INTERLEAVE_FROM_BYTES`]).
    interleave: bool,
    /// The box around the root's children, which a camera's rays are screened against eight
    /// at a time ([`screen`]); `None` where a plane is NaN.
    root_box: Option<RootBox>,
}

/// The size from which a bottom level's rays are walked several at a time by
/// [`Tracer::closest_batch`]: where most of a walk's loads miss the caches near the core and
/// the wait for them, not the work, is the cost. On the Xeon the table is measured on, four
/// rounds alternated against one ray at a time (the twenty-sixth session): incoherent rays
/// 1.29-1.71x as fast on the 1M-triangle scenes (29-52 MB used), 0.76-1.10x on the meshes
/// (2.4-12 MB), where the interleaving's own work costs more than the waits it hides; the
/// crown (126 MB, whose rays end after a few nodes) about the same (1.05x, three rounds).
const INTERLEAVE_FROM_BYTES: u64 = 16 << 20;

impl<'s> Direct<'s> {
    fn new(scene: &'s Scene, tlas: &View<'s>) -> Option<Direct<'s>> {
        let [inst] = tlas.instances else {
            return None;
        };
        if inst.hints & INSTANCE_IDENTITY == 0 {
            return None;
        }
        let blas = scene.instance_blas_index(0)?;
        let view = scene.blas_view(blas)?;
        // Only bottom levels some ray enters (triangles or AABBs) go direct.
        let skip = match view.prim_kind {
            PrimKind::Triangles => RayFlags::SKIP_TRIANGLES,
            PrimKind::Aabbs => RayFlags::SKIP_AABBS,
            _ => return None,
        };
        let root_box = RootBox::new(view.nodes.first()?);
        Some(Direct {
            view,
            inst,
            mask: inst.mask & 0xff,
            skip: skip.0,
            interleave: view.prim_kind == PrimKind::Triangles
                && view.header.used_size >= INTERLEAVE_FROM_BYTES,
            root_box,
        })
    }

    /// The axis permutation of `ray` where it is of the common case that batches walk several
    /// at a time (no culling flag, no `TERMINATE_ON_FIRST_HIT` where `first_hit_alone`, the
    /// instance's mask met, a direction whose inverse is finite); `None` for a ray to trace on
    /// its own.
    #[inline(always)]
    fn common_permutation(&self, ray: &Ray, first_hit_alone: bool) -> Option<usize> {
        let common = self.common_flags(ray, first_hit_alone) && Self::finite_inverse(ray.direction);
        common.then(|| permutation(ray.direction))
    }

    /// [`Direct::common_permutation`]'s test of the ray's flags and mask.
    #[inline(always)]
    fn common_flags(&self, ray: &Ray, first_hit_alone: bool) -> bool {
        let first_hit = if first_hit_alone {
            RayFlags::TERMINATE_ON_FIRST_HIT.0
        } else {
            0
        };
        ray.flags.0 & (CULLING.0 | first_hit | self.skip) == 0 && self.mask & ray.cull_mask != 0
    }

    /// Whether `1 / c` is finite for every component `c` of `dir`, as [`BoxRay`] computes it
    /// (one division of the three lanes: correctly rounded, so the same bits as three).
    #[inline(always)]
    fn finite_inverse(dir: Vec3) -> bool {
        (f32x4::ONE / lanes(dir)).is_finite().to_bitmask() & 0b111 == 0b111
    }

    /// The hits of `rays` (rays `from..` of a batch), one at a time, into `hits`; or the first
    /// invalid ray's error. With `SCREENED`, the rays are first screened eight at a time
    /// against the root's box ([`Direct::screen`]): for a camera's rays, many of which miss.
    /// (A constant, so that the other rays' loop is the plain one: with the choice made at
    /// run time, incoherent rays executed 2.6-3.3% more instructions under callgrind; inlined
    /// into its caller, 0.5% more.)
    #[inline(never)]
    fn trace_each<const FIRST: bool, const SCREENED: bool>(
        &self,
        rays: &[Ray],
        hits: &mut [Hit],
        from: usize,
    ) -> Result<()> {
        // The walk's stack on this thread's stack, a short fixed distance from the walk's own
        // spilled values, rather than on the heap: how far apart the two lay modulo 4 KiB
        // moved the meshes' primary rays by up to 20% from process to process (most likely
        // 4 KiB aliasing, a load taken as overlapping a pending store to an address 4 KiB
        // away; see `LOCAL_STACK_FROM`).
        let mut stack = [Entry::default(); STACK_CAPACITY];
        let mut screen = Screened::default();
        for (i, (r, h)) in rays.iter().zip(hits).enumerate() {
            let bit = 1 << (i % screen::LANES);
            if SCREENED && bit == 1 {
                screen = self.screen(rays.get(i..).unwrap_or_default());
            }
            if screen.plain & bit == 0 {
                r.validate().map_err(|e| e.in_ray(from + i))?;
            }
            if screen.outside & bit != 0 {
                *h = Hit::MISS;
                continue;
            }
            let first_hit = FIRST || r.flags.contains(RayFlags::TERMINATE_ON_FIRST_HIT);
            *h = self.trace(&mut stack, r, first_hit);
        }
        Ok(())
    }

    /// [`RootBox::screen`] of the first [`screen::LANES`] of `rays` against the root's box
    /// (nothing found where there is no box).
    #[inline(always)]
    fn screen(&self, rays: &[Ray]) -> Screened {
        self.root_box
            .as_ref()
            .map_or(Screened::default(), |b| b.screen(rays))
    }

    /// A valid ray's hit, walked on `stack`.
    #[inline(always)]
    fn trace(&self, stack: &mut BlasStack, ray: &Ray, first_hit: bool) -> Hit {
        let mut best = Best::miss(ray.t_max);
        if self.mask & ray.cull_mask != 0 && ray.flags.0 & self.skip == 0 {
            let boxes = BoxRay::new(ray.origin, ray.direction);
            let at = BlasAt {
                view: &self.view,
                inst: self.inst,
            };
            walk_blas(stack, &at, &boxes, ray, &mut best, first_hit);
        }
        hit(&best, self.inst, Some(&self.view))
    }
}

impl Drop for Tracer<'_> {
    fn drop(&mut self) {
        let s = std::mem::take(&mut self.stack);
        STACKS.with(|p| {
            let mut p = p.borrow_mut();
            if p.len() < 8 {
                p.push(s);
            }
        });
    }
}

/// How [`Tracer::closest_batch_with`] walks a batch's rays. Every choice gives the same hits;
/// only the time differs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Interleave {
    /// Several at once where that measured faster, through the scene's only instance (an
    /// identity one) of triangles: closest hits of rays that mostly share an origin (a
    /// camera's) in packets (as `Packets`: on the lent Xeon, against one ray at a time, the
    /// 1M-triangle soup's and boxes' primary rays 1.09-1.15x as fast, Sponza's and Sibenik's
    /// 1.04-1.09x, the other meshes' about as fast), the rest of a batch (and the tracer's next
    /// seven batches) one at a time once its packets are seen to fall apart before their
    /// leaves (the 1M-triangle sphere's, whose packets alone were 0.94-0.96x as fast), a
    /// camera's rows in blocks of 2 x 4 pixels after a batch whose packets split often on the
    /// way to their leaves (the soup's, boxes', the bunny's), and other rays interleaved
    /// through a bottom level of 16 MiB or more (used).
    #[default]
    Auto,
    /// Several at once wherever the scene allows (one identity instance of triangles; rays
    /// with culling flags, `TERMINATE_ON_FIRST_HIT`, a cull mask the instance does not meet or
    /// a direction component whose inverse is not finite are still traced one at a time).
    Always,
    /// One at a time, as [`Tracer::closest`].
    Never,
    /// Closest hits of coherent rays (a camera's, next to each other in the batch) in packets
    /// of up to eight, wherever the scene allows (as `Always`; the other rays, and first hits,
    /// one at a time), as `Auto` walks a batch whose rays mostly share an origin; a camera's
    /// rows always in blocks of 2 x 4 pixels (`Auto` chooses blocks by how its packets held
    /// together).
    Packets,
}

/// From this many rays, a batch traced one ray at a time through a [`Direct`] bottom level
/// walks them on a stack of its own, made (and zeroed, 7 KiB) per batch on the thread's
/// stack; shorter batches use the tracer's, not to pay the zeroing for a ray or two (the
/// threshold is not tuned). Measured on the lent Xeon with address-space randomization off
/// and the process's stack moved by 0 to 3,840 bytes (`docs/results/s27/`): the paired
/// primary rays against Embree MEDIUM read 1.145 (the conference) and 1.195 (Sponza) over the
/// sixteen placements with the heap stack (0.94 and 0.90 at the worst), 1.247 and 1.263 with
/// this one (1.01 and 1.05).
const LOCAL_STACK_FROM: usize = 16;

/// From this many rays, a batch walked in packets makes their state ([`Packets`], about 26
/// KiB) on the thread's stack, where it lies at a fixed distance from the walk's own values;
/// shorter batches use the tracer's, on the heap, not to pay its making (zeroing) for a few
/// rays (the threshold is not tuned). Measured on the lent Xeon with address-space
/// randomization off and the process's stack moved by 0 to 3,840 bytes, sixteen placements
/// twice (`docs/results/s31/`): of 160 paired primary-ray ratios against Embree MEDIUM (the
/// soup and four meshes), 31 read at least 7% below the scene's usual with the heap's state,
/// 18 with the stack's; the means moved by -2.2% (Sibenik) to +2.2% (Sponza).
const LOCAL_PACKETS_FROM: usize = 256;

/// Batches that [`Interleave::Auto`] traces one ray at a time after one whose packets fell
/// apart ([`fell_apart`]), before it judges packets again: the rays a batch walks in packets
/// until judged (70-150 of the 1M sphere's 1,024) cost more than one at a time, and a camera's
/// next batches are much like its last.
const APART_FOR: u32 = 7;

/// The most rays [`Tracer::closest_batch_with`] orders at once (longer batches are split).
const MAX_BATCH: usize = 1 << 30;

/// Whether most consecutive rays of `rays` start at the same point (a camera's primary rays):
/// such rays visit the same nodes one after another, which one ray at a time finds in the
/// caches (interleaved, the soup's and boxes' primary rays were 0.77-0.88x as fast). Judged
/// by [`ORIGIN_PAIRS`] pairs of neighbours spread evenly over the batch, their origins compared
/// bit for bit (comparing every pair cost the conference's incoherent rays 0.5% of their
/// instructions under callgrind).
fn share_origins(rays: &[Ray]) -> bool {
    let stride = (rays.len() / ORIGIN_PAIRS).max(1);
    let bits = |r: &Ray| r.origin.map(f32::to_bits);
    let (mut pairs, mut shared) = (0, 0);
    for w in rays.windows(2).step_by(stride) {
        pairs += 1;
        shared += usize::from(bits(&w[0]) == bits(&w[1]));
    }
    pairs > 0 && 2 * shared >= pairs
}

/// How many pairs of neighbours [`share_origins`] compares.
const ORIGIN_PAIRS: usize = 64;

/// The hit found so far.
#[derive(Clone, Copy)]
pub(super) struct Best {
    pub t: f32,
    pub kind: HitKind,
    instance_slot: u32,
    blas: u32,
    prim_slot: u32,
    barycentrics: [f32; 2],
    front_face: bool,
    /// Whether a walk that looks for ties (a packet's, `TIES` in [`trace_blas`]) met a
    /// candidate at exactly the distance of the hit it had: which of the two the ray's own
    /// walk reports depends on the order, so the ray is traced again on its own.
    pub tied: bool,
}

impl Best {
    /// No hit yet, in a range up to `t`.
    #[inline(always)]
    pub(super) fn miss(t: f32) -> Best {
        Best {
            t,
            kind: HitKind::Miss,
            instance_slot: 0,
            blas: 0,
            prim_slot: 0,
            barycentrics: [0.0; 2],
            front_face: false,
            tied: false,
        }
    }

    /// The bound below which a walk that looks for ties tests candidates: the next float past
    /// the hit's distance, so that a candidate at that distance is seen; the range's end with
    /// no hit yet (the range is strict). (A hit's distance is positive and finite, so the next
    /// float up is the next bit pattern.)
    #[inline(always)]
    pub(super) fn tie_bound(&self) -> f32 {
        f32::from_bits(self.t.to_bits() + u32::from(self.kind != HitKind::Miss))
    }

    /// Whether a candidate at `t`, below [`Best::tie_bound`], ties with the hit (noting it).
    #[inline(always)]
    pub(super) fn ties(&mut self, t: f32) -> bool {
        if t == self.t && self.kind != HitKind::Miss {
            self.tied = true;
            return true;
        }
        false
    }

    /// Makes the triangle hit `h` in stored slot `prim_slot` the nearest so far (`front`: its
    /// facing after the instance's `FLIP_FACING`).
    #[inline(always)]
    pub(super) fn accept_triangle(&mut self, prim_slot: u32, h: &TriangleHit, front: bool) {
        self.t = h.t;
        self.kind = HitKind::Triangle;
        self.prim_slot = prim_slot;
        self.barycentrics = [h.b, h.c];
        self.front_face = front;
    }
}

/// What a top level's leaves hold instead of triangles (nothing to prefetch).
const NO_TRIANGLES: &[[f32; 9]] = &[];

/// A bottom-level walk's stack: of a length known at compile time, so that the walk keeps
/// no register for it. (The top level's entries, at most `STACK_CAPACITY`, lie below it.)
pub(super) type BlasStack = [Entry; STACK_CAPACITY];

/// Room for a top-level and a bottom-level traversal on top of it.
const TRACER_STACK: usize = 2 * STACK_CAPACITY;

impl<'s> Tracer<'s> {
    pub fn new(scene: &'s Scene) -> Tracer<'s> {
        let mut stack = STACKS.with(|p| p.borrow_mut().pop()).unwrap_or_default();
        stack.resize(TRACER_STACK, Entry::default());
        let tlas = scene.tlas_view();
        Tracer {
            scene,
            tlas,
            cached: None,
            stack,
            direct: tlas.as_ref().and_then(|t| Direct::new(scene, t)),
            order: Vec::new(),
            classes: Vec::new(),
            stacks: Vec::new(),
            packet_work: None,
            retraced: 0,
            alone_after_judging: 0,
            in_blocks: false,
            apart_for: 0,
        }
    }

    /// Closest hit (see [`Scene::trace_closest`]).
    pub fn closest(&mut self, ray: &Ray) -> Result<Hit> {
        self.trace(ray, ray.flags.contains(RayFlags::TERMINATE_ON_FIRST_HIT))
    }

    /// First accepted hit (see [`Scene::trace_any`]).
    pub fn any(&mut self, ray: &Ray) -> Result<Hit> {
        self.trace(ray, true)
    }

    /// Closest hits of `rays`, in order, into `hits` (replacing its contents): for each ray
    /// the hit [`Tracer::closest`] gives it, bit for bit, or the first invalid ray's error,
    /// with that ray's index in `rays` as its [`Location::ray`](crate::Location::ray).
    /// Through a bottom level that is the scene's only, identity instance, rays that share an
    /// origin are walked in packets, and other rays through a large one (16 MiB or more)
    /// several at once (see [`Interleave`]).
    pub fn closest_batch(&mut self, rays: &[Ray], hits: &mut Vec<Hit>) -> Result<()> {
        self.closest_batch_with(rays, hits, Interleave::Auto)
    }

    /// [`Tracer::closest_batch`], choosing how the rays are walked.
    pub fn closest_batch_with(
        &mut self,
        rays: &[Ray],
        hits: &mut Vec<Hit>,
        interleave: Interleave,
    ) -> Result<()> {
        self.batch::<false>(rays, hits, interleave)
    }

    /// First accepted hits of `rays` (every ray traced as with `TerminateOnFirstHit`, as
    /// shadow rays are), in order, into `hits`: for each ray the hit [`Tracer::any`] gives
    /// it, bit for bit; otherwise as [`Tracer::closest_batch`].
    pub fn any_batch(&mut self, rays: &[Ray], hits: &mut Vec<Hit>) -> Result<()> {
        self.any_batch_with(rays, hits, Interleave::Auto)
    }

    /// [`Tracer::any_batch`], choosing how the rays are walked.
    pub fn any_batch_with(
        &mut self,
        rays: &[Ray],
        hits: &mut Vec<Hit>,
        interleave: Interleave,
    ) -> Result<()> {
        self.batch::<true>(rays, hits, interleave)
    }

    /// Closest hits, or with `FIRST` first accepted hits, of `rays` into `hits`.
    fn batch<const FIRST: bool>(
        &mut self,
        rays: &[Ray],
        hits: &mut Vec<Hit>,
        interleave: Interleave,
    ) -> Result<()> {
        if rays.len() <= MAX_BATCH {
            return self.chunk::<FIRST>(rays, hits, interleave);
        }
        // (Rays are numbered by `u32` in a chunk.)
        hits.clear();
        let mut part = Vec::new();
        for (k, chunk) in rays.chunks(MAX_BATCH).enumerate() {
            self.chunk::<FIRST>(chunk, &mut part, interleave)
                .map_err(|e| e.shift_ray(k * MAX_BATCH))?;
            hits.append(&mut part);
        }
        Ok(())
    }

    /// One ray traced on its own, for [`Tracer::batch`].
    fn one<const FIRST: bool>(&mut self, ray: &Ray) -> Result<Hit> {
        if FIRST {
            self.any(ray)
        } else {
            self.closest(ray)
        }
    }

    /// [`Tracer::batch`] for at most [`MAX_BATCH`] rays.
    fn chunk<const FIRST: bool>(
        &mut self,
        rays: &[Ray],
        hits: &mut Vec<Hit>,
        interleave: Interleave,
    ) -> Result<()> {
        hits.clear();
        let triangles = self
            .direct
            .as_ref()
            .is_some_and(|d| d.view.prim_kind == PrimKind::Triangles);
        let shared = interleave == Interleave::Auto && share_origins(rays);
        if !FIRST && triangles && (interleave == Interleave::Packets || shared) {
            return self.packets(rays, hits, interleave == Interleave::Auto);
        }
        let direct = self.direct.as_ref().filter(|d| {
            triangles
                && match interleave {
                    Interleave::Always => true,
                    Interleave::Never | Interleave::Packets => false,
                    Interleave::Auto => d.interleave && !shared,
                }
        });
        let Some(d) = direct else {
            if let (Some(d), true) = (&self.direct, rays.len() >= LOCAL_STACK_FROM) {
                hits.resize(rays.len(), Hit::MISS);
                return if shared {
                    d.trace_each::<FIRST, true>(rays, hits, 0)
                } else {
                    d.trace_each::<FIRST, false>(rays, hits, 0)
                };
            }
            hits.reserve(rays.len());
            for (i, r) in rays.iter().enumerate() {
                hits.push(self.one::<FIRST>(r).map_err(|e| e.in_ray(i))?);
            }
            return Ok(());
        };
        // (Written out of order below, every one exactly once.)
        hits.resize(rays.len(), Hit::MISS);
        let (view, inst) = (d.view, d.inst);
        // Rays by class (a permutation, or `ONE_BY_ONE`), in order within each: a counting sort.
        const ONE_BY_ONE: u8 = 6;
        let mut classes = std::mem::take(&mut self.classes);
        classes.clear();
        let mut starts = [0usize; ONE_BY_ONE as usize + 2];
        for (i, r) in rays.iter().enumerate() {
            r.validate().map_err(|e| e.in_ray(i))?;
            // (In a batch of closest hits, a ray with `TerminateOnFirstHit` goes one at a time,
            // through `Tracer::closest`, which honours the flag.)
            let c = d
                .common_permutation(r, !FIRST)
                .map_or(ONE_BY_ONE, |p| p as u8);
            classes.push(c);
            if let Some(n) = starts.get_mut(c as usize + 1) {
                *n += 1;
            }
        }
        for c in 1..starts.len() {
            starts[c] += starts[c - 1];
        }
        // (`starts[c]` is where class `c` begins.)
        let mut order = std::mem::take(&mut self.order);
        order.clear();
        order.resize(rays.len(), 0);
        let mut next = starts;
        for (i, &c) in classes.iter().enumerate() {
            if let Some(n) = next.get_mut(c as usize) {
                if let Some(o) = order.get_mut(*n) {
                    *o = i as u32;
                }
                *n += 1;
            }
        }
        let mut stacks = std::mem::take(&mut self.stacks);
        stacks.resize(interleaved::LANES, [Entry::default(); STACK_CAPACITY]);
        let flip = inst.flags & vk::GeometryInstanceFlagsKHR::TRIANGLE_FLIP_FACING.as_raw() != 0;
        if let Some(lanes) = stacks.first_chunk_mut::<{ interleaved::LANES }>() {
            for perm in 0..ONE_BY_ONE as usize {
                let group = order
                    .get(starts[perm]..starts[perm + 1])
                    .unwrap_or_default();
                if group.is_empty() {
                    continue;
                }
                by_permutation!(perm, P => match view.triangles {
                    Triangles::Direct(t) => interleaved::walk::<P, _, FIRST>(
                        &view, inst, t, flip, rays, group, lanes, hits,
                    ),
                    Triangles::Indexed(t) => interleaved::walk::<P, _, FIRST>(
                        &view, inst, t, flip, rays, group, lanes, hits,
                    ),
                });
            }
        }
        let rest = starts[ONE_BY_ONE as usize];
        self.classes = classes;
        self.stacks = stacks;
        for k in rest..order.len() {
            let i = order[k] as usize;
            if let (Some(r), Some(h)) = (rays.get(i), hits.get_mut(i)) {
                *h = self.one::<FIRST>(r).map_err(|e| e.in_ray(i))?;
            }
        }
        self.order = order;
        Ok(())
    }

    /// Closest hits of `rays` through the scene's only (identity) instance, a bottom level of
    /// triangles, in packets: runs of up to [`packet::PACKET`] consecutive rays of the common
    /// case (no culling or first-hit flags, the instance's mask met, a direction with a finite
    /// inverse) with one axis permutation, one origin and the same signs of direction
    /// ([`packet::share_a_walk`]), in the batch's order (a camera's rays next to each other are
    /// the coherent ones), or where the batch is a camera's rows, in blocks of pixels
    /// ([`tile::Blocks`]). A ray that reaches no child of the root is a miss, gathered in no
    /// packet. The other rays, and a packet's rays that met a tie, are traced one at a time.
    /// With `adapt`, once the batch's packets so far mostly fell apart before their leaves
    /// ([`fell_apart`]), its other rays are traced one at a time, and so are the next
    /// [`APART_FOR`] batches, unjudged; and a camera's rows go in blocks only after a batch
    /// whose packets held together but split often ([`Tracer::in_blocks`]).
    fn packets(&mut self, rays: &[Ray], hits: &mut Vec<Hit>, adapt: bool) -> Result<()> {
        // (Rows looked for only where blocks would be walked.)
        let blocks = !adapt || self.in_blocks;
        let Some(width) = blocks.then(|| tile::row_length(rays)).flatten() else {
            let in_order = Blocks::new(rays.len(), 0);
            return self.packets_in_order::<false>(rays, hits, adapt, in_order);
        };
        // A camera's rows: walked in blocks of pixels, read where they lie.
        let blocks = Blocks::new(rays.len(), width);
        self.packets_in_order::<true>(rays, hits, adapt, blocks)
            .map_err(|e| {
                // The first invalid ray in the batch's order, as its own order would find it.
                let mut each = rays.iter().enumerate();
                let first = each.find_map(|(i, r)| r.validate().err().map(|e| e.in_ray(i)));
                first.unwrap_or(e)
            })
    }

    /// [`Tracer::packets`], the rays gathered in the batch's order, or with `BLOCKS` in the
    /// order of `blocks`. (A constant, so that the batch's order keeps its plain loop.)
    fn packets_in_order<const BLOCKS: bool>(
        &mut self,
        rays: &[Ray],
        hits: &mut Vec<Hit>,
        adapt: bool,
        blocks: Blocks,
    ) -> Result<()> {
        hits.clear();
        hits.resize(rays.len(), Hit::MISS);
        if adapt && self.apart_for > 0 && rays.len() >= LOCAL_STACK_FROM {
            // The last judged batch's packets fell apart: not judged again for a while. (A
            // batch of a few rays goes in packets, not to make a stack for them.)
            self.apart_for -= 1;
            if let Some(d) = &self.direct {
                self.alone_after_judging += rays.len();
                return d.trace_each::<false, true>(rays, hits, 0);
            }
        }
        if rays.len() >= LOCAL_PACKETS_FROM {
            // On this thread's stack, at a fixed distance from the walk's own values (as the
            // one-ray walk's stack, `Direct::trace_each`): on the heap, how far the two lay
            // apart modulo 4 KiB moved primary rays by up to 23% from process to process.
            let mut work = Packets::new();
            return self.packets_in::<BLOCKS>(&mut work, rays, hits, adapt, blocks);
        }
        let mut work = self
            .packet_work
            .take()
            .unwrap_or_else(|| Box::new(Packets::new()));
        let result = self.packets_in::<BLOCKS>(&mut work, rays, hits, adapt, blocks);
        self.packet_work = Some(work);
        result
    }

    /// [`Tracer::packets_in_order`] in `work`, into `hits` (as long as `rays`).
    fn packets_in<const BLOCKS: bool>(
        &mut self,
        work: &mut Packets,
        rays: &[Ray],
        hits: &mut [Hit],
        adapt: bool,
        mut blocks: Blocks,
    ) -> Result<()> {
        let Some(d) = &self.direct else {
            return Ok(());
        };
        let (view, inst) = (d.view, d.inst);
        let flip = inst.flags & vk::GeometryInstanceFlagsKHR::TRIANGLE_FLIP_FACING.as_raw() != 0;
        let mut retraced = 0;
        let root = view.nodes.first();
        // Walks the packet gathered and empties it.
        let mut walk = |work: &mut Packets, hits: &mut [Hit]| {
            let perm = work.gathered().1;
            let walked = by_permutation!(perm, P => match view.triangles {
                Triangles::Direct(t) => packet::walk::<P, _>(&view, inst, t, flip, rays, work, hits),
                Triangles::Indexed(t) => packet::walk::<P, _>(&view, inst, t, flip, rays, work, hits),
            });
            // Which of two candidates at the same distance the packet found first depends
            // on its order; the ray's own walk decides.
            for r in packet::each(walked.tied) {
                let Some(&i) = work.gathered().0.get(r) else {
                    continue;
                };
                if let (Some(ray), Some(h)) = (rays.get(i as usize), hits.get_mut(i as usize)) {
                    *h = d.trace(work.single(), ray, false);
                    retraced += 1;
                }
            }
            work.clear();
            walked
        };
        let mut result = Ok(());
        // (How the batch's packets held together, counted until judged, and over the batch.)
        let mut so_far = Walked::default();
        let (mut whole, mut packets) = (Walked::default(), 0);
        let judge = adapt;
        let mut adapt = adapt;
        // Whether the batch's packets fell apart: in blocks, its other rays go one at a time
        // (in its order, they go to `Direct::trace_each`).
        let mut alone = false;
        let mut screen = Screened::default();
        let mut after_judging = 0;
        for p in 0..rays.len() {
            let i = if BLOCKS { blocks.index(p) } else { p };
            let bit = 1 << (p % screen::LANES);
            if bit == 1 {
                screen = match (BLOCKS, &d.root_box) {
                    (true, Some(b)) => blocks.screen(b, rays, p),
                    _ => d.screen(rays.get(p..).unwrap_or_default()),
                };
            }
            // (Always there: the blocks' indices lie in the batch.)
            let Some(r) = rays.get(i) else {
                break;
            };
            after_judging += usize::from(alone);
            if screen.plain & bit == 0
                && let Err(e) = r.validate()
            {
                result = Err(e.in_ray(i));
                break;
            }
            if screen.outside & bit != 0 {
                // (A miss, as the root's node test would find.)
                if let Some(h) = hits.get_mut(i) {
                    *h = Hit::MISS;
                }
                continue;
            }
            let mut gathered = packet::Gather::Alone;
            if !alone && d.common_flags(r, true) {
                let perm = permutation(r.direction);
                gathered = work.gather(i as u32, r, perm);
                if gathered == packet::Gather::Apart {
                    let walked = walk(work, hits);
                    whole.add(&walked);
                    packets += 1;
                    if adapt {
                        so_far.add(&walked);
                        if let Some(apart) = fell_apart(&so_far) {
                            adapt = false;
                            self.apart_for = if apart { APART_FOR } else { 0 };
                            if apart {
                                self.in_blocks = false;
                                if !BLOCKS {
                                    // The rest one at a time, from this ray, on the one-ray
                                    // walk's own stack (`Direct::trace_each`).
                                    let rest = (rays.get(i..), hits.get_mut(i..));
                                    if let (Some(rest), Some(rest_hits)) = rest {
                                        result = d.trace_each::<false, true>(rest, rest_hits, i);
                                        after_judging += rest.len();
                                    }
                                    break;
                                }
                                // This ray goes alone too (the count of the rays
                                // after it is taken as they come).
                                alone = true;
                                after_judging += 1;
                            }
                        }
                    }
                    // (An empty packet takes any ray with a finite inverse.)
                    gathered = if alone {
                        packet::Gather::Alone
                    } else {
                        work.gather(i as u32, r, perm)
                    };
                }
                if gathered == packet::Gather::Taken
                    && let Some(root) = root
                    && work.take_back_if_missing(root)
                {
                    if let Some(h) = hits.get_mut(i) {
                        *h = hit(&Best::miss(r.t_max), inst, Some(&view));
                    }
                    continue;
                }
            }
            if gathered != packet::Gather::Taken {
                // (Validated: traced at once, as `Tracer::closest` would.)
                let first_hit = r.flags.contains(RayFlags::TERMINATE_ON_FIRST_HIT);
                if let Some(h) = hits.get_mut(i) {
                    *h = d.trace(work.single(), r, first_hit);
                }
            }
        }
        if result.is_ok() && !work.gathered().0.is_empty() {
            whole.add(&walk(work, hits));
            packets += 1;
        }
        self.alone_after_judging += after_judging;
        if judge && result.is_ok() && self.apart_for == 0 {
            self.in_blocks = packet::split_often(&whole, packets);
        }
        work.clear();
        self.retraced += retraced;
        result
    }

    fn blas(&mut self, index: u32) -> Option<View<'s>> {
        if let Some((i, v)) = self.cached
            && i == index
        {
            return Some(v);
        }
        let v = self.scene.blas_view(index)?;
        self.cached = Some((index, v));
        Some(v)
    }

    fn trace(&mut self, ray: &Ray, first_hit: bool) -> Result<Hit> {
        ray.validate()?;
        if let Some(d) = &self.direct {
            let stack = self.stack.first_chunk_mut();
            return Ok(stack.map_or(Hit::MISS, |s| d.trace(s, ray, first_hit)));
        }
        let mut best = Best::miss(ray.t_max);
        let Some(tlas) = self.tlas else {
            return Ok(Hit::MISS);
        };
        if tlas.nodes.is_empty() {
            return Ok(Hit::MISS);
        }
        let mut world = World {
            ray,
            boxes: BoxRay::new(ray.origin, ray.direction),
            object: None,
        };
        // Disjoint borrows of the tracer's parts (the stack is borrowed for the whole trace).
        let stack = &mut self.stack[..];
        let scene = self.scene;
        let cached = &mut self.cached;
        let mut sp = 0;
        let mut cur = Entry {
            child: 0,
            count: 0,
            t: f32::NEG_INFINITY,
        };
        'top: loop {
            if cur.child & LEAF_BIT == 0 {
                if let Some(next) = descend::<ANY_AXES>(
                    stack,
                    &mut sp,
                    tlas.nodes,
                    NO_TRIANGLES,
                    cur.child,
                    &world.boxes,
                    ray.t_min,
                    best.t,
                ) {
                    cur = next;
                    continue;
                }
            } else {
                let first = cur.child & !LEAF_BIT;
                for slot in first..first + cur.count {
                    let found = enter(
                        scene, cached, &tlas, &mut world, slot, stack, sp, &mut best, first_hit,
                    );
                    if found && first_hit {
                        break 'top;
                    }
                }
            }
            match pop(stack, &mut sp, best.t) {
                Some(e) => cur = e,
                None => break,
            }
        }
        if best.kind == HitKind::Miss {
            return Ok(Hit::MISS);
        }
        let Some(inst) = tlas.instances.get(best.instance_slot as usize) else {
            return Ok(Hit::MISS);
        };
        let view = self.blas(best.blas);
        Ok(hit(&best, inst, view.as_ref()))
    }
}

/// The hit record of `best` (found in instance `inst`, whose bottom level is `view`).
#[inline(always)]
pub(super) fn hit(best: &Best, inst: &InstanceRecord, view: Option<&View>) -> Hit {
    if best.kind == HitKind::Miss {
        return Hit::MISS;
    }
    let id = view
        .and_then(|v| v.prim_ids.get(best.prim_slot as usize).copied())
        .unwrap_or(0);
    let (geometry_index, primitive_index) = view.map_or((0, 0), |v| v.locate(id));
    Hit {
        kind: best.kind,
        t: best.t,
        instance_id: inst.instance_id,
        instance_custom_index: inst.custom_index,
        geometry_index,
        primitive_index,
        barycentrics: best.barycentrics,
        front_face: best.front_face,
    }
}

/// The ray in world space and, made when first needed, in the current instance's space.
struct World<'r> {
    ray: &'r Ray,
    boxes: BoxRay,
    /// The ray in the space of the current instance, when it is not the world's.
    object: Option<BoxRay>,
}

/// Traverses the bottom level of instance `slot` on top of `stack` (entries above `sp`) when
/// the ray's mask and flags let it in, updating `best`. Returns whether it accepted a hit.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn enter<'s>(
    scene: &'s Scene,
    cached: &mut Option<(u32, View<'s>)>,
    tlas: &View<'s>,
    world: &mut World,
    slot: u32,
    stack: &mut [Entry],
    sp: usize,
    best: &mut Best,
    first_hit: bool,
) -> bool {
    let ray = world.ray;
    let Some(inst) = tlas.instances.get(slot as usize) else {
        return false;
    };
    if inst.mask & ray.cull_mask & 0xff == 0 {
        return false;
    }
    let Some(bi) = scene.instance_blas_index(slot) else {
        return false;
    };
    // By reference into the cache: a view is a dozen slices, not worth copying per instance.
    if cached.as_ref().is_none_or(|(i, _)| *i != bi) {
        *cached = scene.blas_view(bi).map(|v| (bi, v));
    }
    let Some((_, view)) = cached else {
        return false;
    };
    if ray.flags.skip(view.prim_kind) || view.nodes.is_empty() {
        return false;
    }
    // An identity instance sees the world ray: no transform, no new inverses, nothing copied.
    let local = if inst.hints & INSTANCE_IDENTITY != 0 {
        &world.boxes
    } else {
        let w2o = Affine::from_rows(inst.world_to_object);
        let (o, d) = (w2o.point(ray.origin), w2o.vector(ray.direction));
        &*world.object.insert(BoxRay::new(o, d))
    };
    let at = BlasAt { view, inst };
    // The walk starts on an empty stack of its own: the entries below are the top level's.
    let Some(free) = stack.get_mut(sp..).and_then(|s| s.first_chunk_mut()) else {
        return false;
    };
    let found = walk_blas(free, &at, local, ray, best, first_hit);
    if found {
        best.instance_slot = slot;
        best.blas = bi;
    }
    found
}

/// [`trace_blas`] for the axis permutation of the ray (`local`: in the instance's space).
/// The root's children are tested first: a ray that reaches none of them (most rays that miss
/// the structure) is done before it is prepared for triangles and the loop is entered.
#[inline(always)]
fn walk_blas(
    stack: &mut BlasStack,
    at: &BlasAt,
    local: &BoxRay,
    ray: &Ray,
    best: &mut Best,
    first_hit: bool,
) -> bool {
    let mut sp = 0;
    let view = at.view;
    let Some(cur) = descend::<ANY_AXES>(
        stack,
        &mut sp,
        view.nodes,
        view.triangles,
        0,
        local,
        ray.t_min,
        best.t,
    ) else {
        return false;
    };
    let walk = Walk { sp, cur };
    if first_hit {
        walk_layout::<true>(stack, walk, at, local, ray, best)
    } else {
        walk_layout::<false>(stack, walk, at, local, ray, best)
    }
}

/// [`trace_blas`] for the primitives and triangle layout of the bottom level.
#[inline(always)]
fn walk_layout<const FIRST: bool>(
    stack: &mut BlasStack,
    walk: Walk,
    at: &BlasAt,
    local: &BoxRay,
    ray: &Ray,
    best: &mut Best,
) -> bool {
    let view = at.view;
    if view.prim_kind != PrimKind::Triangles {
        // AABBs: no triangle test, so neither permutation nor triangle layout matters (and
        // one walk serves every ray).
        return trace_blas::<ANY_AXES, &[[f32; 9]], false, FIRST, false>(
            stack,
            walk,
            at,
            NO_TRIANGLES,
            local,
            ray,
            best,
        );
    }
    match view.triangles {
        Triangles::Direct(t) => walk_permuted::<_, FIRST>(stack, walk, at, t, local, ray, best),
        Triangles::Indexed(t) => walk_permuted::<_, FIRST>(stack, walk, at, t, local, ray, best),
    }
}

/// [`trace_blas`] for the axis permutation of the ray and the layout of the triangles.
#[inline(always)]
fn walk_permuted<T: LeafTriangles, const FIRST: bool>(
    stack: &mut BlasStack,
    walk: Walk,
    at: &BlasAt,
    tris: T,
    local: &BoxRay,
    ray: &Ray,
    best: &mut Best,
) -> bool {
    if !local.finite_inverse() {
        // A direction with a zero component (or one so small that its inverse overflows):
        // the general node test, and the permutation read at run time (rare rays).
        return trace_blas::<ANY_AXES, T, true, FIRST, false>(
            stack, walk, at, tris, local, ray, best,
        );
    }
    by_permutation!(permutation(local.direction()), P => {
        trace_blas::<P, T, true, FIRST, false>(stack, walk, at, tris, local, ray, best)
    })
}

/// A layout's triangles as the bottom-level loop tests them: direct ones in place, indexed
/// ones gathered one at a time as rows (see [`Indexed::leaf_rows`]). Both tests give the
/// same bits.
pub(super) trait LeafTriangles: TriangleSource {
    /// A triangle as the test reads it.
    type Tri;
    /// The `count` triangles from `first` (none when out of range).
    fn leaf(&self, first: usize, count: usize) -> impl Iterator<Item = impl Borrow<Self::Tri>>;
    /// [`ShearedRay::intersect_axes`] for a triangle of this layout (the ray's permutation
    /// read at run time for [`ANY_AXES`]).
    fn intersect<const P: usize>(ray: &ShearedRay, tri: &Self::Tri) -> Option<TriangleHit>;
    /// Leaves of at least this many triangles go to [`LeafTriangles::nearest`] (`u32::MAX`:
    /// none, and the bottom-level loop keeps no code for it).
    const NEAREST_FROM: u32 = u32::MAX;
    /// The hit that the loop over the `count` triangles from `first` would accept with no
    /// culling (the first in range `(t_min, t_max)` for `FIRST`, else the nearest, the
    /// earliest of equals), and its offset in the leaf.
    fn nearest<const P: usize, const FIRST: bool>(
        &self,
        _ray: &ShearedRay,
        _first: usize,
        _count: usize,
        _t_min: f32,
        _t_max: f32,
    ) -> Option<(u32, TriangleHit)> {
        None
    }
    /// A leaf of [`LeafTriangles::NEAREST_FROM`] to eight triangles as
    /// [`LeafTriangles::nearest`] reads it, made once for the rays of a packet.
    type Ready;
    /// The `count` triangles from `first` made ready (`None`: not made, or out of range).
    fn ready(&self, _first: usize, _count: usize) -> Option<Self::Ready> {
        None
    }
    /// [`LeafTriangles::nearest`] (closest hits) over the leaf made ready.
    fn nearest_ready<const P: usize>(
        &self,
        _leaf: &Self::Ready,
        _ray: &ShearedRay,
        _t_min: f32,
        _t_max: f32,
    ) -> Option<(u32, TriangleHit)> {
        None
    }
}

/// The triangles of leaf `first`, `count` tested by one ray with no culling, as the one-ray
/// walk tests them (`flip`: the instance flips facing), for the walks of several rays at once:
/// with `FIRST` up to the first accepted; with `TIES` (a packet's) a candidate at exactly the
/// hit's distance is noted ([`Best::ties`]) rather than decided. Returns whether one was
/// accepted.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(super) fn leaf<const P: usize, T: LeafTriangles, const FIRST: bool, const TIES: bool>(
    tris: T,
    flip: bool,
    sheared: &ShearedRay,
    t_min: f32,
    best: &mut Best,
    first: u32,
    count: u32,
) -> bool {
    if T::NEAREST_FROM != u32::MAX && count >= T::NEAREST_FROM {
        let bound = if TIES { best.tie_bound() } else { best.t };
        let found = tris.nearest::<P, FIRST>(sheared, first as usize, count as usize, t_min, bound);
        return take_nearest::<TIES>(best, found, first, flip);
    }
    let mut found = false;
    for (p, tri) in (first..).zip(tris.leaf(first as usize, count as usize)) {
        let Some(h) = T::intersect::<P>(sheared, tri.borrow()) else {
            continue;
        };
        if take::<TIES>(best, t_min, p, &h, flip) {
            found = true;
            if FIRST {
                break;
            }
        }
    }
    found
}

/// Takes the hit `found` of [`LeafTriangles::nearest`] in the leaf from triangle `first`
/// (searched below `best.t`, or with `TIES` below [`Best::tie_bound`]) as `best`, as
/// [`take`] does: whether it was taken.
#[inline(always)]
pub(super) fn take_nearest<const TIES: bool>(
    best: &mut Best,
    found: Option<(u32, TriangleHit)>,
    first: u32,
    flip: bool,
) -> bool {
    let Some((k, h)) = found else {
        return false;
    };
    if TIES && best.ties(h.t) {
        return false;
    }
    best.accept_triangle(first + k, &h, h.front_face != flip);
    true
}

/// Takes hit `h` on triangle `p` (of an instance that flips facing where `flip`) as `best`
/// where it lies in range and nearer, with no culling: whether it was taken. With `TIES` a
/// candidate at exactly the hit's distance is noted ([`Best::ties`]), not taken.
#[inline(always)]
pub(super) fn take<const TIES: bool>(
    best: &mut Best,
    t_min: f32,
    p: u32,
    h: &TriangleHit,
    flip: bool,
) -> bool {
    let bound = if TIES { best.tie_bound() } else { best.t };
    if h.t > t_min && h.t < bound && !(TIES && best.ties(h.t)) {
        best.accept_triangle(p, h, h.front_face != flip);
        return true;
    }
    false
}

/// The loop of [`LeafTriangles::nearest`] over `tris` one at a time (offsets from `base`).
#[inline(always)]
fn nearest_one_by_one<const P: usize, const FIRST: bool>(
    ray: &ShearedRay,
    tris: &[[f32; 9]],
    base: u32,
    t_min: f32,
    t_max: &mut f32,
    best: &mut Option<(u32, TriangleHit)>,
) {
    for (k, tri) in (base..).zip(tris) {
        if let Some(h) = ray.intersect_axes::<P>(tri)
            && h.t > t_min
            && h.t < *t_max
        {
            *t_max = h.t;
            *best = Some((k, h));
            if FIRST {
                return;
            }
        }
    }
}

impl LeafTriangles for &[[f32; 9]] {
    type Tri = [f32; 9];
    #[inline(always)]
    fn leaf(&self, first: usize, count: usize) -> impl Iterator<Item = impl Borrow<[f32; 9]>> {
        self.get(first..first + count).unwrap_or_default().iter()
    }
    #[inline(always)]
    fn intersect<const P: usize>(ray: &ShearedRay, tri: &[f32; 9]) -> Option<TriangleHit> {
        if P < ANY_AXES {
            ray.intersect_axes::<P>(tri)
        } else {
            ray.intersect(tri)
        }
    }

    /// From three triangles, where the eight-lane test has AVX (measured under callgrind on
    /// the soup's incoherent rays: 2 and 4 cost more instructions; without AVX the transpose
    /// and the two-half vectors cost more than the loop saves: +6%).
    const NEAREST_FROM: u32 = if cfg!(target_feature = "avx") {
        3
    } else {
        u32::MAX
    };

    /// Eight triangles at a time ([`Chunk8`], [`ShearedRay::edges8`], then
    /// [`Edges8::hits`](super::triangle::Edges8::hits) for a chunk with a covered lane). A
    /// chunk with an edge function exactly zero in one of its lanes is tested one triangle at
    /// a time.
    #[inline(always)]
    fn nearest<const P: usize, const FIRST: bool>(
        &self,
        ray: &ShearedRay,
        first: usize,
        count: usize,
        t_min: f32,
        t_max: f32,
    ) -> Option<(u32, TriangleHit)> {
        let mut t_max = t_max;
        let mut best = None;
        let mut base = 0;
        while base < count {
            let n = (count - base).min(8);
            let chunk = Chunk8::new(self, first + base, n)?;
            chunk.nearest::<P, FIRST>(self, ray, base as u32, t_min, &mut t_max, &mut best)?;
            if FIRST && best.is_some() {
                return best;
            }
            base += 8;
        }
        best
    }

    type Ready = Chunk8;
    #[inline(always)]
    fn ready(&self, first: usize, count: usize) -> Option<Chunk8> {
        (1..=8)
            .contains(&count)
            .then(|| Chunk8::new(self, first, count))?
    }
    #[inline(always)]
    fn nearest_ready<const P: usize>(
        &self,
        leaf: &Chunk8,
        ray: &ShearedRay,
        t_min: f32,
        t_max: f32,
    ) -> Option<(u32, TriangleHit)> {
        let (mut t_max, mut best) = (t_max, None);
        leaf.nearest::<P, false>(self, ray, 0, t_min, &mut t_max, &mut best)?;
        best
    }
}

/// Up to eight direct triangles from slot `at` as the eight-lane test reads them: each
/// triangle's first eight floats are one load and one 8x8 transpose makes them rows. Lanes
/// past the `n` triangles repeat the last, whose copies can never be accepted before it; the
/// eight slots from `at` are bounds-checked at once (a chunk at the end of the triangles is
/// copied and padded).
pub(super) struct Chunk8 {
    rows: [f32x8; 9],
    at: usize,
    n: usize,
}

impl Chunk8 {
    #[inline(always)]
    fn new(tris: &[[f32; 9]], at: usize, n: usize) -> Option<Chunk8> {
        let padded;
        let window: &[[f32; 9]; 8] = match tris.get(at..at + 8).and_then(|w| w.try_into().ok()) {
            Some(w) => w,
            None => {
                padded = pad8(tris.get(at..at + n)?);
                &padded
            }
        };
        // Lanes past the leaf repeat its last triangle, so that no load leaves the leaf's
        // lines: reading the next leaves' slots took 6% fewer instructions but up to three
        // more lines per leaf (the same speed on one thread on the Xeon; traffic that all
        // threads tracing at once would share).
        let tri = |j: usize| &window[(if j < n { j } else { n - 1 }) & 7];
        let head: [f32x8; 8] = std::array::from_fn(|j| {
            let h: [f32; 8] = bytemuck::cast_slice::<f32, [f32; 8]>(&tri(j)[..8])[0];
            f32x8::from(h)
        });
        let [r0, r1, r2, r3, r4, r5, r6, r7] = f32x8::transpose(head);
        let r8 = f32x8::from(std::array::from_fn::<f32, 8, _>(|j| tri(j)[8]));
        Some(Chunk8 {
            rows: [r0, r1, r2, r3, r4, r5, r6, r7, r8],
            at,
            n,
        })
    }

    /// The chunk's part of [`LeafTriangles::nearest`] for `ray` (of the triangles `tris`),
    /// offsets from `k`: `best` and `t_max` updated where it holds a hit in range nearer than
    /// `t_max`. `None` where the chunk lies out of range.
    #[inline(always)]
    fn nearest<const P: usize, const FIRST: bool>(
        &self,
        tris: &[[f32; 9]],
        ray: &ShearedRay,
        k: u32,
        t_min: f32,
        t_max: &mut f32,
        best: &mut Option<(u32, TriangleHit)>,
    ) -> Option<()> {
        let (at, n) = (self.at, self.n);
        let lanes = (1u32 << n) - 1;
        let edges = ray.edges8::<P>(&self.rows);
        if edges.edge & lanes != 0 {
            let chunk = tris.get(at..at + n)?;
            nearest_one_by_one::<P, FIRST>(ray, chunk, k, t_min, t_max, best);
            return Some(());
        }
        if edges.covered & lanes == 0 {
            return Some(());
        }
        let hits = edges.hits(ray);
        let t = hits.t;
        let range = t.simd_gt(f32x8::splat(t_min)) & t.simd_lt(f32x8::splat(*t_max));
        let in_range = hits.hit & lanes & range.to_bitmask();
        if in_range == 0 {
            return Some(());
        }
        let lane = if FIRST {
            in_range.trailing_zeros()
        } else {
            // The least `t` among the lanes in range, its first lane on a tie.
            let ts = t.to_array();
            let mut m = in_range & (in_range - 1);
            let mut lane = in_range.trailing_zeros();
            while m != 0 {
                let j = m.trailing_zeros();
                if ts[j as usize & 7] < ts[lane as usize & 7] {
                    lane = j;
                }
                m &= m - 1;
            }
            lane
        };
        let h = hits.lane(lane as usize);
        *t_max = h.t;
        *best = Some((k + lane, h));
        Some(())
    }
}

/// The `1..=8` triangles of `tris` followed by copies of the last, for a chunk at the end of
/// a structure's triangles.
#[cold]
#[inline(never)]
fn pad8(tris: &[[f32; 9]]) -> [[f32; 9]; 8] {
    let last = tris.last().copied().unwrap_or([f32::NAN; 9]);
    std::array::from_fn(|j| tris.get(j).copied().unwrap_or(last))
}

impl LeafTriangles for Indexed<'_> {
    type Tri = [f32; 12];
    type Ready = ();
    #[inline(always)]
    fn leaf(&self, first: usize, count: usize) -> impl Iterator<Item = impl Borrow<[f32; 12]>> {
        self.leaf_rows(first, count)
    }
    #[inline(always)]
    fn intersect<const P: usize>(ray: &ShearedRay, tri: &[f32; 12]) -> Option<TriangleHit> {
        if P < ANY_AXES {
            ray.intersect_rows::<P>(tri)
        } else {
            ray.intersect_rows_any(tri)
        }
    }
}

/// Where a bottom-level walk stands: its entries lie below `sp` (the stack is its own), and
/// `cur` is the child to visit next.
#[derive(Clone, Copy)]
pub(super) struct Walk {
    pub sp: usize,
    pub cur: Entry,
}

/// Pops the nearest entry below `sp` that may still hold a hit nearer than `t_max`.
#[inline(always)]
pub(super) fn pop(stack: &[Entry], sp: &mut usize, t_max: f32) -> Option<Entry> {
    while *sp > 0 {
        *sp -= 1;
        let e = stack.get(*sp)?;
        if e.t <= prune_limit(t_max) {
            return Some(*e);
        }
    }
    None
}

/// The ray flags that cull candidates.
const CULLING: RayFlags = RayFlags(
    RayFlags::CULL_BACK_FACING_TRIANGLES.0
        | RayFlags::CULL_FRONT_FACING_TRIANGLES.0
        | RayFlags::CULL_OPAQUE.0
        | RayFlags::CULL_NO_OPAQUE.0,
);

/// Whether a ray with `flags` culls the candidate in stored slot `prim_slot` of `view` (in
/// instance `inst`): by facing (`front`, after `FLIP_FACING`; `None` for an AABB) or by
/// opacity.
#[cold]
#[inline(never)]
fn culled(
    view: &View,
    inst: &InstanceRecord,
    flags: RayFlags,
    prim_slot: u32,
    front: Option<bool>,
) -> bool {
    let iflags = vk::GeometryInstanceFlagsKHR::from_raw(inst.flags);
    if let Some(front) = front
        && !iflags.contains(vk::GeometryInstanceFlagsKHR::TRIANGLE_FACING_CULL_DISABLE)
    {
        let rule = if front {
            RayFlags::CULL_FRONT_FACING_TRIANGLES
        } else {
            RayFlags::CULL_BACK_FACING_TRIANGLES
        };
        if flags.contains(rule) {
            return true;
        }
    }
    if !flags.intersects(RayFlags::CULL_OPAQUE | RayFlags::CULL_NO_OPAQUE) {
        return false;
    }
    let id = view.prim_ids.get(prim_slot as usize).copied().unwrap_or(0);
    let (g, _) = view.locate(id);
    opacity_culled(resolve_opacity(view, g, inst, flags), flags)
}

/// The instance whose bottom-level structure is traversed. (Which instance and which bottom
/// level it is, the hit's caller records: the walk keeps two registers fewer.)
pub(super) struct BlasAt<'a, 's> {
    pub view: &'a View<'s>,
    pub inst: &'a InstanceRecord,
}

/// Continues the walk of one instance's bottom-level structure (its entries on `stack` below
/// `walk.sp`), updating `best`. Returns whether it accepted a hit. Instantiated per axis
/// permutation `P` of the ray (`permutation(boxes.direction()) == P`, for a ray with a finite
/// inverse), so that preparing the ray for the triangle test and the test itself index
/// nothing at run time, and the node test reads the dominant axis's planes at constant
/// offsets and works with integer minima, maxima and compare; for other rays with `P`
/// [`ANY_AXES`] (the general node test, the permutation read at run time); and apart for a
/// structure of AABBs (`TRIANGLES` false, `P` [`ANY_AXES`], `T` unused), so that neither loop
/// holds what only the other needs. With `TIES` (a packet's ray walking a subtree alone,
/// closest hits of triangles), a triangle at exactly the hit's distance is noted
/// ([`Best::ties`]) rather than decided, so that the ray can be traced again on its own; the
/// other walks are instantiated without it and keep their code. Not inlined: the bottom-level
/// loop is the hot one and gets the registers to itself.
#[inline(never)]
pub(super) fn trace_blas<
    const P: usize,
    T: LeafTriangles,
    const TRIANGLES: bool,
    const FIRST: bool,
    const TIES: bool,
>(
    stack: &mut BlasStack,
    walk: Walk,
    at: &BlasAt,
    tris: T,
    boxes: &BoxRay,
    ray: &Ray,
    best: &mut Best,
) -> bool {
    let BlasAt { view, inst } = *at;
    let sheared = boxes.sheared::<P>();
    let flags = ray.flags;
    let flip = inst.flags & vk::GeometryInstanceFlagsKHR::TRIANGLE_FLIP_FACING.as_raw() != 0;
    // Culling by facing or opacity only applies when the ray asks for it (rarely): the common
    // case tests one flag per hit, and the rules are worked out apart.
    let culls = flags.intersects(CULLING);
    let Walk { mut sp, mut cur } = walk;
    let mut found = false;
    loop {
        if cur.child & LEAF_BIT == 0 {
            if let Some(next) = descend::<P>(
                stack, &mut sp, view.nodes, tris, cur.child, boxes, ray.t_min, best.t,
            ) {
                cur = next;
                continue;
            }
            match pop(stack, &mut sp, best.t) {
                Some(e) => {
                    cur = e;
                    continue;
                }
                None => return found,
            }
        }
        let first = cur.child & !LEAF_BIT;
        let range = first as usize..first as usize + cur.count as usize;
        // (The first three terms are constants: a walk without a wide test keeps no code for it.)
        if TRIANGLES
            && P < ANY_AXES
            && T::NEAREST_FROM != u32::MAX
            && !culls
            && cur.count >= T::NEAREST_FROM
        {
            let bound = if TIES { best.tie_bound() } else { best.t };
            if let Some((k, h)) = tris.nearest::<P, FIRST>(
                &sheared,
                first as usize,
                cur.count as usize,
                ray.t_min,
                bound,
            ) && !(TIES && best.ties(h.t))
            {
                best.accept_triangle(first + k, &h, h.front_face != flip);
                found = true;
                if FIRST {
                    return true;
                }
            }
        } else if TRIANGLES {
            for (p, tri) in (first..).zip(tris.leaf(first as usize, cur.count as usize)) {
                let Some(h) = T::intersect::<P>(&sheared, tri.borrow()) else {
                    continue;
                };
                let bound = if TIES { best.tie_bound() } else { best.t };
                if !(h.t > ray.t_min && h.t < bound) || (TIES && best.ties(h.t)) {
                    continue;
                }
                let front = h.front_face != flip;
                if culls && culled(view, inst, flags, p, Some(front)) {
                    continue;
                }
                best.accept_triangle(p, &h, front);
                found = true;
                if FIRST {
                    return true;
                }
            }
        } else {
            for (p, b) in (first..).zip(view.aabbs.get(range).unwrap_or_default()) {
                let Some(t) = boxes.aabb(b, ray.t_min, best.t) else {
                    continue;
                };
                if culls && culled(view, inst, flags, p, None) {
                    continue;
                }
                best.t = t;
                best.kind = HitKind::Generated;
                best.prim_slot = p;
                best.barycentrics = [0.0; 2];
                best.front_face = false;
                found = true;
                if FIRST {
                    return true;
                }
            }
        }
        match pop(stack, &mut sp, best.t) {
            Some(e) => cur = e,
            None => return found,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// A fast-trace scene of one identity instance of `positions` and `indices`.
    fn scene_of(device: &crate::Device, positions: &[[f32; 3]], indices: &[[u32; 3]]) -> Scene {
        let flags = vk::BuildAccelerationStructureFlagsKHR::PREFER_FAST_TRACE;
        let blas = crate::quick::build_triangle_blas(device, positions, indices, flags).unwrap();
        let tlas = crate::quick::build_single_instance_tlas(device, blas).unwrap();
        device.scene(tlas).unwrap()
    }

    /// A packet notes the rays that meet a candidate at exactly their hit's distance, and
    /// only those are traced again on their own: two copies of one triangle (a leaf of two,
    /// tested one triangle at a time: every hit on it ties), eight rays from one point at it
    /// and eight beside it (no hit, no tie), walked as packets.
    #[test]
    fn packets_retrace_exactly_the_rays_that_meet_a_tie() {
        let tri = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let positions: Vec<[f32; 3]> = [tri, tri].concat();
        let indices = [[0, 1, 2], [3, 4, 5]];
        let device = crate::Device::new();
        let scene = scene_of(&device, &positions, &indices);
        let origin = [0.5, 0.5, 4.0];
        let rays: Vec<Ray> = [0.0f32, 3.0]
            .iter()
            .flat_map(|&x| {
                (0..8).map(move |k| {
                    let at = [x + 0.1 + 0.05 * k as f32, 0.2, 0.0];
                    Ray::new(origin, std::array::from_fn(|i| at[i] - origin[i]))
                })
            })
            .collect();
        let mut tracer = Tracer::new(&scene);
        let mut hits = Vec::new();
        tracer
            .closest_batch_with(&rays, &mut hits, Interleave::Packets)
            .unwrap();
        assert_eq!(tracer.retraced, 8);
        for (k, (ray, hit)) in rays.iter().zip(&hits).enumerate() {
            assert_eq!(hit.is_hit(), k < 8);
            assert_eq!(*hit, scene.trace_closest(ray).unwrap());
        }
    }

    /// Under `Interleave::Auto`, a batch whose first packets fell apart before their leaves (a
    /// grid of triangles finer than the rays' spacing) traces its other rays one at a time, and
    /// one whose packets reach the leaves together (two large triangles) keeps its packets;
    /// `Interleave::Packets` keeps them always. Every hit is the one `Tracer::closest` gives.
    #[test]
    fn a_batch_whose_packets_fall_apart_goes_one_ray_at_a_time() {
        let quad = |n: usize| {
            let positions: Vec<[f32; 3]> = (0..=n)
                .flat_map(|y| (0..=n).map(move |x| [x as f32 / n as f32, y as f32 / n as f32, 0.0]))
                .collect();
            let at = |x: usize, y: usize| (y * (n + 1) + x) as u32;
            let indices: Vec<[u32; 3]> = (0..n * n)
                .flat_map(|k| {
                    let (x, y) = (k % n, k / n);
                    [
                        [at(x, y), at(x + 1, y), at(x, y + 1)],
                        [at(x + 1, y), at(x + 1, y + 1), at(x, y + 1)],
                    ]
                })
                .collect();
            (positions, indices)
        };
        // A 32 x 32 image of the square [0, 1]^2, from above.
        let origin = [0.5, 0.5, 4.0];
        let rays: Vec<Ray> = (0..32 * 32)
            .map(|k| {
                let at = [
                    0.01 + 0.98 * (k % 32) as f32 / 31.0,
                    0.01 + 0.98 * (k / 32) as f32 / 31.0,
                    0.0,
                ];
                Ray::new(origin, std::array::from_fn(|i| at[i] - origin[i]))
            })
            .collect();
        let device = crate::Device::new();
        // Cells of 1/128 (rays about 1/32 apart), then one cell.
        for (n, mode, apart) in [
            (128, Interleave::Auto, true),
            (128, Interleave::Packets, false),
            (1, Interleave::Auto, false),
        ] {
            let (positions, indices) = quad(n);
            let scene = scene_of(&device, &positions, &indices);
            let mut tracer = Tracer::new(&scene);
            let mut hits = Vec::new();
            tracer.closest_batch_with(&rays, &mut hits, mode).unwrap();
            let what = format!(
                "{n} cells a side, {mode:?}: {} after",
                tracer.alone_after_judging
            );
            if apart {
                assert!(tracer.alone_after_judging > rays.len() * 3 / 4, "{what}");
                assert_eq!(tracer.apart_for, APART_FOR);
            } else {
                assert_eq!(tracer.alone_after_judging, 0, "{what}");
            }
            // The next `APART_FOR` batches go one at a time, unjudged; the one after is judged
            // again.
            let mut again = Vec::new();
            for k in 0..=APART_FOR {
                let before = tracer.alone_after_judging;
                tracer.closest_batch_with(&rays, &mut again, mode).unwrap();
                assert_eq!(again, hits);
                let alone = tracer.alone_after_judging - before;
                match (apart, k < APART_FOR) {
                    (false, _) => assert_eq!(alone, 0, "{what}, batch {k}"),
                    (true, true) => assert_eq!(alone, rays.len(), "{what}, batch {k}"),
                    (true, false) => {
                        assert!(alone > rays.len() * 3 / 4 && alone < rays.len(), "{what}");
                        assert_eq!(tracer.apart_for, APART_FOR);
                    }
                }
            }
            let mut hit_count = 0;
            for (ray, hit) in rays.iter().zip(&hits) {
                assert_eq!(*hit, scene.trace_closest(ray).unwrap());
                hit_count += usize::from(hit.is_hit());
            }
            assert_eq!(hit_count, rays.len());
        }
        // In blocks (as after a batch whose packets split often), the rest of a batch whose
        // packets fall apart goes one at a time too, in the blocks' order.
        assert_eq!(tile::row_length(&rays), Some(32));
        let (positions, indices) = quad(128);
        let scene = scene_of(&device, &positions, &indices);
        let mut tracer = Tracer::new(&scene);
        tracer.in_blocks = true;
        let mut hits = Vec::new();
        tracer.closest_batch(&rays, &mut hits).unwrap();
        let alone = tracer.alone_after_judging;
        assert!(
            alone > rays.len() * 3 / 4 && alone < rays.len(),
            "{alone} after"
        );
        assert!(!tracer.in_blocks);
        assert_eq!(tracer.apart_for, APART_FOR);
        for (ray, hit) in rays.iter().zip(&hits) {
            assert_eq!(*hit, scene.trace_closest(ray).unwrap());
        }
    }

    /// Under `Interleave::Auto`, a camera's batch over a soup of small random triangles (whose
    /// packets reach their leaves together but split often on the way) sends the camera's next
    /// batch in blocks of pixels; over one large quad (packets that never split), in rows.
    /// Either way every hit is the one `Tracer::closest` gives.
    #[test]
    fn a_camera_whose_packets_split_often_goes_in_blocks() {
        let device = crate::Device::new();
        let mut rng = rand_pcg::Pcg64::seed_from_u64(7);
        let soup: Vec<[f32; 3]> = (0..20_000)
            .flat_map(|_| {
                let c: [f32; 3] = std::array::from_fn(|_| rng.gen_range(0.0f32..1.0));
                let corners: [[f32; 3]; 3] = std::array::from_fn(|_| {
                    std::array::from_fn(|k| c[k] + rng.gen_range(-0.02..0.02))
                });
                corners
            })
            .collect();
        let quad = vec![
            [0.0, 0.0, 0.5],
            [1.0, 0.0, 0.5],
            [0.0, 1.0, 0.5],
            [1.0, 1.0, 0.5],
        ];
        // A 64 x 64 image of the unit square, row by row.
        let w = 64;
        let origin = [0.5, 0.5, 3.0];
        let rays: Vec<Ray> = (0..w * w)
            .map(|k| {
                let at = [
                    (k % w) as f32 / w as f32,
                    1.0 - (k / w) as f32 / w as f32,
                    0.5,
                ];
                Ray::new(origin, std::array::from_fn(|i| at[i] - origin[i]))
            })
            .collect();
        let soup_indices: Vec<[u32; 3]> = (0..soup.len() as u32 / 3)
            .map(|t| [3 * t, 3 * t + 1, 3 * t + 2])
            .collect();
        let quad_indices = vec![[0, 1, 2], [1, 3, 2]];
        for (positions, indices, blocks) in
            [(soup, soup_indices, true), (quad, quad_indices, false)]
        {
            let scene = scene_of(&device, &positions, &indices);
            let mut tracer = Tracer::new(&scene);
            let mut hits = Vec::new();
            assert!(!tracer.in_blocks);
            tracer
                .closest_batch_with(&rays, &mut hits, Interleave::Auto)
                .unwrap();
            assert_eq!(tracer.in_blocks, blocks, "{} triangles", indices.len());
            assert_eq!(tracer.apart_for, 0);
            // The next batch, in blocks where judged so, and judged again.
            let mut again = Vec::new();
            tracer
                .closest_batch_with(&rays, &mut again, Interleave::Auto)
                .unwrap();
            assert_eq!(tracer.in_blocks, blocks, "{} triangles", indices.len());
            assert_eq!(again, hits);
            let mut hit_count = 0;
            for (ray, hit) in rays.iter().zip(&hits) {
                assert_eq!(*hit, scene.trace_closest(ray).unwrap());
                hit_count += usize::from(hit.is_hit());
            }
            assert!(hit_count > rays.len() / 2, "{hit_count} hits");
        }
    }

    /// `nearest` over `tris[first..first + count]` for the ray's permutation, and the loop over
    /// the same triangles one at a time.
    fn both<const FIRST: bool>(
        ray: &ShearedRay,
        tris: &[[f32; 9]],
        first: usize,
        count: usize,
        t_max: f32,
    ) -> [Option<(u32, TriangleHit)>; 2] {
        macro_rules! per_axes {
            ($($p:literal)*) => {
                match ray.perm {
                    $($p => {
                        let wide = tris.nearest::<$p, FIRST>(ray, first, count, 0.0, t_max);
                        let mut one = None;
                        let mut t = t_max;
                        let leaf = &tris[first..first + count];
                        nearest_one_by_one::<$p, FIRST>(ray, leaf, 0, 0.0, &mut t, &mut one);
                        [wide, one]
                    })*
                    _ => unreachable!(),
                }
            };
        }
        per_axes!(0 1 2 3 4 5)
    }

    fn bits(h: Option<(u32, TriangleHit)>) -> Option<(u32, [u32; 3], bool)> {
        h.map(|(k, h)| (k, [h.t, h.b, h.c].map(f32::to_bits), h.front_face))
    }

    /// The eight-wide leaf test accepts the same triangle with the same bits as the loop it
    /// replaces: on a coarse grid (rays through edges and vertices, coplanar ties, zero areas,
    /// duplicates) and on random floats, for leaves of 3 to 12 triangles anywhere in the
    /// array (at its end too, where a chunk is padded), closest hit and first hit.
    #[test]
    fn eight_wide_leaves_accept_what_the_loop_accepts() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(0x1eaf8);
        let mut accepted = 0;
        for round in 0..1000 {
            let grid = round % 2 == 0;
            let coord = |rng: &mut rand_pcg::Pcg64| {
                if grid {
                    rng.gen_range(-2i32..=2) as f32 * 0.5
                } else {
                    rng.gen_range(-2.0f32..2.0)
                }
            };
            let n = rng.gen_range(3..40usize);
            let mut tris: Vec<[f32; 9]> = (0..n)
                .map(|_| std::array::from_fn(|_| coord(&mut rng)))
                .collect();
            // Duplicates, so that equal `t` on different slots occur.
            for _ in 0..n / 4 {
                let (a, b) = (rng.gen_range(0..n), rng.gen_range(0..n));
                tris[b] = tris[a];
            }
            for _ in 0..50 {
                let o = [0, 1, 2].map(|_| coord(&mut rng) + 3.0 * f32::from(grid));
                let d: [f32; 3] = if grid {
                    [0, 1, 2].map(|_| rng.gen_range(-2i32..=2) as f32)
                } else {
                    [0, 1, 2].map(|_| rng.gen_range(-1.0f32..1.0))
                };
                if d == [0.0; 3] {
                    continue;
                }
                let ray = ShearedRay::new(o, d);
                let first = rng.gen_range(0..n - 2);
                let count = rng.gen_range(3..=12usize).min(n - first);
                let t_max = if rng.gen_bool(0.3) {
                    2.5
                } else {
                    f32::INFINITY
                };
                let [wide, one] = both::<false>(&ray, &tris, first, count, t_max);
                assert_eq!(bits(wide), bits(one), "closest, round {round}");
                let [wide, one] = both::<true>(&ray, &tris, first, count, t_max);
                assert_eq!(bits(wide), bits(one), "first, round {round}");
                accepted += usize::from(one.is_some());
            }
        }
        // The scenes must exercise hits, not only misses.
        assert!(accepted > 3000, "{accepted} hits");
    }
}
