//! Traversal against the brute-force oracle, over random and adversarial scenes (triangles,
//! boxes, instances with mirrors, flags, masks, inactive objects, degenerate triangles, huge
//! and tiny sizes) and rays (random, and exactly through vertices, edges and box corners), for
//! every build preset of both levels.

use hostas::{Device, HitKind, Ray, RayFlags, vk};
use hostas_testkit::generate::{self, Rand};
use hostas_testkit::oracle::CandidateKind;
use hostas_testkit::{Oracle, SceneDesc};
use proptest::prelude::*;
use rand::Rng;

const PRESETS: [vk::BuildAccelerationStructureFlagsKHR; 4] = [
    vk::BuildAccelerationStructureFlagsKHR::PREFER_FAST_TRACE,
    vk::BuildAccelerationStructureFlagsKHR::PREFER_FAST_BUILD,
    vk::BuildAccelerationStructureFlagsKHR::empty(),
    vk::BuildAccelerationStructureFlagsKHR::LOW_MEMORY,
];

/// AABB candidates may be reported for near misses (the spec lets implementations grow boxes);
/// this is how near.
const AABB_EPS: f64 = 1e-5;

/// Checks the committed closest hit and the candidate set of `rays` rays against the oracle.
fn check_scene(
    seed: u64,
    desc: &SceneDesc,
    rays: usize,
    r: &mut Rand,
) -> Result<(), TestCaseError> {
    let device = Device::new();
    let oracle = Oracle::new(desc);
    for (pi, preset) in PRESETS.iter().enumerate() {
        let tlas_preset = PRESETS[(pi + seed as usize) % 4];
        let built = desc
            .build(&device, *preset, tlas_preset)
            .map_err(|e| TestCaseError::fail(format!("build: {e}")))?;
        let scene = device
            .scene(built.tlas)
            .map_err(|e| TestCaseError::fail(format!("scene: {e}")))?;
        for _ in 0..rays {
            let mut ray = generate::random_ray(r, desc);
            ray.flags = generate::random_flags(r);
            check_closest(&scene, &oracle, &ray, preset)?;
            check_candidates(&scene, &oracle, &ray, preset)?;
            check_opaque_only(&scene, &oracle, &ray, preset)?;
            check_first_hit(&scene, &oracle, &ray, preset)?;
        }
    }
    Ok(())
}

fn check_closest(
    scene: &hostas::Scene,
    oracle: &Oracle,
    ray: &Ray,
    preset: &vk::BuildAccelerationStructureFlagsKHR,
) -> Result<(), TestCaseError> {
    let hit = scene
        .trace_closest(ray)
        .map_err(|e| TestCaseError::fail(format!("trace: {e}")))?;
    // The batch tracer and the ray-query state machine (accepting everything) agree exactly.
    let via_query = scene
        .trace_with(ray, |_| true, |q| Some(q.candidate().t))
        .map_err(|e| TestCaseError::fail(format!("query: {e}")))?;
    prop_assert_eq!(hit, via_query, "tracer and ray query differ for {:?}", ray);
    let expected = oracle.closest(ray);
    match (hit.kind, expected) {
        (HitKind::Miss, None) => {}
        (HitKind::Miss, Some((t, c))) => {
            // Only a near-miss box may be missed... no: boxes are never missed, triangles never.
            prop_assert!(
                false,
                "preset {preset:?}: hostas missed, oracle hit {:?} at t {t} for {ray:?}",
                c[0]
            );
        }
        (_, None) => {
            // Allowed only for a box the oracle sees as a near miss.
            let near = oracle.candidates(ray, AABB_EPS);
            prop_assert!(
                hit.kind == HitKind::Generated
                    && near.iter().any(|c| c.kind == CandidateKind::Aabb
                        && c.primitive_index == hit.primitive_index),
                "preset {preset:?}: hostas hit {hit:?}, oracle misses, for {ray:?}"
            );
        }
        (kind, Some((t, tied))) => {
            let key = (hit.instance_id, hit.geometry_index, hit.primitive_index);
            if kind == HitKind::Triangle {
                prop_assert_eq!(
                    hit.t as f64,
                    t,
                    "preset {:?}: t differs for {:?}: hostas {:?}, oracle {:?}",
                    preset,
                    ray,
                    hit,
                    tied
                );
                prop_assert!(
                    tied.iter().any(|c| c.key() == key),
                    "preset {preset:?}: hit {hit:?} is not among the oracle's closest {tied:?}"
                );
                let c = tied.iter().find(|c| c.key() == key).unwrap();
                prop_assert_eq!(hit.barycentrics, c.barycentrics);
                prop_assert_eq!(hit.front_face, c.front_face);
            } else {
                // A box hit: the oracle's closest, or a near-miss box the implementation may
                // report (boxes may be enlarged), never farther than the oracle's closest.
                let near = oracle.candidates(ray, AABB_EPS);
                prop_assert!(
                    near.iter().any(|c| c.key() == key),
                    "preset {preset:?}: box hit {hit:?} is not even a near candidate for {ray:?}"
                );
                prop_assert!(
                    hit.t as f64 <= t * (1.0 + AABB_EPS) + AABB_EPS,
                    "preset {preset:?}: box hit {hit:?} is farther than the oracle's closest t {t}"
                );
            }
        }
    }
    Ok(())
}

/// An any-hit that rejects everything and an intersection that reports only opaque boxes:
/// the committed hit is the closest opaque candidate, so opacity resolution is observed.
fn check_opaque_only(
    scene: &hostas::Scene,
    oracle: &Oracle,
    ray: &Ray,
    preset: &vk::BuildAccelerationStructureFlagsKHR,
) -> Result<(), TestCaseError> {
    let hit = scene
        .trace_with(
            ray,
            |_| false,
            |q| q.candidate().opaque.then_some(q.candidate().t),
        )
        .map_err(|e| TestCaseError::fail(format!("{e}")))?;
    let cands: Vec<_> = oracle
        .candidates(ray, 0.0)
        .into_iter()
        .filter(|c| c.opaque)
        .collect();
    let near: Vec<_> = oracle
        .candidates(ray, AABB_EPS)
        .into_iter()
        .filter(|c| c.opaque)
        .collect();
    let best = cands.iter().map(|c| c.t).fold(f64::INFINITY, f64::min);
    match hit.kind {
        HitKind::Miss => prop_assert!(
            best == f64::INFINITY,
            "preset {preset:?}: missed the opaque candidate at {best} for {ray:?}"
        ),
        HitKind::Triangle => {
            prop_assert_eq!(hit.t as f64, best);
            let key = (hit.instance_id, hit.geometry_index, hit.primitive_index);
            prop_assert!(
                cands
                    .iter()
                    .any(|c| c.key() == key && c.t == best && c.kind == CandidateKind::Triangle)
            );
        }
        HitKind::Generated => {
            let key = (hit.instance_id, hit.geometry_index, hit.primitive_index);
            prop_assert!(
                near.iter().any(|c| c.key() == key),
                "preset {preset:?}: {hit:?} is not an opaque box candidate"
            );
            prop_assert!(hit.t as f64 <= best * (1.0 + AABB_EPS) + AABB_EPS);
        }
    }
    Ok(())
}

/// `TerminateOnFirstHit`: whatever is committed must be one of the oracle's candidates.
fn check_first_hit(
    scene: &hostas::Scene,
    oracle: &Oracle,
    ray: &Ray,
    preset: &vk::BuildAccelerationStructureFlagsKHR,
) -> Result<(), TestCaseError> {
    let hit = scene
        .trace_any(ray)
        .map_err(|e| TestCaseError::fail(format!("{e}")))?;
    let cands = oracle.candidates(ray, 0.0);
    let near = oracle.candidates(ray, AABB_EPS);
    let key = (hit.instance_id, hit.geometry_index, hit.primitive_index);
    match hit.kind {
        HitKind::Miss => prop_assert!(
            cands.is_empty(),
            "preset {preset:?}: any-hit missed {} candidates",
            cands.len()
        ),
        HitKind::Triangle => {
            prop_assert!(cands.iter().any(|c| c.key() == key && c.t == hit.t as f64))
        }
        HitKind::Generated => prop_assert!(near.iter().any(|c| c.key() == key)),
    }
    Ok(())
}

/// With every candidate made non-opaque and none confirmed, `proceed` must return exactly the
/// oracle's candidates (order aside).
fn check_candidates(
    scene: &hostas::Scene,
    oracle: &Oracle,
    ray: &Ray,
    preset: &vk::BuildAccelerationStructureFlagsKHR,
) -> Result<(), TestCaseError> {
    let mut ray = *ray;
    let opacity = RayFlags::OPAQUE.0
        | RayFlags::NO_OPAQUE.0
        | RayFlags::CULL_OPAQUE.0
        | RayFlags::CULL_NO_OPAQUE.0;
    ray.flags = RayFlags((ray.flags.0 & !opacity) | RayFlags::NO_OPAQUE.0);
    let mut q = scene
        .ray_query(&ray)
        .map_err(|e| TestCaseError::fail(format!("{e}")))?;
    let mut got = Vec::new();
    while q.proceed() {
        got.push(*q.candidate());
    }
    prop_assert_eq!(q.committed_type(), hostas::CommittedType::None);
    let exact = oracle.candidates(&ray, 0.0);
    let near = oracle.candidates(&ray, AABB_EPS);
    for c in &exact {
        let found = got
            .iter()
            .filter(|g| (g.instance_id, g.geometry_index, g.primitive_index) == c.key())
            .count();
        prop_assert_eq!(
            found,
            1,
            "preset {:?}: oracle candidate {:?} reported {} times for {:?}",
            preset,
            c,
            found,
            ray
        );
        let g = got
            .iter()
            .find(|g| (g.instance_id, g.geometry_index, g.primitive_index) == c.key())
            .unwrap();
        if c.kind == CandidateKind::Triangle {
            prop_assert_eq!(g.candidate_type(), Some(hostas::CandidateType::Triangle));
            prop_assert_eq!(g.t as f64, c.t);
            prop_assert_eq!(g.front_face, c.front_face);
            prop_assert_eq!(g.barycentrics, c.barycentrics);
        } else {
            prop_assert_eq!(g.candidate_type(), Some(hostas::CandidateType::Aabb));
        }
        prop_assert_eq!(g.opaque, c.opaque);
        let inst = oracle_instance(oracle, c.instance_id);
        prop_assert_eq!(g.instance_custom_index, inst.0);
        prop_assert_eq!(g.sbt_record_offset, inst.1);
    }
    for g in &got {
        let key = (g.instance_id, g.geometry_index, g.primitive_index);
        let ok = exact.iter().any(|c| c.key() == key)
            || (g.candidate_type() == Some(hostas::CandidateType::Aabb)
                && near.iter().any(|c| c.key() == key));
        prop_assert!(
            ok,
            "preset {preset:?}: hostas candidate {g:?} is not an oracle candidate for {ray:?}"
        );
    }
    Ok(())
}

thread_local! {
    static CURRENT: std::cell::RefCell<Vec<(u32, u32)>> = const { std::cell::RefCell::new(Vec::new()) };
}

fn oracle_instance(_o: &Oracle, id: u32) -> (u32, u32) {
    CURRENT.with(|c| c.borrow()[id as usize])
}

fn run(seed: u64, prims: usize, adversarial: bool, rays: usize) -> Result<(), TestCaseError> {
    let mut r = generate::rng(seed);
    let desc = generate::random_scene(&mut r, prims, adversarial);
    run_desc(seed, desc, rays, &mut r)
}

/// A random bottom level under a top level of one identity instance (random mask, flags and
/// ids): the batch tracer goes straight to that instance, the ray query through the top level.
fn run_single(
    seed: u64,
    prims: usize,
    adversarial: bool,
    rays: usize,
) -> Result<(), TestCaseError> {
    let mut r = generate::rng(seed);
    let mut desc = generate::random_scene(&mut r, prims, adversarial);
    desc.blases.truncate(1);
    let mut only = hostas_testkit::InstanceDesc::identity(0);
    only.custom_index = r.gen_range(0..1 << 24);
    only.sbt_record_offset = r.gen_range(0..1 << 24);
    only.mask = if r.gen_bool(0.8) { 0xff } else { r.r#gen() };
    // Any of the four instance flags, but not FORCE_OPAQUE with FORCE_NO_OPAQUE (invalid).
    let flags = r.gen_range(0..16u32);
    only.flags = vk::GeometryInstanceFlagsKHR::from_raw(if flags & 0xc == 0xc {
        flags & !0x8
    } else {
        flags
    });
    desc.instances = vec![only];
    run_desc(seed, desc, rays, &mut r)
}

fn run_desc(seed: u64, desc: SceneDesc, rays: usize, r: &mut Rand) -> Result<(), TestCaseError> {
    CURRENT.with(|c| {
        *c.borrow_mut() = desc
            .instances
            .iter()
            .map(|i| (i.custom_index, i.sbt_record_offset))
            .collect()
    });
    check_scene(seed, &desc, rays, r)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn random_scenes_match_oracle(seed in any::<u64>()) {
        run(seed, 60, false, 60)?;
    }

    #[test]
    fn adversarial_scenes_match_oracle(seed in any::<u64>()) {
        run(seed, 60, true, 60)?;
    }

    #[test]
    fn single_identity_instance_scenes_match_oracle(seed in any::<u64>()) {
        run_single(seed, 60, seed % 2 == 1, 60)?;
    }
}

/// Larger scenes (deep trees, many leaves) with fewer rays.
#[test]
fn larger_scenes_match_oracle() {
    for seed in 0..4u64 {
        run(1000 + seed, 3000, seed % 2 == 1, 150).unwrap();
    }
}

/// Many coincident triangles: binning cannot split them; depth must stay bounded.
#[test]
fn coincident_primitives() {
    let mut r = generate::rng(7);
    let tri = [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    let positions: Vec<[f32; 3]> = (0..3000).flat_map(|_| tri).collect();
    let desc = SceneDesc {
        blases: vec![hostas_testkit::BlasDesc {
            geometries: vec![hostas_testkit::GeometryDesc::Triangles {
                positions,
                indices: vec![],
                transform: None,
                flags: vk::GeometryFlagsKHR::empty(),
            }],
        }],
        instances: vec![hostas_testkit::InstanceDesc::identity(0)],
    };
    CURRENT.with(|c| *c.borrow_mut() = vec![(0, 0)]);
    let device = Device::new();
    for preset in PRESETS {
        let built = desc.build(&device, preset, preset).unwrap();
        assert!(device.statistics(built.blases[0]).unwrap().depth <= hostas::layout::MAX_DEPTH);
        let scene = device.scene(built.tlas).unwrap();
        let oracle = Oracle::new(&desc);
        for _ in 0..20 {
            let ray = Ray::new(
                [r.gen_range(0.0..0.5), r.gen_range(0.0..0.5), 1.0],
                [0.0, 0.0, -1.0],
            );
            check_candidates(&scene, &oracle, &ray, &preset).unwrap();
            // Every node box and every hit ties here: the batch tracer must visit children
            // in exactly the ray query's order to report the same one of the 3000.
            check_closest(&scene, &oracle, &ray, &preset).unwrap();
            let slanted = Ray::new(
                [r.gen_range(0.0..0.5), r.gen_range(0.0..0.5), 1.0],
                [r.gen_range(-0.2..0.2), r.gen_range(-0.2..0.2), -1.0],
            );
            check_closest(&scene, &oracle, &slanted, &preset).unwrap();
        }
    }
}

/// Two and three copies of one grid (as separate geometries): every hit ties with its copies,
/// and the copies' boxes tie, so nodes have two or three hit children at the same distance.
/// Which copy is reported depends only on the order children are visited in: the batch
/// tracer and the ray query must report the same one (they share `query::descend`; this
/// failed when the tracer had its own ordering with the tie rule flipped).
#[test]
fn duplicated_grids_tie_in_the_same_order() {
    let mut r = generate::rng(11);
    let device = Device::new();
    for copies in [2, 3] {
        let desc = SceneDesc {
            blases: vec![hostas_testkit::BlasDesc {
                geometries: (0..copies).map(|_| generate::grid(12, None)).collect(),
            }],
            instances: vec![hostas_testkit::InstanceDesc::identity(0)],
        };
        CURRENT.with(|c| *c.borrow_mut() = vec![(0, 0)]);
        let oracle = Oracle::new(&desc);
        for preset in PRESETS {
            let built = desc.build(&device, preset, preset).unwrap();
            let scene = device.scene(built.tlas).unwrap();
            for _ in 0..200 {
                let ray = Ray::new(
                    [r.gen_range(0.0..12.0), r.gen_range(0.0..12.0), 1.0],
                    [r.gen_range(-0.3..0.3), r.gen_range(-0.3..0.3), -1.0],
                );
                check_closest(&scene, &oracle, &ray, &preset).unwrap();
            }
        }
    }
}

/// A scene large enough for the builders' parallel paths (parallel binning, partitioning and
/// encoding of big ranges), checked on fewer rays.
#[test]
fn large_blas_matches_oracle() {
    let mut r = generate::rng(99);
    let desc = SceneDesc {
        blases: vec![hostas_testkit::BlasDesc {
            geometries: vec![
                generate::random_triangles(&mut r, 100_000, true),
                generate::random_triangles(&mut r, 10_000, false),
            ],
        }],
        instances: vec![
            hostas_testkit::InstanceDesc::identity(0),
            hostas_testkit::InstanceDesc {
                transform: generate::random_transform(&mut r, true),
                ..hostas_testkit::InstanceDesc::identity(0)
            },
        ],
    };
    CURRENT.with(|c| {
        *c.borrow_mut() = desc
            .instances
            .iter()
            .map(|i| (i.custom_index, i.sbt_record_offset))
            .collect()
    });
    let device = Device::new();
    let oracle = Oracle::new(&desc);
    for preset in PRESETS {
        let built = desc.build(&device, preset, preset).unwrap();
        let scene = device.scene(built.tlas).unwrap();
        for _ in 0..12 {
            let mut ray = generate::random_ray(&mut r, &desc);
            ray.flags = generate::random_flags(&mut r);
            check_closest(&scene, &oracle, &ray, &preset).unwrap();
            check_candidates(&scene, &oracle, &ray, &preset).unwrap();
        }
    }
}

/// Seeds whose scenes (strips: triangles in different leaves sharing a vertex) sent a ray
/// through a shared vertex where the two triangles' hits differ by an ulp: the nearer one's box
/// had an entry distance rounded past the farther hit and was pruned, so the farther hit was
/// reported. Boxes are now pruned with a little slack (`query::prune_limit`).
#[test]
fn rays_through_shared_vertices_find_the_nearer_hit() {
    for seed in [
        6349006236474401650u64,
        10696786310483891125,
        10989639710171845159,
        15409750116442605428,
    ] {
        run(seed, 60, false, 60).unwrap();
    }
    for seed in [8187941389045683500u64, 17392648709487903280] {
        run_single(seed, 60, seed % 2 == 1, 60).unwrap();
    }
}
