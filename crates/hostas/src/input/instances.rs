//! Reading `VkAccelerationStructureInstanceKHR` records. The 24/8-bit fields are decoded from two
//! little-endian u32 words, the spec's intended bit pattern, never through C bit-fields.

use super::{BuildRangeInfo, InstancesData, read_bytes, read_transform, read_u32};
use crate::error::{Error, Location, Result};
use crate::math::Affine;
use ash::vk;

/// One decoded instance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Instance {
    pub transform: Affine,
    /// Low 24 bits of word 0.
    pub custom_index: u32,
    /// High 8 bits of word 0.
    pub mask: u8,
    /// Low 24 bits of word 1.
    pub sbt_record_offset: u32,
    /// High 8 bits of word 1 (`VkGeometryInstanceFlagsKHR`).
    pub flags: vk::GeometryInstanceFlagsKHR,
    /// The referenced bottom-level structure's handle (its device address); 0 = inactive.
    pub acceleration_structure_reference: u64,
}

impl Instance {
    /// Decodes the 64 bytes of one instance.
    pub fn decode(bytes: &[u8]) -> Option<Instance> {
        let transform = read_transform(bytes, 0)?;
        let w0 = read_u32(bytes, 48)?;
        let w1 = read_u32(bytes, 52)?;
        let reference = u64::from_le_bytes(read_bytes::<8>(bytes, 56)?);
        Some(Instance {
            transform,
            custom_index: w0 & 0x00ff_ffff,
            mask: (w0 >> 24) as u8,
            sbt_record_offset: w1 & 0x00ff_ffff,
            flags: vk::GeometryInstanceFlagsKHR::from_raw(w1 >> 24),
            acceleration_structure_reference: reference,
        })
    }

    /// Encodes the 64-byte `VkAccelerationStructureInstanceKHR` record.
    pub fn encode(&self) -> [u8; 64] {
        let mut out = [0u8; 64];
        for (i, v) in self.transform.to_rows().iter().enumerate() {
            out[4 * i..4 * i + 4].copy_from_slice(&v.to_le_bytes());
        }
        let w0 = (self.custom_index & 0x00ff_ffff) | (self.mask as u32) << 24;
        let w1 = (self.sbt_record_offset & 0x00ff_ffff) | (self.flags.as_raw() & 0xff) << 24;
        out[48..52].copy_from_slice(&w0.to_le_bytes());
        out[52..56].copy_from_slice(&w1.to_le_bytes());
        out[56..64].copy_from_slice(&self.acceleration_structure_reference.to_le_bytes());
        out
    }
}

#[derive(Clone, Copy, Debug)]
pub struct InstanceReader<'a> {
    data: InstancesData<'a>,
    primitive_offset: u64,
    pub primitive_count: u32,
    location: Location,
}

impl<'a> InstanceReader<'a> {
    pub fn new(
        data: &InstancesData<'a>,
        range: &BuildRangeInfo,
        location: Location,
    ) -> Result<Self> {
        if !range.primitive_offset.is_multiple_of(16) {
            return Err(Error::vuid(
                "VUID-VkAccelerationStructureBuildRangeInfoKHR-primitiveOffset-03660",
                location,
                format!(
                    "primitiveOffset {} is not a multiple of 16",
                    range.primitive_offset
                ),
            ));
        }
        Ok(InstanceReader {
            data: *data,
            primitive_offset: range.primitive_offset as u64,
            primitive_count: range.primitive_count,
            location,
        })
    }

    /// Instance `i` of the range.
    pub fn instance(&self, i: u32) -> Result<Instance> {
        let location = self.location.primitive(i);
        let too_short = |what, needed: u64, available: usize| Error::RangeTooShort {
            what,
            needed,
            available: available as u64,
            location,
        };
        let inst = match self.data {
            InstancesData::Array(bytes) => {
                let at = self.primitive_offset + 64 * i as u64;
                let start = usize::try_from(at).unwrap_or(usize::MAX);
                bytes
                    .get(start..)
                    .and_then(Instance::decode)
                    .ok_or_else(|| too_short("instances.data", at + 64, bytes.len()))?
            }
            InstancesData::Pointers(ptrs) => {
                let slot = self.primitive_offset / 8 + i as u64;
                let bytes = usize::try_from(slot)
                    .ok()
                    .and_then(|s| ptrs.get(s))
                    .ok_or_else(|| {
                        too_short(
                            "instances.data (array of pointers)",
                            (slot + 1) * 8,
                            ptrs.len() * 8,
                        )
                    })?;
                Instance::decode(bytes).ok_or_else(|| {
                    too_short("instance pointed to by instances.data", 64, bytes.len())
                })?
            }
        };
        let known = vk::GeometryInstanceFlagsKHR::TRIANGLE_FACING_CULL_DISABLE
            | vk::GeometryInstanceFlagsKHR::TRIANGLE_FLIP_FACING
            | vk::GeometryInstanceFlagsKHR::FORCE_OPAQUE
            | vk::GeometryInstanceFlagsKHR::FORCE_NO_OPAQUE;
        if !known.contains(inst.flags) {
            return Err(Error::vuid(
                "VUID-VkAccelerationStructureInstanceKHR-flags-parameter",
                location,
                format!(
                    "instance flags {:#x} include bits of extensions hostas does not support (opacity micromaps)",
                    inst.flags.as_raw()
                ),
            ));
        }
        let forced = vk::GeometryInstanceFlagsKHR::FORCE_OPAQUE
            | vk::GeometryInstanceFlagsKHR::FORCE_NO_OPAQUE;
        if inst.flags.contains(forced) {
            return Err(Error::vuid(
                "VUID-VkAccelerationStructureInstanceKHR-flags-parameter",
                location,
                "instance flags contain both FORCE_OPAQUE and FORCE_NO_OPAQUE",
            ));
        }
        Ok(inst)
    }
}
