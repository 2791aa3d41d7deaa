//! Convenience calls that size, create and build in one step, for programs that do not need
//! the Vulkan-shaped control over memory and scratch.

use crate::device::{AccelerationStructure, AccelerationStructureCreateInfo, Device};
use crate::error::Result;
use crate::input::instances::Instance;
use crate::input::{
    AabbsData, BuildGeometryInfo, BuildRangeInfo, Geometry, InstancesData, TrianglesData,
};
use crate::math::{Aabb, Affine};
use crate::memory::HostMemory;
use ash::vk;
use parking_lot::Mutex;

/// Sizes, creates and builds one structure from `geometries` (one range per geometry).
pub fn build(
    device: &Device,
    ty: vk::AccelerationStructureTypeKHR,
    flags: vk::BuildAccelerationStructureFlagsKHR,
    geometries: &[Geometry],
    ranges: &[BuildRangeInfo],
) -> Result<AccelerationStructure> {
    let counts: Vec<u32> = ranges.iter().map(|r| r.primitive_count).collect();
    let probe = BuildGeometryInfo::sizes_query(ty, flags, geometries);
    let sizes = device.build_sizes(vk::AccelerationStructureBuildTypeKHR::HOST, &probe, &counts)?;
    let dst = device.create_acceleration_structure(&AccelerationStructureCreateInfo::new(
        ty,
        sizes.acceleration_structure_size,
    ))?;
    let len = sizes.build_scratch_size as usize;
    let mut scratch = match SPARE_SCRATCH.lock().take() {
        Some(m) if m.len() >= len => m,
        _ => HostMemory::zeroed(len)?,
    };
    let info =
        BuildGeometryInfo::build(ty, flags, geometries, dst, &mut scratch.bytes_mut()[..len]);
    let built = device.build_acceleration_structures(&mut [info], &[ranges]);
    keep_scratch(scratch);
    match built {
        Ok(()) => Ok(dst),
        Err(e) => {
            let _ = device.destroy_acceleration_structure(dst);
            Err(e)
        }
    }
}

/// The scratch memory of the last [`build`], kept for the next one, as an application keeps
/// its scratch buffer between builds: a build does not depend on what its scratch holds, and
/// fresh memory costs the OS zeroing it (a fifth of a 70k-triangle fast build).
static SPARE_SCRATCH: Mutex<Option<HostMemory>> = Mutex::new(None);

/// At most this much scratch is kept between builds (a triangle build takes about 116 bytes per
/// triangle: 1 GiB is a 9M-triangle build's; the 3.5M-triangle crown's is 391 MiB), the same
/// limit as for dropped structures' memory.
const SPARE_SCRATCH_MAX: usize = crate::memory::KEPT_MAX;

/// Keeps `scratch` for the next build unless a larger one is kept already.
fn keep_scratch(scratch: HostMemory) {
    let mut spare = SPARE_SCRATCH.lock();
    if scratch.len() <= SPARE_SCRATCH_MAX && spare.as_ref().is_none_or(|s| s.len() < scratch.len())
    {
        *spare = Some(scratch);
    }
}

/// The geometry of an indexed triangle mesh: `R32G32B32_SFLOAT` positions, `UINT32` indices,
/// no transform.
pub fn triangle_mesh<'a>(
    positions: &'a [[f32; 3]],
    indices: &'a [[u32; 3]],
    flags: vk::GeometryFlagsKHR,
) -> Geometry<'a> {
    Geometry::triangles(
        TrianglesData {
            vertex_format: vk::Format::R32G32B32_SFLOAT,
            vertex_data: bytemuck::cast_slice(positions),
            vertex_stride: 12,
            max_vertex: (positions.len() as u32).saturating_sub(1),
            index_type: vk::IndexType::UINT32,
            index_data: Some(bytemuck::cast_slice(indices)),
            transform_data: None,
        },
        flags,
    )
}

/// A bottom-level structure over an indexed triangle mesh (one opaque geometry).
pub fn build_triangle_blas(
    device: &Device,
    positions: &[[f32; 3]],
    indices: &[[u32; 3]],
    flags: vk::BuildAccelerationStructureFlagsKHR,
) -> Result<AccelerationStructure> {
    let g = triangle_mesh(positions, indices, vk::GeometryFlagsKHR::OPAQUE);
    let range = BuildRangeInfo {
        primitive_count: indices.len() as u32,
        ..Default::default()
    };
    build(
        device,
        vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
        flags,
        &[g],
        &[range],
    )
}

/// A bottom-level structure over boxes (one geometry).
pub fn build_aabb_blas(
    device: &Device,
    boxes: &[Aabb],
    geometry_flags: vk::GeometryFlagsKHR,
    flags: vk::BuildAccelerationStructureFlagsKHR,
) -> Result<AccelerationStructure> {
    let g = Geometry::aabbs(
        AabbsData {
            data: bytemuck::cast_slice(boxes),
            stride: 24,
        },
        geometry_flags,
    );
    let range = BuildRangeInfo {
        primitive_count: boxes.len() as u32,
        ..Default::default()
    };
    build(
        device,
        vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
        flags,
        &[g],
        &[range],
    )
}

/// A top-level structure over `instances`.
pub fn build_tlas(
    device: &Device,
    instances: &[Instance],
    flags: vk::BuildAccelerationStructureFlagsKHR,
) -> Result<AccelerationStructure> {
    let bytes: Vec<u8> = instances.iter().flat_map(|i| i.encode()).collect();
    let g = Geometry::instances(InstancesData::Array(&bytes), vk::GeometryFlagsKHR::empty());
    let range = BuildRangeInfo {
        primitive_count: instances.len() as u32,
        ..Default::default()
    };
    build(
        device,
        vk::AccelerationStructureTypeKHR::TOP_LEVEL,
        flags,
        &[g],
        &[range],
    )
}

/// An instance of `blas` with `transform`, mask 0xff and no flags.
pub fn instance(blas: AccelerationStructure, transform: Affine) -> Instance {
    Instance {
        transform,
        custom_index: 0,
        mask: 0xff,
        sbt_record_offset: 0,
        flags: vk::GeometryInstanceFlagsKHR::empty(),
        acceleration_structure_reference: blas.device_address(),
    }
}

/// A top-level structure with one identity instance of `blas`.
pub fn build_single_instance_tlas(
    device: &Device,
    blas: AccelerationStructure,
) -> Result<AccelerationStructure> {
    build_tlas(
        device,
        &[instance(blas, Affine::IDENTITY)],
        vk::BuildAccelerationStructureFlagsKHR::PREFER_FAST_TRACE,
    )
}
