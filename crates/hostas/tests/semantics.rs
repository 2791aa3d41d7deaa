//! Spec semantics that random testing may not reach: the ray-flag table of the CTS
//! (`ray_query/ray_flags`), watertightness (closed grids and fans), ids with inactive
//! instances and primitives, facing under geometry and instance mirrors, range ends, masks.

use hostas::{Affine, Device, HitKind, Interleave, Location, Ray, RayFlags, vk};
use hostas_testkit::generate;
use hostas_testkit::{BlasDesc, GeometryDesc, InstanceDesc, SceneDesc};
use rand::Rng;

const PRESETS: [vk::BuildAccelerationStructureFlagsKHR; 4] = [
    vk::BuildAccelerationStructureFlagsKHR::PREFER_FAST_TRACE,
    vk::BuildAccelerationStructureFlagsKHR::PREFER_FAST_BUILD,
    vk::BuildAccelerationStructureFlagsKHR::empty(),
    vk::BuildAccelerationStructureFlagsKHR::LOW_MEMORY,
];

fn translate(x: f32, y: f32, z: f32) -> Affine {
    let mut m = Affine::IDENTITY;
    m.m[0][3] = x;
    m.m[1][3] = y;
    m.m[2][3] = z;
    m
}

/// One triangle in the unit cell, front-facing for rays along -z when `front`.
fn cell_triangle(front: bool) -> GeometryDesc {
    let positions = if front {
        vec![[0.0, 1.0, 0.0], [0.0, 0.0, 0.0], [1.0, 1.0, 0.0]]
    } else {
        vec![[1.0, 1.0, 0.0], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0]]
    };
    GeometryDesc::Triangles {
        positions,
        indices: vec![],
        transform: None,
        flags: vk::GeometryFlagsKHR::empty(),
    }
}

/// What the CTS shader writes: 2 for a committed triangle or an opaque AABB candidate, 1 for
/// a non-opaque triangle or AABB candidate, 0 for nothing.
fn cts_value(scene: &hostas::Scene, ray: &Ray) -> u32 {
    let mut q = scene.ray_query(ray).unwrap();
    let mut value = 0;
    while q.proceed() {
        match q.candidate_type() {
            Some(hostas::CandidateType::Triangle) => value = value.max(1),
            Some(hostas::CandidateType::Aabb) => {
                value = value.max(if q.candidate().opaque { 2 } else { 1 })
            }
            None => {}
        }
    }
    if q.committed_type() == hostas::CommittedType::Triangle {
        value = 2;
    }
    value
}

#[test]
fn ray_flag_table_triangles() {
    // Left column FORCE_OPAQUE, right column FORCE_NO_OPAQUE; top row front-facing, bottom row
    // back-facing (vktRayQueryCullRayFlagsTests.cpp getHitResult).
    let desc = SceneDesc {
        blases: vec![
            BlasDesc {
                geometries: vec![cell_triangle(true)],
            },
            BlasDesc {
                geometries: vec![cell_triangle(false)],
            },
        ],
        instances: vec![
            InstanceDesc {
                transform: translate(0.0, 1.0, 0.0),
                flags: vk::GeometryInstanceFlagsKHR::FORCE_OPAQUE,
                ..InstanceDesc::identity(0)
            },
            InstanceDesc {
                transform: translate(1.0, 1.0, 0.0),
                flags: vk::GeometryInstanceFlagsKHR::FORCE_NO_OPAQUE,
                ..InstanceDesc::identity(0)
            },
            InstanceDesc {
                transform: translate(0.0, 0.0, 0.0),
                flags: vk::GeometryInstanceFlagsKHR::FORCE_OPAQUE,
                ..InstanceDesc::identity(1)
            },
            InstanceDesc {
                transform: translate(1.0, 0.0, 0.0),
                flags: vk::GeometryInstanceFlagsKHR::FORCE_NO_OPAQUE,
                ..InstanceDesc::identity(1)
            },
        ],
    };
    let table: [(RayFlags, [u32; 4]); 9] = [
        (RayFlags::NONE, [2, 1, 2, 1]),
        (RayFlags::OPAQUE, [2, 2, 2, 2]),
        (RayFlags::NO_OPAQUE, [1, 1, 1, 1]),
        (RayFlags::CULL_OPAQUE, [0, 1, 0, 1]),
        (RayFlags::CULL_NO_OPAQUE, [2, 0, 2, 0]),
        (RayFlags::CULL_BACK_FACING_TRIANGLES, [2, 1, 0, 0]),
        (RayFlags::CULL_FRONT_FACING_TRIANGLES, [0, 0, 2, 1]),
        (RayFlags::SKIP_TRIANGLES, [0, 0, 0, 0]),
        (RayFlags::TERMINATE_ON_FIRST_HIT, [2, 1, 2, 1]),
    ];
    let device = Device::new();
    for preset in PRESETS {
        let built = desc.build(&device, preset, preset).unwrap();
        let scene = device.scene(built.tlas).unwrap();
        for (flags, expected) in table {
            // Cells: (0,1) top-left, (1,1) top-right, (0,0) bottom-left, (1,0) bottom-right.
            let cells = [(0.0, 1.0), (1.0, 1.0), (0.0, 0.0), (1.0, 0.0)];
            for (cell, want) in cells.iter().zip(expected) {
                let ray = Ray {
                    flags,
                    ..Ray::new([cell.0 + 0.25, cell.1 + 0.75, 1.0], [0.0, 0.0, -1.0])
                };
                assert_eq!(
                    cts_value(&scene, &ray),
                    want,
                    "flags {flags:?} cell {cell:?} preset {preset:?}"
                );
            }
        }
    }
}

#[test]
fn ray_flag_table_aabbs() {
    let boxes = GeometryDesc::Aabbs {
        boxes: vec![[0.0, 0.0, -0.1, 1.0, 1.0, 0.1]],
        flags: vk::GeometryFlagsKHR::empty(),
    };
    let desc = SceneDesc {
        blases: vec![BlasDesc {
            geometries: vec![boxes],
        }],
        instances: vec![
            InstanceDesc {
                flags: vk::GeometryInstanceFlagsKHR::FORCE_OPAQUE,
                ..InstanceDesc::identity(0)
            },
            InstanceDesc {
                transform: translate(1.0, 0.0, 0.0),
                flags: vk::GeometryInstanceFlagsKHR::FORCE_NO_OPAQUE,
                ..InstanceDesc::identity(0)
            },
        ],
    };
    let table: [(RayFlags, [u32; 2]); 8] = [
        (RayFlags::NONE, [2, 1]),
        (RayFlags::OPAQUE, [2, 2]),
        (RayFlags::NO_OPAQUE, [1, 1]),
        (RayFlags::CULL_OPAQUE, [0, 1]),
        (RayFlags::CULL_NO_OPAQUE, [2, 0]),
        (RayFlags::CULL_BACK_FACING_TRIANGLES, [2, 1]),
        (RayFlags::SKIP_AABBS, [0, 0]),
        (RayFlags::TERMINATE_ON_FIRST_HIT, [2, 1]),
    ];
    let device = Device::new();
    let built = desc.build(&device, PRESETS[0], PRESETS[0]).unwrap();
    let scene = device.scene(built.tlas).unwrap();
    for (flags, expected) in table {
        for (x, want) in [0.5f32, 1.5].iter().zip(expected) {
            let ray = Ray {
                flags,
                ..Ray::new([*x, 0.5, 1.0], [0.0, 0.0, -1.0])
            };
            assert_eq!(cts_value(&scene, &ray), want, "flags {flags:?} x {x}");
        }
    }
}

/// Counts the candidates a ray meets (all made non-opaque, none confirmed).
fn count_candidates(scene: &hostas::Scene, ray: &Ray) -> usize {
    let mut r = *ray;
    r.flags = RayFlags::NO_OPAQUE;
    let mut q = scene.ray_query(&r).unwrap();
    let mut n = 0;
    while q.proceed() {
        n += 1;
    }
    n
}

#[test]
fn watertight_grid_no_miss_no_double_hit() {
    let mut r = generate::rng(11);
    let device = Device::new();
    for (case, transform) in [None, Some(generate::random_transform(&mut r, true))]
        .into_iter()
        .enumerate()
    {
        let n = 16;
        let desc = SceneDesc {
            blases: vec![BlasDesc {
                geometries: vec![generate::grid(n, transform)],
            }],
            instances: vec![
                InstanceDesc::identity(0),
                InstanceDesc {
                    transform: generate::random_transform(&mut r, true),
                    ..InstanceDesc::identity(0)
                },
            ],
        };
        for preset in PRESETS {
            let built = desc.build(&device, preset, preset).unwrap();
            let scene = device.scene(built.tlas).unwrap();
            for inst in &desc.instances {
                let world = |p: [f32; 3]| {
                    let p = transform.map_or(p, |t| t.point(p));
                    inst.transform.point(p)
                };
                for i in 0..400 {
                    // Exactly at a vertex, on an edge (cell edge or diagonal), or anywhere.
                    let (x, y) = match i % 4 {
                        0 => (r.gen_range(1..n) as f32, r.gen_range(1..n) as f32),
                        1 => (r.gen_range(1..n) as f32, r.gen_range(1.0..(n - 1) as f32)),
                        2 => {
                            let c = r.gen_range(1..n - 1) as f32 + 0.5;
                            (c, c)
                        }
                        _ => (
                            r.gen_range(0.5..n as f32 - 0.5),
                            r.gen_range(0.5..n as f32 - 0.5),
                        ),
                    };
                    let target = world([x, y, 0.0]);
                    let origin = [
                        target[0] + r.gen_range(-20.0..20.0),
                        target[1] + r.gen_range(-20.0..20.0),
                        target[2] + r.gen_range(-20.0f32..20.0),
                    ];
                    let dir = [
                        target[0] - origin[0],
                        target[1] - origin[1],
                        target[2] - origin[2],
                    ];
                    let ray = Ray {
                        t_max: 10.0,
                        ..Ray::new(origin, dir)
                    };
                    // Only this instance: mask everything else out by tracing the two instances separately.
                    let hits = count_candidates(&scene, &ray);
                    // The other instance may also be crossed; count hits on this one only.
                    let mut q = scene
                        .ray_query(&Ray {
                            flags: RayFlags::NO_OPAQUE,
                            ..ray
                        })
                        .unwrap();
                    let mut mine = 0;
                    let me = desc
                        .instances
                        .iter()
                        .position(|d| std::ptr::eq(d, inst))
                        .unwrap() as u32;
                    while q.proceed() {
                        mine += (q.candidate().instance_id == me) as usize;
                    }
                    assert!(hits >= mine);
                    assert_eq!(
                        mine, 1,
                        "case {case} preset {preset:?}: ray through ({x}, {y}) met the grid {mine} times"
                    );
                }
            }
        }
    }
}

#[test]
fn watertight_fans() {
    let mut r = generate::rng(5);
    let device = Device::new();
    for _ in 0..20 {
        let center = [
            r.gen_range(-4.0f32..4.0).round(),
            r.gen_range(-4.0f32..4.0).round() + 0.5,
            r.gen_range(-2.0f32..2.0),
        ];
        let k = r.gen_range(3..12);
        let desc = SceneDesc {
            blases: vec![BlasDesc {
                geometries: vec![generate::fan(center, k, &mut r)],
            }],
            instances: vec![InstanceDesc::identity(0)],
        };
        let built = desc
            .build(&device, PRESETS[r.gen_range(0..4)], PRESETS[0])
            .unwrap();
        let scene = device.scene(built.tlas).unwrap();
        for dz in [1.0f32, -1.0] {
            // Straight through the shared vertex (exactly), and slanted through it.
            for d in [[0.0, 0.0, -dz], [0.25, -0.5, -dz], [-0.125, 0.375, -dz]] {
                let origin = [
                    center[0] - d[0] * 4.0,
                    center[1] - d[1] * 4.0,
                    center[2] - d[2] * 4.0,
                ];
                let ray = Ray::new(origin, d);
                assert_eq!(
                    count_candidates(&scene, &ray),
                    1,
                    "fan of {k} at {center:?}, dir {d:?}"
                );
            }
        }
    }
}

#[test]
fn checkerboard_cells_hit_once_through_the_diagonal() {
    // CTS S1: two triangles per occupied cell, rays through the cell centre lie on the diagonal.
    let mut positions = Vec::new();
    for y in 0..8 {
        for x in 0..8 {
            if (x + y) % 2 == 1 {
                let (x, y) = (x as f32, y as f32);
                let v = [
                    [x, y + 1.0, 0.0],
                    [x, y, 0.0],
                    [x + 1.0, y + 1.0, 0.0],
                    [x + 1.0, y, 0.0],
                ];
                positions.extend_from_slice(&[v[0], v[1], v[2], v[2], v[1], v[3]]);
            }
        }
    }
    let desc = SceneDesc {
        blases: vec![BlasDesc {
            geometries: vec![GeometryDesc::Triangles {
                positions,
                indices: vec![],
                transform: None,
                flags: vk::GeometryFlagsKHR::OPAQUE,
            }],
        }],
        instances: vec![InstanceDesc::identity(0)],
    };
    let device = Device::new();
    for preset in PRESETS {
        let built = desc.build(&device, preset, preset).unwrap();
        let scene = device.scene(built.tlas).unwrap();
        for y in 0..8 {
            for x in 0..8 {
                let ray = Ray {
                    t_max: 1.0,
                    ..Ray::new([x as f32 + 0.5, y as f32 + 0.5, 0.5], [0.0, 0.0, -1.0])
                };
                let expected = ((x + y) % 2 == 1) as usize;
                assert_eq!(count_candidates(&scene, &ray), expected, "cell ({x}, {y})");
                assert_eq!(scene.trace_closest(&ray).unwrap().is_hit(), expected == 1);
            }
        }
    }
}

#[test]
fn ids_count_inactive_instances_and_primitives() {
    // Geometry 1's primitive 0 is inactive (NaN x); instance 1 is inactive (reference 0).
    let tri = |x: f32| [[x, 0.0, 0.0], [x + 1.0, 0.0, 0.0], [x, 1.0, 0.0]];
    let g0 = GeometryDesc::Triangles {
        positions: [tri(0.0), tri(2.0)].concat(),
        indices: vec![],
        transform: None,
        flags: vk::GeometryFlagsKHR::OPAQUE,
    };
    let mut dead = tri(4.0);
    dead[1][0] = f32::NAN;
    let g1 = GeometryDesc::Triangles {
        positions: [dead, tri(6.0), tri(8.0)].concat(),
        indices: vec![],
        transform: None,
        flags: vk::GeometryFlagsKHR::OPAQUE,
    };
    let desc = SceneDesc {
        blases: vec![BlasDesc {
            geometries: vec![g0, g1],
        }],
        instances: vec![
            InstanceDesc {
                custom_index: 0x807f00,
                ..InstanceDesc::identity(0)
            },
            InstanceDesc {
                blas: None,
                ..InstanceDesc::identity(0)
            },
            InstanceDesc {
                transform: translate(0.0, 5.0, 0.0),
                custom_index: 0xffffff,
                sbt_record_offset: 0x654321,
                ..InstanceDesc::identity(0)
            },
        ],
    };
    let device = Device::new();
    let built = desc.build(&device, PRESETS[0], PRESETS[0]).unwrap();
    let scene = device.scene(built.tlas).unwrap();
    let hit = |x: f32, y: f32| {
        scene
            .trace_closest(&Ray::new([x + 0.2, y + 0.2, 1.0], [0.0, 0.0, -1.0]))
            .unwrap()
    };
    let h = hit(2.0, 0.0);
    assert_eq!(
        (
            h.instance_id,
            h.instance_custom_index,
            h.geometry_index,
            h.primitive_index
        ),
        (0, 0x807f00, 0, 1)
    );
    assert!(
        !hit(4.0, 0.0).is_hit(),
        "inactive triangle must be invisible"
    );
    let h = hit(6.0, 5.0);
    assert_eq!(
        (
            h.instance_id,
            h.instance_custom_index,
            h.geometry_index,
            h.primitive_index
        ),
        (2, 0xffffff, 1, 1)
    );
    let h = hit(8.0, 0.0);
    assert_eq!((h.geometry_index, h.primitive_index), (1, 2));
    let mut q = scene
        .ray_query(&Ray {
            flags: RayFlags::NO_OPAQUE,
            ..Ray::new([6.2, 5.2, 1.0], [0.0, 0.0, -1.0])
        })
        .unwrap();
    assert!(q.proceed());
    assert_eq!(q.candidate().sbt_record_offset, 0x654321);
}

#[test]
fn facing_follows_geometry_mirror_not_instance_mirror() {
    let mirror = Affine::from_rows([-1.0, 0.0, 0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0]);
    let front = cell_triangle(true);
    let GeometryDesc::Triangles { positions, .. } = front.clone() else {
        unreachable!()
    };
    let mirrored_geometry = GeometryDesc::Triangles {
        positions,
        indices: vec![],
        transform: Some(mirror),
        flags: vk::GeometryFlagsKHR::empty(),
    };
    let desc = SceneDesc {
        blases: vec![
            BlasDesc {
                geometries: vec![front],
            },
            BlasDesc {
                geometries: vec![mirrored_geometry],
            },
        ],
        instances: vec![
            InstanceDesc::identity(0),
            InstanceDesc {
                transform: Affine {
                    m: [
                        [-1.0, 0.0, 0.0, 4.0],
                        [0.0, 1.0, 0.0, 0.0],
                        [0.0, 0.0, 1.0, 0.0],
                    ],
                },
                ..InstanceDesc::identity(0)
            },
            InstanceDesc {
                transform: translate(6.0, 0.0, 0.0),
                ..InstanceDesc::identity(1)
            },
            InstanceDesc {
                transform: translate(8.0, 0.0, 0.0),
                flags: vk::GeometryInstanceFlagsKHR::TRIANGLE_FLIP_FACING,
                ..InstanceDesc::identity(0)
            },
            InstanceDesc {
                transform: translate(10.0, 0.0, 0.0),
                flags: vk::GeometryInstanceFlagsKHR::TRIANGLE_FACING_CULL_DISABLE,
                ..InstanceDesc::identity(1)
            },
        ],
    };
    let device = Device::new();
    let built = desc.build(&device, PRESETS[2], PRESETS[2]).unwrap();
    let scene = device.scene(built.tlas).unwrap();
    let probe = |x: f32, flags| {
        scene
            .trace_closest(&Ray {
                flags,
                ..Ray::new([x, 0.75, 1.0], [0.0, 0.0, -1.0])
            })
            .unwrap()
    };
    // Identity: front. Instance mirror (x -> 4 - x): still front. Geometry mirror: back.
    assert!(probe(0.25, RayFlags::NONE).front_face);
    assert!(
        probe(3.75, RayFlags::NONE).front_face,
        "an instance transform does not change the winding"
    );
    let h = probe(6.75, RayFlags::NONE);
    assert!(
        h.is_hit() && !h.front_face,
        "a geometry transform with a mirror flips facing"
    );
    assert!(
        !probe(8.25, RayFlags::NONE).front_face,
        "FLIP_FACING reverses facing"
    );
    assert!(!probe(6.75, RayFlags::CULL_BACK_FACING_TRIANGLES).is_hit());
    assert!(
        probe(10.75, RayFlags::CULL_BACK_FACING_TRIANGLES).is_hit(),
        "FACING_CULL_DISABLE"
    );
}

#[test]
fn ranges_are_strict_for_triangles_and_inclusive_for_aabbs() {
    let desc = SceneDesc {
        blases: vec![
            BlasDesc {
                geometries: vec![cell_triangle(true)],
            },
            BlasDesc {
                geometries: vec![GeometryDesc::Aabbs {
                    boxes: vec![[0.0, 0.0, 0.0, 1.0, 1.0, 0.0]],
                    flags: vk::GeometryFlagsKHR::OPAQUE,
                }],
            },
        ],
        instances: vec![
            InstanceDesc::identity(0),
            InstanceDesc {
                transform: translate(2.0, 0.0, 0.0),
                ..InstanceDesc::identity(1)
            },
        ],
    };
    let device = Device::new();
    let built = desc.build(&device, PRESETS[0], PRESETS[0]).unwrap();
    let scene = device.scene(built.tlas).unwrap();
    let tri = |t_min: f32, t_max: f32| {
        scene
            .trace_closest(&Ray {
                t_min,
                t_max,
                ..Ray::new([0.25, 0.75, 1.0], [0.0, 0.0, -1.0])
            })
            .unwrap()
            .kind
    };
    assert_eq!(
        tri(0.0, 1.0),
        HitKind::Miss,
        "t == tMax is outside for triangles"
    );
    assert_eq!(
        tri(1.0, 2.0),
        HitKind::Miss,
        "t == tMin is outside for triangles"
    );
    assert_eq!(tri(0.0, 1.0001), HitKind::Triangle);
    let aabb = |t_min: f32, t_max: f32| {
        count_candidates(
            &scene,
            &Ray {
                t_min,
                t_max,
                ..Ray::new([2.5, 0.5, 1.0], [0.0, 0.0, -1.0])
            },
        )
    };
    assert_eq!(
        aabb(0.0, 1.0),
        1,
        "t == tMax is inside for AABBs (flat box)"
    );
    assert_eq!(aabb(1.0, 2.0), 1, "t == tMin is inside for AABBs");
    assert_eq!(aabb(0.0, 0.999), 0);
}

#[test]
fn cull_mask_uses_low_8_bits() {
    let desc = SceneDesc {
        blases: vec![BlasDesc {
            geometries: vec![cell_triangle(true)],
        }],
        instances: vec![InstanceDesc {
            mask: 0x0c,
            ..InstanceDesc::identity(0)
        }],
    };
    let device = Device::new();
    let built = desc.build(&device, PRESETS[0], PRESETS[0]).unwrap();
    let scene = device.scene(built.tlas).unwrap();
    for (mask, hit) in [
        (0x04u32, true),
        (0x08, true),
        (0x03, false),
        (0xf00, false),
        (0x1ff, true),
    ] {
        let ray = Ray {
            cull_mask: mask,
            ..Ray::new([0.25, 0.75, 1.0], [0.0, 0.0, -1.0])
        };
        assert_eq!(
            scene.trace_closest(&ray).unwrap().is_hit(),
            hit,
            "mask {mask:#x}"
        );
    }
}

#[test]
fn query_getters_transforms_object_ray_and_positions() {
    let t = generate::random_transform(&mut generate::rng(3), true);
    let desc = SceneDesc {
        blases: vec![BlasDesc {
            geometries: vec![cell_triangle(true)],
        }],
        instances: vec![InstanceDesc {
            transform: t,
            ..InstanceDesc::identity(0)
        }],
    };
    let device = Device::new();
    for (flags, has_positions) in [
        (
            vk::BuildAccelerationStructureFlagsKHR::ALLOW_DATA_ACCESS,
            true,
        ),
        (vk::BuildAccelerationStructureFlagsKHR::empty(), false),
    ] {
        let built = desc.build(&device, flags, PRESETS[0]).unwrap();
        let scene = device.scene(built.tlas).unwrap();
        let origin = t.point([0.25, 0.75, 1.0]);
        let dir = t.vector([0.0, 0.0, -2.0]);
        let mut q = scene.ray_query(&Ray::new(origin, dir)).unwrap();
        while q.proceed() {
            q.confirm_intersection().unwrap();
        }
        assert_eq!(q.committed_type(), hostas::CommittedType::Triangle);
        assert!(
            (q.committed().t - 0.5).abs() < 1e-4,
            "t is measured along the unnormalized direction"
        );
        assert_eq!(q.object_to_world(true).unwrap(), t);
        let o = q.object_ray_origin(true).unwrap();
        let d = q.object_ray_direction(true).unwrap();
        for k in 0..3 {
            assert!(
                (o[k] - [0.25, 0.75, 1.0][k]).abs() < 1e-3
                    && (d[k] - [0.0, 0.0, -2.0][k]).abs() < 1e-3
            );
        }
        let w2o = q.world_to_object(true).unwrap();
        assert!((w2o.point(origin)[0] - 0.25).abs() < 1e-3);
        match q.triangle_vertex_positions(true) {
            Ok(p) => {
                assert!(has_positions);
                assert_eq!(p, [[0.0, 1.0, 0.0], [0.0, 0.0, 0.0], [1.0, 1.0, 0.0]]);
            }
            Err(e) => {
                assert!(!has_positions);
                assert_eq!(
                    e.vuid_str(),
                    Some(
                        "VUID-RuntimeSpirv-OpRayQueryGetIntersectionTriangleVertexPositionsKHR-08761"
                    )
                );
            }
        }
    }
}

#[test]
fn generate_and_terminate_flow() {
    let boxes = GeometryDesc::Aabbs {
        boxes: vec![
            [0.0, 0.0, -1.0, 1.0, 1.0, -0.5],
            [0.0, 0.0, -3.0, 1.0, 1.0, -2.5],
        ],
        flags: vk::GeometryFlagsKHR::empty(),
    };
    let desc = SceneDesc {
        blases: vec![BlasDesc {
            geometries: vec![boxes],
        }],
        instances: vec![InstanceDesc::identity(0)],
    };
    let device = Device::new();
    let built = desc.build(&device, PRESETS[0], PRESETS[0]).unwrap();
    let scene = device.scene(built.tlas).unwrap();
    let ray = Ray::new([0.5, 0.5, 0.0], [0.0, 0.0, -1.0]);
    // Generate at the far side of each box; the committed hit is the nearer one.
    let mut q = scene.ray_query(&ray).unwrap();
    while q.proceed() {
        assert_eq!(q.candidate_type(), Some(hostas::CandidateType::Aabb));
        let far = if q.candidate().primitive_index == 0 {
            1.0
        } else {
            3.0
        };
        if far <= q.committed().t || q.committed_type() == hostas::CommittedType::None {
            q.generate_intersection(far).unwrap();
        } else {
            assert!(
                q.generate_intersection(far).is_err(),
                "hitT beyond the committed t is rejected"
            );
        }
    }
    assert_eq!(q.committed_type(), hostas::CommittedType::Generated);
    assert_eq!((q.committed().t, q.committed().primitive_index), (1.0, 0));
    // Terminate stops at once.
    let mut q = scene.ray_query(&ray).unwrap();
    assert!(q.proceed());
    q.terminate();
    assert!(!q.proceed());
    assert_eq!(q.committed_type(), hostas::CommittedType::None);
    // Confirm is only for triangles.
    let mut q = scene.ray_query(&ray).unwrap();
    assert!(q.proceed());
    assert!(q.confirm_intersection().is_err());
}

#[test]
fn invalid_rays_are_rejected() {
    let desc = SceneDesc {
        blases: vec![BlasDesc {
            geometries: vec![cell_triangle(true)],
        }],
        instances: vec![InstanceDesc::identity(0)],
    };
    let device = Device::new();
    let built = desc.build(&device, PRESETS[0], PRESETS[0]).unwrap();
    let scene = device.scene(built.tlas).unwrap();
    let bad = [
        Ray {
            t_min: 2.0,
            t_max: 1.0,
            ..Ray::new([0.0; 3], [0.0, 0.0, 1.0])
        },
        Ray::new([f32::NAN, 0.0, 0.0], [0.0, 0.0, 1.0]),
        Ray {
            flags: RayFlags::SKIP_TRIANGLES | RayFlags::SKIP_AABBS,
            ..Ray::new([0.0; 3], [0.0, 0.0, 1.0])
        },
    ];
    for r in bad {
        assert!(matches!(
            scene.trace_closest(&r),
            Err(hostas::Error::Validation { .. })
        ));
    }
}

#[test]
fn batch_tracing_matches_single_rays() {
    let mut r = generate::rng(8);
    let desc = generate::random_scene(&mut r, 500, true);
    let device = Device::new();
    let built = desc.build(&device, PRESETS[0], PRESETS[0]).unwrap();
    let scene = device.scene(built.tlas).unwrap();
    let rays: Vec<Ray> = (0..2000)
        .map(|_| generate::random_ray(&mut r, &desc))
        .collect();
    for any in [false, true] {
        let batch = scene.trace_batch(&rays, any).unwrap();
        for (ray, hit) in rays.iter().zip(&batch) {
            let single = if any {
                scene.trace_any(ray)
            } else {
                scene.trace_closest(ray)
            }
            .unwrap();
            assert_eq!(*hit, single);
        }
    }
}

/// `rays`' closest hits by `tracer.closest_batch_with(rays, mode)` into `hits`, each checked
/// against `Scene::trace_closest` bit for bit (`what` names the batch in a failure).
fn closest_batch_checked<'h>(
    tracer: &mut hostas::Tracer,
    scene: &hostas::Scene,
    rays: &[Ray],
    mode: Interleave,
    hits: &'h mut Vec<hostas::Hit>,
    what: &str,
) -> &'h [hostas::Hit] {
    tracer.closest_batch_with(rays, hits, mode).unwrap();
    assert_eq!(hits.len(), rays.len());
    for (k, (ray, hit)) in rays.iter().zip(hits.iter()).enumerate() {
        let single = scene.trace_closest(ray).unwrap();
        assert_eq!(*hit, single, "{what}, {mode:?}, ray {k}: {ray:?}");
    }
    hits
}

/// `Tracer::closest_batch` gives every ray the hit `Tracer::closest` gives it, and
/// `Tracer::any_batch` the hit `Tracer::any` gives it, bit for bit: on
/// single identity instances of random (and adversarial) triangles, where rays of the common
/// case are walked several at once, and on scenes of many instances and AABBs, where every
/// ray is traced on its own; with random flags (culling and first-hit rays take the one-ray
/// path), cull masks, ranges and axis-aligned directions, for every build preset and for
/// both leaf layouts, in batches of every size up to a few hundred.
#[test]
fn tracer_batches_match_single_rays() {
    let mut r = generate::rng(0xba7c4);
    let mut hit_count = 0;
    let mut first_not_closest = 0;
    for round in 0..24 {
        let adversarial = round % 2 == 1;
        let desc = if round % 4 == 3 {
            generate::random_scene(&mut r, 200, adversarial)
        } else {
            SceneDesc {
                blases: vec![BlasDesc {
                    geometries: vec![generate::random_triangles(
                        &mut r,
                        300 + 40 * round,
                        adversarial,
                    )],
                }],
                instances: vec![InstanceDesc::identity(0)],
            }
        };
        let preset = PRESETS[round % PRESETS.len()];
        let device = Device::new();
        let built = desc.build(&device, preset, preset).unwrap();
        let scene = device.scene(built.tlas).unwrap();
        let rays: Vec<Ray> = (0..700)
            .map(|k| {
                let mut ray = generate::random_ray(&mut r, &desc);
                if k % 5 == 0 {
                    ray.flags = generate::random_flags(&mut r);
                } else if k % 11 == 0 {
                    ray.flags = RayFlags::TERMINATE_ON_FIRST_HIT;
                }
                ray
            })
            .collect();
        let mut tracer = scene.tracer();
        let mut batch = Vec::new();
        let mut at = 0;
        let modes = [Interleave::Always, Interleave::Auto, Interleave::Never];
        for (j, len) in [1, 2, 7, 8, 9, 64, 255, 354].into_iter().enumerate() {
            let rs = &rays[at..at + len];
            at += len;
            let mode = match j % 3 {
                0 => modes[round % 3],
                1 => Interleave::Packets,
                _ => Interleave::Always,
            };
            let what = format!("round {round}, batch of {len}");
            let hits = closest_batch_checked(&mut tracer, &scene, rs, mode, &mut batch, &what);
            hit_count += hits.iter().filter(|h| h.is_hit()).count();
            // First hits: the one the one-ray walk accepts first, not any hit.
            tracer.any_batch_with(rs, &mut batch, mode).unwrap();
            assert_eq!(batch.len(), rs.len());
            for (k, (ray, hit)) in rs.iter().zip(&batch).enumerate() {
                let single = scene.trace_any(ray).unwrap();
                assert_eq!(
                    *hit, single,
                    "any hit: round {round}, {mode:?}, batch of {len}, ray {k}: {ray:?}"
                );
                first_not_closest += usize::from(single != scene.trace_closest(ray).unwrap());
            }
        }
    }
    // The scenes must produce hits, not only misses, and first hits that are not the closest
    // (or the any-hit comparison would not tell the two walks apart).
    assert!(hit_count > 5000, "{hit_count} hits");
    assert!(
        first_not_closest > 500,
        "{first_not_closest} first hits not closest"
    );
}

/// Coherent rays (a camera's, in scanline order, and packets gathered around triangles'
/// vertices, where the triangles that share one may tie) walked in packets
/// (`Interleave::Packets`) get the hit `Tracer::closest` gives each, bit for bit: over random
/// and adversarial triangles, and over two and three copies of one grid (indexed), where every
/// hit ties with its copies. A packet visits nodes in another order than one ray alone, so
/// this rests on the packet noting the rays that meet a tie and tracing them again alone.
/// Every preset; whole images and odd-sized batches.
#[test]
fn packets_match_single_rays() {
    let mut r = generate::rng(0x9ac4e7);
    let mut hit_count = 0;
    let mut tied = 0;
    for round in 0..12 {
        let (desc, origin, corner, span) = if round % 3 == 2 {
            let copies = 2 + round % 2;
            let desc = SceneDesc {
                blases: vec![BlasDesc {
                    geometries: (0..copies).map(|_| generate::grid(12, None)).collect(),
                }],
                instances: vec![InstanceDesc::identity(0)],
            };
            // Above the grid: every other ray meets a vertex or an edge exactly.
            (desc, [6.0, 6.0, 10.0], [0.0, 0.0, 0.0], 12.0)
        } else {
            let tris = generate::random_triangles(&mut r, 400 + 100 * round, round % 2 == 1);
            let desc = SceneDesc {
                blases: vec![BlasDesc {
                    geometries: vec![tris],
                }],
                instances: vec![InstanceDesc::identity(0)],
            };
            let o = [r.gen_range(-3.0..3.0), r.gen_range(-3.0..3.0), 40.0];
            (desc, o, [-15.0, -15.0, 0.0], 30.0)
        };
        let preset = PRESETS[round % PRESETS.len()];
        let device = Device::new();
        let built = desc.build(&device, preset, preset).unwrap();
        let scene = device.scene(built.tlas).unwrap();
        // A 48 x 48 image, its pixels' centres on the plane z = corner[2].
        let w = 48;
        let rays: Vec<Ray> = (0..w * w)
            .map(|k| {
                let (x, y) = ((k % w) as f32, (k / w) as f32);
                let at = [
                    corner[0] + span * x / (w - 1) as f32,
                    corner[1] + span * y / (w - 1) as f32,
                    corner[2],
                ];
                Ray::new(origin, std::array::from_fn(|i| at[i] - origin[i]))
            })
            .chain(vertex_clusters(&mut r, &desc, origin))
            .collect();
        let mut tracer = scene.tracer();
        let mut batch = Vec::new();
        for (mode, len) in [
            (Interleave::Packets, rays.len()),
            (Interleave::Auto, rays.len()),
            (Interleave::Packets, 13),
        ] {
            for rs in rays.chunks(len) {
                let what = format!("round {round}, batch of {len}");
                let hits = closest_batch_checked(&mut tracer, &scene, rs, mode, &mut batch, &what);
                for hit in hits.iter().filter(|h| h.is_hit()) {
                    hit_count += 1;
                    tied += usize::from(hit.t == 1.0 && round % 3 == 2);
                }
            }
        }
    }
    assert!(hit_count > 20_000, "{hit_count} hits");
    // (The grids' rays all end at t = 1: every one ties with its copies.)
    assert!(tied > 10_000, "{tied} tied hits");
}

/// Packets of rays from `origin`: per packet, one ray exactly through a vertex of a random
/// triangle of `desc`'s first geometry (where the triangles sharing it tie) and seven close
/// to it, so that the packet holds together down to the vertex's leaves.
fn vertex_clusters(r: &mut generate::Rand, desc: &SceneDesc, origin: [f32; 3]) -> Vec<Ray> {
    let g = &desc.blases[0].geometries[0];
    let mut rays = Vec::new();
    for _ in 0..256 {
        let Some(tri) = g.triangle(r.gen_range(0..g.primitive_count())) else {
            continue;
        };
        let v = tri[r.gen_range(0..3)];
        // Seven around the vertex, then the vertex itself.
        for k in 0..8 {
            let (a, d) = (k as f32 * 0.9, if k == 7 { 0.0 } else { 0.05 });
            let at = [v[0] + d * a.cos(), v[1] + d * a.sin(), v[2]];
            rays.push(Ray::new(origin, std::array::from_fn(|i| at[i] - origin[i])));
        }
    }
    rays
}

/// A batch with an invalid ray reports that ray's error, as `Tracer::closest` would.
#[test]
fn closest_batch_reports_invalid_rays() {
    let desc = SceneDesc {
        blases: vec![BlasDesc {
            geometries: vec![generate::grid(4, None)],
        }],
        instances: vec![InstanceDesc::identity(0)],
    };
    let device = Device::new();
    let built = desc.build(&device, PRESETS[0], PRESETS[0]).unwrap();
    let scene = device.scene(built.tlas).unwrap();
    let good = Ray::new([0.5, 0.5, 1.0], [0.0, 0.0, -1.0]);
    let bad = Ray::new([f32::NAN, 0.0, 0.0], [0.0, 0.0, 1.0]);
    let mut hits = Vec::new();
    let mut tracer = scene.tracer();
    let single = scene.trace_closest(&bad).unwrap_err();
    let modes = [
        Interleave::Always,
        Interleave::Auto,
        Interleave::Never,
        Interleave::Packets,
    ];
    for mode in modes {
        tracer
            .closest_batch_with(&[good, good], &mut hits, mode)
            .unwrap();
        assert!(hits.iter().all(|h| h.is_hit()));
        let err = tracer
            .closest_batch_with(&[good, bad, good], &mut hits, mode)
            .unwrap_err();
        assert_eq!(err.vuid_str(), single.vuid_str());
        assert_eq!(err.location(), Some(Location::NONE.ray(1)), "{err}");
        assert!(err.to_string().ends_with("(ray 1)"), "{err}");
    }
    // A camera's rows, walked in blocks of 2 x 4 pixels (rays 0, 1, 16, 17, 32, 33, 48, 49
    // first): the first invalid ray in the batch's order is the one reported.
    let mut camera: Vec<Ray> = (0..16 * 8)
        .map(|p| {
            let (x, y) = ((p % 16) as f32, (p / 16) as f32);
            Ray::new([0.5, 0.5, 4.0], [x / 32.0 - 0.25, 0.125 - y / 32.0, -1.0])
        })
        .collect();
    for (i, r) in camera.iter_mut().enumerate() {
        if i == 34 || i == 49 {
            (r.t_min, r.t_max) = (2.0, 1.0);
        }
    }
    let inverted = scene.trace_closest(&camera[34]).unwrap_err();
    for mode in modes {
        let err = tracer
            .closest_batch_with(&camera, &mut hits, mode)
            .unwrap_err();
        assert_eq!(err.vuid_str(), inverted.vuid_str());
        assert_eq!(
            err.location(),
            Some(Location::NONE.ray(34)),
            "{mode:?}: {err}"
        );
    }
    // Across the chunks `trace_batch` splits a batch into, closest and any hit alike.
    let mut rays = vec![good; 5000];
    rays[3333] = bad;
    for any_hit in [false, true] {
        let err = scene.trace_batch(&rays, any_hit).unwrap_err();
        assert_eq!(err.vuid_str(), single.vuid_str());
        assert_eq!(err.location(), Some(Location::NONE.ray(3333)), "{err}");
    }
}

/// Axis-aligned rays exactly through grid vertices and along grid lines: the ray lies in the
/// boundary planes of many boxes (a zero direction component with the origin on a slab plane),
/// which must count as inside.
#[test]
fn axis_aligned_rays_on_box_boundaries() {
    let n = 24;
    let desc = SceneDesc {
        blases: vec![BlasDesc {
            geometries: vec![generate::grid(n, None)],
        }],
        instances: vec![InstanceDesc::identity(0)],
    };
    let device = Device::new();
    for preset in PRESETS {
        let built = desc.build(&device, preset, preset).unwrap();
        let scene = device.scene(built.tlas).unwrap();
        for y in 1..n {
            for x in 1..n {
                for (dir, z) in [
                    ([0.0f32, 0.0, -1.0], 3.0f32),
                    ([0.0, 0.0, 1.0], -3.0),
                    ([-0.0, 0.0, -1.0], 3.0),
                ] {
                    let ray = Ray::new([x as f32, y as f32, z], dir);
                    assert_eq!(
                        count_candidates(&scene, &ray),
                        1,
                        "vertex ({x}, {y}) dir {dir:?} preset {preset:?}"
                    );
                    assert!(scene.trace_closest(&ray).unwrap().is_hit());
                    let ray = Ray::new([x as f32 + 0.5, y as f32, z], dir);
                    assert_eq!(
                        count_candidates(&scene, &ray),
                        1,
                        "edge ({x}.5, {y}) dir {dir:?} preset {preset:?}"
                    );
                }
            }
        }
    }
    // A flat box hit exactly along its plane and at its boundary.
    let boxes = GeometryDesc::Aabbs {
        boxes: vec![[0.0, 0.0, 0.0, 1.0, 1.0, 0.0]],
        flags: vk::GeometryFlagsKHR::OPAQUE,
    };
    let desc = SceneDesc {
        blases: vec![BlasDesc {
            geometries: vec![boxes],
        }],
        instances: vec![InstanceDesc::identity(0)],
    };
    let built = desc.build(&device, PRESETS[0], PRESETS[0]).unwrap();
    let scene = device.scene(built.tlas).unwrap();
    for ray in [
        Ray::new([-1.0, 0.5, 0.0], [1.0, 0.0, 0.0]),
        Ray::new([1.0, 1.0, 2.0], [0.0, 0.0, -1.0]),
        Ray::new([0.0, -1.0, 0.0], [0.0, 1.0, 0.0]),
    ] {
        assert!(scene.trace_closest(&ray).unwrap().is_hit(), "{ray:?}");
    }
}
