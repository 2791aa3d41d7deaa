//! `hostas bench [MESH...]`: build, trace, refit and copy measurements per mesh and preset.

use crate::cli::print;
use crate::geom::{Rng, add, cross, length, normalize, scale, sub};
use crate::mesh::Mesh;
use crate::render::Camera;
use crate::report::{Table, thousands};
use crate::{input, note, progress, shapes};
use anyhow::{Result, anyhow, bail};
use clap::{Args, ValueEnum};
use hostas::{
    AccelerationStructure, AccelerationStructureCreateInfo, BuildGeometryInfo, Device, Ray, vk,
};
use rayon::prelude::*;
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

type F = vk::BuildAccelerationStructureFlagsKHR;

const AFTER_HELP: &str = "\
For every mesh and preset: the median build time (the build command alone, into memory
sized and allocated beforehand), the structure's SAH cost, its size per triangle as built
(the size vkGetAccelerationStructureBuildSizesKHR asks for) and after compaction, the time
of the COMPACT copy, closest-hit tracing speed for primary rays (a pinhole view of the whole
mesh) and incoherent rays (random points on the surface, random directions), on all
threads, and refit (UPDATE with src == dst after moving every vertex slightly).

Without MESH arguments: two built-in generated meshes, then every mesh in ../shared/meshes/
(relative to the current directory) or in --meshes DIR when given.

Examples:
  hostas bench
  hostas bench bunny.obj --presets fast-trace,fast-build --reps 9
  hostas bench --json --threads 1 > single-thread.jsonl";

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Preset {
    FastTrace,
    FastBuild,
    Default,
    LowMemory,
}

impl Preset {
    const ALL: [Preset; 4] = [
        Preset::FastTrace,
        Preset::FastBuild,
        Preset::Default,
        Preset::LowMemory,
    ];
    fn name(self) -> &'static str {
        match self {
            Preset::FastTrace => "fast-trace",
            Preset::FastBuild => "fast-build",
            Preset::Default => "default",
            Preset::LowMemory => "low-memory",
        }
    }
    fn flags(self) -> F {
        match self {
            Preset::FastTrace => F::PREFER_FAST_TRACE,
            Preset::FastBuild => F::PREFER_FAST_BUILD,
            Preset::Default => F::empty(),
            Preset::LowMemory => F::LOW_MEMORY,
        }
    }
}

/// Measure build, trace, refit and copy speed per mesh and preset
#[derive(Args, Debug)]
#[command(after_help = AFTER_HELP)]
pub struct BenchArgs {
    /// Meshes to measure (default: built-in scenes and ../shared/meshes/)
    #[arg(value_name = "MESH")]
    pub meshes: Vec<PathBuf>,
    /// Directory of meshes to measure instead of ../shared/meshes/
    #[arg(long = "meshes", value_name = "DIR")]
    pub dir: Option<PathBuf>,
    /// Skip the built-in generated scenes
    #[arg(long)]
    pub no_builtin: bool,
    /// Presets to measure (comma-separated)
    #[arg(long, value_enum, value_delimiter = ',', default_values_t = Preset::ALL.to_vec())]
    pub presets: Vec<Preset>,
    /// Timed repetitions per measurement (default: 5, fewer for big meshes)
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=1000))]
    pub reps: Option<u32>,
    /// Rays per trace measurement
    #[arg(long, default_value_t = 1 << 18, value_parser = clap::value_parser!(u32).range(1..=1 << 26))]
    pub rays: u32,
    /// One JSON object per line per mesh and preset
    #[arg(long)]
    pub json: bool,
}

/// One line of results.
#[derive(Serialize, Debug, Clone)]
pub struct Row {
    pub mesh: String,
    pub triangles: u64,
    pub preset: &'static str,
    pub threads: usize,
    pub reps: u32,
    pub build_ms: f64,
    pub build_mtris_per_s: f64,
    pub sah_cost: f32,
    pub depth: u32,
    pub bytes_per_triangle: f64,
    pub compacted_bytes_per_triangle: f64,
    pub compact_ms: f64,
    pub trace_primary_mrays_per_s: f64,
    pub trace_incoherent_mrays_per_s: f64,
    pub refit_ms: f64,
    pub refit_mtris_per_s: f64,
}

enum Source {
    Builtin(fn() -> Mesh),
    File(PathBuf),
}

fn builtin_sphere() -> Mesh {
    let mut m = shapes::uv_sphere(160);
    m.name = "builtin:sphere".into();
    m
}
fn builtin_knot() -> Mesh {
    let mut m = shapes::torus_knot(3, 7, 0.12, 2048, 48);
    m.name = "builtin:knot".into();
    m
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n == 0 {
        0.0
    } else if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// A BLAS of `mesh` with memory and scratch allocated once, for repeated builds.
struct Target {
    dst: AccelerationStructure,
    scratch: hostas::HostMemory,
    update_scratch: hostas::HostMemory,
    size: u64,
}

fn target(device: &Device, m: &Mesh, flags: F) -> Result<Target> {
    let geoms = [hostas::quick::triangle_mesh(
        &m.positions,
        &m.indices,
        vk::GeometryFlagsKHR::OPAQUE,
    )];
    let probe = BuildGeometryInfo::sizes_query(
        vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
        flags,
        &geoms,
    );
    let sizes = device
        .build_sizes(
            vk::AccelerationStructureBuildTypeKHR::HOST,
            &probe,
            &[m.indices.len() as u32],
        )
        .map_err(|e| anyhow!("{e}"))?;
    let dst = device
        .create_acceleration_structure(&AccelerationStructureCreateInfo::new(
            vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
            sizes.acceleration_structure_size,
        ))
        .map_err(|e| anyhow!("{e}"))?;
    Ok(Target {
        dst,
        scratch: hostas::HostMemory::zeroed(sizes.build_scratch_size as usize)
            .map_err(|e| anyhow!("{e}"))?,
        update_scratch: hostas::HostMemory::zeroed(sizes.update_scratch_size.max(1) as usize)
            .map_err(|e| anyhow!("{e}"))?,
        size: sizes.acceleration_structure_size,
    })
}

/// Builds (or updates in place) `t.dst` from `positions`; returns the seconds taken.
fn build_into(
    device: &Device,
    t: &mut Target,
    positions: &[[f32; 3]],
    indices: &[[u32; 3]],
    flags: F,
    update: bool,
) -> Result<f64> {
    let geoms = [hostas::quick::triangle_mesh(
        positions,
        indices,
        vk::GeometryFlagsKHR::OPAQUE,
    )];
    let range = [hostas::BuildRangeInfo {
        primitive_count: indices.len() as u32,
        ..Default::default()
    }];
    let info = BuildGeometryInfo {
        ty: vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
        flags,
        mode: if update {
            vk::BuildAccelerationStructureModeKHR::UPDATE
        } else {
            vk::BuildAccelerationStructureModeKHR::BUILD
        },
        src: update.then_some(t.dst),
        dst: Some(t.dst),
        geometries: &geoms,
        scratch: Some(if update {
            t.update_scratch.bytes_mut()
        } else {
            t.scratch.bytes_mut()
        }),
    };
    let start = Instant::now();
    device
        .build_acceleration_structures(&mut [info], &[&range])
        .map_err(|e| anyhow!("{e}"))?;
    Ok(start.elapsed().as_secs_f64())
}

/// Times `f` `reps` times (after a first run that decides `reps` when not given).
fn timed(reps: Option<u32>, mut f: impl FnMut() -> Result<f64>) -> Result<(f64, u32)> {
    let first = f()?;
    let n = reps.unwrap_or_else(|| (1.5 / first.max(1e-6)).clamp(1.0, 5.0) as u32);
    let mut times = Vec::with_capacity(n as usize);
    if reps.is_none() && n == 1 {
        times.push(first);
    } else {
        for _ in 0..n {
            times.push(f()?);
        }
    }
    Ok((median(times), n))
}

fn trace_speed(device: &Device, tlas: AccelerationStructure, rays: &[Ray]) -> Result<f64> {
    let scene = device.scene(tlas).map_err(|e| anyhow!("{e}"))?;
    let start = Instant::now();
    let n: usize = rays
        .par_chunks(1024)
        .map(|c| {
            // As a renderer hands rays over: a batch, walked interleaved where that pays.
            let mut hits = Vec::with_capacity(c.len());
            scene.tracer().closest_batch(c, &mut hits)?;
            Ok(hits.iter().filter(|h| h.is_hit()).count())
        })
        .collect::<hostas::Result<Vec<usize>>>()
        .map_err(|e| anyhow!("{e}"))?
        .into_iter()
        .sum();
    let secs = start.elapsed().as_secs_f64();
    let _ = n;
    Ok(rays.len() as f64 / secs.max(1e-9) / 1e6)
}

fn primary_rays(m: &Mesh, count: u32) -> Vec<Ray> {
    let (lo, hi) = m.bounds();
    let side = (count as f64).sqrt().ceil() as u32;
    let cam = Camera::framing(lo, hi, [0.0, 1.0, 0.0], 40.0, 1.0);
    let fwd = normalize(sub(cam.target, cam.eye));
    let right = normalize(cross(fwd, cam.up));
    let up = cross(right, fwd);
    let half = (20f32).to_radians().tan();
    let mut rays = Vec::with_capacity((side * side) as usize);
    for y in 0..side {
        for x in 0..side {
            if rays.len() == count as usize {
                break;
            }
            let u = (2.0 * (x as f32 + 0.5) / side as f32 - 1.0) * half;
            let v = (1.0 - 2.0 * (y as f32 + 0.5) / side as f32) * half;
            rays.push(Ray::new(
                cam.eye,
                add(fwd, add(scale(right, u), scale(up, v))),
            ));
        }
    }
    rays
}

/// Rays from random points on the surface in random directions (like diffuse bounces).
fn incoherent_rays(m: &Mesh, count: u32) -> Vec<Ray> {
    let (lo, hi) = m.bounds();
    let eps = 1e-4 * length(sub(hi, lo)).max(1e-6);
    let mut rng = Rng::new(0x5eed);
    (0..count)
        .map(|_| {
            let t = m.indices[(rng.next_u64() % m.indices.len() as u64) as usize];
            let [a, b, c] = t.map(|i| m.positions[i as usize]);
            let (mut u, mut v) = (rng.f32(), rng.f32());
            if u + v > 1.0 {
                (u, v) = (1.0 - u, 1.0 - v);
            }
            let p = add(a, add(scale(sub(b, a), u), scale(sub(c, a), v)));
            let mut r = Ray::new(p, rng.unit_vector());
            r.t_min = eps;
            r
        })
        .filter(|r| r.origin.iter().all(|v| v.is_finite()))
        .collect()
}

fn measure(
    device: &Device,
    m: &Mesh,
    preset: Preset,
    args: &BenchArgs,
    step: &dyn Fn(&str),
) -> Result<Row> {
    let flags = preset.flags();
    let n = m.indices.len() as u64;
    // Build.
    step("build");
    let mut t = target(device, m, flags)?;
    let (build_s, reps) = timed(args.reps, || {
        build_into(device, &mut t, &m.positions, &m.indices, flags, false)
    })?;
    let stats = device.statistics(t.dst).map_err(|e| anyhow!("{e}"))?;
    let size = t.size;
    device
        .destroy_acceleration_structure(t.dst)
        .map_err(|e| anyhow!("{e}"))?;
    drop(t);
    // Compaction.
    step("compact");
    let mut c = target(device, m, flags | F::ALLOW_COMPACTION)?;
    build_into(
        device,
        &mut c,
        &m.positions,
        &m.indices,
        flags | F::ALLOW_COMPACTION,
        false,
    )?;
    let compacted = device
        .acceleration_structure_property(
            c.dst,
            vk::QueryType::ACCELERATION_STRUCTURE_COMPACTED_SIZE_KHR,
        )
        .map_err(|e| anyhow!("{e}"))?;
    let small = device
        .create_acceleration_structure(&AccelerationStructureCreateInfo::new(
            vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
            compacted,
        ))
        .map_err(|e| anyhow!("{e}"))?;
    let (compact_s, _) = timed(args.reps, || {
        let start = Instant::now();
        device
            .copy_acceleration_structure(
                c.dst,
                small,
                vk::CopyAccelerationStructureModeKHR::COMPACT,
            )
            .map_err(|e| anyhow!("{e}"))?;
        Ok(start.elapsed().as_secs_f64())
    })?;
    device
        .destroy_acceleration_structure(c.dst)
        .map_err(|e| anyhow!("{e}"))?;
    drop(c);
    // Trace, on the compacted structure.
    step("trace");
    let tlas =
        hostas::quick::build_single_instance_tlas(device, small).map_err(|e| anyhow!("{e}"))?;
    let primary = trace_speed(device, tlas, &primary_rays(m, args.rays))?;
    let incoherent = trace_speed(device, tlas, &incoherent_rays(m, args.rays))?;
    device
        .destroy_acceleration_structure(tlas)
        .map_err(|e| anyhow!("{e}"))?;
    device
        .destroy_acceleration_structure(small)
        .map_err(|e| anyhow!("{e}"))?;
    // Refit.
    step("refit");
    let uflags = flags | F::ALLOW_UPDATE;
    let mut u = target(device, m, uflags)?;
    build_into(device, &mut u, &m.positions, &m.indices, uflags, false)?;
    let (lo, hi) = m.bounds();
    let jitter = 1e-3 * length(sub(hi, lo));
    let mut rng = Rng::new(11);
    let moved: Vec<[f32; 3]> = m
        .positions
        .iter()
        .map(|p| add(*p, scale(rng.unit_vector(), jitter * rng.f32())))
        .collect();
    let mut flip = false;
    let (refit_s, _) = timed(args.reps, || {
        flip = !flip;
        build_into(
            device,
            &mut u,
            if flip { &moved } else { &m.positions },
            &m.indices,
            uflags,
            true,
        )
    })?;
    device
        .destroy_acceleration_structure(u.dst)
        .map_err(|e| anyhow!("{e}"))?;
    Ok(Row {
        mesh: m.name.clone(),
        triangles: n,
        preset: preset.name(),
        threads: rayon::current_num_threads(),
        reps,
        build_ms: build_s * 1e3,
        build_mtris_per_s: n as f64 / build_s.max(1e-9) / 1e6,
        sah_cost: stats.sah_cost,
        depth: stats.depth,
        bytes_per_triangle: size as f64 / n as f64,
        compacted_bytes_per_triangle: compacted as f64 / n as f64,
        compact_ms: compact_s * 1e3,
        trace_primary_mrays_per_s: primary,
        trace_incoherent_mrays_per_s: incoherent,
        refit_ms: refit_s * 1e3,
        refit_mtris_per_s: n as f64 / refit_s.max(1e-9) / 1e6,
    })
}

fn shared_meshes(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut out: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| anyhow!("{}: cannot list: {e}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            let n = p
                .file_name()
                .map(|n| n.to_string_lossy().to_ascii_lowercase())
                .unwrap_or_default();
            let n = n.strip_suffix(".xz").unwrap_or(&n);
            [".obj", ".ply", ".gltf", ".glb"]
                .iter()
                .any(|e| n.ends_with(e))
        })
        .collect();
    // Smallest files first: quick results come early.
    out.sort_by_key(|p| {
        (
            std::fs::metadata(p).map(|m| m.len()).unwrap_or(0),
            p.clone(),
        )
    });
    Ok(out)
}

fn table_row(t: &mut Table, r: &Row) {
    t.row([
        r.mesh.clone(),
        thousands(r.triangles),
        r.preset.to_string(),
        format!("{:.1}", r.build_ms),
        format!("{:.2}", r.build_mtris_per_s),
        format!("{:.2}", r.sah_cost),
        format!("{:.1}", r.bytes_per_triangle),
        format!("{:.1}", r.compacted_bytes_per_triangle),
        format!("{:.2}", r.compact_ms),
        format!("{:.2}", r.trace_primary_mrays_per_s),
        format!("{:.2}", r.trace_incoherent_mrays_per_s),
        format!("{:.1}", r.refit_mtris_per_s),
    ]);
}

/// What a benchmark of this binary should know about how it was built: hostas chooses its
/// vector code at compile time, so a default `x86-64` build runs SSE2 code even where the
/// processor has AVX2 (measured on the build VM: traces 10-30% and builds 10-18% slower than an
/// AVX2 build; `docs/performance.md`, "How to run").
fn build_hint() -> Option<&'static str> {
    #[cfg(all(target_arch = "x86_64", not(target_feature = "avx2")))]
    if std::is_x86_feature_detected!("avx2") {
        return Some(
            "note: this build has no AVX2 code but this processor has AVX2; hostas chooses its \
             vector code at compile time, so build with RUSTFLAGS=\"-C target-cpu=native\" \
             for its full speed (traces about 10-30% faster)",
        );
    }
    None
}

pub fn run(a: BenchArgs) -> Result<()> {
    let mut sources: Vec<Source> = Vec::new();
    let mut empty_dir = None;
    if a.meshes.is_empty() {
        if !a.no_builtin {
            sources.push(Source::Builtin(builtin_sphere));
            sources.push(Source::Builtin(builtin_knot));
        }
        let dir = a
            .dir
            .clone()
            .unwrap_or_else(|| PathBuf::from("../shared/meshes"));
        if dir.is_dir() {
            let found = shared_meshes(&dir)?;
            note!("meshes from {}: {}", dir.display(), found.len());
            if found.is_empty() {
                empty_dir = Some(dir.clone());
            }
            sources.extend(found.into_iter().map(Source::File));
        } else if a.dir.is_some() {
            bail!("{}: not a directory", dir.display());
        } else {
            note!(
                "{} is absent: measuring the built-in scenes only (give meshes as arguments or --meshes DIR)",
                dir.display()
            );
        }
    } else {
        sources.extend(a.meshes.iter().cloned().map(Source::File));
    }
    if sources.is_empty() {
        match empty_dir {
            Some(d) => bail!(
                "nothing to measure: {} holds no meshes and --no-builtin was given",
                d.display()
            ),
            None => bail!(
                "nothing to measure: no meshes given, and --no-builtin with no mesh directory"
            ),
        }
    }
    let threads = rayon::current_num_threads();
    note!(
        "{} mesh(es) x {} preset(s) on {threads} thread(s)",
        sources.len(),
        a.presets.len()
    );
    if let Some(hint) = build_hint() {
        note!("{hint}");
    }
    let device = Device::new();
    let total = (sources.len() * a.presets.len()) as u64;
    let pb = progress::bar(total, "");
    let mut table = Table::new([
        "mesh",
        "triangles",
        "preset",
        "build ms",
        "Mtris/s",
        "SAH",
        "B/tri",
        "compact B/tri",
        "compact ms",
        "primary Mrays/s",
        "incoh. Mrays/s",
        "refit Mtris/s",
    ]);
    for s in &sources {
        let m = match s {
            Source::Builtin(f) => f(),
            Source::File(p) => {
                pb.set_message(format!("loading {}", p.display()));
                input::load_mesh(p)?
            }
        };
        for &preset in &a.presets {
            let step = |what: &str| pb.set_message(format!("{} {} {what}", m.name, preset.name()));
            let row = measure(&device, &m, preset, &a, &step)?;
            pb.inc(1);
            if a.json {
                pb.suspend(|| print(&(serde_json::to_string(&row).unwrap_or_default() + "\n")))?;
            } else {
                table_row(&mut table, &row);
            }
        }
    }
    pb.finish_and_clear();
    if !a.json {
        print(&table.render())?;
    }
    Ok(())
}
