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

use crate::math::Vec3;

/// A ray prepared for the watertight test.
#[derive(Clone, Copy, Debug)]
pub struct ShearedRay {
    pub origin: Vec3,
    kx: usize,
    ky: usize,
    kz: usize,
    sx: f32,
    sy: f32,
    sz: f32,
}

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

impl ShearedRay {
    pub fn new(origin: Vec3, dir: Vec3) -> ShearedRay {
        let a = dir.map(f32::abs);
        let kz = if a[0] >= a[1] && a[0] >= a[2] {
            0
        } else if a[1] >= a[2] {
            1
        } else {
            2
        };
        let mut kx = (kz + 1) % 3;
        let mut ky = (kx + 1) % 3;
        if dir[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        let sz = 1.0 / dir[kz];
        ShearedRay {
            origin,
            kx,
            ky,
            kz,
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
        let o = self.origin;
        let (kx, ky, kz) = (self.kx, self.ky, self.kz);
        let a = [v[0] - o[0], v[1] - o[1], v[2] - o[2]];
        let b = [v[3] - o[0], v[4] - o[1], v[5] - o[2]];
        let c = [v[6] - o[0], v[7] - o[1], v[8] - o[2]];
        let ax = a[kx] - self.sx * a[kz];
        let ay = a[ky] - self.sy * a[kz];
        let bx = b[kx] - self.sx * b[kz];
        let by = b[ky] - self.sy * b[kz];
        let cx = c[kx] - self.sx * c[kz];
        let cy = c[ky] - self.sy * c[kz];
        let mut u = cx * by - cy * bx;
        let mut vv = ax * cy - ay * cx;
        let mut w = bx * ay - by * ax;
        if u == 0.0 || vv == 0.0 || w == 0.0 {
            let (axd, ayd, bxd, byd, cxd, cyd) = (
                ax as f64, ay as f64, bx as f64, by as f64, cx as f64, cy as f64,
            );
            u = (cxd * byd - cyd * bxd) as f32;
            vv = (axd * cyd - ayd * cxd) as f32;
            w = (bxd * ayd - byd * axd) as f32;
            // The f64 results are exact in sign; a value that rounds to zero in f32 is kept as
            // the smallest subnormal with the right sign.
            let fix = |e: f32, exact: f64| {
                if e == 0.0 && exact != 0.0 {
                    f32::from_bits(1).copysign(exact.signum() as f32)
                } else {
                    e
                }
            };
            u = fix(u, cxd * byd - cyd * bxd);
            vv = fix(vv, axd * cyd - ayd * cxd);
            w = fix(w, bxd * ayd - byd * axd);
        }
        if (u < 0.0 || vv < 0.0 || w < 0.0) && (u > 0.0 || vv > 0.0 || w > 0.0) {
            return None;
        }
        let det = u + vv + w;
        if det == 0.0 {
            return None;
        }
        if u == 0.0 || vv == 0.0 || w == 0.0 {
            let s = if det > 0.0 { 1.0f64 } else { -1.0 };
            // Edge opposite each vertex, in the cyclic order b->c, c->a, a->b.
            let owns = |e0: f64, e1: f64| {
                let (ex, ey) = (s * e0, s * e1);
                ey > 0.0 || (ey == 0.0 && ex > 0.0)
            };
            if u == 0.0 && !owns(cx as f64 - bx as f64, cy as f64 - by as f64) {
                return None;
            }
            if vv == 0.0 && !owns(ax as f64 - cx as f64, ay as f64 - cy as f64) {
                return None;
            }
            if w == 0.0 && !owns(bx as f64 - ax as f64, by as f64 - ay as f64) {
                return None;
            }
        }
        let az = self.sz * a[kz];
        let bz = self.sz * b[kz];
        let cz = self.sz * c[kz];
        let t_scaled = u * az + vv * bz + w * cz;
        let rcp = 1.0 / det;
        let t = t_scaled / det; // one rounding, not two: the spec asks for as much precision as possible
        if t.is_nan() {
            return None;
        }
        Some(TriangleHit {
            t,
            b: vv * rcp,
            c: w * rcp,
            front_face: det > 0.0,
        })
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
