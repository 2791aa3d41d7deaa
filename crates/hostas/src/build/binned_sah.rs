//! Top-down binned SAH builder (Wald 2007), filling 4-wide nodes by repeatedly splitting the
//! child with the largest surface area. Primitive references are partitioned in place, so the
//! final order is the order of `refs` on return.

use super::tree::{Child, InnerNode, Tree};
use super::{MEDIAN_DEPTH, PARALLEL_THRESHOLD, PrimRef, pick_child_to_split};
use crate::math::Aabb;
use rayon::prelude::*;

pub const MAX_BINS: usize = 64;
/// SAH cost of traversing a node, relative to intersecting one primitive.
pub const TRAVERSAL_COST: f32 = 1.0;

/// Bounds of a range and of its primitives' (doubled) centroids.
#[derive(Clone, Copy, Debug)]
pub(crate) struct RangeInfo {
    pub bounds: Aabb,
    pub centroids: Aabb,
}

impl RangeInfo {
    pub const EMPTY: RangeInfo = RangeInfo { bounds: Aabb::EMPTY, centroids: Aabb::EMPTY };

    #[inline(always)]
    fn add(&mut self, r: &PrimRef) {
        self.bounds = self.bounds.union(&r.bounds());
        self.centroids.grow(r.center2());
    }
    fn merge(a: RangeInfo, b: RangeInfo) -> RangeInfo {
        RangeInfo { bounds: a.bounds.union(&b.bounds), centroids: a.centroids.union(&b.centroids) }
    }
    pub fn of(refs: &[PrimRef]) -> RangeInfo {
        if refs.len() > PARALLEL_THRESHOLD * 4 {
            return refs
                .par_chunks(PARALLEL_THRESHOLD)
                .map(RangeInfo::of)
                .reduce(|| RangeInfo::EMPTY, RangeInfo::merge);
        }
        let mut info = RangeInfo::EMPTY;
        for r in refs {
            info.add(r);
        }
        info
    }
}

struct Ctx {
    bins: usize,
    max_leaf: usize,
}

/// A chosen split: primitives whose bin on `axis` is below `bin` go left.
#[derive(Clone, Copy, Debug)]
struct Split {
    axis: usize,
    bin: usize,
    /// `area(left) * n(left) + area(right) * n(right)`.
    cost: f32,
}

#[derive(Clone, Copy)]
struct Binner {
    lo: [f32; 3],
    scale: [f32; 3],
    bins: usize,
}

impl Binner {
    fn new(centroids: &Aabb, bins: usize) -> Binner {
        let mut scale = [0f32; 3];
        for k in 0..3 {
            let ext = centroids.hi[k] - centroids.lo[k];
            scale[k] = if ext > 0.0 { bins as f32 * (1.0 - 1e-6) / ext } else { 0.0 };
        }
        Binner { lo: centroids.lo, scale, bins }
    }
    #[inline(always)]
    fn bin(&self, c: [f32; 3], k: usize) -> usize {
        let b = ((c[k] - self.lo[k]) * self.scale[k]) as usize; // NaN and negatives give 0
        b.min(self.bins - 1)
    }
}

#[derive(Clone)]
struct Bins {
    bounds: [[Aabb; MAX_BINS]; 3],
    counts: [[u32; MAX_BINS]; 3],
}

impl Bins {
    fn new() -> Bins {
        Bins { bounds: [[Aabb::EMPTY; MAX_BINS]; 3], counts: [[0; MAX_BINS]; 3] }
    }
    fn fill(binner: &Binner, refs: &[PrimRef]) -> Bins {
        let mut b = Bins::new();
        for r in refs {
            let c = r.center2();
            let rb = r.bounds();
            for k in 0..3 {
                let i = binner.bin(c, k);
                b.counts[k][i] += 1;
                b.bounds[k][i] = b.bounds[k][i].union(&rb);
            }
        }
        b
    }
    fn merge(mut a: Bins, b: Bins) -> Bins {
        for k in 0..3 {
            for i in 0..MAX_BINS {
                a.counts[k][i] += b.counts[k][i];
                a.bounds[k][i] = a.bounds[k][i].union(&b.bounds[k][i]);
            }
        }
        a
    }
}

fn find_split(refs: &[PrimRef], info: &RangeInfo, ctx: &Ctx) -> Option<(Split, Binner)> {
    let binner = Binner::new(&info.centroids, ctx.bins);
    if binner.scale == [0.0; 3] {
        return None;
    }
    let bins = if refs.len() > PARALLEL_THRESHOLD * 4 {
        refs.par_chunks(PARALLEL_THRESHOLD).map(|c| Bins::fill(&binner, c)).reduce(Bins::new, Bins::merge)
    } else {
        Bins::fill(&binner, refs)
    };
    let nb = ctx.bins;
    let mut best: Option<Split> = None;
    for k in 0..3 {
        if binner.scale[k] == 0.0 {
            continue;
        }
        // right_cost[i] = cost of bins i..nb as one side.
        let mut right_cost = [0f32; MAX_BINS];
        let mut acc = Aabb::EMPTY;
        let mut n = 0u32;
        for i in (1..nb).rev() {
            acc = acc.union(&bins.bounds[k][i]);
            n += bins.counts[k][i];
            right_cost[i] = acc.half_area() * n as f32;
        }
        let mut acc = Aabb::EMPTY;
        let mut n = 0u32;
        for i in 1..nb {
            acc = acc.union(&bins.bounds[k][i - 1]);
            n += bins.counts[k][i - 1];
            if n == 0 || n as usize == refs.len() {
                continue;
            }
            let cost = acc.half_area() * n as f32 + right_cost[i];
            if best.is_none_or(|b| cost < b.cost) {
                best = Some(Split { axis: k, bin: i, cost });
            }
        }
    }
    best.map(|s| (s, binner))
}

/// Partitions `refs` by `split`; returns the size of the left part and both parts' infos.
fn partition(refs: &mut [PrimRef], split: &Split, binner: &Binner) -> (usize, RangeInfo, RangeInfo) {
    let (mut left, mut right) = (RangeInfo::EMPTY, RangeInfo::EMPTY);
    let mut i = 0;
    let mut j = refs.len();
    while i < j {
        if binner.bin(refs[i].center2(), split.axis) < split.bin {
            left.add(&refs[i]);
            i += 1;
        } else {
            j -= 1;
            refs.swap(i, j);
            right.add(&refs[j]);
        }
    }
    (i, left, right)
}

/// Splits at the object median along the widest centroid axis; always makes two non-empty
/// halves, so it bounds depth and handles coincident centroids.
fn median_split(refs: &mut [PrimRef], info: &RangeInfo) -> (usize, RangeInfo, RangeInfo) {
    let mid = refs.len() / 2;
    let ext = [0, 1, 2].map(|k| info.centroids.hi[k] - info.centroids.lo[k]);
    let axis = (0..3).max_by(|&a, &b| ext[a].total_cmp(&ext[b])).unwrap_or(0);
    if ext[axis] > 0.0 {
        refs.select_nth_unstable_by(mid, |a, b| a.center2()[axis].total_cmp(&b.center2()[axis]).then(a.id.cmp(&b.id)));
    }
    (mid, RangeInfo::of(&refs[..mid]), RangeInfo::of(&refs[mid..]))
}

pub fn build(refs: &mut [PrimRef], bins: usize, max_leaf: usize) -> Tree {
    if refs.is_empty() {
        return Tree { root: None };
    }
    let ctx = Ctx { bins: bins.clamp(2, MAX_BINS), max_leaf: max_leaf.max(4) };
    let info = RangeInfo::of(refs);
    Tree { root: Some(build_child(refs, 0, info, &ctx, 0)) }
}

/// One child-to-be of a node during filling.
struct Part {
    begin: usize,
    end: usize,
    info: RangeInfo,
}

fn split_part(refs: &mut [PrimRef], info: &RangeInfo, ctx: &Ctx, depth: u32) -> (usize, RangeInfo, RangeInfo) {
    if depth < MEDIAN_DEPTH {
        if let Some((split, binner)) = find_split(refs, info, ctx) {
            let (mid, l, r) = partition(refs, &split, &binner);
            if mid > 0 && mid < refs.len() {
                return (mid, l, r);
            }
        }
    }
    median_split(refs, info)
}

fn build_child(refs: &mut [PrimRef], base: u32, info: RangeInfo, ctx: &Ctx, depth: u32) -> (Aabb, Child) {
    let n = refs.len();
    let leaf = (info.bounds, Child::Leaf { first: base, count: n as u32 });
    if n <= 3 {
        return leaf;
    }
    if n <= ctx.max_leaf {
        // SAH termination: a leaf when intersecting all is cheaper than the best split.
        let area = info.bounds.half_area();
        match find_split(refs, &info, ctx) {
            Some((split, _)) if TRAVERSAL_COST * area + split.cost < area * n as f32 => {}
            _ => return leaf,
        }
    }
    let mut parts = vec![Part { begin: 0, end: n, info }];
    while parts.len() < 4 {
        let keys: Vec<(usize, usize, f32)> = parts.iter().map(|p| (p.begin, p.end, p.info.bounds.half_area())).collect();
        let Some(i) = pick_child_to_split(&keys) else { break };
        let (begin, end) = (parts[i].begin, parts[i].end);
        let (mid, l, r) = split_part(&mut refs[begin..end], &parts[i].info, ctx, depth);
        parts[i] = Part { begin, end: begin + mid, info: l };
        parts.push(Part { begin: begin + mid, end, info: r });
    }
    parts.sort_by_key(|p| p.begin);
    // Hand each part its own disjoint slice, then build them (in parallel when large).
    let mut slices = Vec::with_capacity(parts.len());
    let mut rest = refs;
    let mut at = 0;
    for p in &parts {
        let (_, tail) = rest.split_at_mut(p.begin - at);
        let (mine, tail) = tail.split_at_mut(p.end - p.begin);
        slices.push((mine, base + p.begin as u32, p.info));
        rest = tail;
        at = p.end;
    }
    let children: Vec<(Aabb, Child)> = if n > PARALLEL_THRESHOLD {
        slices.into_par_iter().map(|(s, b, i)| build_child(s, b, i, ctx, depth + 1)).collect()
    } else {
        slices.into_iter().map(|(s, b, i)| build_child(s, b, i, ctx, depth + 1)).collect()
    };
    (info.bounds, Child::Inner(Box::new(InnerNode { children })))
}
