//! `hostas build MESH... -o FILE`: builds one bottom-level structure per mesh, a top-level
//! structure over them, and writes them serialized in one file.

use crate::cli::{PresetArgs, print, write_file};
use crate::container::Container;
use crate::input::load_mesh;
use crate::report::{Table, bytes, ms, thousands};
use crate::{ops, progress};
use anyhow::{Result, anyhow};
use clap::Args;
use hostas::{Affine, vk};
use std::path::PathBuf;
use std::time::Instant;

const AFTER_HELP: &str = "\
Each mesh becomes one bottom-level structure (geometry 0, opaque, triangles in file order,
built with ALLOW_DATA_ACCESS so that `hostas render` can shade it) and instance i of the
top level, with the identity transform and custom index i. The preset flags apply to every
structure.

The output is a HOSTASF1 container: a 48-byte header (magic, version, count, world bounds),
one entry per structure, then each structure exactly as vkCopyAccelerationStructureToMemoryKHR
serialized it (the spec's header, handle list and payload; `hostas info` decodes it). In the
top level's handle list, i + 1 names bottom level i of the file and 0 an inactive instance.

Examples:
  hostas build bunny.obj -o bunny.hostas
  hostas build --fast-build --compact scene.glb -o scene.hostas
  hostas build a.obj b.ply.xz -o ab.hostas";

/// Build acceleration structures from meshes and write them serialized to FILE
#[derive(Args, Debug)]
#[command(after_help = AFTER_HELP)]
pub struct BuildArgs {
    /// Mesh files (.obj, .ply, .gltf, .glb, each optionally .xz-compressed)
    #[arg(required = true, value_name = "MESH")]
    pub meshes: Vec<PathBuf>,
    /// The file to write
    #[arg(short, long, value_name = "FILE")]
    pub output: PathBuf,
    #[command(flatten)]
    pub preset: PresetArgs,
}

pub fn run(a: BuildArgs) -> Result<()> {
    type F = vk::BuildAccelerationStructureFlagsKHR;
    let flags = a.preset.flags();
    let device = hostas::Device::new();
    let mut table = Table::new([
        "structure",
        "triangles",
        "build ms",
        "size",
        "compacted",
        "B/tri",
    ]);
    let mut blases = Vec::new();
    let mut bounds: Option<([f32; 3], [f32; 3])> = None;
    let mut total_tris = 0u64;
    for path in &a.meshes {
        let m = load_mesh(path)?;
        let (lo, hi) = m.bounds();
        if lo.iter().chain(hi.iter()).all(|v| v.is_finite()) {
            bounds = Some(match bounds {
                None => (lo, hi),
                Some((l, h)) => (
                    [0, 1, 2].map(|k| l[k].min(lo[k])),
                    [0, 1, 2].map(|k| h[k].max(hi[k])),
                ),
            });
        }
        let pb = progress::spinner(format!(
            "building {} ({} triangles)",
            m.name,
            thousands(m.indices.len() as u64)
        ));
        let t = Instant::now();
        let blas = hostas::quick::build_triangle_blas(
            &device,
            &m.positions,
            &m.indices,
            flags | F::ALLOW_DATA_ACCESS,
        )
        .map_err(|e| anyhow!("{}: building: {e}", path.display()));
        let secs = t.elapsed().as_secs_f64();
        pb.finish_and_clear();
        let mut blas = blas?;
        let size = ops::allocated(&device, blas);
        let mut compacted = "-".to_string();
        let mut final_size = size;
        if a.preset.compact {
            let (c, _, after) = ops::compact(
                &device,
                blas,
                vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
            )?;
            blas = c;
            compacted = bytes(after);
            final_size = after;
        }
        let tris = m.indices.len() as u64;
        total_tris += tris;
        table.row([
            format!("BLAS {} ({})", blases.len(), m.name),
            thousands(tris),
            ms(secs),
            bytes(size),
            compacted,
            format!("{:.1}", final_size as f64 / tris as f64),
        ]);
        blases.push((m.name.clone(), blas));
    }
    let instances: Vec<_> = blases
        .iter()
        .enumerate()
        .map(|(i, (_, b))| {
            let mut inst = hostas::quick::instance(*b, Affine::IDENTITY);
            inst.custom_index = i as u32;
            inst
        })
        .collect();
    let t = Instant::now();
    let mut tlas = hostas::quick::build_tlas(&device, &instances, flags)
        .map_err(|e| anyhow!("building the top level: {e}"))?;
    let secs = t.elapsed().as_secs_f64();
    let size = ops::allocated(&device, tlas);
    let mut compacted = "-".to_string();
    if a.preset.compact {
        let (c, _, after) =
            ops::compact(&device, tlas, vk::AccelerationStructureTypeKHR::TOP_LEVEL)?;
        tlas = c;
        compacted = bytes(after);
    }
    table.row([
        format!("TLAS ({} instances)", instances.len()),
        "-".into(),
        ms(secs),
        bytes(size),
        compacted,
        "-".into(),
    ]);
    let container = Container::from_device(&device, &blases, tlas, bounds)?;
    let out = container.to_bytes();
    write_file(&a.output, &out)?;
    let names = crate::report::build_flag_names(flags.as_raw());
    print(&format!(
        "{}\nwrote {} ({}, {} triangles, flags: {})\n",
        table.render(),
        a.output.display(),
        bytes(out.len() as u64),
        thousands(total_tris),
        if names.is_empty() {
            "none (default preset)".to_string()
        } else {
            names.join(" | ")
        }
    ))
}
