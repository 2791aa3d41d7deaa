//! Fast builder: sort primitives by the Morton code of their centroid (radix sort), then split
//! each range at the highest bit in which its first and last codes differ (a top-down LBVH),
//! filling 8-wide nodes. Bounds are computed bottom-up, so the whole build is a few linear passes.

use super::binned_sah::RangeInfo;
use super::tree::{self, Child, NodeList, Tree, node_hint};
use super::{MEDIAN_DEPTH, PARALLEL_THRESHOLD, PrimRef};
use crate::layout::{Node, WIDTH};
use crate::math::{Aabb, fmax, fmin};
use rayon::prelude::*;

/// Spreads the low 10 bits of `v` to every third bit.
#[inline(always)]
fn spread(v: u32) -> u32 {
    let mut x = v & 0x3ff;
    x = (x | (x << 16)) & 0x0300_00ff;
    x = (x | (x << 8)) & 0x0300_f00f;
    x = (x | (x << 4)) & 0x030c_30c3;
    x = (x | (x << 2)) & 0x0924_9249;
    x
}

/// Bits per radix-sort digit: three passes over the 30 code bits.
const DIGIT: u32 = 10;
const BUCKETS: usize = 1 << DIGIT;
/// Shift of the top digit (code bits 20..30).
const TOP_SHIFT: u32 = 2 * DIGIT;
/// Keys are made in chunks of this many, each counting its own digit histograms.
const KEY_CHUNK: usize = PARALLEL_THRESHOLD * 16;

/// Ranges up to this size find their split point by counting, not by a binary search.
const LINEAR_SPLIT: usize = 256;

/// The three digit histograms of a set of codes.
type Hist = Vec<[u32; BUCKETS]>;

fn hist_new() -> Hist {
    vec![[0u32; BUCKETS]; 3]
}

fn hist_add(mut a: Hist, b: Hist) -> Hist {
    for (x, y) in a.iter_mut().zip(&b) {
        for (c, d) in x.iter_mut().zip(y) {
            *c += d;
        }
    }
    a
}

pub fn build(
    refs: &mut [PrimRef],
    aux: &mut [PrimRef],
    keys: &mut [u64],
    tmp: &mut [u64],
    max_leaf: usize,
    nodes: &mut [Node],
) -> Tree {
    let n = refs.len();
    if n == 0 {
        return NodeList::new(nodes).tree(None);
    }
    let info = RangeInfo::of(refs);
    let c = info.centroids;
    let scale = [0, 1, 2].map(|k| {
        let ext = c.hi[k] - c.lo[k];
        if ext > 0.0 { 1023.0 / ext } else { 0.0 }
    });
    let code = |r: &PrimRef| {
        let p = r.center2();
        let q = [0, 1, 2].map(|k| (((p[k] - c.lo[k]) * scale[k]) as u32).min(1023)); // NaN gives 0
        (spread(q[0]) << 2) | (spread(q[1]) << 1) | spread(q[2])
    };
    // Keys (code, position) and the digit histograms of the codes, in one pass.
    let keys = &mut keys[..n];
    let mut counts = keys
        .par_chunks_mut(KEY_CHUNK)
        .zip(refs.par_chunks(KEY_CHUNK))
        .enumerate()
        .map(|(ci, (ks, rs))| {
            let mut h = hist_new();
            let first = ci * KEY_CHUNK;
            for (i, (k, r)) in ks.iter_mut().zip(rs).enumerate() {
                let c = code(r);
                *k = (c as u64) << 32 | (first + i) as u64;
                let c = c as usize;
                h[0][c & (BUCKETS - 1)] += 1;
                h[1][(c >> DIGIT) & (BUCKETS - 1)] += 1;
                h[2][(c >> TOP_SHIFT) & (BUCKETS - 1)] += 1;
            }
            h
        })
        .reduce(hist_new, hist_add);
    for h in counts.iter_mut() {
        let mut sum = 0;
        for c in h.iter_mut() {
            let v = *c;
            *c = sum;
            sum += v;
        }
    }
    // Where each top digit starts in the sorted order (and the end): the split points of the
    // top levels, read off instead of searched for.
    let mut top = counts[2].to_vec();
    top.push(n as u32);
    // LSD radix sort by the code (the position keeps equal codes in input order): three
    // passes, keys -> tmp -> keys -> tmp.
    for (pass, h) in counts.iter_mut().enumerate() {
        let shift = 32 + DIGIT * pass as u32;
        let (src, dst): (&[u64], &mut [u64]) = if pass == 1 {
            (&tmp[..n], keys)
        } else {
            (keys, &mut tmp[..n])
        };
        for &k in src {
            let b = (k >> shift) as usize & (BUCKETS - 1);
            if let Some(d) = dst.get_mut(h[b] as usize) {
                *d = k;
            }
            h[b] += 1;
        }
    }
    // The references in sorted order into `aux` (so leaves read their bounds sequentially)
    // and the sorted codes, for splitting, into `keys` (free now), in one pass.
    let sorted = &tmp[..n];
    let codes: &mut [u32] = &mut bytemuck::cast_slice_mut(keys)[..n];
    let refs_in = &*refs;
    aux[..n]
        .par_chunks_mut(KEY_CHUNK)
        .zip(codes.par_chunks_mut(KEY_CHUNK))
        .zip(sorted.par_chunks(KEY_CHUNK))
        .for_each(|((a, c), s)| {
            for ((a, c), k) in a.iter_mut().zip(c.iter_mut()).zip(s) {
                *a = refs_in[(*k & 0xffff_ffff) as usize];
                *c = (*k >> 32) as u32;
            }
        });
    let codes = &*codes;
    let mut out = NodeList::new(nodes);
    // The leaves copy the sorted references back into `refs` as they read their bounds.
    let src = &aux[..n];
    let root = build_child(src, refs, codes, &top, 0, max_leaf.max(4), 0, &mut out);
    out.tree(Some(root))
}

/// Position of the first code in `codes` that differs from the first in the highest differing
/// bit, or the middle when all codes are equal. `codes` start at position `base` of the sorted
/// codes, and `top` says where each top digit starts there: splits on a top-digit bit are
/// looked up, not searched for (the searches at the top levels miss the caches).
fn split_point(codes: &[u32], base: usize, top: &[u32]) -> usize {
    let (first, last) = (codes[0], codes[codes.len() - 1]);
    if first == last {
        return codes.len() / 2;
    }
    let bit = 31 - (first ^ last).leading_zeros();
    let mask = !((1u32 << bit) - 1);
    let prefix = first & mask;
    if bit >= TOP_SHIFT {
        // Codes before `base` are at most `first`, those from the split on at least
        // `prefix | 1 << bit`, whose low digits are zero: the split is where that digit starts.
        let digit = ((prefix | 1 << bit) >> TOP_SHIFT) as usize;
        if let Some(&at) = top.get(digit) {
            return (at as usize).saturating_sub(base).min(codes.len());
        }
    }
    // codes are sorted: the first one with the bit set starts the right half. Small ranges
    // count the codes without it (no chain of dependent loads, and it vectorizes).
    if codes.len() <= LINEAR_SPLIT {
        return codes.iter().filter(|&&c| (c & mask) == prefix).count();
    }
    codes.partition_point(|&c| (c & mask) == prefix)
}

/// A leaf over `src` (at positions `base..`), copied into `dst`.
#[inline(always)]
fn leaf(src: &[PrimRef], dst: &mut [PrimRef], base: u32) -> (Aabb, Child) {
    // Four lanes at a time (lane 3 holds the id and is dropped): `minps`/`maxps`, with the
    // operand order of `Aabb::union`.
    let (mut lo, mut hi) = ([f32::INFINITY; 4], [f32::NEG_INFINITY; 4]);
    for (d, r) in dst.iter_mut().zip(src) {
        *d = *r;
        let [rl, rh]: [[f32; 4]; 2] = bytemuck::cast(*r);
        for k in 0..4 {
            lo[k] = fmin(lo[k], rl[k]);
            hi[k] = fmax(hi[k], rh[k]);
        }
    }
    let b = Aabb {
        lo: [lo[0], lo[1], lo[2]],
        hi: [hi[0], hi[1], hi[2]],
    };
    let c = Child::Leaf {
        first: base,
        count: src.len() as u32,
    };
    (b, c)
}

/// Builds the subtree over `src` (sorted references at positions `base..`), copying them into
/// `dst` as its leaves read them.
#[allow(clippy::too_many_arguments)]
fn build_child(
    src: &[PrimRef],
    dst: &mut [PrimRef],
    codes: &[u32],
    top: &[u32],
    base: u32,
    max_leaf: usize,
    depth: u32,
    out: &mut NodeList,
) -> (Aabb, Child) {
    let n = src.len();
    if n <= max_leaf.max(WIDTH - 1) {
        return leaf(src, dst, base);
    }
    let mut parts = [(0usize, 0usize); WIDTH];
    parts[0] = (0, n);
    let mut live = 1;
    while live < WIDTH {
        // Split the part with the most primitives (areas are not known top-down), the first
        // made among equals; parts of one primitive are never split (key 0).
        let (mut i, mut best) = (0, 0);
        for (j, &(b, e)) in parts[..live].iter().enumerate() {
            let key = if e - b >= 2 {
                (e - b) * WIDTH + (WIDTH - 1 - j)
            } else {
                0
            };
            if key > best {
                (i, best) = (j, key);
            }
        }
        if best == 0 {
            break;
        }
        let (b, e) = parts[i];
        let mid = if depth < MEDIAN_DEPTH {
            split_point(&codes[b..e], base as usize + b, top)
        } else {
            (e - b) / 2
        };
        let mid = mid.clamp(1, e - b - 1);
        parts[i] = (b, b + mid);
        parts[live] = (b + mid, e);
        live += 1;
    }
    // Every part made is non-empty: in position order.
    parts[..live].sort_unstable_by_key(|&(b, _)| b);
    let me = out.reserve();
    let mut children = [(Aabb::EMPTY, Child::Leaf { first: 0, count: 0 }); WIDTH];
    // The parts cover `0..n` in order: hand each its piece of `dst`.
    let mut pieces: [(usize, usize, &mut [PrimRef]); WIDTH] = Default::default();
    let mut rest = dst;
    for (piece, &(b, e)) in pieces.iter_mut().zip(&parts[..live]) {
        let (mine, tail) = std::mem::take(&mut rest).split_at_mut(e - b);
        *piece = (b, e, mine);
        rest = tail;
    }
    if n > PARALLEL_THRESHOLD && rayon::current_num_threads() > 1 {
        let built: Vec<((Aabb, Child), NodeList)> = pieces
            .into_iter()
            .take(live)
            .collect::<Vec<_>>()
            .into_par_iter()
            .map(|(b, e, d)| {
                let mut sub = NodeList::with_capacity(node_hint(e - b));
                let c = build_child(
                    &src[b..e],
                    d,
                    &codes[b..e],
                    top,
                    base + b as u32,
                    max_leaf,
                    depth + 1,
                    &mut sub,
                );
                (c, sub)
            })
            .collect();
        for (slot, ((b, c), sub)) in children.iter_mut().zip(built) {
            *slot = (b, out.append(c, sub));
        }
    } else {
        for (slot, (b, e, d)) in children.iter_mut().zip(pieces.into_iter().take(live)) {
            // Leaves inline: a returned child read back at once stalls on store forwarding.
            if e - b <= max_leaf.max(WIDTH - 1) {
                *slot = leaf(&src[b..e], d, base + b as u32);
                continue;
            }
            *slot = build_child(
                &src[b..e],
                d,
                &codes[b..e],
                top,
                base + b as u32,
                max_leaf,
                depth + 1,
                out,
            );
        }
    }
    let mut bounds = Aabb::EMPTY;
    for (b, _) in &children[..live] {
        bounds = bounds.union(b);
    }
    out.set(me, tree::node(children.into_iter().take(live)));
    (bounds, Child::Inner(me))
}
