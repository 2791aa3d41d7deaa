//! Indexed triangles: a built structure's triangles rewritten as [`TriRecord`]s into shared
//! vertices, which takes a mesh from 36 bytes per triangle to about 8 + 12 × (distinct
//! vertices per triangle), about 15 on typical meshes (half a vertex per triangle).
//!
//! Vertices are shared where the application's triangles share them: the same vertex index
//! of the same geometry (so the same bits after any transform). They are numbered in order of
//! first use in leaf order, so the vertices of a leaf lie together; a vertex last numbered
//! more than [`WINDOW`] vertices ago is stored again instead, which keeps every triangle's
//! three numbers within an `i16` of each other. The pass runs after the tree and the ids are
//! written: it reads each triangle from the decoded ones (in scratch) and writes the records
//! and vertices straight into the triangle section, then moves the ids and nodes down over the
//! room it frees, so the used size (what compaction keeps) shrinks with it. Where sharing
//! would not save room (triangles that share no vertices), the structure gets direct
//! triangles.

use super::{
    HEADER_SIZE, Header, NODE_SIZE, SECTION_ALIGN, TRIANGLES_INDEXED, TriRecord, align_up,
};
use crate::error::{Error, Result};

/// How far back (in vertices numbered) a vertex may be shared; `i16` deltas hold it with room
/// for the two vertices a triangle may number after its first.
pub const WINDOW: u32 = 32000;

/// "Not numbered yet" in the vertex map: a number so far back that it is never in the window.
const FAR: u32 = u32::MAX - WINDOW;

/// Whether indexing `triangles` could pay when at most `vertices` distinct ones are stored
/// (before the window's repeats): records and vertices must take less room than the direct
/// triangles.
pub fn may_pay(vertices: u64, triangles: u64) -> bool {
    8 * triangles + 12 * vertices < 36 * triangles
}

/// Triangles whose keys are made at a time (their keys stay in the L1 cache).
const CHUNK: usize = 256;

/// Writes the triangles of the structure in `bytes` (header, ids and nodes written, the
/// triangle section not) as indexed ones when that is smaller. `triangles` holds every
/// triangle by primitive sequence number (the decoded scratch), so nothing is read back from
/// the structure: records and vertices go straight into its triangle section.
/// `keys(ids, out)` writes the vertex keys of the triangles with sequence numbers `ids`: below
/// `key_count` and equal exactly where two vertices are the application's same vertex; a
/// triangle with a key at or past it shares nothing. Returns whether the structure is now
/// indexed; if not, the caller writes the direct triangles (their section may hold records).
pub fn share_vertices(
    bytes: &mut [u8],
    triangles: &[[f32; 9]],
    mut keys: impl FnMut(&[u32], &mut [[u32; 3]]),
    key_count: u64,
) -> Result<bool> {
    let header: Header = bytemuck::pod_read_unaligned(
        bytes
            .get(..HEADER_SIZE as usize)
            .ok_or_else(|| internal("no header"))?,
    );
    let stored = header.stored_count as usize;
    // A vertex map much larger than the triangles (a few triangles indexing a large vertex
    // buffer) costs more than it saves; keys are `u32`s.
    if stored == 0 || key_count > (8 * stored as u64 + 1024).min(u32::MAX as u64) {
        return Ok(false);
    }
    let tris_at = header.prims_offset as usize;
    let ids_at = header.prim_ids_offset as usize;
    // Records first, then vertices (each section aligned), up to the ids, and never more
    // vertices than 28 bytes per triangle hold (the room the direct triangles would free).
    let vertices_at = align_up((tris_at + 8 * stored) as u64, SECTION_ALIGN) as usize;
    let room = (28 * stored / 12).min(ids_at.saturating_sub(vertices_at) / 12);
    let (head, tail) = split(bytes, ids_at)?;
    let (head, vertices) = split(head, vertices_at)?;
    let ids: &[u32] = cast(tail.get(..4 * stored))?;
    let records: &mut [TriRecord] = cast_mut(head.get_mut(tris_at..tris_at + 8 * stored))?;
    let vertices: &mut [f32] = cast_mut(vertices.get_mut(..12 * room))?;
    // Count stays below FAR (at most three vertices per triangle), so `count - FAR` wraps to
    // more than WINDOW: one unsigned compare tells a vertex numbered within the window.
    if 3 * stored as u64 >= FAR as u64 {
        return Ok(false);
    }
    let mut map = vec![FAR; key_count as usize];
    let mut count = 0u32;
    let mut chunk_keys = [[0u32; 3]; CHUNK];
    for (records, ids) in records.chunks_mut(CHUNK).zip(ids.chunks(CHUNK)) {
        // The triangles are read at random (mostly from memory): all are asked for first
        // (both lines a triangle may straddle), so that their misses overlap the keys'.
        for &id in ids {
            if let Some(t) = triangles.get(id as usize) {
                crate::math::prefetch(&t[0]);
                crate::math::prefetch(&t[8]);
            }
        }
        let chunk_keys = &mut chunk_keys[..ids.len()];
        keys(ids, chunk_keys);
        let Some(c) = share_chunk(
            &mut map, vertices, count, triangles, ids, chunk_keys, records,
        ) else {
            // No room left (or an id without a triangle): sharing does not pay.
            return Ok(false);
        };
        count = c;
    }
    drop(map);

    // The new sections, each aligned, below the old ones (checked: else keep direct).
    let vertex_count = count as usize;
    let new_ids_at = align_up((vertices_at + 12 * vertex_count) as u64, SECTION_ALIGN) as usize;
    let new_nodes_at = align_up((new_ids_at + 4 * stored) as u64, SECTION_ALIGN) as usize;
    let nodes_at = header.nodes_offset as usize;
    let node_bytes = NODE_SIZE as usize * header.node_count as usize;
    if new_ids_at > ids_at || new_nodes_at > nodes_at || nodes_at + node_bytes > bytes.len() {
        return Ok(false);
    }
    bytes.copy_within(ids_at..ids_at + 4 * stored, new_ids_at);
    bytes.copy_within(nodes_at..nodes_at + node_bytes, new_nodes_at);
    // The alignment gaps, so the bytes do not depend on what the memory held.
    for (start, end) in [
        (tris_at + 8 * stored, vertices_at),
        (vertices_at + 12 * vertex_count, new_ids_at),
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

/// Numbers the vertices of the triangles `ids` (`keys` theirs) from `count` on, writing their
/// records and new vertices (three floats each); returns the new count, or `None` when
/// `vertices` has no room for them.
fn share_chunk(
    map: &mut [u32],
    vertices: &mut [f32],
    mut count: u32,
    triangles: &[[f32; 9]],
    ids: &[u32],
    keys: &[[u32; 3]],
    records: &mut [TriRecord],
) -> Option<u32> {
    for ((&id, key), record) in ids.iter().zip(keys).zip(records) {
        let tri = triangles.get(id as usize)?;
        let mut number = [0u32; 3];
        let at = 3 * count as usize;
        let slots: Option<&mut [f32; 9]> =
            vertices.get_mut(at..at + 9).and_then(|v| v.try_into().ok());
        match slots {
            Some(slots) if key.iter().all(|&k| (k as usize) < map.len()) => {
                // Whether a vertex is new follows no pattern a branch predictor could
                // learn, so it steers no branch: each corner is copied to the next slot
                // (a shared one is overwritten by the next new one), and its number chosen
                // by a mask (the compiler turns `if fresh` into a branch).
                let mut slot = 0;
                for k in 0..3 {
                    let key = key[k] as usize;
                    let last = map[key];
                    let fresh = count.wrapping_sub(last) > WINDOW;
                    let mask = (fresh as u32).wrapping_neg();
                    number[k] = last ^ ((last ^ count) & mask);
                    map[key] = number[k];
                    // The first two corners as 16 bytes (the next slot's first float is
                    // written again or unused).
                    let floats = if k < 2 { 4 } else { 3 };
                    slots[3 * slot..3 * slot + floats].copy_from_slice(&tri[3 * k..3 * k + floats]);
                    slot += fresh as usize;
                    count += fresh as u32;
                }
            }
            // A triangle that shares nothing, or the last room for vertices.
            _ => (number, count) = number_one_by_one(map, vertices, count, tri, key)?,
        }
        let delta = |n: u32| (n as i64 - number[0] as i64) as i16;
        *record = TriRecord {
            a: number[0],
            db: delta(number[1]),
            dc: delta(number[2]),
        };
    }
    Some(count)
}

/// [`share_chunk`]'s numbering of one triangle, a corner at a time; returns its numbers and
/// the new count (out of the loop, which then keeps more in registers).
#[cold]
fn number_one_by_one(
    map: &mut [u32],
    vertices: &mut [f32],
    mut count: u32,
    tri: &[f32; 9],
    key: &[u32; 3],
) -> Option<([u32; 3], u32)> {
    let shares = key.iter().all(|&k| (k as usize) < map.len());
    let mut number = [0u32; 3];
    for k in 0..3 {
        let key = key[k] as usize;
        let known = map.get(key).copied().filter(|_| shares);
        number[k] = match known.filter(|&n| count.wrapping_sub(n) <= WINDOW) {
            Some(n) => n,
            None => {
                let at = 3 * count as usize;
                vertices
                    .get_mut(at..at + 3)?
                    .copy_from_slice(&tri[3 * k..3 * k + 3]);
                if let Some(e) = map.get_mut(key).filter(|_| shares) {
                    *e = count;
                }
                count += 1;
                count - 1
            }
        };
    }
    Some((number, count))
}

fn internal(what: &str) -> Error {
    Error::OutOfHostMemory(format!("indexing triangles: {what}"))
}

fn split(b: &mut [u8], at: usize) -> Result<(&mut [u8], &mut [u8])> {
    b.split_at_mut_checked(at)
        .ok_or_else(|| internal("section out of range"))
}

fn cast<T: bytemuck::Pod>(b: Option<&[u8]>) -> Result<&[T]> {
    bytemuck::try_cast_slice(b.ok_or_else(|| internal("section out of range"))?)
        .map_err(|e| internal(&e.to_string()))
}

fn cast_mut<T: bytemuck::Pod>(b: Option<&mut [u8]>) -> Result<&mut [T]> {
    bytemuck::try_cast_slice_mut(b.ok_or_else(|| internal("section out of range"))?)
        .map_err(|e| internal(&e.to_string()))
}
