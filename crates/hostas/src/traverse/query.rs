//! The ray-query state machine and the traversal loop behind it.
//!
//! Traversal is an explicit, resumable loop: `proceed` runs until it meets a candidate the
//! application must decide on (a non-opaque triangle or any AABB), returns `true` with the
//! state kept in the query, and continues from there on the next call. Opaque triangles are
//! committed inside `proceed`, as the spec says. The stacks have a fixed capacity derived from
//! the layout's depth bound.

use super::scene::Scene;
use super::triangle::{AXES, ShearedRay};
use super::{Ray, RayFlags};
use crate::error::{Error, Location, Result};
use crate::layout::triangles::TriangleSource;
use crate::layout::view::View;
use crate::layout::{
    HEADER_ALL_OPAQUE, HEADER_NONE_OPAQUE, InstanceRecord, LEAF_BIT, MAX_DEPTH, Node, PrimKind,
    WIDTH,
};
use crate::math::{Affine, INTEGER_MIN_MAX, Vec3, fmax, fmax8, fmin, fmin8, imax8, imin8, lanes};
use ash::vk;
use wide::{f32x4, f32x8, i32x8, u32x8};

/// `RayQueryCommittedIntersectionTypeKHR`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u32)]
pub enum CommittedType {
    None = 0,
    Triangle = 1,
    Generated = 2,
}

/// `RayQueryCandidateIntersectionTypeKHR`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u32)]
pub enum CandidateType {
    Triangle = 0,
    Aabb = 1,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    None,
    Triangle,
    Aabb,
    Generated,
}

/// One intersection: a candidate or the committed one, with everything the getters return.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Intersection {
    kind: Kind,
    /// Hit distance (triangles, generated hits). For an AABB candidate, the distance at which
    /// the ray enters the box (clamped to tMin): a hint, the spec leaves it undefined.
    pub t: f32,
    /// `InstanceId`: index in the instance array, inactive instances counted.
    pub instance_id: u32,
    pub instance_custom_index: u32,
    pub sbt_record_offset: u32,
    pub geometry_index: u32,
    /// `PrimitiveId`: index within the geometry's range, inactive primitives counted.
    pub primitive_index: u32,
    /// Weights of vertices 1 and 2 (triangles).
    pub barycentrics: [f32; 2],
    pub front_face: bool,
    /// The opacity decided for this candidate (`OpRayQueryGetIntersectionCandidateAABBOpaqueKHR`).
    pub opaque: bool,
    instance_slot: u32,
    prim_slot: u32,
}

impl Intersection {
    const NONE: Intersection = Intersection {
        kind: Kind::None,
        t: 0.0,
        instance_id: 0,
        instance_custom_index: 0,
        sbt_record_offset: 0,
        geometry_index: 0,
        primitive_index: 0,
        barycentrics: [0.0; 2],
        front_face: false,
        opaque: false,
        instance_slot: 0,
        prim_slot: 0,
    };
    pub fn committed_type(&self) -> CommittedType {
        match self.kind {
            Kind::Triangle => CommittedType::Triangle,
            Kind::Generated => CommittedType::Generated,
            _ => CommittedType::None,
        }
    }
    pub fn candidate_type(&self) -> Option<CandidateType> {
        match self.kind {
            Kind::Triangle => Some(CandidateType::Triangle),
            Kind::Aabb => Some(CandidateType::Aabb),
            _ => None,
        }
    }
}

pub(super) const STACK_CAPACITY: usize = (WIDTH - 1) * MAX_DEPTH as usize + WIDTH;

/// Sixteen bytes (aligned): an entry is addressed by a shift and copied whole.
#[derive(Clone, Copy, Default)]
#[repr(align(16))]
pub(super) struct Entry {
    pub child: u32,
    pub count: u32,
    pub t: f32,
}

struct Stack {
    items: [Entry; STACK_CAPACITY],
    len: usize,
}

thread_local! {
    /// Stacks of finished queries, reused so that a query allocates nothing.
    static STACK_POOL: std::cell::RefCell<Vec<Box<Stack>>> = const { std::cell::RefCell::new(Vec::new()) };
}

impl Stack {
    fn new() -> Box<Stack> {
        STACK_POOL
            .with(|p| p.borrow_mut().pop())
            .unwrap_or_else(|| {
                Box::new(Stack {
                    items: [Entry::default(); STACK_CAPACITY],
                    len: 0,
                })
            })
    }
    fn recycle(self: Box<Stack>) {
        STACK_POOL.with(|p| {
            let mut p = p.borrow_mut();
            if p.len() < 8 {
                p.push(self);
            }
        });
    }
    #[inline(always)]
    fn push(&mut self, e: Entry) {
        // Cannot overflow on a validated view (depth <= MAX_DEPTH); drop rather than panic.
        if let Some(slot) = self.items.get_mut(self.len) {
            *slot = e;
            self.len += 1;
        }
    }
    #[inline(always)]
    fn pop(&mut self) -> Option<Entry> {
        if self.len == 0 {
            return None;
        }
        self.len -= 1;
        Some(self.items[self.len])
    }
}

/// 1 + 2 * gamma(3): widens the slab test's far distance so that rounding never loses a hit
/// (Ize, "Robust BVH Ray Traversal", JCGT 2013).
pub(super) const ROBUST_FAR: f32 =
    1.0 + 2.0 * (3.0 * f32::EPSILON * 0.5) / (1.0 - 3.0 * f32::EPSILON * 0.5);

/// How far past the nearest hit so far a box's entry distance may lie and the box still be
/// entered. A triangle's t and the entry distance of a box around it are rounded
/// independently, so a triangle hit at a vertex on the box's boundary can come out a few ulps
/// nearer than the box's entry: a ray through a vertex that triangles in two leaves share
/// found the farther of the two hits when the nearer one's box was pruned by exactly that.
/// 2^-16 relative (hundreds of ulps) covers it and costs no measurable pruning.
const PRUNE_SLACK: f32 = 1.0 + 1.0 / 65536.0;

/// The farthest entry distance of a box that may still hold a hit nearer than `t_max`.
#[inline(always)]
pub(super) fn prune_limit(t_max: f32) -> f32 {
    t_max * PRUNE_SLACK
}

/// [`prune_limit`] of eight rays at once (the same bits, lane by lane).
#[inline(always)]
pub(super) fn prune_limit8(t_max: f32x8) -> f32x8 {
    t_max * f32x8::splat(PRUNE_SLACK)
}

/// The offsets `origin - plane` of a node's children's near and far planes on each axis, as
/// the node test subtracts them ([`BoxRay::offsets`]): the part of the test that rays sharing
/// an origin and the signs of their directions (and so the rows they read) share, made once
/// for a packet of them.
#[derive(Clone, Copy)]
pub(super) struct PlaneOffsets {
    near: [f32x8; 3],
    far: [f32x8; 3],
}

#[derive(Clone, Copy)]
pub(super) struct BoxRay {
    /// The direction (x, y, z and a zero lane).
    dir4: f32x4,
    /// `origin`, `-inv` and `-(inv * ROBUST_FAR)` (x, y, z and a zero lane): the node test's
    /// operands, made once per ray (the far distances' widening folded into the inverse: as many
    /// roundings as widening the product, so the same bound; three multiplications fewer per node.
    /// Negated, so that the test computes `(origin - plane) * -inv`, the same distance as `(plane -
    /// origin) * inv` but with the plane as the subtraction's memory operand: six loads fewer per
    /// node). Each is stored as one 16-byte vector, so that a walk receiving the ray through
    /// memory broadcasts each lane with a load that its store forwards (scalars stored one by
    /// one were read by a load spanning two of those stores, which cannot be forwarded; stored as
    /// nine 8-lane splats, every ray paid nine 32-byte stores: the 16-byte form read primary
    /// rays 1.1-3.0% higher against Embree on the four meshes on the Xeon, eight rounds each).
    origin4: f32x4,
    neg_inv4: f32x4,
    neg_inv_far4: f32x4,
    /// Per axis, the row of a node (seen as [`Node::rows`]) that holds the children's near
    /// and far planes, chosen once per ray: the `hi_` row when the ray goes towards smaller
    /// values (odd rows are `hi_`).
    near_row: [u32; 3],
    far_row: [u32; 3],
}

/// The rows of [`Node::rows`] holding the children's near and far planes on axis `k` for a
/// ray going towards smaller values on it (`down` 1: the `hi_` row is near) or not (`down` 0).
#[inline(always)]
fn slab_rows(k: usize, down: u32) -> (u32, u32) {
    let lo = Node::LO_ROWS[k] as u32;
    (lo + down, lo + (down ^ 1))
}

impl BoxRay {
    pub(super) fn new(origin: Vec3, dir: Vec3) -> BoxRay {
        // A zero component gives an infinite inverse: a slab the origin is outside of gives
        // +-inf (never entered), and a ray lying exactly in a slab's plane gives 0 * inf = NaN,
        // which the min/max below drop (the ray is inside that slab, boundaries included).
        let inv = [1.0 / dir[0], 1.0 / dir[1], 1.0 / dir[2]];
        let rows = [0, 1, 2].map(|k| slab_rows(k, u32::from(inv[k].is_sign_negative())));
        BoxRay {
            dir4: lanes(dir),
            origin4: lanes(origin),
            neg_inv4: f32x4::from([-inv[0], -inv[1], -inv[2], 0.0]),
            neg_inv_far4: f32x4::from([
                -(inv[0] * ROBUST_FAR),
                -(inv[1] * ROBUST_FAR),
                -(inv[2] * ROBUST_FAR),
                0.0,
            ]),
            near_row: rows.map(|(near, _)| near),
            far_row: rows.map(|(_, far)| far),
        }
    }

    /// The first three lanes of `v`.
    #[inline(always)]
    fn xyz(v: f32x4) -> Vec3 {
        let [x, y, z, _] = v.to_array();
        [x, y, z]
    }

    #[inline(always)]
    fn origin(&self) -> Vec3 {
        Self::xyz(self.origin4)
    }

    #[inline(always)]
    pub(super) fn direction(&self) -> Vec3 {
        Self::xyz(self.dir4)
    }

    /// `1 / direction` (negating the stored `-inv` is exact).
    #[inline(always)]
    fn inv(&self) -> Vec3 {
        Self::xyz(-self.neg_inv4)
    }

    /// The same ray prepared for the watertight triangle test, for a ray whose
    /// [`permutation`](super::triangle::permutation) is `P` (reusing the inverse), or any
    /// ray for [`ANY_AXES`].
    #[inline(always)]
    pub(super) fn sheared<const P: usize>(&self) -> ShearedRay {
        if P < ANY_AXES {
            ShearedRay::for_axes::<P>(self.origin(), self.direction(), self.inv())
        } else {
            ShearedRay::new(self.origin(), self.direction())
        }
    }

    /// Entry distances of the children of `node` and the mask of those the segment
    /// `[t_min, t_max]` reaches (inclusive at both ends). Empty slots have inverted boxes and
    /// never hit. All eight slabs at once (`wide`: AVX, or two SSE halves). `P` below
    /// [`ANY_AXES`] only for a ray with a [`finite_inverse`](Self::finite_inverse).
    #[inline(always)]
    pub(super) fn node<const P: usize>(
        &self,
        n: &Node,
        t_min: f32,
        t_max: f32,
    ) -> (u32, [f32; WIDTH]) {
        if P < ANY_AXES && INTEGER_MIN_MAX {
            self.slabs::<P, true>(n, t_min, t_max)
        } else {
            self.slabs::<P, false>(n, t_min, t_max)
        }
    }

    /// [`BoxRay::node`], reducing and comparing the slabs' distances with integer minima,
    /// maxima and compare (`INTEGER`, for a ray with a finite inverse) or with float ones (any
    /// ray).
    #[inline(always)]
    fn slabs<const P: usize, const INTEGER: bool>(
        &self,
        n: &Node,
        t_min: f32,
        t_max: f32,
    ) -> (u32, [f32; WIDTH]) {
        let (near, missed) = self.slabs_from::<INTEGER>(&self.offsets::<P>(n), t_min, t_max);
        (!missed.to_bitmask() & 0xff, near.to_array())
    }

    /// The offsets from this ray's origin of the children's planes of `n` that its node test
    /// reads (see [`PlaneOffsets`]).
    #[inline(always)]
    pub(super) fn offsets<const P: usize>(&self, n: &Node) -> PlaneOffsets {
        let rows = n.rows();
        // `& 7`: the rows are eight, so the index needs no bounds check.
        let row = |r: u32| f32x8::from(rows[r as usize & 7]);
        let (mut near_row, mut far_row) = (self.near_row, self.far_row);
        if P < ANY_AXES {
            // The permutation fixes the dominant axis and its direction (`P & 1`: towards
            // smaller values), so that axis's rows are constant offsets: two row offsets
            // fewer for the walk to keep.
            let (_, _, kz) = AXES[P];
            (near_row[kz], far_row[kz]) = slab_rows(kz, (P & 1) as u32);
        }
        let o = |k: usize| f32x8::splat(self.origin4.as_array()[k]);
        PlaneOffsets {
            near: [0, 1, 2].map(|k| o(k) - row(near_row[k])),
            far: [0, 1, 2].map(|k| o(k) - row(far_row[k])),
        }
    }

    /// The node test of [`BoxRay::slabs`] from the planes' offsets `off` (this ray's, or those
    /// of a ray with the same origin and the same signs of direction, bit for bit): the
    /// children's entry distances and the lanes of those the ray misses (all bits set).
    #[inline(always)]
    pub(super) fn slabs_from<const INTEGER: bool>(
        &self,
        off: &PlaneOffsets,
        t_min: f32,
        t_max: f32,
    ) -> (f32x8, f32x8) {
        let [dx, dy, dz] = off.near;
        let [ex, ey, ez] = off.far;
        let s = f32x8::splat;
        let sp = |v: &f32x4, k: usize| f32x8::splat(v.as_array()[k]);
        let [ix, iy, iz] = [0, 1, 2].map(|k| sp(&self.neg_inv4, k));
        let [jx, jy, jz] = [0, 1, 2].map(|k| sp(&self.neg_inv_far4, k));
        // Capping the far end at f32::MAX also rejects a ray parallel to a slab it is outside
        // of, which enters at +inf.
        let hi = s(fmin(prune_limit(t_max), f32::MAX));
        if INTEGER {
            // Integer minima, maxima and compare on the distances' bits: one cycle each on the
            // chain from a node to the next, where the float ones take three or four on recent
            // Intel cores (primary rays 5-13% faster on the Xeon). A ray with a finite inverse
            // has no NaN distance, and integer order is float order among values without the
            // sign bit and puts every value with it below them. `+ 0.0` makes a `t_min` of
            // -0.0 +0.0 (the same bound), so the near distance, a maximum with it, is the float
            // one (+0.0 where that is -0.0) and has no sign bit. A far slab distance is made
            // with a zero addend (`(o - f) * j + 0.0`, one rounding: the product, but +0.0
            // where it is -0.0, the origin on a far plane): the far distance is then the
            // float one where no slab's is negative, and has the sign bit, like the float one,
            // where one is; so the box is entered exactly when `near <= far` as floats.
            let lo = s(t_min + 0.0);
            let zero = f32x8::ZERO;
            let near = imax8(dx * ix, imax8(dy * iy, imax8(dz * iz, lo)));
            let far = imin8(
                ex.mul_add(jx, zero),
                imin8(ey.mul_add(jy, zero), imin8(ez.mul_add(jz, zero), hi)),
            );
            let bits = |v: f32x8| -> wide::i32x8 { bytemuck::cast(v) };
            return (near, bytemuck::cast(bits(near).simd_gt(bits(far))));
        }
        // Each axis term goes first: a NaN (ray in a slab plane) leaves the interval unbounded
        // on that axis (`fmax8(term, acc)` is `acc` when `term` is NaN).
        let near = fmax8(dx * ix, fmax8(dy * iy, fmax8(dz * iz, s(t_min))));
        let far = fmin8(ex * jx, fmin8(ey * jy, fmin8(ez * jz, hi)));
        let all: f32x8 = bytemuck::cast(u32x8::splat(u32::MAX));
        (near, near.simd_le(far) ^ all)
    }

    /// Whether `1 / direction` is finite on every axis: a walk instantiated for the ray's
    /// permutation tests its nodes with integer minima, maxima and compare, which a NaN
    /// distance (0 x inf, a ray in a slab's plane) would break.
    #[inline(always)]
    pub(super) fn finite_inverse(&self) -> bool {
        self.neg_inv4.is_finite().to_bitmask() == 0b1111
    }

    #[inline(always)]
    pub(super) fn aabb(&self, b: &[f32; 6], t_min: f32, t_max: f32) -> Option<f32> {
        // As in `node`: axis terms first, so NaN (ray in a slab plane) means "inside".
        let (origin, inv) = (self.origin(), self.inv());
        let mut near = t_min;
        let mut far = t_max;
        for k in 0..3 {
            let (lo, hi) = if self.near_row[k] & 1 != 0 {
                (b[k + 3], b[k])
            } else {
                (b[k], b[k + 3])
            };
            near = fmax((lo - origin[k]) * inv[k], near);
            far = fmin((hi - origin[k]) * inv[k] * ROBUST_FAR, far);
        }
        // A ray parallel to a slab it is outside of has near = +inf: no candidate at infinity.
        (near <= far && near < f32::INFINITY).then_some(near)
    }
}

/// Traversal state of one structure (the top level or the current instance's bottom level).
struct Level<'s> {
    view: View<'s>,
    ray: BoxRay,
    stack: Box<Stack>,
    leaf_next: u32,
    leaf_end: u32,
}

impl<'s> Level<'s> {
    fn new(view: View<'s>, ray: BoxRay, stack: Box<Stack>) -> Level<'s> {
        let mut level = Level {
            view,
            ray,
            stack,
            leaf_next: 0,
            leaf_end: 0,
        };
        level.stack.len = 0;
        if !level.view.nodes.is_empty() {
            level.stack.push(Entry {
                child: 0,
                count: 0,
                t: f32::NEG_INFINITY,
            });
        }
        level
    }

    /// Advances to the next leaf that the segment reaches; `false` when the tree is done.
    #[inline(always)]
    fn next_leaf(&mut self, t_min: f32, t_max: f32) -> bool {
        while let Some(e) = self.stack.pop() {
            if e.t > prune_limit(t_max) {
                continue;
            }
            if e.child & LEAF_BIT != 0 {
                self.leaf_next = e.child & !LEAF_BIT;
                self.leaf_end = self.leaf_next + e.count;
                return true;
            }
            // The batch tracer's ordering (farthest deepest), with the nearest pushed too.
            let stack = &mut *self.stack;
            let mut sp = stack.len;
            let nearest = descend::<ANY_AXES>(
                &mut stack.items,
                &mut sp,
                self.view.nodes,
                self.view.triangles,
                e.child,
                &self.ray,
                t_min,
                t_max,
            );
            stack.len = sp;
            if let Some(n) = nearest {
                stack.push(n);
            }
        }
        false
    }
}

const _: () = assert!(WIDTH == 8, "the node test is written for f32x8");

/// For [`descend`] and [`BoxRay::node`]: a ray of any axis permutation (one that is not known
/// at compile time).
pub(super) const ANY_AXES: usize = AXES.len();

/// Tests the children of node `index`: returns the nearest one the segment reaches, having
/// pushed the others (farthest deepest), or `None` when it reaches none. `triangles` are the
/// structure's triangles (empty when its leaves hold other primitives), for prefetching. `P`
/// is the ray's axis permutation ([`permutation`](super::triangle::permutation)) where the
/// caller knows it at compile time, else [`ANY_AXES`].
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(super) fn descend<const P: usize>(
    stack: &mut [Entry],
    sp: &mut usize,
    nodes: &[Node],
    triangles: impl TriangleSource,
    index: u32,
    ray: &BoxRay,
    t_min: f32,
    t_max: f32,
) -> Option<Entry> {
    let node = nodes.get(index as usize)?;
    // The children's references are read only once the test has picked them: their line is
    // requested now, so that its miss overlaps the planes' instead of following them.
    crate::math::prefetch(&node.child);
    let (mut mask, t) = ray.node::<P>(node, t_min, t_max);
    if mask == 0 {
        return None;
    }
    let entry = |k: usize| Entry {
        child: node.child[k],
        count: node.count[k] as u32,
        t: t[k],
    };
    if mask & (mask - 1) == 0 {
        return Some(entry(mask.trailing_zeros() as usize));
    }
    let warm = |e: &Entry| warm(nodes, triangles, e);
    let start = *sp;
    // Two children (the most common case after one): the farther is pushed, the nearer
    // returned, in the order the insertion sort below would give (on a tie, the later lane
    // is nearer), without its loops.
    let rest = mask & (mask - 1);
    if rest & (rest - 1) == 0 {
        let e0 = entry(mask.trailing_zeros() as usize);
        let e1 = entry(rest.trailing_zeros() as usize);
        let (far, near) = if e0.t < e1.t { (e1, e0) } else { (e0, e1) };
        warm(&far);
        *stack.get_mut(start)? = far;
        *sp = start + 1;
        return Some(near);
    }
    // Three children: the same order by a three-comparison network.
    let rest2 = rest & (rest - 1);
    if rest2 & (rest2 - 1) == 0 {
        let e0 = entry(mask.trailing_zeros() as usize);
        let e1 = entry(rest.trailing_zeros() as usize);
        let e2 = entry(rest2.trailing_zeros() as usize);
        // Deepest first; an entry goes below an earlier one only when strictly farther.
        let (a, b) = if e0.t < e1.t { (e1, e0) } else { (e0, e1) };
        let (b, c) = if b.t < e2.t { (e2, b) } else { (b, e2) };
        let (a, b) = if a.t < b.t { (b, a) } else { (a, b) };
        warm(&a);
        warm(&b);
        let region = stack.get_mut(start..start + 2)?;
        region[0] = a;
        region[1] = b;
        *sp = start + 2;
        return Some(c);
    }
    if RANKED_ORDER {
        // Each child goes straight to its place: farthest deepest, the nearest (rank 0) on
        // top, where it is read back and returned instead of pushed.
        let rank = ranks(&t, mask);
        let last = mask.count_ones() as usize - 1;
        // (Room for a node's eight on any validated view: `STACK_CAPACITY`.)
        let region: &mut [Entry; WIDTH] = stack.get_mut(start..)?.first_chunk_mut()?;
        while mask != 0 {
            let k = mask.trailing_zeros() as usize;
            mask &= mask - 1;
            let e = entry(k);
            warm(&e);
            region[last.wrapping_sub(rank[k & 7] as usize) & 7] = e;
        }
        *sp = start + last;
        return Some(region[last & 7]);
    }
    // Insertion-sort the hit children straight onto the stack, farthest deepest; the
    // nearest ends on top and is returned instead of pushed.
    let mut end = start;
    while mask != 0 {
        let k = mask.trailing_zeros() as usize;
        mask &= mask - 1;
        let e = entry(k);
        warm(&e);
        // Cannot overflow on a validated view (depth <= MAX_DEPTH); drop rather than panic.
        let Some(region) = stack.get_mut(start..=end) else {
            break;
        };
        let mut j = region.len() - 1;
        while j > 0 && region[j - 1].t < e.t {
            region[j] = region[j - 1];
            j -= 1;
        }
        region[j] = e;
        end += 1;
    }
    if end == start {
        return None;
    }
    *sp = end - 1;
    stack.get(*sp).copied()
}

/// Whether [`descend`] orders four or more hit children by [`ranks`] (where eight lanes
/// permute in one instruction) rather than by an insertion sort (whose comparisons
/// mispredict; the same order).
const RANKED_ORDER: bool = cfg!(target_feature = "avx2");

/// The place of each hit child (lanes in `mask`, entry distances `t`) in the order the walk
/// visits them: how many hit children are nearer, a child at the same distance as a later
/// lane counting as farther (the insertion sort's order). All pairs are compared at once,
/// eight lanes against the seven rotations of the distances, with no branch. Lanes not in
/// `mask` get no meaningful rank.
#[inline(always)]
fn ranks(t: &[f32; WIDTH], mask: u32) -> [u32; WIDTH] {
    // As integers: a hit child's distance is finite and not negative (once -0.0 is made
    // +0.0), so its bits order as the floats do; missed lanes take i32::MAX, past them all.
    let lane_bits = i32x8::from([1, 2, 4, 8, 16, 32, 64, 128]);
    let missed = (i32x8::splat(mask as i32) & lane_bits).simd_eq(i32x8::ZERO);
    let bits: i32x8 = bytemuck::cast(f32x8::from(*t) + f32x8::ZERO);
    let key = (bits & !missed) | (i32x8::splat(i32::MAX) & missed);
    let mut rank = i32x8::ZERO;
    for r in 1..WIDTH {
        // Lane i meets lane (i + r) % 8. That one is nearer when its distance is less, or
        // equal with it the later lane: `key > other - 1`, that is `key >= other`.
        let other = u32x8::from(std::array::from_fn(|i| ((i + r) % WIDTH) as u32));
        let later = i32x8::from(std::array::from_fn(|i| i32::from(i + r < WIDTH)));
        let nearer = key.simd_gt(key.shuffle(other) - later);
        // (True lanes are -1.)
        rank -= nearer;
    }
    bytemuck::cast(rank)
}

/// The lanes of `mask` in the order [`descend`] visits them (nearest first by `t`, a later
/// lane first on a tie); entries past the mask's count are 0.
#[inline(always)]
pub(super) fn nearest_first(t: &[f32; WIDTH], mask: u32) -> [u32; WIDTH] {
    let rank = ranks(t, mask);
    let mut order = [0; WIDTH];
    let mut m = mask;
    while m != 0 {
        let k = m.trailing_zeros();
        m &= m - 1;
        order[rank[k as usize & 7] as usize & 7] = k;
    }
    order
}

/// Requests a pushed child now, so that its misses overlap the rest of the walk: an inner
/// node's four lines, or a leaf's first lines ([`TriangleSource::prefetch`]).
#[inline(always)]
pub(super) fn warm(nodes: &[Node], triangles: impl TriangleSource, e: &Entry) {
    if e.child & LEAF_BIT == 0 {
        if let Some(n) = nodes.get(e.child as usize) {
            let r = n.rows();
            // Last line first: in this order the four requests take constant offsets from
            // the node's address (in the other, the last one's address was computed apart for
            // a request shared with the leaf branch: three instructions more per child).
            for k in [6, 4, 2, 0] {
                crate::math::prefetch(&r[k]);
            }
        }
    } else {
        triangles.prefetch((e.child & !LEAF_BIT) as usize, e.count as usize);
    }
}

struct Bottom<'s> {
    level: Level<'s>,
    sheared: ShearedRay,
    instance: &'s InstanceRecord,
    instance_slot: u32,
}

impl Drop for RayQuery<'_> {
    fn drop(&mut self) {
        for s in [
            self.top.take().map(|l| l.stack),
            self.bottom.take().map(|b| b.level.stack),
            self.spare_stack.take(),
        ]
        .into_iter()
        .flatten()
        {
            s.recycle();
        }
    }
}

/// A ray query (`rayQueryEXT`) over a [`Scene`].
pub struct RayQuery<'s> {
    scene: &'s Scene,
    ray: Ray,
    top: Option<Level<'s>>,
    bottom: Option<Bottom<'s>>,
    spare_stack: Option<Box<Stack>>,
    done: bool,
    t_max: f32,
    committed: Intersection,
    candidate: Intersection,
}

impl<'s> RayQuery<'s> {
    /// `rayQueryInitializeEXT`.
    pub fn new(scene: &'s Scene, ray: &Ray) -> Result<RayQuery<'s>> {
        ray.validate()?;
        let top = scene
            .tlas_view()
            .map(|v| Level::new(v, BoxRay::new(ray.origin, ray.direction), Stack::new()));
        Ok(RayQuery {
            scene,
            ray: *ray,
            top,
            bottom: None,
            spare_stack: Some(Stack::new()),
            done: false,
            t_max: ray.t_max,
            committed: Intersection::NONE,
            candidate: Intersection::NONE,
        })
    }

    pub fn ray(&self) -> &Ray {
        &self.ray
    }

    /// `rayQueryProceedEXT`: `true` when a candidate awaits a decision.
    pub fn proceed(&mut self) -> bool {
        self.candidate = Intersection::NONE;
        if self.done {
            return false;
        }
        while let Some(c) = self.next_candidate() {
            if c.kind == Kind::Triangle && c.opaque {
                self.commit(c);
                if self.done {
                    return false;
                }
                continue;
            }
            self.candidate = c;
            return true;
        }
        self.done = true;
        false
    }

    fn commit(&mut self, c: Intersection) {
        self.committed = c;
        self.t_max = c.t;
        if self.ray.flags.contains(RayFlags::TERMINATE_ON_FIRST_HIT) {
            self.done = true;
        }
    }

    /// `rayQueryConfirmIntersectionEXT`: commits the current triangle candidate.
    pub fn confirm_intersection(&mut self) -> Result<()> {
        if self.candidate.kind != Kind::Triangle {
            return Err(Error::vuid(
                "VUID-RuntimeSpirv-OpRayQueryConfirmIntersectionKHR",
                Location::NONE,
                "confirm needs a current triangle candidate",
            ));
        }
        let c = self.candidate;
        if c.t < self.t_max {
            self.commit(c);
        }
        self.candidate.kind = Kind::None;
        Ok(())
    }

    /// `rayQueryGenerateIntersectionEXT`: commits a hit at `t` for the current AABB candidate.
    pub fn generate_intersection(&mut self, t: f32) -> Result<()> {
        if self.candidate.kind != Kind::Aabb {
            return Err(Error::vuid(
                "VUID-RuntimeSpirv-OpRayQueryGenerateIntersectionKHR",
                Location::NONE,
                "generate needs a current AABB candidate",
            ));
        }
        if !(self.ray.t_min <= t && t <= self.t_max) {
            return Err(Error::vuid(
                "VUID-RuntimeSpirv-OpRayQueryGenerateIntersectionKHR-06353",
                Location::NONE,
                format!(
                    "hitT {t} is outside [tMin {}, committed t {}]",
                    self.ray.t_min, self.t_max
                ),
            ));
        }
        let mut c = self.candidate;
        c.kind = Kind::Generated;
        c.t = t;
        self.commit(c);
        self.candidate.kind = Kind::None;
        Ok(())
    }

    /// `rayQueryTerminateEXT`.
    pub fn terminate(&mut self) {
        self.done = true;
        self.candidate = Intersection::NONE;
    }

    /// The current candidate (valid after `proceed` returned `true`).
    pub fn candidate(&self) -> &Intersection {
        &self.candidate
    }
    /// `rayQueryGetIntersectionTypeEXT(q, false)`.
    pub fn candidate_type(&self) -> Option<CandidateType> {
        self.candidate.candidate_type()
    }
    pub fn committed(&self) -> &Intersection {
        &self.committed
    }
    /// `rayQueryGetIntersectionTypeEXT(q, true)`.
    pub fn committed_type(&self) -> CommittedType {
        self.committed.committed_type()
    }

    fn pick(&self, committed: bool) -> Option<&Intersection> {
        let i = if committed {
            &self.committed
        } else {
            &self.candidate
        };
        (i.kind != Kind::None).then_some(i)
    }

    fn instance_of(&self, i: &Intersection) -> Option<&'s InstanceRecord> {
        self.scene
            .tlas_view()?
            .instances
            .get(i.instance_slot as usize)
    }

    /// `rayQueryGetIntersectionObjectToWorldEXT` (3x4, row-major).
    pub fn object_to_world(&self, committed: bool) -> Option<Affine> {
        let i = self.pick(committed)?;
        Some(Affine::from_rows(self.instance_of(i)?.object_to_world))
    }
    /// `rayQueryGetIntersectionWorldToObjectEXT` (3x4, row-major).
    pub fn world_to_object(&self, committed: bool) -> Option<Affine> {
        let i = self.pick(committed)?;
        Some(Affine::from_rows(self.instance_of(i)?.world_to_object))
    }
    /// `rayQueryGetIntersectionObjectRayOriginEXT`.
    pub fn object_ray_origin(&self, committed: bool) -> Option<Vec3> {
        Some(self.world_to_object(committed)?.point(self.ray.origin))
    }
    /// `rayQueryGetIntersectionObjectRayDirectionEXT`.
    pub fn object_ray_direction(&self, committed: bool) -> Option<Vec3> {
        Some(self.world_to_object(committed)?.vector(self.ray.direction))
    }

    /// `rayQueryGetIntersectionTriangleVertexPositionsEXT`: the triangle's vertices in object
    /// space after the geometry transform, in index order. Needs `ALLOW_DATA_ACCESS`.
    pub fn triangle_vertex_positions(&self, committed: bool) -> Result<[Vec3; 3]> {
        let none = || {
            Error::vuid(
                "VUID-RuntimeSpirv-OpRayQueryGetIntersectionTriangleVertexPositionsKHR",
                Location::NONE,
                "no triangle intersection",
            )
        };
        let i = self.pick(committed).ok_or_else(none)?;
        if !matches!(i.kind, Kind::Triangle) {
            return Err(none());
        }
        self.instance_of(i).ok_or_else(none)?;
        let view = self.scene.blas_view_for(i.instance_slot).ok_or_else(none)?;
        if view.header.build_flags
            & vk::BuildAccelerationStructureFlagsKHR::ALLOW_DATA_ACCESS.as_raw()
            == 0
        {
            return Err(Error::vuid(
                "VUID-RuntimeSpirv-OpRayQueryGetIntersectionTriangleVertexPositionsKHR-08761",
                Location::NONE,
                "the bottom-level structure was not built with ALLOW_DATA_ACCESS",
            ));
        }
        let t = view.triangles.get(i.prim_slot as usize).ok_or_else(none)?;
        Ok([[t[0], t[1], t[2]], [t[3], t[4], t[5]], [t[6], t[7], t[8]]])
    }

    /// The next candidate that passes the range, culling and masking rules.
    fn next_candidate(&mut self) -> Option<Intersection> {
        let flags = self.ray.flags;
        loop {
            if let Some(bottom) = &mut self.bottom {
                let level = &mut bottom.level;
                while level.leaf_next < level.leaf_end {
                    let slot = level.leaf_next;
                    level.leaf_next += 1;
                    let c = match level.view.prim_kind {
                        PrimKind::Triangles => test_triangle(
                            &self.ray,
                            self.t_max,
                            bottom.instance,
                            bottom.instance_slot,
                            &level.view,
                            &bottom.sheared,
                            slot,
                        ),
                        PrimKind::Aabbs => test_aabb(
                            &self.ray,
                            self.t_max,
                            bottom.instance,
                            bottom.instance_slot,
                            &level.view,
                            &level.ray,
                            slot,
                        ),
                        _ => None,
                    };
                    if c.is_some() {
                        return c;
                    }
                }
                if !level.next_leaf(self.ray.t_min, self.t_max) {
                    let b = self.bottom.take();
                    self.spare_stack = b.map(|b| b.level.stack);
                }
                continue;
            }
            let top = self.top.as_mut()?;
            while top.leaf_next < top.leaf_end {
                let slot = top.leaf_next;
                top.leaf_next += 1;
                let Some(inst) = top.view.instances.get(slot as usize) else {
                    continue;
                };
                if inst.mask & self.ray.cull_mask & 0xff == 0 {
                    continue;
                }
                let Some(view) = self.scene.blas_view_for(slot) else {
                    continue;
                };
                if flags.skip(view.prim_kind) || view.nodes.is_empty() {
                    continue;
                }
                let w2o = Affine::from_rows(inst.world_to_object);
                let origin = w2o.point(self.ray.origin);
                let dir = w2o.vector(self.ray.direction);
                let stack = self.spare_stack.take().unwrap_or_else(Stack::new);
                self.bottom = Some(Bottom {
                    level: Level::new(view, BoxRay::new(origin, dir), stack),
                    sheared: ShearedRay::new(origin, dir),
                    instance: inst,
                    instance_slot: slot,
                });
                break;
            }
            if self.bottom.is_some() {
                continue;
            }
            if !top.next_leaf(self.ray.t_min, self.t_max) {
                return None;
            }
        }
    }
}

/// Opacity in the spec's order: geometry flag, then instance force flags, then ray flags.
#[inline(always)]
pub(super) fn resolve_opacity(
    view: &View,
    geometry: u32,
    instance: &InstanceRecord,
    ray: RayFlags,
) -> bool {
    let mut opaque = if view.header.header_flags & HEADER_ALL_OPAQUE != 0 {
        true
    } else if view.header.header_flags & HEADER_NONE_OPAQUE != 0 {
        false
    } else {
        view.geometries
            .get(geometry as usize)
            .is_some_and(|g| g.flags & vk::GeometryFlagsKHR::OPAQUE.as_raw() != 0)
    };
    let f = vk::GeometryInstanceFlagsKHR::from_raw(instance.flags);
    if f.contains(vk::GeometryInstanceFlagsKHR::FORCE_OPAQUE) {
        opaque = true;
    } else if f.contains(vk::GeometryInstanceFlagsKHR::FORCE_NO_OPAQUE) {
        opaque = false;
    }
    if ray.contains(RayFlags::OPAQUE) {
        opaque = true;
    } else if ray.contains(RayFlags::NO_OPAQUE) {
        opaque = false;
    }
    opaque
}

#[inline(always)]
pub(super) fn opacity_culled(opaque: bool, ray: RayFlags) -> bool {
    (opaque && ray.contains(RayFlags::CULL_OPAQUE))
        || (!opaque && ray.contains(RayFlags::CULL_NO_OPAQUE))
}

fn intersection(
    instance: &InstanceRecord,
    instance_slot: u32,
    view: &View,
    slot: u32,
    kind: Kind,
    t: f32,
) -> Intersection {
    let id = view.prim_ids.get(slot as usize).copied().unwrap_or(0);
    let (geometry_index, primitive_index) = view.locate(id);
    Intersection {
        kind,
        t,
        instance_id: instance.instance_id,
        instance_custom_index: instance.custom_index,
        sbt_record_offset: instance.sbt_record_offset,
        geometry_index,
        primitive_index,
        barycentrics: [0.0; 2],
        front_face: false,
        opaque: false,
        instance_slot,
        prim_slot: slot,
    }
}

#[inline(always)]
fn test_triangle(
    ray: &Ray,
    t_max: f32,
    inst: &InstanceRecord,
    inst_slot: u32,
    view: &View,
    sheared: &ShearedRay,
    slot: u32,
) -> Option<Intersection> {
    let tri = view.triangles.get(slot as usize)?;
    let h = sheared.intersect(&tri)?;
    if !(h.t > ray.t_min && h.t < t_max) {
        return None;
    }
    let f = vk::GeometryInstanceFlagsKHR::from_raw(inst.flags);
    let front = h.front_face != f.contains(vk::GeometryInstanceFlagsKHR::TRIANGLE_FLIP_FACING);
    if !f.contains(vk::GeometryInstanceFlagsKHR::TRIANGLE_FACING_CULL_DISABLE)
        && ((front && ray.flags.contains(RayFlags::CULL_FRONT_FACING_TRIANGLES))
            || (!front && ray.flags.contains(RayFlags::CULL_BACK_FACING_TRIANGLES)))
    {
        return None;
    }
    let mut c = intersection(inst, inst_slot, view, slot, Kind::Triangle, h.t);
    c.opaque = resolve_opacity(view, c.geometry_index, inst, ray.flags);
    if opacity_culled(c.opaque, ray.flags) {
        return None;
    }
    c.barycentrics = [h.b, h.c];
    c.front_face = front;
    Some(c)
}

#[inline(always)]
fn test_aabb(
    ray: &Ray,
    t_max: f32,
    inst: &InstanceRecord,
    inst_slot: u32,
    view: &View,
    box_ray: &BoxRay,
    slot: u32,
) -> Option<Intersection> {
    let b = view.aabbs.get(slot as usize)?;
    let t = box_ray.aabb(b, ray.t_min, t_max)?;
    let mut c = intersection(inst, inst_slot, view, slot, Kind::Aabb, t);
    c.opaque = resolve_opacity(view, c.geometry_index, inst, ray.flags);
    if opacity_culled(c.opaque, ray.flags) {
        return None;
    }
    Some(c)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::traverse::triangle::{by_permutation, permutation};
    use rand::{Rng, SeedableRng};

    /// The ranks put four to eight hit children in the insertion sort's order (nearest on
    /// top, a later lane nearer on a tie): on random distances, coarse ones (ties), both
    /// signed zeros and the largest float, on random masks of four or more lanes.
    #[test]
    fn ranks_give_the_insertion_sort_order() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(0x5a4c);
        let pool = [0.0, -0.0, 1.0, 1.5, f32::MAX, f32::MIN_POSITIVE, 3.0e-39];
        for round in 0..20_000 {
            let t: [f32; WIDTH] = std::array::from_fn(|_| match round % 3 {
                0 => rng.gen_range(0.0f32..100.0),
                1 => rng.gen_range(0..4) as f32 * 0.5,
                _ => pool[rng.gen_range(0..pool.len())],
            });
            let mask: u32 = rng.gen_range(0..256);
            if mask.count_ones() < 4 {
                continue;
            }
            // The insertion sort of `descend`, on lanes instead of entries.
            let mut sorted: Vec<usize> = Vec::new();
            for k in (0..WIDTH).filter(|k| mask & (1 << k) != 0) {
                let mut j = sorted.len();
                while j > 0 && t[sorted[j - 1]] < t[k] {
                    j -= 1;
                }
                sorted.insert(j, k);
            }
            // Deepest first: the last one is the nearest, rank 0.
            let rank = ranks(&t, mask);
            for (depth, &k) in sorted.iter().enumerate() {
                let expected = sorted.len() - 1 - depth;
                assert_eq!(rank[k] as usize, expected, "round {round}: {t:?} {mask:#b}");
            }
        }
    }

    /// The node test of a walk instantiated for the ray's permutation reads the dominant
    /// axis's planes at constant rows; it must give the bits of the test that reads every row
    /// from the ray, for every direction: signed zeros (a zero direction included), ties
    /// between magnitudes, rays in a slab's plane. And for a ray with a finite inverse, the
    /// integer reduction must give the float one's distances and children: origins on the
    /// children's far planes included, where a far slab distance is -0.0 (which integer order
    /// puts below every other value).
    #[test]
    fn node_test_for_the_permutation_matches_the_general_one() {
        type Test = (u32, [u32; WIDTH]);
        fn node_for<const P: usize, const I: bool>(r: &BoxRay, n: &Node, t: [f32; 2]) -> Test {
            let (mask, near) = r.slabs::<P, I>(n, t[0], t[1]);
            (mask, near.map(f32::to_bits))
        }
        fn node_by_permutation<const I: bool>(r: &BoxRay, n: &Node, t: [f32; 2]) -> Test {
            by_permutation!(permutation(r.direction()), P => node_for::<P, I>(r, n, t))
        }
        let mut rng = rand_pcg::Pcg64::seed_from_u64(0x5eed_a5e5);
        let mut node = Node::EMPTY;
        for k in 0..WIDTH - 1 {
            let lo = [0; 3].map(|_| rng.gen_range(-2.0f32..1.0));
            let hi = lo.map(|l| l + rng.gen_range(0.0f32..2.0));
            node.set_bounds(k, &crate::math::Aabb { lo, hi });
        }
        let values = [0.0, -0.0, 1.0, -1.0, 0.5, -0.5];
        let mut dirs: Vec<Vec3> = Vec::new();
        for x in values {
            for y in values {
                for z in values {
                    dirs.push([x, y, z]);
                }
            }
        }
        dirs.extend((0..2000).map(|_| [0; 3].map(|_| rng.gen_range(-1.0f32..1.0))));
        let (mut hits, mut finite, mut on_far_planes) = (0, 0, 0);
        // On child 2's far plane in x for a ray going up x, past its far plane in y for a ray
        // going up y, inside it in z: its far distance is below 0 in float order, and its far
        // slab distance in x is -0.0 before the zero addend makes it +0.0.
        let b2 = node.bounds(2);
        let past = [b2.hi[0], b2.hi[1] + 0.5, 0.5 * (b2.lo[2] + b2.hi[2])];
        for d in dirs {
            // Origins inside, outside and on the children's planes.
            for o in [
                [0.0; 3],
                [-2.0, 0.5, 3.0],
                node.bounds(0).lo,
                node.bounds(1).hi,
                past,
            ] {
                let r = BoxRay::new(o, d);
                let ts = [0.0, -0.0, 0.25].map(|t_min| [[t_min, f32::INFINITY], [t_min, 1.0]]);
                for t in ts.into_iter().flatten() {
                    let general = node_for::<ANY_AXES, false>(&r, &node, t);
                    let by_permutation = node_by_permutation::<false>(&r, &node, t);
                    assert_eq!(by_permutation, general, "o {o:?} d {d:?} t {t:?}");
                    hits += general.0.count_ones();
                    if !r.finite_inverse() {
                        continue;
                    }
                    finite += 1;
                    for (mask, near) in [
                        node_by_permutation::<true>(&r, &node, t),
                        node_for::<ANY_AXES, true>(&r, &node, t),
                    ] {
                        // The same distances (+0.0 for -0.0 where `t_min` is -0.0).
                        let same = (0..WIDTH).all(|k| {
                            f32::from_bits(near[k]) == f32::from_bits(general.1[k])
                                && (near[k] == general.1[k]
                                    || t[0].to_bits() == (-0.0f32).to_bits())
                        });
                        assert!(same, "o {o:?} d {d:?} t {t:?}: {near:?} {:?}", general.1);
                        assert_eq!(mask, general.0, "o {o:?} d {d:?} t {t:?}");
                        on_far_planes += (0..WIDTH)
                            .filter(|&k| {
                                // The far plane of axis `a` is `hi` for a ray going up it.
                                let b = node.bounds(k);
                                (0..3).any(|a| o[a] == if d[a] > 0.0 { b.hi[a] } else { b.lo[a] })
                            })
                            .count();
                    }
                }
            }
        }
        assert!(
            hits > 1000,
            "the rays hit {hits} children: too few to compare"
        );
        assert!(finite > 10_000, "{finite} rays with a finite inverse");
        assert!(
            on_far_planes > 1000,
            "{on_far_planes} children's far planes hold the origin"
        );
    }
}
