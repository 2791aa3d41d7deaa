//! Small vector helpers and transform constructors for the command's scenes and cameras.

use hostas::Affine;

pub type V3 = [f32; 3];

pub fn add(a: V3, b: V3) -> V3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
pub fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
pub fn scale(a: V3, s: f32) -> V3 {
    [a[0] * s, a[1] * s, a[2] * s]
}
pub fn mul(a: V3, b: V3) -> V3 {
    [a[0] * b[0], a[1] * b[1], a[2] * b[2]]
}
pub fn dot(a: V3, b: V3) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
pub fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
pub fn length(a: V3) -> f32 {
    dot(a, a).sqrt()
}
/// `a` scaled to unit length; the zero vector stays zero.
pub fn normalize(a: V3) -> V3 {
    let l = length(a);
    if l > 0.0 && l.is_finite() {
        scale(a, 1.0 / l)
    } else {
        [0.0; 3]
    }
}
pub fn lerp(a: V3, b: V3, t: f32) -> V3 {
    add(scale(a, 1.0 - t), scale(b, t))
}

/// The product `a * b` of two affine transforms (apply `b` first).
pub fn compose(a: &Affine, b: &Affine) -> Affine {
    let mut out = Affine::IDENTITY;
    for r in 0..3 {
        for c in 0..4 {
            let mut v = if c == 3 { a.m[r][3] } else { 0.0 };
            for k in 0..3 {
                v += a.m[r][k] * b.m[k][c];
            }
            out.m[r][c] = v;
        }
    }
    out
}

pub fn translation(t: V3) -> Affine {
    Affine::from_rows([
        1.0, 0.0, 0.0, t[0], 0.0, 1.0, 0.0, t[1], 0.0, 0.0, 1.0, t[2],
    ])
}
pub fn scaling(s: V3) -> Affine {
    Affine::from_rows([
        s[0], 0.0, 0.0, 0.0, 0.0, s[1], 0.0, 0.0, 0.0, 0.0, s[2], 0.0,
    ])
}
/// Rotation by `angle` radians about the unit `axis` (right-handed).
pub fn rotation(axis: V3, angle: f32) -> Affine {
    let [x, y, z] = normalize(axis);
    let (s, c) = angle.sin_cos();
    let t = 1.0 - c;
    Affine::from_rows([
        t * x * x + c,
        t * x * y - s * z,
        t * x * z + s * y,
        0.0,
        t * x * y + s * z,
        t * y * y + c,
        t * y * z - s * x,
        0.0,
        t * x * z - s * y,
        t * y * z + s * x,
        t * z * z + c,
        0.0,
    ])
}

/// Applies the transpose of the linear part of `m` to `v`: with `m` the world-to-object
/// transform, this takes an object-space normal to world space.
pub fn transpose_vector(m: &Affine, v: V3) -> V3 {
    let m = &m.m;
    [
        m[0][0] * v[0] + m[1][0] * v[1] + m[2][0] * v[2],
        m[0][1] * v[0] + m[1][1] * v[1] + m[2][1] * v[2],
        m[0][2] * v[0] + m[1][2] * v[1] + m[2][2] * v[2],
    ]
}

/// A small, fast, deterministic random generator (xorshift64*).
#[derive(Clone, Debug)]
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Rng {
        Rng(seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1)
    }
    pub fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
    /// Uniform in `[0, 1)`.
    pub fn f32(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }
    pub fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.f32()
    }
    /// A uniformly distributed unit vector.
    pub fn unit_vector(&mut self) -> V3 {
        let z = self.range(-1.0, 1.0);
        let phi = self.range(0.0, std::f32::consts::TAU);
        let r = (1.0 - z * z).max(0.0).sqrt();
        [r * phi.cos(), r * phi.sin(), z]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: V3, b: V3) -> bool {
        (0..3).all(|k| (a[k] - b[k]).abs() < 1e-5)
    }

    #[test]
    fn compose_applies_right_first() {
        let t = compose(&translation([1.0, 2.0, 3.0]), &scaling([2.0, 2.0, 2.0]));
        assert!(close(t.point([1.0, 1.0, 1.0]), [3.0, 4.0, 5.0]));
    }

    #[test]
    fn rotation_is_right_handed() {
        let r = rotation([0.0, 0.0, 1.0], std::f32::consts::FRAC_PI_2);
        assert!(close(r.vector([1.0, 0.0, 0.0]), [0.0, 1.0, 0.0]));
    }

    #[test]
    fn normals_transform_with_inverse_transpose() {
        let m = compose(&rotation([1.0, 1.0, 0.0], 0.7), &scaling([1.0, 3.0, 0.5]));
        let inv = m.inverse().unwrap();
        // A tangent of the plane z = 0 and its normal.
        let (t, n) = ([1.0, 1.0, 0.0], [0.0, 0.0, 1.0]);
        let tw = m.vector(t);
        let nw = transpose_vector(&inv, n);
        assert!(dot(tw, nw).abs() < 1e-5);
    }
}
