//! Closest (or first) hits for many rays at once, their walks interleaved: one thread walks
//! [`LANES`] rays in turn, one step (a node or a leaf) each, and requests the node or leaf
//! each ray goes to next before it turns to the others. A single ray's walk is a chain of dependent
//! loads (a node, then the child it picks); with several rays in flight the caches fetch one
//! ray's next node while the others are worked on.
//!
//! Every ray gets the hit [`Tracer::closest`](super::Tracer::closest) (or, with `FIRST`,
//! [`Tracer::any`](super::Tracer::any)) gives it, bit for bit: the steps of each ray are those
//! of the one-ray walk, in the same order (the root tested by the same general test, the
//! children ordered by the same distances), and with `FIRST` a ray's walk ends at its first
//! accepted hit, as the one-ray walk's does. Only rays of the common case go this way (one
//! identity instance of triangles, no culling, a direction with a finite inverse); the caller
//! traces the others one at a time.

use super::Ray;
use super::query::{ANY_AXES, BoxRay, Entry, descend, warm};
use super::scene::Hit;
use super::tracer::{Best, BlasStack, LeafTriangles, hit, leaf, pop};
use super::triangle::ShearedRay;
use crate::layout::view::View;
use crate::layout::{InstanceRecord, LEAF_BIT};

/// Rays walked at once by one thread.
pub(super) const LANES: usize = 8;

/// One ray's walk in progress.
#[derive(Clone, Copy)]
struct Lane {
    boxes: BoxRay,
    sheared: ShearedRay,
    t_min: f32,
    best: Best,
    /// Its entries on its stack.
    sp: usize,
    /// What it visits next.
    cur: Entry,
    /// Its place in the batch.
    ray: usize,
}

/// Walks the rays `order` (indices into `rays`, every one with permutation `P` and a finite
/// inverse) through the bottom level `view` of instance `inst`, triangles `tris`, [`LANES`]
/// at a time, and writes each ray's hit to `hits` (as long as `rays`): the closest, or with
/// `FIRST` the first accepted. `flip`: the instance flips facing.
#[allow(clippy::too_many_arguments)]
#[inline(never)]
pub(super) fn walk<const P: usize, T: LeafTriangles, const FIRST: bool>(
    view: &View,
    inst: &InstanceRecord,
    tris: T,
    flip: bool,
    rays: &[Ray],
    order: &[u32],
    stacks: &mut [BlasStack; LANES],
    hits: &mut [Hit],
) {
    let mut queue = order.iter();
    let idle = Lane {
        boxes: BoxRay::new([0.0; 3], [1.0; 3]),
        sheared: ShearedRay::new([0.0; 3], [1.0; 3]),
        t_min: 0.0,
        best: Best::miss(f32::INFINITY),
        sp: 0,
        cur: Entry::default(),
        ray: 0,
    };
    let mut lanes = [idle; LANES];
    // The lanes walking a ray.
    let mut live = 0u32;
    for (k, (lane, stack)) in lanes.iter_mut().zip(stacks.iter_mut()).enumerate() {
        if start::<P, T>(view, tris, rays, &mut queue, lane, stack, hits) {
            live |= 1 << k;
        }
    }
    while live != 0 {
        for (k, (lane, stack)) in lanes.iter_mut().zip(stacks.iter_mut()).enumerate() {
            if live & 1 << k == 0 || !step::<P, T, FIRST>(view, tris, flip, lane, stack) {
                continue;
            }
            if let Some(h) = hits.get_mut(lane.ray) {
                *h = hit(&lane.best, inst, Some(view));
            }
            if !start::<P, T>(view, tris, rays, &mut queue, lane, stack, hits) {
                live &= !(1 << k);
            }
        }
    }
}

/// Starts `lane` on the next ray of `queue` whose root test reaches a child (the rays before
/// it, reaching none, are done at once); `false` when the queue is empty.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn start<const P: usize, T: LeafTriangles>(
    view: &View,
    tris: T,
    rays: &[Ray],
    queue: &mut std::slice::Iter<u32>,
    lane: &mut Lane,
    stack: &mut BlasStack,
    hits: &mut [Hit],
) -> bool {
    for &i in queue.by_ref() {
        let Some(ray) = rays.get(i as usize) else {
            continue;
        };
        let boxes = BoxRay::new(ray.origin, ray.direction);
        lane.sp = 0;
        // The root by the general test, as the one-ray walk does.
        let Some(cur) = descend::<ANY_AXES>(
            stack,
            &mut lane.sp,
            view.nodes,
            tris,
            0,
            &boxes,
            ray.t_min,
            ray.t_max,
        ) else {
            if let Some(h) = hits.get_mut(i as usize) {
                *h = Hit::MISS;
            }
            continue;
        };
        warm(view.nodes, tris, &cur);
        lane.boxes = boxes;
        lane.sheared = boxes.sheared::<P>();
        lane.t_min = ray.t_min;
        lane.best = Best::miss(ray.t_max);
        lane.cur = cur;
        lane.ray = i as usize;
        return true;
    }
    false
}

/// One step of `lane`'s walk: its current node (then the child it goes to is requested) or
/// leaf, then the next entry. Returns whether the walk is over (with `FIRST`, also when the
/// leaf gave a hit).
#[inline(always)]
fn step<const P: usize, T: LeafTriangles, const FIRST: bool>(
    view: &View,
    tris: T,
    flip: bool,
    lane: &mut Lane,
    stack: &mut BlasStack,
) -> bool {
    let cur = lane.cur;
    if cur.child & LEAF_BIT == 0 {
        if let Some(next) = descend::<P>(
            stack,
            &mut lane.sp,
            view.nodes,
            tris,
            cur.child,
            &lane.boxes,
            lane.t_min,
            lane.best.t,
        ) {
            warm(view.nodes, tris, &next);
            lane.cur = next;
            return false;
        }
    } else if leaf::<P, T, FIRST, false>(
        tris,
        flip,
        &lane.sheared,
        lane.t_min,
        &mut lane.best,
        cur.child & !LEAF_BIT,
        cur.count,
    ) && FIRST
    {
        return true;
    }
    match pop(stack, &mut lane.sp, lane.best.t) {
        Some(e) => {
            lane.cur = e;
            false
        }
        None => true,
    }
}
