//! Host-command sequences the subcommands share: compaction and timed builds.

use anyhow::{Result, anyhow};
use hostas::{AccelerationStructure, AccelerationStructureCreateInfo, Device, vk};

/// Compacts `src` (built with `ALLOW_COMPACTION`) into a new structure of exactly the
/// compacted size (`vkCmdWriteAccelerationStructuresPropertiesKHR` + `COMPACT` copy), and
/// destroys `src`. Returns the new structure and the sizes before and after.
pub fn compact(
    device: &Device,
    src: AccelerationStructure,
    ty: vk::AccelerationStructureTypeKHR,
) -> Result<(AccelerationStructure, u64, u64)> {
    let before = device.placement(src).map_err(|e| anyhow!("{e}"))?.2;
    let size = device
        .acceleration_structure_property(
            src,
            vk::QueryType::ACCELERATION_STRUCTURE_COMPACTED_SIZE_KHR,
        )
        .map_err(|e| anyhow!("querying the compacted size: {e}"))?;
    let dst = device
        .create_acceleration_structure(&AccelerationStructureCreateInfo::new(ty, size))
        .map_err(|e| anyhow!("{e}"))?;
    device
        .copy_acceleration_structure(src, dst, vk::CopyAccelerationStructureModeKHR::COMPACT)
        .map_err(|e| anyhow!("compacting: {e}"))?;
    device
        .destroy_acceleration_structure(src)
        .map_err(|e| anyhow!("{e}"))?;
    Ok((dst, before, size))
}

/// Bytes of the memory range a structure was created with.
pub fn allocated(device: &Device, a: AccelerationStructure) -> u64 {
    device.placement(a).map(|p| p.2).unwrap_or(0)
}

/// Builds a bottom-level structure over one indexed triangle geometry with the given
/// geometry flags (`quick::build_triangle_blas` always makes it opaque).
pub fn build_triangles(
    device: &Device,
    positions: &[[f32; 3]],
    indices: &[[u32; 3]],
    geometry_flags: vk::GeometryFlagsKHR,
    flags: vk::BuildAccelerationStructureFlagsKHR,
) -> hostas::Result<AccelerationStructure> {
    let g = hostas::quick::triangle_mesh(positions, indices, geometry_flags);
    let range = hostas::BuildRangeInfo {
        primitive_count: indices.len() as u32,
        ..Default::default()
    };
    hostas::quick::build(
        device,
        vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
        flags,
        &[g],
        &[range],
    )
}
