//! Ray traversal with the semantics of `GL_EXT_ray_query` / `SPV_KHR_ray_query`.
//!
//! [`RayQuery`] is the state machine (initialize, proceed, confirm, generate, terminate and the
//! getters); [`Scene`] holds the memory of a top-level structure and every bottom-level
//! structure its instances reference, locked for reading while rays are traced, and offers
//! batch calls for closest-hit and any-hit tracing.

mod interleaved;
mod packet;
mod query;
mod scene;
mod screen;
mod tile;
mod tracer;
pub mod triangle;

pub use query::{CandidateType, CommittedType, Intersection, RayQuery};
pub use scene::{Hit, HitKind, Scene};
pub use tracer::{Interleave, Tracer};

use crate::error::{Error, Location, Result};
use crate::layout::PrimKind;
use crate::math::{Vec3, lanes};
use wide::f32x4;

/// SPIR-V `RayFlags` (`gl_RayFlags*EXT`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct RayFlags(pub u32);

impl RayFlags {
    pub const NONE: RayFlags = RayFlags(0);
    pub const OPAQUE: RayFlags = RayFlags(0x1);
    pub const NO_OPAQUE: RayFlags = RayFlags(0x2);
    pub const TERMINATE_ON_FIRST_HIT: RayFlags = RayFlags(0x4);
    pub const SKIP_CLOSEST_HIT_SHADER: RayFlags = RayFlags(0x8);
    pub const CULL_BACK_FACING_TRIANGLES: RayFlags = RayFlags(0x10);
    pub const CULL_FRONT_FACING_TRIANGLES: RayFlags = RayFlags(0x20);
    pub const CULL_OPAQUE: RayFlags = RayFlags(0x40);
    pub const CULL_NO_OPAQUE: RayFlags = RayFlags(0x80);
    pub const SKIP_TRIANGLES: RayFlags = RayFlags(0x100);
    pub const SKIP_AABBS: RayFlags = RayFlags(0x200);
    pub const FORCE_OPACITY_MICROMAP_2_STATE: RayFlags = RayFlags(0x400);

    pub const fn empty() -> RayFlags {
        RayFlags(0)
    }
    #[inline(always)]
    pub const fn contains(self, other: RayFlags) -> bool {
        self.0 & other.0 == other.0
    }
    #[inline(always)]
    pub const fn intersects(self, other: RayFlags) -> bool {
        self.0 & other.0 != 0
    }
}

impl RayFlags {
    /// Whether these flags skip a bottom level holding `kind` of primitive (`SKIP_TRIANGLES`,
    /// `SKIP_AABBS`); a bottom level without triangles or AABBs is never entered.
    #[inline(always)]
    pub(crate) fn skip(self, kind: PrimKind) -> bool {
        match kind {
            PrimKind::Triangles => self.contains(RayFlags::SKIP_TRIANGLES),
            PrimKind::Aabbs => self.contains(RayFlags::SKIP_AABBS),
            _ => true,
        }
    }
}

impl std::ops::BitOr for RayFlags {
    type Output = RayFlags;
    fn bitor(self, rhs: RayFlags) -> RayFlags {
        RayFlags(self.0 | rhs.0)
    }
}

/// A ray as `rayQueryInitializeEXT` takes it: `t` is measured along the unnormalized
/// direction, in every space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    pub origin: Vec3,
    pub t_min: f32,
    pub direction: Vec3,
    pub t_max: f32,
    pub flags: RayFlags,
    /// Only the low 8 bits are used.
    pub cull_mask: u32,
}

impl Ray {
    pub fn new(origin: Vec3, direction: Vec3) -> Ray {
        Ray {
            origin,
            t_min: 0.0,
            direction,
            t_max: f32::INFINITY,
            flags: RayFlags::NONE,
            cull_mask: 0xff,
        }
    }

    /// The runtime rules of `OpRayQueryInitializeKHR` (VUID-RuntimeSpirv-OpRayQueryInitializeKHR-*).
    #[inline(always)]
    pub fn validate(&self) -> Result<()> {
        // Every ray is checked, so the check is one branch; the error is worked out apart.
        if self.plainly_valid() {
            Ok(())
        } else {
            self.first_broken_rule()
        }
    }

    /// All the rules of [`Ray::validate`] at once, with one branch for rays that set more than
    /// one of the flags the rules name.
    #[inline(always)]
    fn plainly_valid(&self) -> bool {
        let [o, d] = [self.origin, self.direction];
        // Field by field: a caller has usually just stored the ray, field by field, and a
        // load spanning several of those stores cannot be forwarded from them (one 32-byte
        // load of origin to tMax made primary rays 7-17% slower on the Xeon).
        // Lane by lane, as the tracer's `BoxRay` holds the ray (the same vectors, made once):
        // a lane is zero unless its origin or direction component is infinite or NaN.
        let zero = f32x4::ZERO;
        let finite = (lanes(o) * zero + lanes(d) * zero)
            .simd_eq(zero)
            .to_bitmask()
            == 0b1111;
        // False when either is NaN.
        let range = (0.0 <= self.t_min) & (self.t_min <= self.t_max);
        // Each flag rule forbids a pair of the flags it names: a ray that sets at most one of
        // them keeps every rule (most rays: none, or only OPAQUE or a culling flag).
        let named = self.flags.0 & Self::RULE_FLAGS;
        let flags = named & named.wrapping_sub(1) == 0 || self.flags_keep_the_rules();
        finite & range & flags
    }

    /// The flag rules of [`Ray::validate`], without branches.
    #[inline(always)]
    fn flags_keep_the_rules(&self) -> bool {
        let f = self.flags.0;
        let skip = RayFlags::SKIP_TRIANGLES.0 | RayFlags::SKIP_AABBS.0;
        let at_most_one = |m: u32| m & m.wrapping_sub(1) == 0;
        (f & skip != skip) & at_most_one(f & Self::CULL_RULE) & at_most_one(f & Self::OPACITY_RULE)
    }

    /// Every flag some rule of [`Ray::validate`] names.
    const RULE_FLAGS: u32 = RayFlags::SKIP_AABBS.0 | Self::CULL_RULE | Self::OPACITY_RULE;

    const CULL_RULE: u32 = RayFlags::SKIP_TRIANGLES.0
        | RayFlags::CULL_BACK_FACING_TRIANGLES.0
        | RayFlags::CULL_FRONT_FACING_TRIANGLES.0;
    const OPACITY_RULE: u32 = RayFlags::OPAQUE.0
        | RayFlags::NO_OPAQUE.0
        | RayFlags::CULL_OPAQUE.0
        | RayFlags::CULL_NO_OPAQUE.0;

    /// The first rule of [`Ray::validate`] the ray breaks, as an error.
    #[cold]
    #[inline(never)]
    fn first_broken_rule(&self) -> Result<()> {
        let bad = |vuid: &'static str, msg: &str| Err(Error::vuid(vuid, Location::NONE, msg));
        // `x * 0` is 0 for every finite `x` and NaN for infinities and NaN.
        let [o, d] = [self.origin, self.direction];
        let zero = (o[0] * 0.0 + o[1] * 0.0 + o[2] * 0.0) + (d[0] * 0.0 + d[1] * 0.0 + d[2] * 0.0);
        if zero != 0.0 {
            return bad(
                "VUID-RuntimeSpirv-OpRayQueryInitializeKHR-06348",
                "ray origin and direction must be finite",
            );
        }
        if self.t_min.is_nan() || self.t_max.is_nan() {
            return bad(
                "VUID-RuntimeSpirv-OpRayQueryInitializeKHR-06351",
                "tMin and tMax must not be NaN",
            );
        }
        if !(self.t_min >= 0.0 && self.t_max >= 0.0) {
            return bad(
                "VUID-RuntimeSpirv-OpRayQueryInitializeKHR-06349",
                "tMin and tMax must be non-negative",
            );
        }
        if self.t_min > self.t_max {
            return bad(
                "VUID-RuntimeSpirv-OpRayQueryInitializeKHR-06350",
                "tMin must be less than or equal to tMax",
            );
        }
        let f = self.flags;
        if f.contains(RayFlags::SKIP_TRIANGLES | RayFlags::SKIP_AABBS) {
            return bad(
                "VUID-RuntimeSpirv-OpRayQueryInitializeKHR-06889",
                "SkipTriangles and SkipAABBs must not both be set",
            );
        }
        if (f.0 & Self::CULL_RULE).count_ones() > 1 {
            return bad(
                "VUID-RuntimeSpirv-OpRayQueryInitializeKHR-06890",
                "at most one of SkipTriangles, CullBackFacingTriangles and CullFrontFacingTriangles may be set",
            );
        }
        if (f.0 & Self::OPACITY_RULE).count_ones() > 1 {
            return bad(
                "VUID-RuntimeSpirv-OpRayQueryInitializeKHR-06891",
                "at most one of Opaque, NoOpaque, CullOpaque and CullNoOpaque may be set",
            );
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The one-branch check and the rule-by-rule check agree on every flag combination and
    /// on origins, directions and ranges at the edges of each rule.
    #[test]
    fn fast_validation_agrees_with_the_rules() {
        let (inf, nan) = (f32::INFINITY, f32::NAN);
        let vectors = [
            [0.0, 1.0, -2.0],
            [inf, 0.0, 0.0],
            [0.0, -inf, 0.0],
            [0.0, 0.0, nan],
        ];
        let ranges = [
            (0.0, inf),
            (0.0, 0.0),
            (1.0, 0.5),
            (-0.0, 1.0),
            (-1.0, 1.0),
            (0.0, -1.0),
            (nan, 1.0),
            (0.0, nan),
            (inf, inf),
        ];
        let mut rejected = 0;
        for f in 0..0x800u32 {
            for o in vectors {
                for d in vectors {
                    for (t_min, t_max) in ranges {
                        let ray = Ray {
                            origin: o,
                            direction: d,
                            t_min,
                            t_max,
                            flags: RayFlags(f),
                            cull_mask: 0xff,
                        };
                        let slow = ray.first_broken_rule().is_ok();
                        assert_eq!(ray.plainly_valid(), slow, "{ray:?}");
                        assert_eq!(ray.validate().is_ok(), slow);
                        rejected += usize::from(!slow);
                    }
                }
            }
        }
        assert!(rejected > 0);
    }
}
