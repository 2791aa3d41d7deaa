//! The brute-force oracle: every primitive of every instance is tested against the ray, and
//! the spec's rules (ranges, masks, face culling, opacity, skip flags, ids) are applied
//! directly from the specification text, with no tree and no traversal order.
//!
//! The arithmetic that decides a single primitive hit is shared with hostas on purpose (the
//! watertight triangle test and the f32 instance transforms), so that hits compare exactly;
//! everything above it is written independently here.

use crate::scene::{GeometryDesc, SceneDesc};
use hostas::traverse::triangle::ShearedRay;
use hostas::{Affine, Ray, RayFlags, vk};

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum CandidateKind {
    Triangle,
    Aabb,
}

/// A primitive that the ray reaches and that survives culling.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Candidate {
    pub kind: CandidateKind,
    pub instance_id: u32,
    pub geometry_index: u32,
    pub primitive_index: u32,
    /// Triangle: the hit distance. AABB: where the ray enters the box (clamped to tMin), in f64.
    pub t: f64,
    pub opaque: bool,
    pub front_face: bool,
    pub barycentrics: [f32; 2],
}

impl Candidate {
    pub fn key(&self) -> (u32, u32, u32) {
        (self.instance_id, self.geometry_index, self.primitive_index)
    }
}

pub struct Oracle<'a> {
    scene: &'a SceneDesc,
    inverses: Vec<Option<Affine>>,
}

/// The inclusive slab test in f64: entry distance, or `None`. `eps` grows the box (relative
/// to its size and position) to ask "is this a near miss?".
pub fn slab(
    o: [f32; 3],
    d: [f32; 3],
    b: &[f32; 6],
    t_min: f64,
    t_max: f64,
    eps: f64,
) -> Option<f64> {
    let mut near = t_min;
    let mut far = t_max;
    for k in 0..3 {
        let pad =
            eps * (1.0 + (b[k] as f64).abs().max((b[k + 3] as f64).abs()) + (o[k] as f64).abs());
        let (lo, hi) = (b[k] as f64 - pad, b[k + 3] as f64 + pad);
        let (ok, dk) = (o[k] as f64, d[k] as f64);
        if dk == 0.0 {
            if ok < lo || ok > hi {
                return None;
            }
            continue;
        }
        let (t0, t1) = ((lo - ok) / dk, (hi - ok) / dk);
        near = near.max(t0.min(t1));
        far = far.min(t0.max(t1) * (1.0 + eps));
    }
    (near <= far).then_some(near)
}

impl<'a> Oracle<'a> {
    pub fn new(scene: &'a SceneDesc) -> Oracle<'a> {
        Oracle {
            scene,
            inverses: scene
                .instances
                .iter()
                .map(|i| i.transform.inverse())
                .collect(),
        }
    }

    /// Every candidate with `t` inside the ray's range (strict for triangles, inclusive for
    /// AABBs), after skip, mask, face and opacity culling. `eps > 0` widens AABBs (near misses).
    pub fn candidates(&self, ray: &Ray, eps: f64) -> Vec<Candidate> {
        let f = ray.flags;
        let mut out = Vec::new();
        for (id, inst) in self.scene.instances.iter().enumerate() {
            let Some(b) = inst.blas else { continue }; // inactive: invisible, but counted in ids
            if (inst.mask as u32) & ray.cull_mask & 0xff == 0 {
                continue;
            }
            let Some(w2o) = self.inverses[id] else {
                continue;
            };
            let o = w2o.point(ray.origin);
            let d = w2o.vector(ray.direction);
            let sheared = ShearedRay::new(o, d);
            let iflags = inst.flags;
            for (g, geom) in self.scene.blases[b].geometries.iter().enumerate() {
                // Opacity: geometry flag, then instance force flags, then ray flags.
                let mut opaque = geom.flags().contains(vk::GeometryFlagsKHR::OPAQUE);
                if iflags.contains(vk::GeometryInstanceFlagsKHR::FORCE_OPAQUE) {
                    opaque = true;
                }
                if iflags.contains(vk::GeometryInstanceFlagsKHR::FORCE_NO_OPAQUE) {
                    opaque = false;
                }
                if f.contains(RayFlags::OPAQUE) {
                    opaque = true;
                }
                if f.contains(RayFlags::NO_OPAQUE) {
                    opaque = false;
                }
                if (opaque && f.contains(RayFlags::CULL_OPAQUE))
                    || (!opaque && f.contains(RayFlags::CULL_NO_OPAQUE))
                {
                    continue;
                }
                match geom {
                    GeometryDesc::Triangles { .. } => {
                        if f.contains(RayFlags::SKIP_TRIANGLES) {
                            continue;
                        }
                        for p in 0..geom.primitive_count() {
                            let Some(v) = geom.triangle(p) else { continue };
                            let flat = [
                                v[0][0], v[0][1], v[0][2], v[1][0], v[1][1], v[1][2], v[2][0],
                                v[2][1], v[2][2],
                            ];
                            let Some(h) = sheared.intersect(&flat) else {
                                continue;
                            };
                            if !(ray.t_min < h.t && h.t < ray.t_max) {
                                continue;
                            }
                            let mut front = h.front_face;
                            if iflags.contains(vk::GeometryInstanceFlagsKHR::TRIANGLE_FLIP_FACING) {
                                front = !front;
                            }
                            if !iflags.contains(
                                vk::GeometryInstanceFlagsKHR::TRIANGLE_FACING_CULL_DISABLE,
                            ) && ((front && f.contains(RayFlags::CULL_FRONT_FACING_TRIANGLES))
                                || (!front && f.contains(RayFlags::CULL_BACK_FACING_TRIANGLES)))
                            {
                                continue;
                            }
                            out.push(Candidate {
                                kind: CandidateKind::Triangle,
                                instance_id: id as u32,
                                geometry_index: g as u32,
                                primitive_index: p,
                                t: h.t as f64,
                                opaque,
                                front_face: front,
                                barycentrics: [h.b, h.c],
                            });
                        }
                    }
                    GeometryDesc::Aabbs { boxes, .. } => {
                        if f.contains(RayFlags::SKIP_AABBS) {
                            continue;
                        }
                        for (p, bx) in boxes.iter().enumerate() {
                            if bx[0].is_nan() {
                                continue;
                            }
                            let Some(t) = slab(o, d, bx, ray.t_min as f64, ray.t_max as f64, eps)
                            else {
                                continue;
                            };
                            out.push(Candidate {
                                kind: CandidateKind::Aabb,
                                instance_id: id as u32,
                                geometry_index: g as u32,
                                primitive_index: p as u32,
                                t,
                                opaque,
                                front_face: false,
                                barycentrics: [0.0; 2],
                            });
                        }
                    }
                }
            }
        }
        out
    }

    /// `traceRayEXT` with no any-hit shader: every candidate is accepted, AABBs hit where the
    /// ray enters them. Returns the closest distance and every candidate at that distance
    /// (ties: any of them is a correct answer).
    pub fn closest(&self, ray: &Ray) -> Option<(f64, Vec<Candidate>)> {
        let c = self.candidates(ray, 0.0);
        let t = c.iter().map(|c| c.t).fold(f64::INFINITY, f64::min);
        if t == f64::INFINITY {
            return None;
        }
        Some((t, c.into_iter().filter(|c| c.t == t).collect()))
    }
}
