//! A quick look at build, trace and refit speed on a generated sphere. The full benchmark is
//! `hostas bench` (and `bench/peers` for the side-by-side comparison).

use hostas::{Device, Ray, vk};
use std::time::Instant;

fn main() {
    let n: u32 = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(500);
    let res: u32 = std::env::var("PERF_RES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(512);
    // `perf N PRESET`: build that preset only (for instruction counts with `perf stat`).
    let only: Option<String> = std::env::args().nth(2);
    let (p, idx) = hostas_testkit::generate::uv_sphere(n);
    let tris = idx.len() as f64;
    println!(
        "sphere: {} triangles, {} threads",
        idx.len(),
        rayon::current_num_threads()
    );
    let device = Device::new();
    for (name, flags) in [
        (
            "fast-trace",
            vk::BuildAccelerationStructureFlagsKHR::PREFER_FAST_TRACE,
        ),
        (
            "fast-build",
            vk::BuildAccelerationStructureFlagsKHR::PREFER_FAST_BUILD,
        ),
        ("default", vk::BuildAccelerationStructureFlagsKHR::empty()),
        (
            "low-memory",
            vk::BuildAccelerationStructureFlagsKHR::LOW_MEMORY,
        ),
    ] {
        if only.as_deref().is_some_and(|o| o != name) {
            continue;
        }
        let t = Instant::now();
        let blas = hostas::quick::build_triangle_blas(&device, &p, &idx, flags).unwrap();
        let build = t.elapsed().as_secs_f64();
        let s = device.statistics(blas).unwrap();
        if std::env::var("PERF_BUILD_ONLY").is_ok() {
            println!(
                "{name}: {:.1} ms, SAH {:.2}, {} nodes",
                build * 1e3,
                s.sah_cost,
                s.node_count
            );
            continue;
        }
        // Refit: an update (src == dst) after moving every vertex.
        let moved: Vec<[f32; 3]> = p.iter().map(|v| [v[0] * 1.01, v[1] * 0.99, v[2]]).collect();
        let ublas = hostas::quick::build_triangle_blas(
            &device,
            &p,
            &idx,
            flags | vk::BuildAccelerationStructureFlagsKHR::ALLOW_UPDATE,
        )
        .unwrap();
        let geom = [hostas::Geometry::triangles(
            hostas::TrianglesData {
                vertex_format: vk::Format::R32G32B32_SFLOAT,
                vertex_data: bytemuck::cast_slice(&moved),
                vertex_stride: 12,
                max_vertex: p.len() as u32 - 1,
                index_type: vk::IndexType::UINT32,
                index_data: Some(bytemuck::cast_slice(&idx)),
                transform_data: None,
            },
            vk::GeometryFlagsKHR::OPAQUE,
        )];
        let range = [hostas::BuildRangeInfo {
            primitive_count: idx.len() as u32,
            ..Default::default()
        }];
        let mut scratch =
            vec![0u8; hostas::layout::plan::update_scratch_size(idx.len() as u64) as usize];
        let t = Instant::now();
        let info = hostas::BuildGeometryInfo {
            ty: vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
            flags: flags | vk::BuildAccelerationStructureFlagsKHR::ALLOW_UPDATE,
            mode: vk::BuildAccelerationStructureModeKHR::UPDATE,
            src: Some(ublas),
            dst: Some(ublas),
            geometries: &geom,
            scratch: Some(&mut scratch),
        };
        device
            .build_acceleration_structures(&mut [info], &[&range])
            .unwrap();
        let refit = tris / t.elapsed().as_secs_f64() / 1e6;
        if std::env::var("PERF_REFIT_ONLY").is_ok() {
            println!("{name}: refit {refit:.1} Mtris/s");
            continue;
        }
        let tlas = hostas::quick::build_single_instance_tlas(&device, blas).unwrap();
        let scene = device.scene(tlas).unwrap();
        let mut tracer = scene.tracer();
        let t = Instant::now();
        let mut hits = 0;
        for y in 0..res {
            for x in 0..res {
                let d = [
                    (x as f32 / res as f32 - 0.5) * 1.2,
                    (y as f32 / res as f32 - 0.5) * 1.2,
                    -1.0,
                ];
                hits += tracer
                    .closest(&Ray::new([0.0, 0.0, 3.0], d))
                    .unwrap()
                    .is_hit() as u32;
            }
        }
        let primary = (res * res) as f64 / t.elapsed().as_secs_f64() / 1e6;
        let mut seed = 12345u32;
        let mut rnd = || {
            seed ^= seed << 13;
            seed ^= seed >> 17;
            seed ^= seed << 5;
            seed as f32 / u32::MAX as f32 * 2.0 - 1.0
        };
        let t = Instant::now();
        let n_inc = if std::env::var("PERF_NO_INCOHERENT").is_ok() {
            0
        } else {
            res * res
        };
        for _ in 0..n_inc {
            let o = [rnd() * 0.9, rnd() * 0.9, rnd() * 0.9];
            let d = [rnd(), rnd(), rnd()];
            tracer.closest(&Ray::new(o, d)).unwrap();
        }
        let incoherent = (res * res) as f64 / t.elapsed().as_secs_f64() / 1e6;
        println!(
            "{name:>11}: build {:7.1} ms ({:5.2} Mtris/s)  SAH {:6.2}  {:5.1} B/tri  depth {}  primary {:5.2} Mrays/s ({hits} hits)  incoherent {:5.2} Mrays/s  refit {refit:5.1} Mtris/s",
            build * 1e3,
            tris / build / 1e6,
            s.sah_cost,
            s.used_bytes as f64 / tris,
            s.depth,
            primary,
            incoherent
        );
    }
}
