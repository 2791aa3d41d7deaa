//! Reading `VkAabbPositionsKHR` records: `primitiveCount` boxes from `data + primitiveOffset`,
//! `stride` bytes apart.

use super::{AabbsData, BuildRangeInfo, read_f32};
use crate::error::{Error, Location, Result};
use crate::math::Aabb;

#[derive(Clone, Copy, Debug)]
pub struct AabbReader<'a> {
    data: AabbsData<'a>,
    primitive_offset: u64,
    pub primitive_count: u32,
    location: Location,
}

impl<'a> AabbReader<'a> {
    pub fn new(data: &AabbsData<'a>, range: &BuildRangeInfo, location: Location) -> Result<Self> {
        if !data.stride.is_multiple_of(8) {
            return Err(Error::vuid(
                "VUID-VkAccelerationStructureGeometryAabbsDataKHR-stride-03545",
                location,
                format!("stride {} is not a multiple of 8", data.stride),
            ));
        }
        if data.stride > u32::MAX as u64 {
            return Err(Error::vuid(
                "VUID-VkAccelerationStructureGeometryAabbsDataKHR-stride-03820",
                location,
                format!("stride {} is larger than 2^32-1", data.stride),
            ));
        }
        if !range.primitive_offset.is_multiple_of(8) {
            return Err(Error::vuid(
                "VUID-VkAccelerationStructureBuildRangeInfoKHR-primitiveOffset-03659",
                location,
                format!(
                    "primitiveOffset {} is not a multiple of 8",
                    range.primitive_offset
                ),
            ));
        }
        Ok(AabbReader {
            data: *data,
            primitive_offset: range.primitive_offset as u64,
            primitive_count: range.primitive_count,
            location,
        })
    }

    /// Box `i`, or `None` when it is inactive (`minX` is NaN).
    #[inline]
    pub fn aabb(&self, i: u32) -> Result<Option<Aabb>> {
        let at = self.primitive_offset + i as u64 * self.data.stride;
        let mut f = [0f32; 6];
        for (k, v) in f.iter_mut().enumerate() {
            *v = read_f32(self.data.data, at + 4 * k as u64).ok_or(Error::RangeTooShort {
                what: "aabbs.data",
                needed: at + 24,
                available: self.data.data.len() as u64,
                location: self.location.primitive(i),
            })?;
        }
        if f[0].is_nan() {
            return Ok(None);
        }
        const VUIDS: [&str; 3] = [
            "VUID-VkAabbPositionsKHR-minX-03546",
            "VUID-VkAabbPositionsKHR-minY-03547",
            "VUID-VkAabbPositionsKHR-minZ-03548",
        ];
        for k in 0..3 {
            // NaN in any other bound is as invalid as min > max: the box must be well formed.
            if !(f[k] <= f[k + 3]) {
                return Err(Error::vuid(
                    VUIDS[k],
                    self.location.primitive(i),
                    format!(
                        "min {} is not less than or equal to max {} on axis {k}",
                        f[k],
                        f[k + 3]
                    ),
                ));
            }
        }
        Ok(Some(Aabb {
            lo: [f[0], f[1], f[2]],
            hi: [f[3], f[4], f[5]],
        }))
    }
}
