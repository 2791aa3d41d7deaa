//! Builds and updates: update matches a rebuild, in place and into a separate destination;
//! index values changed in an update are honoured; a BLAS updated in place under a built TLAS
//! is traced as updated; builds are deterministic whatever the thread count; empty builds;
//! several infos in one call; sizes cover smaller builds.

use hostas::{
    AccelerationStructureCreateInfo, BuildGeometryInfo, BuildRangeInfo, Device, Geometry, HitKind,
    Ray, vk,
};
use hostas_testkit::generate::{self, Rand};
use hostas_testkit::{BlasDesc, GeometryDesc, InstanceDesc, Oracle, SceneDesc};
use rand::Rng;

const PRESETS: [vk::BuildAccelerationStructureFlagsKHR; 4] = [
    vk::BuildAccelerationStructureFlagsKHR::PREFER_FAST_TRACE,
    vk::BuildAccelerationStructureFlagsKHR::PREFER_FAST_BUILD,
    vk::BuildAccelerationStructureFlagsKHR::empty(),
    vk::BuildAccelerationStructureFlagsKHR::LOW_MEMORY,
];
const UPDATE: vk::BuildAccelerationStructureFlagsKHR =
    vk::BuildAccelerationStructureFlagsKHR::ALLOW_UPDATE;

/// Moves every vertex / box of a scene's BLASes a little (activity unchanged).
fn jiggle(desc: &mut SceneDesc, r: &mut Rand) {
    for b in &mut desc.blases {
        for g in &mut b.geometries {
            match g {
                GeometryDesc::Triangles { positions, .. } => {
                    for p in positions.iter_mut().filter(|p| !p[0].is_nan()) {
                        for c in p.iter_mut() {
                            *c += r.gen_range(-1.5..1.5);
                        }
                    }
                }
                GeometryDesc::Aabbs { boxes, .. } => {
                    for bx in boxes.iter_mut().filter(|b| !b[0].is_nan()) {
                        let d = [
                            r.gen_range(-2.0f32..2.0),
                            r.gen_range(-2.0..2.0),
                            r.gen_range(-2.0..2.0),
                        ];
                        for k in 0..3 {
                            bx[k] += d[k];
                            bx[k + 3] += d[k] + r.gen_range(0.0..0.5);
                        }
                    }
                }
            }
        }
    }
    for i in &mut desc.instances {
        if r.gen_bool(0.5) {
            i.transform = generate::random_transform(r, true);
            i.mask = r.r#gen();
        }
    }
}

/// Same closest hits on both scenes for many rays.
fn same_hits(a: &hostas::Scene, b: &hostas::Scene, desc: &SceneDesc, r: &mut Rand) {
    let oracle = Oracle::new(desc);
    for _ in 0..300 {
        let mut ray = generate::random_ray(r, desc);
        ray.flags = generate::random_flags(r);
        let (ha, hb) = (
            a.trace_closest(&ray).unwrap(),
            b.trace_closest(&ray).unwrap(),
        );
        if ha.kind == HitKind::Triangle || hb.kind == HitKind::Triangle {
            assert_eq!(ha.t, hb.t, "{ray:?}");
            // Identity may differ only on exact ties.
            if (ha.instance_id, ha.geometry_index, ha.primitive_index)
                != (hb.instance_id, hb.geometry_index, hb.primitive_index)
            {
                let (_, tied) = oracle.closest(&ray).unwrap();
                assert!(
                    tied.len() > 1,
                    "different hits without a tie: {ha:?} vs {hb:?}"
                );
            }
        } else {
            assert_eq!(
                ha.kind == HitKind::Miss,
                hb.kind == HitKind::Miss,
                "{ray:?}: {ha:?} vs {hb:?}"
            );
        }
    }
}

#[test]
fn update_matches_rebuild_in_place_and_separate() {
    for seed in 0..12u64 {
        let mut r = generate::rng(seed);
        let mut desc = generate::random_scene(&mut r, 200, seed % 2 == 0);
        let preset = PRESETS[seed as usize % 4] | UPDATE;
        let device = Device::new();
        let built = desc.build(&device, preset, preset).unwrap();
        // A second, separate destination for every BLAS.
        let separate: Vec<_> = built
            .blases
            .iter()
            .map(|b| {
                let (_, _, size) = device.placement(*b).unwrap();
                device
                    .create_acceleration_structure(&AccelerationStructureCreateInfo::new(
                        vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
                        size,
                    ))
                    .unwrap()
            })
            .collect();
        let before: Vec<Vec<u8>> = built.blases.iter().map(|b| read_all(&device, *b)).collect();
        jiggle(&mut desc, &mut r);
        for (i, b) in desc.blases.iter().enumerate() {
            b.update(&device, preset, built.blases[i], separate[i])
                .unwrap();
            assert_eq!(
                read_all(&device, built.blases[i]),
                before[i],
                "an update into another destination leaves the source unchanged"
            );
            b.update(&device, preset, built.blases[i], built.blases[i])
                .unwrap();
        }
        let in_place_tlas = desc.build_tlas(&device, &built.blases, preset).unwrap();
        let separate_tlas = desc.build_tlas(&device, &separate, preset).unwrap();
        let rebuilt = desc.build(&device, preset, preset).unwrap();
        let (a, b, c) = (
            device.scene(in_place_tlas).unwrap(),
            device.scene(separate_tlas).unwrap(),
            device.scene(rebuilt.tlas).unwrap(),
        );
        same_hits(&a, &c, &desc, &mut r);
        same_hits(&b, &c, &desc, &mut r);
    }
}

fn read_all(device: &Device, a: hostas::AccelerationStructure) -> Vec<u8> {
    let (buffer, offset, size) = device.placement(a).unwrap();
    let mut out = vec![0u8; size as usize];
    buffer.read(offset, &mut out).unwrap();
    out
}

#[test]
fn tlas_update_matches_rebuild() {
    let mut r = generate::rng(77);
    let mut desc = generate::random_scene(&mut r, 100, false);
    let device = Device::new();
    let built = desc
        .build(&device, PRESETS[0], PRESETS[2] | UPDATE)
        .unwrap();
    for i in &mut desc.instances {
        i.transform = generate::random_transform(&mut r, true);
        i.custom_index = r.gen_range(0..1 << 24);
    }
    // Update the TLAS in place with new transforms and fields.
    let bytes: Vec<u8> = desc
        .instances
        .iter()
        .flat_map(|i| i.to_instance(&built.blases).encode())
        .collect();
    let g = [Geometry::instances(
        hostas::InstancesData::Array(&bytes),
        vk::GeometryFlagsKHR::empty(),
    )];
    let range = [BuildRangeInfo {
        primitive_count: desc.instances.len() as u32,
        ..Default::default()
    }];
    let mut scratch = vec![0u8; 1024];
    let info = BuildGeometryInfo {
        ty: vk::AccelerationStructureTypeKHR::TOP_LEVEL,
        flags: PRESETS[2] | UPDATE,
        mode: vk::BuildAccelerationStructureModeKHR::UPDATE,
        src: Some(built.tlas),
        dst: Some(built.tlas),
        geometries: &g,
        scratch: Some(&mut scratch),
    };
    device
        .build_acceleration_structures(&mut [info], &[&range])
        .unwrap();
    let rebuilt = desc.build_tlas(&device, &built.blases, PRESETS[2]).unwrap();
    let (a, b) = (
        device.scene(built.tlas).unwrap(),
        device.scene(rebuilt).unwrap(),
    );
    same_hits(&a, &b, &desc, &mut r);
    // The custom index comes from the update.
    let mut checked = 0;
    for _ in 0..200 {
        let ray = generate::random_ray(&mut r, &desc);
        let h = a.trace_closest(&ray).unwrap();
        if h.is_hit() {
            assert_eq!(
                h.instance_custom_index,
                desc.instances[h.instance_id as usize].custom_index
            );
            checked += 1;
        }
    }
    assert!(checked > 0);
}

/// CTS `update/*/indices`: the update changes index values (against VUID-03768) and expects
/// the new ones to be used; and the BLAS is updated under a built TLAS that is not rebuilt.
#[test]
fn update_rereads_indices_and_is_seen_through_a_built_tlas() {
    let positions = vec![
        [0.0f32, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0], // 0..2 at z = 0
        [0.0, 0.0, -0.5],
        [1.0, 0.0, -0.5],
        [0.0, 1.0, -0.5], // 3..5 at z = -0.5
    ];
    let blas = |indices: Vec<u32>| BlasDesc {
        geometries: vec![GeometryDesc::Triangles {
            positions: positions.clone(),
            indices,
            transform: None,
            flags: vk::GeometryFlagsKHR::OPAQUE,
        }],
    };
    let desc = SceneDesc {
        blases: vec![blas(vec![0, 1, 2])],
        instances: vec![InstanceDesc::identity(0)],
    };
    let device = Device::new();
    for preset in PRESETS {
        let built = desc.build(&device, preset | UPDATE, preset).unwrap();
        let ray = Ray::new([0.2, 0.2, 1.0], [0.0, 0.0, -1.0]);
        assert!(
            (device
                .scene(built.tlas)
                .unwrap()
                .trace_closest(&ray)
                .unwrap()
                .t
                - 1.0)
                .abs()
                < 1e-6
        );
        blas(vec![3, 4, 5])
            .update(&device, preset | UPDATE, built.blases[0], built.blases[0])
            .unwrap();
        let h = device
            .scene(built.tlas)
            .unwrap()
            .trace_closest(&ray)
            .unwrap();
        assert!(
            (h.t - 1.5).abs() < 1e-6,
            "new index values and the live BLAS reference: {h:?} preset {preset:?}"
        );
    }
}

/// Builds `blas` with every preset on pools of 1, 2 and 4 threads and compares the bytes.
fn assert_same_bytes_on_1_2_4_threads(blas: &BlasDesc) {
    for preset in PRESETS {
        let bytes = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| {
                let device = Device::new();
                let b = blas.build(&device, preset).unwrap();
                read_all(&device, b)
            })
        };
        let one = bytes(1);
        assert_eq!(one, bytes(2), "preset {preset:?}");
        assert_eq!(one, bytes(4), "preset {preset:?}");
    }
}

#[test]
fn builds_are_deterministic_across_thread_counts() {
    let mut r = generate::rng(9);
    // Large enough for the parallel paths (binning, partitioning, encoding) to run.
    let blas = BlasDesc {
        geometries: vec![
            generate::random_triangles(&mut r, 150_000, true),
            generate::random_triangles(&mut r, 30_000, true),
        ],
    };
    assert_same_bytes_on_1_2_4_threads(&blas);
}

/// A NaN in a vertex component other than the first X is undefined behaviour for the spec;
/// hostas still builds such input without panicking and, like any other, into the same bytes
/// on every thread count.
#[test]
fn builds_with_undefined_nan_components_are_deterministic_across_thread_counts() {
    let mut r = generate::rng(11);
    let mut geometry = generate::random_triangles(&mut r, 150_000, true);
    let GeometryDesc::Triangles { positions, .. } = &mut geometry else {
        unreachable!("random_triangles makes triangles");
    };
    for (i, p) in positions.iter_mut().enumerate() {
        if !p[0].is_nan() && i % 97 == 0 {
            p[1 + i % 2] = f32::NAN;
        }
    }
    let blas = BlasDesc {
        geometries: vec![geometry],
    };
    assert_same_bytes_on_1_2_4_threads(&blas);
}

#[test]
fn empty_builds_have_nonzero_sizes_and_miss() {
    let device = Device::new();
    let geometry_with = |n: u32| GeometryDesc::Triangles {
        positions: vec![[f32::NAN, 0.0, 0.0]; 3 * n as usize],
        indices: vec![],
        transform: None,
        flags: vk::GeometryFlagsKHR::OPAQUE,
    };
    let cases = [
        BlasDesc { geometries: vec![] },
        BlasDesc {
            geometries: vec![geometry_with(0)],
        },
        BlasDesc {
            geometries: vec![geometry_with(3)],
        }, // all inactive
        BlasDesc {
            geometries: vec![GeometryDesc::Aabbs {
                boxes: vec![],
                flags: vk::GeometryFlagsKHR::empty(),
            }],
        },
    ];
    for (i, blas) in cases.into_iter().enumerate() {
        let desc = SceneDesc {
            blases: vec![blas],
            instances: vec![InstanceDesc::identity(0)],
        };
        let probe = BuildGeometryInfo {
            ty: vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
            flags: Default::default(),
            mode: Default::default(),
            src: None,
            dst: None,
            geometries: &[],
            scratch: None,
        };
        let sizes = device
            .build_sizes(vk::AccelerationStructureBuildTypeKHR::HOST, &probe, &[])
            .unwrap();
        assert!(
            sizes.acceleration_structure_size > 0
                && sizes.build_scratch_size > 0
                && sizes.update_scratch_size > 0
        );
        let built = desc.build(&device, PRESETS[i % 4], PRESETS[0]).unwrap();
        let scene = device.scene(built.tlas).unwrap();
        let ray = Ray::new([0.0, 0.0, 5.0], [0.0, 0.0, -1.0]);
        assert!(!scene.trace_closest(&ray).unwrap().is_hit(), "case {i}");
    }
    // A TLAS with no instances, and one with only inactive instances.
    let blas = BlasDesc {
        geometries: vec![geometry_with(0)],
    }
    .build(&device, PRESETS[0])
    .unwrap();
    for instances in [
        vec![],
        vec![InstanceDesc {
            blas: None,
            ..InstanceDesc::identity(0)
        }],
    ] {
        let desc = SceneDesc {
            blases: vec![],
            instances,
        };
        let tlas = desc.build_tlas(&device, &[blas], PRESETS[0]).unwrap();
        assert!(
            !device
                .scene(tlas)
                .unwrap()
                .trace_closest(&Ray::new([0.0; 3], [0.0, 0.0, 1.0]))
                .unwrap()
                .is_hit()
        );
    }
}

#[test]
fn several_infos_in_one_call_and_sizes_cover_smaller_builds() {
    let mut r = generate::rng(21);
    let device = Device::new();
    let descs: Vec<BlasDesc> = (0..3)
        .map(|i| {
            let mut g = generate::random_triangles(&mut r, 500 + 100 * i, false);
            if let GeometryDesc::Triangles { transform, .. } = &mut g {
                *transform = None;
            }
            BlasDesc {
                geometries: vec![g],
            }
        })
        .collect();
    // Sized for 1000 triangles, built with fewer.
    let bytes: Vec<(Vec<u8>, Vec<u8>)> = descs
        .iter()
        .map(|d| match &d.geometries[0] {
            GeometryDesc::Triangles {
                positions, indices, ..
            } => (
                bytemuck::cast_slice(positions).to_vec(),
                bytemuck::cast_slice(indices).to_vec(),
            ),
            _ => unreachable!(),
        })
        .collect();
    let geoms: Vec<[Geometry; 1]> = descs
        .iter()
        .zip(&bytes)
        .map(|(d, (v, i))| {
            let GeometryDesc::Triangles {
                positions,
                indices,
                flags,
                ..
            } = &d.geometries[0]
            else {
                unreachable!()
            };
            [Geometry::triangles(
                hostas::TrianglesData {
                    vertex_format: vk::Format::R32G32B32_SFLOAT,
                    vertex_data: v,
                    vertex_stride: 12,
                    max_vertex: positions.len() as u32 - 1,
                    index_type: if indices.is_empty() {
                        vk::IndexType::NONE_KHR
                    } else {
                        vk::IndexType::UINT32
                    },
                    index_data: if indices.is_empty() { None } else { Some(i) },
                    transform_data: None,
                },
                *flags,
            )]
        })
        .collect();
    let probe = BuildGeometryInfo {
        ty: vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
        flags: PRESETS[0],
        mode: Default::default(),
        src: None,
        dst: None,
        geometries: &geoms[0],
        scratch: None,
    };
    let sizes = device
        .build_sizes(vk::AccelerationStructureBuildTypeKHR::HOST, &probe, &[1000])
        .unwrap();
    let dsts: Vec<_> = (0..3)
        .map(|_| {
            device
                .create_acceleration_structure(&AccelerationStructureCreateInfo::new(
                    vk::AccelerationStructureTypeKHR::GENERIC,
                    sizes.acceleration_structure_size,
                ))
                .unwrap()
        })
        .collect();
    let mut scratches: Vec<Vec<u8>> = (0..3)
        .map(|_| vec![0xcdu8; sizes.build_scratch_size as usize + 7])
        .collect();
    let ranges: Vec<[BuildRangeInfo; 1]> = descs
        .iter()
        .map(|d| {
            [BuildRangeInfo {
                primitive_count: d.geometries[0].primitive_count(),
                ..Default::default()
            }]
        })
        .collect();
    let mut infos: Vec<BuildGeometryInfo> = geoms
        .iter()
        .zip(&dsts)
        .zip(scratches.iter_mut())
        // Scratch at an odd address: host scratch has no alignment guarantee.
        .map(|((g, d), s)| {
            BuildGeometryInfo::build(
                vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
                PRESETS[0],
                g,
                *d,
                &mut s[3..],
            )
        })
        .collect();
    let range_refs: Vec<&[BuildRangeInfo]> = ranges.iter().map(|r| &r[..]).collect();
    device
        .build_acceleration_structures(&mut infos, &range_refs)
        .unwrap();
    for (d, dst) in descs.iter().zip(&dsts) {
        let single = d.build(&device, PRESETS[0]).unwrap();
        let desc = SceneDesc {
            blases: vec![d.clone()],
            instances: vec![InstanceDesc::identity(0)],
        };
        let a = device
            .scene(desc.build_tlas(&device, &[*dst], PRESETS[0]).unwrap())
            .unwrap();
        let b = device
            .scene(desc.build_tlas(&device, &[single], PRESETS[0]).unwrap())
            .unwrap();
        same_hits(&a, &b, &desc, &mut r);
    }
}

#[test]
fn presets_make_different_trees() {
    let mut r = generate::rng(4);
    let blas = BlasDesc {
        geometries: vec![generate::random_triangles(&mut r, 20000, false)],
    };
    let device = Device::new();
    let stats: Vec<_> = PRESETS
        .iter()
        .map(|p| device.statistics(blas.build(&device, *p).unwrap()).unwrap())
        .collect();
    let names: Vec<_> = stats.iter().map(|s| s.preset).collect();
    assert_eq!(names, ["fast-trace", "fast-build", "default", "low-memory"]);
    // Fast trace is at least as good as fast build in SAH; low memory uses the fewest nodes.
    assert!(stats[0].sah_cost <= stats[1].sah_cost, "{stats:?}");
    assert!(
        stats[3].node_count <= stats[2].node_count && stats[3].used_bytes <= stats[0].used_bytes,
        "{stats:?}"
    );
}
