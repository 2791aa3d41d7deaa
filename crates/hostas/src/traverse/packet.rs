//! Closest hits for coherent rays (a camera's primary rays), [`PACKET`] at a time: one walk
//! over the nodes any of them reaches. The rays of a packet share an origin and the signs of
//! their directions ([`share_a_walk`]), so a node's planes lie at the same offsets from all of
//! them: the node test's subtractions are made once per node ([`BoxRay::offsets`]), and each
//! ray that reached the node finishes its own test from them (bit for bit the one-ray walk's).
//! The children any ray reaches are ordered and pushed once for all, each with the set of
//! rays that reach it. A leaf's triangles are fetched once and tested by each of its rays, in
//! the leaf's order. What a ray alone would pay per node beyond its box test (ordering the
//! children, pushing and popping them) the packet pays once.
//!
//! The packet visits nodes in another order than one ray alone, and where two candidates lie
//! at exactly the nearest distance, which of them is the hit depends on the order. The packet
//! tests every candidate that could tie (each lies in a leaf whose entry is at most that
//! distance), so it notes a ray that met one ([`Best::tied`]) and the caller traces that ray
//! again on its own: each ray's hit is the one [`Tracer::closest`](super::Tracer::closest)
//! gives it, bit for bit. Only closest hits go this way (a first hit depends on the order).
//!
//! A ray that reaches no child of the root is not gathered ([`Packets::take_back_if_missing`]):
//! most of a camera's rays that miss the structure miss it there, and for them a packet's
//! walk would only add its set-up.
//!
//! Where fewer than [`ALONE_BELOW`] rays of the packet reach a node, each walks its subtree
//! alone (the one-ray walk, [`trace_blas`]): the packet's own work (the rays' entries per
//! child, kept on its stack so that each ray prunes as it would alone) then no longer pays.

use super::Ray;
use super::query::{ANY_AXES, BoxRay, Entry, STACK_CAPACITY, nearest_first, prune_limit};
use super::scene::Hit;
use super::tracer::{
    Best, BlasAt, BlasStack, LeafTriangles, Walk, hit, leaf, take, take_nearest, trace_blas,
};
use super::triangle::ShearedRay;
use crate::layout::view::View;
use crate::layout::{InstanceRecord, LEAF_BIT, Node};
use crate::math::INTEGER_MIN_MAX;
use std::borrow::Borrow;
use wide::f32x8;

/// Rays walked together.
pub(super) const PACKET: usize = 8;

/// A packet walk's stack: the children to visit, and for each the entry distance of every
/// ray of the packet (+inf for a ray that does not reach it).
struct PacketStack {
    refs: [(u32, u32); STACK_CAPACITY],
    t: [f32x8; STACK_CAPACITY],
}

/// The rays of one packet (at most [`PACKET`], gathered by [`Packets::gather`]): a packet
/// writes the entries of its rays, and reads no others.
struct Packet {
    /// How many rays it holds, their indices in the batch, their permutation and the first.
    len: usize,
    group: [u32; PACKET],
    perm: usize,
    lead: Ray,
    boxes: [BoxRay; PACKET],
    sheared: [ShearedRay; PACKET],
    t_min: [f32; PACKET],
    best: [Best; PACKET],
}

/// What [`Packets::gather`] did with a ray.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Gather {
    Taken,
    /// Not gathered: the packet is full or walks apart from it (walk it, then gather again).
    Apart,
    /// Not gathered: a ray for the one-ray walk.
    Alone,
}

/// What a packet walk works in (about 26 KiB): made on the thread's stack per batch, or kept
/// by the tracer for short batches (see `LOCAL_PACKETS_FROM` in the tracer).
pub(super) struct Packets {
    stack: PacketStack,
    packet: Packet,
    /// The stack of a ray that walks a subtree alone.
    single: BlasStack,
}

impl Packets {
    /// The stack of a ray walked alone.
    pub(super) fn single(&mut self) -> &mut BlasStack {
        &mut self.single
    }

    /// Gathers ray `i` of a batch, `ray` (no culling or first-hit flag, the instance's mask
    /// met), with permutation `perm`, into the packet, prepared for the box test in its slot
    /// (made there, not copied). [`Gather::Apart`], gathering nothing, where the packet is
    /// full or the ray does not share the walk of its first ray (the same permutation and
    /// [`share_a_walk`]); [`Gather::Alone`] for a direction whose inverse is not finite.
    #[inline(always)]
    pub(super) fn gather(&mut self, i: u32, ray: &Ray, perm: usize) -> Gather {
        let p = &mut self.packet;
        let n = p.len;
        if n > 0 && (n >= PACKET || perm != p.perm || !share_a_walk(&p.lead, ray)) {
            return Gather::Apart;
        }
        let Some(boxes) = p.boxes.get_mut(n) else {
            return Gather::Apart;
        };
        *boxes = BoxRay::new(ray.origin, ray.direction);
        if !boxes.finite_inverse() {
            return Gather::Alone;
        }
        if n == 0 {
            (p.perm, p.lead) = (perm, *ray);
        }
        p.group[n] = i;
        p.t_min[n] = ray.t_min;
        p.best[n] = Best::miss(ray.t_max);
        p.len = n + 1;
        Gather::Taken
    }

    /// Takes the ray gathered last back out where it reaches no child of `root` (the bottom
    /// level's root node) within its `[t_min, t_max]`, and says so: its hit is a miss, as alone
    /// (the same test as the one-ray walk's first). Under callgrind (primary rays, 128 x 128)
    /// this took 2.6-5.7% of the meshes' instructions off their packets, 9% off the crown's
    /// (83% of whose rays miss it).
    #[inline(always)]
    pub(super) fn take_back_if_missing(&mut self, root: &Node) -> bool {
        let p = &mut self.packet;
        let Some(last) = p.len.checked_sub(1) else {
            return false;
        };
        let (Some(boxes), Some(&t_min), Some(best)) =
            (p.boxes.get(last), p.t_min.get(last), p.best.get(last))
        else {
            return false;
        };
        // (`best.t` is the ray's `t_max`: nothing is found before the walk.)
        let missing = boxes.node::<ANY_AXES>(root, t_min, best.t).0 == 0;
        if missing {
            p.len = last;
        }
        missing
    }

    /// The batch's indices of the rays gathered, and their permutation.
    pub(super) fn gathered(&self) -> (&[u32], usize) {
        let p = &self.packet;
        (p.group.get(..p.len).unwrap_or_default(), p.perm)
    }

    /// Empties the packet, for the next rays.
    pub(super) fn clear(&mut self) {
        self.packet.len = 0;
    }

    #[inline(always)]
    pub(super) fn new() -> Packets {
        let idle = BoxRay::new([0.0; 3], [1.0; 3]);
        Packets {
            stack: PacketStack {
                refs: [(0, 0); STACK_CAPACITY],
                t: [f32x8::ZERO; STACK_CAPACITY],
            },
            packet: Packet {
                len: 0,
                group: [0; PACKET],
                perm: 0,
                lead: Ray::new([0.0; 3], [1.0; 3]),
                boxes: [idle; PACKET],
                sheared: [ShearedRay::new([0.0; 3], [1.0; 3]); PACKET],
                t_min: [0.0; PACKET],
                best: [Best::miss(f32::NEG_INFINITY); PACKET],
            },
            single: [Entry::default(); STACK_CAPACITY],
        }
    }
}

/// The farthest entry distance at which ray `best` may still find a nearer hit: at most
/// `f32::MAX`, so that +inf (a child the ray does not reach) is always past it.
#[inline(always)]
fn limit_of(best: &Best) -> f32 {
    prune_limit(best.t).min(f32::MAX)
}

/// Whether rays `a` and `b` may walk in one packet: the same origin and the same signs of
/// direction, bit for bit, so that a node's planes lie at the same offsets from both and both
/// read the same planes (the node test's subtractions, made once for the packet).
#[inline(always)]
pub(super) fn share_a_walk(a: &Ray, b: &Ray) -> bool {
    // (Differences as bits, every lane at once: one branch.)
    let apart =
        |u: [f32; 3], v: [f32; 3]| (0..3).fold(0, |m, k| m | (u[k].to_bits() ^ v[k].to_bits()));
    (apart(a.origin, b.origin) | (apart(a.direction, b.direction) & 1 << 31)) == 0
}

/// What a packet's walk did: the rays that met a tie, and how the packet held together.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Walked {
    /// The rays (bits, in the order gathered) that met a tie, whose hits the caller must make
    /// again by the one-ray walk.
    pub tied: u32,
    /// Rays that reached a leaf together with another ray of the packet.
    pub at_leaves: u32,
    /// Subtrees a ray walked alone, the packet having fallen apart above them.
    pub alone: u32,
}

impl Walked {
    /// Adds `other`'s counts to these (the ties are a packet's own: not added).
    pub(super) fn add(&mut self, other: &Walked) {
        self.at_leaves = self.at_leaves.saturating_add(other.at_leaves);
        self.alone = self.alone.saturating_add(other.alone);
    }
}

/// Whether packets, as walked so far (`w`), fell apart before their leaves: once
/// [`JUDGED_FROM`] subtrees were walked alone or rays reached a leaf together, `Some(true)`
/// where subtrees were walked alone more than eight times as often as rays reached a leaf
/// together. Such rays share only the upper nodes, where the packet's own work (its rays'
/// entries per child) costs more than it saves. (Primary rays at 256 x 256, per batch of
/// 1,024: the 1M-triangle sphere's at most 0.06 rays reached a leaf together per subtree
/// walked alone; the soup's, boxes', the bunny's and the other meshes' at least 0.21.)
pub(super) fn fell_apart(w: &Walked) -> Option<bool> {
    (w.alone.saturating_add(w.at_leaves) >= JUDGED_FROM)
        .then(|| w.at_leaves.saturating_mul(8) < w.alone)
}

/// How many subtrees walked alone and rays that reached a leaf together [`fell_apart`] waits
/// for.
const JUDGED_FROM: u32 = 64;

/// Whether `packets` packets, walked as `w`, split often on the way to their leaves: at least
/// [`SPLIT_OFTEN`] subtrees walked alone per packet. A camera's rows then go in blocks of
/// pixels ([`super::tile`]), whose rays stay together longer; where packets split seldom,
/// blocks measured slower. Per packet, primary rays at 256 x 256 (`Interleave::Packets`), row
/// by row: the 1M-triangle soup 13.5, boxes 18.0, the bunny 5.6, Sibenik 1.9, Sponza 0.8, the
/// conference 0.5; in blocks: 11.3, 14.7, 4.3, 1.2, 0.6, 0.3. On the lent Xeon, against
/// Embree MEDIUM (medians of six rounds), blocks for every camera took the soup from 0.94 to
/// 1.02 and boxes from 0.93 to 1.00, but the conference from 1.59 to 1.38 and Sponza from 1.68
/// to 1.51; chosen by this test (eight rounds), boxes went from 0.89 to 0.98, the bunny from
/// 1.06 to 1.09, the soup from 0.95 to 0.96, the others within the rounds' spread.
pub(super) fn split_often(w: &Walked, packets: u32) -> bool {
    packets > 0 && w.alone >= SPLIT_OFTEN.saturating_mul(packets)
}

/// See [`split_often`].
const SPLIT_OFTEN: u32 = 3;

/// Walks the rays gathered in `work` (of batch `rays`, with permutation `P`, as coherent as
/// may be) through the bottom level `view` of instance `inst`, triangles `tris`, and writes
/// each ray's closest hit to `hits`. `flip`: the instance flips facing.
#[allow(clippy::too_many_arguments)]
#[inline(never)]
pub(super) fn walk<const P: usize, T: LeafTriangles>(
    view: &View,
    inst: &InstanceRecord,
    tris: T,
    flip: bool,
    rays: &[Ray],
    work: &mut Packets,
    hits: &mut [Hit],
) -> Walked {
    let Packets {
        stack,
        packet,
        single,
    } = work;
    let group = packet.group.get(..packet.len).unwrap_or_default();
    // Per ray (-inf past the packet's rays, which then never reach anything).
    let mut limit = [f32::NEG_INFINITY; PACKET];
    for (l, best) in limit.iter_mut().zip(&packet.best).take(group.len()) {
        *l = limit_of(best);
    }
    let live = (1u32 << group.len()) - 1;
    let mut limits = f32x8::from(limit);
    // The rays prepared for the triangle test (when they first reach a leaf: most rays of a
    // camera that miss the structure never do).
    let mut sheared = 0u32;
    let (mut child, mut count, mut rays_in) = (0u32, 0u32, live);
    let mut sp = 0usize;
    let nodes = view.nodes;
    let at = BlasAt { view, inst };
    let mut walked = Walked::default();
    loop {
        if rays_in.count_ones() < ALONE_BELOW {
            walked.alone += rays_in.count_ones();
            // Too few rays left for the packet's work to pay: each walks the subtree alone.
            for r in each(rays_in) {
                let Some(ray) = group.get(r).and_then(|&i| rays.get(i as usize)) else {
                    continue;
                };
                let walk = Walk {
                    sp: 0,
                    cur: Entry {
                        child,
                        count,
                        t: 0.0,
                    },
                };
                let best = &mut packet.best[r];
                if trace_blas::<P, T, true, false, true>(
                    single,
                    walk,
                    &at,
                    tris,
                    &packet.boxes[r],
                    ray,
                    best,
                ) {
                    limit[r] = limit_of(best);
                    limits = f32x8::from(limit);
                }
            }
        } else if child & LEAF_BIT == 0 {
            if let Some(node) = nodes.get(child as usize) {
                crate::math::prefetch(&node.child);
                // The planes' offsets from the packet's origin, for all its rays.
                let first = rays_in.trailing_zeros() as usize & (PACKET - 1);
                let offsets = packet.boxes[first].offsets::<P>(node);
                // The children some ray reaches, the rays that reach some child, and row `r`:
                // ray `r`'s entry distance per child, +inf where it does not reach it (every
                // child, for a ray that reaches none or did not reach the node).
                let (mut reached, mut reaching) = (0u32, 0u32);
                let mut rows = [INF8; PACKET];
                let mut near = INF8;
                for r in each(rays_in) {
                    let (t, missed) = packet.boxes[r].slabs_from::<INTEGER_MIN_MAX>(
                        &offsets,
                        packet.t_min[r],
                        packet.best[r].t,
                    );
                    let hit = !missed.to_bitmask() & 0xff;
                    reached |= hit;
                    reaching |= u32::from(hit != 0) << r;
                    let row = missed.select(INF8, t);
                    rows[r] = row;
                    near = near.fast_min(row);
                }
                if reached != 0 && reached & (reached - 1) == 0 {
                    // One child: every ray that reaches a child reaches it, and nothing is
                    // pushed.
                    let k = reached.trailing_zeros() as usize & 7;
                    (child, count) = (node.child[k], node.count[k] as u32);
                    rays_in = reaching;
                    continue;
                }
                let rest = reached & reached.wrapping_sub(1);
                if reached != 0 && rest & (rest - 1) == 0 {
                    // Two children (no transpose, no ranks): the farther pushed with its
                    // rays' entries, the nearer visited (on a tie the later lane, as
                    // `descend` orders them).
                    let near = near.to_array();
                    let (a, b) = (
                        reached.trailing_zeros() as usize & 7,
                        rest.trailing_zeros() as usize & 7,
                    );
                    let (far, nearer) = if near[a] < near[b] { (b, a) } else { (a, b) };
                    let column =
                        |k: usize| f32x8::from(std::array::from_fn(|r| rows[r].as_array()[k]));
                    let (Some(r), Some(t)) = (stack.refs.get_mut(sp), stack.t.get_mut(sp)) else {
                        return Walked {
                            tied: live,
                            ..walked
                        };
                    };
                    *r = (node.child[far], node.count[far] as u32);
                    *t = column(far);
                    sp += 1;
                    (child, count) = (node.child[nearer], node.count[nearer] as u32);
                    rays_in = column(nearer).simd_lt(INF8).to_bitmask();
                    continue;
                }
                if reached != 0 {
                    // The nearest entry per child orders them; column `k`: child `k`'s rays.
                    let near = near.to_array();
                    let columns = f32x8::transpose(rows);
                    let order = nearest_first(&near, reached);
                    let n = reached.count_ones() as usize;
                    // Farthest deepest; the nearest is visited next, not pushed. (Room for a
                    // node's children on any validated view, as for the one-ray walk.)
                    let (Some(refs), Some(ts)) =
                        (stack.refs.get_mut(sp..sp + n), stack.t.get_mut(sp..sp + n))
                    else {
                        return Walked {
                            tied: live,
                            ..walked
                        };
                    };
                    for ((r, t), &k) in refs.iter_mut().zip(ts).zip(order[..n].iter().rev()) {
                        let k = k as usize & 7;
                        *r = (node.child[k], node.count[k] as u32);
                        *t = columns[k];
                    }
                    let k = order[0] as usize & 7;
                    (child, count) = (node.child[k], node.count[k] as u32);
                    rays_in = columns[k].simd_lt(INF8).to_bitmask();
                    sp += n - 1;
                    continue;
                }
            }
        } else {
            let first = child & !LEAF_BIT;
            for r in each(rays_in & !sheared) {
                packet.sheared[r] = packet.boxes[r].sheared::<P>();
            }
            sheared |= rays_in;
            let mut accepted = 0u32;
            let eight_wide = T::NEAREST_FROM != u32::MAX && count >= T::NEAREST_FROM;
            let ready = if eight_wide {
                tris.ready(first as usize, count as usize)
            } else {
                None
            };
            // (The two eight-wide loops apart: one loop choosing per ray took the soup's
            // packets 2% more instructions.)
            if let Some(ready) = ready {
                // (A leaf of up to eight direct triangles, transposed once for all the rays.)
                for r in each(rays_in) {
                    let best = &mut packet.best[r];
                    let (sheared, t_min) = (&packet.sheared[r], packet.t_min[r]);
                    let found = tris.nearest_ready::<P>(&ready, sheared, t_min, best.tie_bound());
                    if take_nearest::<true>(best, found, first, flip) {
                        accepted |= 1 << r;
                    }
                }
            } else if eight_wide {
                // (More than eight: each ray alone, chunk by chunk.)
                for r in each(rays_in) {
                    let best = &mut packet.best[r];
                    let (sheared, t_min) = (&packet.sheared[r], packet.t_min[r]);
                    if leaf::<P, T, false, true>(tris, flip, sheared, t_min, best, first, count) {
                        accepted |= 1 << r;
                    }
                }
            } else {
                // Triangle by triangle, each fetched (an indexed one gathered) once for all
                // the rays; each ray still tests them in the leaf's order, as alone.
                for (p, tri) in (first..).zip(tris.leaf(first as usize, count as usize)) {
                    let tri = tri.borrow();
                    for r in each(rays_in) {
                        let Some(h) = T::intersect::<P>(&packet.sheared[r], tri) else {
                            continue;
                        };
                        let best = &mut packet.best[r];
                        if take::<true>(best, packet.t_min[r], p, &h, flip) {
                            accepted |= 1 << r;
                        }
                    }
                }
            }
            if accepted != 0 {
                for r in each(accepted) {
                    limit[r] = limit_of(&packet.best[r]);
                }
                limits = f32x8::from(limit);
            }
        }
        // The nearest entry that some of its rays may still find a nearer hit in.
        loop {
            if sp == 0 {
                walked.at_leaves = sheared.count_ones();
                for (r, &i) in group.iter().enumerate().take(PACKET) {
                    walked.tied |= u32::from(packet.best[r].tied) << r;
                    if let Some(h) = hits.get_mut(i as usize) {
                        *h = hit(&packet.best[r], inst, Some(view));
                    }
                }
                return walked;
            }
            sp -= 1;
            let (Some(&r), Some(t)) = (stack.refs.get(sp), stack.t.get(sp)) else {
                return Walked {
                    tied: live,
                    ..walked
                };
            };
            let open = t.simd_le(limits).to_bitmask();
            if open != 0 {
                (child, count, rays_in) = (r.0, r.1, open);
                break;
            }
        }
    }
}

/// The packet's rays whose bits `mask` sets, lowest first.
#[inline(always)]
pub(super) fn each(mut mask: u32) -> impl Iterator<Item = usize> {
    std::iter::from_fn(move || {
        (mask != 0).then(|| {
            let r = mask.trailing_zeros() as usize & (PACKET - 1);
            mask &= mask - 1;
            r
        })
    })
}

/// Fewer rays than this reaching a node walk its subtree one at a time.
const ALONE_BELOW: u32 = 2;

const INF8: f32x8 = f32x8::new([f32::INFINITY; 8]);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::traverse::triangle::{TriangleHit, by_permutation, permutation};

    /// A packet gathers a ray only where it shares the walk of the packet's first ray (its
    /// node test subtracts the planes from that origin once for all): the same permutation,
    /// origin and signs of direction, bit for bit; and at most eight.
    #[test]
    fn a_packet_gathers_only_rays_that_share_its_walk() {
        let ray = |o: [f32; 3], d: [f32; 3]| Ray::new(o, d);
        let (o, d) = ([0.5, 0.5, 4.0], [0.1, -0.2, -1.0]);
        let others = [
            ray([0.5, 0.5, 4.5], d),
            ray([-0.0, 0.5, 4.0], d),
            ray(o, [-0.1, -0.2, -1.0]),
            ray(o, [0.1, 0.0, -1.0]),
        ];
        let mut work = Box::new(Packets::new());
        for other in &others {
            work.clear();
            let first = ray(o, d);
            let gather = |w: &mut Packets, i: u32, r: &Ray| {
                w.gather(i, r, permutation(r.direction)) == Gather::Taken
            };
            assert!(gather(&mut work, 0, &first));
            assert!(!gather(&mut work, 1, other), "{other:?} is not gathered");
            // (The same ray, under another permutation: not gathered either.)
            let p = permutation(d);
            assert_eq!(work.gather(1, &first, (p + 1) % 6), Gather::Apart);
            for i in 1..8 {
                let near = ray(o, [0.1 + 0.01 * i as f32, -0.2, -1.0]);
                assert!(gather(&mut work, i, &near));
            }
            assert!(!gather(&mut work, 8, &first), "full");
            assert_eq!(work.gathered(), (&[0, 1, 2, 3, 4, 5, 6, 7][..], p));
        }
        // A zero component (an infinite inverse) goes alone, gathering nothing.
        work.clear();
        let flat = ray(o, [0.1, 0.0, -1.0]);
        assert_eq!(
            work.gather(0, &flat, permutation(flat.direction)),
            Gather::Alone
        );
        assert_eq!(work.gathered().0.len(), 0);
        let origin_zero = [ray([0.0, 0.5, 4.0], d), ray([-0.0, 0.5, 4.0], d)];
        assert!(
            !share_a_walk(&origin_zero[0], &origin_zero[1]),
            "-0 and +0 apart"
        );
    }

    /// A ray gathered that reaches no child of the root within its `[t_min, t_max]` is taken
    /// back out of the packet (its hit is a miss, as alone); one that reaches a child stays.
    #[test]
    fn a_ray_that_misses_the_root_is_taken_back() {
        let mut root = Node::EMPTY;
        let unit = crate::math::Aabb {
            lo: [-1.0; 3],
            hi: [1.0; 3],
        };
        root.set_bounds(3, &unit);
        let o = [0.0, 0.0, 5.0];
        let toward = Ray::new(o, [0.01, 0.02, -1.0]);
        // (Past the box: x is 1.2 or more from z = 1 down to z = -1.)
        let past = Ray::new(o, [0.3, 0.02, -1.0]);
        let mut short = toward;
        short.t_max = 3.0;
        let mut work = Box::new(Packets::new());
        let perm = permutation(toward.direction);
        for (i, r) in [toward, past, short].iter().enumerate() {
            assert_eq!(work.gather(i as u32, r, perm), Gather::Taken);
            let missing = work.take_back_if_missing(&root);
            assert_eq!(missing, i > 0, "ray {i}");
        }
        assert_eq!(work.gathered(), (&[0][..], perm));
    }

    /// A packet's leaf test (of three triangles: the eight-wide test where the build has AVX,
    /// else the loop) notes a candidate at exactly the hit's distance, found earlier in another
    /// leaf, and does not take it; a nearer one it takes, noting nothing.
    #[test]
    fn a_leaf_notes_a_tie_with_the_hit_so_far() {
        let flat = |x: f32, z: f32| [x, 0.0, z, x + 1.0, 0.0, z, x, 1.0, z];
        // One at z = 0 (the hit's distance), one off the ray, and one farther (z = -1, after
        // it) or nearer (z = 1, before it).
        for (z, tied) in [(-1.0, true), (1.0, false)] {
            let other = flat(0.0, z);
            let (off, at_hit) = (flat(5.0, -2.0), flat(0.0, 0.0));
            let tris = if tied {
                [off, at_hit, other]
            } else {
                [other, off, at_hit]
            };
            let tris = &tris[..];
            let hit_slot = if tied { 1 } else { 2 };
            let d = [1e-3, 2e-3, -1.0];
            let boxes = BoxRay::new([0.2, 0.2, 4.0], d);
            by_permutation!(permutation(d), P => {
                let sheared = boxes.sheared::<P>();
                // The hit so far: the middle triangle's distance, from a copy in another leaf.
                let t = sheared.intersect_axes::<P>(&tris[hit_slot]).unwrap().t;
                let mut best = Best::miss(f32::INFINITY);
                let h = TriangleHit { t, b: 0.0, c: 0.0, front_face: true };
                best.accept_triangle(7, &h, true);
                let accepted = leaf::<P, &[[f32; 9]], false, true>(tris, false, &sheared, 0.0, &mut best, 0, 3);
                if tied {
                    assert!(best.tied && !accepted, "the tie is noted, not taken");
                    assert_eq!(best.t, t);
                } else {
                    assert!(!best.tied && accepted, "the nearer one is taken");
                    assert!(best.t < t);
                }
            });
        }
    }
}
