//! Statistics of a built structure: what `hostas info` and the benchmarks report.

use crate::build::Preset;
use crate::device::{AccelerationStructure, Device};
use crate::error::{Error, Result};
use crate::layout::view::View;
use crate::layout::{EMPTY_CHILD, LEAF_BIT, PrimKind};

#[derive(Clone, Debug, PartialEq)]
pub struct Statistics {
    pub top_level: bool,
    pub prim_kind: PrimKind,
    pub build_flags: u32,
    pub preset: &'static str,
    pub geometry_count: u32,
    pub primitive_count: u32,
    /// Active primitives stored in the structure.
    pub stored_count: u32,
    pub node_count: u32,
    pub leaf_count: u32,
    pub depth: u32,
    /// Triangles stored indexed into shared vertices (`layout::indexed`), and how many
    /// vertices they share (0 when direct).
    pub indexed_triangles: bool,
    pub vertex_count: u32,
    /// SAH cost with a node visit and a primitive test both costing 1, relative to the root
    /// box (see `layout::encode`), as built.
    pub sah_cost: f32,
    /// Bytes the structure occupies (what a compacted copy needs).
    pub used_bytes: u64,
    /// Bytes of the memory range it was created with.
    pub allocated_bytes: u64,
    /// Bounds of everything stored (world space for a top-level structure, object space for
    /// a bottom-level one).
    pub bounds: crate::math::Aabb,
}

impl Statistics {
    pub fn from_view(v: &View) -> Statistics {
        let leaf_count = v
            .nodes
            .iter()
            .map(|n| {
                (0..crate::layout::WIDTH)
                    .filter(|&k| n.child[k] != EMPTY_CHILD && n.child[k] & LEAF_BIT != 0)
                    .count() as u32
            })
            .sum();
        let h = v.header;
        Statistics {
            top_level: h.kind == 0,
            prim_kind: v.prim_kind,
            build_flags: h.build_flags,
            preset: Preset::from_id(h.preset).map_or("unknown", |p| p.name),
            geometry_count: h.geometry_count,
            primitive_count: h.primitive_count,
            stored_count: h.stored_count,
            node_count: h.node_count,
            leaf_count,
            depth: h.depth,
            indexed_triangles: matches!(
                v.triangles,
                crate::layout::triangles::Triangles::Indexed(_)
            ),
            vertex_count: h.vertex_count,
            sah_cost: h.sah_cost,
            used_bytes: h.used_size,
            allocated_bytes: h.allocated_size,
            bounds: h.bounds,
        }
    }

    /// Bytes per primitive of the structure as built (used size over primitive count).
    pub fn bytes_per_primitive(&self) -> f64 {
        self.used_bytes as f64 / self.primitive_count.max(1) as f64
    }
}

impl Device {
    /// Statistics of a built structure.
    pub fn statistics(&self, a: AccelerationStructure) -> Result<Statistics> {
        self.with_bytes(a, |b| {
            let v = View::parse(b).map_err(|reason| Error::NotBuilt {
                handle: a.0,
                reason,
            })?;
            Ok(Statistics::from_view(&v))
        })
    }
}
