//! Clone, compact, serialize and deserialize, property queries and the compatibility check;
//! deserialization of corrupted bytes never panics.

use hostas::commands::SerializedHeader;
use hostas::{AccelerationStructureCreateInfo, Device, Ray, vk};
use hostas_testkit::generate::{self, Rand};
use hostas_testkit::{InstanceDesc, SceneDesc};
use rand::Rng;

const FLAGS: vk::BuildAccelerationStructureFlagsKHR =
    vk::BuildAccelerationStructureFlagsKHR::from_raw(
        vk::BuildAccelerationStructureFlagsKHR::ALLOW_COMPACTION.as_raw()
            | vk::BuildAccelerationStructureFlagsKHR::ALLOW_UPDATE.as_raw(),
    );

fn prop(device: &Device, a: hostas::AccelerationStructure, q: vk::QueryType) -> u64 {
    device.acceleration_structure_property(a, q).unwrap()
}

fn hits(scene: &hostas::Scene, rays: &[Ray]) -> Vec<(u32, u32, u32, u32, u32)> {
    rays.iter()
        .map(|r| {
            let h = scene.trace_closest(r).unwrap();
            (
                h.kind as u32,
                h.t.to_bits(),
                h.instance_id,
                h.geometry_index,
                h.primitive_index,
            )
        })
        .collect()
}

fn scene_and_rays(seed: u64) -> (SceneDesc, Vec<Ray>, Rand) {
    let mut r = generate::rng(seed);
    let mut desc = generate::random_scene(&mut r, 300, true);
    desc.instances.push(InstanceDesc {
        blas: None,
        ..InstanceDesc::identity(0)
    });
    let rays = (0..300)
        .map(|_| generate::random_ray(&mut r, &desc))
        .collect();
    (desc, rays, r)
}

#[test]
fn clone_compact_serialize_roundtrip_trace_the_same() {
    for seed in 0..6 {
        let (desc, rays, _) = scene_and_rays(seed);
        let device = Device::new();
        let built = desc.build(&device, FLAGS, FLAGS).unwrap();
        let reference = hits(&device.scene(built.tlas).unwrap(), &rays);

        // Clone and compact every BLAS into exactly-sized destinations; rebuild the TLAS over them.
        for mode in [
            vk::CopyAccelerationStructureModeKHR::CLONE,
            vk::CopyAccelerationStructureModeKHR::COMPACT,
        ] {
            let copies: Vec<_> = built
                .blases
                .iter()
                .map(|b| {
                    let q = if mode == vk::CopyAccelerationStructureModeKHR::CLONE {
                        vk::QueryType::ACCELERATION_STRUCTURE_SIZE_KHR
                    } else {
                        vk::QueryType::ACCELERATION_STRUCTURE_COMPACTED_SIZE_KHR
                    };
                    let size = prop(&device, *b, q);
                    let (_, _, allocated) = device.placement(*b).unwrap();
                    assert!(size <= allocated);
                    let dst = device
                        .create_acceleration_structure(&AccelerationStructureCreateInfo::new(
                            vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
                            size,
                        ))
                        .unwrap();
                    device.copy_acceleration_structure(*b, dst, mode).unwrap();
                    assert_eq!(
                        prop(&device, dst, vk::QueryType::ACCELERATION_STRUCTURE_SIZE_KHR),
                        size,
                        "SIZE(copy) == SIZE(src)"
                    );
                    dst
                })
                .collect();
            let tlas = desc.build_tlas(&device, &copies, FLAGS).unwrap();
            assert_eq!(
                hits(&device.scene(tlas).unwrap(), &rays),
                reference,
                "{mode:?}"
            );
            // A compacted copy can still be updated.
            desc.blases[0]
                .update(&device, FLAGS, copies[0], copies[0])
                .unwrap();
        }

        // Serialize each BLAS and the TLAS, deserialize into new objects, rewrite the handle list.
        let mut new_blases = Vec::new();
        for b in &built.blases {
            let bytes = device.serialize(*b).unwrap();
            let h = SerializedHeader::parse(&bytes).unwrap();
            assert_eq!(h.handle_count, 0);
            assert_eq!(h.serialized_size, bytes.len() as u64);
            assert_eq!(
                prop(
                    &device,
                    *b,
                    vk::QueryType::ACCELERATION_STRUCTURE_SERIALIZATION_BOTTOM_LEVEL_POINTERS_KHR
                ),
                0
            );
            let mut version = [0u8; 32];
            version.copy_from_slice(&bytes[..32]);
            assert_eq!(
                device.compatibility(&version),
                vk::AccelerationStructureCompatibilityKHR::COMPATIBLE
            );
            let nb = device.deserialize(&bytes).unwrap();
            assert_eq!(
                device.serialize(nb).unwrap(),
                bytes,
                "serialize(deserialize(x)) == x for a BLAS"
            );
            new_blases.push(nb);
        }
        let mut tbytes = device.serialize(built.tlas).unwrap();
        let h = SerializedHeader::parse(&tbytes).unwrap();
        assert_eq!(
            h.handle_count as usize,
            desc.instances.len(),
            "one handle per instance"
        );
        assert_eq!(
            prop(
                &device,
                built.tlas,
                vk::QueryType::ACCELERATION_STRUCTURE_SERIALIZATION_BOTTOM_LEVEL_POINTERS_KHR
            ),
            h.handle_count
        );
        assert!(
            prop(
                &device,
                built.tlas,
                vk::QueryType::ACCELERATION_STRUCTURE_SERIALIZATION_SIZE_KHR
            ) >= prop(
                &device,
                built.tlas,
                vk::QueryType::ACCELERATION_STRUCTURE_SIZE_KHR
            )
        );
        for (i, inst) in desc.instances.iter().enumerate() {
            let expected = inst.blas.map_or(0, |b| built.blases[b].raw());
            assert_eq!(h.handles[i], expected, "handle {i}");
            let new = inst.blas.map_or(0, |b| new_blases[b].raw());
            tbytes[56 + 8 * i..64 + 8 * i].copy_from_slice(&new.to_le_bytes());
        }
        let nt = device.deserialize(&tbytes).unwrap();
        let nh = SerializedHeader::parse(&device.serialize(nt).unwrap()).unwrap();
        assert!(
            nh.handles
                .iter()
                .all(|h| *h == 0 || new_blases.iter().any(|b| b.raw() == *h)),
            "the new TLAS references only the new BLASes"
        );
        // The old BLASes can go: the new TLAS does not reference them.
        for b in &built.blases {
            device.destroy_acceleration_structure(*b).unwrap();
        }
        assert_eq!(hits(&device.scene(nt).unwrap(), &rays), reference);
    }
}

#[test]
fn copy_rules() {
    let (desc, _, _) = scene_and_rays(1);
    let device = Device::new();
    let plain = desc.blases[0]
        .build(&device, vk::BuildAccelerationStructureFlagsKHR::empty())
        .unwrap();
    let size = prop(
        &device,
        plain,
        vk::QueryType::ACCELERATION_STRUCTURE_SIZE_KHR,
    );
    let dst = device
        .create_acceleration_structure(&AccelerationStructureCreateInfo::new(
            vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
            size,
        ))
        .unwrap();
    let small = device
        .create_acceleration_structure(&AccelerationStructureCreateInfo::new(
            vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
            size - 64,
        ))
        .unwrap();
    let top = device
        .create_acceleration_structure(&AccelerationStructureCreateInfo::new(
            vk::AccelerationStructureTypeKHR::TOP_LEVEL,
            size,
        ))
        .unwrap();
    let vuid = |r: hostas::Result<()>| r.unwrap_err().vuid_str().unwrap();
    assert_eq!(
        vuid(device.copy_acceleration_structure(
            plain,
            dst,
            vk::CopyAccelerationStructureModeKHR::COMPACT
        )),
        "VUID-VkCopyAccelerationStructureInfoKHR-src-03411"
    );
    assert_eq!(
        vuid(device.copy_acceleration_structure(
            plain,
            dst,
            vk::CopyAccelerationStructureModeKHR::SERIALIZE
        )),
        "VUID-VkCopyAccelerationStructureInfoKHR-mode-03410"
    );
    assert_eq!(
        vuid(device.copy_acceleration_structure(
            plain,
            small,
            vk::CopyAccelerationStructureModeKHR::CLONE
        )),
        "VUID-VkCopyAccelerationStructureInfoKHR-mode-12418"
    );
    assert_eq!(
        vuid(device.copy_acceleration_structure(
            plain,
            top,
            vk::CopyAccelerationStructureModeKHR::CLONE
        )),
        "VUID-VkCopyAccelerationStructureInfoKHR-src-04963"
    );
    assert_eq!(
        vuid(device.copy_acceleration_structure(
            plain,
            plain,
            vk::CopyAccelerationStructureModeKHR::CLONE
        )),
        "VUID-VkCopyAccelerationStructureInfoKHR-dst-07791"
    );
    let e = device
        .acceleration_structure_property(
            plain,
            vk::QueryType::ACCELERATION_STRUCTURE_COMPACTED_SIZE_KHR,
        )
        .unwrap_err();
    assert_eq!(
        e.vuid_str(),
        Some("VUID-vkWriteAccelerationStructuresPropertiesKHR-accelerationStructures-03431")
    );
    let mut data = [0u8; 16];
    let e = device
        .write_acceleration_structures_properties(
            &[plain],
            vk::QueryType::ACCELERATION_STRUCTURE_SIZE_KHR,
            &mut data,
            12,
        )
        .unwrap_err();
    assert_eq!(
        e.vuid_str(),
        Some("VUID-vkWriteAccelerationStructuresPropertiesKHR-queryType-06731")
    );
    let e = device
        .write_acceleration_structures_properties(
            &[plain, plain],
            vk::QueryType::ACCELERATION_STRUCTURE_SIZE_KHR,
            &mut data[..8],
            8,
        )
        .unwrap_err();
    assert_eq!(
        e.vuid_str(),
        Some("VUID-vkWriteAccelerationStructuresPropertiesKHR-dataSize-03452")
    );
    let e = device
        .write_acceleration_structures_properties(&[plain], vk::QueryType::OCCLUSION, &mut data, 8)
        .unwrap_err();
    assert_eq!(
        e.vuid_str(),
        Some("VUID-vkWriteAccelerationStructuresPropertiesKHR-queryType-06742")
    );
    // Serialize into too little memory, and at an unaligned address.
    let mut buf = vec![0u128; 4];
    let bytes: &mut [u8] = bytemuck::cast_slice_mut(&mut buf);
    let e = device
        .copy_acceleration_structure_to_memory(
            plain,
            bytes,
            vk::CopyAccelerationStructureModeKHR::SERIALIZE,
        )
        .unwrap_err();
    assert_eq!(
        e.vuid_str(),
        Some("VUID-VkCopyAccelerationStructureToMemoryInfoKHR-dst-03561")
    );
    let e = device
        .copy_acceleration_structure_to_memory(
            plain,
            &mut bytes[1..],
            vk::CopyAccelerationStructureModeKHR::SERIALIZE,
        )
        .unwrap_err();
    assert_eq!(
        e.vuid_str(),
        Some("VUID-vkCopyAccelerationStructureToMemoryKHR-pInfo-03751")
    );
    // A serialized structure into a too-small or wrongly typed destination.
    let ser = device.serialize(plain).unwrap();
    let mut aligned = vec![0u128; ser.len().div_ceil(16)];
    bytemuck::cast_slice_mut::<u128, u8>(&mut aligned)[..ser.len()].copy_from_slice(&ser);
    let src = &bytemuck::cast_slice::<u128, u8>(&aligned)[..ser.len()];
    let e = device
        .copy_memory_to_acceleration_structure(
            src,
            small,
            vk::CopyAccelerationStructureModeKHR::DESERIALIZE,
        )
        .unwrap_err();
    println!("{e}");
    assert_eq!(
        e.vuid_str(),
        Some("VUID-VkCopyMemoryToAccelerationStructureInfoKHR-dst-03746")
    );
    let e = device
        .copy_memory_to_acceleration_structure(
            src,
            top,
            vk::CopyAccelerationStructureModeKHR::DESERIALIZE,
        )
        .unwrap_err();
    assert_eq!(
        e.vuid_str(),
        Some("VUID-VkCopyMemoryToAccelerationStructureInfoKHR-dst-03746")
    );
    // An incompatible UUID.
    let mut bad = ser.clone();
    bad[20] ^= 1;
    let mut version = [0u8; 32];
    version.copy_from_slice(&bad[..32]);
    assert_eq!(
        device.compatibility(&version),
        vk::AccelerationStructureCompatibilityKHR::INCOMPATIBLE
    );
    assert_eq!(
        device.deserialize(&bad).unwrap_err().vuid_str(),
        Some("VUID-VkCopyMemoryToAccelerationStructureInfoKHR-pInfo-03414")
    );
}

/// Deserialization takes untrusted bytes: truncations and random corruptions are rejected or,
/// when accepted, give a structure that traces without panicking.
#[test]
fn corrupted_serialized_data_never_panics() {
    let (desc, rays, mut r) = scene_and_rays(3);
    let device = Device::new();
    let built = desc.build(&device, FLAGS, FLAGS).unwrap();
    let blas_bytes = device.serialize(built.blases[0]).unwrap();
    let tlas_bytes = device.serialize(built.tlas).unwrap();
    let mut accepted = 0;
    for i in 0..3000 {
        let mut bytes = if i % 2 == 0 {
            blas_bytes.clone()
        } else {
            tlas_bytes.clone()
        };
        match r.gen_range(0..4) {
            0 => bytes.truncate(r.gen_range(0..bytes.len())),
            1 => {
                for _ in 0..r.gen_range(1..8) {
                    let at = r.gen_range(32..bytes.len());
                    bytes[at] = r.r#gen();
                }
            }
            2 => {
                // Corrupt a u32 field of the hostas header or a node child with a nasty value.
                let at =
                    56 + if i % 2 == 0 {
                        0
                    } else {
                        8 * desc.instances.len()
                    } + r.gen_range(0..64) * 4;
                if at + 4 <= bytes.len() {
                    let v: u32 = [0, 1, u32::MAX, 0x8000_0000, r.r#gen()][r.gen_range(0..5)];
                    bytes[at..at + 4].copy_from_slice(&v.to_le_bytes());
                }
            }
            _ => {
                let at = r.gen_range(32..bytes.len() - 8);
                bytes[at..at + 8].copy_from_slice(&r.r#gen::<u64>().to_le_bytes());
            }
        }
        if let Ok(a) = device.deserialize(&bytes) {
            accepted += 1;
            let stats = device.statistics(a);
            let top = stats.as_ref().map(|s| s.top_level).unwrap_or(false);
            let tlas = if top {
                a
            } else {
                match desc.build_tlas(&device, &vec![a; desc.blases.len()], FLAGS) {
                    Ok(t) => t,
                    Err(e) => panic!("{e}: stats {stats:?}"),
                }
            };
            if let Ok(scene) = device.scene(tlas) {
                for ray in &rays[..20] {
                    let _ = scene.trace_closest(ray);
                }
            }
        }
    }
    assert!(
        accepted > 0,
        "some corruptions (in float payload bytes) are harmless"
    );
}

/// A structure of `size` bytes at offset 256 of a buffer whose memory holds `stale` bytes.
fn structure_over_stale_memory(
    device: &Device,
    ty: vk::AccelerationStructureTypeKHR,
    size: u64,
    stale: u8,
) -> hostas::AccelerationStructure {
    let buffer = hostas::Buffer::new(size + 512).unwrap();
    buffer
        .write(0, &vec![stale; (size + 512) as usize])
        .unwrap();
    device
        .create_acceleration_structure(&AccelerationStructureCreateInfo {
            buffer: Some(buffer),
            offset: 256,
            ..AccelerationStructureCreateInfo::new(ty, size)
        })
        .unwrap()
}

/// Builds `geometries` into a structure placed at offset 256 of a buffer whose memory, and
/// the scratch, hold stale bytes (as reused application memory would): the serialized
/// structure must not depend on them.
fn build_over_stale_memory(
    device: &Device,
    ty: vk::AccelerationStructureTypeKHR,
    flags: vk::BuildAccelerationStructureFlagsKHR,
    geometries: &[hostas::Geometry],
    ranges: &[hostas::BuildRangeInfo],
    stale: u8,
) -> Vec<u8> {
    let counts: Vec<u32> = ranges.iter().map(|r| r.primitive_count).collect();
    let probe = hostas::BuildGeometryInfo::sizes_query(ty, flags, geometries);
    let sizes = device
        .build_sizes(vk::AccelerationStructureBuildTypeKHR::HOST, &probe, &counts)
        .unwrap();
    let dst = structure_over_stale_memory(device, ty, sizes.acceleration_structure_size, stale);
    let mut scratch = vec![stale; sizes.build_scratch_size as usize];
    let info = hostas::BuildGeometryInfo::build(ty, flags, geometries, dst, &mut scratch);
    device
        .build_acceleration_structures(&mut [info], &[ranges])
        .unwrap();
    let bytes = device.serialize(dst).unwrap();
    device.destroy_acceleration_structure(dst).unwrap();
    bytes
}

#[test]
fn builds_do_not_depend_on_stale_memory() {
    use vk::BuildAccelerationStructureFlagsKHR as F;
    const BLAS: vk::AccelerationStructureTypeKHR = vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL;
    let mut r = generate::rng(7);
    let (pos, idx) = generate::uv_sphere(70);
    let sphere = hostas::quick::triangle_mesh(&pos, &idx, vk::GeometryFlagsKHR::OPAQUE);
    let soup = generate::random_triangles(&mut r, 3000, true);
    let boxes = generate::random_boxes(&mut r, 3000, true);
    let blas = |g: &hostas_testkit::GeometryDesc| hostas_testkit::BlasDesc {
        geometries: vec![g.clone()],
    };
    let device = Device::new();
    for preset in [
        F::PREFER_FAST_TRACE,
        F::PREFER_FAST_BUILD,
        F::empty(),
        F::LOW_MEMORY,
    ] {
        for flags in [preset, preset | F::ALLOW_UPDATE | F::ALLOW_COMPACTION] {
            let ranges = [hostas::BuildRangeInfo {
                primitive_count: idx.len() as u32,
                ..Default::default()
            }];
            let [a, b] = [0x00, 0xa5].map(|stale| {
                build_over_stale_memory(&device, BLAS, flags, &[sphere], &ranges, stale)
            });
            assert!(a == b, "sphere, {flags:?}: bytes depend on stale memory");
            for g in [&soup, &boxes] {
                let [a, b] = [0x00, 0x5a].map(|stale| {
                    blas(g).with_inputs(|geoms, ranges| {
                        build_over_stale_memory(&device, BLAS, flags, geoms, ranges, stale)
                    })
                });
                assert!(a == b, "{flags:?}: bytes depend on stale memory");
            }
        }
    }
    // A top level over three instances of one bottom level, one of them inactive.
    let blas = hostas::quick::build_triangle_blas(&device, &pos, &idx, F::empty()).unwrap();
    let mut instances: Vec<_> = (0..3)
        .map(|_| hostas::quick::instance(blas, generate::random_transform(&mut r, true)))
        .collect();
    instances[1].acceleration_structure_reference = 0;
    let bytes: Vec<u8> = instances.iter().flat_map(|i| i.encode()).collect();
    let tlas = [hostas::Geometry::instances(
        hostas::InstancesData::Array(&bytes),
        vk::GeometryFlagsKHR::empty(),
    )];
    let ranges = [hostas::BuildRangeInfo {
        primitive_count: 3,
        ..Default::default()
    }];
    let ty = vk::AccelerationStructureTypeKHR::TOP_LEVEL;
    let [a, b] = [0x00, 0xff]
        .map(|stale| build_over_stale_memory(&device, ty, F::empty(), &tlas, &ranges, stale));
    assert!(a == b, "top level: bytes depend on stale memory");
}

#[test]
fn updates_into_another_structure_do_not_depend_on_stale_memory() {
    use vk::BuildAccelerationStructureFlagsKHR as F;
    let ty = vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL;
    let flags = F::ALLOW_UPDATE;
    let mut r = generate::rng(11);
    let desc = hostas_testkit::BlasDesc {
        geometries: vec![generate::random_triangles(&mut r, 2000, true)],
    };
    let device = Device::new();
    let src = desc.build(&device, flags).unwrap();
    let size = device
        .acceleration_structure_property(src, vk::QueryType::ACCELERATION_STRUCTURE_SIZE_KHR)
        .unwrap();
    let [a, b] = [0x00, 0xa5].map(|stale| {
        let dst = structure_over_stale_memory(&device, ty, size, stale);
        desc.update(&device, flags, src, dst).unwrap();
        device.serialize(dst).unwrap()
    });
    assert!(
        a == b,
        "bytes of an update depend on the destination's stale memory"
    );
}
