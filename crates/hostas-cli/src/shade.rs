//! Closest-hit tracing with "shaders": a loop over a [`RayQuery`] that asks an any-hit
//! callback about non-opaque triangles and an intersection callback about AABBs, as a
//! ray-tracing pipeline would, and returns what shading needs (position, normal, ids).

use crate::geom::{V3, add, cross, normalize, scale, sub, transpose_vector};
use hostas::{CandidateType, CommittedType, Hit, HitKind, Intersection, Ray, RayQuery, Scene};

/// The application's shaders.
pub trait Programs: Sync {
    /// Any-hit shader for a non-opaque triangle candidate: `true` accepts it.
    fn any_hit(&self, _q: &RayQuery, _c: &Intersection) -> bool {
        true
    }
    /// Intersection shader for an AABB candidate: the hit distance, or `None`. Without one,
    /// the box is hit where the ray enters it.
    fn intersect(&self, _q: &RayQuery, c: &Intersection) -> Option<f32> {
        Some(c.t)
    }
    /// Object-space normal of a generated (procedural) hit at object-space point `p`.
    fn procedural_normal(&self, _c: &Intersection, _p: V3) -> Option<V3> {
        None
    }
    /// Surface colour (linear RGB) where the default shading should not decide.
    fn albedo(&self, _s: &Surface) -> Option<V3> {
        None
    }
}

/// No shaders: non-opaque triangles are accepted, boxes are hit where the ray enters them.
pub struct NoPrograms;
impl Programs for NoPrograms {}

/// What shading knows about the closest hit.
#[derive(Clone, Copy, Debug)]
pub struct Surface {
    pub hit: Hit,
    /// World-space hit point.
    pub position: V3,
    /// Object-space hit point.
    pub object_position: V3,
    /// World-space unit normal as the geometry is wound (not flipped towards the ray), when
    /// known: triangles of structures built with `ALLOW_DATA_ACCESS`, and procedural hits
    /// whose normal the programs give.
    pub normal: Option<V3>,
}

/// Object-space point at distance `t` along the ray of the candidate (`committed = false`) or
/// the committed intersection.
pub fn object_point(q: &RayQuery, committed: bool, t: f32) -> Option<V3> {
    Some(add(
        q.object_ray_origin(committed)?,
        scale(q.object_ray_direction(committed)?, t),
    ))
}

/// Runs the query to its end with `programs` deciding on candidates.
fn run<'s>(scene: &'s Scene, ray: &Ray, programs: &impl Programs) -> hostas::Result<RayQuery<'s>> {
    let mut q = scene.ray_query(ray)?;
    while q.proceed() {
        let c = *q.candidate();
        match c.candidate_type() {
            Some(CandidateType::Triangle) if programs.any_hit(&q, &c) => {
                q.confirm_intersection()?
            }
            Some(CandidateType::Triangle) => {}
            Some(CandidateType::Aabb) => {
                if let Some(t) = programs.intersect(&q, &c) {
                    // Outside [tMin, closest so far] the hit is dropped, as a shader's is.
                    let _ = q.generate_intersection(t);
                }
            }
            None => {}
        }
    }
    Ok(q)
}

/// Whether anything is hit (for shadow rays: add `TERMINATE_ON_FIRST_HIT` to the flags).
pub fn occluded(scene: &Scene, ray: &Ray, programs: &impl Programs) -> hostas::Result<bool> {
    let q = run(scene, ray, programs)?;
    Ok(q.committed_type() != CommittedType::None)
}

/// The closest hit, or `None` on a miss.
pub fn trace(
    scene: &Scene,
    ray: &Ray,
    programs: &impl Programs,
) -> hostas::Result<Option<Surface>> {
    let q = run(scene, ray, programs)?;
    let c = *q.committed();
    let hit = Hit::from_committed(&c);
    if !hit.is_hit() {
        return Ok(None);
    }
    let kind = hit.kind;
    let position = add(ray.origin, scale(ray.direction, c.t));
    let object_position = object_point(&q, true, c.t).unwrap_or(position);
    let object_normal = match kind {
        HitKind::Triangle => q
            .triangle_vertex_positions(true)
            .ok()
            .map(|v| cross(sub(v[1], v[0]), sub(v[2], v[0]))),
        _ => programs.procedural_normal(&c, object_position),
    };
    let normal = object_normal.and_then(|n| {
        let w = normalize(transpose_vector(&q.world_to_object(true)?, n));
        (w != [0.0; 3]).then_some(w)
    });
    Ok(Some(Surface {
        hit,
        position,
        object_position,
        normal,
    }))
}
