//! Refit (UPDATE, src == dst) speed on one scene, for A/B comparisons of the update path.
//!
//! `refit SCENE [REPS]` with SCENE one of `sphere` (1M-triangle cube-sphere), `soup` (1M random
//! triangles, indexed, vertices in triangle order), `uv` (the `perf` example's sphere) or a
//! path to an OBJ file (`v` and `f` lines). Builds once with ALLOW_UPDATE (default preset, or
//! `REFIT_FLAGS=fast-trace|fast-build|low-memory`), then times REPS updates, alternating
//! between moved and original vertices, and prints the median. With REPS = 0 it only builds
//! (to subtract the build's instruction count under `perf stat`).

use hostas::{Device, vk};
use std::time::Instant;

fn cube_sphere(n: u32) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let mut pos = Vec::new();
    let mut idx = Vec::new();
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
    (pos, idx)
}

struct Rng(u64);
impl Rng {
    fn f32(&mut self) -> f32 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 40) as f32 / (1u64 << 24) as f32
    }
}

fn soup(count: usize) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let mut rng = Rng(0x50);
    let mut pos = Vec::with_capacity(count * 3);
    let mut idx = Vec::with_capacity(count);
    for t in 0..count {
        let c = [rng.f32() * 100.0, rng.f32() * 100.0, rng.f32() * 100.0];
        for _ in 0..3 {
            pos.push([0, 1, 2].map(|k| c[k] + rng.f32() * 2.0 - 1.0));
        }
        let b = 3 * t as u32;
        idx.push([b, b + 1, b + 2]);
    }
    (pos, idx)
}

fn obj(path: &str) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let text = std::fs::read_to_string(path).expect("read OBJ");
    let mut pos = Vec::new();
    let mut idx = Vec::new();
    for line in text.lines() {
        let mut it = line.split_whitespace();
        match it.next() {
            Some("v") => {
                let v: Vec<f32> = it.take(3).map(|s| s.parse().unwrap()).collect();
                pos.push([v[0], v[1], v[2]]);
            }
            Some("f") => {
                let f: Vec<u32> = it
                    .map(|s| {
                        let i: i64 = s.split('/').next().unwrap().parse().unwrap();
                        if i < 0 {
                            (pos.len() as i64 + i) as u32
                        } else {
                            (i - 1) as u32
                        }
                    })
                    .collect();
                for k in 1..f.len() - 1 {
                    idx.push([f[0], f[k], f[k + 1]]);
                }
            }
            _ => {}
        }
    }
    (pos, idx)
}

/// The timed call (a separate symbol for `valgrind --toggle-collect=*refit_once*`).
#[inline(never)]
fn refit_once(device: &Device, info: hostas::BuildGeometryInfo, range: &[hostas::BuildRangeInfo]) {
    device
        .build_acceleration_structures(&mut [info], &[range])
        .unwrap();
}

fn main() {
    let scene = std::env::args().nth(1).unwrap_or_else(|| "sphere".into());
    let reps: usize = std::env::args()
        .nth(2)
        .and_then(|s| s.parse().ok())
        .unwrap_or(9);
    let (p, idx) = match scene.as_str() {
        "sphere" => cube_sphere(289),
        "soup" => soup(1_000_000),
        "uv" => hostas_testkit::generate::uv_sphere(500),
        path => obj(path),
    };
    let flags = match std::env::var("REFIT_FLAGS").as_deref() {
        Ok("fast-trace") => vk::BuildAccelerationStructureFlagsKHR::PREFER_FAST_TRACE,
        Ok("fast-build") => vk::BuildAccelerationStructureFlagsKHR::PREFER_FAST_BUILD,
        Ok("low-memory") => vk::BuildAccelerationStructureFlagsKHR::LOW_MEMORY,
        _ => vk::BuildAccelerationStructureFlagsKHR::empty(),
    } | vk::BuildAccelerationStructureFlagsKHR::ALLOW_UPDATE;
    let device = Device::new();
    let blas = hostas::quick::build_triangle_blas(&device, &p, &idx, flags).unwrap();
    let moved: Vec<[f32; 3]> = p
        .iter()
        .enumerate()
        .map(|(i, v)| {
            let s = 1e-3 * ((i % 7) as f32 - 3.0);
            [v[0] + s, v[1] - s, v[2] + 0.5 * s]
        })
        .collect();
    let mut times = Vec::new();
    for r in 0..reps {
        let verts = if r % 2 == 0 { &moved } else { &p };
        let geom = [hostas::quick::triangle_mesh(
            verts,
            &idx,
            vk::GeometryFlagsKHR::OPAQUE,
        )];
        let range = [hostas::BuildRangeInfo {
            primitive_count: idx.len() as u32,
            ..Default::default()
        }];
        let mut scratch = vec![0u8; 4096];
        let info = hostas::BuildGeometryInfo {
            ty: vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
            flags,
            mode: vk::BuildAccelerationStructureModeKHR::UPDATE,
            src: Some(blas),
            dst: Some(blas),
            geometries: &geom,
            scratch: Some(&mut scratch),
        };
        let t = Instant::now();
        refit_once(&device, info, &range);
        times.push(t.elapsed().as_secs_f64());
    }
    if reps == 0 {
        return;
    }
    times.sort_by(f64::total_cmp);
    let med = times[times.len() / 2];
    println!(
        "{scene}: {} triangles, {} threads, refit median {:.2} ms = {:.1} Mtris/s (best {:.1})",
        idx.len(),
        rayon::current_num_threads(),
        med * 1e3,
        idx.len() as f64 / med / 1e6,
        idx.len() as f64 / times[0] / 1e6
    );
}
