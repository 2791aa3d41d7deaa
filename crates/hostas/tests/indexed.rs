//! Indexed triangles (`layout::indexed`): builds that do not allow update store a mesh's
//! triangles as records into shared vertices. They must trace exactly as the same tree with
//! direct triangles (a build that allows update keeps them direct, over the same tree), be
//! smaller, and be rejected when their records are corrupt.

use hostas::layout::{TriRecord, view};
use hostas::traverse::{CommittedType, RayQuery};
use hostas::{AccelerationStructure, Device, Ray, vk};
use hostas_testkit::generate;
use rand::Rng;

type F = vk::BuildAccelerationStructureFlagsKHR;

const SERIALIZED_HEADER: usize = hostas::commands::copy::SERIALIZED_HEADER_SIZE as usize;

/// A sphere (with a transform), a strip, and a soup without indices, in one bottom level.
fn mixed_blas(r: &mut generate::Rand) -> hostas_testkit::BlasDesc {
    let (pos, idx) = generate::uv_sphere(24);
    let sphere = hostas_testkit::GeometryDesc::Triangles {
        positions: pos,
        indices: idx.into_iter().flatten().collect(),
        transform: Some(generate::random_transform(r, true)),
        flags: vk::GeometryFlagsKHR::OPAQUE,
    };
    let strip = loop {
        // `random_triangles` makes a strip for some seeds: the one geometry here that is.
        let g = generate::random_triangles(r, 500, false);
        if let hostas_testkit::GeometryDesc::Triangles { positions, .. } = &g
            && positions.len() < 600
        {
            break g;
        }
    };
    let soup = loop {
        let g = generate::random_triangles(r, 300, false);
        if let hostas_testkit::GeometryDesc::Triangles { indices, .. } = &g
            && indices.is_empty()
        {
            break g;
        }
    };
    hostas_testkit::BlasDesc {
        geometries: vec![sphere, strip, soup],
    }
}

/// Hits of the same rays through two scenes over `a` and `b`, and (both built with
/// ALLOW_DATA_ACCESS) the committed triangles' vertices.
fn assert_trace_alike(device: &Device, a: AccelerationStructure, b: AccelerationStructure) {
    let ta = hostas::quick::build_single_instance_tlas(device, a).unwrap();
    let tb = hostas::quick::build_single_instance_tlas(device, b).unwrap();
    let (sa, sb) = (device.scene(ta).unwrap(), device.scene(tb).unwrap());
    let bounds = device.statistics(a).unwrap().bounds;
    let mut r = generate::rng(5);
    let mut hits = 0;
    for i in 0..3000 {
        // From around the structure towards a point inside its bounds.
        let mut point = |pad: f32| {
            [0, 1, 2].map(|k| {
                let (lo, hi) = (bounds.lo[k], bounds.hi[k]);
                r.gen_range(lo - pad * (hi - lo)..=hi + pad * (hi - lo))
            })
        };
        let (o, target) = (point(0.3), point(0.0));
        let d = [0, 1, 2].map(|k| target[k] - o[k]);
        let ray = Ray::new(o, d);
        let (ha, hb) = (
            sa.trace_closest(&ray).unwrap(),
            sb.trace_closest(&ray).unwrap(),
        );
        assert_eq!(
            format!("{ha:?}"),
            format!("{hb:?}"),
            "ray {i}: closest hits differ"
        );
        let mut qa = RayQuery::new(&sa, &ray).unwrap();
        let mut qb = RayQuery::new(&sb, &ray).unwrap();
        while qa.proceed() {}
        while qb.proceed() {}
        assert_eq!(qa.committed_type(), qb.committed_type(), "ray {i}");
        if qa.committed_type() == CommittedType::Triangle {
            hits += 1;
            let (va, vb) = (
                qa.triangle_vertex_positions(true).unwrap(),
                qb.triangle_vertex_positions(true).unwrap(),
            );
            assert_eq!(
                va.map(|v| v.map(f32::to_bits)),
                vb.map(|v| v.map(f32::to_bits))
            );
        }
    }
    assert!(hits > 300, "only {hits} of 3000 rays hit");
    drop((sa, sb));
    for t in [ta, tb] {
        device.destroy_acceleration_structure(t).unwrap();
    }
}

#[test]
fn indexed_triangles_trace_as_the_same_tree_with_direct_ones() {
    let device = Device::new();
    let mut r = generate::rng(11);
    let blas = mixed_blas(&mut r);
    for preset in [F::PREFER_FAST_TRACE, F::empty(), F::LOW_MEMORY] {
        let flags = preset | F::ALLOW_DATA_ACCESS;
        let [indexed, direct] =
            [flags, flags | F::ALLOW_UPDATE].map(|f| blas.build(&device, f).unwrap());
        let (si, sd) = (
            device.statistics(indexed).unwrap(),
            device.statistics(direct).unwrap(),
        );
        assert!(si.indexed_triangles, "{preset:?}: not indexed");
        assert!(
            !sd.indexed_triangles,
            "{preset:?}: indexed although it allows update"
        );
        assert_eq!(
            (si.node_count, si.leaf_count, si.sah_cost.to_bits()),
            (sd.node_count, sd.leaf_count, sd.sah_cost.to_bits()),
            "{preset:?}: the trees differ"
        );
        // The sphere's triangles share about half a vertex each, the strip's one, the soup's
        // none (three).
        let tris = si.stored_count as u64;
        assert!(
            si.vertex_count as u64 > tris / 2 && (si.vertex_count as u64) < tris,
            "{preset:?}: {} vertices for {tris} triangles",
            si.vertex_count
        );
        assert!(
            si.used_bytes + 12 * tris < sd.used_bytes,
            "{preset:?}: indexed {} bytes, direct {}",
            si.used_bytes,
            sd.used_bytes
        );
        assert_trace_alike(&device, indexed, direct);
        for a in [indexed, direct] {
            device.destroy_acceleration_structure(a).unwrap();
        }
    }
}

#[test]
fn triangles_that_share_nothing_and_fast_builds_stay_direct() {
    let device = Device::new();
    let mut r = generate::rng(3);
    let soup = loop {
        let g = generate::random_triangles(&mut r, 400, false);
        if let hostas_testkit::GeometryDesc::Triangles { positions, .. } = &g
            && positions.len() >= 1200
        {
            break g;
        }
    };
    let soup = hostas_testkit::BlasDesc {
        geometries: vec![soup],
    };
    let a = soup.build(&device, F::PREFER_FAST_TRACE).unwrap();
    assert!(!device.statistics(a).unwrap().indexed_triangles);
    let (pos, idx) = generate::uv_sphere(20);
    let b = hostas::quick::build_triangle_blas(&device, &pos, &idx, F::PREFER_FAST_BUILD).unwrap();
    assert!(!device.statistics(b).unwrap().indexed_triangles);
    let c = hostas::quick::build_triangle_blas(&device, &pos, &idx, F::PREFER_FAST_TRACE).unwrap();
    let s = device.statistics(c).unwrap();
    assert!(s.indexed_triangles);
    // A closed sphere: about half a vertex per triangle (poles and seam aside).
    assert!((s.vertex_count as f64) < 0.6 * s.stored_count as f64);
}

#[test]
fn compacted_and_deserialized_indexed_structures_trace_the_same() {
    let device = Device::new();
    let (pos, idx) = generate::uv_sphere(30);
    let flags = F::PREFER_FAST_TRACE | F::ALLOW_COMPACTION | F::ALLOW_DATA_ACCESS;
    let a = hostas::quick::build_triangle_blas(&device, &pos, &idx, flags).unwrap();
    assert!(device.statistics(a).unwrap().indexed_triangles);
    let bytes = device.serialize(a).unwrap();
    let b = device.deserialize(&bytes).unwrap();
    assert_trace_alike(&device, a, b);
    assert_eq!(device.serialize(b).unwrap(), bytes);
    // Compacted into exactly the size the query gives: the used size, vertices included.
    let size = device
        .acceleration_structure_property(
            a,
            vk::QueryType::ACCELERATION_STRUCTURE_COMPACTED_SIZE_KHR,
        )
        .unwrap();
    assert_eq!(size, device.statistics(a).unwrap().used_bytes);
    let c = device
        .create_acceleration_structure(&hostas::AccelerationStructureCreateInfo::new(
            vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
            size,
        ))
        .unwrap();
    device
        .copy_acceleration_structure(a, c, vk::CopyAccelerationStructureModeKHR::COMPACT)
        .unwrap();
    assert_trace_alike(&device, a, c);
}

#[test]
fn corrupt_indexed_records_are_rejected() {
    let device = Device::new();
    let (pos, idx) = generate::uv_sphere(16);
    let a = hostas::quick::build_triangle_blas(&device, &pos, &idx, F::PREFER_FAST_TRACE).unwrap();
    let bytes = device.serialize(a).unwrap();
    let header = view::read_header(&bytes[SERIALIZED_HEADER..]).unwrap();
    assert_eq!(header.triangle_format, hostas::layout::TRIANGLES_INDEXED);
    let record_at = |i: usize| SERIALIZED_HEADER + header.prims_offset as usize + 8 * i;
    let last = header.stored_count as usize - 1;
    let corrupt = |f: &dyn Fn(&mut TriRecord)| {
        let mut b = bytes.clone();
        let at = record_at(last);
        let mut rec: TriRecord = bytemuck::pod_read_unaligned(&b[at..at + 8]);
        f(&mut rec);
        b[at..at + 8].copy_from_slice(bytemuck::bytes_of(&rec));
        b
    };
    let v = header.vertex_count;
    for (what, b) in [
        ("first vertex past the end", corrupt(&|r| r.a = v)),
        (
            "second vertex past the end",
            corrupt(&|r| r.db = (v - r.a) as i16),
        ),
        (
            "third vertex before the start",
            corrupt(&|r| r.dc = -(r.a as i16) - 1),
        ),
    ] {
        let err = device.deserialize(&b).expect_err(what).to_string();
        assert!(err.contains("indexed triangle"), "{what}: {err}");
    }
    // Indexed triangles claiming ALLOW_UPDATE (which would let an update write through them).
    let mut b = bytes.clone();
    let flags_at = SERIALIZED_HEADER + 12;
    let f = u32::from_le_bytes(b[flags_at..flags_at + 4].try_into().unwrap());
    b[flags_at..flags_at + 4].copy_from_slice(&(f | F::ALLOW_UPDATE.as_raw()).to_le_bytes());
    let err = device.deserialize(&b).expect_err("update flag").to_string();
    assert!(err.contains("allows update"), "{err}");
}

/// 16-bit indices after a `primitiveOffset`, from a `firstVertex`, with a transform: the
/// vertex numbers that decide sharing are the ones the range addresses.
#[test]
fn indexed_triangles_from_an_offset_range_of_16_bit_indices() {
    let device = Device::new();
    let (pos, idx) = generate::uv_sphere(20);
    let first_vertex = 5u32;
    let mut verts = vec![[9.0f32; 3]; first_vertex as usize];
    verts.extend_from_slice(&pos);
    // Three unused indices first, so that the range starts 6 bytes in.
    let mut indices = vec![0xffffu16; 3];
    indices.extend(idx.iter().flatten().map(|&i| i as u16));
    let transform: [f32; 12] = [0.0, 2.0, 0.0, 1.0, -1.0, 0.0, 0.0, 2.0, 0.0, 0.0, 0.5, 3.0];
    let geometry = hostas::Geometry::triangles(
        hostas::TrianglesData {
            vertex_format: vk::Format::R32G32B32_SFLOAT,
            vertex_data: bytemuck::cast_slice(&verts),
            vertex_stride: 12,
            max_vertex: verts.len() as u32 - 1,
            index_type: vk::IndexType::UINT16,
            index_data: Some(bytemuck::cast_slice(&indices)),
            transform_data: Some(bytemuck::cast_slice(&transform)),
        },
        vk::GeometryFlagsKHR::OPAQUE,
    );
    let range = hostas::BuildRangeInfo {
        primitive_count: idx.len() as u32,
        primitive_offset: 6,
        first_vertex,
        transform_offset: 0,
    };
    let flags = F::PREFER_FAST_TRACE | F::ALLOW_DATA_ACCESS;
    let [indexed, direct] = [flags, flags | F::ALLOW_UPDATE].map(|f| {
        hostas::quick::build(
            &device,
            vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
            f,
            &[geometry],
            &[range],
        )
        .unwrap()
    });
    let s = device.statistics(indexed).unwrap();
    assert!(s.indexed_triangles);
    assert!(
        (s.vertex_count as usize) < pos.len() + 64,
        "{} vertices",
        s.vertex_count
    );
    assert_trace_alike(&device, indexed, direct);
}
