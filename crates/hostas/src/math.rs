//! Small vector, box and affine-transform types in the spec's conventions.

use bytemuck::{Pod, Zeroable};

pub type Vec3 = [f32; 3];

/// `min` as one instruction (`minss`): unlike `f32::min` it does not special-case NaN; when
/// `a` is NaN it returns `b` (the slab tests rely on that, see `traverse::query::BoxRay`).
#[inline(always)]
pub fn fmin(a: f32, b: f32) -> f32 {
    if a < b { a } else { b }
}
/// `max` as one instruction (`maxss`); see [`fmin`].
#[inline(always)]
pub fn fmax(a: f32, b: f32) -> f32 {
    if a > b { a } else { b }
}

/// Lane-by-lane [`fmin`] and [`fmax`] over `wide` vectors, with their exact semantics (NaN and
/// signed zeros included), so that vector and scalar code compute the same bits: on x86 they
/// are `minps`/`maxps`, which return the second operand unless the first is strictly
/// smaller/larger; elsewhere they go lane by lane.
macro_rules! lanewise_min_max {
    ($min:ident, $max:ident, $t:ty) => {
        #[inline(always)]
        pub fn $min(a: $t, b: $t) -> $t {
            #[cfg(any(target_arch = "x86", target_arch = "x86_64"))]
            return a.fast_min(b);
            #[cfg(not(any(target_arch = "x86", target_arch = "x86_64")))]
            {
                let (a, b) = (a.to_array(), b.to_array());
                <$t>::from(std::array::from_fn(|k| fmin(a[k], b[k])))
            }
        }
        #[inline(always)]
        pub fn $max(a: $t, b: $t) -> $t {
            #[cfg(any(target_arch = "x86", target_arch = "x86_64"))]
            return a.fast_max(b);
            #[cfg(not(any(target_arch = "x86", target_arch = "x86_64")))]
            {
                let (a, b) = (a.to_array(), b.to_array());
                <$t>::from(std::array::from_fn(|k| fmax(a[k], b[k])))
            }
        }
    };
}
lanewise_min_max!(fmin4, fmax4, wide::f32x4);
lanewise_min_max!(fmin8, fmax8, wide::f32x8);

/// Whether [`imin8`] and [`imax8`] are single instructions here (`pminsd`/`pmaxsd`, from
/// SSE4.1; NEON's `smin`/`smax`): where they are not, they cost more than the float forms.
pub const INTEGER_MIN_MAX: bool =
    !cfg!(any(target_arch = "x86", target_arch = "x86_64")) || cfg!(target_feature = "sse4.1");

/// Lane-by-lane minimum and maximum of floats compared by their bits as signed integers: one
/// cycle of latency, where `minps`/`maxps` take four on recent Intel cores. For lanes that
/// are not NaN the integer order is the float order among values without the sign bit, puts
/// every value with the sign bit below those, and reverses the order among them (-0.0 the
/// least). So the maximum of a non-negative value and any others is their float maximum, bit
/// for bit; a minimum is theirs when no lane has the sign bit, and has the sign bit when one
/// does.
#[inline(always)]
pub fn imin8(a: wide::f32x8, b: wide::f32x8) -> wide::f32x8 {
    let (a, b): (wide::i32x8, wide::i32x8) = (bytemuck::cast(a), bytemuck::cast(b));
    bytemuck::cast(a.min(b))
}
/// See [`imin8`].
#[inline(always)]
pub fn imax8(a: wide::f32x8, b: wide::f32x8) -> wide::f32x8 {
    let (a, b): (wide::i32x8, wide::i32x8) = (bytemuck::cast(a), bytemuck::cast(b));
    bytemuck::cast(a.max(b))
}

/// A box as two four-lane vectors (lane 3 unspecified), grown with [`fmin4`]/[`fmax4`] in the
/// operand order of [`Aabb`]'s operations, so it holds the same bits as the scalar box would.
#[derive(Clone, Copy, Debug)]
pub struct Box4 {
    pub lo: wide::f32x4,
    pub hi: wide::f32x4,
}

impl Box4 {
    pub const EMPTY: Box4 = Box4 {
        lo: wide::f32x4::new([f32::INFINITY; 4]),
        hi: wide::f32x4::new([f32::NEG_INFINITY; 4]),
    };

    /// A triangle's box: `Aabb::point(a)`, then `grow(b)`, `grow(c)`.
    #[inline(always)]
    pub fn triangle(a: wide::f32x4, b: wide::f32x4, c: wide::f32x4) -> Box4 {
        Box4 {
            lo: fmin4(fmin4(a, b), c),
            hi: fmax4(fmax4(a, b), c),
        }
    }

    /// `Aabb::union`.
    #[inline(always)]
    pub fn union(self, o: Box4) -> Box4 {
        Box4 {
            lo: fmin4(self.lo, o.lo),
            hi: fmax4(self.hi, o.hi),
        }
    }

    #[inline(always)]
    pub fn grow(&mut self, o: &Box4) {
        *self = self.union(*o);
    }

    /// Grows to hold `p`, ignoring NaN lanes of `p` (the point goes first, so a NaN lane
    /// yields the current bound).
    #[inline(always)]
    pub fn grow_point(&mut self, p: wide::f32x4) {
        self.lo = fmin4(p, self.lo);
        self.hi = fmax4(p, self.hi);
    }

    pub fn aabb(&self) -> Aabb {
        let (lo, hi) = (self.lo.to_array(), self.hi.to_array());
        Aabb {
            lo: [lo[0], lo[1], lo[2]],
            hi: [hi[0], hi[1], hi[2]],
        }
    }
}

/// `v` in lanes 0..3 of a vector (lane 3 zero).
#[inline(always)]
pub fn lanes(v: Vec3) -> wide::f32x4 {
    wide::f32x4::from([v[0], v[1], v[2], 0.0])
}

#[inline(always)]
pub fn sub(a: Vec3, b: Vec3) -> Vec3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
#[inline(always)]
pub fn cross(a: Vec3, b: Vec3) -> Vec3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
#[inline(always)]
pub fn dot(a: Vec3, b: Vec3) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// An axis-aligned box; empty boxes have `lo > hi`.
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
#[repr(C)]
pub struct Aabb {
    pub lo: Vec3,
    pub hi: Vec3,
}

impl Aabb {
    pub const EMPTY: Aabb = Aabb {
        lo: [f32::INFINITY; 3],
        hi: [f32::NEG_INFINITY; 3],
    };

    #[inline(always)]
    pub fn point(p: Vec3) -> Self {
        Aabb { lo: p, hi: p }
    }
    #[inline(always)]
    pub fn grow(&mut self, p: Vec3) {
        for k in 0..3 {
            self.lo[k] = fmin(self.lo[k], p[k]);
            self.hi[k] = fmax(self.hi[k], p[k]);
        }
    }
    #[inline(always)]
    pub fn union(&self, o: &Aabb) -> Aabb {
        Aabb {
            lo: [
                fmin(self.lo[0], o.lo[0]),
                fmin(self.lo[1], o.lo[1]),
                fmin(self.lo[2], o.lo[2]),
            ],
            hi: [
                fmax(self.hi[0], o.hi[0]),
                fmax(self.hi[1], o.hi[1]),
                fmax(self.hi[2], o.hi[2]),
            ],
        }
    }
    pub fn is_empty(&self) -> bool {
        !(self.lo[0] <= self.hi[0] && self.lo[1] <= self.hi[1] && self.lo[2] <= self.hi[2])
    }
    /// Half the surface area (the SAH only needs ratios).
    #[inline(always)]
    pub fn half_area(&self) -> f32 {
        if self.is_empty() {
            return 0.0;
        }
        let d = sub(self.hi, self.lo);
        d[0] * d[1] + d[1] * d[2] + d[2] * d[0]
    }
    #[inline(always)]
    pub fn center2(&self) -> Vec3 {
        [
            self.lo[0] + self.hi[0],
            self.lo[1] + self.hi[1],
            self.lo[2] + self.hi[2],
        ]
    }
}

/// `VkTransformMatrixKHR`: a row-major 3x4 matrix; columns 0..2 are the linear part, column 3
/// the translation.
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
#[repr(C)]
pub struct Affine {
    pub m: [[f32; 4]; 3],
}

impl Affine {
    pub const IDENTITY: Affine = Affine {
        m: [
            [1.0, 0.0, 0.0, 0.0],
            [0.0, 1.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, 0.0],
        ],
    };

    pub fn from_rows(r: [f32; 12]) -> Self {
        Affine {
            m: [
                [r[0], r[1], r[2], r[3]],
                [r[4], r[5], r[6], r[7]],
                [r[8], r[9], r[10], r[11]],
            ],
        }
    }
    pub fn to_rows(&self) -> [f32; 12] {
        bytemuck::cast(self.m)
    }
    #[inline(always)]
    pub fn point(&self, p: Vec3) -> Vec3 {
        let m = &self.m;
        [
            m[0][0] * p[0] + m[0][1] * p[1] + m[0][2] * p[2] + m[0][3],
            m[1][0] * p[0] + m[1][1] * p[1] + m[1][2] * p[2] + m[1][3],
            m[2][0] * p[0] + m[2][1] * p[1] + m[2][2] * p[2] + m[2][3],
        ]
    }
    #[inline(always)]
    pub fn vector(&self, v: Vec3) -> Vec3 {
        let m = &self.m;
        [
            m[0][0] * v[0] + m[0][1] * v[1] + m[0][2] * v[2],
            m[1][0] * v[0] + m[1][1] * v[1] + m[1][2] * v[2],
            m[2][0] * v[0] + m[2][1] * v[1] + m[2][2] * v[2],
        ]
    }
    /// Determinant of the linear part, in f64.
    pub fn determinant(&self) -> f64 {
        let m = |r: usize, c: usize| self.m[r][c] as f64;
        m(0, 0) * (m(1, 1) * m(2, 2) - m(1, 2) * m(2, 1))
            - m(0, 1) * (m(1, 0) * m(2, 2) - m(1, 2) * m(2, 0))
            + m(0, 2) * (m(1, 0) * m(2, 1) - m(1, 1) * m(2, 0))
    }
    /// The inverse, computed in f64; `None` when the linear part is singular or not finite.
    pub fn inverse(&self) -> Option<Affine> {
        let det = self.determinant();
        if det == 0.0 || !det.is_finite() {
            return None;
        }
        let m = |r: usize, c: usize| self.m[r][c] as f64;
        let inv_det = 1.0 / det;
        let mut l = [[0f64; 3]; 3];
        l[0][0] = (m(1, 1) * m(2, 2) - m(1, 2) * m(2, 1)) * inv_det;
        l[0][1] = (m(0, 2) * m(2, 1) - m(0, 1) * m(2, 2)) * inv_det;
        l[0][2] = (m(0, 1) * m(1, 2) - m(0, 2) * m(1, 1)) * inv_det;
        l[1][0] = (m(1, 2) * m(2, 0) - m(1, 0) * m(2, 2)) * inv_det;
        l[1][1] = (m(0, 0) * m(2, 2) - m(0, 2) * m(2, 0)) * inv_det;
        l[1][2] = (m(0, 2) * m(1, 0) - m(0, 0) * m(1, 2)) * inv_det;
        l[2][0] = (m(1, 0) * m(2, 1) - m(1, 1) * m(2, 0)) * inv_det;
        l[2][1] = (m(0, 1) * m(2, 0) - m(0, 0) * m(2, 1)) * inv_det;
        l[2][2] = (m(0, 0) * m(1, 1) - m(0, 1) * m(1, 0)) * inv_det;
        let t = [m(0, 3), m(1, 3), m(2, 3)];
        let mut out = Affine::IDENTITY;
        for r in 0..3 {
            for c in 0..3 {
                out.m[r][c] = l[r][c] as f32;
            }
            out.m[r][3] = -(l[r][0] * t[0] + l[r][1] * t[1] + l[r][2] * t[2]) as f32;
        }
        out.m.iter().flatten().all(|v| v.is_finite()).then_some(out)
    }
    /// The box that contains this transform applied to `b`.
    pub fn transform_aabb(&self, b: &Aabb) -> Aabb {
        if b.is_empty() {
            return Aabb::EMPTY;
        }
        let mut out = Aabb::EMPTY;
        for i in 0..8 {
            let p = [
                if i & 1 == 0 { b.lo[0] } else { b.hi[0] },
                if i & 2 == 0 { b.lo[1] } else { b.hi[1] },
                if i & 4 == 0 { b.lo[2] } else { b.hi[2] },
            ];
            out.grow(self.point(p));
        }
        // Widen by a few ulps so that rounding in the corner products never loses a hit.
        for k in 0..3 {
            let pad = (out.hi[k] - out.lo[k])
                .abs()
                .max(out.lo[k].abs())
                .max(out.hi[k].abs())
                * 4.0
                * f32::EPSILON;
            out.lo[k] -= pad;
            out.hi[k] += pad;
        }
        out
    }
}

/// Cache hints: `safe_arch`'s prefetch instructions on x86 with SSE, nothing elsewhere.
#[cfg(all(
    any(target_arch = "x86", target_arch = "x86_64"),
    target_feature = "sse"
))]
mod hint {
    pub use safe_arch::{prefetch_et0 as for_write, prefetch_t0 as for_read};
}
#[cfg(not(all(
    any(target_arch = "x86", target_arch = "x86_64"),
    target_feature = "sse"
)))]
mod hint {
    pub fn for_write<T>(_: &T) {}
    pub fn for_read<T>(_: &T) {}
}

/// Asks the caches for the line holding `x`, about to be written: a hint for scattered writes
/// whose addresses are known well ahead (no effect on any result).
#[inline(always)]
pub fn prefetch_for_write<T>(x: &T) {
    hint::for_write(x);
}

/// Asks the caches for the line holding `x`, about to be read (a hint; no effect on results).
#[inline(always)]
pub fn prefetch<T>(x: &T) {
    hint::for_read(x);
}
