//! Watertight ray/triangle intersection (Woop, Benthin and Wald, JCGT 2013) with a
//! deterministic rule for rays exactly through edges and vertices.
//!
//! The ray is sheared so that it runs along +z'; the three 2D edge functions `u, v, w` then
//! decide coverage. Rounding is consistent across triangles that share an edge (the edge
//! function of the neighbour is the exact negation), so no ray slips between them. When an edge
//! function is exactly zero (recomputed in f64, which is exact for products of f32), the point
//! lies on that edge: it belongs to the triangle only if the edge, oriented counter-clockwise,
//! points "up" (or exactly "right"), a top-left rule. Of two triangles that share the edge
//! with the same winding, exactly one owns it, and of a closed fan exactly one owns the vertex.

use crate::math::{Vec3, lanes};
use wide::{f32x4, f32x8};

/// A ray prepared for the watertight test.
#[derive(Clone, Copy, Debug)]
pub struct ShearedRay {
    pub origin: Vec3,
    /// Which of the six axis permutations [`AXES`] the ray uses (`kz` is the dominant axis of
    /// the direction; `kx, ky` are swapped when it points down `kz`, keeping the winding).
    pub perm: usize,
    sx: f32,
    sy: f32,
    sz: f32,
}

/// The axis permutations `(kx, ky, kz)` a [`ShearedRay`] can use.
pub const AXES: [(usize, usize, usize); 6] = [
    (1, 2, 0),
    (2, 1, 0),
    (2, 0, 1),
    (0, 2, 1),
    (0, 1, 2),
    (1, 0, 2),
];

/// A ray/triangle intersection before range checks.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TriangleHit {
    pub t: f32,
    /// Weight of vertex 1 (the spec's barycentric `b`).
    pub b: f32,
    /// Weight of vertex 2 (the spec's barycentric `c`).
    pub c: f32,
    /// The triangle faces the ray (vertices appear counter-clockwise from the ray's origin in
    /// a right-handed system: the spec's "front face", before `FLIP_FACING`).
    pub front_face: bool,
}

/// The sheared triangle: 2D vertex positions `x, y` relative to the ray, and the unscaled
/// depths `z` along the dominant axis.
struct Sheared {
    x: [f32; 3],
    y: [f32; 3],
    z: [f32; 3],
}

/// Which of the [`AXES`] permutations a ray with direction `dir` uses: `kz` is the dominant
/// axis, and `kx, ky` are swapped when the ray points down `kz` (keeping the winding).
#[inline(always)]
pub fn permutation(dir: Vec3) -> usize {
    // Three comparisons of the magnitudes and three signs, each set made by one vector
    // comparison, index a table of the answers (fewer instructions than the scalar chain of
    // comparisons and selects it replaces).
    let a = dir.map(f32::abs);
    let ge = f32x4::from([a[0], a[0], a[1], 0.0]).simd_ge(f32x4::from([a[1], a[2], a[2], 0.0]));
    // Signs as the box test sees them (the sign of `1 / d`, so -0 points down): a walk
    // instantiated for `P` reads the dominant axis's planes by it.
    let down = lanes(dir).to_bitmask();
    let index = (ge.to_bitmask() & 7) | (down & 7) << 3;
    PERMUTATION_OF[index as usize & 63] as usize
}

/// [`permutation`] by `a0 >= a1 | a0 >= a2 << 1 | a1 >= a2 << 2 | (signs of x, y, z) << 3`
/// (`a` the magnitudes of the direction, a sign bit set when the component is negative, -0
/// included).
const PERMUTATION_OF: [u8; 64] = {
    let mut table = [0; 64];
    let mut i = 0;
    while i < 64 {
        let kz = if i & 3 == 3 {
            0
        } else if i & 4 != 0 {
            1
        } else {
            2
        };
        table[i] = (2 * kz + (i >> (3 + kz) & 1)) as u8;
        i += 1;
    }
    table
};

/// `$body` with the const `$p` set to the permutation `$perm` (0 to 5, read at run time): one
/// dispatch for every function instantiated per permutation.
macro_rules! by_permutation {
    ($perm:expr, $p:ident => $body:expr) => {
        by_permutation!(@arms $perm, $p, $body, 0 1 2 3 4)
    };
    (@arms $perm:expr, $p:ident, $body:expr, $($k:literal)*) => {
        match $perm {
            $($k => {
                const $p: usize = $k;
                $body
            })*
            _ => {
                const $p: usize = 5;
                $body
            }
        }
    };
}
pub(crate) use by_permutation;

impl ShearedRay {
    #[inline(always)]
    pub fn new(origin: Vec3, dir: Vec3) -> ShearedRay {
        let perm = permutation(dir);
        let (kx, ky, kz) = AXES[perm];
        let sz = 1.0 / dir[kz];
        ShearedRay {
            origin,
            perm,
            sx: dir[kx] * sz,
            sy: dir[ky] * sz,
            sz,
        }
    }

    /// [`ShearedRay::new`] for a ray whose [`permutation`] is `P`, given `inv = 1 / dir` per
    /// axis (the box test's): no run-time axis indexing, no division.
    #[inline(always)]
    pub fn for_axes<const P: usize>(origin: Vec3, dir: Vec3, inv: Vec3) -> ShearedRay {
        let (kx, ky, kz) = AXES[P];
        let sz = inv[kz];
        ShearedRay {
            origin,
            perm: P,
            sx: dir[kx] * sz,
            sy: dir[ky] * sz,
            sz,
        }
    }

    /// Intersects the triangle `v` (three vertices, nine floats). Returns the hit for any
    /// `t`; the caller applies the range. `None` when the ray misses or the projected area is
    /// zero (the spec culls such triangles unconditionally).
    #[inline(always)]
    pub fn intersect(&self, v: &[f32; 9]) -> Option<TriangleHit> {
        by_permutation!(self.perm, P => self.intersect_axes::<P>(v))
    }

    /// [`ShearedRay::intersect`] for a ray whose `perm` is `P`, with the axes known at compile
    /// time (the batch tracer instantiates its whole bottom-level loop per permutation).
    #[inline(always)]
    pub fn intersect_axes<const P: usize>(&self, v: &[f32; 9]) -> Option<TriangleHit> {
        let (kx, ky, kz) = AXES[P];
        let o = self.origin;
        let v: &[[f32; 3]; 3] = bytemuck::cast_ref(v);
        let [a, b, c] = v.map(|p| [p[0] - o[0], p[1] - o[1], p[2] - o[2]]);
        let s = Sheared {
            x: [
                a[kx] - self.sx * a[kz],
                b[kx] - self.sx * b[kz],
                c[kx] - self.sx * c[kz],
            ],
            y: [
                a[ky] - self.sy * a[kz],
                b[ky] - self.sy * b[kz],
                c[ky] - self.sy * c[kz],
            ],
            z: [a[kz], b[kz], c[kz]],
        };
        let [ax, bx, cx] = s.x;
        let [ay, by, cy] = s.y;
        let u = cx * by - cy * bx;
        let v = ax * cy - ay * cx;
        let w = bx * ay - by * ax;
        // Bitwise, not short-circuit: one branch per outcome instead of one per comparison
        // (whether a ray covers a triangle is data-dependent; mispredictions cost more than
        // the extra comparisons).
        if (u == 0.0) | (v == 0.0) | (w == 0.0) {
            return on_edge(self.sz, s);
        }
        if ((u < 0.0) | (v < 0.0) | (w < 0.0)) & ((u > 0.0) | (v > 0.0) | (w > 0.0)) {
            return None;
        }
        hit(self.sz, &s.z, u, v, w)
    }

    /// [`ShearedRay::intersect_rows`] for the ray's `perm`, known at run time.
    #[inline(always)]
    pub fn intersect_rows_any(&self, rows: &[f32; 12]) -> Option<TriangleHit> {
        by_permutation!(self.perm, P => self.intersect_rows::<P>(rows))
    }

    /// [`ShearedRay::intersect_axes`] for a triangle given as rows (the x coordinates of its
    /// vertices in index order, then their y, then their z, each row padded to four floats):
    /// the same operations on the same values, a row at a time.
    #[inline(always)]
    pub fn intersect_rows<const P: usize>(&self, rows: &[f32; 12]) -> Option<TriangleHit> {
        let (kx, ky, kz) = AXES[P];
        let o = self.origin;
        let row = |k: usize| {
            let r = [
                rows[4 * k],
                rows[4 * k + 1],
                rows[4 * k + 2],
                rows[4 * k + 3],
            ];
            f32x4::from(r) - f32x4::splat(o[k])
        };
        let z = row(kz);
        let x = row(kx) - f32x4::splat(self.sx) * z;
        let y = row(ky) - f32x4::splat(self.sy) * z;
        // Lanes 0, 1 and 2 are the vertices in index order: lane `j` of `vwu` is the edge
        // function of the edge from vertex `j - 1` (cyclically) to vertex `j`, the same
        // products and difference as `intersect_axes` (lane 0 is `v = ax * cy - ay * cx`,
        // lane 2 is `u = cx * by - cy * bx`), two shuffles in all. The padding lane is never
        // read, and the tests on all three lanes do not depend on their order.
        let prev = |v: f32x4| {
            let [a, b, c, d] = v.to_array();
            f32x4::from([c, a, b, d])
        };
        let vwu = x * prev(y) - y * prev(x);
        let zero = f32x4::ZERO;
        let lanes = |m: f32x4| m.to_bitmask() & 0b111;
        let [v, w, u, _] = vwu.to_array();
        let [ax, bx, cx, _] = x.to_array();
        let [ay, by, cy, _] = y.to_array();
        let [az, bz, cz, _] = z.to_array();
        let s = Sheared {
            x: [ax, bx, cx],
            y: [ay, by, cy],
            z: [az, bz, cz],
        };
        // As in `intersect_axes`: one branch per outcome.
        if lanes(vwu.simd_eq(zero)) != 0 {
            return on_edge(self.sz, s);
        }
        // With no zero, the signs are mixed when the sign bits are: one mask, one range
        // check. (A NaN lane, whose sign bit is either, gives `None` either way: `hit`
        // rejects a NaN edge function through its NaN `t`.)
        if matches!(lanes(vwu), 1..=6) {
            return None;
        }
        hit(self.sz, &s.z, u, v, w)
    }
}

/// Eight triangles' [`Edges8::hits`] results, lane `j` for triangle `j`.
pub struct Hits8 {
    pub t: f32x8,
    pub det: f32x8,
    /// The edge functions whose ratios to `det` are the barycentrics `b` and `c`.
    pub v: f32x8,
    pub w: f32x8,
    /// Lanes the ray hits (at any `t`): what [`ShearedRay::intersect_axes`] returns `Some` for,
    /// among the lanes not in [`Edges8::edge`].
    pub hit: u32,
}

impl Hits8 {
    /// Lane `j`'s hit, as [`ShearedRay::intersect_axes`] returns it (the same operations on
    /// the same values: the same bits).
    #[inline(always)]
    pub fn lane(&self, j: usize) -> TriangleHit {
        let j = j & 7;
        let lane = |x: f32x8| x.to_array()[j];
        TriangleHit::at(lane(self.t), lane(self.det), lane(self.v), lane(self.w))
    }
}

/// The first half of the eight-lane test ([`ShearedRay::edges8`]): the edge functions and
/// which lanes they decide. The second half ([`Edges8::hits`]) is only worth its division
/// where some lane is `covered`: most leaves a ray reaches hold no triangle it passes through.
#[derive(Clone, Copy)]
pub struct Edges8 {
    u: f32x8,
    v: f32x8,
    w: f32x8,
    /// Each vertex's component on the ray's dominant axis, relative to the origin.
    z: [f32x8; 3],
    /// Lanes with an edge function exactly zero, which only the scalar test decides (its
    /// exact recomputation and top-left rule).
    pub edge: u32,
    /// Lanes (not in `edge`) whose edge functions share a sign: the ray passes through the
    /// triangle's plane inside it, a hit unless the determinant is zero or `t` NaN.
    pub covered: u32,
}

impl ShearedRay {
    /// [`ShearedRay::intersect_axes`] for eight triangles at once, up to the edge functions:
    /// `rows[3 * i + k]` holds component `k` of vertex `i` of each lane's triangle. Every
    /// lane takes the scalar test's operations in the same order (no fused products), so a
    /// lane's edge functions, and then its determinant and `t` ([`Edges8::hits`]), are the
    /// scalar test's bits.
    #[inline(always)]
    pub fn edges8<const P: usize>(&self, rows: &[f32x8; 9]) -> Edges8 {
        let (kx, ky, kz) = AXES[P];
        let s = f32x8::splat;
        let o = self.origin.map(s);
        let vertex = |i: usize| [0, 1, 2].map(|k| rows[3 * i + k] - o[k]);
        let [a, b, c] = [vertex(0), vertex(1), vertex(2)];
        let (sx, sy) = (s(self.sx), s(self.sy));
        let [ax, bx, cx] = [a, b, c].map(|p| p[kx] - sx * p[kz]);
        let [ay, by, cy] = [a, b, c].map(|p| p[ky] - sy * p[kz]);
        let u = cx * by - cy * bx;
        let v = ax * cy - ay * cx;
        let w = bx * ay - by * ax;
        let zero = f32x8::ZERO;
        let edge = u.simd_eq(zero) | v.simd_eq(zero) | w.simd_eq(zero);
        let mixed = (u.simd_lt(zero) | v.simd_lt(zero) | w.simd_lt(zero))
            & (u.simd_gt(zero) | v.simd_gt(zero) | w.simd_gt(zero));
        Edges8 {
            u,
            v,
            w,
            z: [a[kz], b[kz], c[kz]],
            edge: edge.to_bitmask(),
            covered: (!(edge | mixed)).to_bitmask(),
        }
    }
}

impl Edges8 {
    /// The test's second half for `ray` (the one [`ShearedRay::edges8`] was made with).
    #[inline(always)]
    pub fn hits(&self, ray: &ShearedRay) -> Hits8 {
        let Edges8 { u, v, w, z, .. } = *self;
        let zero = f32x8::ZERO;
        let det = u + v + w;
        let sz = f32x8::splat(ray.sz);
        let t = (u * (sz * z[0]) + v * (sz * z[1]) + w * (sz * z[2])) / det;
        // `t == t`: not NaN. A zero determinant or mixed signs miss, as in `hit`.
        let hit = self.covered & (det.simd_ne(zero) & t.simd_eq(t)).to_bitmask();
        Hits8 { t, det, v, w, hit }
    }
}

/// The rare case of an edge function that is zero in f32: recomputed exactly, and when it
/// is exactly zero the point is on the edge and the top-left rule decides.
/// Takes the sheared triangle and the ray's scale by value: by reference, every test would
/// have to store them to memory for this rare call.
#[cold]
#[inline(never)]
fn on_edge(sz: f32, s: Sheared) -> Option<TriangleHit> {
    let [ax, bx, cx] = s.x.map(f64::from);
    let [ay, by, cy] = s.y.map(f64::from);
    let exact = [cx * by - cy * bx, ax * cy - ay * cx, bx * ay - by * ax];
    // The f64 results are exact in sign; a value that rounds to zero in f32 is kept as
    // the smallest subnormal with the right sign.
    let [u, v, w] = exact.map(|e| {
        let f = e as f32;
        if f == 0.0 && e != 0.0 {
            f32::from_bits(1).copysign(e.signum() as f32)
        } else {
            f
        }
    });
    if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
        return None;
    }
    let det = u + v + w;
    if det == 0.0 {
        return None;
    }
    let sign = if det > 0.0 { 1.0f64 } else { -1.0 };
    // Edge opposite each vertex, in the cyclic order b->c, c->a, a->b.
    let owns = |e0: f64, e1: f64| {
        let (ex, ey) = (sign * e0, sign * e1);
        ey > 0.0 || (ey == 0.0 && ex > 0.0)
    };
    if u == 0.0 && !owns(cx - bx, cy - by) {
        return None;
    }
    if v == 0.0 && !owns(ax - cx, ay - cy) {
        return None;
    }
    if w == 0.0 && !owns(bx - ax, by - ay) {
        return None;
    }
    hit(sz, &s.z, u, v, w)
}

/// The hit of a ray (depth scale `sz`) inside the triangle with edge functions `u, v, w`.
#[inline(always)]
fn hit(sz: f32, z: &[f32; 3], u: f32, v: f32, w: f32) -> Option<TriangleHit> {
    let det = u + v + w;
    if det == 0.0 {
        return None;
    }
    let [az, bz, cz] = z.map(|z| sz * z);
    let t_scaled = u * az + v * bz + w * cz;
    let t = t_scaled / det; // one rounding, not two: the spec asks for as much precision as possible
    if t.is_nan() {
        return None;
    }
    Some(TriangleHit::at(t, det, v, w))
}

impl TriangleHit {
    /// The hit at `t` of a triangle with determinant `det` and edge functions `v, w` (of the
    /// edges opposite vertices 1 and 2): the barycentrics by one reciprocal, facing by sign.
    #[inline(always)]
    fn at(t: f32, det: f32, v: f32, w: f32) -> TriangleHit {
        let rcp = 1.0 / det;
        TriangleHit {
            t,
            b: v * rcp,
            c: w * rcp,
            front_face: det > 0.0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tri(p: [[f32; 3]; 3]) -> [f32; 9] {
        [
            p[0][0], p[0][1], p[0][2], p[1][0], p[1][1], p[1][2], p[2][0], p[2][1], p[2][2],
        ]
    }

    /// `permutation` avoids indexing by `kz`; it must pick what the definition says, for
    /// signed zeros, ties and non-finite components too, and `for_axes` must agree with `new`.
    #[test]
    fn permutation_and_for_axes_follow_the_definition() {
        let values = [
            0.0,
            -0.0,
            1.0,
            -1.0,
            0.5,
            -2.0,
            f32::INFINITY,
            -f32::INFINITY,
            1e-30,
        ];
        for x in values {
            for y in values {
                for z in values {
                    let d = [x, y, z];
                    let a = d.map(f32::abs);
                    let kz = if a[0] >= a[1] && a[0] >= a[2] {
                        0
                    } else if a[1] >= a[2] {
                        1
                    } else {
                        2
                    };
                    let perm = 2 * kz + usize::from(d[kz].is_sign_negative());
                    assert_eq!(permutation(d), perm, "{d:?}");
                    let inv = d.map(|c| 1.0 / c);
                    let o = [0.5, -0.25, 2.0];
                    let r = ShearedRay::new(o, d);
                    let f = match perm {
                        0 => ShearedRay::for_axes::<0>(o, d, inv),
                        1 => ShearedRay::for_axes::<1>(o, d, inv),
                        2 => ShearedRay::for_axes::<2>(o, d, inv),
                        3 => ShearedRay::for_axes::<3>(o, d, inv),
                        4 => ShearedRay::for_axes::<4>(o, d, inv),
                        _ => ShearedRay::for_axes::<5>(o, d, inv),
                    };
                    let bits = |r: &ShearedRay| (r.perm, [r.sx, r.sy, r.sz].map(f32::to_bits));
                    assert_eq!(bits(&r), bits(&f), "{d:?}");
                }
            }
        }
    }

    #[test]
    fn spec_worked_example_facing() {
        // Ray along -z; (0,1,0),(0,0,0),(1,1,0) is front-facing, the reverse order is not.
        let r = ShearedRay::new([0.25, 0.5, 1.0], [0.0, 0.0, -1.0]);
        let front = r
            .intersect(&tri([[0.0, 1.0, 0.0], [0.0, 0.0, 0.0], [1.0, 1.0, 0.0]]))
            .unwrap();
        assert!(front.front_face);
        assert_eq!(front.t, 1.0);
        let back = r
            .intersect(&tri([[1.0, 1.0, 0.0], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0]]))
            .unwrap();
        assert!(!back.front_face);
    }

    #[test]
    fn barycentrics_weight_vertices_one_and_two() {
        let r = ShearedRay::new([0.2, 0.3, 1.0], [0.0, 0.0, -1.0]);
        let h = r
            .intersect(&tri([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]))
            .unwrap();
        assert!((h.b - 0.2).abs() < 1e-6 && (h.c - 0.3).abs() < 1e-6);
    }

    #[test]
    fn shared_diagonal_is_hit_exactly_once() {
        // The CTS checkerboard cell: the ray through the centre lies on the shared diagonal.
        let v0 = [0.0, 1.0, 0.0];
        let v1 = [0.0, 0.0, 0.0];
        let v2 = [1.0, 1.0, 0.0];
        let v3 = [1.0, 0.0, 0.0];
        for dir in [[0.0f32, 0.0, -1.0], [0.0, 0.0, 1.0], [0.3, -0.2, -1.0]] {
            let origin = [
                0.5 - 0.5 * dir[0] / dir[2].abs(),
                0.5 - 0.5 * dir[1] / dir[2].abs(),
                if dir[2] < 0.0 { 0.5 } else { -0.5 },
            ];
            let r = ShearedRay::new(origin, dir);
            let hits = [tri([v0, v1, v2]), tri([v2, v1, v3])]
                .iter()
                .filter(|t| r.intersect(t).is_some())
                .count();
            assert_eq!(hits, 1, "dir {dir:?}");
        }
    }

    #[test]
    fn zero_area_is_never_hit() {
        let r = ShearedRay::new([0.5, 0.0, 1.0], [0.0, 0.0, -1.0]);
        assert!(
            r.intersect(&tri([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]]))
                .is_none()
        );
    }
}
