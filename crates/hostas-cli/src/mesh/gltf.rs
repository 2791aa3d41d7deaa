//! glTF 2.0, as `.gltf` (JSON with data-URI or external buffers) or `.glb`.
//!
//! The `gltf` crate parses and validates the JSON; the GLB container and the accessor
//! data are read here, with every offset checked, because the crate's own readers assume
//! well-formed files and can panic on bad ones.

use std::borrow::Cow;
use std::path::Path;

use base64::Engine as _;
use gltf::accessor::{DataType, Dimensions};
use gltf::mesh::Mode;
use gltf::{Accessor, Document, Semantic};

use super::{Location, MeshError, Triangles};

type Mat4 = [[f32; 4]; 4];

const IDENTITY: Mat4 = [
    [1.0, 0.0, 0.0, 0.0],
    [0.0, 1.0, 0.0, 0.0],
    [0.0, 0.0, 1.0, 0.0],
    [0.0, 0.0, 0.0, 1.0],
];

pub(super) fn parse(path: &Path, data: &[u8]) -> Result<Triangles, MeshError> {
    let (json, bin) = if data.starts_with(b"glTF") {
        split_glb(path, data)?
    } else {
        (data, None)
    };
    let invalid = |message: String| MeshError::format(path, Location::File, message);
    let root: gltf::json::Root = gltf::json::deserialize::from_slice(json)
        .map_err(|e| invalid(format!("invalid glTF JSON: {e}")))?;
    // gltf-json's validation indexes `accessors` with POSITION's index before checking it.
    let accessor_count = root.accessors.len();
    let bad_attribute = root
        .meshes
        .iter()
        .flat_map(|mesh| &mesh.primitives)
        .flat_map(|primitive| primitive.attributes.values())
        .find(|index| index.value() >= accessor_count);
    if let Some(index) = bad_attribute {
        return Err(invalid(format!(
            "attribute accessor {} does not exist ({accessor_count} accessors)",
            index.value()
        )));
    }
    let document = Document::from_json(root).map_err(|e| invalid(e.to_string()))?;
    let buffers = load_buffers(path, &document, bin)?;

    let mut out = Output::default();
    let scene = document
        .default_scene()
        .or_else(|| document.scenes().next());
    if let Some(scene) = scene {
        // The glTF node hierarchy is a set of disjoint trees: reaching a node twice means
        // a cycle or a shared child, either of which could make the walk endless.
        let mut seen = vec![false; document.nodes().len()];
        let mut stack: Vec<(gltf::Node, Mat4)> =
            scene.nodes().map(|node| (node, IDENTITY)).collect();
        while let Some((node, parent)) = stack.pop() {
            if std::mem::replace(&mut seen[node.index()], true) {
                return Err(invalid(format!(
                    "node {} is reached twice (a cycle or more than one parent)",
                    node.index()
                )));
            }
            let world = mul(&parent, &node.transform().matrix());
            if let Some(mesh) = node.mesh() {
                out.add_mesh(path, &mesh, &buffers, &world)?;
            }
            stack.extend(node.children().map(|child| (child, world)));
        }
    } else {
        // No scene: a library of meshes, taken as they are.
        for mesh in document.meshes() {
            out.add_mesh(path, &mesh, &buffers, &IDENTITY)?;
        }
    }
    Ok((out.positions, out.indices))
}

/// Splits a GLB file into its JSON chunk and optional BIN chunk.
fn split_glb<'a>(path: &Path, data: &'a [u8]) -> Result<(&'a [u8], Option<&'a [u8]>), MeshError> {
    let u32_at = |offset: usize| {
        data.get(offset..offset + 4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize)
    };
    let truncated = |message: String| MeshError::Truncated {
        path: path.to_owned(),
        message,
    };
    let (Some(version), Some(length)) = (u32_at(4), u32_at(8)) else {
        return Err(truncated("GLB header is cut short".to_owned()));
    };
    if version != 2 {
        return Err(MeshError::format(
            path,
            Location::File,
            format!("GLB version {version}, expected 2"),
        ));
    }
    if length > data.len() {
        return Err(truncated(format!(
            "GLB header says {length} bytes, the file has {}",
            data.len()
        )));
    }
    let data = &data[..length];
    let mut offset = 12;
    let mut json = None;
    let mut bin = None;
    while offset < data.len() {
        let (Some(chunk_length), Some(chunk_type)) = (u32_at(offset), u32_at(offset + 4)) else {
            return Err(truncated(format!(
                "GLB chunk header at byte {offset} is cut short"
            )));
        };
        let start = offset + 8;
        let chunk = start
            .checked_add(chunk_length)
            .and_then(|end| data.get(start..end))
            .ok_or_else(|| truncated(format!("GLB chunk at byte {offset} runs past the end")))?;
        match (chunk_type, json.is_some()) {
            (0x4E4F_534A, false) => json = Some(chunk),
            (0x004E_4942, true) if bin.is_none() => bin = Some(chunk),
            (_, false) => {
                return Err(MeshError::format(
                    path,
                    Location::File,
                    "GLB does not start with a JSON chunk",
                ));
            }
            // Chunks of unknown types are skipped, as the specification asks.
            _ => {}
        }
        offset = start + chunk_length;
    }
    let json =
        json.ok_or_else(|| MeshError::format(path, Location::File, "GLB has no JSON chunk"))?;
    Ok((json, bin))
}

/// Loads every buffer: the GLB BIN chunk, base64 data URIs, or files beside `path`.
fn load_buffers<'a>(
    path: &Path,
    document: &Document,
    bin: Option<&'a [u8]>,
) -> Result<Vec<Cow<'a, [u8]>>, MeshError> {
    let invalid = |message: String| MeshError::format(path, Location::File, message);
    let mut buffers = Vec::new();
    for buffer in document.buffers() {
        let index = buffer.index();
        let mut bytes: Cow<[u8]> = match buffer.source() {
            gltf::buffer::Source::Bin => Cow::Borrowed(bin.ok_or_else(|| {
                invalid(format!("buffer {index} refers to a missing GLB BIN chunk"))
            })?),
            gltf::buffer::Source::Uri(uri) => {
                if let Some(rest) = uri.strip_prefix("data:") {
                    let Some((_, payload)) = rest
                        .split_once(',')
                        .filter(|(kind, _)| kind.ends_with(";base64"))
                    else {
                        return Err(invalid(format!("buffer {index}: unsupported data URI")));
                    };
                    let decoded = base64::engine::general_purpose::STANDARD
                        .decode(payload)
                        .map_err(|e| invalid(format!("buffer {index}: bad base64: {e}")))?;
                    Cow::Owned(decoded)
                } else if uri.contains("://") {
                    return Err(invalid(format!("buffer {index}: unsupported URI {uri:?}")));
                } else {
                    let file = path
                        .parent()
                        .unwrap_or(Path::new(""))
                        .join(percent_decode(uri));
                    let bytes = std::fs::read(&file).map_err(|e| {
                        invalid(format!(
                            "buffer {index}: cannot read {}: {e}",
                            file.display()
                        ))
                    })?;
                    Cow::Owned(bytes)
                }
            }
        };
        let declared = buffer.length();
        if bytes.len() < declared {
            return Err(MeshError::Truncated {
                path: path.to_owned(),
                message: format!(
                    "buffer {index} has {} bytes, its byteLength is {declared}",
                    bytes.len()
                ),
            });
        }
        // Views must stay within the declared length (GLB chunks may carry padding).
        match &mut bytes {
            Cow::Borrowed(b) => *b = &b[..declared],
            Cow::Owned(b) => b.truncate(declared),
        }
        buffers.push(bytes);
    }
    Ok(buffers)
}

/// Decodes `%XX` escapes in a relative URI; anything malformed is kept as written.
fn percent_decode(uri: &str) -> String {
    let bytes = uri.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        let hex = bytes
            .get(i + 1..i + 3)
            .and_then(|h| std::str::from_utf8(h).ok())
            .and_then(|h| u8::from_str_radix(h, 16).ok());
        match (bytes[i], hex) {
            (b'%', Some(byte)) => {
                out.push(byte);
                i += 3;
            }
            (byte, _) => {
                out.push(byte);
                i += 1;
            }
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

#[derive(Default)]
struct Output {
    positions: Vec<[f32; 3]>,
    indices: Vec<[u32; 3]>,
}

impl Output {
    fn add_mesh(
        &mut self,
        path: &Path,
        mesh: &gltf::Mesh,
        buffers: &[Cow<[u8]>],
        transform: &Mat4,
    ) -> Result<(), MeshError> {
        for primitive in mesh.primitives() {
            if primitive.mode() != Mode::Triangles {
                continue;
            }
            let location = Location::Primitive {
                mesh: mesh.index(),
                primitive: primitive.index(),
            };
            let invalid = |message: String| MeshError::format(path, location.clone(), message);

            let accessor = primitive
                .get(&Semantic::Positions)
                .ok_or_else(|| invalid("no POSITION attribute".to_owned()))?;
            if accessor.data_type() != DataType::F32 || accessor.dimensions() != Dimensions::Vec3 {
                return Err(invalid(format!(
                    "POSITION is {:?} {:?}, only float VEC3 is supported",
                    accessor.data_type(),
                    accessor.dimensions()
                )));
            }
            let local = read_accessor(&accessor, buffers, |b| {
                let f = |i: usize| f32::from_le_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]]);
                [f(0), f(4), f(8)]
            })
            .map_err(|message| invalid(format!("POSITION accessor: {message}")))?;
            let vertex_count = local.len();

            let corners: Vec<u32> = match primitive.indices() {
                Some(accessor) => {
                    if accessor.dimensions() != Dimensions::Scalar {
                        return Err(invalid("indices accessor is not SCALAR".to_owned()));
                    }
                    match accessor.data_type() {
                        DataType::U8 => read_accessor(&accessor, buffers, |b| u32::from(b[0])),
                        DataType::U16 => read_accessor(&accessor, buffers, |b| {
                            u32::from(u16::from_le_bytes([b[0], b[1]]))
                        }),
                        DataType::U32 => read_accessor(&accessor, buffers, |b| {
                            u32::from_le_bytes([b[0], b[1], b[2], b[3]])
                        }),
                        other => {
                            return Err(invalid(format!("indices of type {other:?}")));
                        }
                    }
                    .map_err(|message| invalid(format!("indices accessor: {message}")))?
                }
                None => (0..vertex_count)
                    .map(|i| u32::try_from(i).map_err(|_| invalid("too many vertices".to_owned())))
                    .collect::<Result<_, _>>()?,
            };
            if !corners.len().is_multiple_of(3) {
                return Err(invalid(format!(
                    "{} indices, not a multiple of 3",
                    corners.len()
                )));
            }

            let base = self.positions.len();
            let base32 = u32::try_from(base + vertex_count)
                .map(|_| base as u32)
                .map_err(|_| invalid("too many vertices for 32-bit indices".to_owned()))?;
            // A mirroring transform turns the triangles inside out; swap two corners back.
            let flip = determinant3(transform) < 0.0;
            self.indices.reserve(corners.len() / 3);
            for (face, triangle) in corners.chunks_exact(3).enumerate() {
                if let Some(&index) = triangle.iter().find(|&&i| i as usize >= vertex_count) {
                    return Err(MeshError::IndexOutOfRange {
                        path: path.to_owned(),
                        location: location.clone(),
                        face: face as u64,
                        index: i64::from(index),
                        vertex_count: vertex_count as u64,
                    });
                }
                let [a, b, c] = [0, 1, 2].map(|k| base32 + triangle[k]);
                self.indices.push(if flip { [a, c, b] } else { [a, b, c] });
            }
            self.positions
                .extend(local.iter().map(|p| transform_point(transform, p)));
        }
        Ok(())
    }
}

/// Reads every element of `accessor` (sparse substitutions included), after checking
/// that all of it lies inside its buffer view and buffer.
fn read_accessor<T: Copy>(
    accessor: &Accessor,
    buffers: &[Cow<[u8]>],
    decode: impl Fn(&[u8]) -> T,
) -> Result<Vec<T>, String> {
    let size = accessor.size();
    let count = accessor.count();
    let view = accessor
        .view()
        .ok_or("no bufferView (zero-filled accessors are not supported)")?;
    let data = view_bytes(&view, buffers)?;
    let stride = view.stride().unwrap_or(size);
    if stride < size {
        return Err(format!(
            "byteStride {stride} is less than the element size {size}"
        ));
    }
    let elements = strided(data, accessor.offset(), stride, size, count)?;
    let mut values: Vec<T> = elements.map(&decode).collect();

    if let Some(sparse) = accessor.sparse() {
        let n = sparse.count();
        let indices = sparse.indices();
        let index_size = match indices.index_type() {
            gltf::accessor::sparse::IndexType::U8 => 1,
            gltf::accessor::sparse::IndexType::U16 => 2,
            gltf::accessor::sparse::IndexType::U32 => 4,
        };
        let index_bytes = view_bytes(&indices.view(), buffers)?;
        let index_iter = strided(index_bytes, indices.offset(), index_size, index_size, n)?;
        let sparse_values = sparse.values();
        let value_bytes = view_bytes(&sparse_values.view(), buffers)?;
        let value_iter = strided(value_bytes, sparse_values.offset(), size, size, n)?;
        for (index, value) in index_iter.zip(value_iter) {
            // Little-endian, of whichever width.
            let index = index
                .iter()
                .rev()
                .fold(0usize, |acc, &byte| (acc << 8) | usize::from(byte));
            *values
                .get_mut(index)
                .ok_or_else(|| format!("sparse index {index} is out of range (count {count})"))? =
                decode(value);
        }
    }
    Ok(values)
}

/// The bytes of a buffer view, checked against its buffer.
fn view_bytes<'b>(view: &gltf::buffer::View, buffers: &'b [Cow<[u8]>]) -> Result<&'b [u8], String> {
    let buffer = &buffers[view.buffer().index()];
    view.offset()
        .checked_add(view.length())
        .and_then(|end| buffer.get(view.offset()..end))
        .ok_or_else(|| format!("bufferView {} lies outside its buffer", view.index()))
}

/// `count` elements of `size` bytes, `stride` apart, from `offset` in `data`.
fn strided(
    data: &[u8],
    offset: usize,
    stride: usize,
    size: usize,
    count: usize,
) -> Result<impl Iterator<Item = &[u8]>, String> {
    if count > 0 {
        let end = (count - 1)
            .checked_mul(stride)
            .and_then(|n| n.checked_add(offset))
            .and_then(|n| n.checked_add(size));
        if end.is_none_or(|end| end > data.len()) {
            return Err(format!(
                "{count} elements of {size} bytes at offset {offset}, stride {stride} do not fit in {} bytes",
                data.len()
            ));
        }
    }
    Ok((0..count).map(move |i| &data[offset + i * stride..][..size]))
}

fn mul(a: &Mat4, b: &Mat4) -> Mat4 {
    // Column-major: m[column][row].
    std::array::from_fn(|c| std::array::from_fn(|r| (0..4).map(|k| a[k][r] * b[c][k]).sum()))
}

fn transform_point(m: &Mat4, p: &[f32; 3]) -> [f32; 3] {
    std::array::from_fn(|r| m[0][r] * p[0] + m[1][r] * p[1] + m[2][r] * p[2] + m[3][r])
}

fn determinant3(m: &Mat4) -> f32 {
    m[0][0] * (m[1][1] * m[2][2] - m[2][1] * m[1][2])
        - m[1][0] * (m[0][1] * m[2][2] - m[2][1] * m[0][2])
        + m[2][0] * (m[0][1] * m[1][2] - m[1][1] * m[0][2])
}
