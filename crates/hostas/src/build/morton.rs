//! Fast builder: sort primitives by the Morton code of their centroid (radix sort), then split
//! each range at the highest bit in which its first and last codes differ (a top-down LBVH),
//! filling 8-wide nodes. Bounds are computed bottom-up, so the whole build is a few linear passes.
//!
//! The passes: centroid bounds (unless the decoder computed them); keys `(code, position)` with the first digit's histogram;
//! the radix sort; the tree, whose leaves gather their primitives in sorted order into their
//! final place while computing their bounds (see `Gather`).

use super::tree::{Child, NodeList, Tree, node_hint};
use super::{MEDIAN_DEPTH, PARALLEL_THRESHOLD, PrimRef};
use crate::layout::{LEAF_BIT, Node, WIDTH};
use crate::math::Box4;
use rayon::prelude::*;
use wide::{f32x4, f64x4, u8x32, u32x8, u64x4};

/// Spreads the low 10 bits of `v` to every third bit.
const fn spread(v: u32) -> u32 {
    let mut x = v & 0x3ff;
    x = (x | (x << 16)) & 0x0300_00ff;
    x = (x | (x << 8)) & 0x0300_f00f;
    x = (x | (x << 4)) & 0x030c_30c3;
    x = (x | (x << 2)) & 0x0924_9249;
    x
}

/// `spread` of every 10-bit value.
static SPREAD: [u32; 1024] = {
    let mut t = [0u32; 1024];
    let mut i = 0;
    while i < 1024 {
        t[i] = spread(i as u32);
        i += 1;
    }
    t
};

/// Bits per radix-sort digit: three passes over the 30 code bits.
const DIGIT: u32 = 10;
const BUCKETS: usize = 1 << DIGIT;
/// Shift of the top digit (code bits 20..30).
const TOP_SHIFT: u32 = 2 * DIGIT;
/// The linear passes work in chunks of this many references.
const CHUNK: usize = PARALLEL_THRESHOLD * 16;

/// Ranges up to this size find their split point in `delta`, not by a binary search.
const LINEAR_SPLIT: usize = 256;

/// Keeps lanes 0..3 (lane 3 of a reference holds the id or pad bits).
const XYZ: f32x4 = f32x4::new([
    f32::from_bits(!0),
    f32::from_bits(!0),
    f32::from_bits(!0),
    0.0,
]);

/// The doubled centroid of `r` (`lo + hi`), lane 3 zero.
#[inline(always)]
fn center2(r: &PrimRef) -> f32x4 {
    let [lo, hi]: [f32x4; 2] = bytemuck::cast(*r);
    (lo & XYZ) + (hi & XYZ)
}

/// Bounds of the doubled centroids of `src`, over fixed chunks combined in order.
fn centroid_bounds<G: Gather>(src: &[G::Prim]) -> Box4 {
    let part = |ps: &[G::Prim]| {
        let mut b = Box4::EMPTY;
        for c in G::centers(ps) {
            b = b.union(Box4 { lo: c, hi: c });
        }
        b
    };
    if src.len() <= CHUNK {
        return part(src);
    }
    let parts: Vec<Box4> = src.par_chunks(CHUNK).map(part).collect();
    parts.into_iter().fold(Box4::EMPTY, Box4::union)
}

/// Digit histograms (bucket counts, then bucket starts).
type Hist<const B: usize = BUCKETS> = Box<[u32; B]>;

fn hist_new<const B: usize>() -> Hist<B> {
    // (Not through an array on the stack: a wide histogram is 128 KiB.)
    bytemuck::allocation::zeroed_box()
}

/// Turns counts into starts.
fn starts<const B: usize>(h: &mut [u32; B]) {
    let mut sum = 0;
    for c in h.iter_mut() {
        let v = *c;
        *c = sum;
        sum += v;
    }
}

/// One radix pass: `src` scattered into `dst` by the digit at `shift` (`at` holds the bucket
/// starts), `each` seeing every key (to count the next digit).
#[inline(always)]
fn scatter<const B: usize>(
    src: &[u64],
    dst: &mut [u64],
    at: &mut [u32; B],
    shift: u32,
    mut each: impl FnMut(u64),
) {
    for &k in src {
        let b = (k >> shift) as usize & (B - 1);
        let p = at[b];
        if let Some(d) = dst.get_mut(p as usize) {
            *d = k;
        }
        at[b] = p + 1;
        each(k);
    }
}

/// Counts the digit at `shift` of `k` into `h`.
#[inline(always)]
fn count<const B: usize>(h: &mut [u32; B], shift: u32) -> impl FnMut(u64) + '_ {
    move |k| h[(k >> shift) as usize & (B - 1)] += 1
}

/// Inputs of at least this many primitives sort by the top digit first.
const MSD_MIN: usize = 1 << 17;
/// Smaller inputs of at least this many primitives sort by two wide digits: one pass fewer,
/// for histograms whose upkeep only pays from here.
const WIDE_MIN: usize = 1 << 15;
/// Bits per wide digit: two passes over the 30 code bits.
const WIDE_DIGIT: u32 = 15;
const WIDE_BUCKETS: usize = 1 << WIDE_DIGIT;
/// Top buckets up to this size are sorted by comparison.
const SMALL_SORT: usize = 96;

/// Sorts `keys` (one top bucket) by the two lower code digits, with `tmp` (as long) as
/// working space.
fn sort_low(keys: &mut [u64], tmp: &mut [u64]) {
    if keys.len() <= SMALL_SORT {
        keys.sort_unstable();
        return;
    }
    let (mut h0, mut h1) = ([0u32; BUCKETS], [0u32; BUCKETS]);
    for &k in keys.iter() {
        h0[(k >> 32) as usize & (BUCKETS - 1)] += 1;
        h1[(k >> (32 + DIGIT)) as usize & (BUCKETS - 1)] += 1;
    }
    starts(&mut h0);
    starts(&mut h1);
    scatter(keys, tmp, &mut h0, 32, |_| {});
    scatter(tmp, keys, &mut h1, 32 + DIGIT, |_| {});
}

/// Sorts `keys` into `tmp` (both changed), given the counts of the first digit sorted by
/// (the top one when `msd`, else the lowest). Returns where each top digit starts in the
/// sorted order, then the length: the split points of the top levels, read off instead of
/// searched for.
fn sort(keys: &mut [u64], tmp: &mut [u64], mut h: Hist, msd: bool) -> Vec<u32> {
    let n = keys.len();
    starts(&mut h);
    let mut top;
    if msd {
        top = h.to_vec();
        top.push(n as u32);
        scatter(keys, tmp, &mut h, 32 + TOP_SHIFT, |_| {});
        let mut buckets = Vec::with_capacity(BUCKETS);
        let (mut a, mut t) = (&mut tmp[..], &mut keys[..]);
        for w in top.windows(2) {
            let m = (w[1] - w[0]) as usize;
            let (x, a2) = std::mem::take(&mut a).split_at_mut(m);
            let (y, t2) = std::mem::take(&mut t).split_at_mut(m);
            buckets.push((x, y));
            (a, t) = (a2, t2);
        }
        buckets
            .into_par_iter()
            .with_min_len(BUCKETS / 16)
            .for_each(|(x, y)| sort_low(x, y));
    } else {
        let (mut h1, mut h2) = (hist_new::<BUCKETS>(), hist_new::<BUCKETS>());
        scatter(keys, tmp, &mut h, 32, count(&mut h1, 32 + DIGIT));
        starts(&mut h1);
        scatter(
            tmp,
            keys,
            &mut h1,
            32 + DIGIT,
            count(&mut h2, 32 + TOP_SHIFT),
        );
        starts(&mut h2);
        top = h2.to_vec();
        top.push(n as u32);
        scatter(keys, tmp, &mut h2, 32 + TOP_SHIFT, |_| {});
    }
    top
}

/// Sorts `keys` by two wide digits (into `tmp` and back: both changed), given the counts of
/// the lower one. Returns what [`sort`] does.
fn sort_wide(keys: &mut [u64], tmp: &mut [u64], mut h: Hist<WIDE_BUCKETS>) -> Vec<u32> {
    let n = keys.len();
    starts(&mut h);
    let mut h1 = hist_new::<WIDE_BUCKETS>();
    scatter(keys, tmp, &mut h, 32, count(&mut h1, 32 + WIDE_DIGIT));
    starts(&mut h1);
    // A top digit starts where the first wide bucket of its upper bits does.
    let per_top = 1 << (TOP_SHIFT - WIDE_DIGIT);
    let mut top: Vec<u32> = h1.iter().step_by(per_top).copied().collect();
    top.push(n as u32);
    scatter(tmp, keys, &mut h1, 32 + WIDE_DIGIT, |_| {});
    top
}

/// Writes the keys `(code, position)` of `src` (centroids mapped by `lo` and `scale`) and
/// returns the histogram of their digit at `shift` (the first sorted by). Centroids lie in
/// the bounds, so the scaled values are in [0, 1023] (up to rounding below 1024); NaN
/// converts to i32::MIN, whose low bits are 0.
fn codes<const B: usize, G: Gather>(
    keys: &mut [u64],
    src: &[G::Prim],
    lo: f32x4,
    scale: f32x4,
    shift: u32,
) -> Hist<B> {
    // One chunk per thread at most: each is a histogram to zero and add (the counts do not
    // depend on the chunks).
    let chunk = keys.len().div_ceil(rayon::current_num_threads()).max(CHUNK);
    keys.par_chunks_mut(chunk)
        .zip(src.par_chunks(chunk))
        .enumerate()
        .map(move |(ci, (ks, ps))| {
            let mut h = hist_new::<B>();
            let first = (ci * chunk) as u64;
            for (i, (k, c)) in ks.iter_mut().zip(G::centers(ps)).enumerate() {
                let q = ((c - lo) * scale).fast_trunc_int().to_array();
                let code = (SPREAD[q[0] as usize & 1023] << 2)
                    | (SPREAD[q[1] as usize & 1023] << 1)
                    | SPREAD[q[2] as usize & 1023];
                *k = (code as u64) << 32 | (first + i as u64);
                h[(code >> shift) as usize & (B - 1)] += 1;
            }
            h
        })
        // (Without an identity: each would be one more histogram to zero.)
        .reduce_with(|mut a, b| {
            for (x, y) in a.iter_mut().zip(b.iter()) {
                *x += y;
            }
            a
        })
        .unwrap_or_else(hist_new)
}

/// Per sorted position, 1 + the highest bit in which its code and the next differ (0: equal,
/// or the last position).
fn deltas(sorted: &[u64], delta: &mut [u8]) {
    delta
        .par_chunks_mut(CHUNK)
        .zip(sorted.par_chunks(CHUNK))
        .enumerate()
        .for_each(|(ci, (d, ks))| {
            let f = |a: u64, b: u64| (64 - ((a ^ b) >> 32).leading_zeros()) as u8;
            let (body, last) = d.split_at_mut(d.len() - 1);
            let mut quads = body.chunks_exact_mut(4);
            for (q, w) in (&mut quads).zip(ks.windows(5).step_by(4)) {
                q.copy_from_slice(&deltas4(w));
            }
            let rest = quads.into_remainder();
            let done = ks.len() - 1 - rest.len();
            for (d, w) in rest.iter_mut().zip(ks[done..].windows(2)) {
                *d = f(w[0], w[1]);
            }
            let (a, next) = (ks[ks.len() - 1], sorted.get((ci + 1) * CHUNK));
            last[0] = next.map_or(0, |&b| f(a, b));
        });
}

/// The deltas of the four pairs in `w` (five keys). AVX2 has no vector `lzcnt`: the number of
/// bits of `x` (the codes' XOR) is the exponent of `2x + 1` (odd, so 0 counts none), read off
/// its exact `f64`, made by the 2^52 trick.
#[inline(always)]
fn deltas4(w: &[u64]) -> [u8; 4] {
    const MAGIC: u64 = 0x4330_0000_0000_0000;
    let at = |k: usize| u64x4::from(<[u64; 4]>::try_from(&w[k..k + 4]).unwrap_or_default());
    let x = ((at(0) ^ at(1)) >> 32_u32) << 1_u32 | u64x4::splat(MAGIC | 1);
    let v = bytemuck::cast::<u64x4, f64x4>(x) - f64x4::splat(f64::from_bits(MAGIC));
    let e: u64x4 = bytemuck::cast::<f64x4, u64x4>(v) >> 52_u32;
    e.to_array().map(|e| (e - 1023) as u8)
}

/// Builds the tree over `refs` (left as they are); the references in final order go into
/// `aux`.
/// `centroids`: the bounds of the doubled centroids where the decoder computed them.
pub fn build(
    refs: &[PrimRef],
    aux: &mut [PrimRef],
    keys: &mut [u64],
    tmp: &mut [u64],
    centroids: Option<Box4>,
    max_leaf: usize,
    nodes: &mut [Node],
) -> Tree {
    let n = refs.len();
    let dst = Refs {
        refs,
        dst: &mut aux[..n],
        first: 0,
    };
    build_into(n, dst, keys, tmp, centroids, max_leaf, nodes)
}

/// Builds the tree over the triangles `tris` (nine floats each, their references as the
/// decoder makes them, with positions for ids, would be the same tree's input): the triangles
/// in final order go straight into `prims` and their positions into `ids` (the structure's
/// primitive sections), so no reference is made or copied, and no other pass gathers the
/// primitives. The tree is the one [`build`] makes over those references.
#[allow(clippy::too_many_arguments)]
pub fn build_triangles(
    tris: &[[f32; 9]],
    prims: &mut [[f32; 9]],
    ids: &mut [u32],
    keys: &mut [u64],
    tmp: &mut [u64],
    centroids: Option<Box4>,
    max_leaf: usize,
    nodes: &mut [Node],
) -> Tree {
    let n = tris.len();
    let dst = Tris {
        tris,
        flat: bytemuck::cast_slice(tris),
        prims: &mut prims[..n],
        ids: &mut ids[..n],
        first: 0,
    };
    build_into(n, dst, keys, tmp, centroids, max_leaf, nodes)
}

fn build_into<G: Gather>(
    n: usize,
    mut dst: G,
    keys: &mut [u64],
    tmp: &mut [u64],
    centroids: Option<Box4>,
    max_leaf: usize,
    nodes: &mut [Node],
) -> Tree {
    if n == 0 {
        return NodeList::new(nodes).tree(None);
    }
    let src = dst.source();
    let c = centroids.unwrap_or_else(|| centroid_bounds::<G>(src));
    let ext = c.hi - c.lo;
    let scale = f32x4::from(
        ext.to_array()
            .map(|e| if e > 0.0 { 1023.0 / e } else { 0.0 }),
    );
    let lo = c.lo;
    let keys = &mut keys[..n];
    let tmp = &mut tmp[..n];
    // Large inputs are sorted by the top digit first (one pass through memory) and then each
    // top bucket by the two lower digits where it sits in the caches; middle ones by two wide
    // digits and small ones by three, from the lowest, each pass counting the next digit. All
    // sort by the whole key, whose low half (the position) keeps equal codes in input order.
    let (top, sorted, free) = if n >= MSD_MIN {
        let h = codes::<BUCKETS, G>(keys, src, lo, scale, TOP_SHIFT);
        (sort(keys, tmp, h, true), tmp, keys)
    } else if n >= WIDE_MIN {
        let h = codes::<WIDE_BUCKETS, G>(keys, src, lo, scale, 0);
        (sort_wide(keys, tmp, h), keys, tmp)
    } else {
        let h = codes::<BUCKETS, G>(keys, src, lo, scale, 0);
        (sort(keys, tmp, h, false), tmp, keys)
    };
    // The other array is free now: the differing bits of neighbouring codes, with 32 zeros
    // after.
    let delta = &mut bytemuck::cast_slice_mut::<u64, u8>(free)[..(n + 32).min(8 * n)];
    delta[n..].fill(0);
    deltas(sorted, &mut delta[..n]);
    let ctx = Ctx {
        keys: sorted,
        top: &top,
        delta,
        leaf_max: max_leaf.max(WIDTH - 1),
    };
    let mut out = NodeList::new(nodes);
    let (b, c) = ctx.build(0, n, &mut dst, 0, &mut out);
    out.tree(Some((b.aabb(), c)))
}

/// Where the leaves put their primitives, in final order, and what they read them from: the
/// places of sorted positions `first..`.
trait Gather: Default + Send + Sized {
    /// A primitive as read.
    type Prim: Sync;
    /// The primitives in input order.
    fn source(&self) -> &[Self::Prim];
    /// The doubled centroids of `ps` (`lo + hi` of their bounds; lane 3 unspecified).
    fn centers(ps: &[Self::Prim]) -> impl Iterator<Item = f32x4> + '_;
    /// The places of the first `at` positions and those of the rest.
    fn split_at(self, at: usize) -> (Self, Self);
    /// Gathers the primitives at positions `keys` (the keys' low halves), sorted positions
    /// `base..`, into their places and returns their bounds.
    fn leaf(&mut self, base: usize, keys: &[u64]) -> Box4;
}

/// References gathered from `refs` into `dst`.
#[derive(Default)]
struct Refs<'a> {
    refs: &'a [PrimRef],
    dst: &'a mut [PrimRef],
    first: usize,
}

impl<'a> Gather for Refs<'a> {
    type Prim = PrimRef;
    fn source(&self) -> &[PrimRef] {
        self.refs
    }
    #[inline(always)]
    fn centers(rs: &[PrimRef]) -> impl Iterator<Item = f32x4> + '_ {
        rs.iter().map(center2)
    }
    fn split_at(self, at: usize) -> (Self, Self) {
        let (a, b) = self.dst.split_at_mut(at.min(self.dst.len()));
        let (refs, first) = (self.refs, self.first);
        (
            Refs {
                refs,
                dst: a,
                first,
            },
            Refs {
                refs,
                dst: b,
                first: first + at,
            },
        )
    }
    #[inline(always)]
    fn leaf(&mut self, base: usize, keys: &[u64]) -> Box4 {
        let mut b = Box4::EMPTY;
        let dst = self.dst.iter_mut().skip(base - self.first);
        for (d, &k) in dst.zip(keys) {
            let r = self.refs[k as u32 as usize];
            *d = r;
            b = b.union(r.box4());
        }
        b
    }
}

/// Floats `i..i + 4` of `w` (a vertex at `i` in lanes 0..3: one load).
#[inline(always)]
fn load4(w: &[f32], i: usize) -> f32x4 {
    f32x4::from(<[f32; 4]>::try_from(&w[i..i + 4]).unwrap_or_default())
}

/// Triangles gathered from `tris` into `prims`, their positions into `ids`.
#[derive(Default)]
struct Tris<'a> {
    tris: &'a [[f32; 9]],
    /// `tris` as one run of floats.
    flat: &'a [f32],
    prims: &'a mut [[f32; 9]],
    ids: &'a mut [u32],
    first: usize,
}

impl Gather for Tris<'_> {
    type Prim = [f32; 9];
    fn source(&self) -> &[[f32; 9]] {
        self.tris
    }
    #[inline(always)]
    fn centers(ts: &[[f32; 9]]) -> impl Iterator<Item = f32x4> + '_ {
        ts.iter().map(|t| {
            // The last vertex from floats 5..9, rotated (the first two from one load each).
            let c = load4(t, 5).to_array();
            let c = f32x4::from([c[1], c[2], c[3], c[0]]);
            let b = Box4::triangle(load4(t, 0), load4(t, 3), c);
            b.lo + b.hi
        })
    }
    fn split_at(self, at: usize) -> (Self, Self) {
        let (p, q) = self.prims.split_at_mut(at.min(self.prims.len()));
        let (i, j) = self.ids.split_at_mut(at.min(self.ids.len()));
        let (tris, flat, first) = (self.tris, self.flat, self.first);
        (
            Tris {
                tris,
                flat,
                prims: p,
                ids: i,
                first,
            },
            Tris {
                tris,
                flat,
                prims: q,
                ids: j,
                first: first + at,
            },
        )
    }
    #[inline(always)]
    fn leaf(&mut self, base: usize, keys: &[u64]) -> Box4 {
        let mut bounds = Box4::EMPTY;
        let at = base - self.first;
        let (Some(prims), Some(ids)) = (
            self.prims.get_mut(at..at + keys.len()),
            self.ids.get_mut(at..at + keys.len()),
        ) else {
            return bounds;
        };
        for ((p, id), &k) in prims.iter_mut().zip(ids).zip(keys) {
            let at = k as u32;
            let first = 9 * at as usize;
            // Each vertex one load of four floats (but the last triangle's last vertex, whose
            // fourth float would lie past the end).
            let tri = match self.flat.get(first..first + 10) {
                Some(t) => {
                    p.copy_from_slice(&t[..9]);
                    Box4::triangle(load4(t, 0), load4(t, 3), load4(t, 6))
                }
                None => {
                    let t = self.flat.get(first..first + 9).unwrap_or(&[0.0; 9]);
                    p.copy_from_slice(t);
                    let v = |i: usize| f32x4::from([t[i], t[i + 1], t[i + 2], 0.0]);
                    Box4::triangle(v(0), v(3), v(6))
                }
            };
            *id = at;
            // The reference's bounds, as the decoder made them (lane 3 aside).
            bounds = bounds.union(tri);
        }
        bounds
    }
}

/// What every level of the tree reads.
struct Ctx<'a> {
    /// Sorted keys: code in the high half, position in `refs` in the low half.
    keys: &'a [u64],
    /// Start of each top digit in the sorted order, then `n`.
    top: &'a [u32],
    /// Per sorted position, 1 + the highest bit in which its code and the next differ (0:
    /// equal, or the last), then zeros.
    delta: &'a [u8],
    /// Ranges up to this size become leaves.
    leaf_max: usize,
}

/// Position of the first key in `keys` whose code differs from the first code in the highest
/// differing bit, or the middle when all codes are equal. `keys` start at position `base` of
/// the sorted keys, and `top` says where each top digit starts there: splits on a top-digit bit
/// are looked up, not searched for (the searches at the top levels miss the caches). `delta`
/// holds per sorted position the highest differing bit (plus one) between its code and the
/// next: in a short range the split is where it equals the range's highest differing bit.
#[inline(always)]
fn split_point(keys: &[u64], base: usize, top: &[u32], delta: &[u8]) -> usize {
    let n = keys.len();
    let (first, last) = ((keys[0] >> 32) as u32, (keys[n - 1] >> 32) as u32);
    if first == last {
        return n / 2;
    }
    let bit = 31 - (first ^ last).leading_zeros();
    if n <= LINEAR_SPLIT {
        // The one pair in the range that differs in `bit`, 32 pairs at a time.
        let want = u8x32::splat(bit as u8 + 1);
        if n <= 33 {
            // Up to 32 pairs (most ranges): one load, no loop.
            if let Some(d) = delta.get(base..base + 32) {
                let d: [u8; 32] = d.try_into().unwrap_or([0; 32]);
                let hits = u8x32::from(d).simd_eq(want).to_bitmask() & (u32::MAX >> (33 - n));
                if hits != 0 {
                    return hits.trailing_zeros() as usize + 1;
                }
            }
        }
        let mut at = 0;
        while at + 1 < n {
            let Some(d) = delta.get(base + at..base + at + 32) else {
                break;
            };
            let d: [u8; 32] = d.try_into().unwrap_or([0; 32]);
            let mut hits = u8x32::from(d).simd_eq(want).to_bitmask();
            // Pairs past the range's last one (`n - 2`) do not count.
            let pairs = n - 1 - at;
            if pairs < 32 {
                hits &= (1u32 << pairs) - 1;
            }
            if hits != 0 {
                return at + hits.trailing_zeros() as usize + 1;
            }
            at += 32;
        }
    }
    // The right half starts at the first code of at least `first`'s prefix with the bit set
    // (its lower bits zero).
    let right = (first & !((1u32 << bit) - 1)) | 1 << bit;
    if bit >= TOP_SHIFT {
        // Codes before `base` are at most `first`: the split is where that top digit starts.
        if let Some(&at) = top.get((right >> TOP_SHIFT) as usize) {
            return (at as usize).saturating_sub(base).min(n);
        }
    }
    let t = (right as u64) << 32;
    keys.partition_point(|&k| k < t)
}

/// Writes child `k` of `node`.
#[inline(always)]
fn set_child(node: &mut Node, k: usize, b: &Box4, c: Child) {
    node.set_bounds(k, &b.aabb());
    match c {
        Child::Leaf { first, count } => {
            node.child[k] = LEAF_BIT | first;
            node.count[k] = count as u8;
        }
        Child::Inner(i) => node.child[k] = i,
    }
}

impl Ctx<'_> {
    /// Builds the subtree over sorted positions `base..base + n`, gathering their primitives
    /// into `dst` as its leaves read them.
    fn build<G: Gather>(
        &self,
        base: usize,
        n: usize,
        dst: &mut G,
        depth: u32,
        out: &mut NodeList,
    ) -> (Box4, Child) {
        let keys = &self.keys[base..base + n];
        if n <= self.leaf_max {
            let c = Child::Leaf {
                first: base as u32,
                count: n as u32,
            };
            return (dst.leaf(base, keys), c);
        }
        // The parts by when they were made (a split's left half keeps its part's number, the
        // right half takes the next one): where each starts, which follows it in position
        // order, and its split key `size * WIDTH + (WIDTH - 1 - number)`, 0 while unmade.
        // The keys are distinct, so their maximum names the part to split next.
        let mut start = [0usize; WIDTH];
        let mut next = [0u8; WIDTH];
        let mut key = u32x8::from([(n * WIDTH + WIDTH - 1) as u32, 0, 0, 0, 0, 0, 0, 0]);
        let lanes = u32x8::from([0, 1, 2, 3, 4, 5, 6, 7]);
        let mut live = 1;
        while live < WIDTH {
            // Split the part with the most primitives (areas are not known top-down), the
            // first made among equals; parts of one primitive are never split.
            let best = key.reduce_max() as usize;
            if best < 2 * WIDTH {
                break;
            }
            let i = WIDTH - 1 - best % WIDTH;
            let (b, size) = (start[i], best / WIDTH);
            // (A pair splits in its middle whatever its codes.)
            let mid = if depth < MEDIAN_DEPTH && size > 2 {
                split_point(&keys[b..b + size], base + b, self.top, self.delta)
            } else {
                size / 2
            }
            .clamp(1, size - 1);
            start[live] = b + mid;
            next[live] = next[i];
            next[i] = live as u8;
            let left = u32x8::splat((mid * WIDTH + WIDTH - 1 - i) as u32);
            let right = u32x8::splat(((size - mid) * WIDTH + WIDTH - 1 - live) as u32);
            key = lanes.simd_eq(u32x8::splat(i as u32)).bitselect(left, key);
            key = lanes
                .simd_eq(u32x8::splat(live as u32))
                .bitselect(right, key);
            live += 1;
        }
        // The parts in position order, by their ends (each starts where the previous ends).
        let key = key.to_array();
        let mut ends = [0usize; WIDTH];
        let (mut part, mut end) = (0, 0);
        for e in &mut ends[..live] {
            end += key[part] as usize / WIDTH;
            *e = end;
            part = next[part] as usize;
        }
        let me = out.reserve();
        let mut node = Node::EMPTY;
        let mut bounds = Box4::EMPTY;
        if n > PARALLEL_THRESHOLD && rayon::current_num_threads() > 1 {
            // (The pieces take all of `dst`'s places: this subtree fills them.)
            let mut pieces = Vec::with_capacity(live);
            let (mut rest, mut s) = (std::mem::take(dst), 0);
            for &e in &ends[..live] {
                let (mine, tail) = rest.split_at(e - s);
                pieces.push((s, e - s, mine));
                (rest, s) = (tail, e);
            }
            let built: Vec<(Box4, Child, NodeList)> = pieces
                .into_par_iter()
                .map(|(s, m, mut d)| {
                    let mut sub = NodeList::with_capacity(node_hint(m));
                    let (b, c) = self.build(base + s, m, &mut d, depth + 1, &mut sub);
                    (b, c, sub)
                })
                .collect();
            for (k, (b, c, sub)) in built.into_iter().enumerate() {
                let c = out.append(c, sub);
                set_child(&mut node, k, &b, c);
                bounds = bounds.union(b);
            }
        } else {
            let mut s = 0;
            for (k, &e) in ends[..live].iter().enumerate() {
                // Leaves inline: a returned child read back at once stalls on store forwarding.
                let (b, c) = if e - s <= self.leaf_max {
                    let c = Child::Leaf {
                        first: (base + s) as u32,
                        count: (e - s) as u32,
                    };
                    (dst.leaf(base + s, &keys[s..e]), c)
                } else {
                    self.build(base + s, e - s, dst, depth + 1, out)
                };
                set_child(&mut node, k, &b, c);
                bounds = bounds.union(b);
                s = e;
            }
        }
        out.set(me, node);
        (bounds, Child::Inner(me))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small deterministic generator (xorshift32).
    fn xorshift(mut seed: u32) -> impl FnMut() -> u32 {
        move || {
            seed ^= seed << 13;
            seed ^= seed >> 17;
            seed ^= seed << 5;
            seed
        }
    }

    /// Split points found in `delta` are those of a binary search.
    #[test]
    fn delta_splits() {
        let mut rnd = xorshift(0x1234_5678);
        // (Past one chunk of the parallel pass.)
        let n = CHUNK + 5000;
        // Few distinct codes in places, so that equal neighbours occur.
        let mut keys: Vec<u64> = (0..n)
            .map(|i| ((rnd() & 0x3fff_ffff & !(rnd() & 0xff)) as u64) << 32 | i as u64)
            .collect();
        keys.sort_unstable();
        let mut delta = vec![0u8; n + 32];
        deltas(&keys, &mut delta[..n]);
        for _ in 0..20_000 {
            let b = rnd() as usize % (n - 2);
            let e = (b + 2 + rnd() as usize % LINEAR_SPLIT).min(n);
            let r = &keys[b..e];
            let (first, last) = ((r[0] >> 32) as u32, (r[r.len() - 1] >> 32) as u32);
            let want = if first == last {
                r.len() / 2
            } else {
                let bit = 31 - (first ^ last).leading_zeros();
                let right = (first & !((1u32 << bit) - 1)) | 1 << bit;
                r.partition_point(|&k| k < (right as u64) << 32)
            };
            assert_eq!(split_point(r, b, &[], &delta), want, "range {b}..{e}");
        }
    }

    /// The sorts (from the top digit, from the lowest, by wide digits) give the keys in order.
    #[test]
    fn radix_sorts_sort() {
        let mut rnd = xorshift(0x2545_f491);
        for (n, clustered) in [(1000, false), (MSD_MIN + 5, false), (MSD_MIN + 5, true)] {
            let keys: Vec<u64> = (0..n)
                .map(|i| {
                    // Clustered codes fill few top buckets, some far beyond SMALL_SORT.
                    let c = rnd() & ((1 << 30) - 1);
                    let c = if clustered { c & 0x0303_ffff } else { c };
                    (c as u64) << 32 | i as u64
                })
                .collect();
            let mut want = keys.clone();
            want.sort_unstable();
            for (msd, wide) in [(false, false), (true, false), (false, true)] {
                let (mut k, mut t) = (keys.clone(), vec![0; n]);
                let top = if wide {
                    let mut h = hist_new::<WIDE_BUCKETS>();
                    for k in &keys {
                        h[(k >> 32) as usize & (WIDE_BUCKETS - 1)] += 1;
                    }
                    let top = sort_wide(&mut k, &mut t, h);
                    // (Sorted back into `k`.)
                    std::mem::swap(&mut k, &mut t);
                    top
                } else {
                    let digit = if msd { TOP_SHIFT } else { 0 };
                    let mut h = hist_new::<BUCKETS>();
                    for k in &keys {
                        h[(k >> (32 + digit)) as usize & (BUCKETS - 1)] += 1;
                    }
                    sort(&mut k, &mut t, h, msd)
                };
                assert_eq!(t, want, "n {n} msd {msd} wide {wide}");
                for (d, w) in top.windows(2).enumerate() {
                    for k in &want[w[0] as usize..w[1] as usize] {
                        assert_eq!((k >> (32 + TOP_SHIFT)) as usize, d);
                    }
                }
                assert_eq!(top.last(), Some(&(n as u32)));
            }
        }
    }
}
