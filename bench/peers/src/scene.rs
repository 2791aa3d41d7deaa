//! Benchmark scenes: three generated ones (deterministic) and the real meshes found in the
//! shared mesh folder.

use crate::util::Rng;
use std::path::{Path, PathBuf};

pub struct Scene {
    pub name: String,
    /// Where it came from (generator parameters or file path), for the report.
    pub source: String,
    pub positions: Vec<[f32; 3]>,
    pub indices: Vec<[u32; 3]>,
    pub bmin: [f32; 3],
    pub bmax: [f32; 3],
}

impl Scene {
    pub fn new(
        name: &str,
        source: String,
        positions: Vec<[f32; 3]>,
        indices: Vec<[u32; 3]>,
    ) -> Scene {
        let mut bmin = [f32::INFINITY; 3];
        let mut bmax = [f32::NEG_INFINITY; 3];
        // Bounds of the referenced vertices only.
        for t in &indices {
            for &i in t {
                let p = positions[i as usize];
                for k in 0..3 {
                    bmin[k] = bmin[k].min(p[k]);
                    bmax[k] = bmax[k].max(p[k]);
                }
            }
        }
        Scene {
            name: name.to_string(),
            source,
            positions,
            indices,
            bmin,
            bmax,
        }
    }
    pub fn tri_count(&self) -> usize {
        self.indices.len()
    }
    pub fn diagonal(&self) -> f32 {
        let d = [0, 1, 2].map(|k| self.bmax[k] - self.bmin[k]);
        (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
    }
    /// Triangle soup with 16-byte vertices, three per triangle (tinybvh's input layout).
    pub fn soup4(&self, positions: &[[f32; 3]]) -> Vec<[f32; 4]> {
        let mut v = Vec::with_capacity(self.indices.len() * 3);
        for t in &self.indices {
            for &i in t {
                let p = positions[i as usize];
                v.push([p[0], p[1], p[2], 0.0]);
            }
        }
        v
    }
}

pub const GENERATED: [&str; 3] = ["sphere", "soup", "boxes"];

/// Real meshes: (scene name, file name in the shared mesh folder).
pub const MESHES: [(&str, &str); 5] = [
    ("bunny", "stanford-bunny.obj"),
    ("sponza", "sponza-dabrovic.obj"),
    ("sibenik", "sibenik.ply"),
    ("conference", "conference.ply"),
    ("crown", "crown-pbrt-flat.ply.xz"),
];

pub fn all_scene_names() -> Vec<&'static str> {
    GENERATED
        .iter()
        .copied()
        .chain(MESHES.iter().map(|m| m.0))
        .collect()
}

/// The shared mesh folder: `--meshes`, else `../../../shared/meshes` relative to this crate
/// (the repository root's `../shared/meshes`).
pub fn default_mesh_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/meshes")
}

pub enum Loaded {
    Scene(Scene),
    Missing(String),
}

pub fn load(name: &str, mesh_dir: &Path) -> Result<Loaded, String> {
    match name {
        "sphere" => Ok(Loaded::Scene(sphere(289))),
        "soup" => Ok(Loaded::Scene(soup(1_000_000))),
        "boxes" => Ok(Loaded::Scene(boxes(83_333))),
        _ => {
            let Some((_, file)) = MESHES.iter().find(|m| m.0 == name) else {
                return Err(format!(
                    "unknown scene '{name}' (known: {})",
                    all_scene_names().join(", ")
                ));
            };
            let path = mesh_dir.join(file);
            if !path.exists() {
                return Ok(Loaded::Missing(format!(
                    "{} not found (mesh folder {} absent or incomplete)",
                    path.display(),
                    mesh_dir.display()
                )));
            }
            let mesh = crate::mesh::load(&path).map_err(|e| format!("{}: {e}", path.display()))?;
            Ok(Loaded::Scene(Scene::new(
                name,
                path.display().to_string(),
                mesh.positions,
                mesh.indices,
            )))
        }
    }
}

/// Tessellated cube-sphere of radius 1: six faces of n x n quads, 12 n^2 triangles
/// (n = 289: 1,002,252). Vertices are not shared across faces.
pub fn sphere(n: u32) -> Scene {
    let mut pos = Vec::with_capacity(6 * ((n + 1) * (n + 1)) as usize);
    let mut idx = Vec::with_capacity(12 * (n * n) as usize);
    for face in 0..6u32 {
        let base = pos.len() as u32;
        for j in 0..=n {
            for i in 0..=n {
                let u = 2.0 * i as f32 / n as f32 - 1.0;
                let v = 2.0 * j as f32 / n as f32 - 1.0;
                let c: [f32; 3] = match face {
                    0 => [1.0, v, -u],
                    1 => [-1.0, v, u],
                    2 => [u, 1.0, -v],
                    3 => [u, -1.0, v],
                    4 => [u, v, 1.0],
                    _ => [-u, v, -1.0],
                };
                let l = (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt();
                pos.push([c[0] / l, c[1] / l, c[2] / l]);
            }
        }
        for j in 0..n {
            for i in 0..n {
                let a = base + j * (n + 1) + i;
                let b = a + 1;
                let c = a + n + 1;
                let d = c + 1;
                idx.push([a, b, d]);
                idx.push([a, d, c]);
            }
        }
    }
    Scene::new(
        "sphere",
        format!("cube-sphere, radius 1, 6 x {n}^2 quads"),
        pos,
        idx,
    )
}

/// `count` random triangles: centre uniform in [0,100]^3, each vertex within +-1 of it per axis.
pub fn soup(count: usize) -> Scene {
    let mut rng = Rng::new(0x50_u64);
    let mut pos = Vec::with_capacity(count * 3);
    let mut idx = Vec::with_capacity(count);
    for t in 0..count {
        let c = [
            rng.range(0.0, 100.0),
            rng.range(0.0, 100.0),
            rng.range(0.0, 100.0),
        ];
        for _ in 0..3 {
            pos.push([0, 1, 2].map(|k| c[k] + rng.range(-1.0, 1.0)));
        }
        let b = 3 * t as u32;
        idx.push([b, b + 1, b + 2]);
    }
    Scene::new(
        "soup",
        format!("{count} random triangles, centres in [0,100]^3, vertices +-1"),
        pos,
        idx,
    )
}

/// `count` randomly rotated boxes (side lengths log-uniform in [0.05, 5] per axis, centres
/// uniform in [0,100]^3) plus a 2-triangle ground plane under them spanning [-5,105]^2.
pub fn boxes(count: usize) -> Scene {
    let mut rng = Rng::new(0xB0C5);
    let mut pos = Vec::with_capacity(count * 8 + 4);
    let mut idx = Vec::with_capacity(count * 12 + 2);
    const FACES: [[u32; 3]; 12] = [
        [0, 2, 3],
        [0, 3, 1],
        [4, 5, 7],
        [4, 7, 6],
        [0, 1, 5],
        [0, 5, 4],
        [2, 6, 7],
        [2, 7, 3],
        [0, 4, 6],
        [0, 6, 2],
        [1, 3, 7],
        [1, 7, 5],
    ];
    for _ in 0..count {
        let c = [
            rng.range(0.0, 100.0),
            rng.range(0.0, 100.0),
            rng.range(0.0, 100.0),
        ];
        let h =
            [0; 3].map(|_| 0.5 * (0.05f32.ln() + rng.f32() * (5.0f32.ln() - 0.05f32.ln())).exp());
        // Uniform random rotation (Shoemake's quaternion method).
        let (u1, u2, u3) = (
            rng.f32(),
            rng.range(0.0, std::f32::consts::TAU),
            rng.range(0.0, std::f32::consts::TAU),
        );
        let (a, b) = ((1.0 - u1).sqrt(), u1.sqrt());
        let (x, y, z, w) = (a * u2.sin(), a * u2.cos(), b * u3.sin(), b * u3.cos());
        let m = [
            [
                1.0 - 2.0 * (y * y + z * z),
                2.0 * (x * y - z * w),
                2.0 * (x * z + y * w),
            ],
            [
                2.0 * (x * y + z * w),
                1.0 - 2.0 * (x * x + z * z),
                2.0 * (y * z - x * w),
            ],
            [
                2.0 * (x * z - y * w),
                2.0 * (y * z + x * w),
                1.0 - 2.0 * (x * x + y * y),
            ],
        ];
        let base = pos.len() as u32;
        for corner in 0..8u32 {
            let l = [0, 1, 2].map(|k| if corner >> k & 1 == 1 { h[k] } else { -h[k] });
            pos.push([0, 1, 2].map(|r| c[r] + m[r][0] * l[0] + m[r][1] * l[1] + m[r][2] * l[2]));
        }
        for f in FACES {
            idx.push(f.map(|v| base + v));
        }
    }
    let base = pos.len() as u32;
    for (x, z) in [(-5.0, -5.0), (105.0, -5.0), (105.0, 105.0), (-5.0, 105.0)] {
        pos.push([x, -3.0, z]);
    }
    idx.push([base, base + 2, base + 1]);
    idx.push([base, base + 3, base + 2]);
    Scene::new(
        "boxes",
        format!(
            "{count} rotated boxes (sides log-uniform 0.05-5, centres in [0,100]^3) + ground plane"
        ),
        pos,
        idx,
    )
}

/// A smooth displacement used for refit measurements: every vertex moves by up to 0.5% of the
/// scene diagonal. Returns the deformed copy.
pub fn deformed(scene: &Scene) -> Vec<[f32; 3]> {
    let d = scene.diagonal().max(1e-20);
    let amp = 0.005 * d;
    let k = std::f32::consts::TAU * 3.0 / d;
    scene
        .positions
        .iter()
        .map(|p| {
            [
                p[0] + amp * (k * p[1]).sin(),
                p[1] + amp * (k * p[2]).sin(),
                p[2] + amp * (k * p[0]).sin(),
            ]
        })
        .collect()
}
