//! Batch tracing on one thread, walked one ray at a time (`Interleave::Never`) and as
//! `Tracer::closest_batch` / `Tracer::any_batch` choose (`Interleave::Auto`), alternated
//! round by round on the same rays: closest hits of incoherent rays, and first hits of
//! shadow rays (from a random point towards another, `tMax` the distance, as a renderer's
//! occlusion queries). Prints Mrays/s (median of the rounds) and Auto ÷ Never, after
//! checking that both give the same hits.
//!
//! `cargo run --release --example batches -- [TRIANGLES] [ROUNDS]` (default 1,000,000 and 5):
//! a soup (random triangles, centres in [0, 100]^3, vertices within 1 of them, as the peer
//! benchmark's) and a UV sphere of about as many (4n² for n = √(TRIANGLES / 4)). Build with
//! `-C target-cpu=native`.

use hostas::{Device, Hit, Interleave, Ray, Tracer, vk};
use rand::{Rng, SeedableRng};
use std::time::Instant;

const RAYS: usize = 65_536;
/// Rays per batch call, as the peer benchmark hands them.
const BATCH: usize = 1024;

fn main() {
    let mut args = std::env::args().skip(1);
    let tris: usize = args
        .next()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1_000_000);
    let rounds: usize = args.next().and_then(|s| s.parse().ok()).unwrap_or(5);
    let mut rng = rand_pcg::Pcg64::seed_from_u64(27);
    let soup = soup(&mut rng, tris);
    let sphere = hostas_testkit::generate::uv_sphere(((tris / 4) as f64).sqrt() as u32);
    println!("| scene | rays | Never Mrays/s | Auto Mrays/s | Auto ÷ Never |");
    println!("|---|---|--:|--:|--:|");
    for (name, (p, idx)) in [("soup", soup), ("sphere", sphere)] {
        let device = Device::new();
        let flags = vk::BuildAccelerationStructureFlagsKHR::PREFER_FAST_TRACE;
        let blas = hostas::quick::build_triangle_blas(&device, &p, &idx, flags).unwrap();
        let tlas = hostas::quick::build_single_instance_tlas(&device, blas).unwrap();
        let scene = device.scene(tlas).unwrap();
        let (lo, hi) = bounds(&p);
        let point = |rng: &mut rand_pcg::Pcg64| -> [f32; 3] {
            std::array::from_fn(|k| rng.gen_range(lo[k]..=hi[k]))
        };
        let incoherent: Vec<Ray> = (0..RAYS)
            .map(|_| {
                let d: [f32; 3] = std::array::from_fn(|_| rng.gen_range(-1.0..=1.0));
                Ray::new(point(&mut rng), d)
            })
            .collect();
        let shadow: Vec<Ray> = (0..RAYS)
            .map(|_| {
                let (o, to) = (point(&mut rng), point(&mut rng));
                let mut r = Ray::new(o, std::array::from_fn(|k| to[k] - o[k]));
                r.t_max = 1.0;
                r
            })
            .collect();
        let mut tracer = scene.tracer();
        for (kind, rays, first) in [
            ("incoherent, closest", &incoherent, false),
            ("shadow, first hit", &shadow, true),
        ] {
            let mut times = [Vec::new(), Vec::new()];
            let mut hits = [Vec::new(), Vec::new()];
            for _ in 0..rounds {
                for (m, mode) in [Interleave::Never, Interleave::Auto]
                    .into_iter()
                    .enumerate()
                {
                    let t = Instant::now();
                    hits[m] = trace(&mut tracer, rays, first, mode);
                    times[m].push(t.elapsed().as_secs_f64());
                }
            }
            assert!(hits[0] == hits[1], "{name}, {kind}: the two walks differ");
            let [never, auto] = times.map(|mut t| RAYS as f64 / median(&mut t) / 1e6);
            println!(
                "| {name} ({} triangles) | {kind} ({} hit) | {:.2} | {:.2} | {:.3} |",
                idx.len(),
                hits[0].iter().filter(|h| h.is_hit()).count(),
                never,
                auto,
                auto / never
            );
        }
    }
}

fn trace(tracer: &mut Tracer, rays: &[Ray], first: bool, mode: Interleave) -> Vec<Hit> {
    let mut all = Vec::with_capacity(rays.len());
    let mut hits = Vec::with_capacity(BATCH);
    for chunk in rays.chunks(BATCH) {
        if first {
            tracer.any_batch_with(chunk, &mut hits, mode).unwrap();
        } else {
            tracer.closest_batch_with(chunk, &mut hits, mode).unwrap();
        }
        all.extend_from_slice(&hits);
    }
    all
}

fn soup(rng: &mut impl Rng, n: usize) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let mut p = Vec::with_capacity(3 * n);
    for _ in 0..n {
        let c: [f32; 3] = std::array::from_fn(|_| rng.gen_range(0.0..100.0));
        for _ in 0..3 {
            p.push(std::array::from_fn(|k| c[k] + rng.gen_range(-1.0..1.0)));
        }
    }
    let idx = (0..n as u32)
        .map(|t| [3 * t, 3 * t + 1, 3 * t + 2])
        .collect();
    (p, idx)
}

fn bounds(p: &[[f32; 3]]) -> ([f32; 3], [f32; 3]) {
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for v in p {
        for k in 0..3 {
            lo[k] = lo[k].min(v[k]);
            hi[k] = hi[k].max(v[k]);
        }
    }
    (lo, hi)
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}
