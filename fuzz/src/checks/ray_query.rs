//! Target `ray_query`: a random scene from the testkit generator (seeded by the input), rays
//! from the generator with fuzz-chosen changes (flags, ranges, origins and directions, valid or
//! not), and a ray query driven by fuzz-chosen decisions (confirm, generate at any t,
//! terminate, skip, calls that are not allowed).
//!
//! Checks against the brute-force oracle of `hostas-testkit`: invalid rays are refused; every
//! candidate is one the oracle sees (triangles with the same t, barycentrics and facing; boxes
//! at least as near misses), offered once, with its instance's ids, transforms and (with
//! ALLOW_DATA_ACCESS) vertices; opaque triangles are never offered; refused calls change
//! nothing; the committed hit is in range and is one of the candidates (or an opaque triangle);
//! when the query ran to the end, no opaque triangle nearer than the committed hit was passed
//! over and every nearer non-opaque candidate was offered; when every candidate was accepted,
//! the committed hit is the oracle's closest.

use super::source::Source;
use hostas::{CandidateType, CommittedType, Device, Ray, RayFlags, vk};
use hostas_testkit::generate;
use hostas_testkit::oracle::CandidateKind;
use hostas_testkit::{GeometryDesc, Oracle, SceneDesc};
use std::collections::HashSet;

const AABB_EPS: f64 = 1e-5;

const PRESETS: [vk::BuildAccelerationStructureFlagsKHR; 4] = [
    vk::BuildAccelerationStructureFlagsKHR::PREFER_FAST_TRACE,
    vk::BuildAccelerationStructureFlagsKHR::PREFER_FAST_BUILD,
    vk::BuildAccelerationStructureFlagsKHR::empty(),
    vk::BuildAccelerationStructureFlagsKHR::LOW_MEMORY,
];

pub fn run(data: &[u8]) {
    let mut s = Source::new(data);
    let seed = s.u64();
    let prims = 1 + s.below(48) as usize;
    let adversarial = s.bool();
    let data_access = s.bool();
    let extra = if data_access {
        vk::BuildAccelerationStructureFlagsKHR::ALLOW_DATA_ACCESS
    } else {
        vk::BuildAccelerationStructureFlagsKHR::empty()
    };
    let blas_flags = s.choose(&PRESETS) | extra;
    let tlas_flags = s.choose(&PRESETS);
    let mut r = generate::rng(seed);
    let desc = generate::random_scene(&mut r, prims, adversarial);
    let device = Device::new();
    let built = desc
        .build(&device, blas_flags, tlas_flags)
        .expect("a testkit scene builds");
    let scene = device.scene(built.tlas).expect("scene");
    let oracle = Oracle::new(&desc);
    let n_rays = 1 + s.below(6);
    for _ in 0..n_rays {
        let mut ray = generate::random_ray(&mut r, &desc);
        ray.flags = match s.u8() % 8 {
            0..=3 => generate::random_flags(&mut r),
            4 => RayFlags(s.u32()),
            5 => RayFlags(s.u16() as u32 & 0x7ff),
            6 => generate::random_flags(&mut r) | RayFlags::TERMINATE_ON_FIRST_HIT,
            _ => RayFlags::NONE,
        };
        match s.u8() % 16 {
            0 => ray.t_min = s.f32(),
            1 => ray.t_max = s.f32(),
            2 => ray.origin[s.below(3) as usize] = s.f32(),
            3 => ray.direction[s.below(3) as usize] = s.f32(),
            4 => ray.direction = [0.0; 3],
            5 => {
                ray.t_min = ray.t_max;
            }
            6 => ray.cull_mask = s.u32(),
            _ => {}
        }
        check_ray(&scene, &oracle, &desc, &ray, blas_flags, &mut s);
    }
}

/// Where the ray enters the box shrunk by a relative margin on every side, in f64; `None` when
/// the shrunk box is empty or missed, or entered too far away for f32: a hit that no rounding
/// can turn into a miss.
fn clearly_entered(o: [f32; 3], d: [f32; 3], b: &[f32; 6], t_min: f64, t_max: f64) -> Option<f64> {
    let (mut near, mut far) = (t_min, t_max);
    for k in 0..3 {
        let pad =
            1e-4 * (1.0 + (b[k] as f64).abs().max((b[k + 3] as f64).abs()) + (o[k] as f64).abs());
        let (lo, hi) = (b[k] as f64 + pad, b[k + 3] as f64 - pad);
        if !(lo < hi) {
            return None;
        }
        let (ok, dk) = (o[k] as f64, d[k] as f64);
        if dk == 0.0 {
            if !(lo < ok && ok < hi) {
                return None;
            }
            continue;
        }
        let (t0, t1) = ((lo - ok) / dk, (hi - ok) / dk);
        near = near.max(t0.min(t1));
        far = far.min(t0.max(t1));
    }
    // Entries past f32's range cannot be reported (they round to +inf, which is no entry).
    (near < far * (1.0 - 1e-4) && near < 1e30).then_some(near)
}

fn check_ray(
    scene: &hostas::Scene,
    oracle: &Oracle,
    desc: &SceneDesc,
    ray: &Ray,
    blas_flags: vk::BuildAccelerationStructureFlagsKHR,
    s: &mut Source,
) {
    let valid = ray.validate().is_ok();
    let q = scene.ray_query(ray);
    assert_eq!(
        q.is_ok(),
        valid,
        "ray query and validate disagree on {ray:?}"
    );
    assert_eq!(scene.trace_closest(ray).is_ok(), valid);
    let Ok(mut q) = q else { return };
    // Rays with extreme components can overflow in object space (instance scales reach 1/0.3),
    // where f32 traversal and the f64 oracle legitimately differ: only the state machine and
    // range checks apply to them.
    let tame = ray
        .origin
        .iter()
        .chain(&ray.direction)
        .all(|v| v.abs() <= 1e15);
    let exact = oracle.candidates(ray, 0.0);
    let near = oracle.candidates(ray, AABB_EPS);
    let data_access =
        blas_flags.contains(vk::BuildAccelerationStructureFlagsKHR::ALLOW_DATA_ACCESS);
    let mut seen: HashSet<(u32, u32, u32)> = HashSet::new();
    let mut t_max = ray.t_max;
    let mut terminated = false;
    let mut accept_all = true;
    let mut generated: Option<((u32, u32, u32), f32)> = None;
    let mut steps = 0usize;
    let bound = near.len() + 1;
    while q.proceed() {
        steps += 1;
        assert!(
            !tame || steps <= bound,
            "more candidates offered ({steps}) than the oracle has ({}) for {ray:?}",
            near.len()
        );
        if q.committed_type() != CommittedType::None {
            t_max = q.committed().t;
        }
        let c = *q.candidate();
        let key = (c.instance_id, c.geometry_index, c.primitive_index);
        assert!(
            seen.insert(key),
            "candidate {key:?} offered twice for {ray:?}"
        );
        let inst = &desc.instances[c.instance_id as usize];
        assert_eq!(
            c.instance_custom_index,
            inst.custom_index & 0xff_ffff,
            "custom index"
        );
        assert_eq!(
            c.sbt_record_offset,
            inst.sbt_record_offset & 0xff_ffff,
            "SBT record offset"
        );
        assert_eq!(
            q.object_to_world(false).map(|m| m.to_rows()),
            Some(inst.transform.to_rows()),
            "ObjectToWorld of {key:?}"
        );
        assert_eq!(
            q.world_to_object(false).map(|m| m.to_rows()),
            inst.transform.inverse().map(|m| m.to_rows()),
            "WorldToObject of {key:?}"
        );
        match c.candidate_type() {
            Some(CandidateType::Triangle) if !tame => assert!(
                ray.t_min < c.t && c.t < t_max,
                "triangle candidate t {} outside ({}, {t_max})",
                c.t,
                ray.t_min
            ),
            Some(CandidateType::Aabb) if !tame => assert!(
                !(c.t < ray.t_min) && !(c.t > t_max),
                "AABB candidate t {} outside [{}, {t_max}]",
                c.t,
                ray.t_min
            ),
            Some(CandidateType::Triangle) => {
                let o = exact
                    .iter()
                    .find(|o| o.key() == key && o.kind == CandidateKind::Triangle);
                let Some(o) = o else {
                    panic!("triangle candidate {c:?} is not an oracle candidate for {ray:?}")
                };
                assert_eq!(c.t as f64, o.t, "triangle candidate t for {key:?}");
                assert_eq!(c.barycentrics, o.barycentrics, "barycentrics of {key:?}");
                assert_eq!(c.front_face, o.front_face, "facing of {key:?}");
                assert!(
                    !c.opaque && !o.opaque,
                    "an opaque triangle was offered: {c:?}"
                );
                assert!(
                    ray.t_min < c.t && c.t < t_max,
                    "triangle candidate t {} outside ({}, {t_max})",
                    c.t,
                    ray.t_min
                );
                let v = q.triangle_vertex_positions(false);
                if data_access {
                    let blas = inst.blas.expect("an active instance");
                    let expected = desc.blases[blas].geometries[c.geometry_index as usize]
                        .triangle(c.primitive_index);
                    assert_eq!(v.ok(), expected, "vertex positions of {key:?}");
                } else {
                    assert!(v.is_err(), "vertex positions without ALLOW_DATA_ACCESS");
                }
            }
            Some(CandidateType::Aabb) => {
                let o = near
                    .iter()
                    .find(|o| o.key() == key && o.kind == CandidateKind::Aabb);
                let Some(o) = o else {
                    panic!("AABB candidate {c:?} is not even a near oracle candidate for {ray:?}")
                };
                assert_eq!(c.opaque, o.opaque, "opacity of {key:?}");
                assert!(
                    !(c.t < ray.t_min) && !(c.t > t_max),
                    "AABB candidate t {} outside [{}, {t_max}]",
                    c.t,
                    ray.t_min
                );
                assert!(q.triangle_vertex_positions(false).is_err());
            }
            None => panic!("proceed returned true without a candidate"),
        }
        let before = *q.committed();
        let d = s.u8();
        let is_tri = c.candidate_type() == Some(CandidateType::Triangle);
        match (is_tri, d % 4) {
            (true, 0) => q
                .confirm_intersection()
                .expect("confirm a triangle candidate"),
            (false, 0) => {
                q.generate_intersection(c.t)
                    .expect("generate at the candidate's entry");
                generated = Some((key, c.t));
            }
            (_, 1) => accept_all = false,
            (_, 2) => {
                accept_all = false;
                let (r, t) = if is_tri {
                    (q.generate_intersection(c.t), c.t)
                } else {
                    let t = match s.u8() % 6 {
                        0 => ray.t_min,
                        1 => t_max,
                        2 => f32::NAN,
                        3 => -1.0,
                        4 => s.f32(),
                        _ => c.t + (s.u8() as f32 - 128.0) / 32.0,
                    };
                    if s.chance(32) {
                        (q.confirm_intersection(), f32::NAN)
                    } else {
                        (q.generate_intersection(t), t)
                    }
                };
                let allowed = !is_tri && !t.is_nan() && ray.t_min <= t && t <= t_max;
                assert_eq!(
                    r.is_ok(),
                    allowed,
                    "decision at t {t} on {c:?} (range [{}, {t_max}]): {r:?}",
                    ray.t_min
                );
                if r.is_ok() {
                    generated = Some((key, t));
                } else {
                    assert_eq!(
                        format!("{:?}", q.committed()),
                        format!("{before:?}"),
                        "a refused call changed the committed hit"
                    );
                }
            }
            _ => {
                if s.u8().is_multiple_of(4) {
                    accept_all = false;
                    terminated = true;
                    q.terminate();
                    assert!(!q.proceed(), "proceed after terminate");
                    assert!(q.candidate_type().is_none(), "a candidate after terminate");
                    break;
                } else if is_tri {
                    q.confirm_intersection().expect("confirm");
                } else {
                    q.generate_intersection(c.t).expect("generate");
                    generated = Some((key, c.t));
                }
            }
        }
        let now = *q.committed();
        if now.committed_type() != CommittedType::None {
            t_max = now.t;
        }
    }
    // After the end, nothing can be confirmed or generated.
    assert!(q.confirm_intersection().is_err());
    assert!(q.generate_intersection(ray.t_min).is_err());
    let c = *q.committed();
    let key = (c.instance_id, c.geometry_index, c.primitive_index);
    let final_t = match c.committed_type() {
        CommittedType::None => ray.t_max,
        CommittedType::Triangle if !tame => {
            assert!(
                ray.t_min < c.t && c.t < ray.t_max,
                "committed triangle t {} outside the ray range",
                c.t
            );
            c.t
        }
        CommittedType::Triangle => {
            assert!(
                ray.t_min < c.t && c.t < ray.t_max,
                "committed triangle t {} outside the ray range",
                c.t
            );
            let o = exact
                .iter()
                .find(|o| o.key() == key && o.kind == CandidateKind::Triangle);
            let Some(o) = o else {
                panic!("committed triangle {c:?} is not an oracle candidate for {ray:?}")
            };
            assert_eq!(c.t as f64, o.t, "committed triangle t");
            assert!(
                o.opaque || seen.contains(&key),
                "a non-opaque triangle committed without being offered"
            );
            if data_access {
                let blas = desc.instances[c.instance_id as usize].blas.expect("active");
                assert_eq!(
                    q.triangle_vertex_positions(true).ok(),
                    desc.blases[blas].geometries[c.geometry_index as usize]
                        .triangle(c.primitive_index)
                );
            }
            c.t
        }
        CommittedType::Generated => {
            assert!(
                ray.t_min <= c.t && c.t <= ray.t_max,
                "generated t {} outside the ray range",
                c.t
            );
            assert_eq!(
                generated,
                Some((key, c.t)),
                "the committed generated hit is not the last one generated"
            );
            c.t
        }
    };
    let ran_to_end = tame && !terminated && !ray.flags.contains(RayFlags::TERMINATE_ON_FIRST_HIT);
    if ran_to_end {
        for o in &exact {
            if o.kind != CandidateKind::Triangle || !(o.t < final_t as f64) {
                continue;
            }
            assert!(
                !o.opaque,
                "opaque triangle {:?} at t {} is nearer than the committed t {final_t} for {ray:?}",
                o.key(),
                o.t
            );
            assert!(
                seen.contains(&o.key()),
                "non-opaque triangle {:?} at t {} < {final_t} was never offered for {ray:?}",
                o.key(),
                o.t
            );
        }
        // Boxes the ray clearly enters, clearly before the committed t, were offered.
        for o in &exact {
            if o.kind != CandidateKind::Aabb || seen.contains(&o.key()) {
                continue;
            }
            let inst = &desc.instances[o.instance_id as usize];
            let (Some(b), Some(w2o)) = (inst.blas, inst.transform.inverse()) else {
                continue;
            };
            let GeometryDesc::Aabbs { boxes, .. } =
                &desc.blases[b].geometries[o.geometry_index as usize]
            else {
                continue;
            };
            let bx = boxes[o.primitive_index as usize];
            if let Some(t) = clearly_entered(
                w2o.point(ray.origin),
                w2o.vector(ray.direction),
                &bx,
                ray.t_min as f64,
                ray.t_max as f64,
            ) {
                assert!(
                    !(t < final_t as f64 * (1.0 - AABB_EPS) - AABB_EPS),
                    "box {:?} {bx:?} entered at t {t} < {final_t} was never offered for {ray:?}",
                    o.key()
                );
            }
        }
    }
    if ran_to_end && accept_all {
        // Every candidate accepted at its entry: the oracle's closest hit.
        match (c.committed_type(), oracle.closest(ray)) {
            (CommittedType::None, None) => {}
            (CommittedType::None, Some((t, tied))) => panic!(
                "missed the oracle's closest {:?} at {t} for {ray:?}",
                tied[0]
            ),
            (CommittedType::Triangle, Some((t, tied))) => {
                assert_eq!(c.t as f64, t, "closest t");
                assert!(
                    tied.iter().any(|o| o.key() == key),
                    "committed {key:?} is not among the closest {tied:?}"
                );
            }
            (CommittedType::Generated, best) => {
                assert!(
                    near.iter()
                        .any(|o| o.key() == key && o.kind == CandidateKind::Aabb)
                );
                if let Some((t, _)) = best {
                    assert!(
                        c.t as f64 <= t * (1.0 + AABB_EPS) + AABB_EPS,
                        "box hit at {} farther than the closest {t}",
                        c.t
                    );
                }
            }
            (CommittedType::Triangle, None) => {
                panic!("committed a triangle the oracle does not see")
            }
        }
    }
    // The geometry of the committed hit's instance, for the record.
    if let Some(b) = desc
        .instances
        .get(c.instance_id as usize)
        .and_then(|i| i.blas)
    {
        let _ = desc.blases[b]
            .geometries
            .get(c.geometry_index as usize)
            .map(GeometryDesc::primitive_count);
    }
}
