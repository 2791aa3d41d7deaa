//! What every target shares: a small fixture of real structures on a fresh device, probe
//! rays, and the tracing checks.

use hostas::{
    AccelerationStructure, AccelerationStructureCreateInfo, Affine, Device, Hit, HitKind, Ray,
    RayFlags, Scene, vk,
};

/// Largest structure, scratch or buffer a target allocates on behalf of an input: inputs that
/// ask for more are still passed to the size checks, with a small allocation.
pub const MAX_ALLOC: u64 = 32 << 20;

/// Known-bug guards: while a bug found by fuzzing is open (pinned by an ignored test in
/// `tests/fuzz_regressions.rs`), a target may skip the inputs that hit it, behind this switch,
/// so that fuzzing goes on past it; `HOSTAS_FUZZ_NO_GUARDS=1` turns guards off to check a fix.
/// No guard is active now: the bugs found so far are fixed.
pub fn guards_on() -> bool {
    thread_local! {
        static ON: bool = std::env::var_os("HOSTAS_FUZZ_NO_GUARDS").is_none_or(|v| v.is_empty() || v == "0");
    }
    ON.with(|v| *v)
}

/// Real structures to reference: two triangles, two boxes, a TLAS, a created but unbuilt
/// structure, and the handle of a destroyed one.
pub struct Fixture {
    pub device: Device,
    pub tri_blas: AccelerationStructure,
    pub aabb_blas: AccelerationStructure,
    pub tlas: AccelerationStructure,
    pub unbuilt: AccelerationStructure,
    pub destroyed: u64,
}

pub const TRI_FLAGS: vk::BuildAccelerationStructureFlagsKHR =
    vk::BuildAccelerationStructureFlagsKHR::from_raw(
        vk::BuildAccelerationStructureFlagsKHR::ALLOW_UPDATE.as_raw()
            | vk::BuildAccelerationStructureFlagsKHR::ALLOW_DATA_ACCESS.as_raw(),
    );

impl Fixture {
    pub fn new() -> Fixture {
        let device = Device::new();
        let positions = [
            [0.0f32, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [1.0, 1.0, 0.5],
        ];
        let tri_blas = hostas::quick::build_triangle_blas(
            &device,
            &positions,
            &[[0, 1, 2], [1, 3, 2]],
            TRI_FLAGS,
        )
        .expect("fixture triangles");
        let boxes = [
            hostas::Aabb {
                lo: [-1.0, -1.0, -1.0],
                hi: [-0.5, -0.5, -0.5],
            },
            hostas::Aabb {
                lo: [0.25, 0.25, 0.25],
                hi: [0.75, 0.75, 1.0],
            },
        ];
        let aabb_blas = hostas::quick::build_aabb_blas(
            &device,
            &boxes,
            vk::GeometryFlagsKHR::empty(),
            vk::BuildAccelerationStructureFlagsKHR::ALLOW_COMPACTION,
        )
        .expect("fixture boxes");
        let tlas =
            hostas::quick::build_single_instance_tlas(&device, tri_blas).expect("fixture tlas");
        let unbuilt = device
            .create_acceleration_structure(&AccelerationStructureCreateInfo::new(
                vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
                4096,
            ))
            .expect("unbuilt");
        let gone = device
            .create_acceleration_structure(&AccelerationStructureCreateInfo::new(
                vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
                256,
            ))
            .expect("gone");
        device
            .destroy_acceleration_structure(gone)
            .expect("destroy");
        Fixture {
            device,
            tri_blas,
            aabb_blas,
            tlas,
            unbuilt,
            destroyed: gone.raw(),
        }
    }
}

impl Default for Fixture {
    fn default() -> Self {
        Fixture::new()
    }
}

/// Creates a structure of `size` bytes (clamped to `1..=MAX_ALLOC`).
pub fn create(
    device: &Device,
    ty: vk::AccelerationStructureTypeKHR,
    size: u64,
) -> hostas::Result<AccelerationStructure> {
    device.create_acceleration_structure(&AccelerationStructureCreateInfo::new(
        ty,
        size.clamp(1, MAX_ALLOC),
    ))
}

/// Rays around and through the box `lo..hi` (or the unit cube when it is not finite), with
/// a spread of flags and masks; a few are invalid on purpose.
pub fn probe_rays(lo: [f32; 3], hi: [f32; 3]) -> Vec<Ray> {
    let finite = lo
        .iter()
        .chain(&hi)
        .all(|v| v.is_finite() && v.abs() < 1e15)
        && (0..3).all(|k| lo[k] <= hi[k]);
    let (lo, hi) = if finite {
        (lo, hi)
    } else {
        ([-1.0; 3], [1.0; 3])
    };
    let c = [
        0.5 * (lo[0] + hi[0]),
        0.5 * (lo[1] + hi[1]),
        0.5 * (lo[2] + hi[2]),
    ];
    let e = (0..3).map(|k| hi[k] - lo[k]).fold(1.0f32, f32::max);
    let mut rays = Vec::new();
    let dirs = [
        [0.0, 0.0, -1.0],
        [0.0, 0.0, 1.0],
        [1.0, 0.0, 0.0],
        [0.0, -1.0, 0.0],
        [0.3, 0.2, -1.0],
        [-0.7, 0.5, 0.1],
    ];
    for (i, d) in dirs.iter().enumerate() {
        let o = [
            c[0] - d[0] * 2.0 * e + 0.1 * i as f32 * e,
            c[1] - d[1] * 2.0 * e,
            c[2] - d[2] * 2.0 * e,
        ];
        rays.push(Ray::new(o, *d));
    }
    // Through a corner, from inside, with flags, masks and short ranges.
    let flags = [
        RayFlags::OPAQUE,
        RayFlags::NO_OPAQUE,
        RayFlags::CULL_BACK_FACING_TRIANGLES,
        RayFlags::CULL_FRONT_FACING_TRIANGLES | RayFlags::CULL_NO_OPAQUE,
        RayFlags::SKIP_TRIANGLES,
        RayFlags::SKIP_AABBS | RayFlags::TERMINATE_ON_FIRST_HIT,
    ];
    for (i, f) in flags.iter().enumerate() {
        let mut r = Ray::new(
            [lo[0] - e, lo[1] - e * 0.5, lo[2] - e],
            [
                e + c[0] - lo[0],
                e * 0.5 + c[1] - lo[1],
                e + c[2] - lo[2] + 0.01 * i as f32,
            ],
        );
        r.flags = *f;
        r.cull_mask = if i % 3 == 0 { 0x01 } else { 0xff };
        rays.push(r);
    }
    let mut inside = Ray::new(c, [0.1, 1.0, 0.2]);
    inside.t_min = 0.0;
    inside.t_max = e;
    rays.push(inside);
    let mut zero_dir = Ray::new(c, [0.0, 0.0, 0.0]);
    zero_dir.t_max = 1.0;
    rays.push(zero_dir);
    // Invalid: NaN origin, tMin > tMax, both skip flags.
    rays.push(Ray::new([f32::NAN, 0.0, 0.0], [0.0, 0.0, 1.0]));
    let mut r = Ray::new(c, [0.0, 0.0, 1.0]);
    r.t_min = 2.0;
    r.t_max = 1.0;
    rays.push(r);
    let mut r = Ray::new(c, [0.0, 0.0, 1.0]);
    r.flags = RayFlags::SKIP_TRIANGLES | RayFlags::SKIP_AABBS;
    rays.push(r);
    rays
}

/// The committed hit lies in the ray's range (open for triangles, closed for generated hits).
pub fn check_hit_range(ray: &Ray, h: &Hit, what: &str) {
    match h.kind {
        HitKind::Miss => {}
        HitKind::Triangle => assert!(
            ray.t_min < h.t && h.t < ray.t_max,
            "{what}: triangle hit t {} outside ({}, {}) for {ray:?}",
            h.t,
            ray.t_min,
            ray.t_max
        ),
        HitKind::Generated => assert!(
            ray.t_min <= h.t && h.t <= ray.t_max,
            "{what}: generated hit t {} outside [{}, {}] for {ray:?}",
            h.t,
            ray.t_min,
            ray.t_max
        ),
    }
}

/// Traces each ray closest-hit and any-hit: invalid rays are rejected by both, valid ones
/// trace and commit hits in range. With `strict` (structures hostas built from finite
/// inputs), any-hit and closest-hit also agree on whether there is a hit, and the any-hit is
/// never closer than the closest.
pub fn trace_rays(scene: &Scene, rays: &[Ray], strict: bool) {
    for ray in rays {
        let valid = ray.validate().is_ok();
        let closest = scene.trace_closest(ray);
        let any = scene.trace_any(ray);
        match (valid, closest, any) {
            (false, Err(_), Err(_)) => {}
            (true, Ok(c), Ok(a)) => {
                check_hit_range(ray, &c, "closest");
                check_hit_range(ray, &a, "any");
                if strict {
                    assert_eq!(
                        c.is_hit(),
                        a.is_hit(),
                        "closest {c:?} and any-hit {a:?} disagree for {ray:?}"
                    );
                    if c.is_hit() {
                        assert!(
                            a.t >= c.t,
                            "any-hit {a:?} is closer than the closest hit {c:?} for {ray:?}"
                        );
                    }
                }
            }
            (v, c, a) => panic!("ray valid = {v} but closest = {c:?}, any = {a:?} for {ray:?}"),
        }
    }
}

/// A ray query driven by `decide` (a stream of decision bytes), with the state machine's
/// invariants checked after every step. Returns how many candidates were seen.
pub fn walk_query(
    scene: &Scene,
    ray: &Ray,
    mut decide: impl FnMut() -> u8,
    step_limit: usize,
) -> usize {
    let Ok(mut q) = scene.ray_query(ray) else {
        assert!(
            ray.validate().is_err(),
            "ray query refused a valid ray {ray:?}"
        );
        return 0;
    };
    assert!(
        ray.validate().is_ok(),
        "ray query accepted an invalid ray {ray:?}"
    );
    let mut seen = 0;
    let mut t_max = ray.t_max;
    while q.proceed() {
        // Opaque triangles met on the way were committed by proceed itself.
        if q.committed_type() != hostas::CommittedType::None {
            t_max = q.committed().t;
        }
        seen += 1;
        assert!(
            seen <= step_limit,
            "ray query yields more than {step_limit} candidates for {ray:?}"
        );
        let c = *q.candidate();
        match c.candidate_type() {
            Some(hostas::CandidateType::Triangle) => {
                assert!(
                    ray.t_min < c.t && c.t < t_max,
                    "triangle candidate t {} outside ({}, {t_max})",
                    c.t,
                    ray.t_min
                );
                assert!(
                    !c.opaque,
                    "opaque triangles are committed by proceed, never offered: {c:?}"
                );
            }
            Some(hostas::CandidateType::Aabb) => {
                assert!(
                    !(c.t < ray.t_min) && !(c.t > t_max),
                    "AABB candidate entry t {} outside [{}, {t_max}]",
                    c.t,
                    ray.t_min
                );
            }
            None => panic!("proceed returned true without a candidate"),
        }
        let _ = q.object_to_world(false);
        let _ = q.world_to_object(false);
        let _ = q.object_ray_origin(false);
        let _ = q.object_ray_direction(false);
        let _ = q.triangle_vertex_positions(false);
        let before = *q.committed();
        let d = decide();
        match d % 8 {
            0 | 1 => {
                let r = q.confirm_intersection();
                assert_eq!(
                    r.is_ok(),
                    c.candidate_type() == Some(hostas::CandidateType::Triangle),
                    "confirm on {c:?}: {r:?}"
                );
            }
            2 | 3 => {
                // Generate at the entry, at a range end, or at an arbitrary (maybe invalid) t.
                let t = match decide() % 6 {
                    0 => c.t,
                    1 => ray.t_min,
                    2 => t_max,
                    3 => f32::NAN,
                    4 => -1.0,
                    _ => c.t + (decide() as f32 - 128.0) / 64.0,
                };
                let r = q.generate_intersection(t);
                let allowed = c.candidate_type() == Some(hostas::CandidateType::Aabb)
                    && ray.t_min <= t
                    && t <= t_max;
                assert_eq!(
                    r.is_ok(),
                    allowed,
                    "generate at {t} on {c:?} (range [{}, {t_max}]): {r:?}",
                    ray.t_min
                );
                if r.is_err() {
                    assert_eq!(
                        format!("{:?}", q.committed()),
                        format!("{before:?}"),
                        "a refused generate changed the committed hit"
                    );
                }
            }
            4 => {
                q.terminate();
                assert!(!q.proceed(), "proceed after terminate");
                break;
            }
            _ => {}
        }
        let now = q.committed();
        if now.committed_type() != hostas::CommittedType::None {
            t_max = now.t;
        }
    }
    // Confirm and generate without a candidate are errors, never panics.
    assert!(q.confirm_intersection().is_err());
    assert!(q.generate_intersection(ray.t_min).is_err());
    let c = *q.committed();
    let h = Hit {
        kind: match c.committed_type() {
            hostas::CommittedType::None => HitKind::Miss,
            hostas::CommittedType::Triangle => HitKind::Triangle,
            hostas::CommittedType::Generated => HitKind::Generated,
        },
        t: c.t,
        instance_id: c.instance_id,
        instance_custom_index: c.instance_custom_index,
        geometry_index: c.geometry_index,
        primitive_index: c.primitive_index,
        barycentrics: c.barycentrics,
        front_face: c.front_face,
    };
    check_hit_range(ray, &h, "ray query");
    let _ = q.object_to_world(true);
    let _ = q.world_to_object(true);
    let _ = q.triangle_vertex_positions(true);
    seen
}

/// Instances of `blas` with a few transforms (identity, rotated and scaled, mirrored).
pub fn instances_of(blas: AccelerationStructure) -> Vec<hostas::Instance> {
    let mut rot = Affine::IDENTITY;
    rot.m = [
        [0.0, -2.0, 0.0, 3.0],
        [1.0, 0.0, 0.0, -1.0],
        [0.0, 0.0, 0.5, 0.25],
    ];
    let mut mirror = Affine::IDENTITY;
    mirror.m[0][0] = -1.0;
    let mut out = vec![
        hostas::quick::instance(blas, Affine::IDENTITY),
        hostas::quick::instance(blas, rot),
        hostas::quick::instance(blas, mirror),
    ];
    out[1].flags = vk::GeometryInstanceFlagsKHR::TRIANGLE_FLIP_FACING
        | vk::GeometryInstanceFlagsKHR::FORCE_NO_OPAQUE;
    out[2].flags = vk::GeometryInstanceFlagsKHR::FORCE_OPAQUE
        | vk::GeometryInstanceFlagsKHR::TRIANGLE_FACING_CULL_DISABLE;
    out[2].mask = 0x0f;
    out
}

/// A tiny deterministic stream of decision bytes (for targets whose input is not a decision
/// stream, e.g. serialized bytes).
pub struct Lcg(pub u64);

impl Lcg {
    pub fn from_bytes(b: &[u8]) -> Lcg {
        let mut h = 0xcbf2_9ce4_8422_2325u64;
        for &x in b.iter().take(4096) {
            h ^= x as u64;
            h = h.wrapping_mul(0x0000_0100_0000_01b3);
        }
        Lcg(h ^ b.len() as u64)
    }
    pub fn byte(&mut self) -> u8 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 56) as u8
    }
}
