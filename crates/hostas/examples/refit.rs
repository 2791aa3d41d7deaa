//! Refit (UPDATE, src == dst) speed on one scene, for A/B comparisons of the update path.
//!
//! `refit SCENE [REPS]` with SCENE one of `sphere` (1M-triangle cube-sphere), `soup` (1M random
//! triangles, indexed, vertices in triangle order), `boxes` (1M triangles: 83k randomly rotated
//! boxes), `uv` (the `perf` example's sphere), or a path to an OBJ file (`v` and `f` lines) or
//! a binary PLY (float vertices, face lists). Builds once with ALLOW_UPDATE (default preset, or
//! `REFIT_FLAGS=fast-trace|fast-build|low-memory`), then times REPS updates, alternating
//! between moved and original vertices, and prints the median wall time and the mean of the
//! calling thread's CPU time (which leaves out waiting for a core). With REPS = 0 it only builds (to
//! subtract the build's instruction count under `perf stat`). With `REFIT_HASH` set it also
//! prints a hash of the structure's bytes after the updates.

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

/// `count` randomly rotated boxes (12 triangles, 8 shared vertices each; sides 0.05-5, centres
/// in [0,100]^3), as the peer benchmark's `boxes` scene.
fn boxes(count: usize) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
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
    let mut rng = Rng(0xB0C5);
    let mut pos = Vec::with_capacity(count * 8);
    let mut idx = Vec::with_capacity(count * 12);
    for _ in 0..count {
        let c = [0; 3].map(|_| rng.f32() * 100.0);
        let h = [0; 3].map(|_| 0.5 * (0.05f32.ln() + rng.f32() * (100.0f32).ln()).exp());
        // A random rotation (Shoemake's quaternion method).
        let (u1, u2, u3) = (
            rng.f32(),
            rng.f32() * std::f32::consts::TAU,
            rng.f32() * std::f32::consts::TAU,
        );
        let (a, b) = ((1.0 - u1).sqrt(), u1.sqrt());
        let (x, y, z, w) = (a * u2.sin(), a * u2.cos(), b * u3.sin(), b * u3.cos());
        let m = hostas_testkit::generate::rotation([w, x, y, z]);
        let base = pos.len() as u32;
        for corner in 0..8u32 {
            let l = [0, 1, 2].map(|k| if corner >> k & 1 == 1 { h[k] } else { -h[k] });
            pos.push([0, 1, 2].map(|r| c[r] + m[r][0] * l[0] + m[r][1] * l[1] + m[r][2] * l[2]));
        }
        for f in FACES {
            idx.push(f.map(|v| base + v));
        }
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

/// A binary little-endian PLY with float x, y, z vertices and `uchar int` face lists (the
/// format of the shared meshes' `.ply` files).
fn ply(path: &str) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let data = std::fs::read(path).expect("read PLY");
    let end = data
        .windows(11)
        .position(|w| w == b"end_header\n")
        .expect("PLY header")
        + 11;
    let header = std::str::from_utf8(&data[..end]).expect("PLY header");
    assert!(header.contains("binary_little_endian"), "binary PLY only");
    let count = |what: &str| -> usize {
        header
            .lines()
            .find_map(|l| l.strip_prefix(what))
            .and_then(|n| n.trim().parse().ok())
            .unwrap_or(0)
    };
    let (nv, nf) = (count("element vertex "), count("element face "));
    let f32_at = |at: usize| f32::from_le_bytes(data[at..at + 4].try_into().unwrap());
    let u32_at = |at: usize| u32::from_le_bytes(data[at..at + 4].try_into().unwrap());
    let pos: Vec<[f32; 3]> = (0..nv)
        .map(|v| [0, 1, 2].map(|k| f32_at(end + 12 * v + 4 * k)))
        .collect();
    let mut idx = Vec::with_capacity(nf);
    let mut at = end + 12 * nv;
    for _ in 0..nf {
        let n = data[at] as usize;
        let f: Vec<u32> = (0..n).map(|k| u32_at(at + 1 + 4 * k)).collect();
        for k in 1..n - 1 {
            idx.push([f[0], f[k], f[k + 1]]);
        }
        at += 1 + 4 * n;
    }
    (pos, idx)
}

/// Nanoseconds this thread has run on a CPU (Linux: `/proc/thread-self/schedstat`; 0
/// elsewhere), as of the last scheduler tick or switch: only sums over many calls are exact.
/// Unlike wall time, it leaves out time spent waiting for a core, which on a shared machine is
/// most of the noise.
fn cpu_ns() -> u64 {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()
        .and_then(|s| s.split_whitespace().next()?.parse().ok())
        .unwrap_or(0)
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
        "boxes" => boxes(83_334),
        "uv" => hostas_testkit::generate::uv_sphere(500),
        path if path.ends_with(".ply") => ply(path),
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
    let mut cpu = 0;
    // One scratch for every update, as an application would keep it.
    let mut scratch =
        vec![0u8; hostas::layout::plan::update_scratch_size(idx.len() as u64) as usize];
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
        let info = hostas::BuildGeometryInfo {
            ty: vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
            flags,
            mode: vk::BuildAccelerationStructureModeKHR::UPDATE,
            src: Some(blas),
            dst: Some(blas),
            geometries: &geom,
            scratch: Some(&mut scratch),
        };
        let (t, c) = (Instant::now(), cpu_ns());
        refit_once(&device, info, &range);
        times.push(t.elapsed().as_secs_f64());
        cpu += cpu_ns() - c;
    }
    if std::env::var_os("REFIT_HASH").is_some() {
        // The structure's bytes after the updates, for byte-identity checks across versions.
        use std::hash::{Hash, Hasher};
        let bytes = device.serialize(blas).unwrap();
        let mut hasher = std::collections::hash_map::DefaultHasher::new();
        bytes.hash(&mut hasher);
        println!("{scene}: {reps} updates, hash {:016x}", hasher.finish());
    }
    if reps == 0 {
        return;
    }
    times.sort_by(f64::total_cmp);
    let med = times[times.len() / 2];
    let rate = |t: f64| idx.len() as f64 / t / 1e6;
    println!(
        "{scene}: {} triangles, {} threads, refit median {:.2} ms = {:.1} Mtris/s (best {:.1}); \
         this thread's CPU time: mean {:.1} Mtris/s",
        idx.len(),
        rayon::current_num_threads(),
        med * 1e3,
        rate(med),
        rate(times[0]),
        rate(cpu as f64 * 1e-9 / reps as f64),
    );
}
