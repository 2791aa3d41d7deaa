//! A camera's rays eight at a time against the box around a bottom level's root children: the
//! rays that miss the whole structure (50-83% of the primary rays of the benchmark's scenes,
//! whose camera frames the scene's bounding sphere) are known for misses from vector
//! operations shared by eight rays, where each used to pay its own checks, inverses and the
//! root's node test (about 230 instructions a ray; under 30 here).
//!
//! The screen only ever answers "misses" for a ray the root's own node test
//! ([`BoxRay::node`](super::query::BoxRay::node), whose answer "no child reached" makes a ray a
//! miss on every path) would also find reaching no child: it is that test, the same
//! operations on the same inverses, with each child's planes replaced by the box around all
//! of them. Each plane of that box is one of the children's own planes, at least as far out,
//! and rounding is monotonic, so each of its slab distances is at least as wide as the
//! child's; with no NaN anywhere (planes checked once, origins and inverses finite for a
//! screened ray), a ray that reaches some child reaches the box.

use super::Ray;
use super::query::{ROBUST_FAR, prune_limit8};
use crate::layout::{Node, WIDTH};
use crate::math::{fmax8, fmin8};
use wide::{f32x8, u32x8};

/// Rays screened at once.
pub(super) const LANES: usize = 8;

/// What [`RootBox::screen`] found for up to [`LANES`] rays (bit `k`: the `k`-th ray).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(super) struct Screened {
    /// Rays that keep every rule of [`Ray::validate`] (a ray not here may keep them too: it
    /// sets two or more of the flags the rules name, and is checked on its own).
    pub plain: u32,
    /// Valid rays that reach no child of the root within `[t_min, t_max]`: misses.
    pub outside: u32,
}

/// The box around the children of a bottom level's root.
#[derive(Clone, Copy, Debug)]
pub(super) struct RootBox {
    lo: [f32; 3],
    hi: [f32; 3],
}

impl RootBox {
    /// The box around the children of `root` (empty slots, inverted, add nothing); `None`
    /// where a plane is NaN, which the node test reads as no bound (a structure from
    /// untrusted bytes may hold one): a box would not cover such a child.
    pub(super) fn new(root: &Node) -> Option<RootBox> {
        let rows = root.rows();
        let mut b = RootBox {
            lo: [f32::INFINITY; 3],
            hi: [f32::NEG_INFINITY; 3],
        };
        for (k, &lo_row) in Node::LO_ROWS.iter().enumerate() {
            let (lo, hi) = (rows.get(lo_row)?, rows.get(lo_row + 1)?);
            for c in 0..WIDTH {
                if lo[c].is_nan() || hi[c].is_nan() {
                    return None;
                }
                b.lo[k] = b.lo[k].min(lo[c]);
                b.hi[k] = b.hi[k].max(hi[c]);
            }
        }
        Some(b)
    }

    /// The box from `lo` to `hi`, for the tests.
    #[cfg(test)]
    pub(super) fn around(lo: [f32; 3], hi: [f32; 3]) -> RootBox {
        RootBox { lo, hi }
    }

    /// Screens `rays` (at most the first [`LANES`]).
    #[inline(always)]
    pub(super) fn screen(&self, rays: &[Ray]) -> Screened {
        let Some(first) = rays.first() else {
            return Screened::default();
        };
        // (Lanes past the last ray repeat the first, and are masked off.)
        self.screen_each(rays.len().min(LANES), |k| rays.get(k).unwrap_or(first))
    }

    /// Screens `n` rays (at most [`LANES`]), the `k`-th `ray(k)`.
    #[inline(always)]
    pub(super) fn screen_each<'r>(&self, n: usize, ray: impl Fn(usize) -> &'r Ray) -> Screened {
        let [ox, oy, oz, t_min, dx, dy, dz, t_max] = f32x8::transpose(std::array::from_fn(|k| {
            let r = ray(k);
            let ([x, y, z], [u, v, w]) = (r.origin, r.direction);
            f32x8::from([x, y, z, r.t_min, u, v, w, r.t_max])
        }));
        let flags = u32x8::from(std::array::from_fn(|k| ray(k).flags.0));

        // `Ray::plainly_valid`, lane by lane, for rays that set at most one of the flags the
        // rules name.
        let zero = f32x8::ZERO;
        let finite = |o: f32x8, d: f32x8| (o * zero + d * zero).simd_eq(zero);
        let named = flags & u32x8::splat(Ray::RULE_FLAGS);
        let one_flag = (named & (named - u32x8::splat(1))).simd_eq(u32x8::ZERO);
        let range = zero.simd_le(t_min) & t_min.simd_le(t_max);
        let plain = finite(ox, dx) & finite(oy, dy) & finite(oz, dz) & range;
        let plain = plain.to_bitmask() & one_flag.to_bitmask();

        // `BoxRay::new`'s inverses, and `BoxRay::slabs` (float form) against the box.
        let s = f32x8::splat;
        let mut near = t_min;
        let mut far = fmin8(prune_limit8(t_max), s(f32::MAX));
        let mut inverses = plain;
        for (k, (o, d)) in [(ox, dx), (oy, dy), (oz, dz)].into_iter().enumerate() {
            let inv = f32x8::ONE / d;
            let (neg_inv, neg_inv_far) = (-inv, -(inv * s(ROBUST_FAR)));
            // (Finite and not zero: no NaN below, from a zero or infinite factor.)
            let usable = neg_inv.is_finite() & neg_inv_far.is_finite() & !neg_inv.simd_eq(zero);
            inverses &= usable.to_bitmask();
            let down = inv.is_sign_negative();
            let (lo, hi) = (s(self.lo[k]), s(self.hi[k]));
            near = fmax8((o - down.select(hi, lo)) * neg_inv, near);
            far = fmin8((o - down.select(lo, hi)) * neg_inv_far, far);
        }
        let reach = near.simd_le(far).to_bitmask();
        let lanes = (1u32 << n) - 1;
        Screened {
            plain: plain & lanes,
            outside: inverses & !reach & lanes,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Aabb;
    use crate::traverse::RayFlags;
    use crate::traverse::query::{ANY_AXES, BoxRay};
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64;

    /// A coordinate: often on a coarse grid (origins on planes, rays through corners and
    /// along faces), sometimes a signed zero, a tiny or huge value, or anywhere.
    fn coord(r: &mut Pcg64) -> f32 {
        match r.gen_range(0..10) {
            0..=4 => r.gen_range(-4..=4) as f32 * 0.5,
            5 => [0.0, -0.0][r.gen_range(0..2)],
            6 => [1e-30, -1e-30, 1e30, -1e30][r.gen_range(0..4)],
            _ => r.gen_range(-3.0..3.0),
        }
    }

    fn random_root(r: &mut Pcg64) -> Node {
        let mut root = Node::EMPTY;
        for k in 0..r.gen_range(1..=WIDTH) {
            let lo: [f32; 3] = std::array::from_fn(|_| r.gen_range(-4..=4) as f32 * 0.5);
            let hi = lo.map(|l| l + r.gen_range(0..=4) as f32 * 0.5);
            root.set_bounds(k, &Aabb { lo, hi });
        }
        root
    }

    fn random_ray(r: &mut Pcg64, root: &Node) -> Ray {
        let origin = std::array::from_fn(|_| coord(r));
        let mut direction = std::array::from_fn(|_| coord(r));
        if r.gen_bool(0.3) {
            // Through a corner of a child box (or a point near it).
            let b = root.bounds(0);
            let at: [f32; 3] = std::array::from_fn(|k| [b.lo[k], b.hi[k]][r.gen_range(0..2)]);
            direction = std::array::from_fn(|k| at[k] - origin[k]);
        }
        let mut ray = Ray::new(origin, direction);
        ray.t_min = [0.0, 0.5, 2.0, 1e30][r.gen_range(0..4)];
        ray.t_max = [f32::INFINITY, f32::MAX, 1.0, 4.0, ray.t_min][r.gen_range(0..5)];
        let flags = [
            RayFlags::NONE,
            RayFlags::OPAQUE,
            RayFlags::CULL_BACK_FACING_TRIANGLES,
            RayFlags::OPAQUE | RayFlags::SKIP_TRIANGLES,
            RayFlags::OPAQUE | RayFlags::NO_OPAQUE,
            RayFlags::SKIP_TRIANGLES | RayFlags::SKIP_AABBS,
        ];
        ray.flags = flags[r.gen_range(0..flags.len())];
        match r.gen_range(0..12) {
            0 => ray.origin[r.gen_range(0..3)] = f32::NAN,
            1 => ray.direction[r.gen_range(0..3)] = f32::INFINITY,
            2 => ray.t_min = -1.0,
            3 => (ray.t_min, ray.t_max) = (3.0, 2.0),
            _ => {}
        }
        ray
    }

    /// Whether the node test of `ray` reaches no child of `node` (what makes a ray a miss).
    fn misses(ray: &Ray, node: &Node) -> bool {
        let boxes = BoxRay::new(ray.origin, ray.direction);
        boxes.node::<ANY_AXES>(node, ray.t_min, ray.t_max).0 == 0
    }

    /// Over random roots and adversarial rays (origins on planes, rays through corners, signed
    /// zero, tiny and huge components, every `t` range, invalid rays and flags): a ray screened
    /// as a miss is valid and reaches no child of the root by the root's own node test; a
    /// ray marked plain is valid, and every valid ray that sets at most one of the flags the
    /// rules name is marked plain; and where the inverse is usable, the screen finds exactly
    /// the misses of the node test against the box itself (a node whose one child is it).
    #[test]
    fn the_screen_finds_only_misses_and_finds_the_boxs_misses() {
        let mut r = Pcg64::seed_from_u64(33);
        let (mut rays_seen, mut outside, mut root_misses) = (0, 0, 0);
        for _ in 0..6000 {
            let root = random_root(&mut r);
            let b = RootBox::new(&root).expect("no NaN plane");
            let mut whole = Node::EMPTY;
            whole.set_bounds(0, &Aabb { lo: b.lo, hi: b.hi });
            let n = r.gen_range(1..=LANES);
            let mut rays: Vec<Ray> = (0..n).map(|_| random_ray(&mut r, &root)).collect();
            for ray in rays.iter_mut().filter(|_| r.gen_bool(0.25)) {
                // Ending just before the box: reached only through the prune limit's slack.
                let boxes = BoxRay::new(ray.origin, ray.direction);
                let (hit, t) = boxes.node::<ANY_AXES>(&whole, ray.t_min, ray.t_max);
                if hit & 1 != 0 && t[0] > 1.0 {
                    ray.t_max = t[0] * (1.0 - 1.0 / (1 << 20) as f32);
                }
            }
            let s = b.screen(&rays);
            assert_eq!((s.plain | s.outside) >> n, 0, "lanes past the rays");
            for (k, ray) in rays.iter().enumerate() {
                let bit = 1 << k;
                let valid = ray.validate().is_ok();
                let named = ray.flags.0 & Ray::RULE_FLAGS;
                assert_eq!(
                    s.plain & bit != 0,
                    valid && named.count_ones() <= 1,
                    "{ray:?}"
                );
                if !valid {
                    assert_eq!(s.outside & bit, 0, "{ray:?}");
                    continue;
                }
                rays_seen += 1;
                root_misses += usize::from(misses(ray, &root));
                if s.outside & bit != 0 {
                    outside += 1;
                    assert!(
                        misses(ray, &root),
                        "screened out, but reaches a child: {ray:?}"
                    );
                }
                let inv = ray.direction.map(|d| 1.0 / d);
                let usable = inv
                    .iter()
                    .all(|&i| i != 0.0 && i.is_finite() && (i * ROBUST_FAR).is_finite());
                if s.plain & bit != 0 && usable {
                    assert_eq!(s.outside & bit != 0, misses(ray, &whole), "{ray:?} {b:?}");
                }
            }
        }
        // (Both sides are exercised: many rays screened out, and many that miss every child
        // but not the box, or whose inverse is not usable, left to the node test.)
        let left = root_misses - outside;
        assert!(
            rays_seen > 10_000 && outside > 2_000 && left > 2_000,
            "{rays_seen} {outside} {root_misses}"
        );
    }

    /// A root with a NaN plane (which the node test reads as no bound) gets no box.
    #[test]
    fn a_root_with_a_nan_plane_is_not_screened() {
        let mut root = Node::EMPTY;
        root.set_bounds(
            0,
            &Aabb {
                lo: [0.0; 3],
                hi: [1.0; 3],
            },
        );
        assert!(RootBox::new(&root).is_some());
        root.hi_y[3] = f32::NAN;
        assert!(RootBox::new(&root).is_none());
    }
}
