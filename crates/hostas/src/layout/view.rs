//! A validated, typed read-only view over a structure's bytes.
//!
//! [`View::parse`] checks every offset, count, child index and leaf range before anything is
//! read, so traversal over a view never indexes out of bounds, loops or recurses without end,
//! whatever the bytes are (memory the application scribbled on, or a structure that was
//! created but never built).

use super::triangles::{Indexed, Triangles};
use super::{
    EMPTY_CHILD, GeometryRecord, HEADER_SIZE, Header, InstanceRecord, LAYOUT_VERSION, LEAF_BIT,
    MAGIC, MAX_DEPTH, MAX_LEAF_SIZE, Node, PrimKind, TRIANGLES_DIRECT, TRIANGLES_INDEXED,
    TriRecord,
};

#[derive(Clone, Copy, Debug)]
pub struct View<'a> {
    pub header: &'a Header,
    pub prim_kind: PrimKind,
    pub geometries: &'a [GeometryRecord],
    pub nodes: &'a [Node],
    pub triangles: Triangles<'a>,
    pub aabbs: &'a [[f32; 6]],
    pub instances: &'a [InstanceRecord],
    pub prim_ids: &'a [u32],
}

fn section<'a, T: bytemuck::Pod>(
    bytes: &'a [u8],
    offset: u64,
    count: u64,
    what: &str,
) -> Result<&'a [T], String> {
    let size = std::mem::size_of::<T>() as u64;
    let end = count
        .checked_mul(size)
        .and_then(|s| s.checked_add(offset))
        .ok_or_else(|| format!("{what} section overflows"))?;
    if end > bytes.len() as u64 {
        return Err(format!(
            "{what} section ends at {end}, past the structure's {} bytes",
            bytes.len()
        ));
    }
    bytemuck::try_cast_slice(&bytes[offset as usize..end as usize])
        .map_err(|e| format!("{what} section is misaligned: {e}"))
}

/// Reads just the header, unvalidated beyond magic and version.
pub fn read_header(bytes: &[u8]) -> Result<Header, String> {
    let raw = bytes
        .get(..HEADER_SIZE as usize)
        .ok_or_else(|| format!("{} bytes is too short for a header", bytes.len()))?;
    let header: Header = bytemuck::pod_read_unaligned(raw);
    if header.magic != MAGIC {
        return Err(format!(
            "no hostas structure (magic {:#010x})",
            header.magic
        ));
    }
    if header.version != LAYOUT_VERSION {
        return Err(format!(
            "layout version {} is not {LAYOUT_VERSION}",
            header.version
        ));
    }
    Ok(header)
}

/// The header in place (the bytes must be 8-byte aligned, as structure memory is).
fn header_ref(bytes: &[u8]) -> Result<&Header, String> {
    read_header(bytes)?;
    bytemuck::try_from_bytes(&bytes[..HEADER_SIZE as usize])
        .map_err(|e| format!("header is misaligned: {e}"))
}

impl<'a> View<'a> {
    pub fn parse(bytes: &'a [u8]) -> Result<View<'a>, String> {
        let view = Self::parse_sections(bytes)?;
        view.check_contents()?;
        Ok(view)
    }

    /// What [`Self::parse`] checks in constant time or per geometry: the header, the sections'
    /// bounds and order, the geometry records. A view from this alone must not be traversed:
    /// the caller checks the rest itself (primitive ids in range, instance records, the node
    /// tree, as [`Self::check_contents`] does), the way a refit does as it walks the tree.
    pub fn parse_sections(bytes: &'a [u8]) -> Result<View<'a>, String> {
        let header = header_ref(bytes)?;
        let h = header;
        let prim_kind = PrimKind::from_raw(h.prim_kind)
            .ok_or_else(|| format!("unknown primitive kind {}", h.prim_kind))?;
        if h.kind > 1 {
            return Err(format!("unknown structure type {}", h.kind));
        }
        if (h.kind == 0) != (prim_kind == PrimKind::Instances) && prim_kind != PrimKind::None {
            return Err("structure type and primitive kind disagree".into());
        }
        if h.used_size > bytes.len() as u64 {
            return Err(format!(
                "used size {} is larger than the {} bytes given",
                h.used_size,
                bytes.len()
            ));
        }
        if h.stored_count > h.prim_capacity
            || h.node_count > h.node_capacity
            || h.stored_count > h.primitive_count
        {
            return Err("counts exceed capacities".into());
        }
        let limits = crate::device::PROPERTIES;
        let max_prims = if h.kind == 0 {
            limits.max_instance_count
        } else {
            limits.max_primitive_count
        };
        if h.primitive_count as u64 > max_prims
            || h.geometry_count as u64 > limits.max_geometry_count
        {
            return Err(format!(
                "{} primitives in {} geometries exceed the device limits",
                h.primitive_count, h.geometry_count
            ));
        }
        let geometries: &[GeometryRecord] = section(
            bytes,
            h.geometries_offset,
            h.geometry_count as u64,
            "geometry",
        )?;
        let nodes: &[Node] = section(bytes, h.nodes_offset, h.node_count as u64, "node")?;
        let stored = h.stored_count as u64;
        let indexed = h.triangle_format == TRIANGLES_INDEXED;
        if h.triangle_format != TRIANGLES_DIRECT && !indexed
            || indexed && prim_kind != PrimKind::Triangles
        {
            return Err(format!(
                "triangle format {} in a structure of {prim_kind:?}",
                h.triangle_format
            ));
        }
        // An update rewrites each triangle's own vertices in place, which shared vertices
        // do not allow: the builder never indexes a structure that allows update.
        let allow_update = ash::vk::BuildAccelerationStructureFlagsKHR::ALLOW_UPDATE.as_raw();
        if indexed && h.build_flags & allow_update != 0 {
            return Err("indexed triangles in a structure that allows update".into());
        }
        if !indexed && (h.vertex_count != 0 || h.vertices_offset != 0) {
            return Err("shared vertices without indexed triangles".into());
        }
        let (mut triangles, mut aabbs, mut instances): (Triangles, &[[f32; 6]], &[InstanceRecord]) =
            (Triangles::default(), &[], &[]);
        let mut prims_size = prim_kind.prim_size();
        let mut vertices_end = None;
        match prim_kind {
            PrimKind::Triangles if indexed => {
                let records: &[TriRecord] = section(bytes, h.prims_offset, stored, "triangle")?;
                let count = h.vertex_count as u64;
                let vertices = section(bytes, h.vertices_offset, count, "vertex")?;
                triangles = Triangles::Indexed(Indexed { records, vertices });
                prims_size = std::mem::size_of::<TriRecord>() as u64;
                vertices_end = Some((h.vertices_offset, h.vertices_offset + 12 * count));
            }
            PrimKind::Triangles => {
                triangles = Triangles::Direct(section(bytes, h.prims_offset, stored, "triangle")?)
            }
            PrimKind::Aabbs => aabbs = section(bytes, h.prims_offset, stored, "AABB")?,
            PrimKind::Instances => instances = section(bytes, h.prims_offset, stored, "instance")?,
            PrimKind::None => {
                if stored != 0 {
                    return Err("primitives stored without geometry".into());
                }
            }
        }
        let prim_ids: &[u32] = section(bytes, h.prim_ids_offset, stored, "primitive id")?;
        // Sections follow the header and each other, in the encoder's order, without overlap
        // (a write into one, as deserialization rewrites instance references, cannot reach
        // another), and everything a reader touches lies inside the used size, which is all
        // a compacted copy keeps.
        let mut sections = vec![
            (
                h.geometries_offset,
                h.geometries_offset + super::GEOMETRY_RECORD_SIZE * h.geometry_count as u64,
            ),
            (h.prims_offset, h.prims_offset + prims_size * stored),
        ];
        sections.extend(vertices_end);
        sections.extend([
            (h.prim_ids_offset, h.prim_ids_offset + 4 * stored),
            (
                h.nodes_offset,
                h.nodes_offset + super::NODE_SIZE * h.node_count as u64,
            ),
        ]);
        if sections.iter().any(|&(_, e)| e > h.used_size) {
            return Err("a section ends past the used size".into());
        }
        let mut prev_end = HEADER_SIZE;
        for (s, e) in sections {
            if s < prev_end || s % super::SECTION_ALIGN != 0 {
                return Err(format!(
                    "section at {s} overlaps the previous one or is misaligned"
                ));
            }
            prev_end = e;
        }

        // Geometries: consecutive primitive ranges covering primitive_count, each of the
        // structure's primitive kind.
        let expected_type = match prim_kind {
            PrimKind::Triangles => Some(ash::vk::GeometryTypeKHR::TRIANGLES),
            PrimKind::Aabbs => Some(ash::vk::GeometryTypeKHR::AABBS),
            PrimKind::Instances => Some(ash::vk::GeometryTypeKHR::INSTANCES),
            PrimKind::None => None,
        };
        let mut next = 0u64;
        for (i, g) in geometries.iter().enumerate() {
            if expected_type.is_some_and(|t| g.geometry_type != t.as_raw() as u32) {
                return Err(format!(
                    "geometry {i} has type {} in a structure of {prim_kind:?}",
                    g.geometry_type
                ));
            }
            if g.first_primitive as u64 != next {
                return Err(format!(
                    "geometry {i} starts at primitive {} instead of {next}",
                    g.first_primitive
                ));
            }
            next += g.primitive_count as u64;
        }
        if next != h.primitive_count as u64 {
            return Err("geometry primitive counts do not add up".into());
        }
        Ok(View {
            header,
            prim_kind,
            geometries,
            nodes,
            triangles,
            aabbs,
            instances,
            prim_ids,
        })
    }

    /// The checks of [`Self::parse`] that [`Self::parse_sections`] leaves out, which read
    /// every instance record, primitive id and node.
    pub fn check_contents(&self) -> Result<(), String> {
        let (h, instances, prim_ids, nodes) =
            (self.header, self.instances, self.prim_ids, self.nodes);
        let stored = h.stored_count as u64;
        let identity = crate::math::Affine::IDENTITY.to_rows();
        if let Some(i) = instances.iter().position(|r| {
            r.hints & super::INSTANCE_IDENTITY != 0
                && (r.object_to_world != identity || r.world_to_object != identity)
        }) {
            return Err(format!("instance record {i} is marked identity but is not"));
        }
        if let Some(bad) = prim_ids.iter().find(|&&id| id >= h.primitive_count) {
            return Err(format!("primitive id {bad} out of range"));
        }
        if let Triangles::Indexed(t) = self.triangles {
            let count = t.vertices.len();
            if let Some(i) = t
                .records
                .iter()
                .position(|r| r.vertices().iter().any(|&v| v >= count))
            {
                return Err(format!(
                    "indexed triangle {i} refers to a vertex past the {count} stored"
                ));
            }
        }
        if (stored > 0) != (h.node_count > 0) {
            return Err("primitives without nodes or nodes without primitives".into());
        }
        // Nodes: children point forward (no cycles), leaves stay in range, depth is bounded.
        let mut depth = vec![0u8; nodes.len()];
        if !nodes.is_empty() {
            depth[0] = 1;
        }
        for (i, n) in nodes.iter().enumerate() {
            for k in 0..super::WIDTH {
                let c = n.child[k];
                if c == EMPTY_CHILD {
                    continue;
                }
                if c & LEAF_BIT != 0 {
                    let first = (c & !LEAF_BIT) as u64;
                    let count = n.count[k] as u64;
                    if count == 0 || count > MAX_LEAF_SIZE as u64 || first + count > stored {
                        return Err(format!(
                            "node {i} child {k}: leaf range {first}+{count} out of range"
                        ));
                    }
                } else {
                    let c = c as usize;
                    if c <= i || c >= nodes.len() {
                        return Err(format!("node {i} child {k}: node index {c} invalid"));
                    }
                    if depth[c] != 0 {
                        return Err(format!("node {c} has two parents"));
                    }
                    depth[c] = depth[i] + 1;
                    if depth[c] as u32 > MAX_DEPTH {
                        return Err(format!("tree deeper than {MAX_DEPTH}"));
                    }
                }
            }
        }
        Ok(())
    }

    /// The geometry that holds primitive sequence number `id`, and the primitive's index in it.
    #[inline]
    pub fn locate(&self, id: u32) -> (u32, u32) {
        // One geometry (the common case): nothing to search.
        if let [g] = self.geometries {
            return (0, id - g.first_primitive);
        }
        let g = self
            .geometries
            .partition_point(|g| g.first_primitive <= id)
            .saturating_sub(1);
        let first = self.geometries.get(g).map_or(0, |r| r.first_primitive);
        (g as u32, id - first)
    }
}

/// Where the sections of a validated structure are, so that a view can be made again from
/// the same (unchanged, still locked) bytes without reading the header or walking the tree.
#[derive(Clone, Debug)]
pub struct Parts {
    prim_kind: PrimKind,
    indexed: bool,
    geometries: std::ops::Range<usize>,
    nodes: std::ops::Range<usize>,
    prims: std::ops::Range<usize>,
    vertices: std::ops::Range<usize>,
    prim_ids: std::ops::Range<usize>,
}

impl<'a> View<'a> {
    /// The section ranges of this view, for [`View::from_parts`].
    pub fn parts(&self, base: &[u8]) -> Parts {
        let range = |s: &[u8]| {
            if s.is_empty() {
                return 0..0;
            }
            let start = s.as_ptr() as usize - base.as_ptr() as usize;
            start..start + s.len()
        };
        let (prims, vertices): (&[u8], &[u8]) = match (self.prim_kind, self.triangles) {
            (PrimKind::Triangles, Triangles::Direct(t)) => (bytemuck::cast_slice(t), &[]),
            (PrimKind::Triangles, Triangles::Indexed(t)) => (
                bytemuck::cast_slice(t.records),
                bytemuck::cast_slice(t.vertices),
            ),
            (PrimKind::Aabbs, _) => (bytemuck::cast_slice(self.aabbs), &[]),
            (PrimKind::Instances, _) => (bytemuck::cast_slice(self.instances), &[]),
            (PrimKind::None, _) => (&[], &[]),
        };
        Parts {
            prim_kind: self.prim_kind,
            indexed: matches!(self.triangles, Triangles::Indexed(_)),
            geometries: range(bytemuck::cast_slice(self.geometries)),
            nodes: range(bytemuck::cast_slice(self.nodes)),
            prims: range(prims),
            vertices: range(vertices),
            prim_ids: range(bytemuck::cast_slice(self.prim_ids)),
        }
    }

    /// The view again, from bytes [`View::parse`] accepted and that have not changed since.
    /// `None` only if `bytes` are not those bytes.
    #[inline]
    pub fn from_parts(bytes: &'a [u8], p: &Parts) -> Option<View<'a>> {
        let header: &Header = bytemuck::try_from_bytes(bytes.get(..HEADER_SIZE as usize)?).ok()?;
        let cast = |r: &std::ops::Range<usize>| bytes.get(r.clone());
        let (mut triangles, mut aabbs, mut instances): (Triangles, &[[f32; 6]], &[InstanceRecord]) =
            (Triangles::default(), &[], &[]);
        let prims = cast(&p.prims)?;
        match p.prim_kind {
            PrimKind::Triangles if p.indexed => {
                triangles = Triangles::Indexed(Indexed {
                    records: bytemuck::try_cast_slice(prims).ok()?,
                    vertices: bytemuck::try_cast_slice(cast(&p.vertices)?).ok()?,
                })
            }
            PrimKind::Triangles => {
                triangles = Triangles::Direct(bytemuck::try_cast_slice(prims).ok()?)
            }
            PrimKind::Aabbs => aabbs = bytemuck::try_cast_slice(prims).ok()?,
            PrimKind::Instances => instances = bytemuck::try_cast_slice(prims).ok()?,
            PrimKind::None => {}
        }
        Some(View {
            header,
            prim_kind: p.prim_kind,
            geometries: bytemuck::try_cast_slice(cast(&p.geometries)?).ok()?,
            nodes: bytemuck::try_cast_slice(cast(&p.nodes)?).ok()?,
            triangles,
            aabbs,
            instances,
            prim_ids: bytemuck::try_cast_slice(cast(&p.prim_ids)?).ok()?,
        })
    }
}
