//! Build inputs as the application describes them, and their decoding from host memory.
//!
//! The types mirror `VkAccelerationStructureBuildGeometryInfoKHR` and its geometry structs, with
//! host addresses replaced by byte slices that start at the address the application gave
//! (`vertexData.hostAddress`, ...). Offsets from the range info are applied here, exactly as the
//! spec's `VkAccelerationStructureBuildRangeInfoKHR` rules say. Host pointers carry no alignment
//! guarantee, so every read is an unaligned little-endian load from a slice.

pub mod aabbs;
pub mod instances;
pub mod triangles;
pub mod vertex_format;

use crate::device::AccelerationStructure;
use ash::vk;

/// `VkAccelerationStructureGeometryTrianglesDataKHR`.
#[derive(Clone, Copy, Debug)]
pub struct TrianglesData<'a> {
    pub vertex_format: vk::Format,
    /// Bytes starting at `vertexData.hostAddress`.
    pub vertex_data: &'a [u8],
    pub vertex_stride: u64,
    pub max_vertex: u32,
    pub index_type: vk::IndexType,
    /// Bytes starting at `indexData.hostAddress`; `None` for `VK_INDEX_TYPE_NONE_KHR`.
    pub index_data: Option<&'a [u8]>,
    /// Bytes starting at `transformData.hostAddress` (a `VkTransformMatrixKHR` at
    /// `transformOffset`); `None` is the NULL address, no transform.
    pub transform_data: Option<&'a [u8]>,
}

/// `VkAccelerationStructureGeometryAabbsDataKHR`.
#[derive(Clone, Copy, Debug)]
pub struct AabbsData<'a> {
    /// Bytes starting at `data.hostAddress`, `VkAabbPositionsKHR` records `stride` apart.
    pub data: &'a [u8],
    pub stride: u64,
}

/// `VkAccelerationStructureGeometryInstancesDataKHR`.
#[derive(Clone, Copy, Debug)]
pub enum InstancesData<'a> {
    /// `arrayOfPointers = VK_FALSE`: bytes starting at `data.hostAddress`, tightly packed
    /// 64-byte `VkAccelerationStructureInstanceKHR` records.
    Array(&'a [u8]),
    /// `arrayOfPointers = VK_TRUE`: the array of addresses starting at `data.hostAddress`,
    /// each resolved to the 64 bytes of one instance. `primitiveOffset` indexes this array
    /// in bytes (8 per entry).
    Pointers(&'a [&'a [u8]]),
}

/// The union in `VkAccelerationStructureGeometryKHR`, tagged by `geometryType`.
#[derive(Clone, Copy, Debug)]
pub enum GeometryData<'a> {
    Triangles(TrianglesData<'a>),
    Aabbs(AabbsData<'a>),
    Instances(InstancesData<'a>),
}

impl GeometryData<'_> {
    pub fn geometry_type(&self) -> vk::GeometryTypeKHR {
        match self {
            GeometryData::Triangles(_) => vk::GeometryTypeKHR::TRIANGLES,
            GeometryData::Aabbs(_) => vk::GeometryTypeKHR::AABBS,
            GeometryData::Instances(_) => vk::GeometryTypeKHR::INSTANCES,
        }
    }
}

/// `VkAccelerationStructureGeometryKHR`.
#[derive(Clone, Copy, Debug)]
pub struct Geometry<'a> {
    pub data: GeometryData<'a>,
    pub flags: vk::GeometryFlagsKHR,
}

impl<'a> Geometry<'a> {
    pub fn triangles(data: TrianglesData<'a>, flags: vk::GeometryFlagsKHR) -> Self {
        Geometry {
            data: GeometryData::Triangles(data),
            flags,
        }
    }
    pub fn aabbs(data: AabbsData<'a>, flags: vk::GeometryFlagsKHR) -> Self {
        Geometry {
            data: GeometryData::Aabbs(data),
            flags,
        }
    }
    pub fn instances(data: InstancesData<'a>, flags: vk::GeometryFlagsKHR) -> Self {
        Geometry {
            data: GeometryData::Instances(data),
            flags,
        }
    }
}

/// `VkAccelerationStructureBuildGeometryInfoKHR`.
#[derive(Debug)]
pub struct BuildGeometryInfo<'a> {
    pub ty: vk::AccelerationStructureTypeKHR,
    pub flags: vk::BuildAccelerationStructureFlagsKHR,
    pub mode: vk::BuildAccelerationStructureModeKHR,
    pub src: Option<AccelerationStructure>,
    pub dst: Option<AccelerationStructure>,
    /// `pGeometries` or `ppGeometries`, as one list.
    pub geometries: &'a [Geometry<'a>],
    /// Bytes starting at `scratchData.hostAddress`, at least the build (or update) scratch
    /// size from [`crate::Device::build_sizes`]. `None` is the NULL address, valid only when that
    /// size is 0 (never the case in hostas).
    pub scratch: Option<&'a mut [u8]>,
}

impl<'a> BuildGeometryInfo<'a> {
    /// A build (mode `BUILD`) of `geometries` into `dst`.
    pub fn build(
        ty: vk::AccelerationStructureTypeKHR,
        flags: vk::BuildAccelerationStructureFlagsKHR,
        geometries: &'a [Geometry<'a>],
        dst: AccelerationStructure,
        scratch: &'a mut [u8],
    ) -> Self {
        BuildGeometryInfo {
            ty,
            flags,
            mode: vk::BuildAccelerationStructureModeKHR::BUILD,
            src: None,
            dst: Some(dst),
            geometries,
            scratch: Some(scratch),
        }
    }

    /// The info `vkGetAccelerationStructureBuildSizesKHR` reads: what a build of
    /// `geometries` would be (mode `BUILD`), with no structures and no scratch, which the query
    /// ignores.
    pub fn sizes_query(
        ty: vk::AccelerationStructureTypeKHR,
        flags: vk::BuildAccelerationStructureFlagsKHR,
        geometries: &'a [Geometry<'a>],
    ) -> Self {
        BuildGeometryInfo {
            ty,
            flags,
            mode: vk::BuildAccelerationStructureModeKHR::BUILD,
            src: None,
            dst: None,
            geometries,
            scratch: None,
        }
    }
}

/// `VkAccelerationStructureBuildRangeInfoKHR`.
pub type BuildRangeInfo = vk::AccelerationStructureBuildRangeInfoKHR;

/// Reads `N` bytes at `offset`, or `None` when the slice is too short.
#[inline(always)]
pub(crate) fn read_bytes<const N: usize>(data: &[u8], offset: u64) -> Option<[u8; N]> {
    let start = usize::try_from(offset).ok()?;
    let end = start.checked_add(N)?;
    data.get(start..end).map(|s| s.try_into().unwrap_or([0; N]))
}

#[inline(always)]
pub(crate) fn read_f32(data: &[u8], offset: u64) -> Option<f32> {
    read_bytes::<4>(data, offset).map(f32::from_le_bytes)
}

#[inline(always)]
pub(crate) fn read_u32(data: &[u8], offset: u64) -> Option<u32> {
    read_bytes::<4>(data, offset).map(u32::from_le_bytes)
}

/// Reads a `VkTransformMatrixKHR` (12 floats, row-major).
pub(crate) fn read_transform(data: &[u8], offset: u64) -> Option<crate::math::Affine> {
    let mut rows = [0f32; 12];
    for (i, r) in rows.iter_mut().enumerate() {
        *r = read_f32(data, offset + 4 * i as u64)?;
    }
    Some(crate::math::Affine::from_rows(rows))
}
