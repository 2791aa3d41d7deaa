//! Builders: from decoded primitives to a [`tree::Tree`].
//!
//! Each preset names an algorithm and its knobs; `PREFER_FAST_TRACE`, `PREFER_FAST_BUILD`,
//! `LOW_MEMORY` and the default select them (see [`Preset::from_flags`]). All builders make
//! 8-wide trees top-down by splitting the most promising child of a node until it has eight,
//! so every inner node has eight children and the size plan's node bound holds.

pub mod binned_sah;
pub mod morton;
pub mod tree;

use crate::math::{Aabb, Box4};
use ash::vk;
use bytemuck::{Pod, Zeroable};
use wide::f32x4;

/// A primitive as the builders see it: its bounds and its index in the decoded input.
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
#[repr(C)]
pub struct PrimRef {
    pub lo: [f32; 3],
    pub id: u32,
    pub hi: [f32; 3],
    pub pad: u32,
}

impl PrimRef {
    pub fn new(b: &Aabb, id: u32) -> Self {
        PrimRef {
            lo: b.lo,
            id,
            hi: b.hi,
            pad: 0,
        }
    }
    /// The bounds as vectors (lane 3 holds the id and pad bits).
    #[inline(always)]
    pub fn box4(&self) -> Box4 {
        let [lo, hi]: [[f32; 4]; 2] = bytemuck::cast(*self);
        Box4 {
            lo: f32x4::from(lo),
            hi: f32x4::from(hi),
        }
    }
    #[inline(always)]
    pub fn bounds(&self) -> Aabb {
        Aabb {
            lo: self.lo,
            hi: self.hi,
        }
    }
    #[inline(always)]
    pub fn center2(&self) -> [f32; 3] {
        [
            self.lo[0] + self.hi[0],
            self.lo[1] + self.hi[1],
            self.lo[2] + self.hi[2],
        ]
    }
}

/// The algorithm behind a preset.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Algorithm {
    /// Top-down binned surface-area heuristic.
    BinnedSah { bins: usize },
    /// Sort by Morton code, split on the highest differing bit.
    Morton,
}

/// A named set of builder knobs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Preset {
    pub name: &'static str,
    pub id: u32,
    pub algorithm: Algorithm,
    /// Leaves never hold more primitives than this. (In the SAH builder, ranges of fewer than
    /// `WIDTH` are always leaves; from `WIDTH` up to this, the SAH decides. Fast-trace allows
    /// 12, so that a small closed object, such as a box of 12 triangles, can stay one leaf
    /// where the SAH prefers it, instead of a full node of eight tiny leaves: 40.7 -> 38.6
    /// bytes per triangle on the benchmark's boxes, trace instructions unchanged within 0.5%.)
    pub max_leaf: usize,
    /// SAH cost of visiting a node relative to testing one primitive: higher values make
    /// larger leaves and fewer nodes.
    pub traversal_cost: f32,
}

impl Preset {
    pub const FAST_TRACE: Preset = Preset {
        name: "fast-trace",
        id: 1,
        algorithm: Algorithm::BinnedSah { bins: 32 },
        max_leaf: 12,
        traversal_cost: 2.0,
    };
    pub const FAST_BUILD: Preset = Preset {
        name: "fast-build",
        id: 2,
        algorithm: Algorithm::Morton,
        max_leaf: 7,
        traversal_cost: 1.0,
    };
    pub const DEFAULT: Preset = Preset {
        name: "default",
        id: 0,
        algorithm: Algorithm::BinnedSah { bins: 16 },
        max_leaf: 8,
        traversal_cost: 3.0,
    };
    pub const LOW_MEMORY: Preset = Preset {
        name: "low-memory",
        id: 3,
        algorithm: Algorithm::BinnedSah { bins: 16 },
        max_leaf: 15,
        traversal_cost: 6.0,
    };
    pub const ALL: [Preset; 4] = [
        Preset::FAST_TRACE,
        Preset::FAST_BUILD,
        Preset::DEFAULT,
        Preset::LOW_MEMORY,
    ];

    /// The preset the build flags select. `PREFER_FAST_TRACE` and `PREFER_FAST_BUILD` are
    /// exclusive (validated before); `LOW_MEMORY` wins over the default only.
    pub fn from_flags(flags: vk::BuildAccelerationStructureFlagsKHR) -> Preset {
        use vk::BuildAccelerationStructureFlagsKHR as F;
        if flags.contains(F::PREFER_FAST_TRACE) {
            Preset::FAST_TRACE
        } else if flags.contains(F::PREFER_FAST_BUILD) {
            Preset::FAST_BUILD
        } else if flags.contains(F::LOW_MEMORY) {
            Preset::LOW_MEMORY
        } else {
            Preset::DEFAULT
        }
    }

    pub fn from_id(id: u32) -> Option<Preset> {
        Preset::ALL.into_iter().find(|p| p.id == id)
    }
}

/// Below this many primitives a subtree is built on the calling thread.
pub(crate) const PARALLEL_THRESHOLD: usize = 4096;
/// Past this depth the builders split at the object median, which bounds the depth.
pub(crate) const MEDIAN_DEPTH: u32 = 40;

/// Builds a tree over `refs` and returns it with the references in final order (leaves refer
/// to positions there): `refs` reordered (SAH) or `aux` (Morton, whose leaves gather them
/// there from `refs`, which saves copying them). `aux`, `keys` and `keys_tmp` are working
/// space of the same length (from build scratch); `centroids`, where the decoder computed
/// them, the bounds of the references' doubled centroids (`lo + hi`, lane 3 zero); the inner
/// nodes are written into `nodes` (the structure's node section).
pub fn build<'a>(
    preset: &Preset,
    refs: &'a mut [PrimRef],
    aux: &'a mut [PrimRef],
    keys: &mut [u64],
    keys_tmp: &mut [u64],
    centroids: Option<Box4>,
    nodes: &mut [crate::layout::Node],
) -> (tree::Tree, &'a [PrimRef]) {
    match preset.algorithm {
        Algorithm::BinnedSah { bins } => {
            let tree = binned_sah::build(
                refs,
                aux,
                bins,
                preset.max_leaf,
                preset.traversal_cost,
                nodes,
            );
            (tree, refs)
        }
        Algorithm::Morton => {
            let tree = morton::build(refs, aux, keys, keys_tmp, centroids, preset.max_leaf, nodes);
            (tree, aux)
        }
    }
}
