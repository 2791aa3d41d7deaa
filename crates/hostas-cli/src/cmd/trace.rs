//! `hostas trace (MESH|FILE) --rays RAYS --hits HITS`: batch tracing of binary ray records.

use crate::cli::write_file;
use crate::records::{self, HIT_SIZE};
use crate::{input, note, progress};
use anyhow::{Context, Result, anyhow};
use clap::Args;
use hostas::vk;
use rayon::prelude::*;
use std::path::PathBuf;
use std::time::Instant;

const AFTER_HELP: &str = "\
Ray record (40 bytes, little-endian): f32 origin[3], f32 tmin, f32 direction[3], f32 tmax,
u32 ray_flags, u32 cull_mask. Hit record (32 bytes): f32 t, u32 instance_id,
u32 geometry_index, u32 primitive_id, f32 barycentric_u, f32 barycentric_v,
u32 kind (0 miss, 1 triangle, 2 generated), u32 front_face. A miss is 32 zero bytes.

Each ray gets the closest hit with the semantics of traceRayEXT with no any-hit or
intersection shader bound: non-opaque triangles are accepted and an AABB is hit where the
ray enters it. Every SPIR-V ray flag and the cull mask of the record are honoured;
--any-hit adds TerminateOnFirstHit to every ray. A ray that breaks the runtime rules of
OpRayQueryInitializeKHR (NaN, negative or reversed range, conflicting flags) is an error.

A mesh file is traced as one BLAS of the whole mesh (geometry 0, opaque, primitives in file
order) under one identity instance (instance 0).

Examples:
  hostas trace bunny.obj --rays rays.bin --hits hits.bin
  hostas trace scene.hostas --rays shadow.bin --hits occluded.bin --any-hit";

/// Trace a file of rays and write a file of hits
#[derive(Args, Debug)]
#[command(after_help = AFTER_HELP)]
pub struct TraceArgs {
    /// A mesh, a `hostas build` file or a serialized bottom-level structure
    #[arg(value_name = "MESH|FILE")]
    pub input: PathBuf,
    /// Ray records to read
    #[arg(long, value_name = "RAYS")]
    pub rays: PathBuf,
    /// Hit records to write, one per ray
    #[arg(long, value_name = "HITS")]
    pub hits: PathBuf,
    /// Stop at the first accepted hit (TerminateOnFirstHit)
    #[arg(long)]
    pub any_hit: bool,
}

pub fn run(a: TraceArgs) -> Result<()> {
    let data =
        std::fs::read(&a.rays).with_context(|| format!("{}: cannot read", a.rays.display()))?;
    let rays = records::decode_rays(&data).with_context(|| format!("{}", a.rays.display()))?;
    let loaded = input::load(
        &a.input,
        vk::BuildAccelerationStructureFlagsKHR::PREFER_FAST_TRACE,
    )?;
    let scene = loaded
        .device
        .scene(loaded.tlas)
        .map_err(|e| anyhow!("{}: {e}", a.input.display()))?;
    const CHUNK: usize = 4096;
    let pb = progress::bar(rays.len() as u64, "tracing");
    let t = Instant::now();
    let results: Vec<Result<Vec<u8>>> = rays
        .par_chunks(CHUNK)
        .enumerate()
        .map(|(c, chunk)| {
            let mut out = Vec::with_capacity(chunk.len() * HIT_SIZE);
            let mut tracer = scene.tracer();
            let mut hits = Vec::with_capacity(chunk.len());
            // A batch, whose walks hostas interleaves where that pays.
            if a.any_hit {
                tracer.any_batch(chunk, &mut hits)
            } else {
                tracer.closest_batch(chunk, &mut hits)
            }
            .map_err(|e| match (&e, e.location().and_then(|l| l.ray)) {
                // The rule alone: the error's own location counts rays within the chunk.
                (hostas::Error::Validation { vuid, message, .. }, Some(k)) => anyhow!(
                    "{}: ray {}: {vuid}: {message}",
                    a.rays.display(),
                    c * CHUNK + k as usize
                ),
                _ => anyhow!("{}: {e}", a.rays.display()),
            })?;
            for hit in &hits {
                out.extend_from_slice(&records::encode_hit(hit));
            }
            pb.inc(chunk.len() as u64);
            Ok(out)
        })
        .collect();
    let secs = t.elapsed().as_secs_f64();
    pb.finish_and_clear();
    let mut out = Vec::with_capacity(rays.len() * HIT_SIZE);
    for r in results {
        out.extend_from_slice(&r?);
    }
    write_file(&a.hits, &out)?;
    let hits = out
        .chunks_exact(HIT_SIZE)
        .filter(|h| h[24..28] != [0; 4])
        .count();
    note!(
        "traced {} rays ({} hits) in {:.1} ms: {:.2} Mrays/s on {} threads",
        rays.len(),
        hits,
        secs * 1e3,
        rays.len() as f64 / secs.max(1e-9) / 1e6,
        rayon::current_num_threads()
    );
    Ok(())
}
