//! Fast builder: sort primitives by the Morton code of their centroid (radix sort), then split
//! each range at the highest bit in which its first and last codes differ (a top-down LBVH),
//! filling 8-wide nodes. Bounds are computed bottom-up, so the whole build is a few linear passes.

use super::binned_sah::RangeInfo;
use super::tree::{self, Child, NodeList, Tree, node_hint};
use super::{MEDIAN_DEPTH, PARALLEL_THRESHOLD, PrimRef};
use crate::layout::{Node, WIDTH};
use crate::math::Aabb;
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

/// Sorts `keys` by their high half (the 30-bit code; the low half, a position, keeps equal
/// codes in input order): LSD radix, three passes of 10 bits with all histograms counted in
/// one first pass. The sorted keys end up in `tmp`.
fn radix_sort(keys: &mut [u64], tmp: &mut [u64]) {
    let n = keys.len();
    const B: usize = 1 << DIGIT;
    let mut counts = vec![[0u32; B]; 3];
    for &k in keys.iter() {
        let c = (k >> 32) as usize;
        counts[0][c & (B - 1)] += 1;
        counts[1][(c >> DIGIT) & (B - 1)] += 1;
        counts[2][(c >> (2 * DIGIT)) & (B - 1)] += 1;
    }
    for h in counts.iter_mut() {
        let mut sum = 0;
        for c in h.iter_mut() {
            let v = *c;
            *c = sum;
            sum += v;
        }
    }
    let (mut src, mut dst) = (keys, &mut tmp[..n]);
    for (pass, h) in counts.iter_mut().enumerate() {
        let shift = 32 + DIGIT * pass as u32;
        for &k in src.iter() {
            let b = (k >> shift) as usize & (B - 1);
            if let Some(d) = dst.get_mut(h[b] as usize) {
                *d = k;
            }
            h[b] += 1;
        }
        std::mem::swap(&mut src, &mut dst);
    }
    // Three passes: the sorted keys are in `tmp`.
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
    keys[..n]
        .par_iter_mut()
        .zip(refs.par_iter())
        .enumerate()
        .with_min_len(PARALLEL_THRESHOLD)
        .for_each(|(i, (k, r))| {
            *k = (code(r) as u64) << 32 | i as u64;
        });
    radix_sort(&mut keys[..n], tmp);
    let sorted = &tmp[..n];
    // The sorted codes (in the space of `keys`, now free), for splitting.
    let codes: &mut [u32] = &mut bytemuck::cast_slice_mut(&mut keys[..n])[..n];
    codes
        .par_iter_mut()
        .zip(sorted.par_iter())
        .with_min_len(PARALLEL_THRESHOLD)
        .for_each(|(c, k)| {
            *c = (k >> 32) as u32;
        });
    // Put the references in sorted order, so leaves read their bounds sequentially.
    aux[..n]
        .par_iter_mut()
        .zip(sorted.par_iter())
        .with_min_len(PARALLEL_THRESHOLD)
        .for_each(|(a, k)| *a = refs[(*k & 0xffff_ffff) as usize]);
    refs.par_iter_mut()
        .zip(aux[..n].par_iter())
        .with_min_len(PARALLEL_THRESHOLD)
        .for_each(|(r, a)| *r = *a);
    let codes = &*codes;
    let mut out = NodeList::new(nodes);
    let root = build_child(refs, codes, 0, max_leaf.max(4), 0, &mut out);
    out.tree(Some(root))
}

/// Position of the first code in `codes` that differs from the first in the highest differing
/// bit, or the middle when all codes are equal.
fn split_point(codes: &[u32]) -> usize {
    let (first, last) = (codes[0], codes[codes.len() - 1]);
    if first == last {
        return codes.len() / 2;
    }
    let bit = 31 - (first ^ last).leading_zeros();
    let mask = !((1u32 << bit) - 1);
    let prefix = first & mask;
    // codes are sorted: the first one with the bit set starts the right half.
    codes.partition_point(|&c| (c & mask) == prefix)
}

fn build_child(
    refs: &[PrimRef],
    codes: &[u32],
    base: u32,
    max_leaf: usize,
    depth: u32,
    out: &mut NodeList,
) -> (Aabb, Child) {
    let n = refs.len();
    if n <= max_leaf.max(WIDTH - 1) {
        let mut b = Aabb::EMPTY;
        for r in refs {
            b = b.union(&r.bounds());
        }
        return (
            b,
            Child::Leaf {
                first: base,
                count: n as u32,
            },
        );
    }
    let mut parts = [(0usize, 0usize); WIDTH];
    parts[0] = (0, n);
    for count in 1..WIDTH {
        // Split the part with the most primitives (areas are not known top-down).
        let Some(i) = (0..count)
            .filter(|&i| parts[i].1 - parts[i].0 >= 2)
            .max_by_key(|&i| (parts[i].1 - parts[i].0, usize::MAX - i))
        else {
            break;
        };
        let (b, e) = parts[i];
        let mid = if depth < MEDIAN_DEPTH {
            split_point(&codes[b..e])
        } else {
            (e - b) / 2
        };
        let mid = mid.clamp(1, e - b - 1);
        parts[i] = (b, b + mid);
        parts[count] = (b + mid, e);
    }
    parts.sort_by_key(|&(b, e)| (e == b, b));
    let me = out.reserve();
    let mut children = [(Aabb::EMPTY, Child::Leaf { first: 0, count: 0 }); WIDTH];
    let live = parts.iter().filter(|p| p.1 > p.0).count();
    let parts = parts.iter().filter(|p| p.1 > p.0);
    if n > PARALLEL_THRESHOLD && rayon::current_num_threads() > 1 {
        let built: Vec<((Aabb, Child), NodeList)> = parts
            .collect::<Vec<_>>()
            .into_par_iter()
            .map(|&(b, e)| {
                let mut sub = NodeList::with_capacity(node_hint(e - b));
                let c = build_child(
                    &refs[b..e],
                    &codes[b..e],
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
        for (slot, &(b, e)) in children.iter_mut().zip(parts) {
            *slot = build_child(
                &refs[b..e],
                &codes[b..e],
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
