//! Top-down binned SAH builder (Wald 2007), filling 8-wide nodes by repeatedly splitting the
//! child with the largest surface area. Primitive references are partitioned in place, so the
//! final order is the order of `refs` on return. Small ranges are split with an exact SAH
//! sweep over sorted centroids instead of bins.

use super::tree::{Child, InnerNode, Tree};
use super::{MEDIAN_DEPTH, PARALLEL_THRESHOLD, PrimRef};
use crate::layout::WIDTH;
use crate::math::{Aabb, fmax, fmin};
use rayon::prelude::*;

pub const MAX_BINS: usize = 32;
/// Ranges up to this size are split by an exact sweep instead of binning.
const SMALL: usize = 16;

/// A box as two 4-lane arrays, so that growing it compiles to one `minps` and one `maxps`.
/// Lane 3 carries whatever the source had there (a primitive id) and is ignored.
#[derive(Clone, Copy, Debug)]
struct B4 {
    lo: [f32; 4],
    hi: [f32; 4],
}

impl B4 {
    const EMPTY: B4 = B4 {
        lo: [f32::INFINITY; 4],
        hi: [f32::NEG_INFINITY; 4],
    };

    #[inline(always)]
    fn of(r: &PrimRef) -> B4 {
        let [lo, hi]: [[f32; 4]; 2] = bytemuck::cast(*r);
        B4 { lo, hi }
    }
    #[inline(always)]
    fn grow(&mut self, o: &B4) {
        for i in 0..4 {
            self.lo[i] = fmin(self.lo[i], o.lo[i]);
            self.hi[i] = fmax(self.hi[i], o.hi[i]);
        }
    }
    #[inline(always)]
    fn grow_point(&mut self, p: &[f32; 4]) {
        for i in 0..4 {
            self.lo[i] = fmin(self.lo[i], p[i]);
            self.hi[i] = fmax(self.hi[i], p[i]);
        }
    }
    #[inline(always)]
    fn half_area(&self) -> f32 {
        let d = [
            self.hi[0] - self.lo[0],
            self.hi[1] - self.lo[1],
            self.hi[2] - self.lo[2],
        ];
        if d[0] < 0.0 || d[1] < 0.0 || d[2] < 0.0 {
            return 0.0;
        }
        d[0] * d[1] + d[1] * d[2] + d[2] * d[0]
    }
    fn aabb(&self) -> Aabb {
        Aabb {
            lo: [self.lo[0], self.lo[1], self.lo[2]],
            hi: [self.hi[0], self.hi[1], self.hi[2]],
        }
    }
}

/// Bounds of a range and of its primitives' (doubled) centroids.
#[derive(Clone, Copy, Debug)]
pub(crate) struct RangeInfo {
    pub bounds: Aabb,
    pub centroids: Aabb,
}

/// [`RangeInfo`] while it is being accumulated.
#[derive(Clone, Copy)]
struct Acc {
    bounds: B4,
    centroids: B4,
}

impl Acc {
    const EMPTY: Acc = Acc {
        bounds: B4::EMPTY,
        centroids: B4::EMPTY,
    };
    #[inline(always)]
    fn add(&mut self, r: &PrimRef) {
        let b = B4::of(r);
        self.bounds.grow(&b);
        let c = [b.lo[0] + b.hi[0], b.lo[1] + b.hi[1], b.lo[2] + b.hi[2], 0.0];
        self.centroids.grow_point(&c);
    }
    fn info(&self) -> RangeInfo {
        RangeInfo {
            bounds: self.bounds.aabb(),
            centroids: self.centroids.aabb(),
        }
    }
}

impl RangeInfo {
    pub const EMPTY: RangeInfo = RangeInfo {
        bounds: Aabb::EMPTY,
        centroids: Aabb::EMPTY,
    };

    fn merge(a: RangeInfo, b: RangeInfo) -> RangeInfo {
        RangeInfo {
            bounds: a.bounds.union(&b.bounds),
            centroids: a.centroids.union(&b.centroids),
        }
    }
    pub fn of(refs: &[PrimRef]) -> RangeInfo {
        if refs.len() > PARALLEL_THRESHOLD * 4 {
            return refs
                .par_chunks(PARALLEL_THRESHOLD)
                .map(RangeInfo::of)
                .reduce(|| RangeInfo::EMPTY, RangeInfo::merge);
        }
        let mut acc = Acc::EMPTY;
        for r in refs {
            acc.add(r);
        }
        acc.info()
    }
}

struct Ctx {
    bins: usize,
    max_leaf: usize,
    traversal_cost: f32,
}

/// A two-way split of a range: `mid` primitives go left, with the infos of both sides and the
/// SAH numerator `area(left) * n(left) + area(right) * n(right)`.
#[derive(Clone, Copy, Debug)]
struct Split {
    mid: usize,
    left: RangeInfo,
    right: RangeInfo,
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
            scale[k] = if ext > 0.0 {
                bins as f32 * (1.0 - 1e-6) / ext
            } else {
                0.0
            };
        }
        Binner {
            lo: centroids.lo,
            scale,
            bins,
        }
    }
    #[inline(always)]
    fn bin(&self, c: f32, k: usize) -> usize {
        // Clamped in float first, so the conversion is a plain truncation (NaN gives 0).
        let f = fmin(
            fmax((c - self.lo[k]) * self.scale[k], 0.0),
            (self.bins - 1) as f32,
        );
        f as i32 as usize
    }
}

struct Bins<const N: usize> {
    bounds: [[B4; N]; 3],
    counts: [[u32; N]; 3],
}

impl<const N: usize> Bins<N> {
    fn new() -> Bins<N> {
        Bins {
            bounds: [[B4::EMPTY; N]; 3],
            counts: [[0; N]; 3],
        }
    }
    fn fill(&mut self, binner: &Binner, refs: &[PrimRef]) {
        for r in refs {
            let rb = B4::of(r);
            for k in 0..3 {
                let i = binner.bin(rb.lo[k] + rb.hi[k], k).min(N - 1);
                self.counts[k][i] += 1;
                self.bounds[k][i].grow(&rb);
            }
        }
    }
    fn merge(mut self, b: Bins<N>) -> Bins<N> {
        for k in 0..3 {
            for i in 0..N {
                self.counts[k][i] += b.counts[k][i];
                self.bounds[k][i].grow(&b.bounds[k][i]);
            }
        }
        self
    }

    /// The best split plane: (axis, first bin of the right side, cost).
    fn best(&self, binner: &Binner, n_total: usize) -> Option<(usize, usize, f32)> {
        let mut best: Option<(usize, usize, f32)> = None;
        for k in 0..3 {
            if binner.scale[k] == 0.0 {
                continue;
            }
            let mut right_cost = [0f32; N];
            let mut acc = B4::EMPTY;
            let mut n = 0u32;
            for i in (1..N).rev() {
                acc.grow(&self.bounds[k][i]);
                n += self.counts[k][i];
                right_cost[i] = acc.half_area() * n as f32;
            }
            let mut acc = B4::EMPTY;
            let mut n = 0u32;
            for i in 1..N {
                acc.grow(&self.bounds[k][i - 1]);
                n += self.counts[k][i - 1];
                if n == 0 || n as usize == n_total {
                    continue;
                }
                let cost = acc.half_area() * n as f32 + right_cost[i];
                if best.is_none_or(|b| cost < b.2) {
                    best = Some((k, i, cost));
                }
            }
        }
        best
    }
}

fn best_bin_split_n<const N: usize>(
    refs: &[PrimRef],
    binner: &Binner,
) -> Option<(usize, usize, f32)> {
    let bins = if refs.len() > PARALLEL_THRESHOLD * 4 {
        refs.par_chunks(PARALLEL_THRESHOLD)
            .map(|c| {
                let mut b = Bins::<N>::new();
                b.fill(binner, c);
                b
            })
            .reduce(Bins::new, Bins::merge)
    } else {
        let mut b = Bins::<N>::new();
        b.fill(binner, refs);
        b
    };
    bins.best(binner, refs.len())
}

/// The best binned split plane, with as many bins as `binner` says (8, 16 or 32).
fn best_bin_split(refs: &[PrimRef], binner: &Binner) -> Option<(usize, usize, f32)> {
    match binner.bins {
        0..=8 => best_bin_split_n::<8>(refs, binner),
        9..=16 => best_bin_split_n::<16>(refs, binner),
        _ => best_bin_split_n::<32>(refs, binner),
    }
}

/// Partitions a large range on all threads: count each chunk's left side, then scatter every
/// chunk into `aux` at its prefix-sum positions and copy back. The result is the same as a
/// sequential stable partition, whatever the thread count.
fn parallel_partition(
    refs: &mut [PrimRef],
    aux: &mut [PrimRef],
    left_of: impl Fn(&PrimRef) -> bool + Sync,
) -> (usize, RangeInfo, RangeInfo) {
    const CHUNK: usize = PARALLEL_THRESHOLD * 4;
    let lefts: Vec<usize> = refs
        .par_chunks(CHUNK)
        .map(|c| c.iter().filter(|r| left_of(r)).count())
        .collect();
    let total_left: usize = lefts.iter().sum();
    // Each chunk writes its own disjoint pieces of `aux`: carve them in order.
    let (mut left_part, mut right_part) = aux.split_at_mut(total_left);
    let mut pieces = Vec::with_capacity(lefts.len());
    for (i, n) in lefts.iter().enumerate() {
        let len = CHUNK.min(refs.len() - i * CHUNK);
        let (lp, lrest) = left_part.split_at_mut(*n);
        let (rp, rrest) = right_part.split_at_mut(len - n);
        pieces.push((lp, rp));
        left_part = lrest;
        right_part = rrest;
    }
    let infos: Vec<(Acc, Acc)> = refs
        .par_chunks(CHUNK)
        .zip(pieces.into_par_iter())
        .map(|(c, (lp, rp))| {
            let (mut la, mut ra) = (Acc::EMPTY, Acc::EMPTY);
            let (mut li, mut ri) = (0, 0);
            for r in c {
                if left_of(r) {
                    lp[li] = *r;
                    li += 1;
                    la.add(r);
                } else {
                    rp[ri] = *r;
                    ri += 1;
                    ra.add(r);
                }
            }
            (la, ra)
        })
        .collect();
    refs.par_chunks_mut(CHUNK)
        .zip(aux.par_chunks(CHUNK))
        .for_each(|(d, s)| d.copy_from_slice(s));
    let (left, right) = infos
        .iter()
        .fold((RangeInfo::EMPTY, RangeInfo::EMPTY), |(l, r), (a, b)| {
            (RangeInfo::merge(l, a.info()), RangeInfo::merge(r, b.info()))
        });
    (total_left, left, right)
}

/// Binned split, partitioning `refs` in place (through `aux` when large).
fn binned_split(
    refs: &mut [PrimRef],
    aux: &mut [PrimRef],
    info: &RangeInfo,
    ctx: &Ctx,
) -> Option<Split> {
    // Small ranges gain nothing from many bins; they only pay for sweeping them.
    let bins = if refs.len() < 256 {
        ctx.bins.min(8)
    } else {
        ctx.bins
    };
    let binner = Binner::new(&info.centroids, bins);
    if binner.scale == [0.0; 3] {
        return None;
    }
    let (axis, bin, cost) = best_bin_split(refs, &binner)?;
    if refs.len() > PARALLEL_THRESHOLD * 16 {
        let (mid, left, right) = parallel_partition(refs, aux, |r| {
            binner.bin(r.lo[axis] + r.hi[axis], axis) < bin
        });
        return (mid > 0 && mid < refs.len()).then_some(Split {
            mid,
            left,
            right,
            cost,
        });
    }
    let (mut left, mut right) = (Acc::EMPTY, Acc::EMPTY);
    let (mut i, mut j) = (0, refs.len());
    while i < j {
        let r = refs[i];
        if binner.bin(r.lo[axis] + r.hi[axis], axis) < bin {
            left.add(&r);
            i += 1;
        } else {
            j -= 1;
            refs.swap(i, j);
            right.add(&r);
        }
    }
    (i > 0 && i < refs.len()).then_some(Split {
        mid: i,
        left: left.info(),
        right: right.info(),
        cost,
    })
}

/// Exact SAH split of a small range: order by centroid on each axis (a sort of small keys, not
/// of the references) and sweep every position; the references are permuted once, for the
/// winning axis.
fn sweep_split(refs: &mut [PrimRef]) -> Split {
    let n = refs.len();
    debug_assert!(n <= SMALL);
    let boxes: [B4; SMALL] =
        std::array::from_fn(|i| if i < n { B4::of(&refs[i]) } else { B4::EMPTY });
    let mut best = (f32::INFINITY, 0usize, n / 2);
    let mut best_order = [0u8; SMALL];
    let mut right_area = [0f32; SMALL];
    for k in 0..3 {
        // Insertion sort of (centroid, index): ties keep input order, so the result is
        // deterministic.
        let mut order = [0u8; SMALL];
        let mut key = [0f32; SMALL];
        for i in 0..n {
            let c = boxes[i].lo[k] + boxes[i].hi[k];
            let mut j = i;
            while j > 0 && key[j - 1] > c {
                key[j] = key[j - 1];
                order[j] = order[j - 1];
                j -= 1;
            }
            key[j] = c;
            order[j] = i as u8;
        }
        let mut acc = B4::EMPTY;
        for i in (1..n).rev() {
            acc.grow(&boxes[order[i] as usize]);
            right_area[i] = acc.half_area();
        }
        let mut acc = B4::EMPTY;
        for i in 1..n {
            acc.grow(&boxes[order[i - 1] as usize]);
            let cost = acc.half_area() * i as f32 + right_area[i] * (n - i) as f32;
            if cost < best.0 {
                best = (cost, k, i);
                best_order = order;
            }
        }
    }
    let (cost, _, mid) = best;
    if cost.is_finite() {
        let copy: [PrimRef; SMALL] = std::array::from_fn(|i| {
            if i < n {
                refs[i]
            } else {
                PrimRef::new(&Aabb::EMPTY, 0)
            }
        });
        for (dst, &src) in refs.iter_mut().zip(&best_order[..n]) {
            *dst = copy[src as usize];
        }
    }
    Split {
        mid,
        left: RangeInfo::of(&refs[..mid]),
        right: RangeInfo::of(&refs[mid..]),
        cost,
    }
}

/// Splits at the object median along the widest centroid axis; always makes two non-empty
/// halves, so it bounds depth and handles coincident centroids.
fn median_split(refs: &mut [PrimRef], info: &RangeInfo) -> Split {
    let mid = refs.len() / 2;
    let ext = [0, 1, 2].map(|k| info.centroids.hi[k] - info.centroids.lo[k]);
    let axis = (0..3)
        .max_by(|&a, &b| ext[a].total_cmp(&ext[b]))
        .unwrap_or(0);
    if ext[axis] > 0.0 {
        refs.select_nth_unstable_by(mid, |a, b| {
            (a.lo[axis] + a.hi[axis])
                .total_cmp(&(b.lo[axis] + b.hi[axis]))
                .then(a.id.cmp(&b.id))
        });
    }
    Split {
        mid,
        left: RangeInfo::of(&refs[..mid]),
        right: RangeInfo::of(&refs[mid..]),
        cost: f32::INFINITY,
    }
}

fn split(
    refs: &mut [PrimRef],
    aux: &mut [PrimRef],
    info: &RangeInfo,
    ctx: &Ctx,
    depth: u32,
) -> Split {
    if depth >= MEDIAN_DEPTH {
        return median_split(refs, info);
    }
    if refs.len() <= SMALL {
        return sweep_split(refs);
    }
    binned_split(refs, aux, info, ctx).unwrap_or_else(|| median_split(refs, info))
}

pub fn build(
    refs: &mut [PrimRef],
    aux: &mut [PrimRef],
    bins: usize,
    max_leaf: usize,
    traversal_cost: f32,
) -> Tree {
    if refs.is_empty() {
        return Tree { root: None };
    }
    let ctx = Ctx {
        bins: bins.clamp(2, MAX_BINS),
        max_leaf: max_leaf.clamp(4, crate::layout::MAX_LEAF_SIZE),
        traversal_cost,
    };
    let info = RangeInfo::of(refs);
    Tree {
        root: Some(build_child(refs, &mut aux[..refs.len()], 0, info, &ctx, 0)),
    }
}

#[derive(Clone, Copy)]
struct Part {
    begin: usize,
    end: usize,
    info: RangeInfo,
}

fn build_child(
    refs: &mut [PrimRef],
    aux: &mut [PrimRef],
    base: u32,
    info: RangeInfo,
    ctx: &Ctx,
    depth: u32,
) -> (Aabb, Child) {
    let n = refs.len();
    let leaf = (
        info.bounds,
        Child::Leaf {
            first: base,
            count: n as u32,
        },
    );
    // Fewer primitives than a node has slots: always a leaf (so every inner node is full).
    if n < WIDTH {
        return leaf;
    }
    // The first split of this node; for a leaf-sized range it also decides, by the SAH,
    // whether a leaf is cheaper.
    let first = split(refs, aux, &info, ctx, depth);
    if n <= ctx.max_leaf {
        let area = info.bounds.half_area();
        if !(ctx.traversal_cost * area + first.cost < area * n as f32) {
            return leaf;
        }
    }
    let mut parts = [Part {
        begin: 0,
        end: 0,
        info: RangeInfo::EMPTY,
    }; WIDTH];
    parts[0] = Part {
        begin: 0,
        end: first.mid,
        info: first.left,
    };
    parts[1] = Part {
        begin: first.mid,
        end: n,
        info: first.right,
    };
    let mut count = 2;
    while count < WIDTH {
        // Split the part with the largest area that has at least two primitives.
        let mut pick = None;
        let mut best_area = -1.0f32;
        for (i, p) in parts[..count].iter().enumerate() {
            let a = p.info.bounds.half_area();
            if p.end - p.begin >= 2 && a > best_area {
                best_area = a;
                pick = Some(i);
            }
        }
        let Some(i) = pick else { break };
        let p = parts[i];
        let s = split(
            &mut refs[p.begin..p.end],
            &mut aux[p.begin..p.end],
            &p.info,
            ctx,
            depth,
        );
        parts[i] = Part {
            begin: p.begin,
            end: p.begin + s.mid,
            info: s.left,
        };
        parts[count] = Part {
            begin: p.begin + s.mid,
            end: p.end,
            info: s.right,
        };
        count += 1;
    }
    let parts = &mut parts[..count];
    parts.sort_by_key(|p| p.begin);
    // Hand each part its own disjoint slice, then build them (in parallel when large).
    type Slot<'r> = Option<(&'r mut [PrimRef], &'r mut [PrimRef], u32, RangeInfo)>;
    let mut slices: [Slot; WIDTH] = Default::default();
    let (mut rest, mut aux_rest) = (refs, aux);
    let mut at = 0;
    for (slot, p) in slices.iter_mut().zip(parts.iter()) {
        let (_, tail) = rest.split_at_mut(p.begin - at);
        let (mine, tail) = tail.split_at_mut(p.end - p.begin);
        let (_, atail) = aux_rest.split_at_mut(p.begin - at);
        let (amine, atail) = atail.split_at_mut(p.end - p.begin);
        *slot = Some((mine, amine, base + p.begin as u32, p.info));
        rest = tail;
        aux_rest = atail;
        at = p.end;
    }
    let node = if n > PARALLEL_THRESHOLD {
        let children: Vec<(Aabb, Child)> = slices
            .into_par_iter()
            .flatten()
            .map(|(s, a, b, i)| build_child(s, a, b, i, ctx, depth + 1))
            .collect();
        InnerNode::new(children)
    } else {
        InnerNode::new(
            slices
                .into_iter()
                .flatten()
                .map(|(s, a, b, i)| build_child(s, a, b, i, ctx, depth + 1)),
        )
    };
    (info.bounds, Child::Inner(Box::new(node)))
}
