//! Seed inputs made with the current build: real structures serialized by hostas (for
//! `deserialize`) and scene seeds (for `ray_query`). `examples/make_seeds.rs` writes them to
//! `corpus/`; the regression test also makes them afresh, so that the deserialize checks keep
//! running on valid data when the layout version (part of the compatibility UUID) changes and
//! the committed seeds become merely "incompatible".

use hostas::{Aabb, Device, vk};
use hostas_testkit::generate;
use hostas_testkit::{BlasDesc, GeometryDesc, InstanceDesc, SceneDesc};

/// Named serialized structures: triangle BLASes for each build preset (several geometries,
/// indexed and not, a transform), an AABB BLAS with ALLOW_UPDATE, an empty BLAS, a TLAS with
/// active and inactive instances.
pub fn deserialize_seeds() -> Vec<(String, Vec<u8>)> {
    use vk::BuildAccelerationStructureFlagsKHR as F;
    let device = Device::new();
    let mut out = Vec::new();
    let mut r = generate::rng(7);
    let tri = generate::random_triangles(&mut r, 12, true);
    let grid = generate::grid(3, Some(generate::random_transform(&mut r, true)));
    let single = GeometryDesc::Triangles {
        positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        indices: vec![],
        transform: None,
        flags: vk::GeometryFlagsKHR::OPAQUE,
    };
    let soup = BlasDesc {
        geometries: vec![tri, grid, single],
    };
    let presets = [
        (
            F::ALLOW_UPDATE | F::ALLOW_COMPACTION | F::ALLOW_DATA_ACCESS,
            "default",
        ),
        (F::PREFER_FAST_BUILD | F::ALLOW_UPDATE, "fast-build"),
        (F::PREFER_FAST_TRACE, "fast-trace"),
        (F::LOW_MEMORY | F::ALLOW_COMPACTION, "low-memory"),
    ];
    let mut blases = Vec::new();
    for (flags, name) in presets {
        let b = soup.build(&device, flags).expect("seed BLAS");
        out.push((
            format!("blas-triangles-{name}"),
            device.serialize(b).expect("serialize"),
        ));
        blases.push(b);
    }
    let boxes: Vec<Aabb> = (0..60)
        .map(|i| {
            let c = [(i % 8) as f32, (i / 8) as f32, (i % 3) as f32 * 0.5];
            Aabb {
                lo: c,
                hi: [c[0] + 0.75, c[1] + 0.5, c[2] + 0.25],
            }
        })
        .collect();
    let ab = hostas::quick::build_aabb_blas(
        &device,
        &boxes,
        vk::GeometryFlagsKHR::empty(),
        F::ALLOW_UPDATE | F::ALLOW_COMPACTION,
    )
    .expect("seed boxes");
    out.push((
        "blas-aabbs-update".into(),
        device.serialize(ab).expect("serialize"),
    ));
    let empty = BlasDesc {
        geometries: vec![GeometryDesc::Aabbs {
            boxes: vec![],
            flags: vk::GeometryFlagsKHR::OPAQUE,
        }],
    };
    let eb = empty.build(&device, F::ALLOW_UPDATE).expect("seed empty");
    out.push((
        "blas-empty".into(),
        device.serialize(eb).expect("serialize"),
    ));
    let scene = SceneDesc {
        blases: vec![soup.clone(), BlasDesc { geometries: vec![] }],
        instances: vec![
            InstanceDesc::identity(0),
            InstanceDesc {
                transform: generate::random_transform(&mut r, true),
                mask: 0x3,
                custom_index: 7,
                ..InstanceDesc::identity(0)
            },
            InstanceDesc {
                blas: None,
                ..InstanceDesc::identity(0)
            },
            InstanceDesc {
                flags: vk::GeometryInstanceFlagsKHR::FORCE_NO_OPAQUE,
                ..InstanceDesc::identity(1)
            },
        ],
    };
    let tl = scene
        .build_tlas(&device, &[blases[0], ab], F::ALLOW_UPDATE)
        .expect("seed TLAS");
    out.push((
        "tlas-4-instances".into(),
        device.serialize(tl).expect("serialize"),
    ));
    out
}

/// Scene seeds: seed, primitives per BLAS, adversarial, data access, presets, then rays and
/// decisions (see `ray_query::run`).
pub fn ray_query_seeds() -> Vec<(String, Vec<u8>)> {
    [1u64, 42, 1234, 99_999]
        .iter()
        .enumerate()
        .map(|(i, seed)| {
            let mut b = seed.to_le_bytes().to_vec();
            b.extend_from_slice(&[
                (10 + 9 * i) as u8,
                (i % 2) as u8,
                ((i / 2) % 2) as u8,
                i as u8,
                (i + 1) as u8,
                5,
            ]);
            b.extend((0..48).map(|k| ((k * 37 + i * 11) % 251) as u8));
            (format!("scene-{seed}"), b)
        })
        .collect()
}

/// Deterministic corruptions of `bytes`: byte flips, nasty u32 and u64 values, truncations.
pub fn mutations(bytes: &[u8], count: usize, seed: u64) -> Vec<Vec<u8>> {
    let mut x = seed ^ 0x9e37_79b9_7f4a_7c15;
    let mut next = move || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        x
    };
    (0..count)
        .map(|i| {
            let mut b = bytes.to_vec();
            if b.len() < 64 {
                return b;
            }
            match i % 5 {
                0 => {
                    let n = next() as usize % b.len();
                    b.truncate(n);
                }
                1 => {
                    for _ in 0..1 + next() % 4 {
                        let at = 32 + next() as usize % (b.len() - 32);
                        b[at] ^= 1 << (next() % 8);
                    }
                }
                2 | 3 => {
                    // A u32 field of the header or the first sections.
                    let at = 32 + 4 * (next() as usize % ((b.len() - 36) / 4).min(200));
                    let v: u32 = [
                        0,
                        1,
                        2,
                        3,
                        u32::MAX,
                        0x8000_0000,
                        0x7fff_ffff,
                        64,
                        256,
                        1 << 24,
                        next() as u32,
                    ][next() as usize % 11];
                    b[at..at + 4].copy_from_slice(&v.to_le_bytes());
                }
                _ => {
                    let at = 32 + next() as usize % (b.len() - 40);
                    b[at..at + 8].copy_from_slice(&next().to_le_bytes());
                }
            }
            b
        })
        .collect()
}
