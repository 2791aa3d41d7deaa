//! `vkCopyAccelerationStructureKHR` (clone, compact), `vkCopyAccelerationStructureToMemoryKHR`
//! (serialize) and `vkCopyMemoryToAccelerationStructureKHR` (deserialize).
//!
//! The layout is position-independent and its used bytes are a prefix of its range, so clone
//! and compact copy that prefix; serialization wraps it in the spec's header with one handle
//! per instance, in instance order (0 for inactive instances), and deserialization validates
//! the untrusted bytes completely before writing them, then takes the instance references
//! from that handle list by position.

use crate::device::{AccelerationStructure, AsObject, COMPATIBILITY_UUID, DRIVER_UUID, Device};
use crate::error::{Error, Location, Result};
use crate::layout::view::{self, View};
use crate::layout::{HEADER_SIZE, Header, InstanceRecord, Kind, PrimKind};
use ash::vk;

/// Bytes before the handle list in a serialized structure.
pub const SERIALIZED_HEADER_SIZE: u64 = 56;

/// The spec's serialized-structure header (`[[serialized-as-header]]`), as any implementation
/// writes it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SerializedHeader {
    pub driver_uuid: [u8; 16],
    pub compatibility_uuid: [u8; 16],
    /// Total bytes of the serialized data.
    pub serialized_size: u64,
    /// The size to create the deserialization target with.
    pub deserialized_size: u64,
    /// Number of bottom-level handles that follow (0 for a bottom-level structure).
    pub handle_count: u64,
    pub handles: Vec<u64>,
}

impl SerializedHeader {
    /// Parses the header and handle list of serialized data from any implementation.
    pub fn parse(bytes: &[u8]) -> Result<SerializedHeader> {
        let short = |needed: u64| Error::RangeTooShort {
            what: "serialized data",
            needed,
            available: bytes.len() as u64,
            location: Location::NONE,
        };
        if (bytes.len() as u64) < SERIALIZED_HEADER_SIZE {
            return Err(short(SERIALIZED_HEADER_SIZE));
        }
        let u64_at = |o: usize| u64::from_le_bytes(bytes[o..o + 8].try_into().unwrap_or([0; 8]));
        let handle_count = u64_at(48);
        // The high half of this field marks a block-based (opacity micromap) header; such data
        // carries no plain handle list.
        let plain = handle_count >> 32 == 0;
        let n = if plain { handle_count } else { 0 };
        let end = n
            .checked_mul(8)
            .and_then(|h| h.checked_add(SERIALIZED_HEADER_SIZE))
            .ok_or_else(|| short(u64::MAX))?;
        if end > bytes.len() as u64 {
            return Err(short(end));
        }
        Ok(SerializedHeader {
            driver_uuid: bytes[0..16].try_into().unwrap_or_default(),
            compatibility_uuid: bytes[16..32].try_into().unwrap_or_default(),
            serialized_size: u64_at(32),
            deserialized_size: u64_at(40),
            handle_count,
            handles: (0..n as usize).map(|i| u64_at(56 + 8 * i)).collect(),
        })
    }
}

/// The handle list a structure serializes: one per instance in instance order for a TLAS.
fn handle_list(v: &View) -> Vec<u64> {
    if v.header.kind != Kind::TopLevel as u32 {
        return Vec::new();
    }
    let mut handles = vec![0u64; v.header.primitive_count as usize];
    for rec in v.instances {
        if let Some(h) = handles.get_mut(rec.instance_id as usize) {
            *h = rec.acceleration_structure_reference;
        }
    }
    handles
}

/// Sets the allocated size in a copied header.
fn patch_allocated(bytes: &mut [u8], allocated: u64) {
    let mut h: Header = bytemuck::pod_read_unaligned(&bytes[..HEADER_SIZE as usize]);
    h.allocated_size = allocated;
    bytes[..HEADER_SIZE as usize].copy_from_slice(bytemuck::bytes_of(&h));
}

impl Device {
    fn constructed(
        &self,
        a: AccelerationStructure,
        vuid: &'static str,
    ) -> Result<(AsObject, Header)> {
        let obj = self.object(a)?;
        let header = self.with_bytes(a, |b| {
            View::parse(b).map(|v| *v.header).map_err(|reason| {
                Error::vuid(
                    vuid,
                    Location::NONE,
                    format!("{:#x} holds no built structure: {reason}", a.0),
                )
            })
        })?;
        Ok((obj, header))
    }

    /// `vkCopyAccelerationStructureKHR` with mode `CLONE` or `COMPACT`.
    #[doc(alias = "vkCopyAccelerationStructureKHR")]
    pub fn copy_acceleration_structure(
        &self,
        src: AccelerationStructure,
        dst: AccelerationStructure,
        mode: vk::CopyAccelerationStructureModeKHR,
    ) -> Result<()> {
        let at = Location::NONE;
        let (src_obj, h) =
            self.constructed(src, "VUID-VkCopyAccelerationStructureInfoKHR-src-11586")?;
        let dst_obj = self.object(dst)?;
        match mode {
            vk::CopyAccelerationStructureModeKHR::CLONE => {}
            vk::CopyAccelerationStructureModeKHR::COMPACT => {
                if h.build_flags & vk::BuildAccelerationStructureFlagsKHR::ALLOW_COMPACTION.as_raw()
                    == 0
                {
                    return Err(Error::vuid(
                        "VUID-VkCopyAccelerationStructureInfoKHR-src-03411",
                        at,
                        "COMPACT needs a source built with ALLOW_COMPACTION",
                    ));
                }
            }
            other => {
                return Err(Error::vuid(
                    "VUID-VkCopyAccelerationStructureInfoKHR-mode-03410",
                    at,
                    format!("mode {other:?} is not CLONE or COMPACT"),
                ));
            }
        }
        if src_obj.handle == dst_obj.handle
            || (src_obj.buffer.id() == dst_obj.buffer.id()
                && src_obj.offset < dst_obj.offset + dst_obj.size
                && dst_obj.offset < src_obj.offset + src_obj.size)
        {
            return Err(Error::vuid(
                "VUID-VkCopyAccelerationStructureInfoKHR-dst-07791",
                at,
                "source and destination memory overlap",
            ));
        }
        let kind_ok = dst_obj.ty == vk::AccelerationStructureTypeKHR::GENERIC
            || (dst_obj.ty == vk::AccelerationStructureTypeKHR::TOP_LEVEL)
                == (h.kind == Kind::TopLevel as u32);
        if !kind_ok {
            return Err(Error::vuid(
                "VUID-VkCopyAccelerationStructureInfoKHR-src-04963",
                at,
                format!(
                    "destination type {:?} differs from the source's",
                    dst_obj.ty
                ),
            ));
        }
        if dst_obj.size < h.used_size {
            let vuid = if mode == vk::CopyAccelerationStructureModeKHR::CLONE {
                "VUID-VkCopyAccelerationStructureInfoKHR-mode-12418"
            } else {
                "VUID-VkCopyAccelerationStructureInfoKHR-mode-12419"
            };
            return Err(Error::vuid(
                vuid,
                at,
                format!(
                    "destination size {} is smaller than the needed {}",
                    dst_obj.size, h.used_size
                ),
            ));
        }
        self.with_dst_src(&dst_obj, Some(&src_obj), at, |d, s| {
            let used = h.used_size as usize;
            let s = s.ok_or_else(|| {
                Error::vuid(
                    "VUID-VkCopyAccelerationStructureInfoKHR-dst-07791",
                    at,
                    "source and destination are the same",
                )
            })?;
            d[..used].copy_from_slice(&s[..used]);
            patch_allocated(d, d.len() as u64);
            Ok(())
        })
    }

    /// `vkCopyAccelerationStructureToMemoryKHR` (mode `SERIALIZE`): writes the spec header,
    /// the handle list and the structure into `dst`; returns the bytes written.
    #[doc(alias = "vkCopyAccelerationStructureToMemoryKHR")]
    pub fn copy_acceleration_structure_to_memory(
        &self,
        src: AccelerationStructure,
        dst: &mut [u8],
        mode: vk::CopyAccelerationStructureModeKHR,
    ) -> Result<u64> {
        let at = Location::NONE;
        if mode != vk::CopyAccelerationStructureModeKHR::SERIALIZE {
            return Err(Error::vuid(
                "VUID-VkCopyAccelerationStructureToMemoryInfoKHR-mode-03412",
                at,
                format!("mode {mode:?} is not SERIALIZE"),
            ));
        }
        if !(dst.as_ptr() as usize).is_multiple_of(16) {
            return Err(Error::vuid(
                "VUID-vkCopyAccelerationStructureToMemoryKHR-pInfo-03751",
                at,
                "dst.hostAddress is not aligned to 16 bytes",
            ));
        }
        self.with_bytes(src, |bytes| {
            let v = View::parse(bytes).map_err(|reason| {
                Error::vuid(
                    "VUID-VkCopyAccelerationStructureToMemoryInfoKHR-src-04959",
                    at,
                    format!("source holds no built structure: {reason}"),
                )
            })?;
            let handles = handle_list(&v);
            let used = v.header.used_size;
            let total = SERIALIZED_HEADER_SIZE + 8 * handles.len() as u64 + used;
            if (dst.len() as u64) < total {
                return Err(Error::vuid(
                    "VUID-VkCopyAccelerationStructureToMemoryInfoKHR-dst-03561",
                    at,
                    format!("dst holds {} bytes, serialization needs {total}", dst.len()),
                ));
            }
            dst[0..16].copy_from_slice(&DRIVER_UUID);
            dst[16..32].copy_from_slice(&COMPATIBILITY_UUID);
            dst[32..40].copy_from_slice(&total.to_le_bytes());
            dst[40..48].copy_from_slice(&used.to_le_bytes());
            dst[48..56].copy_from_slice(&(handles.len() as u64).to_le_bytes());
            for (i, h) in handles.iter().enumerate() {
                dst[56 + 8 * i..64 + 8 * i].copy_from_slice(&h.to_le_bytes());
            }
            let start = (SERIALIZED_HEADER_SIZE + 8 * handles.len() as u64) as usize;
            dst[start..start + used as usize].copy_from_slice(&bytes[..used as usize]);
            // The allocation size is not part of the structure: serialize it as the used size,
            // so that serialize(deserialize(x)) == x.
            patch_allocated(&mut dst[start..], used);
            Ok(total)
        })
    }

    /// `vkCopyMemoryToAccelerationStructureKHR` (mode `DESERIALIZE`). `src` is untrusted: it is
    /// validated completely before anything is written.
    #[doc(alias = "vkCopyMemoryToAccelerationStructureKHR")]
    pub fn copy_memory_to_acceleration_structure(
        &self,
        src: &[u8],
        dst: AccelerationStructure,
        mode: vk::CopyAccelerationStructureModeKHR,
    ) -> Result<()> {
        let at = Location::NONE;
        if mode != vk::CopyAccelerationStructureModeKHR::DESERIALIZE {
            return Err(Error::vuid(
                "VUID-VkCopyMemoryToAccelerationStructureInfoKHR-mode-03413",
                at,
                format!("mode {mode:?} is not DESERIALIZE"),
            ));
        }
        if !(src.as_ptr() as usize).is_multiple_of(16) {
            return Err(Error::vuid(
                "VUID-vkCopyMemoryToAccelerationStructureKHR-pInfo-03750",
                at,
                "src.hostAddress is not aligned to 16 bytes",
            ));
        }
        let header = SerializedHeader::parse(src)?;
        let mut version = [0u8; 32];
        version[..16].copy_from_slice(&header.driver_uuid);
        version[16..].copy_from_slice(&header.compatibility_uuid);
        if self.compatibility(&version) != vk::AccelerationStructureCompatibilityKHR::COMPATIBLE {
            return Err(Error::vuid(
                "VUID-VkCopyMemoryToAccelerationStructureInfoKHR-pInfo-03414",
                at,
                "the data was serialized by an incompatible implementation or layout version",
            ));
        }
        let start = SERIALIZED_HEADER_SIZE + 8 * header.handles.len() as u64;
        let payload_end = start
            .checked_add(header.deserialized_size)
            .filter(|&e| e <= src.len() as u64 && e <= header.serialized_size);
        let Some(payload_end) = payload_end else {
            return Err(Error::RangeTooShort {
                what: "serialized data",
                needed: start.saturating_add(header.deserialized_size),
                available: src.len() as u64,
                location: at,
            });
        };
        let payload = &src[start as usize..payload_end as usize];
        // Validate a copy with the alignment the typed view needs.
        let staged = crate::memory::aligned_copy(payload)?;
        let check = |b: &[u8]| -> Result<(Header, PrimKind)> {
            let v = View::parse(b).map_err(|reason| {
                Error::vuid(
                    "VUID-VkCopyMemoryToAccelerationStructureInfoKHR-pInfo-03414",
                    at,
                    format!("invalid structure data: {reason}"),
                )
            })?;
            if v.header.used_size != header.deserialized_size {
                return Err(Error::vuid(
                    "VUID-VkCopyMemoryToAccelerationStructureInfoKHR-pInfo-03414",
                    at,
                    "deserialized size disagrees with the structure",
                ));
            }
            if v.header.kind == Kind::TopLevel as u32
                && header.handles.len() != v.header.primitive_count as usize
            {
                return Err(Error::vuid(
                    "VUID-VkCopyMemoryToAccelerationStructureInfoKHR-pInfo-03414",
                    at,
                    "handle count differs from the instance count",
                ));
            }
            if v.header.kind == Kind::BottomLevel as u32 && header.handle_count != 0 {
                return Err(Error::vuid(
                    "VUID-VkCopyMemoryToAccelerationStructureInfoKHR-pInfo-03414",
                    at,
                    "a bottom-level structure carries no handles",
                ));
            }
            Ok((*v.header, v.prim_kind))
        };
        let (h, prim_kind) = check(staged.bytes())?;
        let dst_obj = self.object(dst)?;
        let ty_ok = dst_obj.ty == vk::AccelerationStructureTypeKHR::GENERIC
            || (dst_obj.ty == vk::AccelerationStructureTypeKHR::TOP_LEVEL)
                == (h.kind == Kind::TopLevel as u32);
        if !ty_ok {
            return Err(Error::vuid(
                "VUID-VkCopyMemoryToAccelerationStructureInfoKHR-dst-03746",
                at,
                format!(
                    "destination type {:?} differs from the serialized type",
                    dst_obj.ty
                ),
            ));
        }
        if dst_obj.size < header.deserialized_size {
            return Err(Error::vuid(
                "VUID-VkCopyMemoryToAccelerationStructureInfoKHR-dst-03746",
                at,
                format!(
                    "destination size {} is smaller than the deserialized size {}",
                    dst_obj.size, header.deserialized_size
                ),
            ));
        }
        self.with_dst_src(&dst_obj, None, at, |d, _| {
            d[..payload.len()].copy_from_slice(payload);
            patch_allocated(d, d.len() as u64);
            if prim_kind == PrimKind::Instances {
                let recs: &mut [InstanceRecord] = bytemuck::try_cast_slice_mut(
                    &mut d[h.prims_offset as usize
                        ..h.prims_offset as usize + 128 * h.stored_count as usize],
                )
                .map_err(|e| Error::NotSupported(format!("alignment: {e}")))?;
                for r in recs {
                    r.acceleration_structure_reference = header
                        .handles
                        .get(r.instance_id as usize)
                        .copied()
                        .unwrap_or(0);
                }
            }
            Ok(())
        })
    }

    /// `vkWriteAccelerationStructuresPropertiesKHR`: one `VkDeviceSize` per structure at
    /// `data[i * stride..]`.
    #[doc(alias = "vkWriteAccelerationStructuresPropertiesKHR")]
    pub fn write_acceleration_structures_properties(
        &self,
        structures: &[AccelerationStructure],
        query_type: vk::QueryType,
        data: &mut [u8],
        stride: usize,
    ) -> Result<()> {
        let at = Location::NONE;
        let stride_vuid = match query_type {
            vk::QueryType::ACCELERATION_STRUCTURE_COMPACTED_SIZE_KHR => {
                "VUID-vkWriteAccelerationStructuresPropertiesKHR-queryType-03448"
            }
            vk::QueryType::ACCELERATION_STRUCTURE_SERIALIZATION_SIZE_KHR => {
                "VUID-vkWriteAccelerationStructuresPropertiesKHR-queryType-03450"
            }
            vk::QueryType::ACCELERATION_STRUCTURE_SIZE_KHR => {
                "VUID-vkWriteAccelerationStructuresPropertiesKHR-queryType-06731"
            }
            vk::QueryType::ACCELERATION_STRUCTURE_SERIALIZATION_BOTTOM_LEVEL_POINTERS_KHR => {
                "VUID-vkWriteAccelerationStructuresPropertiesKHR-queryType-06733"
            }
            other => {
                return Err(Error::vuid(
                    "VUID-vkWriteAccelerationStructuresPropertiesKHR-queryType-06742",
                    at,
                    format!("query type {other:?} is not an acceleration-structure property"),
                ));
            }
        };
        if !stride.is_multiple_of(8) {
            return Err(Error::vuid(
                stride_vuid,
                at,
                format!("stride {stride} is not a multiple of 8"),
            ));
        }
        if structures.is_empty() {
            return Err(Error::vuid(
                "VUID-vkWriteAccelerationStructuresPropertiesKHR-accelerationStructureCount-arraylength",
                at,
                "accelerationStructureCount must be greater than 0",
            ));
        }
        let fits = structures
            .len()
            .checked_mul(stride)
            .is_some_and(|n| n <= data.len())
            && (structures.len() - 1) * stride + 8 <= data.len();
        if !fits {
            return Err(Error::vuid(
                "VUID-vkWriteAccelerationStructuresPropertiesKHR-dataSize-03452",
                at,
                format!(
                    "dataSize {} is less than count * stride ({} * {stride})",
                    data.len(),
                    structures.len()
                ),
            ));
        }
        let mut values = Vec::with_capacity(structures.len());
        for (i, s) in structures.iter().enumerate() {
            let at = Location::info(i);
            let v = self.with_bytes(*s, |b| {
                let v = View::parse(b).map_err(|reason| Error::vuid("VUID-vkWriteAccelerationStructuresPropertiesKHR-pAccelerationStructures-11591", at, format!("structure {:#x} is not built: {reason}", s.0)))?;
                let h = *v.header;
                Ok(match query_type {
                    vk::QueryType::ACCELERATION_STRUCTURE_COMPACTED_SIZE_KHR => {
                        if h.build_flags & vk::BuildAccelerationStructureFlagsKHR::ALLOW_COMPACTION.as_raw() == 0 {
                            return Err(Error::vuid("VUID-vkWriteAccelerationStructuresPropertiesKHR-accelerationStructures-03431", at, "COMPACTED_SIZE needs a structure built with ALLOW_COMPACTION"));
                        }
                        h.used_size
                    }
                    vk::QueryType::ACCELERATION_STRUCTURE_SERIALIZATION_SIZE_KHR => SERIALIZED_HEADER_SIZE + 8 * handle_list(&v).len() as u64 + h.used_size,
                    vk::QueryType::ACCELERATION_STRUCTURE_SIZE_KHR => h.used_size,
                    // 0 for bottom-level structures, as the CTS expects.
                    _ => handle_list(&v).len() as u64,
                })
            })?;
            values.push(v);
        }
        for (i, v) in values.iter().enumerate() {
            data[i * stride..i * stride + 8].copy_from_slice(&v.to_le_bytes());
        }
        Ok(())
    }

    /// One property of one structure (see [`Device::write_acceleration_structures_properties`]).
    pub fn acceleration_structure_property(
        &self,
        a: AccelerationStructure,
        query_type: vk::QueryType,
    ) -> Result<u64> {
        let mut out = [0u8; 8];
        self.write_acceleration_structures_properties(&[a], query_type, &mut out, 8)?;
        Ok(u64::from_le_bytes(out))
    }

    /// Serializes into a new, 16-byte aligned buffer; returns the bytes.
    pub fn serialize(&self, a: AccelerationStructure) -> Result<Vec<u8>> {
        let size = self.acceleration_structure_property(
            a,
            vk::QueryType::ACCELERATION_STRUCTURE_SERIALIZATION_SIZE_KHR,
        )?;
        let mut words = vec![0u128; (size as usize).div_ceil(16)];
        let bytes: &mut [u8] = bytemuck::cast_slice_mut(&mut words);
        let n = self.copy_acceleration_structure_to_memory(
            a,
            bytes,
            vk::CopyAccelerationStructureModeKHR::SERIALIZE,
        )?;
        Ok(bytes[..n as usize].to_vec())
    }

    /// Deserializes `bytes` (any alignment) into a new `GENERIC` structure that takes the
    /// serialized type. A top-level structure's instances reference the handles in the data's
    /// handle list (one per instance, in instance order): rewrite that list first with the
    /// handles of the bottom-level structures deserialized for it.
    pub fn deserialize(&self, bytes: &[u8]) -> Result<AccelerationStructure> {
        let header = SerializedHeader::parse(bytes)?;
        // Untrusted sizes: nothing is allocated for more than the data actually holds.
        let start = SERIALIZED_HEADER_SIZE + 8 * header.handles.len() as u64;
        if start
            .checked_add(header.deserialized_size)
            .is_none_or(|end| end > bytes.len() as u64)
        {
            return Err(Error::RangeTooShort {
                what: "serialized data",
                needed: start.saturating_add(header.deserialized_size),
                available: bytes.len() as u64,
                location: Location::NONE,
            });
        }
        let mut words = vec![0u128; bytes.len().div_ceil(16)];
        let aligned: &mut [u8] = bytemuck::cast_slice_mut(&mut words);
        aligned[..bytes.len()].copy_from_slice(bytes);
        let aligned = &aligned[..bytes.len()];
        let ty = vk::AccelerationStructureTypeKHR::GENERIC;
        let dst = self.create_acceleration_structure(
            &crate::AccelerationStructureCreateInfo::new(ty, header.deserialized_size.max(1)),
        )?;
        if let Err(e) = self.copy_memory_to_acceleration_structure(
            aligned,
            dst,
            vk::CopyAccelerationStructureModeKHR::DESERIALIZE,
        ) {
            let _ = self.destroy_acceleration_structure(dst);
            return Err(e);
        }
        Ok(dst)
    }
}

/// Whether `bytes` start with a hostas structure header (for tools).
pub fn is_hostas_structure(bytes: &[u8]) -> bool {
    view::read_header(bytes).is_ok()
}
