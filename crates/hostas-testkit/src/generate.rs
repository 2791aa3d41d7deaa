//! Random and adversarial scenes and rays.

use crate::scene::{BlasDesc, GeometryDesc, InstanceDesc, SceneDesc};
use hostas::{Affine, Ray, RayFlags, vk};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

pub type Rand = Pcg64;

pub fn rng(seed: u64) -> Rand {
    Pcg64::seed_from_u64(seed)
}

fn v3(r: &mut Rand, scale: f32) -> [f32; 3] {
    [
        r.gen_range(-scale..scale),
        r.gen_range(-scale..scale),
        r.gen_range(-scale..scale),
    ]
}

/// The rotation matrix of the unit quaternion `[w, x, y, z]` (rows).
pub fn rotation([w, x, y, z]: [f32; 4]) -> [[f32; 3]; 3] {
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - z * w),
            2.0 * (x * z + y * w),
        ],
        [
            2.0 * (x * y + z * w),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - x * w),
        ],
        [
            2.0 * (x * z - y * w),
            2.0 * (y * z + x * w),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
}

/// A random rotation-scale(-mirror)-translation.
pub fn random_transform(r: &mut Rand, allow_mirror: bool) -> Affine {
    // Random rotation from a random unit quaternion.
    let q: [f32; 4] = loop {
        let q = [
            r.gen_range(-1.0f32..1.0),
            r.gen_range(-1.0..1.0),
            r.gen_range(-1.0..1.0),
            r.gen_range(-1.0..1.0),
        ];
        let n = q.iter().map(|x| x * x).sum::<f32>().sqrt();
        if n > 0.1 {
            break q.map(|x| x / n);
        }
    };
    let rot = rotation([q[0], q[1], q[2], q[3]]);
    let mut s = [
        r.gen_range(0.3f32..3.0),
        r.gen_range(0.3..3.0),
        r.gen_range(0.3..3.0),
    ];
    if allow_mirror && r.gen_bool(0.3) {
        s[r.gen_range(0..3)] *= -1.0;
    }
    let t = v3(r, 10.0);
    let mut m = Affine::IDENTITY;
    for i in 0..3 {
        for j in 0..3 {
            m.m[i][j] = rot[i][j] * s[j];
        }
        m.m[i][3] = t[i];
    }
    m
}

/// Random triangles: a soup with some degenerate, inactive, huge and tiny ones, indexed or not;
/// half of the indexed ones are strips (each triangle shares two vertices with the previous
/// one, as meshes share them, so that builds store them as indexed triangles).
pub fn random_triangles(r: &mut Rand, n: usize, adversarial: bool) -> GeometryDesc {
    let indexed = r.gen_bool(0.5);
    let strip = indexed && r.gen_bool(0.5);
    let mut positions = Vec::new();
    let mut indices = Vec::new();
    for i in 0..n {
        // Adversarial scenes also place some triangles far away (large coordinates).
        let far = if adversarial && r.gen_bool(0.05) {
            1e4
        } else {
            1.0
        };
        let c = v3(r, 10.0).map(|x| x * far);
        let size = if adversarial && r.gen_bool(0.1) {
            [1e-4f32, 1e3, 1.0][r.gen_range(0..3)]
        } else {
            r.gen_range(0.2..3.0)
        };
        let mut tri = [0, 1, 2].map(|_| {
            let d = v3(r, size);
            [c[0] + d[0], c[1] + d[1], c[2] + d[2]]
        });
        if adversarial {
            match r.gen_range(0..20) {
                0 => tri[2] = tri[0], // degenerate: repeated vertex
                1 => {
                    tri[2] = [
                        2.0 * tri[1][0] - tri[0][0],
                        2.0 * tri[1][1] - tri[0][1],
                        2.0 * tri[1][2] - tri[0][2],
                    ]
                } // collinear
                2 => tri[r.gen_range(0..3)][0] = f32::NAN, // inactive
                _ => {}
            }
        }
        if strip && i > 0 {
            let base = positions.len() as u32;
            positions.push(tri[2]);
            indices.extend_from_slice(&[base - 2, base - 1, base]);
        } else if strip {
            positions.extend_from_slice(&tri);
            indices.extend_from_slice(&[0, 1, 2]);
        } else if indexed {
            let base = positions.len() as u32;
            positions.extend_from_slice(&tri);
            // Shuffle the index order a little, and sometimes share vertices with the previous triangle.
            if i > 0 && r.gen_bool(0.2) && !tri[0][0].is_nan() {
                indices.extend_from_slice(&[base - 1, base + 1, base + 2]);
            } else {
                indices.extend_from_slice(&[base, base + 1, base + 2]);
            }
        } else {
            positions.extend_from_slice(&tri);
        }
    }
    let transform = if r.gen_bool(0.3) {
        Some(random_transform(r, true))
    } else {
        None
    };
    let flags = if r.gen_bool(0.5) {
        vk::GeometryFlagsKHR::OPAQUE
    } else {
        vk::GeometryFlagsKHR::empty()
    };
    GeometryDesc::Triangles {
        positions,
        indices,
        transform,
        flags,
    }
}

pub fn random_boxes(r: &mut Rand, n: usize, adversarial: bool) -> GeometryDesc {
    let boxes = (0..n)
        .map(|_| {
            let c = v3(r, 10.0);
            let mut e = [
                r.gen_range(0.05f32..2.0),
                r.gen_range(0.05..2.0),
                r.gen_range(0.05..2.0),
            ];
            if adversarial && r.gen_bool(0.1) {
                e[r.gen_range(0..3)] = 0.0; // flat box
            }
            let mut b = [
                c[0] - e[0],
                c[1] - e[1],
                c[2] - e[2],
                c[0] + e[0],
                c[1] + e[1],
                c[2] + e[2],
            ];
            if adversarial && r.gen_bool(0.05) {
                b[0] = f32::NAN; // inactive
            }
            b
        })
        .collect();
    let flags = if r.gen_bool(0.5) {
        vk::GeometryFlagsKHR::OPAQUE
    } else {
        vk::GeometryFlagsKHR::empty()
    };
    GeometryDesc::Aabbs { boxes, flags }
}

/// A random scene: a few BLASes (triangles or boxes, several geometries each) and instances
/// with random transforms (mirrors included), masks, flags, and inactive ones.
pub fn random_scene(r: &mut Rand, prims_per_blas: usize, adversarial: bool) -> SceneDesc {
    let nb = r.gen_range(1..4);
    let blases = (0..nb)
        .map(|_| {
            let aabbs = r.gen_bool(0.3);
            let ng = r.gen_range(1..4);
            BlasDesc {
                geometries: (0..ng)
                    .map(|_| {
                        let n = r.gen_range(0..=prims_per_blas);
                        if aabbs {
                            random_boxes(r, n, adversarial)
                        } else {
                            random_triangles(r, n, adversarial)
                        }
                    })
                    .collect(),
            }
        })
        .collect();
    let ni = r.gen_range(1..6);
    let instances = (0..ni)
        .map(|i| {
            let flag_bits = [
                vk::GeometryInstanceFlagsKHR::TRIANGLE_FACING_CULL_DISABLE,
                vk::GeometryInstanceFlagsKHR::TRIANGLE_FLIP_FACING,
                vk::GeometryInstanceFlagsKHR::FORCE_OPAQUE,
                vk::GeometryInstanceFlagsKHR::FORCE_NO_OPAQUE,
            ];
            let mut flags = vk::GeometryInstanceFlagsKHR::empty();
            for f in flag_bits {
                if r.gen_bool(0.25) {
                    flags |= f;
                }
            }
            if flags.contains(
                vk::GeometryInstanceFlagsKHR::FORCE_OPAQUE
                    | vk::GeometryInstanceFlagsKHR::FORCE_NO_OPAQUE,
            ) {
                flags &= !vk::GeometryInstanceFlagsKHR::FORCE_NO_OPAQUE;
            }
            InstanceDesc {
                transform: if i == 0 || r.gen_bool(0.3) {
                    Affine::IDENTITY
                } else {
                    random_transform(r, true)
                },
                custom_index: 0x807f00 + i as u32,
                mask: if r.gen_bool(0.7) {
                    0xff
                } else {
                    r.r#gen::<u8>()
                },
                sbt_record_offset: r.gen_range(0..1 << 24),
                flags,
                blas: if adversarial && r.gen_bool(0.15) {
                    None
                } else {
                    Some(r.gen_range(0..nb))
                },
            }
        })
        .collect();
    SceneDesc { blases, instances }
}

/// Valid random ray flags: at most one of each exclusive group.
pub fn random_flags(r: &mut Rand) -> RayFlags {
    let mut f = RayFlags::NONE;
    let opacity = [
        RayFlags::NONE,
        RayFlags::OPAQUE,
        RayFlags::NO_OPAQUE,
        RayFlags::CULL_OPAQUE,
        RayFlags::CULL_NO_OPAQUE,
    ];
    f = f | opacity[r.gen_range(0..opacity.len())];
    let cull = [
        RayFlags::NONE,
        RayFlags::NONE,
        RayFlags::CULL_BACK_FACING_TRIANGLES,
        RayFlags::CULL_FRONT_FACING_TRIANGLES,
        RayFlags::SKIP_TRIANGLES,
    ];
    let c = cull[r.gen_range(0..cull.len())];
    f = f | c;
    if c != RayFlags::SKIP_TRIANGLES && r.gen_bool(0.15) {
        f = f | RayFlags::SKIP_AABBS;
    }
    f
}

/// A ray through the scene's region: random, or aimed exactly at a vertex, an edge point or a
/// box corner of some primitive (in the instance's world space).
pub fn random_ray(r: &mut Rand, scene: &SceneDesc) -> Ray {
    let origin = v3(r, 25.0);
    let target: [f32; 3] = match r.gen_range(0..3) {
        0 => v3(r, 12.0),
        _ => {
            // A feature of a random primitive.
            let inst = &scene.instances[r.gen_range(0..scene.instances.len())];
            let Some(b) = inst.blas else {
                return Ray::new(origin, v3(r, 1.0));
            };
            let geoms = &scene.blases[b].geometries;
            let g = &geoms[r.gen_range(0..geoms.len())];
            let n = g.primitive_count();
            if n == 0 {
                v3(r, 12.0)
            } else {
                let p = r.gen_range(0..n);
                let local = match g {
                    GeometryDesc::Triangles { .. } => match g.triangle(p) {
                        Some(v) => {
                            let k = r.gen_range(0..3);
                            if r.gen_bool(0.5) {
                                v[k]
                            } else {
                                let j = (k + 1) % 3;
                                [
                                    0.5 * (v[k][0] + v[j][0]),
                                    0.5 * (v[k][1] + v[j][1]),
                                    0.5 * (v[k][2] + v[j][2]),
                                ]
                            }
                        }
                        None => v3(r, 12.0),
                    },
                    GeometryDesc::Aabbs { boxes, .. } => {
                        let bx = boxes[p as usize];
                        [
                            if r.gen_bool(0.5) { bx[0] } else { bx[3] },
                            if r.gen_bool(0.5) { bx[1] } else { bx[4] },
                            if r.gen_bool(0.5) { bx[2] } else { bx[5] },
                        ]
                    }
                };
                inst.transform.point(local)
            }
        }
    };
    let mut dir = [
        target[0] - origin[0],
        target[1] - origin[1],
        target[2] - origin[2],
    ];
    if r.gen_bool(0.1) {
        // In the planes of the boxes' slabs (a zero component, of either sign): the
        // traversal's general node test, where a slab distance is 0 x inf.
        let k = r.gen_range(0..3);
        dir[k] = if r.gen_bool(0.5) { 0.0 } else { -0.0 };
        if r.gen_bool(0.3) {
            dir[(k + 1) % 3] = 0.0;
        }
    }
    if dir == [0.0; 3] || dir.iter().any(|v| !v.is_finite()) {
        dir = [0.0, 0.0, 1.0];
    }
    let t_min = if r.gen_bool(0.2) {
        r.gen_range(0.0..0.5)
    } else {
        0.0
    };
    let t_max = if r.gen_bool(0.3) {
        r.gen_range(0.5..2.0)
    } else {
        f32::INFINITY
    };
    Ray {
        origin,
        t_min,
        direction: dir,
        t_max: t_max.max(t_min),
        flags: RayFlags::NONE,
        cull_mask: if r.gen_bool(0.8) {
            0xff
        } else {
            r.r#gen::<u8>() as u32
        },
    }
}

/// A regular grid of `n` x `n` cells, two triangles per cell, consistent winding, z = 0,
/// spanning [0, n] in x and y (closed in the interior: no ray may miss or hit twice).
pub fn grid(n: u32, transform: Option<Affine>) -> GeometryDesc {
    let mut positions = Vec::new();
    for y in 0..=n {
        for x in 0..=n {
            positions.push([x as f32, y as f32, 0.0]);
        }
    }
    let mut indices = Vec::new();
    let id = |x: u32, y: u32| y * (n + 1) + x;
    for y in 0..n {
        for x in 0..n {
            indices.extend_from_slice(&[
                id(x, y),
                id(x + 1, y),
                id(x + 1, y + 1),
                id(x, y),
                id(x + 1, y + 1),
                id(x, y + 1),
            ]);
        }
    }
    GeometryDesc::Triangles {
        positions,
        indices,
        transform,
        flags: vk::GeometryFlagsKHR::empty(),
    }
}

/// A closed fan of `k` triangles around `center` (radius 1, z = center z), consistent winding.
pub fn fan(center: [f32; 3], k: u32, r: &mut Rand) -> GeometryDesc {
    let mut angles: Vec<f32> = (0..k)
        .map(|i| (i as f32 + r.gen_range(-0.3..0.3)) / k as f32 * std::f32::consts::TAU)
        .collect();
    angles.sort_by(f32::total_cmp);
    let mut positions = vec![center];
    for a in &angles {
        positions.push([center[0] + a.cos(), center[1] + a.sin(), center[2]]);
    }
    let mut indices = Vec::new();
    for i in 0..k {
        indices.extend_from_slice(&[0, 1 + i, 1 + (i + 1) % k]);
    }
    GeometryDesc::Triangles {
        positions,
        indices,
        transform: None,
        flags: vk::GeometryFlagsKHR::empty(),
    }
}

/// A latitude/longitude sphere of radius 1: `(n + 1) x (2n + 1)` vertices, `4n^2` triangles.
/// The benchmark examples' default scene.
pub fn uv_sphere(n: u32) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let mut p = Vec::new();
    let mut idx = Vec::new();
    for i in 0..=n {
        let th = std::f32::consts::PI * i as f32 / n as f32;
        for j in 0..=2 * n {
            let ph = std::f32::consts::PI * j as f32 / n as f32;
            p.push([th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos()]);
        }
    }
    let w = 2 * n + 1;
    for i in 0..n {
        for j in 0..2 * n {
            let a = i * w + j;
            idx.push([a, a + w, a + 1]);
            idx.push([a + 1, a + w, a + w + 1]);
        }
    }
    (p, idx)
}
