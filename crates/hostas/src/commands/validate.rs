//! Info-level valid-usage rules shared by the build and build-sizes commands.

use crate::error::{Error, Location, Result};
use crate::input::{BuildGeometryInfo, GeometryData};
use crate::layout::{Kind, PrimKind};
use ash::vk;

/// Flags hostas implements; others belong to extensions it does not expose.
const SUPPORTED_FLAGS: vk::BuildAccelerationStructureFlagsKHR =
    vk::BuildAccelerationStructureFlagsKHR::from_raw(
        vk::BuildAccelerationStructureFlagsKHR::ALLOW_UPDATE.as_raw()
            | vk::BuildAccelerationStructureFlagsKHR::ALLOW_COMPACTION.as_raw()
            | vk::BuildAccelerationStructureFlagsKHR::PREFER_FAST_TRACE.as_raw()
            | vk::BuildAccelerationStructureFlagsKHR::PREFER_FAST_BUILD.as_raw()
            | vk::BuildAccelerationStructureFlagsKHR::LOW_MEMORY.as_raw()
            | vk::BuildAccelerationStructureFlagsKHR::ALLOW_DATA_ACCESS.as_raw(),
    );

/// Checks the rules that hold for any use of a build info; returns what it builds.
pub(crate) fn info(info: &BuildGeometryInfo, at: Location) -> Result<(Kind, PrimKind)> {
    let kind = match info.ty {
        vk::AccelerationStructureTypeKHR::TOP_LEVEL => Kind::TopLevel,
        vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL => Kind::BottomLevel,
        vk::AccelerationStructureTypeKHR::GENERIC => {
            return Err(Error::vuid(
                "VUID-VkAccelerationStructureBuildGeometryInfoKHR-type-03654",
                at,
                "type must not be GENERIC",
            ));
        }
        other => {
            return Err(Error::vuid(
                "VUID-VkAccelerationStructureBuildGeometryInfoKHR-type-parameter",
                at,
                format!("unknown type {other:?}"),
            ));
        }
    };
    let f = info.flags;
    if f.contains(
        vk::BuildAccelerationStructureFlagsKHR::PREFER_FAST_TRACE
            | vk::BuildAccelerationStructureFlagsKHR::PREFER_FAST_BUILD,
    ) {
        return Err(Error::vuid(
            "VUID-VkAccelerationStructureBuildGeometryInfoKHR-flags-03796",
            at,
            "PREFER_FAST_TRACE and PREFER_FAST_BUILD must not both be set",
        ));
    }
    let unsupported = f.as_raw() & !SUPPORTED_FLAGS.as_raw();
    if unsupported != 0 {
        return Err(Error::vuid(
            "VUID-VkAccelerationStructureBuildGeometryInfoKHR-flags-parameter",
            at,
            format!(
                "flags {unsupported:#x} belong to extensions hostas does not support (motion blur, micromaps, clusters)"
            ),
        ));
    }
    let g = info.geometries;
    let mut prim_kind = PrimKind::None;
    for (gi, geom) in g.iter().enumerate() {
        let at = at.geometry(gi);
        let valid_flags =
            vk::GeometryFlagsKHR::OPAQUE | vk::GeometryFlagsKHR::NO_DUPLICATE_ANY_HIT_INVOCATION;
        if !valid_flags.contains(geom.flags) {
            return Err(Error::vuid(
                "VUID-VkAccelerationStructureGeometryKHR-flags-parameter",
                at,
                format!("unknown geometry flags {:#x}", geom.flags.as_raw()),
            ));
        }
        let k = match geom.data {
            GeometryData::Triangles(t) => {
                // The address-independent rules (build sizes ignore addresses); the readers
                // check the rest against the data and the ranges.
                let probe = crate::input::TrianglesData {
                    transform_data: None,
                    index_data: if t.index_type == vk::IndexType::NONE_KHR {
                        None
                    } else {
                        Some(&[])
                    },
                    ..t
                };
                crate::input::triangles::TriangleReader::new(&probe, &Default::default(), at)?;
                PrimKind::Triangles
            }
            GeometryData::Aabbs(a) => {
                crate::input::aabbs::AabbReader::new(&a, &Default::default(), at)?;
                PrimKind::Aabbs
            }
            GeometryData::Instances(_) => PrimKind::Instances,
        };
        match kind {
            Kind::TopLevel if k != PrimKind::Instances => {
                return Err(Error::vuid(
                    "VUID-VkAccelerationStructureBuildGeometryInfoKHR-type-03789",
                    at,
                    "a top-level build's geometry must be of type INSTANCES",
                ));
            }
            Kind::BottomLevel if k == PrimKind::Instances => {
                return Err(Error::vuid(
                    "VUID-VkAccelerationStructureBuildGeometryInfoKHR-type-03791",
                    at,
                    "a bottom-level build must not have INSTANCES geometry",
                ));
            }
            _ => {}
        }
        if prim_kind != PrimKind::None && prim_kind != k {
            return Err(Error::vuid(
                "VUID-VkAccelerationStructureBuildGeometryInfoKHR-type-03792",
                at,
                "all geometries of a bottom-level build must have the same type",
            ));
        }
        prim_kind = k;
    }
    if kind == Kind::TopLevel && g.len() != 1 {
        return Err(Error::vuid(
            "VUID-VkAccelerationStructureBuildGeometryInfoKHR-type-03790",
            at,
            format!(
                "a top-level build must have exactly one geometry, not {}",
                g.len()
            ),
        ));
    }
    if g.len() as u64 > crate::device::PROPERTIES.max_geometry_count {
        return Err(Error::vuid(
            "VUID-VkAccelerationStructureBuildGeometryInfoKHR-type-03793",
            at,
            format!("geometryCount {} exceeds maxGeometryCount", g.len()),
        ));
    }
    Ok((kind, prim_kind))
}

/// Checks the primitive totals against the device limits.
pub(crate) fn counts(
    kind: Kind,
    prim_kind: PrimKind,
    total: u64,
    at: Location,
    vuid_instances: &'static str,
) -> Result<()> {
    let p = crate::device::PROPERTIES;
    match (kind, prim_kind) {
        (Kind::TopLevel, _) if total > p.max_instance_count => Err(Error::vuid(
            vuid_instances,
            at,
            format!(
                "{total} instances exceed maxInstanceCount {}",
                p.max_instance_count
            ),
        )),
        (Kind::BottomLevel, PrimKind::Triangles) if total > p.max_primitive_count => {
            Err(Error::vuid(
                "VUID-VkAccelerationStructureBuildGeometryInfoKHR-type-03795",
                at,
                format!(
                    "{total} triangles exceed maxPrimitiveCount {}",
                    p.max_primitive_count
                ),
            ))
        }
        (Kind::BottomLevel, PrimKind::Aabbs) if total > p.max_primitive_count => Err(Error::vuid(
            "VUID-VkAccelerationStructureBuildGeometryInfoKHR-type-03794",
            at,
            format!(
                "{total} AABBs exceed maxPrimitiveCount {}",
                p.max_primitive_count
            ),
        )),
        _ => Ok(()),
    }
}
