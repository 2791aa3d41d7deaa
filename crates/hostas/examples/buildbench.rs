//! Build speed only, into memory and scratch allocated once (as `hostas bench` measures), on
//! generated scenes: `buildbench SCENE PRESET [REPS]` with SCENE `sphere:N` (4N² triangles: sphere:500 is 1M) or
//! `soup:N` (N random triangles, centres in [0,100]³, vertices within ±1, as bench/peers) or
//! `obj:PATH` (a Wavefront OBJ mesh, polygons as fans, e.g. ../shared/meshes/stanford-bunny.obj)
//! and PRESET one of fast-trace, fast-build, default, low-memory. Prints the median build time,
//! Mtris/s and the SAH cost. With REPS = 1 it is cheap enough to run under callgrind.

use hostas::{AccelerationStructureCreateInfo, BuildGeometryInfo, Device, vk};
use std::time::Instant;

fn soup(n: u32) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let mut seed = 0x9e37_79b9u32;
    let mut rnd = || {
        seed ^= seed << 13;
        seed ^= seed >> 17;
        seed ^= seed << 5;
        seed as f32 / u32::MAX as f32
    };
    let mut p = Vec::with_capacity(3 * n as usize);
    let mut idx = Vec::with_capacity(n as usize);
    for t in 0..n {
        let c = [rnd() * 100.0, rnd() * 100.0, rnd() * 100.0];
        for _ in 0..3 {
            p.push([
                c[0] + rnd() * 2.0 - 1.0,
                c[1] + rnd() * 2.0 - 1.0,
                c[2] + rnd() * 2.0 - 1.0,
            ]);
        }
        idx.push([3 * t, 3 * t + 1, 3 * t + 2]);
    }
    (p, idx)
}

/// Vertices and faces of an OBJ file (`v` and `f` lines only; faces as fans, negative
/// indices relative to the end).
fn obj(path: &str) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let text = std::fs::read_to_string(path).expect("readable OBJ file");
    let (mut p, mut idx) = (Vec::new(), Vec::new());
    for line in text.lines() {
        let mut w = line.split_whitespace();
        match w.next() {
            Some("v") => {
                let c: Vec<f32> = w.take(3).map(|x| x.parse().expect("coordinate")).collect();
                p.push([c[0], c[1], c[2]]);
            }
            Some("f") => {
                let f: Vec<u32> = w
                    .map(|v| {
                        let i: i64 = v.split('/').next().unwrap().parse().expect("index");
                        (if i < 0 { p.len() as i64 + i } else { i - 1 }) as u32
                    })
                    .collect();
                for k in 1..f.len().saturating_sub(1) {
                    idx.push([f[0], f[k], f[k + 1]]);
                }
            }
            _ => {}
        }
    }
    (p, idx)
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let scene = args.get(1).map(String::as_str).unwrap_or("sphere:500");
    let preset = args.get(2).map(String::as_str).unwrap_or("fast-trace");
    let reps: usize = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(5);
    let (kind, arg) = scene.split_once(':').unwrap_or((scene, "500"));
    let n = || arg.parse::<u32>().expect("scene size");
    let (p, idx) = match kind {
        "sphere" => hostas_testkit::generate::uv_sphere(n()),
        "soup" => soup(n()),
        "obj" => obj(arg),
        _ => panic!("unknown scene {kind}"),
    };
    use vk::BuildAccelerationStructureFlagsKHR as F;
    let flags = match preset {
        "fast-trace" => F::PREFER_FAST_TRACE,
        "fast-build" => F::PREFER_FAST_BUILD,
        "low-memory" => F::LOW_MEMORY,
        _ => F::empty(),
    };
    let device = Device::new();
    let geoms = [hostas::quick::triangle_mesh(
        &p,
        &idx,
        vk::GeometryFlagsKHR::OPAQUE,
    )];
    let mut info = BuildGeometryInfo::sizes_query(
        vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
        flags,
        &geoms,
    );
    let sizes = device
        .build_sizes(
            vk::AccelerationStructureBuildTypeKHR::HOST,
            &info,
            &[idx.len() as u32],
        )
        .unwrap();
    let dst = device
        .create_acceleration_structure(&AccelerationStructureCreateInfo::new(
            vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
            sizes.acceleration_structure_size,
        ))
        .unwrap();
    let mut scratch = vec![0u8; sizes.build_scratch_size as usize];
    let range = [hostas::BuildRangeInfo {
        primitive_count: idx.len() as u32,
        ..Default::default()
    }];
    info.dst = Some(dst);
    let mut times = Vec::new();
    for _ in 0..reps.max(1) {
        let info = BuildGeometryInfo {
            scratch: Some(&mut scratch),
            ..info
        };
        let t = Instant::now();
        device
            .build_acceleration_structures(&mut [info], &[&range])
            .unwrap();
        times.push(t.elapsed().as_secs_f64());
    }
    times.sort_by(f64::total_cmp);
    let med = times[times.len() / 2];
    let s = device.statistics(dst).unwrap();
    println!(
        "{scene} {preset} ({} tris, {} threads): {:.1} ms (min {:.1}), {:.2} Mtris/s, SAH {:.3}, {} nodes",
        idx.len(),
        rayon::current_num_threads(),
        med * 1e3,
        times[0] * 1e3,
        idx.len() as f64 / med / 1e6,
        s.sah_cost,
        s.node_count
    );
}
