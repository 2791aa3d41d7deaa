//! Writes a built tree into a structure's memory range: header, geometry records and nodes in
//! depth-first order. The caller then fills the primitive sections in the tree's final order.
//! Nothing is assumed about the previous contents of the memory.

use super::plan::Plan;
use super::{EMPTY_CHILD, HEADER_SIZE, Header, LAYOUT_VERSION, LEAF_BIT, MAGIC, MAX_DEPTH, Node, GeometryRecord};
use crate::build::tree::{Child, Tree};
use crate::error::{Error, Result};
use crate::math::Aabb;

/// What the header says besides the tree.
pub struct HeaderFields {
    pub kind: u32,
    pub build_flags: u32,
    pub prim_kind: u32,
    pub primitive_count: u32,
    pub stored_count: u32,
    pub header_flags: u32,
    pub preset: u32,
}

/// SAH constants used for the reported cost: a node visit costs 1, a primitive test costs 1.
pub const SAH_NODE_COST: f32 = 1.0;
pub const SAH_PRIM_COST: f32 = 1.0;

/// Writes header, geometries and nodes into `dst` (the whole structure range). Returns the
/// header written.
pub fn encode(dst: &mut [u8], plan: &Plan, fields: &HeaderFields, geometries: &[GeometryRecord], tree: &Tree) -> Result<Header> {
    if (dst.len() as u64) < plan.total_size {
        return Err(Error::RangeTooShort { what: "acceleration structure", needed: plan.total_size, available: dst.len() as u64, location: Default::default() });
    }
    let allocated_size = dst.len() as u64;
    let g_bytes = &mut dst[plan.geometries_offset as usize..plan.geometries_offset as usize + super::GEOMETRY_RECORD_SIZE as usize * geometries.len()];
    g_bytes.copy_from_slice(bytemuck::cast_slice(geometries));

    let nodes: &mut [Node] = bytemuck::try_cast_slice_mut(&mut dst[plan.nodes_offset as usize..(plan.nodes_offset + 128 * plan.node_capacity) as usize])
        .map_err(|e| Error::NotSupported(format!("acceleration structure memory is not 64-byte aligned ({e})")))?;

    let mut w = Writer { nodes, count: 0, depth: 0, sah: 0.0, root_area: 0.0 };
    let bounds = match &tree.root {
        None => Aabb::EMPTY,
        Some((b, child)) => {
            w.root_area = b.half_area();
            match child {
                Child::Inner(_) => {
                    w.write(child, 1)?;
                }
                Child::Leaf { first, count } => {
                    // A single leaf still gets a node, so traversal always starts at node 0.
                    let mut node = Node::EMPTY;
                    node.set_bounds(0, b);
                    node.child[0] = LEAF_BIT | first;
                    node.count[0] = *count as u8;
                    w.alloc(1)?;
                    w.nodes[0] = node;
                    w.sah += SAH_NODE_COST + SAH_PRIM_COST * *count as f32;
                }
            }
            *b
        }
    };
    let header = Header {
        magic: MAGIC,
        version: LAYOUT_VERSION,
        kind: fields.kind,
        build_flags: fields.build_flags,
        prim_kind: fields.prim_kind,
        geometry_count: geometries.len() as u32,
        primitive_count: fields.primitive_count,
        stored_count: fields.stored_count,
        node_count: w.count,
        depth: w.depth,
        header_flags: fields.header_flags,
        preset: fields.preset,
        bounds,
        used_size: plan.nodes_offset + 128 * w.count as u64,
        allocated_size,
        geometries_offset: plan.geometries_offset,
        nodes_offset: plan.nodes_offset,
        prims_offset: plan.prims_offset,
        prim_ids_offset: plan.prim_ids_offset,
        node_capacity: plan.node_capacity as u32,
        prim_capacity: plan.prim_capacity as u32,
        sah_cost: w.sah,
        reserved: [0; 31],
    };
    dst[..HEADER_SIZE as usize].copy_from_slice(bytemuck::bytes_of(&header));
    Ok(header)
}

struct Writer<'a> {
    nodes: &'a mut [Node],
    count: u32,
    depth: u32,
    sah: f32,
    root_area: f32,
}

impl Writer<'_> {
    fn alloc(&mut self, depth: u32) -> Result<usize> {
        let i = self.count as usize;
        if i >= self.nodes.len() {
            return Err(Error::OutOfHostMemory(format!("tree needs more than the planned {} nodes", self.nodes.len())));
        }
        if depth > MAX_DEPTH {
            return Err(Error::OutOfHostMemory(format!("tree deeper than {MAX_DEPTH}")));
        }
        self.count += 1;
        self.depth = self.depth.max(depth);
        Ok(i)
    }

    fn rel_area(&self, b: &Aabb) -> f32 {
        if self.root_area > 0.0 { b.half_area() / self.root_area } else { 1.0 }
    }

    /// Writes the inner node `child` and its subtree in depth-first order; returns its index.
    fn write(&mut self, child: &Child, depth: u32) -> Result<u32> {
        let Child::Inner(inner) = child else { return Ok(EMPTY_CHILD) };
        let index = self.alloc(depth)?;
        let mut node = Node::EMPTY;
        for (k, (b, c)) in inner.children().iter().enumerate() {
            node.set_bounds(k, b);
            match c {
                Child::Leaf { first, count } => {
                    node.child[k] = LEAF_BIT | first;
                    node.count[k] = *count as u8;
                    self.sah += SAH_PRIM_COST * *count as f32 * self.rel_area(b);
                }
                Child::Inner(_) => {
                    node.child[k] = self.write(c, depth + 1)?;
                    self.sah += SAH_NODE_COST * self.rel_area(b);
                }
            }
        }
        if index == 0 {
            self.sah += SAH_NODE_COST;
        }
        self.nodes[index] = node;
        Ok(index as u32)
    }
}
