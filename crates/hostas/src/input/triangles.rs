//! Reading triangles from host memory, as `VkAccelerationStructureBuildRangeInfoKHR` says:
//! indexed triangles read `3 * primitiveCount` indices at `indexData + primitiveOffset` and add
//! `firstVertex` to each; non-indexed ones read vertices from
//! `vertexData + primitiveOffset + firstVertex * vertexStride`. The optional geometry transform
//! at `transformData + transformOffset` is applied to every vertex.

use super::vertex_format::{VertexFormatInfo, vertex_format_info};
use super::{BuildRangeInfo, TrianglesData, read_bytes, read_transform};
use crate::error::{Error, Location, Result};
use crate::math::{Affine, Vec3};
use ash::vk;

/// An `R32G32B32_SFLOAT` geometry's bytes, from [`TriangleReader::f32_layout`].
#[derive(Clone, Copy, Debug)]
pub struct F32Layout<'a> {
    /// 0 (no indices), 2 or 4.
    pub index_size: usize,
    pub index_data: &'a [u8],
    pub vertex_data: &'a [u8],
    pub vertex_stride: usize,
    pub first_vertex: usize,
    pub max_vertex: usize,
    pub transform: Option<Affine>,
}

/// Which vertices an indexed geometry's triangles use, read straight from its index buffer.
#[derive(Clone, Copy, Debug)]
pub struct IndexedVertices<'a> {
    /// From `primitiveOffset`.
    index_data: &'a [u8],
    /// 2 or 4.
    index_size: usize,
    first_vertex: u64,
    max_vertex: u64,
}

impl IndexedVertices<'_> {
    /// The vertex numbers (`firstVertex` included, at most `maxVertex`) of triangle `i`;
    /// `None` where its indices are not in the buffer or exceed `maxVertex`.
    pub fn triangle(&self, i: u32) -> Option<[u32; 3]> {
        let mut v = [[0; 3]];
        self.triangles(&[i], &mut v);
        v[0].iter()
            .all(|&n| n as u64 <= self.max_vertex)
            .then_some(v[0])
    }

    /// The vertex numbers (`firstVertex` included) of the triangles `ids` into `out`, not
    /// checked against `maxVertex`: `u32::MAX` (past any) where an index is not in the buffer
    /// or the sum exceeds it. The index size is chosen once for them all.
    pub fn triangles(&self, ids: &[u32], out: &mut [[u32; 3]]) {
        fn each<I: Index>(v: &IndexedVertices, ids: &[u32], out: &mut [[u32; 3]]) {
            let size = size_of::<I::Three>();
            let triangles: &[I::Three] =
                bytemuck::cast_slice(&v.index_data[..v.index_data.len() / size * size]);
            // Vulkan's `firstVertex` is a `u32`.
            let first = v.first_vertex.min(u32::MAX as u64) as u32;
            // Read at random (mostly from memory): all are asked for first, so that their
            // misses overlap.
            for &id in ids {
                if let Some(t) = triangles.get(id as usize) {
                    crate::math::prefetch(t);
                }
            }
            for (&id, out) in ids.iter().zip(out) {
                *out = triangles.get(id as usize).map_or([u32::MAX; 3], |&t| {
                    I::three(t).map(|i| i.saturating_add(first))
                });
            }
        }
        if self.index_size == 4 {
            each::<u32>(self, ids, out)
        } else {
            each::<u16>(self, ids, out)
        }
    }

    /// Vertex numbers are at most this.
    pub fn max_vertex(&self) -> u64 {
        self.max_vertex
    }
}

/// An index buffer's element type.
trait Index: Copy {
    /// A triangle's three indices, as bytes.
    type Three: bytemuck::Pod;
    /// Three indices, little-endian.
    fn three(b: Self::Three) -> [u32; 3];
}

impl Index for u32 {
    type Three = [u8; 12];
    #[inline(always)]
    fn three(b: [u8; 12]) -> [u32; 3] {
        bytemuck::cast::<_, [u32; 3]>(b).map(u32::from_le)
    }
}

impl Index for u16 {
    type Three = [u8; 6];
    #[inline(always)]
    fn three(b: [u8; 6]) -> [u32; 3] {
        bytemuck::cast::<_, [u16; 3]>(b).map(|x| u16::from_le(x) as u32)
    }
}

/// A validated view of one triangle geometry's range, ready to decode triangle `i`.
#[derive(Clone, Copy, Debug)]
pub struct TriangleReader<'a> {
    data: TrianglesData<'a>,
    format: VertexFormatInfo,
    index_size: u64,
    primitive_offset: u64,
    first_vertex: u64,
    pub primitive_count: u32,
    pub transform: Option<Affine>,
    location: Location,
}

impl<'a> TriangleReader<'a> {
    /// Checks the geometry-level rules and reads the transform.
    pub fn new(
        data: &TrianglesData<'a>,
        range: &BuildRangeInfo,
        location: Location,
    ) -> Result<Self> {
        let format = vertex_format_info(data.vertex_format).ok_or_else(|| {
            Error::vuid(
                "VUID-VkAccelerationStructureGeometryTrianglesDataKHR-vertexFormat-03797",
                location,
                format!(
                    "vertexFormat {:?} is not supported for acceleration-structure vertex buffers",
                    data.vertex_format
                ),
            )
        })?;
        let index_size = match data.index_type {
            vk::IndexType::NONE_KHR => 0,
            vk::IndexType::UINT16 => 2,
            vk::IndexType::UINT32 => 4,
            other => {
                return Err(Error::vuid(
                    "VUID-VkAccelerationStructureGeometryTrianglesDataKHR-indexType-03798",
                    location,
                    format!("indexType {other:?} is not UINT16, UINT32 or NONE_KHR"),
                ));
            }
        };
        if !data
            .vertex_stride
            .is_multiple_of(format.component_size as u64)
        {
            return Err(Error::vuid(
                "VUID-VkAccelerationStructureGeometryTrianglesDataKHR-vertexStride-03735",
                location,
                format!(
                    "vertexStride {} is not a multiple of the component size {} of {:?}",
                    data.vertex_stride, format.component_size, data.vertex_format
                ),
            ));
        }
        if data.vertex_stride > u32::MAX as u64 {
            return Err(Error::vuid(
                "VUID-VkAccelerationStructureGeometryTrianglesDataKHR-vertexStride-03819",
                location,
                format!("vertexStride {} is larger than 2^32-1", data.vertex_stride),
            ));
        }
        if index_size == 0 && data.index_data.is_some() {
            return Err(Error::vuid(
                "VUID-VkAccelerationStructureGeometryTrianglesDataKHR-indexData-parameter",
                location,
                "indexType is NONE_KHR but indexData is not NULL",
            ));
        }
        if index_size != 0 && data.index_data.is_none() {
            return Err(Error::vuid(
                "VUID-vkBuildAccelerationStructuresKHR-pInfos-03772",
                location,
                "indexType is not NONE_KHR but indexData is NULL",
            ));
        }
        let primitive_offset = range.primitive_offset as u64;
        if index_size != 0 && !primitive_offset.is_multiple_of(index_size) {
            return Err(Error::vuid(
                "VUID-VkAccelerationStructureBuildRangeInfoKHR-primitiveOffset-03656",
                location,
                format!(
                    "primitiveOffset {} is not a multiple of the index size {index_size}",
                    range.primitive_offset
                ),
            ));
        }
        if index_size == 0 && !primitive_offset.is_multiple_of(format.offset_alignment() as u64) {
            return Err(Error::vuid(
                "VUID-VkAccelerationStructureBuildRangeInfoKHR-primitiveOffset-03657",
                location,
                format!(
                    "primitiveOffset {} is not a multiple of the component size {} of {:?}",
                    range.primitive_offset,
                    format.offset_alignment(),
                    data.vertex_format
                ),
            ));
        }
        let transform = match data.transform_data {
            None => None,
            Some(bytes) => {
                if !range.transform_offset.is_multiple_of(16) {
                    return Err(Error::vuid(
                        "VUID-VkAccelerationStructureBuildRangeInfoKHR-transformOffset-03658",
                        location,
                        format!(
                            "transformOffset {} is not a multiple of 16",
                            range.transform_offset
                        ),
                    ));
                }
                Some(read_transform(bytes, range.transform_offset as u64).ok_or(
                    Error::RangeTooShort {
                        what: "transformData",
                        needed: range.transform_offset as u64 + 48,
                        available: bytes.len() as u64,
                        location,
                    },
                )?)
            }
        };
        let first_vertex = range.first_vertex as u64;
        if index_size == 0 && range.primitive_count > 0 {
            // Non-indexed: the last vertex read is firstVertex + 3 * primitiveCount - 1.
            let last = first_vertex + 3 * range.primitive_count as u64 - 1;
            if last > data.max_vertex as u64 {
                return Err(Error::vuid(
                    "VUID-VkAccelerationStructureBuildRangeInfoKHR-None-10775",
                    location,
                    format!(
                        "firstVertex {} + 3 * primitiveCount {} - 1 = {last} exceeds maxVertex {}",
                        range.first_vertex, range.primitive_count, data.max_vertex
                    ),
                ));
            }
        }
        Ok(TriangleReader {
            data: *data,
            format,
            index_size,
            primitive_offset,
            first_vertex,
            primitive_count: range.primitive_count,
            transform,
            location,
        })
    }

    pub fn format(&self) -> VertexFormatInfo {
        self.format
    }

    /// The geometry's bytes as [`Self::triangle_fast`] reads them, for decoders that hoist the
    /// per-geometry setup out of their loop: `None` unless the vertex format is
    /// `R32G32B32_SFLOAT`. `index_data` starts at `primitiveOffset` (indexed geometries) and
    /// `vertex_data` at the first byte a vertex index counts from (`primitiveOffset` for
    /// non-indexed geometries); either may be shorter than the range needs.
    pub fn f32_layout(&self) -> Option<F32Layout<'a>> {
        if self.format.format != vk::Format::R32G32B32_SFLOAT {
            return None;
        }
        let start = |b: &'a [u8], at: u64| b.get(usize::try_from(at).ok()?..);
        let (index_data, vertex_data) = if self.index_size == 0 {
            (
                &[][..],
                start(self.data.vertex_data, self.primitive_offset)?,
            )
        } else {
            (
                start(self.data.index_data?, self.primitive_offset)?,
                self.data.vertex_data,
            )
        };
        Some(F32Layout {
            index_size: self.index_size as usize,
            index_data,
            vertex_data,
            vertex_stride: usize::try_from(self.data.vertex_stride).ok()?,
            first_vertex: usize::try_from(self.first_vertex).ok()?,
            max_vertex: self.data.max_vertex as usize,
            transform: self.transform,
        })
    }

    /// The geometry's index buffer as [`IndexedVertices`] (`None` without indices).
    pub fn indexed_vertices(&self) -> Option<IndexedVertices<'a>> {
        if self.index_size == 0 {
            return None;
        }
        Some(IndexedVertices {
            index_data: self
                .data
                .index_data?
                .get(usize::try_from(self.primitive_offset).ok()?..)?,
            index_size: self.index_size as usize,
            first_vertex: self.first_vertex,
            max_vertex: self.data.max_vertex as u64,
        })
    }

    /// The three vertex indices of triangle `i`, `firstVertex` included.
    #[inline]
    pub fn vertex_indices(&self, i: u32) -> Result<[u64; 3]> {
        let base = 3 * i as u64;
        if self.index_size == 0 {
            return Ok([base, base + 1, base + 2].map(|v| v + self.first_vertex));
        }
        let bytes = self.data.index_data.unwrap_or(&[]);
        if self.index_size == 4 {
            let at = (self.primitive_offset + base * 4) as usize;
            if let Some(b) = bytes.get(at..at.saturating_add(12)) {
                let raw = [0, 4, 8]
                    .map(|i| u32::from_le_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]]) as u64);
                let out = raw.map(|r| r + self.first_vertex);
                if out.iter().all(|&o| o <= self.data.max_vertex as u64) {
                    return Ok(out);
                }
            }
        }
        let mut out = [0u64; 3];
        for (k, o) in out.iter_mut().enumerate() {
            let at = self.primitive_offset + (base + k as u64) * self.index_size;
            let raw = if self.index_size == 2 {
                read_bytes::<2>(bytes, at).map(|b| u16::from_le_bytes(b) as u64)
            } else {
                read_bytes::<4>(bytes, at).map(|b| u32::from_le_bytes(b) as u64)
            };
            let raw = raw.ok_or(Error::RangeTooShort {
                what: "indexData",
                needed: at + self.index_size,
                available: bytes.len() as u64,
                location: self.location.primitive(i),
            })?;
            *o = raw + self.first_vertex;
            if *o > self.data.max_vertex as u64 {
                return Err(Error::vuid(
                    "VUID-VkAccelerationStructureBuildRangeInfoKHR-maxVertex-10774",
                    self.location.primitive(i),
                    format!(
                        "index {raw} + firstVertex {} = {} exceeds maxVertex {}",
                        self.first_vertex, *o, self.data.max_vertex
                    ),
                ));
            }
        }
        Ok(out)
    }

    /// Vertex `v` (firstVertex already added) before the geometry transform.
    #[inline]
    pub fn vertex(&self, v: u64, primitive: u32) -> Result<Vec3> {
        let base = if self.index_size == 0 {
            self.primitive_offset
        } else {
            0
        };
        let at = base + v * self.data.vertex_stride;
        let start = usize::try_from(at).unwrap_or(usize::MAX);
        // The common format, read directly.
        if self.format.format == vk::Format::R32G32B32_SFLOAT
            && let Some(b) = self.data.vertex_data.get(start..start.saturating_add(12))
        {
            let f = |i: usize| f32::from_le_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]]);
            return Ok([f(0), f(4), f(8)]);
        }
        self.data
            .vertex_data
            .get(start..)
            .and_then(|s| self.format.decode(s))
            .ok_or(Error::RangeTooShort {
                what: "vertexData",
                needed: at.saturating_add(self.format.size as u64),
                available: self.data.vertex_data.len() as u64,
                location: self.location.primitive(primitive),
            })
    }

    /// Triangle `i` as nine floats, for the common layouts (`R32G32B32_SFLOAT` with 32-bit,
    /// 16-bit or no indices), with no error path: `None` means "use [`Self::triangle`]", which
    /// handles every format and reports what is wrong. An inactive triangle comes back with
    /// its NaN in place; the caller tests `v[0]`, `v[3]`, `v[6]` (and the others, see
    /// [`Self::triangle`]).
    #[inline(always)]
    pub fn triangle_fast(&self, i: u32) -> Option<[f32; 9]> {
        if self.format.format != vk::Format::R32G32B32_SFLOAT {
            return None;
        }
        let base = 3 * i as usize;
        let fv = self.first_vertex as usize;
        let u32_at = |b: &[u8], k: usize| u32::from_le_bytes([b[k], b[k + 1], b[k + 2], b[k + 3]]);
        let idx: [usize; 3] = match self.index_size {
            0 => [base + fv, base + 1 + fv, base + 2 + fv],
            4 => {
                let at = self.primitive_offset as usize + base * 4;
                let b: &[u8; 12] = self.data.index_data?.get(at..at + 12)?.try_into().ok()?;
                [
                    u32_at(b, 0) as usize + fv,
                    u32_at(b, 4) as usize + fv,
                    u32_at(b, 8) as usize + fv,
                ]
            }
            _ => {
                let at = self.primitive_offset as usize + base * 2;
                let b: &[u8; 6] = self.data.index_data?.get(at..at + 6)?.try_into().ok()?;
                [
                    u16::from_le_bytes([b[0], b[1]]) as usize + fv,
                    u16::from_le_bytes([b[2], b[3]]) as usize + fv,
                    u16::from_le_bytes([b[4], b[5]]) as usize + fv,
                ]
            }
        };
        if idx[0].max(idx[1]).max(idx[2]) > self.data.max_vertex as usize {
            return None;
        }
        let start = if self.index_size == 0 {
            self.primitive_offset as usize
        } else {
            0
        };
        let stride = self.data.vertex_stride as usize;
        let mut out = [0f32; 9];
        for k in 0..3 {
            let at = start + idx[k] * stride;
            let b: &[u8; 12] = self.data.vertex_data.get(at..at + 12)?.try_into().ok()?;
            out[3 * k] = f32::from_le_bytes([b[0], b[1], b[2], b[3]]);
            out[3 * k + 1] = f32::from_le_bytes([b[4], b[5], b[6], b[7]]);
            out[3 * k + 2] = f32::from_le_bytes([b[8], b[9], b[10], b[11]]);
        }
        if let Some(t) = &self.transform
            && !(out[0].is_nan() || out[3].is_nan() || out[6].is_nan())
        {
            for k in 0..3 {
                let p = t.point([out[3 * k], out[3 * k + 1], out[3 * k + 2]]);
                out[3 * k..3 * k + 3].copy_from_slice(&p);
            }
        }
        Some(out)
    }

    /// Triangle `i` in the structure's space (geometry transform applied), in index order.
    /// `None` for an inactive triangle: the X component of any vertex is NaN.
    #[inline]
    pub fn triangle(&self, i: u32) -> Result<Option<[Vec3; 3]>> {
        let idx = self.vertex_indices(i)?;
        let mut v = [[0f32; 3]; 3];
        for k in 0..3 {
            v[k] = self.vertex(idx[k], i)?;
        }
        if v.iter().any(|p| p[0].is_nan()) {
            return Ok(None);
        }
        if let Some(t) = &self.transform {
            v = v.map(|p| t.point(p));
        }
        Ok(Some(v))
    }
}
