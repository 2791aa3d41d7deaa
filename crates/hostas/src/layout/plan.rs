//! The size plan: the one function that decides where each section goes for given maxima.
//! `vkGetAccelerationStructureBuildSizesKHR` answers from it and the encoder writes by it, so the
//! two cannot disagree.

use super::{GEOMETRY_RECORD_SIZE, HEADER_SIZE, PrimKind, SECTION_ALIGN, align_up};

/// Section offsets and sizes for a structure with at most `max_prims` primitives.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Plan {
    pub geometries_offset: u64,
    pub nodes_offset: u64,
    pub prims_offset: u64,
    pub prim_ids_offset: u64,
    pub node_capacity: u64,
    pub prim_capacity: u64,
    pub total_size: u64,
}

/// Most nodes a tree over `n` primitives can need. Every inner node the builders make has all
/// eight children (an inner node is only made for at least eight primitives, and a node is
/// always filled before its children are considered), so `n` leaves need at most
/// `(n - 1) / 7` inner nodes; one for the root of an empty or one-leaf tree.
pub fn max_nodes(n: u64) -> u64 {
    (n.saturating_sub(1))
        .div_ceil(super::WIDTH as u64 - 1)
        .max(1)
}

impl Plan {
    pub fn new(kind: PrimKind, geometry_count: u64, max_prims: u64) -> Plan {
        // Nodes go last: their count is the only one not known before the build, so the used
        // size (what compaction keeps) ends right after the last node written.
        let geometries_offset = HEADER_SIZE;
        let prims_offset = align_up(
            geometries_offset + GEOMETRY_RECORD_SIZE * geometry_count,
            SECTION_ALIGN,
        );
        let prim_ids_offset = align_up(prims_offset + kind.prim_size() * max_prims, SECTION_ALIGN);
        let nodes_offset = align_up(prim_ids_offset + 4 * max_prims, SECTION_ALIGN);
        let node_capacity = max_nodes(max_prims);
        let total_size = nodes_offset + super::NODE_SIZE * node_capacity;
        Plan {
            geometries_offset,
            nodes_offset,
            prims_offset,
            prim_ids_offset,
            node_capacity,
            prim_capacity: max_prims,
            total_size,
        }
    }
}

/// Update scratch: update works in place; the pass in primitive order keeps the stored slot
/// of each primitive (4 bytes each, plus room to align). Never zero: the CTS asserts non-zero
/// scratch sizes.
pub fn update_scratch_size(max_prims: u64) -> u64 {
    align_up(4 * max_prims + 4, SECTION_ALIGN).max(SECTION_ALIGN)
}
