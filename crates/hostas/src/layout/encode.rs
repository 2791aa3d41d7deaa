//! Completes a structure around a built tree: the builders write the nodes straight into the
//! node section ([`node_section`]); this writes the header and geometry records (and the
//! node of a tree that is a single leaf). The caller then fills the primitive sections in the
//! tree's final order. Nothing is assumed about the previous contents of the memory.

use super::plan::Plan;
use super::{
    EMPTY_CHILD, GeometryRecord, HEADER_SIZE, Header, LAYOUT_VERSION, LEAF_BIT, MAGIC, MAX_DEPTH,
    Node,
};
use crate::build::tree::{Child, Tree};
use crate::error::{Error, Result};
use crate::math::Aabb;
use rayon::prelude::*;
use wide::{f32x8, f64x4, u32x8};

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

/// `dst` (the whole structure range) holds everything `plan` lays out.
fn fits(dst: &[u8], plan: &Plan) -> Result<()> {
    if (dst.len() as u64) < plan.total_size {
        return Err(Error::RangeTooShort {
            what: "acceleration structure",
            needed: plan.total_size,
            available: dst.len() as u64,
            location: Default::default(),
        });
    }
    Ok(())
}

/// The node section of `dst` (the whole structure range), for the builders to write into.
pub fn node_section<'a>(dst: &'a mut [u8], plan: &Plan) -> Result<&'a mut [Node]> {
    fits(dst, plan)?;
    bytemuck::try_cast_slice_mut(
        &mut dst[plan.nodes_offset as usize
            ..(plan.nodes_offset + super::NODE_SIZE * plan.node_capacity) as usize],
    )
    .map_err(|e| {
        Error::NotSupported(format!(
            "acceleration structure memory is not 64-byte aligned ({e})"
        ))
    })
}

/// The primitive records (`prim_size` bytes each) and ids of `stored` primitives and the node
/// section of `dst` (the whole structure range), for a builder that writes all three.
pub fn sections<'a>(
    dst: &'a mut [u8],
    plan: &Plan,
    prim_size: usize,
    stored: usize,
) -> Result<(&'a mut [u8], &'a mut [u32], &'a mut [Node])> {
    fits(dst, plan)?;
    let short = || Error::OutOfHostMemory("structure smaller than its plan".into());
    let (head, nodes) = dst.split_at_mut(plan.nodes_offset as usize);
    let (head, ids) = head.split_at_mut(plan.prim_ids_offset as usize);
    let prims = head
        .get_mut(plan.prims_offset as usize..)
        .and_then(|p| p.get_mut(..prim_size * stored))
        .ok_or_else(short)?;
    let cast = |e: bytemuck::PodCastError| {
        Error::NotSupported(format!(
            "acceleration structure memory is not 64-byte aligned ({e})"
        ))
    };
    let ids =
        bytemuck::try_cast_slice_mut(ids.get_mut(..4 * stored).ok_or_else(short)?).map_err(cast)?;
    let nodes = bytemuck::try_cast_slice_mut(
        nodes
            .get_mut(..(super::NODE_SIZE * plan.node_capacity) as usize)
            .ok_or_else(short)?,
    )
    .map_err(cast)?;
    Ok((prims, ids, nodes))
}

/// Writes header and geometries into `dst` (the whole structure range), whose node section
/// holds `tree`'s nodes. Returns the header written.
pub fn encode(
    dst: &mut [u8],
    plan: &Plan,
    fields: &HeaderFields,
    geometries: &[GeometryRecord],
    tree: &Tree,
) -> Result<Header> {
    fits(dst, plan)?;
    let allocated_size = dst.len() as u64;
    let g_bytes = &mut dst[plan.geometries_offset as usize
        ..plan.geometries_offset as usize
            + super::GEOMETRY_RECORD_SIZE as usize * geometries.len()];
    g_bytes.copy_from_slice(bytemuck::cast_slice(geometries));
    zero_gaps(dst, plan, fields, geometries.len() as u64)?;

    let nodes = node_section(dst, plan)?;
    let root_area = match &tree.root {
        Some((b, _)) => b.half_area(),
        None => 0.0,
    };
    let (bounds, node_count, depth, sah) = match &tree.root {
        None => (Aabb::EMPTY, 0, 0, 0.0),
        Some((b, Child::Inner(_))) => {
            let count = tree.node_count;
            if tree.overflow || count > nodes.len() {
                return Err(Error::OutOfHostMemory(format!(
                    "tree needs {count} nodes, the plan has {}",
                    nodes.len()
                )));
            }
            let depth = check_depth(&nodes[..count])?;
            let sah = node_sah(&nodes[..count], root_area);
            (*b, count as u32, depth, sah + SAH_NODE_COST)
        }
        Some((b, Child::Leaf { first, count })) => {
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
        triangle_format: super::TRIANGLES_DIRECT,
        vertices_offset: 0,
        vertex_count: 0,
        reserved: [0; 27],
    };
    dst[..HEADER_SIZE as usize].copy_from_slice(bytemuck::bytes_of(&header));
    Ok(header)
}

/// Zeroes the bytes before the node section that no section holds: the alignment gaps after
/// the geometry records, the primitives and the ids, and the room left by primitives that are
/// not stored (inactive ones). The structure's bytes (serialized, compacted) must not depend
/// on what its memory held before the build.
fn zero_gaps(dst: &mut [u8], plan: &Plan, fields: &HeaderFields, geometries: u64) -> Result<()> {
    let stored = u64::from(fields.stored_count);
    let prim_size =
        super::PrimKind::from_raw(fields.prim_kind).map_or(0, super::PrimKind::prim_size);
    let gaps = [
        (
            plan.geometries_offset + super::GEOMETRY_RECORD_SIZE * geometries,
            plan.prims_offset,
        ),
        (plan.prims_offset + prim_size * stored, plan.prim_ids_offset),
        (plan.prim_ids_offset + 4 * stored, plan.nodes_offset),
    ];
    for (start, end) in gaps {
        dst.get_mut(start as usize..end as usize)
            .ok_or_else(|| Error::OutOfHostMemory("structure smaller than its plan".into()))?
            .fill(0);
    }
    Ok(())
}

/// The inner children of a node.
fn inner_children(node: &Node) -> impl Iterator<Item = u32> + '_ {
    // Leaves and empty slots (`EMPTY_CHILD`) have the leaf bit: one test for all eight.
    let leaf = u32x8::from(node.child) & u32x8::splat(LEAF_BIT);
    let mut inner = leaf.simd_eq(u32x8::ZERO).to_bitmask();
    std::iter::from_fn(move || {
        let k = inner.trailing_zeros() as usize;
        inner &= inner.wrapping_sub(1);
        node.child.get(k).copied()
    })
}

/// Checks that every inner child comes after its parent (the depth-first order the builders
/// promise) and returns the depth, at most `MAX_DEPTH`.
fn check_depth(tree: &[Node]) -> Result<u32> {
    let mut depth = vec![0u8; tree.len()];
    let mut max = 1;
    if let Some(d) = depth.first_mut() {
        *d = 1;
    }
    for (i, node) in tree.iter().enumerate() {
        let d = depth[i];
        for j in inner_children(node) {
            let j = j as usize;
            if j <= i || j >= tree.len() {
                return Err(Error::OutOfHostMemory(format!(
                    "tree node {i} has child {j} out of order"
                )));
            }
            depth[j] = d + 1;
            max = max.max(d as u32 + 1);
            if max > MAX_DEPTH {
                return Err(Error::OutOfHostMemory(format!(
                    "tree deeper than {MAX_DEPTH}"
                )));
            }
        }
    }
    Ok(max)
}

/// Node chunks whose SAH is summed per task; the sum is over fixed chunks in order, so the
/// result does not depend on the thread count.
const CHUNK_NODES: usize = 1024;

/// The SAH contribution of the nodes below the root's own visit.
fn node_sah(tree: &[Node], root_area: f32) -> f32 {
    let inv_root = if root_area > 0.0 {
        1.0 / root_area as f64
    } else {
        0.0
    };
    // The children's half areas, eight at a time with the operations of `Aabb::half_area`
    // (0 for an empty box), so the sums are the same.
    let half_areas = |n: &Node| -> f32x8 {
        let v = |a: [f32; 8]| f32x8::from(a);
        let (lx, ly, lz) = (v(n.lo_x), v(n.lo_y), v(n.lo_z));
        let (hx, hy, hz) = (v(n.hi_x), v(n.hi_y), v(n.hi_z));
        let (dx, dy, dz) = (hx - lx, hy - ly, hz - lz);
        let area = dx * dy + dy * dz + dz * dx;
        let full = lx.simd_le(hx) & ly.simd_le(hy) & lz.simd_le(hz);
        full.select(area, f32x8::ZERO)
    };
    // The children's costs: a primitive test per primitive of a leaf, a node visit per inner
    // node, 0 for an empty slot.
    let costs = |n: &Node| -> f32x8 {
        let child = u32x8::from(n.child);
        let leaf = (child & u32x8::splat(LEAF_BIT)).simd_eq(u32x8::splat(LEAF_BIT));
        let empty = child.simd_eq(u32x8::splat(EMPTY_CHILD));
        let count = f32x8::from(n.count.map(|c| c as f32));
        let cost = bytemuck::cast::<u32x8, f32x8>(leaf).select(
            f32x8::splat(SAH_PRIM_COST) * count,
            f32x8::splat(SAH_NODE_COST),
        );
        bytemuck::cast::<u32x8, f32x8>(empty).select(f32x8::ZERO, cost)
    };
    // Four of eight lanes in `f64`.
    let wide4 = |v: &[f32; 8], at: usize| f64x4::from([0, 1, 2, 3].map(|k| v[at + k] as f64));
    let sums: Vec<f64> = tree
        .par_chunks(CHUNK_NODES)
        .map(|tree| {
            let mut sah = 0.0f64;
            for node in tree {
                // Each child's cost times its area relative to the root's, eight at a time,
                // added in slot order. (An empty slot adds 0 times a finite area, which
                // changes no sum of such terms: none is negative.)
                let (areas, costs) = (half_areas(node).to_array(), costs(node).to_array());
                for at in [0, 4] {
                    let rel_area = if root_area > 0.0 {
                        wide4(&areas, at) * f64x4::splat(inv_root)
                    } else {
                        f64x4::splat(1.0)
                    };
                    for t in (wide4(&costs, at) * rel_area).to_array() {
                        sah += t;
                    }
                }
            }
            sah
        })
        .collect();
    sums.iter().sum::<f64>() as f32
}
