//! Writes a built tree into a structure's memory range: header, geometry records and nodes in
//! depth-first order. The caller then fills the primitive sections in the tree's final order.
//! Nothing is assumed about the previous contents of the memory.

use super::plan::Plan;
use super::{
    GeometryRecord, HEADER_SIZE, Header, LAYOUT_VERSION, LEAF_BIT, MAGIC, MAX_DEPTH, Node, WIDTH,
};
use crate::build::tree::{Child, InnerNode, Tree};
use crate::error::{Error, Result};
use crate::math::Aabb;
use rayon::prelude::*;

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
pub fn encode(
    dst: &mut [u8],
    plan: &Plan,
    fields: &HeaderFields,
    geometries: &[GeometryRecord],
    tree: &Tree,
) -> Result<Header> {
    if (dst.len() as u64) < plan.total_size {
        return Err(Error::RangeTooShort {
            what: "acceleration structure",
            needed: plan.total_size,
            available: dst.len() as u64,
            location: Default::default(),
        });
    }
    let allocated_size = dst.len() as u64;
    let g_bytes = &mut dst[plan.geometries_offset as usize
        ..plan.geometries_offset as usize
            + super::GEOMETRY_RECORD_SIZE as usize * geometries.len()];
    g_bytes.copy_from_slice(bytemuck::cast_slice(geometries));

    let nodes: &mut [Node] = bytemuck::try_cast_slice_mut(
        &mut dst[plan.nodes_offset as usize
            ..(plan.nodes_offset + super::NODE_SIZE * plan.node_capacity) as usize],
    )
    .map_err(|e| {
        Error::NotSupported(format!(
            "acceleration structure memory is not 64-byte aligned ({e})"
        ))
    })?;

    let root_area = match &tree.root {
        Some((b, _)) => b.half_area(),
        None => 0.0,
    };
    let w = Writer { root_area };
    let (bounds, node_count, depth, sah) = match &tree.root {
        None => (Aabb::EMPTY, 0, 0, 0.0),
        Some((b, child)) => match child {
            Child::Inner(inner) => {
                let count = inner.nodes as usize;
                if count > nodes.len() {
                    return Err(Error::OutOfHostMemory(format!(
                        "tree needs {count} nodes, the plan has {}",
                        nodes.len()
                    )));
                }
                let (sah, depth) = w.write(inner, &mut nodes[..count], 0, 1)?;
                (*b, count as u32, depth, sah + SAH_NODE_COST)
            }
            Child::Leaf { first, count } => {
                // A single leaf still gets a node, so traversal always starts at node 0.
                let mut node = Node::EMPTY;
                node.set_bounds(0, b);
                node.child[0] = LEAF_BIT | first;
                node.count[0] = *count as u8;
                let slot = nodes
                    .first_mut()
                    .ok_or_else(|| Error::OutOfHostMemory("no room for the root node".into()))?;
                *slot = node;
                (*b, 1, 1, SAH_NODE_COST + SAH_PRIM_COST * *count as f32)
            }
        },
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
        node_count,
        depth,
        header_flags: fields.header_flags,
        preset: fields.preset,
        bounds,
        used_size: plan.nodes_offset + super::NODE_SIZE * node_count as u64,
        allocated_size,
        geometries_offset: plan.geometries_offset,
        nodes_offset: plan.nodes_offset,
        prims_offset: plan.prims_offset,
        prim_ids_offset: plan.prim_ids_offset,
        node_capacity: plan.node_capacity as u32,
        prim_capacity: plan.prim_capacity as u32,
        sah_cost: sah,
        reserved: [0; 31],
    };
    dst[..HEADER_SIZE as usize].copy_from_slice(bytemuck::bytes_of(&header));
    Ok(header)
}

struct Writer {
    root_area: f32,
}

/// Subtrees with more nodes than this are written on another thread.
const PARALLEL_NODES: u32 = 2048;

impl Writer {
    fn rel_area(&self, b: &Aabb) -> f32 {
        if self.root_area > 0.0 {
            b.half_area() / self.root_area
        } else {
            1.0
        }
    }

    /// Writes `inner` at `out[0]` and its subtree after it, in depth-first order; `index` is
    /// the global index of `out[0]`. Returns the subtree's SAH contribution (below this node's
    /// own visit) and its depth.
    fn write(
        &self,
        inner: &InnerNode,
        out: &mut [Node],
        index: u32,
        depth: u32,
    ) -> Result<(f32, u32)> {
        if depth > MAX_DEPTH {
            return Err(Error::OutOfHostMemory(format!(
                "tree deeper than {MAX_DEPTH}"
            )));
        }
        let (me, mut rest) = out
            .split_first_mut()
            .ok_or_else(|| Error::OutOfHostMemory("node plan exceeded".into()))?;
        let mut node = Node::EMPTY;
        let mut sah = 0.0;
        let mut next = index + 1;
        // Children's subtrees take consecutive ranges of `rest`, in slot order.
        let mut jobs: [Option<(&InnerNode, &mut [Node], u32)>; WIDTH] = Default::default();
        for (k, (b, c)) in inner.children().iter().enumerate() {
            node.set_bounds(k, b);
            match c {
                Child::Leaf { first, count } => {
                    node.child[k] = LEAF_BIT | first;
                    node.count[k] = *count as u8;
                    sah += SAH_PRIM_COST * *count as f32 * self.rel_area(b);
                }
                Child::Inner(sub) => {
                    node.child[k] = next;
                    sah += SAH_NODE_COST * self.rel_area(b);
                    let n = (sub.nodes as usize).min(rest.len());
                    let (mine, tail) = std::mem::take(&mut rest).split_at_mut(n);
                    jobs[k] = Some((sub, mine, next));
                    rest = tail;
                    next += sub.nodes;
                }
            }
        }
        *me = node;
        let run = |j: Option<(&InnerNode, &mut [Node], u32)>| -> Result<(f32, u32)> {
            match j {
                Some((sub, slice, idx)) => self.write(sub, slice, idx, depth + 1),
                None => Ok((0.0, depth)),
            }
        };
        let mut max_depth = depth;
        if inner.nodes > PARALLEL_NODES {
            let results: Vec<Result<(f32, u32)>> = jobs.into_par_iter().map(run).collect();
            for r in results {
                let (s, d) = r?;
                sah += s;
                max_depth = max_depth.max(d);
            }
        } else {
            // Small subtrees: no collection (this runs once per node).
            for j in jobs {
                let (s, d) = run(j)?;
                sah += s;
                max_depth = max_depth.max(d);
            }
        }
        Ok((sah, max_depth))
    }
}
