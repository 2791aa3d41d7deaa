//! Indexed triangles: a built structure's triangles rewritten as [`TriRecord`]s into shared
//! vertices, which takes a mesh from 36 bytes per triangle to about 8 + 12 × (distinct
//! vertices per triangle), about 15 on typical meshes (half a vertex per triangle).
//!
//! Vertices are shared where the application's triangles share them: the same vertex index
//! of the same geometry (so the same bits after any transform). They are numbered in order of
//! first use in leaf order, so the vertices of a leaf lie together; a vertex last numbered
//! more than [`WINDOW`] vertices ago is stored again instead, which keeps every triangle's
//! three numbers within an `i16` of each other. The pass runs after the tree, the ids and the
//! direct triangles are written; it moves the ids and nodes down over the room it frees, so
//! the used size (what compaction keeps) shrinks with it. Where sharing would not save room
//! (triangles that share no vertices), the structure keeps its direct triangles.

use super::{
    HEADER_SIZE, Header, NODE_SIZE, SECTION_ALIGN, TRIANGLES_INDEXED, TriRecord, align_up,
};
use crate::error::{Error, Result};

/// How far back (in vertices numbered) a vertex may be shared; `i16` deltas hold it with room
/// for the two vertices a triangle may number after its first.
pub const WINDOW: u32 = 32000;

/// "Not numbered yet" in the vertex map.
const NONE: u32 = u32::MAX;

/// Whether indexing `triangles` could pay when at most `vertices` distinct ones are stored
/// (before the window's repeats): records and vertices must take less room than the direct
/// triangles.
pub fn may_pay(vertices: u64, triangles: u64) -> bool {
    8 * triangles + 12 * vertices < 36 * triangles
}

/// Rewrites the direct triangles of the structure in `bytes` (header, ids and nodes written)
/// as indexed ones when that is smaller. `keys(slot, id)` gives the vertex keys of stored
/// triangle `slot` (primitive sequence number `id`), each below `key_count`, equal exactly
/// where two vertices are the application's same vertex; `None` for a triangle that shares
/// nothing. `scratch` holds the records and vertices while the triangles are read (36 bytes
/// per stored triangle suffice). Returns whether the structure is now indexed.
pub fn share_vertices(
    bytes: &mut [u8],
    keys: impl Fn(usize, u32) -> Option<[u64; 3]>,
    key_count: u64,
    scratch: &mut [u8],
) -> Result<bool> {
    let header: Header = bytemuck::pod_read_unaligned(
        bytes
            .get(..HEADER_SIZE as usize)
            .ok_or_else(|| internal("no header"))?,
    );
    let stored = header.stored_count as usize;
    // A vertex map much larger than the triangles (a few triangles indexing a large vertex
    // buffer) costs more than it saves.
    if stored == 0 || key_count > 8 * stored as u64 + 1024 {
        return Ok(false);
    }
    let tris_at = header.prims_offset as usize;
    let ids_at = header.prim_ids_offset as usize;
    let triangles: &[[[f32; 3]; 3]] = cast(bytes.get(tris_at..tris_at + 36 * stored))?;
    let ids: &[u32] = cast(bytes.get(ids_at..ids_at + 4 * stored))?;

    // Records first, then vertices, in scratch: at most as many bytes as the direct triangles.
    let (records, vertices) = scratch
        .get_mut(..36 * stored)
        .ok_or_else(|| internal("scratch too small"))?
        .split_at_mut(8 * stored);
    let records: &mut [TriRecord] = cast_mut(Some(records))?;
    let room = vertices.len() / 12 * 12;
    let vertices: &mut [[f32; 3]] = cast_mut(vertices.get_mut(..room))?;
    let mut map = vec![NONE; key_count as usize];
    let mut count = 0u32;
    for (slot, (tri, record)) in triangles.iter().zip(records.iter_mut()).enumerate() {
        let key = keys(slot, ids[slot]);
        let mut number = [0u32; 3];
        for k in 0..3 {
            let key = key.map(|key| key[k] as usize);
            let known = key
                .and_then(|i| map.get(i).copied())
                .filter(|&n| n != NONE && count - n <= WINDOW);
            number[k] = match known {
                Some(n) => n,
                None => {
                    // Stored again (or for the first time): no room left means sharing does
                    // not pay, and the direct triangles stay.
                    let Some(v) = vertices.get_mut(count as usize) else {
                        return Ok(false);
                    };
                    *v = tri[k];
                    if let Some(e) = key.and_then(|i| map.get_mut(i)) {
                        *e = count;
                    }
                    count += 1;
                    count - 1
                }
            };
        }
        let delta = |n: u32| (n as i64 - number[0] as i64) as i16;
        *record = TriRecord {
            a: number[0],
            db: delta(number[1]),
            dc: delta(number[2]),
        };
    }
    drop(map);

    // The new sections, each aligned, below the old ones (checked: else keep direct).
    let vertex_count = count as usize;
    let vertices_at = align_up((tris_at + 8 * stored) as u64, SECTION_ALIGN) as usize;
    let new_ids_at = align_up((vertices_at + 12 * vertex_count) as u64, SECTION_ALIGN) as usize;
    let new_nodes_at = align_up((new_ids_at + 4 * stored) as u64, SECTION_ALIGN) as usize;
    let nodes_at = header.nodes_offset as usize;
    let node_bytes = NODE_SIZE as usize * header.node_count as usize;
    if new_ids_at > ids_at || new_nodes_at > nodes_at || nodes_at + node_bytes > bytes.len() {
        return Ok(false);
    }
    bytes.copy_within(ids_at..ids_at + 4 * stored, new_ids_at);
    bytes.copy_within(nodes_at..nodes_at + node_bytes, new_nodes_at);
    let records: &[u8] = bytemuck::cast_slice(&records[..]);
    bytes[tris_at..tris_at + records.len()].copy_from_slice(records);
    let vertices: &[u8] = bytemuck::cast_slice(&vertices[..vertex_count]);
    bytes[vertices_at..vertices_at + vertices.len()].copy_from_slice(vertices);
    // The alignment gaps, so the bytes do not depend on what the memory held.
    for (start, end) in [
        (tris_at + records.len(), vertices_at),
        (vertices_at + vertices.len(), new_ids_at),
        (new_ids_at + 4 * stored, new_nodes_at),
    ] {
        bytes[start..end].fill(0);
    }
    let header = Header {
        triangle_format: TRIANGLES_INDEXED,
        vertices_offset: vertices_at as u64,
        vertex_count: count,
        prim_ids_offset: new_ids_at as u64,
        nodes_offset: new_nodes_at as u64,
        used_size: (new_nodes_at + node_bytes) as u64,
        ..header
    };
    bytes[..HEADER_SIZE as usize].copy_from_slice(bytemuck::bytes_of(&header));
    Ok(true)
}

fn internal(what: &str) -> Error {
    Error::OutOfHostMemory(format!("indexing triangles: {what}"))
}

fn cast<T: bytemuck::Pod>(b: Option<&[u8]>) -> Result<&[T]> {
    bytemuck::try_cast_slice(b.ok_or_else(|| internal("section out of range"))?)
        .map_err(|e| internal(&e.to_string()))
}

fn cast_mut<T: bytemuck::Pod>(b: Option<&mut [u8]>) -> Result<&mut [T]> {
    bytemuck::try_cast_slice_mut(b.ok_or_else(|| internal("section out of range"))?)
        .map_err(|e| internal(&e.to_string()))
}
