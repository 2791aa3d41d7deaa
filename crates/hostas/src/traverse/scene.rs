//! A scene: a top-level structure and the bottom-level structures its instances reference,
//! with their memory read-locked and their bytes validated, ready for tracing. BLAS contents
//! are reached through the instance references, so a BLAS updated in place under a built TLAS
//! is traced as it is now.

use super::Ray;
use super::query::{CommittedType, RayQuery};
use crate::device::{AccelerationStructure, Device};
use crate::error::{Error, Result};
use crate::layout::Kind;
use crate::layout::view::{Parts, View};
use crate::memory::HostMemory;
use parking_lot::RawRwLock;
use parking_lot::lock_api::ArcRwLockReadGuard;
use std::ops::Range;
use std::sync::Arc;

type Guard = ArcRwLockReadGuard<RawRwLock, HostMemory>;

/// Where a structure's bytes are: which locked memory, which range.
#[derive(Clone, Debug)]
struct Region {
    memory: usize,
    range: Range<usize>,
    parts: Parts,
}

/// A top-level structure ready for tracing. Holds read locks on the memory of every structure
/// involved: builds into them fail with [`Error::InUse`] until the scene is dropped.
pub struct Scene {
    guards: Vec<Guard>,
    tlas: Option<Region>,
    blases: Vec<Region>,
    /// Per stored instance of the TLAS: index into `blases`, or `u32::MAX` when the reference
    /// does not name a valid, built bottom-level structure (such instances are skipped).
    instance_blas: Vec<u32>,
    /// Instances skipped because their reference was not usable.
    pub unresolved_instances: usize,
}

/// What a batch trace reports for one ray.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    pub kind: HitKind,
    pub t: f32,
    pub instance_id: u32,
    pub instance_custom_index: u32,
    pub geometry_index: u32,
    pub primitive_index: u32,
    pub barycentrics: [f32; 2],
    pub front_face: bool,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u32)]
pub enum HitKind {
    Miss = 0,
    Triangle = 1,
    Generated = 2,
}

impl Hit {
    pub const MISS: Hit = Hit {
        kind: HitKind::Miss,
        t: 0.0,
        instance_id: 0,
        instance_custom_index: 0,
        geometry_index: 0,
        primitive_index: 0,
        barycentrics: [0.0; 2],
        front_face: false,
    };
    pub fn is_hit(&self) -> bool {
        self.kind != HitKind::Miss
    }

    /// The hit a ray query committed (`MISS` when it committed nothing).
    pub fn from_committed(c: &super::Intersection) -> Hit {
        let kind = match c.committed_type() {
            CommittedType::None => return Hit::MISS,
            CommittedType::Triangle => HitKind::Triangle,
            CommittedType::Generated => HitKind::Generated,
        };
        Hit {
            kind,
            t: c.t,
            instance_id: c.instance_id,
            instance_custom_index: c.instance_custom_index,
            geometry_index: c.geometry_index,
            primitive_index: c.primitive_index,
            barycentrics: c.barycentrics,
            front_face: c.front_face,
        }
    }
}

impl Scene {
    fn lock(
        guards: &mut Vec<(Arc<parking_lot::RwLock<HostMemory>>, Guard)>,
        mem: &Arc<parking_lot::RwLock<HostMemory>>,
        handle: u64,
    ) -> Result<usize> {
        if let Some(i) = guards.iter().position(|(m, _)| Arc::ptr_eq(m, mem)) {
            return Ok(i);
        }
        let g = mem.try_read_arc().ok_or(Error::InUse { handle })?;
        guards.push((mem.clone(), g));
        Ok(guards.len() - 1)
    }

    /// Locks and validates `tlas` and every bottom-level structure its instances reference.
    pub fn new(device: &Device, tlas: AccelerationStructure) -> Result<Scene> {
        let mut guards = Vec::new();
        let obj = device.object(tlas)?;
        let mem = obj.buffer.memory().ok_or_else(|| Error::NotBuilt {
            handle: tlas.0,
            reason: "its buffer has no memory bound".into(),
        })?;
        let m = Scene::lock(&mut guards, &mem, tlas.0)?;
        let range = obj.offset as usize..(obj.offset + obj.size) as usize;
        let bytes = &guards[m].1.bytes()[range.clone()];
        let view = View::parse(bytes).map_err(|reason| Error::NotBuilt {
            handle: tlas.0,
            reason,
        })?;
        let region = Region {
            memory: m,
            range,
            parts: view.parts(bytes),
        };
        if view.header.kind != Kind::TopLevel as u32 {
            return Err(Error::NotBuilt {
                handle: tlas.0,
                reason: "ray queries need a top-level structure".into(),
            });
        }
        let references: Vec<u64> = view
            .instances
            .iter()
            .map(|i| i.acceleration_structure_reference)
            .collect();
        let mut blases: Vec<(u64, Region)> = Vec::new();
        let mut instance_blas = Vec::with_capacity(references.len());
        let mut unresolved = 0;
        for r in references {
            if let Some(i) = blases.iter().position(|(h, _)| *h == r) {
                instance_blas.push(i as u32);
                continue;
            }
            let resolved = (|| -> Option<Region> {
                let o = device.object(AccelerationStructure(r)).ok()?;
                let mem = o.buffer.memory()?;
                let m = Scene::lock(&mut guards, &mem, r).ok()?;
                let range = o.offset as usize..(o.offset + o.size) as usize;
                let bytes = &guards[m].1.bytes()[range.clone()];
                let v = View::parse(bytes).ok()?;
                (v.header.kind == Kind::BottomLevel as u32).then_some(Region {
                    memory: m,
                    range,
                    parts: v.parts(bytes),
                })
            })();
            match resolved {
                Some(region) => {
                    blases.push((r, region));
                    instance_blas.push((blases.len() - 1) as u32);
                }
                None => {
                    unresolved += 1;
                    instance_blas.push(u32::MAX);
                }
            }
        }
        Ok(Scene {
            guards: guards.into_iter().map(|(_, g)| g).collect(),
            tlas: Some(region),
            blases: blases.into_iter().map(|(_, r)| r).collect(),
            instance_blas,
            unresolved_instances: unresolved,
        })
    }

    fn bytes(&self, r: &Region) -> &[u8] {
        &self.guards[r.memory].bytes()[r.range.clone()]
    }

    pub(crate) fn tlas_view(&self) -> Option<View<'_>> {
        let r = self.tlas.as_ref()?;
        View::from_parts(self.bytes(r), &r.parts)
    }

    /// Index of the bottom-level structure behind stored instance `slot`.
    pub(crate) fn instance_blas_index(&self, instance_slot: u32) -> Option<u32> {
        self.instance_blas
            .get(instance_slot as usize)
            .copied()
            .filter(|&b| b != u32::MAX)
    }

    pub(crate) fn blas_view(&self, index: u32) -> Option<View<'_>> {
        let r = self.blases.get(index as usize)?;
        View::from_parts(self.bytes(r), &r.parts)
    }

    /// A tracer for many rays (reuses its views and stack).
    pub fn tracer(&self) -> super::Tracer<'_> {
        super::Tracer::new(self)
    }

    pub(crate) fn blas_view_for(&self, instance_slot: u32) -> Option<View<'_>> {
        let b = *self.instance_blas.get(instance_slot as usize)?;
        let r = self.blases.get(b as usize)?;
        View::from_parts(self.bytes(r), &r.parts)
    }

    /// A ray query over this scene (`rayQueryInitializeEXT`).
    pub fn ray_query(&self, ray: &Ray) -> Result<RayQuery<'_>> {
        RayQuery::new(self, ray)
    }

    /// Closest hit with the semantics of `traceRayEXT` when no any-hit or intersection shader
    /// is bound: non-opaque triangles are accepted, AABBs report a hit where the ray enters
    /// the box.
    pub fn trace_closest(&self, ray: &Ray) -> Result<Hit> {
        self.tracer().closest(ray)
    }

    /// Like [`Scene::trace_closest`] but stops at the first accepted hit
    /// (`TerminateOnFirstHit`).
    pub fn trace_any(&self, ray: &Ray) -> Result<Hit> {
        self.tracer().any(ray)
    }

    /// Closest hit with callbacks, like an any-hit and an intersection shader: `any_hit`
    /// decides on non-opaque triangle candidates (return `true` to accept), `intersect` on AABB
    /// candidates (return the hit distance, or `None`; distances outside `[tMin, current
    /// closest]` are ignored). Both get the query, so every candidate getter (object-space
    /// ray, transforms, ids, vertex positions) is available to them.
    pub fn trace_with(
        &self,
        ray: &Ray,
        mut any_hit: impl FnMut(&RayQuery) -> bool,
        mut intersect: impl FnMut(&RayQuery) -> Option<f32>,
    ) -> Result<Hit> {
        let mut q = RayQuery::new(self, ray)?;
        while q.proceed() {
            match q.candidate_type() {
                Some(super::CandidateType::Triangle) if any_hit(&q) => q.confirm_intersection()?,
                Some(super::CandidateType::Triangle) => {}
                Some(super::CandidateType::Aabb) => {
                    if let Some(t) = intersect(&q) {
                        // Outside the allowed range the hit is dropped, as a shader's would be.
                        let _ = q.generate_intersection(t);
                    }
                }
                None => {}
            }
        }
        Ok(Hit::from_committed(q.committed()))
    }

    /// Traces a batch of rays on all threads of the current rayon pool: closest hits, or any
    /// hit (`TerminateOnFirstHit`) when `any_hit` is set. Results are in ray order; an invalid
    /// ray's error names its index in `rays` ([`Location::ray`](crate::Location::ray)). The
    /// rays go through [`Tracer::closest_batch`](super::Tracer::closest_batch) or
    /// [`Tracer::any_batch`](super::Tracer::any_batch) in chunks of `TRACE_CHUNK` (1,024) rays
    /// (interleaved walks where they pay).
    pub fn trace_batch(&self, rays: &[Ray], any_hit: bool) -> Result<Vec<Hit>> {
        use rayon::prelude::*;
        let chunks: Vec<Vec<Hit>> = rays
            .par_chunks(TRACE_CHUNK)
            .enumerate()
            .map_init(
                || self.tracer(),
                |t, (k, chunk)| {
                    let mut hits = Vec::with_capacity(chunk.len());
                    if any_hit {
                        t.any_batch(chunk, &mut hits)
                    } else {
                        t.closest_batch(chunk, &mut hits)
                    }
                    .map(|()| hits)
                    .map_err(|e| e.shift_ray(k * TRACE_CHUNK))
                },
            )
            .collect::<Result<_>>()?;
        Ok(chunks.concat())
    }
}

/// Rays per [`Tracer::closest_batch`](super::Tracer::closest_batch) or `any_batch` call in
/// [`Scene::trace_batch`]: enough for each axis permutation's share to keep eight walks in
/// flight most of the time, few enough for a thread's share of work to balance.
const TRACE_CHUNK: usize = 1024;

// Scenes are shared by the threads that trace through them.
const _: () = {
    const fn assert_sync<T: Sync + Send>() {}
    assert_sync::<Scene>();
};

impl Device {
    /// Locks `tlas` and the structures it references for tracing.
    pub fn scene(&self, tlas: AccelerationStructure) -> Result<Scene> {
        Scene::new(self, tlas)
    }
}
