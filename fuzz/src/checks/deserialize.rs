//! Target `deserialize`: arbitrary bytes as serialized acceleration-structure data.
//!
//! 1. `Device::deserialize(bytes)`;
//! 2. `copy_memory_to_acceleration_structure` into a pre-created destination (size, type and
//!    placement picked from the input's hash), from an aligned and a misaligned address; the
//!    bytes around the destination must stay untouched;
//! 3. the payload written straight into a structure's memory (an application scribbling on
//!    it), then used.
//!
//! Whatever is accepted is used: statistics and properties, serialize round trip (the output of
//! serialize must deserialize, and re-serialize to the same bytes), clone and compact, a TLAS
//! over it (BLAS) or a scene of it (TLAS, also with its handles pointed at real BLASes), rays and
//! ray queries, and an update built from its own geometry records. Nothing may panic.

use super::common::*;
use hostas::commands::SerializedHeader;
use hostas::commands::copy::SERIALIZED_HEADER_SIZE;
use hostas::layout::{GeometryRecord as Record, Header, view};
use hostas::{
    AccelerationStructure, AccelerationStructureCreateInfo, Buffer, BuildGeometryInfo,
    BuildRangeInfo, Device, Geometry, vk,
};

pub fn run(data: &[u8]) {
    let fx = Fixture::new();
    let d = &fx.device;
    let mut lcg = Lcg::from_bytes(data);
    let header = SerializedHeader::parse(data).ok();

    // 1. The convenience call.
    if let Ok(a) = d.deserialize(data) {
        exercise(&fx, a, &mut lcg);
        let _ = d.destroy_acceleration_structure(a);
    }
    // 2. Into a pre-created destination.
    if let Some(h) = &header {
        into_precreated(&fx, data, h, &mut lcg);
    }
    // 3. Scribbled memory.
    let payload = match &header {
        Some(h) => {
            let start = SERIALIZED_HEADER_SIZE as usize + 8 * h.handles.len();
            &data[start.min(data.len())..]
        }
        None => data,
    };
    scribble(&fx, payload, &mut lcg);
}

/// `bytes` copied to byte `shift` of a 16-byte aligned allocation.
fn aligned(bytes: &[u8], shift: usize) -> Vec<u128> {
    let mut words = vec![0u128; (bytes.len() + shift).div_ceil(16)];
    bytemuck::cast_slice_mut::<u128, u8>(&mut words)[shift..shift + bytes.len()]
        .copy_from_slice(bytes);
    words
}

fn as_bytes(words: &[u128]) -> &[u8] {
    bytemuck::cast_slice(words)
}

fn into_precreated(fx: &Fixture, data: &[u8], h: &SerializedHeader, lcg: &mut Lcg) {
    let d = &fx.device;
    let want = h.deserialized_size;
    let sel = lcg.byte() % 5;
    let size = if want > MAX_ALLOC {
        4096
    } else {
        match sel {
            0 | 4 => want.max(1),
            1 => want.saturating_sub(64).max(1),
            2 => want + 1000,
            _ => 256,
        }
    };
    let ty = [
        vk::AccelerationStructureTypeKHR::GENERIC,
        vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
        vk::AccelerationStructureTypeKHR::TOP_LEVEL,
    ][lcg.byte() as usize % 3];
    // Placed at offset 256 of a buffer with a neighbour before it and a guard band after it.
    let size = size.div_ceil(256) * 256;
    let Ok(buffer) = Buffer::new(256 + size + 512) else {
        return;
    };
    let neighbour = d
        .create_acceleration_structure(&AccelerationStructureCreateInfo {
            buffer: Some(buffer.clone()),
            ..AccelerationStructureCreateInfo::new(vk::AccelerationStructureTypeKHR::GENERIC, 256)
        })
        .expect("neighbour");
    let dst = d
        .create_acceleration_structure(&AccelerationStructureCreateInfo {
            buffer: Some(buffer.clone()),
            offset: 256,
            ..AccelerationStructureCreateInfo::new(ty, size)
        })
        .expect("placed destination");
    let src = aligned(data, 0);
    let r = d.copy_memory_to_acceleration_structure(
        &as_bytes(&src)[..data.len()],
        dst,
        vk::CopyAccelerationStructureModeKHR::DESERIALIZE,
    );
    // A misaligned source address is always refused.
    let mis = aligned(data, 8);
    let rm = d.copy_memory_to_acceleration_structure(
        &as_bytes(&mis)[8..8 + data.len()],
        neighbour,
        vk::CopyAccelerationStructureModeKHR::DESERIALIZE,
    );
    assert!(
        rm.is_err(),
        "deserialization from a misaligned address was accepted"
    );
    // Nothing outside the destination was written.
    let mut around = vec![0u8; 256];
    buffer.read(0, &mut around).expect("read neighbour");
    assert!(
        around.iter().all(|&b| b == 0),
        "deserialization wrote into the neighbouring structure"
    );
    let mut after = vec![0u8; 512];
    buffer.read(256 + size, &mut after).expect("read guard");
    assert!(
        after.iter().all(|&b| b == 0),
        "deserialization wrote past the destination"
    );
    if r.is_ok() {
        exercise(fx, dst, lcg);
    }
    let _ = d.destroy_acceleration_structure(dst);
    let _ = d.destroy_acceleration_structure(neighbour);
}

/// The structure's bytes, copied out.
fn bytes_of(d: &Device, a: AccelerationStructure) -> Option<Vec<u8>> {
    let (buffer, offset, size) = d.placement(a).ok()?;
    let mut out = vec![0u8; size as usize];
    buffer.read(offset, &mut out).ok()?;
    Some(out)
}

/// Uses a structure that deserialization accepted (or that scribbling produced: `trusted`
/// false relaxes the "must succeed" checks).
fn exercise(fx: &Fixture, a: AccelerationStructure, lcg: &mut Lcg) {
    exercise_with(fx, a, lcg, true)
}

fn exercise_with(fx: &Fixture, a: AccelerationStructure, lcg: &mut Lcg, trusted: bool) {
    let d = &fx.device;
    let stats = match d.statistics(a) {
        Ok(s) => s,
        Err(e) => {
            assert!(!trusted, "an accepted structure has no statistics: {e}");
            return;
        }
    };
    let Some(bytes) = bytes_of(d, a) else { return };
    let Ok(header) = view::read_header(&bytes) else {
        panic!("statistics but no header")
    };
    for q in [
        vk::QueryType::ACCELERATION_STRUCTURE_SIZE_KHR,
        vk::QueryType::ACCELERATION_STRUCTURE_COMPACTED_SIZE_KHR,
        vk::QueryType::ACCELERATION_STRUCTURE_SERIALIZATION_SIZE_KHR,
        vk::QueryType::ACCELERATION_STRUCTURE_SERIALIZATION_BOTTOM_LEVEL_POINTERS_KHR,
    ] {
        let _ = d.acceleration_structure_property(a, q);
    }
    assert_eq!(
        d.acceleration_structure_property(a, vk::QueryType::ACCELERATION_STRUCTURE_SIZE_KHR)
            .ok(),
        Some(stats.used_bytes)
    );

    // Serialize round trip: serialize's output is accepted, and is a fixed point after one round.
    let mut created = Vec::new();
    let s1 = Some(d.serialize(a).expect("serialize a structure that parses"));
    if let Some(s1) = &s1 {
        let d1 = d
            .deserialize(s1)
            .expect("the output of serialize deserializes");
        let s2 = d.serialize(d1).expect("serialize again");
        let d2 = d.deserialize(&s2).expect("deserialize again");
        let s3 = d.serialize(d2).expect("serialize a third time");
        assert!(
            s2 == s3,
            "serialize(deserialize(s)) != s for s = serialize(deserialize(serialize(x)))"
        );
        created.extend([d1, d2]);
    }

    // Clone and compact into exactly sized destinations.
    if let Ok(c) = create(
        d,
        vk::AccelerationStructureTypeKHR::GENERIC,
        stats.used_bytes,
    ) {
        let r = d.copy_acceleration_structure(a, c, vk::CopyAccelerationStructureModeKHR::CLONE);
        if stats.used_bytes <= MAX_ALLOC {
            r.expect("clone into an exactly sized destination");
            assert_eq!(
                d.statistics(c).ok().map(|s| s.used_bytes),
                Some(stats.used_bytes)
            );
        }
        created.push(c);
    }
    if stats.build_flags & vk::BuildAccelerationStructureFlagsKHR::ALLOW_COMPACTION.as_raw() != 0
        && let Ok(c) = create(
            d,
            vk::AccelerationStructureTypeKHR::GENERIC,
            stats.used_bytes,
        )
    {
        let r = d.copy_acceleration_structure(a, c, vk::CopyAccelerationStructureModeKHR::COMPACT);
        if stats.used_bytes <= MAX_ALLOC {
            r.expect("compact into an exactly sized destination");
        }
        created.push(c);
    }

    let rays = probe_rays(header.bounds.lo, header.bounds.hi);
    if stats.top_level {
        match d.scene(a) {
            Ok(scene) => {
                trace_rays(&scene, &rays, false);
                for ray in rays.iter().take(4) {
                    walk_query(&scene, ray, || lcg.byte(), 1 << 22);
                }
            }
            Err(e) => assert!(!trusted, "scene of an accepted TLAS: {e}"),
        }
        // The same TLAS with its handles pointed at real bottom-level structures.
        if let Some(s1) = &s1 {
            let mut s = s1.clone();
            let n = SerializedHeader::parse(&s)
                .map(|h| h.handles.len())
                .unwrap_or(0);
            let targets = [
                fx.tri_blas.raw(),
                fx.aabb_blas.raw(),
                0,
                fx.tlas.raw(),
                fx.unbuilt.raw(),
                fx.destroyed,
            ];
            for i in 0..n {
                let t = targets[(lcg.byte() as usize % 3 + i) % targets.len()];
                s[56 + 8 * i..64 + 8 * i].copy_from_slice(&t.to_le_bytes());
            }
            if let Ok(t) = d.deserialize(&s) {
                if let Ok(scene) = d.scene(t) {
                    trace_rays(&scene, &rays, false);
                    let all = probe_rays([0.0; 3], [1.0; 3]);
                    trace_rays(&scene, &all, false);
                    walk_query(&scene, &all[0], || lcg.byte(), 1 << 22);
                }
                created.push(t);
            } else {
                panic!("a TLAS with its handles replaced no longer deserializes");
            }
        }
    } else {
        let mut instances = instances_of(a);
        instances.push(hostas::quick::instance(
            fx.tri_blas,
            hostas::Affine::IDENTITY,
        ));
        match hostas::quick::build_tlas(
            d,
            &instances,
            vk::BuildAccelerationStructureFlagsKHR::empty(),
        ) {
            Ok(t) => {
                if let Ok(scene) = d.scene(t) {
                    trace_rays(&scene, &rays, false);
                    for ray in rays.iter().take(4) {
                        walk_query(&scene, ray, || lcg.byte(), 1 << 22);
                    }
                }
                created.push(t);
            }
            Err(e) => assert!(!trusted, "a TLAS over an accepted BLAS does not build: {e}"),
        }
        if header.build_flags & vk::BuildAccelerationStructureFlagsKHR::ALLOW_UPDATE.as_raw() != 0 {
            update_from_records(fx, a, &header, &bytes, lcg, &mut created);
        }
    }
    for c in created {
        let _ = d.destroy_acceleration_structure(c);
    }
}

/// The structure's geometry records (the layout's own type, read unaligned), or `None` when
/// they do not fit in `bytes`.
pub fn records(h: &Header, bytes: &[u8]) -> Option<Vec<Record>> {
    let size = hostas::layout::GEOMETRY_RECORD_SIZE;
    (0..h.geometry_count as u64)
        .map(|g| {
            let at = usize::try_from(h.geometries_offset.checked_add(size * g)?).ok()?;
            Some(bytemuck::pod_read_unaligned(
                bytes.get(at..at + size as usize)?,
            ))
        })
        .collect()
}

/// An update of `a` whose inputs match its geometry records (types, formats, counts, flags,
/// transform presence), with new data: what an application updating the structure passes.
fn update_from_records(
    fx: &Fixture,
    a: AccelerationStructure,
    h: &Header,
    bytes: &[u8],
    lcg: &mut Lcg,
    created: &mut Vec<AccelerationStructure>,
) {
    let d = &fx.device;
    let Some(recs) = records(h, bytes) else {
        return;
    };
    if recs.len() > 64 {
        return;
    }
    const CAP: u64 = 4096;
    struct Owned {
        vertices: Vec<u8>,
        indices: Vec<u8>,
        transform: Vec<u8>,
        boxes: Vec<u8>,
    }
    let mut owned = Vec::new();
    for r in &recs {
        let prims = (r.primitive_count as u64).min(CAP) as usize;
        let format = vk::Format::from_raw(r.vertex_format as i32);
        let vsize = hostas::input::vertex_format::vertex_format_info(format)
            .map_or(12, |i| i.size as usize);
        let nverts = (r.max_vertex as u64 + 1).min(3 * CAP) as usize;
        let mut vertices = vec![0u8; nverts * vsize];
        for (i, v) in vertices.chunks_mut(4).enumerate() {
            let f = ((lcg.byte() as i8) as f32 / 16.0 + i as f32 * 0.01).to_le_bytes();
            let n = v.len();
            v.copy_from_slice(&f[..n]);
        }
        if format != vk::Format::R32G32B32_SFLOAT {
            for b in vertices.iter_mut() {
                *b ^= lcg.byte();
            }
        }
        let index_size = match vk::IndexType::from_raw(r.index_type as i32) {
            vk::IndexType::UINT16 => 2,
            vk::IndexType::NONE_KHR => 0,
            _ => 4,
        };
        let span = (r.max_vertex as u64 + 1)
            .saturating_sub(r.first_vertex as u64)
            .max(1);
        let mut indices = Vec::new();
        for _ in 0..3 * prims {
            let i = (lcg.byte() as u64 | (lcg.byte() as u64) << 8) % span;
            if index_size == 2 {
                indices.extend_from_slice(&(i as u16).to_le_bytes());
            } else if index_size == 4 {
                indices.extend_from_slice(&(i as u32).to_le_bytes());
            }
        }
        let transform: Vec<u8> = [
            1.0f32, 0.0, 0.0, 0.5, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, -0.5,
        ]
        .iter()
        .flat_map(|f| f.to_le_bytes())
        .collect();
        let mut boxes = Vec::new();
        for i in 0..prims {
            let c = (lcg.byte() as i8) as f32 / 8.0 + i as f32 * 0.001;
            for v in [c, c, c, c + 0.5, c + 0.25, c + 1.0] {
                boxes.extend_from_slice(&v.to_le_bytes());
            }
        }
        owned.push(Owned {
            vertices,
            indices,
            transform,
            boxes,
        });
    }
    let geoms: Vec<Geometry> = recs
        .iter()
        .zip(&owned)
        .map(|(r, o)| {
            let flags = vk::GeometryFlagsKHR::from_raw(r.flags);
            if r.geometry_type == vk::GeometryTypeKHR::TRIANGLES.as_raw() as u32 {
                let index_type = vk::IndexType::from_raw(r.index_type as i32);
                Geometry::triangles(
                    hostas::TrianglesData {
                        vertex_format: vk::Format::from_raw(r.vertex_format as i32),
                        vertex_data: &o.vertices,
                        vertex_stride: hostas::input::vertex_format::vertex_format_info(
                            vk::Format::from_raw(r.vertex_format as i32),
                        )
                        .map_or(12, |i| i.size as u64),
                        max_vertex: r.max_vertex,
                        index_type,
                        index_data: if index_type == vk::IndexType::NONE_KHR {
                            None
                        } else {
                            Some(&o.indices)
                        },
                        transform_data: if r.extra & 1 != 0 {
                            Some(&o.transform)
                        } else {
                            None
                        },
                    },
                    flags,
                )
            } else {
                Geometry::aabbs(
                    hostas::AabbsData {
                        data: &o.boxes,
                        stride: 24,
                    },
                    flags,
                )
            }
        })
        .collect();
    let ranges: Vec<BuildRangeInfo> = recs
        .iter()
        .map(|r| BuildRangeInfo {
            primitive_count: r.primitive_count,
            first_vertex: r.first_vertex,
            primitive_offset: 0,
            transform_offset: 0,
        })
        .collect();
    let flags = vk::BuildAccelerationStructureFlagsKHR::from_raw(h.build_flags);
    // In place, or into a new destination of the source's size.
    let dst = if lcg.byte().is_multiple_of(2) {
        Some(a)
    } else {
        create(d, vk::AccelerationStructureTypeKHR::GENERIC, h.used_size).ok()
    };
    let Some(dst) = dst else { return };
    if dst != a {
        created.push(dst);
    }
    let mut scratch = vec![0u8; 4096];
    let info = BuildGeometryInfo {
        ty: vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
        flags,
        mode: vk::BuildAccelerationStructureModeKHR::UPDATE,
        src: Some(a),
        dst: Some(dst),
        geometries: &geoms,
        scratch: Some(&mut scratch),
    };
    if d.build_acceleration_structures(&mut [info], &[&ranges])
        .is_ok()
    {
        // An update that succeeded leaves a structure that parses and can be traced.
        let st = d.statistics(dst);
        assert!(
            st.is_ok(),
            "the updated structure no longer parses: {:?}",
            st.err()
        );
        let instances = instances_of(dst);
        if let Ok(t) = hostas::quick::build_tlas(
            d,
            &instances,
            vk::BuildAccelerationStructureFlagsKHR::empty(),
        ) {
            if let Ok(scene) = d.scene(t) {
                trace_rays(&scene, &probe_rays([-2.0; 3], [2.0; 3]), false);
            }
            created.push(t);
        }
    }
}

/// The payload written into a structure's memory directly, then used as a structure.
fn scribble(fx: &Fixture, payload: &[u8], lcg: &mut Lcg) {
    let d = &fx.device;
    if payload.len() as u64 > MAX_ALLOC {
        return;
    }
    let size = (payload.len() as u64).max(256).div_ceil(256) * 256;
    let Ok(a) = create(d, vk::AccelerationStructureTypeKHR::GENERIC, size) else {
        return;
    };
    let (buffer, offset, _) = d.placement(a).expect("placement");
    buffer.write(offset, payload).expect("write payload");
    exercise_with(fx, a, lcg, false);
    let _ = d.destroy_acceleration_structure(a);
}
