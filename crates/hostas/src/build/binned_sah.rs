//! Top-down binned SAH builder (Wald 2007), filling 8-wide nodes by repeatedly splitting the child
//! with the largest surface area. Primitive references are partitioned in place; large ranges into
//! the second array (left side in order, right side backwards), whose next partition of each side
//! moves it back, so the final order is the order of `refs` on return. Small ranges are split with
//! an exact SAH sweep over sorted centroids instead of bins; their centroids are sorted once, and
//! each sweep split hands its sides their orders. Ranges of 16,384 or more are binned on every
//! fourth or eighth reference (`SAMPLE_FROM`); their partitions compute the sides' bounds (which
//! is why large ones need no counting pass on one thread: the bins do not count the sides, and the
//! right side is placed from the end).
//!
//! While the builder runs, each reference holds its bounds as `(lo, -hi)` (`Box8`): negated
//! once on entry (with the pass that bounds the root) and restored on return, instead of on
//! every binning, partition and sweep that reads it.

use super::tree::{self, Child, NodeList, Tree, node_hint};
use super::{MEDIAN_DEPTH, PARALLEL_THRESHOLD, PrimRef};
use crate::layout::{Node, WIDTH};
use crate::math::{Aabb, Box4, fmin8};
use rayon::prelude::*;
use wide::{f32x4, f32x8, i32x4, i32x8, u32x4};

pub const MAX_BINS: usize = 32;
/// Ranges up to this size are split by an exact sweep instead of binning.
const SMALL: usize = 16;
/// Ranges of at least this many primitives are binned on a sample: every fourth reference,
/// or every eighth from twice as many (at least 4,096 either way). The plane a sample chooses
/// is as good as the whole range's within the bins' own resolution (measured: SAH within
/// ±1% on the benchmark's scenes; every sixteenth cost Sponza 3.5%), and the partition that
/// follows reads every reference anyway, so it computes the sides' exact bounds as it goes.
/// (Chunks of parallel binning are multiples of the stride: the sample does not depend on
/// the thread count.)
const SAMPLE_FROM: usize = 16384;

/// Flips the sign of the upper four lanes: a box is kept as `(lo, -hi)` in one 8-lane vector
/// (as Embree does), so that growing it is a single `minps`.
const NEG_HI: f32x8 = f32x8::new([0.0, 0.0, 0.0, 0.0, -0.0, -0.0, -0.0, -0.0]);

/// A box as `[lo.x, lo.y, lo.z, _, -hi.x, -hi.y, -hi.z, _]`. Lanes 3 and 7 carry whatever
/// the source had there (a primitive's id and pad) and are ignored.
#[derive(Clone, Copy, Debug)]
struct Box8(f32x8);

impl Box8 {
    const EMPTY: Box8 = Box8(f32x8::new([f32::INFINITY; 8]));

    /// The box of a reference as the builder holds it (`hi` negated, see [`enter`]).
    #[inline(always)]
    fn of(r: &PrimRef) -> Box8 {
        Box8(bytemuck::cast(*r))
    }
    /// The reference this box was made from by [`Box8::of`].
    #[inline(always)]
    fn prim_ref(&self) -> PrimRef {
        bytemuck::cast(self.0)
    }
    /// Grows to hold `o`: `minps` with the operand order of `fmin`/`fmax` (a NaN in `o`
    /// wins over the current bound).
    #[inline(always)]
    fn grow(&mut self, o: &Box8) {
        self.0 = fmin8(self.0, o.0);
    }
    /// Grows to hold `o`, ignoring its NaN lanes: for merging partial bins, which rayon may
    /// group differently on another thread count. With NaN as the identity the merge is
    /// associative, so the bytes stay the same even on input whose NaN components the spec
    /// leaves undefined (no other input has NaN bounds).
    #[inline(always)]
    fn merge(&mut self, o: &Box8) {
        self.0 = o.0.is_nan().select(self.0, fmin8(self.0, o.0));
    }
    #[inline(always)]
    fn halves(&self) -> (f32x4, f32x4) {
        let [lo, neg_hi]: [f32x4; 2] = bytemuck::cast(self.0);
        (lo, neg_hi)
    }
    /// Grows to hold the point `p` given as `(p, -p)`, ignoring its NaN lanes (the point goes
    /// first: the same bits as [`Box4::grow_point`]).
    #[inline(always)]
    fn grow_point(&mut self, p: f32x8) {
        self.0 = fmin8(p, self.0);
    }
    fn box4(&self) -> Box4 {
        let (lo, neg_hi) = self.halves();
        Box4 { lo, hi: -neg_hi }
    }
    /// The doubled centroid (lane 3 is meaningless).
    #[inline(always)]
    fn center2(&self) -> f32x4 {
        let (lo, neg_hi) = self.halves();
        lo - neg_hi
    }
    fn aabb(&self) -> Aabb {
        let (lo, neg_hi) = self.halves();
        let (lo, hi) = (lo.to_array(), (-neg_hi).to_array());
        Aabb {
            lo: [lo[0], lo[1], lo[2]],
            hi: [hi[0], hi[1], hi[2]],
        }
    }
}

/// The half areas of three boxes, in lanes 0 to 2: `d0 * d1 + d1 * d2 + d2 * d0` of each
/// box's extent `d`. No test for empty boxes: theirs is infinite, and times a count of zero it
/// makes a NaN cost, which loses every comparison.
#[inline(always)]
fn half_areas3(b: &[Box8; 3]) -> f32x4 {
    // The negated extents (exactly): their products are the extents'.
    let d = |b: &Box8| {
        let (lo, neg_hi) = b.halves();
        lo + neg_hi
    };
    let [x, y, z, _] = f32x4::transpose([d(&b[0]), d(&b[1]), d(&b[2]), f32x4::ZERO]);
    x * y + y * z + z * x
}

/// The doubled centroid of a reference (lane 3 is meaningless): `lo - (-hi)`, the same bits
/// as `lo + hi`.
#[inline(always)]
fn center2(r: &PrimRef) -> f32x4 {
    let [lo, neg_hi]: [[f32; 4]; 2] = bytemuck::cast(*r);
    f32x4::new(lo) - f32x4::new(neg_hi)
}

/// Bounds of a range and of its primitives' (doubled) centroids.
#[derive(Clone, Copy, Debug)]
pub(crate) struct RangeInfo {
    pub bounds: Aabb,
    /// Empty for the ranges that splits of small ranges make: those are swept, never binned,
    /// so nothing reads them (the median split finds its own, see [`median_split`]).
    pub centroids: Aabb,
}

/// [`RangeInfo`] while it is being accumulated.
#[derive(Clone, Copy)]
struct Acc {
    bounds: Box8,
    centroids: Box4,
}

impl Acc {
    const EMPTY: Acc = Acc {
        bounds: Box8::EMPTY,
        centroids: Box4::EMPTY,
    };
    #[inline(always)]
    fn add(&mut self, r: &PrimRef) {
        let b = Box8::of(r);
        self.bounds.grow(&b);
        self.centroids.grow_point(b.center2());
    }
    fn of(refs: &[PrimRef]) -> RangeInfo {
        let mut acc = Acc::EMPTY;
        for r in refs {
            acc.add(r);
        }
        acc.info()
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

    /// Unites the infos of two consecutive chunks, ignoring NaN bounds of `b` (see
    /// [`Box8::merge`]; the centroids' bounds never hold NaN).
    fn merge(a: RangeInfo, b: RangeInfo) -> RangeInfo {
        let keep = |x: [f32; 3], y: [f32; 3]| {
            std::array::from_fn(|k| if y[k].is_nan() { x[k] } else { y[k] })
        };
        let bounds = Aabb {
            lo: keep(a.bounds.lo, b.bounds.lo),
            hi: keep(a.bounds.hi, b.bounds.hi),
        };
        RangeInfo {
            bounds: a.bounds.union(&bounds),
            centroids: a.centroids.union(&b.centroids),
        }
    }
    /// A small range's info: its bounds only.
    fn bounded(bounds: &Box8) -> RangeInfo {
        RangeInfo {
            bounds: bounds.aabb(),
            centroids: Aabb::EMPTY,
        }
    }
    pub fn of(refs: &[PrimRef]) -> RangeInfo {
        if refs.len() > PARALLEL_THRESHOLD * 4 {
            return refs
                .par_chunks(PARALLEL_THRESHOLD)
                .map(RangeInfo::of)
                .reduce(|| RangeInfo::EMPTY, RangeInfo::merge);
        }
        Acc::of(refs)
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

/// A part of a node's range: positions `begin..end` of the range, their info and, where a
/// sweep split made it, their orders. Splits write both sides' parts in place.
#[derive(Clone, Copy)]
struct Part {
    begin: usize,
    end: usize,
    info: RangeInfo,
    orders: Option<Orders>,
}

impl Part {
    const EMPTY: Part = Part {
        begin: 0,
        end: 0,
        info: RangeInfo::EMPTY,
        orders: None,
    };
    /// Makes `self` (the part split, now its left side) and `right` the sides of a split
    /// `mid` primitives into it.
    #[inline(always)]
    fn split_into(
        &mut self,
        right: &mut Part,
        mid: usize,
        infos: (RangeInfo, RangeInfo),
        orders: (Option<Orders>, Option<Orders>),
    ) {
        let (begin, end) = (self.begin, self.end);
        *self = Part {
            begin,
            end: begin + mid,
            info: infos.0,
            orders: orders.0,
        };
        *right = Part {
            begin: begin + mid,
            end,
            info: infos.1,
            orders: orders.1,
        };
    }
}

/// Maps doubled centroids to bins, on all axes at once (`cvttps2dq` of the scaled offset).
/// The mapping is monotone in the centroid on each axis, and binning and partitioning use the
/// same arithmetic, so a partition always agrees with the bin counts. Centroids of the range
/// the binner was made for land in `0..bins` (`scale` leaves a margin); anything else (NaN,
/// infinities) lands in some bin, masked into range by the caller.
#[derive(Clone, Copy)]
struct Binner {
    /// The least centroid and the scale, in both halves (two centroids are binned at once).
    lo: f32x8,
    scale: f32x8,
    /// `scale` as scalars (axes without extent have 0).
    scales: [f32; 4],
}

impl Binner {
    fn new(centroids: &Aabb, bins: usize) -> Binner {
        let mut lo = [0f32; 4];
        let mut scale = [0f32; 4];
        for k in 0..3 {
            let ext = centroids.hi[k] - centroids.lo[k];
            lo[k] = centroids.lo[k];
            scale[k] = if ext > 0.0 {
                bins as f32 * (1.0 - 1e-6) / ext
            } else {
                0.0
            };
        }
        let both = |x: [f32; 4]| f32x8::new(std::array::from_fn(|i| x[i % 4]));
        Binner {
            lo: both(lo),
            scale: both(scale),
            scales: scale,
        }
    }
    /// The bins on each axis of two boxes' doubled centroids, as byte offsets into a [`Bins`]
    /// axis of `N` bins (`bin << 5`, masked into range: as a vector, so that the compiler
    /// knows the lanes' range and masks no index again): the first box's in lanes 0 to 2, the
    /// second's in lanes 4 to 6.
    #[inline(always)]
    fn offsets2<const N: usize>(&self, b0: &Box8, b1: &Box8) -> [u32; 8] {
        let (lo0, neg_hi0) = b0.halves();
        let (lo1, neg_hi1) = b1.halves();
        let lo: f32x8 = bytemuck::cast([lo0, lo1]);
        let neg_hi: f32x8 = bytemuck::cast([neg_hi0, neg_hi1]);
        // The centroids as `Box8::center2` computes them.
        let bins = ((lo - neg_hi - self.lo) * self.scale).fast_trunc_int();
        bytemuck::cast((bins << 5) & i32x8::splat(((N - 1) << 5) as i32))
    }
    /// The least centroid on `axis` whose bin is `bin` or more, given that the range's
    /// centroids on `axis` span `lo..=hi` and some lie in bins from `bin` up (`0 < bin`).
    /// The mapping is monotone, so over the range `bin(c) < bin` exactly when `!(c >= t)`: a
    /// partition by one comparison. (A NaN centroid, in bin 0, goes left either way; the
    /// range's centroid bounds hold every other centroid, see [`Box4::grow_point`].) Found by
    /// bisection over the floats' order.
    fn threshold(&self, axis: usize, bin: u32, lo: f32, hi: f32) -> f32 {
        let (l0, s) = (self.lo.to_array()[axis & 3], self.scales[axis & 3]);
        // The same arithmetic as `bins` (the value is in `0..bins` over the range).
        let bin_of = |x: f32| ((x - l0) * s) as i32;
        // Floats in order as integers, and back (the map is its own inverse).
        let key = |x: f32| {
            let b = x.to_bits() as i32;
            (b ^ (((b >> 31) as u32) >> 1) as i32) as i64
        };
        let float = |k: i64| {
            let b = k as i32;
            f32::from_bits((b ^ (((b >> 31) as u32) >> 1) as i32) as u32)
        };
        // bin(lo) = 0 < bin <= bin(hi).
        let (mut l, mut h) = (key(lo), key(hi));
        // The plane's own position is within an ulp or two of the answer: narrow the
        // interval around it first (the answer, the least float of bin `bin` or more, is the
        // same whatever the interval it is searched in).
        let mut guess = l0 + bin as f32 / s;
        if !(guess >= lo) {
            guess = lo;
        }
        if !(guess <= hi) {
            guess = hi;
        }
        let g = key(guess);
        if bin_of(guess) >= bin as i32 {
            h = g;
            if g - 1 > l && bin_of(float(g - 1)) < bin as i32 {
                l = g - 1;
            }
        } else {
            l = g;
            if g + 1 < h && bin_of(float(g + 1)) >= bin as i32 {
                h = g + 1;
            }
        }
        while h - l > 1 {
            let m = l + (h - l) / 2;
            if bin_of(float(m)) >= bin as i32 {
                h = m;
            } else {
                l = m;
            }
        }
        float(h)
    }
}

/// A bin's primitive count, alone in 32 bytes: the stride of the bins' bounds, so that one
/// byte offset (`bin << 5`, masked once) addresses both.
#[derive(Clone, Copy)]
#[repr(C, align(32))]
struct Count(u32);

/// Per axis and bin: the bounds of the primitives whose centroid falls in it and their count.
/// (Counts as `[bin][axis]` lanes ran 2-3 times slower here: the increments then share
/// 16-byte words, which stalls the loads of the next primitive's bins.)
struct Bins<const N: usize> {
    bounds: [[Box8; N]; 3],
    counts: [[Count; N]; 3],
}

impl<const N: usize> Bins<N> {
    fn new() -> Bins<N> {
        // The empty box as a run-time value: the compiler then fills the bins with stores of
        // one register instead of copying a constant array.
        let empty = Box8(f32x8::splat(std::hint::black_box(f32::INFINITY)));
        Bins {
            bounds: [[empty; N]; 3],
            counts: [[Count(0); N]; 3],
        }
    }
    /// Adds a box to its bin on each axis, given as byte offsets (see [`Binner::offsets2`]).
    #[inline(always)]
    fn add(&mut self, at: &[u32], b: &Box8) {
        for k in 0..3 {
            let j = (at[k] >> 5) as usize & (N - 1);
            self.counts[k][j].0 += 1;
            self.bounds[k][j].grow(b);
        }
    }
    fn count(&self, axis: usize, bin: usize) -> u32 {
        self.counts[axis][bin].0
    }
    fn fill(&mut self, binner: &Binner, refs: &[PrimRef], stride: usize) {
        if stride > 1 {
            return self.fill_sampled(binner, refs, stride);
        }
        // Neighbouring primitives often land in the same bins: alternating between two sets
        // of bins halves the chains of dependent updates.
        if refs.len() >= 64 {
            let mut other = Bins::<N>::new();
            let pairs = refs.chunks_exact(2);
            let rest = pairs.remainder();
            for p in pairs {
                let (b0, b1) = (Box8::of(&p[0]), Box8::of(&p[1]));
                let at = binner.offsets2::<N>(&b0, &b1);
                self.add(&at[..4], &b0);
                other.add(&at[4..], &b1);
            }
            for r in rest {
                let b = Box8::of(r);
                self.add(&binner.offsets2::<N>(&b, &b), &b);
            }
            self.merge_from(&other);
            return;
        }
        for r in refs {
            let b = Box8::of(r);
            self.add(&binner.offsets2::<N>(&b, &b), &b);
        }
    }
    /// [`Bins::fill`] with every `stride`-th reference only (from the first).
    fn fill_sampled(&mut self, binner: &Binner, refs: &[PrimRef], stride: usize) {
        let mut other = Bins::<N>::new();
        let mut sample = refs.iter().step_by(stride);
        while let Some(r0) = sample.next() {
            let b0 = Box8::of(r0);
            let Some(r1) = sample.next() else {
                self.add(&binner.offsets2::<N>(&b0, &b0), &b0);
                break;
            };
            let b1 = Box8::of(r1);
            let at = binner.offsets2::<N>(&b0, &b1);
            self.add(&at[..4], &b0);
            other.add(&at[4..], &b1);
        }
        self.merge_from(&other);
    }
    /// Adds the bins of `b`, filled from the primitives after (or between) this one's.
    fn merge_from(&mut self, b: &Bins<N>) {
        for k in 0..3 {
            for i in 0..N {
                self.counts[k][i].0 += b.counts[k][i].0;
                self.bounds[k][i].grow(&b.bounds[k][i]);
            }
        }
    }
    /// [`Bins::merge_from`] for the partial bins of parallel chunks, in whatever grouping
    /// rayon makes: NaN lanes ignored (see [`Box8::merge`]).
    fn merge(mut self, b: Bins<N>) -> Bins<N> {
        for k in 0..3 {
            for i in 0..N {
                self.counts[k][i].0 += b.counts[k][i].0;
                self.bounds[k][i].merge(&b.bounds[k][i]);
            }
        }
        self
    }

    /// The best split plane: (axis, first bin of the right side, cost). Planes with an empty
    /// side cost NaN (an empty box's infinite area times a zero count) and never win.
    fn best(&self, binner: &Binner) -> Option<(usize, usize, f32)> {
        // The three axes side by side in the lanes of one vector (their areas computed
        // together, see `half_areas3`), each keeping its first plane of least cost with
        // selects; then the first axis of least cost: the same winner as sweeping the axes in
        // turn. (Counts are below 2^31: as `i32` they convert to the same floats.)
        let counts = |i: usize| {
            i32x4::new([
                self.count(0, i) as i32,
                self.count(1, i) as i32,
                self.count(2, i) as i32,
                0,
            ])
        };
        let mut right_cost = [f32x4::ZERO; N];
        let mut acc = [Box8::EMPTY; 3];
        let mut n = i32x4::ZERO;
        for i in (1..N).rev() {
            for k in 0..3 {
                acc[k].grow(&self.bounds[k][i]);
            }
            n += counts(i);
            right_cost[i] = half_areas3(&acc) * f32x4::from_i32x4(n);
        }
        let mut acc = [Box8::EMPTY; 3];
        let mut n = i32x4::ZERO;
        let (mut best_cost, mut best_at) = (f32x4::splat(f32::INFINITY), f32x4::ZERO);
        for i in 1..N {
            for k in 0..3 {
                acc[k].grow(&self.bounds[k][i - 1]);
            }
            n += counts(i - 1);
            let cost = half_areas3(&acc) * f32x4::from_i32x4(n) + right_cost[i];
            let better = cost.simd_lt(best_cost);
            best_cost = better.select(cost, best_cost);
            best_at = better.select(f32x4::splat(i as f32), best_at);
        }
        let best: [(f32, usize); 3] = {
            let (c, a) = (best_cost.to_array(), best_at.fast_trunc_int().to_array());
            std::array::from_fn(|k| (c[k], a[k] as usize))
        };
        let mut pick: Option<(usize, usize, f32)> = None;
        let mut best_cost = f32::INFINITY;
        for (k, &(cost, i)) in best.iter().enumerate() {
            // Axes without extent are never split on.
            if binner.scales[k] != 0.0 && cost < best_cost {
                best_cost = cost;
                pick = Some((k, i, cost));
            }
        }
        pick
    }

    /// Bounds of both sides of a plane.
    fn sides(&self, axis: usize, bin: usize) -> (Aabb, Aabb) {
        let (mut l, mut r) = (Box8::EMPTY, Box8::EMPTY);
        for (i, b) in self.bounds[axis].iter().enumerate() {
            if i < bin {
                l.grow(b);
            } else {
                r.grow(b);
            }
        }
        (l.aabb(), r.aabb())
    }
}

/// Binning of a range into empty `bins` (on all threads when large; small ones are filled
/// in place, not moved: a move is a copy of the whole array).
fn bin_range<const N: usize>(bins: &mut Bins<N>, refs: &[PrimRef], binner: &Binner, stride: usize) {
    if refs.len() > PARALLEL_THRESHOLD * 4 {
        *bins = refs
            .par_chunks(PARALLEL_THRESHOLD)
            .map(|c| {
                let mut b = Bins::<N>::new();
                b.fill(binner, c, stride);
                b
            })
            .reduce(Bins::new, Bins::merge);
    } else {
        bins.fill(binner, refs, stride);
    }
}

/// The stride of the sample a range is binned on (see [`SAMPLE_FROM`]); 1 for all of it.
fn sample_stride(len: usize) -> usize {
    if len < SAMPLE_FROM {
        1
    } else if len < 2 * SAMPLE_FROM {
        4
    } else {
        8
    }
}

/// A split plane on axis `A`: a centroid is right of it when `c[A] >= t`, left otherwise (a
/// NaN coordinate goes left, see [`Binner::threshold`]).
#[derive(Clone, Copy)]
struct Plane<const A: usize> {
    t: f32x8,
}

impl<const A: usize> Plane<A> {
    fn new(t: f32) -> Plane<A> {
        Plane { t: f32x8::splat(t) }
    }
    /// A reference as one vector, its doubled centroid `c` as the point `(c, -c)` (`lo - (-hi)`
    /// and `-hi - lo`) and the mask of the side it goes to: all lanes set when right of the
    /// plane, none when left.
    #[inline(always)]
    fn classify(&self, r: &PrimRef) -> (f32x8, f32x8, f32x8) {
        let v: f32x8 = bytemuck::cast(*r);
        let [lo, neg_hi]: [f32x4; 2] = bytemuck::cast(v);
        let p: f32x8 = v - f32x8::from(bytemuck::cast::<_, [f32; 8]>([neg_hi, lo]));
        let right = f32x8::splat(p.to_array()[A]).simd_ge(self.t);
        (v, p, right)
    }
    #[inline(always)]
    fn left_of(&self, r: &PrimRef) -> bool {
        self.classify(r).2.to_bitmask() == 0
    }
}

/// The first lane of a mask as an offset: all bits (-1) when set, 0 when not. (Lanes 0 and 1
/// read as one 64-bit integer: the same value, with no sign extension.)
#[inline(always)]
fn mask_lane(m: f32x8) -> usize {
    bytemuck::cast::<_, [u64; 4]>(m)[0] as usize
}

/// The centroid bounds of both sides of a plane as boxes `(lo, -hi)` ([`Box8`]), grown in
/// registers without branching: each side grows by the centroid with all lanes made NaN when
/// it is on the other side, which [`Box8::grow_point`] ignores (as it ignores a NaN lane of the
/// centroid itself).
///
/// When `BOXES`, also the bounds of both sides' boxes, grown in order with [`Box8::grow`]
/// (the other side's box made +inf, which changes no bound): what a range binned on a sample
/// (see [`SAMPLE_FROM`]) cannot take from its bins.
#[derive(Clone, Copy)]
struct SideBounds<const BOXES: bool> {
    left: Box8,
    right: Box8,
    left_box: Box8,
    right_box: Box8,
}

impl<const BOXES: bool> SideBounds<BOXES> {
    const EMPTY: SideBounds<BOXES> = SideBounds {
        left: Box8::EMPTY,
        right: Box8::EMPTY,
        left_box: Box8::EMPTY,
        right_box: Box8::EMPTY,
    };
    /// Grows the side of `right` by the centroid given as `(c, -c)`. (Where `lo + hi` is +0,
    /// `-hi - lo` may be +0 too: a centroid bound's sign of zero, which changes no bin, no
    /// threshold and no median split.)
    #[inline(always)]
    fn grow(&mut self, v: f32x8, p: f32x8, right: f32x8) {
        self.left.grow_point(p | right);
        self.right
            .grow_point(right.select(p, f32x8::splat(f32::NAN)));
        if BOXES {
            let inf = f32x8::splat(f32::INFINITY);
            self.left_box.grow(&Box8(right.select(inf, v)));
            self.right_box.grow(&Box8(right.select(v, inf)));
        }
    }
    /// Adds the sides of the references after this one's.
    fn merge_from(&mut self, o: &SideBounds<BOXES>) {
        self.left.grow(&o.left);
        self.right.grow(&o.right);
        self.left_box.grow(&o.left_box);
        self.right_box.grow(&o.right_box);
    }
    fn sides(&self) -> Sides {
        Sides {
            centroids: (self.left.box4(), self.right.box4()),
            bounds: BOXES.then(|| (self.left_box.aabb(), self.right_box.aabb())),
        }
    }
}

/// What a partition found out about its sides: their centroid bounds, and their bounds when
/// it was asked for them.
struct Sides {
    centroids: (Box4, Box4),
    bounds: Option<(Aabb, Aabb)>,
}

/// Ranges of more than this many primitives are partitioned through the other array, left
/// side in order and right side backwards ([`mirrored_partition`]).
const LARGE: usize = PARALLEL_THRESHOLD * 16;
// Every large range is binned on a sample, so its partition computes its sides' bounds
// ([`partition_by`] relies on it).
const _: () = assert!(SAMPLE_FROM <= LARGE);

/// Where a range's references are: in `refs`, their final place, or in `aux`, where the
/// partition of a large range leaves both sides (copying them back would be one more pass over
/// the range; the next partition of each side moves it back instead).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum At {
    Refs,
    Aux,
}

impl At {
    /// The references of a range at `self`, given the range's piece of both arrays.
    #[inline(always)]
    fn data<'r>(self, refs: &'r [PrimRef], aux: &'r [PrimRef]) -> &'r [PrimRef] {
        match self {
            At::Refs => refs,
            At::Aux => aux,
        }
    }
    /// Moves a range's references to `refs` if they are in `aux`.
    #[inline(always)]
    fn settle(self, refs: &mut [PrimRef], aux: &[PrimRef]) {
        // Rare: only where a large range's partition made a small side.
        #[cold]
        #[inline(never)]
        fn copy_back(refs: &mut [PrimRef], aux: &[PrimRef]) {
            refs.copy_from_slice(aux);
        }
        if self == At::Aux {
            copy_back(refs, aux);
        }
    }
}

/// The chunks a large range is partitioned in.
const CHUNK: usize = PARALLEL_THRESHOLD * 4;

/// Partitions a large range (always binned on a sample, see [`SAMPLE_FROM`]) on all threads
/// from `src` into `dst`: count each chunk's left side, then scatter every chunk into `dst` at
/// its prefix-sum positions, left ones from the start in order, right ones from the end
/// backwards. The result is the same as [`mirrored_partition`]'s, whatever the thread count.
/// Returns the size of the left side and what it found out about both sides (their bounds
/// included), grown chunk by chunk.
fn parallel_partition<const A: usize>(
    src: &[PrimRef],
    dst: &mut [PrimRef],
    plane: Plane<A>,
) -> (usize, Sides) {
    let lefts: Vec<usize> = src
        .par_chunks(CHUNK)
        .map(|c| c.iter().filter(|r| plane.left_of(r)).count())
        .collect();
    let total_left: usize = lefts.iter().sum();
    // Each chunk writes its own disjoint pieces of `dst`: carve them in order.
    let (mut left_part, mut right_part) = dst.split_at_mut(total_left);
    let mut pieces = Vec::with_capacity(lefts.len());
    for (i, n) in lefts.iter().enumerate() {
        let len = CHUNK.min(src.len() - i * CHUNK);
        let (lp, lrest) = left_part.split_at_mut(*n);
        let (rrest, rp) = right_part.split_at_mut(right_part.len() - (len - n));
        pieces.push((lp, rp));
        left_part = lrest;
        right_part = rrest;
    }
    let infos: Vec<SideBounds<true>> = src
        .par_chunks(CHUNK)
        .zip(pieces.into_par_iter())
        .map(|(c, (lp, rp))| {
            let mut sides = SideBounds::EMPTY;
            let (mut li, mut ri) = (0, 0);
            for r in c {
                let (v, p, right) = plane.classify(r);
                sides.grow(v, p, right);
                if right.to_bitmask() == 0 {
                    lp[li] = *r;
                    li += 1;
                } else {
                    rp[rp.len() - 1 - ri] = *r;
                    ri += 1;
                }
            }
            sides
        })
        .collect();
    let mut all = SideBounds::EMPTY;
    for s in &infos {
        all.merge_from(s);
    }
    (total_left, all.sides())
}

/// Partitions a large range (always binned on a sample, whose bins neither count nor bound
/// the sides) from `src` into `dst` on the calling thread, without a counting pass: left
/// references from the start of `dst` in order, right ones from its end backwards. Chunk by
/// chunk, so that the sides' bounds are grown in the same grouping as [`parallel_partition`]
/// grows them (with a NaN, `fmin` is not associative): the same bytes on every thread count.
fn mirrored_partition<const A: usize>(
    src: &[PrimRef],
    dst: &mut [PrimRef],
    plane: Plane<A>,
) -> (usize, Sides) {
    let dst = &mut dst[..src.len()];
    let mut all = SideBounds::<true>::EMPTY;
    // `end` is one past the next right slot.
    let (mut li, mut end) = (0usize, src.len());
    for c in src.chunks(CHUNK) {
        let mut sides = SideBounds::<true>::EMPTY;
        for r in c {
            let (v, p, right) = plane.classify(r);
            sides.grow(v, p, right);
            // -1 (all bits, as `usize`) when right, 0 when left: one of the cursors moves.
            let right_lane = mask_lane(right);
            end = end.wrapping_add(right_lane);
            let at = if right_lane == 0 { li } else { end };
            if let Some(d) = dst.get_mut(at) {
                *d = bytemuck::cast(v);
            }
            li = li.wrapping_add(1).wrapping_add(right_lane);
        }
        all.merge_from(&sides);
    }
    (li, all.sides())
}

/// Partitions a range into `refs` with those left of `plane` first, reading it from `aux`
/// when `FROM_AUX` (else in place); returns the size of the left side and the centroid
/// bounds of both sides. Branch-free (Lomuto with an unconditional swap, bounds grown with
/// masks): which side a primitive goes to is often a coin toss, and mispredicted branches
/// cost more than the extra stores. From `aux` it is the same permutation: position `j` of
/// `refs` is only read after the swap has written it.
fn partition<const A: usize, const FROM_AUX: bool, const BOXES: bool>(
    refs: &mut [PrimRef],
    aux: &[PrimRef],
    plane: Plane<A>,
) -> (usize, Sides) {
    let aux = &aux[..refs.len()];
    let mut sides = SideBounds::<BOXES>::EMPTY;
    let mut i = 0usize;
    for j in 0..refs.len() {
        let r = if FROM_AUX { &aux[j] } else { &refs[j] };
        let (v, p, right) = plane.classify(r);
        sides.grow(v, p, right);
        // Refs i..j are right ones: swapping j with i keeps that whichever side `r` is on.
        refs[j] = refs[i];
        refs[i] = bytemuck::cast(v);
        // `i` advances past a left reference only.
        i = i.wrapping_add(1).wrapping_add(mask_lane(right));
    }
    (i, sides.sides())
}

/// Partitions a range at `at` by `plane`: large ones into the other array (with the sides'
/// bounds: a large range is always binned on a sample), the others into `refs` (in place when
/// there). Returns the size of the left side, what it found out about the sides (their bounds
/// when `BOXES`: the bins were filled from a sample, so they do not bound the sides) and where
/// the sides are.
fn partition_by<const A: usize, const BOXES: bool>(
    refs: &mut [PrimRef],
    aux: &mut [PrimRef],
    at: At,
    plane: Plane<A>,
) -> (usize, Sides, At) {
    if refs.len() > LARGE {
        let (src, dst, to) = match at {
            At::Refs => (&*refs, aux, At::Aux),
            At::Aux => (&*aux, refs, At::Refs),
        };
        // Both place the sides alike and grow their bounds chunk by chunk: the bytes do not
        // depend on the path.
        let (mid, sides) = if rayon::current_num_threads() > 1 {
            parallel_partition(src, dst, plane)
        } else {
            mirrored_partition(src, dst, plane)
        };
        return (mid, sides, to);
    }
    let (mid, sides) = match at {
        At::Refs => partition::<A, false, BOXES>(refs, aux, plane),
        At::Aux => partition::<A, true, BOXES>(refs, aux, plane),
    };
    (mid, sides, At::Refs)
}

// Not inlined into `split`: see `sweep`.
#[inline(never)]
fn binned_split_n<const N: usize>(
    refs: &mut [PrimRef],
    aux: &mut [PrimRef],
    at: At,
    info: &RangeInfo,
    binner: &Binner,
) -> (Option<Split>, At) {
    let mut bins = Bins::<N>::new();
    let stride = sample_stride(refs.len());
    bin_range(&mut bins, at.data(refs, aux), binner, stride);
    let Some((axis, bin, cost)) = bins.best(binner) else {
        return (None, at);
    };
    // Left of the plane: `!(c >= t)` on the axis.
    let t = binner.threshold(
        axis,
        bin as u32,
        info.centroids.lo[axis],
        info.centroids.hi[axis],
    );
    let (mid, sides, at) = match (axis, stride > 1) {
        (0, false) => partition_by::<0, false>(refs, aux, at, Plane::new(t)),
        (1, false) => partition_by::<1, false>(refs, aux, at, Plane::new(t)),
        (_, false) => partition_by::<2, false>(refs, aux, at, Plane::new(t)),
        (0, true) => partition_by::<0, true>(refs, aux, at, Plane::new(t)),
        (1, true) => partition_by::<1, true>(refs, aux, at, Plane::new(t)),
        (_, true) => partition_by::<2, true>(refs, aux, at, Plane::new(t)),
    };
    if mid == 0 || mid == refs.len() {
        return (None, at);
    }
    let (cl, cr) = sides.centroids;
    let (lb, rb) = sides.bounds.unwrap_or_else(|| bins.sides(axis, bin));
    let split = Split {
        mid,
        left: RangeInfo {
            bounds: lb,
            centroids: cl.aabb(),
        },
        right: RangeInfo {
            bounds: rb,
            centroids: cr.aabb(),
        },
        cost,
    };
    (Some(split), at)
}

/// Binned split of a range at `at` (see [`partition_by`]); also says where the range is
/// afterwards, split or not.
fn binned_split(
    refs: &mut [PrimRef],
    aux: &mut [PrimRef],
    at: At,
    info: &RangeInfo,
    ctx: &Ctx,
) -> (Option<Split>, At) {
    // Small ranges gain nothing from many bins; they only pay for sweeping them.
    let bins = if refs.len() < 256 {
        ctx.bins.min(8)
    } else {
        ctx.bins
    };
    // Powers of two only: the bins array is indexed with a mask.
    let bins = match bins {
        0..=8 => 8,
        9..=16 => 16,
        _ => 32,
    };
    let binner = Binner::new(&info.centroids, bins);
    if binner.scales == [0.0; 4] {
        return (None, at);
    }
    match bins {
        8 => binned_split_n::<8>(refs, aux, at, info, &binner),
        16 => binned_split_n::<16>(refs, aux, at, info, &binner),
        _ => binned_split_n::<32>(refs, aux, at, info, &binner),
    }
}

/// Per lane, a key that orders floats like `f32::total_cmp` when compared as signed integers,
/// with the low 4 bits replaced by `i` so that keys of distinct positions always differ (ties,
/// and centroids closer than 2^-19 relative, order by position).
#[inline(always)]
fn order_keys(x: f32x4, i: usize) -> i32x4 {
    let b: i32x4 = bytemuck::cast(x);
    let flip: i32x4 = bytemuck::cast(bytemuck::cast::<_, u32x4>(b >> 31) >> 1);
    (b ^ flip) & i32x4::splat(!15) | i32x4::splat(i as i32)
}

/// The primitives of a small range (at most [`SMALL`]) in centroid order on each axis, as
/// positions in the range. Sorted once when the range is first swept; a sweep split hands
/// each side its orders by filtering, so the sides are not sorted again.
#[derive(Clone, Copy, Debug)]
struct Orders([[u8; SMALL]; 3]);

impl Orders {
    /// Ranks the centroids on each axis (branch-free: every pair compared; the keys are
    /// distinct, so the ranks are a permutation whatever the values).
    fn of(refs: &[PrimRef]) -> Orders {
        if refs.len() <= 8 {
            Orders::rank::<1>(refs)
        } else {
            Orders::rank::<2>(refs)
        }
    }
    /// [`Orders::of`] for at most `8 * V` primitives, keys in `V` vectors of eight.
    fn rank<const V: usize>(refs: &[PrimRef]) -> Orders {
        let n = refs.len().min(8 * V);
        // Padding keys are larger than any real one, so they never count.
        let mut keys = [[[i32::MAX; 8]; V]; 3];
        for (i, r) in refs[..n].iter().enumerate() {
            let c = order_keys(center2(r), i).to_array();
            for k in 0..3 {
                keys[k][(i / 8) % V][i % 8] = c[k];
            }
        }
        let mut orders = [[0u8; SMALL]; 3];
        for (key, order) in keys.iter().zip(&mut orders) {
            // All ranks at once (vectorized over i): rank[i] counts the real keys below
            // key[i] (a true comparison is -1).
            let ki = key.map(i32x8::new);
            let mut rank = [i32x8::ZERO; V];
            for &kj in &key.as_flattened()[..n] {
                let kj = i32x8::splat(kj);
                for (r, ki) in rank.iter_mut().zip(&ki) {
                    *r -= ki.simd_gt(kj);
                }
            }
            let rank = rank.map(|r| r.to_array());
            for (i, &r) in rank.as_flattened()[..n].iter().enumerate() {
                order[r as usize & (SMALL - 1)] = i as u8;
            }
        }
        Orders(orders)
    }
}

/// Exact SAH split of a small range (2 to [`SMALL`] primitives, the part `left`) given its
/// orders: sweep every position on every axis, then permute the references once, for the
/// winning axis. Makes `left` and `right` the sides, with their orders when `split_again`
/// (the node may split them), and returns the SAH numerator of the split. The sides' infos
/// carry bounds only (see [`RangeInfo::centroids`]).
fn sweep_split(
    refs: &mut [PrimRef],
    orders: &Orders,
    left: &mut Part,
    right: &mut Part,
    split_again: bool,
) -> f32 {
    // Most swept ranges have 8 or fewer primitives: half-size working arrays for them.
    if refs.len() <= 8 {
        sweep::<8>(refs, orders, left, right, split_again)
    } else {
        sweep::<SMALL>(refs, orders, left, right, split_again)
    }
}

/// [`sweep_split`] for ranges of at most `L` primitives (`L` a power of two up to [`SMALL`]).
// Not inlined: inside `split`, its frame and spills cost every split more than the call does.
// The sides are written through `left` and `right`, straight into the node's parts.
#[inline(never)]
fn sweep<const L: usize>(
    refs: &mut [PrimRef],
    orders: &Orders,
    left: &mut Part,
    right: &mut Part,
    split_again: bool,
) -> f32 {
    let n = refs.len().min(L);
    // A box carries the whole reference (lanes 3 and 7 hold the id and the pad).
    let mut boxes = [Box8::EMPTY; L];
    for (b, r) in boxes.iter_mut().zip(refs.iter()) {
        *b = Box8::of(r);
    }
    // The three axes are swept side by side: three independent chains of box growth, their
    // areas computed together.
    let o = &orders.0;
    let mut right_area = [f32x4::ZERO; L];
    let mut acc = [Box8::EMPTY; 3];
    for i in (1..n).rev() {
        for k in 0..3 {
            acc[k].grow(&boxes[o[k][i] as usize & (L - 1)]);
        }
        right_area[i & (L - 1)] = half_areas3(&acc);
    }
    let mut acc = [Box8::EMPTY; 3];
    // Per axis, the first position of least cost (a NaN or infinite cost never wins).
    let (mut best_cost, mut best_at) = (f32x4::splat(f32::INFINITY), f32x4::splat((n / 2) as f32));
    // The sides' counts `i` and `n - i` as floats, counted (small whole numbers: exact).
    let (mut left_n, mut right_n) = (f32x4::ZERO, f32x4::splat(n as f32));
    for i in 1..n {
        for k in 0..3 {
            acc[k].grow(&boxes[o[k][i - 1] as usize & (L - 1)]);
        }
        left_n += f32x4::ONE;
        right_n -= f32x4::ONE;
        let cost = half_areas3(&acc) * left_n + right_area[i & (L - 1)] * right_n;
        // Selects, not branches: which position wins is data, not pattern.
        let better = cost.simd_lt(best_cost);
        best_cost = better.select(cost, best_cost);
        best_at = better.select(left_n, best_at);
    }
    // The first axis of least cost: the same winner as sweeping the axes in turn.
    // (The positions are small whole numbers: truncated as a vector, not converted one by one.)
    let (cost, at) = (best_cost.to_array(), best_at.fast_trunc_int().to_array());
    let (mut best_cost, mut best_axis, mut best_mid) = (f32::INFINITY, 3, n / 2);
    for k in 0..3 {
        if cost[k] < best_cost {
            (best_cost, best_axis, best_mid) = (cost[k], k, at[k] as usize);
        }
    }
    // No finite cost (NaN bounds): split in the middle, in the current order.
    let identity: [u8; SMALL] = std::array::from_fn(|i| i as u8);
    let perm = orders.0.get(best_axis).unwrap_or(&identity);
    let mut pos = [0u8; L];
    let (mut lb, mut rb) = (Box8::EMPTY, Box8::EMPTY);
    for (i, (dst, &src)) in refs.iter_mut().zip(&perm[..n]).enumerate() {
        let b = &boxes[src as usize & (L - 1)];
        *dst = b.prim_ref();
        pos[src as usize & (L - 1)] = i as u8;
        // Both sides' bounds, grown in the new order (the same bits as from the references).
        if i < best_mid {
            lb.grow(b);
        } else {
            rb.grow(b);
        }
    }
    let infos = (RangeInfo::bounded(&lb), RangeInfo::bounded(&rb));
    // Each side's orders: the range's orders filtered, as positions after the permutation.
    // On the winning axis the references now are in its order: both sides' are the identity.
    let mid = best_mid as u8;
    let (mut lo, mut ro) = ([identity; 3], [identity; 3]);
    // Sides of one or two primitives are never swept (see `split`): they need no orders, and
    // neither do the sides of a node's last split.
    let neither = !split_again || (best_mid <= 2 && n - best_mid <= 2);
    for k in 0..3 {
        if k == best_axis || neither {
            continue;
        }
        let (mut li, mut ri) = (0, 0);
        for &o in &orders.0[k][..n] {
            let p = pos[o as usize & (L - 1)];
            lo[k][li & (L - 1)] = p;
            ro[k][ri & (L - 1)] = p.wrapping_sub(mid);
            li += (p < mid) as usize;
            ri += (p >= mid) as usize;
        }
    }
    let orders = if neither {
        (None, None)
    } else {
        (Some(Orders(lo)), Some(Orders(ro)))
    };
    left.split_into(right, best_mid, infos, orders);
    best_cost
}

/// Splits at the object median along the widest centroid axis; always makes two non-empty
/// halves, so it bounds depth and handles coincident centroids.
fn median_split(refs: &mut [PrimRef], info: &RangeInfo) -> Split {
    let mid = refs.len() / 2;
    // Small ranges' infos have no centroid bounds.
    let centroids = if refs.len() <= SMALL {
        Acc::of(refs).centroids
    } else {
        info.centroids
    };
    let ext = [0, 1, 2].map(|k| centroids.hi[k] - centroids.lo[k]);
    let axis = (0..3)
        .max_by(|&a, &b| ext[a].total_cmp(&ext[b]))
        .unwrap_or(0);
    if ext[axis] > 0.0 {
        refs.select_nth_unstable_by(mid, |a, b| {
            // `hi` holds -hi: `lo - (-hi)` is `lo + hi`.
            (a.lo[axis] - a.hi[axis])
                .total_cmp(&(b.lo[axis] - b.hi[axis]))
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

/// Splits the part `left` (a range at `at` with at least two primitives, its orders there
/// when a sweep split made it) into itself and `right`; small ranges' sides get their orders
/// when `split_again` (the node may split them: its last split's sides it never does).
/// Returns the split's SAH numerator and where both sides are.
// Inlined into `build_node`: the sides then reach the parts without going through a return
// slot.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn split(
    refs: &mut [PrimRef],
    aux: &mut [PrimRef],
    at: At,
    left: &mut Part,
    right: &mut Part,
    ctx: &Ctx,
    depth: u32,
    split_again: bool,
) -> (f32, At) {
    let whole = |s: Split, left: &mut Part, right: &mut Part| {
        left.split_into(right, s.mid, (s.left, s.right), (None, None));
        s.cost
    };
    if depth >= MEDIAN_DEPTH {
        at.settle(refs, aux);
        return (whole(median_split(refs, &left.info), left, right), At::Refs);
    }
    if refs.len() == 2 {
        at.settle(refs, aux);
        // One way to split two: no orders to sort or sweep.
        let (l, r) = (Box8::of(&refs[0]), Box8::of(&refs[1]));
        let (l, r) = (RangeInfo::bounded(&l), RangeInfo::bounded(&r));
        let cost = l.bounds.half_area() + r.bounds.half_area();
        let one = Some(Orders([[0; SMALL]; 3]));
        left.split_into(right, 1, (l, r), (one, one));
        return (cost, At::Refs);
    }
    if refs.len() <= SMALL {
        at.settle(refs, aux);
        let orders = match &left.orders {
            Some(o) => *o,
            None => Orders::of(refs),
        };
        let cost = sweep_split(refs, &orders, left, right, split_again);
        return (cost, At::Refs);
    }
    let (s, at) = binned_split(refs, aux, at, &left.info, ctx);
    match s {
        Some(s) => (whole(s, left, right), at),
        None => {
            at.settle(refs, aux);
            (whole(median_split(refs, &left.info), left, right), At::Refs)
        }
    }
}

pub fn build(
    refs: &mut [PrimRef],
    aux: &mut [PrimRef],
    bins: usize,
    max_leaf: usize,
    traversal_cost: f32,
    nodes: &mut [Node],
) -> Tree {
    if refs.is_empty() {
        return NodeList::new(nodes).tree(None);
    }
    let ctx = Ctx {
        bins: bins.clamp(2, MAX_BINS),
        max_leaf: max_leaf.clamp(4, crate::layout::MAX_LEAF_SIZE),
        traversal_cost,
    };
    let info = enter(refs);
    let mut out = NodeList::new(nodes);
    let aux = &mut aux[..refs.len()];
    let root = build_child(refs, aux, At::Refs, 0, info, &ctx, 0, &mut out);
    leave(refs);
    out.tree(Some(root))
}

/// Negates the references' `hi`, as the builder holds them ([`Box8`]), and returns their info.
fn enter(refs: &mut [PrimRef]) -> RangeInfo {
    fn chunk(refs: &mut [PrimRef]) -> RangeInfo {
        let mut acc = Acc::EMPTY;
        for r in refs {
            *r = Box8(f32x8::new(bytemuck::cast(*r)) ^ NEG_HI).prim_ref();
            acc.add(r);
        }
        acc.info()
    }
    if refs.len() > PARALLEL_THRESHOLD * 4 {
        return refs
            .par_chunks_mut(PARALLEL_THRESHOLD)
            .map(chunk)
            .reduce(|| RangeInfo::EMPTY, RangeInfo::merge);
    }
    chunk(refs)
}

/// Restores the references' `hi` on return.
fn leave(refs: &mut [PrimRef]) {
    fn chunk(refs: &mut [PrimRef]) {
        for r in refs {
            *r = bytemuck::cast(Box8::of(r).0 ^ NEG_HI);
        }
    }
    if refs.len() > PARALLEL_THRESHOLD * 4 {
        refs.par_chunks_mut(PARALLEL_THRESHOLD).for_each(chunk);
    } else {
        chunk(refs);
    }
}

/// A leaf over the `n` primitives from position `base`.
#[inline(always)]
fn leaf(info: &RangeInfo, base: u32, n: usize) -> (Aabb, Child) {
    (
        info.bounds,
        Child::Leaf {
            first: base,
            count: n as u32,
        },
    )
}

/// Builds the subtree over a range at `at`, leaving its references in final order in `refs`.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn build_child(
    refs: &mut [PrimRef],
    aux: &mut [PrimRef],
    at: At,
    base: u32,
    info: RangeInfo,
    ctx: &Ctx,
    depth: u32,
    out: &mut NodeList,
) -> (Aabb, Child) {
    if refs.len() > LARGE {
        build_node::<true>(refs, aux, at, base, info, ctx, depth, out)
    } else {
        build_node::<false>(refs, aux, at, base, info, ctx, depth, out)
    }
}

/// [`build_child`] for a range of more than [`LARGE`] primitives when `LARGE`: only then can
/// its parts be in `aux` (a part of a smaller range is in `refs` once the range is split).
#[allow(clippy::too_many_arguments)]
fn build_node<const LARGE: bool>(
    refs: &mut [PrimRef],
    aux: &mut [PrimRef],
    at: At,
    base: u32,
    info: RangeInfo,
    ctx: &Ctx,
    depth: u32,
    out: &mut NodeList,
) -> (Aabb, Child) {
    let n = refs.len();
    let as_leaf = leaf(&info, base, n);
    // Fewer primitives than a node has slots: always a leaf (so every inner node is full).
    if n < WIDTH {
        at.settle(refs, aux);
        return as_leaf;
    }
    // The first split of this node; for a leaf-sized range it also decides, by the SAH,
    // whether a leaf is cheaper.
    let mut parts = [Part::EMPTY; WIDTH];
    parts[0] = Part {
        begin: 0,
        end: n,
        info,
        orders: None,
    };
    let (first_cost, first_at) = {
        let (l, r) = parts.split_at_mut(1);
        split(refs, aux, at, &mut l[0], &mut r[0], ctx, depth, true)
    };
    if n <= ctx.max_leaf {
        let area = info.bounds.half_area();
        if !(ctx.traversal_cost * area + first_cost < area * n as f32) {
            return as_leaf;
        }
    }
    let mut ats = [At::Refs; WIDTH];
    let at_of = |ats: &[At; WIDTH], j: usize| if LARGE { ats[j] } else { At::Refs };
    (ats[0], ats[1]) = (first_at, first_at);
    // Each part's area when it has at least two primitives (else -1, never picked).
    // (`Aabb::half_area`, 0 for an empty box or one with a NaN, without its branches.)
    let area = |p: &Part| {
        let b = &p.info.bounds;
        let d = [b.hi[0] - b.lo[0], b.hi[1] - b.lo[1], b.hi[2] - b.lo[2]];
        let half_area = d[0] * d[1] + d[1] * d[2] + d[2] * d[0];
        let full = (b.lo[0] <= b.hi[0]) & (b.lo[1] <= b.hi[1]) & (b.lo[2] <= b.hi[2]);
        let half_area = if full { half_area } else { 0.0 };
        if p.end - p.begin >= 2 {
            half_area
        } else {
            -1.0
        }
    };
    let mut areas = [-1.0f32; WIDTH];
    areas[0] = area(&parts[0]);
    areas[1] = area(&parts[1]);
    // Slot order as a list: part 0 starts the range, and a split part's right side follows
    // it (no sort of the parts afterwards).
    let mut next = [0u8; WIDTH];
    next[0] = 1;
    let mut count = 2;
    while count < WIDTH {
        // Split the (first) part with the largest area that has at least two primitives.
        // Over all slots with selects, not branches (slots not made yet have -1): which part
        // wins is data, not pattern.
        let (mut pick, mut best_area) = (WIDTH, -1.0f32);
        for (i, &a) in areas.iter().enumerate() {
            let better = a > best_area;
            best_area = if better { a } else { best_area };
            pick = if better { i } else { pick };
        }
        if pick == WIDTH {
            break;
        }
        let i = pick;
        let (head, tail) = parts.split_at_mut(count);
        let (left, right) = (&mut head[i], &mut tail[0]);
        let (begin, end) = (left.begin, left.end);
        let (_, s_at) = split(
            &mut refs[begin..end],
            &mut aux[begin..end],
            at_of(&ats, i),
            left,
            right,
            ctx,
            depth,
            count + 1 < WIDTH,
        );
        (ats[i], ats[count]) = (s_at, s_at);
        areas[i] = area(left);
        areas[count] = area(right);
        next[count] = next[i];
        next[i] = count as u8;
        count += 1;
    }
    let me = out.reserve();
    let mut node = Node::EMPTY;
    if n > PARALLEL_THRESHOLD && rayon::current_num_threads() > 1 {
        let mut cur = 0;
        let in_order: [usize; WIDTH] = std::array::from_fn(|_| {
            let j = cur;
            cur = next[j] as usize & (WIDTH - 1);
            j
        });
        // Hand each part its own disjoint slice, then build them in parallel.
        type Slot<'r> = Option<(&'r mut [PrimRef], &'r mut [PrimRef], At, u32, RangeInfo)>;
        let mut slices: [Slot; WIDTH] = Default::default();
        let (mut rest, mut aux_rest) = (refs, aux);
        let mut at = 0;
        for (slot, &j) in slices.iter_mut().zip(&in_order[..count]) {
            let Part {
                begin, end, info, ..
            } = parts[j];
            let (_, tail) = rest.split_at_mut(begin - at);
            let (mine, tail) = tail.split_at_mut(end - begin);
            let (_, atail) = aux_rest.split_at_mut(begin - at);
            let (amine, atail) = atail.split_at_mut(end - begin);
            *slot = Some((mine, amine, at_of(&ats, j), base + begin as u32, info));
            rest = tail;
            aux_rest = atail;
            at = end;
        }
        // Subtrees on their own lists, appended in slot order: the same nodes in the same
        // order as the sequential path below.
        let built: Vec<((Aabb, Child), NodeList)> = slices
            .into_par_iter()
            .flatten()
            .map(|(s, a, at, b, i)| {
                let mut sub = NodeList::with_capacity(node_hint(s.len()));
                let c = build_child(s, a, at, b, i, ctx, depth + 1, &mut sub);
                (c, sub)
            })
            .collect();
        for (k, ((b, c), sub)) in built.into_iter().enumerate() {
            tree::set_child(&mut node, k, &b, out.append(c, sub));
        }
    } else {
        // The parts in slot order, each on its own piece of the range.
        let mut j = 0;
        for k in 0..count {
            let (begin, end) = (parts[j].begin, parts[j].end);
            let first = base + begin as u32;
            // Most children are small leaves: made here, without a call, their box set
            // straight from the part.
            if end - begin < WIDTH {
                if LARGE {
                    ats[j].settle(&mut refs[begin..end], &aux[begin..end]);
                }
                let (b, c) = leaf(&parts[j].info, first, end - begin);
                tree::set_child(&mut node, k, &b, c);
            } else {
                let (s, a) = (&mut refs[begin..end], &mut aux[begin..end]);
                let info = parts[j].info;
                let (b, c) = build_child(s, a, at_of(&ats, j), first, info, ctx, depth + 1, out);
                tree::set_child(&mut node, k, &b, c);
            }
            j = next[j] as usize & (WIDTH - 1);
        }
    }
    out.set(me, node);
    (info.bounds, Child::Inner(me))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::build::tree::{Child, Tree};
    use crate::layout::{EMPTY_CHILD, LEAF_BIT};

    /// Checks a tree over `refs` with its nodes: every position in exactly one leaf, leaves of
    /// at most `max_leaf`, every inner node full, every child box holding its primitives.
    pub(crate) fn check(tree: &Tree, nodes: &[Node], refs: &[PrimRef], max_leaf: usize) {
        assert!(!tree.overflow);
        let mut seen = vec![false; refs.len()];
        let mut stack = vec![tree.root.expect("a root")];
        while let Some((b, c)) = stack.pop() {
            match c {
                Child::Leaf { first, count } => {
                    assert!(count as usize <= max_leaf.max(WIDTH - 1), "leaf of {count}");
                    for i in first..first + count {
                        assert!(!seen[i as usize], "position {i} twice");
                        seen[i as usize] = true;
                        let r = refs[i as usize].bounds();
                        for k in 0..3 {
                            assert!(b.lo[k] <= r.lo[k] && r.hi[k] <= b.hi[k]);
                        }
                    }
                }
                Child::Inner(i) => {
                    assert!((i as usize) < tree.node_count);
                    let node = &nodes[i as usize];
                    for k in 0..WIDTH {
                        let c = node.child[k];
                        assert_ne!(c, EMPTY_CHILD, "a node not full");
                        let b = node.bounds(k);
                        let child = if c & LEAF_BIT != 0 {
                            Child::Leaf {
                                first: c & !LEAF_BIT,
                                count: node.count[k] as u32,
                            }
                        } else {
                            Child::Inner(c)
                        };
                        stack.push((b, child));
                    }
                }
            }
        }
        assert!(seen.iter().all(|&s| s), "a position in no leaf");
    }

    fn refs_of(boxes: impl Iterator<Item = Aabb>) -> Vec<PrimRef> {
        boxes
            .enumerate()
            .map(|(i, b)| PrimRef::new(&b, i as u32))
            .collect()
    }

    fn build_and_check(mut refs: Vec<PrimRef>) {
        let mut ids: Vec<u32> = refs.iter().map(|r| r.id).collect();
        let mut aux = refs.clone();
        let mut nodes = vec![Node::EMPTY; node_hint(refs.len())];
        let tree = build(&mut refs, &mut aux, 32, 8, 2.0, &mut nodes);
        check(&tree, &nodes, &refs, 8);
        // The references are permuted, never lost or duplicated.
        let mut after: Vec<u32> = refs.iter().map(|r| r.id).collect();
        ids.sort_unstable();
        after.sort_unstable();
        assert_eq!(ids, after);
    }

    /// Uniform numbers in [0, 1] from a 32-bit xorshift.
    fn xorshift(mut seed: u32) -> impl FnMut() -> f32 {
        move || {
            seed ^= seed << 13;
            seed ^= seed >> 17;
            seed ^= seed << 5;
            seed as f32 / u32::MAX as f32
        }
    }

    /// Small ranges go through the sorted sweep, with orders handed from split to split:
    /// random boxes, identical centroids, ties on one axis, every size up to a few nodes.
    #[test]
    fn small_ranges_make_valid_trees() {
        let mut rnd = xorshift(12345u32);
        for n in 1..80usize {
            let random: Vec<Aabb> = (0..n)
                .map(|_| {
                    let c = [rnd() * 10.0, rnd() * 10.0, rnd() * 10.0];
                    let e = rnd();
                    Aabb {
                        lo: c.map(|x| x - e),
                        hi: c.map(|x| x + e),
                    }
                })
                .collect();
            build_and_check(refs_of(random.iter().copied()));
            let same = Aabb {
                lo: [1.0; 3],
                hi: [2.0; 3],
            };
            build_and_check(refs_of(std::iter::repeat_n(same, n)));
            // Equal centroids on x only, growing boxes (nested, all sharing one centre).
            build_and_check(refs_of((0..n).map(|i| Aabb {
                lo: [0.0, i as f32, -(i as f32)],
                hi: [2.0, i as f32 + 1.0, -(i as f32) + 1.0],
            })));
            build_and_check(refs_of((0..n).map(|i| Aabb {
                lo: [-(i as f32); 3],
                hi: [i as f32; 3],
            })));
        }
    }

    /// Ranges large enough to be binned on a sample (and partitioned mirrored, above
    /// `LARGE`) still make valid trees, whose child boxes are their primitives' exact bounds,
    /// and the same tree on one thread as on four.
    #[test]
    fn sampled_ranges_make_exact_trees_on_any_thread_count() {
        let mut rnd = xorshift(4242u32);
        let n = 2 * LARGE + 1234;
        assert!(sample_stride(n) == 8 && sample_stride(SAMPLE_FROM) == 4);
        let boxes: Vec<Aabb> = (0..n)
            .map(|_| {
                let c = [rnd() * 100.0, rnd() * 10.0, rnd()];
                let e = rnd() * rnd() * 2.0;
                Aabb {
                    lo: c.map(|x| x - e),
                    hi: c.map(|x| x + e),
                }
            })
            .collect();
        let on = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| {
                let mut refs = refs_of(boxes.iter().copied());
                let mut aux = refs.clone();
                let mut nodes = vec![Node::EMPTY; node_hint(n)];
                let tree = build(&mut refs, &mut aux, 32, 8, 2.0, &mut nodes);
                check(&tree, &nodes, &refs, 8);
                nodes.truncate(tree.node_count);
                (tree.root.map(|(b, _)| b), nodes, refs)
            })
        };
        let (root, nodes, refs) = on(1);
        // Every child box is the union of what it holds: no slack from the sample.
        let mut exact = vec![Aabb::EMPTY; nodes.len()];
        for i in (0..nodes.len()).rev() {
            for k in 0..WIDTH {
                let c = nodes[i].child[k];
                let held = if c & LEAF_BIT != 0 {
                    let first = (c & !LEAF_BIT) as usize;
                    let count = nodes[i].count[k] as usize;
                    refs[first..first + count]
                        .iter()
                        .fold(Aabb::EMPTY, |b, r| b.union(&r.bounds()))
                } else {
                    exact[c as usize]
                };
                let b = nodes[i].bounds(k);
                assert_eq!((b.lo, b.hi), (held.lo, held.hi), "node {i} child {k}");
                exact[i] = exact[i].union(&held);
            }
        }
        assert_eq!(root.map(|b| (b.lo, b.hi)), Some((exact[0].lo, exact[0].hi)));
        let (root4, nodes4, refs4) = on(4);
        assert_eq!(root.map(|b| (b.lo, b.hi)), root4.map(|b| (b.lo, b.hi)));
        assert!(bytemuck::cast_slice::<_, u8>(&nodes) == bytemuck::cast_slice::<_, u8>(&nodes4));
        assert!(refs.iter().map(|r| r.id).eq(refs4.iter().map(|r| r.id)));
    }

    /// The orders a sweep split hands to each side are the sides' own orders (distinct
    /// centroids, so no ties to break differently).
    #[test]
    fn sweep_hands_down_the_sides_orders() {
        let mut rnd = xorshift(777u32);
        for n in 3..=SMALL {
            for _ in 0..50 {
                let mut refs = refs_of((0..n).map(|_| {
                    let c = [rnd(), rnd(), rnd()];
                    let e = rnd() * 0.1;
                    Aabb {
                        lo: c.map(|x| x - e),
                        hi: c.map(|x| x + e),
                    }
                }));
                let orders = Orders::of(&refs);
                let (mut left, mut right) = (Part::EMPTY, Part::EMPTY);
                left.end = n;
                sweep_split(&mut refs, &orders, &mut left, &mut right, true);
                let mid = left.end;
                assert!(mid > 0 && mid < n && (right.begin, right.end) == (mid, n));
                for (side, part) in [(&refs[..mid], left), (&refs[mid..], right)] {
                    // Sides of one or two are never swept; the others always get orders.
                    let Some(o) = part.orders else {
                        assert!(mid <= 2 && n - mid <= 2, "a swept side without orders");
                        continue;
                    };
                    let fresh = Orders::of(side);
                    for k in 0..3 {
                        assert_eq!(o.0[k][..side.len()], fresh.0[k][..side.len()]);
                    }
                }
            }
        }
    }
}
