//! `hostas info FILE...`: decodes serialized acceleration structures (the spec header of any
//! implementation; statistics for hostas data) and `hostas build` files.

use crate::cli::print;
use crate::container::{self, Container};
use crate::report::{build_flag_names, bytes, thousands, uuid};
use anyhow::{Context, Result, anyhow};
use clap::Args;
use hostas::Device;
use hostas::commands::SerializedHeader;
use hostas::device::{COMPATIBILITY_UUID, DRIVER_UUID};
use serde::Serialize;
use std::fmt::Write as _;
use std::path::PathBuf;

const AFTER_HELP: &str = "\
FILE is a `hostas build` file or the bytes vkCopyAccelerationStructureToMemoryKHR wrote, from
any implementation: the header (driverUUID, compatibility UUID, sizes, handle list) is always
decoded; hostas data of this version is also deserialized for its statistics.

Examples:
  hostas info bunny.hostas
  hostas info --json dump.bin | jq .structures[0].statistics.sah_cost";

/// Decode a serialized acceleration structure or a `hostas build` file
#[derive(Args, Debug)]
#[command(after_help = AFTER_HELP)]
pub struct InfoArgs {
    /// Files to describe
    #[arg(required = true, value_name = "FILE")]
    pub files: Vec<PathBuf>,
    /// One JSON object per file, on one line each
    #[arg(long)]
    pub json: bool,
}

#[derive(Serialize, Debug)]
pub struct FileInfo {
    pub file: String,
    /// `hostas-build` or `serialized`.
    pub format: &'static str,
    pub bytes: u64,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub bounds: Option<[[f32; 3]; 2]>,
    pub structures: Vec<StructureInfo>,
}

#[derive(Serialize, Debug)]
pub struct StructureInfo {
    /// `bottom level i`, `top level` or `structure`.
    pub role: String,
    pub name: String,
    pub header: HeaderInfo,
    /// `hostas` (this version), `hostas-other-version`, or `unknown`.
    pub implementation: &'static str,
    pub compatible: bool,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub statistics: Option<Stats>,
    pub notes: Vec<String>,
}

#[derive(Serialize, Debug)]
pub struct HeaderInfo {
    pub driver_uuid: String,
    pub compatibility_uuid: String,
    pub serialized_size: u64,
    pub deserialized_size: u64,
    pub handle_count: u64,
    pub handles: Vec<u64>,
}

#[derive(Serialize, Debug)]
pub struct Stats {
    #[serde(rename = "type")]
    pub ty: &'static str,
    pub primitive_kind: &'static str,
    pub build_flags: Vec<String>,
    pub preset: &'static str,
    pub geometries: u32,
    pub primitives: u32,
    pub active_primitives: u32,
    pub nodes: u32,
    pub leaves: u32,
    pub depth: u32,
    pub sah_cost: f32,
    /// How triangles are stored: "indexed" (records into shared vertices) or "direct" (three
    /// vertices each); empty for other primitives.
    pub triangles: &'static str,
    /// Vertices the indexed triangles share (0 when direct).
    pub shared_vertices: u32,
    pub bytes: u64,
    pub bytes_per_primitive: f64,
}

fn prim_kind_name(k: hostas::layout::PrimKind) -> &'static str {
    use hostas::layout::PrimKind as K;
    match k {
        K::None => "none",
        K::Triangles => "triangles",
        K::Aabbs => "aabbs",
        K::Instances => "instances",
    }
}

/// Describes one serialized structure.
pub fn describe(device: &Device, role: String, name: String, data: &[u8]) -> Result<StructureInfo> {
    let h = SerializedHeader::parse(data)
        .map_err(|e| anyhow!("{role}: not a serialized acceleration structure: {e}"))?;
    let mut notes = Vec::new();
    if h.serialized_size != data.len() as u64 {
        notes.push(format!(
            "serializedSize says {} bytes, {} are present",
            h.serialized_size,
            data.len()
        ));
    }
    if h.handle_count >> 32 != 0 {
        notes.push("the handle count's high half is set: a block-based (opacity micromap) header, no plain handle list".into());
    }
    let ours = h.driver_uuid == DRIVER_UUID;
    let compatible = ours && h.compatibility_uuid == COMPATIBILITY_UUID;
    let start = 56 + 8 * h.handles.len();
    let hostas_payload = data
        .get(start..)
        .is_some_and(hostas::commands::copy::is_hostas_structure);
    let implementation = if compatible {
        "hostas"
    } else if ours || hostas_payload {
        "hostas-other-version"
    } else {
        "unknown"
    };
    let mut statistics = None;
    if compatible {
        match device.deserialize(data) {
            Ok(a) => {
                let s = device.statistics(a).map_err(|e| anyhow!("{role}: {e}"))?;
                statistics = Some(Stats {
                    ty: if s.top_level {
                        "top-level"
                    } else {
                        "bottom-level"
                    },
                    primitive_kind: prim_kind_name(s.prim_kind),
                    build_flags: build_flag_names(s.build_flags),
                    preset: s.preset,
                    geometries: s.geometry_count,
                    primitives: s.primitive_count,
                    active_primitives: s.stored_count,
                    nodes: s.node_count,
                    leaves: s.leaf_count,
                    depth: s.depth,
                    sah_cost: s.sah_cost,
                    triangles: match (s.prim_kind, s.indexed_triangles) {
                        (hostas::layout::PrimKind::Triangles, true) => "indexed",
                        (hostas::layout::PrimKind::Triangles, false) => "direct",
                        _ => "",
                    },
                    shared_vertices: s.vertex_count,
                    bytes: s.used_bytes,
                    bytes_per_primitive: s.bytes_per_primitive(),
                });
                let _ = device.destroy_acceleration_structure(a);
            }
            Err(e) => notes.push(format!("the payload does not deserialize: {e}")),
        }
    } else if implementation == "hostas-other-version" {
        notes.push(
            "serialized by another hostas version or layout: statistics need the same version"
                .into(),
        );
    } else {
        notes.push("serialized by another implementation: its payload is opaque to hostas".into());
    }
    Ok(StructureInfo {
        role,
        name,
        header: HeaderInfo {
            driver_uuid: uuid(&h.driver_uuid),
            compatibility_uuid: uuid(&h.compatibility_uuid),
            serialized_size: h.serialized_size,
            deserialized_size: h.deserialized_size,
            handle_count: h.handle_count,
            handles: h.handles,
        },
        implementation,
        compatible,
        statistics,
        notes,
    })
}

/// Describes a file.
pub fn inspect(path: &std::path::Path) -> Result<FileInfo> {
    let data = std::fs::read(path).with_context(|| format!("{}: cannot read", path.display()))?;
    let device = Device::new();
    let file = path.display().to_string();
    if container::is_container(&data) {
        let c = Container::parse(&data).with_context(|| file.clone())?;
        let mut structures = Vec::new();
        for (i, b) in c.blases.iter().enumerate() {
            structures.push(
                describe(
                    &device,
                    format!("bottom level {i}"),
                    b.name.clone(),
                    &b.data,
                )
                .with_context(|| file.clone())?,
            );
        }
        structures.push(
            describe(&device, "top level".into(), String::new(), &c.tlas.data)
                .with_context(|| file.clone())?,
        );
        return Ok(FileInfo {
            file,
            format: "hostas-build",
            bytes: data.len() as u64,
            bounds: c.bounds.map(|(l, h)| [l, h]),
            structures,
        });
    }
    let not_one = |why: String| {
        let mesh_hint = if crate::mesh::is_mesh_path(path) {
            "; it looks like a mesh: `hostas build` makes a structure of it"
        } else {
            ""
        };
        anyhow!(
            "{file}: not a hostas build file or serialized acceleration structure ({why}){mesh_hint}"
        )
    };
    // Plausibility: any implementation's data starts with its total size and handle list.
    let h = SerializedHeader::parse(&data).map_err(|e| not_one(e.to_string()))?;
    let listed = 56 + 8 * h.handles.len() as u64;
    if h.serialized_size > data.len() as u64 || h.serialized_size < listed {
        return Err(not_one(format!(
            "its header gives serializedSize {} for a file of {} bytes{}",
            h.serialized_size,
            data.len(),
            if h.serialized_size > data.len() as u64 {
                ": truncated?"
            } else {
                ""
            }
        )));
    }
    let s = describe(&device, "structure".into(), String::new(), &data)
        .map_err(|e| not_one(e.to_string()))?;
    Ok(FileInfo {
        file,
        format: "serialized",
        bytes: data.len() as u64,
        bounds: None,
        structures: vec![s],
    })
}

fn text(info: &FileInfo) -> String {
    let mut s = String::new();
    let what = match info.format {
        "hostas-build" => format!(
            "hostas build file, {} bottom level(s) and a top level",
            info.structures.len().saturating_sub(1)
        ),
        _ => "serialized acceleration structure".to_string(),
    };
    let _ = writeln!(s, "{}: {what}, {}", info.file, bytes(info.bytes));
    if let Some([lo, hi]) = info.bounds {
        let _ = writeln!(
            s,
            "  bounds: ({}, {}, {}) .. ({}, {}, {})",
            lo[0], lo[1], lo[2], hi[0], hi[1], hi[2]
        );
    }
    for st in &info.structures {
        let _ = writeln!(s);
        let name = if st.name.is_empty() {
            String::new()
        } else {
            format!(" \"{}\"", st.name)
        };
        let _ = writeln!(s, "{}{name}:", st.role);
        let h = &st.header;
        let who = match st.implementation {
            "hostas" => format!("hostas {}, this version", env!("CARGO_PKG_VERSION")),
            "hostas-other-version" => "hostas, another version".to_string(),
            _ => "another implementation".to_string(),
        };
        let row = |s: &mut String, k: &str, v: String| {
            let _ = writeln!(s, "  {k:<20} {v}");
        };
        row(&mut s, "driverUUID", format!("{}  ({who})", h.driver_uuid));
        row(
            &mut s,
            "compatibility UUID",
            format!(
                "{}  ({})",
                h.compatibility_uuid,
                if st.compatible {
                    "compatible"
                } else {
                    "incompatible with this hostas"
                }
            ),
        );
        row(
            &mut s,
            "serialized size",
            format!("{} bytes", thousands(h.serialized_size)),
        );
        row(
            &mut s,
            "deserialized size",
            format!("{} bytes", thousands(h.deserialized_size)),
        );
        let mut handles: Vec<String> = h
            .handles
            .iter()
            .take(8)
            .map(|v| format!("{v:#x}"))
            .collect();
        if h.handles.len() > 8 {
            handles.push(format!("... ({} more)", h.handles.len() - 8));
        }
        let legend = if info.format == "hostas-build" && st.role == "top level" {
            "  (i+1 = bottom level i of this file, 0 = inactive)"
        } else {
            ""
        };
        row(
            &mut s,
            "handles",
            if handles.is_empty() {
                format!("{}", h.handle_count)
            } else {
                format!("{}: {}{legend}", h.handle_count, handles.join(", "))
            },
        );
        if let Some(t) = &st.statistics {
            row(&mut s, "type", format!("{}, {}", t.ty, t.primitive_kind));
            row(
                &mut s,
                "build flags",
                if t.build_flags.is_empty() {
                    "none".into()
                } else {
                    t.build_flags.join(" | ")
                },
            );
            row(&mut s, "preset", t.preset.to_string());
            row(&mut s, "geometries", thousands(t.geometries as u64));
            row(
                &mut s,
                "primitives",
                format!(
                    "{} ({} active)",
                    thousands(t.primitives as u64),
                    thousands(t.active_primitives as u64)
                ),
            );
            row(
                &mut s,
                "nodes",
                format!(
                    "{} ({}-wide), {} leaves",
                    thousands(t.nodes as u64),
                    hostas::layout::WIDTH,
                    thousands(t.leaves as u64)
                ),
            );
            row(&mut s, "depth", t.depth.to_string());
            row(&mut s, "SAH cost", format!("{:.2}", t.sah_cost));
            match t.triangles {
                "indexed" => row(
                    &mut s,
                    "triangles",
                    format!(
                        "indexed, {} shared vertices ({:.2} per triangle)",
                        thousands(t.shared_vertices as u64),
                        t.shared_vertices as f64 / t.active_primitives.max(1) as f64
                    ),
                ),
                "direct" => row(&mut s, "triangles", "direct, three vertices each".into()),
                _ => {}
            }
            row(
                &mut s,
                "size",
                format!(
                    "{} ({:.1} bytes per primitive)",
                    bytes(t.bytes),
                    t.bytes_per_primitive
                ),
            );
        }
        for n in &st.notes {
            row(&mut s, "note", n.clone());
        }
    }
    s
}

pub fn run(a: InfoArgs) -> Result<()> {
    let mut out = String::new();
    for (i, f) in a.files.iter().enumerate() {
        let info = inspect(f)?;
        if a.json {
            out.push_str(&serde_json::to_string(&info)?);
            out.push('\n');
        } else {
            if i > 0 {
                out.push('\n');
            }
            out.push_str(&text(&info));
        }
    }
    print(&out)
}
