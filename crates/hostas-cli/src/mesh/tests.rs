use std::path::{Path, PathBuf};
use std::time::Instant;

use base64::Engine as _;

use super::*;

/// Writes `bytes` as `name` in a fresh temporary directory and loads it.
fn load_bytes(name: &str, bytes: &[u8]) -> Result<Mesh, MeshError> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(name);
    std::fs::write(&path, bytes).unwrap();
    load(&path)
}

/// Each triangle as its three corner positions, which does not depend on how a loader
/// numbers its vertices.
fn corners(mesh: &Mesh) -> Vec<[[f32; 3]; 3]> {
    mesh.indices
        .iter()
        .map(|t| t.map(|i| mesh.positions[i as usize]))
        .collect()
}

const QUAD: [[f32; 3]; 4] = [
    [0.0, 0.0, 0.0],
    [1.0, 0.0, 0.0],
    [1.0, 1.0, 0.0],
    [0.0, 1.0, 0.0],
];

/// The fan triangulation of [`QUAD`].
fn quad_fan() -> Vec<[[f32; 3]; 3]> {
    vec![[QUAD[0], QUAD[1], QUAD[2]], [QUAD[0], QUAD[2], QUAD[3]]]
}

// ---------------------------------------------------------------------------- OBJ

#[test]
fn obj_quad_gives_two_triangles() {
    let mesh = load_bytes(
        "quad.OBJ",
        b"# a quad\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\nf 1/1/1 2/1/1 3/1/1 4/1/1\n",
    )
    .unwrap();
    assert_eq!(mesh.name, "quad");
    assert_eq!(mesh.triangle_count(), 2);
    assert_eq!(mesh.positions.len(), 4);
    assert_eq!(corners(&mesh), quad_fan());
    assert_eq!(mesh.bounds(), ([0.0; 3], [1.0, 1.0, 0.0]));
}

#[test]
fn obj_negative_indices_are_relative() {
    let mesh = load_bytes(
        "rel.obj",
        b"v 0 0 0\nv 1 0 0\nv 1 1 0\nf -3 -2 -1\nv 0 1 0\nf -4 -2 -1\n",
    )
    .unwrap();
    assert_eq!(corners(&mesh), quad_fan());
}

#[test]
fn obj_models_are_merged_in_file_order() {
    let mesh = load_bytes(
        "groups.obj",
        b"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\ng first\nf 1 2 3\ng second\nusemtl x\nf 1 3 4\n",
    )
    .unwrap();
    assert_eq!(corners(&mesh), quad_fan());
}

#[test]
fn obj_index_out_of_range_names_line_and_face() {
    let err = load_bytes(
        "bad.obj",
        b"v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\n\nf 1 2 9\n",
    )
    .unwrap_err();
    assert!(
        matches!(
            err,
            MeshError::IndexOutOfRange {
                location: Location::Line(6),
                face: 1,
                index: 9,
                vertex_count: 3,
                ..
            }
        ),
        "{err:?}"
    );
    let message = err.to_string();
    assert!(
        message.contains("bad.obj:6: face 1 refers to vertex 9"),
        "{message}"
    );

    let err = load_bytes("neg.obj", b"v 0 0 0\nv 1 0 0\nv 1 1 0\nf -4 2 3\n").unwrap_err();
    assert!(
        matches!(
            err,
            MeshError::IndexOutOfRange {
                location: Location::Line(4),
                index: -4,
                ..
            }
        ),
        "{err:?}"
    );
}

#[test]
fn obj_other_bad_references_name_the_line() {
    let text = b"v 0 0 0\nv 1 0 0\nv 1 1 0\nvt 0 0\nf 1/1 2/2 3/1\n";
    let err = load_bytes("vt.obj", text).unwrap_err();
    let message = err.to_string();
    assert!(
        message.contains("vt.obj:5: face 0 refers to texture coordinate 2, but there are only 1"),
        "{message}"
    );
    let err = load_bytes(
        "novertex.obj",
        b"v 0 0 0\nv 1 0 0\nv 1 1 0\nvt 0 0\nf 1/1 /1 3/1\n",
    )
    .unwrap_err();
    let message = err.to_string();
    assert!(
        message.contains("novertex.obj:5: face 0: \"/1\" has no vertex index"),
        "{message}"
    );
}

#[test]
fn obj_syntax_errors_name_the_line() {
    let err = load_bytes("syntax.obj", b"v 0 0 0\nv 1 zero 0\nv 1 1 0\nf 1 2 3\n").unwrap_err();
    assert!(
        matches!(
            err,
            MeshError::Format {
                location: Location::Line(2),
                ..
            }
        ),
        "{err:?}"
    );
    assert!(
        err.to_string()
            .contains("syntax.obj:2: expected a number, found \"zero\""),
        "{err}"
    );

    let err = load_bytes("face.obj", b"v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 x\n").unwrap_err();
    assert!(
        matches!(
            err,
            MeshError::Format {
                location: Location::Line(4),
                ..
            }
        ),
        "{err:?}"
    );
}

#[test]
fn obj_keeps_non_finite_positions() {
    let mesh = load_bytes("nan.obj", b"v NaN 0 0\nv inf 0 0\nv 0 -inf 1\nf 1 2 3\n").unwrap();
    assert!(mesh.positions.iter().any(|p| p[0].is_nan()));
    assert!(mesh.positions.iter().any(|p| p[0] == f32::INFINITY));
    // Bounds skip NaN.
    assert_eq!(
        mesh.bounds(),
        ([0.0, f32::NEG_INFINITY, 0.0], [f32::INFINITY, 0.0, 1.0])
    );
}

#[test]
fn obj_xz_round_trip() {
    let text = b"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n";
    let mut compressed = Vec::new();
    lzma_rs::xz_compress(&mut &text[..], &mut compressed).unwrap();
    let mesh = load_bytes("quad.obj.XZ", &compressed).unwrap();
    assert_eq!(mesh.name, "quad");
    assert_eq!(corners(&mesh), quad_fan());

    let err = load_bytes("broken.obj.xz", &compressed[..compressed.len() / 2]).unwrap_err();
    assert!(matches!(err, MeshError::Decompress { .. }), "{err:?}");
    assert!(err.to_string().contains("broken.obj.xz"), "{err}");
}

// ---------------------------------------------------------------------------- PLY

const ASCII_PLY: &str = "ply
format ascii 1.0
comment a quad and a triangle, with properties to skip
element vertex 5
property float x
property float y
property float z
property uchar red
element face 2
property list uchar int vertex_indices
property float quality
element edge 1
property int vertex1
property int vertex2
end_header
0 0 0 255
1 0 0 255
1 1 0 255
0 1 0 255

2.5 -1e1 3 0
4 0 1 2 3 0.5
3 0 1 4 1.0
0 1
";

#[test]
fn ply_ascii() {
    let mesh = load_bytes("ascii.ply", ASCII_PLY.as_bytes()).unwrap();
    assert_eq!(mesh.positions.len(), 5);
    assert_eq!(mesh.positions[4], [2.5, -10.0, 3.0]);
    assert_eq!(mesh.indices, vec![[0, 1, 2], [0, 2, 3], [0, 1, 4]]);
}

#[test]
fn ply_ascii_index_out_of_range_names_line_and_face() {
    let text = ASCII_PLY.replace("3 0 1 4 1.0", "3 0 1 5 1.0");
    let err = load_bytes("ascii.ply", text.as_bytes()).unwrap_err();
    assert!(
        matches!(
            err,
            MeshError::IndexOutOfRange {
                location: Location::Line(23),
                face: 1,
                index: 5,
                vertex_count: 5,
                ..
            }
        ),
        "{err:?}"
    );
    assert!(
        err.to_string()
            .contains("ascii.ply:23: face 1 refers to vertex 5, but there are only 5 vertices"),
        "{err}"
    );
}

#[test]
fn ply_ascii_syntax_errors_name_the_line() {
    let text = ASCII_PLY.replace("1 1 0 255", "1 one 0 255");
    let err = load_bytes("ascii.ply", text.as_bytes()).unwrap_err();
    assert!(
        matches!(
            err,
            MeshError::Format {
                location: Location::Line(18),
                ..
            }
        ),
        "{err:?}"
    );
    assert!(err.to_string().contains("vertex 2"), "{err}");

    let text = ASCII_PLY.replace("0 1 0 255", "0 1 0 255 7");
    let err = load_bytes("ascii.ply", text.as_bytes()).unwrap_err();
    assert!(
        matches!(
            err,
            MeshError::Format {
                location: Location::Line(19),
                ..
            }
        ),
        "{err:?}"
    );

    let text = ASCII_PLY.replace("property float z", "property float w");
    let err = load_bytes("ascii.ply", text.as_bytes()).unwrap_err();
    assert!(
        matches!(
            err,
            MeshError::Format {
                location: Location::Line(4),
                ..
            }
        ),
        "{err:?}"
    );
    assert!(err.to_string().contains("no 'z' property"), "{err}");
}

/// A binary PLY of [`QUAD`] plus one more vertex, with double coordinates, a skipped
/// property between them, a quad and a triangle (uchar/int lists), a trailing face
/// property and an extra element with a list.
fn binary_ply(big_endian: bool, extra_face_vertex: i32) -> Vec<u8> {
    let format = if big_endian {
        "binary_big_endian"
    } else {
        "binary_little_endian"
    };
    let mut out = format!(
        "ply\r\nformat {format} 1.0\r\nelement vertex 5\r\nproperty double x\r\n\
         property short flags\r\nproperty double y\r\nproperty double z\r\n\
         element face 2\r\nproperty list uchar int vertex_indices\r\nproperty float quality\r\n\
         element material 1\r\nproperty list ushort uchar name\r\nend_header\r\n"
    )
    .into_bytes();
    fn put<const N: usize>(out: &mut Vec<u8>, big_endian: bool, le: [u8; N]) {
        let mut bytes = le;
        if big_endian {
            bytes.reverse();
        }
        out.extend_from_slice(&bytes);
    }
    let vertices = QUAD.iter().copied().chain([[0.5f32, 0.5, 2.0]]);
    for p in vertices {
        put(&mut out, big_endian, f64::from(p[0]).to_le_bytes());
        put(&mut out, big_endian, 7i16.to_le_bytes());
        put(&mut out, big_endian, f64::from(p[1]).to_le_bytes());
        put(&mut out, big_endian, f64::from(p[2]).to_le_bytes());
    }
    let faces: [&[i32]; 2] = [&[0, 1, 2, 3], &[0, 1, extra_face_vertex]];
    for face in faces {
        out.push(face.len() as u8);
        for &i in face {
            put(&mut out, big_endian, i.to_le_bytes());
        }
        put(&mut out, big_endian, 1.5f32.to_le_bytes());
    }
    put(&mut out, big_endian, 3u16.to_le_bytes());
    out.extend_from_slice(b"abc");
    out
}

#[test]
fn ply_binary_both_byte_orders() {
    for big_endian in [false, true] {
        let mesh = load_bytes("bin.ply", &binary_ply(big_endian, 4)).unwrap();
        assert_eq!(mesh.positions.len(), 5, "big endian: {big_endian}");
        assert_eq!(&mesh.positions[..4], &QUAD);
        assert_eq!(mesh.positions[4], [0.5, 0.5, 2.0]);
        assert_eq!(mesh.indices, vec![[0, 1, 2], [0, 2, 3], [0, 1, 4]]);
    }
}

#[test]
fn ply_other_int_types() {
    // `vertex_index` with an int count and ushort items, int coordinates.
    let mut data = b"ply\nformat binary_big_endian 1.0\nelement vertex 3\nproperty int x\n\
        property uchar y\nproperty char z\nelement face 1\nproperty list int ushort vertex_index\nend_header\n"
        .to_vec();
    for (x, y, z) in [(0i32, 0u8, 0i8), (-2, 0, 0), (0, 3, -1)] {
        data.extend(x.to_be_bytes());
        data.push(y);
        data.push(z as u8);
    }
    data.extend(3i32.to_be_bytes());
    for i in [0u16, 1, 2] {
        data.extend(i.to_be_bytes());
    }
    let mesh = load_bytes("ints.ply", &data).unwrap();
    assert_eq!(
        mesh.positions,
        vec![[0.0, 0.0, 0.0], [-2.0, 0.0, 0.0], [0.0, 3.0, -1.0]]
    );
    assert_eq!(mesh.indices, vec![[0, 1, 2]]);
}

#[test]
fn ply_binary_truncated() {
    let data = binary_ply(false, 4);
    // Cut inside the second face, then inside the vertices.
    for (cut, expected) in [
        (data.len() - 12, "face 1 of 2"),
        (data.len() - 50, "vertex 4 of 5"),
    ] {
        let err = load_bytes("cut.ply", &data[..cut]).unwrap_err();
        assert!(matches!(err, MeshError::Truncated { .. }), "{err:?}");
        let message = err.to_string();
        assert!(
            message.contains("cut.ply: truncated") && message.contains(expected),
            "{message}"
        );
    }
}

#[test]
fn ply_binary_index_out_of_range_names_the_face() {
    for bad in [5, -1] {
        let err = load_bytes("range.ply", &binary_ply(true, bad)).unwrap_err();
        assert!(
            matches!(
                err,
                MeshError::IndexOutOfRange {
                    face: 1,
                    vertex_count: 5,
                    ..
                }
            ),
            "{err:?}"
        );
        let message = err.to_string();
        assert!(
            message.contains(&format!(
                "range.ply: face 1 refers to vertex {bad}, but there are only 5"
            )),
            "{message}"
        );
    }
}

#[test]
fn ply_huge_header_counts_do_not_allocate() {
    // Claims ~1.8e19 vertices and faces in a file of a few hundred bytes.
    let data =
        b"ply\nformat binary_little_endian 1.0\nelement vertex 4294967295\nproperty float x\n\
        property float y\nproperty float z\nelement face 18446744073709551615\n\
        property list uint int vertex_indices\nend_header\n\0\0\0\0\0\0\0\0\0\0\0\0";
    let err = load_bytes("huge.ply", data).unwrap_err();
    assert!(matches!(err, MeshError::Truncated { .. }), "{err:?}");

    let data = b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n\
        property float y\nproperty float z\nelement face 1\nproperty list uint int vertex_indices\n\
        end_header\n\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\
        \xff\xff\xff\xff\0\0\0\0";
    let err = load_bytes("hugelist.ply", data).unwrap_err();
    assert!(matches!(err, MeshError::Truncated { .. }), "{err:?}");
}

#[test]
fn ply_bad_headers() {
    for (text, expected) in [
        ("", "not a PLY file"),
        ("solid cube\n", "not a PLY file"),
        ("ply\nformat ascii 1.0\nelement vertex 1\n", "no end_header"),
        (
            "ply\nformat ascii 1.0\nproperty float x\nend_header\n",
            ":3: property before any element",
        ),
        (
            "ply\nformat ascii 1.0\nelement vertex 1\nproperty half x\nend_header\n",
            ":4: unknown property type",
        ),
        (
            "ply\nformat ascii 1.0\nelement vertex -1\nend_header\n",
            ":3: bad element count",
        ),
        ("ply\nelement vertex 0\nend_header\n", "no format line"),
        (
            "ply\nformat ascii 1.0\nelement face 0\nend_header\n",
            "no vertex element",
        ),
        (
            "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\n\
             property float z\nelement face 0\nproperty list uchar float vertex_indices\nend_header\n",
            ":7: face property 'vertex_indices' is not a list of integers",
        ),
    ] {
        let err = load_bytes("h.ply", text.as_bytes()).unwrap_err();
        let message = err.to_string();
        assert!(message.contains(expected), "{text:?}: {message}");
    }
}

#[test]
fn ply_without_faces_has_no_triangles() {
    let text = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n\
                property float z\nend_header\n1 2 3\n";
    let err = load_bytes("points.ply", text.as_bytes()).unwrap_err();
    assert!(matches!(err, MeshError::NoTriangles { .. }), "{err:?}");
}

// ---------------------------------------------------------------------------- glTF

/// Four vertices of [`QUAD`] (48 bytes) followed by six u16 indices (12 bytes).
fn quad_buffer(last_index: u16) -> Vec<u8> {
    let mut buffer: Vec<u8> = QUAD
        .iter()
        .flatten()
        .flat_map(|c| c.to_le_bytes())
        .collect();
    for i in [0u16, 1, 2, 0, 2, last_index] {
        buffer.extend(i.to_le_bytes());
    }
    buffer
}

/// glTF JSON for [`quad_buffer`]: a translated parent node with a scaled child that holds
/// the mesh, plus a points primitive that must be skipped.
fn quad_json(buffer_uri: Option<&str>, child_scale: [f32; 3]) -> String {
    let uri = buffer_uri
        .map(|u| format!(r#","uri":"{u}""#))
        .unwrap_or_default();
    format!(
        r#"{{
  "asset": {{"version": "2.0"}},
  "scene": 0,
  "scenes": [{{"nodes": [0]}}],
  "nodes": [
    {{"translation": [10, 0, 0], "children": [1]}},
    {{"mesh": 0, "scale": {child_scale:?}}}
  ],
  "meshes": [{{"primitives": [
    {{"attributes": {{"POSITION": 0}}, "mode": 0}},
    {{"attributes": {{"POSITION": 0}}, "indices": 1}}
  ]}}],
  "buffers": [{{"byteLength": 60{uri}}}],
  "bufferViews": [
    {{"buffer": 0, "byteOffset": 0, "byteLength": 48}},
    {{"buffer": 0, "byteOffset": 48, "byteLength": 12}}
  ],
  "accessors": [
    {{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
      "min": [0, 0, 0], "max": [1, 1, 0]}},
    {{"bufferView": 1, "componentType": 5123, "count": 6, "type": "SCALAR"}}
  ]
}}"#
    )
}

fn data_uri(bytes: &[u8]) -> String {
    let encoded = base64::engine::general_purpose::STANDARD.encode(bytes);
    format!("data:application/octet-stream;base64,{encoded}")
}

fn glb(json: &str, bin: &[u8]) -> Vec<u8> {
    let pad = |mut chunk: Vec<u8>, fill: u8| {
        chunk.resize(chunk.len().next_multiple_of(4), fill);
        chunk
    };
    let json = pad(json.as_bytes().to_vec(), b' ');
    let bin = pad(bin.to_vec(), 0);
    let total = 12 + 8 + json.len() + 8 + bin.len();
    let mut out = Vec::with_capacity(total);
    out.extend(b"glTF");
    out.extend(2u32.to_le_bytes());
    out.extend((total as u32).to_le_bytes());
    out.extend((json.len() as u32).to_le_bytes());
    out.extend(b"JSON");
    out.extend(&json);
    out.extend((bin.len() as u32).to_le_bytes());
    out.extend(b"BIN\0");
    out.extend(&bin);
    out
}

/// [`QUAD`] scaled by 2 and moved 10 along x, fan-triangulated.
fn transformed_quad_fan() -> Vec<[[f32; 3]; 3]> {
    quad_fan()
        .into_iter()
        .map(|t| t.map(|p| [p[0] * 2.0 + 10.0, p[1] * 2.0, p[2] * 2.0]))
        .collect()
}

#[test]
fn gltf_embedded_buffer_with_node_transforms() {
    let json = quad_json(Some(&data_uri(&quad_buffer(3))), [2.0; 3]);
    let mesh = load_bytes("quad.gltf", json.as_bytes()).unwrap();
    assert_eq!(mesh.name, "quad");
    assert_eq!(corners(&mesh), transformed_quad_fan());
    assert_eq!(mesh.bounds(), ([10.0, 0.0, 0.0], [12.0, 2.0, 0.0]));
}

#[test]
fn gltf_external_buffer() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("quad data.bin"), quad_buffer(3)).unwrap();
    let path = dir.path().join("quad.gltf");
    std::fs::write(&path, quad_json(Some("quad%20data.bin"), [2.0; 3])).unwrap();
    assert_eq!(corners(&load(&path).unwrap()), transformed_quad_fan());
}

#[test]
fn glb_with_bin_chunk() {
    let data = glb(&quad_json(None, [2.0; 3]), &quad_buffer(3));
    let mesh = load_bytes("quad.glb", &data).unwrap();
    assert_eq!(corners(&mesh), transformed_quad_fan());

    let err = load_bytes("cut.glb", &data[..data.len() - 20]).unwrap_err();
    assert!(matches!(err, MeshError::Truncated { .. }), "{err:?}");
}

#[test]
fn gltf_mirroring_transform_keeps_winding() {
    let json = quad_json(Some(&data_uri(&quad_buffer(3))), [-1.0, 1.0, 1.0]);
    let mesh = load_bytes("mirror.gltf", json.as_bytes()).unwrap();
    let mirrored = |p: [f32; 3]| [10.0 - p[0], p[1], p[2]];
    let expected: Vec<_> = quad_fan()
        .into_iter()
        .map(|[a, b, c]| [mirrored(a), mirrored(c), mirrored(b)])
        .collect();
    assert_eq!(corners(&mesh), expected);
}

#[test]
fn gltf_index_out_of_range_names_primitive_and_face() {
    let json = quad_json(Some(&data_uri(&quad_buffer(4))), [1.0; 3]);
    let err = load_bytes("range.gltf", json.as_bytes()).unwrap_err();
    assert!(
        matches!(
            err,
            MeshError::IndexOutOfRange {
                location: Location::Primitive {
                    mesh: 0,
                    primitive: 1
                },
                face: 1,
                index: 4,
                vertex_count: 4,
                ..
            }
        ),
        "{err:?}"
    );
    assert!(
        err.to_string()
            .contains("range.gltf (mesh 0, primitive 1): face 1 refers to vertex 4"),
        "{err}"
    );
}

#[test]
fn gltf_buffer_too_short() {
    let json = quad_json(Some(&data_uri(&quad_buffer(3)[..50])), [1.0; 3]);
    let err = load_bytes("short.gltf", json.as_bytes()).unwrap_err();
    assert!(matches!(err, MeshError::Truncated { .. }), "{err:?}");
}

#[test]
fn gltf_node_cycle_is_an_error() {
    let json = quad_json(Some(&data_uri(&quad_buffer(3))), [1.0; 3])
        .replace(r#""mesh": 0,"#, r#""mesh": 0, "children": [0],"#);
    let err = load_bytes("cycle.gltf", json.as_bytes()).unwrap_err();
    assert!(err.to_string().contains("reached twice"), "{err}");
}

// ---------------------------------------------------------------------------- general

#[test]
fn unknown_extension_lists_the_supported_ones() {
    let err = load_bytes("model.stl", b"solid").unwrap_err();
    assert!(
        matches!(err, MeshError::UnsupportedExtension { .. }),
        "{err:?}"
    );
    let message = err.to_string();
    assert!(message.contains("model.stl"), "{message}");
    for ext in [".obj", ".ply", ".gltf", ".glb", ".xz"] {
        assert!(message.contains(ext), "{message}");
    }
    let err = load_bytes("noext", b"").unwrap_err();
    assert!(
        matches!(err, MeshError::UnsupportedExtension { .. }),
        "{err:?}"
    );
}

#[test]
fn missing_file_is_an_io_error() {
    let err = load(Path::new("/nonexistent/dir/x.obj")).unwrap_err();
    assert!(matches!(err, MeshError::Io { .. }), "{err:?}");
    assert!(
        err.to_string()
            .starts_with("/nonexistent/dir/x.obj: cannot read"),
        "{err}"
    );
}

#[test]
fn empty_files() {
    let err = load_bytes("empty.obj", b"").unwrap_err();
    assert!(matches!(err, MeshError::NoTriangles { .. }), "{err:?}");
    assert!(
        err.to_string().ends_with("empty.obj: no triangles"),
        "{err}"
    );
    for name in ["empty.ply", "empty.gltf", "empty.glb", "empty.obj.xz"] {
        let err = load_bytes(name, b"").unwrap_err();
        assert!(err.to_string().contains(name), "{err}");
    }
}

/// A small xorshift generator, so that the mutation test is reproducible.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }

    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

/// Mutations per sample file; `HOSTAS_FUZZ_ITERATIONS` raises it for a longer run
/// (300,000 passed when this was written).
fn fuzz_iterations() -> usize {
    std::env::var("HOSTAS_FUZZ_ITERATIONS")
        .ok()
        .and_then(|n| n.parse().ok())
        .unwrap_or(3000)
}

/// Replaces the first run of digits at or after `at` with a troublesome number, to
/// reach the checks behind the syntax (counts, offsets, indices, lengths).
fn replace_number(data: &mut Vec<u8>, at: usize, rng: &mut Rng) {
    const NUMBERS: [&str; 10] = [
        "0",
        "1",
        "3",
        "4",
        "255",
        "65535",
        "4294967295",
        "4294967296",
        "18446744073709551615",
        "99999999999999999999",
    ];
    let Some(start) = data[at..]
        .iter()
        .position(u8::is_ascii_digit)
        .map(|i| at + i)
    else {
        return;
    };
    let end = data[start..]
        .iter()
        .position(|b| !b.is_ascii_digit())
        .map_or(data.len(), |i| start + i);
    let number = NUMBERS[rng.below(NUMBERS.len())];
    data.splice(start..end, number.bytes());
}

/// Feeds each parser thousands of damaged versions of good files: any result is fine,
/// a panic fails the test. The parsers are called directly, without files.
#[test]
fn damaged_inputs_never_panic() {
    let path = Path::new("fuzz");
    type Parser = fn(&Path, &[u8]) -> Result<Triangles, MeshError>;
    let samples: Vec<(Parser, Vec<u8>)> = vec![
        (
            obj::parse,
            b"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1/1 2/1 3/1 4/1\nf -1 -2 -3\n".to_vec(),
        ),
        (ply::parse, ASCII_PLY.as_bytes().to_vec()),
        (ply::parse, binary_ply(false, 4)),
        (ply::parse, binary_ply(true, 4)),
        (
            gltf::parse,
            quad_json(Some(&data_uri(&quad_buffer(3))), [1.0; 3]).into_bytes(),
        ),
        (
            gltf::parse,
            glb(&quad_json(None, [1.0; 3]), &quad_buffer(3)),
        ),
    ];
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    let interesting: &[u8] = b"0123456789-./ \n\xff\0,:}]\"e";
    for (parse, sample) in &samples {
        for _ in 0..fuzz_iterations() {
            let mut data = sample.clone();
            for _ in 0..1 + rng.below(4) {
                let at = rng.below(data.len());
                match rng.below(6) {
                    0 => data.truncate(at),
                    1 => data[at] = rng.next() as u8,
                    2 => data[at] = interesting[rng.below(interesting.len())],
                    3 => {
                        data.remove(at);
                    }
                    4 => data.insert(at, interesting[rng.below(interesting.len())]),
                    _ => replace_number(&mut data, at, &mut rng),
                }
                if data.is_empty() {
                    break;
                }
            }
            let _ = parse(path, &data);
        }
    }
}

// ---------------------------------------------------------------------------- real meshes

fn shared_meshes() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/meshes")
}

/// Loads each mesh of `../shared/meshes/` (beside the repository) that is present and
/// checks its counts. The triangle counts were verified independently: OBJ by summing
/// `NF - 3` over `f` lines with awk, PLY from the header counts plus a Python check that
/// every face has exactly 3 indices and the body size is exact.
#[test]
fn shared_meshes_load_with_the_right_counts() {
    let dir = shared_meshes();
    if !dir.is_dir() {
        println!("skipping: {} is absent", dir.display());
        return;
    }
    // (file, triangles, vertices where the loader must keep them all)
    let expected: [(&str, usize, Option<usize>); 6] = [
        ("spot.obj", 5_856, Some(2_930)),
        // 35,947 `v` lines, of which 34,834 are used by faces (awk over the `f` lines);
        // tobj keeps only the used ones.
        ("stanford-bunny.obj", 69_451, Some(34_834)),
        // 34 groups that share no vertices, and every vertex is used.
        ("sponza-dabrovic.obj", 66_454, Some(39_999)),
        ("sibenik.ply", 75_284, Some(40_981)),
        ("conference.ply", 331_179, Some(194_399)),
        ("crown-pbrt-flat.ply.xz", 3_540_202, Some(1_868_115)),
    ];
    for (file, triangles, vertices) in expected {
        let path = dir.join(file);
        if !path.is_file() {
            println!("skipping {file}: not present");
            continue;
        }
        let start = Instant::now();
        let mesh = load(&path).unwrap_or_else(|e| panic!("{e}"));
        let elapsed = start.elapsed();
        let (lo, hi) = mesh.bounds();
        println!(
            "{file}: {} triangles, {} vertices, loaded in {:.3} s, bounds {lo:?} .. {hi:?}",
            mesh.triangle_count(),
            mesh.positions.len(),
            elapsed.as_secs_f64()
        );
        assert_eq!(mesh.triangle_count(), triangles, "{file}");
        if let Some(vertices) = vertices {
            assert_eq!(mesh.positions.len(), vertices, "{file}");
        }
        assert!(
            lo.iter()
                .zip(&hi)
                .all(|(l, h)| l.is_finite() && h.is_finite() && l < h),
            "{file}"
        );
    }
}
