//! STAND-IN mesh loader, used until `hostas_cli::mesh::load` exists (another crate of this
//! project is writing it). Same shape: `load(&Path) -> Result<Mesh, MeshError>` with
//! `Mesh { name, positions, indices }`. Reads OBJ (polygons as fans, negative indices, v/vt/vn
//! forms), binary little-endian PLY (float x/y/z, one list property for faces), and either one
//! compressed with xz (`.xz`, through the `xz -dc` command). Nothing more.

use std::path::Path;

pub struct Mesh {
    #[allow(dead_code)]
    pub name: String,
    pub positions: Vec<[f32; 3]>,
    pub indices: Vec<[u32; 3]>,
}

#[derive(Debug)]
pub struct MeshError(pub String);

impl std::fmt::Display for MeshError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for MeshError {}

fn err(s: impl Into<String>) -> MeshError {
    MeshError(s.into())
}

pub fn load(path: &Path) -> Result<Mesh, MeshError> {
    let file_name = path
        .file_name()
        .and_then(|s| s.to_str())
        .unwrap_or("mesh")
        .to_string();
    let (bytes, inner) = if let Some(stripped) = file_name.strip_suffix(".xz") {
        let out = std::process::Command::new("xz")
            .arg("-dc")
            .arg(path)
            .output()
            .map_err(|e| err(format!("{}: cannot run xz: {e}", path.display())))?;
        if !out.status.success() {
            return Err(err(format!("{}: xz -dc failed", path.display())));
        }
        (out.stdout, stripped.to_string())
    } else {
        let b = std::fs::read(path).map_err(|e| err(format!("{}: {e}", path.display())))?;
        (b, file_name.clone())
    };
    let name = inner.split('.').next().unwrap_or("mesh").to_string();
    let lower = inner.to_ascii_lowercase();
    let (positions, indices) = if lower.ends_with(".obj") {
        parse_obj(&bytes)?
    } else if lower.ends_with(".ply") {
        parse_ply(&bytes)?
    } else {
        return Err(err(format!("{}: unsupported mesh format", path.display())));
    };
    for t in &indices {
        for &i in t {
            if i as usize >= positions.len() {
                return Err(err(format!("{}: index {i} out of range", path.display())));
            }
        }
    }
    Ok(Mesh {
        name,
        positions,
        indices,
    })
}

type Parsed = (Vec<[f32; 3]>, Vec<[u32; 3]>);

fn parse_obj(bytes: &[u8]) -> Result<Parsed, MeshError> {
    let text = std::str::from_utf8(bytes).map_err(|_| err("OBJ is not UTF-8"))?;
    let mut pos = Vec::new();
    let mut idx = Vec::new();
    let mut poly: Vec<u32> = Vec::new();
    for line in text.lines() {
        let mut it = line.split_ascii_whitespace();
        match it.next() {
            Some("v") => {
                let mut p = [0f32; 3];
                for c in &mut p {
                    *c = it
                        .next()
                        .and_then(|s| s.parse().ok())
                        .ok_or_else(|| err("bad OBJ vertex"))?;
                }
                pos.push(p);
            }
            Some("f") => {
                poly.clear();
                for tok in it {
                    let first = tok.split('/').next().unwrap_or("");
                    let i: i64 = first
                        .parse()
                        .map_err(|_| err(format!("bad OBJ face index {tok}")))?;
                    let i = if i < 0 { pos.len() as i64 + i } else { i - 1 };
                    if i < 0 {
                        return Err(err("OBJ face index out of range"));
                    }
                    poly.push(i as u32);
                }
                for k in 1..poly.len().saturating_sub(1) {
                    idx.push([poly[0], poly[k], poly[k + 1]]);
                }
            }
            _ => {}
        }
    }
    Ok((pos, idx))
}

#[derive(Clone, Copy)]
enum Ty {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Ty {
    fn parse(s: &str) -> Option<Ty> {
        Some(match s {
            "char" | "int8" => Ty::I8,
            "uchar" | "uint8" => Ty::U8,
            "short" | "int16" => Ty::I16,
            "ushort" | "uint16" => Ty::U16,
            "int" | "int32" => Ty::I32,
            "uint" | "uint32" => Ty::U32,
            "float" | "float32" => Ty::F32,
            "double" | "float64" => Ty::F64,
            _ => return None,
        })
    }
    fn size(self) -> usize {
        match self {
            Ty::I8 | Ty::U8 => 1,
            Ty::I16 | Ty::U16 => 2,
            Ty::I32 | Ty::U32 | Ty::F32 => 4,
            Ty::F64 => 8,
        }
    }
    fn read(self, b: &[u8]) -> f64 {
        match self {
            Ty::I8 => b[0] as i8 as f64,
            Ty::U8 => b[0] as f64,
            Ty::I16 => i16::from_le_bytes([b[0], b[1]]) as f64,
            Ty::U16 => u16::from_le_bytes([b[0], b[1]]) as f64,
            Ty::I32 => i32::from_le_bytes(b[..4].try_into().unwrap()) as f64,
            Ty::U32 => u32::from_le_bytes(b[..4].try_into().unwrap()) as f64,
            Ty::F32 => f32::from_le_bytes(b[..4].try_into().unwrap()) as f64,
            Ty::F64 => f64::from_le_bytes(b[..8].try_into().unwrap()),
        }
    }
}

enum Prop {
    Scalar(String, Ty),
    List(String, Ty, Ty),
}

fn parse_ply(bytes: &[u8]) -> Result<Parsed, MeshError> {
    let end = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .ok_or_else(|| err("PLY: no end_header"))?;
    let header = std::str::from_utf8(&bytes[..end]).map_err(|_| err("PLY header not UTF-8"))?;
    let mut body = &bytes[end + 11..];
    let mut elements: Vec<(String, usize, Vec<Prop>)> = Vec::new();
    for line in header.lines() {
        let t: Vec<&str> = line.split_ascii_whitespace().collect();
        match t.as_slice() {
            ["format", f, ..] if *f != "binary_little_endian" => {
                return Err(err(format!(
                    "PLY format {f} not supported by the stand-in loader"
                )));
            }
            ["element", name, n] => elements.push((
                name.to_string(),
                n.parse().map_err(|_| err("PLY count"))?,
                Vec::new(),
            )),
            ["property", "list", ct, it, name] => {
                let e = elements
                    .last_mut()
                    .ok_or_else(|| err("PLY property before element"))?;
                e.2.push(Prop::List(
                    name.to_string(),
                    Ty::parse(ct).ok_or_else(|| err("PLY type"))?,
                    Ty::parse(it).ok_or_else(|| err("PLY type"))?,
                ));
            }
            ["property", ty, name] => {
                let e = elements
                    .last_mut()
                    .ok_or_else(|| err("PLY property before element"))?;
                e.2.push(Prop::Scalar(
                    name.to_string(),
                    Ty::parse(ty).ok_or_else(|| err("PLY type"))?,
                ));
            }
            _ => {}
        }
    }
    let mut pos = Vec::new();
    let mut idx = Vec::new();
    let short = || err("PLY: truncated body");
    for (name, count, props) in &elements {
        let fixed: Option<usize> = props
            .iter()
            .map(|p| match p {
                Prop::Scalar(_, t) => Some(t.size()),
                Prop::List(..) => None,
            })
            .sum();
        if name == "vertex" {
            let stride = fixed.ok_or_else(|| err("PLY: list property in vertex"))?;
            let mut off = [usize::MAX; 3];
            let mut tys = [Ty::F32; 3];
            let mut o = 0;
            for p in props {
                if let Prop::Scalar(n, t) = p {
                    let k = match n.as_str() {
                        "x" => 0,
                        "y" => 1,
                        "z" => 2,
                        _ => 3,
                    };
                    if k < 3 {
                        off[k] = o;
                        tys[k] = *t;
                    }
                    o += t.size();
                }
            }
            if off.contains(&usize::MAX) {
                return Err(err("PLY: vertex lacks x/y/z"));
            }
            if body.len() < stride * count {
                return Err(short());
            }
            pos.reserve(*count);
            for v in 0..*count {
                let r = &body[v * stride..];
                pos.push([0, 1, 2].map(|k| tys[k].read(&r[off[k]..]) as f32));
            }
            body = &body[stride * count..];
        } else if let Some(stride) = fixed {
            body = body.get(stride * count..).ok_or_else(short)?;
        } else {
            let is_face = name == "face";
            for _ in 0..*count {
                let mut poly: Vec<u32> = Vec::new();
                for p in props {
                    match p {
                        Prop::Scalar(_, t) => body = body.get(t.size()..).ok_or_else(short)?,
                        Prop::List(n, ct, it) => {
                            let c = ct.read(body.get(..ct.size()).ok_or_else(short)?) as usize;
                            body = &body[ct.size()..];
                            let bytes = c * it.size();
                            let items = body.get(..bytes).ok_or_else(short)?;
                            if is_face && (n == "vertex_indices" || n == "vertex_index") {
                                poly = (0..c)
                                    .map(|k| it.read(&items[k * it.size()..]) as u32)
                                    .collect();
                            }
                            body = &body[bytes..];
                        }
                    }
                }
                for k in 1..poly.len().saturating_sub(1) {
                    idx.push([poly[0], poly[k], poly[k + 1]]);
                }
            }
        }
    }
    Ok((pos, idx))
}
