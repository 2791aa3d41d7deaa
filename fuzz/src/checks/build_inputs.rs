//! Target `build_inputs`: structure-aware build inputs decoded from the fuzz bytes.
//!
//! A case is up to three calls of `vkBuildAccelerationStructuresKHR`, each with one to three
//! infos: random vertex formats (supported and not), index types, strides, offsets, maxVertex,
//! byte buffers of any length (structured floats, raw bytes, or procedural point sets: all
//! equal, collinear, tiny, huge, clustered), geometry transforms, AABBs, instances (array or
//! pointers) with valid, null, dangling and garbage references, build flags, destinations and
//! scratch of exact, short or shared placement, BUILD and UPDATE (of a structure built by an
//! earlier call, with new data). `vkGetAccelerationStructureBuildSizesKHR` is asked first.
//!
//! Checks: nothing panics; a build with the sizes `build_sizes` returned never fails for lack
//! of space; what builds parses, serializes and deserializes, and traces (a TLAS over a BLAS,
//! or the TLAS itself) with hits in range, and when every input value was finite and moderate,
//! closest-hit and any-hit agree.

use super::common::*;
use super::source::Source;
use hostas::input::vertex_format::{Component, SUPPORTED_VERTEX_FORMATS, vertex_format_info};
use hostas::{
    AccelerationStructure, AccelerationStructureCreateInfo, Affine, Buffer, BuildGeometryInfo,
    BuildRangeInfo, Geometry, InstancesData, vk,
};

#[derive(Clone, Debug)]
pub enum GeomData {
    Triangles {
        format: vk::Format,
        vertices: Vec<u8>,
        stride: u64,
        max_vertex: u32,
        index_type: vk::IndexType,
        indices: Option<Vec<u8>>,
        transform: Option<Vec<u8>>,
    },
    Aabbs {
        data: Vec<u8>,
        stride: u64,
    },
    InstanceArray(Vec<u8>),
    InstancePointers(Vec<Vec<u8>>),
}

#[derive(Clone, Debug)]
pub struct GeomDesc {
    pub data: GeomData,
    pub flags: vk::GeometryFlagsKHR,
    pub range: BuildRangeInfo,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Dst {
    /// A new structure of `build_sizes`' size (or 4 KiB when that is unavailable or huge).
    Fresh(vk::AccelerationStructureTypeKHR),
    /// A new structure, too small by `n` bytes.
    Short(u32),
    Null,
    /// The destination of an earlier info of the same call.
    SameAsInfo(u8),
    /// A structure built by an earlier call.
    Built(u8),
    FixtureBlas,
    Garbage(u64),
    /// In the same buffer as the previous info's destination, overlapping it or not.
    SharedBuffer {
        overlap: bool,
    },
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scratch {
    Exact { misalign: u8 },
    Short,
    Null,
    Big,
}

#[derive(Clone, Debug)]
pub struct InfoDesc {
    pub ty: vk::AccelerationStructureTypeKHR,
    pub flags: vk::BuildAccelerationStructureFlagsKHR,
    pub mode: vk::BuildAccelerationStructureModeKHR,
    pub geoms: Vec<GeomDesc>,
    pub dst: Dst,
    /// Index into the structures built so far; `None` = NULL.
    pub src: Option<SrcChoice>,
    pub scratch: Scratch,
    /// Pass one range fewer (or more) than geometries.
    pub ranges_delta: i8,
    /// Ask `build_sizes` with these counts instead of the ranges' (`None`: the ranges').
    pub size_counts: Option<Vec<u32>>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SrcChoice {
    Built(u8),
    Dst,
    Garbage(u64),
}

/// A whole case: calls of infos.
#[derive(Clone, Debug)]
pub struct Case {
    pub calls: Vec<Vec<InfoDesc>>,
    /// Some value was not finite or extreme: only the never-panic and range checks apply.
    pub dirty: bool,
}

/// Symbolic instance references, resolved against the fixture and the case at build time.
const REF_TRI: u64 = 0xF0;
const REF_AABB: u64 = 0xF1;
const REF_TLAS: u64 = 0xF2;
const REF_UNBUILT: u64 = 0xF3;
const REF_DESTROYED: u64 = 0xF4;
/// `REF_BUILT + k`: the k-th structure built by this case; `REF_DST + i`: the destination of
/// info i of the current call.
const REF_BUILT: u64 = 0xE0;
const REF_DST: u64 = 0xD0;

fn flags_from(s: &mut Source) -> vk::BuildAccelerationStructureFlagsKHR {
    use vk::BuildAccelerationStructureFlagsKHR as F;
    if s.chance(12) {
        return F::from_raw(s.u32());
    }
    let b = s.u8();
    let mut f = F::empty();
    for (bit, flag) in [
        (1, F::ALLOW_UPDATE),
        (2, F::ALLOW_COMPACTION),
        (4, F::PREFER_FAST_TRACE),
        (8, F::PREFER_FAST_BUILD),
        (16, F::LOW_MEMORY),
        (32, F::ALLOW_DATA_ACCESS),
    ] {
        if b & bit != 0 {
            f |= flag;
        }
    }
    // Both preferences together are invalid; keep that rare.
    if f.contains(F::PREFER_FAST_TRACE | F::PREFER_FAST_BUILD) && b & 64 == 0 {
        f &= !F::PREFER_FAST_BUILD;
    }
    f
}

fn geometry_flags(s: &mut Source) -> vk::GeometryFlagsKHR {
    if s.chance(8) {
        vk::GeometryFlagsKHR::from_raw(s.u32())
    } else {
        vk::GeometryFlagsKHR::from_raw(s.u8() as u32 & 3)
    }
}

fn vertex_format(s: &mut Source) -> vk::Format {
    match s.u8() % 8 {
        0..=3 => vk::Format::R32G32B32_SFLOAT,
        4 | 5 => {
            SUPPORTED_VERTEX_FORMATS[s.below(SUPPORTED_VERTEX_FORMATS.len() as u32) as usize].format
        }
        6 => s.choose(&[
            vk::Format::UNDEFINED,
            vk::Format::R32_SFLOAT,
            vk::Format::R8_UNORM,
            vk::Format::B8G8R8A8_UNORM,
            vk::Format::R16G16B16A16_UINT,
            vk::Format::R32G32B32_UINT,
        ]),
        _ => vk::Format::from_raw(s.u32() as i32),
    }
}

/// Points for procedural geometry: the distributions builders find hard.
fn procedural(s: &mut Source, n: usize) -> (Vec<[f32; 3]>, bool) {
    let mode = s.u8() % 9;
    let mut lcg = Lcg(s.u64());
    let mut u = move || (lcg.byte() as f32 + (lcg.byte() as f32) / 256.0) / 128.0 - 1.0;
    let mut dirty = false;
    let pts = (0..n)
        .map(|i| match mode {
            0 => [u() * 10.0, u() * 10.0, u() * 10.0],
            1 => [1.5, -2.0, 0.25],
            2 => [i as f32 * 0.5, 0.0, 0.0],
            3 => {
                let far = if i % 2 == 0 { 0.0 } else { 1e6 };
                [far + u() * 1e-3, u() * 1e-3, far + u() * 1e-3]
            }
            4 => [u() * 1e-30, u() * 1e-30, u() * 1e-30],
            5 => {
                dirty = true;
                [u() * 1e30, u() * 1e30, u() * 1e30]
            }
            6 => [(i % 16) as f32, (i / 16) as f32, 0.0],
            7 => [u() * 5.0, u() * 5.0, 0.0],
            _ => {
                // Same centroid, different sizes: nested boxes.
                let r = 1.0 + i as f32;
                [
                    if i % 3 == 0 { r } else { -r },
                    if i % 3 == 1 { r } else { -r },
                    if i % 3 == 2 { r } else { -r },
                ]
            }
        })
        .collect();
    (pts, dirty)
}

fn coord(s: &mut Source, dirty: &mut bool) -> f32 {
    let v = s.coord();
    if !v.is_finite() || v.abs() > 1e18 {
        *dirty = true;
    }
    v
}

fn transform_rows(s: &mut Source, dirty: &mut bool) -> [f32; 12] {
    match s.u8() % 6 {
        0 | 1 => Affine::IDENTITY.to_rows(),
        2 => {
            let mut m = Affine::IDENTITY.to_rows();
            m[3] = coord(s, dirty);
            m[7] = coord(s, dirty);
            m[11] = coord(s, dirty);
            m[0] = -1.0;
            m
        }
        3 => [0.0; 12],
        4 => {
            let mut m = [0f32; 12];
            for v in m.iter_mut() {
                *v = coord(s, dirty);
            }
            m
        }
        _ => {
            let mut m = Affine::IDENTITY.to_rows();
            m[s.below(12) as usize] = s.f32();
            *dirty = true;
            m
        }
    }
}

fn triangles(s: &mut Source, dirty: &mut bool) -> (GeomData, BuildRangeInfo) {
    let format = vertex_format(s);
    let info = vertex_format_info(format);
    let vsize = info.map_or(12, |i| i.size as u64);
    let stride = match s.u8() % 8 {
        0..=3 => vsize,
        4 => vsize + info.map_or(4, |i| i.component_size as u64),
        5 => 0,
        6 => vsize * 2 + 1,
        _ => s.count(64) as u64 | if s.chance(16) { 1 << 32 } else { 0 },
    };
    let procedural_mode = s.chance(40);
    let nverts = if procedural_mode {
        3 * (1 + s.below(1400) as usize)
    } else {
        s.below(48) as usize
    };
    let stride_bytes = (stride.max(vsize) as usize).min(64);
    let mut vertices = vec![0u8; nverts * stride_bytes + (s.below(8) as usize)];
    let is_f32 = info.is_some_and(|i| i.component == Component::F32);
    if procedural_mode {
        let (pts, d) = procedural(s, nverts);
        *dirty |= d;
        for (i, p) in pts.iter().enumerate() {
            for k in 0..3 {
                if is_f32 && (k < 2 || vsize >= 12) {
                    vertices[i * stride_bytes + 4 * k..i * stride_bytes + 4 * k + 4]
                        .copy_from_slice(&p[k].to_le_bytes());
                }
            }
        }
    } else if is_f32 && !s.u8().is_multiple_of(4) {
        for i in 0..nverts {
            for k in 0..(vsize as usize / 4) {
                let v = coord(s, dirty);
                vertices[i * stride_bytes + 4 * k..i * stride_bytes + 4 * k + 4]
                    .copy_from_slice(&v.to_le_bytes());
            }
        }
    } else {
        let raw = s.bytes(vertices.len());
        vertices[..raw.len()].copy_from_slice(raw);
        if info.is_some_and(|i| {
            matches!(
                i.component,
                Component::F16 | Component::F32 | Component::F64
            )
        }) {
            *dirty = true;
        }
    }
    let max_vertex = match s.u8() % 6 {
        0..=2 => (nverts as u32).saturating_sub(1),
        3 => nverts as u32 + s.below(4),
        4 => 0,
        _ => s.count(64),
    };
    let index_type = match s.u8() % 8 {
        0..=2 => vk::IndexType::NONE_KHR,
        3 | 4 => vk::IndexType::UINT32,
        5 => vk::IndexType::UINT16,
        6 => vk::IndexType::UINT8_EXT,
        _ => vk::IndexType::from_raw(s.u32() as i32),
    };
    let mut prims = if procedural_mode {
        nverts as u32 / 3
    } else {
        s.count(16)
    };
    if index_type == vk::IndexType::NONE_KHR && !procedural_mode && s.u8().is_multiple_of(2) {
        prims = nverts as u32 / 3;
    }
    let first_vertex = match s.u8() % 6 {
        0..=3 => 0,
        4 => s.below(4),
        _ => s.u32(),
    };
    let primitive_offset = match s.u8() % 6 {
        0..=3 => 0,
        4 => s.below(4) * vsize as u32,
        _ => s.count(64),
    };
    let indices = if index_type == vk::IndexType::NONE_KHR && !s.chance(8) {
        None
    } else {
        let isize = if index_type == vk::IndexType::UINT16 {
            2
        } else {
            4
        };
        let n = 3 * (prims.min(2048) as usize) + primitive_offset.min(64) as usize / isize;
        let n = if s.chance(24) {
            n.saturating_sub(1 + s.below(4) as usize)
        } else {
            n
        };
        let mut out = Vec::with_capacity(n * isize);
        let random = s.chance(128);
        let mut lcg = Lcg(s.u64());
        for _ in 0..n {
            let v = if s.chance(4) {
                s.u32()
            } else if random {
                (lcg.byte() as u32 | (lcg.byte() as u32) << 8) % (nverts as u32).max(1)
            } else {
                s.below((nverts as u32).max(1) + 1)
            };
            if isize == 2 {
                out.extend_from_slice(&(v as u16).to_le_bytes());
            } else {
                out.extend_from_slice(&v.to_le_bytes());
            }
        }
        Some(out)
    };
    let transform_offset = if s.chance(32) {
        s.count(64)
    } else {
        16 * s.below(2)
    };
    let transform = if s.u8().is_multiple_of(4) {
        let rows = transform_rows(s, dirty);
        let mut t = vec![0u8; transform_offset.min(256) as usize];
        t.extend(rows.iter().flat_map(|f| f.to_le_bytes()));
        if s.chance(16) {
            t.truncate(s.below(t.len() as u32 + 1) as usize);
        }
        Some(t)
    } else {
        None
    };
    (
        GeomData::Triangles {
            format,
            vertices,
            stride,
            max_vertex,
            index_type,
            indices,
            transform,
        },
        BuildRangeInfo {
            primitive_count: prims,
            primitive_offset,
            first_vertex,
            transform_offset,
        },
    )
}

fn aabbs(s: &mut Source, dirty: &mut bool) -> (GeomData, BuildRangeInfo) {
    let stride = match s.u8() % 8 {
        0..=3 => 24,
        4 => 32,
        5 => s.choose(&[0, 8, 16, 7]),
        _ => s.count(64) as u64,
    };
    let procedural_mode = s.chance(40);
    let n = if procedural_mode {
        1 + s.below(3000)
    } else {
        s.count(16)
    };
    let primitive_offset = if s.chance(32) {
        s.count(64)
    } else {
        8 * s.below(3)
    };
    let records = n.min(4096) as usize;
    let step = (stride.clamp(24, 64)) as usize;
    let mut data = vec![0u8; primitive_offset.min(64) as usize + records * step];
    let base = primitive_offset.min(64) as usize;
    let pts = if procedural_mode {
        let (p, d) = procedural(s, records);
        *dirty |= d;
        Some(p)
    } else {
        None
    };
    for i in 0..records {
        let b: [f32; 6] = match &pts {
            Some(p) => {
                let c = p[i];
                let e = 0.01 + (i % 7) as f32 * 0.1;
                [
                    c[0] - e,
                    c[1] - e,
                    c[2],
                    c[0] + e,
                    c[1] + e,
                    c[2] + e * (i % 2) as f32,
                ]
            }
            None => {
                let lo = [coord(s, dirty), coord(s, dirty), coord(s, dirty)];
                match s.u8() % 8 {
                    0 => [f32::NAN, lo[1], lo[2], lo[0], lo[1], lo[2]],
                    1 => [lo[0], lo[1], lo[2], lo[0] - 1.0, lo[1], lo[2]],
                    2 => [lo[0], f32::NAN, lo[2], lo[0], lo[1], lo[2]],
                    _ => {
                        let e = [
                            s.u8() as f32 / 16.0,
                            s.u8() as f32 / 16.0,
                            s.u8() as f32 / 16.0,
                        ];
                        [
                            lo[0],
                            lo[1],
                            lo[2],
                            lo[0] + e[0],
                            lo[1] + e[1],
                            lo[2] + e[2],
                        ]
                    }
                }
            }
        };
        let at = base + i * step;
        for (k, v) in b.iter().enumerate() {
            data[at + 4 * k..at + 4 * k + 4].copy_from_slice(&v.to_le_bytes());
        }
        if s.is_empty() && pts.is_none() {
            data.truncate(at + 24);
            break;
        }
    }
    if s.chance(16) {
        data.truncate(s.below(data.len() as u32 + 1) as usize);
    }
    (
        GeomData::Aabbs { data, stride },
        BuildRangeInfo {
            primitive_count: n,
            primitive_offset,
            first_vertex: 0,
            transform_offset: 0,
        },
    )
}

fn instance_bytes(s: &mut Source, dirty: &mut bool, infos_in_call: usize) -> Vec<u8> {
    if s.chance(8) {
        return s.bytes(64).to_vec();
    }
    let transform = Affine::from_rows(transform_rows(s, dirty));
    let reference = match s.u8() % 16 {
        0..=4 => REF_TRI,
        5 | 6 => REF_AABB,
        7 => 0,
        8 => REF_TLAS,
        9 => REF_UNBUILT,
        10 => REF_DESTROYED,
        11 | 12 => REF_BUILT + s.below(8) as u64,
        13 => REF_DST + s.below(infos_in_call as u32) as u64,
        _ => s.u64(),
    };
    let flags = if s.chance(16) {
        s.u8() as u32
    } else {
        s.u8() as u32 & 0xf & !(if s.bool() { 0x8 } else { 0 })
    };
    let inst = hostas::Instance {
        transform,
        custom_index: s.u32(),
        mask: if s.chance(200) { 0xff } else { s.u8() },
        sbt_record_offset: s.u32(),
        flags: vk::GeometryInstanceFlagsKHR::from_raw(flags),
        acceleration_structure_reference: reference,
    };
    inst.encode().to_vec()
}

fn instances(s: &mut Source, dirty: &mut bool, infos_in_call: usize) -> (GeomData, BuildRangeInfo) {
    let n = s.below(12) as usize;
    let pointers = s.chance(64);
    let primitive_offset = if s.chance(32) {
        s.count(64)
    } else {
        16 * s.below(2)
    };
    let count = if s.chance(24) { s.count(16) } else { n as u32 };
    let data = if pointers {
        let mut v: Vec<Vec<u8>> = (0..primitive_offset.min(256) as usize / 8)
            .map(|_| vec![0u8; 64])
            .collect();
        for _ in 0..n {
            let mut b = instance_bytes(s, dirty, infos_in_call);
            if s.chance(8) {
                b.truncate(s.below(64) as usize);
            }
            v.push(b);
        }
        GeomData::InstancePointers(v)
    } else {
        let mut v = vec![0u8; primitive_offset.min(256) as usize];
        for _ in 0..n {
            v.extend(instance_bytes(s, dirty, infos_in_call));
        }
        if s.chance(16) {
            v.truncate(s.below(v.len() as u32 + 1) as usize);
        }
        GeomData::InstanceArray(v)
    };
    (
        data,
        BuildRangeInfo {
            primitive_count: count,
            primitive_offset,
            first_vertex: 0,
            transform_offset: 0,
        },
    )
}

fn info(
    s: &mut Source,
    dirty: &mut bool,
    earlier: &[InfoDesc],
    infos_in_call: usize,
    index: usize,
) -> InfoDesc {
    // An update of a structure an earlier call built, with the same description and new data.
    if !earlier.is_empty() && s.u8().is_multiple_of(3) {
        let k = s.below(earlier.len() as u32) as u8;
        let mut d = earlier[k as usize].clone();
        d.mode = if s.chance(240) {
            vk::BuildAccelerationStructureModeKHR::UPDATE
        } else {
            vk::BuildAccelerationStructureModeKHR::BUILD
        };
        d.src = Some(SrcChoice::Built(k));
        d.dst = match s.u8() % 4 {
            0 | 1 => Dst::Built(k),
            2 => Dst::Fresh(vk::AccelerationStructureTypeKHR::GENERIC),
            _ => Dst::Short(64),
        };
        d.scratch = Scratch::Exact { misalign: 0 };
        d.ranges_delta = 0;
        d.size_counts = None;
        if s.chance(16) {
            d.flags = flags_from(s);
        }
        for g in &mut d.geoms {
            let bytes = match &mut g.data {
                GeomData::Triangles {
                    vertices, indices, ..
                } => {
                    if s.chance(32)
                        && let Some(ix) = indices
                    {
                        for b in ix.iter_mut().take(64) {
                            *b ^= s.u8() & 1;
                        }
                    }
                    vertices
                }
                GeomData::Aabbs { data, .. } => data,
                GeomData::InstanceArray(data) => data,
                GeomData::InstancePointers(v) => match v.last_mut() {
                    Some(b) => b,
                    None => continue,
                },
            };
            // Move things a little (and sometimes make an active primitive inactive).
            let flips = s.below(8);
            for _ in 0..flips {
                if bytes.is_empty() {
                    break;
                }
                let at = s.below(bytes.len() as u32) as usize;
                bytes[at] ^= s.u8();
                *dirty = true;
            }
            if s.chance(8) {
                g.range.primitive_count = s.count(16);
            }
        }
        return d;
    }
    let kind = s.u8() % 8;
    let (ty, n_geoms) = match kind {
        0..=2 => (
            vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
            1 + s.below(3),
        ),
        3 | 4 => (
            vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
            1 + s.below(3),
        ),
        5 | 6 => (vk::AccelerationStructureTypeKHR::TOP_LEVEL, 1),
        _ => (
            s.choose(&[
                vk::AccelerationStructureTypeKHR::GENERIC,
                vk::AccelerationStructureTypeKHR::TOP_LEVEL,
                vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
                vk::AccelerationStructureTypeKHR::from_raw(7),
            ]),
            s.below(4),
        ),
    };
    let geoms = (0..n_geoms)
        .map(|_| {
            let which = match kind {
                0..=2 => 0,
                3 | 4 => 1,
                5 | 6 => 2,
                _ => s.below(3),
            };
            let (data, range) = match which {
                0 => triangles(s, dirty),
                1 => aabbs(s, dirty),
                _ => instances(s, dirty, infos_in_call),
            };
            GeomDesc {
                data,
                flags: geometry_flags(s),
                range,
            }
        })
        .collect();
    let dst = match s.u8() % 16 {
        0..=8 => Dst::Fresh(if s.chance(16) {
            vk::AccelerationStructureTypeKHR::from_raw(s.below(3) as i32)
        } else {
            ty
        }),
        9 => Dst::Short(s.choose(&[1, 64, 128, 4096])),
        10 => Dst::Null,
        11 => Dst::SameAsInfo(s.below(index.max(1) as u32) as u8),
        12 => Dst::Built(s.below(8) as u8),
        13 => Dst::FixtureBlas,
        14 => Dst::Garbage(s.u64()),
        _ => Dst::SharedBuffer { overlap: s.bool() },
    };
    let mode = match s.u8() % 16 {
        0..=12 => vk::BuildAccelerationStructureModeKHR::BUILD,
        13 | 14 => vk::BuildAccelerationStructureModeKHR::UPDATE,
        _ => vk::BuildAccelerationStructureModeKHR::from_raw(s.u32() as i32),
    };
    let src = match s.u8() % 8 {
        0..=4 => None,
        5 => Some(SrcChoice::Built(s.below(8) as u8)),
        6 => Some(SrcChoice::Dst),
        _ => Some(SrcChoice::Garbage(s.u64())),
    };
    let scratch = match s.u8() % 16 {
        0..=10 => Scratch::Exact { misalign: 0 },
        11 => Scratch::Exact {
            misalign: 1 + s.below(63) as u8,
        },
        12 => Scratch::Short,
        13 => Scratch::Null,
        _ => Scratch::Big,
    };
    let ranges_delta = if s.chance(8) {
        if s.bool() { -1 } else { 1 }
    } else {
        0
    };
    let size_counts = if s.chance(16) {
        Some((0..s.below(4)).map(|_| s.count(16)).collect())
    } else {
        None
    };
    InfoDesc {
        ty,
        flags: flags_from(s),
        mode,
        geoms,
        dst,
        src,
        scratch,
        ranges_delta,
        size_counts,
    }
}

impl Case {
    pub fn decode(data: &[u8]) -> Case {
        let mut s = Source::new(data);
        let mut dirty = false;
        let mut calls = Vec::new();
        let mut earlier: Vec<InfoDesc> = Vec::new();
        let n_calls = 1 + s.below(3);
        for _ in 0..n_calls {
            let n_infos = 1 + if s.chance(48) {
                1 + s.below(2) as usize
            } else {
                0
            };
            let mut infos = Vec::new();
            for i in 0..n_infos {
                infos.push(info(&mut s, &mut dirty, &earlier, n_infos, i));
            }
            earlier.extend(infos.iter().cloned());
            calls.push(infos);
            if s.is_empty() {
                break;
            }
        }
        Case { calls, dirty }
    }
}

struct Built {
    handle: AccelerationStructure,
    top: bool,
}

pub fn run(data: &[u8]) {
    let case = Case::decode(data);
    run_case(&case);
}

/// What a case did (for seed selection).
#[derive(Clone, Copy, Debug, Default)]
pub struct Outcome {
    pub built_blas: usize,
    pub built_tlas: usize,
    pub updated: usize,
    pub failed_calls: usize,
}

pub fn run_case(case: &Case) -> Outcome {
    let mut outcome = Outcome::default();
    let fx = Fixture::new();
    let d = &fx.device;
    let mut built: Vec<Option<Built>> = Vec::new();
    let mut all_created: Vec<AccelerationStructure> = Vec::new();
    for infos in &case.calls {
        // Owned views: pointer arrays, geometries, ranges.
        let ptrs: Vec<Vec<Vec<&[u8]>>> = infos
            .iter()
            .map(|i| {
                i.geoms
                    .iter()
                    .map(|g| {
                        if let GeomData::InstancePointers(v) = &g.data {
                            v.iter().map(|b| &b[..]).collect()
                        } else {
                            Vec::new()
                        }
                    })
                    .collect()
            })
            .collect();
        // Instance references resolved: symbolic values become handles.
        let mut dst_handles: Vec<Option<AccelerationStructure>> = vec![None; infos.len()];
        let mut shared_prev: Option<(Buffer, u64, u64)> = None;
        let mut fresh_sizes = vec![None; infos.len()];
        for (i, inf) in infos.iter().enumerate() {
            let probe_geoms = geometries(inf, &ptrs[i], &[]);
            let probe = BuildGeometryInfo {
                ty: inf.ty,
                flags: inf.flags,
                mode: inf.mode,
                src: None,
                dst: None,
                geometries: &probe_geoms,
                scratch: None,
            };
            let counts: Vec<u32> = inf
                .size_counts
                .clone()
                .unwrap_or_else(|| inf.geoms.iter().map(|g| g.range.primitive_count).collect());
            let sizes = d.build_sizes(vk::AccelerationStructureBuildTypeKHR::HOST, &probe, &counts);
            if inf.size_counts.is_none() {
                // Device builds are not supported: refused, never a panic.
                assert!(
                    d.build_sizes(
                        vk::AccelerationStructureBuildTypeKHR::DEVICE,
                        &probe,
                        &counts
                    )
                    .is_err()
                );
            }
            if let Ok(sz) = &sizes {
                assert!(
                    sz.acceleration_structure_size > 0
                        && sz.build_scratch_size > 0
                        && sz.update_scratch_size > 0,
                    "zero size from build_sizes: {sz:?}"
                );
            }
            fresh_sizes[i] = sizes.ok().filter(|s| {
                s.acceleration_structure_size <= MAX_ALLOC && s.build_scratch_size <= MAX_ALLOC
            });
            let size = fresh_sizes[i].map_or(4096, |s| s.acceleration_structure_size);
            dst_handles[i] = match inf.dst {
                Dst::Fresh(ty) => create(d, ty, size).ok(),
                Dst::Short(n) => create(d, inf.ty, size.saturating_sub(n as u64).max(1)).ok(),
                Dst::Null => None,
                Dst::SameAsInfo(k) => dst_handles.get(k as usize).copied().flatten(),
                Dst::Built(k) => built
                    .get(k as usize)
                    .and_then(|b| b.as_ref())
                    .map(|b| b.handle),
                Dst::FixtureBlas => Some(fx.tri_blas),
                Dst::Garbage(h) => Some(AccelerationStructure(h)),
                Dst::SharedBuffer { overlap } => {
                    let placed = size.div_ceil(256) * 256;
                    let (buffer, offset) = match &shared_prev {
                        Some((b, off, len)) => (b.clone(), if overlap { *off } else { off + len }),
                        None => match Buffer::new((placed * 4).min(MAX_ALLOC)) {
                            Ok(b) => (b, 0),
                            Err(_) => continue,
                        },
                    };
                    let r = d.create_acceleration_structure(&AccelerationStructureCreateInfo {
                        buffer: Some(buffer.clone()),
                        offset,
                        ..AccelerationStructureCreateInfo::new(inf.ty, placed)
                    });
                    shared_prev = Some((buffer, offset, placed));
                    r.ok()
                }
            };
            if let (Dst::Fresh(_) | Dst::Short(_) | Dst::SharedBuffer { .. }, Some(h)) =
                (inf.dst, dst_handles[i])
            {
                all_created.push(h);
            }
        }
        let resolve = |r: u64| -> u64 {
            match r {
                REF_TRI => fx.tri_blas.raw(),
                REF_AABB => fx.aabb_blas.raw(),
                REF_TLAS => fx.tlas.raw(),
                REF_UNBUILT => fx.unbuilt.raw(),
                REF_DESTROYED => fx.destroyed,
                r if (REF_BUILT..REF_BUILT + 8).contains(&r) => built
                    .get((r - REF_BUILT) as usize)
                    .and_then(|b| b.as_ref())
                    .map_or(0x1234_5600, |b| b.handle.raw()),
                r if (REF_DST..REF_DST + 8).contains(&r) => dst_handles
                    .get((r - REF_DST) as usize)
                    .copied()
                    .flatten()
                    .map_or(0, |h| h.raw()),
                r => r,
            }
        };
        let resolved: Vec<Vec<GeomData>> = infos
            .iter()
            .map(|i| {
                i.geoms
                    .iter()
                    .map(|g| resolve_refs(&g.data, &resolve))
                    .collect()
            })
            .collect();
        let rptrs: Vec<Vec<Vec<&[u8]>>> = resolved
            .iter()
            .map(|gs| {
                gs.iter()
                    .map(|g| {
                        if let GeomData::InstancePointers(v) = g {
                            v.iter().map(|b| &b[..]).collect()
                        } else {
                            Vec::new()
                        }
                    })
                    .collect()
            })
            .collect();
        let geoms: Vec<Vec<Geometry>> = infos
            .iter()
            .enumerate()
            .map(|(i, inf)| geometries(inf, &rptrs[i], &resolved[i]))
            .collect();
        let ranges: Vec<Vec<BuildRangeInfo>> = infos
            .iter()
            .map(|inf| {
                let mut r: Vec<BuildRangeInfo> = inf.geoms.iter().map(|g| g.range).collect();
                match inf.ranges_delta {
                    -1 => {
                        r.pop();
                    }
                    1 => r.push(BuildRangeInfo::default()),
                    _ => {}
                }
                r
            })
            .collect();
        let mut scratches: Vec<Vec<u8>> = infos
            .iter()
            .enumerate()
            .map(|(i, inf)| {
                let need = fresh_sizes[i].map_or(4096, |s| {
                    if inf.mode == vk::BuildAccelerationStructureModeKHR::UPDATE {
                        s.update_scratch_size
                    } else {
                        s.build_scratch_size
                    }
                });
                match inf.scratch {
                    Scratch::Exact { misalign } => vec![0u8; need as usize + misalign as usize],
                    Scratch::Short => vec![0u8; need.saturating_sub(1) as usize],
                    Scratch::Null => Vec::new(),
                    Scratch::Big => vec![0u8; (need as usize * 2).min(MAX_ALLOC as usize)],
                }
            })
            .collect();
        let mut exact = true;
        let mut build_infos: Vec<BuildGeometryInfo> = Vec::new();
        for ((i, inf), scratch) in infos.iter().enumerate().zip(scratches.iter_mut()) {
            let scratch: Option<&mut [u8]> = match inf.scratch {
                Scratch::Null => None,
                Scratch::Exact { misalign } => Some(&mut scratch[misalign as usize..]),
                _ => Some(&mut scratch[..]),
            };
            exact &= matches!(inf.scratch, Scratch::Exact { .. } | Scratch::Big)
                && matches!(inf.dst, Dst::Fresh(_))
                && fresh_sizes[i].is_some();
            let src = match inf.src {
                None => None,
                Some(SrcChoice::Built(k)) => built
                    .get(k as usize)
                    .and_then(|b| b.as_ref())
                    .map(|b| b.handle),
                Some(SrcChoice::Dst) => dst_handles[i],
                Some(SrcChoice::Garbage(h)) => Some(AccelerationStructure(h)),
            };
            build_infos.push(BuildGeometryInfo {
                ty: inf.ty,
                flags: inf.flags,
                mode: inf.mode,
                src,
                dst: dst_handles[i],
                geometries: &geoms[i],
                scratch,
            });
        }
        let range_refs: Vec<&[BuildRangeInfo]> = ranges.iter().map(|r| &r[..]).collect();
        let result = d.build_acceleration_structures(&mut build_infos, &range_refs);
        if let Err(e) = &result {
            // Exactly sized destinations and scratch never run out of space.
            if exact
                && infos.iter().all(|i| {
                    i.mode == vk::BuildAccelerationStructureModeKHR::BUILD
                        && i.size_counts.is_none()
                        && i.ranges_delta == 0
                })
            {
                let v = e.vuid_str().unwrap_or("");
                assert!(
                    !v.ends_with("-03675")
                        && !v.ends_with("-03725")
                        && !matches!(
                            e,
                            hostas::Error::RangeTooShort {
                                what: "scratch" | "acceleration structure",
                                ..
                            }
                        ),
                    "a build with the sizes from build_sizes ran out of space: {e}"
                );
            }
        }
        drop(build_infos);
        let ok = result.is_ok();
        if !ok {
            outcome.failed_calls += 1;
        }
        for (i, inf) in infos.iter().enumerate() {
            let entry = match (ok, dst_handles[i]) {
                (true, Some(h)) => Some(Built {
                    handle: h,
                    top: inf.ty == vk::AccelerationStructureTypeKHR::TOP_LEVEL,
                }),
                _ => None,
            };
            if let Some(b) = &entry {
                check_built(&fx, b, case.dirty, &mut all_created);
                if inf.mode == vk::BuildAccelerationStructureModeKHR::UPDATE {
                    outcome.updated += 1;
                } else if b.top {
                    outcome.built_tlas += 1;
                } else {
                    outcome.built_blas += 1;
                }
            }
            built.push(entry);
        }
    }
    for h in all_created {
        let _ = d.destroy_acceleration_structure(h);
    }
    outcome
}

fn resolve_refs(g: &GeomData, resolve: &impl Fn(u64) -> u64) -> GeomData {
    let fix = |b: &[u8]| -> Vec<u8> {
        let mut b = b.to_vec();
        if b.len() >= 64 {
            let r = u64::from_le_bytes(b[56..64].try_into().unwrap());
            b[56..64].copy_from_slice(&resolve(r).to_le_bytes());
        }
        b
    };
    match g {
        GeomData::InstanceArray(v) => {
            let mut out = Vec::with_capacity(v.len());
            // Records are 64 bytes from the start of the buffer past the primitive offset; the
            // references to fix are at whatever 64-byte slots the buffer holds.
            let lead = v.len() % 64;
            out.extend_from_slice(&v[..lead]);
            for c in v[lead..].chunks(64) {
                out.extend(fix(c));
            }
            GeomData::InstanceArray(out)
        }
        GeomData::InstancePointers(v) => {
            GeomData::InstancePointers(v.iter().map(|b| fix(b)).collect())
        }
        other => other.clone(),
    }
}

fn geometries<'a>(
    inf: &'a InfoDesc,
    ptrs: &'a [Vec<&'a [u8]>],
    resolved: &'a [GeomData],
) -> Vec<Geometry<'a>> {
    inf.geoms
        .iter()
        .enumerate()
        .map(|(gi, g)| {
            let data = resolved.get(gi).unwrap_or(&g.data);
            let gd = match data {
                GeomData::Triangles {
                    format,
                    vertices,
                    stride,
                    max_vertex,
                    index_type,
                    indices,
                    transform,
                } => hostas::GeometryData::Triangles(hostas::TrianglesData {
                    vertex_format: *format,
                    vertex_data: vertices,
                    vertex_stride: *stride,
                    max_vertex: *max_vertex,
                    index_type: *index_type,
                    index_data: indices.as_deref(),
                    transform_data: transform.as_deref(),
                }),
                GeomData::Aabbs { data, stride } => {
                    hostas::GeometryData::Aabbs(hostas::AabbsData {
                        data,
                        stride: *stride,
                    })
                }
                GeomData::InstanceArray(v) => {
                    hostas::GeometryData::Instances(InstancesData::Array(v))
                }
                GeomData::InstancePointers(_) => {
                    hostas::GeometryData::Instances(InstancesData::Pointers(&ptrs[gi]))
                }
            };
            Geometry {
                data: gd,
                flags: g.flags,
            }
        })
        .collect()
}

/// What a successful build left must parse, serialize, deserialize and trace.
fn check_built(fx: &Fixture, b: &Built, dirty: bool, created: &mut Vec<AccelerationStructure>) {
    let d = &fx.device;
    let stats = d.statistics(b.handle).expect("a built structure parses");
    let (_, _, size) = d.placement(b.handle).expect("placement");
    assert!(
        stats.used_bytes <= size,
        "used size {} exceeds the allocation {size}",
        stats.used_bytes
    );
    assert_eq!(stats.top_level, b.top, "built type");
    let ser = d.serialize(b.handle).expect("serialize a built structure");
    let back = d
        .deserialize(&ser)
        .expect("deserialize what serialize wrote");
    assert!(
        d.serialize(back).expect("serialize again") == ser,
        "serialize(deserialize(x)) != x"
    );
    created.push(back);
    let bytes = {
        let (buffer, offset, size) = d.placement(b.handle).expect("placement");
        let mut v = vec![0u8; size as usize];
        buffer.read(offset, &mut v).expect("read");
        v
    };
    let h = hostas::layout::view::read_header(&bytes).expect("header");
    let rays = probe_rays(h.bounds.lo, h.bounds.hi);
    let strict = !dirty;
    if b.top {
        let scene = d.scene(b.handle).expect("scene of a built TLAS");
        trace_rays(&scene, &rays, strict);
    } else {
        let t = hostas::quick::build_tlas(
            d,
            &instances_of(b.handle),
            vk::BuildAccelerationStructureFlagsKHR::empty(),
        )
        .expect("a TLAS over a built BLAS");
        created.push(t);
        let scene = d.scene(t).expect("scene");
        trace_rays(&scene, &rays, strict);
        let mut lcg = Lcg(stats.used_bytes);
        for r in rays.iter().take(3) {
            walk_query(&scene, r, || lcg.byte(), 1 << 24);
        }
    }
}
