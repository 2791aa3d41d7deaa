//! Triangle-mesh input for the `hostas` command.
//!
//! [`load`] reads a mesh file into one indexed triangle list ([`Mesh`]): Wavefront OBJ,
//! PLY (ASCII and binary of either byte order), glTF 2.0 (`.gltf` and `.glb`), and any of
//! these compressed with xz (a trailing `.xz`, decompressed in memory). Polygons are
//! fan-triangulated; everything but positions and faces (normals, texture coordinates,
//! materials, ...) is ignored.
//!
//! Loading never panics on bad input: malformed, truncated or hostile files give a
//! [`MeshError`] that names the file and, where known, the line and the face.

mod gltf;
mod obj;
mod ply;
#[cfg(test)]
mod tests;

use std::fmt;
use std::io;
use std::path::{Path, PathBuf};

/// The extensions [`load`] accepts, as written in error messages.
pub const SUPPORTED_EXTENSIONS: &str = ".obj, .ply, .gltf, .glb (each optionally followed by .xz)";

/// An indexed triangle mesh.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    /// The file name without its format and compression extensions.
    pub name: String,
    /// Vertex positions. NaN and infinite coordinates are passed through as they are.
    pub positions: Vec<[f32; 3]>,
    /// Triangles, as indices into `positions`; every index is in range.
    pub indices: Vec<[u32; 3]>,
}

impl Mesh {
    /// The number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.indices.len()
    }

    /// The axis-aligned bounds `(min, max)` of all positions, ignoring NaN coordinates.
    ///
    /// With no positions (or only NaN ones) the result is empty: `min` is `+inf` and
    /// `max` is `-inf`.
    pub fn bounds(&self) -> ([f32; 3], [f32; 3]) {
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        for p in &self.positions {
            for axis in 0..3 {
                lo[axis] = lo[axis].min(p[axis]);
                hi[axis] = hi[axis].max(p[axis]);
            }
        }
        (lo, hi)
    }
}

/// Where in a file an error was found.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub enum Location {
    /// Somewhere in the file (binary data, or no more precise place is known).
    #[default]
    File,
    /// A line of a text file, counted from 1.
    Line(usize),
    /// A primitive of a glTF mesh, both counted from 0.
    Primitive { mesh: usize, primitive: usize },
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Location::File => Ok(()),
            Location::Line(line) => write!(f, ":{line}"),
            Location::Primitive { mesh, primitive } => {
                write!(f, " (mesh {mesh}, primitive {primitive})")
            }
        }
    }
}

/// Why a mesh could not be loaded. Every message starts with the file's path.
#[derive(Debug, thiserror::Error)]
pub enum MeshError {
    #[error("{path}: cannot read: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: io::Error,
    },
    #[error("{path}: unsupported extension; supported: {SUPPORTED_EXTENSIONS}")]
    UnsupportedExtension { path: PathBuf },
    #[error("{path}: xz decompression failed: {message}")]
    Decompress { path: PathBuf, message: String },
    /// The file is not well formed, or uses something this loader does not support.
    #[error("{path}{location}: {message}")]
    Format {
        path: PathBuf,
        location: Location,
        message: String,
    },
    /// Binary data ends early.
    #[error("{path}: truncated: {message}")]
    Truncated { path: PathBuf, message: String },
    /// A face refers to a vertex that does not exist. `face` counts from 0, in file
    /// order (for glTF, the triangle within its primitive); `index` is as written in the
    /// file (1-based or negative for OBJ).
    #[error(
        "{path}{location}: face {face} refers to vertex {index}, but there are only {vertex_count} vertices"
    )]
    IndexOutOfRange {
        path: PathBuf,
        location: Location,
        face: u64,
        index: i64,
        vertex_count: u64,
    },
    #[error("{path}: no triangles")]
    NoTriangles { path: PathBuf },
}

impl MeshError {
    fn format(path: &Path, location: Location, message: impl Into<String>) -> Self {
        MeshError::Format {
            path: path.to_owned(),
            location,
            message: message.into(),
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Format {
    Obj,
    Ply,
    Gltf,
}

/// Splits `file.ply.xz` into (`file`, [`Format::Ply`], compressed).
fn classify(path: &Path) -> Option<(String, Format, bool)> {
    let file_name = path.file_name()?.to_string_lossy();
    let lower = file_name.to_ascii_lowercase();
    let (lower, compressed) = match lower.strip_suffix(".xz") {
        Some(rest) => (rest, true),
        None => (lower.as_str(), false),
    };
    let (stem_len, format) = [
        (".obj", Format::Obj),
        (".ply", Format::Ply),
        (".gltf", Format::Gltf),
        (".glb", Format::Gltf),
    ]
    .into_iter()
    .find_map(|(ext, format)| lower.strip_suffix(ext).map(|stem| (stem.len(), format)))?;
    // Lower-casing ASCII keeps byte offsets, so the stem length applies to the original.
    Some((file_name[..stem_len].to_owned(), format, compressed))
}

/// Whether `path` has one of the extensions [`load`] accepts.
pub fn is_mesh_path(path: &Path) -> bool {
    classify(path).is_some()
}

/// Loads the mesh at `path`, choosing the format by its extension (case-insensitive).
pub fn load(path: &Path) -> Result<Mesh, MeshError> {
    let (name, format, compressed) =
        classify(path).ok_or_else(|| MeshError::UnsupportedExtension {
            path: path.to_owned(),
        })?;
    let mut data = std::fs::read(path).map_err(|source| MeshError::Io {
        path: path.to_owned(),
        source,
    })?;
    if compressed {
        data = decompress_xz(path, &data)?;
    }
    let (positions, indices) = match format {
        Format::Obj => obj::parse(path, &data)?,
        Format::Ply => ply::parse(path, &data)?,
        Format::Gltf => gltf::parse(path, &data)?,
    };
    if indices.is_empty() {
        return Err(MeshError::NoTriangles {
            path: path.to_owned(),
        });
    }
    Ok(Mesh {
        name,
        positions,
        indices,
    })
}

fn decompress_xz(path: &Path, data: &[u8]) -> Result<Vec<u8>, MeshError> {
    // A hint only: xz typically shrinks meshes 3 to 5 times.
    let mut out = Vec::with_capacity(data.len().saturating_mul(4));
    lzma_rs::xz_decompress(&mut &data[..], &mut out).map_err(|e| MeshError::Decompress {
        path: path.to_owned(),
        message: e.to_string(),
    })?;
    Ok(out)
}

/// What the format parsers return: positions and in-range triangles.
type Triangles = (Vec<[f32; 3]>, Vec<[u32; 3]>);
