//! Turning a command-line input (a mesh file, a `hostas build` file, or one serialized
//! structure) into a traceable scene.

use crate::container::{self, Container};
use crate::mesh::{self, Mesh, MeshError};
use crate::progress;
use anyhow::{Context, Result, anyhow, bail};
use hostas::commands::SerializedHeader;
use hostas::{AccelerationStructure, Device, vk};
use std::io::Read;
use std::path::Path;
use std::time::{Duration, Instant};

type Flags = vk::BuildAccelerationStructureFlagsKHR;

/// Where a scene came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Source {
    /// A mesh file: one BLAS of the whole mesh under one identity instance.
    Mesh,
    /// A `hostas build` file.
    Container,
    /// One serialized bottom-level structure, under one identity instance.
    Serialized,
}

/// A scene ready to trace.
pub struct Loaded {
    pub device: Device,
    pub tlas: AccelerationStructure,
    pub blases: Vec<AccelerationStructure>,
    pub names: Vec<String>,
    /// World bounds, when known.
    pub bounds: Option<([f32; 3], [f32; 3])>,
    pub source: Source,
    /// Triangles over all bottom levels (each counted once, however often instanced).
    pub triangles: u64,
    /// Time to build (mesh input) or deserialize the structures.
    pub setup_time: Duration,
}

/// Reads the first bytes of a file.
fn head(path: &Path, n: usize) -> Result<Vec<u8>> {
    let mut f =
        std::fs::File::open(path).with_context(|| format!("{}: cannot open", path.display()))?;
    let mut buf = Vec::with_capacity(n);
    f.by_ref()
        .take(n as u64)
        .read_to_end(&mut buf)
        .with_context(|| format!("{}: cannot read", path.display()))?;
    Ok(buf)
}

/// Loads a mesh with a spinner on stderr.
pub fn load_mesh(path: &Path) -> Result<Mesh> {
    let pb = progress::spinner(format!("loading {}", path.display()));
    let m = mesh::load(path);
    pb.finish_and_clear();
    Ok(m?)
}

/// The bounds stored in a hostas structure's header (serialized payload).
fn serialized_bounds(data: &[u8]) -> Option<([f32; 3], [f32; 3])> {
    let h = SerializedHeader::parse(data).ok()?;
    let start = 56 + 8 * h.handles.len();
    let header = hostas::layout::view::read_header(data.get(start..)?).ok()?;
    let b = header.bounds;
    (!b.is_empty() && b.lo.iter().chain(b.hi.iter()).all(|v| v.is_finite())).then_some((b.lo, b.hi))
}

fn triangles_of(device: &Device, blases: &[AccelerationStructure]) -> u64 {
    blases
        .iter()
        .filter_map(|b| device.statistics(*b).ok())
        .filter(|s| s.prim_kind == hostas::layout::PrimKind::Triangles)
        .map(|s| s.primitive_count as u64)
        .sum()
}

/// Builds the scene of one mesh: geometry 0 (opaque, primitives in file order) in one BLAS,
/// instance 0 with the identity transform. `ALLOW_DATA_ACCESS` is added so that shading can
/// fetch triangle vertices.
pub fn scene_of_mesh(
    device: &Device,
    m: &Mesh,
    flags: Flags,
) -> Result<(AccelerationStructure, AccelerationStructure)> {
    let blas = hostas::quick::build_triangle_blas(
        device,
        &m.positions,
        &m.indices,
        flags | Flags::ALLOW_DATA_ACCESS,
    )
    .map_err(|e| anyhow!("{}: building the bottom level: {e}", m.name))?;
    let tlas = hostas::quick::build_tlas(
        device,
        &[hostas::quick::instance(blas, hostas::Affine::IDENTITY)],
        flags & !Flags::ALLOW_DATA_ACCESS,
    )
    .map_err(|e| anyhow!("{}: building the top level: {e}", m.name))?;
    Ok((blas, tlas))
}

/// Loads `path` as a mesh (by its extension), a `hostas build` file or a serialized
/// bottom-level structure (by their content).
pub fn load(path: &Path, mesh_flags: Flags) -> Result<Loaded> {
    let device = Device::new();
    let shown = path.display();
    if container::is_container(&head(path, 8)?) {
        let bytes = std::fs::read(path).with_context(|| format!("{shown}: cannot read"))?;
        let c = Container::parse(&bytes).with_context(|| format!("{shown}"))?;
        let t = Instant::now();
        let (blases, tlas) = c.load(&device).with_context(|| format!("{shown}"))?;
        let triangles = triangles_of(&device, &blases);
        return Ok(Loaded {
            names: c.blases.iter().map(|b| b.name.clone()).collect(),
            device,
            tlas,
            blases,
            bounds: c.bounds.or_else(|| serialized_bounds(&c.tlas.data)),
            source: Source::Container,
            triangles,
            setup_time: t.elapsed(),
        });
    }
    match load_mesh(path) {
        Ok(m) => {
            let pb = progress::spinner(format!(
                "building {} ({} triangles)",
                m.name,
                m.indices.len()
            ));
            let t = Instant::now();
            let r = scene_of_mesh(&device, &m, mesh_flags);
            let setup_time = t.elapsed();
            pb.finish_and_clear();
            let (blas, tlas) = r?;
            let (lo, hi) = m.bounds();
            let bounds = lo
                .iter()
                .chain(hi.iter())
                .all(|v| v.is_finite())
                .then_some((lo, hi));
            Ok(Loaded {
                device,
                tlas,
                blases: vec![blas],
                names: vec![m.name.clone()],
                bounds,
                source: Source::Mesh,
                triangles: m.indices.len() as u64,
                setup_time,
            })
        }
        Err(e)
            if matches!(
                e.downcast_ref::<MeshError>(),
                Some(MeshError::UnsupportedExtension { .. })
            ) =>
        {
            let bytes = std::fs::read(path).with_context(|| format!("{shown}: cannot read"))?;
            let header = SerializedHeader::parse(&bytes).map_err(|_| {
                anyhow!("{shown}: not a mesh ({}), a hostas build file or a serialized acceleration structure", mesh::SUPPORTED_EXTENSIONS)
            })?;
            let mut version = [0u8; 32];
            version[..16].copy_from_slice(&header.driver_uuid);
            version[16..].copy_from_slice(&header.compatibility_uuid);
            if device.compatibility(&version)
                != vk::AccelerationStructureCompatibilityKHR::COMPATIBLE
            {
                bail!(
                    "{shown}: this structure was serialized by another implementation or hostas version (driverUUID {}); hostas can trace only its own. `hostas info` decodes its header",
                    crate::report::uuid(&header.driver_uuid)
                );
            }
            if header.handle_count != 0 {
                bail!(
                    "{shown}: a bare serialized top-level structure carries no bottom levels; trace a `hostas build` file instead"
                );
            }
            let t = Instant::now();
            let blas = device
                .deserialize(&bytes)
                .map_err(|e| anyhow!("{shown}: {e}"))?;
            let tlas = hostas::quick::build_single_instance_tlas(&device, blas)
                .map_err(|e| anyhow!("{shown}: {e}"))?;
            let triangles = triangles_of(&device, &[blas]);
            Ok(Loaded {
                device,
                tlas,
                blases: vec![blas],
                names: vec![
                    path.file_stem()
                        .map(|s| s.to_string_lossy().into_owned())
                        .unwrap_or_default(),
                ],
                bounds: serialized_bounds(&bytes),
                source: Source::Serialized,
                triangles,
                setup_time: t.elapsed(),
            })
        }
        Err(e) => Err(e),
    }
}
