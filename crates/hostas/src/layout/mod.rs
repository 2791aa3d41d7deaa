//! The byte layout of a hostas acceleration structure: the one source of truth.
//!
//! A structure is its bytes. Everything lives in the memory range the application gave the
//! structure, addressed by offsets from its start, never by pointers, so that clone is a byte
//! copy, compaction keeps the used prefix, and serialization wraps the bytes in the spec's
//! header. The only absolute values are instance references to bottom-level structures
//! (handles), which serialization lists and deserialization rewrites.
//!
//! ```text
//! offset 0     Header (256 bytes): magic, LAYOUT_VERSION, type, flags, counts, bounds,
//!              used size, section offsets
//! geometries   GeometryRecord per geometry (48 bytes): first primitive, counts, formats, flags
//!              (what update and the ray query's geometry lookup need)
//! prims        the stored (active) primitives in leaf order:
//!              triangles, direct: [f32; 9] vertices after the geometry transform, in
//!                index order
//!              triangles, indexed: TriRecord (8 bytes) per triangle, then (its own
//!                section, `vertices_offset`) the shared vertices, [f32; 3] each
//!              AABBs: [f32; 6]
//!              instances: InstanceRecord (128 bytes)
//! prim_ids     u32 per stored primitive: the primitive's sequence number across all geometries
//!              (geometry's first primitive + primitive index), inactive primitives counted
//! nodes        Node per 8-wide node (256 bytes), depth-first order, root first; last, so that
//!              the used size ends at the last node
//! ```
//! Every section starts at a multiple of [`SECTION_ALIGN`]. All fields are little-endian.

pub mod encode;
pub mod indexed;
pub mod plan;
pub mod triangles;
pub mod view;

use crate::math::Aabb;
use bytemuck::{Pod, Zeroable};

/// `b"HOST"` read as a little-endian u32.
pub const MAGIC: u32 = u32::from_le_bytes(*b"HOST");
/// Bumped on any change of the byte layout; part of the compatibility UUID.
pub const LAYOUT_VERSION: u32 = 4;
pub const SECTION_ALIGN: u64 = 64;
pub const HEADER_SIZE: u64 = 256;
/// Branching factor of the stored tree.
pub const WIDTH: usize = 8;
/// Bytes per node.
pub const NODE_SIZE: u64 = 256;
/// Most primitives in one leaf.
pub const MAX_LEAF_SIZE: usize = 15;
/// Deepest tree the encoder writes; traversal stacks are sized from it.
pub const MAX_DEPTH: u32 = 64;

/// Child slot value of an unused slot.
pub const EMPTY_CHILD: u32 = u32::MAX;
/// Set in a child slot that holds a leaf; the low 31 bits are the first stored primitive.
pub const LEAF_BIT: u32 = 1 << 31;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u32)]
pub enum Kind {
    TopLevel = 0,
    BottomLevel = 1,
}

/// What the primitives of a structure are.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u32)]
pub enum PrimKind {
    /// No geometries: every ray misses.
    None = 0,
    Triangles = 1,
    Aabbs = 2,
    Instances = 3,
}

impl PrimKind {
    pub fn from_raw(v: u32) -> Option<Self> {
        Some(match v {
            0 => PrimKind::None,
            1 => PrimKind::Triangles,
            2 => PrimKind::Aabbs,
            3 => PrimKind::Instances,
            _ => return None,
        })
    }
    /// Bytes per stored primitive.
    pub fn prim_size(self) -> u64 {
        match self {
            PrimKind::None => 0,
            PrimKind::Triangles => 36,
            PrimKind::Aabbs => 24,
            PrimKind::Instances => std::mem::size_of::<InstanceRecord>() as u64,
        }
    }
}

/// Header flag: every geometry is `OPAQUE`.
pub const HEADER_ALL_OPAQUE: u32 = 1;
/// Header flag: no geometry is `OPAQUE`.
pub const HEADER_NONE_OPAQUE: u32 = 2;

#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
#[repr(C)]
pub struct Header {
    pub magic: u32,
    pub version: u32,
    pub kind: u32,
    /// `VkBuildAccelerationStructureFlagsKHR` the structure was built with.
    pub build_flags: u32,
    pub prim_kind: u32,
    pub geometry_count: u32,
    /// All primitives of all geometries, inactive ones included.
    pub primitive_count: u32,
    /// Stored (active) primitives.
    pub stored_count: u32,
    pub node_count: u32,
    pub depth: u32,
    pub header_flags: u32,
    /// Preset the tree was built with (see `build::Preset`), for statistics.
    pub preset: u32,
    pub bounds: Aabb,
    /// Bytes from the start that hold the structure: the compacted size.
    pub used_size: u64,
    /// The size of the memory range the structure was built in.
    pub allocated_size: u64,
    pub geometries_offset: u64,
    pub nodes_offset: u64,
    pub prims_offset: u64,
    pub prim_ids_offset: u64,
    /// Capacity of the node section, in nodes (what update and compaction may rely on).
    pub node_capacity: u32,
    /// Capacity of the primitive sections, in primitives.
    pub prim_capacity: u32,
    pub sah_cost: f32,
    /// How triangles are stored: [`TRIANGLES_DIRECT`] or [`TRIANGLES_INDEXED`] (0 for other
    /// primitive kinds).
    pub triangle_format: u32,
    /// Indexed triangles: where their shared vertices start, and how many there are.
    pub vertices_offset: u64,
    pub vertex_count: u32,
    pub reserved: [u32; 27],
}

const _: () = assert!(std::mem::size_of::<Header>() as u64 == HEADER_SIZE);

/// [`Header::triangle_format`]: each stored triangle holds its three vertices (36 bytes).
pub const TRIANGLES_DIRECT: u32 = 0;
/// [`Header::triangle_format`]: each stored triangle is a [`TriRecord`] into the shared
/// vertices (8 bytes, plus about 12 bytes per distinct vertex on a mesh).
pub const TRIANGLES_INDEXED: u32 = 1;

/// An indexed triangle: its vertices are `vertices[a]`, `vertices[a + db]` and
/// `vertices[a + dc]`, in index order. A triangle's vertices lie close together because they
/// are numbered in order of first use in leaf order (see `layout::indexed`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
#[repr(C)]
pub struct TriRecord {
    pub a: u32,
    pub db: i16,
    pub dc: i16,
}

const _: () = assert!(std::mem::size_of::<TriRecord>() == 8);

impl TriRecord {
    /// The three vertex numbers (they may be out of range in unchecked bytes).
    #[inline(always)]
    pub fn vertices(&self) -> [usize; 3] {
        let a = self.a as usize;
        [
            a,
            a.wrapping_add_signed(self.db as isize),
            a.wrapping_add_signed(self.dc as isize),
        ]
    }
}

/// Per-geometry record: what the ray query needs (first primitive, opacity) and what update
/// checks against (§update rules: counts, formats, transform presence, flags).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Pod, Zeroable)]
#[repr(C)]
pub struct GeometryRecord {
    pub first_primitive: u32,
    pub primitive_count: u32,
    /// `VkGeometryFlagsKHR`.
    pub flags: u32,
    /// `VkGeometryTypeKHR`.
    pub geometry_type: u32,
    /// `VkFormat` (triangles) or 0.
    pub vertex_format: u32,
    /// `VkIndexType` (triangles) or 0.
    pub index_type: u32,
    /// `maxVertex` (triangles) or 0.
    pub max_vertex: u32,
    /// 1 if a geometry transform was given (triangles), 2 if instances were an array of
    /// pointers.
    pub extra: u32,
    /// `firstVertex` of the range (indexed triangles must keep it in an update).
    pub first_vertex: u32,
    pub reserved: [u32; 3],
}

pub const GEOMETRY_RECORD_SIZE: u64 = std::mem::size_of::<GeometryRecord>() as u64;
const _: () = assert!(GEOMETRY_RECORD_SIZE == 48);

/// An 8-wide node: child boxes in structure-of-arrays form, so one ray tests all eight at once
/// (one AVX2 pass, or two SSE passes).
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
#[repr(C, align(64))]
pub struct Node {
    pub lo_x: [f32; WIDTH],
    pub hi_x: [f32; WIDTH],
    pub lo_y: [f32; WIDTH],
    pub hi_y: [f32; WIDTH],
    pub lo_z: [f32; WIDTH],
    pub hi_z: [f32; WIDTH],
    /// Node index, `LEAF_BIT | first stored primitive`, or `EMPTY_CHILD`.
    pub child: [u32; WIDTH],
    /// Primitives in each leaf child (0 for inner or empty children).
    pub count: [u8; WIDTH],
    pub reserved: [u32; 6],
}

const _: () = assert!(std::mem::size_of::<Node>() == NODE_SIZE as usize);

impl Node {
    pub const EMPTY: Node = Node {
        lo_x: [f32::INFINITY; WIDTH],
        hi_x: [f32::NEG_INFINITY; WIDTH],
        lo_y: [f32::INFINITY; WIDTH],
        hi_y: [f32::NEG_INFINITY; WIDTH],
        lo_z: [f32::INFINITY; WIDTH],
        hi_z: [f32::NEG_INFINITY; WIDTH],
        child: [EMPTY_CHILD; WIDTH],
        count: [0; WIDTH],
        reserved: [0; 6],
    };
    /// Rows of [`Node::rows`] holding `lo_x`, `lo_y`, `lo_z` (each `hi_` follows its `lo_`).
    pub const LO_ROWS: [usize; 3] = [0, 2, 4];
    /// The node as eight rows of eight lanes: the six bound planes, then `child` and
    /// `count`/`reserved` as bits (traversal picks plane rows by index, once per ray).
    #[inline(always)]
    pub fn rows(&self) -> &[[f32; WIDTH]; 8] {
        bytemuck::cast_ref(self)
    }
    pub fn set_bounds(&mut self, k: usize, b: &Aabb) {
        self.lo_x[k] = b.lo[0];
        self.lo_y[k] = b.lo[1];
        self.lo_z[k] = b.lo[2];
        self.hi_x[k] = b.hi[0];
        self.hi_y[k] = b.hi[1];
        self.hi_z[k] = b.hi[2];
    }
    pub fn bounds(&self, k: usize) -> Aabb {
        Aabb {
            lo: [self.lo_x[k], self.lo_y[k], self.lo_z[k]],
            hi: [self.hi_x[k], self.hi_y[k], self.hi_z[k]],
        }
    }
}

/// A stored instance of a top-level structure.
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
#[repr(C)]
pub struct InstanceRecord {
    pub object_to_world: [f32; 12],
    pub world_to_object: [f32; 12],
    pub acceleration_structure_reference: u64,
    /// `InstanceId`: the index in the instance array, inactive instances counted.
    pub instance_id: u32,
    pub custom_index: u32,
    pub mask: u32,
    pub sbt_record_offset: u32,
    pub flags: u32,
    /// `INSTANCE_IDENTITY` when the transform is exactly the identity (traversal then skips
    /// transforming the ray).
    pub hints: u32,
}

/// `InstanceRecord::hints` bit: the object-to-world transform is the identity.
pub const INSTANCE_IDENTITY: u32 = 1;

const _: () = assert!(std::mem::size_of::<InstanceRecord>() == 128);

pub fn align_up(v: u64, a: u64) -> u64 {
    v.div_ceil(a) * a
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn node_rows_are_the_planes_in_order() {
        let mut n = Node::EMPTY;
        n.set_bounds(
            3,
            &Aabb {
                lo: [1.0, 2.0, 3.0],
                hi: [4.0, 5.0, 6.0],
            },
        );
        let rows = n.rows();
        for (axis, lo_row) in Node::LO_ROWS.into_iter().enumerate() {
            assert_eq!(rows[lo_row][3], n.bounds(3).lo[axis]);
            assert_eq!(rows[lo_row + 1][3], n.bounds(3).hi[axis]);
        }
    }
}
