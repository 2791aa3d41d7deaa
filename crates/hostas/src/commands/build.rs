//! `vkGetAccelerationStructureBuildSizesKHR` and `vkBuildAccelerationStructuresKHR` (build and
//! update).

use super::validate;
use crate::build::{self, Algorithm, Preset, PrimRef};
use crate::device::{AccelerationStructure, AsObject, Device};
use crate::error::{Error, Location, Result};
use crate::input::aabbs::AabbReader;
use crate::input::instances::{Instance, InstanceReader};
use crate::input::triangles::{F32Layout, TriangleReader};
use crate::input::{BuildGeometryInfo, BuildRangeInfo, GeometryData};
use crate::layout;
use crate::layout::encode::{self, HeaderFields};
use crate::layout::plan::{self, Plan};
use crate::layout::view::{self, View};
use crate::layout::{
    GeometryRecord, HEADER_ALL_OPAQUE, HEADER_NONE_OPAQUE, Header, InstanceRecord, Kind, PrimKind,
};
use crate::math::{Aabb, Affine, Box4, lanes};
use ash::vk;
use rayon::prelude::*;
use wide::{f32x4, i32x4};

/// `VkAccelerationStructureBuildSizesInfoKHR`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct BuildSizes {
    pub acceleration_structure_size: u64,
    pub update_scratch_size: u64,
    pub build_scratch_size: u64,
}

/// Decoded primitive data as it sits in scratch, indexed by primitive sequence number.
const TRI_BYTES: usize = 36;

/// Build scratch: per primitive a `PrimRef` and a second one to partition into (32 bytes
/// each), two sort keys (8 bytes each) and the decoded primitive, each array 64-byte aligned,
/// plus room to align the start of whatever address the application gives.
fn build_scratch_size(k: PrimKind, n: u64) -> u64 {
    use crate::layout::align_up;
    64 + 2 * align_up(32 * n, 64) + 2 * align_up(8 * n, 64) + align_up(k.prim_size() * n, 64)
}

/// One geometry's reader.
pub(super) enum Reader<'a> {
    Triangles(TriangleReader<'a>),
    Aabbs(AabbReader<'a>),
    Instances(InstanceReader<'a>),
}

impl Device {
    /// `vkGetAccelerationStructureBuildSizesKHR`: sizes for any later build with the same
    /// description and at most `max_primitive_counts[g]` primitives in geometry `g`.
    #[doc(alias = "vkGetAccelerationStructureBuildSizesKHR")]
    pub fn build_sizes(
        &self,
        build_type: vk::AccelerationStructureBuildTypeKHR,
        info: &BuildGeometryInfo,
        max_primitive_counts: &[u32],
    ) -> Result<BuildSizes> {
        let at = Location::NONE;
        if build_type == vk::AccelerationStructureBuildTypeKHR::DEVICE {
            return Err(Error::NotSupported(
                "device builds (buildType DEVICE): hostas implements the host commands".into(),
            ));
        }
        let (kind, prim_kind) = validate::info(info, at)?;
        if max_primitive_counts.len() != info.geometries.len() {
            return Err(Error::vuid(
                "VUID-vkGetAccelerationStructureBuildSizesKHR-pBuildInfo-03619",
                at,
                format!(
                    "{} maximum primitive counts for {} geometries",
                    max_primitive_counts.len(),
                    info.geometries.len()
                ),
            ));
        }
        let total: u64 = max_primitive_counts.iter().map(|&c| c as u64).sum();
        validate::counts(
            kind,
            prim_kind,
            total,
            at,
            "VUID-vkGetAccelerationStructureBuildSizesKHR-pBuildInfo-03785",
        )?;
        let plan = Plan::new(prim_kind, info.geometries.len() as u64, total);
        Ok(BuildSizes {
            acceleration_structure_size: plan.total_size,
            update_scratch_size: plan::update_scratch_size(total),
            build_scratch_size: build_scratch_size(prim_kind, total),
        })
    }

    /// `vkBuildAccelerationStructuresKHR`: builds or updates each info's destination.
    /// `ranges[i]` holds one range per geometry of `infos[i]`. Infos are independent; each
    /// is built with all threads of the current rayon pool.
    #[doc(alias = "vkBuildAccelerationStructuresKHR")]
    pub fn build_acceleration_structures(
        &self,
        infos: &mut [BuildGeometryInfo],
        ranges: &[&[BuildRangeInfo]],
    ) -> Result<()> {
        if infos.is_empty() {
            return Err(Error::vuid(
                "VUID-vkBuildAccelerationStructuresKHR-infoCount-arraylength",
                Location::NONE,
                "infoCount must be greater than 0",
            ));
        }
        if ranges.len() != infos.len() {
            return Err(Error::vuid(
                "VUID-vkBuildAccelerationStructuresKHR-ppBuildRangeInfos-parameter",
                Location::NONE,
                format!("{} range arrays for {} infos", ranges.len(), infos.len()),
            ));
        }
        // Cross-info rules first, so that nothing is written when any info is invalid.
        let mut dsts: Vec<AsObject> = Vec::with_capacity(infos.len());
        for (i, info) in infos.iter().enumerate() {
            let at = Location::info(i);
            let dst = info.dst.ok_or_else(|| {
                Error::vuid(
                    "VUID-vkBuildAccelerationStructuresKHR-dstAccelerationStructure-03800",
                    at,
                    "dstAccelerationStructure is NULL",
                )
            })?;
            let obj = self.object(dst).map_err(|_| {
                Error::vuid(
                    "VUID-vkBuildAccelerationStructuresKHR-dstAccelerationStructure-03800",
                    at,
                    format!(
                        "dstAccelerationStructure {:#x} is not a valid handle",
                        dst.0
                    ),
                )
            })?;
            for (j, other) in dsts.iter().enumerate() {
                if other.handle == obj.handle {
                    return Err(Error::vuid(
                        "VUID-vkBuildAccelerationStructuresKHR-dstAccelerationStructure-03698",
                        at,
                        format!("the destination is also the destination of info {j}"),
                    ));
                }
                if other.buffer.id() == obj.buffer.id()
                    && obj.offset < other.offset + other.size
                    && other.offset < obj.offset + obj.size
                {
                    return Err(Error::vuid(
                        "VUID-vkBuildAccelerationStructuresKHR-dstAccelerationStructure-03702",
                        at,
                        format!("the destination's memory overlaps the destination of info {j}"),
                    ));
                }
            }
            dsts.push(obj);
        }
        let overlaps = |a: &AsObject, b: &AsObject| {
            a.buffer.id() == b.buffer.id()
                && a.offset < b.offset + b.size
                && b.offset < a.offset + a.size
        };
        for (i, info) in infos.iter().enumerate() {
            if let Some(src) = info.src {
                let src_obj = self.object(src).map_err(|_| {
                    Error::vuid(
                        "VUID-vkBuildAccelerationStructuresKHR-srcAccelerationStructure-04629",
                        Location::info(i),
                        format!(
                            "srcAccelerationStructure {:#x} is not a valid handle",
                            src.0
                        ),
                    )
                })?;
                for (j, d) in dsts.iter().enumerate() {
                    if j != i && d.handle == src.0 {
                        return Err(Error::vuid(
                            "VUID-vkBuildAccelerationStructuresKHR-pInfos-03403",
                            Location::info(i),
                            format!("the source is the destination of info {j}"),
                        ));
                    }
                    if j != i
                        && info.mode == vk::BuildAccelerationStructureModeKHR::UPDATE
                        && overlaps(d, &src_obj)
                    {
                        return Err(Error::vuid(
                            "VUID-vkBuildAccelerationStructuresKHR-dstAccelerationStructure-03701",
                            Location::info(j),
                            format!(
                                "the destination's memory overlaps the update source of info {i}"
                            ),
                        ));
                    }
                }
            }
            // Instances may not reference any destination of this call, nor overlap one.
            for (g, geom) in info.geometries.iter().enumerate() {
                let crate::input::GeometryData::Instances(data) = &geom.data else {
                    continue;
                };
                let Some(range) = ranges[i].get(g) else {
                    continue;
                };
                let Ok(reader) = InstanceReader::new(data, range, Location::info(i).geometry(g))
                else {
                    continue;
                };
                // Unreadable instances are reported by the per-info pass; stop at the first.
                for p in 0..reader.primitive_count {
                    let Ok(inst) = reader.instance(p) else { break };
                    let r = inst.acceleration_structure_reference;
                    if r == 0 {
                        continue;
                    }
                    let at = Location::info(i).geometry(g).primitive(p);
                    if let Some(j) = dsts.iter().position(|d| d.handle == r) {
                        return Err(Error::vuid(
                            "VUID-vkBuildAccelerationStructuresKHR-None-03407",
                            at,
                            format!("instance references {r:#x}, the destination of info {j}"),
                        ));
                    }
                    if let Ok(obj) = self.object(AccelerationStructure(r))
                        && let Some(j) = dsts.iter().position(|d| overlaps(d, &obj))
                    {
                        return Err(Error::vuid(
                            "VUID-vkBuildAccelerationStructuresKHR-dstAccelerationStructure-03706",
                            at,
                            format!(
                                "the referenced structure {r:#x} overlaps the destination of info {j}"
                            ),
                        ));
                    }
                }
            }
        }
        for (i, (info, dst)) in infos.iter_mut().zip(&dsts).enumerate() {
            let at = Location::info(i);
            match info.mode {
                vk::BuildAccelerationStructureModeKHR::BUILD => {
                    self.build_one(info, ranges[i], dst, at, &dsts)?
                }
                vk::BuildAccelerationStructureModeKHR::UPDATE => {
                    self.update_one(info, ranges[i], dst, at, &dsts)?
                }
                other => {
                    return Err(Error::vuid(
                        "VUID-vkBuildAccelerationStructuresKHR-mode-04628",
                        at,
                        format!("unknown mode {other:?}"),
                    ));
                }
            }
        }
        Ok(())
    }

    fn readers<'a>(
        &self,
        info: &BuildGeometryInfo<'a>,
        ranges: &[BuildRangeInfo],
        at: Location,
    ) -> Result<Vec<Reader<'a>>> {
        if ranges.len() != info.geometries.len() {
            return Err(Error::vuid(
                "VUID-vkBuildAccelerationStructuresKHR-ppBuildRangeInfos-03676",
                at,
                format!(
                    "{} range infos for {} geometries",
                    ranges.len(),
                    info.geometries.len()
                ),
            ));
        }
        info.geometries
            .iter()
            .zip(ranges)
            .enumerate()
            .map(|(g, (geom, range))| {
                let at = at.geometry(g);
                Ok(match &geom.data {
                    GeometryData::Triangles(t) => {
                        Reader::Triangles(TriangleReader::new(t, range, at)?)
                    }
                    GeometryData::Aabbs(a) => Reader::Aabbs(AabbReader::new(a, range, at)?),
                    GeometryData::Instances(d) => {
                        Reader::Instances(InstanceReader::new(d, range, at)?)
                    }
                })
            })
            .collect()
    }

    fn check_dst_type(
        info: &BuildGeometryInfo,
        kind: Kind,
        dst: &AsObject,
        at: Location,
    ) -> Result<()> {
        let ok = dst.ty == vk::AccelerationStructureTypeKHR::GENERIC
            || (kind == Kind::TopLevel && dst.ty == vk::AccelerationStructureTypeKHR::TOP_LEVEL)
            || (kind == Kind::BottomLevel
                && dst.ty == vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL);
        if !ok {
            let vuid = if kind == Kind::TopLevel {
                "VUID-vkBuildAccelerationStructuresKHR-pInfos-03699"
            } else {
                "VUID-vkBuildAccelerationStructuresKHR-pInfos-03700"
            };
            return Err(Error::vuid(
                vuid,
                at,
                format!(
                    "destination was created as {:?}, the build is {:?}",
                    dst.ty, info.ty
                ),
            ));
        }
        Ok(())
    }

    fn geometry_records(
        info: &BuildGeometryInfo,
        ranges: &[BuildRangeInfo],
    ) -> Vec<GeometryRecord> {
        let mut first = 0u32;
        info.geometries
            .iter()
            .zip(ranges)
            .map(|(g, r)| {
                let (vertex_format, index_type, max_vertex, extra) = match &g.data {
                    GeometryData::Triangles(t) => (
                        t.vertex_format.as_raw() as u32,
                        t.index_type.as_raw() as u32,
                        t.max_vertex,
                        t.transform_data.is_some() as u32,
                    ),
                    GeometryData::Instances(crate::input::InstancesData::Pointers(_)) => {
                        (0, 0, 0, 2)
                    }
                    _ => (0, 0, 0, 0),
                };
                let rec = GeometryRecord {
                    first_primitive: first,
                    primitive_count: r.primitive_count,
                    flags: g.flags.as_raw(),
                    geometry_type: g.data.geometry_type().as_raw() as u32,
                    vertex_format,
                    index_type,
                    max_vertex,
                    extra,
                    first_vertex: if index_type == vk::IndexType::NONE_KHR.as_raw() as u32 {
                        0
                    } else {
                        r.first_vertex
                    },
                    reserved: [0; 3],
                };
                first = first.saturating_add(r.primitive_count);
                rec
            })
            .collect()
    }

    fn header_flags(info: &BuildGeometryInfo) -> u32 {
        let opaque = info
            .geometries
            .iter()
            .filter(|g| g.flags.contains(vk::GeometryFlagsKHR::OPAQUE))
            .count();
        if opaque == info.geometries.len() {
            HEADER_ALL_OPAQUE
        } else if opaque == 0 {
            HEADER_NONE_OPAQUE
        } else {
            0
        }
    }

    /// Reads each instance's BLAS: the root bounds, after checking the reference (VUID-03779).
    fn instance_bounds(&self, inst: &Instance, dsts: &[AsObject], at: Location) -> Result<Aabb> {
        let r = inst.acceleration_structure_reference;
        let bad = |msg: String| {
            Error::vuid(
                "VUID-vkBuildAccelerationStructuresKHR-pInfos-03779",
                at,
                msg,
            )
        };
        let obj = self.object(AccelerationStructure(r)).map_err(|_| bad(format!("accelerationStructureReference {r:#x} is not an acceleration structure of this device")))?;
        if obj.buffer.memory().is_none() {
            return Err(Error::vuid(
                "VUID-vkBuildAccelerationStructuresKHR-pInfos-03724",
                at,
                format!("the buffer of referenced structure {r:#x} has no memory bound"),
            ));
        }
        if dsts.iter().any(|d| d.handle == r) {
            return Err(Error::vuid(
                "VUID-vkBuildAccelerationStructuresKHR-None-03407",
                at,
                format!("instance references {r:#x}, a destination of this call"),
            ));
        }
        let header = self
            .with_bytes(AccelerationStructure(r), |b| {
                view::read_header(b).map_err(|reason| Error::NotBuilt { handle: r, reason })
            })
            .map_err(|e| {
                bad(format!(
                    "accelerationStructureReference {r:#x} is not a built structure: {e}"
                ))
            })?;
        if header.kind != Kind::BottomLevel as u32
            || obj.ty == vk::AccelerationStructureTypeKHR::TOP_LEVEL
        {
            return Err(bad(format!(
                "accelerationStructureReference {r:#x} is not a bottom-level structure"
            )));
        }
        Ok(if header.stored_count == 0 {
            // A degenerate instance: treated as a point at the instance origin.
            Aabb::point(inst.transform.point([0.0; 3]))
        } else {
            inst.transform.transform_aabb(&header.bounds)
        })
    }

    fn instance_record(inst: &Instance, id: u32, at: Location) -> Result<InstanceRecord> {
        let inv = inst.transform.inverse().ok_or_else(|| {
            Error::vuid(
                "VUID-VkTransformMatrixKHR-matrix-03799",
                at,
                "the instance transform's first three columns are not invertible",
            )
        })?;
        Ok(InstanceRecord {
            object_to_world: inst.transform.to_rows(),
            world_to_object: inv.to_rows(),
            acceleration_structure_reference: inst.acceleration_structure_reference,
            instance_id: id,
            custom_index: inst.custom_index,
            mask: inst.mask as u32,
            sbt_record_offset: inst.sbt_record_offset,
            flags: inst.flags.as_raw(),
            hints: if inst.transform == Affine::IDENTITY {
                crate::layout::INSTANCE_IDENTITY
            } else {
                0
            },
        })
    }

    fn build_one(
        &self,
        info: &mut BuildGeometryInfo,
        ranges: &[BuildRangeInfo],
        dst: &AsObject,
        at: Location,
        dsts: &[AsObject],
    ) -> Result<()> {
        let (kind, prim_kind) = validate::info(info, at)?;
        Self::check_dst_type(info, kind, dst, at)?;
        let readers = self.readers(info, ranges, at)?;
        let total: u64 = ranges.iter().map(|r| r.primitive_count as u64).sum();
        validate::counts(
            kind,
            prim_kind,
            total,
            at,
            "VUID-vkBuildAccelerationStructuresKHR-pInfos-03801",
        )?;
        let plan = Plan::new(prim_kind, info.geometries.len() as u64, total);
        if dst.size < plan.total_size {
            return Err(Error::vuid(
                "VUID-vkBuildAccelerationStructuresKHR-pInfos-03675",
                at,
                format!(
                    "destination size {} is smaller than the build size {}",
                    dst.size, plan.total_size
                ),
            ));
        }
        let need = build_scratch_size(prim_kind, total);
        let records = Self::geometry_records(info, ranges);
        let header_flags = Self::header_flags(info);
        let flags = info.flags;
        let scratch = info.scratch.as_deref_mut().unwrap_or(&mut []);
        if (scratch.len() as u64) < need {
            return Err(Error::vuid(
                "VUID-vkBuildAccelerationStructuresKHR-pInfos-03725",
                at,
                format!(
                    "scratch holds {} bytes, the build needs {need}",
                    scratch.len()
                ),
            ));
        }
        let n = total as usize;
        let Scratch {
            refs,
            aux,
            keys,
            keys_tmp,
            data,
        } = carve_scratch(scratch, n, prim_kind.prim_size() as usize)?;

        // Decode every primitive into scratch, by sequence number; inactive ones get no ref.
        // Triangles come with the bounds of their centroids (for the Morton builder), which
        // reads them from scratch as they are when all are active (see `decode_geometries`).
        let preset = Preset::from_flags(flags);
        let tris_direct = prim_kind == PrimKind::Triangles && preset.algorithm == Algorithm::Morton;
        let mut centroids = None;
        let stored = match prim_kind {
            PrimKind::Instances => {
                let Some(Reader::Instances(r)) = readers.first() else {
                    return Err(Error::NotSupported("instances without a reader".into()));
                };
                let out: &mut [InstanceRecord] = bytemuck::try_cast_slice_mut(data)
                    .map_err(|e| Error::NotSupported(format!("scratch carve: {e}")))?;
                let mut stored = 0usize;
                for i in 0..r.primitive_count {
                    let at = at.geometry(0).primitive(i);
                    let inst = r.instance(i)?;
                    if inst.acceleration_structure_reference == 0 {
                        continue;
                    }
                    let bounds = self.instance_bounds(&inst, dsts, at)?;
                    out[i as usize] = Self::instance_record(&inst, i, at)?;
                    refs[stored] = PrimRef::new(&bounds, i);
                    stored += 1;
                }
                stored
            }
            PrimKind::Triangles | PrimKind::Aabbs => {
                let (stored, cb) = decode_geometries(&readers, &records, refs, data, !tris_direct)?;
                centroids = cb;
                stored
            }
            PrimKind::None => 0,
        };
        let tris_direct = tris_direct && stored == n && centroids.is_some();
        let refs = &mut refs[..stored];

        let fields = HeaderFields {
            kind: kind as u32,
            build_flags: flags.as_raw(),
            prim_kind: prim_kind as u32,
            primitive_count: total as u32,
            stored_count: stored as u32,
            header_flags,
            preset: preset.id,
        };
        // Fast builds keep their triangles direct (build time is their preference), and so
        // does a structure that allows update (which rewrites each triangle in place).
        let index_tris = prim_kind == PrimKind::Triangles
            && preset.algorithm != Algorithm::Morton
            && !flags.contains(vk::BuildAccelerationStructureFlagsKHR::ALLOW_UPDATE);
        self.with_dst_src(dst, None, at, |bytes, _| {
            if tris_direct {
                // The Morton builder reads the triangles, and its leaves gather them and their
                // ids straight into the structure.
                let (prims, ids, nodes) = encode::sections(bytes, &plan, TRI_BYTES, stored)?;
                let cast = |e| internal(&format!("triangle records: {e}"));
                let tree = build::morton::build_triangles(
                    bytemuck::try_cast_slice(&*data).map_err(cast)?,
                    bytemuck::try_cast_slice_mut(prims).map_err(cast)?,
                    ids,
                    keys,
                    keys_tmp,
                    centroids,
                    preset.max_leaf,
                    nodes,
                );
                encode::encode(bytes, &plan, &fields, &records, &tree)?;
                return Ok(());
            }
            // The builders write the nodes straight into the structure.
            let (tree, order) = build::build(
                &preset,
                refs,
                &mut aux[..stored],
                &mut keys[..stored],
                &mut keys_tmp[..stored],
                centroids,
                encode::node_section(bytes, &plan)?,
            );
            let header = encode::encode(bytes, &plan, &fields, &records, &tree)?;
            // Indexed triangles are made from the decoded ones, straight into the structure;
            // direct ones are written where sharing does not pay.
            if !(index_tris && share_vertices(bytes, &header, order, &readers, &records, data)?) {
                write_prims(bytes, &header, prim_kind, order, data)?;
            }
            Ok(())
        })
    }

    fn update_one(
        &self,
        info: &mut BuildGeometryInfo,
        ranges: &[BuildRangeInfo],
        dst: &AsObject,
        at: Location,
        dsts: &[AsObject],
    ) -> Result<()> {
        let (kind, prim_kind) = validate::info(info, at)?;
        Self::check_dst_type(info, kind, dst, at)?;
        let src_handle = info.src.ok_or_else(|| {
            Error::vuid(
                "VUID-vkBuildAccelerationStructuresKHR-pInfos-04630",
                at,
                "mode is UPDATE but srcAccelerationStructure is NULL",
            )
        })?;
        let src = self.object(src_handle).map_err(|_| {
            Error::vuid(
                "VUID-vkBuildAccelerationStructuresKHR-srcAccelerationStructure-04629",
                at,
                format!(
                    "srcAccelerationStructure {:#x} is not a valid handle",
                    src_handle.0
                ),
            )
        })?;
        if src.buffer.memory().is_none() {
            return Err(Error::vuid(
                "VUID-vkBuildAccelerationStructuresKHR-pInfos-03723",
                at,
                "the source's buffer has no memory bound",
            ));
        }
        let src_header = self.header(src_handle).map_err(|e| {
            Error::vuid(
                "VUID-vkBuildAccelerationStructuresKHR-pInfos-03667",
                at,
                format!("source holds no built structure: {e}"),
            )
        })?;
        if src_header.build_flags & vk::BuildAccelerationStructureFlagsKHR::ALLOW_UPDATE.as_raw()
            == 0
        {
            return Err(Error::vuid(
                "VUID-vkBuildAccelerationStructuresKHR-pInfos-03667",
                at,
                "the source was not built with ALLOW_UPDATE",
            ));
        }
        if src_header.build_flags != info.flags.as_raw() {
            return Err(Error::vuid(
                "VUID-vkBuildAccelerationStructuresKHR-pInfos-03759",
                at,
                format!(
                    "flags {:#x} differ from the source's {:#x}",
                    info.flags.as_raw(),
                    src_header.build_flags
                ),
            ));
        }
        if src_header.kind != kind as u32 {
            return Err(Error::vuid(
                "VUID-vkBuildAccelerationStructuresKHR-pInfos-03760",
                at,
                "type differs from the source's",
            ));
        }
        if src_header.geometry_count as usize != info.geometries.len() {
            return Err(Error::vuid(
                "VUID-vkBuildAccelerationStructuresKHR-pInfos-03758",
                at,
                format!(
                    "geometryCount {} differs from the source's {}",
                    info.geometries.len(),
                    src_header.geometry_count
                ),
            ));
        }
        if dst.handle != src.handle && dst.size < src_header.used_size {
            return Err(Error::vuid(
                "VUID-vkBuildAccelerationStructuresKHR-pInfos-03675",
                at,
                format!(
                    "destination size {} is smaller than the source's {}",
                    dst.size, src_header.used_size
                ),
            ));
        }
        let scratch_len = info.scratch.as_deref().map_or(0, |s| s.len()) as u64;
        let need = plan::update_scratch_size(src_header.primitive_count as u64);
        if scratch_len < need {
            return Err(Error::vuid(
                "VUID-vkBuildAccelerationStructuresKHR-pInfos-03726",
                at,
                format!("scratch holds {scratch_len} bytes, the update needs {need}"),
            ));
        }
        let readers = self.readers(info, ranges, at)?;
        let total: u64 = ranges.iter().map(|r| r.primitive_count as u64).sum();
        validate::counts(
            kind,
            prim_kind,
            total,
            at,
            "VUID-vkBuildAccelerationStructuresKHR-pInfos-03801",
        )?;
        let records = Self::geometry_records(info, ranges);
        // Instances: decode before locking, to read the referenced BLASes' bounds.
        let mut instance_updates: Vec<(InstanceRecord, Aabb)> = Vec::new();
        if let Some(Reader::Instances(r)) = readers.first() {
            for i in 0..r.primitive_count {
                let at = at.geometry(0).primitive(i);
                let inst = r.instance(i)?;
                if inst.acceleration_structure_reference == 0 {
                    continue;
                }
                let bounds = self.instance_bounds(&inst, dsts, at)?;
                instance_updates.push((Self::instance_record(&inst, i, at)?, bounds));
            }
        }
        let scratch: &mut [u8] = info.scratch.as_deref_mut().unwrap_or_default();
        self.with_dst_src(dst, Some(&src), at, |bytes, src_bytes| {
            if let Some(s) = src_bytes {
                let used = src_header.used_size as usize;
                bytes[..used].copy_from_slice(&s[..used]);
                let mut h: Header = bytemuck::pod_read_unaligned(&bytes[..256]);
                h.allocated_size = bytes.len() as u64;
                bytes[..256].copy_from_slice(bytemuck::bytes_of(&h));
            }
            let not_built = |reason| Error::NotBuilt {
                handle: src.handle,
                reason,
            };
            // The whole source is validated as View::parse does, in two steps: the header,
            // sections and geometry records here, the primitive ids and the tree as the refit
            // walks it (or, where it cannot, by View::parse before anything else is reported).
            let validate = |b: &[u8]| View::parse(b).map(|_| ()).map_err(not_built);
            let view = View::parse_sections(bytes).map_err(not_built)?;
            let header = *view.header;
            if let Err(e) = check_update_geometries(view.geometries, &records, at) {
                validate(bytes)?;
                return Err(e);
            }
            super::refit::refit(
                bytes,
                &header,
                prim_kind,
                &readers,
                &instance_updates,
                at,
                &validate,
                scratch,
            )
        })
    }
}

/// The arrays a build keeps in scratch.
struct Scratch<'s> {
    refs: &'s mut [PrimRef],
    aux: &'s mut [PrimRef],
    keys: &'s mut [u64],
    keys_tmp: &'s mut [u64],
    data: &'s mut [u8],
}

/// Splits scratch into aligned arrays: refs, partition buffer, keys, key buffer, primitive data.
fn carve_scratch(scratch: &mut [u8], n: usize, prim_size: usize) -> Result<Scratch<'_>> {
    let misalign = scratch.as_ptr().align_offset(64).min(scratch.len());
    let s = &mut scratch[misalign..];
    // Each array starts on a 64-byte boundary.
    let r_len = (32 * n).div_ceil(64) * 64;
    let k_len = (8 * n).div_ceil(64) * 64;
    if s.len() < 2 * r_len + 2 * k_len + prim_size * n {
        return Err(Error::RangeTooShort {
            what: "scratch",
            needed: (2 * r_len + 2 * k_len + prim_size * n) as u64,
            available: s.len() as u64,
            location: Location::NONE,
        });
    }
    let (r, rest) = s.split_at_mut(r_len);
    let (a, rest) = rest.split_at_mut(r_len);
    let (k, rest) = rest.split_at_mut(k_len);
    let (kt, rest) = rest.split_at_mut(k_len);
    let data = &mut rest[..prim_size * n];
    let cast_err =
        |e: bytemuck::PodCastError| Error::NotSupported(format!("scratch alignment: {e}"));
    Ok(Scratch {
        refs: bytemuck::try_cast_slice_mut(&mut r[..32 * n]).map_err(cast_err)?,
        aux: bytemuck::try_cast_slice_mut(&mut a[..32 * n]).map_err(cast_err)?,
        keys: bytemuck::try_cast_slice_mut(&mut k[..8 * n]).map_err(cast_err)?,
        keys_tmp: bytemuck::try_cast_slice_mut(&mut kt[..8 * n]).map_err(cast_err)?,
        data,
    })
}

/// Decodes all triangles or AABBs into `data` (indexed by sequence number) and writes a
/// `PrimRef` per active primitive into `refs`; returns how many are active, and for triangles
/// the bounds of their doubled centroids (see [`decode_tris`]). Parallel over chunks; the first
/// error in primitive order is reported.
///
/// Each primitive's reference is first written at its sequence number (an inactive one marked
/// by `pad = 1`); when some are inactive, one pass then closes the gaps in order.
///
/// Without `refs_too`, triangles get their references only where some are inactive or the
/// centroids' bounds are unknown (made from `data` then, as decoding makes them): otherwise
/// the Morton builder reads the decoded triangles instead.
fn decode_geometries(
    readers: &[Reader],
    records: &[GeometryRecord],
    refs: &mut [PrimRef],
    data: &mut [u8],
    refs_too: bool,
) -> Result<(usize, Option<Box4>)> {
    const CHUNK: usize = 4096;
    let mut inactive = 0usize;
    // Chunks' bounds united in order: without NaN, min and max (the later operand on ties)
    // do not depend on the grouping, so this is the bounds the builder would compute.
    let mut centroids = Some(Box4::EMPTY);
    for (reader, rec) in readers.iter().zip(records) {
        let first = rec.first_primitive as usize;
        let count = rec.primitive_count as usize;
        let size = match reader {
            Reader::Triangles(_) => TRI_BYTES,
            _ => 24,
        };
        let geom_data = &mut data[first * size..(first + count) * size];
        let geom_refs = &mut refs[first..first + count];
        let results: Vec<Result<(usize, Option<Box4>)>> = geom_data
            .par_chunks_mut(CHUNK * size)
            .zip(geom_refs.par_chunks_mut(CHUNK))
            .enumerate()
            .map(|(c, (chunk, chunk_refs))| {
                let mut inactive = 0;
                let mut centroids = None;
                let base = c * CHUNK;
                match reader {
                    Reader::Triangles(t) => {
                        let outs: &mut [[u8; TRI_BYTES]] = bytemuck::try_cast_slice_mut(chunk)
                            .map_err(|_| internal("triangle slots"))?;
                        let first = first + base;
                        let (dead, cb) = if refs_too {
                            decode_chunk::<true>(t, base, first, outs, chunk_refs)
                        } else {
                            decode_chunk::<false>(t, base, first, outs, chunk_refs)
                        }?;
                        (inactive, centroids) = (dead, cb);
                    }
                    Reader::Aabbs(a) => {
                        let outs = chunk.chunks_exact_mut(24);
                        for (j, (out, r)) in outs.zip(chunk_refs.iter_mut()).enumerate() {
                            let i = (base + j) as u32;
                            let b = a.aabb(i)?.unwrap_or(Aabb {
                                lo: [f32::NAN; 3],
                                hi: [f32::NAN; 3],
                            });
                            let f = [b.lo[0], b.lo[1], b.lo[2], b.hi[0], b.hi[1], b.hi[2]];
                            let out: &mut [u8; 24] =
                                out.try_into().map_err(|_| internal("box slot"))?;
                            *out = bytemuck::cast(f);
                            let dead = f[0].is_nan();
                            inactive += dead as usize;
                            *r = PrimRef::new(&b, (first + base + j) as u32);
                            r.pad = dead as u32;
                        }
                    }
                    Reader::Instances(_) => {}
                }
                Ok((inactive, centroids))
            })
            .collect();
        for r in results {
            let (dead, cb) = r?;
            inactive += dead;
            centroids = centroids.zip(cb).map(|(a, b)| a.union(b));
        }
    }
    let total: usize = records.iter().map(|r| r.primitive_count as usize).sum();
    let tris = readers.iter().any(|r| matches!(r, Reader::Triangles(_)));
    if tris && !refs_too {
        if inactive == 0 && centroids.is_some() {
            return Ok((total, centroids));
        }
        tri_refs(&data[..TRI_BYTES * total], &mut refs[..total])?;
    }
    if inactive == 0 {
        return Ok((total, centroids));
    }
    // Close the gaps left by inactive primitives, keeping the order.
    let mut stored = 0usize;
    for i in 0..total {
        let r = refs[i];
        if r.pad == 0 {
            refs[stored] = r;
            stored += 1;
        }
    }
    Ok((stored, centroids))
}

/// Decodes triangles `base..` of `t` as [`decode_tris`] does, by the fastest means for
/// its layout.
fn decode_chunk<const REFS: bool>(
    t: &TriangleReader,
    base: usize,
    first: usize,
    outs: &mut [[u8; TRI_BYTES]],
    refs: &mut [PrimRef],
) -> Result<(usize, Option<Box4>)> {
    match F32Tris::new(t) {
        Some(F32Tris::I0(d)) => d.decode::<REFS>(t, base, first, outs, refs),
        Some(F32Tris::I2(d)) => d.decode::<REFS>(t, base, first, outs, refs),
        Some(F32Tris::I4(d)) => d.decode::<REFS>(t, base, first, outs, refs),
        Some(F32Tris::I0S(d)) => d.decode::<REFS>(t, base, first, outs, refs),
        Some(F32Tris::I2S(d)) => d.decode::<REFS>(t, base, first, outs, refs),
        Some(F32Tris::I4S(d)) => d.decode::<REFS>(t, base, first, outs, refs),
        None => {
            let tris = (base..).map(|p| reader_tri(t, p));
            decode_tris::<REFS>(tris, t, base, first, outs, refs)
        }
    }
}

/// Triangle `p` of `t` as three vertices, for the common layouts: `None` where the reader
/// must decide (inactive, out of range, an unusual layout).
#[inline(always)]
fn reader_tri(t: &TriangleReader, p: usize) -> Option<[f32x4; 3]> {
    let f = t.triangle_fast(p as u32)?;
    if f[0].is_nan() || f[3].is_nan() || f[6].is_nan() {
        return None;
    }
    Some([0, 3, 6].map(|k| lanes([f[k], f[k + 1], f[k + 2]])))
}

/// The vertices of an `R32G32B32_SFLOAT` geometry, read 16 bytes at a time (lane 3 is the
/// next float): `0..count`, every vertex up to maxVertex whose 16 bytes lie in the buffer.
#[derive(Clone, Copy)]
struct F32Verts<'a> {
    data: &'a [u8],
    stride: usize,
    count: usize,
}

impl F32Verts<'_> {
    /// Vertex `v < count`.
    #[inline(always)]
    fn vertex(&self, v: usize) -> Option<f32x4> {
        let at = v.wrapping_mul(self.stride);
        Some(bytemuck::pod_read_unaligned(
            self.data.get(at..at.wrapping_add(16))?,
        ))
    }
}

/// An `R32G32B32_SFLOAT` geometry without a transform whose buffers hold every vertex up to
/// maxVertex, its layout read once: `IDX`-byte indices (0: none), `STRIDE` bytes between
/// vertices (0: any).
#[derive(Clone, Copy)]
struct F32Geometry<'a, const IDX: usize, const STRIDE: usize> {
    /// From `primitiveOffset` (indexed geometries).
    index: &'a [u8],
    /// From vertex `firstVertex`, so that indices address them directly.
    verts: F32Verts<'a>,
}

enum F32Tris<'a> {
    I0(F32Geometry<'a, 0, 12>),
    I2(F32Geometry<'a, 2, 12>),
    I4(F32Geometry<'a, 4, 12>),
    I0S(F32Geometry<'a, 0, 0>),
    I2S(F32Geometry<'a, 2, 0>),
    I4S(F32Geometry<'a, 4, 0>),
}

impl<'a> F32Tris<'a> {
    /// `None` where the reader decodes (another format, a transform, short vertex data).
    fn new(t: &TriangleReader<'a>) -> Option<Self> {
        // (Vertices are read as native floats 16 bytes at a time.)
        if cfg!(target_endian = "big") {
            return None;
        }
        let l = t.f32_layout()?;
        if l.transform.is_some() {
            return None;
        }
        // Vertices up to maxVertex must be in the buffer; the last one is read 16 bytes at a
        // time only when 4 more bytes follow (otherwise triangles using it go to the reader).
        let end = l.max_vertex.checked_mul(l.vertex_stride)?.checked_add(12)?;
        let (data, count) = match l.vertex_data.get(..end + 4) {
            Some(d) => (d, l.max_vertex + 1),
            None => (l.vertex_data.get(..end)?, l.max_vertex),
        };
        // From vertex `firstVertex` (past the end: the reader decodes the geometry).
        let verts = F32Verts {
            data: data.get(l.first_vertex.checked_mul(l.vertex_stride)?..)?,
            stride: l.vertex_stride,
            count: count.saturating_sub(l.first_vertex),
        };
        fn g<'a, const IDX: usize, const STRIDE: usize>(
            l: &F32Layout<'a>,
            verts: F32Verts<'a>,
        ) -> F32Geometry<'a, IDX, STRIDE> {
            F32Geometry {
                index: l.index_data,
                verts,
            }
        }
        Some(match (l.index_size, l.vertex_stride == 12) {
            (0, true) => F32Tris::I0(g(&l, verts)),
            (2, true) => F32Tris::I2(g(&l, verts)),
            (_, true) => F32Tris::I4(g(&l, verts)),
            (0, false) => F32Tris::I0S(g(&l, verts)),
            (2, false) => F32Tris::I2S(g(&l, verts)),
            (_, false) => F32Tris::I4S(g(&l, verts)),
        })
    }
}

impl<const IDX: usize, const STRIDE: usize> F32Geometry<'_, IDX, STRIDE> {
    /// Decodes triangles `base..` as [`decode_tris`] does, reading the index records of the
    /// whole run in order (each triangle's own range test is the bounds check of the run).
    #[inline(always)]
    fn decode<const REFS: bool>(
        &self,
        t: &TriangleReader,
        base: usize,
        first: usize,
        outs: &mut [[u8; TRI_BYTES]],
        refs: &mut [PrimRef],
    ) -> Result<(usize, Option<Box4>)> {
        // (A copy: the loop then keeps the layout in registers.)
        let g = *self;
        if IDX == 0 {
            let tris = (base..).map(move |p| g.tri([3 * p, 3 * p + 1, 3 * p + 2]));
            return decode_tris::<REFS>(tris, t, base, first, outs, refs);
        }
        let size = 3 * IDX;
        let u = |b: &[u8], k: usize| -> usize {
            if IDX == 2 {
                u16::from_le_bytes([b[2 * k], b[2 * k + 1]]) as usize
            } else {
                bytemuck::pod_read_unaligned::<u32>(&b[4 * k..4 * k + 4]).to_le() as usize
            }
        };
        match g.index.get(size * base..size * (base + outs.len())) {
            Some(records) => {
                let tris = records
                    .chunks_exact(size)
                    .map(move |b| g.tri([u(b, 0), u(b, 1), u(b, 2)]));
                decode_tris::<REFS>(tris, t, base, first, outs, refs)
            }
            // Index records past the buffer: the reader reports them.
            None => {
                let tris = (base..).map(|p| reader_tri(t, p));
                decode_tris::<REFS>(tris, t, base, first, outs, refs)
            }
        }
    }

    /// The triangle of vertex indices `v` (from firstVertex): `None` where the reader must
    /// decide (a vertex out of range, an X that is NaN).
    #[inline(always)]
    fn tri(&self, v: [usize; 3]) -> Option<[f32x4; 3]> {
        // With 12-byte vertices the reads' bounds check is this test: the data ends where
        // vertex `count - 1`'s 16 bytes do.
        if STRIDE != 12 && v[0].max(v[1]).max(v[2]) >= self.verts.count {
            return None;
        }
        let (a, b, c) = if STRIDE == 12 {
            // One check for the three reads (each vertex's 16 bytes end where the last one's
            // do or before), which the compiler then drops from each read.
            let last = v[0].max(v[1]).max(v[2]);
            let data = self
                .verts
                .data
                .get(..last.checked_mul(12)?.checked_add(16)?)?;
            let read = |v: usize| -> f32x4 { bytemuck::pod_read_unaligned(&data[12 * v..][..16]) };
            (read(v[0]), read(v[1]), read(v[2]))
        } else {
            let mut verts = self.verts;
            if STRIDE != 0 {
                verts.stride = STRIDE;
            }
            (
                verts.vertex(v[0])?,
                verts.vertex(v[1])?,
                verts.vertex(v[2])?,
            )
        };
        // An X that is NaN makes the sum's NaN (so do infinities of both signs, which the
        // reader then decodes): one test on whole vectors, each vertex staying one load.
        if ((a + b) + c).is_nan().to_bitmask() & 1 != 0 {
            return None;
        }
        Some([a, b, c])
    }
}

/// Decodes triangles `base..` of `t` into `outs` and, when `REFS`, their references
/// (sequence numbers from `first`) into `refs`; returns how many are inactive and the bounds of the active ones'
/// doubled centroids (`lo + hi`, lane 3 zero), united in order as the Morton builder would
/// (saving it a pass over the references), or `None` when a centroid has a NaN lane (then the
/// result depends on the grouping). `tris` decodes the common cases in order, the reader the
/// others (and reports what is wrong). (Not inlined: inside the caller's closure the sums
/// stay in memory.)
#[inline(never)]
fn decode_tris<const REFS: bool>(
    tris: impl Iterator<Item = Option<[f32x4; 3]>>,
    t: &TriangleReader,
    base: usize,
    first: usize,
    outs: &mut [[u8; TRI_BYTES]],
    refs: &mut [PrimRef],
) -> Result<(usize, Option<Box4>)> {
    let mut inactive = 0;
    let mut centroids = Box4::EMPTY;
    let mut nan = f32x4::ZERO;
    // Lane 3 of the reference's low half: its sequence number, counted up as a vector.
    let mut id = bytemuck::cast::<[u32; 4], i32x4>([0, 0, 0, first as u32]);
    let next = i32x4::new([0, 0, 0, 1]);
    let mut put = |out: &mut [u8; TRI_BYTES], r: &mut PrimRef, [a, b, c]: [f32x4; 3], dead| {
        // The three vertices, each store overwriting the previous one's lane 3.
        let bytes = |v: f32x4| -> [u8; 16] { bytemuck::cast(v) };
        out[..16].copy_from_slice(&bytes(a));
        out[12..28].copy_from_slice(&bytes(b));
        out[24..].copy_from_slice(&bytes(c)[..12]);
        let (lo, hi) = ref_bounds(a, b, c);
        if REFS {
            *r = tri_ref(lo, hi, id, dead);
            id += next;
        }
        if dead {
            inactive += 1;
        } else {
            let c = lo + hi;
            centroids = centroids.union(Box4 { lo: c, hi: c });
            nan |= c.is_nan();
        }
    };
    let mut slots = outs.iter_mut().zip(refs.iter_mut()).zip(tris).enumerate();
    loop {
        // The triangles `tris` decodes, in a loop without calls (which would keep the sums
        // in memory), up to one it leaves to the reader.
        let rest = loop {
            let Some((j, ((out, r), tri))) = slots.next() else {
                break None;
            };
            match tri {
                Some(v) => put(out, r, v, false),
                None => break Some((j, out, r)),
            }
        };
        let Some((j, out, r)) = rest else {
            break;
        };
        // Inactive: the first vertex's X is NaN.
        match t.triangle((base + j) as u32)? {
            Some(v) => {
                let v = v.map(lanes);
                put(out, r, v, v[0].as_array()[0].is_nan());
            }
            None => put(out, r, [f32x4::splat(f32::NAN); 3], true),
        }
    }
    let clean = nan.to_bitmask() == 0;
    Ok((inactive, clean.then_some(centroids)))
}

/// A triangle's bounds as `Aabb::point` and `grow` make them, lane 3 zero.
#[inline(always)]
fn ref_bounds(a: f32x4, b: f32x4, c: f32x4) -> (f32x4, f32x4) {
    let tri = Box4::triangle(a, b, c);
    (tri.lo & XYZ, tri.hi & XYZ)
}

/// A triangle's reference from its bounds (lane 3 zero): lane 3 the id (low, lane 3 of `id`)
/// and whether it is inactive (high).
#[inline(always)]
fn tri_ref(lo: f32x4, hi: f32x4, id: i32x4, dead: bool) -> PrimRef {
    let mark = if dead { DEAD } else { f32x4::ZERO };
    bytemuck::cast([lo | bytemuck::cast::<i32x4, f32x4>(id), hi | mark])
}

/// The references of the decoded triangles `data` (an inactive one's first X is NaN), as
/// [`decode_tris`] makes them.
fn tri_refs(data: &[u8], refs: &mut [PrimRef]) -> Result<()> {
    const CHUNK: usize = 4096;
    let tris: &[[f32; 9]] =
        bytemuck::try_cast_slice(data).map_err(|_| internal("triangle slots"))?;
    refs.par_chunks_mut(CHUNK)
        .zip(tris.par_chunks(CHUNK))
        .enumerate()
        .for_each(|(c, (refs, tris))| {
            for (i, (r, t)) in refs.iter_mut().zip(tris).enumerate() {
                let v = |k: usize| lanes([t[k], t[k + 1], t[k + 2]]);
                let (lo, hi) = ref_bounds(v(0), v(3), v(6));
                let id = i32x4::new([0, 0, 0, (c * CHUNK + i) as i32]);
                *r = tri_ref(lo, hi, id, t[0].is_nan());
            }
        });
    Ok(())
}

/// Keeps lanes 0..3.
const XYZ: f32x4 = f32x4::new([
    f32::from_bits(!0),
    f32::from_bits(!0),
    f32::from_bits(!0),
    0.0,
]);
/// Lane 3 of an inactive reference's high half (`pad = 1`).
const DEAD: f32x4 = f32x4::new([0.0, 0.0, 0.0, f32::from_bits(1)]);

fn internal(what: &str) -> Error {
    Error::NotSupported(format!("internal: {what}"))
}

/// Writes the ids and the decoded triangles `data` (by sequence number) in the tree's final
/// order `refs` as indexed triangles sharing the application's vertices (same geometry, same
/// vertex index), where that makes the structure smaller; returns whether it did (if not,
/// the primitives are for [`write_prims`] to write).
fn share_vertices(
    bytes: &mut [u8],
    h: &Header,
    refs: &[PrimRef],
    readers: &[Reader],
    records: &[GeometryRecord],
    data: &[u8],
) -> Result<bool> {
    // Each indexed geometry's vertex numbers (0..=maxVertex) get keys of their own.
    let mut geometries = Vec::with_capacity(records.len());
    // At most `bound` vertices get stored (a geometry without indices shares none): when
    // even that many would not fit, sharing cannot pay (a triangle soup) and is not tried.
    let (mut key_count, mut bound, mut triangles) = (0u64, 0u64, 0u64);
    for (r, reader) in records.iter().zip(readers) {
        let Reader::Triangles(t) = reader else {
            return Ok(false);
        };
        let indexed = t.indexed_vertices();
        geometries.push((r.first_primitive, key_count, indexed));
        key_count += indexed.map_or(0, |v| v.max_vertex() + 1);
        let corners = 3 * r.primitive_count as u64;
        bound += indexed.map_or(corners, |v| corners.min(v.max_vertex() + 1));
        triangles += r.primitive_count as u64;
    }
    if !layout::indexed::may_pay(bound, triangles) {
        return Ok(false);
    }
    // The pass reads the ids from the structure, each triangle from `data`.
    let at = h.prim_ids_offset as usize;
    let ids = bytes
        .get_mut(at..at + 4 * refs.len())
        .ok_or_else(|| internal("primitive ids past the structure"))?;
    let ids: &mut [u32] =
        bytemuck::try_cast_slice_mut(ids).map_err(|e| internal(&format!("primitive ids: {e}")))?;
    for (i, r) in ids.iter_mut().zip(refs) {
        *i = r.id;
    }
    let tris: &[[f32; 9]] = bytemuck::try_cast_slice(&data[..data.len() / TRI_BYTES * TRI_BYTES])
        .map_err(|e| internal(&format!("triangle records: {e}")))?;
    if let [(_, _, Some(g))] = geometries[..] {
        // One geometry (the common case) needs no lookup, and its vertex numbers are its
        // keys: those past `maxVertex` are past `key_count`.
        let keys = |ids: &[u32], out: &mut [[u32; 3]]| g.triangles(ids, out);
        return layout::indexed::share_vertices(bytes, tris, keys, key_count);
    }
    // Keys fit a `u32` (share_vertices checks `key_count`).
    let key = |id: u32| {
        let at = geometries.partition_point(|g| g.0 <= id).checked_sub(1)?;
        let (first, base, g) = geometries[at];
        let v = g?.triangle(id - first)?;
        Some(v.map(|v| base as u32 + v))
    };
    let keys = |ids: &[u32], out: &mut [[u32; 3]]| {
        for (&id, out) in ids.iter().zip(out) {
            // Past `key_count`: shares nothing.
            *out = key(id).unwrap_or([u32::MAX; 3]);
        }
    };
    layout::indexed::share_vertices(bytes, tris, keys, key_count)
}

/// Writes the primitive sections in the tree's final order.
fn write_prims(
    bytes: &mut [u8],
    h: &Header,
    prim_kind: PrimKind,
    refs: &[PrimRef],
    data: &[u8],
) -> Result<()> {
    let size = prim_kind.prim_size() as usize;
    let n = refs.len();
    let (head, ids_part) = bytes.split_at_mut(h.prim_ids_offset as usize);
    let ids: &mut [u32] = bytemuck::try_cast_slice_mut(&mut ids_part[..4 * n])
        .map_err(|e| Error::NotSupported(format!("alignment: {e}")))?;
    let prims = &mut head[h.prims_offset as usize..h.prims_offset as usize + size * n];
    // Ids and primitives in one pass over the references, in chunks; fixed-size copies (a
    // copy of a run-time length is a call per primitive).
    const CHUNK: usize = 4096;
    fn gather<const S: usize>(
        prims: &mut [u8],
        ids: &mut [u32],
        refs: &[PrimRef],
        data: &[u8],
    ) -> Result<()> {
        let cast = |e: bytemuck::PodCastError| internal(&format!("primitive records: {e}"));
        let prims: &mut [[u8; S]] = bytemuck::try_cast_slice_mut(prims).map_err(cast)?;
        let data: &[[u8; S]] =
            bytemuck::try_cast_slice(&data[..data.len() / S * S]).map_err(cast)?;
        prims
            .par_chunks_mut(CHUNK)
            .zip(ids.par_chunks_mut(CHUNK))
            .zip(refs.par_chunks(CHUNK))
            .for_each(|((prims, ids), refs)| {
                for ((p, i), r) in prims.iter_mut().zip(ids.iter_mut()).zip(refs) {
                    *i = r.id;
                    if let Some(src) = data.get(r.id as usize) {
                        *p = *src;
                    }
                }
            });
        Ok(())
    }
    match size {
        TRI_BYTES => gather::<TRI_BYTES>(prims, ids, refs, data)?,
        24 => gather::<24>(prims, ids, refs, data)?,
        _ => {
            ids.par_iter_mut()
                .zip(refs.par_iter())
                .with_min_len(CHUNK)
                .for_each(|(o, r)| *o = r.id);
            if size > 0 {
                prims
                    .par_chunks_mut(size)
                    .zip(refs.par_iter())
                    .with_min_len(1024)
                    .for_each(|(out, r)| {
                        let at = r.id as usize * size;
                        out.copy_from_slice(&data[at..at + size]);
                    });
            }
        }
    }
    Ok(())
}

fn check_update_geometries(
    old: &[GeometryRecord],
    new: &[GeometryRecord],
    at: Location,
) -> Result<()> {
    for (g, (o, n)) in old.iter().zip(new).enumerate() {
        let at = at.geometry(g);
        let rule = |cond: bool, vuid: &'static str, what: &str| {
            if cond {
                Ok(())
            } else {
                Err(Error::vuid(
                    vuid,
                    at,
                    format!("{what} differs from the source's"),
                ))
            }
        };
        rule(
            o.geometry_type == n.geometry_type,
            "VUID-vkBuildAccelerationStructuresKHR-pInfos-03761",
            "geometryType",
        )?;
        rule(
            o.flags == n.flags,
            "VUID-vkBuildAccelerationStructuresKHR-pInfos-03762",
            "geometry flags",
        )?;
        rule(
            o.vertex_format == n.vertex_format,
            "VUID-vkBuildAccelerationStructuresKHR-pInfos-03763",
            "vertexFormat",
        )?;
        rule(
            o.max_vertex == n.max_vertex,
            "VUID-vkBuildAccelerationStructuresKHR-pInfos-03764",
            "maxVertex",
        )?;
        rule(
            o.index_type == n.index_type,
            "VUID-vkBuildAccelerationStructuresKHR-pInfos-03765",
            "indexType",
        )?;
        if o.extra & 1 != n.extra & 1 {
            let vuid = if o.extra & 1 == 0 {
                "VUID-vkBuildAccelerationStructuresKHR-pInfos-03766"
            } else {
                "VUID-vkBuildAccelerationStructuresKHR-pInfos-03767"
            };
            return Err(Error::vuid(
                vuid,
                at,
                "transformData NULL-ness differs from the source's",
            ));
        }
        rule(
            o.primitive_count == n.primitive_count,
            "VUID-vkBuildAccelerationStructuresKHR-primitiveCount-03769",
            "primitiveCount",
        )?;
        rule(
            o.first_vertex == n.first_vertex,
            "VUID-vkBuildAccelerationStructuresKHR-firstVertex-03770",
            "firstVertex (indexed triangles)",
        )?;
    }
    Ok(())
}
