//! Ray sets shared by every library: primary rays of a pinhole camera looking at the scene
//! bounds, and incoherent rays (origins uniform in the scene box, directions uniform on the
//! sphere). Directions are unit length (tinybvh normalizes anyway), so every library's t is in
//! the same units. Closest hit, t in [0, inf).

use crate::scene::Scene;
use crate::util::Rng;

#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct Ray {
    pub o: [f32; 3],
    pub d: [f32; 3],
}

/// Closest hit. Miss: t = +inf, prim = u32::MAX.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    pub t: f32,
    pub prim: u32,
}

impl Hit {
    pub const MISS: Hit = Hit {
        t: f32::INFINITY,
        prim: u32::MAX,
    };
    pub fn is_hit(&self) -> bool {
        self.prim != u32::MAX
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Kind {
    Primary,
    Incoherent,
}

impl Kind {
    pub const ALL: [Kind; 2] = [Kind::Primary, Kind::Incoherent];
}

pub struct RaySet {
    pub primary: Vec<Ray>,
    pub incoherent: Vec<Ray>,
}

impl RaySet {
    /// Drops the rays of every kind not in `kinds`: phases then skip those kinds.
    pub fn keep(&mut self, kinds: &[Kind]) {
        for k in Kind::ALL {
            if !kinds.contains(&k) {
                match k {
                    Kind::Primary => self.primary.clear(),
                    Kind::Incoherent => self.incoherent.clear(),
                }
            }
        }
    }
    pub fn get(&self, k: Kind) -> &[Ray] {
        match k {
            Kind::Primary => &self.primary,
            Kind::Incoherent => &self.incoherent,
        }
    }
}

fn normalize(v: [f32; 3]) -> [f32; 3] {
    let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    [v[0] / l, v[1] / l, v[2] / l]
}

fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// `width` x `width` primary rays (scanline order) and as many incoherent rays.
pub fn generate(scene: &Scene, width: usize) -> RaySet {
    let c = [0, 1, 2].map(|k| 0.5 * (scene.bmin[k] + scene.bmax[k]));
    let radius = 0.5 * scene.diagonal().max(1e-20);
    // Camera outside the box, looking at its centre, 45 degree vertical field of view, far
    // enough that the bounding sphere fits the frame.
    let fov = 45f32.to_radians();
    let dist = radius / (0.5 * fov).sin();
    let view_dir = normalize([0.55, 0.35, 0.76]);
    let eye = [0, 1, 2].map(|k| c[k] + view_dir[k] * dist);
    let fwd = normalize([c[0] - eye[0], c[1] - eye[1], c[2] - eye[2]]);
    let right = normalize(cross(fwd, [0.0, 1.0, 0.0]));
    let up = cross(right, fwd);
    let half = (0.5 * fov).tan();
    let mut primary = Vec::with_capacity(width * width);
    for y in 0..width {
        for x in 0..width {
            let sx = ((x as f32 + 0.5) / width as f32 * 2.0 - 1.0) * half;
            let sy = (1.0 - (y as f32 + 0.5) / width as f32 * 2.0) * half;
            let d = normalize([0, 1, 2].map(|k| fwd[k] + sx * right[k] + sy * up[k]));
            primary.push(Ray { o: eye, d });
        }
    }
    let mut rng = Rng::new(0x1_C04E_2E47);
    let incoherent = (0..width * width)
        .map(|_| {
            let o = [0, 1, 2].map(|k| rng.range(scene.bmin[k], scene.bmax[k]));
            Ray {
                o,
                d: rng.unit_vector(),
            }
        })
        .collect();
    RaySet {
        primary,
        incoherent,
    }
}
